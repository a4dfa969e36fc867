//! Errors of the synthesis crate.
//!
//! Recipe errors name the op (by index and kind) and the field that is wrong, so
//! a CLI user or an HTTP client can fix the recipe without guessing.

use motion::MotionError;

#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A parameter value is out of range or inconsistent (`what` names the field).
    #[error("invalid parameter `{field}`: {message}")]
    InvalidParam { field: String, message: String },
    /// The recipe text or structure is wrong; `location` is e.g. `ops[2] (ik)`.
    #[error("recipe: {location}: {message}")]
    Recipe { location: String, message: String },
    /// The clip's skeleton lacks something the op needs (feet, a left/right pair...).
    #[error("skeleton: {0}")]
    Skeleton(String),
    /// An op failed on one clip.
    #[error("{clip}: ops[{index}] ({op}): {source}")]
    InOp {
        clip: String,
        index: usize,
        op: &'static str,
        #[source]
        source: Box<SynthError>,
    },
    /// Building the output motion failed validation.
    #[error(transparent)]
    Motion(#[from] MotionError),
}

impl SynthError {
    pub(crate) fn param(field: &str, message: impl Into<String>) -> Self {
        SynthError::InvalidParam {
            field: field.to_string(),
            message: message.into(),
        }
    }
}
