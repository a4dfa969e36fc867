//! The LSTM recurrence as one candle op with its backward pass written out.
//!
//! Why it exists: written with candle's tensor ops, every one of the T steps
//! adds about a dozen nodes to the autograd graph, and the backward pass of
//! every slice (a step's input, the four gates) pads its gradient with zeros
//! to the full tensor and adds it up. `perf` on a VAE training step (kick, 23
//! clips, one thread) put most of the time there: zero-filling and copying
//! (memset, memcpy, `Tensor::cat`, page faults) and element-wise adds, with
//! the matmul kernels at 17 %. Here the recurrence is plain loops over the
//! gates plus one small matmul per step, forward and backward (BPTT), and the
//! recurrent weight's gradient is one large matmul at the end. The forward
//! pass keeps the states the backward pass needs (gates, cell states) in the
//! op, which the autograd graph holds until the backward pass takes them.
//!
//! Inputs: the input projection `x W_ih^T + b`, time-major `(T, B, 4H)`, and
//! `W_hh` `(4H, H)`; output `h`, time-major `(T, B, H)`. Gates are `[i, f,
//! g, o]`. The backward direction runs the steps last to first and keeps a
//! sequence's state where its mask is 0 (`h <- h + m (h_new - h)`), as
//! [`crate::lstm::Lstm`] documents.

use std::sync::Mutex;

use candle_core::{CpuStorage, CustomOp2, Device, Layout, Shape, Tensor};

/// One LSTM pass over a batch of sequences.
pub(crate) struct Recurrence {
    pub steps: usize,
    pub batch: usize,
    pub hidden: usize,
    /// Run the steps last to first.
    pub reverse: bool,
    /// `(T, B)` time-major 0/1, or none (every frame valid).
    pub mask: Option<Vec<f32>>,
    /// The forward pass's states, taken by the backward pass (recomputed if
    /// absent).
    pub trace: Mutex<Option<Trace>>,
}

/// The forward states a backward pass needs, time-major.
pub(crate) struct Trace {
    /// Activated gates `(T, B, 4H)`: sigmoid i, f, o; tanh g.
    gates: Vec<f32>,
    c_prev: Vec<f32>,
    /// `tanh` of the new cell state.
    tanh_c: Vec<f32>,
    h_prev: Vec<f32>,
}

fn sigmoid(v: f32) -> f32 {
    1.0 / (1.0 + (-v).exp())
}

/// `tanh` through one `exp` (glibc's `tanhf` goes through `expm1f` and was a
/// sixth of a VAE training step in `perf`); saturates cleanly at both ends.
fn tanh(v: f32) -> f32 {
    1.0 - 2.0 / ((2.0 * v).exp() + 1.0)
}

/// `a` `(m, k)` times `b`, where `b` is a `(k, n)` tensor (any strides).
fn matmul(a: &[f32], m: usize, k: usize, b: &Tensor) -> candle_core::Result<Vec<f32>> {
    Tensor::from_slice(a, (m, k), &Device::Cpu)?
        .matmul(b)?
        .flatten_all()?
        .to_vec1::<f32>()
}

impl Recurrence {
    fn order(&self) -> Vec<usize> {
        if self.reverse {
            (0..self.steps).rev().collect()
        } else {
            (0..self.steps).collect()
        }
    }

    fn check(&self, proj: usize, w: usize) -> candle_core::Result<()> {
        let (t, b, h) = (self.steps, self.batch, self.hidden);
        if proj != t * b * 4 * h || w != 4 * h * h {
            candle_core::bail!(
                "lstm recurrence: projection has {proj} values (expected {}), weights {w} (expected {})",
                t * b * 4 * h,
                4 * h * h
            );
        }
        if let Some(m) = &self.mask
            && m.len() != t * b
        {
            candle_core::bail!(
                "lstm recurrence: mask has {} values, expected {}",
                m.len(),
                t * b
            );
        }
        Ok(())
    }

    /// Runs the recurrence; `w_t` is `W_hh^T` `(H, 4H)`. Returns the states
    /// and the output `h`, time-major `(T, B, H)`.
    fn trace(&self, proj: &[f32], w_t: &Tensor) -> candle_core::Result<(Trace, Vec<f32>)> {
        let (t, b, h) = (self.steps, self.batch, self.hidden);
        let g4 = 4 * h;
        let mut tr = Trace {
            gates: vec![0.0; t * b * g4],
            c_prev: vec![0.0; t * b * h],
            tanh_c: vec![0.0; t * b * h],
            h_prev: vec![0.0; t * b * h],
        };
        let mut out = vec![0.0; t * b * h];
        let mut hs = vec![0.0f32; b * h];
        let mut cs = vec![0.0f32; b * h];
        for step in self.order() {
            let rec = matmul(&hs, b, h, w_t)?;
            let s = step * b * h;
            tr.h_prev[s..s + b * h].copy_from_slice(&hs);
            tr.c_prev[s..s + b * h].copy_from_slice(&cs);
            for n in 0..b {
                let m = self.mask.as_ref().map_or(1.0, |m| m[step * b + n]);
                let a = &proj[(step * b + n) * g4..(step * b + n + 1) * g4];
                let r = &rec[n * g4..(n + 1) * g4];
                let acts = &mut tr.gates[(step * b + n) * g4..(step * b + n + 1) * g4];
                for k in 0..h {
                    let i = sigmoid(a[k] + r[k]);
                    let f = sigmoid(a[h + k] + r[h + k]);
                    let g = tanh(a[2 * h + k] + r[2 * h + k]);
                    let o = sigmoid(a[3 * h + k] + r[3 * h + k]);
                    acts[k] = i;
                    acts[h + k] = f;
                    acts[2 * h + k] = g;
                    acts[3 * h + k] = o;
                    let idx = n * h + k;
                    let c_new = f * cs[idx] + i * g;
                    let tanh_c = tanh(c_new);
                    let h_new = o * tanh_c;
                    tr.tanh_c[s + idx] = tanh_c;
                    cs[idx] += m * (c_new - cs[idx]);
                    hs[idx] += m * (h_new - hs[idx]);
                }
            }
            out[s..s + b * h].copy_from_slice(&hs);
        }
        Ok((tr, out))
    }
}

impl CustomOp2 for Recurrence {
    fn name(&self) -> &'static str {
        "lstm-recurrence"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let proj = nn::cpu_op::f32_slice(s1, l1, "lstm recurrence", "the projection")?;
        let w = nn::cpu_op::f32_slice(s2, l2, "lstm recurrence", "W_hh")?;
        self.check(proj.len(), w.len())?;
        let w_t = Tensor::from_slice(w, (4 * self.hidden, self.hidden), &Device::Cpu)?.t()?;
        let (tr, out) = self.trace(proj, &w_t)?;
        if let Ok(mut keep) = self.trace.lock() {
            *keep = Some(tr);
        }
        Ok((
            CpuStorage::F32(out),
            Shape::from((self.steps, self.batch, self.hidden)),
        ))
    }

    fn bwd(
        &self,
        proj: &Tensor,
        w: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let (t, b, h) = (self.steps, self.batch, self.hidden);
        let g4 = 4 * h;
        let w_c = w.contiguous()?.detach();
        let kept = self.trace.lock().ok().and_then(|mut t| t.take());
        let tr = match kept {
            Some(tr) => tr,
            None => {
                let proj_v = proj.flatten_all()?.to_vec1::<f32>()?;
                self.check(proj_v.len(), w_c.elem_count())?;
                self.trace(&proj_v, &w_c.t()?)?.0
            }
        };
        let grad = grad_res.flatten_all()?.to_vec1::<f32>()?;

        let mut d_gates = vec![0.0f32; t * b * g4];
        let mut dh = vec![0.0f32; b * h];
        let mut dc = vec![0.0f32; b * h];
        for step in self.order().into_iter().rev() {
            let s = step * b * h;
            for (d, g) in dh.iter_mut().zip(&grad[s..s + b * h]) {
                *d += g;
            }
            for n in 0..b {
                let m = self.mask.as_ref().map_or(1.0, |m| m[step * b + n]);
                let acts = &tr.gates[(step * b + n) * g4..(step * b + n + 1) * g4];
                let da = &mut d_gates[(step * b + n) * g4..(step * b + n + 1) * g4];
                for k in 0..h {
                    let idx = n * h + k;
                    let (i, f, g, o) = (acts[k], acts[h + k], acts[2 * h + k], acts[3 * h + k]);
                    let tc = tr.tanh_c[s + idx];
                    let dh_new = m * dh[idx];
                    let dc_new = m * dc[idx] + dh_new * o * (1.0 - tc * tc);
                    da[k] = dc_new * g * i * (1.0 - i);
                    da[h + k] = dc_new * tr.c_prev[s + idx] * f * (1.0 - f);
                    da[2 * h + k] = dc_new * i * (1.0 - g * g);
                    da[3 * h + k] = dh_new * tc * o * (1.0 - o);
                    dc[idx] = (1.0 - m) * dc[idx] + dc_new * f;
                    dh[idx] *= 1.0 - m;
                }
            }
            let back = matmul(&d_gates[step * b * g4..(step + 1) * b * g4], b, g4, &w_c)?;
            for (d, v) in dh.iter_mut().zip(back) {
                *d += v;
            }
        }
        let d_gates = Tensor::from_vec(d_gates, (t * b, g4), &Device::Cpu)?;
        let h_prev = Tensor::from_vec(tr.h_prev, (t * b, h), &Device::Cpu)?;
        let d_w = d_gates.t()?.matmul(&h_prev)?;
        let d_proj = d_gates.reshape((t, b, g4))?;
        Ok((
            Some(d_proj.to_device(proj.device())?),
            Some(d_w.to_device(w.device())?),
        ))
    }
}
