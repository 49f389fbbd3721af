//! `gyro_bias`: a constant gyro bias (3 parameters, rad/s, shown in deg/s).
//!
//! `omega_t = omega_t^measured - b` (paper eq. 2 with a constant `b`). Fitted in
//! step 1; in step 2 the per-segment biases refine it, so it is held there.
//!
//! Prior on the roll and pitch axes: `b_a ~ N(l_a, 0.3 deg/s)`, `a = x, y`,
//! with `l` the start guess's bias there, the level-bias guess (the mean rate
//! while standing still, else the mean roll and pitch rates while not
//! turning: a vehicle does not keep rolling or pitching). On a straight, a roll-axis bias leaves the path
//! unchanged (rolling about the forward axis moves nothing), so step 1's
//! first window cannot see it; without the prior, GPS noise pulled it to
//! 1.5 deg/s on a simulated ride, the sensor rolled over in two minutes and
//! the fit ended 26 m from the fixes. The guess is good to a few hundredths
//! of a deg/s plus the bias drift over the ride, which 0.3 deg/s covers.

use nalgebra::Vector3;

use super::{Effect, GyroPartials, ParamInfo, PriorRows, Role};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct GyroBias {
    /// Level-bias guess on the roll and pitch axes (rad/s).
    level: [f64; 2],
    /// Heading only: the roll and pitch biases are not fitted (their rates are zero).
    planar: bool,
}

/// Prior standard deviation of the roll and pitch biases about the level guess (rad/s).
pub(crate) const LEVEL_SIGMA: f64 = 0.3 / DEG_PER_RAD;

impl GyroBias {
    /// Centred on the roll and pitch bias of the start guess.
    pub fn new(start: &StartGuess, planar: bool) -> Self {
        Self {
            level: [start.gyro_bias.x, start.gyro_bias.y],
            planar,
        }
    }
}

pub const DEG_PER_RAD: f64 = 180.0 / std::f64::consts::PI;

impl Effect for GyroBias {
    fn id(&self) -> String {
        "gyro_bias".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        ["x", "y", "z"]
            .iter()
            .map(|a| ParamInfo::new(format!("bias_{a}"), "deg/s", DEG_PER_RAD))
            .collect()
    }

    fn role(&self) -> Role {
        Role::Step1Only
    }

    fn fixed(&self, i: usize) -> bool {
        self.planar && i < 2
    }

    fn initial(&self, guess: &StartGuess) -> Vec<f64> {
        guess.gyro_bias.iter().copied().collect()
    }

    fn acts_on_gyro(&self) -> bool {
        true
    }

    fn n_prior(&self) -> usize {
        2
    }

    /// Residuals `(b_a - l_a) / 0.3 deg/s` for the roll and pitch axes.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        for (a, l) in self.level.iter().enumerate() {
            let row = out.residuals.len();
            out.residuals.push((p[a] - l) / LEVEL_SIGMA);
            out.entries.push((row, a, 1.0 / LEVEL_SIGMA));
        }
    }

    fn gyro(&self, p: &[f64], _j: usize, omega: Vector3<f64>) -> Vector3<f64> {
        omega - Vector3::new(p[0], p[1], p[2])
    }

    fn gyro_partials(&self, _p: &[f64], _j: usize, _omega: &Vector3<f64>) -> GyroPartials {
        GyroPartials::bias(0)
    }

    fn gyro_batch(&self, p: &[f64], _first: usize, rates: &mut [Vector3<f64>]) {
        let b = Vector3::new(p[0], p[1], p[2]);
        for w in rates.iter_mut() {
            *w -= b;
        }
    }

    fn gyro_backward_reads_input(&self) -> bool {
        false
    }

    fn gyro_backward(
        &self,
        _p: &[f64],
        _omega_in: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        grad_p: &mut [f64],
    ) {
        let total: Vector3<f64> = grad.iter().skip(1).sum();
        for a in 0..3 {
            grad_p[a] -= total[a];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partials_match_finite_differences() {
        let p = [0.01, -0.02, 0.03];
        let e = GyroBias::default();
        crate::effects::testing::check_gyro_partials(&e, &p, 5, Vector3::new(0.1, 0.2, -0.3));
        crate::effects::testing::check_batches(&e, &p, 500);
    }

    /// The prior's centre is the true roll and pitch bias to within the
    /// bias drift over the ride, and the prior rows are `(b - l) / sigma`.
    #[test]
    fn the_level_prior_is_centred_on_the_true_roll_and_pitch_bias() {
        let sim = crate::simulation::simulate(&crate::simulation::SimConfig {
            seed: 1,
            duration_s: 600.0,
            ..Default::default()
        })
        .expect("simulate");
        let sig = crate::signals::Signals::from_log(
            &crate::import::parse(sim.log_csv.as_bytes(), "s").expect("parse"),
        )
        .expect("signals");
        let e = GyroBias::new(&StartGuess::from_signals(&sig).expect("start"), false);
        let (start, end) = (sim.truth.gyro_bias_start_dps, sim.truth.gyro_bias_end_dps);
        for a in 0..2 {
            let level = e.level[a] * DEG_PER_RAD;
            let (lo, hi) = (start[a].min(end[a]) - 0.05, start[a].max(end[a]) + 0.05);
            assert!(
                (lo..=hi).contains(&level),
                "axis {a}: {level} vs {lo}..{hi}"
            );
        }
        let mut rows = PriorRows::default();
        let p = [
            e.level[0] + LEVEL_SIGMA,
            e.level[1] - 2.0 * LEVEL_SIGMA,
            5.0,
        ];
        e.prior(&p, &mut rows);
        assert_eq!(rows.residuals.len(), e.n_prior());
        assert!((rows.residuals[0] - 1.0).abs() < 1e-12 && (rows.residuals[1] + 2.0).abs() < 1e-12);
    }
}
