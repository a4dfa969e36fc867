//! The learned interaction model end to end on a tiny configuration: a few
//! variations of the first 1.3 s of the CMU handshake (in
//! `../shared/data/cmu_pairs`; the test prints a note and returns when the
//! data is absent), a few training steps, save/load, whole-clip generation.

use std::path::PathBuf;

use interaction::BoneScale;
use interaction_model::dataset::DatasetConfig;
use interaction_model::generate::{generate, sample_scale};
use interaction_model::{Dataset, InteractionModel, TrainConfig, train};
use motion::{LoadOptions, Motion, load};

fn handshake(frames: usize) -> Option<(Motion, Motion)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/cmu_pairs");
    let a = dir.join("18_01_walk_shake_hands_A.bvh");
    let b = dir.join("18_01_walk_shake_hands_B.bvh");
    if !(a.is_file() && b.is_file()) {
        eprintln!("note: {} missing, test skipped", dir.display());
        return None;
    }
    let cut = |m: Motion| {
        let j = m.joints();
        m.with_frames(
            m.fps(),
            m.root_translation()[..frames].to_vec(),
            m.rotations()[..frames * j].to_vec(),
        )
        .unwrap()
    };
    let o = LoadOptions::default();
    Some((cut(load(a, &o).unwrap()), cut(load(b, &o).unwrap())))
}

#[test]
fn tiny_model_trains_saves_loads_and_generates() {
    // 160 frames at 120 Hz: the hands meet from about frame 64 (30 fps: 16).
    let Some((a, b)) = handshake(160) else {
        return;
    };
    let config = DatasetConfig {
        scale_min: 0.9,
        scale_max: 1.1,
        scale_step: 0.1,
        repeats: 1,
        ..Default::default()
    };
    let data = Dataset::build(&[("hs".into(), a.clone(), b.clone())], &config).unwrap();
    let pair = &data.pairs[0];
    assert_eq!((pair.frames, pair.variations.len()), (40, 3));
    assert_eq!(pair.body_a.len(), pair.body_b.len());
    let dir = tempfile::tempdir().unwrap();
    data.save(&dir.path().join("data")).unwrap();
    let back = Dataset::load(&dir.path().join("data")).unwrap();
    assert_eq!(back.pairs[0].b, pair.b);
    let scales = |d: &Dataset| -> Vec<BoneScale> {
        d.pairs[0]
            .variations
            .iter()
            .map(|v| v.scale.clone())
            .collect()
    };
    assert_eq!(scales(&back), scales(&data));

    let tc = TrainConfig {
        window: 12,
        stride: 4,
        steps: 40,
        batch: 4,
        hidden: 8,
        lr: 3e-3,
        ..Default::default()
    };
    let windows = data.windows(tc.window, tc.stride, |_, _| true);
    assert_eq!(windows.len(), 3 * 8);
    let mut curve = Vec::new();
    let mut progress =
        |_: usize, l: &interaction_model::train::Losses| curve.push(l.retarget + l.adapt);
    let model = train(&data, &windows, &tc, Some(&mut progress)).unwrap();
    let first: f64 = curve[..5].iter().sum::<f64>() / 5.0;
    let last: f64 = curve[curve.len() - 5..].iter().sum::<f64>() / 5.0;
    assert!(last < 0.8 * first, "motion losses {first} -> {last}");

    // Shapes, and a save/load round trip that predicts the same numbers.
    let batch = data.batch(&windows[..2], tc.window).unwrap();
    let (pa, pb) = model
        .predict(&batch.template_a, &batch.template_b, &batch.scales, None)
        .unwrap();
    assert_eq!(pa.dims(), &[2, 12, pair.body_a.len(), 3]);
    assert_eq!(pb.dims(), batch.b.dims());
    model.save(&dir.path().join("model")).unwrap();
    let loaded = InteractionModel::load(&dir.path().join("model")).unwrap();
    let (qa, _) = loaded
        .predict(&batch.template_a, &batch.template_b, &batch.scales, None)
        .unwrap();
    assert_eq!(
        pa.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
        qa.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    );

    // A whole clip: exact bones after IK, B's skeleton scaled, the model's rate.
    let scale = BoneScale::uniform(0.9).unwrap();
    let g = generate(&loaded, &a, &b, &scale, "retarget", &Default::default()).unwrap();
    assert_eq!((g.a.frames(), g.a.fps()), (40, 30.0));
    assert!(g.report.bone_error_m < 1e-6, "{}", g.report.bone_error_m);
    let (l0, l1) = (b.skeleton().bone_lengths(), g.b.skeleton().bone_lengths());
    for (x, y) in l0.iter().zip(&l1) {
        assert!((x * 0.9 - y).abs() < 1e-9);
    }
    assert!(g.report.network_bone_error_m.is_finite());
    assert!(
        !g.report.key_pairs.is_empty(),
        "the hands meet in these frames"
    );

    // Generation: a scale from the prior, reproducible by seed, a valid body.
    let s1 = sample_scale(&loaded, 5).unwrap();
    assert_eq!(s1, sample_scale(&loaded, 5).unwrap());
    assert!(s1.bones.values().all(|f| (0.5..2.0).contains(f)), "{s1:?}");
}
