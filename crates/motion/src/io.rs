//! One entry point to load and save clips in any supported format, chosen by
//! file extension (case-insensitive), so the CLI and the services do not each
//! repeat the dispatch:
//!
//! * `.bvh`: a BVH clip ([`crate::bvh`]), in `unit` (or guessed);
//! * `.amc`: an AMC clip, which needs its ASF skeleton ([`crate::amc`]);
//! * `.asf`: a skeleton alone, loaded as one frame of its rest pose;
//! * `.npz`: a clip the product wrote, lossless or float32
//!   ([`crate::npz::read_motion`]), so outputs can be fed back in;
//! * saving: `.bvh` ([`crate::bvh::write_file`]) or `.npz`
//!   ([`crate::npz::write_motion`]).
//!
//! The byte-slice functions ([`parse_bvh`], [`parse_asf`], [`parse_amc`],
//! [`parse_named`]) serve uploads held in memory.

use std::path::{Path, PathBuf};

use crate::amc;
use crate::asf::{self, Asf};
use crate::bvh;
use crate::error::{MotionError, ParseError};
use crate::motion::Motion;
use crate::npz;
use crate::units::Unit;

/// How to load a clip.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadOptions {
    /// The ASF skeleton of an AMC clip.
    pub skeleton: Option<PathBuf>,
    /// Length unit of BVH files ([`Unit::Auto`] guesses from the body size).
    pub unit: Unit,
    /// Frame rate of clips whose files carry none: AMC clips and an ASF rest
    /// pose (default [`amc::DEFAULT_FPS`], 120 Hz). BVH files always keep their
    /// own `Frame Time` (resample with [`crate::resample`] to change it).
    pub fps: Option<f64>,
}

/// File formats by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Bvh,
    Amc,
    Asf,
    Npz,
}

impl Format {
    /// The format of `path` by its extension.
    pub fn of(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "bvh" => Format::Bvh,
            "amc" => Format::Amc,
            "asf" => Format::Asf,
            "npz" => Format::Npz,
            _ => return None,
        })
    }
}

fn whole(path: &Path, message: String) -> MotionError {
    ParseError {
        file: path.to_path_buf(),
        line: None,
        message,
    }
    .into()
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, MotionError> {
    std::fs::read(path).map_err(|source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn fps_or_default(fps: Option<f64>) -> f64 {
    fps.unwrap_or(amc::DEFAULT_FPS)
}

/// The ASF skeleton beside an AMC clip when none is given: `HDM_<actor>.asf`
/// for `HDM_<actor>_*.amc` (HDM05), `<subject>.asf` for `<subject>_*.amc`
/// (CMU), else the only `.asf` in the clip's folder.
pub fn asf_beside(clip: &Path) -> Option<PathBuf> {
    let dir = clip
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = clip.file_stem()?.to_string_lossy();
    let parts: Vec<&str> = name.split('_').collect();
    let mut candidates = Vec::new();
    if parts.len() > 1 && parts[0] == "HDM" {
        candidates.push(format!("HDM_{}.asf", parts[1]));
    }
    candidates.push(format!("{}.asf", parts[0]));
    if let Some(found) = candidates.iter().map(|c| dir.join(c)).find(|p| p.is_file()) {
        return Some(found);
    }
    let asfs: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("asf")))
        .collect();
    (asfs.len() == 1).then(|| asfs[0].clone())
}

/// Load a clip from disk, dispatching on the extension (see the module doc).
/// An AMC clip is read with `options.skeleton`, else with [`asf_beside`].
pub fn load(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Motion, MotionError> {
    let path = path.as_ref();
    let format = Format::of(path);
    let skeleton = match format {
        Some(Format::Amc) => match options.skeleton.clone().or_else(|| asf_beside(path)) {
            Some(asf_path) => Some(asf::read(asf_path)?),
            None => None,
        },
        _ => None,
    };
    let bytes = read_bytes(path)?;
    match format {
        Some(Format::Bvh) => bvh::parse(&bytes, path, options.unit),
        Some(Format::Amc) => match skeleton {
            Some(asf) => amc::parse(&bytes, path, &asf, fps_or_default(options.fps)),
            None => Err(whole(
                path,
                "an AMC clip needs its ASF skeleton: none beside it (HDM_<actor>.asf, \
                 <subject>.asf or the folder's only .asf); pass it with --skeleton FILE.asf"
                    .into(),
            )),
        },
        Some(Format::Asf) => asf::parse(&bytes, path)?.rest_motion(fps_or_default(options.fps)),
        Some(Format::Npz) => npz::read_motion(&bytes, path),
        None => Err(unknown_extension(path)),
    }
}

fn unknown_extension(path: &Path) -> MotionError {
    whole(
        path,
        format!(
            "unknown file type `{}` (expected .bvh, .amc with an .asf skeleton, .asf or .npz)",
            path.extension()
                .map(|e| format!(".{}", e.to_string_lossy()))
                .unwrap_or_else(|| "(no extension)".into())
        ),
    )
}

/// Save a clip as `.bvh` (in [`bvh::default_unit`]) or `.npz` by extension.
pub fn save(motion: &Motion, path: impl AsRef<Path>) -> Result<(), MotionError> {
    let path = path.as_ref();
    // Written whole or not at all: a crash never leaves half a clip behind.
    match Format::of(path) {
        Some(Format::Bvh) => write_atomic(path, &bvh::to_bytes(motion)),
        Some(Format::Npz) => {
            let bytes = npz::motion_to_bytes(motion, &[]).map_err(|source| MotionError::Io {
                path: path.to_path_buf(),
                source,
            })?;
            write_atomic(path, &bytes)
        }
        _ => Err(MotionError::Unsupported(format!(
            "{}: can only save .bvh or .npz",
            path.display()
        ))),
    }
}

/// A BVH clip from memory; `label` names it in errors.
pub fn parse_bvh(bytes: &[u8], label: impl AsRef<Path>, unit: Unit) -> Result<Motion, MotionError> {
    bvh::parse(bytes, label, unit)
}

/// An ASF skeleton from memory.
pub fn parse_asf(bytes: &[u8], label: impl AsRef<Path>) -> Result<Asf, MotionError> {
    asf::parse(bytes, label)
}

/// An AMC clip from memory, for the skeleton `asf`, at `fps` frames per second.
pub fn parse_amc(
    bytes: &[u8],
    label: impl AsRef<Path>,
    asf: &Asf,
    fps: f64,
) -> Result<Motion, MotionError> {
    amc::parse(bytes, label, asf, fps)
}

/// A clip from memory, by the extension of `name` (an upload's file name), with
/// the ASF skeleton's name and bytes for AMC clips; options as in [`load`]
/// (`options.skeleton` is not used: the skeleton comes as bytes).
pub fn parse_named(
    name: &str,
    bytes: &[u8],
    skeleton: Option<(&str, &[u8])>,
    options: &LoadOptions,
) -> Result<Motion, MotionError> {
    let path = Path::new(name);
    match Format::of(path) {
        Some(Format::Bvh) => bvh::parse(bytes, path, options.unit),
        Some(Format::Amc) => match skeleton {
            Some((asf_name, asf_bytes)) => {
                let asf = asf::parse(asf_bytes, asf_name)?;
                amc::parse(bytes, path, &asf, fps_or_default(options.fps))
            }
            None => Err(whole(
                path,
                "an AMC clip needs its ASF skeleton uploaded with it".into(),
            )),
        },
        Some(Format::Asf) => asf::parse(bytes, path)?.rest_motion(fps_or_default(options.fps)),
        Some(Format::Npz) => npz::read_motion(bytes, path),
        None => Err(unknown_extension(path)),
    }
}

/// Write `bytes` to `path` atomically: a temporary file in the same directory,
/// synced, then renamed, so a crash never leaves half a file behind.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), MotionError> {
    use std::io::Write;
    let io_error = |source| MotionError::Io {
        path: path.to_path_buf(),
        source,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| {
        io_error(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a file path",
        ))
    })?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An AMC clip finds its skeleton beside it by the HDM05 and CMU naming
    /// rules, or as the folder's only ASF; else the error says what to pass.
    #[test]
    fn an_amc_clip_finds_the_asf_beside_it() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
        let amc = data.join("HDM_bd_kickLFront1Reps_001_120.amc");
        assert_eq!(asf_beside(&amc), Some(data.join("HDM_bd.asf")));
        let found = load(&amc, &LoadOptions::default()).unwrap();
        let given = load(
            &amc,
            &LoadOptions {
                skeleton: Some(data.join("HDM_bd.asf")),
                ..LoadOptions::default()
            },
        )
        .unwrap();
        assert_eq!(found.frames(), given.frames());
        assert_eq!(found.rotations(), given.rotations());

        let dir = tempfile::tempdir().unwrap();
        let copy = |from: &str, to: &str| {
            std::fs::copy(data.join(from), dir.path().join(to)).unwrap();
        };
        copy("HDM_bd_kickLFront1Reps_001_120.amc", "07_01.amc");
        let cmu = dir.path().join("07_01.amc");
        let e = load(&cmu, &LoadOptions::default()).unwrap_err().to_string();
        assert!(e.contains("--skeleton"), "{e}");
        // The only ASF of the folder, whatever its name.
        copy("HDM_bd.asf", "someone.asf");
        assert_eq!(asf_beside(&cmu), Some(dir.path().join("someone.asf")));
        // Two ASFs: the CMU name decides; without it nothing is guessed.
        copy("HDM_bd.asf", "other.asf");
        assert_eq!(asf_beside(&cmu), None);
        copy("HDM_bd.asf", "07.asf");
        assert_eq!(asf_beside(&cmu), Some(dir.path().join("07.asf")));
        assert!(load(&cmu, &LoadOptions::default()).is_ok());
    }

    #[test]
    fn dispatch_errors_are_clear() {
        let opts = LoadOptions::default();
        let e = parse_named("clip.amc", b"1\n", None, &opts).unwrap_err();
        assert!(e.to_string().contains("ASF skeleton"), "{e}");
        let e = parse_named("clip.c3d", b"", None, &opts).unwrap_err();
        assert!(e.to_string().contains(".c3d"), "{e}");
        let e = load("/nonexistent/x.bvh", &opts).unwrap_err();
        assert!(matches!(e, MotionError::Io { .. }));
        assert_eq!(Format::of(Path::new("A.BVH")), Some(Format::Bvh));
        // A frame rate for AMC clips leaves a BVH file's own rate alone.
        let bvh = b"HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Yrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.04\n5\n";
        let with_fps = LoadOptions {
            fps: Some(120.0),
            ..LoadOptions::default()
        };
        let m = parse_named("a.bvh", bvh, None, &with_fps).unwrap();
        assert!((m.fps() - 25.0).abs() < 1e-9);
    }
}
