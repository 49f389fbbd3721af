//! The Jacobian of the weighted residuals for Levenberg-Marquardt, built in one
//! forward sweep from prefix sums (not from one forward sweep per parameter).
//!
//! A parameter `c` acts on the path in two ways. At the gyro site (and the
//! initial orientation) a change turns step `j` by a world rotation `u_{j,c}`
//! (`= R_j J_j dt_j d omega_j / d c`), which moves every later position by
//! `u_{j,c} x (p_t - p_{j-1})`. At the distance site (and the initial position)
//! it changes `Delta_j` by `v_{j,c}`. So
//!
//! ```text
//! d p_t / d c = U_c(t) x p_t - V_c(t) + D_c(t)
//! U_c(t) = sum_{j <= t} u_{j,c},  V_c(t) = sum_{j <= t} u_{j,c} x p_{j-1},  D_c(t) = sum_{j <= t} v_{j,c}
//! ```
//!
//! The three prefix sums are updated only at the steps where `c` acts (a
//! segment bias only inside its segment), so building the whole matrix costs
//! O(N) plus one entry per (GPS row, parameter).

use nalgebra::{DMatrix, DVector, Matrix3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::observe::{WanderDerivative, Whitener};
use super::rotation::left_jacobian;
use super::{Anchor, Model};

/// Weighted residuals, their Jacobian with respect to the free parameters, and the cost.
#[derive(Clone, Debug)]
pub struct Linearisation {
    pub jacobian: DMatrix<f64>,
    pub residuals: DVector<f64>,
    pub cost: f64,
    /// Parameter index of each Jacobian column.
    pub columns: Vec<usize>,
}

/// The prefix sums `U_c`, `V_c`, `D_c` of every free parameter at the current row.
#[derive(Clone)]
pub(crate) struct PrefixSums {
    pub u: Vec<Vector3<f64>>,
    pub v: Vec<Vector3<f64>>,
    pub d: Vec<Vector3<f64>>,
    /// Free parameters that have acted so far, in the order they started.
    pub active: Vec<usize>,
    is_active: Vec<bool>,
    /// Increments `v_{j,c}` of `D_c` made at the current step (distance-site
    /// and forward-axis parameters), for observations interpolated inside it.
    pub step_d: Vec<(usize, Vector3<f64>)>,
}

impl PrefixSums {
    pub(crate) fn new(np: usize) -> Self {
        Self {
            u: vec![Vector3::zeros(); np],
            v: vec![Vector3::zeros(); np],
            d: vec![Vector3::zeros(); np],
            active: Vec::new(),
            is_active: vec![false; np],
            step_d: Vec::new(),
        }
    }

    #[inline]
    fn activate(&mut self, i: usize) {
        if !self.is_active[i] {
            self.is_active[i] = true;
            self.active.push(i);
        }
    }

    /// `dp_t / dc = U_c x p_t - V_c + D_c`.
    #[inline]
    pub fn dp(&self, i: usize, p: &Vector3<f64>) -> Vector3<f64> {
        self.u[i].cross(p) - self.v[i] + self.d[i]
    }

    /// Adds `other`'s sums parameter by parameter (its newly active ones
    /// join the active list; no step increments).
    fn add(&mut self, other: &PrefixSums) {
        for &i in &other.active {
            self.u[i] += other.u[i];
            self.v[i] += other.v[i];
            self.d[i] += other.d[i];
            self.activate(i);
        }
        self.step_d.clear();
    }

    /// `d x / d c` for a point `x = p_j - beta Delta_j` inside the current step `j`:
    /// `U_c x x - V_c + D_c - beta v_{j,c}` (the rotation terms are linear in the point).
    #[inline]
    pub fn dp_at(&self, i: usize, x: &Vector3<f64>, beta: f64) -> Vector3<f64> {
        let mut d = self.dp(i, x);
        if beta != 0.0 {
            for (c, v) in &self.step_d {
                if *c == i {
                    d -= v * beta;
                }
            }
        }
        d
    }
}

/// Rows per chunk (at least) of [`Model::prefix_sweep_chunked`]: a
/// 10-minute ride at 100 Hz is six chunks, 30 minutes or more sixteen
/// ([`MAX_PREFIX_CHUNKS`]), and rides under 20,000 rows (the real drives of
/// `../shared/real` have at most 12,000) one. Unit tests use short chunks so
/// that their short rides exercise the chaining.
pub(crate) const PREFIX_CHUNK_ROWS: usize = if cfg!(test) { 300 } else { 10_000 };
/// At most this many chunks: each holds the sums of every parameter (a
/// 6-hour ride's 13,000 segment biases: 1 MB a chunk).
const MAX_PREFIX_CHUNKS: usize = 16;

/// What the chunks of [`Model::prefix_sweep_chunked`] gathered, in order,
/// each with the prefix sums of its own steps.
pub(crate) struct Chunked<T> {
    pub chunks: Vec<(T, PrefixSums)>,
}

impl<T> Chunked<T> {
    /// Calls `each(c, before, gathered)` chunk by chunk in order, `before`
    /// the prefix sums of every chunk before `c` (what its own sums lack);
    /// returns the sums at the end of the sweep.
    pub fn each_with_before(
        self,
        np: usize,
        mut each: impl FnMut(usize, &PrefixSums, T),
    ) -> PrefixSums {
        let mut before = PrefixSums::new(np);
        for (c, (gathered, own)) in self.chunks.into_iter().enumerate() {
            each(c, &before, gathered);
            before.add(&own);
        }
        before
    }

    /// Per chunk the sums of the chunks before it (see [`Self::each_with_before`]).
    pub fn befores(self, np: usize) -> Vec<PrefixSums> {
        let mut out = Vec::with_capacity(self.chunks.len());
        self.each_with_before(np, |_, before, _| out.push(before.clone()));
        out
    }
}

/// Calls `at_row(row, ...)` if `row` is the next of `rows` not yet visited,
/// then moves `visited` past it.
#[inline]
fn visit_row(
    rows: &[usize],
    visited: &mut usize,
    row: usize,
    p: &Vector3<f64>,
    delta: &Vector3<f64>,
    sums: &PrefixSums,
    at_row: &mut impl FnMut(usize, &Vector3<f64>, &Vector3<f64>, &PrefixSums),
) {
    if rows.get(*visited) == Some(&row) {
        at_row(row, p, delta, sums);
        while rows.get(*visited) == Some(&row) {
            *visited += 1;
        }
    }
}

impl Model {
    /// One forward sweep that keeps the prefix sums of the parameters where
    /// `free` is true, calling `at_row(row, p_row, Delta_row, sums)` at every
    /// row where an observation of `rows` (non-decreasing) is evaluated, after
    /// the row's own step is included.
    pub(crate) fn prefix_sweep(
        &self,
        theta: &[f64],
        free: &[bool],
        rows: &[usize],
        mut at_row: impl FnMut(usize, &Vector3<f64>, &Vector3<f64>, &PrefixSums),
    ) {
        let (first, q0, p0, mut sums) = self.prefix_start(theta, free);
        let mut visited = rows.partition_point(|&r| r < first);
        visit_row(
            rows,
            &mut visited,
            first,
            &p0,
            &Vector3::zeros(),
            &sums,
            &mut at_row,
        );
        self.prefix_steps(
            theta,
            free,
            (first, self.horizon().saturating_sub(1)),
            (q0, p0),
            &mut sums,
            rows,
            &mut visited,
            &mut at_row,
        );
    }

    /// [`Model::prefix_sweep`] cut into chunks swept side by side. Chunk `c`
    /// covers the steps `bounds[c] + 1 ..= bounds[c + 1]` (the first also the
    /// start row) and starts from the attitude and position the path has there
    /// (one cheap parallel pass of eq. 1-4, as the cost sweep's chunks are
    /// chained) with its prefix sums at zero, or at `before[c]` where given
    /// (the sums of the chunks before it, from a first sweep, see
    /// [`Chunked::befores`]: the chunk's sums are then the ride's). Since every sum is a sum of
    /// per-step increments that do not depend on the sums themselves,
    ///
    /// ```text
    /// U_c(t) = U_c(a) + sum_{a < j <= t} u_{j,c}   (V_c and D_c alike)
    /// d p_t / d c = dp_chunk(c, t) + U_c(a) x p_t - V_c(a) + D_c(a)
    /// ```
    ///
    /// so a chunk's derivatives are its own plus an affine function of the
    /// point, given by the sums of the chunks before it
    /// ([`PrefixSums::dp`] of the `before` of [`Chunked::each_with_before`]).
    /// Returns, per chunk, what `at_row` gathered into a fresh `init(c)` and
    /// the chunk's sums at its end.
    /// Rides shorter than two chunks are swept in one, exactly as
    /// [`Model::prefix_sweep`] does; the cut depends only on the ride.
    pub(crate) fn prefix_sweep_chunked<T: Send>(
        &self,
        theta: &[f64],
        free: &[bool],
        rows: &[usize],
        before: Option<Vec<PrefixSums>>,
        init: impl Fn(usize) -> T + Sync,
        at_row: impl Fn(&mut T, usize, &Vector3<f64>, &Vector3<f64>, &PrefixSums) + Sync,
    ) -> Chunked<T> {
        let (first, q0, p0, start_sums) = self.prefix_start(theta, free);
        let bounds = self.prefix_bounds(first);
        let k = bounds.len() - 1;
        let starts = if k == 1 {
            vec![(q0, p0)]
        } else {
            self.states_at(theta, (first, q0, p0), &bounds)
        };
        // The first chunk starts from the start's sums, the others from
        // those given (or zero).
        let mut before = before.unwrap_or_default().into_iter();
        let mut start_sums = Some(start_sums);
        let chunk_sums: Vec<PrefixSums> = (0..k)
            .map(|_| {
                let given = before.next();
                start_sums
                    .take()
                    .or(given)
                    .unwrap_or_else(|| PrefixSums::new(self.n_params()))
            })
            .collect();
        let chunks: Vec<(T, PrefixSums)> = chunk_sums
            .into_par_iter()
            .enumerate()
            .map(|(c, mut sums)| {
                let mut out = init(c);
                // The first chunk also visits the rows before the start (none
                // are swept) and the start row itself.
                let from = if c == 0 { first } else { bounds[c] + 1 };
                let mut visited = rows.partition_point(|&r| r < from);
                let (q, p) = starts[c];
                let mut visit = |row: usize, p: &Vector3<f64>, d: &Vector3<f64>, s: &PrefixSums| {
                    at_row(&mut out, row, p, d, s)
                };
                if c == 0 {
                    visit_row(
                        rows,
                        &mut visited,
                        first,
                        &p,
                        &Vector3::zeros(),
                        &sums,
                        &mut visit,
                    );
                }
                self.prefix_steps(
                    theta,
                    free,
                    (bounds[c], bounds[c + 1]),
                    (q, p),
                    &mut sums,
                    rows,
                    &mut visited,
                    &mut visit,
                );
                (out, sums)
            })
            .collect();
        Chunked { chunks }
    }

    /// How many chunks [`Model::prefix_sweep_chunked`] cuts the ride into.
    pub(crate) fn prefix_chunk_count(&self, theta: &[f64], free: &[bool]) -> usize {
        self.prefix_bounds(self.prefix_first(theta, free)).len() - 1
    }

    /// Per chunk of [`Model::prefix_sweep_chunked`], the indices of `rows`
    /// (non-decreasing) that it visits.
    pub(crate) fn prefix_chunk_spans(
        &self,
        theta: &[f64],
        free: &[bool],
        rows: &[usize],
    ) -> Vec<std::ops::Range<usize>> {
        let first = self.prefix_first(theta, free);
        let bounds = self.prefix_bounds(first);
        let last = self.horizon().saturating_sub(1);
        (0..bounds.len() - 1)
            .map(|c| {
                let from = if c == 0 { first } else { bounds[c] + 1 };
                let to = bounds[c + 1].min(last);
                rows.partition_point(|&r| r < from)..rows.partition_point(|&r| r <= to)
            })
            .collect()
    }

    /// The chunks' bounds of a chunked sweep from row `first` (see
    /// [`Model::prefix_sweep_chunked`]).
    fn prefix_bounds(&self, first: usize) -> Vec<usize> {
        let steps = self.horizon().saturating_sub(1).saturating_sub(first);
        let k = (steps / PREFIX_CHUNK_ROWS).clamp(1, MAX_PREFIX_CHUNKS);
        (0..=k).map(|c| first + steps * c / k).collect()
    }

    /// The row a prefix sweep starts at: the anchor's when nothing free
    /// acts before it, else 0.
    fn prefix_first(&self, theta: &[f64], free: &[bool]) -> usize {
        self.prefix_anchor(theta, free).map_or(0, |a| a.row)
    }

    /// The anchor a prefix sweep starts from: the model's, while `theta`
    /// keeps its values and nothing free acts before it.
    fn prefix_anchor(&self, theta: &[f64], free: &[bool]) -> Option<&Anchor> {
        self.anchor_for(theta).filter(|_| self.anchor_holds(free))
    }

    /// Where a prefix sweep starts at `theta` over the `free` parameters: the
    /// anchor (when nothing free acts before it) or row 0, its attitude and
    /// position, and the sums there (the initial position's and orientation's
    /// derivatives when the sweep starts at row 0).
    fn prefix_start(
        &self,
        theta: &[f64],
        free: &[bool],
    ) -> (usize, UnitQuaternion<f64>, Vector3<f64>, PrefixSums) {
        let mut sums = PrefixSums::new(self.n_params());
        let (first, q0, p0, phi) = match self.prefix_anchor(theta, free) {
            Some(a) => (a.row, a.q, a.p, Vector3::zeros()),
            None => {
                let (q, p, phi) = self.initial_state(theta);
                (0, q, p, phi)
            }
        };
        if let Some(e) = self.position.filter(|_| first == 0) {
            for a in 0..3 {
                let i = self.offsets[e] + a;
                if free[i] {
                    sums.d[i][a] = 1.0;
                    sums.activate(i);
                }
            }
        }
        if let Some(e) = self.orientation.filter(|_| first == 0) {
            let jl = left_jacobian(&phi);
            for a in 0..3 {
                let i = self.offsets[e] + a;
                if free[i] {
                    sums.u[i] = jl.column(a).into_owned();
                    sums.v[i] = sums.u[i].cross(&p0);
                    sums.activate(i);
                }
            }
        }
        (first, q0, p0, sums)
    }

    /// Attitude and position at each of `bounds` but the last (non-decreasing
    /// rows from `first`), by eq. 1-4 integrated chunk by chunk from the
    /// identity side by side and chained (`q_b = q_a r`, `p_b = p_a + q_a s`),
    /// as [`Model::forward`] does.
    fn states_at(
        &self,
        theta: &[f64],
        (first, q0, p0): (usize, UnitQuaternion<f64>, Vector3<f64>),
        bounds: &[usize],
    ) -> Vec<(UnitQuaternion<f64>, Vector3<f64>)> {
        let sig = &self.signals;
        let (f, _) = self.forward_axis(theta);
        let inc = self.spec.increment;
        // The last chunk's own end is no chunk's start.
        let ends: Vec<(UnitQuaternion<f64>, Vector3<f64>)> = bounds[..bounds.len() - 1]
            .windows(2)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|w| {
                let (a, b) = (w[0], w[1]);
                let rates = self.corrected_rates(theta, (a + 1, b + 1), false).0;
                let dist = self.corrected_distances(theta, (a + 1, b + 1), false).0;
                let mut r = UnitQuaternion::identity();
                let mut s = Vector3::zeros();
                for j in a + 1..=b {
                    r *= inc.quaternion(&(rates[j - a - 1] * sig.dt[j]));
                    s += r * (f * dist[j - a - 1]);
                }
                (r, s)
            })
            .collect();
        debug_assert_eq!(bounds.first(), Some(&first));
        let (mut q, mut p) = (q0, p0);
        let mut out = Vec::with_capacity(ends.len() + 1);
        for (r, s) in ends {
            out.push((q, p));
            p += q * s;
            q *= r;
        }
        out.push((q, p));
        out
    }

    /// Steps `from + 1 ..= to` from the attitude `q` and position `p` at row
    /// `from`, adding each step's increments to `sums` and calling `at_row`
    /// at the rows of `rows` from index `visited` on (once per row).
    #[allow(clippy::too_many_arguments)]
    fn prefix_steps(
        &self,
        theta: &[f64],
        free: &[bool],
        (from, to): (usize, usize),
        (q0, p0): (UnitQuaternion<f64>, Vector3<f64>),
        sums: &mut PrefixSums,
        rows: &[usize],
        visited: &mut usize,
        at_row: &mut impl FnMut(usize, &Vector3<f64>, &Vector3<f64>, &PrefixSums),
    ) {
        let sig = &self.signals;
        let (f, f_parts) = self.forward_axis(theta);
        let mut chain = vec![Vector3::zeros(); self.gyro_chain.len() + 1];
        let mut dchain = vec![0.0; self.distance_chain.len() + 1];
        let mut q = q0;
        let mut p = p0;
        let inc = self.spec.increment;
        for j in from + 1..(to + 1).min(self.horizon()) {
            chain[0] = sig.gyro[j];
            for (i, &e) in self.gyro_chain.iter().enumerate() {
                chain[i + 1] = self.effects[e].gyro(self.params_of(e, theta), j, chain[i]);
            }
            let th = chain[self.gyro_chain.len()] * sig.dt[j];
            q *= inc.quaternion(&th);
            let rot = q.to_rotation_matrix();
            let dir = rot * f;
            sums.step_d.clear();
            // World rotation per unit change of the final rate, then back through the gyro chain.
            let mut down: Matrix3<f64> = rot.matrix() * inc.right_jacobian(&th) * sig.dt[j];
            for (i, &e) in self.gyro_chain.iter().enumerate().rev() {
                let part = self.effects[e].gyro_partials(self.params_of(e, theta), j, &chain[i]);
                for &(c, col) in part.params.as_slice() {
                    let idx = self.offsets[e] + c;
                    if free[idx] {
                        let w = down * col;
                        sums.u[idx] += w;
                        sums.v[idx] += w.cross(&p);
                        sums.activate(idx);
                    }
                }
                down *= part.d_in;
            }
            dchain[0] = sig.distance[j];
            for (i, &e) in self.distance_chain.iter().enumerate() {
                dchain[i + 1] = self.effects[e].distance(self.params_of(e, theta), j, dchain[i]);
            }
            let d = dchain[self.distance_chain.len()];
            let mut scale = 1.0;
            for (i, &e) in self.distance_chain.iter().enumerate().rev() {
                let part =
                    self.effects[e].distance_partials(self.params_of(e, theta), j, dchain[i]);
                for &(c, dv) in part.params.as_slice() {
                    let idx = self.offsets[e] + c;
                    if free[idx] {
                        let inc = dir * (scale * dv);
                        sums.d[idx] += inc;
                        sums.step_d.push((idx, inc));
                        sums.activate(idx);
                    }
                }
                scale *= part.d_in;
            }
            for &(idx, df) in &f_parts {
                if free[idx] {
                    let inc = rot * (df * d);
                    sums.d[idx] += inc;
                    sums.step_d.push((idx, inc));
                    sums.activate(idx);
                }
            }
            let delta = dir * d;
            p += delta;
            visit_row(rows, visited, j, &p, &delta, sums, at_row);
        }
    }

    /// Linearise the residuals at `theta` in the parameters where `free` is true.
    pub fn linearise(&self, theta: &[f64], free: &[bool]) -> Linearisation {
        let np = self.n_params();
        let columns = super::free_columns(&free[..np]);
        let mut col_of = vec![usize::MAX; np];
        for (c, &i) in columns.iter().enumerate() {
            col_of[i] = c;
        }
        let nr = self.n_residuals();
        let mut jac = DMatrix::<f64>::zeros(nr, columns.len());
        let mut res = DVector::<f64>::zeros(nr);
        let plan = self.obs_plan(theta);
        let obs = &self.observations;
        let sig = &self.signals;
        let mut k = 0;
        let mut white = Whitener::new(&plan, obs);
        // Per observation its slopes (own and previous); rows hold d x_k / d theta until combined.
        let mut slopes = vec![(1.0, 0.0); obs.len()];
        self.prefix_sweep(theta, free, &plan.row, |row, p, delta, sums| {
            while k < obs.len() && plan.row[k] == row {
                let o = &obs[k];
                let beta = plan.beta[k];
                let x = plan.position(k, p, delta);
                let v = white.value(k, x[o.axis]);
                res[k] = v.r;
                slopes[k] = (v.slope, v.back);
                for &i in &sums.active {
                    jac[(k, col_of[i])] = sums.dp_at(i, &x, beta)[o.axis];
                }
                plan.for_extra(k, o.axis, delta, sig.dt[row], |i, d| {
                    if col_of[i] != usize::MAX {
                        jac[(k, col_of[i])] += d;
                    }
                });
                k += 1;
            }
        });
        // d r_k = slope_k d x_k + back_k d z_prev, in order, carrying the
        // filtered wander's rows d z_k = alpha_k d z_prev + kappa_k d x_k.
        let mut wander = WanderDerivative::<DVector<f64>>::new(&plan.links);
        for (k, &(slope, back)) in slopes.iter().enumerate() {
            let link = plan.links[k];
            let dz_prev = wander.take_prev(&plan.links, k);
            wander.record(k, || {
                let dx = jac.row(k).transpose() * link.kappa;
                match &dz_prev {
                    Some(dz) => dx + dz * link.alpha,
                    None => dx,
                }
            });
            jac.row_mut(k).scale_mut(slope);
            if let Some(dz) = dz_prev {
                for c in 0..columns.len() {
                    jac[(k, c)] += back * dz[c];
                }
            }
        }

        let prior = self.prior_rows(theta);
        let base = obs.len();
        for (r, &val) in prior.residuals.iter().enumerate() {
            res[base + r] = val;
        }
        for &(r, c, val) in &prior.entries {
            if col_of[c] != usize::MAX {
                jac[(base + r, col_of[c])] += val;
            }
        }
        let cost = res.norm_squared();
        Linearisation {
            jacobian: jac,
            residuals: res,
            cost,
            columns,
        }
    }
}
