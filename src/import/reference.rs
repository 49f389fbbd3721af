//! Reference tracks: a better trajectory of the same drive (RTK, an INS, a
//! survey, a second receiver) to measure a fit against, as evo does for SLAM.
//!
//! Read from `t_s,lat_deg,lon_deg[,alt_m]` CSV on the ride's own clock (the
//! `truth.csv` of the shared real drives and of `gyropath simulate --truth`).
//! Columns are found by name; `#` lines are comments. Time must increase
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
}

/// Read a reference track (see the module documentation).
pub fn read_reference(path: &Path) -> Result<ReferenceTrack, LoadError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| LoadError::Io {
        file: file.clone(),
        error,
    })?;
    parse_reference(&bytes, &file)
}

/// Parse a reference track from CSV bytes; `file` names it in errors.
pub fn parse_reference(bytes: &[u8], file: &str) -> Result<ReferenceTrack, LoadError> {
    let mut rdr = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(bytes);
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
        source: file.to_string(),
        t_s: Vec::new(),
        points: Vec::new(),
        has_alt: calt.is_some(),
    };
    for record in rdr.records() {
        let record = record.map_err(|e| whole(format!("unreadable CSV: {e}")))?;
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
    }
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
}
