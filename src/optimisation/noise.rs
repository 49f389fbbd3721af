//! Noise settings from the ride itself: the GPS error's wander (sigma and
//! correlation time) and jitter, and the bias-walk density, that maximise the
//! restricted marginal likelihood of the linearised model.
//!
//! Why this and not a validation: held-out fixes share their correlated GPS
//! error with the fixes either side, so any held-out score rewards a path that
//! follows the GPS (issue 13 reproduced it: the held-out error picked the
//! loosest prior, 6-12 % further from the truth than the best). The marginal
//! likelihood asks instead how probable the whole ride is under each setting,
//! with the path's parameters integrated out; with the square-root
//! information smoother it costs one chain solve per setting.
//!
//! Linearised at the fitted `theta` (`J`, the whitened residuals `r`, the
//! bias prior rows `r_p`, all depending on the settings `phi`):
//!
//! ```text
//! -2 ln L(phi) = min_d ||r + J d||^2 + ||r_p + J_p d||^2     the fit at phi (one Gauss-Newton step)
//!              + sum_k ln S_k                              the GPS noise covariance (see model::noise)
//!              + sum_p ln (1 / w_p^2)                        the bias-walk prior's covariance
//!              + ln det (J^T J + J_p^T J_p)                  the parameters integrated out
//! ```
//!
//! up to a constant. The unpenalised directions (start, gain, the bias
//! level) are integrated with a flat prior, which makes this the restricted
//! (REML) likelihood: it does not shrink the noise by the parameters fitted.
//! Why a jitter as well as a wander: with a wander alone the white part of
//! real errors reads as fast wander, and the likelihood trades the correlation
//! time away (on simulated rides with a 60 s wander plus 0.5 m of jitter it
//! chose 3 s), which left the path's sigma a third of its error (32.6 % of the
//! truth inside the 95 % ellipse). The vertical GPS sigma keeps its ratio to the horizontal one. The
//! uncertainty of each setting is the curvature of `-2 ln L` in its
//! logarithm (`sd(ln phi) = sqrt(2 / f'')`, the inverse of the Hessian).

use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::DMatrix;
use rayon::prelude::*;

use crate::model::{ChainSystem, Model, ModelSpec};

/// Which noise settings a fit estimates from the data.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct AutoNoise {
    /// The GPS wander (sigma and correlation time) and jitter.
    pub gps: bool,
    /// The bias-walk density of the segment prior.
    pub walk: bool,
}

/// The GPS noise is estimated by default, the bias walk is not: a
/// temperature-driven bias (or any slow effect the model lacks) looks like a
/// faster walk, and with the walk estimated the diagnosis no longer finds it
/// significant (measured on the hidden-effect rides: t 1.9 instead of above
/// 2). `--bias-walk auto` asks for it.
impl Default for AutoNoise {
    fn default() -> Self {
        Self {
            gps: true,
            walk: false,
        }
    }
}

impl AutoNoise {
    pub const OFF: AutoNoise = AutoNoise {
        gps: false,
        walk: false,
    };

    pub fn any(&self) -> bool {
        self.gps || self.walk
    }
}

/// A setting and its 1-sigma range (the range is multiplicative: the
/// likelihood is close to Gaussian in the logarithm).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimated {
    pub value: f64,
    pub low: f64,
    pub high: f64,
    /// Estimated (`false`: held at the value given).
    pub estimated: bool,
    /// Whether the ride only bounds the setting from one side.
    #[serde(default)]
    pub limit: Limit,
}

/// A setting the likelihood keeps pushing to the edge of the search: the
/// ride cannot tell how far beyond it the setting lies (a correlation time
/// longer than the ride, a jitter too small to see), only that it is beyond
/// `low` (`AtLeast`) or within `high` (`AtMost`), at 1 sigma.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Limit {
    #[default]
    None,
    AtLeast,
    AtMost,
}

impl Estimated {
    pub(crate) fn held(value: f64) -> Self {
        Self {
            value,
            low: value,
            high: value,
            estimated: false,
            limit: Limit::None,
        }
    }

    /// `value` with its range, e.g. "2.1 m (1.8-2.5)", or its one-sided
    /// bound, e.g. "at most 0.03 m".
    pub fn describe(&self, unit: &str, digits: usize) -> String {
        if self.limit == Limit::AtLeast {
            format!("at least {:.d$} {unit}", self.low, d = digits)
        } else if self.limit == Limit::AtMost {
            format!("at most {:.d$} {unit}", self.high, d = digits)
        } else if self.estimated {
            format!(
                "{:.d$} {unit} ({:.d$}-{:.d$})",
                self.value,
                self.low,
                self.high,
                d = digits
            )
        } else {
            format!("{:.d$} {unit} (set)", self.value, d = digits)
        }
    }
}

/// The noise settings the data prefer.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseEstimate {
    /// GPS horizontal sigma per axis (m).
    pub gps_sigma_m: Estimated,
    /// Correlation time of the GPS error (s).
    pub gps_tau_s: Estimated,
    /// The jitter of each fix on top of the wander (m per axis, horizontal).
    #[serde(default = "no_jitter")]
    pub gps_white_m: Estimated,
    /// Bias-walk density (deg/s/sqrt(s)).
    pub bias_walk: Estimated,
    /// `-2 ln L` at the choice.
    pub neg2_log_likelihood: f64,
    /// Likelihood evaluations (chain solves) the search took.
    pub evaluations: usize,
}

impl NoiseEstimate {
    /// `spec` with the settings of `which` replaced by these.
    pub fn apply(&self, spec: &ModelSpec, which: AutoNoise) -> ModelSpec {
        let x = [
            self.gps_sigma_m.value,
            self.gps_tau_s.value,
            self.bias_walk.value,
            self.gps_white_m.value.max(BOUNDS[3].0),
        ];
        spec_at(spec, x.map(f64::ln), which)
    }

    /// The GPS error's correlation in words: "correlated over 3 s (2-4)", or independent fixes.
    pub fn tau_text(&self) -> String {
        if self.gps_tau_s.limit == Limit::AtLeast {
            format!(
                "correlated over {} (more than the ride can tell)",
                self.gps_tau_s.describe("s", 0)
            )
        } else if self.gps_tau_s.value > 0.0 {
            format!("correlated over {}", self.gps_tau_s.describe("s", 0))
        } else {
            "independent fixes (set)".to_string()
        }
    }

    /// The bias walk in words, or no prior.
    pub fn walk_text(&self, unit: &str) -> String {
        if self.bias_walk.value > 0.0 {
            self.bias_walk.describe(unit, 4)
        } else {
            "no prior (set)".to_string()
        }
    }

    /// The jitter in words, or none.
    pub fn jitter_text(&self) -> String {
        if self.gps_tau_s.value > 0.0 {
            format!("jitter {}", self.gps_white_m.describe("m", 2))
        } else {
            "no jitter apart".to_string()
        }
    }

    /// One line for a summary.
    pub fn describe(&self) -> String {
        format!(
            "GPS sigma {}, {}, {}, bias walk {}",
            self.gps_sigma_m.describe("m", 2),
            self.tau_text(),
            self.jitter_text(),
            self.walk_text("deg/s/sqrt(s)")
        )
    }
}

/// Reports written before the jitter was modelled had none.
fn no_jitter() -> Estimated {
    Estimated::held(0.0)
}

/// Bounds of the search (natural units): sigma (m), tau (s), walk
/// (deg/s/sqrt(s)), jitter (m; at the floor the fixes have none to speak of).
const BOUNDS: [(f64, f64); 4] = [(0.05, 100.0), (0.3, 1800.0), (1e-5, 0.5), (0.01, 100.0)];

/// The search stops when the simplex is this small in every log-setting (a
/// quarter of a typical 1-sigma range: 0.02 took 139 likelihoods on a
/// 30-minute ride instead of 75, to move the settings well inside their
/// ranges), or when its corners' `-2 ln L` are this close (all within half a
/// sigma of each other: along a ridge, such as `sigma^2 / tau` when tau nears
/// the ride's length, the simplex otherwise crawls on with nothing to gain).
const NM_TOLERANCE: Tolerance = Tolerance { x: 0.05, f: 0.2 };

/// When [`nelder_mead`] stops: the simplex's size in every coordinate, or the
/// spread of its values.
#[derive(Clone, Copy, Debug)]
struct Tolerance {
    x: f64,
    f: f64,
}

/// Correlation time the search starts from when none is set (s).
const START_TAU_S: f64 = 20.0;

/// The settings of `spec` as a point in log space.
fn point(spec: &ModelSpec) -> [f64; 4] {
    [
        spec.sigma_horizontal_m.ln(),
        spec.gps_tau_s
            .filter(|t| *t > 0.0)
            .unwrap_or(START_TAU_S)
            .ln(),
        spec.bias_walk_dps_sqrt_s
            .unwrap_or(crate::model::DEFAULT_BIAS_WALK)
            .ln(),
        spec.gps_white_m.max(BOUNDS[3].0).ln(),
    ]
}

/// The search's bounds for a ride whose fixes span `span` seconds: a
/// correlation time longer than the ride is no longer identified (a wander
/// that slow is an offset plus a drift over the ride, and only the drift
/// `sigma^2 / tau` shows), so the search stops at the ride's length and says
/// the time is at least that long.
fn bounds_for(span: f64) -> [(f64, f64); 4] {
    let mut b = BOUNDS;
    b[1].1 = span.clamp(10.0 * b[1].0, b[1].1);
    b
}

fn clamp(x: [f64; 4], bounds: &[(f64, f64); 4]) -> [f64; 4] {
    let mut y = x;
    for (v, (lo, hi)) in y.iter_mut().zip(bounds) {
        *v = v.clamp(lo.ln(), hi.ln());
    }
    y
}

/// `spec` with the settings `which` covers taken from the log-space point
/// `x` (sigma, tau, walk, jitter); the others stay as set (independent fixes, no
/// prior), so the likelihood is that of the model the fit will run.
fn spec_at(spec: &ModelSpec, x: [f64; 4], which: AutoNoise) -> ModelSpec {
    let mut out = spec.clone();
    if which.gps {
        let ratio = spec.sigma_vertical_m / spec.sigma_horizontal_m;
        out.sigma_horizontal_m = x[0].exp();
        out.sigma_vertical_m = x[0].exp() * ratio;
        out.gps_tau_s = Some(x[1].exp());
        out.gps_white_m = x[3].exp();
    }
    if which.walk {
        out.bias_walk_dps_sqrt_s = Some(x[2].exp());
    }
    out
}

/// `-2 ln L` of `spec` linearised at `theta` over the `free` parameters
/// (see the module docs), from `base`, the chain system of `model` there;
/// `None` when the solve fails.
pub fn neg2_log_likelihood(
    model: &Model,
    base: &ChainSystem,
    theta: &[f64],
    free: &[bool],
    spec: &ModelSpec,
) -> Option<f64> {
    let m = Model::with_start(model.signals.clone(), spec.clone(), model.start.clone()).ok()?;
    let chain = m.chain_system_like(base, theta)?;
    let (delta, log_det) = chain.solve_with_log_det(0.0)?;
    let fit = chain.cost() - chain.predicted_decrease(&delta);
    let v = fit + m.noise_log_det(theta, free) + log_det;
    v.is_finite().then_some(v)
}

/// The noise settings that maximise the restricted likelihood of `model` at
/// `theta`, starting from the model's own; `which` says which are free.
/// `None` when the model has no segment biases (nothing to balance) or the
/// likelihood cannot be evaluated at the start.
pub fn estimate(
    model: &Model,
    theta: &[f64],
    free: &[bool],
    which: AutoNoise,
) -> Option<NoiseEstimate> {
    let spec = &model.spec;
    let dims: Vec<usize> = [
        (0, which.gps),
        (1, which.gps),
        (3, which.gps),
        (2, which.walk),
    ]
    .iter()
    .filter(|(_, on)| *on)
    .map(|(d, _)| *d)
    .collect();
    // The path's derivatives do not depend on the noise: linearise once.
    let base = model.chain_system(theta, free)?;
    let fixes = &model.signals.fixes;
    let span = fixes
        .last()
        .zip(fixes.first())
        .map_or(0.0, |(l, f)| l.t - f.t);
    let bounds = bounds_for(span);
    let mut x0 = point(spec);
    // The GPS settings start from the fit's own misfits, not from the
    // settings as set (3 m and 20 s, typically tens of times off): a
    // shorter search.
    if which.gps
        && let Some((sigma, tau, jitter)) = model.gps_noise_guess(theta, &base.linearisation().x)
    {
        x0[0] = sigma.ln();
        x0[1] = tau.ln();
        x0[3] = jitter.max(BOUNDS[3].0).ln();
    }
    let x0 = clamp(x0, &bounds);
    let evaluations = AtomicUsize::new(0);
    // -2 ln L at a log-space point; outside the bounds the clamped value
    // plus a wall, so that a search turns back.
    let at = |x: [f64; 4]| -> f64 {
        evaluations.fetch_add(1, Ordering::Relaxed);
        let inside = clamp(x, &bounds);
        neg2_log_likelihood(model, &base, theta, free, &spec_at(spec, inside, which)).map_or(
            f64::INFINITY,
            |v| {
                v + 1e3
                    * x.iter()
                        .zip(inside)
                        .map(|(a, b)| (a - b).abs())
                        .sum::<f64>()
            },
        )
    };
    let side_by_side = fixes.len() <= SIDE_BY_SIDE_FIXES;
    let f = |y: &[f64]| at(with(x0, &dims, y));
    let y0: Vec<f64> = dims.iter().map(|&d| x0[d]).collect();
    let f0 = f(&y0);
    if !f0.is_finite() {
        return None;
    }
    let (mut x, mut value) = if dims.is_empty() {
        (x0, f0)
    } else {
        // The jitter is pinned down by every pair of fixes (its range is a
        // few per cent), the others by the ride as a whole.
        let steps: Vec<f64> = dims
            .iter()
            .map(|&d| if d == 3 { 0.2 } else { 0.7 })
            .collect();
        let objective = Objective {
            f: &f,
            side_by_side,
        };
        let (best, value) = nelder_mead(objective, &y0, f0, &steps, NM_TOLERANCE, 120);
        (with(x0, &dims, &best), value)
    };
    // A setting at an edge of the search is bounded from one side only.
    let mut limit = [Limit::None; 4];
    for &d in &dims {
        let (lo, hi) = (bounds[d].0.ln(), bounds[d].1.ln());
        if x[d] > hi - AT_EDGE {
            (x[d], limit[d]) = (hi, Limit::AtLeast);
        } else if x[d] < lo + AT_EDGE {
            (x[d], limit[d]) = (lo, Limit::AtMost);
        }
    }
    if limit.iter().any(|l| *l != Limit::None) {
        value = at(x);
    }
    // The others' ranges from the curvature, with those held at the edge.
    let inner: Vec<usize> = dims
        .iter()
        .copied()
        .filter(|&d| limit[d] == Limit::None)
        .collect();
    let f_inner = |y: &[f64]| at(with(x, &inner, y));
    let y_inner: Vec<f64> = inner.iter().map(|&d| x[d]).collect();
    let sd = log_sd(
        Objective {
            f: &f_inner,
            side_by_side,
        },
        &y_inner,
        value,
    );
    // How far in from the edge the likelihood allows: along the ridge
    // `sigma^2 / tau` for the correlation time (with sigma free), else alone.
    let mut reach = [0.0; 4];
    for &d in &dims {
        let inward = match limit[d] {
            Limit::None => continue,
            Limit::AtLeast => -1.0,
            Limit::AtMost => 1.0,
        };
        let mut dir = [0.0; 4];
        dir[d] = inward;
        if d == 1 && inner.contains(&0) {
            dir[0] = 0.5 * inward;
        }
        let along = |t: &[f64]| at(std::array::from_fn(|k| x[k] + t[0] * dir[k]));
        reach[d] = one_sided(
            Objective {
                f: &along,
                side_by_side,
            },
            value,
        );
    }
    let evaluations = evaluations.into_inner();
    let est = |d: usize| {
        if !dims.contains(&d) {
            // As set (0: independent fixes, no prior).
            return Estimated::held(
                [
                    spec.sigma_horizontal_m,
                    spec.gps_tau_s.unwrap_or(0.0),
                    spec.bias_walk_dps_sqrt_s.unwrap_or(0.0),
                    spec.gps_white_m,
                ][d],
            );
        }
        let (lo, hi) = (bounds[d].0.ln(), bounds[d].1.ln());
        let (low, high) = match limit[d] {
            Limit::None => {
                let s = inner
                    .iter()
                    .position(|&e| e == d)
                    .map_or(f64::INFINITY, |i| sd[i])
                    .min(5.0);
                (x[d] - s, x[d] + s)
            }
            Limit::AtLeast => ((x[d] - reach[d]).max(lo), x[d]),
            Limit::AtMost => (x[d], (x[d] + reach[d]).min(hi)),
        };
        Estimated {
            value: x[d].exp(),
            low: low.exp(),
            high: high.exp(),
            estimated: true,
            limit: limit[d],
        }
    };
    Some(NoiseEstimate {
        gps_sigma_m: est(0),
        gps_tau_s: est(1),
        gps_white_m: est(3),
        bias_walk: est(2),
        neg2_log_likelihood: value,
        evaluations,
    })
}

/// `x` with the coordinates `dims` replaced by `y`.
fn with(x: [f64; 4], dims: &[usize], y: &[f64]) -> [f64; 4] {
    let mut out = x;
    for (&d, &v) in dims.iter().zip(y) {
        out[d] = v;
    }
    out
}

/// A search that ends this close to a bound (in the logarithm) ended at it:
/// closer than the curvature's step, whose points beyond the bound would
/// meet the wall and read as a tight range (a 60 s drive came out
/// "correlated over 1665 s (1624-1707)").
const AT_EDGE: f64 = HESSIAN_STEP;

/// Steps (in the logarithm) at which [`one_sided`] looks for the edge of the range.
const ONE_SIDED_STEPS: [f64; 4] = [0.35, 0.7, 1.4, 2.8];

/// How far `t >= 0` goes before `f(t)` rises by 1 above `f0 = f(0)` (the
/// 1-sigma edge of `-2 ln L`), interpolated between [`ONE_SIDED_STEPS`];
/// infinite if it does not rise that much within them.
fn one_sided(f: Objective, f0: f64) -> f64 {
    let points: Vec<Vec<f64>> = ONE_SIDED_STEPS.iter().map(|&t| vec![t]).collect();
    let values = f.values(&points);
    let (mut t_prev, mut rise_prev) = (0.0, 0.0);
    for (&t, v) in ONE_SIDED_STEPS.iter().zip(values) {
        let rise = v - f0;
        if rise >= 1.0 {
            return t_prev + (t - t_prev) * (1.0 - rise_prev) / (rise - rise_prev);
        }
        (t_prev, rise_prev) = (t, rise.max(rise_prev));
    }
    f64::INFINITY
}

/// Segment lengths (s) whose likelihood [`segment_preference`] compares.
pub const SEGMENT_CHOICES: [f64; 5] = [2.5, 5.0, 10.0, 20.0, 40.0];

/// What the data say about the segment length: `-2 ln L` of the model with
/// each of [`SEGMENT_CHOICES`] (its noise settings unchanged; the walk prior
/// scales with the length, so the settings mean the same), each from the
/// fitted parameters carried over onto its segments and one Gauss-Newton
/// step, relative to the best. A difference of a few units is no preference;
/// finer segments than preferred cost time and gain nothing.
pub fn segment_preference(model: &Model, theta: &[f64]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = SEGMENT_CHOICES
        .iter()
        .filter_map(|&seg| {
            let spec = ModelSpec {
                segment_s: seg,
                ..model.spec.clone()
            };
            let m =
                Model::with_start(model.signals.clone(), spec.clone(), model.start.clone()).ok()?;
            let t = m.carry_over(model, theta);
            let free = m.free_mask(&[
                crate::effects::Role::Global,
                crate::effects::Role::Segments,
                crate::effects::Role::Step2Only,
            ]);
            let base = m.chain_system(&t, &free)?;
            Some((seg, neg2_log_likelihood(&m, &base, &t, &free, &spec)?))
        })
        .collect();
    let best = out.iter().map(|v| v.1).fold(f64::INFINITY, f64::min);
    for v in &mut out {
        v.1 -= best;
    }
    out
}

/// A function of the log-settings, evaluated side by side where it can be.
#[derive(Clone, Copy)]
struct Objective<'a> {
    f: &'a (dyn Fn(&[f64]) -> f64 + Sync),
    /// Evaluate independent points in parallel. Each evaluation holds a
    /// model and a chain system of its own, about 3 kB per fix (60 MB on a
    /// 6-hour ride): past [`SIDE_BY_SIDE_FIXES`] one at a time.
    side_by_side: bool,
}

/// Rides with more fixes than this search their noise one evaluation at a time.
const SIDE_BY_SIDE_FIXES: usize = 10_000;

impl Objective<'_> {
    fn at(&self, x: &[f64]) -> f64 {
        (self.f)(x)
    }

    /// The function at each of `points`.
    fn values(&self, points: &[Vec<f64>]) -> Vec<f64> {
        if self.side_by_side {
            points.par_iter().map(|p| self.at(p)).collect()
        } else {
            points.iter().map(|p| self.at(p)).collect()
        }
    }
}

/// Nelder-Mead minimisation from `x0` (where `f` is `f0`) with initial steps
/// `step` (per coordinate), until the simplex is within `tol` or `max_eval`
/// is spent. The path is the textbook one-at-a-time method's; what
/// does not depend on an earlier value is evaluated side by side (the first
/// simplex, the expansion with the reflection, a shrink), which on two cores
/// takes a third off the search's time.
fn nelder_mead(
    f: Objective,
    x0: &[f64],
    f0: f64,
    step: &[f64],
    tol: Tolerance,
    max_eval: usize,
) -> (Vec<f64>, f64) {
    let n = x0.len();
    let moved: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let mut x = x0.to_vec();
            x[i] += step[i];
            x
        })
        .collect();
    let mut simplex: Vec<(Vec<f64>, f64)> = std::iter::once((x0.to_vec(), f0))
        .chain(moved.iter().cloned().zip(f.values(&moved)))
        .collect();
    let mut evals = n + 1;
    let point = |c: &[f64], d: &[f64], t: f64| -> Vec<f64> {
        c.iter().zip(d).map(|(a, b)| a + t * (b - a)).collect()
    };
    while evals < max_eval {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let spread = (0..n)
            .map(|d| {
                let (lo, hi) = simplex
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                        (lo.min(s.0[d]), hi.max(s.0[d]))
                    });
                hi - lo
            })
            .fold(0.0, f64::max);
        if spread < tol.x || simplex[n].1 - simplex[0].1 < tol.f {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|d| simplex[..n].iter().map(|s| s.0[d]).sum::<f64>() / n as f64)
            .collect();
        let worst = simplex[n].clone();
        let reflected = point(&centroid, &worst.0, -1.0);
        let expanded = point(&centroid, &worst.0, -2.0);
        // The expansion is only used when the reflection is the best point
        // yet: evaluated with it when side by side, else only then.
        let (fr, speculative) = if f.side_by_side {
            let both = f.values(&[reflected.clone(), expanded.clone()]);
            (both[0], Some(both[1]))
        } else {
            (f.at(&reflected), None)
        };
        evals += 1 + usize::from(speculative.is_some());
        if fr < simplex[0].1 {
            let fe = match speculative {
                Some(v) => v,
                None => {
                    evals += 1;
                    f.at(&expanded)
                }
            };
            simplex[n] = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (reflected, fr);
        } else {
            let contracted = if fr < worst.1 {
                point(&centroid, &reflected, 0.5)
            } else {
                point(&centroid, &worst.0, 0.5)
            };
            let fc = f.at(&contracted);
            evals += 1;
            if fc < worst.1.min(fr) {
                simplex[n] = (contracted, fc);
            } else {
                let best = simplex[0].0.clone();
                let shrunk: Vec<Vec<f64>> = simplex[1..]
                    .iter()
                    .map(|s| point(&best, &s.0, 0.5))
                    .collect();
                let values = f.values(&shrunk);
                evals += n;
                for (s, (x, v)) in simplex[1..].iter_mut().zip(shrunk.into_iter().zip(values)) {
                    *s = (x, v);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    simplex.swap_remove(0)
}

/// Step of the finite-difference Hessian (in the logarithm of a setting).
const HESSIAN_STEP: f64 = 0.15;

/// Standard deviations of the log-settings: `sqrt(diag(2 H^-1))` with `H`
/// the finite-difference Hessian of `f = -2 ln L` at its minimum `x` (central
/// differences, evaluated side by side); a direction the likelihood does not
/// curve in gets an infinite one.
fn log_sd(f: Objective, x: &[f64], fx: f64) -> Vec<f64> {
    let n = x.len();
    let h = HESSIAN_STEP;
    let at = |moves: &[(usize, f64)]| {
        let mut y = x.to_vec();
        for &(d, s) in moves {
            y[d] += s;
        }
        y
    };
    let mut points = Vec::new();
    for i in 0..n {
        points.push(at(&[(i, h)]));
        points.push(at(&[(i, -h)]));
        for j in 0..i {
            for (si, sj) in [(h, h), (h, -h), (-h, h), (-h, -h)] {
                points.push(at(&[(i, si), (j, sj)]));
            }
        }
    }
    let mut values = f.values(&points).into_iter();
    let mut next = || values.next().unwrap_or(f64::NAN);
    let mut hess = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        let (p, m) = (next(), next());
        hess[(i, i)] = (p - 2.0 * fx + m) / (h * h);
        for j in 0..i {
            let (pp, pm, mp, mm) = (next(), next(), next(), next());
            let v = (pp - pm - mp + mm) / (4.0 * h * h);
            hess[(i, j)] = v;
            hess[(j, i)] = v;
        }
    }
    match hess.clone().cholesky() {
        Some(ch) => {
            let inv = ch.inverse();
            (0..n)
                .map(|i| (2.0 * inv[(i, i)]).max(0.0).sqrt())
                .collect()
        }
        None => (0..n)
            .map(|i| {
                let c = hess[(i, i)];
                if c > 0.0 {
                    (2.0 / c).sqrt()
                } else {
                    f64::INFINITY
                }
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    #[test]
    fn nelder_mead_finds_a_quadratic_minimum() {
        let f = |x: &[f64]| (x[0] - 1.0).powi(2) + 3.0 * (x[1] + 2.0).powi(2) + x[0] * x[1];
        for side_by_side in [true, false] {
            let objective = Objective {
                f: &f,
                side_by_side,
            };
            let (x, _) = nelder_mead(
                objective,
                &[0.0, 0.0],
                f(&[0.0, 0.0]),
                &[0.5, 0.5],
                Tolerance { x: 1e-6, f: 0.0 },
                500,
            );
            // Minimum of the quadratic: solve the 2x2 system.
            let a = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 6.0]);
            let b = DVector::from_vec(vec![2.0, -12.0]);
            let want = a.lu().solve(&b).unwrap();
            assert!(
                (x[0] - want[0]).abs() < 1e-4 && (x[1] - want[1]).abs() < 1e-4,
                "{x:?} vs {want}"
            );
        }
    }

    #[test]
    fn one_sided_reach_is_where_the_likelihood_rises_by_one() {
        // -2 ln L rising as (t / 0.5)^2: 1 at t = 0.5, found between steps to within 10 %.
        let rising = |t: &[f64]| 7.0 + (t[0] / 0.5).powi(2);
        let reach = one_sided(
            Objective {
                f: &rising,
                side_by_side: false,
            },
            7.0,
        );
        assert!((reach - 0.5).abs() < 0.05, "{reach}");
        // Flat: no edge within the steps.
        let flat = |t: &[f64]| 7.0 + 0.01 * t[0];
        let reach = one_sided(
            Objective {
                f: &flat,
                side_by_side: true,
            },
            7.0,
        );
        assert!(reach.is_infinite(), "{reach}");
    }

    #[test]
    fn a_setting_at_the_edge_is_described_from_one_side() {
        let tau = Estimated {
            value: 59.0,
            low: 25.0,
            high: 59.0,
            estimated: true,
            limit: Limit::AtLeast,
        };
        assert_eq!(tau.describe("s", 0), "at least 25 s");
        let jitter = Estimated {
            value: 0.01,
            low: 0.01,
            high: 0.03,
            estimated: true,
            limit: Limit::AtMost,
        };
        assert_eq!(jitter.describe("m", 2), "at most 0.03 m");
    }

    #[test]
    fn log_sd_inverts_the_curvature() {
        // f = -2 ln L of a Gaussian in x with sd 0.3: f = (x / 0.3)^2.
        let f = |x: &[f64]| (x[0] / 0.3).powi(2) + (x[1] / 0.1).powi(2);
        let objective = Objective {
            f: &f,
            side_by_side: true,
        };
        let sd = log_sd(objective, &[0.0, 0.0], 0.0);
        assert!((sd[0] - 0.3).abs() < 1e-9, "{sd:?}");
        assert!((sd[1] - 0.1).abs() < 1e-9, "{sd:?}");
    }
}
