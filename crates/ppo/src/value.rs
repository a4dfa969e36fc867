//! The critic: an MLP from the normalised observation to the state value.

use candle_core::{Tensor, Var};
use nn::{Mlp, MlpConfig, MlpInit, Params};
use serde::{Deserialize, Serialize};

use crate::error::Result;

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
    /// `value.<layer>.weight|bias`.
    vars: Vec<(String, Var)>,
}

impl ValueNet {
    /// Registers its parameters in `p` under `value.` (the store must not hold
    /// other `value.` names).
    pub fn new(cfg: &ValueConfig, obs_dim: usize, p: &Params) -> Result<Self> {
        let mlp = MlpConfig {
            init: MlpInit::ScaledOutput { scale: 1.0 },
            ..MlpConfig::new(obs_dim, &cfg.hidden, 1)
        };
        Ok(ValueNet {
            net: Mlp::new(&mlp, p, "value")?,
            vars: p.with_prefix(&["value."]),
        })
    }

    /// State values `[batch]` for normalised observations `[batch, obs_dim]`.
    pub fn forward(&self, obs: &Tensor) -> Result<Tensor> {
        Ok(self.net.forward(obs)?.squeeze(1)?)
    }

    pub fn vars(&self) -> Vec<(String, Var)> {
        self.vars.clone()
    }
}
