//! The learned commands end to end on the bundled HDM05 clips: `vae train` /
//! `vae sample` and `debias train` / `debias apply` (a few iterations: this
//! checks the plumbing, not the model quality, which the crates' tests check).

mod common;
use common::*;

#[test]
fn vae_trains_saves_and_samples_bvh_npz_and_a_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    let out = dir.path().join("samples");
    let (model_s, out_s) = (model.to_str().unwrap(), out.to_str().unwrap());
    ok(motionaug(&[
        "vae",
        "train",
        "examples/data/HDM_bd_kickLFront1Reps_001_120.amc",
        "examples/data/HDM_bd_jogLeftCircle4StepsRstart_001_120.amc",
        "--skeleton",
        "examples/data/HDM_bd.asf",
        "--out",
        model_s,
        "--iterations",
        "2",
        "--log-every",
        "0",
    ]));
    assert!(model.join("weights.safetensors").is_file());
    assert!(model.join("model.json").is_file());
    // Three near samples, seed 4, into `out`, low-passed over `smooth_s`.
    let sample = |out: &str, smooth_s: &str| {
        let smooth = format!("--smooth-s={smooth_s}");
        motionaug(&[
            "vae", "sample", model_s, "--count", "3", "--out", out, "--prior", "near", "--seed",
            "4", &smooth,
        ])
    };
    ok(sample(out_s, "0"));
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    let entries = manifest.as_array().unwrap();
    assert_eq!(entries.len(), 3);
    for e in entries {
        let bvh = out.join(e["bvh"].as_str().unwrap());
        let m = motion::io::load(&bvh, &Default::default()).unwrap();
        assert_eq!(m.frames() as u64, e["frames"].as_u64().unwrap());
        assert!(out.join(e["npz"].as_str().unwrap()).is_file());
    }
    // Smoothed samples (the default, here wider): the same clips' lengths,
    // less jerk than as decoded.
    let smooth = dir.path().join("smooth");
    ok(sample(smooth.to_str().unwrap(), "0.1"));
    let jerk = |dir: &std::path::Path, e: &serde_json::Value| {
        let m =
            motion::io::load(dir.join(e["npz"].as_str().unwrap()), &Default::default()).unwrap();
        (m.frames(), motion::metrics::plausibility(&m).jerk_m_s3)
    };
    let (mut raw, mut smoothed) = (0.0, 0.0);
    for e in entries {
        let (a, b) = (jerk(&out, e), jerk(&smooth, e));
        assert_eq!(a.0, b.0);
        raw += a.1;
        smoothed += b.1;
    }
    assert!(smoothed < raw, "jerk {smoothed} vs {raw}");
    let bad = motionaug(&["vae", "sample", out_s, "--count", "1", "--out", out_s]);
    assert!(
        !bad.status.success(),
        "sampling from a non-model directory must fail"
    );
    // Reconstructions: one clip per input, at the model's 30 fps, as long as
    // the input's duration.
    let recon = dir.path().join("recon");
    ok(motionaug(&[
        "vae",
        "reconstruct",
        model_s,
        "examples/data/HDM_bd_jogLeftCircle4StepsRstart_001_120.amc",
        "--skeleton",
        "examples/data/HDM_bd.asf",
        "--out",
        recon.to_str().unwrap(),
    ]));
    let input = motion::io::load(
        example("HDM_bd_jogLeftCircle4StepsRstart_001_120.amc"),
        &motion::io::LoadOptions {
            skeleton: Some(example("HDM_bd.asf")),
            ..Default::default()
        },
    )
    .unwrap();
    let name = "HDM_bd_jogLeftCircle4StepsRstart_001_120_recon";
    let m = motion::io::load(recon.join(format!("{name}.npz")), &Default::default()).unwrap();
    assert!(recon.join(format!("{name}.bvh")).is_file());
    assert_eq!(m.fps(), 30.0);
    let seconds = |m: &motion::Motion| (m.frames() - 1) as f64 / m.fps();
    assert!((seconds(&m) - seconds(&input)).abs() < 0.1);
    failed(motionaug(&["vae", "reconstruct", model_s, "--out", out_s]));
    let e = failed(sample(out_s, "-0.1"));
    assert!(e.contains("--smooth-s"), "{e}");
}

#[test]
fn debias_trains_on_pairs_and_applies_to_corrected_clips() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    // A stand-in for a corrected clip: the original at the 30 Hz control rate.
    ok(motionaug(&[
        "convert",
        "examples/data/HDM_bd_kickLFront1Reps_001_120.amc",
        &p("kick30.bvh"),
        "--skeleton",
        "examples/data/HDM_bd.asf",
        "--fps",
        "30",
    ]));
    let pair = format!(
        "{}=examples/data/HDM_bd_kickLFront1Reps_001_120.amc",
        p("kick30.bvh")
    );
    ok(motionaug(&[
        "debias",
        "train",
        "--pair",
        &pair,
        "--skeleton",
        "examples/data/HDM_bd.asf",
        "--out",
        &p("model"),
        "--iterations",
        "5",
        "--hidden",
        "16,16",
    ]));
    assert!(dir.path().join("model/debias.json").is_file());
    let applied = motionaug(&[
        "debias",
        "apply",
        &p("model"),
        &p("kick30.bvh"),
        "--out",
        &p("debiased"),
    ]);
    let stderr = String::from_utf8_lossy(&applied.stderr).to_string();
    ok(applied);
    // The kick stands on its right foot: planted frames are found and kept.
    assert!(stderr.contains("planted foot frames kept"), "{stderr}");
    let out = dir.path().join("debiased/kick30.bvh");
    let m = motion::bvh::read(&out, motion::Unit::Auto).expect("debiased BVH");
    assert_eq!(m.joints(), 31);
    assert_eq!(m.fps(), 30.0);

    // A pair without `=` is refused with a message naming it.
    let bad = motionaug(&["debias", "train", "--pair", "a.bvh", "--out", &p("m2")]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("CORRECTED=ORIGINAL"));
}
