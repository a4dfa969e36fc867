//! ASF skeletons (Acclaim Skeleton File), as written by CMU and HDM05.
//!
//! An ASF file describes bones, not joints: each bone has a rest `direction`
//! and `length` in the global frame, a local coordinate frame `C` given by
//! `axis ax ay az ORDER`, and the rotational degrees of freedom (`dof`) that
//! AMC frames animate, in that frame. We convert it to the crate's joint
//! representation:
//!
//! * one joint per bone, placed at the bone's start (the end of its parent
//!   bone), named like the bone; the root joint is named `root`;
//! * a joint's rest offset is its parent bone's `direction * length`, in metres
//!   (children of the root start at the root: offset 0); a leaf bone's own
//!   `direction * length` becomes its `end_site`. Rest orientations are the
//!   identity, as everywhere in the crate, since ASF rest directions are global;
//! * lengths: `:units length f` means one file unit is `1/f` inch (HDM05 and
//!   CMU write `length 0.45`), so metres = value * 0.0254 / f. Without a
//!   `:units` section the factor is 1 (inches) and angles are degrees;
//! * the local rotation of a joint for AMC values is `C * M * C^-1`, where `M`
//!   composes the `dof` rotations in the order listed, the first listed applied
//!   first (`dof rx ry rz` gives `M = Rz * Ry * Rx`), and `C` composes the
//!   `axis` angles the same way in the order its letters give (`XYZ`: `C = Rz *
//!   Ry * Rx`). The root's `C` comes from `orientation` and `axis`, its `M`
//!   from the rotation entries of `order`. This is the convention of the CMU
//!   reference code; the tests check it against the physics of real HDM05
//!   clips (feet on the floor, upright body, left/right symmetry);
//! * `limits` become [`JointLimits`] with `frame = C` and the rotation dofs in
//!   radians, listed outermost first, i.e. in the order
//!   [`crate::rotation::from_channels`] composes them (`dof rx ry rz` is stored
//!   as z, y, x). `(-inf inf)` limits stay infinite.
//!
//! Translation dofs on bones (`tx ty tz`, `l`) are read, and AMC frames must
//! hold them at zero: the motion model animates only the root's position.

use std::path::Path;
use std::sync::Arc;

use glam::{DQuat, DVec3};

use crate::error::MotionError;
#[cfg(test)]
use crate::error::ParseError;
use crate::motion::Motion;
#[cfg(test)]
use crate::rotation;
use crate::skeleton::{Axis, Channel, Joint, JointLimits, Skeleton};
use crate::text::{self, Errors, Line, show};

/// Metres per inch.
const INCH_M: f64 = 0.0254;

/// One degree of freedom of an ASF bone or of the root.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dof {
    Rotation(Axis),
    Translation(Axis),
    /// `l`: a change of bone length.
    Length,
}

impl Dof {
    fn parse(token: &[u8]) -> Option<Dof> {
        Some(match token.to_ascii_lowercase().as_slice() {
            b"rx" => Dof::Rotation(Axis::X),
            b"ry" => Dof::Rotation(Axis::Y),
            b"rz" => Dof::Rotation(Axis::Z),
            b"tx" => Dof::Translation(Axis::X),
            b"ty" => Dof::Translation(Axis::Y),
            b"tz" => Dof::Translation(Axis::Z),
            b"l" => Dof::Length,
            _ => return None,
        })
    }
}

/// The `:root` section.
#[derive(Debug, Clone, PartialEq)]
pub struct AsfRoot {
    /// Order of the root's values in AMC frames (`order`).
    pub order: Vec<Dof>,
    /// Rest position, metres.
    pub position: DVec3,
    /// The root's frame `C` (from `orientation` and `axis`).
    pub frame: DQuat,
}

/// One bone of `:bonedata`.
#[derive(Debug, Clone, PartialEq)]
pub struct AsfBone {
    pub name: String,
    /// Unit rest direction, global frame.
    pub direction: DVec3,
    /// Length, metres.
    pub length: f64,
    /// The bone's frame `C` (from `axis`).
    pub frame: DQuat,
    /// Degrees of freedom in AMC value order.
    pub dofs: Vec<Dof>,
    /// Limits per dof (same order), radians for rotations, metres otherwise.
    pub limits: Vec<(f64, f64)>,
    /// Line of the bone's `begin`.
    pub line: usize,
}

/// A parsed ASF file and its conversion to a [`Skeleton`].
#[derive(Debug, Clone, PartialEq)]
pub struct Asf {
    /// `:name`, empty when absent.
    pub name: String,
    /// Metres per ASF length unit (`0.0254 / length`).
    pub unit_m: f64,
    /// Radians per ASF angle unit (`angle deg` or `rad`); AMC files may override.
    pub angle_rad: f64,
    pub root: AsfRoot,
    /// Bones in file order.
    pub bones: Vec<AsfBone>,
    skeleton: Arc<Skeleton>,
    /// Skeleton joint of each bone (index into `bones`).
    joint_of_bone: Vec<usize>,
}

impl Asf {
    /// The skeleton: joint 0 `root`, then one joint per bone in depth-first order.
    pub fn skeleton(&self) -> &Arc<Skeleton> {
        &self.skeleton
    }

    /// Skeleton joint index of bone `bone` (index into [`Asf::bones`]).
    pub fn joint_of_bone(&self, bone: usize) -> usize {
        self.joint_of_bone[bone]
    }

    /// Index into [`Asf::bones`] of the bone with this name (ASCII case-insensitive).
    pub fn bone(&self, name: &[u8]) -> Option<usize> {
        self.bones
            .iter()
            .position(|b| b.name.as_bytes().eq_ignore_ascii_case(name))
    }

    /// A one-frame motion in the rest pose (all dofs zero) at the root's rest position.
    pub fn rest_motion(&self, fps: f64) -> Result<Motion, MotionError> {
        Motion::new(
            self.skeleton.clone(),
            fps,
            vec![self.root.position],
            vec![DQuat::IDENTITY; self.skeleton.len()],
        )
    }
}

/// Compose rotations about `axes` with `angles`, the first listed applied first.
pub(crate) fn compose_applied_in_order(axes: &[Axis], angles: &[f64]) -> DQuat {
    axes.iter()
        .zip(angles)
        .fold(DQuat::IDENTITY, |q, (axis, angle)| {
            DQuat::from_axis_angle(axis.unit(), *angle) * q
        })
}

fn axis_order(token: &[u8]) -> Option<Vec<Axis>> {
    if token.len() != 3 {
        return None;
    }
    let mut out = Vec::with_capacity(3);
    for b in token {
        let a = match b.to_ascii_uppercase() {
            b'X' => Axis::X,
            b'Y' => Axis::Y,
            b'Z' => Axis::Z,
            _ => return None,
        };
        if out.contains(&a) {
            return None;
        }
        out.push(a);
    }
    Some(out)
}

/// Frame `C` from angles given as x, y, z and the order they are applied in.
fn frame_from(angles_xyz: [f64; 3], order: &[Axis]) -> DQuat {
    let angles: Vec<f64> = order.iter().map(|a| angles_xyz[a.index()]).collect();
    compose_applied_in_order(order, &angles)
}

/// A `:hierarchy` line: parent, children, line number.
type HierarchyLine = (Vec<u8>, Vec<Vec<u8>>, usize);

#[derive(Default)]
struct RawBone {
    line: usize,
    name: Option<String>,
    direction: Option<DVec3>,
    length: Option<f64>,
    axis: Option<([f64; 3], Vec<Axis>)>,
    dofs: Vec<Dof>,
    dof_line: usize,
    limits: Vec<(f64, f64)>,
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

/// Read an ASF skeleton from memory; `label` names the file in errors.
pub fn parse(bytes: &[u8], label: impl AsRef<Path>) -> Result<Asf, MotionError> {
    let errors = Errors::new(label.as_ref());
    let lines = text::lines(bytes);
    let mut section = Section::Preamble;
    let mut name = String::new();
    let mut length_factor: Option<(f64, usize)> = None;
    let mut angle_rad = std::f64::consts::PI / 180.0;
    let mut root_order: Option<(Vec<Dof>, usize)> = None;
    let mut root_axis: Vec<Axis> = vec![Axis::X, Axis::Y, Axis::Z];
    let mut root_position = DVec3::ZERO;
    let mut root_orientation = [0.0; 3];
    let mut bones: Vec<RawBone> = Vec::new();
    let mut in_bone = false;
    let mut hierarchy: Vec<HierarchyLine> = Vec::new();
    let mut hierarchy_open = false;
    let mut seen_hierarchy = false;
    // `limits` continuation: (bone index, values still expected).
    let mut limits_pending: Option<(usize, usize)> = None;

    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        i += 1;
        let toks: Vec<&[u8]> = line.tokens().collect();
        let Some(&first) = toks.first() else { continue };
        if first.starts_with(b"#") {
            continue;
        }
        let n = line.number;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };

        // Continuation lines of `limits`.
        if let Some((b, remaining)) = limits_pending {
            if first.starts_with(b"(") {
                let nums = limit_numbers(&line);
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
                limits_pending = if left > 0 { Some((b, left)) } else { None };
                continue;
            }
            let b = &bones[b];
            return Err(err(format!(
                "bone `{}` has {} dofs but only {} limits",
                b.name.clone().unwrap_or_default(),
                b.dofs.len(),
                b.limits.len()
            )));
        }

        if first.starts_with(b":") {
            let key = first.to_ascii_lowercase();
            if hierarchy_open {
                return Err(err("`:hierarchy` block not closed with `end`".into()));
            }
            if in_bone {
                return Err(err("bone block not closed with `end`".into()));
            }
            section = match key.as_slice() {
                b":version" => Section::Other,
                b":name" => {
                    name = toks[1..]
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
                    seen_hierarchy = true;
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
            continue;
        }

        let key = first.to_ascii_lowercase();
        match section {
            Section::Documentation | Section::Other => {}
            Section::Preamble => {
                return Err(err(format!(
                    "`{}` before any `:section` keyword (is this an ASF file?)",
                    show(first)
                )));
            }
            Section::Units => match key.as_slice() {
                b"length" => {
                    let t = toks
                        .get(1)
                        .ok_or_else(|| err("`length` without a value".into()))?;
                    let f = text::number(t, "length unit").map_err(err)?;
                    if f <= 0.0 {
                        return Err(err(format!("length unit {f} is not positive")));
                    }
                    length_factor = Some((f, n));
                }
                b"angle" => {
                    let t = toks
                        .get(1)
                        .ok_or_else(|| err("`angle` without a value".into()))?;
                    angle_rad = match t.to_ascii_lowercase().as_slice() {
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
            },
            Section::Root => {
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
                match key.as_slice() {
                    b"order" => {
                        let mut order = Vec::new();
                        for t in &toks[1..] {
                            let d =
                                Dof::parse(t).filter(|d| *d != Dof::Length).ok_or_else(|| {
                                    err(format!(
                                        "root order: `{}` is not TX..TZ or RX..RZ",
                                        show(t)
                                    ))
                                })?;
                            if order.contains(&d) {
                                return Err(err(format!("root order lists `{}` twice", show(t))));
                            }
                            order.push(d);
                        }
                        root_order = Some((order, n));
                    }
                    b"axis" => {
                        let t = toks
                            .get(1)
                            .ok_or_else(|| err("root `axis` without an order".into()))?;
                        root_axis = axis_order(t).ok_or_else(|| {
                            err(format!("root axis `{}` is not an order like XYZ", show(t)))
                        })?;
                    }
                    b"position" => root_position = DVec3::from_array(nums("root position")?),
                    b"orientation" => root_orientation = nums("root orientation")?,
                    _ => {
                        return Err(err(format!("unknown root keyword `{}`", show(first))));
                    }
                }
            }
            Section::BoneData => {
                if key == b"begin" {
                    if in_bone {
                        return Err(err("`begin` inside a bone (missing `end`)".into()));
                    }
                    in_bone = true;
                    bones.push(RawBone {
                        line: n,
                        ..RawBone::default()
                    });
                    continue;
                }
                if !in_bone {
                    return Err(err(format!(
                        "`{}` outside a `begin` ... `end` bone block",
                        show(first)
                    )));
                }
                let bi = bones.len() - 1;
                let bone = &mut bones[bi];
                match key.as_slice() {
                    b"end" => {
                        in_bone = false;
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
                        for t in limit_numbers(&line).iter().skip(1) {
                            vals.push(limit_value(t).map_err(err)?);
                        }
                        if vals.len() % 2 != 0 || vals.len() > bone.dofs.len() * 2 {
                            return Err(err(
                                "limits: expected pairs `(min max)`, one per dof".into()
                            ));
                        }
                        bone.limits.clear();
                        for p in vals.chunks(2) {
                            bone.limits.push((p[0], p[1]));
                        }
                        let left = bone.dofs.len() - bone.limits.len();
                        if left > 0 {
                            limits_pending = Some((bi, left));
                        }
                    }
                    _ => {
                        return Err(err(format!("unknown bone keyword `{}`", show(first))));
                    }
                }
            }
            Section::Hierarchy => {
                if key == b"begin" {
                    hierarchy_open = true;
                    continue;
                }
                if key == b"end" {
                    hierarchy_open = false;
                    section = Section::Other;
                    continue;
                }
                if !hierarchy_open {
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
                hierarchy.push((
                    first.to_vec(),
                    toks[1..].iter().map(|t| t.to_vec()).collect(),
                    n,
                ));
            }
        }
    }
    let last_line = lines.last().map_or(1, |l| l.number);
    if let Some((b, _)) = limits_pending {
        return Err(errors
            .at(
                last_line,
                format!(
                    "file ends inside the limits of bone `{}`",
                    bones[b].name.clone().unwrap_or_default()
                ),
            )
            .into());
    }
    if in_bone {
        return Err(errors
            .at(last_line, "file ends inside a bone block (missing `end`)")
            .into());
    }
    if hierarchy_open {
        return Err(errors
            .at(last_line, "file ends inside `:hierarchy` (missing `end`)")
            .into());
    }
    if !seen_hierarchy && !bones.is_empty() {
        return Err(errors.whole("no `:hierarchy` section").into());
    }

    let unit_m = INCH_M / length_factor.map_or(1.0, |(f, _)| f);
    let root_order = root_order.map_or_else(
        || {
            vec![
                Dof::Translation(Axis::X),
                Dof::Translation(Axis::Y),
                Dof::Translation(Axis::Z),
                Dof::Rotation(Axis::X),
                Dof::Rotation(Axis::Y),
                Dof::Rotation(Axis::Z),
            ]
        },
        |(o, _)| o,
    );
    let root = AsfRoot {
        order: root_order,
        position: root_position * unit_m,
        frame: frame_from(root_orientation.map(|a| a * angle_rad), &root_axis),
    };

    // Finish the bones.
    let mut out_bones = Vec::with_capacity(bones.len());
    let mut seen_names = std::collections::HashSet::new();
    for b in bones {
        let name = b.name.unwrap_or_default();
        let at = |m: String| -> MotionError { errors.at(b.line, m).into() };
        if !seen_names.insert(name.to_ascii_lowercase()) {
            return Err(at(format!("bone name `{name}` appears twice")));
        }
        let direction = b
            .direction
            .ok_or_else(|| at(format!("bone `{name}` has no `direction`")))?;
        let length = b
            .length
            .ok_or_else(|| at(format!("bone `{name}` has no `length`")))?;
        let direction = if direction.length() > 1e-12 {
            direction.normalize()
        } else if length == 0.0 {
            DVec3::ZERO
        } else {
            return Err(at(format!("bone `{name}` has a zero `direction`")));
        };
        let frame = match &b.axis {
            Some((angles, order)) => frame_from(angles.map(|a| a * angle_rad), order),
            None => DQuat::IDENTITY,
        };
        if !b.limits.is_empty() && b.limits.len() != b.dofs.len() {
            return Err(errors
                .at(
                    b.dof_line,
                    format!(
                        "bone `{name}` has {} dofs but {} limits",
                        b.dofs.len(),
                        b.limits.len()
                    ),
                )
                .into());
        }
        let limits = b
            .limits
            .iter()
            .zip(&b.dofs)
            .map(|(&(lo, hi), d)| match d {
                Dof::Rotation(_) => (lo * angle_rad, hi * angle_rad),
                _ => (lo * unit_m, hi * unit_m),
            })
            .collect();
        out_bones.push(AsfBone {
            name,
            direction,
            length: length * unit_m,
            frame,
            dofs: b.dofs,
            limits,
            line: b.line,
        });
    }

    let (skeleton, joint_of_bone) = build_skeleton(&out_bones, &root, &hierarchy, unit_m, &errors)?;
    Ok(Asf {
        name,
        unit_m,
        angle_rad,
        root,
        bones: out_bones,
        skeleton: Arc::new(skeleton),
        joint_of_bone,
    })
}

/// Joints in depth-first order following `:hierarchy` (children in listed order).
fn build_skeleton(
    bones: &[AsfBone],
    root: &AsfRoot,
    hierarchy: &[HierarchyLine],
    unit_m: f64,
    errors: &Errors,
) -> Result<(Skeleton, Vec<usize>), MotionError> {
    // Node 0 is the root, node b + 1 is bone b.
    let by_name: std::collections::HashMap<Vec<u8>, usize> = bones
        .iter()
        .enumerate()
        .map(|(b, bone)| (bone.name.as_bytes().to_ascii_lowercase(), b + 1))
        .collect();
    let node = |name: &[u8]| -> Option<usize> {
        if name.eq_ignore_ascii_case(b"root") {
            Some(0)
        } else {
            by_name.get(&name.to_ascii_lowercase()).copied()
        }
    };
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); bones.len() + 1];
    let mut parent_line: Vec<Option<usize>> = vec![None; bones.len() + 1];
    for (parent, kids, line) in hierarchy {
        let p = node(parent).ok_or_else(|| {
            errors.at(
                *line,
                format!("`{}` in :hierarchy is not a bone", show(parent)),
            )
        })?;
        for k in kids {
            let c = node(k).ok_or_else(|| {
                errors.at(*line, format!("`{}` in :hierarchy is not a bone", show(k)))
            })?;
            if c == 0 {
                return Err(errors.at(*line, "the root cannot be a child").into());
            }
            if let Some(prev) = parent_line[c] {
                return Err(errors
                    .at(
                        *line,
                        format!("bone `{}` already has a parent (line {prev})", show(k)),
                    )
                    .into());
            }
            parent_line[c] = Some(*line);
            children[p].push(c);
        }
    }
    let rotations = [
        Channel::Rotation(Axis::Z),
        Channel::Rotation(Axis::Y),
        Channel::Rotation(Axis::X),
    ];
    let mut joints = Vec::with_capacity(bones.len() + 1);
    let mut joint_of_node = vec![usize::MAX; bones.len() + 1];
    // Depth-first, iterative: (node, parent node).
    let mut stack: Vec<(usize, Option<usize>)> = vec![(0, None)];
    while let Some((nd, parent_node)) = stack.pop() {
        let parent_joint = parent_node.map(|p| joint_of_node[p]);
        if joint_of_node[nd] != usize::MAX {
            // Cannot happen with one parent per bone, but never loop.
            continue;
        }
        let index = joints.len();
        joint_of_node[nd] = index;
        let leaf = children[nd].is_empty();
        let joint = if nd == 0 {
            let mut channels = vec![
                Channel::Position(Axis::X),
                Channel::Position(Axis::Y),
                Channel::Position(Axis::Z),
            ];
            channels.extend(rotations);
            Joint {
                name: "root".into(),
                parent: None,
                offset: root.position,
                channels,
                end_site: None,
                limits: None,
            }
        } else {
            let bone = &bones[nd - 1];
            // Offset: the parent bone's vector (0 for children of the root).
            let offset = match parent_node {
                Some(p) if p > 0 => bones[p - 1].direction * bones[p - 1].length,
                _ => DVec3::ZERO,
            };
            let rot_dofs: Vec<(Axis, f64, f64)> = bone
                .dofs
                .iter()
                .enumerate()
                .filter_map(|(k, d)| match d {
                    Dof::Rotation(a) => {
                        let (lo, hi) = bone
                            .limits
                            .get(k)
                            .copied()
                            .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
                        Some((*a, lo, hi))
                    }
                    _ => None,
                })
                .rev()
                .collect();
            let limits = if bone.limits.is_empty() {
                None
            } else {
                Some(JointLimits {
                    frame: bone.frame,
                    dofs: rot_dofs,
                })
            };
            Joint {
                name: bone.name.clone(),
                parent: parent_joint,
                offset,
                channels: rotations.to_vec(),
                end_site: if leaf {
                    Some(bone.direction * bone.length)
                } else {
                    None
                },
                limits,
            }
        };
        joints.push(joint);
        for &c in children[nd].iter().rev() {
            stack.push((c, Some(nd)));
        }
    }
    if let Some(b) = (1..=bones.len()).find(|&nd| joint_of_node[nd] == usize::MAX) {
        let bone = &bones[b - 1];
        return Err(errors
            .at(
                bone.line,
                format!(
                    "bone `{}` is not connected to the root in :hierarchy",
                    bone.name
                ),
            )
            .into());
    }
    let joint_of_bone = (1..=bones.len()).map(|nd| joint_of_node[nd]).collect();
    let skeleton = Skeleton::new(joints, unit_m).map_err(|e| errors.whole(e.to_string()))?;
    Ok((skeleton, joint_of_bone))
}

/// Read an ASF file from disk, see [`parse`].
pub fn read(path: impl AsRef<Path>) -> Result<Asf, MotionError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, path)
}

/// Local rotation of a bone for its AMC rotation values (radians, dof order).
pub(crate) fn local_rotation(frame: DQuat, axes: &[Axis], angles: &[f64]) -> DQuat {
    frame * compose_applied_in_order(axes, angles) * frame.inverse()
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const SMALL: &str = "# test\n:version 1.10\n:name test\n:units\n  mass 1.0\n  length 0.45\n  angle deg\n\
        :documentation\n  anything : goes here\n:root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n\
        :bonedata\n  begin\n     id 1\n     name lfemur\n     direction 0 -1 0\n     length 10\n     axis 0 0 20 XYZ\n     dof rx ry rz\n\
             limits (-160.0 20.0)\n            (-70.0 70.0)\n            (-inf inf)\n  end\n\
          begin\n     id 2\n     name ltibia\n     direction 0 -1 0\n     length 8\n     axis 0 0 0 XYZ\n     dof rx\n     limits (0 170)\n  end\n\
        :hierarchy\n  begin\n    root lfemur\n    lfemur ltibia\n  end\n";

    #[test]
    fn converts_bones_to_joints() {
        let asf = parse(SMALL.as_bytes(), "t.asf").unwrap();
        let s = asf.skeleton();
        assert_eq!(s.len(), 3);
        assert_eq!(s.joint(0).name, "root");
        assert_eq!(s.joint(1).name, "lfemur");
        let unit = 0.0254 / 0.45;
        assert!((asf.unit_m - unit).abs() < 1e-15);
        assert_eq!(s.joint(1).offset, DVec3::ZERO);
        assert!((s.joint(2).offset - DVec3::new(0.0, -10.0 * unit, 0.0)).length() < 1e-12);
        assert!(
            (s.joint(2).end_site.unwrap() - DVec3::new(0.0, -8.0 * unit, 0.0)).length() < 1e-12
        );
        let lim = s.joint(1).limits.as_ref().unwrap();
        assert_eq!(lim.dofs.len(), 3);
        assert_eq!(lim.dofs[0].0, Axis::Z);
        assert!(lim.dofs[0].2.is_infinite());
        assert!((lim.dofs[2].1 + 160f64.to_radians()).abs() < 1e-12);
        assert!(
            rotation::angle_between(lim.frame, DQuat::from_rotation_z(20f64.to_radians())) < 1e-12
        );
    }

    #[test]
    fn applied_in_order_means_first_is_innermost() {
        let q = compose_applied_in_order(&[Axis::X, Axis::Y, Axis::Z], &[0.1, 0.2, 0.3]);
        let e =
            DQuat::from_rotation_z(0.3) * DQuat::from_rotation_y(0.2) * DQuat::from_rotation_x(0.1);
        assert!(rotation::angle_between(q, e) < 1e-12);
    }

    fn err(text: &str) -> ParseError {
        match parse(text.as_bytes(), "bad.asf") {
            Err(MotionError::Parse(e)) => e,
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn errors_name_the_line() {
        let e = err(&SMALL.replace("length 8", "length 8x"));
        assert_eq!(e.line, Some(31), "{e}");
        let e = err(&SMALL.replace("lfemur ltibia", "lfemur lshin"));
        assert!(e.message.contains("lshin"), "{e}");
        let e = err(&SMALL.replace("     dof rx\n", "     dof rx rq\n"));
        assert!(e.message.contains("rq"), "{e}");
        let e = err(&SMALL.replace("            (-inf inf)\n", ""));
        assert!(e.message.contains("3 dofs but"), "{e}");
        let e = err(&SMALL.replace("    lfemur ltibia\n", ""));
        assert!(e.message.contains("not connected"), "{e}");
    }
}
