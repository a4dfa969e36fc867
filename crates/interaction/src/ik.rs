//! Rotations from positions: turn solved point positions back into joint
//! rotations on a skeleton, so bone lengths are exact by construction.
//!
//! Joints are visited root first. Each joint's world rotation is chosen so that
//! its rigid set (see [`crate::layout`]) points from the joint's *actual* (FK)
//! position at the target points: aiming from where the joint really is stops
//! small length errors from piling up along a chain. Starting from the source
//! rotation carried by the new parent (which keeps the source's twist):
//!
//! * no target (a leaf without end site) or a locked joint: keep it;
//! * targets along one line: the smallest rotation taking the longest vector's
//!   direction onto its target direction (twist about the bone unchanged);
//! * targets spanning a plane or more: the best-fit rotation of the vectors onto
//!   the targets, Kabsch's algorithm (W. Kabsch, "A solution for the best
//!   rotation to relate two sets of vectors", Acta Cryst. A32, 1976), by a 3x3
//!   SVD with the reflection fix.

use glam::{DMat3, DQuat, DVec3};
use motion::Skeleton;
use nalgebra::Matrix3;

use crate::layout::Layout;

/// Vectors shorter than this (metres) carry no direction.
const TINY: f64 = 1e-9;
/// Targets whose directions are this close to one line (sine of the largest
/// angle between them) are treated as one direction.
const COLLINEAR_SIN: f64 = 1e-3;

/// The smallest rotation taking direction `from` onto direction `to` (both
/// non-zero). Opposite directions turn half way about an axis perpendicular to `from`.
pub fn arc(from: DVec3, to: DVec3) -> DQuat {
    DQuat::from_rotation_arc(from.normalize(), to.normalize())
}

/// Best-fit rotation `R` minimising `sum w |R u - d|^2` (Kabsch), for vectors
/// that span at least a plane. Returns `None` when they do not.
pub fn kabsch(pairs: &[(DVec3, DVec3, f64)]) -> Option<DQuat> {
    let mut h = Matrix3::<f64>::zeros();
    for (u, d, w) in pairs {
        for r in 0..3 {
            for c in 0..3 {
                h[(r, c)] += w * u[r] * d[c];
            }
        }
    }
    let svd = h.try_svd(true, true, 1e-14, 200)?;
    let (u, v_t) = (svd.u?, svd.v_t?);
    let v = v_t.transpose();
    // Rank check: the two largest singular values must be clearly non-zero.
    let mut s: Vec<f64> = svd.singular_values.iter().copied().collect();
    s.sort_by(|a, b| b.total_cmp(a));
    if s[0] <= 0.0 || s[1] < COLLINEAR_SIN * s[0] {
        return None;
    }
    let det = (v * u.transpose()).determinant();
    let mut fix = Matrix3::<f64>::identity();
    fix[(2, 2)] = if det < 0.0 { -1.0 } else { 1.0 };
    let r = v * fix * u.transpose();
    let m = DMat3::from_cols(
        DVec3::new(r[(0, 0)], r[(1, 0)], r[(2, 0)]),
        DVec3::new(r[(0, 1)], r[(1, 1)], r[(2, 1)]),
        DVec3::new(r[(0, 2)], r[(1, 2)], r[(2, 2)]),
    );
    let q = DQuat::from_mat3(&m).normalize();
    q.is_finite().then_some(q)
}

/// The world rotation that aims `pairs` (vector in the joint frame, target
/// world vector) starting from `start` (see the module doc).
pub fn aim(start: DQuat, pairs: &[(DVec3, DVec3)]) -> DQuat {
    let used: Vec<(DVec3, DVec3, f64)> = pairs
        .iter()
        .filter(|(v, d)| v.length() > TINY && d.length() > TINY)
        .map(|(v, d)| (start * *v, *d, 1.0))
        .collect();
    let Some(longest) = used
        .iter()
        .max_by(|a, b| a.0.length_squared().total_cmp(&b.0.length_squared()))
    else {
        return start;
    };
    let spread = used
        .iter()
        .any(|(u, _, _)| u.normalize().cross(longest.0.normalize()).length() > COLLINEAR_SIN);
    if spread {
        // Kabsch on unit directions: every target counts the same whatever its length.
        let dirs: Vec<(DVec3, DVec3, f64)> = used
            .iter()
            .map(|(u, d, w)| (u.normalize(), d.normalize(), *w))
            .collect();
        if let Some(r) = kabsch(&dirs) {
            return (r * start).normalize();
        }
    }
    (arc(longest.0, longest.1) * start).normalize()
}

/// Local rotations (written into `pose`) and root position placing `skeleton`
/// as close as possible to `points` (laid out by `layout`, which must have been
/// built for `skeleton`), starting from the source pose `source` for twists and
/// for locked joints.
pub fn pose_from_points(
    skeleton: &Skeleton,
    layout: &Layout,
    source: &[DQuat],
    points: &[DVec3],
    pose: &mut [DQuat],
) -> DVec3 {
    let n = skeleton.len();
    let mut world = vec![DQuat::IDENTITY; n];
    let mut pos = vec![DVec3::ZERO; n];
    let root = points[layout.joint_point[0]];
    let mut pairs = Vec::new();
    for j in 0..n {
        let (parent_rot, here) = match skeleton.parent(j) {
            None => (DQuat::IDENTITY, root),
            Some(p) => (world[p], pos[p] + world[p] * skeleton.joint(j).offset),
        };
        pos[j] = here;
        let start = (parent_rot * source[j]).normalize();
        world[j] = if layout.locked[j] {
            start
        } else {
            pairs.clear();
            pairs.extend(layout.rigid[j].iter().map(|&(p, v)| (v, points[p] - here)));
            aim(start, &pairs)
        };
        pose[j] = (parent_rot.inverse() * world[j]).normalize();
    }
    root
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::tests::{cmu_like, cmu_locks};
    use motion::Motion;
    use proptest::prelude::*;
    use std::sync::Arc;

    fn quat(a: [f64; 3]) -> DQuat {
        DQuat::from_scaled_axis(DVec3::from_array(a))
    }

    fn arb_pose(n: usize) -> impl Strategy<Value = Vec<[f64; 3]>> {
        prop::collection::vec(prop::array::uniform3(-1.5f64..1.5), n)
    }

    proptest! {
        #[test]
        fn kabsch_recovers_a_rotation(a in prop::array::uniform3(-3.0f64..3.0),
                                      vs in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 3..6)) {
            let r = quat(a);
            let pairs: Vec<(DVec3, DVec3, f64)> = vs.iter().map(|v| {
                let v = DVec3::from_array(*v);
                (v, r * v, 1.0)
            }).collect();
            // Skip near-degenerate draws (all vectors on one line).
            prop_assume!(kabsch(&pairs).is_some());
            let q = kabsch(&pairs).unwrap();
            prop_assert!(motion::rotation::angle_between(q, r) < 1e-6);
        }

        /// FK -> points -> rotations -> FK reproduces every point, and every
        /// joint whose rotation the points determine gets its rotation back.
        #[test]
        fn rotations_from_positions_round_trip(pose in arb_pose(30), twist in arb_pose(30),
                                               root in prop::array::uniform3(-2.0f64..2.0)) {
            let s = Arc::new(cmu_like());
            let locks = cmu_locks(&s);
            let mut q: Vec<DQuat> = pose.iter().map(|a| quat(*a)).collect();
            for (j, l) in locks.iter().enumerate() { if *l { q[j] = DQuat::IDENTITY; } }
            let layout = Layout::new(&s, &locks, &vec![DQuat::IDENTITY; s.len()]);
            let m = Motion::new(s.clone(), 30.0, vec![DVec3::from_array(root)], q.clone()).unwrap();
            let mut pts = Vec::new();
            layout.positions(&m, 0, &mut pts);
            // A different source pose: twists differ, locked joints agree.
            let mut source: Vec<DQuat> = twist.iter().map(|a| quat(*a)).collect();
            for (j, l) in locks.iter().enumerate() { if *l { source[j] = DQuat::IDENTITY; } }
            let mut out = vec![DQuat::IDENTITY; s.len()];
            let r = pose_from_points(&s, &layout, &source, &pts, &mut out);
            let back = Motion::new(s.clone(), 30.0, vec![r], out.clone()).unwrap();
            let mut pts2 = Vec::new();
            layout.positions(&back, 0, &mut pts2);
            for (a, b) in pts.iter().zip(&pts2) {
                prop_assert!((*a - *b).length() < 1e-9, "{a} vs {b}");
            }
            // With the true pose as the source, rotations come back too.
            let r2 = pose_from_points(&s, &layout, &q, &pts, &mut out);
            prop_assert!((r2 - DVec3::from_array(root)).length() < 1e-12);
            for j in 0..s.len() {
                prop_assert!(motion::rotation::angle_between(out[j], q[j]) < 1e-6, "joint {j}");
            }
        }
    }

    #[test]
    fn aim_keeps_twist_for_one_direction() {
        let start = DQuat::from_rotation_y(0.7);
        let q = aim(start, &[(DVec3::X, DVec3::X)]);
        // The target is already where start sends X? No: start sends X elsewhere;
        // the result sends X onto the target and differs from start by a pure arc.
        assert!(((q * DVec3::X) - DVec3::X).length() < 1e-12);
        let same = aim(start, &[(DVec3::X, start * DVec3::X * 2.0)]);
        assert!(motion::rotation::angle_between(same, start) < 1e-12);
    }
}
