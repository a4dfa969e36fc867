//! A prediction model as a file a user keeps: `motionaug predict train`
//! writes it, `motionaug predict run` loads it and predicts one clip.
//!
//! A model folder holds `model.json` ([`ModelFile`]: the kind and sizes, the
//! skeleton's feature nodes as a [`BodyGraph`], the normalisation, the frame
//! rate and window, the mask it was trained under, its training figures) and
//! `weights.safetensors`. A clip whose skeleton does not have the same nodes
//! is refused with an error naming both joint lists.
//!
//! A prediction ([`Prediction`]) is written as three clips of the observed +
//! predicted window: the truth, what the model saw (occluded joints replaced
//! by the mask's noise) and the prediction, with the mask. The root is not
//! predicted (as in the protocol): predicted frames take the clip's own root.

use std::path::Path;

use candle_core::{Device, Tensor};
use motion::Motion;
use motion::glam::{DQuat, DVec3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::predict::Predictor;
use crate::predict::body_graph::BodyGraph;
use crate::predict::data::{ClipSet, INPUT_FRAMES, Normalizer, OUTPUT_FRAMES, features};
use crate::predict::occlusion::{MaskKind, Occluder};
use crate::predict::protocol::{GraphOptions, ModelKind, ModelSizes, ProtocolConfig, build};
use crate::predict::train::{self, TrainConfig, TrainReport};

pub const MODEL_FILE: &str = "model.json";
pub const WEIGHTS_FILE: &str = "weights.safetensors";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    pub model: ModelKind,
    pub sizes: ModelSizes,
    pub options: GraphOptions,
    /// The feature nodes (every non-root joint of the training skeleton).
    pub graph: BodyGraph,
    pub normalizer: Normalizer,
    pub fps: f64,
    pub input_frames: usize,
    pub output_frames: usize,
    /// The occlusion the model was trained under.
    pub mask: MaskKind,
    pub train: TrainConfig,
    pub seed: u64,
    pub clips: Vec<String>,
    pub windows: usize,
    pub first_loss: f64,
    pub last_loss: f64,
    pub train_seconds: f64,
}

pub struct TrainedPredictor {
    pub file: ModelFile,
    model: Box<dyn Predictor>,
}

/// What `predict run` writes.
pub struct Prediction {
    /// First observed frame in the clip (at the model's frame rate).
    pub start: usize,
    /// Observed + true future frames.
    pub truth: Motion,
    /// Observed frames as the model saw them, then the true future.
    pub seen: Motion,
    /// Observed frames, then the predicted future.
    pub predicted: Motion,
    /// Per observed frame and feature node: all three values visible.
    pub visible: Vec<Vec<bool>>,
}

fn to_config(file: &ModelFile) -> ProtocolConfig {
    let mut c = ProtocolConfig::new(file.model);
    c.sizes = file.sizes;
    c.graph = file.options;
    c.mask = file.mask;
    c.train = file.train;
    c
}

impl TrainedPredictor {
    /// Trains `model` on every window of `clips` (one skeleton layout).
    #[allow(clippy::too_many_arguments)]
    pub fn train(
        clips: &[(String, Motion)],
        model: ModelKind,
        sizes: ModelSizes,
        options: GraphOptions,
        mask: MaskKind,
        train: TrainConfig,
        seed: u64,
        progress: impl FnMut(usize, f64),
    ) -> Result<TrainedPredictor> {
        let reference = &clips
            .first()
            .ok_or_else(|| EvalError::Data("no training clips".into()))?
            .1;
        let set = ClipSet::new(clips, reference, crate::dataset::FPS, 1)?;
        if set.windows.is_empty() {
            return Err(EvalError::Data(format!(
                "no clip has the {} frames of a window at {} fps",
                INPUT_FRAMES + OUTPUT_FRAMES,
                crate::dataset::FPS
            )));
        }
        let norm = Normalizer::fit(&set);
        let graph = BodyGraph::non_root(reference.skeleton())?;
        let mut file = ModelFile {
            model,
            sizes,
            options,
            graph,
            normalizer: norm,
            fps: crate::dataset::FPS,
            input_frames: INPUT_FRAMES,
            output_frames: OUTPUT_FRAMES,
            mask,
            train,
            seed,
            clips: set.clips.iter().map(|c| c.name.clone()).collect(),
            windows: set.windows.len(),
            first_loss: 0.0,
            last_loss: 0.0,
            train_seconds: 0.0,
        };
        let m = build(&to_config(&file), &file.graph, set.dim, seed)?;
        let occluder = Occluder::new(mask, &file.graph)?;
        let report: TrainReport = train::train(
            m.as_ref(),
            &set,
            &file.normalizer,
            &train,
            seed,
            Some(&occluder),
            progress,
        )?;
        file.first_loss = report.first_loss;
        file.last_loss = report.last_loss;
        file.train_seconds = report.seconds;
        Ok(TrainedPredictor { file, model: m })
    }

    pub fn save(&self, dir: &Path) -> Result<()> {
        let io = |source| EvalError::Io {
            path: dir.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        self.model.params().save(&dir.join(WEIGHTS_FILE))?;
        let json =
            serde_json::to_vec_pretty(&self.file).map_err(|e| EvalError::Data(e.to_string()))?;
        let tmp = dir.join(format!("{MODEL_FILE}.tmp"));
        std::fs::write(&tmp, json).map_err(io)?;
        std::fs::rename(&tmp, dir.join(MODEL_FILE)).map_err(io)
    }

    pub fn load(dir: &Path) -> Result<TrainedPredictor> {
        let path = dir.join(MODEL_FILE);
        let bytes = std::fs::read(&path).map_err(|source| EvalError::Io {
            path: path.clone(),
            source,
        })?;
        let file: ModelFile = serde_json::from_slice(&bytes).map_err(|e| {
            EvalError::Data(format!(
                "{}: not a prediction model file: {e}",
                path.display()
            ))
        })?;
        let dim = 3 * file.graph.nodes();
        let model = build(&to_config(&file), &file.graph, dim, file.seed)?;
        model.params().load(&dir.join(WEIGHTS_FILE))?;
        Ok(TrainedPredictor { file, model })
    }

    /// Predicts the window starting at `start` (default: the clip's first
    /// frame) of `clip`, its observed frames occluded by `mask` (seeded).
    pub fn predict_clip(
        &self,
        clip: &Motion,
        start: Option<usize>,
        mask: MaskKind,
        seed: u64,
    ) -> Result<Prediction> {
        let f = &self.file;
        let graph = BodyGraph::non_root(clip.skeleton())?;
        f.graph.check_matches(&graph)?;
        let clip = if (clip.fps() - f.fps).abs() > 1e-9 {
            motion::resample::resample(clip, f.fps)?
        } else {
            clip.clone()
        };
        let len = f.input_frames + f.output_frames;
        if clip.frames() < len {
            return Err(EvalError::Data(format!(
                "the clip has {} frames at {} fps; a prediction window needs {len}",
                clip.frames(),
                f.fps
            )));
        }
        let start = start.unwrap_or(0);
        if start + len > clip.frames() {
            return Err(EvalError::Data(format!(
                "--start {start}: the window of {len} frames ends after the clip's last frame ({})",
                clip.frames() - 1
            )));
        }
        let d = 3 * graph.nodes();
        let feats = features(&clip);
        let mut input = Vec::with_capacity(f.input_frames * d);
        for t in start..start + f.input_frames {
            f.normalizer.norm(&feats[t * d..(t + 1) * d], &mut input);
        }
        let input = Tensor::from_vec(input, (1, f.input_frames, d), &Device::Cpu)?;
        let occluder = Occluder::new(mask, &f.graph)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let seen = occluder.apply(&input, &mut rng)?;
        let mut seen_flat: Vec<f32> = seen.flatten_all()?.to_vec1()?;
        let input_flat: Vec<f32> = input.flatten_all()?.to_vec1()?;
        let visible: Vec<Vec<bool>> = seen_flat
            .chunks(d)
            .zip(input_flat.chunks(d))
            .map(|(s, i)| s.chunks(3).zip(i.chunks(3)).map(|(a, b)| a == b).collect())
            .collect();
        let mut pred: Vec<f32> = self
            .model
            .predict(&seen, f.output_frames)?
            .flatten_all()?
            .to_vec1()?;
        f.normalizer.denorm(&mut seen_flat);
        f.normalizer.denorm(&mut pred);
        let truth_frames: Vec<&[f32]> = (start..start + len)
            .map(|t| &feats[t * d..(t + 1) * d])
            .collect();
        let observed_truth = &truth_frames[..f.input_frames];
        let future_truth = &truth_frames[f.input_frames..];
        let seen_frames: Vec<&[f32]> = seen_flat.chunks(d).collect();
        let pred_frames: Vec<&[f32]> = pred.chunks(d).collect();
        let build_clip = |frames: &[Vec<f32>]| -> Result<Motion> {
            let mut rot = Vec::with_capacity(frames.len() * clip.joints());
            let mut root = Vec::with_capacity(frames.len());
            for (k, feat) in frames.iter().enumerate() {
                let t = start + k;
                rot.push(clip.pose(t)[0]);
                rot.extend(feat.chunks(3).map(|v| {
                    DQuat::from_scaled_axis(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
                }));
                root.push(clip.root_translation()[t]);
            }
            Ok(Motion::new(clip.skeleton().clone(), f.fps, root, rot)?)
        };
        let join = |a: &[&[f32]], b: &[&[f32]]| -> Vec<Vec<f32>> {
            a.iter().chain(b).map(|x| x.to_vec()).collect()
        };
        let truth = join(observed_truth, future_truth);
        let seen_all = join(&seen_frames, future_truth);
        let predicted = join(observed_truth, &pred_frames);
        Ok(Prediction {
            start,
            truth: build_clip(&truth)?,
            seen: build_clip(&seen_all)?,
            predicted: build_clip(&predicted)?,
            visible,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kick() -> Motion {
        crate::example_kick()
    }

    #[test]
    fn a_saved_model_predicts_the_same_and_refuses_another_skeleton() {
        let clip = kick();
        let sizes = ModelSizes {
            graph_channels: [4, 4, 8, 8],
            graph_hidden: 8,
            ..ModelSizes::default()
        };
        let train = TrainConfig {
            iterations: 2,
            batch_size: 4,
            ..TrainConfig::default()
        };
        let t = TrainedPredictor::train(
            &[("kick".into(), clip.clone())],
            ModelKind::Dmgnn,
            sizes,
            GraphOptions::default(),
            MaskKind::Lower,
            train,
            3,
            |_, _| {},
        )
        .unwrap();
        let dir = std::env::temp_dir().join(format!("motionaug-trained-{}", std::process::id()));
        t.save(&dir).unwrap();
        let back = TrainedPredictor::load(&dir).unwrap();
        assert_eq!(back.file, t.file);
        let a = t.predict_clip(&clip, Some(5), MaskKind::Lower, 1).unwrap();
        let b = back
            .predict_clip(&clip, Some(5), MaskKind::Lower, 1)
            .unwrap();
        assert_eq!(a.predicted.rotations(), b.predicted.rotations());
        assert_eq!(a.truth.frames(), INPUT_FRAMES + OUTPUT_FRAMES);
        // Observed frames are the truth's; the lower body was hidden.
        assert_eq!(
            a.predicted.rotations()[..INPUT_FRAMES * clip.joints()],
            a.truth.rotations()[..INPUT_FRAMES * clip.joints()]
        );
        let femur = t
            .file
            .graph
            .names
            .iter()
            .position(|n| n == "lfemur")
            .unwrap();
        assert!(a.visible.iter().all(|f| !f[femur]));
        assert!(
            t.predict_clip(&clip, Some(1000), MaskKind::None, 1)
                .is_err()
        );
        // Another skeleton: a clear error naming the joints.
        let bvh = motion::io::load(
            concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../examples/data/16_11_walk_veer_left.bvh"
            ),
            &motion::io::LoadOptions::default(),
        )
        .unwrap();
        let err = t
            .predict_clip(&bvh, None, MaskKind::None, 1)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("skeleton mismatch") && err.contains("lfemur"),
            "{err}"
        );
        assert!(TrainedPredictor::load(&dir.join("missing")).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
