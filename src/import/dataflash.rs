//! ArduPilot DataFlash logs (`.bin`): what a rover, boat or copter running
//! ArduPilot writes on its SD card. A rover logs its IMU, its GNSS with the
//! Doppler speed and, when it has them, its wheel encoders.
//!
//! The file is a stream of messages, each `A3 95 type` and a payload whose
//! layout the log declares itself in `FMT` records, read by the
//! `ardupilot-binlog` crate. What is read, and how it becomes a ride log:
//!
//! - **Rows**: `IMU` instance 0 (`GyrX/Y/Z` in rad/s in ArduPilot's body
//!   axes forward, right, down, made deg/s in forward, left, up;
//!   instantaneous samples), with `AccX/Y/Z` likewise for the checks.
//! - **GNSS**: `GPS` instance 0 with a 3-D fix or better (`Status` >= 3):
//!   `Lat`/`Lng` (1e-7 deg), `Alt` (above mean sea level), `Spd` and `GCrs`
//!   as the GNSS speed and course, `GPA`'s `HAcc` as the accuracy; one fix a
//!   second by the receiver's own time (`GWk`, `GMS`)
//!   ([`super::timeline::place_gnss`]).
//! - **Wheel encoders** (`WENC`, rovers): `Dist0`/`Dist1` (m, accumulated)
//!   of the wheels that turn, averaged, become the odometer (`odo_m`) on the
//!   row nearest each sample. Without them the distance is the GNSS speed's.
//! - **Clock**: `TimeUS` (boot clock), `t_s` from the first IMU sample;
//!   `t0_boot_s` from it, `t0_unix_s` from the first fix's GPS week and
//!   milliseconds less the 18 leap seconds of GPS time since 2017.
//!
//! The crate is a third-party parser of a binary format: a panic inside it
//! (a damaged `FMT` record declaring a message shorter than its header
//! underflows its payload length) is caught and reported as the file's
//! error, never the app's end. It skips damaged stretches as ArduPilot's own
//! tools do, and a log cut short by a power loss ends where it was cut.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::Path;

use ardupilot_binlog::{Entry, Reader};

use super::LoadError;
use super::timeline::{GnssSample, nearest_row, place_gnss};
use crate::ride::RideLog;

/// The first bytes of every DataFlash log: a message header and the `FMT`
/// record's type.
pub const MAGIC: &[u8] = &[0xA3, 0x95, 0x80];

/// Seconds from the Unix epoch to the GPS epoch (6 January 1980), and the
/// leap seconds GPS time has run ahead of UTC since 1 January 2017.
const GPS_EPOCH_UNIX_S: f64 = 315_964_800.0;
const GPS_LEAP_S: f64 = 18.0;

/// What the log holds of the messages gyropath uses, in the log's order.
#[derive(Default)]
struct Messages {
    /// `TimeUS`, gyro (rad/s), accelerometer (m/s^2), body axes.
    imu: Vec<(u64, [f64; 3], Option<[f64; 3]>)>,
    gps: Vec<GnssSample>,
    /// `TimeUS` -> `HAcc` (m) of the GPA record beside a GPS one.
    hacc: HashMap<u64, f64>,
    /// `TimeUS` and each wheel's accumulated distance (m).
    wenc: Vec<(u64, [f64; 2])>,
    /// The GPS week and milliseconds of the first GPS record kept, and its `TimeUS`.
    first_gps_time: Option<(f64, u64)>,
}

/// Instance 0 of a message that logs several (`I` field), or its only one.
fn first_instance(e: &Entry) -> bool {
    e.get_f64("I").is_none_or(|i| i == 0.0)
}

impl Messages {
    fn read(stream: impl Read) -> Result<Self, String> {
        let mut out = Self::default();
        let mut reader = Reader::new(stream);
        // Whether GPS Lat/Lng are integers of 1e-7 deg ('L', 'i') and Alt
        // centimetres ('i'); decided from the log's own FMT record.
        let mut scales: Option<(f64, f64)> = None;
        while let Some(entry) = reader.next() {
            let e = entry.map_err(|e| e.to_string())?;
            let Some(t_us) = e.timestamp_usec else {
                continue;
            };
            match e.name.as_str() {
                "IMU" if first_instance(&e) => {
                    let v = |n: &str| e.get_f64(n);
                    if let (Some(x), Some(y), Some(z)) = (v("GyrX"), v("GyrY"), v("GyrZ")) {
                        let accel = match (v("AccX"), v("AccY"), v("AccZ")) {
                            (Some(x), Some(y), Some(z)) => Some([x, -y, -z]),
                            _ => None,
                        };
                        out.imu.push((t_us, [x, -y, -z], accel));
                    }
                }
                "GPS" if first_instance(&e) => {
                    let (deg, alt) = *scales.get_or_insert_with(|| {
                        let f = reader.formats().get(&e.msg_type);
                        let char_of = |label: &str| {
                            f.and_then(|f| {
                                let i = f.labels.iter().position(|l| l == label)?;
                                f.format.chars().nth(i)
                            })
                        };
                        (
                            if matches!(char_of("Lat"), Some('L' | 'i')) {
                                1e-7
                            } else {
                                1.0
                            },
                            if char_of("Alt") == Some('i') {
                                0.01
                            } else {
                                1.0
                            },
                        )
                    });
                    let v = |n: &str| e.get_f64(n);
                    if v("Status").is_none_or(|s| s < 3.0) {
                        continue;
                    }
                    let (Some(lat), Some(lon)) = (v("Lat"), v("Lng")) else {
                        continue;
                    };
                    let t = t_us as f64 * 1e-6;
                    let gps_time = match (v("GWk"), v("GMS")) {
                        (Some(w), Some(ms)) if w > 0.0 => Some(w * 604_800.0 + ms * 1e-3),
                        _ => None,
                    };
                    if let (None, Some(g)) = (out.first_gps_time, gps_time) {
                        out.first_gps_time = Some((g, t_us));
                    }
                    out.gps.push(GnssSample {
                        t,
                        stamp: gps_time.unwrap_or(t),
                        lat: lat * deg,
                        lon: lon * deg,
                        alt: v("Alt").map(|a| a * alt),
                        speed: v("Spd"),
                        course: v("GCrs"),
                        hacc: None,
                        hdop: v("HDop"),
                        sats: v("NSats"),
                    });
                }
                "GPA" if first_instance(&e) => {
                    if let Some(h) = e.get_f64("HAcc") {
                        out.hacc.insert(t_us, h);
                    }
                }
                "WENC" => {
                    if let (Some(a), Some(b)) = (e.get_f64("Dist0"), e.get_f64("Dist1")) {
                        out.wenc.push((t_us, [a, b]));
                    }
                }
                _ => {}
            }
        }
        for s in &mut out.gps {
            s.hacc = out.hacc.get(&((s.t * 1e6).round() as u64)).copied();
        }
        Ok(out)
    }
}

/// Read a DataFlash log as a ride log.
pub fn read(path: &Path) -> Result<RideLog, LoadError> {
    let (stream, file) = super::open_file(path)?;
    parse(std::io::BufReader::new(stream), &file)
}

/// Parse a DataFlash log named `file` (for messages).
pub fn parse(stream: impl Read, file: &str) -> Result<RideLog, LoadError> {
    let bad = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let messages =
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| Messages::read(stream))) {
            Ok(Ok(m)) => m,
            Ok(Err(e)) => return Err(bad(format!("not a readable DataFlash log: {e}"))),
            Err(_) => {
                return Err(bad(
                    "the DataFlash parser failed on this file (a damaged FMT record?)".into(),
                ));
            }
        };
    let mut imu = messages.imu;
    imu.retain(|(_, g, _)| g.iter().all(|v| v.is_finite()));
    imu.sort_by_key(|r| r.0);
    imu.dedup_by_key(|r| r.0);
    if imu.len() < 2 {
        return Err(bad(
            "the log has fewer than two IMU samples (an ArduPilot DataFlash log with LOG_BITMASK's IMU bit off?): a path needs a gyro".into(),
        ));
    }
    let t0_us = imu[0].0;
    let n = imu.len();
    let at = |t_us: u64| t_us.wrapping_sub(t0_us) as i64 as f64 * 1e-6;
    let mut log = RideLog {
        source: file.to_string(),
        line: (1..=n as u64).collect(),
        t_s: imu.iter().map(|r| at(r.0)).collect(),
        gyro_dps: imu.iter().map(|r| r.1.map(f64::to_degrees)).collect(),
        accel_mps2: imu.iter().any(|r| r.2.is_some()).then(|| {
            imu.iter()
                .map(|r| r.2.filter(|a| a.iter().all(|v| v.is_finite())))
                .collect()
        }),
        fix: vec![None; n],
        metadata: BTreeMap::from([
            ("source".to_string(), format!("ArduPilot DataFlash {file}")),
            ("gyro_samples".to_string(), "instantaneous".to_string()),
            (
                "t0_boot_s".to_string(),
                format!("{:.6}", t0_us as f64 * 1e-6),
            ),
        ]),
        ..RideLog::default()
    };
    let mut gps = messages.gps;
    for s in &mut gps {
        s.t = at((s.t * 1e6).round() as u64);
    }
    gps.sort_by(|a, b| a.t.total_cmp(&b.t));
    if place_gnss(&mut log, &gps).is_none() {
        return Err(bad(
            "the log has no GPS record with a 3-D fix while the IMU runs: a path needs GNSS fixes"
                .into(),
        ));
    }
    if let Some((gps_s, t_us)) = messages.first_gps_time {
        let unix = GPS_EPOCH_UNIX_S + gps_s - GPS_LEAP_S - at(t_us);
        log.metadata
            .insert("t0_unix_s".into(), format!("{unix:.3}"));
    }
    // Wheel encoders: the wheels that turn, averaged (a rover with one
    // encoder logs the other as zero).
    let turns = |w: usize| messages.wenc.iter().any(|r| r.1[w] != 0.0);
    let wheels: Vec<usize> = (0..2).filter(|&w| turns(w)).collect();
    if !wheels.is_empty() {
        let mut odo = vec![None; n];
        for (t_us, d) in &messages.wenc {
            let t = at(*t_us);
            if !(log.t_s[0]..=log.t_s[n - 1]).contains(&t) {
                continue;
            }
            let mean = wheels.iter().map(|&w| d[w]).sum::<f64>() / wheels.len() as f64;
            if mean.is_finite() {
                odo[nearest_row(&log.t_s, t)] = Some(mean);
            }
        }
        if odo.iter().flatten().count() >= 2 {
            log.odo_m = Some(odo);
        }
    }
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A DataFlash writer for tests: FMT records and messages of the
    /// layouts ArduPilot 4 logs.
    struct Writer(Vec<u8>);

    impl Writer {
        fn new() -> Self {
            let mut w = Writer(Vec::new());
            w.fmt(0x80, 89, "FMT", "BBnNZ", "Type,Length,Name,Format,Labels");
            w.fmt(
                10,
                3 + 8 + 1 + 24,
                "IMU",
                "QBffffff",
                "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
            );
            w.fmt(
                11,
                3 + 8 + 1 + 1 + 4 + 2 + 1 + 2 + 4 + 4 + 4 + 12,
                "GPS",
                "QBBIHBcLLefff",
                "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ",
            );
            w.fmt(
                12,
                3 + 8 + 4 + 1 + 4 + 1,
                "WENC",
                "Qfbfb",
                "TimeUS,Dist0,Qual0,Dist1,Qual1",
            );
            w
        }

        fn fmt(&mut self, ty: u8, len: u8, name: &str, format: &str, labels: &str) {
            let mut p = vec![0u8; 86];
            p[0] = ty;
            p[1] = len;
            p[2..2 + name.len()].copy_from_slice(name.as_bytes());
            p[6..6 + format.len()].copy_from_slice(format.as_bytes());
            p[22..22 + labels.len()].copy_from_slice(labels.as_bytes());
            self.0.extend_from_slice(&[0xA3, 0x95, 0x80]);
            self.0.extend_from_slice(&p);
        }

        fn imu(&mut self, t_us: u64, gyro: [f32; 3], accel: [f32; 3]) {
            self.0.extend_from_slice(&[0xA3, 0x95, 10]);
            self.0.extend_from_slice(&t_us.to_le_bytes());
            self.0.push(0);
            for v in gyro.iter().chain(&accel) {
                self.0.extend_from_slice(&v.to_le_bytes());
            }
        }

        fn gps(&mut self, t_us: u64, gms: u32, lat: f64, lon: f64, speed: f32) {
            self.0.extend_from_slice(&[0xA3, 0x95, 11]);
            self.0.extend_from_slice(&t_us.to_le_bytes());
            self.0.extend_from_slice(&[0, 3]);
            self.0.extend_from_slice(&gms.to_le_bytes());
            self.0.extend_from_slice(&2382u16.to_le_bytes());
            self.0.push(12);
            self.0.extend_from_slice(&90i16.to_le_bytes());
            self.0
                .extend_from_slice(&((lat * 1e7).round() as i32).to_le_bytes());
            self.0
                .extend_from_slice(&((lon * 1e7).round() as i32).to_le_bytes());
            self.0.extend_from_slice(&4777i32.to_le_bytes());
            for v in [speed, 0.0f32, 0.0] {
                self.0.extend_from_slice(&v.to_le_bytes());
            }
        }

        fn wenc(&mut self, t_us: u64, dist: f32) {
            self.0.extend_from_slice(&[0xA3, 0x95, 12]);
            self.0.extend_from_slice(&t_us.to_le_bytes());
            self.0.extend_from_slice(&dist.to_le_bytes());
            self.0.push(100);
            self.0.extend_from_slice(&0f32.to_le_bytes());
            self.0.push(0);
        }
    }

    /// A rover driving north at 2 m/s for `seconds`: IMU at 50 Hz turning
    /// at 0.1 rad/s (about z down, so left is negative), GPS at 5 Hz, one
    /// wheel encoder at 10 Hz.
    fn rover(seconds: u64) -> Vec<u8> {
        let mut w = Writer::new();
        let t0 = 100_000_000u64;
        for k in 0..seconds * 50 {
            let t = t0 + k * 20_000;
            w.imu(t, [0.0, 0.0, -0.1], [0.0, 0.0, -9.81]);
            if k % 5 == 0 {
                w.wenc(t + 1, (k as f64 * 0.04) as f32);
            }
            if k % 10 == 0 {
                let north = k as f64 * 0.04;
                w.gps(
                    t + 3,
                    219_552_000 + (k * 20) as u32,
                    52.0 + north / 111_000.0,
                    10.0,
                    2.0,
                );
            }
        }
        w.0
    }

    #[test]
    fn reads_imu_gps_wheels_and_clock() {
        let log = parse(&rover(10)[..], "rover.bin").unwrap();
        assert_eq!(log.len(), 500);
        assert!((log.t_s[1] - 0.02).abs() < 1e-9);
        // Body z down made z up: a left turn is positive.
        assert!((log.gyro_dps[0][2] - 0.1f64.to_degrees()).abs() < 1e-4);
        let a = log.accel_mps2.as_ref().unwrap()[0].unwrap();
        assert!((a[2] - 9.81).abs() < 1e-4, "{a:?}");
        // 5 Hz over 9.8 s: the nearest sample to each of 11 whole seconds.
        assert_eq!(log.fix_count(), 11);
        assert_eq!(log.gnss_speed_samples(), 50);
        let (lat, lon) = log.fix.iter().flatten().next().copied().unwrap();
        assert!((lat - 52.0).abs() < 1e-6 && (lon - 10.0).abs() < 1e-6);
        let odo: Vec<f64> = log
            .odo_m
            .as_ref()
            .unwrap()
            .iter()
            .flatten()
            .copied()
            .collect();
        assert_eq!(odo.len(), 100);
        assert!((odo[99] - 19.8).abs() < 1e-4, "{}", odo[99]);
        assert_eq!(log.metadata["t0_boot_s"], "100.000000");
        // GPS week 2382, 219552 s, less 18 leap seconds: 2025-09-03.
        let t0: f64 = log.metadata["t0_unix_s"].parse().unwrap();
        let expect = 315_964_800.0 + 2382.0 * 604_800.0 + 219_552.0 - 18.0 - 3e-6;
        assert!((t0 - expect).abs() < 1e-3, "{t0} {expect}");
    }

    #[test]
    fn a_log_without_imu_or_fix_says_so() {
        let mut w = Writer::new();
        w.gps(1, 1000, 52.0, 10.0, 1.0);
        let e = parse(&w.0[..], "x.bin").unwrap_err().to_string();
        assert!(
            e.starts_with("x.bin: ") && e.contains("fewer than two IMU samples"),
            "{e}"
        );
        let mut w = Writer::new();
        w.imu(1, [0.0; 3], [0.0; 3]);
        w.imu(2, [0.0; 3], [0.0; 3]);
        let e = parse(&w.0[..], "x.bin").unwrap_err().to_string();
        assert!(e.contains("no GPS record with a 3-D fix"), "{e}");
    }

    /// A damaged FMT record that declares a message shorter than its own
    /// header makes the crate's payload length underflow: an error, not a panic.
    #[test]
    fn a_damaged_format_record_is_an_error() {
        let mut w = Writer::new();
        w.fmt(13, 2, "BAD", "Q", "TimeUS");
        w.0.extend_from_slice(&[0xA3, 0x95, 13, 0, 0]);
        let e = parse(&w.0[..], "bad.bin").unwrap_err().to_string();
        assert!(e.starts_with("bad.bin: "), "{e}");
    }
}
