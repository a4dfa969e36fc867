//! Character, environment and honesty tests on the humanoid built in code.

use physics::fixtures::{cmu_humanoid, sway};
use physics::{
    CharacterOptions, CharacterSpec, Config, ImitationEnv, JointMapping, OutputFrame, Role, Side,
};

#[test]
fn character_of_the_cmu_style_skeleton() {
    let sk = cmu_humanoid();
    let spec = CharacterSpec::build(sk.clone(), &CharacterOptions::default()).unwrap();
    for line in spec.mapping_report() {
        println!(
            "{:14} -> {}{}",
            line.file_joint,
            line.body,
            if line.merged { " (merged)" } else { "" }
        );
    }
    for b in &spec.bodies {
        println!(
            "{:14} {:?} mass {:.2} shape {:?}",
            b.name, b.parent, b.mass, b.shape
        );
    }
    println!("no collision {:?}", spec.no_collision);
    assert_eq!(spec.bodies.len(), 16);
    assert!((spec.total_mass - 45.0).abs() < 1e-3);
    let driver = |name: &str| match spec.joint_map[sk.find(name).unwrap()] {
        JointMapping::Body(b) => Some(spec.bodies[b].role),
        JointMapping::MergedInto(_) => None,
    };
    assert_eq!(driver("Hips"), Some(Role::Pelvis));
    assert_eq!(driver("LeftHip"), Some(Role::UpperLeg(Side::Left)));
    assert_eq!(driver("RightKnee"), Some(Role::LowerLeg(Side::Right)));
    assert_eq!(driver("LeftAnkle"), Some(Role::Foot(Side::Left)));
    assert_eq!(driver("LeftShoulder"), Some(Role::UpperArm(Side::Left)));
    assert_eq!(driver("RightElbow"), Some(Role::ForeArm(Side::Right)));
    assert_eq!(driver("lhand"), Some(Role::Hand(Side::Left)));
    assert_eq!(driver("lowerback"), Some(Role::Spine));
    assert_eq!(driver("Chest"), Some(Role::Chest));
    assert_eq!(driver("lowerneck"), Some(Role::Neck));
    for merged in [
        "LHipJoint",
        "LeftToe",
        "Chest2",
        "LeftCollar",
        "LFingers",
        "RThumb",
        "Head",
    ] {
        assert_eq!(driver(merged), None, "{merged} should be merged");
    }
}

#[test]
fn standing_sway_is_tracked_with_action_zero() {
    let motion = sway(cmu_humanoid(), 3.0, 120.0);
    let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
    let action = vec![0.0; env.act_dim()];
    let mut err = 0.0;
    let mut steps = 0;
    loop {
        let r = env.step(&action).unwrap();
        err += env.joint_error();
        steps += 1;
        assert!(!r.info.fell(), "fell at frame {}", r.info.frame);
        if r.done {
            // The clip ran out: a truncation, not a failure.
            assert!(r.truncated && !r.terminated);
            assert_eq!(steps, env.episode_len());
            break;
        }
    }
    println!("mean joint error {} over {steps} steps", err / steps as f32);
    assert!(err / (steps as f32) < 0.1);
}

#[test]
fn reward_is_one_at_the_reference_and_falls_with_pose_error() {
    let motion = sway(cmu_humanoid(), 2.0, 120.0);
    let env = ImitationEnv::new(&motion, &Config::default()).unwrap();
    // Right after a reset the simulated state is the reference state.
    let r0 = env.imitation_reward();
    assert!(r0 > 0.97, "reward at the reference {r0}");
    // Bend the elbows away from the reference: the reward must drop, and more for larger errors.
    let mut errs = Vec::new();
    for angle in [0.3f32, 0.8] {
        let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
        let mut states = env.body_states().to_vec();
        for (b, body) in env.spec().bodies.iter().enumerate() {
            if matches!(body.role, Role::ForeArm(_) | Role::LowerLeg(_)) {
                states[b].rot *= glam::Quat::from_rotation_y(angle);
            }
        }
        env.set_state_for_test(&states);
        errs.push(env.imitation_reward());
    }
    assert!(errs[0] < r0 - 0.01 && errs[1] < errs[0], "{r0} {errs:?}");
}

#[test]
fn same_seed_same_rollout() {
    let motion = sway(cmu_humanoid(), 2.0, 120.0);
    let run = |seed: u64| {
        let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
        let mut obs = env.reset_seeded(seed).to_vec();
        let n = env.act_dim();
        let mut rewards = Vec::new();
        for k in 0..20 {
            let action: Vec<f32> = (0..n).map(|i| 0.05 * ((i * 7 + k) as f32).sin()).collect();
            let r = env.step(&action).unwrap();
            rewards.push(r.reward);
            obs.extend_from_slice(env.obs());
            if r.done {
                break;
            }
        }
        (obs, rewards)
    };
    let a = run(7);
    let b = run(7);
    assert_eq!(a, b);
    let c = run(8);
    assert_ne!(a.0, c.0);
}

#[test]
fn recorded_motion_is_the_simulation_not_the_reference() {
    let motion = sway(cmu_humanoid(), 2.0, 120.0);
    let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
    let action = vec![0.0; env.act_dim()];
    while !env.step(&action).unwrap().done {}
    let rec = env.recorded_motion().unwrap();
    assert_eq!(rec.frames(), env.reference().len());
    let sk = rec.skeleton().clone();
    let (mut diff, mut count) = (0.0, 0);
    let mut identical = 0;
    for f in 0..rec.frames() {
        let ref_pose = &env.reference().frames[f].locals;
        for (j, ref_rot) in ref_pose.iter().enumerate() {
            if let JointMapping::Body(_) = env.spec().joint_map[j] {
                let a = motion::rotation::angle_between(rec.rotation(f, j), *ref_rot);
                diff += a;
                count += 1;
                if a < 1e-6 {
                    identical += 1;
                }
            }
        }
    }
    let mean = diff / count as f64;
    println!("mean driver rotation difference {mean}, identical {identical} of {count}");
    // Close to the reference, but not a copy of it.
    assert!(mean < 0.1, "{mean}");
    assert!(
        identical < count / 10,
        "{identical} of {count} rotations copied"
    );
    // Merged joints keep the reference's local rotation.
    let toe = sk.find("LeftToe").unwrap();
    assert!(
        motion::rotation::angle_between(
            rec.rotation(5, toe),
            env.reference().frames[5].locals[toe]
        ) < 1e-6
    );
    // Root follows the simulated pelvis.
    let pelvis = env.body_states()[0].pos.as_dvec3() + glam::DVec3::Y * env.output_floor();
    assert!((rec.root_translation()[rec.frames() - 1] - pelvis).length() < 1e-4);
}

#[test]
fn rejects_wrong_action_sizes_and_bad_steps() {
    let motion = sway(cmu_humanoid(), 1.0, 120.0);
    let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
    assert!(env.step(&[0.0; 3]).is_err());
    let mut cfg = Config::default();
    cfg.sim.dt = 1.0 / 250.0;
    assert!(ImitationEnv::new(&motion, &cfg).is_err());
    let cfg = Config {
        residual: physics::Residual::Learned,
        ..Default::default()
    };
    let env = ImitationEnv::new(&motion, &cfg).unwrap();
    assert_eq!(env.act_dim(), 3 * 15 + 6);
    assert_eq!(env.obs_dim(), 2 + 15 * 16);
}

#[test]
fn learned_residual_applies_the_scaled_action_and_env_is_send() {
    fn assert_send<T: Send>() {}
    assert_send::<ImitationEnv>();
    let motion = sway(cmu_humanoid(), 1.0, 120.0);
    let cfg = Config {
        residual: physics::Residual::Learned,
        sole_reward_weight: 0.0,
        ..Default::default()
    };
    let mut env = ImitationEnv::new(&motion, &cfg).unwrap();
    let mut action = vec![0.0; env.act_dim()];
    let n = action.len();
    action[n - 6] = 0.3;
    action[n - 5] = 0.4;
    let r = env.step(&action).unwrap();
    assert_eq!(
        r.reward, r.info.paper_reward,
        "MotionAug's reward without the sole term"
    );
    assert!(
        (r.info.residual_force - 50.0).abs() < 1e-3,
        "{}",
        r.info.residual_force
    );
    assert_eq!(r.info.residual_torque, 0.0);
    // r_res = exp(-0.01 * 50) enters the reward with weight 0.1.
    assert!((r.reward - (0.9 * r.r_imit + 0.1 * (-0.5f32).exp())).abs() < 1e-5);

    // With the sole term (weight w) the training reward is
    // (0.9 - w) r_imit + 0.1 r_res + w r_sole, the paper's reward unchanged.
    let w = 0.2;
    let mut env = ImitationEnv::new(
        &motion,
        &Config {
            sole_reward_weight: w,
            ..cfg
        },
    )
    .unwrap();
    let s = env.step(&action).unwrap();
    assert!((s.info.paper_reward - r.info.paper_reward).abs() < 1e-6);
    let r_sole = (s.reward - s.info.paper_reward) / w + s.r_imit;
    assert!((-1e-4..=1.0 + 1e-4).contains(&r_sole), "r_sole {r_sole}");
}

#[test]
fn masses_scale_with_the_requested_total() {
    let opts = CharacterOptions {
        total_mass_kg: Some(70.0),
        ..Default::default()
    };
    let heavy = CharacterSpec::build(cmu_humanoid(), &opts).unwrap();
    let light = CharacterSpec::build(cmu_humanoid(), &CharacterOptions::default()).unwrap();
    assert!((heavy.total_mass - 70.0).abs() < 1e-3);
    let ratio = heavy.bodies[1].kp / light.bodies[1].kp;
    assert!((ratio - 70.0 / 45.0).abs() < 1e-4);
}

#[test]
fn roles_come_from_geometry_when_names_say_nothing() {
    let sk = cmu_humanoid();
    let mut joints = sk.joints().to_vec();
    for (i, j) in joints.iter_mut().enumerate() {
        j.name = format!("j{i}");
    }
    let anon = std::sync::Arc::new(motion::Skeleton::new(joints, 1.0).unwrap());
    let named = CharacterSpec::build(sk.clone(), &CharacterOptions::default()).unwrap();
    let spec = CharacterSpec::build(anon, &CharacterOptions::default()).unwrap();
    let roles = |s: &CharacterSpec| {
        s.bodies
            .iter()
            .map(|b| (b.driver, b.role))
            .collect::<Vec<_>>()
    };
    assert_eq!(roles(&spec), roles(&named));
    assert_eq!(spec.joint_map, named.joint_map);
    let left_hip = sk.find("LeftHip").unwrap();
    assert!(
        spec.bodies
            .iter()
            .any(|b| b.driver == left_hip && b.role == Role::UpperLeg(Side::Left))
    );
}

/// Forward kinematics of the recorded motion puts every driver joint where
/// the simulated body is, also when the file has a root above the pelvis.
#[test]
fn recording_matches_the_simulated_bodies_with_an_extra_root() {
    let base = cmu_humanoid();
    let h = physics::fixtures::standing_root_height(&base);
    let mut joints = vec![motion::Joint {
        name: "Reference".into(),
        parent: None,
        offset: glam::DVec3::ZERO,
        channels: vec![],
        end_site: None,
        limits: None,
    }];
    for j in base.joints() {
        let mut j = j.clone();
        j.parent = Some(j.parent.map_or(0, |p| p + 1));
        if j.name == "Hips" {
            j.offset = glam::DVec3::new(0.0, h, 0.0);
        }
        joints.push(j);
    }
    let sk = std::sync::Arc::new(motion::Skeleton::new(joints, 1.0).unwrap());
    let src = sway(base, 1.0, 120.0);
    let n = sk.len();
    let mut rots = Vec::new();
    for f in 0..src.frames() {
        rots.push(glam::DQuat::from_rotation_y(0.1));
        rots.extend_from_slice(src.pose(f));
    }
    let m = motion::Motion::new(
        sk.clone(),
        120.0,
        vec![glam::DVec3::new(0.3, 0.0, 0.2); src.frames()],
        rots,
    )
    .unwrap();
    let mut env = ImitationEnv::new(&m, &Config::default()).unwrap();
    assert_eq!(env.spec().bodies[0].driver, sk.find("Hips").unwrap());
    let action = vec![0.0; env.act_dim()];
    for _ in 0..10 {
        env.step(&action).unwrap();
    }
    let rec = env.recorded_motion().unwrap();
    let world = rec.world_transforms(rec.frames() - 1);
    let floor = glam::DVec3::Y * env.output_floor();
    for (b, body) in env.spec().bodies.iter().enumerate() {
        let s = env.body_states()[b];
        let d = (world[body.driver].translation - (s.pos.as_dvec3() + floor)).length();
        let a = motion::rotation::angle_between(world[body.driver].rotation, s.rot.as_dquat());
        // Rotations are copied exactly; positions follow from the file's bone
        // lengths, so they differ by the joints' constraint drift (sub-mm).
        assert!(d < 5e-3 && a < 1e-4, "{}: {d} m {a} rad", body.name);
    }
    assert_eq!(rec.joints(), n);
}

/// A clip that sinks 5 cm into y = 0 is simulated standing on the floor; the
/// recorded motion stands on y = 0 (default) or, on request, keeps the clip's
/// own height.
#[test]
fn recorded_motion_stands_on_y0_whatever_the_clip_height() {
    let motion = sway(cmu_humanoid(), 0.5, 120.0);
    let mut sunk = motion.clone();
    for p in sunk.root_translation_mut() {
        p.y -= 0.05;
    }
    let record = |m: &motion::Motion, output_frame| {
        let config = Config {
            output_frame,
            ..Config::default()
        };
        let mut env = ImitationEnv::new(m, &config).unwrap();
        let action = vec![0.0; env.act_dim()];
        while !env.step(&action).unwrap().done {}
        env.recorded_motion().unwrap().root_translation().to_vec()
    };
    let lowest = |m: &motion::Motion| {
        (0..m.frames())
            .flat_map(|f| m.world_transforms(f).into_iter().map(|t| t.translation.y))
            .fold(f64::INFINITY, f64::min)
    };
    assert!(lowest(&sunk) < lowest(&motion) - 0.049);
    let (a, b) = (
        record(&motion, OutputFrame::Ground),
        record(&sunk, OutputFrame::Ground),
    );
    let (c, d) = (
        record(&motion, OutputFrame::Clip),
        record(&sunk, OutputFrame::Clip),
    );
    let max_dy = |x: &[glam::DVec3], y: &[glam::DVec3]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p.y - q.y).abs())
            .fold(0.0, f64::max)
    };
    // The same simulation either way (the reference is put on the floor first).
    assert!(max_dy(&a, &b) < 1e-3, "{}", max_dy(&a, &b));
    // In the clip's frame the sunk clip's output is 5 cm lower.
    for (p, q) in c.iter().zip(&d) {
        assert!((p.y - q.y - 0.05).abs() < 1e-3, "{} {}", p.y, q.y);
    }
}

/// The PD-residual force scales with the residual scale: none at 0, half the
/// force at 0.5 from the same state; out-of-range scales are clamped.
#[test]
fn residual_scale_scales_the_root_force() {
    let motion = sway(cmu_humanoid(), 1.0, 120.0);
    let force = |scale: f32| {
        let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
        env.set_residual_scale(scale);
        let action = vec![0.0; env.act_dim()];
        let mut steps = Vec::new();
        for _ in 0..5 {
            steps.push(env.step(&action).unwrap().info.residual_force);
        }
        steps
    };
    let (full, half, none) = (force(1.0), force(0.5), force(0.0));
    assert!(none.iter().all(|&f| f == 0.0), "{none:?}");
    // The first step starts from the same state (the reference's), so its
    // force halves exactly; later states differ with the force applied.
    assert!(full[1] > 0.0, "{full:?}");
    assert!(
        (half[0] - 0.5 * full[0]).abs() <= 1e-4 * full[0].max(1.0),
        "{half:?} {full:?}"
    );
    let mut env = ImitationEnv::new(&motion, &Config::default()).unwrap();
    env.set_residual_scale(7.0);
    assert_eq!(env.residual_scale(), 1.0);
    env.set_residual_scale(f32::NAN);
    assert_eq!(env.residual_scale(), 1.0);
}

#[test]
fn a_tracker_sees_the_upcoming_reference_frames_not_the_phase() {
    let motion = sway(cmu_humanoid(), 2.0, 120.0);
    let plain = ImitationEnv::new(&motion, &Config::default()).unwrap();
    let config = Config {
        tracker_frames: 2,
        ..Config::default()
    };
    let mut env = ImitationEnv::new(&motion, &config).unwrap();
    let n = env.spec().bodies.len();
    assert_eq!(plain.obs_dim(), 2 + 15 * n);
    assert_eq!(env.obs_dim(), plain.obs_dim() + 2 * 9 * n);

    env.reset(0.5);
    let k = env.frame();
    assert!(k > 0);
    let obs = env.obs().to_vec();
    assert_eq!(obs[0], 0.0, "no phase for a tracker");
    let root = env.body_states()[0];
    for ahead in 1..=2 {
        let start = 2 + 15 * n + (ahead - 1) * 9 * n;
        let reference = &env.reference().frames[k + ahead].bodies;
        for (b, r) in reference.iter().enumerate() {
            let block = &obs[start + 9 * b..start + 9 * b + 9];
            // Position relative to the simulated root, turned to its heading:
            // the distance is kept, and the height difference too.
            let d = r.pos - root.pos;
            let p = glam::Vec3::new(block[0], block[1], block[2]);
            assert!(
                (p.length() - d.length()).abs() < 1e-4,
                "body {b} at +{ahead}"
            );
            assert!((p.y - d.y).abs() < 1e-4);
            // Orientation as two unit columns.
            let c0 = glam::Vec3::new(block[3], block[4], block[5]);
            let c1 = glam::Vec3::new(block[6], block[7], block[8]);
            assert!((c0.length() - 1.0).abs() < 1e-4 && (c1.length() - 1.0).abs() < 1e-4);
            assert!(c0.dot(c1).abs() < 1e-4);
        }
    }
    // The frames differ as the reference moves on: the sway is not static.
    let step = env.step(&vec![0.0; env.act_dim()]).unwrap();
    assert!(!step.done);
    assert_ne!(env.obs()[2 + 15 * n..], obs[2 + 15 * n..]);
}

/// Translation tracks (a file that animates a joint's offset) drive the
/// reference the character imitates: a stretching shin moves the foot body.
#[test]
fn the_reference_follows_translation_tracks() {
    use physics::reference::Reference;
    let motion = sway(cmu_humanoid(), 1.0, 120.0);
    let sk = motion.skeleton().clone();
    let spec = CharacterSpec::build(sk.clone(), &CharacterOptions::default()).unwrap();
    let ankle = sk.find("LeftAnkle").unwrap();
    let rest = sk.joint(ankle).offset;
    let mut tracks = vec![None; motion.joints()];
    tracks[ankle] = Some(
        (0..motion.frames())
            .map(|f| rest * (1.0 + f as f64 / 1200.0))
            .collect(),
    );
    let stretched = motion.clone().with_tracks(tracks).unwrap();
    let (a, b) = (
        Reference::new(&motion, &spec, 30.0),
        Reference::new(&stretched, &spec, 30.0),
    );
    let foot = match spec.joint_map[ankle] {
        JointMapping::Body(b) => b,
        JointMapping::MergedInto(_) => panic!("the ankle drives the foot"),
    };
    // The shin (lower leg body to foot body) is 1 + f/1200 times its rest
    // length at clip frame f; control frame k (30 Hz) is clip frame 4 k.
    let shin = |r: &Reference, k: usize| {
        let leg = spec.bodies[foot].parent.unwrap();
        (r.frames[k].bodies[foot].pos - r.frames[k].bodies[leg].pos).length() as f64
    };
    let k = a.frames.len() - 1;
    let stretch = shin(&b, k) - shin(&a, k);
    let expect = rest.length() * (4 * k) as f64 / 1200.0;
    assert!(
        (stretch - expect).abs() < 1e-5,
        "stretch {stretch}, expected {expect}"
    );
    assert!((shin(&b, 0) - shin(&a, 0)).abs() < 1e-6);
}

/// Without the root force and with every joint bent far off its target the
/// character collapses; the step that ends in the fall names a body that is
/// not a foot, and pays the fall penalty in the training reward and nothing
/// in the paper's.
#[test]
fn a_fall_pays_the_fall_penalty_in_the_training_reward_only() {
    let motion = sway(cmu_humanoid(), 3.0, 120.0);
    let fall = |penalty: f32| {
        let config = Config {
            residual: physics::Residual::None,
            fall_penalty: penalty,
            ..Config::default()
        };
        let mut env = ImitationEnv::new(&motion, &config).unwrap();
        let action = vec![1.5; env.act_dim()];
        loop {
            let r = env.step(&action).unwrap();
            if r.done {
                return (r, env.spec().feet.clone());
            }
        }
    };
    for penalty in [0.0, 5.0] {
        let (r, feet) = fall(penalty);
        assert!(r.terminated && r.info.fell(), "{r:?}");
        let body = r.info.fallen_body.expect("the fall names a body");
        assert!(!feet.contains(&body), "a foot is not a fall: {r:?}");
        assert_eq!(r.reward, -penalty);
        assert_eq!(r.info.paper_reward, 0.0);
    }
}
