//! Finding body parts from joint names: left/right pairs, feet, hands, legs.
//!
//! Real files name joints in many ways (`LeftUpLeg`, `LHipJoint`, `lfemur`,
//! `hip_l`, `Hip.L`). Pairs are found by generating the counterpart name of every
//! joint under a few rules and keeping only pairs where both names exist
//! (case-insensitive) and point at each other. Feet and hands are found by name
//! first (`ankle`/`foot`, `wrist`/`hand`), the feet with a structural fallback.

use motion::Skeleton;

use crate::SynthError;

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Left,
    Right,
}

/// Candidate counterpart names of `name` with the side each rule implies for `name`.
fn counterparts(name: &str) -> Vec<(String, Side)> {
    let mut out = Vec::new();
    let lower = name.to_ascii_lowercase();
    // Rule 1: the words left/right anywhere.
    for (word, other, side) in [
        ("left", "right", Side::Left),
        ("right", "left", Side::Right),
    ] {
        if let Some(at) = lower.find(word) {
            let mut s = String::new();
            s.push_str(&name[..at]);
            s.push_str(other);
            s.push_str(&name[at + word.len()..]);
            out.push((s, side));
        }
    }
    // Rule 2: a leading l/r (LHipJoint, lfemur, L_Hip).
    // Rule 3: a trailing l/r (hip_l, Hip.L, HipL).
    let swap = |c: char| match c {
        'l' => Some(('r', Side::Left)),
        'r' => Some(('l', Side::Right)),
        'L' => Some(('R', Side::Left)),
        'R' => Some(('L', Side::Right)),
        _ => None,
    };
    let chars: Vec<char> = name.chars().collect();
    if chars.len() > 1 {
        if let Some((c, side)) = swap(chars[0]) {
            let s: String = std::iter::once(c)
                .chain(chars[1..].iter().copied())
                .collect();
            out.push((s, side));
        }
        if let Some((c, side)) = swap(chars[chars.len() - 1]) {
            let s: String = chars[..chars.len() - 1]
                .iter()
                .copied()
                .chain(std::iter::once(c))
                .collect();
            out.push((s, side));
        }
    }
    out
}

/// Side of each joint and its mirror partner (`partner[j] == j` for joints on the
/// body's centre line), found from names.
#[derive(Debug, Clone, PartialEq)]
pub struct Pairs {
    pub partner: Vec<usize>,
    pub side: Vec<Option<Side>>,
}

impl Pairs {
    /// Pairs found from the joint names.
    pub fn from_names(skeleton: &Skeleton) -> Pairs {
        let n = skeleton.len();
        let mut partner: Vec<usize> = (0..n).collect();
        let mut side = vec![None; n];
        for j in 0..n {
            let name = &skeleton.joint(j).name;
            for (candidate, s) in counterparts(name) {
                let Some(k) = skeleton.find(&candidate) else {
                    continue;
                };
                if k == j {
                    continue;
                }
                // Only accept when the rule works both ways.
                let back = counterparts(&skeleton.joint(k).name)
                    .into_iter()
                    .any(|(c, _)| skeleton.find(&c) == Some(j));
                if back {
                    partner[j] = k;
                    side[j] = Some(s);
                    break;
                }
            }
        }
        // Make the relation symmetric (first rule that matched wins for both).
        for j in 0..n {
            let k = partner[j];
            if partner[k] != j {
                partner[j] = j;
                side[j] = None;
            }
        }
        Pairs { partner, side }
    }

    /// Pairs given explicitly as (left, right) joint names; every other joint is
    /// treated as a centre-line joint.
    pub fn from_list(skeleton: &Skeleton, list: &[(String, String)]) -> Result<Pairs, SynthError> {
        let n = skeleton.len();
        let mut partner: Vec<usize> = (0..n).collect();
        let mut side = vec![None; n];
        for (i, (a, b)) in list.iter().enumerate() {
            let field = format!("pairs[{i}]");
            let ja = skeleton
                .find(a)
                .ok_or_else(|| SynthError::param(&field, format!("no joint named `{a}`")))?;
            let jb = skeleton
                .find(b)
                .ok_or_else(|| SynthError::param(&field, format!("no joint named `{b}`")))?;
            if ja == jb || partner[ja] != ja || partner[jb] != jb {
                return Err(SynthError::param(
                    &field,
                    format!("`{a}` and `{b}` must be two different joints, each in one pair only"),
                ));
            }
            partner[ja] = jb;
            partner[jb] = ja;
            side[ja] = Some(Side::Left);
            side[jb] = Some(Side::Right);
        }
        Ok(Pairs { partner, side })
    }

    pub fn pair_count(&self) -> usize {
        self.partner
            .iter()
            .enumerate()
            .filter(|(j, k)| j < k)
            .count()
    }
}

fn lower_name(skeleton: &Skeleton, j: usize) -> String {
    skeleton.joint(j).name.to_ascii_lowercase()
}

fn depth(skeleton: &Skeleton, j: usize) -> usize {
    skeleton.ancestors(j).len()
}

/// Of several candidates, keep per side the one highest in the hierarchy.
fn one_per_side(skeleton: &Skeleton, pairs: &Pairs, mut candidates: Vec<usize>) -> Vec<usize> {
    candidates.sort_by_key(|&j| (depth(skeleton, j), j));
    let mut out: Vec<usize> = Vec::new();
    for j in candidates {
        // Skip a candidate below an already chosen one (e.g. `LeftFoot_end`).
        if out.iter().any(|&k| skeleton.ancestors(j).contains(&k)) {
            continue;
        }
        let s = pairs.side[j];
        if s.is_some() && out.iter().any(|&k| pairs.side[k] == s) {
            continue;
        }
        out.push(j);
    }
    out.sort_unstable();
    out
}

const NOT_A_FOOT: [&str; 5] = ["toe", "end", "site", "tip", "heel"];
const NOT_A_HAND: [&str; 9] = [
    "finger", "thumb", "index", "middle", "ring", "pinky", "end", "site", "tip",
];

/// The ankle joints: named `*ankle*`, else `*foot*` (not toes/ends); else the
/// first joint above each low leaf whose bone points mostly downwards.
pub fn feet(skeleton: &Skeleton) -> Vec<usize> {
    let pairs = Pairs::from_names(skeleton);
    let named = |word: &str| -> Vec<usize> {
        (1..skeleton.len())
            .filter(|&j| {
                let n = lower_name(skeleton, j);
                n.contains(word) && !NOT_A_FOOT.iter().any(|x| n.contains(x))
            })
            .collect()
    };
    let mut c = named("ankle");
    if c.is_empty() {
        c = named("foot");
    }
    if !c.is_empty() {
        return one_per_side(skeleton, &pairs, c);
    }
    // Structural fallback: leaves well below the root, walked up to the ankle.
    let rest = skeleton.rest_positions();
    let height = skeleton.rest_height().max(1e-9);
    let mut out = Vec::new();
    for leaf in 1..skeleton.len() {
        if skeleton.children(leaf).next().is_some() || rest[leaf].y > rest[0].y - 0.3 * height {
            continue;
        }
        let mut j = leaf;
        while let Some(p) = skeleton.parent(j) {
            let o = skeleton.joint(j).offset;
            if o.length() > 0.05 * height && -o.y > 0.7 * o.length() {
                out.push(j);
                break;
            }
            j = p;
        }
    }
    out.sort_unstable();
    out.dedup();
    one_per_side(skeleton, &pairs, out)
}

/// The wrist joints: named `*wrist*`, else `*hand*` (not fingers/ends).
pub fn hands(skeleton: &Skeleton) -> Vec<usize> {
    let pairs = Pairs::from_names(skeleton);
    let named = |word: &str| -> Vec<usize> {
        (1..skeleton.len())
            .filter(|&j| {
                let n = lower_name(skeleton, j);
                n.contains(word) && !NOT_A_HAND.iter().any(|x| n.contains(x))
            })
            .collect()
    };
    let mut c = named("wrist");
    if c.is_empty() {
        c = named("hand");
    }
    one_per_side(skeleton, &pairs, c)
}

/// Joints of the lower body: each foot's ancestors below the lowest common
/// ancestor of all feet (the pelvis/root), plus everything below the feet.
pub fn lower_body(skeleton: &Skeleton) -> Result<Vec<usize>, SynthError> {
    let feet = feet(skeleton);
    if feet.is_empty() {
        return Err(SynthError::Skeleton(
            "no feet found (no joint named *ankle* or *foot*, no low leaf chain)".into(),
        ));
    }
    let chains: Vec<Vec<usize>> = feet.iter().map(|&f| skeleton.ancestors(f)).collect();
    let common: Vec<usize> = chains[0]
        .iter()
        .copied()
        .filter(|j| chains.iter().all(|c| c.contains(j)))
        .collect();
    let mut mask = vec![false; skeleton.len()];
    for chain in &chains {
        for &j in chain {
            if !common.contains(&j) {
                mask[j] = true;
            }
        }
    }
    // With a single foot the common ancestors are its own chain: keep up to the
    // first joint that has another child chain (the pelvis).
    if feet.len() == 1 {
        for &j in &chains[0] {
            if skeleton.children(j).count() > 1 || skeleton.parent(j).is_none() {
                break;
            }
            mask[j] = true;
        }
    }
    for j in 1..skeleton.len() {
        if let Some(p) = skeleton.parent(j)
            && mask[p]
        {
            mask[j] = true;
        }
    }
    Ok((0..skeleton.len()).filter(|&j| mask[j]).collect())
}

/// Pick the joint of a list on a given side, if the side is known.
pub fn on_side(pairs: &Pairs, joints: &[usize], side: Side) -> Option<usize> {
    joints
        .iter()
        .copied()
        .find(|&j| pairs.side[j] == Some(side))
}
