//! `motionaug bench physics --clip FILE [--json]`: simulation speed and
//! action-0 tracking error on one clip, single thread.
//!
//! `motionaug bench correction --data DIR --classes a,b --per-class N --out DIR`:
//! corrects N clips of each class (spread over the class) and writes the
//! per-class table of acceptance, plausibility and wall time
//! (`correct::summary`); finished clips are reused on a rerun. With
//! `--variants CLIP...` (one class) the class's new clips, e.g. what
//! `motionaug augment` wrote, are corrected from the class tracker in a row of
//! their own; with `--variant-tracker-iterations` those the class tracker
//! does not pass as is start from a second tracker trained on them.
//!
//! `motionaug bench soles --data DIR [--classes a,b]`: the soles criterion of
//! acceptance applied to the captured clips themselves, per class: what the
//! input would score, so that a limit the capture cannot meet shows.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;

use crate::input::ClipArgs;
use crate::output::print_stdout;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(clap::Subcommand)]
enum What {
    /// Simulated seconds per wall second and mean joint error tracking a clip with action 0.
    Physics {
        #[arg(long)]
        clip: PathBuf,
        #[command(flatten)]
        input: ClipArgs,
        /// Seconds of stepping to time (the clip repeats).
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        #[arg(long)]
        json: bool,
        /// Keep the rest-pose foot boxes instead of building them in the standing
        /// foot's frame (an ablation).
        #[arg(long)]
        rest_feet: bool,
    },
    /// Correct clips of each class and tabulate acceptance, plausibility and wall time.
    Correction(CorrectionArgs),
    /// The soles criterion (planted feet on their soles) scored on the
    /// captured clips themselves, per class.
    Soles {
        /// Folder of HDM05 clips (`HDM_<actor>_<class>_<nnn>_120.amc` + `HDM_<actor>.asf`).
        #[arg(long)]
        data: PathBuf,
        /// Classes (parts of class names); every class in the folder when absent.
        #[arg(long, value_delimiter = ',')]
        classes: Vec<String>,
        #[arg(long)]
        json: bool,
    },
    /// Training cost of a prediction model (DMGNN, V-DMGNN-GAN): seconds per
    /// iteration and windows per second of the real training loop.
    Predictor(PredictorArgs),
    /// VAE training curve and wall time per class and loss variant, and the
    /// skating, penetration and MMD of its near samples.
    Vae(super::bench_vae::Args),
}

#[derive(clap::Args)]
struct PredictorArgs {
    /// dmgnn or vdmgnn.
    #[arg(long, default_value = "dmgnn")]
    model: eval::predict::protocol::ModelKind,
    /// ASF or BVH skeleton whose non-root joints are the graph's nodes.
    #[arg(long, default_value = "examples/data/HDM_bd.asf")]
    skeleton: PathBuf,
    /// Observed frames (CMU protocol: 50; HDM05 protocol: 10).
    #[arg(long, default_value_t = 50)]
    frames: usize,
    /// Predicted frames.
    #[arg(long, default_value_t = 10)]
    predict: usize,
    #[arg(long, default_value_t = 32)]
    batch: usize,
    #[arg(long, default_value_t = 5)]
    iterations: usize,
    #[arg(long, default_value = "lower")]
    mask: eval::predict::occlusion::MaskKind,
    /// V-DMGNN-GAN: encode velocities and accelerations too.
    #[arg(long)]
    vel_acc: bool,
    #[arg(long)]
    json: bool,
}

fn bench_predictor(args: PredictorArgs) -> anyhow::Result<()> {
    let skeleton = motion::io::load(&args.skeleton, &motion::io::LoadOptions::default())
        .with_context(|| format!("cannot read the skeleton {}", args.skeleton.display()))?;
    let graph = eval::predict::body_graph::BodyGraph::non_root(skeleton.skeleton())?;
    let options = eval::predict::protocol::GraphOptions {
        vel_acc: args.vel_acc,
        ..Default::default()
    };
    let r = eval::predict::bench::bench_predictor(
        args.model,
        &eval::predict::protocol::ModelSizes::default(),
        &options,
        &graph,
        args.frames,
        args.predict,
        args.batch,
        args.iterations,
        args.mask,
    )?;
    let text = if args.json {
        serde_json::to_string_pretty(&r)? + "\n"
    } else {
        format!(
            "{}: {:.3} s per iteration ({:.1} windows/s) over {} iterations of batch {} \
             ({} observed + {} predicted frames, {} nodes, {} parameters, {} matmul threads)\n",
            r.model,
            r.seconds_per_iteration,
            r.windows_per_second,
            r.iterations,
            r.batch_size,
            r.input_frames,
            r.output_frames,
            r.nodes,
            r.parameters,
            r.threads
        )
    };
    print_stdout(&text)
}

#[derive(clap::Args)]
struct CorrectionArgs {
    /// Folder of HDM05 clips (`HDM_<actor>_<class>_<nnn>_120.amc` + `HDM_<actor>.asf`).
    #[arg(long)]
    data: PathBuf,
    /// Classes (parts of class names).
    #[arg(long, value_delimiter = ',', required = true)]
    classes: Vec<String>,
    /// Clips per class, spread evenly over the class's sorted clips.
    #[arg(long, default_value_t = 3)]
    per_class: usize,
    /// Training wall-time budget per clip, seconds.
    #[arg(long, default_value_t = 300.0)]
    time_budget: f64,
    /// PPO iterations per clip at most (a machine-independent budget).
    #[arg(long)]
    max_iterations: Option<u64>,
    /// PPO iterations at most of the originals' corrections, when they
    /// should differ from `--max-iterations` (`[correct]
    /// original_max_iterations`).
    #[arg(long)]
    original_max_iterations: Option<u64>,
    /// Rollout threads per clip.
    #[arg(long, default_value_t = correct::CorrectConfig::default().ppo.threads)]
    threads: usize,
    /// Keep the rest-pose foot boxes (an ablation).
    #[arg(long)]
    rest_feet: bool,
    /// PD-residual gains lowered to this fraction over `--residual-anneal-iterations`.
    #[arg(long, default_value_t = correct::CorrectConfig::default().residual_schedule.final_scale)]
    residual_final_scale: f32,
    #[arg(long, default_value_t = correct::CorrectConfig::default().residual_schedule.over_iterations)]
    residual_anneal_iterations: u64,
    /// Weight of the sole reward (0 = MotionAug's reward).
    #[arg(long, default_value_t = correct::CorrectConfig::default().physics.sole_reward_weight)]
    sole_reward_weight: f32,
    /// Speed scale of the sole reward's sliding term, m/s (0 = off).
    #[arg(long, default_value_t = correct::CorrectConfig::default().physics.skate_scale_m_s)]
    skate_scale: f32,
    /// Switch the sliding term on at this speed scale, m/s, only for a clip
    /// that skates: from the first judgement at which skating is the one
    /// criterion failed (the warm-started policy as is, or a rollout at the
    /// R_norm target) to the end of its training (0 = never).
    #[arg(long, default_value_t = correct::CorrectConfig::default().skate_scale_when_skating_m_s)]
    skate_scale_when_skating: f32,
    /// Imitate each clip's root re-integrated from its planted feet
    /// (`physics::Config::plant_reference`) instead of as captured.
    #[arg(long)]
    plant_reference: bool,
    /// Train one tracker policy per class on this many of its clips (spread
    /// over the class) first, and start every clip's correction from it
    /// (`correct::class`); 0 = one policy per clip from scratch.
    #[arg(long, default_value_t = 0)]
    tracker_clips: usize,
    /// Wall-time budget of each class tracker, seconds.
    #[arg(long, default_value_t = 1800.0)]
    tracker_budget: f64,
    /// PPO iterations of each class tracker at most.
    #[arg(long)]
    tracker_iterations: Option<u64>,
    /// Upcoming reference frames the tracker sees.
    #[arg(long, default_value_t = correct::ClassConfig::default().correct.physics.tracker_frames)]
    tracker_frames: usize,
    /// Correct only clips the tracker was not trained on.
    #[arg(long)]
    held_out: bool,
    /// New clips of the (one) class, e.g. the IK edits and VAE samples
    /// `motionaug augment` wrote (NPZ or BVH): corrected from the class
    /// tracker like its originals, in a row of their own.
    #[arg(long, num_args = 1.., value_name = "CLIP")]
    variants: Vec<PathBuf>,
    /// Variants the class tracker does not pass as is start from a second
    /// tracker instead: the class tracker trained further on those variants
    /// for at most this many PPO iterations (at its residual gains, within
    /// `--tracker-budget`); 0 = every variant starts from the class tracker.
    #[arg(long, default_value_t = 0)]
    variant_tracker_iterations: u64,
    /// Clips corrected side by side (each on --threads rollout threads, so
    /// `--clips-at-once 2 --threads 1` on two cores); every row also gives
    /// its elapsed time per clip.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    clips_at_once: u16,
    /// Output folder: one correction folder per clip, table.md, table.json.
    #[arg(long)]
    out: PathBuf,
}

/// The per-clip settings the arguments give.
fn base_config(args: &CorrectionArgs) -> correct::CorrectConfig {
    let mut config = correct::CorrectConfig {
        time_budget_s: args.time_budget,
        max_iterations: args.max_iterations,
        ..correct::CorrectConfig::default()
    };
    config.ppo.threads = args.threads;
    config.physics.character.calibrate_feet = !args.rest_feet;
    config.physics.sole_reward_weight = args.sole_reward_weight;
    config.physics.skate_scale_m_s = args.skate_scale;
    config.skate_scale_when_skating_m_s = args.skate_scale_when_skating;
    config.physics.plant_reference = args.plant_reference;
    config.residual_schedule = correct::ResidualSchedule {
        start_scale: 1.0,
        final_scale: args.residual_final_scale,
        over_iterations: args.residual_anneal_iterations,
    };
    config
}

/// Trains (or reuses) the class tracker on `clips` in `dir`.
fn train_tracker(
    class: &str,
    clips: &[eval::dataset::ClipFile],
    data: &Path,
    dir: &Path,
    args: &CorrectionArgs,
) -> anyhow::Result<correct::ClassReport> {
    let done = dir.join(correct::class::REPORT_FILE);
    if done.is_file() {
        return Ok(correct::ClassReport::read(&done)?);
    }
    let motions = clips
        .iter()
        .map(|c| {
            Ok((
                c.name.clone(),
                load_hdm05(&c.path, &data.join(format!("HDM_{}.asf", c.actor)))?,
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut config = correct::ClassConfig {
        correct: correct::CorrectConfig {
            time_budget_s: args.tracker_budget,
            max_iterations: args.tracker_iterations,
            ..base_config(args)
        },
        ..correct::ClassConfig::default()
    };
    config.correct.physics.tracker_frames = args.tracker_frames;
    let resume = dir.join("checkpoints").is_dir();
    let n = motions.len();
    let report = correct::train_class(&motions, &config, dir, resume, |p| {
        if let Some(a) = p.accepted {
            let fails: Vec<String> = p.failures.iter().map(|(f, k)| format!("{f} {k}")).collect();
            eprintln!(
                "{class} tracker: iteration {}, {:.0} s, {a}/{n} clips accepted as is (failed: {})",
                p.iteration,
                p.wall_s,
                fails.join(", ")
            );
        }
    })?;
    Ok(report)
}

fn load_hdm05(path: &Path, asf: &Path) -> anyhow::Result<motion::Motion> {
    Ok(motion::io::load(
        path,
        &motion::io::LoadOptions {
            skeleton: Some(asf.to_path_buf()),
            ..Default::default()
        },
    )?)
}

/// Corrects (or reuses) one clip into `dir` for at most `max_iterations`,
/// from the class tracker when there is one.
fn correct_one(
    load: impl FnOnce() -> anyhow::Result<motion::Motion>,
    name: &str,
    dir: &Path,
    args: &CorrectionArgs,
    max_iterations: Option<u64>,
    tracker: Option<&Tracker>,
) -> anyhow::Result<correct::Report> {
    let done = dir.join("report.json");
    if done.is_file() {
        return Ok(correct::Report::read(&done)?);
    }
    let motion = load()?;
    let base = correct::CorrectConfig {
        max_iterations,
        ..base_config(args)
    };
    let config = match tracker {
        Some((report, class_dir)) => report.warm_config(&base, class_dir),
        None => base,
    };
    let resume = dir.join("checkpoints").is_dir();
    Ok(correct::correct(&motion, name, &config, dir, resume, |_| {})?.report)
}

/// Loads a clip when its correction has not been done yet.
type Loader<'a> = Box<dyn FnOnce() -> anyhow::Result<motion::Motion> + Send + 'a>;

/// A class tracker's report and folder.
type Tracker = (correct::ClassReport, PathBuf);

/// Corrects `clips` (label, loader, the tracker it starts from) into
/// `out/<label>` for at most `max_iterations` each, `--clips-at-once` at a
/// time, printing one line each as it finishes; the reports in order and the
/// elapsed seconds.
fn correct_all(
    row: &str,
    clips: Vec<(String, Loader<'_>, Option<&Tracker>)>,
    out: &Path,
    args: &CorrectionArgs,
    max_iterations: Option<u64>,
) -> anyhow::Result<(Vec<correct::Report>, f64)> {
    let n = clips.len();
    let started = Instant::now();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let one = |(name, load, tracker): (String, Loader<'_>, Option<&Tracker>)| {
        let t = Instant::now();
        let r = correct_one(load, &name, &out.join(&name), args, max_iterations, tracker)?;
        let i = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        eprintln!(
            "{row} {i}/{n} {name}: {} (R_norm {:.3}, residual {:.3} m g, {:.0} s){}",
            if r.accepted { "accepted" } else { "rejected" },
            r.r_norm,
            r.residual_force_ratio,
            t.elapsed().as_secs_f64(),
            if r.rejected_because.is_empty() {
                String::new()
            } else {
                format!("\n    {}", r.rejected_because.join("\n    "))
            }
        );
        Ok(r)
    };
    let at_once = usize::from(args.clips_at_once);
    let reports: anyhow::Result<Vec<correct::Report>> =
        nn::threads::side_by_side(clips, at_once, "correct", one)?
            .into_iter()
            .collect();
    let elapsed = started.elapsed().as_secs_f64();
    if n > 0 {
        eprintln!(
            "{row}: {n} clips in {elapsed:.0} s, {:.1} s per clip ({} at once)",
            elapsed / n as f64,
            args.clips_at_once
        );
    }
    Ok((reports?, elapsed))
}

fn bench_correction(args: CorrectionArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    if !args.variants.is_empty() && args.classes.len() != 1 {
        anyhow::bail!("--variants are the new clips of one class: give exactly one --classes");
    }
    if args.variant_tracker_iterations > 0 && (args.variants.is_empty() || args.tracker_clips == 0)
    {
        anyhow::bail!(
            "--variant-tracker-iterations needs --variants and a class tracker (--tracker-clips)"
        );
    }
    let started = Instant::now();
    let mut rows = Vec::new();
    for class in &args.classes {
        let clips = eval::dataset::find_clips(&args.data, class)?;
        let tracker = if args.tracker_clips > 0 {
            let on = eval::table::physics::spread(&clips, args.tracker_clips);
            let dir = args.out.join(format!("{class}_tracker"));
            let report = train_tracker(class, &on, &args.data, &dir, &args)?;
            eprintln!(
                "{class} tracker: {}/{} clips accepted as is after {} iterations, {:.0} s",
                report.accepted(),
                report.clips,
                report.iterations,
                report.wall_s
            );
            Some((report, dir, on))
        } else {
            None
        };
        let candidates: Vec<_> = match (&tracker, args.held_out) {
            (Some((_, _, on)), true) => clips
                .iter()
                .filter(|c| !on.iter().any(|t| t.name == c.name))
                .cloned()
                .collect(),
            _ => clips.clone(),
        };
        let chosen = eval::table::physics::spread(&candidates, args.per_class);
        let tracker = tracker.map(|(r, d, _)| (r, d));
        let originals = chosen
            .iter()
            .map(|clip| {
                let asf = args.data.join(format!("HDM_{}.asf", clip.actor));
                let load: Loader = Box::new(move || load_hdm05(&clip.path, &asf));
                (clip.name.clone(), load, tracker.as_ref())
            })
            .collect();
        let iterations = args.original_max_iterations.or(args.max_iterations);
        let (reports, elapsed) = correct_all(class, originals, &args.out, &args, iterations)?;
        // `--per-class 0` trains the tracker only: no row of nothing.
        if !reports.is_empty() {
            rows.push(correct::summary::ClassSummary::of(class, &reports).elapsed(elapsed));
        }
        if !args.variants.is_empty() {
            let variants = args
                .variants
                .iter()
                .map(|path| {
                    let motion = motion::io::load(path, &motion::io::LoadOptions::default())
                        .with_context(|| format!("cannot load variant {}", path.display()))?;
                    Ok((crate::input::clip_name(path), motion))
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            // Each variant starts from the class tracker, or, when a second
            // tracker is asked for and the class tracker does not pass it as
            // is, from the second tracker, trained on those variants only.
            let second = match &tracker {
                Some((_, class_dir)) if args.variant_tracker_iterations > 0 => {
                    let dir = args.out.join(format!("{class}_variant_tracker"));
                    let base = correct::CorrectConfig {
                        time_budget_s: args.tracker_budget,
                        ..base_config(&args)
                    };
                    let label = format!("{class} variant tracker");
                    let v = pipeline::stages::train_variant_tracker(
                        &base,
                        class_dir,
                        &variants,
                        args.variant_tracker_iterations,
                        &dir,
                        &|p| {
                            if p.iteration % 10 == 0 {
                                eprintln!("{label}: iteration {}, {:.0} s", p.iteration, p.wall_s);
                            }
                        },
                    )?;
                    eprintln!(
                        "{class} variants: {}/{} accepted as is by the class tracker",
                        v.judged.accepted(),
                        variants.len()
                    );
                    v.second.map(|report| {
                        eprintln!(
                            "{label}: {}/{} variants accepted as is after {} iterations, {:.0} s",
                            report.accepted(),
                            report.clips,
                            report.iterations,
                            report.wall_s
                        );
                        ((report, dir), v.judged)
                    })
                }
                _ => None,
            };
            let clips = variants
                .into_iter()
                .map(|(name, motion)| {
                    let start = match &second {
                        Some((second, judged))
                            if pipeline::stages::VariantTracker::failed_as_is(judged, &name) =>
                        {
                            Some(second)
                        }
                        _ => tracker.as_ref(),
                    };
                    let load: Loader = Box::new(move || Ok(motion));
                    (name, load, start)
                })
                .collect();
            let row = format!("{class} variants");
            let (reports, elapsed) = correct_all(
                &row,
                clips,
                &args.out.join("variants"),
                &args,
                args.max_iterations,
            )?;
            rows.push(correct::summary::ClassSummary::of(&row, &reports).elapsed(elapsed));
        }
        let md = correct::summary::to_markdown(&rows);
        crate::output::write_atomic(&args.out.join("table.md"), md.as_bytes())?;
        crate::output::write_json(&args.out.join("table.json"), &rows)?;
    }
    print_stdout(&correct::summary::to_markdown(&rows))?;
    eprintln!("{:.0} s in all", started.elapsed().as_secs_f64());
    Ok(())
}

/// One class's inputs under the soles criterion.
#[derive(serde::Serialize)]
struct SolesRow {
    class: String,
    clips: usize,
    /// Clips whose input meets the criterion's limit.
    passing: usize,
    mean_flat_fraction: f64,
    min_flat_fraction: f64,
    planted_frames: usize,
}

fn bench_soles(data: &Path, classes: &[String], json: bool) -> anyhow::Result<()> {
    let config = correct::CorrectConfig::default();
    let limit = config.acceptance.min_flat_fraction;
    let mut names: Vec<String> = if classes.is_empty() {
        let all = eval::dataset::find_clips(data, "")?;
        all.iter().map(|c| c.class.clone()).collect()
    } else {
        classes.to_vec()
    };
    names.sort();
    names.dedup();
    let mut rows = Vec::new();
    for class in &names {
        let mut fractions = Vec::new();
        let mut planted = 0;
        for clip in eval::dataset::find_clips(data, class)? {
            let motion = load_hdm05(&clip.path, &data.join(format!("HDM_{}.asf", clip.actor)))?;
            let s = correct::acceptance::input_soles(&motion, &config.physics, &config.acceptance)
                .with_context(|| clip.name.clone())?;
            planted += s.planted_frames;
            fractions.push(s.flat_fraction());
        }
        rows.push(SolesRow {
            class: class.clone(),
            clips: fractions.len(),
            passing: fractions.iter().filter(|&&f| f >= limit).count(),
            mean_flat_fraction: fractions.iter().sum::<f64>() / fractions.len() as f64,
            min_flat_fraction: fractions.iter().copied().fold(f64::INFINITY, f64::min),
            planted_frames: planted,
        });
    }
    let text = if json {
        serde_json::to_string_pretty(&rows)? + "\n"
    } else {
        let mut t = format!(
            "| class | clips | inputs flat in >= {:.0} % of planted frames | mean flat | min flat | planted foot frames |\n|---|---|---|---|---|---|\n",
            limit * 100.0
        );
        for r in &rows {
            t += &format!(
                "| {} | {} | {} | {:.2} | {:.2} | {} |\n",
                r.class,
                r.clips,
                r.passing,
                r.mean_flat_fraction,
                r.min_flat_fraction,
                r.planted_frames
            );
        }
        t
    };
    print_stdout(&text)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Correction(a) => bench_correction(a),
        What::Predictor(a) => bench_predictor(a),
        What::Vae(a) => super::bench_vae::run(a),
        What::Soles {
            data,
            classes,
            json,
        } => bench_soles(&data, &classes, json),
        What::Physics {
            clip,
            input,
            seconds,
            json,
            rest_feet,
        } => {
            let motion = input.load(&clip)?;
            let mut config = physics::Config::default();
            config.character.calibrate_feet = !rest_feet;
            let report = physics::bench::bench_physics_for(&motion, &config, seconds)?;
            let text = if json {
                serde_json::to_string_pretty(&report)? + "\n"
            } else {
                format!(
                    "{:.1} simulated s per wall s (dt {:.5} s, {} substeps x {} PGS passes, \
                     {} bodies), mean joint error {:.4} rad, {} falls\n",
                    report.sim_seconds_per_wall_second,
                    report.dt,
                    report.solver_iterations,
                    report.pgs_iterations,
                    report.bodies,
                    report.mean_joint_error_rad,
                    report.falls
                )
            };
            print_stdout(&text)
        }
    }
}
