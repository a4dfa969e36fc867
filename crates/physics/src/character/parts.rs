//! Finding the body parts of a skeleton from its rest pose: steps 1 to 5 of
//! the [module docs](super) (legs, arms, head, the roles along each limb, the
//! torso), each a method of [`RestPose`] called in that order by
//! [`RestPose::find_parts`].

use glam::DVec3;
use motion::Skeleton;

use super::Side;
use crate::PhysicsError;

/// Segments shorter than this (metres) are zero-length helper joints.
pub(super) const EPS_LEN: f64 = 0.005;

pub(super) fn bad(msg: impl Into<String>) -> PhysicsError {
    PhysicsError::Character(msg.into())
}

/// The rest-pose geometry of a skeleton (root at the origin, y up).
pub(super) struct RestPose<'a> {
    pub sk: &'a Skeleton,
    /// Rest position of each joint.
    pub pos: Vec<DVec3>,
    /// Each joint's position plus its end site (the joint itself without one).
    pub tip: Vec<DVec3>,
    children: Vec<Vec<usize>>,
    /// Length along the bones from the root to each joint.
    path_len: Vec<f64>,
    /// Rest height of the body.
    pub height: f64,
}

/// A limb chain split into roles: indices into the skeleton.
pub(super) struct Limb {
    pub upper: usize,
    pub lower: usize,
    pub end: Option<usize>,
    pub side: Side,
}

/// The torso joints that drive bodies (step 5).
struct Torso {
    pelvis: usize,
    /// Spine drivers up to the chest, at most two (Spine, Chest).
    spine: Vec<usize>,
    neck: Option<usize>,
}

/// Everything steps 1 to 5 found.
pub(super) struct Parts {
    pub pelvis: usize,
    /// At most two: `[Chest]` or `[Spine, Chest]`.
    pub spine: Vec<usize>,
    pub neck: Option<usize>,
    pub legs: [Limb; 2],
    pub arms: [Limb; 2],
    /// Rest-pose facing direction (horizontal unit vector).
    pub forward: DVec3,
}

impl<'a> RestPose<'a> {
    pub fn new(sk: &'a Skeleton) -> Result<Self, PhysicsError> {
        let n = sk.len();
        let pos = sk.rest_positions();
        let mut children = vec![Vec::new(); n];
        for i in 1..n {
            if let Some(p) = sk.parent(i) {
                children[p].push(i);
            }
        }
        let tip: Vec<DVec3> = (0..n)
            .map(|i| pos[i] + sk.joint(i).end_site.unwrap_or(DVec3::ZERO))
            .collect();
        let mut path_len = vec![0.0; n];
        for i in 1..n {
            let p = sk.parent(i).unwrap_or(0);
            path_len[i] = path_len[p] + (pos[i] - pos[p]).length();
        }
        let height = sk.rest_height();
        if !(height.is_finite() && height > 0.3) {
            return Err(bad(format!(
                "rest pose is {height:.3} m tall: not a humanoid in metres"
            )));
        }
        Ok(RestPose {
            sk,
            pos,
            tip,
            children,
            path_len,
            height,
        })
    }

    /// Steps 1 to 5 of the module docs, in order.
    pub fn find_parts(&self) -> Result<Parts, PhysicsError> {
        let leaves: Vec<usize> = (0..self.sk.len()).filter(|&j| self.is_leaf(j)).collect();
        let (p, leg_chains) = self.legs(&leaves)?;
        let (c, arm_chains) = self.arms(&leaves, &leg_chains)?;
        let head = self.head(&leaves, &leg_chains, &arm_chains, c);
        let forward = self.forward(&leg_chains)?;
        let lateral = DVec3::Y.cross(forward); // character's left
        let legs = [
            self.limb(&leg_chains[0], "leg", lateral)?,
            self.limb(&leg_chains[1], "leg", lateral)?,
        ];
        let arms = [
            self.limb(&arm_chains[0], "arm", lateral)?,
            self.limb(&arm_chains[1], "arm", lateral)?,
        ];
        if legs[0].side == legs[1].side {
            return Err(bad("both legs look like the same side"));
        }
        if arms[0].side == arms[1].side {
            return Err(bad("both arms look like the same side"));
        }
        let torso = self.torso(p, c, head);
        Ok(Parts {
            pelvis: torso.pelvis,
            spine: torso.spine,
            neck: torso.neck,
            legs,
            arms,
            forward,
        })
    }

    /// 1. Legs: the two feet and `P`, their common ancestor; the chains are the
    ///    joints after `P` down to each foot tip.
    fn legs(&self, leaves: &[usize]) -> Result<(usize, [Vec<usize>; 2]), PhysicsError> {
        let h = self.height;
        // Height of the lowest point of the rest pose (the floor under the feet).
        let floor_y = self
            .pos
            .iter()
            .chain(&self.tip)
            .map(|p| p.y)
            .fold(f64::INFINITY, f64::min);
        let low: Vec<usize> = leaves
            .iter()
            .copied()
            .filter(|&l| self.tip[l].y < floor_y + 0.25 * h)
            .collect();
        let by_y = |a: &usize, b: &usize| self.tip[*a].y.total_cmp(&self.tip[*b].y);
        let l1 = low.iter().copied().min_by(by_y).ok_or_else(|| {
            bad("no leg: no joint reaches a quarter of the height below the root")
        })?;
        let l2 = low
            .iter()
            .copied()
            .filter(|&l| self.pos[self.lca(l1, l)].y > floor_y + 0.4 * h)
            .min_by(by_y)
            .ok_or_else(|| bad("found only one leg"))?;
        let p = self.lca(l1, l2);
        Ok((p, [self.path_after(p, l1), self.path_after(p, l2)]))
    }

    /// 2. Arms: the two hands among the leaves outside the legs and `C`, their
    ///    common ancestor (the chest); the chains run from after `C` to each hand.
    fn arms(
        &self,
        leaves: &[usize],
        leg_chains: &[Vec<usize>; 2],
    ) -> Result<(usize, [Vec<usize>; 2]), PhysicsError> {
        let h = self.height;
        let upper: Vec<usize> = leaves
            .iter()
            .copied()
            .filter(|&l| !self.in_chains(l, leg_chains))
            .collect();
        let by_len = |a: &usize, b: &usize| self.tip_path_len(*a).total_cmp(&self.tip_path_len(*b));
        let h1 = upper
            .iter()
            .copied()
            .max_by(by_len)
            .ok_or_else(|| bad("no arms"))?;
        let h2 = upper
            .iter()
            .copied()
            .filter(|&l| {
                let c = self.lca(h1, l);
                l != h1 && self.tip_path_len(l) - self.path_len[c] > 0.25 * h
            })
            .max_by(by_len)
            .ok_or_else(|| bad("found only one arm"))?;
        let c = self.lca(h1, h2);
        Ok((c, [self.path_after(c, h1), self.path_after(c, h2)]))
    }

    /// 3. Head: the highest remaining leaf tip under `C`, if any.
    fn head(
        &self,
        leaves: &[usize],
        leg_chains: &[Vec<usize>; 2],
        arm_chains: &[Vec<usize>; 2],
        c: usize,
    ) -> Option<usize> {
        leaves
            .iter()
            .copied()
            .filter(|&l| {
                !self.in_chains(l, leg_chains)
                    && !self.in_chains(l, arm_chains)
                    && self.in_subtree(l, c)
                    && l != c
            })
            .max_by(|a, b| self.tip[*a].y.total_cmp(&self.tip[*b].y))
    }

    /// Facing direction from the feet: the horizontal sum of foot-to-toe-tip.
    fn forward(&self, leg_chains: &[Vec<usize>; 2]) -> Result<DVec3, PhysicsError> {
        let mut fwd = DVec3::ZERO;
        for chain in leg_chains {
            let (_, _, end) = self.split_limb(chain, "leg")?;
            let foot = end.ok_or_else(|| bad("leg without a foot"))?;
            let leaf = *chain.last().unwrap_or(&foot);
            let d = self.tip[leaf] - self.pos[foot];
            fwd += DVec3::new(d.x, 0.0, d.z);
        }
        Ok(if fwd.length() > 1e-6 {
            fwd.normalize()
        } else {
            DVec3::Z
        })
    }

    /// 4. The roles along a limb chain and its side.
    fn limb(&self, chain: &[usize], what: &str, lateral: DVec3) -> Result<Limb, PhysicsError> {
        let (upper, lower, end) = self.split_limb(chain, what)?;
        Ok(Limb {
            upper,
            lower,
            end,
            side: self.side_of(chain, lateral),
        })
    }

    /// 5. Torso: the pelvis (common ancestor of `P` and `C`), the spine drivers
    ///    up to `C` and the neck after it.
    fn torso(&self, p: usize, c: usize, head: Option<usize>) -> Torso {
        let pelvis = self.lca(p, c);
        let torso_end = head.unwrap_or(c);
        let torso = self.path_after(pelvis, torso_end);
        let torso_seg = self.segments(&torso);
        let c_idx = torso.iter().position(|&j| j == c);
        let mut spine_drivers: Vec<usize> = Vec::new();
        let mut neck = None;
        for (k, &j) in torso.iter().enumerate() {
            let upto_c = c_idx.is_some_and(|ci| k <= ci);
            if torso_seg[k] <= EPS_LEN {
                continue;
            }
            if upto_c {
                spine_drivers.push(j);
            } else if neck.is_none() && c_idx.is_some() {
                neck = Some(j);
            }
        }
        if spine_drivers.len() > 2 {
            spine_drivers = vec![spine_drivers[0], *spine_drivers.last().unwrap_or(&c)];
        }
        Torso {
            pelvis,
            spine: spine_drivers,
            neck,
        }
    }

    fn is_leaf(&self, j: usize) -> bool {
        self.children[j].is_empty()
    }

    fn tip_path_len(&self, j: usize) -> f64 {
        self.path_len[j] + (self.tip[j] - self.pos[j]).length()
    }

    fn lca(&self, a: usize, b: usize) -> usize {
        let anc = self.sk.ancestors(a);
        let mut at = b;
        loop {
            if anc.contains(&at) {
                return at;
            }
            match self.sk.parent(at) {
                Some(p) => at = p,
                None => return 0,
            }
        }
    }

    fn in_subtree(&self, j: usize, root: usize) -> bool {
        self.sk.ancestors(j).contains(&root)
    }

    /// Whether `j` lies in the subtree of the first joint of one of `chains`.
    fn in_chains(&self, j: usize, chains: &[Vec<usize>; 2]) -> bool {
        chains
            .iter()
            .any(|c| !c.is_empty() && self.in_subtree(j, c[0]))
    }

    /// Joints strictly after `from` on the path from the root to `to`.
    fn path_after(&self, from: usize, to: usize) -> Vec<usize> {
        let mut path = self.sk.ancestors(to);
        path.reverse();
        match path.iter().position(|&j| j == from) {
            Some(i) => path[i + 1..].to_vec(),
            None => path,
        }
    }

    /// Segment length of each chain joint: to the next chain joint, the last one to its tip.
    fn segments(&self, chain: &[usize]) -> Vec<f64> {
        (0..chain.len())
            .map(|k| {
                let j = chain[k];
                let next = if k + 1 < chain.len() {
                    self.pos[chain[k + 1]]
                } else {
                    self.tip[j]
                };
                (next - self.pos[j]).length()
            })
            .collect()
    }

    fn side_of(&self, chain: &[usize], lateral: DVec3) -> Side {
        let names: Vec<String> = self
            .sk
            .joints()
            .iter()
            .map(|j| j.name.to_ascii_lowercase())
            .collect();
        let mut vote = 0i32;
        for &j in chain {
            let n = &names[j];
            if n.contains("left") {
                vote += 1;
            } else if n.contains("right") {
                vote -= 1;
            } else if let Some(rest) = n.strip_prefix('l') {
                if names.iter().any(|m| m.strip_prefix('r') == Some(rest)) {
                    vote += 1;
                }
            } else if let Some(rest) = n.strip_prefix('r')
                && names.iter().any(|m| m.strip_prefix('l') == Some(rest))
            {
                vote -= 1;
            }
        }
        if vote > 0 {
            Side::Left
        } else if vote < 0 {
            Side::Right
        } else {
            let last = *chain.last().unwrap_or(&0);
            if (self.tip[last] - self.pos[0]).dot(lateral) >= 0.0 {
                Side::Left
            } else {
                Side::Right
            }
        }
    }

    fn split_limb(
        &self,
        chain: &[usize],
        what: &str,
    ) -> Result<(usize, usize, Option<usize>), PhysicsError> {
        let seg = self.segments(chain);
        let next_nonzero = |k: usize| (k + 1..chain.len()).find(|&i| seg[i] > EPS_LEN);
        // Upper and lower limb: the last pair of consecutive non-zero segments that
        // are both at least 45% of the chain's longest segment (a clavicle may be
        // as long as a forearm, but it comes first; wrists and toes are short).
        let longest = seg.iter().copied().fold(0.0, f64::max);
        let mut found = None;
        for k in 0..chain.len() {
            if seg[k] < 0.45 * longest || seg[k] <= EPS_LEN {
                continue;
            }
            if let Some(k2) = next_nonzero(k)
                && seg[k2] >= 0.45 * longest
            {
                found = Some((k, k2));
            }
        }
        let (k1, k2) = found.ok_or_else(|| {
            bad(format!(
                "the {what} chain ending at `{}` has no two consecutive long bones",
                chain
                    .last()
                    .map(|&j| self.sk.joint(j).name.as_str())
                    .unwrap_or("?")
            ))
        })?;
        let end = next_nonzero(k2).or(if k2 + 1 < chain.len() {
            Some(k2 + 1)
        } else {
            None
        });
        Ok((chain[k1], chain[k2], end.map(|k| chain[k])))
    }
}
