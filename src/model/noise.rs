//! The GPS error model: first-order Gauss-Markov errors, correlated from fix
//! to fix, whitened so that the least-squares cost stays a plain sum of
//! squares.
//!
//! Real GPS errors wander (atmosphere, multipath, the receiver's own filter):
//! the error of a fix is mostly the error of the fix before it. With
//! correlation time `tau` and `a_k = exp(-dt_k / tau)` between consecutive
//! fixes, the error `n_k = a_k n_{k-1} + sqrt(1 - a_k^2) sigma_k v_k` with
//! white `v_k`, so
//!
//! ```text
//! e_k  = (x_k - y_k) / sigma_k                      the weighted residual of fix k (one axis)
//! e'_k = (e_k - a_k e_{k-1}) / sqrt(1 - a_k^2)      its innovation: independent, unit variance
//! ```
//!
//! is what the cost sums (its square, through the robust loss when there is
//! one). The first fix of a chain, and the first after an outage longer than
//! [`OUTAGE_S`] (the receiver re-acquires and its error starts afresh),
//! has `a = 0`: `e'_k = e_k`. Without a correlation time every `a_k = 0`
//! and this is the paper's independent least squares.
//!
//! A whitened residual depends on two fixes, so its derivative has two parts:
//! `d r_k = psi'(e'_k) c_k (w_k d x_k - a_k w_{k-1} d x_{k-1})`,
//! `c_k = 1 / sqrt(1 - a_k^2)`. The gradient, the Jacobian and the chain
//! solver each take the two coefficients from [`Link`].

use super::{Model, Observation};

/// Two fixes further apart than this (s) are not linked: the second starts a new chain.
pub const OUTAGE_S: f64 = 10.0;

/// Correlation times at or above this (s) are refused: `a` would be 1 to the
/// digits and the innovations meaningless (a constant offset is an effect, not noise).
pub const MAX_TAU_S: f64 = 3600.0;

/// How observation `k` is linked to the previous fix's observation of the same axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Link {
    /// Index of the previous observation of the same axis (`None`: a chain starts here).
    pub prev: Option<usize>,
    /// `a_k = exp(-dt_k / tau)`.
    pub a: f64,
    /// `c_k = 1 / sqrt(1 - a_k^2)`.
    pub c: f64,
}

impl Link {
    pub const NONE: Link = Link {
        prev: None,
        a: 0.0,
        c: 1.0,
    };
}

/// Link every GPS observation to the previous fix's observation of the same
/// axis (barometric rows are never linked: the barometer's noise is its own).
/// `tau = None` or `0` links nothing.
pub(crate) fn links(obs: &[Observation], tau: Option<f64>) -> Vec<Link> {
    let mut out = vec![Link::NONE; obs.len()];
    let Some(tau) = tau.filter(|t| t.is_finite() && *t > 0.0) else {
        return out;
    };
    let mut last: [Option<usize>; 3] = [None; 3];
    for (k, o) in obs.iter().enumerate() {
        if o.baro {
            continue;
        }
        if let Some(j) = last[o.axis] {
            let dt = o.t - obs[j].t;
            if dt > 0.0 && dt <= OUTAGE_S {
                let a = (-dt / tau).exp();
                // 1 - a^2 without cancellation for dt << tau.
                let one_minus = -(-2.0 * dt / tau).exp_m1();
                if one_minus > 0.0 {
                    out[k] = Link {
                        prev: Some(j),
                        a,
                        c: 1.0 / one_minus.sqrt(),
                    };
                }
            }
        }
        last[o.axis] = Some(k);
    }
    out
}

/// A first guess of the GPS sigma per axis and the correlation time from
/// horizontal misfits `(t, axis, x - y)` of a fitted path: the RMS misfit,
/// and `tau = -dt / ln rho_1` from the lag-one correlation `rho_1` of
/// consecutive fixes (linked as [`links`] links them, `dt` their median
/// spacing). Biased low, both (the fitted path leans towards the fixes), but
/// within a small factor of what the likelihood prefers, where a
/// search started from the settings as set may begin tens of times off.
/// `None` with fewer than ten linked pairs or no positive correlation.
pub(crate) fn gps_noise_guess(misfits: &[(f64, usize, f64)]) -> Option<(f64, f64)> {
    let n = misfits.len();
    if n == 0 {
        return None;
    }
    let sigma = (misfits.iter().map(|m| m.2 * m.2).sum::<f64>() / n as f64).sqrt();
    let mut last: [Option<(f64, f64)>; 2] = [None; 2];
    let (mut cross, mut sq_prev, mut sq_here) = (0.0, 0.0, 0.0);
    let mut spacing = Vec::new();
    for &(t, axis, e) in misfits {
        let axis = axis.min(1);
        if let Some((tp, ep)) = last[axis]
            && t > tp
            && t - tp <= OUTAGE_S
        {
            cross += e * ep;
            sq_prev += ep * ep;
            sq_here += e * e;
            spacing.push(t - tp);
        }
        last[axis] = Some((t, e));
    }
    if spacing.len() < 10 || sigma.is_nan() || sigma <= 0.0 {
        return None;
    }
    let rho = cross / (sq_prev * sq_here).sqrt();
    spacing.sort_by(f64::total_cmp);
    let dt = spacing[spacing.len() / 2];
    (rho > 0.0 && rho < 1.0).then(|| (sigma, -dt / rho.ln()))
}

impl Model {
    /// [`gps_noise_guess`] from the horizontal misfits of the path values `x`
    /// (one per observation, as a linearisation holds them) at `theta`.
    pub(crate) fn gps_noise_guess(&self, theta: &[f64], x: &[f64]) -> Option<(f64, f64)> {
        let plan = self.obs_plan(theta);
        let misfits: Vec<(f64, usize, f64)> = self
            .observations
            .iter()
            .zip(x)
            .zip(&plan.target)
            .filter(|((o, _), _)| !o.baro && o.axis < 2)
            .map(|((o, x), y)| (o.t, o.axis, x - y))
            .collect();
        gps_noise_guess(&misfits)
    }

    /// `ln det` of the covariance of everything the cost weighs: the
    /// observations' (`prod sigma_k^2 (1 - a_k^2)`: a chain's covariance
    /// determinant is its innovations') and the prior rows' with a free
    /// entry (`1 / w^2` per row). A marginal likelihood adds it to the cost.
    pub(crate) fn noise_log_det(&self, theta: &[f64], free: &[bool]) -> f64 {
        let plan = self.obs_plan(theta);
        let obs: f64 = self
            .observations
            .iter()
            .zip(&plan.links)
            .map(|(o, l)| -2.0 * o.w.ln() - 2.0 * l.c.ln())
            .sum();
        let prior = self.prior_rows(theta);
        let mut weight = vec![0.0f64; prior.residuals.len()];
        for &(row, col, v) in &prior.entries {
            if free[col] {
                weight[row] = weight[row].max(v.abs());
            }
        }
        obs + weight
            .iter()
            .filter(|w| **w > 0.0)
            .map(|w| -2.0 * w.ln())
            .sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(t: f64, axis: usize, baro: bool) -> Observation {
        Observation {
            row: 0,
            axis,
            target: 0.0,
            w: 1.0,
            baro,
            t,
        }
    }

    #[test]
    fn the_guess_recovers_a_gauss_markov_error() {
        // Two axes of 1 Hz fixes, sigma 2 m, tau 15 s, an outage in the middle.
        let mut rng = crate::simulation::rng::Rng::new(5);
        let (sigma, tau) = (2.0, 15.0);
        let a = (-1.0f64 / tau).exp();
        let mut misfits = Vec::new();
        let mut n = [sigma * rng.normal(), sigma * rng.normal()];
        for k in 0..4000 {
            let t = k as f64 + if k >= 2000 { 60.0 } else { 0.0 };
            for (axis, e) in n.iter_mut().enumerate() {
                *e = a * *e + (1.0 - a * a).sqrt() * sigma * rng.normal();
                misfits.push((t, axis, *e));
            }
        }
        let (s, t) = gps_noise_guess(&misfits).unwrap();
        assert!((s / sigma - 1.0).abs() < 0.1, "sigma {s}");
        assert!((t / tau - 1.0).abs() < 0.25, "tau {t}");
        // White errors: no positive correlation, no guess of tau.
        let white: Vec<_> = (0..400).map(|k| (k as f64, 0, rng.normal())).collect();
        let guess = gps_noise_guess(&white);
        assert!(guess.is_none_or(|(_, t)| t < 1.0), "{guess:?}");
        assert_eq!(gps_noise_guess(&white[..5]), None, "too few pairs");
    }

    #[test]
    fn links_follow_each_axis_and_restart_after_an_outage() {
        let o = vec![
            obs(0.0, 0, false),
            obs(0.0, 1, false),
            obs(0.0, 2, true),
            obs(1.0, 0, false),
            obs(1.0, 1, false),
            obs(1.0, 2, true),
            obs(30.0, 0, false),
            obs(31.0, 0, false),
        ];
        let l = links(&o, Some(60.0));
        assert_eq!(l[0].prev, None);
        assert_eq!(l[3].prev, Some(0));
        assert_eq!(l[4].prev, Some(1));
        assert_eq!(l[5], Link::NONE, "barometric rows are never linked");
        assert_eq!(l[6].prev, None, "29 s gap: a new chain");
        assert_eq!(l[7].prev, Some(6));
        let a = (-1.0f64 / 60.0).exp();
        assert!((l[7].a - a).abs() < 1e-15);
        assert!((l[7].c - 1.0 / (1.0 - a * a).sqrt()).abs() < 1e-9);
        assert!(links(&o, None).iter().all(|l| *l == Link::NONE));
        assert!(links(&o, Some(0.0)).iter().all(|l| *l == Link::NONE));
    }

    #[test]
    fn whitened_gauss_markov_errors_are_white_with_unit_variance() {
        // Simulate the process the whitening inverts; its innovations come back.
        let tau = 40.0;
        let mut rng = crate::simulation::rng::Rng::new(5);
        let n = 20_000;
        let mut e = Vec::with_capacity(n);
        let mut x = rng.normal();
        for _ in 0..n {
            e.push(x);
            let a: f64 = (-1.0f64 / tau).exp();
            x = a * x + (1.0 - a * a).sqrt() * rng.normal();
        }
        let o: Vec<Observation> = (0..n).map(|i| obs(i as f64, 0, false)).collect();
        let l = links(&o, Some(tau));
        let w: Vec<f64> = (0..n)
            .map(|k| match l[k].prev {
                Some(j) => l[k].c * (e[k] - l[k].a * e[j]),
                None => e[k],
            })
            .collect();
        let var = w.iter().map(|v| v * v).sum::<f64>() / n as f64;
        let lag1 = w.windows(2).map(|p| p[0] * p[1]).sum::<f64>() / n as f64;
        assert!((var - 1.0).abs() < 0.03, "variance {var}");
        assert!(lag1.abs() < 0.03, "lag-1 correlation {lag1}");
        // The raw errors are anything but white.
        let raw1 = e.windows(2).map(|p| p[0] * p[1]).sum::<f64>() / n as f64;
        assert!(raw1 > 0.9, "raw lag-1 {raw1}");
    }
}
