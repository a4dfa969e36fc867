//! Motion: a skeleton animated over time.

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
}

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
        })
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

    /// World transforms of every joint at one frame, written into `out`.
    pub fn world_transforms_into(&self, frame: usize, out: &mut [Transform]) {
        self.skeleton
            .forward(self.root_translation[frame], self.pose(frame), out);
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

    /// A copy with the same skeleton and new per-frame data (validated).
    pub fn with_frames(
        &self,
        fps: f64,
        root_translation: Vec<DVec3>,
        rotations: Vec<DQuat>,
    ) -> Result<Motion, MotionError> {
        Motion::new(self.skeleton.clone(), fps, root_translation, rotations)
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
}
