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
//! Everything is computed by the `eval` crate (the table in `eval::table`);
//! this file turns arguments into its configs, prints and writes.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use ::eval::augment::{Augmentation, VaeChoice};
use ::eval::dataset::Split;
use ::eval::options::TrainOptions;
use ::eval::predict::cmu::{CmuConfig, LowerBody};
use ::eval::predict::dmgnn::Reconstruction;
use ::eval::predict::occlusion::MaskKind;
use ::eval::predict::protocol::{self, Horizons, ModelKind};
use ::eval::scores::synth_scores;
use ::eval::table::{self, PhysicsConfig, SetKind, Table, TableConfig};
use ::vae::Prior;
use anyhow::{Context, bail};
use serde_json::json;

use crate::commands::debias::HoldOut;
use crate::output::{print_stdout, write_json};

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
    /// (Boxed: its options outgrow the other commands'.)
    Table(Box<TableArgs>),
    /// Tables of separate `eval table` runs (e.g. one per test actor) merged
    /// into one, aggregated over all their folds and seeds.
    Merge(MergeArgs),
    /// V-DMGNN-GAN's Table 1 on the CMU data of DMGNN's preprocessing:
    /// DMGNN and V-DMGNN-GAN under lower-body and random masks (resumable).
    Cmu(CmuArgs),
}

#[derive(clap::Args)]
struct CmuArgs {
    /// The data folder (`train/<action>/`, `test/<action>/`), e.g. ../shared/data/cmu_dmgnn.
    #[arg(long)]
    data: PathBuf,
    /// Output folder: cmu_table.json, cmu_table.md, one folder per cell
    /// (weights, progress; a rerun resumes and reuses finished cells).
    #[arg(long)]
    out: PathBuf,
    #[arg(long, value_delimiter = ',', default_value = "dmgnn,vdmgnn")]
    models: Vec<ModelKind>,
    #[arg(long, value_delimiter = ',', default_value = "lower,random")]
    masks: Vec<MaskKind>,
    /// Actions (default: the five with training and test data).
    #[arg(long, value_delimiter = ',', default_value = listed(&::eval::cmu_dmgnn::COMPLETE_ACTIONS))]
    actions: Vec<String>,
    /// Optimiser steps per cell (the paper: 40,000 on a GPU).
    #[arg(long, default_value_t = CmuConfig::new(ModelKind::Dmgnn, MaskKind::Lower).train.iterations)]
    iterations: usize,
    #[arg(long, default_value_t = 32)]
    batch_size: usize,
    #[arg(long, default_value_t = CmuConfig::new(ModelKind::Dmgnn, MaskKind::Lower).train.lr)]
    lr: f64,
    /// Lower-body mask: `reference` (what the reference code ran: knee, ankle
    /// and toes of one leg) or `legs` (both legs from the hips, the synth mask).
    #[arg(long, default_value = "reference")]
    lower_body: LowerBody,
    /// Reconstruction loss: l1 or l2 (V-DMGNN-GAN Table 2).
    #[arg(long, default_value = "l1")]
    loss: Reconstruction,
    /// vdmgnn: encode velocities and accelerations too (V-DMGNN-GAN Table 2).
    #[arg(long)]
    vel_acc: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

fn run_cmu(args: CmuArgs) -> anyhow::Result<()> {
    let actions: Vec<&str> = args.actions.iter().map(String::as_str).collect();
    let set = ::eval::cmu_dmgnn::CmuDmgnnSet::load(&args.data, &actions)
        .with_context(|| format!("cannot load the CMU data from {}", args.data.display()))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let started = Instant::now();
    let mut results = Vec::new();
    for model in &args.models {
        if !matches!(model, ModelKind::Dmgnn | ModelKind::Vdmgnn) {
            bail!("eval cmu runs the graph models only (dmgnn, vdmgnn), not {model}");
        }
        for mask in &args.masks {
            let mut c = CmuConfig::new(*model, *mask);
            c.train.iterations = args.iterations;
            c.train.batch_size = args.batch_size;
            c.train.lr = args.lr;
            c.lower_body = args.lower_body;
            c.options.loss = args.loss;
            if *model == ModelKind::Vdmgnn {
                c.options.vel_acc = args.vel_acc;
            }
            c.seed = args.seed;
            results.push(::eval::predict::cmu::run_cmu(
                &set,
                &c,
                Some(&args.out),
                &mut |l| log(l),
            )?);
            write_json(&args.out.join("cmu_table.json"), &results)?;
            crate::output::write_atomic(
                &args.out.join("cmu_table.md"),
                ::eval::predict::cmu::render_markdown(&results).as_bytes(),
            )?;
        }
    }
    eprintln!(
        "wrote {} in {:.0} s",
        args.out.join("cmu_table.md").display(),
        started.elapsed().as_secs_f64()
    );
    print_stdout(&::eval::predict::cmu::render_markdown(&results))
}

/// A list's default as the one comma-separated value `--help` shows and
/// `value_delimiter = ','` parses (clap would show a list's defaults
/// space-separated). Leaked: built once per parse, a few bytes.
fn listed<T: std::fmt::Display>(items: &[T]) -> &'static str {
    let joined: Vec<String> = items.iter().map(ToString::to_string).collect();
    Box::leak(joined.join(",").into_boxed_str())
}

/// Progress lines of the eval crate go to stderr.
fn log(line: &str) {
    eprintln!("{line}");
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
        table::load_fold(
            &self.data,
            self.skeleton_dir.as_deref(),
            &self.class,
            &self.test_actor,
            &log,
        )
        .with_context(|| {
            format!(
                "cannot load class `{}` from {}",
                self.class,
                self.data.display()
            )
        })
    }
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
    #[arg(long, default_value_t = VaeChoice::default().per_clip)]
    vae_per_clip: usize,
    /// VAE training iterations.
    #[arg(long, default_value_t = VaeChoice::default().iterations)]
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

impl AugmentArgs {
    fn augmentation(&self) -> anyhow::Result<Option<Augmentation>> {
        if let Some(path) = &self.recipe {
            let recipe = pipeline::Recipe::from_file(path)
                .with_context(|| format!("invalid recipe {}", path.display()))?;
            let seed = recipe.effective_seed(self.aug_seed);
            return Ok(Some(Augmentation::Recipe {
                recipe: Box::new(recipe),
                seed,
                label: path.display().to_string(),
                work: self.work.clone(),
            }));
        }
        Ok(self.vae.map(|prior| {
            Augmentation::Vae(VaeChoice {
                prior,
                per_clip: self.vae_per_clip,
                iterations: self.vae_iterations,
                adversarial_weight: self.vae_adversarial_weight,
                seed: self.aug_seed.unwrap_or(0),
            })
        }))
    }
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
        let aug = args
            .aug
            .augmentation()?
            .context("give --recipe, --vae or --files")?;
        (aug.label(), aug.apply(&split.train, &log)?)
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

/// Training options shared by `predict` and `table` (defaults: the eval
/// crate's [`TrainOptions::default`]).
#[derive(clap::Args, Clone)]
struct TrainArgs {
    /// Optimiser steps per model (both conditions get the same number).
    #[arg(long, default_value_t = TrainOptions::default().iterations, conflicts_with = "epochs")]
    iterations: usize,
    /// Passes over the training windows *without* augmentation (sets --iterations).
    #[arg(long)]
    epochs: Option<f64>,
    #[arg(long, default_value_t = TrainOptions::default().batch_size)]
    batch_size: usize,
    #[arg(long, default_value_t = TrainOptions::default().lr)]
    lr: f64,
    /// Models trained per condition; errors are averaged (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = listed(&TrainOptions::default().seeds))]
    seeds: Vec<u64>,
    /// Cap on training and on test windows (evenly spaced); default all.
    #[arg(long)]
    max_windows: Option<usize>,
    /// GRU state size of seq2seq.
    #[arg(long, default_value_t = TrainOptions::default().seq2seq_hidden)]
    seq2seq_hidden: usize,
    /// Hidden features per node of the GCN.
    #[arg(long, default_value_t = TrainOptions::default().gcn_hidden)]
    gcn_hidden: usize,
    /// Residual blocks (two graph convolutions each) of the GCN.
    #[arg(long, default_value_t = TrainOptions::default().gcn_stages)]
    gcn_stages: usize,
    /// Occlusion of the observed frames in training and test: none, lower
    /// (every lower-body joint) or random (each angle visible with p = 0.8).
    #[arg(long, default_value_t = TrainOptions::default().mask)]
    mask: MaskKind,
    /// Occlusion of the training frames when it differs from --mask:
    /// `--mask lower --train-mask none` is a model never shown occlusion, the
    /// baseline of the mask augmentation.
    #[arg(long)]
    train_mask: Option<MaskKind>,
    /// Reconstruction loss of dmgnn / vdmgnn: l1 or l2.
    #[arg(long, default_value_t = TrainOptions::default().graph_loss)]
    loss: Reconstruction,
    /// vdmgnn: also encode velocities and accelerations (V-DMGNN-GAN Table 2).
    #[arg(long)]
    vel_acc: bool,
}

impl TrainArgs {
    fn options(&self) -> TrainOptions {
        TrainOptions {
            iterations: self.iterations,
            epochs: self.epochs,
            batch_size: self.batch_size,
            lr: self.lr,
            seeds: self.seeds.clone(),
            max_windows: self.max_windows,
            seq2seq_hidden: self.seq2seq_hidden,
            gcn_hidden: self.gcn_hidden,
            gcn_stages: self.gcn_stages,
            mask: self.mask,
            train_mask: self.train_mask,
            graph_loss: self.loss,
            vel_acc: self.vel_acc,
        }
    }
}

#[derive(clap::Args)]
struct PredictArgs {
    #[command(flatten)]
    fold: FoldArgs,
    /// seq2seq (GRU, residual decoding), gcn (DCT + graph convolutions),
    /// dmgnn (multi-scale graph encoder, graph-GRU decoder) or vdmgnn
    /// (V-DMGNN-GAN: dmgnn made variational, with a recurrent discriminator).
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
    let config = args.train.options().config(args.model, &split)?;
    let aug = args.aug.augmentation()?;
    eprintln!(
        "{}: {} iterations, batch {}, seeds {:?}; augmentation: {}",
        args.model,
        config.train.iterations,
        config.train.batch_size,
        config.seeds,
        aug.as_ref().map_or("none".to_string(), |a| a.label())
    );
    let closure = |train: &[(String, motion::Motion)]| match &aug {
        Some(a) => a.apply(train, &log),
        None => Ok(Vec::new()),
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
        "mask": config.mask,
        "train_mask": config.train_mask.unwrap_or(config.mask),
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

/// How much physics the table spends (defaults: the eval crate's
/// [`PhysicsConfig::default`]).
#[derive(clap::Args, Clone, Debug)]
struct PhysicsArgs {
    /// Clips corrected per synthesised set (VAE near samples, IK edits), class
    /// and fold (default: 2 per training clip).
    #[arg(long)]
    correct_count: Option<usize>,
    /// Training clips corrected for the debiasing network (default: all).
    #[arg(long)]
    correct_originals: Option<usize>,
    /// PPO environment samples per clip at most (training stops earlier once
    /// the clip reaches the target R_norm; a PPO iteration is 4096 samples).
    #[arg(long, default_value_t = PhysicsConfig::default().correct_samples)]
    correct_samples: u64,
    /// Wall-time cap per clip, seconds (a safety net; samples are the budget).
    #[arg(long, default_value_t = PhysicsConfig::default().correct_budget_s)]
    correct_budget_s: f64,
    /// Debiasing network optimiser steps.
    #[arg(long, default_value_t = PhysicsConfig::default().debias_iterations)]
    debias_iterations: usize,
    /// `clip`: a policy per clip, warm-started from the best corrected
    /// original, bounded by --correct-samples; `class`: one tracker per class
    /// and fold trained on the originals, each clip judged with it and
    /// fine-tuned for at most --clip-iterations when it fails.
    #[arg(long, value_enum, default_value = "clip")]
    correct_policy: CorrectPolicy,
    /// PPO iterations of the class tracker at most (--correct-policy class).
    #[arg(long, default_value_t = PhysicsConfig::default().tracker_iterations)]
    tracker_iterations: u64,
    /// Wall-time cap of the class tracker, seconds (--correct-policy class).
    #[arg(long, default_value_t = PhysicsConfig::default().tracker_budget_s)]
    tracker_budget_s: f64,
    /// PPO iterations of a clip's fine-tuning at most (--correct-policy class).
    #[arg(long, default_value_t = PhysicsConfig::default().clip_iterations)]
    clip_iterations: u64,
    /// PPO iterations at most of a training clip's own correction
    /// (--correct-policy class); default: --clip-iterations.
    #[arg(long)]
    original_iterations: Option<u64>,
    /// Samples the class tracker fails as is start from a second tracker,
    /// trained on them from the class tracker for at most this many PPO
    /// iterations (--correct-policy class); 0 = off.
    #[arg(long, default_value_t = PhysicsConfig::default().variant_tracker_iterations)]
    variant_tracker_iterations: u64,
    /// A clip that fails on skating alone (its starting policy as is, or a
    /// rollout at the R_norm target) is trained with the sole reward's
    /// sliding term at this speed scale, m/s, from then on; 0 = never.
    #[arg(long, default_value_t = PhysicsConfig::default().skate_scale_when_skating_m_s)]
    skate_scale_when_skating: f32,
    /// Debiased rows keep the debiasing network's output as is: the corrected
    /// clip's planted feet are not put back (shows what the network alone does).
    #[arg(long)]
    debias_no_contacts: bool,
    /// The debiasing network starts as the training pairs' mean change (a
    /// constant offset) and departs from it only as far as its held-out
    /// pairs reward.
    #[arg(long)]
    debias_start_from_mean: bool,
    /// Low-pass the debiasing network's change over time with a Gaussian
    /// of this standard deviation, seconds (0: none).
    #[arg(long, default_value_t = PhysicsConfig::default().debias_smoothing_s)]
    debias_smoothing: f64,
    /// Apply the debiasing network's change at this gain in [0, 1] instead
    /// of the one its held-out pairs choose (an ablation).
    #[arg(long)]
    debias_gain: Option<f64>,
    /// What the debiaser's held-out check holds out to choose its step count
    /// and gain: a fifth of the clips (clips), or each training actor in
    /// turn (actors: the change is applied only as far as it carries over to
    /// a body the network has not seen).
    #[arg(long, value_enum, default_value_t = HoldOut::Clips)]
    debias_hold_out: HoldOut,
    /// With `--correct-policy class`: each clip's fine-tuning lowers the root
    /// force's gains from the tracker's scale to this over its
    /// `--clip-iterations` (default: hold the tracker's). Finished
    /// corrections in `--work` are reused whatever their settings: use a
    /// fresh work folder to measure it.
    #[arg(long)]
    tracker_final_residual_scale: Option<f32>,
    /// Imitate every clip with its root re-integrated from its planted feet
    /// (`[correct] plant_reference`); acceptance still compares the output
    /// with the clip as given (with --vae-no-plant: the VAE's decoded
    /// sample). Finished corrections in `--work` are reused whatever their
    /// settings: use a fresh work folder to measure it.
    #[arg(long)]
    plant_reference: bool,
    /// The training reward of a step that ends in a fall, negated, in the
    /// trackers and every correction (`[correct] fall_penalty`; the paper's
    /// reward, which acceptance reads, stays 0 on a fall). Finished
    /// corrections and trackers in `--work` are reused whatever their
    /// settings: use a fresh work folder to measure it.
    #[arg(long, default_value_t = 0.0)]
    fall_penalty: f32,
}

/// The table's correction policy, as the CLI spells it.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum CorrectPolicy {
    Clip,
    Class,
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
    #[arg(long, value_delimiter = ',', default_value = listed(&TableConfig::default().classes))]
    classes: Vec<String>,
    #[arg(long, value_delimiter = ',', default_value = listed(&TableConfig::default().test_actors))]
    test_actors: Vec<String>,
    #[arg(long, value_delimiter = ',', default_value = listed(&TableConfig::default().models))]
    models: Vec<ModelKind>,
    #[command(flatten)]
    train: TrainArgs,
    /// Noise recipe: Gaussian rotation noise, degrees (10 copies per clip).
    #[arg(long, default_value_t = TableConfig::default().noise_sigma_deg)]
    noise_sigma_deg: f64,
    /// VAE training iterations per class and fold.
    #[arg(long, default_value_t = TableConfig::default().vae_iterations)]
    vae_iterations: u64,
    /// Also train the VAE without discriminators (min DTW / MMD ablation).
    #[arg(long)]
    vae_ablation: bool,
    /// Draw the VAE's near codes between this many training clips of a
    /// cluster (default: the VAE's own, the paper's 2; 1 samples near single
    /// clips).
    #[arg(long)]
    vae_near_members: Option<usize>,
    /// Weight of the VAE's pose-speed term on mixed codes (0 = off): keeps
    /// near samples of fast classes (jog) from standing frozen
    /// (crates/vae/README.md, session 18; crates/eval/README.md, jog).
    #[arg(long, default_value_t = TableConfig::default().vae_mixed_motion_weight)]
    vae_mixed_motion_weight: f64,
    /// Weight of the VAE's ground-contact term on mixed codes (0 = off):
    /// moving near samples otherwise hover (crates/vae/README.md, session 33).
    #[arg(long, default_value_t = TableConfig::default().vae_mixed_contact_weight)]
    vae_mixed_contact_weight: f64,
    /// Weight of the VAE's sole term on mixed codes (0 = off): planted feet
    /// of moving near samples otherwise stand on a heel or a toe
    /// (crates/vae/README.md, session 34).
    #[arg(long, default_value_t = TableConfig::default().vae_mixed_sole_weight)]
    vae_mixed_sole_weight: f64,
    /// Weight of the VAE's travel term on mixed codes (0 = off): with the
    /// contact and skating terms, moving near samples otherwise stop
    /// halfway (crates/vae/README.md, session 34).
    #[arg(long, default_value_t = TableConfig::default().vae_mixed_travel_weight)]
    vae_mixed_travel_weight: f64,
    /// Weight of the VAE's balance term on mixed codes (0 = off): keeps a
    /// sample's zero moment point no further outside its feet than its two
    /// parents'; jog samples far outside fall in the simulator (crates/eval/README.md,
    /// session 35).
    #[arg(long, default_value_t = TableConfig::default().vae_mixed_balance_weight)]
    vae_mixed_balance_weight: f64,
    /// Weight of the VAE's skating term on mixed codes (default: the vae
    /// crate's 0.1).
    #[arg(long)]
    vae_skating_weight: Option<f64>,
    /// Low-pass each VAE sample (Gaussian, seconds; 0 = as decoded) before
    /// its root is planted: decoded clips jitter (crates/vae/README.md).
    #[arg(long, default_value_t = TableConfig::default().vae_smooth_s)]
    vae_smooth_s: f64,
    /// Keep each VAE sample's decoded root instead of re-integrating it from
    /// the planted feet: the correction's skating limit is then the decoder's
    /// own skating. Finished corrections in `--work` are reused whatever
    /// their settings: use a fresh work folder to measure it.
    #[arg(long)]
    vae_no_plant: bool,
    /// Train the VAE on the clips as captured instead of putting each on one
    /// floor (HDM05's actors stand 0-3 cm apart; crates/vae/README.md). Tables
    /// made before this option existed were made this way.
    #[arg(long)]
    vae_captured_floors: bool,
    /// Skip the prediction part (synthesis metrics only).
    #[arg(long)]
    no_predict: bool,
    /// Synthesised sets: noise, ik, vae (near and prior samples), vae_ik (the
    /// VAE's near samples and the IK edits together, time-warped +-10 %; needs
    /// vae and ik), physics (subsets of the VAE's near samples and of the IK
    /// edits as made, physically corrected, and debiased; needs vae or ik).
    #[arg(long, value_delimiter = ',', default_value = listed(&TableConfig::default().sets))]
    sets: Vec<SetKind>,
    #[command(flatten)]
    physics: PhysicsArgs,
    /// Also train on each corrected subset's accepted clips as made (`_kept`
    /// rows), to tell what rejecting clips did from what correcting the rest
    /// did.
    #[arg(long)]
    kept_rows: bool,
    /// Folder for the trained VAEs and the corrections (default: OUT/work); a
    /// rerun reuses them and resumes interrupted corrections.
    #[arg(long)]
    work: Option<PathBuf>,
    /// Cores to use: corrections that need nothing from each other, and a
    /// cell's prediction models, run this many at a time (the VAE and the
    /// class trackers train on one). The numbers do not depend on it.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    threads: u16,
}

impl TableArgs {
    fn config(&self) -> TableConfig {
        let p = &self.physics;
        TableConfig {
            data: self.data.clone(),
            skeleton_dir: self.skeleton_dir.clone(),
            work: self.work.clone().unwrap_or_else(|| self.out.join("work")),
            classes: self.classes.clone(),
            test_actors: self.test_actors.clone(),
            models: self.models.clone(),
            train: self.train.options(),
            noise_sigma_deg: self.noise_sigma_deg,
            vae_iterations: self.vae_iterations,
            vae_ablation: self.vae_ablation,
            vae_near_members: self.vae_near_members,
            vae_mixed_motion_weight: self.vae_mixed_motion_weight,
            vae_mixed_contact_weight: self.vae_mixed_contact_weight,
            vae_mixed_sole_weight: self.vae_mixed_sole_weight,
            vae_mixed_travel_weight: self.vae_mixed_travel_weight,
            vae_mixed_balance_weight: self.vae_mixed_balance_weight,
            vae_skating_weight: self.vae_skating_weight,
            vae_smooth_s: self.vae_smooth_s,
            vae_plant_root: !self.vae_no_plant,
            vae_level_floor: !self.vae_captured_floors,
            predict: !self.no_predict,
            sets: self.sets.clone(),
            physics: PhysicsConfig {
                correct_count: p.correct_count,
                correct_originals: p.correct_originals,
                correct_samples: p.correct_samples,
                correct_budget_s: p.correct_budget_s,
                debias_iterations: p.debias_iterations,
                policy: match p.correct_policy {
                    CorrectPolicy::Clip => pipeline::PolicyKind::Clip,
                    CorrectPolicy::Class => pipeline::PolicyKind::Class,
                },
                tracker_iterations: p.tracker_iterations,
                tracker_budget_s: p.tracker_budget_s,
                clip_iterations: p.clip_iterations,
                original_iterations: p.original_iterations,
                variant_tracker_iterations: p.variant_tracker_iterations,
                skate_scale_when_skating_m_s: p.skate_scale_when_skating,
                debias_restore_contacts: !p.debias_no_contacts,
                debias_start_from_mean: p.debias_start_from_mean,
                debias_smoothing_s: p.debias_smoothing,
                debias_gain: p.debias_gain,
                debias_hold_out: p.debias_hold_out.into(),
                tracker_final_residual_scale: p.tracker_final_residual_scale,
                plant_reference: p.plant_reference,
                fall_penalty: p.fall_penalty,
            },
            kept_rows: self.kept_rows,
            threads: usize::from(self.threads),
        }
    }
}

/// The CLI's view of a table run: lines to stderr, the table rewritten after
/// every cell.
struct TableProgress<'a> {
    out: &'a std::path::Path,
}

impl table::Progress for TableProgress<'_> {
    fn line(&self, line: &str) {
        log(line);
    }

    fn cell_done(&self, table: &Table) -> ::eval::Result<()> {
        table.write(self.out)
    }
}

fn run_table(args: TableArgs) -> anyhow::Result<()> {
    let config = args.config();
    match config.validate() {
        Err(::eval::EvalError::PhysicsNeedsVae) => {
            bail!(
                "--sets physics corrects the VAE's samples and the IK edits: add vae or ik to --sets"
            )
        }
        other => other?,
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let started = Instant::now();
    table::run_table(&config, &TableProgress { out: &args.out })?;
    eprintln!(
        "wrote {} and {} in {:.0} s",
        args.out.join("table.json").display(),
        args.out.join("table.md").display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

#[derive(clap::Args)]
struct MergeArgs {
    /// `table.json` files of `eval table` runs that differ only in their
    /// classes and test actors.
    #[arg(required = true, num_args = 1..)]
    tables: Vec<PathBuf>,
    /// Output folder for the merged table.json and table.md.
    #[arg(long)]
    out: PathBuf,
}

fn run_merge(args: MergeArgs) -> anyhow::Result<()> {
    let tables = args
        .tables
        .iter()
        .map(|path| Ok((path.clone(), table::SavedTable::read(path)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let merged = table::merge(&tables)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    merged.write(&args.out)?;
    eprintln!(
        "merged {} tables ({} cells) into {} and {}",
        tables.len(),
        merged.cells.len(),
        args.out.join("table.json").display(),
        args.out.join("table.md").display()
    );
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Synth(a) => run_synth(a),
        Command::Predict(a) => run_predict(a),
        Command::Table(a) => run_table(*a),
        Command::Merge(a) => run_merge(a),
        Command::Cmu(a) => run_cmu(a),
    }
}
