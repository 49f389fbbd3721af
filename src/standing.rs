//! Stands inside the gaps of a GNSS speed, told by the gyro's shaking.
//!
//! Without a wheel sensor the distance is the GNSS speed integrated (see
//! [`crate::signals::distance_from_gnss_speed`]); where the receiver drops
//! out, the speed is interpolated between the gap's ends. A vehicle that
//! stood at a light inside the gap is then tens of metres off along the
//! road (on simulated rides with stops, 20-50 m), and the fit can move only
//! the gap's total. But a moving vehicle shakes its gyro (road, engine,
//! pedals, the rider's sway) and a standing one hardly does: the activity
//!
//! `a_j = sqrt(sum_axes var(omega over the ACTIVITY_WINDOW_S centred on row j))`
//!
//! (the bias, a constant, drops out of a variance) is 0.12 deg/s standing
//! against 6.7 moving on the simulator's bicycle, and on the Berlin car's
//! yaw-rate sensor about five times lower standing than moving.
//!
//! How low is low is the ride's own: outside the gaps the speed is logged,
//! so the rows where it says standing (`v < STANDING_SPEED_MPS`) and moving
//! (`v > MOVING_SPEED_MPS`) give the activity of each. Only where the two
//! are apart (the 95th percentile standing below the 5th moving, with
//! [`MIN_CLASS_S`] of each) is a threshold set, at their geometric mean;
//! else the gyro cannot tell, and no stand is found. Inside a gap, a run of
//! rows below the threshold lasting [`MIN_STAND_S`] is a stand: the speed
//! is zero there, and interpolated between the gap's ends and the stand's.

use crate::statistics::quantile;

/// A GNSS speed slower than this (m/s), on a step whose gyro turns slower
/// than [`STANDING_RATE_DPS`], is a vehicle standing: a receiver at rest
/// reports a few centimetres to decimetres per second of Doppler noise
/// (u-blox: 0.05-0.2 m/s), which integrated over a stop of minutes would
/// move the path by tens of metres. The gyro must agree, so that a vehicle
/// turning slowly (a robot in place, a car manoeuvring) keeps its distance.
pub const STANDING_SPEED_MPS: f64 = 0.3;
/// See [`STANDING_SPEED_MPS`] (deg/s, the norm of the rate as logged, bias
/// included: uncalibrated MEMS gyros are 0.1-2 deg/s off at rest).
pub const STANDING_RATE_DPS: f64 = 3.0;

/// The window over which the gyro's activity is taken (s).
pub const ACTIVITY_WINDOW_S: f64 = 1.0;
/// A logged speed above this (m/s) is a vehicle moving, for the threshold.
pub const MOVING_SPEED_MPS: f64 = 2.0;
/// Least time of each kind (standing, moving) outside the gaps for a threshold (s).
pub const MIN_CLASS_S: f64 = 10.0;
/// Shortest stand found inside a gap (s): a second of quiet is a smooth
/// stretch of road as often as a stop.
pub const MIN_STAND_S: f64 = 2.0;

/// How the ride's gyro tells a stand: the activity threshold (deg/s) and
/// the two classes' percentiles it lies between.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StandRule {
    /// Activity below this (deg/s) is standing.
    pub threshold_dps: f64,
    /// 95th percentile of the activity where the logged speed stands.
    pub standing_q95_dps: f64,
    /// 5th percentile where it moves.
    pub moving_q05_dps: f64,
}

/// The activity `a_j` of every row (deg/s; see the module docs), from the
/// rates `rate(j)` (deg/s) at times `t`: running sums over the sliding
/// window, O(rows) time and no memory beyond the result (prefix sums would
/// hold 48 bytes a row: 100 MB on a 6-hour ride).
pub fn activity(t: &[f64], rate: impl Fn(usize) -> [f64; 3]) -> Vec<f64> {
    let n = t.len();
    let half = 0.5 * ACTIVITY_WINDOW_S;
    let (mut sum, mut sq) = ([0.0; 3], [0.0; 3]);
    let (mut lo, mut hi) = (0usize, 0usize);
    (0..n)
        .map(|j| {
            while hi < n && t[hi] <= t[j] + half {
                let g = rate(hi);
                for a in 0..3 {
                    sum[a] += g[a];
                    sq[a] += g[a] * g[a];
                }
                hi += 1;
            }
            while t[lo] < t[j] - half {
                let g = rate(lo);
                for a in 0..3 {
                    sum[a] -= g[a];
                    sq[a] -= g[a] * g[a];
                }
                lo += 1;
            }
            let m = (hi - lo) as f64;
            if m < 2.0 {
                return f64::NAN;
            }
            (0..3)
                .map(|a| {
                    let mean = sum[a] / m;
                    (sq[a] / m - mean * mean).max(0.0)
                })
                .sum::<f64>()
                .sqrt()
        })
        .collect()
}

/// The ride's rule, from the activity of rows outside the gaps whose speed
/// `v` (interpolated between samples) is logged; `None` when either kind
/// has under [`MIN_CLASS_S`] or the two overlap.
pub fn stand_rule(t: &[f64], v: &[f64], activity: &[f64], in_gap: &[bool]) -> Option<StandRule> {
    let (mut standing, mut moving) = (Vec::new(), Vec::new());
    let (mut standing_s, mut moving_s) = (0.0, 0.0);
    for j in 1..t.len() {
        if in_gap[j] || in_gap[j - 1] || !activity[j].is_finite() {
            continue;
        }
        let dt = t[j] - t[j - 1];
        if v[j] < STANDING_SPEED_MPS && v[j - 1] < STANDING_SPEED_MPS {
            standing.push(activity[j]);
            standing_s += dt;
        } else if v[j] > MOVING_SPEED_MPS && v[j - 1] > MOVING_SPEED_MPS {
            moving.push(activity[j]);
            moving_s += dt;
        }
    }
    if standing_s < MIN_CLASS_S || moving_s < MIN_CLASS_S {
        return None;
    }
    let standing_q95_dps = quantile(&mut standing, 0.95);
    let moving_q05_dps = quantile(&mut moving, 0.05);
    (standing_q95_dps < moving_q05_dps).then(|| StandRule {
        threshold_dps: (standing_q95_dps.max(1e-9) * moving_q05_dps).sqrt(),
        standing_q95_dps,
        moving_q05_dps,
    })
}

/// The rows strictly inside a gap from `a` to `b` (s).
pub fn gap_rows(t: &[f64], (a, b): (f64, f64)) -> std::ops::Range<usize> {
    t.partition_point(|&x| x <= a)..t.partition_point(|&x| x < b)
}

/// Row ranges `first..=last` inside the gaps (`(start, end)` in s, rows
/// strictly between) where the activity stays below the rule's threshold
/// for at least [`MIN_STAND_S`].
pub fn stands_in_gaps(
    t: &[f64],
    activity: &[f64],
    gaps: &[(f64, f64)],
    rule: &StandRule,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for &gap in gaps {
        let std::ops::Range { start: first, end } = gap_rows(t, gap);
        let mut run: Option<usize> = None;
        for j in first..=end {
            let quiet = j < end && activity[j] < rule.threshold_dps;
            match (quiet, run) {
                (true, None) => run = Some(j),
                (false, Some(s)) => {
                    if t[j - 1] - t[s] >= MIN_STAND_S {
                        out.push((s, j - 1));
                    }
                    run = None;
                }
                _ => {}
            }
        }
    }
    out
}

/// Time before a logged stand (and after one) over which the ride's own
/// braking (and pulling away) is measured (s).
const RAMP_LOOK_S: f64 = 3.0;

/// The ride's own braking into a stand and pulling away from one (m/s^2):
/// the medians, over the stands of the logged speed `v` outside the gaps,
/// of `v(t_s - RAMP_LOOK_S) / RAMP_LOOK_S` before a stand starting at `t_s`
/// and `v(t_e + RAMP_LOOK_S) / RAMP_LOOK_S` after one ending at `t_e`.
/// `None` for a kind the ride never shows.
pub fn ramps(t: &[f64], v: &[f64], in_gap: &[bool]) -> (Option<f64>, Option<f64>) {
    let stopped = |j: usize| v[j] < STANDING_SPEED_MPS;
    let at = |x: f64| t.partition_point(|&y| y < x).min(t.len() - 1);
    let (mut braking, mut pulling) = (Vec::new(), Vec::new());
    for j in 1..t.len() {
        if in_gap[j] || in_gap[j - 1] || stopped(j) == stopped(j - 1) {
            continue;
        }
        let (edge, look) = if stopped(j) {
            (t[j], t[j] - RAMP_LOOK_S)
        } else {
            (t[j - 1], t[j - 1] + RAMP_LOOK_S)
        };
        if look < t[0] || look > t[t.len() - 1] {
            continue;
        }
        // The look-back (or ahead) must be logged throughout.
        let (lo, hi) = (at(look.min(edge)), at(look.max(edge)));
        if (lo..=hi).any(|k| in_gap[k]) {
            continue;
        }
        let a = v[at(look)] / RAMP_LOOK_S;
        if stopped(j) {
            braking.push(a)
        } else {
            pulling.push(a)
        }
    }
    let median = |mut x: Vec<f64>| (!x.is_empty()).then(|| crate::statistics::median(&mut x));
    (median(braking), median(pulling))
}

/// The speed inside a gap from `(t_a, v_a)` to `(t_b, v_b)` with stands
/// `stands` (start, end in s, in order) as knots `(t, v)` to interpolate
/// between: zero through each stand, the edge speed held until the ride's
/// braking `brake` reaches the first stand from it (and from the last stand
/// to `v_b` at its pulling away `pull`), and between two stands a hump to
/// the mean of the edge speeds, as high as the time between allows.
/// Without a ramp the speed goes straight to zero (a linear ramp over the
/// whole stretch).
pub fn gap_knots(
    (t_a, v_a): (f64, f64),
    (t_b, v_b): (f64, f64),
    stands: &[(f64, f64)],
    (brake, pull): (Option<f64>, Option<f64>),
) -> Vec<(f64, f64)> {
    let mut knots = Vec::new();
    let v_mid = 0.5 * (v_a + v_b);
    let mut from = (t_a, v_a);
    for (i, &(s, e)) in stands.iter().enumerate() {
        // Braking from `from` into the stand at `s`.
        if let Some(a) = brake.filter(|a| *a > 0.0) {
            let (t0, v0) = from;
            let lead = v0 / a;
            if i == 0 {
                if s - lead > t0 {
                    knots.push((s - lead, v0));
                }
            } else {
                // A hump between the previous stand's end `t0` and `s`.
                let pull_a = pull.filter(|p| *p > 0.0).unwrap_or(a);
                let peak = v_mid.min((s - t0) / (1.0 / pull_a + 1.0 / a));
                let (up, down) = (t0 + peak / pull_a, s - peak / a);
                knots.push((up, peak));
                if down > up {
                    knots.push((down, peak));
                }
            }
        }
        knots.push((s, 0.0));
        knots.push((e, 0.0));
        from = (e, v_mid);
    }
    if let (Some(&(_, e)), Some(a)) = (stands.last(), pull.filter(|a| *a > 0.0)) {
        let lead = v_b / a;
        if e + lead < t_b {
            knots.push((e + lead, v_b));
        }
    }
    knots.retain(|&(x, _)| x > t_a && x < t_b);
    knots
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 100 Hz: standing (quiet) for 20 s, moving (shaking) for 20 s, a gap
    /// from 40 to 70 s whose middle 10 s are quiet, moving again to 90 s.
    fn ride() -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..9000).map(|j| j as f64 * 0.01).collect();
        let quiet = |x: f64| x < 20.0 || (50.0..60.0).contains(&x);
        let rate: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(j, &x)| {
                let wobble = if j % 2 == 0 { 1.0 } else { -1.0 };
                if quiet(x) {
                    0.05 * wobble
                } else {
                    3.0 * wobble
                }
            })
            .collect();
        let v = t
            .iter()
            .map(|&x| if x < 20.0 { 0.0 } else { 5.0 })
            .collect();
        (t, rate, v)
    }

    #[test]
    fn a_quiet_run_inside_a_gap_is_a_stand() {
        let (t, rate, v) = ride();
        let a = activity(&t, |j| [0.0, 0.0, rate[j]]);
        // The standard deviation of +-c is c (an odd count of samples: within 1e-4).
        assert!((a[1000] / 0.05 - 1.0).abs() < 1e-4, "{}", a[1000]);
        assert!((a[3000] / 3.0 - 1.0).abs() < 1e-4, "{}", a[3000]);
        let in_gap: Vec<bool> = t.iter().map(|&x| x > 40.0 && x < 70.0).collect();
        let rule = stand_rule(&t, &v, &a, &in_gap).expect("rule");
        assert!((rule.threshold_dps / (0.05f64 * 3.0).sqrt() - 1.0).abs() < 1e-3);
        let stands = stands_in_gaps(&t, &a, &[(40.0, 70.0)], &rule);
        assert_eq!(stands.len(), 1, "{stands:?}");
        let (s, e) = stands[0];
        // The window smears each edge by half its width at most.
        assert!(
            (t[s] - 50.0).abs() <= 0.5 && (t[e] - 60.0).abs() <= 0.5,
            "{} {}",
            t[s],
            t[e]
        );
    }

    #[test]
    fn no_rule_when_the_gyro_cannot_tell() {
        let (t, _, v) = ride();
        let flat = vec![1.0; t.len()];
        assert_eq!(stand_rule(&t, &v, &flat, &vec![false; t.len()]), None);
        // Too little standing outside the gap.
        let (t, rate, v) = ride();
        let a = activity(&t, |j| [rate[j], 0.0, 0.0]);
        let in_gap: Vec<bool> = t.iter().map(|&x| x < 15.0).collect();
        assert_eq!(stand_rule(&t, &v, &a, &in_gap), None);
    }

    #[test]
    fn a_short_quiet_spell_is_not_a_stand() {
        let (t, rate, v) = ride();
        let a = activity(&t, |j| [0.0, rate[j], 0.0]);
        let in_gap: Vec<bool> = t.iter().map(|&x| x > 40.0 && x < 70.0).collect();
        let rule = stand_rule(&t, &v, &a, &in_gap).expect("rule");
        // The gap ends 1.5 s into the quiet run.
        assert!(stands_in_gaps(&t, &a, &[(40.0, 51.5)], &rule).is_empty());
    }

    #[test]
    fn the_ride_s_own_braking_and_pulling_away() {
        // 10 Hz: 8 m/s, braking at 2 m/s^2 into a stand at 20-30 s, pulling
        // away at 1 m/s^2; a second stand inside a gap is not counted.
        let t: Vec<f64> = (0..800).map(|j| j as f64 * 0.1).collect();
        let v: Vec<f64> = t
            .iter()
            .map(|&x| {
                if x < 16.0 {
                    8.0
                } else if x < 20.0 {
                    8.0 - 2.0 * (x - 16.0)
                } else if x < 30.0 {
                    0.0
                } else {
                    (x - 30.0).min(8.0)
                }
            })
            .collect();
        let in_gap = vec![false; t.len()];
        let (brake, pull) = ramps(&t, &v, &in_gap);
        // v(t_s - 3 s) / 3 s: 6 m/s over 3 s; v(t_e + 3 s) / 3 s: 3 m/s
        // over 3 s (the stand ends a step or three late, where v passes 0.3).
        assert!((brake.expect("brake") - 2.0).abs() < 0.15, "{brake:?}");
        assert!((pull.expect("pull") - 1.0).abs() < 0.1, "{pull:?}");
        let all_gap = vec![true; t.len()];
        assert_eq!(ramps(&t, &v, &all_gap), (None, None));
    }

    #[test]
    fn knots_hold_the_speed_until_the_braking_reaches_a_stand() {
        let ramps = (Some(2.0), Some(1.0));
        // One stand at 20-30 s in a gap from 10 to 50 s, 8 m/s in, 4 m/s out.
        let k = gap_knots((10.0, 8.0), (50.0, 4.0), &[(20.0, 30.0)], ramps);
        assert_eq!(k, vec![(16.0, 8.0), (20.0, 0.0), (30.0, 0.0), (34.0, 4.0)]);
        // Without ramps, straight to zero and back.
        let k = gap_knots((10.0, 8.0), (50.0, 4.0), &[(20.0, 30.0)], (None, None));
        assert_eq!(k, vec![(20.0, 0.0), (30.0, 0.0)]);
        // Two stands 4 s apart: a hump as high as 4 s allows (peak / 1 + peak / 2 = 4).
        let k = gap_knots(
            (0.0, 6.0),
            (60.0, 6.0),
            &[(10.0, 20.0), (24.0, 40.0)],
            ramps,
        );
        let peak = 4.0 / 1.5;
        assert_eq!(k.len(), 7, "{k:?}");
        assert!((k[3].1 - peak).abs() < 1e-12 && (k[3].0 - (20.0 + peak)).abs() < 1e-12);
        // A stand reached sooner than the braking allows starts the ramp at the gap's edge.
        let k = gap_knots((10.0, 8.0), (50.0, 4.0), &[(12.0, 30.0)], ramps);
        assert_eq!(k[0], (12.0, 0.0));
    }
}
