//! Errors of the interaction crate: each names the clip, joint or option at fault.

use motion::MotionError;

#[derive(Debug, thiserror::Error)]
pub enum InteractionError {
    #[error(transparent)]
    Motion(#[from] MotionError),
    /// The two clips of a pair cannot be used together.
    #[error("clips A and B do not form a pair: {0}")]
    Pair(String),
    /// A bone scale is unusable (not positive, unknown joint, ...).
    #[error("bad bone scale: {0}")]
    Scale(String),
    /// A key joint pair names a joint that does not exist or is unusable.
    #[error("bad key joint pair: {0}")]
    KeyPair(String),
    /// An option is out of range.
    #[error("bad option `{field}`: {message}")]
    Option {
        field: &'static str,
        message: String,
    },
    /// The solver produced non-finite numbers (should not happen; reported, not hidden).
    #[error("solver failed at frame {frame}: {message}")]
    Solver { frame: usize, message: String },
}
