//! Where the feet are, differentiably: forward kinematics of the foot chains on
//! candle tensors, and the foot terms of the loss.
//!
//! Why it exists: the VAE's features are a root position plus joint rotations,
//! and a loss on those alone lets the root slide while the legs step in place:
//! decoded samples skated 3-16x more than the captured clips (eval README,
//! session 4). Comparing where the feet land, how fast they move, and
//! penalising planted feet that slide or sink ties the root path to the legs.
//!
//! The foot points are the ones the foot skating metric watches
//! (`motion::metrics::skeleton_foot_points`): joints named foot / ankle / toe /
//! heel and their end sites. Only the joints on the paths from the root to them
//! are transformed (11 of HDM05's 31), so the cost is a few batched 3x3 products
//! per frame.

use candle_core::{D, Device, Tensor};
use motion::Skeleton;
use serde::{Deserialize, Serialize};

use crate::error::{Result, VaeError};
use crate::loss::{check_weights, masked_frame_mean, six_d_matrices};
use crate::mat3;

/// Weights and thresholds of the foot terms (all 0: the plain VAE loss).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FootLoss {
    /// On the mean squared distance (m^2) between reconstructed and captured
    /// foot points.
    pub position: f64,
    /// On the mean squared difference of foot point velocities ((m/s)^2).
    pub velocity: f64,
    /// On the contact-weighted mean squared horizontal foot speed ((m/s)^2) of
    /// clips decoded from codes mixed between training clips, which have no
    /// captured counterpart; what sampling near samples decodes.
    pub skating: f64,
    /// On the mean squared depth (m^2) of foot points below the ground (y = 0),
    /// reconstructions and mixed codes alike.
    pub floor: f64,
    /// A foot point lower than this (m) counts as touching for the skating term
    /// (smoothly: a logistic step 1 cm wide).
    pub contact_height_m: f64,
}

impl Default for FootLoss {
    fn default() -> Self {
        FootLoss {
            position: 1.0,
            velocity: 0.01,
            skating: 0.1,
            floor: 10.0,
            contact_height_m: 0.05,
        }
    }
}

impl FootLoss {
    /// No foot terms (the loss of sessions before 10; an ablation).
    pub fn off() -> Self {
        FootLoss {
            position: 0.0,
            velocity: 0.0,
            skating: 0.0,
            floor: 0.0,
            ..FootLoss::default()
        }
    }

    pub fn is_off(&self) -> bool {
        self.position == 0.0 && self.velocity == 0.0 && self.skating == 0.0 && self.floor == 0.0
    }

    pub fn validate(&self) -> Result<()> {
        check_weights(
            "foot loss weight",
            &[
                ("position", self.position),
                ("velocity", self.velocity),
                ("skating", self.skating),
                ("floor", self.floor),
            ],
        )?;
        if !(self.contact_height_m.is_finite() && self.contact_height_m > 0.0) {
            return Err(VaeError::Config(format!(
                "foot contact height {} m must be > 0",
                self.contact_height_m
            )));
        }
        Ok(())
    }
}

/// One joint on a path from the root to a foot point.
struct ChainJoint {
    /// Skeleton index.
    joint: usize,
    /// Index into the chain of the parent, `None` for the root.
    parent: Option<usize>,
    /// Offset from the parent in the parent's frame, metres.
    offset: [f32; 3],
}

/// Forward kinematics of the foot points of one skeleton.
pub struct FootKinematics {
    joints: usize,
    chain: Vec<ChainJoint>,
    /// Chain index and end-site offset (`None`: the joint's own
    /// position).
    points: Vec<(usize, Option<[f32; 3]>)>,
    /// Columns of the chain joints' 6D rotations in a raw frame, chain order
    /// (`u32`): one `index_select` instead of a slice per joint of all 31,
    /// whose backward passes each padded their gradient to the whole frame.
    columns: Tensor,
    /// One per foot (a foot joint whose parent is not one): see [`Sole`].
    soles: Vec<Sole>,
}

/// The points of one foot, as indices into [`FootKinematics::positions`]'
/// point axis.
///
/// Why: the correction's soles criterion judges the simulated foot box,
/// which is fixed to the ankle joint's frame; its heel and toe are level
/// when the ankle's pitch is the stance pitch. The drop from the ankle to
/// the point fixed in the same frame farthest from it (HDM05: the toes
/// joint; a toe bend does not move it) measures that pitch.
#[derive(Debug, Clone, PartialEq)]
pub struct Sole {
    /// Every point of this foot (ankle, toes, end sites): `u32` indices for
    /// the lowest point of the foot.
    pub points: Vec<u32>,
    /// The ankle joint's own position.
    pub ankle: usize,
    /// The point fixed in the ankle's frame farthest from it.
    pub toe: usize,
}

/// The feet of `points` (`skeleton_foot_points`): each foot joint whose
/// parent is not a foot joint, with the points below it.
fn soles_of(skeleton: &Skeleton, points: &[(usize, Option<motion::glam::DVec3>)]) -> Vec<Sole> {
    let is_foot = |j: usize| points.iter().any(|&(p, _)| p == j);
    let top = |mut j: usize| {
        while let Some(p) = skeleton.parent(j).filter(|&p| is_foot(p)) {
            j = p;
        }
        j
    };
    let mut soles = Vec::new();
    for (ankle, &(a, site)) in points.iter().enumerate() {
        if site.is_some() || top(a) != a {
            continue;
        }
        // Fixed in the ankle's frame: its end site and its children's origins.
        let fixed = points
            .iter()
            .enumerate()
            .filter_map(|(i, &(j, e))| match e {
                Some(e) if j == a => Some((i, e.length())),
                None if skeleton.parent(j) == Some(a) => {
                    Some((i, skeleton.joint(j).offset.length()))
                }
                _ => None,
            });
        let Some((toe, _)) = fixed.max_by(|x, y| x.1.total_cmp(&y.1)) else {
            continue;
        };
        let mine = points.iter().enumerate().filter(|(_, (j, _))| top(*j) == a);
        soles.push(Sole {
            points: mine.map(|(i, _)| i as u32).collect(),
            ankle,
            toe,
        });
    }
    soles
}

/// The joints marked `on_chain`, each with its parent's chain index, and
/// each skeleton joint's chain index (`usize::MAX` off the chain). Joints
/// are in topological order: a parent is on the chain before its child.
fn chain_of(skeleton: &Skeleton, on_chain: &[bool]) -> (Vec<ChainJoint>, Vec<usize>) {
    let mut index = vec![usize::MAX; skeleton.len()];
    let mut chain = Vec::new();
    for j in (0..skeleton.len()).filter(|&j| on_chain[j]) {
        index[j] = chain.len();
        chain.push(ChainJoint {
            joint: j,
            parent: skeleton.parent(j).map(|p| index[p]),
            offset: row(skeleton.joint(j).offset),
        });
    }
    (chain, index)
}

/// The columns of the chain joints' 6D rotations in a raw frame (`u32`).
fn columns_of(chain: &[ChainJoint]) -> Result<Tensor> {
    let columns: Vec<u32> = chain
        .iter()
        .flat_map(|c| (0..6).map(move |k| (3 + 6 * c.joint + k) as u32))
        .collect();
    Ok(Tensor::from_vec(columns, 6 * chain.len(), &Device::Cpu)?)
}

/// A constant offset as a row vector.
fn row(v: motion::glam::DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

impl FootKinematics {
    /// `None` when the skeleton has no foot points.
    pub fn new(skeleton: &Skeleton) -> Result<Option<Self>> {
        let feet = motion::metrics::skeleton_foot_points(skeleton);
        if feet.is_empty() {
            return Ok(None);
        }
        let mut on_chain = vec![false; skeleton.len()];
        for &(j, _) in &feet {
            on_chain[j] = true;
            for a in skeleton.ancestors(j) {
                on_chain[a] = true;
            }
        }
        let (chain, index) = chain_of(skeleton, &on_chain);
        let points = feet.iter().map(|&(j, e)| (index[j], e.map(row))).collect();
        let soles = soles_of(skeleton, &feet);
        Ok(Some(FootKinematics {
            joints: skeleton.len(),
            columns: columns_of(&chain)?,
            chain,
            points,
            soles,
        }))
    }

    /// Forward kinematics of points fixed in joints' frames: `(joint, offset
    /// in its frame, m)` each; what [`crate::balance`] places the simulated
    /// character's body masses and foot soles with.
    pub fn at_offsets(skeleton: &Skeleton, points: &[(usize, [f32; 3])]) -> Result<Self> {
        if let Some(&(j, _)) = points.iter().find(|(j, _)| *j >= skeleton.len()) {
            return Err(VaeError::Config(format!(
                "a point on joint {j} of a {}-joint skeleton",
                skeleton.len()
            )));
        }
        let mut on_chain = vec![false; skeleton.len()];
        for &(j, _) in points {
            on_chain[j] = true;
            for a in skeleton.ancestors(j) {
                on_chain[a] = true;
            }
        }
        let (chain, index) = chain_of(skeleton, &on_chain);
        Ok(FootKinematics {
            joints: skeleton.len(),
            points: points.iter().map(|&(j, o)| (index[j], Some(o))).collect(),
            columns: columns_of(&chain)?,
            chain,
            soles: Vec::new(),
        })
    }

    /// Forward kinematics of every joint's own position (no end sites): what
    /// the pose speed metric (`motion::metrics::Plausibility::pose_speed_m_s`)
    /// watches.
    pub fn all_joints(skeleton: &Skeleton) -> Result<Self> {
        let (chain, _) = chain_of(skeleton, &vec![true; skeleton.len()]);
        Ok(FootKinematics {
            joints: skeleton.len(),
            // Every joint is on the chain: its chain index is its own.
            points: (0..skeleton.len()).map(|c| (c, None)).collect(),
            columns: columns_of(&chain)?,
            chain,
            soles: Vec::new(),
        })
    }

    pub fn points(&self) -> usize {
        self.points.len()
    }

    /// The feet, for the sole terms (empty for [`FootKinematics::all_joints`]).
    pub fn soles(&self) -> &[Sole] {
        &self.soles
    }

    /// World positions `(B, T, P, 3)` of the foot points of raw frames
    /// `(B, T, 3 + 6 J)` (root position, then 6D rotations).
    pub fn positions(&self, raw: &Tensor) -> Result<Tensor> {
        let (b, t, f) = raw.dims3()?;
        if f != 3 + 6 * self.joints {
            return Err(VaeError::Data(format!(
                "frames of {f} numbers for a {}-joint skeleton",
                self.joints
            )));
        }
        let n = b * t;
        // Rows of each joint's 3x3 block are the columns of its rotation, so the
        // block is R^T: globals compose as M_child = M_local * M_parent and a
        // parent-frame offset o lands at o^T * M_parent.
        let k = self.chain.len();
        let six = raw.index_select(&self.columns, 2)?.reshape((b, t, k, 6))?;
        let local = six_d_matrices(&six)?.reshape((n, k, 3, 3))?;
        let root = raw.narrow(2, 0, 3)?.reshape((n, 1, 3))?;
        let mut global: Vec<Tensor> = Vec::with_capacity(k);
        let mut position: Vec<Tensor> = Vec::with_capacity(k);
        for (i, c) in self.chain.iter().enumerate() {
            let m = local.narrow(1, i, 1)?.squeeze(1)?;
            match c.parent {
                None => {
                    global.push(m);
                    position.push(root.clone());
                }
                Some(p) => {
                    position.push((&position[p] + mat3::row_times(c.offset, &global[p])?)?);
                    global.push(mat3::mul(&m, &global[p])?);
                }
            }
        }
        let mut out = Vec::with_capacity(self.points.len());
        for (c, site) in &self.points {
            out.push(match site {
                None => position[*c].clone(),
                Some(e) => (&position[*c] + mat3::row_times(*e, &global[*c])?)?,
            });
        }
        Ok(Tensor::cat(&out, 1)?.reshape((b, t, self.points.len(), 3))?)
    }
}

/// Pose speed of each clip `(B,)`, m/s: the mean over valid steps and points
/// of the speed of points `(B, T, P, 3)` relative to the root `(B, T, 3)` (how
/// fast the body moves, not how fast it travels). A still pose has ~0 (a
/// small epsilon keeps the gradient of a norm at 0 finite).
pub fn pose_speed(pos: &Tensor, root: &Tensor, mask: &Tensor, fps: f64) -> Result<Tensor> {
    let (b, t, _, _) = pos.dims4()?;
    if t < 2 {
        return Ok(Tensor::zeros(b, pos.dtype(), pos.device())?);
    }
    let rel = pos.broadcast_sub(&root.unsqueeze(2)?)?;
    let speed = (velocities(&rel, fps)?.sqr()?.sum(D::Minus1)? + 1e-8)?
        .sqrt()?
        .mean(D::Minus1)?;
    let m = step_mask(mask)?;
    let n = m.sum(1)?.clamp(1.0, f64::INFINITY)?;
    Ok(((speed * &m)?.sum(1)? / n)?)
}

/// Per clip `(B, S)`, the mean horizontal root speed (m/s) in each of `S`
/// equal parts of its valid steps (`lengths`: valid frames per clip): how
/// the clip travels from its start to its end. A clip that stops halfway
/// has ~0 in its last parts.
pub fn travel_profile(root: &Tensor, lengths: &[usize], fps: f64, parts: usize) -> Result<Tensor> {
    let (b, t, _) = root.dims3()?;
    if t < 2 || parts == 0 {
        return Ok(Tensor::zeros((b, parts), root.dtype(), root.device())?);
    }
    let v = velocities(root, fps)?;
    let speed = ((v.narrow(2, 0, 1)?.sqr()? + v.narrow(2, 2, 1)?.sqr()?)? + 1e-8)?.sqrt()?;
    // (B, T - 1, S): step i of a clip of n steps is in part floor(S i / n),
    // weighted 1 / (the steps in that part), so each column averages a part.
    let mut w = vec![0f32; b * (t - 1) * parts];
    for (k, &len) in lengths.iter().enumerate().take(b) {
        let steps = len.min(t).saturating_sub(1);
        let part = |i: usize| parts * i / steps.max(1);
        let mut count = vec![0usize; parts];
        (0..steps).for_each(|i| count[part(i)] += 1);
        for i in 0..steps {
            let p = part(i);
            w[(k * (t - 1) + i) * parts + p] = 1.0 / count[p] as f32;
        }
    }
    let w = Tensor::from_vec(w, (b, t - 1, parts), root.device())?;
    // (B, 1, T - 1) x (B, T - 1, S).
    Ok(speed
        .transpose(1, 2)?
        .contiguous()?
        .matmul(&w)?
        .squeeze(1)?)
}

/// Mean over valid frames of the squared distance between foot points `(B, T, P, 3)`.
pub fn position_error(pred: &Tensor, target: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let d = (pred - target)?.sqr()?.sum(D::Minus1)?.mean(D::Minus1)?;
    masked_frame_mean(&d, mask)
}

/// Frame-to-frame velocities `(B, T - 1, P, 3)` in m/s.
fn velocities(pos: &Tensor, fps: f64) -> Result<Tensor> {
    let t = pos.dim(1)?;
    Ok(((pos.narrow(1, 1, t - 1)? - pos.narrow(1, 0, t - 1)?)? * fps)?)
}

/// Steps `t -> t+1` with both frames valid (padding is at the end).
fn step_mask(mask: &Tensor) -> Result<Tensor> {
    let t = mask.dim(1)?;
    Ok(mask.narrow(1, 1, t - 1)?)
}

/// Mean squared difference of foot velocities ((m/s)^2) over valid steps.
pub fn velocity_error(pred: &Tensor, target: &Tensor, mask: &Tensor, fps: f64) -> Result<Tensor> {
    if pred.dim(1)? < 2 {
        return Ok(Tensor::zeros((), pred.dtype(), pred.device())?);
    }
    let d = (velocities(pred, fps)? - velocities(target, fps)?)?
        .sqr()?
        .sum(D::Minus1)?
        .mean(D::Minus1)?;
    masked_frame_mean(&d, &step_mask(mask)?)
}

/// How far below `height_m` heights are, as a logistic step 1 cm wide: ~1
/// well below, ~0 well above. What every foot term calls touching.
fn below(heights: &Tensor, height_m: f64) -> Result<Tensor> {
    Ok(candle_nn::ops::sigmoid(&((height_m - heights)? * 100.0)?)?)
}

/// The higher of each pair of consecutive frames `(B, T - 1, ...)` of heights
/// `(B, T, ...)`: a point touches over a step only if it does in both frames.
fn step_high(heights: &Tensor) -> Result<Tensor> {
    let t = heights.dim(1)?;
    Ok(heights
        .narrow(1, 1, t - 1)?
        .maximum(&heights.narrow(1, 0, t - 1)?)?)
}

/// Contact-weighted mean squared horizontal speed ((m/s)^2) of foot points
/// `(B, T, P, 3)`: each step weighs `sigmoid((h - y) / 1 cm)` with `y` the
/// point's higher height over the step, taken as a constant (the term slows a
/// planted foot; it does not lift it off the ground to escape).
pub fn skating(pos: &Tensor, mask: &Tensor, fps: f64, contact_height_m: f64) -> Result<Tensor> {
    let t = pos.dim(1)?;
    if t < 2 {
        return Ok(Tensor::zeros((), pos.dtype(), pos.device())?);
    }
    let v = velocities(pos, fps)?;
    let horizontal = (v.narrow(3, 0, 1)?.sqr()? + v.narrow(3, 2, 1)?.sqr()?)?.squeeze(3)?;
    let y = pos.narrow(3, 1, 1)?.squeeze(3)?.detach();
    let weight = below(&step_high(&y)?, contact_height_m)?;
    let per_step = (weight * horizontal)?.mean(D::Minus1)?;
    masked_frame_mean(&per_step, &step_mask(mask)?)
}

/// Per clip `(B,)`, the share of its valid frames whose lowest foot point (of
/// `(B, T, P, 3)`) is below `height_m`, smoothly (a logistic step 1 cm wide):
/// how much of the clip stands on the ground rather than hovering.
pub fn ground_contact(pos: &Tensor, mask: &Tensor, height_m: f64) -> Result<Tensor> {
    let lowest = pos.narrow(3, 1, 1)?.squeeze(3)?.min(D::Minus1)?;
    let touching = below(&lowest, height_m)?;
    let n = mask.sum(1)?.clamp(1.0, f64::INFINITY)?;
    Ok(((touching * mask)?.sum(1)? / n)?)
}

/// Per foot `(B, T - 1, F)` for each valid step `t -> t+1`, how planted the
/// foot is, detached: its lowest point below `contact_height_m` in both
/// frames (a logistic step 1 cm wide) and its fastest point slower than
/// `PLANTED_SPEED_M_S` (a logistic step 5 cm/s wide); the correction's
/// criterion calls a foot planted when it touches and heel and toe are
/// slower than 0.2 m/s; 0 on steps the mask leaves out. And the drop from
/// ankle to toe `(B, T - 1, F)` at frame `t + 1`, m.
fn planted_drop(
    pos: &Tensor,
    mask: &Tensor,
    soles: &[Sole],
    fps: f64,
    contact_height_m: f64,
) -> Result<(Tensor, Tensor)> {
    let t = pos.dim(1)?;
    let dev = pos.device();
    let y = pos.narrow(3, 1, 1)?.squeeze(3)?.contiguous()?;
    let y_const = y.detach();
    let speed = (velocities(&pos.detach(), fps)?.sqr()?.sum(D::Minus1)? + 1e-12)?
        .sqrt()?
        .contiguous()?;
    let (mut weight, mut drop) = (Vec::new(), Vec::new());
    for s in soles {
        let idx = Tensor::new(s.points.as_slice(), dev)?;
        let low = y_const.index_select(&idx, 2)?.min(D::Minus1)?;
        let touching = below(&step_high(&low)?, contact_height_m)?;
        let fastest = speed.index_select(&idx, 2)?.max(D::Minus1)?;
        let slow = candle_nn::ops::sigmoid(&((PLANTED_SPEED_M_S - fastest)? * 20.0)?)?;
        weight.push((touching * slow)?);
        let d = (y.narrow(2, s.ankle, 1)? - y.narrow(2, s.toe, 1)?)?.squeeze(2)?;
        drop.push(d.narrow(1, 1, t - 1)?);
    }
    let weight = Tensor::stack(&weight, 2)?.broadcast_mul(&step_mask(mask)?.unsqueeze(2)?)?;
    Ok((weight, Tensor::stack(&drop, 2)?))
}

/// A foot faster than this (its fastest point, 3D) is not planted, m/s.
const PLANTED_SPEED_M_S: f64 = 0.2;

/// Per foot `(F,)`, the mean ankle-to-toe drop (m) over the planted steps of
/// clips `(B, T, P, 3)`: how the skeleton stands on its soles in the
/// training clips; what [`sole_level`] holds decodes to. A foot never
/// planted gets 0 weight and the mean of nothing, 0.
pub fn stance_drop(
    pos: &Tensor,
    mask: &Tensor,
    soles: &[Sole],
    fps: f64,
    contact_height_m: f64,
) -> Result<Tensor> {
    if pos.dim(1)? < 2 || soles.is_empty() {
        return Ok(Tensor::zeros(soles.len(), pos.dtype(), pos.device())?);
    }
    let (w, d) = planted_drop(pos, mask, soles, fps, contact_height_m)?;
    let total = w.sum((0, 1))?;
    Ok(((w * d)?.sum((0, 1))? / total.clamp(1e-6, f64::INFINITY)?)?)
}

/// Planted-weighted mean squared difference between each foot's ankle-to-toe
/// drop and the stance drop `(F,)`, in units of `tolerance_m` squared (a
/// foot pitched by the tolerance costs 1): asks a foot that stands to stand
/// on its sole, not on its heel or its toe. 0 with no planted step.
pub fn sole_level(
    pos: &Tensor,
    mask: &Tensor,
    soles: &[Sole],
    stance: &Tensor,
    fps: f64,
    contact_height_m: f64,
    tolerance_m: f64,
) -> Result<Tensor> {
    if pos.dim(1)? < 2 || soles.is_empty() {
        return Ok(Tensor::zeros((), pos.dtype(), pos.device())?);
    }
    let (w, d) = planted_drop(pos, mask, soles, fps, contact_height_m)?;
    let e = (d.broadcast_sub(stance)? / tolerance_m)?.sqr()?;
    // A thousandth of a planted step: no planted step gives ~0, not 0 / 0.
    let total = w.sum_all()?.clamp(1e-3, f64::INFINITY)?;
    Ok(((w * e)?.sum_all()? / total)?)
}

/// Mean squared depth (m^2) of foot points below y = 0.
pub fn floor(pos: &Tensor, mask: &Tensor) -> Result<Tensor> {
    let depth = pos.narrow(3, 1, 1)?.squeeze(3)?.neg()?.relu()?;
    masked_frame_mean(&depth.sqr()?.mean(D::Minus1)?, mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{FeatureConfig, motion_to_frames};
    use candle_core::DType;
    use motion::glam::{DQuat, DVec3};
    use motion::{Joint, Motion};
    use std::sync::Arc;

    /// A root, a thigh, a shin and a foot with a toe end site.
    fn leg() -> Arc<Skeleton> {
        let joint = |name: &str, parent, offset, end_site| Joint {
            name: name.into(),
            parent,
            offset,
            channels: vec![],
            end_site,
            limits: None,
        };
        Arc::new(
            Skeleton::new(
                vec![
                    joint("root", None, DVec3::ZERO, None),
                    joint("thigh", Some(0), DVec3::new(0.1, -0.1, 0.0), None),
                    joint("shin", Some(1), DVec3::new(0.0, -0.4, 0.0), None),
                    joint(
                        "foot",
                        Some(2),
                        DVec3::new(0.0, -0.4, 0.0),
                        Some(DVec3::new(0.0, -0.05, 0.15)),
                    ),
                    joint("arm", Some(0), DVec3::new(0.0, 0.5, 0.0), None),
                ],
                1.0,
            )
            .unwrap(),
        )
    }

    fn random_motion(seed: u64) -> Motion {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let s = leg();
        let frames = 4;
        let mut q = || {
            DQuat::from_euler(
                motion::glam::EulerRot::YXZ,
                rng.random_range(-2.0..2.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let rotations: Vec<DQuat> = (0..frames * s.len()).map(|_| q()).collect();
        let root = (0..frames)
            .map(|t| DVec3::new(0.1 * t as f64, 0.9, 0.05 * t as f64))
            .collect();
        Motion::new(s, 30.0, root, rotations).unwrap()
    }

    #[test]
    fn foot_positions_match_the_skeletons_forward_kinematics() {
        for seed in 0..5 {
            let m = random_motion(seed);
            // The features of the clip in its canonical placement, and the clip
            // rebuilt from them: both describe the same world positions.
            let config = FeatureConfig::default();
            let frames = motion_to_frames(&m, &config);
            let canonical = crate::features::frames_to_motion(m.skeleton(), 30.0, &frames).unwrap();
            let fk = FootKinematics::new(m.skeleton()).unwrap().unwrap();
            assert_eq!(fk.points(), 2, "the foot joint and its toe end site");
            let dim = frames.len() / m.frames();
            let raw = Tensor::from_vec(frames, (1, m.frames(), dim), &Device::Cpu).unwrap();
            let got = fk
                .positions(&raw)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap();
            for t in 0..m.frames() {
                let x = canonical.world_transforms(t);
                let foot = x[3].translation;
                let toe = x[3].translation + x[3].rotation * DVec3::new(0.0, -0.05, 0.15);
                for (k, p) in [foot, toe].iter().enumerate() {
                    for (a, e) in got[(t * 2 + k) * 3..(t * 2 + k) * 3 + 3]
                        .iter()
                        .zip(p.to_array())
                    {
                        assert!(
                            (*a as f64 - e).abs() < 1e-4,
                            "seed {seed} t {t}: {a} vs {e}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn every_joint_matches_forward_kinematics_and_a_still_pose_has_no_pose_speed() {
        let m = random_motion(3);
        let config = FeatureConfig::default();
        let frames = motion_to_frames(&m, &config);
        let canonical = crate::features::frames_to_motion(m.skeleton(), 30.0, &frames).unwrap();
        let jk = FootKinematics::all_joints(m.skeleton()).unwrap();
        assert_eq!(jk.points(), m.skeleton().len());
        let dim = frames.len() / m.frames();
        let raw = Tensor::from_vec(frames.clone(), (1, m.frames(), dim), &Device::Cpu).unwrap();
        let pos = jk.positions(&raw).unwrap();
        let got = pos.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let joints = m.skeleton().len();
        for t in 0..m.frames() {
            let x = canonical.world_transforms(t);
            for j in 0..joints {
                for (a, e) in got[(t * joints + j) * 3..(t * joints + j) * 3 + 3]
                    .iter()
                    .zip(x[j].translation.to_array())
                {
                    assert!((*a as f64 - e).abs() < 1e-4, "t {t} joint {j}: {a} vs {e}");
                }
            }
        }
        let mask = Tensor::ones((1, m.frames()), DType::F32, &Device::Cpu).unwrap();
        let root = raw.narrow(2, 0, 3).unwrap();
        let moving = pose_speed(&pos, &root, &mask, 30.0)
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()[0];
        assert!(moving > 1.0, "random poses 1/30 s apart: {moving} m/s");
        // Every frame the first pose, the root still travelling: no pose speed.
        let first = &frames[..dim];
        let still: Vec<f32> = (0..m.frames())
            .flat_map(|t| {
                let mut f = first.to_vec();
                f[0] += 0.1 * t as f32;
                f
            })
            .collect();
        let still = Tensor::from_vec(still, (1, m.frames(), dim), &Device::Cpu).unwrap();
        let p = pose_speed(
            &jk.positions(&still).unwrap(),
            &still.narrow(2, 0, 3).unwrap(),
            &mask,
            30.0,
        )
        .unwrap()
        .to_vec1::<f32>()
        .unwrap()[0];
        assert!(p < 1e-3, "{p}");
    }

    #[test]
    fn skating_counts_low_sliding_points_only() {
        let dev = &Device::Cpu;
        // One clip, three frames, two points: a low point sliding 1 cm per frame
        // in x, a high point sliding the same.
        let pos: Vec<f32> = (0..3)
            .flat_map(|t| {
                let x = 0.01 * t as f32;
                [x, 0.0, 0.0, x, 0.5, 0.0]
            })
            .collect();
        let pos = Tensor::from_vec(pos, (1, 3, 2, 3), dev).unwrap();
        let mask = Tensor::ones((1, 3), candle_core::DType::F32, dev).unwrap();
        let s = skating(&pos, &mask, 30.0, 0.05)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        // Low point: speed 0.3 m/s, weight ~1; high point weight ~0; mean over 2 points.
        assert!((s - 0.09 / 2.0).abs() < 1e-3, "{s}");
        let f = floor(&(pos - 0.1).unwrap(), &mask)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!((f - 0.01 / 2.0).abs() < 1e-6, "{f}");
    }

    #[test]
    fn ground_contact_is_the_share_of_valid_frames_with_a_foot_down() {
        let dev = &Device::Cpu;
        // Two clips, four frames, two foot points. Clip 0: one point on the
        // ground in frames 0-1, both 30 cm up in 2-3. Clip 1: the second
        // point down throughout, but only 2 frames valid.
        let frame = |a: f32, b: f32| [0.0, a, 0.0, 0.0, b, 0.0];
        let pos: Vec<f32> = [
            frame(0.0, 0.3),
            frame(0.0, 0.3),
            frame(0.3, 0.3),
            frame(0.3, 0.3),
            frame(0.3, 0.0),
            frame(0.3, 0.0),
            frame(0.3, 0.3),
            frame(0.3, 0.3),
        ]
        .concat();
        let pos = Tensor::from_vec(pos, (2, 4, 2, 3), dev).unwrap();
        let mask = Tensor::from_vec(vec![1f32, 1., 1., 1., 1., 1., 0., 0.], (2, 4), dev).unwrap();
        let share = ground_contact(&pos, &mask, 0.05)
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert!((share[0] - 0.5).abs() < 0.01, "{share:?}");
        assert!((share[1] - 1.0).abs() < 0.01, "{share:?}");
    }

    #[test]
    fn each_foot_pairs_its_ankle_with_the_farthest_point_fixed_to_it() {
        // The leg: one foot joint with an end site, which is its toe.
        let fk = FootKinematics::new(&leg()).unwrap().unwrap();
        assert_eq!(
            fk.soles(),
            &[Sole {
                points: vec![0, 1],
                ankle: 0,
                toe: 1
            }]
        );
        // HDM05: lfoot and rfoot, each with its toes joint (fixed in the
        // foot's frame) rather than the toes' end site (which a toe bend moves).
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data");
        let path = dir.join("HDM_bd.asf");
        let asf = motion::asf::parse(&std::fs::read(&path).unwrap(), &path).unwrap();
        let skeleton = asf.skeleton().clone();
        let points = motion::metrics::skeleton_foot_points(&skeleton);
        let fk = FootKinematics::new(&skeleton).unwrap().unwrap();
        let named = |i: usize| {
            let (j, site) = points[i];
            (skeleton.joint(j).name.clone(), site.is_some())
        };
        let feet: Vec<_> = fk
            .soles()
            .iter()
            .map(|s| (named(s.ankle), named(s.toe), s.points.len()))
            .collect();
        assert_eq!(
            feet,
            [
                (("lfoot".into(), false), ("ltoes".into(), false), 3),
                (("rfoot".into(), false), ("rtoes".into(), false), 3),
            ]
        );
    }

    #[test]
    fn sole_level_weighs_planted_steps_only() {
        let dev = &Device::Cpu;
        let sole = [Sole {
            points: vec![0, 1],
            ankle: 0,
            toe: 1,
        }];
        // One foot: ankle at `a` m, toe at `b` m, still unless `dx` per frame.
        let clip = |frames: &[(f32, f32, f32)]| {
            let mut x = 0.0;
            let mut v = Vec::new();
            for &(a, b, dx) in frames {
                x += dx;
                v.extend([x, a, 0.0, x + 0.15, b, 0.0]);
            }
            Tensor::from_vec(v, (1, frames.len(), 2, 3), dev).unwrap()
        };
        let mask = Tensor::ones((1, 4), candle_core::DType::F32, dev).unwrap();
        let standing = clip(&[(0.08, 0.0, 0.0); 4]);
        let stance = stance_drop(&standing, &mask, &sole, 120.0, 0.05).unwrap();
        let stance_v = stance.to_vec1::<f32>().unwrap();
        assert!((stance_v[0] - 0.08).abs() < 1e-4, "{stance_v:?}");
        let level = |pos: &Tensor| {
            sole_level(pos, &mask, &sole, &stance, 120.0, 0.05, 0.02)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
        };
        assert!(level(&standing) < 1e-6);
        // Toe 2 cm higher than standing: one tolerance off in every planted
        // step; 4 cm: four.
        assert!((level(&clip(&[(0.07, 0.01, 0.0); 4])) - 1.0).abs() < 1e-3);
        assert!((level(&clip(&[(0.06, 0.02, 0.0); 4])) - 4.0).abs() < 1e-3);
        // The same pitch in the air, or sliding at 1.2 m/s, is not standing.
        assert!(level(&clip(&[(0.37, 0.31, 0.0); 4])) < 1e-3);
        assert!(level(&clip(&[(0.07, 0.01, 0.01); 4])) < 1e-3);
    }

    #[test]
    fn travel_profile_averages_the_root_speed_over_parts_of_each_clip() {
        let dev = &Device::Cpu;
        // Clip 0: 9 frames at 10 fps, 0.1 m per step in x for 4 steps, then
        // still. Clip 1: 5 valid frames moving 0.2 m per step in z.
        let mut v = Vec::new();
        for i in 0..9 {
            v.extend([0.1 * (i.min(4)) as f32, 1.0, 0.0]);
        }
        for i in 0..9 {
            v.extend([0.0, 1.0, 0.2 * (i.min(4)) as f32]);
        }
        let root = Tensor::from_vec(v, (2, 9, 3), dev).unwrap();
        let p = travel_profile(&root, &[9, 5], 10.0, 2)
            .unwrap()
            .to_vec2::<f32>()
            .unwrap();
        assert!(
            (p[0][0] - 1.0).abs() < 1e-3 && p[0][1].abs() < 1e-3,
            "{p:?}"
        );
        assert!(
            (p[1][0] - 2.0).abs() < 1e-3 && (p[1][1] - 2.0).abs() < 1e-3,
            "{p:?}"
        );
    }
}
