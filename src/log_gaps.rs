//! Gaps in the log: rows filled across each, so that the fit can turn the
//! vehicle through it.
//!
//! A logger drops its rows for seconds at a time (a phone app sent to the
//! background, an SD card's write stall, a bag's dropped messages). Across
//! one step the model turns the whole way first and then moves the whole
//! distance along the new heading, `p_j = p_{j-1} + (q_j f) d_j`, with the
//! turn interpolated between the samples either side: a car that took a
//! 74 deg bend in a 20 s gap (simulated, seed 4, 300 s) came out of it
//! dozens of metres off, and the fit bent its bias to 3.5 deg/s to meet the
//! fixes after it and ended 39 m from the truth (2.5 m for the fixes), as a
//! success.
//!
//! So each gap longer than [`MIN_GAP_S`] (and five of the log's intervals)
//! is filled with rows at the log's median interval, on which
//!
//! - the time runs evenly, `t_a + k (t_b - t_a) / (m + 1)`, `k = 1..m`;
//! - the gyro is the line between the samples either side (the signals then
//!   treat the filled rows as a gyro stop, `crate::signals`: the turn across
//!   it is a parameter of the fit, `effects::gyro_stops`, started from
//!   that line);
//! - every optional column is empty, so that the signals interpolate the
//!   odometer, the speeds and the channels across it as across any empty
//!   field (a cumulative odometer then spreads the gap's distance evenly);
//!   wheel pulses hold their last state (no revolution is invented);
//! - the line is that of the row after the gap (what a message names).
//!
//! Gaps longer than [`MAX_GAP_S`] are pauses, refused before any row is
//! filled (`crate::signals`).

use crate::ride::RideLog;

/// The shortest gap (s) whose rows are filled (and five of the log's
/// median intervals): as a gyro stop's (`crate::gyro_stops::MIN_STOP_S`);
/// over shorter ones a vehicle turns little, and the rate interpolated
/// between the samples either side is close to the one it had.
pub const MIN_GAP_S: f64 = crate::gyro_stops::MIN_STOP_S;

/// The longest gap between rows (s) that is filled; a longer one is a
/// pause: a logger stopped, a bike computer's or phone app's auto-pause,
/// after which the vehicle may be anywhere. Across a 10-minute pause in a
/// simulated 20-minute ride, the interpolated turn sent step 1 240 m off,
/// and the fit took 122 s to end 13 m from its fixes (1.8 m without the
/// pause) as a success.
pub const MAX_GAP_S: f64 = 60.0;

/// ", N of them filled across gaps in the log" after a count of rows where
/// `filled` rows were, else nothing: what a summary says of the rows.
pub fn filled_phrase(filled: usize) -> String {
    if filled == 0 {
        String::new()
    } else {
        format!(", {filled} of them filled across gaps in the log")
    }
}

/// The gaps of `t` to fill: `(j, m)`, the row after the gap and the rows
/// to put before it.
fn gaps(t: &[f64]) -> Vec<(usize, usize)> {
    // Most logs have no step as long as the shortest gap: their steps are
    // not copied to find the median (17 MB on a 6-hour ride).
    if !t.windows(2).any(|w| w[1] - w[0] > MIN_GAP_S) {
        return Vec::new();
    }
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let median = crate::statistics::quantile(&mut steps, 0.5);
    if median <= 0.0 || !median.is_finite() {
        return Vec::new();
    }
    let limit = MIN_GAP_S.max(5.0 * median);
    (1..t.len())
        .filter_map(|j| {
            let gap = t[j] - t[j - 1];
            (gap > limit && gap <= MAX_GAP_S)
                .then(|| (j, ((gap / median).round() as usize).saturating_sub(1)))
        })
        .filter(|&(_, m)| m > 0)
        .collect()
}

/// Fill `log`'s gaps (see the module), the rows filled kept in order in
/// [`RideLog::filled`] (the samples either side of each are the rows just
/// outside its range). A log without gaps is left as it is.
pub fn fill(log: &mut RideLog) {
    let found = gaps(&log.t_s);
    if found.is_empty() {
        return;
    }
    // Where each original row goes: row `j` moves down by the rows put
    // before it.
    let mut filled = Vec::with_capacity(found.len());
    let mut added = 0;
    for &(j, m) in &found {
        filled.push(j + added..j + added + m);
        added += m;
    }
    let t = std::mem::take(&mut log.t_s);
    log.t_s = spread(&t, &found, |j, k, m| {
        let (a, b) = (t[j - 1], t[j]);
        a + (b - a) * k as f64 / (m + 1) as f64
    });
    let gyro = std::mem::take(&mut log.gyro_dps);
    log.gyro_dps = spread(&gyro, &found, |j, k, m| {
        let f = k as f64 / (m + 1) as f64;
        let (a, b) = (gyro[j - 1], gyro[j]);
        [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * f)
    });
    let line = std::mem::take(&mut log.line);
    log.line = spread(&line, &found, |j, _, _| line.get(j).copied().unwrap_or(0));
    let fix = std::mem::take(&mut log.fix);
    log.fix = spread(&fix, &found, |_, _, _| None);
    if let Some(p) = log.wheel_pulse.take() {
        log.wheel_pulse = Some(spread(&p, &found, |j, _, _| p[j - 1]));
    }
    if let Some(a) = log.accel_mps2.take() {
        log.accel_mps2 = Some(spread(&a, &found, |_, _, _| None));
    }
    for c in log.number_columns_mut() {
        *c = spread(c, &found, |_, _, _| None);
    }
    for (_, c) in &mut log.channels {
        *c = spread(c, &found, |_, _, _| None);
    }
    log.filled = filled;
}

/// `v` with `m` values `value(j, k, m)` (`k = 1..=m`) put before row `j`
/// for each `(j, m)` of `gaps`. A column shorter than the log (none should
/// be) is returned as it is.
fn spread<T: Clone>(
    v: &[T],
    gaps: &[(usize, usize)],
    value: impl Fn(usize, usize, usize) -> T,
) -> Vec<T> {
    if gaps.last().is_some_and(|&(j, _)| j >= v.len()) {
        return v.to_vec();
    }
    let mut out = Vec::with_capacity(v.len() + gaps.iter().map(|g| g.1).sum::<usize>());
    let mut from = 0;
    for &(j, m) in gaps {
        out.extend_from_slice(&v[from..j]);
        out.extend((1..=m).map(|k| value(j, k, m)));
        from = j;
    }
    out.extend_from_slice(&v[from..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(t: &[f64]) -> RideLog {
        let n = t.len();
        RideLog {
            source: "gaps.csv".into(),
            line: (0..n as u64).map(|i| i + 3).collect(),
            t_s: t.to_vec(),
            gyro_dps: t.iter().map(|&t| [0.0, 0.0, t]).collect(),
            wheel_pulse: Some((0..n).map(|i| i % 2 == 0).collect()),
            odo_m: Some(t.iter().map(|&t| Some(2.0 * t)).collect()),
            fix: (0..n).map(|i| Some((47.0, 19.0 + i as f64))).collect(),
            channels: vec![("temp_c".into(), vec![Some(20.0); n])],
            ..RideLog::default()
        }
    }

    #[test]
    fn a_gap_is_filled_at_the_logs_rate_with_the_gyros_line_and_empty_fields() {
        // 10 Hz with a 2 s gap after t = 0.3 and a 0.4 s one (not filled:
        // under MIN_GAP_S) after t = 2.6.
        let t = [0.0, 0.1, 0.2, 0.3, 2.3, 2.4, 2.5, 2.6, 3.0, 3.1];
        let mut l = log(&t);
        fill(&mut l);
        assert_eq!(l.filled, vec![4..23]);
        assert_eq!((l.t_s[3], l.t_s[23]), (0.3, 2.3), "the samples either side");
        assert_eq!(l.len(), t.len() + 19);
        for j in 4..23 {
            let want = 0.3 + 0.1 * (j - 3) as f64;
            assert!((l.t_s[j] - want).abs() < 1e-12, "{j}: {}", l.t_s[j]);
            // The gyro's line between 0.3 and 2.3 deg/s.
            assert!((l.gyro_dps[j][2] - want).abs() < 1e-12);
            assert_eq!(l.line[j], 7, "the row after the gap's line");
            assert_eq!(l.fix[j], None);
            assert_eq!(l.odo_m.as_ref().unwrap()[j], None);
            assert_eq!(l.channels[0].1[j], None);
            // Pulses hold the last state: no edge is invented.
            let pulses = l.wheel_pulse.as_ref().unwrap();
            assert_eq!(pulses[j], pulses[3]);
        }
        // The rows either side are the log's own.
        assert_eq!(&l.t_s[..4], &t[..4]);
        assert_eq!(&l.t_s[23..], &t[4..]);
        assert_eq!(l.line[23], 7);
        assert_eq!(l.fix[23], Some((47.0, 23.0)));
        assert!(l.t_s.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn logs_without_gaps_and_pauses_are_left_as_they_are() {
        let even: Vec<f64> = (0..100).map(|i| i as f64 * 0.01).collect();
        let mut l = log(&even);
        fill(&mut l);
        assert!(l.filled.is_empty());
        assert_eq!(l.t_s, even);
        // A pause (over MAX_GAP_S) is refused elsewhere, never filled.
        let mut paused = even.clone();
        paused.extend((0..10).map(|i| 100.0 + i as f64 * 0.01));
        let mut l = log(&paused);
        fill(&mut l);
        assert!(l.filled.is_empty());
        assert_eq!(l.len(), paused.len());
    }
}
