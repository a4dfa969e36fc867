//! `motionaug augment IN... --recipe RECIPE --out DIR [--seed N]`.
//!
//! Every input is read and checked before any work starts, so a typo in the
//! tenth file does not cost the first nine clips' work. Clips run in parallel;
//! each output is written atomically as BVH + NPZ as soon as it is made, and
//! `manifest.json` lists every output at the end (sorted, so it does not depend
//! on thread scheduling).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use motion::Motion;
use rayon::prelude::*;
use synth::{Generated, ManifestEntry, Recipe};

use crate::input::{ClipArgs, clip_name};
use crate::output::{write_atomic, write_json};
use crate::progress;

#[derive(clap::Args)]
pub struct Args {
    /// Input clips (BVH, or AMC with --skeleton).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// Recipe file: TOML (`[[ops]]` tables), or JSON with the same structure.
    #[arg(long)]
    recipe: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Seed for every random draw; overrides the recipe's `seed`.
    #[arg(long)]
    seed: Option<u64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let recipe = read_recipe(&args.recipe)?;
    let seed = recipe.effective_seed(args.seed);
    let clips = load_all(&args.inputs, &args.clip)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;

    let total = (clips.len() * recipe.outputs_per_clip()) as u64;
    let bar = progress::bar(total, "augment");
    let results: Vec<(String, anyhow::Result<ManifestEntry>)> = clips
        .par_iter()
        .flat_map_iter(|(name, source, motion)| {
            let recipe = &recipe;
            let bar = &bar;
            let out = &args.out;
            recipe.jobs(name, seed).into_iter().map(move |job| {
                let entry = synth::run_job(recipe, name, motion, job)
                    .map_err(anyhow::Error::from)
                    .and_then(|generated| write_output(out, &generated, source));
                bar.inc(1);
                (name.clone(), entry)
            })
        })
        .collect();
    bar.finish_and_clear();

    let mut manifest = Vec::new();
    let mut failures = Vec::new();
    for (clip, result) in results {
        match result {
            Ok(entry) => manifest.push(entry),
            Err(err) => failures.push(format!("{clip}: {err:#}")),
        }
    }
    manifest.sort_by(|a, b| {
        (a.source.as_str(), a.op_index, a.copy).cmp(&(b.source.as_str(), b.op_index, b.copy))
    });
    write_json(&args.out.join("manifest.json"), &manifest)?;
    eprintln!(
        "wrote {} outputs from {} clips to {}",
        manifest.len(),
        clips.len(),
        args.out.display()
    );
    if !failures.is_empty() {
        bail!(
            "{} of {} outputs failed:\n  {}",
            failures.len(),
            total,
            failures.join("\n  ")
        );
    }
    Ok(())
}

fn read_recipe(path: &Path) -> anyhow::Result<Recipe> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read recipe {}", path.display()))?;
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let recipe = if is_json {
        Recipe::from_json_str(&text)
    } else {
        Recipe::from_toml_str(&text)
    };
    recipe.with_context(|| format!("bad recipe {}", path.display()))
}

/// Read every input (in parallel) and fail with every bad file named.
fn load_all(inputs: &[PathBuf], args: &ClipArgs) -> anyhow::Result<Vec<(String, String, Motion)>> {
    let loaded: Vec<anyhow::Result<Motion>> = inputs.par_iter().map(|p| args.load(p)).collect();
    let mut clips = Vec::new();
    let mut errors = Vec::new();
    let mut seen: HashMap<String, &Path> = HashMap::new();
    for (path, result) in inputs.iter().zip(loaded) {
        match result {
            Ok(motion) => {
                let name = clip_name(path);
                if let Some(other) = seen.insert(name.clone(), path) {
                    errors.push(format!(
                        "{} and {} have the same name `{name}`; outputs would collide",
                        other.display(),
                        path.display()
                    ));
                }
                clips.push((name, path.display().to_string(), motion));
            }
            Err(err) => errors.push(format!("{err:#}")),
        }
    }
    if !errors.is_empty() {
        bail!(
            "{} input(s) cannot be used:\n  {}",
            errors.len(),
            errors.join("\n  ")
        );
    }
    Ok(clips)
}

/// Write one output as `<name>.bvh` and `<name>.npz` (with its occlusion mask
/// as a `mask` array, uint8 [T, J], 1 = visible) and describe it.
fn write_output(out: &Path, generated: &Generated, source: &str) -> anyhow::Result<ManifestEntry> {
    let motion = &generated.output.motion;
    let bvh_name = format!("{}.bvh", generated.name);
    let npz_name = format!("{}.npz", generated.name);
    write_atomic(&out.join(&bvh_name), &motion::bvh::to_bytes(motion))?;
    let mut extras = Vec::new();
    if let Some(mask) = &generated.output.mask {
        let visible: Vec<bool> = mask.rows().into_iter().flatten().collect();
        extras.push(motion::npz::NpyArray::bool(
            "mask",
            &[motion.frames(), motion.joints()],
            &visible,
        )?);
    }
    write_atomic(
        &out.join(&npz_name),
        &motion::npz::motion_to_bytes(motion, &extras)?,
    )?;
    Ok(generated.manifest_entry(bvh_name, source))
}
