//! `motionaug metrics FILE --json`: physical plausibility of a clip.

use std::path::PathBuf;

use crate::input::ClipArgs;
use crate::output::print_stdout;

#[derive(clap::Args)]
pub struct Args {
    /// A BVH, AMC (needs --skeleton) or NPZ clip (one motionaug wrote).
    file: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Print JSON (the default output is a short table).
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let motion = args.clip.load(&args.file)?;
    let metrics = motion::metrics::plausibility(&motion);
    let text = if args.json {
        serde_json::to_string_pretty(&metrics)? + "\n"
    } else {
        let value = serde_json::to_value(&metrics)?;
        let map = value.as_object().into_iter().flatten();
        map.map(|(key, v)| format!("{key:<32} {v}\n")).collect()
    };
    print_stdout(&text)
}
