//! Running observation normaliser: per-dimension mean and variance by Welford's
//! algorithm in f64, mergeable (Chan et al.) so each environment or thread can gather
//! its own statistics and the trainer merges them in a fixed order. Normalised values
//! are clipped. The trainer only updates it between rollouts, so it is frozen while a
//! rollout or a deterministic evaluation runs.

use crate::error::{PpoError, Result};

#[derive(Clone, Debug, PartialEq)]
pub struct RunningNorm {
    count: f64,
    mean: Vec<f64>,
    m2: Vec<f64>,
    clip: f32,
    /// Cached f32 mean and 1/std used by `normalize`; refreshed after every change.
    mean_f32: Vec<f32>,
    inv_std_f32: Vec<f32>,
}

const VAR_EPS: f64 = 1e-8;

impl RunningNorm {
    pub fn new(dim: usize, clip: f32) -> Self {
        RunningNorm {
            count: 0.0,
            mean: vec![0.0; dim],
            m2: vec![0.0; dim],
            clip,
            mean_f32: vec![0.0; dim],
            inv_std_f32: vec![1.0; dim],
        }
    }

    /// Rebuild from saved statistics (checkpoints).
    pub fn from_parts(count: f64, mean: Vec<f64>, m2: Vec<f64>, clip: f32) -> Result<Self> {
        if mean.len() != m2.len() {
            return Err(PpoError::Config(format!(
                "normaliser mean has {} entries but m2 has {}",
                mean.len(),
                m2.len()
            )));
        }
        if count.is_nan() || count < 0.0 || mean.iter().chain(&m2).any(|v| !v.is_finite()) {
            return Err(PpoError::Config(
                "normaliser statistics are negative or not finite".into(),
            ));
        }
        let dim = mean.len();
        let mut n = RunningNorm {
            count,
            mean,
            m2,
            clip,
            mean_f32: vec![0.0; dim],
            inv_std_f32: vec![1.0; dim],
        };
        n.refresh();
        Ok(n)
    }

    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    pub fn count(&self) -> f64 {
        self.count
    }

    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    pub fn m2(&self) -> &[f64] {
        &self.m2
    }

    pub fn clip(&self) -> f32 {
        self.clip
    }

    /// Population variance per dimension (0 before two samples).
    pub fn variance(&self) -> Vec<f64> {
        self.m2
            .iter()
            .map(|m2| {
                if self.count > 1.0 {
                    m2 / self.count
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Add one observation. Does not refresh the cached normalisation (call `refresh`
    /// or `merge`, which does).
    pub fn push(&mut self, x: &[f32]) {
        debug_assert_eq!(x.len(), self.mean.len());
        self.count += 1.0;
        let n = self.count;
        for ((m, m2), &xi) in self.mean.iter_mut().zip(&mut self.m2).zip(x) {
            let xi = xi as f64;
            let d = xi - *m;
            *m += d / n;
            *m2 += d * (xi - *m);
        }
    }

    /// Fold another set of statistics into this one.
    pub fn merge(&mut self, other: &RunningNorm) {
        debug_assert_eq!(other.mean.len(), self.mean.len());
        if other.count == 0.0 {
            return;
        }
        let (na, nb) = (self.count, other.count);
        let n = na + nb;
        for i in 0..self.mean.len() {
            let d = other.mean[i] - self.mean[i];
            self.mean[i] += d * nb / n;
            self.m2[i] += other.m2[i] + d * d * na * nb / n;
        }
        self.count = n;
        self.refresh();
    }

    /// Recompute the cached f32 mean and inverse standard deviation.
    pub fn refresh(&mut self) {
        let var = self.variance();
        for (i, v) in var.iter().enumerate() {
            self.mean_f32[i] = self.mean[i] as f32;
            self.inv_std_f32[i] = if self.count > 1.0 {
                (1.0 / (v + VAR_EPS).sqrt()) as f32
            } else {
                1.0
            };
        }
    }

    /// `out = clip((x - mean) / std)`.
    pub fn normalize(&self, x: &[f32], out: &mut [f32]) {
        let c = self.clip;
        for (((o, &xi), &m), &s) in out
            .iter_mut()
            .zip(x)
            .zip(&self.mean_f32)
            .zip(&self.inv_std_f32)
        {
            *o = ((xi - m) * s).clamp(-c, c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn merge_matches_sequential(
            data in proptest::collection::vec(proptest::collection::vec(-100.0f32..100.0, 3), 2..60),
            split in 0usize..60,
        ) {
            let split = split.min(data.len());
            let mut all = RunningNorm::new(3, 5.0);
            for x in &data { all.push(x); }
            all.refresh();
            let mut a = RunningNorm::new(3, 5.0);
            let mut b = RunningNorm::new(3, 5.0);
            for x in &data[..split] { a.push(x); }
            for x in &data[split..] { b.push(x); }
            a.merge(&b);
            prop_assert_eq!(a.count(), all.count());
            for i in 0..3 {
                prop_assert!((a.mean()[i] - all.mean()[i]).abs() < 1e-9 * (1.0 + all.mean()[i].abs()));
                prop_assert!((a.m2()[i] - all.m2()[i]).abs() < 1e-7 * (1.0 + all.m2()[i]));
            }
        }
    }

    #[test]
    fn normalises_and_clips() {
        let mut n = RunningNorm::new(1, 2.0);
        for x in [1.0f32, 3.0, 1.0, 3.0] {
            n.push(&[x]);
        }
        n.refresh();
        let mut out = [0.0f32];
        n.normalize(&[3.0], &mut out);
        assert!((out[0] - 1.0).abs() < 1e-4, "{out:?}");
        n.normalize(&[100.0], &mut out);
        assert_eq!(out[0], 2.0);
        n.normalize(&[-100.0], &mut out);
        assert_eq!(out[0], -2.0);
    }
}
