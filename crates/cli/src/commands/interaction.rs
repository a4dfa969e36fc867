//! `motionaug interaction ...`: two-person interactions across body sizes.
//!
//! * `retarget A.bvh B.bvh --scale S --out DIR`: one variation with B's bones
//!   scaled (one factor, or per bone with `--scale-json`); writes `A.bvh`,
//!   `B.bvh`, `A.npz`, `B.npz` and `report.json` (bone-length error, key
//!   joint-pair distance error, key pairs, foot skating, wall time).
//! * `variations A.bvh B.bvh --count N --min 0.75 --max 1.25 --seed S --out DIR`:
//!   a dataset of variations from the optimiser, one sub-directory per
//!   variation (`0000/A.bvh`, ...) and `manifest.json` listing scales and reports.

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
    #[arg(long, default_value_t = 0.4)]
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
    match (args.scale, &args.scale_json) {
        (Some(s), _) => Ok(BoneScale::uniform(s)?),
        (None, Some(text)) => {
            let path = Path::new(text);
            let json = if path.is_file() {
                std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read {}", path.display()))?
            } else {
                text.clone()
            };
            BoneScale::from_json_str(&json).with_context(|| format!("--scale-json `{text}`"))
        }
        (None, None) => bail!("give --scale FACTOR or --scale-json FILE|JSON"),
    }
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
