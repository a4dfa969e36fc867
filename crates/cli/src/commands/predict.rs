//! `motionaug predict train CLIPS... --model vdmgnn --out MODEL` and
//! `motionaug predict run MODEL CLIP --mask lower --out DIR`: a motion
//! prediction model a user can keep and look at.
//!
//! `run` writes the window's truth, what the model saw (occluded joints as the
//! mask's noise) and the prediction as BVH and NPZ, and `mask.json` (per
//! observed frame and joint: visible or not), so `motionaug view DIR` plays
//! them side by side. The model file (`eval::predict::trained`) records its
//! skeleton and refuses a clip of another.

use std::path::PathBuf;

use ::eval::predict::dmgnn::Reconstruction;
use ::eval::predict::occlusion::MaskKind;
use ::eval::predict::protocol::{GraphOptions, ModelKind, ModelSizes};
use ::eval::predict::train::TrainConfig;
use ::eval::predict::trained::TrainedPredictor;
use anyhow::Context;
use serde_json::json;

use crate::input::{ClipArgs, clip_name};
use crate::output::{print_stdout, write_json};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Train a prediction model on clips of one skeleton.
    Train(TrainArgs),
    /// Predict the future of one window of a clip (observed frames occluded by a mask).
    Run(RunArgs),
}

#[derive(clap::Args)]
struct TrainArgs {
    /// Training clips (BVH, AMC with --skeleton, or NPZ), one skeleton.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// seq2seq, gcn, dmgnn or vdmgnn (V-DMGNN-GAN).
    #[arg(long, default_value = "vdmgnn")]
    model: ModelKind,
    /// Model folder to write (model.json + weights.safetensors).
    #[arg(long)]
    out: PathBuf,
    /// Occlusion of the observed frames in training: none, lower or random.
    #[arg(long, default_value = "none")]
    mask: MaskKind,
    #[arg(long, default_value_t = 1000)]
    iterations: usize,
    #[arg(long, default_value_t = 32)]
    batch_size: usize,
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    /// dmgnn / vdmgnn reconstruction loss: l1 or l2.
    #[arg(long, default_value = "l1")]
    loss: Reconstruction,
    /// vdmgnn: encode velocities and accelerations too.
    #[arg(long)]
    vel_acc: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(clap::Args)]
struct RunArgs {
    /// Model folder written by `predict train`.
    model: PathBuf,
    /// The clip to predict (its skeleton must be the model's).
    clip_file: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Occlusion of the observed frames: none, lower or random.
    #[arg(long, default_value = "none")]
    mask: MaskKind,
    /// First observed frame, at the model's frame rate (default 0).
    #[arg(long)]
    start: Option<usize>,
    /// Seed of the random mask and the masks' noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output folder (created if missing).
    #[arg(long)]
    out: PathBuf,
}

fn train(args: TrainArgs) -> anyhow::Result<()> {
    let clips = args
        .inputs
        .iter()
        .map(|p| Ok((clip_name(p), args.clip.load(p)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let config = TrainConfig {
        iterations: args.iterations,
        batch_size: args.batch_size,
        lr: args.lr,
        ..TrainConfig::default()
    };
    let every = (args.iterations / 10).max(1);
    let trained = TrainedPredictor::train(
        &clips,
        args.model,
        ModelSizes::default(),
        GraphOptions {
            loss: args.loss,
            vel_acc: args.vel_acc,
        },
        args.mask,
        config,
        args.seed,
        |it, loss| {
            if it % every == 0 || it == args.iterations {
                eprintln!("iteration {it}/{}: loss {loss:.4}", args.iterations);
            }
        },
    )?;
    trained
        .save(&args.out)
        .with_context(|| format!("cannot write the model to {}", args.out.display()))?;
    let f = &trained.file;
    print_stdout(&format!(
        "{}: {} windows of {} clips, loss {:.4} -> {:.4} in {:.1} s; wrote {}\n",
        f.model,
        f.windows,
        f.clips.len(),
        f.first_loss,
        f.last_loss,
        f.train_seconds,
        args.out.display()
    ))
}

fn run_one(args: RunArgs) -> anyhow::Result<()> {
    let trained = TrainedPredictor::load(&args.model)
        .with_context(|| format!("cannot load the model {}", args.model.display()))?;
    let clip = args.clip.load(&args.clip_file)?;
    let p = trained
        .predict_clip(&clip, args.start, args.mask, args.seed)
        .with_context(|| format!("cannot predict {}", args.clip_file.display()))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for (name, m) in [
        ("truth", &p.truth),
        ("seen", &p.seen),
        ("predicted", &p.predicted),
    ] {
        for ext in ["bvh", "npz"] {
            motion::io::save(m, args.out.join(format!("{name}.{ext}")))?;
        }
    }
    let f = &trained.file;
    write_json(
        &args.out.join("mask.json"),
        &json!({
            "mask": args.mask,
            "start": p.start,
            "fps": f.fps,
            "observed_frames": f.input_frames,
            "predicted_frames": f.output_frames,
            "joints": f.graph.names,
            "visible": p.visible,
        }),
    )?;
    print_stdout(&format!(
        "wrote truth, seen and predicted (.bvh, .npz) and mask.json to {}: frames {}..{} observed, {} predicted by {}\n",
        args.out.display(),
        p.start,
        p.start + f.input_frames,
        f.output_frames,
        f.model
    ))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Train(a) => train(a),
        Command::Run(a) => run_one(a),
    }
}
