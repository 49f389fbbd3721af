//! `gyro_scale`: per-axis gyro scale-factor error (3 parameters, shown in %).
//!
//! A MEMS gyro reports `omega_m = (1 + s) omega + b` per axis, with `s` a few
//! tenths of a percent to several percent. Applied after the bias effects,
//! which leave `omega_m - b`, the true rate is
//!
//! ```text
//! omega = omega_in / (1 + s),   d omega / d omega_in = 1 / (1 + s),   d omega / d s = -omega_in / (1 + s)^2
//! ```
//!
//! Visible only through turning: the yaw-axis factor makes every turn too
//! wide or too tight (the heading error grows with accumulated heading change).
//! Roll and pitch rates of a vehicle are small and average out, so their
//! factors are barely observable; a prior `s_a ~ N(0, 5 %)` (consumer MEMS
//! gyros are specified within a few percent) keeps them from wandering to
//! absurd values while leaving a well-observed yaw factor to the data.

use nalgebra::{Matrix3, Vector3};

use super::{Columns, Effect, GyroPartials, ParamInfo, PriorRows};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct GyroScale {
    /// A planar model turns about the vertical only: the roll and pitch
    /// factors act on nothing it integrates and are held, as its roll and
    /// pitch biases are (fitted, they would print the prior's 5 % as a sigma).
    pub planar: bool,
}

/// Prior standard deviation of each scale-factor error.
const PRIOR_SIGMA: f64 = 0.05;

impl Effect for GyroScale {
    fn id(&self) -> String {
        "gyro_scale".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        ["x", "y", "z"]
            .iter()
            .map(|a| ParamInfo::new(format!("scale_error_{a}"), "%", 100.0).within(0.5))
            .collect()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; 3]
    }

    fn fixed(&self, i: usize) -> bool {
        self.planar && i < 2
    }

    fn acts_on_gyro(&self) -> bool {
        true
    }

    fn n_prior(&self) -> usize {
        3
    }

    /// Residuals `s_a / 0.05`.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        for a in 0..3 {
            let row = out.residuals.len();
            out.residuals.push(p[a] / PRIOR_SIGMA);
            out.entries.push((row, a, 1.0 / PRIOR_SIGMA));
        }
    }

    fn gyro(&self, p: &[f64], _j: usize, omega: Vector3<f64>) -> Vector3<f64> {
        Vector3::new(
            omega.x / (1.0 + p[0]),
            omega.y / (1.0 + p[1]),
            omega.z / (1.0 + p[2]),
        )
    }

    fn gyro_partials(&self, p: &[f64], _j: usize, omega: &Vector3<f64>) -> GyroPartials {
        let mut params = Columns::default();
        let mut d_in = Matrix3::zeros();
        for a in 0..3 {
            let k = 1.0 / (1.0 + p[a]);
            d_in[(a, a)] = k;
            let mut col = Vector3::zeros();
            col[a] = -omega[a] * k * k;
            params.push(a, col);
        }
        GyroPartials { d_in, params }
    }

    fn gyro_batch(&self, p: &[f64], _first: usize, rates: &mut [Vector3<f64>]) {
        let k = Vector3::new(1.0 / (1.0 + p[0]), 1.0 / (1.0 + p[1]), 1.0 / (1.0 + p[2]));
        for w in rates.iter_mut() {
            *w = w.component_mul(&k);
        }
    }

    fn gyro_backward(
        &self,
        p: &[f64],
        omega_in: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        grad_p: &mut [f64],
    ) {
        let k = Vector3::new(1.0 / (1.0 + p[0]), 1.0 / (1.0 + p[1]), 1.0 / (1.0 + p[2]));
        let mut acc = Vector3::zeros();
        for (g, w) in grad.iter_mut().zip(omega_in).skip(1) {
            acc -= g.component_mul(w);
            *g = g.component_mul(&k);
        }
        for a in 0..3 {
            grad_p[a] += acc[a] * k[a] * k[a];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partials_match_finite_differences() {
        let p = [0.03, -0.02, 0.045];
        crate::effects::testing::check_gyro_partials(
            &GyroScale::default(),
            &p,
            5,
            Vector3::new(0.4, -0.2, 0.9),
        );
        crate::effects::testing::check_batches(&GyroScale::default(), &p, 300);
    }
}
