//! A lossless encoding of a clip between jobs that run in different processes
//! (the service's workers): the motion crate's lossless NPZ
//! (`motion::npz::exact_to_bytes`: root translation, rotations and
//! translation tracks in f64, the frame rate, the skeleton as JSON) plus the
//! occlusion mask when there is one. The output BVH and NPZ round their
//! numbers; this does not, so a clip handed from one job to the next is the
//! clip the first job made. `motionaug` and the service also read it as an
//! input clip (`motion::io`).

use std::path::Path;

use motion::Motion;

use crate::PipelineError;

fn bad(what: impl std::fmt::Display) -> PipelineError {
    PipelineError::Job(format!("encoded clip: {what}"))
}

/// Encodes `motion` (and its mask) losslessly.
pub fn encode_clip(motion: &Motion, mask: Option<&synth::Mask>) -> Result<Vec<u8>, PipelineError> {
    let mut extras = Vec::new();
    if let Some(mask) = mask {
        extras.push(
            motion::npz::NpyArray::bool("mask", &[mask.frames, mask.joints], &mask.visible)
                .map_err(bad)?,
        );
    }
    motion::npz::exact_to_bytes(motion, &extras).map_err(bad)
}

/// Decodes what [`encode_clip`] wrote.
pub fn decode_clip(bytes: &[u8]) -> Result<(Motion, Option<synth::Mask>), PipelineError> {
    let arrays = motion::npz::read(bytes).map_err(bad)?;
    let motion = motion::npz::motion_from_arrays(&arrays, Path::new("encoded clip"))?;
    let mask = match arrays.iter().find(|a| a.name == "mask") {
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
        // A static base and translation tracks come through too.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
        let s = motion::load(dir.join("static_root_walk.bvh"), &Default::default()).unwrap();
        let n = s.joints();
        let track = (0..s.frames())
            .map(|f| s.skeleton().joint(2).offset * (1.0 + f as f64 * 1e-3))
            .collect();
        let mut tracks = vec![None; n];
        tracks[2] = Some(track);
        let s = s.with_tracks(tracks).unwrap();
        let (back, _) = decode_clip(&encode_clip(&s, None).unwrap()).unwrap();
        assert_eq!(back, s);
        assert_eq!(back.skeleton().base()[0].name, "joint_Root");
    }
}
