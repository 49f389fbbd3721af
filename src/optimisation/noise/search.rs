//! The search itself: a bounded Newton method on a likelihood that is
//! expensive and a little noisy, its curvature from a finite-difference
//! stencil evaluated side by side, one-sided steps along weak directions.

use super::*;

/// Steps (in the logarithm) at which [`one_sided`] looks for the edge of the range.
pub(super) const ONE_SIDED_STEPS: [f64; 4] = [0.35, 0.7, 1.4, 2.8];

/// Halvings of the bracket [`one_sided`] found, before it interpolates.
pub(super) const ONE_SIDED_HALVINGS: usize = 3;

/// How far `t >= 0` goes before `f(t)` rises by 1 above `f0 = f(0)` (the
/// 1-sigma edge of `-2 ln L`): bracketed by [`ONE_SIDED_STEPS`] short of
/// `wall` and `wall` itself (side by side), the bracket halved
/// [`ONE_SIDED_HALVINGS`] times, then interpolated; `wall` (where the
/// search's bounds stop `t`) if it does not rise that much before it.
///
/// Without the step at the wall a direction still flat at the last step
/// read as infinite, and every setting with a share of it as unbounded:
/// with the bias walk estimated on Berlin's drive, whose walk is flat
/// towards zero, the GPS sigma was reported as "13.39 m (12.27-100.00)".
pub(super) fn one_sided(f: Objective, f0: f64, wall: f64) -> f64 {
    let mut steps: Vec<f64> = ONE_SIDED_STEPS
        .iter()
        .copied()
        .filter(|&t| t < wall)
        .collect();
    if wall.is_finite() {
        steps.push(wall);
    }
    let points: Vec<Vec<f64>> = steps.iter().map(|&t| vec![t]).collect();
    let values = f.values(&points);
    let (mut lo, mut rise_lo) = (0.0, 0.0);
    for (&t, v) in steps.iter().zip(values) {
        let rise = v - f0;
        if rise >= 1.0 {
            let (mut hi, mut rise_hi) = (t, rise);
            for _ in 0..ONE_SIDED_HALVINGS {
                let mid = 0.5 * (lo + hi);
                let r = f.at(&[mid]) - f0;
                if r >= 1.0 {
                    (hi, rise_hi) = (mid, r);
                } else {
                    (lo, rise_lo) = (mid, r.max(rise_lo));
                }
            }
            return lo + (hi - lo) * (1.0 - rise_lo) / (rise_hi - rise_lo);
        }
        (lo, rise_lo) = (t, rise.max(rise_lo));
    }
    wall
}

/// A function of the log-settings, evaluated side by side where it can be.
#[derive(Clone, Copy)]
pub(super) struct Objective<'a> {
    pub(super) f: &'a (dyn Fn(&[f64]) -> f64 + Sync),
    /// Evaluate independent points in parallel. Each evaluation holds a
    /// model and a chain system of its own, about 3 kB per fix (60 MB on a
    /// 6-hour ride): past [`SIDE_BY_SIDE_FIXES`] one at a time.
    pub(super) side_by_side: bool,
}

/// Rides with more fixes than this search their noise one evaluation at a time.
pub(super) const SIDE_BY_SIDE_FIXES: usize = 10_000;

impl Objective<'_> {
    pub(super) fn at(&self, x: &[f64]) -> f64 {
        (self.f)(x)
    }

    /// The function at each of `points`.
    pub(super) fn values(&self, points: &[Vec<f64>]) -> Vec<f64> {
        if self.side_by_side {
            points.par_iter().map(|p| self.at(p)).collect()
        } else {
            points.iter().map(|p| self.at(p)).collect()
        }
    }
}

/// The values a [`newton`] search has evaluated, by point (the bits of its
/// coordinates), so that a point asked for again costs nothing; and the
/// spare cores of a round of evaluations put to points likely asked for
/// next. Evaluations side by side run in rounds of as many as there are
/// cores: a stencil of nine on two cores leaves one core idle for its last
/// round, and so do the start's value alone, a single longer line point
/// and the ranges' `f_ij--` points after the search (on a 30-minute ride
/// 36 such rounds for 62 likelihoods). A value is the same whenever it is
/// computed, so what the search finds does not change, only how many
/// rounds it waits for.
pub(super) struct Known {
    values: std::collections::HashMap<Vec<u64>, f64>,
}

impl Known {
    pub(super) fn new() -> Self {
        Self {
            values: std::collections::HashMap::new(),
        }
    }

    fn key(x: &[f64]) -> Vec<u64> {
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// `f` at each of `points`: those not yet known evaluated side by side
    /// (see [`Objective::values`]), with as many of `spare` as fill the
    /// cores that round would leave idle.
    pub(super) fn values(
        &mut self,
        f: &Objective,
        points: &[Vec<f64>],
        spare: &[Vec<f64>],
    ) -> Vec<f64> {
        let mut missing: Vec<Vec<f64>> = Vec::new();
        for p in points {
            if !self.values.contains_key(&Self::key(p)) && !missing.contains(p) {
                missing.push(p.clone());
            }
        }
        if f.side_by_side && !missing.is_empty() {
            let cores = rayon::current_num_threads().max(1);
            let idle = (cores - missing.len() % cores) % cores;
            let extra: Vec<Vec<f64>> = spare
                .iter()
                .filter(|p| !self.values.contains_key(&Self::key(p)) && !missing.contains(p))
                .take(idle)
                .cloned()
                .collect();
            missing.extend(extra);
        }
        for (p, v) in missing.iter().zip(f.values(&missing)) {
            self.values.insert(Self::key(p), v);
        }
        points
            .iter()
            .map(|p| self.values.get(&Self::key(p)).copied().unwrap_or(f64::NAN))
            .collect()
    }

    /// `value` taken as `f` at `x` (a value the caller already has).
    fn insert(&mut self, x: &[f64], value: f64) {
        self.values.insert(Self::key(x), value);
    }

    pub(super) fn at(&mut self, f: &Objective, x: &[f64]) -> f64 {
        self.values(f, &[x.to_vec()], &[])[0]
    }
}

/// The points of [`newton`]'s finite-difference stencil at `x` over the
/// coordinates `free` (step `h`): `x + h e_i`, `x - h e_i` for each, then
/// `x + h e_i + h e_j` for each pair `j < i`.
fn stencil_points(x: &[f64], free: &[usize], h: f64) -> Vec<Vec<f64>> {
    let m = free.len();
    let moved = |moves: &[(usize, f64)]| {
        let mut y = x.to_vec();
        for &(d, s) in moves {
            y[free[d]] += s;
        }
        y
    };
    let mut points = Vec::with_capacity(2 * m + m * (m - 1) / 2);
    for i in 0..m {
        points.push(moved(&[(i, h)]));
        points.push(moved(&[(i, -h)]));
    }
    for i in 0..m {
        for j in 0..i {
            points.push(moved(&[(i, h), (j, h)]));
        }
    }
    points
}

/// The `x - h e_i - h e_j` points (pairs `j < i`) that
/// [`Stencil::symmetric_hessian`] adds to the stencil at `x`.
fn minus_minus_points(x: &[f64], free: &[usize], h: f64) -> Vec<Vec<f64>> {
    let m = free.len();
    let mut points = Vec::with_capacity(m * (m - 1) / 2);
    for i in 0..m {
        for j in 0..i {
            let mut y = x.to_vec();
            y[free[i]] -= h;
            y[free[j]] -= h;
            points.push(y);
        }
    }
    points
}

/// Where a [`newton`] search ended: the minimum `x` (a coordinate the
/// likelihood pushed against a bound held there, `limit` saying which side),
/// `f` there, and how far below and above `x` each log-setting's 1-sigma
/// range reaches (see [`Stencil::ranges`]; infinite where the likelihood
/// does not rise, unused at a bound).
#[derive(Debug)]
pub(super) struct Found {
    pub(super) x: Vec<f64>,
    pub(super) value: f64,
    pub(super) limit: Vec<Limit>,
    pub(super) below: Vec<f64>,
    pub(super) above: Vec<f64>,
}

/// Largest move (in the logarithm of a setting) of one Newton step: a
/// factor of e, about the start's error from the misfits' moments.
pub(super) const MAX_NEWTON_STEP: f64 = 1.0;

/// The search stops after a step smaller than this in every log-setting
/// (a fifth of a typical 1-sigma range) ...
pub(super) const NEWTON_DONE: f64 = 0.05;

/// ... that gains less than this in `-2 ln L`: along the ridge
/// `sigma^2 / tau` that a long correlation time follows, small steps still
/// gain (the Husky robot crawled along it at about 1 a step to the ride's
/// length, and stopped halfway on step size alone).
pub(super) const NEWTON_GAIN: f64 = 0.2;

/// Minimisation of `f` (= `-2 ln L`, smooth and nearly quadratic in the
/// log-settings) from `x0` within `bounds` (log units) by Newton's method on
/// a finite-difference stencil: at `x` the `2m + m(m-1)/2` points
/// `x +- h e_i` and `x + h e_i + h e_j` (all independent, so evaluated side
/// by side) give the gradient and the Hessian
/// `H_ii = (f_i+ - 2 f + f_i-) / h^2`,
/// `H_ij = (f_ij - f_i+ - f_j+ + f) / h^2`, and the step solves
/// `|H| s = -g` (`|H|`: eigenvalues by magnitude, floored, so a saddle or a
/// flat direction still steps downhill), at most [`MAX_NEWTON_STEP`] per
/// coordinate, tried at 1 and 2 times its length side by side (and at 4
/// where 2 beat 1), and at a half and a quarter if none of those lowers
/// `f`. It stops after a step that gains less than [`NEWTON_GAIN`] where
/// the step was below [`NEWTON_DONE`] or the quadratic model, too, expected
/// less than [`NEWTON_GAIN`]: then what is left to gain is a fraction of one unit of
/// `-2 ln L`, a few tenths of each setting's 1-sigma (on the GPS wander's
/// ridge `sigma^2 / tau` the steps went on back and forth by 0.1-0.17 in
/// `ln tau`, whose 1-sigma is 0.37, for more rounds: 66 likelihoods
/// instead of 75 on a 30-minute ride, the same estimate). The model's
/// expectation counts whether or not the stencil curves well in every
/// direction: along a weak one its floored curvature makes the step long
/// and the expectation generous, so an expectation below [`NEWTON_GAIN`]
/// there means a ridge that hardly falls, and the ranges scan it anyway
/// ([`Stencil::ranges`]). Requiring a well-curved stencil as well cost the
/// 30-minute ride a fourth round of eleven likelihoods for 0.04 in
/// `-2 ln L`, and the comma drive 31 likelihoods for 0.03: the
/// forward-difference cross terms read the `sigma^2 / tau` ridge as flatter
/// than the last stencil's symmetric ones do. Near a bound it
/// goes on: the next stencil decides whether the setting is held there.
/// The last stencil, with its cross terms made second-order
/// ([`Stencil::symmetric_hessian`]), gives the ranges: a Nelder-Mead search
/// followed by a central-difference Hessian took 81 likelihoods on a
/// 30-minute ride with three settings and 145 with four; this takes 39 with
/// three, in fewer rounds.
///
/// A coordinate stays `h` inside its bounds while free, so its stencil never
/// meets the wall; when it stands within `2h` of a bound and the step would
/// take it past `h` from it, it is held at the bound (as far as the
/// likelihood can tell, the setting is beyond it).
pub(super) fn newton(
    f: Objective,
    x0: &[f64],
    f0: Option<f64>,
    bounds: &[(f64, f64)],
    max_iter: usize,
) -> Found {
    let n = x0.len();
    let h = HESSIAN_STEP;
    let inside = |d: usize, v: f64| v.clamp(bounds[d].0 + h, bounds[d].1 - h);
    let mut known = Known::new();
    if let Some(v) = f0 {
        known.insert(x0, v);
    }
    let mut x: Vec<f64> = (0..n).map(|d| inside(d, x0[d])).collect();
    let mut limit = vec![Limit::None; n];
    let (mut below, mut above) = (vec![f64::INFINITY; n], vec![f64::INFINITY; n]);
    let mut last: Option<Stencil> = None;
    for _ in 0..max_iter {
        let free: Vec<usize> = (0..n).filter(|&d| limit[d] == Limit::None).collect();
        let m = free.len();
        if m == 0 {
            break;
        }
        let points = stencil_points(&x, &free, h);
        // The centre (the start where not given, a setting just held at its
        // bound) evaluated beside the stencil where not yet known, and in an
        // idle core the ranges' points, in case this stencil is the last.
        let asked: Vec<Vec<f64>> = points.iter().cloned().chain([x.clone()]).collect();
        let mut values = known.values(&f, &asked, &minus_minus_points(&x, &free, h));
        let value = values.pop().unwrap_or(f64::NAN);
        let plus = |i: usize| values[2 * i];
        let mut pair = values[2 * m..].iter();
        let mut gradient = DVector::<f64>::zeros(m);
        let mut hess = DMatrix::<f64>::zeros(m, m);
        for i in 0..m {
            gradient[i] = (plus(i) - values[2 * i + 1]) / (2.0 * h);
            hess[(i, i)] = (plus(i) - 2.0 * value + values[2 * i + 1]) / (h * h);
        }
        for i in 0..m {
            for j in 0..i {
                let fij = pair.next().copied().unwrap_or(f64::NAN);
                let v = (fij - plus(i) - plus(j) + value) / (h * h);
                hess[(i, j)] = v;
                hess[(j, i)] = v;
            }
        }
        if !(gradient.iter().all(|g| g.is_finite()) && hess.iter().all(|v| v.is_finite())) {
            break;
        }
        last = Some(Stencil {
            centre: x.clone(),
            value,
            free: free.clone(),
            values: values.clone(),
            hess: hess.clone(),
        });
        let eigen = hess.clone().symmetric_eigen();
        let top = eigen.eigenvalues.amax();
        let floor = (1e-3 * top).max(0.5);
        let inverse_gradient = eigen.eigenvectors.transpose() * &gradient;
        let scaled = DVector::from_iterator(
            m,
            inverse_gradient
                .iter()
                .zip(eigen.eigenvalues.iter())
                .map(|(g, l)| -g / l.abs().max(floor)),
        );
        let mut step = &eigen.eigenvectors * scaled;
        let longest = step.amax();
        if longest > MAX_NEWTON_STEP {
            step *= MAX_NEWTON_STEP / longest;
        }
        // A coordinate within a stencil step of its inner edge that the step
        // pushes past it goes to the bound and is held there; then a fresh
        // stencil.
        let mut held = false;
        for (i, &d) in free.iter().enumerate() {
            let (lo, hi) = bounds[d];
            if x[d] >= hi - 2.0 * h && x[d] + step[i] > hi - h {
                (x[d], limit[d], held) = (hi, Limit::AtLeast, true);
            } else if x[d] <= lo + 2.0 * h && x[d] + step[i] < lo + h {
                (x[d], limit[d], held) = (lo, Limit::AtMost, true);
            }
        }
        if held {
            continue;
        }
        let target = |fraction: f64| -> Vec<f64> {
            let mut y = x.clone();
            for (i, &d) in free.iter().enumerate() {
                y[d] = inside(d, x[d] + fraction * step[i]);
            }
            y
        };
        let full = target(1.0);
        let size = |y: &[f64]| {
            y.iter()
                .zip(&x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        };
        // What the quadratic model expects the step to gain.
        let expected = -(gradient.dot(&step) + 0.5 * step.dot(&(&hess * &step)));
        if size(&full) < NEWTON_DONE && expected < NEWTON_GAIN {
            break;
        }
        // The step and twice it, side by side (one round on two cores), and
        // four times it only where twice beat once: along a ridge or towards
        // a bound the quadratic model undershoots, but mostly the step itself
        // is best (on a 30-minute ride 4 rounds of 5, Berlin 4 of 6), and
        // the third point side by side cost a second round each time.
        let mut tried = vec![full, target(2.0)];
        let mut tried_values = known.values(&f, &tried, &[]);
        if tried_values[1] < tried_values[0] {
            // Beside it, where a core is idle, the stencil the search takes
            // next if twice the step stays best.
            let further = target(4.0);
            let next = stencil_points(&tried[1], &free, h);
            tried_values.push(known.values(&f, std::slice::from_ref(&further), &next)[0]);
            tried.push(further);
        }
        if tried_values.iter().all(|v| v.is_nan() || *v >= value) {
            tried = vec![target(0.5), target(0.25)];
            tried_values = known.values(&f, &tried, &[]);
        }
        let best = (0..tried.len()).min_by(|&a, &b| tried_values[a].total_cmp(&tried_values[b]));
        match best {
            Some(b) if tried_values[b] < value => {
                let step_size = size(&tried[b]);
                let gain = value - tried_values[b];
                x = tried.swap_remove(b);
                // Near a bound (where a setting is held at it), the next
                // stencil decides whether it goes there ("at least", "at most").
                let at_edge = free
                    .iter()
                    .any(|&d| x[d] <= bounds[d].0 + 2.0 * h || x[d] >= bounds[d].1 - 2.0 * h);
                if gain < NEWTON_GAIN
                    && (step_size < NEWTON_DONE || (!at_edge && expected < NEWTON_GAIN))
                {
                    break;
                }
            }
            _ => break,
        }
    }
    let value = known.at(&f, &x);
    if let Some(stencil) = last {
        let hess = stencil.symmetric_hessian(&f, &mut known, h);
        for (i, (b, a)) in stencil
            .ranges(&f, &hess, &x, value, bounds)
            .into_iter()
            .enumerate()
        {
            below[stencil.free[i]] = b;
            above[stencil.free[i]] = a;
        }
    }
    Found {
        x,
        value,
        limit,
        below,
        above,
    }
}

/// The last finite-difference stencil of a [`newton`] search: its centre,
/// `f` there, the coordinates it moved, its values (`f_i+`, `f_i-` per
/// coordinate, then `f_ij++` per pair) and the Hessian they gave.
pub(super) struct Stencil {
    pub(super) centre: Vec<f64>,
    pub(super) value: f64,
    pub(super) free: Vec<usize>,
    pub(super) values: Vec<f64>,
    pub(super) hess: DMatrix<f64>,
}

impl Stencil {
    /// The Hessian with second-order cross terms, for the ranges: with the
    /// `f_ij--` points added (`m(m-1)/2` evaluations, once),
    /// `H_ij = (f_ij++ + f_ij-- - f_i+ - f_i- - f_j+ - f_j- + 2 f) / (2 h^2)`
    /// (error `O(h^2)`; the search's forward cross term
    /// `(f_ij++ - f_i+ - f_j+ + f) / h^2` is off by `O(h)` third
    /// derivatives). Along a narrow ridge that error decides the ranges: on a
    /// 6-hour ride the GPS sigma and correlation time lie on the ridge
    /// `sigma^2 / tau`, the forward cross term made the Hessian indefinite,
    /// and the ranges fell back to each setting's curvature with the others
    /// held: 2.54-2.59 m where the likelihood allows about 2.4-2.7 m.
    pub(super) fn symmetric_hessian(
        &self,
        f: &Objective,
        known: &mut Known,
        h: f64,
    ) -> DMatrix<f64> {
        let m = self.free.len();
        let points = minus_minus_points(&self.centre, &self.free, h);
        let minus_minus = known.values(f, &points, &[]);
        // f_i+ + f_i- per coordinate.
        let both = |i: usize| self.values[2 * i] + self.values[2 * i + 1];
        let mut hess = self.hess.clone();
        let mut k = 0;
        for i in 0..m {
            for j in 0..i {
                let v = (self.values[2 * m + k] + minus_minus[k] - both(i) - both(j)
                    + 2.0 * self.value)
                    / (2.0 * h * h);
                if v.is_finite() {
                    hess[(i, j)] = v;
                    hess[(j, i)] = v;
                }
                k += 1;
            }
        }
        hess
    }

    /// How far below and above the centre each coordinate's 1-sigma range
    /// reaches, from `hess` (of `-2 ln L`): along each eigen-direction that
    /// curves well (`lambda >=` [`WEAK_CURVATURE`]) the quadratic
    /// `sqrt(diag(2 H^-1))` share; along a weak one, where the quadratic
    /// model is no guide (a ridge such as `sigma^2 / tau`, flat until a bound
    /// or until the data object), the distance `t` each way at which `f`
    /// rises by 1 ([`one_sided`], walls at the bounds included), projected
    /// onto each coordinate. The shares add in quadrature. A weak direction
    /// read quadratically, with its eigenvalue floored, gave the Husky robot
    /// a GPS sigma of 0.02-477 m; read as each setting's own curvature with
    /// the others held, a range far too narrow along a ridge.
    ///
    /// The scans start from `at` (where the search ended, `f` = `value`
    /// there), which may lie a last small step from the stencil's centre:
    /// the curvature changes little over it, the edge of the range does.
    pub(super) fn ranges(
        &self,
        f: &Objective,
        hess: &DMatrix<f64>,
        at: &[f64],
        value: f64,
        bounds: &[(f64, f64)],
    ) -> Vec<(f64, f64)> {
        let m = self.free.len();
        let eigen = hess.clone().symmetric_eigen();
        let mut var = vec![0.0; m];
        let (mut below, mut above) = (vec![0.0f64; m], vec![0.0f64; m]);
        for k in 0..m {
            let v: Vec<f64> = eigen.eigenvectors.column(k).iter().copied().collect();
            let lambda = eigen.eigenvalues[k];
            if lambda >= WEAK_CURVATURE {
                for i in 0..m {
                    var[i] += 2.0 * v[i] * v[i] / lambda;
                }
                continue;
            }
            for sign in [1.0, -1.0] {
                // Where the first free setting meets its bound along `sign v`.
                let wall = (0..m)
                    .filter(|&i| v[i].abs() > 1e-12)
                    .map(|i| {
                        let (lo, hi) = bounds[self.free[i]];
                        let step = sign * v[i];
                        let room = if step > 0.0 {
                            hi - at[self.free[i]]
                        } else {
                            at[self.free[i]] - lo
                        };
                        room.max(0.0) / step.abs()
                    })
                    .fold(f64::INFINITY, f64::min);
                let along = |t: &[f64]| {
                    let mut y = at.to_vec();
                    for i in 0..m {
                        y[self.free[i]] += sign * t[0] * v[i];
                    }
                    (f.f)(&y)
                };
                let t = one_sided(
                    Objective {
                        f: &along,
                        side_by_side: f.side_by_side,
                    },
                    value,
                    wall,
                );
                for i in 0..m {
                    let reach = sign * v[i];
                    if reach > 1e-3 {
                        above[i] = above[i].max(t * reach);
                    } else if reach < -1e-3 {
                        below[i] = below[i].max(-t * reach);
                    }
                }
            }
        }
        (0..m)
            .map(|i| {
                (
                    (var[i] + below[i] * below[i]).sqrt(),
                    (var[i] + above[i] * above[i]).sqrt(),
                )
            })
            .collect()
    }
}

/// Curvature of `-2 ln L` (per log-unit squared) below which a direction is
/// scanned rather than read quadratically: a 1-sigma half-width of more than
/// one log-unit (a factor of e), where a quadratic fitted over the stencil's
/// 0.15 says little.
pub(super) const WEAK_CURVATURE: f64 = 2.0;
