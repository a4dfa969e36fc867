//! The actor: a Gaussian policy whose mean is an MLP of the normalised observation and
//! whose log standard deviation is a per-dimension constant (fixed, as in RFC, or
//! learnable). The last layer starts near zero so the untrained policy's mean action is
//! about 0, which for residual-action environments means "track the reference".

use candle_core::{Tensor, Var};
use nn::{Mlp, MlpConfig, MlpInit, Params};
use serde::{Deserialize, Serialize};

use crate::error::Result;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyConfig {
    pub hidden: Vec<usize>,
    /// Initial (or fixed) log standard deviation of every action dimension.
    pub log_std: f32,
    pub learn_log_std: bool,
    /// Scale of the output layer's initial weights (bias starts at 0).
    pub init_output_scale: f32,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig {
            hidden: vec![512, 256],
            log_std: -2.3,
            learn_log_std: false,
            init_output_scale: 0.01,
        }
    }
}

pub struct GaussianPolicy {
    mean_net: Mlp,
    /// Shape `[act_dim]`; a `Var` only when learnable.
    log_std: LogStd,
    act_dim: usize,
    /// `policy.mean.<layer>.weight|bias` (and `policy.log_std` when learned).
    vars: Vec<(String, Var)>,
}

enum LogStd {
    Fixed(Tensor),
    Learned(Var),
}

const LN_2PI: f64 = 1.837_877_066_409_345_3;

impl GaussianPolicy {
    /// Registers its parameters in `p` under `policy.` (the store must not hold
    /// other `policy.` names).
    pub fn new(cfg: &PolicyConfig, obs_dim: usize, act_dim: usize, p: &Params) -> Result<Self> {
        let mlp = MlpConfig {
            init: MlpInit::ScaledOutput {
                scale: cfg.init_output_scale,
            },
            ..MlpConfig::new(obs_dim, &cfg.hidden, act_dim)
        };
        let mean_net = Mlp::new(&mlp, p, "policy.mean")?;
        let log_std = if cfg.learn_log_std {
            p.constant("policy.log_std", &[act_dim], cfg.log_std)?;
            let var = p
                .get("policy.log_std")
                .ok_or_else(|| crate::PpoError::Config("policy.log_std not registered".into()))?;
            LogStd::Learned(var)
        } else {
            LogStd::Fixed(Tensor::from_vec(
                vec![cfg.log_std; act_dim],
                act_dim,
                &candle_core::Device::Cpu,
            )?)
        };
        Ok(GaussianPolicy {
            mean_net,
            log_std,
            act_dim,
            vars: p.with_prefix(&["policy."]),
        })
    }

    /// Mean action `[batch, act_dim]` for normalised observations `[batch, obs_dim]`.
    pub fn forward(&self, obs: &Tensor) -> Result<Tensor> {
        Ok(self.mean_net.forward(obs)?)
    }

    pub fn log_std(&self) -> &Tensor {
        match &self.log_std {
            LogStd::Fixed(t) => t,
            LogStd::Learned(v) => v.as_tensor(),
        }
    }

    /// Log-density of `act` under the policy at `obs`: shape `[batch]`.
    pub fn log_prob(&self, obs: &Tensor, act: &Tensor) -> Result<Tensor> {
        let mean = self.forward(obs)?;
        let log_std = self.log_std();
        let z = act.sub(&mean)?.broadcast_mul(&log_std.neg()?.exp()?)?;
        let quad = z.sqr()?.sum(1)?.affine(-0.5, 0.0)?;
        let norm = log_std
            .sum_all()?
            .affine(1.0, 0.5 * LN_2PI * self.act_dim as f64)?;
        Ok(quad.broadcast_sub(&norm)?)
    }

    /// Differential entropy of the action distribution (a scalar).
    pub fn entropy(&self) -> Result<Tensor> {
        let c = 0.5 * (1.0 + LN_2PI) * self.act_dim as f64;
        Ok(self.log_std().sum_all()?.affine(1.0, c)?)
    }

    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// All trainable parameters with stable names.
    pub fn vars(&self) -> Vec<(String, Var)> {
        self.vars.clone()
    }
}
