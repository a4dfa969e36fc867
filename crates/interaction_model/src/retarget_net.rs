//! The retargeting network p(q'_B | B_s, q̂_B) (paper Eq. 2, Fig. 2): B's new
//! motion as offsets from the template motion, given B's bone scales.
//!
//! ```text
//! encoder:  z ~ N(mu, sigma),  (mu, log sigma^2) = FC(ST-GCN1(Δq_B, B_s), q̂_B^0, q̂_B^T)
//! decoder:  Δq'_B = G-GRU1(z, q̂_B^0, q̂_B^T, B_s)
//! ```
//!
//! The decoder's initial hidden state comes from a global code `g = FC(z,
//! q̂^0, q̂^T, B_s)` and each node's first and last template positions and
//! scale. One deviation from the paper, which gives the decoder only the
//! first and last template frames: each frame's G-GRU input is that frame's
//! template positions (with the node's scale and `g`), so the network predicts
//! an offset *of a given pose*; with three captured interactions this is what
//! lets it generalise across windows and interactions. Positions are in the
//! window's canonical frame (see [`crate::dataset`]), metres.

use candle_core::Tensor;
use candle_nn::{Linear, Module, VarBuilder};
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::ggru::{GGruConfig, GGruDecoder};
use crate::graph::cat;
use crate::stgcn::{StGcn, StGcnConfig};
use nn::reparameterise;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RetargetNetConfig {
    /// Graph nodes of B's body.
    pub nodes: usize,
    pub latent: usize,
    pub encoder: StGcnConfig,
    /// G-GRU hidden size per node.
    pub hidden: usize,
    /// Size of the global code `g`.
    pub global: usize,
}

impl RetargetNetConfig {
    pub fn new(nodes: usize) -> Self {
        RetargetNetConfig {
            nodes,
            latent: 32,
            encoder: StGcnConfig::new(4, &[16, 32, 32]),
            hidden: 32,
            global: 32,
        }
    }
}

pub struct RetargetNet {
    encoder: StGcn,
    mu: Linear,
    logvar: Linear,
    global: Linear,
    init: Linear,
    decoder: GGruDecoder,
    pub config: RetargetNetConfig,
}

/// Encoder output and decoded offsets.
pub struct RetargetOutput {
    pub delta: Tensor,
    pub mu: Tensor,
    pub logvar: Tensor,
}

/// First and last frames of `x` `[n, T, V, 3]` as `([n, V, 3], [n, V, 3])`.
pub fn endpoints(x: &Tensor) -> Result<(Tensor, Tensor)> {
    let t = x.dim(1)?;
    Ok((
        x.narrow(1, 0, 1)?.squeeze(1)?,
        x.narrow(1, t - 1, 1)?.squeeze(1)?,
    ))
}

/// `[n, V, c]` -> `[n, V * c]`.
pub fn flat(x: &Tensor) -> Result<Tensor> {
    Ok(x.flatten_from(1)?)
}

impl RetargetNet {
    pub fn new(vb: VarBuilder, config: &RetargetNetConfig, parents: &[i32]) -> Result<Self> {
        let v = config.nodes;
        let e = config.encoder.out_dim();
        Ok(RetargetNet {
            encoder: StGcn::new(vb.pp("stgcn1"), &config.encoder, parents)?,
            mu: candle_nn::linear(e + 6 * v, config.latent, vb.pp("mu"))?,
            logvar: candle_nn::linear(e + 6 * v, config.latent, vb.pp("logvar"))?,
            global: candle_nn::linear(config.latent + 7 * v, config.global, vb.pp("global"))?,
            init: candle_nn::linear(config.global + 7, config.hidden, vb.pp("init"))?,
            decoder: GGruDecoder::new(
                vb.pp("ggru1"),
                &GGruConfig {
                    input: 4,
                    node: config.global + 1,
                    frame: 0,
                    hidden: config.hidden,
                    output: 3,
                },
                parents,
            )?,
            config: config.clone(),
        })
    }

    /// `delta` `[n, T, V, 3]`, `template` `[n, T, V, 3]`, `scales` `[n, V]` -> `(mu, logvar)`.
    pub fn encode(
        &self,
        delta: &Tensor,
        template: &Tensor,
        scales: &Tensor,
    ) -> Result<(Tensor, Tensor)> {
        let (n, t, v, _) = delta.dims4()?;
        let s = scales.reshape((n, 1, v, 1))?.broadcast_as((n, t, v, 1))?;
        let h = self.encoder.forward(&cat(&[delta, &s], 3)?)?;
        let (q0, qt) = endpoints(template)?;
        let x = cat(&[&h, &flat(&q0)?, &flat(&qt)?], 1)?;
        Ok((
            self.mu.forward(&x)?,
            self.logvar.forward(&x)?.clamp(-10.0, 10.0)?,
        ))
    }

    /// Offsets `[n, T, V, 3]` from codes `z` `[n, latent]`.
    pub fn decode(&self, z: &Tensor, template: &Tensor, scales: &Tensor) -> Result<Tensor> {
        let (n, t, v, _) = template.dims4()?;
        let (q0, qt) = endpoints(template)?;
        let g = self
            .global
            .forward(&cat(&[z, &flat(&q0)?, &flat(&qt)?, scales], 1)?)?
            .relu()?;
        let s = scales.reshape((n, v, 1))?;
        let gv = g
            .reshape((n, 1, self.config.global))?
            .broadcast_as((n, v, self.config.global))?;
        let node = cat(&[&gv, &s], 2)?;
        let h0 = self.init.forward(&cat(&[&node, &q0, &qt], 2)?)?.tanh()?;
        let st = s.reshape((n, 1, v, 1))?.broadcast_as((n, t, v, 1))?;
        let data = cat(&[template, &st], 3)?;
        self.decoder.unroll(&h0, &data, &node, None)
    }

    /// Training pass: encode the true offsets, sample `z` with noise `eps`, decode.
    pub fn forward(
        &self,
        delta: &Tensor,
        template: &Tensor,
        scales: &Tensor,
        eps: &Tensor,
    ) -> Result<RetargetOutput> {
        let (mu, logvar) = self.encode(delta, template, scales)?;
        let z = reparameterise(&mu, &logvar, eps)?;
        Ok(RetargetOutput {
            delta: self.decode(&z, template, scales)?,
            mu,
            logvar,
        })
    }
}
