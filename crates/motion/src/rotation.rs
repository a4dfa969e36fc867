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

/// Heading of a root rotation: the angle about +y of its forward (+z) axis
/// projected on the ground plane (0 when it faces +z). A root facing straight
/// up or down uses its up axis' projection instead.
pub fn heading(root_rotation: DQuat) -> f64 {
    let f = root_rotation * DVec3::Z;
    if f.x.abs() < 1e-9 && f.z.abs() < 1e-9 {
        let u = root_rotation * DVec3::Y;
        return u.x.atan2(u.z);
    }
    f.x.atan2(f.z)
}

/// The continuous 6D representation of a rotation (Zhou et al. 2019): the first
/// two columns of its matrix, `[x axis, y axis]`.
pub fn to_6d(q: DQuat) -> [f64; 6] {
    let a = q * DVec3::X;
    let b = q * DVec3::Y;
    [a.x, a.y, a.z, b.x, b.y, b.z]
}

/// The rotation nearest a 6D vector (Gram-Schmidt on its two 3-vectors).
/// Degenerate inputs (zero or parallel columns) fall back to the nearest
/// well-defined axis, so the result is always a rotation.
pub fn from_6d(v: &[f64; 6]) -> DQuat {
    let a = DVec3::new(v[0], v[1], v[2]);
    let b = DVec3::new(v[3], v[4], v[5]);
    let x = a.try_normalize().unwrap_or(DVec3::X);
    let mut y = b - x * x.dot(b);
    if y.length_squared() < 1e-18 {
        y = x.any_orthonormal_vector();
    }
    let y = y.normalize();
    let z = x.cross(y);
    DQuat::from_mat3(&glam::DMat3::from_cols(x, y, z)).normalize()
}

/// Angle of the rotation between two unit quaternions, in [0, pi].
///
/// Computed as `2 atan2(|v|, |w|)` of `a^-1 b`, which keeps full precision for
/// tiny angles (an `acos` of the dot product cannot resolve angles below ~1e-8).
pub fn angle_between(a: DQuat, b: DQuat) -> f64 {
    let d = a.conjugate() * b;
    2.0 * d.xyz().length().atan2(d.w.abs())
}

/// The glam Euler sequence whose `from_euler(order, a, b, c)` equals
/// `from_channels(&[a0, a1, a2], &[a, b, c])`, when the three axes have one
/// (glam names intrinsic sequences in the same outermost-first order).
fn euler_order(axes: [Axis; 3]) -> Option<glam::EulerRot> {
    use Axis::{X, Y, Z};
    use glam::EulerRot as E;
    Some(match axes {
        [X, Y, Z] => E::XYZ,
        [X, Z, Y] => E::XZY,
        [Y, X, Z] => E::YXZ,
        [Y, Z, X] => E::YZX,
        [Z, X, Y] => E::ZXY,
        [Z, Y, X] => E::ZYX,
        [X, Y, X] => E::XYX,
        [X, Z, X] => E::XZX,
        [Y, X, Y] => E::YXY,
        [Y, Z, Y] => E::YZY,
        [Z, X, Z] => E::ZXZ,
        [Z, Y, Z] => E::ZYZ,
        _ => return None,
    })
}

/// Whether three channels on `axes` can express every rotation (Tait-Bryan
/// like ZYX or proper Euler like ZXZ), so [`to_channels`] is always exact.
pub fn channels_span_all_rotations(axes: &[Axis]) -> bool {
    axes.len() == 3 && euler_order([axes[0], axes[1], axes[2]]).is_some()
}

/// The first axis not in `used` (X, then Y, then Z).
fn missing_axis(used: &[Axis]) -> Axis {
    [Axis::X, Axis::Y, Axis::Z]
        .into_iter()
        .find(|a| !used.contains(a))
        .unwrap_or(Axis::X)
}

/// Signed angle of the twist of `q` about `axis` (swing-twist decomposition),
/// in (-pi, pi]: the best single-axis approximation of `q`.
fn twist_angle(q: DQuat, axis: Axis) -> f64 {
    let v = q.xyz().dot(axis.unit());
    let a = 2.0 * v.atan2(q.w);
    wrap_pi(a)
}

/// Wrap an angle into (-pi, pi].
pub fn wrap_pi(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let mut r = a % TAU;
    if r <= -PI {
        r += TAU;
    } else if r > PI {
        r -= TAU;
    }
    r
}

/// Angles (radians) of the rotation channels `axes` that reproduce `q`
/// through [`from_channels`]; the inverse of [`from_channels`].
///
/// * Three axes (distinct, or first = last as in ZXZ): exact, through glam's
///   Euler decomposition.
/// * One or two axes, or three with two neighbours equal: exact whenever `q` is
///   representable by those channels (it always is for channels read from a
///   file); otherwise the channels of the closest decomposition found, and the
///   caller should check with [`from_channels`] (the BVH writer adds the missing
///   channels in that case).
/// * No axes: an empty vector.
///
/// Angles are in (-pi, pi]; use [`to_channels_near`] for frame-to-frame continuity.
pub fn to_channels(q: DQuat, axes: &[Axis]) -> Vec<f64> {
    match axes.len() {
        0 => Vec::new(),
        1 => vec![twist_angle(q, axes[0])],
        2 => {
            // Decompose with a third axis appended, drop it: exact when the third
            // angle is zero (q representable), a close guess otherwise; then
            // refine so the result is the best two-angle fit.
            let third = missing_axis(axes);
            let three = [axes[0], axes[1], third];
            let (a, b) = match euler_order(three) {
                Some(order) => {
                    // Of the two Euler solutions (a, b, c) and (a + pi, pi - b,
                    // c + pi), keep the one whose dropped third angle is smaller.
                    let (a, b, c) = q.to_euler(order);
                    let pi = std::f64::consts::PI;
                    if wrap_pi(c + pi).abs() < c.abs() {
                        (a + pi, pi - b)
                    } else {
                        (a, b)
                    }
                }
                None => (twist_angle(q, axes[0]), 0.0),
            };
            refine(q, axes, vec![a, b])
        }
        3 => match euler_order([axes[0], axes[1], axes[2]]) {
            Some(order) => {
                let (a, b, c) = q.to_euler(order);
                vec![a, b, c]
            }
            None => {
                // Two neighbouring channels on the same axis (e.g. Z Z X): they
                // act as one channel; decompose with the merged pair.
                let (merged, split_at) = if axes[0] == axes[1] {
                    ([axes[0], axes[2]], 0)
                } else {
                    ([axes[0], axes[1]], 1)
                };
                let two = to_channels(q, &merged);
                let mut out = vec![0.0; 3];
                if split_at == 0 {
                    out[0] = two[0];
                    out[2] = two[1];
                } else {
                    out[0] = two[0];
                    out[1] = two[1];
                }
                out
            }
        },
        _ => {
            // More than three rotation channels: put the rotation in the first
            // three distinct-enough ones, zeros elsewhere.
            let mut out = vec![0.0; axes.len()];
            let head = to_channels(q, &axes[..3]);
            out[..3].copy_from_slice(&head);
            out
        }
    }
}

/// A few Gauss-Newton steps on the rotation error of a 1-2 channel fit
/// (numerical Jacobian: the problem is tiny). Leaves exact fits untouched.
fn refine(q: DQuat, axes: &[Axis], mut angles: Vec<f64>) -> Vec<f64> {
    let err = |ang: &[f64]| {
        let r = from_channels(axes, ang);
        let d = if r.dot(q) < 0.0 { -r } else { r };
        to_rotation_vector(d.inverse() * q)
    };
    for _ in 0..8 {
        let e = err(&angles);
        if e.length() < 1e-13 {
            break;
        }
        // J columns: derivative of the error vector for each angle.
        let h = 1e-7;
        let mut cols = Vec::with_capacity(angles.len());
        for i in 0..angles.len() {
            let mut p = angles.clone();
            p[i] += h;
            cols.push((err(&p) - e) / h);
        }
        // Solve the normal equations (1x1 or 2x2).
        let step: Vec<f64> = if cols.len() == 1 {
            let jj = cols[0].dot(cols[0]);
            if jj < 1e-18 {
                break;
            }
            vec![-cols[0].dot(e) / jj]
        } else {
            let (a, b, d) = (
                cols[0].dot(cols[0]),
                cols[0].dot(cols[1]),
                cols[1].dot(cols[1]),
            );
            let det = a * d - b * b;
            if det.abs() < 1e-18 {
                break;
            }
            let (g0, g1) = (cols[0].dot(e), cols[1].dot(e));
            vec![-(d * g0 - b * g1) / det, -(a * g1 - b * g0) / det]
        };
        let before = e.length();
        let trial: Vec<f64> = angles.iter().zip(&step).map(|(a, s)| a + s).collect();
        if err(&trial).length() < before {
            angles = trial;
        } else {
            break;
        }
    }
    angles.into_iter().map(wrap_pi).collect()
}

/// Like [`to_channels`], but among the equivalent angle sets (the second Euler
/// solution, multiples of 2 pi) picks the one closest to `previous`, so curves
/// of consecutive frames have no jumps. `previous` must have `axes.len()` values.
pub fn to_channels_near(q: DQuat, axes: &[Axis], previous: &[f64]) -> Vec<f64> {
    use std::f64::consts::PI;
    let base = to_channels(q, axes);
    if previous.len() != base.len() {
        return base;
    }
    let mut candidates = vec![base.clone()];
    if base.len() == 3 {
        let proper = axes[0] == axes[2] && axes[0] != axes[1];
        let distinct = axes[0] != axes[1] && axes[1] != axes[2] && axes[0] != axes[2];
        if distinct {
            // R(a) R(b) R(c) == R(a + pi) R(pi - b) R(c + pi) for Tait-Bryan angles.
            candidates.push(vec![base[0] + PI, PI - base[1], base[2] + PI]);
        } else if proper {
            // ... and R(a + pi) R(-b) R(c + pi) for proper Euler angles.
            candidates.push(vec![base[0] + PI, -base[1], base[2] + PI]);
        }
    }
    let unwrap = |v: &[f64]| -> Vec<f64> {
        v.iter()
            .zip(previous)
            .map(|(a, p)| a + (std::f64::consts::TAU * ((p - a) / std::f64::consts::TAU).round()))
            .collect()
    };
    candidates
        .iter()
        .map(|c| unwrap(c))
        .min_by(|a, b| {
            let da: f64 = a.iter().zip(previous).map(|(x, p)| (x - p).abs()).sum();
            let db: f64 = b.iter().zip(previous).map(|(x, p)| (x - p).abs()).sum();
            da.total_cmp(&db)
        })
        .unwrap_or(base)
}

#[cfg(test)]
mod tests {
    use super::*;
    use Axis::{X, Y, Z};

    fn close(a: DQuat, b: DQuat, tol: f64) -> bool {
        angle_between(a, b) < tol
    }

    #[test]
    fn from_channels_is_outermost_first() {
        let q = from_channels(&[Z, Y, X], &[0.3, -0.2, 0.5]);
        let expected = DQuat::from_rotation_z(0.3)
            * DQuat::from_rotation_y(-0.2)
            * DQuat::from_rotation_x(0.5);
        assert!(close(q, expected, 1e-12));
    }

    #[test]
    fn three_axis_orders_round_trip() {
        let angle_sets = [
            [0.3, -0.2, 0.5],
            [2.9, 1.5, -3.0],
            [-1.0, std::f64::consts::FRAC_PI_2 - 1e-7, 0.4],
        ];
        for axes in [
            [X, Y, Z],
            [X, Z, Y],
            [Y, X, Z],
            [Y, Z, X],
            [Z, X, Y],
            [Z, Y, X],
            [Z, X, Z],
            [Y, X, Y],
            [Z, Z, X],
            [X, Y, Y],
        ] {
            for angles in angle_sets {
                let q = from_channels(&axes, &angles);
                let back = to_channels(q, &axes);
                // Next to gimbal lock (middle angle ~90 degrees) glam's
                // decomposition keeps ~1e-8 rad; elsewhere ~1e-15.
                assert!(
                    close(from_channels(&axes, &back), q, 1e-7),
                    "{axes:?} {angles:?} -> {back:?}"
                );
            }
        }
    }

    #[test]
    fn one_and_two_axes_are_exact_when_representable() {
        let q = from_channels(&[Y], &[2.5]);
        assert!((to_channels(q, &[Y])[0] - 2.5).abs() < 1e-12);
        for axes in [[Z, X], [X, Z], [Y, X], [X, Y]] {
            let q = from_channels(&axes, &[0.7, -1.2]);
            let back = to_channels(q, &axes);
            assert!(
                close(from_channels(&axes, &back), q, 1e-9),
                "{axes:?} {back:?}"
            );
        }
        // Not representable: the fit is still the closest single-axis rotation.
        // Middle angle beyond 90 degrees: the other Euler branch.
        let q = from_channels(&[Y, X], &[0.0, 3.2368879402304476]);
        let back = to_channels(q, &[Y, X]);
        assert!(close(from_channels(&[Y, X], &back), q, 1e-9), "{back:?}");
        let q = from_channels(&[X, Y], &[0.3, 0.4]);
        let only_x = to_channels(q, &[X]);
        assert!((only_x[0] - 0.3).abs() < 0.1);
    }

    #[test]
    fn near_picks_the_continuous_branch() {
        let axes = [Z, Y, X];
        let prev = [3.1, 0.2, -3.1];
        let q = from_channels(&axes, &[3.15, 0.21, -3.15]);
        let got = to_channels_near(q, &axes, &prev);
        for (g, p) in got.iter().zip(prev) {
            assert!((g - p).abs() < 0.1, "{got:?}");
        }
        assert!(close(from_channels(&axes, &got), q, 1e-9));
    }
}
