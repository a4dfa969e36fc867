//! The table as files: `table.json` (the config's summary, the wall time,
//! every cell) and `table.md` (per test actor: a prediction table per model,
//! the synthesis and plausibility tables, the correction's summary).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use serde_json::{Value, json};

use super::paper::{PAPER_ROWS, PaperClass, paper_class};
use super::{PREDICT_CONDITIONS, SetKind, Table, TableCell, TableConfig};
use crate::error::{EvalError, Result};
use crate::predict::data::HORIZONS_MS;
use crate::predict::protocol::Horizons;
use crate::scores::SynthScores;

impl TableConfig {
    /// The config as table.json records it (what shapes the numbers, no paths).
    pub fn to_json(&self) -> Value {
        let c = self;
        let t = &c.train;
        let mut v = json!({
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
            "vae_smooth_s": c.vae_smooth_s,
            "sets": c.sets,
            "physics": c.sets.contains(&SetKind::Physics).then_some(&c.physics),
        });
        // Only when set, so that tables saved before each existed still
        // resume and merge.
        if let Some(map) = v.as_object_mut() {
            if let Some(n) = c.vae_near_members {
                map.insert("vae_near_members".into(), json!(n));
            }
            if c.vae_mixed_contact_weight > 0.0 {
                map.insert(
                    "vae_mixed_contact_weight".into(),
                    json!(c.vae_mixed_contact_weight),
                );
            }
            if c.vae_mixed_sole_weight > 0.0 {
                map.insert(
                    "vae_mixed_sole_weight".into(),
                    json!(c.vae_mixed_sole_weight),
                );
            }
            if c.vae_mixed_travel_weight > 0.0 {
                map.insert(
                    "vae_mixed_travel_weight".into(),
                    json!(c.vae_mixed_travel_weight),
                );
            }
            if c.vae_mixed_balance_weight > 0.0 {
                map.insert(
                    "vae_mixed_balance_weight".into(),
                    json!(c.vae_mixed_balance_weight),
                );
            }
            if let Some(w) = c.vae_skating_weight {
                map.insert("vae_skating_weight".into(), json!(w));
            }
            if c.vae_mixed_motion_weight > 0.0 {
                map.insert(
                    "vae_mixed_motion_weight".into(),
                    json!(c.vae_mixed_motion_weight),
                );
            }
            if !c.vae_plant_root {
                map.insert("vae_plant_root".into(), json!(false));
            }
            // Tables before session 33 trained on the captured floors.
            if c.vae_level_floor {
                map.insert("vae_level_floor".into(), json!(true));
            }
            if c.kept_rows {
                map.insert("kept_rows".into(), json!(true));
            }
            // A cell without predictions must not pass for one with them.
            if !c.predict {
                map.insert("predict".into(), json!(false));
            }
        }
        v
    }

    /// What shapes one cell's numbers: the config but for which classes and
    /// test actors the table has (a finished cell is reused when its key is
    /// this).
    pub fn cell_key(&self) -> Value {
        let mut v = self.to_json();
        if let Some(map) = v.as_object_mut() {
            map.remove("classes");
            map.remove("test_actors");
        }
        v
    }
}

impl Table {
    /// The config as table.json records it.
    pub fn config_json(&self) -> Value {
        self.config.to_json()
    }

    /// table.json's content.
    pub fn to_json(&self) -> Value {
        json!({ "config": self.config_json(), "seconds": self.seconds, "cells": self.cells })
    }

    /// table.md's content.
    pub fn to_markdown(&self) -> String {
        let models: Vec<String> = self.config.models.iter().map(|m| m.to_string()).collect();
        markdown(
            &self.config_json(),
            self.seconds,
            &self.cells,
            &Layout {
                models: &models,
                test_actors: &self.config.test_actors,
                seeds: self.config.train.seeds.len(),
            },
        )
    }

    /// Writes `table.json` and `table.md` into `dir` (each atomically).
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_files(dir, &self.to_json(), &self.to_markdown())
    }
}

/// Writes a table's `table.json` (pretty, newline-terminated) and `table.md`
/// into `dir`, each atomically: [`Table::write`] and `SavedTable::write`.
pub(super) fn write_files(dir: &Path, json: &Value, markdown: &str) -> Result<()> {
    let mut bytes =
        serde_json::to_vec_pretty(json).map_err(|e| EvalError::Data(format!("table.json: {e}")))?;
    bytes.push(b'\n');
    motion::io::write_atomic(&dir.join("table.json"), &bytes)?;
    motion::io::write_atomic(&dir.join("table.md"), markdown.as_bytes())?;
    Ok(())
}

/// What table.md lays out besides the cells: the models, the test actors in
/// order, and how many seeds each condition was trained with.
pub(super) struct Layout<'a> {
    pub models: &'a [String],
    pub test_actors: &'a [String],
    pub seeds: usize,
}

/// table.md's content for a table whose config reads `config_json`, computed
/// in `seconds` (a run's, or the runs' summed for a merged table).
pub(super) fn markdown(
    config_json: &Value,
    seconds: f64,
    cells: &[TableCell],
    layout: &Layout<'_>,
) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# motionaug eval table\n\nConfig: `{}`; {:.0} s.\n",
        config_json, seconds
    );
    let runs_per_class = layout.seeds.max(1)
        * layout
            .test_actors
            .iter()
            .filter(|a| cells.iter().any(|c| &c.test_actor == *a))
            .count();
    if runs_per_class > 1 {
        for model in layout.models {
            aggregate_tables(&mut md, model, cells);
        }
    }
    for actor in layout.test_actors {
        let row_cells: Vec<&TableCell> = cells.iter().filter(|c| &c.test_actor == actor).collect();
        if row_cells.is_empty() {
            continue;
        }
        for model in layout.models {
            prediction_table(&mut md, model, actor, &row_cells);
        }
        set_table(
            &mut md,
            &format!("Synthesis, test actor {actor}: min DTW (synth->test; test->synth) / MMD^2"),
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
                "Plausibility, test actor {actor}: foot skating m/s / mean penetration mm / floating % / pose speed m/s (joints relative to the root; near 0 = frozen clips)"
            ),
            &row_cells,
            |s| {
                let p = &s.plausibility;
                format!(
                    "{:.3} / {:.1} / {:.0} / {:.2}",
                    p.foot_skating_m_s,
                    1000.0 * p.penetration_mean_m,
                    100.0 * p.floating_fraction,
                    p.pose_speed_m_s
                )
            },
        );
        correction_table(&mut md, actor, &row_cells);
    }
    md
}

/// A Markdown table's header line and rule: `first` over the row names, then
/// one column per entry of `columns`.
fn header_row(md: &mut String, first: &str, columns: impl Iterator<Item = String>) {
    let mut header = format!("| {first} |");
    let mut rule = String::from("|---|");
    for c in columns {
        let _ = write!(header, " {c} |");
        rule.push_str("---|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
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
    header_row(
        md,
        "condition",
        row_cells
            .iter()
            .map(|c| format!("{} ({}/{} clips)", c.class, c.train_clips, c.test_clips)),
    );
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

/// The full method's row: VAE & IK corrected and debiased, else the best
/// combination that was made.
const FULL_METHOD: [&str; 3] = ["vae_ik_debiased", "vae_debiased", "ik_debiased"];

/// Mean and sample standard deviation (0 for one value).
fn mean_sd(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n.max(1.0);
    if values.len() < 2 {
        return (mean, 0.0);
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// One condition's errors of one model and class, by (test actor, seed
/// index): the runs the aggregate tables average and pair.
fn runs<'a>(
    cells: &[&'a TableCell],
    model: &str,
    cond: &str,
) -> BTreeMap<(String, usize), &'a Horizons> {
    let mut out = BTreeMap::new();
    for c in cells {
        if let Some(r) = c.predict.get(model).and_then(|p| p.get(cond)) {
            for (i, h) in r.per_seed.iter().enumerate() {
                out.insert((c.test_actor.clone(), i), h);
            }
        }
    }
    out
}

/// Over test actors and seeds, for one model: the mean and spread of every
/// condition per class, the condition with the lowest mean per class, and the
/// full method's paired differences to the rows it must beat.
fn aggregate_tables(md: &mut String, m: &str, all: &[TableCell]) {
    let mut classes: Vec<&str> = Vec::new();
    for c in all {
        if !classes.contains(&c.class.as_str()) {
            classes.push(&c.class);
        }
    }
    let by_class: Vec<(&str, Vec<&TableCell>)> = classes
        .iter()
        .map(|k| (*k, all.iter().filter(|c| c.class == *k).collect()))
        .collect();
    let made = |cond: &str| {
        all.iter()
            .any(|c| c.predict.get(m).is_some_and(|p| p.contains_key(cond)))
    };
    if !made("no_aug") {
        return;
    }
    let conditions: Vec<&str> = ["no_aug"]
        .into_iter()
        .chain(PREDICT_CONDITIONS.into_iter().filter(|c| made(c)))
        .collect();
    let _ = writeln!(
        md,
        "## Prediction error, {m}, over test actors and seeds: mean +- sd (Euler, rad; 100 / 200 / 400 ms)\n"
    );
    header_row(
        md,
        "condition",
        by_class
            .iter()
            .map(|(class, cells)| format!("{class} (n = {})", runs(cells, m, "no_aug").len())),
    );
    // (class, condition) -> mean per horizon, for the ranking below.
    let mut means: BTreeMap<(&str, &str), Vec<f64>> = BTreeMap::new();
    for cond in &conditions {
        let mut line = format!("| {cond} |");
        for (class, cells) in &by_class {
            let r = runs(cells, m, cond);
            if r.is_empty() {
                line.push_str(" - |");
                continue;
            }
            let cols: Vec<String> = HORIZONS_MS
                .iter()
                .map(|ms| {
                    let v: Vec<f64> = r
                        .values()
                        .filter_map(|h| h.get(&ms.to_string()).copied())
                        .collect();
                    let (mean, sd) = mean_sd(&v);
                    means.entry((*class, *cond)).or_default().push(mean);
                    format!("{mean:.3} +- {sd:.3}")
                })
                .collect();
            let _ = write!(line, " {} |", cols.join(" / "));
        }
        let _ = writeln!(md, "{line}");
    }
    md.push('\n');

    let _ = writeln!(md, "Lowest mean error per class (100 / 200 / 400 ms):\n");
    for (class, _) in &by_class {
        let best: Vec<String> = (0..HORIZONS_MS.len())
            .map(|i| {
                conditions
                    .iter()
                    .filter_map(|cond| Some((*cond, *means.get(&(*class, *cond))?.get(i)?)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map_or("-".to_string(), |(cond, _)| cond.to_string())
            })
            .collect();
        let _ = writeln!(md, "- {class}: {}", best.join(" / "));
    }
    md.push('\n');

    let Some(full) = FULL_METHOD.into_iter().find(|c| made(c)) else {
        return;
    };
    let stem = full.trim_end_matches("_debiased");
    // The same synthesis as made: the VAE's set is called vae_near.
    let as_made = if stem == "vae" { "vae_near" } else { stem };
    let others: Vec<String> = [
        "no_aug".to_string(),
        "noise".to_string(),
        as_made.to_string(),
    ]
    .into_iter()
    .chain([format!("{stem}_sub"), format!("{stem}_corrected")])
    .filter(|c| made(c))
    .collect();
    let _ = writeln!(
        md,
        "Paired differences, {full} minus each row, over the same (test actor, seed) runs: mean +- sd; * where |mean| > 2 sd / sqrt(n) (the difference exceeds the spread):\n"
    );
    header_row(
        md,
        "minus",
        by_class.iter().map(|(class, _)| class.to_string()),
    );
    for other in &others {
        paired_row(md, other, &by_class, m, full, other);
    }
    md.push('\n');

    // What correction and debiasing did to each set: against the same clips
    // uncorrected (`_sub`), paired the same way.
    let effects = stage_pairs(|stem| {
        ["corrected", "debiased"].map(|stage| (format!("{stem}_{stage}"), format!("{stem}_sub")))
    });
    let heading = "Paired differences, each corrected or debiased set minus the same clips uncorrected (`_sub`), over the same runs; * as above:";
    pairs_section(md, heading, &effects, &by_class, m, &made);

    // With the kept rows: rejecting clips and correcting the rest, apart.
    let apart = stage_pairs(|stem| {
        [
            (format!("{stem}_kept"), format!("{stem}_sub")),
            (format!("{stem}_corrected"), format!("{stem}_kept")),
        ]
    });
    let heading = "What rejection and correction each did: the accepted clips as made (`_kept`) minus all of them (`_sub`), and the accepted clips corrected minus as made; * as above:";
    pairs_section(md, heading, &apart, &by_class, m, &made);

    beside_the_paper(md, m, &by_class);
}

/// `(a, b)` pairs of rows for each corrected set (IK edits, VAE samples, both).
fn stage_pairs(pairs: impl Fn(&str) -> [(String, String); 2]) -> Vec<(String, String)> {
    ["ik", "vae", "vae_ik"]
        .into_iter()
        .flat_map(pairs)
        .collect()
}

/// A table of `a - b` paired differences under `heading`, one line per pair
/// whose rows were both made (nothing when none was).
fn pairs_section(
    md: &mut String,
    heading: &str,
    pairs: &[(String, String)],
    by_class: &[(&str, Vec<&TableCell>)],
    m: &str,
    made: &dyn Fn(&str) -> bool,
) {
    let pairs: Vec<&(String, String)> = pairs.iter().filter(|(a, b)| made(a) && made(b)).collect();
    if pairs.is_empty() {
        return;
    }
    let _ = writeln!(md, "{heading}\n");
    header_row(
        md,
        "row",
        by_class.iter().map(|(class, _)| class.to_string()),
    );
    for (a, b) in pairs {
        paired_row(md, &format!("{a} - {b}"), by_class, m, a, b);
    }
    md.push('\n');
}

/// One row of a paired-difference table: condition `a` minus `b` per class
/// over the (test actor, seed) runs both have, mean +- sd per horizon, `*`
/// where the mean exceeds twice its standard error.
fn paired_row(
    md: &mut String,
    label: &str,
    by_class: &[(&str, Vec<&TableCell>)],
    m: &str,
    a: &str,
    b: &str,
) {
    let mut line = format!("| {label} |");
    for (_, cells) in by_class {
        let cols: Vec<String> = HORIZONS_MS
            .iter()
            .filter_map(|ms| paired(cells, m, a, b, *ms))
            .map(|d| format!("{:+.3} +- {:.3}{}", d.mean, d.sd, d.star()))
            .collect();
        if cols.is_empty() {
            line.push_str(" - |");
        } else {
            let _ = write!(line, " {} |", cols.join(" / "));
        }
    }
    let _ = writeln!(md, "{line}");
}

/// A paired difference over runs: its mean, sample sd, and whether the mean
/// exceeds twice its standard error (the spread).
struct Paired {
    mean: f64,
    sd: f64,
    beyond: bool,
}

impl Paired {
    fn star(&self) -> &'static str {
        if self.beyond { "*" } else { "" }
    }
}

/// Condition `a` minus `b` at `ms` over the (test actor, seed) runs of
/// `cells` that have both (`None`: none has).
fn paired(cells: &[&TableCell], m: &str, a: &str, b: &str, ms: u32) -> Option<Paired> {
    let key = ms.to_string();
    let rb = runs(cells, m, b);
    let d: Vec<f64> = runs(cells, m, a)
        .iter()
        .filter_map(|(k, ha)| Some(ha.get(&key)? - rb.get(k)?.get(&key)?))
        .collect();
    if d.is_empty() {
        return None;
    }
    let (mean, sd) = mean_sd(&d);
    let beyond = d.len() > 1 && mean.abs() > 2.0 * sd / (d.len() as f64).sqrt();
    Some(Paired { mean, sd, beyond })
}

/// Mean error of `cond` at `ms` over the runs of `cells`.
fn mean_error(cells: &[&TableCell], m: &str, cond: &str, ms: u32) -> Option<f64> {
    let key = ms.to_string();
    let v: Vec<f64> = runs(cells, m, cond)
        .values()
        .filter_map(|h| h.get(&key).copied())
        .collect();
    (!v.is_empty()).then(|| mean_sd(&v).0)
}

/// The full method beside the paper's Tables 2-5 for the classes it reports:
/// per class and horizon, the full method minus Noise and minus the same
/// synthesis uncorrected (the paper's difference, then ours paired over our
/// runs), the lowest of the paper's rows in each, and how many cells meet
/// each part of the goal.
fn beside_the_paper(md: &mut String, m: &str, by_class: &[(&str, Vec<&TableCell>)]) {
    const FULL: &str = "vae_ik_debiased";
    let rows: Vec<(&str, &Vec<&TableCell>, &PaperClass)> = by_class
        .iter()
        .filter_map(|(class, cells)| Some((*class, cells, paper_class(m, class)?)))
        .filter(|(_, cells, _)| !runs(cells, m, FULL).is_empty())
        .collect();
    if rows.is_empty() {
        return;
    }
    let tables: Vec<String> = {
        let mut t: Vec<u8> = rows.iter().map(|(_, _, p)| p.table).collect();
        t.sort_unstable();
        t.dedup();
        t.iter().map(|t| t.to_string()).collect()
    };
    let net = if m == "gcn" { "GCN" } else { "RNN" };
    let _ = writeln!(
        md,
        "Beside the paper (MotionAug Table {}, its {net}; its errors to 0.01 rad): the full method ({FULL}) minus Noise and minus the same synthesis uncorrected (vae_ik), the paper's difference / ours paired over our runs (* as above), and the lowest of the paper's 11 rows, the paper's / ours:\n",
        tables.join(", ")
    );
    let _ = writeln!(
        md,
        "| class | ms | full - noise | full - vae_ik | lowest row |\n|---|---|---|---|---|"
    );
    // Cells meeting each part of the goal: (paper, ours) counts.
    let (mut cells_n, mut lowest, mut below_noise, mut below_uncorrected) =
        (0, (0, 0), (0, 0), (0, 0));
    for (class, cells, p) in &rows {
        for &ms in p.horizons_ms {
            let paper_diff = |other: &str| Some(p.error(FULL, ms)? - p.error(other, ms)?);
            let (Some(pn), Some(pu)) = (paper_diff("noise"), paper_diff("vae_ik")) else {
                continue;
            };
            let ours_n = paired(cells, m, FULL, "noise", ms);
            let ours_u = paired(cells, m, FULL, "vae_ik", ms);
            let ours_lowest = PAPER_ROWS
                .iter()
                .filter_map(|row| Some((*row, mean_error(cells, m, row, ms)?)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(row, _)| row);
            let paper_lowest = p.lowest(ms);
            cells_n += 1;
            lowest.0 += usize::from(paper_lowest == Some(FULL));
            lowest.1 += usize::from(ours_lowest == Some(FULL));
            // Below Noise by the paper's margin: at least as far below as the
            // paper was (and below at all), beyond our spread.
            below_noise.0 += usize::from(pn < 0.0);
            below_noise.1 += usize::from(
                ours_n
                    .as_ref()
                    .is_some_and(|d| d.beyond && d.mean < 0.0 && d.mean <= pn),
            );
            below_uncorrected.0 += usize::from(pu < 0.0);
            below_uncorrected.1 +=
                usize::from(ours_u.as_ref().is_some_and(|d| d.beyond && d.mean < 0.0));
            let show = |d: &Option<Paired>| {
                d.as_ref()
                    .map_or("-".to_string(), |d| format!("{:+.3}{}", d.mean, d.star()))
            };
            let _ = writeln!(
                md,
                "| {class} | {ms} | {pn:+.2} / {} | {pu:+.2} / {} | {} / {} |",
                show(&ours_n),
                show(&ours_u),
                paper_lowest.unwrap_or("-"),
                ours_lowest.unwrap_or("-"),
            );
        }
    }
    let _ = writeln!(
        md,
        "\nOf {cells_n} (class, horizon) cells, the paper's / ours: the full method the lowest of the 11 rows {} / {}; below Noise {} / {} (ours: beyond the spread and by at least the paper's difference); below the same synthesis uncorrected {} / {} (ours: beyond the spread).\n",
        lowest.0, lowest.1, below_noise.0, below_noise.1, below_uncorrected.0, below_uncorrected.1
    );
}

/// One Markdown table: a row per synthesised set, a column per class.
fn set_table(
    md: &mut String,
    title: &str,
    cells: &[&TableCell],
    show: impl Fn(&SynthScores) -> String,
) {
    let _ = writeln!(md, "## {title}\n");
    header_row(md, "set", cells.iter().map(|c| c.class.clone()));
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
            let per_set: Vec<String> = p
                .by_set
                .iter()
                .map(|(set, s)| format!("{set} {}/{}", s.samples_accepted, s.samples))
                .collect();
            let per_set = if per_set.len() > 1 {
                format!(" ({})", per_set.join(", "))
            } else {
                String::new()
            };
            let _ = writeln!(
                md,
                "| {} | {}/{} | {}/{}{per_set} | {:.3} -> {:.3} | {:.3} | {} | {:.0} |",
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
    rejections_table(md, actor, row_cells);
}

/// Why clips were rejected: how many failed each acceptance criterion (a
/// clip can fail several), for the originals and each corrected set.
fn rejections_table(md: &mut String, actor: &str, row_cells: &[&TableCell]) {
    let criteria = correct::acceptance::CRITERIA;
    let _ = writeln!(
        md,
        "Rejections by criterion, test actor {actor} (clips failing each; a clip can fail several):\n\n\
         | class | clips | accepted | {} |\n|---|---|---|{}",
        criteria.join(" | "),
        "---|".repeat(criteria.len())
    );
    for c in row_cells {
        let Some(p) = &c.physics else { continue };
        let originals = (p.originals, p.originals_accepted, &p.originals_rejected_by);
        let sets = p.by_set.iter().map(|(set, s)| {
            (
                set.as_str(),
                (s.samples, s.samples_accepted, &s.rejected_by),
            )
        });
        for (what, (clips, accepted, rejected)) in
            std::iter::once(("originals", originals)).chain(sets)
        {
            let counts: Vec<String> = criteria
                .iter()
                .map(|k| rejected.get(*k).copied().unwrap_or(0).to_string())
                .collect();
            let _ = writeln!(
                md,
                "| {} {what} | {clips} | {accepted} | {} |",
                c.class,
                counts.join(" | ")
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
                originals_rejected_by: [("mean_reward".to_string(), 1)].into_iter().collect(),
                samples: 4,
                samples_accepted: 1,
                by_set: [("vae", 1), ("ik", 0)]
                    .into_iter()
                    .map(|(set, accepted)| {
                        let s = crate::table::physics::SetCorrection {
                            samples: 2,
                            samples_accepted: accepted,
                            rejected_by: [("no_fall", 2 - accepted), ("soles_flat", 1)]
                                .into_iter()
                                .map(|(k, n)| (k.to_string(), n))
                                .collect(),
                            ..Default::default()
                        };
                        (set.to_string(), s)
                    })
                    .collect(),
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
        assert!(
            md.contains("| kick | 2/3 | 1/4 (ik 0/2, vae 1/2) |"),
            "{md}"
        );
        // Why clips were rejected, criterion by criterion, in judging order.
        assert!(
            md.contains(
                "| class | clips | accepted | no_fall | mean_reward | residual_force | foot_skating | soles_flat |\n\
                 |---|---|---|---|---|---|---|---|\n\
                 | kick originals | 3 | 2 | 0 | 1 | 0 | 0 | 0 |\n\
                 | kick ik | 2 | 0 | 2 | 0 | 0 | 0 | 1 |\n\
                 | kick vae | 2 | 1 | 1 | 0 | 0 | 0 | 1 |\n"
            ),
            "{md}"
        );
    }

    /// A condition of two seeds whose errors at every horizon are `a` and `b`.
    fn seeds(a: f64, b: f64) -> ConditionResult {
        let flat = |v: f64| horizons(v).into_keys().map(|k| (k, v)).collect();
        ConditionResult {
            errors: flat((a + b) / 2.0),
            per_seed: vec![flat(a), flat(b)],
            train_clips: 3,
            train_windows: 10,
            skipped_clips: 0,
            train_seconds: vec![0.1, 0.1],
            first_loss: 1.0,
            last_loss: 0.5,
        }
    }

    /// A kick cell of `actor` with GCN results only, one per named condition.
    fn gcn_cell(actor: &str, rows: Vec<(&str, ConditionResult)>) -> TableCell {
        TableCell {
            class: "kick".into(),
            test_actor: actor.into(),
            predict: [(
                "gcn".to_string(),
                rows.into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
            )]
            .into_iter()
            .collect(),
            ..TableCell::default()
        }
    }

    /// A kick cell with two seeds of no_aug, noise and vae_debiased: the
    /// debiased row is 0.1 below no_aug in every run, and +0.1 or -0.3 from
    /// noise (no consistent sign).
    fn two_seed_cell(actor: &str, base: f64) -> TableCell {
        gcn_cell(
            actor,
            vec![
                ("no_aug", seeds(base, base + 0.2)),
                ("noise", seeds(base - 0.2, base + 0.4)),
                ("vae_debiased", seeds(base - 0.1, base + 0.1)),
            ],
        )
    }

    #[test]
    fn over_actors_and_seeds_the_full_method_is_paired_with_each_row() {
        // Two test actors x two seeds (`two_seed_cell`).
        let cell = two_seed_cell;
        let mut t = table();
        t.config.test_actors = vec!["bd".into(), "mm".into()];
        t.config.train.seeds = vec![0, 1];
        t.config.models = vec![ModelKind::Gcn];
        t.cells = vec![cell("bd", 1.0), cell("mm", 2.0)];
        let md = t.to_markdown();
        assert!(
            md.contains("## Prediction error, gcn, over test actors and seeds: mean +- sd"),
            "{md}"
        );
        // no_aug runs: 1.0, 1.2, 2.0, 2.2 -> mean 1.6, sd sqrt(1.04 / 3).
        assert!(md.contains("| kick (n = 4) |"), "{md}");
        assert!(
            md.contains("| no_aug | 1.600 +- 0.589 / 1.600 +- 0.589 /"),
            "{md}"
        );
        assert!(
            md.contains("- kick: vae_debiased / vae_debiased / vae_debiased"),
            "{md}"
        );
        // Against no_aug: -0.1 in every run (sd 0): beyond the spread.
        assert!(md.contains("| no_aug | -0.100 +- 0.000* /"), "{md}");
        // Against noise: +0.1, -0.3, +0.1, -0.3: mean -0.1, sd 0.231, and
        // 2 sd / sqrt(4) = 0.231 > 0.1: within the spread.
        assert!(md.contains("| noise | -0.100 +- 0.231 /"), "{md}");
        // One actor, one seed: no aggregate section.
        assert!(!table().to_markdown().contains("over test actors and seeds"));
    }

    /// A table as its table.json reads back.
    fn saved(t: &Table) -> crate::table::SavedTable {
        serde_json::from_value(t.to_json()).expect("table.json reads back")
    }

    #[test]
    fn tables_of_one_test_actor_each_merge_into_the_table_of_both() {
        let cell = two_seed_cell;
        let fold = |actors: &[&str], cells: Vec<TableCell>, seconds: f64| {
            let mut t = table();
            t.config.test_actors = actors.iter().map(|a| a.to_string()).collect();
            t.config.train.seeds = vec![0, 1];
            t.config.models = vec![ModelKind::Gcn];
            t.cells = cells;
            t.seconds = seconds;
            t
        };
        let both = fold(&["bd", "mm"], vec![cell("bd", 1.0), cell("mm", 2.0)], 3.0);
        let bd = fold(&["bd"], vec![cell("bd", 1.0)], 1.0);
        let mm = fold(&["mm"], vec![cell("mm", 2.0)], 2.0);
        let merged = crate::table::merge(&[
            ("bd.json".into(), saved(&bd)),
            ("mm.json".into(), saved(&mm)),
        ])
        .expect("same config");
        assert_eq!(merged.to_json(), both.to_json());
        assert_eq!(merged.to_markdown().expect("layout"), both.to_markdown());
        assert!(
            merged
                .to_markdown()
                .expect("layout")
                .contains("over test actors and seeds")
        );

        // Why two tables do not merge.
        let refused = |a: &Table, b: (&str, &Table)| {
            crate::table::merge(&[("bd.json".into(), saved(a)), (b.0.into(), saved(b.1))])
                .expect_err("refused")
                .to_string()
        };
        // A cell may come from one table only.
        let err = refused(&bd, ("again.json", &bd));
        assert!(
            err.contains("again.json: the cell of class kick and test actor bd"),
            "{err}"
        );
        // Tables computed differently do not merge, and the error says how.
        let mut other = fold(&["mm"], vec![cell("mm", 2.0)], 2.0);
        other.config.train.iterations += 1;
        let err = refused(&bd, ("mm.json", &other));
        assert!(err.contains("computed differently (iterations)"), "{err}");
    }

    /// A GCN-only table of actor bd and two seeds: no augmentation at 2.0 /
    /// 2.2, and `rows`.
    fn gcn_two_seed_table(rows: Vec<(&str, ConditionResult)>) -> Table {
        let mut all = vec![("no_aug", seeds(2.0, 2.2))];
        all.extend(rows);
        let mut t = table();
        t.config.train.seeds = vec![0, 1];
        t.config.models = vec![ModelKind::Gcn];
        t.cells = vec![gcn_cell("bd", all)];
        t
    }

    #[test]
    fn corrected_and_debiased_sets_are_paired_with_the_same_clips_uncorrected() {
        // One actor, two seeds: corrected 0.2 below the uncorrected clips in
        // both runs, debiased +0.1 and -0.1 (no consistent sign).
        let t = gcn_two_seed_table(vec![
            ("vae_sub", seeds(1.0, 1.2)),
            ("vae_corrected", seeds(0.8, 1.0)),
            ("vae_debiased", seeds(1.1, 1.1)),
        ]);
        let md = t.to_markdown();
        assert!(md.contains("minus the same clips uncorrected"), "{md}");
        assert!(
            md.contains("| vae_corrected - vae_sub | -0.200 +- 0.000* /"),
            "{md}"
        );
        assert!(
            md.contains("| vae_debiased - vae_sub | +0.000 +- 0.141 /"),
            "{md}"
        );
        // No IK rows were made: no IK line.
        assert!(!md.contains("ik_corrected - ik_sub"), "{md}");
        // No kept rows: no section telling rejection and correction apart.
        assert!(
            !md.contains("What rejection and correction each did"),
            "{md}"
        );
    }

    #[test]
    fn the_full_method_is_read_beside_the_papers_table() {
        // Kick, GCN (the paper's Table 3), two seeds: the full method 0.1
        // below VAE & IK as made and 0.6 below noise in both runs.
        let t = gcn_two_seed_table(vec![
            ("noise", seeds(1.5, 1.7)),
            ("vae_ik", seeds(1.0, 1.2)),
            ("vae_ik_debiased", seeds(0.9, 1.1)),
        ]);
        let md = t.to_markdown();
        assert!(
            md.contains("Beside the paper (MotionAug Table 3, its GCN;"),
            "{md}"
        );
        assert!(
            md.contains(
                "| kick | 100 | -0.16 / -0.600* | -0.05 / -0.100* | vae_ik_debiased / vae_ik_debiased |"
            ),
            "{md}"
        );
        // At 400 ms the paper was 0.65 below noise: 0.6 is not its margin.
        assert!(
            md.contains("| kick | 400 | -0.65 / -0.600* | -0.11 / -0.100* |"),
            "{md}"
        );
        assert!(
            md.contains("Of 3 (class, horizon) cells, the paper's / ours: the full method the lowest of the 11 rows 3 / 3;"),
            "{md}"
        );
        assert!(md.contains("below Noise 3 / 2"), "{md}");
        assert!(
            md.contains("below the same synthesis uncorrected 3 / 3"),
            "{md}"
        );

        // A class the paper does not report, or no full method: no section.
        let mut walk = t.clone();
        walk.cells[0].class = "walk".into();
        assert!(!walk.to_markdown().contains("Beside the paper"));
        let without = gcn_two_seed_table(vec![("noise", seeds(1.5, 1.7))]);
        assert!(!without.to_markdown().contains("Beside the paper"));
    }

    #[test]
    fn kept_rows_tell_rejection_from_correction() {
        // Rejecting clips costs +0.3 in both runs; correcting the accepted
        // ones gains 0.1 in both: together +0.2 against all of them as made.
        let mut t = gcn_two_seed_table(vec![
            ("vae_sub", seeds(1.0, 1.2)),
            ("vae_kept", seeds(1.3, 1.5)),
            ("vae_corrected", seeds(1.2, 1.4)),
            ("vae_debiased", seeds(1.2, 1.4)),
        ]);
        t.config.kept_rows = true;
        let md = t.to_markdown();
        for line in [
            "| vae_kept | 1.400 +- 0.141 /",
            "What rejection and correction each did",
            "| vae_kept - vae_sub | +0.300 +- 0.000* /",
            "| vae_corrected - vae_kept | -0.100 +- 0.000* /",
            "| vae_corrected - vae_sub | +0.200 +- 0.000* /",
        ] {
            assert!(md.contains(line), "{line} in\n{md}");
        }
        assert_eq!(t.config.cell_key()["kept_rows"], true);
        t.config.kept_rows = false;
        assert!(t.config.cell_key().get("kept_rows").is_none());
    }

    #[test]
    fn json_records_what_shapes_the_numbers() {
        let t = table();
        let v = t.to_json();
        assert_eq!(v["seconds"], 12.0);
        assert_eq!(v["config"]["models"], json!(["seq2seq", "gcn"]));
        assert_eq!(v["config"]["sets"], json!(["noise", "ik", "vae", "vae_ik"]));
        // No physics set, no physics config; no paths.
        assert!(v["config"]["physics"].is_null());
        assert!(v["config"].get("data").is_none());
        assert_eq!(v["cells"][0]["physics"]["samples"], 4);
    }

    #[test]
    fn the_vae_mixed_motion_weight_is_recorded_only_when_on() {
        let mut t = table();
        let off = t.config.cell_key();
        // Off: left out, so tables saved before it existed still resume and merge.
        assert!(off.get("vae_mixed_motion_weight").is_none(), "{off}");
        t.config.vae_mixed_motion_weight = 1.0;
        let on = t.config.cell_key();
        assert_eq!(on["vae_mixed_motion_weight"], 1.0);
        assert_ne!(
            on, off,
            "a cell made without the term is not reused with it"
        );
        assert_eq!(saved(&t).config["vae_mixed_motion_weight"], 1.0);
    }

    #[test]
    fn the_vae_contact_sole_travel_and_skating_weights_are_recorded_only_when_set() {
        let mut t = table();
        let off = t.config.cell_key();
        assert!(off.get("vae_mixed_contact_weight").is_none(), "{off}");
        assert!(off.get("vae_mixed_sole_weight").is_none(), "{off}");
        assert!(off.get("vae_mixed_travel_weight").is_none(), "{off}");
        assert!(off.get("vae_skating_weight").is_none(), "{off}");
        t.config.vae_mixed_contact_weight = 1.0;
        t.config.vae_mixed_sole_weight = 0.3;
        t.config.vae_mixed_travel_weight = 2.0;
        t.config.vae_skating_weight = Some(0.5);
        let on = t.config.cell_key();
        assert_eq!(on["vae_mixed_contact_weight"], 1.0);
        assert_eq!(on["vae_mixed_sole_weight"], 0.3);
        assert_eq!(on["vae_mixed_travel_weight"], 2.0);
        assert_eq!(on["vae_skating_weight"], 0.5);
        assert_ne!(on, off);
        t.config.vae_mixed_sole_weight = f64::NAN;
        assert!(t.config.validate().is_err());
        t.config.vae_mixed_sole_weight = 0.0;
        t.config.vae_skating_weight = Some(-1.0);
        assert!(t.config.validate().is_err());
    }

    #[test]
    fn vae_clips_on_one_floor_are_recorded_and_captured_floors_are_not() {
        let mut t = table();
        assert!(t.config.vae_level_floor, "the default");
        let one = t.config.cell_key();
        assert_eq!(one["vae_level_floor"], true);
        t.config.vae_level_floor = false;
        let captured = t.config.cell_key();
        // As captured: left out, as tables saved before the option have it,
        // so those resume and merge only when asked for the captured floors.
        assert!(captured.get("vae_level_floor").is_none(), "{captured}");
        assert_ne!(one, captured);
    }

    #[test]
    fn unplanted_vae_samples_are_recorded_only_when_asked_for() {
        let mut t = table();
        let planted = t.config.cell_key();
        assert!(planted.get("vae_plant_root").is_none(), "{planted}");
        t.config.vae_plant_root = false;
        let unplanted = t.config.cell_key();
        assert_eq!(unplanted["vae_plant_root"], false);
        assert_ne!(
            unplanted, planted,
            "a cell of planted samples is not reused"
        );
        assert_eq!(saved(&t).config["vae_plant_root"], false);
    }
}
