//! Learned two-person interaction augmentation across body sizes, after
//! "Two-Person Interaction Augmentation with Skeleton Priors" (paper Sec. 3).
//!
//! The joint distribution of B's bone scales and both motions is factorised
//! as `p(q'_A | q'_B, q̂_A) p(q'_B | B_s, q̂_B) p(B_s)` (Eq. 1) and each factor
//! is a network: the skeleton prior ([`prior`]), the retargeting network for
//! B ([`retarget_net`]: [`stgcn`] encoder, [`ggru`] decoder) and the
//! adaptation network for A ([`adapt_net`]). They learn from variations made
//! by the interaction optimiser ([`dataset`], cached on disk), are trained
//! together ([`train`]) and saved with their configuration ([`model`]).
//! The layers, seeded initialisation, optimiser and KL are the `nn` crate's;
//! [`graph`] holds the skeleton-graph helpers.
//! [`generate`] turns predictions into clips; [`variations`] is the one entry
//! point that makes variations of a pair by either method; [`eval`] measures
//! E_r, E_b, JPD and FID (with the feature network of [`features`]) on the
//! paper's four splits.

pub mod adapt_net;
pub mod dataset;
pub mod error;
pub mod eval;
pub mod features;
pub mod generate;
pub mod ggru;
pub mod graph;
pub mod model;
pub mod prior;
pub mod retarget_net;
pub mod stgcn;
pub mod train;
pub mod variations;

pub use dataset::{Dataset, DatasetConfig};
pub use error::{ModelError, Result};
pub use model::InteractionModel;
pub use train::{TrainConfig, train};
pub use variations::{Made, Method, Summary, make_variations};
