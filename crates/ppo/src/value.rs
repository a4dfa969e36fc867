//! The critic: an MLP from the normalised observation to the state value.

use candle_core::{Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::env::EnvRng;
use crate::error::Result;
use crate::mlp::Mlp;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValueConfig {
    pub hidden: Vec<usize>,
}

impl Default for ValueConfig {
    fn default() -> Self {
        ValueConfig {
            hidden: vec![512, 256],
        }
    }
}

pub struct ValueNet {
    net: Mlp,
}

impl ValueNet {
    pub fn new(cfg: &ValueConfig, obs_dim: usize, rng: &mut EnvRng) -> Result<Self> {
        Ok(ValueNet {
            net: Mlp::new("value", obs_dim, &cfg.hidden, 1, 1.0, rng)?,
        })
    }

    /// State values `[batch]` for normalised observations `[batch, obs_dim]`.
    pub fn forward(&self, obs: &Tensor) -> Result<Tensor> {
        Ok(self.net.forward(obs)?.squeeze(1)?)
    }

    pub fn vars(&self) -> Vec<(String, Var)> {
        self.net.vars().to_vec()
    }
}
