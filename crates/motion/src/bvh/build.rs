//! From the raw hierarchy and frame values to a [`Motion`]: each joint's
//! channel columns, non-root position channels read as translations
//! ([`super::translation`]: constant ones become the joint's offset, varying
//! ones a translation track), the length unit and skeleton, the root
//! translation and local rotations of every frame, and last the static joints
//! above a travelling joint folded into the skeleton's base ([`super::base`]).

use std::sync::Arc;

use glam::{DQuat, DVec3};

use super::base;
use super::frames::Values;
use super::hierarchy::RawJoint;
use super::translation;
use crate::error::{MotionError, ParseError};
use crate::motion::{Motion, Tracks};
use crate::rotation;
use crate::skeleton::{Axis, Channel, Joint, Skeleton};
use crate::text::Errors;
use crate::units::{self, Unit};

/// Turn the raw hierarchy and frame values into a [`Motion`] at `frame_rate` fps.
pub(super) fn motion(
    raw: &[RawJoint],
    values: &Values,
    frame_rate: f64,
    unit: Unit,
    errors: &Errors,
) -> Result<Motion, MotionError> {
    let first_column = first_columns(raw);
    let still = still_joints(raw, values, &first_column);
    let (offsets, file_tracks) = translations(raw, values, &first_column);
    let parents: Vec<Option<usize>> = raw.iter().map(|j| j.parent).collect();
    let tracked: Vec<bool> = file_tracks.iter().map(Option::is_some).collect();
    let chain = base::static_chain(&parents, &still, &tracked);
    // The body's size for the unit guess leaves the static joints out.
    let body: Vec<bool> = (0..raw.len())
        .map(|j| chain.as_ref().is_none_or(|(_, c)| !c.contains(&j)))
        .collect();
    let (skeleton, scale) = skeleton(raw, &offsets, &body, unit, errors)?;
    let (root_translation, rotations) = poses(raw, values, &first_column, &offsets, scale);
    let tracks: Tracks = file_tracks
        .into_iter()
        .map(|t| t.map(|t| t.into_iter().map(|p| p * scale).collect()))
        .collect();
    let whole = |e: MotionError| -> MotionError { errors.whole(e.to_string()).into() };
    let motion = Motion::new(skeleton, frame_rate, root_translation, rotations)
        .and_then(|m| m.with_tracks(tracks))
        .map_err(whole)?;
    match chain {
        Some((travelling, chain)) => {
            base::fold_static_base(motion, travelling, &chain).map_err(whole)
        }
        None => Ok(motion),
    }
}

/// First column of each joint's channels.
fn first_columns(raw: &[RawJoint]) -> Vec<usize> {
    let mut first_column = Vec::with_capacity(raw.len());
    let mut col = 0;
    for j in raw {
        first_column.push(col);
        col += j.channels.len();
    }
    first_column
}

/// Whether two values of one channel are the same up to the rounding of the text.
fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * (1.0 + a.abs().max(b.abs()))
}

/// Whether channel column `c` holds one value over the clip.
fn constant_column(values: &Values, c: usize) -> bool {
    let first = values.at(0, c);
    (1..values.frames).all(|f| same(values.at(f, c), first))
}

/// Per joint: whether every one of its channels holds still over the clip.
fn still_joints(raw: &[RawJoint], values: &Values, first_column: &[usize]) -> Vec<bool> {
    raw.iter()
        .zip(first_column)
        .map(|(j, &c0)| (c0..c0 + j.channels.len()).all(|c| constant_column(values, c)))
        .collect()
}

/// Each joint's offset (file units) and, for joints whose position channels
/// vary, its local translation per frame (file units). The root keeps its
/// `OFFSET` (its position channels are the root translation, see [`poses`]);
/// other joints' position channels are read by [`translation::reads_absolute`]:
/// constant ones become the offset, varying ones a track (the offset stays the
/// file's `OFFSET`, the rest pose).
fn translations(
    raw: &[RawJoint],
    values: &Values,
    first_column: &[usize],
) -> (Vec<DVec3>, Vec<Option<Vec<DVec3>>>) {
    let mut offsets: Vec<DVec3> = raw
        .iter()
        .map(|j| j.offset.unwrap_or(DVec3::ZERO))
        .collect();
    let mut tracks: Vec<Option<Vec<DVec3>>> = vec![None; raw.len()];
    for (ji, j) in raw.iter().enumerate().skip(1) {
        let columns: Vec<(usize, usize)> = j
            .channels
            .iter()
            .enumerate()
            .filter_map(|(k, c)| match c {
                Channel::Position(axis) => Some((axis.index(), first_column[ji] + k)),
                Channel::Rotation(_) => None,
            })
            .collect();
        if columns.is_empty() {
            continue;
        }
        let offset = offsets[ji];
        let raw_values: Vec<DVec3> = (0..values.frames)
            .map(|f| {
                let mut v = DVec3::ZERO;
                for &(axis, c) in &columns {
                    v[axis] = values.at(f, c);
                }
                v
            })
            .collect();
        let axes: Vec<usize> = columns.iter().map(|&(axis, _)| axis).collect();
        let absolute = translation::reads_absolute(&raw_values, offset, &axes);
        let local: Vec<DVec3> = raw_values
            .iter()
            .map(|v| {
                let mut p = offset;
                for &a in &axes {
                    p[a] = if absolute { v[a] } else { offset[a] + v[a] };
                }
                p
            })
            .collect();
        if columns.iter().all(|&(_, c)| constant_column(values, c)) {
            offsets[ji] = local[0];
        } else {
            tracks[ji] = Some(local);
        }
    }
    (offsets, tracks)
}

/// The skeleton in metres and the metres per file unit: `unit`, or guessed
/// from the rest pose in file units of the joints in `body`.
fn skeleton(
    raw: &[RawJoint],
    offsets: &[DVec3],
    body: &[bool],
    unit: Unit,
    errors: &Errors,
) -> Result<(Arc<Skeleton>, f64), ParseError> {
    let file_skeleton = |scale: f64| -> Result<Skeleton, MotionError> {
        let joints = raw
            .iter()
            .zip(offsets)
            .map(|(j, o)| Joint {
                name: j.name.clone(),
                parent: j.parent,
                offset: *o * scale,
                channels: j.channels.clone(),
                end_site: j.end_site.map(|e| e * scale),
                limits: None,
            })
            .collect();
        Skeleton::new(joints, scale)
    };
    let scale = match unit.metres() {
        Some(m) => m,
        None => {
            let in_file_units = file_skeleton(1.0).map_err(|e| errors.whole(e.to_string()))?;
            units::guess_unit(units::rest_size_of(&in_file_units, |j| body[j]))
                .metres()
                .unwrap_or(1.0)
        }
    };
    let skeleton = Arc::new(file_skeleton(scale).map_err(|e| errors.whole(e.to_string()))?);
    Ok((skeleton, scale))
}

/// Per frame: the root translation (metres) and every joint's local rotation.
fn poses(
    raw: &[RawJoint],
    values: &Values,
    first_column: &[usize],
    offsets: &[DVec3],
    scale: f64,
) -> (Vec<DVec3>, Vec<DQuat>) {
    let value = |f: usize, c: usize| values.at(f, c);
    let frames = values.frames;
    let joint_count = raw.len();
    let mut root_translation = Vec::with_capacity(frames);
    let mut rotations = Vec::with_capacity(frames * joint_count);
    let deg = std::f64::consts::PI / 180.0;
    // Rotation axes of each joint and their columns.
    let mut axes: Vec<Vec<Axis>> = Vec::with_capacity(joint_count);
    let mut rot_cols: Vec<Vec<usize>> = Vec::with_capacity(joint_count);
    for (ji, j) in raw.iter().enumerate() {
        let mut a = Vec::new();
        let mut c = Vec::new();
        for (k, ch) in j.channels.iter().enumerate() {
            if let Channel::Rotation(axis) = ch {
                a.push(*axis);
                c.push(first_column[ji] + k);
            }
        }
        axes.push(a);
        rot_cols.push(c);
    }
    let mut angles = Vec::with_capacity(8);
    for f in 0..frames {
        let mut p = offsets[0];
        for (k, ch) in raw[0].channels.iter().enumerate() {
            if let Channel::Position(axis) = ch {
                p[axis.index()] = offsets[0][axis.index()] + value(f, first_column[0] + k);
            }
        }
        root_translation.push(p * scale);
        for ji in 0..joint_count {
            angles.clear();
            angles.extend(rot_cols[ji].iter().map(|&c| value(f, c) * deg));
            rotations.push(if angles.is_empty() {
                DQuat::IDENTITY
            } else {
                rotation::from_channels(&axes[ji], &angles)
            });
        }
    }
    (root_translation, rotations)
}
