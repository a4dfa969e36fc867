//! The bridge between the physics crate and the generic PPO crate: imitation
//! environments seen as one [`ppo::Env`]. A task holds one clip (a policy for
//! that clip) or several (a tracker policy for a class, see
//! [`crate::class`]): each episode picks a clip, with a chance proportional
//! to its length, and starts at a random phase of it (reference state
//! initialisation); a fall terminates (no bootstrap), the end of the clip
//! truncates (the critic bootstraps).

use physics::ImitationEnv;
use ppo::{EnvRng, StepResult};
use rand::Rng;

use crate::CorrectError;

pub struct ImitationTask {
    clips: Vec<ImitationEnv>,
    /// Cumulative episode lengths of `clips`: the draw of a clip.
    cumulative: Vec<usize>,
    current: usize,
}

impl ImitationTask {
    /// A task over one clip.
    pub fn new(env: ImitationEnv) -> Self {
        let cumulative = vec![env.episode_len().max(1)];
        ImitationTask {
            clips: vec![env],
            cumulative,
            current: 0,
        }
    }

    /// A task over several clips, whose characters must have the same
    /// observation and action sizes (the same body layout).
    pub fn over(clips: Vec<ImitationEnv>) -> Result<Self, CorrectError> {
        let Some(first) = clips.first() else {
            return Err(CorrectError::Config(
                "a task needs at least one clip".into(),
            ));
        };
        let dims = (first.obs_dim(), first.act_dim());
        if let Some(i) = clips
            .iter()
            .position(|c| (c.obs_dim(), c.act_dim()) != dims)
        {
            return Err(CorrectError::Config(format!(
                "clip {i} has (observation, action) sizes {:?} where clip 0 has {dims:?}: \
                 one policy needs characters with the same body layout",
                (clips[i].obs_dim(), clips[i].act_dim())
            )));
        }
        let mut total = 0;
        let cumulative = clips
            .iter()
            .map(|c| {
                total += c.episode_len().max(1);
                total
            })
            .collect();
        Ok(ImitationTask {
            clips,
            cumulative,
            current: 0,
        })
    }

    /// The environment of the current episode.
    pub fn env(&self) -> &ImitationEnv {
        &self.clips[self.current]
    }

    /// Scale the PD-residual gains of every clip's environment.
    pub fn set_residual_scale(&mut self, scale: f32) {
        for env in &mut self.clips {
            env.set_residual_scale(scale);
        }
    }

    /// Turn the sole reward's sliding term on (or off, 0) in every clip's
    /// environment.
    pub fn set_skate_scale(&mut self, m_s: f32) {
        for env in &mut self.clips {
            env.set_skate_scale(m_s);
        }
    }

    fn env_mut(&mut self) -> &mut ImitationEnv {
        &mut self.clips[self.current]
    }
}

impl ppo::Env for ImitationTask {
    fn obs_dim(&self) -> usize {
        self.env().obs_dim()
    }

    fn act_dim(&self) -> usize {
        self.env().act_dim()
    }

    fn reset(&mut self, rng: &mut EnvRng, obs: &mut [f32]) {
        if self.clips.len() > 1 {
            let total = self.cumulative.last().copied().unwrap_or(1);
            let draw = rng.random_range(0..total);
            self.current = self.cumulative.partition_point(|&c| c <= draw);
        }
        obs.copy_from_slice(self.env_mut().reset_random(rng));
    }

    fn step(&mut self, action: &[f32], obs: &mut [f32]) -> StepResult {
        let env = self.env_mut();
        match env.step(action) {
            Ok(step) => {
                obs.copy_from_slice(env.obs());
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
                obs.copy_from_slice(env.obs());
                StepResult {
                    reward: 0.0,
                    terminated: true,
                    truncated: false,
                }
            }
        }
    }

    fn reset_eval(&mut self, obs: &mut [f32]) {
        self.current = 0;
        obs.copy_from_slice(self.env_mut().reset(0.0));
    }
}
