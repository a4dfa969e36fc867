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

/// Read an AMC motion from memory for the skeleton `asf`, at `fps` frames per
/// second. `label` names the file in errors.
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
    let skeleton = asf.skeleton();
    let joints = skeleton.len();
    let plans: Vec<BonePlan> = asf
        .bones
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
        .collect();

    let by_name: std::collections::HashMap<Vec<u8>, usize> = asf
        .bones
        .iter()
        .enumerate()
        .map(|(b, bone)| (bone.name.as_bytes().to_ascii_lowercase(), b))
        .collect();
    let mut angle_rad = asf.angle_rad;
    let mut root_translation: Vec<DVec3> = Vec::new();
    let mut rotations: Vec<DQuat> = Vec::new();
    let mut frame_number: Option<(i64, usize)> = None;
    // Bones seen in the current frame (index into asf.bones, root = usize::MAX).
    let mut seen: Vec<bool> = vec![false; asf.bones.len() + 1];
    let mut axes: Vec<Axis> = Vec::with_capacity(3);
    let mut angles: Vec<f64> = Vec::with_capacity(3);
    let mut values: Vec<f64> = Vec::with_capacity(8);

    for line in text::lines(bytes) {
        let mut toks = line.tokens();
        let Some(first) = toks.next() else { continue };
        let n = line.number;
        let err = |m: String| -> MotionError { errors.at(n, m).into() };
        if first.starts_with(b"#") {
            continue;
        }
        if first.starts_with(b":") {
            if frame_number.is_some() {
                return Err(err(format!(
                    "header keyword `{}` after the first frame",
                    show(first)
                )));
            }
            match first.to_ascii_uppercase().as_slice() {
                b":DEGREES" => angle_rad = std::f64::consts::PI / 180.0,
                b":RADIANS" => angle_rad = 1.0,
                _ => {} // :FULLY-SPECIFIED and others change nothing here
            }
            continue;
        }
        // A frame number: a line holding one integer.
        if first.iter().all(|b| b.is_ascii_digit()) {
            if let Some(extra) = toks.next() {
                return Err(err(format!(
                    "`{}` after frame number {} (a bone name cannot be a number)",
                    show(extra),
                    show(first)
                )));
            }
            let number: i64 = std::str::from_utf8(first)
                .ok()
                .and_then(|s| s.parse().ok())
                .ok_or_else(|| err(format!("frame number `{}` is too large", show(first))))?;
            if let Some((prev, _)) = frame_number
                && number != prev + 1
            {
                return Err(err(format!(
                    "frame number {number} does not follow frame {prev}"
                )));
            }
            frame_number = Some((number, n));
            root_translation.push(asf.root.position);
            rotations.extend(std::iter::repeat_n(DQuat::IDENTITY, joints));
            seen.iter_mut().for_each(|s| *s = false);
            continue;
        }
        if frame_number.is_none() {
            return Err(err(format!(
                "bone line `{}` before the first frame number",
                show(first)
            )));
        }
        values.clear();
        for (k, t) in toks.enumerate() {
            values.push(text::number(t, &format!("{} value {}", show(first), k + 1)).map_err(err)?);
        }
        let frame = root_translation.len() - 1;
        if first.eq_ignore_ascii_case(b"root") {
            if seen[asf.bones.len()] {
                return Err(err("`root` appears twice in one frame".into()));
            }
            seen[asf.bones.len()] = true;
            let order = &asf.root.order;
            if values.len() != order.len() {
                return Err(err(format!(
                    "root has {} values, its ASF order lists {}",
                    values.len(),
                    order.len()
                )));
            }
            axes.clear();
            angles.clear();
            let mut position = asf.root.position;
            for (d, v) in order.iter().zip(&values) {
                match d {
                    Dof::Translation(a) => position[a.index()] = v * asf.unit_m,
                    Dof::Rotation(a) => {
                        axes.push(*a);
                        angles.push(v * angle_rad);
                    }
                    Dof::Length => {}
                }
            }
            root_translation[frame] = position;
            rotations[frame * joints] = local_rotation(asf.root.frame, &axes, &angles);
            continue;
        }
        let b = by_name
            .get(&first.to_ascii_lowercase())
            .copied()
            .ok_or_else(|| err(format!("unknown bone `{}` (not in the ASF)", show(first))))?;
        if seen[b] {
            return Err(err(format!(
                "bone `{}` appears twice in one frame",
                asf.bones[b].name
            )));
        }
        seen[b] = true;
        let plan = &plans[b];
        if values.len() != plan.dofs.len() {
            return Err(err(format!(
                "bone `{}` has {} values, its ASF dof lists {}",
                asf.bones[b].name,
                values.len(),
                plan.dofs.len()
            )));
        }
        axes.clear();
        angles.clear();
        for (d, v) in plan.dofs.iter().zip(&values) {
            match d {
                Some(a) => {
                    axes.push(*a);
                    angles.push(v * angle_rad);
                }
                None if v.abs() > 1e-9 => {
                    return Err(err(format!(
                        "bone `{}` has a non-zero translation or length value {v}: only the \
                         root's position can be animated",
                        asf.bones[b].name
                    )));
                }
                None => {}
            }
        }
        rotations[frame * joints + plan.joint] = local_rotation(plan.frame, &axes, &angles);
    }
    if root_translation.is_empty() {
        return Err(errors.whole("no frames (no frame number lines)").into());
    }
    Motion::new(skeleton.clone(), fps, root_translation, rotations)
        .map_err(|e| errors.whole(e.to_string()).into())
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
