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
use nalgebra::{DMatrix, Dyn, linalg::Cholesky};
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

/// Buffers reused from frame to frame, and the contact anchors carried over.
struct Work {
    neighbours: Vec<(usize, f64)>,
    /// Horizontal target of each foot term, set where its contact starts.
    anchors: Vec<DVec3>,
    /// Swinging sole points of the frame and their reference heights.
    swing: Vec<(usize, f64)>,
}

/// A frame's normal equations `m x = rhs` (one right-hand side per axis).
struct System {
    m: DMatrix<f64>,
    rhs: Vec<DVec3>,
}

impl System {
    /// The term `w |x_a - x_b - ...|^2`'s matrix part.
    fn add_diff(&mut self, a: usize, b: usize, w: f64) {
        self.m[(a, a)] += w;
        self.m[(b, b)] += w;
        self.m[(a, b)] -= w;
        self.m[(b, a)] -= w;
    }
}

impl Problem {
    fn n(&self) -> usize {
        self.n_a + self.n_b
    }

    fn body(&self, i: usize) -> usize {
        usize::from(i >= self.n_a)
    }

    /// Solve every frame; returns positions `[frame][point]`.
    ///
    /// Per frame: the prediction from the previous solution, the linear system
    /// of the energy (factorised once), then the local/global iterations.
    pub fn solve(&self, o: &SolverOptions) -> Result<(Vec<DVec3>, SolveStats), InteractionError> {
        o.validate()?;
        let n = self.n();
        let mut out: Vec<DVec3> = Vec::with_capacity(self.frames * n);
        let mut stats = SolveStats::default();
        let mut work = Work {
            neighbours: Vec::new(),
            anchors: vec![DVec3::ZERO; self.feet.len()],
            swing: Vec::new(),
        };
        for t in 0..self.frames {
            let prev: Option<&[DVec3]> = (t > 0).then(|| &out[(t - 1) * n..t * n]);
            let predicted = self.predicted(t, prev);
            let system = self.system(t, o, &predicted, prev.is_some(), &mut work);
            let chol = Cholesky::new(system.m).ok_or_else(|| InteractionError::Solver {
                frame: t,
                message: "system matrix is not positive definite".into(),
            })?;
            let (x, used) = self.iterate(t, o, &chol, &system.rhs, &work.swing, predicted)?;
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

    /// Frame `t`'s starting point: the reference, or the previous solution
    /// `prev` moved by the reference's motion.
    fn predicted(&self, t: usize, prev: Option<&[DVec3]>) -> Vec<DVec3> {
        let n = self.n();
        let refp = &self.reference[t * n..(t + 1) * n];
        match prev {
            None => refp.to_vec(),
            Some(p) => {
                let r0 = &self.reference[(t - 1) * n..t * n];
                (0..n).map(|i| p[i] + refp[i] - r0[i]).collect()
            }
        }
    }

    /// The normal equations of frame `t`'s energy without the rod and swing
    /// projections (those change every iteration); `temporal`: there is a
    /// previous frame to be smooth with.
    fn system(
        &self,
        t: usize,
        o: &SolverOptions,
        predicted: &[DVec3],
        temporal: bool,
        work: &mut Work,
    ) -> System {
        let n = self.n();
        let src = &self.source[t * n..(t + 1) * n];
        let refp = &self.reference[t * n..(t + 1) * n];
        let mut sys = System {
            m: DMatrix::<f64>::zeros(n, n),
            rhs: vec![DVec3::ZERO; n],
        };
        self.add_laplacian(&mut sys, src, refp, o, &mut work.neighbours);
        for r in &self.rods {
            sys.add_diff(r.a, r.b, o.rod);
        }
        for p in &self.pairs {
            let w = o.key_pair * p.weight[t];
            if w > 0.0 {
                sys.add_diff(p.a, p.b, w);
                let target = src[p.a] - src[p.b];
                sys.rhs[p.a] += w * target;
                sys.rhs[p.b] -= w * target;
            }
        }
        self.add_feet(&mut sys, t, refp, predicted, o, work);
        for i in 0..n {
            sys.m[(i, i)] += o.anchor;
            sys.rhs[i] += o.anchor * refp[i];
            if temporal {
                sys.m[(i, i)] += o.temporal;
                sys.rhs[i] += o.temporal * predicted[i];
            }
        }
        sys
    }

    /// Laplacian rows: `x_i - sum_j w_ij x_j = delta_i`, weighted more where
    /// the partner is close.
    fn add_laplacian(
        &self,
        sys: &mut System,
        src: &[DVec3],
        refp: &[DVec3],
        o: &SolverOptions,
        neighbours: &mut Vec<(usize, f64)>,
    ) {
        for i in 0..self.n() {
            self.neighbours(src, i, o, neighbours);
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
            for &(j, w) in neighbours.iter() {
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
                sys.rhs[a] += lam * ca * delta;
                for &(b, cb) in &row {
                    sys.m[(a, b)] += lam * ca * cb;
                }
            }
        }
    }

    /// Planted sole points held at their contact anchor (set where a contact
    /// starts), swinging ones listed in `work.swing` for the local step.
    fn add_feet(
        &self,
        sys: &mut System,
        t: usize,
        refp: &[DVec3],
        predicted: &[DVec3],
        o: &SolverOptions,
        work: &mut Work,
    ) {
        work.swing.clear();
        for (f, anchor) in self.feet.iter().zip(work.anchors.iter_mut()) {
            let i = f.point;
            if !f.contact[t] {
                // Swing: keep at least the reference clearance, so a body
                // pulled down does not drag a swinging sole into ground contact
                // while it still moves. Height only, one-sided: projected in
                // the local step.
                if o.swing > 0.0 {
                    sys.m[(i, i)] += o.swing;
                    work.swing.push((i, refp[i].y));
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
            sys.m[(i, i)] += o.foot;
            sys.rhs[i] += o.foot * target;
        }
    }

    /// Local/global iterations of frame `t` from `x` until no point moves more
    /// than the tolerance; returns the positions and the iterations used.
    fn iterate(
        &self,
        t: usize,
        o: &SolverOptions,
        chol: &Cholesky<f64, Dyn>,
        rhs: &[DVec3],
        swing: &[(usize, f64)],
        mut x: Vec<DVec3>,
    ) -> Result<(Vec<DVec3>, usize), InteractionError> {
        let n = self.n();
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
            for &(i, y) in swing {
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
        Ok((x, used))
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
