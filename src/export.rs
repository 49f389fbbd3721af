//! Outputs: the reconstructed path (CSV, the shared spec's output format) and
//! the fit report (JSON). Files are written to a temporary file beside the
//! target and renamed into place, and never over the input log.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use thiserror::Error;

use crate::model::rotation::compass_deg;
use crate::model::{Model, Trajectory, Uncertainty};
use crate::optimisation::{FitSettings, FitStats, Reconstruction};

#[derive(Debug, Error)]
pub enum ExportError {
    /// The OS's reason is part of the message, not a chained source, so
    /// that a chain printer (anyhow's `{:#}`) says it once.
    #[error("{path}: cannot write: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{0}: refusing to write over the input log")]
    WouldOverwriteInput(String),
    #[error("{path}: unknown {what} format; write {choices}")]
    UnknownFormat {
        path: String,
        what: &'static str,
        choices: &'static str,
    },
    #[error("{path}: cannot write: there is no folder {folder}")]
    NoFolder { path: String, folder: String },
}

/// The folder an output named `path` goes into must exist: said before a
/// fit, not after minutes of it (a 6-hour ride's fit was lost to a typo in
/// `--out`'s folder). Standard output and special files have none to check.
fn check_folder(path: &Path) -> Result<(), ExportError> {
    if path.as_os_str() == "-" || is_special(path) {
        return Ok(());
    }
    match path.parent() {
        Some(folder) if !folder.as_os_str().is_empty() && !folder.is_dir() => {
            Err(ExportError::NoFolder {
                path: path.display().to_string(),
                folder: folder.display().to_string(),
            })
        }
        _ => Ok(()),
    }
}

/// Write an output through `fill`, where the user said:
/// - `-` is standard output;
/// - a special file (a terminal, a pipe, `/dev/stdout`, `/dev/fd/N`, anything
///   under `/dev` or `/proc`) is written in place, appending, never replaced:
///   replacing `/dev/stdout` by a regular file (as root) breaks the machine's
///   standard output for everyone;
/// - a regular file is written to a temporary file beside it and renamed over
///   it, so a crash never leaves half a file; a symbolic link to a regular
///   file keeps the link and gets its target replaced.
///
/// `protect` names a file that must not be overwritten (the input log).
pub fn write_atomically(
    path: &Path,
    protect: Option<&Path>,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), ExportError> {
    let io = |error| ExportError::Io {
        path: path.display().to_string(),
        error,
    };
    if is_stdout(path) {
        let mut out = std::io::stdout().lock();
        return fill(&mut out).and_then(|_| out.flush()).map_err(io);
    }
    if path == Path::new("/dev/stderr") {
        let mut out = std::io::stderr().lock();
        return fill(&mut out).and_then(|_| out.flush()).map_err(io);
    }
    if let Some(input) = protect
        && let (Ok(a), Ok(b)) = (std::fs::canonicalize(input), std::fs::canonicalize(path))
        && a == b
    {
        return Err(ExportError::WouldOverwriteInput(path.display().to_string()));
    }
    if is_special(path) {
        let result = (|| {
            let file = std::fs::OpenOptions::new().append(true).open(path)?;
            let mut w = std::io::BufWriter::new(file);
            fill(&mut w)?;
            w.flush()
        })();
        return result.map_err(io);
    }
    // A link to a regular file: replace its target, keep the link.
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(path).map_err(io)?,
        _ => path.to_path_buf(),
    };
    let dir = target
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = target
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    let tmp: PathBuf = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w)?;
        w.flush()?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, &target)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}

/// Whether an output named `path` goes to standard output (`-` or `/dev/stdout`).
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-" || path == Path::new("/dev/stdout")
}

/// A file that is written in place, never replaced: anything under `/dev` or
/// `/proc`, or an existing path (links followed) that is not a regular file.
fn is_special(path: &Path) -> bool {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    if absolute.starts_with("/dev") || absolute.starts_with("/proc") {
        return true;
    }
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// The format of a path output, from its file name's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathFormat {
    /// `t_s,lat_deg,lon_deg,alt_m,...` (see [`write_path_csv`]).
    Csv,
    /// A GPX 1.1 track (see [`write_path_gpx`]).
    Gpx,
    /// A TUM trajectory for evo (see [`write_path_tum`]).
    Tum,
}

impl PathFormat {
    pub const CHOICES: &str = ".csv (or - for standard output), .gpx, .tum (for evo)";

    /// The format `path` asks for: `-` and special files get CSV, `.csv` and
    /// `.gpx` their own; anything else is an error naming the choices, since
    /// CSV written into `path.kml` is a file no tool opens.
    pub fn of(path: &Path) -> Result<Self, ExportError> {
        if path.as_os_str() == "-" || is_special(path) {
            return Ok(Self::Csv);
        }
        check_folder(path)?;
        match extension(path).as_deref() {
            Some("csv") => Ok(Self::Csv),
            Some("gpx") => Ok(Self::Gpx),
            Some("tum") => Ok(Self::Tum),
            _ => Err(ExportError::UnknownFormat {
                path: path.display().to_string(),
                what: "path",
                choices: Self::CHOICES,
            }),
        }
    }
}

/// A report output (JSON) must be named `.json`, `-` or a special file.
pub fn check_report_name(path: &Path) -> Result<(), ExportError> {
    if path.as_os_str() == "-" || is_special(path) {
        return Ok(());
    }
    if extension(path).as_deref() == Some("json") {
        return check_folder(path);
    }
    Err(ExportError::UnknownFormat {
        path: path.display().to_string(),
        what: "report",
        choices: ".json (or - for standard output)",
    })
}

/// An HTML report must be named `.html` or `.htm`, `-` or a special file.
pub fn check_html_name(path: &Path) -> Result<(), ExportError> {
    let ext = extension(path);
    if path.as_os_str() == "-" || is_special(path) {
        return Ok(());
    }
    if matches!(ext.as_deref(), Some("html" | "htm")) {
        return check_folder(path);
    }
    Err(ExportError::UnknownFormat {
        path: path.display().to_string(),
        what: "HTML report",
        choices: ".html (or - for standard output)",
    })
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

/// The version of the JSON outputs' shape: 2 since a settings' `limit` is
/// `null` (not `"None"`) and a fit report has `reference`.
pub const SCHEMA_VERSION: u32 = 2;

/// A JSON output with what made it: every report, diagnosis and check that
/// gyropath writes carries the tool's version and the schema's, so a
/// script reading it can tell which fields to expect.
#[derive(serde::Serialize)]
pub struct Versioned<'a, T: serde::Serialize> {
    pub tool: &'static str,
    pub tool_version: &'static str,
    pub schema_version: u32,
    #[serde(flatten)]
    pub content: &'a T,
}

/// Write `content` as pretty JSON with the tool's and the schema's versions.
pub fn write_json(w: &mut dyn Write, content: &impl serde::Serialize) -> std::io::Result<()> {
    let versioned = Versioned {
        tool: "gyropath",
        tool_version: env!("CARGO_PKG_VERSION"),
        schema_version: SCHEMA_VERSION,
        content,
    };
    serde_json::to_writer_pretty(&mut *w, &versioned).map_err(std::io::Error::other)?;
    writeln!(w)
}

/// The `#` lines that open a path file: what the columns are measured
/// from, so that the path lines up with the user's other tools without
/// gyropath: the source, the Unix time of `t_s = 0` when the source knows it
/// (a bag's first message), the local frame's origin and the heading's
/// convention. The ride-log and reference readers, pandas (`comment="#"`)
/// and evo skip them.
fn write_path_header(out: &mut dyn Write, sig: &crate::signals::Signals) -> std::io::Result<()> {
    let origin = sig.frame.origin();
    writeln!(out, "# gyropath path {}", env!("CARGO_PKG_VERSION"))?;
    writeln!(out, "# source: {}", sig.source.replace(['\n', '\r'], " "))?;
    match sig.t0_unix_s {
        Some(t0) => writeln!(
            out,
            "# t0_unix_s: {t0:.9}\n# time: t_s is seconds since t0_unix_s (the source's clock)"
        )?,
        None => writeln!(
            out,
            "# time: t_s is the ride log's own clock (the log gives no absolute time)"
        )?,
    }
    writeln!(
        out,
        "# origin_lat_deg: {:.9}\n# origin_lon_deg: {:.9}\n# origin_alt_m: {:.3}",
        origin.lat_deg, origin.lon_deg, origin.alt_m
    )?;
    writeln!(
        out,
        "# frame: east, north, up in metres from the origin, in the plane tangent to the WGS84 ellipsoid there"
    )?;
    writeln!(
        out,
        "# heading: of the sensor's forward (x) axis, degrees clockwise from true north, 0-360"
    )
}

/// Write `t_s,lat_deg,lon_deg,alt_m` (then east, north, up in metres and the
/// compass heading, and with `sigma` the path's 1-sigma east, north and up)
/// for every row of the log, after the header of [`write_path_header`].
pub fn write_path_csv(
    out: &mut dyn Write,
    model: &Model,
    theta: &[f64],
    sigma: Option<&Uncertainty>,
) -> std::io::Result<()> {
    let sig = &model.signals;
    write_path_header(out, sig)?;
    writeln!(
        out,
        "t_s,lat_deg,lon_deg,alt_m,east_m,north_m,up_m,heading_deg{}",
        if sigma.is_some() {
            ",sigma_east_m,sigma_north_m,sigma_up_m"
        } else {
            ""
        }
    )?;
    // From one sweep, a block of poses at a time (a 6-hour ride's path is
    // never held in memory), each block's lines formatted side by side:
    // formatting is most of the work (about 0.1 s a 30-minute ride).
    let mut block: Vec<(usize, nalgebra::UnitQuaternion<f64>, nalgebra::Vector3<f64>)> =
        Vec::with_capacity(WRITE_BLOCK_ROWS);
    let mut result = Ok(());
    let mut flush = |block: &mut Vec<_>, result: &mut std::io::Result<()>| {
        if result.is_ok() {
            let text: Vec<String> = block
                .par_chunks(WRITE_BLOCK_ROWS / 8)
                .map(|rows| path_lines(sig, sigma, rows))
                .collect();
            *result = text.iter().try_for_each(|t| out.write_all(t.as_bytes()));
        }
        block.clear();
    };
    model.for_each_pose(theta, |j, q, p| {
        block.push((j, *q, *p));
        if block.len() == WRITE_BLOCK_ROWS {
            flush(&mut block, &mut result);
        }
    });
    flush(&mut block, &mut result);
    result
}

/// Rows of a path file formatted at a time (see [`write_path_csv`]).
const WRITE_BLOCK_ROWS: usize = 16_384;

/// The path file's lines of `rows` (row, attitude, position).
fn path_lines(
    sig: &crate::signals::Signals,
    sigma: Option<&Uncertainty>,
    rows: &[(usize, nalgebra::UnitQuaternion<f64>, nalgebra::Vector3<f64>)],
) -> String {
    use std::fmt::Write as _;
    let mut text = String::with_capacity(rows.len() * 96);
    for (j, q, p) in rows {
        let g = sig.frame.to_geodetic(p);
        let f = q * nalgebra::Vector3::x();
        // Writing to a String cannot fail.
        let _ = write!(
            text,
            "{},{},{},{},{},{},{},{}",
            sig.t[*j],
            Fixed(g.lat_deg, 9),
            Fixed(g.lon_deg, 9),
            Fixed(g.alt_m, 3),
            Fixed(p.x, 3),
            Fixed(p.y, 3),
            Fixed(p.z, 3),
            Fixed(compass_deg(f.x, f.y), 2)
        );
        let _ = match sigma {
            Some(u) => {
                let [e, n, up] = u.sigma_enu(*j);
                writeln!(text, ",{},{},{}", Fixed(e, 3), Fixed(n, 3), Fixed(up, 3))
            }
            None => writeln!(text),
        };
    }
    text
}

/// `x` with `decimals` digits after the point, exactly as `{:.N}` writes
/// it, in a tenth of the time: a path is millions of such numbers (a
/// 30-minute ride's CSV took longer to format than the ride took to read).
///
/// `y = |x| 10^N` rounded to the nearest integer `n` is what `{:.N}` prints,
/// unless the exact product lies within the floating-point error of `y`
/// (at most an ulp, `EPSILON y`) from a tie `k + 1/2`: then `y` alone
/// cannot tell which way the exact value rounds, and std's exact formatter
/// decides. So does anything too large for the integer path (`y >= 2^52`)
/// or not finite. The sign is printed for every negative value, as std
/// does (`-0.000` for `-0.0001`).
struct Fixed(f64, u32);

impl std::fmt::Display for Fixed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Fixed(x, decimals) = *self;
        let d = decimals as usize;
        let y = x.abs() * 10f64.powi(decimals as i32);
        let floor = y.floor();
        let frac = y - floor;
        if decimals > 15
            || !y.is_finite()
            || y >= 4_503_599_627_370_496.0
            || (frac - 0.5).abs() <= 4.0 * f64::EPSILON * y.max(1.0)
        {
            return write!(f, "{x:.d$}");
        }
        let mut n = if frac > 0.5 { floor + 1.0 } else { floor } as u64;
        // Digits from the right: the decimals, the point, the integer part.
        let mut buf = [0u8; 40];
        let mut at = buf.len();
        for _ in 0..d {
            at -= 1;
            buf[at] = b'0' + (n % 10) as u8;
            n /= 10;
        }
        if d > 0 {
            at -= 1;
            buf[at] = b'.';
        }
        loop {
            at -= 1;
            buf[at] = b'0' + (n % 10) as u8;
            n /= 10;
            if n == 0 {
                break;
            }
        }
        if x.is_sign_negative() {
            at -= 1;
            buf[at] = b'-';
        }
        // Only ASCII digits, '.' and '-' were written.
        f.write_str(std::str::from_utf8(&buf[at..]).map_err(|_| std::fmt::Error)?)
    }
}

/// Write the path as a TUM trajectory, what evo and the SLAM benchmarks read:
/// one line `t x y z qx qy qz qw` per row, space separated, after the header
/// of [`write_path_header`] (`#` lines, which evo skips). `t` is Unix time
/// when the source knows it (`t0_unix_s + t_s`), so the path lines up with
/// other tools' trajectories by time; else the log's own clock. `x y z` are
/// east, north, up (m) from the frame's origin; `q` turns the sensor frame
/// (x forward, y left, z up) into that local frame, so `q * (1, 0, 0)` is the
/// forward direction.
pub fn write_path_tum(out: &mut dyn Write, model: &Model, theta: &[f64]) -> std::io::Result<()> {
    let sig = &model.signals;
    write_path_header(out, sig)?;
    writeln!(out, "# timestamp tx ty tz qx qy qz qw")?;
    let t0 = sig.t0_unix_s.unwrap_or(0.0);
    let mut result = Ok(());
    model.for_each_pose(theta, |j, q, p| {
        if result.is_err() {
            return;
        }
        result = writeln!(
            out,
            "{} {} {} {} {} {} {} {}",
            Fixed(t0 + sig.t[j], 6),
            Fixed(p.x, 4),
            Fixed(p.y, 4),
            Fixed(p.z, 4),
            Fixed(q.i, 9),
            Fixed(q.j, 9),
            Fixed(q.k, 9),
            Fixed(q.w, 9)
        );
    });
    result
}

/// Write the reconstructed path as a GPX 1.1 track (for map tools), at most
/// 10 points per second of ride (a 100 Hz path at full rate only bloats the file).
/// Log time goes into each point's `<extensions><t_s>`, since the log carries
/// no absolute date.
pub fn write_path_gpx(
    out: &mut dyn Write,
    model: &Model,
    path: &Trajectory,
) -> std::io::Result<()> {
    let sig = &model.signals;
    let name = xml_escape(&sig.source);
    writeln!(out, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(
        out,
        r#"<gpx version="1.1" creator="gyropath" xmlns="http://www.topografix.com/GPX/1/1">"#
    )?;
    writeln!(
        out,
        "  <trk>\n    <name>{name} (gyropath)</name>\n    <trkseg>"
    )?;
    let mut last_t = f64::NEG_INFINITY;
    for j in 0..sig.len() {
        if sig.t[j] - last_t < 0.1 - 1e-9 && j + 1 != sig.len() {
            continue;
        }
        last_t = sig.t[j];
        let g = sig.frame.to_geodetic(&path.p[j]);
        writeln!(
            out,
            r#"      <trkpt lat="{:.9}" lon="{:.9}"><ele>{:.3}</ele><extensions><t_s>{}</t_s></extensions></trkpt>"#,
            g.lat_deg, g.lon_deg, g.alt_m, sig.t[j]
        )?;
    }
    writeln!(out, "    </trkseg>\n  </trk>\n</gpx>")
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// One fitted parameter, in the units it is shown in.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ParamValue {
    pub name: String,
    pub value: f64,
    pub unit: String,
    /// Held at its starting value, not fitted (roll and pitch of a planar model).
    pub fixed: bool,
    /// 1-sigma uncertainty under the fit's noise model (see
    /// `model::uncertainty`); `None` where not computed (segment biases, the
    /// constant bias, fixed parameters).
    pub sigma: Option<f64>,
    /// `false` when the sigma spans what the parameter can physically be:
    /// the ride does not determine it (see `ParamInfo::within`).
    pub determined: bool,
    /// Fitted apart from the least squares and held there (the odometer
    /// gain of the heavy-tailed fit, see `optimisation::noise::calibration`);
    /// its sigma is that fit's.
    #[serde(default)]
    pub held: bool,
}

impl ParamValue {
    /// "value ± sigma unit", or why there is no sigma.
    pub fn describe(&self) -> String {
        if self.fixed {
            return "not fitted".to_string();
        }
        let value = crate::effects::plus_minus(
            self.value,
            self.sigma.map(|s| (s, self.determined)),
            &self.unit,
            5,
        );
        if self.held {
            format!("{value} (held: the heavy-tailed fit's)")
        } else {
            value
        }
    }
}

/// The fit report written by `gyropath fit --json`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitReport {
    pub source: String,
    pub rows: usize,
    /// Of `rows`, those filled across gaps in the log (`crate::log_gaps`).
    pub rows_filled: usize,
    pub duration_s: f64,
    pub gps_fixes: usize,
    pub model: Vec<String>,
    pub settings: FitSettings,
    pub iterations_step1: usize,
    pub iterations_step2: usize,
    pub stats: FitStats,
    /// The attitude model (3D or planar) and why it was chosen.
    pub attitude: String,
    /// Where the distance came from (wheel sensor, odometer, GNSS speed).
    pub distance_source: String,
    /// The noise settings the fit ran with (`settings.model` holds what was
    /// asked for): estimated from the ride, with their 1-sigma ranges, or set.
    pub noise: Option<crate::optimisation::NoiseEstimate>,
    /// `-2 ln L` of other segment lengths (s) relative to the best (see
    /// `optimisation::noise::segment_preference`); empty without segments,
    /// and unless asked for ([`FitReport::with_segment_preference`]).
    pub segment_preference: Vec<(f64, f64)>,
    /// The effective GPS sigma (m), correlation time (s, `None`: independent fixes) and bias walk.
    pub gps_sigma_m: f64,
    pub gps_tau_s: Option<f64>,
    /// The GPS heights' own correlation time (s; `None`: `gps_tau_s`).
    #[serde(default)]
    pub gps_tau_vertical_s: Option<f64>,
    /// The jitter on top of a correlated error (m; see `model::noise`).
    #[serde(default)]
    pub gps_white_m: f64,
    /// The GPS error law the fit (and its `stats`) is under, in words.
    pub gps_noise: String,
    pub bias_walk: Option<f64>,
    /// Parameters per effect id.
    pub parameters: BTreeMap<String, Vec<ParamValue>>,
    pub warnings: Vec<String>,
    pub elapsed_s: f64,
    /// The path against a reference track, when one was given (`null` otherwise).
    pub reference: Option<crate::diagnosis::ReferenceComparison>,
    /// The bias the sensor had: the constant plus each segment's, per
    /// fitted axis (x, y, z; `null` for an axis held, as a yaw-rate sensor's
    /// roll and pitch). `gyro_bias` alone is only its constant part.
    pub bias_total: [Option<BiasTotal>; 3],
}

/// One axis of the total gyro bias over the ride (deg/s): its mean over
/// time (each segment weighted by its length) and its range over segments.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct BiasTotal {
    pub mean_dps: f64,
    pub min_dps: f64,
    pub max_dps: f64,
    pub segments: usize,
    /// How well the bias at any moment is known: the median over segments
    /// of a segment's 1-sigma (deg/s; `null` when not computed).
    pub sigma_per_segment_dps: Option<f64>,
}

impl BiasTotal {
    /// Per axis, from the bias per segment (`diagnosis::segment_biases`) and
    /// their 1-sigma (`diagnosis::segment_sigmas`, same length, or empty);
    /// `fitted[a]` says whether axis `a` is estimated at all.
    pub fn of(
        segments: &[crate::diagnosis::SegmentBias],
        sigmas: &[[f64; 3]],
        fitted: [bool; 3],
    ) -> [Option<Self>; 3] {
        [0, 1, 2].map(|a| {
            let span: f64 = segments.iter().map(|s| s.t1 - s.t0).sum();
            (fitted[a] && !segments.is_empty() && span > 0.0).then(|| Self {
                mean_dps: segments
                    .iter()
                    .map(|s| s.bias_dps[a] * (s.t1 - s.t0))
                    .sum::<f64>()
                    / span,
                min_dps: segments
                    .iter()
                    .map(|s| s.bias_dps[a])
                    .fold(f64::INFINITY, f64::min),
                max_dps: segments
                    .iter()
                    .map(|s| s.bias_dps[a])
                    .fold(f64::NEG_INFINITY, f64::max),
                segments: segments.len(),
                sigma_per_segment_dps: {
                    let mut s: Vec<f64> = sigmas
                        .iter()
                        .map(|v| v[a])
                        .filter(|v| v.is_finite())
                        .collect();
                    (!s.is_empty() && s.len() == segments.len())
                        .then(|| crate::statistics::median(&mut s))
                },
            })
        })
    }

    /// "0.0530 deg/s (0.0410 to 0.0890 over 57 segments), 1-sigma 0.0040 per segment".
    pub fn describe(&self) -> String {
        let sigma = self.sigma_per_segment_dps.map_or(String::new(), |s| {
            if self.segments > 1 {
                format!(", 1-sigma {s:.4} per segment")
            } else {
                format!(" ± {s:.4}")
            }
        });
        if self.segments > 1 {
            format!(
                "{:.4} deg/s ({:.4} to {:.4} over {} segments){sigma}",
                self.mean_dps, self.min_dps, self.max_dps, self.segments
            )
        } else {
            format!("{:.4} deg/s{sigma}", self.mean_dps)
        }
    }
}

impl FitReport {
    /// The report of `fit`, with the sigmas of its parameters.
    pub fn new(fit: &Reconstruction, elapsed_s: f64) -> Self {
        Self::with_sigmas(fit, elapsed_s, fit.model().reported_sigmas(fit.params()))
    }

    /// The report with the segment lengths' likelihoods filled in. Only the
    /// JSON report and the verbose summary show them, and they cost five
    /// chain systems and likelihoods: a tenth of a 30-minute ride's fit
    /// (8.6 % of its CPU samples), spent for nothing on every other fit.
    pub fn with_segment_preference(mut self, fit: &Reconstruction) -> Self {
        self.segment_preference =
            crate::optimisation::noise::segment_preference(fit.model(), fit.params());
        self
    }

    /// The report with the sigmas of `u` (see [`Model::uncertainty`]).
    pub fn with_uncertainty(fit: &Reconstruction, elapsed_s: f64, u: &Uncertainty) -> Self {
        Self::with_sigmas(fit, elapsed_s, u.params.clone())
    }

    /// `sigmas`: per parameter, internal units.
    fn with_sigmas(fit: &Reconstruction, elapsed_s: f64, sigmas: Vec<Option<f64>>) -> Self {
        let model = fit.model();
        let sig = &model.signals;
        let mut parameters: BTreeMap<String, Vec<ParamValue>> = BTreeMap::new();
        let fixed = model.fixed_mask();
        let fixed_mask = fixed.clone();
        // Read before the loop below takes the sigmas.
        let bias_sigmas = crate::diagnosis::segment_sigmas(model, &sigmas);
        for ((((effect, info), value), fixed), sigma) in model
            .param_infos()
            .into_iter()
            .zip(fit.params())
            .zip(fixed)
            .zip(sigmas)
        {
            // A held parameter was fitted, by the heavy-tailed fit: its sigma.
            let held = fit.noise().and_then(|n| n.held(&effect, &info.name));
            let sigma = held.map_or(sigma, |c| c.robust_sigma);
            let determined = sigma.is_none_or(|s| info.determined(s));
            parameters.entry(effect).or_default().push(ParamValue {
                name: info.name,
                value: value * info.scale,
                unit: info.unit.to_string(),
                fixed: fixed && held.is_none(),
                sigma: sigma.map(|s| s * info.scale.abs()),
                determined,
                held: held.is_some(),
            });
        }
        let [s1, s2] = fit.phase_iterations();
        Self {
            source: sig.source.clone(),
            rows: sig.len(),
            rows_filled: sig.filled_rows(),
            duration_s: sig.duration(),
            gps_fixes: sig.fixes.len(),
            model: model.effect_ids(),
            settings: fit.settings().clone(),
            iterations_step1: s1,
            iterations_step2: s2,
            stats: fit.stats(),
            attitude: sig.attitude.describe(),
            distance_source: sig.odometer.describe(),
            noise: fit.noise().cloned(),
            segment_preference: Vec::new(),
            gps_sigma_m: model.spec.sigma_horizontal_m,
            gps_tau_s: model.spec.gps_tau_s,
            gps_tau_vertical_s: model.spec.gps_tau_vertical_s,
            gps_white_m: model.spec.gps_white_m,
            gps_noise: model.spec.gps_noise_text(),
            bias_walk: model.spec.bias_walk_dps_sqrt_s,
            parameters,
            warnings: sig.warnings.clone(),
            elapsed_s,
            reference: None,
            bias_total: {
                let fitted = model.effect_index("gyro_bias").map_or([false; 3], |e| {
                    let r = model.range(e);
                    [0, 1, 2].map(|a| !fixed_mask[r.start + a])
                });
                BiasTotal::of(
                    &crate::diagnosis::segment_biases(model, fit.params()),
                    &bias_sigmas,
                    fitted,
                )
            },
        }
    }

    /// A parameter's shown value by effect id and name.
    pub fn value(&self, effect: &str, name: &str) -> Option<f64> {
        self.parameters
            .get(effect)?
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelSpec;
    use proptest::prelude::*;
    use std::sync::Arc;

    /// `Fixed` against std's exact `{:.N}` (what the path files wrote before).
    fn same_as_std(x: f64, d: u32) {
        let want = format!("{x:.0$}", d as usize);
        assert_eq!(Fixed(x, d).to_string(), want, "{x:e} to {d} decimals");
    }

    #[test]
    fn fixed_writes_ties_signs_and_edges_as_std_does() {
        for d in 0..=12 {
            for x in [
                0.0,
                -0.0,
                0.5,
                -0.5,
                1.5,
                2.5,
                0.125,
                0.375,
                -0.125,
                0.0005,
                0.0015,
                1e-4,
                -1e-4,
                9.9999999,
                0.999_999_999_5,
                123_456.789_5,
                52.520_008_5,
                4.5e15,
                -4.5e15,
                1e300,
                f64::MAX,
                f64::MIN_POSITIVE,
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ] {
                same_as_std(x, d);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]
        #[test]
        fn fixed_is_std_fixed(mantissa in -1.0e6f64..1.0e6, exponent in -8i32..6, d in 0u32..=10) {
            same_as_std(mantissa * 10f64.powi(exponent), d);
        }

        #[test]
        fn fixed_is_std_fixed_on_halves(k in -1_000_000_000i64..1_000_000_000, d in 0u32..=9) {
            // Values near a tie at the printed precision, where rounding is delicate.
            let x = (k as f64 + 0.5) / 10f64.powi(d as i32);
            same_as_std(x, d);
            same_as_std(x.next_up(), d);
            same_as_std(x.next_down(), d);
        }
    }

    #[test]
    fn gpx_has_one_point_per_tenth_of_a_second_with_lat_lon() {
        let sig = Arc::new(crate::testing::winding_signals(20.0, 100.0));
        let model = Model::new(sig, ModelSpec::default()).expect("model");
        let traj = model.trajectory(&model.initial_params());
        let mut buf = Vec::new();
        write_path_gpx(&mut buf, &model, &traj).expect("write");
        let text = String::from_utf8(buf).expect("utf8");
        assert!(text.starts_with("<?xml") && text.trim_end().ends_with("</gpx>"));
        let points = text.matches("<trkpt ").count();
        assert!((200..=202).contains(&points), "{points} points");
        let first = text
            .lines()
            .find(|l| l.contains("<trkpt"))
            .expect("a point");
        let g = model.signals.frame.to_geodetic(&traj.p[0]);
        assert!(
            first.contains(&format!("lat=\"{:.9}\"", g.lat_deg)),
            "{first}"
        );
    }

    #[test]
    fn special_files_are_written_in_place_and_links_are_kept() {
        use std::os::unix::fs::FileTypeExt;
        write_atomically(Path::new("/dev/null"), None, |w| w.write_all(b"x")).unwrap();
        let m = std::fs::metadata("/dev/null").unwrap();
        assert!(m.file_type().is_char_device(), "/dev/null was replaced");

        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("real.csv");
        std::fs::write(&target, "old").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_atomically(&link, None, |w| w.write_all(b"new")).unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
    }

    #[test]
    fn the_format_follows_the_extension() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            PathFormat::of(&dir.path().join("p.csv")).unwrap(),
            PathFormat::Csv
        );
        // A folder that is not there is said before any work is done.
        for e in [
            PathFormat::of(Path::new("no-such-folder/p.csv")).unwrap_err(),
            check_report_name(Path::new("no-such-folder/r.json")).unwrap_err(),
            check_html_name(Path::new("no-such-folder/r.html")).unwrap_err(),
        ] {
            assert!(
                e.to_string()
                    .ends_with("cannot write: there is no folder no-such-folder"),
                "{e}"
            );
        }
        assert_eq!(PathFormat::of(Path::new("p.GPX")).unwrap(), PathFormat::Gpx);
        assert_eq!(PathFormat::of(Path::new("-")).unwrap(), PathFormat::Csv);
        assert_eq!(
            PathFormat::of(Path::new("/dev/stdout")).unwrap(),
            PathFormat::Csv
        );
        let e = PathFormat::of(Path::new("p.kml")).unwrap_err().to_string();
        assert!(e.contains("p.kml") && e.contains(".gpx"), "{e}");
        assert!(check_report_name(Path::new("r.json")).is_ok());
        assert!(check_report_name(Path::new("-")).is_ok());
        let e = check_report_name(Path::new("r.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("r.txt") && e.contains(".json"), "{e}");
    }
}
