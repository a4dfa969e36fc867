//! PPO must actually learn: on the point-mass task the trained deterministic policy's
//! return must clearly beat the untrained one's (whose mean action is ~0: it stays put).

mod common;

use common::{PointMass, mean_return};
use ppo::{Control, PpoConfig, RunLimits, Trainer};

#[test]
fn ppo_learns_to_reach_the_target() {
    let mut config = PpoConfig::default();
    config.policy.log_std = -1.0;
    config.samples_per_iteration = 2048;
    let envs = (0..16).map(|_| PointMass::new(50)).collect();
    let mut trainer = Trainer::new(config, envs, 7).unwrap();
    let before = mean_return(&trainer, 32);
    let limits = RunLimits {
        // No time budget: a loaded machine must not make the test fail.
        max_iterations: Some(60),
        ..RunLimits::default()
    };
    let mut rewards = Vec::new();
    trainer
        .run(&limits, |t, report| {
            rewards.push(report.mean_reward);
            // Stop as soon as the deterministic policy is clearly good.
            if report.iteration % 5 == 0 {
                let r = mean_return(t, 32);
                t.record_eval(r);
                if r > 3.0 * before.max(1.0) {
                    return Control::Stop;
                }
            }
            Control::Continue
        })
        .unwrap();
    let after = mean_return(&trainer, 32);
    eprintln!(
        "return before {before:.2}, after {after:.2} ({} iterations, {:.1} s); batch mean reward {:.3} -> {:.3}",
        trainer.progress().iterations,
        trainer.progress().wall_s,
        rewards[0],
        rewards[rewards.len() - 1]
    );
    assert!(
        after > 2.0 * before,
        "return before {before}, after {after}"
    );
    assert!(trainer.progress().curve.iter().any(|p| p.eval.is_some()));
}
