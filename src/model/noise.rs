//! The GPS error model: a first-order Gauss-Markov error, correlated from
//! fix to fix, plus a white error of its own per fix, whitened by a Kalman
//! filter so that the least-squares cost stays a plain sum of squares.
//!
//! Real GPS errors wander (atmosphere, multipath, the receiver's own filter):
//! the error of a fix is mostly the error of the fix before it. On top of that
//! wander each fix has a jitter of its own, and a receiver's per-fix accuracy
//! says how large that jitter is. Per axis, in metres, the misfit of fix `k`
//! is
//!
//! ```text
//! m_k = x_k - y_k = g_k + v_k
//! g_k = a_k g_{k-1} + sqrt(1 - a_k^2) q_k n_k,   a_k = exp(-dt_k / tau)   the wander
//! v_k ~ N(0, R_k)                                                          the jitter
//! q_k = sigma_g acc_k / median(acc),  sqrt(R_k) = sigma_w acc_k / median(acc)
//! ```
//!
//! A fix the receiver rates worse has a larger jitter and lets the wander
//! move faster (a street canyon's multipath), but a wander that stays put
//! stays cheap whatever the ratings do: an earlier model whitened the misfits
//! divided by each fix's sigma, and on the Husky, whose ratings step between
//! 0.8 and 1.2 m from fix to fix, a constant 1 m offset then read as an error
//! jumping at every step (its cost rose by 100 where the model allows 0.44).
//!
//! Its whitening is the Kalman filter of `g` (a scalar per axis, independent
//! of the path's parameters, so its gains are fixed numbers): with `z_k` the
//! filtered wander and `P_k` its variance,
//!
//! ```text
//! S_k  = a_k^2 P_{k-1} + (1 - a_k^2) q_k^2 + R_k          innovation variance
//! e'_k = (m_k - a_k z_{k-1}) / sqrt(S_k) = u_k m_k + v_k z_{k-1}   the innovation: independent, unit variance
//! K_k  = (S_k - R_k) / S_k,  z_k = (1 - K_k) a_k z_{k-1} + K_k m_k = alpha_k z_{k-1} + kappa_k m_k
//! P_k  = (1 - K_k)(S_k - R_k)
//! ```
//!
//! is what the cost sums (its square, through the robust loss when there is
//! one), and `sum_k ln S_k` is the log-determinant of the errors' covariance.
//! The first fix of each axis has `a = 0`: `S = q^2 + R`. An outage is
//! bridged as any gap is, `a = exp(-dt / tau)`: a gap of a few correlation
//! times forgets the wander, a shorter one does not. The atmosphere's part
//! of the error runs on while the receiver sees nothing, and restarting the
//! wander after every gap over 10 s, as this model once did, threw away what
//! the fixes on either side say about it: on simulated rides (wander running
//! through 20-60 s outages) the estimated wander came out 19 % small and its
//! time 22 % short, and the path's 95 % ellipses held the truth at 76 % of
//! the rows instead of 83 %. Without a jitter (`R = 0`) the filter is
//! exact after one fix and `e'_k = (m_k - a_k m_{k-1}) / (q_k sqrt(1 - a_k^2))`;
//! without a correlation time every fix is independent with `S_k = sigma_k^2`,
//! the paper's least squares with per-fix weights.
//!
//! A whitened residual depends on its own misfit and on the filtered wander,
//! itself a fixed linear filter of the earlier misfits, so its derivative is
//! `d r_k = psi'(e'_k) (u_k d m_k + v_k d z_{k-1})` with
//! `d z_k = alpha_k d z_{k-1} + kappa_k d m_k`. The gradient (run backwards),
//! the Jacobian and the chain solver (run forwards) each take the four
//! coefficients from [`Link`].

use super::{Model, Observation};
use crate::contract::PriorRows;
use crate::statistics::median;

/// Consecutive fixes further apart than this (s) are not a pair in the
/// moments of [`gps_noise_guess`] (its lag-one covariance assumes the
/// median spacing).
pub const OUTAGE_S: f64 = 10.0;

/// Correlation times at or above this (s) are refused: `a` would be 1 to the
/// digits and the innovations meaningless (a constant offset is an effect, not noise).
pub const MAX_TAU_S: f64 = 3600.0;

/// How observation `k` is whitened: its innovation `e'_k = u m_k + v z_prev`
/// and the filtered wander `z_k = alpha z_prev + kappa m_k` it passes on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Link {
    /// Index of the previous observation of the same axis (`None`: a chain starts here).
    pub prev: Option<usize>,
    /// `u_k = 1 / sqrt(S_k)`.
    pub u: f64,
    /// `v_k = -a_k / sqrt(S_k)` (0 without `prev`).
    pub v: f64,
    /// `alpha_k = (1 - K_k) a_k` (0 without `prev`).
    pub alpha: f64,
    /// `kappa_k = K_k` (0 for an observation nothing is linked to).
    pub kappa: f64,
}

impl Link {
    /// An independent observation of standard deviation `sd`.
    pub fn independent(sd: f64) -> Self {
        Link {
            prev: None,
            u: 1.0 / sd,
            v: 0.0,
            alpha: 0.0,
            kappa: 0.0,
        }
    }
}

/// The observation linked to each (`links[o].prev == Some(j)` makes `o` the
/// next of `j`; each has at most one, the next fix's observation of its axis).
pub(crate) fn next_in_chain(links: &[Link]) -> Vec<Option<usize>> {
    let mut next = vec![None; links.len()];
    for (o, l) in links.iter().enumerate() {
        if let Some(j) = l.prev {
            next[j] = Some(o);
        }
    }
    next
}

/// The whitening of every observation: GPS observations of one axis are
/// linked to the previous fix's when the model has a correlation time and a
/// wander (`sd_gm > 0`); barometric rows never are (the barometer's noise is
/// its own). `tau = None` or `0` links nothing. Each observation's `update`
/// scales its Kalman gain (see [`Filter::update`], [`robust_updates`]).
pub(crate) fn links(obs: &[Observation], taus: [Option<f64>; 3]) -> Vec<Link> {
    let mut filter = Filter::new(taus);
    (0..obs.len())
        .map(|k| {
            let prior = filter.predict(obs, k);
            filter.update(k, prior, obs[k].update)
        })
        .collect()
}

/// The weight on each observation's Kalman update that a robust (Cauchy,
/// scale `s` in whitened units) filter gives it, run along misfits `m_k`
/// (m): `w_k = 1 / (1 + e'_k^2 / s^2)`, the loss's own weight on the
/// innovation, and the wander passed on is updated by `w_k K_k m_k`.
///
/// What it is for: the noise search. Under the plain filter a jump of 30 m
/// that lasts a minute is one large innovation (which the loss discounts),
/// then a wander that has followed it, then another large innovation: the
/// likelihood reads the jump as wander and prefers a wander as large as the
/// jumps (on a simulated ride with hidden outliers, 3.3 m over 110 s for a
/// true 1.5 m over 60 s; in a city 4.8 m over 93 s). Under the robust filter
/// the wander stays put, every fix inside the jump is an outlier to the
/// loss, and the wander is judged by the fixes that are not (1.7 m over 30
/// s; the path 1.78 m from the truth instead of 2.08 m, and 4.69 m instead
/// of 5.85 m in the city; measured before outages were bridged, which
/// without this read the hidden outliers as 7.1 m over 522 s). The fit itself keeps the plain filter: there the
/// wander taking the jump is what keeps the jump's fixes from pulling the
/// path (each then constrains only the change from its neighbour); fitted
/// under the robust filter's weights, each of them pulls the path's level
/// and the city path ended 9.2 m from the truth.
pub(crate) fn robust_updates(
    obs: &[Observation],
    taus: [Option<f64>; 3],
    m: &[f64],
    s: f64,
) -> Vec<f64> {
    let mut filter = Filter::new(taus);
    let mut z = vec![0.0; obs.len()];
    (0..obs.len())
        .map(|k| {
            let prior = filter.predict(obs, k);
            let z_prev = prior.prev.map_or(0.0, |j| z[j]);
            let w = match prior.prev {
                Some(_) if !obs[k].baro => {
                    let e = (m[k] - prior.a * z_prev) / prior.s.sqrt();
                    1.0 / (1.0 + (e / s).powi(2))
                }
                _ => 1.0,
            };
            let link = filter.update(k, prior, w);
            z[k] = link.alpha * z_prev + link.kappa * m[k];
            w
        })
        .collect()
}

/// The scalar Kalman filter of the wander, per axis, one observation at a time.
struct Filter {
    /// Correlation time per axis (east, north, up).
    tau: [Option<f64>; 3],
    /// Per axis: the last linked observation and its filtered variance P.
    last: [Option<(usize, f64)>; 3],
}

/// Observation `k`'s prediction: the linked observation, `a_k`, the predicted
/// wander variance `a^2 P + (1 - a^2) q^2`, and `S`, its sum with the jitter `R`.
#[derive(Clone, Copy)]
struct Prior {
    axis: usize,
    prev: Option<usize>,
    a: f64,
    predicted: f64,
    s: f64,
    /// An observation the filter does not follow (independent, barometric).
    independent: Option<f64>,
}

impl Filter {
    fn new(taus: [Option<f64>; 3]) -> Self {
        Self {
            tau: taus.map(|tau| tau.filter(|t| t.is_finite() && *t > 0.0)),
            last: [None; 3],
        }
    }

    fn predict(&self, obs: &[Observation], k: usize) -> Prior {
        let o = &obs[k];
        let (Some(tau), false, true) = (self.tau[o.axis], o.baro, o.sd_gm > 0.0) else {
            return Prior {
                axis: o.axis,
                prev: None,
                a: 0.0,
                predicted: 0.0,
                s: o.sd_white * o.sd_white,
                independent: Some(o.sd_white),
            };
        };
        let q = o.sd_gm * o.sd_gm;
        let r = o.sd_white * o.sd_white;
        let linked = self.last[o.axis].and_then(|(j, p)| {
            let dt = o.t - obs[j].t;
            (dt > 0.0).then(|| {
                // 1 - a^2 without cancellation for dt << tau.
                let one_minus = -(-2.0 * dt / tau).exp_m1();
                let a = (-dt / tau).exp();
                (j, a, a * a * p + one_minus * q)
            })
        });
        let (prev, a, predicted) = match linked {
            Some((j, a, predicted)) => (Some(j), a, predicted),
            None => (None, 0.0, q),
        };
        Prior {
            axis: o.axis,
            prev,
            a,
            predicted,
            s: predicted + r,
            independent: None,
        }
    }

    /// The link of an observation predicted as `prior`, its gain scaled by
    /// `w` (1: the plain filter): `K = w (S - R) / S`, `z_k = (1 - K) a z_prev
    /// + K m_k`, `P = (1 - K)(S - R)`, which is the filter's update for a
    /// jitter inflated to `R + S (1 / w - 1)`; the innovation keeps the plain
    /// `S` (the loss, not the filter, discounts it).
    fn update(&mut self, k: usize, prior: Prior, w: f64) -> Link {
        if let Some(sd) = prior.independent {
            return Link::independent(sd);
        }
        let gain = w * prior.predicted / prior.s;
        self.last[prior.axis] = Some((k, (1.0 - gain) * prior.predicted));
        let u = 1.0 / prior.s.sqrt();
        Link {
            prev: prior.prev,
            u,
            v: -prior.a * u,
            alpha: (1.0 - gain) * prior.a,
            kappa: gain,
        }
    }
}

/// A first guess of the GPS error's wander (sigma per axis, correlation
/// time) and jitter from horizontal misfits `(t, axis, x - y)` of a fitted
/// path, by moments: the variance, the lag-one covariance and the mean
/// square of the second differences `m_{k+1} - 2 m_k + m_{k-1}` of
/// consecutive misfits fit the three (when they do not, the second
/// differences' median absolute deviation gives the jitter alone,
/// `sqrt(R) = 1.4826 MAD / sqrt(6)`, and the wander is the rest);
/// `tau = -dt / ln rho` from the wander's lag-one correlation `rho` (`dt` the
/// median spacing). Biased low (the
/// fitted path leans towards the fixes), but within a small factor of what
/// the likelihood prefers, where a search started from the settings as set
/// may begin tens of times off. `None` with fewer than ten linked pairs or
/// no positive correlation.
pub(crate) fn gps_noise_guess(misfits: &[(f64, usize, f64)]) -> Option<(f64, f64, f64)> {
    let n = misfits.len();
    if n == 0 {
        return None;
    }
    let var = misfits.iter().map(|m| m.2 * m.2).sum::<f64>() / n as f64;
    // Per axis the last two misfits (t, m) of the current chain.
    let mut last: [[Option<(f64, f64)>; 2]; 2] = [[None; 2]; 2];
    let (mut cross, mut sq_prev, mut sq_here) = (0.0, 0.0, 0.0);
    let mut spacing = Vec::new();
    let mut second = Vec::new();
    for &(t, axis, e) in misfits {
        let axis = axis.min(1);
        match last[axis][0] {
            Some((tp, ep)) if t > tp && t - tp <= OUTAGE_S => {
                cross += e * ep;
                sq_prev += ep * ep;
                sq_here += e * e;
                spacing.push(t - tp);
                if let Some((tpp, epp)) = last[axis][1]
                    && ((t - tp) - (tp - tpp)).abs() < 0.2 * (t - tp)
                {
                    second.push((e - 2.0 * ep + epp).abs());
                }
                last[axis] = [Some((t, e)), Some((tp, ep))];
            }
            _ => last[axis] = [Some((t, e)), None],
        }
    }
    if spacing.len() < 10 || !(var.is_finite() && var > 0.0) {
        return None;
    }
    // Moments of a wander (variance w, lag-one correlation a) plus jitter R:
    // var = w + R, c1 = w a, E d2^2 = 6 R + w (6 - 8 a + 2 a^2), so
    // w = 2 c1^2 / (E d2^2 - 6 var + 8 c1); else the robust jitter alone.
    let c1 = cross / (sq_prev * sq_here).sqrt() * var;
    let mut wander = f64::NAN;
    if second.len() >= 10 {
        let d2 = second.iter().map(|d| d * d).sum::<f64>() / second.len() as f64;
        let denominator = d2 - 6.0 * var + 8.0 * c1;
        if denominator > 0.0 {
            wander = 2.0 * c1 * c1 / denominator;
        }
        if !(wander > 0.01 * var && wander < var && c1 < wander) {
            let r = 1.4826 * median(&mut second) / 6f64.sqrt();
            wander = var - r.min(0.9 * var.sqrt()).powi(2);
        }
    } else {
        wander = var;
    }
    let jitter = (var - wander).max(0.0).sqrt();
    let rho = c1 / wander;
    let dt = median(&mut spacing);
    (rho > 0.0).then(|| (wander.sqrt(), -dt / rho.min(0.999).ln(), jitter))
}

/// Misfits clipped to 3 robust standard deviations (`1.4826 MAD` about the
/// median) of their own: under a robust loss some fixes jump by tens of
/// metres, and their moments would start the noise search in the mode that
/// reads the jumps as a wander (seed 45 with hidden outliers: 6.8 m over
/// 423 s for a true 1.5 m over 60 s).
fn winsorised(mut misfits: Vec<(f64, usize, f64)>) -> Vec<(f64, usize, f64)> {
    let mut v: Vec<f64> = misfits.iter().map(|m| m.2).collect();
    if v.is_empty() {
        return misfits;
    }
    let centre = median(&mut v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - centre).abs()).collect();
    let c = 3.0 * 1.4826 * median(&mut dev);
    if c > 0.0 {
        for m in &mut misfits {
            m.2 = m.2.clamp(centre - c, centre + c);
        }
    }
    misfits
}

impl Model {
    /// Give every observation the update weight of the robust filter run
    /// along its misfit `x_k - y_k` at `theta` ([`robust_updates`]; `x` the
    /// path values, one per observation, as a linearisation holds them), for
    /// a model whose GPS rows have a robust loss and a correlation time;
    /// otherwise every weight stays 1.
    pub(crate) fn weigh_updates(&mut self, theta: &[f64], x: &[f64]) {
        let (Some(s), Some(_)) = (self.robust_scale(), self.spec.gps_tau_s) else {
            return;
        };
        let plan = self.obs_plan(theta);
        let metres: Vec<f64> = x.iter().zip(&plan.target).map(|(x, y)| x - y).collect();
        let w = robust_updates(&self.observations, self.spec.gps_taus(), &metres, s);
        for (o, w) in self.observations.iter_mut().zip(w) {
            o.update = w;
        }
    }

    /// Whether any GPS height is observed (a planar model observes none).
    pub(crate) fn observes_gps_heights(&self) -> bool {
        self.observations.iter().any(|o| o.axis == 2 && !o.baro)
    }

    /// [`gps_noise_guess`] from the horizontal (`vertical`: the GPS
    /// heights') misfits of the path values `x` (one per observation, as a
    /// linearisation holds them) at `theta`.
    pub(crate) fn gps_noise_guess(
        &self,
        theta: &[f64],
        x: &[f64],
        vertical: bool,
    ) -> Option<(f64, f64, f64)> {
        let plan = self.obs_plan(theta);
        let misfits: Vec<(f64, usize, f64)> = self
            .observations
            .iter()
            .zip(x)
            .zip(&plan.target)
            .filter(|((o, _), _)| !o.baro && (o.axis == 2) == vertical)
            .map(|((o, x), y)| (o.t, o.axis, x - y))
            .collect();
        if self.robust_scale().is_some() {
            return gps_noise_guess(&winsorised(misfits));
        }
        gps_noise_guess(&misfits)
    }

    /// `ln det` of the covariance of everything the cost weighs: the
    /// observations' (`prod S_k`: a chain's covariance determinant is its
    /// innovations') and the prior rows' with a free
    /// entry (`1 / w^2` per row). A marginal likelihood adds it to the cost.
    pub(crate) fn noise_log_det(&self, theta: &[f64], free: &[bool]) -> f64 {
        covariance_log_det(
            &self.obs_plan(theta).links,
            &self.prior_rows(theta),
            |col| free[col],
        )
    }
}

/// [`Model::noise_log_det`] from a chain's links (`u_k = 1 / sqrt(S_k)`) and
/// prior rows, counting the rows with an entry where `free` holds:
/// `sum -2 ln u_k + sum over rows -2 ln w`, `w` a row's largest free entry.
pub(crate) fn covariance_log_det(
    links: &[Link],
    prior: &PriorRows,
    free: impl Fn(usize) -> bool,
) -> f64 {
    let obs: f64 = links.iter().map(|l| -2.0 * l.u.ln()).sum();
    let mut weight = vec![0.0f64; prior.residuals.len()];
    for &(row, col, v) in &prior.entries {
        if free(col) {
            weight[row] = weight[row].max(v.abs());
        }
    }
    obs + weight
        .iter()
        .filter(|w| **w > 0.0)
        .map(|w| -2.0 * w.ln())
        .sum::<f64>()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(t: f64, axis: usize, baro: bool) -> Observation {
        gm_obs(t, axis, baro, 1.0, 0.0)
    }

    fn gm_obs(t: f64, axis: usize, baro: bool, sd_gm: f64, sd_white: f64) -> Observation {
        Observation {
            row: 0,
            axis,
            target: 0.0,
            sd_white,
            sd_gm,
            baro,
            t,
            update: 1.0,
        }
    }

    /// Innovations of misfits `m` as the whitener computes them.
    fn innovations(l: &[Link], m: &[f64]) -> Vec<f64> {
        filtered(l, m).0
    }

    /// Innovations of misfits `m` and the filtered wander after each.
    fn filtered(l: &[Link], m: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let mut z = vec![0.0; m.len()];
        let e = (0..m.len())
            .map(|k| {
                let zp = l[k].prev.map_or(0.0, |j| z[j]);
                z[k] = l[k].alpha * zp + l[k].kappa * m[k];
                l[k].u * m[k] + l[k].v * zp
            })
            .collect();
        (e, z)
    }

    #[test]
    fn the_guess_recovers_a_wander_and_its_jitter() {
        // Two axes of 1 Hz fixes, wander 2 m over 15 s plus 0.5 m of jitter,
        // an outage in the middle.
        let mut rng = crate::simulation::rng::Rng::new(5);
        let (sigma, tau, jitter) = (2.0, 15.0, 0.5);
        let a = (-1.0f64 / tau).exp();
        let mut misfits = Vec::new();
        let mut n = [sigma * rng.normal(), sigma * rng.normal()];
        for k in 0..4000 {
            let t = k as f64 + if k >= 2000 { 60.0 } else { 0.0 };
            for (axis, e) in n.iter_mut().enumerate() {
                *e = a * *e + (1.0 - a * a).sqrt() * sigma * rng.normal();
                misfits.push((t, axis, *e + jitter * rng.normal()));
            }
        }
        let (s, t, j) = gps_noise_guess(&misfits).unwrap();
        assert!((s / sigma - 1.0).abs() < 0.1, "sigma {s}");
        assert!((t / tau - 1.0).abs() < 0.3, "tau {t}");
        assert!((j / jitter - 1.0).abs() < 0.2, "jitter {j}");
        // White errors: no positive correlation, no guess of tau.
        let white: Vec<_> = (0..400).map(|k| (k as f64, 0, rng.normal())).collect();
        let guess = gps_noise_guess(&white);
        assert!(guess.is_none_or(|(_, t, _)| t < 1.0), "{guess:?}");
        assert_eq!(gps_noise_guess(&white[..5]), None, "too few pairs");
    }

    #[test]
    fn links_follow_each_axis_and_bridge_an_outage() {
        let o = vec![
            obs(0.0, 0, false),
            obs(0.0, 1, false),
            gm_obs(0.0, 2, true, 0.0, 0.5),
            obs(1.0, 0, false),
            obs(1.0, 1, false),
            gm_obs(1.0, 2, true, 0.0, 0.5),
            obs(30.0, 0, false),
            obs(31.0, 0, false),
        ];
        let l = links(&o, [Some(60.0); 3]);
        assert_eq!(l[0].prev, None);
        assert_eq!(l[3].prev, Some(0));
        assert_eq!(l[4].prev, Some(1));
        assert_eq!(
            l[5],
            Link::independent(0.5),
            "barometric rows are never linked"
        );
        // A 29 s gap is bridged: a = exp(-29 / 60), S = q^2 (1 - a^2) (no jitter).
        assert_eq!(l[6].prev, Some(3), "29 s gap: the wander carries on");
        let a29 = (-29.0f64 / 60.0).exp();
        assert!((l[6].u - 1.0 / (1.0 - a29 * a29).sqrt()).abs() < 1e-9);
        assert!((l[6].v / l[6].u + a29).abs() < 1e-15);
        assert_eq!(l[7].prev, Some(6));
        // Without a jitter: e' = (m_k - a m_{k-1}) / (sigma sqrt(1 - a^2)).
        let a = (-1.0f64 / 60.0).exp();
        assert!((l[7].v / l[7].u + a).abs() < 1e-15);
        assert!((l[7].u - 1.0 / (1.0 - a * a).sqrt()).abs() < 1e-9);
        assert_eq!((l[7].alpha, l[7].kappa), (0.0, 1.0));
        for tau in [None, Some(0.0)] {
            assert!(
                links(&o, [tau; 3])
                    .iter()
                    .all(|l| l.prev.is_none() && l.kappa == 0.0)
            );
        }
    }

    #[test]
    fn the_filter_is_the_exact_whitening_of_wander_plus_jitter() {
        // Wander 1.5 m over 20 s east and 3 m over 50 s up (the heights'
        // own correlation time), plus a per-fix jitter, with a 30 s outage
        // bridged: sum e'^2 = m^T Sigma^-1 m and sum ln S = ln det Sigma.
        let taus = [Some(20.0), None, Some(50.0)];
        let mut o = Vec::new();
        for k in 0..40 {
            let t = k as f64 * 0.7 + if k >= 25 { 30.0 } else { 0.0 };
            o.push(gm_obs(t, 0, false, 1.5, 0.2 + 0.1 * (k % 4) as f64));
            o.push(gm_obs(t, 2, false, 3.0, 0.6));
        }
        let n = o.len();
        let l = links(&o, taus);
        let sigma = nalgebra::DMatrix::from_fn(n, n, |i, j| {
            let (a, b) = (&o[i], &o[j]);
            let wander = match taus[a.axis] {
                Some(tau) if a.axis == b.axis => {
                    a.sd_gm * b.sd_gm * (-(a.t - b.t).abs() / tau).exp()
                }
                _ => 0.0,
            };
            wander + if i == j { a.sd_white.powi(2) } else { 0.0 }
        });
        let m: Vec<f64> = (0..n).map(|k| (k as f64 * 0.37).sin() * 2.0).collect();
        let mv = nalgebra::DVector::from_column_slice(&m);
        let chol = sigma.cholesky().unwrap();
        let want = mv.dot(&chol.solve(&mv));
        let got: f64 = innovations(&l, &m).iter().map(|e| e * e).sum();
        assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        let log_det: f64 = l.iter().map(|l| -2.0 * l.u.ln()).sum();
        let want = 2.0 * chol.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
        assert!((log_det - want).abs() < 1e-9, "{log_det} vs {want}");
    }

    #[test]
    fn the_robust_filter_does_not_follow_a_jump() {
        // Wander 1.5 m over 60 s plus 0.3 m of jitter, and a 30 m jump from
        // fix 200 to fix 239: the plain filter's wander follows the jump
        // within a few fixes; the robust one's stays put, and it weighs the
        // jump's fixes down and the others hardly at all.
        let (tau, sd_gm, sd_white) = (60.0, 1.5, 0.3);
        let mut rng = crate::simulation::rng::Rng::new(3);
        let a: f64 = (-1.0f64 / tau).exp();
        let mut g = sd_gm * rng.normal();
        let mut m = Vec::new();
        for k in 0..400 {
            g = a * g + (1.0 - a * a).sqrt() * sd_gm * rng.normal();
            let jump = if (200..240).contains(&k) { 30.0 } else { 0.0 };
            m.push(g + sd_white * rng.normal() + jump);
        }
        let mut o: Vec<Observation> = (0..m.len())
            .map(|i| gm_obs(i as f64, 0, false, sd_gm, sd_white))
            .collect();
        let w = robust_updates(&o, [Some(tau); 3], &m, 2.385);
        assert!(w[200..240].iter().all(|w| *w < 0.05), "{:?}", &w[200..240]);
        let typical = w[..200]
            .iter()
            .chain(&w[240..])
            .filter(|w| **w > 0.5)
            .count();
        assert!(
            typical >= 340,
            "{typical} of 360 fixes outside the jump weigh over a half"
        );
        let wander_at = |o: &[Observation], k: usize| filtered(&links(o, [Some(tau); 3]), &m).1[k];
        assert!(wander_at(&o, 220) > 25.0, "the plain filter follows");
        for (o, w) in o.iter_mut().zip(&w) {
            o.update = *w;
        }
        assert!(wander_at(&o, 220).abs() < 5.0, "{}", wander_at(&o, 220));
    }

    #[test]
    fn whitened_gauss_markov_errors_are_white_with_unit_variance() {
        // Simulate the process the whitening inverts; its innovations come back.
        let (tau, sd_gm, sd_white) = (40.0, 1.5, 0.5);
        let mut rng = crate::simulation::rng::Rng::new(5);
        let n = 20_000;
        let mut e = Vec::with_capacity(n);
        let mut x = sd_gm * rng.normal();
        let a: f64 = (-1.0f64 / tau).exp();
        for _ in 0..n {
            e.push(x + sd_white * rng.normal());
            x = a * x + (1.0 - a * a).sqrt() * sd_gm * rng.normal();
        }
        let o: Vec<Observation> = (0..n)
            .map(|i| gm_obs(i as f64, 0, false, sd_gm, sd_white))
            .collect();
        let w = innovations(&links(&o, [Some(tau); 3]), &e);
        let var = w.iter().map(|v| v * v).sum::<f64>() / n as f64;
        let lag1 = w.windows(2).map(|p| p[0] * p[1]).sum::<f64>() / n as f64;
        assert!((var - 1.0).abs() < 0.03, "variance {var}");
        assert!(lag1.abs() < 0.03, "lag-1 correlation {lag1}");
        // The raw errors are anything but white.
        let raw1 = e.windows(2).map(|p| p[0] * p[1]).sum::<f64>() / n as f64;
        assert!(raw1 > 0.8 * sd_gm * sd_gm, "raw lag-1 {raw1}");
    }
}
