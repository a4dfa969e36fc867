//! Whether a decoded motion could stand on its feet, differentiably: the zero
//! moment point of the simulated character's masses against the soles of its
//! feet, on candle tensors.
//!
//! Why it exists: the correction's simulated character falls when the motion
//! it imitates leans or accelerates more than its feet can hold. On jog fold
//! bd, VAE samples whose reference ZMP stays within 0.22 m of the feet (the
//! captures: 0.08-0.19 m) were accepted 30 times of 37, those beyond 0.61 m 3
//! times of 113 (crates/eval/README.md, session 35). The mixed-balance term
//! (`LossWeights::mixed_balance`) asks a mixed-code decode to stay no further
//! outside its feet than the clips it was drawn between.
//!
//! The measure is the one `motionaug metrics --balance` reads
//! (`physics::ImitationEnv::reference_balance`), on the VAE's frames: the
//! centre of mass of the character's bodies (each body's mass at its centre,
//! fixed in its driving joint's frame), its acceleration by central
//! differences, the cart-table ZMP `c_xz - c_y a_xz / (a_y + g)`, and its
//! distance outside the convex hull of the sole corners within `touch_m` of
//! the floor. The hull distance is `max_u (u . p - h(u))` over 32 horizontal
//! directions `u`, with `h` the support function of the touching corners (an
//! exact hull distance up to cos(pi / 32) = 0.995), so it differentiates like
//! a max. Which corners touch is read as a constant (like the skating term's
//! contact): the term moves the body over the feet, it does not lift a foot
//! off the floor to leave a frame unsupported. As the correction does, the
//! clip's floor is where its lower foot stands in its median frame.
//!
//! The masses and soles come from the physics crate's character builder,
//! which this crate does not depend on: `pipeline::vae_balance_model` builds
//! a [`BalanceModel`] for a skeleton.

use candle_core::{D, DType, Device, Tensor};
use motion::Skeleton;
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};
use crate::feet::FootKinematics;

/// A mass fixed in a joint's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MassPoint {
    /// Skeleton joint index.
    pub joint: usize,
    /// Centre of mass in the joint's frame, m.
    pub offset: [f32; 3],
    pub mass_kg: f32,
}

/// The four bottom corners of a foot's sole, fixed in a joint's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SoleCorners {
    pub joint: usize,
    /// m, in the joint's frame.
    pub corners: [[f32; 3]; 4],
}

/// The simulated character's masses and soles, for one skeleton.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BalanceModel {
    pub bodies: Vec<MassPoint>,
    pub soles: Vec<SoleCorners>,
    /// A sole corner at most this high (m) supports the body.
    pub touch_m: f32,
}

impl BalanceModel {
    pub fn validate(&self, skeleton: &Skeleton) -> Result<()> {
        let joints = self
            .bodies
            .iter()
            .map(|b| b.joint)
            .chain(self.soles.iter().map(|s| s.joint));
        if let Some(j) = joints.into_iter().find(|&j| j >= skeleton.len()) {
            return Err(VaeError::Config(format!(
                "balance model: joint {j} of a {}-joint skeleton",
                skeleton.len()
            )));
        }
        let total: f32 = self.bodies.iter().map(|b| b.mass_kg).sum();
        let bad_mass = |m: f32| m.is_nan() || m < 0.0;
        if self.bodies.iter().any(|b| bad_mass(b.mass_kg)) || !(total > 0.0 && total.is_finite()) {
            return Err(VaeError::Config(
                "balance model: masses must be >= 0 with a positive total".into(),
            ));
        }
        if self.soles.is_empty() {
            return Err(VaeError::Config("balance model: no feet".into()));
        }
        if !(self.touch_m.is_finite() && self.touch_m > 0.0) {
            return Err(VaeError::Config(format!(
                "balance model: touch height {} m must be > 0",
                self.touch_m
            )));
        }
        Ok(())
    }
}

/// Standard gravity, m/s^2 (the physics crate's).
const G: f64 = 9.81;
/// Frames whose vertical acceleration leaves less than this share of gravity
/// pressing on the floor are unsupported (the physics crate's `MIN_SUPPORT_G`).
const MIN_SUPPORT_G: f64 = 0.1;
/// Horizontal directions the hull distance is taken over.
const DIRECTIONS: usize = 32;
/// Added (negatively) to the support function of corners off the floor: far
/// more than any distance in a clip, so they never hold the hull.
const OFF_FLOOR: f64 = 1e3;

/// A [`BalanceModel`] on tensors: the kinematics of its mass points then its
/// sole corners.
pub struct Balance {
    kinematics: FootKinematics,
    /// `(1, 1, M, 1)`: each body's share of the total mass.
    shares: Tensor,
    bodies: usize,
    corners: usize,
    touch_m: f64,
    /// `(2, K)`: unit horizontal directions (x, z).
    directions: Tensor,
}

impl Balance {
    pub fn new(model: &BalanceModel, skeleton: &Skeleton) -> Result<Self> {
        model.validate(skeleton)?;
        let mut points: Vec<(usize, [f32; 3])> =
            model.bodies.iter().map(|b| (b.joint, b.offset)).collect();
        for s in &model.soles {
            points.extend(s.corners.iter().map(|&c| (s.joint, c)));
        }
        let total: f32 = model.bodies.iter().map(|b| b.mass_kg).sum();
        let shares: Vec<f32> = model.bodies.iter().map(|b| b.mass_kg / total).collect();
        let m = shares.len();
        let (xs, zs): (Vec<f32>, Vec<f32>) = (0..DIRECTIONS)
            .map(|k| {
                let a = 2.0 * std::f32::consts::PI * k as f32 / DIRECTIONS as f32;
                (a.cos(), a.sin())
            })
            .unzip();
        let dev = &Device::Cpu;
        Ok(Balance {
            kinematics: FootKinematics::at_offsets(skeleton, &points)?,
            shares: Tensor::from_vec(shares, (1, 1, m, 1), dev)?,
            bodies: m,
            corners: 4 * model.soles.len(),
            touch_m: model.touch_m as f64,
            directions: Tensor::from_vec([xs, zs].concat(), (2, DIRECTIONS), dev)?,
        })
    }

    /// Per clip `(B,)` of raw frames `(B, T, 3 + 6 J)` at `fps` (valid where
    /// `mask` `(B, T)` is 1, padding at the end): the mean distance (m) of the
    /// ZMP outside the touching soles over its supported frames (0 with
    /// none), and the number of those frames.
    pub fn zmp_outside(&self, raw: &Tensor, mask: &Tensor, fps: f64) -> Result<(Tensor, Tensor)> {
        let (b, t, _) = raw.dims3()?;
        let dev = raw.device();
        if t < 3 {
            let zero = Tensor::zeros(b, DType::F32, dev)?;
            return Ok((zero.clone(), zero));
        }
        let n = t - 2;
        let pos = self.kinematics.positions(raw)?;
        let com = pos
            .narrow(2, 0, self.bodies)?
            .broadcast_mul(&self.shares)?
            .sum(2)?;
        let c = com.narrow(1, 1, n)?;
        let a = ((com.narrow(1, 2, n)? + com.narrow(1, 0, n)?)? - (&c * 2.0)?)?;
        let a = (a * (fps * fps))?;
        let pressing = (a.narrow(2, 1, 1)? + G)?;
        let enough = pressing
            .detach()
            .ge(MIN_SUPPORT_G * G)?
            .to_dtype(DType::F32)?;
        let lean = (c.narrow(2, 1, 1)? / pressing.clamp(MIN_SUPPORT_G * G, f64::INFINITY)?)?;
        let acc_xz = Tensor::cat(&[a.narrow(2, 0, 1)?, a.narrow(2, 2, 1)?], 2)?;
        let c_xz = Tensor::cat(&[c.narrow(2, 0, 1)?, c.narrow(2, 2, 1)?], 2)?;
        let zmp = (c_xz - acc_xz.broadcast_mul(&lean)?)?;
        // (B, n, C, 3): the sole corners at the middle frames.
        let all_corners = pos.narrow(2, self.bodies, self.corners)?;
        let floor = median_lowest(&all_corners, mask)?;
        let corners = all_corners.narrow(1, 1, n)?;
        let touching = corners
            .narrow(3, 1, 1)?
            .squeeze(3)?
            .detach()
            .broadcast_sub(&floor)?
            .le(self.touch_m)?
            .to_dtype(DType::F32)?;
        let corners_xz = Tensor::cat(&[corners.narrow(3, 0, 1)?, corners.narrow(3, 2, 1)?], 3)?;
        let k = DIRECTIONS;
        let reach = corners_xz
            .reshape((b * n * self.corners, 2))?
            .matmul(&self.directions)?
            .reshape((b, n, self.corners, k))?;
        let off = ((touching.clone() - 1.0)? * OFF_FLOOR)?.unsqueeze(3)?;
        let support = reach.broadcast_add(&off)?.max(2)?;
        let ahead = zmp
            .reshape((b * n, 2))?
            .matmul(&self.directions)?
            .reshape((b, n, k))?;
        let outside = (ahead - support)?.max(D::Minus1)?.relu()?;
        // Supported: a corner touches, the floor is pressed, all three frames valid.
        let valid = ((mask.narrow(1, 0, n)? * mask.narrow(1, 1, n)?)? * mask.narrow(1, 2, n)?)?;
        let supported = ((touching.max(2)? * enough.squeeze(2)?)? * valid)?;
        let frames = supported.sum(1)?;
        let mean = ((outside * &supported)?.sum(1)? / frames.clamp(1.0, f64::INFINITY)?)?;
        Ok((mean, frames))
    }
}

/// Per clip `(B, 1, 1)`, detached: the height of the lowest sole corner of
/// `(B, T, C, 3)` in its median valid frame (`mask` `(B, T)`). The
/// correction puts a clip on its floor so (`physics::reference`: the lower
/// foot touches in the median frame), whatever floor it was captured or
/// decoded on; this measure reads touching feet against the same floor.
fn median_lowest(corners: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let (b, t, _, _) = corners.dims4()?;
    let lowest = corners
        .narrow(3, 1, 1)?
        .squeeze(3)?
        .min(D::Minus1)?
        .detach()
        .to_vec2::<f32>()?;
    let valid = mask.to_vec2::<f32>()?;
    let floors: Vec<f32> = lowest
        .iter()
        .zip(&valid)
        .map(|(l, v)| {
            let mut h: Vec<f32> = (0..t).filter(|&i| v[i] > 0.5).map(|i| l[i]).collect();
            h.sort_by(f32::total_cmp);
            h.get(h.len() / 2).copied().unwrap_or(0.0)
        })
        .collect();
    Ok(Tensor::from_vec(floors, (b, 1, 1), corners.device())?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{FeatureConfig, motion_to_frames};
    use motion::glam::{DQuat, DVec3};
    use motion::{Joint, Motion};
    use std::sync::Arc;

    /// A root with a 1 kg mass 1 m up and one foot joint below it whose sole is
    /// a 0.2 x 0.1 m rectangle around the foot.
    fn stick() -> (Arc<Skeleton>, BalanceModel) {
        let skeleton = Arc::new(
            Skeleton::new(
                vec![
                    Joint::new("root", None, DVec3::ZERO),
                    Joint::new("foot", Some(0), DVec3::new(0.0, -1.0, 0.0)),
                ],
                1.0,
            )
            .unwrap(),
        );
        let model = BalanceModel {
            bodies: vec![MassPoint {
                joint: 0,
                offset: [0.0, 0.0, 0.0],
                mass_kg: 1.0,
            }],
            soles: vec![SoleCorners {
                joint: 1,
                corners: [
                    [-0.05, 0.0, -0.1],
                    [0.05, 0.0, -0.1],
                    [-0.05, 0.0, 0.1],
                    [0.05, 0.0, 0.1],
                ],
            }],
            touch_m: 0.02,
        };
        (skeleton, model)
    }

    /// The stick's frames: root at `root(t)`, the foot joint `lean` m to the
    /// side of it along x, its sole level.
    fn stick_frames(root: impl Fn(usize) -> DVec3, lean: f64, n: usize) -> Tensor {
        let (skeleton, _) = stick();
        let tilt = DQuat::from_rotation_z((lean / 1.0).asin());
        let rotations = (0..n).flat_map(|_| [tilt, tilt.inverse()]).collect();
        let m = Motion::new(skeleton, 30.0, (0..n).map(root).collect(), rotations).unwrap();
        let f = motion_to_frames(&m, &FeatureConfig::default());
        let dim = f.len() / n;
        Tensor::from_vec(f, (1, n, dim), &Device::Cpu).unwrap()
    }

    #[test]
    fn a_body_over_its_foot_balances_and_one_leaning_or_accelerating_does_not() {
        let (skeleton, model) = stick();
        let balance = Balance::new(&model, &skeleton).unwrap();
        let n = 6;
        let mask = Tensor::ones((1, n), DType::F32, &Device::Cpu).unwrap();
        let measure = |raw: &Tensor| {
            let (d, frames) = balance.zmp_outside(raw, &mask, 30.0).unwrap();
            (
                d.to_vec1::<f32>().unwrap()[0],
                frames.to_vec1::<f32>().unwrap()[0],
            )
        };
        // Standing straight: ZMP at the foot, every middle frame supported.
        let (d, frames) = measure(&stick_frames(|_| DVec3::new(0.0, 1.0, 0.0), 0.0, n));
        assert!(d.abs() < 1e-4, "{d}");
        assert_eq!(frames, (n - 2) as f32);
        // Leaning: the foot 0.3 m from under the mass (the features turn the
        // clip to face +z, so measure the distance, not its axis): 0.3 m less
        // the sole's half width or half length.
        let upright = (1.0f64 - 0.09).sqrt();
        let (d, frames_supported) =
            measure(&stick_frames(|_| DVec3::new(0.0, upright, 0.0), 0.3, n));
        assert!((0.24..=0.26).contains(&d), "{d}");
        assert_eq!(frames_supported, (n - 2) as f32);
        // Accelerating at 2 m/s^2 along the root path, the foot under the
        // mass: the ZMP trails by c_y a / g = 0.95 * 2 / 9.81.
        let dt = 1.0 / 30.0;
        let accelerating = stick_frames(|t| DVec3::new(0.0, 1.0, (t as f64 * dt).powi(2)), 0.0, n);
        let (d, _) = measure(&accelerating);
        let trail = 1.0 * 2.0 / G as f32;
        assert!(
            (d - (trail - 0.1)).abs() < 0.01 || (d - (trail - 0.05)).abs() < 0.01,
            "{d} vs {trail} less a half sole"
        );
        // Lifted 5 cm from frame 4 on: the floor is where the foot stands in
        // the median frame, so of the middle frames 1-4 the last is
        // unsupported.
        let hop = stick_frames(
            |t| DVec3::new(0.0, upright + if t >= 4 { 0.05 } else { 0.0 }, 0.0),
            0.3,
            n,
        );
        let (d, frames_supported) = measure(&hop);
        assert!((0.24..=0.26).contains(&d), "{d}");
        assert_eq!(frames_supported, 3.0);
        // Lifted throughout: the same floor, every middle frame supported.
        let (_, frames_supported) = measure(&stick_frames(
            |_| DVec3::new(0.0, upright + 0.05, 0.0),
            0.3,
            n,
        ));
        assert_eq!(frames_supported, (n - 2) as f32);
    }

    #[test]
    fn the_distance_moves_the_mass_back_over_the_foot() {
        let (skeleton, model) = stick();
        let balance = Balance::new(&model, &skeleton).unwrap();
        let n = 5;
        let upright = (1.0f64 - 0.09).sqrt();
        let raw = stick_frames(|_| DVec3::new(0.0, upright, 0.0), 0.3, n);
        let var = candle_core::Var::from_tensor(&raw).unwrap();
        let mask = Tensor::ones((1, n), DType::F32, &Device::Cpu).unwrap();
        let (d, _) = balance.zmp_outside(var.as_tensor(), &mask, 30.0).unwrap();
        let grads = d.sum_all().unwrap().backward().unwrap();
        let g = grads.get(&var).unwrap().to_vec3::<f32>().unwrap();
        // A small step against the gradient brings the body back over the
        // foot by what the gradient predicts (its norm times the step).
        let g = g.concat().concat();
        let norm = g.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!(norm > 0.1, "{norm}");
        let h = 1e-3;
        let step: Vec<f32> = raw
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()
            .iter()
            .zip(&g)
            .map(|(x, g)| x - h * g / norm)
            .collect();
        let stepped = Tensor::from_vec(step, raw.shape(), &Device::Cpu).unwrap();
        let before = d.to_vec1::<f32>().unwrap()[0];
        let after = balance.zmp_outside(&stepped, &mask, 30.0).unwrap().0;
        let after = after.to_vec1::<f32>().unwrap()[0];
        let predicted = h * norm;
        assert!(
            ((before - after) - predicted).abs() < 0.3 * predicted,
            "{before} -> {after}, predicted a drop of {predicted}"
        );
    }

    #[test]
    fn a_model_on_a_joint_the_skeleton_lacks_is_refused() {
        let (skeleton, mut model) = stick();
        model.soles[0].joint = 7;
        assert!(Balance::new(&model, &skeleton).is_err());
        let (skeleton, mut model) = stick();
        model.bodies[0].mass_kg = f32::NAN;
        assert!(Balance::new(&model, &skeleton).is_err());
    }
}
