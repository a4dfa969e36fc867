//! FABRIK (Aristidou & Lasenby 2011), the IK solver MotionAug uses.
//!
//! Solves for joint positions of a chain with a fixed base so that the last
//! point reaches a target, keeping every segment length. Optionally all inner
//! points are kept in a plane through the base (a hinge-like bend plane).
//! Unreachable targets: the chain is stretched straight towards the target (too
//! far) and the residual distance is returned.
//!
//! FABRIK converges slowly when a two-bone chain must fold almost completely
//! (target near `|l1 - l2|` from the base). For two-bone chains that have not
//! converged after `max_iterations`, a closing step puts the middle joint on the
//! exact solution circle at the point nearest to FABRIK's estimate (the point
//! FABRIK is converging to), so the result is exact to rounding.

use glam::DVec3;

/// Outcome of one solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FabrikResult {
    /// Distance from the chain end to the target after solving, metres.
    pub error: f64,
    pub iterations: usize,
    /// The target was farther than the chain's total length.
    pub out_of_reach: bool,
}

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fabrik {
    pub tolerance: f64,
    pub max_iterations: usize,
}

impl Default for Fabrik {
    fn default() -> Self {
        Fabrik {
            tolerance: 1e-10,
            max_iterations: 1000,
        }
    }
}

fn project_to_plane(p: DVec3, origin: DVec3, normal: Option<DVec3>) -> DVec3 {
    match normal {
        Some(n) => p - n * (p - origin).dot(n),
        None => p,
    }
}

/// Place `b` at distance `len` from `a`, in the direction of `b` (any direction
/// if `b == a`).
fn along(a: DVec3, b: DVec3, len: f64) -> DVec3 {
    let d = b - a;
    let l = d.length();
    if l > 1e-15 {
        a + d * (len / l)
    } else {
        a + d.any_orthonormal_vector() * len
    }
}

impl Fabrik {
    /// Solve in place. `points[0]` is the fixed base; `points.len() == lengths.len() + 1`.
    /// `plane_normal` (unit) keeps inner points in the plane through the base.
    pub fn solve(
        &self,
        points: &mut [DVec3],
        target: DVec3,
        plane_normal: Option<DVec3>,
    ) -> FabrikResult {
        let n = points.len();
        assert!(n >= 2, "a chain needs at least two points");
        let lengths: Vec<f64> = points.windows(2).map(|w| (w[1] - w[0]).length()).collect();
        let base = points[0];
        let total: f64 = lengths.iter().sum();
        if (target - base).length() >= total {
            for i in 0..n - 1 {
                points[i + 1] = along(points[i], target, lengths[i]);
            }
            return FabrikResult {
                error: (points[n - 1] - target).length(),
                iterations: 0,
                out_of_reach: true,
            };
        }
        let mut iterations = 0;
        while (points[n - 1] - target).length() > self.tolerance && iterations < self.max_iterations
        {
            iterations += 1;
            // Backward: end to target, walk to the base.
            points[n - 1] = target;
            for i in (0..n - 1).rev() {
                let p = project_to_plane(points[i], base, plane_normal);
                points[i] = along(points[i + 1], p, lengths[i]);
            }
            // Forward: base back in place, walk to the end.
            points[0] = base;
            for i in 0..n - 1 {
                let p = if i + 1 < n - 1 {
                    project_to_plane(points[i + 1], base, plane_normal)
                } else {
                    points[i + 1]
                };
                points[i + 1] = along(points[i], p, lengths[i]);
            }
        }
        if n == 3 && (points[2] - target).length() > self.tolerance {
            close_two_bone(points, &lengths, target);
        }
        FabrikResult {
            error: (points[n - 1] - target).length(),
            iterations,
            out_of_reach: false,
        }
    }
}

/// Exact two-bone placement: the middle joint on the solution circle, nearest
/// to its current position; the end on the target.
fn close_two_bone(points: &mut [DVec3], lengths: &[f64], target: DVec3) {
    let (base, l1, l2) = (points[0], lengths[0], lengths[1]);
    let w = target - base;
    let d = w.length();
    if d < 1e-15 {
        return;
    }
    let wn = w / d;
    let along_w = ((l1 * l1 - l2 * l2 + d * d) / (2.0 * d)).clamp(-l1, l1);
    let radius = (l1 * l1 - along_w * along_w).max(0.0).sqrt();
    let off = points[1] - base;
    let mut perp = off - wn * off.dot(wn);
    if perp.length() < 1e-15 {
        perp = wn.any_orthonormal_vector();
    }
    points[1] = base + wn * along_w + perp.normalize() * radius;
    points[2] = points[1] + (target - points[1]).normalize() * l2;
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn v() -> impl Strategy<Value = DVec3> {
        (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    proptest! {
        #[test]
        fn reaches_reachable_targets_and_keeps_lengths(
            a in v(), b in v(), dir in v(), frac in 0.05..0.95f64, c in v(),
        ) {
            prop_assume!(a.length() > 0.05 && b.length() > 0.05 && dir.length() > 0.1);
            let mut pts = [DVec3::ZERO, a, a + b, a + b + c * 0.3];
            let lengths: Vec<f64> = pts.windows(2).map(|w| (w[1] - w[0]).length()).collect();
            prop_assume!(lengths.iter().all(|l| *l > 0.02));
            let total: f64 = lengths.iter().sum();
            let longest = lengths.iter().cloned().fold(0.0, f64::max);
            let min_reach = (2.0 * longest - total).max(0.0);
            // Away from the fully folded boundary, where plain FABRIK crawls
            // (two-bone chains get the exact closing step instead).
            let lo = min_reach + 0.1 * (total - min_reach);
            let d = lo + frac * (total - 0.005 - lo);
            prop_assume!(d > lo && d < total - 0.005);
            let target = dir.normalize() * d;
            let r = Fabrik::default().solve(&mut pts, target, None);
            prop_assert!(r.error < 1e-3, "error {}", r.error);
            prop_assert_eq!(pts[0], DVec3::ZERO);
            for (w, l) in pts.windows(2).zip(&lengths) {
                prop_assert!(((w[1] - w[0]).length() - l).abs() < 1e-12);
            }
        }

        #[test]
        fn two_bone_in_plane_matches_the_analytic_solution(
            l1 in 0.1..0.6f64, l2 in 0.1..0.6f64, frac in 0.02..0.98f64, yaw in -3.0..3.0f64,
        ) {
            let lo = (l1 - l2).abs() + 1e-3;
            let hi = l1 + l2 - 1e-3;
            let d = lo + frac * (hi - lo);
            let w = DVec3::new(yaw.cos(), 0.3, yaw.sin()).normalize();
            let n = w.any_orthonormal_vector();
            let p = w.cross(n);
            // Start with the knee on the +p side.
            let mut pts = [DVec3::ZERO, (w + p).normalize() * l1, DVec3::ZERO];
            pts[2] = pts[1] + (w - p).normalize() * l2;
            let r = Fabrik::default().solve(&mut pts, w * d, Some(n));
            prop_assert!(r.error < 1e-6, "error {}", r.error);
            let cos_a = (l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d);
            let a = cos_a.clamp(-1.0, 1.0).acos();
            let knee = (w * a.cos() + p * a.sin()) * l1;
            prop_assert!((pts[1] - knee).length() < 1e-4, "knee {:?} vs {:?}", pts[1], knee);
        }
    }

    #[test]
    fn stretches_towards_unreachable_targets() {
        let mut pts = [DVec3::ZERO, DVec3::Y, DVec3::new(1.0, 1.0, 0.0)];
        let r = Fabrik::default().solve(&mut pts, DVec3::new(0.0, 0.0, 5.0), None);
        assert!(r.out_of_reach);
        assert!((r.error - 3.0).abs() < 1e-12);
        assert!((pts[2] - DVec3::new(0.0, 0.0, 2.0)).length() < 1e-12);
    }
}
