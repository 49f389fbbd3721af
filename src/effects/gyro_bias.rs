//! `gyro_bias`: a constant gyro bias (3 parameters, rad/s, shown in deg/s).
//!
//! `omega_t = omega_t^measured - b` (paper eq. 2 with a constant `b`). Fitted in
//! step 1; in step 2 the per-segment biases refine it, so it is held there.

use nalgebra::Vector3;

use super::{Effect, GyroPartials, ParamInfo, Role};
use crate::model::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct GyroBias;

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

    fn initial(&self, guess: &StartGuess) -> Vec<f64> {
        guess.gyro_bias.iter().copied().collect()
    }

    fn acts_on_gyro(&self) -> bool {
        true
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
        crate::effects::testing::check_gyro_partials(
            &GyroBias,
            &p,
            5,
            Vector3::new(0.1, 0.2, -0.3),
        );
        crate::effects::testing::check_batches(&GyroBias, &p, 500);
    }
}
