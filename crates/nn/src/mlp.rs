//! The multi-layer perceptron every trainer uses: `in -> hidden... -> out`,
//! ReLU between layers, a linear output.
//!
//! Layers are named `{name}.{i}` (`{name}.{i}.weight`, `{name}.{i}.bias`).
//! [`MlpInit`] says how they are drawn: the scheme of [`Params`], or the PPO
//! variant whose output layer starts near zero.

use candle_core::Tensor;
use candle_nn::VarBuilder;
use serde::{Deserialize, Serialize};

use crate::error::{NnError, Result};
use crate::linear::Linear;
use crate::params::Params;

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub enum MlpInit {
    /// Every layer with [`Linear::new`] (the scheme: uniform `+-1/sqrt(fan_in)`).
    #[default]
    Uniform,
    /// PPO's actor and critic: weights and biases uniform in the half-open
    /// `[-1/sqrt(fan_in), 1/sqrt(fan_in))` ([`Params::uniform_half_open`]);
    /// the output layer's weights are further scaled by `scale` and its bias
    /// is zero, so a small `scale` makes the initial output close to 0.
    ScaledOutput { scale: f32 },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MlpConfig {
    pub input: usize,
    pub hidden: Vec<usize>,
    pub output: usize,
    #[serde(default)]
    pub init: MlpInit,
}

impl MlpConfig {
    pub fn new(input: usize, hidden: &[usize], output: usize) -> Self {
        MlpConfig {
            input,
            hidden: hidden.to_vec(),
            output,
            init: MlpInit::Uniform,
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.input == 0 || self.output == 0 || self.hidden.contains(&0) {
            return Err(NnError::Config(format!(
                "layer sizes must be positive: {} -> {:?} -> {}",
                self.input, self.hidden, self.output
            )));
        }
        Ok(())
    }

    /// `[input, hidden..., output]`.
    fn dims(&self) -> Vec<usize> {
        std::iter::once(self.input)
            .chain(self.hidden.iter().copied())
            .chain(std::iter::once(self.output))
            .collect()
    }
}

pub struct Mlp {
    layers: Vec<Linear>,
}

impl Mlp {
    /// Layers `{name}.0`, `{name}.1`, ...
    pub fn new(cfg: &MlpConfig, p: &Params, name: &str) -> Result<Self> {
        Mlp::with_layer_names(cfg, p, |i| format!("{name}.{i}"))
    }

    /// The candle-transformers form: layer `i` from `vb.pp(i)` (with a
    /// [`Params::var_builder`], the scheme; `cfg.init` must be `Uniform`).
    pub fn from_vb(cfg: &MlpConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        if cfg.init != MlpInit::Uniform {
            return Err(NnError::Config(
                "an MLP built from a VarBuilder is initialised by the builder".into(),
            ));
        }
        let layers = cfg
            .dims()
            .windows(2)
            .enumerate()
            .map(|(i, d)| Linear::from_vb(vb.pp(i.to_string()), d[0], d[1]))
            .collect::<Result<_>>()?;
        Ok(Mlp { layers })
    }

    /// Layers named by `layer_name(i)` (for model files that predate the
    /// `{name}.{i}` convention).
    pub fn with_layer_names(
        cfg: &MlpConfig,
        p: &Params,
        layer_name: impl Fn(usize) -> String,
    ) -> Result<Self> {
        cfg.validate()?;
        let dims = cfg.dims();
        let n = dims.len() - 1;
        let mut layers = Vec::with_capacity(n);
        for (i, d) in dims.windows(2).enumerate() {
            let (fan_in, fan_out, name) = (d[0], d[1], layer_name(i));
            let layer = match cfg.init {
                MlpInit::Uniform => Linear::new(p, &name, fan_in, fan_out)?,
                MlpInit::ScaledOutput { scale } => {
                    let bound = 1.0 / (fan_in as f32).sqrt();
                    let last = i + 1 == n;
                    let w_scale = if last { scale } else { 1.0 };
                    let (w_name, b_name) = (format!("{name}.weight"), format!("{name}.bias"));
                    let w = p.uniform_half_open(&w_name, &[fan_out, fan_in], bound, w_scale)?;
                    let b = if last {
                        p.constant(&b_name, &[fan_out], 0.0)?
                    } else {
                        p.uniform_half_open(&b_name, &[fan_out], bound, 1.0)?
                    };
                    Linear::from_weights(w, Some(b))?
                }
            };
            layers.push(layer);
        }
        Ok(Mlp { layers })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut x = x.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(&x)?;
            if i != last {
                x = x.relu()?;
            }
        }
        Ok(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    #[test]
    fn shapes_names_and_the_scaled_output() {
        let p = Params::new(4);
        let cfg = MlpConfig {
            init: MlpInit::ScaledOutput { scale: 0.0 },
            ..MlpConfig::new(5, &[8, 6], 2)
        };
        let mlp = Mlp::new(&cfg, &p, "pi").unwrap();
        let names: Vec<String> = p.vars().into_iter().map(|(n, _)| n).collect();
        assert_eq!(
            names,
            [
                "pi.0.weight",
                "pi.0.bias",
                "pi.1.weight",
                "pi.1.bias",
                "pi.2.weight",
                "pi.2.bias"
            ]
        );
        let x = Tensor::ones((3, 5), DType::F32, &Device::Cpu).unwrap();
        let y = mlp.forward(&x).unwrap();
        assert_eq!(y.dims(), &[3, 2]);
        // Output weights scaled to 0 and bias 0: the output is exactly 0.
        assert!(
            y.flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
                .iter()
                .all(|v| *v == 0.0)
        );
        let q = Params::new(4);
        let named = Mlp::with_layer_names(&MlpConfig::new(5, &[8], 2), &q, |i| format!("layer{i}"));
        assert!(named.is_ok());
        assert_eq!(q.vars()[2].0, "layer1.weight");
        assert!(Mlp::new(&MlpConfig::new(5, &[0], 2), &q, "bad").is_err());
        // Through a VarBuilder: the same names and draws as `new`.
        let (a, b) = (Params::new(9), Params::new(9));
        let cfg = MlpConfig::new(3, &[4], 2);
        Mlp::new(&cfg, &a, "m").unwrap();
        Mlp::from_vb(&cfg, b.var_builder().pp("m")).unwrap();
        let flat = |p: &Params| -> Vec<(String, Vec<f32>)> {
            p.vars()
                .into_iter()
                .map(|(n, v)| (n, v.flatten_all().unwrap().to_vec1().unwrap()))
                .collect()
        };
        assert_eq!(flat(&a), flat(&b));
    }
}
