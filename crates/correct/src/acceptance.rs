//! When a corrected clip counts as physically honest: the simulated character
//! did the motion on its own. Mean reward alone (the paper's rule) accepts
//! clips held up by the root force or standing on their heels, so a clip is
//! accepted only when every criterion below holds, and the report lists each
//! one with its value, its limit and whether it passed:
//!
//! * `no_fall`: the deterministic rollout reached the end of the clip.
//! * `mean_reward`: mean per-step reward >= `min_mean_reward` (paper: 0.7).
//! * `residual_force`: mean |F_res| / (m g) <= `max_residual_force_ratio`,
//!   the share of body weight carried by the invisible hand.
//! * `foot_skating`: the output's foot skating (`motion::metrics`) <=
//!   `max_foot_skating_m_s` and (`skating_at_most_input`) <= the input's.
//! * `soles_flat`: in the frames where a simulated foot is planted (touching
//!   the ground with its heel and its toe both slower than
//!   `planted_speed_m_s`: standing, not rolling onto or off its toes), its
//!   heel and toe are both within `sole_tolerance_m` of the floor in at
//!   least `min_flat_fraction` of them (feet on their soles, not on the heel
//!   edge with the toes up).
//!
//! The limits are settings so that a study can ask for more; the defaults are
//! the product's meaning of "accepted" and tests of the pipeline's plumbing
//! are the only place that relaxes them.

use motion::metrics::Plausibility;
use physics::FootContact;
use serde::{Deserialize, Serialize};

use crate::CorrectError;
use crate::rollout::Rollout;

/// The limits of every criterion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AcceptanceConfig {
    /// Mean per-step reward of the whole-clip rollout (paper: 0.7).
    pub min_mean_reward: f64,
    /// Mean |F_res| / (m g).
    pub max_residual_force_ratio: f64,
    /// Foot skating of the output, m/s.
    pub max_foot_skating_m_s: f64,
    /// The output's foot skating must also be at most the input's.
    pub skating_at_most_input: bool,
    /// Heel and toe of a planted foot within this height of the floor, m.
    pub sole_tolerance_m: f64,
    /// Fraction of planted foot frames that must stand on the sole.
    pub min_flat_fraction: f64,
    /// A foot touching the ground with its heel and its toe both slower than
    /// this (3D) is planted, m/s. A foot rolling over its heel or onto its
    /// toes moves one end faster and is not standing on anything yet.
    pub planted_speed_m_s: f64,
}

impl Default for AcceptanceConfig {
    fn default() -> Self {
        AcceptanceConfig {
            min_mean_reward: 0.7,
            max_residual_force_ratio: 0.1,
            max_foot_skating_m_s: 0.1,
            skating_at_most_input: true,
            sole_tolerance_m: 0.02,
            min_flat_fraction: 0.9,
            planted_speed_m_s: 0.2,
        }
    }
}

impl AcceptanceConfig {
    pub fn validate(&self) -> Result<(), CorrectError> {
        let checks = [
            ("min_mean_reward", self.min_mean_reward, 0.0, 1.0),
            (
                "max_residual_force_ratio",
                self.max_residual_force_ratio,
                0.0,
                100.0,
            ),
            (
                "max_foot_skating_m_s",
                self.max_foot_skating_m_s,
                0.0,
                100.0,
            ),
            ("sole_tolerance_m", self.sole_tolerance_m, 0.0, 1.0),
            ("min_flat_fraction", self.min_flat_fraction, 0.0, 1.0),
            ("planted_speed_m_s", self.planted_speed_m_s, 0.0, 100.0),
        ];
        for (name, value, lo, hi) in checks {
            if !(value.is_finite() && (lo..=hi).contains(&value)) {
                return Err(CorrectError::Config(format!(
                    "acceptance {name} = {value} is not in [{lo}, {hi}]"
                )));
            }
        }
        Ok(())
    }
}

/// One criterion as judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Criterion {
    /// `no_fall`, `mean_reward`, `residual_force`, `foot_skating`, `soles_flat`.
    pub name: String,
    pub value: f64,
    /// The bound `value` must meet (a minimum or a maximum, see `at_most`).
    pub limit: f64,
    /// Whether `value` must be at most `limit` (else at least).
    pub at_most: bool,
    pub passed: bool,
    /// What the value is, in words and units.
    pub meaning: String,
}

impl Criterion {
    fn new(name: &str, value: f64, limit: f64, at_most: bool, meaning: String) -> Criterion {
        let passed = value.is_finite()
            && if at_most {
                value <= limit
            } else {
                value >= limit
            };
        Criterion {
            name: name.to_string(),
            value,
            limit,
            at_most,
            passed,
            meaning,
        }
    }

    /// `<=` or `>=`: how `value` must compare with `limit`.
    pub fn op(&self) -> &'static str {
        if self.at_most { "<=" } else { ">=" }
    }

    /// Why it failed, in one line.
    pub fn failure(&self) -> String {
        format!(
            "{} {:.3} (needs {} {:.3}): {}",
            self.name,
            self.value,
            self.op(),
            self.limit,
            self.meaning
        )
    }
}

/// Planted foot frames and how many stood on their soles; of the others,
/// which end was up (to tell a foot on its toes from one on its heel).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SoleStats {
    pub planted_frames: usize,
    pub flat_frames: usize,
    /// Planted, not flat, the heel the higher end: standing on the toes.
    #[serde(default)]
    pub on_toes_frames: usize,
    /// Planted, not flat, the toe the higher end: standing on the heel.
    #[serde(default)]
    pub on_heel_frames: usize,
    /// Sum over the planted frames that are not flat of the height of the
    /// higher end, m (see [`SoleStats::mean_lift_m`]).
    #[serde(default)]
    pub lift_sum_m: f64,
}

impl SoleStats {
    /// Count over every foot of every recorded step.
    pub fn of(feet: &[Vec<FootContact>], config: &AcceptanceConfig) -> SoleStats {
        let mut s = SoleStats::default();
        for f in feet.iter().flatten() {
            if f.touching && (f.speed_m_s as f64) < config.planted_speed_m_s {
                s.planted_frames += 1;
                let high = f.heel_m.max(f.toe_m) as f64;
                if high <= config.sole_tolerance_m {
                    s.flat_frames += 1;
                } else {
                    s.lift_sum_m += high;
                    if f.heel_m > f.toe_m {
                        s.on_toes_frames += 1;
                    } else {
                        s.on_heel_frames += 1;
                    }
                }
            }
        }
        s
    }

    /// Mean height of the higher end of a planted foot that is not flat, m
    /// (0 when every planted frame is flat).
    pub fn mean_lift_m(&self) -> f64 {
        let tilted = self.planted_frames - self.flat_frames;
        if tilted == 0 {
            0.0
        } else {
            self.lift_sum_m / tilted as f64
        }
    }

    /// Flat fraction of the planted frames (1 without planted frames: nothing
    /// stood on the ground to judge; the other criteria catch a character
    /// held in the air).
    pub fn flat_fraction(&self) -> f64 {
        if self.planted_frames == 0 {
            1.0
        } else {
            self.flat_frames as f64 / self.planted_frames as f64
        }
    }
}

/// The soles criterion applied to the *input*: the reference's heel and toe
/// (with the character's own sole points, built from `physics`) in every
/// frame after the first, a reference foot touching when the lower of its
/// heel and toe is within `sole_tolerance_m` of the floor. What the captured
/// motion itself would score, so that a limit the capture cannot meet shows.
pub fn input_soles(
    motion: &motion::Motion,
    physics: &physics::Config,
    config: &AcceptanceConfig,
) -> Result<SoleStats, CorrectError> {
    let env = input_env(motion, physics)?;
    Ok(SoleStats::of(
        &env.reference_foot_contacts(config.sole_tolerance_m as f32),
        config,
    ))
}

/// How far a clip's zero moment point leaves its support polygon
/// ([`physics::balance`]), over the frames a foot supports: what the clip
/// would need from something other than its feet. Not a criterion: it judges
/// the input before a correction (`motionaug metrics --balance`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct BalanceStats {
    /// Interior frames with a foot on the floor (and not in free fall).
    pub supported_frames: usize,
    /// Supported frames whose ZMP lies more than `margin_m` outside.
    pub unbalanced_frames: usize,
    pub margin_m: f64,
    /// Sum and largest distance outside over the supported frames, m.
    pub outside_sum_m: f64,
    pub outside_max_m: f64,
}

/// The margin [`input_balance`] allows the ZMP outside the support polygon:
/// the cart-table model leaves out the angular momentum of swinging arms and
/// legs, and a 30 Hz second difference of captured positions is noisy.
pub const BALANCE_MARGIN_M: f64 = 0.05;

impl BalanceStats {
    pub fn of(stances: &[physics::balance::Stance], margin_m: f64) -> BalanceStats {
        let mut s = BalanceStats {
            margin_m,
            ..BalanceStats::default()
        };
        for st in stances {
            if let physics::balance::Stance::Supported { outside_m } = *st {
                let d = outside_m as f64;
                s.supported_frames += 1;
                s.outside_sum_m += d;
                s.outside_max_m = s.outside_max_m.max(d);
                s.unbalanced_frames += usize::from(d > margin_m);
            }
        }
        s
    }

    /// Unbalanced frames / supported frames (0 with none supported).
    pub fn unbalanced_fraction(&self) -> f64 {
        self.unbalanced_frames as f64 / self.supported_frames.max(1) as f64
    }

    /// Mean distance of the ZMP outside the support polygon, m.
    pub fn mean_outside_m(&self) -> f64 {
        self.outside_sum_m / self.supported_frames.max(1) as f64
    }
}

/// The balance of the *input* at the control rate, with the simulated
/// character's masses and (calibrated) foot boxes, a foot supporting when
/// its sole is within the soles criterion's tolerance of the floor.
pub fn input_balance(
    motion: &motion::Motion,
    physics: &physics::Config,
    config: &AcceptanceConfig,
) -> Result<BalanceStats, CorrectError> {
    let env = input_env(motion, physics)?;
    Ok(BalanceStats::of(
        &env.reference_balance(config.sole_tolerance_m as f32),
        BALANCE_MARGIN_M,
    ))
}

/// The environment of the clip as given, not the planted reference the
/// character imitates: what the input measures read.
fn input_env(
    motion: &motion::Motion,
    physics: &physics::Config,
) -> Result<physics::ImitationEnv, CorrectError> {
    let physics = physics::Config {
        plant_reference: false,
        ..physics.clone()
    };
    Ok(physics::ImitationEnv::new(motion, &physics)?)
}

/// Every criterion, judged on a rollout and the plausibility of the input and
/// the output.
pub fn judge(
    rollout: &Rollout,
    before: &Plausibility,
    after: &Plausibility,
    config: &AcceptanceConfig,
) -> Vec<Criterion> {
    let soles = SoleStats::of(&rollout.feet, config);
    let skating_limit = if config.skating_at_most_input {
        config
            .max_foot_skating_m_s
            .min(before.foot_skating_m_s.max(0.0))
    } else {
        config.max_foot_skating_m_s
    };
    vec![
        Criterion::new(
            "no_fall",
            match rollout.fell_at {
                None => 1.0,
                Some(_) => 0.0,
            },
            1.0,
            false,
            match rollout.fell_at {
                None => "the character reached the end of the clip".into(),
                Some(t) => format!(
                    "the character fell at control step {t} of {}{}",
                    rollout.clip_steps,
                    match &rollout.fell_body {
                        Some(b) => format!(" ({b} touched the ground)"),
                        None => String::new(),
                    }
                ),
            },
        ),
        Criterion::new(
            "mean_reward",
            rollout.mean_reward(),
            config.min_mean_reward,
            false,
            "mean per-step imitation reward of the whole-clip rollout".into(),
        ),
        Criterion::new(
            "residual_force",
            rollout.residual_force_ratio(),
            config.max_residual_force_ratio,
            true,
            "mean root residual force as a fraction of body weight".into(),
        ),
        Criterion::new(
            FOOT_SKATING,
            after.foot_skating_m_s,
            skating_limit,
            true,
            format!(
                "foot skating of the output, m/s (input {:.3}, cap {:.3})",
                before.foot_skating_m_s, config.max_foot_skating_m_s
            ),
        ),
        Criterion::new(
            "soles_flat",
            soles.flat_fraction(),
            config.min_flat_fraction,
            false,
            format!(
                "planted foot frames with heel and toe within {:.0} mm of the floor \
                 ({} of {})",
                config.sole_tolerance_m * 1000.0,
                soles.flat_frames,
                soles.planted_frames
            ),
        ),
    ]
}

/// The name of the foot skating criterion.
pub const FOOT_SKATING: &str = "foot_skating";

/// Every criterion's name, in the order [`judge`] lists them (tables show
/// rejections in this order).
pub const CRITERIA: [&str; 5] = [
    "no_fall",
    "mean_reward",
    "residual_force",
    FOOT_SKATING,
    "soles_flat",
];

/// Whether every criterion passed.
pub fn all_passed(criteria: &[Criterion]) -> bool {
    criteria.iter().all(|c| c.passed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn foot(heel: f32, toe: f32, speed: f32, touching: bool) -> FootContact {
        FootContact {
            heel_m: heel,
            toe_m: toe,
            speed_m_s: speed,
            touching,
        }
    }

    #[test]
    fn heel_standing_is_not_flat_and_swing_is_not_planted() {
        let c = AcceptanceConfig::default();
        let feet = vec![
            // On the sole.
            vec![foot(0.005, 0.01, 0.0, true), foot(0.3, 0.3, 2.0, false)],
            // On the heel edge with the toes 6 cm up.
            vec![foot(0.0, 0.06, 0.05, true), foot(0.25, 0.2, 1.5, false)],
            // Touching but sliding fast: not planted.
            vec![foot(0.0, 0.0, 0.5, true), foot(0.0, 0.07, 0.0, true)],
            // On the toes, heel 4 cm up.
            vec![foot(0.04, 0.01, 0.1, true), foot(0.3, 0.3, 2.0, false)],
        ];
        let s = SoleStats::of(&feet, &c);
        assert_eq!(s.planted_frames, 4);
        assert_eq!(s.flat_frames, 1);
        assert_eq!((s.on_heel_frames, s.on_toes_frames), (2, 1));
        assert!((s.mean_lift_m() - (0.06 + 0.07 + 0.04) / 3.0).abs() < 1e-6);
        assert!((s.flat_fraction() - 1.0 / 4.0).abs() < 1e-12);
        assert_eq!(SoleStats::default().flat_fraction(), 1.0);
        assert_eq!(SoleStats::default().mean_lift_m(), 0.0);
    }

    #[test]
    fn a_criterion_passes_only_within_its_limit() {
        let at_most = Criterion::new("residual_force", 0.18, 0.1, true, String::new());
        assert!(!at_most.passed);
        assert!(at_most.failure().contains("0.180 (needs <= 0.100)"));
        assert!(Criterion::new("x", 0.1, 0.1, true, String::new()).passed);
        assert!(Criterion::new("x", 0.7, 0.7, false, String::new()).passed);
        assert!(!Criterion::new("x", f64::NAN, 0.7, false, String::new()).passed);
    }

    #[test]
    fn bad_limits_are_refused() {
        let c = AcceptanceConfig {
            min_flat_fraction: 1.5,
            ..AcceptanceConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("min_flat_fraction"), "{e}");
        assert!(AcceptanceConfig::default().validate().is_ok());
    }
}
