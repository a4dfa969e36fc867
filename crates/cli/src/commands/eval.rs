//! `motionaug eval synth|predict|table`: how good is an augmentation?
//!
//! * `synth`: min DTW and MMD between synthesised clips and a held-out actor's
//!   clips (MotionAug Sec. 4.1).
//! * `predict`: the downstream protocol (Sec. 4.3): leave one actor out, train a
//!   motion prediction model with and without the augmentation, Euler error at
//!   100 / 200 / 400 ms.
//! * `table`: both, for several classes, actors, models and augmentations, in
//!   one command; writes `table.json` and `table.md` (rewritten after every
//!   class, so a long run can be read while it goes).
//!
//! The science is in the `eval` crate; this file picks clips, builds the
//! augmentation closures (a recipe through the `pipeline` crate, or the VAE
//! directly) and writes.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use ::eval::dataset::{self, Split};
use ::eval::dtw::{self, MinDtw};
use ::eval::euler::EulerClip;
use ::eval::mmd::{self, Mmd};
use ::eval::predict::data::{ClipSet, HORIZONS_MS};
use ::eval::predict::protocol::{
    self, ConditionResult, Horizons, ModelKind, ModelSizes, ProtocolConfig, TestSet,
};
use ::vae::{Prior, TrainConfig as VaeTrainConfig};
use anyhow::{Context, bail};
use motion::Motion;
use rayon::prelude::*;
use serde::Serialize;
use serde_json::json;

use super::eval_physics::{self, PhysicsArgs, PhysicsSummary};
use crate::output::{print_stdout, write_atomic, write_json};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Min DTW and MMD between synthesised clips and a held-out actor's clips.
    Synth(SynthArgs),
    /// Motion prediction error with and without an augmentation (leave one actor out).
    Predict(PredictArgs),
    /// The whole evaluation table for several classes: JSON + Markdown.
    Table(TableArgs),
}

/// Which clips: a class of an HDM05 folder, one actor held out.
#[derive(clap::Args, Clone)]
struct FoldArgs {
    /// Folder of HDM05 clips `HDM_<actor>_<class>_<nnn>_120.amc`.
    #[arg(long)]
    data: PathBuf,
    /// Folder of the `HDM_<actor>.asf` skeletons (default: --data).
    #[arg(long)]
    skeleton_dir: Option<PathBuf>,
    /// Part of the class name (case-insensitive), e.g. `kick` for kickLFront1Reps.
    #[arg(long)]
    class: String,
    /// The held-out actor (bd, bk, dg, mm, tr).
    #[arg(long)]
    test_actor: String,
}

impl FoldArgs {
    fn load(&self) -> anyhow::Result<Split> {
        load_fold(
            &self.data,
            self.skeleton_dir.as_deref(),
            &self.class,
            &self.test_actor,
        )
    }
}

fn load_fold(
    data: &Path,
    skeletons: Option<&Path>,
    class: &str,
    actor: &str,
) -> anyhow::Result<Split> {
    let split = dataset::load_split(data, skeletons.unwrap_or(data), class, actor)
        .with_context(|| format!("cannot load class `{class}` from {}", data.display()))?;
    eprintln!(
        "class `{class}` matched {} ({} clips: {}); test actor {actor}: {} clips, training: {} clips",
        split.classes().join(", "),
        split.train.len() + split.test.len(),
        split
            .actors()
            .iter()
            .map(|(a, n)| format!("{a} {n}"))
            .collect::<Vec<_>>()
            .join(", "),
        split.test.len(),
        split.train.len()
    );
    Ok(split)
}

/// Where synthesised clips come from.
#[derive(clap::Args, Clone)]
struct AugmentArgs {
    /// Recipe (TOML or JSON) applied to the training clips in memory by the
    /// pipeline: `[[ops]]`, and `[vae]`, `[correct]`, `[debias]` tables.
    #[arg(long, conflicts_with = "vae")]
    recipe: Option<PathBuf>,
    /// Train the motion VAE on the training clips and sample from this prior.
    #[arg(long)]
    vae: Option<Prior>,
    /// VAE samples per training clip (MotionAug: 10).
    #[arg(long, default_value_t = 10)]
    vae_per_clip: usize,
    /// VAE training iterations.
    #[arg(long, default_value_t = 300)]
    vae_iterations: u64,
    /// VAE adversarial weight (0: no discriminators).
    #[arg(long)]
    vae_adversarial_weight: Option<f64>,
    /// Seed of the augmentation (recipe seed override, VAE seed).
    #[arg(long)]
    aug_seed: Option<u64>,
    /// Folder for the pipeline's intermediate results (corrections, models);
    /// default: a temporary folder removed at the end.
    #[arg(long)]
    work: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, Serialize)]
struct VaeChoice {
    prior: Prior,
    per_clip: usize,
    iterations: u64,
    adversarial_weight: Option<f64>,
    seed: u64,
}

/// The augmentation as a closure from training clips to synthesised clips.
enum Augmentation {
    Recipe {
        recipe: Box<pipeline::Recipe>,
        seed: u64,
        label: String,
        work: Option<PathBuf>,
    },
    Vae(VaeChoice),
}

impl Augmentation {
    fn from_args(a: &AugmentArgs) -> anyhow::Result<Option<Augmentation>> {
        if let Some(path) = &a.recipe {
            let recipe = pipeline::Recipe::from_file(path)
                .with_context(|| format!("invalid recipe {}", path.display()))?;
            let seed = recipe.effective_seed(a.aug_seed);
            return Ok(Some(Augmentation::Recipe {
                recipe: Box::new(recipe),
                seed,
                label: path.display().to_string(),
                work: a.work.clone(),
            }));
        }
        Ok(a.vae.map(|prior| {
            Augmentation::Vae(VaeChoice {
                prior,
                per_clip: a.vae_per_clip,
                iterations: a.vae_iterations,
                adversarial_weight: a.vae_adversarial_weight,
                seed: a.aug_seed.unwrap_or(0),
            })
        }))
    }

    fn label(&self) -> String {
        match self {
            Augmentation::Recipe { label, .. } => format!("recipe {label}"),
            Augmentation::Vae(v) => format!("vae ({:?} prior)", v.prior),
        }
    }

    fn apply(&self, train: &[(String, Motion)]) -> anyhow::Result<Vec<(String, Motion)>> {
        match self {
            Augmentation::Recipe {
                recipe, seed, work, ..
            } => apply_recipe(recipe, *seed, work.as_deref(), train),
            Augmentation::Vae(v) => {
                let model = train_vae(train, v.iterations, v.adversarial_weight, v.seed)?;
                sample_vae(&model, train.len() * v.per_clip, v.prior, v.seed)
            }
        }
    }
}

/// Runs `recipe` on the training clips in memory with the pipeline crate (the
/// same job graph `motionaug augment` runs); returns the kept outputs.
fn apply_recipe(
    recipe: &pipeline::Recipe,
    seed: u64,
    work: Option<&Path>,
    train: &[(String, Motion)],
) -> anyhow::Result<Vec<(String, Motion)>> {
    let start = Instant::now();
    let clips: Vec<pipeline::Clip> = train
        .iter()
        .map(|(name, m)| pipeline::Clip {
            name: name.clone(),
            source: name.clone(),
            motion: m.clone(),
        })
        .collect();
    let temp = std::env::temp_dir().join(format!("motionaug-eval-{}", std::process::id()));
    let work_dir = work.unwrap_or(&temp);
    let on_event = |event: pipeline::Event<'_>| {
        if let pipeline::Event::JobFinished { job, ok } = event
            && !matches!(job.kind, pipeline::JobKind::Synthesize { .. })
        {
            eprintln!(
                "pipeline: {} {}",
                job.key,
                if ok { "done" } else { "failed" }
            );
        }
    };
    let result = pipeline::run(
        recipe,
        &clips,
        &pipeline::Options {
            out: None,
            work: work_dir,
            seed,
            on_event: &on_event,
        },
    );
    if work.is_none() {
        let _ = std::fs::remove_dir_all(&temp);
    }
    let summary = result.context("the augmentation pipeline failed")?;
    for (job, reason) in &summary.failures {
        eprintln!("pipeline: {job} failed: {reason}");
    }
    if !summary.rejected.is_empty() {
        eprintln!(
            "pipeline: {} outputs rejected by the correction",
            summary.rejected.len()
        );
    }
    let out: Vec<(String, Motion)> = summary
        .outputs
        .into_iter()
        .map(|o| (o.name, o.motion))
        .collect();
    if out.is_empty() {
        bail!(
            "the recipe produced no clips ({} jobs failed)",
            summary.failures.len()
        );
    }
    eprintln!(
        "recipe: {} clips from {} in {:.1} s",
        out.len(),
        train.len(),
        start.elapsed().as_secs_f64()
    );
    Ok(out)
}

/// The table's VAE of one class and fold: loaded from `dir` when an earlier
/// run saved it there (training is deterministic, so this is the same model),
/// else trained and saved, so a rerun of the table does not train it again.
fn cached_vae(
    dir: &Path,
    train: &[(String, Motion)],
    iterations: u64,
    adversarial_weight: Option<f64>,
) -> anyhow::Result<::vae::TrainedVae> {
    if dir.join(::vae::trained::META_FILE).is_file() {
        eprintln!("vae: reusing {}", dir.display());
        return ::vae::TrainedVae::load(dir)
            .with_context(|| format!("cannot load the saved VAE {}", dir.display()));
    }
    let model = train_vae(train, iterations, adversarial_weight, 0)?;
    model
        .save(dir)
        .with_context(|| format!("cannot save the VAE to {}", dir.display()))?;
    Ok(model)
}

fn train_vae(
    train: &[(String, Motion)],
    iterations: u64,
    adversarial_weight: Option<f64>,
    seed: u64,
) -> anyhow::Result<::vae::TrainedVae> {
    let clips: Vec<Motion> = train.iter().map(|(_, m)| m.clone()).collect();
    let mut config = VaeTrainConfig {
        iterations: iterations.max(1),
        seed,
        ..VaeTrainConfig::default()
    };
    if let Some(w) = adversarial_weight {
        if w == 0.0 {
            config.adversarial = false;
        } else {
            config.weights.adversarial = w;
        }
    }
    eprintln!(
        "vae: training on {} clips, {} iterations, adversarial {} (weight {})",
        clips.len(),
        config.iterations,
        config.adversarial,
        config.weights.adversarial
    );
    let every = (config.iterations / 5).max(1);
    let model = ::vae::train(&clips, &config, |p| {
        if p.iteration % every == 0 {
            eprintln!(
                "vae: iteration {}/{} loss {:.4}",
                p.iteration, p.iterations, p.losses.total
            );
        }
    })
    .context("VAE training failed")?;
    eprintln!("vae: trained in {:.1} s", model.meta().training.seconds);
    Ok(model)
}

fn sample_vae(
    model: &::vae::TrainedVae,
    count: usize,
    prior: Prior,
    seed: u64,
) -> anyhow::Result<Vec<(String, Motion)>> {
    let samples = model.sample(count, prior, seed)?;
    Ok(samples
        .into_iter()
        .enumerate()
        .map(|(i, s)| (format!("vae_{prior:?}_{i:04}"), s.motion))
        .collect())
}

/// Closeness of a synthesised set to the test clips.
#[derive(Debug, Clone, Serialize)]
struct SynthScores {
    min_dtw: MinDtw,
    mmd: Mmd,
    plausibility: SetPlausibility,
}

/// Physical plausibility of a set: means over its clips of
/// `motion::metrics::plausibility` (default thresholds, clips at 30 fps).
#[derive(Debug, Clone, Serialize)]
struct SetPlausibility {
    foot_skating_m_s: f64,
    penetration_mean_m: f64,
    floating_fraction: f64,
}

impl SetPlausibility {
    fn of(clips: &[Motion]) -> SetPlausibility {
        let all: Vec<_> = clips.iter().map(motion::metrics::plausibility).collect();
        let mean = |f: fn(&motion::metrics::Plausibility) -> f64| {
            all.iter().map(f).sum::<f64>() / all.len().max(1) as f64
        };
        SetPlausibility {
            foot_skating_m_s: mean(|p| p.foot_skating_m_s),
            penetration_mean_m: mean(|p| p.penetration_mean_m),
            floating_fraction: mean(|p| p.floating_fraction),
        }
    }
}

fn synth_scores(
    synth: &[(String, Motion)],
    test: &[(String, Motion)],
) -> anyhow::Result<SynthScores> {
    if synth.is_empty() {
        bail!("no synthesised clips to score");
    }
    for (name, m) in synth {
        ::eval::euler::check_same_layout(test[0].1.skeleton(), m.skeleton(), name)?;
    }
    let at_fps = |clips: &[(String, Motion)]| -> anyhow::Result<Vec<Motion>> {
        clips
            .iter()
            .map(|(_, m)| Ok(motion::resample::resample(m, dataset::FPS)?))
            .collect()
    };
    let (s, t) = (at_fps(synth)?, at_fps(test)?);
    let euler = |ms: &[Motion]| ms.par_iter().map(EulerClip::of).collect::<Vec<_>>();
    let min_dtw = dtw::min_dtw(&euler(&s), &euler(&t));
    let feats = |ms: &[Motion]| -> anyhow::Result<Vec<Vec<f64>>> {
        ms.iter().map(|m| Ok(mmd::clip_feature(m)?)).collect()
    };
    let mmd = mmd::mmd(&feats(&s)?, &feats(&t)?);
    Ok(SynthScores {
        min_dtw,
        mmd,
        plausibility: SetPlausibility::of(&s),
    })
}

#[derive(clap::Args)]
struct SynthArgs {
    #[command(flatten)]
    fold: FoldArgs,
    #[command(flatten)]
    aug: AugmentArgs,
    /// Already synthesised clips (BVH) instead of --recipe / --vae.
    #[arg(long, num_args = 1.., conflicts_with_all = ["recipe", "vae"])]
    files: Vec<PathBuf>,
    /// Print JSON instead of a summary line.
    #[arg(long)]
    json: bool,
}

fn run_synth(args: SynthArgs) -> anyhow::Result<()> {
    let split = args.fold.load()?;
    let (label, synth) = if !args.files.is_empty() {
        let clips = args
            .files
            .iter()
            .map(|p| {
                let m = motion::io::load(p, &Default::default())
                    .with_context(|| format!("cannot read {}", p.display()))?;
                Ok((crate::input::clip_name(p), m))
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        (format!("{} files", clips.len()), clips)
    } else {
        let aug = Augmentation::from_args(&args.aug)?.context("give --recipe, --vae or --files")?;
        (aug.label(), aug.apply(&split.train)?)
    };
    let start = Instant::now();
    let scores = synth_scores(&synth, &split.test)?;
    let original = synth_scores(&split.train, &split.test)?;
    eprintln!("scored in {:.1} s", start.elapsed().as_secs_f64());
    if args.json {
        let v = json!({
            "class": args.fold.class,
            "matched_classes": split.classes(),
            "test_actor": args.fold.test_actor,
            "synthesised": label,
            "min_dtw": scores.min_dtw.synth_to_test,
            "mmd": scores.mmd.mmd2,
            "scores": scores,
            "original": original,
        });
        print_stdout(&(serde_json::to_string_pretty(&v)? + "\n"))
    } else {
        print_stdout(&format!(
            "{label}: min DTW {:.3} (test->synth {:.3}), MMD^2 {:.4} over {} clips; training clips: min DTW {:.3}, MMD^2 {:.4}\n",
            scores.min_dtw.synth_to_test,
            scores.min_dtw.test_to_synth,
            scores.mmd.mmd2,
            scores.min_dtw.synth_clips,
            original.min_dtw.synth_to_test,
            original.mmd.mmd2
        ))
    }
}

/// Training options shared by `predict` and `table`.
#[derive(clap::Args, Clone)]
struct TrainArgs {
    /// Optimiser steps per model (both conditions get the same number).
    #[arg(long, default_value_t = 1000, conflicts_with = "epochs")]
    iterations: usize,
    /// Passes over the training windows *without* augmentation (sets --iterations).
    #[arg(long)]
    epochs: Option<f64>,
    #[arg(long, default_value_t = 32)]
    batch_size: usize,
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    /// Models trained per condition; errors are averaged (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "0")]
    seeds: Vec<u64>,
    /// Cap on training and on test windows (evenly spaced); default all.
    #[arg(long)]
    max_windows: Option<usize>,
    /// GRU state size of seq2seq.
    #[arg(long, default_value_t = ModelSizes::default().seq2seq_hidden)]
    seq2seq_hidden: usize,
    /// Hidden features per node of the GCN.
    #[arg(long, default_value_t = ModelSizes::default().gcn_hidden)]
    gcn_hidden: usize,
    /// Residual blocks (two graph convolutions each) of the GCN.
    #[arg(long, default_value_t = ModelSizes::default().gcn_stages)]
    gcn_stages: usize,
}

impl TrainArgs {
    fn config(&self, model: ModelKind, split: &Split) -> anyhow::Result<ProtocolConfig> {
        let mut c = ProtocolConfig::new(model);
        c.sizes.seq2seq_hidden = self.seq2seq_hidden;
        c.sizes.gcn_hidden = self.gcn_hidden;
        c.sizes.gcn_stages = self.gcn_stages;
        c.train.batch_size = self.batch_size;
        c.train.lr = self.lr;
        c.seeds = self.seeds.clone();
        c.max_train_windows = self.max_windows;
        c.max_test_windows = self.max_windows;
        c.train.iterations = self.iterations;
        if let Some(e) = self.epochs {
            if !(e.is_finite() && e > 0.0) {
                bail!("--epochs must be positive");
            }
            let mut set = ClipSet::new(&split.train, &split.train[0].1, dataset::FPS, c.stride)?;
            if let Some(m) = self.max_windows {
                set.limit_windows(m);
            }
            c.train.iterations = ((set.windows.len() as f64 * e / self.batch_size.max(1) as f64)
                .ceil() as usize)
                .max(1);
        }
        Ok(c)
    }
}

#[derive(clap::Args)]
struct PredictArgs {
    #[command(flatten)]
    fold: FoldArgs,
    /// seq2seq (GRU, residual decoding) or gcn (DCT + graph convolutions).
    #[arg(long)]
    model: ModelKind,
    #[command(flatten)]
    aug: AugmentArgs,
    #[command(flatten)]
    train: TrainArgs,
    /// Print JSON (no_aug / aug: {"100", "200", "400"} in radians, and details).
    #[arg(long)]
    json: bool,
    /// Also write the JSON to this file.
    #[arg(long)]
    out: Option<PathBuf>,
}

fn run_predict(args: PredictArgs) -> anyhow::Result<()> {
    let split = args.fold.load()?;
    let config = args.train.config(args.model, &split)?;
    let aug = Augmentation::from_args(&args.aug)?;
    eprintln!(
        "{}: {} iterations, batch {}, seeds {:?}; augmentation: {}",
        args.model,
        config.train.iterations,
        config.train.batch_size,
        config.seeds,
        aug.as_ref().map_or("none".to_string(), |a| a.label())
    );
    let closure = |train: &[(String, Motion)]| -> ::eval::Result<Vec<(String, Motion)>> {
        match &aug {
            Some(a) => a
                .apply(train)
                .map_err(|e| ::eval::EvalError::Augmentation(e.into())),
            None => Ok(Vec::new()),
        }
    };
    let augment: Option<protocol::Augment<'_>> =
        aug.as_ref().map(|_| &closure as protocol::Augment<'_>);
    let result = protocol::run(&split.train, &split.test, augment, &config, &mut |l| {
        eprintln!("{l}")
    })?;
    let mut value = json!({
        "class": args.fold.class,
        "matched_classes": split.classes(),
        "test_actor": args.fold.test_actor,
        "model": args.model,
        "augmentation": aug.as_ref().map(|a| a.label()),
        "train_files": split.train_files.iter().map(|f| &f.name).collect::<Vec<_>>(),
        "test_files": split.test_files.iter().map(|f| &f.name).collect::<Vec<_>>(),
        "no_aug": result.no_aug.errors,
        "zero_velocity": result.zero_velocity,
        "details": result,
    });
    if let Some(a) = &result.aug {
        value["aug"] = serde_json::to_value(&a.errors)?;
    }
    if let Some(path) = &args.out {
        write_json(path, &value)?;
    }
    if args.json {
        print_stdout(&(serde_json::to_string_pretty(&value)? + "\n"))
    } else {
        let mut s = String::from("condition   100ms  200ms  400ms  (Euler error, rad)\n");
        let mut row = |name: &str, h: &Horizons| {
            let _ = writeln!(
                s,
                "{name:<10} {:>6.3} {:>6.3} {:>6.3}",
                h["100"], h["200"], h["400"]
            );
        };
        row("zero-vel", &result.zero_velocity);
        row("no_aug", &result.no_aug.errors);
        if let Some(a) = &result.aug {
            row("aug", &a.errors);
        }
        print_stdout(&s)
    }
}

#[derive(clap::Args)]
struct TableArgs {
    /// Folder of HDM05 clips.
    #[arg(long)]
    data: PathBuf,
    /// Folder of the `HDM_<actor>.asf` skeletons (default: --data).
    #[arg(long)]
    skeleton_dir: Option<PathBuf>,
    /// Output folder for table.json and table.md.
    #[arg(long)]
    out: PathBuf,
    /// Classes (parts of class names; also the IK preset names).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "kick,jog,sneak,grab,deposit"
    )]
    classes: Vec<String>,
    #[arg(long, value_delimiter = ',', default_value = "bd")]
    test_actors: Vec<String>,
    #[arg(long, value_delimiter = ',', default_value = "seq2seq,gcn")]
    models: Vec<ModelKind>,
    #[command(flatten)]
    train: TrainArgs,
    /// Noise recipe: Gaussian rotation noise, degrees (10 copies per clip).
    #[arg(long, default_value_t = 2.0)]
    noise_sigma_deg: f64,
    /// VAE training iterations per class and fold.
    #[arg(long, default_value_t = 300)]
    vae_iterations: u64,
    /// Also train the VAE without discriminators (min DTW / MMD ablation).
    #[arg(long)]
    vae_ablation: bool,
    /// Skip the prediction part (synthesis metrics only).
    #[arg(long)]
    no_predict: bool,
    /// Synthesised sets: noise, ik, vae (near and prior samples), physics (a
    /// subset of the VAE's near samples as sampled, physically corrected, and
    /// debiased; needs vae).
    #[arg(long, value_delimiter = ',', default_value = "noise,ik,vae")]
    sets: Vec<SetKind>,
    #[command(flatten)]
    physics: PhysicsArgs,
    /// Folder for the trained VAEs and the corrections (default: OUT/work); a
    /// rerun reuses them and resumes interrupted corrections.
    #[arg(long)]
    work: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
enum SetKind {
    Noise,
    Ik,
    Vae,
    Physics,
}

/// Conditions of the prediction tables, in order (sets not made are skipped).
const PREDICT_CONDITIONS: [&str; 6] = [
    "noise",
    "ik",
    "vae_near",
    "vae_sub",
    "vae_corrected",
    "vae_debiased",
];

#[derive(Serialize, Default)]
struct TableCell {
    class: String,
    matched_classes: Vec<String>,
    test_actor: String,
    train_clips: usize,
    test_clips: usize,
    /// Synthesis metrics per set (original = the training clips themselves).
    synth: BTreeMap<String, SynthScores>,
    synth_clips: BTreeMap<String, usize>,
    /// model -> condition -> errors.
    predict: BTreeMap<String, BTreeMap<String, ConditionResult>>,
    zero_velocity: Option<Horizons>,
    vae_seconds: BTreeMap<String, f64>,
    /// What the physical correction did (with `--sets ...,physics`).
    #[serde(skip_serializing_if = "Option::is_none")]
    physics: Option<PhysicsSummary>,
}

fn run_table(args: TableArgs) -> anyhow::Result<()> {
    if args.sets.contains(&SetKind::Physics) && !args.sets.contains(&SetKind::Vae) {
        bail!("--sets physics corrects the VAE's samples: add vae to --sets");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let started = Instant::now();
    let mut cells: Vec<TableCell> = Vec::new();
    for actor in &args.test_actors {
        for class in &args.classes {
            eprintln!(
                "== {class}, test actor {actor} ({:.0} s so far)",
                started.elapsed().as_secs_f64()
            );
            let split = load_fold(&args.data, args.skeleton_dir.as_deref(), class, actor)?;
            let mut cell = TableCell {
                class: class.clone(),
                matched_classes: split.classes(),
                test_actor: actor.clone(),
                train_clips: split.train.len(),
                test_clips: split.test.len(),
                ..Default::default()
            };
            // Synthesised sets.
            let mut sets: Vec<(String, Vec<(String, Motion)>)> = Vec::new();
            if args.sets.contains(&SetKind::Noise) {
                let noise = pipeline::Recipe::from_toml_str(&format!(
                    "seed = 1\n[[ops]]\nop = \"noise\"\ncopies = 10\nsigma_deg = {}\n",
                    args.noise_sigma_deg
                ))?;
                sets.push(("noise".into(), apply_recipe(&noise, 1, None, &split.train)?));
            }
            if args.sets.contains(&SetKind::Ik) {
                let ik = pipeline::Recipe::from_toml_str(&format!(
                    "seed = 1\n[[ops]]\nop = \"ik\"\npreset = \"{}\"\ncopies = 10\n",
                    class.to_ascii_lowercase()
                ))
                .with_context(|| format!("no IK preset for class `{class}`"))?;
                sets.push(("ik".into(), apply_recipe(&ik, 1, None, &split.train)?));
            }
            let count = split.train.len() * 10;
            let mut vae_runs = vec![];
            if args.sets.contains(&SetKind::Vae) {
                vae_runs.push(("vae", None));
                if args.vae_ablation {
                    vae_runs.push(("vae_noadv", Some(0.0)));
                }
            }
            let work = args
                .work
                .clone()
                .unwrap_or_else(|| args.out.join("work"))
                .join(format!("{actor}_{class}"));
            for (tag, weight) in vae_runs {
                let t = Instant::now();
                let cache = work.join(format!("{tag}-{}it", args.vae_iterations));
                let model = cached_vae(&cache, &split.train, args.vae_iterations, weight)?;
                cell.vae_seconds
                    .insert(tag.into(), t.elapsed().as_secs_f64());
                sets.push((
                    format!("{tag}_near"),
                    sample_vae(&model, count, Prior::Near, 0)?,
                ));
                sets.push((
                    format!("{tag}_prior"),
                    sample_vae(&model, count, Prior::Normal, 0)?,
                ));
            }
            if args.sets.contains(&SetKind::Physics) {
                let near = sets
                    .iter()
                    .find(|(n, _)| n == "vae_near")
                    .map(|(_, c)| c.as_slice())
                    .context("no VAE samples to correct")?;
                let p = eval_physics::correct_and_debias(&args.physics, &split.train, near, &work)?;
                sets.push(("vae_sub".into(), p.subset));
                sets.push(("vae_corrected".into(), p.corrected));
                sets.push(("vae_debiased".into(), p.debiased));
                cell.physics = Some(p.summary);
            }
            let t = Instant::now();
            cell.synth
                .insert("original".into(), synth_scores(&split.train, &split.test)?);
            for (name, clips) in &sets {
                cell.synth_clips.insert(name.clone(), clips.len());
                if !clips.is_empty() {
                    cell.synth
                        .insert(name.clone(), synth_scores(clips, &split.test)?);
                }
            }
            eprintln!("synthesis metrics in {:.1} s", t.elapsed().as_secs_f64());
            if !args.no_predict {
                for &model in &args.models {
                    let config = args.train.config(model, &split)?;
                    let test = TestSet::new(&split.test, &config)?;
                    cell.zero_velocity = Some(test.zero_velocity());
                    let mut by_condition = BTreeMap::new();
                    let mut log = |l: &str| eprintln!("{l}");
                    eprintln!("{model}: no_aug");
                    by_condition.insert(
                        "no_aug".to_string(),
                        protocol::evaluate(&split.train, &test, &config, &mut log)?,
                    );
                    for (name, clips) in &sets {
                        if !PREDICT_CONDITIONS.contains(&name.as_str()) || clips.is_empty() {
                            continue;
                        }
                        eprintln!("{model}: {name}");
                        let mut all = split.train.clone();
                        all.extend(clips.iter().cloned());
                        by_condition.insert(
                            name.clone(),
                            protocol::evaluate(&all, &test, &config, &mut log)?,
                        );
                    }
                    cell.predict.insert(model.to_string(), by_condition);
                }
            }
            cells.push(cell);
            write_table(&args, &cells, started.elapsed().as_secs_f64())?;
        }
    }
    eprintln!(
        "wrote {} and {} in {:.0} s",
        args.out.join("table.json").display(),
        args.out.join("table.md").display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn write_table(args: &TableArgs, cells: &[TableCell], seconds: f64) -> anyhow::Result<()> {
    let config = json!({
        "classes": args.classes,
        "test_actors": args.test_actors,
        "models": args.models,
        "iterations": args.train.iterations,
        "epochs": args.train.epochs,
        "batch_size": args.train.batch_size,
        "lr": args.train.lr,
        "seeds": args.train.seeds,
        "max_windows": args.train.max_windows,
        "seq2seq_hidden": args.train.seq2seq_hidden,
        "gcn_hidden": args.train.gcn_hidden,
        "gcn_stages": args.train.gcn_stages,
        "noise_sigma_deg": args.noise_sigma_deg,
        "vae_iterations": args.vae_iterations,
        "vae_ablation": args.vae_ablation,
        "sets": args.sets,
        "physics": args.sets.contains(&SetKind::Physics).then_some(&args.physics),
    });
    write_json(
        &args.out.join("table.json"),
        &json!({ "config": config, "seconds": seconds, "cells": cells }),
    )?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# motionaug eval table\n\nConfig: `{config}`; {seconds:.0} s.\n"
    );
    for actor in &args.test_actors {
        let row_cells: Vec<&TableCell> = cells.iter().filter(|c| &c.test_actor == actor).collect();
        if row_cells.is_empty() {
            continue;
        }
        for model in &args.models {
            let m = model.to_string();
            if row_cells.iter().all(|c| !c.predict.contains_key(&m)) {
                continue;
            }
            let _ = writeln!(
                md,
                "## Prediction error, {m}, test actor {actor} (Euler, rad; 100 / 200 / 400 ms)\n"
            );
            let mut header = String::from("| condition |");
            let mut rule = String::from("|---|");
            for c in &row_cells {
                let _ = write!(
                    header,
                    " {} ({}/{} clips) |",
                    c.class, c.train_clips, c.test_clips
                );
                rule.push_str("---|");
            }
            let _ = writeln!(md, "{header}\n{rule}");
            let made = |cond: &str| {
                row_cells
                    .iter()
                    .any(|c| c.predict.get(&m).is_some_and(|p| p.contains_key(cond)))
            };
            let conditions = ["zero_velocity", "no_aug"]
                .into_iter()
                .chain(PREDICT_CONDITIONS.into_iter().filter(|c| made(c)));
            for cond in conditions {
                let mut line = format!("| {cond} |");
                for c in &row_cells {
                    let h = if cond == "zero_velocity" {
                        c.zero_velocity.as_ref()
                    } else {
                        c.predict
                            .get(&m)
                            .and_then(|p| p.get(cond))
                            .map(|r| &r.errors)
                    };
                    match h {
                        Some(h) => {
                            let v: Vec<String> = HORIZONS_MS
                                .iter()
                                .map(|ms| format!("{:.3}", h[&ms.to_string()]))
                                .collect();
                            let _ = write!(line, " {} |", v.join(" / "));
                        }
                        None => line.push_str(" - |"),
                    }
                }
                let _ = writeln!(md, "{line}");
            }
            md.push('\n');
        }
        set_table(
            &mut md,
            &format!("Synthesis, test actor {actor}: min DTW (synth->test; test->synth) / MMD^2"),
            &row_cells,
            |s| {
                format!(
                    "{:.3}; {:.3} / {:.4}",
                    s.min_dtw.synth_to_test, s.min_dtw.test_to_synth, s.mmd.mmd2
                )
            },
        );
        set_table(
            &mut md,
            &format!(
                "Plausibility, test actor {actor}: foot skating m/s / mean penetration mm / floating %"
            ),
            &row_cells,
            |s| {
                let p = &s.plausibility;
                format!(
                    "{:.3} / {:.1} / {:.0}",
                    p.foot_skating_m_s,
                    1000.0 * p.penetration_mean_m,
                    100.0 * p.floating_fraction
                )
            },
        );
        if row_cells.iter().any(|c| c.physics.is_some()) {
            let _ = writeln!(
                md,
                "## Correction, test actor {actor}\n\n| class | originals accepted | samples accepted | R_norm action 0 -> corrected | residual force ratio | PPO samples | seconds |\n|---|---|---|---|---|---|---|"
            );
            for c in &row_cells {
                if let Some(p) = &c.physics {
                    let _ = writeln!(
                        md,
                        "| {} | {}/{} | {}/{} | {:.3} -> {:.3} | {:.3} | {} | {:.0} |",
                        c.class,
                        p.originals_accepted,
                        p.originals,
                        p.samples_accepted,
                        p.samples,
                        p.mean_r_norm_action0,
                        p.mean_r_norm,
                        p.mean_residual_force_ratio,
                        p.ppo_samples,
                        p.seconds
                    );
                }
            }
            md.push('\n');
        }
    }
    write_atomic(&args.out.join("table.md"), md.as_bytes())
}

/// One Markdown table: a row per synthesised set, a column per class.
fn set_table(
    md: &mut String,
    title: &str,
    cells: &[&TableCell],
    show: impl Fn(&SynthScores) -> String,
) {
    let _ = writeln!(md, "## {title}\n");
    let mut header = String::from("| set |");
    let mut rule = String::from("|---|");
    for c in cells {
        let _ = write!(header, " {} |", c.class);
        rule.push_str("---|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    let mut names: Vec<&String> = cells.iter().flat_map(|c| c.synth.keys()).collect();
    names.sort();
    names.dedup();
    for name in names {
        let mut line = format!("| {name} |");
        for c in cells {
            match c.synth.get(name) {
                Some(s) => {
                    let _ = write!(line, " {} |", show(s));
                }
                None => line.push_str(" - |"),
            }
        }
        let _ = writeln!(md, "{line}");
    }
    md.push('\n');
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Synth(a) => run_synth(a),
        Command::Predict(a) => run_predict(a),
        Command::Table(a) => run_table(a),
    }
}
