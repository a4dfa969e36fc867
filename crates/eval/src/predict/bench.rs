//! Training cost of a prediction model: wall time per optimiser iteration and
//! windows per second of the real training loop ([`train_batches`], with the
//! discriminator step of V-DMGNN-GAN and the masking), on random batches of a
//! given shape. `motionaug bench predictor` prints it; no timed unit tests.

use std::time::Instant;

use candle_core::{Device, Tensor};
use serde::Serialize;

use crate::error::Result;
use crate::predict::body_graph::BodyGraph;
use crate::predict::occlusion::{MaskKind, Occluder};
use crate::predict::protocol::{GraphOptions, ModelKind, ModelSizes, build_graph_model};
use crate::predict::train::{TrainConfig, train_batches};

#[derive(Debug, Clone, Serialize)]
pub struct PredictorBench {
    pub model: ModelKind,
    pub parameters: usize,
    pub input_frames: usize,
    pub output_frames: usize,
    pub nodes: usize,
    pub batch_size: usize,
    pub iterations: usize,
    pub seconds_per_iteration: f64,
    pub windows_per_second: f64,
    /// candle's matrix-product threads (RAYON_NUM_THREADS, else the cores).
    pub threads: usize,
}

/// Times `iterations` training steps (after one warm-up step).
#[allow(clippy::too_many_arguments)]
pub fn bench_predictor(
    model: ModelKind,
    sizes: &ModelSizes,
    options: &GraphOptions,
    graph: &BodyGraph,
    input_frames: usize,
    output_frames: usize,
    batch_size: usize,
    iterations: usize,
    mask: MaskKind,
) -> Result<PredictorBench> {
    let m = build_graph_model(model, sizes, options, graph, input_frames, 0)?;
    let d = 3 * graph.nodes();
    let occluder = Occluder::new(mask, graph)?;
    let batch = |_: &mut rand_chacha::ChaCha8Rng| {
        Ok((
            Tensor::randn(0f32, 1.0, (batch_size, input_frames, d), &Device::Cpu)?,
            Tensor::randn(0f32, 1.0, (batch_size, output_frames, d), &Device::Cpu)?,
        ))
    };
    let config = TrainConfig {
        iterations: 1,
        batch_size,
        ..TrainConfig::default()
    };
    train_batches(m.as_ref(), &config, 0, Some(&occluder), batch, |_, _| {})?;
    let start = Instant::now();
    let config = TrainConfig {
        iterations: iterations.max(1),
        ..config
    };
    train_batches(m.as_ref(), &config, 1, Some(&occluder), batch, |_, _| {})?;
    let s = start.elapsed().as_secs_f64() / config.iterations as f64;
    Ok(PredictorBench {
        model,
        parameters: m.params().count()
            + m.adversarial()
                .map_or(0, |a| a.discriminator_params().count()),
        input_frames,
        output_frames,
        nodes: graph.nodes(),
        batch_size,
        iterations: config.iterations,
        seconds_per_iteration: s,
        windows_per_second: batch_size as f64 / s,
        threads: candle_core::utils::get_num_threads(),
    })
}
