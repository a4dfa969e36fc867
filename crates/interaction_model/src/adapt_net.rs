//! The adaptation network p(q'_A | q'_B, q̂_A) (paper Eq. 3, Fig. 3): A's new
//! motion as offsets from A's template, given B's new motion.
//!
//! ```text
//! encoder:  (mu, log sigma^2) = FC(ST-GCN2(Δq_A), q̂_A^0, q̂_A^T, ST-GCN3(q'_B))
//! decoder:  Δq'_A = G-GRU2(z, q̂_A^0, q̂_A^T, q'_B)
//! ```
//!
//! The decoder sees B every frame: a context vector `c_t = FC(q'_B^t,
//! q'_B^t - q̂_B^t)` (where B is and how far it moved from its template) is
//! given to every node of A with A's template frame (the same per-frame
//! template conditioning as [`crate::retarget_net`]). At inference `q'_B` is
//! the retargeting network's output.

use candle_core::Tensor;
use candle_nn::{Linear, Module, VarBuilder};
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::ggru::{GGruConfig, GGruDecoder};
use crate::graph::cat;
use crate::retarget_net::{endpoints, flat};
use crate::stgcn::{StGcn, StGcnConfig};
use nn::reparameterise;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AdaptNetConfig {
    pub nodes_a: usize,
    pub nodes_b: usize,
    pub latent: usize,
    /// ST-GCN2 (A's offsets).
    pub encoder_a: StGcnConfig,
    /// ST-GCN3 (B's new motion).
    pub encoder_b: StGcnConfig,
    pub hidden: usize,
    pub global: usize,
    /// Size of the per-frame context from B.
    pub context: usize,
}

impl AdaptNetConfig {
    pub fn new(nodes_a: usize, nodes_b: usize) -> Self {
        AdaptNetConfig {
            nodes_a,
            nodes_b,
            latent: 32,
            encoder_a: StGcnConfig::new(3, &[16, 32, 32]),
            encoder_b: StGcnConfig::new(3, &[16, 32, 32]),
            hidden: 32,
            global: 32,
            context: 32,
        }
    }
}

pub struct AdaptNet {
    encoder_a: StGcn,
    encoder_b: StGcn,
    mu: Linear,
    logvar: Linear,
    global: Linear,
    init: Linear,
    context: Linear,
    decoder: GGruDecoder,
    pub config: AdaptNetConfig,
}

pub struct AdaptOutput {
    pub delta: Tensor,
    pub mu: Tensor,
    pub logvar: Tensor,
}

impl AdaptNet {
    pub fn new(
        vb: VarBuilder,
        config: &AdaptNetConfig,
        parents_a: &[i32],
        parents_b: &[i32],
    ) -> Result<Self> {
        let (va, vb_n) = (config.nodes_a, config.nodes_b);
        let head_in = config.encoder_a.out_dim() + 6 * va + config.encoder_b.out_dim();
        Ok(AdaptNet {
            encoder_a: StGcn::new(vb.pp("stgcn2"), &config.encoder_a, parents_a)?,
            encoder_b: StGcn::new(vb.pp("stgcn3"), &config.encoder_b, parents_b)?,
            mu: candle_nn::linear(head_in, config.latent, vb.pp("mu"))?,
            logvar: candle_nn::linear(head_in, config.latent, vb.pp("logvar"))?,
            global: candle_nn::linear(config.latent + 6 * va, config.global, vb.pp("global"))?,
            init: candle_nn::linear(config.global + 6, config.hidden, vb.pp("init"))?,
            context: candle_nn::linear(6 * vb_n, config.context, vb.pp("context"))?,
            decoder: GGruDecoder::new(
                vb.pp("ggru2"),
                &GGruConfig {
                    input: 3,
                    node: config.global,
                    frame: config.context,
                    hidden: config.hidden,
                    output: 3,
                },
                parents_a,
            )?,
            config: config.clone(),
        })
    }

    /// `(mu, logvar)` from A's true offsets and B's new motion.
    pub fn encode(
        &self,
        delta_a: &Tensor,
        template_a: &Tensor,
        b_new: &Tensor,
    ) -> Result<(Tensor, Tensor)> {
        let ha = self.encoder_a.forward(delta_a)?;
        let hb = self.encoder_b.forward(b_new)?;
        let (q0, qt) = endpoints(template_a)?;
        let x = cat(&[&ha, &flat(&q0)?, &flat(&qt)?, &hb], 1)?;
        Ok((
            self.mu.forward(&x)?,
            self.logvar.forward(&x)?.clamp(-10.0, 10.0)?,
        ))
    }

    /// A's offsets `[n, T, Va, 3]` from codes `z`, A's template and B's new and template motion.
    pub fn decode(
        &self,
        z: &Tensor,
        template_a: &Tensor,
        b_new: &Tensor,
        template_b: &Tensor,
    ) -> Result<Tensor> {
        let (n, _, v, _) = template_a.dims4()?;
        let (q0, qt) = endpoints(template_a)?;
        let g = self
            .global
            .forward(&cat(&[z, &flat(&q0)?, &flat(&qt)?], 1)?)?
            .relu()?;
        let k = self.config.global;
        let gv = g.reshape((n, 1, k))?.broadcast_as((n, v, k))?;
        let h0 = self.init.forward(&cat(&[&gv, &q0, &qt], 2)?)?.tanh()?;
        let moved = (b_new - template_b)?;
        let per_frame = cat(&[b_new, &moved], 3)?.flatten_from(2)?; // [n, T, 6 Vb]
        let c = self.context.forward(&per_frame)?.relu()?; // [n, T, context]
        self.decoder
            .unroll(&h0, template_a, &gv.contiguous()?, Some(&c))
    }

    pub fn forward(
        &self,
        delta_a: &Tensor,
        template_a: &Tensor,
        b_new: &Tensor,
        template_b: &Tensor,
        eps: &Tensor,
    ) -> Result<AdaptOutput> {
        let (mu, logvar) = self.encode(delta_a, template_a, b_new)?;
        let z = reparameterise(&mu, &logvar, eps)?;
        Ok(AdaptOutput {
            delta: self.decode(&z, template_a, b_new, template_b)?,
            mu,
            logvar,
        })
    }
}
