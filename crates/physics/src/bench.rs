//! Speed and tracking figures of the simulation: the clip tracked with action 0
//! and the PD-residual force, single thread, timed around the stepping only.

use std::time::Instant;

use motion::Motion;
use serde::Serialize;

use crate::PhysicsError;
use crate::env::{Config, ImitationEnv, Residual};

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Simulated seconds per wall-clock second, one thread.
    pub sim_seconds_per_wall_second: f64,
    /// Mean over simulated joints and control frames of the angle between the
    /// simulated and reference relative rotations (radians).
    pub mean_joint_error_rad: f64,
    /// Control steps run (over all passes).
    pub steps: usize,
    pub physics_steps: usize,
    /// Mean wall time of one physics step, microseconds.
    pub us_per_physics_step: f64,
    pub dt: f64,
    pub control_hz: f64,
    /// Rapier substeps per physics step.
    pub solver_iterations: usize,
    /// Velocity (PGS) passes per substep.
    pub pgs_iterations: usize,
    pub bodies: usize,
    /// Passes over the clip (the clip is repeated to time at least `min_wall_s`).
    pub passes: usize,
    /// Falls (a pass that ends in a fall restarts at the next frame).
    pub falls: usize,
    pub mean_imitation_reward: f64,
    /// Mean |F_res| / (body mass * g) over the steps (the report's `residual_force_ratio`).
    pub residual_force_ratio: f64,
}

/// [`bench_physics_for`] timing at least two seconds of stepping.
pub fn bench_physics(motion: &Motion, config: &Config) -> Result<BenchReport, PhysicsError> {
    bench_physics_for(motion, config, 2.0)
}

/// Track `motion` with action 0 and the PD-residual force on, repeating the
/// clip until `min_wall_s` seconds of stepping have been timed. A pass that
/// falls restarts (reference state initialisation) at the next frame.
pub fn bench_physics_for(
    motion: &Motion,
    config: &Config,
    min_wall_s: f64,
) -> Result<BenchReport, PhysicsError> {
    let mut cfg = config.clone();
    cfg.residual = Residual::Pd;
    let mut env = ImitationEnv::new(motion, &cfg)?;
    env.set_recording(false);
    let action = vec![0.0f32; env.act_dim()];
    let substeps = cfg.substeps()?;
    let (mut steps, mut passes, mut falls) = (0usize, 0usize, 0usize);
    let (mut err_sum, mut rew_sum, mut force_sum) = (0.0f64, 0.0f64, 0.0f64);
    let mut wall = 0.0f64;
    while passes == 0 || wall < min_wall_s {
        env.reset(0.0);
        passes += 1;
        loop {
            let t0 = Instant::now();
            let r = env.step(&action)?;
            wall += t0.elapsed().as_secs_f64();
            steps += 1;
            err_sum += env.joint_error() as f64;
            rew_sum += r.r_imit as f64;
            force_sum += r.info.residual_force as f64;
            if r.info.fell() {
                falls += 1;
                let last = env.reference().len() - 1;
                let next = env.frame() + 1;
                if next + 1 >= last {
                    break;
                }
                env.reset(next as f64 / (last - 1) as f64);
                continue;
            }
            if r.done {
                break;
            }
        }
        if passes > 1000 {
            break;
        }
    }
    let sim_s = steps as f64 / cfg.control_hz;
    let physics_steps = steps * substeps;
    Ok(BenchReport {
        sim_seconds_per_wall_second: sim_s / wall.max(1e-12),
        mean_joint_error_rad: err_sum / steps.max(1) as f64,
        steps,
        physics_steps,
        us_per_physics_step: wall * 1e6 / physics_steps.max(1) as f64,
        dt: cfg.sim.dt as f64,
        control_hz: cfg.control_hz,
        solver_iterations: cfg.sim.solver_iterations,
        pgs_iterations: cfg.sim.pgs_iterations,
        bodies: env.spec().bodies.len(),
        passes,
        falls,
        mean_imitation_reward: rew_sum / steps.max(1) as f64,
        residual_force_ratio: force_sum
            / steps.max(1) as f64
            / (env.spec().total_mass as f64 * cfg.sim.gravity as f64),
    })
}
