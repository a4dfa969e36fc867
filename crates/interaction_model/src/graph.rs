//! Small building blocks shared by the networks: a ReLU MLP on candle-nn
//! linears, the normalised skeleton adjacency the graph layers mix joints
//! with, seeded initialisation (candle's CPU random ops cannot be seeded, so
//! every weight is redrawn from a ChaCha generator by name) and the
//! reparameterisation trick with seeded noise.

use candle_core::{DType, Device, Tensor};
use candle_nn::{Linear, Module, VarBuilder, VarMap};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::error::Result;

/// `in -> hidden... -> out`, ReLU between layers, linear output.
pub struct Mlp {
    layers: Vec<Linear>,
}

impl Mlp {
    pub fn new(vb: VarBuilder, fan_in: usize, hidden: &[usize], fan_out: usize) -> Result<Self> {
        let dims: Vec<usize> = std::iter::once(fan_in)
            .chain(hidden.iter().copied())
            .chain(std::iter::once(fan_out))
            .collect();
        let layers = dims
            .windows(2)
            .enumerate()
            .map(|(i, w)| candle_nn::linear(w[0], w[1], vb.pp(i.to_string())))
            .collect::<candle_core::Result<_>>()?;
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

/// Redraw every variable of `varmap` from a generator seeded with `seed`, in
/// name order: weights uniform in `+-1/sqrt(fan_in)` (PyTorch's default, fan_in
/// = product of all but the first dimension), biases zero.
pub fn seeded_init(varmap: &VarMap, seed: u64) -> Result<()> {
    let data = varmap
        .data()
        .lock()
        .map_err(|_| crate::ModelError::Data("the variable map lock is poisoned".into()))?;
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for name in names {
        let var = &data[name];
        let dims = var.dims().to_vec();
        let n: usize = dims.iter().product();
        let values: Vec<f32> = if dims.len() < 2 || name.ends_with("bias") {
            vec![0.0; n]
        } else {
            let fan_in: usize = dims[1..].iter().product();
            let bound = 1.0 / (fan_in as f32).sqrt();
            (0..n).map(|_| rng.random_range(-bound..=bound)).collect()
        };
        var.set(&Tensor::from_vec(values, dims, &Device::Cpu)?)?;
    }
    Ok(())
}

/// A fresh variable map and its builder (f32, CPU).
pub fn new_varmap() -> (VarMap, VarBuilder<'static>) {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    (varmap, vb)
}

/// Standard normal noise of `shape` from `rng`.
pub fn normal(shape: &[usize], rng: &mut ChaCha8Rng) -> Result<Tensor> {
    let n: usize = shape.iter().product();
    let v: Vec<f32> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
    Ok(Tensor::from_vec(v, shape, &Device::Cpu)?)
}

/// `Tensor::cat`, made contiguous (linear layers need contiguous inputs).
pub fn cat<T: AsRef<Tensor>>(tensors: &[T], dim: usize) -> Result<Tensor> {
    Ok(Tensor::cat(tensors, dim)?.contiguous()?)
}

/// `mu + exp(logvar / 2) * eps`.
pub fn reparameterise(mu: &Tensor, logvar: &Tensor, eps: &Tensor) -> Result<Tensor> {
    Ok(mu.add(&(logvar * 0.5)?.exp()?.mul(eps)?)?)
}

/// `KL[N(mu, exp(logvar)) || N(0, I)]`, summed over the last dimension and
/// averaged over the rest.
pub fn kl_normal(mu: &Tensor, logvar: &Tensor) -> Result<Tensor> {
    let per = ((mu.sqr()? + logvar.exp()?)? - logvar)?.affine(0.5, -0.5)?;
    let rows = per.elem_count() / per.dim(candle_core::D::Minus1)?;
    Ok((per.sum_all()? / rows as f64)?)
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

    #[test]
    fn seeded_init_is_reproducible() {
        let draw = |seed| {
            let (vm, vb) = new_varmap();
            let _ = candle_nn::linear(4, 3, vb.pp("l")).unwrap();
            seeded_init(&vm, seed).unwrap();
            let d = vm.data().lock().unwrap();
            d["l.weight"]
                .as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
        };
        assert_eq!(draw(3), draw(3));
        assert_ne!(draw(3), draw(4));
    }
}
