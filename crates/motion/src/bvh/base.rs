//! Folding a static root above a travelling joint into the skeleton's base.
//!
//! Some exporters put a joint that never moves (`joint_Root` at the origin)
//! above the joint that carries the body's travel (`Hips`, with animated
//! position channels). Everything downstream (synthesis, metrics, physics,
//! the VAE) takes joint 0 for the body's root and its translation for the
//! body's travel, so the reader turns such a file into the equivalent motion
//! whose root is the travelling joint: its world translation and rotation
//! become the root translation and the root's rotation, and the static joints
//! above it go into the skeleton's base ([`crate::skeleton::BaseJoint`]), from
//! where the writer puts them back. World positions of every joint are
//! unchanged; `docs/TRANSLATION_TRACKS.md` has the whole story.
//!
//! The fold applies when, walking down from the root, every joint holds still
//! over the clip (all its channels constant) and has exactly one child, until
//! a joint with a translation track: that joint is the travelling one. Any
//! other layout is kept as it is (a translation track on a joint below a
//! moving root stays a track).

use std::sync::Arc;

use glam::DVec3;

use crate::error::MotionError;
use crate::motion::{Motion, Tracks};
use crate::skeleton::{BaseJoint, Joint, Skeleton};

/// The travelling joint and the static chain above it (outermost first), if
/// the layout has one: `parents` of every joint, `still[j]` when joint `j`'s
/// channels hold still, `tracked[j]` when it has a translation track.
pub(super) fn static_chain(
    parents: &[Option<usize>],
    still: &[bool],
    tracked: &[bool],
) -> Option<(usize, Vec<usize>)> {
    let mut chain = Vec::new();
    let mut j = 0;
    loop {
        if !still[j] {
            return None;
        }
        let mut kids = (0..parents.len()).filter(|&c| parents[c] == Some(j));
        let (Some(child), None) = (kids.next(), kids.next()) else {
            return None;
        };
        chain.push(j);
        if tracked[child] {
            return Some((child, chain));
        }
        j = child;
    }
}

/// `motion` with the static joints `chain` above its travelling joint
/// `travelling` ([`static_chain`]) folded into the skeleton's base (see the
/// module doc).
pub(super) fn fold_static_base(
    motion: Motion,
    travelling: usize,
    chain: &[usize],
) -> Result<Motion, MotionError> {
    let skeleton = motion.skeleton();
    let base: Vec<BaseJoint> = chain
        .iter()
        .map(|&k| {
            let joint = skeleton.joint(k);
            BaseJoint {
                name: joint.name.clone(),
                offset: joint.offset,
                translation: if k == 0 {
                    motion.root_translation()[0]
                } else {
                    joint.offset
                },
                rotation: motion.rotation(0, k),
                channels: joint.channels.clone(),
                end_site: joint.end_site,
            }
        })
        .collect();
    // Every joint not in the chain descends from the travelling joint and
    // comes after it (parents come first): keep their order.
    let kept: Vec<usize> = (0..skeleton.len()).filter(|j| !chain.contains(j)).collect();
    let mut new_index = vec![usize::MAX; skeleton.len()];
    for (n, &j) in kept.iter().enumerate() {
        new_index[j] = n;
    }
    let joints: Vec<Joint> = kept
        .iter()
        .map(|&j| {
            let mut joint = skeleton.joint(j).clone();
            joint.parent = if j == travelling {
                None
            } else {
                joint.parent.map(|p| new_index[p])
            };
            joint
        })
        .collect();
    let folded = Skeleton::new(joints, skeleton.source_unit_m())?.with_base(base)?;
    let frame = folded.base_frame();
    let track = motion.track(travelling).unwrap_or_default();
    let root: Vec<DVec3> = track
        .iter()
        .map(|p| frame.translation + frame.rotation * *p)
        .collect();
    let mut rotations = Vec::with_capacity(motion.frames() * kept.len());
    for f in 0..motion.frames() {
        for &j in &kept {
            let q = motion.rotation(f, j);
            rotations.push(if j == travelling {
                (frame.rotation * q).normalize()
            } else {
                q
            });
        }
    }
    let tracks: Tracks = if motion.has_tracks() {
        kept.iter()
            .map(|&j| {
                if j == travelling {
                    None
                } else {
                    motion.track(j).map(<[DVec3]>::to_vec)
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    Motion::new(Arc::new(folded), motion.fps(), root, rotations)?.with_tracks(tracks)
}
