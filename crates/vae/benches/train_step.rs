//! Training-step time of the VAE on HDM05 kick clips (actor bd, 30 fps), default
//! and reference sizes, with and without the adversarial terms; and one LSTM
//! direction, forward + backward: the recurrence op against the same on candle's
//! graph ops and the per-step (naive) version.
//!
//! `CARGO_TARGET_DIR=... cargo bench -p vae --bench train_step`
//! (`-- quick` runs fewer steps).

use std::path::PathBuf;
use std::time::Instant;

use candle_core::{DType, Device, Tensor};
use nn::Params;
use vae::lstm::{Direction, Lstm};
use vae::{OptimizerConfig, TrainConfig, Trainer, VaeConfig};

fn kick_clips() -> Vec<motion::Motion> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/hdm05");
    let options = motion::LoadOptions {
        skeleton: Some(dir.join("HDM_bd.asf")),
        ..Default::default()
    };
    (1..=6)
        .map(|i| {
            let p = dir.join(format!("HDM_bd_kickLFront1Reps_{i:03}_120.amc"));
            motion::load(&p, &options).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        })
        .collect()
}

fn time_steps(name: &str, clips: &[motion::Motion], config: &TrainConfig, steps: usize) {
    let mut trainer = Trainer::new(clips, config).expect("trainer");
    trainer.step().expect("warm-up step");
    let start = Instant::now();
    for _ in 0..steps {
        trainer.step().expect("step");
    }
    let ms = start.elapsed().as_secs_f64() * 1e3 / steps as f64;
    println!(
        "{name:<36} params {:>9}  {ms:8.1} ms/step",
        trainer.vae.params.count()
    );
}

/// Forward + backward of one LSTM direction: the recurrence op
/// (`Lstm::forward`), the same on candle's graph ops (`forward_graph`) and
/// the per-step projection (`forward_naive`), interleaved in 3 rounds.
fn time_lstm(b: usize, t: usize, i: usize, h: usize, reps: usize) {
    let p = Params::new(1);
    let lstm = Lstm::new(&p, "l", i, h).expect("lstm");
    let x = p.uniform("x", &[b, t, i], 1.0).expect("x");
    let mask = Tensor::ones((b, t), DType::F32, &Device::Cpu).expect("mask");
    let run = |version: usize| {
        let start = Instant::now();
        for _ in 0..reps {
            let y = match version {
                0 => lstm.forward(&x, &mask, Direction::Backward),
                1 => lstm.forward_graph(&x, &mask, Direction::Backward),
                _ => lstm.forward_naive(&x, &mask, Direction::Backward),
            }
            .expect("forward");
            y.sqr()
                .and_then(|y| y.sum_all())
                .and_then(|l| l.backward())
                .expect("backward");
        }
        start.elapsed().as_secs_f64() * 1e3 / reps as f64
    };
    let mut ms = [0.0f64; 3];
    for _ in 0..3 {
        for (v, m) in ms.iter_mut().enumerate() {
            *m += run(v) / 3.0;
        }
    }
    let [op, graph, naive] = ms;
    println!(
        "LSTM B{b} T{t} I{i} H{h} fwd+bwd: op {op:7.2} ms, graph {graph:7.2} ms ({:.2}x), naive {naive:7.2} ms ({:.2}x)",
        graph / op,
        naive / op
    );
}

fn main() {
    nn::threads::init(); // candle on one thread, as the CLI runs it
    let quick = std::env::args().any(|a| a == "quick");
    let steps = if quick { 3 } else { 10 };
    let lstm_only = std::env::args().any(|a| a == "lstm");
    if lstm_only {
        let (d, r) = (VaeConfig::default(), VaeConfig::reference());
        time_lstm(6, 59, d.dec_input, d.dec_hidden, steps * 2);
        time_lstm(23, 120, d.dec_input, d.dec_hidden, steps);
        time_lstm(6, 59, r.dec_input, r.dec_hidden, steps);
        return;
    }
    let clips = kick_clips();
    let frames: Vec<usize> = clips
        .iter()
        .map(|c| (c.frames() as f64 * 30.0 / c.fps()).round() as usize)
        .collect();
    println!("6 kick clips (bd), frames at 30 fps: {frames:?}");
    let mut default = TrainConfig::default();
    time_steps("default sizes, adversarial", &clips, &default, steps);
    default.adversarial = false;
    time_steps("default sizes, no adversarial", &clips, &default, steps);
    let mut reference = TrainConfig::reference();
    time_steps(
        "reference sizes, adversarial, SGD",
        &clips,
        &reference,
        steps.min(5),
    );
    reference.adversarial = false;
    reference.optimizer = OptimizerConfig::Adam { lr: 1e-3 };
    time_steps(
        "reference sizes, no adversarial",
        &clips,
        &reference,
        steps.min(5),
    );
    let d = VaeConfig::default();
    let r = VaeConfig::reference();
    time_lstm(6, 59, d.dec_input, d.dec_hidden, steps * 2);
    time_lstm(6, 59, r.dec_input, r.dec_hidden, steps);
    time_lstm(6, 59, 189, r.seq_disc_hidden, steps);
}
