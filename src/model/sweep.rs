//! The forward sweep (paper eq. 1-4): orientation and position at every row,
//! then residuals and cost at the GPS rows. One pass, O(N).

use nalgebra::{UnitQuaternion, Vector3};

use super::Model;

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
    /// With `keep_inputs`, also the input of every gyro effect (for back-propagation).
    /// Rows before `first` are left out (`rates[j - first]` is row `j`'s).
    pub(crate) fn corrected_rates(
        &self,
        theta: &[f64],
        first: usize,
        keep_inputs: bool,
    ) -> (Vec<Vector3<f64>>, Vec<Vec<Vector3<f64>>>) {
        let mut rates = self.signals.gyro[first..self.horizon()].to_vec();
        let mut inputs = Vec::new();
        for &e in &self.gyro_chain {
            if keep_inputs {
                inputs.push(rates.clone());
            }
            let p = self.params_of(e, theta);
            if first == 0 {
                self.effects[e].gyro_batch(p, &mut rates);
            } else {
                for (k, w) in rates.iter_mut().enumerate() {
                    *w = self.effects[e].gyro(p, first + k, *w);
                }
            }
        }
        (rates, inputs)
    }

    /// Corrected distance of every step, with the inputs of every distance effect if asked.
    pub(crate) fn corrected_distances(
        &self,
        theta: &[f64],
        first: usize,
        keep_inputs: bool,
    ) -> (Vec<f64>, Vec<Vec<f64>>) {
        let mut d = self.signals.distance[first..self.horizon()].to_vec();
        let mut inputs = Vec::new();
        for &e in &self.distance_chain {
            if keep_inputs {
                inputs.push(d.clone());
            }
            let p = self.params_of(e, theta);
            if first == 0 {
                self.effects[e].distance_batch(p, &mut d);
            } else {
                for (k, x) in d.iter_mut().enumerate() {
                    *x = self.effects[e].distance(p, first + k, *x);
                }
            }
        }
        (d, inputs)
    }

    /// Run eq. 1-4 over the ride (from the anchor of a window), calling
    /// `visit(j, q_j, p_j, theta_j, d_j)` at every row.
    #[inline]
    pub(crate) fn sweep(
        &self,
        theta: &[f64],
        visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>, &Vector3<f64>, f64),
    ) {
        let first = self.anchor_for(theta).map_or(0, |a| a.row);
        let (rates, _) = self.corrected_rates(theta, first, false);
        let (dist, _) = self.corrected_distances(theta, first, false);
        self.sweep_corrected(theta, first, &rates, &dist, visit);
    }

    /// Eq. 1-4 from row `first` (0 or the anchor's) with already corrected
    /// rates and distances of the rows from `first` on (see [`sweep`](Model::sweep)).
    #[inline]
    fn sweep_corrected(
        &self,
        theta: &[f64],
        first: usize,
        rates: &[Vector3<f64>],
        dist: &[f64],
        mut visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>, &Vector3<f64>, f64),
    ) {
        let (mut q, mut p) = match self.anchor_for(theta) {
            Some(a) if a.row == first => (a.q, a.p),
            _ => {
                let (q, p, _) = self.initial_state(theta);
                (q, p)
            }
        };
        let (f, _) = self.forward_axis(theta);
        let inc = self.spec.increment;
        visit(first, &q, &p, &Vector3::zeros(), 0.0);
        let sig = &self.signals;
        for j in first + 1..self.horizon() {
            let th = rates[j - first] * sig.dt[j];
            q *= inc.quaternion(&th);
            let d = dist[j - first];
            p += q * (f * d);
            visit(j, &q, &p, &th, d);
        }
    }

    /// Attitude and position at every row of the ride, in order, without
    /// storing the path (`visit(j, q_j, p_j)`).
    pub fn for_each_pose(
        &self,
        theta: &[f64],
        mut visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>),
    ) {
        let (rates, _) = self.corrected_rates(theta, 0, false);
        let (dist, _) = self.corrected_distances(theta, 0, false);
        self.sweep_corrected(theta, 0, &rates, &dist, |j, q, p, _, _| visit(j, q, p));
    }

    /// The full path for `theta` (from row 0, also for a window).
    pub fn trajectory(&self, theta: &[f64]) -> Trajectory {
        let (rates, _) = self.corrected_rates(theta, 0, false);
        let (dist, _) = self.corrected_distances(theta, 0, false);
        self.trajectory_corrected(theta, &rates, &dist)
    }

    /// The full path from already corrected rates and distances.
    pub(crate) fn trajectory_corrected(
        &self,
        theta: &[f64],
        rates: &[Vector3<f64>],
        dist: &[f64],
    ) -> Trajectory {
        let n = self.horizon();
        let mut t = Trajectory {
            q: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
            theta: Vec::with_capacity(n),
            d: Vec::with_capacity(n),
        };
        self.sweep_corrected(theta, 0, rates, dist, |_, q, p, th, d| {
            t.q.push(*q);
            t.p.push(*p);
            t.theta.push(*th);
            t.d.push(d);
        });
        t
    }

    /// Weighted residuals (observations, then priors) of a computed path.
    pub fn residuals_of(&self, theta: &[f64], path: &Trajectory) -> Vec<f64> {
        let plan = self.obs_plan(theta);
        let mut r: Vec<f64> = self
            .observations
            .iter()
            .enumerate()
            .map(|(k, o)| {
                let j = plan.row[k];
                let delta = path.p[j] - path.p[j.max(1) - 1];
                plan.value(k, o, plan.x(k, o.axis, &path.p[j], &delta)).r
            })
            .collect();
        r.extend(self.prior_rows(theta).residuals);
        r
    }

    /// Weighted residuals for `theta`.
    pub fn residuals(&self, theta: &[f64]) -> Vec<f64> {
        self.residuals_of(theta, &self.trajectory(theta))
    }

    /// The cost `C = sum r^2` (eq. 7 with weights, plus priors) without storing the path.
    pub fn cost(&self, theta: &[f64]) -> f64 {
        self.evaluate(theta).cost
    }

    /// Cost and the unweighted squared misfits per kind of row, in one sweep.
    pub fn evaluate(&self, theta: &[f64]) -> Evaluation {
        let plan = self.obs_plan(theta);
        let obs = &self.observations;
        let mut k = 0;
        let mut ev = Evaluation::default();
        let mut prev = Vector3::zeros();
        self.sweep(theta, |j, _, p, _, _| {
            let delta = p - prev;
            prev = *p;
            while k < obs.len() && plan.row[k] == j {
                let o = &obs[k];
                let v = plan.value(k, o, plan.x(k, o.axis, p, &delta));
                let metres = v.metres;
                ev.cost += v.r * v.r;
                let slot = match (o.axis, o.baro) {
                    (2, true) => 2,
                    (2, false) => 1,
                    _ => 0,
                };
                ev.sum_sq_m[slot] += metres * metres;
                ev.count[slot] += 1;
                k += 1;
            }
        });
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
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Evaluation {
    pub cost: f64,
    /// Sum of squared misfits (m^2): horizontal components, GPS up, barometric up.
    pub sum_sq_m: [f64; 3],
    /// Rows of each kind.
    pub count: [usize; 3],
}
