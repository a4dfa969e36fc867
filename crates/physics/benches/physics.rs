//! Simulation speed and action-0 tracking error on a real clip, for a few
//! physics steps and solver iteration counts (release mode, one thread):
//!
//! `cargo bench -p physics --bench physics [-- CLIP.amc|CLIP.bvh [SKELETON.asf]]`
//!
//! Default clip: the HDM05 kick `HDM_bd_kickLFront1Reps_001_120.amc`.
//! Environment knobs for the measurements in `physics::sim`:
//! `PHYSICS_BENCH_CONFIGS=60:1:10,120:4:1` (step rate : solver substeps
//! [: PGS passes per substep, else `PHYSICS_BENCH_PGS` or the default]),
//! `PHYSICS_BENCH_ARMATURE=0.05`, `PHYSICS_BENCH_STAB=1`, `PHYSICS_BENCH_PGS=10`,
//! `PHYSICS_BENCH_PD=motor|stable|explicit`. Each line also prints the physics
//! steps run, so CPU time from `perf stat -e task-clock` can be put per step.
use std::path::PathBuf;

use motion::io::{LoadOptions, load};

fn main() {
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let clip = args
        .first()
        .map(PathBuf::from)
        .unwrap_or_else(|| data.join("hdm05/HDM_bd_kickLFront1Reps_001_120.amc"));
    let skeleton = args.get(1).map(PathBuf::from).or_else(|| {
        (clip.extension().is_some_and(|e| e == "amc")).then(|| {
            let name = clip
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .to_string();
            let actor = name.split('_').nth(1).unwrap_or("bd").to_string();
            clip.with_file_name(format!("HDM_{actor}.asf"))
        })
    });
    let motion = match load(
        &clip,
        &LoadOptions {
            skeleton,
            ..Default::default()
        },
    ) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let configs: Vec<(f32, usize, Option<usize>)> = match std::env::var("PHYSICS_BENCH_CONFIGS") {
        Ok(s) => s
            .split(',')
            .filter_map(|c| {
                let mut parts = c.split(':');
                let hz = parts.next()?.parse::<f32>().ok()?;
                let it = parts.next()?.parse().ok()?;
                let pgs = match parts.next() {
                    Some(p) => Some(p.parse().ok()?),
                    None => None,
                };
                Some((1.0 / hz, it, pgs))
            })
            .collect(),
        // The default configuration first, then the former default (1/120 s,
        // 4 substeps of one pass) and one substep of 10 passes for comparison.
        Err(_) => vec![
            (1.0 / 60.0, 2, None),
            (1.0 / 120.0, 4, Some(1)),
            (1.0 / 60.0, 1, Some(10)),
        ],
    };
    println!("clip {} ({:.2} s)", clip.display(), motion.duration_s());
    for (dt, iters, pgs) in configs {
        let mut cfg = physics::Config::default();
        cfg.sim.dt = dt;
        cfg.sim.solver_iterations = iters;
        if let Ok(v) = std::env::var("PHYSICS_BENCH_ARMATURE") {
            cfg.sim.min_inertia = v.parse().unwrap_or(0.0);
        }
        if let Ok(v) = std::env::var("PHYSICS_BENCH_STAB") {
            cfg.sim.stabilization_iterations = v.parse().unwrap_or(1);
        }
        if let Ok(v) = std::env::var("PHYSICS_BENCH_PGS") {
            cfg.sim.pgs_iterations = v.parse().unwrap_or(cfg.sim.pgs_iterations);
        }
        if let Some(p) = pgs {
            cfg.sim.pgs_iterations = p;
        }
        cfg.residual_every_substep = std::env::var("PHYSICS_BENCH_RESIDUAL_EVERY_STEP").is_ok();
        cfg.sim.pd = match std::env::var("PHYSICS_BENCH_PD").as_deref() {
            Ok("stable") => physics::sim::PdMode::StableTorque,
            Ok("explicit") => physics::sim::PdMode::Explicit,
            _ => physics::sim::PdMode::Motor,
        };
        match physics::bench::bench_physics_for(&motion, &cfg, 2.0) {
            Ok(r) => println!(
                "dt 1/{:.0} iters {:2} pgs {:2}: {:6.1} sim s/wall s, {:6.1} us/step, joint error {:.4} rad, falls {} in {} passes, r_imit {:.3}, residual force ratio {:.3}, {} physics steps",
                1.0 / r.dt,
                r.solver_iterations,
                r.pgs_iterations,
                r.sim_seconds_per_wall_second,
                r.us_per_physics_step,
                r.mean_joint_error_rad,
                r.falls,
                r.passes,
                r.mean_imitation_reward,
                r.residual_force_ratio,
                r.physics_steps
            ),
            Err(e) => println!("dt {dt}: {e}"),
        }
    }
}
