//! The science of each job kind, given its inputs in memory: one function per
//! kind, called by the one executor ([`crate::exec`]) that the in-process
//! runner, the evaluation and the service's worker all use.

use std::path::Path;

use motion::Motion;
use serde_json::{Map, Value, json};

use crate::PipelineError;
use crate::recipe::{CorrectStep, InteractionStep, VaeStep};

/// A clip a job made, with its manifest entry.
#[derive(Debug, Clone)]
pub struct NewClip {
    pub name: String,
    pub motion: Motion,
    pub mask: Option<synth::Mask>,
    pub entry: synth::ManifestEntry,
}

/// A manifest entry for an output of a dataset-level job (its own fields set by the caller).
fn entry(name: &str, motion: &Motion) -> synth::ManifestEntry {
    synth::ManifestEntry {
        file: format!("{name}.bvh"),
        source: String::new(),
        op: String::new(),
        op_index: 0,
        copy: 0,
        seed: 0,
        params: Value::Null,
        sampled: Map::new(),
        frames: motion.frames(),
        fps: motion.fps(),
        effector: None,
        keyframe: None,
        target: None,
    }
}

/// `synthesize`: one kinematic op output of one clip.
pub fn synthesize(
    ops: &synth::Recipe,
    clip: &str,
    source: &str,
    motion: &Motion,
    job: synth::Job,
) -> Result<NewClip, PipelineError> {
    let generated = synth::run_job(ops, clip, motion, job)?;
    let entry = generated.manifest_entry(format!("{}.bvh", generated.name), source);
    Ok(NewClip {
        name: generated.name,
        motion: generated.output.motion,
        mask: generated.output.mask,
        entry,
    })
}

/// `vae`: train the motion VAE on a class's clips, then sample `copies` clips
/// (manifest op index `op_index`).
pub fn vae(
    step: &VaeStep,
    op_index: usize,
    group: &str,
    clips: &[(String, Motion)],
    seed: u64,
) -> Result<Vec<NewClip>, PipelineError> {
    let span = tracing::info_span!("vae_job", group, clips = clips.len());
    let _guard = span.enter();
    let mut config = step.train_config(seed);
    let motions: Vec<Motion> = clips.iter().map(|(_, m)| m.clone()).collect();
    crate::add_vae_balance_model(&mut config, &motions)?;
    let model = vae::train(&motions, &config, |_| {})?;
    let samples = model.sample_finished(step.copies as usize, step.prior, seed, &step.finish())?;
    let names = crate::plan::vae_outputs(group, step.copies);
    let sources: Vec<Value> = clips.iter().map(|(n, _)| json!(n)).collect();
    let params = serde_json::to_value(step).unwrap_or(Value::Null);
    Ok(samples
        .into_iter()
        .zip(names)
        .enumerate()
        .map(|(copy, (sample, name))| {
            let mut sampled = Map::new();
            sampled.insert("clips".into(), Value::Array(sources.clone()));
            let e = synth::ManifestEntry {
                source: group.to_string(),
                op: "vae".into(),
                op_index,
                copy: copy as u32,
                seed,
                params: params.clone(),
                sampled,
                ..entry(&name, &sample.motion)
            };
            NewClip {
                name,
                motion: sample.motion,
                mask: None,
                entry: e,
            }
        })
        .collect())
}

/// `interaction`: body-size variations of partner B, both partners adapted.
pub fn interaction(
    step: &InteractionStep,
    op_index: usize,
    stem: &str,
    a: &Motion,
    b: &Motion,
    seed: u64,
) -> Result<Vec<NewClip>, PipelineError> {
    let span = tracing::info_span!("interaction_job", pair = stem);
    let _guard = span.enter();
    let spec = step.spec(seed);
    let variations =
        interaction::variations(a, b, &spec, &interaction::RetargetOptions::default())?;
    let params = serde_json::to_value(step).unwrap_or(Value::Null);
    let names = crate::plan::interaction_outputs(stem, step.copies);
    let mut out = Vec::with_capacity(names.len());
    for (v, names) in variations.into_iter().zip(names.chunks(2)) {
        let report = serde_json::to_value(&v.result.report).unwrap_or(Value::Null);
        for (name, motion, side) in [(&names[0], v.result.a, "A"), (&names[1], v.result.b, "B")] {
            let mut sampled = Map::new();
            sampled.insert("partner".into(), json!(side));
            sampled.insert("scale".into(), json!(v.scale.default));
            sampled.insert("report".into(), report.clone());
            let e = synth::ManifestEntry {
                source: stem.to_string(),
                op: "interaction".into(),
                op_index,
                copy: v.index as u32,
                seed,
                params: params.clone(),
                sampled,
                ..entry(name, &motion)
            };
            out.push(NewClip {
                name: name.clone(),
                motion,
                mask: None,
                entry: e,
            });
        }
    }
    Ok(out)
}

/// `correct` / `correct_original`: physical correction of one clip in `dir`
/// (checkpoints, report, corrected clip). A finished correction in `dir` is
/// reused; checkpoints of an interrupted one are resumed.
pub fn correct(
    step: &CorrectStep,
    name: &str,
    motion: &Motion,
    seed: u64,
    dir: &Path,
    warm_start: Option<&Path>,
    on_progress: impl FnMut(&correct::job::ProgressEvent),
) -> Result<correct::Outcome, PipelineError> {
    correct_with_config(
        step.config(seed),
        name,
        motion,
        dir,
        warm_start,
        on_progress,
    )
}

/// Which corrected original warm-starts a correction, given each candidate's
/// (accepted, R_norm) in order: the accepted one with the highest R_norm, else
/// (none accepted) the highest R_norm; ties go to the first; `None` without
/// candidates. Measured on the HDM05 eval table (10 PPO iterations per clip):
/// starting VAE samples from the best original instead of the class's first
/// clip took deposit from 10 to 26 of 52 samples accepted.
pub fn best_warm_start(outcomes: &[(bool, f64)]) -> Option<usize> {
    (0..outcomes.len()).max_by(|&a, &b| {
        let (ka, kb) = (outcomes[a], outcomes[b]);
        ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1)).then(b.cmp(&a))
    })
}

/// [`correct`] with the job's settings given whole (the service's workers
/// shorten `checkpoint_every_s` so that another worker can resume a job).
pub fn correct_with_config(
    mut config: correct::CorrectConfig,
    name: &str,
    motion: &Motion,
    dir: &Path,
    warm_start: Option<&Path>,
    on_progress: impl FnMut(&correct::job::ProgressEvent),
) -> Result<correct::Outcome, PipelineError> {
    if let Some(done) = finished_correction(motion, dir)? {
        tracing::info!(clip = name, "correction already finished; reused");
        return Ok(done);
    }
    config.warm_start = warm_start
        .filter(|d| ppo::latest_checkpoint(d).ok().flatten().is_some())
        .map(Path::to_path_buf);
    let resume = has_checkpoint(&dir.join("checkpoints"))?;
    let outcome = correct::correct(motion, name, &config, dir, resume, on_progress)?;
    motion::io::write_atomic(
        &dir.join(EXACT),
        &crate::codec::encode_clip(&outcome.motion, None)?,
    )?;
    Ok(outcome)
}

/// The corrected clip in full f64 precision ([`crate::codec`]; the BVH and NPZ
/// outputs round), so a reused correction gives bit-identical results downstream.
const EXACT: &str = "corrected.exact.npz";

/// The outcome of a correction that already finished in `dir`, if there is one.
pub fn finished_correction(
    motion: &Motion,
    dir: &Path,
) -> Result<Option<correct::Outcome>, PipelineError> {
    let (report_path, exact) = (dir.join("report.json"), dir.join(EXACT));
    if !(report_path.is_file() && exact.is_file()) {
        return Ok(None);
    }
    let report = correct::Report::read(&report_path)?;
    let bytes = std::fs::read(&exact).map_err(|source| PipelineError::Io {
        path: exact.clone(),
        source,
    })?;
    let (corrected, _) = crate::codec::decode_clip(&bytes)?;
    if corrected.joints() != motion.joints() {
        return Err(PipelineError::Job(format!(
            "{}: a clip of {} joints, not {}",
            exact.display(),
            corrected.joints(),
            motion.joints()
        )));
    }
    Ok(Some(correct::Outcome {
        motion: corrected,
        report,
    }))
}

/// `tracker`: train the class tracker on `clips` in `dir` (`class.json`,
/// `checkpoints/`). A finished tracker in `dir` is reused; an interrupted one
/// resumed from its checkpoint.
pub fn train_tracker(
    config: &correct::ClassConfig,
    clips: &[(String, Motion)],
    dir: &Path,
    on_progress: &(dyn Fn(&correct::job::ProgressEvent) + Sync),
) -> Result<correct::ClassReport, PipelineError> {
    if let Some(done) = reuse_class(dir)? {
        return Ok(done);
    }
    let resume = has_checkpoint(&correct::class::checkpoints_of(dir))?;
    Ok(correct::train_class(clips, config, dir, resume, |p| {
        on_progress(&class_progress(p))
    })?)
}

/// The folder under a `variant_tracker` job's folder holding the class
/// tracker's verdict on each new clip as is (`class.json`).
pub const JUDGED_DIR: &str = "judged";

/// What a `variant_tracker` job found and made.
#[derive(Debug, Clone)]
pub struct VariantTracker {
    /// The class tracker's verdict on every new clip as is.
    pub judged: correct::ClassReport,
    /// The second tracker, trained on the clips the class tracker fails
    /// (`None` when it fails none); its folder is the job's.
    pub second: Option<correct::ClassReport>,
}

impl VariantTracker {
    /// Whether the class tracker failed new clip `clip` as is (in `judged`,
    /// its verdicts): such a clip starts its correction from the second
    /// tracker, when one was trained.
    pub fn failed_as_is(judged: &correct::ClassReport, clip: &str) -> bool {
        judged
            .verdicts
            .iter()
            .any(|v| v.name == clip && !v.accepted)
    }
}

/// `variant_tracker`: judge the class's new `clips` with the class tracker in
/// `class_dir` as is (into `dir/judged`), then train a second tracker in
/// `dir`, from the class tracker at its residual gains and observation, on
/// the clips it fails, for at most `iterations` PPO iterations within
/// `config`'s time budget. Finished parts in `dir` are reused; an interrupted
/// second tracker is resumed from its checkpoint.
///
/// Why: a tracker trained on a class's originals passes most IK edits as is
/// but few VAE samples; training it further on every new clip dilutes what
/// it learnt, on the failures only it learns what they need (jog, 300
/// iterations: VAE samples accepted 2/34 from the class tracker, 5/34 from
/// one trained on all 68 new clips, 8/34 from one trained on the 38 failures).
pub fn train_variant_tracker(
    config: &correct::CorrectConfig,
    class_dir: &Path,
    clips: &[(String, Motion)],
    iterations: u64,
    dir: &Path,
    on_progress: &(dyn Fn(&correct::job::ProgressEvent) + Sync),
) -> Result<VariantTracker, PipelineError> {
    let class = correct::ClassReport::read(&class_dir.join(correct::class::REPORT_FILE))?;
    let from = |max_iterations: u64| correct::ClassConfig {
        correct: correct::CorrectConfig {
            max_iterations: Some(max_iterations),
            // It trains at the class tracker's scale; only the clips'
            // fine-tunes lower it.
            ..class.warm_config(
                &correct::CorrectConfig {
                    tracker_final_residual_scale: None,
                    ..config.clone()
                },
                class_dir,
            )
        },
        ..correct::ClassConfig::default()
    };
    let judged_dir = dir.join(JUDGED_DIR);
    let judged = match reuse_class(&judged_dir)? {
        Some(done) => done,
        None => {
            let resume = has_checkpoint(&correct::class::checkpoints_of(&judged_dir))?;
            correct::train_class(clips, &from(0), &judged_dir, resume, |_| {})?
        }
    };
    let failed: Vec<(String, Motion)> = clips
        .iter()
        .filter(|(name, _)| VariantTracker::failed_as_is(&judged, name))
        .cloned()
        .collect();
    tracing::info!(
        clips = clips.len(),
        failed = failed.len(),
        "new clips judged with the class tracker as is"
    );
    if failed.is_empty() || iterations == 0 {
        return Ok(VariantTracker {
            judged,
            second: None,
        });
    }
    let second = match reuse_class(dir)? {
        Some(done) => done,
        None => {
            let resume = has_checkpoint(&correct::class::checkpoints_of(dir))?;
            correct::train_class(&failed, &from(iterations), dir, resume, |p| {
                on_progress(&class_progress(p))
            })?
        }
    };
    Ok(VariantTracker {
        judged,
        second: Some(second),
    })
}

/// Whether the `checkpoints` folder of an interrupted training holds a
/// checkpoint to resume from.
fn has_checkpoint(checkpoints: &Path) -> Result<bool, PipelineError> {
    Ok(ppo::latest_checkpoint(checkpoints)
        .map_err(correct::CorrectError::from)?
        .is_some())
}

/// The report of a class tracker already trained in `dir`, if there is one.
fn reuse_class(dir: &Path) -> Result<Option<correct::ClassReport>, PipelineError> {
    let done = dir.join(correct::class::REPORT_FILE);
    if !done.is_file() {
        return Ok(None);
    }
    tracing::info!(dir = %dir.display(), "class tracker already trained; reused");
    Ok(Some(correct::ClassReport::read(&done)?))
}

/// A class tracker's progress as a correction's (what terminals and the
/// service show).
fn class_progress(p: &correct::class::ClassProgress) -> correct::job::ProgressEvent {
    correct::job::ProgressEvent {
        iteration: p.iteration,
        samples: p.samples,
        wall_s: p.wall_s,
        budget_s: p.budget_s,
        mean_reward: p.mean_reward,
        r_norm: None,
    }
}

/// `debias_train`: fit the debiasing network on (corrected original, original)
/// pairs, `actors[i]` the actor of `pairs[i]` (for `hold_out = "actors"`).
/// Callers pass only accepted corrections (a fall is not a bias).
pub fn debias_train(
    config: &debias::TrainConfig,
    pairs: &[(Motion, Motion)],
    actors: &[String],
) -> Result<debias::Debiaser, PipelineError> {
    if pairs.is_empty() {
        return Err(PipelineError::Job(
            "no original clip passed its physical correction: the debiasing network has \
             no (corrected, original) pair to learn from"
                .into(),
        ));
    }
    Ok(debias::train_with_actors(pairs, actors, config)?.0)
}

/// `debias_apply`: remove the learned bias from a corrected clip.
pub fn debias_apply(model: &debias::Debiaser, corrected: &Motion) -> Result<Motion, PipelineError> {
    Ok(model.apply(corrected)?)
}

#[cfg(test)]
mod tests {
    use super::best_warm_start;

    #[test]
    fn warm_start_prefers_the_best_accepted_original() {
        // Accepted beats a higher R_norm that was rejected.
        let o = [(false, 0.9), (true, 0.7), (true, 0.8), (false, 0.95)];
        assert_eq!(best_warm_start(&o), Some(2));
        // None accepted: the best R_norm; ties go to the first.
        assert_eq!(best_warm_start(&[(false, 0.5), (false, 0.6)]), Some(1));
        assert_eq!(best_warm_start(&[(true, 0.8), (true, 0.8)]), Some(0));
        assert_eq!(best_warm_start(&[]), None);
    }
}
