//! The PPO loop: collect a batch across the environments in parallel, estimate
//! advantages, run clipped-surrogate minibatch epochs with separate Adam optimisers for
//! the actor and the critic; plus deterministic evaluation, time-budgeted runs with a
//! per-iteration callback, periodic checkpoints and resume.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::{DType, Device, Tensor, Var};
use rand::seq::SliceRandom;
use rand::{RngCore, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use nn::{AdamConfig, Optimizer, Params};

use crate::checkpoint::{self, CheckpointMeta};
use crate::config::PpoConfig;
use crate::env::{Env, EnvRng};
use crate::error::{PpoError, Result};
use crate::gae::{self, GaeInput};
use crate::normalizer::RunningNorm;
use crate::policy::GaussianPolicy;
use crate::rollout::{self, Actor, Slot, Trajectory};
use crate::value::ValueNet;

/// One point of the learning curve (one per iteration).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    pub iteration: u64,
    pub samples: u64,
    pub wall_s: f64,
    /// Mean per-step reward over the iteration's batch.
    pub mean_reward: f64,
    /// Set by `Trainer::record_eval` (e.g. the caller's normalised evaluation reward).
    pub eval: Option<f64>,
}

/// Cumulative training progress (survives checkpoints).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    pub iterations: u64,
    pub samples: u64,
    /// Wall time spent in this job so far, across resumes.
    pub wall_s: f64,
    pub curve: Vec<CurvePoint>,
    /// Facts about the run that a resume must know and the trainer does not
    /// (e.g. a reward term the caller switched on part-way): saved with the
    /// checkpoint, read back on resume, never interpreted here.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub notes: std::collections::BTreeMap<String, String>,
}

/// What one iteration did.
#[derive(Clone, Debug, PartialEq)]
pub struct IterationReport {
    /// Iterations completed, including this one.
    pub iteration: u64,
    /// Total samples so far.
    pub samples: u64,
    pub iteration_samples: usize,
    pub wall_s: f64,
    pub rollout_s: f64,
    pub update_s: f64,
    pub mean_reward: f64,
    /// Over episodes the environments ended (terminated or truncated) in this iteration.
    pub mean_episode_return: Option<f64>,
    pub mean_episode_len: Option<f64>,
    pub episodes: usize,
    pub terminations: usize,
    pub policy_loss: f64,
    pub value_loss: f64,
    pub approx_kl: f64,
    pub clip_fraction: f64,
}

/// A deterministic (mean-action) episode.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation {
    pub rewards: Vec<f32>,
    pub terminated: bool,
    pub truncated: bool,
}

impl Evaluation {
    pub fn total(&self) -> f64 {
        self.rewards.iter().map(|&r| r as f64).sum()
    }
}

/// Returned by the per-iteration callback of [`Trainer::run`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    Continue,
    Stop,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    TimeBudget,
    MaxIterations,
    MaxSamples,
    Callback,
}

/// Limits of [`Trainer::run`]; all counts and times are cumulative over the job
/// (including iterations done before a resume).
#[derive(Clone, Debug, Default)]
pub struct RunLimits {
    /// Stop before an iteration that would (judging by the previous one) end past it.
    pub time_budget_s: Option<f64>,
    pub max_iterations: Option<u64>,
    pub max_samples: Option<u64>,
    /// Write checkpoints here every `checkpoint_every_s` (0: after every iteration) and
    /// when the run stops.
    pub checkpoint_dir: Option<PathBuf>,
    pub checkpoint_every_s: f64,
    /// Checkpoints kept in the directory (at least 1).
    pub keep_checkpoints: usize,
}

struct Batch {
    obs: Vec<f32>,
    act: Vec<f32>,
    logp: Vec<f32>,
    adv: Vec<f32>,
    ret: Vec<f32>,
}

#[derive(Default)]
struct UpdateStats {
    policy_loss: f64,
    value_loss: f64,
    approx_kl: f64,
    clip_fraction: f64,
}

pub struct Trainer<E: Env> {
    config: PpoConfig,
    slots: Vec<Slot<E>>,
    obs_dim: usize,
    act_dim: usize,
    policy: GaussianPolicy,
    value: ValueNet,
    policy_opt: Optimizer,
    value_opt: Optimizer,
    norm: RunningNorm,
    rng: EnvRng,
    progress: Progress,
    pool: std::sync::Arc<rayon::ThreadPool>,
    /// One thread: batch-1 evaluation is dominated by thread hand-offs when candle's
    /// matmuls split across the global pool, so evaluation runs here instead.
    serial_pool: std::sync::Arc<rayon::ThreadPool>,
    /// `progress.wall_s` when this process took the job over, and since when.
    wall_base: f64,
    session_start: Instant,
}

impl<E: Env> Trainer<E> {
    /// A fresh trainer; all randomness (initial weights, resets, noise, minibatches)
    /// derives from `seed`.
    pub fn new(config: PpoConfig, envs: Vec<E>, seed: u64) -> Result<Self> {
        config.validate()?;
        let Some(first) = envs.first() else {
            return Err(PpoError::Config(
                "at least one environment is needed".into(),
            ));
        };
        let (obs_dim, act_dim) = (first.obs_dim(), first.act_dim());
        if obs_dim == 0 || act_dim == 0 {
            return Err(PpoError::Config(format!(
                "environment dimensions must be > 0 (obs {obs_dim}, act {act_dim})"
            )));
        }
        for (i, e) in envs.iter().enumerate() {
            if e.obs_dim() != obs_dim || e.act_dim() != act_dim {
                return Err(PpoError::Env {
                    index: i,
                    msg: format!(
                        "dimensions obs {} act {} differ from environment 0 (obs {obs_dim} act {act_dim})",
                        e.obs_dim(),
                        e.act_dim()
                    ),
                });
            }
        }
        // One generator: the networks' initial weights first, then rollouts.
        let params = Params::from_rng(EnvRng::seed_from_u64(seed));
        let policy = GaussianPolicy::new(&config.policy, obs_dim, act_dim, &params)?;
        let value = ValueNet::new(&config.value, obs_dim, &params)?;
        let rng = params.rng()?;
        let opt = |vars, lr| Optimizer::new(vars, AdamConfig::new(lr), config.max_grad_norm);
        let policy_opt = opt(policy.vars(), config.policy_lr);
        let value_opt = opt(value.vars(), config.value_lr);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads)
            .thread_name(|i| format!("ppo-rollout-{i}"))
            .build()
            .map(std::sync::Arc::new)
            .map_err(|e| {
                PpoError::Config(format!("cannot start {} threads: {e}", config.threads))
            })?;
        let serial_pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .thread_name(|_| "ppo-eval".to_string())
            .build()
            .map(std::sync::Arc::new)
            .map_err(|e| PpoError::Config(format!("cannot start the evaluation thread: {e}")))?;
        let slots = envs
            .into_iter()
            .map(|env| Slot {
                env,
                obs: vec![0.0; obs_dim],
            })
            .collect();
        Ok(Trainer {
            norm: RunningNorm::new(obs_dim, config.obs_clip),
            config,
            slots,
            obs_dim,
            act_dim,
            policy,
            value,
            policy_opt,
            value_opt,
            rng,
            progress: Progress::default(),
            pool,
            serial_pool,
            wall_base: 0.0,
            session_start: Instant::now(),
        })
    }

    /// Continue the job whose checkpoints are in `dir` (see [`checkpoint`]). The network
    /// shapes in `config` must match the checkpoint's; other hyper-parameters are taken
    /// from `config` (identical ones give an identical continuation).
    pub fn resume(config: PpoConfig, envs: Vec<E>, dir: &Path) -> Result<Self> {
        let path = checkpoint::latest_checkpoint(dir)?
            .ok_or_else(|| PpoError::checkpoint(dir, "no checkpoint found"))?;
        Self::load_checkpoint(config, envs, &path)
    }

    /// Resume from `dir` if it holds a checkpoint, else start fresh with `seed`.
    /// The flag says whether it resumed.
    pub fn new_or_resume(
        config: PpoConfig,
        envs: Vec<E>,
        seed: u64,
        dir: &Path,
    ) -> Result<(Self, bool)> {
        match checkpoint::latest_checkpoint(dir)? {
            Some(path) => Ok((Self::load_checkpoint(config, envs, &path)?, true)),
            None => Ok((Self::new(config, envs, seed)?, false)),
        }
    }

    /// Load one checkpoint directory.
    pub fn load_checkpoint(config: PpoConfig, envs: Vec<E>, path: &Path) -> Result<Self> {
        let (meta, tensors) = checkpoint::load(path)?;
        let mut t = Self::new(config, envs, 0)?;
        t.apply_weights(path, &meta, &tensors)?;
        t.policy_opt
            .load_state("opt.policy", &tensors, meta.policy_opt_steps)?;
        t.value_opt
            .load_state("opt.value", &tensors, meta.value_opt_steps)?;
        t.rng = meta
            .rng
            .restore()
            .map_err(|e| PpoError::checkpoint(path, e))?;
        t.wall_base = meta.progress.wall_s;
        t.progress = meta.progress;
        t.session_start = Instant::now();
        tracing::info!(
            checkpoint = %path.display(),
            iterations = t.progress.iterations,
            samples = t.progress.samples,
            "resumed"
        );
        Ok(t)
    }

    /// Warm start: copy the policy, value and normaliser of another job's checkpoint
    /// (`path` is a checkpoint directory or a directory of checkpoints, whose latest is
    /// used) into this trainer. Optimiser state, RNG and progress stay this trainer's own.
    /// Network shapes and dimensions must match. Returns the checkpoint used.
    pub fn warm_start(&mut self, path: &Path) -> Result<PathBuf> {
        let ckpt = if path.join(checkpoint::STATE_FILE).is_file() {
            path.to_path_buf()
        } else {
            checkpoint::latest_checkpoint(path)?
                .ok_or_else(|| PpoError::checkpoint(path, "no checkpoint found"))?
        };
        let (meta, tensors) = checkpoint::load(&ckpt)?;
        self.apply_weights(&ckpt, &meta, &tensors)?;
        tracing::info!(checkpoint = %ckpt.display(), "warm start");
        Ok(ckpt)
    }

    /// Check that a checkpoint fits this trainer and copy its networks and normaliser.
    fn apply_weights(
        &mut self,
        path: &Path,
        meta: &CheckpointMeta,
        tensors: &HashMap<String, Tensor>,
    ) -> Result<()> {
        let mismatch = |what: &str, saved: String, now: String| {
            PpoError::checkpoint(
                path,
                format!("{what} is {saved} in the checkpoint but {now} now"),
            )
        };
        if (meta.obs_dim, meta.act_dim) != (self.obs_dim, self.act_dim) {
            return Err(mismatch(
                "(obs_dim, act_dim)",
                format!("{:?}", (meta.obs_dim, meta.act_dim)),
                format!("{:?}", (self.obs_dim, self.act_dim)),
            ));
        }
        let (a, b) = (&meta.config, &self.config);
        if a.policy.hidden != b.policy.hidden || a.value.hidden != b.value.hidden {
            return Err(mismatch(
                "hidden sizes (policy, value)",
                format!("{:?}", (&a.policy.hidden, &a.value.hidden)),
                format!("{:?}", (&b.policy.hidden, &b.value.hidden)),
            ));
        }
        if a.policy.learn_log_std != b.policy.learn_log_std {
            return Err(mismatch(
                "policy.learn_log_std",
                a.policy.learn_log_std.to_string(),
                b.policy.learn_log_std.to_string(),
            ));
        }
        // Check every tensor before changing anything.
        let vars: Vec<(String, Var)> = self
            .policy
            .vars()
            .into_iter()
            .chain(self.value.vars())
            .collect();
        let mut sources = Vec::with_capacity(vars.len());
        for (name, var) in &vars {
            let src = tensors
                .get(name)
                .ok_or_else(|| PpoError::checkpoint(path, format!("tensor `{name}` missing")))?;
            if src.dims() != var.dims() || src.dtype() != DType::F32 {
                return Err(PpoError::checkpoint(
                    path,
                    format!(
                        "tensor `{name}` is {:?} {:?}, expected F32 {:?}",
                        src.dtype(),
                        src.dims(),
                        var.dims()
                    ),
                ));
            }
            sources.push(src);
        }
        let get64 = |name: &str| -> Result<Vec<f64>> {
            let v = tensors
                .get(name)
                .ok_or_else(|| PpoError::checkpoint(path, format!("tensor `{name}` missing")))?;
            Ok(v.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()?)
        };
        let count = *get64("norm.count")?
            .first()
            .ok_or_else(|| PpoError::checkpoint(path, "tensor `norm.count` is empty"))?;
        let norm = RunningNorm::from_parts(
            count,
            get64("norm.mean")?,
            get64("norm.m2")?,
            self.config.obs_clip,
        )
        .map_err(|e| PpoError::checkpoint(path, e.to_string()))?;
        if norm.dim() != self.obs_dim {
            return Err(PpoError::checkpoint(
                path,
                "normaliser size differs from obs_dim",
            ));
        }
        for ((_, var), src) in vars.iter().zip(sources) {
            var.set(src)?;
        }
        self.norm = norm;
        Ok(())
    }

    /// Write a checkpoint into `dir`, keeping the `keep` most recent. Returns its path.
    pub fn save_checkpoint(&mut self, dir: &Path, keep: usize) -> Result<PathBuf> {
        self.progress.wall_s = self.wall_s();
        let mut tensors: Vec<(String, Tensor)> = Vec::new();
        for (name, var) in self.policy.vars().into_iter().chain(self.value.vars()) {
            tensors.push((name, var.as_tensor().copy()?));
        }
        tensors.extend(self.policy_opt.state_tensors("opt.policy")?);
        tensors.extend(self.value_opt.state_tensors("opt.value")?);
        let dev = &Device::Cpu;
        tensors.push((
            "norm.count".into(),
            Tensor::from_slice(&[self.norm.count()], 1, dev)?,
        ));
        tensors.push((
            "norm.mean".into(),
            Tensor::from_slice(self.norm.mean(), self.obs_dim, dev)?,
        ));
        tensors.push((
            "norm.m2".into(),
            Tensor::from_slice(self.norm.m2(), self.obs_dim, dev)?,
        ));
        let meta = CheckpointMeta::new(
            self.obs_dim,
            self.act_dim,
            self.config.clone(),
            self.progress.clone(),
            &self.rng,
            self.policy_opt.steps(),
            self.value_opt.steps(),
        );
        checkpoint::save(dir, &meta, &tensors, keep)
    }

    pub fn config(&self) -> &PpoConfig {
        &self.config
    }

    pub fn progress(&self) -> &Progress {
        &self.progress
    }

    /// Record a fact about the run in its checkpoints ([`Progress::notes`]).
    pub fn set_note(&mut self, key: &str, value: String) {
        self.progress.notes.insert(key.to_string(), value);
    }

    pub fn policy(&self) -> &GaussianPolicy {
        &self.policy
    }

    pub fn value(&self) -> &ValueNet {
        &self.value
    }

    pub fn normalizer(&self) -> &RunningNorm {
        &self.norm
    }

    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// The training environments (e.g. to read their statistics).
    pub fn envs(&self) -> impl Iterator<Item = &E> {
        self.slots.iter().map(|s| &s.env)
    }

    /// The training environments, mutably (e.g. to change a curriculum setting between
    /// iterations; every iteration starts by resetting them).
    pub fn envs_mut(&mut self) -> impl Iterator<Item = &mut E> {
        self.slots.iter_mut().map(|s| &mut s.env)
    }

    /// Cumulative wall time of the job, including time before a resume.
    pub fn wall_s(&self) -> f64 {
        self.wall_base + self.session_start.elapsed().as_secs_f64()
    }

    /// Attach an evaluation score to the latest curve point.
    pub fn record_eval(&mut self, value: f64) {
        if let Some(p) = self.progress.curve.last_mut() {
            p.eval = Some(value);
        }
    }

    /// Collect `steps` steps on every environment in parallel.
    fn collect(&mut self, steps: usize) -> Result<Vec<Trajectory>> {
        let seeds: Vec<u64> = (0..self.slots.len()).map(|_| self.rng.next_u64()).collect();
        // Batches of a fixed size, whatever the thread count: a thread takes
        // whole batches, so the experience is the same on any number of them.
        let chunk = self.config.rollout_batch.clamp(1, self.slots.len().max(1));
        let log_std = self.policy.log_std().to_vec1::<f32>()?;
        let actor = Actor {
            policy: &self.policy,
            value: &self.value,
            norm: &self.norm,
            std: log_std.iter().map(|l| l.exp()).collect(),
            log_std_sum: log_std.iter().sum(),
        };
        let slots = &mut self.slots;
        let parts: Vec<Result<Vec<Trajectory>>> = self.pool.install(|| {
            slots
                .par_chunks_mut(chunk)
                .zip(seeds.par_chunks(chunk))
                .enumerate()
                .map(|(i, (s, seeds))| rollout::collect(s, i * chunk, seeds, steps, &actor))
                .collect()
        });
        let mut out = Vec::with_capacity(self.slots.len());
        for p in parts {
            out.extend(p?);
        }
        Ok(out)
    }

    /// One PPO iteration: rollout, advantages, update.
    pub fn iterate(&mut self) -> Result<IterationReport> {
        let t0 = Instant::now();
        if self.norm.count() == 0.0 && self.config.norm_warmup_steps > 0 {
            for tr in self.collect(self.config.norm_warmup_steps)? {
                self.norm.merge(&tr.stats);
            }
        }
        let steps = self.config.samples_per_iteration.div_ceil(self.slots.len());
        let trajs = self.collect(steps)?;
        let rollout_s = t0.elapsed().as_secs_f64();
        for tr in &trajs {
            self.norm.merge(&tr.stats);
        }
        let batch = self.assemble(&trajs);
        let n = batch.logp.len();
        let reward_sum: f64 = trajs
            .iter()
            .flat_map(|t| &t.reward)
            .map(|&r| r as f64)
            .sum();
        let episodes: Vec<(f64, usize)> = trajs
            .iter()
            .flat_map(|t| t.episodes.iter().copied())
            .collect();
        let terminations = trajs.iter().map(|t| t.terminations).sum();
        drop(trajs);
        let t1 = Instant::now();
        let pool = self.pool.clone();
        let stats = pool.install(|| self.update(batch))?;
        let update_s = t1.elapsed().as_secs_f64();

        self.progress.iterations += 1;
        self.progress.samples += n as u64;
        self.progress.wall_s = self.wall_s();
        let mean_reward = reward_sum / n as f64;
        self.progress.curve.push(CurvePoint {
            iteration: self.progress.iterations,
            samples: self.progress.samples,
            wall_s: self.progress.wall_s,
            mean_reward,
            eval: None,
        });
        let n_ep = episodes.len();
        let report = IterationReport {
            iteration: self.progress.iterations,
            samples: self.progress.samples,
            iteration_samples: n,
            wall_s: self.progress.wall_s,
            rollout_s,
            update_s,
            mean_reward,
            mean_episode_return: (n_ep > 0)
                .then(|| episodes.iter().map(|e| e.0).sum::<f64>() / n_ep as f64),
            mean_episode_len: (n_ep > 0)
                .then(|| episodes.iter().map(|e| e.1 as f64).sum::<f64>() / n_ep as f64),
            episodes: n_ep,
            terminations,
            policy_loss: stats.policy_loss,
            value_loss: stats.value_loss,
            approx_kl: stats.approx_kl,
            clip_fraction: stats.clip_fraction,
        };
        tracing::debug!(?report, "ppo iteration");
        Ok(report)
    }

    /// Advantages per environment, then everything concatenated in environment order.
    fn assemble(&self, trajs: &[Trajectory]) -> Batch {
        let n: usize = trajs.iter().map(|t| t.reward.len()).sum();
        let mut b = Batch {
            obs: Vec::with_capacity(n * self.obs_dim),
            act: Vec::with_capacity(n * self.act_dim),
            logp: Vec::with_capacity(n),
            adv: vec![0.0; n],
            ret: vec![0.0; n],
        };
        let mut at = 0;
        for t in trajs {
            let len = t.reward.len();
            gae::compute(
                &GaeInput {
                    rewards: &t.reward,
                    values: &t.value,
                    terminated: &t.terminated,
                    truncated: &t.truncated,
                    bootstrap: &t.bootstrap,
                },
                self.config.gamma,
                self.config.lambda,
                &mut b.adv[at..at + len],
                &mut b.ret[at..at + len],
            );
            b.obs.extend_from_slice(&t.obs);
            b.act.extend_from_slice(&t.act);
            b.logp.extend_from_slice(&t.logp);
            at += len;
        }
        if self.config.normalize_advantages && n > 1 {
            let mean = b.adv.iter().map(|&a| a as f64).sum::<f64>() / n as f64;
            let var = b
                .adv
                .iter()
                .map(|&a| (a as f64 - mean).powi(2))
                .sum::<f64>()
                / n as f64;
            let inv = 1.0 / (var.sqrt() + 1e-8);
            for a in &mut b.adv {
                *a = ((*a as f64 - mean) * inv) as f32;
            }
        }
        b
    }

    fn update(&mut self, b: Batch) -> Result<UpdateStats> {
        let n = b.logp.len();
        let dev = &Device::Cpu;
        let obs = Tensor::from_vec(b.obs, (n, self.obs_dim), dev)?;
        let act = Tensor::from_vec(b.act, (n, self.act_dim), dev)?;
        let logp_old = Tensor::from_vec(b.logp, n, dev)?;
        let adv = Tensor::from_vec(b.adv, n, dev)?;
        let ret = Tensor::from_vec(b.ret, n, dev)?;
        let clip = self.config.clip as f64;
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut stats = UpdateStats::default();
        let mut count = 0usize;
        for _ in 0..self.config.epochs {
            order.shuffle(&mut self.rng);
            for mb in order.chunks(self.config.minibatch_size) {
                let idx = Tensor::from_slice(mb, mb.len(), dev)?;
                let o = obs.index_select(&idx, 0)?;
                let a = act.index_select(&idx, 0)?;
                let lp_old = logp_old.index_select(&idx, 0)?;
                let ad = adv.index_select(&idx, 0)?;
                let r = ret.index_select(&idx, 0)?;

                let logp = self.policy.log_prob(&o, &a)?;
                let ratio = logp.sub(&lp_old)?.exp()?;
                let surr1 = ratio.mul(&ad)?;
                let surr2 = ratio.clamp(1.0 - clip, 1.0 + clip)?.mul(&ad)?;
                let mut policy_loss = surr1.minimum(&surr2)?.mean_all()?.neg()?;
                if self.config.entropy_coef != 0.0 && self.config.policy.learn_log_std {
                    let ent = self.policy.entropy()?;
                    policy_loss =
                        policy_loss.sub(&ent.affine(self.config.entropy_coef as f64, 0.0)?)?;
                }
                let value_loss = self.value.forward(&o)?.sub(&r)?.sqr()?.mean_all()?;
                let grads = policy_loss.add(&value_loss)?.backward()?;
                self.policy_opt.step(&grads)?;
                self.value_opt.step(&grads)?;

                stats.policy_loss += policy_loss.to_scalar::<f32>()? as f64;
                stats.value_loss += value_loss.to_scalar::<f32>()? as f64;
                stats.approx_kl += lp_old.sub(&logp)?.mean_all()?.to_scalar::<f32>()? as f64;
                let clipped = ratio
                    .affine(1.0, -1.0)?
                    .abs()?
                    .gt(clip)?
                    .to_dtype(DType::F32)?;
                stats.clip_fraction += clipped.mean_all()?.to_scalar::<f32>()? as f64;
                count += 1;
            }
        }
        let c = count.max(1) as f64;
        stats.policy_loss /= c;
        stats.value_loss /= c;
        stats.approx_kl /= c;
        stats.clip_fraction /= c;
        Ok(stats)
    }

    /// Mean action for one raw observation (normaliser frozen).
    pub fn act_deterministic(&self, obs: &[f32], action: &mut [f32]) -> Result<()> {
        mean_action(&self.policy, &self.norm, obs, action)
    }

    /// Run one deterministic episode from `env.reset_eval` with mean actions, for at most
    /// `max_steps` steps. The normaliser is not updated. Returns the per-step rewards.
    /// Runs on the trainer's single evaluation thread (see `serial_pool`).
    pub fn evaluate<V: Env + ?Sized>(&self, env: &mut V, max_steps: usize) -> Result<Evaluation> {
        let (policy, norm) = (&self.policy, &self.norm);
        self.serial_pool
            .install(|| evaluate_episode(policy, norm, env, max_steps))
    }

    /// Iterate until a limit is reached or `on_iteration` returns [`Control::Stop`].
    /// The callback may evaluate and call [`Trainer::record_eval`]. With a checkpoint
    /// directory, a checkpoint is written every `checkpoint_every_s` and at the end.
    pub fn run<F>(&mut self, limits: &RunLimits, mut on_iteration: F) -> Result<StopReason>
    where
        F: FnMut(&mut Self, &IterationReport) -> Control,
    {
        let mut last_ckpt = Instant::now();
        let mut last_iter_s = 0.0f64;
        let reason = loop {
            if limits
                .max_iterations
                .is_some_and(|m| self.progress.iterations >= m)
            {
                break StopReason::MaxIterations;
            }
            if limits
                .max_samples
                .is_some_and(|m| self.progress.samples >= m)
            {
                break StopReason::MaxSamples;
            }
            if limits
                .time_budget_s
                .is_some_and(|b| self.wall_s() + last_iter_s > b)
            {
                break StopReason::TimeBudget;
            }
            let t = Instant::now();
            let report = self.iterate()?;
            let control = on_iteration(self, &report);
            last_iter_s = t.elapsed().as_secs_f64();
            if control == Control::Stop {
                break StopReason::Callback;
            }
            if let Some(dir) = &limits.checkpoint_dir
                && last_ckpt.elapsed().as_secs_f64() >= limits.checkpoint_every_s
            {
                self.save_checkpoint(dir, limits.keep_checkpoints)?;
                last_ckpt = Instant::now();
            }
        };
        if let Some(dir) = &limits.checkpoint_dir {
            self.save_checkpoint(dir, limits.keep_checkpoints)?;
        }
        Ok(reason)
    }
}

/// Weights and normaliser of a trainer, for comparisons in tests and tools.
pub fn parameters<E: Env>(t: &Trainer<E>) -> Result<HashMap<String, Vec<f32>>> {
    let mut m = HashMap::new();
    for (name, v) in t.policy().vars().into_iter().chain(t.value().vars()) {
        m.insert(name, v.as_tensor().flatten_all()?.to_vec1::<f32>()?);
    }
    Ok(m)
}

/// The policy's mean action for one raw observation (normaliser frozen): the
/// deterministic action, usable from several threads at once.
pub fn mean_action(
    policy: &GaussianPolicy,
    norm: &RunningNorm,
    obs: &[f32],
    action: &mut [f32],
) -> Result<()> {
    let (od, ad) = (norm.dim(), policy.act_dim());
    if obs.len() != od || action.len() != ad {
        return Err(PpoError::Config(format!(
            "act_deterministic: obs has {} values (expected {od}), action {} (expected {ad})",
            obs.len(),
            action.len(),
        )));
    }
    let mut x = vec![0.0f32; od];
    norm.normalize(obs, &mut x);
    let x = Tensor::from_vec(x, (1, od), &Device::Cpu)?;
    let mean = policy.forward(&x)?.flatten_all()?.to_vec1::<f32>()?;
    action.copy_from_slice(&mean);
    Ok(())
}

fn evaluate_episode<V: Env + ?Sized>(
    policy: &GaussianPolicy,
    norm: &RunningNorm,
    env: &mut V,
    max_steps: usize,
) -> Result<Evaluation> {
    let (od, ad) = (norm.dim(), policy.act_dim());
    if env.obs_dim() != od || env.act_dim() != ad {
        return Err(PpoError::Config(format!(
            "evaluation environment has obs {} act {}, the policy obs {od} act {ad}",
            env.obs_dim(),
            env.act_dim(),
        )));
    }
    let mut obs = vec![0.0f32; od];
    let mut action = vec![0.0f32; ad];
    env.reset_eval(&mut obs);
    let mut ev = Evaluation {
        rewards: Vec::new(),
        terminated: false,
        truncated: false,
    };
    for _ in 0..max_steps {
        mean_action(policy, norm, &obs, &mut action)?;
        let r = env.step(&action, &mut obs);
        ev.rewards.push(r.reward);
        if r.terminated || r.truncated {
            ev.terminated = r.terminated;
            ev.truncated = r.truncated && !r.terminated;
            break;
        }
    }
    Ok(ev)
}
