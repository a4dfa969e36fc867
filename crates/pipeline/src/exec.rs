//! The one executor: runs any job of the plan, wherever it runs.
//!
//! Why it exists: the in-process runner ([`crate::run`], used by `motionaug
//! augment` and the evaluation) and the service's worker used to carry their
//! own copy of what each job kind does; now both call [`execute`] and differ
//! only in where inputs come from and where outputs go:
//! * [`Inputs`]: what a job reads (source clips, clips earlier jobs made,
//!   corrections of the originals, the debiasing network), implemented over
//!   memory by the runner and over HTTP by the worker;
//! * [`Outputs`]: what a job makes, as typed values ([`Made`]), handed over one
//!   at a time so the worker can upload and checkpoint after each;
//! * [`Context`]: the job's own folder (a correction's checkpoints, the
//!   debiasing model) and how to report progress and be stopped.
//!
//! The job carries its settings (resolved at planning, [`crate::plan`]); the
//! science of each kind is in [`crate::stages`].

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use motion::Motion;

use crate::PipelineError;
use crate::manifest::{CorrectionSummary, ManifestEntry};
use crate::plan::{JobKind, PlannedJob};
use crate::run::Clip;
use crate::stages::{self, NewClip};

/// A clip between two of its jobs: its motion as the last job left it, and
/// its manifest entry so far.
#[derive(Debug, Clone)]
pub struct WorkClip {
    pub name: String,
    pub motion: Motion,
    pub mask: Option<synth::Mask>,
    pub entry: ManifestEntry,
}

impl WorkClip {
    /// A clip made outside the plan (the evaluation table's VAE samples, for
    /// a plan of [`crate::plan::corrections`]), with a manifest entry that
    /// names only it.
    pub fn given(name: &str, motion: Motion) -> WorkClip {
        WorkClip {
            name: name.to_string(),
            entry: ManifestEntry {
                synth: synth::ManifestEntry {
                    file: name.to_string(),
                    source: name.to_string(),
                    op: "given".into(),
                    op_index: 0,
                    copy: 0,
                    seed: 0,
                    params: serde_json::Value::Null,
                    sampled: serde_json::Map::new(),
                    frames: motion.frames(),
                    fps: motion.fps(),
                    effector: None,
                    keyframe: None,
                    target: None,
                },
                correction: None,
                debiased: false,
            },
            motion,
            mask: None,
        }
    }

    fn made(clip: NewClip) -> WorkClip {
        WorkClip {
            name: clip.name,
            motion: clip.motion,
            mask: clip.mask,
            entry: ManifestEntry {
                synth: clip.entry,
                correction: None,
                debiased: false,
            },
        }
    }
}

/// What a job reads.
pub trait Inputs {
    /// A source clip of the dataset.
    fn source(&self, name: &str) -> Result<Clip, PipelineError>;
    /// The clip `name` as the input job that made (or corrected) it left it;
    /// `None` when that job's correction was rejected (nothing to work on).
    fn clip(&self, name: &str) -> Result<Option<WorkClip>, PipelineError>;
    /// The report of source clip `name`'s correction (`correct_original`).
    fn original_report(&self, name: &str) -> Result<correct::Report, PipelineError>;
    /// The checkpoints folder of source clip `name`'s correction (a warm start).
    fn original_checkpoints(&self, name: &str) -> Result<PathBuf, PipelineError>;
    /// Source clip `name` as its correction left it, when that was accepted.
    fn corrected_original(&self, name: &str) -> Result<Option<Motion>, PipelineError>;
    /// The debiasing network `debias_train` made.
    fn debiaser(&self) -> Result<Arc<debias::Debiaser>, PipelineError>;
    /// The folder of class `group`'s tracker (`class.json`, `checkpoints/`).
    fn tracker(&self, group: &str) -> Result<PathBuf, PipelineError>;
    /// The folder of the second tracker of class `group`'s new clips
    /// (`variant_tracker`) when new clip `clip` starts from it: the class
    /// tracker failed it as is. `None`: it starts from the class tracker.
    fn variant_tracker(&self, group: &str, clip: &str) -> Result<Option<PathBuf>, PipelineError>;
}

/// What a job made.
pub enum Made {
    /// A clip: final when the job [`PlannedJob::finishes`] it, else kept for
    /// the job that works on it next.
    Clip(WorkClip),
    /// A correction that was not accepted (and `keep_rejected` is off): the
    /// clip is left out of the outputs. Its report stays in the job's folder.
    Rejected {
        clip: String,
        correction: CorrectionSummary,
    },
    /// A source clip's correction (`correct_original`); its checkpoints and
    /// report are in the job's folder.
    Original {
        clip: String,
        outcome: correct::Outcome,
    },
    /// The debiasing network (`debias_train`), also saved in the job's folder.
    Debiaser(debias::Debiaser),
    /// A class tracker (`tracker`): its report; `class.json` and its
    /// checkpoints are in the job's folder.
    Tracker {
        group: String,
        report: correct::ClassReport,
    },
    /// The class tracker's verdict on a class's new clips, and the second
    /// tracker trained on those it failed (`variant_tracker`): the verdict in
    /// the job's `judged/` folder, the second tracker in the job's folder.
    VariantTracker {
        group: String,
        tracker: stages::VariantTracker,
    },
}

/// Where a job's results go, one at a time.
pub trait Outputs {
    fn put(&mut self, made: Made) -> Result<(), PipelineError>;
}

/// Collects everything a job made.
impl Outputs for Vec<Made> {
    fn put(&mut self, made: Made) -> Result<(), PipelineError> {
        self.push(made);
        Ok(())
    }
}

/// How a job runs.
pub struct Context<'a> {
    /// The job's own folder: a correction's checkpoints and report (a finished
    /// correction found there is reused, an interrupted one resumed), the
    /// debiasing model.
    pub dir: &'a Path,
    /// Outputs an earlier attempt of this job already handed over: they are
    /// made again (each has its own seed) but not handed over twice.
    pub skip: usize,
    /// What the manifest calls a correction's report (relative to the
    /// results), or `None` to leave it out.
    pub report_path: Option<String>,
    /// Store a correction checkpoint this often instead of the default (the
    /// service's workers, so that another worker can resume a job).
    pub checkpoint_every_s: Option<f64>,
    /// Set from another thread to stop (cancellation, shutdown): corrections
    /// save a checkpoint first; the job returns [`PipelineError::Stopped`].
    pub stop: Option<Arc<AtomicBool>>,
    /// Changes to every correction's settings beyond the recipe's (the
    /// evaluation table bounds corrections by samples on one thread).
    pub tune_correction: Option<&'a (dyn Fn(&mut correct::CorrectConfig) + Sync)>,
    /// Rollout threads of the job's PPO, over the recipe's and the tweaks':
    /// the runner gives corrections that run side by side one thread each.
    pub rollout_threads: Option<usize>,
    /// Each PPO iteration of a correction.
    pub on_progress: &'a (dyn Fn(&correct::job::ProgressEvent) + Sync),
    /// Each finished correction (a reused one too), accepted or not: its
    /// whole report and clip, beyond what the manifest keeps (the evaluation
    /// table's R_norm with action 0 and its corrected clips before debiasing).
    pub on_corrected: &'a (dyn Fn(&correct::Outcome) + Sync),
}

impl<'a> Context<'a> {
    /// A context with no stop flag, no progress and no changes: a job in `dir`.
    pub fn in_dir(dir: &'a Path) -> Context<'a> {
        Context {
            dir,
            skip: 0,
            report_path: None,
            checkpoint_every_s: None,
            stop: None,
            tune_correction: None,
            rollout_threads: None,
            on_progress: &|_| {},
            on_corrected: &|_| {},
        }
    }

    /// The context's changes to a correction's (or tracker's) settings:
    /// checkpoint period, stop flag, the caller's tweaks.
    fn apply_to(&self, config: &mut correct::CorrectConfig) {
        if let Some(every) = self.checkpoint_every_s {
            config.checkpoint_every_s = every;
        }
        config.stop = self.stop.clone();
        if let Some(tune) = self.tune_correction {
            tune(config);
        }
        if let Some(threads) = self.rollout_threads {
            config.ppo.threads = threads;
        }
    }

    fn stopped(&self) -> bool {
        self.stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
    }
}

/// The folder of a job's own files under the in-process runner's `work`
/// folder: `trackers/<group>`, `variant_trackers/<group>`, `originals/<clip>`,
/// `correct/<clip>`, `debias`; `None` for kinds that keep nothing.
pub fn job_dir(work: &Path, job: &PlannedJob) -> Option<PathBuf> {
    match &job.kind {
        JobKind::Tracker { group, .. } => Some(work.join("trackers").join(group)),
        JobKind::VariantTracker { group, .. } => Some(work.join("variant_trackers").join(group)),
        JobKind::CorrectOriginal { clip, .. } => Some(work.join("originals").join(clip)),
        JobKind::Correct { clip, .. } => Some(work.join("correct").join(clip)),
        JobKind::DebiasTrain { .. } => Some(work.join("debias")),
        _ => None,
    }
}

/// Runs `job`: reads what it needs from `inputs`, hands what it makes to `out`.
pub fn execute(
    job: &PlannedJob,
    inputs: &dyn Inputs,
    out: &mut dyn Outputs,
    ctx: &Context,
) -> Result<(), PipelineError> {
    let span = tracing::info_span!("pipeline_job", key = job.key, kind = job.kind.name());
    let _guard = span.enter();
    match &job.kind {
        JobKind::Synthesize { clip, ops, outputs } => {
            let source = inputs.source(clip)?;
            // Outputs are independent: one that fails does not stop the others,
            // but fails the job (naming the first failure) once they are made.
            let mut failed: Vec<PipelineError> = Vec::new();
            for step in outputs.iter().skip(ctx.skip) {
                if ctx.stopped() {
                    return Err(PipelineError::Stopped);
                }
                match stages::synthesize(ops, clip, &source.source, &source.motion, *step) {
                    Ok(made) => out.put(Made::Clip(WorkClip::made(made)))?,
                    Err(e) => failed.push(e),
                }
            }
            let count = failed.len();
            match failed.into_iter().next() {
                None => Ok(()),
                Some(first) if count == 1 => Err(first),
                Some(first) => Err(PipelineError::Job(format!(
                    "{count} outputs failed; the first: {first}"
                ))),
            }
        }
        JobKind::Vae {
            group,
            clips,
            seed,
            step,
            op_index,
        } => {
            let clips = clips
                .iter()
                .map(|n| Ok((n.clone(), inputs.source(n)?.motion)))
                .collect::<Result<Vec<_>, PipelineError>>()?;
            let made = stages::vae(step, *op_index, group, &clips, *seed)?;
            put_all(out, made, ctx)
        }
        JobKind::Interaction {
            pair,
            a,
            b,
            seed,
            step,
            op_index,
        } => {
            let (a, b) = (inputs.source(a)?.motion, inputs.source(b)?.motion);
            let made = stages::interaction(step, *op_index, pair, &a, &b, *seed)?;
            put_all(out, made, ctx)
        }
        JobKind::Tracker {
            group,
            clips,
            seed,
            step,
        } => {
            let clips = clips
                .iter()
                .map(|n| Ok((n.clone(), inputs.source(n)?.motion)))
                .collect::<Result<Vec<_>, PipelineError>>()?;
            let mut config = step.tracker_config(*seed);
            ctx.apply_to(&mut config.correct);
            let report = stages::train_tracker(&config, &clips, ctx.dir, ctx.on_progress)
                .map_err(stopped_is_stopped)?;
            out.put(Made::Tracker {
                group: group.clone(),
                report,
            })
        }
        JobKind::VariantTracker {
            group,
            clips,
            seed,
            step,
        } => {
            let mut made = Vec::with_capacity(clips.len());
            for name in clips {
                let clip = inputs
                    .clip(name)?
                    .ok_or_else(|| PipelineError::Job(format!("`{name}` was not made")))?;
                made.push((clip.name, clip.motion));
            }
            let class_dir = inputs.tracker(group)?;
            let mut config = step.tracker_config(*seed).correct;
            ctx.apply_to(&mut config);
            let tracker = stages::train_variant_tracker(
                &config,
                &class_dir,
                &made,
                step.variant_tracker_iterations,
                ctx.dir,
                ctx.on_progress,
            )
            .map_err(stopped_is_stopped)?;
            out.put(Made::VariantTracker {
                group: group.clone(),
                tracker,
            })
        }
        JobKind::CorrectOriginal {
            clip,
            seed,
            step,
            tracker,
        } => {
            let source = inputs.source(clip)?;
            let warm = match tracker {
                Some(group) => Warm::Tracker(inputs.tracker(group)?),
                None => Warm::None,
            };
            let config = step.original_config(*seed);
            let outcome = correction(ctx, config, clip, &source.motion, warm)?;
            out.put(Made::Original {
                clip: clip.clone(),
                outcome,
            })
        }
        JobKind::Correct {
            clip,
            tracker,
            variant_tracker,
            sources,
            seed,
            step,
        } => {
            let made = inputs
                .clip(clip)?
                .ok_or_else(|| PipelineError::Job(format!("`{clip}` was not made")))?;
            let warm = match tracker {
                Some(group) => {
                    let second = if *variant_tracker {
                        inputs.variant_tracker(group, clip)?
                    } else {
                        None
                    };
                    match second {
                        Some(dir) => {
                            tracing::info!(clip, "starts from the second tracker of its class");
                            Warm::Tracker(dir)
                        }
                        None => Warm::Tracker(inputs.tracker(group)?),
                    }
                }
                None => {
                    let outcomes = sources
                        .iter()
                        .map(|s| inputs.original_report(s).map(|r| (r.accepted, r.r_norm)))
                        .collect::<Result<Vec<_>, _>>()?;
                    match stages::best_warm_start(&outcomes) {
                        Some(i) => Warm::Checkpoints(inputs.original_checkpoints(&sources[i])?),
                        None => Warm::None,
                    }
                }
            };
            let outcome = correction(ctx, step.config(*seed), clip, &made.motion, warm)?;
            let summary = CorrectionSummary::new(&outcome.report, ctx.report_path.clone());
            if !outcome.report.accepted && !step.keep_rejected {
                tracing::info!(clip, "correction not accepted; the clip is left out");
                return out.put(Made::Rejected {
                    clip: clip.clone(),
                    correction: summary,
                });
            }
            let mut entry = made.entry;
            entry.synth.frames = outcome.motion.frames();
            entry.synth.fps = outcome.motion.fps();
            entry.correction = Some(summary);
            out.put(Made::Clip(WorkClip {
                name: made.name,
                motion: outcome.motion,
                mask: made.mask,
                entry,
            }))
        }
        JobKind::DebiasTrain { originals, config } => {
            let (mut pairs, mut actors) = (Vec::new(), Vec::new());
            for name in originals {
                // Only an accepted correction is a fair example of what the
                // simulation does to a clip: a fall teaches the debiaser nonsense.
                if let Some(corrected) = inputs.corrected_original(name)? {
                    pairs.push((corrected, inputs.source(name)?.motion));
                    actors.push(crate::plan::actor_of(name));
                }
            }
            let model = stages::debias_train(config, &pairs, &actors)?;
            model.save(ctx.dir)?;
            out.put(Made::Debiaser(model))
        }
        JobKind::DebiasApply { clip } => {
            // `None`: its correction was not accepted; nothing to debias.
            let Some(made) = inputs.clip(clip)? else {
                return Ok(());
            };
            let model = inputs.debiaser()?;
            let motion = stages::debias_apply(&model, &made.motion)?;
            let mut entry = made.entry;
            entry.debiased = true;
            out.put(Made::Clip(WorkClip {
                motion,
                entry,
                ..made
            }))
        }
    }
}

/// Hands over the clips of a dataset-level job, after the first `ctx.skip`.
fn put_all(out: &mut dyn Outputs, made: Vec<NewClip>, ctx: &Context) -> Result<(), PipelineError> {
    for clip in made.into_iter().skip(ctx.skip) {
        out.put(Made::Clip(WorkClip::made(clip)))?;
    }
    Ok(())
}

/// Training stopped on request is the job stopping, not failing.
fn stopped_is_stopped(e: PipelineError) -> PipelineError {
    match e {
        PipelineError::Correct(correct::CorrectError::Stopped) => PipelineError::Stopped,
        other => other,
    }
}

/// Where a correction's policy starts.
enum Warm {
    /// From scratch.
    None,
    /// From another correction's checkpoints (the source clip's).
    Checkpoints(PathBuf),
    /// From the class tracker in this folder, with its observation and
    /// residual scale.
    Tracker(PathBuf),
}

/// A correction in the job's folder with the job's settings (`config`) and
/// the context's changes.
fn correction(
    ctx: &Context,
    mut config: correct::CorrectConfig,
    name: &str,
    motion: &Motion,
    warm: Warm,
) -> Result<correct::Outcome, PipelineError> {
    ctx.apply_to(&mut config);
    let warm_start = match warm {
        Warm::None => None,
        Warm::Checkpoints(dir) => Some(dir),
        Warm::Tracker(dir) => {
            let report = correct::ClassReport::read(&dir.join(correct::class::REPORT_FILE))?;
            config = report.warm_config(&config, &dir);
            Some(correct::class::checkpoints_of(&dir))
        }
    };
    // The clip as it was before correction, beside the corrected one (the
    // viewer plays them side by side).
    std::fs::create_dir_all(ctx.dir).map_err(|source| PipelineError::Io {
        path: ctx.dir.to_path_buf(),
        source,
    })?;
    motion::io::save(motion, ctx.dir.join("input.bvh"))?;
    let outcome = stages::correct_with_config(
        config,
        name,
        motion,
        ctx.dir,
        warm_start.as_deref(),
        ctx.on_progress,
    )
    .map_err(stopped_is_stopped)?;
    (ctx.on_corrected)(&outcome);
    Ok(outcome)
}
