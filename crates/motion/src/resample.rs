//! Resampling a motion to another frame rate (e.g. 120 Hz mocap to the 30 Hz
//! the papers train on): rotations by slerp, the root position and
//! translation tracks linearly.
//!
//! The clip keeps its duration (`frames / fps`): the output has
//! `round(frames * new_fps / fps)` frames (at least one), frame `k` samples the
//! source at time `k / new_fps`, between the two source frames around it;
//! times past the last source frame hold the last frame.

use crate::error::MotionError;
use crate::motion::Motion;

/// `motion` resampled to `fps` frames per second.
pub fn resample(motion: &Motion, fps: f64) -> Result<Motion, MotionError> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(MotionError::InvalidMotion(format!(
            "target frame rate {fps} is not a positive number"
        )));
    }
    let source_frames = motion.frames();
    let ratio = motion.fps() / fps;
    let frames_f = (source_frames as f64 / ratio).round();
    if !(frames_f.is_finite() && frames_f <= 1e8) {
        return Err(MotionError::InvalidMotion(format!(
            "resampling {source_frames} frames at {} fps to {fps} fps gives too many frames",
            motion.fps()
        )));
    }
    let frames = (frames_f as usize).max(1);
    let joints = motion.joints();
    let mut root = Vec::with_capacity(frames);
    let mut rotations = Vec::with_capacity(frames * joints);
    let mut at = Vec::with_capacity(frames);
    for k in 0..frames {
        let s = k as f64 * ratio;
        let i = (s.floor() as usize).min(source_frames - 1);
        let next = (i + 1).min(source_frames - 1);
        let a = if next == i {
            0.0
        } else {
            (s - i as f64).clamp(0.0, 1.0)
        };
        at.push(i as f64 + a);
        root.push(motion.root_translation()[i].lerp(motion.root_translation()[next], a));
        let (p, q) = (motion.pose(i), motion.pose(next));
        rotations.extend(p.iter().zip(q).map(|(x, y)| x.slerp(*y, a)));
    }
    motion.with_frames_and_tracks(fps, root, rotations, motion.tracks_at(&at))
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{DQuat, DVec3};

    use super::*;
    use crate::rotation::angle_between;
    use crate::skeleton::{Joint, Skeleton};

    fn clip(frames: usize, fps: f64) -> Motion {
        let s = Arc::new(
            Skeleton::new(
                vec![Joint {
                    name: "root".into(),
                    parent: None,
                    offset: DVec3::ZERO,
                    channels: vec![],
                    end_site: None,
                    limits: None,
                }],
                1.0,
            )
            .unwrap(),
        );
        // Root moves 1 m/s along x, turns 1 rad/s about y.
        let root = (0..frames)
            .map(|f| DVec3::new(f as f64 / fps, 0.0, 0.0))
            .collect();
        let rot = (0..frames)
            .map(|f| DQuat::from_rotation_y(f as f64 / fps))
            .collect();
        Motion::new(s, fps, root, rot).unwrap()
    }

    #[test]
    fn keeps_duration_and_interpolates() {
        let m = clip(120, 120.0);
        let r = resample(&m, 30.0).unwrap();
        assert_eq!(r.frames(), 30);
        assert!((r.duration_s() - m.duration_s()).abs() < 1e-12);
        // Frame 7 at 30 Hz = source frame 28 exactly.
        assert!((r.root_translation()[7].x - 28.0 / 120.0).abs() < 1e-12);
        // Upsampling interpolates between frames: slerp of a uniform turn is exact.
        let up = resample(&m, 240.0).unwrap();
        assert_eq!(up.frames(), 240);
        let q = up.rotation(3, 0);
        assert!(angle_between(q, DQuat::from_rotation_y(1.5 / 120.0)) < 1e-12);
        assert!((up.root_translation()[3].x - 1.5 / 120.0).abs() < 1e-12);
        assert!(resample(&m, 0.0).is_err());
        assert_eq!(resample(&clip(1, 120.0), 30.0).unwrap().frames(), 1);
    }

    #[test]
    fn resamples_translation_tracks() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
        let walk = crate::load(dir.join("16_11_walk_veer_left.bvh"), &Default::default()).unwrap();
        // A joint that stretches 1 mm per frame.
        let j = walk.skeleton().find("LeftLeg").unwrap();
        let rest = walk.skeleton().joint(j).offset;
        let track: Vec<DVec3> = (0..walk.frames())
            .map(|f| rest + DVec3::Y * (f as f64 * 1e-3))
            .collect();
        let mut tracks = vec![None; walk.joints()];
        tracks[j] = Some(track);
        let m = walk.with_tracks(tracks).unwrap();
        let r = resample(&m, 30.0).unwrap();
        // Frame 7 at 30 Hz is source frame 28.
        assert!((r.local_translation(7, j) - (rest + DVec3::Y * 0.028)).length() < 1e-12);
        for (a, b) in r.world_positions(7).iter().zip(m.world_positions(28)) {
            assert!((*a - b).length() < 1e-12);
        }
    }
}
