//! The whole augmentation in one process: walk the plan in order, run each
//! job with the one executor ([`crate::exec`]) over inputs kept in memory,
//! and write each output once its last job is done. A stretch of jobs that
//! need nothing from each other runs side by side (synthesis; corrections
//! with [`Tune::parallel_corrections`]), their results kept in plan order.
//! Expensive work survives a crash: every correction lives in
//! `work/correct/<clip>/` (checkpoints, then the finished clip and report),
//! and a rerun with the same recipe and inputs reuses or resumes it.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use motion::Motion;
use rayon::prelude::*;

use crate::PipelineError;
use crate::exec::{self, Context, Inputs, Made, WorkClip};
use crate::manifest::ManifestEntry;
use crate::plan::{JobKind, Plan, PlannedJob, plan};
use crate::recipe::Recipe;

/// A source clip.
#[derive(Debug, Clone)]
pub struct Clip {
    /// Unique name (file stem); outputs are named after it.
    pub name: String,
    /// Where it came from (path or upload name), for the manifest.
    pub source: String,
    pub motion: Motion,
}

impl Clip {
    /// Clips made in memory (the evaluation's training sets): each named
    /// after itself, with no file behind it.
    pub fn all_from(named: &[(String, Motion)]) -> Vec<Clip> {
        named
            .iter()
            .map(|(name, motion)| Clip {
                name: name.clone(),
                source: name.clone(),
                motion: motion.clone(),
            })
            .collect()
    }
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
    /// A correction finished (or was found finished), accepted or not.
    Corrected {
        job: &'a PlannedJob,
        report: &'a correct::Report,
        /// The clip as the simulation tracked it.
        motion: &'a Motion,
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

/// The run's memory: source clips, clips between their jobs, what the
/// corrections of the originals and the debiasing made. It is the
/// [`Inputs`] of every job.
struct State<'a> {
    options: &'a Options<'a>,
    tune: Tune<'a>,
    sources: HashMap<String, &'a Clip>,
    /// Clips between jobs.
    pending: HashMap<String, WorkClip>,
    /// Clips whose correction was rejected (left out).
    rejected: HashSet<String>,
    /// Corrections of the source clips (warm starts, debiasing pairs).
    originals: HashMap<String, correct::Outcome>,
    debiaser: Option<Arc<debias::Debiaser>>,
    failed: HashSet<String>,
    summary: Summary,
}

/// Run `recipe` on `clips`.
pub fn run(recipe: &Recipe, clips: &[Clip], options: &Options) -> Result<Summary, PipelineError> {
    let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
    let plan = plan(recipe, &names, options.seed);
    run_plan(&plan, clips, Vec::new(), options, Tune::default())
}

/// How a run differs from [`run`]'s (nothing: [`Tune::default`]): the
/// evaluation table's correction settings and folder, `motionaug augment
/// --correct-threads`.
#[derive(Clone, Copy, Default)]
pub struct Tune<'a> {
    /// Changes to every correction's settings beyond the plan's (see
    /// [`exec::Context::tune_correction`]).
    pub correction: Option<&'a (dyn Fn(&mut correct::CorrectConfig) + Sync)>,
    /// The folder under `work` of the corrections of made clips, instead of
    /// `correct` (the table keeps them in `samples`, where its earlier runs
    /// left them to be resumed).
    pub corrections_folder: Option<&'a str>,
    /// Corrections (of originals and of made clips) that need nothing from
    /// each other run this many at a time, each on its own thread; 0 or 1:
    /// one after the other. Their results do not change: every correction
    /// has its own seed and files.
    pub parallel_corrections: usize,
}

impl Tune<'_> {
    /// The folder of `job`'s own files under `work` ([`exec::job_dir`] with
    /// this run's corrections folder); `None` for kinds that keep nothing.
    pub fn job_dir(&self, work: &Path, job: &PlannedJob) -> Option<PathBuf> {
        match (&job.kind, self.corrections_folder) {
            (JobKind::Correct { clip, .. }, Some(folder)) => Some(work.join(folder).join(clip)),
            _ => exec::job_dir(work, job),
        }
    }
}

/// Run `plan` on source clips `clips`, with `made` the clips its first jobs
/// work on that no job of it makes (e.g. samples of a VAE trained elsewhere,
/// for a plan of [`crate::plan::corrections`]).
pub fn run_plan(
    plan: &Plan,
    clips: &[Clip],
    made: Vec<WorkClip>,
    options: &Options,
    tune: Tune<'_>,
) -> Result<Summary, PipelineError> {
    let mut names = HashSet::new();
    for c in clips {
        if !names.insert(c.name.as_str()) {
            return Err(PipelineError::Job(format!(
                "two clips are named `{}`; outputs would collide",
                c.name
            )));
        }
    }
    (options.on_event)(Event::Planned {
        jobs: plan.jobs.len(),
    });
    let mut state = State {
        options,
        tune,
        sources: clips.iter().map(|c| (c.name.clone(), c)).collect(),
        pending: made.into_iter().map(|c| (c.name.clone(), c)).collect(),
        rejected: HashSet::new(),
        originals: HashMap::new(),
        debiaser: None,
        failed: HashSet::new(),
        summary: Summary {
            jobs: plan.jobs.len(),
            ..Summary::default()
        },
    };
    state.run_plan(plan)?;
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
            let j = self.batch_end(&plan.jobs, i);
            if j > i {
                self.run_batch(&plan.jobs[i..j])?;
                i = j;
                continue;
            }
            self.run_job(&plan.jobs[i])?;
            i += 1;
        }
        Ok(())
    }

    /// How many jobs of this kind run side by side: synthesis jobs are cheap
    /// and independent (`None`: rayon's pool), corrections take
    /// [`Tune::parallel_corrections`] threads; 1 = one after the other.
    fn batch_threads(&self, kind: &JobKind) -> Option<Option<usize>> {
        match kind {
            JobKind::Synthesize { .. } => Some(None),
            JobKind::CorrectOriginal { .. } | JobKind::Correct { .. }
                if self.tune.parallel_corrections > 1 =>
            {
                Some(Some(self.tune.parallel_corrections))
            }
            _ => None,
        }
    }

    /// The end of the batch starting at `jobs[start]` (`start` when that job
    /// runs alone): the following jobs that run side by side with the same
    /// threads and need nothing the batch makes.
    fn batch_end(&self, jobs: &[PlannedJob], start: usize) -> usize {
        let Some(threads) = self.batch_threads(&jobs[start].kind) else {
            return start;
        };
        let mut keys: HashSet<&str> = HashSet::new();
        let mut end = start;
        while end < jobs.len()
            && self.batch_threads(&jobs[end].kind) == Some(threads)
            && !jobs[end].deps.iter().any(|d| keys.contains(d.as_str()))
        {
            keys.insert(jobs[end].key.as_str());
            end += 1;
        }
        end
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

    /// Runs independent jobs side by side (see [`Self::batch_threads`]), then
    /// keeps what they made in plan order, so the run's memory and outputs
    /// are those of running them one after the other.
    fn run_batch(&mut self, jobs: &[PlannedJob]) -> Result<(), PipelineError> {
        let runnable: Vec<&PlannedJob> = jobs
            .iter()
            .filter(|job| !self.skip_if_inputs_failed(job))
            .collect();
        let Some(first) = runnable.first() else {
            return Ok(());
        };
        let threads = self.batch_threads(&first.kind).flatten();
        let on_event = self.options.on_event;
        let state = &*self;
        let run = |job: &&PlannedJob| {
            on_event(Event::JobStarted { job });
            let (made, r) = state.execute(job, threads.map(|_| 1));
            on_event(Event::JobFinished { job, ok: r.is_ok() });
            (made, r)
        };
        let results: Vec<(Vec<Made>, Result<(), PipelineError>)> = match threads {
            None => runnable.par_iter().map(run).collect(),
            Some(n) => nn::threads::side_by_side(runnable.iter().collect(), n, "correct", run)
                .map_err(|e| {
                    PipelineError::Job(format!("cannot run {n} corrections at once: {e}"))
                })?,
        };
        for (job, (made, result)) in runnable.into_iter().zip(results) {
            self.settle(job, made, result)?;
        }
        Ok(())
    }

    fn run_job(&mut self, job: &PlannedJob) -> Result<(), PipelineError> {
        if self.skip_if_inputs_failed(job) {
            return Ok(());
        }
        (self.options.on_event)(Event::JobStarted { job });
        let (made, result) = self.execute(job, None);
        let ok = result.is_ok();
        self.settle(job, made, result)?;
        (self.options.on_event)(Event::JobFinished { job, ok });
        Ok(())
    }

    /// Keeps what a job made and records how it ended. A broken output
    /// directory is fatal; a job's own failure is not (a synthesis job keeps
    /// the outputs it did make).
    fn settle(
        &mut self,
        job: &PlannedJob,
        made: Vec<Made>,
        result: Result<(), PipelineError>,
    ) -> Result<(), PipelineError> {
        match result {
            Ok(()) => self.keep(job, made),
            Err(e @ PipelineError::Io { .. }) => Err(e),
            Err(e) => {
                if matches!(job.kind, JobKind::Synthesize { .. }) {
                    self.keep(job, made)?;
                }
                self.fail(job, e.to_string());
                Ok(())
            }
        }
    }

    /// Runs one job with the executor (its PPO on `rollout_threads` threads,
    /// when given); what it made, and how it ended.
    fn execute(
        &self,
        job: &PlannedJob,
        rollout_threads: Option<usize>,
    ) -> (Vec<Made>, Result<(), PipelineError>) {
        let work = self.options.work;
        let dir = self
            .tune
            .job_dir(work, job)
            .unwrap_or_else(|| work.to_path_buf());
        // The manifest names a correction's report relative to the output folder.
        let report_path = self.options.out.and_then(|out| {
            dir.join("report.json")
                .strip_prefix(out)
                .ok()
                .map(|p| p.display().to_string())
        });
        let on_event = self.options.on_event;
        let on_progress =
            |p: &correct::job::ProgressEvent| on_event(Event::Correction { job, progress: p });
        let on_corrected = |o: &correct::Outcome| {
            on_event(Event::Corrected {
                job,
                report: &o.report,
                motion: &o.motion,
            })
        };
        let ctx = Context {
            report_path,
            on_progress: &on_progress,
            on_corrected: &on_corrected,
            tune_correction: self.tune.correction,
            rollout_threads,
            ..Context::in_dir(&dir)
        };
        let mut made = Vec::new();
        let result = exec::execute(job, self, &mut made, &ctx);
        (made, result)
    }

    /// Keeps what a job made: final clips are written, others wait for
    /// their next job.
    fn keep(&mut self, job: &PlannedJob, made: Vec<Made>) -> Result<(), PipelineError> {
        for m in made {
            match m {
                Made::Clip(clip) if job.finishes => {
                    self.pending.remove(&clip.name);
                    self.output(clip)?;
                }
                Made::Clip(clip) => {
                    self.pending.insert(clip.name.clone(), clip);
                }
                Made::Rejected { clip, .. } => {
                    self.pending.remove(&clip);
                    self.summary.rejected.push(clip.clone());
                    // Its debiasing still runs and finds nothing to work
                    // on (`Inputs::clip` gives `None`), as on a worker: a
                    // rejection is an outcome, not a failure.
                    self.rejected.insert(clip);
                }
                Made::Original { clip, outcome } => {
                    self.originals.insert(clip, outcome);
                }
                Made::Debiaser(model) => self.debiaser = Some(Arc::new(model)),
                // Its folder holds it for the corrections that start from it.
                Made::Tracker { group, report } => tracing::info!(
                    group,
                    accepted = report.accepted(),
                    clips = report.clips,
                    "class tracker ready"
                ),
                Made::VariantTracker { group, tracker } => tracing::info!(
                    group,
                    accepted_as_is = tracker.judged.accepted(),
                    clips = tracker.judged.clips,
                    second_accepts = tracker.second.as_ref().map(|r| r.accepted()),
                    "second tracker of the class's new clips ready"
                ),
            }
        }
        Ok(())
    }

    /// A clip finished its last job: write it out (or keep it in memory).
    fn output(&mut self, clip: WorkClip) -> Result<(), PipelineError> {
        if let Some(out) = self.options.out {
            write_output(out, &clip.name, &clip.motion, clip.mask.as_ref())?;
        }
        self.summary.manifest.push(clip.entry.clone());
        if self.options.out.is_none() {
            self.summary.outputs.push(Output {
                name: clip.name,
                motion: clip.motion,
                mask: clip.mask,
                entry: clip.entry,
            });
        }
        Ok(())
    }
}

impl Inputs for State<'_> {
    fn source(&self, name: &str) -> Result<Clip, PipelineError> {
        self.sources
            .get(name)
            .map(|c| (*c).clone())
            .ok_or_else(|| PipelineError::Job(format!("no clip named `{name}`")))
    }

    fn clip(&self, name: &str) -> Result<Option<WorkClip>, PipelineError> {
        if self.rejected.contains(name) {
            return Ok(None);
        }
        self.pending
            .get(name)
            .cloned()
            .map(Some)
            .ok_or_else(|| PipelineError::Job(format!("`{name}` was not made")))
    }

    fn original_report(&self, name: &str) -> Result<correct::Report, PipelineError> {
        self.originals
            .get(name)
            .map(|o| o.report.clone())
            .ok_or_else(|| PipelineError::Job(format!("`{name}` was not corrected")))
    }

    fn original_checkpoints(&self, name: &str) -> Result<PathBuf, PipelineError> {
        Ok(self
            .options
            .work
            .join("originals")
            .join(name)
            .join("checkpoints"))
    }

    fn corrected_original(&self, name: &str) -> Result<Option<Motion>, PipelineError> {
        Ok(self
            .originals
            .get(name)
            .filter(|o| o.report.accepted)
            .map(|o| o.motion.clone()))
    }

    fn debiaser(&self) -> Result<Arc<debias::Debiaser>, PipelineError> {
        self.debiaser
            .clone()
            .ok_or_else(|| PipelineError::Job("no debiasing model".into()))
    }

    fn tracker(&self, group: &str) -> Result<PathBuf, PipelineError> {
        let dir = self.options.work.join("trackers").join(group);
        if dir.join(correct::class::REPORT_FILE).is_file() {
            Ok(dir)
        } else {
            Err(PipelineError::Job(format!(
                "the tracker of class `{group}` was not trained"
            )))
        }
    }

    fn variant_tracker(&self, group: &str, clip: &str) -> Result<Option<PathBuf>, PipelineError> {
        let dir = self.options.work.join("variant_trackers").join(group);
        let judged = dir
            .join(crate::stages::JUDGED_DIR)
            .join(correct::class::REPORT_FILE);
        if !judged.is_file() {
            return Err(PipelineError::Job(format!(
                "the new clips of class `{group}` were not judged by its tracker"
            )));
        }
        let judged = correct::ClassReport::read(&judged)?;
        let second = dir.join(correct::class::REPORT_FILE).is_file();
        Ok((second && crate::stages::VariantTracker::failed_as_is(&judged, clip)).then_some(dir))
    }
}

/// The files of one output: `<name>.bvh` and `<name>.npz` (with the occlusion
/// mask as a `mask` array, bool [T, J], true = visible).
pub fn output_files(
    name: &str,
    m: &Motion,
    mask: Option<&synth::Mask>,
) -> Result<Vec<(String, Vec<u8>)>, PipelineError> {
    let mut extras = Vec::new();
    if let Some(mask) = mask {
        extras.push(
            motion::npz::NpyArray::bool("mask", &[m.frames(), m.joints()], &mask.visible).map_err(
                |source| PipelineError::Io {
                    path: PathBuf::from(format!("{}.npz", name)),
                    source,
                },
            )?,
        );
    }
    let npz = motion::npz::motion_to_bytes(m, &extras).map_err(|source| PipelineError::Io {
        path: PathBuf::from(format!("{}.npz", name)),
        source,
    })?;
    Ok(vec![
        (format!("{}.bvh", name), motion::bvh::to_bytes(m)),
        (format!("{}.npz", name), npz),
    ])
}

fn write_output(
    out: &Path,
    name: &str,
    m: &Motion,
    mask: Option<&synth::Mask>,
) -> Result<(), PipelineError> {
    for (name, bytes) in output_files(name, m, mask)? {
        motion::io::write_atomic(&out.join(name), &bytes)?;
    }
    Ok(())
}
