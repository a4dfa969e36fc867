//! V-DMGNN-GAN (Bannadabhavi et al. 2022, "V-DMGNN-GAN: spatial inpainting for
//! human motion prediction"): DMGNN made variational and adversarial, for
//! predicting full future poses from occluded past poses.
//!
//! * Generator: DMGNN's multi-scale encoder ([`MultiScaleEncoder`]) on the
//!   (masked) positions (and, with `vel_acc`, velocities and accelerations: the
//!   Table 2 ablation), one more temporal convolution, frames averaged, then
//!   per node a mean and a log-variance; a sample `z = mu + exp(logvar / 2) eps`
//!   becomes the graph-GRU decoder's initial state ([`GgruDecoder`]). At test
//!   time the mean is used (the most likely state; the reference samples).
//! * Discriminator ([`Discriminator`]): a graph GRU reads the unmasked observed
//!   frames followed by the real or the generated future; its last state goes
//!   through a graph convolution and two linear layers to one logit.
//! * Losses (paper Eq. 7): reconstruction (L1 or L2) + `lambda_kl` KL +
//!   `lambda_gan` BCE(D(fake), real); the discriminator: BCE on real and fake,
//!   its parameters clipped to +-`clip` after each step; iterations alternate
//!   between the two (the reference's schedule). Table 3's values are the
//!   defaults.

use std::sync::Mutex;

use candle_core::Tensor;
use nn::{Linear, Params, kl_mean, normal, reparameterise};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::predict::body_graph::{BodyGraph, Scale};
use crate::predict::dmgnn::{
    DmgnnConfig, GgruDecoder, MultiScaleEncoder, encoder_channels, encoder_input,
};
use crate::predict::graph_layers::{GraphGru, SpatialConv, TemporalConv, pos_vel_acc};
use crate::predict::{Adversarial, Predictor, l1_or_l2};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VdmgnnConfig {
    /// Encoder and decoder sizes, reconstruction loss, `vel_acc` (the paper's
    /// base model reads positions only: `vel_acc = false`).
    pub dmgnn: DmgnnConfig,
    /// Latent size per node.
    pub latent: usize,
    /// Paper Table 3: 0.1.
    pub lambda_kl: f64,
    /// Paper Table 3: 0.07.
    pub lambda_gan: f64,
    /// Discriminator parameter clipping (Table 3: 0.25).
    pub clip: f32,
    /// Discriminator learning rate (Table 3: 4e-6).
    pub discriminator_lr: f64,
    /// Discriminator graph-GRU state per node.
    pub discriminator_hidden: usize,
}

impl VdmgnnConfig {
    pub fn new(input_frames: usize) -> Self {
        let mut dmgnn = DmgnnConfig::new(input_frames);
        dmgnn.vel_acc = false;
        VdmgnnConfig {
            latent: dmgnn.hidden,
            dmgnn,
            lambda_kl: 0.1,
            lambda_gan: 0.07,
            clip: 0.25,
            discriminator_lr: 4e-6,
            discriminator_hidden: 32,
        }
    }
}

/// The recurrent discriminator.
pub struct Discriminator {
    cell: GraphGru,
    gcn: SpatialConv,
    per_node: Linear,
    over_nodes: Linear,
    hidden: usize,
}

impl Discriminator {
    fn new(p: &Params, graph: &BodyGraph, hidden: usize) -> Result<Self> {
        Ok(Discriminator {
            cell: GraphGru::new(p, "disc.cell", graph, 9, hidden)?,
            gcn: SpatialConv::new(p, "disc.gcn", graph, Scale::Joints, hidden, hidden / 2 + 1)?,
            per_node: Linear::new(p, "disc.per_node", hidden / 2 + 1, 1)?,
            over_nodes: Linear::new(p, "disc.over_nodes", graph.nodes(), 1)?,
            hidden,
        })
    }

    /// One logit per sequence `(B, T, V, 3)` -> `(B, 1)`.
    fn forward(&self, seq: &Tensor) -> Result<Tensor> {
        let (b, t, v, _) = seq.dims4()?;
        let mut h = Tensor::zeros((b, v, self.hidden), seq.dtype(), seq.device())?;
        let frame = |i: usize| -> Result<Tensor> { Ok(seq.narrow(1, i, 1)?.squeeze(1)?) };
        let zero = frame(0)?.zeros_like()?;
        let (mut p2, mut p1) = (zero.clone(), zero);
        for i in 0..t {
            let p0 = frame(i)?;
            h = self.cell.step(&pos_vel_acc(&p2, &p1, &p0)?, &h)?;
            (p2, p1) = (p1, p0);
        }
        let y = candle_nn::ops::leaky_relu(&self.gcn.forward(&h)?, 0.2)?;
        let y = candle_nn::ops::leaky_relu(&self.per_node.forward(&y)?, 0.2)?;
        Ok(self.over_nodes.forward(&y.reshape((b, v))?)?)
    }
}

pub struct Vdmgnn {
    config: VdmgnnConfig,
    nodes: usize,
    encoder: MultiScaleEncoder,
    temporal: TemporalConv,
    to_mean: Linear,
    to_logvar: Linear,
    to_state: Linear,
    decoder: GgruDecoder,
    discriminator: Discriminator,
    params: Params,
    disc_params: Params,
    rng: Mutex<ChaCha8Rng>,
}

impl Vdmgnn {
    pub fn new(config: &VdmgnnConfig, graph: &BodyGraph, seed: u64) -> Result<Self> {
        config.dmgnn.validate()?;
        if config.latent == 0 || config.discriminator_hidden == 0 {
            return Err(EvalError::Config("vdmgnn: sizes must be positive".into()));
        }
        let c = &config.dmgnn;
        let p = Params::new(seed);
        let encoder = MultiScaleEncoder::new(&p, "enc", graph, c, encoder_channels(c.vel_acc))?;
        let c4 = c.channels[3];
        let disc_params = Params::new(seed ^ 0xd15c);
        Ok(Vdmgnn {
            temporal: TemporalConv::new(&p, "temporal", c4, c4, 5, 1)?,
            to_mean: Linear::new(&p, "to_mean", c4, config.latent)?,
            to_logvar: Linear::new(&p, "to_logvar", c4, config.latent)?,
            to_state: Linear::new(&p, "to_state", config.latent, c.hidden)?,
            decoder: GgruDecoder::new(&p, "dec", graph, c.hidden)?,
            discriminator: Discriminator::new(&disc_params, graph, config.discriminator_hidden)?,
            encoder,
            nodes: graph.nodes(),
            config: config.clone(),
            params: p,
            disc_params,
            rng: Mutex::new(ChaCha8Rng::seed_from_u64(seed ^ 0x1a7e)),
        })
    }

    pub fn config(&self) -> &VdmgnnConfig {
        &self.config
    }

    fn nodes_of(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        if d != 3 * self.nodes || t != self.config.dmgnn.input_frames {
            return Err(EvalError::Config(format!(
                "vdmgnn: built for {} frames of {} features, got {t} of {d}",
                self.config.dmgnn.input_frames,
                3 * self.nodes
            )));
        }
        Ok(x.reshape((b, t, self.nodes, 3))?)
    }

    /// Per-node latent mean and log-variance `(B, V, Z)` of observed `(B, T, V, 3)`.
    fn encode(&self, x: &Tensor) -> Result<(Tensor, Tensor)> {
        let (_, seq) = self
            .encoder
            .forward(&encoder_input(x, self.config.dmgnn.vel_acc)?)?;
        let h = self.temporal.forward(&seq)?.relu()?.mean(1)?;
        Ok((self.to_mean.forward(&h)?, self.to_logvar.forward(&h)?))
    }

    fn decode(&self, x: &Tensor, z: &Tensor, frames: usize) -> Result<Tensor> {
        let h = self.to_state.forward(z)?.relu()?;
        self.decoder.forward(x, &h, frames)
    }

    /// Generated future `(B, F, V, 3)` with a sampled latent, and `(mu, logvar)`.
    fn generate(&self, x: &Tensor, frames: usize) -> Result<(Tensor, Tensor, Tensor)> {
        let (mu, logvar) = self.encode(x)?;
        let eps = {
            let mut rng = self
                .rng
                .lock()
                .map_err(|_| EvalError::Config("vdmgnn: noise generator poisoned".into()))?;
            normal(mu.dims(), &mut *rng)?
        };
        let z = reparameterise(&mu, &logvar, &eps)?;
        Ok((self.decode(x, &z, frames)?, mu, logvar))
    }

    fn flat(&self, y: &Tensor) -> Result<Tensor> {
        let (b, f, _, _) = y.dims4()?;
        Ok(y.reshape((b, f, 3 * self.nodes))?)
    }

    /// The discriminator's logit for the clean observed frames and a future,
    /// both `(B, T, 3V)`.
    fn judge(&self, clean: &Tensor, future: &Tensor) -> Result<Tensor> {
        let seq = Tensor::cat(&[clean, future], 1)?;
        let (b, t, _) = seq.dims3()?;
        self.discriminator
            .forward(&seq.reshape((b, t, self.nodes, 3))?)
    }
}

/// Binary cross-entropy with logits against a constant label.
fn bce(logits: &Tensor, label: f64) -> Result<Tensor> {
    // max(x, 0) - x y + log(1 + exp(-|x|))
    let pos = logits.relu()?;
    let soft = ((logits.abs()? * -1.0)?.exp()? + 1.0)?.log()?;
    Ok(((pos - (logits * label)?)? + soft)?.mean_all()?)
}

impl Predictor for Vdmgnn {
    /// Reconstruction + KL (the generator's loss without the adversary).
    fn loss(&self, input: &Tensor, target: &Tensor) -> Result<Tensor> {
        let x = self.nodes_of(input)?;
        let (y, mu, logvar) = self.generate(&x, target.dim(1)?)?;
        let rec = l1_or_l2(self.config.dmgnn.loss, &self.flat(&y)?, target)?;
        Ok((rec + (kl_mean(&mu, &logvar)? * self.config.lambda_kl)?)?)
    }

    fn predict(&self, input: &Tensor, frames: usize) -> Result<Tensor> {
        let x = self.nodes_of(input)?;
        let (mu, _) = self.encode(&x)?;
        self.flat(&self.decode(&x, &mu, frames)?)
    }

    fn params(&self) -> &Params {
        &self.params
    }

    fn adversarial(&self) -> Option<&dyn Adversarial> {
        Some(self)
    }
}

impl Adversarial for Vdmgnn {
    fn generator_loss(&self, clean: &Tensor, masked: &Tensor, target: &Tensor) -> Result<Tensor> {
        let x = self.nodes_of(masked)?;
        let (y, mu, logvar) = self.generate(&x, target.dim(1)?)?;
        let fake = self.flat(&y)?;
        let rec = l1_or_l2(self.config.dmgnn.loss, &fake, target)?;
        let kl = kl_mean(&mu, &logvar)?;
        let adv = bce(&self.judge(clean, &fake)?, 1.0)?;
        Ok(((rec + (kl * self.config.lambda_kl)?)? + (adv * self.config.lambda_gan)?)?)
    }

    fn discriminator_loss(
        &self,
        clean: &Tensor,
        masked: &Tensor,
        target: &Tensor,
    ) -> Result<Tensor> {
        let x = self.nodes_of(masked)?;
        let (y, _, _) = self.generate(&x, target.dim(1)?)?;
        let fake = self.flat(&y)?.detach();
        let real = bce(&self.judge(clean, target)?, 1.0)?;
        let fake = bce(&self.judge(clean, &fake)?, 0.0)?;
        Ok(((real + fake)? * 0.5)?)
    }

    fn discriminator_params(&self) -> &Params {
        &self.disc_params
    }

    fn discriminator_lr(&self) -> f64 {
        self.config.discriminator_lr
    }

    fn clip(&self) -> f32 {
        self.config.clip
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn generator_and_discriminator_losses_reach_their_own_parameters() {
        let g = crate::predict::test_support::hdm05_graph();
        let mut cfg = VdmgnnConfig::new(10);
        cfg.dmgnn.channels = [4, 8, 8, 8];
        cfg.dmgnn.hidden = 8;
        cfg.dmgnn.embed = 8;
        cfg.latent = 6;
        cfg.discriminator_hidden = 6;
        let m = Vdmgnn::new(&cfg, &g, 4).unwrap();
        let d = 3 * g.nodes();
        let x = Tensor::randn(0f32, 1.0, (2, 10, d), &Device::Cpu).unwrap();
        let y = Tensor::randn(0f32, 1.0, (2, 5, d), &Device::Cpu).unwrap();
        // Prediction uses the latent mean: deterministic.
        let a: Vec<f32> = m
            .predict(&x, 5)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let b: Vec<f32> = m
            .predict(&x, 5)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert_eq!(a, b);
        let gl = m.generator_loss(&x, &x, &y).unwrap();
        let grads = gl.backward().unwrap();
        for (name, v) in m.params().vars() {
            assert!(
                grads.get(v.as_tensor()).is_some(),
                "generator: no gradient for {name}"
            );
        }
        let dl = m.discriminator_loss(&x, &x, &y).unwrap();
        let dv: f32 = dl.to_scalar().unwrap();
        assert!(dv.is_finite() && dv > 0.0);
        let grads = dl.backward().unwrap();
        for (name, v) in m.discriminator_params().vars() {
            assert!(
                grads.get(v.as_tensor()).is_some(),
                "discriminator: no gradient for {name}"
            );
        }
        // The fake branch is detached: no generator gradient from D's loss.
        let enc = &m.params().vars()[0].1;
        assert!(grads.get(enc.as_tensor()).is_none());
    }

    #[test]
    fn bce_matches_the_closed_form() {
        let x = Tensor::new(&[[0.0f32], [2.0]], &Device::Cpu).unwrap();
        let one: f32 = bce(&x, 1.0).unwrap().to_scalar().unwrap();
        let want = ((2f32).ln() + (1.0 + (-2f32).exp()).ln()) / 2.0;
        assert!((one - want).abs() < 1e-6);
    }
}
