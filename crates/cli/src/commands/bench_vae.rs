//! `motionaug bench vae --data DIR --classes a,b --test-actor bd`: what a VAE
//! training costs and what its samples are worth, per class and loss variant.
//!
//! For each class the clips of every actor but the test actor train one VAE per
//! variant (`full`: adversarial + foot terms, `no_adv`, `no_feet`, `plain`).
//! Printed per variant: the training curve (losses and wall time every
//! `--log-every` iterations, also written to `OUT/<class>_<variant>.curve.json`;
//! the model goes to `OUT/<class>_<variant>.model`),
//! the seconds until the reconstruction loss first came within 10 % of its final
//! value, the foot skating, penetration and floating of the training clips, of
//! their reconstructions and of near samples (as decoded, and root-planted as
//! `TrainedVae::sample` returns them), and the MMD of the samples to the
//! test actor's clips (`eval::mmd`). Why a bench and not a test: these are
//! figures to compare side by side in one run, not pass/fail facts.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use eval::scores::SetPlausibility;
use motion::Motion;
use serde::Serialize;

use crate::output::{print_stdout, write_json};

#[derive(clap::Args)]
pub struct Args {
    /// Folder of HDM05 clips (`HDM_<actor>_<class>_<nnn>_120.amc` + `HDM_<actor>.asf`).
    #[arg(long)]
    data: PathBuf,
    /// Classes (parts of class names).
    #[arg(long, value_delimiter = ',', required = true)]
    classes: Vec<String>,
    /// Actor whose clips are held out (the MMD reference).
    #[arg(long, default_value = "bd")]
    test_actor: String,
    /// Loss variants: full, no_adv, no_feet, plain.
    #[arg(long, value_delimiter = ',', default_value = "full,no_feet")]
    variants: Vec<Variant>,
    #[arg(long, default_value_t = 1500)]
    iterations: u64,
    /// Near samples per training clip.
    #[arg(long, default_value_t = 2)]
    samples_per_clip: usize,
    #[arg(long, default_value_t = 100)]
    log_every: u64,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Adam learning rate (default: the training default).
    #[arg(long)]
    lr: Option<f64>,
    /// Weight of the smoothness term (default: the training default).
    #[arg(long)]
    smooth: Option<f64>,
    /// Weight of the KL term (default: the training default).
    #[arg(long)]
    kl: Option<f64>,
    /// The paper's network sizes (`VaeConfig::reference`) with this bench's
    /// optimiser and iterations.
    #[arg(long)]
    reference_sizes: bool,
    /// Weight of the foot position term (variants with foot terms).
    #[arg(long)]
    foot_position: Option<f64>,
    /// Weight of the foot velocity term (variants with foot terms).
    #[arg(long)]
    foot_velocity: Option<f64>,
    /// Weight of the mixed-code skating term (variants with foot terms).
    #[arg(long)]
    skating: Option<f64>,
    /// Weight of the adversarial terms on mixed-code decodes (variants with
    /// discriminators; default: the training default).
    #[arg(long)]
    mixed_adversarial: Option<f64>,
    /// Weight of the mixed-code pose-speed term (default: the training default).
    #[arg(long)]
    mixed_motion: Option<f64>,
    /// Where the curves and the summary (`summary.json`) go.
    #[arg(long)]
    out: PathBuf,
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
#[value(rename_all = "snake_case")]
enum Variant {
    /// Adversarial terms and foot terms (the default training).
    Full,
    /// Foot terms, no discriminators.
    NoAdv,
    /// Discriminators, no foot terms (the training before session 10).
    NoFeet,
    /// Neither.
    Plain,
}

impl Variant {
    fn config(self, iterations: u64, seed: u64) -> vae::TrainConfig {
        let mut c = vae::TrainConfig {
            iterations,
            seed,
            ..Default::default()
        };
        if matches!(self, Variant::NoAdv | Variant::Plain) {
            c.adversarial = false;
        }
        if matches!(self, Variant::NoFeet | Variant::Plain) {
            c.feet = vae::FootLoss::off();
        }
        c
    }

    fn name(self) -> &'static str {
        match self {
            Variant::Full => "full",
            Variant::NoAdv => "no_adv",
            Variant::NoFeet => "no_feet",
            Variant::Plain => "plain",
        }
    }
}

#[derive(Serialize)]
struct CurvePoint {
    iteration: u64,
    seconds: f64,
    losses: vae::Losses,
}

#[derive(Serialize)]
struct Row {
    class: String,
    variant: Variant,
    train_clips: usize,
    test_clips: usize,
    iterations: u64,
    seconds: f64,
    seconds_per_iteration: f64,
    /// Wall time until root + rotation loss first came within 10 % of its final value.
    seconds_to_within_10_percent: f64,
    final_losses: vae::Losses,
    reconstruction_root_rmse_m: f64,
    reconstruction_joint_angle_rad: f64,
    originals: SetPlausibility,
    reconstructions: SetPlausibility,
    /// Near samples as the decoder gives them.
    samples_decoded: SetPlausibility,
    /// Near samples as `TrainedVae::sample` returns them (root planted).
    samples: SetPlausibility,
    /// Sample skating / original skating.
    skating_ratio: f64,
    /// Fraction of the (planted) samples whose pose speed is at least half
    /// the originals' mean: samples that move, not a frozen in-between pose.
    samples_moving_fraction: f64,
    mmd2_samples_to_test: f64,
    mmd2_train_to_test: f64,
}

fn run_one(
    class: &str,
    variant: Variant,
    split: &eval::dataset::Split,
    args: &Args,
) -> anyhow::Result<Row> {
    let clips: Vec<Motion> = split.train.iter().map(|(_, m)| m.clone()).collect();
    let mut config = variant.config(args.iterations, args.seed);
    if let Some(lr) = args.lr {
        config.optimizer = vae::OptimizerConfig::Adam { lr };
    }
    if let Some(w) = args.smooth {
        config.weights.smooth = w;
    }
    if let Some(w) = args.kl {
        config.weights.kl = w;
    }
    if args.reference_sizes {
        config.model = vae::VaeConfig::reference();
    }
    if let Some(w) = args.mixed_adversarial {
        config.weights.mixed_adversarial = w;
    }
    if let Some(w) = args.mixed_motion {
        config.weights.mixed_motion = w;
    }
    if !config.feet.is_off() {
        if let Some(w) = args.foot_position {
            config.feet.position = w;
        }
        if let Some(w) = args.foot_velocity {
            config.feet.velocity = w;
        }
        if let Some(w) = args.skating {
            config.feet.skating = w;
        }
    }
    let start = Instant::now();
    let mut curve = Vec::new();
    let every = args.log_every.max(1);
    let model = vae::train(&clips, &config, |p| {
        if p.iteration % every == 0 || p.iteration == p.iterations || p.iteration == 1 {
            let seconds = start.elapsed().as_secs_f64();
            let l = p.losses;
            eprintln!(
                "{class} {}: it {}/{} {:.0} s  root {:.4} rot {:.4} feet {:.4} vel {:.3} skate {:.3} floor {:.5} kl {:.3} adv {:.3} disc {:.3} mixed adv {:.3} motion {:.3}",
                variant.name(),
                p.iteration,
                p.iterations,
                seconds,
                l.root,
                l.rotation,
                l.foot_position,
                l.foot_velocity,
                l.skating,
                l.floor,
                l.kl,
                l.adversarial,
                l.discriminator,
                l.mixed_adversarial,
                l.mixed_motion
            );
            curve.push(CurvePoint {
                iteration: p.iteration,
                seconds,
                losses: *l,
            });
        }
    })?;
    let seconds = start.elapsed().as_secs_f64();
    model.save(args.out.join(format!("{class}_{}.model", variant.name())))?;
    write_json(
        &args
            .out
            .join(format!("{class}_{}.curve.json", variant.name())),
        &curve,
    )?;
    let recon_loss = |p: &CurvePoint| (p.losses.root + p.losses.rotation) as f64;
    let last = curve.last().map(recon_loss).unwrap_or(0.0);
    let within = curve
        .iter()
        .find(|p| recon_loss(p) <= 1.1 * last)
        .map_or(seconds, |p| p.seconds);
    let error = model.reconstruction_error(&clips)?;
    let recon = model.reconstruct(&clips)?;
    let count = args.samples_per_clip * clips.len();
    let samples: Vec<Motion> = model
        .sample(count, vae::Prior::Near, args.seed ^ 0x5a)?
        .into_iter()
        .map(|s| s.motion)
        .collect();
    let decoded: Vec<Motion> = model
        .sample_decoded(count, vae::Prior::Near, args.seed ^ 0x5a)?
        .into_iter()
        .map(|s| s.motion)
        .collect();
    let feature = |ms: &mut dyn Iterator<Item = &Motion>| -> anyhow::Result<Vec<Vec<f64>>> {
        ms.map(|m| eval::mmd::clip_feature(m).map_err(anyhow::Error::from))
            .collect()
    };
    let test = feature(&mut split.test.iter().map(|(_, m)| m))?;
    let synth = feature(&mut samples.iter())?;
    let train = feature(&mut clips.iter())?;
    let originals = SetPlausibility::of(&clips);
    let sampled = SetPlausibility::of(&samples);
    let skating_ratio = sampled.foot_skating_m_s / originals.foot_skating_m_s.max(1e-9);
    let moving = samples
        .iter()
        .filter(|m| {
            motion::metrics::plausibility(m).pose_speed_m_s >= 0.5 * originals.pose_speed_m_s
        })
        .count();
    let samples_moving_fraction = moving as f64 / samples.len().max(1) as f64;
    Ok(Row {
        class: class.to_string(),
        variant,
        train_clips: clips.len(),
        test_clips: split.test.len(),
        iterations: args.iterations,
        seconds,
        seconds_per_iteration: seconds / args.iterations as f64,
        seconds_to_within_10_percent: within,
        final_losses: model.meta().training.final_losses,
        reconstruction_root_rmse_m: error.root_rmse_m,
        reconstruction_joint_angle_rad: error.mean_joint_angle_rad,
        originals,
        reconstructions: SetPlausibility::of(&recon),
        samples_decoded: SetPlausibility::of(&decoded),
        samples: sampled,
        skating_ratio,
        samples_moving_fraction,
        mmd2_samples_to_test: eval::mmd::mmd(&synth, &test).mmd2,
        mmd2_train_to_test: eval::mmd::mmd(&train, &test).mmd2,
    })
}

fn table(rows: &[Row]) -> String {
    let mut t = String::from(
        "| class | variant | s (s/it) | s to 10 % | root RMSE m / angle rad | skating m/s orig / recon / decoded / samples (ratio) | penetration mm orig / samples | floating % orig / samples | pose speed m/s orig / samples (moving %) | MMD^2 samples / train |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        t += &format!(
            "| {} | {} | {:.0} ({:.3}) | {:.0} | {:.3} / {:.3} | {:.3} / {:.3} / {:.3} / {:.3} ({:.1}x) | {:.1} / {:.1} | {:.0} / {:.0} | {:.2} / {:.2} ({:.0}) | {:.3} / {:.3} |\n",
            r.class,
            r.variant.name(),
            r.seconds,
            r.seconds_per_iteration,
            r.seconds_to_within_10_percent,
            r.reconstruction_root_rmse_m,
            r.reconstruction_joint_angle_rad,
            r.originals.foot_skating_m_s,
            r.reconstructions.foot_skating_m_s,
            r.samples_decoded.foot_skating_m_s,
            r.samples.foot_skating_m_s,
            r.skating_ratio,
            r.originals.penetration_mean_m * 1000.0,
            r.samples.penetration_mean_m * 1000.0,
            r.originals.floating_fraction * 100.0,
            r.samples.floating_fraction * 100.0,
            r.originals.pose_speed_m_s,
            r.samples.pose_speed_m_s,
            r.samples_moving_fraction * 100.0,
            r.mmd2_samples_to_test,
            r.mmd2_train_to_test,
        );
    }
    t
}

fn out_dir(path: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(path).with_context(|| format!("creating {}", path.display()))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    out_dir(&args.out)?;
    let mut rows = Vec::new();
    for class in &args.classes {
        let split = eval::dataset::load_split(&args.data, &args.data, class, &args.test_actor)?;
        for &variant in &args.variants {
            rows.push(run_one(class, variant, &split, &args)?);
            write_json(&args.out.join("summary.json"), &rows)?;
        }
    }
    let text = if args.json {
        serde_json::to_string_pretty(&rows)? + "\n"
    } else {
        table(&rows)
    };
    print_stdout(&text)
}
