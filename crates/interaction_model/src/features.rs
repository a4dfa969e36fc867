//! The motion feature network for FID, and the Fréchet distance itself.
//!
//! FID needs an encoder whose features describe two-person interaction
//! windows. We train our own (there is no pretrained one for this skeleton):
//! an ST-GCN over both bodies' points (A's graph and B's graph side by side,
//! positions in the window's canonical frame) pooled to a `dim`-number
//! feature, with two heads trained together: which captured interaction the
//! window comes from (cross-entropy) and B's global body scale (squared error,
//! standardised). The features must therefore tell interactions apart and see
//! body size, the two things augmentation changes or must keep. It is trained
//! on the ground-truth windows of the whole dataset (it is a yardstick, not a
//! model under test) and its held-out accuracy and scale error are reported.
//!
//! FID (Heusel et al. 2017) between two feature sets is
//! `|mu1 - mu2|^2 + tr(S1 + S2 - 2 (S1^1/2 S2 S1^1/2)^1/2)`, with symmetric
//! eigendecompositions for the matrix square roots.

use candle_core::{Device, Tensor};
use candle_nn::{Linear, Module, VarBuilder};
use nalgebra::{DMatrix, DVector};
use nn::{AdamConfig, Optimizer, Params};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::dataset::{Dataset, Sample};
use crate::error::{ModelError, Result};
use crate::graph::cat;
use crate::stgcn::{StGcn, StGcnConfig};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureConfig {
    pub encoder: StGcnConfig,
    pub dim: usize,
    pub classes: usize,
    pub steps: usize,
    pub batch: usize,
    pub lr: f64,
    pub seed: u64,
}

impl FeatureConfig {
    pub fn new(classes: usize) -> Self {
        FeatureConfig {
            encoder: StGcnConfig::new(3, &[16, 32]),
            dim: 32,
            classes,
            steps: 300,
            batch: 32,
            lr: 2e-3,
            seed: 0,
        }
    }
}

/// How well the feature network learned its two tasks on held-out windows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FeatureQuality {
    pub train_windows: usize,
    pub test_windows: usize,
    pub class_accuracy: f64,
    /// RMS error of B's predicted global scale (factor units).
    pub scale_rmse: f64,
    pub seconds: f64,
}

pub struct FeatureNet {
    /// The parameters (seeded, `nn`'s scheme).
    pub params: Params,
    encoder: StGcn,
    project: Linear,
    class_head: Linear,
    scale_head: Linear,
    pub config: FeatureConfig,
    /// Mean and std of the global scale (the regression target is standardised).
    scale_stats: (f32, f32),
}

/// A's graph then B's, as one graph of two components.
pub fn joint_graph(parents_a: &[i32], parents_b: &[i32]) -> Vec<i32> {
    let va = parents_a.len() as i32;
    parents_a
        .iter()
        .copied()
        .chain(parents_b.iter().map(|&p| if p < 0 { -1 } else { p + va }))
        .collect()
}

impl FeatureNet {
    /// A fresh network, its parameters drawn into `params`.
    pub fn new(params: &Params, config: &FeatureConfig, parents: &[i32]) -> Result<Self> {
        let e = config.encoder.out_dim();
        let vb: VarBuilder = params.var_builder();
        Ok(FeatureNet {
            params: params.clone(),
            encoder: StGcn::new(vb.pp("stgcn"), &config.encoder, parents)?,
            project: candle_nn::linear(e, config.dim, vb.pp("project"))?,
            class_head: candle_nn::linear(config.dim, config.classes, vb.pp("class"))?,
            scale_head: candle_nn::linear(config.dim, 1, vb.pp("scale"))?,
            config: config.clone(),
            scale_stats: (1.0, 1.0),
        })
    }

    /// Features `[n, dim]` of windows `a` `[n, T, Va, 3]`, `b` `[n, T, Vb, 3]` (canonical frame).
    pub fn features(&self, a: &Tensor, b: &Tensor) -> Result<Tensor> {
        let x = cat(&[a, b], 2)?;
        Ok(self.project.forward(&self.encoder.forward(&x)?)?.tanh()?)
    }

    /// Train on `train` windows' ground truth; report quality on `test`.
    pub fn train(
        dataset: &Dataset,
        train: &[Sample],
        test: &[Sample],
        window: usize,
        config: &FeatureConfig,
    ) -> Result<(FeatureNet, FeatureQuality)> {
        let span = tracing::info_span!("interaction_features_train", steps = config.steps);
        let _guard = span.enter();
        let start = std::time::Instant::now();
        if train.is_empty() {
            return Err(ModelError::Data(
                "no windows to train the feature network".into(),
            ));
        }
        let first = &dataset.pairs[0];
        let parents = joint_graph(&first.body_a.parents, &first.body_b.parents);
        let mut net = FeatureNet::new(&Params::new(config.seed), config, &parents)?;
        let globals: Vec<f32> = train
            .iter()
            .map(|s| dataset.pairs[s.pair].variations[s.variation].global as f32)
            .collect();
        let m = globals.iter().sum::<f32>() / globals.len() as f32;
        let sd = (globals.iter().map(|g| (g - m).powi(2)).sum::<f32>() / globals.len() as f32)
            .sqrt()
            .max(1e-3);
        net.scale_stats = (m, sd);
        let adam = AdamConfig {
            weight_decay: 1e-4,
            ..AdamConfig::new(config.lr)
        };
        let mut opt = Optimizer::new(net.params.vars(), adam, None);
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0xFEA7);
        let mut order: Vec<usize> = (0..train.len()).collect();
        let mut cursor = order.len();
        for _ in 0..config.steps {
            let mut picked = Vec::new();
            while picked.len() < config.batch.min(train.len()) {
                if cursor == order.len() {
                    order.shuffle(&mut rng);
                    cursor = 0;
                }
                picked.push(train[order[cursor]]);
                cursor += 1;
            }
            let loss = net.loss(dataset, &picked, window)?;
            opt.step(&loss.backward()?)?;
        }
        let mut q = FeatureQuality {
            train_windows: train.len(),
            test_windows: test.len(),
            ..Default::default()
        };
        if !test.is_empty() {
            let (mut correct, mut sq) = (0usize, 0.0f64);
            for chunk in test.chunks(64) {
                let batch = dataset.batch(chunk, window)?;
                let f = net.features(&batch.a, &batch.b)?;
                let logits = net.class_head.forward(&f)?.to_vec2::<f32>()?;
                let scale = net
                    .scale_head
                    .forward(&f)?
                    .flatten_all()?
                    .to_vec1::<f32>()?;
                for (k, s) in chunk.iter().enumerate() {
                    let best = logits[k]
                        .iter()
                        .enumerate()
                        .max_by(|x, y| x.1.total_cmp(y.1))
                        .map(|x| x.0);
                    correct += usize::from(best == Some(s.pair));
                    let g = dataset.pairs[s.pair].variations[s.variation].global as f32;
                    let pred = scale[k] * sd + m;
                    sq += ((pred - g) as f64).powi(2);
                }
            }
            q.class_accuracy = correct as f64 / test.len() as f64;
            q.scale_rmse = (sq / test.len() as f64).sqrt();
        }
        q.seconds = start.elapsed().as_secs_f64();
        Ok((net, q))
    }

    fn loss(&self, dataset: &Dataset, picked: &[Sample], window: usize) -> Result<Tensor> {
        let batch = dataset.batch(picked, window)?;
        let f = self.features(&batch.a, &batch.b)?;
        let labels: Vec<u32> = picked.iter().map(|s| s.pair as u32).collect();
        let labels = Tensor::from_vec(labels, picked.len(), &Device::Cpu)?;
        let ce = candle_nn::loss::cross_entropy(&self.class_head.forward(&f)?, &labels)?;
        let (m, sd) = self.scale_stats;
        let target: Vec<f32> = picked
            .iter()
            .map(|s| (dataset.pairs[s.pair].variations[s.variation].global as f32 - m) / sd)
            .collect();
        let target = Tensor::from_vec(target, (picked.len(), 1), &Device::Cpu)?;
        let mse = (self.scale_head.forward(&f)? - target)?.sqr()?.mean_all()?;
        Ok((ce + mse)?)
    }
}

/// Rows of a `[n, d]` tensor.
pub fn rows(t: &Tensor) -> Result<Vec<Vec<f64>>> {
    Ok(t.to_vec2::<f32>()?
        .into_iter()
        .map(|r| r.into_iter().map(f64::from).collect())
        .collect())
}

fn mean_cov(x: &[Vec<f64>]) -> (DVector<f64>, DMatrix<f64>) {
    let d = x[0].len();
    let n = x.len() as f64;
    let mut mu = DVector::zeros(d);
    for r in x {
        mu += DVector::from_column_slice(r);
    }
    mu /= n;
    let mut cov = DMatrix::zeros(d, d);
    for r in x {
        let c = DVector::from_column_slice(r) - &mu;
        cov += &c * c.transpose();
    }
    cov /= (n - 1.0).max(1.0);
    (mu, cov)
}

fn sqrt_psd(m: &DMatrix<f64>) -> DMatrix<f64> {
    let sym = (m + m.transpose()) * 0.5;
    let e = sym.symmetric_eigen();
    let d = DMatrix::from_diagonal(&e.eigenvalues.map(|v| v.max(0.0).sqrt()));
    &e.eigenvectors * d * e.eigenvectors.transpose()
}

/// Fréchet distance between the Gaussians fitted to two feature sets.
pub fn fid(x: &[Vec<f64>], y: &[Vec<f64>]) -> Result<f64> {
    if x.len() < 2 || y.len() < 2 || x[0].len() != y[0].len() {
        return Err(ModelError::Data(format!(
            "FID needs two sets of at least 2 features of one size ({} and {})",
            x.len(),
            y.len()
        )));
    }
    let (m1, s1) = mean_cov(x);
    let (m2, s2) = mean_cov(y);
    let r1 = sqrt_psd(&s1);
    let cross = sqrt_psd(&(&r1 * &s2 * &r1));
    let d = &m1 - &m2;
    Ok((d.dot(&d) + s1.trace() + s2.trace() - 2.0 * cross.trace()).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fid_is_zero_for_one_set_and_grows_with_a_shift() {
        let x: Vec<Vec<f64>> = (0..50)
            .map(|i| {
                vec![
                    (i as f64 * 0.37).sin(),
                    (i as f64 * 0.91).cos(),
                    i as f64 / 50.0,
                ]
            })
            .collect();
        assert!(fid(&x, &x).unwrap() < 1e-9);
        let shifted: Vec<Vec<f64>> = x
            .iter()
            .map(|r| r.iter().map(|v| v + 0.5).collect())
            .collect();
        // A pure shift of the mean by 0.5 in 3 dimensions: FID = 3 * 0.25.
        assert!((fid(&x, &shifted).unwrap() - 0.75).abs() < 1e-6);
        let wide: Vec<Vec<f64>> = x
            .iter()
            .map(|r| r.iter().map(|v| v * 2.0).collect())
            .collect();
        assert!(fid(&x, &wide).unwrap() > 0.1);
    }
}
