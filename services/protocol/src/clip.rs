//! Reading stored clips into motions with the motion crate's readers.
//!
//! The coordinator parses every upload with these functions before accepting it,
//! and workers parse the stored bytes again with the very same functions, so a
//! clip that was accepted is read the same way everywhere. Options match the
//! CLI's defaults: BVH units guessed from the body size (`Unit::Auto`), AMC clips
//! at 120 Hz (the motion crate's `amc::DEFAULT_FPS`), NPZ clips as the motion
//! crate reads the ones the product writes (`motion::npz::read_motion`).

use motion::asf::Asf;
use motion::{Motion, MotionError};

use crate::ClipFormat;

/// A parsed ASF skeleton, ready to read AMC motions against.
pub type LoadedSkeleton = Asf;

/// Reads a BVH file; `label` names it in errors.
pub fn load_bvh(label: &str, bytes: &[u8]) -> Result<Motion, MotionError> {
    motion::io::parse_bvh(bytes, label, motion::Unit::Auto)
}

/// Reads an NPZ clip the product wrote (lossless or float32).
pub fn load_npz(label: &str, bytes: &[u8]) -> Result<Motion, MotionError> {
    motion::npz::read_motion(bytes, label)
}

/// Reads an ASF skeleton.
pub fn load_skeleton(label: &str, bytes: &[u8]) -> Result<LoadedSkeleton, MotionError> {
    motion::io::parse_asf(bytes, label)
}

/// Reads an AMC motion against its skeleton.
pub fn load_amc(
    label: &str,
    bytes: &[u8],
    skeleton: &LoadedSkeleton,
) -> Result<Motion, MotionError> {
    motion::io::parse_amc(bytes, label, skeleton, motion::amc::DEFAULT_FPS)
}

/// Reads a stored clip: `source` is the BVH, AMC or NPZ file, `skeleton` the ASF for AMC.
pub fn load(
    format: ClipFormat,
    source_name: &str,
    source: &[u8],
    skeleton: Option<(&str, &[u8])>,
) -> Result<Motion, MotionError> {
    match format {
        ClipFormat::Bvh => load_bvh(source_name, source),
        ClipFormat::Npz => load_npz(source_name, source),
        ClipFormat::Amc => {
            let (skeleton_name, skeleton_bytes) = skeleton.ok_or_else(|| {
                MotionError::InvalidMotion(format!(
                    "{source_name}: AMC clip stored without its ASF"
                ))
            })?;
            let skeleton = load_skeleton(skeleton_name, skeleton_bytes)?;
            load_amc(source_name, source, &skeleton)
        }
    }
}
