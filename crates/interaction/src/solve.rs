//! The per-frame interaction-mesh optimiser, in point positions.
//!
//! This is the spatial-relationship-preserving deformation of Ho, Komura and
//! Tai, "Spatial relationship preserving character motion adaptation" (ACM TOG
//! 29(4), SIGGRAPH 2010), solved frame by frame instead of as one space-time
//! system, with the bone-length constraint handled the way Projective Dynamics
//! handles springs (Bouaziz, Martin, Liu, Kavan, Pauly, "Projective Dynamics:
//! fusing constraint projections for fast simulation", ACM TOG 33(4), 2014):
//! alternate a *local* step that projects every rod onto its rest length along
//! its current direction with a *global* step that solves one sparse-in-spirit
//! (dense, ~60 unknowns) linear least-squares system whose matrix does not change
//! within the frame, so it is factorised once (Cholesky) per frame and each
//! iteration costs three triangular solves.
//!
//! Energy of frame t over the points x of both bodies (metres):
//!
//! * **Interaction mesh** (Laplacian coordinates): each point's neighbours are
//!   its `k_same` nearest points of its own body and its `k_other` nearest of
//!   the partner, in the *source* frame (a k-nearest-neighbour graph standing in
//!   for the paper's Delaunay tetrahedralisation), weighted `1/(d^2 + eps^2)` and
//!   normalised. The target Laplacian coordinate is `sum_j w_ij e_ij` with
//!   `e_ij` the source vector between the points for cross-body neighbours (the
//!   spatial relation to keep) and the *reference* vector for same-body ones
//!   (the naively scaled body for B: it carries the new proportions). A point's
//!   term is weighted more the closer the partner is: `1 + boost exp(-(d/r)^2)`.
//! * **Rods** (bone lengths and rigid sets, [`crate::layout`]): `|x_a - x_b| = l`.
//! * **Key joint pairs**: the source vector between the two points is kept
//!   (so their distance is kept), with a weight ramping in and out around the
//!   contact stretch.
//! * **Planted feet**: a sole point in contact in the reference stays at its
//!   reference height and, while contact lasts, at the horizontal position
//!   it had when the contact began (no skating, and no slow drift). Out of
//!   contact it is kept (weight `swing`) at least at its reference height, its
//!   horizontal position left free (a one-sided projection in the local step,
//!   like the rods): a body pulled down cannot drag it into ground contact.
//! * **Temporal smoothness**: each point moves from its solved previous position
//!   by the reference's velocity (warm start and damping in one).
//! * **Anchor**: a weak pull to the reference, fixing the translation the
//!   Laplacian does not see.

use glam::DVec3;
use nalgebra::{DMatrix, linalg::Cholesky};
use serde::{Deserialize, Serialize};

use crate::InteractionError;
use crate::layout::Rod;

/// Weights and graph settings of the energy (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SolverOptions {
    pub k_same: usize,
    pub k_other: usize,
    /// Softening of the inverse-square neighbour weights, metres.
    pub eps_m: f64,
    pub laplacian: f64,
    pub close_boost: f64,
    pub close_radius_m: f64,
    pub rod: f64,
    pub key_pair: f64,
    pub foot: f64,
    /// Weight holding a sole point out of contact at its reference height.
    pub swing: f64,
    pub temporal: f64,
    pub anchor: f64,
    /// Local/global iterations per frame (the first frame gets four times as many).
    pub iterations: usize,
    /// Stop a frame's iterations once no point moves more than this, metres.
    pub tolerance_m: f64,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            k_same: 5,
            k_other: 4,
            eps_m: 0.05,
            laplacian: 1.0,
            close_boost: 4.0,
            close_radius_m: 0.3,
            rod: 100.0,
            key_pair: 30.0,
            foot: 100.0,
            swing: 10.0,
            temporal: 0.5,
            anchor: 0.05,
            iterations: 120,
            tolerance_m: 1e-5,
        }
    }
}

impl SolverOptions {
    pub fn validate(&self) -> Result<(), InteractionError> {
        let bad =
            |field: &'static str, message: String| Err(InteractionError::Option { field, message });
        let weights = [
            ("eps_m", self.eps_m),
            ("laplacian", self.laplacian),
            ("close_boost", self.close_boost),
            ("close_radius_m", self.close_radius_m),
            ("rod", self.rod),
            ("key_pair", self.key_pair),
            ("foot", self.foot),
            ("swing", self.swing),
            ("temporal", self.temporal),
            ("anchor", self.anchor),
            ("tolerance_m", self.tolerance_m),
        ];
        for (field, v) in weights {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("{v} is not a non-negative number"));
            }
        }
        if self.anchor <= 0.0 {
            return bad(
                "anchor",
                "must be positive (it fixes the global position)".into(),
            );
        }
        if self.eps_m <= 0.0 || self.close_radius_m <= 0.0 {
            return bad("eps_m", "softening and radius must be positive".into());
        }
        if self.k_same + self.k_other == 0 {
            return bad("k_same", "the graph needs at least one neighbour".into());
        }
        if self.iterations == 0 {
            return bad("iterations", "at least one iteration".into());
        }
        Ok(())
    }
}

/// A key pair constraint: points `a` (of A) and `b` (of B), global indices.
#[derive(Debug, Clone)]
pub struct PairTerm {
    pub a: usize,
    pub b: usize,
    /// Weight factor per frame in [0, 1] (0 = inactive).
    pub weight: Vec<f64>,
}

/// A sole point with its reference contact flags.
#[derive(Debug, Clone)]
pub struct FootTerm {
    pub point: usize,
    pub contact: Vec<bool>,
}

/// Everything the optimiser needs; points are A's then B's.
#[derive(Debug, Clone)]
pub struct Problem {
    pub frames: usize,
    pub n_a: usize,
    pub n_b: usize,
    /// Source positions `[frame][point]` (B unscaled).
    pub source: Vec<DVec3>,
    /// Reference positions `[frame][point]` (A source, B naive retarget).
    pub reference: Vec<DVec3>,
    /// Rods of both bodies (B's indices already offset by `n_a`).
    pub rods: Vec<Rod>,
    pub pairs: Vec<PairTerm>,
    pub feet: Vec<FootTerm>,
}

/// Solver statistics.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SolveStats {
    pub iterations_total: usize,
    pub iterations_max: usize,
    /// Largest |length - rest| over rods and frames before rotations are fitted, m.
    pub rod_residual_max_m: f64,
}

impl Problem {
    fn n(&self) -> usize {
        self.n_a + self.n_b
    }

    fn body(&self, i: usize) -> usize {
        usize::from(i >= self.n_a)
    }

    /// Solve every frame; returns positions `[frame][point]`.
    pub fn solve(&self, o: &SolverOptions) -> Result<(Vec<DVec3>, SolveStats), InteractionError> {
        o.validate()?;
        let n = self.n();
        let mut out: Vec<DVec3> = Vec::with_capacity(self.frames * n);
        let mut stats = SolveStats::default();
        let mut neighbours: Vec<(usize, f64)> = Vec::new();
        let mut anchors = vec![DVec3::ZERO; self.feet.len()];
        let mut swing: Vec<(usize, f64)> = Vec::new();
        for t in 0..self.frames {
            let src = &self.source[t * n..(t + 1) * n];
            let refp = &self.reference[t * n..(t + 1) * n];
            let prev: Option<&[DVec3]> = (t > 0).then(|| &out[(t - 1) * n..t * n]);
            let predicted: Vec<DVec3> = match prev {
                None => refp.to_vec(),
                Some(p) => {
                    let r0 = &self.reference[(t - 1) * n..t * n];
                    (0..n).map(|i| p[i] + refp[i] - r0[i]).collect()
                }
            };

            let mut m = DMatrix::<f64>::zeros(n, n);
            let mut rhs = vec![DVec3::ZERO; n];
            // Laplacian rows: x_i - sum_j w_ij x_j = delta_i.
            for i in 0..n {
                self.neighbours(src, i, o, &mut neighbours);
                if neighbours.is_empty() {
                    continue;
                }
                let other_min = neighbours
                    .iter()
                    .filter(|(j, _)| self.body(*j) != self.body(i))
                    .map(|(j, _)| (src[*j] - src[i]).length())
                    .fold(f64::INFINITY, f64::min);
                let lam = o.laplacian
                    * (1.0 + o.close_boost * (-(other_min / o.close_radius_m).powi(2)).exp());
                let mut delta = DVec3::ZERO;
                for &(j, w) in &neighbours {
                    let e = if self.body(j) == self.body(i) {
                        refp[i] - refp[j]
                    } else {
                        src[i] - src[j]
                    };
                    delta += w * e;
                }
                // row r: +1 at i, -w_j at j.
                let mut row: Vec<(usize, f64)> = Vec::with_capacity(neighbours.len() + 1);
                row.push((i, 1.0));
                row.extend(neighbours.iter().map(|&(j, w)| (j, -w)));
                for &(a, ca) in &row {
                    rhs[a] += lam * ca * delta;
                    for &(b, cb) in &row {
                        m[(a, b)] += lam * ca * cb;
                    }
                }
            }
            let add_diff = |m: &mut DMatrix<f64>, a: usize, b: usize, w: f64| {
                m[(a, a)] += w;
                m[(b, b)] += w;
                m[(a, b)] -= w;
                m[(b, a)] -= w;
            };
            for r in &self.rods {
                add_diff(&mut m, r.a, r.b, o.rod);
            }
            for p in &self.pairs {
                let w = o.key_pair * p.weight[t];
                if w > 0.0 {
                    add_diff(&mut m, p.a, p.b, w);
                    let target = src[p.a] - src[p.b];
                    rhs[p.a] += w * target;
                    rhs[p.b] -= w * target;
                }
            }
            swing.clear();
            for (f, anchor) in self.feet.iter().zip(anchors.iter_mut()) {
                let i = f.point;
                if !f.contact[t] {
                    // Swing: keep at least the reference clearance, so a body
                    // pulled down does not drag a swinging sole into ground contact
                    // while it still moves. Height only, one-sided: projected in
                    // the local step.
                    if o.swing > 0.0 {
                        m[(i, i)] += o.swing;
                        swing.push((i, refp[i].y));
                    }
                    continue;
                }
                // A contact's horizontal target is fixed when it starts: holding
                // the previous *solved* position instead lets the slip of every
                // frame add up whenever other terms pull on the body.
                if t == 0 || !f.contact[t - 1] {
                    *anchor = predicted[i];
                }
                let target = DVec3::new(anchor.x, refp[i].y, anchor.z);
                m[(i, i)] += o.foot;
                rhs[i] += o.foot * target;
            }
            for i in 0..n {
                m[(i, i)] += o.anchor;
                rhs[i] += o.anchor * refp[i];
                if prev.is_some() {
                    m[(i, i)] += o.temporal;
                    rhs[i] += o.temporal * predicted[i];
                }
            }
            let chol = Cholesky::new(m).ok_or_else(|| InteractionError::Solver {
                frame: t,
                message: "system matrix is not positive definite".into(),
            })?;

            // Local/global iterations.
            let mut x = predicted;
            let max_iter = if t == 0 {
                4 * o.iterations
            } else {
                o.iterations
            };
            let mut b = DMatrix::<f64>::zeros(n, 3);
            let mut used = 0;
            for _ in 0..max_iter {
                used += 1;
                for i in 0..n {
                    for c in 0..3 {
                        b[(i, c)] = rhs[i][c];
                    }
                }
                for r in &self.rods {
                    let d = x[r.a] - x[r.b];
                    let len = d.length();
                    let dir = if len > 1e-12 { d / len } else { DVec3::Y };
                    let p = o.rod * r.length * dir;
                    for c in 0..3 {
                        b[(r.a, c)] += p[c];
                        b[(r.b, c)] -= p[c];
                    }
                }
                for &(i, y) in &swing {
                    // Projection onto {height >= y}: only a sole that sinks is held.
                    let p = o.swing * DVec3::new(x[i].x, x[i].y.max(y), x[i].z);
                    for c in 0..3 {
                        b[(i, c)] += p[c];
                    }
                }
                let sol = chol.solve(&b);
                let mut moved = 0.0f64;
                for (i, xi) in x.iter_mut().enumerate() {
                    let v = DVec3::new(sol[(i, 0)], sol[(i, 1)], sol[(i, 2)]);
                    moved = moved.max((v - *xi).length());
                    *xi = v;
                }
                if !moved.is_finite() {
                    return Err(InteractionError::Solver {
                        frame: t,
                        message: "positions became non-finite".into(),
                    });
                }
                if moved < o.tolerance_m {
                    break;
                }
            }
            stats.iterations_total += used;
            stats.iterations_max = stats.iterations_max.max(used);
            for r in &self.rods {
                let e = ((x[r.a] - x[r.b]).length() - r.length).abs();
                stats.rod_residual_max_m = stats.rod_residual_max_m.max(e);
            }
            out.extend_from_slice(&x);
        }
        Ok((out, stats))
    }

    /// The weighted neighbours of point `i` in the source frame `src`.
    fn neighbours(&self, src: &[DVec3], i: usize, o: &SolverOptions, out: &mut Vec<(usize, f64)>) {
        out.clear();
        let mut same: Vec<(f64, usize)> = Vec::new();
        let mut other: Vec<(f64, usize)> = Vec::new();
        for (j, p) in src.iter().enumerate() {
            if j == i {
                continue;
            }
            let d2 = (*p - src[i]).length_squared();
            if self.body(j) == self.body(i) {
                same.push((d2, j));
            } else {
                other.push((d2, j));
            }
        }
        for (list, k) in [(&mut same, o.k_same), (&mut other, o.k_other)] {
            let k = k.min(list.len());
            if k == 0 {
                continue;
            }
            list.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            out.extend(
                list[..k]
                    .iter()
                    .map(|&(d2, j)| (j, 1.0 / (d2 + o.eps_m * o.eps_m))),
            );
        }
        let total: f64 = out.iter().map(|(_, w)| w).sum();
        if total > 0.0 {
            for (_, w) in out.iter_mut() {
                *w /= total;
            }
        }
    }
}
