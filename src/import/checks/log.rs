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
