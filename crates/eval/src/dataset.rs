//! HDM05 clips by class and actor: `HDM_<actor>_<class>_<nnn>_<fps>.amc`, one
//! `HDM_<actor>.asf` per actor. The protocol needs "every clip of this class, split
//! by actor", which is a file-name question, so it lives here and not in the CLI.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use motion::Motion;
use motion::asf::Asf;

use crate::error::{EvalError, Result};

/// The five HDM05 actors (leave-one-actor-out folds).
pub const ACTORS: [&str; 5] = ["bd", "bk", "dg", "mm", "tr"];

/// The frame rate the protocol runs at (MotionAug Sec. 4).
pub const FPS: f64 = 30.0;

/// One HDM05 clip file, its name parsed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClipFile {
    pub path: PathBuf,
    /// File stem, e.g. `HDM_bd_kickLFront1Reps_001_120`.
    pub name: String,
    pub actor: String,
    /// The class part, e.g. `kickLFront1Reps`.
    pub class: String,
}

/// Parses `HDM_<actor>_<class>_<nnn>_<fps>.amc`; `None` for other names.
pub fn parse_name(path: &Path) -> Option<ClipFile> {
    if !path.extension()?.to_str()?.eq_ignore_ascii_case("amc") {
        return None;
    }
    let name = path.file_stem()?.to_str()?.to_string();
    let parts: Vec<&str> = name.split('_').collect();
    if parts.len() < 5 || parts[0] != "HDM" {
        return None;
    }
    let n = parts.len();
    if !parts[n - 1].chars().all(|c| c.is_ascii_digit())
        || !parts[n - 2].chars().all(|c| c.is_ascii_digit())
    {
        return None;
    }
    Some(ClipFile {
        path: path.to_path_buf(),
        actor: parts[1].to_string(),
        class: parts[2..n - 2].join("_"),
        name,
    })
}

/// Every HDM05 clip in `dir` whose class contains `class_query`
/// (case-insensitive), sorted by name.
pub fn find_clips(dir: &Path, class_query: &str) -> Result<Vec<ClipFile>> {
    let entries = std::fs::read_dir(dir).map_err(|source| EvalError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let query = class_query.to_ascii_lowercase();
    let mut all = Vec::new();
    for e in entries {
        let e = e.map_err(|source| EvalError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        if let Some(c) = parse_name(&e.path()) {
            all.push(c);
        }
    }
    if all.is_empty() {
        return Err(EvalError::Data(format!(
            "{}: no HDM05 clips (HDM_<actor>_<class>_<nnn>_<fps>.amc)",
            dir.display()
        )));
    }
    let mut matched: Vec<ClipFile> = all
        .iter()
        .filter(|c| c.class.to_ascii_lowercase().contains(&query))
        .cloned()
        .collect();
    if matched.is_empty() {
        let mut classes: Vec<&str> = all.iter().map(|c| c.class.as_str()).collect();
        classes.sort_unstable();
        classes.dedup();
        return Err(EvalError::Data(format!(
            "{}: no clip's class contains `{class_query}`; classes: {}",
            dir.display(),
            classes.join(", ")
        )));
    }
    matched.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(matched)
}

/// Clips of one class split into training actors and one test actor, at [`FPS`].
#[derive(Debug, Clone)]
pub struct Split {
    pub train: Vec<(String, Motion)>,
    pub test: Vec<(String, Motion)>,
    pub train_files: Vec<ClipFile>,
    pub test_files: Vec<ClipFile>,
}

impl Split {
    /// The distinct class names that matched.
    pub fn classes(&self) -> Vec<String> {
        let mut c: Vec<String> = self
            .train_files
            .iter()
            .chain(&self.test_files)
            .map(|f| f.class.clone())
            .collect();
        c.sort();
        c.dedup();
        c
    }

    /// What `class` matched and how the clips split with `actor` held out,
    /// in one line.
    pub fn describe(&self, class: &str, actor: &str) -> String {
        format!(
            "class `{class}` matched {} ({} clips: {}); test actor {actor}: {} clips, training: {} clips",
            self.classes().join(", "),
            self.train.len() + self.test.len(),
            self.actors()
                .iter()
                .map(|(a, n)| format!("{a} {n}"))
                .collect::<Vec<_>>()
                .join(", "),
            self.test.len(),
            self.train.len()
        )
    }

    /// Clip count per actor, training and test together.
    pub fn actors(&self) -> BTreeMap<String, usize> {
        let mut m = BTreeMap::new();
        for f in self.train_files.iter().chain(&self.test_files) {
            *m.entry(f.actor.clone()).or_insert(0) += 1;
        }
        m
    }
}

/// Loads the clips of `class_query` in `data_dir` (skeletons `HDM_<actor>.asf` in
/// `skeleton_dir`), resampled to [`FPS`], with `test_actor`'s clips held out.
pub fn load_split(
    data_dir: &Path,
    skeleton_dir: &Path,
    class_query: &str,
    test_actor: &str,
) -> Result<Split> {
    let files = find_clips(data_dir, class_query)?;
    let (test_files, train_files): (Vec<ClipFile>, Vec<ClipFile>) =
        files.into_iter().partition(|f| f.actor == test_actor);
    let actors_of = |fs: &[ClipFile]| {
        let mut a: Vec<&str> = fs.iter().map(|f| f.actor.as_str()).collect();
        a.dedup();
        a.join(", ")
    };
    if test_files.is_empty() {
        return Err(EvalError::Data(format!(
            "test actor `{test_actor}` has no clips of class `{class_query}` in {} (actors with clips: {})",
            data_dir.display(),
            actors_of(&train_files)
        )));
    }
    if train_files.is_empty() {
        return Err(EvalError::Data(format!(
            "class `{class_query}` in {} has clips of `{test_actor}` only: nothing to train on",
            data_dir.display()
        )));
    }
    let mut skeletons: BTreeMap<String, Asf> = BTreeMap::new();
    let mut load = |fs: &[ClipFile]| -> Result<Vec<(String, Motion)>> {
        let mut out = Vec::with_capacity(fs.len());
        for f in fs {
            if !skeletons.contains_key(&f.actor) {
                let asf_path = skeleton_dir.join(format!("HDM_{}.asf", f.actor));
                let asf = motion::asf::read(&asf_path)?;
                skeletons.insert(f.actor.clone(), asf);
            }
            let asf = &skeletons[&f.actor];
            let m = motion::amc::read(&f.path, asf, motion::amc::DEFAULT_FPS)?;
            out.push((f.name.clone(), motion::resample::resample(&m, FPS)?));
        }
        Ok(out)
    };
    let train = load(&train_files)?;
    let test = load(&test_files)?;
    Ok(Split {
        train,
        test,
        train_files,
        test_files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_hdm05_names() {
        let c = parse_name(Path::new("/d/HDM_bd_kickLFront1Reps_001_120.amc")).unwrap();
        assert_eq!(
            (c.actor.as_str(), c.class.as_str()),
            ("bd", "kickLFront1Reps")
        );
        assert_eq!(c.name, "HDM_bd_kickLFront1Reps_001_120");
        assert!(parse_name(Path::new("HDM_bd.asf")).is_none());
        assert!(parse_name(Path::new("walk.amc")).is_none());
        assert!(parse_name(Path::new("HDM_bd_kick_x_120.amc")).is_none());
    }
}
