//! Physical correction (MotionAug Sec. 3.3): a simulated humanoid learns, with
//! PPO, to imitate a clip under a PD-residual root force; the corrected clip is
//! what the simulated character actually does, never the reference copied through.
//!
//! * [`task`]: the physics imitation environment seen as a [`ppo::Env`].
//! * [`rollout`]: the deterministic whole-clip rollout that yields the corrected
//!   motion and the paper's figures (R_norm, mean reward, residual force ratio).
//! * [`acceptance`]: when a corrected clip is physically honest (no fall, mean
//!   reward, residual force, foot skating, feet on their soles), each criterion
//!   judged and reported.
//! * [`job`]: one correction job: train within a budget, evaluate, checkpoint,
//!   resume, and write the outputs.
//! * [`report`]: `report.json` and the learning-curve SVG.
//! * [`summary`]: the corrections of a class in one table (`motionaug bench correction`).
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
//! Measured again on 2026-11-22 (session 2) while three other engineers were
//! building and training on the same two cores (load average about 10, so
//! roughly a fifth of the samples per second above); `--time-budget 600`
//! (`90` for the others), `--target-r-norm 0.99`:
//!
//! | run | R_norm action 0 -> trained | residual force / m g | samples, wall |
//! |---|---|---|---|
//! | kick, PD residual, 600 s | 0.871 -> 0.919 | 0.094 | 319k, 598 s |
//! | kick, PD residual, 90 s | 0.871 -> 0.882 | 0.149 | 41k, 83 s |
//! | kick, no residual (ablation), 90 s | 0.415 (falls at frame 20) -> 0.434 (falls) | 0 | 25k, 83 s |
//! | kick, learned residual (RFC ablation), 90 s | 0.415 (falls) -> 0.445 (falls) | 0.002 | 20k, 95 s |
//! | IK kick from scratch, 90 s | 0.869 -> 0.869 | 0.151 | 16k, 85 s |
//! | IK kick warm-started from the kick's policy, 90 s | 0.869 -> 0.888 (0.88 after one iteration) | 0.146 | 41k, 88 s |
//!
//! Plausibility before -> after (source at 120 Hz, output at 30 Hz; the
//! 30 Hz source gives the same skating, 0.057 m/s): IK kick foot skating
//! 0.263 -> 0.101-0.109 m/s, mean penetration 0.011 -> 0.006-0.007 m, floating
//! 0.25 -> 0; original kick: skating 0.058 -> 0.103 m/s (the planted right foot
//! pivots on the floor where the actor rose onto it; the box foot built from
//! the rest pose is rolled 2.2 rad from flat there, see
//! `physics::CharacterOptions::calibrate_feet`), penetration 0.011 -> 0.006 m,
//! floating 0.25 -> 0.
//!
//! The corrected clip is at the 30 Hz control rate; plausibility before is
//! measured on the source clip at its own rate. These figures were measured
//! when the output kept the input's height (`physics::OutputFrame::Clip`);
//! the default now stands it on y = 0, which moves penetration and floating by
//! the clip's median-frame foot level (a few mm for these clips; 5 cm for VAE
//! samples that sank, see crates/eval/README.md).

pub mod acceptance;
pub mod job;
pub mod report;
pub mod rollout;
pub mod summary;
pub mod task;

pub use acceptance::{AcceptanceConfig, Criterion};
pub use job::{CorrectConfig, Outcome, ResidualSchedule, correct};
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
    #[error("stopped on request before the end of training (a checkpoint was saved)")]
    Stopped,
}
