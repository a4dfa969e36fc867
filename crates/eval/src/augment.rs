//! Where an evaluation's synthesised clips come from: a recipe run in memory
//! by the `pipeline` crate (the same job graph `motionaug augment` runs), or
//! the motion VAE directly (trained on the fold's training clips, sampled).

use std::path::{Path, PathBuf};
use std::time::Instant;

use motion::Motion;
use serde::{Deserialize, Serialize};
use vae::{Prior, TrainConfig as VaeTrainConfig, TrainedVae};

use crate::Log;
use crate::error::{EvalError, Result};

/// The VAE as an augmentation: one model on the training clips, `per_clip`
/// samples per training clip from `prior`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct VaeChoice {
    pub prior: Prior,
    pub per_clip: usize,
    pub iterations: u64,
    /// Weight of the adversarial terms; `Some(0.0)`: no discriminators;
    /// `None`: the vae crate's default.
    pub adversarial_weight: Option<f64>,
    pub seed: u64,
}

impl Default for VaeChoice {
    /// MotionAug's: near samples, 10 per training clip; 300 iterations.
    fn default() -> Self {
        VaeChoice {
            prior: Prior::Near,
            per_clip: 10,
            iterations: 300,
            adversarial_weight: None,
            seed: 0,
        }
    }
}

/// An augmentation: from training clips to synthesised clips.
#[derive(Debug, Clone)]
pub enum Augmentation {
    /// A recipe run in memory; `work` keeps the intermediate results
    /// (corrections, models), else a temporary folder removed at the end.
    Recipe {
        recipe: Box<pipeline::Recipe>,
        seed: u64,
        /// What to call it (the recipe file).
        label: String,
        work: Option<PathBuf>,
    },
    Vae(VaeChoice),
}

impl Augmentation {
    pub fn label(&self) -> String {
        match self {
            Augmentation::Recipe { label, .. } => format!("recipe {label}"),
            Augmentation::Vae(v) => format!("vae ({:?} prior)", v.prior),
        }
    }

    /// The synthesised clips of `train`.
    pub fn apply(&self, train: &[(String, Motion)], log: Log) -> Result<Vec<(String, Motion)>> {
        match self {
            Augmentation::Recipe {
                recipe, seed, work, ..
            } => apply_recipe(recipe, *seed, work.as_deref(), train, log),
            Augmentation::Vae(v) => {
                let training = VaeTraining {
                    iterations: v.iterations,
                    adversarial_weight: v.adversarial_weight,
                    ..VaeTraining::default()
                };
                let model = train_vae(train, &training, v.seed, log)?;
                let finish = vae::Finish::default();
                sample_vae(&model, train.len() * v.per_clip, v.prior, v.seed, &finish)
            }
        }
    }
}

/// Runs `recipe` on the training clips in memory with the pipeline crate;
/// returns the kept outputs (an error when there are none).
pub fn apply_recipe(
    recipe: &pipeline::Recipe,
    seed: u64,
    work: Option<&Path>,
    train: &[(String, Motion)],
    log: Log,
) -> Result<Vec<(String, Motion)>> {
    let start = Instant::now();
    let clips = pipeline::Clip::all_from(train);
    let temp = std::env::temp_dir().join(format!("motionaug-eval-{}", std::process::id()));
    let work_dir = work.unwrap_or(&temp);
    let on_event = |event: pipeline::Event<'_>| {
        if let pipeline::Event::JobFinished { job, ok } = event
            && !matches!(job.kind, pipeline::JobKind::Synthesize { .. })
        {
            log(&format!(
                "pipeline: {} {}",
                job.key,
                if ok { "done" } else { "failed" }
            ));
        }
    };
    let result = pipeline::run(
        recipe,
        &clips,
        &pipeline::Options {
            out: None,
            work: work_dir,
            seed,
            on_event: &on_event,
        },
    );
    if work.is_none() {
        let _ = std::fs::remove_dir_all(&temp);
    }
    let summary = result.map_err(EvalError::Pipeline)?;
    for (job, reason) in &summary.failures {
        log(&format!("pipeline: {job} failed: {reason}"));
    }
    if !summary.rejected.is_empty() {
        log(&format!(
            "pipeline: {} outputs rejected by the correction",
            summary.rejected.len()
        ));
    }
    let out: Vec<(String, Motion)> = summary
        .outputs
        .into_iter()
        .map(|o| (o.name, o.motion))
        .collect();
    if out.is_empty() {
        return Err(EvalError::Augmentation(
            format!(
                "the recipe produced no clips ({} jobs failed)",
                summary.failures.len()
            )
            .into(),
        ));
    }
    log(&format!(
        "recipe: {} clips from {} in {:.1} s",
        out.len(),
        train.len(),
        start.elapsed().as_secs_f64()
    ));
    Ok(out)
}

/// What the eval crate changes in the vae crate's training defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VaeTraining {
    pub iterations: u64,
    /// Weight of the adversarial terms; `Some(0.0)`: no discriminators;
    /// `None`: the vae crate's default.
    pub adversarial_weight: Option<f64>,
    /// `vae::LossWeights::mixed_motion` (0: off, the vae crate's default).
    pub mixed_motion_weight: f64,
    /// `vae::LossWeights::mixed_contact` (0: off, the vae crate's default).
    pub mixed_contact_weight: f64,
    /// `vae::LossWeights::mixed_sole` (0: off, the vae crate's default).
    pub mixed_sole_weight: f64,
    /// `vae::LossWeights::mixed_travel` (0: off, the vae crate's default).
    pub mixed_travel_weight: f64,
    /// `vae::LossWeights::mixed_balance` (0: off, the vae crate's default),
    /// with the correction's default character.
    pub mixed_balance_weight: f64,
    /// `vae::FootLoss::skating` (`None`: the vae crate's default).
    pub skating_weight: Option<f64>,
    /// Put the training clips on one floor (`vae::FloorLevel`, the vae
    /// crate's default); off, they stand as captured.
    pub level_floor: bool,
}

impl Default for VaeTraining {
    /// The vae crate's defaults, 1,500 iterations.
    fn default() -> Self {
        VaeTraining {
            iterations: 1500,
            adversarial_weight: None,
            mixed_motion_weight: 0.0,
            mixed_contact_weight: 0.0,
            mixed_sole_weight: 0.0,
            mixed_travel_weight: 0.0,
            mixed_balance_weight: 0.0,
            skating_weight: None,
            level_floor: true,
        }
    }
}

impl VaeTraining {
    /// The folder a model of these settings is kept in, `tag` (`vae`,
    /// `vae_noadv`) first: models of other settings never share one.
    pub fn folder_name(&self, tag: &str) -> String {
        let mut name = format!("{tag}-{}it", self.iterations);
        if self.mixed_motion_weight > 0.0 {
            name.push_str(&format!("-mixed-motion-{}", self.mixed_motion_weight));
        }
        if self.mixed_contact_weight > 0.0 {
            name.push_str(&format!("-mixed-contact-{}", self.mixed_contact_weight));
        }
        if self.mixed_sole_weight > 0.0 {
            name.push_str(&format!("-mixed-sole-{}", self.mixed_sole_weight));
        }
        if self.mixed_travel_weight > 0.0 {
            name.push_str(&format!("-mixed-travel-{}", self.mixed_travel_weight));
        }
        if self.mixed_balance_weight > 0.0 {
            name.push_str(&format!("-mixed-balance-{}", self.mixed_balance_weight));
        }
        if let Some(w) = self.skating_weight {
            name.push_str(&format!("-skating-{w}"));
        }
        if self.level_floor {
            name.push_str("-one-floor");
        }
        name
    }

    fn floor(&self) -> Option<vae::FloorLevel> {
        self.level_floor.then(vae::FloorLevel::default)
    }

    fn config(&self, seed: u64) -> VaeTrainConfig {
        let mut config = VaeTrainConfig {
            iterations: self.iterations.max(1),
            seed,
            ..VaeTrainConfig::default()
        };
        config.weights.mixed_motion = self.mixed_motion_weight;
        config.weights.mixed_contact = self.mixed_contact_weight;
        config.weights.mixed_sole = self.mixed_sole_weight;
        config.weights.mixed_travel = self.mixed_travel_weight;
        config.weights.mixed_balance = self.mixed_balance_weight;
        if let Some(w) = self.skating_weight {
            config.feet.skating = w;
        }
        if let Some(w) = self.adversarial_weight {
            if w == 0.0 {
                config.adversarial = false;
            } else {
                config.weights.adversarial = w;
            }
        }
        config.features.floor = self.floor();
        config
    }
}

/// Trains the motion VAE on the training clips (deterministic for a seed).
pub fn train_vae(
    train: &[(String, Motion)],
    training: &VaeTraining,
    seed: u64,
    log: Log,
) -> Result<TrainedVae> {
    let clips: Vec<Motion> = train.iter().map(|(_, m)| m.clone()).collect();
    let mut config = training.config(seed);
    pipeline::add_vae_balance_model(&mut config, &clips)?;
    log(&format!(
        "vae: training on {} clips, {} iterations, adversarial {} (weight {}), mixed motion weight {}, mixed contact weight {}, mixed sole weight {}, mixed travel weight {}, mixed balance weight {}, skating weight {}, {}",
        clips.len(),
        config.iterations,
        config.adversarial,
        config.weights.adversarial,
        config.weights.mixed_motion,
        config.weights.mixed_contact,
        config.weights.mixed_sole,
        config.weights.mixed_travel,
        config.weights.mixed_balance,
        config.feet.skating,
        if config.features.floor.is_some() {
            "clips on one floor"
        } else {
            "clips on their captured floors"
        }
    ));
    let every = (config.iterations / 5).max(1);
    let model = vae::train(&clips, &config, |p| {
        if p.iteration % every == 0 {
            log(&format!(
                "vae: iteration {}/{} loss {:.4}",
                p.iteration, p.iterations, p.losses.total
            ));
        }
    })?;
    log(&format!(
        "vae: trained in {:.1} s",
        model.meta().training.seconds
    ));
    Ok(model)
}

/// The VAE of one class and fold (seed 0): loaded from `dir` when an earlier
/// run saved it there (training is deterministic, so this is the same model),
/// else trained and saved, so a rerun does not train it again. A saved model
/// whose clips stood on other floors than `training` asks for is an error,
/// not a silent reuse.
pub fn cached_vae(
    dir: &Path,
    train: &[(String, Motion)],
    training: &VaeTraining,
    log: Log,
) -> Result<TrainedVae> {
    if dir.join(vae::trained::META_FILE).is_file() {
        log(&format!("vae: reusing {}", dir.display()));
        let model = TrainedVae::load(dir)?;
        let wanted = training.floor();
        if model.meta().features.floor != wanted {
            return Err(EvalError::Config(format!(
                "the VAE in {} was trained with floor levelling {:?}, this run asks for {:?}: \
                 use another work folder",
                dir.display(),
                model.meta().features.floor,
                wanted
            )));
        }
        return Ok(model);
    }
    let model = train_vae(train, training, 0, log)?;
    model.save(dir)?;
    Ok(model)
}

/// `count` samples of `model` from `prior`, each finished by `finish`, named
/// `vae_<Prior>_<nnnn>`.
pub fn sample_vae(
    model: &TrainedVae,
    count: usize,
    prior: Prior,
    seed: u64,
    finish: &vae::Finish,
) -> Result<Vec<(String, Motion)>> {
    let samples = model.sample_finished(count, prior, seed, finish)?;
    Ok(samples
        .into_iter()
        .enumerate()
        .map(|(i, s)| (format!("vae_{prior:?}_{i:04}"), s.motion))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kick() -> Vec<(String, Motion)> {
        vec![("kick".into(), crate::example_kick())]
    }

    #[test]
    fn each_setting_that_changes_the_model_names_its_folder() {
        let plain = VaeTraining::default();
        assert_eq!(plain.folder_name("vae"), "vae-1500it-one-floor");
        let all = VaeTraining {
            iterations: 300,
            mixed_motion_weight: 1.0,
            mixed_contact_weight: 0.3,
            mixed_sole_weight: 0.5,
            mixed_travel_weight: 2.0,
            mixed_balance_weight: 0.5,
            skating_weight: Some(0.3),
            level_floor: false,
            ..plain
        };
        assert_eq!(
            all.folder_name("vae_noadv"),
            "vae_noadv-300it-mixed-motion-1-mixed-contact-0.3-mixed-sole-0.5-mixed-travel-2-mixed-balance-0.5-skating-0.3"
        );
    }

    #[test]
    fn a_cached_vae_trained_on_other_floors_is_not_reused() {
        let dir = tempfile::tempdir().unwrap();
        let quiet: Log = &|_| {};
        let one_floor = VaeTraining {
            iterations: 1,
            adversarial_weight: Some(0.0),
            ..VaeTraining::default()
        };
        let made = cached_vae(dir.path(), &kick(), &one_floor, quiet).unwrap();
        assert_eq!(made.meta().features.floor, Some(vae::FloorLevel::default()));
        // The same settings reuse it; the captured floors do not.
        assert!(cached_vae(dir.path(), &[], &one_floor, quiet).is_ok());
        let captured = VaeTraining {
            level_floor: false,
            ..one_floor
        };
        match cached_vae(dir.path(), &[], &captured, quiet) {
            Err(e) => assert!(e.to_string().contains("floor"), "{e}"),
            Ok(_) => panic!("a one-floor VAE reused for the captured floors"),
        }
        let fresh = tempfile::tempdir().unwrap();
        let made = cached_vae(fresh.path(), &kick(), &captured, quiet).unwrap();
        assert_eq!(made.meta().features.floor, None);
    }
}
