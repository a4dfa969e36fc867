//! The deterministic whole-clip rollout: start at the first frame of the clip,
//! act with the policy's mean action until the clip ends or the character
//! falls, and record what the simulated character did.
//!
//! Its figures are the paper's: R_norm = (1/T) sum_t r_imit_t / r_imit_max over
//! the T control steps of the clip (r_imit_max = 1; steps after a fall count 0),
//! the mean per-step reward over the same T steps, and the residual force ratio
//! mean |F_res| / (m g) over the steps simulated. It also keeps how the feet met
//! the floor after every step, which [`crate::acceptance`] judges.

use motion::Motion;
use physics::ImitationEnv;

use crate::CorrectError;

/// Gravity used to express the residual force as a fraction of body weight.
pub const GRAVITY: f64 = 9.8;

#[derive(Debug, Clone)]
pub struct Rollout {
    /// Control steps of the whole clip (T).
    pub clip_steps: usize,
    /// MotionAug's per-step reward (`0.9 r_imit + 0.1 r_res`), whatever the
    /// training reward adds.
    pub rewards: Vec<f32>,
    pub r_imit: Vec<f32>,
    /// |F_res| per simulated step, N.
    pub residual_force: Vec<f32>,
    /// Step at which the character fell, if it did.
    pub fell_at: Option<usize>,
    /// The body that touched the ground when it fell (the character's body
    /// name, e.g. `head`).
    pub fell_body: Option<String>,
    /// How each simulated foot met the floor after each step.
    pub feet: Vec<Vec<physics::FootContact>>,
    pub total_mass_kg: f64,
    /// What the simulated character did, on the clip's own skeleton, at the
    /// control rate.
    pub motion: Motion,
}

impl Rollout {
    pub fn r_norm(&self) -> f64 {
        self.r_imit.iter().map(|&r| r as f64).sum::<f64>() / self.clip_steps.max(1) as f64
    }

    pub fn mean_reward(&self) -> f64 {
        self.rewards.iter().map(|&r| r as f64).sum::<f64>() / self.clip_steps.max(1) as f64
    }

    pub fn residual_force_ratio(&self) -> f64 {
        if self.residual_force.is_empty() {
            return 0.0;
        }
        let mean = self.residual_force.iter().map(|&f| f as f64).sum::<f64>()
            / self.residual_force.len() as f64;
        mean / (self.total_mass_kg * GRAVITY)
    }
}

/// Roll the policy `act` (observation -> action) over the whole clip from its
/// first frame. `act` must be deterministic for the rollout to be.
pub fn deterministic_rollout<F>(env: &mut ImitationEnv, mut act: F) -> Result<Rollout, CorrectError>
where
    F: FnMut(&[f32], &mut [f32]) -> Result<(), CorrectError>,
{
    env.set_recording(true);
    let mut obs = env.reset(0.0).to_vec();
    let mut action = vec![0.0f32; env.act_dim()];
    let clip_steps = env.episode_len();
    let mut rewards = Vec::with_capacity(clip_steps);
    let mut r_imit = Vec::with_capacity(clip_steps);
    let mut residual_force = Vec::with_capacity(clip_steps);
    let mut fell_at = None;
    let mut fell_body = None;
    let mut feet = Vec::with_capacity(clip_steps);
    for t in 0..clip_steps {
        act(&obs, &mut action)?;
        let step = env.step(&action)?;
        obs.copy_from_slice(env.obs());
        rewards.push(step.info.paper_reward);
        r_imit.push(step.r_imit);
        residual_force.push(step.info.residual_force);
        feet.push(env.foot_contacts());
        if step.terminated {
            fell_at = Some(t);
            fell_body = step
                .info
                .fallen_body
                .map(|b| env.spec().bodies[b].name.clone());
            break;
        }
        if step.truncated {
            break;
        }
    }
    let motion = env.recorded_motion()?;
    env.set_recording(false);
    Ok(Rollout {
        clip_steps,
        rewards,
        r_imit,
        residual_force,
        fell_at,
        fell_body,
        feet,
        total_mass_kg: env.spec().total_mass as f64,
        motion,
    })
}
