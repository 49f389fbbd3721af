//! comma2k19 segments (github.com/commaai/comma2k19): one minute of a car
//! as a folder whose `processed_log/` holds every signal as a folder of two
//! NumPy arrays, `t` (the device's boot clock, s) and `value` ([`super::npy`]).
//!
//! What is read, and how it becomes a ride log:
//!
//! - **Rows**: the samples of `IMU/gyro_uncalibrated` (about 104 Hz; the
//!   uncalibrated rates keep the gyro's real bias, which gyropath fits), in
//!   the time the distance covers (the CAN speed's, or without it the
//!   u-blox's). `t_s` counts from the first of them in the CAN speed's time
//!   (the u-blox's without CAN), whichever distance is used; its boot time
//!   is the `t0_boot_s` metadata.
//! - **Gyro**: comma's axes are forward, right, down (rad/s); the ride log's
//!   are forward, left, up (deg/s): `gx = fwd`, `gy = -right`, `gz = -down`.
//! - **Distance**: `CAN/speed` (m/s, about 83 Hz) integrated by trapezoids at
//!   its own times and interpolated to the rows as `odo_m`. A segment without
//!   it (or read with `--distance gnss`) integrates the u-blox speed instead.
//! - **GNSS**: `GNSS/live_gnss_ublox` (about 10 Hz: latitude, longitude,
//!   speed m/s, UTC ms, height above the ellipsoid, course deg). Every sample
//!   gives `gps_speed_mps` and `gps_course_deg` on the row nearest its
//!   arrival; the fixes are thinned to one per second (the sample nearest
//!   each second counted from the first fix, the earlier of two as near),
//!   the rate the model's GPS error is built for, also on the row nearest
//!   their arrival.
//! - **Clock**: `t0_unix_s` from the first fix's UTC time less its age at
//!   arrival on the boot clock, so GPX or NMEA references line up (to the
//!   receiver's latency, about 0.1 s); `global_pose` is read on the boot
//!   clock itself ([`read_reference`]).
//!
//! This is the conversion that made `../shared/real/comma2k19-example1`
//! from the same segment (its README), so both fit alike.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::LoadError;
use super::npy::{self, Array};
use super::reference::{Clock, ReferenceTrack};
use super::timeline::{GnssSample, place_gnss};
use crate::geodesy::Geodetic;
use crate::ride::RideLog;

/// Whether `path` is a comma2k19 segment (a folder with a processed log's gyro).
pub fn is_segment(path: &Path) -> bool {
    path.join("processed_log").join("IMU").is_dir()
}

/// One signal of a processed log: its times and values.
struct Signal {
    t: Vec<f64>,
    value: Array,
}

/// Read `processed_log/NAME/{t,value}`; `None` when the folder is absent.
fn signal(segment: &Path, name: &str) -> Result<Option<Signal>, LoadError> {
    let dir = segment.join("processed_log").join(name);
    if !dir.is_dir() {
        return Ok(None);
    }
    let t = npy::read(&dir.join("t"))?.column(0);
    let value = npy::read(&dir.join("value"))?;
    let file = dir.display().to_string();
    if value.rows != t.len() {
        return Err(LoadError::File {
            file,
            message: format!("{} times but {} values", t.len(), value.rows),
        });
    }
    increasing(&t, &dir.join("t"))?;
    Ok(Some(Signal { t, value }))
}

/// Times must be finite and strictly increasing.
fn increasing(t: &[f64], file: &Path) -> Result<(), LoadError> {
    for (k, w) in t.windows(2).enumerate() {
        if !(w[0].is_finite() && w[1] > w[0]) {
            return Err(LoadError::File {
                file: file.display().to_string(),
                message: format!(
                    "time does not increase at sample {} ({} then {})",
                    k + 2,
                    w[0],
                    w[1]
                ),
            });
        }
    }
    Ok(())
}

fn required(segment: &Path, name: &str, cols: usize) -> Result<Signal, LoadError> {
    let s = signal(segment, name)?.ok_or_else(|| LoadError::File {
        file: segment.display().to_string(),
        message: format!("a comma2k19 segment needs processed_log/{name}"),
    })?;
    if s.value.cols < cols {
        return Err(LoadError::File {
            file: segment
                .join("processed_log")
                .join(name)
                .display()
                .to_string(),
            message: format!("value has {} columns, {cols} are needed", s.value.cols),
        });
    }
    Ok(s)
}

/// Read a segment folder as a ride log; `with_odometer = false` leaves the
/// CAN speed out, so the distance comes from the GNSS speed.
pub fn read(segment: &Path, with_odometer: bool) -> Result<RideLog, LoadError> {
    let name = segment.display().to_string();
    let gyro = required(segment, "IMU/gyro_uncalibrated", 3)?;
    let gnss = required(segment, "GNSS/live_gnss_ublox", 6)?;
    let can_speed = signal(segment, "CAN/speed")?;
    let span_of = |t: &[f64]| (t[0], t[t.len() - 1]);
    let within = |(a, b): (f64, f64), x: f64| x >= a && x <= b;
    // The ride's clock: `t_s = 0` at the segment's first gyro sample in the
    // CAN speed's time (the u-blox's without one), whichever distance is
    // used, so that a reference on the ride's clock (the converted ride's
    // `truth.csv`) lines up with `--distance gnss` too. Counted from the
    // first row instead, it moved by the 77 ms the u-blox starts later and
    // such a reference read 0.63 m where the path is 1.64 m off.
    let clock = span_of(can_speed.as_ref().map_or(&gnss.t, |c| &c.t));
    let origin = gyro.t.iter().copied().find(|&x| within(clock, x));
    let can = can_speed.filter(|_| with_odometer);
    // The rows: the gyro's samples within the distance's time.
    let span = span_of(can.as_ref().map_or(&gnss.t, |c| &c.t));
    let rows: Vec<usize> = (0..gyro.t.len())
        .filter(|&k| within(span, gyro.t[k]))
        .collect();
    if rows.len() < 2 {
        return Err(LoadError::File {
            file: name,
            message: "the gyro has fewer than two samples in the time the distance covers".into(),
        });
    }
    let t_boot: Vec<f64> = rows.iter().map(|&k| gyro.t[k]).collect();
    let t0 = origin.unwrap_or(t_boot[0]);
    let n = rows.len();
    let mut log = RideLog {
        source: name.clone(),
        line: (1..=n as u64).collect(),
        t_s: t_boot.iter().map(|t| t - t0).collect(),
        gyro_dps: rows
            .iter()
            .map(|&k| {
                let g = gyro.value.row(k);
                [g[0].to_degrees(), -g[1].to_degrees(), -g[2].to_degrees()]
            })
            .collect(),
        fix: vec![None; n],
        metadata: BTreeMap::from([
            ("source".to_string(), format!("comma2k19 segment {name}")),
            ("t0_boot_s".to_string(), format!("{t0:.6}")),
        ]),
        ..RideLog::default()
    };
    if let Some(c) = &can {
        log.odo_m = Some(
            odometer(&c.t, &c.value.column(0), &t_boot)
                .into_iter()
                .map(Some)
                .collect(),
        );
    }
    // Every u-blox sample's speed and course; one fix per second of its
    // UTC stamps (the arrival times jitter by tens of milliseconds).
    let mut samples = Vec::with_capacity(gnss.t.len());
    let mut skipped = 0usize;
    for k in 0..gnss.t.len() {
        let v = gnss.value.row(k);
        if !v[..6].iter().all(|x| x.is_finite()) || v[2] < 0.0 {
            skipped += 1;
            continue;
        }
        samples.push(GnssSample {
            t: gnss.t[k] - t0,
            stamp: v[3] / 1000.0,
            lat: v[0],
            lon: v[1],
            alt: Some(v[4]),
            speed: Some(v[2]),
            course: Some(v[5]),
            hacc: None,
            hdop: None,
            sats: None,
        });
    }
    if let Some(first) = place_gnss(&mut log, &samples) {
        // The first fix's UTC time less its age at arrival on the boot clock.
        let t0_unix = first.stamp - first.t;
        log.metadata
            .insert("t0_unix_s".into(), format!("{t0_unix:.3}"));
    }
    if skipped > 0 {
        log.warnings.push(format!(
            "{name}: {skipped} u-blox samples with a value out of range or not a number were left out"
        ));
    }
    Ok(log)
}

/// Cumulative distance at `rows` (boot times) of a speed `v` sampled at `t`:
/// trapezoids at the speed's own times, interpolated linearly to the rows,
/// counted from the first row.
fn odometer(t: &[f64], v: &[f64], rows: &[f64]) -> Vec<f64> {
    let mut s = vec![0.0; t.len()];
    for k in 1..t.len() {
        s[k] = s[k - 1] + 0.5 * (v[k - 1] + v[k]) * (t[k] - t[k - 1]);
    }
    let at = |x: f64| {
        let i = t.partition_point(|&u| u < x).clamp(1, t.len() - 1);
        let f = ((x - t[i - 1]) / (t[i] - t[i - 1])).clamp(0.0, 1.0);
        s[i - 1] + f * (s[i] - s[i - 1])
    };
    let start = at(rows[0]);
    rows.iter().map(|&x| at(x) - start).collect()
}

/// The segment folder of `path`: the segment itself, or its `global_pose`.
fn segment_of(path: &Path) -> PathBuf {
    if path.file_name().is_some_and(|n| n == "global_pose") {
        path.parent()
            .map_or_else(|| path.to_path_buf(), Path::to_path_buf)
    } else {
        path.to_path_buf()
    }
}

/// Whether `path` is a segment with a `global_pose`, or that folder itself.
pub fn has_global_pose(path: &Path) -> bool {
    segment_of(path)
        .join("global_pose")
        .join("frame_positions")
        .is_file()
}

/// comma's post-processed pose (`global_pose/frame_times`, `frame_positions`
/// in ECEF, 20 Hz) as a reference track on the boot clock: put on a ride's
/// clock by its `t0_boot_s` (see [`ReferenceTrack::on_ride_clock`]).
pub fn read_reference(path: &Path) -> Result<ReferenceTrack, LoadError> {
    let dir = segment_of(path).join("global_pose");
    let t = npy::read(&dir.join("frame_times"))?.column(0);
    let p = npy::read(&dir.join("frame_positions"))?;
    let file = dir.display().to_string();
    if p.cols != 3 || p.rows != t.len() {
        return Err(LoadError::File {
            file,
            message: format!(
                "{} times but {} positions of {} coordinates (3 are needed)",
                t.len(),
                p.rows,
                p.cols
            ),
        });
    }
    increasing(&t, &dir.join("frame_times"))?;
    let mut points = Vec::with_capacity(p.rows);
    for r in 0..p.rows {
        let x = p.row(r);
        if !x.iter().all(|v| v.is_finite()) || x.iter().map(|v| v * v).sum::<f64>() < 1e12 {
            return Err(LoadError::File {
                file,
                message: format!(
                    "frame_positions row {} ({}, {}, {}) is not a point near the Earth's surface (ECEF, m)",
                    r + 1,
                    x[0],
                    x[1],
                    x[2]
                ),
            });
        }
        points.push(Geodetic::from_ecef(&nalgebra::Vector3::new(
            x[0], x[1], x[2],
        )));
    }
    Ok(ReferenceTrack {
        source: file,
        t_s: t,
        points,
        has_alt: true,
        clock: Clock::Boot,
        warnings: Vec::new(),
    })
}
