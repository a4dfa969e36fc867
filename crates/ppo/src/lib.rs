//! Generic proximal policy optimisation (PPO) on candle, CPU only.
//!
//! This crate knows nothing about physics or motion: anything that implements [`Env`]
//! can be trained. The pieces, one per module:
//! - [`env`]: the environment trait the trainer drives,
//! - [`policy`] / [`value`]: the Gaussian actor and the critic (MLPs of the `nn` crate,
//!   initialised from the trainer's seeded generator),
//! - [`normalizer`]: the running observation normaliser,
//! - [`gae`]: advantage estimation with terminal vs truncated episode ends,
//! - [`rollout`]: parallel experience collection across environments,
//! - [`trainer`]: the PPO loop, deterministic evaluation, time budgets and callbacks,
//! - [`checkpoint`]: atomic save / resume of everything the loop needs (the `nn`
//!   optimiser's Adam moments included, so a resumed run is bit for bit the same).

pub mod checkpoint;
pub mod config;
pub mod env;
pub mod error;
pub mod gae;
pub mod normalizer;
pub mod policy;
pub mod rollout;
pub mod trainer;
pub mod value;

pub use checkpoint::{CheckpointMeta, latest_checkpoint};
pub use config::PpoConfig;
pub use env::{Env, EnvRng, StepResult};
pub use error::{PpoError, Result};
pub use normalizer::RunningNorm;
pub use policy::{GaussianPolicy, PolicyConfig};
pub use trainer::{
    Control, CurvePoint, Evaluation, IterationReport, Progress, RunLimits, StopReason, Trainer,
    mean_action,
};
pub use value::{ValueConfig, ValueNet};
