//! `gnss_gaps`: the distance travelled in each gap of the GNSS speed, free
//! (1 parameter per gap, m). Added by itself where a ride's distance is the
//! GNSS speed's and the speed drops out, as the barometer's offset comes
//! with a barometer.
//!
//! When the receiver loses the sky (a tunnel, a garage, a street canyon)
//! the speed that gives the distance stops with the fixes, and the distance
//! across the gap is the speed interpolated between its ends
//! ([`crate::signals::distance_from_gnss_speed`]): a car that stopped at a
//! light in between, or sped up, is then tens of metres off along the track
//! at the gap's end, and every point after it with it (on a simulated
//! 10-minute ride with two 46 s gaps, 40 m). The fixes after the gap see
//! that error; this effect lets the fit move it, spreading `c_g` metres
//! evenly over gap `g`'s steps:
//!
//! `d'_j = d_j + c_g dt_j / T_g` for the steps of gap `g` (length `T_g`),
//! `d d'_j / d c_g = dt_j / T_g`.
//!
//! Its 1-sigma is part of the path's covariance, so the uncertainty band
//! widens where the gap's distance is not measured. Prior `c_g ~ N(0, (2
//! m/s T_g)^2)`: a vehicle's mean speed over a gap is within a few m/s of
//! the one interpolated between its ends; the prior holds a gap that no fix
//! follows (at a ride's end).

use super::{Columns, DistancePartials, Effect, ParamInfo, PriorRows};
use crate::contract::{ModelError, StartGuess};
use crate::signals::{Odometer, Signals};

/// The prior's spread of a gap's mean speed about the interpolated one (m/s).
const GAP_SPEED_SIGMA_MPS: f64 = 2.0;

#[derive(Clone, Debug, Default)]
pub struct GnssGaps {
    /// Each gap's length (s).
    lengths: Vec<f64>,
    /// Per step: the gap it lies in and its weight `dt_j / T_g`, if any.
    step: Vec<Option<(usize, f64)>>,
}

impl GnssGaps {
    /// Whether `signals` have gaps in a GNSS-speed distance (the effect's use).
    pub fn applies(signals: &Signals) -> bool {
        matches!(&signals.odometer, Odometer::GnssSpeed { gaps, .. } if !gaps.is_empty())
    }

    pub fn new(signals: &Signals) -> Result<Self, ModelError> {
        let Odometer::GnssSpeed { gaps, .. } = &signals.odometer else {
            return Err(ModelError::NotApplicable {
                effect: "gnss_gaps".into(),
                reason: "the distance is not the GNSS speed's".into(),
            });
        };
        let mut step = vec![None; signals.t.len()];
        let mut lengths = Vec::with_capacity(gaps.len());
        for (g, &(a, b)) in gaps.iter().enumerate() {
            let length = b - a;
            lengths.push(length);
            for j in 1..signals.t.len() {
                if signals.t[j] > a && signals.t[j] <= b && length > 0.0 {
                    step[j] = Some((g, signals.dt[j] / length));
                }
            }
        }
        Ok(Self { lengths, step })
    }
}

impl Effect for GnssGaps {
    fn id(&self) -> String {
        "gnss_gaps".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        (0..self.lengths.len())
            .map(|g| ParamInfo::new(format!("gap_{}_m", g + 1), "m", 1.0))
            .collect()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; self.lengths.len()]
    }

    fn n_prior(&self) -> usize {
        self.lengths.len()
    }

    /// Residuals `c_g / (2 m/s T_g)`.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        for (g, &length) in self.lengths.iter().enumerate() {
            let sigma = GAP_SPEED_SIGMA_MPS * length.max(1.0);
            let row = out.residuals.len();
            out.residuals.push(p[g] / sigma);
            out.entries.push((row, g, 1.0 / sigma));
        }
    }

    fn acts_on_distance(&self) -> bool {
        true
    }

    fn distance(&self, p: &[f64], j: usize, d: f64) -> f64 {
        match self.step[j] {
            Some((g, w)) => d + p[g] * w,
            None => d,
        }
    }

    fn distance_partials(&self, _p: &[f64], j: usize, _d: f64) -> DistancePartials {
        let mut params = Columns::default();
        if let Some((g, w)) = self.step[j] {
            params.push(g, w);
        }
        DistancePartials { d_in: 1.0, params }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signals_with_gaps() -> Signals {
        let mut s = crate::testing::simulated_signals(3, 60.0, &[]);
        s.odometer = Odometer::GnssSpeed {
            samples: 40,
            standing_s: 0.0,
            gaps: vec![(10.0, 14.0), (30.5, 40.0)],
        };
        s
    }

    #[test]
    fn partials_match_finite_differences_and_weights_sum_to_one() {
        let s = signals_with_gaps();
        let effect = GnssGaps::new(&s).unwrap();
        assert_eq!(effect.params().len(), 2);
        for g in 0..2 {
            let sum: f64 = effect
                .step
                .iter()
                .flatten()
                .filter(|x| x.0 == g)
                .map(|x| x.1)
                .sum();
            assert!((sum - 1.0).abs() < 0.02, "gap {g}: weights sum to {sum}");
        }
        let h = 1e-6;
        let p = [3.0, -7.0];
        for j in [1, 1200, 3600, 5000] {
            let part = effect.distance_partials(&p, j, 0.04);
            for g in 0..2 {
                let (mut a, mut b) = (p, p);
                a[g] += h;
                b[g] -= h;
                let fd = (effect.distance(&a, j, 0.04) - effect.distance(&b, j, 0.04)) / (2.0 * h);
                let col: f64 = part
                    .params
                    .as_slice()
                    .iter()
                    .filter(|c| c.0 == g)
                    .map(|c| c.1)
                    .sum();
                assert!((fd - col).abs() < 1e-9, "step {j} gap {g}: {fd} vs {col}");
            }
        }
    }

    #[test]
    fn it_applies_only_to_a_gnss_speed_distance_with_gaps() {
        assert!(GnssGaps::applies(&signals_with_gaps()));
        let plain = crate::testing::simulated_signals(3, 60.0, &[]);
        assert!(!GnssGaps::applies(&plain));
        assert!(GnssGaps::new(&plain).is_err());
    }
}
