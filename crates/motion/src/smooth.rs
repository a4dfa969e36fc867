//! Temporal smoothing of a clip: a Gaussian low-pass over the root path and
//! every joint's rotations.
//!
//! Why it exists: decoded VAE clips jitter from frame to frame (their jerk is
//! 3-4x the capture's on HDM05 jogs, crates/vae/README.md, session 18), and a
//! physics tracker cannot follow jitter without help from the root force.
//! Rotations are averaged as sign-aligned weighted quaternion sums,
//! normalised: exact for a constant rotation and accurate for the small
//! angles a window of a few frames spans. The window is cut at the clip's
//! ends (weights renormalised over the frames that exist), so the first and
//! last frames are not pulled towards padding. Translation tracks are kept
//! as they are.

use glam::{DQuat, DVec3};

use crate::Motion;
use crate::error::MotionError;

/// A Gaussian window of `sigma` frames (+-3 sigma) for clips of at most
/// `longest` frames, cut at each clip's ends: what [`gaussian`] and other
/// per-frame low-passes (the debiaser's change) average over.
pub struct GaussianWindow {
    half: isize,
    weights: Vec<f64>,
}

impl GaussianWindow {
    pub fn new(sigma: f64, longest: usize) -> GaussianWindow {
        // Past the longest clip a wider window only adds weights of absent frames.
        let half = (3.0 * sigma).ceil().min(longest as f64) as isize;
        let weights = (-half..=half)
            .map(|k| (-(k as f64).powi(2) / (2.0 * sigma * sigma)).exp())
            .collect();
        GaussianWindow { half, weights }
    }

    /// The frames around frame `t` of a clip of `frames` frames that exist,
    /// with their weights (not normalised: divide by their sum).
    pub fn taps(&self, t: usize, frames: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        (-self.half..=self.half)
            .zip(&self.weights)
            .filter_map(move |(k, &w)| {
                let s = t as isize + k;
                (0..frames as isize).contains(&s).then_some((s as usize, w))
            })
    }
}

/// `motion` low-passed with a Gaussian of standard deviation `sigma_s`
/// seconds (window +-3 sigma). `sigma_s` = 0 returns the clip unchanged.
pub fn gaussian(motion: &Motion, sigma_s: f64) -> Result<Motion, MotionError> {
    if !(sigma_s.is_finite() && sigma_s >= 0.0) {
        return Err(MotionError::InvalidMotion(format!(
            "smoothing sigma {sigma_s} s must be a finite number >= 0"
        )));
    }
    let sigma = sigma_s * motion.fps();
    let mut out = motion.clone();
    let n = motion.frames();
    if sigma < 1e-3 || n < 2 {
        return Ok(out);
    }
    let gaussian = GaussianWindow::new(sigma, n);
    let window = |t: usize| gaussian.taps(t, n);
    for t in 0..n {
        let (mut sum, mut total) = (DVec3::ZERO, 0.0);
        for (s, w) in window(t) {
            sum += motion.root_translation()[s] * w;
            total += w;
        }
        out.root_translation_mut()[t] = sum / total;
        for j in 0..motion.joints() {
            let centre = motion.rotation(t, j);
            let mut acc = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
            for (s, w) in window(t) {
                let mut q = motion.rotation(s, j);
                if q.dot(centre) < 0.0 {
                    q = -q;
                }
                acc += q * w;
            }
            out.pose_mut(t)[j] = if acc.length_squared() > 1e-24 {
                acc.normalize()
            } else {
                centre
            };
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::tests::chain;
    use std::sync::Arc;

    /// The test chain with joint 1 turning by `rot(t)` and the root at `root(t)`.
    fn clip(rot: impl Fn(usize) -> DQuat, root: impl Fn(usize) -> DVec3, n: usize) -> Motion {
        let rotations = (0..n)
            .flat_map(|t| [DQuat::IDENTITY, rot(t), DQuat::IDENTITY])
            .collect();
        Motion::new(
            Arc::new(chain()),
            30.0,
            (0..n).map(root).collect(),
            rotations,
        )
        .unwrap()
    }

    #[test]
    fn linear_motion_is_kept_and_alternating_jitter_is_removed() {
        // A root moving at constant speed and a knee turning at a constant
        // rate are what a low-pass keeps (inside the clip, away from its ends).
        let m = clip(
            |t| DQuat::from_rotation_x(0.02 * t as f64),
            |t| DVec3::new(0.05 * t as f64, 0.9, 0.0),
            40,
        );
        let s = gaussian(&m, 1.0 / 30.0).unwrap();
        for t in 5..35 {
            assert!((s.root_translation()[t] - m.root_translation()[t]).length() < 1e-9);
            assert!(
                s.rotation(t, 1).angle_between(m.rotation(t, 1)) < 1e-6,
                "t {t}"
            );
        }
        // Frame-to-frame jitter of +-0.1 rad around a still pose mostly goes.
        let j = clip(
            |t| DQuat::from_rotation_x(if t % 2 == 0 { 0.1 } else { -0.1 }),
            |_| DVec3::new(0.0, 0.9, 0.0),
            40,
        );
        let s = gaussian(&j, 1.5 / 30.0).unwrap();
        for t in 0..40 {
            // Inside the clip the window is symmetric; at the ends it is cut.
            let bound = if (5..35).contains(&t) { 0.01 } else { 0.05 };
            let a = s.rotation(t, 1).angle_between(DQuat::IDENTITY);
            assert!(a < bound, "t {t}: {a} rad");
            assert!(s.rotation(t, 1).is_normalized());
        }
        assert_eq!(gaussian(&j, 0.0).unwrap().rotations(), j.rotations());
        assert!(gaussian(&j, -1.0).is_err());
        assert!(gaussian(&j, f64::NAN).is_err());
    }
}
