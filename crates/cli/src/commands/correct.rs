//! `motionaug correct IN --out DIR [--time-budget S] [--resume] [--residual pd|none|learned]`:
//! physical correction of one clip by imitation learning in a simulator.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use correct::CorrectConfig;
use physics::Residual;

use crate::input::{ClipArgs, clip_name};

#[derive(clap::Args)]
pub struct Args {
    /// The clip to correct (BVH, AMC with --skeleton, or NPZ written by motionaug).
    input: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Output directory: corrected.bvh, corrected.npz, report.json, curve.svg, checkpoints/.
    #[arg(long)]
    out: PathBuf,
    /// Training wall-time budget in seconds (over all resumes).
    #[arg(long, default_value_t = CorrectConfig::default().time_budget_s)]
    time_budget: f64,
    /// Continue from the latest checkpoint in DIR/checkpoints.
    #[arg(long)]
    resume: bool,
    /// Root force helping the character: pd (MotionAug), none, or learned (RFC).
    #[arg(long, default_value = "pd")]
    residual: Residual,
    /// Stop early once the deterministic rollout reaches this R_norm (and
    /// passes every acceptance criterion) [default: the library's, 0.8].
    #[arg(long)]
    target_r_norm: Option<f64>,
    /// Accept only when the mean root residual force is at most this fraction
    /// of body weight (the other acceptance limits are the library's; a recipe's
    /// `[correct]` sets them all).
    #[arg(long, default_value_t = CorrectConfig::default().acceptance.max_residual_force_ratio)]
    max_residual_force_ratio: f64,
    /// Lower the PD-residual gains linearly to this fraction of MotionAug's over
    /// `--residual-anneal-iterations` PPO iterations (1 keeps them).
    #[arg(long, default_value_t = CorrectConfig::default().residual_schedule.final_scale)]
    residual_final_scale: f32,
    #[arg(long, default_value_t = CorrectConfig::default().residual_schedule.over_iterations)]
    residual_anneal_iterations: u64,
    /// With --tracker: lower the PD-residual gains from the tracker's scale to
    /// this fraction of MotionAug's over `--residual-anneal-iterations`
    /// (default: hold the tracker's scale).
    #[arg(long, requires = "tracker")]
    tracker_final_residual_scale: Option<f32>,
    /// Weight of the sole reward (feet touching the ground rewarded for heel
    /// and toe on it; 0 = MotionAug's reward).
    #[arg(long, default_value_t = CorrectConfig::default().physics.sole_reward_weight)]
    sole_reward_weight: f32,
    /// Training reward of a step that ends in a fall, negated (0 = the
    /// paper's 0; acceptance reads the paper's reward either way).
    #[arg(long, default_value_t = CorrectConfig::default().physics.fall_penalty)]
    fall_penalty: f32,
    /// Speed scale of the sole reward's sliding term, m/s (0 = off).
    #[arg(long, default_value_t = CorrectConfig::default().physics.skate_scale_m_s)]
    skate_scale: f32,
    /// Switch the sliding term on at this speed scale, m/s, only for a clip
    /// that skates: from the first judgement at which skating is the one
    /// criterion failed (the warm-started policy as is, or a rollout at the
    /// R_norm target) to the end of its training (0 = never).
    #[arg(long, default_value_t = CorrectConfig::default().skate_scale_when_skating_m_s)]
    skate_scale_when_skating: f32,
    /// Parallel simulated environments.
    #[arg(long, default_value_t = CorrectConfig::default().envs)]
    envs: usize,
    /// Rollout threads.
    #[arg(long, default_value_t = CorrectConfig::default().ppo.threads)]
    threads: usize,
    /// Stop after this many PPO iterations (for quick runs).
    #[arg(long)]
    max_iterations: Option<u64>,
    #[arg(long, default_value_t = CorrectConfig::default().seed)]
    seed: u64,
    /// Start from another correction's checkpoints (its `DIR/checkpoints`), e.g.
    /// the source clip's for a synthesised variant of it.
    #[arg(long, value_name = "CHECKPOINTS", conflicts_with = "tracker")]
    warm_start: Option<PathBuf>,
    /// Start from a class tracker: a folder with `class.json` and
    /// `checkpoints/` (`bench correction`'s `<class>_tracker`, the eval
    /// table's and the pipeline's class trackers). The correction then sees
    /// the upcoming reference frames the tracker was trained with and keeps
    /// its residual gains (`--residual-final-scale` does not apply; see
    /// `--tracker-final-residual-scale`).
    #[arg(long, value_name = "DIR")]
    tracker: Option<PathBuf>,
    /// Keep the rest-pose foot boxes instead of building them in the standing
    /// foot's frame (an ablation).
    #[arg(long)]
    rest_feet: bool,
    /// Write the corrected clip at the input's own height (the simulated floor
    /// at its median-frame foot level) instead of standing on y = 0; for data
    /// whose floor is not y = 0.
    #[arg(long)]
    keep_clip_height: bool,
    /// Imitate the root re-integrated from the planted feet instead of as
    /// captured (acceptance compares with the clip as given either way).
    #[arg(long)]
    plant_reference: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let motion = args.clip.load(&args.input)?;
    let defaults = CorrectConfig::default();
    let mut config = CorrectConfig {
        time_budget_s: args.time_budget,
        target_r_norm: args.target_r_norm.or(defaults.target_r_norm),
        envs: args.envs,
        max_iterations: args.max_iterations,
        seed: args.seed,
        ..defaults
    };
    config.acceptance.max_residual_force_ratio = args.max_residual_force_ratio;
    config.residual_schedule = correct::ResidualSchedule {
        start_scale: 1.0,
        final_scale: args.residual_final_scale,
        over_iterations: args.residual_anneal_iterations,
    };
    config.tracker_final_residual_scale = args.tracker_final_residual_scale;
    config.physics.residual = args.residual;
    config.physics.sole_reward_weight = args.sole_reward_weight;
    config.physics.fall_penalty = args.fall_penalty;
    config.physics.skate_scale_m_s = args.skate_scale;
    config.skate_scale_when_skating_m_s = args.skate_scale_when_skating;
    config.warm_start = args.warm_start.clone();
    if let Some(from) = &args.warm_start
        && let Some(class_dir) = from.parent()
        && class_dir.join(correct::class::REPORT_FILE).is_file()
    {
        anyhow::bail!(
            "{} holds a class tracker's checkpoints, whose policy sees upcoming reference \
             frames: start from it with --tracker {}",
            from.display(),
            class_dir.display()
        );
    }
    config.physics.character.calibrate_feet = !args.rest_feet;
    config.physics.plant_reference = args.plant_reference;
    if args.keep_clip_height {
        config.physics.output_frame = physics::OutputFrame::Clip;
    }
    config.ppo.threads = args.threads;
    if let Some(dir) = &args.tracker {
        let report = correct::ClassReport::read(&dir.join(correct::class::REPORT_FILE))
            .with_context(|| format!("{} is not a class tracker folder", dir.display()))?;
        config = report.warm_config(&config, dir);
    }
    let terminal = std::io::stderr().is_terminal();
    // The input beside the output, for `motionaug view DIR` to play both.
    std::fs::create_dir_all(&args.out)?;
    motion::io::save(&motion, args.out.join("input.bvh"))?;
    let outcome = correct::correct(
        &motion,
        &clip_name(&args.input),
        &config,
        &args.out,
        args.resume,
        |p| {
            let r = p
                .r_norm
                .map(|r| format!("{r:.3}"))
                .unwrap_or_else(|| "-".into());
            let line = format!(
                "iter {:4}  samples {:8}  {:6.0}/{:.0} s  mean reward {:.3}  R_norm {r}",
                p.iteration, p.samples, p.wall_s, p.budget_s, p.mean_reward
            );
            if terminal {
                eprint!("\r{line}");
            } else {
                eprintln!("{line}");
            }
        },
    )
    .with_context(|| format!("correcting {}", args.input.display()))?;
    if terminal {
        eprintln!();
    }
    let r = &outcome.report;
    eprintln!(
        "R_norm {:.3} (action 0: {:.3}), {} samples in {:.0} s: {}",
        r.r_norm,
        r.r_norm_action0,
        r.samples,
        r.wall_s,
        if r.accepted {
            "accepted"
        } else {
            "not accepted"
        }
    );
    for c in &r.criteria {
        eprintln!(
            "  {} {:<15} {:8.3} {} {:.3}  {}",
            if c.passed { "pass" } else { "FAIL" },
            c.name,
            c.value,
            c.op(),
            c.limit,
            c.meaning
        );
    }
    eprintln!("wrote {}", args.out.display());
    Ok(())
}
