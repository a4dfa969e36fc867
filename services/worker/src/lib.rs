//! The motionaug worker: a stateless process that claims jobs from the
//! coordinator over HTTP, runs them with the library crates, heartbeats while it
//! works, uploads results and checkpoints, and on SIGTERM hands its jobs back.
//!
//! * [`config`]: settings from the environment.
//! * [`client`]: the coordinator's internal worker API.
//! * [`runner`]: claim loop, heartbeats, cancellation and shutdown.
//! * [`jobs`]: running a job with the pipeline's one executor, its inputs
//!   fetched from the coordinator and its outputs uploaded (transport only).
//! * [`transfer`]: downloads and uploads with retries and stop reasons.
//! * [`archive`]: folders (PPO checkpoints, the debiasing model) as zips.

mod archive;
pub mod client;
pub mod config;
pub mod jobs;
pub mod runner;
mod transfer;

pub use config::WorkerConfig;
pub use runner::run;
