//! The job kinds after kinematic synthesis (`vae`, `interaction`,
//! `correct_original`, `correct`, `debias_train`, `debias_apply`): each calls
//! the pipeline crate's stage function, as `motionaug augment` does, with its
//! inputs fetched from the coordinator instead of kept in memory.
//!
//! * Source clips come from `GET /clips/{id}/source`; what earlier jobs made
//!   (clips to correct, a correction's checkpoints, the debiasing model) from
//!   `GET /jobs/{id}/inputs/{name}`, named in the outputs of the job's
//!   dependencies, which the claim carries.
//! * A clip that a later job still works on is stored losslessly
//!   (`pipeline::encode_clip`) under `work/`, outside the results; a clip whose
//!   last job this is becomes `<name>.bvh` and `<name>.npz` with its manifest
//!   entry, written by `pipeline::run::output_files` like the CLI's.
//! * A correction runs in a local work directory; every new PPO checkpoint is
//!   uploaded as the job's checkpoint, and an attempt that finds one (its
//!   worker died) unpacks it first, so `pipeline::stages` resumes from it.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use motion::Motion;
use motionaug_protocol::{ClipRef, JobOutput, PipelineInput, WorkClip};
use pipeline::{CorrectionSummary, JobKind, ManifestEntry, PipelineError};
use serde_json::Value;

use crate::client::with_retries;
use crate::runner::{JobContext, JobFailure, Outcome, Stop};
use crate::synthesize::{fetch, proceed, upload};

/// Why a job stops before its end.
enum Halt {
    /// Cancelled, lease lost or shutting down (see the job's stop reason).
    Stopped,
    Failed(JobFailure),
}

impl From<JobFailure> for Halt {
    fn from(f: JobFailure) -> Self {
        Halt::Failed(f)
    }
}

fn permanent(message: impl Into<String>) -> Halt {
    Halt::Failed(JobFailure::permanent(message))
}

/// Bad inputs cannot get better by retrying; a full disk or a lost file may.
fn pipeline_failure(e: PipelineError) -> Halt {
    match e {
        PipelineError::Io { .. } => Halt::Failed(JobFailure::transient(e.to_string())),
        other => permanent(other.to_string()),
    }
}

/// A clip made by a job: its files, and either its final manifest entry or
/// the [`WorkClip`] a later job reads.
pub(crate) struct Made {
    pub files: Vec<(String, Vec<u8>)>,
    pub entry: Option<Value>,
    pub work_clip: Option<WorkClip>,
}

/// The files of a clip made by a job: final outputs, or (`keep_in` a folder of
/// `work/`) its lossless encoding for the job that works on it next.
fn finish(
    name: &str,
    motion: Motion,
    mask: Option<synth::Mask>,
    entry: ManifestEntry,
    keep_in: Option<&str>,
) -> Result<Made, String> {
    let entry_json = serde_json::to_value(&entry).map_err(|e| e.to_string())?;
    if let Some(folder) = keep_in {
        let file = format!("work/{folder}/{name}.npz");
        let bytes = pipeline::encode_clip(&motion, mask.as_ref()).map_err(|e| e.to_string())?;
        return Ok(Made {
            files: vec![(file.clone(), bytes)],
            entry: None,
            work_clip: Some(WorkClip {
                name: name.to_string(),
                file,
                entry: entry_json,
            }),
        });
    }
    let clip = pipeline::stages::NewClip {
        name: name.to_string(),
        motion,
        mask,
        entry: entry.synth,
    };
    let files = pipeline::run::output_files(&clip).map_err(|e| e.to_string())?;
    Ok(Made {
        files,
        entry: Some(entry_json),
        work_clip: None,
    })
}

/// A clip a synthesis or VAE job made: final, or kept for its correction.
pub(crate) fn finished_or_kept(
    made: pipeline::stages::NewClip,
    keep_for_correction: bool,
) -> Result<Made, String> {
    let entry = ManifestEntry {
        synth: made.entry,
        correction: None,
        debiased: false,
    };
    finish(
        &made.name,
        made.motion,
        made.mask,
        entry,
        keep_for_correction.then_some("made"),
    )
}

struct Job<'a> {
    ctx: &'a JobContext,
    input: PipelineInput,
    recipe: Arc<pipeline::Recipe>,
    /// Local directory of this attempt (removed at the end).
    dir: PathBuf,
}

pub async fn run(ctx: &JobContext) -> Result<Outcome, JobFailure> {
    let input: PipelineInput = serde_json::from_value(ctx.job.input.clone())
        .map_err(|e| JobFailure::permanent(format!("job input is not a pipeline input: {e}")))?;
    let recipe = motionaug_protocol::recipe::parse(&input.recipe)
        .map_err(|e| JobFailure::permanent(format!("recipe: {}", e.message)))?;
    let dir = ctx
        .work_dir
        .join(format!("{}-{}", ctx.job.id, ctx.job.epoch));
    let job = Job {
        ctx,
        input,
        recipe: Arc::new(recipe),
        dir,
    };
    let result = job.execute().await;
    let _ = std::fs::remove_dir_all(&job.dir);
    match result {
        Ok(output) => serde_json::to_value(output)
            .map(Outcome::Done)
            .map_err(|e| JobFailure::transient(format!("cannot encode output: {e}"))),
        Err(Halt::Stopped) => Ok(Outcome::Stopped),
        Err(Halt::Failed(f)) => Err(f),
    }
}

/// Runs `f` on the blocking pool.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, PipelineError> + Send + 'static,
) -> Result<T, Halt> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| Halt::Failed(JobFailure::transient(format!("job crashed: {e}"))))?
        .map_err(pipeline_failure)
}

fn missing(table: &str) -> Halt {
    permanent(format!("the recipe has no [{table}] table"))
}

impl Job<'_> {
    async fn execute(&self) -> Result<JobOutput, Halt> {
        let recipe = self.recipe.clone();
        match self.input.job.kind.clone() {
            JobKind::Synthesize { .. } => Err(permanent(
                "synthesis runs as `synthesize` jobs, not as pipeline jobs",
            )),
            JobKind::Vae { group, clips, seed } => {
                let step = recipe.vae.clone().ok_or_else(|| missing("vae"))?;
                let mut motions = Vec::with_capacity(clips.len());
                for name in &clips {
                    motions.push((name.clone(), self.source(name).await?));
                }
                let keep = recipe.correct.is_some();
                let made = blocking(move || {
                    let made = pipeline::stages::vae(&recipe, &step, &group, &motions, seed)?;
                    made.into_iter()
                        .map(|c| finished_or_kept(c, keep).map_err(PipelineError::Job))
                        .collect::<Result<Vec<_>, _>>()
                })
                .await?;
                self.emit(made).await
            }
            JobKind::Interaction { pair, a, b, seed } => {
                let step = recipe
                    .interaction
                    .clone()
                    .ok_or_else(|| missing("interaction"))?;
                let (a, b) = (self.source(&a).await?, self.source(&b).await?);
                let made = blocking(move || {
                    let made = pipeline::stages::interaction(&recipe, &step, &pair, &a, &b, seed)?;
                    // Two partners are not simulated together: never corrected, always final.
                    made.into_iter()
                        .map(|c| finished_or_kept(c, false).map_err(PipelineError::Job))
                        .collect::<Result<Vec<_>, _>>()
                })
                .await?;
                self.emit(made).await
            }
            JobKind::CorrectOriginal { clip, seed } => {
                let motion = self.source(&clip).await?;
                let outcome = self.correction(&clip, motion, seed, None).await?;
                let checkpoints = {
                    let dir = self.dir.join("run").join("checkpoints");
                    blocking(move || latest_checkpoint_zip(&dir)).await?
                }
                .ok_or_else(|| permanent("the correction left no checkpoint"))?;
                let corrected = pipeline::encode_clip(&outcome.motion, None)
                    .map_err(|e| permanent(e.to_string()))?;
                // The report lets a VAE sample's correction pick the best original.
                let report = serde_json::to_vec(&outcome.report)
                    .map_err(|e| permanent(format!("report.json: {e}")))?;
                let files = vec![
                    (format!("work/originals/{clip}/corrected.npz"), corrected),
                    (
                        format!("work/originals/{clip}/checkpoints.zip"),
                        checkpoints,
                    ),
                    (format!("work/originals/{clip}/report.json"), report),
                ];
                let mut output = JobOutput::default();
                for (name, bytes) in files {
                    self.put(&name, bytes).await?;
                    output.work.push(name);
                }
                if !outcome.report.accepted {
                    // Still a warm start for its variants, but no debiasing pair.
                    output.rejected.push(clip);
                }
                Ok(output)
            }
            JobKind::Correct {
                clip,
                sources,
                seed,
            } => {
                let step = recipe.correct.clone().ok_or_else(|| missing("correct"))?;
                let (motion, mask, mut entry) = self.work_clip(&clip).await?;
                let warm = match self.warm_start_source(&sources).await? {
                    Some(s) => {
                        let key = format!("correct_original:{s}");
                        let file = self.dep_work_file(&key, "checkpoints.zip")?;
                        Some(self.input_file(&file).await?)
                    }
                    None => None,
                };
                let outcome = self.correction(&clip, motion, seed, warm).await?;
                let report_name = format!("work/correct/{clip}/report.json");
                entry.correction = Some(CorrectionSummary::new(
                    &outcome.report,
                    Some(report_name.clone()),
                ));
                entry.synth.frames = outcome.motion.frames();
                entry.synth.fps = outcome.motion.fps();
                if !outcome.report.accepted && !step.keep_rejected {
                    tracing::info!(clip, "correction not accepted; the clip is left out");
                    return Ok(JobOutput {
                        rejected: vec![clip],
                        ..JobOutput::default()
                    });
                }
                let report = std::fs::read(self.dir.join("run").join("report.json"))
                    .map_err(|e| JobFailure::transient(format!("report.json: {e}")))?;
                let keep = recipe.debias.is_some().then_some("corrected");
                let name = clip.clone();
                let made = blocking(move || {
                    finish(&name, outcome.motion, mask, entry, keep).map_err(PipelineError::Job)
                })
                .await?;
                let mut output = self.emit(vec![made]).await?;
                // The manifest names the report (as the CLI's does): it goes into the results.
                self.put(&report_name, report).await?;
                output.files.push(report_name);
                Ok(output)
            }
            JobKind::DebiasTrain { originals } => {
                let config = recipe.debias.clone().ok_or_else(|| missing("debias"))?;
                let mut pairs = Vec::with_capacity(originals.len());
                for name in &originals {
                    let key = format!("correct_original:{name}");
                    if self.dep(&key)?.rejected.contains(name) {
                        continue;
                    }
                    let file = self.dep_work_file(&key, "corrected.npz")?;
                    let bytes = self.input_file(&file).await?;
                    let (corrected, _) = blocking(move || pipeline::decode_clip(&bytes)).await?;
                    pairs.push((corrected, self.source(name).await?));
                }
                let model_dir = self.dir.join("debias");
                let dir = model_dir.clone();
                let bytes = blocking(move || {
                    let model = pipeline::stages::debias_train(&config, &pairs)?;
                    model.save(&dir)?;
                    zip_dir(&dir)
                })
                .await?;
                let name = "work/debias/model.zip".to_string();
                self.put(&name, bytes).await?;
                Ok(JobOutput {
                    work: vec![name],
                    ..JobOutput::default()
                })
            }
            JobKind::DebiasApply { clip } => {
                let correct_key = format!("correct:{clip}");
                if self.dep(&correct_key)?.rejected.contains(&clip) {
                    // Its correction was not accepted: nothing to debias, nothing to output.
                    return Ok(JobOutput::default());
                }
                let (motion, mask, mut entry) = self.work_clip(&clip).await?;
                let file = self.dep_work_file("debias_train", "model.zip")?;
                let model = self.input_file(&file).await?;
                let dir = self.dir.join("debias");
                entry.debiased = true;
                let made = blocking(move || {
                    unzip_into(&model, &dir)?;
                    let model = debias::Debiaser::load(&dir)?;
                    let motion = pipeline::stages::debias_apply(&model, &motion)?;
                    finish(&clip, motion, mask, entry, None).map_err(PipelineError::Job)
                })
                .await?;
                self.emit(vec![made]).await
            }
        }
    }

    fn path(&self, what: &str) -> String {
        let job = &self.ctx.job;
        format!("/jobs/{}/{what}?epoch={}", job.id, job.epoch)
    }

    /// Stores a file of this job.
    async fn put(&self, name: &str, bytes: Vec<u8>) -> Result<(), Halt> {
        if upload(self.ctx, &self.path(&format!("artifacts/{name}")), bytes).await? {
            Ok(())
        } else {
            Err(Halt::Stopped)
        }
    }

    /// Uploads every file of `made` and lists them in the output.
    async fn emit(&self, made: Vec<Made>) -> Result<JobOutput, Halt> {
        let mut output = JobOutput::default();
        for m in made {
            for (name, bytes) in m.files {
                self.put(&name, bytes).await?;
                if m.work_clip.is_none() {
                    output.files.push(name);
                }
            }
            output.manifest.extend(m.entry);
            output.clips.extend(m.work_clip);
        }
        Ok(output)
    }

    /// GET from the coordinator; `None` (404) is an error naming `what`.
    async fn get(&self, path: &str, what: &str) -> Result<Vec<u8>, Halt> {
        match fetch(self.ctx, path).await? {
            None => Err(Halt::Stopped),
            Some(None) => Err(permanent(format!("{what} is missing on the coordinator"))),
            Some(Some(bytes)) => Ok(bytes),
        }
    }

    /// A file stored by one of this job's inputs.
    async fn input_file(&self, name: &str) -> Result<Vec<u8>, Halt> {
        self.get(&self.path(&format!("inputs/{name}")), name).await
    }

    /// A source clip of the dataset, read as the coordinator read it at upload.
    async fn source(&self, name: &str) -> Result<Motion, Halt> {
        let clip: ClipRef = self
            .input
            .clips
            .iter()
            .find(|c| c.clip_name == name)
            .cloned()
            .ok_or_else(|| permanent(format!("the job input lacks the clip `{name}`")))?;
        let source = self
            .get(&format!("/clips/{}/source", clip.clip_id), name)
            .await?;
        let skeleton = match clip.format {
            motionaug_protocol::ClipFormat::Amc => Some(
                self.get(&format!("/clips/{}/skeleton", clip.clip_id), "its skeleton")
                    .await?,
            ),
            motionaug_protocol::ClipFormat::Bvh => None,
        };
        tokio::task::spawn_blocking(move || {
            let skeleton_name = clip.skeleton_name.clone().unwrap_or_default();
            motionaug_protocol::clip::load(
                clip.format,
                &clip.source_name,
                &source,
                skeleton.as_deref().map(|s| (skeleton_name.as_str(), s)),
            )
        })
        .await
        .map_err(|e| Halt::Failed(JobFailure::transient(format!("clip reader crashed: {e}"))))?
        .map_err(|e| permanent(format!("cannot read the clip: {e}")))
    }

    /// The output of the input job `key`.
    fn dep(&self, key: &str) -> Result<JobOutput, Halt> {
        let dep = self
            .ctx
            .job
            .deps
            .iter()
            .find(|d| d.key == key)
            .ok_or_else(|| permanent(format!("the claim lacks the output of `{key}`")))?;
        serde_json::from_value(dep.output.clone())
            .map_err(|e| permanent(format!("the output of `{key}` is unreadable: {e}")))
    }

    /// The corrected original whose policy warm-starts a correction
    /// ([`pipeline::stages::best_warm_start`] over the candidates' reports).
    async fn warm_start_source<'s>(&self, sources: &'s [String]) -> Result<Option<&'s str>, Halt> {
        let mut outcomes = Vec::with_capacity(sources.len());
        for s in sources {
            let file = self.dep_work_file(&format!("correct_original:{s}"), "report.json")?;
            let report: serde_json::Value = serde_json::from_slice(&self.input_file(&file).await?)
                .map_err(|e| permanent(format!("{file}: {e}")))?;
            let (Some(accepted), Some(r_norm)) =
                (report["accepted"].as_bool(), report["r_norm"].as_f64())
            else {
                return Err(permanent(format!("{file} lacks accepted / r_norm")));
            };
            outcomes.push((accepted, r_norm));
        }
        Ok(pipeline::stages::best_warm_start(&outcomes).map(|i| sources[i].as_str()))
    }

    /// The `work` file of input `key` whose name ends with `suffix`.
    fn dep_work_file(&self, key: &str, suffix: &str) -> Result<String, Halt> {
        self.dep(key)?
            .work
            .into_iter()
            .find(|w| w.ends_with(suffix))
            .ok_or_else(|| permanent(format!("`{key}` stored no {suffix}")))
    }

    /// The clip `name` an input job made for this one, with its mask and entry.
    async fn work_clip(
        &self,
        name: &str,
    ) -> Result<(Motion, Option<synth::Mask>, ManifestEntry), Halt> {
        let mut found = None;
        for dep in &self.ctx.job.deps {
            let output: JobOutput = serde_json::from_value(dep.output.clone())
                .map_err(|e| permanent(format!("the output of `{}`: {e}", dep.key)))?;
            if let Some(c) = output.clips.into_iter().find(|c| c.name == name) {
                found = Some(c);
                break;
            }
        }
        let clip = found.ok_or_else(|| permanent(format!("no input job made `{name}`")))?;
        let entry: ManifestEntry = serde_json::from_value(clip.entry)
            .map_err(|e| permanent(format!("manifest entry of `{name}`: {e}")))?;
        let bytes = self.input_file(&clip.file).await?;
        let (motion, mask) = blocking(move || pipeline::decode_clip(&bytes)).await?;
        Ok((motion, mask, entry))
    }

    /// Physical correction of `motion` in `dir/run`, resumed from the job's
    /// checkpoint when an earlier attempt stored one; uploads each new
    /// checkpoint and reports progress (training time / budget).
    async fn correction(
        &self,
        name: &str,
        motion: Motion,
        seed: u64,
        warm: Option<Vec<u8>>,
    ) -> Result<correct::Outcome, Halt> {
        let step = self
            .recipe
            .correct
            .clone()
            .ok_or_else(|| missing("correct"))?;
        let run_dir = self.dir.join("run");
        let checkpoints = run_dir.join("checkpoints");
        std::fs::create_dir_all(&checkpoints)
            .map_err(|e| JobFailure::transient(format!("{}: {e}", checkpoints.display())))?;
        if self.ctx.job.has_checkpoint {
            let bytes = self.get(&self.path("checkpoint"), "the checkpoint").await?;
            let into = checkpoints.clone();
            match blocking(move || unzip_into(&bytes, &into)).await {
                Ok(()) => tracing::info!("resuming the correction from its checkpoint"),
                Err(_) => tracing::warn!("checkpoint unreadable; starting over"),
            }
        }
        let warm_dir = match warm {
            Some(bytes) => {
                let into = self.dir.join("warm");
                let dir = into.clone();
                blocking(move || unzip_into(&bytes, &dir)).await?;
                Some(into)
            }
            None => None,
        };
        let mut config = step.config(seed);
        config.checkpoint_every_s = self.ctx.checkpoint_every.as_secs_f64();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        config.stop = Some(stop.clone());
        let control = self.ctx.control.clone();
        let name = name.to_string();
        let dir = run_dir.clone();
        let mut task = tokio::task::spawn_blocking(move || {
            pipeline::stages::correct_with_config(
                config,
                &name,
                &motion,
                &dir,
                warm_dir.as_deref(),
                |p| {
                    if p.budget_s > 0.0 {
                        control.set_progress((p.wall_s / p.budget_s).min(0.99));
                    }
                },
            )
        });
        let mut uploaded: Option<PathBuf> = None;
        let mut tick = tokio::time::interval(Duration::from_millis(250));
        loop {
            tokio::select! {
                done = &mut task => {
                    return match done
                        .map_err(|e| Halt::Failed(JobFailure::transient(format!("correction crashed: {e}"))))?
                    {
                        // Stopped on our request (cancelled, lease lost, shutdown).
                        Err(PipelineError::Correct(correct::CorrectError::Stopped)) => Err(Halt::Stopped),
                        other => other.map_err(pipeline_failure),
                    };
                }
                _ = tick.tick() => {}
            }
            if self.ctx.control.stop_reason().is_some() {
                // Cancelled, lease lost or shutting down: end the training at the
                // end of its current iteration (it saves a checkpoint first).
                stop.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            if self.ctx.control.stop_reason() == Some(Stop::Shutdown) {
                // The process is exiting; the next worker resumes from the last
                // uploaded checkpoint.
                return Err(Halt::Stopped);
            }
            let latest = ppo::latest_checkpoint(&checkpoints).ok().flatten();
            if latest.is_some() && latest != uploaded {
                let dir = checkpoints.clone();
                if let Some(bytes) = blocking(move || latest_checkpoint_zip(&dir)).await? {
                    let path = self.path("checkpoint");
                    let reply = with_retries("checkpoint", self.ctx.patience, || {
                        self.ctx.coordinator.put(&path, bytes.clone())
                    })
                    .await
                    .map_err(|e| JobFailure::transient(e.to_string()))?;
                    // Cancelled or lease lost: the stop reason is set; the heartbeat
                    // no longer runs, so wait for the thread and drop the result.
                    proceed(self.ctx, reply);
                    uploaded = latest;
                    tracing::info!(
                        progress = self.ctx.control.progress(),
                        "checkpoint uploaded"
                    );
                }
            }
        }
    }
}

fn io_error(path: &Path, source: std::io::Error) -> PipelineError {
    PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The newest complete PPO checkpoint under `dir` as a zip of its folder.
fn latest_checkpoint_zip(dir: &Path) -> Result<Option<Vec<u8>>, PipelineError> {
    let Some(latest) = ppo::latest_checkpoint(dir).map_err(correct::CorrectError::from)? else {
        return Ok(None);
    };
    let name = latest
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    zip_files(&latest, &format!("{name}/")).map(Some)
}

/// The files of `dir` (not recursive) as a zip.
fn zip_dir(dir: &Path) -> Result<Vec<u8>, PipelineError> {
    zip_files(dir, "")
}

fn zip_files(dir: &Path, prefix: &str) -> Result<Vec<u8>, PipelineError> {
    let zip_err = |e: zip::result::ZipError| PipelineError::Job(format!("zip: {e}"));
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| io_error(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    entries.sort();
    for path in entries {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let bytes = std::fs::read(&path).map_err(|e| io_error(&path, e))?;
        zip.start_file(format!("{prefix}{name}"), options)
            .map_err(zip_err)?;
        zip.write_all(&bytes).map_err(|e| io_error(&path, e))?;
    }
    Ok(zip.finish().map_err(zip_err)?.into_inner())
}

/// Unpacks a zip made by [`zip_files`] into `dir` (entries with `..` or
/// absolute paths are refused).
fn unzip_into(bytes: &[u8], dir: &Path) -> Result<(), PipelineError> {
    let zip_err = |e: zip::result::ZipError| PipelineError::Job(format!("zip: {e}"));
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(zip_err)?;
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).map_err(zip_err)?;
        let relative = entry
            .enclosed_name()
            .ok_or_else(|| PipelineError::Job("zip: an entry leaves its folder".into()))?;
        let path = dir.join(relative);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| io_error(parent, e))?;
        }
        let mut content = Vec::new();
        entry
            .read_to_end(&mut content)
            .map_err(|e| io_error(&path, e))?;
        std::fs::write(&path, content).map_err(|e| io_error(&path, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_survive_zipping() {
        let root = std::env::temp_dir().join(format!("motionaug-zip-{}", uuid::Uuid::new_v4()));
        let ckpt = root.join("a").join("ckpt-00000003-0000000000001");
        std::fs::create_dir_all(&ckpt).unwrap();
        std::fs::write(ckpt.join("state.json"), b"{}").unwrap();
        std::fs::write(ckpt.join("tensors.safetensors"), [1u8, 2, 3]).unwrap();
        let zipped = zip_files(&ckpt, "ckpt-00000003-0000000000001/").unwrap();
        let out = root.join("b");
        unzip_into(&zipped, &out).unwrap();
        let back = out.join("ckpt-00000003-0000000000001");
        assert_eq!(std::fs::read(back.join("state.json")).unwrap(), b"{}");
        assert_eq!(
            std::fs::read(back.join("tensors.safetensors")).unwrap(),
            [1, 2, 3]
        );
        assert!(unzip_into(b"not a zip", &out).is_err());
        std::fs::remove_dir_all(root).unwrap();
    }
}
