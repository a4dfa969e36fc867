//! `motionaug debias train --pair CORRECTED=ORIGINAL ... --out MODEL` and
//! `motionaug debias apply MODEL IN... --out DIR`: the debiasing step on its
//! own (recipes run it with a `[debias]` table).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use debias::{Debiaser, TrainConfig};
use motion::Motion;

use crate::input::{ClipArgs, clip_name};
use crate::output::write_atomic;

/// The debiaser's held-out check, as the CLI spells it (`debias train
/// --hold-out`, `eval table --debias-hold-out`).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum HoldOut {
    Clips,
    Actors,
}

impl From<HoldOut> for debias::HoldOut {
    fn from(h: HoldOut) -> Self {
        match h {
            HoldOut::Clips => debias::HoldOut::Clips,
            HoldOut::Actors => debias::HoldOut::Actors,
        }
    }
}

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(clap::Subcommand)]
enum What {
    /// Learn the correction's bias from (corrected original, original) pairs.
    Train {
        /// `CORRECTED=ORIGINAL`: a clip after `motionaug correct` and the clip it
        /// was made from (AMC originals need --skeleton). Repeat for every pair.
        #[arg(long = "pair", required = true, value_name = "CORRECTED=ORIGINAL")]
        pairs: Vec<String>,
        #[command(flatten)]
        clip: ClipArgs,
        /// Model directory (debias.safetensors + debias.json).
        #[arg(long)]
        out: PathBuf,
        /// Optimiser steps.
        #[arg(long, default_value_t = TrainConfig::default().iterations)]
        iterations: usize,
        /// Hidden layer sizes, comma separated (paper: 512,512,512,512).
        #[arg(long, value_delimiter = ',', default_values_t = TrainConfig::default().hidden)]
        hidden: Vec<usize>,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Share of the pairs held out to choose the step count and scale the
        /// change (0: train on all for --iterations, apply at full strength).
        #[arg(long, default_value_t = TrainConfig::default().validation_fraction)]
        validation_fraction: f64,
        /// Do not put the corrected clip's planted feet back after the network
        /// (saved with the model; by default they are, see the debias crate).
        #[arg(long)]
        no_contacts: bool,
        /// Leave planted feet that hang above the floor as the correction left
        /// them (by default they are pitched down onto the sole height of the
        /// corrected originals; saved with the model).
        #[arg(long)]
        no_flatten_soles: bool,
        /// Restore feet only where the height-and-speed rule plants them, not
        /// also where the foot skating metric sees their soles on the ground
        /// (an ablation; saved with the model).
        #[arg(long)]
        no_metric_contacts: bool,
        /// Start the network as the pairs' mean change (a constant offset);
        /// training departs from it only as far as held-out pairs reward.
        #[arg(long)]
        start_from_mean: bool,
        /// Low-pass the predicted change over time with a Gaussian of this
        /// standard deviation, seconds (0: none; saved with the model).
        #[arg(long, default_value_t = TrainConfig::default().smoothing_s)]
        smoothing: f64,
        /// What the held-out check that chooses the step count and the gain
        /// holds out: --validation-fraction of the clips (clips), or each
        /// actor in turn (actors; the actor read from the ORIGINAL's file
        /// name: `HDM_<actor>_...`, else the name without a trailing `_<n>`).
        #[arg(long, value_enum, default_value_t = HoldOut::Clips)]
        hold_out: HoldOut,
    },
    /// Remove the learned bias from corrected clips.
    Apply {
        /// Model directory written by `debias train`.
        model: PathBuf,
        /// Corrected clips (BVH).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        #[command(flatten)]
        clip: ClipArgs,
        /// Output directory: `<name>.bvh` and `<name>.npz` per input.
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Train {
            pairs,
            clip,
            out,
            iterations,
            hidden,
            seed,
            validation_fraction,
            no_contacts,
            no_flatten_soles,
            no_metric_contacts,
            start_from_mean,
            smoothing,
            hold_out,
        } => {
            let contacts = debias::ContactConfig {
                restore: !no_contacts,
                flatten_soles: !no_flatten_soles,
                metric_contacts: !no_metric_contacts,
                ..debias::ContactConfig::default()
            };
            let config = TrainConfig {
                iterations,
                hidden,
                seed,
                validation_fraction,
                contacts,
                start_from_mean,
                smoothing_s: smoothing,
                hold_out: hold_out.into(),
                ..TrainConfig::default()
            };
            train(&pairs, &clip, &out, &config)
        }
        What::Apply {
            model,
            inputs,
            clip,
            out,
        } => apply(&model, &inputs, &clip, &out),
    }
}

/// Read a corrected clip onto the original's skeleton (joint for joint).
fn onto(corrected: Motion, original: &Motion, path: &Path) -> anyhow::Result<Motion> {
    let (a, b) = (corrected.skeleton(), original.skeleton());
    let same = a.len() == b.len() && (0..a.len()).all(|j| a.joint(j).name == b.joint(j).name);
    if !same {
        bail!(
            "{}: its joints are not those of its original ({} vs {} joints)",
            path.display(),
            a.len(),
            b.len()
        );
    }
    // The simulated character has rigid bones: no translation tracks.
    Ok(original.with_frames_and_tracks(
        corrected.fps(),
        corrected.root_translation().to_vec(),
        corrected.rotations().to_vec(),
        Vec::new(),
    )?)
}

fn train(
    pairs: &[String],
    clip: &ClipArgs,
    out: &Path,
    config: &TrainConfig,
) -> anyhow::Result<()> {
    let (mut loaded, mut actors) = (Vec::with_capacity(pairs.len()), Vec::new());
    for pair in pairs {
        let Some((c, o)) = pair.split_once('=') else {
            bail!("--pair `{pair}`: expected CORRECTED=ORIGINAL");
        };
        let (c, o) = (PathBuf::from(c), PathBuf::from(o));
        let original = clip.load(&o)?;
        let corrected = onto(clip.load(&c)?, &original, &c)?;
        loaded.push((corrected, original));
        actors.push(pipeline::plan::actor_of(&clip_name(&o)));
    }
    let (model, report) =
        debias::train_with_actors(&loaded, &actors, config).context("training the debiaser")?;
    model
        .save(out)
        .with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!(
        "{} pairs, {} frames: loss {:.4} -> {:.4} in {:.1} s; wrote {}",
        report.pairs,
        report.frames,
        report.loss_before,
        report.loss_after,
        report.wall_s,
        out.display()
    );
    if let (Some(zero), Some(after)) = (report.validation_loss_zero, report.validation_loss) {
        let how = match report.validation_actors {
            0 => String::new(),
            n => format!(", {n} actors in turn"),
        };
        eprintln!(
            "held out {} pairs{how}: change left {:.5} -> {:.5} (step {}, gain {:.2})",
            report.validation_pairs, zero, after, report.iterations, report.gain
        );
    }
    Ok(())
}

fn apply(model: &Path, inputs: &[PathBuf], clip: &ClipArgs, out: &Path) -> anyhow::Result<()> {
    let model =
        Debiaser::load(model).with_context(|| format!("cannot load {}", model.display()))?;
    let clips = inputs
        .iter()
        .map(|p| clip.load(p))
        .collect::<anyhow::Result<Vec<_>>>()?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    for (path, motion) in inputs.iter().zip(&clips) {
        let (debiased, contacts) = model
            .apply_with_report(motion)
            .with_context(|| format!("debiasing {}", path.display()))?;
        let name = clip_name(path);
        eprintln!(
            "{name}: {} planted foot frames kept (largest ankle error {:.1} mm), {} flattened",
            contacts.planted,
            contacts.max_ankle_error_m * 1e3,
            contacts.flattened
        );
        write_atomic(
            &out.join(format!("{name}.bvh")),
            &motion::bvh::to_bytes(&debiased),
        )?;
        write_atomic(
            &out.join(format!("{name}.npz")),
            &motion::npz::motion_to_bytes(&debiased, &[])?,
        )?;
    }
    eprintln!("wrote {} clips to {}", clips.len(), out.display());
    Ok(())
}
