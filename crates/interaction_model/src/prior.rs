//! The skeleton prior p(B_s) (paper Sec. 3.2): an MLP VAE over B's bone scale
//! vector. MLP1 (`dim -> 16 -> 32 -> 64 -> 128 -> 256`) encodes to the mean
//! and log variance of a latent code, MLP2 (`latent -> 256 -> 128 -> 64 -> 32
//! -> dim`) decodes. Loss (Eq. 5): squared reconstruction error summed over
//! bones plus the KL divergence to N(0, I).
//!
//! Scales vary by a few per cent around 1, so the network sees them
//! standardised (per bone mean and standard deviation of the training set,
//! kept with the model); [`SkeletonPrior::decode`] returns standardised values.

use candle_core::Tensor;
use candle_nn::{Linear, Module, VarBuilder};
use serde::{Deserialize, Serialize};

use crate::error::Result;
use nn::{Mlp, MlpConfig, kl_sum, reparameterise};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorConfig {
    /// Number of bone scales (B's edges).
    pub dim: usize,
    /// MLP1's layer widths (MLP2 uses them reversed).
    pub hidden: Vec<usize>,
    pub latent: usize,
}

impl PriorConfig {
    /// The paper's widths for `dim` bones and a 16-number latent code.
    pub fn paper(dim: usize) -> Self {
        PriorConfig {
            dim,
            hidden: vec![16, 32, 64, 128, 256],
            latent: 16,
        }
    }
}

pub struct SkeletonPrior {
    pub config: PriorConfig,
    encoder: Mlp,
    mu: Linear,
    logvar: Linear,
    decoder: Mlp,
}

/// What one forward pass gives.
pub struct PriorOutput {
    pub reconstruction: Tensor,
    pub mu: Tensor,
    pub logvar: Tensor,
}

impl SkeletonPrior {
    pub fn new(vb: VarBuilder, config: &PriorConfig) -> Result<Self> {
        let last = *config.hidden.last().unwrap_or(&config.dim);
        let (body, _) = config
            .hidden
            .split_at(config.hidden.len().saturating_sub(1));
        let encoder = Mlp::from_vb(&MlpConfig::new(config.dim, body, last), vb.pp("mlp1"))?;
        let mu = candle_nn::linear(last, config.latent, vb.pp("mu"))?;
        let logvar = candle_nn::linear(last, config.latent, vb.pp("logvar"))?;
        let reversed: Vec<usize> = config.hidden.iter().rev().copied().collect();
        let decoder = Mlp::from_vb(
            &MlpConfig::new(config.latent, &reversed, config.dim),
            vb.pp("mlp2"),
        )?;
        Ok(SkeletonPrior {
            config: config.clone(),
            encoder,
            mu,
            logvar,
            decoder,
        })
    }

    /// `bs`: standardised scales `[n, dim]`; `eps`: noise `[n, latent]`.
    pub fn forward(&self, bs: &Tensor, eps: &Tensor) -> Result<PriorOutput> {
        let h = self.encoder.forward(bs)?.relu()?;
        let mu = self.mu.forward(&h)?;
        let logvar = self.logvar.forward(&h)?.clamp(-10.0, 10.0)?;
        let z = reparameterise(&mu, &logvar, eps)?;
        Ok(PriorOutput {
            reconstruction: self.decoder.forward(&z)?,
            mu,
            logvar,
        })
    }

    /// Eq. 5: squared error summed over bones (mean over samples) + KL.
    pub fn loss(&self, bs: &Tensor, out: &PriorOutput) -> Result<Tensor> {
        let n = bs.dim(0)? as f64;
        let rec = ((&out.reconstruction - bs)?.sqr()?.sum_all()? / n)?;
        Ok((rec + kl_sum(&out.mu, &out.logvar)?)?)
    }

    /// Decode latent codes `[n, latent]` into standardised scales `[n, dim]`.
    pub fn decode(&self, z: &Tensor) -> Result<Tensor> {
        Ok(self.decoder.forward(z)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use nn::{AdamConfig, Optimizer, Params, normal};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Trained on standardised two-bone scales that move together (a
    /// global factor), the prior's samples stay in the data's range and keep
    /// the correlation: it learned the distribution, not just the mean.
    #[test]
    fn prior_samples_follow_the_data() {
        let params = Params::new(1);
        let vb = params.var_builder();
        let cfg = PriorConfig {
            dim: 2,
            hidden: vec![16, 32],
            latent: 2,
        };
        let prior = SkeletonPrior::new(vb, &cfg).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut opt = Optimizer::new(params.vars(), AdamConfig::new(3e-3), None);
        let (mut first, mut last) = (0.0, 0.0);
        for step in 0..600 {
            let rows: Vec<f32> = (0..32)
                .flat_map(|_| {
                    let g: f32 = rng.random_range(-1.7..1.7);
                    [g, g + rng.random_range(-0.1..0.1)]
                })
                .collect();
            let x = Tensor::from_vec(rows, (32, 2), &Device::Cpu).unwrap();
            let eps = normal(&[32, 2], &mut rng).unwrap();
            let out = prior.forward(&x, &eps).unwrap();
            let loss = prior.loss(&x, &out).unwrap();
            let v = loss.to_scalar::<f32>().unwrap();
            if step == 0 {
                first = v;
            }
            last = v;
            opt.step(&loss.backward().unwrap()).unwrap();
        }
        assert!(last < 0.8 * first, "loss {first} -> {last}");
        let z = normal(&[400, 2], &mut rng).unwrap();
        let s = prior.decode(&z).unwrap().to_vec2::<f32>().unwrap();
        let inside = s.iter().filter(|r| r.iter().all(|v| v.abs() < 2.2)).count();
        assert!(inside >= 360, "{inside} of 400 samples in range");
        let mean = |i: usize| s.iter().map(|r| r[i]).sum::<f32>() / 400.0;
        let (m0, m1) = (mean(0), mean(1));
        let cov = s.iter().map(|r| (r[0] - m0) * (r[1] - m1)).sum::<f32>() / 400.0;
        let var = |i: usize, m: f32| s.iter().map(|r| (r[i] - m).powi(2)).sum::<f32>() / 400.0;
        let (v0, v1) = (var(0, m0), var(1, m1));
        assert!(m0.abs() < 0.4 && v0 > 0.2, "mean {m0}, variance {v0}");
        assert!(
            cov / (v0 * v1).sqrt() > 0.8,
            "correlation {}",
            cov / (v0 * v1).sqrt()
        );
    }
}
