//! Whether a clip's own motion can balance on its feet: the zero moment point
//! (ZMP) of the reference against its support polygon, frame by frame.
//!
//! Why it exists: a synthesised clip can lean or accelerate in a way no body
//! standing on its feet can (its centre of mass would need a push from
//! nowhere). The simulated character then falls or leans on the root force,
//! and the correction pays for a clip it cannot accept. This tells such clips
//! from the input alone, before paying for a correction.
//!
//! The ZMP is the point on the floor where the ground's reaction must act for
//! the body's centre of mass to move as it does (the cart-table model: the
//! whole body as a point mass, angular momentum about the centre of mass
//! left out): `p = c_xz - c_y a_xz / (a_y + g)`. A body standing on its feet
//! can only push through the area its feet cover: the convex hull of the
//! bottom corners of the foot boxes touching the floor. How far the ZMP lies
//! outside that hull is the lever arm of the torque the motion needs from
//! something other than the feet.

use glam::{Vec2, Vec3};

use crate::character::Shape;
use crate::env::ImitationEnv;

/// Standard gravity, m/s^2.
const G: f32 = 9.81;

/// Below this much of gravity, `a_y + g` is too small for the ZMP to mean
/// anything (the body is close to free fall while a foot touches).
const MIN_SUPPORT_G: f32 = 0.1;

/// How one interior frame of a reference stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stance {
    /// No foot within the touch distance of the floor (flight), or the
    /// centre of mass close to free fall: nothing to judge.
    Unsupported,
    /// The ZMP lies this far (m) outside the support polygon (0 inside).
    Supported { outside_m: f32 },
}

/// Distance from `p` to the convex hull of `points` (0 inside or on it);
/// infinite when there are no points.
pub fn distance_outside_hull(points: &[Vec2], p: Vec2) -> f32 {
    let hull = convex_hull(points);
    match hull.len() {
        0 => f32::INFINITY,
        1 => (p - hull[0]).length(),
        2 => distance_to_segment(p, hull[0], hull[1]),
        n => {
            // Counter-clockwise: inside when left of (or on) every edge.
            let inside = (0..n).all(|i| cross(hull[(i + 1) % n] - hull[i], p - hull[i]) >= 0.0);
            if inside {
                0.0
            } else {
                (0..n)
                    .map(|i| distance_to_segment(p, hull[i], hull[(i + 1) % n]))
                    .fold(f32::INFINITY, f32::min)
            }
        }
    }
}

fn cross(a: Vec2, b: Vec2) -> f32 {
    a.x * b.y - a.y * b.x
}

fn distance_to_segment(p: Vec2, a: Vec2, b: Vec2) -> f32 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + t * ab)).length()
}

/// Andrew's monotone chain, counter-clockwise, collinear points dropped.
fn convex_hull(points: &[Vec2]) -> Vec<Vec2> {
    let mut pts: Vec<Vec2> = points.iter().copied().filter(|p| p.is_finite()).collect();
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    // The lower chain left to right, then the upper one right to left, each
    // without its last point (the other chain's first).
    let mut hull = half_hull(pts.iter());
    hull.extend(half_hull(pts.iter().rev()));
    hull
}

/// One chain of the monotone chain: the points kept turning left.
fn half_hull<'a>(points: impl Iterator<Item = &'a Vec2>) -> Vec<Vec2> {
    let mut chain: Vec<Vec2> = Vec::new();
    for &p in points {
        while let [.., a, b] = chain[..]
            && cross(b - a, p - a) <= 0.0
        {
            chain.pop();
        }
        chain.push(p);
    }
    chain.pop();
    chain
}

impl ImitationEnv {
    /// How the *reference* stands at every interior frame (1 .. len - 1, the
    /// centre of mass's acceleration by central differences at the control
    /// rate): a foot supports when the lowest bottom corner of its box is
    /// within `touch_m` of the floor, and its bottom corners that are
    /// within it span the support polygon. Feet that are not boxes support
    /// with their lowest point.
    pub fn reference_balance(&self, touch_m: f32) -> Vec<Stance> {
        let reference = self.reference();
        let spec = self.spec();
        let frames = &reference.frames;
        let dt = (1.0 / reference.hz) as f32;
        let mut out = Vec::with_capacity(frames.len().saturating_sub(2));
        for k in 1..frames.len().saturating_sub(1) {
            let c = frames[k].com;
            let a = (frames[k + 1].com - 2.0 * c + frames[k - 1].com) / (dt * dt);
            let mut support: Vec<Vec2> = Vec::new();
            for &b in &spec.feet {
                let s = &frames[k].bodies[b];
                let corners = foot_corners(&spec.bodies[b].shape, s.pos, s.rot);
                let low = corners.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
                if low <= touch_m {
                    support.extend(
                        corners
                            .iter()
                            .filter(|p| p.y <= touch_m)
                            .map(|p| Vec2::new(p.x, p.z)),
                    );
                }
            }
            let denominator = a.y + G;
            if support.is_empty() || denominator < MIN_SUPPORT_G * G {
                out.push(Stance::Unsupported);
                continue;
            }
            let zmp = Vec2::new(c.x, c.z) - c.y * Vec2::new(a.x, a.z) / denominator;
            out.push(Stance::Supported {
                outside_m: distance_outside_hull(&support, zmp),
            });
        }
        out
    }
}

/// The bottom corners of a foot box in the world (a body at `pos`, `rot`);
/// the lowest point of another shape.
fn foot_corners(shape: &Shape, pos: Vec3, rot: glam::Quat) -> Vec<Vec3> {
    match *shape {
        Shape::Box {
            center,
            half_extents: h,
            rotation,
        } => {
            let mut corners = Vec::with_capacity(8);
            for sx in [-1.0, 1.0] {
                for sy in [-1.0, 1.0] {
                    for sz in [-1.0, 1.0] {
                        let local = center + rotation * Vec3::new(sx * h.x, sy * h.y, sz * h.z);
                        corners.push(pos + rot * local);
                    }
                }
            }
            // The four lowest are the sole, whichever way the box is turned.
            corners.sort_by(|a, b| a.y.total_cmp(&b.y));
            corners.truncate(4);
            corners
        }
        _ => {
            let c = pos + rot * shape.center();
            vec![Vec3::new(c.x, shape.lowest_y(pos, rot), c.z)]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn square() -> Vec<Vec2> {
        vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(0.5, 0.5),
        ]
    }

    #[test]
    fn the_distance_is_zero_inside_and_to_the_nearest_edge_or_corner_outside() {
        let s = square();
        assert_eq!(distance_outside_hull(&s, Vec2::new(0.3, 0.7)), 0.0);
        assert_eq!(distance_outside_hull(&s, Vec2::new(1.0, 0.5)), 0.0);
        assert!((distance_outside_hull(&s, Vec2::new(1.5, 0.5)) - 0.5).abs() < 1e-6);
        assert!((distance_outside_hull(&s, Vec2::new(2.0, 2.0)) - 2f32.sqrt()).abs() < 1e-6);
        // A segment (two feet's single points) and a point.
        let seg = [Vec2::ZERO, Vec2::new(1.0, 0.0)];
        assert!((distance_outside_hull(&seg, Vec2::new(0.5, 0.3)) - 0.3).abs() < 1e-6);
        assert!((distance_outside_hull(&seg[..1], Vec2::new(0.0, 0.3)) - 0.3).abs() < 1e-6);
        assert_eq!(distance_outside_hull(&[], Vec2::ZERO), f32::INFINITY);
    }

    /// Standing and swaying the arms, the ZMP stays within the feet; the same
    /// pose carried forward (along the feet, which are 23 cm long) at 4 m/s^2,
    /// the feet with it, needs the floor to push from h a / g, about 0.3 m,
    /// behind the centre of mass.
    #[test]
    fn a_standing_clip_balances_and_an_accelerating_one_does_not() {
        use crate::fixtures::{cmu_humanoid, sway};
        let still = sway(cmu_humanoid(), 2.0, 60.0);
        let judge = |m: &motion::Motion| {
            ImitationEnv::new(m, &crate::Config::default())
                .unwrap()
                .reference_balance(0.02)
        };
        let stances = judge(&still);
        assert!(stances.len() > 50);
        for st in &stances {
            match *st {
                Stance::Supported { outside_m } => assert!(outside_m < 0.02, "{st:?}"),
                Stance::Unsupported => panic!("standing is supported"),
            }
        }
        let mut pushed = still.clone();
        let fps = pushed.fps();
        for (f, r) in pushed.root_translation_mut().iter_mut().enumerate() {
            let t = f as f64 / fps;
            r.z += 0.5 * 4.0 * t * t;
        }
        let stances = judge(&pushed);
        // The ends of the resampled clip are one-sided; judge the middle.
        for st in &stances[2..stances.len() - 2] {
            match *st {
                Stance::Supported { outside_m } => assert!(outside_m > 0.1, "{st:?}"),
                Stance::Unsupported => panic!("the feet are on the floor"),
            }
        }
    }

    proptest! {
        /// Every input point is inside its hull; outside points are no
        /// farther than the nearest input point and the distance moves with
        /// the whole picture.
        #[test]
        fn the_hull_holds_its_points_and_bounds_the_distance(
            pts in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0), 1..12),
            p in (-3.0f32..3.0, -3.0f32..3.0),
            shift in (-5.0f32..5.0, -5.0f32..5.0),
        ) {
            let pts: Vec<Vec2> = pts.into_iter().map(|(x, y)| Vec2::new(x, y)).collect();
            let p = Vec2::new(p.0, p.1);
            for &q in &pts {
                prop_assert!(distance_outside_hull(&pts, q) < 1e-5);
            }
            let d = distance_outside_hull(&pts, p);
            let nearest = pts.iter().map(|q| (*q - p).length()).fold(f32::INFINITY, f32::min);
            prop_assert!(d <= nearest + 1e-5, "{d} > {nearest}");
            let s = Vec2::new(shift.0, shift.1);
            let moved: Vec<Vec2> = pts.iter().map(|q| *q + s).collect();
            prop_assert!((distance_outside_hull(&moved, p + s) - d).abs() < 1e-3);
        }
    }
}
