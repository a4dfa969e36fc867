//! IK synthesis: reaching targets, exact bone lengths, hinge knees, presets.

use glam::{DQuat, DVec3};
use motion::Motion;
use motion::skeleton::Transform;
use proptest::prelude::*;
use synth::fixtures::{humanoid, kick, walk};
use synth::ik::limb::{EffectorOrientation, Limb, SolveOptions, solve_frame};
use synth::ik::{Preset, blend_weight};
use synth::*;

/// Largest |FK distance joint-parent - offset length| over all frames.
fn bone_length_error(m: &Motion) -> f64 {
    let s = m.skeleton();
    let lengths = s.bone_lengths();
    let mut worst = 0.0f64;
    for t in 0..m.frames() {
        let p = m.world_positions(t);
        for j in 1..m.joints() {
            let parent = s.parent(j).unwrap();
            worst = worst.max(((p[j] - p[parent]).length() - lengths[j]).abs());
        }
    }
    worst
}

/// Angle of the part of a rotation that is not about `axis`.
fn off_axis(q: DQuat, axis: DVec3) -> f64 {
    let v = DVec3::new(q.x, q.y, q.z);
    (v - axis * v.dot(axis)).length() * 2.0
}

#[test]
fn kick_preset_reaches_its_target_with_exact_bones() {
    let m = kick(90, 30.0, 45);
    for seed in 0..8 {
        let out = ik(
            &m,
            &IkParams::preset(Preset::Kick),
            &mut rng_from_seed(seed),
        )
        .unwrap();
        let r: IkReport =
            serde_json::from_value(serde_json::Value::Object(out.sampled.clone())).unwrap();
        assert_eq!(r.effector, "LeftFoot", "the kicking foot reaches farthest");
        assert!((r.keyframe_farthest as i64 - 45).abs() <= 1);
        assert!(
            (r.keyframe as i64 - r.keyframe_farthest as i64).abs() <= 3,
            "jitter 0.1 s = 3 frames"
        );
        assert!(r.reachable);
        assert!(
            r.error_keyframe_m < 1e-6,
            "keyframe error {}",
            r.error_keyframe_m
        );
        // Frames whose propagated target is past the straight leg are clamped to
        // reach; only they may miss, and then only by the reach deficit.
        if r.frames_out_of_reach == 0 {
            assert!(r.error_max_m < 1e-6, "max error {} ({r:?})", r.error_max_m);
        } else {
            assert!(r.error_max_m < 0.05, "max error {} ({r:?})", r.error_max_m);
        }
        // The effector really is at the target in the output.
        let pos = out.motion.world_positions(r.keyframe)[3];
        assert!((pos - DVec3::from_array(r.target)).length() < 1e-6);
        // The target lies in the kick fan around the hip axis.
        assert!((0.8..=1.2).contains(&r.r_scale) && (0.8..=1.2).contains(&r.h_scale));
        assert!(r.theta_offset.abs() <= 0.785);
        let hip = m.world_positions(r.keyframe)[1];
        let rel = DVec3::from_array(r.target) - hip;
        let flat = DVec3::new(rel.x, 0.0, rel.z).length();
        assert!((flat - r.r_scale * r.key_r_m).abs() < 1e-9);
        assert!((r.target[1] - r.h_scale * r.key_h_m).abs() < 1e-9);
        let heading = rel.x.atan2(rel.z);
        let turn = (heading - r.key_theta - r.theta_offset).rem_euclid(std::f64::consts::TAU);
        assert!(
            !(1e-9..=std::f64::consts::TAU - 1e-9).contains(&turn),
            "heading {heading}"
        );
        let src = m.world_positions(r.keyframe)[3];
        assert!((r.key_h_m - src.y).abs() < 1e-12);
        assert_eq!(r.fan, Preset::Kick.fan());
        assert!(bone_length_error(&out.motion) < 1e-9);
        // First and last frames are unchanged (f = 0 there).
        for t in [0, m.frames() - 1] {
            for (a, b) in out.motion.pose(t).iter().zip(m.pose(t)) {
                assert!(motion::rotation::angle_between(*a, *b) < 1e-9);
            }
        }
        // The knee stays a hinge about x, bending the same way.
        for t in 0..m.frames() {
            let q = out.motion.rotation(t, 2);
            assert!(off_axis(q, DVec3::X) < 1e-6, "frame {t}: knee {q:?}");
            assert!(q.x * q.w >= -1e-9, "frame {t}: knee bends backwards");
        }
    }
    let a = ik(&m, &IkParams::preset(Preset::Kick), &mut rng_from_seed(3)).unwrap();
    let b = ik(&m, &IkParams::preset(Preset::Kick), &mut rng_from_seed(3)).unwrap();
    assert_eq!(a.motion, b.motion);
}

#[test]
fn every_preset_runs_and_hand_presets_move_a_hand() {
    let m = walk(60, 30.0, 1.0);
    for preset in [
        Preset::Punch,
        Preset::Kick,
        Preset::Walk,
        Preset::Grab,
        Preset::Deposit,
        Preset::Jog,
        Preset::Sneak,
        Preset::Throw,
        Preset::Hop,
        Preset::Squat,
    ] {
        let out = ik(&m, &IkParams::preset(preset), &mut rng_from_seed(1)).unwrap();
        let name = out.sampled["effector"].as_str().unwrap().to_string();
        match preset.limb() {
            ik::Limbs::Hand => assert!(name.ends_with("Hand"), "{preset:?}: {name}"),
            ik::Limbs::Foot => assert!(name.ends_with("Foot"), "{preset:?}: {name}"),
        }
        if out.sampled["reachable"].as_bool().unwrap() {
            let e = out.sampled["error_keyframe_m"].as_f64().unwrap();
            assert!(e < 0.01, "{preset:?}: {e}");
        }
        assert!(bone_length_error(&out.motion) < 1e-9);
    }
    let f = Preset::Walk.fan();
    assert_eq!(
        (f.r, f.h, f.theta),
        (Range(0.5, 2.0), Range(1.0, 1.0), Range(-0.3, 0.3))
    );
}

#[test]
fn explicit_effector_ranges_and_errors() {
    let m = kick(60, 30.0, 30);
    let p = IkParams {
        preset: None,
        effector: Some("RightFoot".into()),
        r: Some(Range(1.0, 1.0)),
        h: Some(Range(1.0, 1.0)),
        theta: Some(Range(0.0, 0.0)),
        key_jitter_s: 0.0,
        ..IkParams::preset(Preset::Kick)
    };
    let out = ik(&m, &p, &mut rng_from_seed(0)).unwrap();
    assert_eq!(out.sampled["effector"], "RightFoot");
    // Unit fan: the target is the source position, the motion barely changes.
    let get = |k: &str| -> Vec<f64> {
        out.sampled[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (src, target) = (get("source_position"), get("target"));
    for i in 0..3 {
        assert!((src[i] - target[i]).abs() < 1e-12);
    }
    let missing = IkParams {
        r: None,
        ..p.clone()
    };
    assert!(
        ik(&m, &missing, &mut rng_from_seed(0))
            .unwrap_err()
            .to_string()
            .contains("`r`")
    );
    let bad = IkParams {
        effector: Some("Tail".into()),
        ..p.clone()
    };
    assert!(
        ik(&m, &bad, &mut rng_from_seed(0))
            .unwrap_err()
            .to_string()
            .contains("Tail")
    );
    let unordered = IkParams {
        theta: Some(Range(0.5, -0.5)),
        ..p.clone()
    };
    assert!(ik(&m, &unordered, &mut rng_from_seed(0)).is_err());
}

#[test]
fn unreachable_targets_are_clamped_and_reported() {
    let m = kick(60, 30.0, 30);
    let p = IkParams {
        r: Some(Range(5.0, 5.0)),
        max_tries: 3,
        ..IkParams::preset(Preset::Kick)
    };
    let out = ik(&m, &p, &mut rng_from_seed(0)).unwrap();
    assert_eq!(out.sampled["reachable"], false);
    assert_eq!(out.sampled["tries"], 3);
    assert!(out.sampled["error_keyframe_m"].as_f64().unwrap() > 0.1);
    assert!(out.sampled["frames_out_of_reach"].as_u64().unwrap() >= 1);
    assert!(bone_length_error(&out.motion) < 1e-9);
}

#[test]
fn blend_weight_is_the_papers_triangle() {
    assert_eq!(blend_weight(0, 10, 31), 0.0);
    assert_eq!(blend_weight(5, 10, 31), 0.5);
    assert_eq!(blend_weight(10, 10, 31), 1.0);
    assert_eq!(blend_weight(20, 10, 31), 0.5);
    assert_eq!(blend_weight(30, 10, 31), 0.0);
    assert_eq!(blend_weight(0, 0, 5), 1.0);
    assert_eq!(blend_weight(4, 4, 5), 1.0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    /// Random hip orientation and knee bend, random reachable target: the foot
    /// reaches it, bones keep their lengths, the knee stays a forward-bending hinge.
    #[test]
    fn limb_ik_reaches_random_reachable_targets(
        hx in -1.5..1.0f64, hy in -0.8..0.8f64, hz in -0.6..0.6f64,
        knee in 0.05..2.5f64,
        dir in (-1.0..1.0f64, -1.0..0.5f64, -1.0..1.0f64),
        frac in 0.02..0.98f64,
        world in any::<bool>(),
    ) {
        let s = humanoid();
        let mut pose = vec![DQuat::IDENTITY; s.len()];
        pose[0] = DQuat::from_rotation_y(0.3);
        pose[1] = DQuat::from_euler(glam::EulerRot::XYZ, hx, hy, hz);
        pose[2] = DQuat::from_rotation_x(knee);
        let root = DVec3::new(0.0, 0.9, 0.0);
        let mut x = vec![Transform::IDENTITY; s.len()];
        s.forward(root, &pose, &mut x);
        let limb = Limb::new(&s, 3).unwrap();
        let (l1, l2) = limb.lengths(&x);
        let d = DVec3::new(dir.0, dir.1, dir.2);
        prop_assume!(d.length() > 0.1);
        let lo = (l1 - l2).abs() + 0.01;
        let hi = l1 + l2 - 0.001;
        let target = x[1].translation + d.normalize() * (lo + frac * (hi - lo));
        let original = pose.clone();
        let orientation = if world { EffectorOrientation::World } else { EffectorOrientation::Local };
        let options = SolveOptions { orientation, respect_limits: true };
        let edit = solve_frame(&s, &limb, &x, &mut pose, &original, target, options);
        prop_assert!(!edit.out_of_reach && !edit.clamped);
        let mut y = vec![Transform::IDENTITY; s.len()];
        s.forward(root, &pose, &mut y);
        let err = (y[3].translation - target).length();
        prop_assert!(err < 1e-3, "error {err}");
        prop_assert!(err < 1e-8, "error {err}");
        for j in 1..s.len() {
            let p = s.parent(j).unwrap();
            let len = (y[j].translation - y[p].translation).length();
            prop_assert!((len - s.joint(j).offset.length()).abs() < 1e-12);
        }
        prop_assert!(off_axis(pose[2], DVec3::X) < 1e-6, "knee {:?}", pose[2]);
        prop_assert!(pose[2].x * pose[2].w > 0.0, "knee bends forward");
        if world {
            prop_assert!(motion::rotation::angle_between(y[3].rotation, x[3].rotation) < 1e-9);
        }
        // Nothing but the hip and knee (and foot in world mode) changed.
        for j in 0..s.len() {
            if ![1, 2, 3].contains(&j) {
                prop_assert_eq!(pose[j], original[j]);
            }
        }
    }
}
