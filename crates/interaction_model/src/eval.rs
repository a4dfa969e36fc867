//! Evaluation on the paper's four splits (Sec. 5.1) and the comparison with
//! the optimiser.
//!
//! **Metrics** (per window, averaged over A and B, metres):
//! * E_r: mean distance between predicted and optimiser (ground-truth) points;
//! * E_b: mean |bone length - target length|, the target being the template's
//!   length times B's factor (A keeps its own);
//! * JPD: mean |key pair distance - source distance| over the window's frames
//!   inside the pair's contact stretch (windows without such frames, and the
//!   squats, which have no key pair, do not count). JPD is measured against
//!   the captured source, so the optimiser gets a JPD too (`optimiser_jpd_m`);
//! * FID between the features ([`crate::features`]) of the predicted and the
//!   ground-truth test windows, with the FID of ground-truth training windows
//!   against the test windows as a reference (`fid_data`).
//!
//! Retargeting decodes the latent mean with the test variation's scales;
//! generation draws B's scales from the skeleton prior (one draw per window),
//! so it has no ground truth for E_r.
//!
//! **Splits**: `random` (20 % of the variations held out), `cross_scale`
//! (train on global scales 0.95-1.05, test on 0.75-0.85 and 1.15-1.25),
//! `cross_interaction` (leave one pair out: one fold per pair, averaged) and
//! `cross_scale_interaction` (both). Each fold trains a fresh model.
//!
//! **Comparison**: the random split's model makes whole-clip variations at
//! held-out scales ([`crate::generate::generate`]) next to the optimiser's
//! figures for the same variations (from the dataset, same 30 fps clips).

use std::sync::Mutex;
use std::time::Instant;

use candle_core::Tensor;
use motion::Motion;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::dataset::{Batch, Dataset, Sample};
use crate::error::{ModelError, Result};
use crate::features::{FeatureConfig, FeatureNet, FeatureQuality, fid, rows};
use crate::generate::generate;
use crate::model::InteractionModel;
use crate::train::{TrainConfig, train};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct EvalConfig {
    pub train: TrainConfig,
    /// Stride of the test windows (frames).
    pub test_stride: usize,
    pub feature_steps: usize,
    /// Held-out variations per pair in the whole-clip comparison.
    pub compare_per_pair: usize,
    /// Folds trained at once (each on one thread).
    pub jobs: usize,
    pub seed: u64,
}

impl Default for EvalConfig {
    fn default() -> Self {
        EvalConfig {
            train: TrainConfig::default(),
            test_stride: 8,
            feature_steps: 300,
            compare_per_pair: 3,
            jobs: 1,
            seed: 0,
        }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RetargetMetrics {
    pub e_r_m: f64,
    pub e_b_m: f64,
    pub jpd_m: Option<f64>,
    pub fid: f64,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GenerationMetrics {
    pub e_b_m: f64,
    pub jpd_m: Option<f64>,
    pub fid: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FoldResult {
    pub name: String,
    pub train_variations: usize,
    pub test_variations: usize,
    pub train_windows: usize,
    pub test_windows: usize,
    pub train_s: f64,
    pub final_loss: f64,
    pub retarget: RetargetMetrics,
    pub generation: GenerationMetrics,
    pub optimiser_jpd_m: Option<f64>,
    pub fid_data: f64,
    /// Network time per test window (retargeting, batched), milliseconds.
    pub inference_ms_per_window: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitResult {
    pub split: String,
    pub folds: Vec<FoldResult>,
    /// Mean over folds.
    pub retarget: RetargetMetrics,
    pub generation: GenerationMetrics,
    pub optimiser_jpd_m: Option<f64>,
    pub fid_data: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompareRow {
    pub pair: String,
    pub scale: f64,
    pub method: String,
    /// Seconds per variation (whole clip, 30 fps).
    pub wall_s: f64,
    /// Learned only: mean distance to the optimiser's points, metres.
    pub e_r_m: Option<f64>,
    /// Mean bone-length error of the raw output points (optimiser: exact), metres.
    pub e_b_m: f64,
    pub jpd_m: Option<f64>,
    pub foot_skating_a_m_s: f64,
    pub foot_skating_b_m_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetSummary {
    pub pairs: Vec<(String, usize, usize)>,
    pub fps: f64,
    pub window: usize,
    pub train_stride: usize,
    pub test_stride: usize,
    pub build_wall_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub dataset: DatasetSummary,
    pub config: EvalConfig,
    pub feature_net: FeatureQuality,
    pub splits: Vec<SplitResult>,
    pub comparison: Vec<CompareRow>,
    pub wall_s: f64,
}

/// A split's folds: (name, train?, test?) over (pair, variation).
type Keep = Box<dyn Fn(usize, usize) -> bool>;

fn in_range(x: f64, lo: f64, hi: f64) -> bool {
    x >= lo - 1e-9 && x <= hi + 1e-9
}

fn folds(dataset: &Dataset, split: &str, seed: u64) -> Vec<(String, Keep, Keep)> {
    let globals: Vec<Vec<f64>> = dataset
        .pairs
        .iter()
        .map(|p| p.variations.iter().map(|v| v.global).collect())
        .collect();
    let mid = move |g: f64| in_range(g, 0.95, 1.05);
    let far = move |g: f64| in_range(g, 0.75, 0.85) || in_range(g, 1.15, 1.25);
    match split {
        "random" => {
            let mut all: Vec<(usize, usize)> = globals
                .iter()
                .enumerate()
                .flat_map(|(p, g)| (0..g.len()).map(move |v| (p, v)))
                .collect();
            all.shuffle(&mut ChaCha8Rng::seed_from_u64(seed ^ 0x5B11));
            let n_test = (all.len() as f64 * 0.2).round().max(1.0) as usize;
            let test: std::collections::BTreeSet<(usize, usize)> =
                all[..n_test].iter().copied().collect();
            let t2 = test.clone();
            vec![(
                "random".into(),
                Box::new(move |p, v| !test.contains(&(p, v))),
                Box::new(move |p, v| t2.contains(&(p, v))),
            )]
        }
        "cross_scale" => {
            let (g1, g2) = (globals.clone(), globals);
            vec![(
                "cross_scale".into(),
                Box::new(move |p, v| mid(g1[p][v])),
                Box::new(move |p, v| far(g2[p][v])),
            )]
        }
        "cross_interaction" | "cross_scale_interaction" => {
            let both = split == "cross_scale_interaction";
            (0..dataset.pairs.len())
                .map(|held| {
                    let (g1, g2) = (globals.clone(), globals.clone());
                    let train: Keep = Box::new(move |p, v| p != held && (!both || mid(g1[p][v])));
                    let test: Keep = Box::new(move |p, v| p == held && (!both || far(g2[p][v])));
                    (format!("test={}", dataset.pairs[held].name), train, test)
                })
                .collect()
        }
        _ => Vec::new(),
    }
}

pub const SPLITS: [&str; 4] = [
    "random",
    "cross_scale",
    "cross_interaction",
    "cross_scale_interaction",
];

/// Per-window metric sums.
#[derive(Default)]
struct Acc {
    e_r: f64,
    e_b: f64,
    jpd: f64,
    jpd_n: usize,
    jpd_gt: f64,
    n: usize,
}

fn dist(x: &[f32], y: &[f32]) -> f64 {
    x.iter()
        .zip(y)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Per-window (E_r, E_b) for one body: `pred`, `truth`, `template` are `[T, V, 3]`.
fn body_errors(
    pred: &[f32],
    truth: Option<&[f32]>,
    template: &[f32],
    factors: Option<&[f32]>,
    parents: &[i32],
    frames: usize,
) -> (f64, f64) {
    let v = parents.len();
    let e_r = truth.map_or(0.0, |t| {
        (0..frames * v)
            .map(|k| dist(&pred[k * 3..k * 3 + 3], &t[k * 3..k * 3 + 3]))
            .sum::<f64>()
            / (frames * v) as f64
    });
    let target: Vec<f64> = crate::generate::edge_lengths(template, parents)
        .iter()
        .enumerate()
        .map(|(i, l)| l * factors.map_or(1.0, |f| f[i] as f64))
        .collect();
    let e_b = crate::generate::mean_bone_error(pred, parents, &target, frames);
    (e_r, e_b)
}

/// Mean JPD of one window (None when no key pair frame falls in it).
fn window_jpd(
    dataset: &Dataset,
    s: &Sample,
    window: usize,
    pa: &[f32],
    pb: &[f32],
    ta: &[f32],
    tb: &[f32],
) -> Option<f64> {
    let pair = &dataset.pairs[s.pair];
    let (va, vb) = (pair.body_a.len(), pair.body_b.len());
    let (mut sum, mut n) = (0.0, 0usize);
    for k in &pair.key_pairs {
        for f in 0..window {
            let t = s.start + f;
            if t < k.first || t > k.last || t >= pair.frames {
                continue;
            }
            let p =
                |x: &[f32], v: usize, i: usize| x[(f * v + i) * 3..(f * v + i) * 3 + 3].to_vec();
            let d1 = dist(&p(pa, va, k.a), &p(pb, vb, k.b));
            let d0 = dist(&p(ta, va, k.a), &p(tb, vb, k.b));
            sum += (d1 - d0).abs();
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as f64)
}

fn flat3(t: &Tensor) -> Result<Vec<f32>> {
    Ok(t.flatten_all()?.to_vec1::<f32>()?)
}

/// Metrics of predictions `(pa, pb)` on `batch`; `factors` per window (B).
#[allow(clippy::too_many_arguments)]
fn accumulate(
    dataset: &Dataset,
    batch: &Batch,
    window: usize,
    pa: &Tensor,
    pb: &Tensor,
    factors: &[Vec<f32>],
    with_truth: bool,
    acc: &mut Acc,
) -> Result<()> {
    let pair0 = &dataset.pairs[0];
    let (va, vb) = (pair0.body_a.len(), pair0.body_b.len());
    let (pa, pb) = (flat3(pa)?, flat3(pb)?);
    let (ta, tb) = (flat3(&batch.template_a)?, flat3(&batch.template_b)?);
    let (ga, gb) = (flat3(&batch.a)?, flat3(&batch.b)?);
    let (sa, sb) = (window * va * 3, window * vb * 3);
    for (k, s) in batch.samples.iter().enumerate() {
        let a = &pa[k * sa..(k + 1) * sa];
        let b = &pb[k * sb..(k + 1) * sb];
        let (ta_k, tb_k) = (&ta[k * sa..(k + 1) * sa], &tb[k * sb..(k + 1) * sb]);
        let (ga_k, gb_k) = (&ga[k * sa..(k + 1) * sa], &gb[k * sb..(k + 1) * sb]);
        let (era, eba) = body_errors(
            a,
            with_truth.then_some(ga_k),
            ta_k,
            None,
            &pair0.body_a.parents,
            window,
        );
        let (erb, ebb) = body_errors(
            b,
            with_truth.then_some(gb_k),
            tb_k,
            Some(&factors[k]),
            &pair0.body_b.parents,
            window,
        );
        acc.e_r += 0.5 * (era + erb);
        acc.e_b += 0.5 * (eba + ebb);
        acc.n += 1;
        if let Some(j) = window_jpd(dataset, s, window, a, b, ta_k, tb_k) {
            acc.jpd += j;
            acc.jpd_n += 1;
            if let Some(g) = window_jpd(dataset, s, window, ga_k, gb_k, ta_k, tb_k) {
                acc.jpd_gt += g;
            }
        }
    }
    Ok(())
}

fn evaluate_fold(
    dataset: &Dataset,
    features: &FeatureNet,
    name: &str,
    train_set: &[Sample],
    test_set: &[Sample],
    config: &EvalConfig,
) -> Result<(FoldResult, InteractionModel)> {
    let span = tracing::info_span!("interaction_eval_fold", fold = name);
    let _guard = span.enter();
    let w = config.train.window;
    let model = train(dataset, train_set, &config.train, None)?;
    let count_vars = |s: &[Sample]| {
        let set: std::collections::BTreeSet<(usize, usize)> =
            s.iter().map(|x| (x.pair, x.variation)).collect();
        set.len()
    };
    let (mut ret, mut gen_acc) = (Acc::default(), Acc::default());
    let (mut f_pred, mut f_gen, mut f_true) = (Vec::new(), Vec::new(), Vec::new());
    let mut net_s = 0.0;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x6E6E);
    for chunk in test_set.chunks(64) {
        let batch = dataset.batch(chunk, w)?;
        let factors: Vec<Vec<f32>> = chunk
            .iter()
            .map(|s| dataset.pairs[s.pair].factors[s.variation].clone())
            .collect();
        let t0 = Instant::now();
        let (pa, pb) = model.predict(&batch.template_a, &batch.template_b, &batch.scales, None)?;
        net_s += t0.elapsed().as_secs_f64();
        accumulate(dataset, &batch, w, &pa, &pb, &factors, true, &mut ret)?;
        f_pred.extend(rows(&features.features(&pa, &pb)?)?);
        f_true.extend(rows(&features.features(&batch.a, &batch.b)?)?);
        // Generation: B's scales from the prior.
        let seed = rand::Rng::random::<u64>(&mut rng);
        let drawn = model.sample_scales(chunk.len(), seed)?;
        let flat: Vec<f32> = drawn.iter().flatten().copied().collect();
        let scales = Tensor::from_vec(flat, batch.scales.dims(), batch.scales.device())?;
        let (ga, gb) = model.predict(&batch.template_a, &batch.template_b, &scales, None)?;
        accumulate(dataset, &batch, w, &ga, &gb, &drawn, false, &mut gen_acc)?;
        f_gen.extend(rows(&features.features(&ga, &gb)?)?);
    }
    // Reference: ground-truth training windows against the test windows.
    let mut f_train = Vec::new();
    let mut picked = train_set.to_vec();
    picked.shuffle(&mut ChaCha8Rng::seed_from_u64(config.seed ^ 0xDA7A));
    picked.truncate(test_set.len().max(64));
    for chunk in picked.chunks(64) {
        let batch = dataset.batch(chunk, w)?;
        f_train.extend(rows(&features.features(&batch.a, &batch.b)?)?);
    }
    let n = ret.n.max(1) as f64;
    let jpd = |a: &Acc| (a.jpd_n > 0).then(|| a.jpd / a.jpd_n as f64);
    let result = FoldResult {
        name: name.to_string(),
        train_variations: count_vars(train_set),
        test_variations: count_vars(test_set),
        train_windows: train_set.len(),
        test_windows: test_set.len(),
        train_s: model.meta.training.seconds,
        final_loss: model.meta.training.final_losses.total,
        retarget: RetargetMetrics {
            e_r_m: ret.e_r / n,
            e_b_m: ret.e_b / n,
            jpd_m: jpd(&ret),
            fid: fid(&f_pred, &f_true)?,
        },
        generation: GenerationMetrics {
            e_b_m: gen_acc.e_b / n,
            jpd_m: jpd(&gen_acc),
            fid: fid(&f_gen, &f_true)?,
        },
        optimiser_jpd_m: (ret.jpd_n > 0).then(|| ret.jpd_gt / ret.jpd_n as f64),
        fid_data: fid(&f_train, &f_true)?,
        inference_ms_per_window: 1e3 * net_s / n,
    };
    tracing::info!(fold = name, e_r = result.retarget.e_r_m, "fold done");
    Ok((result, model))
}

fn mean_opt(xs: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = xs.flatten().collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Run the four splits (or those named in `only`) and the comparison
/// (when the source clips are given, named as in the dataset). Folds run
/// `config.jobs` at a time, each on one thread (see [`crate::train::train`]).
/// `on_split` gets the report so far (complete splits) after each fold, to
/// save partial results of a long run.
pub fn evaluate(
    dataset: &Dataset,
    config: &EvalConfig,
    only: &[String],
    sources: &[(String, Motion, Motion)],
    progress: &mut (dyn FnMut(&str) + Send),
    on_split: &mut (dyn FnMut(&EvalReport) + Send),
) -> Result<EvalReport> {
    evaluate_here(dataset, config, only, sources, progress, on_split)
}

fn evaluate_here(
    dataset: &Dataset,
    config: &EvalConfig,
    only: &[String],
    sources: &[(String, Motion, Motion)],
    progress: &mut (dyn FnMut(&str) + Send),
    on_split: &mut (dyn FnMut(&EvalReport) + Send),
) -> Result<EvalReport> {
    let start = Instant::now();
    progress("training the FID feature network");
    let (features, quality) = train_features(dataset, config)?;
    let tasks = tasks(dataset, config, only)?;
    let run = Run {
        dataset,
        config,
        sources,
        features: &features,
        quality: &quality,
        tasks: &tasks,
        start,
        progress: Mutex::new(progress),
        done: Mutex::new(vec![None; tasks.len()]),
        comparison: Mutex::new(Vec::new()),
        on_split: Mutex::new(on_split),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(config.jobs.max(1))
        .thread_name(|i| format!("interaction-eval-{i}"))
        .build()
        .map_err(|e| ModelError::Data(format!("cannot start the evaluation threads: {e}")))?;
    use rayon::prelude::*;
    pool.install(|| {
        (0..tasks.len())
            .into_par_iter()
            .try_for_each(|i| run.fold(i))
    })?;
    let done = run
        .done
        .into_inner()
        .map_err(|_| ModelError::Data("a fold panicked".into()))?;
    let rows = run.comparison.into_inner().unwrap_or_default();
    Ok(report(
        dataset,
        config,
        &quality,
        &assemble(&tasks, &done),
        &rows,
        start,
    ))
}

/// The FID feature network, trained on one thread on every variation (80/20
/// by variation for its own check).
fn train_features(dataset: &Dataset, config: &EvalConfig) -> Result<(FeatureNet, FeatureQuality)> {
    let w = config.train.window;
    let (f_train, f_test) = {
        let keep = folds(dataset, "random", config.seed ^ 0xF1D);
        let (_, tr, te) = &keep[0];
        (
            dataset.windows(w, config.test_stride, tr),
            dataset.windows(w, config.test_stride, te),
        )
    };
    let mut fc = FeatureConfig::new(dataset.pairs.len());
    fc.steps = config.feature_steps;
    fc.seed = config.seed;
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| ModelError::Data(format!("cannot start the evaluation thread: {e}")))?;
    one.install(|| FeatureNet::train(dataset, &f_train, &f_test, w, &fc))
}

/// One fold of one split: what a task trains and tests on.
struct Task {
    split: &'static str,
    name: String,
    train: Vec<Sample>,
    test: Vec<Sample>,
}

/// Every fold of every split (of `only`, when given) as one task.
fn tasks(dataset: &Dataset, config: &EvalConfig, only: &[String]) -> Result<Vec<Task>> {
    let w = config.train.window;
    let mut tasks = Vec::new();
    for split in SPLITS {
        if !only.is_empty() && !only.iter().any(|s| s == split) {
            continue;
        }
        for (name, tr, te) in folds(dataset, split, config.seed) {
            let train = dataset.windows(w, config.train.stride, &tr);
            let test = dataset.windows(w, config.test_stride, &te);
            if train.is_empty() || test.is_empty() {
                return Err(ModelError::Data(format!(
                    "split {split} fold {name}: {} training and {} test windows",
                    train.len(),
                    test.len()
                )));
            }
            tasks.push(Task {
                split,
                name,
                train,
                test,
            });
        }
    }
    Ok(tasks)
}

/// The splits whose folds are all done, averaged.
fn assemble(tasks: &[Task], done: &[Option<FoldResult>]) -> Vec<SplitResult> {
    let mut splits = Vec::new();
    for split in SPLITS {
        let mine: Vec<usize> = (0..tasks.len())
            .filter(|&i| tasks[i].split == split)
            .collect();
        if mine.is_empty() || mine.iter().any(|&i| done[i].is_none()) {
            continue;
        }
        let results: Vec<FoldResult> = mine.iter().filter_map(|&i| done[i].clone()).collect();
        splits.push(split_result(split, results));
    }
    splits
}

/// The evaluation while its folds run, `jobs` at a time: what every fold
/// reads, and what they report into (folds done, the optimiser comparison,
/// the caller's progress and per-split callbacks).
struct Run<'a> {
    dataset: &'a Dataset,
    config: &'a EvalConfig,
    sources: &'a [(String, Motion, Motion)],
    features: &'a FeatureNet,
    quality: &'a FeatureQuality,
    tasks: &'a [Task],
    start: Instant,
    progress: Mutex<&'a mut (dyn FnMut(&str) + Send)>,
    done: Mutex<Vec<Option<FoldResult>>>,
    comparison: Mutex<Vec<CompareRow>>,
    on_split: Mutex<&'a mut (dyn FnMut(&EvalReport) + Send)>,
}

impl Run<'_> {
    fn say(&self, msg: &str) {
        if let Ok(mut p) = self.progress.lock() {
            (*p)(msg);
        }
    }

    /// Train and test fold `i`; on the random split also compare with the
    /// optimiser on whole clips; then report the splits done so far.
    fn fold(&self, i: usize) -> Result<()> {
        let t = &self.tasks[i];
        self.say(&format!(
            "{} {}: training on {} windows, testing on {}",
            t.split,
            t.name,
            t.train.len(),
            t.test.len()
        ));
        let (r, model) = evaluate_fold(
            self.dataset,
            self.features,
            &t.name,
            &t.train,
            &t.test,
            self.config,
        )?;
        if t.split == "random" && !self.sources.is_empty() {
            self.say("comparing with the optimiser on whole clips");
            let held: std::collections::BTreeSet<(usize, usize)> =
                t.test.iter().map(|s| (s.pair, s.variation)).collect();
            let keep: Keep = Box::new(move |p, v| held.contains(&(p, v)));
            let rows = compare(
                self.dataset,
                &model,
                &keep,
                self.sources,
                self.config.compare_per_pair,
            )?;
            if let Ok(mut c) = self.comparison.lock() {
                *c = rows;
            }
        }
        self.say(&format!(
            "{} {}: done in {:.0} s",
            t.split, t.name, r.train_s
        ));
        let snapshot = {
            let mut d = self
                .done
                .lock()
                .map_err(|_| ModelError::Data("a fold panicked".into()))?;
            d[i] = Some(r);
            d.clone()
        };
        let rows = self
            .comparison
            .lock()
            .map(|c| c.clone())
            .unwrap_or_default();
        if let Ok(mut cb) = self.on_split.lock() {
            (*cb)(&report(
                self.dataset,
                self.config,
                self.quality,
                &assemble(self.tasks, &snapshot),
                &rows,
                self.start,
            ));
        }
        Ok(())
    }
}

fn split_result(split: &str, results: Vec<FoldResult>) -> SplitResult {
    let k = results.len().max(1) as f64;
    let avg = |f: &dyn Fn(&FoldResult) -> f64| results.iter().map(f).sum::<f64>() / k;
    SplitResult {
        split: split.to_string(),
        retarget: RetargetMetrics {
            e_r_m: avg(&|r| r.retarget.e_r_m),
            e_b_m: avg(&|r| r.retarget.e_b_m),
            jpd_m: mean_opt(results.iter().map(|r| r.retarget.jpd_m)),
            fid: avg(&|r| r.retarget.fid),
        },
        generation: GenerationMetrics {
            e_b_m: avg(&|r| r.generation.e_b_m),
            jpd_m: mean_opt(results.iter().map(|r| r.generation.jpd_m)),
            fid: avg(&|r| r.generation.fid),
        },
        optimiser_jpd_m: mean_opt(results.iter().map(|r| r.optimiser_jpd_m)),
        fid_data: avg(&|r| r.fid_data),
        folds: results,
    }
}

fn report(
    dataset: &Dataset,
    config: &EvalConfig,
    quality: &FeatureQuality,
    splits: &[SplitResult],
    comparison: &[CompareRow],
    start: Instant,
) -> EvalReport {
    EvalReport {
        dataset: DatasetSummary {
            pairs: dataset
                .pairs
                .iter()
                .map(|p| (p.name.clone(), p.frames, p.variations.len()))
                .collect(),
            fps: dataset.config.fps,
            window: config.train.window,
            train_stride: config.train.stride,
            test_stride: config.test_stride,
            build_wall_s: dataset.build_wall_s,
        },
        config: config.clone(),
        feature_net: *quality,
        splits: splits.to_vec(),
        comparison: comparison.to_vec(),
        wall_s: start.elapsed().as_secs_f64(),
    }
}

/// Whole-clip variations by the model next to the optimiser's, on held-out variations.
fn compare(
    dataset: &Dataset,
    model: &InteractionModel,
    test: &Keep,
    sources: &[(String, Motion, Motion)],
    per_pair: usize,
) -> Result<Vec<CompareRow>> {
    let mut rows = Vec::new();
    for (p, pair) in dataset.pairs.iter().enumerate() {
        let Some((_, a, b)) = sources.iter().find(|(n, _, _)| *n == pair.name) else {
            continue;
        };
        let held: Vec<usize> = (0..pair.variations.len()).filter(|&v| test(p, v)).collect();
        for &v in held.iter().take(per_pair) {
            let meta = &pair.variations[v];
            let g = generate(model, a, b, &meta.scale, "retarget", &Default::default())?;
            let e_r = 0.5
                * (crate::eval::mean_dist(&g.points_a, &pair.a[v])
                    + crate::eval::mean_dist(&g.points_b, &pair.b[v]));
            rows.push(CompareRow {
                pair: pair.name.clone(),
                scale: meta.global,
                method: "learned".into(),
                wall_s: g.report.wall_s,
                e_r_m: Some(e_r),
                e_b_m: g.report.network_bone_error_m,
                jpd_m: g.report.jpd_m,
                foot_skating_a_m_s: g.report.foot_skating.a_output_m_s,
                foot_skating_b_m_s: g.report.foot_skating.b_output_m_s,
            });
            rows.push(CompareRow {
                pair: pair.name.clone(),
                scale: meta.global,
                method: "optimiser".into(),
                wall_s: meta.wall_s,
                e_r_m: None,
                e_b_m: 0.0,
                jpd_m: meta.jpd_m,
                foot_skating_a_m_s: meta.foot_skating_a_m_s,
                foot_skating_b_m_s: meta.foot_skating_b_m_s,
            });
        }
    }
    Ok(rows)
}

/// Mean distance between corresponding points of two `[T, P, 3]` arrays.
pub fn mean_dist(x: &[f32], y: &[f32]) -> f64 {
    let n = x.len().min(y.len()) / 3;
    (0..n)
        .map(|k| dist(&x[k * 3..k * 3 + 3], &y[k * 3..k * 3 + 3]))
        .sum::<f64>()
        / n.max(1) as f64
}

fn cm(x: f64) -> String {
    format!("{:.2}", 100.0 * x)
}

fn cm_opt(x: Option<f64>) -> String {
    x.map(cm).unwrap_or_else(|| "n/a".into())
}

/// The report as Markdown: the four-split table and the comparison.
pub fn markdown(r: &EvalReport) -> String {
    let mut s = String::new();
    s.push_str("# Interaction model evaluation\n\n");
    s.push_str(&format!(
        "Dataset: {} at {} fps; windows of {} frames (training stride {}, test stride {}).\n\n",
        r.dataset
            .pairs
            .iter()
            .map(|(n, f, v)| format!("{n} ({f} frames, {v} variations)"))
            .collect::<Vec<_>>()
            .join(", "),
        r.dataset.fps,
        r.dataset.window,
        r.dataset.train_stride,
        r.dataset.test_stride
    ));
    s.push_str(&format!(
        "FID feature network: held-out interaction accuracy {:.3}, scale RMSE {:.4} ({} / {} windows, {:.0} s).\n\n",
        r.feature_net.class_accuracy,
        r.feature_net.scale_rmse,
        r.feature_net.train_windows,
        r.feature_net.test_windows,
        r.feature_net.seconds
    ));
    s.push_str("Lengths in cm. Retargeting: B's scales given; generation: drawn from the prior. `opt. JPD` is the optimiser's own JPD on the same test windows; `FID data` compares ground-truth training and test windows.\n\n");
    s.push_str("| split | E_r | E_b | JPD | FID | gen. E_b | gen. JPD | gen. FID | opt. JPD | FID data | train / test windows | train s |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for sp in &r.splits {
        let tw: usize = sp.folds.iter().map(|f| f.train_windows).sum();
        let te: usize = sp.folds.iter().map(|f| f.test_windows).sum();
        let ts: f64 = sp.folds.iter().map(|f| f.train_s).sum();
        s.push_str(&format!(
            "| {} | {} | {} | {} | {:.3} | {} | {} | {:.3} | {} | {:.3} | {} / {} | {:.0} |\n",
            sp.split,
            cm(sp.retarget.e_r_m),
            cm(sp.retarget.e_b_m),
            cm_opt(sp.retarget.jpd_m),
            sp.retarget.fid,
            cm(sp.generation.e_b_m),
            cm_opt(sp.generation.jpd_m),
            sp.generation.fid,
            cm_opt(sp.optimiser_jpd_m),
            sp.fid_data,
            tw,
            te,
            ts
        ));
    }
    let multi: Vec<&SplitResult> = r.splits.iter().filter(|s| s.folds.len() > 1).collect();
    if !multi.is_empty() {
        s.push_str("\nPer fold:\n\n| split | fold | E_r | E_b | JPD | FID | gen. E_b | gen. JPD | opt. JPD |\n|---|---|---|---|---|---|---|---|---|\n");
        for sp in multi {
            for f in &sp.folds {
                s.push_str(&format!(
                    "| {} | {} | {} | {} | {} | {:.3} | {} | {} | {} |\n",
                    sp.split,
                    f.name,
                    cm(f.retarget.e_r_m),
                    cm(f.retarget.e_b_m),
                    cm_opt(f.retarget.jpd_m),
                    f.retarget.fid,
                    cm(f.generation.e_b_m),
                    cm_opt(f.generation.jpd_m),
                    cm_opt(f.optimiser_jpd_m)
                ));
            }
        }
    }
    if !r.comparison.is_empty() {
        s.push_str("\n## Optimiser vs learned model (whole clips, held-out variations of the random split, 30 fps)\n\n");
        s.push_str("| pair | scale | method | s / variation | E_r (cm) | E_b (cm) | JPD (cm) | skating A (m/s) | skating B (m/s) |\n|---|---|---|---|---|---|---|---|---|\n");
        for c in &r.comparison {
            s.push_str(&format!(
                "| {} | {:.2} | {} | {:.3} | {} | {} | {} | {:.3} | {:.3} |\n",
                c.pair,
                c.scale,
                c.method,
                c.wall_s,
                cm_opt(c.e_r_m),
                cm(c.e_b_m),
                cm_opt(c.jpd_m),
                c.foot_skating_a_m_s,
                c.foot_skating_b_m_s
            ));
        }
        for m in ["optimiser", "learned"] {
            let rows: Vec<&CompareRow> = r.comparison.iter().filter(|c| c.method == m).collect();
            let k = rows.len().max(1) as f64;
            s.push_str(&format!(
                "\nMean {m}: {:.3} s / variation, E_b {} cm, JPD {} cm, skating A {:.3} m/s, B {:.3} m/s.",
                rows.iter().map(|c| c.wall_s).sum::<f64>() / k,
                cm(rows.iter().map(|c| c.e_b_m).sum::<f64>() / k),
                cm_opt(mean_opt(rows.iter().map(|c| c.jpd_m))),
                rows.iter().map(|c| c.foot_skating_a_m_s).sum::<f64>() / k,
                rows.iter().map(|c| c.foot_skating_b_m_s).sum::<f64>() / k,
            ));
        }
        s.push('\n');
    }
    s.push_str(&format!("\nTotal evaluation time {:.0} s.\n", r.wall_s));
    s
}
