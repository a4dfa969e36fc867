//! `motionaug inspect FILE`: what is in a clip.

use std::fmt::Write;
use std::path::PathBuf;

use serde::Serialize;

use crate::input::ClipArgs;
use crate::output::print_stdout;

#[derive(clap::Args)]
pub struct Args {
    /// A BVH, AMC (needs --skeleton) or NPZ clip (one motionaug wrote).
    file: PathBuf,
    #[command(flatten)]
    clip: ClipArgs,
    /// Print JSON: frames, fps, duration_s, joints, joint_names, rest_height_m,
    /// base_joints, translation_tracks.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Summary {
    frames: usize,
    fps: f64,
    duration_s: f64,
    joints: usize,
    joint_names: Vec<String>,
    /// Height of the rest pose, metres.
    rest_height_m: f64,
    /// Static joints the file has above the root (folded into the skeleton's
    /// base: the root is the joint that carries the travel), outermost first.
    base_joints: Vec<String>,
    /// Joints whose translation the clip animates (besides the root).
    translation_tracks: Vec<String>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let motion = args.clip.load(&args.file)?;
    let skeleton = motion.skeleton();
    let summary = Summary {
        frames: motion.frames(),
        fps: motion.fps(),
        duration_s: motion.duration_s(),
        joints: motion.joints(),
        joint_names: skeleton.joints().iter().map(|j| j.name.clone()).collect(),
        rest_height_m: skeleton.rest_height(),
        base_joints: skeleton.base().iter().map(|b| b.name.clone()).collect(),
        translation_tracks: (0..motion.joints())
            .filter(|&j| motion.track(j).is_some())
            .map(|j| skeleton.joint(j).name.clone())
            .collect(),
    };
    let mut text = String::new();
    if args.json {
        text = serde_json::to_string_pretty(&summary)? + "\n";
    } else {
        writeln!(text, "file:        {}", args.file.display())?;
        writeln!(text, "frames:      {}", summary.frames)?;
        writeln!(text, "fps:         {}", summary.fps)?;
        writeln!(text, "duration:    {:.3} s", summary.duration_s)?;
        writeln!(text, "rest height: {:.3} m", summary.rest_height_m)?;
        if !summary.base_joints.is_empty() {
            writeln!(
                text,
                "static base: {} (above the root, which carries the travel)",
                summary.base_joints.join(", ")
            )?;
        }
        writeln!(text, "joints:      {}", summary.joints)?;
        for (i, joint) in skeleton.joints().iter().enumerate() {
            let parent = joint
                .parent
                .map(|p| skeleton.joint(p).name.as_str())
                .unwrap_or("-");
            let track = if motion.track(i).is_some() {
                "  (animated translation)"
            } else {
                ""
            };
            writeln!(text, "  {i:3} {:<24} parent {parent}{track}", joint.name)?;
        }
    }
    print_stdout(&text)
}
