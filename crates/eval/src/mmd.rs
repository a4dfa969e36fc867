//! Maximum mean discrepancy between synthesised and test clips (MotionAug Sec.
//! 4.1): whether the synthesised set is distributed like real motion of an
//! unseen actor, not just close to one clip.
//!
//! * Feature of a clip ([`clip_feature`]): the clip resampled to
//!   [`FEATURE_FRAMES`] frames spread over its duration (slerp,
//!   [`motion::resample`]), each frame's non-root Euler angles
//!   ([`crate::euler`]), concatenated: one vector per clip, so tempo and
//!   trajectory both count and clip length does not.
//! * Kernel: Gaussian `k(x, y) = exp(-|x - y|^2 / (2 s^2))`; bandwidth `s` = the
//!   median pairwise distance between the *test* clips' features (the median
//!   heuristic on the reference set only, so every synthesised set of one class
//!   and fold is measured with the same kernel). With fewer than two test clips
//!   the median over all pairs of both sets is used.
//! * Estimate: the biased (V-statistic) MMD^2: zero for identical sets, never
//!   negative, at most 2.

use motion::Motion;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::euler::EulerClip;

/// Frames per clip feature.
pub const FEATURE_FRAMES: usize = 16;

/// The per-clip feature vector (see the module doc).
pub fn clip_feature(motion: &Motion) -> Result<Vec<f64>> {
    let fps = FEATURE_FRAMES as f64 / motion.duration_s();
    let m = motion::resample::resample(motion, fps)?;
    Ok(EulerClip::of(&m).data)
}

fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum()
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

fn pair_distances(a: &[Vec<f64>]) -> Vec<f64> {
    let mut d = Vec::new();
    for i in 0..a.len() {
        for j in i + 1..a.len() {
            d.push(sq_dist(&a[i], &a[j]).sqrt());
        }
    }
    d
}

/// MMD^2 and the kernel bandwidth it used.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Mmd {
    pub mmd2: f64,
    pub bandwidth: f64,
}

/// Biased MMD^2 between `synth` and `test` features with a Gaussian kernel of
/// the module's bandwidth rule.
pub fn mmd(synth: &[Vec<f64>], test: &[Vec<f64>]) -> Mmd {
    let bandwidth = median(pair_distances(test))
        .filter(|s| *s > 0.0)
        .or_else(|| {
            let all: Vec<Vec<f64>> = synth.iter().chain(test).cloned().collect();
            median(pair_distances(&all)).filter(|s| *s > 0.0)
        })
        .unwrap_or(1.0);
    Mmd {
        mmd2: mmd2_with_bandwidth(synth, test, bandwidth),
        bandwidth,
    }
}

/// Biased MMD^2 with a given Gaussian bandwidth (NaN for an empty set).
pub fn mmd2_with_bandwidth(x: &[Vec<f64>], y: &[Vec<f64>], bandwidth: f64) -> f64 {
    let g = 1.0 / (2.0 * bandwidth * bandwidth);
    let mean_k = |a: &[Vec<f64>], b: &[Vec<f64>]| {
        let mut s = 0.0;
        for u in a {
            for v in b {
                s += (-g * sq_dist(u, v)).exp();
            }
        }
        s / (a.len() * b.len()) as f64
    };
    (mean_k(x, x) + mean_k(y, y) - 2.0 * mean_k(x, y)).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn sample(n: usize, dim: usize, shift: f64, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let normal = Normal::new(0.0, 1.0).unwrap();
        (0..n)
            .map(|_| (0..dim).map(|_| normal.sample(&mut rng) + shift).collect())
            .collect()
    }

    #[test]
    fn zero_for_identical_and_grows_with_shift() {
        let x = sample(40, 5, 0.0, 1);
        assert!(mmd(&x, &x).mmd2 < 1e-12);
        let same = mmd(&sample(40, 5, 0.0, 2), &x).mmd2;
        let near = mmd(&sample(40, 5, 0.5, 3), &x).mmd2;
        let far = mmd(&sample(40, 5, 2.0, 4), &x).mmd2;
        assert!(same < near && near < far, "{same} {near} {far}");
    }
}
