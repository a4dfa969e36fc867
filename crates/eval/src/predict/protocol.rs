//! One leave-one-actor-out run of MotionAug's prediction protocol (Sec. 4.3):
//! train a model on the training actors' clips, with and without augmented
//! clips, and score both on every window of the held-out actor's clips.
//!
//! The augmentation is not hard-wired: [`run`] takes a closure from the
//! training clips to the synthesised clips (a recipe, a VAE, a full pipeline),
//! and [`evaluate`] scores any training set, so a table can train the
//! no-augmentation model once and compare several augmentations against it.
//!
//! Error at a horizon: for each test window, the Euclidean norm of the wrapped
//! Euler-angle differences over all non-root joints ([`crate::euler`]) between
//! the predicted and the true frame 100 / 200 / 400 ms after the last observed
//! frame; averaged over windows, then over seeds.

use std::collections::BTreeMap;

use motion::Motion;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::euler::l2_distance;
use crate::predict::Predictor;
use crate::predict::body_graph::BodyGraph;
use crate::predict::data::{
    ClipSet, HORIZONS_MS, INPUT_FRAMES, Normalizer, OUTPUT_FRAMES, batch, features_to_euler,
    horizon_index,
};
use crate::predict::dmgnn::{Dmgnn, DmgnnConfig, Reconstruction};
use crate::predict::gcn::{Gcn, GcnConfig};
use crate::predict::occlusion::{MaskKind, Occluder};
use crate::predict::seq2seq::{Seq2Seq, Seq2SeqConfig};
use crate::predict::train::{TrainConfig, train};
use crate::predict::vdmgnn::{Vdmgnn, VdmgnnConfig};

/// Which prediction model to train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    Seq2seq,
    Gcn,
    Dmgnn,
    Vdmgnn,
}

impl std::str::FromStr for ModelKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "seq2seq" | "rnn" => Ok(ModelKind::Seq2seq),
            "gcn" => Ok(ModelKind::Gcn),
            "dmgnn" => Ok(ModelKind::Dmgnn),
            "vdmgnn" | "v-dmgnn-gan" | "vdmgnn-gan" => Ok(ModelKind::Vdmgnn),
            _ => Err(format!(
                "unknown model `{s}` (seq2seq, gcn, dmgnn or vdmgnn)"
            )),
        }
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ModelKind::Seq2seq => "seq2seq",
            ModelKind::Gcn => "gcn",
            ModelKind::Dmgnn => "dmgnn",
            ModelKind::Vdmgnn => "vdmgnn",
        })
    }
}

/// Model sizes (see [`Seq2SeqConfig`], [`GcnConfig`], [`DmgnnConfig`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelSizes {
    pub seq2seq_hidden: usize,
    pub gcn_hidden: usize,
    pub gcn_stages: usize,
    pub gcn_coefficients: usize,
    /// DMGNN / V-DMGNN-GAN encoder block channels and decoder state.
    #[serde(default = "default_graph_channels")]
    pub graph_channels: [usize; 4],
    #[serde(default = "default_graph_hidden")]
    pub graph_hidden: usize,
}

fn default_graph_channels() -> [usize; 4] {
    DmgnnConfig::new(INPUT_FRAMES).channels
}

fn default_graph_hidden() -> usize {
    DmgnnConfig::new(INPUT_FRAMES).hidden
}

impl Default for ModelSizes {
    fn default() -> Self {
        ModelSizes {
            seq2seq_hidden: 128,
            gcn_hidden: 64,
            gcn_stages: 2,
            gcn_coefficients: 20,
            graph_channels: default_graph_channels(),
            graph_hidden: default_graph_hidden(),
        }
    }
}

/// The DMGNN / V-DMGNN-GAN options of a protocol run (Table 2's ablations).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct GraphOptions {
    /// Reconstruction loss (default L1).
    #[serde(default)]
    pub loss: Reconstruction,
    /// V-DMGNN-GAN: also encode velocities and accelerations (DMGNN always does).
    #[serde(default)]
    pub vel_acc: bool,
}

/// Builds a DMGNN or V-DMGNN-GAN predictor (the other kinds are not graph models).
pub fn build_graph_model(
    kind: ModelKind,
    sizes: &ModelSizes,
    options: &GraphOptions,
    graph: &BodyGraph,
    input_frames: usize,
    seed: u64,
) -> Result<Box<dyn Predictor>> {
    let mut d = DmgnnConfig::new(input_frames);
    d.channels = sizes.graph_channels;
    d.hidden = sizes.graph_hidden;
    d.embed = sizes.graph_hidden;
    d.loss = options.loss;
    Ok(match kind {
        ModelKind::Dmgnn => Box::new(Dmgnn::new(&d, graph, seed)?),
        ModelKind::Vdmgnn => {
            d.vel_acc = options.vel_acc;
            let mut v = VdmgnnConfig::new(input_frames);
            v.latent = d.hidden;
            v.dmgnn = d;
            Box::new(Vdmgnn::new(&v, graph, seed)?)
        }
        other => {
            return Err(EvalError::Config(format!("{other} is not a graph model")));
        }
    })
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProtocolConfig {
    pub model: ModelKind,
    pub sizes: ModelSizes,
    pub train: TrainConfig,
    /// One model per seed; errors are averaged over seeds.
    pub seeds: Vec<u64>,
    /// Frames between consecutive windows.
    pub stride: usize,
    /// Caps (evenly spaced) on training and test windows; `None`: all.
    pub max_train_windows: Option<usize>,
    pub max_test_windows: Option<usize>,
    /// Occlusion of the observed test frames (and of training frames unless
    /// `train_mask` says otherwise).
    #[serde(default)]
    pub mask: MaskKind,
    /// Occlusion of the observed training frames (the mask augmentation);
    /// `None`: the same as `mask`.
    #[serde(default)]
    pub train_mask: Option<MaskKind>,
    #[serde(default)]
    pub graph: GraphOptions,
}

impl ProtocolConfig {
    pub fn new(model: ModelKind) -> Self {
        ProtocolConfig {
            model,
            sizes: ModelSizes::default(),
            train: TrainConfig::default(),
            seeds: vec![0],
            stride: 1,
            max_train_windows: None,
            max_test_windows: None,
            mask: MaskKind::None,
            train_mask: None,
            graph: GraphOptions::default(),
        }
    }
}

/// Mean error (radians) per horizon, keyed "100", "200", "400" (ms).
pub type Horizons = BTreeMap<String, f64>;

/// The scores of one training set.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConditionResult {
    /// Mean over seeds.
    pub errors: Horizons,
    pub per_seed: Vec<Horizons>,
    pub train_clips: usize,
    pub train_windows: usize,
    /// Training clips shorter than one window.
    pub skipped_clips: usize,
    /// Wall time of each seed's training, seconds.
    pub train_seconds: Vec<f64>,
    /// Training loss (normalised features) at the start and end, mean over seeds.
    pub first_loss: f64,
    pub last_loss: f64,
}

/// A full run: without and (when an augmentation was given) with augmented clips.
#[derive(Debug, Clone, Serialize)]
pub struct ProtocolResult {
    pub model: ModelKind,
    pub no_aug: ConditionResult,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aug: Option<ConditionResult>,
    /// Synthesised clips added to the training set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub augmented_clips: Option<usize>,
    /// Error of repeating the last observed frame (the zero-velocity baseline).
    pub zero_velocity: Horizons,
    pub test_clips: usize,
    pub test_windows: usize,
    pub config: ProtocolConfig,
}

/// Maps the training clips to synthesised clips.
pub type Augment<'a> = &'a dyn Fn(&[(String, Motion)]) -> Result<Vec<(String, Motion)>>;

/// The test windows of a fold, built once and scored many times.
pub struct TestSet {
    set: ClipSet,
    reference: Motion,
    /// The feature nodes (every non-root joint of the reference skeleton).
    graph: BodyGraph,
    occluder: Occluder,
}

/// Seed of the test masks: every model and condition sees the same occlusions.
const TEST_MASK_SEED: u64 = 0x7e57_3a5c;

impl TestSet {
    pub fn new(test: &[(String, Motion)], config: &ProtocolConfig) -> Result<TestSet> {
        let reference = test
            .first()
            .ok_or_else(|| EvalError::Data("no test clips".into()))?
            .1
            .clone();
        let mut set = ClipSet::new(test, &reference, crate::dataset::FPS, config.stride)?;
        if let Some(m) = config.max_test_windows {
            set.limit_windows(m);
        }
        if set.windows.is_empty() {
            return Err(EvalError::Data(format!(
                "no test clip has the {} frames of a window",
                INPUT_FRAMES + OUTPUT_FRAMES
            )));
        }
        let graph = BodyGraph::non_root(reference.skeleton())?;
        let occluder = Occluder::new(config.mask, &graph)?;
        Ok(TestSet {
            set,
            reference,
            graph,
            occluder,
        })
    }

    pub fn clips(&self) -> usize {
        self.set.clips.len()
    }

    pub fn windows(&self) -> usize {
        self.set.windows.len()
    }

    /// Error of predicting "the pose stays the last observed one" (unmasked).
    pub fn zero_velocity(&self) -> Horizons {
        let mut sums = [0.0; HORIZONS_MS.len()];
        for &(c, s) in &self.set.windows {
            let e = &self.set.clips[c].euler;
            let last = e.frame(s + INPUT_FRAMES - 1);
            for (k, ms) in HORIZONS_MS.iter().enumerate() {
                let h = horizon_index(*ms, crate::dataset::FPS);
                sums[k] += l2_distance(last, e.frame(s + INPUT_FRAMES + h));
            }
        }
        horizons(sums, self.set.windows.len())
    }

    /// Mean Euler error of `model` per horizon.
    fn score(&self, model: &dyn Predictor, norm: &Normalizer) -> Result<Horizons> {
        let mut sums = [0.0; HORIZONS_MS.len()];
        let d = self.set.dim;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(TEST_MASK_SEED);
        for chunk in self.set.windows.chunks(256) {
            let (input, _) = batch(&self.set, norm, chunk)?;
            let input = self.occluder.apply(&input, &mut rng)?;
            let pred = model.predict(&input, OUTPUT_FRAMES)?;
            let mut flat: Vec<f32> = pred.flatten_all()?.to_vec1()?;
            norm.denorm(&mut flat);
            for (w, &(c, s)) in chunk.iter().enumerate() {
                let e = &self.set.clips[c].euler;
                for (k, ms) in HORIZONS_MS.iter().enumerate() {
                    let h = horizon_index(*ms, crate::dataset::FPS);
                    let off = (w * OUTPUT_FRAMES + h) * d;
                    let p = features_to_euler(&flat[off..off + d], &self.set.clips[c].convention);
                    sums[k] += l2_distance(&p, e.frame(s + INPUT_FRAMES + h));
                }
            }
        }
        Ok(horizons(sums, self.set.windows.len()))
    }
}

fn horizons(sums: [f64; HORIZONS_MS.len()], n: usize) -> Horizons {
    HORIZONS_MS
        .iter()
        .zip(sums)
        .map(|(ms, s)| (ms.to_string(), s / n.max(1) as f64))
        .collect()
}

pub(crate) fn build(
    config: &ProtocolConfig,
    graph: &BodyGraph,
    dim: usize,
    seed: u64,
) -> Result<Box<dyn Predictor>> {
    Ok(match config.model {
        ModelKind::Dmgnn | ModelKind::Vdmgnn => build_graph_model(
            config.model,
            &config.sizes,
            &config.graph,
            graph,
            INPUT_FRAMES,
            seed,
        )?,
        ModelKind::Seq2seq => Box::new(Seq2Seq::new(
            &Seq2SeqConfig {
                dim,
                hidden: config.sizes.seq2seq_hidden,
            },
            seed,
        )?),
        ModelKind::Gcn => {
            let frames = INPUT_FRAMES + OUTPUT_FRAMES;
            Box::new(Gcn::new(
                &GcnConfig {
                    dim,
                    frames,
                    coefficients: config.sizes.gcn_coefficients.min(frames),
                    hidden: config.sizes.gcn_hidden,
                    stages: config.sizes.gcn_stages,
                },
                seed,
            )?)
        }
    })
}

/// Trains one model per seed on `train` and scores it on `test`.
/// `progress` receives one line per seed.
pub fn evaluate(
    train_clips: &[(String, Motion)],
    test: &TestSet,
    config: &ProtocolConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<ConditionResult> {
    if config.seeds.is_empty() {
        return Err(EvalError::Config("at least one seed".into()));
    }
    let mut set = ClipSet::new(
        train_clips,
        &test.reference,
        crate::dataset::FPS,
        config.stride,
    )?;
    if let Some(m) = config.max_train_windows {
        set.limit_windows(m);
    }
    let norm = Normalizer::fit(&set);
    let mut per_seed = Vec::new();
    let mut seconds = Vec::new();
    let (mut first, mut last) = (0.0, 0.0);
    for &seed in &config.seeds {
        let model = build(config, &test.graph, set.dim, seed)?;
        let train_occluder = Occluder::new(config.train_mask.unwrap_or(config.mask), &test.graph)?;
        let report = train(
            model.as_ref(),
            &set,
            &norm,
            &config.train,
            seed,
            Some(&train_occluder),
            |_, _| {},
        )?;
        let errors = test.score(model.as_ref(), &norm)?;
        progress(&format!(
            "{} seed {seed}: {} windows of {} clips, loss {:.4} -> {:.4} in {:.1} s; error 100/200/400 ms {:.3}/{:.3}/{:.3} rad",
            config.model,
            set.windows.len(),
            set.clips.len(),
            report.first_loss,
            report.last_loss,
            report.seconds,
            errors["100"],
            errors["200"],
            errors["400"]
        ));
        first += report.first_loss / config.seeds.len() as f64;
        last += report.last_loss / config.seeds.len() as f64;
        seconds.push(report.seconds);
        per_seed.push(errors);
    }
    let mut errors = Horizons::new();
    for ms in HORIZONS_MS {
        let k = ms.to_string();
        let mean = per_seed.iter().map(|e| e[&k]).sum::<f64>() / per_seed.len() as f64;
        errors.insert(k, mean);
    }
    Ok(ConditionResult {
        errors,
        per_seed,
        train_clips: set.clips.len(),
        train_windows: set.windows.len(),
        skipped_clips: set.skipped.len(),
        train_seconds: seconds,
        first_loss: first,
        last_loss: last,
    })
}

/// The whole protocol for one fold: `no_aug` trained on `train`, and with
/// `augment`, `aug` trained on `train` plus `augment(train)`.
pub fn run(
    train: &[(String, Motion)],
    test: &[(String, Motion)],
    augment: Option<Augment<'_>>,
    config: &ProtocolConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<ProtocolResult> {
    let span = tracing::info_span!("predict_protocol", model = %config.model);
    let _guard = span.enter();
    let test_set = TestSet::new(test, config)?;
    progress(&format!(
        "test: {} windows of {} clips; training without augmentation",
        test_set.windows(),
        test_set.clips()
    ));
    let no_aug = evaluate(train, &test_set, config, progress)?;
    let (aug, augmented_clips) = match augment {
        None => (None, None),
        Some(f) => {
            let synth = f(train)?;
            let n = synth.len();
            progress(&format!("training with {n} augmented clips"));
            let mut all = train.to_vec();
            all.extend(synth);
            (Some(evaluate(&all, &test_set, config, progress)?), Some(n))
        }
    };
    Ok(ProtocolResult {
        model: config.model,
        no_aug,
        aug,
        augmented_clips,
        zero_velocity: test_set.zero_velocity(),
        test_clips: test_set.clips(),
        test_windows: test_set.windows(),
        config: config.clone(),
    })
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use motion::glam::{DQuat, DVec3};
    use motion::{Joint, Skeleton};

    use super::*;

    /// Three-joint chain swinging sinusoidally (phase and speed per clip).
    fn clips(n: usize, phase0: f64) -> Vec<(String, Motion)> {
        let joint = |name: &str, parent: Option<usize>| Joint {
            name: name.into(),
            parent,
            offset: DVec3::new(0.0, 0.3, 0.0),
            channels: vec![],
            end_site: None,
            limits: None,
        };
        let s = Arc::new(
            Skeleton::new(
                vec![
                    joint("root", None),
                    joint("a", Some(0)),
                    joint("b", Some(1)),
                ],
                1.0,
            )
            .unwrap(),
        );
        (0..n)
            .map(|i| {
                let speed = 0.15 + 0.02 * i as f64;
                let phase = phase0 + i as f64;
                let frames = 40;
                let root = vec![DVec3::ZERO; frames];
                let rot = (0..frames)
                    .flat_map(|t| {
                        let x = phase + speed * t as f64;
                        [
                            DQuat::IDENTITY,
                            DQuat::from_rotation_x(0.8 * x.sin()),
                            DQuat::from_rotation_z(0.5 * (1.3 * x).cos()),
                        ]
                    })
                    .collect();
                (
                    format!("clip{i}"),
                    Motion::new(s.clone(), 30.0, root, rot).unwrap(),
                )
            })
            .collect()
    }

    /// A skeleton with legs and arms (so bodies, parts and the lower-body
    /// mask exist), every joint swinging at its own phase.
    fn limbed_clips(n: usize, phase0: f64) -> Vec<(String, Motion)> {
        let names = [
            ("root", None),
            ("lfemur", Some(0)),
            ("ltibia", Some(1)),
            ("lfoot", Some(2)),
            ("rfemur", Some(0)),
            ("rtibia", Some(4)),
            ("rfoot", Some(5)),
            ("thorax", Some(0)),
            ("head", Some(7)),
            ("lhumerus", Some(7)),
            ("lwrist", Some(9)),
            ("rhumerus", Some(7)),
            ("rwrist", Some(11)),
        ];
        let s = Arc::new(
            Skeleton::new(
                names
                    .iter()
                    .map(|(name, parent)| Joint {
                        name: (*name).into(),
                        parent: *parent,
                        offset: if name.contains("femur")
                            || name.contains("tibia")
                            || name.contains("foot")
                        {
                            DVec3::new(0.0, -0.4, 0.0)
                        } else {
                            DVec3::new(0.0, 0.3, 0.0)
                        },
                        channels: vec![],
                        end_site: None,
                        limits: None,
                    })
                    .collect(),
                1.0,
            )
            .unwrap(),
        );
        (0..n)
            .map(|i| {
                let speed = 0.15 + 0.02 * i as f64;
                let phase = phase0 + i as f64;
                let frames = 40;
                let rot = (0..frames)
                    .flat_map(|t| {
                        (0..names.len()).map(move |j| {
                            let x = phase + speed * t as f64 + 0.4 * j as f64;
                            if j == 0 {
                                DQuat::IDENTITY
                            } else {
                                DQuat::from_rotation_x(0.6 * x.sin())
                            }
                        })
                    })
                    .collect();
                (
                    format!("clip{i}"),
                    Motion::new(s.clone(), 30.0, vec![DVec3::ZERO; frames], rot).unwrap(),
                )
            })
            .collect()
    }

    #[test]
    fn graph_models_learn_under_masks() {
        let train = limbed_clips(6, 0.0);
        let test = limbed_clips(2, 0.5);
        for (model, mask) in [
            (ModelKind::Dmgnn, MaskKind::Lower),
            (ModelKind::Vdmgnn, MaskKind::Random),
        ] {
            let mut config = ProtocolConfig::new(model);
            config.sizes.graph_channels = [4, 8, 8, 8];
            config.sizes.graph_hidden = 8;
            config.mask = mask;
            config.train.iterations = 60;
            config.train.batch_size = 8;
            config.train.lr = 3e-3;
            let r = run(&train, &test, None, &config, &mut |_| {}).unwrap();
            assert!(
                r.no_aug.last_loss < 0.7 * r.no_aug.first_loss,
                "{model} {mask}: {:?}",
                r.no_aug
            );
            for ms in ["100", "200", "400"] {
                assert!(r.no_aug.errors[ms].is_finite());
            }
        }
    }

    #[test]
    fn both_models_learn_and_beat_zero_velocity() {
        let train = clips(6, 0.0);
        let test = clips(2, 0.5);
        for model in [ModelKind::Seq2seq, ModelKind::Gcn] {
            let mut config = ProtocolConfig::new(model);
            config.sizes = ModelSizes {
                seq2seq_hidden: 32,
                gcn_hidden: 16,
                gcn_stages: 1,
                gcn_coefficients: 20,
                ..ModelSizes::default()
            };
            config.train.iterations = 150;
            config.train.batch_size = 16;
            config.train.lr = 3e-3;
            let mut lines = Vec::new();
            let double = |c: &[(String, Motion)]| Ok(c.to_vec());
            let r = run(&train, &test, Some(&double), &config, &mut |l| {
                lines.push(l.to_string())
            })
            .unwrap();
            let aug = r.aug.as_ref().unwrap();
            assert_eq!(r.augmented_clips, Some(6));
            assert_eq!(aug.train_clips, 12);
            assert!(
                r.no_aug.last_loss < 0.5 * r.no_aug.first_loss,
                "{model}: {:?}",
                r.no_aug
            );
            for ms in ["100", "200", "400"] {
                let e = r.no_aug.errors[ms];
                assert!(
                    e.is_finite() && e < r.zero_velocity[ms],
                    "{model} {ms}: {e} vs {:?}",
                    r.zero_velocity
                );
            }
            assert_eq!(lines.len(), 4, "{lines:?}");
            let json = serde_json::to_value(&r).unwrap();
            assert!(json["no_aug"]["errors"]["400"].is_f64());
        }
    }
}
