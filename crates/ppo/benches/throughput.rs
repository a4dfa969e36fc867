//! Throughput of the learning machinery, independent of any simulator:
//! - policy + value forward per sample at several batch sizes (one thread, and two
//!   threads each running its own batch concurrently, as rollout workers do),
//! - a full PPO iteration on a free environment (obs 250, act 45, like the humanoid),
//!   split into rollout (inference) and update samples per second.
//!
//! For the two net sizes [1024, 512] (reference) and [256, 256].
//! Run: `cargo bench -p ppo --bench throughput`. Like the binaries it keeps candle's
//! kernels on one thread (`nn::threads::init`); set CANDLE_NUM_THREADS=2 to compare.

use std::time::Instant;

use candle_core::{Device, Tensor};
use ppo::{
    Env, EnvRng, GaussianPolicy, PolicyConfig, PpoConfig, RunLimits, StepResult, Trainer,
    ValueConfig, ValueNet,
};

const OBS: usize = 250;
const ACT: usize = 45;

/// An environment that costs nothing, so the figures are the learner's alone.
struct FreeEnv {
    t: usize,
}

impl Env for FreeEnv {
    fn obs_dim(&self) -> usize {
        OBS
    }
    fn act_dim(&self) -> usize {
        ACT
    }
    fn reset(&mut self, _rng: &mut EnvRng, obs: &mut [f32]) {
        self.t = 0;
        for (i, o) in obs.iter_mut().enumerate() {
            *o = (i as f32 * 0.37).sin();
        }
    }
    fn step(&mut self, action: &[f32], obs: &mut [f32]) -> StepResult {
        self.t += 1;
        for (i, o) in obs.iter_mut().enumerate() {
            *o = (i as f32 * 0.37 + self.t as f32 * 0.01).sin() + 0.1 * action[i % ACT];
        }
        StepResult {
            reward: 1.0 - action.iter().map(|a| a * a).sum::<f32>() / ACT as f32,
            terminated: false,
            truncated: self.t >= 300,
        }
    }
}

fn forward_per_sample(policy: &GaussianPolicy, value: &ValueNet, batch: usize, reps: usize) -> f64 {
    let x = Tensor::from_vec(
        (0..batch * OBS)
            .map(|i| (i as f32 * 0.01).sin())
            .collect::<Vec<f32>>(),
        (batch, OBS),
        &Device::Cpu,
    )
    .unwrap();
    let _ = policy.forward(&x).unwrap();
    let t = Instant::now();
    for _ in 0..reps {
        let m = policy
            .forward(&x)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let v = value.forward(&x).unwrap().to_vec1::<f32>().unwrap();
        std::hint::black_box((m, v));
    }
    t.elapsed().as_secs_f64() / (reps * batch) as f64
}

fn main() {
    nn::threads::init();
    println!(
        "candle matmul threads (RAYON_NUM_THREADS or physical cores): {}",
        candle_core::utils::get_num_threads()
    );
    for hidden in [vec![1024, 512], vec![256, 256]] {
        let params = nn::Params::new(0);
        let pcfg = PolicyConfig {
            hidden: hidden.clone(),
            ..PolicyConfig::default()
        };
        let policy = GaussianPolicy::new(&pcfg, OBS, ACT, &params).unwrap();
        let value = ValueNet::new(
            &ValueConfig {
                hidden: hidden.clone(),
            },
            OBS,
            &params,
        )
        .unwrap();
        println!("\nnets {hidden:?} (obs {OBS}, act {ACT}): policy + value forward");
        for batch in [1usize, 8, 32, 128] {
            let reps = (4096 / batch).max(8);
            let s = forward_per_sample(&policy, &value, batch, reps);
            println!(
                "  batch {batch:4}, 1 caller : {:8.1} us/sample  {:9.0} samples/s",
                s * 1e6,
                1.0 / s
            );
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        for batch in [8usize, 32] {
            let reps = (4096 / batch).max(8);
            let t = Instant::now();
            pool.install(|| {
                rayon::join(
                    || forward_per_sample(&policy, &value, batch, reps),
                    || forward_per_sample(&policy, &value, batch, reps),
                )
            });
            let s = t.elapsed().as_secs_f64() / (2 * reps * batch) as f64;
            println!(
                "  batch {batch:4}, 2 callers: {:8.1} us/sample  {:9.0} samples/s (aggregate)",
                s * 1e6,
                1.0 / s
            );
        }

        for threads in [1usize, 2] {
            let config = PpoConfig {
                policy: pcfg.clone(),
                value: ValueConfig {
                    hidden: hidden.clone(),
                },
                samples_per_iteration: 8192,
                minibatch_size: 2048,
                epochs: 2,
                threads,
                // The two threads' halves, as before batches were fixed.
                rollout_batch: 16,
                norm_warmup_steps: 1,
                ..PpoConfig::reference()
            };
            let envs = (0..32).map(|_| FreeEnv { t: 0 }).collect();
            let mut trainer = Trainer::new(config, envs, 1).unwrap();
            let mut rollout = 0.0;
            let mut update = 0.0;
            let mut samples = 0usize;
            let limits = RunLimits {
                max_iterations: Some(2),
                ..RunLimits::default()
            };
            trainer
                .run(&limits, |_, r| {
                    rollout += r.rollout_s;
                    update += r.update_s;
                    samples += r.iteration_samples;
                    ppo::Control::Continue
                })
                .unwrap();
            if threads == 1 {
                let mut env = FreeEnv { t: 0 };
                let t = Instant::now();
                let ev = trainer.evaluate(&mut env, 300).unwrap();
                let on_eval_thread = t.elapsed().as_secs_f64() / ev.rewards.len() as f64;
                let mut obs = vec![0.0f32; OBS];
                let mut act = vec![0.0f32; ACT];
                env.reset_eval(&mut obs);
                let t = Instant::now();
                for _ in 0..300 {
                    trainer.act_deterministic(&obs, &mut act).unwrap();
                    env.step(&act, &mut obs);
                }
                let on_caller = t.elapsed().as_secs_f64() / 300.0;
                println!(
                    "  deterministic evaluation: {:.1} us/step on the evaluation thread, {:.1} us/step calling act_deterministic from main",
                    on_eval_thread * 1e6,
                    on_caller * 1e6
                );
            }
            println!(
                "  trainer, {threads} rollout thread(s), 32 envs: rollout {:9.0} samples/s; update {:9.0} sample-epochs/s ({:.1} us per sample-epoch)",
                samples as f64 / rollout,
                (samples * 2) as f64 / update,
                update / (samples * 2) as f64 * 1e6
            );
        }
    }
}
