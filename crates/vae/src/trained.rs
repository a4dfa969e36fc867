//! A trained model with everything needed to use it later: weights, layer sizes,
//! feature settings, normalisation, the training skeleton, training clip lengths
//! and the training set's latent posteriors (for sampling near samples).
//!
//! On disk, a model directory holds `weights.safetensors` and `model.json`.
//! Samples are motions on the training skeleton (the first training clip's; the
//! other clips' root paths were scaled to its hip height, `features::clip_frames_on`),
//! at the feature frame rate, starting above the origin facing +z. A near sample
//! is as long as the mean of the clips it was drawn between; a prior sample takes
//! a random training clip's length.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use candle_core::{Device, Tensor};
use motion::{Motion, Skeleton};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};
use crate::features::{FeatureConfig, clip_frames_on, frame_dim, frames_to_motion};
use crate::feet::FootLoss;
use crate::latent::{LatentStats, Prior, sample_normal};
use crate::loss::LossWeights;
use crate::model::{Vae, VaeConfig};
use crate::normalize::NormStats;
use crate::train::Losses;
use nn::OptimizerConfig;

pub const FORMAT: u32 = 1;
pub const WEIGHTS_FILE: &str = "weights.safetensors";
pub const META_FILE: &str = "model.json";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    pub clips: usize,
    pub iterations: u64,
    pub adversarial: bool,
    pub optimizer: OptimizerConfig,
    /// Cosine learning-rate decay to this fraction (models saved before it: none).
    #[serde(default)]
    pub cosine_to: Option<f64>,
    pub weights: LossWeights,
    /// Foot terms (models saved before they existed trained without them).
    #[serde(default = "FootLoss::off")]
    pub feet: FootLoss,
    pub seed: u64,
    pub final_losses: Losses,
    pub seconds: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    pub format: u32,
    pub config: VaeConfig,
    pub features: FeatureConfig,
    pub stats: NormStats,
    pub skeleton: Skeleton,
    /// Training clip lengths in frames at `features.fps`.
    pub lengths: Vec<usize>,
    pub latents: LatentStats,
    pub training: TrainingSummary,
}

/// One generated clip.
pub struct Sample {
    pub motion: Motion,
    pub z: Vec<f32>,
    pub prior: Prior,
}

/// Reconstruction quality on a set of clips (decoding the posterior mean).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionError {
    /// RMS root position error, metres (canonical placement).
    pub root_rmse_m: f64,
    /// Mean angle between original and reconstructed local joint rotations, radians.
    pub mean_joint_angle_rad: f64,
}

/// Posterior means and log variances, one row per clip.
pub type Posteriors = (Vec<Vec<f32>>, Vec<Vec<f32>>);

pub struct TrainedVae {
    vae: Vae,
    meta: ModelMeta,
    skeleton: Arc<Skeleton>,
}

/// What is done to a decoded clip before it is handed out.
///
/// Decoded clips jitter frame to frame (3-4x the jerk of captures) and their
/// root does not follow their feet; both make physical correction fail
/// (crates/vae/README.md, sessions 18-19).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Finish {
    /// Low-pass with a Gaussian of this standard deviation in seconds
    /// (`motion::smooth::gaussian`); `None`: as decoded.
    pub smooth_s: Option<f64>,
    /// Re-integrate the root path from the planted feet
    /// (`motion::metrics::plant_root`), after smoothing.
    pub plant_root: bool,
}

impl Default for Finish {
    fn default() -> Self {
        Finish {
            smooth_s: Some(DEFAULT_SMOOTH_S),
            plant_root: true,
        }
    }
}

/// The low-pass [`Finish::default`] applies, seconds.
pub const DEFAULT_SMOOTH_S: f64 = 0.05;

impl Finish {
    /// A low-pass of `smooth_s` seconds (0: none), then planting or not: the
    /// one number every caller's options give.
    pub fn new(smooth_s: f64, plant_root: bool) -> Self {
        Finish {
            smooth_s: (smooth_s > 0.0).then_some(smooth_s),
            plant_root,
        }
    }

    /// `motion` finished.
    pub fn apply(&self, motion: &Motion) -> Result<Motion> {
        let mut m = match self.smooth_s {
            Some(sigma) => motion::smooth::gaussian(motion, sigma)?,
            None => motion.clone(),
        };
        if self.plant_root {
            m = motion::metrics::plant_root(&m, &motion::metrics::Thresholds::default());
        }
        Ok(m)
    }
}

impl TrainedVae {
    pub fn from_parts(vae: Vae, meta: ModelMeta) -> Result<Self> {
        let dim = frame_dim(meta.skeleton.len());
        if vae.frame_dim != dim {
            return Err(VaeError::Model(format!(
                "network frames have {} numbers, the skeleton needs {dim}",
                vae.frame_dim
            )));
        }
        meta.stats.validate(dim)?;
        meta.latents.validate(meta.config.latent)?;
        if meta.lengths.is_empty() || meta.lengths.contains(&0) {
            return Err(VaeError::Model(
                "training lengths are missing or zero".into(),
            ));
        }
        if meta.lengths.len() != meta.latents.mu.len() {
            return Err(VaeError::Model(format!(
                "{} training lengths for {} training codes",
                meta.lengths.len(),
                meta.latents.mu.len()
            )));
        }
        let skeleton = Arc::new(meta.skeleton.clone());
        Ok(TrainedVae {
            vae,
            meta,
            skeleton,
        })
    }

    pub fn meta(&self) -> &ModelMeta {
        &self.meta
    }

    pub fn skeleton(&self) -> &Arc<Skeleton> {
        &self.skeleton
    }

    /// A clip's raw frames as this model sees it (its rate, its skeleton's hip
    /// height; `features::clip_frames_on`).
    fn model_frames(&self, clip: &Motion) -> Result<Vec<f32>> {
        clip_frames_on(clip, &self.meta.features, &self.skeleton)
    }

    /// Posterior `(mu, logvar)` of each clip (resampled to the model's rate).
    pub fn encode(&self, clips: &[Motion]) -> Result<Posteriors> {
        let dim = self.vae.frame_dim;
        let mut mus = Vec::new();
        let mut lvs = Vec::new();
        for (i, c) in clips.iter().enumerate() {
            if c.joints() != self.skeleton.len() {
                return Err(VaeError::Data(format!(
                    "clip {i} has {} joints, the model's skeleton {}",
                    c.joints(),
                    self.skeleton.len()
                )));
            }
            let frames = self.meta.stats.normalise(&self.model_frames(c)?);
            let t = frames.len() / dim;
            let x = Tensor::from_vec(frames, (1, t, dim), &Device::Cpu)?;
            let mask = Tensor::ones((1, t), candle_core::DType::F32, &Device::Cpu)?;
            let (mu, lv) = self.vae.encoder.forward(&x, &mask)?;
            mus.push(mu.squeeze(0)?.to_vec1()?);
            lvs.push(lv.squeeze(0)?.to_vec1()?);
        }
        Ok((mus, lvs))
    }

    /// Decode codes into clips of the given lengths (frames at the model's rate).
    pub fn decode(&self, codes: &[Vec<f32>], lengths: &[usize]) -> Result<Vec<Motion>> {
        let latent = self.meta.config.latent;
        if codes.len() != lengths.len() || codes.iter().any(|z| z.len() != latent) {
            return Err(VaeError::Data(format!(
                "decode needs one length per code and {latent} numbers per code"
            )));
        }
        if codes.is_empty() {
            return Ok(Vec::new());
        }
        if lengths.contains(&0) {
            return Err(VaeError::Data("cannot decode a clip of 0 frames".into()));
        }
        let t = lengths.iter().copied().max().unwrap_or(1);
        let flat: Vec<f32> = codes.iter().flatten().copied().collect();
        let z = Tensor::from_vec(flat, (codes.len(), latent), &Device::Cpu)?;
        let out = self.vae.decoder.forward(&z, t)?.to_vec3::<f32>()?;
        out.iter()
            .zip(lengths)
            .map(|(seq, &n)| {
                let frames: Vec<f32> = seq[..n].iter().flatten().copied().collect();
                let raw = self.meta.stats.denormalise(&frames);
                frames_to_motion(&self.skeleton, self.meta.features.fps, &raw)
            })
            .collect()
    }

    /// Encode and decode (posterior mean) each clip, at its own length.
    pub fn reconstruct(&self, clips: &[Motion]) -> Result<Vec<Motion>> {
        let (mu, _) = self.encode(clips)?;
        let lengths: Vec<usize> = clips
            .iter()
            .map(|c| self.model_frames(c).map(|f| f.len() / self.vae.frame_dim))
            .collect::<Result<_>>()?;
        self.decode(&mu, &lengths)
    }

    /// How well the model reproduces `clips` (compared in the canonical placement).
    pub fn reconstruction_error(&self, clips: &[Motion]) -> Result<ReconstructionError> {
        let recon = self.reconstruct(clips)?;
        let features = self.meta.features;
        let (mut root_sq, mut angle, mut frames, mut rotations) = (0.0, 0.0, 0usize, 0usize);
        for (c, r) in clips.iter().zip(&recon) {
            let original = frames_to_motion(&self.skeleton, features.fps, &self.model_frames(c)?)?;
            for t in 0..original.frames() {
                root_sq +=
                    (original.root_translation()[t] - r.root_translation()[t]).length_squared();
                frames += 1;
                for (a, b) in original.pose(t).iter().zip(r.pose(t)) {
                    angle += motion::rotation::angle_between(*a, *b);
                    rotations += 1;
                }
            }
        }
        Ok(ReconstructionError {
            root_rmse_m: (root_sq / frames.max(1) as f64).sqrt(),
            mean_joint_angle_rad: angle / rotations.max(1) as f64,
        })
    }

    /// The model with near codes drawn between `members` training clips of
    /// a cluster instead of the number it was trained with
    /// ([`crate::NearConfig::members`]).
    pub fn with_near_members(mut self, members: usize) -> Result<Self> {
        if members == 0 {
            return Err(VaeError::Config(
                "near sampling needs at least one member".into(),
            ));
        }
        self.meta.latents.members = members;
        Ok(self)
    }

    /// `count` clips; codes from `prior` (see [`TrainedVae::sample_decoded`]),
    /// each finished as [`Finish::default`] says (low-passed, root re-integrated
    /// from its planted feet so that the root goes where the legs step). The
    /// same seed gives the same clips.
    pub fn sample(&self, count: usize, prior: Prior, seed: u64) -> Result<Vec<Sample>> {
        self.sample_finished(count, prior, seed, &Finish::default())
    }

    /// [`TrainedVae::sample_decoded`], each clip then finished by `finish`.
    pub fn sample_finished(
        &self,
        count: usize,
        prior: Prior,
        seed: u64,
        finish: &Finish,
    ) -> Result<Vec<Sample>> {
        let mut samples = self.sample_decoded(count, prior, seed)?;
        for s in &mut samples {
            s.motion = finish.apply(&s.motion)?;
        }
        Ok(samples)
    }

    /// `count` clips as the decoder gives them; codes from `prior`, lengths from
    /// the clips a near code was drawn between (a random training clip's for the
    /// normal prior). The same seed gives the same clips.
    pub fn sample_decoded(&self, count: usize, prior: Prior, seed: u64) -> Result<Vec<Sample>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut codes = Vec::with_capacity(count);
        let mut lengths = Vec::with_capacity(count);
        for _ in 0..count {
            match prior {
                Prior::Normal => {
                    lengths.push(self.meta.lengths[rng.random_range(0..self.meta.lengths.len())]);
                    codes.push(sample_normal(self.meta.config.latent, &mut rng));
                }
                Prior::Near => {
                    // As long as the clips whose codes it mixes: the decoder runs
                    // on past the end of a short clip's motion otherwise.
                    let (z, members) = self.meta.latents.sample_near_members(&mut rng);
                    let total: usize = members.iter().map(|&i| self.meta.lengths[i]).sum();
                    lengths.push((total as f64 / members.len() as f64).round().max(1.0) as usize);
                    codes.push(z);
                }
            }
        }
        let mut out = Vec::with_capacity(count);
        // Decode in chunks to bound memory on large counts.
        for (zs, ls) in codes.chunks(64).zip(lengths.chunks(64)) {
            for (motion, z) in self.decode(zs, ls)?.into_iter().zip(zs) {
                out.push(Sample {
                    motion,
                    z: z.clone(),
                    prior,
                });
            }
        }
        Ok(out)
    }

    /// Write `weights.safetensors` and `model.json` into `dir` (created if needed).
    pub fn save(&self, dir: impl AsRef<Path>) -> Result<()> {
        let dir = dir.as_ref();
        std::fs::create_dir_all(dir).map_err(|source| VaeError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let tensors: HashMap<String, Tensor> = self
            .vae
            .params
            .vars()
            .iter()
            .map(|(n, v)| (n.clone(), v.as_tensor().clone()))
            .collect();
        let weights = dir.join(WEIGHTS_FILE);
        let tmp = tmp_path(&weights);
        candle_core::safetensors::save(&tensors, &tmp)?;
        rename(&tmp, &weights)?;
        let meta = dir.join(META_FILE);
        let mut json = serde_json::to_vec_pretty(&self.meta).map_err(|source| VaeError::Json {
            path: meta.clone(),
            source,
        })?;
        json.push(b'\n');
        let tmp = tmp_path(&meta);
        std::fs::write(&tmp, json).map_err(|source| VaeError::Io {
            path: tmp.clone(),
            source,
        })?;
        rename(&tmp, &meta)
    }

    pub fn load(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        let meta_path = dir.join(META_FILE);
        let bytes = std::fs::read(&meta_path).map_err(|source| VaeError::Io {
            path: meta_path.clone(),
            source,
        })?;
        let meta: ModelMeta = serde_json::from_slice(&bytes).map_err(|source| VaeError::Json {
            path: meta_path.clone(),
            source,
        })?;
        if meta.format != FORMAT {
            return Err(VaeError::Model(format!(
                "{}: format {} (this build reads {FORMAT})",
                meta_path.display(),
                meta.format
            )));
        }
        // Re-validate the skeleton (serde bypasses its constructor).
        let skeleton = meta.skeleton.clone().validated()?;
        let vae = Vae::new(&meta.config, frame_dim(skeleton.len()), 0)?;
        let weights_path = dir.join(WEIGHTS_FILE);
        let tensors = candle_core::safetensors::load(&weights_path, &Device::Cpu)
            .map_err(|e| VaeError::Model(format!("{}: {e}", weights_path.display())))?;
        for (name, var) in vae.params.vars() {
            let t = tensors.get(&name).ok_or_else(|| {
                VaeError::Model(format!(
                    "{}: tensor `{name}` missing",
                    weights_path.display()
                ))
            })?;
            if t.dims() != var.dims() {
                return Err(VaeError::Model(format!(
                    "{}: tensor `{name}` has shape {:?}, the config needs {:?}",
                    weights_path.display(),
                    t.dims(),
                    var.dims()
                )));
            }
            var.set(&t.to_dtype(candle_core::DType::F32)?)?;
        }
        TrainedVae::from_parts(vae, meta)
    }
}

fn tmp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

fn rename(from: &Path, to: &Path) -> Result<()> {
    std::fs::rename(from, to).map_err(|source| VaeError::Io {
        path: to.to_path_buf(),
        source,
    })
}
