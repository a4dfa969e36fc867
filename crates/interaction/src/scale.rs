//! Bone scales: how partner B's body changes, and the naive retarget that applies
//! a scale without looking at the partner (the optimiser's starting point).
//!
//! A scale is one factor for every bone, optionally overridden per bone. A bone
//! is named by the joint it ends at (the joint whose rest offset it is), so
//! `{"RightForeArm": 1.2}` lengthens the upper arm; the end site of a leaf joint
//! (toe tip, head top, finger tip) scales with that joint's own factor.

use std::collections::BTreeMap;
use std::sync::Arc;

use glam::DVec3;
use motion::{Motion, Skeleton};
use serde::{Deserialize, Serialize};

use crate::InteractionError;

/// Smallest and largest factor accepted: beyond these a body is no longer a body.
pub const MIN_FACTOR: f64 = 0.2;
pub const MAX_FACTOR: f64 = 5.0;

/// A bone scale for one body (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoneScale {
    /// Factor of every bone not listed in `bones`.
    pub default: f64,
    /// Factor per bone, by the name of the joint the bone ends at.
    #[serde(default)]
    pub bones: BTreeMap<String, f64>,
}

/// The JSON forms accepted: a number, or `{"default": f, "bones": {...}}`.
#[derive(Deserialize)]
#[serde(untagged)]
enum ScaleJson {
    Uniform(f64),
    PerBone {
        #[serde(default = "one")]
        default: f64,
        #[serde(default)]
        bones: BTreeMap<String, f64>,
    },
}

fn one() -> f64 {
    1.0
}

fn check_factor(what: &str, f: f64) -> Result<(), InteractionError> {
    if f.is_finite() && (MIN_FACTOR..=MAX_FACTOR).contains(&f) {
        Ok(())
    } else {
        Err(InteractionError::Scale(format!(
            "{what}: factor {f} is outside [{MIN_FACTOR}, {MAX_FACTOR}]"
        )))
    }
}

impl BoneScale {
    /// The same factor for every bone.
    pub fn uniform(factor: f64) -> Result<Self, InteractionError> {
        check_factor("uniform scale", factor)?;
        Ok(BoneScale {
            default: factor,
            bones: BTreeMap::new(),
        })
    }

    /// Parse `1.2` or `{"default": 1.0, "bones": {"LeftArm": 1.1}}`.
    pub fn from_json_str(text: &str) -> Result<Self, InteractionError> {
        let parsed: ScaleJson = serde_json::from_str(text).map_err(|e| {
            InteractionError::Scale(format!(
                "{e} (expected a number or {{\"default\": 1.0, \"bones\": {{\"JointName\": 1.1}}}})"
            ))
        })?;
        let scale = match parsed {
            ScaleJson::Uniform(f) => BoneScale {
                default: f,
                bones: BTreeMap::new(),
            },
            ScaleJson::PerBone { default, bones } => BoneScale { default, bones },
        };
        scale.validate()?;
        Ok(scale)
    }

    /// Every factor in range.
    pub fn validate(&self) -> Result<(), InteractionError> {
        check_factor("default", self.default)?;
        for (name, f) in &self.bones {
            check_factor(&format!("bone `{name}`"), *f)?;
        }
        Ok(())
    }

    /// Is this the identity (every factor 1)?
    pub fn is_identity(&self) -> bool {
        self.default == 1.0 && self.bones.values().all(|f| *f == 1.0)
    }

    /// One factor per joint of `skeleton` (the factor of the bone ending there).
    /// Fails on a bone name the skeleton does not have.
    pub fn factors(&self, skeleton: &Skeleton) -> Result<Vec<f64>, InteractionError> {
        self.validate()?;
        let mut out = vec![self.default; skeleton.len()];
        for (name, f) in &self.bones {
            let j = skeleton.find(name).ok_or_else(|| {
                InteractionError::Scale(format!("bone `{name}`: the skeleton has no such joint"))
            })?;
            out[j] = *f;
        }
        Ok(out)
    }
}

/// A copy of `skeleton` with every offset (and end site) multiplied by its
/// joint's factor.
pub fn scale_skeleton(skeleton: &Skeleton, factors: &[f64]) -> Result<Skeleton, InteractionError> {
    if factors.len() != skeleton.len() {
        return Err(InteractionError::Scale(format!(
            "{} factors for {} joints",
            factors.len(),
            skeleton.len()
        )));
    }
    let joints = skeleton
        .joints()
        .iter()
        .zip(factors)
        .map(|(j, f)| {
            let mut j = j.clone();
            j.offset *= *f;
            j.end_site = j.end_site.map(|e| e * *f);
            j
        })
        .collect();
    Ok(Skeleton::new(joints, skeleton.source_unit_m())?)
}

/// Height of the root above the lowest joint or end site in the rest pose.
fn rest_root_height(skeleton: &Skeleton) -> f64 {
    let rest = skeleton.rest_positions();
    let mut lo = 0.0f64;
    for (i, p) in rest.iter().enumerate() {
        lo = lo.min(p.y);
        if let Some(e) = skeleton.joint(i).end_site {
            lo = lo.min(p.y + e.y);
        }
    }
    -lo
}

/// Factor by which the root's height above the ground changes with the scale
/// (the ratio of rest hip heights: legs longer by 10 % lift the hips by 10 %).
pub fn root_height_factor(old: &Skeleton, new: &Skeleton) -> f64 {
    let (h0, h1) = (rest_root_height(old), rest_root_height(new));
    if h0 > 1e-6 { h1 / h0 } else { 1.0 }
}

/// The naive retarget: the scaled skeleton playing the same local rotations,
/// the root's horizontal path unchanged and its height scaled with the legs.
/// Bone lengths are exact; contacts with the partner are not kept.
pub fn naive_retarget(motion: &Motion, factors: &[f64]) -> Result<Motion, InteractionError> {
    let old = motion.skeleton();
    let new = scale_skeleton(old, factors)?;
    let k = root_height_factor(old, &new);
    let root: Vec<DVec3> = motion
        .root_translation()
        .iter()
        .map(|p| DVec3::new(p.x, p.y * k, p.z))
        .collect();
    Ok(Motion::new(
        Arc::new(new),
        motion.fps(),
        root,
        motion.rotations().to_vec(),
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_forms_and_validation() {
        assert_eq!(BoneScale::from_json_str("1.2").unwrap().default, 1.2);
        let s = BoneScale::from_json_str(r#"{"default": 0.9, "bones": {"LeftArm": 1.1}}"#).unwrap();
        assert_eq!(s.bones["LeftArm"], 1.1);
        assert!(BoneScale::from_json_str("-1").is_err());
        assert!(BoneScale::from_json_str(r#"{"bones": {"x": 0}}"#).is_err());
        let e = BoneScale::from_json_str("\"big\"").unwrap_err();
        assert!(e.to_string().contains("expected a number"), "{e}");
        assert!(BoneScale::uniform(f64::NAN).is_err());
        assert!(BoneScale::uniform(1.0).unwrap().is_identity());
    }
}
