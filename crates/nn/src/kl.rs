//! The diagonal Gaussian latent of the VAEs (the motion VAE, the interaction
//! model's prior and conditional VAEs): its KL divergence to N(0, I), the
//! reparameterisation trick and seeded standard normal noise (candle's CPU
//! random ops cannot be seeded).
//!
//! Both KL reductions share one per-entry term,
//! `-1/2 (1 + logvar - mu^2 - exp(logvar))`; they differ in what they average.

use candle_core::{D, Device, Tensor};
use rand::Rng;
use rand_distr::StandardNormal;

use crate::error::Result;

/// `1 + logvar - mu^2 - exp(logvar)`, per entry.
fn kl_terms(mu: &Tensor, logvar: &Tensor) -> Result<Tensor> {
    Ok((((logvar + 1.0)? - mu.sqr()?)? - logvar.exp()?)?)
}

/// `KL[N(mu, exp(logvar)) || N(0, I)]` averaged over every entry (batch and
/// latent dimensions alike): the motion VAE's term.
pub fn kl_mean(mu: &Tensor, logvar: &Tensor) -> Result<Tensor> {
    Ok((kl_terms(mu, logvar)?.mean_all()? * -0.5)?)
}

/// `KL[N(mu, exp(logvar)) || N(0, I)]` summed over the last (latent) dimension
/// and averaged over the rest: the per-sample divergence.
pub fn kl_sum(mu: &Tensor, logvar: &Tensor) -> Result<Tensor> {
    let rows = mu.elem_count() / mu.dim(D::Minus1)?.max(1);
    Ok((kl_terms(mu, logvar)?.sum_all()? * (-0.5 / rows.max(1) as f64))?)
}

/// `mu + exp(logvar / 2) * eps`.
pub fn reparameterise(mu: &Tensor, logvar: &Tensor, eps: &Tensor) -> Result<Tensor> {
    Ok(mu.add(&(logvar * 0.5)?.exp()?.mul(eps)?)?)
}

/// Standard normal noise of `shape` from `rng` (f32, CPU).
pub fn normal(shape: &[usize], rng: &mut impl Rng) -> Result<Tensor> {
    let n: usize = shape.iter().product();
    let v: Vec<f32> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
    Ok(Tensor::from_vec(v, shape, &Device::Cpu)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::DType;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn kl_is_zero_at_the_prior_and_matches_the_closed_form() {
        let z = Tensor::zeros((2, 3), DType::F32, &Device::Cpu).unwrap();
        assert!(kl_mean(&z, &z).unwrap().to_scalar::<f32>().unwrap().abs() < 1e-7);
        assert!(kl_sum(&z, &z).unwrap().to_scalar::<f32>().unwrap().abs() < 1e-7);
        let mu = Tensor::ones((2, 3), DType::F32, &Device::Cpu).unwrap();
        let k = kl_mean(&mu, &z).unwrap().to_scalar::<f32>().unwrap();
        assert!((k - 0.5).abs() < 1e-6);
        // Summed over 3 latent dimensions: 3 x 0.5 per sample.
        let k = kl_sum(&mu, &z).unwrap().to_scalar::<f32>().unwrap();
        assert!((k - 1.5).abs() < 1e-6);
        // logvar = ln 2, mu = 0: 1/2 (2 - 1 - ln 2) per dimension.
        let lv = Tensor::full(2f32.ln(), (1, 2), &Device::Cpu).unwrap();
        let k = kl_sum(&lv.zeros_like().unwrap(), &lv)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!((k - (1.0 - 2f32.ln())).abs() < 1e-6);
    }

    #[test]
    fn noise_is_seeded_and_reparameterisation_scales_it() {
        let a = normal(&[4, 2], &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let b = normal(&[4, 2], &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let (a, b) = (a.flatten_all().unwrap(), b.flatten_all().unwrap());
        assert_eq!(a.to_vec1::<f32>().unwrap(), b.to_vec1::<f32>().unwrap());
        let mu = Tensor::full(1f32, 8, &Device::Cpu).unwrap();
        let lv = Tensor::full(4f32.ln(), 8, &Device::Cpu).unwrap();
        let z = reparameterise(&mu, &lv, &a)
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        for (z, e) in z.iter().zip(a.to_vec1::<f32>().unwrap()) {
            assert!((z - (1.0 + 2.0 * e)).abs() < 1e-5);
        }
    }
}
