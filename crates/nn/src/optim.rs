//! The optimiser every trainer uses, over candle `Var`s: SGD with a step
//! schedule (the rate halved every N steps, the VAE reference) or Adam with
//! optional decoupled weight decay (AdamW), after global gradient-norm
//! clipping ([`clip_grad_norm`], the one clipping function).
//!
//! The moment estimates live in plain `Vec<f32>`s and the update is one scalar
//! loop per parameter, so the whole state (step count, first and second
//! moments) can be written to a checkpoint ([`Optimizer::state_tensors`]) and
//! restored ([`Optimizer::load_state`]) bit for bit, and a resumed run is the
//! run that never stopped.

use std::collections::HashMap;

use candle_core::backprop::GradStore;
use candle_core::{Device, Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::error::{NnError, Result};

/// The serialisable choice of update rule (as stored in model files:
/// `{"kind": "sgd", "lr": .., "halve_every": ..}` or `{"kind": "adam", "lr": ..}`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum OptimizerConfig {
    /// SGD, the rate halved every `halve_every` steps (MotionAug's VAE: lr 0.005
    /// halved every 4000 iterations).
    Sgd { lr: f64, halve_every: u64 },
    /// Adam with the usual betas (0.9, 0.999) and epsilon 1e-8.
    Adam { lr: f64 },
}

impl OptimizerConfig {
    pub fn validate(&self) -> Result<()> {
        let lr = match *self {
            OptimizerConfig::Sgd { lr, halve_every } => {
                if halve_every == 0 {
                    return Err(NnError::Config("SGD halve_every must be >= 1".into()));
                }
                lr
            }
            OptimizerConfig::Adam { lr } => lr,
        };
        if !(lr.is_finite() && lr > 0.0) {
            return Err(NnError::Config(format!("learning rate {lr} must be > 0")));
        }
        Ok(())
    }
}

impl Default for OptimizerConfig {
    fn default() -> Self {
        OptimizerConfig::Adam { lr: 1e-3 }
    }
}

/// Adam's settings; `weight_decay > 0` makes it AdamW (decoupled decay,
/// `w <- w (1 - lr wd)` before the Adam step, as candle-nn and PyTorch do).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    pub weight_decay: f64,
}

impl AdamConfig {
    pub fn new(lr: f64) -> Self {
        AdamConfig {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
        }
    }
}

/// The update rule an [`Optimizer`] runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    Sgd { lr: f64, halve_every: u64 },
    Adam(AdamConfig),
}

impl From<OptimizerConfig> for Method {
    fn from(c: OptimizerConfig) -> Self {
        match c {
            OptimizerConfig::Sgd { lr, halve_every } => Method::Sgd { lr, halve_every },
            OptimizerConfig::Adam { lr } => Method::Adam(AdamConfig::new(lr)),
        }
    }
}

impl From<AdamConfig> for Method {
    fn from(c: AdamConfig) -> Self {
        Method::Adam(c)
    }
}

pub struct Optimizer {
    method: Method,
    max_grad_norm: Option<f32>,
    params: Vec<(String, Var)>,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
    step: u64,
}

/// Global gradient-norm clipping, the one implementation: the L2 norm of all of
/// `grads` together (each parameter's squares summed in f64, then the
/// parameters' sums) and the factor every gradient is to be multiplied by:
/// `max_norm / norm` when the norm exceeds `max_norm`, else exactly 1.
///
/// The factor is returned rather than applied so that an update can fold it
/// into its own arithmetic (SGD scales its step, Adam its gradient), as the
/// optimisers did before they were merged; results stay bit for bit the same.
pub fn clip_grad_norm(grads: &[Option<Vec<f32>>], max_norm: Option<f32>) -> Clip {
    let sq: f64 = grads
        .iter()
        .flatten()
        .map(|g| g.iter().map(|x| (*x as f64) * (*x as f64)).sum::<f64>())
        .sum();
    let norm = sq.sqrt() as f32;
    let scale = match max_norm {
        Some(max) if norm > max => max / norm,
        _ => 1.0,
    };
    Clip { norm, scale }
}

/// What [`clip_grad_norm`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clip {
    /// The global gradient norm before clipping.
    pub norm: f32,
    /// The factor to multiply every gradient by (1 when no clipping is needed).
    pub scale: f32,
}

impl Optimizer {
    /// An optimiser over `params` (named, so its state can be saved by name);
    /// `max_grad_norm` clips the global gradient norm first.
    pub fn new(
        params: Vec<(String, Var)>,
        method: impl Into<Method>,
        max_grad_norm: Option<f32>,
    ) -> Self {
        let method = method.into();
        let adam = matches!(method, Method::Adam(_));
        let zeros = || -> Vec<Vec<f32>> {
            params
                .iter()
                .map(|(_, p)| {
                    if adam {
                        vec![0.0; p.elem_count()]
                    } else {
                        Vec::new()
                    }
                })
                .collect()
        };
        Optimizer {
            method,
            max_grad_norm,
            m: zeros(),
            v: zeros(),
            params,
            step: 0,
        }
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    pub fn method(&self) -> &Method {
        &self.method
    }

    /// Learning rate used by the next step.
    pub fn lr(&self) -> f64 {
        match self.method {
            Method::Sgd { lr, halve_every } => {
                lr * 0.5f64.powi((self.step / halve_every.max(1)).min(60) as i32)
            }
            Method::Adam(c) => c.lr,
        }
    }

    /// Set the base learning rate (for schedules computed by the caller).
    pub fn set_lr(&mut self, new: f64) {
        match &mut self.method {
            Method::Sgd { lr, .. } => *lr = new,
            Method::Adam(c) => c.lr = new,
        }
    }

    /// One step on every parameter that has a gradient in `grads`; returns the
    /// global gradient norm before clipping.
    pub fn step(&mut self, grads: &GradStore) -> Result<f32> {
        let mut gs = Vec::with_capacity(self.params.len());
        for (_, p) in &self.params {
            gs.push(match grads.get(p.as_tensor()) {
                Some(g) => Some(g.flatten_all()?.to_vec1::<f32>()?),
                None => None,
            });
        }
        let Clip { norm, scale } = clip_grad_norm(&gs, self.max_grad_norm);
        let lr = self.lr();
        self.step += 1;
        for (i, g) in gs.into_iter().enumerate() {
            let Some(g) = g else { continue };
            let p = &self.params[i].1;
            let mut w = p.flatten_all()?.to_vec1::<f32>()?;
            match self.method {
                Method::Sgd { .. } => {
                    let s = (lr as f32) * scale;
                    for (wj, gj) in w.iter_mut().zip(&g) {
                        *wj -= s * gj;
                    }
                }
                Method::Adam(c) => {
                    let (b1, b2, eps) = (c.beta1 as f32, c.beta2 as f32, c.eps as f32);
                    let bc1 = 1.0 - c.beta1.powi(self.step as i32);
                    let bc2_sqrt = (1.0 - c.beta2.powi(self.step as i32)).sqrt() as f32;
                    let step_size = (lr / bc1) as f32;
                    if c.weight_decay != 0.0 {
                        let keep = (1.0 - lr * c.weight_decay) as f32;
                        w.iter_mut().for_each(|wj| *wj *= keep);
                    }
                    let (m, v) = (&mut self.m[i], &mut self.v[i]);
                    for j in 0..w.len() {
                        let gj = g[j] * scale;
                        m[j] = b1 * m[j] + (1.0 - b1) * gj;
                        v[j] = b2 * v[j] + (1.0 - b2) * gj * gj;
                        w[j] -= step_size * m[j] / (v[j].sqrt() / bc2_sqrt + eps);
                    }
                }
            }
            p.set(&Tensor::from_vec(w, p.shape(), &Device::Cpu)?)?;
        }
        Ok(norm)
    }

    /// Adam's moments as tensors named `<prefix>.m.<param>` / `<prefix>.v.<param>`
    /// (none for SGD, whose only state is the step count).
    pub fn state_tensors(&self, prefix: &str) -> Result<Vec<(String, Tensor)>> {
        let mut out = Vec::new();
        if !matches!(self.method, Method::Adam(_)) {
            return Ok(out);
        }
        for (i, (name, p)) in self.params.iter().enumerate() {
            out.push((
                format!("{prefix}.m.{name}"),
                Tensor::from_slice(&self.m[i], p.shape(), &Device::Cpu)?,
            ));
            out.push((
                format!("{prefix}.v.{name}"),
                Tensor::from_slice(&self.v[i], p.shape(), &Device::Cpu)?,
            ));
        }
        Ok(out)
    }

    /// Restore the moments saved by [`Optimizer::state_tensors`] and the step count.
    pub fn load_state(
        &mut self,
        prefix: &str,
        tensors: &HashMap<String, Tensor>,
        step: u64,
    ) -> Result<()> {
        if matches!(self.method, Method::Adam(_)) {
            for (i, (name, p)) in self.params.iter().enumerate() {
                for (kind, dst) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                    let key = format!("{prefix}.{kind}.{name}");
                    let t = tensors.get(&key).ok_or_else(|| {
                        NnError::State(format!("optimiser state `{key}` missing"))
                    })?;
                    if t.dims() != p.dims() {
                        return Err(NnError::State(format!(
                            "optimiser state `{key}` has shape {:?}, parameter has {:?}",
                            t.dims(),
                            p.dims()
                        )));
                    }
                    *dst = t.flatten_all()?.to_vec1::<f32>()?;
                }
            }
        }
        self.step = step;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quadratic(w: &Var) -> GradStore {
        let loss = w
            .as_tensor()
            .affine(1.0, -3.0)
            .unwrap()
            .sqr()
            .unwrap()
            .sum_all()
            .unwrap();
        loss.backward().unwrap()
    }

    fn value(w: &Var) -> Vec<f32> {
        w.as_tensor().to_vec1::<f32>().unwrap()
    }

    #[test]
    fn adam_first_steps_match_closed_form() {
        // Minimise (w - 3)^2 from w = 0: Adam's first step moves by lr * sign(g).
        let w = Var::new(&[0.0f32], &Device::Cpu).unwrap();
        let mut opt = Optimizer::new(vec![("w".into(), w.clone())], AdamConfig::new(0.1), None);
        let norm = opt.step(&quadratic(&w)).unwrap();
        assert!((norm - 6.0).abs() < 1e-6);
        assert!((value(&w)[0] - 0.1).abs() < 1e-6, "{:?}", value(&w));
        for _ in 0..300 {
            opt.step(&quadratic(&w)).unwrap();
        }
        assert!((value(&w)[0] - 3.0).abs() < 0.05, "{:?}", value(&w));
    }

    #[test]
    fn the_serialised_config_is_the_same_adam() {
        // The constants as f64 then f32 equal the f32 literals the VAE used.
        let c = AdamConfig::new(0.1);
        assert_eq!(
            (c.beta1 as f32, c.beta2 as f32, c.eps as f32),
            (0.9f32, 0.999f32, 1e-8f32)
        );
        assert_eq!(
            Method::from(OptimizerConfig::Adam { lr: 0.1 }),
            Method::Adam(c)
        );
        assert!(
            OptimizerConfig::Sgd {
                lr: 0.5,
                halve_every: 0
            }
            .validate()
            .is_err()
        );
        assert!(OptimizerConfig::Adam { lr: -1.0 }.validate().is_err());
        assert!(OptimizerConfig::default().validate().is_ok());
    }

    #[test]
    fn clipping_limits_the_gradient() {
        let w = Var::new(&[0.0f32, 0.0], &Device::Cpu).unwrap();
        let mut opt = Optimizer::new(
            vec![("w".into(), w.clone())],
            AdamConfig::new(0.1),
            Some(1.0),
        );
        let norm = opt.step(&quadratic(&w)).unwrap();
        assert!((norm - 72f32.sqrt()).abs() < 1e-4);
        // The moment after one step equals (1 - beta1) * clipped gradient.
        let st = opt.state_tensors("o").unwrap();
        let m = st[0].1.to_vec1::<f32>().unwrap();
        let expect = 0.1 * (-6.0 / 72f32.sqrt());
        assert!((m[0] - expect).abs() < 1e-6, "{m:?} vs {expect}");
        // The function itself: below the limit the factor is exactly 1.
        let g = vec![Some(vec![3.0f32, 4.0]), None];
        assert_eq!(
            clip_grad_norm(&g, Some(10.0)),
            Clip {
                norm: 5.0,
                scale: 1.0
            }
        );
        assert_eq!(clip_grad_norm(&g, None).scale, 1.0);
        assert_eq!(
            clip_grad_norm(&g, Some(1.0)),
            Clip {
                norm: 5.0,
                scale: 0.2
            }
        );
    }

    #[test]
    fn sgd_halves_its_rate_on_schedule_and_descends() {
        let w = Var::new(&[1.0f32], &Device::Cpu).unwrap();
        let cfg = OptimizerConfig::Sgd {
            lr: 0.1,
            halve_every: 2,
        };
        let mut opt = Optimizer::new(vec![("w".into(), w.clone())], cfg, None);
        let mut rates = vec![];
        for _ in 0..5 {
            rates.push(opt.lr());
            let loss = w.as_tensor().sqr().unwrap().sum_all().unwrap();
            opt.step(&loss.backward().unwrap()).unwrap();
        }
        assert_eq!(rates, vec![0.1, 0.1, 0.05, 0.05, 0.025]);
        // w <- w (1 - 2 lr) each step.
        let expect: f64 = rates.iter().map(|r| 1.0 - 2.0 * r).product();
        let got = value(&w)[0] as f64;
        assert!((got - expect).abs() < 1e-6, "{got} vs {expect}");
    }

    #[test]
    fn weight_decay_shrinks_the_weights() {
        let w = Var::new(&[3.0f32], &Device::Cpu).unwrap();
        let cfg = AdamConfig {
            weight_decay: 0.5,
            ..AdamConfig::new(0.1)
        };
        let mut opt = Optimizer::new(vec![("w".into(), w.clone())], cfg, None);
        // At the minimum the gradient is 0: only the decay moves w.
        opt.step(&quadratic(&w)).unwrap();
        assert!((value(&w)[0] - 3.0 * 0.95).abs() < 1e-6);
    }

    #[test]
    fn state_round_trip_resumes_bit_for_bit() {
        let run = |split: Option<usize>| {
            let w = Var::new(&[0.5f32, -2.0, 1.0], &Device::Cpu).unwrap();
            let mut opt = Optimizer::new(
                vec![("w".into(), w.clone())],
                AdamConfig::new(0.05),
                Some(2.0),
            );
            for i in 0..10 {
                if Some(i) == split {
                    let state: HashMap<String, Tensor> =
                        opt.state_tensors("opt").unwrap().into_iter().collect();
                    let steps = opt.steps();
                    let saved = w.as_tensor().copy().unwrap();
                    let w2 = Var::from_tensor(&saved).unwrap();
                    opt = Optimizer::new(
                        vec![("w".into(), w2.clone())],
                        AdamConfig::new(0.05),
                        Some(2.0),
                    );
                    opt.load_state("opt", &state, steps).unwrap();
                    // Continue on the restored copy.
                    for _ in i..10 {
                        opt.step(&quadratic(&w2)).unwrap();
                    }
                    return value(&w2);
                }
                opt.step(&quadratic(&w)).unwrap();
            }
            value(&w)
        };
        let straight: Vec<u32> = run(None).iter().map(|x| x.to_bits()).collect();
        let resumed: Vec<u32> = run(Some(4)).iter().map(|x| x.to_bits()).collect();
        assert_eq!(straight, resumed);
        // Missing state is an error.
        let w = Var::new(&[0.0f32], &Device::Cpu).unwrap();
        let mut opt = Optimizer::new(vec![("w".into(), w)], AdamConfig::new(0.1), None);
        assert!(opt.load_state("opt", &HashMap::new(), 1).is_err());
    }
}
