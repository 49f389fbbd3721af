//! PX4 ULog (`.ulg`): the flight stack's log of every uORB topic, read for
//! a rover, boat or any PX4 vehicle (github.com/PX4, "ULog File Format").
//!
//! What is read, and how it becomes a ride log:
//!
//! - **Rows**: the samples of `sensor_combined` (`gyro_rad`, rad/s, in PX4's
//!   body frame forward, right, down; made forward, left, up and deg/s:
//!   `gx = x`, `gy = -y`, `gz = -z`), instantaneous (`gyro_samples:
//!   instantaneous`); `accelerometer_m_s2` the same way (PX4's at rest reads
//!   -9.8 on z, ours +9.8 up).
//! - **GNSS**: `vehicle_gps_position` (or `sensor_gps` of newer PX4),
//!   instance 0, fixes with a 3D solution or better (`fix_type >= 3`):
//!   every sample's ground speed (`vel_m_s`) and course (`cog_rad`) on the
//!   row nearest it; the fixes thinned to one per second (the sample nearest
//!   each second counted from the first), with their height above the
//!   ellipsoid and `eph` as the horizontal accuracy.
//! - **Distance**: `wheel_encoders` is not read yet (no real log with it is
//!   known here); the GNSS speed gives the distance.
//! - **Clock**: `t_s` counts from the first gyro sample (`t0_boot_s`: its
//!   time since boot); `t0_unix_s` from the first fix's `time_utc_usec`.
//!
//! Why our own reader (about 250 lines) and not a crate: `px4-ulog` has not
//! changed since 2019 and parses whole files into memory; `yule_log` streams,
//! but as a library it pulls a logger (`env_logger`, `jiff`) into every build
//! and hands each message over as a tree of boxed values. The format is small
//! (a header, then sized messages: formats, subscriptions, data), and this
//! keeps the readers' one style: every rejection names the file and what is
//! wrong, and a bad file never panics (`tests/import_fuzz.rs`).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::LoadError;
use super::timeline::{GnssSample, place_gnss};
use crate::ride::RideLog;

/// The first bytes of every ULog file.
pub const MAGIC: &[u8] = b"ULog\x01\x12\x35";

/// One field of a message format: where it is and what it holds.
#[derive(Clone, Debug)]
struct Field {
    name: String,
    kind: Kind,
    /// Array length (1 for a scalar).
    count: usize,
    offset: usize,
}

#[derive(Clone, Debug, PartialEq)]
enum Kind {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Bool,
    Char,
    /// A nested format, by name.
    Nested(String),
}

impl Kind {
    fn parse(t: &str) -> Self {
        match t {
            "int8_t" => Self::I8,
            "uint8_t" => Self::U8,
            "int16_t" => Self::I16,
            "uint16_t" => Self::U16,
            "int32_t" => Self::I32,
            "uint32_t" => Self::U32,
            "int64_t" => Self::I64,
            "uint64_t" => Self::U64,
            "float" => Self::F32,
            "double" => Self::F64,
            "bool" => Self::Bool,
            "char" => Self::Char,
            other => Self::Nested(other.to_string()),
        }
    }

    fn size(&self) -> Option<usize> {
        Some(match self {
            Self::I8 | Self::U8 | Self::Bool | Self::Char => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::I64 | Self::U64 | Self::F64 => 8,
            Self::Nested(_) => return None,
        })
    }

    /// The value at the start of `b` (which holds at least `size` bytes).
    fn read(&self, b: &[u8]) -> f64 {
        let a = |n: usize| -> [u8; 8] {
            let mut x = [0u8; 8];
            x[..n].copy_from_slice(&b[..n]);
            x
        };
        match self {
            Self::I8 => b[0] as i8 as f64,
            Self::U8 | Self::Bool | Self::Char => b[0] as f64,
            Self::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Self::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Self::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Self::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Self::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Self::I64 => i64::from_le_bytes(a(8)) as f64,
            Self::U64 => u64::from_le_bytes(a(8)) as f64,
            Self::F64 => f64::from_le_bytes(a(8)),
            Self::Nested(_) => f64::NAN,
        }
    }
}

/// The data of the topics a ride needs, per topic name (instance 0):
/// each message's payload after its subscription id.
struct Topics {
    formats: HashMap<String, Vec<(String, Kind, usize)>>,
    data: HashMap<String, Vec<Vec<u8>>>,
}

/// The largest message a ULog can hold (its size is 16 bits): no field or
/// format can be larger.
const MAX_MESSAGE: usize = u16::MAX as usize;

/// The topics read.
const WANTED: [&str; 3] = ["sensor_combined", "vehicle_gps_position", "sensor_gps"];

/// Split `bytes` into its messages and keep the formats and the data of
/// the wanted topics.
fn messages(bytes: &[u8], file: &str) -> Result<Topics, LoadError> {
    let bad = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    if bytes.len() < 16 || !bytes.starts_with(MAGIC) {
        return Err(bad("not a PX4 ULog file (no ULog magic)".into()));
    }
    let mut at = 16usize;
    let mut formats = HashMap::new();
    let mut subscriptions: HashMap<u16, String> = HashMap::new();
    let mut data: HashMap<String, Vec<Vec<u8>>> = HashMap::new();
    while at + 3 <= bytes.len() {
        let size = u16::from_le_bytes([bytes[at], bytes[at + 1]]) as usize;
        let kind = bytes[at + 2];
        let Some(payload) = bytes.get(at + 3..at + 3 + size) else {
            // A log cut off mid-message (a power loss): keep what came before.
            break;
        };
        at += 3 + size;
        match kind {
            b'B' => {
                // Incompatible flags other than "data appended" (bit 0 of the
                // first byte) mean a layout this reader does not know.
                let incompatible = payload.get(8..16).unwrap_or(&[]);
                if incompatible
                    .iter()
                    .enumerate()
                    .any(|(i, &f)| f & if i == 0 { !1 } else { 0xff } != 0)
                {
                    return Err(bad(
                        "the log sets incompatible flags this reader does not know".into(),
                    ));
                }
            }
            b'F' => {
                let text = String::from_utf8_lossy(payload);
                let (name, body) = text
                    .split_once(':')
                    .ok_or_else(|| bad(format!("a message format without a name: '{text}'")))?;
                let mut fields = Vec::new();
                for f in body.split(';').filter(|f| !f.trim().is_empty()) {
                    let (t, n) = f.trim().split_once(' ').ok_or_else(|| {
                        bad(format!("format {name}: field '{f}' has no type and name"))
                    })?;
                    let (base, count) = match t.split_once('[') {
                        Some((b, rest)) => (
                            b,
                            rest.trim_end_matches(']')
                                .parse::<usize>()
                                .ok()
                                .filter(|&c| c <= MAX_MESSAGE)
                                .ok_or_else(|| {
                                    bad(format!("format {name}: field '{f}' has a bad array size"))
                                })?,
                        ),
                        None => (t, 1),
                    };
                    fields.push((n.to_string(), Kind::parse(base), count));
                }
                formats.insert(name.to_string(), fields);
            }
            b'A' if payload.len() >= 3 => {
                let multi = payload[0];
                let id = u16::from_le_bytes([payload[1], payload[2]]);
                let name = String::from_utf8_lossy(&payload[3..]).to_string();
                if multi == 0 && WANTED.contains(&name.as_str()) {
                    subscriptions.insert(id, name);
                }
            }
            b'D' if payload.len() >= 2 => {
                let id = u16::from_le_bytes([payload[0], payload[1]]);
                if let Some(name) = subscriptions.get(&id) {
                    data.entry(name.clone())
                        .or_default()
                        .push(payload[2..].to_vec());
                }
            }
            _ => {}
        }
    }
    Ok(Topics { formats, data })
}

impl Topics {
    /// The fields of format `name` with their offsets (nested formats
    /// flattened as `outer.inner`), or why they cannot be laid out.
    fn layout(&self, name: &str, depth: usize) -> Result<(Vec<Field>, usize), String> {
        if depth > 8 {
            return Err(format!("format {name} nests too deep"));
        }
        let fields = self
            .formats
            .get(name)
            .ok_or_else(|| format!("no format for '{name}'"))?;
        let (mut out, mut offset) = (Vec::new(), 0usize);
        for (n, kind, count) in fields {
            let size = match kind {
                Kind::Nested(inner) => {
                    let (sub, size) = self.layout(inner, depth + 1)?;
                    if offset + size * count > MAX_MESSAGE {
                        return Err(format!("format {name} is larger than a message can be"));
                    }
                    for i in 0..*count {
                        for f in &sub {
                            out.push(Field {
                                name: format!("{n}.{}", f.name),
                                offset: offset + i * size + f.offset,
                                ..f.clone()
                            });
                        }
                    }
                    offset += size * count;
                    continue;
                }
                k => k.size().unwrap_or(0),
            };
            out.push(Field {
                name: n.clone(),
                kind: kind.clone(),
                count: *count,
                offset,
            });
            offset += size * count;
            if offset > MAX_MESSAGE {
                return Err(format!("format {name} is larger than a message can be"));
            }
        }
        Ok((out, offset))
    }
}

/// A topic's messages with a reader of its fields by name.
struct Table<'t> {
    rows: &'t [Vec<u8>],
    fields: Vec<Field>,
}

impl Table<'_> {
    /// Element `i` of field `name` in every message (NaN where a message is
    /// too short to hold it); `None` when the format has no such field.
    fn column(&self, name: &str, i: usize) -> Option<Vec<f64>> {
        let f = self.fields.iter().find(|f| f.name == name)?;
        let size = f.kind.size()?;
        if i >= f.count {
            return None;
        }
        let at = f.offset + i * size;
        Some(
            self.rows
                .iter()
                .map(|r| r.get(at..at + size).map_or(f64::NAN, |b| f.kind.read(b)))
                .collect(),
        )
    }
}

/// Read a ULog file as a ride log.
pub fn read(path: &Path) -> Result<RideLog, LoadError> {
    let (bytes, file) = super::read_bytes(path)?;
    parse(&bytes, &file)
}

/// Parse the bytes of a ULog file named `file` (for messages).
pub fn parse(bytes: &[u8], file: &str) -> Result<RideLog, LoadError> {
    let bad = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    let topics = messages(bytes, file)?;
    let table = |name: &str| -> Result<Option<Table<'_>>, LoadError> {
        let Some(rows) = topics.data.get(name) else {
            return Ok(None);
        };
        let (fields, _) = topics.layout(name, 0).map_err(&bad)?;
        Ok(Some(Table { rows, fields }))
    };
    let imu = table("sensor_combined")?
        .ok_or_else(|| bad("the log has no sensor_combined (gyro) data".into()))?;
    let need = |t: &Table, name: &str, i: usize, topic: &str| {
        t.column(name, i)
            .ok_or_else(|| bad(format!("{topic} has no field {name}")))
    };
    let t_us = need(&imu, "timestamp", 0, "sensor_combined")?;
    let gyro: Vec<Vec<f64>> = (0..3)
        .map(|i| need(&imu, "gyro_rad", i, "sensor_combined"))
        .collect::<Result<_, _>>()?;
    let accel: Option<Vec<Vec<f64>>> = (0..3)
        .map(|i| imu.column("accelerometer_m_s2", i))
        .collect();
    // Rows: the gyro samples in time order, the first of any repeated time.
    let mut order: Vec<usize> = (0..t_us.len())
        .filter(|&k| t_us[k].is_finite() && gyro.iter().all(|g| g[k].is_finite()))
        .collect();
    order.sort_by(|&a, &b| t_us[a].total_cmp(&t_us[b]));
    order.dedup_by(|b, a| t_us[*a] == t_us[*b]);
    if order.len() < 2 {
        return Err(bad("sensor_combined has fewer than two gyro samples".into()));
    }
    let t0_us = t_us[order[0]];
    let t_s: Vec<f64> = order.iter().map(|&k| (t_us[k] - t0_us) * 1e-6).collect();
    let n = t_s.len();
    let mut log = RideLog {
        source: file.to_string(),
        line: (1..=n as u64).collect(),
        gyro_dps: order
            .iter()
            .map(|&k| {
                [
                    gyro[0][k].to_degrees(),
                    -gyro[1][k].to_degrees(),
                    -gyro[2][k].to_degrees(),
                ]
            })
            .collect(),
        accel_mps2: accel.map(|a| {
            order
                .iter()
                .map(|&k| {
                    Some([a[0][k], -a[1][k], -a[2][k]]).filter(|v| v.iter().all(|x| x.is_finite()))
                })
                .collect()
        }),
        fix: vec![None; n],
        metadata: BTreeMap::from([
            ("source".to_string(), format!("PX4 ULog {file}")),
            ("gyro_samples".to_string(), "instantaneous".to_string()),
            ("t0_boot_s".to_string(), format!("{:.6}", t0_us * 1e-6)),
        ]),
        t_s,
        ..RideLog::default()
    };
    let gps = match table("vehicle_gps_position")? {
        Some(t) => Some(("vehicle_gps_position", t)),
        None => table("sensor_gps")?.map(|t| ("sensor_gps", t)),
    };
    let Some((topic, gps)) = gps else {
        return Err(bad(
            "the log has no GNSS data (vehicle_gps_position or sensor_gps)".into(),
        ));
    };
    // Positions as integers of 1e-7 deg (older PX4) or degrees (newer).
    let (lat, lon) = match (gps.column("lat", 0), gps.column("lon", 0)) {
        (Some(la), Some(lo)) => (
            la.iter().map(|v| v * 1e-7).collect(),
            lo.iter().map(|v| v * 1e-7).collect::<Vec<f64>>(),
        ),
        _ => (
            need(&gps, "latitude_deg", 0, topic)?,
            need(&gps, "longitude_deg", 0, topic)?,
        ),
    };
    let alt: Vec<f64> = match gps.column("alt_ellipsoid", 0) {
        Some(a) => a.iter().map(|v| v * 1e-3).collect(),
        None => need(&gps, "altitude_ellipsoid_m", 0, topic)?,
    };
    let gt = need(&gps, "timestamp", 0, topic)?;
    let fix_type = need(&gps, "fix_type", 0, topic)?;
    let speed = gps.column("vel_m_s", 0);
    let course = gps.column("cog_rad", 0);
    let eph = gps.column("eph", 0);
    let hdop = gps.column("hdop", 0);
    let sats = gps.column("satellites_used", 0);
    let utc = gps.column("time_utc_usec", 0);
    let samples: Vec<GnssSample> = (0..gt.len())
        .filter(|&k| fix_type[k] >= 3.0)
        .map(|k| {
            let t = (gt[k] - t0_us) * 1e-6;
            GnssSample {
                t,
                stamp: t,
                lat: lat[k],
                lon: lon[k],
                alt: Some(alt[k]),
                speed: speed.as_ref().map(|v| v[k]),
                course: course.as_ref().map(|v| v[k].to_degrees()),
                hacc: eph.as_ref().map(|v| v[k]),
                hdop: hdop.as_ref().map(|v| v[k]),
                sats: sats.as_ref().map(|v| v[k]),
            }
        })
        .collect();
    let first = place_gnss(&mut log, &samples);
    if let (Some(first), Some(u)) = (first, &utc) {
        // time_utc_usec of that fix, less its time on the ride's clock.
        let k = (0..gt.len()).find(|&k| (gt[k] - t0_us) * 1e-6 == first.t);
        if let Some(k) = k.filter(|&k| u[k] > 0.0) {
            let t0_unix = u[k] * 1e-6 - first.t;
            log.metadata
                .insert("t0_unix_s".into(), format!("{t0_unix:.3}"));
        }
    }
    if first.is_none() {
        return Err(bad(format!(
            "{topic} has no 3D fix while the gyro runs: a path needs GNSS fixes"
        )));
    }
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A message of `kind` with `payload`.
    fn msg(kind: u8, payload: &[u8]) -> Vec<u8> {
        let mut m = (payload.len() as u16).to_le_bytes().to_vec();
        m.push(kind);
        m.extend(payload);
        m
    }

    /// A small log: a nested format, one subscription, two gyro samples,
    /// one GNSS fix.
    fn tiny() -> Vec<u8> {
        let mut b = MAGIC.to_vec();
        b.push(1);
        b.extend(0u64.to_le_bytes());
        b.extend(msg(b'B', &[0u8; 40]));
        b.extend(msg(b'F', b"vec3:float x;float y;float z;"));
        b.extend(msg(
            b'F',
            b"sensor_combined:uint64_t timestamp;float[3] gyro_rad;uint8_t[4] _padding0;",
        ));
        b.extend(msg(
            b'F',
            b"vehicle_gps_position:uint64_t timestamp;int32_t lat;int32_t lon;int32_t alt_ellipsoid;uint8_t fix_type;vec3 v;",
        ));
        b.extend(msg(b'A', b"\x00\x01\x00sensor_combined"));
        b.extend(msg(b'A', b"\x00\x02\x00vehicle_gps_position"));
        for (t, z) in [(1_000_000u64, 0.1f32), (1_005_000, 0.2)] {
            let mut p = 1u16.to_le_bytes().to_vec();
            p.extend(t.to_le_bytes());
            for g in [0.0f32, 0.0, z] {
                p.extend(g.to_le_bytes());
            }
            b.extend(msg(b'D', &p));
        }
        let mut p = 2u16.to_le_bytes().to_vec();
        p.extend(1_004_000u64.to_le_bytes());
        p.extend(634_170_622i32.to_le_bytes());
        p.extend(104_082_151i32.to_le_bytes());
        p.extend(100_000i32.to_le_bytes());
        p.push(3);
        for v in [1.0f32, 2.0, 3.0] {
            p.extend(v.to_le_bytes());
        }
        b.extend(msg(b'D', &p));
        b
    }

    #[test]
    fn reads_gyro_and_fixes_through_the_formats() {
        let log = parse(&tiny(), "tiny.ulg").unwrap();
        assert_eq!(log.t_s, vec![0.0, 0.005]);
        // Down made up: z negated, in deg/s.
        assert!((log.gyro_dps[1][2] + 0.2f32 as f64 * 180.0 / std::f64::consts::PI).abs() < 1e-9);
        assert_eq!(log.fix_count(), 1);
        let (lat, lon) = log.fix[1].unwrap();
        assert!((lat - 63.4170622).abs() < 1e-9 && (lon - 10.4082151).abs() < 1e-9);
        assert_eq!(log.gps_alt_m.as_ref().unwrap()[1], Some(100.0));
        // The nested format lays out after the fix type.
        let topics = messages(&tiny(), "tiny.ulg").unwrap();
        let (fields, size) = topics.layout("vehicle_gps_position", 0).unwrap();
        assert_eq!(size, 8 + 4 * 3 + 1 + 12);
        assert_eq!(fields.last().unwrap().name, "v.z");
        assert_eq!(fields.last().unwrap().offset, 8 + 12 + 1 + 8);
    }

    #[test]
    fn bad_logs_say_what_is_wrong_and_never_panic() {
        let err = |b: &[u8]| parse(b, "bad.ulg").unwrap_err().to_string();
        assert!(err(b"t_s,gx_dps\n").contains("no ULog magic"));
        let good = tiny();
        // Every cut: an error or the part before the cut, never a panic.
        for n in 0..good.len() {
            let _ = parse(&good[..n], "cut.ulg");
        }
        // Cut inside the fix's message: the messages before it are kept.
        assert!(err(&good[..good.len() - 10]).contains("no GNSS data"));
        // A format that names an unknown nested type.
        let mut broken = good.clone();
        let at = good.windows(7).position(|w| w == b"vec3 v;").unwrap();
        broken[at + 3] = b'9';
        assert!(
            err(&broken).contains("no format for 'vec9'"),
            "{}",
            err(&broken)
        );
        let mut flags = good.clone();
        flags[16 + 3 + 8] = 0x02;
        assert!(err(&flags).contains("incompatible flags"));
    }
}
