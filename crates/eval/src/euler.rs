//! Euler angles of every non-root joint: the representation MotionAug evaluates
//! in ("Euclidean distance in the Euler angle in the radian scale ... all joints
//! except a root joint", Sec. 4.1 and 4.3), shared by DTW, MMD and the prediction
//! error so the three agree on one convention.
//!
//! Convention: the angles of the file's own rotation channels. For a joint
//! read from ASF with `limits` (every HDM05 joint with degrees of freedom) that
//! is the AMC file's angles: the local rotation `L` is taken back to the bone's
//! axis frame (`C^-1 L C`) and decomposed into its `dof` axes, so a knee is one
//! flexion angle, as in the data. Other joints use their rotation channels (BVH)
//! and, failing those, Z, Y, X angles of `L`. Each joint has three slots (unused
//! slots are zero), radians, computed by [`motion::rotation::to_channels`].
//! Differences of angles are wrapped into (-pi, pi], so a joint turning through
//! +-pi is not counted as a 2 pi error. The root joint (its world orientation and
//! position) is excluded.

use motion::glam::DQuat;
use motion::rotation::{channels_span_all_rotations, to_channels, wrap_pi};
use motion::{Axis, Channel, Motion, Skeleton};

use crate::error::{EvalError, Result};

/// Decomposition order when a joint has no channels of its own (outermost first).
pub const ORDER: [Axis; 3] = [Axis::Z, Axis::Y, Axis::X];

/// How each non-root joint of one skeleton turns into angles.
#[derive(Debug, Clone, PartialEq)]
pub struct Convention {
    /// Per non-root joint: the frame `C` and the channel axes.
    joints: Vec<(DQuat, Vec<Axis>)>,
}

impl Convention {
    pub fn of(skeleton: &Skeleton) -> Convention {
        let joints = skeleton
            .joints()
            .iter()
            .skip(1)
            .map(|j| {
                if let Some(l) = &j.limits {
                    return (l.frame, l.dofs.iter().map(|d| d.0).take(3).collect());
                }
                let axes: Vec<Axis> = j
                    .channels
                    .iter()
                    .filter_map(|c| match c {
                        Channel::Rotation(a) => Some(*a),
                        Channel::Position(_) => None,
                    })
                    .collect();
                if channels_span_all_rotations(&axes) {
                    (DQuat::IDENTITY, axes)
                } else {
                    (DQuat::IDENTITY, ORDER.to_vec())
                }
            })
            .collect();
        Convention { joints }
    }

    /// Angles of one non-root joint (index `j` counts from the first non-root
    /// joint), three slots.
    pub fn joint(&self, j: usize, local: DQuat) -> [f64; 3] {
        let (frame, axes) = &self.joints[j];
        let m = frame.inverse() * local * *frame;
        let mut out = [0.0; 3];
        for (o, a) in out.iter_mut().zip(to_channels(m, axes)) {
            *o = a;
        }
        out
    }

    /// Angles of every non-root joint of a pose (root first, as in [`Motion::pose`]).
    pub fn pose(&self, pose: &[DQuat]) -> Vec<f64> {
        pose.iter()
            .skip(1)
            .enumerate()
            .flat_map(|(j, q)| self.joint(j, *q))
            .collect()
    }
}

/// One clip as Euler angles: `frames` rows of `dim = 3 (J - 1)` values.
#[derive(Debug, Clone, PartialEq)]
pub struct EulerClip {
    pub dim: usize,
    pub frames: usize,
    /// Row-major `[frame][joint - 1][3 slots]`.
    pub data: Vec<f64>,
}

impl EulerClip {
    pub fn of(motion: &Motion) -> EulerClip {
        let conv = Convention::of(motion.skeleton());
        let dim = 3 * motion.joints().saturating_sub(1);
        let mut data = Vec::with_capacity(motion.frames() * dim);
        for t in 0..motion.frames() {
            data.extend(conv.pose(motion.pose(t)));
        }
        EulerClip {
            dim,
            frames: motion.frames(),
            data,
        }
    }

    pub fn frame(&self, t: usize) -> &[f64] {
        &self.data[t * self.dim..(t + 1) * self.dim]
    }
}

/// Euclidean norm of the wrapped angle differences (all joints together): the
/// motion prediction error of one frame.
pub fn l2_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| wrap_pi(x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Sum over joints of the Euclidean norm of each joint's three wrapped angle
/// differences: MotionAug's frame distance for DTW ("the sum over all joints
/// except a root joint").
pub fn joint_sum_distance(a: &[f64], b: &[f64]) -> f64 {
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(x, y)| l2_distance(x, y))
        .sum()
}

/// Errors unless `b` has the joints of `a` (same names, same order): angles of
/// different skeleton layouts cannot be compared.
pub fn check_same_layout(a: &Skeleton, b: &Skeleton, what: &str) -> Result<()> {
    let same = a.len() == b.len()
        && a.joints()
            .iter()
            .zip(b.joints())
            .all(|(x, y)| x.name == y.name);
    if same {
        Ok(())
    } else {
        Err(EvalError::Data(format!(
            "{what}: skeleton has joints [{}], expected [{}]",
            names(b),
            names(a)
        )))
    }
}

fn names(s: &Skeleton) -> String {
    s.joints()
        .iter()
        .map(|j| j.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::rotation::from_channels;

    #[test]
    fn decomposition_round_trips_and_wraps() {
        let q = from_channels(&ORDER, &[0.3, -0.4, 2.5]);
        let a = to_channels(q, &ORDER);
        assert!(
            (a[0] - 0.3).abs() < 1e-9 && (a[1] + 0.4).abs() < 1e-9 && (a[2] - 2.5).abs() < 1e-9
        );
        // pi - 0.1 and -pi + 0.1 are 0.2 apart, not 2 pi - 0.2.
        let d = l2_distance(
            &[std::f64::consts::PI - 0.1],
            &[-std::f64::consts::PI + 0.1],
        );
        assert!((d - 0.2).abs() < 1e-9);
        // Per-joint sum vs whole-vector norm.
        let (x, y) = ([0.0; 6], [0.3, 0.4, 0.0, 0.0, 0.0, 0.1]);
        assert!((joint_sum_distance(&x, &y) - 0.6).abs() < 1e-9);
        assert!((l2_distance(&x, &y) - 0.26f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn asf_joints_use_the_amc_channels() {
        let m = crate::example_kick();
        let e = EulerClip::of(&m);
        let knee = m.skeleton().find("ltibia").unwrap() - 1;
        let mut bent = 0.0f64;
        for t in 0..e.frames {
            let k = &e.frame(t)[3 * knee..3 * knee + 3];
            // One degree of freedom (rx): one angle, the other slots empty.
            assert!(k[1].abs() < 1e-9 && k[2].abs() < 1e-9, "{k:?}");
            bent = bent.max(k[0].abs());
        }
        assert!(bent > 0.5, "a kick bends the knee: {bent}");
    }
}
