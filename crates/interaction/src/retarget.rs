//! Retargeting one interaction to a new body size for partner B: the product
//! feature (`motionaug interaction retarget`) and the source of training data.
//!
//! Steps: B's skeleton is scaled ([`crate::scale`]) and B's clip naively
//! retargeted (same rotations) to give the *reference*; both bodies' point
//! positions go through the interaction-mesh optimiser ([`crate::solve`]); the
//! solved points are turned back into rotations on A's own skeleton and on B's
//! scaled one ([`crate::ik`]), so bone lengths are exact. The report measures
//! what the paper measures plus the plausibility of the feet.

use std::time::Instant;

use glam::DVec3;
use motion::{Motion, metrics};
use serde::{Deserialize, Serialize};

use crate::contact::{self, KeyPair, KeyPairOptions};
use crate::layout::{Layout, Rod, locked_joints};
use crate::scale::{BoneScale, naive_retarget};
use crate::solve::{FootTerm, PairTerm, Problem, SolveStats, SolverOptions};
use crate::{InteractionError, ik};

/// Everything that steers a retarget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RetargetOptions {
    pub solver: SolverOptions,
    pub key_pairs: KeyPairOptions,
    /// Hold planted feet (sole points in contact in the reference) in place
    /// (default true).
    pub plant_feet: bool,
}

impl Default for RetargetOptions {
    fn default() -> Self {
        RetargetOptions {
            solver: SolverOptions::default(),
            key_pairs: KeyPairOptions::default(),
            plant_feet: true,
        }
    }
}

/// A key pair's distance in the source and in the output over its stretch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPairReport {
    #[serde(flatten)]
    pub pair: KeyPair,
    pub output_mean_m: f64,
    /// Mean |output distance - source distance| over the stretch, metres.
    pub jpd_m: f64,
}

/// Foot skating (mean horizontal speed of planted sole points, m/s, from
/// [`motion::metrics`]) of each clip involved.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FootSkating {
    pub a_source_m_s: f64,
    pub a_output_m_s: f64,
    pub b_source_m_s: f64,
    /// B's scaled skeleton playing B's rotations (the starting point).
    pub b_naive_m_s: f64,
    pub b_output_m_s: f64,
    /// Output minus source, summed over both partners (negative = less skating).
    pub change_m_s: f64,
}

/// The report of one variation (what `report.json` holds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub scale: BoneScale,
    pub frames: usize,
    pub fps: f64,
    /// Largest |bone length - target length| over both bodies' bones and frames, metres.
    pub bone_error_m: f64,
    /// Mean key joint-pair distance error over pairs (null without key pairs), metres.
    pub jpd_m: Option<f64>,
    pub key_pairs: Vec<KeyPairReport>,
    pub foot_skating: FootSkating,
    /// Mean distance of A's joints from their source positions, metres.
    pub a_shift_mean_m: f64,
    /// Mean distance of B's joints from the naive retarget, metres.
    pub b_shift_mean_m: f64,
    /// Smallest distance between any joint of A and any of B: source / output, metres.
    pub closest_approach_source_m: f64,
    pub closest_approach_output_m: f64,
    pub solver: SolveStats,
    pub wall_s: f64,
}

/// The retargeted pair and its report.
#[derive(Debug, Clone)]
pub struct Retargeted {
    pub a: Motion,
    pub b: Motion,
    pub report: Report,
}

/// Check that two clips form a pair: same frame count and frame rate.
pub fn check_pair(a: &Motion, b: &Motion) -> Result<(), InteractionError> {
    if a.frames() != b.frames() {
        return Err(InteractionError::Pair(format!(
            "A has {} frames, B has {}",
            a.frames(),
            b.frames()
        )));
    }
    if (a.fps() - b.fps()).abs() > 1e-6 * a.fps() {
        return Err(InteractionError::Pair(format!(
            "A runs at {} fps, B at {}",
            a.fps(),
            b.fps()
        )));
    }
    Ok(())
}

/// Largest |distance(joint, parent) - bone length| over joints and frames.
pub fn bone_error(motion: &Motion) -> f64 {
    let s = motion.skeleton();
    let lengths = s.bone_lengths();
    let n = motion.joints();
    let pos = motion.all_world_positions();
    let mut worst = 0.0f64;
    for t in 0..motion.frames() {
        for j in 1..n {
            if let Some(p) = s.parent(j) {
                let d = (pos[t * n + j] - pos[t * n + p]).length();
                worst = worst.max((d - lengths[j]).abs());
            }
        }
    }
    worst
}

fn joint_distances(
    a: &[DVec3],
    b: &[DVec3],
    na: usize,
    nb: usize,
    ja: usize,
    jb: usize,
    t: usize,
) -> f64 {
    (a[t * na + ja] - b[t * nb + jb]).length()
}

fn closest_approach(a: &[DVec3], b: &[DVec3], na: usize, nb: usize, frames: usize) -> f64 {
    let mut best = f64::INFINITY;
    for t in 0..frames {
        for pa in &a[t * na..(t + 1) * na] {
            for pb in &b[t * nb..(t + 1) * nb] {
                best = best.min((*pa - *pb).length());
            }
        }
    }
    best
}

/// Retarget the interaction (`a`, `b`) to B's body scaled by `scale`.
///
/// Stages: B's naive retarget, the optimiser's problem over both bodies'
/// points, its solution, rotations fitted back on each skeleton, the report.
pub fn retarget(
    a: &Motion,
    b: &Motion,
    scale: &BoneScale,
    options: &RetargetOptions,
) -> Result<Retargeted, InteractionError> {
    let span = tracing::info_span!(
        "interaction_retarget",
        scale = scale.default,
        frames = a.frames()
    );
    let _guard = span.enter();
    let start = Instant::now();
    check_pair(a, b)?;
    options.solver.validate()?;
    let frames = a.frames();

    let factors = scale.factors(b.skeleton())?;
    let b_naive = naive_retarget(b, &factors)?;

    let locked_a = locked_joints(a);
    let locked_b = locked_joints(b);
    let layouts = Layouts {
        a: Layout::new(a.skeleton(), &locked_a, a.pose(0)),
        b_src: Layout::new(b.skeleton(), &locked_b, b.pose(0)),
        b: Layout::new(b_naive.skeleton(), &locked_b, b.pose(0)),
    };
    let (n_a, n_b) = (layouts.a.len(), layouts.b.len());
    let n = n_a + n_b;
    let (problem, pairs) = layouts.problem(a, b, &b_naive, options)?;
    let (solved, stats) = problem.solve(&options.solver)?;

    // Rotations back on each skeleton.
    let out_a = fit(a, a, &layouts.a, &solved, n, 0..n_a)?;
    let out_b = fit(b, &b_naive, &layouts.b, &solved, n, n_a..n)?;

    // Report.
    let (na, nb) = (a.joints(), b.joints());
    let (src_a, src_b) = (a.all_world_positions(), b.all_world_positions());
    let (o_a, o_b) = (out_a.all_world_positions(), out_b.all_world_positions());
    let naive_b = b_naive.all_world_positions();
    let key_pairs: Vec<KeyPairReport> = pairs
        .into_iter()
        .map(|k| key_pair_report(k, (&src_a, &src_b), (&o_a, &o_b), na, nb))
        .collect();
    let jpd_m = (!key_pairs.is_empty())
        .then(|| key_pairs.iter().map(|k| k.jpd_m).sum::<f64>() / key_pairs.len() as f64);
    let mean_shift = |x: &[DVec3], y: &[DVec3]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (*p - *q).length())
            .sum::<f64>()
            / x.len() as f64
    };
    let bone_target_err = {
        // B must match the scaled lengths exactly; A its own.
        bone_error(&out_a).max(bone_error(&out_b))
    };
    let report = Report {
        scale: scale.clone(),
        frames,
        fps: a.fps(),
        bone_error_m: bone_target_err,
        jpd_m,
        key_pairs,
        foot_skating: foot_skating(a, &out_a, b, &b_naive, &out_b),
        a_shift_mean_m: mean_shift(&o_a, &src_a),
        b_shift_mean_m: mean_shift(&o_b, &naive_b),
        closest_approach_source_m: closest_approach(&src_a, &src_b, na, nb, frames),
        closest_approach_output_m: closest_approach(&o_a, &o_b, na, nb, frames),
        solver: stats,
        wall_s: start.elapsed().as_secs_f64(),
    };
    tracing::info!(wall_s = report.wall_s, jpd_m = ?report.jpd_m, "retargeted");
    Ok(Retargeted {
        a: out_a,
        b: out_b,
        report,
    })
}

/// The point layouts of A, of B's source skeleton and of B's scaled one.
struct Layouts {
    a: Layout,
    b_src: Layout,
    b: Layout,
}

impl Layouts {
    /// The optimiser's problem over A's points then B's: source (B unscaled)
    /// and reference (B naively retargeted) positions, both bodies' rods, the
    /// key pairs (also returned, for the report) and the planted feet.
    fn problem(
        &self,
        a: &Motion,
        b: &Motion,
        b_naive: &Motion,
        options: &RetargetOptions,
    ) -> Result<(Problem, Vec<KeyPair>), InteractionError> {
        let frames = a.frames();
        let (n_a, n_b) = (self.a.len(), self.b.len());
        let n = n_a + n_b;
        let pts_a = self.a.all_positions(a);
        let pts_b_src = self.b_src.all_positions(b);
        let pts_b_ref = self.b.all_positions(b_naive);
        let mut source = Vec::with_capacity(frames * n);
        let mut reference = Vec::with_capacity(frames * n);
        for t in 0..frames {
            source.extend_from_slice(&pts_a[t * n_a..(t + 1) * n_a]);
            source.extend_from_slice(&pts_b_src[t * n_b..(t + 1) * n_b]);
            reference.extend_from_slice(&pts_a[t * n_a..(t + 1) * n_a]);
            reference.extend_from_slice(&pts_b_ref[t * n_b..(t + 1) * n_b]);
        }

        let mut rods: Vec<Rod> = self.a.rods.clone();
        rods.extend(self.b.rods.iter().map(|r| Rod {
            a: r.a + n_a,
            b: r.b + n_a,
            length: r.length,
        }));

        let pairs = contact::key_pairs(a, b, &self.a, &self.b_src, &options.key_pairs)?;
        let ramp = (options.key_pairs.ramp_s * a.fps()).round() as usize;
        let pair_terms = pairs
            .iter()
            .map(|k| PairTerm {
                a: self.a.joint_point[k.a],
                b: n_a + self.b.joint_point[k.b],
                weight: contact::pair_weights(k, frames, ramp),
            })
            .collect();

        let mut feet = Vec::new();
        if options.plant_feet {
            for (p, contact) in contact::foot_contacts(a, &self.a, &pts_a) {
                feet.push(FootTerm { point: p, contact });
            }
            for (p, contact) in contact::foot_contacts(b_naive, &self.b, &pts_b_ref) {
                feet.push(FootTerm {
                    point: n_a + p,
                    contact,
                });
            }
        }

        let problem = Problem {
            frames,
            n_a,
            n_b,
            source,
            reference,
            rods,
            pairs: pair_terms,
            feet,
        };
        Ok((problem, pairs))
    }
}

/// `skel_motion`'s skeleton posed on one body's solved points (`range` of
/// each frame's `n` points in `solved`), starting from the poses of `m`.
fn fit(
    m: &Motion,
    skel_motion: &Motion,
    layout: &Layout,
    solved: &[DVec3],
    n: usize,
    range: std::ops::Range<usize>,
) -> Result<Motion, motion::MotionError> {
    let frames = m.frames();
    let nj = skel_motion.joints();
    let mut root = Vec::with_capacity(frames);
    let mut rot = vec![glam::DQuat::IDENTITY; frames * nj];
    for t in 0..frames {
        let pts = &solved[t * n + range.start..t * n + range.end];
        let r = ik::pose_from_points(
            skel_motion.skeleton(),
            layout,
            m.pose(t),
            pts,
            &mut rot[t * nj..(t + 1) * nj],
        );
        root.push(r);
    }
    Motion::new(skel_motion.skeleton().clone(), m.fps(), root, rot)
}

/// A key pair's output distance and its error against the source over its
/// stretch (world positions `[frame][joint]` of A and B, `na` and `nb` joints).
fn key_pair_report(
    k: KeyPair,
    (src_a, src_b): (&[DVec3], &[DVec3]),
    (o_a, o_b): (&[DVec3], &[DVec3]),
    na: usize,
    nb: usize,
) -> KeyPairReport {
    let span = k.first_frame..=k.last_frame;
    let count = (k.last_frame + 1 - k.first_frame) as f64;
    let (mut out_sum, mut err_sum) = (0.0, 0.0);
    for t in span {
        let d_src = joint_distances(src_a, src_b, na, nb, k.a, k.b, t);
        let d_out = joint_distances(o_a, o_b, na, nb, k.a, k.b, t);
        out_sum += d_out;
        err_sum += (d_out - d_src).abs();
    }
    KeyPairReport {
        pair: k,
        output_mean_m: out_sum / count,
        jpd_m: err_sum / count,
    }
}

/// Foot skating of A's source and output, B's source, naive and output.
fn foot_skating(
    a: &Motion,
    out_a: &Motion,
    b: &Motion,
    b_naive: &Motion,
    out_b: &Motion,
) -> FootSkating {
    let skate = |m: &Motion| metrics::plausibility(m).foot_skating_m_s;
    let (a0, a1, b0, bn, b1) = (
        skate(a),
        skate(out_a),
        skate(b),
        skate(b_naive),
        skate(out_b),
    );
    FootSkating {
        a_source_m_s: a0,
        a_output_m_s: a1,
        b_source_m_s: b0,
        b_naive_m_s: bn,
        b_output_m_s: b1,
        change_m_s: (a1 - a0) + (b1 - b0),
    }
}
