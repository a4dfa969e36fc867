//! V-DMGNN-GAN's Table 1 protocol on the CMU data of DMGNN's preprocessing
//! ([`crate::cmu_dmgnn`]): one model trained on the training sequences of all
//! actions (batches of windows drawn as the reference draws them, masked
//! afresh each batch), scored per action on the eight fixed test windows with
//! the same masks for every model (a fixed seed), mean angle error at 40 / 240
//! / 400 ms.
//!
//! A run is one cell of the table (a model and a mask). With a work folder it
//! survives being stopped: the weights and the iteration are saved every
//! `checkpoint_every` iterations (`<cell>/weights.safetensors` +
//! `progress.json`; Adam's moments restart on resume) and a finished cell's
//! `result.json` is reused by a rerun.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::cmu_dmgnn::{self, CmuDmgnnSet, OBSERVED, PREDICTED, Window};
use crate::error::{EvalError, Result};
use crate::predict::Predictor;
use crate::predict::body_graph::BodyGraph;
use crate::predict::occlusion::{MaskKind, Occluder};
use crate::predict::protocol::{GraphOptions, ModelKind, ModelSizes, build_graph_model};
use crate::predict::train::{TrainConfig, train_batches};

/// Which joints the lower-body mask hides on this data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum LowerBody {
    /// What the reference code ran for its figures: knee, ankle and toes of
    /// one leg ([`cmu_dmgnn::REFERENCE_LOWER_BODY_USED`]).
    #[default]
    Reference,
    /// Both legs from the hips down ([`synth::names::lower_body`]).
    Legs,
}

impl std::str::FromStr for LowerBody {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "reference" => Ok(LowerBody::Reference),
            "legs" => Ok(LowerBody::Legs),
            _ => Err(format!("unknown lower body `{s}` (reference or legs)")),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CmuConfig {
    pub model: ModelKind,
    pub mask: MaskKind,
    pub lower_body: LowerBody,
    pub sizes: ModelSizes,
    pub options: GraphOptions,
    pub train: TrainConfig,
    pub seed: u64,
    /// Iterations between checkpoints (with a work folder).
    pub checkpoint_every: usize,
}

impl CmuConfig {
    pub fn new(model: ModelKind, mask: MaskKind) -> Self {
        CmuConfig {
            model,
            mask,
            lower_body: LowerBody::Reference,
            sizes: ModelSizes::default(),
            options: GraphOptions {
                // DMGNN reads velocities and accelerations; V-DMGNN-GAN's base
                // model does not (its Table 2 ablation adds them).
                vel_acc: model == ModelKind::Dmgnn,
                ..GraphOptions::default()
            },
            train: TrainConfig {
                iterations: 2000,
                batch_size: 32,
                lr: 1e-3,
                weight_decay: 1e-4,
                max_grad_norm: 0.5,
            },
            seed: 0,
            checkpoint_every: 100,
        }
    }

    /// The cell's folder name: `dmgnn-lower`, `vdmgnn-random-l2-velacc`.
    pub fn cell(&self) -> String {
        let mut name = format!("{}-{}", self.model, self.mask);
        if self.options.loss != crate::predict::dmgnn::Reconstruction::L1 {
            name.push_str(&format!("-{}", self.options.loss));
        }
        if self.model == ModelKind::Vdmgnn && self.options.vel_acc {
            name.push_str("-velacc");
        }
        if self.mask == MaskKind::Lower && self.lower_body == LowerBody::Legs {
            name.push_str("-legs");
        }
        name
    }
}

/// Mean angle error (rad) at 40 / 240 / 400 ms.
pub type Reported = [f64; 3];

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CmuResult {
    pub config: CmuConfig,
    pub per_action: BTreeMap<String, Reported>,
    /// Mean over the actions.
    pub average: Reported,
    /// Zero-velocity baseline of the same (masked) windows, per action.
    pub zero_velocity: BTreeMap<String, Reported>,
    pub iterations: usize,
    pub train_seconds: f64,
    pub windows_per_second: f64,
    pub first_loss: f64,
    pub last_loss: f64,
    pub parameters: usize,
}

/// Seed of the test masks (the same occlusions for every model).
const TEST_MASK_SEED: u64 = 0xc4_0000;

/// The graph over the used joints and the occluder of `config`.
pub fn graph_and_occluder(config: &CmuConfig) -> Result<(BodyGraph, Occluder)> {
    let skeleton = cmu_dmgnn::skeleton()?;
    let graph = BodyGraph::new(&skeleton, &cmu_dmgnn::used_joints())?;
    let lower: Vec<bool> = match config.lower_body {
        LowerBody::Legs => graph.lower_body.clone(),
        LowerBody::Reference => (0..graph.nodes())
            .map(|i| cmu_dmgnn::REFERENCE_LOWER_BODY_USED.contains(&i))
            .collect(),
    };
    let occluder = Occluder::with_lower_nodes(config.mask, &lower)?;
    Ok((graph, occluder))
}

fn window_tensors(set: &CmuDmgnnSet, windows: &[Window]) -> Result<(Tensor, Tensor)> {
    let d = cmu_dmgnn::used_dims().len();
    let mut obs = Vec::with_capacity(windows.len() * OBSERVED * d);
    let mut tgt = Vec::with_capacity(windows.len() * PREDICTED * d);
    for w in windows {
        for f in &w.observed {
            obs.extend(set.normalise_used(f));
        }
        for f in &w.target {
            tgt.extend(set.normalise_used(f));
        }
    }
    let b = windows.len();
    Ok((
        Tensor::from_vec(obs, (b, OBSERVED, d), &Device::Cpu)?,
        Tensor::from_vec(tgt, (b, PREDICTED, d), &Device::Cpu)?,
    ))
}

#[derive(Debug, Serialize, Deserialize)]
struct Checkpoint {
    iteration: usize,
    train_seconds: f64,
    first_loss: f64,
}

/// Trains and scores one cell. `progress` gets one line now and then.
pub fn run_cmu(
    set: &CmuDmgnnSet,
    config: &CmuConfig,
    work: Option<&Path>,
    progress: &mut dyn FnMut(&str),
) -> Result<CmuResult> {
    let span = tracing::info_span!("cmu_cell", cell = %config.cell());
    let _guard = span.enter();
    let dir: Option<PathBuf> = work.map(|w| w.join(config.cell()));
    if let Some(d) = &dir {
        let done = d.join("result.json");
        if done.is_file() {
            let r: CmuResult = read_json(&done)?;
            if r.config == *config {
                progress(&format!("{}: reusing {}", config.cell(), done.display()));
                return Ok(r);
            }
        }
        std::fs::create_dir_all(d).map_err(|e| EvalError::Io {
            path: d.clone(),
            source: e,
        })?;
    }
    let (graph, occluder) = graph_and_occluder(config)?;
    let model = build_graph_model(
        config.model,
        &config.sizes,
        &config.options,
        &graph,
        OBSERVED,
        config.seed,
    )?;
    // Resume.
    let mut done = Checkpoint {
        iteration: 0,
        train_seconds: 0.0,
        first_loss: f64::NAN,
    };
    if let Some(d) = &dir {
        let (w, p) = (d.join("weights.safetensors"), d.join("progress.json"));
        if w.is_file() && p.is_file() {
            done = read_json(&p)?;
            model.params().load(&w)?;
            if let Some(a) = model.adversarial() {
                let dw = d.join("discriminator.safetensors");
                if dw.is_file() {
                    a.discriminator_params().load(&dw)?;
                }
            }
            progress(&format!(
                "{}: resuming at iteration {} of {}",
                config.cell(),
                done.iteration,
                config.train.iterations
            ));
        }
    }
    let remaining = config.train.iterations.saturating_sub(done.iteration);
    let started = Instant::now();
    let mut report_first = done.first_loss;
    let mut last_loss = f64::NAN;
    if remaining > 0 {
        let mut cfg = config.train;
        cfg.iterations = remaining;
        let start_it = done.iteration;
        let every = config.checkpoint_every.max(1);
        let mut save_error: Option<EvalError> = None;
        let mut recent = 0.0;
        let report = train_batches(
            model.as_ref(),
            &cfg,
            config.seed.wrapping_add(start_it as u64),
            Some(&occluder),
            |rng| {
                let windows = (0..cfg.batch_size)
                    .map(|_| set.sample_train_window(rng))
                    .collect::<Result<Vec<_>>>()?;
                window_tensors(set, &windows)
            },
            |it, loss| {
                let it = start_it + it;
                recent += loss / every as f64;
                if it.is_multiple_of(every) {
                    progress(&format!(
                        "{}: iteration {it}/{}, loss {recent:.4}, {:.0} s",
                        config.cell(),
                        config.train.iterations,
                        done.train_seconds + started.elapsed().as_secs_f64()
                    ));
                    recent = 0.0;
                    if let Some(d) = &dir
                        && save_error.is_none()
                        && let Err(e) = save(
                            d,
                            model.as_ref(),
                            &Checkpoint {
                                iteration: it,
                                train_seconds: done.train_seconds + started.elapsed().as_secs_f64(),
                                first_loss: done.first_loss,
                            },
                        )
                    {
                        save_error = Some(e);
                    }
                }
            },
        )?;
        if let Some(e) = save_error {
            return Err(e);
        }
        if report_first.is_nan() {
            report_first = report.first_loss;
        }
        last_loss = report.last_loss;
    }
    let train_seconds = done.train_seconds + started.elapsed().as_secs_f64();
    let iterations = config.train.iterations;

    // Score.
    let mut per_action = BTreeMap::new();
    let mut zero_velocity = BTreeMap::new();
    let mut rng = ChaCha8Rng::seed_from_u64(TEST_MASK_SEED);
    for action in set.actions() {
        let windows = set.test_windows(action)?;
        let (obs, _) = window_tensors(set, &windows)?;
        let masked = occluder.apply(&obs, &mut rng)?;
        let pred = model.predict(&masked, PREDICTED)?;
        let flat: Vec<f32> = pred.flatten_all()?.to_vec1()?;
        let d = cmu_dmgnn::used_dims().len();
        let mut total = vec![0.0; PREDICTED];
        let mut zero = vec![0.0; PREDICTED];
        let masked_flat: Vec<f32> = masked.flatten_all()?.to_vec1()?;
        for (w, window) in windows.iter().enumerate() {
            let frames: Vec<Vec<f64>> = (0..PREDICTED)
                .map(|t| {
                    let off = (w * PREDICTED + t) * d;
                    set.unnormalise_to_full(&flat[off..off + d])
                })
                .collect();
            let err = set.mean_angle_error(&frames, &window.target)?;
            // Zero velocity of what the model saw: the last masked frame.
            let off = (w * OBSERVED + OBSERVED - 1) * d;
            let last = set.unnormalise_to_full(&masked_flat[off..off + d]);
            let zv = set.mean_angle_error(&vec![last; PREDICTED], &window.target)?;
            for t in 0..PREDICTED {
                total[t] += err[t] / windows.len() as f64;
                zero[t] += zv[t] / windows.len() as f64;
            }
        }
        per_action.insert(action.clone(), cmu_dmgnn::reported(&total));
        zero_velocity.insert(action.clone(), cmu_dmgnn::reported(&zero));
    }
    let n = per_action.len().max(1) as f64;
    let mut average = [0.0; 3];
    for r in per_action.values() {
        for k in 0..3 {
            average[k] += r[k] / n;
        }
    }
    let result = CmuResult {
        config: config.clone(),
        per_action,
        average,
        zero_velocity,
        iterations,
        train_seconds,
        windows_per_second: if train_seconds > 0.0 {
            (remaining * config.train.batch_size) as f64 / started.elapsed().as_secs_f64().max(1e-9)
        } else {
            0.0
        },
        first_loss: report_first,
        last_loss,
        parameters: model.params().count(),
    };
    if let Some(d) = &dir {
        save(
            d,
            model.as_ref(),
            &Checkpoint {
                iteration: iterations,
                train_seconds,
                first_loss: report_first,
            },
        )?;
        write_json(&d.join("result.json"), &result)?;
    }
    progress(&format!(
        "{}: {iterations} iterations in {train_seconds:.0} s; error 40/240/400 ms {:.3}/{:.3}/{:.3} rad (average of {} actions)",
        config.cell(),
        average[0],
        average[1],
        average[2],
        result.per_action.len()
    ));
    Ok(result)
}

fn save(dir: &Path, model: &dyn Predictor, at: &Checkpoint) -> Result<()> {
    model.params().save(&dir.join("weights.safetensors"))?;
    if let Some(a) = model.adversarial() {
        a.discriminator_params()
            .save(&dir.join("discriminator.safetensors"))?;
    }
    write_json(&dir.join("progress.json"), at)
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let bytes = std::fs::read(path).map_err(|source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&bytes).map_err(|e| EvalError::Data(format!("{}: {e}", path.display())))
}

/// Written whole or not at all (a temporary file renamed into place).
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let bytes = serde_json::to_vec_pretty(value)
        .map_err(|e| EvalError::Data(format!("{}: {e}", path.display())))?;
    let tmp = path.with_extension("json.tmp");
    let io = |source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    };
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// V-DMGNN-GAN's Table 1 on the five complete actions: per action, the
/// published errors at 40 / 240 / 400 ms of (V-DMGNN-GAN, DMGNN) under
/// (lower-body, random) masking.
pub const PAPER_TABLE1: [(&str, [[Reported; 2]; 2]); 5] = [
    // action, [[vdmgnn lower, vdmgnn random], [dmgnn lower, dmgnn random]]
    (
        "basketball",
        [
            [[0.477, 1.074, 1.500], [0.620, 1.028, 1.341]],
            [[0.427, 0.789, 1.205], [0.415, 1.120, 1.476]],
        ],
    ),
    (
        "jumping",
        [
            [[0.558, 1.039, 1.796], [0.968, 1.112, 1.739]],
            [[0.507, 1.068, 1.798], [0.981, 1.153, 1.885]],
        ],
    ),
    (
        "running",
        [
            [[0.387, 0.674, 0.906], [0.615, 0.584, 0.726]],
            [[0.238, 0.422, 0.451], [0.278, 0.517, 0.554]],
        ],
    ),
    (
        "soccer",
        [
            [[0.401, 0.747, 0.992], [0.519, 0.783, 0.978]],
            [[0.437, 0.670, 0.838], [0.345, 0.774, 1.002]],
        ],
    ),
    (
        "walking",
        [
            [[0.276, 0.425, 0.553], [0.506, 0.393, 0.486]],
            [[0.272, 0.302, 0.407], [0.310, 0.389, 0.519]],
        ],
    ),
];

/// The paper's figure for a cell and action, if it reports one.
pub fn paper(model: ModelKind, mask: MaskKind, action: &str) -> Option<Reported> {
    let m = match model {
        ModelKind::Vdmgnn => 0,
        ModelKind::Dmgnn => 1,
        _ => return None,
    };
    let k = match mask {
        MaskKind::Lower => 0,
        MaskKind::Random => 1,
        MaskKind::None => return None,
    };
    PAPER_TABLE1
        .iter()
        .find(|(a, _)| *a == action)
        .map(|(_, v)| v[m][k])
}

/// The cells as a Markdown table, ours beside the paper's, with the zero-velocity
/// baseline of the same masked windows.
pub fn render_markdown(results: &[CmuResult]) -> String {
    let mut s = String::from(
        "| model | mask | action | 40 ms ours / paper | 240 ms ours / paper | 400 ms ours / paper | zero-velocity 40/240/400 |\n|---|---|---|---|---|---|---|\n",
    );
    let cell = |ours: f64, paper: Option<f64>| match paper {
        Some(p) => format!("{ours:.3} / {p:.3}"),
        None => format!("{ours:.3}"),
    };
    for r in results {
        let c = &r.config;
        let mut rows: Vec<(String, Reported, Option<Reported>, Option<Reported>)> = r
            .per_action
            .iter()
            .map(|(a, v)| {
                (
                    a.clone(),
                    *v,
                    paper(c.model, c.mask, a),
                    r.zero_velocity.get(a).copied(),
                )
            })
            .collect();
        let paper_avg = {
            let ps: Vec<Reported> = rows.iter().filter_map(|r| r.2).collect();
            (ps.len() == rows.len() && !ps.is_empty()).then(|| {
                let n = ps.len() as f64;
                [0, 1, 2].map(|k| ps.iter().map(|p| p[k]).sum::<f64>() / n)
            })
        };
        rows.push(("average".into(), r.average, paper_avg, None));
        for (action, v, p, z) in rows {
            let _ = std::fmt::Write::write_fmt(
                &mut s,
                format_args!(
                    "| {} | {} | {} | {} | {} | {} | {} |\n",
                    c.model,
                    c.mask,
                    action,
                    cell(v[0], p.map(|p| p[0])),
                    cell(v[1], p.map(|p| p[1])),
                    cell(v[2], p.map(|p| p[2])),
                    z.map_or(String::new(), |z| format!(
                        "{:.3}/{:.3}/{:.3}",
                        z[0], z[1], z[2]
                    )),
                ),
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny(model: ModelKind, mask: MaskKind, iterations: usize) -> CmuConfig {
        let mut c = CmuConfig::new(model, mask);
        c.sizes.graph_channels = [4, 8, 8, 8];
        c.sizes.graph_hidden = 8;
        c.train.iterations = iterations;
        c.train.batch_size = 4;
        c.checkpoint_every = 1;
        c
    }

    #[test]
    fn cells_train_score_every_action_and_resume() {
        let Some(root) = crate::cmu_dmgnn::test_data_root() else {
            return;
        };
        let set = CmuDmgnnSet::load(&root, &["walking", "running"]).unwrap();
        let work = std::env::temp_dir().join(format!("motionaug-cmu-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&work);
        let mut lines = Vec::new();
        let c = tiny(ModelKind::Vdmgnn, MaskKind::Random, 2);
        let r = run_cmu(&set, &c, Some(&work), &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(r.per_action.len(), 2);
        for v in r.per_action.values().chain(r.zero_velocity.values()) {
            assert!(v.iter().all(|e| e.is_finite() && *e > 0.0), "{r:?}");
        }
        assert!(
            work.join(c.cell())
                .join("discriminator.safetensors")
                .is_file()
        );
        // A rerun of the same cell reuses its result.
        let again = run_cmu(&set, &c, Some(&work), &mut |l| lines.push(l.to_string())).unwrap();
        assert_eq!(again.per_action, r.per_action);
        assert!(lines.iter().any(|l| l.contains("reusing")), "{lines:?}");
        // More iterations resume from the saved weights at iteration 2.
        let longer = tiny(ModelKind::Vdmgnn, MaskKind::Random, 3);
        lines.clear();
        let r3 = run_cmu(&set, &longer, Some(&work), &mut |l| {
            lines.push(l.to_string())
        })
        .unwrap();
        assert!(
            lines.iter().any(|l| l.contains("resuming at iteration 2")),
            "{lines:?}"
        );
        assert_eq!(r3.iterations, 3);
        // The lower-body mask of the reference hides three joints of one leg.
        let (g, _) = graph_and_occluder(&tiny(ModelKind::Dmgnn, MaskKind::Lower, 1)).unwrap();
        assert_eq!(g.nodes(), 26);
        assert_eq!(g.bodies, 5, "{:?}", g.body_of);
        assert!(paper(ModelKind::Dmgnn, MaskKind::Lower, "walking").is_some());
        assert!(render_markdown(&[r3]).contains("| vdmgnn | random | walking |"));
        let _ = std::fs::remove_dir_all(&work);
    }
}
