//! The small feed-forward layers the model is made of: Linear, an MLP with ReLU
//! hidden layers, and a learnable LayerNorm (differentiable; candle-nn's fused
//! layer_norm has no backward pass).

use candle_core::{D, Tensor};

use crate::error::Result;
use crate::params::Params;

pub struct Linear {
    w_t: Tensor,
    w: Tensor,
    b: Tensor,
}

impl Linear {
    /// PyTorch's default initialisation: uniform in +-1/sqrt(fan_in).
    pub fn new(p: &mut Params, name: &str, fan_in: usize, fan_out: usize) -> Result<Self> {
        let bound = 1.0 / (fan_in as f32).sqrt();
        let w = p.uniform(&format!("{name}.weight"), &[fan_out, fan_in], bound)?;
        let b = p.uniform(&format!("{name}.bias"), &[fan_out], bound)?;
        Ok(Linear { w_t: w.t()?, w, b })
    }

    /// `x` of shape `(..., fan_in)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let dims = x.dims().to_vec();
        let fan_in = dims[dims.len() - 1];
        let rows = x.elem_count() / fan_in;
        let y = x
            .reshape((rows, fan_in))?
            .matmul(&self.w_t)?
            .broadcast_add(&self.b)?;
        let mut out = dims;
        let last = out.len() - 1;
        out[last] = self.w.dim(0)?;
        Ok(y.reshape(out)?)
    }
}

/// `in -> hidden... -> out`, ReLU between layers, linear output.
pub struct Mlp {
    layers: Vec<Linear>,
}

impl Mlp {
    pub fn new(
        p: &mut Params,
        name: &str,
        fan_in: usize,
        hidden: &[usize],
        fan_out: usize,
    ) -> Result<Self> {
        let dims: Vec<usize> = std::iter::once(fan_in)
            .chain(hidden.iter().copied())
            .chain(std::iter::once(fan_out))
            .collect();
        let layers = dims
            .windows(2)
            .enumerate()
            .map(|(i, w)| Linear::new(p, &format!("{name}.{i}"), w[0], w[1]))
            .collect::<Result<_>>()?;
        Ok(Mlp { layers })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut x = x.clone();
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(&x)?;
            if i + 1 < self.layers.len() {
                x = x.relu()?;
            }
        }
        Ok(x)
    }
}

pub struct LayerNorm {
    gamma: Tensor,
    beta: Tensor,
}

impl LayerNorm {
    pub fn new(p: &mut Params, name: &str, dim: usize) -> Result<Self> {
        Ok(LayerNorm {
            gamma: p.constant(&format!("{name}.gamma"), &[dim], 1.0)?,
            beta: p.constant(&format!("{name}.beta"), &[dim], 0.0)?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let n = x.dim(D::Minus1)? as f64;
        let centred = x.broadcast_sub(&(x.sum_keepdim(D::Minus1)? / n)?)?;
        let var = (centred.sqr()?.sum_keepdim(D::Minus1)? / n)?;
        let normed = centred.broadcast_div(&(var + 1e-5)?.sqrt()?)?;
        Ok(normed
            .broadcast_mul(&self.gamma)?
            .broadcast_add(&self.beta)?)
    }
}
