//! The affine layer `y = x W^T + b` on parameters from a [`Params`] store.
//!
//! It exists (rather than candle-nn's `Linear`) because it takes inputs of any
//! rank by folding the leading dimensions into one 2-D product with a weight
//! transposed once at construction, which is what the LSTM-based models feed it.

use candle_core::Tensor;
use candle_nn::VarBuilder;

use crate::bias::add_bias;
use crate::error::Result;
use crate::params::Params;

pub struct Linear {
    /// `(fan_out, fan_in)`.
    w: Tensor,
    /// `W^T`, a view of the same storage (so optimiser steps reach it).
    w_t: Tensor,
    b: Option<Tensor>,
}

impl Linear {
    /// The scheme: weight `{name}.weight` and bias `{name}.bias` uniform in
    /// `+-1/sqrt(fan_in)` (PyTorch's default).
    pub fn new(p: &Params, name: &str, fan_in: usize, fan_out: usize) -> Result<Self> {
        let bound = 1.0 / (fan_in as f32).sqrt();
        let w = p.uniform(&format!("{name}.weight"), &[fan_out, fan_in], bound)?;
        let b = p.uniform(&format!("{name}.bias"), &[fan_out], bound)?;
        Linear::from_weights(w, Some(b))
    }

    /// The candle-transformers form: `weight` and `bias` from `vb` (with a
    /// [`Params::var_builder`], the same scheme and draws as [`Linear::new`]).
    pub fn from_vb(vb: VarBuilder, fan_in: usize, fan_out: usize) -> Result<Self> {
        let bound = 1.0 / (fan_in as f64).sqrt();
        let init = candle_nn::Init::Uniform {
            lo: -bound,
            up: bound,
        };
        let w = vb.get_with_hints((fan_out, fan_in), "weight", init)?;
        let b = vb.get_with_hints(fan_out, "bias", init)?;
        Linear::from_weights(w, Some(b))
    }

    /// A layer over given tensors: `w` `(fan_out, fan_in)`, `b` `(fan_out,)`.
    pub fn from_weights(w: Tensor, b: Option<Tensor>) -> Result<Self> {
        Ok(Linear { w_t: w.t()?, w, b })
    }

    pub fn fan_in(&self) -> usize {
        self.w.dims()[1]
    }

    pub fn fan_out(&self) -> usize {
        self.w.dims()[0]
    }

    /// `x` of shape `(..., fan_in)` -> `(..., fan_out)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut dims = x.dims().to_vec();
        let fan_in = self.fan_in();
        let rows = x.elem_count() / fan_in.max(1);
        let y = x.reshape((rows, fan_in))?.matmul(&self.w_t)?;
        let y = match &self.b {
            Some(b) => add_bias(&y, b)?,
            None => y,
        };
        if let Some(last) = dims.last_mut() {
            *last = self.fan_out();
        }
        Ok(y.reshape(dims)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn forward_is_x_wt_plus_b_for_any_rank() {
        let p = Params::new(1);
        let l = Linear::new(&p, "l", 3, 2).unwrap();
        let w = p.vars()[0].1.to_vec2::<f32>().unwrap();
        let b = p.vars()[1].1.to_vec1::<f32>().unwrap();
        let x = Tensor::arange(0f32, 12.0, &Device::Cpu)
            .unwrap()
            .reshape((2, 2, 3))
            .unwrap();
        let y = l.forward(&x).unwrap();
        assert_eq!(y.dims(), &[2, 2, 2]);
        let y = y.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        for r in 0..4 {
            for o in 0..2 {
                let want: f32 = (0..3).map(|k| (r * 3 + k) as f32 * w[o][k]).sum::<f32>() + b[o];
                assert!((y[r * 2 + o] - want).abs() < 1e-5);
            }
        }
    }
}
