//! How the prediction models of an evaluation are trained: the options `eval
//! predict` and the table share, and the [`ProtocolConfig`] they make.

use serde::{Deserialize, Serialize};

use crate::dataset::{self, Split};
use crate::error::{EvalError, Result};
use crate::predict::data::ClipSet;
use crate::predict::dmgnn::Reconstruction;
use crate::predict::occlusion::MaskKind;
use crate::predict::protocol::{GraphOptions, ModelKind, ModelSizes, ProtocolConfig};

/// Training options of the prediction models; [`Default`] is the CLI's defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrainOptions {
    /// Optimiser steps per model (both conditions get the same number).
    pub iterations: usize,
    /// Passes over the training windows *without* augmentation (sets
    /// `iterations` from the fold's window count).
    pub epochs: Option<f64>,
    pub batch_size: usize,
    pub lr: f64,
    /// Models trained per condition; errors are averaged.
    pub seeds: Vec<u64>,
    /// Cap on training and on test windows (evenly spaced); `None`: all.
    pub max_windows: Option<usize>,
    pub seq2seq_hidden: usize,
    pub gcn_hidden: usize,
    pub gcn_stages: usize,
    /// Occlusion of the observed frames (V-DMGNN-GAN's masks), training and test.
    pub mask: MaskKind,
    /// Occlusion in training when it differs from `mask` (the mask augmentation).
    pub train_mask: Option<MaskKind>,
    /// DMGNN / V-DMGNN-GAN reconstruction loss.
    pub graph_loss: Reconstruction,
    /// V-DMGNN-GAN: encode velocities and accelerations too.
    pub vel_acc: bool,
}

impl Default for TrainOptions {
    fn default() -> Self {
        let sizes = ModelSizes::default();
        TrainOptions {
            iterations: 1000,
            epochs: None,
            batch_size: 32,
            lr: 1e-3,
            seeds: vec![0],
            max_windows: None,
            seq2seq_hidden: sizes.seq2seq_hidden,
            gcn_hidden: sizes.gcn_hidden,
            gcn_stages: sizes.gcn_stages,
            mask: MaskKind::None,
            train_mask: None,
            graph_loss: Reconstruction::L1,
            vel_acc: false,
        }
    }
}

impl TrainOptions {
    /// The protocol's settings for `model` on the fold `split`.
    pub fn config(&self, model: ModelKind, split: &Split) -> Result<ProtocolConfig> {
        let mut c = ProtocolConfig::new(model);
        c.sizes.seq2seq_hidden = self.seq2seq_hidden;
        c.sizes.gcn_hidden = self.gcn_hidden;
        c.sizes.gcn_stages = self.gcn_stages;
        c.mask = self.mask;
        c.train_mask = self.train_mask;
        c.graph = GraphOptions {
            loss: self.graph_loss,
            vel_acc: self.vel_acc,
        };
        c.train.batch_size = self.batch_size;
        c.train.lr = self.lr;
        c.seeds = self.seeds.clone();
        c.max_train_windows = self.max_windows;
        c.max_test_windows = self.max_windows;
        c.train.iterations = self.iterations;
        if let Some(e) = self.epochs {
            if !(e.is_finite() && e > 0.0) {
                return Err(EvalError::Config("epochs must be positive".into()));
            }
            let first = split
                .train
                .first()
                .ok_or_else(|| EvalError::Data("no training clips".into()))?;
            let mut set = ClipSet::new(&split.train, &first.1, dataset::FPS, c.stride)?;
            if let Some(m) = self.max_windows {
                set.limit_windows(m);
            }
            c.train.iterations = ((set.windows.len() as f64 * e / self.batch_size.max(1) as f64)
                .ceil() as usize)
                .max(1);
        }
        Ok(c)
    }
}
