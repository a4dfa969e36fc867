//! Named, seeded parameters. Every layer draws its initial weights from one
//! ChaCha RNG (candle's CPU random ops cannot be seeded) and registers them under a
//! stable name (`enc.lstm_fw.w_ih`, ...), which is what the optimisers and the
//! safetensors file use.

use candle_core::{Device, Tensor, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::Result;

pub struct Params {
    vars: Vec<(String, Var)>,
    rng: ChaCha8Rng,
}

impl Params {
    pub fn new(seed: u64) -> Self {
        Params {
            vars: Vec::new(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Uniform in `+-bound`.
    pub fn uniform(&mut self, name: &str, shape: &[usize], bound: f32) -> Result<Tensor> {
        let n: usize = shape.iter().product();
        let data: Vec<f32> = (0..n)
            .map(|_| self.rng.random_range(-bound..=bound))
            .collect();
        self.register(name, Tensor::from_vec(data, shape, &Device::Cpu)?)
    }

    pub fn constant(&mut self, name: &str, shape: &[usize], value: f32) -> Result<Tensor> {
        let n: usize = shape.iter().product();
        self.register(name, Tensor::from_vec(vec![value; n], shape, &Device::Cpu)?)
    }

    pub fn values(&mut self, name: &str, shape: &[usize], data: Vec<f32>) -> Result<Tensor> {
        self.register(name, Tensor::from_vec(data, shape, &Device::Cpu)?)
    }

    fn register(&mut self, name: &str, t: Tensor) -> Result<Tensor> {
        assert!(
            self.vars.iter().all(|(n, _)| n != name),
            "parameter `{name}` registered twice"
        );
        let v = Var::from_tensor(&t)?;
        let t = v.as_tensor().clone();
        self.vars.push((name.to_string(), v));
        Ok(t)
    }

    pub fn vars(&self) -> &[(String, Var)] {
        &self.vars
    }

    /// Parameters whose name starts with one of `prefixes`.
    pub fn with_prefix(&self, prefixes: &[&str]) -> Vec<(String, Var)> {
        self.vars
            .iter()
            .filter(|(n, _)| prefixes.iter().any(|p| n.starts_with(p)))
            .cloned()
            .collect()
    }

    pub fn count(&self) -> usize {
        self.vars.iter().map(|(_, v)| v.elem_count()).sum()
    }
}
