//! `motionaug interaction ...`: two-person interactions across body sizes.
//!
//! * `retarget A.bvh B.bvh --scale S --out DIR`: one variation with B's bones
//!   scaled (one factor, or per bone with `--scale-json`); writes `A.bvh`,
//!   `B.bvh`, `A.npz`, `B.npz` and `report.json` (bone-length error, key
//!   joint-pair distance error, key pairs, foot skating, wall time).
//! * `variations A.bvh B.bvh --count N --min 0.75 --max 1.25 --seed S --out DIR`:
//!   a dataset of variations from the optimiser, one sub-directory per
//!   variation (`0000/A.bvh`, ...) and `manifest.json` listing scales and reports.
//!
//! The learned model (crate `interaction-model`):
//!
//! * `dataset --pairs DIR --out DATA`: the optimiser's variations of every
//!   pair `<name>_A.bvh` + `<name>_B.bvh` in DIR at 30 fps, cached as
//!   `dataset.json` + one NPZ per pair.
//! * `train DATA --out MODEL`: train the three networks (safetensors + JSON).
//! * `generate MODEL A.bvh B.bvh [--scale S] --out DIR`: one variation by the
//!   model (B's scale given, or drawn from the skeleton prior); writes `A.bvh`,
//!   `B.bvh`, `A.npz`, `B.npz`, `report.json`.
//! * `eval DATA --out DIR [--pairs DIR]`: the four-split table (E_r, E_b, JPD,
//!   FID) and the comparison with the optimiser: `eval.json` + `eval.md`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use interaction::{BoneScale, RetargetOptions, Retargeted, VariationSpec};
use motion::Motion;

use crate::input::ClipArgs;
use crate::output::{write_atomic, write_json};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Retarget an interaction to a partner B of another body size.
    Retarget(RetargetArgs),
    /// Generate many variations over a scale range (training data).
    Variations(VariationArgs),
    /// Build the learned model's training data with the optimiser (cached on disk).
    Dataset(DatasetArgs),
    /// Train the learned model (skeleton prior, retargeting and adaptation networks).
    Train(TrainArgs),
    /// Make one variation with a trained model (given scale, or drawn from its prior).
    Generate(GenerateArgs),
    /// Evaluate the learned model on the four splits and against the optimiser.
    Eval(EvalArgs),
}

#[derive(clap::Args)]
struct DatasetArgs {
    /// Directory of pairs `<name>_A.bvh` + `<name>_B.bvh`.
    #[arg(long)]
    pairs: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Output directory (dataset.json + one NPZ per pair).
    #[arg(long)]
    out: PathBuf,
    /// Variations per grid scale (0.75, 0.80, ..., 1.25); the first is uniform.
    #[arg(long, default_value_t = interaction_model::DatasetConfig::default().repeats)]
    repeats: usize,
    /// Per-bone jitter of the other repeats.
    #[arg(long, default_value_t = interaction_model::DatasetConfig::default().bone_jitter)]
    bone_jitter: f64,
    /// Frame rate of the data (the networks' rate).
    #[arg(long, default_value_t = interaction_model::DatasetConfig::default().fps)]
    fps: f64,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Retarget options as JSON (solver weights, key pair settings).
    #[arg(long, value_name = "JSON")]
    options: Option<PathBuf>,
}

#[derive(clap::Args)]
struct TrainArgs {
    /// Dataset directory (from `interaction dataset`).
    data: PathBuf,
    /// Model directory to write (weights.safetensors + model.json).
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().steps)]
    steps: usize,
    /// Window length in frames.
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().window)]
    window: usize,
    /// Training window stride in frames.
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().stride)]
    stride: usize,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().batch)]
    batch: usize,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().hidden)]
    hidden: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(clap::Args)]
struct GenerateArgs {
    /// Model directory (from `interaction train`).
    model: PathBuf,
    a: PathBuf,
    b: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// One factor for all of B's bones; without it (and --scale-json) the
    /// scale is drawn from the model's skeleton prior.
    #[arg(long, conflicts_with = "scale_json")]
    scale: Option<f64>,
    /// Per-bone factors: a JSON file or inline JSON (as for `retarget`).
    #[arg(long, value_name = "FILE|JSON")]
    scale_json: Option<String>,
    /// Seed of the prior draw.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct EvalArgs {
    /// Dataset directory (from `interaction dataset`).
    data: PathBuf,
    /// Output directory: eval.json, eval.md.
    #[arg(long)]
    out: PathBuf,
    /// The source pairs (as given to `dataset`), for the whole-clip comparison
    /// with the optimiser; without it the comparison is skipped.
    #[arg(long)]
    pairs: Option<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// Training steps per fold.
    #[arg(long, default_value_t = 300)]
    steps: usize,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().window)]
    window: usize,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().stride)]
    stride: usize,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().batch)]
    batch: usize,
    #[arg(long, default_value_t = interaction_model::TrainConfig::default().hidden)]
    hidden: usize,
    /// Training steps of the FID feature network.
    #[arg(long, default_value_t = interaction_model::eval::EvalConfig::default().feature_steps)]
    feature_steps: usize,
    /// Folds trained at once (each on one thread).
    #[arg(long, default_value_t = interaction_model::eval::EvalConfig::default().jobs)]
    jobs: usize,
    /// Only these splits (random, cross_scale, cross_interaction, cross_scale_interaction).
    #[arg(long = "split")]
    splits: Vec<String>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Options shared by both subcommands.
#[derive(clap::Args)]
struct PairArgs {
    /// Partner A's clip (keeps its body).
    a: PathBuf,
    /// Partner B's clip (gets the new body); same frame count, same world frame.
    b: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// A key joint pair `A_JOINT:B_JOINT` to keep at its source distance
    /// (repeatable); without it, pairs are detected (sustained proximity).
    #[arg(long = "key-pair", value_name = "A_JOINT:B_JOINT")]
    key_pairs: Vec<String>,
    /// Distance under which two joints are in contact, for key pair detection, metres.
    #[arg(long, default_value_t = interaction::KeyPairOptions::default().threshold_m)]
    pair_threshold: f64,
    /// Do not hold planted feet in place.
    #[arg(long)]
    no_plant_feet: bool,
    /// Retarget options as JSON (solver weights, key pair settings); flags above win.
    #[arg(long, value_name = "JSON")]
    options: Option<PathBuf>,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct RetargetArgs {
    #[command(flatten)]
    pair: PairArgs,
    /// One factor for all of B's bones, e.g. 1.2.
    #[arg(long, conflicts_with = "scale_json")]
    scale: Option<f64>,
    /// Per-bone factors: a JSON file or inline JSON, `1.2` or
    /// `{"default": 1.0, "bones": {"LeftArm": 1.1}}` (bones named by the joint they end at).
    #[arg(long, value_name = "FILE|JSON")]
    scale_json: Option<String>,
}

#[derive(clap::Args)]
struct VariationArgs {
    #[command(flatten)]
    pair: PairArgs,
    #[arg(long, default_value_t = 10)]
    count: usize,
    #[arg(long, default_value_t = 0.75)]
    min: f64,
    #[arg(long, default_value_t = 1.25)]
    max: f64,
    /// Relative per-bone jitter on top of the global factor (left/right kept equal).
    #[arg(long, default_value_t = 0.0)]
    bone_jitter: f64,
    /// Evenly spaced factors from --min to --max instead of random draws.
    #[arg(long)]
    grid: bool,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Retarget(a) => retarget(a),
        Command::Variations(v) => variations(v),
        Command::Dataset(d) => dataset(d),
        Command::Train(t) => train(t),
        Command::Generate(g) => generate(g),
        Command::Eval(e) => eval(e),
    }
}

impl PairArgs {
    fn load(&self) -> anyhow::Result<(Motion, Motion)> {
        Ok((self.clip.load(&self.a)?, self.clip.load(&self.b)?))
    }

    fn options(&self) -> anyhow::Result<RetargetOptions> {
        let mut o: RetargetOptions = match &self.options {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read {}", path.display()))?;
                serde_json::from_str(&text)
                    .with_context(|| format!("bad retarget options {}", path.display()))?
            }
            None => RetargetOptions::default(),
        };
        o.key_pairs.threshold_m = self.pair_threshold;
        if self.no_plant_feet {
            o.plant_feet = false;
        }
        for spec in &self.key_pairs {
            let Some((a, b)) = spec.split_once(':') else {
                bail!("--key-pair `{spec}`: expected A_JOINT:B_JOINT, e.g. RightHand:RightHand");
            };
            o.key_pairs
                .named
                .push((a.trim().to_string(), b.trim().to_string()));
        }
        Ok(o)
    }

    fn create_out(&self) -> anyhow::Result<()> {
        std::fs::create_dir_all(&self.out)
            .with_context(|| format!("cannot create {}", self.out.display()))
    }
}

fn parse_scale(args: &RetargetArgs) -> anyhow::Result<BoneScale> {
    scale_from(args.scale, &args.scale_json)?
        .ok_or_else(|| anyhow::anyhow!("give --scale FACTOR or --scale-json FILE|JSON"))
}

fn scale_from(
    scale: Option<f64>,
    scale_json: &Option<String>,
) -> anyhow::Result<Option<BoneScale>> {
    Ok(Some(match (scale, scale_json) {
        (Some(s), _) => BoneScale::uniform(s)?,
        (None, Some(text)) => {
            let path = Path::new(text);
            let json = if path.is_file() {
                std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read {}", path.display()))?
            } else {
                text.clone()
            };
            BoneScale::from_json_str(&json).with_context(|| format!("--scale-json `{text}`"))?
        }
        (None, None) => return Ok(None),
    }))
}

/// Write `A.bvh`, `B.bvh`, `A.npz`, `B.npz` and `report.json` into `dir`.
fn write_result(dir: &Path, result: &Retargeted) -> anyhow::Result<()> {
    for (name, m) in [("A", &result.a), ("B", &result.b)] {
        write_atomic(&dir.join(format!("{name}.bvh")), &motion::bvh::to_bytes(m))?;
        write_atomic(
            &dir.join(format!("{name}.npz")),
            &motion::npz::motion_to_bytes(m, &[])?,
        )?;
    }
    write_json(&dir.join("report.json"), &result.report)
}

fn retarget(args: RetargetArgs) -> anyhow::Result<()> {
    let scale = parse_scale(&args)?;
    let options = args.pair.options()?;
    let (a, b) = args.pair.load()?;
    let result = interaction::retarget(&a, &b, &scale, &options)
        .with_context(|| format!("{} + {}", args.pair.a.display(), args.pair.b.display()))?;
    args.pair.create_out()?;
    write_result(&args.pair.out, &result)?;
    let r = &result.report;
    eprintln!(
        "wrote {}: {} key pair(s), jpd {}, bone error {:.1e} m, foot skating {:+.3} m/s, {:.2} s",
        args.pair.out.display(),
        r.key_pairs.len(),
        r.jpd_m
            .map(|j| format!("{j:.4} m"))
            .unwrap_or_else(|| "n/a".into()),
        r.bone_error_m,
        r.foot_skating.change_m_s,
        r.wall_s
    );
    Ok(())
}

#[derive(serde::Serialize)]
struct ManifestEntry<'a> {
    index: usize,
    dir: String,
    report: &'a interaction::Report,
}

fn variations(args: VariationArgs) -> anyhow::Result<()> {
    let spec = VariationSpec {
        count: args.count,
        scale_min: args.min,
        scale_max: args.max,
        bone_jitter: args.bone_jitter,
        grid: args.grid,
        seed: args.seed,
    };
    spec.validate()?;
    let options = args.pair.options()?;
    let (a, b) = args.pair.load()?;
    let all = interaction::variations(&a, &b, &spec, &options)?;
    args.pair.create_out()?;
    let mut manifest = Vec::new();
    for v in &all {
        let dir = format!("{:04}", v.index);
        let path = args.pair.out.join(&dir);
        std::fs::create_dir_all(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        write_result(&path, &v.result)?;
        manifest.push(ManifestEntry {
            index: v.index,
            dir,
            report: &v.result.report,
        });
    }
    write_json(&args.pair.out.join("manifest.json"), &manifest)?;
    eprintln!(
        "wrote {} variations to {}",
        all.len(),
        args.pair.out.display()
    );
    Ok(())
}

/// The pairs `<name>_A.bvh` + `<name>_B.bvh` of a directory, by name: the
/// BVH files' stems paired by `interaction::pairs`, the rule the pipeline and
/// the service use.
fn find_pairs(dir: &Path) -> anyhow::Result<Vec<(String, PathBuf, PathBuf)>> {
    let mut stems = Vec::new();
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))?;
    for e in entries {
        let path = e?.path();
        let is_bvh = path
            .extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("bvh"));
        if let (true, Some(stem)) = (is_bvh, path.file_stem().and_then(|n| n.to_str())) {
            stems.push((stem.to_string(), path.clone()));
        }
    }
    let names: Vec<String> = stems.iter().map(|(n, _)| n.clone()).collect();
    let path_of = |name: &str| {
        stems
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, p)| p.clone())
            .unwrap_or_default()
    };
    let out: Vec<_> = interaction::pairs(&names)
        .into_iter()
        .map(|(stem, a, b)| (stem, path_of(&a), path_of(&b)))
        .collect();
    if out.is_empty() {
        bail!("{}: no pairs <name>_A.bvh + <name>_B.bvh", dir.display());
    }
    Ok(out)
}

fn load_pairs(dir: &Path, clip: &ClipArgs) -> anyhow::Result<Vec<(String, Motion, Motion)>> {
    find_pairs(dir)?
        .into_iter()
        .map(|(name, a, b)| Ok((name, clip.load(&a)?, clip.load(&b)?)))
        .collect()
}

fn dataset(args: DatasetArgs) -> anyhow::Result<()> {
    let mut config = interaction_model::DatasetConfig {
        fps: args.fps,
        repeats: args.repeats,
        bone_jitter: args.bone_jitter,
        seed: args.seed,
        ..Default::default()
    };
    if let Some(path) = &args.options {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        config.retarget = serde_json::from_str(&text)
            .with_context(|| format!("bad retarget options {}", path.display()))?;
    }
    config.grid()?;
    let pairs = load_pairs(&args.pairs, &args.clip)?;
    eprintln!(
        "making {} variations of each of {} pairs with the optimiser",
        config.grid()?.len() * config.repeats,
        pairs.len()
    );
    let data = interaction_model::Dataset::build(&pairs, &config)?;
    data.save(&args.out)?;
    for p in &data.pairs {
        let mean_s = p.variations.iter().map(|v| v.wall_s).sum::<f64>() / p.variations.len() as f64;
        eprintln!(
            "  {}: {} frames at {} fps, {} variations, optimiser {:.3} s / variation",
            p.name,
            p.frames,
            p.fps,
            p.variations.len(),
            mean_s
        );
    }
    eprintln!("wrote {} ({:.1} s)", args.out.display(), data.build_wall_s);
    Ok(())
}

fn train(args: TrainArgs) -> anyhow::Result<()> {
    let data = interaction_model::Dataset::load(&args.data)?;
    let config = interaction_model::TrainConfig {
        steps: args.steps,
        window: args.window,
        stride: args.stride,
        batch: args.batch,
        hidden: args.hidden,
        seed: args.seed,
        ..Default::default()
    };
    let windows = data.windows(config.window, config.stride, |_, _| true);
    eprintln!(
        "training on {} windows of {} frames from {} pairs",
        windows.len(),
        config.window,
        data.pairs.len()
    );
    let bar = crate::progress::bar(config.steps as u64, "steps");
    let mut progress = |step: usize, l: &interaction_model::train::Losses| {
        bar.set_position(step as u64 + 1);
        if step.is_multiple_of(50) {
            bar.set_message(format!(
                "loss {:.4} (B {:.3} m, A {:.3} m)",
                l.total, l.b_position_m, l.a_position_m
            ));
        }
    };
    let model = interaction_model::train(&data, &windows, &config, Some(&mut progress))?;
    bar.finish_and_clear();
    model.save(&args.out)?;
    let l = &model.meta.training.final_losses;
    eprintln!(
        "wrote {}: {} parameters, {:.0} s, final loss {:.4} (mean position error B {:.4} m, A {:.4} m)",
        args.out.display(),
        model.parameter_count(),
        model.meta.training.seconds,
        l.total,
        l.b_position_m,
        l.a_position_m
    );
    Ok(())
}

fn generate(args: GenerateArgs) -> anyhow::Result<()> {
    let model = interaction_model::InteractionModel::load(&args.model)?;
    let a = args.clip.load(&args.a)?;
    let b = args.clip.load(&args.b)?;
    let (scale, task) = match scale_from(args.scale, &args.scale_json)? {
        Some(s) => (s, "retarget"),
        None => (
            interaction_model::generate::sample_scale(&model, args.seed)?,
            "generation",
        ),
    };
    let g =
        interaction_model::generate::generate(&model, &a, &b, &scale, task, &Default::default())
            .with_context(|| format!("{} + {}", args.a.display(), args.b.display()))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for (name, m) in [("A", &g.a), ("B", &g.b)] {
        write_atomic(
            &args.out.join(format!("{name}.bvh")),
            &motion::bvh::to_bytes(m),
        )?;
        write_atomic(
            &args.out.join(format!("{name}.npz")),
            &motion::npz::motion_to_bytes(m, &[])?,
        )?;
    }
    write_json(&args.out.join("report.json"), &g.report)?;
    let r = &g.report;
    eprintln!(
        "wrote {} ({}, B scale {:.3}): {} key pair(s), jpd {}, network bone error {:.4} m, {:.3} s",
        args.out.display(),
        r.task,
        r.scale.default,
        r.key_pairs.len(),
        r.jpd_m
            .map(|j| format!("{j:.4} m"))
            .unwrap_or_else(|| "n/a".into()),
        r.network_bone_error_m,
        r.wall_s
    );
    Ok(())
}

fn eval(args: EvalArgs) -> anyhow::Result<()> {
    let data = interaction_model::Dataset::load(&args.data)?;
    let sources = match &args.pairs {
        Some(dir) => load_pairs(dir, &args.clip)?,
        None => Vec::new(),
    };
    for s in &args.splits {
        if !interaction_model::eval::SPLITS.contains(&s.as_str()) {
            bail!(
                "--split `{s}`: expected one of {}",
                interaction_model::eval::SPLITS.join(", ")
            );
        }
    }
    let config = interaction_model::eval::EvalConfig {
        train: interaction_model::TrainConfig {
            steps: args.steps,
            window: args.window,
            stride: args.stride,
            batch: args.batch,
            hidden: args.hidden,
            seed: args.seed,
            ..Default::default()
        },
        feature_steps: args.feature_steps,
        jobs: args.jobs,
        test_stride: (args.window / 2).max(1),
        seed: args.seed,
        ..Default::default()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let save = |report: &interaction_model::eval::EvalReport| -> anyhow::Result<String> {
        write_json(&args.out.join("eval.json"), report)?;
        let md = interaction_model::eval::markdown(report);
        write_atomic(&args.out.join("eval.md"), md.as_bytes())?;
        Ok(md)
    };
    let mut progress = |msg: &str| eprintln!("{msg}");
    // Partial results after each split: a long run that is stopped keeps them.
    let mut on_split = |report: &interaction_model::eval::EvalReport| {
        if let Err(e) = save(report) {
            eprintln!("warning: cannot save partial results: {e:#}");
        }
    };
    let report = interaction_model::eval::evaluate(
        &data,
        &config,
        &args.splits,
        &sources,
        &mut progress,
        &mut on_split,
    )?;
    let md = save(&report)?;
    crate::output::print_stdout(&md)?;
    Ok(())
}
