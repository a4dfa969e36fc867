//! The debiasing network: a per-frame MLP, ReLU hidden layers, linear output.
//! The paper uses 4 hidden layers of 512.

use candle_core::{DType, Device, Module, Tensor, Var};
use candle_nn::{Linear, VarBuilder, VarMap, linear};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::{DebiasError, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MlpConfig {
    pub input: usize,
    pub hidden: Vec<usize>,
    pub output: usize,
}

impl MlpConfig {
    pub fn validate(&self) -> Result<()> {
        if self.input == 0 || self.output == 0 || self.hidden.contains(&0) {
            return Err(DebiasError::Config(format!(
                "layer sizes must be positive: {} -> {:?} -> {}",
                self.input, self.hidden, self.output
            )));
        }
        Ok(())
    }
}

pub struct Mlp {
    layers: Vec<Linear>,
}

impl Mlp {
    pub fn new(config: &MlpConfig, vb: VarBuilder) -> Result<Self> {
        config.validate()?;
        let dims: Vec<usize> = std::iter::once(config.input)
            .chain(config.hidden.iter().copied())
            .chain(std::iter::once(config.output))
            .collect();
        let layers = dims
            .windows(2)
            .enumerate()
            .map(|(i, d)| linear(d[0], d[1], vb.pp(format!("layer{i}"))))
            .collect::<candle_core::Result<Vec<_>>>()?;
        Ok(Mlp { layers })
    }

    /// A fresh network in `vars`, initialised from `seed` (PyTorch's default:
    /// uniform in +-1/sqrt(fan_in)), so training is reproducible; candle's own
    /// initialisers draw from an unseeded generator.
    pub fn seeded(config: &MlpConfig, vars: &VarMap, seed: u64) -> Result<Self> {
        config.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let dims: Vec<usize> = std::iter::once(config.input)
            .chain(config.hidden.iter().copied())
            .chain(std::iter::once(config.output))
            .collect();
        {
            let mut data = vars
                .data()
                .lock()
                .map_err(|_| DebiasError::Config("variable map poisoned".into()))?;
            for (i, d) in dims.windows(2).enumerate() {
                let bound = 1.0 / (d[0] as f32).sqrt();
                let mut draw = |n: usize| -> Vec<f32> {
                    (0..n).map(|_| rng.random_range(-bound..bound)).collect()
                };
                let w = Tensor::from_vec(draw(d[0] * d[1]), (d[1], d[0]), &Device::Cpu)?;
                let b = Tensor::from_vec(draw(d[1]), d[1], &Device::Cpu)?;
                data.insert(format!("layer{i}.weight"), Var::from_tensor(&w)?);
                data.insert(format!("layer{i}.bias"), Var::from_tensor(&b)?);
            }
        }
        Mlp::new(
            config,
            VarBuilder::from_varmap(vars, DType::F32, &Device::Cpu),
        )
    }

    /// `x`: (frames, input) -> (frames, output).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut h = x.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            h = layer.forward(&h)?;
            if i < last {
                h = h.relu()?;
            }
        }
        Ok(h)
    }
}
