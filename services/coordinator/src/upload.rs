//! Turning the files of an upload into validated clips.
//!
//! Zips are unpacked (with limits on entry count and unpacked size), every file is
//! parsed with the motion crate's readers (BVH, ASF/AMC, and the NPZ clips the
//! product writes, so outputs can be uploaded again), AMC motions are paired with an ASF of
//! the same upload, every clip is checked against the frame limit, and the two
//! clips of an interaction pair (`<stem>_A`, `<stem>_B`) must match in length. The first
//! problem rejects the whole upload with an error naming the file and line, so a
//! dataset is stored complete or not at all.

use std::io::Read;

use motionaug_protocol::ClipFormat;
use motionaug_protocol::clip::{self, LoadedSkeleton};

use crate::configuration::Limits;
use crate::error::ApiError;
use crate::upload_memory::{self, Reservation};

/// One uploaded file (or zip entry).
#[derive(Debug, Clone)]
pub struct UploadFile {
    /// Name for messages: `data.zip/HDM_bd.asf` for a zip entry.
    pub label: String,
    /// Base file name, e.g. `HDM_bd.asf`.
    pub name: String,
    pub bytes: Vec<u8>,
}

/// A clip ready to be stored.
#[derive(Debug, Clone)]
pub struct ParsedClip {
    pub name: String,
    pub format: ClipFormat,
    pub source_name: String,
    pub source: Vec<u8>,
    pub skeleton_name: Option<String>,
    pub skeleton: Option<Vec<u8>>,
    pub frames: usize,
    pub fps: f64,
    pub joints: usize,
    pub joint_names: Vec<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Bvh,
    Asf,
    Amc,
    Npz,
    Zip,
}

/// What a clip's name may be: it names the result files (`<clip>__00_noise_000.bvh`,
/// `work/correct/<clip>/report.json`), so it is one safe path segment.
pub const CLIP_NAME_RULE: &str = "a clip's name (the file name without its extension) may hold \
     letters, digits, `.`, `_` and `-`, must not start with `.` and has at most 100 characters";

/// Longest clip name.
const MAX_CLIP_NAME: usize = 100;

/// Whether `name` is a clip name by [`CLIP_NAME_RULE`].
pub fn is_clip_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_CLIP_NAME
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
}

/// A multipart file name is a bare file name: no folders (`/`, `\`), no `.`
/// or `..`, no control characters. Such names are refused, never cut down.
pub fn check_part_name(name: &str) -> Result<(), ApiError> {
    let bad = name.is_empty()
        || name.contains(['/', '\\'])
        || name == "."
        || name == ".."
        || name.chars().any(char::is_control)
        || name.len() > 255;
    if bad {
        return Err(ApiError::unprocessable(format!(
            "file name `{name}` is not a bare file name; send files without folders (no `/` or \
             `\\`, not `.` or `..`), e.g. `walk.bvh`"
        ))
        .with_file(name)
        .with_field("file"));
    }
    Ok(())
}

/// A zip entry's path stays inside the zip: relative, `/`-separated, no `..`.
fn check_entry_path(zip_label: &str, path: &str) -> Result<(), ApiError> {
    let segments: Vec<&str> = path.split('/').collect();
    let bad = path.starts_with('/')
        || path.contains('\\')
        || path.chars().any(char::is_control)
        || segments.iter().any(|s| *s == ".." || s.contains(':'));
    if bad {
        let label = format!("{zip_label}/{path}");
        return Err(ApiError::unprocessable(format!(
            "{zip_label}: entry `{path}` points outside the zip (absolute, `..` or `\\` in its \
             path); zip the files with relative paths"
        ))
        .with_file(label));
    }
    Ok(())
}

fn base_name(path: &str) -> &str {
    path.rsplit(['/', '\\']).next().unwrap_or(path)
}

fn stem(name: &str) -> &str {
    name.rsplit_once('.').map_or(name, |(s, _)| s)
}

fn kind_of(file: &UploadFile) -> Result<Kind, ApiError> {
    let ext = file
        .name
        .rsplit_once('.')
        .map(|(_, e)| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("bvh") => Ok(Kind::Bvh),
        Some("asf") => Ok(Kind::Asf),
        Some("amc") => Ok(Kind::Amc),
        Some("npz") => Ok(Kind::Npz),
        Some("zip") => Ok(Kind::Zip),
        _ => Err(ApiError::unprocessable(format!(
            "{}: unsupported file type; upload .bvh, .asf, .amc, .npz (a clip motionaug \
             wrote) or a .zip of them",
            file.label
        ))
        .with_file(&file.label)),
    }
}

/// Files a zip may hold that are not mocap (ignored instead of rejected).
fn is_ignorable_entry(path: &str) -> bool {
    let base = base_name(path);
    path.starts_with("__MACOSX/")
        || base.starts_with('.')
        || base.eq_ignore_ascii_case("readme.md")
        || base.eq_ignore_ascii_case("readme.txt")
}

/// Replaces every zip by its entries, enforcing the file-count and unpacked-size
/// limits while inflating: each entry is read in 64 KiB steps into memory
/// reserved from the upload budget, and refused as soon as the upload's
/// unpacked bytes pass the limit (a zip bomb costs at most the limit).
pub fn expand_zips(
    files: Vec<UploadFile>,
    limits: &Limits,
    reservation: &mut Reservation,
) -> Result<Vec<UploadFile>, ApiError> {
    let mut out = Vec::new();
    let mut unpacked: u64 = 0;
    let too_many = || {
        ApiError::too_large(format!(
            "too many files: at most {} per upload (zip entries count)",
            limits.max_files
        ))
    };
    for file in files {
        if kind_of(&file)? != Kind::Zip {
            out.push(file);
            if out.len() > limits.max_files {
                return Err(too_many());
            }
            continue;
        }
        let bad_zip = |e: zip::result::ZipError| {
            ApiError::unprocessable(format!("{}: not a readable zip archive: {e}", file.label))
                .with_file(&file.label)
        };
        let mut archive =
            zip::ZipArchive::new(std::io::Cursor::new(&file.bytes)).map_err(bad_zip)?;
        for i in 0..archive.len() {
            let mut entry = archive.by_index(i).map_err(bad_zip)?;
            if entry.is_dir() {
                continue;
            }
            let path = entry.name().map_err(bad_zip)?.to_string();
            check_entry_path(&file.label, &path)?;
            if is_ignorable_entry(&path) {
                continue;
            }
            let label = format!("{}/{}", file.label, path);
            let too_large = || {
                ApiError::too_large(format!(
                    "{label}: the upload unpacks to more than {} bytes",
                    limits.max_unzipped_bytes
                ))
                .with_file(&label)
            };
            let remaining = limits.max_unzipped_bytes.saturating_sub(unpacked);
            if entry.size() > remaining {
                // The declared size already passes the limit.
                return Err(too_large());
            }
            // Never more than the limit (plus the byte that shows it was passed).
            let cap = usize::try_from(remaining.saturating_add(1)).unwrap_or(usize::MAX);
            let mut bytes = Vec::new();
            let mut step = vec![0u8; 64 << 10];
            loop {
                let n = entry.read(&mut step).map_err(|e| {
                    ApiError::unprocessable(format!("{label}: cannot unpack: {e}"))
                        .with_file(&label)
                })?;
                if n == 0 {
                    break;
                }
                if (bytes.len() + n) as u64 > remaining {
                    return Err(too_large());
                }
                upload_memory::append(&mut bytes, &step[..n], cap, reservation)
                    .map_err(|e| e.with_file(&label))?;
            }
            unpacked += bytes.len() as u64;
            let entry_file = UploadFile {
                name: base_name(&path).to_string(),
                label,
                bytes,
            };
            if kind_of(&entry_file)? == Kind::Zip {
                return Err(ApiError::unprocessable(format!(
                    "{}: zips inside zips are not supported",
                    entry_file.label
                ))
                .with_file(&entry_file.label));
            }
            out.push(entry_file);
            if out.len() > limits.max_files {
                return Err(too_many());
            }
        }
    }
    Ok(out)
}

fn parse_failed(label: &str, e: motion::MotionError) -> ApiError {
    let (line, message) = match &e {
        motion::MotionError::Parse(p) => (p.line, e.to_string()),
        _ => (None, format!("{label}: {e}")),
    };
    ApiError::unprocessable(message)
        .with_file(label)
        .with_line(line)
}

/// The ASF an AMC pairs with: the only one, or the one whose name is the longest
/// prefix of the AMC's name (`HDM_bd.asf` for `HDM_bd_kick_001.amc`).
fn pick_skeleton<'a>(
    amc: &UploadFile,
    skeletons: &'a [(UploadFile, LoadedSkeleton)],
) -> Result<&'a (UploadFile, LoadedSkeleton), ApiError> {
    if skeletons.len() == 1 {
        return Ok(&skeletons[0]);
    }
    let amc_stem = stem(&amc.name).to_ascii_lowercase();
    let best = skeletons
        .iter()
        .filter(|(f, _)| amc_stem.starts_with(&stem(&f.name).to_ascii_lowercase()))
        .max_by_key(|(f, _)| stem(&f.name).len());
    best.ok_or_else(|| {
        let detail = if skeletons.is_empty() {
            format!("{}: an AMC motion needs its ASF skeleton in the same upload", amc.label)
        } else {
            let names: Vec<&str> = skeletons.iter().map(|(f, _)| f.name.as_str()).collect();
            format!(
                "{}: cannot tell which skeleton this motion uses; none of {} is a prefix of its name",
                amc.label,
                names.join(", ")
            )
        };
        ApiError::unprocessable(detail).with_file(&amc.label)
    })
}

/// Parses every file; the first problem rejects the upload. Zips are unpacked
/// into memory reserved from `reservation`.
pub fn parse_upload(
    files: Vec<UploadFile>,
    limits: &Limits,
    reservation: &mut Reservation,
) -> Result<Vec<ParsedClip>, ApiError> {
    let files = expand_zips(files, limits, reservation)?;
    let mut skeletons = Vec::new();
    let mut motions = Vec::new();
    for file in files {
        match kind_of(&file)? {
            Kind::Asf => {
                let skeleton = clip::load_skeleton(&file.label, &file.bytes)
                    .map_err(|e| parse_failed(&file.label, e))?;
                skeletons.push((file, skeleton));
            }
            Kind::Bvh | Kind::Amc | Kind::Npz => motions.push(file),
            Kind::Zip => unreachable!("zips were expanded"),
        }
    }
    if motions.is_empty() {
        return Err(ApiError::unprocessable(
            "the upload holds no motion: add at least one .bvh, .amc or .npz file",
        ));
    }
    let mut clips: Vec<ParsedClip> = Vec::with_capacity(motions.len());
    for file in motions {
        let failed = |e| parse_failed(&file.label, e);
        let (format, motion, skeleton_file) = match kind_of(&file)? {
            Kind::Bvh => {
                let motion = clip::load_bvh(&file.label, &file.bytes).map_err(failed)?;
                (ClipFormat::Bvh, motion, None)
            }
            Kind::Npz => {
                let motion = clip::load_npz(&file.label, &file.bytes).map_err(failed)?;
                (ClipFormat::Npz, motion, None)
            }
            _ => {
                let (asf, skeleton) = pick_skeleton(&file, &skeletons)?;
                let motion = clip::load_amc(&file.label, &file.bytes, skeleton).map_err(failed)?;
                (ClipFormat::Amc, motion, Some(asf))
            }
        };
        if motion.frames() > limits.max_frames {
            return Err(ApiError::too_large(format!(
                "{}: {} frames; clips may have at most {} frames",
                file.label,
                motion.frames(),
                limits.max_frames
            ))
            .with_file(&file.label));
        }
        let name = stem(&file.name).to_string();
        if !is_clip_name(&name) {
            return Err(ApiError::unprocessable(format!(
                "{}: `{name}` cannot be a clip name: {CLIP_NAME_RULE}; rename the file",
                file.label
            ))
            .with_file(&file.label));
        }
        if let Some(other) = clips.iter().find(|c| c.name == name) {
            return Err(ApiError::unprocessable(format!(
                "{}: a clip named `{name}` was already uploaded as {}; clip names must be unique",
                file.label, other.source_name
            ))
            .with_file(&file.label));
        }
        let skeleton = motion.skeleton();
        clips.push(ParsedClip {
            name,
            format,
            frames: motion.frames(),
            fps: motion.fps(),
            joints: skeleton.len(),
            joint_names: skeleton.joints().iter().map(|j| j.name.clone()).collect(),
            source_name: file.name.clone(),
            source: file.bytes,
            skeleton_name: skeleton_file.map(|f| f.name.clone()),
            skeleton: skeleton_file.map(|f| f.bytes.clone()),
        });
    }
    check_pairs(&clips)?;
    Ok(clips)
}

/// Two-person pairs (`<stem>_A` / `<stem>_B`, as `pipeline::plan::pairs` finds
/// them) are animated together: both partners need the same frames and rate.
fn check_pairs(clips: &[ParsedClip]) -> Result<(), ApiError> {
    let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
    for (stem, a, b) in pipeline::plan::pairs(&names) {
        let find = |n: &str| clips.iter().find(|c| c.name == n);
        let (Some(a), Some(b)) = (find(&a), find(&b)) else {
            continue;
        };
        if a.frames != b.frames || (a.fps - b.fps).abs() > 1e-9 {
            return Err(ApiError::unprocessable(format!(
                "{} and {} form the two-person pair `{stem}` but differ: {} frames at {} fps \
                 against {} frames at {} fps; the partners of a pair must have the same \
                 frame count and rate",
                a.source_name, b.source_name, a.frames, a.fps, b.frames, b.fps
            ))
            .with_file(&b.source_name));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_kinds() {
        assert_eq!(base_name("a/b/HDM_bd.asf"), "HDM_bd.asf");
        assert_eq!(stem("HDM_bd_kick.amc"), "HDM_bd_kick");
        assert!(is_ignorable_entry("__MACOSX/x.bvh"));
        assert!(is_ignorable_entry("dir/.DS_Store"));
        assert!(!is_ignorable_entry("dir/walk.bvh"));
        let f = |n: &str| UploadFile {
            label: n.into(),
            name: n.into(),
            bytes: vec![],
        };
        assert_eq!(kind_of(&f("A.BVH")).unwrap(), Kind::Bvh);
        assert_eq!(kind_of(&f("walk__noise_000.npz")).unwrap(), Kind::Npz);
        assert!(kind_of(&f("notes.txt")).is_err());
    }

    #[test]
    fn unsafe_names_are_refused() {
        for name in ["walk", "HDM_bd_kick-1.v2", "a"] {
            assert!(is_clip_name(name), "{name}");
        }
        for name in [
            "",
            ".",
            "..",
            ".hidden",
            "my walk",
            "a/b",
            "a\\b",
            "é",
            &"x".repeat(101),
        ] {
            assert!(!is_clip_name(name), "{name}");
        }
        assert!(check_part_name("walk.bvh").is_ok());
        for name in [
            "../../etc/x.bvh",
            "/etc/abs.bvh",
            "..\\..\\evil.bvh",
            "..",
            "a\nb.bvh",
            "",
        ] {
            assert!(check_part_name(name).is_err(), "{name}");
        }
        assert!(check_entry_path("d.zip", "dir/walk.bvh").is_ok());
        for path in [
            "../../escape.bvh",
            "/abs.bvh",
            "a/../b.bvh",
            "..\\x.bvh",
            "C:/x.bvh",
        ] {
            assert!(check_entry_path("d.zip", path).is_err(), "{path}");
        }
    }

    /// The CI-sized counterpart of `fuzz/fuzz_targets/zip_upload.rs` (which
    /// needs a nightly toolchain): random bytes and corrupted copies of a
    /// valid zip, each answered with clips or a client error, never a panic or
    /// a 500, within the memory budget and the limits.
    mod corrupt_zips {
        use super::*;
        use crate::configuration::Limits;
        use crate::upload_memory::UploadMemory;
        use proptest::prelude::*;
        use std::io::Write;

        fn limits() -> Limits {
            Limits {
                max_files: 50,
                max_unzipped_bytes: 8 << 20,
                upload_memory_bytes: 12 << 20,
                ..Limits::default()
            }
        }

        fn valid_zip() -> Vec<u8> {
            let bvh = include_bytes!("../../../examples/data/static_root_walk.bvh");
            let mut out = std::io::Cursor::new(Vec::new());
            let mut w = zip::ZipWriter::new(&mut out);
            let opts = zip::write::SimpleFileOptions::default();
            w.start_file("dir/walk.bvh", opts).expect("zip entry");
            w.write_all(bvh).expect("zip write");
            w.start_file("walk2.bvh", opts).expect("zip entry");
            w.write_all(bvh).expect("zip write");
            w.finish().expect("zip finish");
            out.into_inner()
        }

        /// `parse_upload` of one zip under the scaled-down limits, and the
        /// bytes the upload reserved.
        fn parse(bytes: Vec<u8>) -> (Result<Vec<ParsedClip>, ApiError>, u64) {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .build()
                .expect("a tokio runtime");
            let memory = UploadMemory::new(1, limits().upload_memory_bytes);
            let mut reservation = runtime.block_on(memory.start());
            let files = vec![UploadFile {
                label: "fuzz.zip".into(),
                name: "fuzz.zip".into(),
                bytes,
            }];
            let out = parse_upload(files, &limits(), &mut reservation);
            (out, reservation.bytes())
        }

        fn check(bytes: Vec<u8>) {
            let limits = limits();
            let (out, reserved) = parse(bytes);
            match out {
                Ok(clips) => {
                    assert!(clips.len() <= limits.max_files);
                    let unpacked: u64 = clips.iter().map(|c| c.source.len() as u64).sum();
                    assert!(unpacked <= limits.max_unzipped_bytes);
                }
                Err(e) => assert!(
                    e.status().is_client_error() || e.status().as_u16() == 503,
                    "upload answered {}: {:?}",
                    e.status(),
                    e.0.detail
                ),
            }
            assert!(reserved <= limits.upload_memory_bytes);
        }

        #[test]
        fn the_valid_zip_gives_two_clips() {
            let (out, _) = parse(valid_zip());
            assert_eq!(out.map(|c| c.len()).map_err(|e| e.0.detail), Ok(2));
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(128))]

            #[test]
            fn random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
                check(bytes);
            }

            #[test]
            fn corrupted_valid_zips(flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..16),
                                    cut in any::<prop::sample::Index>()) {
                let mut bytes = valid_zip();
                for (at, value) in flips {
                    let i = at.index(bytes.len());
                    bytes[i] = value;
                }
                if cut.index(4) == 0 {
                    let n = cut.index(bytes.len());
                    bytes.truncate(n);
                }
                check(bytes);
            }
        }
    }
}
