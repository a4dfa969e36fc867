//! The clips of folders and files on disk, for `motionaug view`.
//!
//! * An `augment` output folder (it has `manifest.json`): one clip per
//!   manifest entry (synthesised, corrected or debiased), grouped by source,
//!   each with its versions: the source clip (the manifest's `source` path,
//!   when it can be read from here), the source's corrected version
//!   (`work/originals/<source>/`), the synthesised clip a correction started
//!   from (`work/correct/<clip>/input.bvh`) and the corrected clip before
//!   debiasing (`work/correct/<clip>/corrected.bvh`). The occlusion mask comes
//!   from the entry's NPZ, the IK keyframe and target from the entry, the
//!   learning curve from the report the entry names.
//! * Any other folder: its BVH, AMC (with the ASF next to it) and NPZ files
//!   (one clip per file stem, BVH preferred), and clips given as files.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use motion::Unit;
use serde::Serialize;
use serde_json::Value;

use crate::ViewerError;
use crate::clip::{ClipView, npz_motion};

/// What a clip is to the others in the library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A captured clip an augmentation started from.
    Source,
    /// A source clip after physical correction.
    SourceCorrected,
    /// Made by synthesis (noise, time warp, mirror, mask, IK, VAE, interaction).
    Synthesised,
    /// A synthesised clip after physical correction.
    Corrected,
    /// A corrected clip after debiasing.
    Debiased,
    /// A clip with no augmentation around it.
    Clip,
}

/// How to read the clips.
#[derive(Debug, Clone)]
pub struct ScanOptions {
    /// ASF skeleton for AMC clips (else `HDM_<actor>.asf`, `<subject>.asf` or
    /// the only `.asf` next to the clip).
    pub skeleton: Option<PathBuf>,
    pub unit: Unit,
    pub amc_fps: f64,
}

impl Default for ScanOptions {
    fn default() -> Self {
        ScanOptions {
            skeleton: None,
            unit: Unit::Auto,
            amc_fps: motion::amc::DEFAULT_FPS,
        }
    }
}

/// One clip of the library.
#[derive(Debug, Clone)]
pub struct LibraryClip {
    /// Its index in the library, as text (the page's handle for it).
    pub id: String,
    pub name: String,
    /// The source clip's name (or the folder's) for grouping.
    pub group: String,
    pub role: Role,
    pub path: PathBuf,
    /// The ASF of an AMC clip.
    pub skeleton: Option<PathBuf>,
    /// An NPZ beside a BVH that may hold the occlusion mask.
    pub mask_from: Option<PathBuf>,
    /// Its manifest entry.
    pub entry: Option<Value>,
    /// Its correction's `report.json`.
    pub report: Option<PathBuf>,
    /// IK effector, keyframe time (s) and target.
    pub ik: Option<(String, f64, Option<[f64; 3]>)>,
    /// Ids of the clips to play beside it (itself included), in the order
    /// source, corrected source, synthesised, corrected, debiased.
    pub versions: Vec<String>,
    /// Shown in the list (versions kept under `work/` are not).
    pub listed: bool,
}

/// Every clip found.
#[derive(Debug, Clone)]
pub struct Library {
    pub title: String,
    pub clips: Vec<LibraryClip>,
}

/// The URLs of a clip's parts, made by whichever server serves it.
#[derive(Debug, Clone, Serialize)]
pub struct Urls {
    pub meta: String,
    pub frames: String,
    pub flags: String,
    pub report: Option<String>,
    pub download: Option<String>,
}

/// A clip as the page lists it (both servers send this shape).
#[derive(Debug, Clone, Serialize)]
pub struct Descriptor {
    pub id: String,
    pub name: String,
    pub group: String,
    pub role: Role,
    pub entry: Option<Value>,
    pub frames: Option<u64>,
    pub fps: Option<f64>,
    pub masked: bool,
    pub versions: Vec<String>,
    pub listed: bool,
    pub urls: Urls,
}

const CLIP_EXTENSIONS: [&str; 3] = ["bvh", "amc", "npz"];

fn ext(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ViewerError + '_ {
    move |source| ViewerError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// The ASF for an AMC clip: given, else the one beside it
/// ([`motion::io::asf_beside`]).
fn skeleton_for(clip: &Path, given: Option<&Path>) -> Option<PathBuf> {
    given
        .map(Path::to_path_buf)
        .or_else(|| motion::io::asf_beside(clip))
}

/// The frame rate a BVH file states (`Frame Time`), without reading the rest.
fn bvh_fps(path: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with("Frame Time"))?;
    let dt: f64 = line.split(':').nth(1)?.trim().parse().ok()?;
    (dt > 0.0).then_some(1.0 / dt)
}

struct Builder {
    options: ScanOptions,
    clips: Vec<LibraryClip>,
    by_path: HashMap<PathBuf, usize>,
}

impl Builder {
    /// Adds a clip (once per path); returns its index.
    fn add(
        &mut self,
        path: PathBuf,
        name: String,
        group: String,
        role: Role,
        listed: bool,
    ) -> usize {
        if let Some(&i) = self.by_path.get(&path) {
            if listed {
                self.clips[i].listed = true;
            }
            return i;
        }
        let i = self.clips.len();
        let skeleton = (ext(&path) == "amc")
            .then(|| skeleton_for(&path, self.options.skeleton.as_deref()))
            .flatten();
        self.clips.push(LibraryClip {
            id: i.to_string(),
            name,
            group,
            role,
            skeleton,
            mask_from: None,
            entry: None,
            report: None,
            ik: None,
            versions: Vec::new(),
            listed,
            path: path.clone(),
        });
        self.by_path.insert(path, i);
        i
    }

    /// The clip files of `dir`, one per stem (BVH, then AMC, then NPZ),
    /// sorted by name.
    fn files(dir: &Path) -> Result<Vec<PathBuf>, ViewerError> {
        let mut by_stem: HashMap<String, PathBuf> = HashMap::new();
        for entry in std::fs::read_dir(dir).map_err(io(dir))? {
            let path = entry.map_err(io(dir))?.path();
            let e = ext(&path);
            let Some(rank) = CLIP_EXTENSIONS.iter().position(|x| *x == e) else {
                continue;
            };
            if !path.is_file() {
                continue;
            }
            let better = by_stem.get(&stem(&path)).is_none_or(|old| {
                rank < CLIP_EXTENSIONS
                    .iter()
                    .position(|x| *x == ext(old))
                    .unwrap_or(9)
            });
            if better {
                by_stem.insert(stem(&path), path);
            }
        }
        let mut files: Vec<PathBuf> = by_stem.into_values().collect();
        files.sort();
        Ok(files)
    }

    fn folder(&mut self, dir: &Path) -> Result<(), ViewerError> {
        let manifest = dir.join("manifest.json");
        let mut in_manifest = Vec::new();
        if manifest.is_file() {
            in_manifest = self.manifest(dir, &manifest)?;
        }
        let group = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| dir.display().to_string());
        // A `motionaug correct` output: corrected.bvh with its report.json.
        let report = dir.join("report.json");
        let corrected = Self::files(dir)?
            .into_iter()
            .find(|p| stem(p) == "corrected");
        if let (true, Some(corrected)) = (report.is_file() && !manifest.is_file(), corrected) {
            let source = std::fs::read(&report)
                .ok()
                .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
                .and_then(|r| r.get("source").and_then(Value::as_str).map(str::to_string))
                .unwrap_or_else(|| group.clone());
            let input = dir.join("input.bvh");
            let mut versions = Vec::new();
            if input.is_file() {
                versions.push(self.add(input, source.clone(), source.clone(), Role::Source, false));
            }
            let i = self.add(
                corrected,
                format!("{source} (corrected)"),
                source,
                Role::Corrected,
                true,
            );
            versions.push(i);
            self.clips[i].report = Some(report);
            self.clips[i].versions = versions.iter().map(|v| v.to_string()).collect();
            in_manifest.extend(["corrected".into(), "input".into()]);
        }
        for path in Self::files(dir)? {
            if in_manifest.iter().any(|m: &String| *m == stem(&path)) {
                continue;
            }
            self.add(path.clone(), stem(&path), group.clone(), Role::Clip, true);
        }
        Ok(())
    }

    /// The manifest's outputs and their versions; returns the stems listed.
    fn manifest(&mut self, dir: &Path, manifest: &Path) -> Result<Vec<String>, ViewerError> {
        let bytes = std::fs::read(manifest).map_err(io(manifest))?;
        let entries: Vec<Value> = serde_json::from_slice(&bytes).map_err(|e| ViewerError::Bad {
            path: manifest.display().to_string(),
            message: format!("not a manifest (a JSON array of entries): {e}"),
        })?;
        let mut stems = Vec::new();
        for entry in entries {
            let Some(file) = entry.get("file").and_then(Value::as_str) else {
                continue;
            };
            let path = dir.join(file);
            let name = stem(&path);
            stems.push(name.clone());
            let source = entry.get("source").and_then(Value::as_str).unwrap_or("");
            let source_name = stem(Path::new(source));
            let group = if source_name.is_empty() {
                name.clone()
            } else {
                source_name.clone()
            };
            let correction = entry.get("correction").filter(|c| !c.is_null());
            let debiased = entry
                .get("debiased")
                .and_then(Value::as_bool)
                .unwrap_or(false);
            let role = if debiased {
                Role::Debiased
            } else if correction.is_some() {
                Role::Corrected
            } else {
                Role::Synthesised
            };
            let report = correction
                .and_then(|c| c.get("report"))
                .and_then(Value::as_str)
                .map(|r| dir.join(r))
                .filter(|r| r.is_file());
            let mut versions = Vec::new();

            // The source, as the command line named it (relative to here or absolute).
            let source_path = PathBuf::from(source);
            let source_fps = if source_path.is_file() {
                let i = self.add(
                    source_path.clone(),
                    source_name.clone(),
                    group.clone(),
                    Role::Source,
                    true,
                );
                versions.push(i);
                match ext(&source_path).as_str() {
                    "bvh" => bvh_fps(&source_path),
                    _ => Some(self.options.amc_fps),
                }
            } else {
                None
            };
            let originals = dir.join("work").join("originals").join(&source_name);
            // Only beside a corrected output: what correction does to captured motion.
            if correction.is_some()
                && !source_name.is_empty()
                && originals.join("corrected.bvh").is_file()
            {
                let i = self.add(
                    originals.join("corrected.bvh"),
                    format!("{source_name} (corrected)"),
                    group.clone(),
                    Role::SourceCorrected,
                    false,
                );
                let report = originals.join("report.json");
                self.clips[i].report = report.is_file().then_some(report);
                versions.push(i);
            }
            let correction_dir = report
                .as_ref()
                .and_then(|r| r.parent())
                .map(Path::to_path_buf);
            let mut synth_fps = if correction.is_none() {
                entry.get("fps").and_then(Value::as_f64)
            } else {
                source_fps
            };
            if let Some(cdir) = &correction_dir {
                let input = cdir.join("input.bvh");
                if input.is_file() {
                    synth_fps = bvh_fps(&input).or(synth_fps);
                    versions.push(self.add(
                        input,
                        format!("{name} (synthesised)"),
                        group.clone(),
                        Role::Synthesised,
                        false,
                    ));
                }
                let corrected = cdir.join("corrected.bvh");
                if debiased && corrected.is_file() {
                    let i = self.add(
                        corrected,
                        format!("{name} (corrected)"),
                        group.clone(),
                        Role::Corrected,
                        false,
                    );
                    self.clips[i].report = report.clone();
                    versions.push(i);
                }
            }
            let i = self.add(path.clone(), name.clone(), group, role, true);
            versions.push(i);
            let npz = path.with_extension("npz");
            let ik = match (
                entry.get("effector").and_then(Value::as_str),
                entry.get("keyframe").and_then(Value::as_u64),
                synth_fps,
            ) {
                (Some(effector), Some(keyframe), Some(fps)) => Some((
                    effector.to_string(),
                    keyframe as f64 / fps,
                    entry
                        .get("target")
                        .and_then(|t| serde_json::from_value::<[f64; 3]>(t.clone()).ok()),
                )),
                _ => None,
            };
            let ids: Vec<String> = versions.iter().map(|v| v.to_string()).collect();
            for &v in &versions {
                let c = &mut self.clips[v];
                if matches!(c.role, Role::Synthesised | Role::Corrected | Role::Debiased) {
                    c.ik = ik.clone();
                }
            }
            let clip = &mut self.clips[i];
            clip.mask_from = (ext(&path) != "npz" && npz.is_file()).then_some(npz);
            clip.entry = Some(entry);
            clip.report = report;
            clip.versions = ids;
        }
        Ok(stems)
    }
}

/// The library of `paths` (folders and clip files).
pub fn scan(paths: &[PathBuf], options: &ScanOptions) -> Result<Library, ViewerError> {
    let mut b = Builder {
        options: options.clone(),
        clips: Vec::new(),
        by_path: HashMap::new(),
    };
    for path in paths {
        if path.is_dir() {
            b.folder(path)?;
        } else if path.is_file() {
            if !CLIP_EXTENSIONS.contains(&ext(path).as_str()) {
                return Err(ViewerError::Bad {
                    path: path.display().to_string(),
                    message: "not a clip (expected .bvh, .amc or .npz, or a folder)".into(),
                });
            }
            let group = path
                .parent()
                .and_then(|p| p.file_name())
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            b.add(path.clone(), stem(path), group, Role::Clip, true);
        } else {
            return Err(io(path)(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no such file or folder",
            )));
        }
    }
    // Listed clips first by group, in the order found; versions stay where they are.
    let title = paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    Ok(Library {
        title,
        clips: b.clips,
    })
}

impl LibraryClip {
    /// Reads and prepares the clip.
    pub fn load(&self, options: &ScanOptions) -> Result<ClipView, ViewerError> {
        let (motion, mut mask) = if ext(&self.path) == "npz" {
            let bytes = std::fs::read(&self.path).map_err(io(&self.path))?;
            npz_motion(&bytes, &self.path.display().to_string())?
        } else {
            let load = motion::LoadOptions {
                skeleton: self.skeleton.clone(),
                unit: options.unit,
                fps: Some(options.amc_fps),
            };
            (motion::load(&self.path, &load)?, None)
        };
        if let Some(npz) = &self.mask_from {
            let bytes = std::fs::read(npz).map_err(io(npz))?;
            let arrays = motion::npz::read(&bytes).map_err(io(npz))?;
            if let Some(m) = arrays
                .iter()
                .find(|a| a.name == "mask")
                .and_then(|a| a.to_u8())
                && m.len() == motion.frames() * motion.joints()
            {
                mask = Some(m.into_iter().map(|b| b != 0).collect());
            }
        }
        let view = ClipView::from_motion(&self.name, &motion, mask.as_deref())?;
        Ok(match &self.ik {
            Some((effector, at, target)) => view.with_ik(effector, *at, *target),
            None => view,
        })
    }

    /// What the page lists, with the server's URLs.
    pub fn describe(&self, urls: Urls) -> Descriptor {
        let number = |k: &str| self.entry.as_ref().and_then(|e| e.get(k));
        Descriptor {
            id: self.id.clone(),
            name: self.name.clone(),
            group: self.group.clone(),
            role: self.role,
            entry: self.entry.clone(),
            frames: number("frames").and_then(Value::as_u64),
            fps: number("fps").and_then(Value::as_f64),
            masked: self
                .entry
                .as_ref()
                .and_then(|e| e.get("op"))
                .and_then(Value::as_str)
                == Some("mask"),
            versions: if self.versions.is_empty() {
                vec![self.id.clone()]
            } else {
                self.versions.clone()
            },
            listed: self.listed,
            urls,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn walk_path() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data/16_11_walk_veer_left.bvh")
    }

    /// An augment output folder as the pipeline lays it out: a noise output,
    /// a masked IK output, and a corrected + debiased output with its work files.
    fn output_folder(dir: &Path) {
        let walk = motion::load(walk_path(), &motion::LoadOptions::default()).unwrap();
        let source = walk_path().display().to_string();
        for name in ["w__00_noise_000", "w__01_ik_000", "w__02_noise_000"] {
            motion::save(&walk, dir.join(format!("{name}.bvh"))).unwrap();
        }
        let n = walk.frames() * walk.joints();
        let mask =
            motion::npz::NpyArray::bool("mask", &[walk.frames(), walk.joints()], &vec![false; n])
                .unwrap();
        std::fs::write(
            dir.join("w__01_ik_000.npz"),
            motion::npz::motion_to_bytes(&walk, &[mask]).unwrap(),
        )
        .unwrap();
        let correct = dir.join("work/correct/w__02_noise_000");
        let originals = dir.join("work/originals/16_11_walk_veer_left");
        for d in [&correct, &originals] {
            std::fs::create_dir_all(d).unwrap();
            motion::save(&walk, d.join("corrected.bvh")).unwrap();
            std::fs::write(d.join("report.json"), "{}").unwrap();
        }
        motion::save(&walk, correct.join("input.bvh")).unwrap();
        let entry = |file: &str, op: &str| {
            json!({"file": file, "source": source, "op": op, "op_index": 0, "copy": 0,
                   "seed": 1, "params": {}, "frames": walk.frames(), "fps": walk.fps()})
        };
        let mut ik = entry("w__01_ik_000.bvh", "ik");
        ik["effector"] = json!("RightFoot");
        ik["keyframe"] = json!(60);
        ik["target"] = json!([0.1, 0.0, 0.3]);
        let mut corrected = entry("w__02_noise_000.bvh", "noise");
        corrected["correction"] = json!({"report": "work/correct/w__02_noise_000/report.json"});
        corrected["debiased"] = json!(true);
        let manifest = json!([entry("w__00_noise_000.bvh", "noise"), ik, corrected]);
        std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
        // A file the manifest does not name is still listed.
        motion::save(&walk, dir.join("extra.bvh")).unwrap();
    }

    #[test]
    fn an_output_folder_lists_its_entries_with_their_versions() {
        let tmp = tempfile::tempdir().unwrap();
        output_folder(tmp.path());
        let lib = scan(&[tmp.path().to_path_buf()], &ScanOptions::default()).unwrap();
        let by_name = |n: &str| {
            lib.clips
                .iter()
                .find(|c| c.name == n)
                .unwrap_or_else(|| panic!("no {n}"))
        };
        let listed: Vec<&str> = lib
            .clips
            .iter()
            .filter(|c| c.listed)
            .map(|c| c.name.as_str())
            .collect();
        assert_eq!(
            listed,
            [
                "16_11_walk_veer_left",
                "w__00_noise_000",
                "w__01_ik_000",
                "w__02_noise_000",
                "extra"
            ]
        );
        let noise = by_name("w__00_noise_000");
        assert_eq!(noise.role, Role::Synthesised);
        assert_eq!(noise.group, "16_11_walk_veer_left");
        assert_eq!(
            noise.versions,
            [by_name("16_11_walk_veer_left").id.clone(), noise.id.clone()]
        );
        let ik = by_name("w__01_ik_000");
        assert_eq!(
            ik.mask_from.as_deref(),
            Some(tmp.path().join("w__01_ik_000.npz").as_path())
        );
        let (effector, at, target) = ik.ik.clone().unwrap();
        assert_eq!(effector, "RightFoot");
        assert!((at - 0.5).abs() < 1e-9, "keyframe 60 at 120 Hz");
        assert_eq!(target, Some([0.1, 0.0, 0.3]));
        let debiased = by_name("w__02_noise_000");
        assert_eq!(debiased.role, Role::Debiased);
        let roles: Vec<Role> = debiased
            .versions
            .iter()
            .map(|id| lib.clips.iter().find(|c| &c.id == id).unwrap().role)
            .collect();
        assert_eq!(
            roles,
            [
                Role::Source,
                Role::SourceCorrected,
                Role::Synthesised,
                Role::Corrected,
                Role::Debiased
            ]
        );
        assert!(debiased.report.is_some());
        assert_eq!(by_name("extra").role, Role::Clip);

        // Loading: the mask hides every joint, the IK keyframe is on the clip's frames.
        let view = ik.load(&ScanOptions::default()).unwrap();
        assert!(view.meta().masked);
        assert_eq!(view.meta().ik.as_ref().unwrap().keyframe, 60);
        let described = ik.describe(Urls {
            meta: "m".into(),
            frames: "f".into(),
            flags: "g".into(),
            report: None,
            download: None,
        });
        assert_eq!(described.frames, Some(view.meta().frames as u64));
    }

    #[test]
    fn files_and_folders_without_manifest() {
        let tmp = tempfile::tempdir().unwrap();
        let walk = motion::load(walk_path(), &motion::LoadOptions::default()).unwrap();
        motion::save(&walk, tmp.path().join("a.bvh")).unwrap();
        motion::save(&walk, tmp.path().join("a.npz")).unwrap();
        motion::save(&walk, tmp.path().join("b.npz")).unwrap();
        let lib = scan(&[tmp.path().to_path_buf()], &ScanOptions::default()).unwrap();
        let files: Vec<String> = lib
            .clips
            .iter()
            .map(|c| c.path.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(files, ["a.bvh", "b.npz"], "one clip per stem, BVH first");
        let b = lib.clips[1].load(&ScanOptions::default()).unwrap();
        assert_eq!(b.meta().frames, walk.frames());
        let one = scan(&[walk_path()], &ScanOptions::default()).unwrap();
        assert_eq!(one.clips.len(), 1);
        assert!(scan(&[tmp.path().join("nothing")], &ScanOptions::default()).is_err());
        std::fs::write(tmp.path().join("x.txt"), "").unwrap();
        assert!(scan(&[tmp.path().join("x.txt")], &ScanOptions::default()).is_err());
    }

    #[test]
    fn hdm05_clips_find_their_skeleton() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
        let lib = scan(std::slice::from_ref(&dir), &ScanOptions::default()).unwrap();
        let kick = lib
            .clips
            .iter()
            .find(|c| c.name.starts_with("HDM_bd_kick"))
            .unwrap();
        assert_eq!(
            kick.skeleton.as_deref(),
            Some(dir.join("HDM_bd.asf").as_path())
        );
        assert!(kick.load(&ScanOptions::default()).unwrap().meta().frames > 100);
    }
}
