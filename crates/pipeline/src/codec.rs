//! A lossless encoding of a clip between jobs that run in different processes
//! (the service's workers): an NPZ with the root translation and rotations in
//! f64, the frame rate, the skeleton as JSON (serde_json round-trips f64
//! exactly with `float_roundtrip`, which the workspace enables) and the
//! occlusion mask when there is one. The output BVH and NPZ round their
//! numbers; this does not, so a clip handed from one job to the next is the
//! clip the first job made.

use std::sync::Arc;

use motion::Motion;
use motion::skeleton::Skeleton;

use crate::PipelineError;

fn bad(what: impl std::fmt::Display) -> PipelineError {
    PipelineError::Job(format!("encoded clip: {what}"))
}

/// Encodes `motion` (and its mask) losslessly.
pub fn encode_clip(motion: &Motion, mask: Option<&synth::Mask>) -> Result<Vec<u8>, PipelineError> {
    let (t, j) = (motion.frames(), motion.joints());
    let root: Vec<f64> = motion
        .root_translation()
        .iter()
        .flat_map(|p| [p.x, p.y, p.z])
        .collect();
    let rot: Vec<f64> = motion
        .rotations()
        .iter()
        .flat_map(|q| [q.w, q.x, q.y, q.z])
        .collect();
    let skeleton = serde_json::to_vec(motion.skeleton().as_ref()).map_err(bad)?;
    let mut w = motion::npz::NpzWriter::new(std::io::Cursor::new(Vec::new()))
        .array_f64("root_translation", &[t, 3], &root)
        .and_then(|w| w.array_f64("rotations", &[t, j, 4], &rot))
        .and_then(|w| w.scalar_f64("fps", motion.fps()))
        .and_then(|w| w.array_u8("skeleton_json", &[skeleton.len()], &skeleton))
        .map_err(bad)?;
    if let Some(mask) = mask {
        w = w
            .array_bool("mask", &[mask.frames, mask.joints], &mask.visible)
            .map_err(bad)?;
    }
    Ok(w.finish().map_err(bad)?.into_inner())
}

/// Decodes what [`encode_clip`] wrote.
pub fn decode_clip(bytes: &[u8]) -> Result<(Motion, Option<synth::Mask>), PipelineError> {
    let arrays = motion::npz::read(bytes).map_err(bad)?;
    let find = |name: &str| arrays.iter().find(|a| a.name == name);
    let f64s = |name: &str| {
        find(name)
            .and_then(|a| a.to_f64())
            .ok_or_else(|| bad(format!("no float64 array `{name}`")))
    };
    let (root, rot, fps) = (f64s("root_translation")?, f64s("rotations")?, f64s("fps")?);
    let fps = *fps.first().ok_or_else(|| bad("empty fps"))?;
    let json = find("skeleton_json")
        .and_then(|a| a.to_u8())
        .ok_or_else(|| bad("no skeleton"))?;
    let skeleton: Skeleton = serde_json::from_slice(&json).map_err(bad)?;
    let skeleton = Skeleton::new(skeleton.joints().to_vec(), skeleton.source_unit_m())?;
    let root = root
        .chunks_exact(3)
        .map(|p| motion::glam::DVec3::new(p[0], p[1], p[2]))
        .collect();
    let rot: Vec<motion::glam::DQuat> = rot
        .chunks_exact(4)
        .map(|q| motion::glam::DQuat::from_xyzw(q[1], q[2], q[3], q[0]))
        .collect();
    let mut motion = Motion::new(Arc::new(skeleton), fps, root, rot.clone())?;
    // `Motion::new` renormalises the quaternions, which can move their last
    // bit; put back the exact values it validated.
    let joints = motion.joints();
    for frame in 0..motion.frames() {
        motion
            .pose_mut(frame)
            .copy_from_slice(&rot[frame * joints..(frame + 1) * joints]);
    }
    let mask = match find("mask") {
        None => None,
        Some(a) => {
            let visible: Vec<bool> = a
                .to_u8()
                .ok_or_else(|| bad("mask is not a bool array"))?
                .into_iter()
                .map(|b| b != 0)
                .collect();
            if visible.len() != motion.frames() * motion.joints() {
                return Err(bad("mask shape does not fit the clip"));
            }
            Some(synth::Mask {
                frames: motion.frames(),
                joints: motion.joints(),
                visible,
            })
        }
    };
    Ok((motion, mask))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clips_survive_encoding_exactly() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
        let bytes = std::fs::read(dir.join("16_11_walk_veer_left.bvh")).unwrap();
        let m = motion::io::parse_bvh(&bytes, "walk.bvh", motion::Unit::Auto).unwrap();
        let mask = synth::Mask {
            frames: m.frames(),
            joints: m.joints(),
            visible: (0..m.frames() * m.joints()).map(|i| i % 3 != 0).collect(),
        };
        let (back, back_mask) = decode_clip(&encode_clip(&m, Some(&mask)).unwrap()).unwrap();
        assert_eq!(back.skeleton(), m.skeleton());
        assert_eq!(back.fps(), m.fps());
        assert_eq!(back.root_translation(), m.root_translation());
        assert_eq!(back.rotations(), m.rotations());
        assert_eq!(back_mask, Some(mask));
        assert!(decode_clip(b"not an npz").is_err());
    }
}
