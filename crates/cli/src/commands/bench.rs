//! `motionaug bench physics --clip FILE [--json]`: simulation speed and
//! action-0 tracking error on one clip, single thread.

use std::path::PathBuf;

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
        /// Tilt the foot boxes flat in the clip's stance frames (an ablation; off by default).
        #[arg(long)]
        calibrate_feet: bool,
    },
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Physics {
            clip,
            input,
            seconds,
            json,
            calibrate_feet,
        } => {
            let motion = input.load(&clip)?;
            let mut config = physics::Config::default();
            config.character.calibrate_feet = calibrate_feet;
            let report = physics::bench::bench_physics_for(&motion, &config, seconds)?;
            let text = if json {
                serde_json::to_string_pretty(&report)? + "\n"
            } else {
                format!(
                    "{:.1} simulated s per wall s (dt {:.5} s, {} solver iterations, {} bodies), \
                     mean joint error {:.4} rad, {} falls\n",
                    report.sim_seconds_per_wall_second,
                    report.dt,
                    report.solver_iterations,
                    report.bodies,
                    report.mean_joint_error_rad,
                    report.falls
                )
            };
            print_stdout(&text)
        }
    }
}
