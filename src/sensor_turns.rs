//! Turns of the sensor alone: a helmet camera's rider looking over a
//! shoulder, a hand-held phone swung round, a camera on a loose mount.
//!
//! The model takes the vehicle's heading from the sensor's,
//! `p_j = p_{j-1} + (q_j f) d_j`: where the sensor turns and the vehicle
//! does not, the path sets off sideways. Simulated, a look of 30 deg to
//! alternate sides for 2 s a minute took a 5-minute car on its GNSS speed
//! 8.27 m from the truth (0.80 m without the looks; the fixes 1.49 m) as a
//! success: the fit bent its bias round the looks, and the check read the
//! gyro's units as 0.72 of deg/s. Looks of 60 deg failed the fit, the check
//! blaming the axes.
//!
//! A bicycle's looks are harder to see: at 5 m/s a chord between fixes is
//! 5 m, which half a metre of GPS jitter turns by 7 deg, and 30 deg looks
//! are within five of those (a simulated bicycle ended 2.95 m from the
//! truth with them, 1.57 m without; they are not found).
//!
//! The GPS course shows it. Between consecutive fixes the track's chord `g`
//! and the dead-reckoned track's chord `r` over the same steps (the
//! heading `psi = sum w_z dt`, see [`crate::reversing`]) point the same way
//! but for a rotation, `a = angle(g) - angle(r)`, that drifts only as the
//! gyro's bias turns the track. Its running circular median over
//! [`BASELINE_S`] either side is that drift; what departs from it,
//! `e = a - median`, is the sensor turned against the vehicle, plus the
//! chords' noise. A run of consecutive chords that all depart the same way
//! by more than [`MIN_TURN_RAD`] and [`SCATTERS`] times the ride's robust
//! scatter of `e` (its MAD, 1.4826 scaled), but less than [`MAX_TURN_RAD`],
//! for at most [`MAX_TURN_S`], is a
//! sensor turn; a lone chord is not (a GPS jump moves one chord one way and
//! its end another the other way). Each turn is bridged as a gyro stop from
//! the fix before its first chord to the fix after its last, whose chords
//! hold the turn out and back in part (see
//! `signals::bridge_stops`): the yaw rate there is the line between the
//! readings either side, and `effects::gyro_stops` fits the vehicle's own
//! turn across it from the fixes.

use crate::reversing::RowFix;
use crate::rotation::wrap_pi;

/// Chords shorter than this (m), on either track, give no direction: GPS
/// jitter of half a metre turns a 3 m chord by 10-15 deg.
pub const MIN_CHORD_M: f64 = 3.0;

/// Fixes further apart than this (s) make no chord.
const MAX_CHORD_S: f64 = 2.5;

/// The drift of the rotation between the tracks is its circular median
/// over this (s) either side of a chord: the gyro's bias turns the track by
/// at most a few degrees in that time, and a head turn lasts seconds.
pub const BASELINE_S: f64 = 30.0;

/// A chord's drift needs this many chords in its window (the chord and
/// five either side): fewer, at the ride's ends, and it is not judged.
const MIN_WINDOW_CHORDS: usize = 11;

/// A chord departs when its rotation differs from the drift by more than
/// this (rad, 20 deg) ...
pub const MIN_TURN_RAD: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// ... and by this many robust scatters of all chords' departures.
pub const SCATTERS: f64 = 5.0;

/// ... and by no more than this (rad, 135 deg): a head turns less, and
/// half a turn is a vehicle reversing on a distance without a sign (see
/// [`crate::reversing`]) or a GPS jump.
pub const MAX_TURN_RAD: f64 = 135.0 * std::f64::consts::PI / 180.0;

/// A sensor turn lasts at most this (s): longer departures are something
/// else (a street canyon's run of reflected fixes, a GPS lag in a long
/// bend) and are left to the fit.
pub const MAX_TURN_S: f64 = 15.0;

/// A run of chords that the sensor turned across: the fix rows either side
/// (`first_row < last_row`), their times and the largest departure (rad).
#[derive(Clone, Debug, PartialEq)]
pub struct SensorTurn {
    pub first_row: usize,
    pub last_row: usize,
    pub from_s: f64,
    pub to_s: f64,
    pub turn_rad: f64,
}

/// One chord between consecutive fixes: the rows of its ends and its
/// rotation from the dead-reckoned chord.
struct Chord {
    first_row: usize,
    last_row: usize,
    t: f64,
    rotation: f64,
}

/// The sensor turns of a log (see the module docs): `t` its times, `dt`
/// its steps, `yaw_rate(j)` step `j`'s rate about the vertical (rad/s),
/// `distance` the signed distance of each step, `fixes` its GPS fixes.
pub fn find(
    t: &[f64],
    dt: &[f64],
    yaw_rate: impl Fn(usize) -> f64,
    distance: &[f64],
    fixes: &[RowFix],
) -> Vec<SensorTurn> {
    let n = t.len().min(dt.len()).min(distance.len());
    if n < 2 {
        return Vec::new();
    }
    let track = crate::reversing::dead_reckoned(n, dt, &yaw_rate, distance, fixes);
    let chords: Vec<Chord> = fixes
        .windows(2)
        .zip(track.windows(2))
        .filter_map(|(w, p)| {
            let ((a, ga), (b, gb)) = (w[0], w[1]);
            if b >= n || t[b] - t[a] > MAX_CHORD_S {
                return None;
            }
            let g = [gb[0] - ga[0], gb[1] - ga[1]];
            let r = [p[1][0] - p[0][0], p[1][1] - p[0][1]];
            if g[0].hypot(g[1]) < MIN_CHORD_M || r[0].hypot(r[1]) < MIN_CHORD_M {
                return None;
            }
            Some(Chord {
                first_row: a,
                last_row: b,
                t: 0.5 * (t[a] + t[b]),
                rotation: g[1].atan2(g[0]) - r[1].atan2(r[0]),
            })
        })
        .collect();
    let (Some(first), Some(last)) = (chords.first(), chords.last()) else {
        return Vec::new();
    };
    let (start, end) = (first.t, last.t);
    let departures: Vec<f64> = (0..chords.len())
        .map(|k| {
            // A window centred on the chord, so that a drift (an uncorrected
            // bias turns the rotation steadily) has its median there.
            let half = BASELINE_S.min(chords[k].t - start).min(end - chords[k].t);
            let from = chords.partition_point(|c| c.t < chords[k].t - half);
            let to = chords.partition_point(|c| c.t <= chords[k].t + half);
            if to - from < MIN_WINDOW_CHORDS {
                // Near the ride's ends: too few chords to tell a drift.
                return f64::NAN;
            }
            let around: Vec<f64> = chords[from..to].iter().map(|c| c.rotation).collect();
            wrap_pi(chords[k].rotation - circular_median(&around))
        })
        .collect();
    let mut magnitudes: Vec<f64> = departures
        .iter()
        .filter(|e| e.is_finite())
        .map(|e| e.abs())
        .collect();
    if magnitudes.len() < MIN_WINDOW_CHORDS {
        return Vec::new();
    }
    let scatter = 1.4826 * crate::statistics::median(&mut magnitudes);
    let limit = MIN_TURN_RAD.max(SCATTERS * scatter);
    let mut turns = Vec::new();
    let mut k = 0;
    while k < chords.len() {
        let sign = departures[k].signum();
        let departs = |i: usize| {
            (limit..=MAX_TURN_RAD).contains(&departures[i].abs()) && departures[i].signum() == sign
        };
        if !departs(k) {
            k += 1;
            continue;
        }
        let run = k;
        // Consecutive chords: each starts at the fix the one before ended on.
        while k + 1 < chords.len()
            && chords[k + 1].first_row == chords[k].last_row
            && departs(k + 1)
        {
            k += 1;
        }
        // From the fix before the run to the fix after it: the chords
        // either side hold the sensor's turn out and back in part.
        let at = |row: usize| fixes.partition_point(|f| f.0 < row);
        let (a, b) = (at(chords[run].first_row), at(chords[k].last_row));
        let first_row = match a.checked_sub(1).map(|i| fixes[i].0) {
            Some(row) if t[fixes[a].0] - t[row] <= MAX_CHORD_S => row,
            _ => fixes[a].0,
        };
        let last_row = match fixes.get(b + 1).map(|f| f.0) {
            Some(row) if row < n && t[row] - t[fixes[b].0] <= MAX_CHORD_S => row,
            _ => fixes[b].0,
        };
        if k > run && t[last_row] - t[first_row] <= MAX_TURN_S {
            turns.push(SensorTurn {
                first_row,
                last_row,
                from_s: t[first_row],
                to_s: t[last_row],
                turn_rad: departures[run..=k]
                    .iter()
                    .map(|e| e.abs())
                    .fold(0.0, f64::max),
            });
        }
        k += 1;
    }
    turns
}

/// The circular median of angles `a` (rad): the median of their departures
/// from their mean direction, added back to it.
fn circular_median(a: &[f64]) -> f64 {
    let (s, c) = a
        .iter()
        .fold((0.0, 0.0), |(s, c), x| (s + x.sin(), c + x.cos()));
    let mean = s.atan2(c);
    let mut off: Vec<f64> = a.iter().map(|x| wrap_pi(x - mean)).collect();
    mean + crate::statistics::median(&mut off)
}

/// What was found, in a sentence; `None` for nothing.
pub fn describe(found: &[SensorTurn]) -> Option<String> {
    let largest = found
        .iter()
        .max_by(|a, b| a.turn_rad.total_cmp(&b.turn_rad))?;
    let longest = found.iter().map(|s| s.to_s - s.from_s).fold(0.0, f64::max);
    Some(format!(
        "the sensor turned without the vehicle {} time(s) (a helmet or hand-held camera, a loose mount?): the GPS course did not follow it, by up to {:.0} deg (at {:.1}-{:.1} s), for at most {longest:.0} s; the vehicle's turn across each is fitted as across a gyro stop",
        found.len(),
        largest.turn_rad.to_degrees(),
        largest.from_s,
        largest.to_s,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A simulated drive: times, steps, the sensor's yaw rate per step,
    /// distances and fixes.
    struct Drive {
        t: Vec<f64>,
        dt: Vec<f64>,
        rate: Vec<f64>,
        distance: Vec<f64>,
        fixes: Vec<RowFix>,
    }

    impl Drive {
        fn turns(&self) -> Vec<SensorTurn> {
            find(
                &self.t,
                &self.dt,
                |j| self.rate[j],
                &self.distance,
                &self.fixes,
            )
        }
    }

    /// A drive at 10 m/s sampled at 10 Hz for `seconds`, the vehicle
    /// turning at `vehicle(t)` and the sensor at that plus `look(t)`
    /// (rad/s); fixes at 1 Hz off by `error(k)`.
    fn drive(
        seconds: f64,
        vehicle: impl Fn(f64) -> f64,
        look: impl Fn(f64) -> f64,
        error: impl Fn(usize) -> [f64; 2],
    ) -> Drive {
        let n = (seconds * 10.0) as usize + 1;
        let t: Vec<f64> = (0..n).map(|j| j as f64 * 0.1).collect();
        let (mut dt, mut rate, mut distance) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let (mut heading, mut p) = (0.0f64, vec![[0.0, 0.0]; n]);
        for j in 1..n {
            dt[j] = 0.1;
            heading += vehicle(t[j]) * 0.1;
            rate[j] = vehicle(t[j]) + look(t[j]);
            distance[j] = 1.0;
            p[j] = [p[j - 1][0] + heading.cos(), p[j - 1][1] + heading.sin()];
        }
        let fixes = (0..n)
            .step_by(10)
            .enumerate()
            .map(|(k, row)| {
                let e = error(k);
                (row, [p[row][0] + e[0], p[row][1] + e[1]])
            })
            .collect();
        Drive {
            t,
            dt,
            rate,
            distance,
            fixes,
        }
    }

    fn jitter(k: usize) -> [f64; 2] {
        let k = k as f64;
        [0.4 * (1.7 * k).sin(), 0.4 * (2.3 * k).cos()]
    }

    /// A look of 30 deg to the left from 50 s, held 2 s, back by 53 s.
    fn look(t: f64) -> f64 {
        let rate = 60f64.to_radians();
        if (50.0..50.5).contains(&t) {
            rate
        } else if (52.5..53.0).contains(&t) {
            -rate
        } else {
            0.0
        }
    }

    /// The vehicle's own bends: 90 deg left at 30 s, back right at 80 s.
    fn bends(t: f64) -> f64 {
        let rate = 30f64.to_radians();
        if (30.0..33.0).contains(&t) {
            rate
        } else if (80.0..83.0).contains(&t) {
            -rate
        } else {
            0.0
        }
    }

    #[test]
    fn a_look_to_the_side_is_found_and_the_vehicles_bends_are_not() {
        let found = drive(120.0, bends, look, jitter).turns();
        assert_eq!(found.len(), 1, "{found:?}");
        let s = &found[0];
        assert!(
            s.from_s <= 50.0 && s.to_s >= 53.0 && s.to_s - s.from_s <= 6.0,
            "{s:?}"
        );
        assert!((s.turn_rad.to_degrees() - 30.0).abs() < 8.0, "{s:?}");
        let said = describe(&found).unwrap_or_default();
        assert!(said.contains("1 time(s)"), "{said}");
    }

    #[test]
    fn a_sensor_fixed_to_the_vehicle_turns_with_it() {
        let mut fixed = drive(120.0, bends, |_| 0.0, jitter);
        assert!(fixed.turns().is_empty());
        // A gyro bias of 4 deg/s turns the dead-reckoned track steadily.
        for r in &mut fixed.rate {
            *r += 4f64.to_radians();
        }
        assert!(fixed.turns().is_empty());
    }

    #[test]
    fn a_gps_jump_is_no_sensor_turn() {
        // One fix 25 m off: the chord into it and the chord out of it
        // depart, the other way each.
        let jump = |k: usize| if k == 60 { [0.0, 25.0] } else { jitter(k) };
        assert!(drive(120.0, bends, |_| 0.0, jump).turns().is_empty());
        // Reflections of tens of metres every few seconds: no chord departs
        // beyond their scatter.
        let city = |k: usize| {
            let k = k as f64;
            [20.0 * (1.3 * k).sin(), 20.0 * (0.7 * k).cos()]
        };
        assert!(drive(120.0, bends, look, city).turns().is_empty());
    }

    #[test]
    fn a_crawl_too_slow_for_a_chord_has_no_turns() {
        // 0.5 m/s: every chord is shorter than MIN_CHORD_M.
        let mut crawl = drive(120.0, bends, look, jitter);
        for d in &mut crawl.distance {
            *d *= 0.05;
        }
        assert!(crawl.turns().is_empty());
        assert!(
            find(
                &crawl.t[..1],
                &crawl.dt[..1],
                |_| 0.0,
                &crawl.distance[..1],
                &[]
            )
            .is_empty()
        );
    }

    #[test]
    fn the_circular_median_lies_across_the_wrap() {
        let pi = std::f64::consts::PI;
        let m = circular_median(&[pi - 0.1, -pi + 0.1, pi - 0.05, -pi + 0.2, pi - 0.3]);
        assert!(wrap_pi(m - pi).abs() < 0.06, "{m}");
    }
}
