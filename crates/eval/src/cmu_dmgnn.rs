//! The CMU data set as preprocessed for DMGNN, and the test protocol of DMGNN
//! and V-DMGNN-GAN on it, reproduced exactly.
//!
//! Why this module exists: the V-DMGNN-GAN paper (and DMGNN) report their CMU
//! results on one published preprocessing (`../shared/data/cmu_dmgnn/`: text,
//! one frame per line, 117 floats = 39 triplets: the root position, then 38
//! joints as exponential maps) and one protocol (every second frame, 50
//! observed / 10 predicted frames, 8 test windows per action drawn by numpy's
//! legacy `RandomState(1234567890)`, an Euler-angle error read at 40 / 240 /
//! 400 ms). Our figures are only comparable with theirs if every step is the
//! same, so this module owns all of it: the skeleton, the reader, the data set
//! with its normalisation, numpy's generator and bounded `randint`, the test
//! windows and the metric. The models live elsewhere (`predict`); they see the
//! data through [`CmuDmgnnSet`] and are scored by
//! [`CmuDmgnnSet::mean_angle_error`].
//!
//! Conventions, checked on the data (tests below):
//! * triplet 0 is the root position (CMU ASF length unit, y up, world frame);
//!   triplet `t >= 1` is the local rotation of skeleton joint `t - 1`;
//! * an exponential map `r` is the reference's row-vector rotation
//!   (`v' = v R(r)`), so in the column-vector convention of [`motion`] the local
//!   rotation is `R(r)^T`, the quaternion of the rotation vector `-r` (with the
//!   other sign the knees bend forwards);
//! * the skeleton is the reference's `_some_variables` (parents, offsets from
//!   the parent in its rest frame, BVH style): joint 2 (`lfemur`) sits one
//!   hip bone from the root and its triplet turns the thigh. Joints are named
//!   after the CMU ASF bone whose rotation they carry; the seven leaves are
//!   bone tips with a triplet that is always zero.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use motion::glam::{DQuat, DVec3};
use motion::{Axis, Channel, Joint, Motion, Skeleton, Unit};

use crate::{EvalError, Result};

/// Floats per frame: 39 triplets.
pub const DIMS: usize = 117;
/// Joints of the skeleton (each with one rotation triplet; the root also has
/// the position triplet).
pub const JOINTS: usize = 38;
/// Frame rate of the files: every second frame is kept, and the reference
/// labels output frame `k` (0-based) as `40 (k + 1)` ms.
pub const FILE_FPS: f64 = 50.0;
/// Every `FRAME_STEP`-th frame is kept, starting with the first (0, 2, 4, ...).
pub const FRAME_STEP: usize = 2;
/// Frames the predictor observes (the reference's 49 encoder frames plus the
/// decoder's first input).
pub const OBSERVED: usize = 50;
/// Frames it predicts (the short-term setting).
pub const PREDICTED: usize = 10;
/// Test windows per action.
pub const WINDOWS: usize = 8;
/// Seed of the test windows' generator (a new generator per action).
pub const WINDOW_SEED: u32 = 1_234_567_890;
/// Reported horizons (ms) of V-DMGNN-GAN's Table 1.
pub const REPORTED_MS: [u32; 3] = [40, 240, 400];
/// The 0-based output frames they are read at (output frame `k` is
/// `40 (k + 1)` ms; 1-based frames 1, 6, 10).
pub const REPORTED_FRAMES: [usize; 3] = [0, 5, 9];
/// Training dims whose standard deviation is below this are "constant": their
/// std is set to 1 and they are left out of the metric.
pub const STD_EPS: f64 = 1e-4;

/// The actions with training and test files in the shared copy, the ones of
/// the paper's Table 1 we can report.
pub const COMPLETE_ACTIONS: [&str; 5] = ["basketball", "jumping", "running", "soccer", "walking"];

/// Joint names: each joint is named after the ASF bone whose rotation its
/// triplet holds (so `synth::names` finds sides, feet and hands); the seven
/// leaves are the tips of their parents' bones.
const NAMES: [&str; JOINTS] = [
    "root",
    "lhipjoint",
    "lfemur",
    "ltibia",
    "lfoot",
    "ltoes",
    "ltoes_end",
    "rhipjoint",
    "rfemur",
    "rtibia",
    "rfoot",
    "rtoes",
    "rtoes_end",
    "lowerback",
    "upperback",
    "thorax",
    "lowerneck",
    "upperneck",
    "head",
    "head_end",
    "lclavicle",
    "lhumerus",
    "lradius",
    "lwrist",
    "lhand",
    "lfingers",
    "lfingers_end",
    "lthumb",
    "lthumb_end",
    "rclavicle",
    "rhumerus",
    "rradius",
    "rwrist",
    "rhand",
    "rfingers",
    "rfingers_end",
    "rthumb",
    "rthumb_end",
];

/// Parent of each joint, 0-based (the reference's 1-based list minus one).
const PARENTS: [Option<usize>; JOINTS] = {
    const ONE_BASED: [usize; JOINTS] = [
        0, 1, 2, 3, 4, 5, 6, 1, 8, 9, 10, 11, 12, 1, 14, 15, 16, 17, 18, 19, 16, 21, 22, 23, 24,
        25, 26, 24, 28, 16, 30, 31, 32, 33, 34, 35, 33, 37,
    ];
    let mut out = [None; JOINTS];
    let mut j = 1;
    while j < JOINTS {
        out[j] = Some(ONE_BASED[j] - 1);
        j += 1;
    }
    out
};

/// Each joint's offset from its parent (ASF length units, the parent's rest
/// frame): the reference's `_some_variables` offsets.
const OFFSETS: [[f64; 3]; JOINTS] = [
    [0.0, 0.0, 0.0],
    [0.0, 0.0, 0.0],
    [1.65674, -1.80282, 0.62477],
    [2.5972, -7.13576, 0.0],
    [2.49236, -6.8477, 0.0],
    [0.19704, -0.54136, 2.14581],
    [0.0, 0.0, 1.11249],
    [0.0, 0.0, 0.0],
    [-1.6107, -1.80282, 0.62476],
    [-2.59502, -7.12977, 0.0],
    [-2.4678, -6.78024, 0.0],
    [-0.23024, -0.63258, 2.13368],
    [0.0, 0.0, 1.11569],
    [0.0, 0.0, 0.0],
    [0.01961, 2.0545, -0.14112],
    [0.01021, 2.06436, -0.05921],
    [0.0, 0.0, 0.0],
    [0.00713, 1.56711, 0.14968],
    [0.03429, 1.56041, -0.10006],
    [0.01305, 1.6256, -0.05265],
    [0.0, 0.0, 0.0],
    [3.54205, 0.90436, -0.17364],
    [4.86513, 0.0, 0.0],
    [3.35554, 0.0, 0.0],
    [0.0, 0.0, 0.0],
    [0.66117, 0.0, 0.0],
    [0.53306, 0.0, 0.0],
    [0.0, 0.0, 0.0],
    [0.5412, 0.0, 0.5412],
    [0.0, 0.0, 0.0],
    [-3.49802, 0.75994, -0.32616],
    [-5.02649, 0.0, 0.0],
    [-3.36431, 0.0, 0.0],
    [0.0, 0.0, 0.0],
    [-0.73041, 0.0, 0.0],
    [-0.58887, 0.0, 0.0],
    [0.0, 0.0, 0.0],
    [-0.59786, 0.0, 0.59786],
];

/// The 26 triplets the reference predicts (its `dim_to_use`, 78 dims, read as
/// whole triplets): every animated joint but the root. The others are the
/// root position and rotation and twelve triplets that are zero in every
/// training frame (the hip joints, clavicles and the leaves).
const USED_TRIPLETS: [usize; 26] = [
    3, 4, 5, 6, 9, 10, 11, 12, 14, 15, 16, 17, 18, 19, 22, 23, 24, 25, 26, 28, 31, 32, 33, 34, 35,
    37,
];

static USED_DIMS: [usize; 78] = {
    let mut out = [0; 78];
    let mut i = 0;
    while i < 26 {
        let mut k = 0;
        while k < 3 {
            out[3 * i + k] = 3 * USED_TRIPLETS[i] + k;
            k += 1;
        }
        i += 1;
    }
    out
};

/// The reference's lower-body mask (V-DMGNN-GAN, `lower_body_joints`):
/// indices into the 26 used triplets ([`used_joints`]) = `ltibia`, `lfoot`,
/// `ltoes`, every observed frame, in normalised units, occluded values
/// replaced by `N(0, 0.5^2)` noise. Both whole legs (`lfemur` .. `rtoes`, what
/// a name-based lower body gives) are used triplets `0..8`, an alternative
/// left commented out in the reference.
pub const REFERENCE_LOWER_BODY_USED: [usize; 3] = [1, 2, 3];

/// The 78 dims (of 117) the reference predicts, ascending: whole triplets.
pub fn used_dims() -> &'static [usize] {
    &USED_DIMS
}

/// The skeleton joint of each used triplet, in the order of [`used_dims`]
/// (used dims `3 i .. 3 i + 3` are the local rotation of joint
/// `used_joints()[i]`).
pub fn used_joints() -> Vec<usize> {
    used_dims()
        .chunks_exact(3)
        .map(|c| {
            assert!(
                c[0] % 3 == 0 && c[1] == c[0] + 1 && c[2] == c[0] + 2,
                "used dims {c:?} are not one whole triplet"
            );
            c[0] / 3 - 1
        })
        .collect()
}

/// Metres per length unit of the data (the CMU ASF unit, 1/0.45 inch).
pub fn unit_m() -> f64 {
    Unit::CmuAsf.metres().unwrap_or(0.0254 / 0.45)
}

/// The skeleton of the data: 38 joints, joint 0 the root (it carries the
/// position triplet), offsets in metres, every leaf a bone tip.
pub fn skeleton() -> Result<Skeleton> {
    let unit = unit_m();
    let rot = vec![
        Channel::Rotation(Axis::Z),
        Channel::Rotation(Axis::Y),
        Channel::Rotation(Axis::X),
    ];
    let joints = (0..JOINTS)
        .map(|j| {
            let parent = PARENTS[j];
            let offset = DVec3::from(OFFSETS[j]) * unit;
            let channels = if parent.is_none() {
                let mut c = vec![
                    Channel::Position(Axis::X),
                    Channel::Position(Axis::Y),
                    Channel::Position(Axis::Z),
                ];
                c.extend(rot.iter().copied());
                c
            } else {
                rot.clone()
            };
            Joint {
                name: NAMES[j].to_string(),
                parent,
                offset,
                channels,
                end_site: None,
                limits: None,
            }
        })
        .collect();
    Ok(Skeleton::new(joints, unit)?)
}

/// The reference's exponential map to rotation matrix (Rodrigues' formula
/// with its epsilon in the axis normalisation), row-vector convention.
pub fn expmap_to_matrix(r: [f64; 3]) -> [[f64; 3]; 3] {
    let theta = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let d = theta + f64::from(f32::EPSILON);
    let (x, y, z) = (r[0] / d, r[1] / d, r[2] / d);
    let k = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]];
    let (s, c) = (theta.sin(), 1.0 - theta.cos());
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            let kk: f64 = (0..3).map(|l| k[i][l] * k[l][j]).sum();
            *v = f64::from(u8::from(i == j)) + s * k[i][j] + c * kk;
        }
    }
    m
}

/// The reference's rotation matrix to Euler angles (`rotmat2euler`, with its
/// exact-equality gimbal test).
pub fn matrix_to_euler(m: [[f64; 3]; 3]) -> [f64; 3] {
    if m[0][2] == 1.0 || m[0][2] == -1.0 {
        let e3 = 0.0;
        let delta = m[0][1].atan2(m[0][2]);
        if m[0][2] == -1.0 {
            [e3 + delta, std::f64::consts::FRAC_PI_2, e3]
        } else {
            [-e3 + delta, -std::f64::consts::FRAC_PI_2, e3]
        }
    } else {
        let e2 = -m[0][2].asin();
        let c = e2.cos();
        [
            (m[1][2] / c).atan2(m[2][2] / c),
            e2,
            (m[0][1] / c).atan2(m[0][0] / c),
        ]
    }
}

/// An exponential map of the data as the local rotation of [`motion`]
/// (column vectors): the rotation by `-r`.
pub fn expmap_to_quat(r: [f64; 3]) -> DQuat {
    DQuat::from_scaled_axis(-DVec3::from(r))
}

/// Inverse of [`expmap_to_quat`], angle in `[0, pi]`.
pub fn quat_to_expmap(q: DQuat) -> [f64; 3] {
    let q = if q.w < 0.0 { -q } else { q };
    (-q.normalize().to_scaled_axis()).to_array()
}

/// Parses one file's text: one frame per line, [`DIMS`] comma-separated
/// numbers (blank lines are skipped). `source` names the file in errors.
pub fn parse_frames(text: &str, source: &Path) -> Result<Vec<Vec<f64>>> {
    let bad = |line: usize, what: String| {
        EvalError::Data(format!("{}, line {line}: {what}", source.display()))
    };
    let mut frames = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != DIMS {
            return Err(bad(
                i + 1,
                format!("{} values, expected {DIMS}", fields.len()),
            ));
        }
        let mut frame = Vec::with_capacity(DIMS);
        for (k, f) in fields.iter().enumerate() {
            let v: f64 = f.trim().parse().map_err(|_| {
                bad(
                    i + 1,
                    format!("value {} `{}` is not a number", k + 1, f.trim()),
                )
            })?;
            if !v.is_finite() {
                return Err(bad(
                    i + 1,
                    format!("value {} `{}` is not finite", k + 1, f.trim()),
                ));
            }
            frame.push(v);
        }
        frames.push(frame);
    }
    if frames.is_empty() {
        return Err(EvalError::Data(format!("{}: no frames", source.display())));
    }
    Ok(frames)
}

/// Reads one file's frames (all of them, at [`FILE_FPS`]).
pub fn read_frames(path: &Path) -> Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path).map_err(|source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_frames(&text, path)
}

/// Frames (117 values each) as a [`Motion`] on [`skeleton`]: the root
/// position in metres, each joint's rotation from its triplet.
pub fn frames_to_motion(skeleton: Arc<Skeleton>, frames: &[Vec<f64>], fps: f64) -> Result<Motion> {
    if skeleton.len() != JOINTS {
        return Err(EvalError::Data(format!(
            "a skeleton of {} joints is not the CMU (DMGNN) skeleton of {JOINTS}",
            skeleton.len()
        )));
    }
    let unit = unit_m();
    let mut root = Vec::with_capacity(frames.len());
    let mut rotations = Vec::with_capacity(frames.len() * JOINTS);
    for (f, frame) in frames.iter().enumerate() {
        if frame.len() != DIMS {
            return Err(EvalError::Data(format!(
                "frame {f}: {} values, expected {DIMS}",
                frame.len()
            )));
        }
        root.push(DVec3::new(frame[0], frame[1], frame[2]) * unit);
        for j in 0..JOINTS {
            let t = 3 * (j + 1);
            rotations.push(expmap_to_quat([frame[t], frame[t + 1], frame[t + 2]]));
        }
    }
    Ok(Motion::new(skeleton, fps, root, rotations)?)
}

/// Inverse of [`frames_to_motion`]: 117 values per frame.
pub fn motion_to_frames(motion: &Motion) -> Result<Vec<Vec<f64>>> {
    if motion.joints() != JOINTS {
        return Err(EvalError::Data(format!(
            "a motion of {} joints is not on the CMU (DMGNN) skeleton of {JOINTS}",
            motion.joints()
        )));
    }
    let unit = unit_m();
    Ok((0..motion.frames())
        .map(|f| {
            let mut frame = Vec::with_capacity(DIMS);
            frame.extend((motion.root_translation()[f] / unit).to_array());
            for &q in motion.pose(f) {
                frame.extend(quat_to_expmap(q));
            }
            frame
        })
        .collect())
}

/// Reads one file as a [`Motion`] at [`FILE_FPS`].
pub fn read_motion(path: &Path) -> Result<Motion> {
    let frames = read_frames(path)?;
    frames_to_motion(Arc::new(skeleton()?), &frames, FILE_FPS)
}

/// numpy's legacy `RandomState`: MT19937 seeded by `init_genrand`, and the
/// bounded integers of `RandomState.randint` (masked rejection sampling).
#[derive(Debug, Clone)]
pub struct NumpyRandomState {
    mt: Box<[u32; 624]>,
    pos: usize,
}

impl NumpyRandomState {
    /// `np.random.RandomState(seed)` for an integer seed.
    pub fn new(seed: u32) -> Self {
        let mut mt = Box::new([0u32; 624]);
        mt[0] = seed;
        for i in 1..624 {
            let prev = mt[i - 1];
            mt[i] = 1_812_433_253u32
                .wrapping_mul(prev ^ (prev >> 30))
                .wrapping_add(i as u32);
        }
        NumpyRandomState { mt, pos: 624 }
    }

    fn twist(&mut self) {
        for i in 0..624 {
            let y = (self.mt[i] & 0x8000_0000) | (self.mt[(i + 1) % 624] & 0x7fff_ffff);
            let mag = if y & 1 == 1 { 0x9908_b0df } else { 0 };
            self.mt[i] = self.mt[(i + 397) % 624] ^ (y >> 1) ^ mag;
        }
        self.pos = 0;
    }

    /// The next 32-bit output (`genrand_int32`).
    pub fn next_u32(&mut self) -> u32 {
        if self.pos >= 624 {
            self.twist();
        }
        let mut y = self.mt[self.pos];
        self.pos += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    fn next_u64(&mut self) -> u64 {
        let hi = u64::from(self.next_u32());
        (hi << 32) | u64::from(self.next_u32())
    }

    /// `randint(low, high)`: uniform in `[low, high)`. Draws nothing when the
    /// range holds one value, 32-bit draws when it fits in 32 bits, as numpy.
    pub fn randint(&mut self, low: i64, high: i64) -> Result<i64> {
        if low >= high {
            return Err(EvalError::Config(format!(
                "randint: low {low} >= high {high}"
            )));
        }
        let rng = (high as i128 - low as i128 - 1) as u64;
        if rng == 0 {
            return Ok(low);
        }
        let value = if rng <= u64::from(u32::MAX) {
            let rng = rng as u32;
            if rng == u32::MAX {
                self.next_u32()
            } else {
                let mask = u32::MAX >> rng.leading_zeros();
                loop {
                    let v = self.next_u32() & mask;
                    if v <= rng {
                        break v;
                    }
                }
            }
            .into()
        } else if rng == u64::MAX {
            self.next_u64()
        } else {
            let mask = u64::MAX >> rng.leading_zeros();
            loop {
                let v = self.next_u64() & mask;
                if v <= rng {
                    break v;
                }
            }
        };
        Ok((low as i128 + value as i128) as i64)
    }
}

/// One sequence of the data set: a file's frames, every second one kept.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    pub action: String,
    /// The file's number (`<action>_<n>.txt`).
    pub number: usize,
    pub path: PathBuf,
    /// Frames 0, 2, 4, ... of the file, 117 values each.
    pub frames: Vec<Vec<f64>>,
}

/// One test window: what a predictor sees and what it must predict.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    pub action: String,
    /// First frame of the window in the test sequence's kept frames.
    pub start: usize,
    /// Kept frames `start .. start + 50`, 117 values each.
    pub observed: Vec<Vec<f64>>,
    /// Kept frames `start + 50 .. start + 60`.
    pub target: Vec<Vec<f64>>,
}

impl Window {
    /// The zero-velocity prediction: the last observed frame, repeated.
    pub fn zero_velocity(&self) -> Vec<Vec<f64>> {
        let last = self.observed.last().cloned().unwrap_or_default();
        vec![last; self.target.len()]
    }
}

/// The data set: per action its training sequences (`train/<action>/`) and
/// its test sequence (`test/<action>/<action>_1.txt`, the only one the
/// reference tests on), with the normalisation statistics of the training
/// frames.
#[derive(Debug, Clone)]
pub struct CmuDmgnnSet {
    actions: Vec<String>,
    train: Vec<Sequence>,
    test: Vec<Sequence>,
    mean: Vec<f64>,
    /// Standard deviation, constant dims set to 1.
    std: Vec<f64>,
    constant: Vec<bool>,
}

fn keep_every_second(frames: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    frames.into_iter().step_by(FRAME_STEP).collect()
}

/// The numbered files of `dir` the reference reads: it counts the folder's
/// entries (n) and reads `<action>_1.txt` ..= `<action>_<n>.txt`.
fn numbered_files(dir: &Path, action: &str) -> Result<Vec<(usize, PathBuf)>> {
    let io = |source| EvalError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let count = std::fs::read_dir(dir).map_err(io)?.count();
    if count == 0 {
        return Err(EvalError::Data(format!("{}: no files", dir.display())));
    }
    (1..=count)
        .map(|n| {
            let path = dir.join(format!("{action}_{n}.txt"));
            if path.is_file() {
                Ok((n, path))
            } else {
                Err(EvalError::Data(format!(
                    "{}: missing {action}_{n}.txt (the folder has {count} entries, \
                     read as {action}_1.txt ..= {action}_{count}.txt)",
                    dir.display()
                )))
            }
        })
        .collect()
}

impl CmuDmgnnSet {
    /// Loads `actions` from `root` (`train/<action>/<action>_<n>.txt`,
    /// `test/<action>/<action>_1.txt`). The mean and standard deviation are
    /// over every frame (all, not every second) of the training files of
    /// these actions, as the reference computes them over the actions it
    /// loads.
    pub fn load(root: &Path, actions: &[&str]) -> Result<CmuDmgnnSet> {
        if actions.is_empty() {
            return Err(EvalError::Config("no CMU (DMGNN) action given".into()));
        }
        let _span = tracing::info_span!("cmu_dmgnn_load", root = %root.display()).entered();
        let mut train = Vec::new();
        let mut test = Vec::new();
        // Every frame of every training file, for the statistics.
        let mut all: Vec<Vec<f64>> = Vec::new();
        for &action in actions {
            let dir = root.join("train").join(action);
            if !dir.is_dir() {
                return Err(EvalError::Data(format!(
                    "{}: no training folder for action `{action}`",
                    dir.display()
                )));
            }
            for (number, path) in numbered_files(&dir, action)? {
                let frames = read_frames(&path)?;
                all.extend(frames.iter().cloned());
                train.push(Sequence {
                    action: action.to_string(),
                    number,
                    path,
                    frames: keep_every_second(frames),
                });
            }
            let path = root
                .join("test")
                .join(action)
                .join(format!("{action}_1.txt"));
            if !path.is_file() {
                return Err(EvalError::Data(format!(
                    "{}: no test file for action `{action}`",
                    path.display()
                )));
            }
            let frames = read_frames(&path)?;
            test.push(Sequence {
                action: action.to_string(),
                number: 1,
                path,
                frames: keep_every_second(frames),
            });
        }
        let n = all.len() as f64;
        let mean: Vec<f64> = (0..DIMS)
            .map(|d| all.iter().map(|f| f[d]).sum::<f64>() / n)
            .collect();
        let raw_std: Vec<f64> = (0..DIMS)
            .map(|d| (all.iter().map(|f| (f[d] - mean[d]).powi(2)).sum::<f64>() / n).sqrt())
            .collect();
        let constant: Vec<bool> = raw_std.iter().map(|&s| s < STD_EPS).collect();
        let std = raw_std
            .iter()
            .zip(&constant)
            .map(|(&s, &c)| if c { 1.0 } else { s })
            .collect();
        tracing::info!(
            actions = actions.len(),
            train_files = train.len(),
            train_frames = all.len(),
            "CMU (DMGNN) set loaded"
        );
        Ok(CmuDmgnnSet {
            actions: actions.iter().map(|a| a.to_string()).collect(),
            train,
            test,
            mean,
            std,
            constant,
        })
    }

    pub fn actions(&self) -> &[String] {
        &self.actions
    }

    /// Every training sequence (every second frame), in action then file order.
    pub fn train(&self) -> &[Sequence] {
        &self.train
    }

    /// The test sequence of `action` (every second frame).
    pub fn test(&self, action: &str) -> Result<&Sequence> {
        self.test
            .iter()
            .find(|s| s.action == action)
            .ok_or_else(|| {
                EvalError::Config(format!(
                    "action `{action}` is not loaded (loaded: {})",
                    self.actions.join(", ")
                ))
            })
    }

    /// Mean of each of the 117 dims over the training frames.
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// Standard deviation of each dim, 1 where it is below [`STD_EPS`].
    pub fn std(&self) -> &[f64] {
        &self.std
    }

    /// The dims whose training standard deviation is below [`STD_EPS`].
    pub fn constant_dims(&self) -> Vec<usize> {
        (0..DIMS).filter(|&d| self.constant[d]).collect()
    }

    /// A 117-value frame as the model's input: the 78 used dims, normalised.
    ///
    /// Panics if `frame` does not hold 117 values.
    pub fn normalise_used(&self, frame: &[f64]) -> Vec<f32> {
        assert_eq!(frame.len(), DIMS, "a CMU (DMGNN) frame has {DIMS} values");
        used_dims()
            .iter()
            .map(|&d| ((frame[d] - self.mean[d]) / self.std[d]) as f32)
            .collect()
    }

    /// 78 normalised values back to a 117-value frame, as the reference
    /// fills it: used dims un-normalised, constant dims and every unused dim
    /// at the training mean.
    ///
    /// Panics if `used` does not hold 78 values.
    pub fn unnormalise_to_full(&self, used: &[f32]) -> Vec<f64> {
        assert_eq!(used.len(), USED_DIMS.len(), "78 used values expected");
        let mut full = self.mean.clone();
        for (&d, &v) in used_dims().iter().zip(used) {
            if !self.constant[d] {
                full[d] = f64::from(v) * self.std[d] + self.mean[d];
            }
        }
        full
    }

    /// A 117-value frame as the reference's metric sees it after its
    /// normalise / un-normalise round trip (in f64): the used, non-constant
    /// dims kept, every other dim at the training mean.
    ///
    /// Panics if `frame` does not hold 117 values.
    pub fn as_seen(&self, frame: &[f64]) -> Vec<f64> {
        assert_eq!(frame.len(), DIMS, "a CMU (DMGNN) frame has {DIMS} values");
        let mut full = self.mean.clone();
        for &d in used_dims() {
            if !self.constant[d] {
                full[d] = frame[d];
            }
        }
        full
    }

    /// The window starts of `action`: a new `RandomState(1234567890)`, then
    /// eight `randint(0, T - 60)` on the test sequence's `T` kept frames.
    pub fn window_starts(&self, action: &str) -> Result<Vec<usize>> {
        let seq = self.test(action)?;
        let t = seq.frames.len() as i64;
        let span = (OBSERVED + PREDICTED) as i64;
        if t <= span {
            return Err(EvalError::Data(format!(
                "{}: {t} kept frames, a test window needs more than {span}",
                seq.path.display()
            )));
        }
        let mut rng = NumpyRandomState::new(WINDOW_SEED);
        (0..WINDOWS)
            .map(|_| Ok(rng.randint(0, t - span)? as usize))
            .collect()
    }

    /// The eight test windows of `action`, as the reference builds them.
    pub fn test_windows(&self, action: &str) -> Result<Vec<Window>> {
        let seq = self.test(action)?;
        Ok(self
            .window_starts(action)?
            .into_iter()
            .map(|start| Window {
                action: action.to_string(),
                start,
                observed: seq.frames[start..start + OBSERVED].to_vec(),
                target: seq.frames[start + OBSERVED..start + OBSERVED + PREDICTED].to_vec(),
            })
            .collect())
    }

    /// A training window as the reference samples one (`train_sample`): a
    /// training sequence chosen uniformly (not by length), then a start
    /// uniform in `0 .. T_even - 60` of its kept frames. Sequences too short
    /// for a window are skipped (none is in the shared copy: the shortest has
    /// 76 kept frames).
    pub fn sample_train_window(&self, rng: &mut impl rand::Rng) -> Result<Window> {
        let span = OBSERVED + PREDICTED;
        let long: Vec<&Sequence> = self
            .train
            .iter()
            .filter(|s| s.frames.len() > span)
            .collect();
        if long.is_empty() {
            return Err(EvalError::Data(format!(
                "no training sequence has more than {span} kept frames"
            )));
        }
        let seq = long[rng.random_range(0..long.len())];
        let start = rng.random_range(0..seq.frames.len() - span);
        Ok(Window {
            action: seq.action.clone(),
            start,
            observed: seq.frames[start..start + OBSERVED].to_vec(),
            target: seq.frames[start + OBSERVED..start + span].to_vec(),
        })
    }

    /// The reference's mean angle error of one window, per predicted frame
    /// (radians). Both sides are seen as the reference sees them
    /// ([`Self::as_seen`]), every triplet is turned to Euler angles
    /// (exponential map -> matrix -> Euler, the reference's formulas), the
    /// target's first six Euler values are zeroed, and the error of a frame is
    /// the L2 norm over the Euler dims that vary in the target window (std >
    /// 1e-4 over its frames) and are not constant in training.
    pub fn mean_angle_error(
        &self,
        pred_full: &[Vec<f64>],
        target_full: &[Vec<f64>],
    ) -> Result<Vec<f64>> {
        if pred_full.len() != target_full.len() || target_full.is_empty() {
            return Err(EvalError::Data(format!(
                "{} predicted frames for {} target frames",
                pred_full.len(),
                target_full.len()
            )));
        }
        if let Some(f) = pred_full
            .iter()
            .chain(target_full)
            .find(|f| f.len() != DIMS)
        {
            return Err(EvalError::Data(format!(
                "a frame of {} values, expected {DIMS}",
                f.len()
            )));
        }
        let euler = |frame: &[f64]| -> Vec<f64> {
            let seen = self.as_seen(frame);
            seen.chunks_exact(3)
                .flat_map(|r| matrix_to_euler(expmap_to_matrix([r[0], r[1], r[2]])))
                .collect()
        };
        let pred: Vec<Vec<f64>> = pred_full.iter().map(|f| euler(f)).collect();
        let target: Vec<Vec<f64>> = target_full
            .iter()
            .map(|f| {
                let mut e = euler(f);
                e[..6].fill(0.0);
                e
            })
            .collect();
        let n = target.len() as f64;
        let dims: Vec<usize> = (0..DIMS)
            .filter(|&d| {
                let m = target.iter().map(|e| e[d]).sum::<f64>() / n;
                let var = target.iter().map(|e| (e[d] - m).powi(2)).sum::<f64>() / n;
                var.sqrt() > STD_EPS && !self.constant[d]
            })
            .collect();
        Ok(pred
            .iter()
            .zip(&target)
            .map(|(p, t)| {
                dims.iter()
                    .map(|&d| (t[d] - p[d]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect())
    }

    /// The mean angle error of a predictor on `action`: per predicted frame,
    /// averaged over the eight test windows. `predict` returns 10 frames of
    /// 117 values per window.
    pub fn action_error(
        &self,
        action: &str,
        mut predict: impl FnMut(&Window) -> Result<Vec<Vec<f64>>>,
    ) -> Result<Vec<f64>> {
        let mut total = vec![0.0; PREDICTED];
        for window in self.test_windows(action)? {
            let err = self.mean_angle_error(&predict(&window)?, &window.target)?;
            for (t, e) in total.iter_mut().zip(err) {
                *t += e;
            }
        }
        Ok(total.into_iter().map(|t| t / WINDOWS as f64).collect())
    }
}

/// The error at the reported horizons ([`REPORTED_MS`]) of a per-frame error.
pub fn reported(per_frame: &[f64]) -> [f64; 3] {
    REPORTED_FRAMES.map(|k| per_frame.get(k).copied().unwrap_or(f64::NAN))
}

/// The shared copy of the data for tests (`../shared/data/cmu_dmgnn` beside
/// the repository), or `None` with a note when it is missing.
#[cfg(test)]
pub(crate) fn test_data_root() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/cmu_dmgnn");
    if dir.join("train").is_dir() && dir.join("test").is_dir() {
        Some(dir)
    } else {
        eprintln!("note: {} missing, test skipped", dir.display());
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::glam::DMat3;
    use proptest::prelude::*;

    fn data_root() -> Option<PathBuf> {
        test_data_root()
    }

    fn complete_set() -> Option<CmuDmgnnSet> {
        data_root().map(|root| CmuDmgnnSet::load(&root, &COMPLETE_ACTIONS).unwrap())
    }

    // ---- Fixtures: the figures printed by benches/cmu_dmgnn_protocol_check.py
    // (numpy 2.4.6, float64), an independent implementation of the protocol
    // written in Python from the README, sharing no code with this module.
    // (The reference itself computes in float32 in places, so its own
    // figures agree with these to about 1e-6.) ----
    const NUMPY_STARTS: [(&str, [usize; 8]); 5] = [
        ("basketball", [130, 102, 47, 140, 51, 33, 171, 105]),
        ("jumping", [386, 358, 47, 140, 819, 289, 939, 105]),
        ("running", [2, 6, 15, 12, 19, 1, 11, 9]),
        ("soccer", [130, 102, 47, 140, 51, 33, 171, 105]),
        ("walking", [2, 102, 47, 12, 51, 33, 43, 105]),
    ];
    const NUMPY_ZERO_VELOCITY: [(&str, [f64; 10]); 5] = [
        (
            "basketball",
            [
                0.271567221,
                0.458987800,
                0.619385157,
                0.768686956,
                0.917017654,
                1.059490612,
                1.201798252,
                1.318010600,
                1.434432372,
                1.532573860,
            ],
        ),
        (
            "jumping",
            [
                0.260529460,
                0.357088550,
                0.482183254,
                0.601547755,
                0.703210696,
                0.864246490,
                1.011215932,
                1.454929346,
                1.552184266,
                1.650651187,
            ],
        ),
        (
            "running",
            [
                0.232871158,
                0.434753734,
                0.619077237,
                0.801242086,
                0.967079860,
                1.120739508,
                1.250902194,
                1.360797964,
                1.444339647,
                1.523001715,
            ],
        ),
        (
            "soccer",
            [
                0.150676721,
                0.271369644,
                0.384886205,
                0.471853551,
                0.575372919,
                0.706930292,
                0.817605295,
                0.908497759,
                0.990536776,
                1.074094905,
            ],
        ),
        (
            "walking",
            [
                0.316569000,
                0.400766950,
                0.468484649,
                0.574562572,
                0.625574528,
                0.646103246,
                0.708836245,
                0.757846487,
                0.827128815,
                0.882629178,
            ],
        ),
    ];

    #[test]
    fn mt19937_and_randint_match_numpy() {
        // numpy 2.4.6: RandomState(s).randint(0, 2**32, size=n, dtype=np.uint32)
        // (raw 32-bit outputs) and a sequence of randint(0, b) on one generator.
        let mut r = NumpyRandomState::new(1_234_567_890);
        let raw: Vec<u32> = (0..5).map(|_| r.next_u32()).collect();
        assert_eq!(
            raw,
            [2657703298, 1462474751, 2541004134, 640082991, 3816866956]
        );
        let mut r = NumpyRandomState::new(5489);
        assert_eq!(r.next_u32(), 3499211612);
        let mut r = NumpyRandomState::new(1_234_567_890);
        let bounds: [i64; 12] = [
            1,
            2,
            3,
            7,
            100,
            229,
            1000,
            1 << 31,
            (1 << 32) - 1,
            1 << 32,
            1 << 40,
            1_000_000_000_000_000,
        ];
        let got: Vec<i64> = bounds.iter().map(|&b| r.randint(0, b).unwrap()).collect();
        assert_eq!(
            got,
            [
                0,
                0,
                2,
                4,
                51,
                33,
                939,
                1965237353,
                3628085564,
                3342292366,
                589557549700,
                560944186970400
            ]
        );
        let mut r = NumpyRandomState::new(0);
        let got: Vec<i64> = (0..10).map(|_| r.randint(-5, 5).unwrap()).collect();
        assert_eq!(got, [0, -5, -2, -2, 2, 4, -2, 0, -3, -1]);
        // Past the first 624 outputs (a second twist).
        let mut r = NumpyRandomState::new(7);
        let got: Vec<i64> = (0..1000).map(|_| r.randint(0, 22).unwrap()).collect();
        assert_eq!(got[997..], [18, 6, 4]);
        assert!(r.randint(3, 3).is_err());
    }

    #[test]
    fn used_dims_are_the_references_whole_triplets() {
        let d = used_dims();
        assert_eq!(d.len(), 78);
        assert_eq!(&d[..6], &[9, 10, 11, 12, 13, 14]);
        assert_eq!(&d[72..], &[105, 106, 107, 111, 112, 113]);
        assert!(d.windows(2).all(|w| w[0] < w[1]));
        let joints = used_joints();
        assert_eq!(joints.len(), 26);
        let sk = skeleton().unwrap();
        let names: Vec<&str> = joints.iter().map(|&j| sk.joint(j).name.as_str()).collect();
        assert_eq!(&names[..4], &["lfemur", "ltibia", "lfoot", "ltoes"]);
        assert!(!names.contains(&"root") && !names.contains(&"lclavicle"));
        assert!(names.contains(&"lhumerus") && names.contains(&"rthumb"));
        let lower: Vec<&str> = REFERENCE_LOWER_BODY_USED
            .iter()
            .map(|&i| names[i])
            .collect();
        assert_eq!(lower, ["ltibia", "lfoot", "ltoes"]);
        assert_eq!(
            &names[..8],
            &[
                "lfemur", "ltibia", "lfoot", "ltoes", "rfemur", "rtibia", "rfoot", "rtoes"
            ]
        );
    }

    #[test]
    fn skeleton_offsets_are_the_references() {
        let sk = skeleton().unwrap();
        assert_eq!(sk.len(), JOINTS);
        let u = unit_m();
        // The knee sits one femur below the hip; the hip one hip bone from the root.
        let lfemur = sk.joint(2);
        assert_eq!(lfemur.parent, Some(1));
        assert!((lfemur.offset - DVec3::new(1.65674, -1.80282, 0.62477) * u).length() < 1e-12);
        let ltibia = sk.joint(3);
        assert!((ltibia.offset - DVec3::new(2.59720, -7.13576, 0.0) * u).length() < 1e-12);
        // Neck and both clavicles start at the thorax (its bone is empty).
        for j in [16, 20, 29] {
            assert_eq!(sk.joint(j).parent, Some(15));
            assert_eq!(sk.joint(j).offset, DVec3::ZERO);
        }
        // Hip to toe tip at rest, about 0.9 m for an adult.
        let leg: f64 = [2, 3, 4, 5, 6].iter().map(|&j| sk.joint(j).offset.y).sum();
        assert!((-0.95..-0.8).contains(&leg), "{leg}");
    }

    #[test]
    fn expmap_matrix_euler_agree_with_quaternions() {
        let cases = [
            [0.0, 0.0, 0.0],
            [0.3, -0.2, 0.1],
            [1.5, 0.0, 0.0],
            [0.0, 0.0, -2.5],
            [2.0, 1.0, -1.0],
        ];
        for r in cases {
            let m = expmap_to_matrix(r);
            // The reference's matrix is the row-vector rotation: its transpose
            // is the column rotation of our quaternion.
            let q = DMat3::from_quat(expmap_to_quat(r));
            for (i, row) in m.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    assert!((v - q.col(i)[j]).abs() < 1e-6, "{r:?}");
                }
            }
            // The reference's Euler angles decompose its matrix as
            // Rx(-e1) Ry(-e2) Rz(-e3) (column-vector matrices; its epsilon
            // leaves the matrix orthogonal to about 1e-7 only).
            let e = matrix_to_euler(m);
            let back = DMat3::from_rotation_x(-e[0])
                * DMat3::from_rotation_y(-e[1])
                * DMat3::from_rotation_z(-e[2]);
            for (i, row) in m.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    assert!((v - back.col(j)[i]).abs() < 1e-6, "{r:?}");
                }
            }
        }
        // Gimbal case, exact as the reference tests it.
        let e = matrix_to_euler([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]);
        assert_eq!(e, [0.0, -std::f64::consts::FRAC_PI_2, 0.0]);
    }

    fn matrix_eq(a: [f64; 3], b: [f64; 3]) -> bool {
        let (ma, mb) = (expmap_to_matrix(a), expmap_to_matrix(b));
        (0..3).all(|i| (0..3).all(|j| (ma[i][j] - mb[i][j]).abs() < 1e-6))
    }

    fn row(values: &[f64]) -> String {
        values
            .iter()
            .map(|v| format!("{v}"))
            .collect::<Vec<_>>()
            .join(",")
    }

    proptest! {
        #[test]
        fn valid_rows_round_trip_through_motion(
            rows in proptest::collection::vec(
                proptest::collection::vec(-3.0f64..3.0, DIMS), 1..4)
        ) {
            let text: String = rows.iter().map(|r| row(r) + "\n").collect();
            let frames = parse_frames(&text, Path::new("gen.txt")).unwrap();
            prop_assert_eq!(&frames, &rows);
            let m = frames_to_motion(Arc::new(skeleton().unwrap()), &frames, FILE_FPS).unwrap();
            let back = motion_to_frames(&m).unwrap();
            for (a, b) in frames.iter().zip(&back) {
                for d in 0..3 {
                    prop_assert!((a[d] - b[d]).abs() < 1e-9);
                }
                for t in 1..39 {
                    let ra = [a[3 * t], a[3 * t + 1], a[3 * t + 2]];
                    let rb = [b[3 * t], b[3 * t + 1], b[3 * t + 2]];
                    prop_assert!(matrix_eq(ra, rb), "{:?} {:?}", ra, rb);
                }
            }
        }

        #[test]
        fn garbage_rows_are_errors_not_panics(text in "[0-9a-z,.eE+\\- \n]{0,400}") {
            // Anything that is not whole rows of 117 numbers is an error.
            if let Ok(frames) = parse_frames(&text, Path::new("gen.txt")) {
                prop_assert!(!frames.is_empty());
                prop_assert!(frames.iter().all(|f| f.len() == DIMS));
            }
        }

        #[test]
        fn one_bad_field_names_its_line(
            rows in proptest::collection::vec(
                proptest::collection::vec(-3.0f64..3.0, DIMS), 1..4),
            at in 0usize..DIMS,
            junk in "[a-z]{1,5}|",
        ) {
            let mut lines: Vec<String> = rows.iter().map(|r| row(r)).collect();
            let last = lines.len() - 1;
            let mut fields: Vec<String> = lines[last].split(',').map(String::from).collect();
            fields[at] = junk;
            lines[last] = fields.join(",");
            let err = parse_frames(&lines.join("\n"), Path::new("gen.txt")).unwrap_err();
            let msg = err.to_string();
            let line = format!("gen.txt, line {}", last + 1);
            prop_assert!(msg.contains(&line), "{}", msg);
        }
    }

    #[test]
    fn parser_errors_name_file_and_line() {
        let p = Path::new("x/walking_1.txt");
        let e = parse_frames("", p).unwrap_err().to_string();
        assert!(
            e.contains("x/walking_1.txt") && e.contains("no frames"),
            "{e}"
        );
        let good = row(&[0.5; DIMS]);
        let e = parse_frames(&format!("{good}\n1,2,3\n"), p)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 2") && e.contains("3 values, expected 117"),
            "{e}"
        );
        let bad = good.replacen("0.5", "nan", 1);
        let e = parse_frames(&bad, p).unwrap_err().to_string();
        assert!(e.contains("line 1") && e.contains("not finite"), "{e}");
    }

    #[test]
    fn missing_folders_and_files_are_named() {
        let dir = std::env::temp_dir().join(format!("cmu_dmgnn_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let e = CmuDmgnnSet::load(&dir, &["walking"])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("train/walking") && e.contains("no training folder"),
            "{e}"
        );
        let train = dir.join("train/walking");
        std::fs::create_dir_all(&train).unwrap();
        let frames: String = (0..130).map(|_| row(&[0.1; DIMS]) + "\n").collect();
        std::fs::write(train.join("walking_1.txt"), &frames).unwrap();
        std::fs::write(train.join("walking_3.txt"), &frames).unwrap();
        let e = CmuDmgnnSet::load(&dir, &["walking"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing walking_2.txt"), "{e}");
        std::fs::remove_file(train.join("walking_3.txt")).unwrap();
        let e = CmuDmgnnSet::load(&dir, &["walking"])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("test/walking/walking_1.txt") && e.contains("no test file"),
            "{e}"
        );
        let test = dir.join("test/walking");
        std::fs::create_dir_all(&test).unwrap();
        std::fs::write(test.join("walking_1.txt"), &frames[..frames.len() / 2]).unwrap();
        let set = CmuDmgnnSet::load(&dir, &["walking"]).unwrap();
        // 65 lines -> 33 kept frames: too short for a 60-frame window.
        let e = set.test_windows("walking").unwrap_err().to_string();
        assert!(e.contains("33 kept frames"), "{e}");
        assert!(set.test_windows("running").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn real_data_frames_and_normalisation() {
        let Some(set) = complete_set() else { return };
        // Every second frame from the first: 359 lines -> 180 kept frames.
        let walk = set.test("walking").unwrap();
        assert_eq!(walk.frames.len(), 180);
        let all = read_frames(&walk.path).unwrap();
        assert_eq!(walk.frames[1], all[2]);
        assert_eq!(set.train().len(), 25);
        // The 47 constant dims are those the reference ignores and nine more
        // inside used triplets (an unused axis of a one- or two-axis joint).
        let constant = set.constant_dims();
        assert_eq!(constant.len(), 47);
        assert!(constant.iter().all(|d| !(0..6).contains(d)));
        let unused: Vec<usize> = (6..DIMS).filter(|d| !used_dims().contains(d)).collect();
        assert!(unused.iter().all(|d| constant.contains(d)));
        // Normalise / un-normalise keeps every used, non-constant dim and puts
        // the rest at the training mean.
        let frame = &walk.frames[60];
        let used = set.normalise_used(frame);
        assert_eq!(used.len(), 78);
        let back = set.unnormalise_to_full(&used);
        let seen = set.as_seen(frame);
        for d in 0..DIMS {
            assert!(
                (back[d] - seen[d]).abs() < 1e-5 * (1.0 + seen[d].abs()),
                "dim {d}"
            );
        }
        assert_eq!(back[1], set.mean()[1]);
        // Training windows: inside their sequence, every action drawn.
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut seen = std::collections::BTreeSet::new();
        for _ in 0..200 {
            let w = set.sample_train_window(&mut rng).unwrap();
            assert_eq!((w.observed.len(), w.target.len()), (OBSERVED, PREDICTED));
            let seqs: Vec<&Sequence> = set
                .train()
                .iter()
                .filter(|s| s.action == w.action)
                .collect();
            assert!(
                seqs.iter()
                    .any(|s| s.frames.get(w.start) == Some(&w.observed[0])
                        && s.frames.get(w.start + OBSERVED + PREDICTED - 1) == w.target.last())
            );
            seen.insert(w.action);
        }
        assert_eq!(seen.len(), 5);
    }

    #[test]
    fn real_data_motion_conventions() {
        let Some(root) = data_root() else { return };
        let m = read_motion(&root.join("train/walking/walking_1.txt")).unwrap();
        let sk = m.skeleton().clone();
        let (lf, lt, la) = (2, 3, 4);
        let (rf, rt, ra) = (8, 9, 10);
        let mut backward = 0;
        let mut bent = 0;
        let mut lowest = f64::INFINITY;
        for f in 0..m.frames() {
            let x = m.world_transforms(f);
            for (hip, knee, ankle) in [(lf, lt, la), (rf, rt, ra)] {
                // In the pelvis frame, thigh x shin points along +x when the
                // shin swings back (toes point +z).
                let inv = x[0].rotation.inverse();
                let thigh = inv * (x[knee].translation - x[hip].translation);
                let shin = inv * (x[ankle].translation - x[knee].translation);
                let c = thigh.normalize().cross(shin.normalize());
                if c.length() > 0.2 {
                    bent += 1;
                    if c.x > 0.0 {
                        backward += 1;
                    }
                }
            }
            for j in [5, 6, 11, 12] {
                lowest = lowest.min(x[j].translation.y);
            }
        }
        assert!(bent > 50, "{bent}");
        assert_eq!(backward, bent, "knees bend forwards");
        // The toes reach the floor (y = 0) within a few centimetres.
        assert!(lowest.abs() < 0.05, "lowest toe at {lowest} m");
        assert_eq!(sk.joint(lf).name, "lfemur");
    }

    #[test]
    fn real_data_window_starts_match_numpy() {
        let Some(set) = complete_set() else { return };
        for (action, starts) in NUMPY_STARTS {
            assert_eq!(set.window_starts(action).unwrap(), starts, "{action}");
            let windows = set.test_windows(action).unwrap();
            let seq = set.test(action).unwrap();
            for (w, &s) in windows.iter().zip(&starts) {
                assert_eq!(w.start, s);
                assert_eq!(w.observed.len(), OBSERVED);
                assert_eq!(w.target.len(), PREDICTED);
                assert_eq!(w.observed[0], seq.frames[s]);
                assert_eq!(w.target[0], seq.frames[s + OBSERVED]);
            }
        }
    }

    #[test]
    fn real_data_zero_velocity_matches_numpy_and_prints_the_table() {
        let Some(set) = complete_set() else { return };
        println!("zero-velocity mean angle error, CMU (DMGNN preprocessing), 8 windows per action");
        println!("| action | 40 ms | 240 ms | 400 ms |");
        println!("|---|---|---|---|");
        let mut sum = [0.0; 3];
        for (action, expected) in NUMPY_ZERO_VELOCITY {
            let err = set.action_error(action, |w| Ok(w.zero_velocity())).unwrap();
            for (k, (a, b)) in err.iter().zip(expected).enumerate() {
                assert!((a - b).abs() < 2e-9, "{action} frame {k}: {a} vs numpy {b}");
            }
            let r = reported(&err);
            println!("| {action} | {:.3} | {:.3} | {:.3} |", r[0], r[1], r[2]);
            for (s, v) in sum.iter_mut().zip(r) {
                *s += v / 5.0;
            }
        }
        println!(
            "| average | {:.3} | {:.3} | {:.3} |",
            sum[0], sum[1], sum[2]
        );
        // A perfect prediction scores zero; a different one does not.
        let w = &set.test_windows("walking").unwrap()[0];
        let perfect = set.mean_angle_error(&w.target, &w.target).unwrap();
        assert!(perfect.iter().all(|&e| e == 0.0));
        assert!(set.mean_angle_error(&w.target[..3], &w.target).is_err());
    }
}
