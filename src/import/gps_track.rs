//! GPS fixes from a separate track of the same ride (`--gps-track`): a
//! watch's or bike computer's GPX or FIT, a phone's NMEA, a receiver's
//! `t_s,lat_deg,lon_deg` CSV. Action cameras without GPS (GoPro HERO12-13,
//! DJI, Insta360, Sony), phone loggers with their GPS off and robots whose
//! receiver logged on another machine all record the gyro alone; the fixes
//! that the method needs are in another device's file.
//!
//! **Clock.** A track on the ride's clock (CSV `t_s`) is taken as it is; a
//! UTC track (GPX, FIT, NMEA) by the ride's `t0_unix_s` (a boot-clock one
//! by `t0_boot_s`). A ride that does not say when it started (a camera
//! without GPS has no UTC time; its file's creation time is local and
//! often minutes off) is placed by the one thing both devices record: the
//! vehicle's turns. At the right offset `c` (track time minus ride time)
//! the gyro's turn about the vertical over each of the track's intervals,
//! `Y(t_{k+1} - c) - Y(t_k - c)` with `Y(t) = sum_j (w_j . u) dt_j`,
//! follows the track's change of course over it,
//! `-wrap(chi_{k+1} - chi_k)` (course clockwise, turns anticlockwise
//! positive). The offset is the peak of their correlation, searched over
//! every offset at which they share [`MIN_TURN_OVERLAP_S`], refined in steps of
//! [`FINE_STEP_S`]; a peak that is weak ([`MIN_CORRELATION`]), or that
//! another offset nearly matches ([`RIVAL_RATIO`], a route driven twice, a
//! ride that hardly turns), places nothing, and the error says how to give
//! the start instead. The vertical `u` is the accelerometer's mean (gravity)
//! where logged, else the gyro's principal axis over one-second means (a
//! vehicle turns about its vertical far more than it rolls or pitches for a
//! second), either sign.
//!
//! **Fixes.** Each track point inside the ride gives the nearest row a fix,
//! its position interpolated along the track to that row's time (points up
//! to [`MAX_POINT_GAP_S`] apart), with the height where the track has one
//! and the ground speed from the neighbouring points (the distance of a
//! ride without a wheel sensor). The ride is cut to the time the track
//! covers: a path is not fitted where nothing says where it is. Fixes the
//! log had are replaced, with a warning.

use std::path::Path;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::LoadError;
use super::reference::{Clock, ReferenceTrack, read_reference};
use crate::geodesy::{Geodetic, LocalFrame};
use crate::ride::RideLog;

/// Least time (s) the track and the ride must share.
const MIN_OVERLAP_S: f64 = 10.0;

/// Least time (s) they must share to be placed by the turns, and at least
/// half of the shorter one: a turn or two match anywhere by chance.
const MIN_TURN_OVERLAP_S: f64 = 30.0;

/// Least track points inside the ride.
const MIN_FIXES: usize = 10;

/// Track points further apart (s) are not interpolated between, nor
/// differenced into a speed or course: a gap in the track.
const MAX_POINT_GAP_S: f64 = 2.5;

/// Least time (s) between the track points whose course changes are
/// compared with the gyro's turns.
const MIN_TURN_STEP_S: f64 = 0.9;

/// Slowest speed (m/s) at which a track's course is read: below it a few
/// metres of GPS noise turn the course at random.
const MIN_COURSE_SPEED_MPS: f64 = 2.0;

/// A course change over one interval is read at most this (rad): a
/// glitch's half-turn does not swamp the correlation.
const MAX_TURN_RAD: f64 = 1.5;

/// Steps (s) of the offset search and of its refinement around the peak
/// (+-[`FINE_SPAN_S`]).
const COARSE_STEP_S: f64 = 0.5;
const FINE_STEP_S: f64 = 0.02;
const FINE_SPAN_S: f64 = 1.0;

/// The coarse pass compares at most about this many interval pairs in all
/// (longer searches use every k-th interval; the refinement uses all).
const MAX_COARSE_PAIRS: f64 = 6e7;

/// Least correlation of the turns at the offset found.
const MIN_CORRELATION: f64 = 0.5;

/// Another offset at least [`RIVAL_S`] away whose correlation is above this
/// share of the best makes the placement ambiguous.
const RIVAL_RATIO: f64 = 0.8;
const RIVAL_S: f64 = 20.0;

/// Least track intervals with a readable course that the ride shares at the
/// offset found, and least turning (rad) over them.
const MIN_INTERVALS: usize = 30;
const MIN_TURNING_RAD: f64 = std::f64::consts::FRAC_PI_2;

/// A clock that puts the track further (s) from where the turns put it is
/// said to be off.
const CLOCKS_AGREE_S: f64 = 1.0;

/// A time difference as a reader takes it in: seconds, or hours, minutes
/// and seconds.
fn duration(s: f64) -> String {
    let sign = if s < 0.0 { "-" } else { "+" };
    let a = s.abs();
    if a < 120.0 {
        format!("{sign}{a:.1} s")
    } else {
        let whole = a.round() as u64;
        format!(
            "{sign}{} h {:02} min {:02} s",
            whole / 3600,
            whole / 60 % 60,
            whole % 60
        )
    }
}

/// Where a track falls on a ride's clock, found from the turns.
#[derive(Clone, Debug, PartialEq)]
pub struct TurnClock {
    /// Track time minus ride time (s).
    pub offset_s: f64,
    /// Correlation of the gyro's turns with the track's at that offset.
    pub correlation: f64,
    /// The best other offset at least [`RIVAL_S`] away, and its correlation.
    pub rival: Option<(f64, f64)>,
    /// Track intervals compared at the offset found.
    pub intervals: usize,
    /// Which vertical the gyro's turns were read about.
    pub vertical: String,
}

/// Read `path` as a track and give `log` its fixes (see the module
/// documentation).
pub fn merge_track(log: &mut RideLog, path: &Path) -> Result<(), LoadError> {
    let track = read_reference(path)?;
    merge(log, track, &path.display().to_string())
}

/// [`merge_track`] of a track read from `file`.
fn merge(log: &mut RideLog, track: ReferenceTrack, file: &str) -> Result<(), LoadError> {
    let error = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let (Some(&ride_first), Some(&ride_last)) = (log.t_s.first(), log.t_s.last()) else {
        return Err(error(format!("{} has no rows", log.source)));
    };
    if track.t_s.len() < MIN_FIXES {
        return Err(error(format!(
            "the track holds {} point(s): at least {MIN_FIXES} are needed",
            track.t_s.len()
        )));
    }
    log.warnings.extend(track.warnings.iter().cloned());
    let t0_unix = log.t0_unix_s();
    let t0_boot = log.metadata.get("t0_boot_s").and_then(|v| v.parse().ok());
    let placed_by_clock = match track.clock {
        Clock::Ride => true,
        Clock::Unix | Clock::TimeOfDay => t0_unix.is_some(),
        Clock::Boot => t0_boot.is_some(),
    };
    let clock = track.clock;
    let (track, how) = if placed_by_clock {
        let how = match clock {
            Clock::Ride => "on the ride's clock".to_string(),
            Clock::Boot => "by the ride's boot-clock start".to_string(),
            _ => "by UTC".to_string(),
        };
        // The turns' own placement, where they can tell one, checks the two
        // clocks against each other: a camera's clock in local time, a
        // logger's drifted clock.
        let turns = (clock != Clock::Ride)
            .then(|| turn_clock(log, &track).ok())
            .flatten();
        let raw_first = track.t_s[0];
        let track = track.on_ride_clock(t0_unix, t0_boot, &log.source)?;
        let by_clock = raw_first - track.t_s[0];
        let (first, last) = (track.t_s[0], track.t_s[track.t_s.len() - 1]);
        if let Some(turns) = turns.filter(|t| (t.offset_s - by_clock).abs() > CLOCKS_AGREE_S) {
            let apart = turns.offset_s - by_clock;
            let (name, start) = if clock == Clock::Boot {
                ("t0_boot_s", t0_boot)
            } else {
                ("t0_unix_s", t0_unix)
            };
            let shared = last.min(ride_last) - first.max(ride_first);
            let what = format!(
                "the vehicle's turns put {file} {} from where the ride's start puts it (correlation {:.2}): one of the two clocks is off (a camera's local time, a time zone, a drifted clock)",
                duration(apart),
                turns.correlation
            );
            if shared < MIN_OVERLAP_S {
                return Err(error(format!(
                    "{what}; placed by the ride's start, the two share {:.0} s. If the turns are right, the ride's start is {name} {:.3} ('# {name}:' in the log)",
                    shared.max(0.0),
                    start.map_or(turns.offset_s, |t0| t0 + apart)
                )));
            }
            log.warnings.push(format!(
                "{}: {what}; the fixes are placed by the ride's start as given",
                log.source
            ));
        }
        (track, how)
    } else {
        let turns = turn_clock(log, &track).map_err(|why| {
            error(format!(
                "its times are {}, and {} does not say when it started (no t0_unix_s), so the track is placed on the ride's clock by the vehicle's turns; {why}. Give the ride log a '# t0_unix_s:' line, or the track as t_s,lat_deg,lon_deg CSV on the ride's clock",
                if clock == Clock::Boot { "a device's boot clock" } else { "UTC" },
                log.source
            ))
        })?;
        if clock == Clock::Unix {
            log.metadata
                .insert("t0_unix_s".into(), format!("{:.3}", turns.offset_s));
        }
        let mut track = track;
        for t in &mut track.t_s {
            *t -= turns.offset_s;
        }
        track.clock = Clock::Ride;
        log.warnings.push(format!(
            "{}: {file} is placed on the ride's clock by the vehicle's turns: the gyro's turns about {} follow the track's course at {} (correlation {:.2} over {} of its intervals{}); a latency of the camera's gyro or of the track shifts the fixes along the path (0.1 s is {:.1} m at the ride's mean speed): give '# t0_unix_s:' where the start is known",
            log.source,
            turns.vertical,
            if clock == Clock::Unix {
                format!("t0_unix_s {:.2}", turns.offset_s)
            } else {
                format!("an offset of {:.2} s", turns.offset_s)
            },
            turns.correlation,
            turns.intervals,
            match turns.rival {
                Some((at, r)) => format!(", the next best {r:.2} at {:+.0} s from it", at - turns.offset_s),
                None => String::new(),
            },
            0.1 * mean_speed(&track)
        ));
        (track, "by the vehicle's turns".to_string())
    };
    let (first, last) = (track.t_s[0], track.t_s[track.t_s.len() - 1]);
    let (start, end) = (first.max(ride_first), last.min(ride_last));
    if end - start < MIN_OVERLAP_S {
        return Err(error(format!(
            "the track ({first:.0}-{last:.0} s on the ride's clock, placed {how}) and {} ({ride_first:.0}-{ride_last:.0} s) share {:.0} s; at least {MIN_OVERLAP_S:.0} s are needed: is it the same ride?",
            log.source,
            (end - start).max(0.0)
        )));
    }
    log.cut_to(start, end, file);
    let replaced = log.fix_count();
    if replaced > 0 {
        log.warnings.push(format!(
            "{}: its own {replaced} fixes are replaced by {file}'s",
            log.source
        ));
    }
    let n = log.len();
    log.fix = vec![None; n];
    for column in [
        &mut log.gps_course_deg,
        &mut log.gps_hacc_m,
        &mut log.gps_vacc_m,
        &mut log.gps_hdop,
        &mut log.gps_num_sats,
    ] {
        *column = None;
    }
    let mut alt = track.has_alt.then(|| vec![None; n]);
    let mut speed = vec![None; n];
    let (frame, en) = horizontal(&track);
    let mut placed = 0;
    for (k, &tk) in track.t_s.iter().enumerate() {
        if tk < start || tk > end {
            continue;
        }
        let j = nearest(&log.t_s, tk);
        if log.fix[j].is_some() {
            continue;
        }
        let t = log.t_s[j];
        let (a, b) = if t >= tk {
            (k, (k + 1).min(track.t_s.len() - 1))
        } else {
            (k.saturating_sub(1), k)
        };
        let span = track.t_s[b] - track.t_s[a];
        let (point, height) = if b > a && span <= MAX_POINT_GAP_S {
            let w = ((t - track.t_s[a]) / span).clamp(0.0, 1.0);
            let (ha, hb) = (track.points[a].alt_m, track.points[b].alt_m);
            (
                frame.to_geodetic(&(en[a] + (en[b] - en[a]) * w)),
                ha + (hb - ha) * w,
            )
        } else {
            (track.points[k], track.points[k].alt_m)
        };
        log.fix[j] = Some((point.lat_deg, point.lon_deg));
        if let Some(alt) = &mut alt {
            alt[j] = height.is_finite().then_some(height);
        }
        speed[j] = ground_velocity(&track.t_s, &en, k).map(|v| v.norm());
        placed += 1;
    }
    if placed < MIN_FIXES {
        return Err(error(format!(
            "{placed} of its points fall inside {}: at least {MIN_FIXES} are needed",
            log.source
        )));
    }
    if alt.is_none() {
        log.warnings.push(format!(
            "{}: {file} gives no heights: the path's heights are {}",
            log.source,
            if log.baro_alt_m.is_some() {
                "the barometer's, from an unknown start"
            } else {
                "not measured"
            }
        ));
    }
    log.gps_alt_m = alt;
    log.gps_speed_mps = Some(speed);
    log.metadata
        .insert("gps".into(), format!("{file}, placed {how}"));
    log.warnings.push(format!(
        "{}: the GPS fixes are {file}'s ({placed} points, placed {how}; ground speed from its positions)",
        log.source
    ));
    Ok(())
}

/// Index of the row nearest time `t` in increasing `times`.
fn nearest(times: &[f64], t: f64) -> usize {
    let i = times.partition_point(|&x| x < t);
    if i == 0 {
        0
    } else if i >= times.len() || t - times[i - 1] < times[i] - t {
        (i - 1).min(times.len() - 1)
    } else {
        i
    }
}

/// The track's horizontal velocity (east, north; m/s) at point `k`, by
/// central difference (one-sided at an end or a gap); `None` where both
/// neighbours are more than [`MAX_POINT_GAP_S`] away.
fn ground_velocity(t: &[f64], en: &[Vector3<f64>], k: usize) -> Option<Vector3<f64>> {
    let near = |i: usize| (t[i] - t[k]).abs() <= MAX_POINT_GAP_S;
    let a = if k > 0 && near(k - 1) { k - 1 } else { k };
    let b = if k + 1 < t.len() && near(k + 1) {
        k + 1
    } else {
        k
    };
    (b > a).then(|| {
        let mut v = (en[b] - en[a]) / (t[b] - t[a]);
        v.z = 0.0;
        v
    })
}

/// The track's points in a local frame at its first, east and north (m),
/// heights left out (a track may have none).
fn horizontal(track: &ReferenceTrack) -> (LocalFrame, Vec<Vector3<f64>>) {
    let flat = |p: &Geodetic| Geodetic::new(p.lat_deg, p.lon_deg, 0.0);
    let frame = LocalFrame::new(flat(&track.points[0]));
    let en = track
        .points
        .iter()
        .map(|p| frame.to_enu(&flat(p)))
        .collect();
    (frame, en)
}

/// The track's mean ground speed (m/s) over its points.
fn mean_speed(track: &ReferenceTrack) -> f64 {
    let (_, en) = horizontal(track);
    let length: f64 = en
        .windows(2)
        .zip(track.t_s.windows(2))
        .filter(|(_, t)| t[1] - t[0] <= MAX_POINT_GAP_S)
        .map(|(p, _)| (p[1] - p[0]).xy().norm())
        .sum();
    let time: f64 = track
        .t_s
        .windows(2)
        .map(|t| t[1] - t[0])
        .filter(|&d| d <= MAX_POINT_GAP_S)
        .sum();
    if time > 0.0 { length / time } else { 0.0 }
}

/// The track's turns: each interval between two points with a readable
/// course at both ends, as its start and end time and the course's change
/// over it, anticlockwise positive (rad).
fn track_turns(track: &ReferenceTrack) -> Vec<(f64, f64, f64)> {
    let (_, en) = horizontal(track);
    // A faster track (5-20 Hz) is read a point per second or so: between
    // points a fifth of a second apart, a receiver's decimetres of noise
    // are a chord's whole length.
    let mut kept: Vec<usize> = Vec::with_capacity(en.len());
    for k in 0..en.len() {
        if kept
            .last()
            .is_none_or(|&j| track.t_s[k] - track.t_s[j] >= MIN_TURN_STEP_S)
        {
            kept.push(k);
        }
    }
    let t: Vec<f64> = kept.iter().map(|&k| track.t_s[k]).collect();
    let en: Vec<Vector3<f64>> = kept.iter().map(|&k| en[k]).collect();
    let course: Vec<Option<f64>> = (0..en.len())
        .map(|k| {
            ground_velocity(&t, &en, k)
                .filter(|v| v.norm() >= MIN_COURSE_SPEED_MPS)
                .map(|v| v.x.atan2(v.y))
        })
        .collect();
    (0..en.len().saturating_sub(1))
        .filter(|&k| t[k + 1] - t[k] <= MAX_POINT_GAP_S)
        .filter_map(|k| {
            let (a, b) = (course[k]?, course[k + 1]?);
            let turn = -crate::rotation::wrap_pi(b - a);
            Some((t[k], t[k + 1], turn.clamp(-MAX_TURN_RAD, MAX_TURN_RAD)))
        })
        .collect()
}

/// The verticals to read the gyro's turns about, each named: gravity's
/// direction where the log has an accelerometer (one sign), else the
/// gyro's principal axis over one-second means (either sign).
fn verticals(log: &RideLog) -> Vec<(Vector3<f64>, String)> {
    if let Some(accel) = &log.accel_mps2 {
        let (sum, count) = accel
            .iter()
            .flatten()
            .fold((Vector3::zeros(), 0usize), |(s, c), a| {
                (s + Vector3::from(*a), c + 1)
            });
        let mean = sum / count.max(1) as f64;
        if count >= 100 && (5.0..15.0).contains(&mean.norm()) {
            return vec![(
                mean.normalize(),
                "gravity's direction (the accelerometer's mean)".into(),
            )];
        }
    }
    let mut moment = Matrix3::zeros();
    let mut block = (
        Vector3::zeros(),
        0.0,
        log.t_s.first().copied().unwrap_or(0.0),
    );
    for (j, w) in log.gyro_dps.iter().enumerate().skip(1) {
        let dt = log.t_s[j] - log.t_s[j - 1];
        block.0 += Vector3::from(*w) * dt;
        block.1 += dt;
        if log.t_s[j] - block.2 >= 1.0 {
            let m = block.0 / block.1;
            moment += m * m.transpose();
            block = (Vector3::zeros(), 0.0, log.t_s[j]);
        }
    }
    let eigen = SymmetricEigen::new(moment);
    let k = eigen.eigenvalues.imax();
    let axis: Vector3<f64> = eigen.eigenvectors.column(k).into_owned();
    let name = |s: f64| {
        let names = ["x", "y", "z"];
        let big = axis.iamax();
        if axis[big].abs() > 0.99 {
            format!(
                "the gyro's {}{} axis",
                if s * axis[big] > 0.0 { "+" } else { "-" },
                names[big]
            )
        } else {
            format!(
                "the gyro's principal axis ({:+.2}, {:+.2}, {:+.2})",
                s * axis.x,
                s * axis.y,
                s * axis.z
            )
        }
    };
    vec![(axis, name(1.0)), (-axis, name(-1.0))]
}

/// The gyro's turn about a vertical `u` since the log's start (rad),
/// `Y(t) = sum_{t_j <= t} (w_j . u) (t_j - t_{j-1})` (a row holds the mean
/// rate since the one before), sampled every [`GRID_S`] so that the search
/// reads it at any time in O(1), whatever the log's rate.
struct Turned {
    start: f64,
    end: f64,
    y: Vec<f64>,
}

/// Step (s) of [`Turned`]'s samples: linear between them, the turn's
/// integral is exact to a fraction of a degree at any gyro rate.
const GRID_S: f64 = 0.02;

impl Turned {
    fn new(log: &RideLog, up: &Vector3<f64>) -> Self {
        let (start, end) = (log.t_s[0], log.t_s[log.len() - 1]);
        let n = ((end - start) / GRID_S).ceil() as usize + 1;
        let mut y = Vec::with_capacity(n);
        let (mut j, mut sum) = (0, 0.0);
        for k in 0..n {
            let t = start + k as f64 * GRID_S;
            // Whole rows up to t, then the part of the next row's step
            // before t at its mean rate.
            while j + 1 < log.len() && log.t_s[j + 1] <= t {
                j += 1;
                sum += Vector3::from(log.gyro_dps[j]).dot(up).to_radians()
                    * (log.t_s[j] - log.t_s[j - 1]);
            }
            let part = if j + 1 < log.len() {
                Vector3::from(log.gyro_dps[j + 1]).dot(up).to_radians() * (t - log.t_s[j]).max(0.0)
            } else {
                0.0
            };
            y.push(sum + part);
        }
        Self { start, end, y }
    }

    fn at(&self, t: f64) -> f64 {
        let u = ((t - self.start) / GRID_S).clamp(0.0, (self.y.len() - 1) as f64);
        let k = (u as usize).min(self.y.len().saturating_sub(2));
        match self.y.get(k + 1) {
            Some(&next) => self.y[k] + (next - self.y[k]) * (u - k as f64),
            None => self.y[k],
        }
    }
}

/// The correlation of the gyro's turns with the track's `turns` at
/// `offset` (every `stride`-th interval), with the intervals compared and
/// the track's turning over them.
fn correlation(
    gyro: &Turned,
    turns: &[(f64, f64, f64)],
    offset: f64,
    stride: usize,
) -> (f64, usize, f64) {
    let (first, last) = (gyro.start + offset, gyro.end + offset);
    let from = turns.partition_point(|&(a, _, _)| a < first);
    let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy, mut turning) =
        (0usize, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for &(a, b, track) in turns[from..].iter().step_by(stride.max(1)) {
        if b > last {
            break;
        }
        let turned = (gyro.at(b - offset) - gyro.at(a - offset)).clamp(-MAX_TURN_RAD, MAX_TURN_RAD);
        n += 1;
        sx += turned;
        sy += track;
        sxx += turned * turned;
        syy += track * track;
        sxy += turned * track;
        turning += track.abs();
    }
    if n < 3 {
        return (0.0, n, turning);
    }
    let nf = n as f64;
    let cov = sxy - sx * sy / nf;
    let (vx, vy) = (sxx - sx * sx / nf, syy - sy * sy / nf);
    let r = if vx > 0.0 && vy > 0.0 {
        cov / (vx * vy).sqrt()
    } else {
        0.0
    };
    (r, n, turning)
}

/// Place `track` on `log`'s clock by the vehicle's turns (see the module
/// documentation); the reason why not otherwise.
pub fn turn_clock(log: &RideLog, track: &ReferenceTrack) -> Result<TurnClock, String> {
    let turns = track_turns(track);
    let (Some(&ride_first), Some(&ride_last)) = (log.t_s.first(), log.t_s.last()) else {
        return Err("the ride has no rows".into());
    };
    let (Some(&(track_first, _, _)), Some(&(_, track_last, _))) = (turns.first(), turns.last())
    else {
        return Err(format!(
            "the track never moves at {MIN_COURSE_SPEED_MPS} m/s or more, so it shows no turns"
        ));
    };
    // Offsets at which they share little would match a turn or two by
    // chance: at least half of the shorter one is shared.
    let overlap =
        MIN_TURN_OVERLAP_S.max(0.5 * (ride_last - ride_first).min(track_last - track_first));
    let (lo, hi) = (
        track_first - ride_last + overlap,
        track_last - ride_first - overlap,
    );
    if hi < lo {
        return Err("the track is shorter than the ride's overlap needs".into());
    }
    let steps = ((hi - lo) / COARSE_STEP_S).ceil() as usize + 1;
    let ride_intervals = (ride_last - ride_first).min(track_last - track_first)
        * turns.len() as f64
        / (track_last - track_first).max(1.0);
    let stride = ((steps as f64 * ride_intervals / MAX_COARSE_PAIRS).ceil() as usize).max(1);
    let mut best: Option<(f64, f64)> = None;
    let mut vertical = String::new();
    let mut best_turned = None;
    let mut coarse = Vec::new();
    for (up, name) in verticals(log) {
        let turned = Turned::new(log, &up);
        let scores: Vec<(f64, f64)> = (0..steps)
            .map(|s| {
                let c = lo + s as f64 * COARSE_STEP_S;
                let (r, n, turning) = correlation(&turned, &turns, c, stride);
                let ok = n * stride >= MIN_INTERVALS && turning * stride as f64 >= MIN_TURNING_RAD;
                (c, if ok { r } else { f64::NEG_INFINITY })
            })
            .collect();
        if let Some(&(c, r)) = scores.iter().max_by(|a, b| a.1.total_cmp(&b.1))
            && best.is_none_or(|(_, rb)| r > rb)
        {
            best = Some((c, r));
            vertical = name;
            best_turned = Some(turned);
            coarse = scores;
        }
    }
    let (Some((coarse_c, coarse_r)), Some(turned)) =
        (best.filter(|(_, r)| r.is_finite()), best_turned)
    else {
        return Err(format!(
            "the track and the ride share too little turning (at least {MIN_INTERVALS} intervals and {:.0} deg of turns are needed)",
            MIN_TURNING_RAD.to_degrees()
        ));
    };
    let rival = coarse
        .iter()
        .filter(|(c, _)| (c - coarse_c).abs() >= RIVAL_S)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .copied()
        .filter(|(_, r)| r.is_finite());
    let fine_steps = (2.0 * FINE_SPAN_S / FINE_STEP_S).round() as usize;
    let (offset, (correlation_at, intervals, _)) = (0..=fine_steps)
        .map(|s| {
            let c = coarse_c - FINE_SPAN_S + s as f64 * FINE_STEP_S;
            (c, correlation(&turned, &turns, c, 1))
        })
        .max_by(|a, b| a.1.0.total_cmp(&b.1.0))
        .unwrap_or((coarse_c, (coarse_r, 0, 0.0)));
    if correlation_at < MIN_CORRELATION {
        return Err(format!(
            "the turns agree at best with a correlation of {correlation_at:.2}, where at least {MIN_CORRELATION} is needed (a track of another ride, or one too noisy to read turns from)"
        ));
    }
    if let Some((at, r)) = rival
        && r > RIVAL_RATIO * coarse_r
    {
        return Err(format!(
            "the turns agree about as well ({r:.2} against {coarse_r:.2}) at two offsets {:.0} s apart (a route driven twice, or too few turns to tell)",
            (at - coarse_c).abs()
        ));
    }
    Ok(TurnClock {
        offset_s: offset,
        correlation: correlation_at,
        rival,
        intervals,
        vertical,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulation::{SimConfig, simulate};

    /// A simulated ride's log (seed `seed`, 600 s) and its own fixes as a
    /// 1 Hz UTC track starting at `t0` (what a watch logged beside it).
    fn ride_and_track(seed: u64, t0: f64) -> (RideLog, ReferenceTrack) {
        let sim = simulate(&SimConfig {
            seed,
            duration_s: 600.0,
            ..SimConfig::default()
        })
        .unwrap();
        let log = sim.log("ride.csv").unwrap();
        let mut track = ReferenceTrack::empty("watch.gpx", Clock::Unix);
        for (j, fix) in log.fix.iter().enumerate() {
            if let Some((lat, lon)) = fix {
                let alt = log
                    .gps_alt_m
                    .as_ref()
                    .and_then(|a| a[j])
                    .unwrap_or(f64::NAN);
                track.t_s.push(t0 + log.t_s[j]);
                track.points.push(Geodetic::new(*lat, *lon, alt));
            }
        }
        track.has_alt = true;
        (log, track)
    }

    fn without_fixes(mut log: RideLog) -> RideLog {
        log.fix = vec![None; log.len()];
        log.gps_alt_m = None;
        log.metadata.remove("t0_unix_s");
        log
    }

    #[test]
    fn a_utc_track_is_placed_on_a_ride_without_a_start_by_its_turns() {
        let t0 = 1_700_000_000.37;
        let (log, track) = ride_and_track(3, t0);
        let fixes = log.fix.clone();
        let mut bare = without_fixes(log);
        merge(&mut bare, track.clone(), "watch.gpx").unwrap();
        let found = bare.t0_unix_s().unwrap();
        assert!(
            (found - t0).abs() < 0.1,
            "placed at {found}, truly {t0}: {:?}",
            bare.warnings
        );
        // Every point lands on its own row, where the log had its fix.
        let placed = bare.fix.iter().flatten().count();
        assert!(
            placed + 2 >= track.t_s.len(),
            "{placed} of {}",
            track.t_s.len()
        );
        let mut worst: f64 = 0.0;
        for (a, b) in bare.fix.iter().zip(&fixes) {
            if let (Some(a), Some(b)) = (a, b) {
                worst = worst.max((a.0 - b.0).abs().max(a.1 - b.1).abs());
            }
        }
        assert!(worst < 1e-6, "a fix moved by {worst} deg");
        assert!(
            bare.gps_speed_mps
                .as_ref()
                .unwrap()
                .iter()
                .flatten()
                .count()
                > 500
        );
        assert!(
            bare.warnings
                .iter()
                .any(|w| w.contains("by the vehicle's turns")),
            "{:?}",
            bare.warnings
        );
        // The signals derive from it: a ride with fixes again.
        crate::signals::Signals::from_log(&bare).unwrap();
    }

    /// A 10 Hz track (a sports receiver's), half a metre of noise on each
    /// point: read a point a second, it places the ride as well.
    #[test]
    fn a_fast_noisy_track_is_read_a_point_a_second() {
        let sim = simulate(&SimConfig {
            seed: 3,
            duration_s: 600.0,
            ..SimConfig::default()
        })
        .unwrap();
        let truth = sim.reference("truth.csv").unwrap();
        let t0 = 1_650_000_000.0;
        let mut track = ReferenceTrack::empty("fast.gpx", Clock::Unix);
        let mut state: u64 = 12_345;
        let mut noise = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1.7e-5 // +-0.9 m in latitude
        };
        for (k, (&t, p)) in truth.t_s.iter().zip(&truth.points).enumerate() {
            if k % 10 == 0 {
                track.t_s.push(t0 + t);
                track.points.push(Geodetic::new(
                    p.lat_deg + noise(),
                    p.lon_deg + noise(),
                    f64::NAN,
                ));
            }
        }
        let mut bare = without_fixes(sim.log("ride.csv").unwrap());
        merge(&mut bare, track, "fast.gpx").unwrap();
        let found = bare.t0_unix_s().unwrap();
        assert!(
            (found - t0).abs() < 0.3,
            "placed at {found}: {:?}",
            bare.warnings
        );
        assert!(bare.warnings.iter().any(|w| w.contains("gives no heights")));
        assert!(bare.gps_alt_m.is_none());
    }

    #[test]
    fn a_track_of_another_ride_places_nothing() {
        let (log, _) = ride_and_track(3, 1e9);
        let (_, other) = ride_and_track(5, 1e9);
        let mut bare = without_fixes(log);
        let e = merge(&mut bare, other, "other.gpx")
            .unwrap_err()
            .to_string();
        assert!(e.contains("turns") && e.contains("t0_unix_s"), "{e}");
        assert_eq!(bare.fix_count(), 0);
    }

    #[test]
    fn a_track_is_matched_by_utc_or_the_ride_clock_where_the_ride_says() {
        let t0 = 1_600_000_000.0;
        let (log, track) = ride_and_track(4, t0);
        // UTC: by the ride's start, even 5 s off what the turns would say.
        let mut dated = without_fixes(log.clone());
        dated
            .metadata
            .insert("t0_unix_s".into(), format!("{}", t0 + 5.0));
        merge(&mut dated, track.clone(), "watch.gpx").unwrap();
        assert_eq!(dated.t0_unix_s(), Some(t0 + 5.0));
        assert!(dated.warnings.iter().any(|w| w.contains("placed by UTC")));
        // ... and the turns say that the clocks are 5 s apart.
        assert!(
            dated.warnings.iter().any(|w| ["-4.9 s", "-5.0 s", "-5.1 s"]
                .iter()
                .any(|d| w.contains(&format!("{d} from where the ride's start puts it")))),
            "{:?}",
            dated.warnings
        );
        // A ride's start in local time (an hour off): no time in common by
        // the clock, and the error gives the start that the turns find.
        let mut local = without_fixes(log.clone());
        local
            .metadata
            .insert("t0_unix_s".into(), format!("{}", t0 + 3600.0));
        let e = merge(&mut local, track.clone(), "watch.gpx")
            .unwrap_err()
            .to_string();
        let start: f64 = e
            .split("start is t0_unix_s ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{e}"));
        assert!(
            e.contains("-1 h 00 min 00 s") && (start - t0).abs() < 0.2,
            "{e}"
        );
        // The ride's clock puts the track 5 s early: its last 5 s are cut.
        let last = dated.t_s[dated.len() - 1];
        assert!((590.0..595.1).contains(&last), "{last}");
        // On the ride's clock: as it is, and its own fixes are replaced.
        let mut ride_clock = track;
        for t in &mut ride_clock.t_s {
            *t -= t0;
        }
        ride_clock.clock = Clock::Ride;
        let fixes = ride_clock.t_s.len();
        let mut replaced = log;
        merge(&mut replaced, ride_clock, "fixes.csv").unwrap();
        assert!(replaced.warnings.iter().any(|w| w.contains("are replaced")));
        assert!(
            replaced.fix_count() + 2 >= fixes,
            "{} of {fixes}",
            replaced.fix_count()
        );
    }

    #[test]
    fn a_short_or_far_track_is_an_error_naming_it() {
        let (log, track) = ride_and_track(3, 0.0);
        let mut short = track.clone();
        short.t_s.truncate(5);
        short.points.truncate(5);
        short.clock = Clock::Ride;
        let e = merge(&mut without_fixes(log.clone()), short, "short.gpx")
            .unwrap_err()
            .to_string();
        assert!(e.contains("short.gpx") && e.contains("5 point"), "{e}");
        let mut late = track;
        for t in &mut late.t_s {
            *t += 10_000.0;
        }
        late.clock = Clock::Ride;
        let e = merge(&mut without_fixes(log), late, "late.gpx")
            .unwrap_err()
            .to_string();
        assert!(e.contains("same ride"), "{e}");
    }

    #[test]
    fn the_checks_say_a_log_without_fixes_needs_a_track() {
        let (log, _) = ride_and_track(3, 0.0);
        let bare = without_fixes(log.clone());
        let said = |log: &RideLog| {
            crate::import::checks::check(log).verdicts.iter().any(|v| {
                v.subject == "GPS"
                    && v.level == crate::import::Level::Problem
                    && v.message.contains("--gps-track")
            })
        };
        assert!(said(&bare));
        assert!(!said(&log));
    }

    #[test]
    fn the_turn_is_read_between_rows_at_their_mean_rates() {
        // 3 rows at 0, 0.3 and 1.0 s: 10 deg/s, then 20 deg/s.
        let log = RideLog {
            t_s: vec![0.0, 0.3, 1.0],
            gyro_dps: vec![[0.0, 0.0, 0.0], [0.0, 0.0, 10.0], [0.0, 0.0, 20.0]],
            ..RideLog::default()
        };
        let turned = Turned::new(&log, &Vector3::z());
        for (t, deg) in [
            (0.0, 0.0),
            (0.15, 1.5),
            (0.3, 3.0),
            (0.65, 10.0),
            (1.0, 17.0),
            (2.0, 17.0),
        ] {
            assert!(
                (turned.at(t).to_degrees() - deg).abs() < 1e-9,
                "{t}: {}",
                turned.at(t).to_degrees()
            );
        }
    }

    #[test]
    fn the_nearest_row_and_the_wrapped_turn() {
        let t = [0.0, 0.1, 0.2, 0.3];
        assert_eq!(nearest(&t, -1.0), 0);
        assert_eq!(nearest(&t, 0.14), 1);
        assert_eq!(nearest(&t, 0.16), 2);
        assert_eq!(nearest(&t, 9.0), 3);
        assert!(
            (crate::rotation::wrap_pi(3.0 * std::f64::consts::PI / 2.0)
                + std::f64::consts::FRAC_PI_2)
                .abs()
                < 1e-12
        );
    }
}
