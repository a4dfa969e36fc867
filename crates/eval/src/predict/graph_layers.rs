//! The graph layers DMGNN and V-DMGNN-GAN are built from, on channels-last
//! tensors `(B, T, V, C)` (batch, frames, nodes, channels) so that every
//! feature transform is one matrix product:
//!
//! * [`SpatialConv`]: a graph convolution over nodes with the two adjacency
//!   partitions of [`BodyGraph::adjacency`], each with a learnable
//!   multiplicative and additive edge weighting (DMGNN's `emul`/`eadd`).
//! * [`TemporalConv`]: a convolution over frames (kernel 5, zero padding,
//!   optional stride) as one product over the stacked shifted frames.
//! * [`StGcn`]: DMGNN's single-scale graph convolution block (SS-GCB): spatial
//!   convolution, ReLU, temporal convolution, layer norm, residual, ReLU. One
//!   layer norm over channels stands in for the original's two batch norms (no
//!   running statistics to keep; the same function in training and test; a
//!   second norm doubled the block's cost on a CPU, measured with
//!   `motionaug bench predictor`).
//! * [`mix_nodes`]: `(S, V)` node mixing (pooling to parts and bodies, spreading
//!   back, attention).
//! * [`GraphGru`]: DMGNN's graph GRU cell (G-GRU), used by the decoder and the
//!   discriminator.

use candle_core::{D, Device, Tensor};
use nn::{LayerNorm, Linear, Params};

use crate::error::Result;
use crate::predict::body_graph::{BodyGraph, Scale};

/// `out[.., s, c] = sum_v m[s, v] x[.., v, c]` for `x` `(.., V, C)`, `m` `(S, V)`:
/// one batched product with `m` broadcast over the leading dimensions (no
/// transposed copies of `x`).
pub fn mix_nodes(m: &Tensor, x: &Tensor) -> Result<Tensor> {
    let dims = x.dims().to_vec();
    let r = dims.len();
    let (v, c) = (dims[r - 2], dims[r - 1]);
    let lead: usize = dims[..r - 2].iter().product();
    let s = m.dim(0)?;
    let mixed = m.broadcast_left(lead)?.matmul(&x.reshape((lead, v, c))?)?;
    let mut out = dims[..r - 2].to_vec();
    out.extend([s, c]);
    Ok(mixed.reshape(out)?)
}

/// A constant `(rows, cols)` matrix.
pub fn constant(data: Vec<f32>, rows: usize, cols: usize) -> Result<Tensor> {
    Ok(Tensor::from_vec(data, (rows, cols), &Device::Cpu)?)
}

pub struct SpatialConv {
    /// `C_in -> 2 C_out` (one block of outputs per partition).
    lin: Linear,
    /// The partitions' fixed adjacency, `(S, S)` each.
    adjacency: [Tensor; 2],
    edge_mul: [Tensor; 2],
    edge_add: [Tensor; 2],
    c_out: usize,
}

impl SpatialConv {
    pub fn new(
        p: &Params,
        name: &str,
        graph: &BodyGraph,
        scale: Scale,
        c_in: usize,
        c_out: usize,
    ) -> Result<Self> {
        let s = graph.size(scale);
        let a = graph.adjacency(scale);
        let part = |k: usize| constant(a[k * s * s..(k + 1) * s * s].to_vec(), s, s);
        Ok(SpatialConv {
            lin: Linear::new(p, &format!("{name}.lin"), c_in, 2 * c_out)?,
            adjacency: [part(0)?, part(1)?],
            edge_mul: [
                p.constant(&format!("{name}.emul0"), &[s, s], 1.0)?,
                p.constant(&format!("{name}.emul1"), &[s, s], 1.0)?,
            ],
            edge_add: [
                p.constant(&format!("{name}.eadd0"), &[s, s], 0.0)?,
                p.constant(&format!("{name}.eadd1"), &[s, s], 0.0)?,
            ],
            c_out,
        })
    }

    /// `x` `(.., S, C_in)` -> `(.., S, C_out)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let y = self.lin.forward(x)?;
        let last = y.rank() - 1;
        let mut out: Option<Tensor> = None;
        for k in 0..2 {
            let a = ((&self.adjacency[k] * &self.edge_mul[k])? + &self.edge_add[k])?;
            let yk = y.narrow(last, k * self.c_out, self.c_out)?;
            let mixed = mix_nodes(&a, &yk)?;
            out = Some(match out {
                None => mixed,
                Some(o) => (o + mixed)?,
            });
        }
        Ok(out.expect("two partitions"))
    }
}

pub struct TemporalConv {
    lin: Linear,
    kernel: usize,
    stride: usize,
}

impl TemporalConv {
    pub fn new(
        p: &Params,
        name: &str,
        c_in: usize,
        c_out: usize,
        kernel: usize,
        stride: usize,
    ) -> Result<Self> {
        Ok(TemporalConv {
            lin: Linear::new(p, &format!("{name}.lin"), kernel * c_in, c_out)?,
            kernel,
            stride: stride.max(1),
        })
    }

    /// Frames after a convolution with this stride: `ceil(T / stride)`.
    pub fn frames_out(&self, t: usize) -> usize {
        t.div_ceil(self.stride)
    }

    /// `x` `(B, T, V, C_in)` -> `(B, ceil(T / stride), V, C_out)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, v, c) = x.dims4()?;
        let pad = self.kernel / 2;
        let zeros = Tensor::zeros((b, pad, v, c), x.dtype(), x.device())?;
        let padded = Tensor::cat(&[&zeros, x, &zeros], 1)?;
        let t_out = self.frames_out(t);
        // Each shift takes only the frames the stride keeps.
        let shifted: Vec<Tensor> = (0..self.kernel)
            .map(|k| {
                if self.stride == 1 {
                    padded.narrow(1, k, t)?.contiguous()
                } else {
                    let idx: Vec<u32> = (0..t_out).map(|i| (k + i * self.stride) as u32).collect();
                    padded.index_select(&Tensor::from_vec(idx, t_out, x.device())?, 1)
                }
            })
            .collect::<candle_core::Result<_>>()?;
        let stacked = Tensor::cat(&shifted, 3)?;
        Ok(self.lin.forward(&stacked)?)
    }
}

/// DMGNN's SS-GCB.
pub struct StGcn {
    gcn: SpatialConv,
    tcn: TemporalConv,
    norm: LayerNorm,
    residual: Residual,
}

enum Residual {
    None,
    Identity,
    Project { lin: Linear, stride: usize },
}

impl StGcn {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        p: &Params,
        name: &str,
        graph: &BodyGraph,
        scale: Scale,
        c_in: usize,
        c_out: usize,
        stride: usize,
        residual: bool,
    ) -> Result<Self> {
        let residual = if !residual {
            Residual::None
        } else if c_in == c_out && stride == 1 {
            Residual::Identity
        } else {
            Residual::Project {
                lin: Linear::new(p, &format!("{name}.res"), c_in, c_out)?,
                stride,
            }
        };
        Ok(StGcn {
            gcn: SpatialConv::new(p, &format!("{name}.gcn"), graph, scale, c_in, c_out)?,
            tcn: TemporalConv::new(p, &format!("{name}.tcn"), c_out, c_out, 5, stride)?,
            norm: LayerNorm::new(p, &format!("{name}.norm"), c_out)?,
            residual,
        })
    }

    /// `(B, T, S, C_in)` -> `(B, ceil(T / stride), S, C_out)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let h = self.gcn.forward(x)?.relu()?;
        let h = self.norm.forward(&self.tcn.forward(&h)?)?;
        let h = match &self.residual {
            Residual::None => h,
            Residual::Identity => (h + x)?,
            Residual::Project { lin, stride } => {
                let t = x.dim(1)?;
                let xs = if *stride == 1 {
                    x.clone()
                } else {
                    let idx: Vec<u32> = (0..t.div_ceil(*stride))
                        .map(|i| (i * stride) as u32)
                        .collect();
                    let n = idx.len();
                    x.index_select(&Tensor::from_vec(idx, n, x.device())?, 1)?
                };
                (h + lin.forward(&xs)?)?
            }
        };
        Ok(h.relu()?)
    }
}

/// DMGNN's graph GRU cell: the hidden state `(B, V, H)` exchanges messages
/// over the joint graph before the gates.
pub struct GraphGru {
    msg: SpatialConv,
    input_r: Linear,
    input_u: Linear,
    input_n: Linear,
    hidden_r: Linear,
    hidden_u: Linear,
    hidden_n: Linear,
}

impl GraphGru {
    pub fn new(
        p: &Params,
        name: &str,
        graph: &BodyGraph,
        input: usize,
        hidden: usize,
    ) -> Result<Self> {
        let l = |n: &str, i: usize, o: usize| Linear::new(p, &format!("{name}.{n}"), i, o);
        Ok(GraphGru {
            msg: SpatialConv::new(
                p,
                &format!("{name}.msg"),
                graph,
                Scale::Joints,
                hidden,
                hidden,
            )?,
            input_r: l("input_r", input, hidden)?,
            input_u: l("input_u", input, hidden)?,
            input_n: l("input_n", input, hidden)?,
            hidden_r: l("hidden_r", hidden, hidden)?,
            hidden_u: l("hidden_u", hidden, hidden)?,
            hidden_n: l("hidden_n", hidden, hidden)?,
        })
    }

    /// One step: `x` `(B, V, I)`, `h` `(B, V, H)` -> the next `h`.
    pub fn step(&self, x: &Tensor, h: &Tensor) -> Result<Tensor> {
        let msg = self.msg.forward(h)?;
        let r =
            candle_nn::ops::sigmoid(&(self.input_r.forward(x)? + self.hidden_r.forward(&msg)?)?)?;
        let u =
            candle_nn::ops::sigmoid(&(self.input_u.forward(x)? + self.hidden_u.forward(&msg)?)?)?;
        let n = (self.input_n.forward(x)? + (r * self.hidden_n.forward(&msg)?)?)?.tanh()?;
        // h' = (1 - u) n + u h
        Ok(((&n - (&u * &n)?)? + (&u * h)?)?)
    }
}

/// Position, velocity and acceleration of the last frame of `(p0, p1, p2)`
/// (oldest first), concatenated over the last dimension.
pub fn pos_vel_acc(p_prev2: &Tensor, p_prev: &Tensor, p: &Tensor) -> Result<Tensor> {
    let v = (p - p_prev)?;
    let v_prev = (p_prev - p_prev2)?;
    let a = (&v - v_prev)?;
    Ok(Tensor::cat(&[p, &v, &a], D::Minus1)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::DType;

    fn graph() -> BodyGraph {
        crate::predict::test_support::hdm05_graph()
    }

    #[test]
    fn mixing_pools_and_spreads() {
        let m = constant(vec![0.5, 0.5, 0.0, 0.0, 0.0, 1.0], 2, 3).unwrap();
        let x = Tensor::arange(0f32, 12.0, &Device::Cpu)
            .unwrap()
            .reshape((2, 3, 2))
            .unwrap();
        let y = mix_nodes(&m, &x).unwrap();
        assert_eq!(y.dims(), &[2, 2, 2]);
        let v: Vec<Vec<Vec<f32>>> = y.to_vec3().unwrap();
        assert_eq!(v[0][0], vec![1.0, 2.0]);
        assert_eq!(v[0][1], vec![4.0, 5.0]);
        assert_eq!(v[1][0], vec![7.0, 8.0]);
    }

    #[test]
    fn block_shapes_and_strides() {
        let g = graph();
        let p = Params::new(1);
        let v = g.nodes();
        let x = Tensor::randn(0f32, 1.0, (2, 10, v, 3), &Device::Cpu).unwrap();
        let b1 = StGcn::new(&p, "b1", &g, Scale::Joints, 3, 8, 1, false).unwrap();
        let b2 = StGcn::new(&p, "b2", &g, Scale::Joints, 8, 16, 2, true).unwrap();
        let y = b2.forward(&b1.forward(&x).unwrap()).unwrap();
        assert_eq!(y.dims(), &[2, 5, v, 16]);
        let t = TemporalConv::new(&p, "t", 3, 4, 5, 2).unwrap();
        assert_eq!(t.forward(&x).unwrap().dims(), &[2, 5, v, 4]);
        let parts = Tensor::zeros((2, 10, g.parts, 3), DType::F32, &Device::Cpu).unwrap();
        let bp = StGcn::new(&p, "bp", &g, Scale::Parts, 3, 8, 2, true).unwrap();
        assert_eq!(bp.forward(&parts).unwrap().dims(), &[2, 5, g.parts, 8]);
        let gru = GraphGru::new(&p, "gru", &g, 9, 12).unwrap();
        let h = Tensor::zeros((2, v, 12), DType::F32, &Device::Cpu).unwrap();
        let xin = Tensor::randn(0f32, 1.0, (2, v, 9), &Device::Cpu).unwrap();
        assert_eq!(gru.step(&xin, &h).unwrap().dims(), &[2, v, 12]);
    }
}
