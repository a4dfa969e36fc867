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
//! * `correct_original` (one per source clip, when `[correct]` warm-starts or
//!   `[debias]` is on): the source clip.
//! * `correct` (one per new clip, except interaction outputs: two partners are
//!   not simulated together): the job that made the clip, and with warm start
//!   the corrections of the clips it was made from (its source clip; every
//!   clip of the class for a VAE sample), the best of which warm-starts it.
//! * `debias_train`: every `correct_original`.
//! * `debias_apply` (one per corrected clip): its `correct` and `debias_train`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::recipe::{CorrectStep, GroupBy, InteractionStep, Recipe, VaeStep};

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
    CorrectOriginal {
        clip: String,
        seed: u64,
        step: CorrectStep,
    },
    Correct {
        clip: String,
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
            JobKind::Vae { clips, .. } => clips.iter().map(String::as_str).collect(),
            JobKind::Interaction { a, b, .. } => vec![a, b],
            JobKind::DebiasTrain { originals, .. } => {
                originals.iter().map(String::as_str).collect()
            }
            JobKind::Correct { .. } | JobKind::DebiasApply { .. } => vec![],
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
            JobKind::Vae { .. } | JobKind::DebiasTrain { .. } => None,
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

/// The class of a clip name: the class part of HDM05 names
/// (`HDM_bd_kickLFront1Reps_001_120` -> `kickLFront1Reps`), else the name
/// without trailing `_<digits>` groups.
pub fn class_of(name: &str) -> String {
    let parts: Vec<&str> = name.split('_').collect();
    if parts.len() >= 4 && parts[0].eq_ignore_ascii_case("HDM") {
        return parts[2].to_string();
    }
    let mut end = parts.len();
    while end > 1 && parts[end - 1].chars().all(|c| c.is_ascii_digit()) {
        end -= 1;
    }
    parts[..end].join("_")
}

/// Two-person pairs among clip names: `<stem>_A` with `<stem>_B` (the CMU
/// pairs' naming). Returns `(stem, a, b)` sorted by stem.
pub fn pairs(names: &[String]) -> Vec<(String, String, String)> {
    let mut out = Vec::new();
    for a in names {
        let Some(stem) = a.strip_suffix("_A").or_else(|| a.strip_suffix("_a")) else {
            continue;
        };
        if let Some(b) = names
            .iter()
            .find(|b| b.as_str() == format!("{stem}_B") || b.as_str() == format!("{stem}_b"))
        {
            out.push((stem.to_string(), a.clone(), b.clone()));
        }
    }
    out.sort();
    out
}

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

/// The job graph for clips `names` (in the order given) under `recipe`.
pub fn plan(recipe: &Recipe, names: &[String], seed: u64) -> Plan {
    let mut jobs = Vec::new();
    let mut new_clips = Vec::new();
    // Manifest op indices: the `[[ops]]`, then `[vae]`, then `[interaction]`.
    let vae_op_index = recipe.synth.as_ref().map_or(0, |s| s.ops.len());

    if let Some(s) = &recipe.synth {
        for clip in names {
            let outputs = s.jobs(clip, seed);
            let key = format!("synthesize:{clip}");
            let made: Vec<String> = outputs
                .iter()
                .map(|job| {
                    let op = s.ops[job.op_index].op.kind();
                    format!("{clip}__{:02}_{op}_{:03}", job.op_index, job.copy)
                })
                .collect();
            new_clips.extend(made.iter().map(|name| NewClip {
                name: name.clone(),
                producer: key.clone(),
                sources: vec![clip.clone()],
                correctable: true,
            }));
            jobs.push(PlannedJob {
                key,
                kind: JobKind::Synthesize {
                    clip: clip.clone(),
                    ops: s.clone(),
                    outputs,
                },
                deps: vec![],
                outputs: made,
                finishes: false,
            });
        }
    }

    if let Some(v) = &recipe.vae {
        let mut groups: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for name in names {
            let group = match v.group_by {
                GroupBy::Class => class_of(name),
                GroupBy::All => "all".to_string(),
            };
            groups.entry(group).or_default().push(name.clone());
        }
        for (group, clips) in groups {
            if clips.len() < v.min_clips {
                continue;
            }
            let key = format!("vae:{group}");
            let outputs = vae_outputs(&group, v.copies);
            new_clips.extend(outputs.iter().map(|name| NewClip {
                name: name.clone(),
                producer: key.clone(),
                // Warm start from the best-corrected clip of the class: same
                // skeleton and action, and the policy that balances best.
                sources: clips.clone(),
                correctable: true,
            }));
            jobs.push(PlannedJob {
                key: key.clone(),
                kind: JobKind::Vae {
                    group: group.clone(),
                    clips,
                    seed: job_seed(seed, &key),
                    step: v.clone(),
                    op_index: vae_op_index,
                },
                deps: vec![],
                outputs,
                finishes: false,
            });
        }
    }

    if let Some(i) = &recipe.interaction {
        for (stem, a, b) in pairs(names) {
            let key = format!("interaction:{stem}");
            let outputs = interaction_outputs(&stem, i.copies);
            new_clips.extend(outputs.iter().map(|name| NewClip {
                name: name.clone(),
                producer: key.clone(),
                sources: vec![],
                correctable: false,
            }));
            jobs.push(PlannedJob {
                key: key.clone(),
                kind: JobKind::Interaction {
                    pair: stem,
                    a,
                    b,
                    seed: job_seed(seed, &key),
                    step: i.clone(),
                    op_index: vae_op_index + 1,
                },
                deps: vec![],
                outputs,
                finishes: false,
            });
        }
    }

    let Some(c) = &recipe.correct else {
        return Plan::finished(jobs);
    };
    let originals_needed = c.warm_start || recipe.debias.is_some();
    if originals_needed {
        for clip in names {
            let key = format!("correct_original:{clip}");
            jobs.push(PlannedJob {
                key: key.clone(),
                kind: JobKind::CorrectOriginal {
                    clip: clip.clone(),
                    seed: job_seed(seed, &key),
                    step: c.clone(),
                },
                deps: vec![],
                outputs: vec![],
                finishes: false,
            });
        }
    }
    let mut corrected = Vec::new();
    for clip in new_clips.iter().filter(|n| n.correctable) {
        let key = format!("correct:{}", clip.name);
        let mut deps = vec![clip.producer.clone()];
        let sources = if c.warm_start {
            clip.sources.clone()
        } else {
            vec![]
        };
        deps.extend(sources.iter().map(|s| format!("correct_original:{s}")));
        jobs.push(PlannedJob {
            key: key.clone(),
            kind: JobKind::Correct {
                clip: clip.name.clone(),
                sources,
                seed: job_seed(seed, &key),
                step: c.clone(),
            },
            deps,
            outputs: vec![clip.name.clone()],
            finishes: false,
        });
        corrected.push((clip.name.clone(), key));
    }
    if let Some(config) = recipe.debias.as_ref().filter(|_| !names.is_empty()) {
        let train_key = "debias_train".to_string();
        jobs.push(PlannedJob {
            key: train_key.clone(),
            kind: JobKind::DebiasTrain {
                originals: names.to_vec(),
                config: config.clone(),
            },
            deps: names
                .iter()
                .map(|n| format!("correct_original:{n}"))
                .collect(),
            outputs: vec![],
            finishes: false,
        });
        for (name, correct_key) in corrected {
            jobs.push(PlannedJob {
                key: format!("debias_apply:{name}"),
                kind: JobKind::DebiasApply { clip: name.clone() },
                deps: vec![correct_key, train_key.clone()],
                outputs: vec![name],
                finishes: false,
            });
        }
    }
    Plan::finished(jobs)
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
/// table's VAE samples): correct every clip of `originals`, then each clip of
/// `clips` warm-started from the best corrected original, then with `debias`
/// train the debiasing network on the accepted originals and apply it to the
/// accepted corrected clips. `seed_of` gives each correction's seed.
pub fn corrections(
    originals: &[String],
    clips: &[String],
    step: &CorrectStep,
    debias: Option<&debias::TrainConfig>,
    seed_of: impl Fn(&str) -> u64,
) -> Plan {
    let mut jobs: Vec<PlannedJob> = originals
        .iter()
        .map(|clip| PlannedJob {
            key: format!("correct_original:{clip}"),
            kind: JobKind::CorrectOriginal {
                clip: clip.clone(),
                seed: seed_of(clip),
                step: step.clone(),
            },
            deps: vec![],
            outputs: vec![],
            finishes: false,
        })
        .collect();
    let original_keys: Vec<String> = jobs.iter().map(|j| j.key.clone()).collect();
    for clip in clips {
        jobs.push(PlannedJob {
            key: format!("correct:{clip}"),
            kind: JobKind::Correct {
                clip: clip.clone(),
                sources: originals.to_vec(),
                seed: seed_of(clip),
                step: step.clone(),
            },
            deps: original_keys.clone(),
            outputs: vec![clip.clone()],
            finishes: false,
        });
    }
    if let Some(config) = debias {
        jobs.push(PlannedJob {
            key: "debias_train".into(),
            kind: JobKind::DebiasTrain {
                originals: originals.to_vec(),
                config: config.clone(),
            },
            deps: original_keys,
            outputs: vec![],
            finishes: false,
        });
        for clip in clips {
            jobs.push(PlannedJob {
                key: format!("debias_apply:{clip}"),
                kind: JobKind::DebiasApply { clip: clip.clone() },
                deps: vec![format!("correct:{clip}"), "debias_train".into()],
                outputs: vec![clip.clone()],
                finishes: false,
            });
        }
    }
    Plan::finished(jobs)
}
