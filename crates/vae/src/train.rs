//! Training one VAE on the clips of one action class.
//!
//! Each iteration: encode a batch, draw z with the reparameterisation trick (noise
//! from a seeded ChaCha RNG, so runs are reproducible), decode it together with
//! as many codes mixed between two clips of the batch (when the foot terms are
//! on), and step the generator (encoder + decoder) on reconstruction +
//! smoothness + KL + the foot terms (`feet`: foot position and velocity of the
//! reconstructions, skating of the mixed decodes, floor for both) (+ the
//! adversarial hinge terms) (+ the mixed-code terms: the pose speed of each
//! mixed decode against its two parents', its share of frames with a foot on
//! the ground against theirs, and adversarial terms on the mixed decodes).
//! With adversarial training the two discriminators then take one step on
//! real clips vs the (detached) reconstructions (and mixed decodes),
//! all in one batch. With Adam the rate follows a cosine down to `cosine_to`
//! of itself.

use std::time::Instant;

use candle_core::Tensor;
use motion::Motion;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::balance::{Balance, BalanceModel};
use crate::data::{Batch, Dataset};
use crate::error::{Result, VaeError};
use crate::features::FeatureConfig;
use crate::feet::{self, FootKinematics, FootLoss};
use crate::latent::{LatentStats, NearConfig};
use crate::loss::{self, Denorm, LossWeights};
use crate::model::{DISCRIMINATORS, GENERATOR, Vae, VaeConfig};
use crate::trained::{ModelMeta, TrainedVae, TrainingSummary};
use nn::{Optimizer, OptimizerConfig};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub model: VaeConfig,
    pub features: FeatureConfig,
    /// Used for the generator and (a fresh copy) for the discriminators.
    pub optimizer: OptimizerConfig,
    /// With Adam: the rate follows a cosine from the configured rate down to
    /// this fraction of it at the last iteration (`None`: constant). Ignored
    /// with SGD, which has its own halving schedule.
    pub cosine_to: Option<f64>,
    pub iterations: u64,
    /// Clips per iteration; a class smaller than this is one full batch.
    pub batch_size: usize,
    pub adversarial: bool,
    pub weights: LossWeights,
    /// Foot terms through forward kinematics (`feet`); off on a skeleton
    /// without foot joints.
    pub feet: FootLoss,
    /// Global gradient-norm clip for both optimisers (LSTMs like it).
    pub max_grad_norm: Option<f32>,
    pub near: NearConfig,
    pub seed: u64,
    /// The simulated character's masses and soles, for the mixed-balance
    /// term (`LossWeights::mixed_balance`); `None` without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub balance: Option<BalanceModel>,
}

impl Default for TrainConfig {
    /// Small model, Adam 1e-3, 1500 iterations, adversarial on.
    fn default() -> Self {
        TrainConfig {
            model: VaeConfig::default(),
            features: FeatureConfig::default(),
            optimizer: OptimizerConfig::default(),
            cosine_to: Some(0.1),
            iterations: 1500,
            batch_size: 128,
            adversarial: true,
            weights: LossWeights::default(),
            feet: FootLoss::default(),
            max_grad_norm: Some(1.0),
            near: NearConfig::default(),
            seed: 0,
            balance: None,
        }
    }
}

impl TrainConfig {
    /// The MotionAug reference: paper sizes, SGD lr 0.005 halved every 4000 of
    /// 20000 iterations, batch 128.
    pub fn reference() -> Self {
        TrainConfig {
            model: VaeConfig::reference(),
            optimizer: OptimizerConfig::Sgd {
                lr: 0.005,
                halve_every: 4000,
            },
            iterations: 20_000,
            ..TrainConfig::default()
        }
    }

    pub fn validate(&self) -> Result<()> {
        self.model.validate()?;
        self.optimizer.validate()?;
        self.weights.validate()?;
        self.feet.validate()?;
        if self
            .cosine_to
            .is_some_and(|f| !(f.is_finite() && f > 0.0 && f <= 1.0))
        {
            return Err(VaeError::Config(
                "cosine_to must be a fraction in (0, 1]".into(),
            ));
        }
        self.near.validate()?;
        if self.weights.mixed_balance > 0.0 && self.balance.is_none() {
            return Err(VaeError::Config(
                "the mixed-balance term needs the character's masses and soles (TrainConfig::balance)"
                    .into(),
            ));
        }
        if self.iterations == 0 || self.batch_size == 0 {
            return Err(VaeError::Config(
                "iterations and batch_size must be >= 1".into(),
            ));
        }
        self.features.validate()?;
        if self
            .max_grad_norm
            .is_some_and(|m| !(m.is_finite() && m > 0.0))
        {
            return Err(VaeError::Config("max_grad_norm must be > 0".into()));
        }
        Ok(())
    }
}

/// Loss values of one iteration (the generator's terms are unweighted).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Losses {
    /// Root position MSE, m^2.
    pub root: f32,
    /// Rotation-matrix entry MSE.
    pub rotation: f32,
    pub smooth: f32,
    pub kl: f32,
    /// Generator hinge term (frame + sequence), 0 without adversarial training.
    pub adversarial: f32,
    /// Discriminator hinge loss (frame + sequence), 0 without adversarial training.
    pub discriminator: f32,
    /// Mean squared foot point distance to the capture, m^2 (0 without foot terms).
    #[serde(default)]
    pub foot_position: f32,
    /// Mean squared foot velocity difference, (m/s)^2.
    #[serde(default)]
    pub foot_velocity: f32,
    /// Contact-weighted squared horizontal foot speed of mixed-code decodes, (m/s)^2.
    #[serde(default)]
    pub skating: f32,
    /// Mean squared foot depth below the ground, m^2.
    #[serde(default)]
    pub floor: f32,
    /// Generator hinge term on mixed-code decodes (0 when off).
    #[serde(default)]
    pub mixed_adversarial: f32,
    /// Squared relative pose-speed difference of mixed-code decodes (0 when off).
    #[serde(default)]
    pub mixed_motion: f32,
    /// Squared difference of ground-contact share between mixed-code decodes
    /// and their parents (0 when off).
    #[serde(default)]
    pub mixed_contact: f32,
    /// Planted-weighted squared ankle-to-toe drop error of mixed-code decodes,
    /// in units of the 2 cm sole tolerance (0 when off).
    #[serde(default)]
    pub mixed_sole: f32,
    /// Squared relative root travel profile difference of mixed-code decodes
    /// and their parents (0 when off).
    #[serde(default)]
    pub mixed_travel: f32,
    /// Squared excess (in units of 10 cm) of mixed-code decodes' mean ZMP
    /// distance outside their soles over their parents' (0 when off).
    #[serde(default)]
    pub mixed_balance: f32,
    /// Weighted total the generator minimised.
    pub total: f32,
}

/// Reported to the caller after every iteration.
pub struct Progress<'a> {
    pub iteration: u64,
    pub iterations: u64,
    pub lr: f64,
    pub losses: &'a Losses,
}

/// One training step's state; `step` is public so the bench can time it.
pub struct Trainer {
    pub vae: Vae,
    pub data: Dataset,
    config: TrainConfig,
    denorm: Denorm,
    gen_opt: Optimizer,
    dis_opt: Optimizer,
    rng: ChaCha8Rng,
    order: Vec<usize>,
    cursor: usize,
    full_batch: Option<Prepared>,
    /// Foot kinematics of the training skeleton, when the foot terms are on.
    feet: Option<FootKinematics>,
    /// Kinematics of every joint, when the mixed-motion term is on.
    joints: Option<FootKinematics>,
    /// The character's balance, when the mixed-balance term is on.
    balance: Option<Balance>,
}

/// A batch with what the loss compares it to: rotation matrices and foot positions.
#[derive(Clone)]
struct Prepared {
    batch: Batch,
    rotations: Tensor,
    feet: Option<Tensor>,
    /// Pose speed of each clip `(B,)` (when the mixed-motion term is on):
    /// what its mixed decodes are asked to match.
    pose_speed: Option<Tensor>,
    /// Share of each clip's frames with a foot on the ground `(B,)` (when the
    /// mixed-contact term is on): what its mixed decodes are asked to match.
    ground_contact: Option<Tensor>,
    /// Mean ankle-to-toe drop of the batch's planted feet `(F,)` (when the
    /// mixed-sole term is on): how the skeleton stands on its soles.
    stance_drop: Option<Tensor>,
    /// Each clip's root travel profile `(B, TRAVEL_PARTS)` (when the
    /// mixed-travel term is on): what its mixed decodes are asked to match.
    travel: Option<Tensor>,
    /// Each clip's mean ZMP distance outside its soles `(B,)` (when the
    /// mixed-balance term is on): what its mixed decodes may not exceed.
    balance: Option<Tensor>,
}

/// Parts of a clip the travel profile averages the root speed over.
const TRAVEL_PARTS: usize = 4;

/// The unit of the mixed-balance term's excess ZMP distance, m.
const BALANCE_UNIT_M: f64 = 0.1;

/// The correction's sole tolerance (`correct::AcceptanceConfig::sole_tolerance_m`),
/// the unit of the mixed-sole term.
const SOLE_TOLERANCE_M: f64 = 0.02;

impl Prepared {
    fn new(
        batch: Batch,
        feet: Option<&FootKinematics>,
        joints: Option<&FootKinematics>,
        balance: Option<&Balance>,
        config: &TrainConfig,
    ) -> Result<Self> {
        let rotations = loss::rotation_matrices(&batch.raw)?;
        let kinematics = feet;
        let feet = feet.map(|fk| fk.positions(&batch.raw)).transpose()?;
        let pose_speed = joints
            .map(|jk| pose_speed(jk, &batch.raw, &batch.mask, config.features.fps))
            .transpose()?;
        let ground_contact = match &feet {
            Some(pos) if config.weights.mixed_contact > 0.0 => Some(feet::ground_contact(
                pos,
                &batch.mask,
                config.feet.contact_height_m,
            )?),
            _ => None,
        };
        let stance_drop = match (&feet, kinematics) {
            (Some(pos), Some(fk)) if config.weights.mixed_sole > 0.0 => Some(feet::stance_drop(
                pos,
                &batch.mask,
                fk.soles(),
                config.features.fps,
                config.feet.contact_height_m,
            )?),
            _ => None,
        };
        let travel = if config.weights.mixed_travel > 0.0 {
            Some(feet::travel_profile(
                &batch.raw.narrow(2, 0, 3)?,
                &batch.lengths,
                config.features.fps,
                TRAVEL_PARTS,
            )?)
        } else {
            None
        };
        let balance = balance
            .map(|b| b.zmp_outside(&batch.raw, &batch.mask, config.features.fps))
            .transpose()?
            .map(|(outside, _)| outside);
        Ok(Prepared {
            batch,
            rotations,
            feet,
            pose_speed,
            ground_contact,
            stance_drop,
            travel,
            balance,
        })
    }
}

/// Pose speed `(B,)` of raw frames `(B, T, 3 + 6 J)` through the kinematics of every joint.
fn pose_speed(joints: &FootKinematics, raw: &Tensor, mask: &Tensor, fps: f64) -> Result<Tensor> {
    feet::pose_speed(&joints.positions(raw)?, &raw.narrow(2, 0, 3)?, mask, fps)
}

/// Codes drawn between two clips of a batch, decoded beside the reconstructions.
struct Mixed {
    /// `(B, latent)`, detached.
    codes: Tensor,
    /// `(B, T)`: as long as the mean of the two parents' lengths.
    mask: Tensor,
    /// Batch indices `(B,)` of the two parent clips (`u32`).
    parents: (Tensor, Tensor),
    /// Valid frames of each (what `mask` marks).
    lengths: Vec<usize>,
}

impl Mixed {
    /// Per mixed code `(B,)`, the mean of a per-clip quantity `(B,)` over its
    /// two parent clips: what the mixed-code terms ask each decode to match.
    fn parents_mean(&self, per_clip: &Tensor) -> Result<Tensor> {
        Ok(((per_clip.index_select(&self.parents.0, 0)?
            + per_clip.index_select(&self.parents.1, 0)?)?
            * 0.5)?)
    }

    /// Mean squared difference between what the decodes made and their
    /// parents' mean of `per_clip`, relative to that mean (floored at
    /// `floor`, so that parents near 0 do not divide by it).
    fn relative_error(&self, made: &Tensor, per_clip: &Tensor, floor: f64) -> Result<Tensor> {
        let target = self.parents_mean(per_clip)?;
        let rel = ((made - &target)? / target.clamp(floor, f64::INFINITY)?)?;
        Ok(rel.sqr()?.mean_all()?)
    }
}

impl Trainer {
    pub fn new(clips: &[Motion], config: &TrainConfig) -> Result<Self> {
        config.validate()?;
        let data = Dataset::new(clips, &config.features)?;
        let vae = Vae::new(&config.model, data.dim, config.seed)?;
        let denorm = Denorm::new(&data.stats)?;
        let gen_opt = Optimizer::new(
            vae.params.with_prefix(&GENERATOR),
            config.optimizer,
            config.max_grad_norm,
        );
        let dis_opt = Optimizer::new(
            vae.params.with_prefix(&DISCRIMINATORS),
            config.optimizer,
            config.max_grad_norm,
        );
        let feet = if config.feet.is_off() {
            None
        } else {
            FootKinematics::new(&data.skeleton)?
        };
        let joints = if config.weights.mixed_motion > 0.0 {
            Some(FootKinematics::all_joints(&data.skeleton)?)
        } else {
            None
        };
        let balance = match (&config.balance, config.weights.mixed_balance > 0.0) {
            (Some(model), true) => Some(Balance::new(model, &data.skeleton)?),
            _ => None,
        };
        let full_batch = if data.len() <= config.batch_size {
            let all: Vec<usize> = (0..data.len()).collect();
            Some(Prepared::new(
                data.batch(&all)?,
                feet.as_ref(),
                joints.as_ref(),
                balance.as_ref(),
                config,
            )?)
        } else {
            None
        };
        Ok(Trainer {
            order: (0..data.len()).collect(),
            cursor: usize::MAX,
            rng: ChaCha8Rng::seed_from_u64(config.seed ^ 0x7261_696e),
            config: config.clone(),
            vae,
            data,
            denorm,
            gen_opt,
            dis_opt,
            full_batch,
            feet,
            joints,
            balance,
        })
    }

    fn next_batch(&mut self) -> Result<Prepared> {
        if let Some(p) = &self.full_batch {
            // Tensors are reference-counted: the clone shares their storage.
            return Ok(p.clone());
        }
        let bs = self.config.batch_size;
        if self.cursor.saturating_add(bs) > self.order.len() {
            self.order.shuffle(&mut self.rng);
            self.cursor = 0;
        }
        let idx = self.order[self.cursor..self.cursor + bs].to_vec();
        self.cursor += bs;
        Prepared::new(
            self.data.batch(&idx)?,
            self.feet.as_ref(),
            self.joints.as_ref(),
            self.balance.as_ref(),
            &self.config,
        )
    }

    /// Codes drawn between two random clips of the batch, as sampling near
    /// samples draws them (mean of the two posteriors' means, their mean
    /// variance), detached, each with a mask as long as the mean of the two
    /// clips' lengths.
    fn mixed_codes(
        &mut self,
        mu: &Tensor,
        logvar: &Tensor,
        lengths: &[usize],
        frames: usize,
    ) -> Result<Mixed> {
        let (b, latent) = mu.dims2()?;
        let pick = |rng: &mut ChaCha8Rng| -> Vec<u32> {
            (0..b).map(|_| rng.random_range(0..b) as u32).collect()
        };
        let i = pick(&mut self.rng);
        let j = pick(&mut self.rng);
        let mut mask = vec![0.0f32; b * frames];
        let mut valid = Vec::with_capacity(b);
        for (k, (&a, &c)) in i.iter().zip(&j).enumerate() {
            let n = (lengths[a as usize] + lengths[c as usize])
                .div_ceil(2)
                .min(frames);
            mask[k * frames..k * frames + n].fill(1.0);
            valid.push(n);
        }
        let dev = mu.device();
        let ii = Tensor::from_vec(i, b, dev)?;
        let jj = Tensor::from_vec(j, b, dev)?;
        let (mu, logvar) = (mu.detach(), logvar.detach());
        let mean = ((mu.index_select(&ii, 0)? + mu.index_select(&jj, 0)?)? * 0.5)?;
        let var =
            ((logvar.index_select(&ii, 0)?.exp()? + logvar.index_select(&jj, 0)?.exp()?)? * 0.5)?;
        let eps = nn::normal(&[b, latent], &mut self.rng)?;
        let z = (mean + (var.sqrt()? * eps)?)?;
        Ok(Mixed {
            codes: z,
            mask: Tensor::from_vec(mask, (b, frames), dev)?,
            parents: (ii, jj),
            lengths: valid,
        })
    }

    pub fn lr(&self) -> f64 {
        self.gen_opt.lr()
    }

    /// The learning rate of iteration `it` (0-based) under the cosine schedule.
    fn scheduled_lr(&self, it: u64) -> Option<f64> {
        let OptimizerConfig::Adam { lr } = self.config.optimizer else {
            return None;
        };
        let end = self.config.cosine_to?;
        let x = it as f64 / self.config.iterations.max(1) as f64;
        Some(lr * (end + (1.0 - end) * 0.5 * (1.0 + (std::f64::consts::PI * x).cos())))
    }

    /// One generator step (and one discriminator step when adversarial).
    pub fn step(&mut self) -> Result<Losses> {
        let prepared = self.next_batch()?;
        let batch = &prepared.batch;
        let w = self.config.weights;
        let wf = self.config.feet;
        let (mu, logvar) = self.vae.encoder.forward(&batch.x, &batch.mask)?;
        let (b, latent) = mu.dims2()?;
        let eps = nn::normal(&[b, latent], &mut self.rng)?;
        let z = nn::reparameterise(&mu, &logvar, &eps)?;
        let frames = batch.x.dim(1)?;
        // Codes between training clips, decoded in the same pass: they have no
        // captured counterpart, only the mixed-code terms (skating, floor,
        // pose speed, ground contact, adversarial) judge them.
        let mixed_adversarial = self.config.adversarial && w.mixed_adversarial > 0.0;
        let mixed = if (self.feet.is_some()
            && (wf.skating > 0.0 || wf.floor > 0.0 || w.mixed_contact > 0.0 || w.mixed_sole > 0.0))
            || w.mixed_motion > 0.0
            || w.mixed_travel > 0.0
            || self.balance.is_some()
            || mixed_adversarial
        {
            Some(self.mixed_codes(&mu, &logvar, &batch.lengths, frames)?)
        } else {
            None
        };
        let vae = &self.vae;
        let z_all = match &mixed {
            Some(m) => Tensor::cat(&[&z, &m.codes], 0)?,
            None => z,
        };
        let decoded = match &mixed {
            Some(m) => vae
                .decoder
                .forward_masked(&z_all, &Tensor::cat(&[&batch.mask, &m.mask], 0)?)?,
            None => vae.decoder.forward_masked(&z_all, &batch.mask)?,
        };
        let raw_all = self.denorm.apply(&decoded)?;
        let xhat = decoded.narrow(0, 0, b)?;
        let raw_hat = raw_all.narrow(0, 0, b)?;
        let (root, rot) =
            loss::reconstruction(&raw_hat, &batch.raw, &prepared.rotations, &batch.mask)?;
        let smooth = loss::smoothness(&raw_hat, &batch.mask)?;
        let kl = nn::kl_mean(&mu, &logvar)?;
        let mut total = ((&root + &rot)? + ((smooth.clone() * w.smooth)? + (kl.clone() * w.kl)?)?)?;
        let mut mixed_motion = 0.0;
        if let (Some(m), Some(jk), Some(real)) = (&mixed, &self.joints, &prepared.pose_speed) {
            let raw_mixed = raw_all.narrow(0, b, b)?;
            let moving = pose_speed(jk, &raw_mixed, &m.mask, self.config.features.fps)?;
            let term = m.relative_error(&moving, real, 1e-3)?;
            mixed_motion = term.to_scalar::<f32>()?;
            total = (total + (term * w.mixed_motion)?)?;
        }
        let mut mixed_travel = 0.0;
        if let (Some(m), Some(real)) = (&mixed, &prepared.travel) {
            let root = raw_all.narrow(0, b, b)?.narrow(2, 0, 3)?;
            let made =
                feet::travel_profile(&root, &m.lengths, self.config.features.fps, TRAVEL_PARTS)?;
            // Relative to the parents' speed, at least 0.1 m/s.
            let term = m.relative_error(&made, real, 0.1)?;
            mixed_travel = term.to_scalar::<f32>()?;
            total = (total + (term * w.mixed_travel)?)?;
        }
        let mut mixed_balance = 0.0;
        if let (Some(m), Some(bal), Some(real)) = (&mixed, &self.balance, &prepared.balance) {
            let raw_mixed = raw_all.narrow(0, b, b)?;
            let (made, _) = bal.zmp_outside(&raw_mixed, &m.mask, self.config.features.fps)?;
            // Only what exceeds the parents' own distance, in units of 10 cm.
            let excess = ((made - m.parents_mean(real)?)?.relu()? / BALANCE_UNIT_M)?;
            let term = excess.sqr()?.mean_all()?;
            mixed_balance = term.to_scalar::<f32>()?;
            total = (total + (term * w.mixed_balance)?)?;
        }
        let mut foot = [0.0f32; 4];
        let mut mixed_contact = 0.0;
        let mut mixed_sole = 0.0;
        if let (Some(fk), Some(target)) = (&self.feet, &prepared.feet) {
            let fps = self.config.features.fps;
            let pos_all = fk.positions(&raw_all)?;
            let pos = pos_all.narrow(0, 0, b)?;
            let position = feet::position_error(&pos, target, &batch.mask)?;
            let velocity = feet::velocity_error(&pos, target, &batch.mask, fps)?;
            let mut floor = feet::floor(&pos, &batch.mask)?;
            let mut skating = Tensor::zeros((), floor.dtype(), floor.device())?;
            if let Some(m) = &mixed {
                let pm = pos_all.narrow(0, b, pos_all.dim(0)? - b)?;
                skating = feet::skating(&pm, &m.mask, fps, wf.contact_height_m)?;
                floor = (floor + feet::floor(&pm, &m.mask)?)?;
                if let Some(real) = &prepared.ground_contact {
                    let want = m.parents_mean(real)?;
                    let made = feet::ground_contact(&pm, &m.mask, wf.contact_height_m)?;
                    let term = (made - want)?.sqr()?.mean_all()?;
                    mixed_contact = term.to_scalar::<f32>()?;
                    total = (total + (term * w.mixed_contact)?)?;
                }
                if let Some(stance) = &prepared.stance_drop {
                    let term = feet::sole_level(
                        &pm,
                        &m.mask,
                        fk.soles(),
                        stance,
                        fps,
                        wf.contact_height_m,
                        SOLE_TOLERANCE_M,
                    )?;
                    mixed_sole = term.to_scalar::<f32>()?;
                    total = (total + (term * w.mixed_sole)?)?;
                }
            }
            foot = [
                position.to_scalar()?,
                velocity.to_scalar()?,
                skating.to_scalar()?,
                floor.to_scalar()?,
            ];
            let terms = ((position * wf.position)? + (velocity * wf.velocity)?)?;
            let terms = (terms + ((skating * wf.skating)? + (floor * wf.floor)?)?)?;
            total = (total + terms)?;
        }
        let mut adv = 0.0;
        let mut adv_mixed = 0.0;
        if self.config.adversarial {
            let g =
                (loss::hinge_generator(
                    &vae.frame_disc.forward(&xhat, Some(&batch.mask))?,
                    Some(&batch.mask),
                )? + loss::hinge_generator(&vae.seq_disc.forward(&xhat, &batch.mask)?, None)?)?;
            adv = g.to_scalar::<f32>()?;
            total = (total + (g * w.adversarial)?)?;
        }
        let x_mixed = match (&mixed, mixed_adversarial) {
            (Some(m), true) => Some((decoded.narrow(0, b, b)?, &m.mask)),
            _ => None,
        };
        if let Some((xm, mm)) = &x_mixed {
            let g = (loss::hinge_generator(&vae.frame_disc.forward(xm, Some(mm))?, Some(mm))?
                + loss::hinge_generator(&vae.seq_disc.forward(xm, mm)?, None)?)?;
            adv_mixed = g.to_scalar::<f32>()?;
            total = (total + (g * w.mixed_adversarial)?)?;
        }
        let grads = total.backward()?;
        self.gen_opt.step(&grads)?;
        let mut disc = 0.0;
        if self.config.adversarial {
            // Real and fake clips in one batch: one pass of each discriminator
            // (the sequence one is a BiLSTM, whose steps run one after another).
            // With mixed adversarial terms the mixed decodes are a third block
            // of fakes in the same pass.
            let m = &batch.mask;
            let (all, masks) = match &x_mixed {
                Some((xm, mm)) => (
                    Tensor::cat(&[&batch.x, &xhat.detach(), &xm.detach()], 0)?,
                    Tensor::cat(&[m, m, *mm], 0)?,
                ),
                None => (
                    Tensor::cat(&[&batch.x, &xhat.detach()], 0)?,
                    Tensor::cat(&[m, m], 0)?,
                ),
            };
            let frame = vae.frame_disc.forward(&all, Some(&masks))?;
            let seq = vae.seq_disc.forward(&all, &masks)?;
            let mut d = (loss::hinge_discriminator(
                &frame.narrow(0, 0, b)?,
                &frame.narrow(0, b, b)?,
                Some(m),
            )? + loss::hinge_discriminator(
                &seq.narrow(0, 0, b)?,
                &seq.narrow(0, b, b)?,
                None,
            )?)?;
            if let Some((_, mm)) = &x_mixed {
                let fake_frame = (frame.narrow(0, 2 * b, b)? + 1.0)?.relu()?;
                let fake_seq = (seq.narrow(0, 2 * b, b)? + 1.0)?.relu()?;
                d = (d + (loss::masked_frame_mean(&fake_frame, mm)? + fake_seq.mean_all()?)?)?;
            }
            disc = d.to_scalar::<f32>()?;
            self.dis_opt.step(&d.backward()?)?;
        }
        let losses = Losses {
            root: root.to_scalar()?,
            rotation: rot.to_scalar()?,
            smooth: smooth.to_scalar()?,
            kl: kl.to_scalar()?,
            adversarial: adv,
            discriminator: disc,
            foot_position: foot[0],
            foot_velocity: foot[1],
            skating: foot[2],
            floor: foot[3],
            mixed_adversarial: adv_mixed,
            mixed_motion,
            mixed_contact,
            mixed_sole,
            mixed_travel,
            mixed_balance,
            total: total.to_scalar()?,
        };
        if !losses.total.is_finite() {
            return Err(VaeError::Data(format!(
                "training diverged (loss {}); try a smaller learning rate",
                losses.total
            )));
        }
        Ok(losses)
    }

    /// Train for the configured iterations, then encode the training set and
    /// cluster it for sampling near samples.
    pub fn run(mut self, mut progress: impl FnMut(&Progress)) -> Result<TrainedVae> {
        let _span = tracing::info_span!("vae_train", clips = self.data.len()).entered();
        let start = Instant::now();
        let mut last = Losses::default();
        for it in 0..self.config.iterations {
            if let Some(lr) = self.scheduled_lr(it) {
                self.gen_opt.set_lr(lr);
                self.dis_opt.set_lr(lr);
            }
            let lr = self.lr();
            last = self.step()?;
            progress(&Progress {
                iteration: it + 1,
                iterations: self.config.iterations,
                lr,
                losses: &last,
            });
        }
        let seconds = start.elapsed().as_secs_f64();
        let all: Vec<usize> = (0..self.data.len()).collect();
        let batch = self.data.batch(&all)?;
        let (mu, logvar) = self.vae.encoder.forward(&batch.x, &batch.mask)?;
        let mut rng = ChaCha8Rng::seed_from_u64(self.config.seed ^ 0x6e65_6172);
        let latents = LatentStats::fit(
            mu.to_vec2()?,
            logvar.to_vec2()?,
            &self.config.near,
            &mut rng,
        )?;
        let meta = ModelMeta {
            format: crate::trained::FORMAT,
            config: self.config.model.clone(),
            features: self.config.features,
            stats: self.data.stats.clone(),
            skeleton: (*self.data.skeleton).clone(),
            lengths: self.data.lengths(),
            latents,
            training: TrainingSummary {
                clips: self.data.len(),
                iterations: self.config.iterations,
                adversarial: self.config.adversarial,
                optimizer: self.config.optimizer,
                cosine_to: self.config.cosine_to,
                weights: self.config.weights,
                feet: self.config.feet,
                seed: self.config.seed,
                final_losses: last,
                seconds,
            },
        };
        TrainedVae::from_parts(self.vae, meta)
    }
}

/// Train a model on `clips` (one action class).
pub fn train(
    clips: &[Motion],
    config: &TrainConfig,
    progress: impl FnMut(&Progress),
) -> Result<TrainedVae> {
    Trainer::new(clips, config)?.run(progress)
}
