//! Keeping the simulation's ground contacts through debiasing.
//!
//! Why this exists: the debiasing network changes joint rotations frame by
//! frame, and a leg rotated by a few degrees moves its planted foot: the
//! session-3 debiaser (which also rewrote the root's height and path) turned
//! corrected clips that stood still on their feet back into skating, floating
//! ones (kick: foot skating 0.10 -> 0.33 m/s, floating frames 17 -> 54 %). The
//! physically corrected clip is the one thing that knows where the feet touch
//! the ground, so after the network has run, every foot the corrected clip has
//! planted is put back where the simulation put it:
//!
//! * A foot is planted at a frame of the corrected clip when its lowest point
//!   (the ankle, the joints below it and their end sites) is within
//!   `height_band_m` of that foot's planted height (the 5th percentile of its
//!   lowest point over the clip) and its ankle moves slower than
//!   `max_speed_m_s` horizontally; with `metric_contacts` (the default), also
//!   wherever the foot skating metric ([`motion::metrics::foot_contacts`])
//!   sees one of its sole points touching the ground. Why both: a foot
//!   rolling onto its toes (push-off) moves its ankle faster than
//!   `max_speed_m_s` while its toes stay on the floor; left to the network,
//!   those toes slid, and debiasing raised the skating of corrected IK grabs
//!   and kicks from 0.03-0.05 to 0.16-0.20 m/s (session 13).
//! * In planted frames the leg is solved with the two-bone IK of the synthesis
//!   crate (`synth::ik::limb`, joint limits respected) so the ankle reaches the
//!   corrected clip's ankle, the foot takes the corrected clip's world
//!   orientation and the joints below it (toes) their corrected rotations.
//! * The weight of that edit ramps linearly to zero over `blend_s` on either
//!   side of a contact, so the leg does not pop when a contact starts or ends.
//! * With `flatten_soles`, a planted foot whose lowest point is higher than
//!   the sole height of real planted feet (learnt from the training pairs'
//!   corrected originals, [`sole_height`]) is pitched down about its ankle
//!   until it reaches it. Why: a VAE sample whose feet point up is tracked
//!   by the simulation standing on the heel edges of its foot boxes (the
//!   PD-residual root force keeps it balanced), so the corrected clip's toes
//!   hang 5-9 cm above the floor while the character stands (grab: 47 % of
//!   frames "floating"); the heel is not a point of the file's skeleton.
//!   Only a foot standing still is pitched (every point of the corrected
//!   clip's foot slower than `still_speed_m_s`, acceptance's "planted"), with
//!   the same ramp: a foot pivoting on its heel or landing, pitched onto the
//!   floor, would slide its toes along it (corrected IK grabs: skating 0.031
//!   -> 0.042 m/s when every planted frame was pitched).
//! * With `lift_lowered_feet`, a foot the corrected clip has not planted is
//!   never left lower than the corrected clip has it, within `clearance_m`
//!   of the floor: the network's leg rotations can otherwise push a swinging
//!   foot into the floor or skim it along it (corrected IK grabs: toes 8 cm
//!   under the floor at the end of a clip; skating 0.029 m/s corrected ->
//!   0.21 m/s debiased, 0.031 lifted).
//!
//! The root is not touched here: the debiased clip already carries the
//! corrected clip's root path (see [`crate::features::apply_rotations`]).

use motion::Motion;
use motion::glam::{DQuat, DVec3};
use motion::metrics::{FootContacts, Thresholds, foot_contacts};
use motion::skeleton::Transform;
use serde::{Deserialize, Serialize};
use synth::ik::limb::{EffectorOrientation, Limb, SolveOptions, solve_frame};

use crate::{DebiasError, Result};

/// How contacts are found and restored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactConfig {
    /// Restore the corrected clip's contacts at all (off = the network's output as is).
    pub restore: bool,
    /// A foot whose lowest point is this close to its planted height may be in contact.
    pub height_band_m: f64,
    /// Largest horizontal ankle speed of a planted foot.
    pub max_speed_m_s: f64,
    /// Ramp of the restoring edit before and after a contact.
    pub blend_s: f64,
    /// Pitch planted feet down onto the learnt sole height (see the module docs).
    pub flatten_soles: bool,
    /// Also treat a foot as planted wherever the foot skating metric sees one
    /// of its sole points in contact (see the module docs).
    pub metric_contacts: bool,
    /// Where the corrected clip has not planted a foot, never leave it lower
    /// than the corrected clip has it once it is within `clearance_m` of the
    /// floor: lift it back with the leg IK (see the module docs).
    pub lift_lowered_feet: bool,
    /// Height above the planted height under which `lift_lowered_feet` acts
    /// (the foot skating metric's contact height).
    pub clearance_m: f64,
    /// A planted foot is pitched onto the sole height only where every point
    /// of it moves slower than this (3D) in the corrected clip.
    pub still_speed_m_s: f64,
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig {
            restore: true,
            height_band_m: 0.03,
            max_speed_m_s: 0.5,
            blend_s: 0.1,
            flatten_soles: true,
            metric_contacts: true,
            lift_lowered_feet: true,
            clearance_m: 0.1,
            still_speed_m_s: 0.2,
        }
    }
}

impl ContactConfig {
    pub fn validate(&self) -> Result<()> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.height_band_m)
            || !positive(self.max_speed_m_s)
            || !positive(self.clearance_m)
            || !positive(self.still_speed_m_s)
        {
            return Err(DebiasError::Config(format!(
                "contact height_band_m {}, max_speed_m_s {}, clearance_m {} and still_speed_m_s {} \
                 must be positive",
                self.height_band_m, self.max_speed_m_s, self.clearance_m, self.still_speed_m_s
            )));
        }
        if !(self.blend_s.is_finite() && self.blend_s >= 0.0) {
            return Err(DebiasError::Config(format!(
                "contact blend_s {} is negative",
                self.blend_s
            )));
        }
        Ok(())
    }
}

/// What restoring did to one clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct ContactReport {
    /// Legs found (two on a human skeleton; 0 = nothing could be restored).
    pub legs: usize,
    /// Planted (foot, frame) pairs in the corrected clip.
    pub planted: usize,
    /// Largest ankle distance to the corrected clip's ankle in planted frames after restoring, m.
    pub max_ankle_error_m: f64,
    /// Planted (foot, frame) pairs pitched down onto the sole height.
    pub flattened: usize,
    /// Unplanted (foot, frame) pairs the network had lowered towards the
    /// floor, lifted back.
    #[serde(default)]
    pub lifted: usize,
}

/// A leg: its IK chain and the joints of its foot (the ankle and everything below).
struct Leg {
    limb: Limb,
    foot: Vec<usize>,
}

fn legs(motion: &Motion, frames: &[Vec<Transform>]) -> Vec<Leg> {
    let skeleton = motion.skeleton();
    synth::names::feet(skeleton)
        .into_iter()
        .filter_map(|ankle| {
            let mut limb = Limb::new(skeleton, ankle).ok()?;
            limb.estimate_hinge(skeleton, frames);
            let mut foot = vec![ankle];
            let mut i = 0;
            while i < foot.len() {
                foot.extend(skeleton.children(foot[i]));
                i += 1;
            }
            Some(Leg { limb, foot })
        })
        .collect()
}

/// The points of a foot (its joints and their end sites) in one frame.
fn foot_points<'a>(
    motion: &'a Motion,
    x: &'a [Transform],
    foot: &'a [usize],
) -> impl Iterator<Item = DVec3> + 'a {
    let skeleton = motion.skeleton();
    foot.iter().flat_map(move |&j| {
        let end = skeleton
            .joint(j)
            .end_site
            .map(|e| x[j].translation + x[j].rotation * e);
        std::iter::once(x[j].translation).chain(end)
    })
}

/// Height of the lowest point of a foot in one frame.
fn lowest(motion: &Motion, x: &[Transform], foot: &[usize]) -> f64 {
    foot_points(motion, x, foot)
        .map(|p| p.y)
        .fold(f64::INFINITY, f64::min)
}

/// Per frame, the height of the lowest point of the leg's foot in `frames`
/// (world transforms of `motion`).
fn lowest_track(motion: &Motion, frames: &[Vec<Transform>], leg: &Leg) -> Vec<f64> {
    frames
        .iter()
        .map(|x| lowest(motion, x, &leg.foot))
        .collect()
}

/// Per frame, is the leg's foot planted in `frames` (world transforms of
/// `motion`)? `heights` is the foot's [`lowest_track`]; `metric` the foot
/// skating metric's contacts of `motion` (`None`: the height-and-speed rule
/// alone).
fn planted(
    motion: &Motion,
    frames: &[Vec<Transform>],
    heights: &[f64],
    leg: &Leg,
    config: &ContactConfig,
    metric: Option<&FootContacts>,
) -> Vec<bool> {
    let n = frames.len();
    if n == 0 {
        return Vec::new();
    }
    let floor = planted_height(heights);
    let ankle = leg.limb.effector;
    let horizontal = |v: DVec3| DVec3::new(v.x, 0.0, v.z).length();
    let mut out: Vec<bool> = (0..n)
        .map(|t| {
            let (a, b) = if t + 1 < n {
                (t, t + 1)
            } else {
                (t.saturating_sub(1), t)
            };
            let speed = if a == b {
                0.0
            } else {
                horizontal(frames[b][ankle].translation - frames[a][ankle].translation)
                    * motion.fps()
            };
            heights[t] <= floor + config.height_band_m && speed <= config.max_speed_m_s
        })
        .collect();
    if let Some(metric) = metric {
        let np = metric.points.len();
        let mine: Vec<usize> = (0..np)
            .filter(|&i| leg.foot.contains(&metric.points[i].0))
            .collect();
        for (step, speeds) in metric.steps.chunks(np.max(1)).enumerate() {
            if mine.iter().any(|&i| speeds[i].is_some()) {
                out[step] = true;
                if step + 1 < n {
                    out[step + 1] = true;
                }
            }
        }
    }
    out
}

/// Per frame, does every point of the leg's foot move slower than `speed`
/// (m/s, 3D, forward differences; the last frame takes the step before it)?
fn standing_still(motion: &Motion, frames: &[Vec<Transform>], leg: &Leg, speed: f64) -> Vec<bool> {
    let n = frames.len();
    let points: Vec<Vec<DVec3>> = frames
        .iter()
        .map(|x| foot_points(motion, x, &leg.foot).collect())
        .collect();
    (0..n)
        .map(|t| {
            if n < 2 {
                return true;
            }
            let (a, b) = if t + 1 < n { (t, t + 1) } else { (t - 1, t) };
            points[a]
                .iter()
                .zip(&points[b])
                .all(|(p, q)| (*q - *p).length() * motion.fps() < speed)
        })
        .collect()
}

/// Where a foot stands when planted: the 5th percentile of the heights of its
/// lowest point over a clip (`heights`, one per frame, not empty).
fn planted_height(heights: &[f64]) -> f64 {
    let mut sorted = heights.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted[(sorted.len() - 1) * 5 / 100]
}

/// The foot skating metric's contacts of `motion` when `config` asks for them.
fn metric_contacts(motion: &Motion, config: &ContactConfig) -> Option<FootContacts> {
    config
        .metric_contacts
        .then(|| foot_contacts(motion, &Thresholds::default()))
}

/// What restoring does to one leg, per frame of the corrected clip.
struct LegPlan {
    /// Planted in the corrected clip.
    contact: Vec<bool>,
    /// Weight of the restoring edit.
    weight: Vec<f64>,
    /// Weight of the sole flattening (planted and standing still).
    flat: Vec<f64>,
    /// Lowest height the foot's lowest point may have where not planted.
    floor: Vec<f64>,
}

/// Edit weight per frame: 1 in contact, ramping down linearly over `ramp` frames.
fn weights(contact: &[bool], ramp: usize) -> Vec<f64> {
    let n = contact.len();
    let mut distance = vec![usize::MAX; n];
    let mut last = None;
    for t in 0..n {
        if contact[t] {
            last = Some(t);
        }
        if let Some(c) = last {
            distance[t] = t - c;
        }
    }
    let mut next = None;
    for t in (0..n).rev() {
        if contact[t] {
            next = Some(t);
        }
        if let Some(c) = next {
            distance[t] = distance[t].min(c - t);
        }
    }
    distance
        .iter()
        .map(|&d| {
            if d == usize::MAX {
                0.0
            } else {
                (1.0 - d as f64 / (ramp + 1) as f64).max(0.0)
            }
        })
        .collect()
}

/// Median height of the lowest foot point over the planted frames of `clips`
/// (corrected clips in the simulation's floor frame): where real planted
/// soles are. `None` without legs or planted frames.
pub fn sole_height(clips: &[&Motion], config: &ContactConfig) -> Option<f64> {
    let mut heights = Vec::new();
    for clip in clips {
        let frames: Vec<Vec<Transform>> = (0..clip.frames())
            .map(|t| clip.world_transforms(t))
            .collect();
        if frames.is_empty() {
            continue;
        }
        let metric = metric_contacts(clip, config);
        for leg in legs(clip, &frames) {
            let track = lowest_track(clip, &frames, &leg);
            let contact = planted(clip, &frames, &track, &leg, config, metric.as_ref());
            heights.extend(
                track
                    .iter()
                    .zip(contact)
                    .filter(|(_, c)| *c)
                    .map(|(h, _)| h),
            );
        }
    }
    if heights.is_empty() {
        return None;
    }
    heights.sort_by(f64::total_cmp);
    Some(heights[heights.len() / 2])
}

/// Largest pitch (rad) a foot is turned down by to reach the sole height.
const MAX_PITCH: f64 = 1.2;

/// The downward pitch about the ankle that puts the foot's lowest point at
/// `target` (0 when it is already there or lower; at most [`MAX_PITCH`]).
/// `x` are the frame's world transforms; the pitch axis is horizontal and
/// across the foot, so a positive angle lowers the toes.
fn pitch_to(motion: &Motion, x: &[Transform], leg: &Leg, target: f64) -> (DVec3, f64) {
    let ankle = leg.limb.effector;
    let a = x[ankle].translation;
    let points: Vec<DVec3> = foot_points(motion, x, &leg.foot).map(|p| p - a).collect();
    let reach = points
        .iter()
        .copied()
        .max_by(|p, q| {
            let h = |v: &DVec3| DVec3::new(v.x, 0.0, v.z).length();
            h(p).total_cmp(&h(q))
        })
        .unwrap_or(DVec3::ZERO);
    let forward = DVec3::new(reach.x, 0.0, reach.z);
    if forward.length() < 1e-6 {
        return (DVec3::X, 0.0);
    }
    let axis = DVec3::Y.cross(forward).normalize();
    let low = |theta: f64| {
        let q = DQuat::from_axis_angle(axis, theta);
        points
            .iter()
            .map(|p| a.y + (q * *p).y)
            .fold(f64::INFINITY, f64::min)
    };
    if low(0.0) <= target {
        return (axis, 0.0);
    }
    if low(MAX_PITCH) > target {
        return (axis, MAX_PITCH);
    }
    let (mut lo, mut hi) = (0.0, MAX_PITCH);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if low(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (axis, hi)
}

fn world(motion: &Motion, root: DVec3, pose: &[DQuat], out: &mut [Transform]) {
    motion.skeleton().forward(root, pose, out);
}

/// Put the feet of `debiased` back where `corrected` plants them. Both clips
/// must have the same skeleton layout and frame count (`debiased` is made from
/// `corrected`); `debiased`'s root path is kept.
///
/// `sole_height_m` is where planted soles belong ([`sole_height`]); feet are
/// only pitched onto it with `config.flatten_soles`.
pub fn restore(
    debiased: &Motion,
    corrected: &Motion,
    config: &ContactConfig,
    sole_height_m: Option<f64>,
) -> Result<(Motion, ContactReport)> {
    config.validate()?;
    if debiased.joints() != corrected.joints() || debiased.frames() != corrected.frames() {
        return Err(DebiasError::Data(format!(
            "restoring contacts needs the clip debiasing started from: {} joints x {} frames \
             against {} x {}",
            debiased.joints(),
            debiased.frames(),
            corrected.joints(),
            corrected.frames()
        )));
    }
    let n = corrected.frames();
    let mut report = ContactReport::default();
    if !config.restore || n == 0 {
        return Ok((debiased.clone(), report));
    }
    let reference: Vec<Vec<Transform>> = (0..n).map(|t| corrected.world_transforms(t)).collect();
    let legs = legs(corrected, &reference);
    report.legs = legs.len();
    if legs.is_empty() {
        tracing::warn!("no legs found by joint names: contacts not restored");
        return Ok((debiased.clone(), report));
    }
    let ramp = (config.blend_s * corrected.fps()).round() as usize;
    let metric = metric_contacts(corrected, config);
    // Per leg: planted frames, the restoring weight, the flattening weight
    // (planted and standing still), and per frame the lowest a foot the
    // corrected clip has not planted may go (where the corrected clip has it,
    // up to `clearance_m` above its planted height; see `lift_lowered_feet`).
    let per_leg: Vec<LegPlan> = legs
        .iter()
        .map(|leg| {
            let heights = lowest_track(corrected, &reference, leg);
            let contact = planted(
                corrected,
                &reference,
                &heights,
                leg,
                config,
                metric.as_ref(),
            );
            let still = standing_still(corrected, &reference, leg, config.still_speed_m_s);
            let flat: Vec<bool> = contact.iter().zip(&still).map(|(c, s)| *c && *s).collect();
            let top = planted_height(&heights) + config.clearance_m;
            LegPlan {
                weight: weights(&contact, ramp),
                flat: weights(&flat, ramp),
                floor: heights.iter().map(|h| h.min(top)).collect(),
                contact,
            }
        })
        .collect();
    report.planted = per_leg
        .iter()
        .map(|p| p.contact.iter().filter(|c| **c).count())
        .sum();

    let skeleton = debiased.skeleton();
    let nj = debiased.joints();
    // Every leg edit keeps the foot's world orientation and the joint limits.
    let options = SolveOptions {
        orientation: EffectorOrientation::World,
        respect_limits: true,
    };
    let mut rotations = Vec::with_capacity(n * nj);
    let mut x = vec![Transform::IDENTITY; nj];
    for (t, target_x) in reference.iter().enumerate() {
        let root = debiased.root_translation()[t];
        let original = debiased.pose(t).to_vec();
        let mut pose = original.clone();
        for (leg, plan) in legs.iter().zip(&per_leg) {
            let (w, flat, contact) = (plan.weight[t], plan.flat[t], plan.contact[t]);
            if w > 0.0 {
                let ankle = leg.limb.effector;
                world(debiased, root, &pose, &mut x);
                let target = x[ankle].translation.lerp(target_x[ankle].translation, w);
                solve_frame(
                    skeleton, &leg.limb, &x, &mut pose, &original, target, options,
                );
                world(debiased, root, &pose, &mut x);
                let parent = skeleton.parent(ankle).unwrap_or(0);
                let want = x[ankle].rotation.slerp(target_x[ankle].rotation, w);
                pose[ankle] = (x[parent].rotation.inverse() * want).normalize();
                for &j in &leg.foot[1..] {
                    pose[j] = pose[j].slerp(corrected.rotation(t, j), w).normalize();
                }
                if let (true, Some(target), true) =
                    (config.flatten_soles, sole_height_m, flat > 0.0)
                {
                    world(debiased, root, &pose, &mut x);
                    let (axis, theta) = pitch_to(debiased, &x, leg, target);
                    if theta > 0.0 {
                        let turned = DQuat::from_axis_angle(axis, flat * theta) * x[ankle].rotation;
                        pose[ankle] = (x[parent].rotation.inverse() * turned).normalize();
                        if contact {
                            report.flattened += 1;
                        }
                    }
                }
                if contact {
                    world(debiased, root, &pose, &mut x);
                    let e = (x[ankle].translation - target_x[ankle].translation).length();
                    report.max_ankle_error_m = report.max_ankle_error_m.max(e);
                }
            }
            if config.lift_lowered_feet && !contact {
                world(debiased, root, &pose, &mut x);
                let lift = plan.floor[t] - lowest(debiased, &x, &leg.foot);
                if lift > 1e-4 {
                    let ankle = leg.limb.effector;
                    let target = x[ankle].translation + DVec3::Y * lift;
                    solve_frame(
                        skeleton, &leg.limb, &x, &mut pose, &original, target, options,
                    );
                    report.lifted += 1;
                }
            }
        }
        rotations.extend(pose);
    }
    let restored = debiased.with_frames(
        debiased.fps(),
        debiased.root_translation().to_vec(),
        rotations,
    )?;
    Ok((restored, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::tests::walk;

    #[test]
    fn weights_ramp_around_contacts() {
        let c = [false, false, false, true, true, false, false, false, false];
        let w = weights(&c, 2);
        let want = [
            0.0,
            1.0 / 3.0,
            2.0 / 3.0,
            1.0,
            1.0,
            2.0 / 3.0,
            1.0 / 3.0,
            0.0,
            0.0,
        ];
        for (a, b) in w.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        assert!(weights(&[false; 4], 3).iter().all(|w| *w == 0.0));
    }

    /// `m` with both knees bent further by `angle` in every frame.
    fn bent_knees(m: &Motion, angle: f64) -> Motion {
        let s = m.skeleton();
        let knees: Vec<usize> = synth::names::feet(s)
            .into_iter()
            .filter_map(|a| s.parent(a))
            .collect();
        assert_eq!(knees.len(), 2, "two knees on the HDM05 skeleton");
        let nj = m.joints();
        let mut rot = m.rotations().to_vec();
        for t in 0..m.frames() {
            for &k in &knees {
                rot[t * nj + k] *= DQuat::from_rotation_x(angle);
            }
        }
        m.with_frames(m.fps(), m.root_translation().to_vec(), rot)
            .expect("motion")
    }

    fn ankle_error(a: &Motion, b: &Motion, t: usize, ankle: usize) -> f64 {
        (a.world_transforms(t)[ankle].translation - b.world_transforms(t)[ankle].translation)
            .length()
    }

    #[test]
    fn planted_feet_go_back_to_the_corrected_clip() {
        let corrected = walk();
        let edited = bent_knees(&corrected, 0.3);
        let (restored, report) =
            restore(&edited, &corrected, &ContactConfig::default(), None).expect("restore");
        assert_eq!(report.legs, 2);
        assert!(report.planted > corrected.frames() / 2, "{report:?}");
        assert!(report.max_ankle_error_m < 2e-3, "{report:?}");
        // Before restoring, bending the knees moved the planted feet by centimetres.
        let reference: Vec<_> = (0..corrected.frames())
            .map(|t| corrected.world_transforms(t))
            .collect();
        let leg = &legs(&corrected, &reference)[0];
        let heights = lowest_track(&corrected, &reference, leg);
        let contact = planted(
            &corrected,
            &reference,
            &heights,
            leg,
            &ContactConfig::default(),
            None,
        );
        let t = contact.iter().position(|c| *c).expect("a planted frame");
        let ankle = leg.limb.effector;
        assert!(ankle_error(&edited, &corrected, t, ankle) > 0.02);
        assert!(ankle_error(&restored, &corrected, t, ankle) < 2e-3);
        // The foot's world orientation is the corrected one too.
        let a = restored.world_transforms(t)[ankle].rotation;
        let b = reference[t][ankle].rotation;
        assert!(motion::rotation::angle_between(a, b) < 1e-3);
        // Root untouched; upper body untouched.
        assert_eq!(restored.root_translation(), edited.root_translation());
        let head = corrected.skeleton().find("head").expect("HDM05 head");
        for t in 0..corrected.frames() {
            assert_eq!(restored.rotation(t, head), edited.rotation(t, head));
        }
    }

    /// Largest difference, over the steps where `corrected`'s sole points
    /// touch the ground (the skating metric's rule), between the horizontal
    /// speeds of the same points in `corrected` and in `other`.
    fn contact_speed_change(corrected: &Motion, other: &Motion) -> f64 {
        let th = Thresholds::default();
        let c = foot_contacts(corrected, &th);
        let np = c.points.len();
        let speed = |m: &Motion, t: usize, i: usize| {
            let (j, end) = c.points[i];
            let at = |t: usize| {
                let x = m.world_transforms(t);
                match (end, m.skeleton().joint(j).end_site) {
                    (true, Some(e)) => x[j].translation + x[j].rotation * e,
                    _ => x[j].translation,
                }
            };
            let v = (at(t + 1) - at(t)) * m.fps();
            DVec3::new(v.x, 0.0, v.z).length()
        };
        let mut worst: f64 = 0.0;
        for (t, steps) in c.steps.chunks(np).enumerate() {
            for (i, s) in steps.iter().enumerate() {
                if s.is_some() {
                    worst = worst.max((speed(other, t, i) - speed(corrected, t, i)).abs());
                }
            }
        }
        worst
    }

    #[test]
    fn soles_touching_the_ground_keep_the_corrected_clips_speed() {
        let corrected = walk();
        let edited = bent_knees(&corrected, 0.3);
        assert!(
            contact_speed_change(&corrected, &edited) > 0.05,
            "bending the knees moves the soles in contact"
        );
        let (restored, _) =
            restore(&edited, &corrected, &ContactConfig::default(), None).expect("restore");
        let change = contact_speed_change(&corrected, &restored);
        assert!(change < 0.02, "contact speeds changed by {change} m/s");
    }

    #[test]
    fn feet_the_network_lowers_towards_the_floor_are_lifted_back() {
        let corrected = walk();
        let config = ContactConfig::default();
        let reference: Vec<_> = (0..corrected.frames())
            .map(|t| corrected.world_transforms(t))
            .collect();
        let metric = metric_contacts(&corrected, &config);
        // Straightening the knees lowers the feet where the corrected clip
        // swings them with bent knees.
        let edited = bent_knees(&corrected, -0.3);
        // (lowest of `m`, lowest of the corrected clip) per unplanted frame
        // where the corrected foot is within the clearance.
        let dips = |m: &Motion| -> Vec<(f64, f64)> {
            let mut out = Vec::new();
            for leg in legs(&corrected, &reference) {
                let heights = lowest_track(&corrected, &reference, &leg);
                let c = planted(
                    &corrected,
                    &reference,
                    &heights,
                    &leg,
                    &config,
                    metric.as_ref(),
                );
                let top = planted_height(&heights) + config.clearance_m;
                for t in 0..corrected.frames() {
                    if !c[t] && heights[t] < top {
                        out.push((lowest(m, &m.world_transforms(t), &leg.foot), heights[t]));
                    }
                }
            }
            out
        };
        let before = dips(&edited);
        assert!(
            before.iter().any(|(m, c)| m < &(c - 0.02)),
            "the edit lowers unplanted feet: {before:?}"
        );
        let (lifted, report) = restore(&edited, &corrected, &config, None).expect("restore");
        assert!(report.lifted > 0, "{report:?}");
        for (m, c) in dips(&lifted) {
            assert!(m > c - 2e-3, "foot at {m} under the corrected clip's {c}");
        }
        let off = ContactConfig {
            lift_lowered_feet: false,
            ..config
        };
        let (_, r) = restore(&edited, &corrected, &off, None).expect("restore");
        assert_eq!(r.lifted, 0);
    }

    /// `m` with both feet pitched toes-up by `angle` (world, about the lateral axis).
    fn toes_up(m: &Motion, angle: f64) -> Motion {
        let s = m.skeleton();
        let nj = m.joints();
        let mut rot = m.rotations().to_vec();
        for t in 0..m.frames() {
            let x = m.world_transforms(t);
            for ankle in synth::names::feet(s) {
                let parent = s.parent(ankle).expect("ankle has a parent");
                let toe = s.children(ankle).next().expect("HDM05 toes");
                let d = x[toe].translation - x[ankle].translation;
                let axis = DVec3::Y.cross(DVec3::new(d.x, 0.0, d.z)).normalize();
                let w = DQuat::from_axis_angle(axis, -angle) * x[ankle].rotation;
                rot[t * nj + ankle] = (x[parent].rotation.inverse() * w).normalize();
            }
        }
        m.with_frames(m.fps(), m.root_translation().to_vec(), rot)
            .expect("motion")
    }

    /// Highest lowest-foot-point of `m` over the frames where `by` plants that
    /// foot and it stands still (the frames flattening pitches).
    fn lowest_planted(m: &Motion, by: &Motion, config: &ContactConfig) -> f64 {
        let frames: Vec<_> = (0..m.frames()).map(|t| m.world_transforms(t)).collect();
        let by_frames: Vec<_> = (0..by.frames()).map(|t| by.world_transforms(t)).collect();
        let mut worst = f64::NEG_INFINITY;
        let metric = metric_contacts(by, config);
        for leg in legs(by, &by_frames) {
            let heights = lowest_track(by, &by_frames, &leg);
            let contact = planted(by, &by_frames, &heights, &leg, config, metric.as_ref());
            let still = standing_still(by, &by_frames, &leg, config.still_speed_m_s);
            for ((x, c), s) in frames.iter().zip(contact).zip(still) {
                if c && s {
                    worst = worst.max(lowest(m, x, &leg.foot));
                }
            }
        }
        worst
    }

    #[test]
    fn flattening_pitches_raised_planted_feet_onto_the_sole_height() {
        let real = walk();
        let config = ContactConfig::default();
        assert!(config.flatten_soles, "on by default");
        let sole = sole_height(&[&real], &config).expect("planted frames");
        let raised = toes_up(&real, 0.5);
        // Toes up by 0.5 rad lifts the planted soles by centimetres.
        assert!(lowest_planted(&raised, &raised, &config) > sole + 0.03);
        let (flat, report) = restore(&raised, &raised, &config, Some(sole)).expect("restore");
        assert!(report.flattened > 0, "{report:?}");
        let after = lowest_planted(&flat, &raised, &config);
        assert!(
            (after - sole).abs() < 0.01,
            "sole {sole}, planted feet at {after}"
        );
        // The ankle stays where it was; without flattening the feet stay raised.
        assert!(report.max_ankle_error_m < 2e-3, "{report:?}");
        let off = ContactConfig {
            flatten_soles: false,
            ..config
        };
        let (same, r) = restore(&raised, &raised, &off, Some(sole)).expect("restore");
        assert_eq!(r.flattened, 0);
        let moved = same
            .rotations()
            .iter()
            .zip(raised.rotations())
            .map(|(a, b)| motion::rotation::angle_between(*a, *b))
            .fold(0.0, f64::max);
        assert!(
            moved < 1e-3,
            "restoring a clip onto itself turned a joint by {moved} rad"
        );
    }

    #[test]
    fn restoring_can_be_switched_off_and_checks_its_input() {
        let corrected = walk();
        let edited = bent_knees(&corrected, 0.2);
        let off = ContactConfig {
            restore: false,
            ..ContactConfig::default()
        };
        let (same, _) = restore(&edited, &corrected, &off, None).expect("restore");
        assert_eq!(same.rotations(), edited.rotations());
        let short = corrected
            .with_frames(
                corrected.fps(),
                corrected.root_translation()[..10].to_vec(),
                corrected.rotations()[..10 * corrected.joints()].to_vec(),
            )
            .expect("short");
        assert!(matches!(
            restore(&edited, &short, &ContactConfig::default(), None),
            Err(DebiasError::Data(_))
        ));
        let bad = ContactConfig {
            height_band_m: -1.0,
            ..ContactConfig::default()
        };
        assert!(matches!(
            restore(&edited, &corrected, &bad, None),
            Err(DebiasError::Config(_))
        ));
    }
}
