//! Joint limits from the source file (ASF `dof` + `limits`), as far as the IK uses them.
//!
//! A limited rotation `r = frame^-1 * local * frame` is decomposed into Euler
//! angles about the joint's dof axes in file order, followed by the locked axes
//! (which should be zero). Clamping keeps every angle inside the file's range,
//! widened to include the source pose's own angle: mocap often sits slightly
//! outside its nominal limits, and the IK must not snap such a frame when it
//! barely moves it.

use glam::DQuat;
use motion::{Axis, JointLimits, rotation};

/// Angles `[a, b, c]` with `q = R(order[0], a) R(order[1], b) R(order[2], c)`;
/// the axes must be distinct. The Euler maths is the motion crate's.
pub fn decompose(q: DQuat, order: [Axis; 3]) -> [f64; 3] {
    let angles = rotation::to_channels(q, &order);
    [angles[0], angles[1], angles[2]]
}

pub fn compose(angles: [f64; 3], order: [Axis; 3]) -> DQuat {
    rotation::from_channels(&order, &angles)
}

/// The dof axes followed by the locked ones; `None` if the dofs repeat an axis.
fn order(limits: &JointLimits) -> Option<(usize, [Axis; 3])> {
    let mut axes: Vec<Axis> = limits.dofs.iter().map(|d| d.0).collect();
    if axes.len() > 3 {
        return None;
    }
    for a in [Axis::X, Axis::Y, Axis::Z] {
        if !axes.contains(&a) {
            axes.push(a);
        }
    }
    if axes.len() != 3 {
        return None;
    }
    Some((limits.dofs.len(), [axes[0], axes[1], axes[2]]))
}

/// Angle tolerance of the limit test, radians.
pub const SLACK: f64 = 1e-6;

/// Remove from `local` the rotation about the axes the file locks (keeping any
/// the source pose itself has), leaving the dof angles as they are. Real
/// skeletons are not exactly hinge-consistent (an HDM05 forearm is ~1e-3 rad off
/// the elbow's plane), so a hinge solved in positions picks up ~1e-4 rad about
/// locked axes; this puts it back on the file's hinge.
pub fn project_to_dofs(local: DQuat, original: DQuat, limits: &JointLimits) -> DQuat {
    let Some((free, order)) = order(limits) else {
        return local;
    };
    if free == 3 {
        return local;
    }
    let to_limited = |q: DQuat| limits.frame.inverse() * q * limits.frame;
    let mut ang = decompose(to_limited(local), order);
    let orig = decompose(to_limited(original), order);
    for i in free..3 {
        ang[i] = ang[i].clamp(orig[i].min(0.0), orig[i].max(0.0));
    }
    (limits.frame * compose(ang, order) * limits.frame.inverse()).normalize()
}

/// How far (radians, summed over axes) `local` lies outside `limits` widened by
/// `original`; 0 inside.
pub fn excess(local: DQuat, original: DQuat, limits: &JointLimits) -> f64 {
    let Some((free, order)) = order(limits) else {
        return 0.0;
    };
    let to_limited = |q: DQuat| limits.frame.inverse() * q * limits.frame;
    let ang = decompose(to_limited(local), order);
    let orig = decompose(to_limited(original), order);
    (0..3)
        .map(|i| {
            let (lo, hi) = if i < free {
                (limits.dofs[i].1, limits.dofs[i].2)
            } else {
                (0.0, 0.0)
            };
            let (lo, hi) = (lo.min(orig[i]) - SLACK, hi.max(orig[i]) + SLACK);
            (lo - ang[i]).max(0.0) + (ang[i] - hi).max(0.0)
        })
        .sum()
}

/// Clamp `local` to `limits` widened by `original`. Returns the clamped rotation
/// and whether it changed. Joints whose dofs repeat an axis are left alone.
pub fn clamp(local: DQuat, original: DQuat, limits: &JointLimits) -> (DQuat, bool) {
    let Some((free, order)) = order(limits) else {
        return (local, false);
    };
    let to_limited = |q: DQuat| limits.frame.inverse() * q * limits.frame;
    let mut ang = decompose(to_limited(local), order);
    let orig = decompose(to_limited(original), order);
    let mut changed = false;
    for i in 0..3 {
        let (lo, hi) = if i < free {
            (limits.dofs[i].1, limits.dofs[i].2)
        } else {
            (0.0, 0.0)
        };
        // 1e-6 rad of slack: the bend-plane solve keeps a hinge to ~1e-9 rad,
        // which must not count as leaving a locked axis.
        let (lo, hi) = (lo.min(orig[i]) - SLACK, hi.max(orig[i]) + SLACK);
        if ang[i] < lo || ang[i] > hi {
            ang[i] = ang[i].clamp(lo, hi);
            changed = true;
        }
    }
    if !changed {
        return (local, false);
    }
    let r = compose(ang, order);
    (
        (limits.frame * r * limits.frame.inverse()).normalize(),
        true,
    )
}

/// The single hinge axis of a one-dof joint, in the joint's parent frame.
pub fn hinge_axis(limits: &JointLimits) -> Option<glam::DVec3> {
    match limits.dofs.as_slice() {
        [(axis, _, _)] => Some(limits.frame * axis.unit()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::rotation::angle_between;

    #[test]
    fn decompose_inverts_compose_for_every_order() {
        use Axis::*;
        let orders = [
            [X, Y, Z],
            [X, Z, Y],
            [Y, X, Z],
            [Y, Z, X],
            [Z, X, Y],
            [Z, Y, X],
        ];
        for order in orders {
            for a in [
                [0.3, -0.7, 1.2],
                [-2.5, 1.2, 0.1],
                [0.0, 0.0, 0.0],
                [1.0, -1.4, -3.0],
            ] {
                let q = compose(a, order);
                let b = decompose(q, order);
                assert!(
                    angle_between(q, compose(b, order)) < 1e-9,
                    "{order:?} {a:?}"
                );
                for i in 0..3 {
                    assert!((a[i] - b[i]).abs() < 1e-9, "{order:?} {a:?} -> {b:?}");
                }
            }
        }
    }

    #[test]
    fn clamps_to_limits_widened_by_the_original() {
        let knee = JointLimits {
            frame: DQuat::from_rotation_z(0.35),
            dofs: vec![(Axis::X, -0.17, 2.97)],
        };
        let f = knee.frame;
        let bend = |a: f64| f * DQuat::from_rotation_x(a) * f.inverse();
        let (q, changed) = clamp(bend(3.1), bend(1.0), &knee);
        assert!(changed);
        assert!(angle_between(q, bend(2.97)) < 1e-5);
        let (q, changed) = clamp(bend(-0.3), bend(-0.25), &knee);
        assert!(changed && angle_between(q, bend(-0.25)) < 1e-5);
        let (_, changed) = clamp(bend(1.5), bend(1.0), &knee);
        assert!(!changed);
        // A locked axis (y) is pushed back to zero.
        let (q, changed) = clamp(bend(1.0) * DQuat::from_rotation_y(0.2), bend(1.0), &knee);
        assert!(changed);
        let a = decompose(f.inverse() * q * f, [Axis::X, Axis::Y, Axis::Z]);
        assert!(
            a[1].abs() < 2.0 * SLACK && a[2].abs() < 2.0 * SLACK,
            "{a:?}"
        );
        assert!((hinge_axis(&knee).unwrap() - f * glam::DVec3::X).length() < 1e-12);
    }
}
