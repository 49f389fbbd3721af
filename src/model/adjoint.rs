//! The analytic gradient in O(N): one forward sweep, one backward sweep.
//!
//! This is the paper's eq. 12-20 written as suffix sums. With
//! `g_k = d C / d p_{i_k}` (the weighted residuals of GPS row `k`, times 2):
//!
//! ```text
//! A_j = sum_{i_k >= j} g_k                 d C / d Delta_j (every later fix moves with step j)
//! B_j = sum_{t >= j} Delta_t x A_t         d C / d eps_j for a world rotation eps_j at step j,
//!                                          since it moves p_t by eps_j x (p_t - p_{j-1})
//! d C / d theta_j = J_j^T R_j^T B_j        J_j: right Jacobian of the increment
//! d C / d d_j     = A_j . (R_j f)
//! d C / d p_0 = A_0,   d C / d phi = J_l(phi)^T B_1
//! ```
//!
//! Both sums are accumulated from the end of the ride backwards, so the whole
//! gradient costs two passes instead of the naive O(N^2) chain rule. The
//! effects then map `d C / d omega_j` and `d C / d d_j` onto their parameters.

use nalgebra::Vector3;

use super::Model;
use super::rotation::left_jacobian;

impl Model {
    /// Cost and its gradient with respect to every parameter.
    pub fn gradient(&self, theta: &[f64]) -> (f64, Vec<f64>) {
        // The corrected signals with every chain stage kept: the path is built
        // from them and the back-propagation below needs the stage inputs.
        let (rates, rate_inputs) = self.corrected_rates(theta, true);
        let (dist, dist_inputs) = self.corrected_distances(theta, true);
        let path = self.trajectory_corrected(theta, &rates, &dist);
        let sig = &self.signals;
        let n = sig.len();
        let mut grad = vec![0.0; self.n_params()];
        let baro = self.baro_offset(theta);
        let obs = &self.observations;
        let mut cost = 0.0;
        let mut k = obs.len();
        let mut a = Vector3::zeros();
        let mut b = Vector3::zeros();
        // dC/d omega_j and dC/d d_j of the corrected signals, then back through the chains.
        let mut g_rate = vec![Vector3::zeros(); n];
        let mut g_dist = vec![0.0; n];
        let mut baro_grad = 0.0;

        // Add the residual gradient of every observation on `row` into `a`.
        let mut take_row = |row: usize, a: &mut Vector3<f64>, k: &mut usize, cost: &mut f64| {
            while *k > 0 && obs[*k - 1].row == row {
                *k -= 1;
                let o = &obs[*k];
                let target = if o.baro { o.target + baro } else { o.target };
                let r = o.w * (path.p[row][o.axis] - target);
                *cost += r * r;
                a[o.axis] += 2.0 * r * o.w;
                if o.baro {
                    baro_grad -= 2.0 * r * o.w;
                }
            }
        };

        for j in (1..n).rev() {
            take_row(j, &mut a, &mut k, &mut cost);
            let rot = path.q[j].to_rotation_matrix();
            let dir = super::rotation::forward(&path.q[j]);
            b += (dir * path.d[j]).cross(&a);
            // d C / d omega_j = dt_j J_j^T R_j^T B_j.
            let jr = self.spec.increment.right_jacobian(&path.theta[j]);
            g_rate[j] = jr.transpose() * (rot.transpose() * b) * sig.dt[j];
            g_dist[j] = a.dot(&dir);
        }
        take_row(0, &mut a, &mut k, &mut cost);
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
        if let Some(e) = self.baro {
            grad[self.offsets[e]] += baro_grad;
        }
        let prior = self.prior_rows(theta);
        for &(row, col, v) in &prior.entries {
            grad[col] += 2.0 * prior.residuals[row] * v;
        }
        cost += prior.residuals.iter().map(|r| r * r).sum::<f64>();
        (cost, grad)
    }
}
