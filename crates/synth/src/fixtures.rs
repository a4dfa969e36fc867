//! A small synthetic humanoid and simple motions on it.
//!
//! Used by this crate's tests, doc examples and benchmark so that they do not
//! depend on a file reader; real-data tests read `../shared/data` in addition.

use std::sync::Arc;

use glam::{DQuat, DVec3};
use motion::{Joint, Motion, Skeleton};

fn joint(name: &str, parent: Option<usize>, offset: [f64; 3]) -> Joint {
    Joint {
        name: name.into(),
        parent,
        offset: DVec3::from_array(offset),
        channels: vec![],
        end_site: None,
        limits: None,
    }
}

/// A 19-joint humanoid, metres, y up, facing +z, mirror-symmetric in x, named in
/// the BVH `Left*`/`Right*` style. Left limbs are on +x.
pub fn humanoid() -> Skeleton {
    let j = vec![
        joint("Hips", None, [0.0, 0.0, 0.0]),
        joint("LeftUpLeg", Some(0), [0.09, -0.06, 0.0]),
        joint("LeftLeg", Some(1), [0.0, -0.42, 0.0]),
        joint("LeftFoot", Some(2), [0.0, -0.41, 0.0]),
        joint("LeftToeBase", Some(3), [0.0, -0.05, 0.12]),
        joint("RightUpLeg", Some(0), [-0.09, -0.06, 0.0]),
        joint("RightLeg", Some(5), [0.0, -0.42, 0.0]),
        joint("RightFoot", Some(6), [0.0, -0.41, 0.0]),
        joint("RightToeBase", Some(7), [0.0, -0.05, 0.12]),
        joint("Spine", Some(0), [0.0, 0.12, 0.0]),
        joint("Chest", Some(9), [0.0, 0.22, 0.0]),
        joint("Neck", Some(10), [0.0, 0.2, 0.0]),
        joint("Head", Some(11), [0.0, 0.1, 0.0]),
        joint("LeftArm", Some(10), [0.17, 0.16, 0.0]),
        joint("LeftForeArm", Some(13), [0.28, 0.0, 0.0]),
        joint("LeftHand", Some(14), [0.25, 0.0, 0.0]),
        joint("RightArm", Some(10), [-0.17, 0.16, 0.0]),
        joint("RightForeArm", Some(16), [-0.28, 0.0, 0.0]),
        joint("RightHand", Some(17), [-0.25, 0.0, 0.0]),
    ];
    Skeleton::new(j, 1.0).expect("the fixture skeleton is valid")
}

/// Height of the hips above the ground when the legs are straight.
pub const HIP_HEIGHT: f64 = 0.06 + 0.42 + 0.41 + 0.05;

/// A walking-like motion: legs and arms swing, knees bend, the root moves
/// forward at `speed` m/s. Deterministic, `frames` frames at `fps`.
pub fn walk(frames: usize, fps: f64, speed: f64) -> Motion {
    let skeleton = Arc::new(humanoid());
    let n = skeleton.len();
    let mut root = Vec::with_capacity(frames);
    let mut rot = Vec::with_capacity(frames * n);
    for t in 0..frames {
        let time = t as f64 / fps;
        let phase = 2.0 * std::f64::consts::PI * time; // one stride per second
        root.push(DVec3::new(0.0, HIP_HEIGHT - 0.02, speed * time));
        let mut pose = vec![DQuat::IDENTITY; n];
        pose[0] = DQuat::from_rotation_y(0.05 * phase.sin());
        pose[1] = DQuat::from_rotation_x(-0.4 * phase.sin());
        pose[2] = DQuat::from_rotation_x(0.5 * (0.5 + 0.5 * phase.cos()));
        pose[5] = DQuat::from_rotation_x(0.4 * phase.sin());
        pose[6] = DQuat::from_rotation_x(0.5 * (0.5 - 0.5 * phase.cos()));
        pose[9] = DQuat::from_rotation_x(0.05);
        pose[13] = DQuat::from_rotation_z(-1.2) * DQuat::from_rotation_x(0.3 * phase.sin());
        pose[14] = DQuat::from_rotation_y(-0.3);
        pose[16] = DQuat::from_rotation_z(1.2) * DQuat::from_rotation_x(-0.3 * phase.sin());
        pose[17] = DQuat::from_rotation_y(0.3);
        rot.extend(pose);
    }
    Motion::new(skeleton, fps, root, rot).expect("the fixture motion is valid")
}

/// A kick-like motion: the left leg swings forward and up to a peak at
/// `peak_frame` and back, the knee bends and extends.
pub fn kick(frames: usize, fps: f64, peak_frame: usize) -> Motion {
    let skeleton = Arc::new(humanoid());
    let n = skeleton.len();
    let mut root = Vec::with_capacity(frames);
    let mut rot = Vec::with_capacity(frames * n);
    for t in 0..frames {
        let d = (t as f64 - peak_frame as f64) / (0.25 * frames as f64);
        let w = (-d * d).exp(); // 1 at the peak
        root.push(DVec3::new(0.0, HIP_HEIGHT - 0.01, 0.0));
        let mut pose = vec![DQuat::IDENTITY; n];
        pose[1] = DQuat::from_rotation_x(-1.3 * w);
        pose[2] = DQuat::from_rotation_x(0.9 * (1.0 - w) * w * 4.0 + 0.1);
        pose[5] = DQuat::from_rotation_x(0.1);
        pose[6] = DQuat::from_rotation_x(0.15);
        pose[13] = DQuat::from_rotation_z(-1.3);
        pose[16] = DQuat::from_rotation_z(1.3);
        rot.extend(pose);
    }
    Motion::new(skeleton, fps, root, rot).expect("the fixture motion is valid")
}
