//! `motionaug`: the whole product in one process, no Postgres, no Redis.
//!
//! Each subcommand lives in its own module under `commands/`; this file only
//! parses arguments, sets up logging and dispatches.

mod commands;
mod input;
mod output;
mod progress;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "motionaug",
    version,
    about = "Motion-capture data augmentation"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print frames, frame rate, duration and joints of a clip.
    Inspect(commands::inspect::Args),
    /// Convert a clip to BVH or NPZ, optionally resampling it.
    Convert(commands::convert::Args),
    /// Synthesise new clips from a recipe (noise, time warp, mirror, masks, IK).
    Augment(commands::augment::Args),
    /// Physical plausibility metrics of a clip (foot skating, penetration, ...).
    Metrics(commands::metrics::Args),
    /// Two-person interactions: retarget to another body size, generate variations.
    Interaction(commands::interaction::Args),
    /// Physically correct a clip: a simulated humanoid learns to imitate it (PPO).
    Correct(commands::correct::Args),
    /// Benchmarks that print figures.
    Bench(commands::bench::Args),
    /// Train the MotionAug motion VAE on a class, or sample clips from one.
    Vae(commands::vae::Args),
    /// Learn the bias physical correction leaves in clips, and remove it.
    Debias(commands::debias::Args),
    /// Evaluate augmentations: min DTW / MMD, and motion prediction with and without them.
    Eval(Box<commands::eval::Args>),
    /// Motion prediction models: train one on clips, predict a clip's future from occluded frames.
    Predict(commands::predict::Args),
    /// Serve the viewer page for augment outputs or clips: play them in 3D, see corrections' curves.
    View(commands::view::Args),
}

fn main() -> ExitCode {
    nn::threads::init();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Inspect(args) => commands::inspect::run(args),
        Command::Convert(args) => commands::convert::run(args),
        Command::Augment(args) => commands::augment::run(args),
        Command::Metrics(args) => commands::metrics::run(args),
        Command::Interaction(args) => commands::interaction::run(args),
        Command::Correct(args) => commands::correct::run(args),
        Command::Bench(args) => commands::bench::run(args),
        Command::Vae(args) => commands::vae::run(args),
        Command::Debias(args) => commands::debias::run(args),
        Command::Eval(args) => commands::eval::run(*args),
        Command::View(args) => commands::view::run(args),
        Command::Predict(args) => commands::predict::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", message(&err));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes, `: `-separated, without repeating a cause that an
/// outer message already quotes (library errors name the file and include
/// their source; anyhow's `{:#}` would print the source a second time).
fn message(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}
