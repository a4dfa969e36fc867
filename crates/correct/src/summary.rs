//! The corrections of a class in one table: how many were accepted, which
//! criterion rejected the others, what correction did to plausibility, and
//! what it cost. Built from the reports alone, so a table can be made again
//! from the `report.json` files of a finished run.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::report::Report;

/// Mean of a plausibility figure before and after correction.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BeforeAfter {
    pub before: f64,
    pub after: f64,
}

/// The corrections of one class.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ClassSummary {
    pub class: String,
    pub clips: usize,
    pub accepted: usize,
    /// Criterion name -> clips that passed it.
    pub passed: BTreeMap<String, usize>,
    pub mean_residual_force_ratio: f64,
    pub mean_r_norm: f64,
    pub foot_skating_m_s: BeforeAfter,
    pub penetration_mean_m: BeforeAfter,
    pub floating_fraction: BeforeAfter,
    /// Mean fraction of planted foot frames standing on the sole, after.
    pub sole_flat_fraction: f64,
    /// The same on the inputs' own feet (reports that measured it).
    #[serde(default)]
    pub sole_flat_fraction_before: Option<f64>,
    /// Mean and total training wall time per clip, seconds.
    pub mean_wall_s: f64,
    pub total_wall_s: f64,
    /// Wall time of the whole row as it ran (clips side by side, reused
    /// ones), seconds, when the runner measured it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elapsed_s: Option<f64>,
    pub mean_samples: f64,
    /// Clips trained with the sole reward's sliding term.
    #[serde(default)]
    pub sliding_term: usize,
}

impl ClassSummary {
    pub fn of(class: &str, reports: &[Report]) -> ClassSummary {
        let n = reports.len().max(1) as f64;
        let mean = |f: &dyn Fn(&Report) -> f64| reports.iter().map(f).sum::<f64>() / n;
        let both = |f: &dyn Fn(&motion::metrics::Plausibility) -> f64| BeforeAfter {
            before: mean(&|r| f(&r.plausibility_before)),
            after: mean(&|r| f(&r.plausibility_after)),
        };
        let mut passed = BTreeMap::new();
        for r in reports {
            for c in &r.criteria {
                *passed.entry(c.name.clone()).or_insert(0) += usize::from(c.passed);
            }
        }
        let criterion = |r: &Report, name: &str| {
            r.criteria
                .iter()
                .find(|c| c.name == name)
                .map_or(0.0, |c| c.value)
        };
        ClassSummary {
            class: class.to_string(),
            clips: reports.len(),
            accepted: reports.iter().filter(|r| r.accepted).count(),
            passed,
            mean_residual_force_ratio: mean(&|r| r.residual_force_ratio),
            mean_r_norm: mean(&|r| r.r_norm),
            foot_skating_m_s: both(&|p| p.foot_skating_m_s),
            penetration_mean_m: both(&|p| p.penetration_mean_m),
            floating_fraction: both(&|p| p.floating_fraction),
            sole_flat_fraction: mean(&|r| criterion(r, "soles_flat")),
            sole_flat_fraction_before: {
                let known: Vec<f64> = reports.iter().filter_map(|r| r.soles_flat_before).collect();
                (!known.is_empty()).then(|| known.iter().sum::<f64>() / known.len() as f64)
            },
            mean_wall_s: mean(&|r| r.wall_s),
            total_wall_s: reports.iter().map(|r| r.wall_s).sum(),
            elapsed_s: None,
            mean_samples: mean(&|r| r.samples as f64),
            sliding_term: reports.iter().filter(|r| r.skate_scale_m_s > 0.0).count(),
        }
    }

    /// The row with the wall time it took as run.
    pub fn elapsed(self, seconds: f64) -> ClassSummary {
        ClassSummary {
            elapsed_s: Some(seconds),
            ..self
        }
    }
}

/// The criteria in report order.
pub const CRITERIA: [&str; 5] = [
    "no_fall",
    "mean_reward",
    "residual_force",
    "foot_skating",
    "soles_flat",
];

/// One row per class, as a Markdown table.
pub fn to_markdown(rows: &[ClassSummary]) -> String {
    let mut s = String::from(
        "| class | clips | accepted | no fall | reward | residual | skating | soles | \
         residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % | \
         wall s / clip | wall s total (elapsed) |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let passed: Vec<String> = CRITERIA
            .iter()
            .map(|c| format!("{}", r.passed.get(*c).copied().unwrap_or(0)))
            .collect();
        s += &format!(
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.3} -> {:.3} | {:.1} -> {:.1} | \
             {:.0} -> {:.0} | {}{:.0} | {:.0} | {:.0}{} |\n",
            r.class,
            r.clips,
            r.accepted,
            passed.join(" | "),
            r.mean_residual_force_ratio,
            r.mean_r_norm,
            r.foot_skating_m_s.before,
            r.foot_skating_m_s.after,
            r.penetration_mean_m.before * 1000.0,
            r.penetration_mean_m.after * 1000.0,
            r.floating_fraction.before * 100.0,
            r.floating_fraction.after * 100.0,
            r.sole_flat_fraction_before
                .map_or(String::new(), |b| format!("{:.0} -> ", b * 100.0)),
            r.sole_flat_fraction * 100.0,
            r.mean_wall_s,
            r.total_wall_s,
            r.elapsed_s.map_or(String::new(), |e| format!(" ({e:.0})")),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_elapsed_time_of_a_row_shows_beside_its_total() {
        let last_line = |row: &ClassSummary| {
            let md = to_markdown(std::slice::from_ref(row));
            md.lines().last().unwrap_or_default().to_string()
        };
        let row = ClassSummary::of("kick", &[]);
        assert!(row.elapsed_s.is_none());
        assert!(!last_line(&row).contains('('), "{}", last_line(&row));
        let row = row.elapsed(42.4);
        assert!(last_line(&row).ends_with(" (42) |"), "{}", last_line(&row));
    }
}
