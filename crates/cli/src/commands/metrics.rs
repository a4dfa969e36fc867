//! `motionaug metrics FILE --json [--soles] [--balance]`: physical
//! plausibility of a clip, and with `--soles` the correction's soles criterion
//! scored on the clip as given, with `--balance` how far its zero moment point
//! leaves its feet (so synthesised clips can be judged before paying for a
//! correction).

use std::path::PathBuf;

use crate::input::ClipArgs;
use crate::output::print_stdout;

#[derive(clap::Args)]
pub struct Args {
    /// A BVH, AMC (needs --skeleton) or NPZ clip (one motionaug wrote).
    file: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Print JSON (the default output is a short table).
    #[arg(long)]
    json: bool,
    /// Also score the soles criterion of `correct` on the clip itself: of the
    /// frames where a foot of the simulated character (its sole points,
    /// calibrated on this clip) would be planted, the share with heel and toe
    /// within the criterion's tolerance of the floor. Builds the character,
    /// so it takes a moment longer.
    #[arg(long)]
    soles: bool,
    /// Also measure whether the clip can balance on its feet: with the
    /// simulated character's masses and foot boxes, how far the zero moment
    /// point (where the floor must push for the centre of mass to move as it
    /// does) lies outside the polygon of the feet on the floor, over the
    /// frames a foot is down.
    #[arg(long)]
    balance: bool,
}

/// The input's zero moment point against its support polygon.
#[derive(serde::Serialize)]
struct Balance {
    supported_frames: usize,
    /// Supported frames with the ZMP more than `margin_m` outside.
    unbalanced_frames: usize,
    unbalanced_fraction: f64,
    margin_m: f64,
    /// Mean and largest distance outside over the supported frames, m.
    mean_outside_m: f64,
    max_outside_m: f64,
}

/// The soles criterion on the input clip.
#[derive(serde::Serialize)]
struct Soles {
    planted_frames: usize,
    flat_frames: usize,
    /// Planted, not flat, on the toes (heel up) / on the heel (toe up).
    on_toes_frames: usize,
    on_heel_frames: usize,
    /// Mean height of the higher end in the planted frames that are not flat, m.
    mean_lift_m: f64,
    /// Flat frames / planted frames (1 with no planted frame).
    flat_fraction: f64,
    /// The criterion's limit on `flat_fraction` for an accepted correction.
    min_flat_fraction: f64,
}

#[derive(serde::Serialize)]
struct Report {
    #[serde(flatten)]
    plausibility: motion::metrics::Plausibility,
    #[serde(skip_serializing_if = "Option::is_none")]
    soles: Option<Soles>,
    #[serde(skip_serializing_if = "Option::is_none")]
    balance: Option<Balance>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let motion = args.clip.load(&args.file)?;
    let config = correct::CorrectConfig::default();
    let soles = if args.soles {
        let s = correct::acceptance::input_soles(&motion, &config.physics, &config.acceptance)?;
        Some(Soles {
            planted_frames: s.planted_frames,
            flat_frames: s.flat_frames,
            on_toes_frames: s.on_toes_frames,
            on_heel_frames: s.on_heel_frames,
            mean_lift_m: s.mean_lift_m(),
            flat_fraction: s.flat_fraction(),
            min_flat_fraction: config.acceptance.min_flat_fraction,
        })
    } else {
        None
    };
    let balance = if args.balance {
        let b = correct::acceptance::input_balance(&motion, &config.physics, &config.acceptance)?;
        Some(Balance {
            supported_frames: b.supported_frames,
            unbalanced_frames: b.unbalanced_frames,
            unbalanced_fraction: b.unbalanced_fraction(),
            margin_m: b.margin_m,
            mean_outside_m: b.mean_outside_m(),
            max_outside_m: b.outside_max_m,
        })
    } else {
        None
    };
    let report = Report {
        plausibility: motion::metrics::plausibility(&motion),
        soles,
        balance,
    };
    let text = if args.json {
        serde_json::to_string_pretty(&report)? + "\n"
    } else {
        let value = serde_json::to_value(&report)?;
        let mut lines = String::new();
        for (key, v) in value.as_object().into_iter().flatten() {
            match v.as_object() {
                Some(inner) => {
                    for (k, v) in inner {
                        lines += &format!("{:<32} {v}\n", format!("{key}.{k}"));
                    }
                }
                None => lines += &format!("{key:<32} {v}\n"),
            }
        }
        lines
    };
    print_stdout(&text)
}
