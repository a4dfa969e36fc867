//! The debiasing network: a per-frame `nn::Mlp` (ReLU hidden layers, linear
//! output; the paper uses 4 hidden layers of 512), its layers named
//! `layer{i}.weight` / `layer{i}.bias` as in the model files written before the
//! `nn` crate existed, so those files still load.

use nn::{Mlp, MlpConfig, Params};

use crate::Result;

/// The network for `config`, its parameters registered (seeded) in `p`.
pub fn build(config: &MlpConfig, p: &Params) -> Result<Mlp> {
    Ok(Mlp::with_layer_names(config, p, |i| format!("layer{i}"))?)
}
