//! From the finished bones and the `:hierarchy` lines to the crate's
//! [`Skeleton`]: the bone tree, then one joint per node in depth-first order
//! (the root, then each bone at the end of its parent bone).

use std::collections::HashMap;

use glam::DVec3;

use super::sections::HierarchyLine;
use super::{AsfBone, AsfRoot, Dof};
use crate::error::MotionError;
use crate::skeleton::{Axis, Channel, Joint, JointLimits, Skeleton};
use crate::text::{Errors, show};

/// The rotation channels of every joint, outermost first.
const ROTATIONS: [Channel; 3] = [
    Channel::Rotation(Axis::Z),
    Channel::Rotation(Axis::Y),
    Channel::Rotation(Axis::X),
];

/// Joints in depth-first order following `:hierarchy` (children in listed
/// order), and the joint of each bone.
pub(super) fn build(
    bones: &[AsfBone],
    root: &AsfRoot,
    hierarchy: &[HierarchyLine],
    unit_m: f64,
    errors: &Errors,
) -> Result<(Skeleton, Vec<usize>), MotionError> {
    let children = tree(bones, hierarchy, errors)?;
    let mut joints = Vec::with_capacity(bones.len() + 1);
    let mut joint_of_node = vec![usize::MAX; bones.len() + 1];
    // Depth-first, iterative: (node, parent node).
    let mut stack: Vec<(usize, Option<usize>)> = vec![(0, None)];
    while let Some((nd, parent_node)) = stack.pop() {
        let parent_joint = parent_node.map(|p| joint_of_node[p]);
        if joint_of_node[nd] != usize::MAX {
            // Cannot happen with one parent per bone, but never loop.
            continue;
        }
        let index = joints.len();
        joint_of_node[nd] = index;
        let leaf = children[nd].is_empty();
        joints.push(if nd == 0 {
            root_joint(root)
        } else {
            bone_joint(bones, nd, parent_node, parent_joint, leaf)
        });
        for &c in children[nd].iter().rev() {
            stack.push((c, Some(nd)));
        }
    }
    if let Some(b) = (1..=bones.len()).find(|&nd| joint_of_node[nd] == usize::MAX) {
        let bone = &bones[b - 1];
        return Err(errors
            .at(
                bone.line,
                format!(
                    "bone `{}` is not connected to the root in :hierarchy",
                    bone.name
                ),
            )
            .into());
    }
    let joint_of_bone = (1..=bones.len()).map(|nd| joint_of_node[nd]).collect();
    let skeleton = Skeleton::new(joints, unit_m).map_err(|e| errors.whole(e.to_string()))?;
    Ok((skeleton, joint_of_bone))
}

/// Children of each node (node 0 is the root, node b + 1 is bone b), in the
/// order `:hierarchy` lists them; every bone has at most one parent.
fn tree(
    bones: &[AsfBone],
    hierarchy: &[HierarchyLine],
    errors: &Errors,
) -> Result<Vec<Vec<usize>>, MotionError> {
    let by_name: HashMap<Vec<u8>, usize> = bones
        .iter()
        .enumerate()
        .map(|(b, bone)| (bone.name.as_bytes().to_ascii_lowercase(), b + 1))
        .collect();
    let node = |name: &[u8]| -> Option<usize> {
        if name.eq_ignore_ascii_case(b"root") {
            Some(0)
        } else {
            by_name.get(&name.to_ascii_lowercase()).copied()
        }
    };
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); bones.len() + 1];
    let mut parent_line: Vec<Option<usize>> = vec![None; bones.len() + 1];
    for (parent, kids, line) in hierarchy {
        let p = node(parent).ok_or_else(|| {
            errors.at(
                *line,
                format!("`{}` in :hierarchy is not a bone", show(parent)),
            )
        })?;
        for k in kids {
            let c = node(k).ok_or_else(|| {
                errors.at(*line, format!("`{}` in :hierarchy is not a bone", show(k)))
            })?;
            if c == 0 {
                return Err(errors.at(*line, "the root cannot be a child").into());
            }
            if let Some(prev) = parent_line[c] {
                return Err(errors
                    .at(
                        *line,
                        format!("bone `{}` already has a parent (line {prev})", show(k)),
                    )
                    .into());
            }
            parent_line[c] = Some(*line);
            children[p].push(c);
        }
    }
    Ok(children)
}

/// The `root` joint: at its rest position, with position and rotation channels.
fn root_joint(root: &AsfRoot) -> Joint {
    let mut channels = vec![
        Channel::Position(Axis::X),
        Channel::Position(Axis::Y),
        Channel::Position(Axis::Z),
    ];
    channels.extend(ROTATIONS);
    Joint {
        name: "root".into(),
        parent: None,
        offset: root.position,
        channels,
        end_site: None,
        limits: None,
    }
}

/// The joint of node `nd` (bone `nd - 1`), at the end of its parent bone.
fn bone_joint(
    bones: &[AsfBone],
    nd: usize,
    parent_node: Option<usize>,
    parent_joint: Option<usize>,
    leaf: bool,
) -> Joint {
    let bone = &bones[nd - 1];
    // Offset: the parent bone's vector (0 for children of the root).
    let offset = match parent_node {
        Some(p) if p > 0 => bones[p - 1].direction * bones[p - 1].length,
        _ => DVec3::ZERO,
    };
    let rot_dofs: Vec<(Axis, f64, f64)> = bone
        .dofs
        .iter()
        .enumerate()
        .filter_map(|(k, d)| match d {
            Dof::Rotation(a) => {
                let (lo, hi) = bone
                    .limits
                    .get(k)
                    .copied()
                    .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
                Some((*a, lo, hi))
            }
            _ => None,
        })
        .rev()
        .collect();
    let limits = if bone.limits.is_empty() {
        None
    } else {
        Some(JointLimits {
            frame: bone.frame,
            dofs: rot_dofs,
        })
    };
    Joint {
        name: bone.name.clone(),
        parent: parent_joint,
        offset,
        channels: ROTATIONS.to_vec(),
        end_site: if leaf {
            Some(bone.direction * bone.length)
        } else {
            None
        },
        limits,
    }
}
