//! IK synthesis after MotionAug (Sec. 3.2, 4.3 and supplementary Sec. 10).
//!
//! 1. Effector: a joint by name, or the foot/hand (ankle/wrist joint) reaching
//!    farthest from the root horizontally over the clip; a preset picks foot or
//!    hand as the paper does (foot for punch, kick, walk, jog, sneak; hand for
//!    grab, deposit, throw). Two presets are ours, not the paper's, for the
//!    HDM05 classes it does not use: hop (a foot, the locomotion fan) and squat
//!    (a hand, reach and heading varied, height kept within 20 %).
//! 2. Keyframe: the frame where the effector is farthest from the root
//!    horizontally, shifted by a uniform jitter in `[-key_jitter_s, +key_jitter_s]`
//!    (default 0.1 s, as in the authors' configuration files).
//! 3. Target: sampled uniformly in a fan around the vertical axis through the
//!    limb's base joint (hip/shoulder) at the keyframe, in cylindrical
//!    coordinates relative to the keyframe position `(r0, h0, theta0)`: `r0` is
//!    the horizontal hip-to-effector distance, `h0` the effector's height above
//!    the ground plane y = 0, `theta0` its heading around the axis (as in the
//!    authors' code). The target is `(r * r0, h * h0, theta0 + theta)` with `r`,
//!    `h`, `theta` drawn uniformly from the ranges. Targets out of the limb's
//!    reach (or needing a joint past its limits at the keyframe) are redrawn, up
//!    to `max_tries` times; after that the last draw is used and the IK clamps it
//!    (reported as `reachable = false`).
//! 4. Propagation: `p_target(t) = p(t) + (p_sample - p(t_key)) * f(t)`, with
//!    `f = t / t_key` before the keyframe and `(T-1-t) / (T-1-t_key)` after it
//!    (frame indices `0..T`, so the first and last frames are unchanged unless
//!    they are the keyframe).
//! 5. Per frame, FABRIK on the two-bone limb (see [`limb`]): bone lengths are
//!    exact because only rotations change; the knee/elbow keeps its bend plane
//!    and direction; joint limits from the file are respected (clamped, widened
//!    to the source pose's own angle); the effector keeps its local rotation
//!    (default) or its world orientation.
//!
//! The output reports the effector, keyframe, target, the achieved error at the
//! keyframe and the largest error over all frames (both from FK of the output),
//! and how many frames were clamped by reach or limits.

pub mod fabrik;
pub mod limb;
pub mod limits;

use glam::{DQuat, DVec3};
use motion::Motion;
use motion::skeleton::Transform;
use serde::{Deserialize, Serialize};

pub use limb::{EffectorOrientation, Limb};

use crate::{Augmented, Range, SynthError, SynthRng, names};

/// The paper's action classes, and two of ours (hop, squat) so every HDM05
/// class of `../shared/data/hdm05` has IK edits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    Punch,
    Kick,
    Walk,
    Grab,
    Deposit,
    Jog,
    Sneak,
    Throw,
    /// Not in the paper: a foot with the locomotion fan (the landing stance
    /// changes; the hop itself is left to physics).
    Hop,
    /// Not in the paper: a hand (the arms that balance the squat) swung up to
    /// 45 degrees sideways, its reach scaled 0.5-2x and its height 0.8-1.2x.
    Squat,
}

/// Which kind of end effector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Limbs {
    Foot,
    Hand,
}

/// The fan: scale ranges for r and h, an offset range for theta (radians).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fan {
    pub r: Range,
    pub h: Range,
    pub theta: Range,
}

impl Preset {
    /// Ranges of MotionAug Sec. 4.3 (punch, kick, walk) and Sec. 10 (grab,
    /// deposit, jog, sneak, throw); hop and squat are ours.
    pub fn fan(self) -> Fan {
        let wide = Range(0.5, 2.0);
        let one = Range(1.0, 1.0);
        match self {
            Preset::Kick => Fan {
                r: Range(0.8, 1.2),
                h: Range(0.8, 1.2),
                theta: Range(-0.785, 0.785),
            },
            Preset::Punch | Preset::Grab | Preset::Deposit | Preset::Throw => Fan {
                r: wide,
                h: one,
                theta: Range(-1.7, 1.7),
            },
            Preset::Walk | Preset::Jog | Preset::Sneak | Preset::Hop => Fan {
                r: wide,
                h: one,
                theta: Range(-0.3, 0.3),
            },
            Preset::Squat => Fan {
                r: wide,
                h: Range(0.8, 1.2),
                theta: Range(-0.785, 0.785),
            },
        }
    }

    /// The paper's effector: a hand for grab, deposit and throw (and squat),
    /// else a foot.
    pub fn limb(self) -> Limbs {
        match self {
            Preset::Grab | Preset::Deposit | Preset::Throw | Preset::Squat => Limbs::Hand,
            _ => Limbs::Foot,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IkParams {
    /// The paper's class: selects the fan ranges and the effector kind.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<Preset>,
    /// `"foot"`, `"hand"`, `"auto"` (the preset's kind, else foot) or a joint name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effector: Option<String>,
    /// Scale range of the horizontal distance (overrides the preset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub r: Option<Range>,
    /// Scale range of the height above the ground (overrides the preset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub h: Option<Range>,
    /// Offset range of the heading, radians (overrides the preset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta: Option<Range>,
    /// Keyframe jitter, seconds (uniform in +-).
    #[serde(default = "default_jitter")]
    pub key_jitter_s: f64,
    #[serde(default)]
    pub orientation: EffectorOrientation,
    /// Clamp to the file's joint limits (ASF) where present.
    #[serde(default = "yes")]
    pub respect_limits: bool,
    /// Redraws of a target that is out of reach.
    #[serde(default = "default_tries")]
    pub max_tries: u32,
}

fn default_jitter() -> f64 {
    0.1
}
fn yes() -> bool {
    true
}
fn default_tries() -> u32 {
    100
}

impl IkParams {
    pub fn preset(preset: Preset) -> Self {
        IkParams {
            preset: Some(preset),
            effector: None,
            r: None,
            h: None,
            theta: None,
            key_jitter_s: default_jitter(),
            orientation: EffectorOrientation::Local,
            respect_limits: true,
            max_tries: default_tries(),
        }
    }

    /// The fan in effect: explicit ranges over the preset's.
    pub fn fan(&self) -> Result<Fan, SynthError> {
        let base = self.preset.map(Preset::fan);
        let pick = |own: Option<Range>, from: Option<Range>, field: &str| {
            own.or(from).ok_or_else(|| {
                SynthError::param(field, "required without a `preset` (or give a preset)")
            })
        };
        Ok(Fan {
            r: pick(self.r, base.map(|f| f.r), "r")?,
            h: pick(self.h, base.map(|f| f.h), "h")?,
            theta: pick(self.theta, base.map(|f| f.theta), "theta")?,
        })
    }

    pub fn validate(&self) -> Result<(), SynthError> {
        let fan = self.fan()?;
        fan.r.validate("r")?;
        fan.h.validate("h")?;
        fan.theta.validate("theta")?;
        if fan.r.0 < 0.0 || fan.r.1 > 10.0 {
            return Err(SynthError::param("r", "scale must lie within [0, 10]"));
        }
        if fan.h.0 < -10.0 || fan.h.1 > 10.0 {
            return Err(SynthError::param("h", "scale must lie within [-10, 10]"));
        }
        let pi = std::f64::consts::PI;
        if fan.theta.0 < -pi || fan.theta.1 > pi {
            return Err(SynthError::param(
                "theta",
                "offset must lie within [-pi, pi] radians",
            ));
        }
        if !(self.key_jitter_s.is_finite() && (0.0..=2.0).contains(&self.key_jitter_s)) {
            return Err(SynthError::param(
                "key_jitter_s",
                "must be in [0, 2] seconds",
            ));
        }
        if !(1..=10_000).contains(&self.max_tries) {
            return Err(SynthError::param("max_tries", "must be in 1..=10000"));
        }
        if let Some(e) = &self.effector
            && e.trim().is_empty()
        {
            return Err(SynthError::param("effector", "must not be empty"));
        }
        Ok(())
    }
}

/// What the IK op did, for the manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IkReport {
    pub effector: String,
    /// Keyframe index in the output (the output has the input's frame count).
    pub keyframe: usize,
    /// Keyframe before jitter.
    pub keyframe_farthest: usize,
    /// Effector target at the keyframe, world metres.
    pub target: [f64; 3],
    /// Effector position at the keyframe in the source, world metres.
    pub source_position: [f64; 3],
    /// The fan in effect (preset ranges with explicit overrides).
    pub fan: Fan,
    /// Keyframe cylindrical coordinates around the hip/shoulder axis: horizontal
    /// distance (m), height above y = 0 (m), heading (radians, atan2(x, z)).
    pub key_r_m: f64,
    pub key_h_m: f64,
    pub key_theta: f64,
    /// Drawn fan coordinates: r scale, h scale, theta offset (radians).
    pub r_scale: f64,
    pub h_scale: f64,
    pub theta_offset: f64,
    pub reachable: bool,
    pub tries: u32,
    /// |effector - target| at the keyframe after IK (FK of the output), metres.
    pub error_keyframe_m: f64,
    /// Largest |effector - target(t)| over all frames, metres.
    pub error_max_m: f64,
    pub frames_out_of_reach: usize,
    pub frames_limit_clamped: usize,
}

fn all_transforms(motion: &Motion) -> Vec<Vec<Transform>> {
    (0..motion.frames())
        .map(|t| motion.world_transforms(t))
        .collect()
}

fn horizontal(v: DVec3) -> f64 {
    DVec3::new(v.x, 0.0, v.z).length()
}

/// Largest horizontal distance of `joint` from the root over the clip, and its frame.
fn farthest(frames: &[Vec<Transform>], joint: usize) -> (f64, usize) {
    let mut best = (f64::NEG_INFINITY, 0);
    for (t, x) in frames.iter().enumerate() {
        let d = horizontal(x[joint].translation - x[0].translation);
        if d > best.0 {
            best = (d, t);
        }
    }
    best
}

fn choose_effector(
    motion: &Motion,
    params: &IkParams,
    frames: &[Vec<Transform>],
) -> Result<usize, SynthError> {
    let skeleton = motion.skeleton();
    let requested = params.effector.as_deref().map(str::trim);
    let kind = match requested.map(str::to_ascii_lowercase).as_deref() {
        Some("foot") => Limbs::Foot,
        Some("hand") => Limbs::Hand,
        Some("auto") | None => params.preset.map(Preset::limb).unwrap_or(Limbs::Foot),
        Some(_) => {
            let name = requested.unwrap_or_default();
            return skeleton.find(name).ok_or_else(|| {
                SynthError::param(
                    "effector",
                    format!("no joint named `{name}` in the skeleton"),
                )
            });
        }
    };
    let candidates = match kind {
        Limbs::Foot => names::feet(skeleton),
        Limbs::Hand => names::hands(skeleton),
    };
    let usable: Vec<usize> = candidates
        .into_iter()
        .filter(|&j| Limb::new(skeleton, j).is_ok())
        .collect();
    usable
        .into_iter()
        .map(|j| (farthest(frames, j).0, j))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, j)| j)
        .ok_or_else(|| {
            SynthError::Skeleton(format!(
                "no {kind:?} joint with a two-bone limb found by name; set `effector` to a joint name"
            ))
        })
}

/// Blend weight of MotionAug's propagation at frame `t` (frames `0..n`).
pub fn blend_weight(t: usize, key: usize, n: usize) -> f64 {
    if t == key {
        1.0
    } else if t < key {
        t as f64 / key as f64
    } else {
        (n - 1 - t) as f64 / (n - 1 - key) as f64
    }
}

/// Would the limb reach `target` at this pose with its knee/hip inside limits?
fn keyframe_ok(
    motion: &Motion,
    limb: &Limb,
    frame: usize,
    x: &[Transform],
    target: DVec3,
    params: &IkParams,
) -> bool {
    let (l1, l2) = limb.lengths(x);
    let d = (target - x[limb.upper].translation).length();
    if d > l1 + l2 || d < (l1 - l2).abs() {
        return false;
    }
    if !params.respect_limits {
        return true;
    }
    let mut pose = motion.pose(frame).to_vec();
    let edit = limb::solve_frame(
        motion.skeleton(),
        limb,
        x,
        &mut pose,
        motion.pose(frame),
        target,
        limb::SolveOptions {
            orientation: params.orientation,
            respect_limits: true,
        },
    );
    !edit.clamped
}

/// MotionAug IK synthesis on one clip.
pub fn ik(motion: &Motion, params: &IkParams, rng: &mut SynthRng) -> Result<Augmented, SynthError> {
    params.validate()?;
    let fan = params.fan()?;
    let skeleton = motion.skeleton().clone();
    let frames = all_transforms(motion);
    let effector = choose_effector(motion, params, &frames)?;
    let mut limb = Limb::new(&skeleton, effector)?;
    limb.estimate_hinge(&skeleton, &frames);
    let n = motion.frames();

    // Keyframe with jitter.
    let (_, key0) = farthest(&frames, effector);
    let shift = Range(-params.key_jitter_s, params.key_jitter_s).sample(rng) * motion.fps();
    let key = (key0 as f64 + shift).round().clamp(0.0, (n - 1) as f64) as usize;

    // Fan target.
    let xk = &frames[key];
    let base = xk[limb.upper].translation;
    let p_key = xk[effector].translation;
    let rel = p_key - base;
    let (r0, h0, theta0) = (horizontal(rel), p_key.y, rel.x.atan2(rel.z));
    let mut tries = 0;
    let (target, draw, reachable) = loop {
        tries += 1;
        let (rs, hs, ts) = (fan.r.sample(rng), fan.h.sample(rng), fan.theta.sample(rng));
        let th = theta0 + ts;
        let target = DVec3::new(
            base.x + rs * r0 * th.sin(),
            hs * h0,
            base.z + rs * r0 * th.cos(),
        );
        let ok = keyframe_ok(motion, &limb, key, xk, target, params);
        if ok || tries >= params.max_tries {
            break (target, (rs, hs, ts), ok);
        }
    };

    // Propagate and solve every frame.
    let diff = target - p_key;
    let mut rot = motion.rotations().to_vec();
    let j_n = motion.joints();
    let mut targets = Vec::with_capacity(n);
    let (mut out_of_reach, mut clamped) = (0, 0);
    for (t, x) in frames.iter().enumerate() {
        let goal = x[effector].translation + diff * blend_weight(t, key, n);
        targets.push(goal);
        let pose: &mut [DQuat] = &mut rot[t * j_n..(t + 1) * j_n];
        let edit = limb::solve_frame(
            &skeleton,
            &limb,
            x,
            pose,
            motion.pose(t),
            goal,
            limb::SolveOptions {
                orientation: params.orientation,
                respect_limits: params.respect_limits,
            },
        );
        out_of_reach += usize::from(edit.out_of_reach);
        clamped += usize::from(edit.clamped);
    }
    let out = motion.with_frames(motion.fps(), motion.root_translation().to_vec(), rot)?;

    // Measure what was achieved, from FK of the output.
    let mut buf = vec![Transform::IDENTITY; j_n];
    let mut err_max = 0.0f64;
    let mut err_key = 0.0;
    for (t, goal) in targets.iter().enumerate() {
        out.world_transforms_into(t, &mut buf);
        let e = (buf[effector].translation - *goal).length();
        err_max = err_max.max(e);
        if t == key {
            err_key = e;
        }
    }
    let report = IkReport {
        effector: skeleton.joint(effector).name.clone(),
        keyframe: key,
        keyframe_farthest: key0,
        target: target.to_array(),
        source_position: p_key.to_array(),
        fan,
        key_r_m: r0,
        key_h_m: h0,
        key_theta: theta0,
        r_scale: draw.0,
        h_scale: draw.1,
        theta_offset: draw.2,
        reachable,
        tries,
        error_keyframe_m: err_key,
        error_max_m: err_max,
        frames_out_of_reach: out_of_reach,
        frames_limit_clamped: clamped,
    };
    tracing::debug!(?report, "ik done");
    let mut aug = Augmented::new(out);
    if let Ok(serde_json::Value::Object(m)) = serde_json::to_value(&report) {
        aug.sampled = m;
    }
    Ok(aug)
}
