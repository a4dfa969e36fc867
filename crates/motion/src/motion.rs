//! Motion: a skeleton animated over time.
//!
//! Per frame the world position of the root and one local rotation per joint;
//! plus, for the joints a file animates the translation of (BVH position
//! channels on a non-root joint whose values vary), a *translation track*: the
//! joint's local translation at every frame, which replaces its rest offset in
//! forward kinematics. Most clips have none. Ops that keep the frame count keep
//! the tracks ([`Motion::with_frames`]); ops that change it resample them
//! ([`Motion::tracks_at`], [`Motion::with_frames_and_tracks`]).

use std::sync::Arc;

use glam::{DQuat, DVec3};

use crate::MotionError;
use crate::skeleton::{Skeleton, Transform};

/// A clip: per frame, the world position of the root joint (metres, y up) and
/// one local rotation per joint (relative to the parent, rest pose = identity).
#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    skeleton: Arc<Skeleton>,
    fps: f64,
    root_translation: Vec<DVec3>,
    /// Row-major `[frame][joint]`.
    rotations: Vec<DQuat>,
    /// Empty, or per joint its local translation at every frame (`None`: its
    /// rest offset; always `None` for the root).
    tracks: Vec<Option<Vec<DVec3>>>,
}

/// Translation tracks: empty, or per joint `None` (rest offset) or its local
/// translation per frame, metres, in the parent's frame.
pub type Tracks = Vec<Option<Vec<DVec3>>>;

impl Motion {
    /// Validates shapes and values: a positive finite frame rate, at least one
    /// frame, one rotation per joint per frame, finite values. Rotations are
    /// normalised (files round their numbers).
    pub fn new(
        skeleton: Arc<Skeleton>,
        fps: f64,
        root_translation: Vec<DVec3>,
        mut rotations: Vec<DQuat>,
    ) -> Result<Self, MotionError> {
        let bad = |m: String| Err(MotionError::InvalidMotion(m));
        if !(fps.is_finite() && fps > 0.0) {
            return bad(format!("frame rate {fps} is not a positive number"));
        }
        let frames = root_translation.len();
        if frames == 0 {
            return bad("no frames".into());
        }
        if rotations.len() != frames * skeleton.len() {
            return bad(format!(
                "{} rotations for {} frames of {} joints",
                rotations.len(),
                frames,
                skeleton.len()
            ));
        }
        if let Some(t) = root_translation.iter().position(|p| !p.is_finite()) {
            return bad(format!("frame {t}: root position is not finite"));
        }
        for (i, q) in rotations.iter_mut().enumerate() {
            let n = q.length();
            if !(n.is_finite() && n > 1e-9) {
                return bad(format!(
                    "frame {}, joint `{}`: rotation is not a valid quaternion",
                    i / skeleton.len(),
                    skeleton.joint(i % skeleton.len()).name
                ));
            }
            *q /= n;
        }
        Ok(Motion {
            skeleton,
            fps,
            root_translation,
            rotations,
            tracks: Vec::new(),
        })
    }

    /// The same motion with translation `tracks` (empty or all `None`: none).
    /// Validated: one entry per joint, none for the root (its translation is
    /// the root translation), one finite value per frame.
    pub fn with_tracks(mut self, tracks: Tracks) -> Result<Self, MotionError> {
        let bad = |m: String| Err(MotionError::InvalidMotion(m));
        if tracks.iter().all(Option::is_none) {
            self.tracks = Vec::new();
            return Ok(self);
        }
        if tracks.len() != self.joints() {
            return bad(format!(
                "{} translation tracks for {} joints",
                tracks.len(),
                self.joints()
            ));
        }
        for (j, track) in tracks.iter().enumerate() {
            let Some(track) = track else { continue };
            let name = &self.skeleton.joint(j).name;
            if self.skeleton.parent(j).is_none() {
                return bad(format!(
                    "root `{name}` has a translation track; its translation is the root translation"
                ));
            }
            if track.len() != self.frames() {
                return bad(format!(
                    "joint `{name}`: translation track of {} frames in a clip of {}",
                    track.len(),
                    self.frames()
                ));
            }
            if let Some(t) = track.iter().position(|p| !p.is_finite()) {
                return bad(format!(
                    "frame {t}, joint `{name}`: translation is not finite"
                ));
            }
        }
        self.tracks = tracks;
        Ok(self)
    }

    pub fn skeleton(&self) -> &Arc<Skeleton> {
        &self.skeleton
    }

    pub fn fps(&self) -> f64 {
        self.fps
    }

    pub fn frames(&self) -> usize {
        self.root_translation.len()
    }

    pub fn joints(&self) -> usize {
        self.skeleton.len()
    }

    /// Duration from the first to one past the last frame: `frames / fps`.
    pub fn duration_s(&self) -> f64 {
        self.frames() as f64 / self.fps
    }

    pub fn root_translation(&self) -> &[DVec3] {
        &self.root_translation
    }

    pub fn root_translation_mut(&mut self) -> &mut [DVec3] {
        &mut self.root_translation
    }

    /// All rotations, row-major `[frame][joint]`.
    pub fn rotations(&self) -> &[DQuat] {
        &self.rotations
    }

    /// Local rotations of one frame.
    pub fn pose(&self, frame: usize) -> &[DQuat] {
        let j = self.joints();
        &self.rotations[frame * j..(frame + 1) * j]
    }

    /// Mutable local rotations of one frame. Callers keep them unit length.
    pub fn pose_mut(&mut self, frame: usize) -> &mut [DQuat] {
        let j = self.joints();
        &mut self.rotations[frame * j..(frame + 1) * j]
    }

    pub fn rotation(&self, frame: usize, joint: usize) -> DQuat {
        self.rotations[frame * self.joints() + joint]
    }

    /// Whether any joint has a translation track.
    pub fn has_tracks(&self) -> bool {
        !self.tracks.is_empty()
    }

    /// The translation tracks: empty, or one entry per joint (see [`Tracks`]).
    pub fn tracks(&self) -> &[Option<Vec<DVec3>>] {
        &self.tracks
    }

    /// The translation track of one joint, if it has one.
    pub fn track(&self, joint: usize) -> Option<&[DVec3]> {
        self.tracks.get(joint)?.as_deref()
    }

    /// Local translation of a non-root joint at one frame: its track's value,
    /// else its rest offset.
    pub fn local_translation(&self, frame: usize, joint: usize) -> DVec3 {
        match self.track(joint) {
            Some(track) => track[frame],
            None => self.skeleton.joint(joint).offset,
        }
    }

    /// Local translation of a non-root joint at fractional frame `s` (clamped
    /// to the clip; linear between frames).
    pub fn local_translation_at(&self, s: f64, joint: usize) -> DVec3 {
        match self.track(joint) {
            Some(track) => {
                let (i0, i1, a) = self.between(s);
                track[i0].lerp(track[i1], a)
            }
            None => self.skeleton.joint(joint).offset,
        }
    }

    /// The two frames around fractional frame `s` (clamped) and the weight of the second.
    fn between(&self, s: f64) -> (usize, usize, f64) {
        let last = self.frames() - 1;
        let s = if s.is_finite() {
            s.clamp(0.0, last as f64)
        } else {
            0.0
        };
        let i0 = (s.floor() as usize).min(last);
        let i1 = (i0 + 1).min(last);
        (i0, i1, s - i0 as f64)
    }

    /// The translation tracks sampled at fractional frames `at` (clamped,
    /// linear between frames), for ops that change the frame count.
    pub fn tracks_at(&self, at: &[f64]) -> Tracks {
        self.tracks
            .iter()
            .enumerate()
            .map(|(j, t)| {
                t.as_ref().map(|_| {
                    at.iter()
                        .map(|&s| self.local_translation_at(s, j))
                        .collect()
                })
            })
            .collect()
    }

    /// World transforms of every joint at one frame, written into `out`.
    pub fn world_transforms_into(&self, frame: usize, out: &mut [Transform]) {
        self.skeleton.forward_with(
            self.root_translation[frame],
            self.pose(frame),
            |j| self.local_translation(frame, j),
            out,
        );
    }

    /// World transforms of every joint at one frame.
    pub fn world_transforms(&self, frame: usize) -> Vec<Transform> {
        let mut out = vec![Transform::IDENTITY; self.joints()];
        self.world_transforms_into(frame, &mut out);
        out
    }

    /// World positions of every joint at one frame, metres.
    pub fn world_positions(&self, frame: usize) -> Vec<DVec3> {
        self.world_transforms(frame)
            .into_iter()
            .map(|t| t.translation)
            .collect()
    }

    /// World positions of every joint at every frame, row-major `[frame][joint]`.
    pub fn all_world_positions(&self) -> Vec<DVec3> {
        let mut buf = vec![Transform::IDENTITY; self.joints()];
        let mut out = Vec::with_capacity(self.frames() * self.joints());
        for t in 0..self.frames() {
            self.world_transforms_into(t, &mut buf);
            out.extend(buf.iter().map(|x| x.translation));
        }
        out
    }

    /// A copy with the same skeleton and new per-frame data (validated). It
    /// keeps the translation tracks, so the frame count must stay the same
    /// when there are some (else resample them with [`Motion::tracks_at`] and
    /// use [`Motion::with_frames_and_tracks`]).
    pub fn with_frames(
        &self,
        fps: f64,
        root_translation: Vec<DVec3>,
        rotations: Vec<DQuat>,
    ) -> Result<Motion, MotionError> {
        if self.has_tracks() && root_translation.len() != self.frames() {
            return Err(MotionError::InvalidMotion(format!(
                "{} new frames for a clip of {} frames with translation tracks \
                 (resample them with `tracks_at`)",
                root_translation.len(),
                self.frames()
            )));
        }
        Motion::new(self.skeleton.clone(), fps, root_translation, rotations)?
            .with_tracks(self.tracks.clone())
    }

    /// A copy with the same skeleton, new per-frame data and new translation tracks.
    pub fn with_frames_and_tracks(
        &self,
        fps: f64,
        root_translation: Vec<DVec3>,
        rotations: Vec<DQuat>,
        tracks: Tracks,
    ) -> Result<Motion, MotionError> {
        Motion::new(self.skeleton.clone(), fps, root_translation, rotations)?.with_tracks(tracks)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::Joint;

    #[test]
    fn validates_shapes_and_normalises() {
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
        let m = Motion::new(
            s.clone(),
            30.0,
            vec![DVec3::ZERO; 2],
            vec![DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0); 2],
        )
        .unwrap();
        assert!((m.rotation(1, 0).length() - 1.0).abs() < 1e-12);
        assert!((m.duration_s() - 2.0 / 30.0).abs() < 1e-12);
        assert!(Motion::new(s.clone(), 0.0, vec![DVec3::ZERO], vec![DQuat::IDENTITY]).is_err());
        assert!(Motion::new(s.clone(), 30.0, vec![DVec3::ZERO], vec![]).is_err());
        assert!(
            Motion::new(
                s,
                30.0,
                vec![DVec3::ZERO],
                vec![DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0)]
            )
            .is_err()
        );
    }

    #[test]
    fn translation_tracks_drive_forward_kinematics() {
        let joint = |name: &str, parent, y| Joint {
            name: String::from(name),
            parent,
            offset: DVec3::new(0.0, y, 0.0),
            channels: vec![],
            end_site: None,
            limits: None,
        };
        let s = Arc::new(
            Skeleton::new(
                vec![joint("root", None, 0.0), joint("a", Some(0), 1.0)],
                1.0,
            )
            .unwrap(),
        );
        let m = Motion::new(
            s.clone(),
            10.0,
            vec![DVec3::ZERO; 3],
            vec![DQuat::IDENTITY; 6],
        )
        .unwrap();
        let track = vec![
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::new(1.0, 2.0, 0.0),
        ];
        let t = m
            .clone()
            .with_tracks(vec![None, Some(track.clone())])
            .unwrap();
        assert!(t.has_tracks() && !m.has_tracks());
        assert_eq!(t.world_positions(2)[1], DVec3::new(1.0, 2.0, 0.0));
        assert_eq!(m.world_positions(2)[1], DVec3::new(0.0, 1.0, 0.0));
        assert_eq!(t.local_translation_at(1.5, 1), DVec3::new(0.5, 2.0, 0.0));
        assert_eq!(t.local_translation_at(9.0, 1), track[2]);
        let half = t.tracks_at(&[0.5, 2.0]);
        assert_eq!(
            half[1].as_deref(),
            Some(&[DVec3::new(0.0, 1.5, 0.0), track[2]][..])
        );
        // Same frame count: tracks kept; another one: they must be given.
        let same = t
            .with_frames(10.0, vec![DVec3::X; 3], vec![DQuat::IDENTITY; 6])
            .unwrap();
        assert_eq!(same.track(1), Some(&track[..]));
        assert!(
            t.with_frames(10.0, vec![DVec3::X; 2], vec![DQuat::IDENTITY; 4])
                .is_err()
        );
        let shorter = t
            .with_frames_and_tracks(10.0, vec![DVec3::X; 2], vec![DQuat::IDENTITY; 4], half)
            .unwrap();
        assert_eq!(shorter.track(1).map(<[DVec3]>::len), Some(2));
        // Validation: the root has none, lengths match, values are finite.
        assert!(
            m.clone()
                .with_tracks(vec![Some(track.clone()), None])
                .is_err()
        );
        assert!(
            m.clone()
                .with_tracks(vec![None, Some(track[..2].to_vec())])
                .is_err()
        );
        let mut bad = track.clone();
        bad[1].y = f64::NAN;
        let e = m.clone().with_tracks(vec![None, Some(bad)]).unwrap_err();
        assert!(e.to_string().contains("frame 1, joint `a`"), "{e}");
        assert!(!m.with_tracks(vec![None, None]).unwrap().has_tracks());
    }
}
