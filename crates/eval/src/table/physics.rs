//! The physically corrected and debiased rows of the table.
//!
//! Why a module of its own: correction is minutes of PPO per clip, so the
//! table corrects a subset of the VAE's near samples (spread evenly over the
//! set), keeps the work in a folder so an interrupted table resumes where it
//! stopped, and bounds each clip by environment samples rather than wall time,
//! so that the rows do not depend on how busy the machine is.
//!
//! The jobs are the pipeline's own, run by its one executor
//! (`pipeline::run_plan` of a `pipeline::plan::corrections` plan, as
//! `motionaug augment` and the service's workers run theirs): correct the
//! training clips (originals), correct the samples warm-started from the best
//! corrected original's policy, train the debiasing network on the
//! (corrected original, original) pairs of accepted corrections, apply it to
//! the accepted corrected samples. What the table changes is in
//! [`pipeline::Tune`]: at most `correct_samples` PPO samples per clip, the
//! table's threads for a tracker running alone (one per correction side by
//! side), and the samples' corrections kept in `work/samples/`.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

use motion::Motion;
use serde::{Deserialize, Serialize};

use crate::Log;
use crate::error::{EvalError, Result};

/// How much physics the table spends; [`Default`] is the CLI's defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PhysicsConfig {
    /// VAE near samples corrected per class and fold (`None`: 2 per training clip).
    pub correct_count: Option<usize>,
    /// Training clips corrected for the debiasing network (`None`: all).
    pub correct_originals: Option<usize>,
    /// PPO environment samples per clip at most (training stops earlier once
    /// the clip reaches the target R_norm; a PPO iteration is 4096 samples).
    pub correct_samples: u64,
    /// Wall-time cap per clip, seconds (a safety net; samples are the budget).
    pub correct_budget_s: f64,
    /// Debiasing network optimiser steps.
    pub debias_iterations: usize,
    /// `clip`: every clip trains its own policy (warm-started from the best
    /// corrected original), bounded by `correct_samples`; `class`: one tracker
    /// per class and fold trained on the originals first, every clip judged
    /// with it and fine-tuned for at most `clip_iterations` when it fails.
    pub policy: pipeline::PolicyKind,
    /// PPO iterations of the class tracker at most (`policy = class`).
    pub tracker_iterations: u64,
    /// Wall-time cap of the class tracker, seconds (`policy = class`).
    pub tracker_budget_s: f64,
    /// PPO iterations of a clip's fine-tuning at most (`policy = class`).
    pub clip_iterations: u64,
    /// PPO iterations at most of a training clip's own correction (`policy =
    /// class`; `[correct] original_max_iterations`); `None`: `clip_iterations`.
    /// Left out of the config's JSON when `None`, so tables saved before it
    /// existed still resume and merge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub original_iterations: Option<u64>,
    /// With `policy = class`, samples the class tracker fails as is start from
    /// a second tracker trained on them for at most this many PPO iterations
    /// (`[correct] variant_tracker_iterations`); 0 = off. Left out of the
    /// config's JSON when 0, so tables saved before it existed still resume.
    #[serde(skip_serializing_if = "is_zero")]
    pub variant_tracker_iterations: u64,
    /// A clip that fails on skating alone is trained with the sole reward's
    /// sliding term at this speed scale, m/s, from then on (`[correct]
    /// skate_scale_when_skating_m_s`, the same default); 0 = never. Tables
    /// saved before it existed read as 0 (their cells were computed without
    /// it) and are recomputed under the new default.
    #[serde(default)]
    pub skate_scale_when_skating_m_s: f32,
    /// After the debiasing network, put the corrected clip's planted feet
    /// back ([`debias::ContactConfig::restore`]); off shows what the network
    /// alone does to the rows. Left out of the config's JSON when on (the
    /// default), so tables saved before it existed still resume (a missing
    /// field reads as the struct's default, on).
    #[serde(skip_serializing_if = "is_true")]
    pub debias_restore_contacts: bool,
    /// The debiasing network starts as the pairs' mean change
    /// ([`debias::TrainConfig::start_from_mean`]). Left out of the config's
    /// JSON when off (the default), so tables saved before it existed resume.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub debias_start_from_mean: bool,
    /// Low-pass of the debiasing network's change over time, seconds
    /// ([`debias::TrainConfig::smoothing_s`], the same default); 0 = none.
    /// Tables saved before it existed read as 0 (their debiased rows were
    /// made without it) and are recomputed under the new default; 0 is
    /// left out of the JSON, so they still merge with tables run with 0.
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub debias_smoothing_s: f64,
    /// The debiaser's change applied at this gain instead of its held-out
    /// choice ([`debias::TrainConfig::gain`], an ablation). Left out of the
    /// config's JSON when unset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub debias_gain: Option<f64>,
    /// What the debiaser's held-out check holds out
    /// ([`debias::TrainConfig::hold_out`]): a share of the clips (the
    /// default, left out of the JSON so earlier tables still resume and
    /// merge) or each training actor in turn.
    #[serde(default, skip_serializing_if = "debias::HoldOut::is_clips")]
    pub debias_hold_out: debias::HoldOut,
    /// With `policy = class`: each clip's fine-tuning lowers the root force's
    /// gains from the tracker's scale to this over its `clip_iterations`
    /// (`[correct] tracker_final_residual_scale`). Left out of the config's
    /// JSON when unset. Finished corrections in the work folder are reused
    /// whatever their settings: measure it in a fresh one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracker_final_residual_scale: Option<f32>,
    /// Every clip is imitated with its root re-integrated from its planted
    /// feet (`[correct] plant_reference`); acceptance still compares the
    /// output with the clip as given. Left out of the config's JSON when off
    /// (the default). Finished corrections in the work folder are reused
    /// whatever their settings: measure it in a fresh one.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub plant_reference: bool,
    /// The training reward of a step that ends in a fall, negated, in the
    /// trackers and every correction (`[correct] fall_penalty`). Left out of
    /// the config's JSON when 0 (the default). Finished corrections and
    /// trackers in the work folder are reused whatever their settings:
    /// measure it in a fresh one.
    #[serde(default, skip_serializing_if = "is_zero_f32")]
    pub fall_penalty: f32,
}

fn is_zero_f32(x: &f32) -> bool {
    *x == 0.0
}

fn is_zero_f64(x: &f64) -> bool {
    *x == 0.0
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

fn is_true(b: &bool) -> bool {
    *b
}

impl Default for PhysicsConfig {
    fn default() -> Self {
        PhysicsConfig {
            correct_count: None,
            correct_originals: None,
            correct_samples: 40_960,
            correct_budget_s: 600.0,
            debias_iterations: 2000,
            policy: pipeline::PolicyKind::Clip,
            tracker_iterations: 150,
            tracker_budget_s: 6000.0,
            clip_iterations: 15,
            original_iterations: None,
            variant_tracker_iterations: 0,
            skate_scale_when_skating_m_s: correct::CorrectConfig::default()
                .skate_scale_when_skating_m_s,
            debias_restore_contacts: true,
            debias_start_from_mean: false,
            debias_smoothing_s: debias::TrainConfig::default().smoothing_s,
            debias_gain: None,
            debias_hold_out: debias::HoldOut::Clips,
            tracker_final_residual_scale: None,
            plant_reference: false,
            fall_penalty: 0.0,
        }
    }
}

impl PhysicsConfig {
    pub fn validate(&self) -> Result<()> {
        if !(self.tracker_budget_s.is_finite() && self.tracker_budget_s > 0.0) {
            return Err(EvalError::Config(
                "the class tracker's time budget must be positive".into(),
            ));
        }
        debias_config(self)
            .validate()
            .map_err(|e| EvalError::Config(format!("debiasing: {e}")))?;
        if self.original_iterations.is_some() && self.policy != pipeline::PolicyKind::Class {
            return Err(EvalError::Config(
                "the training clips' own iterations (original iterations) need the class policy"
                    .into(),
            ));
        }
        if self.variant_tracker_iterations > 0 && self.policy != pipeline::PolicyKind::Class {
            return Err(EvalError::Config(
                "a second tracker (variant tracker iterations) needs the class policy".into(),
            ));
        }
        if self.tracker_final_residual_scale.is_some() && self.policy != pipeline::PolicyKind::Class
        {
            return Err(EvalError::Config(
                "lowering the tracker's residual scale needs the class policy".into(),
            ));
        }
        // Its range, as the correction itself checks it.
        correct_step(self)
            .config(0)
            .validate()
            .map_err(|e| EvalError::Config(format!("correction: {e}")))?;
        let skate = self.skate_scale_when_skating_m_s;
        if !(skate.is_finite() && skate >= 0.0) {
            return Err(EvalError::Config(format!(
                "the sliding term's speed scale {skate} m/s is not >= 0"
            )));
        }
        if !(self.correct_budget_s.is_finite() && self.correct_budget_s > 0.0) {
            return Err(EvalError::Config(
                "the correction's time budget must be positive".into(),
            ));
        }
        Ok(())
    }
}

/// What the correction did, for the table's JSON: the originals, and the
/// samples of every corrected set together and (`by_set`) each on its own.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PhysicsSummary {
    pub originals: usize,
    pub originals_accepted: usize,
    /// Originals failing each acceptance criterion, by criterion name.
    #[serde(default)]
    pub originals_rejected_by: BTreeMap<String, usize>,
    /// (corrected, original) pairs the debiaser learnt from: the accepted originals.
    pub debias_pairs: usize,
    pub samples: usize,
    pub samples_accepted: usize,
    /// Mean R_norm of the corrected samples (final rollout).
    pub mean_r_norm: f64,
    /// Mean R_norm of the same samples tracked with action 0.
    pub mean_r_norm_action0: f64,
    pub mean_residual_force_ratio: f64,
    /// The same counts and means per corrected set (`vae`, `ik`).
    #[serde(default)]
    pub by_set: BTreeMap<String, SetCorrection>,
    /// PPO samples and wall seconds spent, originals and samples together.
    pub ppo_samples: u64,
    pub seconds: f64,
}

/// What the correction did to the subset of one synthesised set.
#[derive(Debug, Clone, Serialize, Deserialize, Default, PartialEq)]
pub struct SetCorrection {
    pub samples: usize,
    pub samples_accepted: usize,
    pub mean_r_norm: f64,
    pub mean_r_norm_action0: f64,
    pub mean_residual_force_ratio: f64,
    /// Clips failing each acceptance criterion, by criterion name (a clip
    /// can fail several).
    #[serde(default)]
    pub rejected_by: BTreeMap<String, usize>,
}

/// Adds one to each criterion `report` failed.
fn count_failed(report: &correct::Report, counts: &mut BTreeMap<String, usize>) {
    for c in report.criteria.iter().filter(|c| !c.passed) {
        *counts.entry(c.name.clone()).or_default() += 1;
    }
}

impl SetCorrection {
    fn of<'a>(reports: impl Iterator<Item = &'a correct::Report>) -> SetCorrection {
        let mut s = SetCorrection::default();
        for r in reports {
            s.samples += 1;
            s.samples_accepted += usize::from(r.accepted);
            s.mean_r_norm += r.r_norm;
            s.mean_r_norm_action0 += r.r_norm_action0;
            s.mean_residual_force_ratio += r.residual_force_ratio;
            count_failed(r, &mut s.rejected_by);
        }
        let n = s.samples.max(1) as f64;
        s.mean_r_norm /= n;
        s.mean_r_norm_action0 /= n;
        s.mean_residual_force_ratio /= n;
        s
    }
}

/// A synthesised set whose subset the table corrects: the prefix of its rows
/// (`vae` -> `vae_sub`, `vae_corrected`, `vae_debiased`) and its clips.
pub struct ToCorrect<'a> {
    pub row: &'a str,
    pub clips: &'a [(String, Motion)],
}

/// One corrected set's three versions of the same clips: as made, after
/// correction (accepted clips only), after debiasing.
pub struct CorrectedSet {
    pub row: String,
    pub subset: Vec<(String, Motion)>,
    pub corrected: Vec<(String, Motion)>,
    pub debiased: Vec<(String, Motion)>,
}

/// Every corrected set and what the correction cost.
pub struct PhysicsSets {
    pub sets: Vec<CorrectedSet>,
    pub summary: PhysicsSummary,
}

/// `count` items spread evenly over `items` (all of them when there are fewer).
pub fn spread<T: Clone>(items: &[T], count: usize) -> Vec<T> {
    if count >= items.len() {
        return items.to_vec();
    }
    (0..count)
        .map(|i| items[i * items.len() / count].clone())
        .collect()
}

/// The rollout threads of a job that runs alone (a tracker; corrections side
/// by side get one each from the runner), and (per-clip policies) the sample
/// bound; a class tracker and its fine-tuning are bounded by iterations
/// instead (a sample bound would cut the tracker short). PPO's experience
/// does not depend on its thread count (`ppo::PpoConfig::rollout_batch`), so
/// neither do the rows.
fn tune(
    config: &PhysicsConfig,
    threads: usize,
) -> impl Fn(&mut correct::CorrectConfig) + Sync + use<> {
    let max_samples =
        (config.policy == pipeline::PolicyKind::Clip).then_some(config.correct_samples);
    move |c: &mut correct::CorrectConfig| {
        c.ppo.threads = threads.max(1);
        if max_samples.is_some() {
            c.max_samples = max_samples;
        }
    }
}

/// What the run's events told about the corrections.
#[derive(Default)]
struct Seen {
    /// Every correction's report, by clip.
    reports: HashMap<String, correct::Report>,
    /// Accepted corrected samples (before debiasing), by clip.
    corrected: HashMap<String, Motion>,
    done: usize,
    /// When each running job started, by key (corrections run side by side);
    /// a tracker found trained in the work folder has no start.
    started: HashMap<String, Instant>,
    debias_started: Option<Instant>,
    said_warm_start: bool,
}

/// Whether a tracker job's folder already holds its trained tracker (the
/// runner reuses it; `class.json` is written last).
fn tracker_trained(work: &Path, job: &pipeline::PlannedJob) -> bool {
    pipeline::exec::job_dir(work, job)
        .is_some_and(|dir| dir.join(correct::class::REPORT_FILE).is_file())
}

impl Seen {
    /// Keeps what the runner reports: when jobs start (for timings and the
    /// warm-start line), and every correction's report and accepted clip.
    fn observe(
        &mut self,
        event: pipeline::Event<'_>,
        originals: &[String],
        total: usize,
        work: &Path,
        log: Log,
    ) {
        match event {
            pipeline::Event::JobStarted { job } => {
                let reused = matches!(
                    job.kind,
                    pipeline::JobKind::Tracker { .. } | pipeline::JobKind::VariantTracker { .. }
                ) && tracker_trained(work, job);
                if !reused {
                    self.started.insert(job.key.clone(), Instant::now());
                }
                match &job.kind {
                    pipeline::JobKind::Tracker { .. } if reused => {
                        log("class tracker: reusing the one trained earlier in the work folder")
                    }
                    pipeline::JobKind::Tracker { clips, .. } => log(&format!(
                        "class tracker: training on {} originals",
                        clips.len()
                    )),
                    pipeline::JobKind::VariantTracker { .. } if reused => {
                        log("second tracker: reusing the one trained earlier in the work folder")
                    }
                    pipeline::JobKind::VariantTracker { clips, .. } => log(&format!(
                        "second tracker: judging {} samples with the class tracker, \
                         training on those it fails",
                        clips.len()
                    )),
                    pipeline::JobKind::Correct {
                        tracker: Some(_),
                        variant_tracker,
                        ..
                    } if !self.said_warm_start => {
                        self.said_warm_start = true;
                        log(if *variant_tracker {
                            "warm start: every sample starts from the class tracker, or from \
                             the second tracker when the class tracker fails it as is"
                        } else {
                            "warm start: every sample starts from the class tracker"
                        });
                    }
                    pipeline::JobKind::Correct { .. } if !self.said_warm_start => {
                        self.said_warm_start = true;
                        log(&warm_start_line(originals, &self.reports));
                    }
                    pipeline::JobKind::DebiasTrain { .. } => {
                        self.debias_started = Some(Instant::now())
                    }
                    _ => {}
                }
            }
            pipeline::Event::JobFinished { job, ok } => {
                let started = self.started.remove(&job.key);
                let what = match job.kind {
                    pipeline::JobKind::Tracker { .. } => Some("class tracker"),
                    pipeline::JobKind::VariantTracker { .. } => Some("second tracker"),
                    _ => None,
                };
                // A tracker found trained has no start: no "trained in" line.
                if let (Some(what), Some(started)) = (what, started) {
                    log(&format!(
                        "{what}: {} in {:.0} s",
                        if ok { "trained" } else { "failed" },
                        started.elapsed().as_secs_f64()
                    ));
                }
            }
            pipeline::Event::Corrected {
                job,
                report,
                motion,
            } => {
                self.done += 1;
                let Some(name) = job.kind.clip() else { return };
                log(&format!(
                    "correct {}/{total} {name}: R_norm {:.3} -> {:.3}, {} samples, {}, {:.1} s",
                    self.done,
                    report.r_norm_action0,
                    report.r_norm,
                    report.samples,
                    if report.accepted {
                        "accepted"
                    } else {
                        "rejected"
                    },
                    self.started
                        .get(&job.key)
                        .map_or(0.0, |t| t.elapsed().as_secs_f64())
                ));
                if report.accepted && matches!(job.kind, pipeline::JobKind::Correct { .. }) {
                    self.corrected.insert(name.to_string(), motion.clone());
                }
                self.reports.insert(name.to_string(), report.clone());
            }
            _ => {}
        }
    }
}

/// The run's failures, but for the expected ones: nothing to debias (no
/// accepted original). A sample whose own correction was rejected is not a
/// failure: its debiasing runs and finds nothing to debias.
fn unexpected_failures(run: &pipeline::Summary, no_pairs: bool) -> Vec<String> {
    run.failures
        .iter()
        .filter(|(key, _)| {
            let expected = no_pairs && (key == "debias_train" || key.starts_with("debias_apply:"));
            !expected
        })
        .map(|(key, reason)| format!("{key}: {reason}"))
        .collect()
}

/// The training clips the table corrects (for the debiaser's pairs): the
/// same in [`correct_originals`] and [`correct_and_debias`], so the second
/// finds the first's corrections.
fn originals_to_correct(
    config: &PhysicsConfig,
    train: &[(String, Motion)],
) -> Vec<(String, Motion)> {
    spread(train, config.correct_originals.unwrap_or(train.len()))
}

/// Each clip's correction seed: its place in `names` (the originals first,
/// so their seeds are the same with or without the samples after them).
fn seeds_in_order<'a>(names: impl IntoIterator<Item = &'a String>) -> HashMap<&'a str, u64> {
    names
        .into_iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i as u64))
        .collect()
}

/// The correction step every job of the table's plans runs.
fn correct_step(config: &PhysicsConfig) -> pipeline::CorrectStep {
    let class = config.policy == pipeline::PolicyKind::Class;
    pipeline::CorrectStep {
        time_budget_s: config.correct_budget_s,
        policy: config.policy,
        max_iterations: class.then_some(config.clip_iterations),
        original_max_iterations: config.original_iterations.filter(|_| class),
        tracker_iterations: Some(config.tracker_iterations),
        tracker_budget_s: config.tracker_budget_s,
        variant_tracker_iterations: config.variant_tracker_iterations,
        skate_scale_when_skating_m_s: config.skate_scale_when_skating_m_s,
        tracker_final_residual_scale: config.tracker_final_residual_scale,
        plant_reference: config.plant_reference,
        fall_penalty: config.fall_penalty,
        ..pipeline::CorrectStep::default()
    }
}

/// Runs a plan of the table's corrections in `work`, `threads` at a time,
/// tuned as the table tunes them ([`tune`], the samples' corrections kept in
/// `work/samples/`).
fn run_corrections(
    config: &PhysicsConfig,
    plan: &pipeline::Plan,
    clips: &[pipeline::Clip],
    made: Vec<pipeline::WorkClip>,
    work: &Path,
    threads: usize,
    on_event: &(dyn Fn(pipeline::Event<'_>) + Sync),
) -> Result<pipeline::Summary> {
    let tune_correction = tune(config, threads);
    Ok(pipeline::run_plan(
        plan,
        clips,
        made,
        &pipeline::Options {
            out: None,
            work,
            seed: 0,
            on_event,
        },
        pipeline::Tune {
            correction: Some(&tune_correction),
            corrections_folder: Some("samples"),
            parallel_corrections: threads,
        },
    )?)
}

/// The training clips' corrections on their own, one at a time (with `policy
/// = class` the class tracker first): the same jobs, seeds and folders as in
/// [`correct_and_debias`], which finds them finished in `work` and reuses
/// them. They need nothing from the synthesised sets, so the table runs them
/// beside the VAE's training when it has a second thread; the rows do not
/// change. Returns the wall seconds.
pub fn correct_originals(
    config: &PhysicsConfig,
    train: &[(String, Motion)],
    work: &Path,
    log: Log,
) -> Result<f64> {
    let started = Instant::now();
    let originals = originals_to_correct(config, train);
    let names: Vec<String> = originals.iter().map(|(n, _)| n.clone()).collect();
    let seeds = seeds_in_order(&names);
    let plan = pipeline::corrections(&names, &[], &correct_step(config), None, |name| {
        seeds.get(name).copied().unwrap_or(0)
    });
    let seen = Mutex::new(Seen::default());
    let on_event = |event: pipeline::Event<'_>| {
        if let Ok(mut seen) = seen.lock() {
            seen.observe(event, &names, names.len(), work, log);
        }
    };
    let clips = pipeline::Clip::all_from(&originals);
    let run = run_corrections(config, &plan, &clips, Vec::new(), work, 1, &on_event)?;
    let failures = unexpected_failures(&run, false);
    if !failures.is_empty() {
        return Err(EvalError::Correction(failures.join("; ")));
    }
    Ok(started.elapsed().as_secs_f64())
}

/// Corrects a subset of each of `sets` (see [`PhysicsConfig`]) and the
/// training clips in `work`, `threads` corrections at a time, then
/// debiases; finished corrections in `work` are reused, interrupted ones
/// resumed. The originals' corrections and the debiaser are shared by all
/// sets.
pub fn correct_and_debias(
    config: &PhysicsConfig,
    train: &[(String, Motion)],
    sets: &[ToCorrect<'_>],
    work: &Path,
    threads: usize,
    log: Log,
) -> Result<PhysicsSets> {
    let started = Instant::now();
    let per_set = config.correct_count.unwrap_or(2 * train.len());
    let subsets: Vec<Vec<(String, Motion)>> =
        sets.iter().map(|s| spread(s.clips, per_set)).collect();
    let originals = originals_to_correct(config, train);
    let all_samples: Vec<&(String, Motion)> = subsets.iter().flatten().collect();
    if originals.is_empty() || all_samples.is_empty() {
        return Err(EvalError::Data(format!(
            "nothing to correct ({} training clips, {} samples)",
            originals.len(),
            all_samples.len()
        )));
    }
    let original_names: Vec<String> = originals.iter().map(|(n, _)| n.clone()).collect();
    let sample_names: Vec<String> = all_samples.iter().map(|(n, _)| n.clone()).collect();
    let mut unique = HashSet::new();
    if let Some(twice) = original_names
        .iter()
        .chain(&sample_names)
        .find(|n| !unique.insert(n.as_str()))
    {
        return Err(EvalError::Data(format!(
            "two clips to correct are both called `{twice}`"
        )));
    }
    // Seeds as the table always had them: the originals 0.., then the
    // samples, set after set (the VAE's first, so its seeds did not change
    // when the IK edits joined).
    let seeds = seeds_in_order(original_names.iter().chain(&sample_names));
    let step = correct_step(config);
    let debias = debias_config(config);
    let plan = pipeline::corrections(
        &original_names,
        &sample_names,
        &step,
        Some(&debias),
        |name| seeds.get(name).copied().unwrap_or(0),
    );
    let clips = pipeline::Clip::all_from(&originals);
    let made: Vec<pipeline::WorkClip> = all_samples
        .iter()
        .map(|(name, m)| pipeline::WorkClip::given(name, m.clone()))
        .collect();

    let total = originals.len() + all_samples.len();
    let seen = Mutex::new(Seen::default());
    let on_event = |event: pipeline::Event<'_>| {
        if let Ok(mut seen) = seen.lock() {
            seen.observe(event, &original_names, total, work, log);
        }
    };
    let run = run_corrections(config, &plan, &clips, made, work, threads, &on_event)?;
    let seen = seen
        .into_inner()
        .map_err(|_| EvalError::Data("a correction's progress report panicked".into()))?;

    let report = |name: &str| {
        seen.reports
            .get(name)
            .ok_or_else(|| EvalError::Data(format!("`{name}` was not corrected")))
    };
    let mut summary = PhysicsSummary {
        originals: originals.len(),
        ..PhysicsSummary::default()
    };
    for name in &original_names {
        // A missing report is a failed job, listed below.
        if let Ok(r) = report(name) {
            summary.ppo_samples += r.samples;
            summary.originals_accepted += usize::from(r.accepted);
            count_failed(r, &mut summary.originals_rejected_by);
        }
    }
    // The accepted originals are exactly the debiaser's training pairs.
    summary.debias_pairs = summary.originals_accepted;
    let no_pairs = summary.originals_accepted == 0;
    let failures = unexpected_failures(&run, no_pairs);
    if !failures.is_empty() {
        return Err(EvalError::Correction(failures.join("; ")));
    }
    let sample_reports = sample_names
        .iter()
        .map(|n| report(n))
        .collect::<Result<Vec<_>>>()?;
    summary.ppo_samples += sample_reports.iter().map(|r| r.samples).sum::<u64>();
    let all = SetCorrection::of(sample_reports.into_iter());
    summary.samples = all.samples;
    summary.samples_accepted = all.samples_accepted;
    summary.mean_r_norm = all.mean_r_norm;
    summary.mean_r_norm_action0 = all.mean_r_norm_action0;
    summary.mean_residual_force_ratio = all.mean_residual_force_ratio;

    // The debiased clips are the run's outputs (debias_apply finishes them).
    let mut outputs: HashMap<String, Motion> = run
        .outputs
        .into_iter()
        .map(|o| (o.name, o.motion))
        .collect();
    let mut corrected_sets = Vec::new();
    for (set, subset) in sets.iter().zip(subsets) {
        let reports = subset
            .iter()
            .map(|(n, _)| report(n))
            .collect::<Result<Vec<_>>>()?;
        summary
            .by_set
            .insert(set.row.to_string(), SetCorrection::of(reports.into_iter()));
        let corrected: Vec<(String, Motion)> = subset
            .iter()
            .filter_map(|(name, _)| Some((name.clone(), seen.corrected.get(name)?.clone())))
            .collect();
        let debiased: Vec<(String, Motion)> = corrected
            .iter()
            .filter_map(|(name, _)| Some((name.clone(), outputs.remove(name)?)))
            .collect();
        corrected_sets.push(CorrectedSet {
            row: set.row.to_string(),
            subset,
            corrected,
            debiased,
        });
    }
    let debiased_count: usize = corrected_sets.iter().map(|s| s.debiased.len()).sum();
    if no_pairs {
        // Nothing to learn the simulation's bias from: the rows stay empty.
        log("debias: no original passed its correction; no debiased set");
    } else {
        log(&format!(
            "debias: trained on {} pairs, applied to {debiased_count} clips in {:.1} s",
            summary.debias_pairs,
            seen.debias_started
                .map_or(0.0, |t| t.elapsed().as_secs_f64())
        ));
    }
    summary.seconds = started.elapsed().as_secs_f64();
    Ok(PhysicsSets {
        sets: corrected_sets,
        summary,
    })
}

/// The debiaser's settings: the debias crate's defaults with the table's.
fn debias_config(config: &PhysicsConfig) -> debias::TrainConfig {
    let defaults = debias::TrainConfig::default();
    debias::TrainConfig {
        iterations: config.debias_iterations,
        contacts: debias::ContactConfig {
            restore: config.debias_restore_contacts,
            ..defaults.contacts
        },
        start_from_mean: config.debias_start_from_mean,
        smoothing_s: config.debias_smoothing_s,
        gain: config.debias_gain,
        hold_out: config.debias_hold_out,
        ..defaults
    }
}

/// Which original's policy the samples start from (the executor's choice:
/// accepted first, then the highest R_norm).
fn warm_start_line(originals: &[String], reports: &HashMap<String, correct::Report>) -> String {
    let outcomes: Vec<(bool, f64)> = originals
        .iter()
        .map(|n| {
            reports
                .get(n)
                .map_or((false, f64::NEG_INFINITY), |r| (r.accepted, r.r_norm))
        })
        .collect();
    let Some(best) = pipeline::stages::best_warm_start(&outcomes) else {
        return "warm start: no original to start from".into();
    };
    let (accepted, r_norm) = outcomes[best];
    format!(
        "warm start: samples start from the policy of {} (R_norm {r_norm:.3}, {})",
        originals[best],
        if accepted {
            "accepted"
        } else {
            "no original was accepted"
        }
    )
}

#[cfg(test)]
mod tests {
    use super::{PhysicsConfig, spread};

    #[test]
    fn contact_restoring_is_on_and_absent_from_saved_configs_by_default() {
        // Saved cells are keyed by the config's JSON: the default must write
        // what configs written before the knob existed wrote, and read them
        // back as restoring contacts.
        let default = PhysicsConfig::default();
        let json = serde_json::to_value(&default).unwrap();
        assert!(json.get("debias_restore_contacts").is_none());
        assert!(json.get("debias_start_from_mean").is_none());
        assert!(json.get("original_iterations").is_none());
        assert_eq!(json["debias_smoothing_s"], 0.05);
        assert!(json.get("debias_gain").is_none());
        assert!(json.get("tracker_final_residual_scale").is_none());
        assert!(json.get("debias_hold_out").is_none());
        assert!(json.get("plant_reference").is_none());
        assert!(json.get("fall_penalty").is_none());
        let back: PhysicsConfig = serde_json::from_value(json.clone()).unwrap();
        assert!(back.debias_restore_contacts);
        assert_eq!(back.debias_smoothing_s, 0.05);
        // A table saved before the low-pass existed was debiased without it.
        let mut old = json;
        old.as_object_mut().unwrap().remove("debias_smoothing_s");
        let back: PhysicsConfig = serde_json::from_value(old).unwrap();
        assert_eq!(back.debias_smoothing_s, 0.0);
        let none = PhysicsConfig {
            debias_smoothing_s: 0.0,
            ..PhysicsConfig::default()
        };
        assert!(
            serde_json::to_value(&none)
                .unwrap()
                .get("debias_smoothing_s")
                .is_none()
        );
        let off = PhysicsConfig {
            debias_restore_contacts: false,
            ..default
        };
        let json = serde_json::to_value(&off).unwrap();
        assert_eq!(json["debias_restore_contacts"], false);
        let back: PhysicsConfig = serde_json::from_value(json).unwrap();
        assert!(!back.debias_restore_contacts);
    }

    #[test]
    fn debiasing_gain_and_low_pass_are_checked() {
        for bad in [
            PhysicsConfig {
                debias_gain: Some(1.5),
                ..PhysicsConfig::default()
            },
            PhysicsConfig {
                debias_smoothing_s: -1.0,
                ..PhysicsConfig::default()
            },
        ] {
            let e = bad.validate().expect_err("out of range").to_string();
            assert!(e.contains("debiasing"), "{e}");
        }
        let half = PhysicsConfig {
            debias_gain: Some(0.5),
            ..PhysicsConfig::default()
        };
        half.validate().expect("gain in range");
        assert_eq!(serde_json::to_value(&half).unwrap()["debias_gain"], 0.5);
        let by_actor = PhysicsConfig {
            debias_hold_out: debias::HoldOut::Actors,
            ..PhysicsConfig::default()
        };
        let json = serde_json::to_value(&by_actor).unwrap();
        assert_eq!(json["debias_hold_out"], "actors");
        assert_eq!(
            super::debias_config(&by_actor).hold_out,
            debias::HoldOut::Actors
        );
        let back: PhysicsConfig = serde_json::from_value(json).unwrap();
        assert_eq!(back, by_actor);
    }

    #[test]
    fn lowering_the_trackers_residual_scale_needs_the_class_policy() {
        let lowered = |policy| PhysicsConfig {
            policy,
            tracker_final_residual_scale: Some(0.15),
            ..PhysicsConfig::default()
        };
        let e = lowered(pipeline::PolicyKind::Clip)
            .validate()
            .expect_err("clip policy")
            .to_string();
        assert!(e.contains("class policy"), "{e}");
        let class = lowered(pipeline::PolicyKind::Class);
        class.validate().expect("class policy");
        let step = super::correct_step(&class);
        assert_eq!(step.tracker_final_residual_scale, Some(0.15));
        // Over the clip's fine-tuning iterations.
        let c = step.config(0);
        assert_eq!(c.tracker_final_residual_scale, Some(0.15));
        assert_eq!(c.residual_schedule.over_iterations, class.clip_iterations);
        let zero = PhysicsConfig {
            tracker_final_residual_scale: Some(0.0),
            ..lowered(pipeline::PolicyKind::Class)
        };
        assert!(zero.validate().is_err());
    }

    #[test]
    fn a_planted_reference_reaches_every_correction_and_the_saved_config() {
        let planted = PhysicsConfig {
            policy: pipeline::PolicyKind::Class,
            plant_reference: true,
            ..PhysicsConfig::default()
        };
        planted.validate().expect("valid");
        let json = serde_json::to_value(&planted).unwrap();
        assert_eq!(json["plant_reference"], true);
        let back: PhysicsConfig = serde_json::from_value(json).unwrap();
        assert_eq!(back, planted);
        let step = super::correct_step(&planted);
        assert!(step.config(0).physics.plant_reference);
        assert!(step.tracker_config(0).correct.physics.plant_reference);
        let as_captured = super::correct_step(&PhysicsConfig::default());
        assert!(!as_captured.config(0).physics.plant_reference);
    }

    #[test]
    fn a_fall_penalty_reaches_the_trackers_every_correction_and_the_saved_config() {
        let penalised = PhysicsConfig {
            policy: pipeline::PolicyKind::Class,
            fall_penalty: 10.0,
            ..PhysicsConfig::default()
        };
        penalised.validate().expect("valid");
        let json = serde_json::to_value(&penalised).unwrap();
        assert_eq!(json["fall_penalty"], 10.0);
        let back: PhysicsConfig = serde_json::from_value(json).unwrap();
        assert_eq!(back, penalised);
        let step = super::correct_step(&penalised);
        assert_eq!(step.config(0).physics.fall_penalty, 10.0);
        assert_eq!(step.original_config(0).physics.fall_penalty, 10.0);
        assert_eq!(step.tracker_config(0).correct.physics.fall_penalty, 10.0);
        let negative = PhysicsConfig {
            fall_penalty: -1.0,
            ..penalised
        };
        let e = negative.validate().expect_err("negative").to_string();
        assert!(e.contains("fall penalty"), "{e}");
    }

    #[test]
    fn the_originals_own_iterations_need_the_class_policy() {
        let clip = PhysicsConfig {
            original_iterations: Some(200),
            ..PhysicsConfig::default()
        };
        let e = clip.validate().expect_err("clip policy").to_string();
        assert!(e.contains("original iterations"), "{e}");
        let class = PhysicsConfig {
            policy: pipeline::PolicyKind::Class,
            ..clip
        };
        class.validate().expect("class policy");
        let step = super::correct_step(&class);
        assert_eq!(step.original_max_iterations, Some(200));
        assert_eq!(step.max_iterations, Some(class.clip_iterations));
    }

    #[test]
    fn spread_takes_evenly_spaced_items() {
        let v: Vec<usize> = (0..10).collect();
        assert_eq!(spread(&v, 3), vec![0, 3, 6]);
        assert_eq!(spread(&v, 5), vec![0, 2, 4, 6, 8]);
        assert_eq!(spread(&v, 10), v);
        assert_eq!(spread(&v, 20), v);
        assert!(spread(&v, 0).is_empty());
    }
}
