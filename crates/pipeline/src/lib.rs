//! The whole augmentation: a recipe ([`recipe`]) becomes a graph of per-clip
//! jobs that carry their settings ([`plan`]); one executor runs any of them
//! ([`exec`], the science of each kind in [`stages`]); [`run`] walks the graph
//! in one process (the CLI, evaluation), while the service stores the same
//! graph in Postgres and hands its jobs to workers that call the same
//! executor over HTTP inputs.

pub mod balance;
pub mod codec;
pub mod exec;
pub mod manifest;
pub mod plan;
pub mod recipe;
pub mod run;
pub mod stages;

pub use balance::{add_vae_balance_model, vae_balance_model};
pub use codec::{decode_clip, encode_clip};
pub use exec::{Context, Inputs, Made, Outputs, WorkClip, execute};
pub use manifest::{CorrectionSummary, ManifestEntry};
pub use plan::{JobKind, Plan, PlannedJob, corrections, plan};
pub use recipe::{CorrectStep, InteractionStep, PolicyKind, Recipe, ResidualKind, VaeStep};
pub use run::{Clip, Event, Options, Output, Summary, Tune, run, run_plan};

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("recipe: {location}: {message}")]
    Recipe { location: String, message: String },
    #[error("{path}: {source}")]
    InFile {
        path: std::path::PathBuf,
        #[source]
        source: Box<PipelineError>,
    },
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error(transparent)]
    Synth(#[from] synth::SynthError),
    #[error(transparent)]
    Vae(#[from] vae::VaeError),
    #[error(transparent)]
    Interaction(#[from] interaction::InteractionError),
    #[error(transparent)]
    Correct(#[from] correct::CorrectError),
    #[error(transparent)]
    Debias(#[from] debias::DebiasError),
    #[error("{0}")]
    Job(String),
    /// Stopped on request (cancellation, shutdown) before the end.
    #[error("stopped before the end")]
    Stopped,
    /// An input could not be fetched now; trying again later may work.
    #[error("{0}")]
    Unavailable(String),
}
