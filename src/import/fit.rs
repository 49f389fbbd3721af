//! Garmin FIT activities (`.fit`, from bike computers and watches), read by
//! the `fitparser` crate: GNSS positions, speed and distance at 1 Hz, and
//! which ANT+ sensors were paired, but no gyro (no licensed FIT sample with
//! `gyroscope_data` is known). A FIT file is therefore a reference track of
//! a ride that has a gyro (`--reference ride.fit`, in UTC like GPX), and
//! opened as a ride it says what it is.
//!
//! The activity's `record` messages give the points: `position_lat` and
//! `position_long` (semicircles, `deg = s * 180 / 2^31`), `enhanced_altitude`
//! (else `altitude`) and the `timestamp` (whole seconds, UTC). Records
//! without a position (sensor-only seconds, a lost fix) are left out, as
//! are repeats of a second. A wheel-speed sensor is told by `device_info`
//! (`antplus_device_type` or `device_type` `bike_speed` or
//! `bike_speed_cadence`, 121 or 123): the FIT `speed` field does not say
//! whether the GNSS or the wheel measured it.
//!
//! A bike computer's wheel-speed sensor is the odometer that a camera, a
//! phone or a drone log lacks: `--wheel ride.fit` (see [`merge_distance`])
//! takes the FIT's cumulative `distance` as the ride's odometer, matched by
//! UTC time.

use std::path::Path;

use fitparser::profile::MesgNum;
use fitparser::{FitDataRecord, Value};

use super::LoadError;
use super::reference::{Clock, ReferenceTrack};
use crate::geodesy::Geodetic;
use crate::ride::RideLog;

/// Whether the first bytes of a file are a FIT header (`.FIT` at byte 8).
pub fn is_fit(head: &[u8]) -> bool {
    head.len() >= 12 && &head[8..12] == b".FIT"
}

/// What a FIT activity holds, beyond its track.
#[derive(Clone, Debug, PartialEq)]
pub struct Activity {
    pub track: ReferenceTrack,
    /// The device's last `distance` (m), where it logs one.
    pub distance_m: Option<f64>,
    /// The cumulative `distance` (m) of every record that logs one, by its
    /// time (s since 1970, UTC; increasing): the wheel-speed sensor's where
    /// one is paired, else the device's GNSS track's.
    pub odometer: Vec<(f64, f64)>,
    /// Whether a wheel-speed sensor was paired.
    pub wheel_sensor: bool,
    /// The device's product name, where it says it.
    pub device: Option<String>,
}

impl Activity {
    /// One line for messages: the device, the points, duration and distance.
    pub fn describe(&self) -> String {
        let t = &self.track.t_s;
        format!(
            "a Garmin FIT activity{} of {} points over {:.0} s{}{}",
            self.device
                .as_ref()
                .map_or(String::new(), |d| format!(" ({d})")),
            t.len(),
            t.last().zip(t.first()).map_or(0.0, |(l, f)| l - f),
            self.distance_m
                .map_or(String::new(), |d| format!(", {:.1} km", d / 1000.0)),
            if self.wheel_sensor {
                ", with a wheel-speed sensor paired"
            } else {
                ""
            }
        )
    }
}

fn number(v: &Value) -> Option<f64> {
    let x: f64 = v.clone().try_into().ok()?;
    x.is_finite().then_some(x)
}

fn field<'r>(r: &'r FitDataRecord, name: &str) -> Option<&'r Value> {
    r.fields()
        .iter()
        .find(|f| f.name() == name)
        .map(|f| f.value())
}

/// The data records of a FIT file, read one by one; and where the file is
/// shorter than its header declares (a device that stopped while writing:
/// the CRC and the records after the cut are missing), the declared size,
/// with the records before the cut. A fault inside a whole file is an
/// error, as `fitparser::from_bytes` makes it.
fn records_of(bytes: &[u8]) -> fitparser::Result<(Vec<FitDataRecord>, Option<usize>)> {
    // Header: its own size (byte 0), the data's (bytes 4-7), then the
    // data and a two-byte CRC.
    let declared = bytes
        .get(4..8)
        .map(|d| bytes[0] as usize + u32::from_le_bytes([d[0], d[1], d[2], d[3]]) as usize + 2);
    let cut = declared.filter(|&n| bytes.len() < n);
    let mut processor = fitparser::de::FitStreamProcessor::new();
    let mut records = Vec::new();
    let mut rest = bytes;
    while !rest.is_empty() {
        let (next, object) = match processor.deserialize_next(rest) {
            Ok(v) => v,
            Err(_) if cut.is_some() && !records.is_empty() => break,
            Err(e) => return Err(e),
        };
        match object {
            fitparser::de::FitObject::Crc(..) => processor.reset(),
            fitparser::de::FitObject::DataMessage(message) => {
                records.push(processor.decode_message(message)?);
            }
            _ => {}
        }
        rest = next;
    }
    Ok((records, cut))
}

/// Parse the bytes of a FIT file named `file` (for messages).
pub fn parse(bytes: &[u8], file: &str) -> Result<Activity, LoadError> {
    let whole = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    // A third-party parser of a binary format: its panic is this file's error.
    let (records, cut) = match std::panic::catch_unwind(|| records_of(bytes)) {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => return Err(whole(format!("not a readable FIT file: {e}"))),
        Err(_) => {
            return Err(whole(
                "the FIT parser failed on this file (it is damaged)".into(),
            ));
        }
    };
    let mut track = ReferenceTrack::empty(file, Clock::Unix);
    if let Some(declared) = cut {
        track.warnings.push(format!(
            "{file}: the file is cut short ({} of the {declared} bytes its header declares, as when a device stops while writing): the {} records before the cut are read",
            bytes.len(),
            records.len()
        ));
    }
    let mut distance_m = None;
    let mut odometer: Vec<(f64, f64)> = Vec::new();
    let mut wheel_sensor = false;
    let mut device = None;
    const SEMICIRCLE_DEG: f64 = 180.0 / 2_147_483_648.0;
    for r in &records {
        match r.kind() {
            MesgNum::Record => {
                if let Some(d) = field(r, "distance").and_then(number) {
                    distance_m = Some(d);
                    if let Some(Value::Timestamp(time)) = field(r, "timestamp") {
                        let t = time.timestamp() as f64;
                        if odometer.last().is_none_or(|&(last, _)| t > last) {
                            odometer.push((t, d));
                        }
                    }
                }
                let (Some(lat), Some(lon), Some(Value::Timestamp(time))) = (
                    field(r, "position_lat").and_then(number),
                    field(r, "position_long").and_then(number),
                    field(r, "timestamp"),
                ) else {
                    continue;
                };
                let t = time.timestamp() as f64;
                if track.t_s.last().is_some_and(|&last| t <= last) {
                    continue;
                }
                let alt = field(r, "enhanced_altitude")
                    .or_else(|| field(r, "altitude"))
                    .and_then(number);
                track.has_alt |= alt.is_some();
                track.t_s.push(t);
                track.points.push(Geodetic::new(
                    lat * SEMICIRCLE_DEG,
                    lon * SEMICIRCLE_DEG,
                    alt.unwrap_or(f64::NAN),
                ));
            }
            MesgNum::DeviceInfo => {
                let kind = |name: &str| field(r, name).map(|v| v.to_string());
                let speed_sensor = |k: Option<String>| {
                    k.is_some_and(|k| {
                        matches!(
                            k.as_str(),
                            "bike_speed" | "bike_speed_cadence" | "121" | "123"
                        )
                    })
                };
                wheel_sensor |=
                    speed_sensor(kind("antplus_device_type")) || speed_sensor(kind("device_type"));
                if kind("device_index").as_deref() == Some("creator") {
                    device = field(r, "product_name")
                        .or_else(|| field(r, "garmin_product"))
                        .map(|v| v.to_string())
                        .filter(|s| !s.is_empty() && s != "0")
                        .or(device);
                }
            }
            _ => {}
        }
    }
    if track.t_s.len() < 2 {
        return Err(whole(
            "the FIT file has fewer than two records with a position and a time: no track".into(),
        ));
    }
    Ok(Activity {
        track,
        distance_m,
        odometer,
        wheel_sensor,
        device,
    })
}

/// Shortest stretch (s) that a FIT's distance and a ride must share.
const MIN_OVERLAP_S: f64 = 10.0;

/// Longest time (s) between a FIT's records that is not a pause: smart
/// recording logs every 1-8 s.
const MAX_RECORD_GAP_S: f64 = 10.0;

/// Take the cumulative `distance` of the FIT activity at `path` as `log`'s
/// odometer (`odo_m`, in place of any wheel sensor or speed it has),
/// matched by UTC: row `j` is at `t0_unix_s + t_j`, and its distance is
/// the FIT's interpolated linearly between its records (whole seconds,
/// usually 1 Hz). Where the FIT covers only part of the ride, the ride is
/// cut to that part (a path does not stand still where no distance is
/// known). Errors: a ride without `t0_unix_s`, a FIT without distances, or
/// less than [`MIN_OVERLAP_S`] in common. Without a paired wheel-speed
/// sensor the FIT's distance is its own GNSS track's: taken, with a warning.
pub fn merge_distance(log: &mut RideLog, path: &Path) -> Result<(), LoadError> {
    let (bytes, file) = super::read_bytes(path)?;
    merge_activity(log, &parse(&bytes, &file)?, &file)
}

/// [`merge_distance`] of an activity read from `file` (named in messages).
fn merge_activity(log: &mut RideLog, activity: &Activity, file: &str) -> Result<(), LoadError> {
    let file = file.to_string();
    let error = |message: String| LoadError::File {
        file: file.clone(),
        message,
    };
    let odometer = &activity.odometer;
    let (Some(&(first, _)), Some(&(last, _))) = (odometer.first(), odometer.last()) else {
        return Err(error("the FIT file logs no distance".into()));
    };
    if odometer.len() < 2 {
        return Err(error(
            "the FIT file logs one distance: at least two are needed".into(),
        ));
    }
    let t0 = log.t0_unix_s().ok_or_else(|| {
            error(format!(
                "{} has no t0_unix_s (its start in UTC), so the FIT's distance cannot be matched to it by time",
                log.source
            ))
        })?;
    let (Some(&ride_first), Some(&ride_last)) = (log.t_s.first(), log.t_s.last()) else {
        return Err(error(format!("{} has no rows", log.source)));
    };
    let (start, end) = ((first - t0).max(ride_first), (last - t0).min(ride_last));
    if end - start < MIN_OVERLAP_S {
        return Err(error(format!(
            "its distance ({first:.0}-{last:.0} s UTC) and {} ({:.0}-{:.0} s UTC) share {:.0} s; at least {MIN_OVERLAP_S:.0} s are needed: is it the same ride?",
            log.source,
            t0 + ride_first,
            t0 + ride_last,
            (end - start).max(0.0)
        )));
    }
    log.warnings.extend(activity.track.warnings.iter().cloned());
    log.cut_to(start, end, &format!("{file}'s distance"));
    let mut k = 0;
    let distance = log
        .t_s
        .iter()
        .map(|&t| {
            let utc = t0 + t;
            while k + 2 < odometer.len() && odometer[k + 1].0 < utc {
                k += 1;
            }
            let ((ta, da), (tb, db)) = (odometer[k], odometer[k + 1]);
            Some(da + (db - da) * ((utc - ta) / (tb - ta)).clamp(0.0, 1.0))
        })
        .collect();
    // Seconds the FIT logged no distance inside the ride (a pause, a lost
    // sensor): its distance is interpolated across them.
    let paused: Vec<f64> = odometer
        .windows(2)
        .filter(|w| w[1].0 > t0 + start && w[0].0 < t0 + end && w[1].0 - w[0].0 > MAX_RECORD_GAP_S)
        .map(|w| w[1].0 - w[0].0)
        .collect();
    if !paused.is_empty() {
        log.warnings.push(format!(
            "{}: {file} logs no distance for {} stretch(es) of {:.0} s in all (paused?): the distance is interpolated across them",
            log.source,
            paused.len(),
            paused.iter().sum::<f64>()
        ));
    }
    if log.odo_m.is_some() || log.wheel_pulse.is_some() || log.speed_mps.is_some() {
        log.warnings.push(format!(
            "{}: its own odometer is replaced by {file}'s distance",
            log.source
        ));
    }
    log.odo_m = Some(distance);
    log.wheel_pulse = None;
    log.speed_mps = None;
    log.warnings.push(if activity.wheel_sensor {
        format!(
            "{}: the distance is {file}'s wheel-speed sensor's ({} records), matched by UTC",
            log.source,
            odometer.len()
        )
    } else {
        format!(
            "{}: the distance is {file}'s, which has no wheel-speed sensor paired: it is the bike computer's GNSS distance ({} records), matched by UTC",
            log.source,
            odometer.len()
        )
    });
    log.metadata.insert(
        "odometer".into(),
        format!(
            "{} of {file}, matched by UTC",
            if activity.wheel_sensor {
                "the wheel-speed sensor's distance"
            } else {
                "the GNSS distance"
            }
        ),
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 60 s ride at 10 Hz starting at Unix time 1000 s, and an activity
    /// whose distance grows 5 m a second from 990 s with a 20 s pause.
    fn ride_and_activity() -> (RideLog, Activity) {
        let mut log = crate::testing::winding_log(60.0, 10.0);
        log.metadata.insert("t0_unix_s".into(), "1000".into());
        let mut odometer: Vec<(f64, f64)> = (990..=1020)
            .map(|t| (t as f64, 5.0 * (t - 990) as f64))
            .collect();
        // Paused from 1020 s to 1040 s (the bike stood): no records, no distance.
        odometer.extend((1040..=1100).map(|t| (t as f64, 150.0 + 5.0 * (t - 1040) as f64)));
        let activity = Activity {
            track: ReferenceTrack::empty("a.fit", Clock::Unix),
            distance_m: odometer.last().map(|r| r.1),
            odometer,
            wheel_sensor: true,
            device: None,
        };
        (log, activity)
    }

    #[test]
    fn each_row_takes_the_fits_distance_at_its_utc_time() {
        let (mut log, activity) = ride_and_activity();
        merge_activity(&mut log, &activity, "a.fit").unwrap();
        let odo = log.odo_m.as_ref().unwrap();
        let at = |t: f64| odo[log.t_s.partition_point(|&x| x < t - 1e-9)].unwrap();
        assert!((at(0.0) - 50.0).abs() < 1e-9);
        assert!((at(12.5) - 112.5).abs() < 1e-9);
        // Across the pause the distance is interpolated, and a warning says so.
        assert!((at(30.0) - 150.0).abs() < 1e-9);
        assert!((at(45.0) - 175.0).abs() < 1e-9);
        assert!(log.wheel_pulse.is_none() && log.speed_mps.is_none());
        assert!(
            log.warnings
                .iter()
                .any(|w| w.contains("1 stretch(es) of 20 s")),
            "{:?}",
            log.warnings
        );
        assert!(
            log.warnings
                .iter()
                .any(|w| w.contains("its own odometer is replaced"))
        );
    }

    #[test]
    fn a_ride_the_fit_covers_in_part_is_cut_to_it() {
        let (mut log, mut activity) = ride_and_activity();
        activity.odometer.retain(|r| r.0 >= 1010.0);
        merge_activity(&mut log, &activity, "a.fit").unwrap();
        assert!((log.t_s[0] - 10.0).abs() < 1e-9, "{}", log.t_s[0]);
        assert!(
            log.warnings
                .iter()
                .any(|w| w.contains("is cut to 10.0-60.0 s"))
        );
        // Under 10 s in common, and no UTC start: errors naming the FIT.
        let (mut log, mut activity) = ride_and_activity();
        activity.odometer.retain(|r| r.0 >= 1055.0);
        let e = merge_activity(&mut log, &activity, "a.fit")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("a.fit: ") && e.contains("share 5 s"), "{e}");
        let (mut log, activity) = ride_and_activity();
        log.metadata.remove("t0_unix_s");
        let e = merge_activity(&mut log, &activity, "a.fit")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no t0_unix_s"), "{e}");
    }

    /// A FIT file cut short (a device that stopped while writing: no CRC,
    /// the last record cut) keeps its records before the cut, with a
    /// warning; refused whole, it took the reference and the fit with it.
    #[test]
    fn a_fit_file_cut_short_keeps_the_records_before_the_cut() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/formats/fit/Edge810-Vector-2013-08-16-15-35-10.fit");
        let bytes = std::fs::read(path).unwrap();
        let whole = parse(&bytes, "a.fit").unwrap();
        assert!(whole.track.warnings.is_empty());
        let cut = parse(&bytes[..bytes.len() * 3 / 5 + 7], "a.fit").unwrap();
        let n = cut.track.t_s.len();
        assert!(n > 1000 && n < whole.track.t_s.len(), "{n}");
        assert_eq!(cut.track.t_s[..], whole.track.t_s[..n]);
        assert_eq!(cut.odometer[..], whole.odometer[..cut.odometer.len()]);
        assert_eq!(cut.track.warnings.len(), 1);
        assert!(
            cut.track.warnings[0].contains("cut short"),
            "{:?}",
            cut.track.warnings
        );
        // Whole but damaged inside, or cut before any record: still an error.
        let mut damaged = bytes.clone();
        damaged[5000] ^= 0xff;
        damaged[5001] ^= 0xff;
        let e = parse(&damaged, "a.fit").unwrap_err().to_string();
        assert!(e.contains("not a readable FIT file"), "{e}");
        assert!(parse(&bytes[..20], "a.fit").is_err());
    }
}
