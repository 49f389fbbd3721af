//! A UTC reference track (GPX, NMEA, FIT) placed on the clock of a ride
//! that does not say when it started (no `t0_unix_s`: a logger counting
//! from its own power-on, a phone export in elapsed time), by the one
//! thing both share: the road. The reference is a better track of the
//! same drive, so at the right clock offset `c` (reference time minus ride
//! time) every fix `(t_i, x_i)` lies near the reference's position at
//! `t_i + c`; at any other offset only the places the drive passes twice.
//!
//! The offset is found in three passes, the first two robust to city
//! fixes tens of metres off:
//!
//! 1. votes: every reference point within [`VOTE_RADIUS_M`] of a fix votes
//!    for the offset `t_ref - t_fix` (whole seconds, one vote per fix and
//!    second), and the most-voted second wins;
//! 2. the fixes: around it, the offset whose median fix-to-reference
//!    distance `median_i |x_i - r(t_i + c)|` is least, in steps of
//!    [`FINE_STEP_S`];
//! 3. the odometer: around that, the offset at which the ride's distance
//!    over each stretch of the reference matches the stretch's length
//!    ([`distance_clock`]). The fixes' offset carries their latency (the
//!    comma drive's arrive 0.1 s late, and a path's error to a reference
//!    placed by them hid that lag: 0.72 m for 1.25 m); the odometer's
//!    carries its own, smaller one (0.04 s there, 0.09-0.17 s for a
//!    bicycle's wheel pulses).
//!
//! A clock that the track cannot tell (a vehicle that stood still, a loop
//! driven twice with another offset as good) is no placement: the caller
//! refuses the reference as before, asking for the ride's start time.

use std::collections::HashMap;

use crate::import::reference::ReferenceTrack;
use crate::signals::Signals;

/// A reference point votes for a fix's offset within this distance (m):
/// beyond city fixes' usual error (10-30 m), inside a block.
const VOTE_RADIUS_M: f64 = 40.0;

/// Fixes used (evenly spread): the vote's cost stays bounded on long rides.
const MAX_FIXES: usize = 600;

/// Step (s) of the fixes' refinement, over +-[`VOTE_SPAN_S`] around the
/// vote; the odometer's spans +-[`FINE_SPAN_S`] around that.
const FINE_STEP_S: f64 = 0.05;
const VOTE_SPAN_S: f64 = 10.0;
const FINE_SPAN_S: f64 = 2.0;

/// The odometer's refinement: stretches of the reference at least this
/// long (s), at most [`MAX_STRETCHES`] of them, offsets in steps of
/// [`DISTANCE_STEP_S`]; its minimum must be [`SHARPNESS`] times below the
/// misfit [`SHARP_S`] either side.
const STRETCH_S: f64 = 0.5;
const MAX_STRETCHES: usize = 4000;
const DISTANCE_STEP_S: f64 = 0.01;
const SHARP_S: f64 = 0.5;
const SHARPNESS: f64 = 1.5;

/// At the offset found, the fixes' median distance from the reference must
/// be within this (m): the reference then is this drive's.
const MAX_MEDIAN_M: f64 = 50.0;

/// Another offset at least this far (s) from the one found, whose median
/// distance is within [`AMBIGUOUS_RATIO`] of it, makes the placement
/// ambiguous.
const OTHER_PEAK_S: f64 = 25.0;
const AMBIGUOUS_RATIO: f64 = 1.5;

/// Where a UTC reference falls on a ride's clock, found from its track.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackClock {
    /// Reference time minus ride time (s): a reference point at `t` is at
    /// `t - offset_s` on the ride's clock.
    pub offset_s: f64,
    /// The fixes' median distance (m) from the reference at that offset.
    pub median_m: f64,
    /// Fixes compared.
    pub fixes: usize,
    /// Whether the offset is the odometer's (free of the fixes' latency);
    /// else the fixes' own, their latency in it.
    pub by_distance: bool,
    /// The fixes' median distance (m) from the reference at no offset
    /// (`None` where too few fixes fall inside it there).
    pub median_at_zero_m: Option<f64>,
}

impl TrackClock {
    /// How the offset was found, in words: "where the odometer's distance
    /// matches the track's", or where the fixes lie nearest it (the
    /// odometer's speed varies too little to tell).
    pub fn found_by(&self) -> &'static str {
        if self.by_distance {
            "where the odometer's distance matches the track's"
        } else {
            "where the fixes lie nearest it (the odometer's speed varies too little to tell)"
        }
    }
}

/// The reference's horizontal position (east, north) at time `t` on its own
/// clock, interpolated between points at most `max_gap` apart.
fn at(track_t: &[f64], en: &[[f64; 2]], t: f64, max_gap: f64) -> Option<[f64; 2]> {
    let k = track_t.partition_point(|&x| x <= t);
    if k == 0 || k == track_t.len() {
        return None;
    }
    let (ta, tb) = (track_t[k - 1], track_t[k]);
    if tb - ta > max_gap {
        return None;
    }
    let w = (t - ta) / (tb - ta);
    let (a, b) = (en[k - 1], en[k]);
    Some([a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])])
}

/// The clock offset of `track` (on its own, UTC clock) against the ride
/// of `signals`, from their tracks (see the module docs); `None` where the
/// track cannot tell it.
pub fn track_clock(track: &ReferenceTrack, signals: &Signals) -> Option<TrackClock> {
    let en: Vec<[f64; 2]> = track
        .points
        .iter()
        .map(|g| {
            let p = signals
                .frame
                .to_enu(&crate::geodesy::Geodetic::new(g.lat_deg, g.lon_deg, 0.0));
            [p.x, p.y]
        })
        .collect();
    let stride = signals.fixes.len().div_ceil(MAX_FIXES).max(1);
    let fixes: Vec<(f64, [f64; 2])> = signals
        .fixes
        .iter()
        .step_by(stride)
        .map(|f| (f.t, f.en))
        .collect();
    if fixes.len() < 10 || en.len() < 2 {
        return None;
    }
    // Reference points by cell of VOTE_RADIUS_M.
    let cell = |p: [f64; 2]| {
        (
            (p[0] / VOTE_RADIUS_M).floor() as i64,
            (p[1] / VOTE_RADIUS_M).floor() as i64,
        )
    };
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (k, p) in en.iter().enumerate() {
        if p[0].is_finite() && p[1].is_finite() {
            grid.entry(cell(*p)).or_default().push(k);
        }
    }
    let mut votes: HashMap<i64, usize> = HashMap::new();
    let mut mine = Vec::new();
    for (t, x) in &fixes {
        let (ci, cj) = cell(*x);
        mine.clear();
        for di in -1..=1 {
            for dj in -1..=1 {
                for &k in grid.get(&(ci + di, cj + dj)).into_iter().flatten() {
                    let d = (en[k][0] - x[0]).hypot(en[k][1] - x[1]);
                    if d <= VOTE_RADIUS_M {
                        mine.push((track.t_s[k] - t).round() as i64);
                    }
                }
            }
        }
        mine.sort_unstable();
        mine.dedup();
        for &s in &mine {
            *votes.entry(s).or_default() += 1;
        }
    }
    let max_gap = super::reference::MAX_GAP_S;
    let median_at = |offset: f64| -> Option<(f64, usize)> {
        let mut d: Vec<f64> = fixes
            .iter()
            .filter_map(|(t, x)| {
                at(&track.t_s, &en, t + offset, max_gap).map(|r| (r[0] - x[0]).hypot(r[1] - x[1]))
            })
            .collect();
        // A quarter of the fixes at least (a reference may cover part of
        // the ride) must fall inside the reference.
        (4 * d.len() >= fixes.len() && d.len() >= 10)
            .then(|| (crate::statistics::median(&mut d), d.len()))
    };
    // The best refined offset around a voted second: a vote's peak is as
    // wide as the time a vehicle takes to cross the vote's radius (16 s
    // at 5 m/s), so the scan spans VOTE_SPAN_S either side.
    let refine = |second: i64| -> Option<(f64, f64, usize)> {
        let steps = (VOTE_SPAN_S / FINE_STEP_S).round() as i64;
        (-steps..=steps)
            .filter_map(|k| {
                let c = second as f64 + k as f64 * FINE_STEP_S;
                median_at(c).map(|(m, n)| (c, m, n))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
    };
    let mut ranked: Vec<(i64, usize)> = votes.into_iter().collect();
    ranked.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let &(best_second, _) = ranked.first()?;
    let (offset, median_m, n) = refine(best_second)?;
    if median_m > MAX_MEDIAN_M {
        return None;
    }
    // The strongest other candidates, away from the one found: none may
    // fit nearly as well.
    let rival = ranked
        .iter()
        .filter(|(s, _)| (*s as f64 - offset).abs() >= OTHER_PEAK_S)
        .take(3)
        .filter_map(|&(s, _)| refine(s))
        .map(|r| r.1)
        .fold(f64::INFINITY, f64::min);
    if rival < AMBIGUOUS_RATIO * median_m.max(1.0) {
        return None;
    }
    // The fixes' offset carries their latency (comma's arrive 0.1 s late):
    // the odometer's, where the distance tells it, does not.
    let by_distance = distance_clock(&track.t_s, &en, signals, offset);
    Some(TrackClock {
        offset_s: by_distance.unwrap_or(offset),
        median_m: median_at(by_distance.unwrap_or(offset)).map_or(median_m, |m| m.0),
        fixes: n,
        by_distance: by_distance.is_some(),
        median_at_zero_m: median_at(0.0).map(|m| m.0),
    })
}

/// The offset (s) near `coarse` at which the ride's odometer distance over
/// each stretch of the reference, `D(t_(k+1) - c) - D(t_k - c)`, best
/// matches the stretch's own length `|r_(k+1) - r_k|` up to a gain `g`:
/// least `sum_k (|r_(k+1) - r_k| - g (D(t_(k+1) - c) - D(t_k - c)))^2`,
/// over `coarse +- FINE_SPAN_S` in steps of [`DISTANCE_STEP_S`]. The
/// stretches join reference points at least [`STRETCH_S`] apart. `None`
/// where the minimum is not sharp (a speed that never changes) or the gain
/// is no odometer's.
fn distance_clock(track_t: &[f64], en: &[[f64; 2]], signals: &Signals, coarse: f64) -> Option<f64> {
    let mut along = Vec::with_capacity(signals.t.len());
    let mut total = 0.0;
    for d in &signals.distance {
        total += d;
        along.push(total);
    }
    let ride = &signals.t;
    let (first, last) = (*ride.first()?, *ride.last()?);
    let distance_at = |t: f64| -> Option<f64> {
        if !(first..=last).contains(&t) {
            return None;
        }
        let k = ride.partition_point(|&x| x <= t).clamp(1, ride.len() - 1);
        let (ta, tb) = (ride[k - 1], ride[k]);
        let w = if tb > ta { (t - ta) / (tb - ta) } else { 0.0 };
        Some(along[k - 1] + w * (along[k] - along[k - 1]))
    };
    // Stretches between points at least STRETCH_S apart, without gaps.
    let mut kept = vec![0usize];
    for k in 1..track_t.len() {
        if track_t[k] - track_t[kept[kept.len() - 1]] >= STRETCH_S {
            kept.push(k);
        }
    }
    let stride = kept.len().div_ceil(MAX_STRETCHES).max(1);
    let stretches: Vec<(f64, f64, f64)> = kept
        .windows(2)
        .step_by(stride)
        .filter(|w| track_t[w[1]] - track_t[w[0]] <= 3.0 * STRETCH_S)
        .map(|w| {
            let (a, b) = (en[w[0]], en[w[1]]);
            (
                track_t[w[0]],
                track_t[w[1]],
                (b[0] - a[0]).hypot(b[1] - a[1]),
            )
        })
        .filter(|s| s.2.is_finite())
        .collect();
    let misfit = |c: f64| -> Option<(f64, f64)> {
        let (mut xx, mut xy, mut yy, mut n) = (0.0, 0.0, 0.0, 0usize);
        for &(ta, tb, y) in &stretches {
            let (Some(da), Some(db)) = (distance_at(ta - c), distance_at(tb - c)) else {
                continue;
            };
            let x = db - da;
            xx += x * x;
            xy += x * y;
            yy += y * y;
            n += 1;
        }
        (n >= 20 && xx > 0.0).then(|| (yy - xy * xy / xx, xy / xx))
    };
    let steps = (FINE_SPAN_S / DISTANCE_STEP_S).round() as i64;
    let (best, sse, gain) = (-steps..=steps)
        .filter_map(|k| {
            let c = coarse + k as f64 * DISTANCE_STEP_S;
            misfit(c).map(|(sse, gain)| (c, sse, gain))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    // Sharp: half a second either way (where it can be told) fits far worse.
    let sharp = [-SHARP_S, SHARP_S]
        .iter()
        .filter_map(|d| misfit(best + d))
        .all(|(other, _)| other > SHARPNESS * sse.max(1e-9));
    ((0.5..=2.0).contains(&gain) && sharp).then_some(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::reference::Clock;

    /// The simulator's truth of a ride, put on a UTC clock `t0` seconds
    /// ahead, is placed back by its track: by the odometer, within a
    /// quarter of a second (0.17 s here: the wheel pulses' own timing, a
    /// revolution every 0.4 s).
    #[test]
    fn a_utc_track_is_placed_on_the_rides_clock_by_its_track() {
        let signals = crate::testing::simulated_signals(3, 300.0, &[]);
        let mut truth = crate::testing::simulated_truth(3, 300.0, &[]);
        const T0: f64 = 1_600_000_123.4;
        for t in &mut truth.t_s {
            *t += T0;
        }
        truth.clock = Clock::Unix;
        let clock = track_clock(&truth, &signals).expect("placed");
        assert!(clock.by_distance);
        assert!(
            (clock.offset_s - T0).abs() < 0.25,
            "{}",
            clock.offset_s - T0
        );
        assert!(clock.median_m < 5.0, "{}", clock.median_m);
        // Part of the ride (its second half) is placed as well.
        let mut half = truth.clone();
        let from = half.t_s.partition_point(|&t| t < T0 + 150.0);
        half.t_s.drain(..from);
        half.points.drain(..from);
        let clock = track_clock(&half, &signals).expect("half placed");
        assert!(
            (clock.offset_s - T0).abs() < 0.25,
            "{}",
            clock.offset_s - T0
        );
    }

    /// A track of another place, or of a vehicle that stood still, tells
    /// no clock: no placement (the reference is then refused, asking for
    /// the ride's start).
    #[test]
    fn a_track_that_cannot_tell_the_clock_places_nothing() {
        let signals = crate::testing::simulated_signals(3, 300.0, &[]);
        let truth = crate::testing::simulated_truth(3, 300.0, &[]);
        let mut elsewhere = truth.clone();
        for p in &mut elsewhere.points {
            p.lat_deg += 0.05;
        }
        assert_eq!(track_clock(&elsewhere, &signals), None);
        let mut standing = truth.clone();
        let here = standing.points[0];
        for p in &mut standing.points {
            *p = here;
        }
        assert_eq!(track_clock(&standing, &signals), None);
    }
}
