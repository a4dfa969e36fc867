//! Rotation helpers: Euler channels <-> quaternions, axis-angle.

use glam::{DQuat, DVec3};

use crate::skeleton::Axis;

/// Compose rotation channels in file order: `R = R(axes[0], a0) * R(axes[1], a1) * ...`
/// (the BVH and ASF convention: the first listed channel is the outermost).
pub fn from_channels(axes: &[Axis], angles_rad: &[f64]) -> DQuat {
    axes.iter()
        .zip(angles_rad)
        .fold(DQuat::IDENTITY, |q, (axis, angle)| {
            q * DQuat::from_axis_angle(axis.unit(), *angle)
        })
}

/// Rotation vector (axis * angle, angle in [0, pi]) of a unit quaternion.
pub fn to_rotation_vector(q: DQuat) -> DVec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let (axis, angle) = q.to_axis_angle();
    if angle.abs() < 1e-12 {
        DVec3::ZERO
    } else {
        axis * angle
    }
}

/// Angle of the rotation between two unit quaternions, in [0, pi].
pub fn angle_between(a: DQuat, b: DQuat) -> f64 {
    let d = a.dot(b).abs().min(1.0);
    2.0 * d.acos()
}
