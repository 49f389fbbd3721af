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
    /// Corrected gyro rate of step `j` (the gyro chain).
    #[inline]
    pub(crate) fn rate(&self, theta: &[f64], j: usize) -> Vector3<f64> {
        let mut w = self.signals.gyro[j];
        for &e in &self.gyro_chain {
            w = self.effects[e].gyro(self.params_of(e, theta), j, w);
        }
        w
    }

    /// Corrected distance of step `j` (the distance chain).
    #[inline]
    pub(crate) fn step_distance(&self, theta: &[f64], j: usize) -> f64 {
        let mut d = self.signals.distance[j];
        for &e in &self.distance_chain {
            d = self.effects[e].distance(self.params_of(e, theta), j, d);
        }
        d
    }

    /// Run eq. 1-4 over the ride, calling `visit(j, q_j, p_j, theta_j, d_j)` at every row.
    #[inline]
    pub(crate) fn sweep(
        &self,
        theta: &[f64],
        mut visit: impl FnMut(usize, &UnitQuaternion<f64>, &Vector3<f64>, &Vector3<f64>, f64),
    ) {
        let (mut q, mut p, _) = self.initial_state(theta);
        let inc = self.spec.increment;
        visit(0, &q, &p, &Vector3::zeros(), 0.0);
        let sig = &self.signals;
        for j in 1..sig.len() {
            let th = self.rate(theta, j) * sig.dt[j];
            q *= inc.quaternion(&th);
            let d = self.step_distance(theta, j);
            p += q * Vector3::x() * d;
            visit(j, &q, &p, &th, d);
        }
    }

    /// The full path for `theta`.
    pub fn trajectory(&self, theta: &[f64]) -> Trajectory {
        let n = self.signals.len();
        let mut t = Trajectory {
            q: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
            theta: Vec::with_capacity(n),
            d: Vec::with_capacity(n),
        };
        self.sweep(theta, |_, q, p, th, d| {
            t.q.push(*q);
            t.p.push(*p);
            t.theta.push(*th);
            t.d.push(d);
        });
        t
    }

    /// Weighted residuals (observations, then priors) of a computed path.
    pub fn residuals_of(&self, theta: &[f64], path: &Trajectory) -> Vec<f64> {
        let baro = self.baro_offset(theta);
        let mut r: Vec<f64> = self
            .observations
            .iter()
            .map(|o| {
                let target = if o.baro { o.target + baro } else { o.target };
                o.w * (path.p[o.row][o.axis] - target)
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
        let baro = self.baro_offset(theta);
        let obs = &self.observations;
        let mut k = 0;
        let mut c = 0.0;
        self.sweep(theta, |j, _, p, _, _| {
            while k < obs.len() && obs[k].row == j {
                let o = &obs[k];
                let target = if o.baro { o.target + baro } else { o.target };
                let r = o.w * (p[o.axis] - target);
                c += r * r;
                k += 1;
            }
        });
        c + self
            .prior_rows(theta)
            .residuals
            .iter()
            .map(|r| r * r)
            .sum::<f64>()
    }
}
