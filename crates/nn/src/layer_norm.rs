//! Layer normalisation with a learnable gain and offset, written out in tensor
//! ops so that it differentiates (candle-nn's fused `layer_norm` has no
//! backward pass).

use candle_core::{D, Tensor};

use crate::error::Result;
use crate::params::Params;

pub struct LayerNorm {
    gamma: Tensor,
    beta: Tensor,
    eps: f64,
}

impl LayerNorm {
    /// Gain `{name}.gamma` = 1, offset `{name}.beta` = 0, epsilon 1e-5.
    pub fn new(p: &Params, name: &str, dim: usize) -> Result<Self> {
        Ok(LayerNorm {
            gamma: p.constant(&format!("{name}.gamma"), &[dim], 1.0)?,
            beta: p.constant(&format!("{name}.beta"), &[dim], 0.0)?,
            eps: 1e-5,
        })
    }

    /// Normalises over the last dimension.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let n = x.dim(D::Minus1)? as f64;
        let centred = x.broadcast_sub(&(x.sum_keepdim(D::Minus1)? / n)?)?;
        let var = (centred.sqr()?.sum_keepdim(D::Minus1)? / n)?;
        let normed = centred.broadcast_div(&(var + self.eps)?.sqrt()?)?;
        Ok(normed
            .broadcast_mul(&self.gamma)?
            .broadcast_add(&self.beta)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn rows_get_zero_mean_and_unit_variance_and_gradients_flow() {
        let p = Params::new(0);
        let ln = LayerNorm::new(&p, "ln", 4).unwrap();
        let x = Var::new(&[[1f32, 2., 3., 6.], [-1., 0., 0., 1.]], &Device::Cpu).unwrap();
        let y = ln.forward(x.as_tensor()).unwrap();
        for row in y.to_vec2::<f32>().unwrap() {
            let m = row.iter().sum::<f32>() / 4.0;
            let v = row.iter().map(|r| (r - m).powi(2)).sum::<f32>() / 4.0;
            assert!(m.abs() < 1e-6 && (v - 1.0).abs() < 1e-3, "{row:?}");
        }
        // Agrees with candle-nn's fused forward.
        let ones = Tensor::ones(4, candle_core::DType::F32, &Device::Cpu).unwrap();
        let zeros = ones.zeros_like().unwrap();
        let fused = candle_nn::ops::layer_norm(x.as_tensor(), &ones, &zeros, 1e-5).unwrap();
        let d = (fused - &y).unwrap().abs().unwrap().max_all().unwrap();
        assert!(d.to_scalar::<f32>().unwrap() < 1e-5);
        let w = Tensor::new(&[1f32, 0., 0., 0.], &Device::Cpu).unwrap();
        let g = y
            .broadcast_mul(&w)
            .unwrap()
            .sum_all()
            .unwrap()
            .backward()
            .unwrap();
        let gx = g.get(x.as_tensor()).unwrap().to_vec2::<f32>().unwrap();
        assert!(gx[0][0] > 0.0 && gx[0].iter().sum::<f32>().abs() < 1e-5);
        assert!(g.get(&p.vars()[0].1).is_some());
    }
}
