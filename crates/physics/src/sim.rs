//! The rapier3d world of one character: bodies, impulse spherical joints, the
//! ground, per-joint PD control and the root residual force.
//!
//! Joints are impulse spherical joints (positions constrained, rotations free):
//! multibody joints are several times slower in rapier 0.36, and rapier's
//! ball-joint *position* motors work on per-axis angles that misbehave for
//! large rotations. The PD law `tau = kp e + kd (w_ref - w)` (`e` = axis-angle
//! from the current to the target relative rotation, from quaternions) is
//! realised in one of three ways ([`PdMode`]):
//!
//! * `Explicit`: external torques. Explodes at any step we can afford: the
//!   light hands and feet and the twist axes of the limbs have
//!   `kd dt / I >> 2`.
//! * `StableTorque`: implicit PD torques against the child subtree's rest
//!   inertia (Tan et al. with a rigid-subtree approximation). Stable per joint,
//!   but the chain is not: the parent side's inertia is ignored.
//! * `Motor` (default): the PD law as a *velocity target* of rapier's three
//!   angular joint motors, `v* = w_ref + (kp / kd) e` with damping `kd` and the
//!   torque limit as force limit. The motor torque is `kd (v* - w) = kp e +
//!   kd (w_ref - w)`, solved implicitly inside the constraint solver with the
//!   whole body, so it is stable whenever `dt kp / kd < 2` (every reference
//!   gain pair has `kp / kd = 10`).
//!
//! A minimum principal inertia per body ("armature", as in MuJoCo/DeepMimic
//! models) lets the solver run at coarse steps; it slows the spin of the hands
//! and feet about their own axes, not the motion of the body as a whole.
//!
//! ## Step, substeps and PGS passes (default since issue 12): measured
//!
//! The default is a 1/60 s step of 2 substeps (`solver_iterations`) with 5
//! velocity (PGS) passes each (`pgs_iterations`), one stabilisation pass,
//! friction solved in every pass, no CCD and no broad-phase tree optimiser. Profile of the former default
//! (1/120 s, 4 substeps of one pass; `perf record --call-graph dwarf` on
//! `motionaug bench physics --seconds 3`): rapier's solver 72 % (joint rows:
//! per-substep rebuild `JointConstraint::update` 29 %, `solve` 21 %,
//! `finalize_constraints` 11 %), collision detection 10 % (narrow phase 6 %,
//! broad phase and its tree optimiser 6 %), CCD 2 %, our own code (PD
//! targets, motors, observation, reward) about 5 %. The motorised spherical
//! joints take rapier's scalar path (6 rows each, no SIMD). The tracking
//! error is set by how far the motors of the whole chain converge, not by
//! the step: more passes per substep buy the same error as more substeps,
//! without rebuilding every row each substep.
//!
//! HDM05 kick, action 0 with the PD residual, `PHYSICS_BENCH_CONFIGS=...
//! perf stat -e task-clock cargo bench -p physics --bench physics`
//! (hz:substeps:passes), 3 interleaved rounds in one run under load from
//! other builds; CPU time per simulated second (task-clock / physics steps)
//! is the steadier figure:
//!
//! | step : substeps : passes | CPU ms per sim s | sim s / wall s (median) | kick error rad | CMU 131 walk (80 steps) |
//! |---|---|---|---|---|
//! | 1/120 : 4 : 1 (former) | 6.14 | 89 | 0.080 | 0.097, up |
//! | **1/60 : 2 : 5** | **3.24** | **164** | **0.077** | **0.096, up** |
//! | 1/60 : 2 : 6 | 4.04 | 144 | 0.069 | 0.086, up |
//! | 1/90 : 1 : 7 | 3.37 | 168 | 0.074 | - |
//! | 1/90 : 1 : 8 | 4.03 | 130 | 0.067 | 0.078, up |
//! | 1/60 : 1 : 10 | 2.49 | 191 | 0.079 | 0.081, **falls** at step 73 |
//!
//! (Measured before friction moved into every pass, below; with it the
//! default row's kick error is 0.076 rad.) One substep per 1/60 s tracks the kick but drops the walk
//! (`action_zero_with_pd_residual_keeps_a_walk_up`), whatever the passes
//! (10, 12, 16 tried); 1/60 s with 2 substeps keeps it up from 4 passes on
//! (walk error 0.106 at 4, 0.096 at 5). Other HDM05 classes at 1/60 : 2 : 5
//! against the former default (falls as before: the jog, deposit and sneak
//! fall with action 0 in both): squat 0.088 vs 0.086 rad, hop 0.078 vs
//! 0.074, jog 0.077 vs 0.078. Rapier's joint warm start changed nothing
//! (same error to 4 digits). Turning CCD off saved ~9 % of a step, the tree
//! optimiser ~4 % (CPU time, 4 rounds; no measurable change in tracking).
//!
//! Foot skating of the action-0 rollout (`motion::metrics::plausibility` of
//! the recorded motion, m/s; input in brackets). Rapier solves friction only
//! in the stabilisation pass by default, one per substep: with fewer
//! substeps the planted feet slid. Solving it in every pass
//! (`friction_in_bias_pass`) fixes that at no measurable cost (CPU 66.6 vs
//! 65.5 us per step, 3 rounds) and brings the kick's error to 0.076 rad:
//!
//! | clip | 1/120 : 4 : 1 (former) | 1/60 : 2 : 5, friction in stabilisation only | **1/60 : 2 : 5, friction in every pass** |
//! |---|---|---|---|
//! | kick (0.058) | 0.064 | 0.100 | **0.063** |
//! | jog (0.102), falls at step 38-39 | 0.180 | 0.147 | **0.076** |
//! | hop (0.148) | 0.043 | 0.197 | **0.044** |
//! | squat (0.107) | 0.026 | 0.050 | **0.022** |
//!
//! ## Step size, solver iterations, armature: measured (one PGS pass, before issue 12)
//!
//! HDM05 `HDM_bd_kickLFront1Reps_001` (1.34 s), action 0 with the PD residual,
//! control at 30 Hz, `cargo bench -p physics --bench physics` (release, one
//! thread). Rapier's `num_solver_iterations` are substeps (the step is divided
//! by them). "falls" = passes that ended with a non-foot body on the ground
//! (the bench then restarts at the next frame). One run, all rows under the
//! same heavy load (load average ~10 on the 2 cores from other builds): read
//! the speeds relative to each other. On a quiet moment the default row ran at
//! 127 sim s / wall s (65 us per step).
//!
//! | PD mode | armature kg m^2 | dt : iters | sim s / wall s | us / step | joint error rad | falls / passes |
//! |---|---|---|---|---|---|---|
//! | StableTorque | 0 | 1/240 : 4 | 62.5 | 67 | 1.41 | 200 / 100 |
//! | Motor | 0 | 1/1200 : 4 | 11.3 | 74 | 0.045 | 0 / 17 |
//! | Motor | 0 | 1/600 : 4 | 15.4 | 108 | 0.070 | 25 / 25 |
//! | Motor | 0 | 1/600 : 8 | 6.3 | 263 | 0.045 | 0 / 10 |
//! | Motor | 0 | 1/300 : 12 | 14.5 | 230 | 0.052 | 0 / 22 |
//! | Motor | 0 | 1/240 : 4 | 28.3 | 147 | 0.116 | 44 / 44 |
//! | Motor | 0 | 1/120 : 4 | 38.4 | 217 | 0.122 | 189 / 63 |
//! | Motor | 0.02 | 1/600 : 4 | 11.0 | 151 | 0.042 | 0 / 17 |
//! | Motor | 0.02 | 1/240 : 4 | 29.5 | 141 | 0.067 | 0 / 45 |
//! | Motor | 0.02 | 1/120 : 4 | 44.9 | 186 | 0.095 | 70 / 70 |
//! | Motor | 0.05 | 1/1200 : 4 | 5.2 | 159 | 0.035 | 0 / 8 |
//! | Motor | 0.05 | 1/240 : 4 | 29.1 | 143 | 0.051 | 0 / 44 |
//! | **Motor** | **0.05** | **1/120 : 4** | **52.9** | **157** | **0.075** | **0 / 80** |
//! | Motor | 0.05 | 1/60 : 8 | 59.7 | 279 | 0.081 | 0 / 90 |
//! | Motor | 0.1 | 1/120 : 4 | 46.3 | 180 | 0.061 | 0 / 70 |
//! | Motor, no stabilisation pass | 0.05 | 1/120 : 4 | 56.4 | 148 | 0.095 | 87 / 87 |
//!
//! The bold row was the default before issue 12: the coarsest step that
//! tracked the kick without a fall at the smallest armature tried (with one
//! PGS pass per substep). 1/60 s with 8 substeps is a little
//! faster at a similar error, but collision detection then runs only every
//! 17 ms. `Explicit` torques blow up at all of these steps. Most of the time is
//! rapier's joint solver (`JointConstraint::solve`, `finalize_constraints`:
//! about half in `perf`); our own per-step code is about 3 %.
//!
//! Our code in [`Sim::substep`] and the environment's step allocates nothing;
//! rapier 0.36 itself makes about 11 small heap allocations per physics step
//! (counted with a counting global allocator on the sway fixture). In `Motor`
//! mode [`Sim::substep`] borrows only the root body mutably (a mutably
//! borrowed body goes through rapier's user-change pass). Setting the motor
//! targets needs `ImpulseJointSet::get_mut`, which makes rapier rebuild its
//! joint assembly (colouring, builders, island links) at every step: about
//! 3-5 % of a step, with no public way around it in rapier 0.36.
//!
//! ## Many characters in one world: no gain (session 20)
//!
//! The "batched environments" idea (issue 12): step the 8 PPO environments
//! of a job as 8 characters of one rapier world, hoping rapier's SIMD joint
//! path and its fixed per-step costs amortise over them. Measured with a
//! throwaway test (not kept): K copies of the CMU humanoid
//! (`fixtures::cmu_humanoid`, 16 bodies) 3 m apart on the one ground,
//! default [`SimParams`], motors holding the rest pose, 600 world steps
//! after 20 to settle, release build, one core:
//!
//! | characters K | us per world step | us per character step |
//! |---|---|---|
//! | 1 | 66.6 | 66.6 |
//! | 4 | 233.6 | 58.4 |
//! | 8 | 449.1 | 56.1 |
//! | 16 | 918.9 | 57.4 |
//! | 32 | 2,036.1 | 63.6 |
//! | 64 | 3,551.7 | 55.5 |
//!
//! At most 16 % per character, at K that no job uses. The reason is in
//! rapier 0.36 itself: a joint with a motor on a free axis never takes the
//! SIMD path (`GenericJoint::supports_simd_constraints` requires the motor
//! axes to be locked ones), and the staged solver solves a joint colour
//! serially unless it holds at least 64 joints (`JOINT_BATCH *
//! LAYOUT_REF_WORKERS / 2`). Every joint here is motorised on its three
//! angular axes, so the cost per character is the scalar joint rows, with or
//! without company. Batched worlds were therefore not built; the 100x
//! target stays limited by this solver (48x measured side by side with
//! pybullet in session 15).

use glam::{Mat3, Quat, Vec3};
use rapier3d::prelude::*;

use crate::character::CharacterSpec;

/// Physics settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimParams {
    /// Physics step, seconds.
    pub dt: f32,
    pub solver_iterations: usize,
    pub friction: f32,
    pub gravity: f32,
    pub pd: PdMode,
    /// Minimum principal moment of inertia of every body (kg m^2), a joint
    /// "armature": light hands and feet otherwise need tiny steps.
    pub min_inertia: f32,
    /// Rapier's stabilisation (position-correction) passes per substep.
    pub stabilization_iterations: usize,
    /// Rapier's velocity (PGS) passes per substep
    /// (`num_internal_pgs_iterations`): the joint motors of the whole chain
    /// converge with passes, so several passes in one substep track as well
    /// as several substeps of one pass, at a fraction of the cost (each
    /// substep also rebuilds every joint row).
    pub pgs_iterations: usize,
}

impl Default for SimParams {
    fn default() -> Self {
        SimParams {
            dt: 1.0 / 60.0,
            solver_iterations: 2,
            friction: 0.9,
            gravity: 9.8,
            pd: PdMode::Motor,
            min_inertia: 0.05,
            stabilization_iterations: 1,
            pgs_iterations: 5,
        }
    }
}

/// How the joint PD controller is realised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PdMode {
    /// `tau = kp e + kd (w_ref - w)` as external torques (needs tiny steps).
    Explicit,
    /// Implicit PD torques against the rest inertia of the child's subtree.
    StableTorque,
    /// The PD law as a velocity target of rapier's joint motors:
    /// `v* = w_ref + (kp / kd) e`, motor damping `kd`, force limit = torque
    /// limit. The motor torque is `kd (v* - w) = kp e + kd (w_ref - w)`, but
    /// solved inside the constraint solver with the whole body (implicitly), so
    /// it is stable for any step with `dt kp / kd < 2` (all reference gains
    /// have `kp / kd = 10`). `e` comes from quaternions, never per-axis angles.
    #[default]
    Motor,
}

/// Kinematic state of one body: frame origin (= driver joint), orientation,
/// origin velocity and angular velocity, world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyState {
    pub pos: Vec3,
    pub rot: Quat,
    pub vel: Vec3,
    pub angvel: Vec3,
}

pub struct Sim {
    world: PhysicsWorld,
    bodies: Vec<RigidBodyHandle>,
    joints: Vec<Option<ImpulseJointHandle>>,
    colliders: Vec<ColliderHandle>,
    ground: ColliderHandle,
    parent: Vec<Option<usize>>,
    kp: Vec<f32>,
    kd: Vec<f32>,
    limit: Vec<f32>,
    /// Rest inertia of each body's subtree about its joint (rest frame = world).
    subtree_inertia: Vec<Mat3>,
    params: SimParams,
    /// Current state, refreshed by [`Sim::read_state`].
    pub state: Vec<BodyState>,
    /// Torque applied at each joint in the last substep (world frame).
    pub joint_torque: Vec<Vec3>,
}

fn quat_log(q: Quat) -> Vec3 {
    // Axis-angle vector of the shortest rotation.
    let q = if q.w < 0.0 { -q } else { q };
    let v = Vec3::new(q.x, q.y, q.z);
    let s = v.length();
    if s < 1e-7 {
        return 2.0 * v;
    }
    let angle = 2.0 * s.atan2(q.w);
    v * (angle / s)
}

pub(crate) fn axis_angle(q: Quat) -> Vec3 {
    quat_log(q)
}

impl Sim {
    /// The world of `spec`: the ground, then each body with its collider and
    /// the joint to its parent, then the subtree inertias.
    pub fn new(spec: &CharacterSpec, params: SimParams) -> Self {
        let n = spec.bodies.len();
        let mut world = world(&params);
        let ground = insert_ground(&mut world, &params);
        let mut bodies = Vec::with_capacity(n);
        let mut joints = Vec::with_capacity(n);
        let mut colliders = Vec::with_capacity(n);
        for b in 0..n {
            let (rb, col, joint) = insert_body(&mut world, spec, b, &bodies, &params);
            joints.push(joint);
            bodies.push(rb);
            colliders.push(col);
        }
        let subtree_inertia = subtree_inertia(spec, &world, &bodies);
        Sim {
            world,
            bodies,
            joints,
            colliders,
            ground,
            parent: spec.bodies.iter().map(|b| b.parent).collect(),
            kp: spec.bodies.iter().map(|b| b.kp).collect(),
            kd: spec.bodies.iter().map(|b| b.kd).collect(),
            limit: spec.bodies.iter().map(|b| b.torque_limit).collect(),
            subtree_inertia,
            params,
            state: vec![BodyState::default(); n],
            joint_torque: vec![Vec3::ZERO; n],
        }
    }

    pub fn params(&self) -> &SimParams {
        &self.params
    }

    pub fn len(&self) -> usize {
        self.bodies.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bodies.is_empty()
    }

    /// Teleport every body to `states` (origin velocity converted to the centre
    /// of mass velocity rapier stores) and clear forces.
    pub fn set_state(&mut self, states: &[BodyState]) {
        for (b, s) in states.iter().enumerate() {
            let rb = &mut self.world.bodies[self.bodies[b]];
            rb.set_position(Pose::from_parts(s.pos, s.rot), true);
            let com = s.pos + s.rot * rb.mass_properties().local_mprops.local_com;
            rb.set_linvel(s.vel + s.angvel.cross(com - s.pos), true);
            rb.set_angvel(s.angvel, true);
            rb.reset_forces(false);
            rb.reset_torques(false);
        }
        self.read_state();
    }

    /// Refresh [`Sim::state`] from the world.
    pub fn read_state(&mut self) {
        for (b, h) in self.bodies.iter().enumerate() {
            let rb = &self.world.bodies[*h];
            let pos = rb.translation();
            self.state[b] = BodyState {
                pos,
                rot: *rb.rotation(),
                vel: rb.velocity_at_point(pos),
                angvel: rb.angvel(),
            };
        }
    }

    /// Total mass and centre of mass position and velocity.
    pub fn com(&self) -> (f32, Vec3, Vec3) {
        let mut m = 0.0;
        let mut p = Vec3::ZERO;
        let mut v = Vec3::ZERO;
        for h in &self.bodies {
            let rb = &self.world.bodies[*h];
            let mb = rb.mass();
            m += mb;
            p += rb.center_of_mass() * mb;
            v += rb.linvel() * mb;
        }
        (m, p / m, v / m)
    }

    /// One physics step: PD torques toward `targets` (relative rotation of each
    /// body in its parent's frame; entry 0 unused) with relative target angular
    /// velocities `target_vel` (parent frame), plus a root force and torque.
    /// Call [`Sim::read_state`] before (done by `set_state` and by this method after stepping).
    pub fn substep(
        &mut self,
        targets: &[Quat],
        target_vel: &[Vec3],
        root_force: Vec3,
        root_torque: Vec3,
    ) {
        let dt = self.params.dt;
        // Only the root carries a force in `Motor` mode: borrowing a body
        // mutably queues it for rapier's user-change pass, so the others are
        // left alone.
        let touched = if self.params.pd == PdMode::Motor {
            &self.bodies[..1]
        } else {
            &self.bodies[..]
        };
        for h in touched {
            let rb = &mut self.world.bodies[*h];
            rb.reset_forces(false);
            rb.reset_torques(false);
        }
        for b in 1..self.bodies.len() {
            let Some(p) = self.parent[b] else { continue };
            let (kp, kd) = (self.kp[b], self.kd[b]);
            if kp == 0.0 && kd == 0.0 {
                continue;
            }
            let sp = self.state[p];
            let sb = self.state[b];
            let rel = sp.rot.inverse() * sb.rot;
            let e_local = quat_log(targets[b] * rel.inverse());
            let e = sp.rot * e_local;
            let w = sb.angvel - sp.angvel;
            let w_ref = sp.rot * target_vel[b];
            let mut tau = match self.params.pd {
                PdMode::Motor => {
                    // Parent-frame velocity target for the three angular motor axes.
                    let v = target_vel[b] + (kp / kd.max(1e-6)) * e_local;
                    if let Some(h) = self.joints[b]
                        && let Some(j) = self.world.impulse_joints.get_mut(h, false)
                    {
                        j.data.set_motor_velocity(JointAxis::AngX, v.x, kd);
                        j.data.set_motor_velocity(JointAxis::AngY, v.y, kd);
                        j.data.set_motor_velocity(JointAxis::AngZ, v.z, kd);
                    }
                    self.joint_torque[b] = kp * e + kd * (w_ref - w);
                    continue;
                }
                PdMode::StableTorque => {
                    let rhs = kp * (e - dt * (w - w_ref)) + kd * (w_ref - w);
                    let r = Mat3::from_quat(sb.rot);
                    let iw = r * self.subtree_inertia[b] * r.transpose();
                    let c = kp * dt * dt + kd * dt;
                    let a = iw + Mat3::IDENTITY * c;
                    a.inverse() * (iw * rhs)
                }
                PdMode::Explicit => kp * e + kd * (w_ref - w),
            };
            let lim = self.limit[b];
            let norm = tau.length();
            if norm > lim {
                tau *= lim / norm;
            }
            self.joint_torque[b] = tau;
            self.world.bodies[self.bodies[b]].add_torque(tau, false);
            self.world.bodies[self.bodies[p]].add_torque(-tau, false);
        }
        let root = &mut self.world.bodies[self.bodies[0]];
        root.add_force(root_force, false);
        root.add_torque(root_torque, false);
        self.world.step();
        self.read_state();
    }

    /// Whether body `b` touches the ground.
    pub fn touches_ground(&self, b: usize) -> bool {
        self.world
            .narrow_phase
            .contact_pair(self.ground, self.colliders[b])
            .is_some_and(|c| c.has_any_active_contact())
    }
}

/// An empty world with the step, gravity and solver settings of `params`.
fn world(params: &SimParams) -> PhysicsWorld {
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::new(0.0, -params.gravity, 0.0);
    world.integration_parameters.dt = params.dt;
    world.integration_parameters.num_solver_iterations = params.solver_iterations.max(1);
    world
        .integration_parameters
        .num_internal_stabilization_iterations = params.stabilization_iterations;
    world.integration_parameters.num_internal_pgs_iterations = params.pgs_iterations.max(1);
    // No continuous collision detection: no body is fast or thin enough to
    // tunnel through the 2 m ground box in one step, and rapier's automatic
    // CCD of fast bodies against fixed colliders cost ~15 % of a step.
    world.integration_parameters.max_ccd_substeps = 0;
    // Friction in every velocity pass, not only in the one stabilisation
    // (unbiased) pass of each substep, rapier's default: with 2 substeps per
    // 1/60 s step that left friction unconverged and planted feet sliding
    // (action-0 foot skating of the HDM05 hop 0.043 -> 0.197 m/s; with this
    // on 0.044, the jog 0.180 -> 0.076, see the table above).
    world.integration_parameters.friction_in_bias_pass = true;
    // 17 colliders: the incremental tree optimiser of the broad phase costs
    // more than a less balanced tree (~15 % of a step, measured).
    world.broad_phase = BroadPhaseBvh::with_optimization_strategy(
        rapier3d::geometry::BvhOptimizationStrategy::None,
    );
    world
}

/// The ground: a fixed box whose top is y = 0, in collision group 31.
fn insert_ground(world: &mut PhysicsWorld, params: &SimParams) -> ColliderHandle {
    let ground_body =
        world.insert_body(RigidBodyBuilder::fixed().translation(Vector::new(0.0, -1.0, 0.0)));
    let ground_bit = Group::from_bits_truncate(1 << 31);
    world.insert_collider(
        ColliderBuilder::cuboid(100.0, 1.0, 100.0)
            .friction(params.friction)
            .collision_groups(InteractionGroups::new(
                ground_bit,
                Group::ALL,
                InteractionTestMode::And,
            )),
        Some(ground_body),
    )
}

/// Body `b` of `spec` (its parent already in `bodies`): the rigid body, its
/// collider (group `b`, not colliding with the excluded pairs) and, but for the
/// pelvis, the spherical joint to its parent (with motors in [`PdMode::Motor`]).
fn insert_body(
    world: &mut PhysicsWorld,
    spec: &CharacterSpec,
    b: usize,
    bodies: &[RigidBodyHandle],
    params: &SimParams,
) -> (RigidBodyHandle, ColliderHandle, Option<ImpulseJointHandle>) {
    let body = &spec.bodies[b];
    let rb = world.insert_body(
        RigidBodyBuilder::dynamic()
            .translation(body.rest_origin + Vec3::Y * 2.0)
            .can_sleep(false),
    );
    let mut filter = Group::ALL.bits();
    for &(a, c) in &spec.no_collision {
        if a == b {
            filter &= !(1u32 << c);
        } else if c == b {
            filter &= !(1u32 << a);
        }
    }
    let (shape, local) = body.shape.to_parry();
    let mut mprops = shape.mass_properties(1.0);
    mprops.set_mass(body.mass, true);
    if params.min_inertia > 0.0 {
        let inv = mprops.inv_principal_inertia;
        let clamp = |i: f32| {
            if i > 0.0 {
                i.min(1.0 / params.min_inertia)
            } else {
                i
            }
        };
        mprops.inv_principal_inertia = Vec3::new(clamp(inv.x), clamp(inv.y), clamp(inv.z));
    }
    let col = world.insert_collider(
        ColliderBuilder::new(shape)
            .position(local)
            .mass_properties(mprops)
            .friction(params.friction)
            .collision_groups(InteractionGroups::new(
                Group::from_bits_truncate(1 << b),
                Group::from_bits_truncate(filter),
                InteractionTestMode::And,
            )),
        Some(rb),
    );
    let joint = body.parent.map(|p| {
        let mut joint = SphericalJointBuilder::new()
            .local_anchor1(body.anchor_in_parent)
            .local_anchor2(Vec3::ZERO)
            .contacts_enabled(false);
        if params.pd == PdMode::Motor {
            for axis in [JointAxis::AngX, JointAxis::AngY, JointAxis::AngZ] {
                joint = joint
                    .motor_model(axis, MotorModel::ForceBased)
                    .motor_velocity(axis, 0.0, body.kd)
                    .motor_max_force(axis, body.torque_limit);
            }
        }
        world.insert_impulse_joint(bodies[p], rb, joint)
    });
    (rb, col, joint)
}

/// Rest inertia of each body's subtree about its joint (rest frame = world).
fn subtree_inertia(
    spec: &CharacterSpec,
    world: &PhysicsWorld,
    bodies: &[RigidBodyHandle],
) -> Vec<Mat3> {
    let n = spec.bodies.len();
    let mut subtree_inertia = vec![Mat3::ZERO; n];
    #[allow(clippy::needless_range_loop)]
    for b in 0..n {
        let pivot = spec.bodies[b].rest_origin;
        let mut total = Mat3::ZERO;
        for k in 0..n {
            let mut at = Some(k);
            let mut inside = false;
            while let Some(a) = at {
                if a == b {
                    inside = true;
                    break;
                }
                at = spec.bodies[a].parent;
            }
            if !inside {
                continue;
            }
            let mp = world.bodies[bodies[k]].mass_properties().local_mprops;
            let ic = mp.reconstruct_inertia_matrix();
            let m = mp.mass();
            let d = spec.bodies[k].rest_origin + mp.local_com - pivot;
            total += ic + (Mat3::IDENTITY * d.length_squared() - outer(d, d)) * m;
        }
        subtree_inertia[b] = total;
    }
    subtree_inertia
}

fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}
