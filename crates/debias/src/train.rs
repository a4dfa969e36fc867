//! Fitting the debiasing MLP and applying it.
//!
//! Training pairs are (corrected original, original). The original is
//! resampled to the corrected clip's frame rate and both are cut to the shorter
//! length (a correction that fell ends early). Inputs and targets are
//! standardised with statistics of the training set, which are saved with the
//! weights. The target is the change of rotations (root tilt and joints, 6D)
//! `original - corrected`; applying adds the predicted change to a corrected
//! clip's rotations, keeps its root translation and then puts its planted feet
//! back where the corrected clip has them ([`crate::contacts`]).
//!
//! Why a held-out check: the pairs are few (the accepted originals of one
//! training fold, ~20 clips), and a 4 x 512 network fits any 20 clips, so
//! the training loss says nothing about the clips it will be applied to. A
//! share of the pairs (whole clips) is held out of a first fit, which picks
//! the number of steps with the lowest held-out loss and the gain in `[0, 1]`
//! that fits the held-out pairs best (least squares); the network is then
//! fitted on all pairs for that many steps and its change scaled by that
//! gain, so a network that does not generalise is applied weakly or barely
//! trained rather than adding its noise to every clip.

use std::path::Path;
use std::time::Instant;

use candle_core::{Device, Tensor};
use motion::Motion;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::contacts::{self, ContactConfig, ContactReport};
use crate::features::{
    apply_rotations, input_dim, inputs, low_pass, output_dim, rotations_of, state_dim, states,
};
use crate::model;
use crate::{DebiasError, Result};
use nn::{AdamConfig, Mlp, MlpConfig, MlpInit, Optimizer, Params};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    pub hidden: Vec<usize>,
    /// Optimiser steps.
    pub iterations: usize,
    /// Frames per step.
    pub batch_size: usize,
    pub learning_rate: f64,
    pub weight_decay: f64,
    pub seed: u64,
    /// Share of the pairs (whole clips, at least one when there are two or
    /// more) held out to pick the step count and the gain; 0 trains on all
    /// pairs for `iterations` steps and applies the change at full strength.
    pub validation_fraction: f64,
    /// How the corrected clip's foot contacts are kept when applying.
    pub contacts: ContactConfig,
    /// Start the network as the training pairs' mean change (its output
    /// layer zero: a constant offset per rotation value, the simplest model
    /// of a simulation's bias), so the held-out check at step 0 scores that
    /// offset alone and training departs from it only as far as the
    /// held-out pairs reward; off: the layer starts random like the others.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub start_from_mean: bool,
    /// Standard deviation, seconds, of the Gaussian low-pass over time of the
    /// predicted change ([`crate::features::low_pass`]), in the held-out
    /// check and when applying; 0 = none (the paper's per-frame change).
    /// Default 0.05 s: on kick fold dg it brings the debiased samples' jerk
    /// from 2x the corrected clips' to 1.1x and leaves the held-out loss as
    /// it was (crate docs, session 27).
    pub smoothing_s: f64,
    /// Apply the change at this gain instead of the held-out least-squares
    /// one (an ablation: how the cost or gain of debiasing scales with how
    /// far it moves a clip). `None`: the held-out choice (1 without pairs
    /// held out). The step count and the report's held-out losses stay the
    /// held-out check's (at its own least-squares gain).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain: Option<f64>,
    /// Which pairs the held-out check scores: a share of the clips
    /// (`validation_fraction`, clips of actors the first fit also saw) or
    /// every actor in turn ([`train_with_actors`]).
    #[serde(skip_serializing_if = "HoldOut::is_clips")]
    pub hold_out: HoldOut,
}

/// What the held-out check of [`train`] holds out.
///
/// Why actors: the debiaser is applied to clips of the actors it was trained
/// on, but the table's predictors are tested on an actor nobody trained on,
/// and a network that only learnt each training actor's own style moves
/// samples towards those actors. Holding out whole actors asks whether the
/// change it learnt carries over to a body it has not seen, and scales it
/// by as much as it does (crate docs: on unseen actors it did not, session 21).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldOut {
    /// `validation_fraction` of the clips, chosen by the seed.
    #[default]
    Clips,
    /// Each actor's pairs in turn, the network fitted on the other actors'
    /// (one fit per actor); the step count and the gain are chosen on the
    /// held-out losses pooled over actors. Needs pairs of two actors or more.
    Actors,
}

impl HoldOut {
    /// The default (left out of saved configs).
    pub fn is_clips(&self) -> bool {
        *self == HoldOut::Clips
    }
}

impl Default for TrainConfig {
    /// The paper's 4 x 512 network, AdamW 1e-3, 2000 steps of 256 frames.
    fn default() -> Self {
        TrainConfig {
            hidden: vec![512; 4],
            iterations: 2000,
            batch_size: 256,
            learning_rate: 1e-3,
            weight_decay: 1e-4,
            seed: 0,
            validation_fraction: 0.2,
            contacts: ContactConfig::default(),
            start_from_mean: false,
            smoothing_s: 0.05,
            gain: None,
            hold_out: HoldOut::Clips,
        }
    }
}

impl TrainConfig {
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DebiasError::Config(m));
        if self.iterations == 0 {
            return bad("iterations must be at least 1".into());
        }
        if self.batch_size == 0 {
            return bad("batch_size must be at least 1".into());
        }
        if !(0.0..1.0).contains(&self.validation_fraction) {
            return bad(format!(
                "validation_fraction {} is not in [0, 1)",
                self.validation_fraction
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return bad(format!(
                "learning_rate {} is not positive",
                self.learning_rate
            ));
        }
        if !(self.weight_decay.is_finite() && self.weight_decay >= 0.0) {
            return bad(format!("weight_decay {} is negative", self.weight_decay));
        }
        if let Some(g) = self.gain
            && !(0.0..=1.0).contains(&g)
        {
            return bad(format!("gain {g} is not in [0, 1]"));
        }
        if !(self.smoothing_s.is_finite() && self.smoothing_s >= 0.0) {
            return bad(format!(
                "smoothing_s {} is not a number >= 0",
                self.smoothing_s
            ));
        }
        self.contacts.validate()
    }
}

/// What training measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    pub pairs: usize,
    pub frames: usize,
    /// Steps of the final fit: the held-out best when pairs are held out,
    /// else the configured `iterations`.
    pub iterations: usize,
    /// Mean squared rotation error (standardised units) before training: corrected vs original.
    pub loss_before: f64,
    /// The same after training (training set).
    pub loss_after: f64,
    /// Pairs held out of the first fit to choose the step count and the gain.
    #[serde(default)]
    pub validation_pairs: usize,
    /// Actors held out in turn (0: the check held out a share of the clips,
    /// or nothing).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub validation_actors: usize,
    /// Held-out mean squared change of rotations (6D, raw units) left by doing
    /// nothing: corrected vs original.
    #[serde(default)]
    pub validation_loss_zero: Option<f64>,
    /// The same after debiasing (best step, gain applied): below
    /// `validation_loss_zero` when the network generalises.
    #[serde(default)]
    pub validation_loss: Option<f64>,
    /// Scale of the predicted change when applied, in `[0, 1]`.
    #[serde(default = "full_gain")]
    pub gain: f64,
    pub wall_s: f64,
}

fn full_gain() -> f64 {
    1.0
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Held-out loss is checked every this many steps.
const CHECK_EVERY: usize = 50;

/// Mean and standard deviation per column (std floored so constant columns stay finite).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Standardiser {
    mean: Vec<f32>,
    std: Vec<f32>,
}

impl Standardiser {
    fn fit(rows: &[f32], dim: usize) -> Standardiser {
        let n = (rows.len() / dim).max(1) as f64;
        let mut mean = vec![0.0f64; dim];
        for r in rows.chunks_exact(dim) {
            for (m, x) in mean.iter_mut().zip(r) {
                *m += *x as f64 / n;
            }
        }
        let mut var = vec![0.0f64; dim];
        for r in rows.chunks_exact(dim) {
            for ((v, x), m) in var.iter_mut().zip(r).zip(&mean) {
                *v += (*x as f64 - m).powi(2) / n;
            }
        }
        Standardiser {
            mean: mean.iter().map(|m| *m as f32).collect(),
            std: var.iter().map(|v| (v.sqrt() as f32).max(1e-3)).collect(),
        }
    }

    fn apply(&self, rows: &[f32]) -> Vec<f32> {
        let d = self.mean.len();
        rows.iter()
            .enumerate()
            .map(|(i, x)| (x - self.mean[i % d]) / self.std[i % d])
            .collect()
    }

    fn invert(&self, rows: &[f32]) -> Vec<f32> {
        let d = self.mean.len();
        rows.iter()
            .enumerate()
            .map(|(i, x)| x * self.std[i % d] + self.mean[i % d])
            .collect()
    }
}

/// Saved next to the weights as `debias.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Meta {
    format: u32,
    joints: usize,
    fps: f64,
    mlp: MlpConfig,
    contacts: ContactConfig,
    /// Low-pass of the predicted change, seconds (models saved before it
    /// existed read as 0: none).
    #[serde(default)]
    smoothing_s: f64,
    /// Where the corrected originals' planted soles are (for `flatten_soles`).
    #[serde(default)]
    sole_height_m: Option<f64>,
    input: Standardiser,
    output: Standardiser,
    report: TrainReport,
}

/// 2: the network predicts rotations only and contacts are restored (1 also
/// predicted the root's height and velocity).
const FORMAT: u32 = 2;
const WEIGHTS: &str = "debias.safetensors";
const META: &str = "debias.json";

/// A trained debiasing network with its standardisation.
pub struct Debiaser {
    meta: Meta,
    params: Params,
    mlp: Mlp,
}

/// Align a pair at the corrected clip's frame rate and length.
fn aligned(corrected: &Motion, original: &Motion) -> Result<(Vec<f32>, Vec<f32>)> {
    if corrected.joints() != original.joints() {
        return Err(DebiasError::Data(format!(
            "a pair has {} and {} joints: the corrected clip must be on the original's skeleton",
            corrected.joints(),
            original.joints()
        )));
    }
    let original = if (original.fps() - corrected.fps()).abs() > 1e-6 {
        motion::resample::resample(original, corrected.fps())?
    } else {
        original.clone()
    };
    let dim = state_dim(corrected.joints());
    let n = corrected.frames().min(original.frames());
    let mut a = states(corrected);
    let mut b = states(&original);
    a.truncate(n * dim);
    b.truncate(n * dim);
    Ok((a, b))
}

/// Train on pairs `(corrected original, original)`.
///
/// With pairs held out: a first fit on the rest scores the held-out pairs
/// every [`CHECK_EVERY`] steps and picks the step and the gain; the model is
/// then fitted on all pairs for that many steps and applied with that gain.
/// [`HoldOut::Actors`] needs each pair's actor: [`train_with_actors`].
pub fn train(pairs: &[(Motion, Motion)], config: &TrainConfig) -> Result<(Debiaser, TrainReport)> {
    train_with_actors(pairs, &[], config)
}

/// [`train`], told the actor of each pair (`actors[i]` for `pairs[i]`):
/// with [`HoldOut::Actors`] each actor's pairs are held out of one first fit
/// in turn, and the step and the gain are chosen on the held-out losses
/// pooled over actors. `actors` is not read with [`HoldOut::Clips`].
pub fn train_with_actors(
    pairs: &[(Motion, Motion)],
    actors: &[String],
    config: &TrainConfig,
) -> Result<(Debiaser, TrainReport)> {
    config.validate()?;
    let span = tracing::info_span!("debias_train", pairs = pairs.len());
    let _guard = span.enter();
    let started = Instant::now();
    let Some((first, _)) = pairs.first() else {
        return Err(DebiasError::Data("no training pairs".into()));
    };
    let joints = first.joints();
    let fps = first.fps();
    let sd = state_dim(joints);
    let folds = held_out_folds(pairs.len(), actors, config)?;
    let mut clips = Vec::with_capacity(pairs.len());
    for (i, (corrected, original)) in pairs.iter().enumerate() {
        if corrected.joints() != joints || (corrected.fps() - fps).abs() > 1e-6 {
            return Err(DebiasError::Data(format!(
                "pair {i}: {} joints at {} fps, the first pair has {joints} at {fps}",
                corrected.joints(),
                corrected.fps()
            )));
        }
        let (c, o) = aligned(corrected, original)?;
        let x = inputs(&c, sd);
        let (c, o) = (rotations_of(&c, joints), rotations_of(&o, joints));
        let y: Vec<f32> = o.iter().zip(&c).map(|(o, c)| o - c).collect();
        let frames = y.len() / output_dim(joints);
        clips.push(Rows {
            x,
            y,
            lengths: vec![frames],
        });
    }
    let all = Rows::of(clips.iter());
    // One first fit per fold; their checks pooled step by step.
    let mut pooled: Vec<Check> = Vec::new();
    for fold in &folds {
        let (val, kept): (Vec<usize>, Vec<usize>) =
            (0..clips.len()).partition(|i| fold.contains(i));
        let kept = Rows::of(kept.iter().map(|&i| &clips[i]));
        let val = Rows::of(val.iter().map(|&i| &clips[i]));
        let (_, checks) = fit(&kept, joints, fps, config, config.iterations, Some(&val))?;
        pooled = match pooled.is_empty() {
            true => checks,
            false => pooled
                .iter()
                .zip(&checks)
                .map(|(a, b)| a.pooled(b))
                .collect(),
        };
    }
    let (steps, gain, validation) = match Check::best(&pooled) {
        Some(best) => (
            best.iteration,
            best.gain(),
            Some((best.loss_zero(), best.loss())),
        ),
        None if folds.is_empty() => (config.iterations, 1.0, None),
        None => return Err(DebiasError::Data("no held-out check ran".into())),
    };
    let gain = config.gain.unwrap_or(gain);
    let (fitted, _) = fit(&all, joints, fps, config, steps, None)?;
    let report = TrainReport {
        pairs: pairs.len(),
        frames: fitted.frames,
        iterations: steps,
        loss_before: fitted.loss_before,
        loss_after: fitted.loss_after,
        validation_pairs: folds.iter().map(Vec::len).sum(),
        validation_actors: match config.hold_out {
            HoldOut::Actors => folds.len(),
            HoldOut::Clips => 0,
        },
        validation_loss_zero: validation.map(|v| v.0),
        validation_loss: validation.map(|v| v.1),
        gain,
        wall_s: started.elapsed().as_secs_f64(),
    };
    tracing::info!(
        loss_before = report.loss_before,
        loss_after = report.loss_after,
        frames = report.frames,
        gain,
        steps,
        validation_actors = report.validation_actors,
        validation_loss_zero = ?report.validation_loss_zero,
        validation_loss = ?report.validation_loss,
        "debias trained"
    );
    let meta = Meta {
        format: FORMAT,
        joints,
        fps,
        mlp: fitted.mlp_config,
        contacts: config.contacts,
        smoothing_s: config.smoothing_s,
        sole_height_m: contacts::sole_height(
            &pairs.iter().map(|(c, _)| c).collect::<Vec<_>>(),
            &config.contacts,
        ),
        input: fitted.input,
        output: fitted.output,
        report: report.clone(),
    };
    let (params, mlp) = (fitted.params, fitted.mlp);
    Ok((Debiaser { meta, params, mlp }, report))
}

/// The pairs each first fit holds out (none: no held-out check).
fn held_out_folds(n: usize, actors: &[String], config: &TrainConfig) -> Result<Vec<Vec<usize>>> {
    match config.hold_out {
        HoldOut::Clips => {
            let fold = held_out(n, config.validation_fraction, config.seed);
            Ok(if fold.is_empty() { vec![] } else { vec![fold] })
        }
        HoldOut::Actors => {
            if actors.len() != n {
                return Err(DebiasError::Config(format!(
                    "holding out actors needs the actor of every pair: {} actors for {n} pairs",
                    actors.len()
                )));
            }
            let mut by_actor: std::collections::BTreeMap<&str, Vec<usize>> = Default::default();
            for (i, actor) in actors.iter().enumerate() {
                by_actor.entry(actor.as_str()).or_default().push(i);
            }
            if by_actor.len() < 2 {
                return Err(DebiasError::Data(format!(
                    "holding out actors needs pairs of two actors or more; all {n} are {}'s",
                    actors.first().map_or("nobody", String::as_str)
                )));
            }
            Ok(by_actor.into_values().collect())
        }
    }
}

/// Per-frame inputs and targets (row-major) of some pairs.
#[derive(Default)]
struct Rows {
    x: Vec<f32>,
    y: Vec<f32>,
    /// Frames of each pair, in order (the low-pass stays within a clip).
    lengths: Vec<usize>,
}

impl Rows {
    /// Some clips' rows, one after the other.
    fn of<'a>(clips: impl Iterator<Item = &'a Rows>) -> Rows {
        let mut rows = Rows::default();
        for clip in clips {
            rows.x.extend_from_slice(&clip.x);
            rows.y.extend_from_slice(&clip.y);
            rows.lengths.extend_from_slice(&clip.lengths);
        }
        rows
    }
}

/// A network fitted on some rows, with the standardisation it was fitted with.
struct Fitted {
    mlp_config: MlpConfig,
    params: Params,
    mlp: Mlp,
    input: Standardiser,
    output: Standardiser,
    frames: usize,
    /// Training loss (standardised units) of the zero change and after fitting.
    loss_before: f64,
    loss_after: f64,
}

/// Fit a fresh network (seeded by `config.seed`) on `rows` for `steps` steps;
/// with `held_out`, score it every [`CHECK_EVERY`] steps and after the last,
/// and return those checks in order.
fn fit(
    rows: &Rows,
    joints: usize,
    fps: f64,
    config: &TrainConfig,
    steps: usize,
    held_out: Option<&Rows>,
) -> Result<(Fitted, Vec<Check>)> {
    let (id, od) = (input_dim(joints), output_dim(joints));
    let frames = rows.y.len() / od;
    if frames < 2 {
        return Err(DebiasError::Data(
            "fewer than two frames of training data".into(),
        ));
    }
    let input = Standardiser::fit(&rows.x, id);
    let output = Standardiser::fit(&rows.y, od);
    let x = Tensor::from_vec(input.apply(&rows.x), (frames, id), &Device::Cpu)?;
    let y = Tensor::from_vec(output.apply(&rows.y), (frames, od), &Device::Cpu)?;
    // Held-out inputs standardised like the training rows, with raw targets.
    let val = match held_out {
        Some(v) => {
            let x = Tensor::from_vec(input.apply(&v.x), (v.y.len() / od, id), &Device::Cpu)?;
            Some((x, v))
        }
        None => None,
    };

    let mlp_config = MlpConfig {
        init: match config.start_from_mean {
            true => MlpInit::ScaledOutput { scale: 0.0 },
            false => MlpInit::Uniform,
        },
        ..MlpConfig::new(id, &config.hidden, od)
    };
    let params = Params::new(config.seed);
    let mlp = model::build(&mlp_config, &params)?;
    let adam = AdamConfig {
        weight_decay: config.weight_decay,
        ..AdamConfig::new(config.learning_rate)
    };
    let mut opt = Optimizer::new(params.vars(), adam, None);
    // Loss of "no correction" in standardised target units: the zero change.
    let zero = output.apply(&vec![0.0; od]);
    let zero = Tensor::from_vec(zero, (1, od), &Device::Cpu)?;
    let loss_before = y
        .broadcast_sub(&zero)?
        .sqr()?
        .mean_all()?
        .to_scalar::<f32>()? as f64;

    let mut checks: Vec<Check> = Vec::new();
    let mut check = |it: usize| -> Result<()> {
        if let Some((x, rows)) = &val {
            let sigma = config.smoothing_s * fps;
            checks.push(Check::score(it, &mlp, x, rows, sigma, &output)?);
        }
        Ok(())
    };
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut order: Vec<u32> = (0..frames as u32).collect();
    let mut cursor = frames;
    let batch = config.batch_size.min(frames);
    for it in 0..steps {
        if it % CHECK_EVERY == 0 {
            check(it)?;
        }
        if cursor + batch > frames {
            order.shuffle(&mut rng);
            cursor = 0;
        }
        let idx = Tensor::from_slice(&order[cursor..cursor + batch], batch, &Device::Cpu)?;
        cursor += batch;
        let pred = mlp.forward(&x.index_select(&idx, 0)?)?;
        let loss = pred.sub(&y.index_select(&idx, 0)?)?.sqr()?.mean_all()?;
        opt.step(&loss.backward()?)?;
        if it % 500 == 0 {
            tracing::debug!(it, loss = loss.to_scalar::<f32>()?, "debias step");
        }
    }
    check(steps)?;
    let loss_after = mlp
        .forward(&x)?
        .sub(&y)?
        .sqr()?
        .mean_all()?
        .to_scalar::<f32>()? as f64;
    let fitted = Fitted {
        mlp_config,
        params,
        mlp,
        input,
        output,
        frames,
        loss_before,
        loss_after,
    };
    Ok((fitted, checks))
}

/// Which pairs are held out: `round(fraction * n)` of them, at least one when
/// `n >= 2` and `fraction > 0`, never all; chosen by the seed.
fn held_out(n: usize, fraction: f64, seed: u64) -> Vec<usize> {
    if n < 2 || fraction <= 0.0 {
        return Vec::new();
    }
    let k = ((fraction * n as f64).round() as usize).clamp(1, n - 1);
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_da7a));
    order.truncate(k);
    order
}

/// One held-out check: sums over the held-out values of the predicted change
/// `p` (raw units, low-passed as when applied) and the wanted change `y`.
#[derive(Debug, Clone, Copy)]
struct Check {
    iteration: usize,
    pp: f64,
    py: f64,
    yy: f64,
    values: f64,
}

impl Check {
    /// Score the current weights on the held-out frames (the change
    /// low-passed by `sigma` frames, as when applied).
    fn score(
        iteration: usize,
        mlp: &Mlp,
        x_val: &Tensor,
        val: &Rows,
        sigma: f64,
        output: &Standardiser,
    ) -> Result<Check> {
        let pred = mlp.forward(x_val)?.flatten_all()?.to_vec1::<f32>()?;
        let pred = low_pass(
            &output.invert(&pred),
            output.mean.len(),
            &val.lengths,
            sigma,
        );
        let (mut py, mut pp, mut yy) = (0.0f64, 0.0f64, 0.0f64);
        for (p, y) in pred.iter().zip(&val.y) {
            let (p, y) = (*p as f64, *y as f64);
            py += p * y;
            pp += p * p;
            yy += y * y;
        }
        Ok(Check {
            iteration,
            pp,
            py,
            yy,
            values: val.y.len() as f64,
        })
    }

    /// The same step checked on other held-out pairs: the sums added.
    fn pooled(&self, other: &Check) -> Check {
        debug_assert_eq!(self.iteration, other.iteration);
        Check {
            iteration: self.iteration,
            pp: self.pp + other.pp,
            py: self.py + other.py,
            yy: self.yy + other.yy,
            values: self.values + other.values,
        }
    }

    /// The least-squares gain in [0, 1] of the predicted change.
    fn gain(&self) -> f64 {
        match self.pp > 0.0 {
            true => (self.py / self.pp).clamp(0.0, 1.0),
            false => 0.0,
        }
    }

    /// Mean squared error of the change at [`Check::gain`]:
    /// `sum (g p - y)^2 = g^2 pp - 2 g py + yy`.
    fn loss(&self) -> f64 {
        let g = self.gain();
        (g * g * self.pp - 2.0 * g * self.py + self.yy).max(0.0) / self.values.max(1.0)
    }

    /// Mean squared error of doing nothing.
    fn loss_zero(&self) -> f64 {
        self.yy / self.values.max(1.0)
    }

    /// The check with the lowest loss (the earliest of equals).
    fn best(checks: &[Check]) -> Option<&Check> {
        checks
            .iter()
            .fold(None, |best: Option<&Check>, c| match best {
                Some(b) if b.loss() <= c.loss() => Some(b),
                _ => Some(c),
            })
    }
}

impl Debiaser {
    /// Joints of the skeleton the network was trained on.
    pub fn joints(&self) -> usize {
        self.meta.joints
    }

    /// Frame rate of the corrected clips it was trained on.
    pub fn fps(&self) -> f64 {
        self.meta.fps
    }

    pub fn report(&self) -> &TrainReport {
        &self.meta.report
    }

    /// Debias a corrected clip (same skeleton layout and frame rate as training).
    pub fn apply(&self, corrected: &Motion) -> Result<Motion> {
        Ok(self.apply_with_report(corrected)?.0)
    }

    /// [`Debiaser::apply`], and what restoring the contacts did.
    pub fn apply_with_report(&self, corrected: &Motion) -> Result<(Motion, ContactReport)> {
        if corrected.joints() != self.meta.joints {
            return Err(DebiasError::Data(format!(
                "the clip has {} joints, the model was trained on {}",
                corrected.joints(),
                self.meta.joints
            )));
        }
        let corrected = if (corrected.fps() - self.meta.fps).abs() > 1e-6 {
            motion::resample::resample(corrected, self.meta.fps)?
        } else {
            corrected.clone()
        };
        let sd = state_dim(self.meta.joints);
        let s = states(&corrected);
        let frames = s.len() / sd;
        let x = self.meta.input.apply(&inputs(&s, sd));
        let x = Tensor::from_vec(x, (frames, 2 * sd), &Device::Cpu)?;
        let delta = self.mlp.forward(&x)?.flatten_all()?.to_vec1::<f32>()?;
        let gain = self.meta.report.gain as f32;
        let delta = self.meta.output.invert(&delta);
        let sigma = self.meta.smoothing_s * self.meta.fps;
        let delta: Vec<f32> = low_pass(&delta, output_dim(self.meta.joints), &[frames], sigma)
            .iter()
            .map(|d| gain * d)
            .collect();
        let rotations = rotations_of(&s, self.meta.joints);
        let new: Vec<f32> = rotations.iter().zip(&delta).map(|(a, d)| a + d).collect();
        let debiased = apply_rotations(&corrected, &new)?;
        contacts::restore(
            &debiased,
            &corrected,
            &self.meta.contacts,
            self.meta.sole_height_m,
        )
    }

    /// Write `debias.safetensors` and `debias.json` into `dir` (created if missing).
    pub fn save(&self, dir: &Path) -> Result<()> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| DebiasError::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let meta = serde_json::to_vec_pretty(&self.meta).map_err(|e| DebiasError::Model {
            path: dir.join(META),
            message: e.to_string(),
        })?;
        let tmp = dir.join(format!("{WEIGHTS}.tmp"));
        self.params.save(&tmp)?;
        std::fs::rename(&tmp, dir.join(WEIGHTS)).map_err(io(&dir.join(WEIGHTS)))?;
        motion::io::write_atomic(&dir.join(META), &meta)?;
        Ok(())
    }

    /// Load a model written by [`Debiaser::save`].
    pub fn load(dir: &Path) -> Result<Debiaser> {
        let meta_path = dir.join(META);
        let bytes = std::fs::read(&meta_path).map_err(|source| DebiasError::Io {
            path: meta_path.clone(),
            source,
        })?;
        let meta: Meta = serde_json::from_slice(&bytes).map_err(|e| DebiasError::Model {
            path: meta_path.clone(),
            message: e.to_string(),
        })?;
        if meta.format != FORMAT {
            return Err(DebiasError::Model {
                path: meta_path,
                message: format!("format {} (this build reads {FORMAT})", meta.format),
            });
        }
        let params = Params::new(0);
        let mlp = model::build(&meta.mlp, &params).map_err(|e| DebiasError::Model {
            path: meta_path.clone(),
            message: e.to_string(),
        })?;
        let weights = dir.join(WEIGHTS);
        params.load(&weights).map_err(|e| DebiasError::Model {
            path: weights,
            message: e.to_string(),
        })?;
        Ok(Debiaser { meta, params, mlp })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::tests::walk;
    use motion::glam::DQuat;

    /// The joints the test bias bends: an upper arm and the upper back.
    fn bent_joints(m: &Motion) -> [usize; 2] {
        let s = m.skeleton();
        [
            s.find("lhumerus").expect("HDM05 lhumerus"),
            s.find("upperback").expect("HDM05 upperback"),
        ]
    }

    /// `m` with a systematic bias: the left upper arm turned by 0.3 rad and the
    /// upper back by 0.15 rad in every frame.
    fn biased(m: &Motion) -> Motion {
        let nj = m.joints();
        let [arm, back] = bent_joints(m);
        let mut rot = m.rotations().to_vec();
        for t in 0..m.frames() {
            rot[t * nj + arm] *= DQuat::from_rotation_x(0.3);
            rot[t * nj + back] *= DQuat::from_rotation_z(0.15);
        }
        m.with_frames(m.fps(), m.root_translation().to_vec(), rot)
            .expect("motion")
    }

    fn error(a: &Motion, b: &Motion) -> f64 {
        let mut e = 0.0;
        for t in 0..a.frames() {
            for j in bent_joints(a) {
                e += motion::rotation::angle_between(a.rotation(t, j), b.rotation(t, j));
            }
        }
        e / a.frames() as f64
    }

    fn tiny() -> TrainConfig {
        TrainConfig {
            hidden: vec![64, 64],
            iterations: 400,
            batch_size: 40,
            ..TrainConfig::default()
        }
    }

    #[test]
    fn learns_a_systematic_bias_and_removes_it() {
        let original = walk();
        let corrected = biased(&original);
        let (model, report) =
            train(&[(corrected.clone(), original.clone())], &tiny()).expect("train");
        assert!(report.loss_after < 0.1 * report.loss_before, "{report:?}");
        let before = error(&corrected, &original);
        let debiased = model.apply(&corrected).expect("apply");
        let after = error(&debiased, &original);
        assert!(after < 0.2 * before, "error {before} -> {after}");
        // The root path is the corrected clip's.
        assert_eq!(debiased.root_translation(), corrected.root_translation());
    }

    /// `m` with the left upper arm turned by a random angle in +-0.3 rad in
    /// every frame (a different draw per seed): no input predicts it.
    fn jittered(m: &Motion, seed: u64) -> Motion {
        use rand::Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let nj = m.joints();
        let [arm, _] = bent_joints(m);
        let mut rot = m.rotations().to_vec();
        for t in 0..m.frames() {
            rot[t * nj + arm] *= DQuat::from_rotation_x(rng.random_range(-0.3..0.3));
        }
        m.with_frames(m.fps(), m.root_translation().to_vec(), rot)
            .expect("motion")
    }

    fn held_out_config() -> TrainConfig {
        TrainConfig {
            validation_fraction: 0.4,
            ..tiny()
        }
    }

    /// Five pairs: an original with its own arm noise, and it biased.
    fn biased_jittered_pairs() -> Vec<(Motion, Motion)> {
        (0..5)
            .map(|i| {
                let original = jittered(&walk(), 100 + i);
                (biased(&original), original)
            })
            .collect()
    }

    #[test]
    fn a_bias_that_holds_on_held_out_pairs_is_applied_at_full_strength() {
        let pairs = biased_jittered_pairs();
        let (model, report) = train(&pairs, &held_out_config()).expect("train");
        assert_eq!(report.validation_pairs, 2);
        let (zero, after) = (
            report.validation_loss_zero.expect("held out"),
            report.validation_loss.expect("held out"),
        );
        assert!(after < 0.2 * zero, "{report:?}");
        assert!(report.gain > 0.8, "{report:?}");
        let (corrected, original) = &pairs[0];
        let after = error(&model.apply(corrected).expect("apply"), original);
        assert!(after < 0.3 * error(corrected, original), "{after}");
    }

    /// `m` with the upper back turned by `back` rad and the left upper arm
    /// by `arm` rad in every frame.
    fn styled(m: &Motion, back: f64, arm: f64) -> Motion {
        let nj = m.joints();
        let [arm_j, back_j] = bent_joints(m);
        let mut rot = m.rotations().to_vec();
        for t in 0..m.frames() {
            rot[t * nj + arm_j] *= DQuat::from_rotation_x(arm);
            rot[t * nj + back_j] *= DQuat::from_rotation_z(back);
        }
        m.with_frames(m.fps(), m.root_translation().to_vec(), rot)
            .expect("motion")
    }

    /// Three actors, three clips each. Each actor's back is turned its own way
    /// in both clips of a pair (the network can tell the actors apart), and
    /// its originals hold the arm its own way (+0.3, -0.3, +0.3 rad), which
    /// the corrected clips lost: a style per actor, not a bias of the
    /// simulation, so it carries over to new clips of an actor but not to a
    /// new actor.
    fn styled_pairs() -> (Vec<(Motion, Motion)>, Vec<String>) {
        let (mut pairs, mut actors) = (Vec::new(), Vec::new());
        for (k, (back, arm)) in [(0.0, 0.3), (0.2, -0.3), (0.4, 0.3)]
            .into_iter()
            .enumerate()
        {
            for c in 0..3 {
                let clip = jittered(&walk(), 500 + 10 * k as u64 + c);
                pairs.push((styled(&clip, back, 0.0), styled(&clip, back, arm)));
                actors.push(format!("actor{k}"));
            }
        }
        (pairs, actors)
    }

    #[test]
    fn holding_out_actors_drops_a_change_that_is_each_actors_own() {
        let (pairs, actors) = styled_pairs();
        let clips = TrainConfig {
            validation_fraction: 0.34,
            ..tiny()
        };
        let (_, by_clip) = train_with_actors(&pairs, &actors, &clips).expect("train");
        assert_eq!(by_clip.validation_actors, 0);
        assert!(by_clip.gain > 0.7, "clips held out: {by_clip:?}");
        let by_actor = TrainConfig {
            hold_out: HoldOut::Actors,
            ..clips
        };
        let (model, report) = train_with_actors(&pairs, &actors, &by_actor).expect("train");
        assert_eq!((report.validation_actors, report.validation_pairs), (3, 9));
        assert!(
            report.gain < 0.5 * by_clip.gain,
            "actors held out: {report:?}"
        );
        // Applied to a clip of a training actor it moves the arm less than
        // the actor's style would.
        let (corrected, original) = &pairs[0];
        let moved = error(&model.apply(corrected).expect("apply"), corrected);
        assert!(moved < 0.6 * error(corrected, original), "moved {moved}");
    }

    #[test]
    fn holding_out_actors_keeps_a_bias_every_actor_shares() {
        let pairs = biased_jittered_pairs();
        let actors: Vec<String> = ["bd", "bd", "bk", "bk", "dg"].map(String::from).into();
        let config = TrainConfig {
            hold_out: HoldOut::Actors,
            ..tiny()
        };
        let (model, report) = train_with_actors(&pairs, &actors, &config).expect("train");
        assert_eq!((report.validation_actors, report.validation_pairs), (3, 5));
        assert!(report.gain > 0.8, "{report:?}");
        let (corrected, original) = &pairs[0];
        let after = error(&model.apply(corrected).expect("apply"), original);
        assert!(after < 0.3 * error(corrected, original), "{after}");
    }

    #[test]
    fn holding_out_actors_needs_two_actors_and_one_per_pair() {
        let pairs = biased_jittered_pairs();
        let config = TrainConfig {
            hold_out: HoldOut::Actors,
            ..tiny()
        };
        let one: Vec<String> = vec!["bd".into(); 5];
        let err = train_with_actors(&pairs, &one, &config)
            .err()
            .expect("one actor");
        assert!(err.to_string().contains("two actors"), "{err}");
        let err = train(&pairs, &config).err().expect("no actors");
        assert!(err.to_string().contains("0 actors for 5 pairs"), "{err}");
    }

    #[test]
    fn started_from_the_mean_change_a_constant_bias_is_removed_before_any_training() {
        // A constant bias under noise no input predicts: the mean change is
        // the best a network can do, and where one started from the mean is.
        let clean = walk();
        let corrected = biased(&clean);
        let pairs: Vec<_> = (0..4)
            .map(|i| (corrected.clone(), jittered(&clean, 300 + i)))
            .collect();
        // One step: each network is (nearly) where it started.
        let one_step = |start_from_mean| TrainConfig {
            iterations: 1,
            validation_fraction: 0.0,
            start_from_mean,
            ..tiny()
        };
        let before = error(&corrected, &clean);
        let left = |start_from_mean| {
            let (model, _) = train(&pairs, &one_step(start_from_mean)).expect("train");
            error(&model.apply(&corrected).expect("apply"), &clean)
        };
        let (from_mean, random) = (left(true), left(false));
        assert!(from_mean < 0.3 * before, "{from_mean} of {before}");
        assert!(
            from_mean < 0.85 * random,
            "{from_mean} vs {random} from random weights"
        );
    }

    #[test]
    fn a_change_no_input_predicts_is_barely_applied() {
        // The corrected clip is always the same; the originals differ by
        // noise: the training pairs can be memorised, the held-out ones not.
        let corrected = walk();
        let pairs: Vec<_> = (0..5)
            .map(|i| (corrected.clone(), jittered(&corrected, 200 + i)))
            .collect();
        let (model, report) = train(&pairs, &held_out_config()).expect("train");
        // Nothing learnt holds on the held-out pairs: the weights before the
        // network memorised its pairs are kept.
        let zero = report.validation_loss_zero.expect("held out");
        let after = report.validation_loss.expect("held out");
        assert!(after <= zero && after > 0.9 * zero, "{report:?}");
        assert!(report.iterations < 100, "{report:?}");
        // Applied, it leaves the clip nearly as corrected.
        let moved = error(&model.apply(&corrected).expect("apply"), &corrected);
        assert!(
            moved < 0.05,
            "moved the arm and back by {moved} rad per frame"
        );
    }

    /// Mean frame-to-frame turn of the bent upper arm, rad.
    fn arm_jitter(m: &Motion) -> f64 {
        let [arm, _] = bent_joints(m);
        let turns: f64 = (1..m.frames())
            .map(|t| motion::rotation::angle_between(m.rotation(t, arm), m.rotation(t - 1, arm)))
            .sum();
        turns / (m.frames() - 1) as f64
    }

    #[test]
    fn the_low_pass_drops_memorised_jitter_and_keeps_the_bias() {
        // One pair, no held-out check: the network memorises the original's
        // per-frame noise on top of the constant bias.
        let clean = walk();
        let corrected = biased(&clean);
        let original = jittered(&clean, 400);
        let config = TrainConfig {
            iterations: 1500,
            validation_fraction: 0.0,
            smoothing_s: 0.0,
            ..tiny()
        };
        let (mut model, _) = train(&[(corrected.clone(), original)], &config).expect("train");
        let raw = model.apply(&corrected).expect("apply");
        model.meta.smoothing_s = 0.1;
        let smooth = model.apply(&corrected).expect("apply");
        let (base, raw_j, smooth_j) = (
            arm_jitter(&corrected),
            arm_jitter(&raw),
            arm_jitter(&smooth),
        );
        assert!(raw_j > base + 0.05, "memorised jitter {raw_j} vs {base}");
        assert!(
            smooth_j - base < 0.3 * (raw_j - base),
            "jitter left {smooth_j} (raw {raw_j}, corrected {base})"
        );
        // The constant bias is still removed.
        let before = error(&corrected, &clean);
        let after = error(&smooth, &clean);
        assert!(after < 0.5 * before, "error {before} -> {after}");
    }

    #[test]
    fn a_fixed_gain_replaces_the_held_out_one() {
        let pairs = biased_jittered_pairs();
        let (corrected, original) = &pairs[0];
        let before = error(corrected, original);
        let at = |gain| {
            let config = TrainConfig {
                gain: Some(gain),
                ..held_out_config()
            };
            let (model, report) = train(&pairs, &config).expect("train");
            assert_eq!(report.gain, gain);
            error(&model.apply(corrected).expect("apply"), original)
        };
        // Gain 0 leaves the bent joints as corrected; 1 removes most of it.
        assert!((at(0.0) - before).abs() < 1e-6 * before.max(1.0));
        assert!(at(1.0) < 0.3 * before);
        let bad = TrainConfig {
            gain: Some(1.5),
            ..tiny()
        };
        assert!(matches!(train(&pairs, &bad), Err(DebiasError::Config(_))));
    }

    #[test]
    fn held_out_pairs_are_whole_clips_and_never_all() {
        assert!(held_out(1, 0.2, 0).is_empty());
        assert!(held_out(5, 0.0, 0).is_empty());
        assert_eq!(held_out(2, 0.2, 0).len(), 1);
        assert_eq!(held_out(27, 0.2, 0).len(), 5);
        assert_eq!(held_out(3, 0.9, 0).len(), 2);
        let mut a = held_out(27, 0.2, 7);
        a.sort();
        a.dedup();
        assert_eq!(a.len(), 5);
        assert!(a.iter().all(|&i| i < 27));
        assert_eq!(held_out(27, 0.2, 7), held_out(27, 0.2, 7));
    }

    #[test]
    fn save_load_round_trip_gives_the_same_output() {
        let original = walk();
        let corrected = biased(&original);
        let config = TrainConfig {
            iterations: 5,
            ..tiny()
        };
        let (model, _) = train(&[(corrected.clone(), original)], &config).expect("train");
        let dir = tempfile::tempdir().expect("tempdir");
        model.save(dir.path()).expect("save");
        let loaded = Debiaser::load(dir.path()).expect("load");
        let (a, b) = (
            model.apply(&corrected).expect("apply"),
            loaded.apply(&corrected).expect("apply"),
        );
        assert_eq!(a.rotations(), b.rotations());
        assert_eq!(a.root_translation(), b.root_translation());
    }

    #[test]
    fn training_is_reproducible() {
        let original = walk();
        let corrected = biased(&original);
        let config = TrainConfig {
            iterations: 20,
            ..tiny()
        };
        let pairs = [(corrected.clone(), original)];
        let (a, _) = train(&pairs, &config).expect("train");
        let (b, _) = train(&pairs, &config).expect("train");
        let (a, b) = (
            a.apply(&corrected).expect("apply"),
            b.apply(&corrected).expect("apply"),
        );
        assert_eq!(a.rotations(), b.rotations());
    }

    #[test]
    fn refuses_bad_input() {
        let original = walk();
        assert!(matches!(train(&[], &tiny()), Err(DebiasError::Data(_))));
        let bad_configs = [
            TrainConfig {
                iterations: 0,
                ..tiny()
            },
            TrainConfig {
                smoothing_s: -0.1,
                ..tiny()
            },
            TrainConfig {
                smoothing_s: f64::NAN,
                ..tiny()
            },
            TrainConfig {
                validation_fraction: 1.0,
                ..tiny()
            },
        ];
        for bad in &bad_configs {
            assert!(matches!(
                train(&[(original.clone(), original.clone())], bad),
                Err(DebiasError::Config(_))
            ));
        }
        let dir = tempfile::tempdir().expect("tempdir");
        assert!(matches!(
            Debiaser::load(dir.path()),
            Err(DebiasError::Io { .. })
        ));
    }
}
