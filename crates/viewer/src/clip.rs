//! A clip as the page plays it.
//!
//! Points are the skeleton's joints followed by its end sites (hands, feet
//! and head look finished that way). Per frame the page receives the world
//! positions of every point as little-endian float32 (12 bytes a point), in
//! pages of frames, and once per clip one byte of flags per frame and point:
//! [`OCCLUDED`] (a mask hides the joint), [`CONTACT`] (a sole point touching
//! the ground, by `motion::metrics`' contact rule) and [`SKATING`] (in contact
//! but sliding faster than [`SKATING_M_S`]).

use motion::Motion;
use motion::metrics::{Thresholds, foot_contacts};
use serde::Serialize;

use crate::ViewerError;

pub const OCCLUDED: u8 = 1;
pub const CONTACT: u8 = 2;
pub const SKATING: u8 = 4;
/// Horizontal speed of a planted sole point above which it is drawn as skating
/// (the acceptance limit of physical correction on mean skating).
pub const SKATING_M_S: f64 = 0.1;

/// One point of the drawn skeleton.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Point {
    pub name: String,
    /// Index of the point it hangs from, -1 for the root.
    pub parent: i32,
    /// An end site (no joint of its own).
    pub end: bool,
}

/// An IK edit to mark: the effector, the keyframe and the target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ik {
    /// Index of the effector among the points.
    pub effector: usize,
    pub effector_name: String,
    /// Frame of this clip at which the effector should reach the target.
    pub keyframe: usize,
    /// World position, metres.
    pub target: Option<[f64; 3]>,
}

/// Everything the page needs before the frames.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Meta {
    pub name: String,
    pub fps: f64,
    pub frames: usize,
    pub points: Vec<Point>,
    /// Whether some joint is occluded in some frame.
    pub masked: bool,
    /// Sole points (indices among the points) whose contacts are flagged.
    pub soles: Vec<usize>,
    pub ik: Option<Ik>,
    /// Box around every point over the clip, metres.
    pub bounds: Bounds,
    /// Bytes of one frame of positions.
    pub frame_bytes: usize,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bounds {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// A clip ready to be served: positions and flags of every frame.
#[derive(Debug, Clone)]
pub struct ClipView {
    meta: Meta,
    /// `[frames, points, 3]` float32.
    positions: Vec<f32>,
    /// `[frames, points]`.
    flags: Vec<u8>,
}

impl ClipView {
    /// From a motion and its optional occlusion mask (`[frames, joints]`, true =
    /// visible, as the NPZ outputs store it).
    pub fn from_motion(
        name: &str,
        motion: &Motion,
        visible: Option<&[bool]>,
    ) -> Result<ClipView, ViewerError> {
        let s = motion.skeleton();
        let (n_t, n_j) = (motion.frames(), motion.joints());
        if let Some(v) = visible
            && v.len() != n_t * n_j
        {
            return Err(ViewerError::Bad {
                path: name.into(),
                message: format!(
                    "mask has {} values, the clip {n_t} frames x {n_j} joints",
                    v.len()
                ),
            });
        }
        let mut points: Vec<Point> = s
            .joints()
            .iter()
            .map(|j| Point {
                name: j.name.clone(),
                parent: j.parent.map_or(-1, |p| p as i32),
                end: false,
            })
            .collect();
        // End sites after the joints: (joint, offset, point index).
        let mut ends = Vec::new();
        for (j, joint) in s.joints().iter().enumerate() {
            if let Some(offset) = joint.end_site {
                ends.push((j, offset, points.len()));
                points.push(Point {
                    name: format!("{}_end", joint.name),
                    parent: j as i32,
                    end: true,
                });
            }
        }
        let n_p = points.len();
        let mut positions = Vec::with_capacity(n_t * n_p * 3);
        let mut x = vec![motion::skeleton::Transform::IDENTITY; n_j];
        for t in 0..n_t {
            motion.world_transforms_into(t, &mut x);
            for tr in &x {
                positions.extend(tr.translation.to_array().map(|v| v as f32));
            }
            for (j, offset, _) in &ends {
                let p = x[*j].translation + x[*j].rotation * *offset;
                positions.extend(p.to_array().map(|v| v as f32));
            }
        }

        let mut flags = vec![0u8; n_t * n_p];
        if let Some(visible) = visible {
            for t in 0..n_t {
                for j in 0..n_j {
                    if !visible[t * n_j + j] {
                        flags[t * n_p + j] |= OCCLUDED;
                    }
                }
                // An end site is hidden with its joint.
                for (j, _, p) in &ends {
                    if !visible[t * n_j + j] {
                        flags[t * n_p + p] |= OCCLUDED;
                    }
                }
            }
        }
        let contacts = foot_contacts(motion, &Thresholds::default());
        let soles: Vec<usize> = contacts
            .points
            .iter()
            .map(|&(j, end)| {
                if end {
                    ends.iter().find(|e| e.0 == j).map_or(j, |e| e.2)
                } else {
                    j
                }
            })
            .collect();
        let nf = soles.len();
        // A step's contact marks both of its frames.
        for t in 0..n_t.saturating_sub(1) {
            for (i, &p) in soles.iter().enumerate() {
                if let Some(speed) = contacts.steps[t * nf + i] {
                    let flag = CONTACT | if speed > SKATING_M_S { SKATING } else { 0 };
                    flags[t * n_p + p] |= flag;
                    flags[(t + 1) * n_p + p] |= flag;
                }
            }
        }

        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in positions.chunks_exact(3) {
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        if positions.is_empty() {
            (min, max) = ([0.0; 3], [0.0; 3]);
        }
        Ok(ClipView {
            meta: Meta {
                name: name.to_string(),
                fps: motion.fps(),
                frames: n_t,
                masked: visible.is_some_and(|v| v.iter().any(|x| !x)),
                frame_bytes: n_p * 12,
                points,
                soles,
                ik: None,
                bounds: Bounds { min, max },
            },
            positions,
            flags,
        })
    }

    /// Marks an IK edit of `effector` (a joint name) reaching `target` at
    /// `keyframe_s` seconds into the clip. Unknown effectors are ignored.
    pub fn with_ik(mut self, effector: &str, keyframe_s: f64, target: Option<[f64; 3]>) -> Self {
        if let Some(i) = self
            .meta
            .points
            .iter()
            .position(|p| !p.end && p.name == effector)
        {
            let frame = (keyframe_s * self.meta.fps).round().max(0.0) as usize;
            self.meta.ik = Some(Ik {
                effector: i,
                effector_name: effector.to_string(),
                keyframe: frame.min(self.meta.frames.saturating_sub(1)),
                target,
            });
        }
        self
    }

    pub fn meta(&self) -> &Meta {
        &self.meta
    }

    /// Positions of frames `start .. start + count` (clamped to the clip), as
    /// little-endian float32 `[count, points, 3]`.
    pub fn frames_bytes(&self, start: usize, count: usize) -> Result<Vec<u8>, ViewerError> {
        let frames = self.meta.frames;
        let end = start.saturating_add(count).min(frames);
        if start >= frames && !(start == 0 && frames == 0) {
            return Err(ViewerError::Range {
                start,
                end: start.saturating_add(count),
                frames,
            });
        }
        let per = self.meta.points.len() * 3;
        let values = &self.positions[start * per..end * per];
        let mut out = Vec::with_capacity(values.len() * 4);
        for v in values {
            out.extend_from_slice(&v.to_le_bytes());
        }
        Ok(out)
    }

    /// Flags of every frame and point, `[frames, points]`.
    pub fn flags(&self) -> &[u8] {
        &self.flags
    }

    /// Positions as float32 `[frames, points, 3]`.
    pub fn positions(&self) -> &[f32] {
        &self.positions
    }
}

/// An array of float32 or float64 values as f64.
fn numbers(a: &motion::npz::NpyArray) -> Option<Vec<f64>> {
    a.to_f64()
        .or_else(|| a.to_f32().map(|v| v.into_iter().map(f64::from).collect()))
}

/// A motion and its mask from an NPZ written by motionaug (`rotations`,
/// `root_translation`, `offsets`, `parents`, `joint_names`, `fps`, optional
/// `mask`): the skeleton is rebuilt from offsets and parents, so FK gives the
/// stored positions back.
pub fn npz_motion(bytes: &[u8], label: &str) -> Result<(Motion, Option<Vec<bool>>), ViewerError> {
    let bad = |message: String| ViewerError::Bad {
        path: label.to_string(),
        message,
    };
    let arrays = motion::npz::read(bytes).map_err(|e| bad(format!("not a readable NPZ: {e}")))?;
    let find = |name: &str| arrays.iter().find(|a| a.name == name);
    let need = |name: &str| find(name).ok_or_else(|| bad(format!("no `{name}` array")));
    let names = need("joint_names")?
        .to_strings()
        .ok_or_else(|| bad("`joint_names` is not text".into()))?;
    let parents = need("parents")?
        .to_i32()
        .ok_or_else(|| bad("`parents` is not int32".into()))?;
    let offsets =
        numbers(need("offsets")?).ok_or_else(|| bad("`offsets` is not numeric".into()))?;
    let rotations =
        numbers(need("rotations")?).ok_or_else(|| bad("`rotations` is not numeric".into()))?;
    let root = numbers(need("root_translation")?)
        .ok_or_else(|| bad("`root_translation` is not numeric".into()))?;
    let fps = numbers(need("fps")?)
        .and_then(|v| v.first().copied())
        .ok_or_else(|| bad("`fps` is not a number".into()))?;
    let n_j = names.len();
    if parents.len() != n_j || offsets.len() != n_j * 3 {
        return Err(bad(format!(
            "{n_j} joint names but {} parents and {} offsets",
            parents.len(),
            offsets.len() / 3
        )));
    }
    if n_j == 0 || rotations.len() % (n_j * 4) != 0 {
        return Err(bad("`rotations` is not [frames, joints, 4]".into()));
    }
    let n_t = rotations.len() / (n_j * 4);
    if root.len() != n_t * 3 {
        return Err(bad("`root_translation` is not [frames, 3]".into()));
    }
    let joints = names
        .iter()
        .enumerate()
        .map(|(j, name)| motion::Joint {
            name: name.clone(),
            parent: usize::try_from(parents[j]).ok(),
            offset: glam::DVec3::new(offsets[j * 3], offsets[j * 3 + 1], offsets[j * 3 + 2]),
            channels: vec![],
            end_site: None,
            limits: None,
        })
        .collect();
    let skeleton = std::sync::Arc::new(motion::Skeleton::new(joints, 1.0)?);
    let quats = rotations
        .chunks_exact(4)
        .map(|q| glam::DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize())
        .collect();
    let root = root
        .chunks_exact(3)
        .map(|p| glam::DVec3::new(p[0], p[1], p[2]))
        .collect();
    let motion = Motion::new(skeleton, fps, root, quats)?;
    let mask = match find("mask") {
        None => None,
        Some(m) => {
            let v = m
                .to_u8()
                .ok_or_else(|| bad("`mask` is not boolean".into()))?;
            if v.len() != n_t * n_j {
                return Err(bad("`mask` is not [frames, joints]".into()));
            }
            Some(v.into_iter().map(|b| b != 0).collect())
        }
    };
    Ok((motion, mask))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walk() -> Motion {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/data/16_11_walk_veer_left.bvh");
        motion::load(&path, &motion::LoadOptions::default()).expect("the bundled walk")
    }

    fn floats(bytes: &[u8]) -> Vec<f32> {
        bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    }

    #[test]
    fn points_are_joints_then_end_sites_at_their_fk_positions() {
        let m = walk();
        let view = ClipView::from_motion("walk", &m, None).unwrap();
        let meta = view.meta();
        let ends = m
            .skeleton()
            .joints()
            .iter()
            .filter(|j| j.end_site.is_some())
            .count();
        assert_eq!(meta.points.len(), m.joints() + ends);
        assert_eq!(meta.frames, m.frames());
        assert_eq!(meta.frame_bytes, meta.points.len() * 12);
        assert!(
            meta.points[m.joints()..]
                .iter()
                .all(|p| p.end && p.parent >= 0)
        );
        let t = 100;
        let page = floats(&view.frames_bytes(t, 3).unwrap());
        assert_eq!(page.len(), 3 * meta.points.len() * 3);
        for (j, p) in m.world_positions(t).iter().enumerate() {
            for k in 0..3 {
                assert!((page[j * 3 + k] as f64 - p[k]).abs() < 1e-5);
            }
        }
        // The last page is cut at the end; past the end is an error.
        let tail = view.frames_bytes(m.frames() - 2, 10).unwrap();
        assert_eq!(tail.len(), 2 * meta.frame_bytes);
        assert!(view.frames_bytes(m.frames(), 1).is_err());
        for k in 0..3 {
            assert!(meta.bounds.min[k] < meta.bounds.max[k]);
        }
    }

    #[test]
    fn planted_soles_are_flagged_and_only_they() {
        let m = walk();
        let view = ClipView::from_motion("walk", &m, None).unwrap();
        let meta = view.meta();
        let n_p = meta.points.len();
        assert!(!meta.soles.is_empty());
        let mut contact_frames = 0;
        for t in 0..meta.frames {
            for p in 0..n_p {
                let f = view.flags()[t * n_p + p];
                assert_eq!(f & OCCLUDED, 0, "no mask, nothing occluded");
                if f & (CONTACT | SKATING) != 0 {
                    assert!(
                        meta.soles.contains(&p),
                        "{} is not a sole point",
                        meta.points[p].name
                    );
                    assert!(f & CONTACT != 0, "skating is a kind of contact");
                    contact_frames += 1;
                }
            }
        }
        // A walk is on the ground much of the time.
        assert!(contact_frames > meta.frames / 4, "{contact_frames}");
    }

    #[test]
    fn a_mask_hides_its_joints_and_their_end_sites() {
        let m = walk();
        let (n_t, n_j) = (m.frames(), m.joints());
        let hidden = m
            .skeleton()
            .joints()
            .iter()
            .position(|j| j.end_site.is_some())
            .unwrap();
        let visible: Vec<bool> = (0..n_t * n_j)
            .map(|i| !(i % n_j == hidden && i / n_j >= 10))
            .collect();
        let view = ClipView::from_motion("walk", &m, Some(&visible)).unwrap();
        let meta = view.meta();
        assert!(meta.masked);
        let n_p = meta.points.len();
        let end = meta
            .points
            .iter()
            .position(|p| p.end && p.parent == hidden as i32)
            .unwrap();
        for t in 0..n_t {
            for p in 0..n_p {
                let occluded = view.flags()[t * n_p + p] & OCCLUDED != 0;
                assert_eq!(
                    occluded,
                    t >= 10 && (p == hidden || p == end),
                    "frame {t} point {p}"
                );
            }
        }
        assert!(ClipView::from_motion("walk", &m, Some(&visible[1..])).is_err());
    }

    #[test]
    fn ik_keyframes_follow_the_clip_rate() {
        let m = walk();
        let view = ClipView::from_motion("walk", &m, None).unwrap().with_ik(
            "RightFoot",
            1.5,
            Some([0.1, 0.0, 0.2]),
        );
        let ik = view.meta().ik.clone().expect("RightFoot is a joint");
        assert_eq!(ik.keyframe, (1.5 * m.fps()).round() as usize);
        assert_eq!(view.meta().points[ik.effector].name, "RightFoot");
        let none =
            ClipView::from_motion("walk", &m, None)
                .unwrap()
                .with_ik("NoSuchJoint", 1.0, None);
        assert!(none.meta().ik.is_none());
    }

    #[test]
    fn npz_outputs_read_back_with_their_mask() {
        let m = walk();
        let (n_t, n_j) = (m.frames(), m.joints());
        let visible: Vec<bool> = (0..n_t * n_j).map(|i| i % 3 != 0).collect();
        let mask = motion::npz::NpyArray::bool("mask", &[n_t, n_j], &visible).unwrap();
        let bytes = motion::npz::motion_to_bytes(&m, &[mask]).unwrap();
        let (back, read_mask) = npz_motion(&bytes, "walk.npz").unwrap();
        assert_eq!(read_mask.as_deref(), Some(&visible[..]));
        assert_eq!((back.frames(), back.joints()), (n_t, n_j));
        assert!((back.fps() - m.fps()).abs() < 1e-9);
        for t in [0, n_t / 2, n_t - 1] {
            for (a, b) in m.world_positions(t).iter().zip(back.world_positions(t)) {
                assert!((*a - b).length() < 1e-4, "frame {t}: {a} vs {b}");
            }
        }
        let err = npz_motion(b"not a zip", "bad.npz").unwrap_err();
        assert!(err.to_string().contains("bad.npz"), "{err}");
    }
}
