//! The evaluation table: for several classes and held-out actors, the
//! synthesis metrics of each synthesised set and the prediction error with
//! each as augmentation, as one typed result ([`Table`]) with its renderer
//! ([`Table::to_markdown`], [`Table::write`]).
//!
//! * [`TableConfig`]: what to compute; [`Default`] is `motionaug eval table`'s defaults.
//! * [`run_table`]: computes it, cell by cell (one class of one test actor),
//!   reporting progress and each finished cell ([`Progress`]).
//! * [`physics`]: the physically corrected and debiased rows, through the
//!   pipeline's one executor.
//! * `render`: table.json and table.md.
//! * `paper`: the MotionAug paper's Tables 2-5, which table.md reads the full
//!   method beside.
//! * [`merge`]: tables of separate runs (folds) merged into one, from their
//!   table.json files.
//!
//! Trained VAEs and corrections are kept in `work/<actor>_<class>/`, so a
//! rerun reuses them and resumes interrupted corrections.

mod merge;
mod paper;
pub mod physics;
mod render;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use motion::Motion;
use serde::{Deserialize, Serialize};
use vae::Prior;

use crate::augment::{VaeTraining, apply_recipe, cached_vae, sample_vae};
use crate::dataset::{self, Split};
use crate::error::{EvalError, Result};
use crate::options::TrainOptions;
use crate::predict::protocol::{self, ConditionResult, Horizons, ModelKind, TestSet};
use crate::scores::{SynthScores, synth_scores};
pub use merge::{SavedTable, merge};
pub use physics::{PhysicsConfig, PhysicsSummary};

/// A synthesised set of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SetKind {
    /// Gaussian rotation noise, 10 copies per clip.
    Noise,
    /// IK edits with the class's preset, 10 copies per clip.
    Ik,
    /// VAE near and prior samples (10 per training clip).
    Vae,
    /// VAE & IK: the VAE's near samples and the IK edits together, each clip
    /// time-warped (+-10 %, MotionAug Sec. 4.3; needs both).
    VaeIk,
    /// Subsets of the VAE's near samples and of the IK edits as made,
    /// physically corrected, and debiased (needs [`SetKind::Vae`] or
    /// [`SetKind::Ik`]); with [`SetKind::VaeIk`] also their time-warped union.
    Physics,
}

impl SetKind {
    pub const ALL: [SetKind; 5] = [
        SetKind::Noise,
        SetKind::Ik,
        SetKind::Vae,
        SetKind::VaeIk,
        SetKind::Physics,
    ];

    pub fn name(self) -> &'static str {
        match self {
            SetKind::Noise => "noise",
            SetKind::Ik => "ik",
            SetKind::Vae => "vae",
            SetKind::VaeIk => "vae_ik",
            SetKind::Physics => "physics",
        }
    }
}

impl std::str::FromStr for SetKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        SetKind::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown set `{s}` (noise, ik, vae, vae_ik or physics)"))
    }
}

impl std::fmt::Display for SetKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Conditions of the prediction tables, in order (sets not made are skipped):
/// the synthesised sets as made, then the corrected subsets as made
/// (`_sub`), the clips of it the correction accepted, as made (`_kept`, with
/// [`TableConfig::kept_rows`]), physically corrected (`_corrected`) and
/// debiased (`_debiased`).
pub const PREDICT_CONDITIONS: [&str; 16] = [
    "noise",
    "ik",
    "vae_near",
    "vae_ik",
    "ik_sub",
    "ik_kept",
    "ik_corrected",
    "ik_debiased",
    "vae_sub",
    "vae_kept",
    "vae_corrected",
    "vae_debiased",
    "vae_ik_sub",
    "vae_ik_kept",
    "vae_ik_corrected",
    "vae_ik_debiased",
];

/// What the table computes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TableConfig {
    /// Folder of HDM05 clips.
    pub data: PathBuf,
    /// Folder of the `HDM_<actor>.asf` skeletons (`None`: `data`).
    pub skeleton_dir: Option<PathBuf>,
    /// Where trained VAEs and corrections are kept (`<actor>_<class>/` each).
    pub work: PathBuf,
    /// Classes (parts of class names; also the IK preset names).
    pub classes: Vec<String>,
    pub test_actors: Vec<String>,
    pub models: Vec<ModelKind>,
    pub train: TrainOptions,
    /// Noise set: Gaussian rotation noise, degrees.
    pub noise_sigma_deg: f64,
    /// VAE training iterations per class and fold (default 1,500, the vae
    /// crate's: with 300 the correction accepted 2 of kick's 46 VAE samples,
    /// with 1,500 it accepted 8; a class trains in 6-27 min on one loaded
    /// core, see the vae crate's README).
    pub vae_iterations: u64,
    /// Also train the VAE without discriminators (synthesis metrics only).
    pub vae_ablation: bool,
    /// Draw near codes between this many training clips of a cluster instead
    /// of the VAE's own (the paper's 2; see the vae crate's README).
    pub vae_near_members: Option<usize>,
    /// Weight of the VAE's pose-speed term on mixed codes
    /// (`vae::LossWeights::mixed_motion`; 0: off, the vae crate's default).
    /// Near samples of a class whose clips move fast (jog) otherwise stand
    /// nearly frozen, and the correction rejects them (crates/eval/README.md,
    /// jog).
    pub vae_mixed_motion_weight: f64,
    /// Weight of the VAE's ground-contact term on mixed codes
    /// (`vae::LossWeights::mixed_contact`; 0: off, the vae crate's default):
    /// moving jog samples otherwise hover in half their frames.
    pub vae_mixed_contact_weight: f64,
    /// Weight of the VAE's sole term on mixed codes
    /// (`vae::LossWeights::mixed_sole`; 0: off, the vae crate's default):
    /// planted feet of moving jog samples otherwise stand on a heel or a toe.
    pub vae_mixed_sole_weight: f64,
    /// Weight of the VAE's travel term on mixed codes
    /// (`vae::LossWeights::mixed_travel`; 0: off, the vae crate's default):
    /// with the contact and skating terms, moving jog samples stop halfway.
    pub vae_mixed_travel_weight: f64,
    /// Weight of the VAE's balance term on mixed codes
    /// (`vae::LossWeights::mixed_balance`; 0: off, the vae crate's
    /// default): jog samples whose ZMP leaves the feet fall in the simulator.
    pub vae_mixed_balance_weight: f64,
    /// Weight of the VAE's skating term on mixed codes (`vae::FootLoss::skating`;
    /// `None`: the vae crate's 0.1).
    pub vae_skating_weight: Option<f64>,
    /// Low-pass each VAE sample with a Gaussian of this many seconds before
    /// its root is planted (0: as decoded; `vae::Finish`).
    pub vae_smooth_s: f64,
    /// Re-integrate each VAE sample's root path from its planted feet
    /// (`vae::Finish::plant_root`, the default). Off, the samples keep the
    /// decoded root, and the correction's "no more skating than the input"
    /// is measured against the decoder's own skating instead of a root
    /// planted onto the feet (crates/eval/README.md, jog fold mm, session 31).
    pub vae_plant_root: bool,
    /// Put the VAE's training clips on one floor (`vae::FloorLevel`, the vae
    /// crate's default); off, each stands as captured (tables made before
    /// session 33). HDM05's actors stand 0-3 cm apart in height, and fold
    /// bd's jog samples floated in 55 % of frames on the captured floors,
    /// 46 % on one (crates/vae/README.md).
    pub vae_level_floor: bool,
    /// Train and score the prediction models (else synthesis metrics only).
    pub predict: bool,
    pub sets: Vec<SetKind>,
    pub physics: PhysicsConfig,
    /// Also train on the corrected subsets' accepted clips as made (`_kept`
    /// rows): `_corrected` keeps only accepted clips, so `_corrected - _sub`
    /// mixes what rejecting clips did with what correcting the rest did;
    /// `_kept - _sub` and `_corrected - _kept` tell them apart.
    pub kept_rows: bool,
    /// Cores the table uses: corrections that need nothing from each other,
    /// and the prediction models of a cell, run this many at a time. Each
    /// has its own seeds and runs on one thread (the class trackers too), so
    /// the numbers do not depend on it and it is not part of the JSON.
    #[serde(skip)]
    pub threads: usize,
}

impl Default for TableConfig {
    fn default() -> Self {
        TableConfig {
            data: PathBuf::new(),
            skeleton_dir: None,
            work: PathBuf::new(),
            classes: ["kick", "jog", "sneak", "grab", "deposit"]
                .map(String::from)
                .to_vec(),
            test_actors: vec!["bd".into()],
            models: vec![ModelKind::Seq2seq, ModelKind::Gcn],
            train: TrainOptions::default(),
            noise_sigma_deg: 2.0,
            vae_iterations: 1500,
            vae_ablation: false,
            vae_near_members: None,
            vae_mixed_motion_weight: 0.0,
            vae_mixed_contact_weight: 0.0,
            vae_mixed_sole_weight: 0.0,
            vae_mixed_travel_weight: 0.0,
            vae_mixed_balance_weight: 0.0,
            vae_skating_weight: None,
            vae_smooth_s: vae::trained::DEFAULT_SMOOTH_S,
            vae_plant_root: true,
            vae_level_floor: true,
            predict: true,
            sets: vec![SetKind::Noise, SetKind::Ik, SetKind::Vae, SetKind::VaeIk],
            physics: PhysicsConfig::default(),
            kept_rows: false,
            threads: 1,
        }
    }
}

impl TableConfig {
    /// Checks what a run would otherwise find out late.
    pub fn validate(&self) -> Result<()> {
        if self.has(SetKind::Physics) && !self.has(SetKind::Vae) && !self.has(SetKind::Ik) {
            return Err(EvalError::PhysicsNeedsVae);
        }
        if self.has(SetKind::VaeIk) && !(self.has(SetKind::Vae) && self.has(SetKind::Ik)) {
            return Err(EvalError::Config(
                "the vae_ik set is the vae and ik sets together: add both".into(),
            ));
        }
        let config = |m: &str| Err(EvalError::Config(m.into()));
        if self.kept_rows && !self.has(SetKind::Physics) {
            return config("the kept rows are the physics set's accepted clips: add physics");
        }
        if self.data.as_os_str().is_empty() {
            return config("no data folder");
        }
        if self.threads == 0 {
            return config("at least one thread");
        }
        if self.work.as_os_str().is_empty() {
            return config("no work folder");
        }
        if self.classes.is_empty() || self.test_actors.is_empty() {
            return config("no classes or no test actors");
        }
        if self.predict && self.models.is_empty() {
            return config("no prediction models");
        }
        if let Some(e) = self.train.epochs
            && !(e.is_finite() && e > 0.0)
        {
            return config("epochs must be positive");
        }
        if !(self.vae_smooth_s.is_finite() && (0.0..=1.0).contains(&self.vae_smooth_s)) {
            return config("the VAE samples' smoothing must be 0-1 s");
        }
        if !(self.vae_mixed_motion_weight.is_finite() && self.vae_mixed_motion_weight >= 0.0) {
            return config("the VAE's mixed-motion weight must be 0 or more");
        }
        if !(self.vae_mixed_contact_weight.is_finite() && self.vae_mixed_contact_weight >= 0.0) {
            return config("the VAE's mixed-contact weight must be 0 or more");
        }
        if !(self.vae_mixed_sole_weight.is_finite() && self.vae_mixed_sole_weight >= 0.0) {
            return config("the VAE's mixed-sole weight must be 0 or more");
        }
        if !(self.vae_mixed_travel_weight.is_finite() && self.vae_mixed_travel_weight >= 0.0) {
            return config("the VAE's mixed-travel weight must be 0 or more");
        }
        if !(self.vae_mixed_balance_weight.is_finite() && self.vae_mixed_balance_weight >= 0.0) {
            return config("the VAE's mixed-balance weight must be 0 or more");
        }
        if self
            .vae_skating_weight
            .is_some_and(|w| !(w.is_finite() && w >= 0.0))
        {
            return config("the VAE's skating weight must be 0 or more");
        }
        self.physics.validate()
    }

    fn has(&self, set: SetKind) -> bool {
        self.sets.contains(&set)
    }
}

/// One class of one test actor.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct TableCell {
    pub class: String,
    pub matched_classes: Vec<String>,
    pub test_actor: String,
    pub train_clips: usize,
    pub test_clips: usize,
    /// Synthesis metrics per set (original = the training clips themselves).
    pub synth: BTreeMap<String, SynthScores>,
    pub synth_clips: BTreeMap<String, usize>,
    /// model -> condition -> errors.
    pub predict: BTreeMap<String, BTreeMap<String, ConditionResult>>,
    pub zero_velocity: Option<Horizons>,
    pub vae_seconds: BTreeMap<String, f64>,
    /// What the physical correction did (with [`SetKind::Physics`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physics: Option<PhysicsSummary>,
}

/// The table: its config, the cells computed so far, and the wall time.
#[derive(Debug, Clone)]
pub struct Table {
    pub config: TableConfig,
    pub cells: Vec<TableCell>,
    /// Wall seconds from the start of the run to the last cell.
    pub seconds: f64,
}

/// What a table run reports while it goes.
pub trait Progress: Sync {
    /// A line for a log (the CLI prints it on stderr).
    fn line(&self, line: &str);
    /// A cell is done: the table so far (the CLI rewrites table.json and
    /// table.md, so a long run can be read while it goes). An error stops the run.
    fn cell_done(&self, table: &Table) -> Result<()> {
        let _ = table;
        Ok(())
    }
}

/// Any `Fn(&str)` is a progress that logs lines and ignores cells.
impl<F: Fn(&str) + Sync> Progress for F {
    fn line(&self, line: &str) {
        self(line)
    }
}

/// Loads one class of `data` with `actor` held out, and says what matched.
pub fn load_fold(
    data: &std::path::Path,
    skeletons: Option<&std::path::Path>,
    class: &str,
    actor: &str,
    log: crate::Log,
) -> Result<Split> {
    let split = dataset::load_split(data, skeletons.unwrap_or(data), class, actor)?;
    log(&split.describe(class, actor));
    Ok(split)
}

/// Computes the table `config` describes, cell by cell.
pub fn run_table(config: &TableConfig, progress: &dyn Progress) -> Result<Table> {
    config.validate()?;
    let started = Instant::now();
    let mut table = Table {
        config: config.clone(),
        cells: Vec::new(),
        seconds: 0.0,
    };
    for actor in &config.test_actors {
        for class in &config.classes {
            progress.line(&format!(
                "== {class}, test actor {actor} ({:.0} s so far)",
                started.elapsed().as_secs_f64()
            ));
            let saved = config
                .work
                .join("cells")
                .join(format!("{actor}_{class}.json"));
            let cell = match finished_cell(&saved, config) {
                Some(cell) => {
                    progress.line(&format!("reusing the finished cell {}", saved.display()));
                    cell
                }
                None => {
                    let cell = run_cell(config, class, actor, progress)?;
                    save_cell(&saved, config, &cell)?;
                    cell
                }
            };
            table.cells.push(cell);
            table.seconds = started.elapsed().as_secs_f64();
            progress.cell_done(&table)?;
        }
    }
    Ok(table)
}

/// The cell saved at `path` if it was computed with what shapes `config`'s
/// numbers ([`TableConfig::cell_key`]).
fn finished_cell(path: &std::path::Path, config: &TableConfig) -> Option<TableCell> {
    #[derive(Deserialize)]
    struct Saved {
        key: serde_json::Value,
        cell: TableCell,
    }
    let text = std::fs::read(path).ok()?;
    let saved: Saved = serde_json::from_slice(&text).ok()?;
    // A cell made with predictions also serves a run without them; one made
    // without them never serves a run that wants them.
    let with_predictions = TableConfig {
        predict: true,
        ..config.clone()
    };
    let fits = saved.key == config.cell_key()
        || (!config.predict && saved.key == with_predictions.cell_key());
    // Cells saved before the key recorded it: one without a single trained
    // model is a synthesis-only cell.
    let lacks_predictions = config.predict && saved.cell.predict.values().all(|m| m.is_empty());
    (fits && !lacks_predictions).then_some(saved.cell)
}

/// Saves a finished cell with its key, so a rerun reuses it.
fn save_cell(path: &std::path::Path, config: &TableConfig, cell: &TableCell) -> Result<()> {
    let json = serde_json::to_vec_pretty(&serde_json::json!({
        "key": config.cell_key(),
        "cell": cell,
    }))
    .map_err(|e| EvalError::Data(format!("{}: {e}", path.display())))?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|source| EvalError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    motion::io::write_atomic(path, &json)?;
    Ok(())
}

/// One class of one test actor: its synthesised sets, their scores, the
/// prediction models trained with each.
fn run_cell(
    config: &TableConfig,
    class: &str,
    actor: &str,
    progress: &dyn Progress,
) -> Result<TableCell> {
    let log = |l: &str| progress.line(l);
    let split = load_fold(
        &config.data,
        config.skeleton_dir.as_deref(),
        class,
        actor,
        &log,
    )?;
    let mut cell = TableCell {
        class: class.to_string(),
        matched_classes: split.classes(),
        test_actor: actor.to_string(),
        train_clips: split.train.len(),
        test_clips: split.test.len(),
        ..Default::default()
    };
    let work = config.work.join(format!("{actor}_{class}"));
    let sets = synthesised_sets(config, class, &split, &work, &mut cell, &log)?;

    let t = Instant::now();
    cell.synth
        .insert("original".into(), synth_scores(&split.train, &split.test)?);
    for (name, clips) in &sets {
        cell.synth_clips.insert(name.clone(), clips.len());
        if !clips.is_empty() {
            cell.synth
                .insert(name.clone(), synth_scores(clips, &split.test)?);
        }
    }
    log(&format!(
        "synthesis metrics in {:.1} s",
        t.elapsed().as_secs_f64()
    ));
    if config.predict {
        for &model in &config.models {
            let (zero_velocity, by_condition) =
                predict_conditions(config, model, &split, &sets, &log)?;
            cell.zero_velocity = Some(zero_velocity);
            cell.predict.insert(model.to_string(), by_condition);
        }
    }
    Ok(cell)
}

/// A named synthesised set.
type Set = (String, Vec<(String, Motion)>);

/// The synthesised sets of a cell, in table order; VAE timings and the
/// correction's summary go into `cell`.
fn synthesised_sets(
    config: &TableConfig,
    class: &str,
    split: &Split,
    work: &std::path::Path,
    cell: &mut TableCell,
    log: crate::Log,
) -> Result<Vec<Set>> {
    let physics = config.has(SetKind::Physics);
    let mut sets = if physics && config.threads >= 2 {
        // The originals' corrections (and the class tracker) need nothing
        // from the synthesised sets: on the second thread while the VAE
        // trains; the plan below finds them finished and reuses them.
        let (sets, originals) = nn::threads::beside(
            "originals",
            || made_sets(config, class, split, work, cell, log),
            || physics::correct_originals(&config.physics, &split.train, work, log),
        )
        .map_err(|e| EvalError::Data(format!("cannot start a thread: {e}")))?;
        let seconds = originals?;
        log(&format!(
            "the originals' corrections ran beside the synthesis: {seconds:.0} s"
        ));
        sets?
    } else {
        made_sets(config, class, split, work, cell, log)?
    };
    if physics {
        correct_sets(config, split, work, cell, &mut sets, log)?;
    }
    Ok(sets)
}

/// The noise, IK, VAE and VAE & IK sets (as made, before any correction).
fn made_sets(
    config: &TableConfig,
    class: &str,
    split: &Split,
    work: &std::path::Path,
    cell: &mut TableCell,
    log: crate::Log,
) -> Result<Vec<Set>> {
    let mut sets: Vec<Set> = Vec::new();
    if config.has(SetKind::Noise) {
        let noise = pipeline::Recipe::from_toml_str(&format!(
            "seed = 1\n[[ops]]\nop = \"noise\"\ncopies = 10\nsigma_deg = {}\n",
            config.noise_sigma_deg
        ))?;
        sets.push((
            "noise".into(),
            apply_recipe(&noise, 1, None, &split.train, log)?,
        ));
    }
    if config.has(SetKind::Ik) {
        let ik = pipeline::Recipe::from_toml_str(&format!(
            "seed = 1\n[[ops]]\nop = \"ik\"\npreset = \"{}\"\ncopies = 10\n",
            class.to_ascii_lowercase()
        ))
        .map_err(|e| EvalError::Config(format!("no IK preset for class `{class}`: {e}")))?;
        sets.push(("ik".into(), apply_recipe(&ik, 1, None, &split.train, log)?));
    }
    let count = split.train.len() * 10;
    let mut vae_runs = vec![];
    if config.has(SetKind::Vae) {
        vae_runs.push(("vae", None));
        if config.vae_ablation {
            vae_runs.push(("vae_noadv", Some(0.0)));
        }
    }
    let finish = vae::Finish::new(config.vae_smooth_s, config.vae_plant_root);
    for (tag, weight) in vae_runs {
        let t = Instant::now();
        let training = VaeTraining {
            iterations: config.vae_iterations,
            adversarial_weight: weight,
            mixed_motion_weight: config.vae_mixed_motion_weight,
            mixed_contact_weight: config.vae_mixed_contact_weight,
            mixed_sole_weight: config.vae_mixed_sole_weight,
            mixed_travel_weight: config.vae_mixed_travel_weight,
            mixed_balance_weight: config.vae_mixed_balance_weight,
            skating_weight: config.vae_skating_weight,
            level_floor: config.vae_level_floor,
        };
        let folder = work.join(training.folder_name(tag));
        let mut model = cached_vae(&folder, &split.train, &training, log)?;
        if let Some(members) = config.vae_near_members {
            model = model.with_near_members(members)?;
        }
        cell.vae_seconds
            .insert(tag.into(), t.elapsed().as_secs_f64());
        sets.push((
            format!("{tag}_near"),
            sample_vae(&model, count, Prior::Near, 0, &finish)?,
        ));
        sets.push((
            format!("{tag}_prior"),
            sample_vae(&model, count, Prior::Normal, 0, &finish)?,
        ));
    }
    if config.has(SetKind::VaeIk) {
        let union = union_of(&sets, "vae_near", "ik");
        sets.push(("vae_ik".into(), time_warped(&union)?));
    }
    Ok(sets)
}

/// The physics rows: subsets of the VAE's near samples and of the IK edits,
/// corrected and debiased (appended to `sets`; the summary goes into `cell`).
fn correct_sets(
    config: &TableConfig,
    split: &Split,
    work: &std::path::Path,
    cell: &mut TableCell,
    sets: &mut Vec<Set>,
    log: crate::Log,
) -> Result<()> {
    let to_correct: Vec<physics::ToCorrect<'_>> = [("vae", "vae_near"), ("ik", "ik")]
        .into_iter()
        .filter_map(|(row, set)| {
            let clips = sets.iter().find(|(n, _)| n == set)?.1.as_slice();
            Some(physics::ToCorrect { row, clips })
        })
        .collect();
    if to_correct.is_empty() {
        return Err(EvalError::PhysicsNeedsVae);
    }
    let p = physics::correct_and_debias(
        &config.physics,
        &split.train,
        &to_correct,
        work,
        config.threads,
        log,
    )?;
    for set in p.sets {
        let row = set.row;
        if config.kept_rows {
            let accepted: std::collections::HashSet<&str> =
                set.corrected.iter().map(|(n, _)| n.as_str()).collect();
            let kept = set
                .subset
                .iter()
                .filter(|(n, _)| accepted.contains(n.as_str()))
                .cloned()
                .collect();
            sets.push((format!("{row}_kept"), kept));
        }
        sets.push((format!("{row}_sub"), set.subset));
        sets.push((format!("{row}_corrected"), set.corrected));
        sets.push((format!("{row}_debiased"), set.debiased));
    }
    cell.physics = Some(p.summary);
    if config.has(SetKind::VaeIk) {
        let stages = ["sub", "kept", "corrected", "debiased"]
            .into_iter()
            .filter(|stage| *stage != "kept" || config.kept_rows);
        for stage in stages {
            let union = union_of(sets, &format!("vae_{stage}"), &format!("ik_{stage}"));
            sets.push((format!("vae_ik_{stage}"), time_warped(&union)?));
        }
    }
    Ok(())
}

/// The clips of sets `a` and `b` together (a set not made adds nothing).
fn union_of(sets: &[Set], a: &str, b: &str) -> Vec<(String, Motion)> {
    [a, b]
        .iter()
        .filter_map(|name| sets.iter().find(|(n, _)| n == name))
        .flat_map(|(_, clips)| clips.iter().cloned())
        .collect()
}

/// Every clip time-warped (MotionAug Sec. 4.3: 10 % shorter to 10 % longer),
/// its factor drawn from a seed of its name: a clip gets the same factor in
/// every row it is in (as made, corrected, debiased), so rows differ only by
/// what the correction did.
fn time_warped(clips: &[(String, Motion)]) -> Result<Vec<(String, Motion)>> {
    let params = synth::TimeWarpParams::default();
    clips
        .iter()
        .map(|(name, m)| {
            let mut rng = synth::rng_from_seed(synth::output_seed(1, name, 0, 0));
            let warped = synth::time_warp(m, &params, &mut rng)
                .map_err(|e| EvalError::Data(format!("time warp of `{name}`: {e}")))?;
            Ok((format!("{name}__tw"), warped.motion))
        })
        .collect()
}

/// One model's prediction error without augmentation and with each set of
/// [`PREDICT_CONDITIONS`] that was made; and zero velocity's.
fn predict_conditions(
    config: &TableConfig,
    model: ModelKind,
    split: &Split,
    sets: &[Set],
    log: crate::Log,
) -> Result<(Horizons, BTreeMap<String, ConditionResult>)> {
    let protocol_config = config.train.config(model, split)?;
    let test = TestSet::new(&split.test, &protocol_config)?;
    let mut conditions: Vec<(&str, &[(String, Motion)])> = vec![("no_aug", &[])];
    conditions.extend(
        sets.iter()
            .filter(|(name, clips)| {
                PREDICT_CONDITIONS.contains(&name.as_str()) && !clips.is_empty()
            })
            .map(|(name, clips)| (name.as_str(), clips.as_slice())),
    );
    let side_by_side = config.threads > 1;
    let one = |(name, extra): (&str, &[(String, Motion)])| -> Result<(String, ConditionResult)> {
        log(&format!("{model}: {name}"));
        let mut all = split.train.clone();
        all.extend(extra.iter().cloned());
        // Side by side, each line says whose it is.
        let mut progress = |l: &str| match side_by_side {
            true => log(&format!("{model} {name}: {l}")),
            false => log(l),
        };
        let result = protocol::evaluate(&all, &test, &protocol_config, &mut progress)?;
        Ok((name.to_string(), result))
    };
    let results: Result<Vec<(String, ConditionResult)>> =
        nn::threads::side_by_side(conditions, config.threads, "predict", one)
            .map_err(|e| EvalError::Data(format!("cannot train models side by side: {e}")))?
            .into_iter()
            .collect();
    Ok((test.zero_velocity(), results?.into_iter().collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> TableConfig {
        TableConfig {
            data: "data".into(),
            work: "work".into(),
            ..TableConfig::default()
        }
    }

    #[test]
    fn the_physics_set_needs_the_vae_set() {
        let mut c = config();
        assert!(c.validate().is_ok());
        c.sets = vec![SetKind::Physics];
        assert!(matches!(c.validate(), Err(EvalError::PhysicsNeedsVae)));
        c.sets.push(SetKind::Vae);
        assert!(c.validate().is_ok());
        c.threads = 0;
        assert!(matches!(c.validate(), Err(EvalError::Config(m)) if m.contains("thread")));
        c.threads = 2;
        assert!(c.validate().is_ok());
        c.train.epochs = Some(0.0);
        assert!(matches!(c.validate(), Err(EvalError::Config(_))));
        assert!(matches!(
            TableConfig::default().validate(),
            Err(EvalError::Config(_))
        ));
    }

    #[test]
    fn set_kinds_read_and_print_as_the_json_names_them() {
        for k in SetKind::ALL {
            assert_eq!(k.to_string().parse::<SetKind>(), Ok(k));
            assert_eq!(
                serde_json::to_value(k).ok(),
                Some(serde_json::Value::String(k.to_string()))
            );
        }
        assert!("vaee".parse::<SetKind>().is_err());
    }

    #[test]
    fn vae_and_ik_together_needs_both_sets_and_physics_needs_one_of_them() {
        let mut c = config();
        c.sets = vec![SetKind::Vae, SetKind::VaeIk];
        assert!(matches!(c.validate(), Err(EvalError::Config(m)) if m.contains("vae_ik")));
        c.sets.push(SetKind::Ik);
        assert!(c.validate().is_ok());
        c.sets = vec![SetKind::Ik, SetKind::Physics];
        assert!(c.validate().is_ok());
        c.sets = vec![SetKind::Noise, SetKind::Physics];
        assert!(matches!(c.validate(), Err(EvalError::PhysicsNeedsVae)));
        // The kept rows are the physics set's.
        c.kept_rows = true;
        c.sets = vec![SetKind::Ik];
        assert!(matches!(c.validate(), Err(EvalError::Config(m)) if m.contains("kept rows")));
        c.sets.push(SetKind::Physics);
        assert!(c.validate().is_ok());
    }

    /// A two-joint clip of `frames` frames swinging at `speed`.
    fn clip(frames: usize, speed: f64) -> Motion {
        use motion::glam::{DQuat, DVec3};
        let joint = |name: &str, parent: Option<usize>| motion::Joint {
            name: name.into(),
            parent,
            offset: DVec3::new(0.0, 0.3, 0.0),
            channels: vec![],
            end_site: None,
            limits: None,
        };
        let skeleton = motion::Skeleton::new(vec![joint("root", None), joint("a", Some(0))], 1.0)
            .expect("a valid skeleton");
        let rot = (0..frames)
            .flat_map(|t| {
                [
                    DQuat::IDENTITY,
                    DQuat::from_rotation_x((speed * t as f64).sin()),
                ]
            })
            .collect();
        Motion::new(
            std::sync::Arc::new(skeleton),
            30.0,
            vec![DVec3::ZERO; frames],
            rot,
        )
        .expect("a valid motion")
    }

    #[test]
    fn a_clip_is_warped_by_the_same_factor_in_every_row() {
        let made: Vec<(String, Motion)> = (0..8)
            .map(|i| (format!("vae_Near_{i:04}"), clip(91, 0.1)))
            .collect();
        // The same clips after a correction: other poses, same names.
        let corrected: Vec<(String, Motion)> = made
            .iter()
            .map(|(n, _)| (n.clone(), clip(91, 0.2)))
            .collect();
        let (a, b) = (
            time_warped(&made).expect("warps"),
            time_warped(&corrected).expect("warps"),
        );
        let frames: Vec<usize> = a.iter().map(|(_, m)| m.frames()).collect();
        assert_eq!(
            frames,
            b.iter().map(|(_, m)| m.frames()).collect::<Vec<_>>()
        );
        for ((name, _), f) in a.iter().zip(&frames) {
            assert!(name.ends_with("__tw"), "{name}");
            // 90 frame steps played 0.9x to 1.1x as fast.
            assert!((81..=101).contains(f), "{name}: {f} frames");
        }
        // Different clips draw different factors.
        assert!(frames.iter().any(|f| *f != frames[0]), "{frames:?}");
    }

    #[test]
    fn the_union_of_two_sets_skips_a_set_that_was_not_made() {
        let sets: Vec<Set> = vec![
            ("vae_near".into(), vec![("v".into(), clip(5, 0.1))]),
            (
                "ik".into(),
                vec![("i".into(), clip(5, 0.1)), ("j".into(), clip(5, 0.1))],
            ),
        ];
        let names = |u: Vec<(String, Motion)>| u.into_iter().map(|(n, _)| n).collect::<Vec<_>>();
        assert_eq!(names(union_of(&sets, "vae_near", "ik")), ["v", "i", "j"]);
        assert_eq!(names(union_of(&sets, "vae_sub", "ik")), ["i", "j"]);
    }

    #[test]
    fn a_finished_cell_is_reused_only_when_what_shapes_it_is_the_same() {
        let dir = std::env::temp_dir().join(format!("eval-cell-{}", std::process::id()));
        let path = dir.join("cells").join("bd_kick.json");
        let c = config();
        let no_aug = ConditionResult {
            errors: Horizons::new(),
            per_seed: Vec::new(),
            train_clips: 7,
            train_windows: 70,
            skipped_clips: 0,
            train_seconds: Vec::new(),
            first_loss: 1.0,
            last_loss: 0.5,
        };
        let cell = TableCell {
            class: "kick".into(),
            test_actor: "bd".into(),
            train_clips: 7,
            predict: [(
                "gcn".to_string(),
                [("no_aug".to_string(), no_aug)].into_iter().collect(),
            )]
            .into_iter()
            .collect(),
            ..TableCell::default()
        };
        assert!(finished_cell(&path, &c).is_none());
        save_cell(&path, &c, &cell).expect("saves");
        assert_eq!(finished_cell(&path, &c).map(|c| c.train_clips), Some(7));
        // More classes or actors do not change a cell ...
        let mut wider = c.clone();
        wider.classes.push("walk".into());
        wider.test_actors.push("mm".into());
        assert!(finished_cell(&path, &wider).is_some());
        // ... more iterations do.
        let mut longer = c.clone();
        longer.train.iterations += 1;
        assert!(finished_cell(&path, &longer).is_none());
        // A cell with predictions serves a run without them, not the reverse.
        let mut synthesis_only = c.clone();
        synthesis_only.predict = false;
        assert!(finished_cell(&path, &synthesis_only).is_some());
        let without = dir.join("cells").join("bd_kick_synthesis_only.json");
        save_cell(&without, &synthesis_only, &cell).expect("saves");
        assert!(finished_cell(&without, &synthesis_only).is_some());
        assert!(finished_cell(&without, &c).is_none());
        // A synthesis-only cell saved before its key said so: no model in it.
        let older = dir.join("cells").join("bd_kick_older.json");
        let synthesis_cell = TableCell {
            predict: BTreeMap::new(),
            ..cell.clone()
        };
        save_cell(&older, &c, &synthesis_cell).expect("saves");
        assert!(finished_cell(&older, &c).is_none());
        assert!(finished_cell(&older, &synthesis_only).is_some());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_config_survives_json_and_missing_fields_are_the_defaults() {
        let mut c = config();
        c.sets.push(SetKind::Physics);
        c.physics.correct_count = Some(3);
        let text = serde_json::to_string(&c).expect("serialises");
        assert_eq!(serde_json::from_str::<TableConfig>(&text).ok(), Some(c));
        assert_eq!(
            serde_json::from_str::<TableConfig>("{}").ok(),
            Some(TableConfig::default())
        );
    }
}
