//! Every input format into one [`RideLog`]: the ride-log CSV (format:
//! `data/ride-log-format.md`), ROS 1 bags, ROS 2 bags (MCAP, alone or in a
//! rosbag2 folder), comma2k19 segments (folders of NumPy arrays) and CSV
//! exports described by a small TOML map. Then the
//! axes, units and datum are checked against the data ([`checks`]) and a
//! sensor mounting is applied ([`mount`]).
//!
//! One file per source format; each reader only turns bytes into samples or
//! rows. What is shared (sorting messages, joining streams on one timeline,
//! integrating speed) lives in [`timeline`], so a new format is one new file.
//! Every rejection names the file and, where there is one, the line and
//! column or the topic; a bad input never panics and never loads half.
//!
//! The measurements and the history behind these choices: docs/real-logs.md
//! (every format, the checks and the mounting, with worked examples).

pub mod camera;
pub mod chapters;
pub mod checks;
pub mod comma2k19;
mod csv_rows;
pub mod dataflash;
pub mod fit;
pub mod gnsslogger;
pub mod gps_track;
pub mod mapped_csv;
pub mod mount;
pub mod npy;
pub mod reference;
pub mod ride_csv;
pub mod ros1;
pub mod ros2;
pub mod timeline;
pub mod ulog;
pub mod wire;

use std::path::{Path, PathBuf};

use thiserror::Error;

pub use checks::{CheckReport, Level, Verdict};
pub use mount::Mount;
pub use reference::{ReferenceTrack, read_reference};
pub use ride_csv::{load_file, parse, parse_reader};
pub use timeline::{TopicChoice, TopicInfo, Topics};

/// The extensions of the files a ride is read from (a `.txt` is a ride
/// only when it is a GnssLogger log: [`is_ride_file`]).
pub const RIDE_EXTENSIONS: [&str; 8] = ["csv", "bag", "mcap", "ulg", "bin", "mp4", "mov", "txt"];

/// Whether a batch folder's file `path` is a ride, by its extension (and a
/// `.txt`'s header).
pub fn is_ride_file(path: &Path) -> bool {
    let Some(ext) = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
    else {
        return false;
    };
    path.is_file()
        && RIDE_EXTENSIONS.contains(&ext.as_str())
        && (ext != "txt" || gnsslogger::is_gnsslogger_file(path))
}

/// Why an input could not be loaded.
#[derive(Debug, Error)]
pub enum LoadError {
    /// The OS's reason is part of the message, not a chained source, so
    /// that a chain printer (anyhow's `{:#}`) says it once.
    #[error("{file}: cannot read: {error}")]
    Io { file: String, error: std::io::Error },
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
    /// A recording without a single GNSS fix (a camera that logs no GPS):
    /// a GPS track of the same ride can give it its fixes (`--gps-track`).
    #[error("{file}: {message}")]
    NoFix { file: String, message: String },
    /// A bag's record or message that cannot be decoded.
    #[error("{file}: topic '{topic}': {message}")]
    Topic {
        file: String,
        topic: String,
        message: String,
    },
}

pub use crate::ride::RideLog;

/// The kind of an input, told by its content (magic bytes) before its name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum SourceKind {
    /// gyropath's own ride-log CSV.
    RideCsv,
    /// A ROS 1 bag (`#ROSBAG V2.0`).
    Ros1Bag,
    /// A ROS 2 bag: a bare MCAP file or a rosbag2 folder holding one.
    Ros2Mcap,
    /// Any CSV export, read through a TOML column map.
    MappedCsv,
    /// A comma2k19 segment: a folder of NumPy arrays.
    Comma2k19,
    /// A PX4 ULog (`ULog` magic, `.ulg`).
    Ulog,
    /// A camera's telemetry (GoPro MP4 and what telemetry-parser reads).
    Camera,
    /// An Android phone's GnssLogger text log.
    GnssLogger,
    /// An ArduPilot DataFlash log (`.bin`).
    DataFlash,
}

impl SourceKind {
    pub fn label(self) -> &'static str {
        match self {
            Self::RideCsv => "ride-log CSV",
            Self::Ros1Bag => "ROS 1 bag",
            Self::Ros2Mcap => "ROS 2 bag (MCAP)",
            Self::MappedCsv => "mapped CSV",
            Self::Comma2k19 => "comma2k19 segment",
            Self::Ulog => "PX4 ULog",
            Self::Camera => "camera telemetry",
            Self::GnssLogger => "Android GnssLogger",
            Self::DataFlash => "ArduPilot DataFlash",
        }
    }

    /// Bags carry no mounting, so they are mounted by the checks unless told otherwise.
    pub fn default_mount(self) -> MountChoice {
        match self {
            Self::Ros1Bag | Self::Ros2Mcap | Self::Camera | Self::GnssLogger => MountChoice::Auto,
            Self::RideCsv | Self::MappedCsv | Self::Comma2k19 | Self::Ulog | Self::DataFlash => {
                MountChoice::AsLogged
            }
        }
    }
}

/// Which sensor mounting to apply on load.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum MountChoice {
    /// The source's default: `Auto` for bags, `AsLogged` for CSV.
    #[default]
    Default,
    /// The axes as the file has them.
    AsLogged,
    /// The mounting the checks recommend (as logged when they cannot tell).
    Auto,
    /// A mounting given by hand.
    Fixed(Mount),
}

impl std::str::FromStr for MountChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "" | "default" => Ok(Self::Default),
            "auto" => Ok(Self::Auto),
            "none" | "as-logged" | "identity" => Ok(Self::AsLogged),
            other => other.parse().map(Self::Fixed),
        }
    }
}

/// How to read an input.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportOptions {
    /// Topics of a bag (by message type when not given).
    pub topics: TopicChoice,
    pub mount: MountChoice,
    /// TOML column map: the input is a mapped CSV.
    pub map: Option<PathBuf>,
    /// A second CSV with the GPS fixes of a mapped CSV, joined by time.
    pub gps: Option<PathBuf>,
    /// The attitude model, `3d` or `planar`, written to the log's `attitude`
    /// metadata (`None`: as the log says, else chosen from the data).
    pub attitude: Option<String>,
    /// Where the distance comes from.
    pub distance: DistanceChoice,
    /// A Garmin FIT activity whose distance (its wheel-speed sensor's)
    /// becomes the ride's odometer, matched by UTC ([`fit::merge_distance`]).
    pub wheel: Option<PathBuf>,
    /// A GPS track of the same ride (GPX, FIT, NMEA, `t_s,lat_deg,lon_deg`
    /// CSV) whose points become the ride's fixes ([`gps_track::merge_track`]):
    /// for a camera, phone or robot log without GPS.
    pub gps_track: Option<PathBuf>,
    /// Keep only the rows from the first to the second time (s, on the
    /// log's own clock): a part of a ride, such as one side of a pause the
    /// gyro cannot be integrated across.
    pub between: Option<(f64, f64)>,
}

/// Where a ride's distance comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DistanceChoice {
    /// The wheel sensor or odometer when the log has one, else the GNSS speed.
    #[default]
    Auto,
    /// The GNSS speed, whatever else the log has: to fit a log as if it had
    /// no wheel sensor (or one known to be faulty), and to compare the two.
    Gnss,
}

impl std::str::FromStr for DistanceChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => Ok(Self::Auto),
            "gnss" => Ok(Self::Gnss),
            other => Err(format!("'{other}' is neither 'auto' nor 'gnss'")),
        }
    }
}

/// Whether `path` is a folder that holds one ride (a rosbag2 folder, a
/// comma2k19 segment), not a folder of rides.
pub fn is_ride_folder(path: &Path) -> bool {
    path.is_dir() && (path.join("metadata.yaml").is_file() || comma2k19::is_segment(path))
}

/// What was read, from where, and what the checks say of it.
#[derive(Clone, Debug)]
pub struct Imported {
    pub log: RideLog,
    pub kind: SourceKind,
    /// The topics read and the candidates there were (bags only).
    pub topics: Option<Topics>,
    /// The mounting applied on load (`None`: as logged).
    pub mount: Option<Mount>,
    /// Verdicts on the data as read (before the mounting).
    pub check: CheckReport,
}

impl Imported {
    /// Every warning to show a user: the reader's, then the checks' that are not fine.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = self.log.warnings.clone();
        w.extend(self.check.warnings(self.mount.as_ref()));
        w
    }

    /// The signals of the imported log, consuming it, with the checks'
    /// warnings after those of the reader and the derivation (the signals
    /// already carry the log's own warnings: they are not added twice, nor
    /// is a check's that only repeats one of the derivation's, as the GPS
    /// blunders left out).
    pub fn into_signals(self) -> Result<crate::signals::Signals, crate::signals::SignalError> {
        let checks = self.check.warnings(self.mount.as_ref());
        let mut signals = crate::signals::Signals::from_owned_log(self.log)?;
        let new: Vec<String> = checks
            .into_iter()
            .filter(|c| !signals.warnings.iter().any(|w| c.ends_with(w.as_str())))
            .collect();
        signals.warnings.extend(new);
        Ok(signals)
    }
}

/// The bytes of the file at `path` and its name for messages.
/// Open `path` for reading, the I/O error naming it; with its name for messages.
pub(crate) fn open_file(path: &Path) -> Result<(std::fs::File, String), LoadError> {
    let file = path.display().to_string();
    match std::fs::File::open(path) {
        Ok(f) => Ok((f, file)),
        Err(error) => Err(LoadError::Io { file, error }),
    }
}

/// The first bytes of the file at `path` (as many as fit `buf`, fewer for a
/// short file): what its kind is told by.
pub(crate) fn head(path: &Path, buf: &mut [u8]) -> std::io::Result<usize> {
    std::fs::File::open(path).and_then(|mut f| ros1::read_full(&mut f, buf))
}

pub(crate) fn read_bytes(path: &Path) -> Result<(Vec<u8>, String), LoadError> {
    let file = path.display().to_string();
    match std::fs::read(path) {
        Ok(bytes) => Ok((bytes, file)),
        Err(error) => Err(LoadError::Io { file, error }),
    }
}

/// Tell the kind of `path` by its content, then its name.
pub fn detect(path: &Path, options: &ImportOptions) -> Result<SourceKind, LoadError> {
    if options.map.is_some() {
        return Ok(SourceKind::MappedCsv);
    }
    if comma2k19::is_segment(path) {
        return Ok(SourceKind::Comma2k19);
    }
    if path.is_dir() {
        return Ok(SourceKind::Ros2Mcap);
    }
    let mut buf = [0u8; 256];
    let n = head(path, &mut buf).map_err(|error| LoadError::Io {
        file: path.display().to_string(),
        error,
    })?;
    let head = &buf[..n];
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    Ok(
        if head.starts_with(ros1::MAGIC) || ext.as_deref() == Some("bag") {
            SourceKind::Ros1Bag
        } else if head.starts_with(ros2::MCAP_MAGIC) || ext.as_deref() == Some("mcap") {
            SourceKind::Ros2Mcap
        } else if head.starts_with(ulog::MAGIC) || ext.as_deref() == Some("ulg") {
            SourceKind::Ulog
        } else if head.starts_with(dataflash::MAGIC) || ext.as_deref() == Some("bin") {
            SourceKind::DataFlash
        } else if camera::is_camera(path, head) {
            SourceKind::Camera
        } else if gnsslogger::is_gnsslogger(head) {
            SourceKind::GnssLogger
        } else {
            SourceKind::RideCsv
        },
    )
}

/// What a GNSS-only file is, when `path` is one (GPX, NMEA 0183, Garmin
/// FIT: no gyro), told by its content: a ride needs a gyro, so opening one
/// as a ride says what it is and how it can serve instead.
fn gnss_only(path: &Path) -> Option<String> {
    let mut buf = [0u8; 64];
    let n = head(path, &mut buf).ok()?;
    let head = &buf[..n];
    let text = String::from_utf8_lossy(head);
    let trimmed = text.trim_start_matches('\u{feff}').trim_start();
    if fit::is_fit(head) {
        let bytes = std::fs::read(path).ok()?;
        return Some(match fit::parse(&bytes, &path.display().to_string()) {
            Ok(a) => format!(
                "{}: GNSS only, no gyro; it can be the reference track of a ride that has one (--reference {}, File > Open reference track), or the fixes of a gyro log without GPS (--gps-track {})",
                a.describe(),
                path.display(),
                path.display()
            ),
            Err(e) => format!(
                "a Garmin FIT file: GNSS only, no gyro, and not readable as a reference track either: {e}"
            ),
        });
    }
    let parse: fn(&[u8], &str) -> Result<ReferenceTrack, LoadError> =
        if trimmed.starts_with("<?xml") || trimmed.starts_with("<gpx") {
            reference::parse_gpx
        } else if trimmed.starts_with('$') {
            reference::parse_nmea
        } else {
            return None;
        };
    let what = if trimmed.starts_with('$') {
        "NMEA 0183"
    } else {
        "a GPX track"
    };
    let track = std::fs::read(path)
        .ok()
        .map(|bytes| (what, parse(&bytes, &path.display().to_string())));
    track.map(|(what, read)| match read {
        Ok(r) => format!(
            "{what} of {} points over {:.0} s: GNSS only, no gyro; it can be the reference track of a ride that has one (--reference {}, File > Open reference track), or the fixes of a gyro log without GPS (--gps-track {})",
            r.t_s.len(),
            r.t_s.last().zip(r.t_s.first()).map_or(0.0, |(l, f)| l - f),
            path.display(),
            path.display()
        ),
        Err(e) => format!("{what}: GNSS only, no gyro, and not readable as a reference track either: {e}"),
    })
}

/// Read any supported input, check it, and mount it as `options` say.
pub fn open(path: &Path, options: &ImportOptions) -> Result<Imported, LoadError> {
    let kind = detect(path, options)?;
    if kind == SourceKind::RideCsv
        && let Some(what) = gnss_only(path)
    {
        return Err(LoadError::File {
            file: path.display().to_string(),
            message: format!(
                "{what}. A path needs a gyro: a ride log, a bag, a comma2k19 segment, a PX4 ULog or ArduPilot log, a camera file or an Android GnssLogger log"
            ),
        });
    }
    let (mut log, topics): (RideLog, Option<Topics>) = match kind {
        SourceKind::RideCsv => (load_file(path)?, None),
        SourceKind::Ros1Bag => {
            let (rec, topics) = ros1::read(path, &options.topics)?;
            (timeline::assemble(rec, &topics)?, Some(topics))
        }
        SourceKind::Ros2Mcap => {
            let (rec, topics) = ros2::read(path, &options.topics)?;
            (timeline::assemble(rec, &topics)?, Some(topics))
        }
        SourceKind::MappedCsv => {
            let map = options.map.as_deref().ok_or_else(|| LoadError::File {
                file: path.display().to_string(),
                message: "a mapped CSV needs a column map (--map MAP.toml)".into(),
            })?;
            (mapped_csv::load(path, options.gps.as_deref(), map)?, None)
        }
        SourceKind::Comma2k19 => (
            comma2k19::read(path, options.distance == DistanceChoice::Auto)?,
            None,
        ),
        SourceKind::Ulog => (ulog::read(path)?, None),
        SourceKind::Camera => (camera::read(path, options.gps_track.is_none())?, None),
        SourceKind::GnssLogger => (gnsslogger::read(path)?, None),
        SourceKind::DataFlash => (dataflash::read(path)?, None),
    };
    if let Some(track) = &options.gps_track {
        gps_track::merge_track(&mut log, track)?;
    }
    if let Some(wheel) = &options.wheel {
        if options.distance == DistanceChoice::Gnss {
            return Err(LoadError::File {
                file: wheel.display().to_string(),
                message: "a wheel distance and --distance gnss exclude each other".into(),
            });
        }
        fit::merge_distance(&mut log, wheel)?;
    }
    if options.distance == DistanceChoice::Gnss {
        without_odometer(&mut log)?;
    }
    if let Some((start, end)) = options.between {
        let first = log.t_s.partition_point(|&t| t < start);
        let last = log.t_s.partition_point(|&t| t <= end);
        if last < first + 2 {
            return Err(LoadError::File {
                file: path.display().to_string(),
                message: format!(
                    "--between {start},{end} keeps {} row(s) of the log, which runs from {:.2} to {:.2} s",
                    last.saturating_sub(first),
                    log.t_s.first().copied().unwrap_or(f64::NAN),
                    log.t_s.last().copied().unwrap_or(f64::NAN)
                ),
            });
        }
        log.keep_rows(first..last);
    }
    if topics.is_some() && !log.metadata.contains_key("source") {
        log.metadata.insert(
            "source".into(),
            format!("{} {}", kind.label(), path.display()),
        );
    }
    if let Some(a) = &options.attitude {
        match a.as_str() {
            "3d" | "planar" => {
                log.metadata.insert("attitude".into(), a.clone());
            }
            "auto" => {
                log.metadata.remove("attitude");
            }
            other => {
                return Err(LoadError::File {
                    file: path.display().to_string(),
                    message: format!("attitude '{other}' is none of auto, 3d, planar"),
                });
            }
        }
    }
    Ok(checked(log, kind, topics, &options.mount))
}

/// Leave out a log's wheel sensor and odometer, so that its distance comes
/// from the GNSS speed; an error when it has none.
fn without_odometer(log: &mut RideLog) -> Result<(), LoadError> {
    if log.gnss_speed_samples() < 2 {
        return Err(LoadError::File {
            file: log.source.clone(),
            message: "--distance gnss: the log has no GNSS speed (a 'gps_speed_mps' column) to take the distance from".into(),
        });
    }
    log.wheel_pulse = None;
    log.odo_m = None;
    log.speed_mps = None;
    log.warnings.push(format!(
        "{}: the distance is the GNSS speed's (--distance gnss); the log's wheel sensor or odometer is not used",
        log.source
    ));
    Ok(())
}

/// Check a log read by any reader and mount it as `mount` says.
pub fn checked(
    mut log: RideLog,
    kind: SourceKind,
    topics: Option<Topics>,
    mount: &MountChoice,
) -> Imported {
    let check = checks::check(&log);
    let choice = match mount {
        MountChoice::Default => kind.default_mount(),
        other => other.clone(),
    };
    if choice == MountChoice::Auto && check.recommended.is_none() {
        log.warnings.push(format!(
            "{}: mounting: the data cannot tell which axis is up (see the checks); the axes are read as logged (x forward, y left, z up assumed); give --mount if they are not",
            log.source
        ));
    }
    let mount = match choice {
        MountChoice::Default | MountChoice::AsLogged => None,
        MountChoice::Auto => check.recommended.clone().filter(|m| !m.is_identity()),
        MountChoice::Fixed(m) => Some(m).filter(|m| !m.is_identity()),
    };
    if let Some(m) = &mount {
        m.apply(&mut log);
    }
    Imported {
        log,
        kind,
        topics,
        mount,
        check,
    }
}
