//! The ride-log CSV (format: `data/ride-log-format.md`, version 1): read in
//! three parts that each read on their own ([`read_metadata`] for the comment
//! lines, [`Columns::bind`] for the header, [`RowReader`] for the rows), and
//! written back by [`write`] (what `gyropath import` produces).
//!
//! The reader keeps the columns as read (units of the file, empty fields as
//! `None`); everything derived from them lives in [`crate::signals`]. Every
//! rejection names the file, the 1-based line and the column, and nothing is
//! loaded from a bad file.

use std::collections::BTreeMap;
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};

use super::{LoadError, RideLog};

/// Load a ride log from a file.
pub fn load_file(path: &Path) -> Result<RideLog, LoadError> {
    let (f, file) = super::open_file(path)?;
    parse_reader(std::io::BufReader::with_capacity(1 << 20, f), &file)
}

/// Load a ride log from a path given as a string (convenience for callers).
pub fn load(path: impl Into<PathBuf>) -> Result<RideLog, LoadError> {
    load_file(&path.into())
}

/// Parse a ride log held in memory; `source` names it in messages.
pub fn parse(bytes: &[u8], source: &str) -> Result<RideLog, LoadError> {
    parse_reader(bytes, source)
}

/// Parse a ride log read from `input` (streamed: a large file is never held
/// in memory as text); `source` names it in errors.
pub fn parse_reader(mut input: impl BufRead, source: &str) -> Result<RideLog, LoadError> {
    let head = read_metadata(&mut input, source)?;
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(delimiter(&head.header))
        .has_headers(true)
        .flexible(false)
        .trim(csv::Trim::All)
        .from_reader(super::csv_rows::LastByte::new(
            std::io::Cursor::new(head.header).chain(input),
        ));
    let header_line = head.comment_lines + 1;
    let headers = reader
        .byte_headers()
        .map_err(|e| LoadError::Line {
            file: source.to_string(),
            line: header_line,
            message: format!("cannot read the header: {e}"),
        })?
        .clone();
    let columns = Columns::bind(&headers, source, header_line)?;
    check_circumference(&columns, &head.metadata, source)?;
    let mut rows = RowReader::new(&columns, source, head.comment_lines, head.metadata);
    let comment_lines = head.comment_lines;
    let cut = super::csv_rows::each_record(
        &mut reader,
        |reader, record| read_row(reader, record, source, comment_lines),
        |record, before| rows.push(record, before),
    )?;
    rows.log.warnings.extend(cut);
    rows.finish()
}

/// The field separator of a log whose header is `header`: a comma, or
/// where the header has none, a tab or a semicolon (the exports of
/// spreadsheets set to a language that writes decimal commas).
fn delimiter(header: &[u8]) -> u8 {
    if header.contains(&b',') {
        b','
    } else if header.contains(&b'\t') {
        b'\t'
    } else if header.contains(&b';') {
        b';'
    } else {
        b','
    }
}

/// `'s' is not a number`, and where `s` has a comma, that a decimal comma is
/// not read (a spreadsheet's export in a language that writes them).
fn not_a_number(s: &str) -> String {
    if s.contains(',') {
        format!("'{s}' is not a number (a decimal comma? numbers take a decimal point)")
    } else {
        format!("'{s}' is not a number")
    }
}

/// The comment lines before the header, and the header line itself.
struct Head {
    metadata: BTreeMap<String, String>,
    comment_lines: u64,
    header: Vec<u8>,
}

/// Read the leading `#` lines (`# key: value` is metadata) up to the header.
fn read_metadata(input: &mut impl BufRead, file: &str) -> Result<Head, LoadError> {
    let mut metadata = BTreeMap::new();
    let mut comment_lines = 0u64;
    let mut line = Vec::new();
    loop {
        line.clear();
        let read = input
            .read_until(b'\n', &mut line)
            .map_err(|e| LoadError::Line {
                file: file.to_string(),
                line: comment_lines + 1,
                message: format!("cannot read: {e}"),
            })?;
        if read == 0 {
            return Err(LoadError::File {
                file: file.to_string(),
                message: "no header row (the file holds no data)".into(),
            });
        }
        if comment_lines == 0
            && let Some(rest) = line.strip_prefix(b"\xEF\xBB\xBF")
        {
            line = rest.to_vec();
        }
        let trimmed = line.trim_ascii();
        if !trimmed.is_empty() && trimmed[0] != b'#' {
            return Ok(Head {
                metadata,
                comment_lines,
                header: line,
            });
        }
        if let Some(body) = trimmed.strip_prefix(b"#") {
            let body = std::str::from_utf8(body).map_err(|_| LoadError::Line {
                file: file.to_string(),
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
}

/// The columns the format knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Known {
    T,
    Gx,
    Gy,
    Gz,
    Pulse,
    Odo,
    Speed,
    Lat,
    Lon,
    GpsAlt,
    GpsSpeed,
    GpsCourse,
    Hacc,
    Vacc,
    Hdop,
    Sats,
    Baro,
    Ax,
    Ay,
    Az,
}

/// What the format takes as a receiver's HDOP (`gps_hdop`) and satellite
/// count (`gps_num_sats`, a whole number): a reader of another format
/// leaves out what lies outside (a receiver's 0 for "unknown", say).
pub(crate) const HDOP_RANGE: std::ops::RangeInclusive<f64> = 0.1..=100.0;
pub(crate) const SATS_RANGE: std::ops::RangeInclusive<f64> = 0.0..=255.0;

/// Names of the known columns, in the order [`write`] writes them.
const KNOWN: [(&str, Known); 20] = [
    ("t_s", Known::T),
    ("gx_dps", Known::Gx),
    ("gy_dps", Known::Gy),
    ("gz_dps", Known::Gz),
    ("wheel_pulse", Known::Pulse),
    ("odo_m", Known::Odo),
    ("speed_mps", Known::Speed),
    ("lat_deg", Known::Lat),
    ("lon_deg", Known::Lon),
    ("gps_alt_m", Known::GpsAlt),
    ("gps_speed_mps", Known::GpsSpeed),
    ("gps_course_deg", Known::GpsCourse),
    ("gps_hacc_m", Known::Hacc),
    ("gps_vacc_m", Known::Vacc),
    ("gps_hdop", Known::Hdop),
    ("gps_num_sats", Known::Sats),
    ("baro_alt_m", Known::Baro),
    ("ax_mps2", Known::Ax),
    ("ay_mps2", Known::Ay),
    ("az_mps2", Known::Az),
];

fn known(name: &str) -> Option<Known> {
    KNOWN.iter().find(|(n, _)| *n == name).map(|&(_, k)| k)
}

/// Why column `name` is missing from a header of `names`, with what may
/// stand for it: the same name in other letter case or with a unit
/// suffix left off ("T_S", "gx"), or else the header's own names and how
/// a CSV of another layout is read.
fn missing_column(name: &str, names: &[String]) -> String {
    let stem = name.rsplit_once('_').map_or(name, |(stem, _)| stem);
    let near = names
        .iter()
        .find(|n| n.eq_ignore_ascii_case(name) || (stem != name && n.eq_ignore_ascii_case(stem)));
    match near {
        Some(n) => format!(
            "required column is missing from the header, which has '{n}': the format's column names are lower case and end in their unit, as '{name}'"
        ),
        None => {
            let shown: Vec<&str> = names.iter().take(12).map(String::as_str).collect();
            format!(
                "required column is missing from the header ({}{}); a CSV of another layout is read with a column map: --map FILE.toml (docs/real-logs.md)",
                shown.join(", "),
                if names.len() > shown.len() {
                    ", ..."
                } else {
                    ""
                }
            )
        }
    }
}

/// Where each column sits in a row.
struct Columns {
    names: Vec<String>,
    t: usize,
    gyro: [usize; 3],
    lat: usize,
    lon: usize,
    pulse: Option<usize>,
    odo: Option<usize>,
    speed: Option<usize>,
    alt: Option<usize>,
    gps_speed: Option<usize>,
    gps_course: Option<usize>,
    hacc: Option<usize>,
    vacc: Option<usize>,
    hdop: Option<usize>,
    sats: Option<usize>,
    baro: Option<usize>,
    accel: Option<[usize; 3]>,
    /// Columns the format does not know: extra channels.
    extra: Vec<usize>,
}

impl Columns {
    /// Bind the header's names to the format's columns.
    fn bind(headers: &csv::ByteRecord, file: &str, line: u64) -> Result<Self, LoadError> {
        let field_err = |column: &str, message: String| LoadError::Field {
            file: file.to_string(),
            line,
            column: column.to_string(),
            message,
        };
        let line_err = |message: String| LoadError::Line {
            file: file.to_string(),
            line,
            message,
        };
        let mut names: Vec<String> = Vec::with_capacity(headers.len());
        for (i, h) in headers.iter().enumerate() {
            let name = std::str::from_utf8(h)
                .map_err(|_| line_err(format!("header field {} is not valid UTF-8", i + 1)))?
                .trim()
                .to_string();
            if name.is_empty() {
                return Err(line_err(format!("header field {} is empty", i + 1)));
            }
            if names.contains(&name) {
                return Err(field_err(
                    &name,
                    "column appears twice in the header".into(),
                ));
            }
            names.push(name);
        }
        let find = |k: Known| names.iter().position(|n| known(n) == Some(k));
        let require = |k: Known, name: &str| {
            find(k).ok_or_else(|| field_err(name, missing_column(name, &names)))
        };
        let t = require(Known::T, "t_s")?;
        let no_gyro = [Known::Gx, Known::Gy, Known::Gz]
            .iter()
            .all(|&k| find(k).is_none());
        if no_gyro && find(Known::Lat).is_some() && find(Known::Lon).is_some() {
            // A `truth.csv` beside a ride, opened as one: say what it is.
            return Err(field_err(
                "gx_dps",
                format!(
                    "a track of positions without a gyro (t_s, lat_deg, lon_deg): it can be the reference track of a ride that has one (--reference {file}, File > Open reference track), or the fixes of a gyro log without GPS (--gps-track {file}); a ride log needs the gyro columns gx_dps, gy_dps, gz_dps"
                ),
            ));
        }
        let gyro = [
            require(Known::Gx, "gx_dps")?,
            require(Known::Gy, "gy_dps")?,
            require(Known::Gz, "gz_dps")?,
        ];
        let lat = require(Known::Lat, "lat_deg")?;
        let lon = require(Known::Lon, "lon_deg")?;
        let (pulse, odo, speed) = (find(Known::Pulse), find(Known::Odo), find(Known::Speed));
        let gps_speed = find(Known::GpsSpeed);
        if pulse.is_none() && odo.is_none() && speed.is_none() && gps_speed.is_none() {
            return Err(field_err(
                "wheel_pulse",
                "the log needs a distance column: 'wheel_pulse', 'odo_m', 'speed_mps' or 'gps_speed_mps'".into(),
            ));
        }
        let accel = match (find(Known::Ax), find(Known::Ay), find(Known::Az)) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            (None, None, None) => None,
            (x, y, _) => {
                let missing = if x.is_none() {
                    "ax_mps2"
                } else if y.is_none() {
                    "ay_mps2"
                } else {
                    "az_mps2"
                };
                return Err(field_err(
                    missing,
                    "the accelerometer needs all three columns ax_mps2, ay_mps2, az_mps2".into(),
                ));
            }
        };
        let extra = (0..names.len())
            .filter(|&i| known(&names[i]).is_none())
            .collect();
        Ok(Self {
            t,
            gyro,
            lat,
            lon,
            pulse,
            odo,
            speed,
            alt: find(Known::GpsAlt),
            gps_speed,
            gps_course: find(Known::GpsCourse),
            hacc: find(Known::Hacc),
            vacc: find(Known::Vacc),
            hdop: find(Known::Hdop),
            sats: find(Known::Sats),
            baro: find(Known::Baro),
            accel,
            extra,
            names,
        })
    }
}

/// A log with `wheel_pulse` needs a positive `wheel_circumference_m`.
fn check_circumference(
    columns: &Columns,
    metadata: &BTreeMap<String, String>,
    file: &str,
) -> Result<(), LoadError> {
    if columns.pulse.is_none() {
        return Ok(());
    }
    let err = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    match metadata.get("wheel_circumference_m") {
        None => Err(err(
            "the log has 'wheel_pulse' but no '# wheel_circumference_m: ...' metadata line".into(),
        )),
        Some(v) => match v.parse::<f64>() {
            Ok(c) if c.is_finite() && c > 0.0 => Ok(()),
            _ => Err(err(format!(
                "metadata 'wheel_circumference_m' must be a positive number of metres, got '{v}'"
            ))),
        },
    }
}

/// Read the next record of a log whose header follows `comment_lines`
/// comments; `false` at the end of the input.
fn read_row(
    reader: &mut csv::Reader<impl Read>,
    record: &mut csv::ByteRecord,
    file: &str,
    comment_lines: u64,
) -> Result<bool, LoadError> {
    reader.read_byte_record(record).map_err(|e| {
        let line = e
            .position()
            .map_or(comment_lines + 1, |p| p.line() + comment_lines);
        let message = match e.kind() {
            csv::ErrorKind::UnequalLengths {
                expected_len, len, ..
            } => format!("row has {len} fields, the header has {expected_len}"),
            _ => format!("cannot read the row: {e}"),
        };
        LoadError::Line {
            file: file.to_string(),
            line,
            message,
        }
    })
}

/// Parses rows one at a time into the columns of a [`RideLog`].
struct RowReader<'c> {
    columns: &'c Columns,
    file: String,
    comment_lines: u64,
    log: RideLog,
    /// Per extra column: `Some(true)` numeric, `Some(false)` text (dropped), `None` not yet known.
    extra_numeric: Vec<Option<bool>>,
    extra_values: Vec<Vec<Option<f64>>>,
    prev_t: f64,
    repeats: Repeats,
}

/// Rows that repeat the row before them exactly, field by field: a logger
/// that wrote a buffer twice (SD-card loggers do on a slow card), or an
/// export appended twice. They hold nothing new, so they are dropped and
/// counted; a row at the same time with other values is still an error,
/// since which of the two holds is not known.
#[derive(Default)]
struct Repeats {
    count: usize,
    first_line: u64,
}

impl<'c> RowReader<'c> {
    fn new(
        columns: &'c Columns,
        file: &str,
        comment_lines: u64,
        metadata: BTreeMap<String, String>,
    ) -> Self {
        fn some_if<T>(c: Option<usize>) -> Option<Vec<T>> {
            c.map(|_| Vec::new())
        }
        let log = RideLog {
            source: file.to_string(),
            metadata,
            wheel_pulse: some_if(columns.pulse),
            odo_m: some_if(columns.odo),
            speed_mps: some_if(columns.speed),
            gps_alt_m: some_if(columns.alt),
            gps_speed_mps: some_if(columns.gps_speed),
            gps_course_deg: some_if(columns.gps_course),
            gps_hacc_m: some_if(columns.hacc),
            gps_vacc_m: some_if(columns.vacc),
            gps_hdop: some_if(columns.hdop),
            gps_num_sats: some_if(columns.sats),
            baro_alt_m: some_if(columns.baro),
            accel_mps2: columns.accel.map(|_| Vec::new()),
            ..RideLog::default()
        };
        Self {
            columns,
            file: file.to_string(),
            comment_lines,
            log,
            extra_numeric: vec![None; columns.extra.len()],
            extra_values: vec![Vec::new(); columns.extra.len()],
            prev_t: f64::NEG_INFINITY,
            repeats: Repeats::default(),
        }
    }

    fn field_err(&self, line: u64, column: &str, message: String) -> LoadError {
        LoadError::Field {
            file: self.file.clone(),
            line,
            column: column.to_string(),
            message,
        }
    }

    /// Parse one row into the log; `before` is the row read before it.
    fn push(
        &mut self,
        record: &csv::ByteRecord,
        before: Option<&csv::ByteRecord>,
    ) -> Result<(), LoadError> {
        let c = self.columns;
        let line = record.position().map_or(0, |p| p.line()) + self.comment_lines;
        let row = Row {
            record,
            line,
            reader: self,
        };
        let t = row.required(c.t)?;
        if t == self.prev_t && before.is_some_and(|b| b.iter().eq(record.iter())) {
            if self.repeats.count == 0 {
                self.repeats.first_line = line;
            }
            self.repeats.count += 1;
            return Ok(());
        }
        if t <= self.prev_t {
            return Err(self.field_err(
                line,
                "t_s",
                format!(
                    "time {t} does not increase (previous row {}){}",
                    self.prev_t,
                    coarse_time_hint(t, self.prev_t, "s")
                ),
            ));
        }
        let g = match [
            row.number(c.gyro[0])?,
            row.number(c.gyro[1])?,
            row.number(c.gyro[2])?,
        ] {
            [Some(x), Some(y), Some(z)] => [x, y, z],
            [None, None, None] => [f64::NAN; 3],
            _ => [
                row.required(c.gyro[0])?,
                row.required(c.gyro[1])?,
                row.required(c.gyro[2])?,
            ],
        };
        let fix = row.fix()?;
        let pulse = match c.pulse {
            Some(i) => Some(match row.text(i)? {
                "0" => false,
                "1" => true,
                "" => self
                    .log
                    .wheel_pulse
                    .as_ref()
                    .and_then(|v| v.last().copied())
                    .unwrap_or(false),
                s => {
                    return Err(self.field_err(
                        line,
                        "wheel_pulse",
                        format!("'{s}' is not 0 or 1"),
                    ));
                }
            }),
            None => None,
        };
        let optional = |i: Option<usize>| i.map(|i| row.number(i)).transpose();
        let odo = optional(c.odo)?;
        let speed = optional(c.speed)?;
        let alt = optional(c.alt)?;
        let baro = optional(c.baro)?;
        let gps_speed = row.in_range(c.gps_speed, 0.0..=1000.0, "a ground speed in m/s")?;
        let gps_course = row.in_range(c.gps_course, -360.0..=360.0, "a course in degrees")?;
        let hacc = row.accuracy(c.hacc)?;
        let vacc = row.accuracy(c.vacc)?;
        let hdop = row.in_range(c.hdop, HDOP_RANGE, "a dilution of precision")?;
        let sats = row.in_range(c.sats, SATS_RANGE, "a number of satellites")?;
        if let Some(Some(n)) = sats
            && n.fract() != 0.0
        {
            return Err(self.field_err(
                line,
                "gps_num_sats",
                format!("{n} is not a whole number of satellites"),
            ));
        }
        let accel = match c.accel {
            Some(a) => Some(
                match (row.number(a[0])?, row.number(a[1])?, row.number(a[2])?) {
                    (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                    _ => None,
                },
            ),
            None => None,
        };
        let extra = self.extra_row(record, line)?;
        let log = &mut self.log;
        for (column, value) in [
            (&mut log.odo_m, odo),
            (&mut log.speed_mps, speed),
            (&mut log.gps_alt_m, alt),
            (&mut log.gps_speed_mps, gps_speed),
            (&mut log.gps_course_deg, gps_course),
            (&mut log.baro_alt_m, baro),
            (&mut log.gps_hacc_m, hacc),
            (&mut log.gps_vacc_m, vacc),
            (&mut log.gps_hdop, hdop),
            (&mut log.gps_num_sats, sats),
        ] {
            if let (Some(col), Some(v)) = (column.as_mut(), value) {
                col.push(v);
            }
        }
        if let (Some(col), Some(p)) = (log.wheel_pulse.as_mut(), pulse) {
            col.push(p);
        }
        if let (Some(col), Some(a)) = (log.accel_mps2.as_mut(), accel) {
            col.push(a);
        }
        for (values, v) in self.extra_values.iter_mut().zip(extra) {
            if let Some(v) = v {
                values.push(v);
            }
        }
        log.line.push(line);
        log.t_s.push(t);
        log.gyro_dps.push(g);
        log.fix.push(fix);
        self.prev_t = t;

        Ok(())
    }

    /// The extra columns of a row: `Some(value)` for a numeric column, `None` for a dropped one.
    fn extra_row(
        &mut self,
        record: &csv::ByteRecord,
        line: u64,
    ) -> Result<Vec<Option<Option<f64>>>, LoadError> {
        let mut out = Vec::with_capacity(self.columns.extra.len());
        for (k, &c) in self.columns.extra.iter().enumerate() {
            let name = &self.columns.names[c];
            let s = std::str::from_utf8(&record[c])
                .map_err(|_| self.field_err(line, name, "value is not valid UTF-8".into()))?;
            out.push(match self.extra_numeric[k] {
                Some(false) => None,
                _ if s.is_empty() => Some(None),
                numeric => match s.parse::<f64>() {
                    Ok(v) if v.is_finite() => {
                        self.extra_numeric[k] = Some(true);
                        Some(Some(v))
                    }
                    Ok(_) => {
                        return Err(self.field_err(
                            line,
                            name,
                            format!("'{s}' is not a finite number"),
                        ));
                    }
                    Err(_) if numeric == Some(true) => {
                        return Err(self.field_err(line, name, not_a_number(s)));
                    }
                    Err(_) => {
                        self.extra_numeric[k] = Some(false);
                        self.log.warnings.push(format!(
                            "{}:{line}: column '{name}' holds text ('{s}'); it is ignored",
                            self.file
                        ));
                        None
                    }
                },
            });
        }
        Ok(out)
    }

    /// Rows without a gyro sample (all three fields empty) get the rate of
    /// the sample that covers their time. Such rows come from another stream
    /// merged in by time (an outer join of the IMU's and the receiver's
    /// exports puts each fix on a row of its own); refusing them refused
    /// the ride. Under the format's mean rates the row at `t_k` holds the
    /// mean over `(t_{k-1}, t_k]`, so the next sample's rate covers every row
    /// between it and the sample before (`g_j = g_next`, the same rotation
    /// over the same time); instantaneous samples are interpolated linearly
    /// in time. Either way the rotation integrated is the gyro's own.
    fn fill_gyro(&mut self) -> Result<(), LoadError> {
        // A row without a sample holds NaN (parsed values are finite).
        let n = self.log.gyro_dps.len();
        let has: Vec<bool> = self.log.gyro_dps.iter().map(|g| !g[0].is_nan()).collect();
        let Some(first) = has.iter().position(|&h| !h) else {
            return Ok(());
        };
        let column = &self.columns.names[self.columns.gyro[0]];
        let own: Vec<f64> = (0..n)
            .filter(|&j| has[j])
            .map(|j| self.log.t_s[j])
            .collect();
        if own.is_empty() {
            return Err(self.field_err(
                self.log.line[first],
                column,
                "empty on every row: the log has no gyro sample".into(),
            ));
        }
        // The gyro's own rate, which the rows of other streams would hide.
        let rate = crate::signals::median_rate_hz(&own);
        if own.len() < 2 || rate < crate::signals::MIN_GYRO_RATE_HZ {
            return Err(self.field_err(
                self.log.line[first],
                column,
                format!(
                    "the gyro's own samples ({} of {n} rows; the others have none) come at {rate:.2} Hz: far too slow to integrate a vehicle's turns; a path needs a gyro at {} Hz or more",
                    own.len(),
                    crate::signals::MIN_GYRO_RATE_HZ
                ),
            ));
        }
        let instantaneous = self
            .log
            .metadata
            .get("gyro_samples")
            .is_some_and(|v| v.trim() == "instantaneous");
        let (t, g) = (&self.log.t_s, &mut self.log.gyro_dps);
        // The sample after each row without one (a backward pass), then the
        // sample before it (forwards).
        let mut next = vec![None; n];
        let mut after = None;
        for j in (0..n).rev() {
            if has[j] {
                after = Some(j);
            } else {
                next[j] = after;
            }
        }
        let mut before = None;
        let mut longest = 0.0f64;
        for j in 0..n {
            if has[j] {
                before = Some(j);
                continue;
            }
            let after = next[j];
            longest = longest.max(t[after.unwrap_or(j)] - t[before.unwrap_or(j)]);
            g[j] = match (before, after) {
                (Some(p), Some(q)) if instantaneous => {
                    let w = (t[j] - t[p]) / (t[q] - t[p]);
                    [0, 1, 2].map(|i| g[p][i] + w * (g[q][i] - g[p][i]))
                }
                (_, Some(q)) => g[q],
                (Some(p), None) => g[p],
                (None, None) => unreachable!("a log with a gyro sample has one either side"),
            };
        }
        let filled = n - own.len();
        self.log.warnings.push(format!(
            "{}:{}: {} row{} no gyro sample (the rows of another stream merged in by time, such as the fixes): each takes the rate of the sample that covers its time ({}), the longest stretch {longest:.3} s",
            self.file,
            self.log.line[first],
            filled,
            if filled == 1 { " has" } else { "s have" },
            if instantaneous { "interpolated" } else { "the next sample's mean rate" },
        ));
        Ok(())
    }

    /// The log, once every row is read.
    fn finish(mut self) -> Result<RideLog, LoadError> {
        if self.repeats.count > 0 {
            self.log.warnings.push(format!(
                "{}:{}: {} row{} repeat the row before them exactly (a logger that wrote a buffer twice) and {} dropped",
                self.file,
                self.repeats.first_line,
                self.repeats.count,
                if self.repeats.count == 1 { "" } else { "s" },
                if self.repeats.count == 1 { "is" } else { "are" },
            ));
        }
        if self.log.t_s.is_empty() {
            return Err(LoadError::File {
                file: self.file,
                message: "the log has a header but no data rows".into(),
            });
        }
        self.fill_gyro()?;
        for (k, &c) in self.columns.extra.iter().enumerate() {
            if self.extra_numeric[k] != Some(false) {
                self.log.channels.push((
                    self.columns.names[c].clone(),
                    std::mem::take(&mut self.extra_values[k]),
                ));
            }
        }
        self.log.shrink_to_fit();
        Ok(self.log)
    }
}

/// One record being parsed, with its line for messages.
struct Row<'a, 'c> {
    record: &'a csv::ByteRecord,
    line: u64,
    reader: &'a RowReader<'c>,
}

impl Row<'_, '_> {
    fn name(&self, i: usize) -> &str {
        &self.reader.columns.names[i]
    }

    fn text(&self, i: usize) -> Result<&str, LoadError> {
        std::str::from_utf8(&self.record[i]).map_err(|_| {
            self.reader
                .field_err(self.line, self.name(i), "value is not valid UTF-8".into())
        })
    }

    /// A finite number, or `None` for an empty field.
    fn number(&self, i: usize) -> Result<Option<f64>, LoadError> {
        let s = self.text(i)?;
        if s.is_empty() {
            return Ok(None);
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some(v)),
            Ok(_) => Err(self.reader.field_err(
                self.line,
                self.name(i),
                format!("'{s}' is not a finite number"),
            )),
            Err(_) => Err(self
                .reader
                .field_err(self.line, self.name(i), not_a_number(s))),
        }
    }

    fn required(&self, i: usize) -> Result<f64, LoadError> {
        self.number(i)?.ok_or_else(|| {
            self.reader.field_err(
                self.line,
                self.name(i),
                "value is empty but the column needs one on every row".into(),
            )
        })
    }

    /// A 1-sigma accuracy: positive where given.
    /// An optional column whose values must lie in `range` (`what` says what they are).
    fn in_range(
        &self,
        i: Option<usize>,
        range: std::ops::RangeInclusive<f64>,
        what: &str,
    ) -> Result<Option<Option<f64>>, LoadError> {
        let Some(i) = i else { return Ok(None) };
        match self.number(i)? {
            Some(v) if !range.contains(&v) => Err(self.reader.field_err(
                self.line,
                self.name(i),
                format!("{v} is not {what} ({} to {})", range.start(), range.end()),
            )),
            v => Ok(Some(v)),
        }
    }

    fn accuracy(&self, i: Option<usize>) -> Result<Option<Option<f64>>, LoadError> {
        let Some(i) = i else { return Ok(None) };
        match self.number(i)? {
            Some(v) if v <= 0.0 => Err(self.reader.field_err(
                self.line,
                self.name(i),
                format!("{v} is not a positive accuracy in metres"),
            )),
            v => Ok(Some(v)),
        }
    }

    /// The fix on this row: both coordinates or neither, within range.
    fn fix(&self) -> Result<Option<(f64, f64)>, LoadError> {
        let c = self.reader.columns;
        let err = |column: &str, m: String| self.reader.field_err(self.line, column, m);
        match (self.number(c.lat)?, self.number(c.lon)?) {
            (Some(la), Some(lo)) => {
                if !(-90.0..=90.0).contains(&la) {
                    return Err(err(
                        "lat_deg",
                        format!("{la} is outside -90..90{}", coordinate_hint(la, lo)),
                    ));
                }
                if !(-180.0..=360.0).contains(&lo) {
                    return Err(err(
                        "lon_deg",
                        format!("{lo} is outside -180..360{}", coordinate_hint(la, lo)),
                    ));
                }
                Ok(Some((la, lo)))
            }
            (None, None) => Ok(None),
            (Some(_), None) => Err(err("lon_deg", "empty while lat_deg has a value".into())),
            (None, Some(_)) => Err(err("lat_deg", "empty while lon_deg has a value".into())),
        }
    }
}

/// Write `log` as a ride-log CSV: metadata comments, then the columns it has
/// (numbers in Rust's shortest round-trip form, so reading it back gives the
/// same values to the bit).
pub fn write(log: &RideLog, w: &mut dyn Write) -> std::io::Result<()> {
    writeln!(w, "# gyropath ride log")?;
    for (k, v) in &log.metadata {
        writeln!(w, "# {k}: {}", v.replace('\n', " "))?;
    }
    let opt = |c: &Option<Vec<Option<f64>>>, i: usize| -> String {
        c.as_ref()
            .and_then(|v| v[i])
            .map_or(String::new(), |x| x.to_string())
    };
    let mut header: Vec<&str> = vec!["t_s", "gx_dps", "gy_dps", "gz_dps"];
    let optional_columns: [(&str, &Option<Vec<Option<f64>>>); 3] = [
        ("odo_m", &log.odo_m),
        ("speed_mps", &log.speed_mps),
        ("gps_alt_m", &log.gps_alt_m),
    ];
    if log.wheel_pulse.is_some() {
        header.push("wheel_pulse");
    }
    for (name, c) in &optional_columns[..2] {
        if c.is_some() {
            header.push(name);
        }
    }
    header.extend(["lat_deg", "lon_deg"]);
    let late: [(&str, &Option<Vec<Option<f64>>>); 8] = [
        ("gps_alt_m", &log.gps_alt_m),
        ("gps_speed_mps", &log.gps_speed_mps),
        ("gps_course_deg", &log.gps_course_deg),
        ("gps_hacc_m", &log.gps_hacc_m),
        ("gps_vacc_m", &log.gps_vacc_m),
        ("gps_hdop", &log.gps_hdop),
        ("gps_num_sats", &log.gps_num_sats),
        ("baro_alt_m", &log.baro_alt_m),
    ];
    for (name, c) in &late {
        if c.is_some() {
            header.push(name);
        }
    }
    if log.accel_mps2.is_some() {
        header.extend(["ax_mps2", "ay_mps2", "az_mps2"]);
    }
    let mut header = header.join(",");
    for (name, _) in &log.channels {
        header.push(',');
        header.push_str(name);
    }
    writeln!(w, "{header}")?;
    let mut line = String::with_capacity(256);
    for i in 0..log.len() {
        use std::fmt::Write as _;
        line.clear();
        let g = log.gyro_dps[i];
        let _ = write!(line, "{},{},{},{}", log.t_s[i], g[0], g[1], g[2]);
        if let Some(p) = &log.wheel_pulse {
            line.push_str(if p[i] { ",1" } else { ",0" });
        }
        for (_, c) in &optional_columns[..2] {
            if c.is_some() {
                let _ = write!(line, ",{}", opt(c, i));
            }
        }
        match log.fix[i] {
            Some((la, lo)) => {
                let _ = write!(line, ",{la},{lo}");
            }
            None => line.push_str(",,"),
        }
        for (_, c) in &late {
            if c.is_some() {
                let _ = write!(line, ",{}", opt(c, i));
            }
        }
        if let Some(a) = &log.accel_mps2 {
            match a[i] {
                Some([x, y, z]) => {
                    let _ = write!(line, ",{x},{y},{z}");
                }
                None => line.push_str(",,,"),
            }
        }
        for (_, c) in &log.channels {
            let _ = write!(line, ",{}", c[i].map_or(String::new(), |x| x.to_string()));
        }
        writeln!(w, "{line}")?;
    }
    Ok(())
}

/// Why a time that repeats the row before may do so: a Unix time (or
/// any time past 2^24 s) written as a single-precision float, whose steps
/// there are 2 s or more (128 s in 2018), so that a 100 Hz log's rows share
/// their times by the hundred.
pub(crate) fn coarse_time_hint(t: f64, prev: f64, unit: &str) -> String {
    let single = |v: f64| (v as f32) as f64 == v;
    if t != prev || t.abs() < f64::from(1u32 << 24) || !single(t) {
        return String::new();
    }
    let step = f64::from((t as f32).abs()).log2().floor() - 23.0;
    format!(
        ": the times are whole multiples of {:.0} {unit}, as a single-precision float (7 digits) holds a time this large; write the time with more digits, or from the start of the log",
        step.exp2()
    )
}

/// A coordinate written as NMEA writes it, degrees and minutes run
/// together (`ddmm.mmmm`, `dddmm.mmmm`: 4743.2599 is 47 deg 43.2599'), in
/// degrees: `None` where `v` cannot be one (its minutes 60 or more, or its
/// degrees beyond `limit`).
fn degrees_minutes(v: f64, limit: f64) -> Option<f64> {
    let a = v.abs();
    let (degrees, minutes) = ((a / 100.0).trunc(), a % 100.0);
    (a >= 100.0 && minutes < 60.0 && degrees <= limit)
        .then(|| v.signum() * (degrees + minutes / 60.0))
}

/// What a fix out of range most likely is, for its error: integers of
/// degrees times 10^7 (as u-blox and ArduPilot log them), NMEA's degrees
/// and minutes run together, or the two columns swapped (a longitude
/// beyond 90 degrees read as latitude).
pub(crate) fn coordinate_hint(lat: f64, lon: f64) -> String {
    // Beyond any degree (1e5 is 0.01 deg times 10^7) and within range divided.
    let e7 = |v: f64, limit: f64| v.abs() >= 1e5 && (v / 1e7).abs() <= limit;
    // Either out of range as degrees, and both readable as degrees and minutes.
    let nmea = (lat.abs() > 90.0 || lon.abs() > 180.0)
        .then(|| {
            let read = |v: f64, limit: f64| {
                if v.abs() >= 100.0 {
                    degrees_minutes(v, limit)
                } else {
                    (v.abs() <= limit).then_some(v)
                }
            };
            Some((read(lat, 90.0)?, read(lon, 180.0)?))
        })
        .flatten();
    // Both beyond any degree but under 10^7: as degrees times 10^7 within a
    // degree of 0, 0 (open sea in the Gulf of Guinea); as metres, a
    // projection's east and north (UTM's eastings are 166-834 km, its
    // northings up to 10,000 km) or ECEF coordinates.
    let metres = |v: f64| (1e3..1e7).contains(&v.abs());
    if metres(lat) && metres(lon) && (lat.abs() >= 1e5 || lon.abs() >= 1e5) {
        " (metres of a projection, such as UTM's easting and northing or ECEF, not degrees: lat_deg and lon_deg are WGS84 degrees; convert them, e.g. with pyproj)".into()
    } else if e7(lat, 90.0) || e7(lon, 180.0) {
        format!(
            " (degrees times 10^7, as u-blox and ArduPilot log them? {:.7}, {:.7} in degrees: divide both by 10^7)",
            lat / 1e7,
            lon / 1e7
        )
    } else if (-90.0..=90.0).contains(&lon) && (-180.0..=180.0).contains(&lat) {
        format!(
            " (lat_deg and lon_deg swapped? {lat} is a longitude and {lon} a latitude: swap the two names in the header)"
        )
    } else if let Some((la, lo)) = nmea {
        format!(
            " (degrees and minutes run together, as NMEA writes them? {la:.7}, {lo:.7} in degrees: dd + mm.mmmm / 60)"
        )
    } else {
        String::new()
    }
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

    /// [`GOOD`] with its data lines (and header) passed through `edit`.
    fn good_with(edit: impl Fn(&str) -> String) -> String {
        GOOD.lines()
            .map(|l| {
                if l.starts_with('#') {
                    l.to_string()
                } else {
                    edit(l)
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// A logger that stopped in the middle of writing its last row leaves a
    /// line without its end: that row is left out with a warning, wherever
    /// it was cut, and the rows before it are the log. A short last row
    /// that has its line end is bad input.
    #[test]
    fn a_last_row_cut_short_is_left_out_with_a_warning() {
        let whole = parse(GOOD.as_bytes(), "ex.csv").unwrap();
        for cut in [GOOD.len() - 8, GOOD.len() - 36, GOOD.len() - 40] {
            let log = parse(&GOOD.as_bytes()[..cut], "ex.csv").unwrap();
            assert_eq!(log.t_s, whole.t_s[..2], "cut at {cut}");
            assert_eq!(log.warnings.len(), 1, "{:?}", log.warnings);
            assert!(
                log.warnings[0].starts_with("ex.csv:6: ")
                    && log.warnings[0].ends_with("the last line is left out: it has no line end, as when a logger stops in the middle of writing a row"),
                "{:?}",
                log.warnings
            );
        }
        let short = GOOD.replace(",136.05,16.6\n", "\n");
        assert_eq!(
            err(&short),
            "bad.csv:6: row has 8 fields, the header has 10"
        );
        // A bad row before the last is an error whether or not the file ends in a line end.
        let bad = GOOD.replace("0.17500", "abc");
        assert!(err(&bad[..bad.len() - 1]).starts_with("bad.csv:5: column 'gx_dps'"));
    }

    /// A fix merged in on a row of its own (the gyro fields empty) takes
    /// the rate of the gyro sample that covers its time: the next one's
    /// mean rate, or interpolated between instantaneous samples. One or two
    /// empty gyro fields, or a log with no gyro sample, are errors.
    #[test]
    fn a_row_without_a_gyro_sample_takes_the_rate_that_covers_it() {
        let merged = GOOD.replace(
            "0.01,0.17500",
            "0.005,,,,0,47.49788890,19.04019790,95.8,,\n0.01,0.17500",
        );
        let log = parse(merged.as_bytes(), "ex.csv").unwrap();
        assert_eq!(log.t_s, vec![0.0, 0.005, 0.01, 0.02]);
        assert_eq!(log.gyro_dps[1], log.gyro_dps[2]);
        assert_eq!(log.fix_count(), 2);
        assert_eq!(
            log.warnings,
            vec![
                "ex.csv:5: 1 row has no gyro sample (the rows of another stream merged in by time, such as the fixes): each takes the rate of the sample that covers its time (the next sample's mean rate), the longest stretch 0.010 s"
            ]
        );
        let instantaneous = merged.replace(
            "# wheel_circumference_m",
            "# gyro_samples: instantaneous\n# wheel_circumference_m",
        );
        let log = parse(instantaneous.as_bytes(), "ex.csv").unwrap();
        for i in 0..3 {
            let mid = 0.5 * (log.gyro_dps[0][i] + log.gyro_dps[2][i]);
            assert!((log.gyro_dps[1][i] - mid).abs() < 1e-12);
        }
        let partly = GOOD.replace("0.01,0.17500,0.00875", "0.01,0.17500,");
        assert_eq!(
            err(&partly),
            "bad.csv:5: column 'gy_dps': value is empty but the column needs one on every row"
        );
        // A gyro at 0.1 Hz among 10 Hz fixes is too slow, whatever the rows' rate.
        let mut sparse = String::from("t_s,gx_dps,gy_dps,gz_dps,odo_m,lat_deg,lon_deg\n");
        for k in 0..300 {
            let gyro = if k % 100 == 0 { "0.1,0.2,0.3" } else { ",," };
            sparse.push_str(&format!("{:.1},{gyro},{k},47.5,19.0\n", k as f64 * 0.1));
        }
        assert!(
            err(&sparse).contains(
                "the gyro's own samples (3 of 300 rows; the others have none) come at 0.10 Hz"
            ),
            "{}",
            err(&sparse)
        );
        let none = GOOD
            .replace("0.12250,-0.31500,0.28000", ",,")
            .replace("0.17500,0.00875,0.23625", ",,")
            .replace("0.16625,-0.04375,0.19250", ",,");
        assert_eq!(
            err(&none),
            "bad.csv:4: column 'gx_dps': empty on every row: the log has no gyro sample"
        );
    }

    /// A row written twice, field for field, is dropped and counted; a row
    /// at the same time with other values is still an error.
    #[test]
    fn a_row_written_twice_is_dropped_and_said() {
        let row = "0.01,0.17500,0.00875,0.23625,0,,,,136.01,16.6\n";
        let twice = GOOD.replace(row, &format!("{row}{row}{row}"));
        let log = parse(twice.as_bytes(), "ex.csv").unwrap();
        let good = parse(GOOD.as_bytes(), "ex.csv").unwrap();
        assert_eq!((&log.t_s, &log.gyro_dps), (&good.t_s, &good.gyro_dps));
        assert_eq!(log.line, vec![4, 5, 8]);
        assert_eq!(
            log.warnings,
            vec![
                "ex.csv:6: 2 rows repeat the row before them exactly (a logger that wrote a buffer twice) and are dropped"
            ]
        );
        let other = GOOD.replace(row, &format!("{row}{}", row.replace("16.6", "16.7")));
        assert!(err(&other).starts_with("bad.csv:6: column 't_s': time 0.01 does not increase"));
    }

    #[test]
    fn tab_and_semicolon_separated_logs_read_as_the_comma_separated() {
        let good = parse(GOOD.as_bytes(), "ex.csv").unwrap();
        for sep in ["\t", ";"] {
            let log = parse(good_with(|l| l.replace(',', sep)).as_bytes(), "ex.csv").unwrap();
            assert_eq!(
                (&log.t_s, &log.fix, &log.gyro_dps),
                (&good.t_s, &good.fix, &good.gyro_dps)
            );
        }
        // A spreadsheet's decimal commas are named, on their line and column.
        assert_eq!(
            err(&good_with(|l| l.replace(',', ";").replace('.', ","))),
            "bad.csv:4: column 't_s': '0,00' is not a number (a decimal comma? numbers take a decimal point)"
        );
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
            e.contains("bad.csv:3: column 'gz_dps': required column is missing")
                && e.contains("gq_dps")
                && e.contains("--map FILE.toml"),
            "{e}"
        );
        let e = err(&GOOD.replace("t_s,", "T_S,"));
        assert!(
            e.contains("column 't_s': required column is missing from the header, which has 'T_S'"),
            "{e}"
        );
        let e = err(&GOOD.replace("gz_dps,", "gz,"));
        assert!(
            e.contains(
                "column 'gz_dps': required column is missing from the header, which has 'gz'"
            ),
            "{e}"
        );
        let e = err("t_s,lat_deg,lon_deg,alt_m\n0.0,52.5,13.3,40.0\n");
        assert!(
            e.starts_with("bad.csv:1: column 'gx_dps': a track of positions without a gyro")
                && e.contains("--reference bad.csv"),
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
        // Degrees times 10^7, and the two columns swapped, are named.
        let e = err(&GOOD.replace("47.49788883,19.04019799", "474978888,190401980"));
        assert!(
            e.starts_with("bad.csv:4: column 'lat_deg': 474978888 is outside -90..90")
                && e.contains("degrees times 10^7")
                && e.contains("47.4978888, 19.0401980"),
            "{e}"
        );
        let e = err(&GOOD.replace("47.49788883,19.04019799", "-122.47,37.72"));
        assert!(e.contains("swapped") && !e.contains("10^7"), "{e}");
        let e = err(&GOOD.replace("47.49788883,19.04019799", "95.0,400.0"));
        assert!(
            !e.contains("swapped") && !e.contains("10^7") && !e.contains("NMEA"),
            "{e}"
        );
        // A Unix time written as a single-precision float: 128 s steps.
        let e = err(&GOOD
            .replace("\n0.00,", "\n1533198848,")
            .replace("\n0.01,", "\n1533198848,"));
        assert!(
            e.starts_with("bad.csv:5: column 't_s': time 1533198848 does not increase")
                && e.contains("whole multiples of 128 s, as a single-precision float"),
            "{e}"
        );
        // NMEA's degrees and minutes run together (47 deg 29.8733', 19 deg
        // 2.4119', and a western longitude) are named with the degrees.
        let e = err(&GOOD.replace("47.49788883,19.04019799", "4729.87333,01902.41188"));
        assert!(
            e.starts_with("bad.csv:4: column 'lat_deg': 4729.87333 is outside -90..90")
                && e.contains("as NMEA writes them? 47.4978888, 19.0401980 in degrees"),
            "{e}"
        );
        let e = err(&GOOD.replace("47.49788883,19.04019799", "3743.25986,-12228.33818"));
        assert!(e.contains("37.7209977, -122.4723030 in degrees"), "{e}");
        // UTM's easting and northing in metres, either way round.
        for pair in ["5800123.4,390456.7", "390456.7,5800123.4"] {
            let e = err(&GOOD.replace("47.49788883,19.04019799", pair));
            assert!(e.contains("UTM") && !e.contains("10^7"), "{e}");
        }
        // Minutes of 60 or more are no minutes.
        let e = err(&GOOD.replace("47.49788883,19.04019799", "4775.0,01902.4"));
        assert!(!e.contains("NMEA"), "{e}");
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

    const NEW_COLUMNS: &str = "t_s,gx_dps,gy_dps,gz_dps,speed_mps,lat_deg,lon_deg,gps_hacc_m,gps_vacc_m,ax_mps2,ay_mps2,az_mps2\n0,0.1,0.2,0.3,1.5,47.5,19.0,2.5,4.0,0.1,0.2,9.8\n0.01,0.1,0.2,0.3,1.6,,,,,0.1,0.2,9.7\n";

    #[test]
    fn reads_accuracy_speed_and_accelerometer_columns() {
        let log = parse(NEW_COLUMNS.as_bytes(), "new.csv").unwrap();
        assert_eq!(log.speed_mps.as_ref().unwrap(), &vec![Some(1.5), Some(1.6)]);
        assert_eq!(log.gps_hacc_m.as_ref().unwrap(), &vec![Some(2.5), None]);
        assert_eq!(log.gps_vacc_m.as_ref().unwrap()[0], Some(4.0));
        assert_eq!(log.accel_mps2.as_ref().unwrap()[1], Some([0.1, 0.2, 9.7]));
        let e = err(&NEW_COLUMNS.replace(",2.5,", ",-1,"));
        assert!(e.starts_with("bad.csv:2: column 'gps_hacc_m'"), "{e}");
        let e = err(&NEW_COLUMNS.replace(",ay_mps2", ",ay"));
        assert!(e.contains("column 'ay_mps2'"), "{e}");
    }

    /// The receiver's quality fields: a dilution of precision and a whole
    /// number of satellites, each error naming its line and column.
    #[test]
    fn reads_the_receivers_hdop_and_satellites() {
        let csv = "t_s,gx_dps,gy_dps,gz_dps,speed_mps,lat_deg,lon_deg,gps_hdop,gps_num_sats\n0,0.1,0.2,0.3,1.5,47.5,19.0,1.4,9\n0.01,0.1,0.2,0.3,1.6,,,,\n";
        let log = parse(csv.as_bytes(), "q.csv").unwrap();
        assert_eq!(log.gps_hdop.as_ref().unwrap(), &vec![Some(1.4), None]);
        assert_eq!(log.gps_num_sats.as_ref().unwrap(), &vec![Some(9.0), None]);
        assert!(log.channels.is_empty());
        let e = err(&csv.replace(",1.4,9", ",0,9"));
        assert!(
            e.starts_with("bad.csv:2: column 'gps_hdop'")
                && e.contains("not a dilution of precision"),
            "{e}"
        );
        let e = err(&csv.replace(",1.4,9", ",1.4,8.5"));
        assert!(
            e.starts_with("bad.csv:2: column 'gps_num_sats'") && e.contains("not a whole number"),
            "{e}"
        );
        let e = err(&csv.replace(",1.4,9", ",1.4,NaN"));
        assert!(e.starts_with("bad.csv:2: column 'gps_num_sats'"), "{e}");
    }

    /// A log with no wheel sensor: the receiver's speed and course.
    const GNSS_SPEED: &str = "t_s,gx_dps,gy_dps,gz_dps,lat_deg,lon_deg,gps_speed_mps,gps_course_deg\n0,0.1,0.2,0.3,47.5,19.0,4.25,271.5\n0.01,0.1,0.2,0.3,,,,\n";

    #[test]
    fn reads_the_receivers_speed_and_course() {
        let log = parse(GNSS_SPEED.as_bytes(), "gnss.csv").unwrap();
        assert_eq!(log.gps_speed_mps.as_ref().unwrap(), &vec![Some(4.25), None]);
        assert_eq!(
            log.gps_course_deg.as_ref().unwrap(),
            &vec![Some(271.5), None]
        );
        assert!(log.odo_m.is_none() && log.speed_mps.is_none());
        let e = err(&GNSS_SPEED.replace(",4.25,", ",-0.5,"));
        assert!(
            e.starts_with("bad.csv:2: column 'gps_speed_mps': -0.5 is not a ground speed"),
            "{e}"
        );
        let e = err(&GNSS_SPEED.replace(",271.5", ",400"));
        assert!(e.starts_with("bad.csv:2: column 'gps_course_deg'"), "{e}");
        let e = err(&GNSS_SPEED.replace(",gps_speed_mps", ",speed_over_ground"));
        assert!(e.contains("'gps_speed_mps'"), "{e}");
    }

    #[test]
    fn what_is_written_reads_back_the_same() {
        for text in [GOOD, NEW_COLUMNS, GNSS_SPEED] {
            let log = parse(text.as_bytes(), "a.csv").unwrap();
            let mut out = Vec::new();
            write(&log, &mut out).unwrap();
            let back = parse(&out, "b.csv").unwrap();
            assert_eq!(back.t_s, log.t_s);
            assert_eq!(back.gyro_dps, log.gyro_dps);
            assert_eq!(back.fix, log.fix);
            assert_eq!(back.wheel_pulse, log.wheel_pulse);
            assert_eq!(back.speed_mps, log.speed_mps);
            assert_eq!(back.gps_alt_m, log.gps_alt_m);
            assert_eq!(back.gps_hacc_m, log.gps_hacc_m);
            assert_eq!(back.gps_speed_mps, log.gps_speed_mps);
            assert_eq!(back.gps_course_deg, log.gps_course_deg);
            assert_eq!(back.baro_alt_m, log.baro_alt_m);
            assert_eq!(back.accel_mps2, log.accel_mps2);
            assert_eq!(back.channels, log.channels);
            assert_eq!(back.metadata, log.metadata);
        }
    }
}
