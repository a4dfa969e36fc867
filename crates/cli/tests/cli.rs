//! The `motionaug` binary end to end, on the bundled example clips.

mod common;
use common::*;
use std::path::Path;

use motion::io::{LoadOptions, load};

const KICK: &str = "examples/data/HDM_bd_kickLFront1Reps_001_120.amc";
const JOG: &str = "examples/data/HDM_bd_jogLeftCircle4StepsRstart_001_120.amc";
const ASF: &str = "examples/data/HDM_bd.asf";

#[test]
fn inspect_json_has_the_documented_keys() {
    let text = ok(motionaug(&["inspect", KICK, "--skeleton", ASF, "--json"]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["fps"], 120.0);
    let frames = v["frames"].as_u64().unwrap();
    assert!(frames > 100);
    let duration = v["duration_s"].as_f64().unwrap();
    assert!((duration - frames as f64 / 120.0).abs() < 1e-9);
    assert_eq!(v["joints"], 31);
    assert_eq!(v["joint_names"].as_array().unwrap().len(), 31);
    assert_eq!(v["joint_names"][0], "root");
}

/// An AMC clip reads with the ASF beside it (`HDM_bd.asf` for `HDM_bd_*`);
/// alone in a folder it is a clear error naming `--skeleton`.
#[test]
fn amc_finds_its_skeleton_beside_it_or_asks_for_one() {
    let text = ok(motionaug(&["inspect", KICK, "--json"]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["joints"], 31);
    let dir = tempfile::tempdir().unwrap();
    let alone = dir.path().join("HDM_bd_kickLFront1Reps_001_120.amc");
    std::fs::copy(example("HDM_bd_kickLFront1Reps_001_120.amc"), &alone).unwrap();
    let err = failed(motionaug(&["inspect", alone.to_str().unwrap()]));
    assert!(err.contains("--skeleton"), "{err}");
}

#[test]
fn a_missing_file_is_named_once() {
    let err = failed(motionaug(&["metrics", "no/such/clip.bvh"]));
    assert_eq!(err.matches("no/such/clip.bvh").count(), 1, "{err}");
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
}

#[test]
fn bad_bvh_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.bvh");
    std::fs::write(
        &bad,
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n  CHANNELS 3 Xrotation Yrotation Zrotation\n}\n",
    )
    .unwrap();
    let err = failed(motionaug(&["inspect", bad.to_str().unwrap()]));
    assert!(err.contains("bad.bvh:4"), "{err}");
}

#[test]
fn convert_resamples_and_writes_bvh_and_npz() {
    let dir = tempfile::tempdir().unwrap();
    let bvh = dir.path().join("kick30.bvh");
    let npz = dir.path().join("kick30.npz");
    for out in [&bvh, &npz] {
        let out = out.to_str().unwrap();
        ok(motionaug(&[
            "convert",
            KICK,
            out,
            "--skeleton",
            ASF,
            "--fps",
            "30",
        ]));
    }
    let source = load(
        root().join(KICK),
        &LoadOptions {
            skeleton: Some(root().join(ASF)),
            ..Default::default()
        },
    )
    .unwrap();
    let converted = load(&bvh, &LoadOptions::default()).unwrap();
    assert_eq!(converted.fps(), 30.0);
    assert!((converted.duration_s() - source.duration_s()).abs() <= 1.0 / 30.0 + 1e-9);
    let arrays = motion::npz::read(&std::fs::read(&npz).unwrap()).unwrap();
    let positions = arrays.iter().find(|a| a.name == "positions").unwrap();
    assert_eq!(positions.shape, vec![converted.frames(), 31, 3]);
    // Smoothing: same frames, less jerk; a negative width is refused.
    let smooth = dir.path().join("kick30_smooth.npz");
    ok(motionaug(&[
        "convert",
        KICK,
        smooth.to_str().unwrap(),
        "--skeleton",
        ASF,
        "--fps",
        "30",
        "--smooth-s",
        "0.05",
    ]));
    let smoothed = load(&smooth, &LoadOptions::default()).unwrap();
    assert_eq!(smoothed.frames(), converted.frames());
    let jerk = |m: &motion::Motion| motion::metrics::plausibility(m).jerk_m_s3;
    assert!(
        jerk(&smoothed) < 0.8 * jerk(&converted),
        "{} vs {}",
        jerk(&smoothed),
        jerk(&converted)
    );
    let err = failed(motionaug(&[
        "convert",
        KICK,
        smooth.to_str().unwrap(),
        "--skeleton",
        ASF,
        "--smooth-s=-1",
    ]));
    assert!(err.contains("sigma"), "{err}");
}

#[test]
fn augment_writes_every_output_and_a_manifest_reproducibly() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let augment = |dir: &Path, seed: &str, threads: &str| {
        motionaug(&[
            "augment",
            KICK,
            JOG,
            "--skeleton",
            ASF,
            "--recipe",
            "examples/recipes/kinematic.toml",
            "--out",
            dir.to_str().unwrap(),
            "--seed",
            seed,
            "--correct-threads",
            threads,
        ])
    };
    let run = |dir: &Path, seed: &str| ok(augment(dir, seed, "1"));
    run(a.path(), "11");
    run(b.path(), "11");
    let manifest: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(a.path().join("manifest.json")).unwrap()).unwrap();
    let recipe = synth::Recipe::from_toml_str(
        &std::fs::read_to_string(root().join("examples/recipes/kinematic.toml")).unwrap(),
    )
    .unwrap();
    assert_eq!(manifest.len(), 2 * recipe.outputs_per_clip());
    for entry in &manifest {
        let file = entry["file"].as_str().unwrap();
        for keys in ["source", "op", "params"] {
            assert!(!entry[keys].is_null(), "{keys} missing in {entry}");
        }
        let bytes_a = std::fs::read(a.path().join(file)).unwrap();
        let bytes_b = std::fs::read(b.path().join(file)).unwrap();
        assert!(
            bytes_a == bytes_b,
            "{file} differs between two runs with one seed"
        );
        assert!(a.path().join(file.replace(".bvh", ".npz")).exists());
    }
    let c = tempfile::tempdir().unwrap();
    run(c.path(), "12");
    let noise = manifest.iter().find(|e| e["op"] == "noise").unwrap()["file"]
        .as_str()
        .unwrap();
    assert_ne!(
        std::fs::read(a.path().join(noise)).unwrap(),
        std::fs::read(c.path().join(noise)).unwrap(),
        "another seed must give another output"
    );
    let err = failed(augment(c.path(), "12", "0"));
    assert!(err.contains("--correct-threads"), "{err}");
}

#[test]
fn ik_outputs_reach_their_targets_through_the_written_bvh() {
    let dir = tempfile::tempdir().unwrap();
    ok(motionaug(&[
        "augment",
        KICK,
        "--skeleton",
        ASF,
        "--recipe",
        "examples/recipes/ik_kick.toml",
        "--out",
        dir.path().to_str().unwrap(),
        "--seed",
        "5",
    ]));
    let manifest: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(dir.path().join("manifest.json")).unwrap()).unwrap();
    let source = load(
        root().join(KICK),
        &LoadOptions {
            skeleton: Some(root().join(ASF)),
            ..Default::default()
        },
    )
    .unwrap();
    let rest = source.skeleton().bone_lengths();
    assert!(!manifest.is_empty());
    for entry in &manifest {
        assert_eq!(entry["op"], "ik");
        let out = load(
            dir.path().join(entry["file"].as_str().unwrap()),
            &LoadOptions::default(),
        )
        .unwrap();
        let effector = out
            .skeleton()
            .require(entry["effector"].as_str().unwrap())
            .unwrap();
        let key = entry["keyframe"].as_u64().unwrap() as usize;
        let target: Vec<f64> = serde_json::from_value(entry["target"].clone()).unwrap();
        let reached = out.world_positions(key)[effector];
        let error = (reached - motion::glam::DVec3::new(target[0], target[1], target[2])).length();
        assert!(
            error < 0.01,
            "{}: effector {error} m from its target",
            entry["file"]
        );
        for t in [0, key, out.frames() - 1] {
            let p = out.world_positions(t);
            for (j, joint) in out.skeleton().joints().iter().enumerate().skip(1) {
                let length = (p[j] - p[joint.parent.unwrap()]).length();
                assert!(
                    (length - rest[j]).abs() < 1e-4,
                    "bone {} changed length",
                    joint.name
                );
            }
        }
    }
}

#[test]
fn bad_recipe_names_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = dir.path().join("r.toml");
    std::fs::write(&recipe, "[[ops]]\nop = \"noise\"\nsigma_deg = -1.0\n").unwrap();
    let err = failed(motionaug(&[
        "augment",
        KICK,
        "--skeleton",
        ASF,
        "--recipe",
        recipe.to_str().unwrap(),
        "--out",
        dir.path().join("o").to_str().unwrap(),
    ]));
    assert!(err.contains("sigma_deg"), "{err}");
}

#[test]
fn metrics_json_reports_plausibility() {
    let text = ok(motionaug(&["metrics", JOG, "--skeleton", ASF, "--json"]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(
        v["foot_joints"].as_array().is_some_and(|f| !f.is_empty()),
        "{v}"
    );
    assert!(v.as_object().unwrap().len() > 5);
    assert!(v.get("soles").is_none(), "soles only when asked: {v}");
}

/// `motionaug metrics JOG --json <flag>`, parsed.
fn jog_metrics(flag: &str) -> serde_json::Value {
    let text = ok(motionaug(&[
        "metrics",
        JOG,
        "--skeleton",
        ASF,
        "--json",
        flag,
    ]));
    serde_json::from_str(&text).unwrap()
}

#[test]
fn metrics_scores_the_soles_criterion_on_the_clip_itself() {
    let v = jog_metrics("--soles");
    let s = &v["soles"];
    let planted = s["planted_frames"].as_u64().unwrap();
    let flat = s["flat_frames"].as_u64().unwrap();
    // A captured jog stands on its feet, mostly on the flat sole; the
    // others stood on a heel or on the toes.
    assert!(planted > 10 && flat <= planted, "{s}");
    let tilted = s["on_toes_frames"].as_u64().unwrap() + s["on_heel_frames"].as_u64().unwrap();
    assert_eq!(flat + tilted, planted, "{s}");
    assert!(
        tilted == 0 || s["mean_lift_m"].as_f64().unwrap() > 0.02,
        "{s}"
    );
    let fraction = s["flat_fraction"].as_f64().unwrap();
    assert!(
        (fraction - flat as f64 / planted as f64).abs() < 1e-12,
        "{s}"
    );
    assert!(fraction > 0.5, "{s}");
    assert_eq!(s["min_flat_fraction"], 0.9);
    // The plain table names the nested figures.
    let table = ok(motionaug(&["metrics", JOG, "--skeleton", ASF, "--soles"]));
    assert!(table.contains("soles.flat_fraction"), "{table}");
    assert!(v.get("balance").is_none(), "only when asked");
}

/// `--balance` counts the frames a foot is down and how far the zero moment
/// point leaves the feet over them; its figures agree with each other.
#[test]
fn metrics_measures_the_balance_of_the_clip_itself() {
    let v = jog_metrics("--balance");
    let b = &v["balance"];
    let supported = b["supported_frames"].as_u64().unwrap();
    let unbalanced = b["unbalanced_frames"].as_u64().unwrap();
    assert!(supported > 10 && unbalanced <= supported, "{b}");
    let fraction = b["unbalanced_fraction"].as_f64().unwrap();
    assert!(
        (fraction - unbalanced as f64 / supported as f64).abs() < 1e-12,
        "{b}"
    );
    let (mean, max) = (
        b["mean_outside_m"].as_f64().unwrap(),
        b["max_outside_m"].as_f64().unwrap(),
    );
    assert!(mean >= 0.0 && mean <= max && max.is_finite(), "{b}");
    assert!(
        unbalanced == 0 || max > b["margin_m"].as_f64().unwrap(),
        "{b}"
    );
    assert!(v.get("soles").is_none(), "only when asked");
}

#[test]
fn bvh_examples_work_without_a_skeleton() {
    let file = example("16_11_walk_veer_left.bvh");
    let text = ok(motionaug(&["inspect", file.to_str().unwrap(), "--json"]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["fps"], 120.0);
}

/// The walk written with a static `joint_Root` above the travelling `Hips`
/// and six channels on every joint (crates/motion/tests/static_root.rs).
const STATIC_ROOT: &str = "examples/data/static_root_walk.bvh";

/// Largest world distance between same-named joints (the base's included).
fn named_error(a: &motion::Motion, b: &motion::Motion) -> f64 {
    let positions = |m: &motion::Motion, f: usize| {
        let s = m.skeleton();
        let mut out: Vec<(String, motion::glam::DVec3)> = s
            .base()
            .iter()
            .zip(s.base_transforms())
            .map(|(j, t)| (j.name.clone(), t.translation))
            .collect();
        out.extend(
            m.world_positions(f)
                .into_iter()
                .enumerate()
                .map(|(j, p)| (s.joint(j).name.clone(), p)),
        );
        out
    };
    assert_eq!(a.frames(), b.frames());
    let mut worst: f64 = 0.0;
    for f in 0..a.frames() {
        let (pa, pb) = (positions(a, f), positions(b, f));
        assert_eq!(pa.len(), pb.len());
        for (name, p) in pa {
            let q = pb.iter().find(|(n, _)| *n == name).unwrap().1;
            worst = worst.max((p - q).length());
        }
    }
    worst
}

#[test]
fn a_static_root_above_the_hips_inspects_converts_and_round_trips() {
    let v: serde_json::Value =
        serde_json::from_str(&ok(motionaug(&["inspect", STATIC_ROOT, "--json"]))).unwrap();
    assert_eq!(v["joints"], 31);
    assert_eq!(v["joint_names"][0], "Hips");
    assert_eq!(v["base_joints"], serde_json::json!(["joint_Root"]));
    assert_eq!(v["translation_tracks"], serde_json::json!([]));
    let text = ok(motionaug(&["inspect", STATIC_ROOT]));
    assert!(text.contains("static base: joint_Root"), "{text}");
    // BVH -> BVH keeps the layout and every joint within a micrometre.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("walk.bvh");
    ok(motionaug(&["convert", STATIC_ROOT, out.to_str().unwrap()]));
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(written.starts_with("HIERARCHY\nROOT joint_Root\n"));
    assert_eq!(written.matches("CHANNELS 6 ").count(), 32);
    let source = load(root().join(STATIC_ROOT), &LoadOptions::default()).unwrap();
    let back = load(&out, &LoadOptions::default()).unwrap();
    assert!(named_error(&source, &back) < 1e-6);
    // Resampled too.
    let slow = dir.path().join("walk30.npz");
    ok(motionaug(&[
        "convert",
        STATIC_ROOT,
        slow.to_str().unwrap(),
        "--fps",
        "30",
    ]));
    let v: serde_json::Value = serde_json::from_str(&ok(motionaug(&[
        "inspect",
        slow.to_str().unwrap(),
        "--json",
    ])))
    .unwrap();
    assert_eq!(
        (v["frames"].as_u64(), v["fps"].as_f64()),
        (Some(90), Some(30.0))
    );
}

#[test]
fn npz_outputs_feed_back_in() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    // The float32 NPZ motionaug writes, and the lossless one of the pipeline.
    ok(motionaug(&["convert", STATIC_ROOT, &path("f32.npz")]));
    let source = load(root().join(STATIC_ROOT), &LoadOptions::default()).unwrap();
    std::fs::write(
        path("exact.npz"),
        pipeline::encode_clip(&source, None).unwrap(),
    )
    .unwrap();
    let exact = load(path("exact.npz"), &LoadOptions::default()).unwrap();
    assert_eq!(exact, source, "the lossless NPZ is the clip");
    let f32s = load(path("f32.npz"), &LoadOptions::default()).unwrap();
    assert_eq!(f32s.joints(), source.joints());
    let mut worst: f64 = 0.0;
    for f in 0..source.frames() {
        for (p, q) in source
            .world_positions(f)
            .iter()
            .zip(f32s.world_positions(f))
        {
            worst = worst.max((*p - q).length());
        }
    }
    assert!(worst < 1e-5, "{worst} m");
    for npz in ["f32.npz", "exact.npz"] {
        let v: serde_json::Value =
            serde_json::from_str(&ok(motionaug(&["inspect", &path(npz), "--json"]))).unwrap();
        assert_eq!(v["frames"], 180, "{npz}");
        ok(motionaug(&["metrics", &path(npz), "--json"]));
        ok(motionaug(&[
            "convert",
            &path(npz),
            &path(&npz.replace(".npz", ".bvh")),
        ]));
    }
    // The exact one keeps the static base through BVH.
    let bvh = std::fs::read_to_string(path("exact.bvh")).unwrap();
    assert!(bvh.starts_with("HIERARCHY\nROOT joint_Root\n"));
    // Both kinds, and augment's own outputs, go through augment.
    let out = path("aug");
    ok(motionaug(&[
        "augment",
        &path("f32.npz"),
        &path("exact.npz"),
        "--recipe",
        "examples/recipes/kinematic.toml",
        "--out",
        &out,
    ]));
    let manifest: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(Path::new(&out).join("manifest.json")).unwrap())
            .unwrap();
    let recipe = synth::Recipe::from_toml_str(
        &std::fs::read_to_string(root().join("examples/recipes/kinematic.toml")).unwrap(),
    )
    .unwrap();
    assert_eq!(manifest.len(), 2 * recipe.outputs_per_clip());
    let masked = manifest.iter().find(|e| e["op"] == "mask").unwrap()["file"]
        .as_str()
        .unwrap()
        .replace(".bvh", ".npz");
    let again = path("again");
    ok(motionaug(&[
        "augment",
        Path::new(&out).join(&masked).to_str().unwrap(),
        "--recipe",
        "examples/recipes/basic.toml",
        "--out",
        &again,
    ]));
    // A file that is no clip is named.
    std::fs::write(path("junk.npz"), b"PK not really").unwrap();
    let err = failed(motionaug(&["inspect", &path("junk.npz")]));
    assert!(err.contains("junk.npz") && err.contains("NPZ"), "{err}");
}

#[test]
fn a_static_root_above_the_hips_augments_and_corrects() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("aug");
    ok(motionaug(&[
        "augment",
        STATIC_ROOT,
        "--recipe",
        "examples/recipes/kinematic.toml",
        "--out",
        out.to_str().unwrap(),
    ]));
    let manifest: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    for entry in &manifest {
        let file = out.join(entry["file"].as_str().unwrap());
        let text = std::fs::read_to_string(&file).unwrap();
        assert!(
            text.starts_with("HIERARCHY\nROOT joint_Root\n"),
            "{}",
            file.display()
        );
        let m = load(&file, &LoadOptions::default()).unwrap();
        assert_eq!(m.skeleton().joint(0).name, "Hips");
    }
    // A short correction runs end to end and writes the file's layout back.
    let corrected = dir.path().join("corrected");
    ok(motionaug(&[
        "correct",
        STATIC_ROOT,
        "--out",
        corrected.to_str().unwrap(),
        "--max-iterations",
        "1",
        "--envs",
        "2",
    ]));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(corrected.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["iterations"], 1);
    let bvh = std::fs::read_to_string(corrected.join("corrected.bvh")).unwrap();
    assert!(bvh.starts_with("HIERARCHY\nROOT joint_Root\n"));
    let m = load(corrected.join("corrected.npz"), &LoadOptions::default()).unwrap();
    assert_eq!(m.fps(), 30.0);
}

/// `bench correction --variants`: a class's new clips in a row of their own,
/// judged by the class tracker; one it does not pass as is starts from a
/// second tracker, trained from the first on such clips only.
#[test]
fn bench_correction_corrects_variants_from_the_class_tracker_or_a_second_one() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = dir.path().join("noise.toml");
    std::fs::write(&recipe, "seed = 3\n[[ops]]\nop = \"noise\"\ncopies = 1\n").unwrap();
    let made = dir.path().join("made");
    ok(motionaug(&[
        "augment",
        KICK,
        "--recipe",
        recipe.to_str().unwrap(),
        "--out",
        made.to_str().unwrap(),
    ]));
    let variant = std::fs::read_dir(&made)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "npz"))
        .expect("augment wrote an NPZ");
    let name = variant.file_stem().unwrap().to_str().unwrap().to_string();
    let out = dir.path().join("bench");
    let bench = |classes: &str| {
        motionaug(&[
            "bench",
            "correction",
            "--data",
            "examples/data",
            "--classes",
            classes,
            "--per-class",
            "1",
            "--tracker-clips",
            "1",
            "--tracker-iterations",
            "1",
            "--max-iterations",
            "1",
            "--threads",
            "1",
            "--variants",
            variant.to_str().unwrap(),
            "--variant-tracker-iterations",
            "1",
            "--clips-at-once",
            "2",
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let err = failed(bench("kick,jog"));
    assert!(err.contains("one class"), "{err}");

    ok(bench("kick"));
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("table.json")).unwrap()).unwrap();
    let classes: Vec<&str> = rows.iter().map(|r| r["class"].as_str().unwrap()).collect();
    assert_eq!(classes, ["kick", "kick variants"]);
    assert!(rows.iter().all(|r| r["clips"] == 1), "{rows:?}");
    assert!(rows.iter().all(|r| r["elapsed_s"].is_f64()), "{rows:?}");
    let read = |p: std::path::PathBuf| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap()
    };
    let judged = read(out.join("kick_variant_tracker/judged/class.json"));
    assert_eq!(judged["iterations"], 0, "judged as is, not trained");
    assert_eq!(judged["verdicts"][0]["name"], name.as_str());
    let report = read(out.join("variants").join(&name).join("report.json"));
    let warm = report["warm_start"].as_str().unwrap().to_string();
    if judged["verdicts"][0]["accepted"] == true {
        assert!(warm.contains("kick_tracker"), "{warm}");
        assert!(!out.join("kick_variant_tracker/class.json").exists());
    } else {
        assert!(warm.contains("kick_variant_tracker"), "{warm}");
        let second = read(out.join("kick_variant_tracker/class.json"));
        assert_eq!(second["clips"], 1);
        assert_eq!(second["iterations"], 1);
    }

    // One clip corrected from the class tracker with `correct --tracker`;
    // its checkpoints given as a plain warm start are refused with a hint
    // (the tracker's policy sees upcoming frames a per-clip one does not).
    let tracker = out.join("kick_tracker");
    let one = dir.path().join("one");
    let correct = |from: &[&str]| {
        let mut args = vec![
            "correct",
            variant.to_str().unwrap(),
            "--out",
            one.to_str().unwrap(),
            "--max-iterations",
            "1",
            "--envs",
            "2",
            "--threads",
            "1",
        ];
        args.extend_from_slice(from);
        motionaug(&args)
    };
    let checkpoints = tracker.join("checkpoints");
    let err = failed(correct(&["--warm-start", checkpoints.to_str().unwrap()]));
    assert!(err.contains("--tracker"), "{err}");
    ok(correct(&["--tracker", tracker.to_str().unwrap()]));
    let report = read(one.join("report.json"));
    assert!(
        report["warm_start"]
            .as_str()
            .unwrap()
            .contains("kick_tracker"),
        "{report}"
    );
}

/// HDM05 clips of all five actors (not bundled; the eval tests skip without it).
const HDM05: &str = "../shared/data/hdm05";

#[test]
fn eval_predict_tiny_run_reports_both_conditions_per_horizon() {
    if !root().join(HDM05).is_dir() {
        eprintln!("note: {HDM05} is absent; skipping the eval predict test");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let recipe = dir.path().join("noise.toml");
    std::fs::write(
        &recipe,
        "seed = 3\n[[ops]]\nop = \"noise\"\nsigma_deg = 2.0\n",
    )
    .unwrap();
    let text = ok(motionaug(&[
        "eval",
        "predict",
        "--data",
        HDM05,
        "--class",
        "SNEAK",
        "--test-actor",
        "bk",
        "--model",
        "gcn",
        "--recipe",
        recipe.to_str().unwrap(),
        "--epochs",
        "0.05",
        "--max-windows",
        "24",
        "--gcn-hidden",
        "8",
        "--gcn-stages",
        "1",
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(
        v["matched_classes"],
        serde_json::json!(["sneak2StepsLStart"])
    );
    let test_files = v["test_files"].as_array().unwrap();
    assert!(!test_files.is_empty());
    assert!(
        test_files
            .iter()
            .all(|f| f.as_str().unwrap().contains("_bk_"))
    );
    assert!(
        v["train_files"]
            .as_array()
            .unwrap()
            .iter()
            .all(|f| !f.as_str().unwrap().contains("_bk_"))
    );
    for cond in ["no_aug", "aug"] {
        for ms in ["100", "200", "400"] {
            let e = v[cond][ms].as_f64().unwrap_or(f64::NAN);
            assert!(e.is_finite() && e > 0.0, "{cond} {ms}: {e}");
        }
    }
    // One noisy copy per training clip.
    let train = v["train_files"].as_array().unwrap().len() as u64;
    assert_eq!(v["details"]["augmented_clips"].as_u64(), Some(train));
    // The same noisy copies scored against the held-out actor.
    let text = ok(motionaug(&[
        "eval",
        "synth",
        "--data",
        HDM05,
        "--class",
        "sneak",
        "--test-actor",
        "bk",
        "--recipe",
        recipe.to_str().unwrap(),
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let (dtw, mmd) = (v["min_dtw"].as_f64().unwrap(), v["mmd"].as_f64().unwrap());
    assert!(
        dtw.is_finite() && dtw > 0.0 && (0.0..=2.0).contains(&mmd),
        "{v}"
    );
    assert_eq!(v["scores"]["min_dtw"]["synth_clips"].as_u64(), Some(train));
    assert!(v["original"]["min_dtw"]["synth_to_test"].as_f64().unwrap() > 0.0);
    let err = failed(motionaug(&[
        "eval",
        "predict",
        "--data",
        HDM05,
        "--class",
        "sneak",
        "--test-actor",
        "zz",
        "--model",
        "seq2seq",
    ]));
    assert!(
        err.contains("`zz` has no clips") && err.contains("bd"),
        "{err}"
    );
    // Without an augmentation there is no `aug`.
    let text = ok(motionaug(&[
        "eval",
        "predict",
        "--data",
        HDM05,
        "--class",
        "sneak",
        "--test-actor",
        "bk",
        "--model",
        "seq2seq",
        "--iterations",
        "2",
        "--max-windows",
        "8",
        "--seq2seq-hidden",
        "8",
        "--json",
    ]));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v["no_aug"]["400"].as_f64().unwrap() > 0.0);
    assert!(v.get("aug").is_none(), "{v}");
}

#[test]
fn eval_table_tiny_run_has_corrected_and_debiased_rows_and_resumes() {
    if !root().join(HDM05).is_dir() {
        eprintln!("note: {HDM05} is absent; skipping the eval table test");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("table");
    let args = [
        "eval",
        "table",
        "--data",
        HDM05,
        "--classes",
        "sneak",
        "--test-actors",
        "bk",
        "--models",
        "gcn",
        "--sets",
        "ik,vae,vae_ik,physics",
        "--vae-iterations",
        "2",
        "--correct-count",
        "2",
        "--correct-originals",
        "2",
        "--correct-samples",
        "1",
        "--debias-iterations",
        "20",
        "--iterations",
        "2",
        "--max-windows",
        "8",
        "--gcn-hidden",
        "8",
        "--gcn-stages",
        "1",
        "--out",
        out.to_str().unwrap(),
    ];
    ok(motionaug(&args));
    let read = || -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(out.join("table.json")).unwrap()).unwrap()
    };
    let first = read();
    let cell = &first["cells"][0];
    let physics = &cell["physics"];
    assert_eq!(physics["originals"], 2, "{physics}");
    // Two VAE samples and two IK edits.
    assert_eq!(physics["samples"], 4, "{physics}");
    assert_eq!(physics["by_set"]["vae"]["samples"], 2, "{physics}");
    assert_eq!(physics["by_set"]["ik"]["samples"], 2, "{physics}");
    // One PPO iteration (4096 samples) at most per clip.
    assert!(
        physics["ppo_samples"].as_u64().unwrap() <= 6 * 4096,
        "{physics}"
    );
    let clips = &cell["synth_clips"];
    assert_eq!(clips["vae_sub"], 2);
    assert_eq!(clips["ik_sub"], 2);
    // VAE & IK: both sets together, time-warped, as made and corrected.
    assert_eq!(
        clips["vae_ik"].as_u64(),
        Some(clips["vae_near"].as_u64().unwrap() + clips["ik"].as_u64().unwrap())
    );
    assert_eq!(clips["vae_ik_sub"], 4);
    let accepted = physics["samples_accepted"].as_u64().unwrap();
    let by_set = |set: &str| physics["by_set"][set]["samples_accepted"].as_u64().unwrap();
    assert_eq!(by_set("vae") + by_set("ik"), accepted);
    assert_eq!(clips["vae_corrected"].as_u64(), Some(by_set("vae")));
    assert_eq!(clips["ik_corrected"].as_u64(), Some(by_set("ik")));
    assert_eq!(clips["vae_ik_corrected"].as_u64(), Some(accepted));
    // The debiaser learns from the accepted originals only; without one there
    // is no debiased set (one PPO iteration rarely gets an original accepted).
    let pairs = physics["debias_pairs"].as_u64().unwrap();
    assert_eq!(physics["originals_accepted"].as_u64(), Some(pairs));
    let debiased = if pairs > 0 { accepted } else { 0 };
    assert_eq!(clips["vae_ik_debiased"].as_u64(), Some(debiased));
    for set in ["vae_near", "vae_sub", "vae_ik", "ik_sub"] {
        let p = &cell["synth"][set]["plausibility"];
        assert!(p["foot_skating_m_s"].as_f64().unwrap() >= 0.0, "{set}: {p}");
        assert!(
            cell["predict"]["gcn"][set]["errors"]["400"]
                .as_f64()
                .unwrap()
                > 0.0,
            "{set}"
        );
    }
    let md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        md.contains("| vae_sub |") && md.contains("| vae_ik_sub |") && md.contains("## Correction"),
        "{md}"
    );
    // A rerun reuses the finished cell ...
    let rerun = motionaug(&args);
    let stderr = String::from_utf8_lossy(&rerun.stderr).to_string();
    ok(rerun);
    assert!(stderr.contains("reusing the finished cell"), "{stderr}");
    assert_eq!(read()["cells"], first["cells"]);
    // ... and without it, the VAE and the corrections kept in OUT/work: the
    // same sets.
    assert!(out.join("work/bk_sneak/samples").is_dir());
    assert!(
        out.join("work/bk_sneak/vae-2it-one-floor/model.json")
            .is_file()
    );
    // This time on two threads: the originals' corrections (deleted, so
    // redone) beside the synthesis, the prediction models side by side,
    // give what one after the other gave.
    std::fs::remove_dir_all(out.join("work/cells")).unwrap();
    std::fs::remove_dir_all(out.join("work/bk_sneak/originals")).unwrap();
    let mut two = args.to_vec();
    two.extend(["--threads", "2"]);
    let rerun = motionaug(&two);
    let stderr = String::from_utf8_lossy(&rerun.stderr).to_string();
    ok(rerun);
    assert!(stderr.contains("vae: reusing"), "{stderr}");
    assert!(
        stderr.contains("the originals' corrections ran beside the synthesis"),
        "{stderr}"
    );
    assert!(out.join("work/bk_sneak/originals").is_dir());
    let second = read();
    assert_eq!(second["cells"][0]["synth"], first["cells"][0]["synth"]);
    for field in [
        "ppo_samples",
        "originals_accepted",
        "mean_r_norm",
        "samples_accepted",
    ] {
        assert_eq!(
            second["cells"][0]["physics"][field], physics[field],
            "{field}"
        );
    }
    let predicted = |table: &serde_json::Value| -> Vec<(String, serde_json::Value)> {
        let by_condition = table["cells"][0]["predict"]["gcn"].as_object().unwrap();
        by_condition
            .iter()
            .map(|(c, r)| (c.clone(), r["errors"].clone()))
            .collect()
    };
    assert!(predicted(&first).len() >= 8, "{:?}", predicted(&first));
    assert_eq!(predicted(&second), predicted(&first));
    // Merged with a copy of itself as another test actor's fold: one table
    // of both, aggregated over them; the same fold twice is refused.
    let mut other = second.clone();
    other["config"]["test_actors"] = serde_json::json!(["zz"]);
    other["cells"][0]["test_actor"] = "zz".into();
    let other_json = dir.path().join("other.json");
    std::fs::write(&other_json, other.to_string()).unwrap();
    let merged = dir.path().join("merged");
    let table_json = out.join("table.json");
    let merge = |tables: [&std::path::Path; 2]| {
        motionaug(&[
            "eval",
            "merge",
            tables[0].to_str().unwrap(),
            tables[1].to_str().unwrap(),
            "--out",
            merged.to_str().unwrap(),
        ])
    };
    ok(merge([&table_json, &other_json]));
    let both: serde_json::Value =
        serde_json::from_slice(&std::fs::read(merged.join("table.json")).unwrap()).unwrap();
    assert_eq!(
        both["config"]["test_actors"],
        serde_json::json!(["bk", "zz"])
    );
    assert_eq!(both["cells"].as_array().unwrap().len(), 2);
    let md = std::fs::read_to_string(merged.join("table.md")).unwrap();
    assert!(
        md.contains("## Prediction error, gcn, over test actors and seeds")
            && md.contains("| sneak (n = 2) |")
            && md.contains("test actor zz"),
        "{md}"
    );
    let err = failed(merge([&table_json, &table_json]));
    assert!(err.contains("is in an earlier table too"), "{err}");
    // A file that is not a table says so, naming it.
    let not_a_table = dir.path().join("not-a-table.json");
    std::fs::write(&not_a_table, "{\"cells\": 3}").unwrap();
    let err = failed(merge([&table_json, &not_a_table]));
    assert!(
        err.contains("not-a-table.json: not a table.json of `eval table`"),
        "{err}"
    );
    // The physics set needs something to correct.
    let mut nothing = args.to_vec();
    nothing[11] = "noise,physics";
    let err = failed(motionaug(&nothing));
    assert!(err.contains("add vae or ik to --sets"), "{err}");
}

#[test]
fn eval_table_corrects_with_one_class_tracker() {
    if !root().join(HDM05).is_dir() {
        eprintln!("note: {HDM05} is absent; skipping the eval table test");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("table");
    let output = motionaug(&[
        "eval",
        "table",
        "--data",
        HDM05,
        "--classes",
        "sneak",
        "--test-actors",
        "bk",
        "--no-predict",
        "--sets",
        "vae,physics",
        "--vae-iterations",
        "2",
        "--correct-count",
        "2",
        "--correct-originals",
        "2",
        "--correct-policy",
        "class",
        "--tracker-iterations",
        "1",
        "--clip-iterations",
        "1",
        "--variant-tracker-iterations",
        "1",
        "--debias-iterations",
        "20",
        // The corrections two at a time (crates/pipeline's tests check the
        // numbers equal one after the other's).
        "--threads",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr).to_string();
    ok(output);
    assert!(
        stderr.contains("class tracker: training on 2 originals"),
        "{stderr}"
    );
    // The samples are judged by the class tracker, and those it fails go to
    // a second tracker.
    assert!(
        stderr.contains("second tracker: judging 2 samples"),
        "{stderr}"
    );
    assert!(stderr.contains("second tracker: trained"), "{stderr}");
    let judged = out.join("work/bk_sneak/variant_trackers/class/judged/class.json");
    let judged: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&judged).unwrap()).unwrap();
    assert_eq!(judged["clips"], 2, "{judged}");
    // Trained once beside the VAE; the samples' plan finds it trained and
    // says so rather than "trained in 0 s".
    assert_eq!(
        stderr.matches("class tracker: trained").count(),
        1,
        "{stderr}"
    );
    assert!(
        stderr.contains("class tracker: reusing the one trained earlier"),
        "{stderr}"
    );
    assert!(
        stderr.contains("every sample starts from the class tracker"),
        "{stderr}"
    );
    assert!(out.join("work/bk_sneak/trackers/class").is_dir());
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("table.json")).unwrap()).unwrap();
    let physics = &v["cells"][0]["physics"];
    assert_eq!(physics["samples"], 2, "{physics}");
    // Every rejected clip is counted under at least one criterion.
    let set = &physics["by_set"]["vae"];
    let rejected = set["samples"].as_u64().unwrap() - set["samples_accepted"].as_u64().unwrap();
    let counted: u64 = set["rejected_by"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert!(counted >= rejected, "{physics}");
    assert_eq!(v["config"]["physics"]["policy"], "class");
    assert_eq!(v["config"]["physics"]["variant_tracker_iterations"], 1);
}
