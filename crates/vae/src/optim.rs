//! Optimisers over candle `Var`s: plain SGD with the reference's step schedule
//! (learning rate halved every N iterations) and Adam, both with optional global
//! gradient-norm clipping. State lives in `Vec<f32>`s, like the ppo crate's Adam.

use candle_core::backprop::GradStore;
use candle_core::{Device, Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum OptimizerConfig {
    /// MotionAug reference: SGD, lr 0.005 halved every 4000 iterations.
    Sgd {
        lr: f64,
        halve_every: u64,
    },
    Adam {
        lr: f64,
    },
}

impl OptimizerConfig {
    pub fn reference() -> Self {
        OptimizerConfig::Sgd {
            lr: 0.005,
            halve_every: 4000,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let lr = match *self {
            OptimizerConfig::Sgd { lr, halve_every } => {
                if halve_every == 0 {
                    return Err(VaeError::Config("SGD halve_every must be >= 1".into()));
                }
                lr
            }
            OptimizerConfig::Adam { lr } => lr,
        };
        if !(lr.is_finite() && lr > 0.0) {
            return Err(VaeError::Config(format!("learning rate {lr} must be > 0")));
        }
        Ok(())
    }
}

impl Default for OptimizerConfig {
    fn default() -> Self {
        OptimizerConfig::Adam { lr: 1e-3 }
    }
}

pub struct Optimizer {
    config: OptimizerConfig,
    max_grad_norm: Option<f32>,
    params: Vec<(String, Var)>,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
    step: u64,
}

impl Optimizer {
    pub fn new(
        params: Vec<(String, Var)>,
        config: OptimizerConfig,
        max_grad_norm: Option<f32>,
    ) -> Self {
        let zeros = |on: bool| {
            params
                .iter()
                .map(|(_, p)| {
                    if on {
                        vec![0.0; p.elem_count()]
                    } else {
                        Vec::new()
                    }
                })
                .collect()
        };
        let adam = matches!(config, OptimizerConfig::Adam { .. });
        Optimizer {
            config,
            max_grad_norm,
            m: zeros(adam),
            v: zeros(adam),
            params,
            step: 0,
        }
    }

    /// Learning rate used by the next step.
    pub fn lr(&self) -> f64 {
        match self.config {
            OptimizerConfig::Sgd { lr, halve_every } => {
                lr * 0.5f64.powi((self.step / halve_every).min(60) as i32)
            }
            OptimizerConfig::Adam { lr } => lr,
        }
    }

    /// One step on every parameter with a gradient; returns the gradient norm
    /// before clipping.
    pub fn step(&mut self, grads: &GradStore) -> Result<f32> {
        let mut gs = Vec::with_capacity(self.params.len());
        let mut sq = 0.0f64;
        for (_, p) in &self.params {
            let g = match grads.get(p.as_tensor()) {
                Some(g) => {
                    let g = g.flatten_all()?.to_vec1::<f32>()?;
                    sq += g.iter().map(|x| (*x as f64).powi(2)).sum::<f64>();
                    Some(g)
                }
                None => None,
            };
            gs.push(g);
        }
        let norm = sq.sqrt() as f32;
        let scale = match self.max_grad_norm {
            Some(max) if norm > max => max / norm,
            _ => 1.0,
        };
        let lr = self.lr();
        self.step += 1;
        for (i, g) in gs.into_iter().enumerate() {
            let Some(g) = g else { continue };
            let p = &self.params[i].1;
            let mut w = p.flatten_all()?.to_vec1::<f32>()?;
            match self.config {
                OptimizerConfig::Sgd { .. } => {
                    let s = (lr as f32) * scale;
                    for (wj, gj) in w.iter_mut().zip(&g) {
                        *wj -= s * gj;
                    }
                }
                OptimizerConfig::Adam { .. } => {
                    let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
                    let bc1 = 1.0 - 0.9f64.powi(self.step as i32);
                    let bc2 = (1.0 - 0.999f64.powi(self.step as i32)).sqrt() as f32;
                    let step_size = (lr / bc1) as f32;
                    let (m, v) = (&mut self.m[i], &mut self.v[i]);
                    for j in 0..w.len() {
                        let gj = g[j] * scale;
                        m[j] = b1 * m[j] + (1.0 - b1) * gj;
                        v[j] = b2 * v[j] + (1.0 - b2) * gj * gj;
                        w[j] -= step_size * m[j] / (v[j].sqrt() / bc2 + eps);
                    }
                }
            }
            p.set(&Tensor::from_vec(w, p.shape(), &Device::Cpu)?)?;
        }
        Ok(norm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let got = w.as_tensor().to_vec1::<f32>().unwrap()[0] as f64;
        assert!((got - expect).abs() < 1e-6, "{got} vs {expect}");
    }

    #[test]
    fn adam_first_step_moves_by_lr() {
        let w = Var::new(&[0.0f32], &Device::Cpu).unwrap();
        let mut opt = Optimizer::new(
            vec![("w".into(), w.clone())],
            OptimizerConfig::Adam { lr: 0.1 },
            Some(1.0),
        );
        let loss = w
            .as_tensor()
            .affine(1.0, -3.0)
            .unwrap()
            .sqr()
            .unwrap()
            .sum_all()
            .unwrap();
        let norm = opt.step(&loss.backward().unwrap()).unwrap();
        assert!((norm - 6.0).abs() < 1e-5);
        let v = w.as_tensor().to_vec1::<f32>().unwrap()[0];
        assert!((v - 0.1).abs() < 1e-5, "{v}");
    }
}
