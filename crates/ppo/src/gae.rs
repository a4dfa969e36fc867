//! Generalised advantage estimation over one environment's step sequence.
//!
//! Episode ends are handled the way the environment reports them:
//! - `terminated[t]`: the return after step t is 0 (no bootstrap),
//! - `truncated[t]`: the episode was cut, the rest is estimated by
//!   `bootstrap[t]` = V(observation reached by step t),
//!
//! In both cases the advantage recursion restarts at t.

/// Inputs for one environment, all of the same length T (step order).
pub struct GaeInput<'a> {
    pub rewards: &'a [f32],
    pub values: &'a [f32],
    pub terminated: &'a [bool],
    pub truncated: &'a [bool],
    /// Value of the state reached at step t; only read where `truncated[t]`.
    pub bootstrap: &'a [f32],
}

/// Writes advantages and value targets (returns = advantages + values).
/// The last step must end an episode (terminated or truncated): rollouts mark their last
/// step as truncated when the environment did not end it.
pub fn compute(input: &GaeInput, gamma: f32, lambda: f32, adv: &mut [f32], ret: &mut [f32]) {
    let n = input.rewards.len();
    debug_assert!(
        n == 0 || input.terminated[n - 1] || input.truncated[n - 1],
        "the last step must end an episode"
    );
    let mut next_adv = 0.0f32;
    for t in (0..n).rev() {
        let (next_value, carry) = if input.terminated[t] {
            (0.0, 0.0)
        } else if input.truncated[t] {
            (input.bootstrap[t], 0.0)
        } else {
            (input.values[t + 1], next_adv)
        };
        let delta = input.rewards[t] + gamma * next_value - input.values[t];
        let a = delta + gamma * lambda * carry;
        adv[t] = a;
        ret[t] = a + input.values[t];
        next_adv = a;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terminal_truncated_and_continuing_steps() {
        // Episode 1: steps 0,1 (terminated at 1). Episode 2: steps 2,3 (truncated at 3).
        let rewards = [1.0, 2.0, 3.0, 4.0];
        let values = [0.5, 0.25, 1.0, 2.0];
        let terminated = [false, true, false, false];
        let truncated = [false, false, false, true];
        let bootstrap = [0.0, 99.0, 0.0, 10.0];
        let (g, l) = (0.9f32, 0.8f32);
        let mut adv = [0.0; 4];
        let mut ret = [0.0; 4];
        compute(
            &GaeInput {
                rewards: &rewards,
                values: &values,
                terminated: &terminated,
                truncated: &truncated,
                bootstrap: &bootstrap,
            },
            g,
            l,
            &mut adv,
            &mut ret,
        );
        // Hand computation.
        let d1 = 2.0 - 0.25; // terminal: no bootstrap (the 99 must be ignored)
        let d0 = 1.0 + g * 0.25 - 0.5;
        let a1 = d1;
        let a0 = d0 + g * l * a1;
        let d3 = 4.0 + g * 10.0 - 2.0; // truncated: bootstrap from V(final obs)
        let d2 = 3.0 + g * 2.0 - 1.0;
        let a3 = d3;
        let a2 = d2 + g * l * a3;
        let expect = [a0, a1, a2, a3];
        for i in 0..4 {
            assert!(
                (adv[i] - expect[i]).abs() < 1e-6,
                "adv[{i}] {} vs {}",
                adv[i],
                expect[i]
            );
            assert!((ret[i] - (expect[i] + values[i])).abs() < 1e-6);
        }
    }

    #[test]
    fn lambda_one_gives_discounted_return() {
        let rewards = [1.0f32, 1.0, 1.0];
        let values = [0.3f32, -0.2, 0.7];
        let mut adv = [0.0; 3];
        let mut ret = [0.0; 3];
        compute(
            &GaeInput {
                rewards: &rewards,
                values: &values,
                terminated: &[false, false, true],
                truncated: &[false; 3],
                bootstrap: &[0.0; 3],
            },
            0.5,
            1.0,
            &mut adv,
            &mut ret,
        );
        assert!((ret[0] - 1.75).abs() < 1e-6);
        assert!((ret[1] - 1.5).abs() < 1e-6);
        assert!((ret[2] - 1.0).abs() < 1e-6);
    }
}
