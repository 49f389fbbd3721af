//! Action cameras and the other logs that gyroflow's `telemetry-parser`
//! reads (GoPro GPMF inside MP4, Sony, Insta360, DJI, phone-app exports,
//! Betaflight blackbox, ArduPilot): a camera on a handlebar or a dashboard
//! logs a gyro, an accelerometer and, on GoPros, GNSS with its speed, but
//! no wheel distance.
//!
//! What is read, and how it becomes a ride log:
//!
//! - **Rows**: the gyro samples as the parser normalises them (deg/s, in the
//!   camera's IMU axes, which `gyropath check` names and `--mount auto`
//!   turns to x forward, y left, z up: cameras are mounted every way), with
//!   the accelerometer (m/s^2) for those checks; instantaneous samples.
//! - **GNSS** (GoPro `GPS5`: latitude, longitude, height, 2-D and 3-D speed
//!   at 10-18 Hz in one-second payloads, with a fix type `GPSF` and the UTC
//!   time `GPSU` of each payload): the samples of each payload spread evenly
//!   over its time, those of a 2-D or 3-D fix kept; every one's 2-D speed as
//!   `gps_speed_mps`, one fix a second ([`super::timeline::place_gnss`]).
//!   The distance is the GNSS speed's.
//! - **Clock**: `t_s` from the first gyro sample; `t0_unix_s` from the first
//!   payload's `GPSU` (to the payload's second).
//!
//! The parser reads the metadata track's samples through the MP4's sample
//! tables, not the video (peak memory does not grow with the video). It
//! is a third-party parser of binary formats: a panic inside it is caught
//! and reported as the file's error, never the app's end.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use telemetry_parser::tags_impl::{GetWithType, GroupId, TagId};

use super::LoadError;
use super::timeline::{GnssSample, place_gnss};
use crate::ride::RideLog;

/// Whether `path` looks like a file the camera reader takes: an MP4/MOV
/// family container (`ftyp` at byte 4) or a telemetry extension.
pub fn is_camera(path: &Path, head: &[u8]) -> bool {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    (head.len() >= 8 && &head[4..8] == b"ftyp")
        || matches!(
            ext.as_deref(),
            Some("mp4" | "mov" | "insv" | "360" | "lrv" | "bbl" | "bfl")
        )
}

/// The four characters of a GoPro key as the parser's unknown tag id.
const fn key(k: &[u8; 4]) -> TagId {
    TagId::Unknown(u32::from_be_bytes(*k))
}

/// Why an MP4 cannot be read, where it is a recording the camera never
/// finished: its top-level boxes run past the end of the file and there
/// is no `moov` (the index of every sample, written last), as when the
/// battery ran out or the card was pulled while recording. Without the
/// index no telemetry sample can be found, so the file's own words are
/// not "unsupported" but how to mend it.
fn unfinished_mp4(path: &Path) -> Option<String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path).ok()?;
    let len = f.metadata().ok()?.len();
    let mut at = 0u64;
    let mut head = [0u8; 16];
    while at + 8 <= len {
        f.seek(SeekFrom::Start(at)).ok()?;
        let n = f.read(&mut head).ok()?;
        if n < 8 {
            return None;
        }
        let size = match u32::from_be_bytes([head[0], head[1], head[2], head[3]]) {
            1 if n >= 16 => u64::from_be_bytes(head[8..16].try_into().ok()?),
            0 => len - at,
            size => u64::from(size),
        };
        if &head[4..8] == b"moov" || size < 8 {
            return None;
        }
        if at + size > len {
            let kind = String::from_utf8_lossy(&head[4..8]).into_owned();
            return Some(format!(
                "the recording was never finished: its '{kind}' box declares {size} bytes from byte {at}, the file ends {} bytes short, and it has no index ('moov'), as when the camera's battery ran out or the card was pulled while recording; the camera offers to repair such a file when the card is put back (GoPro's SOS), or a repair tool (untrunc, with a whole file of the same camera) rebuilds the index",
                at + size - len
            ));
        }
        at += size;
    }
    None
}

/// Read a camera file as a ride log; a GoPro recording's first chapter
/// with the chapters that follow it beside it ([`super::chapters`]), as one.
/// A recording without a fix is an error where it `needs_fixes`, not where
/// its fixes come from another device's track (`--gps-track`).
pub fn read(path: &Path, needs_fixes: bool) -> Result<RideLog, LoadError> {
    let mut log = read_file(path)?;
    let file = log.source.clone();
    let mut following = super::chapters::following(path);
    // A later chapter that cannot be read (the last one, never finished
    // when the battery ran out) ends the recording there, and is said: the
    // chapters before it are whole.
    for (k, next) in following.iter().enumerate() {
        match read_file(next) {
            Ok(other) => super::chapters::append(&mut log, other, &next.display().to_string())?,
            Err(e) => {
                log.warnings.push(format!(
                    "{e}: the recording is read up to the chapter before it"
                ));
                following.truncate(k);
                break;
            }
        }
    }
    if !following.is_empty() {
        let names: Vec<String> = std::iter::once(path)
            .chain(following.iter().map(PathBuf::as_path))
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        log.warnings.push(format!(
            "{file}: read with the {} that follow{} it as one recording of {:.0} s ({}); --between fits a part of it",
            match following.len() {
                1 => "chapter".to_string(),
                n => format!("{n} chapters"),
            },
            if following.len() == 1 { "s" } else { "" },
            log.t_s.last().copied().unwrap_or(0.0) - log.t_s.first().copied().unwrap_or(0.0),
            names.join(" + ")
        ));
        if let Some(source) = log.metadata.get_mut("source") {
            source.push_str(&format!(" + {} chapters", following.len()));
        }
    } else if let Some(first) = super::chapters::first_of(path) {
        log.warnings.push(format!(
            "{file}: a later chapter of a GoPro recording, read alone: its path starts without the chapters before it; open {} to read the whole recording as one ride",
            first.display()
        ));
    }
    if needs_fixes && log.fix_count() == 0 {
        return Err(LoadError::NoFix {
            file,
            message: "the recording has no GNSS fix while the gyro runs (this camera logs no GPS, or it had no fix): a path needs GNSS fixes; a GPS track of the same ride (a watch's or bike computer's GPX or FIT) gives them: --gps-track FILE".into(),
        });
    }
    Ok(log)
}

/// One camera file as a ride log (which may hold no fix: a chapter in a
/// tunnel, whose recording has fixes in its other chapters).
fn read_file(path: &Path) -> Result<RideLog, LoadError> {
    let (mut stream, file) = super::open_file(path)?;
    let bad = |message: String| LoadError::File {
        file: file.clone(),
        message,
    };
    let size = stream
        .metadata()
        .map_err(|error| LoadError::Io {
            file: file.clone(),
            error,
        })?
        .len() as usize;
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let input = telemetry_parser::Input::from_stream(
            &mut stream,
            size,
            path,
            |_| {},
            Arc::new(AtomicBool::new(false)),
        )?;
        let imu = telemetry_parser::util::normalized_imu(&input, None)?;
        Ok::<_, std::io::Error>((input, imu))
    }));
    let (input, imu) = match parsed {
        Ok(Ok(x)) => x,
        Ok(Err(e)) => {
            return Err(bad(match unfinished_mp4(path) {
                Some(why) => why,
                None => format!("not a camera or telemetry file that telemetry-parser reads: {e}"),
            }));
        }
        Err(_) => {
            return Err(bad(
                "telemetry-parser failed on this file (it is damaged or of a kind it does not know)"
                    .into(),
            ));
        }
    };
    let camera = format!(
        "{} {}",
        input.camera_type(),
        input.camera_model().cloned().unwrap_or_default()
    )
    .trim()
    .to_string();
    // Rows: gyro samples in time order, the first of any repeated time.
    let mut rows: Vec<_> = imu
        .iter()
        .filter_map(|s| Some((s.timestamp_ms, s.gyro?, s.accl)))
        .filter(|(t, g, _)| t.is_finite() && g.iter().all(|v| v.is_finite()))
        .collect();
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    rows.dedup_by(|b, a| a.0 == b.0);
    if rows.len() < 2 {
        return Err(bad(format!(
            "{camera}: the file has fewer than two gyro samples: a path needs a gyro"
        )));
    }
    let t0_ms = rows[0].0;
    let n = rows.len();
    let mut log = RideLog {
        source: file.clone(),
        line: (1..=n as u64).collect(),
        t_s: rows.iter().map(|r| (r.0 - t0_ms) * 1e-3).collect(),
        gyro_dps: rows.iter().map(|r| r.1).collect(),
        accel_mps2: rows
            .iter()
            .any(|r| r.2.is_some())
            .then(|| rows.iter().map(|r| r.2).collect()),
        fix: vec![None; n],
        metadata: BTreeMap::from([
            ("source".to_string(), format!("{camera} {file}")),
            ("gyro_samples".to_string(), "instantaneous".to_string()),
        ]),
        ..RideLog::default()
    };
    // GNSS: GoPro's GPS5 payloads, one a second.
    let mut samples = Vec::new();
    let mut utc_of_first: Option<(f64, f64)> = None;
    for info in input.samples.iter().flatten() {
        let Some(gps) = info.tag_map.as_ref().and_then(|m| m.get(&GroupId::GPS)) else {
            continue;
        };
        let data: Option<&Vec<Vec<i32>>> = gps.get_t(TagId::Data);
        let scale: Option<&Vec<i32>> = gps.get_t(TagId::Scale);
        let (Some(data), Some(scale)) = (data, scale) else {
            continue;
        };
        let fix: Option<&u32> = gps.get_t(key(b"GPSF"));
        if fix.is_some_and(|f| *f < 2) || scale.len() < 4 || scale.contains(&0) {
            continue;
        }
        let count = data.len().max(1) as f64;
        for (i, v) in data.iter().enumerate().filter(|(_, v)| v.len() >= 4) {
            let t = (info.timestamp_ms + info.duration_ms * i as f64 / count - t0_ms) * 1e-3;
            let value = |j: usize| v[j] as f64 / scale[j] as f64;
            samples.push(GnssSample {
                t,
                stamp: t,
                lat: value(0),
                lon: value(1),
                alt: Some(value(2)),
                speed: Some(value(3)),
                course: None,
                hacc: None,
                hdop: None,
                sats: None,
            });
        }
        let utc: Option<&u64> = gps.get_t(key(b"GPSU"));
        if let (None, Some(u)) = (utc_of_first, utc) {
            utc_of_first = Some((*u as f64 * 1e-3, (info.timestamp_ms - t0_ms) * 1e-3));
        }
    }
    if place_gnss(&mut log, &samples).is_none() {
        log.warnings.push(format!(
            "{file}: {camera}: no GNSS fix while the gyro runs (this camera logs no GPS, or it had no fix)"
        ));
    }
    if let Some((utc, t)) = utc_of_first {
        log.metadata
            .insert("t0_unix_s".into(), format!("{:.3}", utc - t));
    }
    Ok(log)
}
