//! How sure the fit is of its parameters: 1-sigma uncertainties under the
//! fit's own noise model (GPS correlation, per-fix accuracy, robust weights,
//! priors), from the linearisation at the fitted parameters.
//!
//! `Cov(theta) = (J^T J + J_p^T J_p)^-1` with `J` the Jacobian of the whitened
//! residuals, widened by what correlation the whitened residuals still show
//! ([`Model::residual_inflation`]). The global parameters' block comes exactly
//! from the O(N) chain solver's final triangle, the segment biases' and the
//! path's from posterior draws of the same factorisation
//! ([`super::ChainSystem::posterior`]); a model without segment biases is
//! small enough for the dense normal equations.

use nalgebra::{DVector, Vector3};

use super::{Model, Posterior};
use crate::effects::Role;
use crate::optimisation::lm::damped_solve;

/// Longest lag (fixes) of the residual autocorrelation that widens the sigmas.
const MAX_LAG: usize = 120;

/// Posterior draws behind the segment-bias and path sigmas: a sigma from 40
/// draws is within about 11 % (1 / sqrt(2 k)) of its value.
pub const DRAWS: usize = 40;

/// Seed of the posterior draws the CLI and the app use: the same fit gives
/// the same sigmas.
pub const UNCERTAINTY_SEED: u64 = 1;

/// How sure the fit is of its path and its segment biases.
#[derive(Clone, Debug, Default)]
pub struct Uncertainty {
    /// 1-sigma of every parameter (internal units), `None` where not free.
    pub params: Vec<Option<f64>>,
    /// Per log row: variance of east, north, up (m^2) and the east-north covariance.
    pub path: Vec<[f64; 4]>,
}

impl Uncertainty {
    /// 1-sigma east, north, up (m) at row `j`.
    pub fn sigma_enu(&self, j: usize) -> [f64; 3] {
        let v = self.path.get(j).copied().unwrap_or([f64::NAN; 4]);
        [v[0].sqrt(), v[1].sqrt(), v[2].sqrt()]
    }

    /// The squared Mahalanobis distance of a horizontal error `(de, dn)` at
    /// row `j`: below 5.99 inside the 95 % ellipse.
    pub fn mahalanobis2(&self, j: usize, de: f64, dn: f64) -> f64 {
        let [ve, vn, _, c] = self.path.get(j).copied().unwrap_or([f64::NAN; 4]);
        let det = ve * vn - c * c;
        (vn * de * de - 2.0 * c * de * dn + ve * dn * dn) / det
    }
}

impl Model {
    /// The 1-sigma uncertainty of every parameter at `theta` (internal units)
    /// that step 2 fits; `None` for parameters held fixed, for the constant
    /// bias (step 2 leaves it to the segments: the two are one direction) and
    /// for the segment biases (their sigmas need posterior draws, see
    /// [`Self::uncertainty`]).
    pub fn parameter_sigmas(&self, theta: &[f64]) -> Vec<Option<f64>> {
        let free = self.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let inflation = self.residual_inflation(theta);
        if let Some(chain) = self.chain_system(theta, &free) {
            return chain.posterior(0, UNCERTAINTY_SEED).map_or_else(
                || vec![None; self.n_params()],
                |p| self.sigmas_of(&p, chain.columns(), inflation),
            );
        }
        let mut out = vec![None; self.n_params()];
        let ne = self.normal_equations(theta, &free);
        for (c, &i) in ne.columns.iter().enumerate() {
            let mut unit = DVector::zeros(ne.columns.len());
            unit[c] = 1.0;
            out[i] = damped_solve(&ne.a, &unit, 0.0).map(|x| inflation * x[c].max(0.0).sqrt());
        }
        out
    }

    /// Per parameter: the exact sigma of a global one, the draws' root mean
    /// square of any other free column (`columns`), widened by `inflation`.
    fn sigmas_of(&self, p: &Posterior, columns: &[usize], inflation: f64) -> Vec<Option<f64>> {
        let mut out = vec![None; self.n_params()];
        let k = p.draws.len() as f64;
        if k > 0.0 {
            for (c, &i) in columns.iter().enumerate() {
                let var = p.draws.iter().map(|d| d[c] * d[c]).sum::<f64>() / k;
                out[i] = Some(inflation * var.sqrt());
            }
        }
        for (a, &i) in p.globals.iter().enumerate() {
            out[i] = Some(inflation * p.global_cov[(a, a)].max(0.0).sqrt());
        }
        out
    }

    /// The sigmas of every parameter and of the path at every row, from
    /// [`DRAWS`] posterior draws of the chain solver (exact for the globals,
    /// see [`Self::parameter_sigmas`]) widened as those, each draw's path
    /// swept and compared with the fitted one. `None` for a model without
    /// segment biases (no chain) or when the solve fails.
    pub fn uncertainty(&self, theta: &[f64], seed: u64) -> Option<Uncertainty> {
        self.uncertainty_at(theta, seed, None)
    }

    /// [`Self::uncertainty`] with the path's covariance kept only at `rows`
    /// (sorted; `Uncertainty::path[i]` is then row `rows[i]`): what a view
    /// that draws a few thousand points needs, without a long ride's every row.
    pub fn uncertainty_at(
        &self,
        theta: &[f64],
        seed: u64,
        rows: Option<&[usize]>,
    ) -> Option<Uncertainty> {
        let free = self.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let chain = self.chain_system(theta, &free)?;
        let posterior = chain.posterior(DRAWS, seed)?;
        let inflation = self.residual_inflation(theta);
        let columns = chain.columns();
        let params = self.sigmas_of(&posterior, columns, inflation);
        let draws = &posterior.draws;
        let k = draws.len() as f64;
        let n = rows.map_or(self.signals.len(), |r| r.len());
        // Index into the kept rows of log row `j`.
        let slot = |j: usize| match rows {
            None => Some(j),
            Some(r) => r.binary_search(&j).ok(),
        };
        let mut fitted = vec![Vector3::zeros(); n];
        self.sweep_from(theta, self.start_of_ride(theta), |j, _, p, _, _| {
            if let Some(f) = slot(j).and_then(|i| fitted.get_mut(i)) {
                *f = *p;
            }
        });
        let mut path = vec![[0.0; 4]; n];
        let mut drawn = theta.to_vec();
        for d in draws {
            for (c, &i) in columns.iter().enumerate() {
                drawn[i] = theta[i] + inflation * d[c];
            }
            self.sweep_from(&drawn, self.start_of_ride(&drawn), |j, _, p, _, _| {
                let Some(i) = slot(j) else {
                    return;
                };
                if let (Some(acc), Some(f)) = (path.get_mut(i), fitted.get(i)) {
                    let e: Vector3<f64> = p - f;
                    acc[0] += e.x * e.x;
                    acc[1] += e.y * e.y;
                    acc[2] += e.z * e.z;
                    acc[3] += e.x * e.y;
                }
            });
        }
        for v in &mut path {
            for x in v.iter_mut() {
                *x /= k;
            }
        }
        Some(Uncertainty { params, path })
    }

    /// `sqrt(1 + 2 sum_k rho_k)`: how much the residuals' remaining
    /// correlation widens every sigma (the effective-sample-size correction).
    /// The whitened residuals are white only if the noise model is right; a
    /// single Gauss-Markov process fitted to GPS error that wanders over a
    /// minute *and* has a white part settles on a short correlation time and
    /// leaves the slow wander in the residuals, where it would be counted as
    /// independent information. `rho_k` is the lag-`k` autocorrelation of the
    /// east and north whitened residuals (fix to fix), summed with Bartlett
    /// weights `1 - k / (K + 1)` up to `K =` [`MAX_LAG`] fixes (Newey-West:
    /// the weights keep the estimate positive), the larger axis taken.
    fn residual_inflation(&self, theta: &[f64]) -> f64 {
        let r = self.residuals(theta);
        let mut worst = 1.0f64;
        for axis in 0..2 {
            let x: Vec<f64> = self
                .observations
                .iter()
                .zip(&r)
                .filter(|(o, _)| o.axis == axis && !o.baro)
                .map(|(_, v)| *v)
                .collect();
            let n = x.len();
            if n < 3 * MAX_LAG {
                continue;
            }
            let mean = x.iter().sum::<f64>() / n as f64;
            let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
            if var <= 0.0 {
                continue;
            }
            let mut sum = 0.0;
            for k in 1..=MAX_LAG {
                let c: f64 = (k..n)
                    .map(|i| (x[i] - mean) * (x[i - k] - mean))
                    .sum::<f64>()
                    / var;
                sum += (1.0 - k as f64 / (MAX_LAG + 1) as f64) * c;
            }
            worst = worst.max(1.0 + 2.0 * sum);
        }
        worst.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::model::ModelSpec;

    /// The chain's marginal covariance of the globals equals the dense
    /// inverse of the full normal matrix, white and correlated (to 1e-4: the
    /// rows pinning the chain's state carry a finite weight, see `chain`).
    #[test]
    fn global_sigmas_from_the_chain_equal_the_dense_inverse() {
        for tau in [None, Some(20.0)] {
            let sig = Arc::new(crate::testing::simulated_signals(6, 90.0, &[]));
            let spec = ModelSpec {
                gps_tau_s: tau,
                ..ModelSpec::default()
            };
            let m = Model::new(sig, spec).unwrap();
            let mut p = m.initial_params();
            for (i, v) in p.iter_mut().enumerate() {
                *v += 1e-4 * (i as f64).cos();
            }
            let free = m.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
            let lin = m.linearise(&p, &free);
            let a = lin.jacobian.transpose() * &lin.jacobian;
            let inv = a.clone().cholesky().expect("positive definite").inverse();
            let inflation = m.residual_inflation(&p);
            let sigmas: Vec<Option<f64>> = m
                .parameter_sigmas(&p)
                .iter()
                .map(|s| s.map(|s| s / inflation))
                .collect();
            let mut globals = 0;
            for (c, &i) in lin.columns.iter().enumerate() {
                if let Some(s) = sigmas[i] {
                    let dense = inv[(c, c)].sqrt();
                    assert!(
                        (s - dense).abs() < 1e-4 * dense,
                        "tau {tau:?} param {i}: {s} vs {dense}"
                    );
                    globals += 1;
                }
            }
            assert!(globals >= 7, "{globals} globals");
        }
    }
}
