//! DMGNN (Li et al., CVPR 2020, "Dynamic multiscale graph neural networks for
//! 3D skeleton based human motion prediction"): the deterministic baseline of
//! V-DMGNN-GAN, sized for a CPU.
//!
//! * [`MultiScaleEncoder`] (the MFE unit): the observed frames at three scales
//!   (joints; parts and bodies by averaging, [`BodyGraph`]); per scale four
//!   SS-GCB blocks ([`StGcn`]) that widen the channels and halve the frames;
//!   after the first two blocks, cross-scale fusion ([`CrossScaleFusion`]):
//!   attention graphs between joints and parts and between parts and bodies,
//!   computed from embeddings of each node's whole feature trajectory; at the
//!   end the parts' and bodies' features are spread back to their joints
//!   (weighted by `lambda`), a fifth block runs on the joints, and the frames
//!   are averaged.
//! * The encoder reads each node's position, velocity and acceleration as nine
//!   input channels (the original runs three encoders, one per quantity, and
//!   concatenates their features: three times the cost for what one encoder
//!   with the three as channels also sees); its node features are projected to
//!   the decoder's state.
//! * [`GgruDecoder`]: a graph GRU ([`GraphGru`]) started from that state, fed
//!   each step the current pose with its velocity and acceleration, predicting
//!   the change to the next pose (residual).
//!
//! Left out of the original: dropout, batch norm (layer norm instead), the
//! node-edge message passing inside the fusion embeddings (a two-layer MLP per
//! node instead).

use candle_core::{D, Tensor};
use candle_nn::ops::softmax;
use nn::{Linear, Params};
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::predict::body_graph::{BodyGraph, Scale};
use crate::predict::graph_layers::{GraphGru, StGcn, constant, mix_nodes, pos_vel_acc};
use crate::predict::{Predictor, l1_or_l2};

/// The reconstruction loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Reconstruction {
    /// Mean absolute error (DMGNN, V-DMGNN-GAN's base).
    #[default]
    L1,
    /// Mean squared error (V-DMGNN-GAN's Table 2 ablation).
    L2,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DmgnnConfig {
    /// Observed frames (the fusion embeddings read whole trajectories).
    pub input_frames: usize,
    /// Channels of the four encoder blocks (original: 32, 64, 128, 256).
    pub channels: [usize; 4],
    /// Node state of the decoder (original: 256).
    pub hidden: usize,
    /// Size of the fusion embeddings (original: 256).
    pub embed: usize,
    /// Weight of the cross-scale messages (original `cross_w`: 0.3).
    pub cross_weight: f32,
    /// Weight of the parts' and bodies' features spread back to the joints
    /// (original `lamda`: 0.6).
    pub lambda: f32,
    /// Read velocities and accelerations too (as input channels).
    pub vel_acc: bool,
    pub loss: Reconstruction,
}

impl std::str::FromStr for Reconstruction {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "l1" => Ok(Reconstruction::L1),
            "l2" => Ok(Reconstruction::L2),
            _ => Err(format!("unknown loss `{s}` (l1 or l2)")),
        }
    }
}

impl std::fmt::Display for Reconstruction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Reconstruction::L1 => "l1",
            Reconstruction::L2 => "l2",
        })
    }
}

impl DmgnnConfig {
    pub fn new(input_frames: usize) -> Self {
        DmgnnConfig {
            input_frames,
            channels: [16, 32, 64, 64],
            hidden: 64,
            embed: 64,
            cross_weight: 0.3,
            lambda: 0.6,
            vel_acc: true,
            loss: Reconstruction::L1,
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.input_frames < 3 {
            return Err(EvalError::Config(
                "dmgnn: needs at least 3 observed frames (velocity and acceleration)".into(),
            ));
        }
        if self.channels.contains(&0) || self.hidden == 0 || self.embed == 0 {
            return Err(EvalError::Config(format!(
                "dmgnn: sizes must be positive, got {self:?}"
            )));
        }
        Ok(())
    }
}

/// Attention between the nodes of two scales, from embeddings of each node's
/// trajectory `(T C)`: `att[w, v] = softmax_v(h_to[w] . h_from[v])`.
pub struct CrossScaleFusion {
    embed_a: [Linear; 2],
    embed_b: [Linear; 2],
}

impl CrossScaleFusion {
    fn new(p: &Params, name: &str, t: usize, c: usize, e: usize) -> Result<Self> {
        let l = |n: &str, i: usize, o: usize| Linear::new(p, &format!("{name}.{n}"), i, o);
        Ok(CrossScaleFusion {
            embed_a: [l("a1", t * c, e)?, l("a2", e, e)?],
            embed_b: [l("b1", t * c, e)?, l("b2", e, e)?],
        })
    }

    fn embed(layers: &[Linear; 2], x: &Tensor) -> Result<Tensor> {
        // (B, T, S, C) -> (B, S, T C) -> (B, S, E)
        let (b, t, s, c) = x.dims4()?;
        let flat = x.transpose(1, 2)?.contiguous()?.reshape((b, s, t * c))?;
        let h = leaky(&layers[0].forward(&flat)?)?;
        Ok(layers[1].forward(&h)?)
    }

    /// Messages from `a` to `b` and from `b` to `a`, each shaped like its target.
    fn exchange(&self, a: &Tensor, b: &Tensor) -> Result<(Tensor, Tensor)> {
        let ha = Self::embed(&self.embed_a, a)?;
        let hb = Self::embed(&self.embed_b, b)?;
        let scores = hb.matmul(&ha.transpose(1, 2)?.contiguous()?)?; // (B, Sb, Sa)
        let to_b = softmax(&scores, D::Minus1)?;
        let to_a = softmax(&scores.transpose(1, 2)?.contiguous()?, D::Minus1)?;
        Ok((attend(&to_a, b)?, attend(&to_b, a)?))
    }
}

/// `att` `(B, S_to, S_from)` applied to `x` `(B, T, S_from, C)`.
fn attend(att: &Tensor, x: &Tensor) -> Result<Tensor> {
    let (b, t, s, c) = x.dims4()?;
    let flat = x.transpose(1, 2)?.contiguous()?.reshape((b, s, t * c))?;
    let out = att.matmul(&flat)?;
    let s_to = att.dim(1)?;
    Ok(out
        .reshape((b, s_to, t, c))?
        .transpose(1, 2)?
        .contiguous()?)
}

fn leaky(x: &Tensor) -> Result<Tensor> {
    Ok(candle_nn::ops::leaky_relu(x, 0.1)?)
}

/// DMGNN's multi-scale feature extraction unit.
pub struct MultiScaleEncoder {
    joints: Vec<StGcn>,
    parts: Vec<StGcn>,
    bodies: Vec<StGcn>,
    fuse_jp: Vec<CrossScaleFusion>,
    fuse_pb: Vec<CrossScaleFusion>,
    last: StGcn,
    pool_parts: Tensor,
    pool_bodies: Tensor,
    spread_parts: Tensor,
    spread_bodies: Tensor,
    cross_weight: f64,
    lambda: f64,
}

/// Frames halve in blocks 2-4 (stride 2), as in the original.
const STRIDES: [usize; 4] = [1, 2, 2, 2];
/// Fusion after the first two blocks (the original's best setting).
const FUSIONS: usize = 2;

impl MultiScaleEncoder {
    pub fn new(
        p: &Params,
        name: &str,
        graph: &BodyGraph,
        cfg: &DmgnnConfig,
        c_in: usize,
    ) -> Result<Self> {
        let blocks = |scale: Scale, tag: &str| -> Result<Vec<StGcn>> {
            let mut c = c_in;
            let mut out = Vec::new();
            for (i, (&c_out, &stride)) in cfg.channels.iter().zip(&STRIDES).enumerate() {
                out.push(StGcn::new(
                    p,
                    &format!("{name}.{tag}{i}"),
                    graph,
                    scale,
                    c,
                    c_out,
                    stride,
                    i > 0,
                )?);
                c = c_out;
            }
            Ok(out)
        };
        let mut fuse_jp = Vec::new();
        let mut fuse_pb = Vec::new();
        let mut t = cfg.input_frames;
        for (i, stride) in STRIDES.iter().enumerate().take(FUSIONS) {
            t = t.div_ceil(*stride);
            let c = cfg.channels[i];
            fuse_jp.push(CrossScaleFusion::new(
                p,
                &format!("{name}.jp{i}"),
                t,
                c,
                cfg.embed,
            )?);
            fuse_pb.push(CrossScaleFusion::new(
                p,
                &format!("{name}.pb{i}"),
                t,
                c,
                cfg.embed,
            )?);
        }
        let c4 = cfg.channels[3];
        let (v, np, nb) = (graph.nodes(), graph.parts, graph.bodies);
        Ok(MultiScaleEncoder {
            joints: blocks(Scale::Joints, "j")?,
            parts: blocks(Scale::Parts, "p")?,
            bodies: blocks(Scale::Bodies, "b")?,
            fuse_jp,
            fuse_pb,
            last: StGcn::new(
                p,
                &format!("{name}.j4"),
                graph,
                Scale::Joints,
                c4,
                c4,
                1,
                true,
            )?,
            pool_parts: constant(graph.pooling(Scale::Parts), np, v)?,
            pool_bodies: constant(graph.pooling(Scale::Bodies), nb, v)?,
            spread_parts: constant(graph.spreading(Scale::Parts), v, np)?,
            spread_bodies: constant(graph.spreading(Scale::Bodies), v, nb)?,
            cross_weight: cfg.cross_weight as f64,
            lambda: cfg.lambda as f64,
        })
    }

    /// `(B, T, V, C_in)` -> node features `(B, V, C_4)` (frames averaged) and
    /// the last block's output `(B, T', V, C_4)`.
    pub fn forward(&self, x: &Tensor) -> Result<(Tensor, Tensor)> {
        let mut j = x.clone();
        let mut p = mix_nodes(&self.pool_parts, x)?;
        let mut b = mix_nodes(&self.pool_bodies, x)?;
        for i in 0..self.joints.len() {
            j = self.joints[i].forward(&j)?;
            p = self.parts[i].forward(&p)?;
            b = self.bodies[i].forward(&b)?;
            if i < FUSIONS {
                let (p_to_j, j_to_p) = self.fuse_jp[i].exchange(&j, &p)?;
                let (b_to_p, p_to_b) = self.fuse_pb[i].exchange(&p, &b)?;
                let w = self.cross_weight;
                j = (&j + (p_to_j * w)?)?;
                p = (&p + ((j_to_p + b_to_p)? * w)?)?;
                b = (&b + (p_to_b * w)?)?;
            }
        }
        let back = (mix_nodes(&self.spread_parts, &p)? + mix_nodes(&self.spread_bodies, &b)?)?;
        let joined = (j + (back * self.lambda)?)?;
        let h = self.last.forward(&joined)?;
        Ok((h.mean(1)?, h))
    }
}

/// The graph-GRU decoder: residual pose steps from an initial node state.
pub struct GgruDecoder {
    cell: GraphGru,
    out: [Linear; 3],
}

impl GgruDecoder {
    pub fn new(p: &Params, name: &str, graph: &BodyGraph, hidden: usize) -> Result<Self> {
        let l = |n: &str, i: usize, o: usize| Linear::new(p, &format!("{name}.{n}"), i, o);
        Ok(GgruDecoder {
            cell: GraphGru::new(p, &format!("{name}.cell"), graph, 9, hidden)?,
            out: [
                l("out1", hidden, hidden)?,
                l("out2", hidden, hidden)?,
                l("out3", hidden, 3)?,
            ],
        })
    }

    /// `frames` poses `(B, frames, V, 3)` after the observed `(B, T, V, 3)`
    /// (T >= 3), from node state `h` `(B, V, H)`.
    pub fn forward(&self, observed: &Tensor, h: &Tensor, frames: usize) -> Result<Tensor> {
        let t = observed.dim(1)?;
        let frame = |i: usize| -> Result<Tensor> { Ok(observed.narrow(1, i, 1)?.squeeze(1)?) };
        let (mut p2, mut p1, mut p0) = (frame(t - 3)?, frame(t - 2)?, frame(t - 1)?);
        let mut h = h.clone();
        let mut out = Vec::with_capacity(frames);
        for _ in 0..frames {
            let x = pos_vel_acc(&p2, &p1, &p0)?;
            h = self.cell.step(&x, &h)?;
            let d = leaky(&self.out[0].forward(&h)?)?;
            let d = leaky(&self.out[1].forward(&d)?)?;
            let next = (&p0 + self.out[2].forward(&d)?)?;
            out.push(next.clone());
            (p2, p1, p0) = (p1, p0, next);
        }
        Ok(Tensor::stack(&out, 1)?)
    }
}

/// The encoder's input of `(B, T, V, 3)` frames: the positions, or with
/// `vel_acc` positions, velocities and accelerations `(B, T, V, 9)` (zero where
/// a frame has no predecessor).
pub fn encoder_input(x: &Tensor, vel_acc: bool) -> Result<Tensor> {
    if !vel_acc {
        return Ok(x.clone());
    }
    let t = x.dim(1)?;
    let zero = x.narrow(1, 0, 1)?.zeros_like()?;
    let v = Tensor::cat(
        &[&zero, &(x.narrow(1, 1, t - 1)? - x.narrow(1, 0, t - 1)?)?],
        1,
    )?;
    let a = Tensor::cat(
        &[&zero, &(v.narrow(1, 1, t - 1)? - v.narrow(1, 0, t - 1)?)?],
        1,
    )?;
    Ok(Tensor::cat(&[x, &v, &a], D::Minus1)?)
}

/// Input channels per node of the encoder.
pub fn encoder_channels(vel_acc: bool) -> usize {
    if vel_acc { 9 } else { 3 }
}

pub struct Dmgnn {
    config: DmgnnConfig,
    nodes: usize,
    encoder: MultiScaleEncoder,
    to_state: Linear,
    decoder: GgruDecoder,
    params: Params,
}

impl Dmgnn {
    pub fn new(config: &DmgnnConfig, graph: &BodyGraph, seed: u64) -> Result<Self> {
        config.validate()?;
        let p = Params::new(seed);
        let encoder =
            MultiScaleEncoder::new(&p, "enc", graph, config, encoder_channels(config.vel_acc))?;
        Ok(Dmgnn {
            to_state: Linear::new(&p, "to_state", config.channels[3], config.hidden)?,
            decoder: GgruDecoder::new(&p, "dec", graph, config.hidden)?,
            encoder,
            nodes: graph.nodes(),
            config: config.clone(),
            params: p,
        })
    }

    pub fn config(&self) -> &DmgnnConfig {
        &self.config
    }

    /// `(B, T, 3V)` -> `(B, T, V, 3)`, checking the sizes.
    fn nodes_of(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        if d != 3 * self.nodes || t != self.config.input_frames {
            return Err(EvalError::Config(format!(
                "dmgnn: built for {} frames of {} features, got {t} of {d}",
                self.config.input_frames,
                3 * self.nodes
            )));
        }
        Ok(x.reshape((b, t, self.nodes, 3))?)
    }

    fn run(&self, input: &Tensor, frames: usize) -> Result<Tensor> {
        let x = self.nodes_of(input)?;
        let (feats, _) = self
            .encoder
            .forward(&encoder_input(&x, self.config.vel_acc)?)?;
        let h = self.to_state.forward(&feats)?.relu()?;
        let y = self.decoder.forward(&x, &h, frames)?;
        let (b, _, _, _) = y.dims4()?;
        Ok(y.reshape((b, frames, 3 * self.nodes))?)
    }
}

impl Predictor for Dmgnn {
    fn loss(&self, input: &Tensor, target: &Tensor) -> Result<Tensor> {
        let pred = self.run(input, target.dim(1)?)?;
        l1_or_l2(self.config.loss, &pred, target)
    }

    fn predict(&self, input: &Tensor, frames: usize) -> Result<Tensor> {
        self.run(input, frames)
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
    fn shapes_loss_and_gradients_reach_every_encoder() {
        let g = crate::predict::test_support::hdm05_graph();
        let mut cfg = DmgnnConfig::new(10);
        cfg.channels = [4, 8, 8, 8];
        cfg.hidden = 8;
        cfg.embed = 8;
        let m = Dmgnn::new(&cfg, &g, 2).unwrap();
        let d = 3 * g.nodes();
        let x = Tensor::randn(0f32, 1.0, (3, 10, d), &Device::Cpu).unwrap();
        assert_eq!(m.predict(&x, 7).unwrap().dims(), &[3, 7, d]);
        let bad = Tensor::randn(0f32, 1.0, (3, 9, d), &Device::Cpu).unwrap();
        assert!(m.predict(&bad, 7).is_err());
        let y = Tensor::randn(0f32, 1.0, (3, 7, d), &Device::Cpu).unwrap();
        let loss = m.loss(&x, &y).unwrap();
        let grads = loss.backward().unwrap();
        for (name, v) in m.params().vars() {
            // Every learnable tensor takes part in the prediction.
            assert!(grads.get(v.as_tensor()).is_some(), "no gradient for {name}");
        }
    }
}
