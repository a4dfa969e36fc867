//! The stages of [`super::write_in`]: the joints as written (the skeleton's
//! static base, if any, then its joints, depth first), each one's channel
//! layout and `OFFSET`, the `HIERARCHY` text (one block per joint: name,
//! `OFFSET`, `CHANNELS`, `End Site`), the `MOTION` header and the frame lines
//! (one value per channel of the layout).

use std::io::Write;

use glam::{DQuat, DVec3};

use super::channel_name;
use super::translation;
use crate::motion::Motion;
use crate::rotation;
use crate::skeleton::{Axis, Channel, Transform};

/// A joint as written: one of the skeleton's static base joints or one of its joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Node {
    Base(usize),
    Joint(usize),
}

/// How one joint is written: its channels and the axes of its rotation channels.
struct JointLayout {
    channels: Vec<Channel>,
    rot_axes: Vec<Axis>,
}

/// Everything the header and the frame lines need, computed once.
pub(super) struct Plan<'a> {
    motion: &'a Motion,
    /// Depth-first order: the base chain, then the joints from the root.
    nodes: Vec<Node>,
    /// Children of each node (indices into `nodes`).
    children: Vec<Vec<usize>>,
    layouts: Vec<JointLayout>,
    /// The `OFFSET` written for each node, metres.
    offsets: Vec<DVec3>,
    /// World transform of the innermost base joint (identity without a base):
    /// the frame the root's values are written in.
    base_frame: Transform,
    /// File units per metre.
    scale: f64,
}

impl<'a> Plan<'a> {
    /// The plan for writing `motion` with lengths times `scale` (file units per metre).
    pub(super) fn new(motion: &'a Motion, scale: f64) -> Self {
        let skeleton = motion.skeleton();
        let base = skeleton.base().len();
        let mut nodes: Vec<Node> = (0..base).map(Node::Base).collect();
        let mut children: Vec<Vec<usize>> = (0..base)
            .map(|k| vec![k + 1])
            .chain(std::iter::repeat_with(Vec::new).take(skeleton.len()))
            .collect();
        // Depth-first order of the joints (the skeleton may list them breadth-first).
        let mut joint_children: Vec<Vec<usize>> = vec![Vec::new(); skeleton.len()];
        for (i, j) in skeleton.joints().iter().enumerate() {
            if let Some(p) = j.parent {
                joint_children[p].push(i);
            }
        }
        let mut node_of = vec![0usize; skeleton.len()];
        let mut stack = vec![0usize];
        while let Some(j) = stack.pop() {
            node_of[j] = nodes.len();
            nodes.push(Node::Joint(j));
            for &c in joint_children[j].iter().rev() {
                stack.push(c);
            }
        }
        for (j, kids) in joint_children.iter().enumerate() {
            children[node_of[j]] = kids.iter().map(|&c| node_of[c]).collect();
        }
        let mut plan = Plan {
            motion,
            nodes,
            children,
            layouts: Vec::new(),
            offsets: Vec::new(),
            base_frame: skeleton.base_frame(),
            scale,
        };
        for n in 0..plan.nodes.len() {
            let (layout, offset) = plan.layout(n);
            plan.layouts.push(layout);
            plan.offsets.push(offset);
        }
        plan
    }

    fn name(&self, n: usize) -> &str {
        match self.nodes[n] {
            Node::Base(k) => &self.motion.skeleton().base()[k].name,
            Node::Joint(j) => &self.motion.skeleton().joint(j).name,
        }
    }

    fn source_channels(&self, n: usize) -> &[Channel] {
        match self.nodes[n] {
            Node::Base(k) => &self.motion.skeleton().base()[k].channels,
            Node::Joint(j) => &self.motion.skeleton().joint(j).channels,
        }
    }

    fn end_site(&self, n: usize) -> Option<DVec3> {
        match self.nodes[n] {
            Node::Base(k) => self.motion.skeleton().base()[k].end_site,
            Node::Joint(j) => self.motion.skeleton().joint(j).end_site,
        }
    }

    /// The node's rest offset as the skeleton has it, metres.
    fn rest_offset(&self, n: usize) -> DVec3 {
        match self.nodes[n] {
            Node::Base(k) => self.motion.skeleton().base()[k].offset,
            Node::Joint(j) => self.motion.skeleton().joint(j).offset,
        }
    }

    /// Local translation and rotation of node `n` at frame `f`: for the
    /// written root its world values, for the skeleton's root under a base
    /// its values in the base's frame, else the joint's local values.
    fn local(&self, n: usize, f: usize) -> (DVec3, DQuat) {
        let m = self.motion;
        match self.nodes[n] {
            Node::Base(k) => {
                let b = &m.skeleton().base()[k];
                (b.translation, b.rotation)
            }
            Node::Joint(0) => {
                let (p, q) = (m.root_translation()[f], m.rotation(f, 0));
                let inv = self.base_frame.rotation.inverse();
                (
                    inv * (p - self.base_frame.translation),
                    (inv * q).normalize(),
                )
            }
            Node::Joint(j) => (m.local_translation(f, j), m.rotation(f, j)),
        }
    }

    /// Whether node `n`'s translation changes over the clip.
    fn translates(&self, n: usize) -> bool {
        match self.nodes[n] {
            Node::Base(_) => false,
            Node::Joint(0) => n > 0,
            Node::Joint(j) => self.motion.track(j).is_some(),
        }
    }

    /// Channel layout and written `OFFSET` of node `n` (see [`super::write_in`]).
    fn layout(&self, n: usize) -> (JointLayout, DVec3) {
        let written_root = n == 0;
        let mut channels = self.source_channels(n).to_vec();
        if channels.is_empty() {
            channels = default_channels(written_root);
        }
        let frames = self.motion.frames();
        let mut offset = self.rest_offset(n);
        if written_root {
            channels = self.with_moving_root_axes(channels);
            // Position channels hold the world position: OFFSET 0 on their
            // axes, the (constant) first position on the others.
            let first = self.local(n, 0).0;
            for axis in [Axis::X, Axis::Y, Axis::Z] {
                offset[axis.index()] = if channels.contains(&Channel::Position(axis)) {
                    0.0
                } else {
                    first[axis.index()]
                };
            }
        } else if self.translates(n) {
            channels = with_all_position_axes(channels);
            let values: Vec<DVec3> = (0..frames).map(|f| self.local(n, f).0).collect();
            offset = translation::written_offset(&values, offset, self.scale);
        }
        // Rotation channels: keep them if they express every frame.
        let rot_axes: Vec<Axis> = channels
            .iter()
            .filter_map(|c| match c {
                Channel::Rotation(a) => Some(*a),
                _ => None,
            })
            .collect();
        let layout = if self.expresses_every_frame(n, &rot_axes) {
            JointLayout { channels, rot_axes }
        } else {
            complete_rotations(&channels, &rot_axes)
        };
        (layout, offset)
    }

    /// The written root's channels with a position channel put first for each
    /// axis it moves along without one.
    fn with_moving_root_axes(&self, channels: Vec<Channel>) -> Vec<Channel> {
        let first = self.local(0, 0).0;
        let mut missing = Vec::new();
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            if channels.contains(&Channel::Position(axis)) {
                continue;
            }
            let i = axis.index();
            let moves =
                (0..self.motion.frames()).any(|f| (self.local(0, f).0[i] - first[i]).abs() > 1e-12);
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

    /// Whether rotation channels about `rot_axes` express node `n` at every frame.
    fn expresses_every_frame(&self, n: usize, rot_axes: &[Axis]) -> bool {
        // One or two rotation channels: Blender's importer reads a value
        // from the wrong column for the missing ones, so always write three.
        let partial = matches!(rot_axes.len(), 1 | 2);
        !partial
            && (rotation::channels_span_all_rotations(rot_axes)
                || (0..self.motion.frames()).all(|f| {
                    let q = self.local(n, f).1;
                    let angles = rotation::to_channels(q, rot_axes);
                    let back = rotation::from_channels(rot_axes, &angles);
                    // 1e-7 rad: decomposition noise next to gimbal lock stays
                    // below it, a lost rotation axis is far above it.
                    rotation::angle_between(q, back) < 1e-7
                }))
    }

    /// The `HIERARCHY` section and the `MOTION` header, lengths times `scale`.
    pub(super) fn header(&self) -> String {
        let scale = self.scale;
        let motion = self.motion;
        let mut s = String::with_capacity(4096 + motion.frames() * self.nodes.len() * 30);
        s.push_str("HIERARCHY\n");
        // Emit the hierarchy with an explicit stack: (node, depth, closing?).
        let mut todo: Vec<(usize, usize, bool)> = vec![(0, 0, false)];
        while let Some((n, depth, closing)) = todo.pop() {
            let indent = "\t".repeat(depth);
            if closing {
                s.push_str(&indent);
                s.push_str("}\n");
                continue;
            }
            self.joint_block(&mut s, n, &indent, scale);
            todo.push((n, depth, true));
            for &c in self.children[n].iter().rev() {
                todo.push((c, depth + 1, false));
            }
        }
        s.push_str("MOTION\n");
        s.push_str(&format!("Frames: {}\n", motion.frames()));
        s.push_str(&format!("Frame Time: {}\n", 1.0 / motion.fps()));
        s
    }

    /// A node's block up to (not including) its children and closing brace.
    fn joint_block(&self, s: &mut String, n: usize, indent: &str, scale: f64) {
        let lay = &self.layouts[n];
        s.push_str(indent);
        s.push_str(if n == 0 { "ROOT " } else { "JOINT " });
        s.push_str(&clean_name(self.name(n)));
        s.push('\n');
        s.push_str(indent);
        s.push_str("{\n");
        s.push_str(indent);
        s.push_str("\tOFFSET");
        for v in (self.offsets[n] * scale).to_array() {
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
        if let Some(e) = self.end_site(n) {
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

    /// One line per frame: every node's channel values in depth-first order.
    pub(super) fn frames(&self, out: &mut impl Write) -> std::io::Result<()> {
        let scale = self.scale;
        let deg = 180.0 / std::f64::consts::PI;
        let mut previous: Vec<Vec<f64>> = self
            .layouts
            .iter()
            .map(|l| vec![0.0; l.rot_axes.len()])
            .collect();
        let mut line = String::with_capacity(self.nodes.len() * 40);
        for f in 0..self.motion.frames() {
            line.clear();
            let mut first = true;
            for (n, lay) in self.layouts.iter().enumerate() {
                let (translation, q) = self.local(n, f);
                // Euler angles on the previous frame's branch: no 360-degree jumps.
                let angles = if f == 0 {
                    rotation::to_channels(q, &lay.rot_axes)
                } else {
                    rotation::to_channels_near(q, &lay.rot_axes, &previous[n])
                };
                let mut next_angle = angles.iter();
                for c in &lay.channels {
                    if !first {
                        line.push(' ');
                    }
                    first = false;
                    let v = match c {
                        Channel::Position(axis) => translation[axis.index()] * scale,
                        Channel::Rotation(_) => next_angle.next().copied().unwrap_or(0.0) * deg,
                    };
                    push_number(&mut line, v);
                }
                previous[n] = angles;
            }
            line.push('\n');
            out.write_all(line.as_bytes())?;
        }
        Ok(())
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

/// A translated joint's channels with the position channels it lacks put
/// first, so its translation is written on every axis.
fn with_all_position_axes(channels: Vec<Channel>) -> Vec<Channel> {
    let mut out: Vec<Channel> = [Axis::X, Axis::Y, Axis::Z]
        .into_iter()
        .map(Channel::Position)
        .filter(|c| !channels.contains(c))
        .collect();
    out.extend(channels);
    out
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
