//! Behaviour of the non-IK ops on the synthetic humanoid.

use glam::{DQuat, DVec3};
use motion::rotation::angle_between;
use synth::fixtures::{humanoid, walk};
use synth::*;

fn same_bits(a: &motion::Motion, b: &motion::Motion) -> bool {
    a.frames() == b.frames()
        && a.root_translation()
            .iter()
            .zip(b.root_translation())
            .all(|(x, y)| x.to_array().map(f64::to_bits) == y.to_array().map(f64::to_bits))
        && a.rotations()
            .iter()
            .zip(b.rotations())
            .all(|(x, y)| x.to_array().map(f64::to_bits) == y.to_array().map(f64::to_bits))
}

#[test]
fn noise_is_reproducible_and_has_the_requested_spread() {
    let m = walk(200, 30.0, 1.2);
    let p = NoiseParams {
        sigma_deg: 3.0,
        root_sigma_m: 0.01,
        include_root: false,
    };
    let a = noise(&m, &p, &mut rng_from_seed(5)).unwrap().motion;
    let b = noise(&m, &p, &mut rng_from_seed(5)).unwrap().motion;
    let c = noise(&m, &p, &mut rng_from_seed(6)).unwrap().motion;
    assert!(same_bits(&a, &b));
    assert!(!same_bits(&a, &c));
    // Mean perturbation angle of a 3D Gaussian rotation vector: sigma * sqrt(8/pi).
    let n = m.joints();
    let mut sum = 0.0;
    let mut count = 0;
    for t in 0..m.frames() {
        assert_eq!(
            a.rotation(t, 0),
            m.rotation(t, 0),
            "root orientation untouched"
        );
        for j in 1..n {
            sum += angle_between(a.rotation(t, j), m.rotation(t, j));
            count += 1;
        }
    }
    let expected = 3.0f64.to_radians() * (8.0 / std::f64::consts::PI).sqrt();
    let mean = sum / count as f64;
    assert!(
        (mean / expected - 1.0).abs() < 0.05,
        "mean {mean} vs {expected}"
    );
    let root_dev: f64 = a
        .root_translation()
        .iter()
        .zip(m.root_translation())
        .map(|(x, y)| (*x - *y).length_squared())
        .sum::<f64>()
        / (3.0 * m.frames() as f64);
    assert!(
        (root_dev.sqrt() / 0.01 - 1.0).abs() < 0.15,
        "root sigma {}",
        root_dev.sqrt()
    );
    let zero = NoiseParams {
        sigma_deg: 0.0,
        ..NoiseParams::default()
    };
    assert!(same_bits(
        &noise(&m, &zero, &mut rng_from_seed(1)).unwrap().motion,
        &m
    ));
    assert!(
        noise(
            &m,
            &NoiseParams {
                sigma_deg: -1.0,
                ..zero
            },
            &mut rng_from_seed(1)
        )
        .is_err()
    );
}

#[test]
fn time_warp_resamples_at_the_drawn_speed() {
    let m = walk(101, 30.0, 1.0);
    let p = TimeWarpParams {
        factor: Range(1.25, 1.25),
    };
    let out = time_warp(&m, &p, &mut rng_from_seed(0)).unwrap();
    let w = out.motion;
    assert_eq!(w.frames(), 81);
    assert_eq!(w.fps(), m.fps());
    // Output frame 4 is source frame 5 exactly; frame 1 is source 1.25.
    assert!((w.root_translation()[4] - m.root_translation()[5]).length() < 1e-12);
    let expect = m.root_translation()[1].lerp(m.root_translation()[2], 0.25);
    assert!((w.root_translation()[1] - expect).length() < 1e-12);
    assert!(angle_between(w.rotation(4, 1), m.rotation(5, 1)) < 1e-9);
    let q = m.rotation(1, 1).slerp(m.rotation(2, 1), 0.25);
    assert!(angle_between(w.rotation(1, 1), q) < 1e-9);
    assert_eq!(out.sampled["factor"].as_f64(), Some(1.25));
    // Slower: more frames; the drawn factor stays in range.
    for seed in 0..20 {
        let o = time_warp(&m, &TimeWarpParams::default(), &mut rng_from_seed(seed)).unwrap();
        let f = o.sampled["factor_drawn"].as_f64().unwrap();
        assert!((0.9..=1.1).contains(&f));
        let expected = (100.0 / f).round() as usize + 1;
        assert_eq!(o.motion.frames(), expected);
    }
    assert!(
        time_warp(
            &m,
            &TimeWarpParams {
                factor: Range(1.1, 0.9)
            },
            &mut rng_from_seed(0)
        )
        .is_err()
    );
}

#[test]
fn mirror_reflects_world_positions_exactly_on_a_symmetric_skeleton() {
    let m = walk(60, 30.0, 1.0);
    let out = mirror(&m, &MirrorParams::default(), &mut rng_from_seed(0)).unwrap();
    let w = &out.motion;
    let s = m.skeleton();
    let left_foot = s.find("LeftFoot").unwrap();
    let right_foot = s.find("RightFoot").unwrap();
    let pairs = synth::names::Pairs::from_names(s);
    assert_eq!(pairs.pair_count(), 7);
    assert_eq!(pairs.partner[left_foot], right_foot);
    let flip = |p: DVec3| DVec3::new(-p.x, p.y, p.z);
    for t in 0..m.frames() {
        let a = m.world_positions(t);
        let b = w.world_positions(t);
        for j in 0..m.joints() {
            let d = (b[pairs.partner[j]] - flip(a[j])).length();
            assert!(d < 1e-9, "frame {t} joint {j}: {d}");
        }
    }
    // Mirroring twice gives the clip back.
    let back = mirror(w, &MirrorParams::default(), &mut rng_from_seed(0))
        .unwrap()
        .motion;
    for (x, y) in back.rotations().iter().zip(m.rotations()) {
        assert!(angle_between(*x, *y) < 1e-12);
    }
    // Quaternion reflection for an x mirror: (w, x, y, z) -> (w, x, -y, -z).
    let q = DQuat::from_xyzw(0.1, 0.2, 0.3, 0.9).normalize();
    let r = mirror::reflect_rotation(q, DVec3::new(-1.0, 1.0, 1.0));
    assert_eq!(r.to_array(), [q.x, -q.y, -q.z, q.w]);
}

#[test]
fn mirror_rejects_asymmetric_skeletons_and_bad_pairs() {
    let mut joints = humanoid().joints().to_vec();
    joints[2].offset.y -= 0.2; // left shin 20 cm longer than the right
    let s = std::sync::Arc::new(motion::Skeleton::new(joints, 1.0).unwrap());
    let m0 = walk(5, 30.0, 1.0);
    let m = motion::Motion::new(
        s,
        30.0,
        m0.root_translation().to_vec(),
        m0.rotations().to_vec(),
    )
    .unwrap();
    let err = mirror(&m, &MirrorParams::default(), &mut rng_from_seed(0)).unwrap_err();
    assert!(err.to_string().contains("LeftLeg"), "{err}");
    let loose = MirrorParams {
        tolerance_m: 0.25,
        ..MirrorParams::default()
    };
    let out = mirror(&m, &loose, &mut rng_from_seed(0)).unwrap();
    assert!((out.sampled["max_asymmetry_m"].as_f64().unwrap() - 0.2).abs() < 1e-9);
    let bad = MirrorParams {
        pairs: Some(vec![("LeftFoot".into(), "Nope".into())]),
        ..MirrorParams::default()
    };
    let err = mirror(&m0, &bad, &mut rng_from_seed(0)).unwrap_err();
    assert!(err.to_string().contains("pairs[0]"), "{err}");
}

#[test]
fn pairs_are_found_in_common_naming_styles() {
    let names = |list: &[&str]| {
        let joints = list
            .iter()
            .enumerate()
            .map(|(i, n)| motion::Joint {
                name: n.to_string(),
                parent: if i == 0 { None } else { Some(0) },
                offset: DVec3::ZERO,
                channels: vec![],
                end_site: None,
                limits: None,
            })
            .collect();
        let s = motion::Skeleton::new(joints, 1.0).unwrap();
        synth::names::Pairs::from_names(&s)
    };
    let p = names(&[
        "root",
        "lfemur",
        "rfemur",
        "lowerback",
        "lhipjoint",
        "rhipjoint",
        "thorax",
    ]);
    assert_eq!(p.partner, vec![0, 2, 1, 3, 5, 4, 6]);
    let p = names(&[
        "Hips",
        "LHipJoint",
        "RHipJoint",
        "hip_l",
        "hip_R",
        "Arm.L",
        "Arm.R",
    ]);
    assert_eq!(p.partner, vec![0, 2, 1, 4, 3, 6, 5]);
    let p = names(&["Hips", "left_foot", "RIGHT_FOOT", "Head"]);
    assert_eq!(p.partner, vec![0, 2, 1, 3]);
    assert_eq!(p.side[1], Some(synth::names::Side::Left));
}

#[test]
fn masks_follow_the_mode_and_probability() {
    let m = walk(300, 30.0, 1.0);
    let s = m.skeleton();
    let out = mask(&m, &MaskParams::lower_body(), &mut rng_from_seed(3)).unwrap();
    let k = out.mask.as_ref().unwrap();
    let legs: Vec<usize> = (1..=8).collect();
    for j in 0..m.joints() {
        assert_eq!(
            k.is_visible(10, j),
            !legs.contains(&j),
            "joint {}",
            s.joint(j).name
        );
    }
    // Occluded rotations are rest pose + noise: near identity, not the original.
    let knee = s.find("LeftLeg").unwrap();
    assert!(angle_between(out.motion.rotation(0, knee), DQuat::IDENTITY) < 0.5);
    assert_eq!(out.motion.rotation(0, 9), m.rotation(0, 9));

    let p = MaskParams::random_joints(0.7);
    let out = mask(&m, &p, &mut rng_from_seed(4)).unwrap();
    let k = out.mask.unwrap();
    let non_root: Vec<bool> = (0..m.frames())
        .flat_map(|t| (1..m.joints()).map(move |j| (t, j)))
        .map(|(t, j)| k.is_visible(t, j))
        .collect();
    let frac = non_root.iter().filter(|v| **v).count() as f64 / non_root.len() as f64;
    assert!((frac - 0.7).abs() < 0.02, "visible fraction {frac}");
    assert!((0..m.frames()).all(|t| k.is_visible(t, 0)));
    for t in 0..m.frames() {
        for j in 0..m.joints() {
            if k.is_visible(t, j) {
                assert_eq!(out.motion.rotation(t, j), m.rotation(t, j));
            }
        }
    }
    let mut bad = MaskParams::lower_body();
    bad.p = Some(0.5);
    assert!(mask(&m, &bad, &mut rng_from_seed(0)).is_err());
    assert!(mask(&m, &MaskParams::random_joints(1.5), &mut rng_from_seed(0)).is_err());
}

/// The walk with translation tracks on a centre joint (the spine slides
/// forward and back) and a left one (the left shin stretches).
fn walk_with_tracks() -> motion::Motion {
    let m = walk(61, 30.0, 1.0);
    let s = m.skeleton().clone();
    let (spine, shin) = (s.find("Spine").unwrap(), s.find("LeftFoot").unwrap());
    let mut tracks = vec![None; m.joints()];
    let wave = |f: usize| (f as f64 * 0.3).sin();
    tracks[spine] = Some(
        (0..m.frames())
            .map(|f| s.joint(spine).offset + DVec3::new(0.0, 0.0, 0.02 * wave(f)))
            .collect(),
    );
    tracks[shin] = Some(
        (0..m.frames())
            .map(|f| s.joint(shin).offset * (1.0 + 0.03 * wave(f)))
            .collect(),
    );
    m.with_tracks(tracks).unwrap()
}

#[test]
fn ops_carry_translation_tracks() {
    let m = walk_with_tracks();
    let s = m.skeleton().clone();
    let (spine, left, right) = (
        s.find("Spine").unwrap(),
        s.find("LeftFoot").unwrap(),
        s.find("RightFoot").unwrap(),
    );
    // Ops that keep the frames keep the tracks.
    let noisy = noise(&m, &NoiseParams::default(), &mut rng_from_seed(1)).unwrap();
    let masked = mask(&m, &MaskParams::lower_body(), &mut rng_from_seed(1)).unwrap();
    let reached = ik(&m, &IkParams::preset(Preset::Kick), &mut rng_from_seed(1)).unwrap();
    for out in [&noisy, &masked, &reached] {
        assert_eq!(out.motion.tracks(), m.tracks());
    }
    let r: IkReport =
        serde_json::from_value(serde_json::Value::Object(reached.sampled.clone())).unwrap();
    let effector = s.find(&r.effector).unwrap();
    let at = reached.motion.world_positions(r.keyframe)[effector];
    assert!((at - DVec3::from_array(r.target)).length() < 1e-6, "{r:?}");
    // Time warp interpolates them: output frame 1 is source frame 1.25.
    let p = TimeWarpParams {
        factor: Range(1.25, 1.25),
    };
    let w = time_warp(&m, &p, &mut rng_from_seed(0)).unwrap().motion;
    let expect = m.track(spine).unwrap()[1].lerp(m.track(spine).unwrap()[2], 0.25);
    assert!((w.track(spine).unwrap()[1] - expect).length() < 1e-12);
    for (a, b) in w.world_positions(4).iter().zip(m.world_positions(5)) {
        assert!((*a - b).length() < 1e-9);
    }
    // Mirror reflects them onto the partner joint: world positions mirror exactly.
    let mirrored = mirror(&m, &MirrorParams::default(), &mut rng_from_seed(0))
        .unwrap()
        .motion;
    assert!(mirrored.track(left).is_none() && mirrored.track(right).is_some());
    let pairs = synth::names::Pairs::from_names(&s);
    let flip = |p: DVec3| DVec3::new(-p.x, p.y, p.z);
    for t in 0..m.frames() {
        let (a, b) = (m.world_positions(t), mirrored.world_positions(t));
        for j in 0..m.joints() {
            assert!(
                (b[pairs.partner[j]] - flip(a[j])).length() < 1e-9,
                "frame {t} joint {j}"
            );
        }
    }
}
