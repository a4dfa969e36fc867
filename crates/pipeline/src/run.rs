//! The whole augmentation in one process: walk the plan in order, keep every
//! clip in memory between its stages, and write each output once its last
//! stage is done. Expensive work survives a crash: every correction lives in
//! `work/correct/<clip>/` (checkpoints, then the finished clip and report),
//! and a rerun with the same recipe and inputs reuses or resumes it.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use motion::Motion;
use rayon::prelude::*;

use crate::PipelineError;
use crate::manifest::{CorrectionSummary, ManifestEntry};
use crate::plan::{JobKind, Plan, PlannedJob, plan};
use crate::recipe::Recipe;
use crate::stages::{self, NewClip};

/// A source clip.
#[derive(Debug, Clone)]
pub struct Clip {
    /// Unique name (file stem); outputs are named after it.
    pub name: String,
    /// Where it came from (path or upload name), for the manifest.
    pub source: String,
    pub motion: Motion,
}

/// Something happened; for progress displays and logs.
#[derive(Debug, Clone)]
pub enum Event<'a> {
    /// The plan is known.
    Planned {
        jobs: usize,
    },
    JobStarted {
        job: &'a PlannedJob,
    },
    JobFinished {
        job: &'a PlannedJob,
        ok: bool,
    },
    /// A PPO iteration of a correction finished.
    Correction {
        job: &'a PlannedJob,
        progress: &'a correct::job::ProgressEvent,
    },
}

/// Where and how to run.
pub struct Options<'a> {
    /// Write `<name>.bvh`, `<name>.npz` and `manifest.json` here; `None` keeps
    /// the outputs in memory only (evaluation).
    pub out: Option<&'a Path>,
    /// Corrections, models and other intermediate results (for `out = Some(d)`
    /// use `d/work`, so that a rerun finds them).
    pub work: &'a Path,
    pub seed: u64,
    pub on_event: &'a (dyn Fn(Event<'_>) + Sync),
}

/// One finished output.
#[derive(Debug, Clone)]
pub struct Output {
    pub name: String,
    pub motion: Motion,
    pub mask: Option<synth::Mask>,
    pub entry: ManifestEntry,
}

/// What a run made.
#[derive(Debug, Default)]
pub struct Summary {
    /// Kept outputs, in manifest order (motions only when `out` was `None`).
    pub outputs: Vec<Output>,
    pub manifest: Vec<ManifestEntry>,
    /// Outputs whose correction was not accepted (and `keep_rejected` was off).
    pub rejected: Vec<String>,
    /// Jobs that failed (or were skipped because an input failed), with the reason.
    pub failures: Vec<(String, String)>,
    pub jobs: usize,
}

struct State<'a> {
    recipe: &'a Recipe,
    options: &'a Options<'a>,
    sources: HashMap<String, &'a Clip>,
    /// Clips between stages.
    pending: HashMap<String, NewClip>,
    /// Correction summaries of corrected outputs awaiting debiasing.
    corrections: HashMap<String, CorrectionSummary>,
    /// Accepted corrections of the source clips: the debiaser's training pairs.
    corrected_originals: HashMap<String, Motion>,
    /// (accepted, R_norm) of every corrected source clip, for warm starts.
    original_outcomes: HashMap<String, (bool, f64)>,
    debiaser: Option<debias::Debiaser>,
    failed: HashSet<String>,
    summary: Summary,
    /// Output name -> key of its last job (it is written after that one).
    last_job: HashMap<String, String>,
}

/// Run `recipe` on `clips`.
pub fn run(recipe: &Recipe, clips: &[Clip], options: &Options) -> Result<Summary, PipelineError> {
    let mut names = HashSet::new();
    for c in clips {
        if !names.insert(c.name.as_str()) {
            return Err(PipelineError::Job(format!(
                "two clips are named `{}`; outputs would collide",
                c.name
            )));
        }
    }
    let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
    let plan = plan(recipe, &names, options.seed);
    (options.on_event)(Event::Planned {
        jobs: plan.jobs.len(),
    });
    let mut last_job = HashMap::new();
    for job in &plan.jobs {
        for o in &job.outputs {
            last_job.insert(o.clone(), job.key.clone());
        }
    }
    let mut state = State {
        recipe,
        options,
        sources: clips.iter().map(|c| (c.name.clone(), c)).collect(),
        pending: HashMap::new(),
        corrections: HashMap::new(),
        corrected_originals: HashMap::new(),
        original_outcomes: HashMap::new(),
        debiaser: None,
        failed: HashSet::new(),
        summary: Summary {
            jobs: plan.jobs.len(),
            ..Summary::default()
        },
        last_job,
    };
    state.run_plan(&plan)?;
    let mut summary = state.summary;
    crate::manifest::sort(&mut summary.manifest);
    summary.outputs.sort_by_key(|o| {
        summary
            .manifest
            .iter()
            .position(|e| e.synth.file == o.entry.synth.file)
    });
    if let Some(out) = options.out {
        let bytes = serde_json::to_vec_pretty(&summary.manifest)
            .map_err(|e| PipelineError::Job(e.to_string()))?;
        let mut bytes = bytes;
        bytes.push(b'\n');
        motion::io::write_atomic(&out.join("manifest.json"), &bytes)?;
    }
    Ok(summary)
}

impl<'a> State<'a> {
    fn run_plan(&mut self, plan: &Plan) -> Result<(), PipelineError> {
        let mut i = 0;
        while i < plan.jobs.len() {
            // Synthesis jobs are cheap and independent: run a whole run of them in parallel.
            let mut j = i;
            while j < plan.jobs.len() && matches!(plan.jobs[j].kind, JobKind::Synthesize { .. }) {
                j += 1;
            }
            if j > i {
                self.synthesize_batch(&plan.jobs[i..j])?;
                i = j;
                continue;
            }
            self.run_job(&plan.jobs[i])?;
            i += 1;
        }
        Ok(())
    }

    fn skip_if_inputs_failed(&mut self, job: &PlannedJob) -> bool {
        if let Some(dep) = job.deps.iter().find(|d| self.failed.contains(*d)) {
            self.fail(job, format!("skipped: {dep} failed"));
            return true;
        }
        false
    }

    fn fail(&mut self, job: &PlannedJob, reason: String) {
        tracing::warn!(job = job.key, reason, "job failed");
        self.failed.insert(job.key.clone());
        self.summary.failures.push((job.key.clone(), reason));
    }

    fn source(&self, name: &str) -> Result<&'a Clip, PipelineError> {
        self.sources
            .get(name)
            .copied()
            .ok_or_else(|| PipelineError::Job(format!("no clip named `{name}`")))
    }

    fn synthesize_batch(&mut self, jobs: &[PlannedJob]) -> Result<(), PipelineError> {
        let recipe = self.recipe;
        let on_event = self.options.on_event;
        let sources = &self.sources;
        let results: Vec<Result<NewClip, PipelineError>> = jobs
            .par_iter()
            .map(|job| {
                on_event(Event::JobStarted { job });
                let JobKind::Synthesize { clip, job: sj } = &job.kind else {
                    return Err(PipelineError::Job("not a synthesis job".into()));
                };
                let src = sources
                    .get(clip)
                    .ok_or_else(|| PipelineError::Job(format!("no clip named `{clip}`")))?;
                let r = stages::synthesize(recipe, clip, &src.source, &src.motion, *sj);
                on_event(Event::JobFinished { job, ok: r.is_ok() });
                r
            })
            .collect();
        for (job, result) in jobs.iter().zip(results) {
            match result {
                Ok(clip) => self.made(job, vec![clip])?,
                Err(e) => self.fail(job, e.to_string()),
            }
        }
        Ok(())
    }

    fn run_job(&mut self, job: &PlannedJob) -> Result<(), PipelineError> {
        if self.skip_if_inputs_failed(job) {
            return Ok(());
        }
        (self.options.on_event)(Event::JobStarted { job });
        let span = tracing::info_span!("pipeline_job", key = job.key, kind = job.kind.name());
        let _guard = span.enter();
        let result = self.execute(job);
        let ok = result.is_ok();
        if let Err(e) = result {
            // A broken output directory is fatal; a job's own failure is not.
            if let PipelineError::Io { .. } = e {
                return Err(e);
            }
            self.fail(job, e.to_string());
        }
        (self.options.on_event)(Event::JobFinished { job, ok });
        Ok(())
    }

    fn execute(&mut self, job: &PlannedJob) -> Result<(), PipelineError> {
        let recipe = self.recipe;
        match &job.kind {
            JobKind::Synthesize { .. } => self.synthesize_batch(std::slice::from_ref(job)),
            JobKind::Vae { group, clips, seed } => {
                let step = recipe.vae.as_ref().ok_or_else(|| missing("vae"))?;
                let clips = clips
                    .iter()
                    .map(|n| Ok((n.clone(), self.source(n)?.motion.clone())))
                    .collect::<Result<Vec<_>, PipelineError>>()?;
                let made = stages::vae(recipe, step, group, &clips, *seed)?;
                self.made(job, made)
            }
            JobKind::Interaction { pair, a, b, seed } => {
                let step = recipe
                    .interaction
                    .as_ref()
                    .ok_or_else(|| missing("interaction"))?;
                let (a, b) = (&self.source(a)?.motion, &self.source(b)?.motion);
                let made = stages::interaction(recipe, step, pair, a, b, *seed)?;
                self.made(job, made)
            }
            JobKind::CorrectOriginal { clip, seed } => {
                let step = recipe.correct.as_ref().ok_or_else(|| missing("correct"))?;
                let src = self.source(clip)?;
                let dir = self.original_dir(clip);
                let on_event = self.options.on_event;
                let outcome = stages::correct(step, clip, &src.motion, *seed, &dir, None, |p| {
                    on_event(Event::Correction { job, progress: p })
                })?;
                self.original_outcomes.insert(
                    clip.clone(),
                    (outcome.report.accepted, outcome.report.r_norm),
                );
                // Only an accepted correction is a fair example of what the
                // simulation does to a clip: a fall teaches the debiaser nonsense.
                if outcome.report.accepted {
                    self.corrected_originals
                        .insert(clip.clone(), outcome.motion);
                }
                Ok(())
            }
            JobKind::Correct {
                clip,
                sources,
                seed,
            } => {
                let step = recipe.correct.as_ref().ok_or_else(|| missing("correct"))?;
                let made = self
                    .pending
                    .remove(clip)
                    .ok_or_else(|| PipelineError::Job(format!("`{clip}` was not made")))?;
                let dir = self.correct_dir(clip);
                let outcomes = sources
                    .iter()
                    .map(|s| {
                        self.original_outcomes
                            .get(s)
                            .copied()
                            .ok_or_else(|| PipelineError::Job(format!("`{s}` was not corrected")))
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let warm = stages::best_warm_start(&outcomes)
                    .map(|i| self.original_dir(&sources[i]).join("checkpoints"));
                let on_event = self.options.on_event;
                let outcome = stages::correct(
                    step,
                    clip,
                    &made.motion,
                    *seed,
                    &dir,
                    warm.as_deref(),
                    |p| on_event(Event::Correction { job, progress: p }),
                );
                let outcome = match outcome {
                    Ok(o) => o,
                    Err(e) => {
                        self.pending.insert(clip.clone(), made);
                        return Err(e);
                    }
                };
                let report_path = self.options.out.and_then(|out| {
                    dir.join("report.json")
                        .strip_prefix(out)
                        .ok()
                        .map(|p| p.display().to_string())
                });
                let summary = CorrectionSummary::new(&outcome.report, report_path);
                let mut entry = ManifestEntry {
                    synth: made.entry,
                    correction: Some(summary.clone()),
                    debiased: false,
                };
                entry.synth.frames = outcome.motion.frames();
                entry.synth.fps = outcome.motion.fps();
                let accepted = outcome.report.accepted;
                // Debiasing keeps the correction's summary in the clip's manifest entry.
                self.corrections.insert(clip.clone(), summary);
                if !accepted && !step.keep_rejected {
                    self.summary.rejected.push(clip.clone());
                    self.failed.insert(job.key.clone());
                    return Ok(());
                }
                let corrected = NewClip {
                    name: made.name,
                    motion: outcome.motion,
                    mask: made.mask,
                    entry: entry.synth.clone(),
                };
                self.stage_done(job, corrected, entry)
            }
            JobKind::DebiasTrain { originals } => {
                let config = recipe.debias.as_ref().ok_or_else(|| missing("debias"))?;
                let mut pairs = Vec::with_capacity(originals.len());
                for name in originals {
                    if let Some(corrected) = self.corrected_originals.get(name) {
                        pairs.push((corrected.clone(), self.source(name)?.motion.clone()));
                    }
                }
                let model = stages::debias_train(config, &pairs)?;
                model.save(&self.options.work.join("debias"))?;
                self.debiaser = Some(model);
                Ok(())
            }
            JobKind::DebiasApply { clip } => {
                let made = self
                    .pending
                    .remove(clip)
                    .ok_or_else(|| PipelineError::Job(format!("`{clip}` was not corrected")))?;
                let model = self
                    .debiaser
                    .as_ref()
                    .ok_or_else(|| PipelineError::Job("no debiasing model".into()))?;
                let motion = stages::debias_apply(model, &made.motion)?;
                let entry = ManifestEntry {
                    correction: self.corrections.remove(clip),
                    debiased: true,
                    synth: made.entry.clone(),
                };
                self.stage_done(job, NewClip { motion, ..made }, entry)
            }
        }
    }

    fn original_dir(&self, clip: &str) -> PathBuf {
        self.options.work.join("originals").join(clip)
    }

    fn correct_dir(&self, clip: &str) -> PathBuf {
        self.options.work.join("correct").join(clip)
    }

    /// New clips from a producing job.
    fn made(&mut self, job: &PlannedJob, clips: Vec<NewClip>) -> Result<(), PipelineError> {
        for clip in clips {
            let entry = ManifestEntry {
                synth: clip.entry.clone(),
                correction: None,
                debiased: false,
            };
            self.stage_done(job, clip, entry)?;
        }
        Ok(())
    }

    /// A clip finished a stage: keep it for the next one, or write it out.
    fn stage_done(
        &mut self,
        job: &PlannedJob,
        clip: NewClip,
        entry: ManifestEntry,
    ) -> Result<(), PipelineError> {
        if self.last_job.get(&clip.name) != Some(&job.key) {
            self.pending.insert(clip.name.clone(), clip);
            return Ok(());
        }
        if let Some(out) = self.options.out {
            write_output(out, &clip)?;
        }
        let keep_motion = self.options.out.is_none();
        self.summary.manifest.push(entry.clone());
        if keep_motion {
            self.summary.outputs.push(Output {
                name: clip.name,
                motion: clip.motion,
                mask: clip.mask,
                entry,
            });
        }
        Ok(())
    }
}

fn missing(table: &str) -> PipelineError {
    PipelineError::Job(format!("the recipe has no [{table}] table"))
}

/// The files of one output: `<name>.bvh` and `<name>.npz` (with the occlusion
/// mask as a `mask` array, bool [T, J], true = visible).
pub fn output_files(clip: &NewClip) -> Result<Vec<(String, Vec<u8>)>, PipelineError> {
    let m = &clip.motion;
    let mut extras = Vec::new();
    if let Some(mask) = &clip.mask {
        extras.push(
            motion::npz::NpyArray::bool("mask", &[m.frames(), m.joints()], &mask.visible).map_err(
                |source| PipelineError::Io {
                    path: PathBuf::from(format!("{}.npz", clip.name)),
                    source,
                },
            )?,
        );
    }
    let npz = motion::npz::motion_to_bytes(m, &extras).map_err(|source| PipelineError::Io {
        path: PathBuf::from(format!("{}.npz", clip.name)),
        source,
    })?;
    Ok(vec![
        (format!("{}.bvh", clip.name), motion::bvh::to_bytes(m)),
        (format!("{}.npz", clip.name), npz),
    ])
}

fn write_output(out: &Path, clip: &NewClip) -> Result<(), PipelineError> {
    for (name, bytes) in output_files(clip)? {
        motion::io::write_atomic(&out.join(name), &bytes)?;
    }
    Ok(())
}
