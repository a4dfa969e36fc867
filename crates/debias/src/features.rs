//! Per-frame features for the debiasing MLP.
//!
//! A frame's *state* is `[root height, root velocity (3, heading frame, m/s),
//! root tilt (6D, heading removed), joint rotations (6D each, local)]`; the
//! network sees the state and its difference to the previous frame and predicts
//! a change of the state. Removing the heading keeps the features the same for
//! a clip walked in any direction, so the network learns the bias, not the route;
//! the corrected clip keeps its own heading and horizontal path, integrated from
//! the debiased velocities.

use motion::Motion;
use motion::glam::{DQuat, DVec3};
use motion::rotation::{from_6d, heading, to_6d};

/// Numbers per frame state for `joints` joints (root tilt counts as one joint).
pub fn state_dim(joints: usize) -> usize {
    4 + 6 * joints
}

/// Input numbers per frame: the state and its frame difference.
pub fn input_dim(joints: usize) -> usize {
    2 * state_dim(joints)
}

/// Root velocity at frame `t` (backward difference; forward at frame 0), m/s.
fn root_velocity(motion: &Motion, t: usize) -> DVec3 {
    let r = motion.root_translation();
    let n = r.len();
    if n < 2 {
        return DVec3::ZERO;
    }
    let (a, b) = if t == 0 { (0, 1) } else { (t - 1, t) };
    (r[b] - r[a]) * motion.fps()
}

/// The per-frame states of a clip, row-major `[frame][state_dim]`.
pub fn states(motion: &Motion) -> Vec<f32> {
    let nj = motion.joints();
    let mut out = Vec::with_capacity(motion.frames() * state_dim(nj));
    for t in 0..motion.frames() {
        let root = motion.rotation(t, 0);
        let unyaw = DQuat::from_rotation_y(-heading(root));
        let v = unyaw * root_velocity(motion, t);
        out.push(motion.root_translation()[t].y as f32);
        out.extend([v.x as f32, v.y as f32, v.z as f32]);
        out.extend(to_6d(unyaw * root).map(|x| x as f32));
        for j in 1..nj {
            out.extend(to_6d(motion.rotation(t, j)).map(|x| x as f32));
        }
    }
    out
}

/// Network inputs from states: each state followed by its difference to the
/// previous frame (zero at frame 0).
pub fn inputs(states: &[f32], dim: usize) -> Vec<f32> {
    let n = states.len() / dim;
    let mut out = Vec::with_capacity(2 * states.len());
    for t in 0..n {
        let s = &states[t * dim..(t + 1) * dim];
        out.extend_from_slice(s);
        if t == 0 {
            out.extend(std::iter::repeat_n(0.0, dim));
        } else {
            let p = &states[(t - 1) * dim..t * dim];
            out.extend(s.iter().zip(p).map(|(a, b)| a - b));
        }
    }
    out
}

/// Rebuild a clip from `motion` with its states replaced by `new_states`: the
/// heading of each frame is kept, the tilt and joint rotations come from the
/// 6D values, the height from the state and the horizontal path is integrated
/// from the new velocities (starting where `motion` starts).
pub fn apply_states(motion: &Motion, new_states: &[f32]) -> Result<Motion, motion::MotionError> {
    let nj = motion.joints();
    let dim = state_dim(nj);
    let n = motion.frames();
    let dt = 1.0 / motion.fps();
    let mut root = Vec::with_capacity(n);
    let mut rotations = Vec::with_capacity(n * nj);
    let six = |s: &[f32], at: usize| {
        let mut v = [0.0f64; 6];
        for (k, x) in v.iter_mut().enumerate() {
            *x = s[at + k] as f64;
        }
        from_6d(&v)
    };
    let mut pos = motion.root_translation()[0];
    for t in 0..n {
        let s = &new_states[t * dim..(t + 1) * dim];
        let yaw = DQuat::from_rotation_y(heading(motion.rotation(t, 0)));
        if t > 0 {
            let v = yaw * DVec3::new(s[1] as f64, s[2] as f64, s[3] as f64);
            pos += v * dt;
        }
        root.push(DVec3::new(pos.x, s[0] as f64, pos.z));
        rotations.push((yaw * six(s, 4)).normalize());
        for j in 1..nj {
            rotations.push(six(s, 4 + 6 * j));
        }
    }
    Motion::new(motion.skeleton().clone(), motion.fps(), root, rotations)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The bundled HDM05 kick at 30 fps (first 40 frames).
    pub(crate) fn walk() -> Motion {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/data/");
        let options = motion::io::LoadOptions {
            skeleton: Some(format!("{dir}HDM_bd.asf").into()),
            ..Default::default()
        };
        let m = motion::io::load(format!("{dir}HDM_bd_kickLFront1Reps_001_120.amc"), &options)
            .expect("bundled clip");
        let m = motion::resample::resample(&m, 30.0).expect("resample");
        let nj = m.joints();
        m.with_frames(
            30.0,
            m.root_translation()[..40].to_vec(),
            m.rotations()[..40 * nj].to_vec(),
        )
        .expect("frames")
    }

    #[test]
    fn states_round_trip_reproduces_the_clip() {
        let m = walk();
        let s = states(&m);
        assert_eq!(s.len(), m.frames() * state_dim(m.joints()));
        let back = apply_states(&m, &s).expect("rebuild");
        for t in 0..m.frames() {
            let d = (back.root_translation()[t] - m.root_translation()[t]).length();
            assert!(d < 1e-5, "frame {t}: root off by {d}");
            for j in 0..m.joints() {
                let a = motion::rotation::angle_between(back.rotation(t, j), m.rotation(t, j));
                assert!(a < 1e-5, "frame {t} joint {j}: {a} rad");
            }
        }
    }

    #[test]
    fn inputs_hold_state_and_difference() {
        let m = walk();
        let dim = state_dim(m.joints());
        let s = states(&m);
        let x = inputs(&s, dim);
        assert_eq!(x.len(), 2 * s.len());
        assert!(x[dim..2 * dim].iter().all(|v| *v == 0.0));
        let t = 5;
        for k in 0..dim {
            let d = x[t * 2 * dim + dim + k];
            assert!((d - (s[t * dim + k] - s[(t - 1) * dim + k])).abs() < 1e-6);
        }
    }

    #[test]
    fn heading_is_removed_from_the_state() {
        let m = walk();
        let turned = m
            .with_frames(
                m.fps(),
                m.root_translation()
                    .iter()
                    .map(|p| DQuat::from_rotation_y(1.2) * *p)
                    .collect(),
                (0..m.frames())
                    .flat_map(|t| {
                        let mut pose = m.pose(t).to_vec();
                        pose[0] = DQuat::from_rotation_y(1.2) * pose[0];
                        pose
                    })
                    .collect(),
            )
            .expect("motion");
        let (a, b) = (states(&m), states(&turned));
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max);
        assert!(worst < 1e-5, "{worst}");
    }
}
