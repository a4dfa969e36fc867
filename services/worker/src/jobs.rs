//! Running a claimed job: the pipeline's one executor (`pipeline::execute`)
//! with its inputs fetched from the coordinator and its outputs uploaded to
//! it. This module is transport only: what each job kind does is the
//! pipeline's, exactly as `motionaug augment` runs it.
//!
//! * Inputs ([`HttpInputs`]): source clips from `GET /clips/{id}/source`;
//!   what earlier jobs made from `GET /jobs/{id}/inputs/{name}`, found in the
//!   outputs of the job's dependencies, which the claim carries, under the
//!   names of `motionaug_protocol::artifacts`.
//! * Outputs ([`Uploader`]): a clip whose last job this is becomes
//!   `<name>.bvh` and `<name>.npz` with its manifest entry (as the CLI writes
//!   them); a clip a later job works on is stored losslessly
//!   (`pipeline::encode_clip`) under `work/`, outside the results.
//! * Resuming: a `synthesize` job checkpoints after every output (the outputs
//!   handed over so far); a correction uploads each new PPO checkpoint, and an
//!   attempt that finds one (its worker died) unpacks it first, so the
//!   executor resumes from it.
//!
//! The executor runs on the blocking pool; the inputs and outputs reach the
//! coordinator from there through the runtime's handle.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use motion::Motion;
use motionaug_protocol::{
    ClipFormat, ClipRef, JobOutput, PipelineInput, SynthesizeCheckpoint, WorkClip, artifacts,
};
use pipeline::{JobKind, Made, PipelineError, PlannedJob};
use tokio::runtime::Handle;

use crate::archive::{latest_checkpoint_zip, unzip_into, zip_dir};
use crate::client::with_retries;
use crate::runner::{JobContext, JobFailure, Outcome, Stop};
use crate::transfer::{fetch, proceed, test_pause, upload};

/// A correction's learning curve so far: [wall_s, samples, r_norm] per rollout.
type Curve = Arc<Mutex<Vec<[f64; 3]>>>;

/// Runs the claimed job `ctx.job` to its end, or until it must stop.
pub async fn run(ctx: Arc<JobContext>) -> Result<Outcome, JobFailure> {
    let input: PipelineInput = serde_json::from_value(ctx.job.input.clone())
        .map_err(|e| JobFailure::permanent(format!("job input is not a pipeline job: {e}")))?;
    let dir = ctx
        .work_dir
        .join(format!("{}-{}", ctx.job.id, ctx.job.epoch));
    let result = run_in(&ctx, input, &dir).await;
    let _ = std::fs::remove_dir_all(&dir);
    match result {
        Ok(output) => serde_json::to_value(output)
            .map(Outcome::Done)
            .map_err(|e| JobFailure::transient(format!("cannot encode output: {e}"))),
        Err(PipelineError::Stopped) => Ok(Outcome::Stopped),
        Err(e) => Err(failure(e)),
    }
}

/// Bad inputs cannot get better by retrying; a full disk, a lost file or an
/// unreachable coordinator may.
fn failure(e: PipelineError) -> JobFailure {
    match e {
        PipelineError::Io { .. } | PipelineError::Unavailable(_) => {
            JobFailure::transient(e.to_string())
        }
        other => JobFailure::permanent(other.to_string()),
    }
}

/// Jobs that train a policy: they upload PPO checkpoints while they run and
/// resume from them (class trackers too; a `variant_tracker`'s is its second
/// tracker's, the judging before it is quick and done again).
fn is_correction(job: &PlannedJob) -> bool {
    matches!(
        job.kind,
        JobKind::Correct { .. }
            | JobKind::CorrectOriginal { .. }
            | JobKind::Tracker { .. }
            | JobKind::VariantTracker { .. }
    )
}

/// The job's own folder for the executor (corrections in `run/`, as their
/// checkpoints are uploaded from there; the debiasing model in `debias/`).
fn exec_dir(dir: &Path, job: &PlannedJob) -> PathBuf {
    match job.kind {
        JobKind::Correct { .. }
        | JobKind::CorrectOriginal { .. }
        | JobKind::Tracker { .. }
        | JobKind::VariantTracker { .. } => dir.join("run"),
        JobKind::DebiasTrain { .. } => dir.join("debias"),
        _ => dir.join("job"),
    }
}

async fn run_in(
    ctx: &Arc<JobContext>,
    input: PipelineInput,
    dir: &Path,
) -> Result<JobOutput, PipelineError> {
    let job = input.job.clone();
    let run_dir = exec_dir(dir, &job);
    std::fs::create_dir_all(run_dir.join("checkpoints")).map_err(|e| io_error(&run_dir, e))?;
    let resumed = resume(ctx, &job, &run_dir).await?;
    let correction_dir = is_correction(&job).then(|| run_dir.clone());
    let stop = Arc::new(AtomicBool::new(false));
    // The learning curve so far, uploaded while the correction trains.
    let curve: Curve = Arc::new(Mutex::new(Vec::new()));
    let live_curve = match &job.kind {
        JobKind::Correct { clip, .. } => Some(artifacts::correction_curve(clip)),
        JobKind::CorrectOriginal { clip, .. } => Some(artifacts::original_curve(clip)),
        _ => None,
    }
    .map(|name| (name, curve.clone()));
    let task = {
        let (ctx, stop, dir, run_dir) = (ctx.clone(), stop.clone(), dir.to_path_buf(), run_dir);
        let handle = Handle::current();
        tokio::task::spawn_blocking(move || {
            let inputs = HttpInputs {
                ctx: &ctx,
                input: &input,
                handle: &handle,
                dir: &dir,
            };
            let mut uploader = Uploader::new(&ctx, &handle, &job, &run_dir, resumed);
            let control = ctx.control.clone();
            let on_progress = move |p: &correct::job::ProgressEvent| {
                if p.budget_s > 0.0 {
                    control.set_progress((p.wall_s / p.budget_s).min(0.99));
                }
                if let (Some(r), Ok(mut points)) = (p.r_norm, curve.lock()) {
                    points.push([p.wall_s, p.samples as f64, r]);
                }
            };
            let context = pipeline::Context {
                dir: &run_dir,
                skip: uploader.checkpoint.done,
                report_path: match &job.kind {
                    JobKind::Correct { clip, .. } => Some(artifacts::correction_report(clip)),
                    _ => None,
                },
                checkpoint_every_s: Some(ctx.checkpoint_every.as_secs_f64()),
                stop: Some(stop),
                tune_correction: None,
                rollout_threads: None,
                on_progress: &on_progress,
                on_corrected: &|_| {},
            };
            pipeline::execute(&job, &inputs, &mut uploader, &context)?;
            Ok(uploader.output)
        })
    };
    watch(ctx, task, &stop, correction_dir, live_curve).await
}

/// What an earlier attempt left: a `synthesize` job's outputs so far, or a
/// correction's PPO checkpoint (unpacked into `run_dir/checkpoints`).
async fn resume(
    ctx: &JobContext,
    job: &PlannedJob,
    run_dir: &Path,
) -> Result<SynthesizeCheckpoint, PipelineError> {
    if !ctx.job.has_checkpoint {
        return Ok(SynthesizeCheckpoint::default());
    }
    let bytes = get(ctx, &job_path(ctx, "checkpoint"), "the checkpoint").await?;
    if is_correction(job) {
        let into = run_dir.join("checkpoints");
        match tokio::task::spawn_blocking(move || unzip_into(&bytes, &into)).await {
            Ok(Ok(())) => tracing::info!("resuming the correction from its checkpoint"),
            _ => tracing::warn!("checkpoint unreadable; starting over"),
        }
        return Ok(SynthesizeCheckpoint::default());
    }
    match serde_json::from_slice::<SynthesizeCheckpoint>(&bytes) {
        Ok(c) if c.manifest.len() + c.clips.len() == c.done && c.done <= job.outputs.len() => {
            tracing::info!(
                done = c.done,
                total = job.outputs.len(),
                "resuming from checkpoint"
            );
            Ok(c)
        }
        _ => {
            tracing::warn!("checkpoint unreadable or does not fit the job; starting over");
            Ok(SynthesizeCheckpoint::default())
        }
    }
}

/// Waits for the executor while passing on stop requests and (for a
/// correction) uploading each new PPO checkpoint it stores.
async fn watch(
    ctx: &JobContext,
    mut task: tokio::task::JoinHandle<Result<JobOutput, PipelineError>>,
    stop: &AtomicBool,
    correction_dir: Option<PathBuf>,
    live_curve: Option<(String, Curve)>,
) -> Result<JobOutput, PipelineError> {
    let checkpoints = correction_dir.map(|d| d.join("checkpoints"));
    let mut uploaded: Option<PathBuf> = None;
    let mut curve_points = 0;
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    loop {
        tokio::select! {
            done = &mut task => {
                return done.map_err(|e| PipelineError::Unavailable(format!("job crashed: {e}")))?;
            }
            _ = tick.tick() => {}
        }
        if ctx.control.stop_reason().is_some() {
            // Cancelled, lease lost or shutting down: a correction ends its
            // current iteration (saving a checkpoint), other jobs their output.
            stop.store(true, Ordering::Relaxed);
        }
        if let Some((name, curve)) = &live_curve {
            upload_curve(ctx, name, curve, &mut curve_points).await;
        }
        let Some(checkpoints) = &checkpoints else {
            // Other jobs stop after their current output (or run to the end).
            continue;
        };
        if ctx.control.stop_reason() == Some(Stop::Shutdown) {
            // The process is exiting; the next worker resumes the correction
            // from the last uploaded checkpoint.
            return Err(PipelineError::Stopped);
        }
        let latest = ppo::latest_checkpoint(checkpoints).ok().flatten();
        if latest.is_some() && latest != uploaded {
            let dir = checkpoints.clone();
            let zipped = tokio::task::spawn_blocking(move || latest_checkpoint_zip(&dir))
                .await
                .map_err(|e| PipelineError::Unavailable(format!("zip crashed: {e}")))??;
            if let Some(bytes) = zipped {
                let path = job_path(ctx, "checkpoint");
                let reply = with_retries("checkpoint", ctx.patience, || {
                    ctx.coordinator.put(&path, bytes.clone())
                })
                .await
                .map_err(|e| PipelineError::Unavailable(e.to_string()))?;
                // Cancelled or lease lost: the stop reason is set; the heartbeat
                // no longer runs, so wait for the thread and drop the result.
                proceed(ctx, reply);
                uploaded = latest;
                tracing::info!(progress = ctx.control.progress(), "checkpoint uploaded");
            }
        }
    }
}

/// Uploads the learning curve when it has new points (for the viewer; a
/// failed upload is only logged: the curve is a view, not a result).
async fn upload_curve(
    ctx: &JobContext,
    name: &str,
    curve: &Mutex<Vec<[f64; 3]>>,
    sent: &mut usize,
) {
    let body = match curve.lock() {
        Ok(points) if points.len() > *sent => {
            *sent = points.len();
            serde_json::to_vec(&*points).unwrap_or_default()
        }
        _ => return,
    };
    let path = job_path(ctx, &format!("artifacts/{name}"));
    if let Err(e) = upload(ctx, &path, body).await {
        tracing::warn!(error = %e.message, "learning curve upload failed");
    }
}

/// `/jobs/{id}/{what}?epoch=N` of the running job.
fn job_path(ctx: &JobContext, what: &str) -> String {
    let job = &ctx.job;
    format!("/jobs/{}/{what}?epoch={}", job.id, job.epoch)
}

/// GET from the coordinator: a stop is [`PipelineError::Stopped`], a 404 an
/// error naming `what`.
async fn get(ctx: &JobContext, path: &str, what: &str) -> Result<Vec<u8>, PipelineError> {
    match fetch(ctx, path)
        .await
        .map_err(|f| PipelineError::Unavailable(f.message))?
    {
        None => Err(PipelineError::Stopped),
        Some(None) => Err(PipelineError::Job(format!(
            "{what} is missing on the coordinator"
        ))),
        Some(Some(bytes)) => Ok(bytes),
    }
}

fn io_error(path: &Path, source: std::io::Error) -> PipelineError {
    PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A job's inputs, fetched from the coordinator when the executor asks.
struct HttpInputs<'a> {
    ctx: &'a JobContext,
    input: &'a PipelineInput,
    handle: &'a Handle,
    /// The attempt's folder (warm starts and the debiasing model are unpacked here).
    dir: &'a Path,
}

impl HttpInputs<'_> {
    fn get(&self, path: &str, what: &str) -> Result<Vec<u8>, PipelineError> {
        self.handle.block_on(get(self.ctx, path, what))
    }

    /// A file stored by one of this job's inputs.
    fn input_file(&self, name: &str) -> Result<Vec<u8>, PipelineError> {
        self.get(&job_path(self.ctx, &format!("inputs/{name}")), name)
    }

    /// The output of input job `key`.
    fn dep(&self, key: &str) -> Result<JobOutput, PipelineError> {
        let dep = self
            .ctx
            .job
            .deps
            .iter()
            .find(|d| d.key == key)
            .ok_or_else(|| PipelineError::Job(format!("the claim lacks the output of `{key}`")))?;
        serde_json::from_value(dep.output.clone())
            .map_err(|e| PipelineError::Job(format!("the output of `{key}` is unreadable: {e}")))
    }

    /// Artifact `name` of input job `key` (which must list it).
    fn dep_file(&self, key: &str, name: &str) -> Result<Vec<u8>, PipelineError> {
        if !self.dep(key)?.work.iter().any(|w| w == name) {
            return Err(PipelineError::Job(format!("`{key}` stored no {name}")));
        }
        self.input_file(name)
    }

    fn original_key(name: &str) -> String {
        format!("correct_original:{name}")
    }
}

impl pipeline::Inputs for HttpInputs<'_> {
    fn source(&self, name: &str) -> Result<pipeline::Clip, PipelineError> {
        let clip: &ClipRef = self
            .input
            .clips
            .iter()
            .find(|c| c.clip_name == name)
            .ok_or_else(|| PipelineError::Job(format!("the job input lacks the clip `{name}`")))?;
        let source = self.get(&format!("/clips/{}/source", clip.clip_id), name)?;
        let skeleton = match clip.format {
            ClipFormat::Amc => {
                Some(self.get(&format!("/clips/{}/skeleton", clip.clip_id), "its skeleton")?)
            }
            ClipFormat::Bvh | ClipFormat::Npz => None,
        };
        let skeleton_name = clip.skeleton_name.clone().unwrap_or_default();
        let motion = motionaug_protocol::clip::load(
            clip.format,
            &clip.source_name,
            &source,
            skeleton.as_deref().map(|s| (skeleton_name.as_str(), s)),
        )
        .map_err(|e| PipelineError::Job(format!("cannot read the clip: {e}")))?;
        Ok(pipeline::Clip {
            name: name.to_string(),
            source: clip.source_name.clone(),
            motion,
        })
    }

    fn clip(&self, name: &str) -> Result<Option<pipeline::WorkClip>, PipelineError> {
        for dep in &self.ctx.job.deps {
            let output: JobOutput = serde_json::from_value(dep.output.clone())
                .map_err(|e| PipelineError::Job(format!("the output of `{}`: {e}", dep.key)))?;
            if output.rejected.iter().any(|r| r == name) {
                // Its correction was not accepted: nothing to work on.
                return Ok(None);
            }
            if let Some(c) = output.clips.into_iter().find(|c| c.name == name) {
                let entry = serde_json::from_value(c.entry)
                    .map_err(|e| PipelineError::Job(format!("manifest entry of `{name}`: {e}")))?;
                let (motion, mask) = pipeline::decode_clip(&self.input_file(&c.file)?)?;
                return Ok(Some(pipeline::WorkClip {
                    name: c.name,
                    motion,
                    mask,
                    entry,
                }));
            }
        }
        Err(PipelineError::Job(format!("no input job made `{name}`")))
    }

    fn original_report(&self, name: &str) -> Result<correct::Report, PipelineError> {
        let file = artifacts::original_report(name);
        let bytes = self.dep_file(&Self::original_key(name), &file)?;
        serde_json::from_slice(&bytes).map_err(|e| PipelineError::Job(format!("{file}: {e}")))
    }

    fn original_checkpoints(&self, name: &str) -> Result<PathBuf, PipelineError> {
        let file = artifacts::original_checkpoints(name);
        let bytes = self.dep_file(&Self::original_key(name), &file)?;
        let into = self.dir.join("warm");
        unzip_into(&bytes, &into)?;
        Ok(into)
    }

    fn corrected_original(&self, name: &str) -> Result<Option<Motion>, PipelineError> {
        let key = Self::original_key(name);
        if self.dep(&key)?.rejected.iter().any(|r| r == name) {
            return Ok(None);
        }
        let bytes = self.dep_file(&key, &artifacts::original_corrected(name))?;
        Ok(Some(pipeline::decode_clip(&bytes)?.0))
    }

    fn debiaser(&self) -> Result<Arc<debias::Debiaser>, PipelineError> {
        let bytes = self.dep_file("debias_train", artifacts::DEBIAS_MODEL)?;
        let into = self.dir.join("debias-model");
        unzip_into(&bytes, &into)?;
        Ok(Arc::new(debias::Debiaser::load(&into)?))
    }

    /// The tracker's report and latest checkpoint, unpacked as the executor
    /// expects its folder (`class.json`, `checkpoints/<latest>/`).
    fn tracker(&self, group: &str) -> Result<PathBuf, PipelineError> {
        let key = pipeline::plan::tracker_key(group);
        let report = self.dep_file(&key, &artifacts::tracker_report(group))?;
        let checkpoint = self.dep_file(&key, &artifacts::tracker_checkpoints(group))?;
        let into = self.dir.join("tracker");
        unpack_tracker(&into, &report, &checkpoint)?;
        Ok(into)
    }

    /// The judged verdicts say whether `clip` starts from the second tracker;
    /// only then is it fetched and unpacked.
    fn variant_tracker(&self, group: &str, clip: &str) -> Result<Option<PathBuf>, PipelineError> {
        let key = pipeline::plan::variant_tracker_key(group);
        let file = artifacts::variant_judged(group);
        let judged: correct::ClassReport = serde_json::from_slice(&self.dep_file(&key, &file)?)
            .map_err(|e| PipelineError::Job(format!("{file}: {e}")))?;
        let report_file = artifacts::variant_tracker_report(group);
        let second = self.dep(&key)?.work.contains(&report_file);
        if !(second && pipeline::stages::VariantTracker::failed_as_is(&judged, clip)) {
            return Ok(None);
        }
        let report = self.dep_file(&key, &report_file)?;
        let checkpoint = self.dep_file(&key, &artifacts::variant_tracker_checkpoints(group))?;
        let into = self.dir.join("variant_tracker");
        unpack_tracker(&into, &report, &checkpoint)?;
        Ok(Some(into))
    }
}

/// A tracker's folder as the executor expects it: `class.json` and
/// `checkpoints/<latest>/` (from its zipped latest checkpoint).
fn unpack_tracker(into: &Path, report: &[u8], checkpoint: &[u8]) -> Result<(), PipelineError> {
    unzip_into(checkpoint, &into.join("checkpoints"))?;
    let path = into.join(correct::class::REPORT_FILE);
    std::fs::write(&path, report).map_err(|e| io_error(&path, e))
}

/// Uploads what the executor makes and builds the job's output.
struct Uploader<'a> {
    ctx: &'a JobContext,
    handle: &'a Handle,
    job: &'a PlannedJob,
    /// The executor's folder (a correction's report, the debiasing model).
    run_dir: &'a Path,
    /// Outputs handed over so far (uploaded as the checkpoint of a `synthesize` job).
    checkpoint: SynthesizeCheckpoint,
    output: JobOutput,
}

impl<'a> Uploader<'a> {
    fn new(
        ctx: &'a JobContext,
        handle: &'a Handle,
        job: &'a PlannedJob,
        run_dir: &'a Path,
        resumed: SynthesizeCheckpoint,
    ) -> Self {
        let output = JobOutput {
            manifest: resumed.manifest.clone(),
            files: resumed.files.clone(),
            clips: resumed.clips.clone(),
            ..JobOutput::default()
        };
        ctx.control
            .set_progress(resumed.done as f64 / job.outputs.len().max(1) as f64);
        Uploader {
            ctx,
            handle,
            job,
            run_dir,
            checkpoint: resumed,
            output,
        }
    }

    /// Stores a file of this job.
    fn put_file(&self, name: &str, bytes: Vec<u8>) -> Result<(), PipelineError> {
        let path = job_path(self.ctx, &format!("artifacts/{name}"));
        let go_on = self
            .handle
            .block_on(upload(self.ctx, &path, bytes))
            .map_err(|f| PipelineError::Unavailable(f.message))?;
        if go_on {
            Ok(())
        } else {
            Err(PipelineError::Stopped)
        }
    }

    fn put_work(&mut self, name: String, bytes: Vec<u8>) -> Result<(), PipelineError> {
        self.put_file(&name, bytes)?;
        self.output.work.push(name);
        Ok(())
    }

    /// A clip: final files and manifest entry, or a work clip for the next job.
    fn clip(&mut self, clip: pipeline::WorkClip) -> Result<(), PipelineError> {
        let synthesize = matches!(self.job.kind, JobKind::Synthesize { .. });
        if synthesize {
            self.handle.block_on(test_pause(self.ctx));
            if self.ctx.control.stop_reason().is_some() {
                return Err(PipelineError::Stopped);
            }
        }
        let entry =
            serde_json::to_value(&clip.entry).map_err(|e| PipelineError::Job(e.to_string()))?;
        let mut files = Vec::new();
        if self.job.finishes {
            for (name, bytes) in
                pipeline::run::output_files(&clip.name, &clip.motion, clip.mask.as_ref())?
            {
                self.put_file(&name, bytes)?;
                files.push(name);
            }
            self.output.manifest.push(entry.clone());
            self.checkpoint.manifest.push(entry);
        } else {
            let folder = match self.job.kind {
                JobKind::Correct { .. } => "corrected",
                _ => "made",
            };
            let file = artifacts::work_clip(folder, &clip.name);
            self.put_file(
                &file,
                pipeline::encode_clip(&clip.motion, clip.mask.as_ref())?,
            )?;
            let work = WorkClip {
                name: clip.name.clone(),
                file,
                entry,
            };
            self.output.clips.push(work.clone());
            self.checkpoint.clips.push(work);
        }
        if let JobKind::Correct { clip: name, .. } = &self.job.kind {
            // The manifest names the report (as the CLI's does): it goes into the results.
            let report = self.run_dir.join("report.json");
            let bytes = std::fs::read(&report).map_err(|e| io_error(&report, e))?;
            let report_name = artifacts::correction_report(name);
            self.put_file(&report_name, bytes)?;
            files.push(report_name);
        }
        self.output.files.extend(files.iter().cloned());
        if synthesize {
            self.checkpoint.files.extend(files);
            self.checkpoint.done += 1;
            self.save_checkpoint()?;
        }
        Ok(())
    }

    /// The outputs handed over so far, so that another attempt continues after them.
    fn save_checkpoint(&self) -> Result<(), PipelineError> {
        let body = serde_json::to_vec(&self.checkpoint)
            .map_err(|e| PipelineError::Job(format!("cannot encode checkpoint: {e}")))?;
        let path = job_path(self.ctx, "checkpoint");
        let go_on = self
            .handle
            .block_on(upload(self.ctx, &path, body))
            .map_err(|f| PipelineError::Unavailable(f.message))?;
        if !go_on {
            return Err(PipelineError::Stopped);
        }
        self.ctx
            .control
            .set_progress(self.checkpoint.done as f64 / self.job.outputs.len().max(1) as f64);
        Ok(())
    }
}

impl pipeline::Outputs for Uploader<'_> {
    fn put(&mut self, made: Made) -> Result<(), PipelineError> {
        match made {
            Made::Clip(clip) => self.clip(clip),
            Made::Rejected { clip, .. } => {
                self.output.rejected.push(clip);
                Ok(())
            }
            Made::Original { clip, outcome } => {
                let corrected = pipeline::encode_clip(&outcome.motion, None)?;
                let checkpoints = latest_checkpoint_zip(&self.run_dir.join("checkpoints"))?
                    .ok_or_else(|| {
                        PipelineError::Job("the correction left no checkpoint".into())
                    })?;
                // The report lets a VAE sample's correction pick the best original.
                let report = serde_json::to_vec(&outcome.report)
                    .map_err(|e| PipelineError::Job(format!("report.json: {e}")))?;
                self.put_work(artifacts::original_corrected(&clip), corrected)?;
                self.put_work(artifacts::original_checkpoints(&clip), checkpoints)?;
                self.put_work(artifacts::original_report(&clip), report)?;
                if !outcome.report.accepted {
                    // Still a warm start for its variants, but no debiasing pair.
                    self.output.rejected.push(clip);
                }
                Ok(())
            }
            Made::Debiaser(_) => {
                // The executor saved it in its folder.
                let bytes = zip_dir(self.run_dir)?;
                self.put_work(artifacts::DEBIAS_MODEL.to_string(), bytes)
            }
            Made::Tracker { group, report } => {
                let checkpoint = latest_checkpoint_zip(&self.run_dir.join("checkpoints"))?
                    .ok_or_else(|| PipelineError::Job("the tracker left no checkpoint".into()))?;
                let report = serde_json::to_vec(&report)
                    .map_err(|e| PipelineError::Job(format!("class.json: {e}")))?;
                self.put_work(artifacts::tracker_checkpoints(&group), checkpoint)?;
                self.put_work(artifacts::tracker_report(&group), report)
            }
            Made::VariantTracker { group, tracker } => {
                let judged = serde_json::to_vec(&tracker.judged)
                    .map_err(|e| PipelineError::Job(format!("judged.json: {e}")))?;
                self.put_work(artifacts::variant_judged(&group), judged)?;
                let Some(second) = tracker.second else {
                    return Ok(());
                };
                let checkpoint = latest_checkpoint_zip(&self.run_dir.join("checkpoints"))?
                    .ok_or_else(|| {
                        PipelineError::Job("the second tracker left no checkpoint".into())
                    })?;
                let report = serde_json::to_vec(&second)
                    .map_err(|e| PipelineError::Job(format!("class.json: {e}")))?;
                self.put_work(artifacts::variant_tracker_checkpoints(&group), checkpoint)?;
                self.put_work(artifacts::variant_tracker_report(&group), report)
            }
        }
    }
}
