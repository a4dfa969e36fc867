//! Contacts: feet planted on the ground, and key joint pairs between partners.
//!
//! **Feet.** Sole points are chosen as in [`motion::metrics`]: points of joints
//! named `foot`, `ankle`, `toe` or `heel` (and their end sites) whose rest
//! height is within `sole_band_m` of the lowest of them. A sole point is planted
//! at a frame when it is below `contact_height_m`, within `contact_band_m` of its
//! planted height (5th percentile of its height over the clip) and moving
//! vertically slower than `contact_vertical_speed_m_s` (the metrics' thresholds,
//! so the constraint holds exactly where skating is measured).
//!
//! **Key joint pairs** (sustained contacts between the partners): a pair of
//! joints, one per body, whose source distance stays under `threshold_m` for at
//! least `min_duration_s` in one stretch. Candidates are ranked by their mean
//! distance over that stretch and taken greedily, each joint at most once, up to
//! `max_pairs`. The threshold is generous by default (0.4 m) because CMU's hand
//! joints are wrists: in the handshake 18_01 the right hands' joints never come
//! closer than 0.29 m although the hands touch.

use glam::DVec3;
use motion::Motion;
use motion::metrics::Thresholds;
use serde::{Deserialize, Serialize};

use crate::InteractionError;
use crate::layout::{Layout, PointKind};

/// Sole points of a body and their contact flags per frame.
pub fn foot_contacts(
    motion: &Motion,
    layout: &Layout,
    positions: &[DVec3],
) -> Vec<(usize, Vec<bool>)> {
    let th = Thresholds::default();
    let s = motion.skeleton();
    let words = ["foot", "ankle", "toe", "heel"];
    let feet: Vec<usize> = (0..layout.len())
        .filter(|&p| {
            let n = s.joint(layout.owner(p)).name.to_ascii_lowercase();
            words.iter().any(|w| n.contains(w))
        })
        .collect();
    if feet.is_empty() {
        return Vec::new();
    }
    // Rest heights of the candidates.
    let rest = Motion::new(
        s.clone(),
        motion.fps(),
        vec![DVec3::ZERO],
        vec![glam::DQuat::IDENTITY; s.len()],
    );
    let Ok(rest) = rest else { return Vec::new() };
    let mut rest_pos = Vec::new();
    layout.positions(&rest, 0, &mut rest_pos);
    let lo = feet
        .iter()
        .map(|&p| rest_pos[p].y)
        .fold(f64::INFINITY, f64::min);
    let n = layout.len();
    let frames = motion.frames();
    let dt = 1.0 / motion.fps();
    feet.into_iter()
        .filter(|&p| rest_pos[p].y <= lo + th.sole_band_m)
        .map(|p| {
            let ys: Vec<f64> = (0..frames).map(|t| positions[t * n + p].y).collect();
            let mut sorted = ys.clone();
            sorted.sort_by(f64::total_cmp);
            let planted = sorted[(sorted.len() - 1) / 20];
            let low = |t: usize| ys[t] < th.contact_height_m && ys[t] < planted + th.contact_band_m;
            let slow =
                |a: usize, b: usize| ((ys[b] - ys[a]) / dt).abs() < th.contact_vertical_speed_m_s;
            let flags = (0..frames)
                .map(|t| {
                    low(t) && (t == 0 || slow(t - 1, t)) && (t + 1 == frames || slow(t, t + 1))
                })
                .collect();
            (p, flags)
        })
        .collect()
}

/// How key joint pairs are found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct KeyPairOptions {
    /// Source distance under which a pair is in contact, metres.
    pub threshold_m: f64,
    /// Shortest contact stretch that makes a pair a key pair, seconds.
    pub min_duration_s: f64,
    /// At most this many automatically detected pairs.
    pub max_pairs: usize,
    /// Pairs given by name (A's joint, B's joint): used instead of detection.
    pub named: Vec<(String, String)>,
    /// The constraint fades in and out over this long around the stretch, seconds.
    pub ramp_s: f64,
}

impl Default for KeyPairOptions {
    fn default() -> Self {
        KeyPairOptions {
            threshold_m: 0.4,
            min_duration_s: 0.25,
            max_pairs: 2,
            named: Vec::new(),
            ramp_s: 0.25,
        }
    }
}

/// One key joint pair and its contact stretch in the source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPair {
    pub a_joint: String,
    pub b_joint: String,
    #[serde(skip)]
    pub a: usize,
    #[serde(skip)]
    pub b: usize,
    /// First and last frame (inclusive) of the contact stretch.
    pub first_frame: usize,
    pub last_frame: usize,
    pub source_mean_m: f64,
    pub source_min_m: f64,
}

/// Longest run of `true`, as (first, last) inclusive.
fn longest_run(flags: impl Iterator<Item = bool>) -> Option<(usize, usize)> {
    let mut best: Option<(usize, usize)> = None;
    let mut start = None;
    let consider = |s: usize, e: usize, best: &mut Option<(usize, usize)>| {
        if best.is_none_or(|(bs, be)| e - s > be - bs) {
            *best = Some((s, e));
        }
    };
    let mut last = 0;
    for (t, f) in flags.enumerate() {
        last = t;
        match (f, start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                consider(s, t - 1, &mut best);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        consider(s, last, &mut best);
    }
    best
}

fn distances(a: &Motion, b: &Motion, ja: usize, jb: usize, pa: &[DVec3], pb: &[DVec3]) -> Vec<f64> {
    let (na, nb) = (a.joints(), b.joints());
    (0..a.frames())
        .map(|t| (pa[t * na + ja] - pb[t * nb + jb]).length())
        .collect()
}

fn pair_from(
    a: &Motion,
    b: &Motion,
    ja: usize,
    jb: usize,
    d: &[f64],
    run: (usize, usize),
) -> KeyPair {
    let seg = &d[run.0..=run.1];
    KeyPair {
        a_joint: a.skeleton().joint(ja).name.clone(),
        b_joint: b.skeleton().joint(jb).name.clone(),
        a: ja,
        b: jb,
        first_frame: run.0,
        last_frame: run.1,
        source_mean_m: seg.iter().sum::<f64>() / seg.len() as f64,
        source_min_m: seg.iter().copied().fold(f64::INFINITY, f64::min),
    }
}

/// Key pairs of the source clips `a` and `b` (see the module doc). Named pairs
/// use the longest stretch under the threshold, or, if they never come that
/// close, the longest stretch within 1.5 times their closest distance.
pub fn key_pairs(
    a: &Motion,
    b: &Motion,
    layout_a: &Layout,
    layout_b: &Layout,
    o: &KeyPairOptions,
) -> Result<Vec<KeyPair>, InteractionError> {
    let bad = |field: &'static str, message: String| InteractionError::Option { field, message };
    if !(o.threshold_m.is_finite() && o.threshold_m > 0.0) {
        return Err(bad(
            "threshold_m",
            format!("{} is not positive", o.threshold_m),
        ));
    }
    if !(o.min_duration_s.is_finite() && o.min_duration_s >= 0.0) {
        return Err(bad(
            "min_duration_s",
            format!("{} is negative", o.min_duration_s),
        ));
    }
    if !(o.ramp_s.is_finite() && o.ramp_s >= 0.0) {
        return Err(bad("ramp_s", format!("{} is negative", o.ramp_s)));
    }
    let pa = a.all_world_positions();
    let pb = b.all_world_positions();
    if !o.named.is_empty() {
        return o
            .named
            .iter()
            .map(|(na, nb)| {
                let ja = a
                    .skeleton()
                    .find(na)
                    .ok_or_else(|| InteractionError::KeyPair(format!("A has no joint `{na}`")))?;
                let jb = b
                    .skeleton()
                    .find(nb)
                    .ok_or_else(|| InteractionError::KeyPair(format!("B has no joint `{nb}`")))?;
                let d = distances(a, b, ja, jb, &pa, &pb);
                let min = d.iter().copied().fold(f64::INFINITY, f64::min);
                let run = longest_run(d.iter().map(|v| *v < o.threshold_m))
                    .or_else(|| longest_run(d.iter().map(|v| *v <= 1.5 * min)))
                    .unwrap_or((0, d.len() - 1));
                Ok(pair_from(a, b, ja, jb, &d, run))
            })
            .collect();
    }
    let min_frames = ((o.min_duration_s * a.fps()).ceil() as usize).max(1);
    let owners = |l: &Layout| -> Vec<usize> {
        l.points
            .iter()
            .filter_map(|p| match p {
                PointKind::Joint(j) => Some(*j),
                PointKind::EndSite(_) => None,
            })
            .collect()
    };
    let mut candidates = Vec::new();
    for ja in owners(layout_a) {
        for jb in owners(layout_b) {
            let d = distances(a, b, ja, jb, &pa, &pb);
            if let Some(run) = longest_run(d.iter().map(|v| *v < o.threshold_m))
                && run.1 + 1 - run.0 >= min_frames
            {
                candidates.push(pair_from(a, b, ja, jb, &d, run));
            }
        }
    }
    candidates.sort_by(|x, y| x.source_mean_m.total_cmp(&y.source_mean_m));
    let mut chosen: Vec<KeyPair> = Vec::new();
    for c in candidates {
        if chosen.len() >= o.max_pairs {
            break;
        }
        if chosen.iter().any(|k| k.a == c.a || k.b == c.b) {
            continue;
        }
        chosen.push(c);
    }
    Ok(chosen)
}

/// Per-frame weight of a key pair: 1 over its stretch, fading linearly to 0
/// over `ramp` frames either side.
pub fn pair_weights(pair: &KeyPair, frames: usize, ramp: usize) -> Vec<f64> {
    (0..frames)
        .map(|t| {
            let outside = pair.first_frame.saturating_sub(t) + t.saturating_sub(pair.last_frame);
            if outside == 0 {
                1.0
            } else if outside > ramp {
                0.0
            } else {
                1.0 - outside as f64 / (ramp + 1) as f64
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn longest_runs() {
        let f = |v: &[u8]| longest_run(v.iter().map(|x| *x == 1));
        assert_eq!(f(&[0, 1, 1, 0, 1, 1, 1]), Some((4, 6)));
        assert_eq!(f(&[1, 1, 0, 1]), Some((0, 1)));
        assert_eq!(f(&[0, 0]), None);
    }

    #[test]
    fn weights_ramp() {
        let k = KeyPair {
            a_joint: "x".into(),
            b_joint: "y".into(),
            a: 0,
            b: 0,
            first_frame: 3,
            last_frame: 4,
            source_mean_m: 0.0,
            source_min_m: 0.0,
        };
        let w = pair_weights(&k, 8, 1);
        assert_eq!(w, vec![0.0, 0.0, 0.5, 1.0, 1.0, 0.5, 0.0, 0.0]);
    }
}
