//! Errors of the VAE crate: every failure names what was wrong (file, field, clip).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum VaeError {
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
    #[error("{path}: invalid JSON: {source}")]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("invalid training data: {0}")]
    Data(String),
    #[error("invalid model file: {0}")]
    Model(String),
}

pub type Result<T> = std::result::Result<T, VaeError>;
