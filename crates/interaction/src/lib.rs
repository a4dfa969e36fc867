//! Two-person interaction retargeting across body sizes.
//!
//! Given one captured interaction (clips A and B recorded together in one
//! world frame) and a bone scale for B, [`retarget`] produces new motions for
//! both partners: B with exactly the new bone lengths, A with its own, and the
//! spatial relations between the bodies kept (an interaction mesh after Ho,
//! Komura and Tai 2010, see [`solve`]). [`variations`] generates many such
//! variations over a scale range from a seed: the training data for a learned
//! model (Two-Person Interaction Augmentation with Skeleton Priors, Sec. 4).
//!
//! Modules, in pipeline order: [`scale`] (bone scales, naive retarget),
//! [`layout`] (points and rigid distances of a body), [`contact`] (planted feet,
//! key joint pairs), [`pairs`] (which clips are partners), [`solve`] (the optimiser), [`ik`] (rotations from
//! positions), [`retarget`] (one variation and its report), [`dataset`] (many).

pub mod contact;
pub mod dataset;
pub mod error;
pub mod ik;
pub mod layout;
pub mod pairs;
pub mod retarget;
pub mod scale;
pub mod solve;

pub use contact::{KeyPair, KeyPairOptions};
pub use dataset::{Variation, VariationSpec, variations};
pub use error::InteractionError;
pub use pairs::pairs;
pub use retarget::{Report, RetargetOptions, Retargeted, retarget};
pub use scale::BoneScale;
pub use solve::SolverOptions;
