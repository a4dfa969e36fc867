//! The graph helpers the ST-GCN and G-GRU layers share: the normalised
//! skeleton adjacency they mix joints with, the mixing itself, and a
//! contiguous `cat`. (The general building blocks, MLP, seeded
//! initialisation, KL, reparameterisation and noise, are the `nn` crate's.)

use candle_core::{Device, Tensor};

use crate::error::Result;

/// `D^-1/2 (A + I) D^-1/2` of the tree given by `parents` (-1 for the root),
/// row-major `[V, V]` (Kipf and Welling's normalised graph convolution).
pub fn adjacency(parents: &[i32]) -> Vec<f32> {
    let v = parents.len();
    let mut a = vec![0.0f32; v * v];
    for (i, &p) in parents.iter().enumerate() {
        a[i * v + i] = 1.0;
        if p >= 0 {
            let p = p as usize;
            a[i * v + p] = 1.0;
            a[p * v + i] = 1.0;
        }
    }
    let deg: Vec<f32> = (0..v).map(|i| a[i * v..(i + 1) * v].iter().sum()).collect();
    for i in 0..v {
        for j in 0..v {
            a[i * v + j] /= (deg[i] * deg[j]).sqrt();
        }
    }
    a
}

/// The adjacency as a `[V, V]` tensor (symmetric, so it is its own transpose).
pub fn adjacency_tensor(parents: &[i32]) -> Result<Tensor> {
    let v = parents.len();
    Ok(Tensor::from_vec(adjacency(parents), (v, v), &Device::Cpu)?)
}

/// Mix `x` `[..., V, C]` over the graph: `A x` per leading index, as one 2-D
/// product with `adjacency_t` = `A^T` `[V, V]` (a batched product of many tiny
/// matrices is several times slower on a CPU, backward pass included).
pub fn graph_mix(adjacency_t: &Tensor, x: &Tensor) -> Result<Tensor> {
    let dims = x.dims().to_vec();
    let r = dims.len();
    let (v, c) = (dims[r - 2], dims[r - 1]);
    let rows: usize = dims[..r - 2].iter().product();
    let y = x
        .reshape((rows, v, c))?
        .transpose(1, 2)?
        .contiguous()?
        .reshape((rows * c, v))?
        .matmul(adjacency_t)?
        .reshape((rows, c, v))?
        .transpose(1, 2)?
        .contiguous()?;
    Ok(y.reshape(dims)?)
}

/// `Tensor::cat`, made contiguous (linear layers need contiguous inputs).
pub fn cat<T: AsRef<Tensor>>(tensors: &[T], dim: usize) -> Result<Tensor> {
    Ok(Tensor::cat(tensors, dim)?.contiguous()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adjacency_is_symmetric_and_normalised() {
        let a = adjacency(&[-1, 0, 1, 1]);
        for i in 0..4 {
            for j in 0..4 {
                assert!((a[i * 4 + j] - a[j * 4 + i]).abs() < 1e-7);
            }
        }
        // Leaf 3: degree 2 (self + parent 1 of degree 4 = self, 0, 2, 3).
        assert!((a[3 * 4 + 3] - 0.5).abs() < 1e-6);
        assert!((a[3 * 4 + 1] - 1.0 / (2.0f32 * 4.0).sqrt()).abs() < 1e-6);
        assert_eq!(a[3 * 4], 0.0);
    }

    #[test]
    fn graph_mix_is_a_per_row_product() {
        let a = adjacency_tensor(&[-1, 0, 1]).unwrap();
        let x = Tensor::arange(0f32, 12.0, &Device::Cpu)
            .unwrap()
            .reshape((2, 3, 2))
            .unwrap();
        let want = a.broadcast_matmul(&x).unwrap().flatten_all().unwrap();
        let got = graph_mix(&a, &x).unwrap().flatten_all().unwrap();
        let d = (want - got).unwrap().abs().unwrap().max_all().unwrap();
        assert!(d.to_scalar::<f32>().unwrap() < 1e-5);
    }
}
