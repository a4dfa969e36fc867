//! The multi-layer perceptron both networks are made of: ReLU hidden layers and a linear
//! output layer, with parameters held in named candle `Var`s so they can be optimised
//! and checkpointed. Initialisation draws from a caller-supplied seeded RNG (candle's CPU
//! random ops cannot be seeded), which makes training reproducible.

use candle_core::{Device, Module, Tensor, Var};
use candle_nn::Linear;
use rand::Rng;

use crate::env::EnvRng;
use crate::error::Result;

pub struct Mlp {
    layers: Vec<Linear>,
    vars: Vec<(String, Var)>,
}

impl Mlp {
    /// `in_dim -> hidden[0] -> ... -> out_dim`. Weights are uniform in
    /// +-1/sqrt(fan_in) (PyTorch's default); the output layer's weights are further
    /// scaled by `out_scale` and its bias is zero, so a small `out_scale` makes the
    /// initial output close to 0.
    pub fn new(
        name: &str,
        in_dim: usize,
        hidden: &[usize],
        out_dim: usize,
        out_scale: f32,
        rng: &mut EnvRng,
    ) -> Result<Self> {
        let dims: Vec<usize> = std::iter::once(in_dim)
            .chain(hidden.iter().copied())
            .chain(std::iter::once(out_dim))
            .collect();
        let n_layers = dims.len() - 1;
        let mut layers = Vec::with_capacity(n_layers);
        let mut vars = Vec::with_capacity(2 * n_layers);
        for (i, pair) in dims.windows(2).enumerate() {
            let (fan_in, fan_out) = (pair[0], pair[1]);
            let bound = 1.0 / (fan_in as f32).sqrt();
            let last = i + 1 == n_layers;
            let scale = if last { out_scale } else { 1.0 };
            let w: Vec<f32> = (0..fan_in * fan_out)
                .map(|_| rng.random_range(-bound..bound) * scale)
                .collect();
            let b: Vec<f32> = if last {
                vec![0.0; fan_out]
            } else {
                (0..fan_out)
                    .map(|_| rng.random_range(-bound..bound))
                    .collect()
            };
            let w = Var::from_tensor(&Tensor::from_vec(w, (fan_out, fan_in), &Device::Cpu)?)?;
            let b = Var::from_tensor(&Tensor::from_vec(b, fan_out, &Device::Cpu)?)?;
            layers.push(Linear::new(
                w.as_tensor().clone(),
                Some(b.as_tensor().clone()),
            ));
            vars.push((format!("{name}.{i}.weight"), w));
            vars.push((format!("{name}.{i}.bias"), b));
        }
        Ok(Mlp { layers, vars })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut x = x.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(&x)?;
            if i != last {
                x = x.relu()?;
            }
        }
        Ok(x)
    }

    /// Parameters with stable names (`<name>.<layer>.weight|bias`).
    pub fn vars(&self) -> &[(String, Var)] {
        &self.vars
    }
}
