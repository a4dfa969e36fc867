//! Retargeting figures on the CMU pairs: `cargo bench -p interaction --bench retarget`.
//!
//! For each pair in `../shared/data/cmu_pairs` and each scale (0.75, 1.0, 1.25,
//! or the scales given as arguments) prints wall time, bone-length error, key
//! pair distance error (JPD) and foot skating before/after. Not a timed test:
//! figures for the notes.

use std::path::PathBuf;

use interaction::{BoneScale, RetargetOptions, retarget};
use motion::{LoadOptions, load};

const PAIRS: [&str; 3] = [
    "18_01_walk_shake_hands",
    "20_05_synchronized_walk",
    "22_14_alternating_squats",
];

fn main() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/cmu_pairs");
    if !dir.is_dir() {
        eprintln!("{} is missing: nothing to measure", dir.display());
        return;
    }
    let mut scales: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    if scales.is_empty() {
        scales = vec![0.75, 1.0, 1.25];
    }
    let options = RetargetOptions::default();
    println!(
        "{:<26} {:>5} {:>6} {:>7} {:>9} {:>8} {:>12} {:>12} {:>12} {:>8} {:>8} {:>6}",
        "pair",
        "scale",
        "frames",
        "wall_s",
        "bone_m",
        "jpd_m",
        "skateA s>o",
        "skateB s>o",
        "skateB naive",
        "shiftA",
        "shiftB",
        "iters"
    );
    for name in PAIRS {
        let load_one = |side: &str| {
            load(
                dir.join(format!("{name}_{side}.bvh")),
                &LoadOptions::default(),
            )
        };
        let (a, b) = match (load_one("A"), load_one("B")) {
            (Ok(a), Ok(b)) => (a, b),
            (Err(e), _) | (_, Err(e)) => {
                eprintln!("{name}: {e}");
                continue;
            }
        };
        for &s in &scales {
            let scale = match BoneScale::uniform(s) {
                Ok(x) => x,
                Err(e) => {
                    eprintln!("{e}");
                    continue;
                }
            };
            match retarget(&a, &b, &scale, &options) {
                Ok(r) => {
                    let p = &r.report;
                    let f = &p.foot_skating;
                    println!(
                        "{:<26} {:>5.2} {:>6} {:>7.3} {:>9.2e} {:>8} {:>5.3}>{:<6.3} {:>5.3}>{:<6.3} {:>12.3} {:>8.4} {:>8.4} {:>6.1}",
                        name,
                        s,
                        p.frames,
                        p.wall_s,
                        p.bone_error_m,
                        p.jpd_m
                            .map(|j| format!("{j:.4}"))
                            .unwrap_or_else(|| "-".into()),
                        f.a_source_m_s,
                        f.a_output_m_s,
                        f.b_source_m_s,
                        f.b_output_m_s,
                        f.b_naive_m_s,
                        p.a_shift_mean_m,
                        p.b_shift_mean_m,
                        p.solver.iterations_total as f64 / p.frames as f64,
                    );
                    for k in &p.key_pairs {
                        println!(
                            "    key pair {}-{} frames {}..{} source {:.3} m output {:.3} m jpd {:.4} m",
                            k.pair.a_joint,
                            k.pair.b_joint,
                            k.pair.first_frame,
                            k.pair.last_frame,
                            k.pair.source_mean_m,
                            k.output_mean_m,
                            k.jpd_m
                        );
                    }
                    println!(
                        "    rod residual before IK {:.2e} m, closest approach {:.3} -> {:.3} m",
                        p.solver.rod_residual_max_m,
                        p.closest_approach_source_m,
                        p.closest_approach_output_m
                    );
                }
                Err(e) => eprintln!("{name} @ {s}: {e}"),
            }
        }
    }
}
