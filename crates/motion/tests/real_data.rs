//! Real mocap from `../shared/data` (relative to the workspace root): every
//! file parses, converts to BVH and NPZ, and round-trips within 1 mm at every
//! joint and frame, and the physics of the result is right (units, floor,
//! upright bodies). Skips with a note when the folder is absent.

use std::path::{Path, PathBuf};

use motion::glam::DVec3;
use motion::{Motion, Unit, amc, asf, bvh, npz, resample, units};

fn data_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "note: {} is absent, skipping the real-data tests",
            dir.display()
        );
        None
    }
}

fn files(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case(ext)))
        .collect();
    out.sort();
    out
}

/// Largest distance between same-named joints over all frames, metres.
fn max_position_error(a: &Motion, b: &Motion) -> f64 {
    assert_eq!(a.frames(), b.frames(), "frame counts differ");
    assert_eq!(a.joints(), b.joints(), "joint counts differ");
    let map: Vec<usize> = a
        .skeleton()
        .joints()
        .iter()
        .map(|j| {
            b.skeleton()
                .find(&j.name)
                .expect("joint lost in round trip")
        })
        .collect();
    let pa = a.all_world_positions();
    let pb = b.all_world_positions();
    let n = a.joints();
    let mut worst: f64 = 0.0;
    for f in 0..a.frames() {
        for j in 0..n {
            worst = worst.max((pa[f * n + j] - pb[f * n + map[j]]).length());
        }
    }
    worst
}

/// Lowest and highest world y over the clip, metres.
fn y_range(m: &Motion) -> (f64, f64) {
    m.all_world_positions()
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.y), hi.max(p.y))
        })
}

#[test]
fn cmu_bvh_files_parse_and_round_trip() {
    let Some(dir) = data_dir() else { return };
    let mut paths = files(&dir.join("cmu"), "bvh");
    paths.extend(files(&dir.join("cmu_pairs"), "bvh"));
    assert_eq!(paths.len(), 9, "expected 3 CMU clips and 6 pair clips");
    for path in &paths {
        let m = bvh::read(path, Unit::Auto).unwrap_or_else(|e| panic!("{e}"));
        let name = path.display();
        // Unit guess: the CMU conversions keep the ASF unit (1/0.45 inch).
        assert_eq!(
            Unit::from_metres(m.skeleton().source_unit_m()),
            Some(Unit::CmuAsf),
            "{name}"
        );
        let size = units::rest_size(m.skeleton());
        assert!((1.3..1.9).contains(&size), "{name}: body size {size} m");
        assert!((m.fps() - 120.0).abs() < 0.01, "{name}: fps {}", m.fps());
        assert_eq!(m.joints(), 31, "{name}");
        // Feet reach the floor (y = 0 within 15 cm), the head is 1.3-1.9 m up.
        let (lo, hi) = y_range(&m);
        assert!(lo.abs() < 0.15, "{name}: lowest joint at {lo} m");
        assert!((1.3..1.9).contains(&hi), "{name}: highest joint at {hi} m");

        // BVH -> BVH within 1 mm (in fact ~1e-6 m).
        let text = bvh::to_bytes(&m);
        let back = bvh::parse(&text, format!("{name} (written)"), Unit::Auto)
            .unwrap_or_else(|e| panic!("{e}"));
        let err = max_position_error(&m, &back);
        assert!(err < 1e-5, "{name}: round trip error {err} m");
        for (a, b) in m.skeleton().joints().iter().zip(back.skeleton().joints()) {
            assert_eq!(
                a.channels, b.channels,
                "{name}: channel layout of {}",
                a.name
            );
        }
        check_npz(&m, &format!("{name}"));
        check_resample(&m, &format!("{name}"));
    }
}

#[test]
fn cmu_pairs_share_one_world_frame() {
    let Some(dir) = data_dir() else { return };
    let pairs = dir.join("cmu_pairs");
    let read = |f: &str| bvh::read(pairs.join(f), Unit::Auto).unwrap_or_else(|e| panic!("{e}"));
    // The capture notes: side-by-side walk, hips about 0.83 m apart throughout.
    let a = read("20_05_synchronized_walk_A.bvh");
    let b = read("20_05_synchronized_walk_B.bvh");
    assert_eq!(a.frames(), b.frames());
    for f in (0..a.frames()).step_by(10) {
        let d = a.root_translation()[f] - b.root_translation()[f];
        let horizontal = DVec3::new(d.x, 0.0, d.z).length();
        assert!(
            (0.6..1.1).contains(&horizontal),
            "frame {f}: hips {horizontal} m apart"
        );
    }
    // Handshake: hips from about 2 m apart to about 0.7 m, right wrists
    // closest (about 0.36 m) near frame 124.
    let a = read("18_01_walk_shake_hands_A.bvh");
    let b = read("18_01_walk_shake_hands_B.bvh");
    let hips = |f: usize| {
        let d = a.root_translation()[f] - b.root_translation()[f];
        DVec3::new(d.x, 0.0, d.z).length()
    };
    let closest_hips = (0..a.frames()).map(hips).fold(f64::INFINITY, f64::min);
    assert!(
        (1.7..2.3).contains(&hips(0)),
        "hips start {} m apart",
        hips(0)
    );
    assert!(
        (0.55..0.85).contains(&closest_hips),
        "hips closest {closest_hips} m"
    );
    let wrist = |m: &Motion| m.skeleton().find("RightHand").expect("RightHand");
    let (wa, wb) = (wrist(&a), wrist(&b));
    let (frame, gap) = (0..a.frames())
        .map(|f| {
            (
                f,
                (a.world_positions(f)[wa] - b.world_positions(f)[wb]).length(),
            )
        })
        .fold(
            (0, f64::INFINITY),
            |best, x| if x.1 < best.1 { x } else { best },
        );
    assert!((0.25..0.45).contains(&gap), "right hands closest {gap} m");
    assert!(
        (100..150).contains(&frame),
        "right hands closest at frame {frame}"
    );
}

/// The HDM05 physical facts a wrong ASF/AMC convention breaks (checked: the
/// other composition orders of `dof` or `axis` rotations fail them).
struct Facts {
    lowest: f64,
    left_toe_min: f64,
    right_toe_min: f64,
    head_below_root_frames: usize,
    right_hand_min: f64,
    right_hand_over_head: f64,
}

fn facts(m: &Motion) -> Facts {
    let s = m.skeleton();
    let id = |n: &str| s.find(n).unwrap_or_else(|| panic!("no joint {n}"));
    let (lt, rt, head, rh) = (id("ltoes"), id("rtoes"), id("head"), id("rhand"));
    let mut f = Facts {
        lowest: f64::INFINITY,
        left_toe_min: f64::INFINITY,
        right_toe_min: f64::INFINITY,
        head_below_root_frames: 0,
        right_hand_min: f64::INFINITY,
        right_hand_over_head: f64::NEG_INFINITY,
    };
    for t in 0..m.frames() {
        let p = m.world_positions(t);
        f.lowest = p.iter().fold(f.lowest, |lo, q| lo.min(q.y));
        f.left_toe_min = f.left_toe_min.min(p[lt].y);
        f.right_toe_min = f.right_toe_min.min(p[rt].y);
        if p[head].y < p[0].y {
            f.head_below_root_frames += 1;
        }
        f.right_hand_min = f.right_hand_min.min(p[rh].y);
        f.right_hand_over_head = f.right_hand_over_head.max(p[rh].y - p[head].y);
    }
    f
}

#[test]
fn hdm05_clips_parse_convert_and_round_trip() {
    let Some(dir) = data_dir() else { return };
    let dir = dir.join("hdm05");
    let started = std::time::Instant::now();
    let mut skeletons = std::collections::HashMap::new();
    for asf_path in files(&dir, "asf") {
        let asf = asf::read(&asf_path).unwrap_or_else(|e| panic!("{e}"));
        // Upright rest pose, arms out: height (toe to head tip) and arm span.
        let height = asf.skeleton().rest_height();
        let size = units::rest_size(asf.skeleton());
        assert!(
            (1.5..1.95).contains(&height),
            "{}: rest height {height} m",
            asf_path.display()
        );
        assert!(
            (1.5..2.2).contains(&size),
            "{}: rest size {size} m",
            asf_path.display()
        );
        let actor = asf_path
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .replace("HDM_", "");
        skeletons.insert(actor, asf);
    }
    assert_eq!(skeletons.len(), 5);
    let clips = files(&dir, "amc");
    // 210 clips + 5 skeletons = the 215 files of the folder (7 classes, see its README).
    assert_eq!(clips.len(), 210, "expected the 210 HDM05 clips");
    // The clips are independent: check them on every core (a panic in a
    // worker fails the test with its message).
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = clips.len().div_ceil(threads);
    let worst = std::thread::scope(|scope| {
        let workers: Vec<_> = clips
            .chunks(chunk)
            .map(|part| scope.spawn(|| check_hdm05_clips(part, &skeletons)))
            .collect();
        workers
            .into_iter()
            .map(|w| w.join().expect("a clip check failed (see above)"))
            .fold(0.0, f64::max)
    });
    eprintln!(
        "hdm05: {} clips parsed, checked and round-tripped in {:.2?} on {threads} threads \
         (worst error {worst:.2e} m)",
        clips.len(),
        started.elapsed()
    );
}

/// Parse, check the physics of, and round-trip `clips`; the worst AMC -> BVH error.
fn check_hdm05_clips(
    clips: &[PathBuf],
    skeletons: &std::collections::HashMap<String, asf::Asf>,
) -> f64 {
    let mut worst: f64 = 0.0;
    for path in clips {
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        let name = path.display();
        let actor = stem.split('_').nth(1).unwrap();
        let asf = &skeletons[actor];
        let m = amc::read(path, asf, 120.0).unwrap_or_else(|e| panic!("{e}"));
        assert!(m.frames() > 10, "{name}");

        let f = facts(&m);
        assert!(
            (-0.05..0.12).contains(&f.lowest),
            "{name}: lowest joint at {} m",
            f.lowest
        );
        let deposit = stem.contains("depositFloorR");
        if !deposit {
            // Upright (depositing on the floor, some takes stoop lower than the hips).
            assert_eq!(f.head_below_root_frames, 0, "{name}: head below the hips");
        }
        if !stem.contains("kick") && !deposit {
            // Both feet touch the floor at some point, equally (left/right symmetry).
            let d = (f.left_toe_min - f.right_toe_min).abs();
            assert!(
                d < 0.06,
                "{name}: toes reach {} / {} m",
                f.left_toe_min,
                f.right_toe_min
            );
        }
        if deposit {
            assert!(
                f.right_hand_min < 0.35,
                "{name}: right hand lowest {} m",
                f.right_hand_min
            );
        }
        if stem.contains("grabHighR") {
            assert!(
                f.right_hand_over_head > -0.05,
                "{name}: right hand {} m over head",
                f.right_hand_over_head
            );
        }

        // AMC -> BVH -> read: same world positions.
        let text = bvh::to_bytes(&m);
        let back = bvh::parse(&text, format!("{name} (as BVH)"), Unit::Auto)
            .unwrap_or_else(|e| panic!("{e}"));
        let err = max_position_error(&m, &back);
        worst = worst.max(err);
        assert!(err < 1e-5, "{name}: AMC -> BVH error {err} m");

        check_npz(&m, &format!("{name}"));
        check_resample(&m, &format!("{name}"));
    }
    worst
}

/// The NPZ of a clip reads back with the right shapes and positions (float32).
fn check_npz(m: &Motion, name: &str) {
    let bytes = npz::motion_to_bytes(m, &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
    let arrays = npz::read(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
    let get = |n: &str| {
        arrays
            .iter()
            .find(|a| a.name == n)
            .unwrap_or_else(|| panic!("{name}: no `{n}` in the NPZ"))
    };
    let (t, j) = (m.frames(), m.joints());
    assert_eq!(get("positions").shape, vec![t, j, 3], "{name}");
    assert_eq!(get("rotations").shape, vec![t, j, 4], "{name}");
    assert_eq!(get("root_translation").shape, vec![t, 3], "{name}");
    assert_eq!(get("parents").shape, vec![j], "{name}");
    assert_eq!(get("offsets").shape, vec![j, 3], "{name}");
    assert_eq!(get("fps").to_f64(), Some(vec![m.fps()]), "{name}");
    let names = get("joint_names").to_strings().unwrap();
    assert!(
        names
            .iter()
            .zip(m.skeleton().joints())
            .all(|(a, b)| *a == b.name)
    );
    let pos = get("positions").to_f32().unwrap();
    let world = m.all_world_positions();
    let worst = world
        .iter()
        .enumerate()
        .map(|(k, p)| {
            (DVec3::new(
                pos[3 * k] as f64,
                pos[3 * k + 1] as f64,
                pos[3 * k + 2] as f64,
            ) - *p)
                .length()
        })
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "{name}: NPZ positions off by {worst} m");
}

/// 120 Hz -> 30 Hz keeps the duration and samples the source frames exactly.
fn check_resample(m: &Motion, name: &str) {
    let r = resample::resample(m, 30.0).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(
        (r.duration_s() - m.duration_s()).abs() <= 0.5 / 30.0 + 1e-9,
        "{name}"
    );
    let k = r.frames() / 2;
    let src = (k as f64 * m.fps() / 30.0).round() as usize;
    if (k as f64 * m.fps() / 30.0 - src as f64).abs() < 1e-6 {
        let a = r.world_positions(k);
        let b = m.world_positions(src);
        let err = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (*x - *y).length())
            .fold(0.0, f64::max);
        assert!(err < 1e-6, "{name}: resampled frame {k} off by {err} m");
    }
}
