//! The skeleton as the three graphs DMGNN works on (joints, parts, bodies),
//! derived from any skeleton's hierarchy and joint names, so that HDM05 (ASF),
//! CMU (DMGNN's preprocessing) and BVH skeletons all work, not one fixed
//! 26-joint list.
//!
//! * **Joints** (scale 1): the model's nodes, a subset of the skeleton's joints
//!   (the ones whose rotations are features); a node's parent is its nearest
//!   ancestor that is also a node.
//! * **Bodies** (scale 3): the four limbs and the torso. A limb is the subtree
//!   of the highest ancestor of a hand or foot ([`synth::names::hands`],
//!   [`synth::names::feet`]) below the joint where that limb branches off; what
//!   no limb holds is the torso (spine, neck, head).
//! * **Parts** (scale 2): every body split in two along its chain (upper and
//!   lower arm or leg, lower torso and neck/head): a node belongs to the first
//!   half when its depth below the body's top is less than half the body's depth.
//!
//! Graph convolutions use two adjacency partitions per scale (DMGNN's
//! "distance" strategy with one hop): the identity and the degree-normalised
//! neighbours. Parts and bodies are neighbours when a skeleton edge joins them.

use motion::Skeleton;
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BodyGraph {
    /// Skeleton joint of each node.
    pub joints: Vec<usize>,
    /// Joint name of each node (what a model file records of its skeleton).
    pub names: Vec<String>,
    /// Parent node of each node.
    pub parents: Vec<Option<usize>>,
    /// Part (scale 2) of each node, and the number of parts.
    pub part_of: Vec<usize>,
    pub parts: usize,
    /// Body (scale 3) of each node, and the number of bodies.
    pub body_of: Vec<usize>,
    pub bodies: usize,
    /// Nodes of the lower body ([`synth::names::lower_body`]): what the
    /// lower-body occlusion mask hides.
    pub lower_body: Vec<bool>,
}

/// Which of the three graphs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    Joints,
    Parts,
    Bodies,
}

impl BodyGraph {
    /// The graph over `node_joints` (skeleton joint indices, in feature order).
    pub fn new(skeleton: &Skeleton, node_joints: &[usize]) -> Result<BodyGraph> {
        if node_joints.is_empty() {
            return Err(EvalError::Config("body graph: no nodes".into()));
        }
        let n = skeleton.len();
        let mut node_of = vec![None; n];
        for (i, &j) in node_joints.iter().enumerate() {
            if j >= n || node_of[j].is_some() {
                return Err(EvalError::Config(format!(
                    "body graph: joint {j} out of range or listed twice"
                )));
            }
            node_of[j] = Some(i);
        }
        let parents: Vec<Option<usize>> = node_joints
            .iter()
            .map(|&j| {
                skeleton
                    .ancestors(j)
                    .into_iter()
                    .skip(1)
                    .find_map(|a| node_of[a])
            })
            .collect();

        // Bodies: one limb per hand and foot, the torso for the rest.
        let mut limb_of = vec![None::<usize>; n];
        let mut ends: Vec<usize> = synth::names::hands(skeleton);
        ends.extend(synth::names::feet(skeleton));
        let chains: Vec<Vec<usize>> = ends.iter().map(|&e| skeleton.ancestors(e)).collect();
        let mut limbs = 0;
        for (k, chain) in chains.iter().enumerate() {
            // The top of the limb: the highest joint of this chain that is on
            // no other end's chain.
            let Some(&top) = chain
                .iter()
                .take_while(|j| {
                    chains
                        .iter()
                        .enumerate()
                        .all(|(o, c)| o == k || !c.contains(j))
                })
                .last()
            else {
                continue;
            };
            if skeleton.parent(top).is_none() {
                continue;
            }
            for (j, limb) in limb_of.iter_mut().enumerate() {
                if limb.is_none() && skeleton.ancestors(j).contains(&top) {
                    *limb = Some(limbs);
                }
            }
            limbs += 1;
        }
        let torso = limbs;
        let body_joint: Vec<usize> = (0..n).map(|j| limb_of[j].unwrap_or(torso)).collect();
        // Renumber bodies that hold nodes, in the order their first node appears.
        let mut body_ids: Vec<usize> = Vec::new();
        let body_of: Vec<usize> = node_joints
            .iter()
            .map(|&j| {
                let b = body_joint[j];
                match body_ids.iter().position(|&x| x == b) {
                    Some(i) => i,
                    None => {
                        body_ids.push(b);
                        body_ids.len() - 1
                    }
                }
            })
            .collect();
        let bodies = body_ids.len();

        // Parts: each body's nodes split by depth below the body's top.
        let depth_in_body = |i: usize| -> usize {
            let mut d = 0;
            let mut at = i;
            while let Some(p) = parents[at] {
                if body_of[p] != body_of[i] {
                    break;
                }
                d += 1;
                at = p;
            }
            d
        };
        let depths: Vec<usize> = (0..node_joints.len()).map(depth_in_body).collect();
        let mut part_of = vec![0; node_joints.len()];
        let mut parts = 0;
        for b in 0..bodies {
            let members: Vec<usize> = (0..node_joints.len())
                .filter(|&i| body_of[i] == b)
                .collect();
            let max_depth = members.iter().map(|&i| depths[i]).max().unwrap_or(0);
            let split = max_depth.div_ceil(2).max(1);
            let upper = parts;
            let lower = if max_depth == 0 { parts } else { parts + 1 };
            for &i in &members {
                part_of[i] = if depths[i] < split { upper } else { lower };
            }
            parts = lower + 1;
        }

        let lower_joints = synth::names::lower_body(skeleton).unwrap_or_default();
        Ok(BodyGraph {
            joints: node_joints.to_vec(),
            names: node_joints
                .iter()
                .map(|&j| skeleton.joint(j).name.clone())
                .collect(),
            parents,
            part_of,
            parts,
            body_of,
            bodies,
            lower_body: node_joints
                .iter()
                .map(|j| lower_joints.contains(j))
                .collect(),
        })
    }

    /// Every non-root joint of `skeleton` (the features of [`super::data`]).
    pub fn non_root(skeleton: &Skeleton) -> Result<BodyGraph> {
        let nodes: Vec<usize> = (1..skeleton.len()).collect();
        BodyGraph::new(skeleton, &nodes)
    }

    pub fn nodes(&self) -> usize {
        self.joints.len()
    }

    pub fn size(&self, scale: Scale) -> usize {
        match scale {
            Scale::Joints => self.nodes(),
            Scale::Parts => self.parts,
            Scale::Bodies => self.bodies,
        }
    }

    /// Group of each node at `scale` (itself at the joint scale).
    fn group(&self, scale: Scale) -> Vec<usize> {
        match scale {
            Scale::Joints => (0..self.nodes()).collect(),
            Scale::Parts => self.part_of.clone(),
            Scale::Bodies => self.body_of.clone(),
        }
    }

    /// Neighbour pairs at `scale` (each once, no self pairs). Nodes without a
    /// parent node hang from the same joint (the root, which is no node when
    /// only non-root rotations are features): they are neighbours of each other.
    fn edges(&self, scale: Scale) -> Vec<(usize, usize)> {
        let g = self.group(scale);
        let tops: Vec<usize> = (0..self.nodes())
            .filter(|&i| self.parents[i].is_none())
            .collect();
        let mut pairs: Vec<(usize, usize)> = self
            .parents
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (i, p)))
            .collect();
        for (k, &a) in tops.iter().enumerate() {
            pairs.extend(tops[k + 1..].iter().map(|&b| (a, b)));
        }
        let mut out = Vec::new();
        for (i, p) in pairs {
            let (a, b) = (g[i].min(g[p]), g[i].max(g[p]));
            if a != b && !out.contains(&(a, b)) {
                out.push((a, b));
            }
        }
        out
    }

    /// The two adjacency partitions `(2, S, S)` row-major: identity, then the
    /// neighbours with each row divided by its degree.
    pub fn adjacency(&self, scale: Scale) -> Vec<f32> {
        let s = self.size(scale);
        let mut a = vec![0f32; 2 * s * s];
        for i in 0..s {
            a[i * s + i] = 1.0;
        }
        let mut degree = vec![0f32; s];
        let edges = self.edges(scale);
        for &(x, y) in &edges {
            degree[x] += 1.0;
            degree[y] += 1.0;
        }
        for &(x, y) in &edges {
            a[s * s + x * s + y] = 1.0 / degree[x];
            a[s * s + y * s + x] = 1.0 / degree[y];
        }
        a
    }

    /// `(S, V)` row-major: each group's row averages its member nodes.
    pub fn pooling(&self, scale: Scale) -> Vec<f32> {
        let (s, v) = (self.size(scale), self.nodes());
        let g = self.group(scale);
        let mut count = vec![0f32; s];
        for &k in &g {
            count[k] += 1.0;
        }
        let mut m = vec![0f32; s * v];
        for (i, &k) in g.iter().enumerate() {
            m[k * v + i] = 1.0 / count[k];
        }
        m
    }

    /// `(V, S)` row-major: each node takes its group's value.
    pub fn spreading(&self, scale: Scale) -> Vec<f32> {
        let (s, v) = (self.size(scale), self.nodes());
        let g = self.group(scale);
        let mut m = vec![0f32; v * s];
        for (i, &k) in g.iter().enumerate() {
            m[i * s + k] = 1.0;
        }
        m
    }

    /// Same nodes in the same order (what a trained model checks of a clip).
    pub fn check_matches(&self, other: &BodyGraph) -> Result<()> {
        if self.names != other.names || self.parents != other.parents {
            return Err(EvalError::Data(format!(
                "skeleton mismatch: the model was trained on {} joints ({}), the clip has {} ({})",
                self.nodes(),
                self.names.join(", "),
                other.nodes(),
                other.names.join(", ")
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hdm05() -> Skeleton {
        crate::predict::test_support::hdm05_skeleton()
    }

    #[test]
    fn hdm05_has_five_bodies_ten_parts_and_legs_below() {
        let s = hdm05();
        let g = BodyGraph::non_root(&s).unwrap();
        assert_eq!(g.nodes(), s.len() - 1);
        assert_eq!(g.bodies, 5, "{:?}", g.body_of);
        assert_eq!(g.parts, 10, "{:?}", g.part_of);
        let node = |name: &str| g.names.iter().position(|n| n == name).unwrap();
        // Both halves of a leg are in one body, different parts.
        assert_eq!(g.body_of[node("lfemur")], g.body_of[node("lfoot")]);
        assert_ne!(g.part_of[node("lfemur")], g.part_of[node("lfoot")]);
        assert_ne!(g.body_of[node("lfemur")], g.body_of[node("rfemur")]);
        assert_ne!(g.body_of[node("lhumerus")], g.body_of[node("head")]);
        assert!(g.lower_body[node("ltibia")] && !g.lower_body[node("lhumerus")]);
        // Every group has a member; pooling rows sum to 1.
        for scale in [Scale::Joints, Scale::Parts, Scale::Bodies] {
            let (k, v) = (g.size(scale), g.nodes());
            let p = g.pooling(scale);
            for r in 0..k {
                let sum: f32 = p[r * v..(r + 1) * v].iter().sum();
                assert!((sum - 1.0).abs() < 1e-5);
            }
            let a = g.adjacency(scale);
            // The neighbour partition is connected: every group has a neighbour.
            for r in 0..k {
                let sum: f32 = a[k * k + r * k..k * k + (r + 1) * k].iter().sum();
                assert!((sum - 1.0).abs() < 1e-5, "{scale:?} row {r}");
            }
        }
    }

    #[test]
    fn a_subset_of_joints_keeps_its_nearest_node_ancestors() {
        let s = hdm05();
        let pick: Vec<usize> = ["lfemur", "lfoot", "thorax", "lhumerus", "lwrist"]
            .iter()
            .map(|n| s.find(n).unwrap())
            .collect();
        let g = BodyGraph::new(&s, &pick).unwrap();
        assert_eq!(g.parents[1], Some(0), "lfoot hangs under lfemur");
        assert_eq!(g.parents[4], Some(3));
        assert!(BodyGraph::new(&s, &[1, 1]).is_err());
        let other = BodyGraph::non_root(&s).unwrap();
        assert!(g.check_matches(&other).is_err());
        assert!(other.check_matches(&other).is_ok());
    }
}
