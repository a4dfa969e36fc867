//! Throughput of parsing, forward kinematics and IK synthesis on real HDM05
//! clips (`../shared/data/hdm05`, ASF/AMC at 120 Hz).
//!
//! Run: `cargo bench -p synth --bench throughput` (release profile). For each
//! clip of the chosen classes it measures, single-threaded and wall-clock:
//! 1. parse: reading and parsing the actor's ASF and the AMC clip into a Motion;
//! 2. FK: world transforms of every joint in every frame;
//! 3. IK: one `ik` op with the `kick` preset (keyframe search, fan sampling
//!    with the reachability/limit test, per-frame FABRIK + limits, and the FK
//!    error check of the output);
//! 4. all three together, as the CLI does per clip and IK copy.
//!
//! Each stage is repeated until it has run for at least 2 s; the figures are
//! clips/s and frames/s (frames at 120 Hz).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use motion::{Motion, amc, asf};
use synth::ik::Preset;
use synth::{IkParams, ik, rng_from_seed};

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/hdm05")
}

fn clips() -> Vec<(PathBuf, PathBuf)> {
    let dir = data_dir();
    let mut out: Vec<(PathBuf, PathBuf)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            n.ends_with(".amc") && (n.contains("kick") || n.contains("grab"))
        })
        .map(|amc_path| {
            let name = amc_path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            let asf_path = dir.join(format!("{}.asf", &name[..6]));
            (asf_path, amc_path)
        })
        .collect();
    out.sort();
    out
}

fn parse(pair: &(PathBuf, PathBuf)) -> Motion {
    let skeleton = asf::read(&pair.0).expect("ASF parses");
    amc::read(&pair.1, &skeleton, 120.0).expect("AMC parses")
}

fn fk(m: &Motion) -> f64 {
    let mut buf = vec![motion::Transform::IDENTITY; m.joints()];
    let mut acc = 0.0;
    for t in 0..m.frames() {
        m.world_transforms_into(t, &mut buf);
        acc += buf[m.joints() - 1].translation.y;
    }
    acc
}

fn run_ik(m: &Motion, seed: u64) -> f64 {
    let out = ik(m, &IkParams::preset(Preset::Kick), &mut rng_from_seed(seed)).expect("IK runs");
    out.sampled["error_keyframe_m"].as_f64().unwrap_or(0.0)
}

/// Repeat `pass` (one pass over all clips) for at least `min`; passes per second.
fn measure(min: Duration, mut pass: impl FnMut() -> f64) -> (f64, usize) {
    let start = Instant::now();
    let mut passes = 0;
    let mut sink = 0.0;
    while start.elapsed() < min || passes == 0 {
        sink += pass();
        passes += 1;
    }
    std::hint::black_box(sink);
    (passes as f64 / start.elapsed().as_secs_f64(), passes)
}

fn main() {
    let pairs = clips();
    assert!(!pairs.is_empty(), "no clips in {}", data_dir().display());
    let motions: Vec<Motion> = pairs.iter().map(parse).collect();
    let n = motions.len() as f64;
    let frames: usize = motions.iter().map(Motion::frames).sum();
    println!(
        "{} HDM05 clips (kick + grab), {} frames at 120 Hz, {} joints; single thread",
        motions.len(),
        frames,
        motions[0].joints()
    );
    let min = Duration::from_secs(2);
    let report = |what: &str, (passes_per_s, passes): (f64, usize)| {
        println!(
            "{what:<22} {:>10.1} clips/s {:>12.0} frames/s  ({passes} passes)",
            passes_per_s * n,
            passes_per_s * frames as f64
        );
    };
    report(
        "parse (ASF + AMC)",
        measure(min, || pairs.iter().map(|p| parse(p).frames() as f64).sum()),
    );
    report(
        "FK (all frames)",
        measure(min, || motions.iter().map(fk).sum()),
    );
    report(
        "IK (kick preset)",
        measure(min, || motions.iter().map(|m| run_ik(m, 1)).sum()),
    );
    report(
        "parse + FK + IK",
        measure(min, || {
            pairs
                .iter()
                .map(|p| {
                    let m = parse(p);
                    fk(&m) + run_ik(&m, 1)
                })
                .sum()
        }),
    );
}
