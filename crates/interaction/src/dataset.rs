//! Many variations of one interaction: the training set for a learned model.
//!
//! Each variation draws B's bone scale from a seeded generator: a global factor
//! uniform in `[scale_min, scale_max]` (or, with `grid`, evenly spaced over it,
//! like the paper's 0.75..1.25 in steps of 0.05), times an optional per-bone
//! jitter `1 + U(-bone_jitter, bone_jitter)` shared by the left and right bone
//! of a pair (`LeftArm`/`RightArm`, `LHipJoint`/`RHipJoint`) so bodies stay
//! symmetric. Variation `i` uses its own generator seeded from `(seed, i)`, so
//! the set does not depend on thread scheduling and any one variation can be
//! regenerated alone. Variations run in parallel (rayon).

use std::collections::BTreeMap;

use motion::Motion;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::InteractionError;
use crate::retarget::{RetargetOptions, Retargeted, retarget};
use crate::scale::{BoneScale, MAX_FACTOR, MIN_FACTOR};

/// How to draw the variations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariationSpec {
    pub count: usize,
    pub scale_min: f64,
    pub scale_max: f64,
    /// Relative per-bone jitter on top of the global factor (0 = uniform bodies).
    pub bone_jitter: f64,
    /// Evenly spaced global factors instead of random ones.
    pub grid: bool,
    pub seed: u64,
}

impl VariationSpec {
    pub fn validate(&self) -> Result<(), InteractionError> {
        let bad =
            |field: &'static str, message: String| Err(InteractionError::Option { field, message });
        if self.count == 0 {
            return bad("count", "at least one variation".into());
        }
        let ok = |f: f64| f.is_finite() && (MIN_FACTOR..=MAX_FACTOR).contains(&f);
        if !(ok(self.scale_min) && ok(self.scale_max) && self.scale_min <= self.scale_max) {
            return bad(
                "scale_min",
                format!(
                    "[{}, {}] is not a range within [{MIN_FACTOR}, {MAX_FACTOR}]",
                    self.scale_min, self.scale_max
                ),
            );
        }
        if !(self.bone_jitter.is_finite() && (0.0..0.5).contains(&self.bone_jitter)) {
            return bad(
                "bone_jitter",
                format!("{} is not in [0, 0.5)", self.bone_jitter),
            );
        }
        Ok(())
    }
}

/// One generated variation.
#[derive(Debug, Clone)]
pub struct Variation {
    pub index: usize,
    pub scale: BoneScale,
    pub result: Retargeted,
}

/// The name shared by a left/right pair of bones (`LeftArm` -> `Arm`,
/// `RHipJoint` -> `HipJoint`); other names are their own key.
pub fn symmetric_key(name: &str) -> String {
    let s = name.replace("Left", "").replace("Right", "");
    let b = s.as_bytes();
    if b.len() > 1 && (b[0] == b'L' || b[0] == b'R') && b[1].is_ascii_uppercase() {
        s[1..].to_string()
    } else {
        s
    }
}

/// The bone scale of variation `index` (see the module doc).
pub fn draw_scale(
    spec: &VariationSpec,
    skeleton: &motion::Skeleton,
    index: usize,
) -> Result<BoneScale, InteractionError> {
    let mut rng =
        ChaCha8Rng::seed_from_u64(spec.seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let global = if spec.grid {
        if spec.count == 1 {
            0.5 * (spec.scale_min + spec.scale_max)
        } else {
            spec.scale_min
                + (spec.scale_max - spec.scale_min) * index as f64 / (spec.count - 1) as f64
        }
    } else {
        rng.random_range(spec.scale_min..=spec.scale_max)
    };
    let mut bones = BTreeMap::new();
    if spec.bone_jitter > 0.0 {
        let mut by_key: BTreeMap<String, f64> = BTreeMap::new();
        for joint in skeleton.joints().iter().skip(1) {
            let key = symmetric_key(&joint.name);
            let f = *by_key
                .entry(key)
                .or_insert_with(|| 1.0 + rng.random_range(-spec.bone_jitter..=spec.bone_jitter));
            bones.insert(
                joint.name.clone(),
                (global * f).clamp(MIN_FACTOR, MAX_FACTOR),
            );
        }
    }
    let scale = BoneScale {
        default: global,
        bones,
    };
    scale.validate()?;
    Ok(scale)
}

/// Generate `spec.count` variations of the interaction (`a`, `b`).
pub fn variations(
    a: &Motion,
    b: &Motion,
    spec: &VariationSpec,
    options: &RetargetOptions,
) -> Result<Vec<Variation>, InteractionError> {
    spec.validate()?;
    (0..spec.count)
        .into_par_iter()
        .map(|index| {
            let scale = draw_scale(spec, b.skeleton(), index)?;
            let result = retarget(a, b, &scale, options)?;
            Ok(Variation {
                index,
                scale,
                result,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::tests::cmu_like;

    #[test]
    fn symmetric_names() {
        assert_eq!(symmetric_key("LeftArm"), "Arm");
        assert_eq!(symmetric_key("RightArm"), "Arm");
        assert_eq!(symmetric_key("LHipJoint"), symmetric_key("RHipJoint"));
        assert_eq!(symmetric_key("LowerBack"), "LowerBack");
        assert_eq!(symmetric_key("Head"), "Head");
    }

    #[test]
    fn draws_are_seeded_symmetric_and_in_range() {
        let s = cmu_like();
        let spec = VariationSpec {
            count: 8,
            scale_min: 0.75,
            scale_max: 1.25,
            bone_jitter: 0.05,
            grid: false,
            seed: 7,
        };
        for i in 0..spec.count {
            let x = draw_scale(&spec, &s, i).unwrap();
            assert_eq!(x, draw_scale(&spec, &s, i).unwrap(), "same seed, same draw");
            assert!((0.75..=1.25).contains(&x.default));
            assert_eq!(x.bones["LeftForeArm"], x.bones["RightForeArm"]);
            for f in x.bones.values() {
                assert!((f / x.default - 1.0).abs() <= 0.05 + 1e-12);
            }
        }
        assert_ne!(
            draw_scale(&spec, &s, 0).unwrap(),
            draw_scale(&spec, &s, 1).unwrap()
        );
        let grid = VariationSpec {
            grid: true,
            count: 11,
            bone_jitter: 0.0,
            ..spec
        };
        let g: Vec<f64> = (0..11)
            .map(|i| draw_scale(&grid, &s, i).unwrap().default)
            .collect();
        assert!((g[0] - 0.75).abs() < 1e-12 && (g[10] - 1.25).abs() < 1e-12);
        assert!((g[5] - 1.0).abs() < 1e-12);
        assert!(
            VariationSpec {
                count: 0,
                ..grid.clone()
            }
            .validate()
            .is_err()
        );
        assert!(
            VariationSpec {
                scale_min: 2.0,
                scale_max: 1.0,
                ..grid
            }
            .validate()
            .is_err()
        );
    }
}
