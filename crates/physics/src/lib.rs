//! Physical correction, simulation side: a humanoid built from any mocap
//! skeleton, simulated with rapier3d, and the imitation environment a policy
//! learns in (MotionAug Sec. 3.3, DeepMimic with a PD-residual root force).
//!
//! * [`character`]: file skeleton -> simulated bodies (mapping rules, shapes, masses, gains).
//! * [`sim`]: the rapier world, impulse spherical joints, our own stable PD torques.
//! * [`reference`]: the clip resampled to the control rate, per body, with velocities.
//! * [`env`]: the imitation environment (observation, action, reward, termination,
//!   PD-residual / learned / no root force, recording the simulated motion).
//! * [`bench`]: speed and action-0 tracking figures.
//!
//! The crate knows nothing of learning: `reset`/`step` take and return plain `f32` slices.
//!
//! ```no_run
//! # fn demo(clip: &motion::Motion) -> Result<(), physics::PhysicsError> {
//! let mut env = physics::ImitationEnv::new(clip, &physics::Config::default())?;
//! env.reset_seeded(1); // reference state initialisation at a random phase
//! let action = vec![0.0; env.act_dim()]; // 0 = track the reference
//! loop {
//!     let r = env.step(&action)?; // new observation in env.obs()
//!     if r.done { break; }
//! }
//! let simulated = env.recorded_motion()?; // on the clip's own skeleton
//! # Ok(()) }
//! ```
//!
//! Measured (release, one thread, `motionaug bench physics --seconds 3` on the
//! bundled HDM05 kick, action 0 with the PD-residual force, 4 interleaved
//! rounds in one run with the former default and pybullet while other builds
//! loaded the machine): 208-280 simulated seconds per wall second at the
//! default 1/60 s step with 2 substeps of 5 PGS passes, against 86-116 at the
//! former 1/120 s with 4 substeps of one pass (2.35x, per-round median);
//! mean joint error 0.076 rad (was 0.080), no fall. Against pybullet's
//! DeepMimic humanoid at 1/1200 s (`benches/physics_vs_pybullet.sh 5`):
//! 43-58x, median 50x (the former default: 15-23x, median 23x). See [`sim`]
//! for the profile, the table of steps, substeps and passes, and foot skating.

pub mod bench;
pub mod character;
pub mod env;
pub mod fixtures;
pub mod reference;
pub mod sim;

pub use bench::{BenchReport, bench_physics};
pub use character::{
    CharacterOptions, CharacterSpec, FootCalibration, JointMapping, MappingLine, Role, Shape, Side,
};
pub use env::{Config, FootContact, ImitationEnv, OutputFrame, Residual, StepInfo, StepResult};
pub use sim::{BodyState, Sim, SimParams};

#[derive(Debug, thiserror::Error)]
pub enum PhysicsError {
    #[error("cannot build a character from this skeleton: {0}")]
    Character(String),
    #[error("invalid physics configuration: {0}")]
    Config(String),
    #[error("action has {got} values, expected {expected}")]
    ActionSize { got: usize, expected: usize },
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
}
