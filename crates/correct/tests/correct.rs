//! A short correction job end to end on the bundled kick clip: outputs,
//! report fields, honesty of the corrected motion, and resume.

use std::path::Path;

use correct::{CorrectConfig, Report, correct};
use motion::{LoadOptions, Motion, load};

fn kick() -> Motion {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    load(
        data.join("HDM_bd_kickLFront1Reps_001_120.amc"),
        &LoadOptions {
            skeleton: Some(data.join("HDM_bd.asf")),
            ..Default::default()
        },
    )
    .unwrap()
}

fn tiny(max_iterations: u64) -> CorrectConfig {
    let mut config = CorrectConfig {
        envs: 2,
        max_iterations: Some(max_iterations),
        target_r_norm: None,
        checkpoint_every_s: 0.0,
        // Off unless a test turns it on.
        skate_scale_when_skating_m_s: 0.0,
        ..CorrectConfig::default()
    };
    config.ppo.policy.hidden = vec![32, 32];
    config.ppo.value.hidden = vec![32, 32];
    config.ppo.samples_per_iteration = 128;
    config.ppo.minibatch_size = 64;
    config.ppo.epochs = 2;
    config
}

#[test]
fn short_job_writes_honest_outputs_and_resumes() {
    let clip = kick();
    let dir = tempfile::tempdir().unwrap();
    let out = correct(&clip, "kick", &tiny(2), dir.path(), false, |_| {}).unwrap();

    for file in ["corrected.bvh", "corrected.npz", "report.json", "curve.svg"] {
        assert!(dir.path().join(file).exists(), "{file} missing");
    }
    let report: Report =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report.iterations, 2);
    assert!(report.samples >= 256);
    assert!((0.0..=1.0).contains(&report.r_norm));
    assert!(report.residual_force_ratio > 0.0);
    assert_eq!(
        report.curve.len(),
        3,
        "the action-0 point and one per iteration"
    );
    assert_eq!(report.curve[0], [0.0, 0.0, report.r_norm_action0]);
    // Accepted exactly when every criterion passed, each judged on the
    // figures the report gives.
    let names: Vec<&str> = report.criteria.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "no_fall",
            "mean_reward",
            "residual_force",
            "foot_skating",
            "soles_flat"
        ]
    );
    assert_eq!(
        report.accepted,
        report.criteria.iter().all(|c| c.passed),
        "{:?}",
        report.criteria
    );
    assert_eq!(
        report.rejected_because.len(),
        report.criteria.iter().filter(|c| !c.passed).count()
    );
    let by = |n: &str| report.criteria.iter().find(|c| c.name == n).unwrap();
    assert_eq!(by("mean_reward").value, report.mean_reward);
    assert_eq!(by("residual_force").value, report.residual_force_ratio);
    assert_eq!(
        by("residual_force").passed,
        report.residual_force_ratio <= 0.1
    );
    assert_eq!(
        by("foot_skating").value,
        report.plausibility_after.foot_skating_m_s
    );
    assert!(by("foot_skating").limit <= report.plausibility_before.foot_skating_m_s);

    // Honest: the corrected clip is the simulated character, not the reference.
    let corrected =
        motion::load(dir.path().join("corrected.bvh"), &LoadOptions::default()).unwrap();
    assert_eq!(corrected.fps(), 30.0);
    let reference = motion::resample::resample(&clip, 30.0).unwrap();
    let frames = corrected.frames().min(reference.frames());
    let mut diff = 0.0;
    for t in 0..frames {
        let (a, b) = (corrected.world_positions(t), reference.world_positions(t));
        diff += a
            .iter()
            .zip(&b)
            .map(|(p, q)| (*p - *q).length())
            .sum::<f64>()
            / a.len() as f64;
    }
    let mean_diff = diff / frames as f64;
    assert!(
        mean_diff > 1e-3,
        "corrected clip equals the reference ({mean_diff} m)"
    );
    assert!(
        mean_diff < 0.5,
        "corrected clip is far from the reference ({mean_diff} m)"
    );
    assert_eq!(out.motion.frames(), corrected.frames());

    // A second run without --resume refuses to overwrite the checkpoints...
    assert!(correct(&clip, "kick", &tiny(3), dir.path(), false, |_| {}).is_err());
    // ...and with it, continues where the first stopped.
    let resumed = correct(&clip, "kick", &tiny(3), dir.path(), true, |_| {}).unwrap();
    assert_eq!(resumed.report.iterations, 3);
    assert!(resumed.report.samples > report.samples);
    assert_eq!(resumed.report.curve[..3], report.curve[..]);
}

/// Limits every criterion but skating (and falls) passes, so that skating is
/// the one criterion left to fail.
fn relax_all_but_skating(config: &mut CorrectConfig) {
    config.acceptance.min_mean_reward = 0.0;
    config.acceptance.max_residual_force_ratio = 100.0;
    config.acceptance.min_flat_fraction = 0.0;
}

/// The sliding term for clips that skate also switches on during training:
/// a rollout that reaches the R_norm target but skates turns it on for the
/// rest of the job.
#[test]
fn a_rollout_that_skates_during_training_switches_the_sliding_term_on() {
    let run = |scale: f32| {
        let mut config = tiny(2);
        config.target_r_norm = Some(0.0);
        config.acceptance.max_foot_skating_m_s = 0.0;
        relax_all_but_skating(&mut config);
        config.skate_scale_when_skating_m_s = scale;
        let dir = tempfile::tempdir().unwrap();
        correct(&kick(), "kick", &config, dir.path(), false, |_| {})
            .unwrap()
            .report
    };
    let (on, off) = (run(0.1), run(0.0));
    assert!(
        (on.skate_scale_m_s - 0.1).abs() < 1e-6,
        "{}",
        on.skate_scale_m_s
    );
    assert_eq!(off.skate_scale_m_s, 0.0);
    assert_eq!(on.iterations, 2, "it skates, so it is not accepted early");
    assert_ne!(on.r_norm, off.r_norm, "the term changed nothing");
}

/// The untrained tracker (action 0) keeps the kick up only with the root
/// force's help: the acceptance names that hand of god, whatever its reward.
#[test]
fn a_clip_held_up_by_the_root_force_is_rejected() {
    let config = CorrectConfig::default();
    let clip = kick();
    let mut env = physics::ImitationEnv::new(&clip, &config.physics).unwrap();
    let rollout = correct::deterministic_rollout(&mut env, |_, a| {
        a.fill(0.0);
        Ok(())
    })
    .unwrap();
    let before = motion::metrics::plausibility(&clip);
    let after = motion::metrics::plausibility(&rollout.motion);
    let criteria = correct::acceptance::judge(&rollout, &before, &after, &config.acceptance);
    let residual = criteria
        .iter()
        .find(|c| c.name == "residual_force")
        .unwrap();
    assert!(
        rollout.residual_force_ratio() > 0.1 && !residual.passed,
        "{criteria:?}"
    );
    assert!(!correct::acceptance::all_passed(&criteria));
    // Its planted feet were judged: the kick stands on one foot throughout.
    let soles = correct::acceptance::SoleStats::of(&rollout.feet, &config.acceptance);
    assert!(soles.planted_frames > 10, "{soles:?}");
}

/// Without the root force and with every joint bent far off its target the
/// kick collapses: the judgement says at which step of how many it fell and
/// what touched the ground, and the output holds the frames simulated up to
/// the fall (so `frames` in a report is not the clip's length).
#[test]
fn a_fall_is_judged_with_its_step_and_the_body_that_touched() {
    let mut config = CorrectConfig::default();
    config.physics.residual = physics::Residual::None;
    let clip = kick();
    let mut env = physics::ImitationEnv::new(&clip, &config.physics).unwrap();
    let feet: Vec<String> = env
        .spec()
        .feet
        .iter()
        .map(|&b| env.spec().bodies[b].name.clone())
        .collect();
    let rollout = correct::deterministic_rollout(&mut env, |_, a| {
        a.fill(1.5);
        Ok(())
    })
    .unwrap();
    let t = rollout.fell_at.expect("the bent character falls");
    let body = rollout.fell_body.clone().expect("the fall names a body");
    assert!(!feet.contains(&body), "{body} is a foot");
    assert!(
        t + 1 < rollout.clip_steps,
        "fell at {t} of {}",
        rollout.clip_steps
    );
    assert_eq!(rollout.motion.frames(), t + 2);
    let before = motion::metrics::plausibility(&clip);
    let after = motion::metrics::plausibility(&rollout.motion);
    let criteria = correct::acceptance::judge(&rollout, &before, &after, &config.acceptance);
    let no_fall = criteria.iter().find(|c| c.name == "no_fall").unwrap();
    assert!(!no_fall.passed);
    let said = format!(
        "fell at control step {t} of {} ({body} touched the ground)",
        rollout.clip_steps
    );
    assert!(no_fall.meaning.contains(&said), "{no_fall:?}");
}

/// Feet built in the frame of the standing foot stand on their soles: with
/// the untrained tracker on the bundled kick, the rest-pose boxes stand on a
/// corner (no planted frame flat) and the calibrated ones mostly flat.
#[test]
fn calibrated_feet_stand_on_their_soles() {
    let clip = kick();
    let flat = |calibrate: bool| {
        let mut config = CorrectConfig::default();
        config.physics.character.calibrate_feet = calibrate;
        let mut env = physics::ImitationEnv::new(&clip, &config.physics).unwrap();
        let rollout = correct::deterministic_rollout(&mut env, |_, a| {
            a.fill(0.0);
            Ok(())
        })
        .unwrap();
        correct::acceptance::SoleStats::of(&rollout.feet, &config.acceptance)
    };
    let (rest, calibrated) = (flat(false), flat(true));
    assert!(rest.flat_fraction() < 0.1, "{rest:?}");
    assert!(calibrated.flat_fraction() > 0.5, "{calibrated:?}");
}

#[test]
fn bad_settings_are_rejected_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = tiny(1);
    config.envs = 0;
    assert!(correct(&kick(), "kick", &config, dir.path(), false, |_| {}).is_err());
    assert!(!dir.path().join("checkpoints").exists());
}

#[test]
fn a_stop_request_ends_training_with_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut config = tiny(1000);
    config.stop = Some(stop.clone());
    let mut iterations = 0;
    let result = correct(&kick(), "kick", &config, dir.path(), false, |_| {
        iterations += 1;
        if iterations == 2 {
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    });
    assert!(
        matches!(result, Err(correct::CorrectError::Stopped)),
        "{:?}",
        result.err()
    );
    assert_eq!(iterations, 2, "training went on after the stop request");
    assert!(
        ppo::latest_checkpoint(&dir.path().join("checkpoints"))
            .unwrap()
            .is_some()
    );
    assert!(
        !dir.path().join("report.json").exists(),
        "a stopped job reports nothing"
    );
}

fn jog() -> Motion {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    load(
        data.join("HDM_bd_jogLeftCircle4StepsRstart_001_120.amc"),
        &LoadOptions {
            skeleton: Some(data.join("HDM_bd.asf")),
            ..Default::default()
        },
    )
    .unwrap()
}

#[test]
fn a_class_tracker_judges_every_clip_and_warm_starts_a_clip() {
    let clips = vec![("kick".to_string(), kick()), ("jog".to_string(), jog())];
    let dir = tempfile::tempdir().unwrap();
    let class_dir = dir.path().join("tracker");
    let mut config = correct::ClassConfig {
        correct: tiny(3),
        judge_every: 2,
        keep_tolerance: 0.05,
    };
    config.correct.physics.tracker_frames = 2;

    // A tracker must see the clip ahead.
    let mut blind = config.clone();
    blind.correct.physics.tracker_frames = 0;
    assert!(correct::train_class(&clips, &blind, &class_dir, false, |_| {}).is_err());

    let mut judged = Vec::new();
    let report = correct::train_class(&clips, &config, &class_dir, false, |p| {
        judged.extend(p.accepted.map(|a| (p.iteration, a)));
    })
    .unwrap();
    assert_eq!(report.clips, 2);
    assert_eq!(report.iterations, 3);
    assert_eq!(report.verdicts.len(), 2);
    assert_eq!(judged.len(), 1, "judged at iteration 2: {judged:?}");
    // Judged at iteration 2 and again at the end.
    let its: Vec<u64> = report.curve.iter().map(|p| p.iteration).collect();
    assert_eq!(its, vec![2, 3]);
    // The tracker kept is the latest judged one within one clip (5 % of 2
    // clips, at least one) of the best, and its verdicts are reported.
    let best = report.curve.iter().map(|p| p.accepted).max().unwrap();
    let want = report
        .curve
        .iter()
        .rev()
        .find(|p| p.accepted + 1 >= best)
        .unwrap();
    assert_eq!(report.kept_iteration, want.iteration, "{:?}", report.curve);
    assert_eq!(report.accepted(), want.accepted);
    let mean_r_norm = report.verdicts.iter().map(|v| v.r_norm).sum::<f64>() / 2.0;
    assert!((mean_r_norm - want.mean_r_norm).abs() < 1e-9);
    assert!(
        !class_dir.join("kept").exists(),
        "the kept tracker's scratch folder is removed"
    );
    for v in &report.verdicts {
        assert_eq!(v.accepted, v.rejected_because.is_empty(), "{v:?}");
        assert!((0.0..=1.0).contains(&v.r_norm));
    }
    let read = correct::ClassReport::read(&class_dir.join(correct::class::REPORT_FILE)).unwrap();
    assert_eq!(read.verdicts.len(), 2);
    // The schedule had lowered the gains; the tracker keeps that scale.
    assert!(read.residual_scale < 1.0);

    // A clip's correction from the tracker: its observation, checkpoint and
    // residual scale.
    let warm = report.warm_config(&tiny(1), &class_dir);
    assert_eq!(warm.physics.tracker_frames, 2);
    assert_eq!(
        warm.residual_schedule.start_scale,
        warm.residual_schedule.final_scale
    );
    let out = correct(
        &kick(),
        "kick",
        &warm,
        &dir.path().join("kick"),
        false,
        |_| {},
    )
    .unwrap();
    assert!(out.report.warm_start.is_some());
    assert!((out.report.residual_scale - report.residual_scale).abs() < 1e-6);
    assert_eq!(out.report.skate_scale_m_s, 0.0, "the sliding term is off");

    // The sliding term for clips that skate: on only when skating is the
    // one criterion the tracker's clip fails as is (a cap of 0 m/s fails
    // it, one of 100 m/s that ignores the input passes it; the R_norm
    // target of 1 is not met, so every run fine-tunes); it changes what
    // training learns, and a resumed job keeps it. With another criterion
    // failing too it stays off.
    let sliding = |cap: f64, iterations: u64, name: &str, resume: bool| {
        let mut c = report.warm_config(&tiny(iterations), &class_dir);
        c.target_r_norm = Some(1.0);
        c.acceptance.max_foot_skating_m_s = cap;
        c.acceptance.skating_at_most_input = false;
        relax_all_but_skating(&mut c);
        c.skate_scale_when_skating_m_s = 0.1;
        correct(&kick(), "kick", &c, &dir.path().join(name), resume, |_| {})
            .unwrap()
            .report
    };
    let skates = sliding(0.0, 2, "skates", false);
    let glides = sliding(100.0, 2, "glides", false);
    assert!(
        (skates.skate_scale_m_s - 0.1).abs() < 1e-6,
        "{}",
        skates.skate_scale_m_s
    );
    assert_eq!(glides.skate_scale_m_s, 0.0);
    assert_ne!(skates.r_norm, glides.r_norm, "the term changed nothing");
    sliding(0.0, 1, "resumed", false);
    let resumed = sliding(100.0, 2, "resumed", true);
    assert!(
        (resumed.skate_scale_m_s - 0.1).abs() < 1e-6,
        "resume lost the term"
    );
    assert_eq!(resumed.iterations, 2);
    assert_eq!(resumed.r_norm, skates.r_norm, "resumed without the term");
    let mut strict = report.warm_config(&tiny(1), &class_dir);
    strict.target_r_norm = Some(1.0);
    strict.acceptance.max_foot_skating_m_s = 0.0;
    strict.acceptance.max_residual_force_ratio = 0.0;
    strict.skate_scale_when_skating_m_s = 0.1;
    let both = correct(
        &kick(),
        "kick",
        &strict,
        &dir.path().join("both"),
        false,
        |_| {},
    )
    .unwrap()
    .report;
    assert_eq!(both.skate_scale_m_s, 0.0, "{:?}", both.rejected_because);

    // A per-clip policy (no tracker observation) cannot start from it.
    let mut wrong = warm.clone();
    wrong.physics.tracker_frames = 0;
    assert!(
        correct(
            &kick(),
            "kick",
            &wrong,
            &dir.path().join("wrong"),
            false,
            |_| {}
        )
        .is_err()
    );

    // A tracker of new clips starts from this one: untrained, it judges the
    // same clips exactly as the kept tracker did; a fresh one does not.
    let stage = |warm: bool, name: &str| {
        let mut base = tiny(0);
        base.physics.tracker_frames = 2;
        let correct = if warm {
            report.warm_config(&base, &class_dir)
        } else {
            base
        };
        let config = correct::ClassConfig {
            correct,
            ..config.clone()
        };
        correct::train_class(&clips, &config, &dir.path().join(name), false, |_| {}).unwrap()
    };
    let r_norms =
        |r: &correct::ClassReport| r.verdicts.iter().map(|v| v.r_norm).collect::<Vec<_>>();
    let warmed = stage(true, "warmed");
    assert_eq!(warmed.iterations, 0);
    assert_eq!(r_norms(&warmed), r_norms(&report));
    assert_ne!(r_norms(&stage(false, "fresh")), r_norms(&report));
}

/// The layout with a static root above the travelling Hips (six channels
/// everywhere): the Hips drive the simulated pelvis, so the untrained tracker
/// follows the clip as it does the same walk written with Hips as the root,
/// and the corrected clip is written back in the file's layout.
#[test]
fn a_static_root_above_the_hips_corrects_like_the_plain_layout() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    let layered = load(data.join("static_root_walk.bvh"), &LoadOptions::default()).unwrap();
    assert_eq!(layered.skeleton().base()[0].name, "joint_Root");
    // The same walk without the base (every joint where it was).
    let plain_skeleton = motion::Skeleton::new(
        layered.skeleton().joints().to_vec(),
        layered.skeleton().source_unit_m(),
    )
    .unwrap();
    let plain = Motion::new(
        std::sync::Arc::new(plain_skeleton),
        layered.fps(),
        layered.root_translation().to_vec(),
        layered.rotations().to_vec(),
    )
    .unwrap();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let one = correct(&layered, "layered", &tiny(1), a.path(), false, |_| {}).unwrap();
    let two = correct(&plain, "plain", &tiny(1), b.path(), false, |_| {}).unwrap();
    assert_eq!(one.report.r_norm_action0, two.report.r_norm_action0);
    assert_eq!(one.report.r_norm, two.report.r_norm);
    let text = std::fs::read_to_string(a.path().join("corrected.bvh")).unwrap();
    assert!(
        text.starts_with("HIERARCHY\nROOT joint_Root\n"),
        "{}",
        &text[..80]
    );
    let back = load(a.path().join("corrected.bvh"), &LoadOptions::default()).unwrap();
    assert_eq!(back.skeleton().joint(0).name, "Hips");
    for t in 0..back.frames() {
        for (p, q) in back
            .world_positions(t)
            .iter()
            .zip(one.motion.world_positions(t))
        {
            assert!((*p - q).length() < 1e-5);
        }
    }
}

#[test]
fn the_rollout_threads_do_not_change_a_correction() {
    // A correction's own network sizes and 8 environments: what the table
    // and the service's workers run, on one thread or two.
    let clip = kick();
    let run = |threads: usize, rollout_batch: usize| {
        let mut config = CorrectConfig {
            max_iterations: Some(1),
            target_r_norm: None,
            checkpoint_every_s: 0.0,
            ..CorrectConfig::default()
        };
        config.ppo.samples_per_iteration = 512;
        config.ppo.minibatch_size = 256;
        config.ppo.epochs = 1;
        config.ppo.threads = threads;
        config.ppo.rollout_batch = rollout_batch;
        let dir = tempfile::tempdir().unwrap();
        let out = correct(&clip, "kick", &config, dir.path(), false, |_| {}).unwrap();
        // Everything but wall times: the simulated clip and its scores.
        (out.motion, out.report.r_norm, out.report.mean_reward)
    };
    let one = run(1, 4);
    assert_eq!(one, run(2, 4));
    // The batch shapes the numbers (what one thread gave before batches were
    // fixed: all 8 environments in one batch).
    assert_ne!(one, run(1, 8));
}
