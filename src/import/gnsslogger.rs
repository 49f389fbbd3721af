//! Android phones: Google's GnssLogger app (`.txt`). A phone on a
//! handlebar or in a car's cradle logs its gyro, accelerometer and GNSS
//! fixes with the Doppler speed, but no wheel distance.
//!
//! The file is text: `# Type,field,…` comment lines declare each record
//! type's columns, and every record line is `Type,value,…` in that order.
//! Columns are found by name, so the app's versions (v2 `Latitude`, v3
//! `LatitudeDegrees`, …) read alike.
//!
//! What is read, and how it becomes a ride log:
//!
//! - **Rows**: the `UncalGyro` samples (the chip's rates before Android's
//!   own bias estimate, which is what the model fits), else the calibrated
//!   `Gyro` ones, rad/s made deg/s, in the phone's axes (x right, y up the
//!   screen, z out of it): `gyropath check` names them and `--mount auto`
//!   (the default here, as for cameras) turns them to x forward, y left,
//!   z up. `UncalAccel` (else `Accel`) samples go to the row nearest them,
//!   for the checks.
//! - **GNSS**: the `Fix` records of the `GPS` provider: the receiver's own
//!   fixes with their speed, bearing and accuracy. `FLP` (the fused
//!   location, which already mixes the phone's inertial sensors in) and
//!   `NLP` (network) are used only when the log has no `GPS` fix, with a
//!   warning. One fix a second by `UnixTimeMillis`
//!   ([`super::timeline::place_gnss`]); every fix's speed is the distance.
//! - **Clock**: every record's `elapsedRealtimeNanos` (the phone's boot
//!   clock, shared by sensors and fixes), `t_s` from the first gyro sample;
//!   `t0_boot_s` and `t0_unix_s` from it and the first fix's
//!   `UnixTimeMillis`.
//!
//! See `docs/real-logs.md` for what the shared sample holds.

use std::collections::{BTreeMap, HashMap};
use std::io::BufRead;
use std::path::Path;

use super::LoadError;
use super::timeline::{GnssSample, nearest_row, place_gnss};
use crate::ride::RideLog;

/// Whether the first bytes of a file are a GnssLogger header.
pub fn is_gnsslogger(head: &[u8]) -> bool {
    let text = String::from_utf8_lossy(head);
    text.starts_with('#') && (text.contains("Header Description") || text.contains("GnssLogger"))
}

/// Whether the file at `path` starts with a GnssLogger header (a batch
/// folder's `.txt` files are rides only when it does).
pub fn is_gnsslogger_file(path: &Path) -> bool {
    let mut head = [0u8; 256];
    super::head(path, &mut head).is_ok_and(|n| is_gnsslogger(&head[..n]))
}

/// One record read from a line: its line number and its values by column.
struct Record {
    line: u64,
    values: Vec<String>,
}

/// The records of the types gyropath uses, with each type's column names.
#[derive(Default)]
struct Records {
    columns: HashMap<String, Vec<String>>,
    rows: HashMap<String, Vec<Record>>,
}

/// Record types gyropath reads; every other line (`Raw`, `Status`, …) is skipped.
const USED: [&str; 5] = ["UncalGyro", "Gyro", "UncalAccel", "Accel", "Fix"];

impl Records {
    fn read(reader: impl BufRead, file: &str) -> Result<Self, LoadError> {
        let mut out = Self::default();
        for (i, line) in reader.split(b'\n').enumerate() {
            let line_no = i as u64 + 1;
            let bytes = line.map_err(|error| LoadError::Io {
                file: file.to_string(),
                error,
            })?;
            let text = String::from_utf8_lossy(&bytes);
            let text = text.trim_end_matches('\r');
            if let Some(header) = text.strip_prefix('#') {
                let mut names = header.trim().split(',').map(|s| s.trim().to_string());
                if let Some(kind) = names.next().filter(|k| USED.contains(&k.as_str())) {
                    out.columns.insert(kind, names.collect());
                }
                continue;
            }
            let mut values = text.split(',');
            let Some(kind) = values.next().filter(|k| USED.contains(k)) else {
                continue;
            };
            out.rows.entry(kind.to_string()).or_default().push(Record {
                line: line_no,
                values: values.map(|s| s.trim().to_string()).collect(),
            });
        }
        Ok(out)
    }

    /// The records of `kind` with a reader of their columns, when it has any.
    fn table<'r>(&'r self, kind: &'r str, file: &'r str) -> Option<Table<'r>> {
        let rows = self.rows.get(kind).filter(|r| !r.is_empty())?;
        Some(Table {
            kind,
            file,
            columns: self.columns.get(kind).map(Vec::as_slice).unwrap_or(&[]),
            rows,
        })
    }
}

/// The records of one type, read by column name.
struct Table<'r> {
    kind: &'r str,
    file: &'r str,
    columns: &'r [String],
    rows: &'r [Record],
}

impl Table<'_> {
    /// The index of the first of `names` that the header declares.
    fn index(&self, names: &[&str]) -> Result<usize, LoadError> {
        names
            .iter()
            .find_map(|n| self.columns.iter().position(|c| c == n))
            .ok_or_else(|| LoadError::File {
                file: self.file.to_string(),
                message: format!(
                    "the '# {}' header declares no column {} (the app's version may be unknown)",
                    self.kind,
                    names.join(" or ")
                ),
            })
    }

    /// The value of column `c` of `record`: `None` when empty, an error
    /// naming the line and column when it is not a finite number.
    fn value(&self, record: &Record, c: usize) -> Result<Option<f64>, LoadError> {
        let Some(text) = record.values.get(c).filter(|s| !s.is_empty()) else {
            return Ok(None);
        };
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some(v)),
            _ => Err(LoadError::Field {
                file: self.file.to_string(),
                line: record.line,
                column: self.columns.get(c).cloned().unwrap_or_default(),
                message: format!("'{text}' is not a finite number"),
            }),
        }
    }

    /// Like [`Self::value`], for a column every record must fill.
    fn required(&self, record: &Record, c: usize) -> Result<f64, LoadError> {
        self.value(record, c)?.ok_or_else(|| LoadError::Field {
            file: self.file.to_string(),
            line: record.line,
            column: self.columns.get(c).cloned().unwrap_or_default(),
            message: "empty".into(),
        })
    }

    /// Every record's time (s on the boot clock) and three axes from
    /// columns `axes`, scaled by `scale`.
    fn triads(&self, axes: [&str; 3], scale: f64) -> Result<Vec<(f64, u64, [f64; 3])>, LoadError> {
        let t = self.index(&["elapsedRealtimeNanos"])?;
        let [a0, a1, a2] = [
            self.index(&[axes[0]])?,
            self.index(&[axes[1]])?,
            self.index(&[axes[2]])?,
        ];
        self.rows
            .iter()
            .map(|r| {
                Ok((
                    self.required(r, t)? * 1e-9,
                    r.line,
                    [
                        self.required(r, a0)? * scale,
                        self.required(r, a1)? * scale,
                        self.required(r, a2)? * scale,
                    ],
                ))
            })
            .collect()
    }
}

/// Read a GnssLogger file as a ride log.
pub fn read(path: &Path) -> Result<RideLog, LoadError> {
    let (f, file) = super::open_file(path)?;
    parse(std::io::BufReader::new(f), &file)
}

/// Parse a GnssLogger log named `file` (for messages).
pub fn parse(reader: impl BufRead, file: &str) -> Result<RideLog, LoadError> {
    let bad = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let records = Records::read(reader, file)?;
    let (gyro_kind, gyro) = match records.table("UncalGyro", file) {
        Some(t) => (
            "UncalGyro",
            t.triads(
                [
                    "UncalGyroXRadPerSec",
                    "UncalGyroYRadPerSec",
                    "UncalGyroZRadPerSec",
                ],
                1f64.to_degrees(),
            )?,
        ),
        None => match records.table("Gyro", file) {
            Some(t) => (
                "Gyro",
                t.triads(
                    ["GyroXRadPerSec", "GyroYRadPerSec", "GyroZRadPerSec"],
                    1f64.to_degrees(),
                )?,
            ),
            None => {
                return Err(bad(
                    "the log has no gyro records (UncalGyro or Gyro lines; turn the sensors on in GnssLogger's settings): a path needs a gyro".into(),
                ));
            }
        },
    };
    let accel = match records.table("UncalAccel", file) {
        Some(t) => Some(t.triads(
            ["UncalAccelXMps2", "UncalAccelYMps2", "UncalAccelZMps2"],
            1.0,
        )?),
        None => records
            .table("Accel", file)
            .map(|t| t.triads(["AccelXMps2", "AccelYMps2", "AccelZMps2"], 1.0))
            .transpose()?,
    };
    // Rows: the gyro samples in time order, the first of any repeated time.
    let mut gyro = gyro;
    gyro.sort_by(|a, b| a.0.total_cmp(&b.0));
    gyro.dedup_by(|b, a| a.0 == b.0);
    if gyro.len() < 2 {
        return Err(bad(format!(
            "the log has fewer than two {gyro_kind} samples: a path needs a gyro"
        )));
    }
    let t0 = gyro[0].0;
    let n = gyro.len();
    let mut log = RideLog {
        source: file.to_string(),
        line: gyro.iter().map(|g| g.1).collect(),
        t_s: gyro.iter().map(|g| g.0 - t0).collect(),
        gyro_dps: gyro.iter().map(|g| g.2).collect(),
        fix: vec![None; n],
        metadata: BTreeMap::from([
            (
                "source".to_string(),
                format!("Android GnssLogger {file} ({gyro_kind})"),
            ),
            ("gyro_samples".to_string(), "instantaneous".to_string()),
            ("t0_boot_s".to_string(), format!("{t0:.6}")),
        ]),
        ..RideLog::default()
    };
    if let Some(accel) = accel {
        // Each accelerometer sample on the gyro row nearest it, within half
        // the gyro's median step (phones log the two at their own rates).
        let half = 0.5 / crate::signals::median_rate_hz(&log.t_s);
        let mut column = vec![None; n];
        for (t, _, a) in accel {
            let t = t - t0;
            let row = nearest_row(&log.t_s, t);
            if (log.t_s[row] - t).abs() <= half {
                column[row] = Some(a);
            }
        }
        log.accel_mps2 = Some(column);
    }
    let fixes = records
        .table("Fix", file)
        .ok_or_else(|| bad("the log has no Fix records: a path needs GNSS fixes".into()))?;
    let provider = fixes.index(&["Provider"])?;
    let of = |p: &str| {
        fixes
            .rows
            .iter()
            .filter(|r| r.values.get(provider).is_some_and(|v| v == p))
            .count()
    };
    let chosen = ["GPS", "FLP", "NLP"]
        .into_iter()
        .find(|p| of(p) > 0)
        .ok_or_else(|| bad("the log's Fix records name no GPS, FLP or NLP provider".into()))?;
    if chosen != "GPS" {
        log.warnings.push(format!(
            "{file}: the log has no fixes of the GPS provider; the {chosen} provider's are used ({}), whose errors are not a receiver's",
            if chosen == "FLP" {
                "Android's fused location, which already mixes in the phone's inertial sensors"
            } else {
                "network locations, tens to hundreds of metres off"
            }
        ));
    }
    let lat = fixes.index(&["LatitudeDegrees", "Latitude"])?;
    let lon = fixes.index(&["LongitudeDegrees", "Longitude"])?;
    let alt = fixes.index(&["AltitudeMeters", "Altitude"]).ok();
    let speed = fixes.index(&["SpeedMps", "Speed"]).ok();
    let bearing = fixes.index(&["BearingDegrees", "Bearing"]).ok();
    let accuracy = fixes.index(&["AccuracyMeters", "Accuracy"]).ok();
    let unix = fixes.index(&["UnixTimeMillis"])?;
    let boot = fixes.index(&["elapsedRealtimeNanos"]).map_err(|_| {
        bad("the Fix records have no elapsedRealtimeNanos (GnssLogger before v2.0): the fixes cannot be put on the sensors' clock".into())
    })?;
    let optional = |r: &Record, c: Option<usize>| c.map(|c| fixes.value(r, c)).transpose();
    let mut samples = Vec::new();
    for r in fixes
        .rows
        .iter()
        .filter(|r| r.values.get(provider).is_some_and(|v| v == chosen))
    {
        samples.push(GnssSample {
            t: fixes.required(r, boot)? * 1e-9 - t0,
            stamp: fixes.required(r, unix)? * 1e-3,
            lat: fixes.required(r, lat)?,
            lon: fixes.required(r, lon)?,
            alt: optional(r, alt)?.flatten(),
            speed: optional(r, speed)?.flatten(),
            course: optional(r, bearing)?.flatten(),
            hacc: optional(r, accuracy)?.flatten(),
            hdop: None,
            sats: None,
        });
    }
    samples.sort_by(|a, b| a.t.total_cmp(&b.t));
    let Some(first) = place_gnss(&mut log, &samples) else {
        return Err(bad(format!(
            "no {chosen} fix falls while the gyro runs ({:.0} s of {gyro_kind} samples): a path needs GNSS fixes",
            log.t_s[n - 1]
        )));
    };
    log.metadata
        .insert("t0_unix_s".into(), format!("{:.3}", first.stamp - first.t));
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "# Header Description:\n#\n# Version: v3.0.6.4 Platform: 14\n#\n\
# UncalGyro,utcTimeMillis,elapsedRealtimeNanos,UncalGyroXRadPerSec,UncalGyroYRadPerSec,UncalGyroZRadPerSec,DriftXRadPerSec,DriftYRadPerSec,DriftZRadPerSec\n\
# UncalAccel,utcTimeMillis,elapsedRealtimeNanos,UncalAccelXMps2,UncalAccelYMps2,UncalAccelZMps2,BiasXMps2,BiasYMps2,BiasZMps2\n\
# Fix,Provider,LatitudeDegrees,LongitudeDegrees,AltitudeMeters,SpeedMps,AccuracyMeters,BearingDegrees,UnixTimeMillis,SpeedAccuracyMps,BearingAccuracyDegrees,elapsedRealtimeNanos\n";

    /// A log of `seconds` at 10 Hz: a gyro turning at 0.1 rad/s about z,
    /// gravity on y, one GPS fix a second moving north at 5 m/s.
    fn log(seconds: usize) -> String {
        let mut s = HEAD.to_string();
        for k in 0..seconds * 10 {
            let ns = 5_000_000_000u64 + k as u64 * 100_000_000;
            s += &format!("UncalGyro,0,{ns},0.0,0.0,0.1,0,0,0\n");
            s += &format!("UncalAccel,0,{},0.0,9.81,0.0,0,0,0\n", ns + 10_000_000);
        }
        for k in 0..seconds {
            let ns = 5_050_000_000u64 + k as u64 * 1_000_000_000;
            let lat = 37.0 + k as f64 * 5.0 / 111_000.0;
            s += &format!(
                "Fix,GPS,{lat},-122.0,10.0,5.0,3.5,0.0,{},0.1,1.0,{ns}\n",
                1_700_000_000_000u64 + k as u64 * 1000
            );
            s += &format!(
                "Fix,NLP,{lat},-122.0,10.0,,15,,{},,,{ns}\n",
                1_700_000_000_000u64
            );
        }
        s
    }

    #[test]
    fn reads_rows_fixes_speed_and_clock() {
        let log = parse(log(10).as_bytes(), "phone.txt").unwrap();
        assert_eq!(log.len(), 100);
        assert!((log.gyro_dps[0][2] - 0.1f64.to_degrees()).abs() < 1e-9);
        assert_eq!(log.fix_count(), 10, "the GPS provider's fixes only");
        assert_eq!(log.gnss_speed_samples(), 10);
        let accel = log.accel_mps2.as_ref().unwrap();
        assert_eq!(accel.iter().flatten().count(), 100);
        assert_eq!(log.metadata["t0_boot_s"], "5.000000");
        assert_eq!(log.metadata["t0_unix_s"], "1699999999.950");
        assert!(log.warnings.is_empty());
        // Line numbers are the file's: the first gyro record is line 8.
        assert_eq!(log.line[0], 8);
    }

    #[test]
    fn bad_values_name_line_and_column() {
        let text = log(3).replacen("0.0,0.0,0.1", "0.0,x,0.1", 1);
        let e = parse(text.as_bytes(), "phone.txt").unwrap_err().to_string();
        assert_eq!(
            e,
            "phone.txt:8: column 'UncalGyroYRadPerSec': 'x' is not a finite number"
        );
    }

    #[test]
    fn a_log_without_gyro_or_fixes_says_what_is_missing() {
        let e = parse(without(&log(3), "UncalGyro").as_bytes(), "p.txt")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no gyro records"), "{e}");
        let nlp = parse(without(&log(3), "Fix,GPS").as_bytes(), "p.txt").unwrap();
        assert!(
            nlp.warnings[0].contains("NLP provider"),
            "{:?}",
            nlp.warnings
        );
        let e = parse(without(&log(3), "Fix,").as_bytes(), "p.txt")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no Fix records"), "{e}");
    }

    /// `text` without its record lines that start with `prefix`.
    fn without(text: &str, prefix: &str) -> String {
        text.lines()
            .filter(|l| !l.starts_with(prefix))
            .map(|l| format!("{l}\n"))
            .collect()
    }

    #[test]
    fn detects_its_header() {
        assert!(is_gnsslogger(b"# Header Description:\n#\n# Version: v3"));
        assert!(!is_gnsslogger(b"t_s,gyro_x_dps"));
    }
}
