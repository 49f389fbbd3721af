//! A gyro that stopped answering: one reading repeated on all three axes,
//! row after row.
//!
//! A logger writes zeros, or its last reading, when its IMU stops
//! answering (a loose I2C wire, a driver's hiccup, a bus overrun), and the
//! heading integrated through it is wrong from there on: Berlin's yaw rate
//! held at its last reading for 25 s sent the fit 58 m from its fixes, 25 s
//! of zeros in a bend 31 m from its reference, reported as a success. A
//! MEMS gyro's noise never repeats a reading on all three axes for a
//! second; a car's yaw-rate sensor may hold 0.00 along a straight, within
//! its deadband. So a run of repeated readings (see [`repeated_readings`])
//! is a stop where
//!
//! - the reading held is not zero (no sensor holds one, and integrated it
//!   turns the heading at that rate): [`Kind::Held`];
//! - zeros on all three axes while the odometer moves [`MIN_MOVED_M`], in a
//!   log whose three axes read something elsewhere (a moving vehicle's gyro
//!   is never exactly still): [`Kind::Zeros`];
//! - zeros for [`MIN_LONE_ZEROS_S`] while the vehicle moves on a gyro with
//!   an axis that never reads (a yaw-rate sensor alone), where elsewhere it
//!   reads zero on under [`MAX_DEADBAND_SHARE`] of the rows that move (a
//!   deadband reads zero on every straight; Berlin's yaw rate on 1.3 % of
//!   them): [`Kind::LoneZeros`].
//!
//! Other runs of zeros are left undecided (`kind: None`): `gyropath check`
//! then asks the GPS course whether the vehicle turned through them. The
//! fit bridges each decided stop (`effects::gyro_stops`): the yaw rates
//! inside it are interpolated between the readings either side, as across
//! a gap in the log, and the turns across it are free parameters.

/// Shortest run of repeated readings (s, rows) that can be a stop.
pub const MIN_STOP_S: f64 = 1.0;
pub const MIN_STOP_ROWS: usize = 5;

/// A run of repeated readings is at least this many times the log's
/// typical run (its 95th percentile): a slow gyro written on every row of a
/// faster log repeats each reading as a matter of course.
pub const STOP_PER_TYPICAL: f64 = 5.0;

/// Odometer distance (m) over a run of zeros that says the vehicle moved.
pub const MIN_MOVED_M: f64 = 2.0;

/// See [`Kind::LoneZeros`].
pub const MIN_LONE_ZEROS_S: f64 = 5.0;
pub const MAX_DEADBAND_SHARE: f64 = 0.05;

/// Why a run of repeated readings is a stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A nonzero reading held.
    Held,
    /// Zeros on a three-axis gyro while the vehicle moves.
    Zeros,
    /// Zeros on a gyro with an axis that never reads, while the vehicle
    /// moves, where the sensor has no deadband; with the share of the
    /// moving rows elsewhere that read zero.
    LoneZeros { share: f64 },
}

/// A run of rows `first..=last` on which the gyro repeats one reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Run {
    pub first: usize,
    pub last: usize,
    /// The odometer's distance over the run (m).
    pub moved_m: f64,
    /// Why it is a stop; `None`: zeros that may be a deadband.
    pub kind: Option<Kind>,
}

/// The runs of repeated readings of a log with times `t`, readings
/// `reading(j)` (any unit: only equality and zero are read) and odometer
/// distance per step `distance` (m), each classified (see the module).
pub fn find(t: &[f64], reading: impl Fn(usize) -> [f64; 3], distance: &[f64]) -> Vec<Run> {
    let n = t.len();
    let three_axes = (0..3).all(|a| (0..n).any(|j| reading(j)[a] != 0.0));
    let moved = |first: usize, last: usize| -> f64 { distance[first + 1..=last].iter().sum() };
    repeated_readings(t, &reading)
        .into_iter()
        .filter_map(|(first, last)| {
            let value = reading(first);
            let moved_m = moved(first, last);
            let kind = if value != [0.0; 3] {
                Some(Kind::Held)
            } else if three_axes {
                // Three axes of zeros that stand still: the vehicle stood.
                (moved_m >= MIN_MOVED_M).then_some(Kind::Zeros)
            } else if moved_m >= MIN_MOVED_M && t[last] - t[first] >= MIN_LONE_ZEROS_S {
                let share = zeros_while_moving(&reading, distance, (first, last));
                (share < MAX_DEADBAND_SHARE).then_some(Kind::LoneZeros { share })
            } else {
                None
            };
            if three_axes && kind.is_none() {
                return None;
            }
            Some(Run {
                first,
                last,
                moved_m,
                kind,
            })
        })
        .collect()
}

/// Runs of rows `(first, last)` on which the readings repeat, that last at
/// least [`MIN_STOP_S`] and [`MIN_STOP_ROWS`], and [`STOP_PER_TYPICAL`]
/// times the 95th percentile of the log's runs.
fn repeated_readings(t: &[f64], reading: &impl Fn(usize) -> [f64; 3]) -> Vec<(usize, usize)> {
    let n = t.len();
    let mut runs = Vec::new();
    let mut start = 0;
    for j in 1..=n {
        if j < n && reading(j) == reading(j - 1) {
            continue;
        }
        runs.push((start, j - 1));
        start = j;
    }
    // A live gyro's runs are single rows (span 0) but for a few: the
    // percentile is then 0 without sorting a run per row.
    let single = runs.iter().filter(|&&(a, b)| a == b).count();
    let typical = if (0.95 * runs.len() as f64).ceil() as usize <= single {
        0.0
    } else {
        let mut spans: Vec<f64> = runs.iter().map(|&(a, b)| t[b] - t[a]).collect();
        crate::statistics::quantile(&mut spans, 0.95)
    };
    let shortest = MIN_STOP_S.max(STOP_PER_TYPICAL * typical);
    runs.retain(|&(a, b)| b - a + 1 >= MIN_STOP_ROWS && t[b] - t[a] >= shortest);
    runs
}

/// The share of the rows on which the vehicle moves, outside rows `skip`,
/// where the gyro reads zero on every axis.
fn zeros_while_moving(
    reading: &impl Fn(usize) -> [f64; 3],
    distance: &[f64],
    skip: (usize, usize),
) -> f64 {
    let (mut moving, mut zeros) = (0usize, 0usize);
    for j in (1..distance.len()).filter(|&j| distance[j] > 0.0 && !(skip.0..=skip.1).contains(&j)) {
        moving += 1;
        zeros += usize::from(reading(j) == [0.0; 3]);
    }
    if moving == 0 {
        return 1.0;
    }
    zeros as f64 / moving as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 100 Hz three-axis gyro with noise, moving 10 m/s.
    fn noisy(n: usize) -> (Vec<f64>, Vec<[f64; 3]>, Vec<f64>) {
        let t: Vec<f64> = (0..n).map(|j| j as f64 * 0.01).collect();
        let g: Vec<[f64; 3]> = (0..n)
            .map(|j| {
                let x = j as f64;
                [(x * 0.37).sin(), (x * 0.91).cos(), 5.0 + (x * 1.3).sin()]
            })
            .collect();
        (t, g, vec![0.1; n])
    }

    #[test]
    fn held_readings_and_zeros_while_moving_are_stops() {
        let (t, mut g, mut d) = noisy(6000);
        assert!(find(&t, |j| g[j], &d).is_empty());
        let held = g[999];
        for r in &mut g[1000..1300] {
            *r = held;
        }
        for r in &mut g[3000..3500] {
            *r = [0.0; 3];
        }
        // Zeros while standing still: the vehicle stood, no stop.
        for (r, dist) in g[5000..5400].iter_mut().zip(&mut d[5000..5400]) {
            *r = [0.0; 3];
            *dist = 0.0;
        }
        let runs = find(&t, |j| g[j], &d);
        assert_eq!(runs.len(), 2, "{runs:?}");
        assert_eq!(
            (runs[0].first, runs[0].last, runs[0].kind),
            (999, 1299, Some(Kind::Held))
        );
        assert_eq!(
            (runs[1].first, runs[1].last, runs[1].kind),
            (3000, 3499, Some(Kind::Zeros))
        );
        // A half-second hold is no stop.
        let (t, mut g, d) = noisy(6000);
        for r in &mut g[1000..1050] {
            *r = [1.0, 2.0, 3.0];
        }
        assert!(find(&t, |j| g[j], &d).is_empty());
    }

    /// A yaw rate alone: zeros are a stop only where the sensor has no
    /// deadband; a slow gyro written on every row of a faster log repeats
    /// each reading and is no stop.
    #[test]
    fn a_yaw_rate_alone_stops_only_without_a_deadband() {
        let (t, g3, d) = noisy(6000);
        let yaw = |deadband: f64, zeros: std::ops::Range<usize>| -> Vec<[f64; 3]> {
            (0..g3.len())
                .map(|j| {
                    let z = (j as f64 * 0.002).sin() * 10.0 + (j as f64 * 1.3).sin() * 0.01;
                    let z = if z.abs() < deadband || zeros.contains(&j) {
                        0.0
                    } else {
                        z
                    };
                    [0.0, 0.0, z]
                })
                .collect()
        };
        let g = yaw(0.0, 2000..2700);
        let runs = find(&t, |j| g[j], &d);
        assert_eq!(runs.len(), 1, "{runs:?}");
        assert!(matches!(runs[0].kind, Some(Kind::LoneZeros { share }) if share < 0.01));
        // A 2 deg/s deadband reads zero on a tenth of the moving rows.
        let g = yaw(2.0, 2000..2700);
        let runs = find(&t, |j| g[j], &d);
        assert!(runs.iter().all(|r| r.kind.is_none()), "{runs:?}");
        // A 10 Hz gyro on the rows of a 100 Hz log.
        let g: Vec<[f64; 3]> = (0..g3.len()).map(|j| g3[j - j % 10]).collect();
        assert!(find(&t, |j| g[j], &d).is_empty());
    }
}
