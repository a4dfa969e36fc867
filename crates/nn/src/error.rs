//! The crate's error type: tensor failures, bad settings and parameter-store
//! problems (a name registered twice, a saved tensor missing or of the wrong shape).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum NnError {
    #[error("tensor operation failed: {0}")]
    Candle(#[from] candle_core::Error),
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("parameter `{0}` registered twice")]
    Duplicate(String),
    #[error("{path}: {msg}")]
    File { path: PathBuf, msg: String },
    #[error("{0}")]
    State(String),
}

pub type Result<T> = std::result::Result<T, NnError>;
