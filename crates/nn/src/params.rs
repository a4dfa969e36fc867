//! Named, seeded parameters: the one place initial weights come from.
//!
//! candle's CPU random ops cannot be seeded, so every parameter is drawn from one
//! ChaCha8 generator, in the order the layers register them, under a stable name
//! (`enc.lstm_fw.w_ih`, `policy.mean.0.weight`, ...). Those names are what the
//! optimisers, checkpoints and model files use. Same seed, same layers, same
//! order: the same network, bit for bit.
//!
//! **The scheme**: PyTorch's default for linear layers, every weight and bias
//! uniform in `[-1/sqrt(fan_in), +1/sqrt(fan_in)]` ([`Params::uniform`]), with
//! `fan_in` the product of all but the first dimension of the weight. Modules
//! built with candle-nn's constructors (`candle_nn::linear(.., vb)`) get the same
//! scheme through [`Params::var_builder`].
//!
//! **The variant**: [`Params::uniform_half_open`] draws from the half-open
//! interval and scales the draws; the PPO networks were trained that way before
//! this crate existed and keep it so that their checkpoints and runs stay bit
//! for bit what they were (see [`crate::MlpInit::ScaledOutput`]).
//!
//! The store is shared (`Clone` is cheap, an `Arc`), which is what lets a
//! candle-nn `VarBuilder` register into it while the caller keeps a handle.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};

use candle_core::{DType, Device, Shape, Tensor, Var};
use candle_nn::VarBuilder;
use candle_nn::var_builder::SimpleBackend;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{NnError, Result};

#[derive(Clone)]
pub struct Params {
    inner: Arc<Mutex<Store>>,
}

struct Store {
    vars: Vec<(String, Var)>,
    index: HashMap<String, usize>,
    rng: ChaCha8Rng,
}

impl Params {
    /// An empty store drawing from `ChaCha8Rng::seed_from_u64(seed)`.
    pub fn new(seed: u64) -> Self {
        Params::from_rng(ChaCha8Rng::seed_from_u64(seed))
    }

    /// An empty store drawing from `rng` (a generator the caller keeps using
    /// afterwards: take it back with [`Params::rng`]).
    pub fn from_rng(rng: ChaCha8Rng) -> Self {
        Params {
            inner: Arc::new(Mutex::new(Store {
                vars: Vec::new(),
                index: HashMap::new(),
                rng,
            })),
        }
    }

    fn store(&self) -> Result<MutexGuard<'_, Store>> {
        self.inner
            .lock()
            .map_err(|_| NnError::State("the parameter store's lock is poisoned".into()))
    }

    /// The generator in its current state (after every draw so far).
    pub fn rng(&self) -> Result<ChaCha8Rng> {
        Ok(self.store()?.rng.clone())
    }

    /// The scheme: uniform in `[-bound, bound]`.
    pub fn uniform(&self, name: &str, shape: &[usize], bound: f32) -> Result<Tensor> {
        let mut s = self.store()?;
        let n: usize = shape.iter().product();
        let data: Vec<f32> = (0..n).map(|_| s.rng.random_range(-bound..=bound)).collect();
        s.register(name, Tensor::from_vec(data, shape, &Device::Cpu)?)
    }

    /// The PPO variant: uniform in `[-bound, bound)`, each draw times `scale`.
    pub fn uniform_half_open(
        &self,
        name: &str,
        shape: &[usize],
        bound: f32,
        scale: f32,
    ) -> Result<Tensor> {
        let mut s = self.store()?;
        let n: usize = shape.iter().product();
        let data: Vec<f32> = (0..n)
            .map(|_| s.rng.random_range(-bound..bound) * scale)
            .collect();
        s.register(name, Tensor::from_vec(data, shape, &Device::Cpu)?)
    }

    /// Every entry `value` (no draw).
    pub fn constant(&self, name: &str, shape: &[usize], value: f32) -> Result<Tensor> {
        let n: usize = shape.iter().product();
        self.values(name, shape, vec![value; n])
    }

    /// Given values (no draw).
    pub fn values(&self, name: &str, shape: &[usize], data: Vec<f32>) -> Result<Tensor> {
        let t = Tensor::from_vec(data, shape, &Device::Cpu)?;
        self.store()?.register(name, t)
    }

    /// The parameter registered as `name`.
    pub fn get(&self, name: &str) -> Option<Var> {
        let s = self.store().ok()?;
        s.index.get(name).map(|&i| s.vars[i].1.clone())
    }

    /// Every parameter, in registration order.
    pub fn vars(&self) -> Vec<(String, Var)> {
        self.store().map(|s| s.vars.clone()).unwrap_or_default()
    }

    /// Parameters whose name starts with one of `prefixes`, in registration order.
    pub fn with_prefix(&self, prefixes: &[&str]) -> Vec<(String, Var)> {
        self.vars()
            .into_iter()
            .filter(|(n, _)| prefixes.iter().any(|p| n.starts_with(p)))
            .collect()
    }

    /// Number of scalars.
    pub fn count(&self) -> usize {
        self.vars().iter().map(|(_, v)| v.elem_count()).sum()
    }

    /// A candle-nn `VarBuilder` that registers into this store with the scheme:
    /// a `Uniform { lo, up }` hint (candle-nn's linear bias) is drawn in
    /// `[lo, up]`, a constant hint is kept, and any other hint (normal, Kaiming)
    /// becomes uniform in `+-1/sqrt(fan_in)`. Asking twice for a name returns
    /// the registered tensor.
    pub fn var_builder(&self) -> VarBuilder<'static> {
        VarBuilder::from_backend(Box::new(self.clone()), DType::F32, Device::Cpu)
    }

    /// Write every parameter to a safetensors file under its name.
    pub fn save(&self, path: &Path) -> Result<()> {
        let tensors: HashMap<String, Tensor> = self
            .vars()
            .into_iter()
            .map(|(n, v)| (n, v.as_tensor().clone()))
            .collect();
        candle_core::safetensors::save(&tensors, path).map_err(|e| NnError::File {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })
    }

    /// Set every registered parameter from a safetensors file written by
    /// [`Params::save`]; a missing name or a different shape is an error.
    pub fn load(&self, path: &Path) -> Result<()> {
        let file = |msg: String| NnError::File {
            path: path.to_path_buf(),
            msg,
        };
        let tensors =
            candle_core::safetensors::load(path, &Device::Cpu).map_err(|e| file(e.to_string()))?;
        for (name, var) in self.vars() {
            let t = tensors
                .get(&name)
                .ok_or_else(|| file(format!("tensor `{name}` missing")))?;
            if t.dims() != var.dims() {
                return Err(file(format!(
                    "tensor `{name}` has shape {:?}, the network has {:?}",
                    t.dims(),
                    var.dims()
                )));
            }
            var.set(&t.to_dtype(DType::F32)?)?;
        }
        Ok(())
    }
}

impl Store {
    fn register(&mut self, name: &str, t: Tensor) -> Result<Tensor> {
        if self.index.contains_key(name) {
            return Err(NnError::Duplicate(name.to_string()));
        }
        let v = Var::from_tensor(&t)?;
        let t = v.as_tensor().clone();
        self.index.insert(name.to_string(), self.vars.len());
        self.vars.push((name.to_string(), v));
        Ok(t)
    }
}

impl SimpleBackend for Params {
    fn get(
        &self,
        shape: Shape,
        name: &str,
        hint: candle_nn::Init,
        dtype: DType,
        dev: &Device,
    ) -> candle_core::Result<Tensor> {
        let map = |e: NnError| candle_core::Error::Msg(e.to_string());
        if dtype != DType::F32 || !dev.is_cpu() {
            candle_core::bail!("parameter `{name}`: the store holds f32 tensors on the CPU");
        }
        let dims = shape.dims().to_vec();
        {
            let s = self.store().map_err(map)?;
            if let Some(&i) = s.index.get(name) {
                let v = &s.vars[i].1;
                if v.dims() != dims.as_slice() {
                    candle_core::bail!(
                        "parameter `{name}` has shape {:?}, asked for {dims:?}",
                        v.dims()
                    );
                }
                return Ok(v.as_tensor().clone());
            }
        }
        match hint {
            candle_nn::Init::Const(c) => self.constant(name, &dims, c as f32),
            candle_nn::Init::Uniform { lo, up } if lo == -up => {
                self.uniform(name, &dims, up as f32)
            }
            _ => {
                let fan_in: usize = dims.iter().skip(1).product::<usize>().max(1);
                self.uniform(name, &dims, 1.0 / (fan_in as f32).sqrt())
            }
        }
        .map_err(map)
    }

    fn get_unchecked(
        &self,
        name: &str,
        _dtype: DType,
        _dev: &Device,
    ) -> candle_core::Result<Tensor> {
        let s = self
            .store()
            .map_err(|e| candle_core::Error::Msg(e.to_string()))?;
        match s.index.get(name) {
            Some(&i) => Ok(s.vars[i].1.as_tensor().clone()),
            None => candle_core::bail!("parameter `{name}` is not registered"),
        }
    }

    fn contains_tensor(&self, name: &str) -> bool {
        self.store().is_ok_and(|s| s.index.contains_key(name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(p: &Params, name: &str) -> Vec<f32> {
        p.vars()
            .into_iter()
            .find(|(n, _)| n == name)
            .unwrap()
            .1
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap()
    }

    #[test]
    fn seeded_init_is_reproducible_and_in_bounds() {
        let draw = |seed| {
            let p = Params::new(seed);
            p.uniform("a", &[3, 4], 0.5).unwrap();
            p.uniform("b", &[5], 0.5).unwrap();
            (values(&p, "a"), values(&p, "b"))
        };
        assert_eq!(draw(3), draw(3));
        assert_ne!(draw(3), draw(4));
        let (a, b) = draw(3);
        assert!(a.iter().chain(&b).all(|v| v.abs() <= 0.5));
    }

    #[test]
    fn registration_order_is_draw_order_and_names_are_unique() {
        let p = Params::new(1);
        p.uniform("x", &[4], 1.0).unwrap();
        let q = Params::new(1);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let expect: Vec<f32> = (0..4).map(|_| rng.random_range(-1.0f32..=1.0)).collect();
        assert_eq!(values(&p, "x"), expect);
        assert!(matches!(
            p.constant("x", &[1], 0.0),
            Err(NnError::Duplicate(_))
        ));
        // The rng handed back continues where the draws stopped.
        q.uniform("y", &[4], 1.0).unwrap();
        let next: f32 = q.rng().unwrap().random();
        assert_eq!(next, rng.random::<f32>());
    }

    #[test]
    fn var_builder_registers_with_the_scheme() {
        let p = Params::new(2);
        let vb = p.var_builder();
        let _l = candle_nn::linear(4, 3, vb.pp("l")).unwrap();
        let names: Vec<String> = p.vars().into_iter().map(|(n, _)| n).collect();
        assert_eq!(names, ["l.weight", "l.bias"]);
        // Same draws as the store's own uniform with bound 1/sqrt(4).
        let q = Params::new(2);
        q.uniform("w", &[3, 4], 0.5).unwrap();
        q.uniform("b", &[3], 0.5).unwrap();
        assert_eq!(values(&p, "l.weight"), values(&q, "w"));
        assert_eq!(values(&p, "l.bias"), values(&q, "b"));
        // Asking again returns the same parameter.
        let again = vb.pp("l").get((3, 4), "weight").unwrap();
        assert_eq!(
            again.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            values(&p, "l.weight")
        );
        assert_eq!(p.vars().len(), 2);
    }

    #[test]
    fn save_load_round_trip_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.safetensors");
        let p = Params::new(5);
        p.uniform("a", &[2, 3], 1.0).unwrap();
        p.save(&path).unwrap();
        let q = Params::new(6);
        q.uniform("a", &[2, 3], 1.0).unwrap();
        q.load(&path).unwrap();
        assert_eq!(values(&p, "a"), values(&q, "a"));
        let r = Params::new(6);
        r.uniform("b", &[2, 3], 1.0).unwrap();
        assert!(r.load(&path).is_err());
        std::fs::write(&path, b"junk").unwrap();
        assert!(q.load(&path).is_err());
    }
}
