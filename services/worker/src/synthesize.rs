//! The `synthesize` job: run the augmentation's recipe over one clip with the
//! synth crate, output by output.
//!
//! After each output its files are uploaded and a checkpoint (outputs done, their
//! manifest entries) is stored, so an attempt that dies resumes where the last one
//! stopped. Every output has its own seed derived from (seed, clip, op, copy), so
//! a resumed job produces exactly the files an uninterrupted run would.
//!
//! When the recipe has `[correct]`, the outputs are not final: each is stored
//! losslessly (`pipeline::encode_clip`) as `work/clips/<name>.npz` for its
//! `correct` job instead of as BVH and NPZ.

use std::sync::Arc;
use std::time::{Duration, Instant};

use motionaug_protocol::{ClipFormat, SynthesizeCheckpoint, SynthesizeInput, SynthesizeOutput};

use crate::client::{Reply, with_retries};
use crate::runner::{JobContext, JobFailure, Outcome, Stop};

/// Turns a reply into "go on" or "stop"; records why the job must stop.
pub(crate) fn proceed(ctx: &JobContext, reply: Reply<()>) -> bool {
    match reply {
        Reply::Ok(()) => true,
        Reply::Cancelled => {
            ctx.control.set_stop(Stop::Cancelled);
            false
        }
        Reply::LeaseLost => {
            ctx.control.set_stop(Stop::LeaseLost);
            false
        }
    }
}

pub(crate) async fn fetch(
    ctx: &JobContext,
    path: &str,
) -> Result<Option<Option<Vec<u8>>>, JobFailure> {
    let reply = with_retries(path, ctx.patience, || ctx.coordinator.get(path))
        .await
        .map_err(|e| JobFailure::transient(e.to_string()))?;
    Ok(match reply {
        Reply::Ok(bytes) => Some(bytes),
        other => {
            proceed(ctx, other.clone_unit());
            None
        }
    })
}

trait CloneUnit {
    fn clone_unit(&self) -> Reply<()>;
}

impl<T> CloneUnit for Reply<T> {
    fn clone_unit(&self) -> Reply<()> {
        match self {
            Reply::Ok(_) => Reply::Ok(()),
            Reply::LeaseLost => Reply::LeaseLost,
            Reply::Cancelled => Reply::Cancelled,
        }
    }
}

pub(crate) async fn upload(
    ctx: &JobContext,
    path: &str,
    body: Vec<u8>,
) -> Result<bool, JobFailure> {
    let reply = with_retries(path, ctx.patience, || {
        ctx.coordinator.put(path, body.clone())
    })
    .await
    .map_err(|e| JobFailure::transient(e.to_string()))?;
    Ok(proceed(ctx, reply))
}

/// Sleeps for the test-only delay, in small steps so a stop is noticed promptly.
pub(crate) async fn test_pause(ctx: &JobContext) {
    let Some(delay) = ctx.test_delay else { return };
    let until = Instant::now() + delay;
    while Instant::now() < until && ctx.control.stop_reason().is_none() {
        tokio::time::sleep(Duration::from_millis(10).min(until - Instant::now())).await;
    }
}

pub async fn run(ctx: &JobContext) -> Result<Outcome, JobFailure> {
    let job = &ctx.job;
    let input: SynthesizeInput = serde_json::from_value(job.input.clone())
        .map_err(|e| JobFailure::permanent(format!("job input is not a synthesize input: {e}")))?;
    let recipe = Arc::new(
        motionaug_protocol::recipe::parse(&input.recipe)
            .map_err(|e| JobFailure::permanent(format!("recipe: {}", e.message)))?,
    );
    let Some(source) = fetch(ctx, &format!("/clips/{}/source", input.clip_id)).await? else {
        return Ok(Outcome::Stopped);
    };
    let source = source.ok_or_else(|| JobFailure::permanent("the clip no longer exists"))?;
    let skeleton = if input.format == ClipFormat::Amc {
        let Some(bytes) = fetch(ctx, &format!("/clips/{}/skeleton", input.clip_id)).await? else {
            return Ok(Outcome::Stopped);
        };
        Some(bytes.ok_or_else(|| JobFailure::permanent("the clip's ASF skeleton is missing"))?)
    } else {
        None
    };
    let mut checkpoint = SynthesizeCheckpoint::default();
    if job.has_checkpoint {
        let path = format!("/jobs/{}/checkpoint?epoch={}", job.id, job.epoch);
        let Some(bytes) = fetch(ctx, &path).await? else {
            return Ok(Outcome::Stopped);
        };
        if let Some(bytes) = bytes {
            match serde_json::from_slice::<SynthesizeCheckpoint>(&bytes) {
                Ok(c) if c.manifest.len() + c.clips.len() == c.done => checkpoint = c,
                _ => tracing::warn!("checkpoint unreadable; starting over"),
            }
        }
    }
    let load_input = input.clone();
    let motion = tokio::task::spawn_blocking(move || {
        let skeleton_name = load_input.skeleton_name.clone().unwrap_or_default();
        motionaug_protocol::clip::load(
            load_input.format,
            &load_input.source_name,
            &source,
            skeleton.as_deref().map(|s| (skeleton_name.as_str(), s)),
        )
    })
    .await
    .map_err(|e| JobFailure::transient(format!("clip reader crashed: {e}")))?
    .map_err(|e| JobFailure::permanent(format!("cannot read the clip: {e}")))?;
    let motion = Arc::new(motion);
    let synth_recipe = recipe
        .synth
        .as_ref()
        .ok_or_else(|| JobFailure::permanent("the recipe has no [[ops]]"))?;
    let plan = synth_recipe.jobs(&input.clip_name, input.seed);
    let keep_for_correction = recipe.correct.is_some();
    let total = plan.len();
    if checkpoint.done > total {
        tracing::warn!(
            done = checkpoint.done,
            total,
            "checkpoint does not fit the recipe; starting over"
        );
        checkpoint = SynthesizeCheckpoint::default();
    }
    if checkpoint.done > 0 {
        tracing::info!(done = checkpoint.done, total, "resuming from checkpoint");
    }
    ctx.control
        .set_progress(checkpoint.done as f64 / total.max(1) as f64);
    for (index, step) in plan.into_iter().enumerate().skip(checkpoint.done) {
        if ctx.control.stop_reason().is_some() {
            return Ok(Outcome::Stopped);
        }
        let (recipe, motion, clip) = (recipe.clone(), motion.clone(), input.clip_name.clone());
        let source_name = input.source_name.clone();
        let made = tokio::task::spawn_blocking(move || {
            let made = pipeline::stages::synthesize(&recipe, &clip, &source_name, &motion, step)
                .map_err(|e| e.to_string())?;
            crate::stages::finished_or_kept(made, keep_for_correction)
        })
        .await
        .map_err(|e| JobFailure::transient(format!("synthesis crashed: {e}")))?
        .map_err(JobFailure::permanent)?;
        test_pause(ctx).await;
        if ctx.control.stop_reason().is_some() {
            return Ok(Outcome::Stopped);
        }
        for (name, bytes) in made.files {
            let path = format!("/jobs/{}/artifacts/{name}?epoch={}", job.id, job.epoch);
            if !upload(ctx, &path, bytes).await? {
                return Ok(Outcome::Stopped);
            }
            if made.work_clip.is_none() {
                checkpoint.files.push(name);
            }
        }
        checkpoint.manifest.extend(made.entry);
        checkpoint.clips.extend(made.work_clip);
        checkpoint.done = index + 1;
        let body = serde_json::to_vec(&checkpoint)
            .map_err(|e| JobFailure::transient(format!("cannot encode checkpoint: {e}")))?;
        let path = format!("/jobs/{}/checkpoint?epoch={}", job.id, job.epoch);
        if !upload(ctx, &path, body).await? {
            return Ok(Outcome::Stopped);
        }
        ctx.control
            .set_progress(checkpoint.done as f64 / total.max(1) as f64);
    }
    let output = SynthesizeOutput {
        manifest: checkpoint.manifest,
        files: checkpoint.files,
        clips: checkpoint.clips,
        ..SynthesizeOutput::default()
    };
    serde_json::to_value(output)
        .map(Outcome::Done)
        .map_err(|e| JobFailure::transient(format!("cannot encode output: {e}")))
}
