//! Errors of the evaluation crate: each names the clip, file or option at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("tensor operation failed: {0}")]
    Candle(#[from] candle_core::Error),
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error(transparent)]
    Nn(#[from] nn::NnError),
    /// The table's VAE set (training, caching, sampling).
    #[error(transparent)]
    Vae(#[from] vae::VaeError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("invalid data: {0}")]
    Data(String),
    #[error("augmentation failed: {0}")]
    Augmentation(Box<dyn std::error::Error + Send + Sync>),
    #[error("the augmentation pipeline failed: {0}")]
    Pipeline(#[from] pipeline::PipelineError),
    /// The table's physics set corrects the VAE's samples and the IK edits.
    #[error(
        "invalid configuration: the physics set corrects the VAE's samples and the IK edits: add the vae or the ik set"
    )]
    PhysicsNeedsVae,
    #[error("physical correction failed: {0}")]
    Correction(String),
}

pub type Result<T> = std::result::Result<T, EvalError>;
