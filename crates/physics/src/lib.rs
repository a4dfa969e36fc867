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
//! Measured (release, one thread, `cargo bench -p physics --bench physics`):
//! on the HDM05 kick, 47-58 simulated seconds per wall second at the default
//! 1/120 s step with 4 solver substeps while other builds loaded the machine
//! (127 on a quiet moment), mean joint error 0.075 rad with action 0 and the
//! PD-residual force, no fall. See [`sim`] for the table of step sizes.

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
