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
//!
//! [`parse`] runs in stages: the sections line by line as written
//! (`sections`), the root and bones in metres and radians (here), then the
//! joints in depth-first order (`joints`).

use std::path::Path;
use std::sync::Arc;

use glam::{DQuat, DVec3};

use crate::error::MotionError;
#[cfg(test)]
use crate::error::ParseError;
use crate::motion::Motion;
#[cfg(test)]
use crate::rotation;
use crate::skeleton::{Axis, Skeleton};
use crate::text::Errors;

mod joints;
mod sections;

use sections::{RawAsf, RawBone};

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

/// Read an ASF skeleton from memory; `label` names the file in errors.
///
/// Stages: the sections as written, the root and the bones in metres and
/// radians, then the joints.
pub fn parse(bytes: &[u8], label: impl AsRef<Path>) -> Result<Asf, MotionError> {
    let errors = Errors::new(label.as_ref());
    let raw = sections::read(bytes, &errors)?;
    let unit_m = INCH_M / raw.length_factor.map_or(1.0, |(f, _)| f);
    let angle_rad = raw.angle_rad;
    let root = finish_root(&raw, unit_m);
    let bones = finish_bones(raw.bones, unit_m, angle_rad, &errors)?;
    let (skeleton, joint_of_bone) = joints::build(&bones, &root, &raw.hierarchy, unit_m, &errors)?;
    Ok(Asf {
        name: raw.name,
        unit_m,
        angle_rad,
        root,
        bones,
        skeleton: Arc::new(skeleton),
        joint_of_bone,
    })
}

/// The root in metres and radians; without `order`, `TX TY TZ RX RY RZ`.
fn finish_root(raw: &RawAsf, unit_m: f64) -> AsfRoot {
    let order = raw.root_order.clone().map_or_else(
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
    AsfRoot {
        order,
        position: raw.root_position * unit_m,
        frame: frame_from(
            raw.root_orientation.map(|a| a * raw.angle_rad),
            &raw.root_axis,
        ),
    }
}

/// Each bone checked (unique name, `direction`, `length`, one limit per dof)
/// and converted to metres and radians.
fn finish_bones(
    raw: Vec<RawBone>,
    unit_m: f64,
    angle_rad: f64,
    errors: &Errors,
) -> Result<Vec<AsfBone>, MotionError> {
    let mut out_bones = Vec::with_capacity(raw.len());
    let mut seen_names = std::collections::HashSet::new();
    for b in raw {
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
    Ok(out_bones)
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
