//! The bridge between the physics crate and the generic PPO crate: the
//! imitation environment implements [`ppo::Env`]. Episodes start at a random
//! phase of the clip (reference state initialisation); a fall terminates (no
//! bootstrap), the end of the clip truncates (the critic bootstraps).

use physics::ImitationEnv;
use ppo::{EnvRng, StepResult};

pub struct ImitationTask {
    pub env: ImitationEnv,
}

impl ImitationTask {
    pub fn new(env: ImitationEnv) -> Self {
        ImitationTask { env }
    }
}

impl ppo::Env for ImitationTask {
    fn obs_dim(&self) -> usize {
        self.env.obs_dim()
    }

    fn act_dim(&self) -> usize {
        self.env.act_dim()
    }

    fn reset(&mut self, rng: &mut EnvRng, obs: &mut [f32]) {
        obs.copy_from_slice(self.env.reset_random(rng));
    }

    fn step(&mut self, action: &[f32], obs: &mut [f32]) -> StepResult {
        match self.env.step(action) {
            Ok(step) => {
                obs.copy_from_slice(self.env.obs());
                StepResult {
                    reward: step.reward,
                    terminated: step.terminated,
                    truncated: step.truncated,
                }
            }
            // The trainer always passes act_dim values; a mismatch is a bug we
            // surface as a failed episode rather than a panic in a worker thread.
            Err(err) => {
                tracing::error!(%err, "imitation step failed");
                obs.copy_from_slice(self.env.obs());
                StepResult {
                    reward: 0.0,
                    terminated: true,
                    truncated: false,
                }
            }
        }
    }

    fn reset_eval(&mut self, obs: &mut [f32]) {
        obs.copy_from_slice(self.env.reset(0.0));
    }
}
