//! Property tests of the file formats: random skeletons and motions survive a
//! BVH round trip, and no input bytes make a parser panic.

use std::sync::Arc;

use motion::glam::{DQuat, DVec3};
use motion::{Axis, Channel, Joint, Motion, Skeleton, Unit, bvh, rotation};
use proptest::prelude::*;

const AXES: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

/// A random joint layout: parent index, offset, channels.
#[derive(Debug, Clone)]
struct JointSpec {
    parent_pick: usize,
    offset: [f64; 3],
    rot_axes: Vec<usize>,
    root_pos_axes: Vec<usize>,
    end_site: Option<[f64; 3]>,
}

fn joint_spec() -> impl Strategy<Value = JointSpec> {
    (
        any::<usize>(),
        prop::array::uniform3(-50.0f64..50.0),
        prop::sample::subsequence(vec![0usize, 1, 2], 0..=3).prop_shuffle(),
        prop::sample::subsequence(vec![0usize, 1, 2], 0..=3).prop_shuffle(),
        prop::option::of(prop::array::uniform3(-20.0f64..20.0)),
    )
        .prop_map(
            |(parent_pick, offset, rot_axes, root_pos_axes, end_site)| JointSpec {
                parent_pick,
                offset,
                rot_axes,
                root_pos_axes,
                end_site,
            },
        )
}

#[derive(Debug, Clone)]
struct Case {
    joints: Vec<JointSpec>,
    unit: Unit,
    frames: usize,
    /// Angles in radians per frame per joint per channel (enough of them).
    angles: Vec<f64>,
    root: Vec<[f64; 3]>,
    /// Free rotations for the "not representable" variant.
    free: Vec<[f64; 4]>,
    fps: f64,
}

fn case() -> impl Strategy<Value = Case> {
    (
        prop::collection::vec(joint_spec(), 1..10),
        prop::sample::select(vec![
            Unit::Metres,
            Unit::Centimetres,
            Unit::Inches,
            Unit::CmuAsf,
            Unit::Millimetres,
        ]),
        1usize..5,
        prop::sample::select(vec![24.0, 30.0, 60.0, 120.0, 29.97]),
    )
        .prop_flat_map(|(joints, unit, frames, fps)| {
            let n = joints.len();
            (
                Just(joints),
                Just(unit),
                Just(frames),
                prop::collection::vec(-4.0f64..4.0, frames * n * 3),
                prop::collection::vec(prop::array::uniform3(-300.0f64..300.0), frames),
                prop::collection::vec(prop::array::uniform4(-1.0f64..1.0), frames * n),
                Just(fps),
            )
        })
        .prop_map(|(joints, unit, frames, angles, root, free, fps)| Case {
            joints,
            unit,
            frames,
            angles,
            root,
            free,
            fps,
        })
}

fn build(case: &Case, free_rotations: bool) -> Motion {
    let scale = case.unit.metres().unwrap();
    let joints: Vec<Joint> = case
        .joints
        .iter()
        .enumerate()
        .map(|(i, spec)| {
            let mut channels = Vec::new();
            if i == 0 {
                channels.extend(
                    spec.root_pos_axes
                        .iter()
                        .map(|&a| Channel::Position(AXES[a])),
                );
            }
            channels.extend(spec.rot_axes.iter().map(|&a| Channel::Rotation(AXES[a])));
            Joint {
                name: format!("joint {i}"),
                parent: if i == 0 {
                    None
                } else {
                    Some(spec.parent_pick % i)
                },
                offset: DVec3::from_array(spec.offset) * scale,
                channels,
                end_site: spec.end_site.map(|e| DVec3::from_array(e) * scale),
                limits: None,
            }
        })
        .collect();
    let n = joints.len();
    let skeleton = Arc::new(Skeleton::new(joints, scale).unwrap());
    let mut rotations = Vec::with_capacity(case.frames * n);
    for f in 0..case.frames {
        for (j, spec) in case.joints.iter().enumerate() {
            let q = if free_rotations {
                let [x, y, z, w] = case.free[f * n + j];
                let q = DQuat::from_xyzw(x, y, z, w);
                if q.length() < 1e-3 {
                    DQuat::IDENTITY
                } else {
                    q.normalize()
                }
            } else {
                let axes: Vec<Axis> = spec.rot_axes.iter().map(|&a| AXES[a]).collect();
                let base = (f * n + j) * 3;
                rotation::from_channels(&axes, &case.angles[base..base + axes.len()])
            };
            rotations.push(q);
        }
    }
    // The root may only move along axes it has position channels for (else it
    // stays at its offset), unless the rotations are free anyway.
    let root_spec = &case.joints[0];
    let root = (0..case.frames)
        .map(|f| {
            let mut p = DVec3::from_array(root_spec.offset);
            for &a in &root_spec.root_pos_axes {
                p[a] = case.root[f][a];
            }
            if free_rotations {
                p = DVec3::from_array(case.root[f]);
            }
            p * scale
        })
        .collect();
    Motion::new(skeleton, case.fps, root, rotations).unwrap()
}

fn max_position_error(a: &Motion, b: &Motion) -> f64 {
    assert_eq!(a.frames(), b.frames());
    assert_eq!(a.joints(), b.joints());
    let mut worst: f64 = 0.0;
    for f in 0..a.frames() {
        let pa = a.world_positions(f);
        let pb = b.world_positions(f);
        for (j, p) in pa.iter().enumerate() {
            let k = b.skeleton().find(&a.skeleton().joint(j).name).unwrap();
            worst = worst.max((*p - pb[k]).length());
        }
    }
    worst
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn bvh_round_trip_keeps_world_positions(case in case()) {
        for free in [false, true] {
            let m = build(&case, free);
            let text = bvh::to_bytes(&m);
            let back = bvh::parse(&text, "rt.bvh", case.unit).unwrap();
            prop_assert!((back.fps() - m.fps()).abs() < 1e-9 * m.fps());
            let err = max_position_error(&m, &back);
            prop_assert!(err < 1e-5, "free={free}: error {err} m\n{}", String::from_utf8_lossy(&text));
            if !free {
                // Every joint keeps its channels in their order; joints with one
                // or two rotation channels get the missing axes after them.
                for (j, joint) in m.skeleton().joints().iter().enumerate().skip(1) {
                    let k = back.skeleton().find(&joint.name).unwrap();
                    let written = &back.skeleton().joint(k).channels;
                    if joint.channels.is_empty() {
                        continue;
                    }
                    prop_assert_eq!(&written[..joint.channels.len()], &joint.channels[..], "joint {}", j);
                    let expected_len = if joint.channels.len() < 3 { 3 } else { joint.channels.len() };
                    prop_assert_eq!(written.len(), expected_len, "joint {}", j);
                }
            }
        }
    }

    #[test]
    fn bvh_never_panics_on_bytes(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        let _ = bvh::parse(&bytes, "fuzz.bvh", Unit::Auto);
    }

    #[test]
    fn bvh_never_panics_on_mutations(
        case in case(),
        edits in prop::collection::vec((any::<usize>(), any::<u8>(), 0u8..4), 1..6),
    ) {
        let mut text = bvh::to_bytes(&build(&case, false));
        mutate(&mut text, &edits);
        let _ = bvh::parse(&text, "fuzz.bvh", Unit::Auto);
    }
}

// --- Translation tracks: animated position channels on any joint ---

/// Random translation tracks for a [`Case`]: which joints get one, where
/// their values centre (the offset, zero or elsewhere: the reader's rule and
/// the writer's choice of `OFFSET` both get exercised) and the motion.
#[derive(Debug, Clone)]
struct TrackSpec {
    tracked: Vec<bool>,
    centre: Vec<u8>,
    elsewhere: Vec<[f64; 3]>,
    deltas: Vec<[f64; 3]>,
}

fn track_spec(joints: usize, frames: usize) -> impl Strategy<Value = TrackSpec> {
    (
        prop::collection::vec(any::<bool>(), joints),
        prop::collection::vec(0u8..3, joints),
        prop::collection::vec(prop::array::uniform3(-80.0f64..80.0), joints),
        prop::collection::vec(prop::array::uniform3(-30.0f64..30.0), joints * frames),
    )
        .prop_map(|(tracked, centre, elsewhere, deltas)| TrackSpec {
            tracked,
            centre,
            elsewhere,
            deltas,
        })
}

fn case_with_tracks() -> impl Strategy<Value = (Case, TrackSpec)> {
    case().prop_flat_map(|c| {
        let (n, frames) = (c.joints.len(), c.frames);
        (Just(c), track_spec(n, frames))
    })
}

/// `motion` with the tracks of `spec` on its non-root joints (file units
/// scaled by the skeleton's unit).
fn with_tracks(motion: Motion, spec: &TrackSpec) -> Motion {
    let scale = motion.skeleton().source_unit_m();
    let n = motion.joints();
    let tracks: Vec<Option<Vec<DVec3>>> = (0..n)
        .map(|j| {
            if j == 0 || !spec.tracked[j] {
                return None;
            }
            let offset = motion.skeleton().joint(j).offset;
            let centre = match spec.centre[j] {
                0 => offset,
                1 => DVec3::ZERO,
                _ => DVec3::from_array(spec.elsewhere[j]) * scale,
            };
            Some(
                (0..motion.frames())
                    .map(|f| centre + DVec3::from_array(spec.deltas[f * n + j]) * scale)
                    .collect(),
            )
        })
        .collect();
    motion.with_tracks(tracks).unwrap()
}

/// World position of every joint by name at frame `f`, the base's too.
fn named_positions(m: &Motion, f: usize) -> std::collections::HashMap<String, DVec3> {
    let s = m.skeleton();
    let mut out: std::collections::HashMap<String, DVec3> = s
        .base()
        .iter()
        .zip(s.base_transforms())
        .map(|(b, t)| (b.name.clone(), t.translation))
        .collect();
    for (j, p) in m.world_positions(f).into_iter().enumerate() {
        out.insert(s.joint(j).name.clone(), p);
    }
    out
}

/// Largest world distance between joints of the same name (every joint of
/// `a` must be in `b`, as a joint or a base joint).
fn named_position_error(a: &Motion, b: &Motion) -> f64 {
    assert_eq!(a.frames(), b.frames());
    let mut worst: f64 = 0.0;
    for f in 0..a.frames() {
        let (pa, pb) = (named_positions(a, f), named_positions(b, f));
        assert_eq!(pa.len(), pb.len(), "same joints, base included");
        for (name, p) in &pa {
            worst = worst.max((*p - pb[name]).length());
        }
    }
    worst
}

/// A [`Case`] whose root stands still with one child, the travelling joint,
/// which gets a translation track; everything else hangs below that child.
fn static_root(case: &Case, spec: &TrackSpec) -> Motion {
    let mut case = case.clone();
    let n = case.joints.len();
    for (i, j) in case.joints.iter_mut().enumerate().skip(2) {
        j.parent_pick = j.parent_pick % (i - 1) + 1; // parent in 1..i
    }
    if n > 1 {
        case.joints[1].parent_pick = 0;
    }
    let m = build(&case, true);
    // The root: its first frame, held.
    let (p0, q0) = (m.root_translation()[0], m.rotation(0, 0));
    let root = vec![p0; m.frames()];
    let mut rotations = m.rotations().to_vec();
    for f in 0..m.frames() {
        rotations[f * n] = q0;
    }
    let held = m.with_frames(m.fps(), root, rotations).unwrap();
    let mut spec = spec.clone();
    spec.tracked = (0..n).map(|j| j == 1).collect();
    with_tracks(held, &spec)
}

/// Columns of the position channels of non-root joints in a written file.
fn joint_position_columns(text: &str) -> Vec<usize> {
    let mut columns = Vec::new();
    let mut col = 0;
    for (k, line) in text.lines().filter(|l| l.contains("CHANNELS")).enumerate() {
        for name in line.split_whitespace().skip(2) {
            if k > 0 && name.ends_with("position") {
                columns.push(col);
            }
            col += 1;
        }
    }
    columns
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn bvh_round_trip_keeps_translation_tracks((case, spec) in case_with_tracks()) {
        let m = with_tracks(build(&case, false), &spec);
        let text = bvh::to_bytes(&m);
        let back = bvh::parse(&text, "tracks.bvh", case.unit).unwrap();
        let err = named_position_error(&m, &back);
        prop_assert!(err < 1e-5, "error {err} m\n{}", String::from_utf8_lossy(&text));
        // Varying tracks stay tracks (or become the root if a static root above was folded).
        // A joint that neither rotates nor travels may itself be part of a folded
        // static chain above the travelling joint: then it is a base joint.
        if m.frames() > 1 {
            for j in 1..m.joints() {
                let name = &m.skeleton().joint(j).name;
                match back.skeleton().find(name) {
                    Some(k) => prop_assert!(
                        m.track(j).is_none() || k == 0 || back.track(k).is_some(),
                        "{}",
                        name
                    ),
                    None => prop_assert!(
                        m.track(j).is_none()
                            && back.skeleton().base().iter().any(|b| &b.name == name),
                        "{} is neither a joint nor a folded base joint",
                        name
                    ),
                }
            }
        }
    }

    #[test]
    fn bvh_static_root_above_a_travelling_joint_is_folded((case, spec) in case_with_tracks()) {
        prop_assume!(case.joints.len() >= 2);
        let m = static_root(&case, &spec);
        let text = bvh::to_bytes(&m);
        let back = bvh::parse(&text, "static.bvh", case.unit).unwrap();
        let err = named_position_error(&m, &back);
        prop_assert!(err < 1e-5, "error {err} m\n{}", String::from_utf8_lossy(&text));
        if m.frames() > 1 {
            // The travelling joint is the root, the still one the base.
            prop_assert_eq!(back.joints(), m.joints() - 1);
            prop_assert_eq!(&back.skeleton().joint(0).name, &m.skeleton().joint(1).name);
            prop_assert_eq!(&back.skeleton().base()[0].name, &m.skeleton().joint(0).name);
            // And it stays so through a second round trip.
            let again = bvh::parse(&bvh::to_bytes(&back), "again.bvh", case.unit).unwrap();
            prop_assert!(named_position_error(&back, &again) < 1e-5);
            prop_assert_eq!(again.skeleton().base().len(), 1);
        }
    }

    #[test]
    fn bvh_malformed_translation_values_name_the_line(
        (case, spec) in case_with_tracks(),
        pick in any::<usize>(),
        frame_pick in any::<usize>(),
        kind in 0u8..3,
    ) {
        let m = with_tracks(build(&case, false), &spec);
        let text = String::from_utf8(bvh::to_bytes(&m)).unwrap();
        let columns = joint_position_columns(&text);
        prop_assume!(!columns.is_empty());
        let lines: Vec<&str> = text.lines().collect();
        let first_frame = lines.iter().position(|l| l.starts_with("Frame Time")).unwrap() + 1;
        let f = frame_pick % m.frames();
        let col = columns[pick % columns.len()];
        let mut tokens: Vec<String> = lines[first_frame + f].split_whitespace().map(String::from).collect();
        let expect = match kind {
            0 => { tokens[col] = "nan".into(); "not a finite number" }
            1 => { tokens.remove(col); "values" }
            _ => { tokens.insert(col, "1.5".into()); "values" }
        };
        let mut edited: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
        edited[first_frame + f] = tokens.join(" ");
        let bad = edited.join("\n") + "\n";
        match bvh::parse(bad.as_bytes(), "bad.bvh", case.unit) {
            Err(motion::MotionError::Parse(e)) => {
                prop_assert_eq!(e.line, Some(first_frame + f + 1), "{}", e);
                prop_assert!(e.message.contains(expect), "{}", e);
                prop_assert!(e.to_string().starts_with("bad.bvh:"), "{}", e);
            }
            other => prop_assert!(false, "expected a parse error, got {:?}", other.map(|m| m.frames())),
        }
    }
}

// --- NPZ in: the archives the product writes read back as clips ---

proptest! {
    #![proptest_config(ProptestConfig { cases: 100, ..ProptestConfig::default() })]

    #[test]
    fn npz_clips_read_back((case, spec) in case_with_tracks(), folded in any::<bool>()) {
        let m = if folded && case.joints.len() >= 2 {
            // Through BVH, so the static root is folded into a base.
            let s = static_root(&case, &spec);
            bvh::parse(&bvh::to_bytes(&s), "s.bvh", case.unit).unwrap()
        } else {
            with_tracks(build(&case, true), &spec)
        };
        // Lossless: the same clip, bit for bit.
        let exact = motion::npz::exact_to_bytes(&m, &[]).unwrap();
        let back = motion::npz::read_motion(&exact, "exact.npz").unwrap();
        prop_assert_eq!(&back, &m);
        // float32: the same joints and motion to float precision.
        let f32s = motion::npz::motion_to_bytes(&m, &[]).unwrap();
        let back = motion::npz::read_motion(&f32s, "f32.npz").unwrap();
        prop_assert_eq!(back.joints(), m.joints());
        prop_assert_eq!(back.fps(), m.fps());
        prop_assert_eq!(back.has_tracks(), m.has_tracks());
        for (a, b) in back.skeleton().joints().iter().zip(m.skeleton().joints()) {
            prop_assert_eq!(a.end_site.is_some(), b.end_site.is_some());
            if let (Some(x), Some(y)) = (a.end_site, b.end_site) {
                prop_assert!((x - y).length() < 1e-5);
            }
        }
        let err = max_position_error(&m, &back);
        prop_assert!(err < 1e-4, "error {err} m");
    }

    #[test]
    fn npz_clip_reader_never_panics(
        (case, spec) in case_with_tracks(),
        edits in prop::collection::vec((any::<usize>(), any::<u8>(), 0u8..4), 1..4),
        which in 0u8..2,
    ) {
        let m = with_tracks(build(&case, false), &spec);
        let mut bytes = if which == 0 {
            motion::npz::exact_to_bytes(&m, &[]).unwrap()
        } else {
            motion::npz::motion_to_bytes(&m, &[]).unwrap()
        };
        mutate(&mut bytes, &edits);
        let _ = motion::npz::read_motion(&bytes, "fuzz.npz");
    }
}

#[test]
fn npz_clips_that_cannot_be_read_are_named() {
    use motion::npz::{NpzWriter, read_motion};
    let walk = motion::load(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/data/16_11_walk_veer_left.bvh"),
        &Default::default(),
    )
    .unwrap();
    let err = |bytes: &[u8]| read_motion(bytes, "in/clip.npz").unwrap_err().to_string();
    let e = err(b"not a zip");
    assert!(
        e.starts_with("in/clip.npz: not a readable NPZ archive"),
        "{e}"
    );
    // An archive of other arrays.
    let other = NpzWriter::new(std::io::Cursor::new(Vec::new()))
        .array_f32("x", &[1], &[1.0])
        .unwrap()
        .finish()
        .unwrap()
        .into_inner();
    let e = err(&other);
    assert!(
        e.contains("in/clip.npz") && e.contains("no array `rotations`"),
        "{e}"
    );
    // A non-finite root position, a wrong shape.
    let arrays = motion::npz::read(&motion::npz::motion_to_bytes(&walk, &[]).unwrap()).unwrap();
    let rebuilt = |change: &dyn Fn(&mut motion::npz::NpyArray)| {
        let mut w = NpzWriter::new(std::io::Cursor::new(Vec::new()));
        for a in &arrays {
            let mut a = a.clone();
            change(&mut a);
            w = w.array(&a).unwrap();
        }
        w.finish().unwrap().into_inner()
    };
    let nan = rebuilt(&|a| {
        if a.name == "root_translation" {
            a.data[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
        }
    });
    let e = err(&nan);
    assert!(
        e.contains("in/clip.npz") && e.contains("frame 1: root position is not finite"),
        "{e}"
    );
    let shape = rebuilt(&|a| {
        if a.name == "offsets" {
            a.shape = vec![a.shape[0] * 3];
        }
    });
    let e = err(&shape);
    assert!(e.contains("array `offsets` has shape"), "{e}");
    // Extras such as a mask do not get in the way.
    let mask = motion::npz::NpyArray::bool(
        "mask",
        &[walk.frames(), walk.joints()],
        &vec![true; walk.frames() * walk.joints()],
    )
    .unwrap();
    let with_mask = motion::npz::motion_to_bytes(&walk, &[mask]).unwrap();
    assert_eq!(
        read_motion(&with_mask, "m.npz").unwrap().frames(),
        walk.frames()
    );
}

/// Apply byte edits: replace, delete, insert or truncate at a position.
fn mutate(text: &mut Vec<u8>, edits: &[(usize, u8, u8)]) {
    for &(pos, byte, kind) in edits {
        if text.is_empty() {
            text.push(byte);
            continue;
        }
        let at = pos % text.len();
        match kind {
            0 => text[at] = byte,
            1 => {
                text.remove(at);
            }
            2 => text.insert(at, byte),
            _ => text.truncate(at),
        }
    }
}

#[test]
fn bvh_guesses_units_from_body_size() {
    // A 1.8 m tall two-bone body written in mm, cm, in and m reads back the same.
    let joint = |name: &str, parent, y: f64| Joint {
        name: name.into(),
        parent,
        offset: DVec3::new(0.0, y, 0.0),
        channels: vec![],
        end_site: None,
        limits: None,
    };
    let mut top = joint("head", Some(1), 0.8);
    top.end_site = Some(DVec3::new(0.0, 0.1, 0.0));
    let joints = vec![joint("hips", None, 0.0), joint("spine", Some(0), 0.0), top];
    for unit in [
        Unit::Millimetres,
        Unit::Centimetres,
        Unit::Inches,
        Unit::Metres,
    ] {
        let mut js = joints.clone();
        js[0].end_site = None;
        js[1].end_site = Some(DVec3::new(0.0, -0.9, 0.0));
        let s = Arc::new(Skeleton::new(js, unit.metres().unwrap()).unwrap());
        let m = Motion::new(
            s,
            30.0,
            vec![DVec3::new(0.0, 0.9, 0.0)],
            vec![DQuat::IDENTITY; 3],
        )
        .unwrap();
        let back = bvh::parse(&bvh::to_bytes(&m), "u.bvh", Unit::Auto).unwrap();
        assert_eq!(back.skeleton().source_unit_m(), unit.metres().unwrap());
        assert!(max_position_error(&m, &back) < 1e-6);
    }
}

const ASF: &str = ":version 1.10\n:name t\n:units\n  mass 1.0\n  length 0.45\n  angle deg\n:documentation\n  x\n\
:root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n\
:bonedata\n  begin\n     id 1\n     name lfemur\n     direction 0.34 -0.94 0\n     length 7.3\n     axis 0 0 20 XYZ\n     dof rx ry rz\n\
     limits (-160.0 20.0)\n            (-70.0 70.0)\n            (-inf inf)\n  end\n\
  begin\n     id 2\n     name ltibia\n     direction 0.34 -0.94 0\n     length 6.9\n     axis 0 0 20 XYZ\n     dof rx\n     limits (-10 170)\n  end\n\
  begin\n     id 3\n     name lowerback\n     direction 0 1 0\n     length 2\n     axis 0 0 0 XYZ\n     dof rx ry rz\n  end\n\
:hierarchy\n  begin\n    root lfemur lowerback\n    lfemur ltibia\n  end\n";

const AMC: &str = "# c\n:FULLY-SPECIFIED\n:DEGREES\n1\nroot 1 16 3 10 -20 170\nlfemur 1 2 3\nltibia 40\nlowerback 1 2 3\n\
2\nroot 1 16 3.5 10 -20 171\nlfemur 1 2 4\nltibia 41\n";

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn asf_amc_never_panic_on_mutations(
        edits in prop::collection::vec((any::<usize>(), any::<u8>(), 0u8..4), 1..6),
        which in 0u8..2,
    ) {
        let mut asf_text = ASF.as_bytes().to_vec();
        let mut amc_text = AMC.as_bytes().to_vec();
        if which == 0 {
            mutate(&mut asf_text, &edits);
        } else {
            mutate(&mut amc_text, &edits);
        }
        if let Ok(asf) = motion::asf::parse(&asf_text, "fuzz.asf") {
            let _ = motion::amc::parse(&amc_text, "fuzz.amc", &asf, 120.0);
        }
    }

    #[test]
    fn asf_amc_never_panic_on_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = motion::asf::parse(&bytes, "fuzz.asf");
        let asf = motion::asf::parse(ASF.as_bytes(), "t.asf").unwrap();
        let _ = motion::amc::parse(&bytes, "fuzz.amc", &asf, 120.0);
    }
}

#[test]
fn amc_to_bvh_round_trip_and_limits() {
    let asf = motion::asf::parse(ASF.as_bytes(), "t.asf").unwrap();
    let m = motion::amc::parse(AMC.as_bytes(), "t.amc", &asf, 120.0).unwrap();
    let back = bvh::parse(&bvh::to_bytes(&m), "t.bvh", Unit::Auto).unwrap();
    assert!(max_position_error(&m, &back) < 1e-6);
    // The knee's limits in radians with frame C = Rz(20 deg).
    let knee = asf.skeleton().find("ltibia").unwrap();
    let lim = asf.skeleton().joint(knee).limits.clone().unwrap();
    assert_eq!(
        lim.dofs,
        vec![(Axis::X, -10f64.to_radians(), 170f64.to_radians())]
    );
    // The knee value 40 degrees sits inside the limits once expressed in C.
    let local = m.rotation(0, knee);
    let in_frame = lim.frame.inverse() * local * lim.frame;
    let angle = rotation::to_channels(in_frame, &[Axis::X])[0];
    assert!((angle - 40f64.to_radians()).abs() < 1e-9);
}

/// Arrays of an NPZ archive by name.
fn npz_arrays(bytes: &[u8]) -> std::collections::HashMap<String, motion::npz::NpyArray> {
    motion::npz::read(bytes)
        .unwrap()
        .into_iter()
        .map(|a| (a.name.clone(), a))
        .collect()
}

#[test]
fn npz_holds_the_motion_and_extras() {
    let asf = motion::asf::parse(ASF.as_bytes(), "t.asf").unwrap();
    let m = motion::amc::parse(AMC.as_bytes(), "t.amc", &asf, 120.0).unwrap();
    let (t, j) = (m.frames(), m.joints());
    let mask: Vec<u8> = (0..t * j).map(|i| (i % 2) as u8).collect();
    let extra = motion::npz::NpyArray::u8("mask", &[t, j], &mask).unwrap();
    let bytes = motion::npz::motion_to_bytes(&m, &[extra]).unwrap();
    let a = npz_arrays(&bytes);
    assert_eq!(a["positions"].shape, vec![t, j, 3]);
    assert_eq!(a["rotations"].shape, vec![t, j, 4]);
    assert_eq!(a["root_translation"].shape, vec![t, 3]);
    assert_eq!(a["parents"].to_i32().unwrap(), vec![-1, 0, 1, 0]);
    assert_eq!(a["offsets"].shape, vec![j, 3]);
    assert_eq!(a["end_sites"].shape, vec![j, 3]);
    assert_eq!(
        a["joint_names"].to_strings().unwrap(),
        vec!["root", "lfemur", "ltibia", "lowerback"]
    );
    assert_eq!(a["fps"].to_f64().unwrap(), vec![120.0]);
    assert_eq!(a["mask"].to_u8().unwrap(), mask);
    let pos = a["positions"].to_f32().unwrap();
    let world = m.all_world_positions();
    for (k, p) in world.iter().enumerate() {
        for c in 0..3 {
            assert!((pos[k * 3 + c] as f64 - p[c]).abs() < 1e-6);
        }
    }
    let rot = a["rotations"].to_f32().unwrap();
    let q = m.rotation(1, 2);
    assert!((rot[(j + 2) * 4] as f64 - q.w).abs() < 1e-6);
    assert!((rot[(j + 2) * 4 + 1] as f64 - q.x).abs() < 1e-6);
}

/// `np.load` reads the archive (skipped with a note without python3 + numpy).
#[test]
fn numpy_reads_the_npz() {
    let has_numpy = std::process::Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_numpy {
        eprintln!("note: python3 with numpy not found, skipping the np.load check");
        return;
    }
    let asf = motion::asf::parse(ASF.as_bytes(), "t.asf").unwrap();
    let m = motion::amc::parse(AMC.as_bytes(), "t.amc", &asf, 120.0).unwrap();
    let path = std::env::temp_dir().join(format!("motion-npz-{}.npz", std::process::id()));
    let mask = vec![true; m.frames() * m.joints()];
    let extra = motion::npz::NpyArray::bool("mask", &[m.frames(), m.joints()], &mask).unwrap();
    motion::npz::write_motion(&m, &[extra], &path).unwrap();
    let script = r#"
import sys, numpy as np
d = np.load(sys.argv[1])
p, r = d["positions"], d["rotations"]
assert p.dtype == np.float32 and p.shape == (2, 4, 3), (p.dtype, p.shape)
assert r.dtype == np.float32 and r.shape == (2, 4, 4)
assert np.allclose(np.linalg.norm(r, axis=-1), 1.0, atol=1e-6)
assert d["root_translation"].shape == (2, 3)
assert np.allclose(d["root_translation"], p[:, 0, :])
assert d["parents"].dtype == np.int32 and list(d["parents"]) == [-1, 0, 1, 0]
assert d["offsets"].shape == (4, 3)
assert d["joint_names"].dtype.kind == "U" and list(d["joint_names"]) == ["root", "lfemur", "ltibia", "lowerback"]
assert d["fps"].shape == () and float(d["fps"]) == 120.0
assert d["mask"].dtype == np.bool_ and d["mask"].shape == (2, 4) and d["mask"].all()
# Bone lengths from positions match the offsets.
par = d["parents"]
for j in range(1, 4):
    L = np.linalg.norm(p[:, j] - p[:, par[j]], axis=-1)
    assert np.allclose(L, np.linalg.norm(d["offsets"][j]), atol=1e-5), (j, L)
print("ok")
"#;
    let out = std::process::Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(&path)
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(
        out.status.success(),
        "np.load failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "ok");
}

/// The example clips committed with the project load through `io::load`.
#[test]
fn example_clips_load() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
    let asf = dir.join("HDM_bd.asf");
    let opts = motion::LoadOptions {
        skeleton: Some(asf.clone()),
        ..Default::default()
    };
    let kick = motion::load(dir.join("HDM_bd_kickLFront1Reps_001_120.amc"), &opts).unwrap();
    assert_eq!((kick.frames(), kick.joints(), kick.fps()), (161, 31, 120.0));
    let jog = motion::load(
        dir.join("HDM_bd_jogLeftCircle4StepsRstart_001_120.amc"),
        &opts,
    )
    .unwrap();
    assert_eq!(jog.frames(), 244);
    let walk = motion::load(dir.join("16_11_walk_veer_left.bvh"), &Default::default()).unwrap();
    assert_eq!((walk.frames(), walk.joints()), (534, 31));
    let rest = motion::load(&asf, &Default::default()).unwrap();
    assert_eq!((rest.frames(), rest.joints()), (1, 31));
    // Without the skeleton an AMC clip reads with the ASF beside it; alone
    // in a folder it is a clear error.
    let beside = motion::load(
        dir.join("HDM_bd_kickLFront1Reps_001_120.amc"),
        &Default::default(),
    )
    .unwrap();
    assert_eq!(beside.frames(), kick.frames());
    let lone = tempfile::tempdir().unwrap();
    let alone = lone.path().join("HDM_bd_kickLFront1Reps_001_120.amc");
    std::fs::copy(dir.join("HDM_bd_kickLFront1Reps_001_120.amc"), &alone).unwrap();
    let e = motion::load(&alone, &Default::default());
    assert!(e.is_err_and(|e| e.to_string().contains("ASF skeleton")));
    // save() writes both output formats.
    let out = std::env::temp_dir().join(format!("motion-save-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    motion::save(&kick, out.join("kick.bvh")).unwrap();
    motion::save(&kick, out.join("kick.npz")).unwrap();
    let back = motion::load(out.join("kick.bvh"), &Default::default()).unwrap();
    assert_eq!(back.frames(), 161);
    assert!(motion::save(&kick, out.join("kick.txt")).is_err());
    let _ = std::fs::remove_dir_all(&out);
}

// --- Random ASF/AMC: the joint conversion matches bone-based forward kinematics ---

#[derive(Debug, Clone)]
struct BoneSpec {
    parent_pick: usize,
    direction: [f64; 3],
    length: f64,
    axis: [f64; 3],
    axis_order: Vec<usize>,
    dofs: Vec<usize>,
}

fn bone_spec() -> impl Strategy<Value = BoneSpec> {
    (
        any::<usize>(),
        prop::array::uniform3(-1.0f64..1.0),
        0.5f64..10.0,
        prop::array::uniform3(-180.0f64..180.0),
        Just(vec![0usize, 1, 2]).prop_shuffle(),
        prop::sample::subsequence(vec![0usize, 1, 2], 0..=3).prop_shuffle(),
    )
        .prop_filter("direction must not vanish", |t| {
            DVec3::from_array(t.1).length() > 0.1
        })
        .prop_map(
            |(parent_pick, direction, length, axis, axis_order, dofs)| BoneSpec {
                parent_pick,
                direction,
                length,
                axis,
                axis_order,
                dofs,
            },
        )
}

const XYZ: [&str; 3] = ["x", "y", "z"];

fn asf_text(bones: &[BoneSpec], root_order: &[usize]) -> String {
    let mut s = String::from(":units\n  length 0.45\n  angle deg\n:root\n   order TX TY TZ");
    for &a in root_order {
        s.push_str(&format!(" R{}", XYZ[a].to_uppercase()));
    }
    s.push_str("\n   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n:bonedata\n");
    for (i, b) in bones.iter().enumerate() {
        let order: String = b
            .axis_order
            .iter()
            .map(|&a| XYZ[a].to_uppercase())
            .collect();
        s.push_str(&format!(
            "  begin\n    id {}\n    name b{i}\n    direction {} {} {}\n    length {}\n    axis {} {} {} {order}\n",
            i + 1,
            b.direction[0],
            b.direction[1],
            b.direction[2],
            b.length,
            b.axis[0],
            b.axis[1],
            b.axis[2]
        ));
        if !b.dofs.is_empty() {
            let dofs: Vec<String> = b.dofs.iter().map(|&a| format!("r{}", XYZ[a])).collect();
            s.push_str(&format!("    dof {}\n", dofs.join(" ")));
        }
        s.push_str("  end\n");
    }
    s.push_str(":hierarchy\n  begin\n");
    for (i, b) in bones.iter().enumerate() {
        let parent = if i == 0 {
            "root".to_string()
        } else {
            format!("b{}", b.parent_pick % i)
        };
        s.push_str(&format!("    {parent} b{i}\n"));
    }
    s.push_str("  end\n");
    s
}

/// Rotation about `axes` by `deg`, the first listed applied first (ASF).
fn applied_in_order(axes: &[usize], deg: &[f64]) -> DQuat {
    axes.iter().zip(deg).fold(DQuat::IDENTITY, |q, (&a, d)| {
        DQuat::from_axis_angle(AXES[a].unit(), d.to_radians()) * q
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 150, ..ProptestConfig::default() })]

    #[test]
    fn asf_joints_match_bone_kinematics(
        bones in prop::collection::vec(bone_spec(), 1..8),
        root_order in Just(vec![0usize, 1, 2]).prop_shuffle(),
        values in prop::collection::vec(-170.0f64..170.0, 2 * (6 + 8 * 3)),
    ) {
        let asf_src = asf_text(&bones, &root_order);
        let asf = motion::asf::parse(asf_src.as_bytes(), "r.asf").unwrap();
        let unit = 0.0254 / 0.45;
        // Two AMC frames of random values.
        let mut amc = String::from(":FULLY-SPECIFIED\n:DEGREES\n");
        let mut v = values.iter();
        let mut frames = Vec::new();
        for f in 0..2 {
            amc.push_str(&format!("{}\n", f + 1));
            let root: Vec<f64> = (0..6).map(|_| *v.next().unwrap()).collect();
            amc.push_str(&format!("root {} {} {} {} {} {}\n", root[0], root[1], root[2], root[3], root[4], root[5]));
            let mut per_bone = Vec::new();
            for (i, b) in bones.iter().enumerate() {
                let vals: Vec<f64> = b.dofs.iter().map(|_| *v.next().unwrap()).collect();
                if !vals.is_empty() {
                    let text: Vec<String> = vals.iter().map(|x| x.to_string()).collect();
                    amc.push_str(&format!("b{i} {}\n", text.join(" ")));
                }
                per_bone.push(vals);
            }
            frames.push((root, per_bone));
        }
        let m = motion::amc::parse(amc.as_bytes(), "r.amc", &asf, 120.0).unwrap();

        // Reference: bone-based FK as the CMU code states it. Global bone
        // rotation G_b = G_parent C M C^-1, bone end = start + length G_b dir.
        for (f, (root, per_bone)) in frames.iter().enumerate() {
            let root_pos = DVec3::new(root[0], root[1], root[2]) * unit;
            // The root's rotation values come in `order`, which is also the order applied.
            let root_rot = applied_in_order(&root_order, &root[3..6]);
            let mut global = vec![DQuat::IDENTITY; bones.len()];
            let mut start = vec![DVec3::ZERO; bones.len()];
            let mut end = vec![DVec3::ZERO; bones.len()];
            for (i, b) in bones.iter().enumerate() {
                let (parent_rot, parent_end) = if i == 0 {
                    (root_rot, root_pos)
                } else {
                    let p = b.parent_pick % i;
                    (global[p], end[p])
                };
                let c = applied_in_order(&b.axis_order, &b.axis_order.iter().map(|&a| b.axis[a]).collect::<Vec<_>>());
                let mm = applied_in_order(&b.dofs, &per_bone[i]);
                global[i] = parent_rot * c * mm * c.inverse();
                start[i] = parent_end;
                let dir = DVec3::from_array(b.direction).normalize();
                end[i] = start[i] + global[i] * (dir * b.length * unit);
            }
            let world = m.world_positions(f);
            prop_assert!((world[0] - root_pos).length() < 1e-9);
            for (i, s) in start.iter().enumerate() {
                let j = asf.joint_of_bone(i);
                prop_assert!((world[j] - *s).length() < 1e-9, "bone {} start", i);
            }
        }
        // And AMC -> BVH keeps every joint.
        let back = bvh::parse(&bvh::to_bytes(&m), "r.bvh", Unit::CmuAsf).unwrap();
        prop_assert!(max_position_error(&m, &back) < 1e-5);
    }

    #[test]
    fn npz_reader_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = motion::npz::read(&bytes);
    }
}
