//! Skeleton: the joint hierarchy of one subject.
//!
//! Joints are stored in topological order (`parent < index`), joint 0 is the
//! root. Rest offsets are in metres in the parent's frame, with every rest
//! orientation the identity: a zero pose is the file's rest pose (the BVH
//! convention; ASF skeletons are converted to it when read).
//!
//! A skeleton may also carry a static *base* above its root: the joints a file
//! puts above the joint that carries the body's travel when they stand still
//! over the whole clip (a static `joint_Root` above a moving `Hips`). They are
//! not animated and take no part in forward kinematics (the root's translation
//! and rotation are world values); the BVH writer writes them back above the
//! root, so the file keeps its layout (`docs/TRANSLATION_TRACKS.md`).

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::MotionError;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn unit(self) -> DVec3 {
        match self {
            Axis::X => DVec3::X,
            Axis::Y => DVec3::Y,
            Axis::Z => DVec3::Z,
        }
    }

    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// One animation channel of a joint, as laid out in the source file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Channel {
    Position(Axis),
    Rotation(Axis),
}

/// Rotation limits of a joint, as the source file states them (ASF `limits`).
///
/// The limited rotation is `frame.inverse() * local * frame` (ASF: `C^-1 L C`),
/// decomposed into the rotations of `dofs`, applied in order. Axes not listed are
/// locked at zero.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointLimits {
    pub frame: DQuat,
    /// (axis, min, max) in radians, in composition order: outermost first, as
    /// [`crate::rotation::from_channels`] composes them (ASF `dof rx ry rz`,
    /// which applies x first, is stored as z, y, x).
    pub dofs: Vec<(Axis, f64, f64)>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Joint {
    pub name: String,
    pub parent: Option<usize>,
    /// Rest offset from the parent joint, metres, in the parent's frame.
    pub offset: DVec3,
    /// Channels as the source file lays them out (used when writing BVH).
    pub channels: Vec<Channel>,
    /// Tip of a leaf joint (BVH `End Site`, ASF leaf bone end), metres.
    pub end_site: Option<DVec3>,
    pub limits: Option<JointLimits>,
}

impl Joint {
    /// A joint with no file channels, end site or limits: where a skeleton
    /// built in code (tests, fixtures) starts.
    pub fn new(name: &str, parent: Option<usize>, offset: DVec3) -> Joint {
        Joint {
            name: name.into(),
            parent,
            offset,
            channels: Vec::new(),
            end_site: None,
            limits: None,
        }
    }
}

/// A world transform of one joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    pub translation: DVec3,
    pub rotation: DQuat,
}

impl Transform {
    pub const IDENTITY: Transform = Transform {
        translation: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
    };
}

/// A static joint above the root (see the module doc): as the file had it,
/// with the constant translation and rotation it held over the clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaseJoint {
    pub name: String,
    /// The file's `OFFSET`, metres, in the parent's frame.
    pub offset: DVec3,
    /// Its constant local translation, metres (for the first base joint, the
    /// file's root, its world position).
    pub translation: DVec3,
    /// Its constant local rotation (for the first, its world rotation).
    pub rotation: DQuat,
    /// Channels as the source file lays them out.
    pub channels: Vec<Channel>,
    pub end_site: Option<DVec3>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skeleton {
    joints: Vec<Joint>,
    /// Metres per length unit of the source file (for writing back in its units).
    source_unit_m: f64,
    /// Static joints above the root, outermost first (empty for most files).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    base: Vec<BaseJoint>,
}

impl Skeleton {
    /// Validates the hierarchy: at least one joint, joint 0 is the only root,
    /// parents come before children, names are unique and non-empty, offsets finite.
    pub fn new(joints: Vec<Joint>, source_unit_m: f64) -> Result<Self, MotionError> {
        let bad = |m: String| Err(MotionError::InvalidSkeleton(m));
        if joints.is_empty() {
            return bad("no joints".into());
        }
        if !(source_unit_m.is_finite() && source_unit_m > 0.0) {
            return bad(format!(
                "unit scale {source_unit_m} is not a positive number"
            ));
        }
        let mut names = std::collections::HashSet::new();
        for (i, j) in joints.iter().enumerate() {
            if j.name.trim().is_empty() {
                return bad(format!("joint {i} has an empty name"));
            }
            if !names.insert(j.name.as_str()) {
                return bad(format!("joint name `{}` appears twice", j.name));
            }
            match (i, j.parent) {
                (0, None) => {}
                (0, Some(_)) => return bad(format!("root joint `{}` has a parent", j.name)),
                (_, None) => return bad(format!("joint `{}` is a second root", j.name)),
                (_, Some(p)) if p >= i => {
                    return bad(format!("joint `{}` comes before its parent", j.name));
                }
                _ => {}
            }
            let finite = j.offset.is_finite() && j.end_site.is_none_or(|e| e.is_finite());
            if !finite {
                return bad(format!("joint `{}` has a non-finite offset", j.name));
            }
        }
        Ok(Skeleton {
            joints,
            source_unit_m,
            base: Vec::new(),
        })
    }

    /// The same skeleton with `base` above its root (outermost first): the
    /// names must be new and non-empty, the values finite; rotations are
    /// normalised (left as they are when already unit to 1e-12, so a base
    /// read back from JSON is the base written).
    pub fn with_base(mut self, mut base: Vec<BaseJoint>) -> Result<Self, MotionError> {
        let bad = |m: String| Err(MotionError::InvalidSkeleton(m));
        for (i, b) in base.iter_mut().enumerate() {
            if b.name.trim().is_empty() {
                return bad(format!("base joint {i} has an empty name"));
            }
            let finite = b.offset.is_finite()
                && b.translation.is_finite()
                && b.end_site.is_none_or(|e| e.is_finite());
            let n = b.rotation.length();
            if !(finite && n.is_finite() && n > 1e-9) {
                return bad(format!("base joint `{}` has a non-finite value", b.name));
            }
            if (n - 1.0).abs() > 1e-12 {
                b.rotation /= n;
            }
        }
        for (i, b) in base.iter().enumerate() {
            let twice = base[..i].iter().any(|o| o.name == b.name);
            if twice || self.joints.iter().any(|j| j.name == b.name) {
                return bad(format!("joint name `{}` appears twice", b.name));
            }
        }
        self.base = base;
        Ok(self)
    }

    /// Validates a skeleton that did not come from [`Skeleton::new`] (serde
    /// deserialisation bypasses it): the checks of `new` and `with_base`.
    pub fn validated(self) -> Result<Self, MotionError> {
        let Skeleton {
            joints,
            source_unit_m,
            base,
        } = self;
        Skeleton::new(joints, source_unit_m)?.with_base(base)
    }

    /// Static joints above the root, outermost first (see the module doc).
    pub fn base(&self) -> &[BaseJoint] {
        &self.base
    }

    /// World transform of each base joint, outermost first.
    pub fn base_transforms(&self) -> Vec<Transform> {
        let mut out: Vec<Transform> = Vec::with_capacity(self.base.len());
        for b in &self.base {
            out.push(match out.last() {
                None => Transform {
                    translation: b.translation,
                    rotation: b.rotation,
                },
                Some(p) => Transform {
                    translation: p.translation + p.rotation * b.translation,
                    rotation: (p.rotation * b.rotation).normalize(),
                },
            });
        }
        out
    }

    /// The frame the root's local values are written in: the world transform
    /// of the innermost base joint (identity without a base).
    pub fn base_frame(&self) -> Transform {
        self.base_transforms()
            .last()
            .copied()
            .unwrap_or(Transform::IDENTITY)
    }

    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    pub fn joint(&self, index: usize) -> &Joint {
        &self.joints[index]
    }

    pub fn len(&self) -> usize {
        self.joints.len()
    }

    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }

    pub fn source_unit_m(&self) -> f64 {
        self.source_unit_m
    }

    /// Index of the joint with this name (exact match first, then ASCII case-insensitive).
    pub fn find(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name).or_else(|| {
            self.joints
                .iter()
                .position(|j| j.name.eq_ignore_ascii_case(name))
        })
    }

    /// Like [`Skeleton::find`] but an error naming the joint when it is missing.
    pub fn require(&self, name: &str) -> Result<usize, MotionError> {
        self.find(name)
            .ok_or_else(|| MotionError::UnknownJoint(name.to_string()))
    }

    pub fn parent(&self, index: usize) -> Option<usize> {
        self.joints[index].parent
    }

    pub fn children(&self, index: usize) -> impl Iterator<Item = usize> + '_ {
        self.joints
            .iter()
            .enumerate()
            .filter(move |(_, j)| j.parent == Some(index))
            .map(|(i, _)| i)
    }

    /// Joint indices from `from` up to (and including) the root.
    pub fn ancestors(&self, from: usize) -> Vec<usize> {
        let mut chain = vec![from];
        let mut at = from;
        while let Some(p) = self.joints[at].parent {
            chain.push(p);
            at = p;
        }
        chain
    }

    /// Length of the bone from each joint's parent to the joint (0 for the root).
    pub fn bone_lengths(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| {
                if j.parent.is_some() {
                    j.offset.length()
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Forward kinematics for one pose: world transforms of every joint.
    ///
    /// `root` is the world position of the root joint, `pose` one local rotation
    /// per joint. `out` must have one slot per joint.
    pub fn forward(&self, root: DVec3, pose: &[DQuat], out: &mut [Transform]) {
        self.forward_with(root, pose, |j| self.joints[j].offset, out);
    }

    /// Forward kinematics with each joint's local translation from `offset`
    /// (a motion's translation tracks; [`Skeleton::forward`] uses the rest
    /// offsets). `offset` is not asked for the root.
    pub fn forward_with(
        &self,
        root: DVec3,
        pose: &[DQuat],
        offset: impl Fn(usize) -> DVec3,
        out: &mut [Transform],
    ) {
        assert_eq!(pose.len(), self.joints.len(), "pose has wrong joint count");
        assert_eq!(out.len(), self.joints.len(), "output has wrong joint count");
        for (i, joint) in self.joints.iter().enumerate() {
            out[i] = match joint.parent {
                None => Transform {
                    translation: root,
                    rotation: pose[i],
                },
                Some(p) => {
                    let parent = out[p];
                    Transform {
                        translation: parent.translation + parent.rotation * offset(i),
                        rotation: parent.rotation * pose[i],
                    }
                }
            };
        }
    }

    /// World positions of the rest pose with the root at the origin.
    pub fn rest_positions(&self) -> Vec<DVec3> {
        let pose = vec![DQuat::IDENTITY; self.len()];
        let mut out = vec![Transform::IDENTITY; self.len()];
        self.forward(DVec3::ZERO, &pose, &mut out);
        out.into_iter().map(|t| t.translation).collect()
    }

    /// Height of the rest pose (top of the highest joint or end site minus the
    /// lowest), metres. Used to guess units and to scale body models.
    pub fn rest_height(&self) -> f64 {
        let (lo, hi) = self.rest_extent();
        hi - lo
    }

    /// Lowest and highest height (y) of a joint or end site in the rest pose
    /// with the root at the origin, metres.
    pub fn rest_extent(&self) -> (f64, f64) {
        let positions = self.rest_positions();
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for (i, p) in positions.iter().enumerate() {
            let mut ys = vec![p.y];
            if let Some(e) = self.joints[i].end_site {
                ys.push(p.y + e.y);
            }
            for y in ys {
                lo = lo.min(y);
                hi = hi.max(y);
            }
        }
        (lo, hi)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Three joints in a line (root, a, b), unit offsets along y.
    pub(crate) fn chain() -> Skeleton {
        let joint = Joint::new;
        Skeleton::new(
            vec![
                joint("root", None, DVec3::ZERO),
                joint("a", Some(0), DVec3::new(0.0, 1.0, 0.0)),
                joint("b", Some(1), DVec3::new(0.0, 1.0, 0.0)),
            ],
            1.0,
        )
        .unwrap()
    }

    #[test]
    fn forward_kinematics_rotates_children() {
        let s = chain();
        let pose = [
            DQuat::IDENTITY,
            DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
            DQuat::IDENTITY,
        ];
        let mut out = [Transform::IDENTITY; 3];
        s.forward(DVec3::new(1.0, 0.0, 0.0), &pose, &mut out);
        assert!((out[1].translation - DVec3::new(1.0, 1.0, 0.0)).length() < 1e-12);
        assert!((out[2].translation - DVec3::new(0.0, 1.0, 0.0)).length() < 1e-12);
    }

    #[test]
    fn rejects_bad_hierarchies() {
        let mut joints = chain().joints().to_vec();
        joints[2].parent = Some(2);
        assert!(Skeleton::new(joints.clone(), 1.0).is_err());
        joints[2].parent = Some(1);
        joints[2].name = "a".into();
        assert!(Skeleton::new(joints, 1.0).is_err());
        assert!(Skeleton::new(vec![], 1.0).is_err());
    }

    #[test]
    fn find_is_exact_then_case_insensitive() {
        let s = chain();
        assert_eq!(s.find("A"), Some(1));
        assert_eq!(s.find("b"), Some(2));
        assert!(s.require("nope").is_err());
        assert_eq!(s.ancestors(2), vec![2, 1, 0]);
        assert_eq!(s.children(0).collect::<Vec<_>>(), vec![1]);
    }
}
