//! The log itself: its sample rate, and a gyro pinned at its range.

use super::*;

/// Returns whether the gyro is fast enough to integrate at all.
pub(super) fn sample_rate(log: &RideLog, report: &mut CheckReport) -> bool {
    let rate = crate::signals::median_rate_hz(&log.t_s);
    let (level, note) = if rate < crate::signals::MIN_GYRO_RATE_HZ {
        (
            Level::Problem,
            format!(
                ": far too slow to integrate turns; a path needs {} Hz or more{}",
                crate::signals::MIN_GYRO_RATE_HZ,
                crate::signals::time_unit_hint(
                    rate,
                    log.t_s.last().copied().unwrap_or(0.0)
                        - log.t_s.first().copied().unwrap_or(0.0)
                )
            ),
        )
    } else if rate < 20.0 {
        (
            Level::Info,
            ": a coarse integration step; fast turns are smoothed".to_string(),
        )
    } else {
        (Level::Ok, String::new())
    };
    report.say(
        "sample rate",
        level,
        format!(
            "{} rows at {rate:.prec$} Hz over {:.0} s, time increasing{note}",
            log.len(),
            log.t_s[log.len() - 1] - log.t_s[0],
            prec = if rate < 1.0 { 3 } else { 1 },
        ),
    );
    if let Some((pause, _)) = crate::signals::pause(&log.t_s, &log.line) {
        report.say("pause", Level::Problem, pause);
    }
    if log.fix_count() == 0 {
        report.say(
            "GPS",
            Level::Problem,
            "no fix in the whole log: a path needs GNSS fixes; a GPS track of the same ride (a watch's or bike computer's GPX or FIT, a phone's NMEA) gives them: --gps-track FILE".into(),
        );
    }
    rate >= crate::signals::MIN_GYRO_RATE_HZ
}

/// Rows pinned at an axis's extreme: a saturated gyro.
pub(super) fn saturation(log: &RideLog, report: &mut CheckReport) {
    for a in 0..3 {
        let max = log
            .gyro_dps
            .iter()
            .map(|g| g[a].abs())
            .fold(0.0f64, f64::max);
        if max < 30.0 {
            continue;
        }
        let pinned = log
            .gyro_dps
            .iter()
            .filter(|g| g[a].abs() >= max * (1.0 - 1e-9))
            .count();
        if pinned >= 5 {
            report.say(
                "gyro saturation",
                Level::Warning,
                format!(
                    "axis {} sits at +-{max:.1} (as labelled) on {pinned} rows: it looks saturated, and turns there are lost",
                    ['x', 'y', 'z'][a]
                ),
            );
        }
    }
}

/// Runs of rows on which the gyro repeats one reading on all three axes,
/// `(first row, last row)`, that last at least [`MIN_STUCK_S`] and
/// [`MIN_STUCK_ROWS`], and [`STUCK_PER_TYPICAL`] times the 95th percentile
/// of the log's runs (a slow gyro written on every row of a faster log
/// repeats each reading as a matter of course).
fn repeated_readings(log: &RideLog) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut start = 0;
    for j in 1..=log.len() {
        if j < log.len() && log.gyro_dps[j] == log.gyro_dps[j - 1] {
            continue;
        }
        runs.push((start, j - 1));
        start = j;
    }
    let mut spans: Vec<f64> = runs.iter().map(|&(a, b)| log.t_s[b] - log.t_s[a]).collect();
    let typical = crate::statistics::quantile(&mut spans, 0.95);
    let shortest = MIN_STUCK_S.max(STUCK_PER_TYPICAL * typical);
    runs.retain(|&(a, b)| b - a + 1 >= MIN_STUCK_ROWS && log.t_s[b] - log.t_s[a] >= shortest);
    runs
}

/// A gyro that stopped answering: one reading repeated on every axis, row
/// after row. A logger writes zeros, or its last reading, when its IMU
/// stops answering (a loose I2C wire, a driver's hiccup), and the heading
/// is then wrong from there on: Berlin's yaw rate held at its last reading
/// for 25 s sent the fit 58 m from its fixes. A MEMS gyro's noise never
/// repeats a reading on all three axes for a second, so named as a problem:
///
/// - a nonzero reading held (no sensor holds one; integrated, it turns the
///   heading at that rate);
/// - zeros on all three axes while the odometer moves `MIN_MOVED_M`, in a
///   log whose three axes read something elsewhere (a moving vehicle's
///   gyro is never exactly still).
///
/// A log with an axis that never reads (a car's yaw-rate sensor alone) may
/// hold 0.00 along a straight within the sensor's deadband; there a run of
/// zeros is named, as a warning, only where the GPS course turns by more
/// than [`STUCK_TURN_DEG`] across it, read from chords of the stretches'
/// length either side (straight lines, as in the course check) against the
/// gyro's turn between the chords' middles about `vertical`, or the axis
/// that comes nearest where the vertical is not known; or where it lasts
/// [`MIN_LONE_ZEROS_S`] while the vehicle moves and the sensor has no
/// deadband (see [`zeros_while_moving`]). City fixes blur the course: 25 s
/// of zeros in a 37 deg bend of Berlin's drive are not seen by it (its
/// 57 m chords turn with the gyro's zeros to a degree), but its yaw rate
/// reads zero on 1.3 % of the rows that move elsewhere.
pub(super) fn stuck_gyro(
    log: &RideLog,
    distance: &[f64],
    (fixes, stretches): (&[AtFix], &Stretches),
    vertical: Option<(usize, f64)>,
    report: &mut CheckReport,
) {
    let three_axes = (0..3).all(|a| log.gyro_dps.iter().any(|g| g[a] != 0.0));
    let mut found: Vec<(usize, usize, Level, String)> = Vec::new();
    for (first, last) in repeated_readings(log) {
        let g = log.gyro_dps[first];
        let moved: f64 = distance[first + 1..=last].iter().sum();
        if g != [0.0; 3] {
            found.push((first, last, Level::Problem, String::new()));
        } else if three_axes && moved >= MIN_MOVED_M {
            found.push((
                first,
                last,
                Level::Problem,
                format!(" while the odometer moves {moved:.0} m"),
            ));
        } else if let Some(missed) = course_missed(first, last, log, (fixes, stretches), vertical)
            && missed > STUCK_TURN_DEG
        {
            found.push((
                first,
                last,
                Level::Warning,
                format!(" while the GPS course turns {missed:.0} deg more than it does"),
            ));
        } else if moved >= MIN_MOVED_M
            && log.t_s[last] - log.t_s[first] >= MIN_LONE_ZEROS_S
            && zeros_while_moving(log, distance, (first, last)) < MAX_DEADBAND_SHARE
        {
            found.push((
                first,
                last,
                Level::Warning,
                format!(
                    " while the odometer moves {moved:.0} m, where elsewhere it reads zero on {:.1} % of the rows that move",
                    100.0 * zeros_while_moving(log, distance, (first, last))
                ),
            ));
        }
    }
    let worst = found
        .iter()
        .max_by(|a, b| (a.2, a.1 - a.0).cmp(&(b.2, b.1 - b.0)));
    let Some((first, last, level, why)) = worst else {
        return;
    };
    let (first, last) = (*first, *last);
    let g = log.gyro_dps[first];
    report.say(
        "gyro stopped",
        *level,
        format!(
            "the gyro repeats one reading ({}, {}, {} as labelled) on every row from t = {:.2} to {:.2} s (lines {}-{}){why}{}: a sensor that stopped answering, its dropout written as zeros or its last reading repeated; the heading is lost there, so fit each side apart (--between) or mend the log",
            g[0],
            g[1],
            g[2],
            log.t_s[first],
            log.t_s[last],
            log.line.get(first).copied().unwrap_or(first as u64 + 2),
            log.line.get(last).copied().unwrap_or(last as u64 + 2),
            if found.len() > 1 {
                format!(" (the longest of {} such runs)", found.len())
            } else {
                String::new()
            }
        ),
    );
}

/// The share of the rows on which the vehicle moves, outside rows
/// `skip`, where the gyro reads zero on every axis: a sensor with a
/// deadband reads zero along every straight, one without it seldom
/// (Berlin's yaw rate on 18 of 1357 rows, 1.3 %).
fn zeros_while_moving(log: &RideLog, distance: &[f64], skip: (usize, usize)) -> f64 {
    let (mut moving, mut zeros) = (0usize, 0usize);
    for j in (1..log.len()).filter(|&j| distance[j] > 0.0 && !(skip.0..=skip.1).contains(&j)) {
        moving += 1;
        zeros += usize::from(log.gyro_dps[j] == [0.0; 3]);
    }
    if moving == 0 {
        return 1.0;
    }
    zeros as f64 / moving as f64
}

/// A run of zeros on a gyro with an axis that never reads is named, where
/// the GPS course cannot tell, if it lasts this long (s) while the vehicle
/// moves and the sensor reads zero elsewhere on less than
/// [`MAX_DEADBAND_SHARE`] of the rows that move.
const MIN_LONE_ZEROS_S: f64 = 5.0;
const MAX_DEADBAND_SHARE: f64 = 0.05;

/// How far (deg) the GPS course turns beyond the gyro across rows
/// `first..=last` (see [`stuck_gyro`]); `None` where the fixes cannot tell.
fn course_missed(
    first: usize,
    last: usize,
    log: &RideLog,
    (fixes, stretches): (&[AtFix], &Stretches),
    vertical: Option<(usize, f64)>,
) -> Option<f64> {
    let per_m = stretches.odometer_per_m?;
    let length = stretches.length_m * per_m;
    let course = |a: &AtFix, b: &AtFix| {
        let (de, dn) = (b.en[0] - a.en[0], b.en[1] - a.en[1]);
        let straight = de.hypot(dn) >= 0.5 * (b.s - a.s) / per_m;
        straight.then(|| dn.atan2(de).to_degrees())
    };
    let (ta, tb) = (log.t_s[first], log.t_s[last]);
    let ka = fixes.iter().rposition(|f| f.t <= ta)?;
    let kb = fixes.iter().position(|f| f.t >= tb)?;
    let ka0 = (0..ka)
        .rev()
        .find(|&k| fixes[ka].s - fixes[k].s >= length)?;
    let kb1 = (kb + 1..fixes.len()).find(|&k| fixes[k].s - fixes[kb].s >= length)?;
    let turned = course(&fixes[kb], &fixes[kb1])? - course(&fixes[ka0], &fixes[ka])?;
    let gyro = |a: usize| {
        0.5 * (fixes[kb].turn[a] + fixes[kb1].turn[a] - fixes[ka0].turn[a] - fixes[ka].turn[a])
    };
    // The course is known modulo a full turn.
    let off = |x: f64| ((x + 540.0).rem_euclid(360.0) - 180.0).abs();
    Some(match vertical {
        Some((axis, sign)) => off(turned - sign * gyro(axis)),
        None => (0..3)
            .flat_map(|a| [off(turned - gyro(a)), off(turned + gyro(a))])
            .fold(f64::INFINITY, f64::min),
    })
}

/// Shortest run of repeated gyro readings (s, rows) that [`stuck_gyro`] looks at.
const MIN_STUCK_S: f64 = 1.0;
const MIN_STUCK_ROWS: usize = 5;

/// A run of repeated readings is at least this many times the log's
/// typical run (see [`repeated_readings`]).
const STUCK_PER_TYPICAL: f64 = 5.0;

/// Odometer distance (m) over a run of zeros that says the vehicle moved.
const MIN_MOVED_M: f64 = 2.0;

/// How far (deg) the GPS course must turn beyond the gyro across a run of
/// zeros for [`stuck_gyro`] to name it: a chord of the stretches' length
/// (ten times the fixes' scatter) reads its course to some 8 deg, the
/// difference of two to some 11.
const STUCK_TURN_DEG: f64 = 30.0;
