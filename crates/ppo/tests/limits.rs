//! Run limits and the stop callback of `Trainer::run`.

mod common;

use common::PointMass;
use ppo::{Control, PpoConfig, RunLimits, StopReason, Trainer};

fn trainer() -> Trainer<PointMass> {
    let config = PpoConfig {
        samples_per_iteration: 128,
        minibatch_size: 64,
        epochs: 1,
        threads: 1,
        ..PpoConfig::default()
    };
    Trainer::new(config, (0..2).map(|_| PointMass::new(20)).collect(), 5).unwrap()
}

#[test]
fn stops_on_each_limit() {
    let mut t = trainer();
    let limits = RunLimits {
        time_budget_s: Some(0.0),
        ..RunLimits::default()
    };
    assert_eq!(
        t.run(&limits, |_, _| Control::Continue).unwrap(),
        StopReason::TimeBudget
    );
    assert_eq!(t.progress().iterations, 0);

    let limits = RunLimits {
        max_samples: Some(300),
        ..RunLimits::default()
    };
    assert_eq!(
        t.run(&limits, |_, _| Control::Continue).unwrap(),
        StopReason::MaxSamples
    );
    assert_eq!(t.progress().samples, 384, "three iterations of 128 samples");

    let limits = RunLimits {
        max_iterations: Some(100),
        ..RunLimits::default()
    };
    let mut calls = 0;
    let reason = t
        .run(&limits, |t, r| {
            calls += 1;
            t.record_eval(r.mean_reward);
            if r.iteration == 5 {
                Control::Stop
            } else {
                Control::Continue
            }
        })
        .unwrap();
    assert_eq!(reason, StopReason::Callback);
    assert_eq!(calls, 2);
    assert_eq!(t.progress().iterations, 5);
    assert_eq!(t.progress().curve.len(), 5);
    assert!(t.progress().curve[4].eval.is_some());
    assert!(t.progress().curve[0].eval.is_none());
}

#[test]
fn evaluation_is_deterministic_and_checks_dimensions() {
    let t = trainer();
    let mut env = PointMass::new(30);
    let a = t.evaluate(&mut env, 1000).unwrap();
    let b = t.evaluate(&mut env, 1000).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.rewards.len(), 30);
    assert!(a.truncated && !a.terminated);
    let short = t.evaluate(&mut env, 7).unwrap();
    assert_eq!(short.rewards.len(), 7);
    let mut act = [0.0f32; 3];
    assert!(t.act_deterministic(&[0.0; 6], &mut act).is_err());
}

#[test]
fn untrained_policy_acts_near_zero() {
    let t = trainer();
    let mut act = [1.0f32; 2];
    t.act_deterministic(&[0.5, -0.3, 0.1, 0.0, 0.2, 0.9], &mut act)
        .unwrap();
    assert!(act.iter().all(|a| a.abs() < 0.05), "{act:?}");
}
