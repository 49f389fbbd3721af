//! CSV exports of phones and custom loggers, read through a small TOML map
//! that names their columns, units and axes. GPS may sit in the same file
//! (rows with a fix) or in a second CSV joined by time; both become streams
//! joined on one timeline by [`super::timeline::join`], as bags are.
//!
//! ```toml
//! channels = ["temp_c"]        # extra columns to keep (top level: before the first table)
//!
//! [time]
//! column = "seconds_elapsed"   # required
//! unit = "s"                   # s, ms, us or ns
//! offset_s = 0.0               # added after the unit conversion
//!
//! [gyro]
//! columns = ["x", "y", "z"]    # the logged x, y and z
//! unit = "rad/s"               # rad/s or deg/s
//! axes = "gx = -y, gy = x, gz = z"   # optional: the mounting (default: as logged)
//! samples = "instantaneous"    # or "mean" (a mean over the step before the row)
//!
//! [accel]                      # optional
//! columns = ["ax", "ay", "az"]
//! unit = "m/s2"                # m/s2 or g
//!
//! [odometer]
//! kind = "speed"               # distance (cumulative m), speed, pulses (0/1 reed switch), ticks (cumulative)
//! column = "speed"
//! unit = "m/s"                 # speed: m/s, km/h, mph or knots; distance: m, km, ft or mi
//! circumference_m = 2.1        # pulses
//! ticks_per_m = 1000.0         # ticks
//! in_gps_file = false          # read the odometer column from the GPS file
//!
//! [gps]
//! lat = "latitude"
//! lon = "longitude"
//! alt = "altitude"             # optional
//! hacc = "horizontalAccuracy"  # optional, 1-sigma m
//! vacc = "verticalAccuracy"    # optional
//! hdop = "hdop"                # optional, the receiver's HDOP
//! sats = "satellites"          # optional, satellites used
//! time = "seconds_elapsed"     # the GPS file's time column (default: [time] column)
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::mount::Mount;
use super::timeline::{OdometerKind, Streams, join};
use super::wire::{FixMsg, ImuMsg, SpeedMsg};
use super::{LoadError, RideLog};

/// A column map.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ColumnMap {
    pub time: TimeMap,
    pub gyro: GyroMap,
    pub accel: Option<AccelMap>,
    pub odometer: OdometerMap,
    pub gps: GpsMap,
    #[serde(default)]
    pub channels: Vec<String>,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TimeMap {
    pub column: String,
    #[serde(default = "seconds")]
    pub unit: String,
    #[serde(default)]
    pub offset_s: f64,
}

fn seconds() -> String {
    "s".into()
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GyroMap {
    pub columns: [String; 3],
    pub unit: String,
    pub axes: Option<String>,
    pub samples: Option<String>,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AccelMap {
    pub columns: [String; 3],
    #[serde(default = "mps2")]
    pub unit: String,
}

fn mps2() -> String {
    "m/s2".into()
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OdometerMap {
    pub kind: String,
    pub column: String,
    pub unit: Option<String>,
    pub circumference_m: Option<f64>,
    pub ticks_per_m: Option<f64>,
    #[serde(default)]
    pub in_gps_file: bool,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GpsMap {
    pub lat: String,
    pub lon: String,
    pub alt: Option<String>,
    pub hacc: Option<String>,
    pub vacc: Option<String>,
    pub hdop: Option<String>,
    pub sats: Option<String>,
    pub time: Option<String>,
}

/// Read a column map.
pub fn read_map(path: &Path) -> Result<ColumnMap, LoadError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|error| LoadError::Io {
        file: file.clone(),
        error,
    })?;
    toml::from_str(&text).map_err(|e| LoadError::File {
        file,
        message: format!("not a column map: {}", e.to_string().trim()),
    })
}

/// A CSV read whole into named numeric columns (empty fields `None`), with line numbers.
struct Table {
    file: String,
    names: Vec<String>,
    lines: Vec<u64>,
    values: Vec<Vec<Option<f64>>>,
    /// The warning that the last line, cut short, is left out (see `csv_rows`).
    cut: Option<String>,
}

impl Table {
    /// Read the columns `wanted` (every one must exist) of the CSV at `path`.
    fn read(path: &Path, wanted: &[&str]) -> Result<Self, LoadError> {
        let (f, file) = super::open_file(path)?;
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(super::csv_rows::LastByte::new(
                std::io::BufReader::with_capacity(1 << 20, f),
            ));
        let headers = reader
            .headers()
            .map_err(|e| LoadError::Line {
                file: file.clone(),
                line: 1,
                message: format!("cannot read the header: {e}"),
            })?
            .clone();
        let header_line = leading_comments(path) + 1;
        let mut index = Vec::new();
        let mut names = Vec::new();
        for w in wanted {
            if names.iter().any(|n: &String| n == w) {
                continue;
            }
            let i = headers
                .iter()
                .position(|h| h == *w)
                .ok_or_else(|| LoadError::Field {
                    file: file.clone(),
                    line: header_line,
                    column: w.to_string(),
                    message: format!(
                        "the map names this column but the header has: {}",
                        headers.iter().collect::<Vec<_>>().join(", ")
                    ),
                })?;
            index.push(i);
            names.push(w.to_string());
        }
        let mut values = vec![Vec::new(); names.len()];
        let mut lines = Vec::new();
        let cut = super::csv_rows::each_record(
            &mut reader,
            |reader, record| {
                reader
                    .read_byte_record(record)
                    .map_err(|e| LoadError::Line {
                        file: file.clone(),
                        line: e.position().map_or(0, |p| p.line()),
                        message: format!("cannot read the row: {e}"),
                    })
            },
            |record, _| {
                let line = record.position().map_or(0, |p| p.line());
                let mut row = Vec::with_capacity(index.len());
                for (k, &i) in index.iter().enumerate() {
                    let s = std::str::from_utf8(record.get(i).unwrap_or(b"")).unwrap_or("?");
                    row.push(if s.is_empty() {
                        None
                    } else {
                        match s.parse::<f64>() {
                            Ok(v) if v.is_finite() => Some(v),
                            _ => {
                                return Err(LoadError::Field {
                                    file: file.clone(),
                                    line,
                                    column: names[k].clone(),
                                    message: format!("'{s}' is not a finite number"),
                                });
                            }
                        }
                    });
                }
                for (column, v) in values.iter_mut().zip(row) {
                    column.push(v);
                }
                lines.push(line);
                Ok(())
            },
        )?;
        if lines.is_empty() {
            return Err(LoadError::File {
                file,
                message: "the file has a header but no data rows".into(),
            });
        }
        Ok(Self {
            file,
            names,
            lines,
            values,
            cut,
        })
    }

    fn column(&self, name: &str) -> &[Option<f64>] {
        let k = self.names.iter().position(|n| n == name).unwrap_or(0);
        &self.values[k]
    }

    fn field_err(&self, row: usize, column: &str, message: String) -> LoadError {
        LoadError::Field {
            file: self.file.clone(),
            line: self.lines[row],
            column: column.to_string(),
            message,
        }
    }

    /// A column that needs a value on every row.
    fn required(&self, row: usize, name: &str) -> Result<f64, LoadError> {
        self.column(name)[row].ok_or_else(|| {
            self.field_err(row, name, "value is empty but needed on every row".into())
        })
    }

    /// Times in ns, increasing (a row repeating the previous time is dropped, one going back is refused).
    fn times(
        &self,
        column: &str,
        unit: &str,
        offset_s: f64,
    ) -> Result<Vec<Option<i64>>, LoadError> {
        let scale = match unit {
            "s" => 1e9,
            "ms" => 1e6,
            "us" => 1e3,
            "ns" => 1.0,
            other => {
                return Err(LoadError::File {
                    file: self.file.clone(),
                    message: format!("time unit '{other}' is none of s, ms, us, ns"),
                });
            }
        };
        let mut out = Vec::with_capacity(self.lines.len());
        let mut prev = i64::MIN;
        // The first repeated time as read, and the one before it.
        let mut repeated: Option<(usize, f64)> = None;
        let mut raw_prev = f64::NAN;
        for row in 0..self.lines.len() {
            let raw = self.required(row, column)?;
            let t = (raw * scale + offset_s * 1e9).round() as i64;
            if t == prev && repeated.is_none() {
                repeated = Some((row, raw_prev));
            }
            raw_prev = raw;
            if t < prev {
                return Err(self.field_err(
                    row,
                    column,
                    format!(
                        "time goes backwards ({} s after {} s)",
                        t as f64 * 1e-9,
                        prev as f64 * 1e-9
                    ),
                ));
            }
            out.push((t > prev).then_some(t));
            prev = t;
        }
        // Most rows on the time of the row before: the column is too coarse
        // for its rows, and dropping them would leave a log of a few.
        let dropped = out.iter().filter(|t| t.is_none()).count();
        if let Some((row, before)) = repeated.filter(|_| 2 * dropped > out.len()) {
            return Err(self.field_err(
                row,
                column,
                format!(
                    "{dropped} of {} rows repeat the time of the row before ({before} {unit}): the column is too coarse for its rows{}",
                    out.len(),
                    super::ride_csv::coarse_time_hint(before, before, unit)
                ),
            ));
        }
        Ok(out)
    }
}

/// How many lines before the header are `#` comments (the csv reader skips them unnumbered).
fn leading_comments(path: &Path) -> u64 {
    use std::io::BufRead;
    let Ok(f) = std::fs::File::open(path) else {
        return 0;
    };
    std::io::BufReader::new(f)
        .lines()
        .map_while(Result::ok)
        .take_while(|l| l.trim_start().starts_with('#'))
        .count() as u64
}

fn unit_factor(what: &str, unit: &str, known: &[(&str, f64)]) -> Result<f64, String> {
    known
        .iter()
        .find(|(u, _)| *u == unit)
        .map(|&(_, f)| f)
        .ok_or_else(|| {
            format!(
                "{what} unit '{unit}' is none of {}",
                known.iter().map(|(u, _)| *u).collect::<Vec<_>>().join(", ")
            )
        })
}

/// Load a mapped CSV (and its GPS file) as a ride log.
pub fn load(path: &Path, gps_path: Option<&Path>, map_path: &Path) -> Result<RideLog, LoadError> {
    let map = read_map(map_path)?;
    let map_err = |message: String| LoadError::File {
        file: map_path.display().to_string(),
        message,
    };
    let gyro_scale = unit_factor(
        "gyro",
        &map.gyro.unit,
        &[("rad/s", 1.0), ("deg/s", std::f64::consts::PI / 180.0)],
    )
    .map_err(map_err)?;
    let mount: Option<Mount> = map
        .gyro
        .axes
        .as_deref()
        .map(str::parse)
        .transpose()
        .map_err(|e| map_err(format!("gyro axes: {e}")))?;
    let mean_samples = match map.gyro.samples.as_deref() {
        None | Some("instantaneous") => false,
        Some("mean") => true,
        Some(other) => {
            return Err(map_err(format!(
                "gyro samples '{other}' is neither instantaneous nor mean"
            )));
        }
    };
    let accel_scale = map
        .accel
        .as_ref()
        .map(|a| unit_factor("accelerometer", &a.unit, &[("m/s2", 1.0), ("g", 9.80665)]))
        .transpose()
        .map_err(map_err)?;
    let odo = &map.odometer;
    let (odo_kind, odo_scale) = match odo.kind.as_str() {
        "speed" => (
            OdometerKind::Speed,
            unit_factor(
                "speed",
                odo.unit.as_deref().unwrap_or("m/s"),
                &[
                    ("m/s", 1.0),
                    ("km/h", 1.0 / 3.6),
                    ("mph", 0.44704),
                    ("knots", 0.514_444),
                ],
            )
            .map_err(map_err)?,
        ),
        "distance" => (
            OdometerKind::Distance,
            unit_factor(
                "distance",
                odo.unit.as_deref().unwrap_or("m"),
                &[("m", 1.0), ("km", 1000.0), ("ft", 0.3048), ("mi", 1609.344)],
            )
            .map_err(map_err)?,
        ),
        "ticks" => (
            OdometerKind::Distance,
            1.0 / odo
                .ticks_per_m
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| {
                    map_err("odometer kind 'ticks' needs a positive ticks_per_m".into())
                })?,
        ),
        "pulses" => (
            OdometerKind::Distance,
            odo.circumference_m
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| {
                    map_err("odometer kind 'pulses' needs a positive circumference_m".into())
                })?,
        ),
        other => {
            return Err(map_err(format!(
                "odometer kind '{other}' is none of distance, speed, pulses, ticks"
            )));
        }
    };
    if odo.in_gps_file && gps_path.is_none() {
        return Err(map_err(
            "the odometer is in the GPS file, but no GPS file is given (--gps)".into(),
        ));
    }

    // The main file: time, gyro, accelerometer, channels; GPS and odometer when they are here.
    let mut wanted: Vec<&str> = vec![&map.time.column];
    wanted.extend(map.gyro.columns.iter().map(String::as_str));
    if let Some(a) = &map.accel {
        wanted.extend(a.columns.iter().map(String::as_str));
    }
    wanted.extend(map.channels.iter().map(String::as_str));
    let gps_columns: Vec<&str> = [
        Some(&map.gps.lat),
        Some(&map.gps.lon),
        map.gps.alt.as_ref(),
        map.gps.hacc.as_ref(),
        map.gps.vacc.as_ref(),
        map.gps.hdop.as_ref(),
        map.gps.sats.as_ref(),
    ]
    .into_iter()
    .flatten()
    .map(String::as_str)
    .collect();
    if gps_path.is_none() {
        wanted.extend(&gps_columns);
    }
    if !odo.in_gps_file {
        wanted.push(&odo.column);
    }
    let main = Table::read(path, &wanted)?;
    let times = main.times(&map.time.column, &map.time.unit, map.time.offset_s)?;
    let mut streams = Streams {
        source: path.display().to_string(),
        odometer_kind: Some(odo_kind),
        mean_samples,
        names: [
            format!("{} (gyro)", main.file),
            format!(
                "{} column '{}'",
                if odo.in_gps_file {
                    "GPS file"
                } else {
                    "main file"
                },
                odo.column
            ),
            format!(
                "{} (GPS)",
                gps_path.map_or(main.file.clone(), |p| p.display().to_string())
            ),
        ],
        ..Streams::default()
    };
    streams.warnings.extend(main.cut.clone());
    let dropped = times.iter().filter(|t| t.is_none()).count();
    if dropped > 0 {
        streams.warnings.push(format!(
            "{}: {dropped} row(s) repeat the time of the row before and are dropped",
            main.file
        ));
    }
    for (row, t) in times.iter().enumerate() {
        let Some(t_ns) = *t else { continue };
        let mut g = [0.0; 3];
        for (i, gi) in g.iter_mut().enumerate() {
            *gi = main.required(row, &map.gyro.columns[i])? * gyro_scale;
        }
        let acc = match (&map.accel, accel_scale) {
            (Some(a), Some(s)) => {
                let c = [0, 1, 2].map(|i| main.column(&a.columns[i])[row]);
                match c {
                    [Some(x), Some(y), Some(z)] => Some([x * s, y * s, z * s]),
                    _ => None,
                }
            }
            _ => None,
        };
        streams.imu.push(ImuMsg {
            t_ns,
            angular_velocity: g,
            linear_acceleration: acc,
        });
    }
    let gps_table;
    let (gps, gps_times) = match gps_path {
        Some(p) => {
            let time_col = map.gps.time.as_deref().unwrap_or(&map.time.column);
            let mut w: Vec<&str> = vec![time_col];
            w.extend(&gps_columns);
            if odo.in_gps_file {
                w.push(&odo.column);
            }
            gps_table = Table::read(p, &w)?;
            streams.warnings.extend(gps_table.cut.clone());
            let t = gps_table.times(time_col, &map.time.unit, map.time.offset_s)?;
            (&gps_table, t)
        }
        None => (&main, times.clone()),
    };
    for (row, t) in gps_times.iter().enumerate() {
        let Some(t_ns) = *t else { continue };
        let (Some(lat), Some(lon)) = (gps.column(&map.gps.lat)[row], gps.column(&map.gps.lon)[row])
        else {
            continue;
        };
        let opt = |c: &Option<String>| c.as_ref().and_then(|c| gps.column(c)[row]);
        let acc = |c: &Option<String>| opt(c).filter(|v| *v > 0.0);
        streams.fixes.push(FixMsg {
            t_ns,
            status: 0,
            lat,
            lon,
            alt: opt(&map.gps.alt).unwrap_or(f64::NAN),
            hacc: acc(&map.gps.hacc),
            vacc: acc(&map.gps.vacc),
            hdop: opt(&map.gps.hdop),
            sats: opt(&map.gps.sats),
        });
    }
    let (odo_table, odo_times) = if odo.in_gps_file {
        (gps, &gps_times)
    } else {
        (&main, &times)
    };
    let mut raw: Vec<(i64, f64)> = odo_times
        .iter()
        .zip(odo_table.column(&odo.column))
        .filter_map(|(t, v)| Some(((*t)?, (*v)?)))
        .collect();
    // A speed from the GPS file is the receiver's ground speed, which has
    // no sign: a negative one is its "none" (iOS writes -1), not reversing.
    if odo.in_gps_file && odo.kind == "speed" {
        let before = raw.len();
        raw.retain(|&(_, v)| v >= 0.0);
        if raw.len() < before {
            streams.warnings.push(format!(
                "{}: {} negative value(s) of the GPS file's speed column '{}' left out: a ground speed has no sign (iOS writes -1 where it has none)",
                odo_table.file,
                before - raw.len(),
                odo.column
            ));
        }
    }
    if odo.kind == "pulses" {
        // Reed-switch states: each rising edge is one revolution (the ride-log rule).
        let t: Vec<f64> = raw.iter().map(|&(t, _)| t as f64 * 1e-9).collect();
        let states: Vec<bool> = raw.iter().map(|&(_, v)| v > 0.5).collect();
        let (d, _) = crate::signals::distance_from_pulses(&t, &states, 1.0);
        let mut s = 0.0;
        for (&(t_ns, _), dj) in raw.iter().zip(d) {
            s += dj * odo_scale;
            streams.odometer.push(SpeedMsg {
                t_ns,
                speed: s,
                yaw_rate: 0.0,
            });
        }
    } else {
        streams.odometer = raw
            .iter()
            .map(|&(t_ns, v)| SpeedMsg {
                t_ns,
                speed: v * odo_scale,
                yaw_rate: 0.0,
            })
            .collect();
    }
    let mut log = join(streams)?;
    // Extra channels, interpolated at the rows' times.
    let t0 = log.t0_unix_s().unwrap_or(0.0);
    for name in &map.channels {
        let samples: Vec<(f64, f64)> = times
            .iter()
            .zip(main.column(name))
            .filter_map(|(t, v)| Some(((*t)? as f64 * 1e-9 - t0, (*v)?)))
            .collect();
        log.channels
            .push((name.clone(), resample(&samples, &log.t_s)));
    }
    let mut meta: BTreeMap<String, String> = BTreeMap::new();
    meta.insert(
        "source".into(),
        format!("mapped CSV {} with map {}", main.file, map_path.display()),
    );
    if let Some(g) = gps_path {
        meta.insert("gps_source".into(), g.display().to_string());
    }
    log.metadata.extend(meta);
    if let Some(m) = mount.filter(|m| !m.is_identity()) {
        m.apply(&mut log);
    }
    Ok(log)
}

/// Linear interpolation of `(t, value)` samples at `times` (`None` outside them).
fn resample(samples: &[(f64, f64)], times: &[f64]) -> Vec<Option<f64>> {
    let mut k = 0usize;
    times
        .iter()
        .map(|&t| {
            while k + 1 < samples.len() && samples[k + 1].0 <= t {
                k += 1;
            }
            let a = samples.get(k)?;
            match samples.get(k + 1) {
                Some(b) if a.0 <= t => Some(a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)),
                _ if (a.0 - t).abs() < 1e-9 => Some(a.1),
                _ => None,
            }
        })
        .collect()
}
