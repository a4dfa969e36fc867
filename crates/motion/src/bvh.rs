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
//! * position channels on other joints are translations, read as absolute
//!   (the joint's local translation, what Blender reads) when their values lie
//!   closer to the `OFFSET` than to zero, else as added to the `OFFSET`
//!   (module `translation` has the rule). Constant ones become the joint's offset;
//!   varying ones become the joint's translation track in the [`Motion`],
//!   which forward kinematics uses and the writer writes back;
//! * a root that stands still above the joint carrying the body's travel (a
//!   static `joint_Root` above a moving `Hips`) is folded into the skeleton's
//!   base, so the motion's root is the travelling joint (module `base`; the writer
//!   writes the static joints back above it);
//! * any problem is a [`crate::ParseError`] naming the file, the line and what is
//!   wrong; no input panics and nothing partial is returned.
//!
//! The writer produces the standard layout Blender and other tools read (tabs,
//! `End Site` blocks, `MOTION`, `Frames:`, `Frame Time:`), see [`write()`].
//!
//! The reader runs in stages, one file each: the header's token stream
//! (`cursor`), the `HIERARCHY` section (`hierarchy`: one method per keyword),
//! the `MOTION` header and frame values (`frames`), and the conversion to a
//! [`Motion`] (`build`). The writer's stages (channel layouts, hierarchy text,
//! frame lines) are in `write`.

use std::io::Write;
use std::path::Path;

use crate::error::MotionError;
use crate::motion::Motion;
use crate::skeleton::{Axis, Channel, Skeleton};
use crate::text::{self, Errors};
use crate::units::Unit;

mod base;
mod build;
mod cursor;
mod frames;
mod hierarchy;
mod translation;
mod write;

use cursor::Cursor;

/// Read a BVH file from memory. `label` names the file in errors; `unit` is the
/// file's length unit ([`Unit::Auto`] to guess it from the body size).
///
/// Stages: the hierarchy (joints, offsets, channels), the `MOTION` header, the
/// frame values, then the [`Motion`] (offsets, unit, poses).
pub fn parse(bytes: &[u8], label: impl AsRef<Path>, unit: Unit) -> Result<Motion, MotionError> {
    let errors = Errors::new(label.as_ref());
    let lines = text::lines(bytes);
    let mut cur = Cursor::new(&lines, &errors);
    let joints = hierarchy::read(&mut cur, &errors)?;
    let header = frames::read_header(&mut cur, &errors)?;
    let values = frames::read_values(&lines, &header, &joints, &errors)?;
    build::motion(
        &joints,
        &values,
        frame_rate(header.frame_time),
        unit,
        &errors,
    )
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
/// * A joint with a translation track gets position channels on all three
///   axes holding its local translation per frame; its `OFFSET` is its rest
///   offset, unless the values would then read as relative ones (module
///   `translation`). A skeleton's static base is written above the root,
///   with its constant values in every frame, and the root's channels then
///   hold its translation and rotation in the base's frame.
/// * Angles in degrees, lengths in `unit`, 6 decimals: round trips keep world
///   joint positions to about 1e-6 m. Euler angles follow the previous frame's
///   branch, so curves have no 360-degree jumps.
pub fn write_in(motion: &Motion, unit: Unit, out: &mut impl Write) -> std::io::Result<()> {
    let unit = match unit {
        Unit::Auto => default_unit(motion.skeleton()),
        u => u,
    };
    let plan = write::Plan::new(motion, 1.0 / unit.metres().unwrap_or(1.0));
    out.write_all(plan.header().as_bytes())?;
    plan.frames(out)
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

/// The BVH name of a channel.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::ParseError;
    use crate::rotation;
    use glam::{DQuat, DVec3};

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
        assert!(!m.has_tracks());
        // Zeros (relative to the offset) are the offset too.
        let zeros = abs
            .replace("0 0 0 0 -40 0 0", "0 0 0 0 0 0 0")
            .replace("30 0 -40 0 90", "30 0 0 0 90");
        let z = parse(zeros.as_bytes(), "zeros.bvh", Unit::Centimetres).unwrap();
        assert_eq!(z.all_world_positions(), m.all_world_positions());
        // Varying: a translation track, used by forward kinematics.
        let moving = abs.replace("30 0 -40 0 90", "30 0 -41 0 90");
        let m = parse(moving.as_bytes(), "moving.bvh", Unit::Centimetres).unwrap();
        let track = m.track(1).unwrap();
        assert!((track[1] - DVec3::new(0.0, -0.41, 0.0)).length() < 1e-12);
        assert!((m.skeleton().joint(1).offset - DVec3::new(0.0, -0.4, 0.0)).length() < 1e-12);
        let root = m.world_transforms(1)[0];
        let leg = root.translation + root.rotation * DVec3::new(0.0, -0.41, 0.0);
        assert!((m.world_positions(1)[1] - leg).length() < 1e-12);
        // And comes back through the writer.
        let back = parse(&to_bytes(&m), "back.bvh", Unit::Auto).unwrap();
        assert_eq!(back.track(1).unwrap().len(), 2);
        for f in 0..2 {
            for (a, b) in m.world_positions(f).iter().zip(back.world_positions(f)) {
                assert!((*a - b).length() < 1e-8);
            }
        }
    }

    /// A static root (rotated and moved) above a travelling `Hips`, six
    /// channels on most joints, the exporters' layout of the issue.
    const STATIC_ROOT: &str = "HIERARCHY\nROOT Base\n{\n\tOFFSET 10 0 5\n\
        \tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
        \tJOINT Hips\n\t{\n\t\tOFFSET 0 90 0\n\
        \t\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
        \t\tJOINT Leg\n\t\t{\n\t\t\tOFFSET 0 -40 0\n\
        \t\t\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
        \t\t\tEnd Site\n\t\t\t{\n\t\t\t\tOFFSET 0 -40 0\n\t\t\t}\n\t\t}\n\
        \t\tJOINT Spine\n\t\t{\n\t\t\tOFFSET 0 10 0\n\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n\
        \t\t\tEnd Site\n\t\t\t{\n\t\t\t\tOFFSET 0 50 0\n\t\t\t}\n\t\t}\n\t}\n}\n\
        MOTION\nFrames: 3\nFrame Time: 0.0333333\n\
        1 0 2 0 90 0 0 90 0 0 0 0 0 -40 0 10 0 0 0 0 0\n\
        1 0 2 0 90 0 5 91 1 0 10 0 0 -40 0 20 0 0 0 0 5\n\
        1 0 2 0 90 0 10 92 2 5 10 0 0 -40 0 30 0 0 0 0 10\n";

    /// World positions (metres) of Base, Hips, Leg, Spine at frame `f` of
    /// [`STATIC_ROOT`], by forward kinematics written out here.
    fn static_root_expected(f: usize) -> [DVec3; 4] {
        let zxy = [Axis::Z, Axis::X, Axis::Y];
        let r = |deg: [f64; 3]| rotation::from_channels(&zxy, &deg.map(f64::to_radians));
        let hips = [[0.0, 90.0, 0.0], [5.0, 91.0, 1.0], [10.0, 92.0, 2.0]];
        let hips_rot = [[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [5.0, 10.0, 0.0]];
        let base_p = DVec3::new(11.0, 0.0, 7.0);
        let base_q = r([0.0, 90.0, 0.0]);
        let hips_p = base_p + base_q * DVec3::from_array(hips[f]);
        let hips_q = base_q * r(hips_rot[f]);
        let leg = hips_p + hips_q * DVec3::new(0.0, -40.0, 0.0);
        let spine = hips_p + hips_q * DVec3::new(0.0, 10.0, 0.0);
        [base_p, hips_p, leg, spine].map(|p| p * 0.01)
    }

    #[test]
    fn static_root_above_travelling_hips_is_folded() {
        let m = parse(STATIC_ROOT.as_bytes(), "static.bvh", Unit::Centimetres).unwrap();
        let names: Vec<&str> = m
            .skeleton()
            .joints()
            .iter()
            .map(|j| j.name.as_str())
            .collect();
        assert_eq!(names, ["Hips", "Leg", "Spine"]);
        assert_eq!(m.skeleton().base().len(), 1);
        assert_eq!(m.skeleton().base()[0].name, "Base");
        assert!(!m.has_tracks(), "Leg's constant channels are its offset");
        let check = |m: &Motion| {
            for f in 0..3 {
                let want = static_root_expected(f);
                let base = m.skeleton().base_transforms()[0].translation;
                assert!((base - want[0]).length() < 1e-9, "frame {f}");
                for (got, want) in m.world_positions(f).iter().zip(&want[1..]) {
                    assert!((*got - *want).length() < 1e-9, "frame {f}: {got} {want}");
                }
                assert!((m.root_translation()[f] - want[1]).length() < 1e-9);
            }
        };
        check(&m);
        // Written back with the static root above the Hips, and read the same.
        let text = String::from_utf8(to_bytes(&m)).unwrap();
        assert!(text.starts_with("HIERARCHY\nROOT Base\n"), "{text}");
        assert!(text.contains("\tJOINT Hips\n"), "{text}");
        let back = parse(text.as_bytes(), "back.bvh", Unit::Auto).unwrap();
        // (The root's OFFSET is written 0 on axes with position channels.)
        let (a, b) = (&back.skeleton().base()[0], &m.skeleton().base()[0]);
        assert_eq!((&a.name, &a.channels), (&b.name, &b.channels));
        assert!((a.translation - b.translation).length() < 1e-9);
        assert!(rotation::angle_between(a.rotation, b.rotation) < 1e-9);
        check(&back);
        // The unit is guessed from the body, not from how far the static root is.
        let far = STATIC_ROOT
            .replace("OFFSET 0 90 0", "OFFSET 600 90 0")
            .replace(" 0 90 0 0 0 0 0 -40", " 600 90 0 0 0 0 0 -40")
            .replace(" 5 91 1 0 10 0", " 605 91 1 0 10 0")
            .replace(" 10 92 2 5 10 0", " 610 92 2 5 10 0");
        let m = parse(far.as_bytes(), "far.bvh", Unit::Auto).unwrap();
        assert_eq!(m.skeleton().source_unit_m(), 0.01);
        assert_eq!(m.skeleton().base().len(), 1);
    }

    #[test]
    fn malformed_translation_channels_name_the_line() {
        // Frames start on line 33: a NaN in Hips' Yposition of frame 2.
        let nan = STATIC_ROOT.replace("5 91 1 0 10 0", "5 nan 1 0 10 0");
        let e = err(&nan);
        assert_eq!(e.line, Some(34), "{e}");
        assert!(e.message.contains("not a finite number"), "{e}");
        // A position value missing from frame 3.
        let short = STATIC_ROOT.replace("10 92 2 5 10 0", "10 92 5 10 0");
        let e = err(&short);
        assert_eq!(e.line, Some(35), "{e}");
        assert!(
            e.message.contains("20 values") && e.message.contains("21 channels"),
            "{e}"
        );
        // A CHANNELS count that does not match its names.
        let count = STATIC_ROOT.replacen("CHANNELS 6 Xposition", "CHANNELS 7 Xposition", 2);
        let e = err(&count);
        assert_eq!(e.line, Some(6), "{e}");
        assert!(
            e.message.contains("JOINT") && e.message.contains("channel"),
            "{e}"
        );
    }
}
