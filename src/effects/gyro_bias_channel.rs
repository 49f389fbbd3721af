//! `gyro_bias_channel:<column>`: gyro bias linear in an extra channel of the
//! log (3 parameters: one slope per axis, deg/s per unit of the channel).
//!
//! MEMS gyro biases drift with temperature (tenths of a deg/s over a warm-up);
//! any logged channel can stand in (temperature, supply voltage, ...):
//!
//! ```text
//! omega_j = omega_j^in - k (c_j - c_ref),   d omega_j / d k_a = -(c_j - c_ref) e_a
//! ```
//!
//! `c_ref` is the channel's mean over the ride, so the slope does not also
//! carry a constant bias (that stays with `gyro_bias`). The channel is used as
//! filled by the loader (held between samples).
//!
//! Prior: the bias the channel explains over the ride, slope times the
//! channel's standard deviation `s_c`, is `N(0, 0.5 deg/s)` per axis
//! (residual `k_a s_c / 0.5 deg/s`). Real sensitivities (a few hundredths of
//! a deg/s per degree C over a spread of a few degrees) sit well inside it;
//! it keeps the slope of the barely observable roll axis finite.
//!
//! The slopes are fitted in step 2 only ([`Role::Step2Only`]): inside step
//! 1's first, short windows the channel hardly varies, so its slope is just
//! more constant bias there, and a slope fitted on one window threw the next,
//! wider one into a wrong basin (10 m from the fixes on a simulated ride).
//! Step 2 starts from the paper's path and tells the slope from the segment
//! biases by the fast part of the channel, which the random walk cannot follow.

use nalgebra::Vector3;

use super::gyro_bias::DEG_PER_RAD;
use super::{Effect, GyroPartials, ParamInfo, PriorRows, Role};
use crate::contract::{ModelError, StartGuess};
use crate::signals::Signals;

#[derive(Clone, Debug)]
pub struct GyroBiasChannel {
    channel: String,
    /// `c_j - c_ref` per row.
    centred: Vec<f64>,
    /// Prior weight `s_c / 0.5 deg/s` (per rad/s of slope).
    prior_weight: f64,
    /// A planar model holds the roll and pitch slopes (see `GyroScale::planar`).
    planar: bool,
}

/// Prior standard deviation of the bias a channel explains (deg/s).
const PRIOR_BIAS_DPS: f64 = 0.5;

impl GyroBiasChannel {
    pub fn new(signals: &Signals, channel: &str) -> Result<Self, ModelError> {
        let values = signals
            .channel(channel)
            .ok_or_else(|| ModelError::NotApplicable {
                effect: format!("gyro_bias_channel:{channel}"),
                reason: format!(
                    "the log has no extra channel '{channel}' (it has: {})",
                    signals
                        .channels
                        .iter()
                        .map(|(n, _)| n.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
        let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
        let centred: Vec<f64> = values.iter().map(|v| v - mean).collect();
        let std = (centred.iter().map(|v| v * v).sum::<f64>() / centred.len() as f64).sqrt();
        if !(std > 0.0 && std.is_finite()) {
            return Err(ModelError::NotApplicable {
                effect: format!("gyro_bias_channel:{channel}"),
                reason: format!("channel '{channel}' is constant over the ride"),
            });
        }
        Ok(Self {
            channel: channel.to_string(),
            centred,
            prior_weight: std / (PRIOR_BIAS_DPS / DEG_PER_RAD),
            planar: signals.attitude.is_planar(),
        })
    }
}

impl Effect for GyroBiasChannel {
    fn id(&self) -> String {
        format!("gyro_bias_channel:{}", self.channel)
    }

    fn params(&self) -> Vec<ParamInfo> {
        ["x", "y", "z"]
            .iter()
            .map(|a| ParamInfo::new(format!("slope_{a}"), "deg/s per unit", DEG_PER_RAD))
            .collect()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; 3]
    }

    fn role(&self) -> Role {
        Role::Step2Only
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

    /// Residuals `k_a s_c / 0.5 deg/s`.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        for (a, k) in p.iter().enumerate().take(3) {
            let row = out.residuals.len();
            out.residuals.push(k * self.prior_weight);
            out.entries.push((row, a, self.prior_weight));
        }
    }

    fn gyro(&self, p: &[f64], j: usize, omega: Vector3<f64>) -> Vector3<f64> {
        omega - Vector3::new(p[0], p[1], p[2]) * self.centred[j]
    }

    fn gyro_partials(&self, _p: &[f64], j: usize, _omega: &Vector3<f64>) -> GyroPartials {
        let mut part = GyroPartials::bias(0);
        for (_, col) in part.params.as_mut_slice() {
            *col *= self.centred[j];
        }
        part
    }

    fn gyro_batch(&self, p: &[f64], first: usize, rates: &mut [Vector3<f64>]) {
        let k = Vector3::new(p[0], p[1], p[2]);
        for (w, &c) in rates.iter_mut().zip(&self.centred[first..]) {
            *w -= k * c;
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
        let mut acc = Vector3::zeros();
        for (g, &c) in grad.iter().zip(&self.centred).skip(1) {
            acc += g * c;
        }
        for a in 0..3 {
            grad_p[a] -= acc[a];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partials_match_finite_differences() {
        let sig = crate::testing::simulated_signals(3, 120.0, &[]);
        let e = GyroBiasChannel::new(&sig, "temp_c").expect("temp_c");
        let p = [0.001, -0.002, 0.003];
        crate::effects::testing::check_gyro_partials(&e, &p, 500, Vector3::new(0.1, 0.2, -0.3));
        crate::effects::testing::check_batches(&e, &p, 1000);
        assert!(GyroBiasChannel::new(&sig, "nope").is_err());
    }
}
