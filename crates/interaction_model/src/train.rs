//! Training the three networks together (paper Eq. 4): `L = L_Bs + L_BM + L_AM`.
//!
//! * `L_Bs` (Eq. 5): the skeleton prior on B's standardised bone scales.
//! * `L_BM` (Eq. 6): the retargeting network, `w1 |q~'_B - q'_B|_1 + w2 |dq~'_B -
//!   dq'_B|_1 + w3 BL + w4 KL` with `w = (0.75, 0.1, 0.05, 0.1)`.
//! * `L_AM` (Eq. 8): the adaptation network, same terms on A, given the true
//!   `q'_B` (teacher forcing between the two networks; at inference A gets the
//!   retargeting network's output).
//!
//! L1 terms are means over coordinates (metres), the bone-length term `BL`
//! (Eq. 7) is the squared bone-length difference summed over bones and
//! averaged over frames and samples, KL is summed over latent dimensions.
//! One AdamW (the `nn` optimiser) over every parameter; batches are drawn from the
//! training windows by a seeded generator, so a run is reproducible.

use std::time::Instant;

use candle_core::{Device, Tensor};
use nn::{AdamConfig, Optimizer, kl_sum, normal};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::dataset::{Batch, Dataset, Sample};
use crate::error::{ModelError, Result};
use crate::model::{InteractionModel, ModelConfig, ModelMeta, PriorStats, TrainingSummary};

/// The paper's loss weights (Sec. 3.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    pub position: f64,
    pub velocity: f64,
    pub bone: f64,
    pub kl: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            position: 0.75,
            velocity: 0.1,
            bone: 0.05,
            kl: 0.1,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrainConfig {
    pub window: usize,
    pub stride: usize,
    pub steps: usize,
    pub batch: usize,
    pub lr: f64,
    pub weight_decay: f64,
    pub weights: LossWeights,
    /// G-GRU hidden size per node (both decoders).
    pub hidden: usize,
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            window: 16,
            stride: 2,
            steps: 1500,
            batch: 8,
            lr: 2e-3,
            weight_decay: 1e-4,
            weights: LossWeights::default(),
            hidden: 32,
            seed: 0,
        }
    }
}

/// Loss terms of one step (for the curve).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Losses {
    pub total: f64,
    pub prior: f64,
    pub retarget: f64,
    pub adapt: f64,
    /// Unweighted mean |position error| of B and A, metres.
    pub b_position_m: f64,
    pub a_position_m: f64,
}

/// Bone lengths `[n, T, V]` of points `[n, T, V, 3]` (0 at the root).
pub fn bone_lengths(x: &Tensor, parents: &Tensor) -> Result<Tensor> {
    let d = (x - x.index_select(parents, 2)?)?;
    Ok((d.sqr()?.sum(3)? + 1e-10)?.sqrt()?)
}

/// Parent index per node as a tensor (the root points to itself).
pub fn parent_index(parents: &[i32]) -> Result<Tensor> {
    let idx: Vec<u32> = parents
        .iter()
        .enumerate()
        .map(|(i, &p)| if p < 0 { i as u32 } else { p as u32 })
        .collect();
    Ok(Tensor::from_vec(idx, parents.len(), &Device::Cpu)?)
}

/// Eq. 6 / 8 without the KL term: weighted L1 position, L1 velocity and
/// bone-length terms. Returns (loss, mean |position error|).
pub fn motion_loss(
    pred: &Tensor,
    truth: &Tensor,
    parents: &Tensor,
    w: &LossWeights,
) -> Result<(Tensor, Tensor)> {
    let pos = (pred - truth)?.abs()?.mean_all()?;
    let t = pred.dim(1)?;
    let vel = if t > 1 {
        let dp = (pred.narrow(1, 1, t - 1)? - pred.narrow(1, 0, t - 1)?)?;
        let dt = (truth.narrow(1, 1, t - 1)? - truth.narrow(1, 0, t - 1)?)?;
        (dp - dt)?.abs()?.mean_all()?
    } else {
        pos.zeros_like()?
    };
    let bl = (bone_lengths(pred, parents)? - bone_lengths(truth, parents)?)?
        .sqr()?
        .sum(2)?
        .mean_all()?;
    let loss = ((pos.affine(w.position, 0.0)? + vel.affine(w.velocity, 0.0)?)?
        + bl.affine(w.bone, 0.0)?)?;
    Ok((loss, pos))
}

/// Mean and standard deviation (floored) of B's bone factors (root excluded)
/// over the training variations.
pub fn prior_stats(dataset: &Dataset, samples: &[Sample]) -> Result<PriorStats> {
    let mut seen = std::collections::BTreeSet::new();
    let mut rows: Vec<&[f32]> = Vec::new();
    for s in samples {
        if seen.insert((s.pair, s.variation)) {
            rows.push(&dataset.pairs[s.pair].factors[s.variation][1..]);
        }
    }
    let Some(first) = rows.first() else {
        return Err(ModelError::Data("no training variations".into()));
    };
    let d = first.len();
    let n = rows.len() as f32;
    let mean: Vec<f32> = (0..d)
        .map(|i| rows.iter().map(|r| r[i]).sum::<f32>() / n)
        .collect();
    let std: Vec<f32> = (0..d)
        .map(|i| {
            let v = rows.iter().map(|r| (r[i] - mean[i]).powi(2)).sum::<f32>() / n;
            v.sqrt().max(1e-3)
        })
        .collect();
    let (lo, hi) = rows
        .iter()
        .flat_map(|r| r.iter())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    Ok(PriorStats {
        mean,
        std,
        min: lo,
        max: hi,
    })
}

/// One training step's losses on `batch` (no optimiser step).
pub fn losses(
    model: &InteractionModel,
    batch: &Batch,
    w: &LossWeights,
    rng: &mut ChaCha8Rng,
) -> Result<(Tensor, Losses)> {
    let n = batch.samples.len();
    let m = &model.meta;
    // L_Bs.
    let bs = model.standardise(&batch.scales)?;
    let eps = normal(&[n, m.config.prior.latent], rng)?;
    let out = model.prior.forward(&bs, &eps)?;
    let l_prior = model.prior.loss(&bs, &out)?;
    // L_BM.
    let delta_b = (&batch.b - &batch.template_b)?;
    let eps = normal(&[n, m.config.retarget.latent], rng)?;
    let rb = model
        .retarget
        .forward(&delta_b, &batch.template_b, &batch.scales, &eps)?;
    let pred_b = (&batch.template_b + &rb.delta)?;
    let (lb, pos_b) = motion_loss(&pred_b, &batch.b, &model.parents_b, w)?;
    let l_b = (lb + kl_sum(&rb.mu, &rb.logvar)?.affine(w.kl, 0.0)?)?;
    // L_AM (true B as the condition).
    let delta_a = (&batch.a - &batch.template_a)?;
    let eps = normal(&[n, m.config.adapt.latent], rng)?;
    let ra = model.adapt.forward(
        &delta_a,
        &batch.template_a,
        &batch.b,
        &batch.template_b,
        &eps,
    )?;
    let pred_a = (&batch.template_a + &ra.delta)?;
    let (la, pos_a) = motion_loss(&pred_a, &batch.a, &model.parents_a, w)?;
    let l_a = (la + kl_sum(&ra.mu, &ra.logvar)?.affine(w.kl, 0.0)?)?;
    let total = ((&l_prior + &l_b)? + &l_a)?;
    let s = |t: &Tensor| -> Result<f64> { Ok(t.to_scalar::<f32>()? as f64) };
    let values = Losses {
        total: s(&total)?,
        prior: s(&l_prior)?,
        retarget: s(&l_b)?,
        adapt: s(&l_a)?,
        b_position_m: s(&pos_b)?,
        a_position_m: s(&pos_a)?,
    };
    Ok((total, values))
}

/// Progress callback: (step, losses).
pub type Progress<'a> = &'a mut (dyn FnMut(usize, &Losses) + Send);

/// Train a fresh model on `samples` (windows of `dataset`), on one thread:
/// the tensors are small, and handing candle's many small operations to a
/// thread pool cost more than it gave (measured 4x slower on two busy cores).
pub fn train(
    dataset: &Dataset,
    samples: &[Sample],
    config: &TrainConfig,
    progress: Option<Progress>,
) -> Result<InteractionModel> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "interaction-train".into())
        .build()
        .map_err(|e| ModelError::Data(format!("cannot start the training thread: {e}")))?;
    pool.install(|| train_here(dataset, samples, config, progress))
}

fn train_here(
    dataset: &Dataset,
    samples: &[Sample],
    config: &TrainConfig,
    progress: Option<Progress>,
) -> Result<InteractionModel> {
    let span = tracing::info_span!(
        "interaction_model_train",
        steps = config.steps,
        windows = samples.len()
    );
    let _guard = span.enter();
    if samples.is_empty() {
        return Err(ModelError::Data("no training windows".into()));
    }
    if config.batch == 0 || config.window < 2 {
        return Err(ModelError::Config {
            field: "train",
            message: "batch >= 1 and window >= 2".into(),
        });
    }
    let start = Instant::now();
    let first = &dataset.pairs[0];
    let model_config = ModelConfig::new(
        dataset.config.fps,
        config.window,
        first.body_a.len(),
        first.body_b.len(),
        config.hidden,
    );
    let mut pairs: Vec<String> = samples
        .iter()
        .map(|s| dataset.pairs[s.pair].name.clone())
        .collect();
    pairs.dedup();
    pairs.sort();
    pairs.dedup();
    let meta = ModelMeta {
        format: crate::model::FORMAT,
        config: model_config,
        body_a: first.body_a.clone(),
        body_b: first.body_b.clone(),
        prior: prior_stats(dataset, samples)?,
        training: TrainingSummary {
            config: config.clone(),
            pairs,
            windows: samples.len(),
            seconds: 0.0,
            final_losses: Losses::default(),
            curve: Vec::new(),
        },
    };
    let mut model = InteractionModel::new(meta, config.seed)?;
    let adam = AdamConfig {
        weight_decay: config.weight_decay,
        ..AdamConfig::new(config.lr)
    };
    let mut opt = Optimizer::new(model.params.vars(), adam, None);
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x5EED);
    let mut order: Vec<usize> = (0..samples.len()).collect();
    let mut cursor = order.len();
    let mut last = Losses::default();
    let mut progress = progress;
    let mut curve = Vec::new();
    for step in 0..config.steps {
        // Cosine decay to a tenth of the rate.
        let frac = step as f64 / config.steps.max(1) as f64;
        opt.set_lr(config.lr * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * frac).cos())));
        let mut picked = Vec::with_capacity(config.batch);
        while picked.len() < config.batch.min(samples.len()) {
            if cursor == order.len() {
                order.shuffle(&mut rng);
                cursor = 0;
            }
            picked.push(samples[order[cursor]]);
            cursor += 1;
        }
        let batch = dataset.batch(&picked, config.window)?;
        let (loss, values) = losses(&model, &batch, &config.weights, &mut rng)?;
        if !values.total.is_finite() {
            return Err(ModelError::Data(format!(
                "loss became {} at step {step}",
                values.total
            )));
        }
        opt.step(&loss.backward()?)?;
        last = values;
        if step % 10 == 0 || step + 1 == config.steps {
            curve.push((step, values.total));
        }
        if let Some(p) = progress.as_mut() {
            p(step, &values);
        }
    }
    model.meta.training.seconds = start.elapsed().as_secs_f64();
    model.meta.training.final_losses = last;
    model.meta.training.curve = curve;
    tracing::info!(
        seconds = model.meta.training.seconds,
        loss = last.total,
        "trained"
    );
    Ok(model)
}
