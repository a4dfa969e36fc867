//! The RNN baseline of Martinez et al. 2017 ("residual sup." with sampling-based
//! loss), which MotionAug Table 2 evaluates: one GRU reads the observed frames;
//! the same GRU then decodes, each step feeding its own previous prediction and
//! outputting a velocity added to it (residual decoding), so "no motion" is the
//! default and the network learns the change.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use candle_nn::rnn::{GRU, GRUConfig, RNN};
use nn::{Linear, Params};

use crate::error::{EvalError, Result};
use crate::predict::{Predictor, mse};

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Seq2SeqConfig {
    /// Pose features per frame.
    pub dim: usize,
    /// GRU state size (Martinez et al.: 1024; ours is sized for a CPU).
    pub hidden: usize,
}

impl Seq2SeqConfig {
    pub fn new(dim: usize) -> Self {
        Seq2SeqConfig { dim, hidden: 128 }
    }
}

pub struct Seq2Seq {
    gru: GRU,
    out: Linear,
    params: Params,
}

impl Seq2Seq {
    pub fn new(config: &Seq2SeqConfig, seed: u64) -> Result<Self> {
        if config.dim == 0 || config.hidden == 0 {
            return Err(EvalError::Config("seq2seq sizes must be positive".into()));
        }
        let (d, h) = (config.dim, config.hidden);
        let params = Params::new(seed);
        // PyTorch's GRU initialisation: uniform in +-1/sqrt(hidden).
        let bound = 1.0 / (h as f32).sqrt();
        let mut t = HashMap::new();
        for (name, shape) in [
            ("weight_ih_l0", vec![3 * h, d]),
            ("weight_hh_l0", vec![3 * h, h]),
            ("bias_ih_l0", vec![3 * h]),
            ("bias_hh_l0", vec![3 * h]),
        ] {
            t.insert(
                name.to_string(),
                params.uniform(&format!("gru.{name}"), &shape, bound)?,
            );
        }
        let vb = candle_nn::VarBuilder::from_tensors(t, DType::F32, &Device::Cpu);
        let gru = candle_nn::rnn::gru(d, h, GRUConfig::default(), vb)?;
        let out = Linear::new(&params, "out", h, d)?;
        Ok(Seq2Seq { gru, out, params })
    }

    /// Encodes frames `0..T_in - 1`, then decodes `frames` steps from the last
    /// observed frame: `(B, frames, D)`.
    fn run(&self, input: &Tensor, frames: usize) -> Result<Tensor> {
        let (b, t_in, _) = input.dims3()?;
        let mut state = self.gru.zero_state(b)?;
        for t in 0..t_in.saturating_sub(1) {
            let x = input.narrow(1, t, 1)?.squeeze(1)?;
            state = self.gru.step(&x, &state)?;
        }
        let mut prev = input.narrow(1, t_in - 1, 1)?.squeeze(1)?;
        let mut outputs = Vec::with_capacity(frames);
        for _ in 0..frames {
            state = self.gru.step(&prev, &state)?;
            let next = (&prev + self.out.forward(&state.h)?)?;
            outputs.push(next.clone());
            prev = next;
        }
        Ok(Tensor::stack(&outputs, 1)?)
    }
}

impl Predictor for Seq2Seq {
    fn loss(&self, input: &Tensor, target: &Tensor) -> Result<Tensor> {
        let pred = self.run(input, target.dim(1)?)?;
        mse(&pred, target)
    }

    fn predict(&self, input: &Tensor, frames: usize) -> Result<Tensor> {
        self.run(input, frames)
    }

    fn params(&self) -> &Params {
        &self.params
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_and_residual_start() {
        let m = Seq2Seq::new(&Seq2SeqConfig { dim: 6, hidden: 16 }, 1).unwrap();
        let x = Tensor::randn(0f32, 1.0, (4, 10, 6), &Device::Cpu).unwrap();
        let y = m.predict(&x, 12).unwrap();
        assert_eq!(y.dims(), &[4, 12, 6]);
        let target = Tensor::zeros((4, 12, 6), DType::F32, &Device::Cpu).unwrap();
        let loss: f32 = m.loss(&x, &target).unwrap().to_scalar().unwrap();
        assert!(loss.is_finite() && loss > 0.0);
        // 4 GRU tensors + 2 output tensors, all registered.
        assert_eq!(m.params().vars().len(), 6);
    }
}
