//! `motionaug convert IN OUT.bvh|OUT.npz [--fps N] [--smooth-s S]`.

use std::path::PathBuf;

use anyhow::Context;

use crate::input::ClipArgs;

#[derive(clap::Args)]
pub struct Args {
    /// Input clip (BVH, AMC with --skeleton, or NPZ written by motionaug).
    input: PathBuf,
    /// Output file: `.bvh` or `.npz`.
    output: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Resample to this frame rate (slerp), e.g. 30.
    #[arg(long)]
    fps: Option<f64>,
    /// Low-pass the root path and rotations with a Gaussian of this standard
    /// deviation, seconds (after resampling), e.g. 0.05.
    #[arg(long)]
    smooth_s: Option<f64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut motion = args.clip.load(&args.input)?;
    if let Some(fps) = args.fps {
        motion = motion::resample::resample(&motion, fps)
            .with_context(|| format!("cannot resample {} to {fps} fps", args.input.display()))?;
    }
    if let Some(sigma) = args.smooth_s {
        motion = motion::smooth::gaussian(&motion, sigma)?;
    }
    motion::io::save(&motion, &args.output)?;
    eprintln!(
        "wrote {} ({} frames at {} fps, {} joints)",
        args.output.display(),
        motion.frames(),
        motion.fps(),
        motion.joints()
    );
    Ok(())
}
