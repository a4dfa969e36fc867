//! The full recipe: the kinematic `[[ops]]` of [`synth::Recipe`] plus the
//! tables that make new clips from the whole dataset (`[vae]`, `[interaction]`)
//! and the tables that post-process every new clip (`[correct]`, `[debias]`).
//!
//! ```toml
//! seed = 7
//!
//! [[ops]]                   # per clip, see synth::Recipe
//! op = "ik"
//! copies = 4
//! preset = "kick"
//!
//! [vae]                     # one VAE per class of the dataset, sampled `copies` times
//! copies = 10
//! iterations = 1500
//! prior = "near"            # near | normal
//! near_members = 2          # near codes between this many clips of a cluster
//! mixed_motion_weight = 0.0 # > 0: codes between clips decode to motion as fast as theirs
//! mixed_contact_weight = 0.0 # > 0: ... with as many frames on the ground as theirs
//! mixed_sole_weight = 0.0   # > 0: ... their planted feet on their soles
//! mixed_travel_weight = 0.0 # > 0: ... travelling, quarter by quarter, like theirs
//! mixed_balance_weight = 0.0 # > 0: ... their zero moment point no further outside the feet
//! smooth_s = 0.05           # low-pass each sample (seconds; 0 = as decoded): decoded clips jitter
//! plant_root = true         # re-integrate each sample's root from its planted feet
//! level_floor = true        # train on every clip moved onto one floor (actors stand 0-3 cm apart)
//!
//! [interaction]             # every pair <stem>_A / <stem>_B: `copies` body-size variations of B
//! copies = 4
//! scale_min = 0.75
//! scale_max = 1.25
//!
//! [correct]                 # every new clip through physical correction
//! time_budget_s = 300
//! max_iterations = 15       # PPO iterations per clip at most (optional)
//! original_max_iterations = 200  # the source clips' own corrections at most
//!                           #   (optional; default: max_iterations)
//! residual = "pd"           # pd | none | learned
//! plant_reference = false   # imitate the root re-integrated from the planted feet
//! fall_penalty = 0.0        # training reward of a step that ends in a fall, negated
//!                           #   (acceptance reads the paper's reward, 0 on a fall)
//! keep_rejected = false     # keep clips that fail acceptance (marked in the manifest)
//! accept_threshold = 0.7    # acceptance (correct::acceptance): mean reward at least,
//! max_residual_force_ratio = 0.1  # root force / body weight at most,
//! max_foot_skating_m_s = 0.1      # skating at most,
//! skating_at_most_input = true    # and at most the input's,
//! min_sole_flat_fraction = 0.9    # planted frames on the sole at least
//! policy = "clip"           # clip (one policy per clip) | class (one tracker per class first)
//! tracker_budget_s = 1800   # with policy = "class": each class tracker's budget
//! tracker_iterations = 150  #   and its PPO iterations at most (optional)
//! variant_tracker_iterations = 300  # new clips the class tracker fails start from a
//!                           #   second tracker trained on them (0 = off)
//! skate_scale_when_skating_m_s = 0.1  # a clip failing on skating alone trains
//!                           #   with a sliding term from then on (0 = off)
//! tracker_final_residual_scale = 0.15  # with policy = "class": lower the root force's
//!                           #   gains from the tracker's scale to this while fine-tuning
//!                           #   each clip (optional; default: hold the tracker's)
//!
//! [debias]                  # learn (corrected original -> original), apply to corrected clips
//! iterations = 2000
//! [debias.contacts]         # keep the corrected clip's planted feet (debias::ContactConfig)
//! restore = true
//! ```
//!
//! The same structure is accepted as JSON by the HTTP service. Unknown keys are
//! errors naming the table and the field; every table is optional but a recipe
//! must make something (`[[ops]]`, `[vae]` or `[interaction]`), and `[debias]`
//! needs `[correct]`.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::PipelineError;

/// `[vae]`: train the motion VAE on the dataset's clips of each class, then sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VaeStep {
    /// Samples per class.
    pub copies: u32,
    /// `class`: one model per HDM05 class (the class part of `HDM_<actor>_<class>_<n>`,
    /// else the whole name without trailing digits); `all`: one model for the dataset.
    pub group_by: GroupBy,
    pub iterations: u64,
    pub prior: vae::Prior,
    pub adversarial: bool,
    /// Classes with fewer clips than this are skipped (a VAE of one clip only copies it).
    pub min_clips: usize,
    /// Near codes are drawn between this many training clips of a cluster
    /// (`vae::NearConfig::members`; the paper's 2).
    pub near_members: usize,
    /// Weight of the training term that asks codes between two clips to decode
    /// to motion as fast as theirs (`vae::LossWeights::mixed_motion`; 0: off).
    /// Samples then move like the class instead of standing nearly still, but
    /// on jog fewer pass physical correction (crates/vae/README.md, session 18).
    pub mixed_motion_weight: f64,
    /// `vae::LossWeights::mixed_contact` (0: off; written only when set).
    #[serde(skip_serializing_if = "is_zero")]
    pub mixed_contact_weight: f64,
    /// `vae::LossWeights::mixed_sole` (0: off; written only when set).
    #[serde(skip_serializing_if = "is_zero")]
    pub mixed_sole_weight: f64,
    /// `vae::LossWeights::mixed_travel` (0: off; written only when set).
    #[serde(skip_serializing_if = "is_zero")]
    pub mixed_travel_weight: f64,
    /// `vae::LossWeights::mixed_balance` with the correction's default
    /// character (`vae_balance_model`): samples whose zero moment point
    /// leaves the feet fall in the simulator (crates/vae/README.md, session
    /// 36). 0: off; written only when set.
    #[serde(skip_serializing_if = "is_zero")]
    pub mixed_balance_weight: f64,
    /// Low-pass each sample with a Gaussian of this many seconds (0: as
    /// decoded; `vae::Finish`): decoded clips jitter, and smoothed jog samples
    /// pass physical correction 15/30 where the same samples raw pass 2/30
    /// (crates/vae/README.md, session 19).
    pub smooth_s: f64,
    /// Re-integrate each sample's root path from its planted feet.
    pub plant_root: bool,
    /// Move each training clip vertically onto one floor before training
    /// (`vae::FloorLevel`); off, clips stand as captured. HDM05's actors
    /// stand 0-3 cm apart, and a VAE trained on them as captured decodes
    /// feet that hover (crates/vae/README.md, session 33).
    pub level_floor: bool,
}

impl VaeStep {
    /// The vae crate's training configuration this step asks for.
    pub fn train_config(&self, seed: u64) -> vae::TrainConfig {
        let mut config = vae::TrainConfig {
            iterations: self.iterations,
            adversarial: self.adversarial,
            seed,
            ..vae::TrainConfig::default()
        };
        config.near.members = self.near_members;
        config.weights.mixed_motion = self.mixed_motion_weight;
        config.weights.mixed_contact = self.mixed_contact_weight;
        config.weights.mixed_sole = self.mixed_sole_weight;
        config.weights.mixed_travel = self.mixed_travel_weight;
        config.weights.mixed_balance = self.mixed_balance_weight;
        config.features.floor = self.level_floor.then(vae::FloorLevel::default);
        config
    }

    /// What is done to each decoded sample.
    pub fn finish(&self) -> vae::Finish {
        vae::Finish::new(self.smooth_s, self.plant_root)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GroupBy {
    Class,
    All,
}

impl Default for VaeStep {
    fn default() -> Self {
        VaeStep {
            copies: 10,
            group_by: GroupBy::Class,
            iterations: 1500,
            prior: vae::Prior::Near,
            adversarial: true,
            min_clips: 2,
            near_members: vae::NearConfig::default().members,
            mixed_motion_weight: 0.0,
            mixed_contact_weight: 0.0,
            mixed_sole_weight: 0.0,
            mixed_travel_weight: 0.0,
            mixed_balance_weight: 0.0,
            smooth_s: vae::trained::DEFAULT_SMOOTH_S,
            plant_root: true,
            level_floor: true,
        }
    }
}

/// `[interaction]`: body-size variations of every two-person pair.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InteractionStep {
    /// Variations per pair.
    pub copies: u32,
    pub scale_min: f64,
    pub scale_max: f64,
    /// Relative per-bone jitter on top of the global factor.
    pub bone_jitter: f64,
    /// Evenly spaced factors instead of random ones.
    pub grid: bool,
}

impl Default for InteractionStep {
    fn default() -> Self {
        InteractionStep {
            copies: 4,
            scale_min: 0.75,
            scale_max: 1.25,
            bone_jitter: 0.0,
            grid: false,
        }
    }
}

impl InteractionStep {
    /// The variations of one pair, drawn with `seed`.
    pub fn spec(&self, seed: u64) -> interaction::VariationSpec {
        interaction::VariationSpec {
            count: self.copies as usize,
            scale_min: self.scale_min,
            scale_max: self.scale_max,
            bone_jitter: self.bone_jitter,
            grid: self.grid,
            seed,
        }
    }
}

/// `[correct]`: physical correction of every new clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CorrectStep {
    /// Training budget per clip, seconds.
    pub time_budget_s: f64,
    /// PPO iterations per clip at most (a budget that does not depend on the
    /// machine; the time budget still applies). With `policy = "class"`, 0
    /// judges the tracker as is.
    pub max_iterations: Option<u64>,
    /// PPO iterations at most of a source clip's own correction
    /// (`correct_original`), when it should differ from `max_iterations`
    /// (`None`: the same). The originals are few (one in 21 corrections with
    /// 10 IK edits and 10 VAE samples each) and the debiaser learns from
    /// them, so they can afford the time budget the variants cannot: kick,
    /// class tracker of 150 iterations, 24/29 originals accepted within 15
    /// iterations, 29/29 within 300 s (the five needed 17-79 iterations).
    pub original_max_iterations: Option<u64>,
    pub residual: ResidualKind,
    /// Imitate each clip with its root re-integrated from its planted feet
    /// (`physics::Config::plant_reference`); acceptance still compares the
    /// output with the clip as given.
    pub plant_reference: bool,
    /// The training reward of a step that ends in a fall, negated, in every
    /// correction and tracker (`physics::Config::fall_penalty`; 0, the
    /// paper's, by default). Written only when set, so recipes saved before
    /// it existed serialise as they did.
    #[serde(skip_serializing_if = "is_zero_f32")]
    pub fall_penalty: f32,
    /// Stop a clip's training once its rollout reaches this R_norm (and is accepted).
    pub target_r_norm: f64,
    /// Mean per-step reward a corrected clip needs to be kept (paper: 0.7).
    pub accept_threshold: f64,
    /// Largest mean root residual force accepted, as a fraction of body weight.
    pub max_residual_force_ratio: f64,
    /// Largest foot skating of a corrected clip, m/s.
    pub max_foot_skating_m_s: f64,
    /// A corrected clip must also skate no more than its input.
    pub skating_at_most_input: bool,
    /// Smallest fraction of planted foot frames standing on the sole.
    pub min_sole_flat_fraction: f64,
    /// Keep clips whose correction was not accepted (marked in the manifest).
    pub keep_rejected: bool,
    /// Correct each original first and start its variants from its policy
    /// (with `policy = "clip"`).
    pub warm_start: bool,
    /// Parallel simulated environments per clip.
    pub envs: usize,
    /// Which policy corrects a clip: `clip`, one trained for that clip (from
    /// scratch, or from its source's with `warm_start`); `class`, one tracker
    /// per class trained on the class's originals first, every correction of
    /// the class starting from it (`correct::class`: judged as is, fine-tuned
    /// only when it does not pass).
    pub policy: PolicyKind,
    /// Training budget of each class tracker, seconds (`policy = "class"`).
    pub tracker_budget_s: f64,
    /// PPO iterations of each class tracker at most (`policy = "class"`).
    pub tracker_iterations: Option<u64>,
    /// Upcoming reference frames a class tracker sees.
    pub tracker_frames: usize,
    /// With `policy = "class"`, the new clips of a class (IK edits, VAE
    /// samples) that its tracker does not pass as is start from a second
    /// tracker: the class tracker trained further on those clips only, for at
    /// most this many PPO iterations (within `tracker_budget_s`). 0 = every
    /// new clip starts from the class tracker. Measured with 300 iterations:
    /// jog VAE samples accepted 2/34 -> 8/34 (bench correction); kick (eval
    /// table, fold bd) IK edits 33/46 -> 43/46, VAE samples 11/46 -> 25/46.
    pub variant_tracker_iterations: u64,
    /// Train a clip with the sole reward's sliding term at this speed scale,
    /// m/s, from the first judgement at which skating is all it fails (its
    /// starting policy as is, or a rollout at the R_norm target) on (0 = never;
    /// `correct::CorrectConfig::skate_scale_when_skating_m_s`).
    pub skate_scale_when_skating_m_s: f32,
    /// With `policy = "class"`: lower the PD-residual gains from the
    /// tracker's scale to this while fine-tuning each clip, linearly over its
    /// `max_iterations` (when set)
    /// (`correct::CorrectConfig::tracker_final_residual_scale`; `None`: hold
    /// the tracker's). The second tracker still trains at the class
    /// tracker's scale. Written only when set, so recipes saved before it
    /// existed serialise as they did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tracker_final_residual_scale: Option<f32>,
}

fn is_zero_f32(x: &f32) -> bool {
    *x == 0.0
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// See [`CorrectStep::policy`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PolicyKind {
    #[default]
    Clip,
    Class,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualKind {
    Pd,
    None,
    Learned,
}

impl ResidualKind {
    pub fn physics(self) -> physics::Residual {
        match self {
            ResidualKind::Pd => physics::Residual::Pd,
            ResidualKind::None => physics::Residual::None,
            ResidualKind::Learned => physics::Residual::Learned,
        }
    }
}

impl Default for CorrectStep {
    fn default() -> Self {
        let c = correct::CorrectConfig::default();
        CorrectStep {
            time_budget_s: c.time_budget_s,
            max_iterations: None,
            original_max_iterations: None,
            residual: ResidualKind::Pd,
            plant_reference: c.physics.plant_reference,
            fall_penalty: c.physics.fall_penalty,
            target_r_norm: c.target_r_norm.unwrap_or(0.8),
            accept_threshold: c.acceptance.min_mean_reward,
            max_residual_force_ratio: c.acceptance.max_residual_force_ratio,
            max_foot_skating_m_s: c.acceptance.max_foot_skating_m_s,
            skating_at_most_input: c.acceptance.skating_at_most_input,
            min_sole_flat_fraction: c.acceptance.min_flat_fraction,
            keep_rejected: false,
            warm_start: true,
            envs: c.envs,
            policy: PolicyKind::Clip,
            tracker_budget_s: 1800.0,
            tracker_iterations: None,
            tracker_frames: correct::ClassConfig::default()
                .correct
                .physics
                .tracker_frames,
            variant_tracker_iterations: 0,
            skate_scale_when_skating_m_s: c.skate_scale_when_skating_m_s,
            tracker_final_residual_scale: c.tracker_final_residual_scale,
        }
    }
}

impl CorrectStep {
    /// The correction job's settings for one clip.
    pub fn config(&self, seed: u64) -> correct::CorrectConfig {
        let mut c = correct::CorrectConfig {
            time_budget_s: self.time_budget_s,
            max_iterations: self.max_iterations,
            target_r_norm: Some(self.target_r_norm),
            acceptance: correct::AcceptanceConfig {
                min_mean_reward: self.accept_threshold,
                max_residual_force_ratio: self.max_residual_force_ratio,
                max_foot_skating_m_s: self.max_foot_skating_m_s,
                skating_at_most_input: self.skating_at_most_input,
                min_flat_fraction: self.min_sole_flat_fraction,
                ..correct::AcceptanceConfig::default()
            },
            envs: self.envs,
            seed,
            skate_scale_when_skating_m_s: self.skate_scale_when_skating_m_s,
            tracker_final_residual_scale: self.tracker_final_residual_scale,
            ..correct::CorrectConfig::default()
        };
        c.physics.residual = self.residual.physics();
        c.physics.plant_reference = self.plant_reference;
        c.physics.fall_penalty = self.fall_penalty;
        // Lowered over the clip's whole fine-tuning, when it is bounded: the
        // gains reach the final scale at the last iteration allowed.
        if let (Some(_), Some(n)) = (self.tracker_final_residual_scale, self.max_iterations)
            && n > 0
        {
            c.residual_schedule.over_iterations = n;
        }
        c
    }

    /// The settings of a source clip's own correction: [`Self::config`] with
    /// `original_max_iterations` (when unset, `max_iterations`).
    pub fn original_config(&self, seed: u64) -> correct::CorrectConfig {
        correct::CorrectConfig {
            max_iterations: self.original_max_iterations.or(self.max_iterations),
            ..self.config(seed)
        }
    }

    /// The class tracker's settings (`policy = "class"`): the clips' settings
    /// with the tracker's budget and observation.
    pub fn tracker_config(&self, seed: u64) -> correct::ClassConfig {
        let mut c = correct::ClassConfig {
            correct: self.config(seed),
            ..correct::ClassConfig::default()
        };
        c.correct.time_budget_s = self.tracker_budget_s;
        c.correct.max_iterations = self.tracker_iterations;
        c.correct.physics.tracker_frames = self.tracker_frames;
        c
    }
}

/// A validated recipe.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Recipe {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The `[[ops]]` (kinematic synthesis per clip), when there are any.
    #[serde(skip)]
    pub synth: Option<synth::Recipe>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vae: Option<VaeStep>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interaction: Option<InteractionStep>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correct: Option<CorrectStep>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub debias: Option<debias::TrainConfig>,
}

impl<'de> Deserialize<'de> for Recipe {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Value::deserialize(d)?;
        Recipe::from_value(v).map_err(serde::de::Error::custom)
    }
}

/// The upper bound of one numeric recipe field.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bound {
    /// The table, e.g. `correct`.
    pub table: &'static str,
    pub field: &'static str,
    /// The largest value accepted.
    pub max: f64,
    /// What the value counts, for messages.
    pub unit: &'static str,
}

impl Bound {
    /// `value` if it is finite and at most the bound; else an error naming the
    /// table, the field and the bound.
    fn check(&self, value: f64) -> Result<(), PipelineError> {
        if value.is_finite() && value <= self.max {
            return Ok(());
        }
        Err(err(
            format!("[{}]", self.table),
            format!(
                "`{}` = {value} is above its bound of {} {}",
                self.field, self.max, self.unit
            ),
        ))
    }
}

/// Upper bounds of the numeric fields that the tables' own crates leave
/// open (the ops' parameters are bounded by the synth crate, the acceptance
/// criteria by the correct crate, the interaction ranges by the interaction
/// crate, copies by [`synth::recipe::MAX_COPIES`]). Each bounds a cost: a
/// typo such as `time_budget_s = 1e308`, `envs = 1000000` or
/// `iterations = 1e12` is refused, naming the field and its bound, instead of
/// running for ever or exhausting a worker's memory. Generous on purpose: ten
/// to a hundred times the defaults.
pub mod bounds {
    use super::Bound;

    /// Largest number of `[[ops]]` tables (the synth crate's bound).
    pub const MAX_OPS: usize = synth::recipe::MAX_OPS;
    /// Largest `copies` of an op, of `[vae]` and of `[interaction]`.
    pub const MAX_COPIES: u32 = synth::recipe::MAX_COPIES;

    const fn bound(
        table: &'static str,
        field: &'static str,
        max: f64,
        unit: &'static str,
    ) -> Bound {
        Bound {
            table,
            field,
            max,
            unit,
        }
    }

    pub const VAE_ITERATIONS: Bound = bound("vae", "iterations", 100_000.0, "training steps");
    pub const VAE_MIN_CLIPS: Bound = bound("vae", "min_clips", 10_000.0, "clips");
    pub const VAE_NEAR_MEMBERS: Bound = bound("vae", "near_members", 10_000.0, "clips");
    pub const VAE_SMOOTH_S: Bound = bound("vae", "smooth_s", 1.0, "seconds");
    pub const CORRECT_TIME_BUDGET_S: Bound = bound(
        "correct",
        "time_budget_s",
        86_400.0,
        "seconds per clip (24 h)",
    );
    pub const CORRECT_ENVS: Bound = bound("correct", "envs", 64.0, "simulated environments");
    pub const CORRECT_TRACKER_BUDGET_S: Bound = bound(
        "correct",
        "tracker_budget_s",
        7.0 * 86_400.0,
        "seconds per class tracker (a week)",
    );
    pub const CORRECT_MAX_ITERATIONS: Bound = bound(
        "correct",
        "max_iterations",
        1_000_000.0,
        "PPO iterations per clip",
    );
    pub const CORRECT_ORIGINAL_MAX_ITERATIONS: Bound = bound(
        "correct",
        "original_max_iterations",
        1_000_000.0,
        "PPO iterations per source clip",
    );
    pub const CORRECT_TRACKER_ITERATIONS: Bound = bound(
        "correct",
        "tracker_iterations",
        1_000_000.0,
        "PPO iterations per class tracker",
    );
    pub const CORRECT_VARIANT_TRACKER_ITERATIONS: Bound = bound(
        "correct",
        "variant_tracker_iterations",
        1_000_000.0,
        "PPO iterations per second tracker",
    );
    pub const DEBIAS_ITERATIONS: Bound =
        bound("debias", "iterations", 200_000.0, "optimiser steps");
    pub const DEBIAS_BATCH_SIZE: Bound = bound("debias", "batch_size", 65_536.0, "frames");
    pub const DEBIAS_LAYERS: Bound = bound("debias", "hidden", 8.0, "hidden layers");
    pub const DEBIAS_WIDTH: Bound = bound("debias", "hidden[]", 4096.0, "units per layer");
    pub const DEBIAS_LEARNING_RATE: Bound = bound("debias", "learning_rate", 1.0, "");
    pub const DEBIAS_WEIGHT_DECAY: Bound = bound("debias", "weight_decay", 1.0, "");
    pub const DEBIAS_HEIGHT_BAND_M: Bound =
        bound("debias", "contacts.height_band_m", 1.0, "metres");
    pub const DEBIAS_MAX_SPEED: Bound = bound(
        "debias",
        "contacts.max_speed_m_s",
        10.0,
        "metres per second",
    );
    pub const DEBIAS_BLEND_S: Bound = bound("debias", "contacts.blend_s", 10.0, "seconds");
    pub const DEBIAS_SMOOTHING_S: Bound = bound("debias", "smoothing_s", 10.0, "seconds");
    pub const DEBIAS_CLEARANCE_M: Bound = bound("debias", "contacts.clearance_m", 1.0, "metres");
    pub const DEBIAS_STILL_SPEED: Bound = bound(
        "debias",
        "contacts.still_speed_m_s",
        10.0,
        "metres per second",
    );

    /// Every bound above (for documentation and the service's limits endpoint).
    pub const ALL: &[Bound] = &[
        VAE_ITERATIONS,
        VAE_MIN_CLIPS,
        VAE_NEAR_MEMBERS,
        VAE_SMOOTH_S,
        CORRECT_TIME_BUDGET_S,
        CORRECT_ENVS,
        CORRECT_TRACKER_BUDGET_S,
        CORRECT_MAX_ITERATIONS,
        CORRECT_ORIGINAL_MAX_ITERATIONS,
        CORRECT_TRACKER_ITERATIONS,
        CORRECT_VARIANT_TRACKER_ITERATIONS,
        DEBIAS_ITERATIONS,
        DEBIAS_BATCH_SIZE,
        DEBIAS_LAYERS,
        DEBIAS_WIDTH,
        DEBIAS_LEARNING_RATE,
        DEBIAS_WEIGHT_DECAY,
        DEBIAS_HEIGHT_BAND_M,
        DEBIAS_MAX_SPEED,
        DEBIAS_BLEND_S,
        DEBIAS_SMOOTHING_S,
        DEBIAS_CLEARANCE_M,
        DEBIAS_STILL_SPEED,
    ];
}

fn err(location: impl Into<String>, message: impl Into<String>) -> PipelineError {
    PipelineError::Recipe {
        location: location.into(),
        message: message.into(),
    }
}

/// Deserialise one table, naming it in the error.
fn table<T: serde::de::DeserializeOwned>(name: &str, v: Value) -> Result<T, PipelineError> {
    if !v.is_object() {
        return Err(err(format!("[{name}]"), "must be a table/object"));
    }
    serde_json::from_value(v).map_err(|e| err(format!("[{name}]"), e.to_string()))
}

impl Recipe {
    pub const TABLES: &[&str] = &["seed", "ops", "vae", "interaction", "correct", "debias"];

    pub fn from_toml_str(text: &str) -> Result<Recipe, PipelineError> {
        let v: Value = toml::from_str(text).map_err(|e| err("TOML", e.to_string()))?;
        Recipe::from_value(v)
    }

    pub fn from_json_str(text: &str) -> Result<Recipe, PipelineError> {
        let v: Value = serde_json::from_str(text).map_err(|e| err("JSON", e.to_string()))?;
        Recipe::from_value(v)
    }

    /// Read a recipe file: JSON when it ends in `.json`, TOML otherwise.
    pub fn from_file(path: &std::path::Path) -> Result<Recipe, PipelineError> {
        let text = std::fs::read_to_string(path).map_err(|source| PipelineError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let parsed = if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        {
            Recipe::from_json_str(&text)
        } else {
            Recipe::from_toml_str(&text)
        };
        parsed.map_err(|e| PipelineError::InFile {
            path: path.to_path_buf(),
            source: Box::new(e),
        })
    }

    /// Parse the generic structure shared by TOML and JSON.
    pub fn from_value(v: Value) -> Result<Recipe, PipelineError> {
        let Value::Object(mut top) = v else {
            return Err(err("recipe", "must be a table/object"));
        };
        if let Some(unknown) = top.keys().find(|k| !Self::TABLES.contains(&k.as_str())) {
            return Err(err(
                "recipe",
                format!(
                    "unknown key `{unknown}` (known: {})",
                    Self::TABLES.join(", ")
                ),
            ));
        }
        let vae = top.remove("vae").map(|v| table("vae", v)).transpose()?;
        let interaction = top
            .remove("interaction")
            .map(|v| table("interaction", v))
            .transpose()?;
        let correct = top
            .remove("correct")
            .map(|v| table("correct", v))
            .transpose()?;
        let debias = top
            .remove("debias")
            .map(|v| table("debias", v))
            .transpose()?;
        let seed = match top.get("seed") {
            None => None,
            Some(s) => Some(
                s.as_u64()
                    .ok_or_else(|| err("seed", "must be a non-negative integer below 2^64"))?,
            ),
        };
        let synth = if top.contains_key("ops") {
            Some(
                synth::Recipe::from_value(Value::Object(top)).map_err(|e| match e {
                    synth::SynthError::Recipe { location, message } => err(location, message),
                    other => err("ops", other.to_string()),
                })?,
            )
        } else {
            None
        };
        Recipe {
            seed,
            synth,
            vae,
            interaction,
            correct,
            debias,
        }
        .validated()
    }

    fn validated(self) -> Result<Recipe, PipelineError> {
        if self.synth.is_none() && self.vae.is_none() && self.interaction.is_none() {
            return Err(err(
                "recipe",
                "makes nothing: add [[ops]] tables, a [vae] table or an [interaction] table",
            ));
        }
        if self.debias.is_some() && self.correct.is_none() {
            return Err(err(
                "[debias]",
                "needs a [correct] table (it learns from corrected originals)",
            ));
        }
        if let Some(v) = &self.vae {
            if !(1..=synth::recipe::MAX_COPIES).contains(&v.copies) {
                return Err(err(
                    "[vae]",
                    format!("`copies` must be in 1..={}", synth::recipe::MAX_COPIES),
                ));
            }
            if v.iterations == 0 {
                return Err(err("[vae]", "`iterations` must be at least 1"));
            }
            bounds::VAE_ITERATIONS.check(v.iterations as f64)?;
            if v.near_members == 0 {
                return Err(err("[vae]", "`near_members` must be at least 1"));
            }
            bounds::VAE_NEAR_MEMBERS.check(v.near_members as f64)?;
            for (name, w) in [
                ("mixed_motion_weight", v.mixed_motion_weight),
                ("mixed_contact_weight", v.mixed_contact_weight),
                ("mixed_sole_weight", v.mixed_sole_weight),
                ("mixed_travel_weight", v.mixed_travel_weight),
                ("mixed_balance_weight", v.mixed_balance_weight),
            ] {
                if !(w.is_finite() && w >= 0.0) {
                    return Err(err(
                        "[vae]",
                        format!("`{name}` must be a finite number >= 0"),
                    ));
                }
            }
            if !(v.smooth_s.is_finite() && v.smooth_s >= 0.0) {
                return Err(err("[vae]", "`smooth_s` must be a finite number >= 0"));
            }
            bounds::VAE_SMOOTH_S.check(v.smooth_s)?;
            if v.min_clips == 0 {
                return Err(err("[vae]", "`min_clips` must be at least 1"));
            }
            bounds::VAE_MIN_CLIPS.check(v.min_clips as f64)?;
        }
        if let Some(i) = &self.interaction {
            if !(1..=synth::recipe::MAX_COPIES).contains(&i.copies) {
                return Err(err(
                    "[interaction]",
                    format!("`copies` must be in 1..={}", synth::recipe::MAX_COPIES),
                ));
            }
            self.interaction_spec(0)
                .map(|s| s.validate())
                .transpose()
                .map_err(|e| err("[interaction]", e.to_string()))?;
        }
        if let Some(c) = &self.correct {
            if !(c.time_budget_s.is_finite() && c.time_budget_s >= 0.0) {
                return Err(err(
                    "[correct]",
                    "`time_budget_s` must be a duration in seconds",
                ));
            }
            bounds::CORRECT_TIME_BUDGET_S.check(c.time_budget_s)?;
            bounds::CORRECT_ENVS.check(c.envs as f64)?;
            if let Some(n) = c.max_iterations {
                bounds::CORRECT_MAX_ITERATIONS.check(n as f64)?;
            }
            if let Some(n) = c.original_max_iterations {
                bounds::CORRECT_ORIGINAL_MAX_ITERATIONS.check(n as f64)?;
            }
            for (name, v) in [
                ("target_r_norm", c.target_r_norm),
                ("accept_threshold", c.accept_threshold),
                ("min_sole_flat_fraction", c.min_sole_flat_fraction),
            ] {
                if !(0.0..=1.0).contains(&v) {
                    return Err(err("[correct]", format!("`{name}` must be in [0, 1]")));
                }
            }
            c.config(0)
                .validate()
                .map_err(|e| err("[correct]", e.to_string()))?;
            if c.policy == PolicyKind::Class {
                if !(c.tracker_budget_s.is_finite() && c.tracker_budget_s >= 0.0) {
                    return Err(err(
                        "[correct]",
                        "`tracker_budget_s` must be a duration in seconds",
                    ));
                }
                bounds::CORRECT_TRACKER_BUDGET_S.check(c.tracker_budget_s)?;
                if let Some(n) = c.tracker_iterations {
                    bounds::CORRECT_TRACKER_ITERATIONS.check(n as f64)?;
                }
                if !(1..=8).contains(&c.tracker_frames) {
                    return Err(err("[correct]", "`tracker_frames` must be in 1..=8"));
                }
                bounds::CORRECT_VARIANT_TRACKER_ITERATIONS
                    .check(c.variant_tracker_iterations as f64)?;
            } else if c.variant_tracker_iterations > 0 {
                return Err(err(
                    "[correct]",
                    "`variant_tracker_iterations` trains a second class tracker: it needs \
                     `policy = \"class\"`",
                ));
            } else if c.tracker_final_residual_scale.is_some() {
                return Err(err(
                    "[correct]",
                    "`tracker_final_residual_scale` lowers a class tracker's root force: it \
                     needs `policy = \"class\"`",
                ));
            }
        }
        if let Some(d) = &self.debias {
            d.validate().map_err(|e| err("[debias]", e.to_string()))?;
            bounds::DEBIAS_ITERATIONS.check(d.iterations as f64)?;
            bounds::DEBIAS_BATCH_SIZE.check(d.batch_size as f64)?;
            bounds::DEBIAS_LAYERS.check(d.hidden.len() as f64)?;
            for width in &d.hidden {
                bounds::DEBIAS_WIDTH.check(*width as f64)?;
            }
            bounds::DEBIAS_LEARNING_RATE.check(d.learning_rate)?;
            bounds::DEBIAS_WEIGHT_DECAY.check(d.weight_decay)?;
            bounds::DEBIAS_HEIGHT_BAND_M.check(d.contacts.height_band_m)?;
            bounds::DEBIAS_MAX_SPEED.check(d.contacts.max_speed_m_s)?;
            bounds::DEBIAS_BLEND_S.check(d.contacts.blend_s)?;
            bounds::DEBIAS_SMOOTHING_S.check(d.smoothing_s)?;
            bounds::DEBIAS_CLEARANCE_M.check(d.contacts.clearance_m)?;
            bounds::DEBIAS_STILL_SPEED.check(d.contacts.still_speed_m_s)?;
        }
        Ok(self)
    }

    /// The seed to use: the caller's, else the recipe's, else 0.
    pub fn effective_seed(&self, override_seed: Option<u64>) -> u64 {
        override_seed.or(self.seed).unwrap_or(0)
    }

    /// The interaction variations of one pair, drawn with `seed`.
    pub fn interaction_spec(&self, seed: u64) -> Option<interaction::VariationSpec> {
        self.interaction.as_ref().map(|i| i.spec(seed))
    }

    /// The recipe as the JSON object it was read from (with defaults filled in).
    pub fn to_value(&self) -> Value {
        let mut m = match serde_json::to_value(self) {
            Ok(Value::Object(m)) => m,
            _ => Map::new(),
        };
        if let Some(s) = &self.synth
            && let Ok(Value::Object(ops)) = serde_json::to_value(s)
        {
            for (k, v) in ops {
                m.insert(k, v);
            }
        }
        Value::Object(m)
    }
}
