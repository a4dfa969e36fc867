//! Spatio-temporal graph convolution encoder (ST-GCN: Yan, Xiong and Lin,
//! AAAI 2018), the encoders of the paper (ST-GCN1, ST-GCN2, ST-GCN3) and of
//! the FID feature network.
//!
//! Input `[n, T, V, C]` (channels last: per frame, per graph node, features).
//! Each block: a spatial graph convolution (linear over channels, then mixing
//! over the skeleton's normalised adjacency), ReLU, a temporal convolution of
//! width `kernel` per node (the `kernel` shifted copies concatenated and mixed
//! by one linear layer), a residual connection, ReLU, then every `stride`-th
//! frame. The output is the mean over frames and nodes, `[n, channels.last]`.

use candle_core::{Device, Tensor};
use candle_nn::{Linear, Module, VarBuilder};
use serde::{Deserialize, Serialize};

use crate::error::{ModelError, Result};
use crate::graph::{adjacency_tensor, cat, graph_mix};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StGcnConfig {
    pub in_channels: usize,
    /// Output channels of each block.
    pub channels: Vec<usize>,
    /// Temporal stride of each block.
    pub strides: Vec<usize>,
    /// Temporal kernel width (odd).
    pub kernel: usize,
}

impl StGcnConfig {
    pub fn new(in_channels: usize, channels: &[usize]) -> Self {
        let strides = (0..channels.len())
            .map(|i| if i == 0 { 1 } else { 2 })
            .collect();
        StGcnConfig {
            in_channels,
            channels: channels.to_vec(),
            strides,
            kernel: 3,
        }
    }

    pub fn out_dim(&self) -> usize {
        *self.channels.last().unwrap_or(&self.in_channels)
    }

    pub fn validate(&self) -> Result<()> {
        if self.channels.is_empty() || self.channels.len() != self.strides.len() {
            return Err(ModelError::Config {
                field: "stgcn.channels",
                message: "one stride per block and at least one block".into(),
            });
        }
        if self.kernel.is_multiple_of(2) || self.strides.contains(&0) {
            return Err(ModelError::Config {
                field: "stgcn.kernel",
                message: "odd kernel and positive strides".into(),
            });
        }
        Ok(())
    }
}

struct Block {
    spatial: Linear,
    temporal: Linear,
    residual: Option<Linear>,
    stride: usize,
    kernel: usize,
}

pub struct StGcn {
    adjacency: Tensor,
    blocks: Vec<Block>,
    pub config: StGcnConfig,
}

impl StGcn {
    /// `parents`: the graph (parent node of each node, -1 for the root).
    pub fn new(vb: VarBuilder, config: &StGcnConfig, parents: &[i32]) -> Result<Self> {
        config.validate()?;
        let mut blocks = Vec::new();
        let mut c_in = config.in_channels;
        for (i, (&c, &stride)) in config.channels.iter().zip(&config.strides).enumerate() {
            let vb = vb.pp(format!("block{i}"));
            blocks.push(Block {
                spatial: candle_nn::linear(c_in, c, vb.pp("spatial"))?,
                temporal: candle_nn::linear(c * config.kernel, c, vb.pp("temporal"))?,
                residual: (c_in != c)
                    .then(|| candle_nn::linear(c_in, c, vb.pp("residual")))
                    .transpose()?,
                stride,
                kernel: config.kernel,
            });
            c_in = c;
        }
        Ok(StGcn {
            adjacency: adjacency_tensor(parents)?,
            blocks,
            config: config.clone(),
        })
    }

    /// Per-frame features `[n, T', V, C]` after all blocks (no pooling).
    pub fn features(&self, x: &Tensor) -> Result<Tensor> {
        let mut x = x.clone();
        for b in &self.blocks {
            let t = x.dim(1)?;
            // Spatial: channels, then neighbours.
            let y = b.spatial.forward(&x)?;
            let y = graph_mix(&self.adjacency, &y)?.relu()?;
            // Temporal: `kernel` shifted copies side by side, one linear map.
            let pad = b.kernel / 2;
            let padded = y.pad_with_zeros(1, pad, pad)?;
            let shifted: Vec<Tensor> = (0..b.kernel)
                .map(|k| padded.narrow(1, k, t))
                .collect::<candle_core::Result<_>>()?;
            let y = b.temporal.forward(&cat(&shifted, 3)?)?;
            let res = match &b.residual {
                Some(r) => r.forward(&x)?,
                None => x.clone(),
            };
            let mut y = (y + res)?.relu()?;
            if b.stride > 1 {
                let keep: Vec<u32> = (0..t as u32).step_by(b.stride).collect();
                let idx = Tensor::from_vec(keep.clone(), keep.len(), &Device::Cpu)?;
                y = y.index_select(&idx, 1)?;
            }
            x = y;
        }
        Ok(x)
    }

    /// `x`: `[n, T, V, in_channels]` -> `[n, out_dim]` (mean over frames and nodes).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(self.features(x)?.mean(2)?.mean(1)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_and_strides() {
        let params = nn::Params::new(1);
        let cfg = StGcnConfig::new(3, &[8, 16, 16]);
        let net = StGcn::new(params.var_builder(), &cfg, &[-1, 0, 1, 0]).unwrap();
        let x = Tensor::ones((2, 9, 4, 3), candle_core::DType::F32, &Device::Cpu).unwrap();
        assert_eq!(net.features(&x).unwrap().dims(), &[2, 3, 4, 16]);
        assert_eq!(net.forward(&x).unwrap().dims(), &[2, 16]);
    }
}
