//! Minimum DTW distance between synthesised and test clips (MotionAug Sec. 4.1):
//! how close the synthesised motions come to real motions of an unseen actor.
//!
//! * Frame distance: [`crate::euler::joint_sum_distance`], the sum over non-root
//!   joints of the Euclidean norm of the joint's wrapped Euler-angle differences
//!   (radians), as the paper states it.
//! * DTW: the classic recursion with steps (1, 0), (0, 1), (1, 1); the distance of
//!   two clips is the cost of the cheapest warping path divided by that path's
//!   length (the mean frame distance along the alignment), so clips of different
//!   lengths compare on one scale. It is symmetric and never above the lock-step
//!   mean of two equally long clips (the diagonal is one of the paths).
//! * Min DTW: for each synthesised clip the distance to the closest test clip,
//!   averaged over synthesised clips ([`MinDtw::synth_to_test`]); the paper's
//!   wording (for each test clip the closest synthesised clip) is reported too
//!   ([`MinDtw::test_to_synth`]).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::euler::{EulerClip, joint_sum_distance};

/// Mean frame distance along the cheapest DTW alignment of `a` and `b`.
pub fn dtw(a: &EulerClip, b: &EulerClip) -> f64 {
    let (n, m) = (a.frames, b.frames);
    if n == 0 || m == 0 {
        return f64::INFINITY;
    }
    // Rows over `a`, columns over `b`; (cost, path length) per cell, two rows kept.
    let mut prev = vec![(f64::INFINITY, 0usize); m];
    let mut cur = vec![(f64::INFINITY, 0usize); m];
    for i in 0..n {
        for j in 0..m {
            let d = joint_sum_distance(a.frame(i), b.frame(j));
            let best = if i == 0 && j == 0 {
                (0.0, 0)
            } else {
                let mut best = (f64::INFINITY, usize::MAX);
                for c in [
                    (i > 0).then(|| prev[j]),
                    (j > 0).then(|| cur[j - 1]),
                    (i > 0 && j > 0).then(|| prev[j - 1]),
                ]
                .into_iter()
                .flatten()
                {
                    if c.0 < best.0 || (c.0 == best.0 && c.1 < best.1) {
                        best = c;
                    }
                }
                best
            };
            cur[j] = (best.0 + d, best.1 + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    let (cost, len) = prev[m - 1];
    cost / len as f64
}

/// Minimum DTW distances between a synthesised set and a test set.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MinDtw {
    /// Mean over synthesised clips of the distance to the closest test clip.
    pub synth_to_test: f64,
    /// Mean over test clips of the distance to the closest synthesised clip.
    pub test_to_synth: f64,
    pub synth_clips: usize,
    pub test_clips: usize,
}

/// Every pairwise DTW distance (rows: `synth`, columns: `test`), in parallel.
pub fn distance_matrix(synth: &[EulerClip], test: &[EulerClip]) -> Vec<Vec<f64>> {
    synth
        .par_iter()
        .map(|s| test.iter().map(|t| dtw(s, t)).collect())
        .collect()
}

/// Min DTW of `synth` against `test` (both non-empty, else NaN).
pub fn min_dtw(synth: &[EulerClip], test: &[EulerClip]) -> MinDtw {
    let d = distance_matrix(synth, test);
    let mean = |v: Vec<f64>| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let synth_to_test = mean(
        d.iter()
            .map(|row| row.iter().copied().fold(f64::INFINITY, f64::min))
            .collect(),
    );
    let test_to_synth = mean(
        (0..test.len())
            .map(|j| d.iter().map(|row| row[j]).fold(f64::INFINITY, f64::min))
            .collect(),
    );
    MinDtw {
        synth_to_test,
        test_to_synth,
        synth_clips: synth.len(),
        test_clips: test.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn clip(frames: usize, dim: usize, seed: u64) -> EulerClip {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut data = Vec::new();
        let mut x = vec![0.0; dim];
        for _ in 0..frames {
            for v in x.iter_mut() {
                *v += rng.random_range(-0.2..0.2);
            }
            data.extend(&x);
        }
        EulerClip { dim, frames, data }
    }

    #[test]
    fn identical_is_zero_symmetric_and_below_lockstep() {
        let a = clip(30, 6, 1);
        assert_eq!(dtw(&a, &a), 0.0);
        for seed in 2..8 {
            let b = clip(30, 6, seed);
            let ab = dtw(&a, &b);
            assert!((ab - dtw(&b, &a)).abs() < 1e-12, "not symmetric");
            let lockstep = (0..30)
                .map(|t| joint_sum_distance(a.frame(t), b.frame(t)))
                .sum::<f64>()
                / 30.0;
            assert!(ab > 0.0 && ab <= lockstep + 1e-12, "{ab} vs {lockstep}");
        }
        // A clip played at half speed aligns with itself at zero cost.
        let slow = EulerClip {
            dim: 6,
            frames: 60,
            data: (0..60).flat_map(|t| a.frame(t / 2).to_vec()).collect(),
        };
        assert_eq!(dtw(&a, &slow), 0.0);
    }

    #[test]
    fn min_dtw_picks_the_closest_clip() {
        let test = vec![clip(20, 3, 1), clip(25, 3, 2)];
        let synth = vec![test[0].clone(), clip(22, 3, 9)];
        let m = min_dtw(&synth, &test);
        // The copy of test[0] has distance 0, the other clip a positive one.
        let other = dtw(&synth[1], &test[0]).min(dtw(&synth[1], &test[1]));
        assert!((m.synth_to_test - other / 2.0).abs() < 1e-12);
        let t1 = dtw(&test[1], &synth[0]).min(dtw(&test[1], &synth[1]));
        assert!((m.test_to_synth - t1 / 2.0).abs() < 1e-12);
    }
}
