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
//!   report the Euler-angle error at 100, 200 and 400 ms.
//!
//! No HTTP, no SQL, no files written: the CLI (`motionaug eval`) does I/O.

pub mod dataset;
pub mod dtw;
pub mod error;
pub mod euler;
pub mod mmd;
pub mod predict;

pub use error::{EvalError, Result};
