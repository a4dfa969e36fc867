//! The orthonormal DCT-II basis the GCN model works in (Mao et al. 2019: a
//! trajectory becomes a few DCT coefficients per joint angle, smooth by
//! construction, and the graph convolutions act on those coefficients).

use candle_core::{Device, Tensor};

use crate::error::Result;

/// The first `k` rows of the orthonormal DCT-II matrix of length `n`, `(k, n)`:
/// `coefficients = basis . signal`, `signal ~= basis^T . coefficients` (exact
/// when `k == n`).
pub fn basis(k: usize, n: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(k * n);
    for row in 0..k {
        let w = if row == 0 {
            (1.0 / n as f64).sqrt()
        } else {
            (2.0 / n as f64).sqrt()
        };
        for t in 0..n {
            let angle = std::f64::consts::PI * (2 * t + 1) as f64 * row as f64 / (2 * n) as f64;
            out.push((w * angle.cos()) as f32);
        }
    }
    out
}

/// [`basis`] as a tensor `(k, n)`.
pub fn basis_tensor(k: usize, n: usize) -> Result<Tensor> {
    Ok(Tensor::from_vec(basis(k, n), (k, n), &Device::Cpu)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_exact_with_all_coefficients() {
        let n = 22;
        let d = basis_tensor(n, n).unwrap();
        let x = Tensor::arange(0f32, (3 * n) as f32, &Device::Cpu)
            .unwrap()
            .sin()
            .unwrap()
            .reshape((3, n))
            .unwrap();
        // (3, n) signals -> (3, n) coefficients -> (3, n) signals.
        let c = x.matmul(&d.t().unwrap()).unwrap();
        let back = c.matmul(&d).unwrap();
        let err: f32 = (back - &x)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar()
            .unwrap();
        assert!(err < 1e-5, "{err}");
        // Truncation keeps a smooth signal close and drops high frequencies.
        let k = 10;
        let dk = basis_tensor(k, n).unwrap();
        let smooth = Tensor::arange(0f32, n as f32, &Device::Cpu)
            .unwrap()
            .affine(0.1, 0.0)
            .unwrap()
            .sin()
            .unwrap()
            .reshape((1, n))
            .unwrap();
        let approx = smooth
            .matmul(&dk.t().unwrap())
            .unwrap()
            .matmul(&dk)
            .unwrap();
        let err: f32 = (approx - &smooth)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar()
            .unwrap();
        assert!(err < 0.05, "{err}");
    }
}
