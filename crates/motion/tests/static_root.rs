//! The bundled example of the layout some exporters write (six channels on
//! every joint, a static `joint_Root` above a travelling `Hips`):
//! `examples/data/static_root_walk.bvh` is the CMU walk example rewritten in
//! that layout by [`static_root_layout`] (text edits only, no reader or writer
//! of ours involved), and it reads as the walk it came from.
//!
//! `MOTIONAUG_BLESS=1 cargo test -p motion --test static_root` rewrites the
//! example after a deliberate change of the rewriting.

use std::path::PathBuf;

use motion::glam::DVec3;
use motion::{Motion, Unit, bvh};

fn examples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/data")
}

/// Frames kept: every second one (60 Hz) of the first 360.
const KEPT: usize = 180;

/// The CMU BVH text `cmu` in the static-root layout: a `joint_Root` at the
/// origin with six constant channels above `Hips`, which becomes a `JOINT`
/// whose `OFFSET` is its first position and whose position channels hold its
/// (absolute) position; every other joint gets position channels repeating
/// its `OFFSET`; every second frame of the first `2 * KEPT`; LF line ends.
fn static_root_layout(cmu: &str) -> String {
    let lines: Vec<&str> = cmu.lines().map(|l| l.trim_end_matches('\r')).collect();
    let motion_at = lines.iter().position(|l| l.trim() == "MOTION").unwrap();
    let frames: Vec<Vec<&str>> = lines[motion_at + 3..]
        .iter()
        .filter(|l| !l.trim().is_empty())
        .step_by(2)
        .take(KEPT)
        .map(|l| l.split_whitespace().collect())
        .collect();
    let mut out = String::from(
        "HIERARCHY\nROOT joint_Root\n{\n\tOFFSET 0 0 0\n\
         \tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n",
    );
    // The OFFSET text of every joint after Hips, in file order.
    let mut offsets: Vec<String> = Vec::new();
    let mut in_end_site = false;
    for line in &lines[1..motion_at] {
        let tabs = line.len() - line.trim_start_matches('\t').len() + 1;
        let indent = "\t".repeat(tabs);
        let t = line.trim();
        let text = if t.starts_with("ROOT") {
            t.replacen("ROOT", "JOINT", 1)
        } else if t.starts_with("End Site") {
            in_end_site = true;
            t.to_string()
        } else if t == "}" {
            in_end_site = false;
            t.to_string()
        } else if t.starts_with("OFFSET") && !in_end_site {
            if offsets.is_empty() {
                // The first one is Hips' own: its first position.
                offsets.push(String::new());
                format!("OFFSET {} {} {}", frames[0][0], frames[0][1], frames[0][2])
            } else {
                let xyz = t.split_whitespace().skip(1).collect::<Vec<_>>().join(" ");
                offsets.push(xyz);
                t.to_string()
            }
        } else if let Some(rest) = t.strip_prefix("CHANNELS 3 ") {
            format!("CHANNELS 6 Xposition Yposition Zposition {rest}")
        } else {
            t.trim_end().to_string()
        };
        out.push_str(&indent);
        out.push_str(&text);
        out.push('\n');
    }
    out.push_str(&format!(
        "}}\nMOTION\nFrames: {}\nFrame Time: 0.016667\n",
        frames.len()
    ));
    for values in &frames {
        let mut row: Vec<&str> = vec!["0"; 6];
        row.extend(&values[..6]);
        for (k, offset) in offsets.iter().enumerate().skip(1) {
            row.extend(offset.split_whitespace());
            row.extend(&values[6 + 3 * (k - 1)..6 + 3 * k]);
        }
        out.push_str(&row.join(" "));
        out.push('\n');
    }
    out
}

fn walk() -> (String, Motion) {
    let cmu = std::fs::read_to_string(examples().join("16_11_walk_veer_left.bvh")).unwrap();
    let m = bvh::parse(cmu.as_bytes(), "walk.bvh", Unit::Auto).unwrap();
    (cmu, m)
}

#[test]
fn the_example_is_the_walk_in_the_static_root_layout() {
    let (cmu, _) = walk();
    let derived = static_root_layout(&cmu);
    let path = examples().join("static_root_walk.bvh");
    if std::env::var_os("MOTIONAUG_BLESS").is_some() {
        std::fs::write(&path, &derived).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap();
    assert!(
        committed == derived,
        "{} is not the rewritten walk",
        path.display()
    );
    // Every joint has six channels; Hips' positions vary, the others' do not.
    let channels: Vec<&str> = committed
        .lines()
        .filter(|l| l.contains("CHANNELS"))
        .collect();
    assert_eq!(channels.len(), 32);
    assert!(channels.iter().all(|l| l.contains("CHANNELS 6 ")));
}

#[test]
fn the_static_root_layout_reads_as_the_walk() {
    let (_, original) = walk();
    let path = examples().join("static_root_walk.bvh");
    let m = motion::load(&path, &Default::default()).unwrap();
    // Hips is the root, joint_Root the static base, nothing else is animated.
    assert_eq!(m.skeleton().joint(0).name, "Hips");
    assert_eq!(m.joints(), original.joints());
    assert_eq!(m.skeleton().base().len(), 1);
    assert_eq!(m.skeleton().base()[0].name, "joint_Root");
    assert!(!m.has_tracks());
    assert_eq!((m.frames(), m.fps()), (KEPT, 60.0));
    assert_eq!(
        m.skeleton().source_unit_m(),
        original.skeleton().source_unit_m()
    );
    // Every joint where the walk has it, frame for frame.
    let mut worst: f64 = 0.0;
    for f in 0..m.frames() {
        let (a, b) = (m.world_positions(f), original.world_positions(2 * f));
        for (p, q) in a.iter().zip(&b) {
            worst = worst.max((*p - *q).length());
        }
    }
    assert!(worst < 1e-9, "{worst} m");
    assert_eq!(m.skeleton().base_transforms()[0].translation, DVec3::ZERO);
    // Written back in the same layout, within a micrometre.
    let text = String::from_utf8(bvh::to_bytes(&m)).unwrap();
    assert!(text.starts_with("HIERARCHY\nROOT joint_Root\n"));
    let back = bvh::parse(text.as_bytes(), "back.bvh", Unit::Auto).unwrap();
    assert_eq!(back.skeleton().base()[0].name, "joint_Root");
    for f in 0..m.frames() {
        for (p, q) in m.world_positions(f).iter().zip(back.world_positions(f)) {
            assert!((*p - q).length() < 1e-6);
        }
    }
}
