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

impl Model {
    /// Linearise the residuals at `theta` in the parameters where `free` is true.
    pub fn linearise(&self, theta: &[f64], free: &[bool]) -> Linearisation {
        let sig = &self.signals;
        let np = self.n_params();
        let columns: Vec<usize> = (0..np).filter(|&i| free[i]).collect();
        let mut col_of = vec![usize::MAX; np];
        for (c, &i) in columns.iter().enumerate() {
            col_of[i] = c;
        }
        let nr = self.n_residuals();
        let mut jac = DMatrix::<f64>::zeros(nr, columns.len());
        let mut res = DVector::<f64>::zeros(nr);

        let mut u = vec![Vector3::zeros(); np];
        let mut v = vec![Vector3::zeros(); np];
        let mut dsum = vec![Vector3::zeros(); np];
        let mut active: Vec<usize> = Vec::new();
        let mut is_active = vec![false; np];
        let mut activate = |i: usize, active: &mut Vec<usize>| {
            if !is_active[i] {
                is_active[i] = true;
                active.push(i);
            }
        };

        let (q0, p0, phi) = self.initial_state(theta);
        if let Some(e) = self.position {
            for a in 0..3 {
                let i = self.offsets[e] + a;
                if free[i] {
                    dsum[i][a] = 1.0;
                    activate(i, &mut active);
                }
            }
        }
        if let Some(e) = self.orientation {
            let jl = left_jacobian(&phi);
            for a in 0..3 {
                let i = self.offsets[e] + a;
                if free[i] {
                    u[i] = jl.column(a).into_owned();
                    v[i] = u[i].cross(&p0);
                    activate(i, &mut active);
                }
            }
        }
        let baro_col = self.baro.map(|e| col_of[self.offsets[e]]);
        let baro = self.baro_offset(theta);
        let obs = &self.observations;
        let mut k = 0;
        let mut dp = vec![Vector3::zeros(); np];
        let mut chain = vec![Vector3::zeros(); self.gyro_chain.len() + 1];
        let mut dchain = vec![0.0; self.distance_chain.len() + 1];

        let mut emit = |row: usize,
                        p: &Vector3<f64>,
                        active: &[usize],
                        u: &[Vector3<f64>],
                        v: &[Vector3<f64>],
                        dsum: &[Vector3<f64>],
                        k: &mut usize| {
            if *k >= obs.len() || obs[*k].row != row {
                return;
            }
            for &i in active {
                dp[i] = u[i].cross(p) - v[i] + dsum[i];
            }
            while *k < obs.len() && obs[*k].row == row {
                let o = &obs[*k];
                let target = if o.baro { o.target + baro } else { o.target };
                res[*k] = o.w * (p[o.axis] - target);
                for &i in active {
                    jac[(*k, col_of[i])] = o.w * dp[i][o.axis];
                }
                if o.baro
                    && let Some(c) = baro_col.filter(|&c| c != usize::MAX)
                {
                    jac[(*k, c)] = -o.w;
                }
                *k += 1;
            }
        };

        emit(0, &p0, &active, &u, &v, &dsum, &mut k);
        let mut q = q0;
        let mut p = p0;
        let inc = self.spec.increment;
        for j in 1..sig.len() {
            chain[0] = sig.gyro[j];
            for (i, &e) in self.gyro_chain.iter().enumerate() {
                chain[i + 1] = self.effects[e].gyro(self.params_of(e, theta), j, chain[i]);
            }
            let th = chain[self.gyro_chain.len()] * sig.dt[j];
            q *= inc.quaternion(&th);
            let rot = q.to_rotation_matrix();
            let dir = rot * Vector3::x();
            // World rotation per unit change of the final rate.
            let mut down: Matrix3<f64> = rot.matrix() * inc.right_jacobian(&th) * sig.dt[j];
            for (i, &e) in self.gyro_chain.iter().enumerate().rev() {
                let part = self.effects[e].gyro_partials(self.params_of(e, theta), j, &chain[i]);
                for &(c, col) in part.params.as_slice() {
                    let idx = self.offsets[e] + c;
                    if free[idx] {
                        let w = down * col;
                        u[idx] += w;
                        v[idx] += w.cross(&p);
                        activate(idx, &mut active);
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
                        dsum[idx] += dir * (scale * dv);
                        activate(idx, &mut active);
                    }
                }
                scale *= part.d_in;
            }
            p += dir * d;
            emit(j, &p, &active, &u, &v, &dsum, &mut k);
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
