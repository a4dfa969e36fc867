//! The physically corrected and debiased rows of `motionaug eval table`.
//!
//! Why a module of its own: correction is minutes of PPO per clip, so the
//! table corrects a subset of the VAE's near samples (spread evenly over the
//! set), keeps the work in a folder so an interrupted table resumes where it
//! stopped, and bounds each clip by environment samples rather than wall time,
//! so that the rows do not depend on how busy the machine is. The steps are
//! the pipeline's own (`pipeline::stages`): correct the training clips
//! (originals), correct the samples warm-started from the best corrected
//! original's policy, train the debiasing network on the (corrected original, original)
//! pairs of accepted corrections, apply it to the accepted corrected samples.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use motion::Motion;
use serde::Serialize;

/// How much physics the table spends.
#[derive(clap::Args, Clone, Debug, Serialize)]
pub struct PhysicsArgs {
    /// VAE near samples corrected per class and fold (default: 2 per training clip).
    #[arg(long)]
    pub correct_count: Option<usize>,
    /// Training clips corrected for the debiasing network (default: all).
    #[arg(long)]
    pub correct_originals: Option<usize>,
    /// PPO environment samples per clip at most (training stops earlier once
    /// the clip reaches the target R_norm; a PPO iteration is 4096 samples).
    #[arg(long, default_value_t = 40_960)]
    pub correct_samples: u64,
    /// Wall-time cap per clip, seconds (a safety net; samples are the budget).
    #[arg(long, default_value_t = 600.0)]
    pub correct_budget_s: f64,
    /// Debiasing network optimiser steps.
    #[arg(long, default_value_t = 2000)]
    pub debias_iterations: usize,
}

/// What the correction did to one set, for the table's JSON.
#[derive(Debug, Clone, Serialize, Default)]
pub struct PhysicsSummary {
    pub originals: usize,
    pub originals_accepted: usize,
    /// (corrected, original) pairs the debiaser learnt from: the accepted originals.
    pub debias_pairs: usize,
    pub samples: usize,
    pub samples_accepted: usize,
    /// Mean R_norm of the corrected samples (final rollout).
    pub mean_r_norm: f64,
    /// Mean R_norm of the same samples tracked with action 0.
    pub mean_r_norm_action0: f64,
    pub mean_residual_force_ratio: f64,
    /// PPO samples and wall seconds spent, originals and samples together.
    pub ppo_samples: u64,
    pub seconds: f64,
}

/// The three sets the table compares (the same samples before correction,
/// after it, after debiasing) and what it cost.
pub struct PhysicsSets {
    pub subset: Vec<(String, Motion)>,
    pub corrected: Vec<(String, Motion)>,
    pub debiased: Vec<(String, Motion)>,
    pub summary: PhysicsSummary,
}

/// `count` items spread evenly over `items` (all of them when there are fewer).
pub fn spread<T: Clone>(items: &[T], count: usize) -> Vec<T> {
    if count >= items.len() {
        return items.to_vec();
    }
    (0..count)
        .map(|i| items[i * items.len() / count].clone())
        .collect()
}

fn config(args: &PhysicsArgs, seed: u64) -> correct::CorrectConfig {
    let mut c = pipeline::CorrectStep {
        time_budget_s: args.correct_budget_s,
        ..pipeline::CorrectStep::default()
    }
    .config(seed);
    // One rollout thread: the table runs one class per process, and two
    // processes share this 2-core machine.
    c.ppo.threads = 1;
    c.max_samples = Some(args.correct_samples);
    c
}

/// Corrects `samples` (a subset of them, see [`PhysicsArgs`]) and the training
/// clips in `work`, then debiases; finished corrections in `work` are reused.
pub fn correct_and_debias(
    args: &PhysicsArgs,
    train: &[(String, Motion)],
    samples: &[(String, Motion)],
    work: &Path,
) -> anyhow::Result<PhysicsSets> {
    let started = Instant::now();
    let subset = spread(samples, args.correct_count.unwrap_or(2 * train.len()));
    let originals = spread(train, args.correct_originals.unwrap_or(train.len()));
    anyhow::ensure!(
        !originals.is_empty() && !subset.is_empty(),
        "nothing to correct ({} training clips, {} samples)",
        originals.len(),
        subset.len()
    );
    let mut summary = PhysicsSummary {
        originals: originals.len(),
        samples: subset.len(),
        ..PhysicsSummary::default()
    };
    let total = originals.len() + subset.len();
    let run = |i: usize,
               name: &str,
               m: &Motion,
               dir: &Path,
               warm: Option<&Path>|
     -> anyhow::Result<correct::Outcome> {
        let t = Instant::now();
        let outcome = pipeline::stages::correct_with_config(
            config(args, i as u64),
            name,
            m,
            dir,
            warm,
            |_| {},
        )
        .with_context(|| format!("correcting {name}"))?;
        let r = &outcome.report;
        eprintln!(
            "correct {}/{total} {name}: R_norm {:.3} -> {:.3}, {} samples, {}, {:.1} s",
            i + 1,
            r.r_norm_action0,
            r.r_norm,
            r.samples,
            if r.accepted { "accepted" } else { "rejected" },
            t.elapsed().as_secs_f64()
        );
        Ok(outcome)
    };

    let mut pairs = Vec::with_capacity(originals.len());
    let mut reports = Vec::with_capacity(originals.len());
    for (i, (name, m)) in originals.iter().enumerate() {
        let o = run(i, name, m, &work.join("originals").join(name), None)?;
        summary.ppo_samples += o.report.samples;
        reports.push((o.report.accepted, o.report.r_norm));
        if o.report.accepted {
            pairs.push((o.motion, m.clone()));
        }
    }
    // The samples start from the best corrected original's policy (a VAE
    // sample has no single source clip; session 3 used the first original,
    // whose own correction was rejected on jog and deposit).
    let best = pipeline::stages::best_warm_start(&reports).unwrap_or(0);
    eprintln!(
        "warm start: samples start from the policy of {} (R_norm {:.3}, {})",
        originals[best].0,
        reports[best].1,
        if reports[best].0 {
            "accepted"
        } else {
            "no original was accepted"
        }
    );
    let warm = work
        .join("originals")
        .join(&originals[best].0)
        .join("checkpoints");
    let mut corrected = Vec::new();
    let (mut r, mut r0, mut force) = (0.0, 0.0, 0.0);
    for (k, (name, m)) in subset.iter().enumerate() {
        let o = run(
            originals.len() + k,
            name,
            m,
            &work.join("samples").join(name),
            Some(&warm),
        )?;
        summary.ppo_samples += o.report.samples;
        r += o.report.r_norm;
        r0 += o.report.r_norm_action0;
        force += o.report.residual_force_ratio;
        if o.report.accepted {
            corrected.push((name.clone(), o.motion));
        }
    }
    let n = subset.len() as f64;
    summary.samples_accepted = corrected.len();
    summary.mean_r_norm = r / n;
    summary.mean_r_norm_action0 = r0 / n;
    summary.mean_residual_force_ratio = force / n;

    // The accepted originals are exactly the debiaser's training pairs.
    summary.originals_accepted = pairs.len();
    summary.debias_pairs = pairs.len();
    let debiased = if pairs.is_empty() {
        // Nothing to learn the simulation's bias from: the row stays empty.
        eprintln!("debias: no original passed its correction; no debiased set");
        Vec::new()
    } else {
        let t = Instant::now();
        let model = pipeline::stages::debias_train(
            &debias::TrainConfig {
                iterations: args.debias_iterations,
                ..debias::TrainConfig::default()
            },
            &pairs,
        )?;
        let debiased = corrected
            .iter()
            .map(|(name, m)| Ok((name.clone(), pipeline::stages::debias_apply(&model, m)?)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        eprintln!(
            "debias: trained on {} pairs, applied to {} clips in {:.1} s",
            pairs.len(),
            debiased.len(),
            t.elapsed().as_secs_f64()
        );
        debiased
    };
    summary.seconds = started.elapsed().as_secs_f64();
    Ok(PhysicsSets {
        subset,
        corrected,
        debiased,
        summary,
    })
}

#[cfg(test)]
mod tests {
    use super::spread;

    #[test]
    fn spread_takes_evenly_spaced_items() {
        let v: Vec<usize> = (0..10).collect();
        assert_eq!(spread(&v, 3), vec![0, 3, 6]);
        assert_eq!(spread(&v, 5), vec![0, 2, 4, 6, 8]);
        assert_eq!(spread(&v, 10), v);
        assert_eq!(spread(&v, 20), v);
        assert!(spread(&v, 0).is_empty());
    }
}
