//! How close a synthesised set is to the held-out actor's clips (min DTW,
//! MMD) and how physically plausible it is: the synthesis rows of `eval synth`
//! and of the table.

use motion::Motion;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dataset;
use crate::dtw::{self, MinDtw};
use crate::error::{EvalError, Result};
use crate::euler::{self, EulerClip};
use crate::mmd::{self, Mmd};

/// Closeness of a synthesised set to the test clips.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SynthScores {
    pub min_dtw: MinDtw,
    pub mmd: Mmd,
    pub plausibility: SetPlausibility,
}

/// Physical plausibility of a set: means over its clips of
/// `motion::metrics::plausibility` (default thresholds, clips at 30 fps).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SetPlausibility {
    pub foot_skating_m_s: f64,
    pub penetration_mean_m: f64,
    pub floating_fraction: f64,
    /// Joint speed relative to the root, m/s (`Plausibility::pose_speed_m_s`):
    /// low for sets of near-frozen clips.
    #[serde(default)]
    pub pose_speed_m_s: f64,
}

impl SetPlausibility {
    pub fn of(clips: &[Motion]) -> SetPlausibility {
        let all: Vec<_> = clips.iter().map(motion::metrics::plausibility).collect();
        let mean = |f: fn(&motion::metrics::Plausibility) -> f64| {
            all.iter().map(f).sum::<f64>() / all.len().max(1) as f64
        };
        SetPlausibility {
            foot_skating_m_s: mean(|p| p.foot_skating_m_s),
            penetration_mean_m: mean(|p| p.penetration_mean_m),
            floating_fraction: mean(|p| p.floating_fraction),
            pose_speed_m_s: mean(|p| p.pose_speed_m_s),
        }
    }
}

/// Scores `synth` against `test` (both non-empty, one skeleton layout), at
/// the protocol's frame rate.
pub fn synth_scores(synth: &[(String, Motion)], test: &[(String, Motion)]) -> Result<SynthScores> {
    let reference = test
        .first()
        .ok_or_else(|| EvalError::Data("no test clips to score against".into()))?;
    if synth.is_empty() {
        return Err(EvalError::Data("no synthesised clips to score".into()));
    }
    for (name, m) in synth {
        euler::check_same_layout(reference.1.skeleton(), m.skeleton(), name)?;
    }
    let at_fps = |clips: &[(String, Motion)]| -> Result<Vec<Motion>> {
        clips
            .iter()
            .map(|(_, m)| Ok(motion::resample::resample(m, dataset::FPS)?))
            .collect()
    };
    let (s, t) = (at_fps(synth)?, at_fps(test)?);
    let euler = |ms: &[Motion]| ms.par_iter().map(EulerClip::of).collect::<Vec<_>>();
    let min_dtw = dtw::min_dtw(&euler(&s), &euler(&t));
    let feats =
        |ms: &[Motion]| -> Result<Vec<Vec<f64>>> { ms.iter().map(mmd::clip_feature).collect() };
    let mmd = mmd::mmd(&feats(&s)?, &feats(&t)?);
    Ok(SynthScores {
        min_dtw,
        mmd,
        plausibility: SetPlausibility::of(&s),
    })
}
