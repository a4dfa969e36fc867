//! One correction job: build the simulated character from the clip, train a
//! PPO policy to imitate it within a time budget (resumable from checkpoints),
//! then roll the final policy deterministically over the whole clip and keep
//! what the character did.
//!
//! Training stops at the first of: the deterministic rollout reaching
//! `target_r_norm` and passing every acceptance criterion
//! ([`crate::acceptance`]), the time budget, or the iteration / sample
//! limits. The curve is reported either way.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use motion::Motion;
use physics::{ImitationEnv, Residual};
use ppo::{Control, PpoConfig, RunLimits, StopReason, Trainer};

use crate::CorrectError;
use crate::acceptance::{AcceptanceConfig, Criterion, all_passed, judge};
use crate::report::{Report, curve_svg};
use crate::rollout::{Rollout, deterministic_rollout};
use crate::task::ImitationTask;

/// Everything a correction job can be told.
#[derive(Debug, Clone)]
pub struct CorrectConfig {
    pub physics: physics::Config,
    pub ppo: PpoConfig,
    /// Parallel environments (spread over `ppo.threads` threads).
    pub envs: usize,
    /// Training wall time budget, seconds, over all resumes.
    pub time_budget_s: f64,
    pub max_iterations: Option<u64>,
    pub max_samples: Option<u64>,
    /// Run the deterministic rollout every this many iterations.
    pub eval_every: u64,
    /// Stop once a rollout reaches this R_norm and passes every acceptance
    /// criterion.
    pub target_r_norm: Option<f64>,
    /// When a corrected clip is accepted ([`crate::acceptance`]).
    pub acceptance: AcceptanceConfig,
    /// Hand the balance from the PD-residual root force to the policy over
    /// training.
    pub residual_schedule: ResidualSchedule,
    /// Starting from a class tracker ([`crate::ClassReport::warm_config`]):
    /// lower the PD-residual gains further, from the tracker's scale to this
    /// one (when lower) over `residual_schedule.over_iterations` fine-tuning
    /// iterations, so a clip the tracker holds up only with more root force
    /// than allowed learns to carry itself (`None`: hold the tracker's scale).
    /// Measured on four jog VAE samples that moved and failed the residual
    /// limit alone after 15 iterations (0.111-0.134 m g; eval fold mm,
    /// session 29), from that fold's second tracker (scale 0.3): 60
    /// iterations held at 0.3 passed 2 of 4 (0.100 and 0.098 m g; the other
    /// two stayed at 0.108 and 0.135); annealing to 0.15 over 30 iterations
    /// passed the three tried (both of those two among them) within 10, 19
    /// and 26 iterations, the criteria unchanged.
    pub tracker_final_residual_scale: Option<f32>,
    /// The sole reward's sliding term ([`physics::Config::skate_scale_m_s`])
    /// at this speed scale, m/s, only for a clip for which skating is the one
    /// criterion failed, by its warm-started policy as is or by a rollout
    /// that reaches the R_norm target (0 = never): switched on from then to
    /// the end of the job, recorded in its checkpoints and `report.json`
    /// (`skate_scale_m_s`). 0.1 by default: measured side by side from the
    /// same class trackers (`motionaug bench correction`, 300 s per clip),
    /// originals accepted grab 27 -> 29 of 29, squat 48 -> 52 of 52, deposit
    /// 32 of 32 either way, the clips' training 650 -> 316 s, 1,266 -> 251 s
    /// and 455 -> 226 s; switched on whenever skating failed, with other
    /// criteria too, it cost a deposit and two jog variants; on for every
    /// clip, it had traded skating rejections for soles ones (squat, session
    /// 11).
    pub skate_scale_when_skating_m_s: f32,
    pub checkpoint_every_s: f64,
    pub seed: u64,
    /// Start a fresh run from the policy, value and normaliser of another job's
    /// checkpoints (a directory of checkpoints, whose latest is used), e.g. the
    /// source clip's correction for a synthesised variant of it. Ignored when
    /// resuming this job's own checkpoint.
    pub warm_start: Option<PathBuf>,
    /// Set from another thread to stop training (cancellation, shutdown): the
    /// job saves a checkpoint and returns [`CorrectError::Stopped`] at the end of
    /// the current PPO iteration.
    pub stop: Option<Arc<AtomicBool>>,
}

impl Default for CorrectConfig {
    fn default() -> Self {
        let ppo = PpoConfig {
            policy: ppo::PolicyConfig {
                hidden: vec![256, 256],
                ..ppo::PolicyConfig::default()
            },
            value: ppo::ValueConfig {
                hidden: vec![256, 256],
            },
            policy_lr: 1e-4,
            value_lr: 1e-3,
            samples_per_iteration: 4096,
            minibatch_size: 512,
            epochs: 5,
            ..PpoConfig::default()
        };
        CorrectConfig {
            physics: physics::Config::default(),
            ppo,
            envs: 8,
            time_budget_s: 600.0,
            max_iterations: None,
            max_samples: None,
            eval_every: 1,
            target_r_norm: Some(0.8),
            acceptance: AcceptanceConfig::default(),
            residual_schedule: ResidualSchedule::default(),
            tracker_final_residual_scale: None,
            skate_scale_when_skating_m_s: 0.1,
            checkpoint_every_s: 120.0,
            seed: 0,
            warm_start: None,
            stop: None,
        }
    }
}

impl CorrectConfig {
    /// The trainer's limits: this budget, checkpoints into `checkpoints`.
    pub(crate) fn run_limits(&self, checkpoints: &Path) -> RunLimits {
        RunLimits {
            time_budget_s: Some(self.time_budget_s),
            max_iterations: self.max_iterations,
            max_samples: self.max_samples,
            checkpoint_dir: Some(checkpoints.to_path_buf()),
            checkpoint_every_s: self.checkpoint_every_s,
            keep_checkpoints: 2,
        }
    }

    /// Whether another thread asked training to stop ([`CorrectConfig::stop`]).
    pub(crate) fn stop_requested(&self) -> bool {
        self.stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
    }

    pub fn validate(&self) -> Result<(), CorrectError> {
        let bad = |m: String| Err(CorrectError::Config(m));
        if self.envs == 0 {
            return bad("envs must be at least 1".into());
        }
        if !(self.time_budget_s.is_finite() && self.time_budget_s >= 0.0) {
            return bad(format!(
                "time budget {} s is not a duration",
                self.time_budget_s
            ));
        }
        if self.eval_every == 0 {
            return bad("eval_every must be at least 1".into());
        }
        self.acceptance.validate()?;
        for skate in [
            self.physics.skate_scale_m_s,
            self.skate_scale_when_skating_m_s,
        ] {
            if !(skate.is_finite() && skate >= 0.0) {
                return bad(format!("skate scale {skate} m/s is not >= 0"));
            }
        }
        let w = self.physics.sole_reward_weight;
        if !(w.is_finite() && (0.0..=0.9).contains(&w)) {
            return bad(format!("sole reward weight {w} is not in [0, 0.9]"));
        }
        let p = self.physics.fall_penalty;
        if !(p.is_finite() && p >= 0.0) {
            return bad(format!("fall penalty {p} is not a number >= 0"));
        }
        self.residual_schedule.validate()?;
        if let Some(s) = self.tracker_final_residual_scale
            && !(s.is_finite() && s > 0.0 && s <= 1.0)
        {
            return bad(format!("tracker final residual scale {s} is not in (0, 1]"));
        }
        self.ppo.validate()?;
        self.physics.substeps()?;
        Ok(())
    }
}

/// The PD-residual gains over training: from MotionAug's (scale 1) down to
/// `final_scale` of them, linearly over `over_iterations` PPO iterations, so
/// the policy learns the balance the root force gave. The rollouts that judge
/// the clip run at the scale reached (`report.json`: `residual_scale`).
/// `final_scale` 1 keeps MotionAug's gains throughout. A policy warm-started
/// from a class tracker ([`crate::class`]) already learnt the balance at the
/// tracker's final scale: its schedule starts there (`start_scale`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualSchedule {
    pub start_scale: f32,
    pub final_scale: f32,
    pub over_iterations: u64,
}

/// Down to 0.3 of the gains over 40 iterations. Measured with `motionaug
/// bench correction --per-class 1 --max-iterations 60` on HDM05 bd kick 001,
/// jog 001 and squat 001 (feet in the standing foot's frame): residual force
/// 0.108 / 0.097 / 0.058 m g without the schedule, 0.044 / 0.075 / 0.024 with
/// it, R_norm 0.909 / 0.927 / 0.962 -> 0.889 / 0.893 / 0.951, foot skating
/// 0.065 / 0.167 / 0.029 -> 0.073 / 0.066 / 0.044 m/s.
impl Default for ResidualSchedule {
    fn default() -> Self {
        ResidualSchedule {
            start_scale: 1.0,
            final_scale: 0.3,
            over_iterations: 40,
        }
    }
}

impl ResidualSchedule {
    /// The gain scale after `iterations` PPO iterations.
    pub fn scale(&self, iterations: u64) -> f32 {
        let t = (iterations as f32 / self.over_iterations.max(1) as f32).min(1.0);
        self.start_scale - (self.start_scale - self.final_scale) * t
    }

    /// Training environments run at the scale of the iteration to come.
    pub(crate) fn apply(&self, trainer: &mut Trainer<ImitationTask>) {
        let scale = self.scale(trainer.progress().iterations);
        for task in trainer.envs_mut() {
            task.set_residual_scale(scale);
        }
    }

    /// The rollouts that judge the policy run at the scale it was last
    /// trained at.
    pub(crate) fn judged(&self, trainer: &Trainer<ImitationTask>) -> f32 {
        self.scale(trainer.progress().iterations.saturating_sub(1))
    }

    fn validate(&self) -> Result<(), CorrectError> {
        let unit = |x: f32| x.is_finite() && (0.0..=1.0).contains(&x);
        if !unit(self.start_scale) || !unit(self.final_scale) || self.over_iterations == 0 {
            return Err(CorrectError::Config(format!(
                "residual schedule: scales {} -> {} must be in [0, 1] over at least one iteration",
                self.start_scale, self.final_scale
            )));
        }
        Ok(())
    }
}

/// Progress of a running job, for terminals and the service.
#[derive(Debug, Clone)]
pub struct ProgressEvent {
    pub iteration: u64,
    pub samples: u64,
    pub wall_s: f64,
    pub budget_s: f64,
    pub mean_reward: f64,
    /// R_norm of the latest deterministic rollout, when one ran this iteration.
    pub r_norm: Option<f64>,
}

/// The result of a job: the corrected clip and its report.
pub struct Outcome {
    pub motion: Motion,
    pub report: Report,
}

/// Correct `motion` (named `source` in the report), writing into `out_dir`:
/// `corrected.bvh`, `corrected.npz`, `report.json`, `curve.svg` and
/// `checkpoints/`. With `resume`, training continues from the latest checkpoint
/// in `out_dir/checkpoints` (and starts fresh when there is none).
pub fn correct(
    motion: &Motion,
    source: &str,
    config: &CorrectConfig,
    out_dir: &Path,
    resume: bool,
    mut on_progress: impl FnMut(&ProgressEvent),
) -> Result<Outcome, CorrectError> {
    config.validate()?;
    let span = tracing::info_span!("correct", source, residual = ?config.physics.residual);
    let _guard = span.enter();
    let (checkpoints, has_checkpoint) = prepare_dir(out_dir, resume)?;

    let mut eval_env = ImitationEnv::new(motion, &config.physics)?;
    let before = motion::metrics::plausibility(motion);
    let soles_before = crate::acceptance::input_soles(motion, &config.physics, &config.acceptance)?
        .flat_fraction();
    let action0 = deterministic_rollout(&mut eval_env, |_, a| {
        a.fill(0.0);
        Ok(())
    })?;
    let (mut trainer, warm_from) = trainer_for(motion, config, &checkpoints, has_checkpoint)?;
    let (reason, at_target) = train(
        &mut trainer,
        &mut eval_env,
        &before,
        config,
        &checkpoints,
        &mut on_progress,
    )?;

    // Stopped at the target: the rollout that met it is the final one (the
    // policy has not changed since); else roll the final policy out.
    let reached_target = at_target.is_some();
    let final_rollout = match at_target {
        Some(rollout) => rollout,
        None => {
            eval_env.set_residual_scale(config.residual_schedule.judged(&trainer));
            evaluate(&trainer, &mut eval_env)?
        }
    };
    let stop_reason = match reason {
        StopReason::Callback if reached_target => "target",
        StopReason::Callback => "stopped",
        StopReason::TimeBudget => "time_budget",
        StopReason::MaxIterations => "max_iterations",
        StopReason::MaxSamples => "max_samples",
    };
    let report = report(
        source,
        config,
        &trainer,
        &final_rollout,
        &action0,
        before,
        Finish {
            stop_reason,
            warm_from,
            residual_scale: eval_env.residual_scale(),
            soles_before,
        },
    );
    write_outputs(out_dir, &final_rollout, &report)?;
    Ok(Outcome {
        motion: final_rollout.motion,
        report,
    })
}

/// Creates `out_dir`; its checkpoints folder and whether it holds a
/// checkpoint, which only `resume` may continue.
pub(crate) fn prepare_dir(out_dir: &Path, resume: bool) -> Result<(PathBuf, bool), CorrectError> {
    std::fs::create_dir_all(out_dir).map_err(|source| CorrectError::Io {
        path: out_dir.to_path_buf(),
        source,
    })?;
    let checkpoints = out_dir.join("checkpoints");
    let has_checkpoint = ppo::latest_checkpoint(&checkpoints)?.is_some();
    if has_checkpoint && !resume {
        return Err(CorrectError::Config(format!(
            "{} already holds checkpoints of an earlier run: pass --resume to continue it, \
             or choose another output directory",
            checkpoints.display()
        )));
    }
    Ok((checkpoints, has_checkpoint))
}

/// The trainer over `config.envs` environments: resumed from this job's
/// checkpoint, else fresh (warm-started from `config.warm_start`, whose
/// checkpoint it names).
fn trainer_for(
    motion: &Motion,
    config: &CorrectConfig,
    checkpoints: &Path,
    has_checkpoint: bool,
) -> Result<(Trainer<ImitationTask>, Option<String>), CorrectError> {
    let envs = (0..config.envs)
        .map(|_| ImitationEnv::new(motion, &config.physics).map(ImitationTask::new))
        .collect::<Result<Vec<_>, _>>()?;
    if has_checkpoint {
        let (trainer, _) =
            Trainer::new_or_resume(config.ppo.clone(), envs, config.seed, checkpoints)?;
        tracing::info!(iterations = trainer.progress().iterations, "resumed");
        return Ok((trainer, None));
    }
    let mut trainer = Trainer::new(config.ppo.clone(), envs, config.seed)?;
    let warm_from = match &config.warm_start {
        Some(from) => Some(trainer.warm_start(from)?.display().to_string()),
        None => None,
    };
    Ok((trainer, warm_from))
}

/// PPO within the limits, a deterministic rollout every `eval_every`
/// iterations (stopping once it meets the R_norm target and every
/// acceptance criterion), the residual schedule applied between iterations.
/// Returns why training stopped and, when the target was met, the rollout
/// that met it.
fn train(
    trainer: &mut Trainer<ImitationTask>,
    eval_env: &mut ImitationEnv,
    before: &motion::metrics::Plausibility,
    config: &CorrectConfig,
    checkpoints: &Path,
    on_progress: &mut impl FnMut(&ProgressEvent),
) -> Result<(StopReason, Option<Rollout>), CorrectError> {
    let schedule = config.residual_schedule;
    schedule.apply(trainer);
    SlidingTerm::resume(trainer);
    let limits = config.run_limits(checkpoints);
    let mut eval_error = None;
    let mut at_target = None;
    let stop_requested = || config.stop_requested();
    if stop_requested() {
        return Err(CorrectError::Stopped);
    }
    // A warm-started policy (a class tracker, the source clip's) may already
    // do the clip: judge it before any training.
    if trainer.progress().iterations == 0 && config.warm_start.is_some() {
        eval_env.set_residual_scale(schedule.scale(0));
        let rollout = evaluate(trainer, eval_env)?;
        let criteria = criteria(&rollout, before, &config.acceptance);
        if config.target_r_norm.is_some_and(|t| rollout.r_norm() >= t) && all_passed(&criteria) {
            tracing::info!(r_norm = rollout.r_norm(), "accepted as warm-started");
            return Ok((StopReason::Callback, Some(rollout)));
        }
        SlidingTerm::decide(trainer, config, &criteria);
    }
    let started = Instant::now();
    let reason = trainer.run(&limits, |trainer, it| {
        let mut r_norm = None;
        if it.iteration % config.eval_every == 0 {
            eval_env.set_residual_scale(schedule.judged(trainer));
            match evaluate(trainer, eval_env) {
                Ok(rollout) => {
                    let r = rollout.r_norm();
                    trainer.record_eval(r);
                    r_norm = Some(r);
                    // Judging costs a forward-kinematics pass over the clip:
                    // only when the R_norm target is met.
                    if config.target_r_norm.is_some_and(|t| r >= t) {
                        let criteria = criteria(&rollout, before, &config.acceptance);
                        if all_passed(&criteria) {
                            at_target = Some(rollout);
                        } else {
                            SlidingTerm::decide(trainer, config, &criteria);
                        }
                    }
                }
                Err(err) => eval_error = Some(err),
            }
        }
        schedule.apply(trainer);
        on_progress(&ProgressEvent {
            iteration: it.iteration,
            samples: it.samples,
            wall_s: it.wall_s,
            budget_s: config.time_budget_s,
            mean_reward: it.mean_reward,
            r_norm,
        });
        if eval_error.is_some() || at_target.is_some() || stop_requested() {
            Control::Stop
        } else {
            Control::Continue
        }
    })?;
    if let Some(err) = eval_error {
        return Err(err);
    }
    if stop_requested() && at_target.is_none() {
        tracing::info!("stopped on request; checkpoint saved");
        return Err(CorrectError::Stopped);
    }
    tracing::info!(
        ?reason,
        session_s = started.elapsed().as_secs_f64(),
        "training stopped"
    );
    Ok((reason, at_target))
}

/// How training ended, for the report.
struct Finish {
    stop_reason: &'static str,
    warm_from: Option<String>,
    residual_scale: f32,
    soles_before: f64,
}

/// The report of the final rollout: its figures, every acceptance criterion,
/// the learning curve and the plausibility before and after.
fn report(
    source: &str,
    config: &CorrectConfig,
    trainer: &Trainer<ImitationTask>,
    rollout: &Rollout,
    action0: &Rollout,
    before: motion::metrics::Plausibility,
    finish: Finish,
) -> Report {
    let after = motion::metrics::plausibility(&rollout.motion);
    let criteria = judge(rollout, &before, &after, &config.acceptance);
    let progress = trainer.progress();
    // The curve starts at the untrained tracker (action 0, which the fresh
    // policy's near-zero output layer approximates), then one point per evaluation.
    let curve: Vec<[f64; 3]> = std::iter::once([0.0, 0.0, action0.r_norm()])
        .chain(
            progress
                .curve
                .iter()
                .filter_map(|p| p.eval.map(|r| [p.wall_s, p.samples as f64, r])),
        )
        .collect();
    Report {
        source: source.to_string(),
        r_norm: rollout.r_norm(),
        mean_reward: rollout.mean_reward(),
        residual_force_ratio: rollout.residual_force_ratio(),
        samples: progress.samples,
        wall_s: progress.wall_s,
        iterations: progress.iterations,
        curve,
        accepted: all_passed(&criteria),
        rejected_because: criteria
            .iter()
            .filter(|c| !c.passed)
            .map(Criterion::failure)
            .collect(),
        criteria,
        accept_threshold: config.acceptance.min_mean_reward,
        fell_at: rollout.fell_at,
        fell_body: rollout.fell_body.clone(),
        clip_steps: rollout.clip_steps,
        r_norm_action0: action0.r_norm(),
        stop_reason: finish.stop_reason.to_string(),
        residual: residual_name(config.physics.residual).to_string(),
        residual_scale: finish.residual_scale as f64,
        fps: rollout.motion.fps(),
        frames: rollout.motion.frames(),
        warm_start: finish.warm_from,
        plausibility_before: before,
        plausibility_after: after,
        soles_flat_before: Some(finish.soles_before),
        skate_scale_m_s: SlidingTerm::of(trainer)
            .unwrap_or(config.physics.skate_scale_m_s)
            .into(),
    }
}

/// Every acceptance criterion of `rollout`.
fn criteria(
    rollout: &Rollout,
    before: &motion::metrics::Plausibility,
    config: &AcceptanceConfig,
) -> Vec<Criterion> {
    let after = motion::metrics::plausibility(&rollout.motion);
    judge(rollout, before, &after, config)
}

/// The sliding term for clips that skate
/// ([`CorrectConfig::skate_scale_when_skating_m_s`]): switched on by the
/// first judgement at which skating is the one criterion failed (the
/// warm-started policy's before any training, or one during training, which
/// judges only rollouts that reach the R_norm target), then on for the rest
/// of the job; kept in the checkpoints' notes so that a resumed job (on another worker
/// too) trains with the same reward.
struct SlidingTerm;

impl SlidingTerm {
    const NOTE: &'static str = "skate_scale_m_s";

    fn decide(
        trainer: &mut Trainer<ImitationTask>,
        config: &CorrectConfig,
        criteria: &[Criterion],
    ) {
        let scale = config.skate_scale_when_skating_m_s;
        let failed: Vec<&str> = criteria
            .iter()
            .filter(|c| !c.passed)
            .map(|c| c.name.as_str())
            .collect();
        let skates = failed == [crate::acceptance::FOOT_SKATING];
        let off = config.physics.skate_scale_m_s == 0.0 && Self::of(trainer).is_none();
        if scale > 0.0 && off && skates {
            tracing::info!(
                scale,
                iteration = trainer.progress().iterations,
                "the clip skates: sliding term on"
            );
            trainer.set_note(Self::NOTE, scale.to_string());
            Self::resume(trainer);
        }
    }

    /// Switch the term on in the training environments when the run's notes
    /// say it is on.
    fn resume(trainer: &mut Trainer<ImitationTask>) {
        if let Some(scale) = Self::of(trainer) {
            for task in trainer.envs_mut() {
                task.set_skate_scale(scale);
            }
        }
    }

    /// The scale the job switched on, if it did.
    fn of(trainer: &Trainer<ImitationTask>) -> Option<f32> {
        let note = trainer.progress().notes.get(Self::NOTE)?;
        note.parse()
            .ok()
            .filter(|s: &f32| s.is_finite() && *s > 0.0)
    }
}

fn evaluate(
    trainer: &Trainer<ImitationTask>,
    env: &mut ImitationEnv,
) -> Result<Rollout, CorrectError> {
    deterministic_rollout(env, |obs, action| {
        Ok(trainer.act_deterministic(obs, action)?)
    })
}

pub fn residual_name(residual: Residual) -> &'static str {
    match residual {
        Residual::None => "none",
        Residual::Pd => "pd",
        Residual::Learned => "learned",
    }
}

fn write_outputs(out_dir: &Path, rollout: &Rollout, report: &Report) -> Result<(), CorrectError> {
    let files: [(PathBuf, Vec<u8>); 4] = [
        (
            out_dir.join("corrected.bvh"),
            motion::bvh::to_bytes(&rollout.motion),
        ),
        (
            out_dir.join("corrected.npz"),
            motion::npz::motion_to_bytes(&rollout.motion, &[]).map_err(|source| {
                CorrectError::Io {
                    path: out_dir.join("corrected.npz"),
                    source,
                }
            })?,
        ),
        (
            out_dir.join("report.json"),
            serde_json::to_vec_pretty(report).map_err(|e| CorrectError::Config(e.to_string()))?,
        ),
        (
            out_dir.join("curve.svg"),
            curve_svg(&report.curve, &format!("{}: R_norm", report.source)).into_bytes(),
        ),
    ];
    for (path, bytes) in files {
        motion::io::write_atomic(&path, &bytes)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_residual_schedule_lowers_the_gains_linearly_then_holds() {
        let s = ResidualSchedule {
            start_scale: 1.0,
            final_scale: 0.2,
            over_iterations: 4,
        };
        let scales: Vec<f32> = (0..7).map(|i| s.scale(i)).collect();
        let want = [1.0, 0.8, 0.6, 0.4, 0.2, 0.2, 0.2];
        for (got, want) in scales.iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "{scales:?}");
        }
        let off = ResidualSchedule {
            start_scale: 1.0,
            final_scale: 1.0,
            over_iterations: 1,
        };
        assert_eq!(off.scale(1000), 1.0);
        // A tracker's clips hold the scale it was trained at.
        let held = ResidualSchedule {
            start_scale: 0.3,
            final_scale: 0.3,
            over_iterations: 40,
        };
        assert!((0..50).all(|i| (held.scale(i) - 0.3).abs() < 1e-6));
        let bad = ResidualSchedule {
            start_scale: 1.0,
            final_scale: 1.5,
            over_iterations: 4,
        };
        assert!(bad.validate().is_err());
        let bad_start = ResidualSchedule {
            start_scale: -0.1,
            ..s
        };
        assert!(bad_start.validate().is_err());
    }
}
