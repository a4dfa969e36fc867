//! From the found body parts to the simulated bodies: which joint drives
//! which body, how every file joint maps to a body, masses and gains, shapes,
//! knee/elbow limits and the pairs that never collide (the last three
//! paragraphs of the [module docs](super)). [`assemble`] runs the stages in
//! that order.

use std::sync::Arc;

use glam::{DVec3, Quat, Vec3};
use motion::Skeleton;
use rapier3d::parry;

use super::parts::{Parts, RestPose, bad};
use super::{
    BodySpec, CharacterOptions, CharacterSpec, HingeLimit, JointMapping, Role, Shape, Side,
    reference_model,
};
use crate::PhysicsError;

/// One simulated body per driver joint: (file joint, role), sorted by joint.
type Drivers = Vec<(usize, Role)>;

/// The character of the skeleton whose rest pose `rest` is and whose parts are `parts`.
pub(super) fn assemble(
    rest: &RestPose,
    parts: &Parts,
    skeleton: Arc<Skeleton>,
    opts: &CharacterOptions,
) -> Result<CharacterSpec, PhysicsError> {
    let drivers = drivers(rest, parts)?;
    let joint_map = joint_map(rest.sk, &drivers);
    let present: Vec<Role> = drivers.iter().map(|d| d.1).collect();
    let masses = reference_masses(&present);
    let ref_total: f32 = masses.iter().sum();
    let scale = opts.total_mass_kg.map(|m| m / ref_total).unwrap_or(1.0);
    if !(scale.is_finite() && scale > 0.0) {
        return Err(bad("total mass must be a positive number"));
    }
    let shapes = Shapes {
        rest,
        drivers: &drivers,
        joint_map: &joint_map,
        fwd: parts.forward,
        h: rest.height,
        s: (rest.height / 1.7) as f32, // size scale for radii
    };
    let all_weights: f32 = present.iter().map(|r| reference_model(*r).4).sum();
    let bodies: Vec<BodySpec> = (0..drivers.len())
        .map(|b| shapes.body(b, masses[b], scale, all_weights))
        .collect();
    let no_collision = no_collision(&bodies);
    let feet: Vec<usize> = (0..bodies.len())
        .filter(|&b| matches!(bodies[b].role, Role::Foot(_)))
        .collect();
    let end_effectors = end_effectors(&bodies, &feet);
    let total_mass = bodies.iter().map(|b| b.mass).sum();
    Ok(CharacterSpec {
        skeleton,
        bodies,
        joint_map,
        forward: parts.forward.as_vec3(),
        total_mass,
        no_collision,
        feet,
        end_effectors,
    })
}

/// The driver joint of every simulated body, sorted by joint (the pelvis first).
fn drivers(rest: &RestPose, parts: &Parts) -> Result<Drivers, PhysicsError> {
    let mut drivers: Drivers = vec![(parts.pelvis, Role::Pelvis)];
    match parts.spine.len() {
        0 => {}
        1 => drivers.push((parts.spine[0], Role::Chest)),
        _ => {
            drivers.push((parts.spine[0], Role::Spine));
            drivers.push((parts.spine[1], Role::Chest));
        }
    }
    if let Some(nk) = parts.neck {
        drivers.push((nk, Role::Neck));
    }
    for l in &parts.legs {
        drivers.push((l.upper, Role::UpperLeg(l.side)));
        drivers.push((l.lower, Role::LowerLeg(l.side)));
        let foot = l.end.ok_or_else(|| bad("leg without a foot"))?;
        drivers.push((foot, Role::Foot(l.side)));
    }
    for a in &parts.arms {
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
                rest.sk.joint(w[0].0).name,
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
    Ok(drivers)
}

/// Each file joint drives its body or is merged into its nearest driver ancestor's.
fn joint_map(sk: &Skeleton, drivers: &Drivers) -> Vec<JointMapping> {
    let n = sk.len();
    let mut joint_map = vec![JointMapping::MergedInto(0); n];
    for j in 0..n {
        if let Some(b) = drivers.iter().position(|d| d.0 == j) {
            joint_map[j] = JointMapping::Body(b);
        } else if let Some(pj) = sk.parent(j) {
            joint_map[j] = match joint_map[pj] {
                JointMapping::Body(b) | JointMapping::MergedInto(b) => JointMapping::MergedInto(b),
            };
        }
    }
    joint_map
}

/// Reference mass of each present body, plus the mass of the reference bodies
/// this skeleton lacks (given to the nearest present one).
fn reference_masses(present: &[Role]) -> Vec<f32> {
    let mut masses: Vec<f32> = present.iter().map(|r| reference_model(*r).0).collect();
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
    masses
}

/// Pairs of bodies that are adjacent in the tree or overlap in the rest pose.
fn no_collision(bodies: &[BodySpec]) -> Vec<(usize, usize)> {
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
    no_collision
}

/// The feet, then each side's hand (or forearm without a hand).
fn end_effectors(bodies: &[BodySpec], feet: &[usize]) -> Vec<usize> {
    let mut end_effectors = feet.to_vec();
    for side in [Side::Left, Side::Right] {
        let hand = bodies.iter().position(|b| b.role == Role::Hand(side));
        let fore = bodies.iter().position(|b| b.role == Role::ForeArm(side));
        if let Some(e) = hand.or(fore) {
            end_effectors.push(e);
        }
    }
    end_effectors
}

fn v(d: DVec3) -> Vec3 {
    d.as_vec3()
}

/// What the body of each driver is built from.
struct Shapes<'r, 'a> {
    rest: &'r RestPose<'a>,
    drivers: &'r Drivers,
    joint_map: &'r [JointMapping],
    /// Facing direction.
    fwd: DVec3,
    /// Body height, metres.
    h: f64,
    /// Size scale for radii (`h / 1.7`).
    s: f32,
}

/// The rest-pose points of one body, relative to its origin (the driver).
struct Points {
    origin: DVec3,
    /// The driver and the joints merged into it.
    members: Vec<usize>,
    /// Driver joints of the child bodies.
    child_drivers: Vec<usize>,
}

impl<'r, 'a> Shapes<'r, 'a> {
    fn body_of(&self, j: usize) -> usize {
        match self.joint_map[j] {
            JointMapping::Body(b) | JointMapping::MergedInto(b) => b,
        }
    }

    /// Body `b` with mass `mass` (reference kg), masses and gains scaled by `scale`.
    fn body(&self, b: usize, mass: f32, scale: f32, all_weights: f32) -> BodySpec {
        let (j, role) = self.drivers[b];
        let sk = self.rest.sk;
        let pts = self.points(b);
        let shape = self.shape(role, j, &pts);
        let (_, kp, kd, tl, w) = reference_model(role);
        // Joints above the pelvis driver are merged into the pelvis: it has no parent body.
        let parent = if b == 0 {
            None
        } else {
            sk.parent(j).map(|pj| self.body_of(pj))
        };
        let anchor_in_parent = match parent {
            Some(pb) => v(pts.origin - self.rest.pos[self.drivers[pb].0]),
            None => Vec3::ZERO,
        };
        BodySpec {
            name: role.to_string(),
            role,
            driver: j,
            parent,
            anchor_in_parent,
            rest_origin: v(pts.origin - self.rest.pos[0]),
            shape,
            mass: mass * scale,
            kp: kp * scale,
            kd: kd * scale,
            torque_limit: tl * scale,
            weight: w / all_weights,
            hinge: self.hinge(role, &pts),
            com_local: shape.center(),
        }
    }

    fn points(&self, b: usize) -> Points {
        let rest = self.rest;
        let origin = rest.pos[self.drivers[b].0];
        // Points of this body: the driver, merged joints, their tips, child driver anchors.
        let members: Vec<usize> = (0..rest.sk.len())
            .filter(|&k| self.body_of(k) == b)
            .collect();
        let child_drivers: Vec<usize> = self
            .drivers
            .iter()
            .filter(|d| rest.sk.parent(d.0).is_some_and(|pj| self.body_of(pj) == b))
            .map(|d| d.0)
            .collect();
        Points {
            origin,
            members,
            child_drivers,
        }
    }

    /// The segment to the (single) child body of a limb.
    fn main_child(&self, pts: &Points) -> Option<DVec3> {
        pts.child_drivers
            .first()
            .map(|&cj| self.rest.pos[cj] - pts.origin)
    }

    /// The body's point farthest from its origin.
    fn far_tip(&self, pts: &Points) -> DVec3 {
        let mut best = DVec3::ZERO;
        for &k in &pts.members {
            for p in [self.rest.pos[k], self.rest.tip[k]] {
                if (p - pts.origin).length() > best.length() {
                    best = p - pts.origin;
                }
            }
        }
        best
    }

    fn shape(&self, role: Role, j: usize, pts: &Points) -> Shape {
        match role {
            Role::Pelvis => self.pelvis(pts),
            Role::Spine | Role::Chest => self.spine(role, pts),
            Role::Neck => self.head(j, pts),
            Role::UpperLeg(_) | Role::LowerLeg(_) | Role::UpperArm(_) | Role::ForeArm(_) => {
                self.limb(role, pts)
            }
            Role::Hand(_) => {
                let t = self.far_tip(pts);
                let s = self.s;
                Shape::Sphere {
                    center: v(t * 0.5),
                    radius: (0.5 * t.length() as f32).clamp(0.03 * s, 0.05 * s),
                }
            }
            Role::Foot(_) => self.foot(pts),
        }
    }

    /// A sphere between the hips.
    fn pelvis(&self, pts: &Points) -> Shape {
        let (h, s) = (self.h, self.s);
        let hips: Vec<DVec3> = pts
            .child_drivers
            .iter()
            .filter(|&&cj| {
                matches!(
                    self.drivers.iter().find(|d| d.0 == cj).map(|d| d.1),
                    Some(Role::UpperLeg(_))
                )
            })
            .map(|&cj| self.rest.pos[cj] - pts.origin)
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

    /// A sphere halfway to the child bodies.
    fn spine(&self, role: Role, pts: &Points) -> Shape {
        let s = self.s;
        let top = if pts.child_drivers.is_empty() {
            self.far_tip(pts)
        } else {
            pts.child_drivers
                .iter()
                .map(|&cj| self.rest.pos[cj] - pts.origin)
                .sum::<DVec3>()
                / pts.child_drivers.len() as f64
        };
        let len = top.length() as f32;
        let r = if role == Role::Chest { 0.11 } else { 0.1 };
        Shape::Sphere {
            center: v(top * 0.5),
            radius: (0.6 * len).clamp(0.07 * s, r * s),
        }
    }

    /// Head sphere: around the top of the neck chain (`j` is the neck driver).
    fn head(&self, j: usize, pts: &Points) -> Shape {
        let (h, s) = (self.h, self.s);
        let t = self.far_tip(pts);
        let top_joint = pts
            .members
            .iter()
            .copied()
            .max_by(|a, b| self.rest.pos[*a].y.total_cmp(&self.rest.pos[*b].y))
            .unwrap_or(j);
        let base = self.rest.pos[top_joint] - pts.origin;
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

    /// A capsule along the segment to the child body.
    fn limb(&self, role: Role, pts: &Points) -> Shape {
        let end = self.main_child(pts).unwrap_or_else(|| self.far_tip(pts));
        let r = match role {
            Role::UpperLeg(_) => 0.06,
            Role::LowerLeg(_) => 0.05,
            Role::UpperArm(_) => 0.045,
            _ => 0.04,
        } * self.s;
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

    /// A box from heel to toe tip, ankle height, along the facing direction.
    fn foot(&self, pts: &Points) -> Shape {
        let h = self.h;
        let f = self.fwd;
        let mut front: f64 = 0.05 * h / 1.7;
        let mut sole = 0.0f64;
        for &k in &pts.members {
            for p in [self.rest.pos[k], self.rest.tip[k]] {
                let d = p - pts.origin;
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

    /// Knees and elbows bend one way about the axis across the facing direction.
    fn hinge(&self, role: Role, pts: &Points) -> Option<HingeLimit> {
        let fwd = self.fwd;
        match role {
            Role::LowerLeg(_) | Role::ForeArm(_) => {
                let seg = self.main_child(pts).unwrap_or_else(|| self.far_tip(pts));
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
        }
    }
}
