//! A two-bone limb (hip-knee-ankle or shoulder-elbow-wrist) found in a skeleton,
//! and the per-frame IK edit that moves its end to a target.
//!
//! The chain is found from the effector upwards: the effector `e` (ankle/wrist),
//! the lower pivot `l = parent(e)` (at the knee/elbow), and the upper pivot `u`
//! (at the hip/shoulder): the parent of the first joint at or above `l` with a
//! non-zero bone. Zero-length joints between (ASF `lhipjoint`-like bones of zero
//! length, BVH `LHipJoint` with a zero offset) ride along rigidly.
//!
//! Per frame: FABRIK moves the knee/elbow and the effector in positions, with
//! the bend plane kept: the new plane contains the hip-target line and is as
//! close as possible to the old plane (its normal is the old normal projected),
//! and the knee stays on the same side, so a knee keeps bending forward. The
//! positions are then turned back into rotations of `u` and `l` only, so the
//! skeleton's offsets (bone lengths) are untouched: `u` gets the rotation that
//! maps the old (thigh, plane normal) frame onto the new one and `l` the shortest
//! arc that lays the shin onto its new direction, which is a rotation about the
//! plane normal: a hinge knee (ASF one-dof `tibia`) stays a pure hinge.
//! For a straight limb (no plane) the normal comes from the knee's hinge axis:
//! the file's one-dof axis if it has one, else the clip's average bend normal.

use glam::{DMat3, DQuat, DVec3};
use motion::Skeleton;
use motion::skeleton::Transform;

use super::fabrik::Fabrik;
use super::limits;
use crate::SynthError;

/// What happens to the effector's own rotation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectorOrientation {
    /// Keep the effector's local rotation: the foot/hand follows the shin/forearm.
    #[default]
    Local,
    /// Keep the effector's world orientation (the foot keeps pointing where it did).
    World,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Limb {
    pub effector: usize,
    pub lower: usize,
    pub upper: usize,
    /// Knee hinge axis in the frame of `parent(lower)`, oriented like the clip's
    /// bend normal (thigh x shin), if known.
    pub hinge_local: Option<DVec3>,
}

const EPS_LEN: f64 = 1e-6;

impl Limb {
    /// Find the limb ending at `effector`.
    pub fn new(skeleton: &Skeleton, effector: usize) -> Result<Limb, SynthError> {
        let name = |j: usize| skeleton.joint(j).name.clone();
        if skeleton.joint(effector).offset.length() < EPS_LEN {
            return Err(SynthError::Skeleton(format!(
                "effector `{}` coincides with its parent; choose the joint at the ankle/wrist",
                name(effector)
            )));
        }
        let lower = skeleton.parent(effector).ok_or_else(|| {
            SynthError::Skeleton(format!("effector `{}` is the root", name(effector)))
        })?;
        let mut k = lower;
        while skeleton.joint(k).offset.length() < EPS_LEN {
            k = skeleton.parent(k).ok_or_else(|| {
                SynthError::Skeleton(format!("no upper bone above `{}`", name(effector)))
            })?;
        }
        let upper = skeleton.parent(k).filter(|&u| u != 0).ok_or_else(|| {
            SynthError::Skeleton(format!(
                "the limb of `{}` hangs directly off the root; IK needs a hip/shoulder joint",
                name(effector)
            ))
        })?;
        Ok(Limb {
            effector,
            lower,
            upper,
            hinge_local: None,
        })
    }

    /// Lengths of the upper and lower bone.
    pub fn lengths(&self, x: &[Transform]) -> (f64, f64) {
        let (h, k, e) = self.points(x);
        ((k - h).length(), (e - k).length())
    }

    fn points(&self, x: &[Transform]) -> (DVec3, DVec3, DVec3) {
        (
            x[self.upper].translation,
            x[self.lower].translation,
            x[self.effector].translation,
        )
    }

    /// Estimate the hinge axis from the file's limits or the clip's poses.
    pub fn estimate_hinge(&mut self, skeleton: &Skeleton, frames: &[Vec<Transform>]) {
        let p = skeleton.parent(self.lower).unwrap_or(0);
        let mut sum = DVec3::ZERO;
        for x in frames {
            let (h, k, e) = self.points(x);
            sum += x[p].rotation.inverse() * (k - h).cross(e - k);
        }
        let from_data = (sum.length() > 1e-9).then(|| sum.normalize());
        let from_limits = skeleton
            .joint(self.lower)
            .limits
            .as_ref()
            .and_then(limits::hinge_axis);
        self.hinge_local = match (from_limits, from_data) {
            (Some(a), Some(d)) => Some(if a.dot(d) < 0.0 { -a } else { a }),
            (a, d) => a.or(d),
        };
    }
}

/// How a frame is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SolveOptions {
    pub orientation: EffectorOrientation,
    /// Clamp the edited joints to the file's limits (widened by the source pose).
    pub respect_limits: bool,
}

/// Outcome of one frame's edit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameEdit {
    /// The target was out of the limb's reach and was pulled in.
    pub out_of_reach: bool,
    /// A joint limit clamped the solution.
    pub clamped: bool,
}

fn frame_from(a: DVec3, b: DVec3) -> DMat3 {
    let a = a.normalize();
    let b = (b - a * a.dot(b)).normalize();
    DMat3::from_cols(a, b, a.cross(b))
}

/// Rotation taking direction `a0` to `a1` and (the part of) `b0` orthogonal to
/// `a0` to (the part of) `b1` orthogonal to `a1`.
fn frame_map(a0: DVec3, b0: DVec3, a1: DVec3, b1: DVec3) -> DQuat {
    let m = frame_from(a1, b1) * frame_from(a0, b0).transpose();
    DQuat::from_mat3(&m).normalize()
}

fn arc(from: DVec3, to: DVec3) -> DQuat {
    DQuat::from_rotation_arc(from.normalize(), to.normalize())
}

/// Solve one frame. `x` are the frame's world transforms (from FK of `pose`),
/// `pose` its local rotations, edited in place. `original` are the source local
/// rotations (for widening limits).
pub fn solve_frame(
    skeleton: &Skeleton,
    limb: &Limb,
    x: &[Transform],
    pose: &mut [DQuat],
    original: &[DQuat],
    target: DVec3,
    options: SolveOptions,
) -> FrameEdit {
    let SolveOptions {
        orientation,
        respect_limits,
    } = options;
    let (h, k, e) = limb.points(x);
    let (l1, l2) = ((k - h).length(), (e - k).length());
    let thigh = k - h;
    let shin = e - k;
    // Reference bend normal of this frame.
    let m = thigh.cross(shin);
    let p_lower = skeleton.parent(limb.lower).unwrap_or(0);
    let n_ref = if m.length() > 1e-6 * l1 * l2 {
        m.normalize()
    } else {
        let axis = limb
            .hinge_local
            .map(|a| x[p_lower].rotation * a)
            .unwrap_or_else(|| thigh.any_orthonormal_vector());
        let proj = axis - thigh * (axis.dot(thigh) / (l1 * l1));
        if proj.length() > 1e-9 {
            proj.normalize()
        } else {
            thigh.any_orthonormal_vector()
        }
    };
    // Pull the target into the reachable shell.
    let mut w = target - h;
    let d = w.length();
    let (lo, hi) = ((l1 - l2).abs(), l1 + l2);
    let out_of_reach = d > hi || d < lo;
    if d < 1e-12 {
        w = thigh;
    }
    let wn = w.normalize();
    let goal = h + wn * d.clamp(lo, hi);
    // New bend plane: the old normal made orthogonal to the hip-goal line.
    let mut n_new = n_ref - wn * n_ref.dot(wn);
    if n_new.length() < 1e-9 {
        n_new = wn.cross(thigh);
        if n_new.length() < 1e-9 {
            n_new = wn.any_orthonormal_vector();
        }
    }
    let n_new = n_new.normalize();
    let side = wn.cross(n_new); // the knee goes to this side of the hip-goal line
    let mut knee = h + (thigh - n_new * thigh.dot(n_new));
    if (knee - h).dot(side) < 1e-3 * l1 {
        knee = h + (wn + side).normalize() * l1;
    } else {
        knee = h + (knee - h).normalize() * l1;
    }
    let mut pts = [h, knee, knee + (goal - knee).normalize() * l2];
    Fabrik::default().solve(&mut pts, goal, Some(n_new));
    let (k1, e1) = (pts[1], pts[2]);

    // Positions -> rotations of the upper and lower pivots.
    let du = frame_map(thigh, n_ref, k1 - h, n_new);
    let p_upper = skeleton.parent(limb.upper).unwrap_or(0);
    let r_u = x[limb.upper].rotation;
    let r_pu = x[p_upper].rotation;
    let dl = arc(du * shin, e1 - k1);
    let r_l = x[limb.lower].rotation;
    let r_pl = x[p_lower].rotation;
    let r_e = x[limb.effector].rotation;
    pose[limb.upper] = (r_pu.inverse() * du * r_u).normalize();
    pose[limb.lower] = (r_pl.inverse() * du.inverse() * dl * du * r_l).normalize();
    if orientation == EffectorOrientation::World {
        let r_l_new = dl * du * r_l;
        pose[limb.effector] = (r_l_new.inverse() * r_e).normalize();
    }
    let mut clamped = false;
    if respect_limits {
        for j in [limb.upper, limb.lower, limb.effector] {
            if let Some(lim) = &skeleton.joint(j).limits {
                let (q, c) = limits::clamp(pose[j], original[j], lim);
                pose[j] = q;
                clamped |= c;
            }
        }
    }
    FrameEdit {
        out_of_reach,
        clamped,
    }
}
