//! `motionaug interaction dataset / train / generate / eval` end to end on
//! the first second of two CMU pairs (`../shared/data/cmu_pairs`; skipped
//! with a note when absent), with a tiny model: this checks the plumbing and
//! the files, not the model's quality (the crate's tests and README do).

mod common;
use common::*;
use std::path::Path;

use motion::{LoadOptions, load};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn dataset_train_generate_and_eval() {
    let src = root().join("../shared/data/cmu_pairs");
    if !src.is_dir() {
        eprintln!("note: {} missing, test skipped", src.display());
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pairs = dir.path().join("pairs");
    std::fs::create_dir_all(&pairs).unwrap();
    for (name, frames) in [
        ("18_01_walk_shake_hands", 160),
        ("20_05_synchronized_walk", 120),
    ] {
        for side in ["A", "B"] {
            let m = load(
                src.join(format!("{name}_{side}.bvh")),
                &LoadOptions::default(),
            )
            .unwrap();
            let j = m.joints();
            let cut = m
                .with_frames(
                    m.fps(),
                    m.root_translation()[..frames].to_vec(),
                    m.rotations()[..frames * j].to_vec(),
                )
                .unwrap();
            std::fs::write(
                pairs.join(format!("{name}_{side}.bvh")),
                motion::bvh::to_bytes(&cut),
            )
            .unwrap();
        }
    }
    let p = |x: &Path| x.to_str().unwrap().to_string();
    let (data, model) = (dir.path().join("data"), dir.path().join("model"));
    ok(motionaug(&[
        "interaction",
        "dataset",
        "--pairs",
        &p(&pairs),
        "--out",
        &p(&data),
        "--repeats",
        "1",
    ]));
    let manifest = json(&data.join("dataset.json"));
    assert_eq!(manifest["pairs"].as_array().unwrap().len(), 2);
    assert_eq!(
        manifest["pairs"][0]["variations"].as_array().unwrap().len(),
        11
    );
    ok(motionaug(&[
        "interaction",
        "train",
        &p(&data),
        "--out",
        &p(&model),
        "--steps",
        "3",
        "--window",
        "12",
        "--batch",
        "4",
        "--hidden",
        "8",
    ]));
    assert!(model.join("weights.safetensors").is_file() && model.join("model.json").is_file());

    let model_s = p(&model);
    let a = p(&pairs.join("18_01_walk_shake_hands_A.bvh"));
    let b = p(&pairs.join("18_01_walk_shake_hands_B.bvh"));
    for (extra, task) in [
        (vec!["--scale", "1.1"], "retarget"),
        (vec!["--seed", "3"], "generation"),
    ] {
        let out = dir.path().join(task);
        let mut args = vec!["interaction", "generate", &model_s, &a, &b, "--out"];
        let out_s = p(&out);
        args.push(&out_s);
        args.extend(extra.iter().copied());
        ok(motionaug(&args));
        for f in ["A.bvh", "B.bvh", "A.npz", "B.npz", "report.json"] {
            assert!(out.join(f).is_file(), "{task}: {f} missing");
        }
        let r = json(&out.join("report.json"));
        assert_eq!(r["task"], task);
        assert_eq!(r["frames"], 40);
        assert!(r["bone_error_m"].as_f64().unwrap() < 1e-6, "{r}");
        for key in [
            "jpd_m",
            "key_pairs",
            "wall_s",
            "network_bone_error_m",
            "foot_skating",
        ] {
            assert!(r.get(key).is_some(), "report.json has no `{key}`");
        }
        let b_out = load(out.join("B.bvh"), &LoadOptions::default()).unwrap();
        assert_eq!(b_out.frames(), 40);
    }
    let r = json(&dir.path().join("retarget/report.json"));
    assert_eq!(r["scale"]["default"], 1.1);

    let eval = dir.path().join("eval");
    let md = ok(motionaug(&[
        "interaction",
        "eval",
        &p(&data),
        "--out",
        &p(&eval),
        "--pairs",
        &p(&pairs),
        "--steps",
        "2",
        "--feature-steps",
        "2",
        "--window",
        "12",
        "--hidden",
        "8",
        "--split",
        "random",
        "--split",
        "cross_interaction",
    ]));
    assert!(
        md.contains("| random |") && md.contains("| cross_interaction |"),
        "{md}"
    );
    let e = json(&eval.join("eval.json"));
    assert_eq!(e["splits"].as_array().unwrap().len(), 2);
    assert_eq!(e["splits"][1]["folds"].as_array().unwrap().len(), 2);
    assert!(!e["comparison"].as_array().unwrap().is_empty());
    assert!(eval.join("eval.md").is_file());

    let bad = motionaug(&[
        "interaction",
        "eval",
        &p(&data),
        "--out",
        &p(&eval),
        "--split",
        "nope",
    ]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("cross_scale_interaction"));
}
