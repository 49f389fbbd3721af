//! Reference tracks: a better trajectory of the same drive (RTK, an INS, a
//! survey, a second receiver) to measure a fit against, as evo does for SLAM.
//!
//! Read from `t_s,lat_deg,lon_deg[,alt_m]` CSV on the ride's own clock (the
//! `truth.csv` of the shared real drives and of `gyropath simulate --truth`),
//! from a GPX track (`.gpx`: every track point with its `<time>`, `<ele>`
//! when given) or from NMEA 0183 (`.gga`, `.nmea`: the GGA sentences of a
//! fix, dated by the RMC sentences) or from a Garmin FIT activity
//! ([`super::fit`]), the last three in UTC: they are put on the
//! ride's clock by its `t0_unix_s` ([`ReferenceTrack::on_ride_clock`]), or
//! from a comma2k19 segment's `global_pose` (its folder or the segment's),
//! on the device's boot clock ([`super::comma2k19::read_reference`]).
//! CSV columns are found by name; `#` lines are comments. Time must increase
//! strictly and every value must be a finite number: anything else is an
//! error naming the file, the line and the column.

use std::path::Path;

use super::LoadError;
use crate::geodesy::Geodetic;

/// A reference trajectory on the ride's clock.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceTrack {
    /// Where it came from (for messages and reports).
    pub source: String,
    /// Time of each point on the ride's clock (s), strictly increasing.
    pub t_s: Vec<f64>,
    /// Each point; `alt_m` is NaN where the reference has no heights.
    pub points: Vec<Geodetic>,
    /// Whether the reference gives heights.
    pub has_alt: bool,
    /// What `t_s` counts from.
    pub clock: Clock,
    /// What was left out in reading it (a last line cut short), said
    /// wherever the track is used.
    pub warnings: Vec<String>,
}

/// The clock of a reference track's times.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clock {
    /// The ride's own (`t_s` of the ride log): CSV references.
    Ride,
    /// Unix seconds (UTC): GPX, NMEA dated by RMC.
    Unix,
    /// Seconds since the UTC midnight of the first point's day, its day
    /// unknown (NMEA with GGA only, as GNSS/INS exports often are): dated
    /// by the ride's start.
    TimeOfDay,
    /// A device's boot clock (comma2k19's `global_pose`): put on the ride's
    /// clock by its `t0_boot_s`.
    Boot,
}

impl ReferenceTrack {
    /// A track with no points yet, from `source`, on `clock`.
    pub fn empty(source: &str, clock: Clock) -> Self {
        Self {
            source: source.to_string(),
            t_s: Vec::new(),
            points: Vec::new(),
            has_alt: false,
            clock,
            warnings: Vec::new(),
        }
    }

    /// The track on the clock of a ride whose `t_s = 0` is `t0_unix_s`
    /// (`t_ride = t_unix - t0_unix_s`; a boot-clock track: `t0_boot_s`); a
    /// track already on the ride's clock as it is. A UTC track and a ride
    /// without `t0_unix_s` is an error naming both: nothing says where on the
    /// ride's clock the track falls.
    pub fn on_ride_clock(
        mut self,
        t0_unix_s: Option<f64>,
        t0_boot_s: Option<f64>,
        ride: &str,
    ) -> Result<Self, LoadError> {
        match (self.clock, t0_boot_s) {
            (Clock::Ride, _) => return Ok(self),
            (Clock::Boot, Some(t0)) => {
                for t in &mut self.t_s {
                    *t -= t0;
                }
                self.clock = Clock::Ride;
                return Ok(self);
            }
            (Clock::Boot, None) => {
                return Err(LoadError::File {
                    file: self.source.clone(),
                    message: format!(
                        "its times are on a device's boot clock, and {ride} has no t0_boot_s (the boot time of its t_s = 0) to put them on the ride's clock"
                    ),
                });
            }
            _ => {}
        }
        let Some(t0) = t0_unix_s else {
            return Err(LoadError::File {
                file: self.source.clone(),
                message: format!(
                    "its times are UTC, and {ride} has no t0_unix_s (the Unix time of its t_s = 0) to put them on the ride's clock: give the ride log a '# t0_unix_s:' line, or the reference as t_s,lat_deg,lon_deg CSV on the ride's clock"
                ),
            });
        };
        // A time of day falls on the day (before, of or after the ride's
        // start) that puts the track's first point nearest the ride's start.
        let day = match self.clock {
            Clock::TimeOfDay => {
                let midnight = (t0 / 86_400.0).floor() * 86_400.0;
                [-86_400.0, 0.0, 86_400.0]
                    .map(|d| midnight + d)
                    .into_iter()
                    .min_by(|a, b| {
                        (a + self.t_s[0] - t0)
                            .abs()
                            .total_cmp(&(b + self.t_s[0] - t0).abs())
                    })
                    .unwrap_or(midnight)
            }
            _ => 0.0,
        };
        for t in &mut self.t_s {
            *t += day - t0;
        }
        self.clock = Clock::Ride;
        Ok(self)
    }
}

/// Read a reference track (see the module documentation).
pub fn read_reference(path: &Path) -> Result<ReferenceTrack, LoadError> {
    if super::comma2k19::has_global_pose(path) {
        return super::comma2k19::read_reference(path);
    }
    let (bytes, file) = super::read_bytes(path)?;
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if extension.as_deref() == Some("fit") || super::fit::is_fit(&bytes) {
        return Ok(super::fit::parse(&bytes, &file)?.track);
    }
    match extension.as_deref() {
        Some("gpx") => parse_gpx(&bytes, &file),
        Some("gga" | "nmea") => parse_nmea(&bytes, &file),
        _ => parse_reference(&bytes, &file),
    }
}

/// Parse a GPX reference track: the points of every track and segment in
/// order, each with its time (a point without one is an error); a point at
/// the same instant as the one before is dropped (devices repeat a point
/// when they pause), an earlier one is an error.
pub fn parse_gpx(bytes: &[u8], file: &str) -> Result<ReferenceTrack, LoadError> {
    let whole = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let mut track = ReferenceTrack::empty(file, Clock::Unix);
    let doc = match gpx::read(bytes) {
        Ok(doc) => doc,
        Err(e) => {
            let Some(closed) = closed_at_last_point(bytes) else {
                return Err(whole(format!("not a GPX file: {e}")));
            };
            let doc =
                gpx::read(closed.as_slice()).map_err(|_| whole(format!("not a GPX file: {e}")))?;
            track.warnings.push(format!(
                "{file}: the file ends inside its track (no closing </gpx>, as when a logger stops while writing): the track points before the cut are read, what follows the last whole point is left out"
            ));
            doc
        }
    };
    let points = doc
        .tracks
        .iter()
        .flat_map(|t| &t.segments)
        .flat_map(|s| &s.points);
    for (i, p) in points.enumerate() {
        let Some(time) = p.time else {
            return Err(whole(format!(
                "track point {} has no <time>: a reference track needs times",
                i + 1
            )));
        };
        let t = time::OffsetDateTime::from(time).unix_timestamp_nanos() as f64 * 1e-9;
        let (lon, lat) = (p.point().x(), p.point().y());
        match track.t_s.last() {
            Some(&last) if t == last => continue,
            Some(&last) if t < last => {
                return Err(whole(format!(
                    "track point {} is at {t:.3} s, before the point before it ({last:.3} s)",
                    i + 1
                )));
            }
            _ => {}
        }
        track.has_alt |= p.elevation.is_some();
        track.t_s.push(t);
        track
            .points
            .push(Geodetic::new(lat, lon, p.elevation.unwrap_or(f64::NAN)));
    }
    if track.t_s.len() < 2 {
        return Err(whole(
            "a reference track needs at least two track points with times".into(),
        ));
    }
    Ok(track)
}

/// A GPX file cut short (no `</gpx>`: a logger that stopped while writing)
/// closed after its last whole track point, as the logger would have
/// closed it there; `None` for a file that has its end (its fault is
/// another) or no whole point.
fn closed_at_last_point(bytes: &[u8]) -> Option<Vec<u8>> {
    let find_last = |needle: &[u8]| bytes.windows(needle.len()).rposition(|w| w == needle);
    if find_last(b"</gpx>").is_some() {
        return None;
    }
    let end = find_last(b"</trkpt>")? + b"</trkpt>".len();
    let mut closed = bytes[..end].to_vec();
    closed.extend_from_slice(b"</trkseg></trk></gpx>");
    Some(closed)
}

/// Parse NMEA 0183 as a reference track: one point per GGA sentence with a
/// fix (quality not 0), its UTC time of day dated by the RMC sentences (the
/// last before it, or the first in the file; without one, by the ride's
/// start: [`Clock::TimeOfDay`]); heights are GGA's altitude above mean sea
/// level. Sentences whose checksum does not match are left out (real logs
/// hold garbled ones); a GGA with a fix that cannot be read is an error
/// naming its line and field.
///
/// Hand-written rather than with the `nmea` crate: two sentences' fields
/// are needed, the crate pulls chrono and nom for them, and its GGA has no
/// date either.
pub fn parse_nmea(bytes: &[u8], file: &str) -> Result<ReferenceTrack, LoadError> {
    let text = String::from_utf8_lossy(bytes);
    let field_error = |line: usize, column: &str, message: String| LoadError::Field {
        file: file.to_string(),
        line: line as u64,
        column: column.to_string(),
        message,
    };
    // Every GGA and RMC sentence whose checksum matches: its line and fields.
    // Real logs hold garbled sentences (a serial line drops bytes) and some
    // exporters write wrong checksums; such sentences are left out, and
    // counted for the error when nothing is left.
    let mut sentences = Vec::new();
    let mut garbled = 0usize;
    // A file that ends inside a sentence (a logger that stopped while
    // writing) ends in a line without its end and without its checksum:
    // that sentence is left out, and said, whatever it holds, since its
    // last field may be cut short (a height of 33.6 for 33.694).
    let ends_cut = !text.is_empty() && !text.ends_with(['\n', '\r']);
    let count = text.lines().count();
    let mut warnings = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        let Some(body) = line.strip_prefix('$') else {
            continue;
        };
        let body = match body.split_once('*') {
            None if ends_cut && i + 1 == count => {
                warnings.push(format!(
                    "{file}:{}: the last line is left out: it ends without its checksum or line end, as when a logger stops in the middle of writing a sentence",
                    i + 1
                ));
                continue;
            }
            Some((body, sum)) => {
                let sound = u8::from_str_radix(sum.trim(), 16)
                    .is_ok_and(|want| body.bytes().fold(0u8, |a, b| a ^ b) == want);
                if !sound {
                    garbled += 1;
                    continue;
                }
                body
            }
            None => body,
        };
        let fields: Vec<&str> = body.split(',').collect();
        let kind = fields[0].get(2..).unwrap_or("");
        if kind == "GGA" || kind == "RMC" {
            sentences.push((i + 1, kind == "GGA", fields));
        }
    }
    let date_of = |f: &[&str]| f.get(9).and_then(|d| days_from_ddmmyy(d));
    // Dated by RMC where there is one; else times of day, dated by the ride.
    let mut date = sentences
        .iter()
        .filter(|s| !s.1)
        .find_map(|s| date_of(&s.2));
    let clock = if date.is_some() {
        Clock::Unix
    } else {
        Clock::TimeOfDay
    };
    let mut track = ReferenceTrack {
        warnings,
        ..ReferenceTrack::empty(file, clock)
    };
    for (line, gga, f) in &sentences {
        if !gga {
            if let Some(d) = date_of(f) {
                date = Some(d);
            }
            continue;
        }
        let get = |k: usize| f.get(k).copied().unwrap_or("");
        if get(6).is_empty() || get(6) == "0" {
            continue; // no fix
        }
        let tod = seconds_of_day(get(1))
            .ok_or_else(|| field_error(*line, "time", format!("'{}' is no hhmmss time", get(1))))?;
        let lat = degrees(get(2), get(3), 'N', 'S').ok_or_else(|| {
            field_error(
                *line,
                "latitude",
                format!("'{},{}' is no latitude", get(2), get(3)),
            )
        })?;
        let lon = degrees(get(4), get(5), 'E', 'W').ok_or_else(|| {
            field_error(
                *line,
                "longitude",
                format!("'{},{}' is no longitude", get(4), get(5)),
            )
        })?;
        let alt = get(9).parse::<f64>().ok().filter(|a| a.is_finite());
        let mut t = date.unwrap_or(0) as f64 * 86_400.0 + tod;
        if let Some(&last) = track.t_s.last() {
            // Past midnight before the RMC of the new day.
            if t < last - 43_200.0 {
                t += 86_400.0;
            }
            if t == last {
                continue;
            }
            if t < last {
                return Err(field_error(
                    *line,
                    "time",
                    format!("{} is before the fix before it", get(1)),
                ));
            }
        }
        track.has_alt |= alt.is_some();
        track.t_s.push(t);
        track
            .points
            .push(Geodetic::new(lat, lon, alt.unwrap_or(f64::NAN)));
    }
    if track.t_s.len() < 2 {
        return Err(LoadError::File {
            file: file.to_string(),
            message: format!(
                "a reference track needs at least two GGA fixes ({garbled} sentences with a wrong checksum left out)"
            ),
        });
    }
    Ok(track)
}

/// `hhmmss[.sss]` as seconds of the day.
fn seconds_of_day(s: &str) -> Option<f64> {
    let (h, m, sec) = (s.get(0..2)?, s.get(2..4)?, s.get(4..)?);
    let (h, m, sec): (f64, f64, f64) = (h.parse().ok()?, m.parse().ok()?, sec.parse().ok()?);
    (h < 24.0 && m < 60.0 && sec < 61.0).then_some(h * 3600.0 + m * 60.0 + sec)
}

/// NMEA's `(d)ddmm.mmmm` with its hemisphere as signed degrees.
fn degrees(value: &str, hemisphere: &str, plus: char, minus: char) -> Option<f64> {
    let dot = value.find('.').unwrap_or(value.len());
    let split = dot.checked_sub(2)?;
    let deg: f64 = value.get(..split)?.parse().ok()?;
    let min: f64 = value.get(split..)?.parse().ok()?;
    let v = deg + min / 60.0;
    match hemisphere.chars().next()? {
        c if c == plus => Some(v),
        c if c == minus => Some(-v),
        _ => None,
    }
}

/// RMC's `ddmmyy` as days since 1970-01-01 (years 80-99 are 19xx), by
/// Howard Hinnant's `days_from_civil`.
fn days_from_ddmmyy(s: &str) -> Option<i64> {
    if s.len() != 6 {
        return None;
    }
    let (d, m, y): (i64, i64, i64) = (
        s.get(0..2)?.parse().ok()?,
        s.get(2..4)?.parse().ok()?,
        s.get(4..6)?.parse().ok()?,
    );
    if !(1..=31).contains(&d) || !(1..=12).contains(&m) {
        return None;
    }
    let y = if y >= 80 { 1900 + y } else { 2000 + y };
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some(era * 146_097 + doe - 719_468)
}

/// Parse a reference track from CSV bytes; `file` names it in errors.
pub fn parse_reference(bytes: &[u8], file: &str) -> Result<ReferenceTrack, LoadError> {
    let mut rdr = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(super::csv_rows::LastByte::new(bytes));
    let whole = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let headers = rdr
        .headers()
        .map_err(|e| whole(format!("not a CSV reference track: {e}")))?
        .clone();
    let column = |name: &str| headers.iter().position(|h| h == name);
    let need = |name: &str| {
        column(name).ok_or_else(|| {
            whole(format!(
                "no '{name}' column: a reference track has t_s,lat_deg,lon_deg[,alt_m] (found: {})",
                headers.iter().collect::<Vec<_>>().join(",")
            ))
        })
    };
    let (ct, clat, clon) = (need("t_s")?, need("lat_deg")?, need("lon_deg")?);
    let calt = column("alt_m");
    let mut track = ReferenceTrack {
        has_alt: calt.is_some(),
        ..ReferenceTrack::empty(file, Clock::Ride)
    };
    // Read one ahead: an INS or a logger that stops while writing leaves
    // a last line without its end, which is left out (and said) rather
    // than losing the whole reference, and with it the fit.
    let cut = super::csv_rows::each_record(
        &mut rdr,
        |rdr, record| {
            rdr.read_byte_record(record)
                .map_err(|e| whole(format!("unreadable CSV: {e}")))
        },
        |record, _| {
            let line = record.position().map_or(0, |p| p.line());
            let value = |c: usize, name: &str| -> Result<f64, LoadError> {
                let field = |message: String| LoadError::Field {
                    file: file.to_string(),
                    line,
                    column: name.to_string(),
                    message,
                };
                let text = record
                    .get(c)
                    .map(String::from_utf8_lossy)
                    .ok_or_else(|| field("missing (the line is short)".into()))?;
                let v: f64 = text
                    .parse()
                    .map_err(|_| field(format!("'{text}' is not a number")))?;
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(field(format!("'{text}' is not a finite number")))
                }
            };
            let t = value(ct, "t_s")?;
            let lat = value(clat, "lat_deg")?;
            let lon = value(clon, "lon_deg")?;
            let alt = match calt {
                Some(c) => value(c, "alt_m")?,
                None => f64::NAN,
            };
            if !(-90.0..=90.0).contains(&lat) || !(-180.0..=360.0).contains(&lon) {
                return Err(LoadError::Field {
                    file: file.to_string(),
                    line,
                    column: if (-90.0..=90.0).contains(&lat) {
                        "lon_deg"
                    } else {
                        "lat_deg"
                    }
                    .into(),
                    message: format!("({lat}, {lon}) is no latitude and longitude in degrees"),
                });
            }
            if let Some(&last) = track.t_s.last()
                && t <= last
            {
                return Err(LoadError::Field {
                    file: file.to_string(),
                    line,
                    column: "t_s".into(),
                    message: format!("time {t} s does not increase (the line before: {last} s)"),
                });
            }
            track.t_s.push(t);
            track.points.push(Geodetic::new(lat, lon, alt));
            Ok(())
        },
    )?;
    track.warnings.extend(cut);
    if track.t_s.len() < 2 {
        return Err(whole(
            "a reference track needs at least two points with times".into(),
        ));
    }
    Ok(track)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An NMEA sentence with its checksum.
    fn sentence(body: &str) -> String {
        format!("${body}*{:02X}\n", body.bytes().fold(0u8, |a, b| a ^ b))
    }

    #[test]
    fn gga_fixes_are_dated_by_rmc_and_checked() {
        let text = [
            sentence("GPGGA,235959.00,3725.5838626,N,12205.6186063,W,1,15,1.0,6.83,M,-32.64,M,,"),
            sentence("GPRMC,235959.00,A,3725.584,N,12205.619,W,0.0,62.8,060220,,,A"),
            sentence("GPGGA,000000.50,3725.5838636,N,12205.6186036,W,4,15,1.0,6.90,M,-32.64,M,,"),
            sentence("GPGGA,000001.50,3725.58,N,12205.61,W,0,15,1.0,6.90,M,-32.64,M,,"),
            sentence("GNGSA,A,3,,,,,,,,,,,,,1.0,1.0,1.0"),
        ]
        .concat();
        let r = parse_nmea(text.as_bytes(), "span.gga").unwrap();
        assert_eq!(r.t_s.len(), 2, "the fix of quality 0 is left out");
        // 2020-02-06 23:59:59 UTC, and half a second past midnight after it.
        assert_eq!(r.t_s[0], 1_581_033_599.0);
        assert_eq!(r.t_s[1], 1_581_033_600.5);
        assert!((r.points[0].lat_deg - (37.0 + 25.5838626 / 60.0)).abs() < 1e-12);
        assert!((r.points[0].lon_deg + (122.0 + 5.6186063 / 60.0)).abs() < 1e-12);
        assert!(r.has_alt && r.clock == Clock::Unix);

        // A sentence with a wrong checksum is left out: here the RMC, so
        // the fixes are times of day, dated by the ride's start.
        let garbled = text.replacen("060220,,,A*", "060221,,,A*", 1);
        let r = parse_nmea(garbled.as_bytes(), "span.gga").unwrap();
        assert_eq!(r.clock, Clock::TimeOfDay);
        assert_eq!(r.t_s, vec![86_399.0, 86_400.5]);
        // A ride that starts at 00:00:10 on 7 Feb puts the first fix 11 s before it.
        let on = r
            .on_ride_clock(Some(1_581_033_610.0), None, "ride.csv")
            .unwrap();
        assert_eq!(on.t_s, vec![-11.0, -9.5]);
        let unreadable =
            sentence("GPGGA,12x000.00,3725.58,N,12205.61,W,1,15,1.0,6.8,M,,M,,").repeat(2);
        let e = parse_nmea(unreadable.as_bytes(), "x.nmea")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.nmea:1") && e.contains("time"), "{e}");
        let e = parse_nmea(b"$GPGGA,1*00\n", "x.nmea")
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 sentences with a wrong checksum"), "{e}");
    }

    #[test]
    fn a_utc_track_needs_the_rides_start_time() {
        let gpx = br#"<?xml version="1.0"?><gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>
            <trkpt lat="52.5" lon="13.37"><ele>40</ele><time>2020-02-07T02:14:31Z</time></trkpt>
            <trkpt lat="52.5" lon="13.37"><time>2020-02-07T02:14:31Z</time></trkpt>
            <trkpt lat="52.50001" lon="13.37"><time>2020-02-07T02:14:32.5Z</time></trkpt>
            </trkseg></trk></gpx>"#;
        let r = parse_gpx(gpx, "t.gpx").unwrap();
        assert_eq!(
            r.t_s,
            vec![1_581_041_671.0, 1_581_041_672.5],
            "a repeated instant is dropped"
        );
        assert!(r.has_alt && r.points[1].alt_m.is_nan());
        let on = r
            .clone()
            .on_ride_clock(Some(1_581_041_670.0), None, "ride.csv")
            .unwrap();
        assert_eq!(on.t_s, vec![1.0, 2.5]);
        assert_eq!(on.clock, Clock::Ride);
        let e = r
            .on_ride_clock(None, None, "ride.csv")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.gpx") && e.contains("ride.csv has no t0_unix_s"),
            "{e}"
        );
        let e = parse_gpx(b"<gpx>", "t.gpx").unwrap_err().to_string();
        assert!(e.contains("t.gpx") && e.contains("not a GPX file"), "{e}");
    }

    /// The shared real files: the NovAtel SPAN reference of the NMEA drive
    /// (1 Hz GGA, 7 Feb 2020 02:13-02:43 UTC) and a Garmin GPX export.
    #[test]
    fn the_shared_span_and_garmin_tracks_read() {
        let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/formats");
        let span =
            read_reference(&shared.join("nmea/MTV.Local1.SPAN.20200206-181434.gga")).unwrap();
        let span_s = span.t_s.last().unwrap() - span.t_s[0];
        eprintln!(
            "SPAN: {} points over {span_s} s from {}",
            span.t_s.len(),
            span.t_s[0]
        );
        assert!(span.t_s.len() > 1700 && (1700.0..1800.0).contains(&span_s));
        // Its RMC sentences all carry wrong checksums: the GGA fixes are
        // times of day (02:13:31 UTC first), dated by a ride's start.
        assert_eq!(span.clock, Clock::TimeOfDay);
        assert_eq!(span.t_s[0], 8011.0);
        // The u-blox log of the same drive starts at 2020-02-07 02:14:17 UTC.
        let on = span
            .clone()
            .on_ride_clock(Some(1_581_041_657.0), None, "ublox")
            .unwrap();
        assert_eq!(on.t_s[0], -46.0);
        assert!((span.points[0].lat_deg - 37.4264).abs() < 1e-3);
        let garmin = read_reference(&shared.join("gpx/garmin-activity.gpx")).unwrap();
        let garmin_s = garmin.t_s.last().unwrap() - garmin.t_s[0];
        eprintln!("Garmin: {} points over {garmin_s} s", garmin.t_s.len());
        assert!(garmin.t_s.len() > 900 && (5400.0..5600.0).contains(&garmin_s));
        assert!(garmin.has_alt);
    }

    #[test]
    fn a_truth_csv_reads_with_heights_and_without() {
        let r = parse_reference(
            b"# truth\nt_s,lat_deg,lon_deg,alt_m\n0,52.5,13.37,76\n0.5,52.50001,13.37,76.1\n",
            "truth.csv",
        )
        .unwrap();
        assert_eq!(r.t_s, vec![0.0, 0.5]);
        assert!(r.has_alt && (r.points[1].alt_m - 76.1).abs() < 1e-12);
        let r = parse_reference(b"lat_deg,t_s,lon_deg\n1,0,2\n1,1,2\n", "r.csv").unwrap();
        assert!(!r.has_alt && r.points[0].alt_m.is_nan());
        assert_eq!(r.points[0].lon_deg, 2.0);
    }

    #[test]
    fn bad_references_name_file_line_and_column() {
        let err = |text: &str| {
            parse_reference(text.as_bytes(), "ref.csv")
                .unwrap_err()
                .to_string()
        };
        let e = err("t_s,lat_deg,lon_deg\n0,1,2\n1,x,2\n");
        assert!(
            e.contains("ref.csv:3") && e.contains("lat_deg") && e.contains("'x'"),
            "{e}"
        );
        let e = err("t_s,lat_deg,lon_deg\n0,1,2\n0,1,2\n");
        assert!(
            e.contains("ref.csv:3") && e.contains("t_s") && e.contains("increase"),
            "{e}"
        );
        let e = err("t_s,lat_deg,lon_deg\n0,1,NaN\n1,1,2\n");
        assert!(e.contains("ref.csv:2") && e.contains("lon_deg"), "{e}");
        let e = err("t_s,lat,lon\n0,1,2\n");
        assert!(e.contains("no 'lat_deg' column"), "{e}");
        let e = err("t_s,lat_deg,lon_deg\n0,1\n1,1,2\n");
        assert!(e.contains("ref.csv:2") && e.contains("short"), "{e}");
        let e = err("t_s,lat_deg,lon_deg\n0,91,2\n1,1,2\n");
        assert!(e.contains("lat_deg") && e.contains("no latitude"), "{e}");
        let e = err("t_s,lat_deg,lon_deg\n0,1,2\n");
        assert!(e.contains("at least two"), "{e}");
    }

    /// A reference whose logger stopped while writing (a flat battery, a
    /// recorder killed) keeps every point before the cut, and says so:
    /// refused whole, it took the fit with it. Cut from the real files:
    /// the comma drive's truth, the Garmin GPX and the SPAN GGA.
    #[test]
    fn a_reference_cut_short_keeps_the_points_before_the_cut() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared");
        let read = |p: &str| std::fs::read(root.join(p)).unwrap();
        // Cut inside a row: the short last row is left out, naming its line.
        let csv = read("real/comma2k19-example1/truth.csv");
        let whole = parse_reference(&csv, "truth.csv").unwrap();
        assert!(whole.warnings.is_empty());
        let cut = &csv[..200_020];
        let r = parse_reference(cut, "truth.csv").unwrap();
        assert_eq!(r.t_s[..], whole.t_s[..r.t_s.len()]);
        assert!(r.t_s.len() > 4400 && r.t_s.len() < whole.t_s.len());
        assert_eq!(r.warnings.len(), 1);
        assert!(r.warnings[0].contains("truth.csv:4463") && r.warnings[0].contains("left out"));
        // The same short row with its line end is bad input, as before.
        let mut ended = cut.to_vec();
        ended.push(b'\n');
        let e = parse_reference(&ended, "truth.csv")
            .unwrap_err()
            .to_string();
        assert!(e.contains("truth.csv:4463") && e.contains("short"), "{e}");

        // GPX cut inside a track point: closed after the last whole one.
        let gpx = read("formats/gpx/garmin-activity.gpx");
        let whole = parse_gpx(&gpx, "a.gpx").unwrap();
        let r = parse_gpx(&gpx[..150_000], "a.gpx").unwrap();
        assert!(
            r.t_s.len() > 300 && r.t_s.len() < whole.t_s.len(),
            "{}",
            r.t_s.len()
        );
        assert_eq!(r.t_s[..], whole.t_s[..r.t_s.len()]);
        assert_eq!(r.points[..], whole.points[..r.points.len()]);
        assert!(r.warnings.len() == 1 && r.warnings[0].contains("before the cut"));
        // A file with its end and a fault of another kind, or cut before
        // any whole point, is no GPX, as before.
        let mut broken = gpx.clone();
        broken.drain(100_000..100_010);
        assert!(parse_gpx(&broken, "a.gpx").is_err());
        assert!(parse_gpx(&gpx[..300], "a.gpx").is_err());

        // NMEA cut inside a GGA: that sentence is left out, even where its
        // fields still read (a cut height).
        let gga = read("formats/nmea/MTV.Local1.SPAN.20200206-181434.gga");
        let whole = parse_nmea(&gga, "s.gga").unwrap();
        let text = std::str::from_utf8(&gga).unwrap();
        let start = text[..100_000].rfind("$GPGGA").unwrap();
        let cut = &text[..start + 60];
        let r = parse_nmea(cut.as_bytes(), "s.gga").unwrap();
        let full = parse_nmea(&gga[..start], "s.gga").unwrap();
        assert_eq!(r.t_s, full.t_s);
        assert!(r.t_s.len() > 100 && r.t_s.len() < whole.t_s.len());
        assert!(
            r.warnings.len() == 1 && r.warnings[0].contains("checksum"),
            "{:?}",
            r.warnings
        );
        assert!(full.warnings.is_empty());
    }
}
