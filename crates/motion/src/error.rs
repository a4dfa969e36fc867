//! Errors of the motion crate.
//!
//! Parse errors always say which file, which line and what is wrong, so that a
//! user (or the service's problem+json response) can act on them.

use std::fmt;
use std::path::PathBuf;

/// Where in which file a parse error happened and what was wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// File name as given by the caller (may be a label such as an upload name).
    pub file: PathBuf,
    /// 1-based line number, `None` when the problem is not tied to one line.
    pub line: Option<usize>,
    pub message: String,
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}: {}", self.file.display(), line, self.message),
            None => write!(f, "{}: {}", self.file.display(), self.message),
        }
    }
}

impl std::error::Error for ParseError {}

#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    #[error(transparent)]
    Parse(#[from] ParseError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("invalid skeleton: {0}")]
    InvalidSkeleton(String),
    #[error("invalid motion: {0}")]
    InvalidMotion(String),
    #[error("unknown joint `{0}`")]
    UnknownJoint(String),
    #[error("unsupported: {0}")]
    Unsupported(String),
}
