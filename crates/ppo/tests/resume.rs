//! Checkpoint / resume: k + m iterations in one go must equal k iterations, a checkpoint,
//! a fresh trainer resumed from it and m more iterations, bit for bit.

mod common;

use std::collections::HashMap;

use common::PointMass;
use ppo::trainer::parameters;
use ppo::{PpoConfig, RunLimits, Trainer};

fn config(threads: usize) -> PpoConfig {
    PpoConfig {
        samples_per_iteration: 256,
        minibatch_size: 64,
        epochs: 2,
        threads,
        ..PpoConfig::default()
    }
}

fn envs() -> Vec<PointMass> {
    (0..4).map(|_| PointMass::new(20)).collect()
}

fn train(t: &mut Trainer<PointMass>, iterations: u64) {
    let limits = RunLimits {
        max_iterations: Some(iterations),
        ..RunLimits::default()
    };
    t.run(&limits, |_, _| ppo::Control::Continue).unwrap();
}

fn assert_same(a: &HashMap<String, Vec<f32>>, b: &HashMap<String, Vec<f32>>) {
    assert_eq!(a.len(), b.len());
    for (k, va) in a {
        let vb = &b[k];
        let bits_a: Vec<u32> = va.iter().map(|x| x.to_bits()).collect();
        let bits_b: Vec<u32> = vb.iter().map(|x| x.to_bits()).collect();
        assert!(bits_a == bits_b, "parameter {k} differs");
    }
}

#[test]
fn resume_continues_bit_for_bit() {
    let dir = std::env::temp_dir().join(format!("ppo-resume-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);

    let mut straight = Trainer::new(config(2), envs(), 3).unwrap();
    train(&mut straight, 5);

    let mut first = Trainer::new(config(2), envs(), 3).unwrap();
    let limits = RunLimits {
        max_iterations: Some(3),
        checkpoint_dir: Some(dir.clone()),
        checkpoint_every_s: 0.0,
        keep_checkpoints: 2,
        ..RunLimits::default()
    };
    first.run(&limits, |_, _| ppo::Control::Continue).unwrap();
    let curve_before = first.progress().curve.clone();
    drop(first);

    // Only the 2 newest checkpoints are kept.
    let kept = std::fs::read_dir(&dir)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with("ckpt-")
        })
        .count();
    assert_eq!(kept, 2);

    let mut resumed = Trainer::resume(config(2), envs(), &dir).unwrap();
    assert_eq!(resumed.progress().iterations, 3);
    assert_eq!(resumed.progress().curve, curve_before);
    train(&mut resumed, 5);

    assert_eq!(resumed.progress().samples, straight.progress().samples);
    assert_same(
        &parameters(&straight).unwrap(),
        &parameters(&resumed).unwrap(),
    );
    assert_eq!(straight.normalizer(), resumed.normalizer());
    let a: Vec<f64> = straight
        .progress()
        .curve
        .iter()
        .map(|p| p.mean_reward)
        .collect();
    let b: Vec<f64> = resumed
        .progress()
        .curve
        .iter()
        .map(|p| p.mean_reward)
        .collect();
    assert_eq!(a, b);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn thread_count_does_not_change_the_result() {
    let mut one = Trainer::new(config(1), envs(), 11).unwrap();
    let mut two = Trainer::new(config(2), envs(), 11).unwrap();
    train(&mut one, 2);
    train(&mut two, 2);
    assert_same(&parameters(&one).unwrap(), &parameters(&two).unwrap());
}

#[test]
fn resume_rejects_a_different_network() {
    let dir = std::env::temp_dir().join(format!("ppo-resume-shape-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut t = Trainer::new(config(1), envs(), 1).unwrap();
    t.save_checkpoint(&dir, 1).unwrap();
    let mut other = config(1);
    other.policy.hidden = vec![32];
    let err = Trainer::resume(other, envs(), &dir)
        .err()
        .expect("must fail");
    assert!(err.to_string().contains("hidden sizes"), "{err}");
    assert!(Trainer::<PointMass>::resume(config(1), envs(), &dir.join("nothing")).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn warm_start_copies_networks_but_not_progress() {
    let dir = std::env::temp_dir().join(format!("ppo-warm-start-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut source = Trainer::new(config(1), envs(), 21).unwrap();
    train(&mut source, 2);
    source.save_checkpoint(&dir, 1).unwrap();
    let mut fresh = Trainer::new(config(1), envs(), 22).unwrap();
    assert_ne!(parameters(&fresh).unwrap(), parameters(&source).unwrap());
    fresh.warm_start(&dir).unwrap();
    assert_same(&parameters(&fresh).unwrap(), &parameters(&source).unwrap());
    assert_eq!(fresh.normalizer(), source.normalizer());
    assert_eq!(fresh.progress().iterations, 0);
    std::fs::remove_dir_all(&dir).unwrap();
}
