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
}

pub type Result<T> = std::result::Result<T, EvalError>;
