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
//! Prior `c_g ~ N(0, (2 m/s T_g)^2)`: a vehicle's mean speed over a gap is
//! within a few m/s of the one interpolated between its ends; the prior
//! holds a gap that no fix follows (at a ride's end).
//!
//! The band: `c_g`'s sigma is part of the path's covariance, but how the
//! gap's distance is spread inside it (a stop at a light, then a sprint) no
//! parameter carries. Taking the speed's error against the interpolation as
//! a Brownian bridge of intensity `q` (m^2/s^3), the distance's error at
//! `tau` into the gap, with the gap's total pinned by `c_g`, has the variance
//!
//! `Var(tau) = q tau^2 (T_g - tau)^2 / (12 T_g)`
//!
//! (the integrated bridge less its share of the total; checked by Monte
//! Carlo), added along the track. `q` is the ride's own: the mean square of
//! its speed's one-second changes outside the gaps.

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
    /// Per step in a gap: the spread of the distance inside it (m^2).
    variance: Vec<f64>,
}

/// The intensity `q` (m^2/s^3) of the speed's changes: the mean square of
/// its one-second changes outside the gaps, from the distance per step.
fn speed_intensity(signals: &Signals, in_gap: &[Option<(usize, f64)>]) -> f64 {
    let speed = |j: usize| {
        if signals.dt[j] > 0.0 {
            signals.distance[j] / signals.dt[j]
        } else {
            0.0
        }
    };
    let (mut sum, mut time) = (0.0, 0.0);
    let mut last: Option<usize> = None;
    for j in 1..signals.t.len() {
        if in_gap[j].is_some() {
            last = None;
            continue;
        }
        match last {
            None => last = Some(j),
            Some(i) if signals.t[j] - signals.t[i] >= 1.0 => {
                sum += (speed(j) - speed(i)).powi(2);
                time += signals.t[j] - signals.t[i];
                last = Some(j);
            }
            Some(_) => {}
        }
    }
    if time > 0.0 { sum / time } else { 0.0 }
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
        let n = signals.t.len();
        let mut step = vec![None; n];
        let mut lengths = Vec::with_capacity(gaps.len());
        for (g, &(a, b)) in gaps.iter().enumerate() {
            let length = b - a;
            lengths.push(length);
            if length <= 0.0 {
                continue;
            }
            // The steps ending inside the gap, `a < t_j <= b`.
            let first = signals.t.partition_point(|&t| t <= a).max(1);
            let end = signals.t.partition_point(|&t| t <= b);
            for j in first..end {
                step[j] = Some((g, signals.dt[j] / length));
            }
        }
        let q = speed_intensity(signals, &step);
        let mut variance = vec![0.0; n];
        for (j, v) in variance.iter_mut().enumerate() {
            if let Some((g, _)) = step[j] {
                let (length, tau) = (lengths[g], signals.t[j] - gaps[g].0);
                *v = q * tau * tau * (length - tau).powi(2) / (12.0 * length);
            }
        }
        Ok(Self {
            lengths,
            step,
            variance,
        })
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

    fn along_track_variance(&self, j: usize) -> f64 {
        self.variance.get(j).copied().unwrap_or(0.0)
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

    /// The bridge's spread: nothing at a gap's ends, `q T^3 / 192` in its
    /// middle, nothing outside the gaps.
    #[test]
    fn the_spread_inside_a_gap_is_the_bridges() {
        let s = signals_with_gaps();
        let effect = GnssGaps::new(&s).unwrap();
        let q = speed_intensity(&s, &effect.step);
        assert!(q > 0.0);
        let row = |t: f64| s.t.partition_point(|&v| v < t);
        let mid = effect.along_track_variance(row(35.25));
        let expect = q * 9.5f64.powi(3) / 192.0;
        assert!((mid - expect).abs() < 0.01 * expect, "{mid} vs {expect}");
        assert!(effect.along_track_variance(row(30.51)) < 0.01 * mid);
        assert_eq!(effect.along_track_variance(row(20.0)), 0.0);
    }

    #[test]
    fn it_applies_only_to_a_gnss_speed_distance_with_gaps() {
        assert!(GnssGaps::applies(&signals_with_gaps()));
        let plain = crate::testing::simulated_signals(3, 60.0, &[]);
        assert!(!GnssGaps::applies(&plain));
        assert!(GnssGaps::new(&plain).is_err());
    }
}
