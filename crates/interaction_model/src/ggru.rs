//! Graph gated recurrent unit (G-GRU, after DMGNN: Li et al., "Dynamic
//! multiscale graph neural networks for 3D skeleton based human motion
//! prediction", CVPR 2020), the decoders G-GRU1 and G-GRU2 of the paper.
//!
//! The hidden state is one vector per graph node, `[n, V, hidden]`. The gates
//! of an ordinary GRU become graph convolutions: inputs and hidden state are
//! mapped linearly and then mixed over the skeleton's normalised adjacency,
//!
//! ```text
//! r = sigmoid(A (x W_xr) + A (h W_hr))       u = sigmoid(A (x W_xu) + A (h W_hu))
//! c = tanh(A (x W_xc) + r * A (h W_hc))      h' = u * h + (1 - u) * c
//! ```
//!
//! [`GGruDecoder::unroll`] runs the cell over the frames of a window: the
//! input of node `i` at frame `t` is the caller's per-frame conditioning for
//! that node, and the output a linear read-out of the hidden state. Unlike
//! DMGNN's predictor the output is not fed back as the next input: the
//! conditioning (the template frame) already carries the motion, and without
//! feedback the input half of every gate is computed for all frames in one
//! product, which makes training several times faster on a CPU.

use candle_core::Tensor;
use candle_nn::{Linear, Module, VarBuilder};
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::graph::{adjacency_tensor, graph_mix};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GGruConfig {
    /// Per-node data channels per frame (the template).
    pub input: usize,
    /// Per-node code channels, constant over frames.
    pub node: usize,
    /// Per-frame code channels, shared by all nodes (0 = none).
    pub frame: usize,
    pub hidden: usize,
    /// Per-node output channels (3: a position offset).
    pub output: usize,
}

pub struct GGruCell {
    adjacency: Tensor,
    x_gates: Linear,
    h_gates: Linear,
    hidden: usize,
}

impl GGruCell {
    pub fn new(vb: VarBuilder, input: usize, hidden: usize, parents: &[i32]) -> Result<Self> {
        Ok(GGruCell {
            adjacency: adjacency_tensor(parents)?,
            x_gates: candle_nn::linear(input, 3 * hidden, vb.pp("x_gates"))?,
            h_gates: candle_nn::linear_no_bias(hidden, 3 * hidden, vb.pp("h_gates"))?,
            hidden,
        })
    }

    /// The input half of the gates, `A (x W_x)`, for inputs of any leading
    /// shape `[..., V, input]` (computed for all frames at once).
    pub fn input_gates(&self, x: &Tensor) -> Result<Tensor> {
        let dims = x.dims().to_vec();
        let v = dims[dims.len() - 2];
        let rows: usize = dims[..dims.len() - 2].iter().product();
        let g = self
            .x_gates
            .forward(x)?
            .reshape((rows, v, 3 * self.hidden))?;
        let mut out = dims;
        let last = out.len() - 1;
        out[last] = 3 * self.hidden;
        Ok(graph_mix(&self.adjacency, &g)?.reshape(out)?)
    }

    /// One step from precomputed input gates `xg` `[n, V, 3 hidden]` and the
    /// state `h` `[n, V, hidden]`.
    pub fn step_gates(&self, xg: &Tensor, h: &Tensor) -> Result<Tensor> {
        let hg = graph_mix(&self.adjacency, &self.h_gates.forward(h)?)?;
        let k = self.hidden;
        let ru = candle_nn::ops::sigmoid(&(xg.narrow(2, 0, 2 * k)? + hg.narrow(2, 0, 2 * k)?)?)?;
        let (r, u) = (ru.narrow(2, 0, k)?, ru.narrow(2, k, k)?);
        let c = (xg.narrow(2, 2 * k, k)? + r.mul(&hg.narrow(2, 2 * k, k)?)?)?.tanh()?;
        // h' = u h + (1 - u) c = c + u (h - c)
        Ok((&c + u.mul(&(h - &c)?)?)?)
    }

    /// One step: `x` `[n, V, input]`, `h` `[n, V, hidden]` -> `[n, V, hidden]`.
    pub fn step(&self, x: &Tensor, h: &Tensor) -> Result<Tensor> {
        self.step_gates(&self.input_gates(x)?, h)
    }
}

pub struct GGruDecoder {
    adjacency: Tensor,
    data_gates: Linear,
    node_gates: Linear,
    frame_gates: Option<Linear>,
    h_gates: Linear,
    readout: Linear,
    pub config: GGruConfig,
}

impl GGruDecoder {
    pub fn new(vb: VarBuilder, config: &GGruConfig, parents: &[i32]) -> Result<Self> {
        let h3 = 3 * config.hidden;
        Ok(GGruDecoder {
            adjacency: adjacency_tensor(parents)?,
            data_gates: candle_nn::linear(config.input, h3, vb.pp("data_gates"))?,
            node_gates: candle_nn::linear_no_bias(config.node, h3, vb.pp("node_gates"))?,
            frame_gates: (config.frame > 0)
                .then(|| candle_nn::linear_no_bias(config.frame, h3, vb.pp("frame_gates")))
                .transpose()?,
            h_gates: candle_nn::linear_no_bias(config.hidden, h3, vb.pp("h_gates"))?,
            readout: candle_nn::linear(config.hidden, config.output, vb.pp("readout"))?,
            config: config.clone(),
        })
    }

    /// Outputs `[n, T, V, output]` from the initial state `h0` `[n, V, hidden]`,
    /// per-frame node data `data` `[n, T, V, input]` (constants: the template),
    /// per-node codes `node` `[n, V, node]` (the same every frame) and optional
    /// per-frame codes `frame` `[n, T, frame]` (the same for every node).
    ///
    /// The input is split this way because candle's gradient of a slice is as
    /// large as the sliced tensor: slicing a parameter-dependent `[n, T, V,
    /// 3 hidden]` tensor frame by frame would cost O(T^2) in the backward pass.
    /// Here only the data (no gradient) and the small per-frame codes are sliced.
    pub fn unroll(
        &self,
        h0: &Tensor,
        data: &Tensor,
        node: &Tensor,
        frame: Option<&Tensor>,
    ) -> Result<Tensor> {
        let (n, t, v, _) = data.dims4()?;
        let k = self.config.hidden;
        let node_term = self.node_gates.forward(node)?;
        let frame_term = match (&self.frame_gates, frame) {
            (Some(l), Some(f)) => Some(l.forward(f)?),
            _ => None,
        };
        let mut h = h0.clone();
        let mut states = Vec::with_capacity(t);
        for f in 0..t {
            let mut pre = (self
                .data_gates
                .forward(&data.narrow(1, f, 1)?.squeeze(1)?)?
                + &node_term)?;
            if let Some(ft) = &frame_term {
                pre = pre.broadcast_add(&ft.narrow(1, f, 1)?)?;
            }
            let xg = graph_mix(&self.adjacency, &pre)?;
            let hg = graph_mix(&self.adjacency, &self.h_gates.forward(&h)?)?;
            let ru =
                candle_nn::ops::sigmoid(&(xg.narrow(2, 0, 2 * k)? + hg.narrow(2, 0, 2 * k)?)?)?;
            let (r, u) = (ru.narrow(2, 0, k)?, ru.narrow(2, k, k)?);
            let c = (xg.narrow(2, 2 * k, k)? + r.mul(&hg.narrow(2, 2 * k, k)?)?)?.tanh()?;
            // h' = u h + (1 - u) c = c + u (h - c)
            h = (&c + u.mul(&(&h - &c)?)?)?;
            states.push(h.clone());
        }
        debug_assert_eq!(h.dims(), &[n, v, k]);
        Ok(self.readout.forward(&Tensor::stack(&states, 1)?)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    #[test]
    fn unroll_shapes_and_bounded_state() {
        let params = nn::Params::new(2);
        let vb = params.var_builder();
        let cfg = GGruConfig {
            input: 2,
            node: 4,
            frame: 3,
            hidden: 6,
            output: 3,
        };
        let dec = GGruDecoder::new(vb.pp("d"), &cfg, &[-1, 0, 0]).unwrap();
        let cell = GGruCell::new(vb.pp("c"), 5, 6, &[-1, 0, 0]).unwrap();
        let h0 = Tensor::zeros((4, 3, 6), DType::F32, &Device::Cpu).unwrap();
        let data = (Tensor::ones((4, 7, 3, 2), DType::F32, &Device::Cpu).unwrap() * 100.0).unwrap();
        let node = Tensor::ones((4, 3, 4), DType::F32, &Device::Cpu).unwrap();
        let frame = Tensor::ones((4, 7, 3), DType::F32, &Device::Cpu).unwrap();
        let y = dec.unroll(&h0, &data, &node, Some(&frame)).unwrap();
        assert_eq!(y.dims(), &[4, 7, 3, 3]);
        // A GRU state is a convex mix of tanh values: bounded whatever the input.
        let x = (Tensor::ones((4, 3, 5), DType::F32, &Device::Cpu).unwrap() * 1e3).unwrap();
        let h = cell.step(&x, &h0).unwrap();
        let m = h
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!(m <= 1.0);
    }
}
