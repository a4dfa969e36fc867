//! The point layout of a body: which distinct 3-D points a skeleton's pose
//! places, and which distances between them are fixed by the skeleton.
//!
//! The optimiser works on points, not rotations. Joints at zero offset from
//! their parent (CMU's `LHipJoint`, `LowerBack`, `LeftShoulder`, ...) share
//! their parent's point; each end site with a non-zero offset is a point of its
//! own (toe tips for ground contact, head top and finger tips for orientation).
//!
//! A joint whose local rotation never changes in the source clip is *locked*
//! (CMU BVH exports the hip joints as zero-offset joints with constant zero
//! rotation): it keeps that rotation, so everything it carries is rigidly
//! attached to its parent. The *rigid set* of a joint is the list of points its
//! world rotation places, with their vectors in its frame: its children, its
//! end site, and through locked children their children too. All pairwise
//! distances within a rigid set (plus the joint's own point) are fixed: these
//! are the *rods* the optimiser holds at length. Positions satisfying every rod
//! can be turned back into rotations exactly ([`crate::ik`]).

use glam::{DQuat, DVec3};
use motion::{Motion, Skeleton};

/// Offsets shorter than this (metres) count as zero.
pub const ZERO_OFFSET_M: f64 = 1e-9;
/// A joint whose local rotation stays within this angle (radians) of its
/// first-frame value over the whole clip is locked.
pub const LOCKED_ANGLE_RAD: f64 = 1e-6;

/// What a point is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointKind {
    /// The position of this joint (and of its zero-offset descendants).
    Joint(usize),
    /// The end site of this joint.
    EndSite(usize),
}

/// A fixed distance between two points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rod {
    pub a: usize,
    pub b: usize,
    pub length: f64,
}

/// See the module doc.
#[derive(Debug, Clone)]
pub struct Layout {
    /// Point index of each joint's position.
    pub joint_point: Vec<usize>,
    /// Point index of each joint's end site, if it has a non-zero one.
    pub end_point: Vec<Option<usize>>,
    pub points: Vec<PointKind>,
    /// Per joint: keeps its source local rotation.
    pub locked: Vec<bool>,
    /// Per joint: (point, vector from the joint in the joint's frame).
    pub rigid: Vec<Vec<(usize, DVec3)>>,
    pub rods: Vec<Rod>,
}

/// Joints whose local rotation is constant over `motion`. A one-frame clip
/// says nothing about constancy: there only zero-offset joints at the identity
/// rotation (CMU's hip joints) count as locked.
pub fn locked_joints(motion: &Motion) -> Vec<bool> {
    let n = motion.joints();
    let s = motion.skeleton();
    (0..n)
        .map(|j| {
            let first = motion.rotation(0, j);
            if motion.frames() < 2 {
                return s.joint(j).parent.is_some()
                    && s.joint(j).offset.length() <= ZERO_OFFSET_M
                    && motion::rotation::angle_between(first, glam::DQuat::IDENTITY)
                        <= LOCKED_ANGLE_RAD;
            }
            (1..motion.frames()).all(|t| {
                motion::rotation::angle_between(first, motion.rotation(t, j)) <= LOCKED_ANGLE_RAD
            })
        })
        .collect()
}

impl Layout {
    /// The layout of `skeleton` (offsets as given: pass the scaled skeleton for a
    /// scaled body), with `locked` joints keeping `locked_rotation[j]`.
    pub fn new(skeleton: &Skeleton, locked: &[bool], locked_rotation: &[DQuat]) -> Layout {
        let n = skeleton.len();
        let mut points = Vec::new();
        let mut joint_point = vec![0; n];
        let mut end_point = vec![None; n];
        for j in 0..n {
            let joint = skeleton.joint(j);
            joint_point[j] = match joint.parent {
                Some(p) if joint.offset.length() <= ZERO_OFFSET_M => joint_point[p],
                _ => {
                    points.push(PointKind::Joint(j));
                    points.len() - 1
                }
            };
            if joint.end_site.is_some_and(|e| e.length() > ZERO_OFFSET_M) {
                points.push(PointKind::EndSite(j));
                end_point[j] = Some(points.len() - 1);
            }
        }
        let children: Vec<Vec<usize>> = (0..n).map(|j| skeleton.children(j).collect()).collect();
        let mut rigid = vec![Vec::new(); n];
        for (j, set) in rigid.iter_mut().enumerate() {
            collect_rigid(
                skeleton,
                &children,
                locked,
                locked_rotation,
                &joint_point,
                &end_point,
                j,
                DQuat::IDENTITY,
                DVec3::ZERO,
                set,
            );
        }
        let mut rods: Vec<Rod> = Vec::new();
        for (j, set) in rigid.iter().enumerate() {
            let mut all = vec![(joint_point[j], DVec3::ZERO)];
            all.extend(set.iter().copied());
            for (x, &(a, va)) in all.iter().enumerate() {
                for &(b, vb) in &all[x + 1..] {
                    if a == b {
                        continue;
                    }
                    let key = (a.min(b), a.max(b));
                    if rods.iter().any(|r| (r.a, r.b) == key) {
                        continue;
                    }
                    rods.push(Rod {
                        a: key.0,
                        b: key.1,
                        length: (va - vb).length(),
                    });
                }
            }
        }
        Layout {
            joint_point,
            end_point,
            points,
            locked: locked.to_vec(),
            rigid,
            rods,
        }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The joint a point belongs to (the joint itself or the end site's joint).
    pub fn owner(&self, point: usize) -> usize {
        match self.points[point] {
            PointKind::Joint(j) | PointKind::EndSite(j) => j,
        }
    }

    /// Point positions of one frame of `motion` (which must use a skeleton
    /// with this layout's topology).
    pub fn positions(&self, motion: &Motion, frame: usize, out: &mut Vec<DVec3>) {
        let x = motion.world_transforms(frame);
        out.clear();
        out.extend(self.points.iter().map(|p| match *p {
            PointKind::Joint(j) => x[j].translation,
            PointKind::EndSite(j) => {
                let e = motion.skeleton().joint(j).end_site.unwrap_or(DVec3::ZERO);
                x[j].translation + x[j].rotation * e
            }
        }));
    }

    /// Point positions of every frame, row-major `[frame][point]`.
    pub fn all_positions(&self, motion: &Motion) -> Vec<DVec3> {
        let mut out = Vec::with_capacity(motion.frames() * self.len());
        let mut frame = Vec::new();
        for t in 0..motion.frames() {
            self.positions(motion, t, &mut frame);
            out.extend_from_slice(&frame);
        }
        out
    }
}

#[allow(clippy::too_many_arguments)]
fn collect_rigid(
    skeleton: &Skeleton,
    children: &[Vec<usize>],
    locked: &[bool],
    locked_rotation: &[DQuat],
    joint_point: &[usize],
    end_point: &[Option<usize>],
    j: usize,
    rotation: DQuat,
    origin: DVec3,
    out: &mut Vec<(usize, DVec3)>,
) {
    if let (Some(p), Some(e)) = (end_point[j], skeleton.joint(j).end_site) {
        out.push((p, origin + rotation * e));
    }
    for &c in &children[j] {
        let v = origin + rotation * skeleton.joint(c).offset;
        if skeleton.joint(c).offset.length() > ZERO_OFFSET_M {
            out.push((joint_point[c], v));
        }
        if locked[c] {
            collect_rigid(
                skeleton,
                children,
                locked,
                locked_rotation,
                joint_point,
                end_point,
                c,
                rotation * locked_rotation[c],
                v,
                out,
            );
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use motion::Joint;

    /// A small CMU-like body: zero-offset hip joints and shoulders, end sites.
    pub(crate) fn cmu_like() -> Skeleton {
        let j = |name: &str, parent: Option<usize>, o: [f64; 3], end: Option<[f64; 3]>| Joint {
            name: name.into(),
            parent,
            offset: DVec3::from_array(o),
            channels: vec![],
            end_site: end.map(DVec3::from_array),
            limits: None,
        };
        Skeleton::new(
            vec![
                j("Hips", None, [0.0; 3], None),
                j("LHipJoint", Some(0), [0.0; 3], None),
                j("LeftUpLeg", Some(1), [0.09, -0.05, 0.0], None),
                j("LeftLeg", Some(2), [0.0, -0.42, 0.0], None),
                j("LeftFoot", Some(3), [0.0, -0.41, 0.0], None),
                j(
                    "LeftToeBase",
                    Some(4),
                    [0.0, -0.05, 0.12],
                    Some([0.0, 0.0, 0.05]),
                ),
                j("RHipJoint", Some(0), [0.0; 3], None),
                j("RightUpLeg", Some(6), [-0.09, -0.05, 0.0], None),
                j("RightLeg", Some(7), [0.0, -0.42, 0.0], None),
                j("RightFoot", Some(8), [0.0, -0.41, 0.0], None),
                j(
                    "RightToeBase",
                    Some(9),
                    [0.0, -0.05, 0.12],
                    Some([0.0, 0.0, 0.05]),
                ),
                j("LowerBack", Some(0), [0.0; 3], None),
                j("Spine", Some(11), [0.0, 0.12, 0.0], None),
                j("Spine1", Some(12), [0.0, 0.12, 0.0], None),
                j("Neck", Some(13), [0.0; 3], None),
                j("Head", Some(14), [0.0, 0.2, 0.02], Some([0.0, 0.15, 0.0])),
                j("LeftShoulder", Some(13), [0.0; 3], None),
                j("LeftArm", Some(16), [0.17, 0.03, 0.0], None),
                j("LeftForeArm", Some(17), [0.28, 0.0, 0.0], None),
                j("LeftHand", Some(18), [0.25, 0.0, 0.0], None),
                j("LeftFingerBase", Some(19), [0.0; 3], None),
                j(
                    "LeftHandIndex1",
                    Some(20),
                    [0.05, 0.0, 0.0],
                    Some([0.04, 0.0, 0.0]),
                ),
                j("LThumb", Some(19), [0.0; 3], Some([0.03, 0.0, 0.03])),
                j("RightShoulder", Some(13), [0.0; 3], None),
                j("RightArm", Some(23), [-0.17, 0.03, 0.0], None),
                j("RightForeArm", Some(24), [-0.28, 0.0, 0.0], None),
                j("RightHand", Some(25), [-0.25, 0.0, 0.0], None),
                j("RightFingerBase", Some(26), [0.0; 3], None),
                j(
                    "RightHandIndex1",
                    Some(27),
                    [-0.05, 0.0, 0.0],
                    Some([-0.04, 0.0, 0.0]),
                ),
                j("RThumb", Some(26), [0.0; 3], Some([-0.03, 0.0, 0.03])),
            ],
            1.0,
        )
        .unwrap()
    }

    /// CMU locks: the hip joints and finger bases never rotate.
    pub(crate) fn cmu_locks(s: &Skeleton) -> Vec<bool> {
        (0..s.len())
            .map(|j| {
                let n = &s.joint(j).name;
                n.contains("HipJoint") || n.contains("FingerBase") || n.contains("Thumb")
            })
            .collect()
    }

    #[test]
    fn zero_offsets_share_points_and_locks_make_rigid_sets() {
        let s = cmu_like();
        let locks = cmu_locks(&s);
        let l = Layout::new(&s, &locks, &vec![DQuat::IDENTITY; s.len()]);
        // 30 joints, 10 at zero offset -> 20 joint points, plus 7 end sites.
        assert_eq!(l.len(), 27);
        assert_eq!(l.joint_point[1], l.joint_point[0]);
        // Hips places both hips through the locked hip joints.
        let hips: Vec<usize> = l.rigid[0].iter().map(|p| p.0).collect();
        assert_eq!(hips, vec![l.joint_point[2], l.joint_point[7]]);
        // The left hand places its finger and thumb tip.
        assert_eq!(l.rigid[19].len(), 2, "{:?}", l.rigid[19]);
        // Rods: the hip triangle is rigid.
        let (a, b) = (l.joint_point[2], l.joint_point[7]);
        let rod = l
            .rods
            .iter()
            .find(|r| (r.a, r.b) == (a.min(b), a.max(b)))
            .unwrap();
        assert!((rod.length - 0.18).abs() < 1e-12);
        // Every rod length matches the rest pose.
        let mut rest = Vec::new();
        let m = Motion::new(
            std::sync::Arc::new(s.clone()),
            30.0,
            vec![DVec3::ZERO],
            vec![DQuat::IDENTITY; s.len()],
        )
        .unwrap();
        l.positions(&m, 0, &mut rest);
        for r in &l.rods {
            assert!(((rest[r.a] - rest[r.b]).length() - r.length).abs() < 1e-12);
        }
    }
}
