//! Kinematic motion synthesis: turn one clip into many.
//!
//! Every op has the shape `fn(&Motion, &Params, &mut SynthRng) -> Result<Augmented, SynthError>`
//! and is reproducible: the same motion, parameters and seed give bit-identical
//! output (ChaCha8 from a `u64`, no global state, no float reductions that
//! depend on thread count).
//!
//! * [`noise`]: i.i.d. Gaussian noise on joint rotations (MotionAug's baseline).
//! * [`time_warp`]: uniform speed change, factor drawn from a range (+-10%).
//! * [`mirror`]: left/right mirror with joint pairs from names or given.
//! * [`mask`]: V-DMGNN-GAN occlusion masks (lower body or random joints).
//! * [`ik`]: MotionAug IK synthesis: a fan-shaped target for the end effector
//!   at the keyframe, propagated over the clip, solved with FABRIK per frame.
//!
//! A [`Recipe`] (TOML for the CLI, the same structure as JSON for the service)
//! lists ops with their parameters and copy counts; [`expand_clip`] runs a
//! recipe over one clip with a per-output seed derived from (recipe seed, clip
//! name, op index, copy index), so results do not depend on the order in which
//! clips or jobs run. [`ManifestEntry`] describes one output for `manifest.json`.
//!
//! How a CLI or a worker drives it:
//!
//! ```
//! use synth::{Recipe, expand_clip, run_job};
//!
//! let recipe = Recipe::from_toml_str(r#"
//!     seed = 7
//!     [[ops]]
//!     op = "ik"
//!     preset = "kick"
//!     copies = 2
//!     [[ops]]
//!     op = "mask"
//!     mode = "lower_body"
//! "#)?;
//! let clip = synth::fixtures::kick(60, 30.0, 30); // a Motion, e.g. from motion::io::load
//! let seed = recipe.effective_seed(None); // the CLI's --seed wins over the recipe's
//!
//! // CLI: all outputs of one clip (run clips in parallel with rayon; each clip's
//! // outputs do not depend on the others).
//! let outputs = expand_clip(&recipe, "kick_001", &clip, seed)?;
//! assert_eq!(outputs.len(), 3);
//! for g in &outputs {
//!     // write g.output.motion as `{g.name}.bvh` / `.npz`, g.output.mask beside it
//!     let entry = g.manifest_entry(format!("{}.bvh", g.name), "kick_001.amc");
//!     if g.op == "ik" {
//!         assert!(entry.keyframe.is_some() && entry.target.is_some());
//!     }
//! }
//!
//! // Worker: one job at a time, same result as in the batch.
//! let jobs = recipe.jobs("kick_001", seed);
//! let one = run_job(&recipe, "kick_001", &clip, jobs[1])?;
//! assert_eq!(one.output.motion, outputs[1].output.motion);
//! # Ok::<(), synth::SynthError>(())
//! ```

pub mod error;
pub mod fixtures;
pub mod ik;
pub mod mask;
pub mod mirror;
pub mod names;
pub mod noise;
pub mod recipe;
pub mod seed;
pub mod time_warp;

use serde::{Deserialize, Serialize};

pub use error::SynthError;
pub use ik::{IkParams, IkReport, Preset, ik};
pub use mask::{Mask, MaskFill, MaskMode, MaskParams, mask};
pub use mirror::{MirrorAxis, MirrorParams, mirror};
pub use noise::{NoiseParams, noise};
pub use recipe::{Generated, Job, ManifestEntry, Op, OpEntry, Recipe, expand_clip, run_job};
pub use seed::{output_seed, rng_from_seed};
pub use time_warp::{TimeWarpParams, time_warp};

/// The random number generator every op draws from.
pub type SynthRng = rand_chacha::ChaCha8Rng;

/// The result of one op on one clip.
#[derive(Debug, Clone)]
pub struct Augmented {
    pub motion: motion::Motion,
    /// Occlusion mask (the `mask` op only).
    pub mask: Option<Mask>,
    /// Values the op drew or measured (e.g. the time-warp factor), for the manifest.
    pub sampled: serde_json::Map<String, serde_json::Value>,
}

impl Augmented {
    pub fn new(motion: motion::Motion) -> Self {
        Augmented {
            motion,
            mask: None,
            sampled: serde_json::Map::new(),
        }
    }
}

/// A closed interval `[lo, hi]`, written as a two-element array in recipes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Range(pub f64, pub f64);

impl Range {
    /// Finite and ordered (`lo <= hi`); `field` names the parameter in errors.
    pub fn validate(&self, field: &str) -> Result<(), SynthError> {
        if !(self.0.is_finite() && self.1.is_finite()) {
            return Err(SynthError::param(field, "bounds must be finite numbers"));
        }
        if self.0 > self.1 {
            return Err(SynthError::param(
                field,
                format!("range [{}, {}] is not ordered (low > high)", self.0, self.1),
            ));
        }
        Ok(())
    }

    /// A uniform draw (one draw even when `lo == hi`, so the stream stays aligned).
    pub fn sample(&self, rng: &mut SynthRng) -> f64 {
        use rand::Rng;
        self.0 + (self.1 - self.0) * rng.random::<f64>()
    }
}
