//! The motion model every other crate builds on.
//!
//! * [`Skeleton`]: joints in topological order (a parent always comes before its
//!   children), rest offsets in metres, y up, the source file's channel layout and
//!   joint limits where the file has them, and the static joints a file had above
//!   its travelling joint ([`BaseJoint`]).
//! * [`Motion`]: a skeleton, a frame rate, the world position of the root per
//!   frame and one local rotation per joint per frame, translation tracks for the
//!   joints a file animates the offset of, plus forward kinematics.
//!
//! `docs/TRANSLATION_TRACKS.md` says how animated translations and a static
//! root above the travelling joint are read, stored and written.
//!
//! All lengths are metres, all angles radians, all rotations unit quaternions
//! (`glam::DQuat`, f64: the motion model is the reference copy of a clip, physics
//! converts to f32 where speed matters).

pub mod amc;
pub mod asf;
pub mod bvh;
pub mod error;
pub mod io;
pub mod metrics;
pub mod motion;
pub mod npz;
pub mod resample;
pub mod rotation;
pub mod skeleton;
pub mod smooth;
mod text;
pub mod units;

pub use error::{MotionError, ParseError};
pub use io::{LoadOptions, load, save};
pub use motion::{Motion, Tracks};
pub use skeleton::{Axis, BaseJoint, Channel, Joint, JointLimits, Skeleton, Transform};
pub use units::Unit;

/// Re-exported so downstream crates use the same maths types.
pub use glam;
