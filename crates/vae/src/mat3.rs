//! Batches of 3x3 rotation-matrix products for the foot kinematics, as ops
//! with their backward passes written out.
//!
//! Why it exists: candle multiplies a batch of matrices one gemm call per
//! batch entry, so the forward kinematics of a training batch (a 3x3 product
//! per joint per frame, tens of thousands of them) spent its time in call
//! overhead, three times over counting the backward pass. Here a batch is one
//! loop: `C_i = A_i B_i` and its gradients `dA_i = dC_i B_i^T`,
//! `dB_i = A_i^T dC_i`, and for a constant row vector `v`, `v B_i` and
//! `dB_i = v^T dC_i`.

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Shape, Tensor};

use crate::error::{Result, VaeError};

/// `out_i = a_i b_i` for 3x3 blocks; with `ta`/`tb` the blocks of `a`/`b`
/// are read transposed.
fn products(a: &[f32], b: &[f32], ta: bool, tb: bool) -> Vec<f32> {
    let mut out = vec![0.0f32; a.len()];
    for ((o, x), y) in out
        .chunks_exact_mut(9)
        .zip(a.chunks_exact(9))
        .zip(b.chunks_exact(9))
    {
        for r in 0..3 {
            for c in 0..3 {
                let mut s = 0.0;
                for k in 0..3 {
                    let xa = if ta { x[k * 3 + r] } else { x[r * 3 + k] };
                    let yb = if tb { y[c * 3 + k] } else { y[k * 3 + c] };
                    s += xa * yb;
                }
                o[r * 3 + c] = s;
            }
        }
    }
    out
}

struct Mul;

impl CustomOp2 for Mul {
    fn name(&self) -> &'static str {
        "mat3-mul"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let a = nn::cpu_op::f32_slice(s1, l1, "mat3", "the left matrices")?;
        let b = nn::cpu_op::f32_slice(s2, l2, "mat3", "the right matrices")?;
        Ok((
            CpuStorage::F32(products(a, b, false, false)),
            l1.shape().clone(),
        ))
    }

    fn bwd(
        &self,
        a: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let av = a.flatten_all()?.to_vec1::<f32>()?;
        let bv = b.flatten_all()?.to_vec1::<f32>()?;
        let g = grad.flatten_all()?.to_vec1::<f32>()?;
        let da = a
            .track_op()
            .then(|| Tensor::from_vec(products(&g, &bv, false, true), a.shape(), a.device()))
            .transpose()?;
        let db = b
            .track_op()
            .then(|| Tensor::from_vec(products(&av, &g, true, false), b.shape(), b.device()))
            .transpose()?;
        Ok((da, db))
    }
}

/// `(n, 3, 3)` times `(n, 3, 3)`, block by block (f32, CPU).
pub fn mul(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let n = a.dim(0)?;
    if a.dims() != [n, 3, 3] || b.dims() != [n, 3, 3] {
        return Err(VaeError::Data(format!(
            "mat3::mul needs two (n, 3, 3) batches, got {:?} and {:?}",
            a.dims(),
            b.dims()
        )));
    }
    Ok(a.contiguous()?.apply_op2(&b.contiguous()?, Mul)?)
}

struct RowTimes([f32; 3]);

impl CustomOp1 for RowTimes {
    fn name(&self) -> &'static str {
        "mat3-row-times"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let m = nn::cpu_op::f32_slice(s, l, "mat3", "the matrices")?;
        let v = self.0;
        let n = m.len() / 9;
        let mut out = Vec::with_capacity(3 * n);
        for x in m.chunks_exact(9) {
            for c in 0..3 {
                out.push(v[0] * x[c] + v[1] * x[3 + c] + v[2] * x[6 + c]);
            }
        }
        Ok((CpuStorage::F32(out), Shape::from((n, 1, 3))))
    }

    fn bwd(&self, m: &Tensor, _res: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let g = grad.flatten_all()?.to_vec1::<f32>()?;
        let v = self.0;
        let mut dm = Vec::with_capacity(3 * g.len());
        for gi in g.chunks_exact(3) {
            for vk in v {
                dm.extend(gi.iter().map(|x| vk * x));
            }
        }
        Ok(Some(Tensor::from_vec(dm, m.shape(), m.device())?))
    }
}

/// The constant row vector `v` times each block of `(n, 3, 3)`: `(n, 1, 3)`.
pub fn row_times(v: [f32; 3], m: &Tensor) -> Result<Tensor> {
    let n = m.dim(0)?;
    if m.dims() != [n, 3, 3] {
        return Err(VaeError::Data(format!(
            "mat3::row_times needs an (n, 3, 3) batch, got {:?}",
            m.dims()
        )));
    }
    Ok(m.contiguous()?.apply_op1(RowTimes(v))?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};
    use nn::Params;

    fn close(a: &Tensor, b: &Tensor) {
        let a = a.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let b = b.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-5, "{x} vs {y}");
        }
    }

    /// Gradients of `sum(out * w)`.
    fn grads(out: Tensor, w: &Tensor) -> candle_core::backprop::GradStore {
        (out * w).unwrap().sum_all().unwrap().backward().unwrap()
    }

    #[test]
    fn products_and_gradients_match_candles_batched_matmul() {
        let p = Params::new(3);
        let a = Var::from_tensor(&p.uniform("a", &[5, 3, 3], 1.0).unwrap()).unwrap();
        let b = Var::from_tensor(&p.uniform("b", &[5, 3, 3], 1.0).unwrap()).unwrap();
        let w = p.uniform("w", &[5, 3, 3], 1.0).unwrap().detach();
        let ours = mul(a.as_tensor(), b.as_tensor()).unwrap();
        let theirs = a.as_tensor().matmul(b.as_tensor()).unwrap();
        close(&ours, &theirs);
        let (g1, g2) = (grads(ours, &w), grads(theirs, &w));
        for v in [a.as_tensor(), b.as_tensor()] {
            close(g1.get(v).unwrap(), g2.get(v).unwrap());
        }
    }

    #[test]
    fn a_row_times_matrices_matches_broadcast_matmul() {
        let p = Params::new(4);
        let m = Var::from_tensor(&p.uniform("m", &[4, 3, 3], 1.0).unwrap()).unwrap();
        let w = p.uniform("w", &[4, 1, 3], 1.0).unwrap().detach();
        let v = [0.3f32, -1.2, 0.7];
        let row = Tensor::from_slice(&v, (1, 1, 3), &Device::Cpu).unwrap();
        let ours = row_times(v, m.as_tensor()).unwrap();
        let theirs = row.broadcast_matmul(m.as_tensor()).unwrap();
        assert_eq!(ours.dims(), &[4, 1, 3]);
        close(&ours, &theirs);
        let (g1, g2) = (grads(ours, &w), grads(theirs, &w));
        close(
            g1.get(m.as_tensor()).unwrap(),
            g2.get(m.as_tensor()).unwrap(),
        );
    }

    #[test]
    fn wrong_shapes_are_errors() {
        let x = Tensor::zeros((2, 3, 2), candle_core::DType::F32, &Device::Cpu).unwrap();
        let y = Tensor::zeros((2, 3, 3), candle_core::DType::F32, &Device::Cpu).unwrap();
        assert!(mul(&x, &y).is_err());
        assert!(row_times([1.0, 0.0, 0.0], &x).is_err());
    }
}
