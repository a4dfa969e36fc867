//! Training clips as normalised frames, and batches of them padded to the longest
//! clip of the batch with a mask of valid frames. Whole clips, as in the paper
//! (one clip of a class is one training sequence); no fixed-length windows.

use std::sync::Arc;

use candle_core::{Device, Tensor};
use motion::{Motion, Skeleton};

use crate::error::{Result, VaeError};
use crate::features::{FeatureConfig, clip_frames_on, frame_dim};
use crate::normalize::NormStats;

pub struct Dataset {
    pub skeleton: Arc<Skeleton>,
    pub dim: usize,
    /// Raw frames per clip, `[frame][dim]`.
    pub raw: Vec<Vec<f32>>,
    /// Normalised frames per clip.
    pub normalised: Vec<Vec<f32>>,
    pub stats: NormStats,
}

/// A padded batch: `x` normalised `(B, T, F)`, `raw` `(B, T, F)`, `mask` `(B, T)`.
#[derive(Clone)]
pub struct Batch {
    pub x: Tensor,
    pub raw: Tensor,
    pub mask: Tensor,
    pub lengths: Vec<usize>,
}

impl Dataset {
    /// Clips must share one skeleton layout (same joint names in the same order);
    /// the first clip's skeleton (bone lengths included) is the one samples use.
    pub fn new(clips: &[Motion], features: &FeatureConfig) -> Result<Self> {
        let first = clips
            .first()
            .ok_or_else(|| VaeError::Data("no training clips".into()))?;
        let skeleton = first.skeleton().clone();
        for (i, c) in clips.iter().enumerate() {
            let same = c.skeleton().len() == skeleton.len()
                && c.skeleton()
                    .joints()
                    .iter()
                    .zip(skeleton.joints())
                    .all(|(a, b)| a.name == b.name && a.parent == b.parent);
            if !same {
                return Err(VaeError::Data(format!(
                    "clip {i} has a different joint hierarchy from clip 0 \
                     (all clips of a model must share one skeleton layout)"
                )));
            }
        }
        let dim = frame_dim(skeleton.len());
        let raw: Vec<Vec<f32>> = clips
            .iter()
            .map(|c| clip_frames_on(c, features, &skeleton))
            .collect::<Result<_>>()?;
        let stats = NormStats::fit(&raw, dim)?;
        let normalised = raw.iter().map(|c| stats.normalise(c)).collect();
        Ok(Dataset {
            skeleton,
            dim,
            raw,
            normalised,
            stats,
        })
    }

    pub fn len(&self) -> usize {
        self.raw.len()
    }

    pub fn is_empty(&self) -> bool {
        self.raw.is_empty()
    }

    pub fn lengths(&self) -> Vec<usize> {
        self.raw.iter().map(|c| c.len() / self.dim).collect()
    }

    pub fn batch(&self, indices: &[usize]) -> Result<Batch> {
        let lengths: Vec<usize> = indices
            .iter()
            .map(|&i| self.raw[i].len() / self.dim)
            .collect();
        let t = lengths.iter().copied().max().unwrap_or(0).max(1);
        let b = indices.len();
        let mut x = vec![0.0f32; b * t * self.dim];
        let mut raw = vec![0.0f32; b * t * self.dim];
        let mut mask = vec![0.0f32; b * t];
        for (k, &i) in indices.iter().enumerate() {
            let n = self.raw[i].len();
            let at = k * t * self.dim;
            x[at..at + n].copy_from_slice(&self.normalised[i]);
            raw[at..at + n].copy_from_slice(&self.raw[i]);
            // Pad raw frames with the last frame so padded rotations stay valid.
            let last = &self.raw[i][n - self.dim..];
            for f in lengths[k]..t {
                raw[at + f * self.dim..at + (f + 1) * self.dim].copy_from_slice(last);
            }
            mask[k * t..k * t + lengths[k]].fill(1.0);
        }
        let dev = &Device::Cpu;
        Ok(Batch {
            x: Tensor::from_vec(x, (b, t, self.dim), dev)?,
            raw: Tensor::from_vec(raw, (b, t, self.dim), dev)?,
            mask: Tensor::from_vec(mask, (b, t), dev)?,
            lengths,
        })
    }
}
