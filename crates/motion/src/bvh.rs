//! BVH (Biovision Hierarchy) reading and writing.
//!
//! BVH is the most common interchange format for mocap clips, written by many
//! exporters in slightly different dialects, so the reader is liberal in what it
//! accepts and strict in what it returns:
//!
//! * any joint count and names (a name is the rest of its `JOINT` line), any
//!   order and subset of rotation channels, position channels anywhere, `End
//!   Site` blocks, CRLF / LF / CR line ends in any mix, braces on their own line
//!   or not, a T-pose first frame kept as an ordinary frame;
//! * lengths are converted to metres with a [`Unit`] given by the caller or
//!   guessed from the body size ([`crate::units::guess_unit`]), angles (degrees
//!   in BVH) to radians;
//! * the root's world position is its `OFFSET` plus its position channels, as
//!   most readers do (Blender takes the channels alone; the root `OFFSET` is 0
//!   in nearly every file, and the writer makes it 0 on axes with channels so
//!   both readings agree); a root without position channels stays at its
//!   `OFFSET`;
//! * position channels on other joints are supported when they hold still: if
//!   they repeat the joint's `OFFSET` at every frame (exporters that write six
//!   channels everywhere, read by Blender as absolute translations) they are
//!   taken as that offset, if they are constant otherwise they are added to it.
//!   Animated (varying) non-root translations cannot be represented by
//!   [`Motion`] and are an error naming the joint;
//! * any problem is a [`ParseError`] naming the file, the line and what is
//!   wrong; no input panics and nothing partial is returned.
//!
//! The writer produces the standard layout Blender and other tools read (tabs,
//! `End Site` blocks, `MOTION`, `Frames:`, `Frame Time:`), see [`write()`].

use std::io::Write;
use std::path::Path;
use std::sync::Arc;

use glam::{DQuat, DVec3};

use crate::error::{MotionError, ParseError};
use crate::motion::Motion;
use crate::rotation;
use crate::skeleton::{Axis, Channel, Joint, Skeleton};
use crate::text::{self, Errors, Line, show};
use crate::units::{self, Unit};

/// Tokens of the hierarchy with their line numbers, and where the frame data
/// starts (the index of the first line after `Frame Time`).
struct Cursor<'a> {
    lines: &'a [Line<'a>],
    line: usize,
    tokens: Vec<&'a [u8]>,
    token: usize,
    errors: &'a Errors,
}

impl<'a> Cursor<'a> {
    fn new(lines: &'a [Line<'a>], errors: &'a Errors) -> Self {
        let mut c = Cursor {
            lines,
            line: 0,
            tokens: Vec::new(),
            token: 0,
            errors,
        };
        c.load();
        c
    }

    /// Make `tokens` hold the tokens of the first non-blank line at or after `line`.
    fn load(&mut self) {
        while self.line < self.lines.len() {
            self.tokens = self.lines[self.line].tokens().collect();
            self.token = 0;
            if !self.tokens.is_empty() {
                return;
            }
            self.line += 1;
        }
        self.tokens.clear();
        self.token = 0;
    }

    /// Line number of the next token (or of the last line at the end).
    fn line_number(&self) -> usize {
        match self.lines.get(self.line) {
            Some(l) => l.number,
            None => self.lines.last().map_or(1, |l| l.number),
        }
    }

    fn next(&mut self) -> Option<(&'a [u8], usize)> {
        if self.token >= self.tokens.len() {
            return None;
        }
        let t = self.tokens[self.token];
        let n = self.line_number();
        self.token += 1;
        if self.token >= self.tokens.len() {
            self.line += 1;
            self.load();
        }
        Some((t, n))
    }

    fn peek(&self) -> Option<&'a [u8]> {
        self.tokens.get(self.token).copied()
    }

    /// The next token, or an error saying the file ended while `expected`.
    fn need(&mut self, expected: &str) -> Result<(&'a [u8], usize), ParseError> {
        let at = self.line_number();
        self.next().ok_or_else(|| {
            self.errors
                .at(at, format!("file ends where {expected} was expected"))
        })
    }

    /// The next token, which must be `word` (ASCII case-insensitive).
    fn expect(&mut self, word: &str) -> Result<usize, ParseError> {
        let (t, n) = self.need(&format!("`{word}`"))?;
        if t.eq_ignore_ascii_case(word.as_bytes()) {
            Ok(n)
        } else {
            Err(self
                .errors
                .at(n, format!("expected `{word}`, found `{}`", show(t))))
        }
    }

    fn number(&mut self, what: &str) -> Result<f64, ParseError> {
        let (t, n) = self.need(what)?;
        text::number(t, what).map_err(|m| self.errors.at(n, m))
    }

    /// All remaining tokens of the current line (for names with spaces).
    fn rest_of_line(&mut self) -> Vec<&'a [u8]> {
        if self.token >= self.tokens.len() {
            return Vec::new();
        }
        let rest = self.tokens[self.token..].to_vec();
        self.line += 1;
        self.load();
        rest
    }
}

fn channel_from(token: &[u8]) -> Option<Channel> {
    let t = token.to_ascii_lowercase();
    Some(match t.as_slice() {
        b"xposition" => Channel::Position(Axis::X),
        b"yposition" => Channel::Position(Axis::Y),
        b"zposition" => Channel::Position(Axis::Z),
        b"xrotation" => Channel::Rotation(Axis::X),
        b"yrotation" => Channel::Rotation(Axis::Y),
        b"zrotation" => Channel::Rotation(Axis::Z),
        _ => return None,
    })
}

fn channel_name(c: Channel) -> &'static str {
    match c {
        Channel::Position(Axis::X) => "Xposition",
        Channel::Position(Axis::Y) => "Yposition",
        Channel::Position(Axis::Z) => "Zposition",
        Channel::Rotation(Axis::X) => "Xrotation",
        Channel::Rotation(Axis::Y) => "Yrotation",
        Channel::Rotation(Axis::Z) => "Zrotation",
    }
}

/// A joint while the hierarchy is read, in file units.
struct RawJoint {
    name: String,
    parent: Option<usize>,
    line: usize,
    offset: Option<DVec3>,
    channels: Vec<Channel>,
    channels_line: usize,
    end_site: Option<DVec3>,
}

/// Read a BVH file from memory. `label` names the file in errors; `unit` is the
/// file's length unit ([`Unit::Auto`] to guess it from the body size).
pub fn parse(bytes: &[u8], label: impl AsRef<Path>, unit: Unit) -> Result<Motion, MotionError> {
    let errors = Errors::new(label.as_ref());
    let lines = text::lines(bytes);
    let mut cur = Cursor::new(&lines, &errors);

    // --- HIERARCHY ---
    cur.expect("HIERARCHY")?;
    let mut joints: Vec<RawJoint> = Vec::new();
    // Joint name -> line of its declaration.
    let mut names: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut stack: Vec<usize> = Vec::new();
    let mut started = false;
    loop {
        let at = cur.line_number();
        let Some((tok, line)) = cur.next() else {
            return Err(if stack.is_empty() {
                errors.at(at, "file ends where `ROOT` was expected")
            } else {
                errors.at(
                    at,
                    format!(
                        "file ends inside joint `{}`: missing `}}`",
                        joints[stack[stack.len() - 1]].name
                    ),
                )
            }
            .into());
        };
        let word = tok.to_ascii_uppercase();
        match word.as_slice() {
            b"ROOT" | b"JOINT" => {
                let is_root = word == b"ROOT";
                if is_root && started {
                    return Err(errors
                        .at(
                            line,
                            "a second `ROOT`: only one skeleton per file is supported",
                        )
                        .into());
                }
                if is_root != stack.is_empty() {
                    return Err(errors
                        .at(
                            line,
                            if is_root {
                                "`ROOT` inside a joint (missing `}`?)"
                            } else {
                                "`JOINT` outside the root's braces"
                            },
                        )
                        .into());
                }
                started = true;
                let mut name_tokens = cur.rest_of_line();
                let brace_on_line = name_tokens.last() == Some(&&b"{"[..]);
                if brace_on_line {
                    name_tokens.pop();
                }
                if name_tokens.is_empty() {
                    return Err(errors.at(line, "joint without a name").into());
                }
                let name = name_tokens
                    .iter()
                    .map(|t| String::from_utf8_lossy(t).into_owned())
                    .collect::<Vec<_>>()
                    .join(" ");
                if let Some(prev) = names.insert(name.clone(), line) {
                    return Err(errors
                        .at(
                            line,
                            format!("joint name `{name}` was already used on line {prev}"),
                        )
                        .into());
                }
                if !brace_on_line {
                    cur.expect("{")?;
                }
                joints.push(RawJoint {
                    name,
                    parent: stack.last().copied(),
                    line,
                    offset: None,
                    channels: Vec::new(),
                    channels_line: line,
                    end_site: None,
                });
                stack.push(joints.len() - 1);
            }
            b"END" => {
                let Some(&owner) = stack.last() else {
                    return Err(errors.at(line, "`End Site` outside any joint").into());
                };
                let (site, site_line) = cur.need("`Site`")?;
                if !site.eq_ignore_ascii_case(b"Site") {
                    return Err(errors
                        .at(
                            site_line,
                            format!("expected `Site` after `End`, found `{}`", show(site)),
                        )
                        .into());
                }
                // Some exporters name end sites (`End Site LeftToe_End`): skip it.
                let mut brace = false;
                if cur.line_number() == site_line {
                    brace = cur.rest_of_line().last() == Some(&&b"{"[..]);
                }
                if !brace {
                    cur.expect("{")?;
                }
                cur.expect("OFFSET")?;
                let x = cur.number("End Site OFFSET x")?;
                let y = cur.number("End Site OFFSET y")?;
                let z = cur.number("End Site OFFSET z")?;
                cur.expect("}")?;
                if joints[owner].end_site.is_some() {
                    return Err(errors
                        .at(
                            line,
                            format!("joint `{}` has a second `End Site`", joints[owner].name),
                        )
                        .into());
                }
                joints[owner].end_site = Some(DVec3::new(x, y, z));
            }
            b"OFFSET" => {
                let Some(&j) = stack.last() else {
                    return Err(errors.at(line, "`OFFSET` outside any joint").into());
                };
                if joints[j].offset.is_some() {
                    return Err(errors
                        .at(
                            line,
                            format!("joint `{}` has a second `OFFSET`", joints[j].name),
                        )
                        .into());
                }
                let x = cur.number("OFFSET x")?;
                let y = cur.number("OFFSET y")?;
                let z = cur.number("OFFSET z")?;
                joints[j].offset = Some(DVec3::new(x, y, z));
            }
            b"CHANNELS" => {
                let Some(&j) = stack.last() else {
                    return Err(errors.at(line, "`CHANNELS` outside any joint").into());
                };
                if !joints[j].channels.is_empty() {
                    return Err(errors
                        .at(
                            line,
                            format!("joint `{}` has a second `CHANNELS`", joints[j].name),
                        )
                        .into());
                }
                let (t, n) = cur.need("the channel count")?;
                let count = text::count(t, "channel count").map_err(|m| errors.at(n, m))?;
                if count > 64 {
                    return Err(errors
                        .at(n, format!("{count} channels on one joint is not plausible"))
                        .into());
                }
                let mut channels = Vec::with_capacity(count);
                for i in 0..count {
                    let (t, n) = cur.need(&format!("channel {} of {count}", i + 1))?;
                    let c = channel_from(t).ok_or_else(|| {
                        errors.at(
                            n,
                            format!(
                                "`{}` is not a channel (expected Xposition .. Zrotation; \
                                 the CHANNELS count may be wrong)",
                                show(t)
                            ),
                        )
                    })?;
                    if channels.contains(&c) && matches!(c, Channel::Position(_)) {
                        return Err(errors
                            .at(n, format!("channel `{}` listed twice", channel_name(c)))
                            .into());
                    }
                    channels.push(c);
                }
                joints[j].channels = channels;
                joints[j].channels_line = line;
            }
            b"}" => {
                let Some(j) = stack.pop() else {
                    return Err(errors.at(line, "`}` without a matching `{`").into());
                };
                if joints[j].offset.is_none() {
                    return Err(errors
                        .at(
                            line,
                            format!(
                                "joint `{}` (line {}) has no `OFFSET`",
                                joints[j].name, joints[j].line
                            ),
                        )
                        .into());
                }
                if stack.is_empty() {
                    break;
                }
            }
            b"MOTION" => {
                let message = match stack.last() {
                    Some(&j) => format!(
                        "`MOTION` while joint `{}` (line {}) is still open: missing `}}`",
                        joints[j].name, joints[j].line
                    ),
                    None => "`MOTION` before any `ROOT`".to_string(),
                };
                return Err(errors.at(line, message).into());
            }
            _ => {
                return Err(errors
                    .at(
                        line,
                        format!(
                            "unexpected `{}` (expected JOINT, End Site, OFFSET, CHANNELS or `}}`)",
                            show(tok)
                        ),
                    )
                    .into());
            }
        }
    }

    // --- MOTION header ---
    let motion_line = {
        let at = cur.line_number();
        let (t, n) = cur.need("`MOTION`")?;
        if t.eq_ignore_ascii_case(b"ROOT") {
            return Err(errors
                .at(
                    n,
                    "a second `ROOT`: only one skeleton per file is supported",
                )
                .into());
        }
        if !t.eq_ignore_ascii_case(b"MOTION") {
            return Err(errors
                .at(
                    n.max(at),
                    format!(
                        "expected `MOTION` after the hierarchy, found `{}` (an extra `}}`?)",
                        show(t)
                    ),
                )
                .into());
        }
        n
    };
    let frames_declared = {
        let (t, n) = cur.need("`Frames:`")?;
        let count_token = if t.eq_ignore_ascii_case(b"Frames:") {
            cur.need("the frame count")?
        } else if t.len() > 7 && t[..7].eq_ignore_ascii_case(b"Frames:") {
            (&t[7..], n)
        } else {
            return Err(errors
                .at(
                    n,
                    format!(
                        "expected `Frames:` after `MOTION` (line {motion_line}), found `{}`",
                        show(t)
                    ),
                )
                .into());
        };
        text::count(count_token.0, "frame count").map_err(|m| errors.at(count_token.1, m))?
    };
    let frame_time = {
        cur.expect("Frame")?;
        let (t, n) = cur.need("`Time:`")?;
        let value = if t.eq_ignore_ascii_case(b"Time:") {
            let (v, vn) = cur.need("the frame time")?;
            (v, vn)
        } else if t.len() > 5 && t[..5].eq_ignore_ascii_case(b"Time:") {
            (&t[5..], n)
        } else {
            return Err(errors
                .at(
                    n,
                    format!("expected `Frame Time:`, found `Frame {}`", show(t)),
                )
                .into());
        };
        let dt = text::number(value.0, "frame time").map_err(|m| errors.at(value.1, m))?;
        if dt <= 0.0 {
            return Err(errors
                .at(value.1, format!("frame time {dt} is not positive"))
                .into());
        }
        (dt, value.1)
    };
    if cur.peek().is_some() && cur.line_number() == frame_time.1 {
        // Frame data on the `Frame Time` line itself: not a layout any exporter uses.
        let (t, n) = cur.need("")?;
        return Err(errors
            .at(n, format!("unexpected `{}` after the frame time", show(t)))
            .into());
    }
    if frames_declared == 0 {
        return Err(errors
            .at(frame_time.1, "`Frames: 0`: the clip has no frames")
            .into());
    }

    // --- frame data: one frame per non-blank line ---
    let channel_count: usize = joints.iter().map(|j| j.channels.len()).sum();
    if channel_count == 0 {
        return Err(errors
            .at(
                motion_line,
                "no joint has CHANNELS: there is nothing to animate",
            )
            .into());
    }
    // Line numbers are 1-based indices into `lines`: data starts after the frame time.
    let data_lines: Vec<&Line> = lines[frame_time.1.min(lines.len())..]
        .iter()
        .filter(|l| !l.is_blank())
        .collect();
    if data_lines.len() != frames_declared {
        return Err(if data_lines.len() > frames_declared {
            errors.at(
                data_lines[frames_declared].number,
                format!(
                    "more frames than `Frames: {frames_declared}` says (this is frame {})",
                    frames_declared + 1
                ),
            )
        } else {
            errors.at(
                lines.last().map_or(frame_time.1, |l| l.number),
                format!(
                    "file ends after {} frames, `Frames:` says {frames_declared}",
                    data_lines.len()
                ),
            )
        }
        .into());
    }
    let frames = frames_declared;
    let mut values = vec![0.0f64; frames * channel_count];
    {
        for (f, line) in data_lines.iter().enumerate() {
            let row = &mut values[f * channel_count..(f + 1) * channel_count];
            let mut n = 0;
            for tok in line.tokens() {
                if n >= channel_count {
                    let found = line.tokens().count();
                    return Err(errors
                        .at(
                            line.number,
                            format!(
                                "frame {} has {found} values, the hierarchy has {channel_count} channels",
                                f + 1
                            ),
                        )
                        .into());
                }
                row[n] = text::number(tok, &format!("frame {}, value {}", f + 1, n + 1))
                    .map_err(|m| errors.at(line.number, m))?;
                n += 1;
            }
            if n != channel_count {
                return Err(errors
                    .at(
                        line.number,
                        format!(
                            "frame {} has {n} values, the hierarchy has {channel_count} channels",
                            f + 1
                        ),
                    )
                    .into());
            }
        }
    }

    build(
        joints,
        values,
        frames,
        channel_count,
        frame_time.0,
        unit,
        &errors,
    )
}

/// Turn the raw hierarchy and frame values into a [`Motion`].
fn build(
    raw: Vec<RawJoint>,
    values: Vec<f64>,
    frames: usize,
    channel_count: usize,
    frame_time: f64,
    unit: Unit,
    errors: &Errors,
) -> Result<Motion, MotionError> {
    // First column of each joint's channels.
    let mut first_column = Vec::with_capacity(raw.len());
    let mut col = 0;
    for j in &raw {
        first_column.push(col);
        col += j.channels.len();
    }
    let value = |f: usize, c: usize| values[f * channel_count + c];

    // Non-root position channels: fold into the offset when they hold still.
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
                for f in 0..frames {
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
            return Err(errors
                .at(
                    j.channels_line,
                    format!(
                        "joint `{}` has animated position channels (they vary by up to {spread} \
                         file units); only the root's position can be animated",
                        j.name
                    ),
                )
                .into());
        }
        for (k, c) in j.channels.iter().enumerate() {
            if let Channel::Position(axis) = c {
                offsets[ji][axis.index()] += value(0, first_column[ji] + k);
            }
        }
    }

    // Unit: given, or guessed from the rest pose in file units.
    let file_skeleton = |scale: f64| -> Result<Skeleton, MotionError> {
        let joints = raw
            .iter()
            .zip(&offsets)
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

    // Per-frame root translation and local rotations.
    let joint_count = raw.len();
    let mut root_translation = Vec::with_capacity(frames);
    let mut rotations = Vec::with_capacity(frames * joint_count);
    let deg = std::f64::consts::PI / 180.0;
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
    Motion::new(
        skeleton,
        frame_rate(frame_time),
        root_translation,
        rotations,
    )
    .map_err(|e| errors.whole(e.to_string()).into())
}

/// Frame rate of a `Frame Time`. Exporters round the frame time to a few
/// decimals (`0.008333` for 120 Hz, which is 120.0048 Hz taken literally), so a
/// rate within 1e-4 (relative) of a whole number is taken to be that number.
pub fn frame_rate(frame_time: f64) -> f64 {
    let fps = 1.0 / frame_time;
    let whole = fps.round();
    if whole >= 1.0 && ((fps - whole) / whole).abs() < 1e-4 {
        whole
    } else {
        fps
    }
}

/// Read a BVH file from disk, see [`parse`].
pub fn read(path: impl AsRef<Path>, unit: Unit) -> Result<Motion, MotionError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, path, unit)
}

// ---------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------

/// The unit a motion is written in by default: the skeleton's source unit when
/// it is one of the [`Unit`]s (so a BVH file comes back in its own unit, and
/// CMU/HDM05 ASF skeletons, `length 0.45`, in [`Unit::CmuAsf`] like the CMU BVH
/// conversions), otherwise centimetres. Either way [`Unit::Auto`] reads the
/// file back in the same unit for human-sized bodies.
pub fn default_unit(skeleton: &Skeleton) -> Unit {
    Unit::from_metres(skeleton.source_unit_m()).unwrap_or(Unit::Centimetres)
}

/// How one joint is written: its channels and where the values come from.
struct JointLayout {
    channels: Vec<Channel>,
    rot_axes: Vec<Axis>,
}

/// Channel layout of each joint for writing: the source layout where it can
/// express the motion, completed where it cannot (see [`write_in`]).
fn layouts(motion: &Motion) -> Vec<JointLayout> {
    let skeleton = motion.skeleton();
    let frames = motion.frames();
    skeleton
        .joints()
        .iter()
        .enumerate()
        .map(|(ji, joint)| {
            let is_root = joint.parent.is_none();
            let mut channels = joint.channels.clone();
            if channels.is_empty() {
                channels = if is_root {
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
            }
            // Root: add position channels for axes that move.
            if is_root {
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
                if !missing.is_empty() {
                    missing.extend(channels);
                    channels = missing;
                }
            }
            // Rotation channels: keep them if they express every frame.
            let rot_axes: Vec<Axis> = channels
                .iter()
                .filter_map(|c| match c {
                    Channel::Rotation(a) => Some(*a),
                    _ => None,
                })
                .collect();
            // One or two rotation channels: Blender's importer reads a value
            // from the wrong column for the missing ones, so always write three.
            let partial = matches!(rot_axes.len(), 1 | 2);
            let representable = !partial
                && (rotation::channels_span_all_rotations(&rot_axes)
                    || (0..frames).all(|f| {
                        let q = motion.rotation(f, ji);
                        let angles = rotation::to_channels(q, &rot_axes);
                        let back = rotation::from_channels(&rot_axes, &angles);
                        // 1e-7 rad: decomposition noise next to gimbal lock stays
                        // below it, a lost rotation axis is far above it.
                        rotation::angle_between(q, back) < 1e-7
                    }));
            let rot_axes = if representable {
                rot_axes
            } else {
                // Distinct source axes in order, then the missing ones.
                let mut full: Vec<Axis> = Vec::with_capacity(3);
                for a in rot_axes.iter().chain(&[Axis::Z, Axis::Y, Axis::X]) {
                    if !full.contains(a) {
                        full.push(*a);
                    }
                }
                let mut rebuilt = Vec::with_capacity(channels.len() + 3);
                let mut placed = false;
                for c in &channels {
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
                channels = rebuilt;
                full
            };
            JointLayout { channels, rot_axes }
        })
        .collect()
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

/// Write `motion` as BVH in [`default_unit`], see [`write_in`].
pub fn write(motion: &Motion, out: &mut impl Write) -> std::io::Result<()> {
    write_in(motion, default_unit(motion.skeleton()), out)
}

/// Write `motion` as BVH with lengths in `unit` ([`Unit::Auto`] means
/// [`default_unit`]).
///
/// * Joints in depth-first order, tabs, `End Site` blocks, `MOTION`,
///   `Frames:`, `Frame Time:` (shortest exact decimal of `1 / fps`).
/// * Each joint keeps its source channels and their order when they can
///   express its rotations at every frame. Joints without channels (built in
///   code) get `Zrotation Yrotation Xrotation`, the root also `X/Y/Zposition`;
///   a joint with one or two rotation channels gets the missing axes added
///   after its own (Blender reads partial rotation channels wrongly, and an
///   augmented clip may rotate about them), and a root that moves along an
///   axis without a position channel gets that channel.
/// * The root's position channels hold its world position and its `OFFSET`
///   is 0 on those axes, so readers that add the offset and readers that
///   ignore it (Blender) agree. Position channels of other joints repeat the
///   joint's `OFFSET` (what Blender expects; [`parse`] reads that back as the
///   offset).
/// * Angles in degrees, lengths in `unit`, 6 decimals: round trips keep world
///   joint positions to about 1e-6 m. Euler angles follow the previous frame's
///   branch, so curves have no 360-degree jumps.
pub fn write_in(motion: &Motion, unit: Unit, out: &mut impl Write) -> std::io::Result<()> {
    let skeleton = motion.skeleton();
    let unit = match unit {
        Unit::Auto => default_unit(skeleton),
        u => u,
    };
    let scale = 1.0 / unit.metres().unwrap_or(1.0);
    let layout = layouts(motion);

    // Depth-first order (the skeleton may list joints breadth-first).
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
        let joint = skeleton.joint(j);
        let lay = &layout[j];
        s.push_str(&indent);
        s.push_str(if joint.parent.is_none() {
            "ROOT "
        } else {
            "JOINT "
        });
        s.push_str(&clean_name(&joint.name));
        s.push('\n');
        s.push_str(&indent);
        s.push_str("{\n");
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
        s.push_str(&indent);
        s.push_str("\tOFFSET");
        for v in (offset * scale).to_array() {
            s.push(' ');
            push_number(&mut s, v);
        }
        s.push('\n');
        s.push_str(&indent);
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
                push_number(&mut s, v);
            }
            s.push_str(&format!("\n{indent}\t}}\n"));
        }
        todo.push((j, depth, true));
        for &c in children[j].iter().rev() {
            todo.push((c, depth + 1, false));
        }
    }
    s.push_str("MOTION\n");
    s.push_str(&format!("Frames: {}\n", motion.frames()));
    s.push_str(&format!("Frame Time: {}\n", 1.0 / motion.fps()));
    out.write_all(s.as_bytes())?;

    let deg = 180.0 / std::f64::consts::PI;
    let mut previous: Vec<Vec<f64>> = layout.iter().map(|l| vec![0.0; l.rot_axes.len()]).collect();
    let mut line = String::with_capacity(skeleton.len() * 40);
    for f in 0..motion.frames() {
        line.clear();
        let mut first = true;
        for &j in &order {
            let lay = &layout[j];
            let joint = skeleton.joint(j);
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

/// The BVH text of `motion` in [`default_unit`].
pub fn to_bytes(motion: &Motion) -> Vec<u8> {
    let mut out = Vec::new();
    // Writing into a Vec cannot fail.
    let _ = write(motion, &mut out);
    out
}

/// Write `motion` to a BVH file in [`default_unit`].
pub fn write_file(motion: &Motion, path: impl AsRef<Path>) -> Result<(), MotionError> {
    let path = path.as_ref();
    let io = |source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::create(path).map_err(io)?;
    let mut w = std::io::BufWriter::new(file);
    write(motion, &mut w).map_err(io)?;
    w.flush().map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "HIERARCHY\r\nROOT Hips\r\n{\r\n\tOFFSET 0 0 0\r\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n\
        \tJOINT Leg\n\t{\n\t\tOFFSET 0 -40 0\n\t\tCHANNELS 1 Xrotation\n\t\tEnd Site\n\t\t{\n\t\t\tOFFSET 0 -40 0\n\t\t}\n\t}\n\
        \tJOINT Spine\n\t{\n\t\tOFFSET 0 10 0\n\t\tCHANNELS 3 Xrotation Zrotation Yrotation\n\t\tEnd Site\n\t\t{\n\t\t\tOFFSET 0 80 0\n\t\t}\n\t}\n}\n\
        MOTION\nFrames: 2\nFrame Time: .0083333\n\
        0 90 0 0 0 0 0 0 0 0\r\n1 91 2 10 20 30 90 5 6 7\n";

    #[test]
    fn reads_a_small_file() {
        let m = parse(SMALL.as_bytes(), "small.bvh", Unit::Centimetres).unwrap();
        assert_eq!(m.frames(), 2);
        assert_eq!(m.joints(), 3);
        assert_eq!(m.fps(), 120.0, "0.0083333 s is 120 Hz rounded");
        assert_eq!(frame_rate(0.008333), 120.0);
        assert_eq!(frame_rate(1.0 / 29.97), 1.0 / (1.0 / 29.97));
        assert_eq!(frame_rate(0.04), 25.0);
        let p = m.world_positions(0);
        assert!((p[1] - DVec3::new(0.0, 0.5, 0.0)).length() < 1e-12);
        // Leg rotated 90 degrees about x: its end site points along -z... its
        // child offset is not a joint, so check the root instead.
        assert!((m.root_translation()[1] - DVec3::new(0.01, 0.91, 0.02)).length() < 1e-12);
        let leg = m.rotation(1, 1);
        assert!(rotation::angle_between(leg, DQuat::from_rotation_x(90f64.to_radians())) < 1e-12);
        // Auto: 1.7 units tall body at 170 "units" -> centimetres.
        let auto = parse(SMALL.as_bytes(), "small.bvh", Unit::Auto).unwrap();
        assert_eq!(auto.skeleton().source_unit_m(), 0.01);
        // Named end sites and braces on the joint line are accepted.
        let variant = SMALL
            .replace("\t\tEnd Site\n\t\t{", "\t\tEnd Site LegEnd {")
            .replace("JOINT Spine\n\t{", "JOINT Spine {");
        assert!(variant.contains("LegEnd {") && variant.contains("Spine {"));
        let v = parse(variant.as_bytes(), "variant.bvh", Unit::Centimetres).unwrap();
        assert_eq!(v.all_world_positions(), m.all_world_positions());
    }

    #[test]
    fn writes_and_reads_back() {
        let m = parse(SMALL.as_bytes(), "small.bvh", Unit::Centimetres).unwrap();
        let text = to_bytes(&m);
        let back = parse(&text, "back.bvh", Unit::Auto).unwrap();
        assert_eq!(
            back.skeleton().joint(2).channels,
            m.skeleton().joint(2).channels
        );
        // A single rotation channel is completed to three, its own first.
        assert_eq!(
            back.skeleton().joint(1).channels,
            vec![
                Channel::Rotation(Axis::X),
                Channel::Rotation(Axis::Z),
                Channel::Rotation(Axis::Y)
            ]
        );
        for f in 0..2 {
            for (a, b) in m.world_positions(f).iter().zip(back.world_positions(f)) {
                assert!((*a - b).length() < 1e-8);
            }
        }
    }

    fn err(text: &str) -> ParseError {
        match parse(text.as_bytes(), "bad.bvh", Unit::Metres) {
            Err(MotionError::Parse(e)) => e,
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn errors_name_the_line() {
        let bad_number = SMALL.replace(
            "OFFSET 0 -40 0\n\t\tCHANNELS",
            "OFFSET 0 -4x0 0\n\t\tCHANNELS",
        );
        let e = err(&bad_number);
        assert_eq!(e.line, Some(8), "{e}");
        assert!(e.message.contains("-4x0"), "{e}");
        let e = err(&SMALL.replace("Frames: 2", "Frames: 3"));
        assert!(e.message.contains("after 2 frames"), "{e}");
        let e = err(&SMALL.replace("Frames: 2", "Frames: 1"));
        assert_eq!(e.line, Some(29), "{e}");
        let e = err(&SMALL.replace("1 91 2 10", "1 91 10"));
        assert_eq!(e.line, Some(29), "{e}");
        assert!(e.message.contains("9 values"), "{e}");
        let e = err(&SMALL.replace(".0083333", "0"));
        assert!(e.message.contains("not positive"), "{e}");
        let e = err(&SMALL.replace("\t}\n\tJOINT Spine", "\tJOINT Spine"));
        assert!(e.message.contains("missing `}`"), "{e}");
        let e = err(&SMALL.replace("JOINT Spine", "JOINT Leg"));
        assert!(e.message.contains("already used on line 6"), "{e}");
        assert!(err("").message.contains("HIERARCHY"));
        let e = err(&SMALL.replace("Frames: 2", "Frames: 99999999999999"));
        assert!(e.message.contains("after 2 frames"), "{e}");
        let e = err(
            "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n}\nMOTION\nFrames: 99999999999\nFrame Time: 0.1\n",
        );
        assert!(e.message.contains("nothing to animate"), "{e}");
        assert!(
            err(&SMALL.replace("CHANNELS 1 Xrotation", "CHANNELS 1 Qrotation"))
                .message
                .contains("Qrotation")
        );
    }

    #[test]
    fn constant_position_channels_on_joints() {
        // Six channels everywhere, positions repeating the offset (absolute).
        let abs = SMALL
            .replace(
                "CHANNELS 1 Xrotation",
                "CHANNELS 4 Xposition Yposition Zposition Xrotation",
            )
            .replace("0 90 0 0 0 0 0 0 0 0", "0 90 0 0 0 0 0 -40 0 0 0 0 0")
            .replace(
                "1 91 2 10 20 30 90 5 6 7",
                "1 91 2 10 20 30 0 -40 0 90 5 6 7",
            );
        let m = parse(abs.as_bytes(), "abs.bvh", Unit::Centimetres).unwrap();
        assert!((m.skeleton().joint(1).offset - DVec3::new(0.0, -0.4, 0.0)).length() < 1e-12);
        // Varying: an error naming the joint's CHANNELS line.
        let moving = abs.replace("30 0 -40 0 90", "30 0 -41 0 90");
        let e = err(&moving);
        assert_eq!(e.line, Some(9), "{e}");
        assert!(e.message.contains("Leg"));
    }
}
