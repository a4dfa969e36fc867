//! The environment interface the trainer drives.
//!
//! Observations are written into caller-owned buffers so stepping allocates nothing.
//! Episodes end in one of two ways that PPO must treat differently:
//! `terminated` (a failure such as a fall: the future is worth nothing, no bootstrap) and
//! `truncated` (a time limit or the end of a clip: the state still has value, bootstrap
//! from the critic).

use rand::SeedableRng;

/// The random generator handed to environments (for reference state initialisation etc.).
pub type EnvRng = rand_chacha::ChaCha8Rng;

/// Outcome of one environment step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepResult {
    pub reward: f32,
    /// The episode ended in failure (fall, non-finite state): no value beyond this step.
    pub terminated: bool,
    /// The episode was cut (time limit, end of clip): the critic bootstraps the rest.
    pub truncated: bool,
}

/// A continuous-control environment with fixed observation and action sizes.
///
/// After a step that returns `terminated` or `truncated`, `obs` must hold the observation
/// of the state reached (used to bootstrap on truncation); the trainer then calls `reset`.
/// Implementations must write finite values into every slot of `obs`.
pub trait Env: Send {
    fn obs_dim(&self) -> usize;
    fn act_dim(&self) -> usize;
    /// Start a new episode (possibly at a random state drawn from `rng`), write its
    /// first observation into `obs` (`obs.len() == obs_dim()`).
    fn reset(&mut self, rng: &mut EnvRng, obs: &mut [f32]);
    /// Apply `action` (`action.len() == act_dim()`), advance one control step and write
    /// the next observation into `obs`.
    fn step(&mut self, action: &[f32], obs: &mut [f32]) -> StepResult;
    /// Start the episode used for deterministic evaluation (e.g. the start of the clip).
    /// The default is `reset` with a fixed seed.
    fn reset_eval(&mut self, obs: &mut [f32]) {
        let mut rng = EnvRng::seed_from_u64(0);
        self.reset(&mut rng, obs);
    }
}
