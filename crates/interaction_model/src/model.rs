//! A trained model: the three networks, their configuration, the bodies they
//! were trained on and the prior's standardisation, saved as
//! `weights.safetensors` + `model.json` in a directory (as `crates/vae` does).
//!
//! Inference works on windows in their canonical frame
//! ([`InteractionModel::predict`]) or on a whole clip
//! ([`InteractionModel::predict_clip`]): windows every half window, each
//! decoded from the latent mean (z = 0, the most likely offsets), put back in
//! the world frame and blended with triangular weights where they overlap.

use std::path::Path;

use candle_core::{DType, Device, Tensor};
use nn::{Params, normal};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::adapt_net::{AdaptNet, AdaptNetConfig};
use crate::dataset::{Body, Canon, cut, window_starts, write_json};
use crate::error::{ModelError, Result};
use crate::prior::{PriorConfig, SkeletonPrior};
use crate::retarget_net::{RetargetNet, RetargetNetConfig};
use crate::train::{Losses, TrainConfig, parent_index};

pub const FORMAT: u32 = 1;
pub const WEIGHTS_FILE: &str = "weights.safetensors";
pub const META_FILE: &str = "model.json";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    pub fps: f64,
    pub window: usize,
    pub prior: PriorConfig,
    pub retarget: RetargetNetConfig,
    pub adapt: AdaptNetConfig,
}

impl ModelConfig {
    /// Paper-shaped networks for bodies of `va` and `vb` points.
    pub fn new(fps: f64, window: usize, va: usize, vb: usize, hidden: usize) -> Self {
        let mut retarget = RetargetNetConfig::new(vb);
        retarget.hidden = hidden;
        let mut adapt = AdaptNetConfig::new(va, vb);
        adapt.hidden = hidden;
        ModelConfig {
            fps,
            window,
            prior: PriorConfig::paper(vb - 1),
            retarget,
            adapt,
        }
    }
}

/// Standardisation of B's bone factors (root excluded) and their training range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorStats {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
    pub min: f32,
    pub max: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    pub config: TrainConfig,
    pub pairs: Vec<String>,
    pub windows: usize,
    pub seconds: f64,
    pub final_losses: Losses,
    /// (step, total loss) every 10 steps.
    pub curve: Vec<(usize, f64)>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    pub format: u32,
    pub config: ModelConfig,
    pub body_a: Body,
    pub body_b: Body,
    pub prior: PriorStats,
    pub training: TrainingSummary,
}

pub struct InteractionModel {
    /// Every network's parameters, seeded (`nn`'s scheme, in registration order).
    pub params: Params,
    pub prior: SkeletonPrior,
    pub retarget: RetargetNet,
    pub adapt: AdaptNet,
    pub meta: ModelMeta,
    pub parents_a: Tensor,
    pub parents_b: Tensor,
}

/// Whole-clip predictions in the world frame, `[T, P, 3]` flat.
pub struct ClipPrediction {
    pub a: Vec<f32>,
    pub b: Vec<f32>,
}

impl InteractionModel {
    /// Fresh networks (seeded initialisation) for `meta`.
    pub fn new(meta: ModelMeta, seed: u64) -> Result<Self> {
        let params = Params::new(seed);
        let vb = params.var_builder();
        let c = &meta.config;
        if meta.body_a.len() != c.adapt.nodes_a
            || meta.body_b.len() != c.retarget.nodes
            || meta.prior.mean.len() != c.prior.dim
            || meta.prior.std.len() != c.prior.dim
        {
            return Err(ModelError::Data(
                "model.json: body sizes and network sizes disagree".into(),
            ));
        }
        let prior = SkeletonPrior::new(vb.pp("prior"), &c.prior)?;
        let retarget = RetargetNet::new(vb.pp("retarget"), &c.retarget, &meta.body_b.parents)?;
        let adapt = AdaptNet::new(
            vb.pp("adapt"),
            &c.adapt,
            &meta.body_a.parents,
            &meta.body_b.parents,
        )?;
        Ok(InteractionModel {
            parents_a: parent_index(&meta.body_a.parents)?,
            parents_b: parent_index(&meta.body_b.parents)?,
            params,
            prior,
            retarget,
            adapt,
            meta,
        })
    }

    pub fn parameter_count(&self) -> usize {
        self.params.count()
    }

    /// Write `weights.safetensors` and `model.json` into `dir`.
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| ModelError::io(dir, e))?;
        let weights = dir.join(WEIGHTS_FILE);
        let tmp = dir.join(format!("{WEIGHTS_FILE}.tmp"));
        self.params.save(&tmp)?;
        std::fs::rename(&tmp, &weights).map_err(|e| ModelError::io(&weights, e))?;
        write_json(&dir.join(META_FILE), &self.meta)
    }

    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join(META_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| ModelError::io(&path, e))?;
        let meta: ModelMeta = serde_json::from_str(&text).map_err(|source| ModelError::Json {
            path: path.clone(),
            source,
        })?;
        if meta.format != FORMAT {
            return Err(ModelError::Data(format!(
                "{}: format {} (this build reads {FORMAT})",
                path.display(),
                meta.format
            )));
        }
        let model = InteractionModel::new(meta, 0)?;
        let weights = dir.join(WEIGHTS_FILE);
        if !weights.is_file() {
            return Err(ModelError::io(
                &weights,
                std::io::Error::new(std::io::ErrorKind::NotFound, "missing"),
            ));
        }
        model.params.load(&weights)?;
        Ok(model)
    }

    /// Per-point factors `[n, Vb]` -> standardised bone scales `[n, Vb - 1]`.
    pub fn standardise(&self, scales: &Tensor) -> Result<Tensor> {
        let d = self.meta.prior.mean.len();
        let mean = Tensor::from_slice(&self.meta.prior.mean, d, &Device::Cpu)?;
        let std = Tensor::from_slice(&self.meta.prior.std, d, &Device::Cpu)?;
        Ok(scales
            .narrow(1, 1, d)?
            .broadcast_sub(&mean)?
            .broadcast_div(&std)?)
    }

    /// `count` per-point factor vectors (root 1) drawn from the skeleton prior.
    pub fn sample_scales(&self, count: usize, seed: u64) -> Result<Vec<Vec<f32>>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let z = normal(&[count, self.meta.config.prior.latent], &mut rng)?;
        let x = self.prior.decode(&z)?.to_vec2::<f32>()?;
        let p = &self.meta.prior;
        Ok(x.into_iter()
            .map(|row| {
                std::iter::once(1.0)
                    .chain(
                        row.iter()
                            .enumerate()
                            .map(|(i, v)| v * p.std[i] + p.mean[i]),
                    )
                    .collect()
            })
            .collect())
    }

    /// Retarget B and adapt A on canonical windows: `(A, B)` positions
    /// `[n, T, V, 3]`. `z` = None decodes the latent mean (zeros).
    pub fn predict(
        &self,
        template_a: &Tensor,
        template_b: &Tensor,
        scales: &Tensor,
        rng: Option<&mut ChaCha8Rng>,
    ) -> Result<(Tensor, Tensor)> {
        let n = template_a.dim(0)?;
        let (lb, la) = (
            self.meta.config.retarget.latent,
            self.meta.config.adapt.latent,
        );
        let (zb, za) = match rng {
            Some(r) => (normal(&[n, lb], r)?, normal(&[n, la], r)?),
            None => (
                Tensor::zeros((n, lb), DType::F32, &Device::Cpu)?,
                Tensor::zeros((n, la), DType::F32, &Device::Cpu)?,
            ),
        };
        let b = (template_b + self.retarget.decode(&zb, template_b, scales)?)?;
        let a = (template_a + self.adapt.decode(&za, template_a, &b, template_b)?)?;
        Ok((a, b))
    }

    /// Whole-clip prediction from world-frame templates `[T, P, 3]` and B's
    /// per-point factors (see the module doc).
    pub fn predict_clip(
        &self,
        template_a: &[f32],
        template_b: &[f32],
        frames: usize,
        factors: &[f32],
    ) -> Result<ClipPrediction> {
        let w = self.meta.config.window;
        let (va, vb) = (self.meta.body_a.len(), self.meta.body_b.len());
        if template_a.len() != frames * va * 3
            || template_b.len() != frames * vb * 3
            || factors.len() != vb
            || frames == 0
        {
            return Err(ModelError::Data(format!(
                "clip of {frames} frames does not fit the model's bodies ({va} and {vb} points)"
            )));
        }
        let starts = window_starts(frames, w, (w / 2).max(1));
        let n = starts.len();
        let mut ta = Vec::with_capacity(n * w * va * 3);
        let mut tb = Vec::with_capacity(n * w * vb * 3);
        let mut canons = Vec::with_capacity(n);
        for &s in &starts {
            let wa = cut(template_a, frames, va, s, w);
            let wb = cut(template_b, frames, vb, s, w);
            let c = Canon::of(&wa[0..3], &wb[0..3]);
            ta.extend(c.apply(&wa));
            tb.extend(c.apply(&wb));
            canons.push(c);
        }
        let ta = Tensor::from_vec(ta, (n, w, va, 3), &Device::Cpu)?;
        let tb = Tensor::from_vec(tb, (n, w, vb, 3), &Device::Cpu)?;
        let sc: Vec<f32> = (0..n).flat_map(|_| factors.iter().copied()).collect();
        let sc = Tensor::from_vec(sc, (n, vb), &Device::Cpu)?;
        let (pa, pb) = self.predict(&ta, &tb, &sc, None)?;
        let blend = |pred: &Tensor, v: usize| -> Result<Vec<f32>> {
            let flat = pred.flatten_all()?.to_vec1::<f32>()?;
            let mut sum = vec![0.0f32; frames * v * 3];
            let mut weight = vec![0.0f32; frames];
            for (k, (&s, c)) in starts.iter().zip(&canons).enumerate() {
                let world = c.invert(&flat[k * w * v * 3..(k + 1) * w * v * 3]);
                for f in 0..w {
                    let t = s + f;
                    if t >= frames {
                        break;
                    }
                    let wt = (f + 1).min(w - f) as f32;
                    weight[t] += wt;
                    for (o, x) in sum[t * v * 3..(t + 1) * v * 3]
                        .iter_mut()
                        .zip(&world[f * v * 3..(f + 1) * v * 3])
                    {
                        *o += wt * x;
                    }
                }
            }
            for t in 0..frames {
                for o in &mut sum[t * v * 3..(t + 1) * v * 3] {
                    *o /= weight[t];
                }
            }
            Ok(sum)
        };
        Ok(ClipPrediction {
            a: blend(&pa, va)?,
            b: blend(&pb, vb)?,
        })
    }
}
