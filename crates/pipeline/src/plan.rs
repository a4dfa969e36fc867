//! The augmentation as a graph of jobs, computed from the recipe and the clip
//! names alone, so that the CLI (which runs it in one process) and the
//! coordinator (which stores it in Postgres and hands jobs to workers) run the
//! same graph with the same names and seeds.
//!
//! Every job carries the settings it runs with, resolved here once (the
//! recipe's defaults filled in at planning, not when the job runs), so a
//! stored plan runs as it was planned and the executor ([`crate::exec`])
//! needs nothing but the job and its inputs.
//!
//! Jobs and what they need:
//! * `synthesize` (one per clip: every kinematic output of it): the source clip.
//! * `vae` (one per class): the class's clips; trains, then samples `copies` clips.
//! * `interaction` (one per pair `<stem>_A` / `<stem>_B`): both clips.
//! * `tracker` (one per class, with `[correct] policy = "class"`): the
//!   class's clips; trains the class tracker every correction of the class
//!   starts from (`correct::class`).
//! * `variant_tracker` (one per class with new clips to correct, with
//!   `policy = "class"` and `variant_tracker_iterations > 0`): the class's
//!   `tracker` and the jobs that made its new clips; judges every new clip
//!   with the class tracker as is, then trains a second tracker, from the
//!   class tracker, on those it fails.
//! * `correct_original` (one per source clip, when `[correct]` warm-starts
//!   with one policy per clip, or `[debias]` is on): the source clip, and its
//!   class's `tracker` with `policy = "class"`.
//! * `correct` (one per new clip, except interaction outputs: two partners are
//!   not simulated together): the job that made the clip; with
//!   `policy = "class"` the tracker of the class of the first clip it was
//!   made from (and that class's `variant_tracker`, when there is one: a clip
//!   the class tracker fails starts from the second tracker); else with warm
//!   start the corrections of the clips it was made from (its source clip;
//!   every clip of the class for a VAE sample), the best of which warm-starts
//!   it.
//! * `debias_train`: every `correct_original`.
//! * `debias_apply` (one per corrected clip): its `correct` and `debias_train`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::recipe::{CorrectStep, GroupBy, InteractionStep, PolicyKind, Recipe, VaeStep};

/// What one job does, with the settings it runs with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum JobKind {
    /// Every kinematic output of one clip (milliseconds each).
    Synthesize {
        clip: String,
        /// The recipe's `[[ops]]`.
        ops: synth::Recipe,
        /// One entry per output, in output order.
        outputs: Vec<synth::Job>,
    },
    Vae {
        group: String,
        clips: Vec<String>,
        seed: u64,
        step: VaeStep,
        /// The manifest's op index of the VAE's outputs (after the `[[ops]]`).
        op_index: usize,
    },
    Interaction {
        pair: String,
        a: String,
        b: String,
        seed: u64,
        step: InteractionStep,
        op_index: usize,
    },
    /// One tracker policy for the clips of a class (`policy = "class"`).
    Tracker {
        group: String,
        clips: Vec<String>,
        seed: u64,
        step: CorrectStep,
    },
    /// The class tracker's verdict on the class's new clips as is, and a
    /// second tracker trained on those it fails (`variant_tracker_iterations`).
    VariantTracker {
        group: String,
        /// The new clips of the class, made by the job's dependencies.
        clips: Vec<String>,
        seed: u64,
        step: CorrectStep,
    },
    CorrectOriginal {
        clip: String,
        seed: u64,
        step: CorrectStep,
        /// The class tracker it starts from (`policy = "class"`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tracker: Option<String>,
    },
    Correct {
        clip: String,
        /// The class tracker it starts from (`policy = "class"`; then
        /// `sources` is empty).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        tracker: Option<String>,
        /// Whether the class has a `variant_tracker` job: when the class
        /// tracker failed this clip as is, it starts from the second tracker.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        variant_tracker: bool,
        /// Originals whose corrected policy may warm-start this one (with
        /// `[correct] warm_start`): the clip a variant was made from, or every
        /// clip of a VAE sample's class; the executor takes the best corrected
        /// one ([`crate::stages::best_warm_start`]).
        sources: Vec<String>,
        seed: u64,
        step: CorrectStep,
    },
    DebiasTrain {
        originals: Vec<String>,
        config: debias::TrainConfig,
    },
    DebiasApply {
        clip: String,
    },
}

impl JobKind {
    pub fn name(&self) -> &'static str {
        match self {
            JobKind::Synthesize { .. } => "synthesize",
            JobKind::Vae { .. } => "vae",
            JobKind::Interaction { .. } => "interaction",
            JobKind::Tracker { .. } => "tracker",
            JobKind::VariantTracker { .. } => "variant_tracker",
            JobKind::CorrectOriginal { .. } => "correct_original",
            JobKind::Correct { .. } => "correct",
            JobKind::DebiasTrain { .. } => "debias_train",
            JobKind::DebiasApply { .. } => "debias_apply",
        }
    }

    /// The source clips of the dataset the job reads.
    pub fn sources(&self) -> Vec<&str> {
        match self {
            JobKind::Synthesize { clip, .. } | JobKind::CorrectOriginal { clip, .. } => {
                vec![clip]
            }
            JobKind::Vae { clips, .. } | JobKind::Tracker { clips, .. } => {
                clips.iter().map(String::as_str).collect()
            }
            JobKind::Interaction { a, b, .. } => vec![a, b],
            JobKind::DebiasTrain { originals, .. } => {
                originals.iter().map(String::as_str).collect()
            }
            JobKind::Correct { .. }
            | JobKind::VariantTracker { .. }
            | JobKind::DebiasApply { .. } => vec![],
        }
    }

    /// The clip the job is about, when there is one (for error listings).
    pub fn clip(&self) -> Option<&str> {
        match self {
            JobKind::Synthesize { clip, .. }
            | JobKind::CorrectOriginal { clip, .. }
            | JobKind::Correct { clip, .. }
            | JobKind::DebiasApply { clip } => Some(clip),
            JobKind::Interaction { a, .. } => Some(a),
            JobKind::Vae { .. }
            | JobKind::Tracker { .. }
            | JobKind::VariantTracker { .. }
            | JobKind::DebiasTrain { .. } => None,
        }
    }
}

/// One job of the graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedJob {
    /// Unique within the plan, e.g. `correct:kick__00_ik_001`.
    pub key: String,
    pub kind: JobKind,
    /// Keys of the jobs whose results this one needs.
    pub deps: Vec<String>,
    /// Clips this job makes (a new clip, or a new version of one).
    pub outputs: Vec<String>,
    /// Whether its outputs are final here (no later job works on them):
    /// written as `<name>.bvh` / `.npz` with their manifest entries, else kept
    /// losslessly for the next job.
    pub finishes: bool,
}

/// Every job, in an order where each job comes after its dependencies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub jobs: Vec<PlannedJob>,
}

/// A new clip and where it came from.
#[derive(Debug, Clone, PartialEq)]
struct NewClip {
    name: String,
    producer: String,
    /// The clips it was made from (warm-start candidates): one for a
    /// synthesised variant, the class for a VAE sample, none for interaction.
    sources: Vec<String>,
    correctable: bool,
}

/// `(actor, class)` of an HDM05 name (`HDM_<actor>_<class>_<n>...`), else `None`.
fn hdm05_parts(name: &str) -> Option<(&str, &str)> {
    let parts: Vec<&str> = name.split('_').collect();
    (parts.len() >= 4 && parts[0].eq_ignore_ascii_case("HDM")).then(|| (parts[1], parts[2]))
}

/// The name without trailing `_<digits>` groups (at least its first part).
fn stem(name: &str) -> String {
    let parts: Vec<&str> = name.split('_').collect();
    let mut end = parts.len();
    while end > 1 && parts[end - 1].chars().all(|c| c.is_ascii_digit()) {
        end -= 1;
    }
    parts[..end].join("_")
}

/// The class of a clip name: the class part of HDM05 names
/// (`HDM_bd_kickLFront1Reps_001_120` -> `kickLFront1Reps`), else the name
/// without trailing `_<digits>` groups.
pub fn class_of(name: &str) -> String {
    hdm05_parts(name).map_or_else(|| stem(name), |(_, class)| class.to_string())
}

/// The actor of a clip name: the actor part of HDM05 names
/// (`HDM_bd_kickLFront1Reps_001_120` -> `bd`), else the name without
/// trailing `_<digits>` groups (CMU's `01_03` -> `01`, its subject).
pub fn actor_of(name: &str) -> String {
    hdm05_parts(name).map_or_else(|| stem(name), |(actor, _)| actor.to_string())
}

/// Two-person pairs among clip names (one rule for the whole product).
pub use interaction::pairs;

/// Seed of a dataset-level job, from the recipe seed and the job's key.
pub fn job_seed(seed: u64, key: &str) -> u64 {
    synth::output_seed(seed, key, usize::MAX, 0)
}

/// Names of the VAE's outputs for a class.
pub fn vae_outputs(group: &str, copies: u32) -> Vec<String> {
    (0..copies)
        .map(|c| format!("{group}__vae_{c:03}"))
        .collect()
}

/// Names of the interaction outputs of a pair: `<stem>__interaction_<k>_A` / `_B`.
pub fn interaction_outputs(stem: &str, copies: u32) -> Vec<String> {
    (0..copies)
        .flat_map(|k| ["A", "B"].map(|side| format!("{stem}__interaction_{k:03}_{side}")))
        .collect()
}

/// The job graph for clips `names` (in the order given) under `recipe`: the
/// jobs that make new clips (synthesis, VAE, interaction), then their
/// corrections and debiasing.
pub fn plan(recipe: &Recipe, names: &[String], seed: u64) -> Plan {
    let mut graph = Graph::default();
    // Manifest op indices: the `[[ops]]`, then `[vae]`, then `[interaction]`.
    let vae_op_index = recipe.synth.as_ref().map_or(0, |s| s.ops.len());
    if let Some(s) = &recipe.synth {
        graph.synthesize(s, names, seed);
    }
    if let Some(v) = &recipe.vae {
        graph.vae(v, names, seed, vae_op_index);
    }
    if let Some(i) = &recipe.interaction {
        graph.interaction(i, names, seed, vae_op_index + 1);
    }
    if let Some(c) = &recipe.correct {
        graph.correct(c, recipe.debias.as_ref(), names, seed);
    }
    Plan::finished(graph.jobs)
}

/// The groups of clips that get a VAE: those with at least `min_clips` clips.
fn vae_groups(v: &VaeStep, names: &[String]) -> BTreeMap<String, Vec<String>> {
    let mut groups: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for name in names {
        let group = match v.group_by {
            GroupBy::Class => class_of(name),
            GroupBy::All => "all".to_string(),
        };
        groups.entry(group).or_default().push(name.clone());
    }
    groups.retain(|_, clips| clips.len() >= v.min_clips);
    groups
}

/// How big [`plan`]'s graph would be, counted without making it (a recipe of
/// 64 ops x 1000 copies over many clips plans millions of jobs): what a
/// service checks against its quotas before planning.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PlanSize {
    /// New clips the plan makes (kinematic, VAE and interaction outputs).
    pub outputs: u64,
    /// Correction jobs (`correct_original` and `correct`), each training up to
    /// `[correct] time_budget_s`.
    pub corrections: u64,
    /// Class tracker jobs (`policy = "class"`), and second trackers of their
    /// new clips (`variant_tracker_iterations`), each training up to
    /// `[correct] tracker_budget_s`.
    pub trackers: u64,
    /// Every job of the graph.
    pub jobs: u64,
}

/// The size of `plan(recipe, names, _)` (any seed), in time linear in the
/// number of clips.
pub fn size(recipe: &Recipe, names: &[String]) -> PlanSize {
    let clips = names.len() as u64;
    let mut size = PlanSize::default();
    let mut correctable = 0u64;
    // Classes with new clips to correct (each gets a `variant_tracker`).
    let mut new_classes: std::collections::BTreeSet<String> = Default::default();
    if let Some(s) = &recipe.synth {
        let made = clips.saturating_mul(s.outputs_per_clip() as u64);
        size.jobs += clips;
        size.outputs = size.outputs.saturating_add(made);
        correctable = correctable.saturating_add(made);
        if made > 0 {
            new_classes.extend(names.iter().map(|n| class_of(n)));
        }
    }
    if let Some(v) = &recipe.vae {
        let groups = vae_groups(v, names);
        let made = (groups.len() as u64).saturating_mul(v.copies as u64);
        size.jobs += groups.len() as u64;
        size.outputs = size.outputs.saturating_add(made);
        correctable = correctable.saturating_add(made);
        if v.copies > 0 {
            // A sample's class is that of the first clip it was made from.
            new_classes.extend(groups.values().map(|clips| class_of(&clips[0])));
        }
    }
    if let Some(i) = &recipe.interaction {
        let pairs = pairs(names).len() as u64;
        size.jobs += pairs;
        size.outputs = size
            .outputs
            .saturating_add(pairs.saturating_mul(2 * i.copies as u64));
    }
    if let Some(c) = &recipe.correct {
        let by_class = c.policy == PolicyKind::Class;
        let originals = if (c.warm_start && !by_class) || recipe.debias.is_some() {
            clips
        } else {
            0
        };
        if by_class {
            let classes: std::collections::BTreeSet<String> =
                names.iter().map(|n| class_of(n)).collect();
            size.trackers = classes.len() as u64;
            if c.variant_tracker_iterations > 0 {
                size.trackers += new_classes.len() as u64;
            }
        }
        size.corrections = originals.saturating_add(correctable);
        size.jobs = size
            .jobs
            .saturating_add(size.corrections)
            .saturating_add(size.trackers);
        if recipe.debias.is_some() && clips > 0 {
            size.jobs = size.jobs.saturating_add(1).saturating_add(correctable);
        }
    }
    size
}

/// The plan under construction: its jobs so far, and the new clips they make
/// (what the correction jobs are planned over).
#[derive(Default)]
struct Graph {
    jobs: Vec<PlannedJob>,
    new_clips: Vec<NewClip>,
}

impl Graph {
    /// A job that makes `outputs` from `sources` (no dependencies).
    fn push_maker(
        &mut self,
        key: String,
        kind: JobKind,
        outputs: Vec<String>,
        sources: &[String],
        correctable: bool,
    ) {
        self.new_clips.extend(outputs.iter().map(|name| NewClip {
            name: name.clone(),
            producer: key.clone(),
            sources: sources.to_vec(),
            correctable,
        }));
        self.jobs.push(PlannedJob {
            key,
            kind,
            deps: vec![],
            outputs,
            finishes: false,
        });
    }

    /// One `synthesize` job per clip: every `[[ops]]` output of it.
    fn synthesize(&mut self, s: &synth::Recipe, names: &[String], seed: u64) {
        for clip in names {
            let outputs = s.jobs(clip, seed);
            let made: Vec<String> = outputs
                .iter()
                .map(|job| {
                    let op = s.ops[job.op_index].op.kind();
                    format!("{clip}__{:02}_{op}_{:03}", job.op_index, job.copy)
                })
                .collect();
            let kind = JobKind::Synthesize {
                clip: clip.clone(),
                ops: s.clone(),
                outputs,
            };
            self.push_maker(
                format!("synthesize:{clip}"),
                kind,
                made,
                std::slice::from_ref(clip),
                true,
            );
        }
    }

    /// One `vae` job per group of at least `min_clips` clips.
    fn vae(&mut self, v: &VaeStep, names: &[String], seed: u64, op_index: usize) {
        for (group, clips) in vae_groups(v, names) {
            let key = format!("vae:{group}");
            let outputs = vae_outputs(&group, v.copies);
            // Warm start from the best-corrected clip of the class: same
            // skeleton and action, and the policy that balances best.
            let sources = clips.clone();
            let kind = JobKind::Vae {
                group,
                clips,
                seed: job_seed(seed, &key),
                step: v.clone(),
                op_index,
            };
            self.push_maker(key, kind, outputs, &sources, true);
        }
    }

    /// One `interaction` job per pair; its outputs are not corrected (two
    /// partners are not simulated together).
    fn interaction(&mut self, i: &InteractionStep, names: &[String], seed: u64, op_index: usize) {
        for (stem, a, b) in pairs(names) {
            let key = format!("interaction:{stem}");
            let outputs = interaction_outputs(&stem, i.copies);
            let kind = JobKind::Interaction {
                pair: stem,
                a,
                b,
                seed: job_seed(seed, &key),
                step: i.clone(),
                op_index,
            };
            self.push_maker(key, kind, outputs, &[], false);
        }
    }

    /// The class trackers (`policy = "class"`), the corrected originals
    /// (when warm start or debiasing needs them), a `correct` job per
    /// correctable new clip, and the debiasing jobs.
    fn correct(
        &mut self,
        c: &CorrectStep,
        debias: Option<&debias::TrainConfig>,
        names: &[String],
        seed: u64,
    ) {
        let by_class = c.policy == PolicyKind::Class;
        if by_class {
            let mut groups: BTreeMap<String, Vec<String>> = BTreeMap::new();
            for name in names {
                groups.entry(class_of(name)).or_default().push(name.clone());
            }
            for (group, clips) in groups {
                let key = tracker_key(&group);
                self.jobs.push(PlannedJob {
                    kind: JobKind::Tracker {
                        group,
                        clips,
                        seed: job_seed(seed, &key),
                        step: c.clone(),
                    },
                    key,
                    deps: vec![],
                    outputs: vec![],
                    finishes: false,
                });
            }
        }
        let tracker_of = |clip: &str| by_class.then(|| class_of(clip));
        if (c.warm_start && !by_class) || debias.is_some() {
            for clip in names {
                let key = format!("correct_original:{clip}");
                let tracker = tracker_of(clip);
                self.jobs.push(PlannedJob {
                    kind: JobKind::CorrectOriginal {
                        clip: clip.clone(),
                        seed: job_seed(seed, &key),
                        step: c.clone(),
                        tracker: tracker.clone(),
                    },
                    key,
                    deps: tracker.iter().map(|g| tracker_key(g)).collect(),
                    outputs: vec![],
                    finishes: false,
                });
            }
        }
        // The second trackers: per class, its new clips and the jobs that made them.
        let second = by_class && c.variant_tracker_iterations > 0;
        if second {
            let mut variants: BTreeMap<String, (Vec<String>, Vec<String>)> = BTreeMap::new();
            for clip in self.new_clips.iter().filter(|n| n.correctable) {
                if let Some(group) = clip.sources.first().map(|s| class_of(s)) {
                    let (clips, makers) = variants.entry(group).or_default();
                    clips.push(clip.name.clone());
                    if !makers.contains(&clip.producer) {
                        makers.push(clip.producer.clone());
                    }
                }
            }
            for (group, (clips, makers)) in variants {
                let job_seed = job_seed(seed, &variant_tracker_key(&group));
                self.jobs
                    .push(variant_tracker_job(&group, clips, makers, job_seed, c));
            }
        }
        let mut corrected = Vec::new();
        for clip in self.new_clips.iter().filter(|n| n.correctable) {
            let key = format!("correct:{}", clip.name);
            let tracker = clip.sources.first().and_then(|s| tracker_of(s));
            let sources = if c.warm_start && tracker.is_none() {
                clip.sources.clone()
            } else {
                vec![]
            };
            let mut deps = vec![clip.producer.clone()];
            deps.extend(tracker.iter().map(|g| tracker_key(g)));
            if second {
                deps.extend(tracker.iter().map(|g| variant_tracker_key(g)));
            }
            deps.extend(sources.iter().map(|s| format!("correct_original:{s}")));
            self.jobs.push(PlannedJob {
                kind: JobKind::Correct {
                    clip: clip.name.clone(),
                    variant_tracker: second && tracker.is_some(),
                    tracker,
                    sources,
                    seed: job_seed(seed, &key),
                    step: c.clone(),
                },
                key: key.clone(),
                deps,
                outputs: vec![clip.name.clone()],
                finishes: false,
            });
            corrected.push((clip.name.clone(), key));
        }
        if let Some(config) = debias.filter(|_| !names.is_empty()) {
            self.jobs.extend(debias_jobs(names, config, corrected));
        }
    }
}

/// The key of the tracker job of class `group`.
pub fn tracker_key(group: &str) -> String {
    format!("tracker:{group}")
}

/// The key of the second tracker job of class `group`'s new clips.
pub fn variant_tracker_key(group: &str) -> String {
    format!("variant_tracker:{group}")
}

/// The `variant_tracker` job of class `group`, with seed `seed`: its new
/// `clips`, made by the jobs `makers`, judged by the class tracker, those it
/// fails trained on.
fn variant_tracker_job(
    group: &str,
    clips: Vec<String>,
    makers: Vec<String>,
    seed: u64,
    step: &CorrectStep,
) -> PlannedJob {
    let mut deps = vec![tracker_key(group)];
    deps.extend(makers);
    PlannedJob {
        key: variant_tracker_key(group),
        kind: JobKind::VariantTracker {
            group: group.to_string(),
            clips,
            seed,
            step: step.clone(),
        },
        deps,
        outputs: vec![],
        finishes: false,
    }
}

/// `debias_train` on the corrected `originals`, then a `debias_apply` per
/// `(clip, key of its correct job)`.
fn debias_jobs(
    originals: &[String],
    config: &debias::TrainConfig,
    corrected: Vec<(String, String)>,
) -> Vec<PlannedJob> {
    let train_key = "debias_train".to_string();
    let mut jobs = vec![PlannedJob {
        key: train_key.clone(),
        kind: JobKind::DebiasTrain {
            originals: originals.to_vec(),
            config: config.clone(),
        },
        deps: originals
            .iter()
            .map(|n| format!("correct_original:{n}"))
            .collect(),
        outputs: vec![],
        finishes: false,
    }];
    for (name, correct_key) in corrected {
        jobs.push(PlannedJob {
            key: format!("debias_apply:{name}"),
            kind: JobKind::DebiasApply { clip: name.clone() },
            deps: vec![correct_key, train_key.clone()],
            outputs: vec![name],
            finishes: false,
        });
    }
    jobs
}

impl Plan {
    /// The plan of `jobs` (in dependency order), each job told whether its
    /// outputs are final: no later job makes a new version of them.
    fn finished(mut jobs: Vec<PlannedJob>) -> Plan {
        let mut later: std::collections::HashSet<String> = std::collections::HashSet::new();
        for job in jobs.iter_mut().rev() {
            job.finishes = job.outputs.iter().all(|o| !later.contains(o));
            later.extend(job.outputs.iter().cloned());
        }
        Plan { jobs }
    }

    /// The job with key `key`.
    pub fn job(&self, key: &str) -> Option<&PlannedJob> {
        self.jobs.iter().find(|j| j.key == key)
    }
}

/// The correction part of a plan for clips made elsewhere (the evaluation
/// table's VAE samples and IK edits): correct every clip of `originals`, then
/// each clip of `clips` warm-started from the best corrected original, then
/// with `debias` train the debiasing network on the accepted originals and
/// apply it to the accepted corrected clips. With `policy = "class"` one
/// tracker (group `class`) is trained on the originals first and every
/// correction starts from it instead (with `variant_tracker_iterations`, a
/// clip of `clips` it fails as is from the second tracker trained on those).
/// `seed_of` gives each job's seed (the trackers' are `seed_of("tracker")`
/// and `seed_of("variant_tracker")`).
pub fn corrections(
    originals: &[String],
    clips: &[String],
    step: &CorrectStep,
    debias: Option<&debias::TrainConfig>,
    seed_of: impl Fn(&str) -> u64,
) -> Plan {
    let tracker = (step.policy == PolicyKind::Class).then(|| "class".to_string());
    let tracker_deps: Vec<String> = tracker.iter().map(|g| tracker_key(g)).collect();
    let mut jobs: Vec<PlannedJob> = tracker
        .iter()
        .map(|group| PlannedJob {
            key: tracker_key(group),
            kind: JobKind::Tracker {
                group: group.clone(),
                clips: originals.to_vec(),
                seed: seed_of("tracker"),
                step: step.clone(),
            },
            deps: vec![],
            outputs: vec![],
            finishes: false,
        })
        .collect();
    let mut original_keys = Vec::new();
    for clip in originals {
        let key = format!("correct_original:{clip}");
        original_keys.push(key.clone());
        jobs.push(PlannedJob {
            key,
            kind: JobKind::CorrectOriginal {
                clip: clip.clone(),
                seed: seed_of(clip),
                step: step.clone(),
                tracker: tracker.clone(),
            },
            deps: tracker_deps.clone(),
            outputs: vec![],
            finishes: false,
        });
    }
    let second = tracker.is_some() && step.variant_tracker_iterations > 0 && !clips.is_empty();
    if second {
        let seed = seed_of("variant_tracker");
        jobs.push(variant_tracker_job(
            "class",
            clips.to_vec(),
            vec![],
            seed,
            step,
        ));
    }
    for clip in clips {
        let (sources, deps) = match &tracker {
            Some(_) if second => {
                let mut deps = tracker_deps.clone();
                deps.push(variant_tracker_key("class"));
                (vec![], deps)
            }
            Some(_) => (vec![], tracker_deps.clone()),
            None => (originals.to_vec(), original_keys.clone()),
        };
        jobs.push(PlannedJob {
            key: format!("correct:{clip}"),
            kind: JobKind::Correct {
                clip: clip.clone(),
                variant_tracker: second,
                tracker: tracker.clone(),
                sources,
                seed: seed_of(clip),
                step: step.clone(),
            },
            deps,
            outputs: vec![clip.clone()],
            finishes: false,
        });
    }
    if let Some(config) = debias {
        let corrected = clips
            .iter()
            .map(|clip| (clip.clone(), format!("correct:{clip}")))
            .collect();
        jobs.extend(debias_jobs(originals, config, corrected));
    }
    Plan::finished(jobs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn actors_are_read_from_hdm05_names_and_else_from_the_name_stem() {
        assert_eq!(actor_of("HDM_bd_kickLFront1Reps_001_120"), "bd");
        assert_eq!(actor_of("hdm_tr_jogLeftCircle4StepsRstart_003_120"), "tr");
        assert_eq!(actor_of("01_03"), "01");
        assert_eq!(actor_of("walk_002"), "walk");
        assert_eq!(actor_of("HDM_bd"), "HDM_bd");
    }

    #[test]
    fn corrections_start_from_the_originals_or_from_one_class_tracker() {
        let (originals, clips) = (names(&["a", "b"]), names(&["s1", "s2"]));
        let debias = debias::TrainConfig::default();
        let deps = |plan: &Plan, key: &str| plan.job(key).map(|j| j.deps.clone());

        let clip = CorrectStep::default();
        let plan = corrections(&originals, &clips, &clip, Some(&debias), |_| 0);
        assert!(plan.job("tracker:class").is_none());
        assert_eq!(
            deps(&plan, "correct:s1"),
            Some(names(&["correct_original:a", "correct_original:b"]))
        );
        assert_eq!(deps(&plan, "correct_original:a"), Some(vec![]));

        let class = CorrectStep {
            policy: PolicyKind::Class,
            ..CorrectStep::default()
        };
        let plan = corrections(&originals, &clips, &class, Some(&debias), |n| {
            if n == "tracker" { 7 } else { 0 }
        });
        match plan.job("tracker:class").map(|j| &j.kind) {
            Some(JobKind::Tracker { clips, seed, .. }) => {
                assert_eq!(clips, &originals);
                assert_eq!(*seed, 7);
            }
            other => panic!("no class tracker: {other:?}"),
        }
        for key in ["correct:s1", "correct_original:b"] {
            assert_eq!(deps(&plan, key), Some(names(&["tracker:class"])), "{key}");
        }
        match plan.job("correct:s2").map(|j| &j.kind) {
            Some(JobKind::Correct {
                tracker, sources, ..
            }) => {
                assert_eq!(tracker.as_deref(), Some("class"));
                assert!(sources.is_empty());
            }
            other => panic!("no correction of s2: {other:?}"),
        }
        // The debiaser still learns from the corrected originals.
        assert!(plan.job("debias_train").is_some());
    }

    #[test]
    fn a_second_tracker_sits_between_the_class_tracker_and_the_new_clips() {
        let step = CorrectStep {
            policy: PolicyKind::Class,
            variant_tracker_iterations: 9,
            ..CorrectStep::default()
        };
        // The evaluation's plan: the new clips are given.
        let plan = corrections(&names(&["a"]), &names(&["s1", "s2"]), &step, None, |n| {
            if n == "variant_tracker" { 3 } else { 0 }
        });
        let key = variant_tracker_key("class");
        match plan.job(&key).map(|j| (&j.kind, &j.deps)) {
            Some((JobKind::VariantTracker { clips, seed, .. }, deps)) => {
                assert_eq!(clips, &names(&["s1", "s2"]));
                assert_eq!(*seed, 3);
                assert_eq!(deps, &names(&["tracker:class"]));
            }
            other => panic!("no second tracker: {other:?}"),
        }
        let s1 = plan.job("correct:s1").expect("correct:s1");
        assert_eq!(s1.deps, names(&["tracker:class", &key]));
        assert!(matches!(
            s1.kind,
            JobKind::Correct {
                variant_tracker: true,
                ..
            }
        ));
        // Originals do not wait for it.
        let original = plan.job("correct_original:a").expect("original");
        assert_eq!(original.deps, names(&["tracker:class"]));

        // The pipeline's plan: one per class with new clips, after the jobs
        // that made them.
        let recipe = Recipe::from_toml_str(
            "[[ops]]\nop = \"mirror\"\n[vae]\ncopies = 1\nmin_clips = 2\n\
             [correct]\npolicy = \"class\"\nvariant_tracker_iterations = 9\n",
        )
        .expect("recipe");
        let clips = names(&["HDM_bd_kick_001_120", "HDM_bk_kick_002_120", "walk"]);
        let plan = super::plan(&recipe, &clips, 0);
        let position = |key: &str| plan.jobs.iter().position(|j| j.key == key);
        let kick = plan
            .job("variant_tracker:kick")
            .expect("kick's second tracker");
        assert_eq!(
            kick.deps,
            names(&[
                "tracker:kick",
                "synthesize:HDM_bd_kick_001_120",
                "synthesize:HDM_bk_kick_002_120",
                "vae:kick"
            ])
        );
        for dep in &kick.deps {
            assert!(position(dep) < position("variant_tracker:kick"), "{dep}");
        }
        let walk = plan
            .job("variant_tracker:walk")
            .expect("walk's second tracker");
        assert_eq!(walk.deps, names(&["tracker:walk", "synthesize:walk"]));
        let sample = plan
            .job("correct:kick__vae_000")
            .expect("the sample's correction");
        assert!(sample.deps.contains(&"variant_tracker:kick".to_string()));
        assert!(position("variant_tracker:kick") < position("correct:kick__vae_000"));
        // Off by default: no second tracker, no dependency on one.
        let off =
            Recipe::from_toml_str("[[ops]]\nop = \"mirror\"\n[correct]\npolicy = \"class\"\n")
                .expect("recipe");
        let off = super::plan(&off, &clips, 0);
        assert!(
            !off.jobs
                .iter()
                .any(|j| j.key.starts_with("variant_tracker:")
                    || j.deps.iter().any(|d| d.starts_with("variant_tracker:")))
        );
    }
}
