//! Errors of the learned interaction model: each names the file, field or data at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    #[error(transparent)]
    Interaction(#[from] interaction::InteractionError),
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error(transparent)]
    Nn(#[from] nn::NnError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    /// The data does not fit (shapes, empty sets, unknown pair, ...).
    #[error("data: {0}")]
    Data(String),
    /// A configuration value is out of range.
    #[error("bad config `{field}`: {message}")]
    Config {
        field: &'static str,
        message: String,
    },
}

pub type Result<T> = std::result::Result<T, ModelError>;

impl ModelError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        ModelError::Io {
            path: path.into(),
            source,
        }
    }
}
