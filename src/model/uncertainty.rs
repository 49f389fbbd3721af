//! How sure the fit is of its parameters and its path: 1-sigma uncertainties
//! under the fit's own noise model (GPS correlation, per-fix accuracy, robust
//! weights, priors), from the linearisation at the fitted parameters.
//!
//! `Cov(theta) = (J^T J + J_p^T J_p)^-1` with `J` the Jacobian of the whitened
//! residuals, widened by what correlation the whitened residuals still show
//! ([`Model::residual_inflation`]). Its marginals come exactly from the O(N)
//! chain solver's backward pass ([`super::ChainSystem::marginals`]): every
//! parameter's variance, and at every row of the path the covariance of what
//! moves it there, which the path's derivatives (one prefix sweep, see
//! [`super::jacobian`]) turn into the path's covariance
//! `Cov(p_j) = H_j P H_j^T`, plus what an effect says no parameter carries
//! (`Effect::along_track_variance`: a GNSS-speed gap's spread inside it).
//! A model without segment biases is small enough for the dense normal
//! equations (parameters only).
//!
//! The measurements and the history behind these choices: docs/uncertainty.md
//! (how well the sigmas hold the truth, measured).

use nalgebra::{DVector, Matrix2, Vector2};
use rayon::prelude::*;

use super::chain::PathRows;
use super::normal::damped_solve;
use super::{ChainSystem, Marginals, Model};
use crate::effects::Role;

/// Rides with more fixes than this solve the two settings of an averaged
/// uncertainty one after the other: each chain system holds about 3 kB per
/// fix (as the noise search's evaluations side by side do).
const SIDE_BY_SIDE_FIXES: usize = 10_000;

/// Longest lag (fixes) of the residual autocorrelation that widens the sigmas.
const MAX_LAG: usize = 120;

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
    /// that step 2 fits; `None` for parameters held fixed and for the constant
    /// bias (step 2 leaves it to the segments: the two are one direction).
    pub fn parameter_sigmas(&self, theta: &[f64]) -> Vec<Option<f64>> {
        let free = self.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let inflation = self.residual_inflation(theta);
        if let Some(chain) = self.chain_system(theta, &free) {
            return chain.marginals(PathRows::None).map_or_else(
                || vec![None; self.n_params()],
                |m| self.sigmas_of(&m.var, chain.columns(), inflation),
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

    /// [`Self::parameter_sigmas`] as the fit reports them: averaged over
    /// [`crate::contract::ModelSpec::band_specs`] where the spec has them, as
    /// the path's band is ([`Self::uncertainty_at`]). The tests that compare
    /// two fits' sigmas (Hausman's) take each fit's own.
    pub fn reported_sigmas(&self, theta: &[f64]) -> Vec<Option<f64>> {
        let free = self.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        if self.spec.band_specs().is_none() {
            return self.parameter_sigmas(theta);
        }
        self.drawn_marginals(theta, &free, PathRows::None)
            .map_or_else(|| self.parameter_sigmas(theta), |(_, _, sigmas)| sigmas)
    }

    /// [`Self::solved`] for this model under `spec` (one of the band's
    /// settings): from `base`'s linearisation where given, else its own.
    fn solved_under(
        &self,
        spec: crate::contract::ModelSpec,
        base: Option<&ChainSystem>,
        theta: &[f64],
        free: &[bool],
        which: PathRows,
    ) -> Option<(Marginals, Vec<usize>, f64)> {
        let m = self.with_spec(spec).ok()?;
        let chain = match base {
            Some(b) => m.chain_system_like(b, theta)?,
            None => m.chain_system(theta, free)?,
        };
        m.solved(chain, theta, which)
    }

    /// The marginals of `chain` (this model's, at `theta`) at `which` rows,
    /// its columns and this model's widening; the chain is let go here.
    fn solved(
        &self,
        chain: ChainSystem,
        theta: &[f64],
        which: PathRows,
    ) -> Option<(Marginals, Vec<usize>, f64)> {
        let marginals = chain.marginals(which)?;
        Some((
            marginals,
            chain.columns().to_vec(),
            self.residual_inflation(theta),
        ))
    }

    /// Per parameter the marginal sigma of its free column (`columns`, with
    /// variances `var`), widened by `inflation`.
    fn sigmas_of(&self, var: &[f64], columns: &[usize], inflation: f64) -> Vec<Option<f64>> {
        let mut out = vec![None; self.n_params()];
        for (&v, &i) in var.iter().zip(columns) {
            out[i] = Some(inflation * v.max(0.0).sqrt());
        }
        out
    }

    /// The sigmas of every parameter and the covariance of the path at every
    /// row, exact under the linearisation (see the module docs) and widened as
    /// [`Self::parameter_sigmas`]. `None` for a model without segment biases
    /// (no chain) or when the solve fails.
    pub fn uncertainty(&self, theta: &[f64]) -> Option<Uncertainty> {
        self.uncertainty_at(theta, None)
    }

    /// [`Self::uncertainty`] with the path's covariance kept only at `rows`
    /// (sorted; `Uncertainty::path[i]` is then row `rows[i]`): what a view
    /// that draws a few thousand points needs, without a long ride's every row.
    ///
    /// Averaged over [`crate::contract::ModelSpec::band_specs`] where the
    /// spec has them: the path is this model's, its covariance and the
    /// parameters' variances the mean of the two settings' (one sweep of the
    /// path's derivatives serves both: they do not depend on the noise).
    pub fn uncertainty_at(&self, theta: &[f64], rows: Option<&[usize]>) -> Option<Uncertainty> {
        let free = self.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let which = rows.map_or(PathRows::All, PathRows::Only);
        let all: Vec<usize>;
        let rows = match rows {
            Some(r) => r,
            None => {
                all = (0..self.signals.len()).collect();
                &all
            }
        };
        let (marginals, weight, params) = self.drawn_marginals(theta, &free, which)?;
        let mut path = vec![[f64::NAN; 4]; rows.len()];
        self.put_path_covariance(theta, &free, rows, (&marginals, weight), &mut path);
        self.add_along_track_spread(theta, rows, &mut path);
        Some(Uncertainty { params, path })
    }

    /// The marginals the uncertainty is drawn from and the weight that folds
    /// its widening in: this model's own, `c^2 P`, or over the two ends of
    /// [`crate::contract::ModelSpec::band_specs`] their mean,
    /// `(c_a^2 P_a + c_b^2 P_b) / 2`, as one square root per stage
    /// ([`Marginals::mix`]), so that the rows are swept once. Also the
    /// parameters' sigmas, the root of the settings' mean variance. Short
    /// rides solve the two side by side from one linearisation of the ride
    /// (the settings differ only in how the fixes are whitened); past
    /// [`SIDE_BY_SIDE_FIXES`] the second setting's backward pass is mixed
    /// into the first's marginals as it goes, so that one setting's chain
    /// and marginals are held at a time.
    fn drawn_marginals(
        &self,
        theta: &[f64],
        free: &[bool],
        which: PathRows,
    ) -> Option<(Marginals, f64, Vec<Option<f64>>)> {
        match self.spec.band_specs() {
            None => {
                let (m, columns, c) = self.solved(self.chain_system(theta, free)?, theta, which)?;
                let sigmas = self.sigmas_of(&m.var, &columns, c);
                Some((m, c * c, sigmas))
            }
            Some([first, second]) if self.observed_fixes() > SIDE_BY_SIDE_FIXES => {
                let (a, columns, ca) = self.solved_under(first, None, theta, free, which)?;
                let mut sigmas = vec![self.sigmas_of(&a.var, &columns, ca)];
                let m = self.with_spec(second).ok()?;
                let cb = m.residual_inflation(theta);
                let chain = m.chain_system(theta, free)?;
                if chain.columns() != columns.as_slice() {
                    return None;
                }
                let (mixed, own) = chain.marginals_mixed(which, a, 0.5 * ca * ca, 0.5 * cb * cb)?;
                sigmas.push(self.sigmas_of(&own, &columns, cb));
                Some((mixed, 1.0, mean_sigmas(sigmas)))
            }
            Some(specs) => {
                let base = self.chain_system(theta, free)?;
                let solved: Vec<_> = specs
                    .into_par_iter()
                    .map(|s| self.solved_under(s, Some(&base), theta, free, which))
                    .collect::<Option<_>>()?;
                drop(base);
                let mut solved = solved.into_iter();
                let ((a, columns, ca), (b, _, cb)) = (solved.next()?, solved.next()?);
                let sigmas = vec![
                    self.sigmas_of(&a.var, &columns, ca),
                    self.sigmas_of(&b.var, &columns, cb),
                ];
                let mixed = Marginals::mix(a, 0.5 * ca * ca, b, 0.5 * cb * cb)?;
                Some((mixed, 1.0, mean_sigmas(sigmas)))
            }
        }
    }

    /// Puts `w H P H^T` (`part = (P, w)`) into `path` at `rows`: one sweep
    /// of the path's derivatives, in chunks side by side.
    fn put_path_covariance(
        &self,
        theta: &[f64],
        free: &[bool],
        rows: &[usize],
        (marginals, w): (&Marginals, f64),
        path: &mut [[f64; 4]],
    ) {
        // Chunks side by side (the covariance at every row is most of the
        // work), each from the sums of those before it: one sweep without
        // visits finds them when there is more than one chunk.
        let befores = (self.prefix_chunk_count(theta, free) > 1).then(|| {
            self.prefix_sweep_chunked(theta, free, &[], None, |_| (), |_, _, _, _, _| {})
                .befores(self.n_params())
        });
        // Each chunk writes the rows it visits in place (a 6-hour ride's
        // covariances are 69 MB: gathered apart and copied they were twice that).
        let spans = self.prefix_chunk_spans(theta, free, rows);
        let mut slices = Vec::with_capacity(spans.len());
        let mut rest = &mut path[..];
        let mut at = 0;
        for span in &spans {
            let (_, tail) = std::mem::take(&mut rest).split_at_mut(span.start - at);
            let (own, tail) = tail.split_at_mut(span.len());
            slices.push(Some((span.start, span.start, own)));
            (rest, at) = (tail, span.end);
        }
        let slices = std::sync::Mutex::new(slices);
        self.prefix_sweep_chunked(
            theta,
            free,
            rows,
            befores,
            |c| {
                slices
                    .lock()
                    .ok()
                    .and_then(|mut s| s.get_mut(c).and_then(Option::take))
            },
            // (first row index of the chunk, the next one to write, its rows)
            |out: &mut Option<(usize, usize, &mut [[f64; 4]])>, row, p, _, sums| {
                let Some((start, k, out)) = out else { return };
                while *k < rows.len() && rows[*k] == row {
                    let c = marginals.path_covariance(row, p, |i| sums.dp(i, p));
                    if let Some(slot) = out.get_mut(*k - *start) {
                        *slot = c.map(|v| w * v);
                    }
                    *k += 1;
                }
            },
        );
    }

    /// A bridged distance's own spread (`Effect::along_track_variance`,
    /// `sigma_s^2` in metres of distance), as the spread of the point
    /// `P(s + e)` along the path itself with `e ~ N(0, sigma_s^2)`: by
    /// three-point Gauss-Hermite quadrature (nodes `0, +-sqrt(3) sigma_s`,
    /// weights `2/3, 1/6, 1/6`),
    ///
    /// `Cov = 1/6 sum_(+-) (P(s +- sqrt(3) sigma_s) - P(s)) (...)^T`,
    ///
    /// the arc clamped to the bridge's own stretch of path. On a straight
    /// path that is `sigma_s^2 u u^T` along the direction `u`; where the path
    /// turns inside a gap, a point tens of metres behind along the road is
    /// off in another direction than the road's at the point, which the
    /// tangent alone would call impossible (measured on simulated rides with
    /// stops in their gaps: see `tests/gnss_speed.rs`).
    fn add_along_track_spread(&self, theta: &[f64], rows: &[usize], path: &mut [[f64; 4]]) {
        let n = self.signals.len().min(self.horizon());
        let spread = |j: usize| -> f64 {
            self.effects
                .iter()
                .filter(|e| e.acts_on_distance())
                .map(|e| e.along_track_variance(j))
                .sum()
        };
        // The bridged runs of rows, each with a row of margin on either side.
        let mut runs: Vec<(usize, usize)> = Vec::new();
        let mut j = 0;
        while j < n {
            if spread(j) > 0.0 {
                let a = j.saturating_sub(1);
                while j < n && spread(j) > 0.0 {
                    j += 1;
                }
                let b = j.min(n - 1);
                // Runs a row or two apart share their margin: one run.
                match runs.last_mut() {
                    Some(last) if a <= last.1 => last.1 = b,
                    _ => runs.push((a, b)),
                }
            }
            j += 1;
        }
        if runs.is_empty() {
            return;
        }
        let held: Vec<usize> = runs.iter().flat_map(|&(a, b)| a..=b).collect();
        let sparse = self.sparse_path(theta, held);
        let mut at = 0;
        for &(a, b) in &runs {
            let run = PathArc::new((0..=b - a).map(|i| sparse.p_of(at + i).xy()).collect());
            at += b - a + 1;
            let first = rows.partition_point(|&r| r < a);
            for (k, &row) in rows.iter().enumerate().skip(first) {
                if row > b {
                    break;
                }
                let var = spread(row);
                if var <= 0.0 {
                    continue;
                }
                let cov = run.spread(row - a, var);
                path[k][0] += cov[(0, 0)];
                path[k][1] += cov[(1, 1)];
                path[k][3] += cov[(0, 1)];
            }
        }
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

/// A stretch of path as a polyline with its arc length: where a point
/// `s` metres along it lies.
struct PathArc {
    points: Vec<Vector2<f64>>,
    arc: Vec<f64>,
}

impl PathArc {
    fn new(points: Vec<Vector2<f64>>) -> Self {
        let mut arc = vec![0.0; points.len()];
        for i in 1..points.len() {
            arc[i] = arc[i - 1] + (points[i] - points[i - 1]).norm();
        }
        Self { points, arc }
    }

    /// The point `s` metres along, clamped to the stretch's ends.
    fn point_at(&self, s: f64) -> Vector2<f64> {
        let Some(&last) = self.points.last() else {
            return Vector2::zeros();
        };
        if self.points.len() < 2 {
            return last;
        }
        let i = self
            .arc
            .partition_point(|&x| x < s)
            .clamp(1, self.arc.len() - 1);
        let (s0, s1) = (self.arc[i - 1], self.arc[i]);
        let w = if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        self.points[i - 1] + w * (self.points[i] - self.points[i - 1])
    }

    /// The covariance of `P(s_i + e) - P(s_i)`, `e ~ N(0, var)`, by the
    /// three-point quadrature of [`Model::add_along_track_spread`].
    fn spread(&self, i: usize, var: f64) -> Matrix2<f64> {
        let (here, s) = (self.points[i], self.arc[i]);
        let reach = (3.0 * var).sqrt();
        let mut cov = Matrix2::zeros();
        for side in [-1.0, 1.0] {
            let d = self.point_at(s + side * reach) - here;
            cov += d * d.transpose() / 6.0;
        }
        cov
    }
}

/// Per parameter the root of the mean variance over `each` (one sigma list
/// per setting); `None` where any setting has none.
fn mean_sigmas(each: Vec<Vec<Option<f64>>>) -> Vec<Option<f64>> {
    let n = each.iter().map(Vec::len).max().unwrap_or(0);
    let share = 1.0 / each.len().max(1) as f64;
    (0..n)
        .map(|i| {
            each.iter()
                .map(|s| s.get(i).copied().flatten().map(|v| share * v * v))
                .sum::<Option<f64>>()
                .map(f64::sqrt)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::model::ModelSpec;

    /// Independent fixes, a wander alone, a wander with a jitter (see `noise`).
    const NOISES: [(Option<f64>, f64); 3] = [(None, 0.0), (Some(20.0), 0.0), (Some(20.0), 1.2)];

    /// A 90-second ride's model at slightly perturbed starting values, its
    /// free mask, its dense linearisation and `(J^T J)^-1`.
    fn dense_case(
        tau: Option<f64>,
        white: f64,
    ) -> (
        Model,
        Vec<f64>,
        Vec<bool>,
        crate::model::Linearisation,
        nalgebra::DMatrix<f64>,
    ) {
        let sig = Arc::new(crate::testing::simulated_signals(6, 90.0, &[]));
        let spec = ModelSpec {
            gps_tau_s: tau,
            gps_white_m: white,
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
        let inv = a.cholesky().expect("positive definite").inverse();
        (m, p, free, lin, inv)
    }

    /// The backward pass's marginals equal the dense inverse of the full
    /// normal matrix: every free parameter's variance (segment biases
    /// included), and at rows along the ride, inside blocks and at their
    /// edges, the path's covariance `H (J^T J)^-1 H^T` with `H` the path's
    /// derivative with respect to every free parameter; white and correlated.
    #[test]
    fn path_and_parameter_covariances_equal_the_dense_inverse() {
        for (tau, white) in NOISES {
            let (m, p, free, lin, inv) = dense_case(tau, white);
            let sig = m.signals.clone();
            let chain = m.chain_system(&p, &free).expect("chain");
            assert_eq!(chain.columns(), &lin.columns[..]);
            let marg = chain.marginals(PathRows::All).expect("marginals");
            let close =
                |x: f64, dense: f64, floor: f64| (x - dense).abs() <= 1e-4 * dense.abs().max(floor);
            for c in 0..lin.columns.len() {
                assert!(
                    close(marg.var[c], inv[(c, c)], 0.0),
                    "tau {tau:?} column {c}: {} vs {}",
                    marg.var[c],
                    inv[(c, c)]
                );
            }
            let rows: Vec<usize> = (1..sig.len()).step_by(37).collect();
            let mut seen = 0;
            let mut k = 0;
            m.prefix_sweep(&p, &free, &rows, |row, pos, _, sums| {
                if k >= rows.len() || rows[k] != row {
                    return;
                }
                k += 1;
                let h = nalgebra::DMatrix::from_fn(3, lin.columns.len(), |r, c| {
                    sums.dp(lin.columns[c], pos)[r]
                });
                let dense = &h * &inv * h.transpose();
                let got = marg.path_covariance(row, pos, |i| sums.dp(i, pos));
                let floor = 1e-3 * dense[(0, 0)].max(dense[(1, 1)]);
                for (v, d) in
                    got.iter()
                        .zip([dense[(0, 0)], dense[(1, 1)], dense[(2, 2)], dense[(0, 1)]])
                {
                    assert!(
                        close(*v, d, floor.max(1e-12)),
                        "tau {tau:?} row {row}: {got:?} vs {dense}"
                    );
                }
                seen += 1;
            });
            assert!(seen > 200, "{seen} rows");
        }
    }

    /// The path's covariance at every row, swept in chunks side by side
    /// (each from the sums of those before it), equals the same covariance
    /// from one sweep of the whole ride, row by row.
    #[test]
    fn the_chunked_path_covariance_is_the_one_sweeps() {
        for (tau, white) in NOISES {
            let (m, p, free, _, _) = dense_case(tau, white);
            assert!(
                m.prefix_chunk_count(&p, &free) > 5,
                "the test ride is one chunk"
            );
            let u = m.uncertainty(&p).expect("uncertainty");
            let chain = m.chain_system(&p, &free).expect("chain");
            let marg = chain.marginals(PathRows::All).expect("marginals");
            let widen = m.residual_inflation(&p).powi(2);
            let mut rows = 0;
            m.prefix_sweep(
                &p,
                &free,
                &(0..m.signals.len()).collect::<Vec<_>>(),
                |row, pos, _, sums| {
                    let one = marg.path_covariance(row, pos, |i| sums.dp(i, pos));
                    for (a, b) in one.iter().zip(&u.path[row]) {
                        assert!(
                            (a * widen - b).abs() <= 1e-9 * b.abs().max(1e-6),
                            "tau {tau:?} row {row}: {one:?} against {:?}",
                            u.path[row]
                        );
                    }
                    rows += 1;
                },
            );
            assert_eq!(rows, m.signals.len());
        }
    }

    /// The uncertainty averaged over the correlation time's range (one
    /// blended square root per stage, `ModelSpec::band_specs`) is the mean of
    /// the two settings' own, row by row and parameter by parameter.
    #[test]
    fn the_band_averaged_over_the_range_is_the_mean_of_its_two_ends() {
        let (m, p, _, _, _) = dense_case(Some(20.0), 1.2);
        let mut spec = m.spec.clone();
        spec.band_taus = Some((12.0, 45.0));
        let averaged = m.with_spec(spec.clone()).unwrap().uncertainty(&p).unwrap();
        let ends = spec.band_specs().expect("a range around the time");
        assert_eq!(ends[1].gps_tau_s, Some(45.0));
        let ratio = ends[1].sigma_horizontal_m.powi(2) / 45.0;
        assert!((ratio - spec.sigma_horizontal_m.powi(2) / 20.0).abs() < 1e-12);
        let each: Vec<Uncertainty> = ends
            .into_iter()
            .map(|s| m.with_spec(s).unwrap().uncertainty(&p).unwrap())
            .collect();
        for row in 0..m.signals.len() {
            for k in 0..4 {
                let mean = 0.5 * (each[0].path[row][k] + each[1].path[row][k]);
                let got = averaged.path[row][k];
                assert!(
                    (got - mean).abs() <= 1e-9 * mean.abs().max(1e-6),
                    "row {row}: {got} against {mean}"
                );
            }
        }
        for (i, got) in averaged.params.iter().enumerate() {
            let (Some(a), Some(b)) = (each[0].params[i], each[1].params[i]) else {
                assert!(got.is_none());
                continue;
            };
            let mean = (0.5 * (a * a + b * b)).sqrt();
            assert!((got.unwrap() - mean).abs() <= 1e-12 * mean, "parameter {i}");
        }
        // Through one blended square root, not the row-by-row fallback.
        let free = m.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let ends: Vec<Marginals> = spec
            .band_specs()
            .unwrap()
            .into_iter()
            .map(|s| {
                let chain = m.with_spec(s).unwrap().chain_system(&p, &free).unwrap();
                chain.marginals(PathRows::All).unwrap()
            })
            .collect();
        let mut ends = ends.into_iter();
        let (a, b) = (ends.next().unwrap(), ends.next().unwrap());
        let n = a.stage_count();
        let mixed = Marginals::mix(a, 0.5, b, 0.5).expect("the same columns");
        assert_eq!(mixed.stage_count(), n);
    }

    /// The second setting's backward pass mixed into the first's marginals
    /// as it goes (how a long ride averages its band) gives what mixing the
    /// two settings' whole marginals does, row by row and column by column,
    /// and hands back the second setting's own variances.
    #[test]
    fn marginals_mixed_as_the_pass_goes_equal_the_mixed_whole() {
        let (m, p, _, _, _) = dense_case(Some(20.0), 1.2);
        let mut spec = m.spec.clone();
        spec.band_taus = Some((12.0, 45.0));
        let free = m.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let chains: Vec<ChainSystem> = spec
            .band_specs()
            .unwrap()
            .into_iter()
            .map(|s| m.with_spec(s).unwrap().chain_system(&p, &free).unwrap())
            .collect();
        let marg = |k: usize| chains[k].marginals(PathRows::All).unwrap();
        let (wa, wb) = (0.4, 0.9);
        let whole = Marginals::mix(marg(0), wa, marg(1), wb).unwrap();
        let (streamed, own) = chains[1]
            .marginals_mixed(PathRows::All, marg(0), wa, wb)
            .unwrap();
        assert_eq!(own, marg(1).var);
        assert_eq!(streamed.var, whole.var);
        assert_eq!(streamed.stage_count(), whole.stage_count());
        let (mut rows, mut pairs) = (0, Vec::new());
        m.prefix_sweep(
            &p,
            &free,
            &(0..m.signals.len()).collect::<Vec<_>>(),
            |row, pos, _, sums| {
                pairs.push((
                    streamed.path_covariance(row, pos, |i| sums.dp(i, pos)),
                    whole.path_covariance(row, pos, |i| sums.dp(i, pos)),
                ));
                rows += 1;
            },
        );
        assert_eq!(rows, m.signals.len());
        for (row, (got, want)) in pairs.iter().enumerate() {
            assert!(want[0] > 0.0, "row {row}");
            assert_eq!(got, want, "row {row}");
        }
    }

    /// On a long ride the backward pass stays sane: every row's horizontal
    /// sigma positive and below 30 m (at the unfitted parameters), every parameter's variance positive.
    /// (Carried as `P` instead of a square root, the covariance went
    /// indefinite about an hour from the end and reached 1e60.)
    #[test]
    fn the_backward_pass_stays_sane_on_a_long_ride() {
        let sig = Arc::new(crate::testing::simulated_signals(5, 7200.0, &[]));
        let m = Model::new(sig.clone(), ModelSpec::default()).unwrap();
        let p = m.initial_params();
        let u = m.uncertainty(&p).expect("uncertainty");
        for j in (0..sig.len()).step_by(50) {
            let [e, n, _] = u.sigma_enu(j);
            let h = (e * e + n * n).sqrt();
            assert!(h > 0.0 && h < 30.0, "row {j}: sigma {h} m");
        }
        assert!(u.params.iter().flatten().all(|s| s.is_finite() && *s > 0.0));
    }

    /// The chain's marginal covariance of the globals equals the dense
    /// inverse of the full normal matrix, white and correlated (to 1e-4: the
    /// rows pinning the chain's state carry a finite weight, see `chain`).
    #[test]
    fn global_sigmas_from_the_chain_equal_the_dense_inverse() {
        for (tau, white) in NOISES {
            let (m, p, _, lin, inv) = dense_case(tau, white);
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
    /// Along a straight stretch the spread lies along it, `sigma^2 u u^T`;
    /// where the stretch turns a right angle within reach, the points
    /// behind and ahead lie on either leg, and the spread covers both.
    #[test]
    fn a_bridged_spread_follows_the_path() {
        let straight = PathArc::new(
            (0..=100)
                .map(|i| Vector2::new(0.6, 0.8) * i as f64)
                .collect(),
        );
        let cov = straight.spread(50, 4.0);
        let expect = Vector2::new(0.6, 0.8) * Vector2::new(0.6, 0.8).transpose() * 4.0;
        assert!((cov - expect).norm() < 1e-9, "{cov} against {expect}");
        // East 50 m, then north 50 m; the point at the corner, sigma 10 m.
        let mut corner: Vec<Vector2<f64>> = (0..=50).map(|i| Vector2::new(i as f64, 0.0)).collect();
        corner.extend((1..=50).map(|i| Vector2::new(50.0, i as f64)));
        let l = PathArc::new(corner);
        let reach = 300f64.sqrt();
        let cov = l.spread(50, 100.0);
        let expect = Matrix2::new(reach * reach, 0.0, 0.0, reach * reach) / 6.0;
        assert!((cov - expect).norm() < 1e-9, "{cov} against {expect}");
        // Near an end the reach is clamped to the stretch.
        assert_eq!(l.point_at(-5.0), Vector2::zeros());
        assert_eq!(l.point_at(1e3), Vector2::new(50.0, 50.0));
    }
}
