//! Experience collection: the environments are cut into batches of `rollout_batch`
//! (whatever the thread count); a worker thread takes whole batches, steps a batch in
//! lock-step and runs one batched policy + value forward per step for it. Each
//! environment draws its action noise and resets from its own RNG, seeded by the trainer
//! at the start of the iteration, and the observation normaliser is frozen during the
//! rollout (each environment gathers its own statistics, merged afterwards in
//! environment order). So the experience does not depend on how many threads there are
//! or how they are scheduled.
//!
//! Every iteration starts all environments from a reset and ends with a truncation
//! (bootstrapped by the critic), which lets a checkpoint hold the whole training state
//! without the environments' internal state.

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use crate::env::{Env, EnvRng};
use crate::error::{PpoError, Result};
use crate::normalizer::RunningNorm;
use crate::policy::GaussianPolicy;
use crate::value::ValueNet;

pub(crate) const LN_2PI: f32 = 1.837_877_1;

/// One environment's experience over one iteration (T steps, step order).
pub struct Trajectory {
    /// Normalised observations the policy saw, `T * obs_dim`.
    pub obs: Vec<f32>,
    /// Actions taken (mean + noise), `T * act_dim`.
    pub act: Vec<f32>,
    pub logp: Vec<f32>,
    pub value: Vec<f32>,
    pub reward: Vec<f32>,
    pub terminated: Vec<bool>,
    /// Episode cut by the environment or by the end of the iteration.
    pub truncated: Vec<bool>,
    /// V(observation reached) where `truncated`, else 0.
    pub bootstrap: Vec<f32>,
    /// Statistics of the raw observations the policy saw.
    pub stats: RunningNorm,
    /// (return, length) of each episode the environment ended during the iteration.
    pub episodes: Vec<(f64, usize)>,
    pub terminations: usize,
}

/// The frozen networks and normaliser a rollout acts with.
pub(crate) struct Actor<'a> {
    pub policy: &'a GaussianPolicy,
    pub value: &'a ValueNet,
    pub norm: &'a RunningNorm,
    pub std: Vec<f32>,
    pub log_std_sum: f32,
}

/// An environment and its current raw observation.
pub(crate) struct Slot<E> {
    pub env: E,
    pub obs: Vec<f32>,
}

fn check_finite(values: &[f32], index: usize, what: &str) -> Result<()> {
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(PpoError::Env {
            index,
            msg: format!("{what} has a non-finite value at index {i}"),
        });
    }
    Ok(())
}

/// Run `steps` steps on every environment of `slots` (global indices start at `first`).
pub(crate) fn collect<E: Env>(
    slots: &mut [Slot<E>],
    first: usize,
    seeds: &[u64],
    steps: usize,
    actor: &Actor,
) -> Result<Vec<Trajectory>> {
    let n = slots.len();
    if n == 0 {
        return Ok(Vec::new());
    }
    let od = actor.norm.dim();
    let ad = actor.policy.act_dim();
    let mut rngs: Vec<EnvRng> = seeds.iter().map(|&s| EnvRng::seed_from_u64(s)).collect();
    let mut trajs: Vec<Trajectory> = (0..n)
        .map(|_| Trajectory {
            obs: Vec::with_capacity(steps * od),
            act: Vec::with_capacity(steps * ad),
            logp: Vec::with_capacity(steps),
            value: Vec::with_capacity(steps),
            reward: Vec::with_capacity(steps),
            terminated: Vec::with_capacity(steps),
            truncated: Vec::with_capacity(steps),
            bootstrap: vec![0.0; steps],
            stats: RunningNorm::new(od, actor.norm.clip()),
            episodes: Vec::new(),
            terminations: 0,
        })
        .collect();
    for (k, slot) in slots.iter_mut().enumerate() {
        slot.env.reset(&mut rngs[k], &mut slot.obs);
    }
    let mut batch = vec![0.0f32; n * od];
    let mut action = vec![0.0f32; ad];
    let mut ep_return = vec![0.0f64; n];
    let mut ep_len = vec![0usize; n];
    // (env, step) of truncations and their normalised final observations.
    let mut boot_at: Vec<(usize, usize)> = Vec::new();
    let mut boot_obs: Vec<f32> = Vec::new();
    let logp_const = -actor.log_std_sum - 0.5 * LN_2PI * ad as f32;

    for t in 0..steps {
        for (k, slot) in slots.iter().enumerate() {
            check_finite(&slot.obs, first + k, "observation")?;
            trajs[k].stats.push(&slot.obs);
            let row = &mut batch[k * od..(k + 1) * od];
            actor.norm.normalize(&slot.obs, row);
            trajs[k].obs.extend_from_slice(row);
        }
        let x = Tensor::from_slice(&batch, (n, od), &Device::Cpu)?;
        let mean = actor.policy.forward(&x)?.flatten_all()?.to_vec1::<f32>()?;
        let values = actor.value.forward(&x)?.to_vec1::<f32>()?;
        let last = t + 1 == steps;
        for (k, slot) in slots.iter_mut().enumerate() {
            let mut sq = 0.0f32;
            for j in 0..ad {
                let z: f32 = StandardNormal.sample(&mut rngs[k]);
                sq += z * z;
                action[j] = mean[k * ad + j] + actor.std[j] * z;
            }
            let res = slot.env.step(&action, &mut slot.obs);
            if !res.reward.is_finite() {
                return Err(PpoError::Env {
                    index: first + k,
                    msg: format!("non-finite reward {} at step {t}", res.reward),
                });
            }
            let tr = &mut trajs[k];
            tr.act.extend_from_slice(&action);
            tr.logp.push(-0.5 * sq + logp_const);
            tr.value.push(values[k]);
            tr.reward.push(res.reward);
            let truncated = !res.terminated && (res.truncated || last);
            tr.terminated.push(res.terminated);
            tr.truncated.push(truncated);
            ep_return[k] += res.reward as f64;
            ep_len[k] += 1;
            if truncated {
                check_finite(&slot.obs, first + k, "final observation")?;
                let start = boot_obs.len();
                boot_obs.resize(start + od, 0.0);
                actor.norm.normalize(&slot.obs, &mut boot_obs[start..]);
                boot_at.push((k, t));
            }
            if res.terminated || res.truncated {
                tr.episodes.push((ep_return[k], ep_len[k]));
                tr.terminations += res.terminated as usize;
                ep_return[k] = 0.0;
                ep_len[k] = 0;
                if !last {
                    slot.env.reset(&mut rngs[k], &mut slot.obs);
                }
            }
        }
    }
    if !boot_at.is_empty() {
        let x = Tensor::from_slice(&boot_obs, (boot_at.len(), od), &Device::Cpu)?;
        let v = actor.value.forward(&x)?.to_vec1::<f32>()?;
        for (&(k, t), v) in boot_at.iter().zip(v) {
            trajs[k].bootstrap[t] = v;
        }
    }
    Ok(trajs)
}
