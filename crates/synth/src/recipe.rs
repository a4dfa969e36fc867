//! Recipes: which ops to run on every clip, with which parameters, how often.
//!
//! ```toml
//! seed = 7                  # optional; the CLI's --seed overrides it
//!
//! [[ops]]
//! op = "noise"              # noise | time_warp | mirror | mask | ik
//! copies = 3                # default 1, at most 1000
//! sigma_deg = 2.0           # the op's own parameters
//! ```
//!
//! The same structure is accepted as JSON (`{"seed": 7, "ops": [{"op": "noise",
//! ...}]}`) by the HTTP service: [`Recipe`] implements `Deserialize` through a
//! JSON value, so both paths share one validator. Unknown keys and bad values are
//! errors naming the op index, its kind and the field.
//!
//! Extending: new top-level tables (e.g. `[correct]`) are added as new optional
//! keys of [`Recipe`] and new ops as new [`Op`] variants; existing recipes keep
//! their meaning. Every op is applied to the source clip (ops do not chain).

use motion::Motion;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::{
    Augmented, IkParams, MaskParams, MirrorParams, NoiseParams, SynthError, TimeWarpParams, ik,
    mask, mirror, noise, output_seed, rng_from_seed, time_warp,
};

/// Largest `copies` of one op (a guard against typos like `copies = 100000`).
pub const MAX_COPIES: u32 = 1000;
/// Largest number of `[[ops]]` tables.
pub const MAX_OPS: usize = 64;

/// One operation with its parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum Op {
    Noise(NoiseParams),
    TimeWarp(TimeWarpParams),
    Mirror(MirrorParams),
    Mask(MaskParams),
    Ik(IkParams),
}

impl Op {
    pub const KINDS: &[&str] = &["noise", "time_warp", "mirror", "mask", "ik"];

    /// The op's name as written in recipes.
    pub fn kind(&self) -> &'static str {
        match self {
            Op::Noise(_) => "noise",
            Op::TimeWarp(_) => "time_warp",
            Op::Mirror(_) => "mirror",
            Op::Mask(_) => "mask",
            Op::Ik(_) => "ik",
        }
    }

    /// Check the parameters; the error names the field.
    pub fn validate(&self) -> Result<(), SynthError> {
        match self {
            Op::Noise(p) => p.validate(),
            Op::TimeWarp(p) => p.validate(),
            Op::Mirror(p) => p.validate(),
            Op::Mask(p) => p.validate(),
            Op::Ik(p) => p.validate(),
        }
    }

    /// Run the op on one clip.
    pub fn apply(
        &self,
        motion: &Motion,
        rng: &mut crate::SynthRng,
    ) -> Result<Augmented, SynthError> {
        match self {
            Op::Noise(p) => noise(motion, p, rng),
            Op::TimeWarp(p) => time_warp(motion, p, rng),
            Op::Mirror(p) => mirror(motion, p, rng),
            Op::Mask(p) => mask(motion, p, rng),
            Op::Ik(p) => ik(motion, p, rng),
        }
    }

    /// The parameters as a JSON object (without `op`), for the manifest.
    pub fn params_json(&self) -> Value {
        let mut v = serde_json::to_value(self).unwrap_or(Value::Null);
        if let Value::Object(m) = &mut v {
            m.remove("op");
        }
        v
    }

    fn parse(kind: &str, params: Value) -> Result<Op, String> {
        let e = |err: serde_json::Error| err.to_string();
        Ok(match kind {
            "noise" => Op::Noise(serde_json::from_value(params).map_err(e)?),
            "time_warp" => Op::TimeWarp(serde_json::from_value(params).map_err(e)?),
            "mirror" => Op::Mirror(serde_json::from_value(params).map_err(e)?),
            "mask" => Op::Mask(serde_json::from_value(params).map_err(e)?),
            "ik" => Op::Ik(serde_json::from_value(params).map_err(e)?),
            other => {
                return Err(format!(
                    "unknown op `{other}` (known: {})",
                    Op::KINDS.join(", ")
                ));
            }
        })
    }
}

/// One `[[ops]]` table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OpEntry {
    pub copies: u32,
    #[serde(flatten)]
    pub op: Op,
}

/// A validated recipe.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Recipe {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    pub ops: Vec<OpEntry>,
}

impl<'de> Deserialize<'de> for Recipe {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Value::deserialize(d)?;
        Recipe::from_value(v).map_err(serde::de::Error::custom)
    }
}

fn recipe_err(location: impl Into<String>, message: impl Into<String>) -> SynthError {
    SynthError::Recipe {
        location: location.into(),
        message: message.into(),
    }
}

impl Recipe {
    /// Build and validate a recipe in code.
    pub fn new(seed: Option<u64>, ops: Vec<OpEntry>) -> Result<Recipe, SynthError> {
        if ops.is_empty() {
            return Err(recipe_err(
                "ops",
                "a recipe needs at least one [[ops]] table",
            ));
        }
        if ops.len() > MAX_OPS {
            return Err(recipe_err("ops", format!("at most {MAX_OPS} ops")));
        }
        for (i, entry) in ops.iter().enumerate() {
            let location = format!("ops[{i}] ({})", entry.op.kind());
            if !(1..=MAX_COPIES).contains(&entry.copies) {
                return Err(recipe_err(
                    location,
                    format!("`copies` must be in 1..={MAX_COPIES}"),
                ));
            }
            entry
                .op
                .validate()
                .map_err(|e| recipe_err(location, e.to_string()))?;
        }
        Ok(Recipe { seed, ops })
    }

    pub fn from_toml_str(text: &str) -> Result<Recipe, SynthError> {
        let v: Value = toml::from_str(text).map_err(|e| recipe_err("TOML", e.to_string()))?;
        Recipe::from_value(v)
    }

    pub fn from_json_str(text: &str) -> Result<Recipe, SynthError> {
        let v: Value = serde_json::from_str(text).map_err(|e| recipe_err("JSON", e.to_string()))?;
        Recipe::from_value(v)
    }

    /// Parse the generic structure shared by TOML and JSON.
    pub fn from_value(v: Value) -> Result<Recipe, SynthError> {
        let Value::Object(top) = v else {
            return Err(recipe_err("recipe", "must be a table/object"));
        };
        let mut seed = None;
        let mut ops_value = None;
        for (key, value) in top {
            match key.as_str() {
                "seed" => {
                    seed = Some(value.as_u64().ok_or_else(|| {
                        recipe_err("seed", "must be a non-negative integer below 2^64")
                    })?)
                }
                "ops" => ops_value = Some(value),
                other => {
                    return Err(recipe_err(
                        "recipe",
                        format!("unknown key `{other}` (known: seed, ops)"),
                    ));
                }
            }
        }
        let Some(Value::Array(tables)) = ops_value else {
            return Err(recipe_err("ops", "missing: add at least one [[ops]] table"));
        };
        let mut ops = Vec::with_capacity(tables.len());
        for (i, table) in tables.into_iter().enumerate() {
            let Value::Object(mut m) = table else {
                return Err(recipe_err(format!("ops[{i}]"), "must be a table/object"));
            };
            let kind = match m.remove("op") {
                Some(Value::String(s)) => s,
                Some(_) => return Err(recipe_err(format!("ops[{i}]"), "`op` must be a string")),
                None => {
                    return Err(recipe_err(
                        format!("ops[{i}]"),
                        format!("missing `op` (one of {})", Op::KINDS.join(", ")),
                    ));
                }
            };
            let location = format!("ops[{i}] ({kind})");
            let copies = match m.remove("copies") {
                None => 1,
                Some(c) => c
                    .as_u64()
                    .and_then(|c| u32::try_from(c).ok())
                    .filter(|c| (1..=MAX_COPIES).contains(c))
                    .ok_or_else(|| {
                        recipe_err(
                            &location,
                            format!("`copies` must be an integer in 1..={MAX_COPIES}"),
                        )
                    })?,
            };
            let op =
                Op::parse(&kind, Value::Object(m)).map_err(|msg| recipe_err(&location, msg))?;
            ops.push(OpEntry { copies, op });
        }
        Recipe::new(seed, ops)
    }

    /// The seed to use: the CLI's, else the recipe's, else 0.
    pub fn effective_seed(&self, override_seed: Option<u64>) -> u64 {
        override_seed.or(self.seed).unwrap_or(0)
    }

    /// Number of outputs per clip.
    pub fn outputs_per_clip(&self) -> usize {
        self.ops.iter().map(|o| o.copies as usize).sum()
    }

    /// Every output of one clip as an independent job, in a fixed order.
    pub fn jobs(&self, clip: &str, seed: u64) -> Vec<Job> {
        let mut jobs = Vec::with_capacity(self.outputs_per_clip());
        for (op_index, entry) in self.ops.iter().enumerate() {
            for copy in 0..entry.copies {
                jobs.push(Job {
                    op_index,
                    copy,
                    seed: output_seed(seed, clip, op_index, copy),
                });
            }
        }
        jobs
    }
}

/// One output to make: op `op_index`, copy `copy`, with its own seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Job {
    pub op_index: usize,
    pub copy: u32,
    pub seed: u64,
}

/// One output with what is needed to name it and describe it.
#[derive(Debug, Clone)]
pub struct Generated {
    /// `<clip>__<op index>_<op>_<copy>`, e.g. `walk__01_time_warp_002`: a file stem.
    pub name: String,
    pub clip: String,
    pub job: Job,
    pub op: &'static str,
    pub params: Value,
    pub output: Augmented,
}

/// Run one job (the HTTP worker's unit of work).
pub fn run_job(
    recipe: &Recipe,
    clip: &str,
    motion: &Motion,
    job: Job,
) -> Result<Generated, SynthError> {
    let entry = recipe.ops.get(job.op_index).ok_or_else(|| {
        recipe_err(
            format!("ops[{}]", job.op_index),
            format!("the recipe has {} ops", recipe.ops.len()),
        )
    })?;
    let op = entry.op.kind();
    let span = tracing::debug_span!("synth_job", clip, op, index = job.op_index, copy = job.copy);
    let _guard = span.enter();
    let mut rng = rng_from_seed(job.seed);
    let output = entry
        .op
        .apply(motion, &mut rng)
        .map_err(|e| SynthError::InOp {
            clip: clip.to_string(),
            index: job.op_index,
            op,
            source: Box::new(e),
        })?;
    Ok(Generated {
        name: format!("{clip}__{:02}_{op}_{:03}", job.op_index, job.copy),
        clip: clip.to_string(),
        job,
        op,
        params: entry.op.params_json(),
        output,
    })
}

/// Run every op and copy of a recipe on one clip. Stops at the first failing op.
pub fn expand_clip(
    recipe: &Recipe,
    clip: &str,
    motion: &Motion,
    seed: u64,
) -> Result<Vec<Generated>, SynthError> {
    recipe
        .jobs(clip, seed)
        .into_iter()
        .map(|job| run_job(recipe, clip, motion, job))
        .collect()
}

/// One line of `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestEntry {
    /// Output file (relative to the output directory).
    pub file: String,
    /// Source clip (as given on the command line / upload name).
    pub source: String,
    pub op: String,
    pub op_index: usize,
    pub copy: u32,
    pub seed: u64,
    /// The op's parameters as given in the recipe (with defaults filled in).
    pub params: Value,
    /// Values drawn or measured by the op (time-warp factor, IK errors, ...).
    #[serde(default, skip_serializing_if = "Map::is_empty")]
    pub sampled: Map<String, Value>,
    pub frames: usize,
    pub fps: f64,
    /// IK only: effector joint name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effector: Option<String>,
    /// IK only: keyframe index in the output.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keyframe: Option<usize>,
    /// IK only: target of the effector at the keyframe, world metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f64; 3]>,
}

impl Generated {
    pub fn manifest_entry(
        &self,
        file: impl Into<String>,
        source: impl Into<String>,
    ) -> ManifestEntry {
        let s = &self.output.sampled;
        let target = s.get("target").and_then(|t| {
            let a = t.as_array()?;
            Some([
                a.first()?.as_f64()?,
                a.get(1)?.as_f64()?,
                a.get(2)?.as_f64()?,
            ])
        });
        ManifestEntry {
            file: file.into(),
            source: source.into(),
            op: self.op.to_string(),
            op_index: self.job.op_index,
            copy: self.job.copy,
            seed: self.job.seed,
            params: self.params.clone(),
            sampled: s.clone(),
            frames: self.output.motion.frames(),
            fps: self.output.motion.fps(),
            effector: s.get("effector").and_then(|v| v.as_str()).map(String::from),
            keyframe: s
                .get("keyframe")
                .and_then(|v| v.as_u64())
                .map(|k| k as usize),
            target,
        }
    }
}
