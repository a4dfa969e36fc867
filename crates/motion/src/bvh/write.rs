//! The stages of [`super::write_in`]: each joint's channel layout, the
//! depth-first joint order, the `HIERARCHY` text (one block per joint: name,
//! `OFFSET`, `CHANNELS`, `End Site`), the `MOTION` header and the frame lines
//! (one value per channel of the layout).

use std::io::Write;

use super::channel_name;
use crate::motion::Motion;
use crate::rotation;
use crate::skeleton::{Axis, Channel, Joint, Skeleton};

/// How one joint is written: its channels and the axes of its rotation channels.
pub(super) struct JointLayout {
    channels: Vec<Channel>,
    rot_axes: Vec<Axis>,
}

/// Channel layout of each joint for writing: the source layout where it can
/// express the motion, completed where it cannot (see [`super::write_in`]).
pub(super) fn layouts(motion: &Motion) -> Vec<JointLayout> {
    motion
        .skeleton()
        .joints()
        .iter()
        .enumerate()
        .map(|(ji, joint)| joint_layout(motion, ji, joint))
        .collect()
}

fn joint_layout(motion: &Motion, ji: usize, joint: &Joint) -> JointLayout {
    let is_root = joint.parent.is_none();
    let mut channels = joint.channels.clone();
    if channels.is_empty() {
        channels = default_channels(is_root);
    }
    if is_root {
        channels = with_moving_root_axes(motion, channels);
    }
    // Rotation channels: keep them if they express every frame.
    let rot_axes: Vec<Axis> = channels
        .iter()
        .filter_map(|c| match c {
            Channel::Rotation(a) => Some(*a),
            _ => None,
        })
        .collect();
    if expresses_every_frame(motion, ji, &rot_axes) {
        JointLayout { channels, rot_axes }
    } else {
        complete_rotations(&channels, &rot_axes)
    }
}

/// Channels of a joint without any (built in code): `Z/Y/Xrotation`, the root
/// first `X/Y/Zposition`.
fn default_channels(is_root: bool) -> Vec<Channel> {
    let mut channels = if is_root {
        vec![
            Channel::Position(Axis::X),
            Channel::Position(Axis::Y),
            Channel::Position(Axis::Z),
        ]
    } else {
        Vec::new()
    };
    channels.extend([
        Channel::Rotation(Axis::Z),
        Channel::Rotation(Axis::Y),
        Channel::Rotation(Axis::X),
    ]);
    channels
}

/// The root's channels with a position channel put first for each axis it
/// moves along without one.
fn with_moving_root_axes(motion: &Motion, channels: Vec<Channel>) -> Vec<Channel> {
    let first = motion.root_translation()[0];
    let mut missing = Vec::new();
    for axis in [Axis::X, Axis::Y, Axis::Z] {
        if channels.contains(&Channel::Position(axis)) {
            continue;
        }
        let i = axis.index();
        let moves = motion
            .root_translation()
            .iter()
            .any(|p| (p[i] - first[i]).abs() > 1e-12);
        if moves {
            missing.push(Channel::Position(axis));
        }
    }
    if missing.is_empty() {
        channels
    } else {
        missing.extend(channels);
        missing
    }
}

/// Whether rotation channels about `rot_axes` express joint `ji` at every frame.
fn expresses_every_frame(motion: &Motion, ji: usize, rot_axes: &[Axis]) -> bool {
    // One or two rotation channels: Blender's importer reads a value
    // from the wrong column for the missing ones, so always write three.
    let partial = matches!(rot_axes.len(), 1 | 2);
    !partial
        && (rotation::channels_span_all_rotations(rot_axes)
            || (0..motion.frames()).all(|f| {
                let q = motion.rotation(f, ji);
                let angles = rotation::to_channels(q, rot_axes);
                let back = rotation::from_channels(rot_axes, &angles);
                // 1e-7 rad: decomposition noise next to gimbal lock stays
                // below it, a lost rotation axis is far above it.
                rotation::angle_between(q, back) < 1e-7
            }))
}

/// Three rotation channels where the source has its first rotation channel:
/// the distinct source axes in order, then the missing ones.
fn complete_rotations(channels: &[Channel], rot_axes: &[Axis]) -> JointLayout {
    let mut full: Vec<Axis> = Vec::with_capacity(3);
    for a in rot_axes.iter().chain(&[Axis::Z, Axis::Y, Axis::X]) {
        if !full.contains(a) {
            full.push(*a);
        }
    }
    let mut rebuilt = Vec::with_capacity(channels.len() + 3);
    let mut placed = false;
    for c in channels {
        match c {
            Channel::Position(_) => rebuilt.push(*c),
            Channel::Rotation(_) if !placed => {
                rebuilt.extend(full.iter().map(|a| Channel::Rotation(*a)));
                placed = true;
            }
            Channel::Rotation(_) => {}
        }
    }
    if !placed {
        rebuilt.extend(full.iter().map(|a| Channel::Rotation(*a)));
    }
    JointLayout {
        channels: rebuilt,
        rot_axes: full,
    }
}

/// A number with up to 6 decimals, trailing zeros dropped, no `-0`.
fn push_number(out: &mut String, v: f64) {
    use std::fmt::Write as _;
    let start = out.len();
    let _ = write!(out, "{v:.6}");
    if out[start..].contains('.') {
        while out.ends_with('0') {
            out.pop();
        }
        if out.ends_with('.') {
            out.pop();
        }
    }
    if &out[start..] == "-0" {
        out.truncate(start);
        out.push('0');
    }
}

fn clean_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c == '{' || c == '}' || (c.is_whitespace() && c != ' ') {
                '_'
            } else {
                c
            }
        })
        .collect::<String>()
        .trim()
        .to_string()
}

/// Children of each joint and the depth-first order of the joints from the
/// root (the skeleton may list joints breadth-first).
pub(super) fn depth_first(skeleton: &Skeleton) -> (Vec<Vec<usize>>, Vec<usize>) {
    let mut order = Vec::with_capacity(skeleton.len());
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); skeleton.len()];
    for (i, j) in skeleton.joints().iter().enumerate() {
        if let Some(p) = j.parent {
            children[p].push(i);
        }
    }
    let mut stack = vec![0usize];
    while let Some(j) = stack.pop() {
        order.push(j);
        for &c in children[j].iter().rev() {
            stack.push(c);
        }
    }
    (children, order)
}

/// The `HIERARCHY` section and the `MOTION` header, lengths times `scale`.
pub(super) fn header(
    motion: &Motion,
    layout: &[JointLayout],
    children: &[Vec<usize>],
    scale: f64,
) -> String {
    let skeleton = motion.skeleton();
    let mut s = String::with_capacity(4096 + motion.frames() * skeleton.len() * 30);
    s.push_str("HIERARCHY\n");
    // Emit the hierarchy with an explicit stack: (joint, depth, closing?).
    let mut todo: Vec<(usize, usize, bool)> = vec![(0, 0, false)];
    while let Some((j, depth, closing)) = todo.pop() {
        let indent = "\t".repeat(depth);
        if closing {
            s.push_str(&indent);
            s.push_str("}\n");
            continue;
        }
        joint_block(&mut s, motion, j, &layout[j], &indent, scale);
        todo.push((j, depth, true));
        for &c in children[j].iter().rev() {
            todo.push((c, depth + 1, false));
        }
    }
    s.push_str("MOTION\n");
    s.push_str(&format!("Frames: {}\n", motion.frames()));
    s.push_str(&format!("Frame Time: {}\n", 1.0 / motion.fps()));
    s
}

/// A joint's block up to (not including) its children and closing brace.
fn joint_block(
    s: &mut String,
    motion: &Motion,
    j: usize,
    lay: &JointLayout,
    indent: &str,
    scale: f64,
) {
    let joint = motion.skeleton().joint(j);
    s.push_str(indent);
    s.push_str(if joint.parent.is_none() {
        "ROOT "
    } else {
        "JOINT "
    });
    s.push_str(&clean_name(&joint.name));
    s.push('\n');
    s.push_str(indent);
    s.push_str("{\n");
    // The root's offset is 0 on axes with position channels (they hold its
    // world position), its first position on the others.
    let mut offset = joint.offset;
    if joint.parent.is_none() {
        let first = motion.root_translation()[0];
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            offset[axis.index()] = if lay.channels.contains(&Channel::Position(axis)) {
                0.0
            } else {
                first[axis.index()]
            };
        }
    }
    s.push_str(indent);
    s.push_str("\tOFFSET");
    for v in (offset * scale).to_array() {
        s.push(' ');
        push_number(s, v);
    }
    s.push('\n');
    s.push_str(indent);
    s.push_str(&format!("\tCHANNELS {}", lay.channels.len()));
    for c in &lay.channels {
        s.push(' ');
        s.push_str(channel_name(*c));
    }
    s.push('\n');
    if let Some(e) = joint.end_site {
        s.push_str(&format!(
            "{indent}\tEnd Site\n{indent}\t{{\n{indent}\t\tOFFSET"
        ));
        for v in (e * scale).to_array() {
            s.push(' ');
            push_number(s, v);
        }
        s.push_str(&format!("\n{indent}\t}}\n"));
    }
}

/// One line per frame: every joint's channel values in `order`.
pub(super) fn frames(
    motion: &Motion,
    layout: &[JointLayout],
    order: &[usize],
    scale: f64,
    out: &mut impl Write,
) -> std::io::Result<()> {
    let skeleton = motion.skeleton();
    let deg = 180.0 / std::f64::consts::PI;
    let mut previous: Vec<Vec<f64>> = layout.iter().map(|l| vec![0.0; l.rot_axes.len()]).collect();
    let mut line = String::with_capacity(skeleton.len() * 40);
    for f in 0..motion.frames() {
        line.clear();
        let mut first = true;
        for &j in order {
            let lay = &layout[j];
            let joint = skeleton.joint(j);
            // Euler angles on the previous frame's branch: no 360-degree jumps.
            let angles = if f == 0 {
                rotation::to_channels(motion.rotation(f, j), &lay.rot_axes)
            } else {
                rotation::to_channels_near(motion.rotation(f, j), &lay.rot_axes, &previous[j])
            };
            let mut next_angle = angles.iter();
            for c in &lay.channels {
                if !first {
                    line.push(' ');
                }
                first = false;
                let v = match c {
                    Channel::Position(axis) => {
                        let metres = if joint.parent.is_none() {
                            motion.root_translation()[f][axis.index()]
                        } else {
                            joint.offset[axis.index()]
                        };
                        metres * scale
                    }
                    Channel::Rotation(_) => next_angle.next().copied().unwrap_or(0.0) * deg,
                };
                push_number(&mut line, v);
            }
            previous[j] = angles;
        }
        line.push('\n');
        out.write_all(line.as_bytes())?;
    }
    Ok(())
}
