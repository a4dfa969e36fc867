//! AMC motions (Acclaim Motion Capture), the frames that go with an ASF skeleton.
//!
//! An AMC file is a header (`#` comments, `:FULLY-SPECIFIED`, `:DEGREES` or
//! `:RADIANS`) and then, per frame, a frame number on its own line followed by
//! one line per bone: the bone name and its dof values in the ASF `dof` order
//! (the root: in its `order`). Conventions (see [`crate::asf`] for the
//! rotation convention):
//!
//! * the bytes are parsed as bytes: comments may hold any encoding (HDM05
//!   headers carry Latin-1 path names);
//! * root positions are in ASF length units, converted to metres; they are the
//!   root's world position (the ASF `position` only fills axes `order` lacks);
//! * angles follow `:DEGREES` / `:RADIANS`, else the ASF `angle` unit;
//! * a bone absent from a frame is at rest (all its dofs zero); an unknown bone
//!   name, a wrong value count, a repeated bone or a frame number that does not
//!   follow the previous one is an error naming the line;
//! * AMC files carry no frame rate: the caller gives it (HDM05 and CMU capture
//!   at 120 Hz, the `_120` in HDM05 file names; [`DEFAULT_FPS`]).

use std::collections::HashMap;
use std::path::Path;

use glam::{DQuat, DVec3};

use crate::asf::{Asf, Dof, local_rotation};
use crate::error::MotionError;
use crate::motion::Motion;
use crate::skeleton::Axis;
use crate::text::{self, Errors, show};

/// Frame rate assumed for AMC clips when the caller does not give one.
pub const DEFAULT_FPS: f64 = 120.0;

/// Per bone: where its values go.
struct BonePlan {
    joint: usize,
    frame: DQuat,
    /// For each dof in value order: rotation axis, or None for a translation /
    /// length dof that must stay zero.
    dofs: Vec<Option<Axis>>,
}

fn plans(asf: &Asf) -> Vec<BonePlan> {
    asf.bones
        .iter()
        .enumerate()
        .map(|(b, bone)| BonePlan {
            joint: asf.joint_of_bone(b),
            frame: bone.frame,
            dofs: bone
                .dofs
                .iter()
                .map(|d| match d {
                    Dof::Rotation(a) => Some(*a),
                    _ => None,
                })
                .collect(),
        })
        .collect()
}

/// Read an AMC motion from memory for the skeleton `asf`, at `fps` frames per
/// second. `label` names the file in errors.
///
/// Each line is a comment, a header keyword, a frame number (starting a frame
/// at rest) or a bone line of the current frame.
pub fn parse(
    bytes: &[u8],
    label: impl AsRef<Path>,
    asf: &Asf,
    fps: f64,
) -> Result<Motion, MotionError> {
    let errors = Errors::new(label.as_ref());
    if !(fps.is_finite() && fps > 0.0) {
        return Err(errors
            .whole(format!("frame rate {fps} is not a positive number"))
            .into());
    }
    let mut r = Reader::new(asf);
    for line in text::lines(bytes) {
        let mut toks = line.tokens();
        let Some(first) = toks.next() else { continue };
        let n = line.number;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        if first.starts_with(b"#") {
            continue;
        }
        if first.starts_with(b":") {
            r.header_keyword(first).map_err(err)?;
            continue;
        }
        // A frame number: a line holding one integer.
        if first.iter().all(|b| b.is_ascii_digit()) {
            r.frame_number(first, toks.next(), n).map_err(err)?;
            continue;
        }
        r.bone_line(first, toks).map_err(err)?;
    }
    if r.root_translation.is_empty() {
        return Err(errors.whole("no frames (no frame number lines)").into());
    }
    Motion::new(asf.skeleton().clone(), fps, r.root_translation, r.rotations)
        .map_err(|e| errors.whole(e.to_string()).into())
}

/// The frames read so far; errors are messages for the current line.
struct Reader<'a> {
    asf: &'a Asf,
    plans: Vec<BonePlan>,
    by_name: HashMap<Vec<u8>, usize>,
    /// Radians per angle unit: the ASF's, or `:DEGREES` / `:RADIANS`.
    angle_rad: f64,
    root_translation: Vec<DVec3>,
    /// `[frame][joint]` flattened.
    rotations: Vec<DQuat>,
    /// The current frame number and its line.
    frame_number: Option<(i64, usize)>,
    /// Bones seen in the current frame (index into asf.bones, root = the last).
    seen: Vec<bool>,
    axes: Vec<Axis>,
    angles: Vec<f64>,
    values: Vec<f64>,
}

impl<'a> Reader<'a> {
    fn new(asf: &'a Asf) -> Self {
        let by_name = asf
            .bones
            .iter()
            .enumerate()
            .map(|(b, bone)| (bone.name.as_bytes().to_ascii_lowercase(), b))
            .collect();
        Reader {
            asf,
            plans: plans(asf),
            by_name,
            angle_rad: asf.angle_rad,
            root_translation: Vec::new(),
            rotations: Vec::new(),
            frame_number: None,
            seen: vec![false; asf.bones.len() + 1],
            axes: Vec::with_capacity(3),
            angles: Vec::with_capacity(3),
            values: Vec::with_capacity(8),
        }
    }

    /// `:DEGREES`, `:RADIANS`, `:FULLY-SPECIFIED`, ... before the first frame.
    fn header_keyword(&mut self, first: &[u8]) -> Result<(), String> {
        if self.frame_number.is_some() {
            return Err(format!(
                "header keyword `{}` after the first frame",
                show(first)
            ));
        }
        match first.to_ascii_uppercase().as_slice() {
            b":DEGREES" => self.angle_rad = std::f64::consts::PI / 180.0,
            b":RADIANS" => self.angle_rad = 1.0,
            _ => {} // :FULLY-SPECIFIED and others change nothing here
        }
        Ok(())
    }

    /// A frame number line (`extra` is a second token, an error): starts a
    /// frame with every bone at rest.
    fn frame_number(&mut self, first: &[u8], extra: Option<&[u8]>, n: usize) -> Result<(), String> {
        if let Some(extra) = extra {
            return Err(format!(
                "`{}` after frame number {} (a bone name cannot be a number)",
                show(extra),
                show(first)
            ));
        }
        let number: i64 = std::str::from_utf8(first)
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| format!("frame number `{}` is too large", show(first)))?;
        if let Some((prev, _)) = self.frame_number
            && number != prev + 1
        {
            return Err(format!(
                "frame number {number} does not follow frame {prev}"
            ));
        }
        self.frame_number = Some((number, n));
        self.root_translation.push(self.asf.root.position);
        self.rotations.extend(std::iter::repeat_n(
            DQuat::IDENTITY,
            self.asf.skeleton().len(),
        ));
        self.seen.iter_mut().for_each(|s| *s = false);
        Ok(())
    }

    /// `name v1 v2 ..` of the root or a bone in the current frame.
    fn bone_line<'t>(
        &mut self,
        first: &[u8],
        toks: impl Iterator<Item = &'t [u8]>,
    ) -> Result<(), String> {
        if self.frame_number.is_none() {
            return Err(format!(
                "bone line `{}` before the first frame number",
                show(first)
            ));
        }
        self.values.clear();
        for (k, t) in toks.enumerate() {
            self.values.push(text::number(
                t,
                &format!("{} value {}", show(first), k + 1),
            )?);
        }
        if first.eq_ignore_ascii_case(b"root") {
            return self.root_values();
        }
        let asf = self.asf;
        let b = self
            .by_name
            .get(&first.to_ascii_lowercase())
            .copied()
            .ok_or_else(|| format!("unknown bone `{}` (not in the ASF)", show(first)))?;
        if self.seen[b] {
            return Err(format!(
                "bone `{}` appears twice in one frame",
                asf.bones[b].name
            ));
        }
        self.seen[b] = true;
        let plan = &self.plans[b];
        if self.values.len() != plan.dofs.len() {
            return Err(format!(
                "bone `{}` has {} values, its ASF dof lists {}",
                asf.bones[b].name,
                self.values.len(),
                plan.dofs.len()
            ));
        }
        self.axes.clear();
        self.angles.clear();
        for (d, v) in plan.dofs.iter().zip(&self.values) {
            match d {
                Some(a) => {
                    self.axes.push(*a);
                    self.angles.push(v * self.angle_rad);
                }
                None if v.abs() > 1e-9 => {
                    return Err(format!(
                        "bone `{}` has a non-zero translation or length value {v}: only the \
                         root's position can be animated",
                        asf.bones[b].name
                    ));
                }
                None => {}
            }
        }
        let frame = self.root_translation.len() - 1;
        let joints = asf.skeleton().len();
        self.rotations[frame * joints + plan.joint] =
            local_rotation(plan.frame, &self.axes, &self.angles);
        Ok(())
    }

    /// The root's values (in its ASF `order`) in the current frame.
    fn root_values(&mut self) -> Result<(), String> {
        let asf = self.asf;
        let root_seen = asf.bones.len();
        if self.seen[root_seen] {
            return Err("`root` appears twice in one frame".into());
        }
        self.seen[root_seen] = true;
        let order = &asf.root.order;
        if self.values.len() != order.len() {
            return Err(format!(
                "root has {} values, its ASF order lists {}",
                self.values.len(),
                order.len()
            ));
        }
        self.axes.clear();
        self.angles.clear();
        let mut position = asf.root.position;
        for (d, v) in order.iter().zip(&self.values) {
            match d {
                Dof::Translation(a) => position[a.index()] = v * asf.unit_m,
                Dof::Rotation(a) => {
                    self.axes.push(*a);
                    self.angles.push(v * self.angle_rad);
                }
                Dof::Length => {}
            }
        }
        let frame = self.root_translation.len() - 1;
        let joints = asf.skeleton().len();
        self.root_translation[frame] = position;
        self.rotations[frame * joints] = local_rotation(asf.root.frame, &self.axes, &self.angles);
        Ok(())
    }
}

/// Read an AMC file from disk, see [`parse`].
pub fn read(path: impl AsRef<Path>, asf: &Asf, fps: f64) -> Result<Motion, MotionError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, path, asf, fps)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::asf;
    use crate::error::ParseError;
    use crate::rotation;

    const ASF: &str = ":units\n  length 0.45\n  angle deg\n:root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n\
        :bonedata\n  begin\n     name lfemur\n     direction 0 -1 0\n     length 10\n     axis 0 0 90 XYZ\n     dof rx rz\n  end\n\
          begin\n     name ltibia\n     direction 0 -1 0\n     length 8\n     axis 0 0 0 XYZ\n     dof rx\n  end\n\
        :hierarchy\n  begin\n    root lfemur\n    lfemur ltibia\n  end\n";

    const AMC: &[u8] = b"#!OML:ASF X:\\f\xfcr Bonn\\x.ASF\r\n:FULLY-SPECIFIED\r\n:DEGREES\r\n1\nroot 1 2 3 0 90 0\r\nlfemur 30 0\nltibia 45\n2\nroot 1 2 3 0 0 0\n";

    #[test]
    fn reads_frames_with_latin1_comments() {
        let asf = asf::parse(ASF.as_bytes(), "t.asf").unwrap();
        let m = parse(AMC, "t.amc", &asf, 120.0).unwrap();
        assert_eq!(m.frames(), 2);
        let unit = 0.0254 / 0.45;
        assert!((m.root_translation()[0] - DVec3::new(1.0, 2.0, 3.0) * unit).length() < 1e-12);
        let root = m.rotation(0, 0);
        assert!(rotation::angle_between(root, DQuat::from_rotation_y(90f64.to_radians())) < 1e-12);
        // lfemur: C = Rz(90), dof rx 30: rotation of 30 degrees about C*x = y.
        let femur = m.rotation(0, 1);
        assert!(rotation::angle_between(femur, DQuat::from_rotation_y(30f64.to_radians())) < 1e-12);
        // Frame 2 omits the bones: rest.
        assert_eq!(m.rotation(1, 2), DQuat::IDENTITY);
    }

    fn err(amc: &[u8]) -> ParseError {
        let asf = asf::parse(ASF.as_bytes(), "t.asf").unwrap();
        match parse(amc, "bad.amc", &asf, 120.0) {
            Err(MotionError::Parse(e)) => e,
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn errors_name_the_line() {
        let e = err(b":DEGREES\n1\nroot 0 0 0 0 0 0\nlfemor 1 2\n");
        assert_eq!(e.line, Some(4));
        assert!(e.message.contains("lfemor"), "{e}");
        let e = err(b"1\nroot 0 0 0 0 0 0\nlfemur 1\n");
        assert_eq!(e.line, Some(3));
        assert!(e.message.contains("1 values"), "{e}");
        let e = err(b"1\nroot 0 0 0 0 0 0\n3\n");
        assert_eq!(e.line, Some(3));
        let e = err(b"1\nroot 0 0 0 0 0 0\nltibia 1e\n");
        assert!(e.message.contains("1e"), "{e}");
        let e = err(b"lfemur 0 0\n");
        assert_eq!(e.line, Some(1));
        assert!(err(b"# nothing\n").message.contains("no frames"));
    }
}
