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

use std::fmt;
use std::sync::Arc;

use glam::{DVec3, Mat3, Quat, Vec3};
use motion::{Motion, Skeleton, Transform};
use rapier3d::parry;
use serde::Serialize;

use crate::PhysicsError;

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
    /// Tilt each foot box so its sole is flat on the ground in the clip's own
    /// stance frames (see [`CharacterSpec::calibrate_feet`]). Off by default:
    /// on the bundled HDM05 kick the rest-pose box of the planted right foot is
    /// rolled 2.2 rad (the data's foot twist is free: the toe is a leaf), yet
    /// calibrating made the corrected clip worse after 90 s of training on a
    /// loaded machine (foot skating 0.103 -> 0.200 m/s, mean penetration
    /// 0.006 -> 0.023 m, R_norm 0.882 -> 0.880); why is still open.
    pub calibrate_feet: bool,
}

impl Default for CharacterOptions {
    fn default() -> Self {
        CharacterOptions {
            total_mass_kg: None,
            friction: 0.9,
            calibrate_feet: false,
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
    /// Tilt each foot box so that its sole lies flat on the ground when the
    /// foot is planted in `motion`.
    ///
    /// The boxes are built from the rest pose, whose foot is rarely the
    /// standing foot: HDM05's rest foot points 22 degrees down, its planted
    /// feet about 31 degrees, so an uncalibrated box stands on its toe edge
    /// and pivots. Stance frames are those where the ankle is within
    /// 2 cm of its lowest height over the clip and moves slower than 0.3 m/s
    /// horizontally; the box is turned about the ankle so that its up
    /// axis is the mean world-up direction (in the foot's frame) over them.
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
            let shape = self.bodies[b].shape;
            let Shape::Box {
                center,
                half_extents,
                rotation,
            } = shape
            else {
                continue;
            };
            // The ankle, not the box: a rest-pose box tilted in the swing can dip
            // lower than in stance.
            let lows: Vec<f32> = poses[i].iter().map(|(p, _)| p.y).collect();
            let floor = lows.iter().copied().fold(f32::INFINITY, f32::min);
            let mut up = Vec3::ZERO;
            let mut count = 0;
            for t in 0..n {
                let (p, q) = poses[i][t];
                let other = if t + 1 < n {
                    poses[i][t + 1].0
                } else {
                    poses[i][t - 1].0
                };
                let v = (other - p) / dt as f32;
                let slow = Vec3::new(v.x, 0.0, v.z).length() < 0.3;
                if lows[t] < floor + 0.02 && slow {
                    up += q.inverse() * Vec3::Y;
                    count += 1;
                }
            }
            if count < 3 || up.length() < 1e-6 {
                continue;
            }
            let target = up.normalize();
            let current = rotation * Vec3::Y;
            let delta = Quat::from_rotation_arc(current, target);
            let tilt = delta.angle_between(Quat::IDENTITY);
            if !tilt.is_finite() {
                continue;
            }
            let body = &mut self.bodies[b];
            body.shape = Shape::Box {
                center: delta * center,
                half_extents,
                rotation: (delta * rotation).normalize(),
            };
            body.com_local = body.shape.center();
            out.push(FootCalibration {
                body: b,
                stance_frames: count,
                tilt_rad: tilt,
            });
        }
        out
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

    /// Build the character of `skeleton` (see the module docs for the rules).
    pub fn build(skeleton: Arc<Skeleton>, opts: &CharacterOptions) -> Result<Self, PhysicsError> {
        Builder::new(&skeleton)?.build(skeleton.clone(), opts)
    }
}

const EPS_LEN: f64 = 0.005;

struct Builder<'a> {
    sk: &'a Skeleton,
    pos: Vec<DVec3>,
    tip: Vec<DVec3>,
    children: Vec<Vec<usize>>,
    path_len: Vec<f64>,
    height: f64,
}

fn bad(msg: impl Into<String>) -> PhysicsError {
    PhysicsError::Character(msg.into())
}

/// A limb chain split into roles: indices into the skeleton.
struct Limb {
    upper: usize,
    lower: usize,
    end: Option<usize>,
    side: Side,
}

impl<'a> Builder<'a> {
    fn new(sk: &'a Skeleton) -> Result<Self, PhysicsError> {
        let n = sk.len();
        let pos = sk.rest_positions();
        let mut children = vec![Vec::new(); n];
        for i in 1..n {
            if let Some(p) = sk.parent(i) {
                children[p].push(i);
            }
        }
        let tip: Vec<DVec3> = (0..n)
            .map(|i| pos[i] + sk.joint(i).end_site.unwrap_or(DVec3::ZERO))
            .collect();
        let mut path_len = vec![0.0; n];
        for i in 1..n {
            let p = sk.parent(i).unwrap_or(0);
            path_len[i] = path_len[p] + (pos[i] - pos[p]).length();
        }
        let height = sk.rest_height();
        if !(height.is_finite() && height > 0.3) {
            return Err(bad(format!(
                "rest pose is {height:.3} m tall: not a humanoid in metres"
            )));
        }
        Ok(Builder {
            sk,
            pos,
            tip,
            children,
            path_len,
            height,
        })
    }

    fn is_leaf(&self, j: usize) -> bool {
        self.children[j].is_empty()
    }

    fn tip_path_len(&self, j: usize) -> f64 {
        self.path_len[j] + (self.tip[j] - self.pos[j]).length()
    }

    fn lca(&self, a: usize, b: usize) -> usize {
        let anc = self.sk.ancestors(a);
        let mut at = b;
        loop {
            if anc.contains(&at) {
                return at;
            }
            match self.sk.parent(at) {
                Some(p) => at = p,
                None => return 0,
            }
        }
    }

    fn in_subtree(&self, j: usize, root: usize) -> bool {
        self.sk.ancestors(j).contains(&root)
    }

    /// Joints strictly after `from` on the path from the root to `to`.
    fn path_after(&self, from: usize, to: usize) -> Vec<usize> {
        let mut path = self.sk.ancestors(to);
        path.reverse();
        match path.iter().position(|&j| j == from) {
            Some(i) => path[i + 1..].to_vec(),
            None => path,
        }
    }

    /// Segment length of each chain joint: to the next chain joint, the last one to its tip.
    fn segments(&self, chain: &[usize]) -> Vec<f64> {
        (0..chain.len())
            .map(|k| {
                let j = chain[k];
                let next = if k + 1 < chain.len() {
                    self.pos[chain[k + 1]]
                } else {
                    self.tip[j]
                };
                (next - self.pos[j]).length()
            })
            .collect()
    }

    fn side_of(&self, chain: &[usize], lateral: DVec3) -> Side {
        let names: Vec<String> = self
            .sk
            .joints()
            .iter()
            .map(|j| j.name.to_ascii_lowercase())
            .collect();
        let mut vote = 0i32;
        for &j in chain {
            let n = &names[j];
            if n.contains("left") {
                vote += 1;
            } else if n.contains("right") {
                vote -= 1;
            } else if let Some(rest) = n.strip_prefix('l') {
                if names.iter().any(|m| m.strip_prefix('r') == Some(rest)) {
                    vote += 1;
                }
            } else if let Some(rest) = n.strip_prefix('r')
                && names.iter().any(|m| m.strip_prefix('l') == Some(rest))
            {
                vote -= 1;
            }
        }
        if vote > 0 {
            Side::Left
        } else if vote < 0 {
            Side::Right
        } else {
            let last = *chain.last().unwrap_or(&0);
            if (self.tip[last] - self.pos[0]).dot(lateral) >= 0.0 {
                Side::Left
            } else {
                Side::Right
            }
        }
    }

    fn split_limb(
        &self,
        chain: &[usize],
        what: &str,
    ) -> Result<(usize, usize, Option<usize>), PhysicsError> {
        let seg = self.segments(chain);
        let next_nonzero = |k: usize| (k + 1..chain.len()).find(|&i| seg[i] > EPS_LEN);
        // Upper and lower limb: the last pair of consecutive non-zero segments that
        // are both at least 45% of the chain's longest segment (a clavicle may be
        // as long as a forearm, but it comes first; wrists and toes are short).
        let longest = seg.iter().copied().fold(0.0, f64::max);
        let mut found = None;
        for k in 0..chain.len() {
            if seg[k] < 0.45 * longest || seg[k] <= EPS_LEN {
                continue;
            }
            if let Some(k2) = next_nonzero(k)
                && seg[k2] >= 0.45 * longest
            {
                found = Some((k, k2));
            }
        }
        let (k1, k2) = found.ok_or_else(|| {
            bad(format!(
                "the {what} chain ending at `{}` has no two consecutive long bones",
                chain
                    .last()
                    .map(|&j| self.sk.joint(j).name.as_str())
                    .unwrap_or("?")
            ))
        })?;
        let end = next_nonzero(k2).or(if k2 + 1 < chain.len() {
            Some(k2 + 1)
        } else {
            None
        });
        Ok((chain[k1], chain[k2], end.map(|k| chain[k])))
    }

    fn build(
        self,
        skeleton: Arc<Skeleton>,
        opts: &CharacterOptions,
    ) -> Result<CharacterSpec, PhysicsError> {
        let h = self.height;
        let n = self.sk.len();
        let leaves: Vec<usize> = (0..n).filter(|&j| self.is_leaf(j)).collect();
        // Height of the lowest point of the rest pose (the floor under the feet).
        let floor_y = self
            .pos
            .iter()
            .chain(&self.tip)
            .map(|p| p.y)
            .fold(f64::INFINITY, f64::min);

        // 1. Legs.
        let low: Vec<usize> = leaves
            .iter()
            .copied()
            .filter(|&l| self.tip[l].y < floor_y + 0.25 * h)
            .collect();
        let by_y = |a: &usize, b: &usize| self.tip[*a].y.total_cmp(&self.tip[*b].y);
        let l1 = low.iter().copied().min_by(by_y).ok_or_else(|| {
            bad("no leg: no joint reaches a quarter of the height below the root")
        })?;
        let l2 = low
            .iter()
            .copied()
            .filter(|&l| self.pos[self.lca(l1, l)].y > floor_y + 0.4 * h)
            .min_by(by_y)
            .ok_or_else(|| bad("found only one leg"))?;
        let p = self.lca(l1, l2);
        let leg_chains = [self.path_after(p, l1), self.path_after(p, l2)];
        let in_legs = |j: usize| {
            leg_chains
                .iter()
                .any(|c| !c.is_empty() && self.in_subtree(j, c[0]))
        };

        // 2. Arms.
        let upper: Vec<usize> = leaves.iter().copied().filter(|&l| !in_legs(l)).collect();
        let by_len = |a: &usize, b: &usize| self.tip_path_len(*a).total_cmp(&self.tip_path_len(*b));
        let h1 = upper
            .iter()
            .copied()
            .max_by(by_len)
            .ok_or_else(|| bad("no arms"))?;
        let h2 = upper
            .iter()
            .copied()
            .filter(|&l| {
                let c = self.lca(h1, l);
                l != h1 && self.tip_path_len(l) - self.path_len[c] > 0.25 * h
            })
            .max_by(by_len)
            .ok_or_else(|| bad("found only one arm"))?;
        let c = self.lca(h1, h2);
        let arm_chains = [self.path_after(c, h1), self.path_after(c, h2)];
        let in_arms = |j: usize| {
            arm_chains
                .iter()
                .any(|ch| !ch.is_empty() && self.in_subtree(j, ch[0]))
        };

        // 3. Head.
        let head = leaves
            .iter()
            .copied()
            .filter(|&l| !in_legs(l) && !in_arms(l) && self.in_subtree(l, c) && l != c)
            .max_by(|a, b| self.tip[*a].y.total_cmp(&self.tip[*b].y));

        // Facing and lateral directions from the feet.
        let mut fwd = DVec3::ZERO;
        for chain in &leg_chains {
            let (_, _, end) = self.split_limb(chain, "leg")?;
            let foot = end.ok_or_else(|| bad("leg without a foot"))?;
            let leaf = *chain.last().unwrap_or(&foot);
            let d = self.tip[leaf] - self.pos[foot];
            fwd += DVec3::new(d.x, 0.0, d.z);
        }
        let fwd = if fwd.length() > 1e-6 {
            fwd.normalize()
        } else {
            DVec3::Z
        };
        let lateral = DVec3::Y.cross(fwd); // character's left

        let limb = |chain: &[usize], what: &str| -> Result<Limb, PhysicsError> {
            let (u, l, e) = self.split_limb(chain, what)?;
            Ok(Limb {
                upper: u,
                lower: l,
                end: e,
                side: self.side_of(chain, lateral),
            })
        };
        let legs = [limb(&leg_chains[0], "leg")?, limb(&leg_chains[1], "leg")?];
        let arms = [limb(&arm_chains[0], "arm")?, limb(&arm_chains[1], "arm")?];
        if legs[0].side == legs[1].side {
            return Err(bad("both legs look like the same side"));
        }
        if arms[0].side == arms[1].side {
            return Err(bad("both arms look like the same side"));
        }

        // 5. Torso.
        let pelvis = self.lca(p, c);
        let torso_end = head.unwrap_or(c);
        let torso = self.path_after(pelvis, torso_end);
        let torso_seg = self.segments(&torso);
        let c_idx = torso.iter().position(|&j| j == c);
        let mut spine_drivers: Vec<usize> = Vec::new();
        let mut neck = None;
        for (k, &j) in torso.iter().enumerate() {
            let upto_c = c_idx.is_some_and(|ci| k <= ci);
            if torso_seg[k] <= EPS_LEN {
                continue;
            }
            if upto_c {
                spine_drivers.push(j);
            } else if neck.is_none() && c_idx.is_some() {
                neck = Some(j);
            }
        }
        if spine_drivers.len() > 2 {
            spine_drivers = vec![spine_drivers[0], *spine_drivers.last().unwrap_or(&c)];
        }

        // Collect drivers with roles.
        let mut drivers: Vec<(usize, Role)> = vec![(pelvis, Role::Pelvis)];
        match spine_drivers.len() {
            0 => {}
            1 => drivers.push((spine_drivers[0], Role::Chest)),
            _ => {
                drivers.push((spine_drivers[0], Role::Spine));
                drivers.push((spine_drivers[1], Role::Chest));
            }
        }
        if let Some(nk) = neck {
            drivers.push((nk, Role::Neck));
        }
        for l in &legs {
            drivers.push((l.upper, Role::UpperLeg(l.side)));
            drivers.push((l.lower, Role::LowerLeg(l.side)));
            let foot = l.end.ok_or_else(|| bad("leg without a foot"))?;
            drivers.push((foot, Role::Foot(l.side)));
        }
        for a in &arms {
            drivers.push((a.upper, Role::UpperArm(a.side)));
            drivers.push((a.lower, Role::ForeArm(a.side)));
            if let Some(hd) = a.end {
                drivers.push((hd, Role::Hand(a.side)));
            }
        }
        drivers.sort_by_key(|d| d.0);
        for w in drivers.windows(2) {
            if w[0].0 == w[1].0 {
                return Err(bad(format!(
                    "joint `{}` would drive two bodies ({} and {})",
                    self.sk.joint(w[0].0).name,
                    w[0].1,
                    w[1].1
                )));
            }
        }
        if drivers.len() > 31 {
            return Err(bad("more than 31 bodies"));
        }
        if drivers[0].1 != Role::Pelvis {
            return Err(bad("pelvis is not the first body"));
        }

        // Joint mapping.
        let mut joint_map = vec![JointMapping::MergedInto(0); n];
        for j in 0..n {
            if let Some(b) = drivers.iter().position(|d| d.0 == j) {
                joint_map[j] = JointMapping::Body(b);
            } else if let Some(pj) = self.sk.parent(j) {
                joint_map[j] = match joint_map[pj] {
                    JointMapping::Body(b) | JointMapping::MergedInto(b) => {
                        JointMapping::MergedInto(b)
                    }
                };
            }
        }
        let body_of = |j: usize| match joint_map[j] {
            JointMapping::Body(b) | JointMapping::MergedInto(b) => b,
        };

        // Mass model.
        let present: Vec<Role> = drivers.iter().map(|d| d.1).collect();
        let mut masses: Vec<f32> = present.iter().map(|r| reference_model(*r).0).collect();
        // Mass of reference bodies this skeleton lacks goes to the nearest present one.
        let idx = |r: Role| present.iter().position(|x| *x == r);
        if idx(Role::Spine).is_none() {
            let to = idx(Role::Chest).unwrap_or(0);
            masses[to] += 7.0;
        }
        if idx(Role::Chest).is_none() {
            masses[0] += 7.0;
        }
        if idx(Role::Neck).is_none() {
            let to = idx(Role::Chest).unwrap_or(0);
            masses[to] += 2.0;
        }
        for s in [Side::Left, Side::Right] {
            if idx(Role::Hand(s)).is_none()
                && let Some(f) = idx(Role::ForeArm(s))
            {
                masses[f] += 0.5;
            }
        }
        let ref_total: f32 = masses.iter().sum();
        let scale = opts.total_mass_kg.map(|m| m / ref_total).unwrap_or(1.0);
        if !(scale.is_finite() && scale > 0.0) {
            return Err(bad("total mass must be a positive number"));
        }
        let s = (h / 1.7) as f32; // size scale for radii

        // Shapes.
        let v = |d: DVec3| d.as_vec3();
        let mut bodies: Vec<BodySpec> = Vec::with_capacity(drivers.len());
        let all_weights: f32 = present.iter().map(|r| reference_model(*r).4).sum();
        for (b, &(j, role)) in drivers.iter().enumerate() {
            let origin = self.pos[j];
            // Points of this body: the driver, merged joints, their tips, child driver anchors.
            let members: Vec<usize> = (0..n).filter(|&k| body_of(k) == b).collect();
            let child_drivers: Vec<usize> = drivers
                .iter()
                .filter(|d| self.sk.parent(d.0).is_some_and(|pj| body_of(pj) == b))
                .map(|d| d.0)
                .collect();
            // The segment to the (single) child body of a limb.
            let main_child =
                || -> Option<DVec3> { child_drivers.first().map(|&cj| self.pos[cj] - origin) };
            let far_tip = || -> DVec3 {
                let mut best = DVec3::ZERO;
                for &k in &members {
                    for p in [self.pos[k], self.tip[k]] {
                        if (p - origin).length() > best.length() {
                            best = p - origin;
                        }
                    }
                }
                best
            };
            let shape = match role {
                Role::Pelvis => {
                    let hips: Vec<DVec3> = child_drivers
                        .iter()
                        .filter(|&&cj| {
                            matches!(
                                drivers.iter().find(|d| d.0 == cj).map(|d| d.1),
                                Some(Role::UpperLeg(_))
                            )
                        })
                        .map(|&cj| self.pos[cj] - origin)
                        .collect();
                    let hip_w = if hips.len() == 2 {
                        (hips[0] - hips[1]).length()
                    } else {
                        0.2 * h / 1.7
                    };
                    let mut c = DVec3::ZERO;
                    for hp in &hips {
                        c += *hp;
                    }
                    c /= (hips.len() + 1) as f64;
                    Shape::Sphere {
                        center: v(c),
                        radius: (0.5 * hip_w as f32).clamp(0.07 * s, 0.12 * s),
                    }
                }
                Role::Spine | Role::Chest => {
                    let top = if child_drivers.is_empty() {
                        far_tip()
                    } else {
                        child_drivers
                            .iter()
                            .map(|&cj| self.pos[cj] - origin)
                            .sum::<DVec3>()
                            / child_drivers.len() as f64
                    };
                    let len = top.length() as f32;
                    let r = if role == Role::Chest { 0.11 } else { 0.1 };
                    Shape::Sphere {
                        center: v(top * 0.5),
                        radius: (0.6 * len).clamp(0.07 * s, r * s),
                    }
                }
                Role::Neck => {
                    // Head sphere: around the top of the neck chain.
                    let t = far_tip();
                    let top_joint = members
                        .iter()
                        .copied()
                        .max_by(|a, b| self.pos[*a].y.total_cmp(&self.pos[*b].y))
                        .unwrap_or(j);
                    let base = self.pos[top_joint] - origin;
                    let head_len = (t - base).length().max(0.1 * h / 1.7);
                    let r = (0.5 * head_len as f32).clamp(0.07 * s, 0.11 * s);
                    let center = if (t - base).length() > 1e-6 {
                        base + (t - base) * 0.5
                    } else {
                        t * 0.7
                    };
                    Shape::Sphere {
                        center: v(center),
                        radius: r,
                    }
                }
                Role::UpperLeg(_) | Role::LowerLeg(_) | Role::UpperArm(_) | Role::ForeArm(_) => {
                    let end = main_child().unwrap_or_else(far_tip);
                    let r = match role {
                        Role::UpperLeg(_) => 0.06,
                        Role::LowerLeg(_) => 0.05,
                        Role::UpperArm(_) => 0.045,
                        _ => 0.04,
                    } * s;
                    let len = end.length() as f32;
                    let r = r.min(0.3 * len.max(0.05));
                    let dir = if len > 1e-6 {
                        v(end) / len
                    } else {
                        Vec3::NEG_Y
                    };
                    let a = dir * r;
                    let b2 = v(end) - dir * r;
                    let (a, b2) = if len > 2.0 * r {
                        (a, b2)
                    } else {
                        (v(end) * 0.5, v(end) * 0.5)
                    };
                    Shape::Capsule {
                        a,
                        b: b2,
                        radius: r,
                    }
                }
                Role::Hand(_) => {
                    let t = far_tip();
                    Shape::Sphere {
                        center: v(t * 0.5),
                        radius: (0.5 * t.length() as f32).clamp(0.03 * s, 0.05 * s),
                    }
                }
                Role::Foot(_) => {
                    let f = fwd;
                    let mut front: f64 = 0.05 * h / 1.7;
                    let mut sole = 0.0f64;
                    for &k in &members {
                        for p in [self.pos[k], self.tip[k]] {
                            let d = p - origin;
                            front = front.max(d.dot(f));
                            sole = sole.min(d.y);
                        }
                    }
                    let back = -0.05 * h / 1.7;
                    let height = (-sole).max(0.045 * h);
                    let width = 0.09 * h / 1.7;
                    let center = f * (0.5 * (front + back)) + DVec3::new(0.0, -0.5 * height, 0.0);
                    // Box axes: x = lateral, y = up, z = forward.
                    let rotation = Quat::from_rotation_arc(Vec3::Z, v(f));
                    Shape::Box {
                        center: v(center),
                        half_extents: Vec3::new(
                            0.5 * width as f32,
                            0.5 * height as f32,
                            0.5 * (front - back) as f32,
                        ),
                        rotation,
                    }
                }
            };
            let (_, kp, kd, tl, w) = reference_model(role);
            // Joints above the pelvis driver are merged into the pelvis: it has no parent body.
            let parent = if b == 0 {
                None
            } else {
                self.sk.parent(j).map(body_of)
            };
            let anchor_in_parent = match parent {
                Some(pb) => v(origin - self.pos[drivers[pb].0]),
                None => Vec3::ZERO,
            };
            let hinge = match role {
                Role::LowerLeg(_) | Role::ForeArm(_) => {
                    let seg = main_child().unwrap_or_else(far_tip);
                    let axis = if matches!(role, Role::LowerLeg(_)) {
                        fwd.cross(seg)
                    } else {
                        seg.cross(fwd)
                    };
                    if axis.length() > 1e-6 {
                        let hi = if matches!(role, Role::LowerLeg(_)) {
                            std::f64::consts::PI as f32
                        } else {
                            2.57
                        };
                        Some(HingeLimit {
                            axis: v(axis.normalize()),
                            lo: 0.0,
                            hi,
                            swing: 0.1,
                        })
                    } else {
                        None
                    }
                }
                _ => None,
            };
            bodies.push(BodySpec {
                name: role.to_string(),
                role,
                driver: j,
                parent,
                anchor_in_parent,
                rest_origin: v(origin - self.pos[0]),
                shape,
                mass: masses[b] * scale,
                kp: kp * scale,
                kd: kd * scale,
                torque_limit: tl * scale,
                weight: w / all_weights,
                hinge,
                com_local: shape.center(),
            });
        }

        // Collision exclusions: adjacent bodies and bodies overlapping at rest.
        let mut no_collision = Vec::new();
        for a in 0..bodies.len() {
            for b in a + 1..bodies.len() {
                let adjacent = bodies[b].parent == Some(a) || bodies[a].parent == Some(b);
                let (sa, pa) = bodies[a].shape.to_parry();
                let (sb, pb) = bodies[b].shape.to_parry();
                let wa = parry::math::Pose::from_translation(bodies[a].rest_origin) * pa;
                let wb = parry::math::Pose::from_translation(bodies[b].rest_origin) * pb;
                let overlap = parry::query::distance(&wa, sa.as_ref(), &wb, sb.as_ref())
                    .map(|d| d.distance < 0.01)
                    .unwrap_or(true);
                if adjacent || overlap {
                    no_collision.push((a, b));
                }
            }
        }
        let feet: Vec<usize> = (0..bodies.len())
            .filter(|&b| matches!(bodies[b].role, Role::Foot(_)))
            .collect();
        let mut end_effectors = feet.clone();
        for side in [Side::Left, Side::Right] {
            let hand = bodies.iter().position(|b| b.role == Role::Hand(side));
            let fore = bodies.iter().position(|b| b.role == Role::ForeArm(side));
            if let Some(e) = hand.or(fore) {
                end_effectors.push(e);
            }
        }
        let total_mass = bodies.iter().map(|b| b.mass).sum();
        Ok(CharacterSpec {
            skeleton,
            bodies,
            joint_map,
            forward: v(fwd),
            total_mass,
            no_collision,
            feet,
            end_effectors,
        })
    }
}
