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
//! The models are built from the `nn` crate's seeded parameter store and layers.
//! * [`protocol`]: one leave-one-actor-out run: train, predict, score.

pub mod data;
pub mod dct;
pub mod gcn;
pub mod protocol;
pub mod seq2seq;
pub mod train;

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
}

/// Mean squared error of two tensors of one shape.
pub(crate) fn mse(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    Ok((a - b)?.sqr()?.mean_all()?)
}
