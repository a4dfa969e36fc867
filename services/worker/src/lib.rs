//! The motionaug worker: a stateless process that claims jobs from the
//! coordinator over HTTP, runs them with the library crates, heartbeats while it
//! works, uploads results and checkpoints, and on SIGTERM hands its jobs back.
//!
//! * [`config`]: settings from the environment.
//! * [`client`]: the coordinator's internal worker API.
//! * [`runner`]: claim loop, heartbeats, cancellation and shutdown.
//! * [`synthesize`]: the `synthesize` job (kinematic synthesis of one clip).
//! * [`stages`]: every other job kind of the augmentation's graph (VAE,
//!   interaction, physical correction, debiasing).

pub mod client;
pub mod config;
pub mod runner;
pub mod stages;
pub mod synthesize;

pub use config::WorkerConfig;
pub use runner::run;
