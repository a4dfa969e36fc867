//! MotionAug's motion VAE (Sec. 3.1) on candle, CPU.
//!
//! Train one model per action class on 30 fps clips ([`train()`]), then sample new
//! clips from the N(0, I) prior or by "sampling near samples"
//! ([`TrainedVae::sample`]). Models save to a directory (safetensors + JSON).
//!
//! * [`features`]: motion <-> per-frame vectors (root position + 6D rotations),
//!   reusable by debiasing and evaluation code.
//! * [`frames`]: the valid frames of a padded batch, so per-frame layers skip
//!   the padding.
//! * [`lstm`]: LSTM / BiLSTM with one fused input projection per sequence.
//! * [`model`]: encoder, decoder, frame and sequence discriminators, built from
//!   the `nn` crate's seeded parameters, Linear, MLP and LayerNorm.
//! * [`loss`], [`train`]: losses and the training loop (the `nn` crate's
//!   SGD/Adam optimiser and KL term).
//! * [`feet`]: forward kinematics of the foot points (or of every joint, for
//!   the pose speed of mixed decodes) on tensors, and the foot terms (foot position and velocity against the capture; skating and floor
//!   penetration of clips decoded from codes mixed between training clips).
//! * [`balance`]: the zero moment point of the simulated character's masses
//!   against its soles, on tensors (the mixed-balance term).
//! * [`latent`]: PCA + k-means clustering of training posteriors, near sampling.
//! * [`trained`]: a trained model: encode, decode, sample, save, load.

pub mod balance;
pub mod data;
pub mod error;
pub mod features;
pub mod feet;
pub mod frames;
pub mod latent;
pub mod loss;
pub mod lstm;
mod lstm_op;
mod mat3;
pub mod model;
pub mod normalize;
pub mod train;
pub mod trained;

pub use balance::BalanceModel;
pub use error::{Result, VaeError};
pub use features::{FeatureConfig, FloorLevel};
pub use feet::FootLoss;
pub use latent::{NearConfig, Prior};
pub use model::VaeConfig;
pub use nn::OptimizerConfig;
pub use train::{Losses, Progress, TrainConfig, Trainer, train};
pub use trained::{Finish, ReconstructionError, Sample, TrainedVae};
