//! Left/right mirroring across the body's sagittal plane.
//!
//! The world is reflected by `M = diag(-1, 1, 1)` (axis `x`, the default: the YZ
//! plane, which is the sagittal plane for a clip whose subject faces +-z; use
//! axis `z` for clips facing +-x). Root positions become `M p`. A rotation `R`
//! becomes `M R M`, which for a quaternion `(w, x, y, z)` and an x mirror is
//! `(w, x, -y, -z)`. Paired joints swap their (reflected) local rotations; joints
//! on the centre line keep their own, reflected. Translation tracks are
//! reflected (`M t`) and move to the partner joint like rotations.
//!
//! The skeleton is kept as it is (offsets untouched), so the output is an exact
//! mirror image only if the skeleton is mirror-symmetric: paired joints have
//! mirrored offsets and centre-line joints lie on the mirror plane. Real
//! skeletons are only nearly symmetric (HDM05 legs differ by a few mm), so each
//! world position of the output differs from the mirrored input by at most the
//! accumulated offset asymmetry along its chain. The largest offset asymmetry is
//! reported as `max_asymmetry_m`, and a skeleton whose asymmetry exceeds
//! `tolerance_m` (default 5 cm, i.e. pairs that cannot be right) is an error.

use glam::{DQuat, DVec3};
use motion::{Motion, Skeleton};
use serde::{Deserialize, Serialize};

use crate::names::Pairs;
use crate::{Augmented, SynthError, SynthRng};

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MirrorAxis {
    /// Negate x (mirror across the YZ plane).
    #[default]
    X,
    /// Negate z (mirror across the XY plane).
    Z,
}

impl MirrorAxis {
    fn diag(self) -> DVec3 {
        match self {
            MirrorAxis::X => DVec3::new(-1.0, 1.0, 1.0),
            MirrorAxis::Z => DVec3::new(1.0, 1.0, -1.0),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MirrorParams {
    #[serde(default)]
    pub axis: MirrorAxis,
    /// Explicit (left, right) joint name pairs; replaces the pairs found from names.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pairs: Option<Vec<(String, String)>>,
    /// Largest allowed offset asymmetry of the skeleton, metres.
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
}

fn default_tolerance() -> f64 {
    0.05
}

impl Default for MirrorParams {
    fn default() -> Self {
        MirrorParams {
            axis: MirrorAxis::X,
            pairs: None,
            tolerance_m: default_tolerance(),
        }
    }
}

impl MirrorParams {
    pub fn validate(&self) -> Result<(), SynthError> {
        if !(self.tolerance_m.is_finite() && (0.0..=1.0).contains(&self.tolerance_m)) {
            return Err(SynthError::param("tolerance_m", "must be in [0, 1] metres"));
        }
        Ok(())
    }
}

/// Reflect a rotation: `M R M` for the diagonal reflection `m`.
pub fn reflect_rotation(q: DQuat, m: DVec3) -> DQuat {
    // The axis is a pseudo-vector: it maps to det(M) M axis = -M axis.
    let v = -(m * DVec3::new(q.x, q.y, q.z));
    DQuat::from_xyzw(v.x, v.y, v.z, q.w)
}

/// The mirror partner of every joint, after checking the skeleton is symmetric
/// enough under them. Returns (partner, largest offset asymmetry in metres).
pub fn mirror_map(
    skeleton: &Skeleton,
    params: &MirrorParams,
) -> Result<(Vec<usize>, f64), SynthError> {
    params.validate()?;
    let pairs = match &params.pairs {
        Some(list) => Pairs::from_list(skeleton, list)?,
        None => Pairs::from_names(skeleton),
    };
    if pairs.pair_count() == 0 {
        return Err(SynthError::Skeleton(
            "no left/right joint pairs found from the names; give `pairs` explicitly".into(),
        ));
    }
    let m = params.axis.diag();
    let mut worst = 0.0f64;
    for (j, &k) in pairs.partner.iter().enumerate() {
        let pj = skeleton.parent(j).map(|p| pairs.partner[p]);
        if skeleton.parent(k) != pj {
            return Err(SynthError::Skeleton(format!(
                "mirror pair `{}`/`{}` has parents that are not mirror partners",
                skeleton.joint(j).name,
                skeleton.joint(k).name
            )));
        }
        if j == 0 {
            continue; // the root offset is unused (the root position is per frame)
        }
        let d = (skeleton.joint(k).offset - m * skeleton.joint(j).offset).length();
        if d > params.tolerance_m {
            let what = if j == k {
                "lies off the mirror plane".to_string()
            } else {
                format!("does not mirror `{}`", skeleton.joint(k).name)
            };
            return Err(SynthError::Skeleton(format!(
                "joint `{}` {what} by {:.3} m (tolerance_m = {} m); check the pairs",
                skeleton.joint(j).name,
                d,
                params.tolerance_m
            )));
        }
        worst = worst.max(d);
    }
    Ok((pairs.partner, worst))
}

/// Mirror a motion left/right. Uses no randomness (the rng is accepted so every
/// op has the same shape).
pub fn mirror(
    motion: &Motion,
    params: &MirrorParams,
    _rng: &mut SynthRng,
) -> Result<Augmented, SynthError> {
    let (partner, worst) = mirror_map(motion.skeleton(), params)?;
    let m = params.axis.diag();
    let n = motion.joints();
    let root: Vec<DVec3> = motion.root_translation().iter().map(|p| m * *p).collect();
    let mut rot = vec![DQuat::IDENTITY; motion.rotations().len()];
    for t in 0..motion.frames() {
        let pose = motion.pose(t);
        for j in 0..n {
            rot[t * n + partner[j]] = reflect_rotation(pose[j], m);
        }
    }
    let mut tracks: motion::Tracks = vec![None; motion.tracks().len()];
    for (j, track) in motion.tracks().iter().enumerate() {
        if let Some(track) = track {
            tracks[partner[j]] = Some(track.iter().map(|t| m * *t).collect());
        }
    }
    let mut out = Augmented::new(motion.with_frames_and_tracks(motion.fps(), root, rot, tracks)?);
    out.sampled.insert("max_asymmetry_m".into(), worst.into());
    Ok(out)
}
