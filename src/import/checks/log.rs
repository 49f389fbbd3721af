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

/// A gyro that stopped answering (see [`crate::gyro_stops`]): the
/// stops it finds are problems (the fit bridges them with a free turn),
/// and a run of zeros it leaves undecided on a gyro with an axis that never
/// reads is named, as a warning, where the GPS course turns by more than
/// [`STUCK_TURN_DEG`] across it, read from chords of the stretches' length
/// either side (straight lines, as in the course check) against the gyro's
/// turn between the chords' middles about `vertical`, or the axis that
/// comes nearest where the vertical is not known.
pub(super) fn stuck_gyro(
    log: &RideLog,
    distance: &[f64],
    (fixes, stretches): (&[AtFix], &Stretches),
    vertical: Option<(usize, f64)>,
    report: &mut CheckReport,
) {
    use crate::gyro_stops::Kind;
    let mut found: Vec<(usize, usize, Level, String)> = Vec::new();
    for run in crate::gyro_stops::find(&log.t_s, |j| log.gyro_dps[j], distance) {
        let (first, last, moved) = (run.first, run.last, run.moved_m);
        let bridged = "; the fit bridges it with free turns (effect gyro_stops)";
        match run.kind {
            Some(Kind::Held) => found.push((first, last, Level::Problem, bridged.into())),
            Some(Kind::Zeros) => found.push((
                first,
                last,
                Level::Problem,
                format!(" while the odometer moves {moved:.0} m{bridged}"),
            )),
            Some(Kind::LoneZeros { share }) => found.push((
                first,
                last,
                Level::Problem,
                format!(
                    " while the odometer moves {moved:.0} m, where elsewhere it reads zero on {:.1} % of the rows that move{bridged}",
                    100.0 * share
                ),
            )),
            None => {
                if let Some(missed) = course_missed(first, last, log, (fixes, stretches), vertical)
                    && missed > STUCK_TURN_DEG
                {
                    found.push((
                        first,
                        last,
                        Level::Warning,
                        format!(
                            " while the GPS course turns {missed:.0} deg more than it does; fit each side apart (--between) or mend the log"
                        ),
                    ));
                }
            }
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
            "the gyro repeats one reading ({}, {}, {} as labelled) on every row from t = {:.2} to {:.2} s (lines {}-{}){}: a sensor that stopped answering, its dropout written as zeros or its last reading repeated{why}",
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

/// How far (deg) the GPS course turns beyond the gyro across rows
/// `first..=last` (see [`stuck_gyro`]); `None` where the fixes cannot tell.
fn course_missed(
    first: usize,
    last: usize,
    log: &RideLog,
    (fixes, stretches): (&[AtFix], &Stretches),
    vertical: Option<(usize, f64)>,
) -> Option<f64> {
    let length = stretches.length_m * stretches.odometer_per_m?;
    let (ta, tb) = (log.t_s[first], log.t_s[last]);
    let ka = fixes.iter().rposition(|f| f.t <= ta)?;
    let kb = fixes.iter().position(|f| f.t >= tb)?;
    let ka0 = (0..ka)
        .rev()
        .find(|&k| fixes[ka].s - fixes[k].s >= length)?;
    let kb1 = (kb + 1..fixes.len()).find(|&k| fixes[k].s - fixes[kb].s >= length)?;
    let turned =
        stretches.course(&fixes[kb], &fixes[kb1])? - stretches.course(&fixes[ka0], &fixes[ka])?;
    let gyro = |a: usize| {
        0.5 * (fixes[kb].turn[a] + fixes[kb1].turn[a] - fixes[ka0].turn[a] - fixes[ka].turn[a])
    };
    // The course is known modulo a full turn.
    let off = |x: f64| super::axes::wrap_deg(x).abs();
    Some(match vertical {
        Some((axis, sign)) => off(turned - sign * gyro(axis)),
        None => (0..3)
            .flat_map(|a| [off(turned - gyro(a)), off(turned + gyro(a))])
            .fold(f64::INFINITY, f64::min),
    })
}

/// How far (deg) the GPS course must turn beyond the gyro across a run of
/// zeros for [`stuck_gyro`] to name it: a chord of the stretches' length
/// (ten times the fixes' scatter) reads its course to some 8 deg, the
/// difference of two to some 11.
const STUCK_TURN_DEG: f64 = 30.0;
