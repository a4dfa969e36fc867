//! The downstream protocol of MotionAug Sec. 4.3: train a motion prediction
//! model on the training actors' clips (with and without augmented clips) and
//! measure its Euler-angle error on a held-out actor at 100, 200 and 400 ms.
//!
//! * [`data`]: windows of 10 input + 12 output frames at 30 fps, model features
//!   (rotation vectors of the non-root joints), normalisation, batches.
//! * [`seq2seq`]: the RNN baseline (one GRU, residual velocity decoding).
//! * [`dct`], [`gcn`]: the DCT + graph-convolution model.
//! * [`train`]: the training loop (the `nn` optimiser: AdamW after global
//!   gradient-norm clipping; seeded batches).
//!
//! * [`body_graph`], [`graph_layers`], [`dmgnn`], [`vdmgnn`]: DMGNN and
//!   V-DMGNN-GAN (multi-scale graph encoders over the skeleton, graph-GRU
//!   decoders; the second variational with a recurrent discriminator).
//! * [`occlusion`]: the lower-body and random masks on observed features.
//! * [`cmu`]: V-DMGNN-GAN's Table 1 protocol on DMGNN's CMU data.
//! * [`trained`]: a model as a folder (`predict train` / `predict run`).
//! * [`bench`]: training cost per iteration.
//!
//! The models are built from the `nn` crate's seeded parameter store and layers.
//! * [`protocol`]: one leave-one-actor-out run: train, predict, score.

pub mod bench;
pub mod body_graph;
pub mod cmu;
pub mod data;
pub mod dct;
pub mod dmgnn;
pub mod gcn;
pub mod graph_layers;
pub mod occlusion;
pub mod protocol;
pub mod seq2seq;
pub mod train;
pub mod trained;
pub mod vdmgnn;

use candle_core::Tensor;
use nn::Params;

use crate::error::Result;

/// A motion prediction model on normalised features.
pub trait Predictor {
    /// Training loss for a batch: `input` `(B, T_in, D)`, `target` `(B, T_out, D)`.
    fn loss(&self, input: &Tensor, target: &Tensor) -> Result<Tensor>;
    /// Predicted next `frames` frames `(B, frames, D)` after `input` `(B, T_in, D)`.
    fn predict(&self, input: &Tensor, frames: usize) -> Result<Tensor>;
    /// The trainable parameters.
    fn params(&self) -> &Params;
    /// A model trained against a discriminator ([`train::train`] alternates
    /// its generator and discriminator steps).
    fn adversarial(&self) -> Option<&dyn Adversarial> {
        None
    }
}

/// The adversarial half of a GAN-trained predictor. `clean` is the unmasked
/// observed input (what the discriminator sees), `masked` what the generator sees.
pub trait Adversarial {
    fn generator_loss(&self, clean: &Tensor, masked: &Tensor, target: &Tensor) -> Result<Tensor>;
    fn discriminator_loss(
        &self,
        clean: &Tensor,
        masked: &Tensor,
        target: &Tensor,
    ) -> Result<Tensor>;
    fn discriminator_params(&self) -> &Params;
    fn discriminator_lr(&self) -> f64;
    /// Every discriminator parameter is clamped to `[-clip, clip]` after its step.
    fn clip(&self) -> f32;
}

/// L1 (mean absolute) or L2 (mean squared) error of two tensors of one shape.
pub(crate) fn l1_or_l2(kind: dmgnn::Reconstruction, a: &Tensor, b: &Tensor) -> Result<Tensor> {
    match kind {
        dmgnn::Reconstruction::L1 => Ok((a - b)?.abs()?.mean_all()?),
        dmgnn::Reconstruction::L2 => mse(a, b),
    }
}

/// Mean squared error of two tensors of one shape.
pub(crate) fn mse(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    Ok((a - b)?.sqr()?.mean_all()?)
}

/// The bundled HDM05 skeleton and its feature graph, for the models' tests.
#[cfg(test)]
pub(crate) mod test_support {
    use super::body_graph::BodyGraph;

    pub fn hdm05_skeleton() -> motion::Skeleton {
        motion::asf::parse(
            include_bytes!("../../../../examples/data/HDM_bd.asf"),
            "HDM_bd.asf",
        )
        .expect("the bundled skeleton parses")
        .skeleton()
        .as_ref()
        .clone()
    }

    pub fn hdm05_graph() -> BodyGraph {
        BodyGraph::non_root(&hdm05_skeleton()).expect("the bundled skeleton has limbs")
    }
}
