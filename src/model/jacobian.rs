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

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::Model;
use super::observe::{WanderDerivative, Whitener};
use super::rotation::left_jacobian;

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
    fn new(np: usize) -> Self {
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
        let sig = &self.signals;
        let mut sums = PrefixSums::new(self.n_params());
        // From the anchor when nothing free acts before it, else from the start.
        let (first, q0, p0, phi) = match self.anchor_for(theta) {
            Some(a) if self.anchor_holds(free) => (a.row, a.q, a.p, Vector3::zeros()),
            _ => {
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
        let (f, f_parts) = self.forward_axis(theta);
        let mut k = 0;
        let mut visit = |row: usize, p: &Vector3<f64>, delta: &Vector3<f64>, sums: &PrefixSums| {
            if k < rows.len() && rows[k] == row {
                at_row(row, p, delta, sums);
                while k < rows.len() && rows[k] == row {
                    k += 1;
                }
            }
        };
        visit(first, &p0, &Vector3::zeros(), &sums);
        let mut chain = vec![Vector3::zeros(); self.gyro_chain.len() + 1];
        let mut dchain = vec![0.0; self.distance_chain.len() + 1];
        let mut q = q0;
        let mut p = p0;
        let inc = self.spec.increment;
        for j in first + 1..self.horizon() {
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
            visit(j, &p, &delta, &sums);
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
