//! Generic proximal policy optimisation (PPO) on candle, CPU only.
//!
//! This crate knows nothing about physics or motion: anything that implements [`Env`]
//! can be trained. The pieces, one per module:
//! - [`env`]: the environment trait the trainer drives,
//! - [`policy`] / [`value`]: the Gaussian actor and the critic (MLPs built from [`mlp`]),
//! - [`normalizer`]: the running observation normaliser,
//! - [`adam`]: Adam whose moment state can be checkpointed exactly,
//! - [`gae`]: advantage estimation with terminal vs truncated episode ends,
//! - [`rollout`]: parallel experience collection across environments,
//! - [`trainer`]: the PPO loop, deterministic evaluation, time budgets and callbacks,
//! - [`checkpoint`]: atomic save / resume of everything the loop needs.

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod env;
pub mod error;
pub mod gae;
pub mod mlp;
pub mod normalizer;
pub mod policy;
pub mod rollout;
pub mod trainer;
pub mod value;

pub use adam::{Adam, AdamConfig};
pub use checkpoint::{CheckpointMeta, latest_checkpoint};
pub use config::PpoConfig;
pub use env::{Env, EnvRng, StepResult};
pub use error::{PpoError, Result};
pub use normalizer::RunningNorm;
pub use policy::{GaussianPolicy, PolicyConfig};
pub use trainer::{
    Control, CurvePoint, Evaluation, IterationReport, Progress, RunLimits, StopReason, Trainer,
};
pub use value::{ValueConfig, ValueNet};
