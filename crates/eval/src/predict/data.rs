//! Prediction data: clips as per-frame feature vectors, windows of
//! [`INPUT_FRAMES`] observed + [`OUTPUT_FRAMES`] predicted frames at 30 fps,
//! normalisation and batches.
//!
//! Model features are the rotation vectors (axis * angle, the "expmap" of
//! Martinez et al. 2017) of every non-root joint's local rotation: continuous
//! where Euler angles jump, and 3 numbers per joint. The root is excluded from
//! input and output, as it is from the error. Errors are measured in Euler
//! angles ([`crate::euler`]) after converting predictions back to rotations.
//!
//! A rotation vector with its angle in [0, pi] jumps to the opposite
//! direction where a rotation passes half a turn, so a clip's features take
//! its quaternions on one hemisphere frame to frame ([`features`]) and the
//! angle runs past pi instead. Why: two HDM05 kicks of actor mm
//! (`kickLFront1Reps_023`, `_024`) hold the right foot rolled half a turn
//! about its bone (AMC `rfoot 153 159`); their physically corrected versions
//! cross pi twice each, and four such clips among 59 made every model trained
//! on them predict that foot a half turn off (its squared Euler error 10.8
//! rad^2 at 400 ms against about 1 for the other joints; the kick
//! `ik_corrected` rows 0.3-1.1 rad worse than no augmentation).

use candle_core::{Device, Tensor};
use motion::Motion;
use motion::glam::{DQuat, DVec3};
use motion::rotation::to_rotation_vector;

use crate::error::{EvalError, Result};
use crate::euler::{Convention, EulerClip, check_same_layout};

/// Observed frames per window (MotionAug: 10 at 30 fps).
pub const INPUT_FRAMES: usize = 10;
/// Predicted frames per window (400 ms at 30 fps).
pub const OUTPUT_FRAMES: usize = 12;
/// Horizons reported, in milliseconds.
pub const HORIZONS_MS: [u32; 3] = [100, 200, 400];

/// Index among the predicted frames of the frame `ms` after the last observed
/// one at `fps` (100 ms at 30 fps = the 3rd predicted frame, index 2).
pub fn horizon_index(ms: u32, fps: f64) -> usize {
    ((ms as f64 * fps / 1000.0).round() as usize).max(1) - 1
}

/// Per-frame model features of a clip: `frames x 3 (J - 1)` rotation vectors,
/// continuous in time (see the module docs): each joint's first frame on the
/// hemisphere w >= 0 (angle at most pi), every later one on its predecessor's.
pub fn features(motion: &Motion) -> Vec<f32> {
    let joints = motion.joints().saturating_sub(1);
    let mut out = Vec::with_capacity(motion.frames() * 3 * joints);
    let mut previous: Vec<Option<DQuat>> = vec![None; joints];
    for t in 0..motion.frames() {
        for (q, prev) in motion.pose(t)[1..].iter().zip(previous.iter_mut()) {
            let q = match prev {
                Some(p) if p.dot(*q) < 0.0 => -*q,
                Some(_) => *q,
                None if q.w < 0.0 => -*q,
                None => *q,
            };
            let v = rotation_vector_of(q);
            *prev = Some(q);
            out.extend([v.x as f32, v.y as f32, v.z as f32]);
        }
    }
    out
}

/// Rotation vector of a unit quaternion as it stands: angle 2 atan2(|xyz|,
/// w), beyond pi when w < 0 (`DQuat::from_scaled_axis` turns it back into the
/// same rotation).
fn rotation_vector_of(q: DQuat) -> DVec3 {
    if q.w >= 0.0 {
        return to_rotation_vector(q);
    }
    let xyz = DVec3::new(q.x, q.y, q.z);
    let s = xyz.length();
    if s < 1e-12 {
        // A full turn: the same rotation as none.
        return DVec3::ZERO;
    }
    xyz / s * (2.0 * s.atan2(q.w))
}

/// Euler angles ([`crate::euler`]) of one frame of features.
pub fn features_to_euler(frame: &[f32], convention: &Convention) -> Vec<f64> {
    frame
        .chunks_exact(3)
        .enumerate()
        .flat_map(|(j, v)| {
            let q = DQuat::from_scaled_axis(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64));
            convention.joint(j, q)
        })
        .collect()
}

/// One clip ready for windows.
#[derive(Debug, Clone)]
pub struct Clip {
    pub name: String,
    pub frames: usize,
    /// `frames x dim` model features.
    pub features: Vec<f32>,
    /// Ground-truth Euler angles, for scoring.
    pub euler: EulerClip,
    /// The clip's skeleton's angle convention (for predictions).
    pub convention: Convention,
}

/// Clips of one skeleton layout with their windows.
#[derive(Debug, Clone)]
pub struct ClipSet {
    pub dim: usize,
    pub clips: Vec<Clip>,
    /// `(clip, first frame)` of every window.
    pub windows: Vec<(usize, usize)>,
    /// Clips too short for one window.
    pub skipped: Vec<String>,
}

impl ClipSet {
    /// Windows of `INPUT_FRAMES + OUTPUT_FRAMES` frames every `stride` frames;
    /// clips at another rate than `fps` are resampled; every clip must have the
    /// joints of `reference`.
    pub fn new(
        clips: &[(String, Motion)],
        reference: &Motion,
        fps: f64,
        stride: usize,
    ) -> Result<ClipSet> {
        if stride == 0 {
            return Err(EvalError::Config("window stride must be at least 1".into()));
        }
        let len = INPUT_FRAMES + OUTPUT_FRAMES;
        let dim = 3 * reference.joints().saturating_sub(1);
        let mut set = ClipSet {
            dim,
            clips: Vec::new(),
            windows: Vec::new(),
            skipped: Vec::new(),
        };
        for (name, m) in clips {
            check_same_layout(reference.skeleton(), m.skeleton(), name)?;
            let resampled;
            let m = if (m.fps() - fps).abs() > 1e-9 {
                resampled = motion::resample::resample(m, fps)?;
                &resampled
            } else {
                m
            };
            if m.frames() < len {
                set.skipped.push(name.clone());
                continue;
            }
            let index = set.clips.len();
            set.windows
                .extend((0..=m.frames() - len).step_by(stride).map(|s| (index, s)));
            set.clips.push(Clip {
                name: name.clone(),
                frames: m.frames(),
                features: features(m),
                euler: EulerClip::of(m),
                convention: Convention::of(m.skeleton()),
            });
        }
        Ok(set)
    }

    /// Keeps at most `max` windows, evenly spaced over the list (deterministic).
    pub fn limit_windows(&mut self, max: usize) {
        if max > 0 && self.windows.len() > max {
            let n = self.windows.len();
            self.windows = (0..max).map(|i| self.windows[i * n / max]).collect();
        }
    }

    /// Frame `t` of clip `c`.
    pub fn frame(&self, c: usize, t: usize) -> &[f32] {
        &self.clips[c].features[t * self.dim..(t + 1) * self.dim]
    }
}

/// Per-feature mean and standard deviation (floored), from training frames.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Normalizer {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl Normalizer {
    /// Statistics over every frame of every clip in `set`; a feature with a
    /// standard deviation below 1e-4 (a joint that never moves) keeps scale 1.
    pub fn fit(set: &ClipSet) -> Normalizer {
        let d = set.dim;
        let mut sum = vec![0f64; d];
        let mut sq = vec![0f64; d];
        let mut n = 0usize;
        for c in &set.clips {
            for f in c.features.chunks_exact(d) {
                for (i, v) in f.iter().enumerate() {
                    sum[i] += *v as f64;
                    sq[i] += (*v as f64).powi(2);
                }
                n += 1;
            }
        }
        let n = n.max(1) as f64;
        let mean: Vec<f64> = sum.iter().map(|s| s / n).collect();
        let std = sq
            .iter()
            .zip(&mean)
            .map(|(s, m)| {
                let v = (s / n - m * m).max(0.0).sqrt();
                if v < 1e-4 { 1.0 } else { v as f32 }
            })
            .collect();
        Normalizer {
            mean: mean.into_iter().map(|m| m as f32).collect(),
            std,
        }
    }

    pub fn norm(&self, frame: &[f32], out: &mut Vec<f32>) {
        out.extend(
            frame
                .iter()
                .zip(self.mean.iter().zip(&self.std))
                .map(|(v, (m, s))| (v - m) / s),
        );
    }

    /// Denormalises a flat `(.., dim)` buffer in place.
    pub fn denorm(&self, data: &mut [f32]) {
        let d = self.mean.len();
        for f in data.chunks_exact_mut(d) {
            for (i, v) in f.iter_mut().enumerate() {
                *v = *v * self.std[i] + self.mean[i];
            }
        }
    }
}

/// Normalised `(B, INPUT_FRAMES, D)` inputs and `(B, OUTPUT_FRAMES, D)` targets
/// of the given windows.
pub fn batch(
    set: &ClipSet,
    norm: &Normalizer,
    windows: &[(usize, usize)],
) -> Result<(Tensor, Tensor)> {
    let (b, d) = (windows.len(), set.dim);
    let mut input = Vec::with_capacity(b * INPUT_FRAMES * d);
    let mut target = Vec::with_capacity(b * OUTPUT_FRAMES * d);
    for &(c, s) in windows {
        for t in 0..INPUT_FRAMES {
            norm.norm(set.frame(c, s + t), &mut input);
        }
        for t in 0..OUTPUT_FRAMES {
            norm.norm(set.frame(c, s + INPUT_FRAMES + t), &mut target);
        }
    }
    Ok((
        Tensor::from_vec(input, (b, INPUT_FRAMES, d), &Device::Cpu)?,
        Tensor::from_vec(target, (b, OUTPUT_FRAMES, d), &Device::Cpu)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn horizons_at_30_fps() {
        let idx: Vec<usize> = HORIZONS_MS
            .iter()
            .map(|ms| horizon_index(*ms, 30.0))
            .collect();
        assert_eq!(idx, vec![2, 5, 11]);
    }

    #[test]
    fn features_stay_continuous_where_a_rotation_passes_half_a_turn() {
        let asf = motion::asf::parse(
            include_bytes!("../../../../examples/data/HDM_bd.asf"),
            "HDM_bd.asf",
        )
        .unwrap();
        let skeleton = asf.skeleton().clone();
        let nj = skeleton.len();
        let frames = 20;
        // One joint turning about a fixed axis from 2.9 to 3.4 rad.
        let joint = 5;
        let axis = DVec3::new(0.3, 0.9, -0.2).normalize();
        let mut rotations = vec![DQuat::IDENTITY; frames * nj];
        for t in 0..frames {
            let angle = 2.9 + 0.5 * t as f64 / (frames - 1) as f64;
            rotations[t * nj + joint] = DQuat::from_axis_angle(axis, angle);
        }
        let m = Motion::new(skeleton, 30.0, vec![DVec3::ZERO; frames], rotations).unwrap();
        let f = features(&m);
        let d = 3 * (nj - 1);
        let v = |t: usize| {
            let o = t * d + 3 * (joint - 1);
            DVec3::new(f[o] as f64, f[o + 1] as f64, f[o + 2] as f64)
        };
        for t in 1..frames {
            let step = (v(t) - v(t - 1)).length();
            assert!(step < 0.05, "features jump by {step} at frame {t}");
        }
        assert!(
            v(frames - 1).length() > std::f64::consts::PI,
            "the angle runs past pi"
        );
        // Features still mean the clip's rotations.
        let conv = Convention::of(m.skeleton());
        let truth = EulerClip::of(&m);
        for t in 0..frames {
            let e = features_to_euler(&f[t * d..(t + 1) * d], &conv);
            assert!(crate::euler::l2_distance(&e, truth.frame(t)) < 1e-4);
        }
    }

    #[test]
    fn features_convert_back_to_the_same_euler_angles() {
        let amc = crate::example_kick();
        let conv = Convention::of(amc.skeleton());
        let f = features(&amc);
        let d = 3 * (amc.joints() - 1);
        let truth = EulerClip::of(&amc);
        for t in [0, 50, 100] {
            let e = features_to_euler(&f[t * d..(t + 1) * d], &conv);
            assert!(crate::euler::l2_distance(&e, truth.frame(t)) < 1e-4);
        }
    }
}
