//! A toy continuous-control task shared by the integration tests: a point in the plane
//! with first-order velocity dynamics must reach a random target and stay there.

use ppo::{Env, EnvRng, StepResult};
use rand::Rng;

pub struct PointMass {
    pos: [f32; 2],
    vel: [f32; 2],
    target: [f32; 2],
    t: usize,
    pub horizon: usize,
}

impl PointMass {
    pub fn new(horizon: usize) -> Self {
        PointMass {
            pos: [0.0; 2],
            vel: [0.0; 2],
            target: [0.0; 2],
            t: 0,
            horizon,
        }
    }

    fn write_obs(&self, obs: &mut [f32]) {
        obs[0] = self.target[0] - self.pos[0];
        obs[1] = self.target[1] - self.pos[1];
        obs[2] = self.vel[0];
        obs[3] = self.vel[1];
        obs[4] = self.pos[0];
        obs[5] = self.pos[1];
    }
}

impl Env for PointMass {
    fn obs_dim(&self) -> usize {
        6
    }

    fn act_dim(&self) -> usize {
        2
    }

    fn reset(&mut self, rng: &mut EnvRng, obs: &mut [f32]) {
        for i in 0..2 {
            self.pos[i] = rng.random_range(-1.0..1.0);
            self.target[i] = rng.random_range(-1.0..1.0);
            self.vel[i] = 0.0;
        }
        self.t = 0;
        self.write_obs(obs);
    }

    fn step(&mut self, action: &[f32], obs: &mut [f32]) -> StepResult {
        for (i, a) in action.iter().enumerate().take(2) {
            self.vel[i] = 0.7 * self.vel[i] + 0.6 * a.clamp(-1.0, 1.0);
            self.pos[i] += 0.1 * self.vel[i];
        }
        self.t += 1;
        self.write_obs(obs);
        let d2 = obs[0] * obs[0] + obs[1] * obs[1];
        let far = self.pos[0].abs() > 3.0 || self.pos[1].abs() > 3.0;
        StepResult {
            reward: if far { 0.0 } else { (-2.0 * d2).exp() },
            terminated: far,
            truncated: self.t >= self.horizon,
        }
    }
}

/// Mean return of the deterministic policy over `episodes` random starts.
#[allow(dead_code)]
pub fn mean_return<E: Env>(trainer: &ppo::Trainer<E>, episodes: u64) -> f64 {
    use rand::SeedableRng;
    let mut env = PointMass::new(50);
    let mut obs = vec![0.0f32; 6];
    let mut act = vec![0.0f32; 2];
    let mut total = 0.0f64;
    for e in 0..episodes {
        let mut rng = EnvRng::seed_from_u64(1000 + e);
        env.reset(&mut rng, &mut obs);
        loop {
            trainer.act_deterministic(&obs, &mut act).expect("act");
            let r = env.step(&act, &mut obs);
            total += r.reward as f64;
            if r.terminated || r.truncated {
                break;
            }
        }
    }
    total / episodes as f64
}
