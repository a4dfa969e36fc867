//! Gaussian noise on joint rotations: the augmentation baseline of the MotionAug
//! paper ("Noise" rows of its Tables 2-3).
//!
//! Each local rotation is perturbed by a random rotation vector drawn i.i.d. per
//! frame and per joint: `q' = q * exp(e)`, `e ~ N(0, sigma^2 I3)` (radians, in the
//! joint's own frame). The noise is not smoothed over time, as in the baseline, so
//! it adds jitter (see the jerk metric). The root orientation is left alone unless
//! `include_root` is set (noise there swings the whole body); the root position
//! can get its own i.i.d. noise (`root_sigma_m`, metres per axis).

use glam::{DQuat, DVec3};
use motion::Motion;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::{Augmented, SynthError, SynthRng};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseParams {
    /// Standard deviation of each rotation-vector component, degrees.
    #[serde(default = "default_sigma_deg")]
    pub sigma_deg: f64,
    /// Standard deviation of each root position component, metres (0 = none).
    #[serde(default)]
    pub root_sigma_m: f64,
    /// Also perturb the root joint's orientation.
    #[serde(default)]
    pub include_root: bool,
}

fn default_sigma_deg() -> f64 {
    2.0
}

impl Default for NoiseParams {
    fn default() -> Self {
        NoiseParams {
            sigma_deg: default_sigma_deg(),
            root_sigma_m: 0.0,
            include_root: false,
        }
    }
}

impl NoiseParams {
    pub fn validate(&self) -> Result<(), SynthError> {
        if !(self.sigma_deg.is_finite() && (0.0..=90.0).contains(&self.sigma_deg)) {
            return Err(SynthError::param("sigma_deg", "must be in [0, 90] degrees"));
        }
        if !(self.root_sigma_m.is_finite() && (0.0..=1.0).contains(&self.root_sigma_m)) {
            return Err(SynthError::param(
                "root_sigma_m",
                "must be in [0, 1] metres",
            ));
        }
        Ok(())
    }
}

pub(crate) fn gaussian_vec(rng: &mut SynthRng, sigma: f64) -> DVec3 {
    let mut g = || -> f64 { StandardNormal.sample(rng) };
    DVec3::new(g(), g(), g()) * sigma
}

/// Add i.i.d. Gaussian rotation noise (and optionally root position noise).
pub fn noise(
    motion: &Motion,
    params: &NoiseParams,
    rng: &mut SynthRng,
) -> Result<Augmented, SynthError> {
    params.validate()?;
    let sigma = params.sigma_deg.to_radians();
    let first = if params.include_root { 0 } else { 1 };
    let mut root = motion.root_translation().to_vec();
    let mut rot = motion.rotations().to_vec();
    let n = motion.joints();
    for (t, p) in root.iter_mut().enumerate() {
        if params.root_sigma_m > 0.0 {
            *p += gaussian_vec(rng, params.root_sigma_m);
        }
        if sigma == 0.0 {
            continue;
        }
        for q in &mut rot[t * n + first..(t + 1) * n] {
            *q = (*q * DQuat::from_scaled_axis(gaussian_vec(rng, sigma))).normalize();
        }
    }
    Ok(Augmented::new(motion.with_frames(
        motion.fps(),
        root,
        rot,
    )?))
}
