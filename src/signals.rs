//! What is derived from a ride log once, before any fitting: time steps,
//! gyro rates in rad/s, raw distance per step, GPS fixes in a local ENU frame,
//! the vertical references and the extra channels.
//!
//! Row `j` of the log closes the step `(t_{j-1}, t_j]`: its gyro value is the
//! mean rate over that step and `distance[j]` the odometer distance covered in
//! it. Row 0 only fixes the start (`dt[0] = 0`, `distance[0] = 0`).
//!
//! The measurements and the history behind these choices: data/ride-log-
//! format.md (the columns) and docs/vehicles.md (planar or 3D).

use nalgebra::Vector3;
use thiserror::Error;

use crate::geodesy::{Geodetic, LocalFrame};
use crate::ride::RideLog;
use crate::standing::{STANDING_RATE_DPS, STANDING_SPEED_MPS};

/// Why a loaded log cannot be used for a reconstruction.
#[derive(Debug, Error)]
pub enum SignalError {
    #[error("{file}: {message}")]
    Unusable { file: String, message: String },
    #[error("{file}:{line}: column '{column}': {message}")]
    Field {
        file: String,
        line: u64,
        column: String,
        message: String,
    },
    /// No GPS fix in the whole log: a GPS track of the same ride can give
    /// it its fixes (`--gps-track`).
    #[error("{file}: {message}")]
    NoFix { file: String, message: String },
    /// A pause in the log (see [`pause`]), with the time windows (log
    /// clock, s) either side of its longest one, each of which can be fitted.
    #[error("{file}: {message}")]
    Pause {
        file: String,
        message: String,
        windows: [(f64, f64); 2],
    },
}

impl SignalError {
    /// The windows either side of the log's longest pause, where a pause is what refused it.
    pub fn pause_windows(&self) -> Option<[(f64, f64); 2]> {
        match self {
            Self::Pause { windows, .. } => Some(*windows),
            _ => None,
        }
    }
}

/// The slowest gyro a path is integrated from (Hz, median rate): a vehicle
/// turns through 90 deg in 2-5 s, so at 2 Hz a turn still spans four steps
/// or more (the smartLoc car's yaw-rate sensor logs 5 Hz and fits well);
/// slower logs (a phone's decimated test file logs 0.02 Hz) have no heading
/// between their samples.
pub const MIN_GYRO_RATE_HZ: f64 = 2.0;

/// A log's rate (Hz): one over the median step of its times `t_s`, which
/// a few gaps or a burst do not move.
pub fn median_rate_hz(t_s: &[f64]) -> f64 {
    let mut dt: Vec<f64> = t_s.windows(2).map(|w| w[1] - w[0]).collect();
    1.0 / crate::statistics::median(&mut dt)
}

/// One GPS fix, in the local frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Fix {
    /// Row of the log that holds it.
    pub row: usize,
    pub t: f64,
    /// East and north (m).
    pub en: [f64; 2],
    /// GPS altitude in the local frame (m), when the log has it on this row.
    pub up: Option<f64>,
    /// Barometric altitude (m, unknown offset) at this row, when the log has a barometer.
    pub baro: Option<f64>,
    /// The receiver's own 1-sigma horizontal and vertical accuracy (m), when logged.
    pub hacc: Option<f64>,
    pub vacc: Option<f64>,
    /// The receiver's horizontal dilution of precision, when logged: the
    /// fix's relative accuracy where the log has no `hacc`.
    pub hdop: Option<f64>,
}

/// The longest gap in the log's rows that the gyro cannot be integrated
/// across (see [`MAX_GAP_S`]), said with its line, its time and the
/// `--between` windows of the ride on either side of it; `None` without one.
pub(crate) fn pause(t: &[f64], line: &[u64]) -> Option<(String, [(f64, f64); 2])> {
    let (j, gap) = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    if gap <= MAX_GAP_S {
        return None;
    }
    let pauses = t.windows(2).filter(|w| w[1] - w[0] > MAX_GAP_S).count();
    let (before, after) = (t[j], t[j + 1]);
    let (first, last) = (t[0], t[t.len() - 1]);
    let message = format!(
        "the log pauses for {gap:.0} s after t = {before:.2} s (line {}){}: the gyro's turns across a pause are unknown, so the path cannot be carried over it; fit each side apart, --between {first},{before} and --between {after},{last}",
        line.get(j + 1).copied().unwrap_or(j as u64 + 2),
        if pauses > 1 {
            format!(", the longest of its {pauses} pauses over {MAX_GAP_S:.0} s")
        } else {
            String::new()
        }
    );
    Some((message, [(first, before), (after, last)]))
}

/// Seconds either side of a gap in the log over which the wheel's speed
/// into and out of it is taken (see [`pulses_across_gaps`]).
const PULSE_SPEED_S: f64 = 2.0;

/// The distance on the rows `filled` across the log's gaps (see
/// [`crate::log_gaps`]) where it comes from wheel pulses: the speed
/// interpolated between the wheel's mean speeds over the [`PULSE_SPEED_S`]
/// either side, `d_j = v(t_j) dt_j`, up to the row after the gap. The
/// revolutions inside a gap were never logged, and the pulses' own rule
/// takes a long wait for the next one as a stop: a simulated bicycle went
/// nowhere through a 15 s gap, and with the gap's distance free about that
/// (`effects::gnss_gaps`, a prior of 2 m/s on its mean speed) the fit drove
/// 224 m where the bicycle rode 60.
fn pulses_across_gaps(t: &[f64], distance: &mut [f64], filled: &[std::ops::Range<usize>]) {
    let speed = |from: f64, to: f64, distance: &[f64]| -> f64 {
        let rows = t.partition_point(|&x| x <= from)..t.partition_point(|&x| x <= to);
        let (first, last) = (rows.start.max(1), rows.end.min(t.len()));
        if last <= first {
            return 0.0;
        }
        let time = t[last - 1] - t[first - 1];
        let moved: f64 = distance[first..last].iter().sum();
        if time > 0.0 { moved / time } else { 0.0 }
    };
    for rows in filled.iter().filter(|r| r.start > 0 && r.end < t.len()) {
        let (from, to) = (t[rows.start - 1], t[rows.end]);
        let before = speed(from - PULSE_SPEED_S, from, distance);
        let after = speed(to, to + PULSE_SPEED_S, distance);
        for j in rows.start..=rows.end {
            let v = before + (after - before) * ((t[j] - from) / (to - from)).clamp(0.0, 1.0);
            distance[j] = v * (t[j] - t[j - 1]);
        }
    }
}

/// The stops of a gyro that stopped answering (see [`crate::gyro_stops`])
/// in the step rates `gyro` (rad/s) of rows at `t` moving `distance`, as
/// `(t_a, t_b)`: the rates of their steps (`t_a < t_j <= t_b`, the run's
/// rows) are made anew so that a held reading turns nothing of its own.
///
/// - About z, the line between the readings either side (as across a gap
///   in the log), the turn across the stop being the free parameter of
///   `effects::gyro_stops`, spread evenly on top of it. A constant rate
///   there (the two readings' mean) lost the shape of the turn inside the
///   stop: on Berlin's yaw rate held for 25 s after a reading of -27 deg/s
///   in a right bend (the next one -3 deg/s, the car turning left between),
///   39 m from the reference against 17 m along the line.
/// - About x and y, the log's median rate: a vehicle's roll and pitch come
///   back to where they were, so over a stop they turn by the bias alone.
///   (`effects::gyro_stops` replaces these with its own roll and pitch
///   turns; they are what the start guess, and a fit without the effect,
///   integrate.)
///   The line between the readings either side rolled a simulated bicycle,
///   caught leaning into a bend at the stop's start and out of it at its
///   end, by tens of degrees over a 15 s stop, and the fit failed 75 m from
///   its fixes.
///
/// The rows `filled` across the log's gaps (see [`crate::log_gaps`]) are
/// bridged alike: the gyro did not answer there either; and so are the
/// rows `turned`, `(first, last)`, where the sensor turned without the
/// vehicle (see [`crate::sensor_turns`]): the gyro answered for the
/// sensor, not for the vehicle.
fn bridge_stops(
    t: &[f64],
    gyro: &mut [Vector3<f64>],
    distance: &[f64],
    filled: &[std::ops::Range<usize>],
    turned: &[(usize, usize)],
) -> Vec<(f64, f64)> {
    let mut runs: Vec<(usize, usize)> = crate::gyro_stops::find(t, |j| gyro[j].into(), distance)
        .into_iter()
        .filter(|r| r.kind.is_some())
        .map(|r| (r.first, r.last))
        .collect();
    runs.extend(
        filled
            .iter()
            .filter(|rows| !rows.is_empty())
            .map(|rows| (rows.start, rows.end - 1)),
    );
    // The sensor's own turns (see `crate::sensor_turns`), where no stop or
    // gap is bridged already.
    let apart = |a: &(usize, usize), b: &(usize, usize)| a.1 + 1 < b.0 || b.1 + 1 < a.0;
    let free: Vec<(usize, usize)> = turned
        .iter()
        .filter(|s| s.0 <= s.1 && runs.iter().all(|r| apart(r, s)))
        .copied()
        .collect();
    runs.extend(free);
    runs.sort_unstable();
    if runs.is_empty() {
        return Vec::new();
    }
    let median = |a: usize| {
        let mut v: Vec<f64> = gyro.iter().skip(1).map(|w| w[a]).collect();
        crate::statistics::quantile(&mut v, 0.5)
    };
    let (roll, pitch) = (median(0), median(1));
    let mut stops = Vec::new();
    for (first, last) in runs {
        let first = first.max(1);
        let before = gyro[first - 1].z;
        let after = gyro.get(last + 1).map_or(before, |w| w.z);
        let (ta, tb) = (t[first - 1], t.get(last + 1).copied().unwrap_or(t[last]));
        for j in first..=last {
            let f = if tb > ta {
                (t[j] - ta) / (tb - ta)
            } else {
                0.0
            };
            gyro[j] = Vector3::new(roll, pitch, before + (after - before) * f);
        }
        stops.push((t[first - 1], t[last]));
    }
    stops
}

pub use crate::log_gaps::MAX_GAP_S;

/// A hint that column `t_s` holds milliseconds, microseconds or
/// nanoseconds, when read so its rate `rate_hz` (read as seconds) becomes a
/// gyro's usual 10 Hz to 10 kHz and the log, `span_s` long read as
/// seconds, lasts more than half a day (a bag's slow IMU over a few
/// minutes is not told to divide its times); empty otherwise. Loggers
/// often write their clock's own unit, and "0.10 Hz over 300000 s" alone
/// does not say why.
pub(crate) fn time_unit_hint(rate_hz: f64, span_s: f64) -> String {
    if span_s < 43_200.0 {
        return String::new();
    }
    [
        (1e3, "milliseconds", "ms"),
        (1e6, "microseconds", "us"),
        (1e9, "nanoseconds", "ns"),
    ]
    .iter()
    .find(|(scale, _, _)| (10.0..=10_000.0).contains(&(rate_hz * scale)))
    .map_or_else(String::new, |(scale, unit, short)| {
            format!(
                ". Column 't_s' looks like {unit} (read so, the gyro runs at {:.0} Hz): t_s is in seconds: divide it by {scale:.0}, or read the file through a column map (--map, with [time] unit = \"{short}\")",
                rate_hz * scale
            )
        })
}

/// Everything the model needs from a log, in SI units.
#[derive(Clone, Debug)]
pub struct Signals {
    pub source: String,
    pub t: Vec<f64>,
    /// `dt[j] = t_j - t_{j-1}`, `dt[0] = 0`.
    pub dt: Vec<f64>,
    /// Measured angular rate (rad/s), sensor frame, mean over step `j`.
    pub gyro: Vec<Vector3<f64>>,
    /// Odometer distance over step `j` (m) before any gain correction.
    pub distance: Vec<f64>,
    pub fixes: Vec<Fix>,
    /// Row index -> fix index (or `u32::MAX`).
    pub fix_at_row: Vec<u32>,
    pub frame: LocalFrame,
    pub has_baro: bool,
    pub has_gps_alt: bool,
    /// Whether the log has the GNSS receiver's speed (two samples or more):
    /// a distance without the odometer (`--distance gnss`).
    pub has_gnss_speed: bool,
    /// Extra channels, interpolated over empty fields.
    pub channels: Vec<(String, Vec<f64>)>,
    /// How distance was measured, for reports.
    pub odometer: Odometer,
    /// Whether the attitude is modelled in 3D or about the vertical only, and why.
    pub attitude: Attitude,
    pub warnings: Vec<String>,
    /// The Unix time (s) of `t = 0` when the source knows it (a bag's first
    /// message, a log's `# t0_unix_s:` line): the path's outputs carry it so
    /// that they line up with the user's other tools.
    pub t0_unix_s: Option<f64>,
    /// The device's boot-clock time (s) of `t = 0`, when the log gives it
    /// (comma2k19: every signal and its reference pose run on that clock).
    pub t0_boot_s: Option<f64>,
    /// Where the gyro stopped answering (see [`crate::gyro_stops`]): the
    /// times `(t_a, t_b)` whose steps `t_a < t_j <= t_b` carry a yaw rate
    /// interpolated between the readings either side and the log's median
    /// roll and pitch rates (see `bridge_stops`), and whose turns
    /// `effects::gyro_stops` fits.
    pub gyro_stops: Vec<(f64, f64)>,
    /// The gaps in the log filled with rows (see [`crate::log_gaps`]), as
    /// the times `(t_a, t_b)` of the samples either side; each is also one
    /// of the [`Signals::gyro_stops`].
    pub log_gaps: Vec<(f64, f64)>,
    /// Where the sensor turned without the vehicle (see
    /// [`crate::sensor_turns`]), as the times of the fixes either side;
    /// each is also one of the [`Signals::gyro_stops`] (unless a stop or a
    /// gap there is bridged already).
    pub sensor_turns: Vec<(f64, f64)>,
    /// Per row, the spread (m^2) of the distance inside the GNSS-speed gaps
    /// that no parameter carries (`effects::gnss_gaps`), filled by the first
    /// model built on these signals: it depends on them alone, and the noise
    /// search builds a model for every likelihood it evaluates (a 30-minute
    /// ride with five gaps took 22 ms a model for it, 2.2 s a fit).
    pub(crate) gap_spread: std::sync::OnceLock<std::sync::Arc<[f64]>>,
    /// The ride in steps of [`COARSE_STEP_S`] ([`Signals::coarse`]), made
    /// once: every validation fold and candidate of `diagnose` takes its
    /// later iterations' derivatives from it.
    coarse_steps: std::sync::OnceLock<Option<std::sync::Arc<Signals>>>,
}

/// The step of the coarse ride that fits take their windows and later
/// derivatives from (s): ten rows of a 100 Hz log.
pub const COARSE_STEP_S: f64 = 0.1;

/// Rides with more rows than this do not hold their coarse ride
/// ([`Signals::coarse_shared`]): a 6-hour ride's is some 20 MB, made only a
/// few times a fit (it is validated one fold at a time), where a short
/// ride's validation asks for it in every fold of every candidate.
pub const COARSE_SHARED_ROWS: usize = 1_000_000;

/// How the attitude is modelled: the choice and the reason for it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum Attitude {
    /// Full 3D attitude from all three rates.
    Full { reason: String },
    /// Heading only: the roll and pitch rates are set to zero and the start
    /// tilt is not fitted, so the sensor stays upright.
    Planar { reason: String },
}

impl Attitude {
    pub fn is_planar(&self) -> bool {
        matches!(self, Self::Planar { .. })
    }

    /// One line for reports: the model and why.
    pub fn describe(&self) -> String {
        match self {
            Self::Full { reason } => format!("3D ({reason})"),
            Self::Planar { reason } => format!("planar, heading only ({reason})"),
        }
    }
}

/// A vehicle whose roll and pitch change by less than this over
/// [`LEVEL_WINDOW_S`] in 95 % of the windows is taken as level (degrees).
///
/// Measured: a skid-steer robot shaking on rough ground 1.6-1.7 deg (its
/// roll and pitch rates are 1.4-2.1 deg/s of noise), a car on a motorway 0.9
/// and 4.9 (hill crests), simulated bicycles leaning into turns 10-19.
/// Below this, modelling roll and pitch buys at most cos(3 deg) = 0.9986 in
/// distance and costs a degeneracy: a free tilt of the yaw axis can stand in
/// for a yaw scale error (cos 24 deg = 0.913 turned a robot's sensor 40 deg).
pub const LEVEL_LIMIT_DEG: f64 = 3.0;
/// Window over which roll and pitch changes are measured (s).
pub const LEVEL_WINDOW_S: f64 = 10.0;

/// The 95th percentile, over windows of [`LEVEL_WINDOW_S`], of how far the
/// roll and the pitch angle move (deg): the rates less their median (the
/// bias: a vehicle does not keep rolling), integrated.
pub fn level_motion(t: &[f64], rates: &[Vector3<f64>]) -> [f64; 2] {
    let mut out = [0.0; 2];
    if t.len() < 3 {
        return out;
    }
    for (a, o) in out.iter_mut().enumerate() {
        let mut r: Vec<f64> = rates.iter().map(|w| w[a]).collect();
        let mid = r.len() / 2;
        let median = *r.select_nth_unstable_by(mid, f64::total_cmp).1;
        let mut angle = vec![0.0; t.len()];
        for j in 1..t.len() {
            angle[j] = angle[j - 1] + (rates[j][a] - median) * (t[j] - t[j - 1]);
        }
        let mut k = 0usize;
        r.clear();
        for j in 0..t.len() {
            while t[j] - t[k] > LEVEL_WINDOW_S {
                k += 1;
            }
            r.push((angle[j] - angle[k]).abs());
        }
        let q = (r.len() * 95 / 100).min(r.len() - 1);
        *o = r.select_nth_unstable_by(q, f64::total_cmp).1.to_degrees();
    }
    out
}

/// Choose the attitude model of a log: `# attitude: planar|3d` in its
/// metadata decides; else planar when there are no roll and pitch rates
/// (a yaw-rate sensor) or the vehicle stays level (see [`LEVEL_LIMIT_DEG`]).
fn choose_attitude(log: &RideLog, t: &[f64], rates: &[Vector3<f64>]) -> Result<Attitude, String> {
    match log.metadata.get("attitude").map(|v| v.trim()) {
        Some("planar") => {
            return Ok(Attitude::Planar {
                reason: "asked for".into(),
            });
        }
        Some("3d") => {
            return Ok(Attitude::Full {
                reason: "asked for".into(),
            });
        }
        None | Some("auto") => {}
        Some(other) => {
            return Err(format!(
                "metadata attitude: '{other}' is none of auto, 3d, planar"
            ));
        }
    }
    if rates.iter().all(|w| w.x == 0.0 && w.y == 0.0) {
        return Ok(Attitude::Planar {
            reason: "the log has no roll and pitch rates: a yaw-rate sensor".into(),
        });
    }
    let [roll, pitch] = level_motion(t, rates);
    let stays = format!(
        "roll and pitch move {roll:.1} and {pitch:.1} deg over {LEVEL_WINDOW_S:.0} s (95 %)"
    );
    Ok(if roll.max(pitch) < LEVEL_LIMIT_DEG {
        Attitude::Planar {
            reason: format!("the vehicle stays level: {stays}"),
        }
    } else {
        Attitude::Full { reason: stays }
    })
}

#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum Odometer {
    WheelPulses {
        circumference_m: f64,
        revolutions: usize,
    },
    Cumulative,
    /// A cumulative distance from a second file, matched by time (a bike
    /// computer's wheel-speed sensor, `--wheel`): where from, in words.
    Merged {
        from: String,
    },
    /// Integrated from a logged forward speed.
    Speed,
    /// Integrated from the GNSS receiver's ground speed: the log has no
    /// wheel sensor (see [`distance_from_gnss_speed`]).
    GnssSpeed {
        /// Speed samples integrated.
        samples: usize,
        /// Time counted as standing (s): no distance.
        standing_s: f64,
        /// Stretches with no speed sample for longer than [`GNSS_SPEED_GAP_S`]
        /// (start, end in s): their distance is interpolated, not measured.
        gaps: Vec<(f64, f64)>,
        /// Stands found inside the gaps by the gyro (start, end in s).
        stands_in_gaps: Vec<(f64, f64)>,
        /// How the ride's gyro tells a stand; `None` where it cannot.
        stand_rule: Option<crate::standing::StandRule>,
    },
}

impl Odometer {
    /// Where the distance came from, in words, for summaries and reports.
    pub fn describe(&self) -> String {
        match self {
            Self::WheelPulses {
                circumference_m,
                revolutions,
            } => format!("wheel pulses ({revolutions} revolutions of {circumference_m:.3} m)"),
            Self::Cumulative => "a cumulative distance".into(),
            Self::Merged { from } => from.clone(),
            Self::Speed => "a logged forward speed, integrated".into(),
            Self::GnssSpeed {
                samples,
                standing_s,
                gaps,
                stands_in_gaps,
                ..
            } => {
                let mut s = format!(
                    "the GNSS speed, integrated (no wheel sensor; {samples} samples, {standing_s:.0} s standing"
                );
                if !gaps.is_empty() {
                    let total: f64 = gaps.iter().map(|(a, b)| b - a).sum();
                    s.push_str(&format!(
                        ", {} gaps of {total:.0} s interpolated",
                        gaps.len()
                    ));
                }
                if !stands_in_gaps.is_empty() {
                    let total: f64 = stands_in_gaps.iter().map(|(a, b)| b - a).sum();
                    s.push_str(&format!(
                        ", {total:.0} s of them standing by the gyro's shaking"
                    ));
                }
                s.push(')');
                s
            }
        }
    }
}

const NO_FIX: u32 = u32::MAX;

impl Signals {
    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    pub fn duration(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0) - self.t.first().copied().unwrap_or(0.0)
    }

    /// The stretches whose distance is interpolated, not measured, as
    /// `(t_a, t_b)`: the GNSS speed's gaps, or the log's own gaps
    /// ([`Signals::log_gaps`]) where the distance is a logged speed's or the
    /// wheel pulses' (a cumulative odometer's reading after a gap says how
    /// far the vehicle went). Each one's distance is a parameter of the fit
    /// (`effects::gnss_gaps`).
    pub fn distance_gaps(&self) -> Vec<(f64, f64)> {
        match &self.odometer {
            Odometer::GnssSpeed { gaps, .. } => gaps.clone(),
            Odometer::Speed | Odometer::WheelPulses { .. } => self.log_gaps.clone(),
            Odometer::Cumulative | Odometer::Merged { .. } => Vec::new(),
        }
    }

    /// How many of the rows were filled across gaps in the log (see
    /// [`crate::log_gaps`]): no line of the source holds them.
    pub fn filled_rows(&self) -> usize {
        self.log_gaps
            .iter()
            .map(|&(a, b)| {
                self.t
                    .partition_point(|&x| x < b)
                    .saturating_sub(self.t.partition_point(|&x| x <= a))
            })
            .sum()
    }

    /// The ride's mean speed (m/s): its distance over its duration.
    pub fn mean_speed_mps(&self) -> f64 {
        self.distance.iter().sum::<f64>() / self.duration().max(1e-9)
    }

    /// Index of the fix on `row`, if any.
    pub fn fix_index(&self, row: usize) -> Option<usize> {
        match self.fix_at_row[row] {
            NO_FIX => None,
            k => Some(k as usize),
        }
    }

    /// Derive the signals of a loaded log.
    pub fn from_log(log: &RideLog) -> Result<Self, SignalError> {
        Self::from_owned_log(log.clone())
    }

    /// Derive the signals of a loaded log, consuming it: its gyro column
    /// becomes the rates in place (a 6-hour log is not copied).
    /// The log's gaps are filled first (see [`crate::log_gaps`]).
    pub fn from_owned_log(mut log: RideLog) -> Result<Self, SignalError> {
        crate::log_gaps::fill(&mut log);
        let gyro_dps = std::mem::take(&mut log.gyro_dps);
        Self::derive(&log, gyro_dps)
    }

    /// The signals of `log`, whose gyro column (deg/s) is given apart.
    fn derive(log: &RideLog, gyro_dps: Vec<[f64; 3]>) -> Result<Self, SignalError> {
        let file = log.source.clone();
        let unusable = |message: String| SignalError::Unusable {
            file: file.clone(),
            message,
        };
        let n = log.len();
        if n < 2 {
            return Err(unusable("the log needs at least two rows".into()));
        }
        let t = log.t_s.clone();
        let mut dt = vec![0.0; n];
        for j in 1..n {
            dt[j] = t[j] - t[j - 1];
        }
        let rate = median_rate_hz(&t);
        if rate < MIN_GYRO_RATE_HZ {
            return Err(unusable(format!(
                "the gyro is logged at {rate:.2} Hz ({n} rows over {:.0} s): far too slow to integrate a vehicle's turns, which take a few seconds; a path needs a gyro at {MIN_GYRO_RATE_HZ} Hz or more{}",
                t[n - 1] - t[0],
                time_unit_hint(rate, t[n - 1] - t[0])
            )));
        }
        // Same size and alignment: the collect reuses the column's memory.
        let raw: Vec<Vector3<f64>> = gyro_dps
            .into_iter()
            .map(|g| Vector3::new(g[0], g[1], g[2]) * std::f64::consts::PI / 180.0)
            .collect();
        let instantaneous = match log.metadata.get("gyro_samples").map(|v| v.trim()) {
            None | Some("mean") => false,
            Some("instantaneous") => true,
            Some(other) => {
                return Err(unusable(format!(
                    "metadata gyro_samples: '{other}' is neither 'mean' nor 'instantaneous'"
                )));
            }
        };
        if let Some((message, windows)) = pause(&t, &log.line) {
            return Err(SignalError::Pause {
                file,
                message,
                windows,
            });
        }
        let (mut gyro, gaps) = step_rates(raw, &dt, instantaneous);
        let attitude = choose_attitude(log, &t, &gyro).map_err(&unusable)?;
        // The distance's standing rule and a gap's stands read the rates
        // as logged, before a planar ride's roll and pitch are set aside.
        let (distance, jumps) =
            odometer_distance_and_jumps(log, |j| gyro[j].map(f64::to_degrees).into());
        let (mut distance, odometer) = distance?;
        if matches!(odometer, Odometer::WheelPulses { .. }) {
            pulses_across_gaps(&t, &mut distance, &log.filled);
        }
        // The times of the samples either side of each filled gap.
        let log_gaps: Vec<(f64, f64)> = log
            .filled
            .iter()
            .filter(|rows| rows.start > 0 && rows.end < n)
            .map(|rows| (t[rows.start - 1], t[rows.end]))
            .collect();
        let mut warnings = log.warnings.clone();
        if let Some(&(from, to)) = log_gaps
            .iter()
            .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)))
        {
            let after = t.partition_point(|&x| x < to);
            warnings.push(format!(
                "{file}: {} gap(s) in the log of {:.0}-{MAX_GAP_S:.0} s, the longest {:.2} s after t = {from:.2} s (line {}): rows are filled across each at the log's rate, and the turn across it is fitted as across a gyro stop",
                log_gaps.len(),
                crate::log_gaps::MIN_GAP_S,
                to - from,
                log.line.get(after).copied().unwrap_or(0),
            ));
        }
        if let Some(g) = gaps.longest {
            warnings.push(format!(
                "{file}: {} gap(s) in the log longer than {:.3} s (5 sample intervals), the longest {:.2} s at t = {:.2} s; the rotation across each is interpolated between the samples either side",
                gaps.count,
                gaps.limit_s,
                g.1,
                t[g.0],
            ));
        }

        let time = |key: &str, what: &str| -> Result<Option<f64>, SignalError> {
            match log.metadata.get(key).map(|v| v.trim()) {
                None => Ok(None),
                Some(v) => v
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| unusable(format!("metadata {key}: '{v}' is not {what}"))),
            }
        };
        let t0_unix_s = time("t0_unix_s", "a time in seconds since 1970")?;
        let t0_boot_s = time("t0_boot_s", "a time in seconds on the device's boot clock")?;

        if let Some(w) = jumps.describe(&file, &log.line, &t) {
            warnings.push(w);
        }
        let blunders = crate::blunders::find(
            &log.t_s,
            &log.fix,
            log.gps_hacc_m.as_deref(),
            Some(&distance),
        );
        if let Some(w) = blunders.describe(&file, &log.line, &t) {
            warnings.push(w);
        }
        let usable = |row: usize| log.fix[row].is_some() && !blunders.contains(row);
        let first = (0..n).find(|&row| usable(row)).ok_or_else(|| SignalError::NoFix {
            file: file.clone(),
            message: format!(
                "the log has no GPS fix ({}); a GPS track of the same ride (a watch's or bike computer's GPX or FIT, a phone's NMEA) gives it fixes: --gps-track FILE",
                if blunders.is_empty() {
                    "lat_deg/lon_deg are empty on every row".to_string()
                } else {
                    format!(
                        "only blunders: {} at 0, 0, a receiver's placeholder while it has no fix",
                        blunders.null_island
                    )
                }
            ),
        })?;
        let (lat0, lon0) = log.fix[first].unwrap_or_default();
        let alt0 = log
            .gps_alt_m
            .as_ref()
            .and_then(|a| a.iter().flatten().next().copied())
            .unwrap_or(0.0);
        let frame = LocalFrame::new(Geodetic::new(lat0, lon0, alt0));
        if let Some(raw) = &log.baro_alt_m
            && raw.iter().all(Option::is_none)
        {
            return Err(SignalError::Field {
                file,
                line: log.line[0],
                column: "baro_alt_m".into(),
                message: "the column is empty on every row".into(),
            });
        }
        let baro = log.baro_alt_m.as_ref().map(|b| fill_gaps(b));

        let mut fixes = Vec::new();
        let mut fix_at_row = vec![NO_FIX; n];
        for (row, f) in log.fix.iter().enumerate() {
            if let Some((lat, lon)) = *f
                && !blunders.contains(row)
            {
                let up = log.gps_alt_m.as_ref().and_then(|a| a[row]);
                let enu = frame.to_enu(&Geodetic::new(lat, lon, up.unwrap_or(alt0)));
                fix_at_row[row] = fixes.len() as u32;
                fixes.push(Fix {
                    row,
                    t: t[row],
                    en: [enu.x, enu.y],
                    up: up.map(|_| enu.z),
                    baro: baro.as_ref().map(|b| b[row]),
                    hacc: log.gps_hacc_m.as_ref().and_then(|a| a[row]),
                    vacc: log.gps_vacc_m.as_ref().and_then(|a| a[row]),
                    hdop: log.gps_hdop.as_ref().and_then(|a| a[row]),
                });
            }
        }
        if fixes.len() < 2 {
            let left_out = blunders.sentences(&log.line, &t);
            return Err(unusable(format!(
                "the log has {} GPS fix; at least two are needed{}",
                fixes.len(),
                if left_out.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", left_out.join("; "))
                }
            )));
        }
        let at_fixes: Vec<crate::reversing::RowFix> = fixes.iter().map(|f| (f.row, f.en)).collect();
        let reversals = crate::reversing::find(&t, &dt, |j| gyro[j].z, &distance, &at_fixes);
        crate::reversing::apply(&mut distance, &reversals);
        if let Some(w) = crate::reversing::describe(&reversals) {
            warnings.push(format!("{file}: {w}"));
        }
        let turns = crate::sensor_turns::find(&t, &dt, |j| gyro[j].z, &distance, &at_fixes);
        if let Some(w) = crate::sensor_turns::describe(&turns) {
            warnings.push(format!("{file}: {w}"));
        }
        let turned: Vec<(usize, usize)> = turns
            .iter()
            .map(|s| (s.first_row + 1, s.last_row))
            .collect();
        let gyro_stops = bridge_stops(&t, &mut gyro, &distance, &log.filled, &turned);
        if attitude.is_planar() {
            for w in &mut gyro {
                w.x = 0.0;
                w.y = 0.0;
            }
        }
        let has_gps_alt = fixes.iter().any(|f| f.up.is_some());
        let channels = log
            .channels
            .iter()
            .filter(|(_, v)| v.iter().any(Option::is_some))
            .map(|(name, v)| (name.clone(), fill_gaps(v)))
            .collect();
        Ok(Self {
            source: file,
            t,
            dt,
            gyro,
            distance,
            fixes,
            fix_at_row,
            frame,
            has_baro: baro.is_some(),
            has_gps_alt,
            channels,
            odometer,
            attitude,
            warnings,
            t0_unix_s,
            t0_boot_s,
            has_gnss_speed: log.gnss_speed_samples() >= 2,
            gyro_stops,
            log_gaps,
            sensor_turns: turns.iter().map(|s| (s.from_s, s.to_s)).collect(),
            gap_spread: std::sync::OnceLock::new(),
            coarse_steps: std::sync::OnceLock::new(),
        })
    }

    /// [`Signals::coarse`] in steps of [`COARSE_STEP_S`], made on first use
    /// and shared from then on; on rides of more than
    /// [`COARSE_SHARED_ROWS`] made anew each time, not held.
    pub fn coarse_shared(&self) -> Option<std::sync::Arc<Signals>> {
        let make = || self.coarse(COARSE_STEP_S).map(std::sync::Arc::new);
        if self.len() > COARSE_SHARED_ROWS {
            return make();
        }
        self.coarse_steps.get_or_init(make).clone()
    }

    /// The same ride in steps of about `step_s` seconds: rows merged in runs
    /// that end on every fix's row (each fix keeps its time and place) and on
    /// the last row. A merged step `J` of rows `a+1..=b` carries what they
    /// carried: `dt_J = t_b - t_a`, the distance `d_J = sum d_j`, the mean
    /// rate `w_J = sum w_j dt_j / dt_J` (so the heading it turns through,
    /// `w_J dt_J`, is theirs exactly; the rotation's composition and the path
    /// travelled along the step's end heading err by `O(|w|^2 dt_J^2)` and
    /// `O(d_J |w| dt_J)`), and each channel's mean over the same weights.
    ///
    /// Step 1's windows only have to bring the fit into the right basin
    /// (the whole ride, swept at the log's own rate, then settles it): on
    /// these they cost a tenth of the log's rows. `None` where the log's own
    /// steps are not at least twice shorter, or merging would leave fewer
    /// than a hundred rows.
    pub fn coarse(&self, step_s: f64) -> Option<Self> {
        let n = self.len();
        let rate = median_rate_hz(&self.t);
        let every = (step_s * rate).floor();
        // A rate that is not a number merges nothing either.
        if every.is_nan() || every < 2.0 || n < 200 {
            return None;
        }
        let every = every as usize;
        let mut ends = Vec::with_capacity(n / every + self.fixes.len() + 2);
        ends.push(0);
        let mut last = 0;
        for j in 1..n {
            if j - last >= every || self.fix_at_row[j] != NO_FIX || j + 1 == n {
                ends.push(j);
                last = j;
            }
        }
        if ends.len() < 100 {
            return None;
        }
        let m = ends.len();
        let (mut t, mut dt) = (Vec::with_capacity(m), Vec::with_capacity(m));
        let (mut gyro, mut distance) = (Vec::with_capacity(m), Vec::with_capacity(m));
        let mut channels: Vec<(String, Vec<f64>)> = self
            .channels
            .iter()
            .map(|(name, _)| (name.clone(), Vec::with_capacity(m)))
            .collect();
        let mut fix_at_row = vec![NO_FIX; m];
        let mut fixes = self.fixes.clone();
        for (k, &b) in ends.iter().enumerate() {
            let a = if k == 0 { 0 } else { ends[k - 1] + 1 };
            let span: f64 = self.dt[a..=b].iter().sum();
            // Weights of the merged rows: their steps' lengths, or equal
            // where the steps have none (row 0, repeated times).
            let weight = |j: usize| {
                if span > 0.0 {
                    self.dt[j] / span
                } else {
                    1.0 / (b + 1 - a) as f64
                }
            };
            t.push(self.t[b]);
            dt.push(span);
            gyro.push((a..=b).map(|j| self.gyro[j] * weight(j)).sum());
            distance.push(self.distance[a..=b].iter().sum());
            for ((_, out), (_, v)) in channels.iter_mut().zip(&self.channels) {
                out.push((a..=b).map(|j| v[j] * weight(j)).sum());
            }
            fix_at_row[k] = self.fix_at_row[b];
        }
        // Every fix's row ends a merged step.
        for f in &mut fixes {
            f.row = ends.partition_point(|&e| e < f.row);
        }
        Some(Self {
            source: self.source.clone(),
            t,
            dt,
            gyro,
            distance,
            fixes,
            fix_at_row,
            frame: self.frame.clone(),
            has_baro: self.has_baro,
            has_gps_alt: self.has_gps_alt,
            has_gnss_speed: self.has_gnss_speed,
            gyro_stops: self.gyro_stops.clone(),
            log_gaps: self.log_gaps.clone(),
            sensor_turns: self.sensor_turns.clone(),
            channels,
            odometer: self.odometer.clone(),
            attitude: self.attitude.clone(),
            warnings: self.warnings.clone(),
            t0_unix_s: self.t0_unix_s,
            t0_boot_s: self.t0_boot_s,
            gap_spread: std::sync::OnceLock::new(),
            coarse_steps: std::sync::OnceLock::new(),
        })
    }

    /// Values of an extra channel by name.
    pub fn channel(&self, name: &str) -> Option<&[f64]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }
}

/// How fast a sensor turns (deg/s, the norm of its rates in deg/s): with
/// the GNSS speed, whether a vehicle stands.
pub fn turn_rate_dps(g: &[f64; 3]) -> f64 {
    (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt()
}

/// Per-step odometer distance of a log, from whichever odometer it has
/// (cumulative distance, then speed, then wheel pulses, then the GNSS speed,
/// which also needs `rate_dps`, the gyro's rates at row `j` in deg/s as
/// logged, to tell a stop; asked only there, so no other log pays for it),
/// and which it was.
pub fn odometer_distance(
    log: &RideLog,
    rate_dps: impl Fn(usize) -> [f64; 3],
) -> Result<(Vec<f64>, Odometer), SignalError> {
    odometer_distance_and_jumps(log, rate_dps).0
}

/// [`odometer_distance`], and the readings of the column it takes the
/// distance from that are no distance, as it mends them (see
/// [`crate::odometer_jumps`]; said whether or not a distance comes of it).
pub fn odometer_distance_and_jumps(
    log: &RideLog,
    rate_dps: impl Fn(usize) -> [f64; 3],
) -> (
    Result<(Vec<f64>, Odometer), SignalError>,
    crate::odometer_jumps::Jumps,
) {
    use crate::odometer_jumps::{Jumps, cumulative, speed};
    if let Some(odo) = &log.odo_m {
        let kind = match log.metadata.get("odometer") {
            Some(from) => Odometer::Merged { from: from.clone() },
            None => Odometer::Cumulative,
        };
        let (odo, jumps) = cumulative(&log.t_s, odo);
        (distance_from_odometer(&odo, log).map(|d| (d, kind)), jumps)
    } else if let Some(v) = &log.speed_mps {
        let (v, jumps) = speed("speed_mps", v);
        (
            distance_from_speed(&v, log).map(|d| (d, Odometer::Speed)),
            jumps,
        )
    } else if let Some(pulses) = &log.wheel_pulse {
        let distance = log
            .wheel_circumference_m()
            .and_then(|s| s.parse::<f64>().ok())
            .ok_or_else(|| SignalError::Unusable {
                file: log.source.clone(),
                message: "wheel_circumference_m is missing".into(),
            })
            .map(|c| {
                let (d, revolutions) = distance_from_pulses(&log.t_s, pulses, c);
                (
                    d,
                    Odometer::WheelPulses {
                        circumference_m: c,
                        revolutions,
                    },
                )
            });
        (distance, Jumps::default())
    } else if let Some(v) = &log.gps_speed_mps {
        let (v, jumps) = speed("gps_speed_mps", v);
        (distance_from_gnss_speed(&v, log, rate_dps), jumps)
    } else {
        (
            Err(SignalError::Unusable {
                file: log.source.clone(),
                message: "the log has no distance column".into(),
            }),
            Jumps::default(),
        )
    }
}

/// Per-step distance from a signed speed: the trapezoid
/// `d_j = (v_{j-1} + v_j) / 2 * dt_j` (a speed is an instantaneous sample);
/// empty fields are interpolated. Negative speed is reversing: the path moves backwards.
fn distance_from_speed(speed: &[Option<f64>], log: &RideLog) -> Result<Vec<f64>, SignalError> {
    let v = filled_column(speed, log, "speed_mps")?;
    let mut d = vec![0.0; v.len()];
    for j in 1..v.len() {
        d[j] = 0.5 * (v[j - 1] + v[j]) * (log.t_s[j] - log.t_s[j - 1]);
    }
    Ok(d)
}

/// Consecutive GNSS speed samples further apart than this (s) leave a gap
/// (a receiver reports at 1-18 Hz; a missed sample or two is not a gap).
pub const GNSS_SPEED_GAP_S: f64 = 2.5;

/// Per-step distance from the GNSS receiver's ground speed, for a log with
/// no wheel sensor. The speed (a Doppler measurement, far better than
/// differenced positions) is interpolated linearly between its samples to
/// every row and integrated by trapezoids, `d_j = (v_{j-1} + v_j) / 2 dt_j`,
/// except on steps where the vehicle stands (both ends slower than
/// [`STANDING_SPEED_MPS`] and the gyro below
/// [`STANDING_RATE_DPS`]), which
/// get none. Before the first and after the last sample the speed is held.
/// Gaps longer than [`GNSS_SPEED_GAP_S`] are bridged the same way and
/// listed: there the distance is a guess the fit's gain cannot correct, so
/// each gap's distance is a parameter of the fit (`effects::GnssGaps`).
/// Inside a gap, where the gyro's shaking says the vehicle stood (see
/// [`crate::standing`]), the speed is zero, and interpolated between the
/// gap's ends and the stand's.
pub fn distance_from_gnss_speed(
    speed: &[Option<f64>],
    log: &RideLog,
    rate_dps: impl Fn(usize) -> [f64; 3],
) -> Result<(Vec<f64>, Odometer), SignalError> {
    let samples: Vec<usize> = (0..speed.len()).filter(|&i| speed[i].is_some()).collect();
    if samples.len() < 2 {
        return Err(SignalError::Field {
            file: log.source.clone(),
            line: log.line.first().copied().unwrap_or(0),
            column: "gps_speed_mps".into(),
            message: format!(
                "the log has no wheel sensor and {} GNSS speed sample(s): at least two are needed to integrate a distance",
                samples.len()
            ),
        });
    }
    let t = &log.t_s;
    // The samples either side of each gap, and its times.
    let gap_samples: Vec<(usize, usize)> = samples
        .windows(2)
        .map(|w| (w[0], w[1]))
        .filter(|&(i, k)| t[k] - t[i] > GNSS_SPEED_GAP_S)
        .collect();
    let gaps: Vec<(f64, f64)> = gap_samples.iter().map(|&(i, k)| (t[i], t[k])).collect();
    let mut v = fill_gaps(speed);
    let mut stands_in_gaps = Vec::new();
    let mut stand_rule = None;
    if !gaps.is_empty() {
        let mut activity = crate::standing::activity(t, &rate_dps);
        // Rows filled across a gap in the log carry no shaking of their
        // own: they are not told to stand.
        for rows in &log.filled {
            if let Some(a) = activity.get_mut(rows.clone()) {
                a.fill(f64::NAN);
            }
        }
        let mut in_gap = vec![false; t.len()];
        for &gap in &gaps {
            in_gap[crate::standing::gap_rows(t, gap)].fill(true);
        }
        stand_rule = crate::standing::stand_rule(t, &v, &activity, &in_gap);
        if let Some(rule) = &stand_rule {
            let rows = crate::standing::stands_in_gaps(t, &activity, &gaps, rule);
            if !rows.is_empty() {
                let ramps = crate::standing::ramps(t, &v, &in_gap);
                let mut known = speed.to_vec();
                for &(first, last) in &rows {
                    known[first..=last].fill(Some(0.0));
                    stands_in_gaps.push((t[first], t[last]));
                }
                // Stands lie inside gaps, so only the gaps' samples bound them.
                for &(i, k) in &gap_samples {
                    let (a, b) = (t[i], t[k]);
                    let inside: Vec<(f64, f64)> = stands_in_gaps
                        .iter()
                        .copied()
                        .filter(|&(s, e)| s > a && e < b)
                        .collect();
                    if inside.is_empty() {
                        continue;
                    }
                    let knots = crate::standing::gap_knots((a, v[i]), (b, v[k]), &inside, ramps);
                    for (x, speed) in knots {
                        let j = t.partition_point(|&y| y < x);
                        if j > i && j < k && known[j].is_none() {
                            known[j] = Some(speed);
                        }
                    }
                }
                v = fill_gaps(&known);
            }
        }
    }
    let still = |j: usize| turn_rate_dps(&rate_dps(j)) < STANDING_RATE_DPS;
    let mut d = vec![0.0; v.len()];
    let mut standing_s = 0.0;
    for j in 1..v.len() {
        let dt = t[j] - t[j - 1];
        let stopped = v[j - 1] == 0.0 && v[j] == 0.0;
        if stopped || (v[j - 1] < STANDING_SPEED_MPS && v[j] < STANDING_SPEED_MPS && still(j)) {
            standing_s += dt;
        } else {
            d[j] = 0.5 * (v[j - 1] + v[j]) * dt;
        }
    }
    Ok((
        d,
        Odometer::GnssSpeed {
            samples: samples.len(),
            standing_s,
            gaps,
            stands_in_gaps,
            stand_rule,
        },
    ))
}

/// Per-step distance from a cumulative odometer; empty fields are interpolated.
/// Signed: an odometer that counts down is reversing (the path moves
/// backwards), and the sub-millimetre jitter of one at a standstill is noise.
fn distance_from_odometer(odo: &[Option<f64>], log: &RideLog) -> Result<Vec<f64>, SignalError> {
    let filled = filled_column(odo, log, "odo_m")?;
    let mut d = vec![0.0; filled.len()];
    for j in 1..filled.len() {
        d[j] = filled[j] - filled[j - 1];
    }
    Ok(d)
}

/// A column with its empty fields interpolated; one empty on every row is an error naming it.
fn filled_column(
    values: &[Option<f64>],
    log: &RideLog,
    column: &str,
) -> Result<Vec<f64>, SignalError> {
    if values.iter().all(Option::is_none) {
        return Err(SignalError::Field {
            file: log.source.clone(),
            line: log.line[0],
            column: column.into(),
            message: "the column is empty on every row".into(),
        });
    }
    Ok(fill_gaps(values))
}

/// Linear interpolation over empty fields; ends are held at the nearest value.
pub fn fill_gaps(v: &[Option<f64>]) -> Vec<f64> {
    let mut out = vec![0.0; v.len()];
    let known: Vec<usize> = (0..v.len()).filter(|&i| v[i].is_some()).collect();
    let Some((&first, &last)) = known.first().zip(known.last()) else {
        return out;
    };
    let value = |i: usize| v[i].unwrap_or(0.0);
    for o in out.iter_mut().take(first) {
        *o = value(first);
    }
    for w in known.windows(2) {
        let (a, b) = (w[0], w[1]);
        for (i, o) in out.iter_mut().enumerate().take(b + 1).skip(a) {
            let s = (i - a) as f64 / (b - a) as f64;
            *o = value(a) + s * (value(b) - value(a));
        }
    }
    for o in out.iter_mut().skip(last) {
        *o = value(last);
    }
    out
}

/// Gaps found in the sample times.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Gaps {
    pub count: usize,
    /// A step longer than this is a gap (s): 5 median sample intervals.
    pub limit_s: f64,
    /// Row ending the longest gap and its length (s).
    pub longest: Option<(usize, f64)>,
}

/// The rate to integrate over each step `(t_{j-1}, t_j]`.
///
/// The format says a row holds the mean rate over its step; loggers that
/// store instantaneous samples instead (`# gyro_samples: instantaneous`) get
/// the trapezoid mean `(omega_{j-1} + omega_j) / 2`, which is exact for a
/// rate linear over the step. A gap (a step longer than five median sample
/// intervals: dropped samples) is never integrated with the one sample after
/// it held over the whole gap: the trapezoid between the samples either side
/// is used there whatever the sample kind.
pub fn step_rates(
    mut rates: Vec<Vector3<f64>>,
    dt: &[f64],
    instantaneous: bool,
) -> (Vec<Vector3<f64>>, Gaps) {
    let mut sorted: Vec<f64> = dt.iter().skip(1).copied().collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let limit = 5.0 * median;
    let mut gaps = Gaps {
        limit_s: limit,
        ..Gaps::default()
    };
    // In place, last row first, so that row j - 1 is still the raw sample
    // when row j is averaged with it (a long log is not copied).
    for j in (1..rates.len()).rev() {
        let gap = dt[j] > limit;
        if gap {
            gaps.count += 1;
            if gaps.longest.is_none_or(|(_, l)| dt[j] >= l) {
                gaps.longest = Some((j, dt[j]));
            }
        }
        if gap || instantaneous {
            rates[j] = (rates[j - 1] + rates[j]) * 0.5;
        }
    }
    (rates, gaps)
}

/// A gap between wheel revolutions longer than this (s) is taken as a stop.
const STOP_GAP_S: f64 = 3.0;

/// Per-step distance from reed-switch states.
///
/// Each rising edge is one revolution of `circumference` metres. The
/// cumulative distance is known exactly at the edges (`k c` at edge `k`) and is
/// interpolated linearly in time between them, which spreads each revolution
/// over the time it took and adds no lag. A gap longer than [`STOP_GAP_S`] is a
/// stop: the revolution before it is spread at the speed of the revolution
/// before (slowing down), the one after at the speed of the revolution after
/// (pulling away), and the time in between gets no distance. Before the first
/// and after the last edge no distance is counted (at most one revolution).
/// Returns the distances and the number of revolutions.
pub fn distance_from_pulses(t: &[f64], pulses: &[bool], circumference: f64) -> (Vec<f64>, usize) {
    let n = t.len();
    let edges: Vec<usize> = (1..n).filter(|&j| pulses[j] && !pulses[j - 1]).collect();
    // Knots of the cumulative distance curve s(t): (time, distance).
    let mut knots: Vec<(f64, f64)> = Vec::with_capacity(edges.len() * 2);
    for (k, &e) in edges.iter().enumerate() {
        let te = t[e];
        let s = k as f64 * circumference;
        if let Some(&(tp, sp)) = knots.last()
            && te - tp > STOP_GAP_S
        {
            // Stop between the previous edge and this one.
            let before = if k >= 2 {
                t[edges[k - 1]] - t[edges[k - 2]]
            } else {
                STOP_GAP_S
            };
            let after = edges.get(k + 1).map_or(STOP_GAP_S, |&nx| t[nx] - te);
            let slow = before.min(STOP_GAP_S) / 2.0;
            let start = after.min(STOP_GAP_S) / 2.0;
            knots.push((tp + slow, sp + circumference / 2.0));
            knots.push((te - start, sp + circumference / 2.0));
        }
        knots.push((te, s));
    }
    // Cumulative distance at each row by interpolating the knots.
    let mut cum = vec![0.0; n];
    let mut k = 0usize;
    for j in 0..n {
        let tj = t[j];
        while k + 1 < knots.len() && knots[k + 1].0 <= tj {
            k += 1;
        }
        cum[j] = if knots.is_empty() || tj <= knots[0].0 {
            0.0
        } else if k + 1 >= knots.len() {
            knots[knots.len() - 1].1
        } else {
            let (t0, s0) = knots[k];
            let (t1, s1) = knots[k + 1];
            s0 + (s1 - s0) * (tj - t0) / (t1 - t0)
        };
    }
    let mut d = vec![0.0; n];
    for j in 1..n {
        d[j] = cum[j] - cum[j - 1];
    }
    (d, edges.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The coarse ride carries what the log's rows carried: the same span,
    /// distance, turn (`sum w dt`, per axis) and channel integrals, every fix
    /// on a merged row at its own time, and steps of about the length asked
    /// for. A 20 Hz log is not merged at 0.1 s, a 100 Hz one in tens.
    #[test]
    fn the_coarse_ride_keeps_time_distance_turn_and_fixes() {
        let sig = crate::testing::simulated_signals(5, 300.0, &[]);
        assert!(sig.channel("temp_c").is_some());
        let coarse = sig.coarse(0.1).expect("a 100 Hz log merges");
        assert!(coarse.len() * 8 < sig.len() && coarse.len() * 12 > sig.len());
        assert_eq!(coarse.t[0], sig.t[0]);
        assert_eq!(coarse.t.last(), sig.t.last());
        let total = |s: &Signals| s.distance.iter().sum::<f64>();
        assert!((total(&coarse) - total(&sig)).abs() < 1e-9 * total(&sig));
        let turn =
            |s: &Signals| -> Vector3<f64> { s.gyro.iter().zip(&s.dt).map(|(w, dt)| w * *dt).sum() };
        assert!((turn(&coarse) - turn(&sig)).norm() < 1e-9);
        for w in coarse.t.windows(2) {
            assert!(w[1] > w[0] && w[1] - w[0] <= 0.1 + 1e-9, "{w:?}");
        }
        for ((name, a), (_, b)) in coarse.channels.iter().zip(&sig.channels) {
            let integral =
                |s: &Signals, v: &[f64]| -> f64 { v.iter().zip(&s.dt).map(|(x, dt)| x * dt).sum() };
            let (ia, ib) = (integral(&coarse, a), integral(&sig, b));
            assert!(
                (ia - ib).abs() < 1e-9 * ib.abs().max(1.0),
                "{name}: {ia} {ib}"
            );
        }
        assert_eq!(coarse.fixes.len(), sig.fixes.len());
        for (k, (c, f)) in coarse.fixes.iter().zip(&sig.fixes).enumerate() {
            assert_eq!(coarse.t[c.row], sig.t[f.row]);
            assert_eq!(coarse.fix_index(c.row), Some(k));
            assert_eq!((c.t, c.en), (f.t, f.en));
        }
        let fixes = (0..coarse.len()).filter(|&j| coarse.fix_index(j).is_some());
        assert_eq!(fixes.count(), sig.fixes.len());
        let slow = Signals::from_log(&crate::testing::winding_log(60.0, 20.0)).expect("signals");
        assert!(slow.coarse(0.1).is_none());
    }

    #[test]
    fn pulses_at_constant_speed_give_constant_distance() {
        // 2 m wheel at 4 m/s: an edge every 0.5 s, 100 Hz rows.
        let t: Vec<f64> = (0..1000).map(|i| i as f64 * 0.01).collect();
        let pulses: Vec<bool> = t.iter().map(|&ti| (ti % 0.5) < 0.05 && ti > 0.2).collect();
        let (d, revs) = distance_from_pulses(&t, &pulses, 2.0);
        assert_eq!(revs, 19);
        // Between the first and last edges each step covers 4 m/s * 0.01 s.
        for (j, dj) in d.iter().enumerate().take(940).skip(60) {
            assert!((dj - 0.04).abs() < 1e-9, "row {j}: {dj}");
        }
        assert!((d.iter().sum::<f64>() - 18.0 * 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_stop_gets_no_distance() {
        // 2 m/s (1 s per 2 m revolution), stop from 10.5 s to 30 s, then 2 m/s again.
        let t: Vec<f64> = (0..5000).map(|i| i as f64 * 0.01).collect();
        let edge_times: Vec<f64> = (1..=10)
            .map(|k| k as f64)
            .chain((0..15).map(|k| 31.0 + k as f64))
            .collect();
        let pulses: Vec<bool> = t
            .iter()
            .map(|&ti| edge_times.iter().any(|&e| ti >= e - 1e-9 && ti < e + 0.03))
            .collect();
        let (d, _) = distance_from_pulses(&t, &pulses, 2.0);
        // Stopped between about 10.5 s and 30.5 s.
        let stopped: f64 = d[1100..3000].iter().sum();
        assert!(stopped.abs() < 1e-9, "moved {stopped} m while stopped");
        assert!((d.iter().sum::<f64>() - 24.0 * 2.0).abs() < 1e-9);
    }

    #[test]
    fn gaps_are_interpolated() {
        let v = [None, Some(1.0), None, Some(3.0), None];
        assert_eq!(fill_gaps(&v), vec![1.0, 1.0, 2.0, 3.0, 3.0]);
    }
}

#[cfg(test)]
mod rate_tests {
    use super::*;

    #[test]
    fn gaps_and_instantaneous_samples_use_the_trapezoid() {
        let raw: Vec<Vector3<f64>> = (0..8).map(|k| Vector3::new(0.0, 0.0, k as f64)).collect();
        let mut dt = vec![0.01; 8];
        dt[0] = 0.0;
        dt[5] = 0.5; // 49 dropped samples
        let (mean, gaps) = step_rates(raw.clone(), &dt, false);
        assert_eq!(gaps.count, 1);
        assert_eq!(gaps.longest, Some((5, 0.5)));
        assert!((gaps.limit_s - 0.05).abs() < 1e-12);
        assert_eq!(mean[4].z, 4.0);
        assert_eq!(mean[5].z, 4.5);
        let (inst, _) = step_rates(raw, &dt, true);
        assert_eq!(inst[4].z, 3.5);
        assert_eq!(inst[0].z, 0.0);
    }

    #[test]
    fn a_log_with_a_gap_warns_and_an_unknown_sample_kind_is_refused() {
        let mut log = crate::testing::winding_log(30.0, 100.0);
        let cut = 1000..1100;
        log.t_s.drain(cut.clone());
        log.line.drain(cut.clone());
        log.gyro_dps.drain(cut.clone());
        log.fix.drain(cut.clone());
        if let Some(p) = log.wheel_pulse.as_mut() {
            p.drain(cut.clone());
        }
        if let Some(o) = log.odo_m.as_mut() {
            o.drain(cut.clone());
        }
        if let Some(a) = log.gps_alt_m.as_mut() {
            a.drain(cut.clone());
        }
        if let Some(b) = log.baro_alt_m.as_mut() {
            b.drain(cut.clone());
        }
        for (_, c) in log.channels.iter_mut() {
            c.drain(cut.clone());
        }
        let sig = Signals::from_log(&log).expect("signals");
        assert!(
            sig.warnings
                .iter()
                .any(|w| w.contains("gap") && w.contains("1.01 s")),
            "{:?}",
            sig.warnings
        );
        log.metadata
            .insert("gyro_samples".into(), "sometimes".into());
        let err = Signals::from_log(&log).expect_err("bad metadata");
        assert!(err.to_string().contains("gyro_samples"), "{err}");
    }
}

#[cfg(test)]
mod owned_tests {
    use super::*;

    #[test]
    fn consuming_the_log_gives_the_same_signals() {
        let log = crate::testing::winding_log(20.0, 100.0);
        let (a, b) = (
            Signals::from_log(&log).unwrap(),
            Signals::from_owned_log(log).unwrap(),
        );
        assert_eq!(a.t, b.t);
        assert_eq!(a.dt, b.dt);
        assert_eq!(a.gyro, b.gyro);
        assert_eq!(a.distance, b.distance);
        assert_eq!(a.fixes, b.fixes);
        assert_eq!(a.warnings, b.warnings);
    }
}

#[cfg(test)]
mod attitude_tests {
    use super::*;

    #[test]
    fn yaw_rate_sensors_and_level_vehicles_are_planar_and_leaning_bicycles_3d() {
        let mut log = crate::testing::winding_log(300.0, 50.0);
        for g in &mut log.gyro_dps {
            g[0] = 0.0;
            g[1] = 0.0;
        }
        let sig = Signals::from_log(&log).unwrap();
        assert!(
            sig.attitude.describe().contains("yaw-rate sensor"),
            "{:?}",
            sig.attitude
        );
        let sim = crate::simulation::simulate(&crate::simulation::SimConfig {
            seed: 2,
            duration_s: 300.0,
            ..Default::default()
        })
        .unwrap();
        let bike =
            Signals::from_log(&crate::import::parse(sim.log_csv.as_bytes(), "b").unwrap()).unwrap();
        assert!(!bike.attitude.is_planar(), "{:?}", bike.attitude);
        assert!(bike.gyro.iter().any(|w| w.x != 0.0));
        // Asked for, either way.
        let mut asked = crate::import::parse(sim.log_csv.as_bytes(), "b").unwrap();
        asked.metadata.insert("attitude".into(), "planar".into());
        let planar = Signals::from_log(&asked).unwrap();
        assert!(planar.attitude.is_planar());
        assert!(planar.gyro.iter().all(|w| w.x == 0.0 && w.y == 0.0));
        asked.metadata.insert("attitude".into(), "sideways".into());
        assert!(
            Signals::from_log(&asked)
                .unwrap_err()
                .to_string()
                .contains("sideways")
        );
    }

    #[test]
    fn level_motion_measures_roll_and_pitch_over_ten_seconds() {
        // 100 Hz; roll swings +-20 deg every 4 s (a bicycle), pitch a constant bias.
        let t: Vec<f64> = (0..6000).map(|i| i as f64 * 0.01).collect();
        let rates: Vec<Vector3<f64>> = t
            .iter()
            .map(|&s| {
                let roll_rate = 20f64.to_radians()
                    * std::f64::consts::FRAC_PI_2
                    * (s * std::f64::consts::FRAC_PI_2).cos();
                Vector3::new(roll_rate, 0.01, 0.2)
            })
            .collect();
        let [roll, pitch] = level_motion(&t, &rates);
        assert!(roll > 15.0 && roll < 45.0, "{roll}");
        assert!(pitch < 1e-6, "a constant bias is no motion: {pitch}");
    }

    #[test]
    fn a_decreasing_odometer_and_a_negative_speed_are_reversing() {
        let mut log = crate::testing::winding_log(30.0, 10.0);
        let n = log.len();
        let odo: Vec<Option<f64>> = (0..n)
            .map(|j| {
                Some(if j < n / 2 {
                    j as f64
                } else {
                    (n - j) as f64 - 0.0001 * (j % 2) as f64
                })
            })
            .collect();
        log.odo_m = Some(odo);
        let (d, _) = odometer_distance(&log, |j| log.gyro_dps[j]).unwrap();
        assert!(d[1] > 0.0 && d[n - 2] < 0.0);
        assert!((d.iter().sum::<f64>() - (1.0 - 0.0001 * ((n - 1) % 2) as f64)).abs() < 1e-9);
        log.odo_m = None;
        log.speed_mps = Some(
            (0..n)
                .map(|j| Some(if j < n / 2 { 2.0 } else { -1.0 }))
                .collect(),
        );
        let (d, kind) = odometer_distance(&log, |j| log.gyro_dps[j]).unwrap();
        assert_eq!(kind, Odometer::Speed);
        assert!((d[1] - 0.2).abs() < 1e-12 && (d[n - 1] + 0.1).abs() < 1e-12);
    }

    /// A speed's invalid-value code (a CAN signal's 0xFFFF, 655.35) is no
    /// distance: read as empty, as the check and the fit's warning say;
    /// taken as a speed it put 65.5 m into one 0.1 s step.
    #[test]
    fn an_invalid_speed_code_is_read_as_an_empty_field() {
        let mut log = crate::testing::winding_log(30.0, 10.0);
        let n = log.len();
        let mut speed: Vec<Option<f64>> = vec![Some(2.0); n];
        speed[n / 2] = Some(655.35);
        log.odo_m = None;
        log.speed_mps = Some(speed);
        let (d, _) = odometer_distance(&log, |j| log.gyro_dps[j]).unwrap();
        for j in 1..n {
            let dt = log.t_s[j] - log.t_s[j - 1];
            assert!(
                (d[j] - 2.0 * dt).abs() < 1e-12,
                "row {j}: {} m in {dt} s",
                d[j]
            );
        }
        let said = odometer_distance_and_jumps(&log, |j| log.gyro_dps[j])
            .1
            .describe("r.csv", &log.line, &log.t_s)
            .expect("said");
        assert!(
            said.contains("1 speed sample faster than 100 m/s"),
            "{said}"
        );
    }

    /// A stand inside a gap of the GNSS speed, told by the gyro's shaking:
    /// the rule is learnt from a logged stand (5-20 s) and the moving outside
    /// the gap; the gap (40-70 s) stands from 50 to 60 s. The speed is held at
    /// 5 m/s until the ride's own braking (5 m/s over the 3 s before the
    /// logged stand) reaches the stand, and pulls away as the logged one did.
    #[test]
    fn a_stand_inside_a_gap_is_told_by_the_gyro() {
        let mut log = crate::testing::winding_log(80.0, 100.0);
        let n = log.len();
        let stood = |x: f64| (5.0..20.0).contains(&x) || (50.0..60.0).contains(&x);
        let speed: Vec<Option<f64>> = (0..n)
            .map(|j| {
                let x = log.t_s[j];
                (j % 100 == 0 && !(40.5..70.0).contains(&x)).then_some(if stood(x) {
                    0.0
                } else {
                    5.0
                })
            })
            .collect();
        log.odo_m = None;
        log.speed_mps = None;
        log.gps_speed_mps = Some(speed);
        for (j, g) in log.gyro_dps.iter_mut().enumerate() {
            let wobble = if j % 2 == 0 { 1.0 } else { -1.0 };
            let size = if stood(log.t_s[j]) { 0.05 } else { 3.0 };
            *g = [size * wobble, 0.0, 0.1];
        }
        let (d, kind) = odometer_distance(&log, |j| log.gyro_dps[j]).unwrap();
        let Odometer::GnssSpeed {
            gaps,
            stands_in_gaps,
            stand_rule,
            ..
        } = &kind
        else {
            panic!("{kind:?}");
        };
        assert_eq!(gaps, &vec![(40.0, 70.0)]);
        assert!(stand_rule.is_some());
        assert_eq!(stands_in_gaps.len(), 1, "{stands_in_gaps:?}");
        let (a, b) = stands_in_gaps[0];
        assert!(
            (a - 50.0).abs() <= 0.5 && (b - 60.0).abs() <= 0.5,
            "{a} {b}"
        );
        let across = |from: f64, to: f64| -> f64 {
            (0..n)
                .filter(|&j| log.t_s[j] > from && log.t_s[j] <= to)
                .map(|j| d[j])
                .sum()
        };
        assert!(across(50.6, 59.4).abs() < 1e-12);
        // 7.5 s at 5 m/s, 3 s braking, the stand, 3 s pulling away, 7.5 s
        // at 5 m/s: 90 m (straight across, 150 m).
        let gap = across(40.0, 70.0);
        assert!((gap - 90.0).abs() < 3.0, "{gap} m across the gap");
        assert!(
            kind.describe().contains("of them standing by the gyro"),
            "{}",
            kind.describe()
        );
    }

    /// A log with only the receiver's speed: sparse samples are interpolated
    /// and integrated, a stop (slow and not turning) adds nothing, a slow
    /// turn does, and a gap is listed.
    #[test]
    fn the_gnss_speed_gives_the_distance_without_a_wheel_sensor() {
        let mut log = crate::testing::winding_log(30.0, 10.0);
        let n = log.len();
        let dt = log.t_s[1] - log.t_s[0];
        // 1 Hz samples: 5 m/s, a stop from 10 to 15 s (0.1 m/s of Doppler
        // noise), none from 20 to 25 s.
        let every = (1.0 / dt).round() as usize;
        let speed: Vec<Option<f64>> = (0..n)
            .map(|j| {
                let tj = log.t_s[j];
                (j % every == 0 && !(20.5..25.0).contains(&tj)).then_some(
                    if (10.0..=15.0).contains(&tj) {
                        0.1
                    } else {
                        5.0
                    },
                )
            })
            .collect();
        log.odo_m = None;
        log.speed_mps = None;
        log.gps_speed_mps = Some(speed.clone());
        for g in &mut log.gyro_dps {
            *g = [0.05, -0.1, 0.2];
        }
        let (d, kind) = odometer_distance(&log, |j| log.gyro_dps[j]).unwrap();
        let Odometer::GnssSpeed {
            samples,
            standing_s,
            gaps,
            ..
        } = &kind
        else {
            panic!("{kind:?}");
        };
        assert_eq!(*samples, speed.iter().flatten().count());
        assert!((standing_s - 5.0).abs() < 1e-6, "{standing_s}");
        assert_eq!(gaps, &vec![(20.0, 25.0)]);
        let total: f64 = d.iter().sum();
        // 30 s at 5 m/s less the stop (5 s) and the ramps into and out of it (2 x 1 s at half speed).
        let expected = 5.0 * (log.t_s[n - 1] - 5.0 - 1.0);
        assert!(
            (total - expected).abs() < 0.5,
            "{total} m, expected {expected}"
        );
        assert!(
            kind.describe().contains("1 gaps of 5 s interpolated"),
            "{}",
            kind.describe()
        );
        // Turning while slow is not standing.
        for g in &mut log.gyro_dps {
            *g = [0.0, 0.0, 20.0];
        }
        let (turning, _) = odometer_distance(&log, |j| log.gyro_dps[j]).unwrap();
        assert!(turning.iter().sum::<f64>() > total + 0.4);
        // One sample cannot be integrated.
        log.gps_speed_mps = Some((0..n).map(|j| (j == 3).then_some(2.0)).collect());
        let e = odometer_distance(&log, |j| log.gyro_dps[j])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("gps_speed_mps") && e.contains("1 GNSS speed sample"),
            "{e}"
        );
    }
}
