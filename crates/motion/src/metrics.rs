//! Physical plausibility metrics on any motion: the yardsticks for synthesis and
//! for the physical correction that follows it.
//!
//! All lengths are metres, times seconds, the ground is the plane y = 0 (y up).
//! "Body points" are all joints plus end sites. "Foot points" are the joints
//! whose names contain `foot`, `ankle`, `toe` or `heel` (with their end sites);
//! without such names, the leaf joints whose rest position lies in the lowest
//! 10 % of the body, with their end sites.
//!
//! * Foot skating: mean horizontal speed (m/s) of the sole points while in
//!   ground contact. Sole points are the foot points whose rest height is within
//!   `sole_band_m` of the lowest foot point (toes and toe ends on HDM05/CMU
//!   skeletons; the ankle, 5-8 cm higher, swings that low too and would count
//!   swing as contact). A sole point is in contact over the step `t -> t+1` when
//!   at both frames it is within `contact_band_m` of its own planted height (the
//!   5th percentile of its height over the clip: toe end sites of real data sit
//!   a few cm below or above y = 0 when planted) and below `contact_height_m`
//!   (so a clip floating in the air has no contact), and its vertical speed is
//!   below `contact_vertical_speed_m_s`. Speeds are forward differences.
//! * Ground penetration: per frame the depth of the lowest body point below
//!   y = 0 (0 when above); mean and max over frames.
//! * Floating: fraction of frames whose lowest body point is higher than
//!   `floating_height_m` (jumps count), and the mean height of the lowest point.
//! * Bone-length drift: largest relative difference between the FK distance of
//!   a joint to its parent and the skeleton's bone length, over frames (0 up to
//!   rounding for rotation-based motion; matters for position-derived outputs).
//! * Jerk: mean magnitude of the third time derivative of joint positions
//!   (m/s^3), third-order finite differences; 0 for clips under 4 frames.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::Motion;
use crate::skeleton::Transform;

/// Thresholds of the contact and floating tests.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Thresholds {
    /// Height above the ground under which a sole point may be in contact.
    pub contact_height_m: f64,
    /// Height above its planted height under which a sole point may be in contact.
    pub contact_band_m: f64,
    /// Foot points this close (rest height) to the lowest one are sole points.
    pub sole_band_m: f64,
    /// Vertical speed under which a low foot point is in contact.
    pub contact_vertical_speed_m_s: f64,
    /// Height of the lowest body point above which a frame counts as floating.
    pub floating_height_m: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            contact_height_m: 0.10,
            contact_band_m: 0.02,
            sole_band_m: 0.03,
            contact_vertical_speed_m_s: 0.25,
            floating_height_m: 0.05,
        }
    }
}

/// The plausibility metrics of one motion (units in the field names).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plausibility {
    pub frames: usize,
    pub fps: f64,
    /// Joints whose positions or end sites are used as sole points.
    pub foot_joints: Vec<String>,
    /// Mean horizontal speed of foot points in contact, m/s (0 without contact).
    pub foot_skating_m_s: f64,
    /// Fraction of (sole point, frame step) pairs in contact.
    pub contact_fraction: f64,
    /// Mean over frames of the lowest point's depth below y = 0, m.
    pub penetration_mean_m: f64,
    /// Largest depth below y = 0, m.
    pub penetration_max_m: f64,
    /// Fraction of frames with the lowest point above `floating_height_m`.
    pub floating_fraction: f64,
    /// Mean height of the lowest body point, m (negative = below ground).
    pub lowest_point_mean_m: f64,
    /// Largest relative bone-length error (dimensionless).
    pub bone_length_drift: f64,
    /// Mean magnitude of the third derivative of joint positions, m/s^3.
    pub jerk_m_s3: f64,
    /// Mean speed of the joints relative to the root, m/s: how much the body
    /// moves apart from travelling. A generative model that averages motions
    /// decodes near-frozen poses, which every other metric here rates well
    /// (no skating, no jerk); HDM05 jogs move 0.5-0.9 m/s.
    #[serde(default)]
    pub pose_speed_m_s: f64,
    pub thresholds: Thresholds,
}

/// The foot points of a skeleton (see the module doc): each a joint and, for
/// its end site, the site's offset (`None`: the joint itself). What the foot
/// skating metric watches; the VAE's foot loss uses the same points.
pub fn skeleton_foot_points(s: &crate::Skeleton) -> Vec<(usize, Option<DVec3>)> {
    let words = ["foot", "ankle", "toe", "heel"];
    let mut joints: Vec<usize> = (0..s.len())
        .filter(|&j| {
            let n = s.joint(j).name.to_ascii_lowercase();
            words.iter().any(|w| n.contains(w))
        })
        .collect();
    if joints.is_empty() {
        let rest = s.rest_positions();
        let lo = rest.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        let cut = lo + 0.1 * s.rest_height();
        joints = (1..s.len())
            .filter(|&j| s.children(j).next().is_none() && rest[j].y <= cut)
            .collect();
    }
    let mut points = Vec::new();
    for j in joints {
        points.push((j, None));
        if let Some(e) = s.joint(j).end_site {
            points.push((j, Some(e)));
        }
    }
    points
}

fn foot_points(motion: &Motion) -> Vec<(usize, Option<DVec3>)> {
    skeleton_foot_points(motion.skeleton())
}

fn point(x: &[Transform], p: (usize, Option<DVec3>)) -> DVec3 {
    match p.1 {
        None => x[p.0].translation,
        Some(e) => x[p.0].translation + x[p.0].rotation * e,
    }
}

/// Height of the lowest body point (joints and end sites) of one frame's
/// world transforms `x`.
fn lowest_point(s: &crate::Skeleton, x: &[Transform]) -> f64 {
    let mut lo = f64::INFINITY;
    for (j, t) in x.iter().enumerate() {
        lo = lo.min(t.translation.y);
        if let Some(e) = s.joint(j).end_site {
            lo = lo.min((t.translation + t.rotation * e).y);
        }
    }
    lo
}

/// Per frame, the height of the lowest body point (joints and end sites), m.
pub fn lowest_points(motion: &Motion) -> Vec<f64> {
    let mut x = vec![Transform::IDENTITY; motion.joints()];
    (0..motion.frames())
        .map(|t| {
            motion.world_transforms_into(t, &mut x);
            lowest_point(motion.skeleton(), &x)
        })
        .collect()
}

/// The sole points of `motion`'s skeleton: the foot points whose rest height
/// is within `th.sole_band_m` of the lowest one (see the module doc), each a
/// joint and, for its end site, the site's offset.
fn sole_points(motion: &Motion, th: &Thresholds) -> Vec<(usize, Option<DVec3>)> {
    let s = motion.skeleton();
    let n_j = s.len();
    let mut rest_x = vec![Transform::IDENTITY; n_j];
    s.forward(DVec3::ZERO, &vec![glam::DQuat::IDENTITY; n_j], &mut rest_x);
    let all_feet = foot_points(motion);
    let rest_lo = all_feet
        .iter()
        .map(|p| point(&rest_x, *p).y)
        .fold(f64::INFINITY, f64::min);
    all_feet
        .into_iter()
        .filter(|p| point(&rest_x, *p).y <= rest_lo + th.sole_band_m)
        .collect()
}

/// For each step `t -> t+1` and sole point `i` (index `t * nf + i`), the
/// horizontal speed (m/s) when the point is in contact over the step, `None`
/// when it is not; `foot_pos` holds `nf` positions per frame.
fn contact_steps(foot_pos: &[DVec3], nf: usize, dt: f64, th: &Thresholds) -> Vec<Option<f64>> {
    if nf == 0 {
        return Vec::new();
    }
    let n_t = foot_pos.len() / nf;
    let planted: Vec<f64> = (0..nf)
        .map(|i| {
            let mut ys: Vec<f64> = (0..n_t).map(|t| foot_pos[t * nf + i].y).collect();
            ys.sort_by(f64::total_cmp);
            ys[(ys.len() - 1) / 20]
        })
        .collect();
    let in_contact = |t: usize, i: usize| {
        let y = foot_pos[t * nf + i].y;
        y < th.contact_height_m && y < planted[i] + th.contact_band_m
    };
    let mut out = Vec::with_capacity(n_t.saturating_sub(1) * nf);
    for t in 0..n_t.saturating_sub(1) {
        for i in 0..nf {
            let (a, b) = (foot_pos[t * nf + i], foot_pos[(t + 1) * nf + i]);
            let v = (b - a) / dt;
            let contact = in_contact(t, i)
                && in_contact(t + 1, i)
                && v.y.abs() < th.contact_vertical_speed_m_s;
            out.push(contact.then(|| DVec3::new(v.x, 0.0, v.z).length()));
        }
    }
    out
}

/// Where and when the soles touch the ground, by the same rule as the foot
/// skating metric: for each sole point, per step `t -> t+1`, its horizontal
/// speed while in contact. What a viewer highlights.
#[derive(Debug, Clone, PartialEq)]
pub struct FootContacts {
    /// The sole points: a joint, and whether the point is its end site.
    pub points: Vec<(usize, bool)>,
    /// `steps[t * points.len() + i]`: speed of point `i` over step `t -> t+1`
    /// when in contact (m/s), `None` otherwise; `frames - 1` steps.
    pub steps: Vec<Option<f64>>,
}

/// [`FootContacts`] of `motion` with thresholds `th`.
pub fn foot_contacts(motion: &Motion, th: &Thresholds) -> FootContacts {
    sole_tracks(motion, th).1
}

/// The world positions of the sole points, `frames * points` (frame-major),
/// and their [`FootContacts`].
fn sole_tracks(motion: &Motion, th: &Thresholds) -> (Vec<DVec3>, FootContacts) {
    let feet = sole_points(motion, th);
    let mut x = vec![Transform::IDENTITY; motion.joints()];
    let mut foot_pos = Vec::with_capacity(motion.frames() * feet.len());
    for t in 0..motion.frames() {
        motion.world_transforms_into(t, &mut x);
        foot_pos.extend(feet.iter().map(|p| point(&x, *p)));
    }
    let contacts = FootContacts {
        points: feet.iter().map(|p| (p.0, p.1.is_some())).collect(),
        steps: contact_steps(&foot_pos, feet.len(), 1.0 / motion.fps(), th),
    };
    (foot_pos, contacts)
}

/// Metrics with the default thresholds.
pub fn plausibility(motion: &Motion) -> Plausibility {
    plausibility_with(motion, &Thresholds::default())
}

pub fn plausibility_with(motion: &Motion, th: &Thresholds) -> Plausibility {
    let s = motion.skeleton();
    let (n_t, n_j) = (motion.frames(), motion.joints());
    let dt = 1.0 / motion.fps();
    let mut x = vec![Transform::IDENTITY; n_j];

    let feet = sole_points(motion, th);

    let lengths = s.bone_lengths();
    let mut positions = Vec::with_capacity(n_t * n_j);
    let mut foot_pos = Vec::with_capacity(n_t * feet.len());
    let mut lowest = Vec::with_capacity(n_t);
    let mut drift = 0.0f64;
    for t in 0..n_t {
        motion.world_transforms_into(t, &mut x);
        for j in 0..n_j {
            let p = x[j].translation;
            if let Some(parent) = s.parent(j)
                && lengths[j] > 1e-9
            {
                let d = (p - x[parent].translation).length();
                drift = drift.max((d - lengths[j]).abs() / lengths[j]);
            }
            positions.push(p);
        }
        lowest.push(lowest_point(s, &x));
        foot_pos.extend(feet.iter().map(|p| point(&x, *p)));
    }

    // Foot skating.
    let nf = feet.len();
    let steps = n_t.saturating_sub(1) * nf;
    let (mut speed_sum, mut contacts) = (0.0, 0usize);
    for speed in contact_steps(&foot_pos, nf, dt, th).into_iter().flatten() {
        contacts += 1;
        speed_sum += speed;
    }

    // Jerk.
    let mut jerk_sum = 0.0;
    let mut jerk_n = 0usize;
    for t in 0..n_t.saturating_sub(3) {
        for j in 0..n_j {
            let p = |k: usize| positions[(t + k) * n_j + j];
            let d3 = p(3) - 3.0 * p(2) + 3.0 * p(1) - p(0);
            jerk_sum += d3.length() / (dt * dt * dt);
            jerk_n += 1;
        }
    }

    // Speed relative to the root (joint 0).
    let mut pose_sum = 0.0;
    for t in 0..n_t.saturating_sub(1) {
        let (a, b) = (
            &positions[t * n_j..][..n_j],
            &positions[(t + 1) * n_j..][..n_j],
        );
        for j in 1..n_j {
            pose_sum += ((b[j] - b[0]) - (a[j] - a[0])).length() / dt;
        }
    }
    let pose_n = n_t.saturating_sub(1) * n_j.saturating_sub(1);

    let depth: Vec<f64> = lowest.iter().map(|y| (-y).max(0.0)).collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Plausibility {
        frames: n_t,
        fps: motion.fps(),
        foot_joints: {
            let mut names: Vec<String> = feet.iter().map(|p| s.joint(p.0).name.clone()).collect();
            names.dedup();
            names
        },
        foot_skating_m_s: if contacts > 0 {
            speed_sum / contacts as f64
        } else {
            0.0
        },
        contact_fraction: contacts as f64 / steps.max(1) as f64,
        penetration_mean_m: mean(&depth),
        penetration_max_m: depth.iter().copied().fold(0.0, f64::max),
        floating_fraction: lowest.iter().filter(|y| **y > th.floating_height_m).count() as f64
            / n_t as f64,
        lowest_point_mean_m: mean(&lowest),
        bone_length_drift: drift,
        jerk_m_s3: if jerk_n > 0 {
            jerk_sum / jerk_n as f64
        } else {
            0.0
        },
        pose_speed_m_s: pose_sum / pose_n.max(1) as f64,
        thresholds: *th,
    }
}

/// The clip with its root path re-integrated so that planted sole points stay
/// put: over each step `t -> t+1` the root's horizontal motion loses the mean
/// horizontal displacement of the sole points in contact ([`foot_contacts`],
/// the skating metric's rule). Steps without contact (flight, a clip in the
/// air) keep their root motion; heights and every rotation are unchanged.
///
/// Why it exists: a generative model's root path and legs are decoded
/// separately and drift apart by centimetres per frame, which the skating
/// metric and a physics tracker both see as sliding feet; when the legs step,
/// the root follows them ("root from feet").
pub fn plant_root(motion: &Motion, th: &Thresholds) -> Motion {
    let (pos, contacts) = sole_tracks(motion, th);
    let np = contacts.points.len();
    let n = motion.frames();
    let mut out = motion.clone();
    if np == 0 || n < 2 {
        return out;
    }
    let mut shift = DVec3::ZERO;
    let root = out.root_translation_mut();
    for t in 0..n - 1 {
        let (mut slide, mut k) = (DVec3::ZERO, 0usize);
        for i in 0..np {
            if contacts.steps[t * np + i].is_some() {
                let d = pos[(t + 1) * np + i] - pos[t * np + i];
                slide += DVec3::new(d.x, 0.0, d.z);
                k += 1;
            }
        }
        if k > 0 {
            shift -= slide / k as f64;
        }
        root[t + 1] += shift;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Joint, Skeleton};
    use glam::DQuat;
    use std::sync::Arc;

    fn legs() -> Arc<Skeleton> {
        let j = |name: &str, parent: Option<usize>, o: [f64; 3], end: Option<[f64; 3]>| Joint {
            name: name.into(),
            parent,
            offset: DVec3::from_array(o),
            channels: vec![],
            end_site: end.map(DVec3::from_array),
            limits: None,
        };
        Arc::new(
            Skeleton::new(
                vec![
                    j("Hips", None, [0.0; 3], None),
                    j("LeftUpLeg", Some(0), [0.1, 0.0, 0.0], None),
                    j("LeftLeg", Some(1), [0.0, -0.45, 0.0], None),
                    j("LeftFoot", Some(2), [0.0, -0.42, 0.0], None),
                    j(
                        "LeftToe",
                        Some(3),
                        [0.0, -0.08, 0.1],
                        Some([0.0, 0.0, 0.05]),
                    ),
                    j("RightUpLeg", Some(0), [-0.1, 0.0, 0.0], None),
                    j("RightLeg", Some(5), [0.0, -0.45, 0.0], None),
                    j("RightFoot", Some(6), [0.0, -0.42, 0.0], None),
                    j(
                        "RightToe",
                        Some(7),
                        [0.0, -0.08, 0.1],
                        Some([0.0, 0.0, 0.05]),
                    ),
                    j("Spine", Some(0), [0.0, 0.3, 0.0], Some([0.0, 0.4, 0.0])),
                ],
                1.0,
            )
            .unwrap(),
        )
    }

    /// Standing (toes on y = 0 plus `lift`), the root sliding along z at `speed`.
    fn standing(frames: usize, speed: f64, lift: f64) -> Motion {
        let s = legs();
        let n = s.len();
        let root = (0..frames)
            .map(|t| DVec3::new(0.0, 0.95 + lift, speed * t as f64 / 30.0))
            .collect();
        Motion::new(s, 30.0, root, vec![DQuat::IDENTITY; frames * n]).unwrap()
    }

    #[test]
    fn sliding_feet_skate_at_the_sliding_speed() {
        let m = plausibility(&standing(40, 0.5, 0.0));
        assert!((m.foot_skating_m_s - 0.5).abs() < 1e-9, "{m:?}");
        assert!((m.contact_fraction - 1.0).abs() < 1e-12);
        assert_eq!(
            m.foot_joints,
            ["LeftToe", "RightToe"],
            "ankles are not sole points"
        );
        let still = plausibility(&standing(40, 0.0, 0.0));
        assert!(still.foot_skating_m_s.abs() < 1e-12);
        assert!(still.penetration_max_m < 1e-12 && still.floating_fraction == 0.0);
        assert!(still.jerk_m_s3 < 1e-9 && still.bone_length_drift < 1e-12);
    }

    #[test]
    fn foot_contacts_are_the_skating_metrics_steps() {
        let th = Thresholds::default();
        let sliding = foot_contacts(&standing(40, 0.5, 0.0), &th);
        // LeftToe and RightToe with their end sites.
        assert_eq!(
            sliding.points,
            [(4, false), (4, true), (8, false), (8, true)]
        );
        assert_eq!(sliding.steps.len(), 39 * 4);
        for step in &sliding.steps {
            let speed = step.expect("planted all along");
            assert!((speed - 0.5).abs() < 1e-9, "{speed}");
        }
        let floating = foot_contacts(&standing(20, 0.3, 0.2), &th);
        assert!(floating.steps.iter().all(Option::is_none));
    }

    #[test]
    fn planting_the_root_stops_sliding_feet_and_leaves_flight_alone() {
        let th = Thresholds::default();
        let sliding = standing(40, 0.5, 0.0);
        let planted = plant_root(&sliding, &th);
        let p = plausibility(&planted);
        assert!(p.foot_skating_m_s < 1e-9, "{p:?}");
        assert!((p.contact_fraction - 1.0).abs() < 1e-12);
        // Heights and rotations are untouched.
        for t in 0..40 {
            assert_eq!(
                planted.root_translation()[t].y,
                sliding.root_translation()[t].y
            );
            assert_eq!(planted.pose(t), sliding.pose(t));
        }
        // In the air nothing is in contact: the root path is kept.
        let flying = standing(20, 0.3, 0.2);
        let kept = plant_root(&flying, &th);
        assert_eq!(kept.root_translation(), flying.root_translation());
    }

    #[test]
    fn lowering_by_5_cm_penetrates_5_cm_and_lifting_floats() {
        let m = plausibility(&standing(20, 0.0, -0.05));
        assert!((m.penetration_mean_m - 0.05).abs() < 1e-9, "{m:?}");
        assert!((m.penetration_max_m - 0.05).abs() < 1e-9);
        assert!((m.lowest_point_mean_m + 0.05).abs() < 1e-9);
        let up = plausibility(&standing(20, 0.3, 0.2));
        assert_eq!(up.floating_fraction, 1.0);
        assert!((up.lowest_point_mean_m - 0.2).abs() < 1e-9);
        assert_eq!(up.contact_fraction, 0.0);
        assert_eq!(up.foot_skating_m_s, 0.0, "no contact, no skating");
        let lows = lowest_points(&standing(20, 0.3, 0.2));
        assert_eq!(lows.len(), 20);
        assert!(lows.iter().all(|y| (y - 0.2).abs() < 1e-9), "{lows:?}");
    }

    #[test]
    fn jerk_of_a_cubic_trajectory_is_its_third_derivative() {
        // Root y(t) = 0.95 + a t^3: every joint has jerk 6a.
        let s = legs();
        let n = s.len();
        let a = 0.7;
        let root = (0..30)
            .map(|t| {
                let time = t as f64 / 30.0;
                DVec3::new(0.0, 0.95 + a * time.powi(3), 0.0)
            })
            .collect();
        let m = Motion::new(s, 30.0, root, vec![DQuat::IDENTITY; 30 * n]).unwrap();
        let p = plausibility(&m);
        assert!((p.jerk_m_s3 - 6.0 * a).abs() < 1e-6, "{}", p.jerk_m_s3);
    }

    #[test]
    fn pose_speed_counts_the_body_moving_not_travelling() {
        // Travelling at 0.5 m/s in a fixed pose: no pose speed.
        assert!(plausibility(&standing(40, 0.5, 0.0)).pose_speed_m_s < 1e-12);
        // Turning about the vertical at w rad/s: each joint moves at w times
        // its distance from the vertical through the root (0.1 m for the
        // legs, 0.1 * sqrt 2 for the toes, 0 for the spine).
        let s = legs();
        let n = s.len();
        let w = 1.5;
        let mut rot = vec![DQuat::IDENTITY; 60 * n];
        for t in 0..60 {
            rot[t * n] = DQuat::from_rotation_y(w * t as f64 / 30.0);
        }
        let m = Motion::new(s, 30.0, vec![DVec3::Y; 60], rot).unwrap();
        let mean_r = (2.0 * (3.0 * 0.1 + 0.1 * 2f64.sqrt())) / 9.0;
        let chord = 2.0 * (w / 60.0).sin() * 30.0 / w;
        let p = plausibility(&m);
        assert!(
            (p.pose_speed_m_s - w * mean_r * chord).abs() < 1e-9,
            "{} vs {}",
            p.pose_speed_m_s,
            w * mean_r * chord
        );
    }

    #[test]
    fn bone_drift_is_zero_for_rotations() {
        let s = legs();
        let n = s.len();
        let rot: Vec<DQuat> = (0..10 * n)
            .map(|i| DQuat::from_rotation_x(0.1 * i as f64))
            .collect();
        let m = Motion::new(s, 30.0, vec![DVec3::Y; 10], rot).unwrap();
        assert!(plausibility(&m).bone_length_drift < 1e-12);
    }
}
