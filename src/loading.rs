//! Reading a ride log (format: `shared/ride-log-format.md`, version 1).
//!
//! The loader keeps the columns as read (units of the file, empty fields as
//! `None`); everything derived from them lives in [`crate::signals`]. Every
//! rejection names the file, the 1-based line and the column, and nothing is
//! loaded from a bad file.

use std::collections::BTreeMap;
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

use thiserror::Error;

/// Why a ride log could not be loaded.
#[derive(Debug, Error)]
pub enum LoadError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: column '{column}': {message}")]
    Field {
        file: String,
        line: u64,
        column: String,
        message: String,
    },
    #[error("{file}:{line}: {message}")]
    Line {
        file: String,
        line: u64,
        message: String,
    },
    #[error("{file}: {message}")]
    File { file: String, message: String },
}

/// Raw columns of a ride log, in the file's units.
#[derive(Clone, Debug, Default)]
pub struct RideLog {
    /// Where it came from (for messages).
    pub source: String,
    /// `# key: value` comments before the header.
    pub metadata: BTreeMap<String, String>,
    /// 1-based line number of each data row in the file.
    pub line: Vec<u64>,
    pub t_s: Vec<f64>,
    /// Angular rate in deg/s, sensor frame (x forward, y left, z up).
    pub gyro_dps: Vec<[f64; 3]>,
    pub wheel_pulse: Option<Vec<bool>>,
    pub odo_m: Option<Vec<Option<f64>>>,
    /// (lat, lon) in degrees, `None` where the row has no fix.
    pub fix: Vec<Option<(f64, f64)>>,
    pub gps_alt_m: Option<Vec<Option<f64>>>,
    pub baro_alt_m: Option<Vec<Option<f64>>>,
    /// Extra numeric channels, by column name, in file order.
    pub channels: Vec<(String, Vec<Option<f64>>)>,
    /// Notes about the file that are not errors (dropped text columns, ...).
    pub warnings: Vec<String>,
}

impl RideLog {
    /// Give back the columns' growth slack (up to half of a long log's
    /// memory) before the signals are derived from them.
    fn shrink_to_fit(&mut self) {
        self.line.shrink_to_fit();
        self.t_s.shrink_to_fit();
        self.gyro_dps.shrink_to_fit();
        self.fix.shrink_to_fit();
        for c in [&mut self.odo_m, &mut self.gps_alt_m, &mut self.baro_alt_m]
            .into_iter()
            .flatten()
        {
            c.shrink_to_fit();
        }
        if let Some(p) = &mut self.wheel_pulse {
            p.shrink_to_fit();
        }
        for (_, c) in &mut self.channels {
            c.shrink_to_fit();
        }
    }

    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Configured wheel circumference, when the metadata gives one.
    pub fn wheel_circumference_m(&self) -> Option<&str> {
        self.metadata
            .get("wheel_circumference_m")
            .map(String::as_str)
    }
}

/// Load a ride log from a file.
pub fn load_file(path: &Path) -> Result<RideLog, LoadError> {
    let file = std::fs::File::open(path).map_err(|source| LoadError::Io {
        file: path.display().to_string(),
        source,
    })?;
    parse_reader(
        std::io::BufReader::with_capacity(1 << 20, file),
        &path.display().to_string(),
    )
}

/// Load a ride log from a path given as a string (convenience for callers).
pub fn load(path: impl Into<PathBuf>) -> Result<RideLog, LoadError> {
    load_file(&path.into())
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Known {
    T,
    Gx,
    Gy,
    Gz,
    Pulse,
    Odo,
    Lat,
    Lon,
    GpsAlt,
    Baro,
}

fn known(name: &str) -> Option<Known> {
    Some(match name {
        "t_s" => Known::T,
        "gx_dps" => Known::Gx,
        "gy_dps" => Known::Gy,
        "gz_dps" => Known::Gz,
        "wheel_pulse" => Known::Pulse,
        "odo_m" => Known::Odo,
        "lat_deg" => Known::Lat,
        "lon_deg" => Known::Lon,
        "gps_alt_m" => Known::GpsAlt,
        "baro_alt_m" => Known::Baro,
        _ => return None,
    })
}

/// Parse a ride log held in memory; `source` names it in messages.
pub fn parse(bytes: &[u8], source: &str) -> Result<RideLog, LoadError> {
    parse_reader(bytes, source)
}

/// Parse a ride log read from `input` (streamed: a large file is never held
/// in memory as text); `source` names it in errors.
pub fn parse_reader(mut input: impl BufRead, source: &str) -> Result<RideLog, LoadError> {
    let file = source.to_string();
    let field_err = |line: u64, column: &str, message: String| LoadError::Field {
        file: file.clone(),
        line,
        column: column.to_string(),
        message,
    };

    // Leading comment lines: metadata.
    let mut metadata = BTreeMap::new();
    let mut comment_lines = 0u64;
    let mut line = Vec::new();
    loop {
        line.clear();
        let read = input
            .read_until(b'\n', &mut line)
            .map_err(|e| LoadError::Line {
                file: file.clone(),
                line: comment_lines + 1,
                message: format!("cannot read: {e}"),
            })?;
        if read == 0 {
            return Err(LoadError::File {
                file,
                message: "no header row (the file holds no data)".into(),
            });
        }
        let text = if comment_lines == 0 {
            line.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&line)
        } else {
            &line[..]
        };
        let trimmed = text.trim_ascii();
        if !trimmed.is_empty() && trimmed[0] != b'#' {
            break;
        }
        if let Some(body) = trimmed.strip_prefix(b"#") {
            let body = std::str::from_utf8(body).map_err(|_| LoadError::Line {
                file: file.clone(),
                line: comment_lines + 1,
                message: "comment is not valid UTF-8".into(),
            })?;
            if let Some((k, v)) = body.split_once(':') {
                let key = k.trim();
                if !key.is_empty() && !key.contains(' ') {
                    metadata.insert(key.to_string(), v.trim().to_string());
                }
            }
        }
        comment_lines += 1;
    }
    // The header line just read, then the rest of the input.
    let header = if comment_lines == 0 {
        line.strip_prefix(b"\xEF\xBB\xBF")
            .map_or(line.clone(), <[u8]>::to_vec)
    } else {
        line
    };

    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .trim(csv::Trim::All)
        .from_reader(std::io::Cursor::new(header).chain(input));
    let header_line = comment_lines + 1;
    let headers = reader
        .byte_headers()
        .map_err(|e| LoadError::Line {
            file: file.clone(),
            line: header_line,
            message: format!("cannot read the header: {e}"),
        })?
        .clone();

    let mut columns: Vec<(String, Option<Known>)> = Vec::with_capacity(headers.len());
    for (i, h) in headers.iter().enumerate() {
        let name = std::str::from_utf8(h).map_err(|_| LoadError::Line {
            file: file.clone(),
            line: header_line,
            message: format!("header field {} is not valid UTF-8", i + 1),
        })?;
        let name = name.trim().to_string();
        if name.is_empty() {
            return Err(LoadError::Line {
                file: file.clone(),
                line: header_line,
                message: format!("header field {} is empty", i + 1),
            });
        }
        if columns.iter().any(|(n, _)| *n == name) {
            return Err(field_err(
                header_line,
                &name,
                "column appears twice in the header".into(),
            ));
        }
        let k = known(&name);
        columns.push((name, k));
    }
    let find = |k: Known| columns.iter().position(|(_, c)| *c == Some(k));
    let require = |k: Known, name: &str| {
        find(k).ok_or_else(|| {
            field_err(
                header_line,
                name,
                "required column is missing from the header".into(),
            )
        })
    };
    let c_t = require(Known::T, "t_s")?;
    let c_g = [
        require(Known::Gx, "gx_dps")?,
        require(Known::Gy, "gy_dps")?,
        require(Known::Gz, "gz_dps")?,
    ];
    let c_lat = require(Known::Lat, "lat_deg")?;
    let c_lon = require(Known::Lon, "lon_deg")?;
    let c_pulse = find(Known::Pulse);
    let c_odo = find(Known::Odo);
    if c_pulse.is_none() && c_odo.is_none() {
        return Err(field_err(
            header_line,
            "wheel_pulse",
            "the log needs a distance column: 'wheel_pulse' or 'odo_m'".into(),
        ));
    }
    let c_alt = find(Known::GpsAlt);
    let c_baro = find(Known::Baro);

    let mut log = RideLog {
        source: file.clone(),
        metadata,
        wheel_pulse: c_pulse.map(|_| Vec::new()),
        odo_m: c_odo.map(|_| Vec::new()),
        gps_alt_m: c_alt.map(|_| Vec::new()),
        baro_alt_m: c_baro.map(|_| Vec::new()),
        ..RideLog::default()
    };
    if c_pulse.is_some() {
        match log.wheel_circumference_m() {
            None => {
                return Err(LoadError::File {
                    file,
                    message: "the log has 'wheel_pulse' but no '# wheel_circumference_m: ...' metadata line".into(),
                });
            }
            Some(v) => match v.parse::<f64>() {
                Ok(c) if c.is_finite() && c > 0.0 => {}
                _ => {
                    return Err(LoadError::File {
                        file,
                        message: format!(
                            "metadata 'wheel_circumference_m' must be a positive number of metres, got '{v}'"
                        ),
                    });
                }
            },
        }
    }
    // Extra channels: numeric unless their first non-empty value is not a number.
    let extra: Vec<usize> = (0..columns.len())
        .filter(|&i| columns[i].1.is_none())
        .collect();
    let mut extra_state: Vec<Option<bool>> = vec![None; extra.len()]; // Some(true) numeric
    let mut extra_values: Vec<Vec<Option<f64>>> = vec![Vec::new(); extra.len()];

    let mut record = csv::ByteRecord::new();
    let mut prev_t = f64::NEG_INFINITY;
    loop {
        let more = reader.read_byte_record(&mut record).map_err(|e| {
            let line = e
                .position()
                .map_or(header_line, |p| p.line() + comment_lines);
            let message = match e.kind() {
                csv::ErrorKind::UnequalLengths {
                    expected_len, len, ..
                } => format!("row has {len} fields, the header has {expected_len}"),
                _ => format!("cannot read the row: {e}"),
            };
            LoadError::Line {
                file: file.clone(),
                line,
                message,
            }
        })?;
        if !more {
            break;
        }
        let line = record.position().map_or(0, |p| p.line()) + comment_lines;
        let text = |i: usize| -> Result<&str, LoadError> {
            std::str::from_utf8(&record[i])
                .map_err(|_| field_err(line, &columns[i].0, "value is not valid UTF-8".into()))
        };
        let number = |i: usize| -> Result<Option<f64>, LoadError> {
            let s = text(i)?;
            if s.is_empty() {
                return Ok(None);
            }
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(Some(v)),
                Ok(_) => Err(field_err(
                    line,
                    &columns[i].0,
                    format!("'{s}' is not a finite number"),
                )),
                Err(_) => Err(field_err(
                    line,
                    &columns[i].0,
                    format!("'{s}' is not a number"),
                )),
            }
        };
        let required = |i: usize| -> Result<f64, LoadError> {
            number(i)?.ok_or_else(|| {
                field_err(
                    line,
                    &columns[i].0,
                    "value is empty but the column needs one on every row".into(),
                )
            })
        };

        let t = required(c_t)?;
        if t <= prev_t {
            return Err(field_err(
                line,
                "t_s",
                format!("time {t} does not increase (previous row {prev_t})"),
            ));
        }
        prev_t = t;
        let g = [required(c_g[0])?, required(c_g[1])?, required(c_g[2])?];
        let lat = number(c_lat)?;
        let lon = number(c_lon)?;
        let fix = match (lat, lon) {
            (Some(la), Some(lo)) => {
                if !(-90.0..=90.0).contains(&la) {
                    return Err(field_err(
                        line,
                        "lat_deg",
                        format!("{la} is outside -90..90"),
                    ));
                }
                if !(-180.0..=360.0).contains(&lo) {
                    return Err(field_err(
                        line,
                        "lon_deg",
                        format!("{lo} is outside -180..360"),
                    ));
                }
                Some((la, lo))
            }
            (None, None) => None,
            (Some(_), None) => {
                return Err(field_err(
                    line,
                    "lon_deg",
                    "empty while lat_deg has a value".into(),
                ));
            }
            (None, Some(_)) => {
                return Err(field_err(
                    line,
                    "lat_deg",
                    "empty while lon_deg has a value".into(),
                ));
            }
        };
        if let (Some(c), Some(v)) = (c_pulse, log.wheel_pulse.as_mut()) {
            let state = match text(c)? {
                "0" => false,
                "1" => true,
                "" => v.last().copied().unwrap_or(false),
                s => {
                    return Err(field_err(
                        line,
                        "wheel_pulse",
                        format!("'{s}' is not 0 or 1"),
                    ));
                }
            };
            v.push(state);
        }
        if let (Some(c), Some(v)) = (c_odo, log.odo_m.as_mut()) {
            v.push(number(c)?);
        }
        if let (Some(c), Some(v)) = (c_alt, log.gps_alt_m.as_mut()) {
            v.push(number(c)?);
        }
        if let (Some(c), Some(v)) = (c_baro, log.baro_alt_m.as_mut()) {
            v.push(number(c)?);
        }
        for (k, &c) in extra.iter().enumerate() {
            match extra_state[k] {
                Some(false) => {}
                Some(true) => extra_values[k].push(number(c)?),
                None => {
                    let s = text(c)?;
                    if s.is_empty() {
                        extra_values[k].push(None);
                    } else if let Ok(v) = s.parse::<f64>() {
                        if !v.is_finite() {
                            return Err(field_err(
                                line,
                                &columns[c].0,
                                format!("'{s}' is not a finite number"),
                            ));
                        }
                        extra_state[k] = Some(true);
                        extra_values[k].push(Some(v));
                    } else {
                        extra_state[k] = Some(false);
                        log.warnings.push(format!(
                            "{file}:{line}: column '{}' holds text ('{s}'); it is ignored",
                            columns[c].0
                        ));
                    }
                }
            }
        }
        log.line.push(line);
        log.t_s.push(t);
        log.gyro_dps.push(g);
        log.fix.push(fix);
    }
    if log.t_s.is_empty() {
        return Err(LoadError::File {
            file,
            message: "the log has a header but no data rows".into(),
        });
    }
    for (k, &c) in extra.iter().enumerate() {
        if extra_state[k] != Some(false) {
            log.channels
                .push((columns[c].0.clone(), std::mem::take(&mut extra_values[k])));
        }
    }
    log.shrink_to_fit();
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "# gyropath ride log\n# wheel_circumference_m: 2.1180\nt_s,gx_dps,gy_dps,gz_dps,wheel_pulse,lat_deg,lon_deg,gps_alt_m,baro_alt_m,temp_c\n0.00,0.12250,-0.31500,0.28000,0,47.49788883,19.04019799,95.9,136.08,16.7\n0.01,0.17500,0.00875,0.23625,0,,,,136.01,16.6\n0.02,0.16625,-0.04375,0.19250,1,,,,136.05,16.6\n";

    #[test]
    fn reads_the_spec_example() {
        let log = parse(GOOD.as_bytes(), "ex.csv").unwrap();
        assert_eq!(log.len(), 3);
        assert_eq!(log.wheel_circumference_m(), Some("2.1180"));
        assert_eq!(log.line, vec![4, 5, 6]);
        assert_eq!(log.fix[0], Some((47.49788883, 19.04019799)));
        assert_eq!(log.fix[1], None);
        assert_eq!(log.wheel_pulse.as_ref().unwrap(), &vec![false, false, true]);
        assert_eq!(log.channels.len(), 1);
        assert_eq!(log.channels[0].0, "temp_c");
        assert_eq!(log.channels[0].1[2], Some(16.6));
        assert_eq!(log.baro_alt_m.as_ref().unwrap()[1], Some(136.01));
    }

    fn err(text: &str) -> String {
        parse(text.as_bytes(), "bad.csv").unwrap_err().to_string()
    }

    #[test]
    fn bad_inputs_name_file_line_and_column() {
        let e = err(&GOOD.replace("0.17500", "abc"));
        assert_eq!(e, "bad.csv:5: column 'gx_dps': 'abc' is not a number");
        let e = err(&GOOD.replace("0.17500", "NaN"));
        assert!(e.starts_with("bad.csv:5: column 'gx_dps'"), "{e}");
        let e = err(&GOOD.replace("0.02,", "0.01,"));
        assert!(
            e.starts_with("bad.csv:6: column 't_s': time 0.01 does not increase"),
            "{e}"
        );
        let e = err(&GOOD.replace("gz_dps,", "gq_dps,"));
        assert!(
            e.contains("bad.csv:3: column 'gz_dps': required column is missing"),
            "{e}"
        );
        let e = err(&GOOD.replace(",136.01,16.6", ",136.01"));
        assert!(e.starts_with("bad.csv:5:") && e.contains("fields"), "{e}");
        let e = err(&GOOD.replace("# wheel_circumference_m: 2.1180\n", ""));
        assert!(e.contains("wheel_circumference_m"), "{e}");
        let e = err(&GOOD.replace(",1,,,", ",2,,,"));
        assert!(e.starts_with("bad.csv:6: column 'wheel_pulse'"), "{e}");
        let e = err(&GOOD.replace("47.49788883,19.04019799", "47.49788883,"));
        assert!(e.starts_with("bad.csv:4: column 'lon_deg'"), "{e}");
        let e = err("# only comments\n");
        assert!(e.contains("no header"), "{e}");
        let e = err(GOOD.split("0.00,").next().unwrap());
        assert!(e.contains("no data rows"), "{e}");
    }

    #[test]
    fn text_extra_columns_are_dropped_with_a_warning() {
        let text = GOOD
            .replace("temp_c\n", "temp_c,note\n")
            .replace(",16.7\n", ",16.7,start\n")
            .replace(",16.6\n", ",16.6,x\n");
        let log = parse(text.as_bytes(), "n.csv").unwrap();
        assert_eq!(log.channels.len(), 1);
        assert_eq!(log.warnings.len(), 1);
    }
}
