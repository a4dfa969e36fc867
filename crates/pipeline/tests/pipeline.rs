//! The pipeline end to end on the bundled clips: recipe validation, the job
//! graph, and in-process runs with correction, debiasing and the VAE.

use std::path::PathBuf;

use pipeline::{Clip, CorrectStep, Event, JobKind, Options, PolicyKind, Recipe, plan, run};

fn data(name: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/data")).join(name)
}

fn kick() -> Clip {
    let options = motion::io::LoadOptions {
        skeleton: Some(data("HDM_bd.asf")),
        ..Default::default()
    };
    Clip {
        name: "HDM_bd_kickLFront1Reps_001_120".into(),
        source: "kick.amc".into(),
        motion: motion::io::load(data("HDM_bd_kickLFront1Reps_001_120.amc"), &options)
            .expect("bundled clip"),
    }
}

fn quiet(_: Event<'_>) {}

/// The in-process runner's options: results in memory, work in `work`, seed 5.
fn in_process(work: &std::path::Path) -> Options<'_> {
    Options {
        out: None,
        work,
        seed: 5,
        on_event: &quiet,
    }
}

fn recipe_err(text: &str) -> String {
    match Recipe::from_toml_str(text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn recipes_are_validated_with_the_table_and_field_named() {
    let full = Recipe::from_toml_str(
        r#"
        seed = 3
        [[ops]]
        op = "noise"
        copies = 2
        [vae]
        copies = 4
        prior = "normal"
        [interaction]
        copies = 2
        [correct]
        time_budget_s = 30
        residual = "none"
        plant_reference = true
        [debias]
        iterations = 10
        "#,
    )
    .expect("full recipe");
    assert_eq!(full.seed, Some(3));
    assert_eq!(full.vae.as_ref().map(|v| v.copies), Some(4));
    assert_eq!(
        full.correct.as_ref().map(|c| c.residual),
        Some(pipeline::ResidualKind::None)
    );
    // The recipe's choices reach the correction jobs and the class tracker.
    let correct = full.correct.as_ref().expect("[correct]");
    assert!(correct.config(0).physics.plant_reference);
    assert!(correct.tracker_config(0).correct.physics.plant_reference);
    assert!(
        !pipeline::CorrectStep::default()
            .config(0)
            .physics
            .plant_reference
    );
    // JSON with the same structure is the same recipe.
    let json = Recipe::from_value(full.to_value()).expect("round trip");
    assert_eq!(json, full);

    let e = recipe_err("[[ops]]\nop = \"noise\"\n[correct]\ntime_budget = 3\n");
    assert!(e.contains("[correct]") && e.contains("time_budget"), "{e}");
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[debias]\niterations = 3\n");
    assert!(e.contains("[debias]") && e.contains("[correct]"), "{e}");
    let e = recipe_err("[correct]\n");
    assert!(e.contains("makes nothing"), "{e}");
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[corect]\n");
    assert!(e.contains("unknown key `corect`"), "{e}");
    let e = recipe_err("[[ops]]\nop = \"noise\"\nsigma_deg = -1\n");
    assert!(e.contains("ops[0]"), "{e}");
    let e = recipe_err("[interaction]\nscale_min = 0.1\n");
    assert!(
        e.contains("[interaction]") && e.contains("scale_min"),
        "{e}"
    );
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[correct]\naccept_threshold = 2\n");
    assert!(e.contains("accept_threshold"), "{e}");
    for term in ["motion", "contact", "sole", "travel", "balance"] {
        let e = recipe_err(&format!("[vae]\nmixed_{term}_weight = -0.5\n"));
        assert!(
            e.contains("[vae]") && e.contains(&format!("mixed_{term}_weight")),
            "{e}"
        );
    }
    for bad in ["-0.01", "5.0"] {
        let e = recipe_err(&format!("[vae]\nsmooth_s = {bad}\n"));
        assert!(e.contains("[vae]") && e.contains("smooth_s"), "{e}");
    }
}

#[test]
fn example_recipes_parse() {
    let dir = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/recipes"
    ));
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("examples/recipes") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            Recipe::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 4, "{n} recipes");
}

#[test]
fn the_plan_orders_jobs_after_their_inputs() {
    let recipe = Recipe::from_toml_str(
        r#"
        [[ops]]
        op = "mirror"
        [vae]
        copies = 2
        [interaction]
        copies = 1
        [correct]
        [debias]
        "#,
    )
    .expect("recipe");
    let names: Vec<String> = [
        "HDM_bd_kickLFront1Reps_001_120",
        "HDM_bk_kickLFront1Reps_002_120",
        "18_01_shake_A",
        "18_01_shake_B",
    ]
    .map(String::from)
    .to_vec();
    let plan = plan(&recipe, &names, 0);
    let position = |key: &str| {
        plan.jobs
            .iter()
            .position(|j| j.key == key)
            .unwrap_or_else(|| panic!("no job {key}"))
    };
    for (i, job) in plan.jobs.iter().enumerate() {
        for dep in &job.deps {
            assert!(
                position(dep) < i,
                "{} needs {dep}, which comes later",
                job.key
            );
        }
    }
    // One VAE for the kick class (both actors), none for the single pair clips.
    let vae: Vec<_> = plan
        .jobs
        .iter()
        .filter(|j| matches!(j.kind, JobKind::Vae { .. }))
        .collect();
    assert_eq!(vae.len(), 1, "{vae:?}");
    assert_eq!(
        vae[0].outputs,
        ["kickLFront1Reps__vae_000", "kickLFront1Reps__vae_001"]
    );
    // The pair is found; its outputs are not simulated (two partners, one world).
    let inter = position("interaction:18_01_shake");
    assert_eq!(plan.jobs[inter].outputs.len(), 2);
    assert!(
        !plan
            .jobs
            .iter()
            .any(|j| j.key == "correct:18_01_shake__interaction_000_A")
    );
    // Variants warm-start from their original's correction; debiasing needs all originals.
    let c = &plan.jobs[position("correct:HDM_bd_kickLFront1Reps_001_120__00_mirror_000")];
    assert!(
        c.deps
            .contains(&"correct_original:HDM_bd_kickLFront1Reps_001_120".to_string())
    );
    // A VAE sample may start from any clip of its class: the best corrected one.
    let v = &plan.jobs[position("correct:kickLFront1Reps__vae_000")];
    let JobKind::Correct { sources, .. } = &v.kind else {
        panic!("{v:?}")
    };
    let kicks: Vec<&String> = names.iter().filter(|n| n.contains("kick")).collect();
    assert_eq!(sources.iter().collect::<Vec<_>>(), kicks);
    for k in kicks {
        assert!(v.deps.contains(&format!("correct_original:{k}")), "{v:?}");
    }
    let train = &plan.jobs[position("debias_train")];
    assert_eq!(train.deps.len(), names.len());
    let apply = &plan.jobs[position("debias_apply:kickLFront1Reps__vae_001")];
    assert_eq!(
        apply.deps,
        ["correct:kickLFront1Reps__vae_001", "debias_train"]
    );
}

/// The service stores the plan as JSON and runs it as planned: every job
/// round-trips, carries its settings (defaults filled in at planning) and
/// says whether its outputs are final.
#[test]
fn the_plan_is_stored_as_planned_with_its_settings() {
    let recipe = Recipe::from_toml_str(
        r#"
        seed = 9
        [[ops]]
        op = "noise"
        copies = 2
        [[ops]]
        op = "ik"
        preset = "kick"
        [vae]
        copies = 1
        [correct]
        time_budget_s = 12
        [debias]
        iterations = 7
        "#,
    )
    .expect("recipe");
    let names: Vec<String> = [
        "HDM_bd_kickLFront1Reps_001_120",
        "HDM_bk_kickLFront1Reps_002_120",
    ]
    .map(String::from)
    .to_vec();
    let planned = plan(&recipe, &names, 9);
    let json = serde_json::to_string(&planned).expect("plan as JSON");
    let stored: pipeline::Plan = serde_json::from_str(&json).expect("plan from JSON");
    assert_eq!(stored, planned);

    // One synthesis job per clip, with every output of it.
    let synth = planned
        .job("synthesize:HDM_bd_kickLFront1Reps_001_120")
        .expect("synthesize job");
    let JobKind::Synthesize { outputs, ops, .. } = &synth.kind else {
        panic!("{synth:?}")
    };
    assert_eq!(outputs.len(), 3);
    assert_eq!(ops.ops.len(), 2);
    assert_eq!(
        synth.outputs[2],
        "HDM_bd_kickLFront1Reps_001_120__01_ik_000"
    );
    // Settings resolved once: the recipe's values and the defaults it left out.
    for job in &planned.jobs {
        match &job.kind {
            JobKind::Correct { step, .. } | JobKind::CorrectOriginal { step, .. } => {
                assert_eq!(step.time_budget_s, 12.0);
                assert_eq!(step.envs, pipeline::CorrectStep::default().envs);
            }
            JobKind::DebiasTrain { config, .. } => assert_eq!(config.iterations, 7),
            JobKind::Vae { step, op_index, .. } => {
                assert_eq!(step.copies, 1);
                assert_eq!(*op_index, 2, "after the two [[ops]]");
            }
            _ => {}
        }
        // Only debiasing finishes a corrected clip.
        let final_here = matches!(job.kind, JobKind::DebiasApply { .. });
        if !job.outputs.is_empty() {
            assert_eq!(job.finishes, final_here, "{}", job.key);
        }
    }
    // Without [correct], synthesis and the VAE finish their clips.
    let plain = Recipe::from_toml_str("[[ops]]\nop = \"mirror\"\n").expect("recipe");
    assert!(plan(&plain, &names, 0).jobs.iter().all(|j| j.finishes));
}

const CORRECTED: &str = r#"
    seed = 5
    [[ops]]
    op = "noise"
    sigma_deg = 1.0
    copies = 2
    [correct]
    time_budget_s = 1
    target_r_norm = 0.0
    # Plumbing, not physics: one second of training is accepted whatever it did.
    accept_threshold = 0.0
    max_residual_force_ratio = 100.0
    max_foot_skating_m_s = 100.0
    skating_at_most_input = false
    min_sole_flat_fraction = 0.0
    envs = 2
    [debias]
    hidden = [32]
    iterations = 20
"#;

#[test]
fn correction_and_debiasing_run_in_process_and_survive_a_rerun() {
    let recipe = Recipe::from_toml_str(CORRECTED).expect("recipe");
    let clips = [kick()];
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).expect("mkdir");
    let work = out.join("work");
    let options = Options {
        out: Some(&out),
        ..in_process(&work)
    };
    let summary = run(&recipe, &clips, &options).expect("run");
    assert!(summary.failures.is_empty(), "{:?}", summary.failures);
    assert_eq!(summary.manifest.len(), 2);
    for e in &summary.manifest {
        let c = e.correction.as_ref().expect("correction summary");
        assert!(c.accepted, "{c:?}");
        // Trained, or accepted as the original's policy left it (a
        // warm-started policy is judged before any training).
        let report = correct::Report::read(&out.join(c.report.as_ref().expect("report path")))
            .expect("report");
        assert!(
            report.samples > 0 || report.warm_start.is_some(),
            "{report:?}"
        );
        assert_eq!(c.samples, report.samples);
        assert!(e.debiased);
        assert_eq!(e.synth.fps, 30.0, "corrected clips are at the control rate");
        let bvh = out.join(&e.synth.file);
        let m = motion::bvh::read(&bvh, motion::Unit::Auto).expect("output BVH");
        assert_eq!(m.frames(), e.synth.frames);
        assert!(
            work.join("correct")
                .join(e.synth.file.trim_end_matches(".bvh"))
                .join("report.json")
                .is_file()
        );
    }
    assert!(
        work.join("originals/HDM_bd_kickLFront1Reps_001_120/report.json")
            .is_file()
    );
    assert!(work.join("debias/debias.json").is_file());
    let manifest = std::fs::read(out.join("manifest.json")).expect("manifest");

    // A rerun finds every correction finished and writes the same files.
    let corrected = out.join(&summary.manifest[0].synth.file);
    let before = std::fs::read(&corrected).expect("output");
    let started = std::time::Instant::now();
    let again = run(&recipe, &clips, &options).expect("rerun");
    assert!(again.failures.is_empty());
    assert!(
        started.elapsed().as_secs_f64() < 3.0,
        "rerun retrained: {:?}",
        started.elapsed()
    );
    assert!(
        std::fs::read(&corrected).expect("output") == before,
        "output changed"
    );
    assert!(
        std::fs::read(out.join("manifest.json")).expect("manifest") == manifest,
        "manifest changed"
    );
}

#[test]
fn rejected_corrections_are_left_out_unless_kept() {
    let text = CORRECTED
        .replace("accept_threshold = 0.0", "accept_threshold = 1.0")
        .replace("[debias]\n    hidden = [32]\n    iterations = 20\n", "");
    let recipe = Recipe::from_toml_str(&text).expect("recipe");
    let clips = [kick()];
    let work = tempfile::tempdir().expect("tempdir");
    let options = in_process(work.path());
    let summary = run(&recipe, &clips, &options).expect("run");
    assert!(summary.outputs.is_empty());
    assert_eq!(summary.rejected.len(), 2);

    let kept =
        Recipe::from_toml_str(&text.replace("envs = 2", "envs = 2\n    keep_rejected = true"))
            .expect("recipe");
    let summary = run(&kept, &clips, &options).expect("run");
    assert_eq!(
        summary.outputs.len(),
        2,
        "reused corrections, kept despite rejection"
    );
    assert!(
        summary
            .outputs
            .iter()
            .all(|o| o.entry.correction.as_ref().is_some_and(|c| !c.accepted))
    );

    // The original was rejected too: it is no debiasing pair, and with none
    // the debiasing step fails, naming why, and so do the clips waiting for it.
    let debiased = Recipe::from_toml_str(&format!(
        "{}\n[debias]\nhidden = [8]\niterations = 2\n",
        text.replace("envs = 2", "envs = 2\n    keep_rejected = true")
    ))
    .expect("recipe");
    let summary = run(&debiased, &clips, &options).expect("run");
    assert!(summary.outputs.is_empty());
    let (_, reason) = summary
        .failures
        .iter()
        .find(|(job, _)| job == "debias_train")
        .expect("debias_train failed");
    assert!(reason.contains("no original clip passed"), "{reason}");
    assert_eq!(summary.failures.len(), 3, "{:?}", summary.failures);
}

#[test]
fn a_rejected_clips_debiasing_makes_nothing_and_nothing_fails() {
    // Copies twisted by 30 degrees of noise per joint are not accepted even
    // by the plumbing's lenient limits, while the original is and pairs the
    // debiaser: each rejected copy's debiasing runs, finds nothing to work
    // on and makes nothing, which is an outcome of the run, not a failure.
    let recipe = Recipe::from_toml_str(&CORRECTED.replace("sigma_deg = 1.0", "sigma_deg = 30.0"))
        .expect("recipe");
    let work = tempfile::tempdir().expect("tempdir");
    let finished = std::sync::Mutex::new(Vec::new());
    let on_event = |e: Event<'_>| {
        if let Event::JobFinished { job, ok } = e {
            finished.lock().expect("lock").push((job.key.clone(), ok));
        }
    };
    let options = Options {
        on_event: &on_event,
        ..in_process(work.path())
    };
    let summary = run(&recipe, &[kick()], &options).expect("run");
    assert!(summary.failures.is_empty(), "{:?}", summary.failures);
    assert_eq!(summary.rejected.len(), 2, "{:?}", summary.rejected);
    assert!(summary.outputs.is_empty());
    let finished = finished.into_inner().expect("lock");
    for clip in &summary.rejected {
        let key = format!("debias_apply:{clip}");
        assert!(
            finished.contains(&(key.clone(), true)),
            "{key}: {finished:?}"
        );
        let r = correct::Report::read(&work.path().join("correct").join(clip).join("report.json"))
            .expect("the rejected correction's report");
        assert!(!r.accepted && !r.rejected_because.is_empty(), "{r:?}");
    }
}

#[test]
fn the_vae_trains_on_one_floor_unless_told_to_keep_the_captured_ones() {
    let floor = |text: &str| {
        let recipe = Recipe::from_toml_str(text).expect("recipe");
        let step = recipe.vae.expect("a [vae] table");
        step.train_config(0).features.floor
    };
    assert_eq!(floor("[vae]\n"), Some(vae::FloorLevel::default()));
    assert_eq!(floor("[vae]\nlevel_floor = false\n"), None);
    let step = Recipe::from_toml_str(
        "[vae]\nmixed_motion_weight = 2\nnear_members = 3\nmixed_contact_weight = 0.3\n\
         mixed_sole_weight = 0.5\nmixed_travel_weight = 0.7\nmixed_balance_weight = 0.9\n",
    )
    .expect("recipe")
    .vae
    .expect("a [vae] table");
    let config = step.train_config(5);
    let w = config.weights;
    assert_eq!(
        (w.mixed_motion, config.near.members, config.seed),
        (2.0, 3, 5)
    );
    assert_eq!(
        (
            w.mixed_contact,
            w.mixed_sole,
            w.mixed_travel,
            w.mixed_balance
        ),
        (0.3, 0.5, 0.7, 0.9)
    );
}

#[test]
fn vae_table_trains_per_class_and_samples() {
    let recipe = Recipe::from_toml_str(
        // Every mixed-code term on: the balance term needs the character's
        // masses and soles, which the stage builds (training fails without).
        "[vae]\ncopies = 3\niterations = 2\nmin_clips = 1\nadversarial = false\n\
         mixed_motion_weight = 1\nmixed_contact_weight = 0.3\nmixed_sole_weight = 1\n\
         mixed_travel_weight = 1\nmixed_balance_weight = 1\n",
    )
    .expect("recipe");
    let clips = [kick()];
    let work = tempfile::tempdir().expect("tempdir");
    let summary = run(
        &recipe,
        &clips,
        &Options {
            out: None,
            work: work.path(),
            seed: 1,
            on_event: &quiet,
        },
    )
    .expect("run");
    assert!(summary.failures.is_empty(), "{:?}", summary.failures);
    let names: Vec<_> = summary.outputs.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "kickLFront1Reps__vae_000",
            "kickLFront1Reps__vae_001",
            "kickLFront1Reps__vae_002"
        ]
    );
    for o in &summary.outputs {
        assert_eq!(o.entry.synth.op, "vae");
        assert_eq!(o.motion.joints(), clips[0].motion.joints());
        assert!(o.motion.frames() > 1);
    }
}

#[test]
fn with_class_trackers_every_correction_starts_from_its_class_tracker() {
    let recipe = Recipe::from_toml_str(
        r#"
        [[ops]]
        op = "mirror"
        [vae]
        copies = 1
        min_clips = 1
        [correct]
        policy = "class"
        tracker_budget_s = 60
        "#,
    )
    .expect("recipe");
    let names: Vec<String> = [
        "HDM_bd_kickLFront1Reps_001_120",
        "HDM_bk_kickLFront1Reps_002_120",
        "HDM_bd_jogLeftCircle4StepsRstart_001_120",
    ]
    .map(String::from)
    .to_vec();
    let plan = plan(&recipe, &names, 0);
    let job = |key: &str| plan.job(key).unwrap_or_else(|| panic!("no job {key}"));
    let position = |key: &str| plan.jobs.iter().position(|j| j.key == key).unwrap();
    // One tracker per class, on the class's clips.
    match &job("tracker:kickLFront1Reps").kind {
        JobKind::Tracker { clips, .. } => assert_eq!(clips, &names[..2]),
        other => panic!("{other:?}"),
    }
    assert!(plan.job("tracker:jogLeftCircle4StepsRstart").is_some());
    // No per-clip warm start from the originals: the tracker replaces it.
    assert!(
        !plan
            .jobs
            .iter()
            .any(|j| j.key.starts_with("correct_original:"))
    );
    for (clip, class) in [
        (
            "HDM_bk_kickLFront1Reps_002_120__00_mirror_000",
            "kickLFront1Reps",
        ),
        ("kickLFront1Reps__vae_000", "kickLFront1Reps"),
        (
            "HDM_bd_jogLeftCircle4StepsRstart_001_120__00_mirror_000",
            "jogLeftCircle4StepsRstart",
        ),
    ] {
        let key = format!("correct:{clip}");
        let tracker = format!("tracker:{class}");
        let c = job(&key);
        match &c.kind {
            JobKind::Correct {
                tracker: Some(t),
                sources,
                ..
            } => {
                assert_eq!(t, class);
                assert!(sources.is_empty());
            }
            other => panic!("{other:?}"),
        }
        assert!(c.deps.contains(&tracker), "{c:?}");
        assert!(position(&tracker) < position(&key));
    }

    // With debiasing the originals are corrected, from their tracker too.
    let debiased = Recipe::from_toml_str(
        "[[ops]]\nop = \"mirror\"\n[correct]\npolicy = \"class\"\n[debias]\n",
    )
    .expect("recipe");
    let plan = pipeline::plan(&debiased, &names, 0);
    let original = plan
        .job("correct_original:HDM_bd_jogLeftCircle4StepsRstart_001_120")
        .expect("original");
    assert_eq!(original.deps, vec!["tracker:jogLeftCircle4StepsRstart"]);

    let e =
        recipe_err("[[ops]]\nop = \"noise\"\n[correct]\npolicy = \"class\"\ntracker_frames = 0\n");
    assert!(e.contains("tracker_frames"), "{e}");
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[correct]\npolicy = \"dataset\"\n");
    assert!(e.contains("[correct]"), "{e}");

    // Lowering the tracker's root force while fine-tuning: class policy only,
    // a scale in (0, 1].
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[correct]\ntracker_final_residual_scale = 0.15\n");
    assert!(e.contains("needs `policy = \"class\"`"), "{e}");
    let e = recipe_err(
        "[[ops]]\nop = \"noise\"\n[correct]\npolicy = \"class\"\ntracker_final_residual_scale = 0\n",
    );
    assert!(e.contains("(0, 1]"), "{e}");
    let lowered = Recipe::from_toml_str(
        "[[ops]]\nop = \"noise\"\n[correct]\npolicy = \"class\"\ntracker_final_residual_scale = 0.15\n",
    )
    .expect("recipe");
    let step = lowered.correct.as_ref().expect("[correct]");
    assert_eq!(step.config(0).tracker_final_residual_scale, Some(0.15));
}

#[test]
fn a_class_tracker_runs_in_process_and_its_corrections_start_from_it() {
    let text = CORRECTED.replace(
        "[correct]",
        "[correct]\npolicy = \"class\"\ntracker_budget_s = 1",
    );
    let recipe = Recipe::from_toml_str(&text).expect("recipe");
    let clips = [kick()];
    let dir = tempfile::tempdir().expect("tempdir");
    let work = dir.path().join("work");
    let options = in_process(&work);
    let summary = run(&recipe, &clips, &options).expect("run");
    // A one-second tracker is barely trained: a clip it corrects may fall
    // (rejected, so its debiasing finds nothing to do, which is not a
    // failure). That is the plumbing working; no job may fail.
    assert!(summary.failures.is_empty(), "{:?}", summary.failures);
    for clip in &summary.rejected {
        let r = correct::Report::read(&work.join("correct").join(clip).join("report.json"))
            .expect("the rejected correction's report");
        assert!(!r.accepted && !r.rejected_because.is_empty(), "{r:?}");
    }
    let tracker = work.join("trackers/kickLFront1Reps");
    let report =
        correct::ClassReport::read(&tracker.join(correct::class::REPORT_FILE)).expect("class.json");
    assert_eq!(report.clips, 1);
    assert!(report.iterations >= 1);
    // Every correction (the noisy copies and the original for debiasing)
    // started from the tracker.
    let reports: Vec<PathBuf> = ["correct", "originals"]
        .iter()
        .flat_map(|f| std::fs::read_dir(work.join(f)).expect("folder"))
        .map(|e| e.expect("entry").path().join("report.json"))
        .collect();
    assert_eq!(reports.len(), 3);
    for path in reports {
        let r = correct::Report::read(&path).expect("report");
        let from = r.warm_start.expect("warm-started");
        assert!(from.contains("trackers"), "{from}");
    }
}

#[test]
fn new_clips_the_class_tracker_fails_start_from_a_second_tracker() {
    // A mean reward of 1 is never reached: the class tracker fails both
    // noisy copies as is, so the second tracker trains on both.
    let text = CORRECTED
        .replace(
            "[correct]",
            "[correct]\npolicy = \"class\"\ntracker_budget_s = 1\nvariant_tracker_iterations = 1",
        )
        .replace(
            "accept_threshold = 0.0",
            "accept_threshold = 1.0\nkeep_rejected = true",
        );
    let text = &text[..text.find("[debias]").expect("debias table")];
    let recipe = Recipe::from_toml_str(text).expect("recipe");
    let dir = tempfile::tempdir().expect("tempdir");
    let work = dir.path().join("work");
    let options = in_process(&work);
    let summary = run(&recipe, &[kick()], &options).expect("run");
    assert!(summary.failures.is_empty(), "{:?}", summary.failures);
    assert_eq!(summary.manifest.len(), 2);
    let variants = work.join("variant_trackers/kickLFront1Reps");
    let judged = correct::ClassReport::read(
        &variants
            .join(pipeline::stages::JUDGED_DIR)
            .join(correct::class::REPORT_FILE),
    )
    .expect("judged");
    assert_eq!(judged.clips, 2);
    assert_eq!(judged.accepted(), 0);
    let second =
        correct::ClassReport::read(&variants.join(correct::class::REPORT_FILE)).expect("second");
    assert_eq!((second.clips, second.iterations), (2, 1));
    for entry in &summary.manifest {
        let clip = entry.synth.file.trim_end_matches(".bvh");
        let r = correct::Report::read(&work.join("correct").join(clip).join("report.json"))
            .expect("report");
        let from = r.warm_start.expect("warm-started");
        assert!(from.contains("variant_trackers"), "{clip}: {from}");
    }
    // A rerun reuses the judgement, the second tracker and the corrections.
    let again = run(&recipe, &[kick()], &options).expect("rerun");
    assert_eq!(again.manifest, summary.manifest);
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[correct]\nvariant_tracker_iterations = 5\n");
    assert!(e.contains("variant_tracker_iterations"), "{e}");
    let e = recipe_err("[[ops]]\nop = \"noise\"\n[correct]\nskate_scale_when_skating_m_s = -1\n");
    assert!(e.contains("skate scale -1"), "{e}");
}

/// Every numeric field the tables' crates leave open has an upper bound:
/// values past it are refused naming the table, the field and the bound, and
/// the bound itself is accepted.
#[test]
fn numeric_recipe_fields_have_upper_bounds() {
    let base = "[[ops]]\nop = \"noise\"\n";
    let cases = [
        (
            "[correct]",
            "time_budget_s",
            "[correct]\ntime_budget_s = 1e308\n",
        ),
        ("[correct]", "envs", "[correct]\nenvs = 1000000\n"),
        (
            "[correct]",
            "max_iterations",
            "[correct]\nmax_iterations = 1000001\n",
        ),
        (
            "[correct]",
            "original_max_iterations",
            "[correct]\noriginal_max_iterations = 1000001\n",
        ),
        (
            "[correct]",
            "tracker_iterations",
            "[correct]\npolicy = \"class\"\ntracker_iterations = 1000001\n",
        ),
        (
            "[correct]",
            "tracker_budget_s",
            "[correct]\npolicy = \"class\"\ntracker_budget_s = 1e12\n",
        ),
        (
            "[correct]",
            "variant_tracker_iterations",
            "[correct]\npolicy = \"class\"\nvariant_tracker_iterations = 1000001\n",
        ),
        ("[vae]", "iterations", "[vae]\niterations = 1000000000000\n"),
        ("[vae]", "min_clips", "[vae]\nmin_clips = 1000000\n"),
        ("[vae]", "near_members", "[vae]\nnear_members = 1000000\n"),
        ("[vae]", "smooth_s", "[vae]\nsmooth_s = 2.0\n"),
        (
            "[debias]",
            "iterations",
            "[correct]\n[debias]\niterations = 100000000\n",
        ),
        (
            "[debias]",
            "batch_size",
            "[correct]\n[debias]\nbatch_size = 10000000\n",
        ),
        (
            "[debias]",
            "hidden[]",
            "[correct]\n[debias]\nhidden = [100000]\n",
        ),
        (
            "[debias]",
            "hidden",
            "[correct]\n[debias]\nhidden = [8, 8, 8, 8, 8, 8, 8, 8, 8]\n",
        ),
        (
            "[debias]",
            "learning_rate",
            "[correct]\n[debias]\nlearning_rate = 10.0\n",
        ),
        (
            "[debias]",
            "weight_decay",
            "[correct]\n[debias]\nweight_decay = 5.0\n",
        ),
        (
            "[debias]",
            "blend_s",
            "[correct]\n[debias.contacts]\nblend_s = 1e9\n",
        ),
        (
            "[debias]",
            "smoothing_s",
            "[correct]\n[debias]\nsmoothing_s = 1e9\n",
        ),
        (
            "[debias]",
            "height_band_m",
            "[correct]\n[debias.contacts]\nheight_band_m = 1e9\n",
        ),
        (
            "[debias]",
            "max_speed_m_s",
            "[correct]\n[debias.contacts]\nmax_speed_m_s = 1e9\n",
        ),
    ];
    for (table, field, text) in cases {
        let e = recipe_err(&format!("{base}{text}"));
        assert!(
            e.contains(table) && e.contains(field) && e.contains("bound"),
            "{text}: {e}"
        );
    }
    let e = recipe_err("[[ops]]\nop = \"mirror\"\ntolerance_m = 1e300\n");
    assert!(e.contains("ops[0]") && e.contains("tolerance_m"), "{e}");
    // The bounds themselves are accepted.
    let at_bounds = format!(
        "{base}[vae]\niterations = 100000\nnear_members = 10000\nsmooth_s = 1.0\n[correct]\ntime_budget_s = 86400\nenvs = 64\n\
         policy = \"class\"\ntracker_budget_s = 604800\nmax_iterations = 1000000\noriginal_max_iterations = 1000000\n\
         tracker_iterations = 1000000\nvariant_tracker_iterations = 1000000\n[debias]\niterations = 200000\nbatch_size = 65536\nsmoothing_s = 10.0\nhidden = [4096, 4096, 4096, 4096, 4096, 4096, 4096, 4096]\n"
    );
    Recipe::from_toml_str(&at_bounds).expect("values at their bounds");
    assert_eq!(pipeline::recipe::bounds::ALL.len(), 23);
}

/// `plan::size` counts the graph `plan` makes without making it.
#[test]
fn plan_size_counts_what_plan_makes() {
    let names: Vec<String> = [
        "hug_A",
        "hug_B",
        "HDM_bd_kick_001_120",
        "HDM_bd_kick_002_120",
        "walk",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let recipes = [
        "[[ops]]\nop = \"noise\"\ncopies = 3\n[[ops]]\nop = \"mirror\"\n",
        "[[ops]]\nop = \"noise\"\n[vae]\ncopies = 2\n[interaction]\ncopies = 3\n",
        "[[ops]]\nop = \"noise\"\ncopies = 2\n[vae]\ncopies = 4\n[correct]\n[debias]\n",
        "[interaction]\ncopies = 2\n[correct]\nwarm_start = false\n",
        "[vae]\ngroup_by = \"all\"\ncopies = 5\n[correct]\nwarm_start = false\n",
        "[[ops]]\nop = \"mirror\"\n[vae]\ncopies = 2\n[correct]\npolicy = \"class\"\n",
        "[[ops]]\nop = \"mirror\"\n[correct]\npolicy = \"class\"\n[debias]\n",
        "[[ops]]\nop = \"mirror\"\n[vae]\ncopies = 2\n[correct]\npolicy = \"class\"\nvariant_tracker_iterations = 3\n",
        "[vae]\ngroup_by = \"all\"\ncopies = 2\n[correct]\npolicy = \"class\"\nvariant_tracker_iterations = 3\n",
    ];
    for text in recipes {
        let recipe = Recipe::from_toml_str(text).expect(text);
        for clips in [0, 1, 2, names.len()] {
            let names = &names[..clips];
            let plan = pipeline::plan(&recipe, names, 7);
            let made: u64 = plan
                .jobs
                .iter()
                .filter(|j| matches!(j.kind.name(), "synthesize" | "vae" | "interaction"))
                .map(|j| j.outputs.len() as u64)
                .sum();
            let corrections = plan
                .jobs
                .iter()
                .filter(|j| matches!(j.kind.name(), "correct" | "correct_original"))
                .count() as u64;
            let trackers = plan
                .jobs
                .iter()
                .filter(|j| matches!(j.kind.name(), "tracker" | "variant_tracker"))
                .count() as u64;
            let size = pipeline::plan::size(&recipe, names);
            assert_eq!(size.outputs, made, "{text} over {clips} clips");
            assert_eq!(size.trackers, trackers, "{text} over {clips} clips");
            assert_eq!(size.corrections, corrections, "{text} over {clips} clips");
            assert_eq!(
                size.jobs,
                plan.jobs.len() as u64,
                "{text} over {clips} clips"
            );
        }
    }
}

/// Every correction of a [`pipeline::corrections`] plan (each clip made
/// three times under other names, one PPO iteration each, the original
/// two: `original_max_iterations`) with `parallel`
/// corrections at a time: clip -> (R_norm, iterations, tracked clip).
fn corrections_side_by_side(parallel: usize) -> Vec<(String, f64, u64, motion::Motion)> {
    let original = kick();
    let step = CorrectStep {
        time_budget_s: 600.0,
        max_iterations: Some(1),
        original_max_iterations: Some(2),
        target_r_norm: 2.0,
        // Never accepted as is, so every clip trains its iteration.
        accept_threshold: 1.0,
        keep_rejected: true,
        envs: 2,
        policy: PolicyKind::Class,
        tracker_budget_s: 600.0,
        tracker_iterations: Some(1),
        ..CorrectStep::default()
    };
    let made: Vec<String> = (0..3).map(|i| format!("copy_{i}")).collect();
    let plan = pipeline::corrections(
        std::slice::from_ref(&original.name),
        &made,
        &step,
        None,
        |name| name.bytes().map(u64::from).sum(),
    );
    let seen = std::sync::Mutex::new(Vec::new());
    let on_event = |e: pipeline::Event<'_>| {
        if let pipeline::Event::Corrected {
            job,
            report,
            motion,
        } = e
        {
            seen.lock().expect("lock").push((
                job.key.clone(),
                report.r_norm,
                report.iterations,
                motion.clone(),
            ));
        }
    };
    // One rollout thread, as the evaluation table runs them: the runner
    // gives corrections side by side one thread each.
    let small = |c: &mut correct::CorrectConfig| {
        c.ppo.threads = 1;
        c.ppo.samples_per_iteration = 256;
        c.ppo.minibatch_size = 128;
        c.ppo.epochs = 1;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let given = made
        .iter()
        .map(|n| pipeline::WorkClip::given(n, original.motion.clone()))
        .collect();
    pipeline::run_plan(
        &plan,
        std::slice::from_ref(&original),
        given,
        &Options {
            on_event: &on_event,
            ..in_process(dir.path())
        },
        pipeline::Tune {
            correction: Some(&small),
            parallel_corrections: parallel,
            ..pipeline::Tune::default()
        },
    )
    .expect("run");
    let mut seen = seen.into_inner().expect("lock");
    seen.sort_by(|a, b| a.0.cmp(&b.0));
    seen
}

#[test]
fn corrections_side_by_side_give_what_they_give_one_after_the_other() {
    let one = corrections_side_by_side(1);
    let two = corrections_side_by_side(2);
    let keys: Vec<&str> = one.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(
        keys,
        [
            "correct:copy_0",
            "correct:copy_1",
            "correct:copy_2",
            "correct_original:HDM_bd_kickLFront1Reps_001_120"
        ],
        "every clip corrected once"
    );
    let numbers = |run: &[(String, f64, u64, motion::Motion)]| -> Vec<(String, f64, u64)> {
        run.iter().map(|c| (c.0.clone(), c.1, c.2)).collect()
    };
    assert_eq!(numbers(&one), numbers(&two));
    let iterations: Vec<u64> = one.iter().map(|c| c.2).collect();
    assert_eq!(iterations, [1, 1, 1, 2], "the original trains its own cap");
    for (a, b) in one.iter().zip(&two) {
        assert!(a.3 == b.3, "{}: the tracked clips differ", a.0);
    }
}
