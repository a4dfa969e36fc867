//! Per-frame features for the debiasing MLP.
//!
//! A frame's *state* is `[root height, root velocity (3, heading frame, m/s),
//! root tilt (6D, heading removed), joint rotations (6D each, local)]`; the
//! network sees the state and its difference to the previous frame and
//! predicts a change of the *rotations* (tilt and joints, [`output_dim`]).
//! Removing the heading keeps the features the same for a clip walked in any
//! direction, so the network learns the bias, not the route.
//!
//! The root's height and path are inputs only: the debiased clip keeps the
//! corrected clip's root translation, the part of the motion the simulation
//! made physically consistent with its ground contacts. (Session 3 also
//! predicted a root height and velocity change; integrated over a VAE sample
//! it lifted feet off the ground in half the frames.)

use motion::Motion;
use motion::glam::{DQuat, DVec3};
use motion::rotation::{from_6d, heading, to_6d};

/// Numbers per frame state for `joints` joints (root tilt counts as one joint).
pub fn state_dim(joints: usize) -> usize {
    4 + 6 * joints
}

/// Numbers the network predicts per frame: the 6D rotation change of the root
/// tilt and of every non-root joint (the state without its first four numbers).
pub fn output_dim(joints: usize) -> usize {
    6 * joints
}

/// Where the rotations start in a state.
pub const ROTATIONS_AT: usize = 4;

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

/// Rebuild a clip from `motion` with its rotations replaced by
/// `rotations` (`[frame][output_dim]`: root tilt then joints, 6D): each frame
/// keeps its heading and `motion`'s root translation.
pub fn apply_rotations(motion: &Motion, rotations: &[f32]) -> Result<Motion, motion::MotionError> {
    let nj = motion.joints();
    let dim = output_dim(nj);
    let six = |s: &[f32], at: usize| {
        let mut v = [0.0f64; 6];
        for (k, x) in v.iter_mut().enumerate() {
            *x = s[at + k] as f64;
        }
        from_6d(&v)
    };
    let mut out = Vec::with_capacity(motion.frames() * nj);
    for t in 0..motion.frames() {
        let s = &rotations[t * dim..(t + 1) * dim];
        let yaw = DQuat::from_rotation_y(heading(motion.rotation(t, 0)));
        out.push((yaw * six(s, 0)).normalize());
        for j in 1..nj {
            out.push(six(s, 6 * j));
        }
    }
    motion.with_frames(motion.fps(), motion.root_translation().to_vec(), out)
}

/// `rows` (`[frame][dim]`, clips of `lengths` frames one after the other)
/// low-passed over time, clip by clip and column by column, with a Gaussian
/// of `sigma` frames (window +-3 sigma, cut at each clip's ends with the
/// weights renormalised: [`motion::smooth::GaussianWindow`]). `sigma` below
/// 1e-3 frames returns the rows unchanged.
///
/// Why it exists: the network predicts each frame's change from that frame
/// alone, and its errors differ from frame to frame; added to a clip they
/// are jitter (kick fold dg: the debiased corrected originals' jerk 1.5x the
/// corrected clips', 2-3x on clips it did not train on). The bias it models
/// (a simulated body's lag and posture) changes slowly, so a low-pass keeps
/// it and drops the jitter.
pub fn low_pass(rows: &[f32], dim: usize, lengths: &[usize], sigma: f64) -> Vec<f32> {
    if sigma.is_nan() || sigma < 1e-3 || dim == 0 {
        return rows.to_vec();
    }
    let longest = lengths.iter().copied().max().unwrap_or(0);
    let window = motion::smooth::GaussianWindow::new(sigma, longest);
    let mut out = vec![0.0f32; rows.len()];
    let mut acc = vec![0.0f64; dim];
    let mut start = 0usize;
    for &n in lengths {
        let clip = &rows[start * dim..(start + n) * dim];
        let smoothed = &mut out[start * dim..(start + n) * dim];
        for t in 0..n {
            acc.fill(0.0);
            let mut total = 0.0f64;
            for (s, w) in window.taps(t, n) {
                let row = &clip[s * dim..(s + 1) * dim];
                for (a, x) in acc.iter_mut().zip(row) {
                    *a += w * *x as f64;
                }
                total += w;
            }
            for (o, a) in smoothed[t * dim..(t + 1) * dim].iter_mut().zip(&acc) {
                *o = (a / total) as f32;
            }
        }
        start += n;
    }
    out
}

/// The rotation part of every state, `[frame][output_dim]`.
pub fn rotations_of(states: &[f32], joints: usize) -> Vec<f32> {
    states
        .chunks_exact(state_dim(joints))
        .flat_map(|s| s[ROTATIONS_AT..].iter().copied())
        .collect()
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
        let r = rotations_of(&s, m.joints());
        assert_eq!(r.len(), m.frames() * output_dim(m.joints()));
        let back = apply_rotations(&m, &r).expect("rebuild");
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
    fn low_pass_keeps_slow_change_drops_jitter_and_keeps_clips_apart() {
        // Two clips, two columns: a constant and a constant plus +-0.1 jitter.
        let (a, b) = (12usize, 9usize);
        let mut rows = Vec::new();
        for t in 0..a {
            rows.extend([0.5f32, 1.0 + if t % 2 == 0 { 0.1 } else { -0.1 }]);
        }
        for _ in 0..b {
            rows.extend([-2.0f32, 3.0]);
        }
        let out = low_pass(&rows, 2, &[a, b], 1.5);
        assert_eq!(out.len(), rows.len());
        for t in 0..a {
            assert!((out[2 * t] - 0.5).abs() < 1e-6, "frame {t}: constant moved");
            // Away from the clip's ends the jitter mostly goes.
            if (3..a - 3).contains(&t) {
                let left = (out[2 * t + 1] - 1.0).abs();
                assert!(left < 0.01, "frame {t}: jitter {left} left");
            }
        }
        // The second clip is not pulled towards the first.
        for t in a..a + b {
            assert!((out[2 * t] + 2.0).abs() < 1e-6 && (out[2 * t + 1] - 3.0).abs() < 1e-6);
        }
        assert_eq!(low_pass(&rows, 2, &[a, b], 0.0), rows);
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
