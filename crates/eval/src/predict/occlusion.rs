//! Occluded observations for the V-DMGNN-GAN protocol: the masks of that
//! paper's Sec. 6.2 applied to normalised model features, at training time
//! (fresh masks every batch) and at test time (masks from a fixed seed, so
//! every model sees the same occlusions).
//!
//! * `lower`: every feature of every lower-body node is occluded in every
//!   observed frame; which joints are lower body is decided by the synth
//!   crate's mask op ([`synth::names::lower_body`], through
//!   [`BodyGraph::lower_body`]), so synthesis and prediction agree.
//! * `random`: each feature value (joint angle) of each observed frame is
//!   visible with probability [`synth::mask::DEFAULT_VISIBILITY`] (0.8), drawn
//!   per angle as the reference code does (the synth crate's motion mask draws
//!   per joint, since a rotation cannot lose one angle).
//!
//! Occluded values are replaced by Gaussian noise of standard deviation
//! [`NOISE_SD`] (in normalised units, as the reference code does).

use candle_core::{Device, Tensor};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::predict::body_graph::BodyGraph;

/// Standard deviation of the noise in occluded values (reference code: 0.5).
pub const NOISE_SD: f32 = 0.5;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum MaskKind {
    #[default]
    None,
    Lower,
    Random,
}

impl std::str::FromStr for MaskKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "none" => Ok(MaskKind::None),
            "lower" | "lower-body" | "lower_body" => Ok(MaskKind::Lower),
            "random" => Ok(MaskKind::Random),
            _ => Err(format!("unknown mask `{s}` (none, lower or random)")),
        }
    }
}

impl std::fmt::Display for MaskKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            MaskKind::None => "none",
            MaskKind::Lower => "lower",
            MaskKind::Random => "random",
        })
    }
}

/// Applies one kind of mask to `(B, T, 3V)` feature batches.
#[derive(Debug, Clone)]
pub struct Occluder {
    kind: MaskKind,
    /// Per feature: part of the lower body.
    lower: Vec<bool>,
    visibility: f64,
}

impl Occluder {
    pub fn new(kind: MaskKind, graph: &BodyGraph) -> Result<Occluder> {
        Occluder::with_lower_nodes(kind, &graph.lower_body)
    }

    /// With another choice of lower-body nodes (the CMU protocol's reference
    /// lower body, [`crate::cmu_dmgnn::REFERENCE_LOWER_BODY_USED`]).
    pub fn with_lower_nodes(kind: MaskKind, lower_nodes: &[bool]) -> Result<Occluder> {
        let lower: Vec<bool> = lower_nodes.iter().flat_map(|&l| [l, l, l]).collect();
        if kind == MaskKind::Lower && !lower.contains(&true) {
            return Err(EvalError::Config(
                "lower-body mask: no lower-body joint among the features (no feet found)".into(),
            ));
        }
        Ok(Occluder {
            kind,
            lower,
            visibility: synth::mask::DEFAULT_VISIBILITY,
        })
    }

    pub fn kind(&self) -> MaskKind {
        self.kind
    }

    /// The visibility of every value of a `(B, T, D)` batch, row-major.
    pub fn draw(&self, shape: (usize, usize, usize), rng: &mut impl Rng) -> Vec<bool> {
        let (b, t, d) = shape;
        match self.kind {
            MaskKind::None => vec![true; b * t * d],
            MaskKind::Lower => (0..b * t)
                .flat_map(|_| self.lower.iter().map(|l| !l))
                .collect(),
            MaskKind::Random => (0..b * t * d)
                .map(|_| rng.random::<f64>() < self.visibility)
                .collect(),
        }
    }

    /// `x` with occluded values replaced by noise.
    pub fn apply(&self, x: &Tensor, rng: &mut impl Rng) -> Result<Tensor> {
        if self.kind == MaskKind::None {
            return Ok(x.clone());
        }
        let (b, t, d) = x.dims3()?;
        if d != self.lower.len() {
            return Err(EvalError::Config(format!(
                "mask built for {} features, batch has {d}",
                self.lower.len()
            )));
        }
        let visible = self.draw((b, t, d), rng);
        let noise = Normal::new(0.0f32, NOISE_SD).map_err(|e| EvalError::Config(e.to_string()))?;
        let mut v: Vec<f32> = x.flatten_all()?.to_vec1()?;
        for (x, seen) in v.iter_mut().zip(visible) {
            if !seen {
                *x = noise.sample(rng);
            }
        }
        Ok(Tensor::from_vec(v, (b, t, d), &Device::Cpu)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn lower_hides_the_legs_and_random_about_a_fifth() {
        let g = crate::predict::test_support::hdm05_graph();
        let d = 3 * g.nodes();
        let x = Tensor::ones((4, 10, d), candle_core::DType::F32, &Device::Cpu).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let lower = Occluder::new(MaskKind::Lower, &g).unwrap();
        let y: Vec<f32> = lower
            .apply(&x, &mut rng)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let femur = 3 * g.names.iter().position(|n| n == "lfemur").unwrap();
        let humerus = 3 * g.names.iter().position(|n| n == "lhumerus").unwrap();
        for f in 0..40 {
            assert_ne!(y[f * d + femur], 1.0);
            assert_eq!(y[f * d + humerus], 1.0);
        }
        let random = Occluder::new(MaskKind::Random, &g).unwrap();
        let y: Vec<f32> = random
            .apply(&x, &mut rng)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let hidden = y.iter().filter(|v| **v != 1.0).count() as f64 / y.len() as f64;
        assert!((hidden - 0.2).abs() < 0.03, "{hidden}");
        let none = Occluder::new(MaskKind::None, &g).unwrap();
        assert_eq!(
            none.apply(&x, &mut rng).unwrap().to_vec3::<f32>().unwrap(),
            x.to_vec3::<f32>().unwrap()
        );
        assert!("upper".parse::<MaskKind>().is_err());
    }
}
