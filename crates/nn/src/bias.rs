//! Adding a bias to every row, as one op with its backward pass written out.
//!
//! Why it exists: `y.broadcast_add(b)` differentiates through candle's
//! broadcast node, whose backward sums the gradient over the rows with the
//! strided reduction (a column at a time over `(rows, C)`) and accumulates a
//! zero-initialised copy of the full gradient for `y`; with thousands of rows
//! per layer (every frame of a batch of clips) that was a tenth of a VAE
//! training step in `perf`. Here the forward pass adds row by row and the
//! backward pass passes the gradient through to `y` and sums it for `b` row
//! by row, in contiguous memory. Measured in crates/vae/README.md.

use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Tensor};

use crate::cpu_op::f32_slice;
use crate::error::{NnError, Result};

struct AddBias;

impl CustomOp2 for AddBias {
    fn name(&self) -> &'static str {
        "add-bias"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let y = f32_slice(s1, l1, "add-bias", "the input")?;
        let b = f32_slice(s2, l2, "add-bias", "the bias")?;
        let c = b.len();
        if c == 0 || y.len() % c != 0 {
            candle_core::bail!("add-bias: {} values are not rows of {c}", y.len());
        }
        let mut out = y.to_vec();
        for row in out.chunks_exact_mut(c) {
            for (v, bias) in row.iter_mut().zip(b) {
                *v += bias;
            }
        }
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }

    fn bwd(
        &self,
        _y: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let c = b.elem_count();
        let g = grad.flatten_all()?.to_vec1::<f32>()?;
        let mut db = vec![0.0f32; c];
        for row in g.chunks_exact(c) {
            for (d, v) in db.iter_mut().zip(row) {
                *d += v;
            }
        }
        let db = Tensor::from_vec(db, b.shape(), b.device())?;
        Ok((Some(grad.clone()), Some(db)))
    }
}

/// `y` `(..., C)` plus `b` `(C,)` on every row (f32, CPU).
pub fn add_bias(y: &Tensor, b: &Tensor) -> Result<Tensor> {
    let c = b.elem_count();
    if b.rank() != 1 || y.dims().last() != Some(&c) {
        return Err(NnError::Config(format!(
            "a bias of shape {:?} does not fit rows of shape {:?}",
            b.dims(),
            y.dims()
        )));
    }
    Ok(y.contiguous()?.apply_op2(&b.contiguous()?, AddBias)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn values(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    }

    #[test]
    fn matches_broadcast_add_forward_and_backward() {
        let dev = Device::Cpu;
        let y = Var::new(&[[1f32, 2., 3.], [4., 5., 6.]], &dev).unwrap();
        let b = Var::new(&[0.5f32, -1., 2.], &dev).unwrap();
        let w = Tensor::new(&[[1f32, 2., 3.], [-1., 0.5, 4.]], &dev).unwrap();
        let ours = add_bias(y.as_tensor(), b.as_tensor()).unwrap();
        let theirs = y.as_tensor().broadcast_add(b.as_tensor()).unwrap();
        assert_eq!(values(&ours), values(&theirs));
        let grads = |out: Tensor| (out * &w).unwrap().sum_all().unwrap().backward().unwrap();
        let (g1, g2) = (grads(ours), grads(theirs));
        for v in [y.as_tensor(), b.as_tensor()] {
            assert_eq!(values(g1.get(v).unwrap()), values(g2.get(v).unwrap()));
        }
    }

    #[test]
    fn a_bias_of_the_wrong_width_is_an_error() {
        let y = Tensor::zeros((2, 3), candle_core::DType::F32, &Device::Cpu).unwrap();
        let b = Tensor::zeros(4, candle_core::DType::F32, &Device::Cpu).unwrap();
        assert!(add_bias(&y, &b).is_err());
    }
}
