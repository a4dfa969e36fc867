//! One entry point for "make variations of this pair at these scales", by the
//! optimiser or by the learned model, with the same summary for both (what a
//! recipe or a service job calls).

use interaction::{BoneScale, RetargetOptions};
use motion::Motion;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::generate::generate;
use crate::model::InteractionModel;

/// How to make the variations.
pub enum Method<'a> {
    /// The interaction-mesh optimiser ([`interaction::retarget`]), at the clips' own rate.
    Optimiser(&'a RetargetOptions),
    /// A trained model (outputs at the model's rate, 30 fps by default).
    Learned(&'a InteractionModel),
}

/// The figures both methods report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub method: String,
    pub scale: BoneScale,
    pub fps: f64,
    /// Largest |bone length - target| in the clips, metres.
    pub bone_error_m: f64,
    /// Mean key joint-pair distance error against the source, metres.
    pub jpd_m: Option<f64>,
    pub foot_skating_a_m_s: f64,
    pub foot_skating_b_m_s: f64,
    pub wall_s: f64,
}

pub struct Made {
    pub a: Motion,
    pub b: Motion,
    pub summary: Summary,
}

/// Variations of (`a`, `b`), one per scale, in the order given.
pub fn make_variations(
    a: &Motion,
    b: &Motion,
    scales: &[BoneScale],
    method: &Method,
) -> Result<Vec<Made>> {
    match method {
        Method::Optimiser(options) => scales
            .par_iter()
            .map(|s| {
                let r = interaction::retarget(a, b, s, options)?;
                let p = &r.report;
                Ok(Made {
                    summary: Summary {
                        method: "optimiser".into(),
                        scale: s.clone(),
                        fps: a.fps(),
                        bone_error_m: p.bone_error_m,
                        jpd_m: p.jpd_m,
                        foot_skating_a_m_s: p.foot_skating.a_output_m_s,
                        foot_skating_b_m_s: p.foot_skating.b_output_m_s,
                        wall_s: p.wall_s,
                    },
                    a: r.a,
                    b: r.b,
                })
            })
            .collect(),
        Method::Learned(model) => scales
            .iter()
            .map(|s| {
                let g = generate(model, a, b, s, "retarget", &Default::default())?;
                let p = &g.report;
                Ok(Made {
                    summary: Summary {
                        method: "learned".into(),
                        scale: s.clone(),
                        fps: p.fps,
                        bone_error_m: p.bone_error_m,
                        jpd_m: p.jpd_m,
                        foot_skating_a_m_s: p.foot_skating.a_output_m_s,
                        foot_skating_b_m_s: p.foot_skating.b_output_m_s,
                        wall_s: p.wall_s,
                    },
                    a: g.a,
                    b: g.b,
                })
            })
            .collect(),
    }
}
