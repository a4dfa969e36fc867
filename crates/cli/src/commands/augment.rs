//! `motionaug augment IN... --recipe RECIPE --out DIR [--seed N]`.
//!
//! Every input is read and checked before any work starts, so a typo in the
//! tenth file does not cost the first nine clips' work. The recipe runs as the
//! pipeline crate's job graph in this process: synthesis in parallel, then (with
//! `[correct]` / `[debias]` / `[vae]` / `[interaction]` tables) the heavier jobs
//! one after another, or corrections `--correct-threads` at a time. Each output is written atomically as BVH + NPZ once its
//! last stage is done, and `manifest.json` lists every output at the end
//! (sorted, so it does not depend on thread scheduling). Corrections keep their
//! checkpoints in `OUT/work/`: rerunning the same command after a crash reuses
//! finished corrections and resumes interrupted ones.

use std::collections::HashMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use motion::Motion;
use pipeline::{Clip, Event, Options, Recipe};
use rayon::prelude::*;

use crate::input::{ClipArgs, clip_name};
use crate::progress;

#[derive(clap::Args)]
pub struct Args {
    /// Input clips (BVH, AMC with --skeleton, or NPZ written by motionaug).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// Recipe file: TOML (`[[ops]]`, `[vae]`, `[interaction]`, `[correct]`, `[debias]`
    /// tables), or JSON with the same structure.
    #[arg(long)]
    recipe: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Seed for every random draw; overrides the recipe's `seed`.
    #[arg(long)]
    seed: Option<u64>,
    /// Corrections that need nothing from each other run this many at a
    /// time, each on one rollout thread (e.g. the cores to spare); 1 = one
    /// after the other on the recipe's `[correct]` threads.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    correct_threads: u16,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let recipe = Recipe::from_file(&args.recipe)?;
    let seed = recipe.effective_seed(args.seed);
    let clips = load_all(&args.inputs, &args.clip)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let clips: Vec<Clip> = clips
        .into_iter()
        .map(|(name, source, motion)| Clip {
            name,
            source,
            motion,
        })
        .collect();

    let bar = progress::bar(0, "augment");
    let terminal = std::io::stderr().is_terminal();
    let on_event = |event: Event<'_>| match event {
        Event::Planned { jobs } => bar.set_length(jobs as u64),
        Event::JobStarted { job } => {
            if !matches!(job.kind, pipeline::JobKind::Synthesize { .. }) {
                let line = format!("{} ...", job.key);
                if terminal {
                    bar.set_message(line);
                } else {
                    eprintln!("{line}");
                }
            }
        }
        Event::JobFinished { .. } => bar.inc(1),
        Event::Corrected { .. } => {}
        Event::Correction { job, progress: p } => {
            let r = p
                .r_norm
                .map(|r| format!("{r:.3}"))
                .unwrap_or_else(|| "-".into());
            let line = format!(
                "{}: iter {} samples {} {:.0}/{:.0} s R_norm {r}",
                job.key, p.iteration, p.samples, p.wall_s, p.budget_s
            );
            if terminal {
                bar.set_message(line);
            } else {
                eprintln!("{line}");
            }
        }
    };
    let work = args.out.join("work");
    let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
    let summary = pipeline::run_plan(
        &pipeline::plan(&recipe, &names, seed),
        &clips,
        Vec::new(),
        &Options {
            out: Some(&args.out),
            work: &work,
            seed,
            on_event: &on_event,
        },
        pipeline::Tune {
            parallel_corrections: usize::from(args.correct_threads),
            ..pipeline::Tune::default()
        },
    )?;
    bar.finish_and_clear();

    eprintln!(
        "wrote {} outputs from {} clips to {}{}",
        summary.manifest.len(),
        clips.len(),
        args.out.display(),
        if summary.rejected.is_empty() {
            String::new()
        } else {
            format!(
                " ({} not accepted by physical correction and left out: {})",
                summary.rejected.len(),
                summary.rejected.join(", ")
            )
        }
    );
    if !summary.failures.is_empty() {
        let lines: Vec<String> = summary
            .failures
            .iter()
            .map(|(job, why)| format!("{job}: {why}"))
            .collect();
        bail!(
            "{} of {} jobs failed:\n  {}",
            lines.len(),
            summary.jobs,
            lines.join("\n  ")
        );
    }
    Ok(())
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
