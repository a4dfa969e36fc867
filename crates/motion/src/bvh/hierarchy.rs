//! Reading the `HIERARCHY` section: one [`RawJoint`] per `ROOT`/`JOINT`, in
//! file order, with its `OFFSET`, `CHANNELS` and `End Site` as written (file
//! units). [`read`] dispatches each keyword to its own stage; a new per-joint
//! keyword is one more arm and one more method.

use std::collections::HashMap;

use glam::DVec3;

use super::channel_name;
use super::cursor::Cursor;
use crate::error::ParseError;
use crate::skeleton::{Axis, Channel};
use crate::text::{self, Errors, show};

/// A joint while the hierarchy is read, in file units.
pub(super) struct RawJoint {
    pub name: String,
    pub parent: Option<usize>,
    pub line: usize,
    pub offset: Option<DVec3>,
    pub channels: Vec<Channel>,
    pub channels_line: usize,
    pub end_site: Option<DVec3>,
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

/// The joints of the hierarchy, from `HIERARCHY` to the root's closing `}`.
pub(super) fn read(cur: &mut Cursor, errors: &Errors) -> Result<Vec<RawJoint>, ParseError> {
    cur.expect("HIERARCHY")?;
    let mut r = Reader {
        cur,
        errors,
        joints: Vec::new(),
        names: HashMap::new(),
        stack: Vec::new(),
        started: false,
    };
    loop {
        let at = r.cur.line_number();
        let Some((tok, line)) = r.cur.next() else {
            return Err(r.file_ends(at));
        };
        let word = tok.to_ascii_uppercase();
        match word.as_slice() {
            b"ROOT" | b"JOINT" => r.joint(word == b"ROOT", line)?,
            b"END" => r.end_site(line)?,
            b"OFFSET" => r.offset(line)?,
            b"CHANNELS" => r.channels(line)?,
            b"}" => {
                if r.close(line)? {
                    return Ok(r.joints);
                }
            }
            b"MOTION" => return Err(r.early_motion(line)),
            _ => {
                return Err(errors.at(
                    line,
                    format!(
                        "unexpected `{}` (expected JOINT, End Site, OFFSET, CHANNELS or `}}`)",
                        show(tok)
                    ),
                ));
            }
        }
    }
}

/// The hierarchy read so far.
struct Reader<'c, 'a> {
    cur: &'c mut Cursor<'a>,
    errors: &'c Errors,
    joints: Vec<RawJoint>,
    /// Joint name -> line of its declaration.
    names: HashMap<String, usize>,
    /// Open joints, innermost last.
    stack: Vec<usize>,
    /// A `ROOT` was seen.
    started: bool,
}

impl Reader<'_, '_> {
    /// The joint whose braces are open, or an error saying `what` is outside any.
    fn open_joint(&self, line: usize, what: &str) -> Result<usize, ParseError> {
        self.stack
            .last()
            .copied()
            .ok_or_else(|| self.errors.at(line, format!("{what} outside any joint")))
    }

    /// `ROOT name {` or `JOINT name {` (the name may hold spaces, the brace may
    /// be on the next line).
    fn joint(&mut self, is_root: bool, line: usize) -> Result<(), ParseError> {
        let errors = self.errors;
        if is_root && self.started {
            return Err(errors.at(
                line,
                "a second `ROOT`: only one skeleton per file is supported",
            ));
        }
        if is_root != self.stack.is_empty() {
            return Err(errors.at(
                line,
                if is_root {
                    "`ROOT` inside a joint (missing `}`?)"
                } else {
                    "`JOINT` outside the root's braces"
                },
            ));
        }
        self.started = true;
        let mut name_tokens = self.cur.rest_of_line();
        let brace_on_line = name_tokens.last() == Some(&&b"{"[..]);
        if brace_on_line {
            name_tokens.pop();
        }
        if name_tokens.is_empty() {
            return Err(errors.at(line, "joint without a name"));
        }
        let name = name_tokens
            .iter()
            .map(|t| String::from_utf8_lossy(t).into_owned())
            .collect::<Vec<_>>()
            .join(" ");
        if let Some(prev) = self.names.insert(name.clone(), line) {
            return Err(errors.at(
                line,
                format!("joint name `{name}` was already used on line {prev}"),
            ));
        }
        if !brace_on_line {
            self.cur.expect("{")?;
        }
        self.joints.push(RawJoint {
            name,
            parent: self.stack.last().copied(),
            line,
            offset: None,
            channels: Vec::new(),
            channels_line: line,
            end_site: None,
        });
        self.stack.push(self.joints.len() - 1);
        Ok(())
    }

    /// `End Site { OFFSET x y z }` of the open joint.
    fn end_site(&mut self, line: usize) -> Result<(), ParseError> {
        let errors = self.errors;
        let owner = self.open_joint(line, "`End Site`")?;
        let (site, site_line) = self.cur.need("`Site`")?;
        if !site.eq_ignore_ascii_case(b"Site") {
            return Err(errors.at(
                site_line,
                format!("expected `Site` after `End`, found `{}`", show(site)),
            ));
        }
        // Some exporters name end sites (`End Site LeftToe_End`): skip it.
        let mut brace = false;
        if self.cur.line_number() == site_line {
            brace = self.cur.rest_of_line().last() == Some(&&b"{"[..]);
        }
        if !brace {
            self.cur.expect("{")?;
        }
        self.cur.expect("OFFSET")?;
        let x = self.cur.number("End Site OFFSET x")?;
        let y = self.cur.number("End Site OFFSET y")?;
        let z = self.cur.number("End Site OFFSET z")?;
        self.cur.expect("}")?;
        let joint = &mut self.joints[owner];
        if joint.end_site.is_some() {
            return Err(errors.at(
                line,
                format!("joint `{}` has a second `End Site`", joint.name),
            ));
        }
        joint.end_site = Some(DVec3::new(x, y, z));
        Ok(())
    }

    /// `OFFSET x y z` of the open joint.
    fn offset(&mut self, line: usize) -> Result<(), ParseError> {
        let j = self.open_joint(line, "`OFFSET`")?;
        if self.joints[j].offset.is_some() {
            return Err(self.errors.at(
                line,
                format!("joint `{}` has a second `OFFSET`", self.joints[j].name),
            ));
        }
        let x = self.cur.number("OFFSET x")?;
        let y = self.cur.number("OFFSET y")?;
        let z = self.cur.number("OFFSET z")?;
        self.joints[j].offset = Some(DVec3::new(x, y, z));
        Ok(())
    }

    /// `CHANNELS n c1 .. cn` of the open joint.
    fn channels(&mut self, line: usize) -> Result<(), ParseError> {
        let errors = self.errors;
        let j = self.open_joint(line, "`CHANNELS`")?;
        if !self.joints[j].channels.is_empty() {
            return Err(errors.at(
                line,
                format!("joint `{}` has a second `CHANNELS`", self.joints[j].name),
            ));
        }
        let (t, n) = self.cur.need("the channel count")?;
        let count = text::count(t, "channel count").map_err(|m| errors.at(n, m))?;
        if count > 64 {
            return Err(errors.at(n, format!("{count} channels on one joint is not plausible")));
        }
        let mut channels = Vec::with_capacity(count);
        for i in 0..count {
            let (t, n) = self.cur.need(&format!("channel {} of {count}", i + 1))?;
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
                return Err(errors.at(n, format!("channel `{}` listed twice", channel_name(c))));
            }
            channels.push(c);
        }
        self.joints[j].channels = channels;
        self.joints[j].channels_line = line;
        Ok(())
    }

    /// `}`: closes the open joint; true when that was the root.
    fn close(&mut self, line: usize) -> Result<bool, ParseError> {
        let Some(j) = self.stack.pop() else {
            return Err(self.errors.at(line, "`}` without a matching `{`"));
        };
        let joint = &self.joints[j];
        if joint.offset.is_none() {
            return Err(self.errors.at(
                line,
                format!(
                    "joint `{}` (line {}) has no `OFFSET`",
                    joint.name, joint.line
                ),
            ));
        }
        Ok(self.stack.is_empty())
    }

    /// The error for `MOTION` before the hierarchy is complete.
    fn early_motion(&self, line: usize) -> ParseError {
        let message = match self.stack.last() {
            Some(&j) => format!(
                "`MOTION` while joint `{}` (line {}) is still open: missing `}}`",
                self.joints[j].name, self.joints[j].line
            ),
            None => "`MOTION` before any `ROOT`".to_string(),
        };
        self.errors.at(line, message)
    }

    /// The error for a file that ends inside the hierarchy, at line `at`.
    fn file_ends(&self, at: usize) -> ParseError {
        match self.stack.last() {
            None => self.errors.at(at, "file ends where `ROOT` was expected"),
            Some(&j) => self.errors.at(
                at,
                format!(
                    "file ends inside joint `{}`: missing `}}`",
                    self.joints[j].name
                ),
            ),
        }
    }
}
