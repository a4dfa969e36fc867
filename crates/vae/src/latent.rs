//! Where to draw latent codes from: the N(0, I) prior, or MotionAug's "sampling near
//! samples" (Sec. 3.1): the training clips' posterior means are reduced by PCA,
//! clustered by k-means, and a code is drawn from N(mean mu, mean sigma^2) of a few
//! random members of one cluster (picked with probability proportional to its
//! size). With a handful of clips the prior mostly lands in regions the decoder
//! never saw; near samples stay in learned regions.
//!
//! PCA (power iteration with deflation on the covariance) and k-means (k-means++
//! seeding, Lloyd iterations, best of several restarts) are small enough to write
//! here rather than pull a linear-algebra crate in.

use rand::Rng;
use rand::seq::index::sample as sample_indices;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};

/// Parameters of sampling near samples (paper: 13 PCA dimensions, 3 clusters, 2 members).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct NearConfig {
    pub components: usize,
    pub clusters: usize,
    pub members: usize,
}

impl Default for NearConfig {
    fn default() -> Self {
        NearConfig {
            components: 13,
            clusters: 3,
            members: 2,
        }
    }
}

impl NearConfig {
    pub fn validate(&self) -> Result<()> {
        if self.components == 0 || self.clusters == 0 || self.members == 0 {
            return Err(VaeError::Config(format!(
                "near sampling needs components, clusters and members >= 1, got {self:?}"
            )));
        }
        Ok(())
    }
}

/// The training set in latent space: posterior of every clip and its cluster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LatentStats {
    pub mu: Vec<Vec<f32>>,
    pub logvar: Vec<Vec<f32>>,
    /// Cluster label of each clip, `0..clusters`.
    pub labels: Vec<usize>,
    pub members: usize,
}

/// Which distribution sample codes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Prior {
    /// N(0, I).
    Normal,
    /// Sampling near samples.
    Near,
}

impl std::str::FromStr for Prior {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "normal" | "prior" => Ok(Prior::Normal),
            "near" => Ok(Prior::Near),
            other => Err(format!("unknown prior `{other}` (expected near or normal)")),
        }
    }
}

impl LatentStats {
    /// Cluster the training posteriors.
    pub fn fit(
        mu: Vec<Vec<f32>>,
        logvar: Vec<Vec<f32>>,
        config: &NearConfig,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        config.validate()?;
        if mu.is_empty() || mu.len() != logvar.len() {
            return Err(VaeError::Data(format!(
                "{} means and {} variances to cluster",
                mu.len(),
                logvar.len()
            )));
        }
        let points: Vec<Vec<f64>> = mu
            .iter()
            .map(|m| m.iter().map(|&v| v as f64).collect())
            .collect();
        let projected = pca_project(&points, config.components);
        let labels = kmeans(&projected, config.clusters, 100, 5, rng);
        Ok(LatentStats {
            mu,
            logvar,
            labels,
            members: config.members,
        })
    }

    pub fn latent(&self) -> usize {
        self.mu.first().map_or(0, Vec::len)
    }

    pub fn validate(&self, latent: usize) -> Result<()> {
        let ok = !self.mu.is_empty()
            && self.mu.len() == self.logvar.len()
            && self.mu.len() == self.labels.len()
            && self.members >= 1
            && self
                .mu
                .iter()
                .chain(&self.logvar)
                .all(|v| v.len() == latent && v.iter().all(|x| x.is_finite()));
        if !ok {
            return Err(VaeError::Model(format!(
                "training latents are inconsistent (expected {latent} finite numbers per clip, \
                 one label per clip)"
            )));
        }
        Ok(())
    }

    /// Indices of clips per cluster (non-empty clusters only).
    pub fn clusters(&self) -> Vec<Vec<usize>> {
        let k = self.labels.iter().copied().max().map_or(0, |m| m + 1);
        let mut out = vec![Vec::new(); k];
        for (i, &l) in self.labels.iter().enumerate() {
            out[l].push(i);
        }
        out.retain(|c| !c.is_empty());
        out
    }

    /// One code by sampling near samples.
    pub fn sample_near(&self, rng: &mut impl Rng) -> Vec<f32> {
        self.sample_near_members(rng).0
    }

    /// One code by sampling near samples, and the training clips it was drawn
    /// between.
    pub fn sample_near_members(&self, rng: &mut impl Rng) -> (Vec<f32>, Vec<usize>) {
        let clusters = self.clusters();
        let total: usize = clusters.iter().map(Vec::len).sum();
        let mut pick = rng.random_range(0..total);
        let mut cluster = &clusters[0];
        for c in &clusters {
            if pick < c.len() {
                cluster = c;
                break;
            }
            pick -= c.len();
        }
        let n = self.members.min(cluster.len());
        let chosen: Vec<usize> = sample_indices(rng, cluster.len(), n)
            .into_iter()
            .map(|k| cluster[k])
            .collect();
        let d = self.latent();
        let z = (0..d)
            .map(|j| {
                let mean = chosen.iter().map(|&i| self.mu[i][j]).sum::<f32>() / n as f32;
                let var = chosen.iter().map(|&i| self.logvar[i][j].exp()).sum::<f32>() / n as f32;
                let e: f32 = StandardNormal.sample(rng);
                mean + var.sqrt() * e
            })
            .collect();
        (z, chosen)
    }
}

/// One code from N(0, I).
pub fn sample_normal(latent: usize, rng: &mut impl Rng) -> Vec<f32> {
    (0..latent).map(|_| StandardNormal.sample(rng)).collect()
}

/// Coordinates of `points` on their first `components` principal axes (fewer when
/// the data has fewer directions: at most n - 1 and the dimension).
pub fn pca_project(points: &[Vec<f64>], components: usize) -> Vec<Vec<f64>> {
    let n = points.len();
    let d = points.first().map_or(0, Vec::len);
    let mean: Vec<f64> = (0..d)
        .map(|j| points.iter().map(|p| p[j]).sum::<f64>() / n as f64)
        .collect();
    let centred: Vec<Vec<f64>> = points
        .iter()
        .map(|p| p.iter().zip(&mean).map(|(a, b)| a - b).collect())
        .collect();
    let mut cov = vec![0.0f64; d * d];
    for p in &centred {
        for a in 0..d {
            for b in 0..d {
                cov[a * d + b] += p[a] * p[b];
            }
        }
    }
    let k = components.min(d).min(n.saturating_sub(1)).max(1);
    let mut axes: Vec<Vec<f64>> = Vec::with_capacity(k);
    for c in 0..k {
        // Deterministic start that is not orthogonal to typical data.
        let mut v: Vec<f64> = (0..d).map(|j| 1.0 + ((j + c) % 7) as f64 * 0.1).collect();
        let mut eigen = 0.0;
        for _ in 0..300 {
            let mut w = vec![0.0f64; d];
            for a in 0..d {
                w[a] = (0..d).map(|b| cov[a * d + b] * v[b]).sum();
            }
            for prev in &axes {
                let dot: f64 = w.iter().zip(prev).map(|(x, y)| x * y).sum();
                for (x, y) in w.iter_mut().zip(prev) {
                    *x -= dot * y;
                }
            }
            let norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm < 1e-12 {
                break;
            }
            eigen = norm;
            v = w.into_iter().map(|x| x / norm).collect();
        }
        if eigen < 1e-12 {
            break;
        }
        axes.push(v);
    }
    centred
        .iter()
        .map(|p| {
            if axes.is_empty() {
                return vec![0.0];
            }
            axes.iter()
                .map(|a| a.iter().zip(p).map(|(x, y)| x * y).sum())
                .collect()
        })
        .collect()
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum()
}

/// Labels `0..k` (k capped at the number of points) from the best of `restarts`
/// k-means++ / Lloyd runs.
pub fn kmeans(
    points: &[Vec<f64>],
    k: usize,
    iterations: usize,
    restarts: usize,
    rng: &mut impl Rng,
) -> Vec<usize> {
    let n = points.len();
    let k = k.min(n).max(1);
    let mut best: Option<(f64, Vec<usize>)> = None;
    for _ in 0..restarts.max(1) {
        let mut centres = vec![points[rng.random_range(0..n)].clone()];
        while centres.len() < k {
            let d: Vec<f64> = points
                .iter()
                .map(|p| {
                    centres
                        .iter()
                        .map(|c| dist2(p, c))
                        .fold(f64::INFINITY, f64::min)
                })
                .collect();
            let total: f64 = d.iter().sum();
            let next = if total <= 0.0 {
                rng.random_range(0..n)
            } else {
                let mut r = rng.random_range(0.0..total);
                d.iter()
                    .position(|&x| {
                        r -= x;
                        r < 0.0
                    })
                    .unwrap_or(n - 1)
            };
            centres.push(points[next].clone());
        }
        let mut labels = vec![0usize; n];
        for _ in 0..iterations {
            let mut changed = false;
            for (i, p) in points.iter().enumerate() {
                let l = (0..k)
                    .min_by(|&a, &b| dist2(p, &centres[a]).total_cmp(&dist2(p, &centres[b])))
                    .unwrap_or(0);
                changed |= l != labels[i];
                labels[i] = l;
            }
            for (c, centre) in centres.iter_mut().enumerate() {
                let members: Vec<&Vec<f64>> = points
                    .iter()
                    .zip(&labels)
                    .filter(|(_, l)| **l == c)
                    .map(|(p, _)| p)
                    .collect();
                if members.is_empty() {
                    continue;
                }
                for (j, x) in centre.iter_mut().enumerate() {
                    *x = members.iter().map(|p| p[j]).sum::<f64>() / members.len() as f64;
                }
            }
            if !changed {
                break;
            }
        }
        let inertia: f64 = points
            .iter()
            .zip(&labels)
            .map(|(p, &l)| dist2(p, &centres[l]))
            .sum();
        if best.as_ref().is_none_or(|(b, _)| inertia < *b) {
            best = Some((inertia, labels));
        }
    }
    // Relabel in order of first appearance so that labels are 0..used.
    let labels = best.map(|(_, l)| l).unwrap_or_default();
    let mut map = Vec::new();
    labels
        .iter()
        .map(|l| match map.iter().position(|m| m == l) {
            Some(p) => p,
            None => {
                map.push(*l);
                map.len() - 1
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn pca_finds_the_dominant_axis() {
        let pts: Vec<Vec<f64>> = (0..20)
            .map(|i| {
                let t = i as f64 - 10.0;
                vec![3.0 * t, 3.0 * t, 0.1 * ((i * 7) % 3) as f64]
            })
            .collect();
        let p = pca_project(&pts, 2);
        // First coordinate carries the spread along ~(1,1,0)/sqrt 2; point 0 sits
        // 28.5 sqrt 2 from the mean along it (the mean of 3t over -10..9 is -1.5).
        let var0: f64 = p.iter().map(|x| x[0] * x[0]).sum();
        let var1: f64 = p.iter().map(|x| x[1] * x[1]).sum();
        assert!(var0 > 100.0 * var1);
        assert!(
            (p[0][0].abs() - 28.5 * 2f64.sqrt()).abs() < 0.05,
            "{}",
            p[0][0]
        );
    }

    #[test]
    fn kmeans_separates_three_blobs() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let centres = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]];
        let pts: Vec<Vec<f64>> = (0..30)
            .map(|i| {
                let c = centres[i % 3];
                vec![
                    c[0] + (i as f64 * 0.37).sin() * 0.5,
                    c[1] + (i as f64 * 0.91).cos() * 0.5,
                ]
            })
            .collect();
        let labels = kmeans(&pts, 3, 100, 3, &mut rng);
        for i in 0..30 {
            assert_eq!(labels[i], labels[i % 3], "point {i}");
        }
        assert_ne!(labels[0], labels[1]);
        assert_ne!(labels[1], labels[2]);
        assert_ne!(labels[0], labels[2]);
    }

    #[test]
    fn near_samples_stay_near_training_means() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let d = 32;
        // Six training posteriors far from the origin, with small variances.
        let mu: Vec<Vec<f32>> = (0..6)
            .map(|i| {
                (0..d)
                    .map(|j| 3.0 * (((i * 13 + j * 7) % 11) as f32 / 5.0 - 1.0))
                    .collect()
            })
            .collect();
        let logvar = vec![vec![(0.05f32).ln(); d]; 6];
        let stats = LatentStats::fit(mu.clone(), logvar, &NearConfig::default(), &mut rng).unwrap();
        assert_eq!(stats.clusters().len(), 3);
        let nearest = |z: &[f32]| {
            mu.iter()
                .map(|m| {
                    m.iter()
                        .zip(z)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f32>()
                        .sqrt()
                })
                .fold(f32::INFINITY, f32::min)
        };
        let (mut near, mut prior) = (0.0, 0.0);
        for _ in 0..200 {
            near += nearest(&stats.sample_near(&mut rng));
            prior += nearest(&sample_normal(d, &mut rng));
        }
        // A near code is the midpoint of two cluster members plus small noise, so it
        // is not on top of a training mean, but far closer than a prior draw.
        assert!(near * 1.5 < prior, "near {near} vs prior {prior}");
    }
}
