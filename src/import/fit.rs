//! Garmin FIT activities (`.fit`, from bike computers and watches), read by
//! the `fitparser` crate: GNSS positions, speed and distance at 1 Hz, and
//! which ANT+ sensors were paired, but no gyro (no licensed FIT sample with
//! `gyroscope_data` is known). A FIT file is therefore a reference track of
//! a ride that has a gyro (`--reference ride.fit`, in UTC like GPX), and
//! opened as a ride it says what it is.
//!
//! The activity's `record` messages give the points: `position_lat` and
//! `position_long` (semicircles, `deg = s * 180 / 2^31`), `enhanced_altitude`
//! (else `altitude`) and the `timestamp` (whole seconds, UTC). Records
//! without a position (sensor-only seconds, a lost fix) are left out, as
//! are repeats of a second. A wheel-speed sensor is told by `device_info`
//! (`antplus_device_type` or `device_type` `bike_speed` or
//! `bike_speed_cadence`, 121 or 123): the FIT `speed` field does not say
//! whether the GNSS or the wheel measured it.

use fitparser::profile::MesgNum;
use fitparser::{FitDataRecord, Value};

use super::LoadError;
use super::reference::{Clock, ReferenceTrack};
use crate::geodesy::Geodetic;

/// Whether the first bytes of a file are a FIT header (`.FIT` at byte 8).
pub fn is_fit(head: &[u8]) -> bool {
    head.len() >= 12 && &head[8..12] == b".FIT"
}

/// What a FIT activity holds, beyond its track.
#[derive(Clone, Debug, PartialEq)]
pub struct Activity {
    pub track: ReferenceTrack,
    /// The device's last `distance` (m), where it logs one.
    pub distance_m: Option<f64>,
    /// Whether a wheel-speed sensor was paired.
    pub wheel_sensor: bool,
    /// The device's product name, where it says it.
    pub device: Option<String>,
}

impl Activity {
    /// One line for messages: the device, the points, duration and distance.
    pub fn describe(&self) -> String {
        let t = &self.track.t_s;
        format!(
            "a Garmin FIT activity{} of {} points over {:.0} s{}{}",
            self.device
                .as_ref()
                .map_or(String::new(), |d| format!(" ({d})")),
            t.len(),
            t.last().zip(t.first()).map_or(0.0, |(l, f)| l - f),
            self.distance_m
                .map_or(String::new(), |d| format!(", {:.1} km", d / 1000.0)),
            if self.wheel_sensor {
                ", with a wheel-speed sensor paired"
            } else {
                ""
            }
        )
    }
}

fn number(v: &Value) -> Option<f64> {
    let x: f64 = v.clone().try_into().ok()?;
    x.is_finite().then_some(x)
}

fn field<'r>(r: &'r FitDataRecord, name: &str) -> Option<&'r Value> {
    r.fields()
        .iter()
        .find(|f| f.name() == name)
        .map(|f| f.value())
}

/// Parse the bytes of a FIT file named `file` (for messages).
pub fn parse(bytes: &[u8], file: &str) -> Result<Activity, LoadError> {
    let whole = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    // A third-party parser of a binary format: its panic is this file's error.
    let records = match std::panic::catch_unwind(|| fitparser::from_bytes(bytes)) {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => return Err(whole(format!("not a readable FIT file: {e}"))),
        Err(_) => {
            return Err(whole(
                "the FIT parser failed on this file (it is damaged)".into(),
            ));
        }
    };
    let mut track = ReferenceTrack::empty(file, Clock::Unix);
    let mut distance_m = None;
    let mut wheel_sensor = false;
    let mut device = None;
    const SEMICIRCLE_DEG: f64 = 180.0 / 2_147_483_648.0;
    for r in &records {
        match r.kind() {
            MesgNum::Record => {
                if let Some(d) = field(r, "distance").and_then(number) {
                    distance_m = Some(d);
                }
                let (Some(lat), Some(lon), Some(Value::Timestamp(time))) = (
                    field(r, "position_lat").and_then(number),
                    field(r, "position_long").and_then(number),
                    field(r, "timestamp"),
                ) else {
                    continue;
                };
                let t = time.timestamp() as f64;
                if track.t_s.last().is_some_and(|&last| t <= last) {
                    continue;
                }
                let alt = field(r, "enhanced_altitude")
                    .or_else(|| field(r, "altitude"))
                    .and_then(number);
                track.has_alt |= alt.is_some();
                track.t_s.push(t);
                track.points.push(Geodetic::new(
                    lat * SEMICIRCLE_DEG,
                    lon * SEMICIRCLE_DEG,
                    alt.unwrap_or(f64::NAN),
                ));
            }
            MesgNum::DeviceInfo => {
                let kind = |name: &str| field(r, name).map(|v| v.to_string());
                let speed_sensor = |k: Option<String>| {
                    k.is_some_and(|k| {
                        matches!(
                            k.as_str(),
                            "bike_speed" | "bike_speed_cadence" | "121" | "123"
                        )
                    })
                };
                wheel_sensor |=
                    speed_sensor(kind("antplus_device_type")) || speed_sensor(kind("device_type"));
                if kind("device_index").as_deref() == Some("creator") {
                    device = field(r, "product_name")
                        .or_else(|| field(r, "garmin_product"))
                        .map(|v| v.to_string())
                        .filter(|s| !s.is_empty() && s != "0")
                        .or(device);
                }
            }
            _ => {}
        }
    }
    if track.t_s.len() < 2 {
        return Err(whole(
            "the FIT file has fewer than two records with a position and a time: no track".into(),
        ));
    }
    Ok(Activity {
        track,
        distance_m,
        wheel_sensor,
        device,
    })
}
