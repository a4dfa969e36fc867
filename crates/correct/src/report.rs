//! `report.json` and the learning-curve plot written next to a corrected clip.

use std::path::Path;

use motion::metrics::Plausibility;
use serde::{Deserialize, Serialize};

use crate::CorrectError;
use crate::acceptance::Criterion;

/// Everything a user needs to judge one correction.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    /// The clip that was corrected.
    pub source: String,
    /// Paper's normalised reward of the final deterministic rollout over the whole clip.
    pub r_norm: f64,
    /// Mean per-step reward of that rollout (0 for steps after a fall).
    pub mean_reward: f64,
    /// Mean |F_res| / (body mass * g) over that rollout.
    pub residual_force_ratio: f64,
    /// Environment steps used for training, over all resumes.
    pub samples: u64,
    /// Training wall time, seconds, over all resumes.
    pub wall_s: f64,
    pub iterations: u64,
    /// Learning curve: [wall_s, samples, r_norm] of deterministic rollouts; the
    /// first point is the untrained tracker (action 0) at [0, 0, r_norm_action0].
    pub curve: Vec<[f64; 3]>,
    /// Every acceptance criterion passed ([`crate::acceptance`]).
    pub accepted: bool,
    /// Each criterion with its value, limit and verdict.
    #[serde(default)]
    pub criteria: Vec<Criterion>,
    /// The failed criteria, one line each (empty when accepted).
    #[serde(default)]
    pub rejected_because: Vec<String>,
    /// The mean-reward limit (paper: 0.7); the others are in `criteria`.
    pub accept_threshold: f64,
    /// Control step at which the character fell in the final rollout, if it
    /// did (of `clip_steps`; `frames` counts the frames simulated, so a clip
    /// that fell is shorter than its input).
    pub fell_at: Option<usize>,
    /// The body that touched the ground when it fell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fell_body: Option<String>,
    /// Control steps of the whole clip (reports written before it read 0).
    #[serde(default)]
    pub clip_steps: usize,
    /// R_norm of the untrained tracker (action 0) for comparison.
    pub r_norm_action0: f64,
    /// Why training stopped: target, time_budget, max_iterations, max_samples.
    pub stop_reason: String,
    /// Root force used: pd, none or learned.
    pub residual: String,
    /// Factor on the PD-residual gains in the rollout that produced the clip
    /// (1 = MotionAug's; lower after a schedule handed balance to the policy).
    #[serde(default = "one")]
    pub residual_scale: f64,
    /// Frame rate of the corrected clip (the control rate).
    pub fps: f64,
    /// Frames of the corrected clip: the frames simulated, up to the fall.
    pub frames: usize,
    /// Checkpoint the policy was warm-started from, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm_start: Option<String>,
    pub plausibility_before: Plausibility,
    pub plausibility_after: Plausibility,
    /// The soles criterion measured on the input (the reference's own feet,
    /// with the character's soles): how often the captured feet themselves
    /// stand flat where they are planted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub soles_flat_before: Option<f64>,
    /// Speed scale of the sole reward's sliding term the policy was trained
    /// with, m/s (0: off): set for every clip, or switched on for a clip once
    /// skating was all it failed (`CorrectConfig::skate_scale_when_skating_m_s`).
    #[serde(default)]
    pub skate_scale_m_s: f64,
}

/// A JSON file a correction wrote (`report.json`, a tracker's `class.json`).
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, CorrectError> {
    let bytes = std::fs::read(path).map_err(|source| CorrectError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&bytes).map_err(|e| CorrectError::BadReport {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn one() -> f64 {
    1.0
}

impl Report {
    /// A `report.json` as a finished correction wrote it.
    pub fn read(path: &Path) -> Result<Report, CorrectError> {
        read_json(path)
    }
}

/// The learning curve (R_norm against wall time) as a small standalone SVG.
pub fn curve_svg(curve: &[[f64; 3]], title: &str) -> String {
    let (w, h, m) = (640.0, 360.0, 50.0);
    let t_max = curve.iter().map(|p| p[0]).fold(0.0f64, f64::max).max(1e-9);
    let x = |t: f64| m + (w - 2.0 * m) * t / t_max;
    let y = |r: f64| h - m - (h - 2.0 * m) * r.clamp(0.0, 1.0);
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
         font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{m}\" y=\"20\">{}</text>\n",
        escape(title)
    );
    for i in 0..=5 {
        let r = i as f64 / 5.0;
        svg += &format!(
            "<line x1=\"{m}\" x2=\"{}\" y1=\"{y0:.1}\" y2=\"{y0:.1}\" stroke=\"#ddd\"/>\
             <text x=\"{}\" y=\"{:.1}\" text-anchor=\"end\">{r:.1}</text>\n",
            w - m,
            m - 6.0,
            y(r) + 4.0,
            y0 = y(r)
        );
        let t = t_max * i as f64 / 5.0;
        svg += &format!(
            "<text x=\"{:.1}\" y=\"{}\" text-anchor=\"middle\">{t:.0}</text>\n",
            x(t),
            h - m + 18.0
        );
    }
    svg += &format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">wall time (s)</text>\n\
         <text x=\"14\" y=\"{}\" transform=\"rotate(-90 14 {})\" text-anchor=\"middle\">R_norm</text>\n",
        w / 2.0,
        h - 8.0,
        h / 2.0,
        h / 2.0
    );
    let points: Vec<String> = curve
        .iter()
        .map(|p| format!("{:.1},{:.1}", x(p[0]), y(p[2])))
        .collect();
    svg += &format!(
        "<polyline fill=\"none\" stroke=\"#1f77b4\" stroke-width=\"2\" points=\"{}\"/>\n</svg>\n",
        points.join(" ")
    );
    svg
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_one_vertex_per_curve_point() {
        let svg = curve_svg(
            &[[0.0, 0.0, 0.5], [10.0, 100.0, 0.7], [20.0, 200.0, 0.9]],
            "a<b",
        );
        let points = svg
            .split("points=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap();
        assert_eq!(points.split(' ').count(), 3);
        assert!(svg.contains("a&lt;b"));
        assert!(svg.starts_with("<svg"));
    }
}
