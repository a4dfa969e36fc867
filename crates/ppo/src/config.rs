//! PPO hyper-parameters, with the reference values and small test defaults.

use serde::{Deserialize, Serialize};

use crate::error::{PpoError, Result};
use crate::policy::PolicyConfig;
use crate::value::ValueConfig;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PpoConfig {
    pub policy: PolicyConfig,
    pub value: ValueConfig,
    pub policy_lr: f64,
    pub value_lr: f64,
    /// PPO ratio clip epsilon.
    pub clip: f32,
    pub gamma: f32,
    /// GAE lambda.
    pub lambda: f32,
    /// Environment steps collected per iteration (rounded up to a multiple of the env count).
    pub samples_per_iteration: usize,
    pub minibatch_size: usize,
    pub epochs: usize,
    /// Clip each network's gradient to this global L2 norm before the Adam step.
    pub max_grad_norm: Option<f32>,
    /// Standardise advantages over each iteration's batch.
    pub normalize_advantages: bool,
    /// Normalised observations are clipped to [-obs_clip, obs_clip].
    pub obs_clip: f32,
    /// Steps per environment run before the first iteration to initialise the
    /// observation normaliser (no learning from them).
    pub norm_warmup_steps: usize,
    /// Rollout worker threads: each steps whole batches of `rollout_batch`
    /// environments, so the experience does not depend on this.
    pub threads: usize,
    /// Environments stepped in lock-step with one batched policy + value
    /// forward per step during a rollout. Products over different batch
    /// sizes differ in their last bits, so this (not `threads`) shapes the
    /// numbers, and at most `envs / rollout_batch` threads have work.
    /// Default 4: 8 environments on 2 threads, the batches every run had
    /// before the field existed when it used 2 rollout threads (older
    /// configs read as 4).
    #[serde(default = "default_rollout_batch")]
    pub rollout_batch: usize,
    /// Entropy bonus (only matters with a learnable log-std).
    pub entropy_coef: f32,
}

impl PpoConfig {
    /// The RFC / MotionAug PPO settings (see shared/notes/reference-facts.md).
    pub fn reference() -> Self {
        PpoConfig {
            policy: PolicyConfig {
                hidden: vec![1024, 512],
                ..PolicyConfig::default()
            },
            value: ValueConfig {
                hidden: vec![1024, 512],
            },
            policy_lr: 5e-5,
            value_lr: 3e-4,
            clip: 0.2,
            gamma: 0.95,
            lambda: 0.95,
            samples_per_iteration: 50_000,
            minibatch_size: 2048,
            epochs: 10,
            max_grad_norm: None,
            normalize_advantages: true,
            obs_clip: 5.0,
            norm_warmup_steps: 30,
            threads: 2,
            rollout_batch: default_rollout_batch(),
            entropy_coef: 0.0,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(PpoError::Config(m));
        if self.policy.hidden.contains(&0) || self.value.hidden.contains(&0) {
            return bad("hidden layer sizes must be > 0".into());
        }
        if !(self.policy_lr > 0.0 && self.value_lr > 0.0) {
            return bad(format!(
                "learning rates must be > 0 (policy_lr {}, value_lr {})",
                self.policy_lr, self.value_lr
            ));
        }
        if !(self.clip > 0.0 && self.clip < 1.0) {
            return bad(format!("clip must be in (0, 1), got {}", self.clip));
        }
        if !(0.0..=1.0).contains(&self.gamma) || !(0.0..=1.0).contains(&self.lambda) {
            return bad(format!(
                "gamma and lambda must be in [0, 1], got {} and {}",
                self.gamma, self.lambda
            ));
        }
        if self.samples_per_iteration == 0 || self.minibatch_size == 0 || self.epochs == 0 {
            return bad("samples_per_iteration, minibatch_size and epochs must be > 0".into());
        }
        if self.threads == 0 || self.rollout_batch == 0 {
            return bad("threads and rollout_batch must be > 0".into());
        }
        if self.obs_clip.is_nan() || self.obs_clip <= 0.0 {
            return bad(format!("obs_clip must be > 0, got {}", self.obs_clip));
        }
        if let Some(g) = self.max_grad_norm
            && (g.is_nan() || g <= 0.0)
        {
            return bad(format!("max_grad_norm must be > 0, got {g}"));
        }
        if !self.policy.log_std.is_finite() {
            return bad("policy.log_std must be finite".into());
        }
        Ok(())
    }
}

fn default_rollout_batch() -> usize {
    4
}

/// Small, fast settings for tests and toy problems.
impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            policy: PolicyConfig {
                hidden: vec![64, 64],
                ..PolicyConfig::default()
            },
            value: ValueConfig {
                hidden: vec![64, 64],
            },
            policy_lr: 3e-4,
            value_lr: 1e-3,
            clip: 0.2,
            gamma: 0.95,
            lambda: 0.95,
            samples_per_iteration: 2048,
            minibatch_size: 256,
            epochs: 5,
            max_grad_norm: Some(1.0),
            normalize_advantages: true,
            obs_clip: 5.0,
            norm_warmup_steps: 10,
            threads: 2,
            rollout_batch: default_rollout_batch(),
            entropy_coef: 0.0,
        }
    }
}
