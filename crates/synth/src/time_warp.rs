//! Time warping: a uniform speed change (MotionAug Sec. 4.3: clips "10% shorter
//! and 10% longer").
//!
//! A speed factor `s` is drawn uniformly from `factor` (default [0.9, 1.1]);
//! `s > 1` plays the clip faster, so it gets fewer frames. The frame rate stays
//! the same: the output has `round((T-1)/s) + 1` frames, spread exactly over the
//! source's first to last frame (so the factor actually applied, reported as
//! `factor`, differs from the drawn one by the rounding). Rotations are slerped,
//! the root position and translation tracks are linearly interpolated.

use glam::{DQuat, DVec3};
use motion::Motion;
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::{Augmented, Range, SynthError, SynthRng};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeWarpParams {
    /// Range of the speed factor (>1 = faster, fewer frames).
    #[serde(default = "default_factor")]
    pub factor: Range,
}

fn default_factor() -> Range {
    Range(0.9, 1.1)
}

impl Default for TimeWarpParams {
    fn default() -> Self {
        TimeWarpParams {
            factor: default_factor(),
        }
    }
}

impl TimeWarpParams {
    pub fn validate(&self) -> Result<(), SynthError> {
        self.factor.validate("factor")?;
        if !(self.factor.0 >= 0.1 && self.factor.1 <= 10.0) {
            return Err(SynthError::param("factor", "must lie within [0.1, 10]"));
        }
        Ok(())
    }
}

/// Resample `motion` at fractional source frame `s` (clamped to the clip).
pub fn sample_at(motion: &Motion, s: f64, root: &mut Vec<DVec3>, rot: &mut Vec<DQuat>) {
    let last = motion.frames() - 1;
    let s = s.clamp(0.0, last as f64);
    let i0 = (s.floor() as usize).min(last);
    let i1 = (i0 + 1).min(last);
    let a = s - i0 as f64;
    let r = motion.root_translation();
    root.push(r[i0].lerp(r[i1], a));
    let (p0, p1) = (motion.pose(i0), motion.pose(i1));
    rot.extend(
        p0.iter()
            .zip(p1)
            .map(|(q0, q1)| q0.slerp(*q1, a).normalize()),
    );
}

/// Change the playback speed by a factor drawn from `params.factor`.
pub fn time_warp(
    motion: &Motion,
    params: &TimeWarpParams,
    rng: &mut SynthRng,
) -> Result<Augmented, SynthError> {
    params.validate()?;
    let drawn = params.factor.0 + (params.factor.1 - params.factor.0) * rng.random::<f64>();
    let t = motion.frames();
    let n = (((t - 1) as f64 / drawn).round() as usize + 1).max(1);
    let step = if n > 1 {
        (t - 1) as f64 / (n - 1) as f64
    } else {
        0.0
    };
    let mut root = Vec::with_capacity(n);
    let mut rot = Vec::with_capacity(n * motion.joints());
    let at: Vec<f64> = (0..n).map(|i| i as f64 * step).collect();
    for &s in &at {
        sample_at(motion, s, &mut root, &mut rot);
    }
    let applied = if n > 1 { step } else { drawn };
    let tracks = motion.tracks_at(&at);
    let mut out = Augmented::new(motion.with_frames_and_tracks(motion.fps(), root, rot, tracks)?);
    out.sampled.insert("factor_drawn".into(), drawn.into());
    out.sampled.insert("factor".into(), applied.into());
    Ok(out)
}
