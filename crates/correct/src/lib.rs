//! Physical correction (MotionAug Sec. 3.3): a simulated humanoid learns, with
//! PPO, to imitate a clip under a PD-residual root force; the corrected clip is
//! what the simulated character actually does, never the reference copied through.
//!
//! * [`task`]: the physics imitation environment seen as a [`ppo::Env`].
//! * [`rollout`]: the deterministic whole-clip rollout that yields the corrected
//!   motion and the paper's figures (R_norm, mean reward, residual force ratio).
//! * [`job`]: one correction job: train within a budget, evaluate, checkpoint,
//!   resume, and write the outputs.
//! * [`report`]: `report.json` and the learning-curve SVG.
//!
//! Measured on 2026-11-22 (2-core machine, release build, defaults: [256, 256]
//! nets, 8 envs, 2 threads, 4096 samples per iteration; `motionaug correct
//! CLIP --skeleton examples/data/HDM_bd.asf --out DIR --time-budget 150
//! --target-r-norm 0.99`):
//!
//! | clip | R_norm action 0 -> trained | residual force / m g | samples, wall |
//! |---|---|---|---|
//! | HDM05 bd kick 001 | 0.871 -> 0.923 | 0.087 | 344k, 148 s |
//! | IK kick (ik_kick.toml, seed 1, copy 0) | 0.869 -> 0.910 | 0.097 | 324k, 149 s |
//! | HDM05 bd jog 001 (target 0.8) | 0.599 (falls) -> 0.904 | 0.110 | 86k, 37 s |
//!
//! The corrected clip is at the 30 Hz control rate; plausibility before is
//! measured on the 120 Hz source, so jerk is not comparable across the two.

pub mod job;
pub mod report;
pub mod rollout;
pub mod task;

pub use job::{CorrectConfig, Outcome, correct};
pub use report::Report;
pub use rollout::{Rollout, deterministic_rollout};

#[derive(Debug, thiserror::Error)]
pub enum CorrectError {
    #[error(transparent)]
    Physics(#[from] physics::PhysicsError),
    #[error(transparent)]
    Learning(#[from] ppo::PpoError),
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("invalid correction settings: {0}")]
    Config(String),
}
