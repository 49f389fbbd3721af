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
//! `d'_j = d_j + c_g dt_j / T'_g` for the steps of gap `g` that move
//! (`d_j != 0`; `T'_g` their time, the gap's length `T_g` less the stands
//! that the gyro told, see [`crate::standing`]), `d d'_j / d c_g = dt_j / T'_g`.
//!
//! Prior `c_g ~ N(0, (2 m/s T_g)^2)`: a vehicle's mean speed over a gap is
//! within a few m/s of the one interpolated between its ends; the prior
//! holds a gap that no fix follows (at a ride's end).
//!
//! The band: `c_g`'s sigma is part of the path's covariance, but how the
//! gap's distance is spread inside it (a stop at a light, then a sprint) no
//! parameter carries. With the gap's total pinned by `c_g`, the distance's
//! error at `tau = f T_g` into the gap is the bridge
//!
//! `e(f) = D(f T) - D_lin(f T) - f (D(T) - D_lin(T))`,
//!
//! `D` the distance travelled, `D_lin` the one the speed interpolated
//! between the gap's ends gives. How large `e` gets is the ride's own: every
//! stretch of length `T_g` of the ride where the speed was logged is a gap
//! that did not happen, whose `e(f)` the log shows. Its spread, added along
//! the track, is `(q95(|e(f)|) / 1.96)^2`, the 95th percentile over those
//! stretches (one a second), so that the 95 % band holds the stretches the
//! ride has: a vehicle that stops at lights stops in its gaps too, which a
//! Gaussian speed error does not expect (measured on simulated rides with
//! stops, seeds 2-9 of `tests/gnss_speed.rs`: the truth inside the 95 %
//! ellipse on 69.0 % of the gap rows with the Brownian bridge below laid
//! along the road's direction, 83.9 % with this spread laid along the path,
//! 92.6 % once the stands inside the gaps are told by the gyro, see
//! [`crate::standing`]; the spread is still taken from stretches
//! interpolated straight across, so where a stand is told it errs wide).
//!
//! Where the ride has too few such stretches (a gap as long as the ride's
//! logged stretches), the speed's error against the interpolation is taken
//! as a Brownian bridge of intensity `q` (m^2/s^3), the mean square of the
//! speed's one-second changes outside the gaps:
//!
//! `Var(tau) = q tau^2 (T_g - tau)^2 / (12 T_g)`
//!
//! (the integrated bridge less its share of the total; checked by Monte
//! Carlo).

use super::{Columns, DistancePartials, Effect, ParamInfo, PriorRows};
use crate::contract::{ModelError, StartGuess};
use crate::signals::Signals;

/// The prior's spread of a gap's mean speed about the interpolated one (m/s).
const GAP_SPEED_SIGMA_MPS: f64 = 2.0;

/// Intervals of a gap at whose ends the ride's own spread is tabulated.
const SPREAD_GRID: usize = 20;

/// Fewest stretches of a gap's length (one a second) for the ride's own
/// spread; fewer, and the Brownian bridge stands in.
const MIN_STRETCHES: usize = 30;

/// Most stretches per gap: a long ride's are spaced further than a second.
const MAX_STRETCHES: usize = 2000;

#[derive(Clone, Debug, Default)]
pub struct GnssGaps {
    /// Each gap's length (s).
    lengths: Vec<f64>,
    /// Per step: the gap it lies in and its weight `dt_j / T'_g`, if any.
    step: Vec<Option<(usize, f64)>>,
    /// Per step in a gap: the spread of the distance inside it (m^2), the
    /// signals' own (computed once per ride, see `Signals::gap_spread`).
    variance: std::sync::Arc<[f64]>,
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

/// The Brownian bridge's spread at `tau` into a gap of length `length` (m^2).
fn brownian_bridge(q: f64, length: f64, tau: f64) -> f64 {
    q * tau * tau * (length - tau).powi(2) / (12.0 * length)
}

/// `table[k]` at `f = k / SPREAD_GRID`, linear in between; nothing at the ends.
fn interpolate(table: &[f64], f: f64) -> f64 {
    let x = f.clamp(0.0, 1.0) * SPREAD_GRID as f64;
    let k = (x.floor() as usize).min(SPREAD_GRID - 1);
    let w = x - k as f64;
    table[k] * (1.0 - w) + table[k + 1] * w
}

/// The distance travelled along the ride and the speed, at any time.
struct Travelled<'a> {
    t: &'a [f64],
    /// Distance from the ride's start at each row (m).
    cumulative: Vec<f64>,
    /// The mean speed of the step ending at each row (m/s).
    speed: Vec<f64>,
}

impl<'a> Travelled<'a> {
    fn new(signals: &'a Signals) -> Self {
        let mut total = 0.0;
        let cumulative = signals
            .distance
            .iter()
            .map(|d| {
                total += d;
                total
            })
            .collect();
        let speed = signals
            .distance
            .iter()
            .zip(&signals.dt)
            .map(|(d, dt)| if *dt > 0.0 { d / dt } else { 0.0 })
            .collect();
        Self {
            t: &signals.t,
            cumulative,
            speed,
        }
    }

    /// The distance travelled by time `t`, interpolated between rows.
    fn at(&self, t: f64) -> f64 {
        let j = self.t.partition_point(|&x| x < t);
        if j == 0 {
            return self.cumulative[0];
        }
        if j >= self.t.len() {
            return self.cumulative[self.t.len() - 1];
        }
        let (a, b) = (self.t[j - 1], self.t[j]);
        let w = if b > a { (t - a) / (b - a) } else { 1.0 };
        self.cumulative[j - 1] + w * (self.cumulative[j] - self.cumulative[j - 1])
    }

    /// The speed at time `t` (the step's that ends at or after it).
    fn speed_at(&self, t: f64) -> f64 {
        let j = self.t.partition_point(|&x| x < t).min(self.t.len() - 1);
        self.speed[j.max(1)]
    }

    /// The ride's own spread of a bridged distance over gaps of `length` s
    /// (see the module docs): per `f = k / SPREAD_GRID`, `(q95 |e(f)| /
    /// 1.96)^2` over the stretches of that length clear of every gap, one a
    /// second. `None` with fewer than [`MIN_STRETCHES`].
    fn bridge_spread(&self, length: f64, gaps: &[(f64, f64)]) -> Option<Vec<f64>> {
        let (&first, &last) = self.t.first().zip(self.t.last())?;
        let span = last - first - length;
        if !(length > 0.0 && span > 0.0) {
            return None;
        }
        let spacing = (span / MAX_STRETCHES as f64).max(1.0);
        let mut errors: Vec<Vec<f64>> = vec![Vec::new(); SPREAD_GRID + 1];
        let mut k = 0;
        loop {
            let a = first + k as f64 * spacing;
            k += 1;
            let b = a + length;
            if b > last {
                break;
            }
            if gaps.iter().any(|&(ga, gb)| a < gb && b > ga) {
                continue;
            }
            let (va, vb) = (self.speed_at(a), self.speed_at(b));
            let base = self.at(a);
            let total = self.at(b) - base - 0.5 * (va + vb) * length;
            for (i, e) in errors.iter_mut().enumerate().take(SPREAD_GRID).skip(1) {
                let f = i as f64 / SPREAD_GRID as f64;
                let tau = f * length;
                let linear = va * tau + 0.5 * (vb - va) * f * tau;
                e.push((self.at(a + tau) - base - linear - f * total).abs());
            }
        }
        if errors[1].len() < MIN_STRETCHES {
            return None;
        }
        Some(
            errors
                .iter_mut()
                .map(|e| {
                    if e.is_empty() {
                        return 0.0;
                    }
                    (crate::statistics::quantile(e, 0.95) / 1.96).powi(2)
                })
                .collect(),
        )
    }
}

impl GnssGaps {
    /// Whether `signals` have gaps in a GNSS-speed distance (the effect's use).
    pub fn applies(signals: &Signals) -> bool {
        !signals.distance_gaps().is_empty()
    }

    pub fn new(signals: &Signals) -> Result<Self, ModelError> {
        let gaps = &signals.distance_gaps();
        if gaps.is_empty() {
            return Err(ModelError::NotApplicable {
                effect: "gnss_gaps".into(),
                reason: "the distance is measured over the whole ride (no gap in the GNSS speed, nor in a logged speed or wheel pulses)".into(),
            });
        }
        let n = signals.t.len();
        let mut step = vec![None; n];
        let mut lengths = Vec::with_capacity(gaps.len());
        for (g, &(a, b)) in gaps.iter().enumerate() {
            let length = b - a;
            lengths.push(length);
            if length <= 0.0 {
                continue;
            }
            // The steps ending inside the gap, `a < t_j <= b`; the
            // correction moves only those the vehicle moves on (a stand the
            // gyro told stays put), over their time `T'_g`.
            let first = signals.t.partition_point(|&t| t <= a).max(1);
            let end = signals.t.partition_point(|&t| t <= b);
            // A gap in the log has no stand told inside it (its rows are
            // filled, see `crate::log_gaps`), and wheel pulses count no
            // distance there: the correction moves all of it.
            let filled = signals.log_gaps.contains(&(a, b));
            let moving = |j: usize| filled || signals.distance[j] != 0.0;
            let moving_s: f64 = (first..end)
                .filter(|&j| moving(j))
                .map(|j| signals.dt[j])
                .sum();
            for j in first..end {
                step[j] = if moving_s <= 0.0 {
                    Some((g, signals.dt[j] / length))
                } else if moving(j) {
                    Some((g, signals.dt[j] / moving_s))
                } else {
                    Some((g, 0.0))
                };
            }
        }
        let variance = signals
            .gap_spread
            .get_or_init(|| {
                let q = speed_intensity(signals, &step);
                let ride = Travelled::new(signals);
                let spreads: Vec<Option<Vec<f64>>> = lengths
                    .iter()
                    .map(|&length| ride.bridge_spread(length, gaps))
                    .collect();
                let mut variance = vec![0.0; n];
                for (j, v) in variance.iter_mut().enumerate() {
                    if let Some((g, _)) = step[j] {
                        let (length, tau) = (lengths[g], signals.t[j] - gaps[g].0);
                        *v = match &spreads[g] {
                            Some(table) => interpolate(table, tau / length),
                            None => brownian_bridge(q, length, tau),
                        };
                    }
                }
                variance.into()
            })
            .clone();
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
    use crate::signals::Odometer;

    fn signals_with_gaps() -> Signals {
        let mut s = crate::testing::simulated_signals(3, 60.0, &[]);
        s.odometer = Odometer::GnssSpeed {
            samples: 40,
            standing_s: 0.0,
            gaps: vec![(10.0, 14.0), (30.5, 40.0)],
            stands_in_gaps: Vec::new(),
            stand_rule: None,
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

    /// A gap as long as the ride's logged stretches allow too few of its
    /// length (here 20 < [`MIN_STRETCHES`]) takes the Brownian bridge's
    /// spread: nothing at its ends, `q T^3 / 192` in its middle, nothing
    /// outside the gaps.
    #[test]
    fn a_long_gap_takes_the_brownian_bridges_spread() {
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

    /// The ride's own spread, checked against the bridge computed in closed
    /// form: a speed `v(t) = 4 + 3.5 sin(2 pi t / 97)` travels
    /// `D(t) = 4 t + 3.5 (97 / 2 pi) (1 - cos(2 pi t / 97))`; every stretch of
    /// 40 s clear of the gap, one a second, gives
    /// `e(1/2) = D(a + 20) - D(a) - 20 v_a - 5 (v_b - v_a) - (D(b) - D(a) - 20 (v_a + v_b)) / 2`,
    /// whose 95th percentile over 1.96, squared, is the gap's middle.
    #[test]
    fn a_gaps_spread_is_the_95th_percentile_of_the_rides_own_stretches() {
        let mut s = crate::testing::simulated_signals(3, 400.0, &[]);
        let w = 2.0 * std::f64::consts::PI / 97.0;
        let travelled = |t: f64| 4.0 * t + 3.5 / w * (1.0 - (w * t).cos());
        let speed = |t: f64| 4.0 + 3.5 * (w * t).sin();
        for j in 1..s.t.len() {
            s.distance[j] = travelled(s.t[j]) - travelled(s.t[j - 1]);
        }
        let gap = (200.0, 240.0);
        s.odometer = Odometer::GnssSpeed {
            samples: 4000,
            standing_s: 0.0,
            gaps: vec![gap],
            stands_in_gaps: Vec::new(),
            stand_rule: None,
        };
        let effect = GnssGaps::new(&s).unwrap();
        let mut e: Vec<f64> = Vec::new();
        let (first, last) = (s.t[0], s.t[s.t.len() - 1]);
        let mut a = first;
        while a + 40.0 <= last {
            let b = a + 40.0;
            if !(a < gap.1 && b > gap.0) {
                let (va, vb) = (speed(a), speed(b));
                let total = travelled(b) - travelled(a) - 20.0 * (va + vb);
                let half = travelled(a + 20.0) - travelled(a) - 20.0 * va - 5.0 * (vb - va);
                e.push((half - 0.5 * total).abs());
            }
            a += 1.0;
        }
        assert!(e.len() >= MIN_STRETCHES, "{} stretches", e.len());
        e.sort_by(f64::total_cmp);
        let q95 = e[(0.95 * e.len() as f64).ceil() as usize - 1];
        let expect = (q95 / 1.96).powi(2);
        let row = |t: f64| s.t.partition_point(|&v| v < t);
        let mid = effect.along_track_variance(row(220.0));
        assert!(expect > 1.0, "{expect}");
        assert!((mid - expect).abs() < 0.02 * expect, "{mid} vs {expect}");
        assert!(effect.along_track_variance(row(200.3)) < 0.05 * mid);
        assert_eq!(effect.along_track_variance(row(100.0)), 0.0);
    }

    #[test]
    fn it_applies_only_to_a_gnss_speed_distance_with_gaps() {
        assert!(GnssGaps::applies(&signals_with_gaps()));
        let plain = crate::testing::simulated_signals(3, 60.0, &[]);
        assert!(!GnssGaps::applies(&plain));
        assert!(GnssGaps::new(&plain).is_err());
    }
}
