//! LSTM layers on candle tensors, shaped for CPU speed.
//!
//! The input projection `x_t W_ih^T + b` of every frame does not depend on the
//! recurrent state, so it is one `(B*T, I) x (I, 4H)` matmul for the whole
//! sequence; the recurrence (`h_{t-1} W_hh^T` and the gate arithmetic, step by
//! step) is one op with its backward pass written out ([`crate::lstm_op`]):
//! on candle's graph ops every step added a dozen nodes whose backward passes
//! zero-padded and summed gradients. [`Lstm::forward_graph`] (the recurrence
//! on graph ops) and [`Lstm::forward_naive`] (the textbook per-step version)
//! are kept as the references the tests and the bench compare against.
//! Measured side by side in the crate README.
//!
//! Gates are laid out `[i, f, g, o]` (PyTorch's order). Sequences are padded at the
//! end; a backward (reversed) pass must start at each sequence's last valid frame,
//! so it keeps its state at zero over padding: `h <- h + m_t (h_new - h)`. The
//! forward pass needs no mask (outputs past a sequence's end are ignored by the
//! callers, which mask them out).

use candle_core::{D, Tensor};

use crate::error::Result;
use crate::frames::Frames;
use crate::lstm_op::Recurrence;
use nn::Params;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Forward,
    Backward,
}

pub struct Lstm {
    w_ih_t: Tensor,
    w_hh: Tensor,
    bias: Tensor,
    hidden: usize,
}

impl Lstm {
    /// Uniform init in +-1/sqrt(hidden) (PyTorch); the forget-gate bias starts at 1
    /// so that early training keeps memory.
    pub fn new(p: &Params, name: &str, input: usize, hidden: usize) -> Result<Self> {
        let bound = 1.0 / (hidden as f32).sqrt();
        let w_ih = p.uniform(&format!("{name}.w_ih"), &[4 * hidden, input], bound)?;
        let w_hh = p.uniform(&format!("{name}.w_hh"), &[4 * hidden, hidden], bound)?;
        let mut b = vec![0.0f32; 4 * hidden];
        b[hidden..2 * hidden].fill(1.0);
        let bias = p.values(&format!("{name}.bias"), &[4 * hidden], b)?;
        Ok(Lstm {
            w_ih_t: w_ih.t()?,
            w_hh,
            bias,
            hidden,
        })
    }

    pub fn hidden(&self) -> usize {
        self.hidden
    }

    /// `x`: `(B, T, I)`; `mask`: `(B, T)` of 0/1, used by the backward direction.
    /// Returns `(B, T, H)`, outputs in time order for both directions. The
    /// recurrence is one op with its own backward pass ([`crate::lstm_op`]).
    pub fn forward(&self, x: &Tensor, mask: &Tensor, dir: Direction) -> Result<Tensor> {
        self.recurrence(&self.projection(x)?, Some(mask), dir)
    }

    /// The same from the valid frames' inputs only, `rows` `(valid, I)` of
    /// the batch `frames` describes: the input projection is computed for
    /// those; padded steps get a zero projection (their outputs are masked by
    /// every caller, and the backward direction keeps its state at zero over
    /// them anyway).
    pub fn forward_rows(
        &self,
        rows: &Tensor,
        frames: &Frames,
        mask: &Tensor,
        dir: Direction,
    ) -> Result<Tensor> {
        let proj = frames
            .unpack(&self.project(rows)?)?
            .transpose(0, 1)?
            .contiguous()?;
        self.recurrence(&proj, Some(mask), dir)
    }

    /// The same input `x` `(B, I)` at each of `steps` steps, forward (the
    /// decoder's repeated code): projected once, not once per step.
    pub fn forward_repeated(&self, x: &Tensor, steps: usize) -> Result<Tensor> {
        let (b, _) = x.dims2()?;
        let proj = self
            .project(x)?
            .unsqueeze(0)?
            .broadcast_as((steps, b, 4 * self.hidden))?
            .contiguous()?;
        self.recurrence(&proj, None, Direction::Forward)
    }

    /// `rows` `(N, I)` -> `x W_ih^T + b`, `(N, 4H)`.
    fn project(&self, rows: &Tensor) -> Result<Tensor> {
        Ok(nn::add_bias(&rows.matmul(&self.w_ih_t)?, &self.bias)?)
    }

    /// The recurrence op on a time-major projection `(T, B, 4H)`; the mask
    /// is read by the backward direction only. Returns `(B, T, H)`.
    fn recurrence(&self, proj: &Tensor, mask: Option<&Tensor>, dir: Direction) -> Result<Tensor> {
        let (t, b, _) = proj.dims3()?;
        let mask = match (dir, mask) {
            (Direction::Backward, Some(m)) => Some(
                m.to_dtype(candle_core::DType::F32)?
                    .t()?
                    .flatten_all()?
                    .to_vec1::<f32>()?,
            ),
            _ => None,
        };
        let op = Recurrence {
            steps: t,
            batch: b,
            hidden: self.hidden,
            reverse: dir == Direction::Backward,
            mask,
            trace: Default::default(),
        };
        Ok(proj.apply_op2(&self.w_hh, op)?.transpose(0, 1)?)
    }

    /// `x W_ih^T + b` for every frame at once, time-major `(T, B, 4H)`.
    fn projection(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, i) = x.dims3()?;
        Ok(self
            .project(&x.reshape((b * t, i))?)?
            .reshape((b, t, 4 * self.hidden))?
            .transpose(0, 1)?
            .contiguous()?)
    }

    /// The recurrence written with candle's tensor ops on top of the fused
    /// projection (the version before [`crate::lstm_op`]; kept for the bench
    /// and the tests).
    pub fn forward_graph(&self, x: &Tensor, mask: &Tensor, dir: Direction) -> Result<Tensor> {
        let (b, t, _) = x.dims3()?;
        let proj = self.projection(x)?;
        // candle's backward of a slice pads its gradient to the full tensor, so
        // slicing T steps straight out of the projection would cost O(T^2) in the
        // backward pass. Slicing blocks of ~sqrt(T) steps first, then steps out of
        // the blocks, costs O(T^1.5).
        let block = ((t as f64).sqrt().ceil() as usize).max(1);
        let blocks: Vec<Tensor> = (0..t)
            .step_by(block)
            .map(|s| proj.narrow(0, s, block.min(t - s)))
            .collect::<candle_core::Result<_>>()?;
        self.recur(b, t, mask, dir, |step| {
            Ok(blocks[step / block].get(step % block)?)
        })
    }

    /// The same function with the input projection done per step (reference).
    pub fn forward_naive(&self, x: &Tensor, mask: &Tensor, dir: Direction) -> Result<Tensor> {
        let (b, t, _) = x.dims3()?;
        self.recur(b, t, mask, dir, |step| {
            let xt = x.narrow(1, step, 1)?.squeeze(1)?;
            Ok(xt.matmul(&self.w_ih_t)?.broadcast_add(&self.bias)?)
        })
    }

    fn recur(
        &self,
        b: usize,
        t: usize,
        mask: &Tensor,
        dir: Direction,
        input_gates: impl Fn(usize) -> Result<Tensor>,
    ) -> Result<Tensor> {
        let hsz = self.hidden;
        let w_hh_t = self.w_hh.t()?;
        let dev = self.bias.device();
        let mut h = Tensor::zeros((b, hsz), self.bias.dtype(), dev)?;
        let mut c = h.clone();
        let mut outs = Vec::with_capacity(t);
        let order: Vec<usize> = match dir {
            Direction::Forward => (0..t).collect(),
            Direction::Backward => (0..t).rev().collect(),
        };
        for step in order {
            let gates = (input_gates(step)? + h.matmul(&w_hh_t)?)?;
            let sig = candle_nn::ops::sigmoid(&gates)?;
            let i = sig.narrow(D::Minus1, 0, hsz)?;
            let f = sig.narrow(D::Minus1, hsz, hsz)?;
            let g = gates.narrow(D::Minus1, 2 * hsz, hsz)?.tanh()?;
            let o = sig.narrow(D::Minus1, 3 * hsz, hsz)?;
            let c_new = ((f * &c)? + (i * g)?)?;
            let h_new = (o * c_new.tanh()?)?;
            match dir {
                Direction::Forward => {
                    c = c_new;
                    h = h_new;
                }
                Direction::Backward => {
                    let m = mask.narrow(1, step, 1)?; // (B, 1)
                    c = (&c + (c_new - &c)?.broadcast_mul(&m)?)?;
                    h = (&h + (h_new - &h)?.broadcast_mul(&m)?)?;
                }
            }
            outs.push(h.clone());
        }
        if dir == Direction::Backward {
            outs.reverse();
        }
        Ok(Tensor::stack(&outs, 1)?)
    }
}

/// Two LSTMs reading the sequence in both directions; outputs concatenated,
/// `(B, T, 2H)`.
pub struct BiLstm {
    fw: Lstm,
    bw: Lstm,
}

impl BiLstm {
    pub fn new(p: &Params, name: &str, input: usize, hidden: usize) -> Result<Self> {
        Ok(BiLstm {
            fw: Lstm::new(p, &format!("{name}.fw"), input, hidden)?,
            bw: Lstm::new(p, &format!("{name}.bw"), input, hidden)?,
        })
    }

    /// `x` `(B, T, I)`, padded frames skipped by the input projections.
    pub fn forward(&self, x: &Tensor, mask: &Tensor) -> Result<Tensor> {
        let frames = Frames::new(mask)?;
        self.forward_rows(&frames.pack(x)?, &frames, mask)
    }

    /// From the valid frames' inputs `(valid, I)` (see [`Lstm::forward_rows`]).
    pub fn forward_rows(&self, rows: &Tensor, frames: &Frames, mask: &Tensor) -> Result<Tensor> {
        let f = self
            .fw
            .forward_rows(rows, frames, mask, Direction::Forward)?;
        let b = self
            .bw
            .forward_rows(rows, frames, mask, Direction::Backward)?;
        Ok(Tensor::cat(&[f, b], D::Minus1)?)
    }
}

/// Mean over the valid frames: `x` `(B, T, C)`, `mask` `(B, T)` -> `(B, C)`.
pub fn masked_mean(x: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let m = mask.unsqueeze(D::Minus1)?;
    let sum = x.broadcast_mul(&m)?.sum(1)?;
    let count = m.sum(1)?.clamp(1.0, f64::INFINITY)?;
    Ok(sum.broadcast_div(&count)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    /// Scalar LSTM cell in plain f64, straight from the equations.
    #[allow(clippy::too_many_arguments)]
    fn scalar_reference(
        w_ih: &[f32],
        w_hh: &[f32],
        bias: &[f32],
        x: &[f32],
        t: usize,
        i: usize,
        h: usize,
        len: usize,
        backward: bool,
    ) -> Vec<f64> {
        let sig = |v: f64| 1.0 / (1.0 + (-v).exp());
        let mut hs = vec![0.0f64; h];
        let mut cs = vec![0.0f64; h];
        let mut out = vec![0.0f64; t * h];
        let steps: Vec<usize> = if backward {
            (0..len).rev().collect()
        } else {
            (0..t).collect()
        };
        for s in steps {
            let mut g = vec![0.0f64; 4 * h];
            for r in 0..4 * h {
                let mut acc = bias[r] as f64;
                for k in 0..i {
                    acc += w_ih[r * i + k] as f64 * x[s * i + k] as f64;
                }
                for k in 0..h {
                    acc += w_hh[r * h + k] as f64 * hs[k];
                }
                g[r] = acc;
            }
            for k in 0..h {
                let (ig, fg, gg, og) = (
                    sig(g[k]),
                    sig(g[h + k]),
                    g[2 * h + k].tanh(),
                    sig(g[3 * h + k]),
                );
                cs[k] = fg * cs[k] + ig * gg;
                hs[k] = og * cs[k].tanh();
            }
            out[s * h..(s + 1) * h].copy_from_slice(&hs);
        }
        out
    }

    #[test]
    fn fused_matches_naive_and_the_scalar_reference() {
        let (b, t, i, h) = (2, 5, 3, 4);
        let p = Params::new(7);
        let lstm = Lstm::new(&p, "l", i, h).unwrap();
        let x = p.uniform("x", &[b, t, i], 1.0).unwrap();
        // Second sequence has 3 valid frames.
        let mask = Tensor::from_vec(
            vec![1f32, 1., 1., 1., 1., 1., 1., 1., 0., 0.],
            (b, t),
            &Device::Cpu,
        )
        .unwrap();
        let get = |n: &str| {
            p.vars()
                .iter()
                .find(|(k, _)| k == n)
                .unwrap()
                .1
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
        };
        let (w_ih, w_hh, bias) = (get("l.w_ih"), get("l.w_hh"), get("l.bias"));
        let xs = x.to_dtype(DType::F32).unwrap().to_vec3::<f32>().unwrap();
        for dir in [Direction::Forward, Direction::Backward] {
            let fused = lstm
                .forward(&x, &mask, dir)
                .unwrap()
                .to_vec3::<f32>()
                .unwrap();
            let naive = lstm
                .forward_naive(&x, &mask, dir)
                .unwrap()
                .to_vec3::<f32>()
                .unwrap();
            for s in 0..b {
                let len = if s == 0 { 5 } else { 3 };
                let flat: Vec<f32> = xs[s].iter().flatten().copied().collect();
                let reference = scalar_reference(
                    &w_ih,
                    &w_hh,
                    &bias,
                    &flat,
                    t,
                    i,
                    h,
                    len,
                    dir == Direction::Backward,
                );
                // Compare on valid frames (padding outputs are unspecified).
                let valid = if dir == Direction::Backward { len } else { t };
                for step in 0..valid {
                    for k in 0..h {
                        let r = reference[step * h + k];
                        assert!(
                            (fused[s][step][k] as f64 - r).abs() < 1e-5,
                            "{dir:?} {s} {step} {k}"
                        );
                        assert!((naive[s][step][k] - fused[s][step][k]).abs() < 1e-6);
                    }
                }
            }
        }
    }

    /// The op's hand-written backward pass against candle's autograd through
    /// the per-step and the graph versions: gradients of every parameter and of
    /// the input, both directions, one sequence padded.
    #[test]
    fn gradients_match_between_the_op_the_graph_and_naive() {
        let (b, t, i, h) = (3, 7, 3, 5);
        let p = Params::new(3);
        let lstm = Lstm::new(&p, "l", i, h).unwrap();
        let x = p.uniform("x", &[b, t, i], 1.0).unwrap();
        let mut m = vec![1f32; b * t];
        m[t + 4..2 * t].fill(0.0); // second sequence: 4 valid frames
        let mask = Tensor::from_vec(m, (b, t), &Device::Cpu).unwrap();
        let weights = Tensor::from_vec(
            (0..b * t * h)
                .map(|k| ((k * 37) % 11) as f32 / 11.0 - 0.4)
                .collect::<Vec<_>>(),
            (b, t, h),
            &Device::Cpu,
        )
        .unwrap();
        for dir in [Direction::Forward, Direction::Backward] {
            let grads = |version: usize| {
                let y = match version {
                    0 => lstm.forward(&x, &mask, dir),
                    1 => lstm.forward_graph(&x, &mask, dir),
                    _ => lstm.forward_naive(&x, &mask, dir),
                }
                .unwrap();
                // A weighted sum of squares so that every output matters differently.
                let loss = (y.sqr().unwrap() * &weights).unwrap().sum_all().unwrap();
                let g = loss.backward().unwrap();
                p.vars()
                    .iter()
                    .map(|(name, v)| {
                        let values = g
                            .get(v.as_tensor())
                            .unwrap()
                            .flatten_all()
                            .unwrap()
                            .to_vec1::<f32>()
                            .unwrap();
                        (name.clone(), values)
                    })
                    .collect::<Vec<_>>()
            };
            let (op, graph, naive) = (grads(0), grads(1), grads(2));
            for ((name, a), ((_, g), (_, n))) in op.iter().zip(graph.iter().zip(&naive)) {
                assert!(a.iter().any(|v| v.abs() > 1e-4), "{dir:?} {name}: all zero");
                for (k, ((x, y), z)) in a.iter().zip(g).zip(n).enumerate() {
                    assert!(
                        (x - y).abs() < 1e-5,
                        "{dir:?} {name}[{k}]: op {x} graph {y}"
                    );
                    assert!(
                        (x - z).abs() < 1e-5,
                        "{dir:?} {name}[{k}]: op {x} naive {z}"
                    );
                }
            }
        }
    }

    #[test]
    fn masked_mean_ignores_padding() {
        let x =
            Tensor::from_vec(vec![1f32, 2., 100., 4., 5., 6.], (2, 3, 1), &Device::Cpu).unwrap();
        let m = Tensor::from_vec(vec![1f32, 1., 0., 1., 1., 1.], (2, 3), &Device::Cpu).unwrap();
        let r = masked_mean(&x, &m).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(r, vec![vec![1.5], vec![5.0]]);
    }
}
