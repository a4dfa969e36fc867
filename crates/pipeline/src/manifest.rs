//! One line of `manifest.json`: the synthesis entry (unchanged when a recipe has
//! no `[correct]`, so kinematic-only manifests stay as they were), plus what
//! correction and debiasing did to the clip.

use serde::{Deserialize, Serialize};

/// What physical correction measured for one output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CorrectionSummary {
    pub r_norm: f64,
    pub mean_reward: f64,
    pub residual_force_ratio: f64,
    pub accepted: bool,
    pub samples: u64,
    pub wall_s: f64,
    pub foot_skating_before_m_s: f64,
    pub foot_skating_after_m_s: f64,
    pub penetration_before_m: f64,
    pub penetration_after_m: f64,
    pub floating_before: f64,
    pub floating_after: f64,
    /// Each acceptance criterion with its value, limit and verdict (as in the report).
    #[serde(default)]
    pub criteria: Vec<correct::Criterion>,
    /// The failed criteria, one line each (empty when accepted).
    #[serde(default)]
    pub rejected_because: Vec<String>,
    /// The job's report, relative to the output directory (CLI only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report: Option<String>,
}

impl CorrectionSummary {
    pub fn new(report: &correct::Report, path: Option<String>) -> Self {
        let (b, a) = (&report.plausibility_before, &report.plausibility_after);
        CorrectionSummary {
            r_norm: report.r_norm,
            mean_reward: report.mean_reward,
            residual_force_ratio: report.residual_force_ratio,
            accepted: report.accepted,
            samples: report.samples,
            wall_s: report.wall_s,
            foot_skating_before_m_s: b.foot_skating_m_s,
            foot_skating_after_m_s: a.foot_skating_m_s,
            penetration_before_m: b.penetration_mean_m,
            penetration_after_m: a.penetration_mean_m,
            floating_before: b.floating_fraction,
            floating_after: a.floating_fraction,
            criteria: report.criteria.clone(),
            rejected_because: report.rejected_because.clone(),
            report: path,
        }
    }
}

fn is_false(b: &bool) -> bool {
    !*b
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestEntry {
    #[serde(flatten)]
    pub synth: synth::ManifestEntry,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction: Option<CorrectionSummary>,
    #[serde(default, skip_serializing_if = "is_false")]
    pub debiased: bool,
}

/// Sort entries as the manifest lists them: by source, op index, copy, file.
pub fn sort(entries: &mut [ManifestEntry]) {
    entries.sort_by(|a, b| {
        let key = |e: &ManifestEntry| {
            (
                e.synth.source.clone(),
                e.synth.op_index,
                e.synth.copy,
                e.synth.file.clone(),
            )
        };
        key(a).cmp(&key(b))
    });
}
