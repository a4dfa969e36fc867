//! From network predictions to clips: the learned counterpart of
//! [`interaction::retarget`].
//!
//! Both clips are resampled to the model's rate, the networks predict both
//! bodies' points for B's bone scale ([`InteractionModel::predict_clip`]), and
//! the points are turned into rotations on A's skeleton and on B's scaled one
//! by the optimiser's own inverse kinematics ([`interaction::ik`]), so the
//! written clips have exact bone lengths. The report holds the same figures as
//! the optimiser's (`bone_error_m`, `jpd_m`, `key_pairs`, foot skating,
//! `wall_s`) plus the bone-length error of the raw network points (E_b,
//! before IK repairs it) and the network's share of the wall time.

use std::sync::Arc;
use std::time::Instant;

use glam::{DQuat, DVec3};
use interaction::contact::KeyPairOptions;
use interaction::scale::scale_skeleton;
use interaction::{BoneScale, ik};
use motion::{Motion, Skeleton, metrics};
use serde::{Deserialize, Serialize};

use crate::dataset::{Body, layout_of};
use crate::error::{ModelError, Result};
use crate::model::InteractionModel;

/// A key pair's distance error in the output (joints, over its contact stretch).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeyPairReport {
    pub a_joint: String,
    pub b_joint: String,
    pub first_frame: usize,
    pub last_frame: usize,
    pub source_mean_m: f64,
    pub output_mean_m: f64,
    pub jpd_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FootSkating {
    pub a_source_m_s: f64,
    pub a_output_m_s: f64,
    pub b_source_m_s: f64,
    pub b_output_m_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GenerateReport {
    pub method: String,
    /// `retarget` (scale given) or `generation` (scale drawn from the prior).
    pub task: String,
    pub scale: BoneScale,
    pub frames: usize,
    pub fps: f64,
    /// Largest |bone length - target| in the written clips, metres (after IK).
    pub bone_error_m: f64,
    /// Mean |bone length - target| of the network's points (E_b), metres.
    pub network_bone_error_m: f64,
    pub jpd_m: Option<f64>,
    pub key_pairs: Vec<KeyPairReport>,
    pub foot_skating: FootSkating,
    pub network_s: f64,
    pub wall_s: f64,
}

pub struct Generated {
    pub a: Motion,
    pub b: Motion,
    pub report: GenerateReport,
    /// The network's points, world frame, `[T, P, 3]`.
    pub points_a: Vec<f32>,
    pub points_b: Vec<f32>,
}

/// Mean |edge length - target| over frames and edges of points `[T, P, 3]`.
pub fn mean_bone_error(points: &[f32], parents: &[i32], target: &[f64], frames: usize) -> f64 {
    let v = parents.len();
    let (mut sum, mut count) = (0.0, 0usize);
    for t in 0..frames {
        for (i, &p) in parents.iter().enumerate() {
            if p < 0 {
                continue;
            }
            let (a, b) = (t * v + i, t * v + p as usize);
            let d: f64 = (0..3)
                .map(|c| (points[a * 3 + c] - points[b * 3 + c]) as f64)
                .map(|x| x * x)
                .sum::<f64>()
                .sqrt();
            sum += (d - target[i]).abs();
            count += 1;
        }
    }
    sum / count.max(1) as f64
}

/// Edge lengths at frame 0 of points `[T, P, 3]` (0 at the root).
pub fn edge_lengths(points: &[f32], parents: &[i32]) -> Vec<f64> {
    parents
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            if p < 0 {
                return 0.0;
            }
            (0..3)
                .map(|c| (points[i * 3 + c] - points[p as usize * 3 + c]) as f64)
                .map(|x| x * x)
                .sum::<f64>()
                .sqrt()
        })
        .collect()
}

/// Rotations on `skeleton` placing its points at `points` `[T, P, 3]`.
fn fit(skeleton: &Arc<Skeleton>, source: &Motion, points: &[f32], fps: f64) -> Result<Motion> {
    let layout = layout_of(skeleton, source);
    let (frames, p, nj) = (source.frames(), layout.len(), skeleton.len());
    let mut root = Vec::with_capacity(frames);
    let mut rot = vec![DQuat::IDENTITY; frames * nj];
    let mut pts = Vec::with_capacity(p);
    for t in 0..frames {
        pts.clear();
        pts.extend(
            points[t * p * 3..(t + 1) * p * 3]
                .chunks(3)
                .map(|c| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64)),
        );
        root.push(ik::pose_from_points(
            skeleton,
            &layout,
            source.pose(t),
            &pts,
            &mut rot[t * nj..(t + 1) * nj],
        ));
    }
    Ok(Motion::new(skeleton.clone(), fps, root, rot)?)
}

fn check_body(expected: &Body, skeleton: &Skeleton, source: &Motion, who: &str) -> Result<()> {
    let got = Body::of(skeleton, &layout_of(skeleton, source));
    if got.parents != expected.parents || got.names != expected.names {
        return Err(ModelError::Data(format!(
            "partner {who}'s skeleton ({} points) is not the one the model was trained on ({} points)",
            got.len(),
            expected.len()
        )));
    }
    Ok(())
}

/// Key pair distance errors of `(out_a, out_b)` against the sources.
pub fn key_pair_errors(
    a: &Motion,
    b: &Motion,
    out_a: &Motion,
    out_b: &Motion,
    options: &KeyPairOptions,
) -> Result<Vec<KeyPairReport>> {
    let (la, lb) = (layout_of(a.skeleton(), a), layout_of(b.skeleton(), b));
    let pairs = interaction::contact::key_pairs(a, b, &la, &lb, options)?;
    let (sa, sb) = (a.all_world_positions(), b.all_world_positions());
    let (oa, ob) = (out_a.all_world_positions(), out_b.all_world_positions());
    let (na, nb) = (a.joints(), b.joints());
    Ok(pairs
        .into_iter()
        .map(|k| {
            let count = (k.last_frame + 1 - k.first_frame) as f64;
            let (mut out_sum, mut err) = (0.0, 0.0);
            for t in k.first_frame..=k.last_frame {
                let d0 = (sa[t * na + k.a] - sb[t * nb + k.b]).length();
                let d1 = (oa[t * na + k.a] - ob[t * nb + k.b]).length();
                out_sum += d1;
                err += (d1 - d0).abs();
            }
            KeyPairReport {
                a_joint: k.a_joint,
                b_joint: k.b_joint,
                first_frame: k.first_frame,
                last_frame: k.last_frame,
                source_mean_m: k.source_mean_m,
                output_mean_m: out_sum / count,
                jpd_m: err / count,
            }
        })
        .collect())
}

/// One variation of the pair (`a`, `b`) with B's body scaled by `scale`;
/// `task` names how the scale was chosen (`retarget` or `generation`).
pub fn generate(
    model: &InteractionModel,
    a: &Motion,
    b: &Motion,
    scale: &BoneScale,
    task: &str,
    key_pairs: &KeyPairOptions,
) -> Result<Generated> {
    let span = tracing::info_span!("interaction_generate", scale = scale.default, task);
    let _guard = span.enter();
    let start = Instant::now();
    interaction::retarget::check_pair(a, b)?;
    let fps = model.meta.config.fps;
    let resampled = |m: &Motion| -> Result<Motion> {
        if (m.fps() - fps).abs() < 1e-9 {
            Ok(m.clone())
        } else {
            Ok(motion::resample::resample(m, fps)?)
        }
    };
    let (a, b) = (resampled(a)?, resampled(b)?);
    let (body_a, body_b) = (&model.meta.body_a, &model.meta.body_b);
    check_body(body_a, a.skeleton(), &a, "A")?;
    check_body(body_b, b.skeleton(), &b, "B")?;
    let to_flat = |p: Vec<DVec3>| -> Vec<f32> {
        p.iter()
            .flat_map(|v| [v.x as f32, v.y as f32, v.z as f32])
            .collect()
    };
    let ta = to_flat(layout_of(a.skeleton(), &a).all_positions(&a));
    let tb = to_flat(layout_of(b.skeleton(), &b).all_positions(&b));
    let factors = body_b.factors(b.skeleton(), scale)?;
    let frames = a.frames();
    let net_start = Instant::now();
    let pred = model.predict_clip(&ta, &tb, frames, &factors)?;
    let network_s = net_start.elapsed().as_secs_f64();

    let target_a = edge_lengths(&ta, &body_a.parents);
    let target_b: Vec<f64> = edge_lengths(&tb, &body_b.parents)
        .iter()
        .zip(&factors)
        .map(|(l, f)| l * *f as f64)
        .collect();
    let network_bone_error_m = 0.5
        * (mean_bone_error(&pred.a, &body_a.parents, &target_a, frames)
            + mean_bone_error(&pred.b, &body_b.parents, &target_b, frames));

    let scaled = Arc::new(scale_skeleton(b.skeleton(), &scale.factors(b.skeleton())?)?);
    let out_a = fit(a.skeleton(), &a, &pred.a, fps)?;
    let out_b = fit(&scaled, &b, &pred.b, fps)?;

    let key_pairs = key_pair_errors(&a, &b, &out_a, &out_b, key_pairs)?;
    let jpd_m = (!key_pairs.is_empty())
        .then(|| key_pairs.iter().map(|k| k.jpd_m).sum::<f64>() / key_pairs.len() as f64);
    let skate = |m: &Motion| metrics::plausibility(m).foot_skating_m_s;
    let report = GenerateReport {
        method: "learned".into(),
        task: task.into(),
        scale: scale.clone(),
        frames,
        fps,
        bone_error_m: interaction::retarget::bone_error(&out_a)
            .max(interaction::retarget::bone_error(&out_b)),
        network_bone_error_m,
        jpd_m,
        key_pairs,
        foot_skating: FootSkating {
            a_source_m_s: skate(&a),
            a_output_m_s: skate(&out_a),
            b_source_m_s: skate(&b),
            b_output_m_s: skate(&out_b),
        },
        network_s,
        wall_s: start.elapsed().as_secs_f64(),
    };
    Ok(Generated {
        a: out_a,
        b: out_b,
        report,
        points_a: pred.a,
        points_b: pred.b,
    })
}

/// A bone scale for B drawn from the model's skeleton prior.
pub fn sample_scale(model: &InteractionModel, seed: u64) -> Result<BoneScale> {
    let f = model
        .sample_scales(1, seed)?
        .pop()
        .ok_or_else(|| ModelError::Data("the prior gave no sample".into()))?;
    model.meta.body_b.scale_of(&f)
}
