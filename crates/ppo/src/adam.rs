//! Adam over candle `Var`s with its moment estimates kept in plain `Vec<f32>`s, so the
//! whole optimiser state (step count, first and second moments) can be written to a
//! checkpoint and restored bit for bit. Optional global gradient-norm clipping.

use std::collections::HashMap;

use candle_core::backprop::GradStore;
use candle_core::{Device, Tensor, Var};

use crate::error::{PpoError, Result};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    pub max_grad_norm: Option<f32>,
}

impl AdamConfig {
    pub fn new(lr: f64) -> Self {
        AdamConfig {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            max_grad_norm: None,
        }
    }
}

pub struct Adam {
    config: AdamConfig,
    params: Vec<(String, Var)>,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
    step: u64,
}

impl Adam {
    pub fn new(params: Vec<(String, Var)>, config: AdamConfig) -> Self {
        let m = params
            .iter()
            .map(|(_, p)| vec![0.0; p.elem_count()])
            .collect();
        let v = params
            .iter()
            .map(|(_, p)| vec![0.0; p.elem_count()])
            .collect();
        Adam {
            config,
            params,
            m,
            v,
            step: 0,
        }
    }

    pub fn steps(&self) -> u64 {
        self.step
    }

    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// One Adam step on every parameter that has a gradient in `grads`.
    /// Returns the global gradient L2 norm before clipping.
    pub fn step(&mut self, grads: &GradStore) -> Result<f32> {
        let mut gs: Vec<Option<Vec<f32>>> = Vec::with_capacity(self.params.len());
        let mut sq = 0.0f64;
        for (_, p) in &self.params {
            let g = match grads.get(p.as_tensor()) {
                Some(g) => {
                    let g = g.flatten_all()?.to_vec1::<f32>()?;
                    sq += g.iter().map(|x| (*x as f64) * (*x as f64)).sum::<f64>();
                    Some(g)
                }
                None => None,
            };
            gs.push(g);
        }
        let norm = sq.sqrt() as f32;
        let scale = match self.config.max_grad_norm {
            Some(max) if norm > max => max / norm,
            _ => 1.0,
        };
        self.step += 1;
        let c = &self.config;
        let (b1, b2) = (c.beta1 as f32, c.beta2 as f32);
        let bc1 = 1.0 - c.beta1.powi(self.step as i32);
        let bc2 = 1.0 - c.beta2.powi(self.step as i32);
        let step_size = (c.lr / bc1) as f32;
        let bc2_sqrt = bc2.sqrt() as f32;
        let eps = c.eps as f32;
        for (i, g) in gs.into_iter().enumerate() {
            let Some(g) = g else { continue };
            let p = &self.params[i].1;
            let mut w = p.flatten_all()?.to_vec1::<f32>()?;
            let (m, v) = (&mut self.m[i], &mut self.v[i]);
            for j in 0..w.len() {
                let gj = g[j] * scale;
                m[j] = b1 * m[j] + (1.0 - b1) * gj;
                v[j] = b2 * v[j] + (1.0 - b2) * gj * gj;
                w[j] -= step_size * m[j] / (v[j].sqrt() / bc2_sqrt + eps);
            }
            p.set(&Tensor::from_vec(w, p.shape(), &Device::Cpu)?)?;
        }
        Ok(norm)
    }

    /// Moment tensors named `<prefix>.m.<param>` / `<prefix>.v.<param>`.
    pub fn state_tensors(&self, prefix: &str) -> Result<Vec<(String, Tensor)>> {
        let mut out = Vec::with_capacity(2 * self.params.len());
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

    /// Restore moments saved by `state_tensors` and the step count.
    pub fn load_state(
        &mut self,
        prefix: &str,
        tensors: &HashMap<String, Tensor>,
        step: u64,
    ) -> Result<()> {
        for (i, (name, p)) in self.params.iter().enumerate() {
            for (kind, dst) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                let key = format!("{prefix}.{kind}.{name}");
                let t = tensors
                    .get(&key)
                    .ok_or_else(|| PpoError::Config(format!("optimiser state `{key}` missing")))?;
                if t.dims() != p.dims() {
                    return Err(PpoError::Config(format!(
                        "optimiser state `{key}` has shape {:?}, parameter has {:?}",
                        t.dims(),
                        p.dims()
                    )));
                }
                *dst = t.flatten_all()?.to_vec1::<f32>()?;
            }
        }
        self.step = step;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_steps_match_closed_form() {
        // Minimise (w - 3)^2 from w = 0: Adam's first step moves by lr * sign(g).
        let w = Var::new(&[0.0f32], &Device::Cpu).unwrap();
        let mut opt = Adam::new(vec![("w".into(), w.clone())], AdamConfig::new(0.1));
        let loss = w
            .as_tensor()
            .affine(1.0, -3.0)
            .unwrap()
            .sqr()
            .unwrap()
            .sum_all()
            .unwrap();
        let g = loss.backward().unwrap();
        let norm = opt.step(&g).unwrap();
        assert!((norm - 6.0).abs() < 1e-6);
        let v = w.as_tensor().to_vec1::<f32>().unwrap()[0];
        assert!((v - 0.1).abs() < 1e-6, "{v}");
        for _ in 0..300 {
            let loss = w
                .as_tensor()
                .affine(1.0, -3.0)
                .unwrap()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap();
            opt.step(&loss.backward().unwrap()).unwrap();
        }
        let v = w.as_tensor().to_vec1::<f32>().unwrap()[0];
        assert!((v - 3.0).abs() < 0.05, "{v}");
    }

    #[test]
    fn clipping_limits_the_gradient() {
        let w = Var::new(&[0.0f32, 0.0], &Device::Cpu).unwrap();
        let mut cfg = AdamConfig::new(0.1);
        cfg.max_grad_norm = Some(1.0);
        let mut opt = Adam::new(vec![("w".into(), w.clone())], cfg);
        let loss = w
            .as_tensor()
            .affine(1.0, -3.0)
            .unwrap()
            .sqr()
            .unwrap()
            .sum_all()
            .unwrap();
        let norm = opt.step(&loss.backward().unwrap()).unwrap();
        assert!((norm - 72f32.sqrt()).abs() < 1e-4);
        // The moment after one step equals (1 - beta1) * clipped gradient.
        let st = opt.state_tensors("o").unwrap();
        let m = st[0].1.to_vec1::<f32>().unwrap();
        let expect = 0.1 * (-6.0 / 72f32.sqrt());
        assert!((m[0] - expect).abs() < 1e-6, "{m:?} vs {expect}");
    }
}
