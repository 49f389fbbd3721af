//! `speed_lag`: the GNSS speed that gives the distance (a log without a
//! wheel sensor) lags the gyro (1 parameter, s).
//!
//! A receiver's Doppler speed refers to its epoch and reaches the log some
//! hundreds of milliseconds later, stamped on arrival, while the gyro's
//! samples are stamped as they are taken. The distance travelled up to row
//! time `t` is then `D(t + lag)` of the logged one, to first order
//! `D(t) + lag s(t)`, so each step's distance becomes
//!
//! `d'_j = d_j + lag (s_j - s_{j-1})`, `d d'_j / d lag = s_j - s_{j-1}`,
//!
//! with `s_j` the logged speed at row `j`, taken from the logged distance
//! over a window of `2 h` ([`SPEED_WINDOW_S`]) around it. The correction
//! telescopes: it moves each point of the path along the track by
//! `lag s(t)` and leaves the total distance as it was. Visible as an
//! along-track residual that follows acceleration (where `gps_lag`'s
//! follows speed). The fixes of the same receiver share its latency, so
//! on their own the two are seen together; the gyro's turns tell them
//! apart.
//!
//! Chained before `odometer_gain` (`d = k (d_raw + lag Delta s)`), so the
//! speed's scale and its lag stay apart. Offered only where the distance
//! is the GNSS speed's: a wheel sensor's distance is not a receiver's.

use super::{Columns, DistancePartials, Effect, ParamInfo};
use crate::contract::{ModelError, StartGuess};
use crate::signals::{Odometer, Signals};

/// Half the window over which the speed at a row is taken from the
/// distance (s): wide enough to smooth a 1-18 Hz receiver's steps.
const SPEED_WINDOW_S: f64 = 0.25;

#[derive(Clone, Debug, Default)]
pub struct SpeedLag {
    /// `s_j - s_{j-1}` (m/s) of each step, `0` at step 0.
    speed_change: Vec<f64>,
}

impl SpeedLag {
    /// Whether `signals` take the effect: a distance from the GNSS speed.
    pub fn applies(signals: &Signals) -> bool {
        matches!(signals.odometer, Odometer::GnssSpeed { .. })
    }

    pub fn new(signals: &Signals) -> Result<Self, ModelError> {
        if !Self::applies(signals) {
            return Err(ModelError::NotApplicable {
                effect: "speed_lag".into(),
                reason: format!(
                    "the distance is not the GNSS speed's but {} (--distance gnss takes it)",
                    signals.odometer.describe()
                ),
            });
        }
        let n = signals.t.len();
        // Cumulative distance at each row, and the speed over a window
        // around each row (linear interpolation of the cumulative distance).
        let mut cumulative = Vec::with_capacity(n);
        let mut sum = 0.0;
        for &d in &signals.distance {
            sum += d;
            cumulative.push(sum);
        }
        let t = &signals.t;
        let at = |x: f64| -> f64 {
            let i = t.partition_point(|&v| v < x);
            if i == 0 {
                return cumulative[0];
            }
            if i >= n {
                return cumulative[n - 1];
            }
            let w = (x - t[i - 1]) / (t[i] - t[i - 1]);
            cumulative[i - 1] + w * (cumulative[i] - cumulative[i - 1])
        };
        let speed: Vec<f64> = t
            .iter()
            .map(|&tj| {
                let (a, b) = (
                    (tj - SPEED_WINDOW_S).max(t[0]),
                    (tj + SPEED_WINDOW_S).min(t[n - 1]),
                );
                if b > a {
                    (at(b) - at(a)) / (b - a)
                } else {
                    0.0
                }
            })
            .collect();
        let mut speed_change = vec![0.0; n];
        for j in 1..n {
            speed_change[j] = speed[j] - speed[j - 1];
        }
        Ok(Self { speed_change })
    }
}

impl Effect for SpeedLag {
    fn id(&self) -> String {
        "speed_lag".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        vec![ParamInfo::new("lag", "s", 1.0).within(5.0)]
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0]
    }

    fn acts_on_distance(&self) -> bool {
        true
    }

    fn distance(&self, p: &[f64], j: usize, d: f64) -> f64 {
        d + p[0] * self.speed_change[j]
    }

    fn distance_partials(&self, _p: &[f64], j: usize, _d: f64) -> DistancePartials {
        let mut params = Columns::default();
        params.push(0, self.speed_change[j]);
        DistancePartials { d_in: 1.0, params }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signals_on_gnss_speed() -> Signals {
        let mut s = crate::testing::simulated_signals(3, 40.0, &[]);
        s.odometer = Odometer::GnssSpeed {
            samples: 40,
            standing_s: 0.0,
            gaps: Vec::new(),
            stands_in_gaps: Vec::new(),
            stand_rule: None,
        };
        s
    }

    #[test]
    fn partials_match_finite_differences() {
        let effect = SpeedLag::new(&signals_on_gnss_speed()).unwrap();
        let h = 1e-6;
        for j in [1, 50, 777, 2000] {
            let (p, d) = ([0.3], 0.05);
            let part = effect.distance_partials(&p, j, d);
            let fd_d = (effect.distance(&p, j, d + h) - effect.distance(&p, j, d - h)) / (2.0 * h);
            assert!((fd_d - part.d_in).abs() < 1e-8);
            let fd_p = (effect.distance(&[p[0] + h], j, d) - effect.distance(&[p[0] - h], j, d))
                / (2.0 * h);
            let col = part.params.as_slice().iter().map(|&(_, v)| v).sum::<f64>();
            assert!((fd_p - col).abs() < 1e-8, "step {j}: {fd_p} vs {col}");
        }
    }

    /// The correction telescopes: the total distance is unchanged up to the
    /// difference of the end speeds, and each point moves by `lag s(t)`.
    #[test]
    fn a_lag_moves_the_path_along_the_track_and_keeps_its_length() {
        let s = signals_on_gnss_speed();
        let effect = SpeedLag::new(&s).unwrap();
        let total: f64 = effect.speed_change.iter().sum();
        let n = s.t.len();
        let speed = |j: usize| {
            let (a, b) = (j.saturating_sub(25), (j + 25).min(n - 1));
            s.distance[a + 1..=b].iter().sum::<f64>() / (s.t[b] - s.t[a])
        };
        assert!((total - (speed(n - 1) - speed(0))).abs() < 0.5, "{total}");
    }

    #[test]
    fn a_wheel_sensor_ride_does_not_offer_it() {
        let s = crate::testing::simulated_signals(3, 40.0, &[]);
        let e = SpeedLag::new(&s).unwrap_err().to_string();
        assert!(
            e.contains("speed_lag") && e.contains("--distance gnss"),
            "{e}"
        );
    }
}
