//! Motion <-> per-frame feature vectors, the representation the VAE (and later the
//! debiasing and evaluation code) works in.
//!
//! A frame is `[root x, root y, root z, 6D rotation of joint 0, ..., of joint J-1]`,
//! `3 + 6 J` numbers:
//! * root position: the clip is moved so that the first frame's root lies above
//!   the origin (x = z = 0; the height y is kept), and, with `heading_normalise`,
//!   rotated about the vertical so that the first frame's root faces +z. Every clip
//!   of a class then starts in the same place and direction, which is what lets a
//!   handful of clips share one latent space.
//! * 6D rotation (Zhou et al. 2019): the first two columns of the local rotation
//!   matrix, continuous unlike quaternions or Euler angles. Back to a rotation by
//!   Gram-Schmidt, so any 6 numbers (a network's output) give a valid rotation.
//!
//! The conversion is exact up to rounding in both directions (for the canonical
//! placement): `frames_to_motion(motion_to_frames(m))` is `m` moved to the origin.
//!
//! Training clips are also put on one floor ([`FloorLevel`], in
//! [`clip_frames_on`]): HDM05's actors were captured with their feet 0-3 cm
//! apart in height, and a model that learns all of them at once decodes feet
//! that hover.

use std::sync::Arc;

use motion::glam::{DQuat, DVec3};
use motion::{Motion, Skeleton};
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};

/// How clips become frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureConfig {
    /// Frame rate the clips are resampled to before conversion (30 in the paper).
    pub fps: f64,
    /// Rotate each clip about y so that its first frame's root faces +z.
    pub heading_normalise: bool,
    /// Move each clip up or down onto one floor before training (`None`: as
    /// captured; models saved before this existed read as `None`).
    #[serde(default)]
    pub floor: Option<FloorLevel>,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        FeatureConfig {
            fps: 30.0,
            heading_normalise: true,
            floor: Some(FloorLevel::default()),
        }
    }
}

impl FeatureConfig {
    pub fn validate(&self) -> Result<()> {
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(VaeError::Config(format!(
                "feature frame rate {} must be > 0",
                self.fps
            )));
        }
        match self.floor {
            Some(f) => f.validate(),
            None => Ok(()),
        }
    }
}

/// One floor for every training clip: each clip's root moves vertically so
/// that, in `quantile` of its frames, its lowest body point (joints and end
/// sites, on the model's skeleton) is at or below `height_m`.
///
/// Why: the actors of a class stand on floors that differ by centimetres
/// (HDM05 jog: the 10th percentile of the lowest point is 5-14 mm for bk,
/// 21-26 mm for mm, 33-38 mm for dg and tr). Trained on them as captured, fold
/// bd's VAE decoded jog samples floating in 55 % of frames and skating
/// 0.098 m/s; on one floor 46 % and 0.072 m/s at the same pose speed
/// (crates/vae/README.md, session 33). A quantile rather than the minimum, so that a toe
/// dipping through the floor in a frame or two does not lift the whole clip;
/// a low one, so that a clip with flight phases stands on its stance frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FloorLevel {
    /// Share of frames, 0-1.
    pub quantile: f64,
    /// Height of the lowest point at that quantile, m.
    pub height_m: f64,
}

impl Default for FloorLevel {
    /// The 10th percentile at 5 mm.
    fn default() -> Self {
        FloorLevel {
            quantile: 0.1,
            height_m: 0.005,
        }
    }
}

impl FloorLevel {
    pub fn validate(&self) -> Result<()> {
        if !(self.quantile.is_finite() && (0.0..=1.0).contains(&self.quantile)) {
            return Err(VaeError::Config(format!(
                "floor quantile {} must be in 0-1",
                self.quantile
            )));
        }
        if !(self.height_m.is_finite() && self.height_m.abs() <= 0.5) {
            return Err(VaeError::Config(format!(
                "floor height {} m must be within 0.5 m of the floor",
                self.height_m
            )));
        }
        Ok(())
    }

    /// How far to raise `motion` (negative: lower it), m.
    pub fn lift(&self, motion: &Motion) -> f64 {
        let mut lows = motion::metrics::lowest_points(motion);
        if lows.is_empty() {
            return 0.0;
        }
        lows.sort_by(f64::total_cmp);
        let i = ((lows.len() - 1) as f64 * self.quantile).round() as usize;
        self.height_m - lows[i]
    }
}

/// Numbers per frame for a skeleton of `joints` joints.
pub fn frame_dim(joints: usize) -> usize {
    3 + 6 * joints
}

/// Heading of a root rotation (see [`motion::rotation::heading`]).
pub fn heading(root_rotation: DQuat) -> f64 {
    motion::rotation::heading(root_rotation)
}

/// First two columns of the rotation matrix of `q` (see [`motion::rotation::to_6d`]).
pub fn quat_to_6d(q: DQuat) -> [f64; 6] {
    motion::rotation::to_6d(q)
}

/// The rotation nearest the first six numbers of `v` (see [`motion::rotation::from_6d`]).
pub fn rotation_from_6d(v: &[f64]) -> DQuat {
    let mut six = [0.0; 6];
    for (s, x) in six.iter_mut().zip(v) {
        *s = *x;
    }
    motion::rotation::from_6d(&six)
}

/// The frames of a clip (already at the wanted frame rate), row-major
/// `[frame][3 + 6 J]`, f32.
pub fn motion_to_frames(motion: &Motion, config: &FeatureConfig) -> Vec<f32> {
    let joints = motion.joints();
    let dim = frame_dim(joints);
    let root0 = motion.root_translation()[0];
    let origin = DVec3::new(root0.x, 0.0, root0.z);
    let turn = if config.heading_normalise {
        DQuat::from_rotation_y(-heading(motion.rotation(0, 0)))
    } else {
        DQuat::IDENTITY
    };
    let mut out = Vec::with_capacity(motion.frames() * dim);
    for t in 0..motion.frames() {
        let p = turn * (motion.root_translation()[t] - origin);
        out.extend([p.x as f32, p.y as f32, p.z as f32]);
        for (j, &q) in motion.pose(t).iter().enumerate() {
            let q = if j == 0 { turn * q } else { q };
            out.extend(quat_to_6d(q).map(|x| x as f32));
        }
    }
    out
}

/// A clip on `skeleton` from frames laid out as [`motion_to_frames`] writes them.
pub fn frames_to_motion(skeleton: &Arc<Skeleton>, fps: f64, frames: &[f32]) -> Result<Motion> {
    let joints = skeleton.len();
    let dim = frame_dim(joints);
    if frames.is_empty() || !frames.len().is_multiple_of(dim) {
        return Err(VaeError::Data(format!(
            "{} numbers are not whole frames of {dim} for a {joints}-joint skeleton",
            frames.len()
        )));
    }
    let n = frames.len() / dim;
    let mut root = Vec::with_capacity(n);
    let mut rotations = Vec::with_capacity(n * joints);
    let mut six = [0.0f64; 6];
    for frame in frames.chunks_exact(dim) {
        root.push(DVec3::new(
            frame[0] as f64,
            frame[1] as f64,
            frame[2] as f64,
        ));
        for j in 0..joints {
            for (k, s) in six.iter_mut().enumerate() {
                *s = frame[3 + 6 * j + k] as f64;
            }
            rotations.push(rotation_from_6d(&six));
        }
    }
    Ok(Motion::new(skeleton.clone(), fps, root, rotations)?)
}

/// Resample a clip to `config.fps` (when it is not already there) and convert it.
pub fn clip_frames(motion: &Motion, config: &FeatureConfig) -> Result<Vec<f32>> {
    if (motion.fps() - config.fps).abs() < 1e-9 {
        Ok(motion_to_frames(motion, config))
    } else {
        let m = motion::resample::resample(motion, config.fps)?;
        Ok(motion_to_frames(&m, config))
    }
}

/// Height of the root above the lowest point (joint or end site) of the rest
/// pose, metres: the leg length that sets how far a step carries the root.
pub fn hip_height(skeleton: &Skeleton) -> f64 {
    -skeleton.rest_extent().0.min(0.0)
}

/// The frames of a clip as the skeleton `model` would perform it: [`clip_frames`]
/// with the root path scaled by the ratio of the two skeletons' hip heights,
/// then, with `config.floor`, moved vertically onto the floor ([`FloorLevel`],
/// measured on `model`).
///
/// Why: a class's clips come from actors of different sizes (HDM05's bk has legs
/// 14 % longer than bd's) and a model decodes every clip on one skeleton. Without
/// the scaling a tall actor's root height makes the model's feet float and a
/// short one's sink, and a long stride on short legs can only slide.
pub fn clip_frames_on(
    motion: &Motion,
    config: &FeatureConfig,
    model: &Arc<Skeleton>,
) -> Result<Vec<f32>> {
    let mut frames = clip_frames(motion, config)?;
    let dim = frame_dim(motion.joints());
    let own = hip_height(motion.skeleton());
    let target = hip_height(model);
    if own > 1e-6 && target > 1e-6 && (own - target).abs() > 1e-9 {
        let k = (target / own) as f32;
        for frame in frames.chunks_exact_mut(dim) {
            for v in &mut frame[..3] {
                *v *= k;
            }
        }
    }
    if let Some(floor) = config.floor {
        let lift = floor.lift(&frames_to_motion(model, config.fps, &frames)?) as f32;
        for frame in frames.chunks_exact_mut(dim) {
            frame[1] += lift;
        }
    }
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::Joint;
    use proptest::prelude::*;

    fn skeleton() -> Arc<Skeleton> {
        two_joints(DVec3::new(0.0, 0.5, 0.0))
    }

    /// A root and one child joint at `child` from it.
    fn two_joints(child: DVec3) -> Arc<Skeleton> {
        let joint = Joint::new;
        Arc::new(
            Skeleton::new(
                vec![joint("root", None, DVec3::ZERO), joint("a", Some(0), child)],
                1.0,
            )
            .unwrap(),
        )
    }

    fn quat(v: [f64; 4]) -> DQuat {
        DQuat::from_xyzw(v[0], v[1], v[2], v[3]).normalize()
    }

    proptest! {
        #[test]
        fn six_d_round_trips(v in prop::array::uniform4(-1.0f64..1.0)) {
            prop_assume!(DQuat::from_array(v).length() > 0.1);
            let q = quat(v);
            let back = rotation_from_6d(&quat_to_6d(q));
            prop_assert!(motion::rotation::angle_between(q, back) < 1e-9);
        }

        #[test]
        fn any_six_numbers_give_a_rotation(v in prop::array::uniform6(-3.0f64..3.0)) {
            let q = rotation_from_6d(&v);
            prop_assert!((q.length() - 1.0).abs() < 1e-9);
        }

        #[test]
        fn frames_round_trip_to_the_canonical_clip(
            r0 in prop::array::uniform4(-1.0f64..1.0),
            r1 in prop::array::uniform4(-1.0f64..1.0),
            yaw in -3.0f64..3.0,
            start in prop::array::uniform3(-5.0f64..5.0),
        ) {
            prop_assume!(DQuat::from_array(r0).length() > 0.1 && DQuat::from_array(r1).length() > 0.1);
            let s = skeleton();
            let root0 = DQuat::from_rotation_y(yaw) * quat(r0);
            let roots = vec![DVec3::from(start), DVec3::from(start) + DVec3::new(0.3, 0.1, -0.2)];
            let rots = vec![root0, quat(r1), quat(r1), root0];
            let m = Motion::new(s.clone(), 30.0, roots, rots).unwrap();
            let config = FeatureConfig::default();
            let frames = motion_to_frames(&m, &config);
            prop_assert_eq!(frames.len(), 2 * frame_dim(2));
            let back = frames_to_motion(&s, 30.0, &frames).unwrap();
            // First frame: above the origin, facing +z, same height.
            let p0 = back.root_translation()[0];
            prop_assert!(p0.x.abs() < 1e-6 && p0.z.abs() < 1e-6);
            prop_assert!((p0.y - start[1]).abs() < 1e-5);
            prop_assert!(heading(back.rotation(0, 0)).abs() < 1e-5);
            // Non-root rotations unchanged; relative root motion only turned.
            prop_assert!(motion::rotation::angle_between(back.rotation(0, 1), quat(r1)) < 1e-5);
            let step = back.root_translation()[1] - p0;
            prop_assert!((step.length() - DVec3::new(0.3, 0.1, -0.2).length()).abs() < 1e-5);
            // Relative root rotation between frames is preserved.
            let rel_a = m.rotation(0, 0).inverse() * m.rotation(1, 0);
            let rel_b = back.rotation(0, 0).inverse() * back.rotation(1, 0);
            prop_assert!(motion::rotation::angle_between(rel_a, rel_b) < 1e-5);
        }
    }

    #[test]
    fn a_taller_actors_root_path_is_scaled_to_the_models_legs() {
        // A leg hanging below the root, 0.8 m (the model) or 1 m (the actor).
        let leg = |length: f64| two_joints(DVec3::new(0.0, -length, 0.0));
        let (short, tall) = (leg(0.8), leg(1.0));
        assert!((hip_height(&tall) - 1.0).abs() < 1e-12);
        let roots = vec![DVec3::new(0.0, 1.0, 0.0), DVec3::new(0.5, 1.1, 0.2)];
        let m = Motion::new(tall.clone(), 30.0, roots, vec![DQuat::IDENTITY; 4]).unwrap();
        let config = FeatureConfig {
            floor: None,
            ..FeatureConfig::default()
        };
        let own = clip_frames_on(&m, &config, &tall).unwrap();
        assert_eq!(
            own,
            clip_frames(&m, &config).unwrap(),
            "same legs: unchanged"
        );
        let scaled = clip_frames_on(&m, &config, &short).unwrap();
        let dim = frame_dim(2);
        for t in 0..2 {
            for k in 0..3 {
                assert!((scaled[t * dim + k] - 0.8 * own[t * dim + k]).abs() < 1e-6);
            }
            assert_eq!(
                scaled[t * dim + 3..(t + 1) * dim],
                own[t * dim + 3..(t + 1) * dim]
            );
        }
    }

    #[test]
    fn each_clip_is_moved_onto_one_floor_at_its_stance_frames() {
        // A leg hanging 1 m below the root: the lowest point is the root's
        // height minus 1 m. Ten frames standing 3 cm up, then a hop to 30 cm.
        let s = two_joints(DVec3::new(0.0, -1.0, 0.0));
        let heights = [1.03, 1.03, 1.03, 1.03, 1.03, 1.03, 1.03, 1.03, 1.1, 1.3];
        let roots = heights.map(|y| DVec3::new(0.0, y, 0.0)).to_vec();
        let m = Motion::new(s.clone(), 30.0, roots, vec![DQuat::IDENTITY; 20]).unwrap();
        let config = FeatureConfig::default();
        let level = config.floor.unwrap();
        assert!(
            (level.lift(&m) - (0.005 - 0.03)).abs() < 1e-9,
            "the hop does not count"
        );
        let frames = clip_frames_on(&m, &config, &s).unwrap();
        let dim = frame_dim(2);
        for (t, y) in heights.iter().enumerate() {
            assert!((frames[t * dim + 1] as f64 - (y - 0.025)).abs() < 1e-5);
        }
        // Sunk 2 cm into the floor: raised, by the same rule.
        let sunk = m
            .with_frames(
                30.0,
                heights.map(|y| DVec3::new(0.0, y - 0.05, 0.0)).to_vec(),
                vec![DQuat::IDENTITY; 20],
            )
            .unwrap();
        assert!((level.lift(&sunk) - 0.025).abs() < 1e-9);
        let off = FeatureConfig {
            floor: None,
            ..config
        };
        assert_eq!(clip_frames_on(&m, &off, &s).unwrap()[1], 1.03);
        assert!(
            FloorLevel {
                quantile: 1.5,
                height_m: 0.0
            }
            .validate()
            .is_err()
        );
        assert!(
            FloorLevel {
                quantile: 0.1,
                height_m: f64::NAN
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn rejects_partial_frames() {
        assert!(frames_to_motion(&skeleton(), 30.0, &[0.0; 16]).is_err());
        assert!(frames_to_motion(&skeleton(), 30.0, &[]).is_err());
    }
}
