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
