//! Per-feature normalisation (mean and standard deviation over every frame of the
//! training clips), saved with the model so that sampling undoes it exactly.

use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};

/// Features whose spread is below this (locked joints, constant channels) are
/// divided by this instead, so that they normalise to ~0 rather than blow up.
pub const MIN_STD: f32 = 1e-3;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NormStats {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl NormStats {
    /// Statistics over all frames of `clips` (each row-major `[frame][dim]`).
    pub fn fit(clips: &[Vec<f32>], dim: usize) -> Result<Self> {
        let mut sum = vec![0.0f64; dim];
        let mut sq = vec![0.0f64; dim];
        let mut n = 0usize;
        for (c, clip) in clips.iter().enumerate() {
            if clip.is_empty() || !clip.len().is_multiple_of(dim) {
                return Err(VaeError::Data(format!(
                    "clip {c}: {} numbers are not whole frames of {dim}",
                    clip.len()
                )));
            }
            for frame in clip.chunks_exact(dim) {
                for (k, &x) in frame.iter().enumerate() {
                    sum[k] += x as f64;
                    sq[k] += (x as f64) * (x as f64);
                }
                n += 1;
            }
        }
        if n == 0 {
            return Err(VaeError::Data(
                "no frames to compute statistics from".into(),
            ));
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / n as f64).collect();
        let std = sq
            .iter()
            .zip(&mean)
            .map(|(s, m)| ((s / n as f64 - m * m).max(0.0).sqrt() as f32).max(MIN_STD))
            .collect();
        Ok(NormStats {
            mean: mean.into_iter().map(|m| m as f32).collect(),
            std,
        })
    }

    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    pub fn normalise(&self, frames: &[f32]) -> Vec<f32> {
        let d = self.dim();
        frames
            .iter()
            .enumerate()
            .map(|(i, x)| (x - self.mean[i % d]) / self.std[i % d])
            .collect()
    }

    pub fn denormalise(&self, frames: &[f32]) -> Vec<f32> {
        let d = self.dim();
        frames
            .iter()
            .enumerate()
            .map(|(i, x)| x * self.std[i % d] + self.mean[i % d])
            .collect()
    }

    /// Checks a loaded copy: equal lengths, finite values, positive spreads.
    pub fn validate(&self, dim: usize) -> Result<()> {
        if self.mean.len() != dim || self.std.len() != dim {
            return Err(VaeError::Model(format!(
                "normalisation has {} means and {} spreads, the skeleton needs {dim}",
                self.mean.len(),
                self.std.len()
            )));
        }
        if self.mean.iter().any(|m| !m.is_finite())
            || self.std.iter().any(|s| !(s.is_finite() && *s > 0.0))
        {
            return Err(VaeError::Model(
                "normalisation has non-finite means or non-positive spreads".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_floors_constant_features() {
        let clips = vec![vec![1.0, 5.0, 3.0, 5.0], vec![2.0, 5.0]];
        let s = NormStats::fit(&clips, 2).unwrap();
        assert!((s.mean[0] - 2.0).abs() < 1e-6);
        assert_eq!(s.std[1], MIN_STD);
        let n = s.normalise(&clips[0]);
        assert!((n[0] + 1.0 / (2.0f32 / 3.0).sqrt()).abs() < 1e-5, "{n:?}");
        let back = s.denormalise(&n);
        for (a, b) in back.iter().zip(&clips[0]) {
            assert!((a - b).abs() < 1e-5);
        }
        assert!(NormStats::fit(&[vec![1.0; 3]], 2).is_err());
    }
}
