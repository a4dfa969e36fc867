//! The VAE's training losses, on candle tensors so that they differentiate.
//!
//! Reconstruction is measured in physical units, not normalised features: the
//! decoder output is denormalised, its root position compared in metres and its
//! 6D rotations turned into rotation matrices (Gram-Schmidt) and compared entry by
//! entry (MotionAug: "MSE on root position and rotation matrices"). Smoothness
//! penalises squared frame-to-frame differences of the denormalised output; KL is
//! the usual Gaussian term (`nn::kl_mean`); the adversarial terms are hinge losses.
//! Every mean is over valid frames only.

use candle_core::{D, Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};
use crate::normalize::NormStats;

/// Weights of the loss terms (reconstruction has weight 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    pub smooth: f64,
    /// On the KL term averaged over latent dimensions (see `nn::kl_mean`).
    pub kl: f64,
    /// On the generator's adversarial terms (frame + sequence). The notes give no
    /// number. Measured on 6 HDM05 kick clips, 500 Adam iterations: 0.01 stalls
    /// reconstruction (0.27 rad mean joint error, worse than untrained), 0.001
    /// trains like no adversarial term (0.15 rad; README).
    pub adversarial: f64,
    /// On the generator's adversarial terms for clips decoded from codes mixed
    /// between two training clips (what sampling near samples decodes); with a
    /// weight > 0 the discriminators also see those decodes as fakes. 0: the
    /// discriminators judge reconstructions only (the training before session 18).
    #[serde(default)]
    pub mixed_adversarial: f64,
    /// On the squared relative difference between a mixed-code decode's pose
    /// speed (`feet::pose_speed`, every joint) and the mean of its two parent
    /// clips'. A decoder left alone renders most in-between codes as a nearly
    /// still pose (crates/vae/README.md, session 16); this asks them to move as
    /// fast as the clips they were drawn between. 0: off.
    #[serde(default)]
    pub mixed_motion: f64,
    /// On the squared difference between the share of a mixed-code decode's
    /// frames that stand on the ground (`feet::ground_contact`) and the mean
    /// of its two parent clips' shares. Needs the foot terms. Decoded jog
    /// samples hovered in 46 % of frames where the captures hover in 10-30 %
    /// (crates/vae/README.md, session 33). 0: off.
    #[serde(default)]
    pub mixed_contact: f64,
    /// On how far a mixed-code decode's planted feet are from standing on
    /// their soles (`feet::sole_level`): the ankle-to-toe drop of a foot that
    /// is low and slow, against the training clips' mean stance drop, in
    /// units of the correction's 2 cm sole tolerance. Needs the foot terms.
    /// With the ground-contact term alone, decoded jog samples met "a foot
    /// point down" with a heel or a toe: 15 % of their planted frames on the
    /// flat sole against the captures' 80 % (crates/vae/README.md, session
    /// 33). 0: off.
    #[serde(default)]
    pub mixed_sole: f64,
    /// On the squared relative difference between a mixed-code decode's
    /// root travel profile (`feet::travel_profile`: mean horizontal root
    /// speed in each quarter of the clip) and the mean of its two parents'.
    /// With the contact and skating terms, decoded jog samples met "feet on
    /// the ground" by stopping: half of them travelled < 10 % of their path
    /// in their last quarter (captures 30 %; crates/vae/README.md, session
    /// 34), and the simulated jogger fell stopping. 0: off.
    #[serde(default)]
    pub mixed_travel: f64,
    /// On how much further a mixed-code decode's zero moment point lies
    /// outside its touching soles than its two parents' (mean over supported
    /// frames, `balance::Balance::zmp_outside`), in units of 10 cm, squared;
    /// only the excess counts. Needs `TrainConfig::balance`. Jog samples
    /// whose ZMP left the feet by more than 0.6 m fell in the simulator 110
    /// times of 113 (crates/eval/README.md, session 35). 0: off.
    #[serde(default)]
    pub mixed_balance: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            smooth: 0.001,
            kl: 0.01,
            adversarial: 0.001,
            mixed_adversarial: 0.0,
            mixed_motion: 0.0,
            mixed_contact: 0.0,
            mixed_sole: 0.0,
            mixed_travel: 0.0,
            mixed_balance: 0.0,
        }
    }
}

impl LossWeights {
    pub fn validate(&self) -> Result<()> {
        check_weights(
            "loss weight",
            &[
                ("smooth", self.smooth),
                ("kl", self.kl),
                ("adversarial", self.adversarial),
                ("mixed_adversarial", self.mixed_adversarial),
                ("mixed_motion", self.mixed_motion),
                ("mixed_contact", self.mixed_contact),
                ("mixed_sole", self.mixed_sole),
                ("mixed_travel", self.mixed_travel),
                ("mixed_balance", self.mixed_balance),
            ],
        )
    }
}

/// Every weight a finite number >= 0; `what` names them in the error.
pub(crate) fn check_weights(what: &str, weights: &[(&str, f64)]) -> Result<()> {
    for &(name, v) in weights {
        if !(v.is_finite() && v >= 0.0) {
            return Err(VaeError::Config(format!(
                "{what} {name} = {v}: must be a finite number >= 0"
            )));
        }
    }
    Ok(())
}

/// Normalisation statistics as broadcastable tensors.
pub struct Denorm {
    mean: Tensor,
    std: Tensor,
}

impl Denorm {
    pub fn new(stats: &NormStats) -> Result<Self> {
        Ok(Denorm {
            mean: Tensor::from_slice(&stats.mean, stats.dim(), &Device::Cpu)?,
            std: Tensor::from_slice(&stats.std, stats.dim(), &Device::Cpu)?,
        })
    }

    pub fn apply(&self, x: &Tensor) -> Result<Tensor> {
        Ok(x.broadcast_mul(&self.std)?.broadcast_add(&self.mean)?)
    }
}

/// `(B, T, 3 + 6J)` raw frames -> `(B, T, 9J)` rotation matrices, rows of
/// `[x axis, y axis, z axis]` per joint.
pub fn rotation_matrices(raw: &Tensor) -> Result<Tensor> {
    let (b, t, f) = raw.dims3()?;
    let joints = (f - 3) / 6;
    let six = raw.narrow(2, 3, 6 * joints)?.reshape((b, t, joints, 6))?;
    Ok(six_d_matrices(&six)?.reshape((b, t, 9 * joints))?)
}

/// `(B, T, J, 6)` 6D rotations -> `(B, T, J, 9)` rotation matrices (Gram-Schmidt),
/// rows `[x axis, y axis, z axis]`.
pub fn six_d_matrices(six: &Tensor) -> Result<Tensor> {
    let unit = |v: &Tensor| -> Result<Tensor> {
        let n = (v.sqr()?.sum_keepdim(D::Minus1)? + 1e-8)?.sqrt()?;
        Ok(v.broadcast_div(&n)?)
    };
    let x = unit(&six.narrow(3, 0, 3)?)?;
    let a2 = six.narrow(3, 3, 3)?;
    let proj = (&x * &a2)?.sum_keepdim(D::Minus1)?;
    let y = unit(&(a2 - x.broadcast_mul(&proj)?)?)?;
    let c = |v: &Tensor, k: usize| v.narrow(3, k, 1);
    let z = Tensor::cat(
        &[
            ((c(&x, 1)? * c(&y, 2)?)? - (c(&x, 2)? * c(&y, 1)?)?)?,
            ((c(&x, 2)? * c(&y, 0)?)? - (c(&x, 0)? * c(&y, 2)?)?)?,
            ((c(&x, 0)? * c(&y, 1)?)? - (c(&x, 1)? * c(&y, 0)?)?)?,
        ],
        3,
    )?;
    Ok(Tensor::cat(&[x, y, z], 3)?)
}

/// Mean over valid frames of a per-frame value `(B, T)`.
pub fn masked_frame_mean(per_frame: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let n = mask.sum_all()?.clamp(1.0, f64::INFINITY)?;
    Ok((per_frame * mask)?.sum_all()?.broadcast_div(&n)?)
}

/// Reconstruction terms: `(root MSE in m^2, rotation-matrix MSE)`.
pub fn reconstruction(
    pred_raw: &Tensor,
    target_raw: &Tensor,
    target_rotmat: &Tensor,
    mask: &Tensor,
) -> Result<(Tensor, Tensor)> {
    let root = (pred_raw.narrow(2, 0, 3)? - target_raw.narrow(2, 0, 3)?)?
        .sqr()?
        .mean(D::Minus1)?;
    let rot = (rotation_matrices(pred_raw)? - target_rotmat)?
        .sqr()?
        .mean(D::Minus1)?;
    Ok((
        masked_frame_mean(&root, mask)?,
        masked_frame_mean(&rot, mask)?,
    ))
}

/// Mean squared difference between consecutive valid frames.
pub fn smoothness(raw: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let t = raw.dim(1)?;
    if t < 2 {
        return Ok(Tensor::zeros((), raw.dtype(), raw.device())?);
    }
    let d = (raw.narrow(1, 1, t - 1)? - raw.narrow(1, 0, t - 1)?)?
        .sqr()?
        .mean(D::Minus1)?;
    // Padding is at the end: frame t+1 valid implies frame t valid.
    masked_frame_mean(&d, &mask.narrow(1, 1, t - 1)?)
}

/// Hinge loss of a discriminator: `mean relu(1 - real) + mean relu(1 + fake)`.
/// Scores are `(B, T)` with a mask, or `(B,)` with `None`.
pub fn hinge_discriminator(real: &Tensor, fake: &Tensor, mask: Option<&Tensor>) -> Result<Tensor> {
    let r = (1.0 - real)?.relu()?;
    let f = (fake + 1.0)?.relu()?;
    match mask {
        Some(m) => Ok((masked_frame_mean(&r, m)? + masked_frame_mean(&f, m)?)?),
        None => Ok((r.mean_all()? + f.mean_all()?)?),
    }
}

/// The generator's hinge term: `-mean fake`.
pub fn hinge_generator(fake: &Tensor, mask: Option<&Tensor>) -> Result<Tensor> {
    match mask {
        Some(m) => Ok(masked_frame_mean(fake, m)?.neg()?),
        None => Ok(fake.mean_all()?.neg()?),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::quat_to_6d;
    use motion::glam::{DMat3, DQuat};

    #[test]
    fn rotation_matrices_match_glam() {
        let q = DQuat::from_euler(motion::glam::EulerRot::YXZ, 0.3, -1.1, 2.0);
        let mut frame = vec![0.5f32, 1.0, -0.2];
        // Scaled, non-orthogonal 6D input still gives the same rotation.
        let s = quat_to_6d(q);
        frame.extend([s[0] * 2.0, s[1] * 2.0, s[2] * 2.0].map(|v| v as f32));
        frame.extend([s[3] + 0.3 * s[0], s[4] + 0.3 * s[1], s[5] + 0.3 * s[2]].map(|v| v as f32));
        let t = Tensor::from_vec(frame, (1, 1, 9), &Device::Cpu).unwrap();
        let m = rotation_matrices(&t)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let r = DMat3::from_quat(q);
        let expect: Vec<f64> = [r.x_axis, r.y_axis, r.z_axis]
            .iter()
            .flat_map(|c| c.to_array())
            .collect();
        for (a, b) in m.iter().zip(&expect) {
            assert!((*a as f64 - b).abs() < 1e-5, "{m:?} vs {expect:?}");
        }
    }

    #[test]
    fn hinge_is_zero_for_a_confident_correct_discriminator() {
        let real = Tensor::new(&[2f32, 1.5], &Device::Cpu).unwrap();
        let fake = Tensor::new(&[-1f32, -3.0], &Device::Cpu).unwrap();
        let d = hinge_discriminator(&real, &fake, None)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert_eq!(d, 0.0);
        let d = hinge_discriminator(&fake, &real, None)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!(d > 2.0);
        let g = hinge_generator(&fake, None)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert_eq!(g, 2.0);
    }
}
