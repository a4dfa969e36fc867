//! The table as files: `table.json` (the config's summary, the wall time,
//! every cell) and `table.md` (per test actor: a prediction table per model,
//! the synthesis and plausibility tables, the correction's summary).

use std::fmt::Write as _;
use std::path::Path;

use serde_json::{Value, json};

use super::{PREDICT_CONDITIONS, SetKind, Table, TableCell};
use crate::error::{EvalError, Result};
use crate::predict::data::HORIZONS_MS;
use crate::scores::SynthScores;

impl Table {
    /// The config as table.json records it (what shapes the numbers, no paths).
    pub fn config_json(&self) -> Value {
        let c = &self.config;
        let t = &c.train;
        json!({
            "classes": c.classes,
            "test_actors": c.test_actors,
            "models": c.models,
            "iterations": t.iterations,
            "epochs": t.epochs,
            "batch_size": t.batch_size,
            "lr": t.lr,
            "seeds": t.seeds,
            "max_windows": t.max_windows,
            "seq2seq_hidden": t.seq2seq_hidden,
            "gcn_hidden": t.gcn_hidden,
            "gcn_stages": t.gcn_stages,
            "noise_sigma_deg": c.noise_sigma_deg,
            "vae_iterations": c.vae_iterations,
            "vae_ablation": c.vae_ablation,
            "sets": c.sets,
            "physics": c.sets.contains(&SetKind::Physics).then_some(&c.physics),
        })
    }

    /// table.json's content.
    pub fn to_json(&self) -> Value {
        json!({ "config": self.config_json(), "seconds": self.seconds, "cells": self.cells })
    }

    /// table.md's content.
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "# motionaug eval table\n\nConfig: `{}`; {:.0} s.\n",
            self.config_json(),
            self.seconds
        );
        for actor in &self.config.test_actors {
            let row_cells: Vec<&TableCell> = self
                .cells
                .iter()
                .filter(|c| &c.test_actor == actor)
                .collect();
            if row_cells.is_empty() {
                continue;
            }
            for model in &self.config.models {
                prediction_table(&mut md, &model.to_string(), actor, &row_cells);
            }
            set_table(
                &mut md,
                &format!(
                    "Synthesis, test actor {actor}: min DTW (synth->test; test->synth) / MMD^2"
                ),
                &row_cells,
                |s| {
                    format!(
                        "{:.3}; {:.3} / {:.4}",
                        s.min_dtw.synth_to_test, s.min_dtw.test_to_synth, s.mmd.mmd2
                    )
                },
            );
            set_table(
                &mut md,
                &format!(
                    "Plausibility, test actor {actor}: foot skating m/s / mean penetration mm / floating %"
                ),
                &row_cells,
                |s| {
                    let p = &s.plausibility;
                    format!(
                        "{:.3} / {:.1} / {:.0}",
                        p.foot_skating_m_s,
                        1000.0 * p.penetration_mean_m,
                        100.0 * p.floating_fraction
                    )
                },
            );
            correction_table(&mut md, actor, &row_cells);
        }
        md
    }

    /// Writes `table.json` and `table.md` into `dir` (each atomically).
    pub fn write(&self, dir: &Path) -> Result<()> {
        let mut json = serde_json::to_vec_pretty(&self.to_json())
            .map_err(|e| EvalError::Data(format!("table.json: {e}")))?;
        json.push(b'\n');
        motion::io::write_atomic(&dir.join("table.json"), &json)?;
        motion::io::write_atomic(&dir.join("table.md"), self.to_markdown().as_bytes())?;
        Ok(())
    }
}

/// One model's prediction errors: a row per condition, a column per class.
fn prediction_table(md: &mut String, m: &str, actor: &str, row_cells: &[&TableCell]) {
    if row_cells.iter().all(|c| !c.predict.contains_key(m)) {
        return;
    }
    let _ = writeln!(
        md,
        "## Prediction error, {m}, test actor {actor} (Euler, rad; 100 / 200 / 400 ms)\n"
    );
    let mut header = String::from("| condition |");
    let mut rule = String::from("|---|");
    for c in row_cells {
        let _ = write!(
            header,
            " {} ({}/{} clips) |",
            c.class, c.train_clips, c.test_clips
        );
        rule.push_str("---|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    let made = |cond: &str| {
        row_cells
            .iter()
            .any(|c| c.predict.get(m).is_some_and(|p| p.contains_key(cond)))
    };
    let conditions = ["zero_velocity", "no_aug"]
        .into_iter()
        .chain(PREDICT_CONDITIONS.into_iter().filter(|c| made(c)));
    for cond in conditions {
        let mut line = format!("| {cond} |");
        for c in row_cells {
            let h = if cond == "zero_velocity" {
                c.zero_velocity.as_ref()
            } else {
                c.predict
                    .get(m)
                    .and_then(|p| p.get(cond))
                    .map(|r| &r.errors)
            };
            match h {
                Some(h) => {
                    let v: Vec<String> = HORIZONS_MS
                        .iter()
                        .map(|ms| match h.get(&ms.to_string()) {
                            Some(e) => format!("{e:.3}"),
                            None => "-".into(),
                        })
                        .collect();
                    let _ = write!(line, " {} |", v.join(" / "));
                }
                None => line.push_str(" - |"),
            }
        }
        let _ = writeln!(md, "{line}");
    }
    md.push('\n');
}

/// One Markdown table: a row per synthesised set, a column per class.
fn set_table(
    md: &mut String,
    title: &str,
    cells: &[&TableCell],
    show: impl Fn(&SynthScores) -> String,
) {
    let _ = writeln!(md, "## {title}\n");
    let mut header = String::from("| set |");
    let mut rule = String::from("|---|");
    for c in cells {
        let _ = write!(header, " {} |", c.class);
        rule.push_str("---|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    let mut names: Vec<&String> = cells.iter().flat_map(|c| c.synth.keys()).collect();
    names.sort();
    names.dedup();
    for name in names {
        let mut line = format!("| {name} |");
        for c in cells {
            match c.synth.get(name) {
                Some(s) => {
                    let _ = write!(line, " {} |", show(s));
                }
                None => line.push_str(" - |"),
            }
        }
        let _ = writeln!(md, "{line}");
    }
    md.push('\n');
}

/// What the correction did, a row per class (only with the physics set).
fn correction_table(md: &mut String, actor: &str, row_cells: &[&TableCell]) {
    if row_cells.iter().all(|c| c.physics.is_none()) {
        return;
    }
    let _ = writeln!(
        md,
        "## Correction, test actor {actor}\n\n| class | originals accepted | samples accepted | R_norm action 0 -> corrected | residual force ratio | PPO samples | seconds |\n|---|---|---|---|---|---|---|"
    );
    for c in row_cells {
        if let Some(p) = &c.physics {
            let _ = writeln!(
                md,
                "| {} | {}/{} | {}/{} | {:.3} -> {:.3} | {:.3} | {} | {:.0} |",
                c.class,
                p.originals_accepted,
                p.originals,
                p.samples_accepted,
                p.samples,
                p.mean_r_norm_action0,
                p.mean_r_norm,
                p.mean_residual_force_ratio,
                p.ppo_samples,
                p.seconds
            );
        }
    }
    md.push('\n');
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::predict::protocol::{ConditionResult, ModelKind};
    use crate::table::{PhysicsSummary, TableConfig};

    fn horizons(base: f64) -> BTreeMap<String, f64> {
        [("100", base), ("200", base + 1.0), ("400", base + 2.0)]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect()
    }

    fn table() -> Table {
        let no_aug = ConditionResult {
            errors: horizons(1.0),
            per_seed: vec![horizons(1.0)],
            train_clips: 3,
            train_windows: 10,
            skipped_clips: 0,
            train_seconds: vec![0.1],
            first_loss: 1.0,
            last_loss: 0.5,
        };
        let cell = TableCell {
            class: "kick".into(),
            test_actor: "bd".into(),
            train_clips: 3,
            test_clips: 1,
            zero_velocity: Some(horizons(0.5)),
            predict: [(
                "gcn".to_string(),
                [("no_aug".to_string(), no_aug)].into_iter().collect(),
            )]
            .into_iter()
            .collect(),
            physics: Some(PhysicsSummary {
                originals: 3,
                originals_accepted: 2,
                samples: 4,
                samples_accepted: 1,
                ..PhysicsSummary::default()
            }),
            ..TableCell::default()
        };
        Table {
            config: TableConfig {
                classes: vec!["kick".into()],
                models: vec![ModelKind::Seq2seq, ModelKind::Gcn],
                ..TableConfig::default()
            },
            cells: vec![cell],
            seconds: 12.0,
        }
    }

    #[test]
    fn markdown_has_a_table_per_trained_model_and_the_correction() {
        let md = table().to_markdown();
        assert!(
            md.starts_with("# motionaug eval table\n\nConfig: `{"),
            "{md}"
        );
        assert!(md.contains("`; 12 s.\n"), "{md}");
        // Only the model that was trained gets a table.
        assert!(!md.contains("seq2seq, test actor"), "{md}");
        assert!(md.contains(
            "## Prediction error, gcn, test actor bd (Euler, rad; 100 / 200 / 400 ms)\n\n\
             | condition | kick (3/1 clips) |\n|---|---|\n\
             | zero_velocity | 0.500 / 1.500 / 2.500 |\n\
             | no_aug | 1.000 / 2.000 / 3.000 |\n"
        ));
        assert!(md.contains("## Correction, test actor bd"), "{md}");
        assert!(md.contains("| kick | 2/3 | 1/4 |"), "{md}");
    }

    #[test]
    fn json_records_what_shapes_the_numbers() {
        let t = table();
        let v = t.to_json();
        assert_eq!(v["seconds"], 12.0);
        assert_eq!(v["config"]["models"], json!(["seq2seq", "gcn"]));
        assert_eq!(v["config"]["sets"], json!(["noise", "ik", "vae"]));
        // No physics set, no physics config; no paths.
        assert!(v["config"]["physics"].is_null());
        assert!(v["config"].get("data").is_none());
        assert_eq!(v["cells"][0]["physics"]["samples"], 4);
    }
}
