//! Tables merged from their `table.json` files.
//!
//! Why this exists: a fold of the table (one class, one test actor, three
//! seeds, with corrections) takes about an hour on two cores, so the five
//! folds of the paper's protocol are run as separate commands, often in
//! separate sessions. Their `table.json` files are merged here into one table
//! whose aggregate (mean and spread, paired differences) runs over every fold
//! and seed, exactly as if one `eval table` had run them all.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde_json::{Value, json};

use super::TableCell;
use super::render::{Layout, markdown, write_files};
use crate::error::{EvalError, Result};
use crate::predict::protocol::ModelKind;

/// A table as its `table.json` holds it: the config's summary, the wall time,
/// the cells.
#[derive(Debug, Clone, Deserialize)]
pub struct SavedTable {
    pub config: Value,
    pub seconds: f64,
    pub cells: Vec<TableCell>,
}

/// The part of a saved config the layout of table.md needs.
#[derive(Deserialize)]
struct SavedLayout {
    models: Vec<ModelKind>,
    test_actors: Vec<String>,
    seeds: Vec<u64>,
}

impl SavedTable {
    /// Reads a `table.json` written by `eval table`.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| EvalError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        serde_json::from_slice(&bytes).map_err(|e| {
            EvalError::Data(format!(
                "{}: not a table.json of `eval table`: {e}",
                path.display()
            ))
        })
    }

    fn layout(&self) -> Result<SavedLayout> {
        SavedLayout::deserialize(&self.config)
            .map_err(|e| EvalError::Data(format!("the table's config: {e}")))
    }

    /// table.json's content (the shape `eval table` writes).
    pub fn to_json(&self) -> Value {
        json!({ "config": self.config, "seconds": self.seconds, "cells": self.cells })
    }

    /// table.md's content, laid out as `eval table` lays out its own.
    pub fn to_markdown(&self) -> Result<String> {
        let layout = self.layout()?;
        let models: Vec<String> = layout.models.iter().map(|m| m.to_string()).collect();
        Ok(markdown(
            &self.config,
            self.seconds,
            &self.cells,
            &Layout {
                models: &models,
                test_actors: &layout.test_actors,
                seeds: layout.seeds.len(),
            },
        ))
    }

    /// Writes `table.json` and `table.md` into `dir` (each atomically).
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_files(dir, &self.to_json(), &self.to_markdown()?)
    }
}

/// The config keys a merge may combine: which classes and test actors each
/// table has. Everything else shapes the numbers and must agree.
const UNION_KEYS: [&str; 2] = ["classes", "test_actors"];

/// One table of every cell of `tables` (each named by the file it came from):
/// the configs must agree on everything but the classes and test actors,
/// which are united in order of first appearance; a (class, test actor) cell
/// may come from one table only; the wall time is the runs' sum.
pub fn merge(tables: &[(PathBuf, SavedTable)]) -> Result<SavedTable> {
    let Some((first_path, first)) = tables.first() else {
        return Err(EvalError::Config("no tables to merge".into()));
    };
    first.layout()?;
    let shape = |config: &Value| {
        let mut v = config.clone();
        if let Some(map) = v.as_object_mut() {
            for key in UNION_KEYS {
                map.remove(key);
            }
        }
        v
    };
    let first_shape = shape(&first.config);
    let mut merged = SavedTable {
        config: first.config.clone(),
        seconds: 0.0,
        cells: Vec::new(),
    };
    let mut united: [Vec<Value>; 2] = [Vec::new(), Vec::new()];
    for (path, table) in tables {
        let this_shape = shape(&table.config);
        if this_shape != first_shape {
            return Err(EvalError::Config(format!(
                "{} and {} were computed differently ({}): only tables that differ in their classes and test actors merge",
                first_path.display(),
                path.display(),
                differing_keys(&first_shape, &this_shape).join(", ")
            )));
        }
        for (i, key) in UNION_KEYS.iter().enumerate() {
            for item in table.config[key].as_array().into_iter().flatten() {
                if !united[i].contains(item) {
                    united[i].push(item.clone());
                }
            }
        }
        for cell in &table.cells {
            if merged
                .cells
                .iter()
                .any(|c| c.class == cell.class && c.test_actor == cell.test_actor)
            {
                return Err(EvalError::Config(format!(
                    "{}: the cell of class {} and test actor {} is in an earlier table too",
                    path.display(),
                    cell.class,
                    cell.test_actor
                )));
            }
            merged.cells.push(cell.clone());
        }
        merged.seconds += table.seconds;
    }
    if let Some(map) = merged.config.as_object_mut() {
        for (key, items) in UNION_KEYS.iter().zip(united) {
            map.insert((*key).to_string(), Value::Array(items));
        }
    }
    Ok(merged)
}

/// The top-level keys whose values differ between two configs (for the error).
fn differing_keys(a: &Value, b: &Value) -> Vec<String> {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return vec!["the config".into()];
    };
    let mut keys: Vec<String> = a
        .keys()
        .chain(b.keys())
        .filter(|k| a.get(*k) != b.get(*k))
        .cloned()
        .collect();
    keys.sort();
    keys.dedup();
    keys
}
