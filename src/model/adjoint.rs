//! The analytic gradient in O(N): one forward sweep, one backward sweep.
//!
//! This is the paper's eq. 12-20 written as suffix sums. With
//! `g_k = d C / d p_{i_k}` (`2 r dr / dx` summed over the residuals that see
//! fix `k`: its own and, with correlated GPS errors, the next fix's whitened one):
//!
//! ```text
//! A_j = sum_{i_k >= j} g_k                 d C / d Delta_j (every later fix moves with step j)
//! B_j = sum_{t >= j} Delta_t x A_t         d C / d eps_j for a world rotation eps_j at step j,
//!                                          since it moves p_t by eps_j x (p_t - p_{j-1})
//! d C / d theta_j = J_j^T R_j^T B_j        J_j: right Jacobian of the increment
//! d C / d d_j     = A_j . (R_j f)
//! d C / d p_0 = A_0,   d C / d phi = J_l(phi)^T B_1
//! d C / d m       = sum_j A_j . (R_j (d f / d m) d_j)   forward-axis parameters (dir_j = R_j f)
//! ```
//!
//! An observation interpolated inside step `j` (GPS lag, see `observe`) puts
//! `(1 - beta) g` on `p_j` and `beta g` on `p_{j-1}`; lag and target-shift
//! parameters get their partials directly.
//!
//! Both sums are accumulated from the end of the ride backwards, so the whole
//! gradient costs two passes instead of the naive O(N^2) chain rule. The
//! effects then map `d C / d omega_j` and `d C / d d_j` onto their parameters.

use nalgebra::Vector3;

use super::Model;
use super::observe::Whitener;
use super::rotation::left_jacobian;

impl Model {
    /// Cost and its gradient with respect to every parameter.
    pub fn gradient(&self, theta: &[f64]) -> (f64, Vec<f64>) {
        // The corrected signals with every chain stage kept: the path is built
        // from them and the back-propagation below needs the stage inputs.
        let rows = (0, self.horizon());
        let (rates, rate_inputs) = self.corrected_rates(theta, rows, true);
        let (dist, dist_inputs) = self.corrected_distances(theta, rows, true);
        let plan = self.obs_plan(theta);
        // Attitude at every row, positions where the observations look.
        let path = self.forward(
            theta,
            self.start_of_ride(theta),
            Some((&rates, &dist)),
            &plan.row,
            true,
        );
        let sig = &self.signals;
        let n = self.horizon();
        let mut grad = vec![0.0; self.n_params()];
        let (f, f_parts) = self.forward_axis(theta);
        let obs = &self.observations;
        let mut cost = 0.0;
        let mut k = obs.len();
        let mut a = Vector3::zeros();
        let mut b = Vector3::zeros();
        // The share of observations interpolated inside step j + 1 that falls on p_j.
        let mut pending = Vector3::zeros();
        // dC/d omega_j and dC/d d_j of the corrected signals, then back through the chains.
        let mut g_rate = vec![Vector3::zeros(); n];
        let mut g_dist = vec![0.0; n];

        // d C / d x_k of every observation: 2 r_k on its own x and, through
        // the filtered wander the later residuals subtract, on theirs (see
        // `noise`): backwards, `g_z` the cost's derivative by `z_k`.
        let values = Whitener::new(&plan, obs)
            .all((0..obs.len()).map(|k| plan.x(k, obs[k].axis, &path.p[k], &path.delta[k])));
        let mut g_x = vec![0.0; obs.len()];
        let mut g_z = vec![0.0; obs.len()];
        for (k, v) in values.iter().enumerate().rev() {
            cost += v.r * v.r;
            let link = plan.links[k];
            g_x[k] = 2.0 * v.r * v.slope + g_z[k] * link.kappa;
            if let Some(j) = link.prev {
                g_z[j] += 2.0 * v.r * v.back + g_z[k] * link.alpha;
            }
        }

        // Add the residual gradient of every observation evaluated in step `row`:
        // x = p_row - beta Delta_row = (1 - beta) p_row + beta p_{row-1}.
        let take_row = |row: usize,
                        a: &mut Vector3<f64>,
                        pending: &mut Vector3<f64>,
                        k: &mut usize,
                        grad: &mut [f64]| {
            *a += std::mem::take(pending);
            while *k > 0 && plan.row[*k - 1] == row {
                *k -= 1;
                let o = &obs[*k];
                let delta = path.delta[*k];
                let g = g_x[*k];
                let beta = plan.beta[*k];
                a[o.axis] += g * (1.0 - beta);
                pending[o.axis] += g * beta;
                plan.for_extra(*k, o.axis, &delta, sig.dt[row], |i, d| grad[i] += g * d);
            }
        };

        // Chunk by chunk, last first, in the chunk's own frame: with
        // q_j = q_a r_j, `A' = q_a^-1 A` and `B' = q_a^-1 B` follow the same
        // recursion with the relative attitudes r_j (rotations keep cross and
        // dot products), so no row needs q_a r_j.
        for (qa, from, rs) in path.chunks.iter().rev() {
            let to_chunk = qa.inverse();
            let mut a_rel = to_chunk * a;
            let mut b_rel = to_chunk * b;
            for (i, r) in rs.iter().enumerate().rev() {
                let j = from + i;
                if pending != Vector3::zeros() || (k > 0 && plan.row[k - 1] == j) {
                    let mut add = Vector3::zeros();
                    take_row(j, &mut add, &mut pending, &mut k, &mut grad);
                    a_rel += to_chunk * add;
                }
                let th = rates[j] * sig.dt[j];
                let rot = r.to_rotation_matrix();
                let dir = rot * f;
                let d = dist[j];
                b_rel += (dir * d).cross(&a_rel);
                // d C / d omega_j = dt_j J_j^T R_j^T B_j.
                g_rate[j] = self
                    .spec
                    .increment
                    .right_jacobian_transpose_mul(&th, &(rot.transpose() * b_rel))
                    * sig.dt[j];
                g_dist[j] = a_rel.dot(&dir);
                // d Delta_j / d m = R_j (d f / d m) d_j for the forward-axis parameters.
                for &(i, df) in &f_parts {
                    grad[i] += a_rel.dot(&(rot * df)) * d;
                }
            }
            a = qa * a_rel;
            b = qa * b_rel;
        }
        take_row(0, &mut a, &mut pending, &mut k, &mut grad);
        for (i, &e) in self.gyro_chain.iter().enumerate().rev() {
            let r = self.range(e);
            self.effects[e].gyro_backward(
                self.params_of(e, theta),
                &rate_inputs[i],
                &mut g_rate,
                &mut grad[r],
            );
        }
        for (i, &e) in self.distance_chain.iter().enumerate().rev() {
            let r = self.range(e);
            self.effects[e].distance_backward(
                self.params_of(e, theta),
                &dist_inputs[i],
                &mut g_dist,
                &mut grad[r],
            );
        }

        if let Some(e) = self.position {
            for i in 0..3 {
                grad[self.offsets[e] + i] += a[i];
            }
        }
        if let Some(e) = self.orientation {
            let (_, _, phi) = self.initial_state(theta);
            let g = left_jacobian(&phi).transpose() * b;
            for i in 0..3 {
                grad[self.offsets[e] + i] += g[i];
            }
        }
        let prior = self.prior_rows(theta);
        for &(row, col, v) in &prior.entries {
            grad[col] += 2.0 * prior.residuals[row] * v;
        }
        cost += prior.residuals.iter().map(|r| r * r).sum::<f64>();
        (cost, grad)
    }
}
