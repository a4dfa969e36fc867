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
//!
//! Session 15 (2026-12-04), a quiet core (`taskset -c 1`, the other core
//! running a correction), `benches/physics_vs_pybullet.sh 3`: ours 401-416
//! simulated s per wall s (42 us per physics step), pybullet 8.3-8.6: **48x,
//! 50x, 48x, median 48x**, short of the issue's 100x. What limits it, from
//! `perf record` of the same run and rapier 0.36's source: 37 % of the time
//! is `JointConstraint<f32, 1>::solve`, the *scalar* joint solver, and 4 %
//! its `finalize_constraints`. Rapier solves joints four at a time (SIMD)
//! only when (a) the joint has no motor on a free axis
//! (`GenericJoint::supports_simd_constraints`: in 3-D any motor on an
//! unlocked axis excludes it) and (b) a colour of body-disjoint joints
//! holds at least 64 joints (`JOINT_BATCH * LAYOUT_REF_WORKERS / 2`);
//! our PD motors fail (a) and a 15-joint tree fails (b), so batching many
//! characters into one world would not reach the SIMD path either. Among the rest:
//! contacts 5 %, narrow phase 3 %, rapier's stage bookkeeping and copies
//! 13 %, row rebuilds 4 %, our own environment step 2 %. A 2x from here needs fewer solver
//! passes (1/60 s with one substep of 10 passes is 1.3x faster but drops the
//! CMU walk, table in [`sim`]) or a solver other than rapier's; neither is
//! done.

pub mod balance;
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
