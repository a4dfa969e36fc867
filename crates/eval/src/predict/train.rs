//! Training a [`Predictor`]: the `nn` crate's optimiser (AdamW after global
//! gradient-norm clipping), batches of windows drawn uniformly with a seeded
//! ChaCha RNG, a fixed number of iterations (so a model trained with augmented
//! clips gets the same budget as one without).

use std::time::Instant;

use nn::{AdamConfig, Optimizer};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::predict::Predictor;
use crate::predict::data::{ClipSet, Normalizer, batch};

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

/// Trains `model` on the windows of `set`; `progress(iteration, loss)` after each step.
pub fn train(
    model: &dyn Predictor,
    set: &ClipSet,
    norm: &Normalizer,
    config: &TrainConfig,
    seed: u64,
    mut progress: impl FnMut(usize, f64),
) -> Result<TrainReport> {
    if set.windows.is_empty() {
        return Err(EvalError::Data(
            "no training windows (every clip is shorter than a window)".into(),
        ));
    }
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
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_ba7c);
    let tenth = (config.iterations / 10).max(1);
    let (mut first, mut last) = (0.0, 0.0);
    for it in 0..config.iterations {
        let picks: Vec<(usize, usize)> = (0..config.batch_size)
            .map(|_| set.windows[rng.random_range(0..set.windows.len())])
            .collect();
        let (input, target) = batch(set, norm, &picks)?;
        let loss = model.loss(&input, &target)?;
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
