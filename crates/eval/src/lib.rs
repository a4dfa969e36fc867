//! Evaluation of motion data augmentation (MotionAug Sec. 4.1 and 4.3).
//!
//! * [`euler`]: the one angle representation every metric here uses (Euler
//!   angles of every non-root joint, radians, wrapped differences).
//! * [`dataset`]: HDM05 file names (`HDM_<actor>_<class>_<nnn>_120.amc`), class and
//!   actor selection, loading at 30 fps.
//! * [`dtw`]: minimum DTW distance between synthesised and test clips.
//! * [`mmd`]: maximum mean discrepancy between synthesised and test clips.
//! * [`predict`]: the downstream protocol: leave one actor out, train a motion
//!   prediction model (GRU seq2seq or DCT + GCN) with and without augmented clips,
//!   report the Euler-angle error at 100, 200 and 400 ms; [`options`]: how
//!   its models are trained.
//! * [`cmu_dmgnn`]: the CMU data set as preprocessed for DMGNN (exponential
//!   maps, text) and the exact test protocol of DMGNN / V-DMGNN-GAN on it
//!   (test windows from numpy's `RandomState`, the Euler mean angle error).
//! * [`augment`]: where synthesised clips come from (a recipe run in memory by
//!   the `pipeline` crate, or the motion VAE); [`scores`]: min DTW, MMD and
//!   plausibility of a synthesised set.
//! * [`table`]: the whole evaluation table (config, a run returning a typed
//!   result, its JSON and Markdown), its physics rows through the pipeline's
//!   one executor.
//!
//! No HTTP, no SQL; files only where asked: the table's `work` folder (trained
//! VAEs, corrections, so a rerun resumes) and [`table::Table::write`]. The CLI
//! (`motionaug eval`) parses arguments and prints.

pub mod augment;
pub mod cmu_dmgnn;
pub mod dataset;
pub mod dtw;
pub mod error;
pub mod euler;
pub mod mmd;
pub mod options;
pub mod predict;
pub mod scores;
pub mod table;

/// The bundled example kick (bd, 120 fps), for the crate's tests.
#[cfg(test)]
pub(crate) fn example_kick() -> motion::Motion {
    let asf = motion::asf::parse(
        include_bytes!("../../../examples/data/HDM_bd.asf"),
        "HDM_bd.asf",
    )
    .expect("the bundled skeleton parses");
    motion::amc::read(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../examples/data/HDM_bd_kickLFront1Reps_001_120.amc"
        ),
        &asf,
        120.0,
    )
    .expect("the bundled kick reads")
}

pub use error::{EvalError, Result};

/// Where progress lines go (the CLI prints them on stderr).
pub type Log<'a> = &'a (dyn Fn(&str) + Sync);
