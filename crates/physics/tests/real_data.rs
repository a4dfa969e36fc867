//! Character building and action-0 tracking on real clips from ../shared/data.

use std::path::PathBuf;

use motion::Motion;
use motion::io::{LoadOptions, load};
use physics::{CharacterOptions, CharacterSpec, Config, ImitationEnv, JointMapping, Role};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(rel)
}

/// The shared mocap is not part of a clone: without it these tests say so and pass.
fn absent() -> bool {
    let missing = !data("hdm05").is_dir() || !data("cmu").is_dir();
    if missing {
        eprintln!("note: ../shared/data is absent; skipping the real-data physics test");
    }
    missing
}

fn hdm05(clip: &str) -> Motion {
    let opts = LoadOptions {
        skeleton: Some(data("hdm05/HDM_bd.asf")),
        ..Default::default()
    };
    load(data(&format!("hdm05/{clip}")), &opts).unwrap()
}

fn cmu(clip: &str) -> Motion {
    load(data(&format!("cmu/{clip}")), &LoadOptions::default()).unwrap()
}

/// Track with action 0 for at most `max_steps`; returns (mean joint error, steps, fell).
fn track(motion: &Motion, cfg: &Config, max_steps: usize, verbose: bool) -> (f32, usize, bool) {
    let mut env = ImitationEnv::new(motion, cfg).unwrap();
    let action = vec![0.0; env.act_dim()];
    let (mut err, mut steps) = (0.0, 0);
    loop {
        let r = env.step(&action).unwrap();
        err += env.joint_error();
        steps += 1;
        if verbose && steps % 10 == 0 {
            println!(
                "step {steps} err {:.3} r_imit {:.3} F {:.0} root {:?}",
                env.joint_error(),
                r.r_imit,
                r.info.residual_force,
                env.body_states()[0].pos
            );
        }
        if r.info.fell() {
            if verbose {
                let s = env.body_states();
                let touching: Vec<String> = (0..s.len())
                    .filter(|&b| env.sim().touches_ground(b))
                    .map(|b| {
                        format!(
                            "{} ref lowest {:.3} sim y {:.3}",
                            env.spec().bodies[b].name,
                            env.reference().frames[r.info.frame].lowest[b],
                            s[b].pos.y
                        )
                    })
                    .collect();
                println!("fell: touching {touching:?}");
                let rf = &env.reference().frames[r.info.frame];
                let errs: Vec<String> = (1..s.len())
                    .map(|b| {
                        let p = env.spec().bodies[b].parent.unwrap();
                        let rel = s[p].rot.inverse() * s[b].rot;
                        format!(
                            "{}={:.2}",
                            env.spec().bodies[b].name,
                            2.0 * rf.rel[b].dot(rel).abs().min(1.0).acos()
                        )
                    })
                    .collect();
                println!("{}", errs.join(" "));
            }
            return (err / steps as f32, steps, true);
        }
        if r.done || steps >= max_steps {
            return (err / steps as f32, steps, false);
        }
    }
}

#[test]
fn hdm05_character_mapping() {
    if absent() {
        return;
    }
    let m = hdm05("HDM_bd_kickLFront1Reps_001_120.amc");
    let spec = CharacterSpec::build(m.skeleton().clone(), &CharacterOptions::default()).unwrap();
    for l in spec.mapping_report() {
        println!(
            "{:12} -> {}{}",
            l.file_joint,
            l.body,
            if l.merged { " (merged)" } else { "" }
        );
    }
    assert_eq!(spec.bodies.len(), 16);
    let sk = m.skeleton();
    let role = |n: &str| match spec.joint_map[sk.find(n).unwrap()] {
        JointMapping::Body(b) => Some(spec.bodies[b].role),
        _ => None,
    };
    assert_eq!(role("lfemur"), Some(Role::UpperLeg(physics::Side::Left)));
    assert_eq!(role("rtibia"), Some(Role::LowerLeg(physics::Side::Right)));
    assert_eq!(role("lhumerus"), Some(Role::UpperArm(physics::Side::Left)));
    assert_eq!(role("rradius"), Some(Role::ForeArm(physics::Side::Right)));
    assert_eq!(role("lclavicle"), None);
    assert_eq!(role("ltoes"), None);
    assert!((spec.total_mass - 45.0).abs() < 1e-3);
}

#[test]
fn every_hdm05_actor_and_cmu_pair_skeleton_builds() {
    if absent() {
        return;
    }
    for actor in ["bd", "bk", "dg", "mm", "tr"] {
        let rest = load(
            data(&format!("hdm05/HDM_{actor}.asf")),
            &LoadOptions::default(),
        )
        .unwrap();
        let spec =
            CharacterSpec::build(rest.skeleton().clone(), &CharacterOptions::default()).unwrap();
        assert_eq!(spec.bodies.len(), 16, "{actor}");
    }
    let dir = data("cmu_pairs");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "bvh") {
            let m = load(&path, &LoadOptions::default()).unwrap();
            let spec = CharacterSpec::build(m.skeleton().clone(), &CharacterOptions::default())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert_eq!(spec.bodies.len(), 16, "{}", path.display());
            count += 1;
        }
    }
    assert!(count > 0);
}

#[test]
fn cmu_character_mapping() {
    if absent() {
        return;
    }
    for clip in [
        "131_01_walk.bvh",
        "01_01_forward_jumps.bvh",
        "16_11_walk_veer_left.bvh",
    ] {
        let m = cmu(clip);
        let spec =
            CharacterSpec::build(m.skeleton().clone(), &CharacterOptions::default()).unwrap();
        assert_eq!(spec.bodies.len(), 16, "{clip}");
        assert!((spec.total_mass - 45.0).abs() < 1e-3);
    }
}

#[test]
fn action_zero_with_pd_residual_keeps_a_walk_up() {
    if absent() {
        return;
    }
    // The first 2.7 s of the CMU 131 walk (the subject crouches after that,
    // which action 0 does not survive; neither does the veering walk 16_11
    // after 1.2 s: balance is the policy's job, the PD residual only helps).
    let m = cmu("131_01_walk.bvh");
    let cfg = Config::default();
    let (err, steps, fell) = track(&m, &cfg, 80, true);
    println!("walk: mean joint error {err:.3} over {steps} steps, fell {fell}");
    assert!(!fell, "fell after {steps} steps");
    assert!(err < 0.15, "{err}");
}

#[test]
fn action_zero_tracks_the_hdm05_kick() {
    if absent() {
        return;
    }
    let m = hdm05("HDM_bd_kickLFront1Reps_001_120.amc");
    let (err, steps, fell) = track(&m, &Config::default(), 10_000, false);
    println!("kick: mean joint error {err:.3} over {steps} steps, fell {fell}");
    assert!(!fell);
    assert!(err < 0.1, "{err}");
}

#[test]
fn recorded_kick_is_close_to_the_clip_but_simulated() {
    if absent() {
        return;
    }
    let m = hdm05("HDM_bd_kickLFront1Reps_001_120.amc");
    let mut env = ImitationEnv::new(&m, &Config::default()).unwrap();
    let action = vec![0.0; env.act_dim()];
    while !env.step(&action).unwrap().done {}
    let rec = env.recorded_motion().unwrap();
    assert_eq!(rec.skeleton().len(), m.skeleton().len());
    // Compare with the input resampled at the recording's times.
    let mut pose = vec![motion::glam::DQuat::IDENTITY; m.joints()];
    let (mut ang, mut n, mut root_err) = (0.0, 0, 0.0f64);
    for f in 0..rec.frames() {
        let root = physics::reference::sample(&m, f as f64 / rec.fps(), &mut pose);
        root_err = root_err.max((rec.root_translation()[f] - root).length());

        for (j, q) in pose.iter().enumerate() {
            if let JointMapping::Body(_) = env.spec().joint_map[j] {
                ang += motion::rotation::angle_between(rec.rotation(f, j), *q);
                n += 1;
            }
        }
    }
    let mean = ang / n as f64;
    println!(
        "kick output vs input: mean driver angle {mean:.3} rad, max root distance {root_err:.3} m"
    );
    assert!(mean > 0.005 && mean < 0.15, "{mean}");
    // With action 0 the stance knee gives a little under the load and the PD
    // residual (200 N/m) only partly holds the root: ~0.3 m by the end of the
    // kick. Closing that gap is the policy's job.
    assert!(root_err < 0.5, "{root_err}");
}

#[test]
fn foot_calibration_lays_the_soles_flat_in_stance() {
    if absent() {
        return;
    }
    let kick = hdm05("HDM_bd_kickLFront1Reps_001_120.amc");
    let mut spec =
        physics::CharacterSpec::build(kick.skeleton().clone(), &Default::default()).unwrap();
    let before = spec.clone();
    let feet = spec.calibrate_feet(&kick);
    assert_eq!(
        feet.len(),
        2,
        "both feet are planted somewhere in a kick: {feet:?}"
    );
    // The sole's up axis, in world frame, at the first frame (both feet planted).
    let x = kick.world_transforms(0);
    let tilt = |s: &physics::CharacterSpec, b: usize| {
        let physics::Shape::Box { rotation, .. } = s.bodies[b].shape else {
            panic!("feet are boxes")
        };
        let q = x[s.bodies[b].driver].rotation.as_quat() * rotation;
        (q * glam::Vec3::Y).angle_between(glam::Vec3::Y)
    };
    for f in &feet {
        assert!(
            f.stance_frames >= 3 && f.tilt_rad > 0.01 && f.tilt_rad < std::f32::consts::PI,
            "{f:?}"
        );
        let (was, now) = (tilt(&before, f.body), tilt(&spec, f.body));
        assert!(now < 0.2 && now < was, "sole tilt {was} -> {now} rad");
    }
}
