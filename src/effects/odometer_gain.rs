//! `odometer_gain`: metres travelled per metre the odometer reports (1 parameter).
//!
//! `d_t = k d_t^raw` (paper: the odometer gain). Covers a wrongly configured
//! wheel circumference or a speed sensor's scale error; `d d_t / d k = d_t^raw`.
//!
//! Prior `k ~ N(1, 0.1)`: a physical limit, not a guess. A wrong
//! circumference or a CAN scale is off by a few percent, so the prior costs a
//! real fit nothing (a 3 % error adds 0.09 to the cost), while it keeps an
//! early, short window from flipping the gain's sign. A fit that still ends
//! outside 0.7-1.3 is reported as failed (`limits`).

use super::{Columns, DistancePartials, Effect, ParamInfo, PriorRows};
use crate::contract::StartGuess;

/// Prior standard deviation of the gain about 1.
const GAIN_PRIOR_SIGMA: f64 = 0.1;

#[derive(Clone, Copy, Debug, Default)]
pub struct OdometerGain;

impl Effect for OdometerGain {
    fn id(&self) -> String {
        "odometer_gain".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        vec![ParamInfo::new("gain", "", 1.0).within(0.5)]
    }

    fn initial(&self, guess: &StartGuess) -> Vec<f64> {
        vec![guess.odometer_gain]
    }

    fn n_prior(&self) -> usize {
        1
    }

    /// Residual `(k - 1) / 0.1`.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        let row = out.residuals.len();
        out.residuals.push((p[0] - 1.0) / GAIN_PRIOR_SIGMA);
        out.entries.push((row, 0, 1.0 / GAIN_PRIOR_SIGMA));
    }

    fn acts_on_distance(&self) -> bool {
        true
    }

    fn distance(&self, p: &[f64], _j: usize, d: f64) -> f64 {
        p[0] * d
    }

    fn distance_partials(&self, p: &[f64], _j: usize, d: f64) -> DistancePartials {
        let mut params = Columns::default();
        params.push(0, d);
        DistancePartials { d_in: p[0], params }
    }

    fn distance_batch(&self, p: &[f64], _first: usize, d: &mut [f64]) {
        for x in d.iter_mut() {
            *x *= p[0];
        }
    }

    fn distance_backward(&self, p: &[f64], d_in: &[f64], grad: &mut [f64], grad_p: &mut [f64]) {
        for (g, &x) in grad.iter_mut().zip(d_in).skip(1) {
            grad_p[0] += x * *g;
            *g *= p[0];
        }
    }
}
