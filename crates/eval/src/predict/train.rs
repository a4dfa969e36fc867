//! Training a [`Predictor`]: the `nn` crate's optimiser (AdamW after global
//! gradient-norm clipping), batches of windows drawn uniformly with a seeded
//! ChaCha RNG, a fixed number of iterations (so a model trained with augmented
//! clips gets the same budget as one without).
//!
//! With an [`Occluder`] the observed frames of every batch are masked afresh
//! (the targets never are). A model with an [`Adversarial`] half steps its
//! discriminator (its own Adam, learning rate and parameter clipping) before
//! each generator step, on the same batch (the reference code alternates
//! iterations: the same one-to-one ratio); the loss reported is the generator's.

use std::time::Instant;

use nn::{AdamConfig, Optimizer};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::predict::data::{ClipSet, Normalizer, batch};
use crate::predict::occlusion::Occluder;
use crate::predict::{Adversarial, Predictor};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub iterations: usize,
    pub batch_size: usize,
    pub lr: f64,
    pub weight_decay: f64,
    /// Global gradient-norm clip (Martinez et al.: 5).
    pub max_grad_norm: f64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            iterations: 1000,
            batch_size: 32,
            lr: 1e-3,
            weight_decay: 0.0,
            max_grad_norm: 5.0,
        }
    }
}

/// What a training run did.
#[derive(Debug, Clone, Serialize)]
pub struct TrainReport {
    /// Mean loss of the first and the last tenth of the iterations.
    pub first_loss: f64,
    pub last_loss: f64,
    pub seconds: f64,
}

/// Trains `model` on the windows of `set` (their observed frames masked by
/// `occluder`); `progress(iteration, loss)` after each step.
pub fn train(
    model: &dyn Predictor,
    set: &ClipSet,
    norm: &Normalizer,
    config: &TrainConfig,
    seed: u64,
    occluder: Option<&Occluder>,
    progress: impl FnMut(usize, f64),
) -> Result<TrainReport> {
    if set.windows.is_empty() {
        return Err(EvalError::Data(
            "no training windows (every clip is shorter than a window)".into(),
        ));
    }
    let windows = &set.windows;
    train_batches(
        model,
        config,
        seed,
        occluder,
        |rng| {
            let picks: Vec<(usize, usize)> = (0..config.batch_size)
                .map(|_| windows[rng.random_range(0..windows.len())])
                .collect();
            batch(set, norm, &picks)
        },
        progress,
    )
}

/// The loop itself, over batches `(input, target)` drawn by `next_batch`;
/// `occluder` masks the inputs. Shared by the HDM05 protocol and the CMU
/// (DMGNN preprocessing) protocol, whose batches come from another data set.
pub fn train_batches(
    model: &dyn Predictor,
    config: &TrainConfig,
    seed: u64,
    occluder: Option<&Occluder>,
    mut next_batch: impl FnMut(&mut ChaCha8Rng) -> Result<(candle_core::Tensor, candle_core::Tensor)>,
    mut progress: impl FnMut(usize, f64),
) -> Result<TrainReport> {
    if config.iterations == 0 || config.batch_size == 0 {
        return Err(EvalError::Config(
            "iterations and batch size must be at least 1".into(),
        ));
    }
    let span = tracing::info_span!("train_predictor", iterations = config.iterations, seed);
    let _guard = span.enter();
    let start = Instant::now();
    let mut opt = Optimizer::new(
        model.params().vars(),
        AdamConfig {
            weight_decay: config.weight_decay,
            ..AdamConfig::new(config.lr)
        },
        Some(config.max_grad_norm as f32),
    );
    let adversary = model.adversarial();
    let mut disc = adversary.map(|a| {
        Optimizer::new(
            a.discriminator_params().vars(),
            AdamConfig {
                weight_decay: config.weight_decay,
                ..AdamConfig::new(a.discriminator_lr())
            },
            Some(config.max_grad_norm as f32),
        )
    });
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_ba7c);
    let tenth = (config.iterations / 10).max(1);
    let (mut first, mut last) = (0.0, 0.0);
    for it in 0..config.iterations {
        let (input, target) = next_batch(&mut rng)?;
        let masked = match occluder {
            Some(o) => o.apply(&input, &mut rng)?,
            None => input.clone(),
        };
        if let (Some(a), Some(d_opt)) = (adversary, disc.as_mut()) {
            discriminator_step(a, d_opt, &input, &masked, &target)?;
        }
        let loss = match adversary {
            Some(a) => a.generator_loss(&input, &masked, &target)?,
            None => model.loss(&masked, &target)?,
        };
        let value = loss.to_scalar::<f32>()? as f64;
        if !value.is_finite() {
            return Err(EvalError::Data(format!(
                "training diverged at iteration {it} (loss {value})"
            )));
        }
        opt.step(&loss.backward()?)?;
        if it < tenth {
            first += value / tenth as f64;
        }
        if it >= config.iterations - tenth {
            last += value / tenth as f64;
        }
        progress(it + 1, value);
    }
    Ok(TrainReport {
        first_loss: first,
        last_loss: last,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// One discriminator step, then every discriminator parameter clamped.
fn discriminator_step(
    a: &dyn Adversarial,
    opt: &mut Optimizer,
    clean: &candle_core::Tensor,
    masked: &candle_core::Tensor,
    target: &candle_core::Tensor,
) -> Result<()> {
    let loss = a.discriminator_loss(clean, masked, target)?;
    opt.step(&loss.backward()?)?;
    let c = a.clip();
    for (_, v) in a.discriminator_params().vars() {
        let clamped = v.as_tensor().clamp(-c, c)?;
        v.set(&clamped)?;
    }
    Ok(())
}
