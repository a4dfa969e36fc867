//! Debiasing (MotionAug Sec. 3.4).
//!
//! Physical correction changes a clip in systematic ways (the simulated body is
//! not the actor's, the PD servos lag, the feet are boxes), so corrected clips
//! drift from the captured style. Debiasing learns that drift from pairs
//! (an original clip after correction -> the original clip) with a per-frame MLP
//! and removes it from corrected synthesised clips.
//!
//! * [`features`]: the per-frame input (root height, root velocity in the
//!   heading frame, 6D joint rotations, and their frame differences) and the
//!   output (a correction of the rotations), and back to a clip that keeps the
//!   corrected root path.
//! * [`contacts`]: after the network, the corrected clip's planted feet are put
//!   back with leg IK, so debiasing does not bring back skating and floating,
//!   and planted feet hanging above the floor (a sample tracked standing on its
//!   heels) are pitched onto the sole height learnt from the training pairs.
//! * [`model`]: the MLP (4 x 512 ReLU in the paper), an `nn::Mlp`.
//! * [`train`]: fitting the MLP on pairs (the `nn` crate's seeded initialisation
//!   and AdamW); [`Debiaser`] applies, saves and loads it.

pub mod contacts;
pub mod features;
pub mod model;
pub mod train;

pub use contacts::{ContactConfig, ContactReport};
pub use nn::MlpConfig;
pub use train::{Debiaser, TrainConfig, TrainReport, train};

#[derive(Debug, thiserror::Error)]
pub enum DebiasError {
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error(transparent)]
    Nn(#[from] nn::NnError),
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Model {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("{0}")]
    Data(String),
    #[error("invalid debias settings: {0}")]
    Config(String),
}

pub type Result<T> = std::result::Result<T, DebiasError>;
