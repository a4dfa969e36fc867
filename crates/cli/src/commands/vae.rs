//! `motionaug vae train CLIPS... --out MODEL_DIR`,
//! `motionaug vae sample MODEL_DIR --count N --out DIR` and
//! `motionaug vae reconstruct MODEL_DIR CLIPS... --out DIR`: the MotionAug motion VAE.
//!
//! Train one model per action class (all clips of one actor's class, so that they
//! share a skeleton; samples use the first clip's skeleton). Sampling writes one
//! BVH + NPZ per sample and a `manifest.json`.

use std::path::PathBuf;

use ::vae::{OptimizerConfig, Prior, TrainConfig, TrainedVae};
use anyhow::{Context, bail};
use serde::Serialize;

use crate::input::{ClipArgs, clip_name};
use crate::output::{write_atomic, write_json};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Train a VAE on the clips of one action class.
    Train(TrainArgs),
    /// Generate clips from a trained VAE.
    Sample(SampleArgs),
    /// Encode clips and decode their posterior means: what the model makes of
    /// clips it knows (e.g. to correct them beside the originals and samples).
    Reconstruct(ReconstructArgs),
}

#[derive(clap::Args)]
struct ReconstructArgs {
    /// Model directory written by `vae train`.
    model: PathBuf,
    /// Clips to reconstruct (BVH, AMC with --skeleton, or NPZ).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// Output directory (created if missing): `<clip>_recon.bvh` / `.npz`.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    finish: FinishArgs,
}

/// What is done to each decoded clip (`vae::Finish`); the defaults are what
/// the pipeline does.
#[derive(clap::Args)]
struct FinishArgs {
    /// Low-pass each decoded clip (`motion::smooth::gaussian`, this standard
    /// deviation in seconds; 0 = as decoded) before its root is planted:
    /// decoded clips jitter.
    #[arg(long, default_value_t = vae::trained::DEFAULT_SMOOTH_S)]
    smooth_s: f64,
    /// Keep each root path as decoded instead of re-integrating it from the
    /// planted feet.
    #[arg(long)]
    no_plant: bool,
}

impl FinishArgs {
    fn finish(&self) -> anyhow::Result<vae::Finish> {
        if !(self.smooth_s.is_finite() && self.smooth_s >= 0.0) {
            bail!("--smooth-s must be a finite number of seconds >= 0");
        }
        Ok(vae::Finish::new(self.smooth_s, !self.no_plant))
    }
}

#[derive(clap::Args)]
struct TrainArgs {
    /// Training clips (BVH, AMC with --skeleton, or NPZ), one action class.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// Model directory to write (weights.safetensors + model.json).
    #[arg(long)]
    out: PathBuf,
    /// Passes over the training clips (one pass = ceil(clips / batch) iterations).
    #[arg(long, conflicts_with = "iterations")]
    epochs: Option<u64>,
    /// Optimiser steps (default 1500; 20000 with --reference).
    #[arg(long)]
    iterations: Option<u64>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Train without the frame and sequence discriminators (ablation; lower
    /// MMD on kick, jog and sneak, crates/vae/README.md).
    #[arg(long)]
    no_adversarial: bool,
    /// Train without the foot terms (foot position / velocity, skating of
    /// mixed codes, floor; an ablation).
    #[arg(long)]
    no_foot_terms: bool,
    /// The paper's sizes and optimiser (SGD lr 0.005 halved every 4000 of 20000
    /// iterations); slow on a CPU.
    #[arg(long)]
    reference: bool,
    /// Learning rate (Adam by default, SGD with --reference).
    #[arg(long)]
    lr: Option<f64>,
    /// Weight of the generator's adversarial (hinge) terms.
    #[arg(long)]
    adversarial_weight: Option<f64>,
    /// Weight of the adversarial terms on clips decoded from codes mixed
    /// between two training clips (what near sampling decodes).
    #[arg(long)]
    mixed_adversarial_weight: Option<f64>,
    /// Weight of the term asking mixed-code decodes to move as fast as the two
    /// clips they were drawn between (pose speed).
    #[arg(long)]
    mixed_motion_weight: Option<f64>,
    /// Weight of the term asking mixed-code decodes to stand on the ground
    /// in as many frames as the two clips they were drawn between (needs the
    /// foot terms).
    #[arg(long)]
    mixed_contact_weight: Option<f64>,
    /// Weight of the term asking the planted feet of mixed-code decodes to
    /// stand on their soles: the ankle-to-toe drop of a low, slow foot held
    /// to the training clips' stance drop (needs the foot terms).
    #[arg(long)]
    mixed_sole_weight: Option<f64>,
    /// Weight of the term asking mixed-code decodes to travel like the two
    /// clips they were drawn between (root speed in each quarter of the clip).
    #[arg(long)]
    mixed_travel_weight: Option<f64>,
    /// Weight of the term asking mixed-code decodes to keep their zero moment
    /// point no further outside their soles than the two clips they were
    /// drawn between (the simulated character's masses and feet, as
    /// `motionaug metrics --balance` measures).
    #[arg(long)]
    mixed_balance_weight: Option<f64>,
    /// Weight of the foot terms' skating of mixed-code decodes (planted feet
    /// that slide; `vae::FootLoss::skating`).
    #[arg(long)]
    skating_weight: Option<f64>,
    /// Train on the clips as captured instead of moving each onto one floor
    /// (its lowest body point at 5 mm in a tenth of its frames; actors of
    /// one dataset stand centimetres apart, and the samples' feet hover).
    #[arg(long)]
    captured_floors: bool,
    /// Print losses every N iterations (0: only the summary).
    #[arg(long, default_value_t = 100)]
    log_every: u64,
}

#[derive(clap::Args)]
struct SampleArgs {
    /// Model directory written by `vae train`.
    model: PathBuf,
    #[arg(long)]
    count: usize,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Latent codes from `near` (sampling near samples) or `normal` (N(0, I)).
    #[arg(long, default_value = "near")]
    prior: Prior,
    /// Near codes are drawn between this many training clips of a cluster
    /// (default: the model's, the paper's 2; 1 samples near single clips).
    #[arg(long)]
    members: Option<usize>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    finish: FinishArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Train(a) => train(a),
        Command::Sample(a) => sample(a),
        Command::Reconstruct(a) => reconstruct(a),
    }
}

fn reconstruct(args: ReconstructArgs) -> anyhow::Result<()> {
    let model = TrainedVae::load(&args.model)
        .with_context(|| format!("cannot load the model in {}", args.model.display()))?;
    let clips = args
        .inputs
        .iter()
        .map(|p| args.clip.load(p))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let finish = args.finish.finish()?;
    let recon = model.reconstruct(&clips)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for (path, m) in args.inputs.iter().zip(recon) {
        let m = finish.apply(&m)?;
        let name = format!("{}_recon", clip_name(path));
        write_atomic(
            &args.out.join(format!("{name}.bvh")),
            &motion::bvh::to_bytes(&m),
        )?;
        let bytes = motion::npz::motion_to_bytes(&m, &[])
            .with_context(|| format!("cannot encode {name}.npz"))?;
        write_atomic(&args.out.join(format!("{name}.npz")), &bytes)?;
    }
    eprintln!(
        "wrote {} reconstructions to {}",
        args.inputs.len(),
        args.out.display()
    );
    Ok(())
}

fn train(args: TrainArgs) -> anyhow::Result<()> {
    let clips = args
        .inputs
        .iter()
        .map(|p| args.clip.load(p))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut config = if args.reference {
        TrainConfig::reference()
    } else {
        TrainConfig::default()
    };
    config.seed = args.seed;
    config.adversarial = !args.no_adversarial;
    if args.no_foot_terms {
        config.feet = ::vae::FootLoss::off();
    }
    if args.captured_floors {
        config.features.floor = None;
    }
    if let Some(lr) = args.lr {
        config.optimizer = match config.optimizer {
            OptimizerConfig::Sgd { halve_every, .. } => OptimizerConfig::Sgd { lr, halve_every },
            OptimizerConfig::Adam { .. } => OptimizerConfig::Adam { lr },
        };
    }
    if let Some(w) = args.adversarial_weight {
        config.weights.adversarial = w;
    }
    if let Some(w) = args.mixed_adversarial_weight {
        config.weights.mixed_adversarial = w;
    }
    if let Some(w) = args.mixed_motion_weight {
        config.weights.mixed_motion = w;
    }
    if let Some(w) = args.mixed_contact_weight {
        config.weights.mixed_contact = w;
    }
    if let Some(w) = args.mixed_sole_weight {
        config.weights.mixed_sole = w;
    }
    if let Some(w) = args.mixed_travel_weight {
        config.weights.mixed_travel = w;
    }
    if let Some(w) = args.mixed_balance_weight {
        config.weights.mixed_balance = w;
    }
    pipeline::add_vae_balance_model(&mut config, &clips)?;
    if let Some(w) = args.skating_weight {
        config.feet.skating = w;
    }
    if let Some(n) = args.iterations {
        config.iterations = n;
    }
    if let Some(epochs) = args.epochs {
        let per_epoch = clips.len().div_ceil(config.batch_size) as u64;
        config.iterations = epochs.saturating_mul(per_epoch);
    }
    if config.iterations == 0 {
        bail!("--iterations/--epochs must be at least 1");
    }
    eprintln!(
        "training on {} clips ({} joints), {} iterations, adversarial {}, foot terms {}",
        clips.len(),
        clips[0].joints(),
        config.iterations,
        config.adversarial,
        !config.feet.is_off()
    );
    let log_every = args.log_every;
    let model = ::vae::train(&clips, &config, |p| {
        if log_every > 0 && (p.iteration % log_every == 0 || p.iteration == 1) {
            let l = p.losses;
            eprintln!(
                "iter {:>6}/{} lr {:.2e} total {:.4} root {:.5} rot {:.5} smooth {:.5} kl {:.4} adv {:.3} disc {:.3} feet {:.4} vel {:.3} skate {:.3} floor {:.5} mixed adv {:.3} motion {:.3} contact {:.4} sole {:.4} travel {:.4} balance {:.4}",
                p.iteration, p.iterations, p.lr, l.total, l.root, l.rotation, l.smooth, l.kl,
                l.adversarial, l.discriminator, l.foot_position, l.foot_velocity, l.skating, l.floor,
                l.mixed_adversarial, l.mixed_motion, l.mixed_contact, l.mixed_sole, l.mixed_travel, l.mixed_balance
            );
        }
    })
    .context("training failed")?;
    model
        .save(&args.out)
        .with_context(|| format!("cannot save the model to {}", args.out.display()))?;
    let err = model.reconstruction_error(&clips)?;
    eprintln!(
        "trained in {:.1} s; reconstruction on the training clips: root RMSE {:.3} m, mean joint angle {:.3} rad; saved {}",
        model.meta().training.seconds,
        err.root_rmse_m,
        err.mean_joint_angle_rad,
        args.out.display()
    );
    Ok(())
}

#[derive(Serialize)]
struct ManifestEntry {
    name: String,
    bvh: String,
    npz: String,
    frames: usize,
    fps: f64,
    prior: Prior,
    seed: u64,
    index: usize,
    model: String,
}

fn sample(args: SampleArgs) -> anyhow::Result<()> {
    if args.count == 0 {
        bail!("--count must be at least 1");
    }
    let mut model = TrainedVae::load(&args.model)
        .with_context(|| format!("cannot load the model in {}", args.model.display()))?;
    if let Some(members) = args.members {
        model = model.with_near_members(members)?;
    }
    let finish = args.finish.finish()?;
    let samples = model.sample_finished(args.count, args.prior, args.seed, &finish)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let model_name = clip_name(&args.model);
    let prior = match args.prior {
        Prior::Near => "near",
        Prior::Normal => "normal",
    };
    let mut manifest = Vec::with_capacity(samples.len());
    for (i, s) in samples.iter().enumerate() {
        let name = format!("{model_name}_vae_{prior}_{i:04}");
        let bvh = format!("{name}.bvh");
        let npz = format!("{name}.npz");
        write_atomic(&args.out.join(&bvh), &motion::bvh::to_bytes(&s.motion))?;
        let z = motion::npz::NpyArray::f32("z", &[s.z.len()], &s.z)?;
        let bytes = motion::npz::motion_to_bytes(&s.motion, &[z])
            .with_context(|| format!("cannot encode {npz}"))?;
        write_atomic(&args.out.join(&npz), &bytes)?;
        manifest.push(ManifestEntry {
            name,
            bvh,
            npz,
            frames: s.motion.frames(),
            fps: s.motion.fps(),
            prior: s.prior,
            seed: args.seed,
            index: i,
            model: args.model.display().to_string(),
        });
    }
    write_json(&args.out.join("manifest.json"), &manifest)?;
    eprintln!(
        "wrote {} samples ({prior} prior) to {}",
        manifest.len(),
        args.out.display()
    );
    Ok(())
}
