//! The forward sweep (paper eq. 1-4): orientation and position at every row,
//! then residuals and cost at the GPS rows. One pass, O(N).

use nalgebra::{UnitQuaternion, Vector3};
use rayon::prelude::*;

use super::Model;
use super::observe::{ObsValue, Whitener};

/// Rows per chunk of the parallel forward sweep (and at most this many chunks):
/// a 30-minute ride at 100 Hz is two chunks, one per core of a small machine.
/// The split depends only on the ride, so results do not depend on the machine.
/// Unit tests use short chunks so that their short rides exercise the chaining.
pub(crate) const CHUNK_ROWS: usize = if cfg!(test) { 500 } else { 90_000 };
const MAX_CHUNKS: usize = 64;
/// Rows whose corrected signals [`Model::sweep_from`] makes at a time (a few
/// MB; small in tests, so that short rides cross blocks too).
const SWEEP_BLOCK_ROWS: usize = if cfg!(test) { 700 } else { 65_536 };

/// A row and the attitude and position there, where a sweep starts.
pub(crate) type Start = (usize, UnitQuaternion<f64>, Vector3<f64>);

/// The path where the observations look, from one forward sweep.
pub(crate) struct Forward {
    /// Attitudes (if kept) per chunk: the chunk's start attitude `q_a`, its
    /// first row, and `r_j` of each of its rows (`q_j = q_a r_j`).
    pub chunks: Vec<(UnitQuaternion<f64>, usize, Vec<UnitQuaternion<f64>>)>,
    /// Position at each observation's row and the step `Delta` that led there.
    pub p: Vec<Vector3<f64>>,
    pub delta: Vec<Vector3<f64>>,
}

/// What evaluating residuals reads of a path: the attitude, the position and
/// the step's distance at a row. A full [`Trajectory`] has every row; a
/// [`SparsePath`] only those it was asked for.
pub trait PathAt {
    fn q_at(&self, j: usize) -> UnitQuaternion<f64>;
    fn p_at(&self, j: usize) -> Vector3<f64>;
    fn d_at(&self, j: usize) -> f64;
}

impl PathAt for Trajectory {
    fn q_at(&self, j: usize) -> UnitQuaternion<f64> {
        self.q[j]
    }
    fn p_at(&self, j: usize) -> Vector3<f64> {
        self.p[j]
    }
    fn d_at(&self, j: usize) -> f64 {
        self.d[j]
    }
}

/// The path at chosen rows (see [`Model::sparse_path`]).
#[derive(Clone, Debug, Default)]
pub struct SparsePath {
    rows: Vec<usize>,
    q: Vec<UnitQuaternion<f64>>,
    p: Vec<Vector3<f64>>,
    d: Vec<f64>,
}

impl SparsePath {
    /// The rows held, in order.
    pub fn rows(&self) -> &[usize] {
        &self.rows
    }

    /// Index of row `j`, which must be one of those asked for (else the
    /// nearest held row, and a debug build stops).
    fn index(&self, j: usize) -> usize {
        match self.rows.binary_search(&j) {
            Ok(i) => i,
            Err(i) => {
                debug_assert!(false, "row {j} was not asked of the sparse path");
                i.min(self.rows.len().saturating_sub(1))
            }
        }
    }

    /// Position at the `i`-th held row.
    pub fn p_of(&self, i: usize) -> Vector3<f64> {
        self.p[i]
    }
}

impl PathAt for SparsePath {
    fn q_at(&self, j: usize) -> UnitQuaternion<f64> {
        self.q[self.index(j)]
    }
    fn p_at(&self, j: usize) -> Vector3<f64> {
        self.p[self.index(j)]
    }
    fn d_at(&self, j: usize) -> f64 {
        self.d[self.index(j)]
    }
}

/// The reconstructed path for one parameter vector.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    /// Attitude at each row (sensor -> world).
    pub q: Vec<UnitQuaternion<f64>>,
    /// Position at each row (local ENU, m).
    pub p: Vec<Vector3<f64>>,
    /// Corrected rotation vector of each step, `theta_j = omega_j dt_j` (`theta_0 = 0`).
    pub theta: Vec<Vector3<f64>>,
    /// Corrected distance of each step (`d_0 = 0`).
    pub d: Vec<f64>,
}

impl Model {
    /// Corrected rates (rad/s) of every step: the gyro chain applied in batch.
    /// With `keep_inputs`, also the input of every gyro effect whose backward pass reads it (empty for the others).
    /// Only the rows `first..to` (`rates[j - first]` is row `j`'s).
    pub(crate) fn corrected_rates(
        &self,
        theta: &[f64],
        (first, to): (usize, usize),
        keep_inputs: bool,
    ) -> (Vec<Vector3<f64>>, Vec<Vec<Vector3<f64>>>) {
        let mut rates = self.signals.gyro[first..to].to_vec();
        let mut inputs = Vec::new();
        for &e in &self.gyro_chain {
            if keep_inputs {
                inputs.push(if self.effects[e].gyro_backward_reads_input() {
                    rates.clone()
                } else {
                    Vec::new()
                });
            }
            self.effects[e].gyro_batch(self.params_of(e, theta), first, &mut rates);
        }
        (rates, inputs)
    }

    /// Corrected distance of every step, with the inputs of every distance effect if asked.
    pub(crate) fn corrected_distances(
        &self,
        theta: &[f64],
        (first, to): (usize, usize),
        keep_inputs: bool,
    ) -> (Vec<f64>, Vec<Vec<f64>>) {
        let mut d = self.signals.distance[first..to].to_vec();
        let mut inputs = Vec::new();
        for &e in &self.distance_chain {
            if keep_inputs {
                inputs.push(d.clone());
            }
            self.effects[e].distance_batch(self.params_of(e, theta), first, &mut d);
        }
        (d, inputs)
    }

    /// Where the cost sweeps start at `theta`: the anchor's row and state
    /// while the anchor holds, else row 0 and the initial state.
    pub(crate) fn sweep_start(&self, theta: &[f64]) -> Start {
        match self.anchor_for(theta) {
            Some(a) => (a.row, a.q, a.p),
            None => self.start_of_ride(theta),
        }
    }

    /// Row 0 and the initial state at `theta`.
    pub(crate) fn start_of_ride(&self, theta: &[f64]) -> Start {
        let (q, p, _) = self.initial_state(theta);
        (0, q, p)
    }

    /// Run eq. 1-4 over the ride (from the anchor of a window), calling
    /// `visit(j, q_j, p_j, theta_j, d_j)` at every row.
    #[inline]
    pub(crate) fn sweep(
        &self,
        theta: &[f64],
        visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>, &Vector3<f64>, f64),
    ) {
        self.sweep_from(theta, self.sweep_start(theta), visit);
    }

    /// Eq. 1-4 from `start` (a row and the state there) to the horizon.
    #[inline]
    pub(crate) fn sweep_from(
        &self,
        theta: &[f64],
        (first, mut q, mut p): Start,
        mut visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>, &Vector3<f64>, f64),
    ) {
        let (f, _) = self.forward_axis(theta);
        let inc = self.spec.increment;
        visit(first, &q, &p, &Vector3::zeros(), 0.0);
        let sig = &self.signals;
        // The corrected signals a block of rows at a time (every effect
        // corrects a row from its own inputs): a 6-hour ride's at once were
        // 69 MB, the peak of writing its path.
        let end = self.horizon();
        let mut a = first + 1;
        while a < end {
            let b = (a + SWEEP_BLOCK_ROWS).min(end);
            let (rates, _) = self.corrected_rates(theta, (a, b), false);
            let (dist, _) = self.corrected_distances(theta, (a, b), false);
            for j in a..b {
                let th = rates[j - a] * sig.dt[j];
                q *= inc.quaternion(&th);
                let d = dist[j - a];
                p += q * (f * d);
                visit(j, &q, &p, &th, d);
            }
            a = b;
        }
    }

    /// Eq. 1-4 from row `first` (state `q0`, `p0`) in parallel: the rows are
    /// cut into chunks, each integrated from the identity (`q = q_a r_j`,
    /// `p = p_a + q_a s_j` with `r_j`, `s_j` the chunk's own attitude and
    /// position), and the chunks' end states chained afterwards. Positions are
    /// kept only where the observations of `rows` (non-decreasing) look;
    /// attitudes at every row if `keep_q`. The corrected rates and distances
    /// (`[k]` for row `first + k`) are given, or made chunk by chunk.
    pub(crate) fn forward(
        &self,
        theta: &[f64],
        (first, q0, p0): Start,
        corrected: Option<(&[Vector3<f64>], &[f64])>,
        rows: &[usize],
        keep_q: bool,
    ) -> Forward {
        let sig = &self.signals;
        let (f, _) = self.forward_axis(theta);
        let inc = self.spec.increment;
        let steps = self.horizon().saturating_sub(first + 1);
        let k = (steps / CHUNK_ROWS).clamp(1, MAX_CHUNKS);
        let bounds: Vec<usize> = (0..=k).map(|c| first + steps * c / k).collect();
        let chunks: Vec<_> = (0..k)
            .into_par_iter()
            .map(|c| {
                let (a, b) = (bounds[c], bounds[c + 1]);
                let o1 = rows.partition_point(|&r| r <= b);
                let mut o = rows.partition_point(|&r| r <= a);
                let mut r = UnitQuaternion::identity();
                let mut s = Vector3::zeros();
                let mut ps = Vec::with_capacity(o1 - o);
                let mut ds = Vec::with_capacity(o1 - o);
                let mut qs = Vec::with_capacity(if keep_q { b - a } else { 0 });
                // This chunk's corrected signals, from row a + 1 on.
                let own;
                let (rates, dist) = match corrected {
                    Some((w, d)) => (&w[a + 1 - first..], &d[a + 1 - first..]),
                    None => {
                        own = (
                            self.corrected_rates(theta, (a + 1, b + 1), false).0,
                            self.corrected_distances(theta, (a + 1, b + 1), false).0,
                        );
                        (&own.0[..], &own.1[..])
                    }
                };
                for j in a + 1..=b {
                    r *= inc.quaternion(&(rates[j - a - 1] * sig.dt[j]));
                    let delta = r * (f * dist[j - a - 1]);
                    s += delta;
                    if keep_q {
                        qs.push(r);
                    }
                    while o < o1 && rows[o] == j {
                        ps.push(s);
                        ds.push(delta);
                        o += 1;
                    }
                }
                (r, s, ps, ds, qs)
            })
            .collect();
        // Chain the chunks: each starts where the previous one ended.
        let at_first = rows.partition_point(|&r| r <= first);
        let mut p = vec![p0; at_first];
        let mut delta = vec![Vector3::zeros(); at_first];
        p.reserve(rows.len() - at_first);
        delta.reserve(rows.len() - at_first);
        let mut attitudes = Vec::with_capacity(k);
        let (mut qa, mut pa) = (q0, p0);
        for (c, (r, s, ps, ds, qs)) in chunks.into_iter().enumerate() {
            p.extend(ps.iter().map(|x| pa + qa * x));
            delta.extend(ds.iter().map(|x| qa * x));
            if keep_q {
                attitudes.push((qa, bounds[c] + 1, qs));
            }
            pa += qa * s;
            qa *= r;
        }
        Forward {
            chunks: attitudes,
            p,
            delta,
        }
    }

    /// Attitude and position at every row of the ride, in order, without
    /// storing the path (`visit(j, q_j, p_j)`).
    pub fn for_each_pose(
        &self,
        theta: &[f64],
        mut visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>),
    ) {
        self.sweep_from(theta, self.start_of_ride(theta), |j, q, p, _, _| {
            visit(j, q, p)
        });
    }

    /// The path at the given rows only (sorted, without repeats), from one
    /// sweep: what a view needs of a long ride (its fixes, a decimated path)
    /// without holding every row's attitude and position (a 6-hour ride's
    /// full trajectory is some 190 MB).
    pub fn sparse_path(&self, theta: &[f64], rows: Vec<usize>) -> SparsePath {
        let mut out = SparsePath {
            q: Vec::with_capacity(rows.len()),
            p: Vec::with_capacity(rows.len()),
            d: Vec::with_capacity(rows.len()),
            rows,
        };
        let mut next = 0usize;
        self.sweep_from(theta, self.start_of_ride(theta), |j, q, p, _, d| {
            if out.rows.get(next) == Some(&j) {
                out.q.push(*q);
                out.p.push(*p);
                out.d.push(d);
                next += 1;
            }
        });
        // Rows past the sweep's horizon (a window's) keep its last state.
        while out.q.len() < out.rows.len() {
            let (q, p) = (
                out.q
                    .last()
                    .copied()
                    .unwrap_or_else(UnitQuaternion::identity),
                out.p.last().copied().unwrap_or_else(Vector3::zeros),
            );
            out.q.push(q);
            out.p.push(p);
            out.d.push(0.0);
        }
        out
    }

    /// The path at the rows that residuals read ([`Model::residual_rows`]).
    pub fn residual_path(&self, theta: &[f64]) -> SparsePath {
        self.sparse_path(theta, self.residual_rows(theta))
    }

    /// The full path for `theta` (from row 0, also for a window).
    pub fn trajectory(&self, theta: &[f64]) -> Trajectory {
        let n = self.horizon();
        let mut t = Trajectory {
            q: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
            theta: Vec::with_capacity(n),
            d: Vec::with_capacity(n),
        };
        self.sweep_from(theta, self.start_of_ride(theta), |_, q, p, th, d| {
            t.q.push(*q);
            t.p.push(*p);
            t.theta.push(*th);
            t.d.push(d);
        });
        t
    }

    /// The whitened observation values for `theta`, from one sweep that keeps
    /// the path only at the observed rows (never the whole ride: on a 6-hour
    /// ride a full trajectory is 190 MB).
    fn observation_values(&self, theta: &[f64]) -> Vec<ObsValue> {
        self.observed(theta).1
    }

    /// The model's value `x_k` of each observed coordinate at `theta` and
    /// its whitened value, from one sweep (see
    /// [`Model::observation_values`]).
    fn observed(&self, theta: &[f64]) -> (Vec<f64>, Vec<ObsValue>) {
        let plan = self.obs_plan(theta);
        let obs = &self.observations;
        let fw = self.forward(theta, self.sweep_start(theta), None, &plan.row, false);
        let x: Vec<f64> = obs
            .iter()
            .enumerate()
            .map(|(k, o)| plan.x(k, o.axis, &fw.p[k], &fw.delta[k]))
            .collect();
        let values = Whitener::new(&plan, obs).all(x.iter().copied());
        (x, values)
    }

    /// Weighted residuals (observations, then priors) for `theta`.
    pub fn residuals(&self, theta: &[f64]) -> Vec<f64> {
        let mut r: Vec<f64> = self
            .observation_values(theta)
            .into_iter()
            .map(|v| v.r)
            .collect();
        r.extend(self.prior_rows(theta).residuals);
        r
    }

    /// The cost `C = sum r^2` (eq. 7 with weights, plus priors) without storing the path.
    pub fn cost(&self, theta: &[f64]) -> f64 {
        self.evaluate(theta).cost
    }

    /// Cost and the unweighted squared misfits per kind of row, in one sweep.
    pub fn evaluate(&self, theta: &[f64]) -> Evaluation {
        let (x, values) = self.observed(theta);
        let mut ev = Evaluation {
            observed: x,
            ..Evaluation::default()
        };
        for (o, v) in self.observations.iter().zip(values) {
            ev.cost += v.r * v.r;
            let slot = match (o.axis, o.baro) {
                (2, true) => 2,
                (2, false) => 1,
                _ => 0,
            };
            ev.sum_sq_m[slot] += v.metres * v.metres;
            ev.count[slot] += 1;
        }
        ev.cost += self
            .prior_rows(theta)
            .residuals
            .iter()
            .map(|r| r * r)
            .sum::<f64>();
        ev
    }
}

/// What one cheap sweep tells about a parameter vector.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Evaluation {
    pub cost: f64,
    /// Sum of squared misfits (m^2): horizontal components, GPS up, barometric up.
    pub sum_sq_m: [f64; 3],
    /// Rows of each kind.
    pub count: [usize; 3],
    /// The model's value `x_k` of each observed coordinate (m), in the
    /// order of the observations: what a linearisation made elsewhere needs
    /// to be moved here (see `Model::chain_system_from_coarse`).
    pub observed: Vec<f64>,
}
