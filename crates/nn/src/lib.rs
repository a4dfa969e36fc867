//! The neural-net toolkit of the workspace: every crate that trains a network
//! (ppo, vae, debias, eval, interaction-model) builds it from these pieces, in
//! the candle-transformers style (a module is made by `new` from its settings
//! and a parameter store, and has a `forward` that reads top to bottom).
//!
//! * [`params`]: the named, seeded parameter store and the one initialisation
//!   scheme (candle's CPU random ops cannot be seeded); it also backs a candle-nn
//!   `VarBuilder` for modules built with `candle_nn::linear` and friends.
//! * [`linear`], [`mlp`], [`layer_norm`]: the feed-forward layers; [`bias`]:
//!   the row-wise bias add they use, with a backward pass that sums rows in
//!   contiguous memory; [`cpu_op`]: what hand-written candle ops share.
//! * [`optim`]: SGD with a halving schedule and Adam(W), whose state can be saved
//!   and restored bit for bit, and the one gradient-norm clipping function.
//! * [`kl`]: the diagonal Gaussian latent: KL to N(0, I), reparameterisation,
//!   seeded standard normal noise.
//! * [`threads`]: candle's kernels on one thread (its spinning worker pool
//!   costs more than it gives our small networks), set once in `main`.
//!
//! Everything is f32 on the CPU.

pub mod bias;
pub mod cpu_op;
pub mod error;
pub mod kl;
pub mod layer_norm;
pub mod linear;
pub mod mlp;
pub mod optim;
pub mod params;
pub mod threads;

pub use bias::add_bias;
pub use error::{NnError, Result};
pub use kl::{kl_mean, kl_sum, normal, reparameterise};
pub use layer_norm::LayerNorm;
pub use linear::Linear;
pub use mlp::{Mlp, MlpConfig, MlpInit};
pub use optim::{AdamConfig, Clip, Method, Optimizer, OptimizerConfig, clip_grad_norm};
pub use params::Params;
