//! The viewer: a page that plays clips in 3D and draws corrections' curves,
//! served by `motionaug view` for folders on disk and by the coordinator for
//! a tenant's datasets and augmentations.
//!
//! This crate holds what both servers share and knows nothing of HTTP:
//! * [`assets`]: the page itself (three.js + uPlot, bundled at build time
//!   from `web/` by `build.rs` and embedded in the binary);
//! * [`clip`]: a clip as the page plays it: world positions of joints and end
//!   sites as little-endian float32, paged by frame, and one byte of flags per
//!   frame and point (occluded, in contact, skating), with the IK keyframe;
//! * [`library`]: the clips of folders and files on disk (an `augment` output
//!   folder with its `manifest.json` and `work/` corrections, or any folder of
//!   BVH / AMC / NPZ files), each with its related versions (source,
//!   synthesised, corrected, debiased).

pub mod assets;
pub mod clip;
pub mod library;

pub use clip::{ClipView, Ik, Meta};
pub use library::{Library, LibraryClip, Role};

/// What can go wrong reading clips for the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error("{path}: {message}")]
    Bad { path: String, message: String },
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("frames {start}..{end} are outside the clip's {frames} frames")]
    Range {
        start: usize,
        end: usize,
        frames: usize,
    },
}
