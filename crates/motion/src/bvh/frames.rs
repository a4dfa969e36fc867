//! Reading the `MOTION` section: the header (`MOTION`, `Frames:`, `Frame
//! Time:`) from the token stream, then the frame values, one frame per
//! non-blank line, each line holding one value per channel of the hierarchy.

use super::cursor::Cursor;
use super::hierarchy::RawJoint;
use crate::error::ParseError;
use crate::text::{self, Errors, Line, show};

/// The `MOTION` header.
pub(super) struct Header {
    /// Line of `MOTION`.
    pub motion_line: usize,
    /// `Frames:`, never 0.
    pub frames: usize,
    /// `Frame Time:` in seconds (positive).
    pub frame_time: f64,
    /// Line of the frame time value; the frame data starts after it.
    pub frame_time_line: usize,
}

/// All frame values, `[frame][channel]` flattened, channels in hierarchy order.
pub(super) struct Values {
    pub frames: usize,
    pub channel_count: usize,
    pub values: Vec<f64>,
}

impl Values {
    /// Value of channel column `c` at frame `f`.
    pub fn at(&self, f: usize, c: usize) -> f64 {
        self.values[f * self.channel_count + c]
    }
}

/// `MOTION`, `Frames: n` and `Frame Time: dt`, right after the hierarchy.
pub(super) fn read_header(cur: &mut Cursor, errors: &Errors) -> Result<Header, ParseError> {
    let motion_line = {
        let at = cur.line_number();
        let (t, n) = cur.need("`MOTION`")?;
        if t.eq_ignore_ascii_case(b"ROOT") {
            return Err(errors.at(
                n,
                "a second `ROOT`: only one skeleton per file is supported",
            ));
        }
        if !t.eq_ignore_ascii_case(b"MOTION") {
            return Err(errors.at(
                n.max(at),
                format!(
                    "expected `MOTION` after the hierarchy, found `{}` (an extra `}}`?)",
                    show(t)
                ),
            ));
        }
        n
    };
    let frames = {
        let (t, n) = cur.need("`Frames:`")?;
        let count_token = if t.eq_ignore_ascii_case(b"Frames:") {
            cur.need("the frame count")?
        } else if t.len() > 7 && t[..7].eq_ignore_ascii_case(b"Frames:") {
            (&t[7..], n)
        } else {
            return Err(errors.at(
                n,
                format!(
                    "expected `Frames:` after `MOTION` (line {motion_line}), found `{}`",
                    show(t)
                ),
            ));
        };
        text::count(count_token.0, "frame count").map_err(|m| errors.at(count_token.1, m))?
    };
    let (frame_time, frame_time_line) = {
        cur.expect("Frame")?;
        let (t, n) = cur.need("`Time:`")?;
        let value = if t.eq_ignore_ascii_case(b"Time:") {
            let (v, vn) = cur.need("the frame time")?;
            (v, vn)
        } else if t.len() > 5 && t[..5].eq_ignore_ascii_case(b"Time:") {
            (&t[5..], n)
        } else {
            return Err(errors.at(
                n,
                format!("expected `Frame Time:`, found `Frame {}`", show(t)),
            ));
        };
        let dt = text::number(value.0, "frame time").map_err(|m| errors.at(value.1, m))?;
        if dt <= 0.0 {
            return Err(errors.at(value.1, format!("frame time {dt} is not positive")));
        }
        (dt, value.1)
    };
    if cur.peek().is_some() && cur.line_number() == frame_time_line {
        // Frame data on the `Frame Time` line itself: not a layout any exporter uses.
        let (t, n) = cur.need("")?;
        return Err(errors.at(n, format!("unexpected `{}` after the frame time", show(t))));
    }
    if frames == 0 {
        return Err(errors.at(frame_time_line, "`Frames: 0`: the clip has no frames"));
    }
    Ok(Header {
        motion_line,
        frames,
        frame_time,
        frame_time_line,
    })
}

/// The frame values after the header: exactly `header.frames` lines of one
/// value per channel of `joints`.
pub(super) fn read_values(
    lines: &[Line],
    header: &Header,
    joints: &[RawJoint],
    errors: &Errors,
) -> Result<Values, ParseError> {
    let channel_count: usize = joints.iter().map(|j| j.channels.len()).sum();
    if channel_count == 0 {
        return Err(errors.at(
            header.motion_line,
            "no joint has CHANNELS: there is nothing to animate",
        ));
    }
    let frames_declared = header.frames;
    // Line numbers are 1-based indices into `lines`: data starts after the frame time.
    let data_lines: Vec<&Line> = lines[header.frame_time_line.min(lines.len())..]
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
                lines.last().map_or(header.frame_time_line, |l| l.number),
                format!(
                    "file ends after {} frames, `Frames:` says {frames_declared}",
                    data_lines.len()
                ),
            )
        });
    }
    let mut values = vec![0.0f64; frames_declared * channel_count];
    for (f, line) in data_lines.iter().enumerate() {
        let row = &mut values[f * channel_count..(f + 1) * channel_count];
        read_row(line, f, row, errors)?;
    }
    Ok(Values {
        frames: frames_declared,
        channel_count,
        values,
    })
}

/// The values of frame `f` (0-based) from `line` into `row`.
fn read_row(line: &Line, f: usize, row: &mut [f64], errors: &Errors) -> Result<(), ParseError> {
    let channel_count = row.len();
    let mut n = 0;
    for tok in line.tokens() {
        if n >= channel_count {
            let found = line.tokens().count();
            return Err(errors.at(
                line.number,
                format!(
                    "frame {} has {found} values, the hierarchy has {channel_count} channels",
                    f + 1
                ),
            ));
        }
        row[n] = text::number(tok, &format!("frame {}, value {}", f + 1, n + 1))
            .map_err(|m| errors.at(line.number, m))?;
        n += 1;
    }
    if n != channel_count {
        return Err(errors.at(
            line.number,
            format!(
                "frame {} has {n} values, the hierarchy has {channel_count} channels",
                f + 1
            ),
        ));
    }
    Ok(())
}
