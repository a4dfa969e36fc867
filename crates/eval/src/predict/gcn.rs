//! The DCT + graph-convolution model of Mao et al. 2019 ("Learning trajectory
//! dependencies", the GCN of MotionAug Table 3), sized for a CPU.
//!
//! The observed frames are padded with copies of the last one to the whole
//! window, each feature's trajectory becomes its first `coefficients` DCT
//! coefficients, and graph convolutions over the features (nodes; a learnable
//! fully connected adjacency instead of the skeleton's, so the model finds which
//! angles move together) map those coefficients to the residual of the whole
//! window's coefficients. The inverse DCT gives the observed and predicted
//! frames; the loss covers both, as in the original.

use candle_core::Tensor;
use nn::Params;

use crate::error::{EvalError, Result};
use crate::predict::{Predictor, dct, mse};

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GcnConfig {
    /// Pose features per frame (graph nodes).
    pub dim: usize,
    /// Observed + predicted frames (the padded sequence).
    pub frames: usize,
    /// DCT coefficients kept (paper: 20).
    pub coefficients: usize,
    /// Hidden features per node (paper: 256).
    pub hidden: usize,
    /// Residual blocks of two graph convolutions (paper: 12 stages).
    pub stages: usize,
}

impl GcnConfig {
    pub fn new(dim: usize, frames: usize) -> Self {
        GcnConfig {
            dim,
            frames,
            coefficients: 20.min(frames),
            hidden: 64,
            stages: 2,
        }
    }
}

/// `adjacency . x . weight + bias` over nodes, `x` `(B, N, F_in)`.
struct GraphConv {
    adjacency: Tensor,
    weight: Tensor,
    bias: Tensor,
}

impl GraphConv {
    fn new(p: &Params, name: &str, nodes: usize, f_in: usize, f_out: usize) -> Result<Self> {
        // Mao et al.: uniform in +-1/sqrt(out features) for every tensor.
        let b = 1.0 / (f_out as f32).sqrt();
        Ok(GraphConv {
            adjacency: p.uniform(&format!("{name}.adjacency"), &[nodes, nodes], b)?,
            weight: p.uniform(&format!("{name}.weight"), &[f_in, f_out], b)?,
            bias: p.uniform(&format!("{name}.bias"), &[f_out], b)?,
        })
    }

    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (b, n, f) = x.dims3()?;
        let xw = x.reshape((b * n, f))?.matmul(&self.weight)?;
        let f_out = xw.dim(1)?;
        // One (N, N) x (N, B F) product instead of B small ones.
        let by_node = xw
            .reshape((b, n, f_out))?
            .transpose(0, 1)?
            .contiguous()?
            .reshape((n, b * f_out))?;
        let mixed = self
            .adjacency
            .matmul(&by_node)?
            .reshape((n, b, f_out))?
            .transpose(0, 1)?
            .contiguous()?;
        Ok(mixed.broadcast_add(&self.bias)?)
    }
}

pub struct Gcn {
    config: GcnConfig,
    /// `(K, L)` DCT basis and its transpose.
    dct: Tensor,
    dct_t: Tensor,
    input: GraphConv,
    blocks: Vec<(GraphConv, GraphConv)>,
    output: GraphConv,
    params: Params,
}

impl Gcn {
    pub fn new(config: &GcnConfig, seed: u64) -> Result<Self> {
        let c = *config;
        if c.dim == 0 || c.hidden == 0 || c.coefficients == 0 || c.coefficients > c.frames {
            return Err(EvalError::Config(format!(
                "gcn: need positive sizes and coefficients <= frames, got {c:?}"
            )));
        }
        let p = Params::new(seed);
        let input = GraphConv::new(&p, "gc_in", c.dim, c.coefficients, c.hidden)?;
        let mut blocks = Vec::with_capacity(c.stages);
        for s in 0..c.stages {
            blocks.push((
                GraphConv::new(&p, &format!("block{s}.gc1"), c.dim, c.hidden, c.hidden)?,
                GraphConv::new(&p, &format!("block{s}.gc2"), c.dim, c.hidden, c.hidden)?,
            ));
        }
        let output = GraphConv::new(&p, "gc_out", c.dim, c.hidden, c.coefficients)?;
        let dct = dct::basis_tensor(c.coefficients, c.frames)?;
        Ok(Gcn {
            config: c,
            dct_t: dct.t()?.contiguous()?,
            dct,
            input,
            blocks,
            output,
            params: p,
        })
    }

    /// The whole window `(B, L, D)` (observed frames reproduced, then predicted).
    fn run(&self, input: &Tensor) -> Result<Tensor> {
        let (b, t_in, d) = input.dims3()?;
        let l = self.config.frames;
        if t_in >= l {
            return Err(EvalError::Config(format!(
                "gcn: {t_in} observed frames leave nothing to predict in a window of {l}"
            )));
        }
        let last = input.narrow(1, t_in - 1, 1)?;
        let padded = Tensor::cat(
            &[
                input.clone(),
                last.broadcast_as((b, l - t_in, d))?.contiguous()?,
            ],
            1,
        )?;
        // (B, L, D) -> (B, D, L) -> DCT coefficients (B, D, K).
        let traj = padded.transpose(1, 2)?.contiguous()?.reshape((b * d, l))?;
        let coeffs = traj.matmul(&self.dct_t)?.reshape((b, d, ()))?;
        let mut y = self.input.forward(&coeffs)?.tanh()?;
        for (g1, g2) in &self.blocks {
            let h = g1.forward(&y)?.tanh()?;
            let h = g2.forward(&h)?.tanh()?;
            y = (h + y)?;
        }
        let out = (self.output.forward(&y)? + coeffs)?;
        // Inverse DCT (B, D, K) -> (B, D, L) -> (B, L, D).
        let k = self.config.coefficients;
        Ok(out
            .reshape((b * d, k))?
            .matmul(&self.dct)?
            .reshape((b, d, l))?
            .transpose(1, 2)?
            .contiguous()?)
    }
}

impl Predictor for Gcn {
    fn loss(&self, input: &Tensor, target: &Tensor) -> Result<Tensor> {
        let whole = Tensor::cat(&[input, target], 1)?;
        mse(&self.run(input)?, &whole)
    }

    fn predict(&self, input: &Tensor, frames: usize) -> Result<Tensor> {
        let t_in = input.dim(1)?;
        if t_in + frames > self.config.frames {
            return Err(EvalError::Config(format!(
                "gcn: built for {} frames, asked for {t_in} + {frames}",
                self.config.frames
            )));
        }
        Ok(self.run(input)?.narrow(1, t_in, frames)?)
    }

    fn params(&self) -> &Params {
        &self.params
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn shapes() {
        let c = GcnConfig {
            dim: 6,
            frames: 22,
            coefficients: 20,
            hidden: 8,
            stages: 1,
        };
        let m = Gcn::new(&c, 3).unwrap();
        let x = Tensor::randn(0f32, 1.0, (4, 10, 6), &Device::Cpu).unwrap();
        assert_eq!(m.predict(&x, 12).unwrap().dims(), &[4, 12, 6]);
        assert!(m.predict(&x, 13).is_err());
        let y = Tensor::randn(0f32, 1.0, (4, 12, 6), &Device::Cpu).unwrap();
        let loss: f32 = m.loss(&x, &y).unwrap().to_scalar().unwrap();
        assert!(loss.is_finite() && loss > 0.0);
        // in + 2 per block + out, three tensors each.
        assert_eq!(m.params().vars().len(), 3 * 4);
    }
}
