//! A humanoid built in code (the CMU 131 walk skeleton's rest offsets in
//! metres, arms hanging, legs splayed, zero-length helper joints, fingers and
//! thumbs) and simple motions on it, for tests and examples that must run
//! without the data folder.

use std::sync::Arc;

use glam::{DQuat, DVec3};
use motion::{Joint, Motion, Skeleton};

const UNIT: f64 = 0.0254 / 0.45;

/// (name, parent name, offset, end site) in CMU ASF units.
type Row = (&'static str, &'static str, [f64; 3], Option<[f64; 3]>);

const ROWS: &[Row] = &[
    ("Hips", "", [0.0, 0.0, 0.0], None),
    ("LHipJoint", "Hips", [0.0, 0.0, 0.0], None),
    ("LeftHip", "LHipJoint", [1.24777, -1.64261, 0.71711], None),
    ("LeftKnee", "LeftHip", [2.49329, -6.85026, 0.0], None),
    ("LeftAnkle", "LeftKnee", [2.36770, -6.50520, 0.0], None),
    (
        "LeftToe",
        "LeftAnkle",
        [0.14820, -0.40718, 2.21395],
        Some([0.0, 0.0, 1.13491]),
    ),
    ("RHipJoint", "Hips", [0.0, 0.0, 0.0], None),
    ("RightHip", "RHipJoint", [-1.18320, -1.64261, 0.71711], None),
    ("RightKnee", "RightHip", [-2.46559, -6.77417, 0.0], None),
    ("RightAnkle", "RightKnee", [-2.38450, -6.55136, 0.0], None),
    (
        "RightToe",
        "RightAnkle",
        [-0.17454, -0.47954, 2.02925],
        Some([0.0, 0.0, 1.05076]),
    ),
    ("lowerback", "Hips", [0.0, 0.0, 0.0], None),
    ("Chest", "lowerback", [-0.02305, 1.98660, 0.00319], None),
    ("Chest2", "Chest", [-0.00718, 1.99033, -0.00533], None),
    ("lowerneck", "Chest2", [0.0, 0.0, 0.0], None),
    ("Neck", "lowerneck", [0.00095, 1.61015, 0.10698], None),
    (
        "Head",
        "Neck",
        [-0.01060, 1.59924, 0.01317],
        Some([-0.00458, 1.63304, -0.00592]),
    ),
    ("LeftCollar", "Chest2", [0.0, 0.0, 0.0], None),
    (
        "LeftShoulder",
        "LeftCollar",
        [3.05381, 1.47088, -0.01697],
        None,
    ),
    ("LeftElbow", "LeftShoulder", [0.0, -4.25106, 0.0], None),
    ("LeftWrist", "LeftElbow", [0.0, -3.27592, 0.0], None),
    ("lhand", "LeftWrist", [0.0, 0.0, 0.0], None),
    (
        "LFingers",
        "lhand",
        [0.0, -0.65781, 0.0],
        Some([0.0, -0.53034, 0.0]),
    ),
    (
        "LThumb",
        "lhand",
        [0.0, 0.0, 0.0],
        Some([0.0, -0.53844, 0.53844]),
    ),
    ("RightCollar", "Chest2", [0.0, 0.0, 0.0], None),
    (
        "RightShoulder",
        "RightCollar",
        [-2.83695, 1.31619, -0.22674],
        None,
    ),
    ("RightElbow", "RightShoulder", [0.0, -4.46073, 0.0], None),
    ("RightWrist", "RightElbow", [0.0, -3.44416, 0.0], None),
    ("rhand", "RightWrist", [0.0, 0.0, 0.0], None),
    (
        "RFingers",
        "rhand",
        [0.0, -0.61651, 0.0],
        Some([0.0, -0.49705, 0.0]),
    ),
    (
        "RThumb",
        "rhand",
        [0.0, 0.0, 0.0],
        Some([0.0, -0.50464, 0.50464]),
    ),
];

/// The CMU-style humanoid (31 joints, about 1.7 m tall).
pub fn cmu_humanoid() -> Arc<Skeleton> {
    let mut joints: Vec<Joint> = Vec::new();
    for (name, parent, off, end) in ROWS {
        let parent = joints.iter().position(|j| j.name == *parent);
        joints.push(Joint {
            name: (*name).into(),
            parent,
            offset: DVec3::from_array(*off) * UNIT,
            channels: vec![],
            end_site: end.map(|e| DVec3::from_array(e) * UNIT),
            limits: None,
        });
    }
    Arc::new(Skeleton::new(joints, UNIT).expect("fixture skeleton is valid"))
}

/// Height of the root above the ground in the rest pose (lowest tip on the floor).
pub fn standing_root_height(sk: &Skeleton) -> f64 {
    let pos = sk.rest_positions();
    let mut lo = f64::INFINITY;
    for (i, p) in pos.iter().enumerate() {
        lo = lo.min(p.y);
        if let Some(e) = sk.joint(i).end_site {
            lo = lo.min(p.y + e.y);
        }
    }
    -lo
}

/// Standing in the rest pose, with a slow sway of the arms and the trunk:
/// statically stable, a clip the character should track closely.
pub fn sway(sk: Arc<Skeleton>, seconds: f64, fps: f64) -> Motion {
    let frames = (seconds * fps).round().max(2.0) as usize;
    let h = standing_root_height(&sk);
    let n = sk.len();
    let mut root = Vec::with_capacity(frames);
    let mut rot = Vec::with_capacity(frames * n);
    for f in 0..frames {
        let t = f as f64 / fps;
        root.push(DVec3::new(0.0, h, 0.0));
        for j in 0..n {
            let name = sk.joint(j).name.as_str();
            let a = (t * 1.5).sin();
            let q = match name {
                "LeftShoulder" => DQuat::from_rotation_x(-0.5 * a),
                "RightShoulder" => DQuat::from_rotation_x(0.5 * a),
                "LeftElbow" | "RightElbow" => DQuat::from_rotation_x(-0.4 - 0.3 * a),
                "Chest" => DQuat::from_rotation_y(0.15 * a),
                "Neck" => DQuat::from_rotation_x(0.1 * a),
                _ => DQuat::IDENTITY,
            };
            rot.push(q);
        }
    }
    Motion::new(sk, fps, root, rot).expect("fixture motion is valid")
}
