//! Reading an ASF file line by line into its raw sections: `:name`,
//! `:units`, `:root`, the `:bonedata` blocks and the `:hierarchy` lines, as
//! written (file units, no checks across sections). [`read`] sends each line
//! to the stage of its section; the conversion to metres, radians and joints
//! is in the parent module and its `joints` stage.

use glam::DVec3;

use super::{Dof, axis_order};
use crate::error::MotionError;
use crate::skeleton::Axis;
use crate::text::{self, Errors, Line, show};

/// A `:hierarchy` line: parent, children, line number.
pub(super) type HierarchyLine = (Vec<u8>, Vec<Vec<u8>>, usize);

/// One `begin` ... `end` block of `:bonedata`, as written.
#[derive(Default)]
pub(super) struct RawBone {
    pub line: usize,
    pub name: Option<String>,
    pub direction: Option<DVec3>,
    pub length: Option<f64>,
    pub axis: Option<([f64; 3], Vec<Axis>)>,
    pub dofs: Vec<Dof>,
    pub dof_line: usize,
    pub limits: Vec<(f64, f64)>,
}

/// Everything read from the file.
pub(super) struct RawAsf {
    /// `:name`, empty when absent.
    pub name: String,
    /// `:units length` and its line.
    pub length_factor: Option<(f64, usize)>,
    /// Radians per angle unit (`:units angle`, degrees by default).
    pub angle_rad: f64,
    /// Root `order` and its line.
    pub root_order: Option<(Vec<Dof>, usize)>,
    pub root_axis: Vec<Axis>,
    pub root_position: DVec3,
    pub root_orientation: [f64; 3],
    pub bones: Vec<RawBone>,
    pub hierarchy: Vec<HierarchyLine>,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Section {
    Preamble,
    Units,
    Documentation,
    Root,
    BoneData,
    Hierarchy,
    Other,
}

/// Numbers of a `limits` entry: `(-160.0 20.0)`, `( -inf inf )`, ...
fn limit_numbers(line: &Line) -> Vec<Vec<u8>> {
    let cleaned: Vec<u8> = line
        .bytes
        .iter()
        .map(|&b| if b == b'(' || b == b')' { b' ' } else { b })
        .collect();
    cleaned
        .split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| t.to_vec())
        .collect()
}

fn limit_value(token: &[u8]) -> Result<f64, String> {
    match token.to_ascii_lowercase().as_slice() {
        b"inf" | b"+inf" | b"infinity" => Ok(f64::INFINITY),
        b"-inf" | b"-infinity" => Ok(f64::NEG_INFINITY),
        _ => text::number(token, "limit"),
    }
}

/// Read the sections of `bytes`; errors name the line.
pub(super) fn read(bytes: &[u8], errors: &Errors) -> Result<RawAsf, MotionError> {
    let lines = text::lines(bytes);
    let mut r = Reader {
        errors,
        section: Section::Preamble,
        raw: RawAsf {
            name: String::new(),
            length_factor: None,
            angle_rad: std::f64::consts::PI / 180.0,
            root_order: None,
            root_axis: vec![Axis::X, Axis::Y, Axis::Z],
            root_position: DVec3::ZERO,
            root_orientation: [0.0; 3],
            bones: Vec::new(),
            hierarchy: Vec::new(),
        },
        in_bone: false,
        hierarchy_open: false,
        seen_hierarchy: false,
        limits_pending: None,
    };
    for line in &lines {
        let toks: Vec<&[u8]> = line.tokens().collect();
        let Some(&first) = toks.first() else { continue };
        if first.starts_with(b"#") {
            continue;
        }
        if let Some(pending) = r.limits_pending {
            r.limits_continuation(line, first, pending)?;
            continue;
        }
        if first.starts_with(b":") {
            r.section_keyword(&toks, line.number)?;
            continue;
        }
        r.section_line(line, &toks)?;
    }
    let last_line = lines.last().map_or(1, |l| l.number);
    r.finish(last_line)
}

/// The reader's state between lines.
struct Reader<'e> {
    errors: &'e Errors,
    section: Section,
    raw: RawAsf,
    /// Inside a `begin` ... `end` bone block.
    in_bone: bool,
    /// Inside `:hierarchy`'s `begin` ... `end`.
    hierarchy_open: bool,
    seen_hierarchy: bool,
    /// `limits` continuation: (bone index, values still expected).
    limits_pending: Option<(usize, usize)>,
}

impl Reader<'_> {
    /// A continuation line `(min max)` of a bone's `limits`.
    fn limits_continuation(
        &mut self,
        line: &Line,
        first: &[u8],
        (b, remaining): (usize, usize),
    ) -> Result<(), MotionError> {
        let errors = self.errors;
        let err = |m: String| -> MotionError { errors.at(line.number, m).into() };
        let bones = &mut self.raw.bones;
        if first.starts_with(b"(") {
            let nums = limit_numbers(line);
            let mut vals = Vec::new();
            for t in &nums {
                vals.push(limit_value(t).map_err(err)?);
            }
            if vals.len() % 2 != 0 || vals.len() > remaining * 2 {
                return Err(err(format!(
                    "limits of bone `{}`: expected pairs `(min max)`, one per dof",
                    bones[b].name.clone().unwrap_or_default()
                )));
            }
            for p in vals.chunks(2) {
                bones[b].limits.push((p[0], p[1]));
            }
            let left = remaining - vals.len() / 2;
            self.limits_pending = if left > 0 { Some((b, left)) } else { None };
            return Ok(());
        }
        let b = &bones[b];
        Err(err(format!(
            "bone `{}` has {} dofs but only {} limits",
            b.name.clone().unwrap_or_default(),
            b.dofs.len(),
            b.limits.len()
        )))
    }

    /// A `:keyword` line: starts a section.
    fn section_keyword(&mut self, toks: &[&[u8]], n: usize) -> Result<(), MotionError> {
        let errors = self.errors;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        let first = toks[0];
        let key = first.to_ascii_lowercase();
        if self.hierarchy_open {
            return Err(err("`:hierarchy` block not closed with `end`".into()));
        }
        if self.in_bone {
            return Err(err("bone block not closed with `end`".into()));
        }
        self.section = match key.as_slice() {
            b":version" => Section::Other,
            b":name" => {
                self.raw.name = toks[1..]
                    .iter()
                    .map(|t| String::from_utf8_lossy(t).into_owned())
                    .collect::<Vec<_>>()
                    .join(" ");
                Section::Other
            }
            b":units" => Section::Units,
            b":documentation" => Section::Documentation,
            b":root" => Section::Root,
            b":bonedata" => Section::BoneData,
            b":hierarchy" => {
                self.seen_hierarchy = true;
                Section::Hierarchy
            }
            _ => Section::Other,
        };
        if toks.len() > 1 && !matches!(key.as_slice(), b":name" | b":version") {
            return Err(err(format!(
                "unexpected `{}` after `{}`",
                show(toks[1]),
                show(first)
            )));
        }
        Ok(())
    }

    /// Any other line: belongs to the current section.
    fn section_line(&mut self, line: &Line, toks: &[&[u8]]) -> Result<(), MotionError> {
        let first = toks[0];
        match self.section {
            Section::Documentation | Section::Other => Ok(()),
            Section::Preamble => Err(self
                .errors
                .at(
                    line.number,
                    format!(
                        "`{}` before any `:section` keyword (is this an ASF file?)",
                        show(first)
                    ),
                )
                .into()),
            Section::Units => self.units_line(toks, line.number),
            Section::Root => self.root_line(toks, line.number),
            Section::BoneData => self.bone_line(line, toks),
            Section::Hierarchy => self.hierarchy_line(toks, line.number),
        }
    }

    /// `length f` or `angle deg|rad` in `:units` (others are ignored).
    fn units_line(&mut self, toks: &[&[u8]], n: usize) -> Result<(), MotionError> {
        let errors = self.errors;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        match toks[0].to_ascii_lowercase().as_slice() {
            b"length" => {
                let t = toks
                    .get(1)
                    .ok_or_else(|| err("`length` without a value".into()))?;
                let f = text::number(t, "length unit").map_err(err)?;
                if f <= 0.0 {
                    return Err(err(format!("length unit {f} is not positive")));
                }
                self.raw.length_factor = Some((f, n));
            }
            b"angle" => {
                let t = toks
                    .get(1)
                    .ok_or_else(|| err("`angle` without a value".into()))?;
                self.raw.angle_rad = match t.to_ascii_lowercase().as_slice() {
                    b"deg" | b"degree" | b"degrees" => std::f64::consts::PI / 180.0,
                    b"rad" | b"radian" | b"radians" => 1.0,
                    _ => {
                        return Err(err(format!(
                            "angle unit `{}` (expected deg or rad)",
                            show(t)
                        )));
                    }
                };
            }
            _ => {} // mass and others do not matter here
        }
        Ok(())
    }

    /// `order`, `axis`, `position` or `orientation` in `:root`.
    fn root_line(&mut self, toks: &[&[u8]], n: usize) -> Result<(), MotionError> {
        let errors = self.errors;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        let first = toks[0];
        let nums = |what: &str| -> Result<[f64; 3], MotionError> {
            if toks.len() < 4 {
                return Err(err(format!("`{what}` needs 3 numbers")));
            }
            let mut v = [0.0; 3];
            for k in 0..3 {
                v[k] = text::number(toks[k + 1], what).map_err(err)?;
            }
            Ok(v)
        };
        match first.to_ascii_lowercase().as_slice() {
            b"order" => {
                let mut order = Vec::new();
                for t in &toks[1..] {
                    let d = Dof::parse(t).filter(|d| *d != Dof::Length).ok_or_else(|| {
                        err(format!("root order: `{}` is not TX..TZ or RX..RZ", show(t)))
                    })?;
                    if order.contains(&d) {
                        return Err(err(format!("root order lists `{}` twice", show(t))));
                    }
                    order.push(d);
                }
                self.raw.root_order = Some((order, n));
            }
            b"axis" => {
                let t = toks
                    .get(1)
                    .ok_or_else(|| err("root `axis` without an order".into()))?;
                self.raw.root_axis = axis_order(t).ok_or_else(|| {
                    err(format!("root axis `{}` is not an order like XYZ", show(t)))
                })?;
            }
            b"position" => self.raw.root_position = DVec3::from_array(nums("root position")?),
            b"orientation" => self.raw.root_orientation = nums("root orientation")?,
            _ => {
                return Err(err(format!("unknown root keyword `{}`", show(first))));
            }
        }
        Ok(())
    }

    /// A line of `:bonedata`: `begin`, `end` or a field of the open bone.
    fn bone_line(&mut self, line: &Line, toks: &[&[u8]]) -> Result<(), MotionError> {
        let n = line.number;
        let errors = self.errors;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        let first = toks[0];
        let key = first.to_ascii_lowercase();
        if key == b"begin" {
            if self.in_bone {
                return Err(err("`begin` inside a bone (missing `end`)".into()));
            }
            self.in_bone = true;
            self.raw.bones.push(RawBone {
                line: n,
                ..RawBone::default()
            });
            return Ok(());
        }
        if !self.in_bone {
            return Err(err(format!(
                "`{}` outside a `begin` ... `end` bone block",
                show(first)
            )));
        }
        let bi = self.raw.bones.len() - 1;
        let bone = &mut self.raw.bones[bi];
        match key.as_slice() {
            b"end" => {
                self.in_bone = false;
                if bone.name.is_none() {
                    return Err(err(format!(
                        "bone starting on line {} has no `name`",
                        bone.line
                    )));
                }
            }
            b"id" | b"bodymass" | b"cofmass" => {}
            b"name" => {
                let t = toks
                    .get(1)
                    .ok_or_else(|| err("`name` without a value".into()))?;
                let s = String::from_utf8_lossy(t).into_owned();
                if s.eq_ignore_ascii_case("root") {
                    return Err(err("a bone may not be called `root`".into()));
                }
                bone.name = Some(s);
            }
            b"direction" => {
                if toks.len() < 4 {
                    return Err(err("`direction` needs 3 numbers".into()));
                }
                let mut v = [0.0; 3];
                for k in 0..3 {
                    v[k] = text::number(toks[k + 1], "direction").map_err(err)?;
                }
                bone.direction = Some(DVec3::from_array(v));
            }
            b"length" => {
                let t = toks
                    .get(1)
                    .ok_or_else(|| err("`length` without a value".into()))?;
                let l = text::number(t, "bone length").map_err(err)?;
                if l < 0.0 {
                    return Err(err(format!("bone length {l} is negative")));
                }
                bone.length = Some(l);
            }
            b"axis" => {
                if toks.len() < 5 {
                    return Err(err("`axis` needs 3 angles and an order like XYZ".into()));
                }
                let mut v = [0.0; 3];
                for k in 0..3 {
                    v[k] = text::number(toks[k + 1], "axis angle").map_err(err)?;
                }
                let order = axis_order(toks[4]).ok_or_else(|| {
                    err(format!("axis order `{}` is not like XYZ", show(toks[4])))
                })?;
                bone.axis = Some((v, order));
            }
            b"dof" => {
                let mut dofs = Vec::new();
                for t in &toks[1..] {
                    let d = Dof::parse(t).ok_or_else(|| {
                        err(format!("`{}` is not a dof (rx ry rz tx ty tz l)", show(t)))
                    })?;
                    if dofs.contains(&d) {
                        return Err(err(format!("dof `{}` listed twice", show(t))));
                    }
                    dofs.push(d);
                }
                bone.dofs = dofs;
                bone.dof_line = n;
            }
            b"limits" => {
                if bone.dofs.is_empty() {
                    return Err(err("`limits` before (or without) `dof`".into()));
                }
                let mut vals = Vec::new();
                for t in limit_numbers(line).iter().skip(1) {
                    vals.push(limit_value(t).map_err(err)?);
                }
                if vals.len() % 2 != 0 || vals.len() > bone.dofs.len() * 2 {
                    return Err(err("limits: expected pairs `(min max)`, one per dof".into()));
                }
                bone.limits.clear();
                for p in vals.chunks(2) {
                    bone.limits.push((p[0], p[1]));
                }
                let left = bone.dofs.len() - bone.limits.len();
                if left > 0 {
                    self.limits_pending = Some((bi, left));
                }
            }
            _ => {
                return Err(err(format!("unknown bone keyword `{}`", show(first))));
            }
        }
        Ok(())
    }

    /// A line of `:hierarchy`: `begin`, `end` or `parent child..`.
    fn hierarchy_line(&mut self, toks: &[&[u8]], n: usize) -> Result<(), MotionError> {
        let errors = self.errors;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        let first = toks[0];
        let key = first.to_ascii_lowercase();
        if key == b"begin" {
            self.hierarchy_open = true;
            return Ok(());
        }
        if key == b"end" {
            self.hierarchy_open = false;
            self.section = Section::Other;
            return Ok(());
        }
        if !self.hierarchy_open {
            return Err(err(format!(
                "`{}` before `begin` in `:hierarchy`",
                show(first)
            )));
        }
        if toks.len() < 2 {
            return Err(err(format!(
                "bone `{}` listed without children",
                show(first)
            )));
        }
        self.raw.hierarchy.push((
            first.to_vec(),
            toks[1..].iter().map(|t| t.to_vec()).collect(),
            n,
        ));
        Ok(())
    }

    /// The checks at the end of the file (`last_line`): no block left open.
    fn finish(self, last_line: usize) -> Result<RawAsf, MotionError> {
        let errors = self.errors;
        if let Some((b, _)) = self.limits_pending {
            return Err(errors
                .at(
                    last_line,
                    format!(
                        "file ends inside the limits of bone `{}`",
                        self.raw.bones[b].name.clone().unwrap_or_default()
                    ),
                )
                .into());
        }
        if self.in_bone {
            return Err(errors
                .at(last_line, "file ends inside a bone block (missing `end`)")
                .into());
        }
        if self.hierarchy_open {
            return Err(errors
                .at(last_line, "file ends inside `:hierarchy` (missing `end`)")
                .into());
        }
        if !self.seen_hierarchy && !self.raw.bones.is_empty() {
            return Err(errors.whole("no `:hierarchy` section").into());
        }
        Ok(self.raw)
    }
}
