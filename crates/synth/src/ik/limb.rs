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
//!
//! Joint limits (files that have them, i.e. ASF): if the preferred solution
//! puts the hip/shoulder, knee/elbow or (in `World` mode) the effector outside
//! its limits (widened to the source pose's own angles), the knee/elbow is
//! swivelled about the hip-target line, the one free degree of freedom of a
//! two-bone limb, in 5 degree steps up to 120 degrees each way, and the first
//! solution inside the limits is taken; the target is still reached exactly.
//! If none is, the least violating one is clamped to the limits and the
//! knee/elbow re-bent about its hinge towards the target (the target is then
//! missed; the frame is reported as clamped). The knee/elbow rotation is
//! also projected onto the file's dofs (see [`limits::project_to_dofs`]); on
//! HDM05 arms that moves the wrist by well under a millimetre, which shows in
//! the reported error.

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
/// Swivel search when the preferred bend plane breaks a joint limit: steps of
/// 5 degrees up to +-120 degrees about the hip-target line.
const SWIVEL_STEP: f64 = 5.0 * std::f64::consts::PI / 180.0;
const SWIVEL_STEPS: usize = 24;

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
///
/// Stages (see the module docs): the frame's geometry and preferred bend
/// plane, the solution in that plane, the swivel search when it breaks a
/// limit, the clamp and re-bend when no swivel helps.
pub fn solve_frame(
    skeleton: &Skeleton,
    limb: &Limb,
    x: &[Transform],
    pose: &mut [DQuat],
    original: &[DQuat],
    target: DVec3,
    options: SolveOptions,
) -> FrameEdit {
    let geo = Geometry::new(skeleton, limb, x, target);
    let p_upper = skeleton.parent(limb.upper).unwrap_or(0);
    let p_lower = skeleton.parent(limb.lower).unwrap_or(0);
    let solver = Candidates {
        skeleton,
        limb,
        original,
        options,
        geo: &geo,
        r_u: x[limb.upper].rotation,
        r_pu: x[p_upper].rotation,
        r_l: x[limb.lower].rotation,
        r_pl: x[p_lower].rotation,
        r_e: x[limb.effector].rotation,
        effector_local: pose[limb.effector],
    };
    let mut best = solver.attempt(geo.preferred);
    let mut clamped = false;
    if options.respect_limits {
        let worst;
        (worst, best) = solver.swivel(best);
        if worst > 0.0 {
            best = solver.clamp(best);
            clamped = true;
        }
    }
    for (k, &j) in solver.joints().iter().enumerate() {
        pose[j] = best[k];
    }
    FrameEdit {
        out_of_reach: geo.out_of_reach,
        clamped,
    }
}

/// The limb of one frame: hip, knee, effector, the bend normal, the goal.
struct Geometry {
    h: DVec3,
    l1: f64,
    l2: f64,
    thigh: DVec3,
    shin: DVec3,
    /// Reference bend normal of this frame.
    n_ref: DVec3,
    /// Unit direction from the hip to the goal.
    wn: DVec3,
    /// The target pulled into the reachable shell.
    goal: DVec3,
    out_of_reach: bool,
    /// New bend plane: the old normal made orthogonal to the hip-goal line.
    preferred: DVec3,
}

impl Geometry {
    fn new(skeleton: &Skeleton, limb: &Limb, x: &[Transform], target: DVec3) -> Self {
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
        Geometry {
            h,
            l1,
            l2,
            thigh,
            shin,
            n_ref,
            wn,
            goal,
            out_of_reach,
            preferred: n_new.normalize(),
        }
    }
}

/// Candidate solutions of one frame: new local rotations of the upper pivot,
/// lower pivot and effector for a bend-plane normal.
struct Candidates<'a> {
    skeleton: &'a Skeleton,
    limb: &'a Limb,
    original: &'a [DQuat],
    options: SolveOptions,
    geo: &'a Geometry,
    /// World rotations of the upper pivot and its parent, the lower pivot and
    /// its parent, and the effector.
    r_u: DQuat,
    r_pu: DQuat,
    r_l: DQuat,
    r_pl: DQuat,
    r_e: DQuat,
    /// The effector's local rotation in the pose.
    effector_local: DQuat,
}

impl Candidates<'_> {
    fn joints(&self) -> [usize; 3] {
        [self.limb.upper, self.limb.lower, self.limb.effector]
    }

    /// The solution for the bend-plane normal `n`.
    fn attempt(&self, n: DVec3) -> [DQuat; 3] {
        let Geometry {
            h,
            l1,
            l2,
            thigh,
            shin,
            n_ref,
            wn,
            goal,
            ..
        } = *self.geo;
        let (limb, skeleton) = (self.limb, self.skeleton);
        let side = wn.cross(n); // the knee goes to this side of the hip-goal line
        let mut knee = h + (thigh - n * thigh.dot(n));
        if (knee - h).dot(side) < 1e-3 * l1 {
            knee = h + (wn + side).normalize() * l1;
        } else {
            knee = h + (knee - h).normalize() * l1;
        }
        let mut pts = [h, knee, knee + (goal - knee).normalize() * l2];
        Fabrik::default().solve(&mut pts, goal, Some(n));
        let (k1, e1) = (pts[1], pts[2]);
        // Positions -> rotations of the upper and lower pivots.
        let du = frame_map(thigh, n_ref, k1 - h, n);
        let dl = arc(du * shin, e1 - k1);
        let upper = (self.r_pu.inverse() * du * self.r_u).normalize();
        let mut lower = (self.r_pl.inverse() * du.inverse() * dl * du * self.r_l).normalize();
        if self.options.respect_limits
            && let Some(lim) = &skeleton.joint(limb.lower).limits
        {
            lower = limits::project_to_dofs(lower, self.original[limb.lower], lim);
        }
        let effector = match self.options.orientation {
            EffectorOrientation::World => ((dl * du * self.r_l).inverse() * self.r_e).normalize(),
            EffectorOrientation::Local => self.effector_local,
        };
        [upper, lower, effector]
    }

    /// How far a solution lies outside the joint limits (0 inside).
    fn excess(&self, q: &[DQuat; 3]) -> f64 {
        self.joints()
            .iter()
            .zip(q)
            .map(|(&j, &r)| match &self.skeleton.joint(j).limits {
                Some(lim) => limits::excess(r, self.original[j], lim),
                None => 0.0,
            })
            .sum()
    }

    /// `best` (the preferred plane's solution) if it keeps the limits, else
    /// the knee/elbow swivelled about the hip-goal line (the one free degree
    /// of freedom) in growing steps: the first solution inside the limits, or
    /// the least violating one. Returns its excess too.
    fn swivel(&self, best: [DQuat; 3]) -> (f64, [DQuat; 3]) {
        let mut least = (self.excess(&best), best);
        if least.0 > 0.0 {
            let (wn, preferred) = (self.geo.wn, self.geo.preferred);
            'search: for i in 1..=SWIVEL_STEPS {
                let delta = i as f64 * SWIVEL_STEP;
                for a in [delta, -delta] {
                    let q = self.attempt(DQuat::from_axis_angle(wn, a) * preferred);
                    let x = self.excess(&q);
                    if x < least.0 {
                        least = (x, q);
                    }
                    if x == 0.0 {
                        break 'search;
                    }
                }
            }
        }
        least
    }

    /// `best` clamped to the limits, the knee/elbow then re-bent about its
    /// hinge to bring the effector as close to the goal as it gets.
    fn clamp(&self, mut best: [DQuat; 3]) -> [DQuat; 3] {
        let (skeleton, limb, original) = (self.skeleton, self.limb, self.original);
        for (k, &j) in self.joints().iter().enumerate() {
            if let Some(lim) = &skeleton.joint(j).limits {
                best[k] = limits::clamp(best[k], original[j], lim).0;
            }
        }
        let Some(hinge) = limb.hinge_local else {
            return best;
        };
        let Geometry { h, thigh, goal, .. } = *self.geo;
        let d = (self.r_pu * best[0]) * self.r_u.inverse(); // world change of u's subtree
        let k_new = h + d * thigh;
        let frame_pl = d * self.r_pl;
        let a = (frame_pl * hinge).normalize();
        let shin_new = frame_pl * best[1] * skeleton.joint(limb.effector).offset;
        let flat = |v: DVec3| v - a * v.dot(a);
        let (from, to) = (flat(shin_new), flat(goal - k_new));
        if from.length() > 1e-9 && to.length() > 1e-9 {
            let theta = from.cross(to).dot(a).atan2(from.dot(to));
            let bent = DQuat::from_axis_angle(hinge.normalize(), theta) * best[1];
            best[1] = match &skeleton.joint(limb.lower).limits {
                Some(lim) => limits::clamp(bent, original[limb.lower], lim).0,
                None => bent,
            };
        }
        best
    }
}
