//! The ops on real HDM05 clips (ASF/AMC, 120 Hz) from `../shared/data`.

use std::path::PathBuf;

use motion::{Motion, amc, asf};
use synth::ik::Preset;
use synth::*;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/hdm05")
        .join(name)
}

/// The shared mocap is not part of a clone: without it these tests say so and pass.
fn absent() -> bool {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let missing = !root.join("hdm05").is_dir() || !root.join("cmu").is_dir();
    if missing {
        eprintln!("note: ../shared/data is absent; skipping the real-data synthesis test");
    }
    missing
}

fn clip(actor: &str, class: &str, n: u32) -> Motion {
    let skeleton = asf::read(data(&format!("HDM_{actor}.asf"))).unwrap();
    amc::read(
        data(&format!("HDM_{actor}_{class}_{n:03}_120.amc")),
        &skeleton,
        120.0,
    )
    .unwrap()
}

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

fn report(out: &Augmented) -> IkReport {
    serde_json::from_value(serde_json::Value::Object(out.sampled.clone())).unwrap()
}

#[test]
fn ik_presets_on_hdm05_reach_targets_with_exact_bones() {
    if absent() {
        return;
    }
    let cases = [
        ("bd", "kickLFront1Reps", 1, Preset::Kick, "lfoot"),
        ("mm", "kickLFront1Reps", 20, Preset::Kick, "lfoot"),
        ("bk", "grabHighR", 7, Preset::Grab, "rwrist"),
        ("dg", "depositFloorR", 13, Preset::Deposit, "rwrist"),
        ("tr", "jogLeftCircle4StepsRstart", 14, Preset::Jog, ""),
        ("bd", "sneak2StepsLStart", 1, Preset::Sneak, ""),
        ("bk", "hopBothLegs1hops", 13, Preset::Hop, ""),
        ("tr", "squat1Reps", 41, Preset::Squat, ""),
    ];
    for (actor, class, n, preset, effector) in cases {
        let m = clip(actor, class, n);
        for seed in 0..3 {
            let out = ik(&m, &IkParams::preset(preset), &mut rng_from_seed(seed)).unwrap();
            let r = report(&out);
            eprintln!("{actor} {class} {preset:?} seed {seed}: {r:?}");
            if !effector.is_empty() {
                assert_eq!(r.effector, effector, "{class}");
            }
            assert!(r.reachable, "{class}: {r:?}");
            assert!(r.error_keyframe_m < 0.01, "{class}: {r:?}");
            assert!(bone_length_error(&out.motion) < 1e-4, "{class}");
            // Every edited joint stays inside its ASF limits (widened to the
            // source pose), in every frame; the knee/elbow stays on its hinge.
            let s = m.skeleton();
            let e = s.find(&r.effector).unwrap();
            let lower = s.parent(e).unwrap();
            let upper = s.parent(lower).unwrap();
            for j in [upper, lower, e] {
                let lim = s.joint(j).limits.as_ref().unwrap();
                for t in 0..m.frames() {
                    let x =
                        synth::ik::limits::excess(out.motion.rotation(t, j), m.rotation(t, j), lim);
                    assert!(x < 1e-6, "{class} frame {t} joint {}: {x}", s.joint(j).name);
                }
            }
            let hinge = s.joint(lower).limits.as_ref().unwrap();
            assert_eq!(hinge.dofs.len(), 1);
        }
    }
}

#[test]
fn mirror_on_hdm05_is_within_the_skeleton_asymmetry() {
    if absent() {
        return;
    }
    let m = clip("bd", "kickLFront1Reps", 1);
    let out = mirror(&m, &MirrorParams::default(), &mut rng_from_seed(0)).unwrap();
    let asym = out.sampled["max_asymmetry_m"].as_f64().unwrap();
    assert!(
        asym > 0.0 && asym < 0.05,
        "HDM05 skeletons are nearly symmetric: {asym}"
    );
    let (partner, _) = synth::mirror::mirror_map(m.skeleton(), &MirrorParams::default()).unwrap();
    let s = m.skeleton();
    assert_eq!(s.joint(partner[s.find("lfemur").unwrap()]).name, "rfemur");
    assert_eq!(
        s.joint(partner[s.find("lhipjoint").unwrap()]).name,
        "rhipjoint"
    );
    assert_eq!(s.joint(partner[s.find("lthumb").unwrap()]).name, "rthumb");
    // The left kick becomes a right kick: the right foot now reaches farthest.
    let k = ik(
        &out.motion,
        &IkParams::preset(Preset::Kick),
        &mut rng_from_seed(0),
    )
    .unwrap();
    assert_eq!(k.sampled["effector"], "rfoot");
    // World positions are the mirror image up to the chain's accumulated asymmetry.
    let depth = 12.0;
    for t in (0..m.frames()).step_by(10) {
        let a = m.world_positions(t);
        let b = out.motion.world_positions(t);
        for j in 0..m.joints() {
            let p = a[j];
            let d = (b[partner[j]] - glam::DVec3::new(-p.x, p.y, p.z)).length();
            assert!(d < depth * asym + 1e-9, "frame {t} joint {j}: {d}");
        }
    }
}

#[test]
fn kinematic_recipe_runs_on_hdm05_and_metrics_are_sane() {
    if absent() {
        return;
    }
    let text = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/recipes/kinematic.toml"),
    )
    .unwrap();
    let recipe = Recipe::from_toml_str(&text).unwrap();
    let m = clip("bk", "grabHighR", 7);
    let source = motion::metrics::plausibility(&m);
    assert!(source.penetration_max_m < 0.1, "{source:?}");
    assert!(source.bone_length_drift < 1e-9);
    assert!(source.foot_skating_m_s < 0.2, "{source:?}");
    let outs = expand_clip(&recipe, "HDM_bk_grabHighR_007_120", &m, 7).unwrap();
    assert_eq!(outs.len(), recipe.outputs_per_clip());
    for g in &outs {
        let p = motion::metrics::plausibility(&g.output.motion);
        assert!(p.bone_length_drift < 1e-9, "{}", g.name);
        if g.op == "noise" {
            assert!(p.jerk_m_s3 > source.jerk_m_s3, "i.i.d. noise adds jerk");
        }
        let entry = g.manifest_entry(format!("{}.bvh", g.name), "HDM_bk_grabHighR_007_120.amc");
        if g.op == "ik" {
            assert!(entry.effector.is_some() && entry.keyframe.is_some() && entry.target.is_some());
        }
    }
}

fn cmu(name: &str) -> Motion {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/cmu")
        .join(name);
    motion::bvh::read(path, motion::Unit::Auto).unwrap()
}

#[test]
fn ik_and_mirror_on_cmu_bvh_without_limits() {
    if absent() {
        return;
    }
    for (file, foot, hand) in [
        ("131_01_walk.bvh", "Ankle", "Wrist"),
        ("16_11_walk_veer_left.bvh", "Foot", "Hand"),
        ("01_01_forward_jumps.bvh", "Foot", "Hand"),
    ] {
        let m = cmu(file);
        for (preset, part) in [(Preset::Walk, foot), (Preset::Throw, hand)] {
            let out = ik(&m, &IkParams::preset(preset), &mut rng_from_seed(9)).unwrap();
            let r = report(&out);
            eprintln!("{file} {preset:?}: {r:?}");
            assert!(r.effector.ends_with(part), "{file}: {}", r.effector);
            assert!(r.reachable && r.error_keyframe_m < 0.01, "{file}: {r:?}");
            assert!(bone_length_error(&out.motion) < 1e-4);
        }
        let out = mirror(&m, &MirrorParams::default(), &mut rng_from_seed(0)).unwrap();
        assert!(
            out.sampled["max_asymmetry_m"].as_f64().unwrap() < 0.05,
            "{file}"
        );
    }
}

#[test]
fn lower_body_of_an_asf_skeleton_is_the_two_legs() {
    if absent() {
        return;
    }
    let m = clip("dg", "kickLFront1Reps", 13);
    let s = m.skeleton();
    let mut legs: Vec<&str> = synth::names::lower_body(s)
        .unwrap()
        .into_iter()
        .map(|j| s.joint(j).name.as_str())
        .collect();
    legs.sort_unstable();
    assert_eq!(
        legs,
        [
            "lfemur",
            "lfoot",
            "lhipjoint",
            "ltibia",
            "ltoes",
            "rfemur",
            "rfoot",
            "rhipjoint",
            "rtibia",
            "rtoes"
        ]
    );
    let feet: Vec<&str> = synth::names::feet(s)
        .into_iter()
        .map(|j| s.joint(j).name.as_str())
        .collect();
    let hands: Vec<&str> = synth::names::hands(s)
        .into_iter()
        .map(|j| s.joint(j).name.as_str())
        .collect();
    assert_eq!(feet, ["lfoot", "rfoot"]);
    assert_eq!(hands.len(), 2);
    assert!(hands.iter().all(|h| h.ends_with("wrist")), "{hands:?}");
}
