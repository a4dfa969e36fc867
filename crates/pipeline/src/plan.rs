//! The augmentation as a graph of jobs, computed from the recipe and the clip
//! names alone, so that the CLI (which runs it in one process) and the
//! coordinator (which stores it in Postgres and hands jobs to workers) run the
//! same graph with the same names and seeds.
//!
//! Jobs and what they need:
//! * `synthesize` (one per clip, op and copy): the source clip.
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

use crate::recipe::{GroupBy, Recipe};

/// What one job does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum JobKind {
    Synthesize {
        clip: String,
        job: synth::Job,
    },
    Vae {
        group: String,
        clips: Vec<String>,
        seed: u64,
    },
    Interaction {
        pair: String,
        a: String,
        b: String,
        seed: u64,
    },
    CorrectOriginal {
        clip: String,
        seed: u64,
    },
    Correct {
        clip: String,
        /// Originals whose corrected policy may warm-start this one (with
        /// `[correct] warm_start`): the clip a variant was made from, or every
        /// clip of a VAE sample's class; the runner takes the best corrected
        /// one ([`crate::stages::best_warm_start`]).
        #[serde(default)]
        sources: Vec<String>,
        seed: u64,
    },
    DebiasTrain {
        originals: Vec<String>,
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

    if let Some(s) = &recipe.synth {
        for clip in names {
            for job in s.jobs(clip, seed) {
                let op = s.ops[job.op_index].op.kind();
                let name = format!("{clip}__{:02}_{op}_{:03}", job.op_index, job.copy);
                let key = format!("synthesize:{name}");
                new_clips.push(NewClip {
                    name: name.clone(),
                    producer: key.clone(),
                    sources: vec![clip.clone()],
                    correctable: true,
                });
                jobs.push(PlannedJob {
                    key,
                    kind: JobKind::Synthesize {
                        clip: clip.clone(),
                        job,
                    },
                    deps: vec![],
                    outputs: vec![name],
                });
            }
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
                },
                deps: vec![],
                outputs,
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
                },
                deps: vec![],
                outputs,
            });
        }
    }

    let Some(c) = &recipe.correct else {
        return Plan { jobs };
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
                },
                deps: vec![],
                outputs: vec![],
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
            },
            deps,
            outputs: vec![clip.name.clone()],
        });
        corrected.push((clip.name.clone(), key));
    }
    if recipe.debias.is_some() && !names.is_empty() {
        let train_key = "debias_train".to_string();
        jobs.push(PlannedJob {
            key: train_key.clone(),
            kind: JobKind::DebiasTrain {
                originals: names.to_vec(),
            },
            deps: names
                .iter()
                .map(|n| format!("correct_original:{n}"))
                .collect(),
            outputs: vec![],
        });
        for (name, correct_key) in corrected {
            jobs.push(PlannedJob {
                key: format!("debias_apply:{name}"),
                kind: JobKind::DebiasApply { clip: name.clone() },
                deps: vec![correct_key, train_key.clone()],
                outputs: vec![name],
            });
        }
    }
    Plan { jobs }
}
