//! From the raw hierarchy and frame values to a [`Motion`]: each joint's
//! channel columns, non-root position channels folded into the offsets (the
//! module docs of [`crate::bvh`] say when that is allowed), the length unit
//! and skeleton, then the root translation and local rotations of every frame.

use std::sync::Arc;

use glam::{DQuat, DVec3};

use super::frames::Values;
use super::hierarchy::RawJoint;
use crate::error::{MotionError, ParseError};
use crate::motion::Motion;
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
    let offsets = still_offsets(raw, values, &first_column, errors)?;
    let (skeleton, scale) = skeleton(raw, &offsets, unit, errors)?;
    let (root_translation, rotations) = poses(raw, values, &first_column, &offsets, scale);
    Motion::new(skeleton, frame_rate, root_translation, rotations)
        .map_err(|e| errors.whole(e.to_string()).into())
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

/// Each joint's offset (file units), with non-root position channels folded
/// in when they hold still: channels that repeat the offset are the offset,
/// constant ones are added to it, varying ones are an error.
fn still_offsets(
    raw: &[RawJoint],
    values: &Values,
    first_column: &[usize],
    errors: &Errors,
) -> Result<Vec<DVec3>, ParseError> {
    let value = |f: usize, c: usize| values.at(f, c);
    let mut offsets: Vec<DVec3> = raw
        .iter()
        .map(|j| j.offset.unwrap_or(DVec3::ZERO))
        .collect();
    for (ji, j) in raw.iter().enumerate().skip(1) {
        let mut absolute = true;
        let mut constant = true;
        let mut spread: f64 = 0.0;
        let mut any = false;
        for (k, c) in j.channels.iter().enumerate() {
            if let Channel::Position(axis) = c {
                any = true;
                let base = offsets[ji][axis.index()];
                let first = value(0, first_column[ji] + k);
                for f in 0..values.frames {
                    let v = value(f, first_column[ji] + k);
                    let tol = 1e-6 * (1.0 + v.abs());
                    if (v - base).abs() > tol {
                        absolute = false;
                    }
                    if (v - first).abs() > tol {
                        constant = false;
                    }
                    spread = spread.max((v - first).abs());
                }
            }
        }
        if !any || absolute {
            continue;
        }
        if !constant {
            return Err(errors.at(
                j.channels_line,
                format!(
                    "joint `{}` has animated position channels (they vary by up to {spread} \
                     file units); only the root's position can be animated",
                    j.name
                ),
            ));
        }
        for (k, c) in j.channels.iter().enumerate() {
            if let Channel::Position(axis) = c {
                offsets[ji][axis.index()] += value(0, first_column[ji] + k);
            }
        }
    }
    Ok(offsets)
}

/// The skeleton in metres and the metres per file unit: `unit`, or guessed
/// from the rest pose in file units.
fn skeleton(
    raw: &[RawJoint],
    offsets: &[DVec3],
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
            units::guess_unit(units::rest_size(&in_file_units))
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
