//! Character builder: turns any mocap [`Skeleton`] into a simulated humanoid.
//!
//! Files differ in joint names, joint counts and in where they put zero-length
//! helper joints, so the builder finds the body parts from the skeleton's
//! *geometry* (rest pose, root at the origin, y up) and uses names only to tell
//! left from right:
//!
//! 1. **Legs**: the lowest leaf tip of the rest pose is one foot; the other
//!    foot is the lowest leaf tip (in the lowest quarter of the body) whose
//!    common ancestor with the first lies above the knees, 40 % of the height
//!    over the floor (toes of the same foot meet at the foot, far lower).
//!    `P` = their common ancestor.
//! 2. **Arms**: among the remaining leaves, the one farthest from the root along
//!    the bones is a hand; the other hand is the farthest leaf whose branch (from
//!    the common ancestor to the tip) is longer than a quarter of the height
//!    (fingers of the same hand branch off at the hand). `C` = their common
//!    ancestor (the chest).
//! 3. **Head**: the highest remaining leaf tip; the torso path runs from the root
//!    through `C` to it.
//! 4. Along a limb chain (joints after `P` or `C`), each joint's *segment* is the
//!    vector to the next joint of the chain (or its end site). The upper limb is
//!    the joint whose segment plus the next non-zero segment is longest (so a
//!    clavicle or a zero-length `LHipJoint` never wins), the lower limb is the
//!    next non-zero segment, the foot/hand is the next joint with a non-zero
//!    segment after it (or the joint at the wrist if there is none).
//! 5. **Pelvis** = common ancestor of `P` and `C` (the file root in every file
//!    seen). **Spine** = the first torso joint after the pelvis with a non-zero
//!    segment, **Chest** = the last one up to `C` (middle ones are merged into
//!    Spine, so at most the reference's two spine bodies), **Neck** = the first
//!    torso joint after `C` with a non-zero segment; the head is merged into it
//!    (as in the reference, whose "Neck" body is the head sphere).
//!
//! Every file joint is either the *driver* of one simulated body (its world
//! rotation is the body's orientation, its position the body's origin) or
//! *merged* into the body of its nearest driver ancestor: clavicles, zero-length
//! helper joints, toes, fingers, thumbs, the head, extra spine segments. A merged
//! joint keeps the reference's local rotation when a simulated pose is written
//! back to the file skeleton ([`JointMapping`]). Joints above the pelvis driver
//! (a ground "reference" root, if any) are merged into the pelvis.
//!
//! Shapes follow the reference (MotionAug): spheres for pelvis, spine, chest,
//! head and hands, capsules for upper/lower limbs, boxes for the feet (heel to
//! toe tip, ankle height, sized from the file's foot and toe joints). Masses are
//! the reference 45 kg split (optionally scaled to a given total, gains scaled
//! with it). Bodies that are adjacent in the tree or already overlap in the rest
//! pose never collide with each other.
//!
//! [`CharacterSpec::build`] runs steps 1 to 5 in `parts` (one method per
//! step) and then the bodies, in `bodies`: drivers, joint mapping, masses,
//! shapes, limits, collision exclusions.

use std::fmt;
use std::sync::Arc;

use glam::{Mat3, Quat, Vec3};
use motion::{Motion, Skeleton, Transform};
use rapier3d::parry;
use serde::Serialize;

use crate::PhysicsError;

mod bodies;
mod parts;

use parts::RestPose;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum Side {
    Left,
    Right,
}

/// What a simulated body is, which fixes its mass, gains and shape kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum Role {
    Pelvis,
    Spine,
    Chest,
    Neck,
    UpperLeg(Side),
    LowerLeg(Side),
    Foot(Side),
    UpperArm(Side),
    ForeArm(Side),
    Hand(Side),
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let side = |s: &Side| match s {
            Side::Left => "Left",
            Side::Right => "Right",
        };
        match self {
            Role::Pelvis => write!(f, "Hips"),
            Role::Spine => write!(f, "Spine"),
            Role::Chest => write!(f, "Spine1"),
            Role::Neck => write!(f, "Neck"),
            Role::UpperLeg(s) => write!(f, "{}UpLeg", side(s)),
            Role::LowerLeg(s) => write!(f, "{}Leg", side(s)),
            Role::Foot(s) => write!(f, "{}Foot", side(s)),
            Role::UpperArm(s) => write!(f, "{}Arm", side(s)),
            Role::ForeArm(s) => write!(f, "{}ForeArm", side(s)),
            Role::Hand(s) => write!(f, "{}Hand", side(s)),
        }
    }
}

/// Reference body model of one role: (mass kg, kp, kd, torque limit N m, pose-reward weight).
fn reference_model(role: Role) -> (f32, f32, f32, f32, f32) {
    match role {
        Role::Pelvis => (6.0, 0.0, 0.0, 0.0, 1.0),
        Role::Spine | Role::Chest => (7.0, 1000.0, 100.0, 300.0, 0.5),
        Role::Neck => (2.0, 100.0, 10.0, 75.0, 0.3),
        Role::UpperLeg(_) => (4.5, 500.0, 50.0, 300.0, 0.5),
        Role::LowerLeg(_) => (3.0, 500.0, 50.0, 225.0, 0.3),
        Role::Foot(_) => (1.0, 400.0, 40.0, 135.0, 0.2),
        Role::UpperArm(_) => (1.5, 400.0, 40.0, 150.0, 0.3),
        Role::ForeArm(_) => (1.0, 300.0, 30.0, 90.0, 0.2),
        // The reference leaves the hand passive; a weak PD keeps it from flapping.
        Role::Hand(_) => (0.5, 50.0, 5.0, 30.0, 0.1),
    }
}

/// A collision shape in the body's frame (metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Shape {
    Sphere {
        center: Vec3,
        radius: f32,
    },
    Capsule {
        a: Vec3,
        b: Vec3,
        radius: f32,
    },
    Box {
        center: Vec3,
        half_extents: Vec3,
        rotation: Quat,
    },
}

impl Shape {
    pub fn center(&self) -> Vec3 {
        match *self {
            Shape::Sphere { center, .. } | Shape::Box { center, .. } => center,
            Shape::Capsule { a, b, .. } => 0.5 * (a + b),
        }
    }

    /// Lowest point (world y) of the shape when its body sits at `pos`, `rot`.
    pub fn lowest_y(&self, pos: Vec3, rot: Quat) -> f32 {
        match *self {
            Shape::Sphere { center, radius } => (pos + rot * center).y - radius,
            Shape::Capsule { a, b, radius } => (pos + rot * a).y.min((pos + rot * b).y) - radius,
            Shape::Box {
                center,
                half_extents,
                rotation,
            } => {
                let r = rot * rotation;
                let c = pos + rot * center;
                let m = Mat3::from_quat(r);
                // Lowest corner: subtract |projection| of each half axis on y.
                c.y - (m.x_axis.y.abs() * half_extents.x
                    + m.y_axis.y.abs() * half_extents.y
                    + m.z_axis.y.abs() * half_extents.z)
            }
        }
    }

    /// The shape as parry sees it (for collider creation and rest-overlap tests).
    pub(crate) fn to_parry(self) -> (parry::shape::SharedShape, parry::math::Pose) {
        use parry::math::Pose;
        use parry::shape::SharedShape;
        match self {
            Shape::Sphere { center, radius } => {
                (SharedShape::ball(radius), Pose::from_translation(center))
            }
            Shape::Capsule { a, b, radius } => (SharedShape::capsule(a, b, radius), Pose::IDENTITY),
            Shape::Box {
                center,
                half_extents,
                rotation,
            } => (
                SharedShape::cuboid(half_extents.x, half_extents.y, half_extents.z),
                Pose::from_parts(center, rotation),
            ),
        }
    }
}

/// A one-axis ("hinge-like") limit: rotation about `axis` (parent frame) kept in
/// `[lo, hi]`, rotation about the other axes within `swing` radians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HingeLimit {
    pub axis: Vec3,
    pub lo: f32,
    pub hi: f32,
    pub swing: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BodySpec {
    /// Role name in the reference model's naming (e.g. `LeftUpLeg`).
    pub name: String,
    pub role: Role,
    /// File joint whose world frame is this body's frame.
    pub driver: usize,
    /// Parent body (None for the pelvis).
    pub parent: Option<usize>,
    /// Joint position (= this body's origin) in the parent body's frame.
    pub anchor_in_parent: Vec3,
    /// Rest-pose world position of the body origin (root at the origin).
    pub rest_origin: Vec3,
    pub shape: Shape,
    pub mass: f32,
    pub kp: f32,
    pub kd: f32,
    pub torque_limit: f32,
    /// Normalised pose-reward weight.
    pub weight: f32,
    pub hinge: Option<HingeLimit>,
    /// Centre of the shape (= centre of mass) in the body frame.
    pub com_local: Vec3,
}

/// How one file joint is simulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum JointMapping {
    /// The joint drives this body.
    Body(usize),
    /// The joint is part of this body and keeps the reference's local rotation.
    MergedInto(usize),
}

/// The simulated character of one skeleton.
#[derive(Debug, Clone)]
pub struct CharacterSpec {
    pub skeleton: Arc<Skeleton>,
    pub bodies: Vec<BodySpec>,
    /// One entry per file joint.
    pub joint_map: Vec<JointMapping>,
    /// Rest-pose facing direction (horizontal unit vector).
    pub forward: Vec3,
    pub total_mass: f32,
    /// Pairs of bodies that must not collide (adjacent or overlapping at rest).
    pub no_collision: Vec<(usize, usize)>,
    /// Bodies allowed to touch the ground (the feet).
    pub feet: Vec<usize>,
    /// End effectors for the reward: feet and hands (or forearms without hands).
    pub end_effectors: Vec<usize>,
}

/// Options of the character builder.
#[derive(Debug, Clone, PartialEq)]
pub struct CharacterOptions {
    /// Total mass in kg; `None` = the reference 45 kg. Gains scale with mass.
    pub total_mass_kg: Option<f32>,
    /// Ground / body friction coefficient.
    pub friction: f32,
    /// Build each foot box in the frame of the standing foot, so its sole is
    /// flat on the ground in the clip's own stance frames (see
    /// [`CharacterSpec::calibrate_feet`]). On by default: with the rest-pose
    /// boxes the bundled HDM05 kick's stance foot stands on a box corner (heel
    /// 18 cm up) and no planted frame is flat; measured over 14 HDM05 clips of
    /// 7 classes after 10 PPO iterations (`motionaug bench correction`, see
    /// crates/correct), planted frames on the sole went from 5-48 % to
    /// 27-82 % per class, R_norm up on 4 classes. Off = the rest-pose boxes.
    pub calibrate_feet: bool,
}

impl Default for CharacterOptions {
    fn default() -> Self {
        CharacterOptions {
            total_mass_kg: None,
            friction: 0.9,
            calibrate_feet: true,
        }
    }
}

/// What [`CharacterSpec::calibrate_feet`] did to one foot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FootCalibration {
    pub body: usize,
    /// Frames used (the foot planted).
    pub stance_frames: usize,
    /// Rotation applied to the box, radians.
    pub tilt_rad: f32,
}

/// One line of the mapping report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MappingLine {
    pub file_joint: String,
    pub body: String,
    pub merged: bool,
}

impl CharacterSpec {
    /// The heel and toe of foot body `b`'s sole, in the body frame: the back
    /// and front midpoints of its box's bottom face. A foot stands on its sole
    /// when both are on the floor; standing on the heel edge (toes up) or on a
    /// rolled box puts one of them, or both, above it. `None` when `b` is not
    /// a box.
    pub fn sole_points(&self, b: usize) -> Option<[Vec3; 2]> {
        match self.bodies.get(b)?.shape {
            Shape::Box {
                center,
                half_extents: h,
                rotation,
            } => Some([
                center + rotation * Vec3::new(0.0, -h.y, -h.z),
                center + rotation * Vec3::new(0.0, -h.y, h.z),
            ]),
            _ => None,
        }
    }

    /// Rebuild each foot box in the frame of the standing foot, so that its
    /// sole lies flat on the ground when the foot is planted in `motion`.
    ///
    /// The boxes are built from the rest pose, whose foot is rarely the
    /// standing foot: HDM05's rest foot points 22 degrees down, its planted
    /// feet about 31 degrees, and the data's foot twist is free (the toe is a
    /// leaf), so on the bundled kick the uncalibrated stance box stands on
    /// its toe corner, heel 18 cm up. Stance frames are those where the ankle
    /// is within 2 cm of its lowest height over the clip and moves slower
    /// than 0.3 m/s horizontally. In the foot's own frame the box gets:
    /// * up: the mean world-up direction over the stance frames;
    /// * forward (its long axis): towards the foot point farthest from the
    ///   ankle across that up direction (the toe), so heel and toe lie along it;
    /// * its sole through the lowest foot point along up, its front at the
    ///   toe, its back, width and height those of the rest-pose box.
    ///
    /// Feet never planted keep the rest-pose box.
    pub fn calibrate_feet(&mut self, motion: &Motion) -> Vec<FootCalibration> {
        let n = motion.frames();
        if n < 2 {
            return Vec::new();
        }
        let dt = 1.0 / motion.fps();
        let mut x = vec![Transform::IDENTITY; motion.joints()];
        let feet = self.feet.clone();
        let mut poses: Vec<Vec<(Vec3, Quat)>> = vec![Vec::with_capacity(n); feet.len()];
        for t in 0..n {
            motion.world_transforms_into(t, &mut x);
            for (i, &b) in feet.iter().enumerate() {
                let tr = x[self.bodies[b].driver];
                poses[i].push((tr.translation.as_vec3(), tr.rotation.as_quat().normalize()));
            }
        }
        let mut out = Vec::new();
        for (i, &b) in feet.iter().enumerate() {
            let Some((up, count)) = stance_up(&poses[i], dt as f32) else {
                continue;
            };
            let points = self.foot_points(b);
            let Some(calibrated) = standing_box(&self.bodies[b].shape, &points, up) else {
                continue;
            };
            let tilt = match (self.bodies[b].shape, calibrated) {
                (Shape::Box { rotation: a, .. }, Shape::Box { rotation: c, .. }) => {
                    a.angle_between(c)
                }
                _ => 0.0,
            };
            let body = &mut self.bodies[b];
            body.shape = calibrated;
            body.com_local = calibrated.center();
            out.push(FootCalibration {
                body: b,
                stance_frames: count,
                tilt_rad: tilt,
            });
        }
        out
    }

    /// The rest-pose positions of foot body `b`'s joints and end sites,
    /// relative to its origin (the body frame: rest orientations are the
    /// identity).
    fn foot_points(&self, b: usize) -> Vec<Vec3> {
        let sk = &self.skeleton;
        let rest = sk.rest_positions();
        let origin = rest[self.bodies[b].driver];
        let mut points = Vec::new();
        for (j, m) in self.joint_map.iter().enumerate() {
            let mine = matches!(*m, JointMapping::Body(x) | JointMapping::MergedInto(x) if x == b);
            if !mine {
                continue;
            }
            points.push((rest[j] - origin).as_vec3());
            if let Some(e) = sk.joint(j).end_site {
                points.push((rest[j] + e - origin).as_vec3());
            }
        }
        points
    }

    /// File joint -> simulated body (or the body it is merged into).
    pub fn mapping_report(&self) -> Vec<MappingLine> {
        self.skeleton
            .joints()
            .iter()
            .zip(&self.joint_map)
            .map(|(j, m)| {
                let (b, merged) = match *m {
                    JointMapping::Body(b) => (b, false),
                    JointMapping::MergedInto(b) => (b, true),
                };
                MappingLine {
                    file_joint: j.name.clone(),
                    body: self.bodies[b].name.clone(),
                    merged,
                }
            })
            .collect()
    }

    pub fn body_index(&self, role: Role) -> Option<usize> {
        self.bodies.iter().position(|b| b.role == role)
    }

    /// Build the character of `skeleton` (see the module docs for the rules):
    /// find the body parts in the rest pose, then turn them into bodies.
    pub fn build(skeleton: Arc<Skeleton>, opts: &CharacterOptions) -> Result<Self, PhysicsError> {
        let rest = RestPose::new(&skeleton)?;
        let parts = rest.find_parts()?;
        bodies::assemble(&rest, &parts, skeleton.clone(), opts)
    }
}

/// The mean world-up direction in the foot's frame over its stance frames
/// (ankle within 2 cm of its lowest height, slower than 0.3 m/s
/// horizontally) and how many there were; `None` with fewer than 3.
fn stance_up(poses: &[(Vec3, Quat)], dt: f32) -> Option<(Vec3, usize)> {
    let n = poses.len();
    let floor = poses.iter().map(|(p, _)| p.y).fold(f32::INFINITY, f32::min);
    let mut up = Vec3::ZERO;
    let mut count = 0;
    for t in 0..n {
        let (p, q) = poses[t];
        let other = if t + 1 < n {
            poses[t + 1].0
        } else {
            poses[t - 1].0
        };
        let v = (other - p) / dt;
        if p.y < floor + 0.02 && Vec3::new(v.x, 0.0, v.z).length() < 0.3 {
            up += q.inverse() * Vec3::Y;
            count += 1;
        }
    }
    (count >= 3 && up.length() > 1e-6).then(|| (up.normalize(), count))
}

/// A foot box with sole normal `up` (body frame): long axis towards the
/// farthest of `points` across `up`, sole through the lowest point along
/// `up`, back, width and height from `rest` (the rest-pose box).
fn standing_box(rest: &Shape, points: &[Vec3], up: Vec3) -> Option<Shape> {
    let Shape::Box {
        center,
        half_extents: h,
        rotation,
    } = *rest
    else {
        return None;
    };
    let across = |p: Vec3| p - up * p.dot(up);
    let toe = points
        .iter()
        .copied()
        .max_by(|a, b| across(*a).length().total_cmp(&across(*b).length()))?;
    let forward = across(toe).try_normalize()?;
    let lateral = up.cross(forward);
    let front = points.iter().map(|p| p.dot(forward)).fold(0.0f32, f32::max);
    let back = center.dot(rotation * Vec3::Z) - h.z;
    let sole = points.iter().map(|p| p.dot(up)).fold(0.0f32, f32::min);
    let half_height = 0.5 * (-sole).max(2.0 * h.y);
    let center = forward * (0.5 * (front + back)) + up * (sole + half_height);
    let basis = Mat3::from_cols(lateral, up, forward);
    Some(Shape::Box {
        center,
        half_extents: Vec3::new(h.x, half_height, 0.5 * (front - back)),
        rotation: Quat::from_mat3(&basis).normalize(),
    })
}
