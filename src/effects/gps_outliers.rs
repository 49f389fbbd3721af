//! `gps_outliers`: a robust loss on the GPS rows (no parameters).
//!
//! Multipath near buildings throws fixes tens of metres off for seconds at a
//! time; squared residuals let a few such fixes bend the whole path. With
//! this effect each GPS row's weighted residual `e` enters the cost through
//! the Cauchy loss `s^2 ln(1 + e^2 / s^2)` (see `model::observe`), which grows
//! only logarithmically beyond the scale `s`.
//!
//! The scale is estimated from the fixes themselves, before any fit: the
//! second differences `f_{i+1} - 2 f_i + f_{i-1}` of consecutive 1 Hz fixes
//! remove the smooth motion and keep the noise (variance `6 sigma^2` for white
//! noise), and their median absolute deviation ignores the jumps:
//! `sigma = 1.4826 MAD / sqrt(6)`, `s = 2.385 max(sigma, sigma_h) / sigma_h`
//! in weighted units (2.385: 95 % efficiency on Gaussian noise).

use super::{Effect, ParamInfo};
use crate::contract::StartGuess;
use crate::signals::Signals;

#[derive(Clone, Copy, Debug)]
pub struct GpsOutliers {
    /// Cauchy scale in units of the weighted residual.
    scale: f64,
    /// The noise level it was estimated from (m).
    pub sigma_m: f64,
}

impl GpsOutliers {
    pub fn new(signals: &Signals, sigma_horizontal_m: f64) -> Self {
        let f = &signals.fixes;
        let mut second: Vec<f64> = Vec::new();
        for w in f.windows(3) {
            let regular =
                (w[1].t - w[0].t - 1.0).abs() < 0.2 && (w[2].t - w[1].t - 1.0).abs() < 0.2;
            if regular {
                for a in 0..2 {
                    second.push((w[2].en[a] - 2.0 * w[1].en[a] + w[0].en[a]).abs());
                }
            }
        }
        let sigma_m = if second.is_empty() {
            sigma_horizontal_m
        } else {
            1.4826 * crate::statistics::median(&mut second) / 6f64.sqrt()
        };
        let scale = 2.385 * sigma_m.max(sigma_horizontal_m) / sigma_horizontal_m;
        Self { scale, sigma_m }
    }
}

impl Effect for GpsOutliers {
    fn id(&self) -> String {
        "gps_outliers".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        Vec::new()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        Vec::new()
    }

    fn robust_scale(&self) -> Option<f64> {
        Some(self.scale)
    }
}
