//! How each observation is evaluated for one parameter vector: where on the
//! path it looks, what it is compared with, and through which loss.
//!
//! Observation `k` (axis `a` of fix `i` logged at `t_i`) compares
//!
//! ```text
//! x_k = p_j[a] - beta_k Delta_j[a]              the path at t_i - lag, interpolated in step j
//!       (t_{j-1} <= t_i - lag <= t_j,  beta_k = (t_j - (t_i - lag)) / dt_j,  Delta_j = p_j - p_{j-1})
//! y_k = target_k + sum_e s_e(theta)             the target shifted by observation effects
//! e_k = w_k (x_k - y_k)                         weighted residual
//! r_k = psi(e_k)                                the residual in the cost C = sum r_k^2
//! ```
//!
//! with `psi(e) = e` for least squares and, with a robust (Cauchy) loss of
//! scale `s` on GPS rows, `psi(e) = sign(e) s sqrt(ln(1 + e^2 / s^2))`, so
//! that `psi^2` is the Cauchy loss and Gauss-Newton works on `r` unchanged.
//! Every derivative is `d r_k / d theta = psi'(e_k) w_k (d x_k / d theta - d y_k / d theta)`
//! with `d x_k / d lag = -Delta_j[a] / dt_j`. Without lag `j` is the fix's own
//! row and `beta = 0`, which is the paper's objective (eq. 7).
//!
//! With a GPS correlation time (see [`super::noise`]) `psi` acts on the
//! innovation `e'_k = u_k (x_k - y_k) + v_k z_{k-1}` instead, and `r_k` has a
//! second slope, on the filtered wander `z` of the fixes before it:
//! [`ObsValue::back`].

use nalgebra::Vector3;

use super::noise::{self, Link};
use super::{Model, Observation};
use crate::effects::TargetSite;

/// The evaluation of every observation for one parameter vector.
pub(crate) struct ObsPlan {
    /// Row in whose step observation `k` is evaluated (non-decreasing in `k`).
    pub row: Vec<usize>,
    /// How far back into that step: `x = p_row - beta Delta_row`.
    pub beta: Vec<f64>,
    /// Shifted targets `y_k`.
    pub target: Vec<f64>,
    /// `d y_k / d theta` entries `(parameter, value)`, observation `k` owning
    /// `shifts[shift_start[k]..shift_start[k + 1]]`.
    shifts: Vec<(usize, f64)>,
    shift_start: Vec<usize>,
    /// The lag parameter and, per observation, whether `x` moves with it (not clamped at the ride's ends).
    lag: Option<usize>,
    lag_moves: Vec<bool>,
    /// Cauchy scale on GPS rows (weighted units).
    robust: Option<f64>,
    /// Each observation's link to the previous fix (GPS error correlation).
    pub links: Vec<Link>,
}

/// One observation's misfit, in metres and normalised by the noise model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Misfit {
    /// `x_k - y_k` (m).
    pub metres: f64,
    /// `e'_k`, the whitened misfit (unit variance under the noise model).
    pub white: f64,
}

/// One observation's residual and slope.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ObsValue {
    /// `r_k`, the residual that enters the cost.
    pub r: f64,
    /// `d r_k / d m_k = psi'(e'_k) u_k`.
    pub slope: f64,
    /// `d r_k / d z_prev = psi'(e'_k) v_k`, on the filtered wander of the
    /// linked previous observation (`links[k].prev`; 0 when there is none).
    pub back: f64,
    /// `x_k - y_k` (m).
    pub metres: f64,
}

/// `psi(e)` and `psi'(e)` of the Cauchy loss with scale `s`.
#[inline]
fn cauchy(e: f64, s: f64) -> (f64, f64) {
    let u = e / s;
    if u.abs() < 1e-6 {
        // psi(e) = e (1 - u^2 / 4 + ...), psi' = 1 - 3 u^2 / 4 + ...
        return (e * (1.0 - 0.25 * u * u), 1.0 - 0.75 * u * u);
    }
    let l = (u * u).ln_1p();
    let psi = e.signum() * s * l.sqrt();
    // psi^2 = s^2 ln(1 + u^2)  =>  2 psi psi' = 2 e / (1 + u^2).
    (psi, e / ((1.0 + u * u) * psi))
}

/// The residuals of the observations, computed in observation order: a
/// whitened residual needs the filtered wander of the fixes before it.
pub(crate) struct Whitener<'a> {
    plan: &'a ObsPlan,
    obs: &'a [Observation],
    /// The filtered wander `z_k` of the observations seen so far (m).
    z: Vec<f64>,
}

impl<'a> Whitener<'a> {
    pub fn new(plan: &'a ObsPlan, obs: &'a [Observation]) -> Self {
        Self {
            plan,
            obs,
            z: vec![0.0; obs.len()],
        }
    }

    /// Misfit of observation `k` whose path value is `x`, in metres and
    /// whitened (`e'_k = u_k m_k + v_k z_prev`, before the robust loss);
    /// every observation before `k` that `k` is linked to must have been seen.
    #[inline]
    pub fn misfit(&mut self, k: usize, x: f64) -> Misfit {
        let metres = x - self.plan.target[k];
        let link = self.plan.links[k];
        let z_prev = link.prev.map_or(0.0, |j| self.z[j]);
        self.z[k] = link.alpha * z_prev + link.kappa * metres;
        Misfit {
            metres,
            white: link.u * metres + link.v * z_prev,
        }
    }

    /// Residual of observation `k` whose path value is `x` (see [`Self::misfit`]).
    #[inline]
    pub fn value(&mut self, k: usize, x: f64) -> ObsValue {
        let Misfit { metres, white } = self.misfit(k, x);
        let link = self.plan.links[k];
        let (r, d) = match self.plan.robust {
            Some(s) if !self.obs[k].baro => cauchy(white, s),
            _ => (white, 1.0),
        };
        ObsValue {
            r,
            slope: d * link.u,
            back: d * link.v,
            metres,
        }
    }

    /// Residuals of every observation, from their path values in order.
    pub fn all(mut self, x: impl Iterator<Item = f64>) -> Vec<ObsValue> {
        x.enumerate().map(|(k, x)| self.value(k, x)).collect()
    }
}

/// The derivative of the filtered wander, carried forwards through the
/// observations: `d z_k = alpha_k d z_prev + kappa_k d m_k` (see
/// [`super::noise`]), for any linear form `T` of a misfit's derivative (a
/// number, a Jacobian row). Each observation is the previous one of at most
/// one later observation, so a derivative is dropped once it has been used.
pub(crate) struct WanderDerivative<T> {
    held: Vec<Option<T>>,
    /// Whether a later observation is linked to each.
    needed: Vec<bool>,
}

impl<T: Clone> WanderDerivative<T> {
    pub fn new(links: &[Link]) -> Self {
        Self {
            held: vec![None; links.len()],
            needed: noise::next_in_chain(links)
                .iter()
                .map(Option::is_some)
                .collect(),
        }
    }

    /// `d z_prev` of observation `k` (`None`: not linked, zero), taken out.
    pub fn take_prev(&mut self, links: &[Link], k: usize) -> Option<T> {
        links[k].prev.and_then(|j| self.held[j].take())
    }

    /// Record `d z_k` from `d z_prev` and `d m_k`, if a later observation needs it.
    pub fn record(&mut self, k: usize, dz: impl FnOnce() -> T) {
        if self.needed[k] {
            self.held[k] = Some(dz());
        }
    }
}

impl ObsPlan {
    /// `x_k` from the path at its row and the step that ends there.
    #[inline]
    pub fn x(&self, k: usize, axis: usize, p: &Vector3<f64>, delta: &Vector3<f64>) -> f64 {
        p[axis] - self.beta[k] * delta[axis]
    }

    /// The interpolated position of observation `k`.
    #[inline]
    pub fn position(&self, k: usize, p: &Vector3<f64>, delta: &Vector3<f64>) -> Vector3<f64> {
        p - delta * self.beta[k]
    }

    /// Partials of `x_k - y_k` other than through the path: the lag
    /// (`-Delta_j[a] / dt_j`) and the target shifts (`-d y / d theta`).
    #[inline]
    pub fn for_extra(
        &self,
        k: usize,
        axis: usize,
        delta: &Vector3<f64>,
        dt: f64,
        mut f: impl FnMut(usize, f64),
    ) {
        if let Some(i) = self.lag
            && self.lag_moves[k]
            && dt > 0.0
        {
            f(i, -delta[axis] / dt);
        }
        for &(i, v) in &self.shifts[self.shift_start[k]..self.shift_start[k + 1]] {
            f(i, -v);
        }
    }
}

impl Model {
    /// The Cauchy scale on GPS rows (whitened units), when an effect asks for a robust loss.
    pub(crate) fn robust_scale(&self) -> Option<f64> {
        if self.least_squares {
            return None;
        }
        self.effects.iter().find_map(|e| e.robust_scale())
    }

    /// Of every observation for a computed path: `x_k - y_k` (m, model minus
    /// measurement) and its normalised innovation `e'_k = u_k m_k + v_k z_{k-1}`
    /// (see [`super::noise`]), before the robust loss: what the fit's noise
    /// model says is independent with unit variance.
    pub(crate) fn misfits(&self, theta: &[f64], path: &impl super::PathAt) -> Vec<Misfit> {
        let plan = self.obs_plan(theta);
        let mut whitener = Whitener::new(&plan, &self.observations);
        self.observations
            .iter()
            .enumerate()
            .map(|(k, o)| {
                let j = plan.row[k];
                let p = path.p_at(j);
                let delta = p - path.p_at(j.max(1) - 1);
                whitener.misfit(k, plan.x(k, o.axis, &p, &delta))
            })
            .collect()
    }

    /// The rows a residual evaluation reads at `theta` (each observation's
    /// row and the one before it, and every fix's row), sorted, without repeats.
    pub fn residual_rows(&self, theta: &[f64]) -> Vec<usize> {
        let plan = self.obs_plan(theta);
        let mut rows: Vec<usize> = plan
            .row
            .iter()
            .flat_map(|&j| [j.max(1) - 1, j])
            .chain(
                self.signals
                    .fixes
                    .iter()
                    .flat_map(|f| [f.row, f.row.max(1)]),
            )
            .collect();
        rows.sort_unstable();
        rows.dedup();
        rows
    }

    /// The vehicle's forward axis in sensor axes and its partials `(parameter, d f / d p)`.
    pub(crate) fn forward_axis(&self, theta: &[f64]) -> (Vector3<f64>, Vec<(usize, Vector3<f64>)>) {
        for (e, effect) in self.effects.iter().enumerate() {
            if let Some((f, cols)) = effect.forward_axis(self.params_of(e, theta)) {
                let parts = cols
                    .as_slice()
                    .iter()
                    .map(|&(c, v)| (self.offsets[e] + c, v))
                    .collect();
                return (f, parts);
            }
        }
        (Vector3::x(), Vec::new())
    }

    /// Where and against what every observation is evaluated at `theta`.
    pub(crate) fn obs_plan(&self, theta: &[f64]) -> ObsPlan {
        let sig = &self.signals;
        let obs = &self.observations;
        let n = obs.len();
        let mut lag = None;
        let mut lag_value = 0.0;
        for (e, effect) in self.effects.iter().enumerate() {
            if let Some(l) = effect.gps_lag(self.params_of(e, theta)) {
                lag = Some(self.offsets[e]);
                lag_value = l;
            }
        }
        let mut row = Vec::with_capacity(n);
        let mut beta = Vec::with_capacity(n);
        let mut lag_moves = Vec::with_capacity(n);
        if lag.is_some() && lag_value != 0.0 && lag_value.is_finite() {
            let t = &sig.t;
            let last = self.horizon() - 1;
            let (first, _, _) = self.sweep_start(theta);
            for o in obs {
                let te = o.t - lag_value;
                if te <= t[first] {
                    row.push(first);
                    beta.push(0.0);
                    lag_moves.push(false);
                } else if te >= t[last] {
                    row.push(last);
                    beta.push(0.0);
                    lag_moves.push(false);
                } else {
                    // First row with t_j >= te (j >= 1 since te > t_0).
                    let j = t.partition_point(|&x| x < te);
                    row.push(j);
                    beta.push((t[j] - te) / sig.dt[j]);
                    lag_moves.push(true);
                }
            }
        } else {
            row.extend(obs.iter().map(|o| o.row));
            beta.resize(n, 0.0);
            lag_moves.resize(n, true);
        }

        let shifting: Vec<usize> = (0..self.effects.len())
            .filter(|&e| self.effects[e].n_params() > 0)
            .collect();
        let t_start = sig.t[0];
        let mut target = Vec::with_capacity(n);
        let mut shifts = Vec::new();
        let mut shift_start = Vec::with_capacity(n + 1);
        for o in obs {
            shift_start.push(shifts.len());
            let site = TargetSite {
                t: o.t,
                t_start,
                axis: o.axis,
                baro: o.baro,
            };
            let mut y = o.target;
            for &e in &shifting {
                if let Some((s, cols)) =
                    self.effects[e].target_shift(self.params_of(e, theta), &site)
                {
                    y += s;
                    shifts.extend(
                        cols.as_slice()
                            .iter()
                            .map(|&(c, v)| (self.offsets[e] + c, v)),
                    );
                }
            }
            target.push(y);
        }
        shift_start.push(shifts.len());
        ObsPlan {
            row,
            beta,
            target,
            shifts,
            shift_start,
            lag,
            lag_moves,
            robust: self.robust_scale(),
            links: noise::links(obs, self.spec.gps_taus()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::cauchy;

    #[test]
    fn cauchy_residual_squares_to_the_loss_and_its_slope_is_exact() {
        let s = 1.3;
        for &e in &[-40.0, -3.0, -0.2, -1e-9, 0.0, 1e-8, 0.5, 2.0, 25.0] {
            let (psi, d) = cauchy(e, s);
            let loss = s * s * (1.0 + (e / s) * (e / s)).ln();
            assert!((psi * psi - loss).abs() < 1e-12 * (1.0 + loss), "e {e}");
            assert!(psi * e >= 0.0);
            let h = 1e-6 * (1.0 + e.abs());
            let fd = (cauchy(e + h, s).0 - cauchy(e - h, s).0) / (2.0 * h);
            assert!((fd - d).abs() < 1e-6, "e {e}: {fd} vs {d}");
        }
    }
}
