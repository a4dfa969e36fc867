//! Reading clips given on the command line: the options every subcommand shares.

use std::path::{Path, PathBuf};

use motion::{Motion, Unit};

/// How to read input clips.
#[derive(clap::Args, Debug, Clone)]
pub struct ClipArgs {
    /// ASF skeleton for AMC clips (HDM05, CMU); default: the one beside each
    /// clip (`HDM_bd.asf` for `HDM_bd_*.amc`, `07.asf` for `07_01.amc`, or the
    /// folder's only .asf).
    #[arg(long, value_name = "ASF")]
    pub skeleton: Option<PathBuf>,
    /// Length unit of BVH files: m, cm, mm, in, ft, cmu, or auto (a guess from
    /// body height; see docs).
    #[arg(long, default_value = "auto")]
    pub unit: Unit,
    /// Frame rate of AMC clips, which do not store one.
    #[arg(long, value_name = "FPS", default_value_t = motion::amc::DEFAULT_FPS)]
    pub amc_fps: f64,
}

impl ClipArgs {
    pub fn load(&self, path: &Path) -> anyhow::Result<Motion> {
        let options = motion::io::LoadOptions {
            skeleton: self.skeleton.clone(),
            unit: self.unit,
            fps: Some(self.amc_fps),
        };
        // Motion errors name the file (and line) themselves.
        Ok(motion::io::load(path, &options)?)
    }
}

/// The name of a clip: its file stem (`HDM_bd_kickLFront1Reps_001_120`).
pub fn clip_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "clip".to_string())
}
