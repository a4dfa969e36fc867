//! Occlusion masks after V-DMGNN-GAN (Sec. 6.2 of that paper).
//!
//! * `lower_body`: structural occlusion. Every joint of the leg chains (below
//!   the pelvis, see [`crate::names::lower_body`]) is occluded in every frame.
//! * `random_joints`: each joint of each frame is visible with probability `p`
//!   (Bernoulli, i.i.d. per frame and joint; the paper uses p = 0.8 and draws per
//!   joint angle, we draw per joint so a joint is either seen or not). The root
//!   is never masked unless `include_root` is set.
//!
//! The paper multiplies the pose by the mask (an occluded joint angle becomes 0)
//! and then injects Gaussian noise. For rotations that is `fill = "zero_noise"`
//! (default): an occluded local rotation becomes `exp(e)`, the rest pose plus
//! noise, `e ~ N(0, sigma^2 I3)`. `fill = "original_noise"` keeps the value and
//! adds the noise instead (`q * exp(e)`). Root positions are never masked.
//!
//! The mask is returned beside the motion, `[frame][joint]`, `true` = visible.

use glam::DQuat;
use motion::Motion;
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::noise::gaussian_vec;
use crate::{Augmented, SynthError, SynthRng, names};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskMode {
    LowerBody,
    RandomJoints,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskFill {
    /// Occluded rotation = rest pose + Gaussian noise (the paper).
    #[default]
    ZeroNoise,
    /// Occluded rotation = original + Gaussian noise.
    OriginalNoise,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaskParams {
    pub mode: MaskMode,
    /// Visibility probability per joint and frame (`random_joints` only; default 0.8).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p: Option<f64>,
    /// Standard deviation of the noise in occluded rotations, degrees.
    #[serde(default = "default_sigma")]
    pub sigma_deg: f64,
    #[serde(default)]
    pub fill: MaskFill,
    /// Let `random_joints` mask the root orientation too.
    #[serde(default)]
    pub include_root: bool,
}

fn default_sigma() -> f64 {
    5.0
}

pub const DEFAULT_VISIBILITY: f64 = 0.8;

impl MaskParams {
    pub fn lower_body() -> Self {
        MaskParams {
            mode: MaskMode::LowerBody,
            p: None,
            sigma_deg: default_sigma(),
            fill: MaskFill::ZeroNoise,
            include_root: false,
        }
    }

    pub fn random_joints(p: f64) -> Self {
        MaskParams {
            mode: MaskMode::RandomJoints,
            p: Some(p),
            ..Self::lower_body()
        }
    }

    pub fn validate(&self) -> Result<(), SynthError> {
        match (self.mode, self.p) {
            (MaskMode::LowerBody, Some(_)) => {
                return Err(SynthError::param(
                    "p",
                    "applies to mode = \"random_joints\" only (lower_body masks every leg joint in every frame)",
                ));
            }
            (MaskMode::RandomJoints, Some(p)) if !(0.0..=1.0).contains(&p) => {
                return Err(SynthError::param("p", "must be a probability in [0, 1]"));
            }
            _ => {}
        }
        if self.include_root && self.mode == MaskMode::LowerBody {
            return Err(SynthError::param(
                "include_root",
                "applies to mode = \"random_joints\" only",
            ));
        }
        if !(self.sigma_deg.is_finite() && (0.0..=180.0).contains(&self.sigma_deg)) {
            return Err(SynthError::param(
                "sigma_deg",
                "must be in [0, 180] degrees",
            ));
        }
        Ok(())
    }
}

/// Visibility of every joint in every frame, row-major `[frame][joint]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mask {
    pub frames: usize,
    pub joints: usize,
    /// `true` = visible, `false` = occluded.
    pub visible: Vec<bool>,
}

impl Mask {
    pub fn is_visible(&self, frame: usize, joint: usize) -> bool {
        self.visible[frame * self.joints + joint]
    }

    /// Fraction of (frame, joint) entries that are visible.
    pub fn visible_fraction(&self) -> f64 {
        self.visible.iter().filter(|v| **v).count() as f64 / self.visible.len().max(1) as f64
    }

    /// The mask as rows, one per frame.
    pub fn rows(&self) -> Vec<Vec<bool>> {
        self.visible
            .chunks(self.joints)
            .map(|r| r.to_vec())
            .collect()
    }
}

/// Occlude joints and replace their rotations with noise.
pub fn mask(
    motion: &Motion,
    params: &MaskParams,
    rng: &mut SynthRng,
) -> Result<Augmented, SynthError> {
    params.validate()?;
    let (t_n, j_n) = (motion.frames(), motion.joints());
    let mut visible = vec![true; t_n * j_n];
    match params.mode {
        MaskMode::LowerBody => {
            let legs = names::lower_body(motion.skeleton())?;
            for t in 0..t_n {
                for &j in &legs {
                    visible[t * j_n + j] = false;
                }
            }
        }
        MaskMode::RandomJoints => {
            let p = params.p.unwrap_or(DEFAULT_VISIBILITY);
            let first = if params.include_root { 0 } else { 1 };
            for t in 0..t_n {
                for j in first..j_n {
                    visible[t * j_n + j] = rng.random::<f64>() < p;
                }
            }
        }
    }
    let sigma = params.sigma_deg.to_radians();
    let mut rot = motion.rotations().to_vec();
    for (q, _) in rot.iter_mut().zip(&visible).filter(|(_, v)| !**v) {
        let e = DQuat::from_scaled_axis(gaussian_vec(rng, sigma));
        *q = match params.fill {
            MaskFill::ZeroNoise => e,
            MaskFill::OriginalNoise => (*q * e).normalize(),
        };
    }
    let mut out = Augmented::new(motion.with_frames(
        motion.fps(),
        motion.root_translation().to_vec(),
        rot,
    )?);
    let m = Mask {
        frames: t_n,
        joints: j_n,
        visible,
    };
    out.sampled
        .insert("visible_fraction".into(), m.visible_fraction().into());
    out.mask = Some(m);
    Ok(out)
}
