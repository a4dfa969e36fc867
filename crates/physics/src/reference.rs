//! The reference clip as the simulation needs it: resampled to the control
//! rate, per simulated body (world pose of its driver joint, relative rotation
//! to its parent body, velocities from central finite differences; joints
//! with translation tracks where the clip puts them), plus the
//! file's local rotations (for merged joints when recording), the centre of
//! mass and the lowest point of every body shape (to tell a fall from a
//! reference that itself touches the floor).

use glam::{DQuat, DVec3, Quat, Vec3};
use motion::Motion;
use motion::skeleton::Transform;

use crate::character::CharacterSpec;
use crate::sim::{BodyState, axis_angle};

/// One control frame of the reference.
#[derive(Debug, Clone)]
pub struct RefFrame {
    /// World state of every body (origin velocity, angular velocity).
    pub bodies: Vec<BodyState>,
    /// Rotation of each body relative to its parent (body 0: world rotation).
    pub rel: Vec<Quat>,
    /// Relative angular velocity, parent frame (body 0: world).
    pub rel_vel: Vec<Vec3>,
    /// File root translation and local rotations (f64, as the motion stores them).
    pub root: DVec3,
    pub locals: Vec<DQuat>,
    pub com: Vec3,
    pub com_vel: Vec3,
    /// Lowest world y of each body's shape.
    pub lowest: Vec<f32>,
}

#[derive(Debug, Clone)]
pub struct Reference {
    pub hz: f64,
    /// Height of the simulated floor in the file's coordinates: the clip was
    /// shifted down by this much (see [`Reference::new`]).
    pub floor: f32,
    pub frames: Vec<RefFrame>,
}

/// Sample a motion at time `t` seconds (linear root, slerped rotations), clamped to the clip.
pub fn sample(motion: &Motion, t: f64, pose: &mut [DQuat]) -> DVec3 {
    let last = motion.frames() - 1;
    let x = (t * motion.fps()).clamp(0.0, last as f64);
    let f0 = (x.floor() as usize).min(last);
    let f1 = (f0 + 1).min(last);
    let a = x - f0 as f64;
    for (j, q) in pose.iter_mut().enumerate() {
        let q0 = motion.rotation(f0, j);
        let mut q1 = motion.rotation(f1, j);
        if q0.dot(q1) < 0.0 {
            q1 = -q1;
        }
        *q = q0.slerp(q1, a).normalize();
    }
    motion.root_translation()[f0].lerp(motion.root_translation()[f1], a)
}

impl Reference {
    /// Resample `motion` at `hz` (frames at `k / hz` up to the clip's last frame).
    pub fn new(motion: &Motion, spec: &CharacterSpec, hz: f64) -> Self {
        let n_b = spec.bodies.len();
        let n_j = motion.joints();
        let last_t = (motion.frames() - 1) as f64 / motion.fps();
        let count = ((last_t * hz).floor() as usize + 1).max(2);
        let mut pose = vec![DQuat::IDENTITY; n_j];
        let mut world = vec![Transform::IDENTITY; n_j];
        let mut frames: Vec<RefFrame> = Vec::with_capacity(count);
        let total_mass: f32 = spec.bodies.iter().map(|b| b.mass).sum();
        for k in 0..count {
            let t = (k as f64 / hz).min(last_t);
            let root = sample(motion, t, &mut pose);
            // Translation tracks (joints a file animates the offset of) at the same time.
            let s = t * motion.fps();
            motion.skeleton().forward_with(
                root,
                &pose,
                |j| motion.local_translation_at(s, j),
                &mut world,
            );
            let mut bodies = Vec::with_capacity(n_b);
            let mut lowest = Vec::with_capacity(n_b);
            let mut com = Vec3::ZERO;
            for b in &spec.bodies {
                let w = world[b.driver];
                let pos = w.translation.as_vec3();
                let rot = w.rotation.as_quat().normalize();
                bodies.push(BodyState {
                    pos,
                    rot,
                    vel: Vec3::ZERO,
                    angvel: Vec3::ZERO,
                });
                lowest.push(b.shape.lowest_y(pos, rot));
                com += (pos + rot * b.com_local) * b.mass;
            }
            let rel = (0..n_b)
                .map(|b| match spec.bodies[b].parent {
                    Some(p) => (bodies[p].rot.inverse() * bodies[b].rot).normalize(),
                    None => bodies[b].rot,
                })
                .collect();
            frames.push(RefFrame {
                bodies,
                rel,
                rel_vel: vec![Vec3::ZERO; n_b],
                root,
                locals: pose.clone(),
                com: com / total_mass,
                com_vel: Vec3::ZERO,
                lowest,
            });
        }
        // The file's floor is not the simulated one (markers sit above the sole,
        // foot boxes have their own height): shift the clip vertically so that
        // the lower foot touches y = 0 in the median frame (a pointed toe in a
        // kick reaches lower than the standing foot, a jump leaves the floor).
        let mut lows: Vec<f32> = frames
            .iter()
            .map(|f| {
                spec.feet
                    .iter()
                    .map(|&b| f.lowest[b])
                    .fold(f32::INFINITY, f32::min)
            })
            .collect();
        lows.sort_by(f32::total_cmp);
        let mut floor = lows[lows.len() / 2];
        if !floor.is_finite() {
            floor = 0.0;
        }
        {
            for f in &mut frames {
                for b in &mut f.bodies {
                    b.pos.y -= floor;
                }
                for l in &mut f.lowest {
                    *l -= floor;
                }
                f.com.y -= floor;
                f.root.y -= floor as f64;
            }
        }
        // Velocities by central differences (one-sided at the ends).
        let dt = 1.0 / hz as f32;
        for k in 0..count {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(count - 1));
            let span = (b - a) as f32 * dt;
            for i in 0..n_b {
                let (fa, fb) = (&frames[a], &frames[b]);
                let vel = (fb.bodies[i].pos - fa.bodies[i].pos) / span;
                let angvel = axis_angle(fb.bodies[i].rot * fa.bodies[i].rot.inverse()) / span;
                let rel_vel = axis_angle(fb.rel[i] * fa.rel[i].inverse()) / span;
                let com_vel = (fb.com - fa.com) / span;
                let f = &mut frames[k];
                f.bodies[i].vel = vel;
                f.bodies[i].angvel = angvel;
                f.rel_vel[i] = rel_vel;
                f.com_vel = com_vel;
            }
        }
        Reference { hz, floor, frames }
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}
