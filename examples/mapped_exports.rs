//! Writes the two mapped-CSV examples of the README into `data/mapped/` from
//! a simulated ride (seed 31, 3 minutes, odometer logged as cumulative distance):
//!
//! - a phone export (`phone-gyro.csv` + `phone-location.csv`, read with
//!   `phone.toml`): nanosecond clock, gyro in rad/s in the phone's own axes
//!   (upright in a handlebar mount: x right, y up, z towards the rider), a
//!   separate location file at 1 Hz with the GPS speed, accuracy and altitude;
//! - a custom logger (`logger.csv`, read with `logger.toml`): milliseconds,
//!   deg/s in the ride frame, a wheel encoder counting 512 ticks per
//!   2.105 m revolution, GPS in the same file, a temperature column.
//!
//! `cargo run --example mapped_exports`

use std::fmt::Write as _;
use std::path::Path;

use gyropath::import::parse;
use gyropath::simulation::{SimConfig, simulate};

fn main() -> anyhow::Result<()> {
    let sim = simulate(&SimConfig {
        seed: 31,
        duration_s: 180.0,
        odometer: true,
        ..SimConfig::default()
    })?;
    let log = parse(sim.log_csv.as_bytes(), "sim")?;
    let odo = log.odo_m.clone().unwrap_or_default();
    let temp = log
        .channels
        .iter()
        .find(|(n, _)| n == "temp_c")
        .map(|(_, v)| v.clone());
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/mapped");
    std::fs::create_dir_all(&dir)?;
    let boot_ns: i64 = 1_725_000_000_000_000_000;

    // Phone: gyro in rad/s in the phone's frame. With the phone upright
    // (x right, y up, z towards the rider, i.e. backwards), the ride frame
    // is gx = -z, gy = -x, gz = y, so the phone logs x = -gy, y = gz, z = -gx.
    let mut gyro = String::from("time,seconds_elapsed,z,y,x\n");
    for j in 0..log.len() {
        let t = log.t_s[j];
        let g = log.gyro_dps[j].map(f64::to_radians);
        let (x, y, z) = (-g[1], g[2], -g[0]);
        writeln!(
            gyro,
            "{},{t},{z},{y},{x}",
            boot_ns + (t * 1e9).round() as i64
        )?;
    }
    std::fs::write(dir.join("phone-gyro.csv"), gyro)?;
    let mut loc = String::from(
        "time,seconds_elapsed,latitude,longitude,altitude,speed,horizontalAccuracy,verticalAccuracy\n",
    );
    let fixes: Vec<usize> = (0..log.len()).filter(|&j| log.fix[j].is_some()).collect();
    for (k, &j) in fixes.iter().enumerate() {
        let (lat, lon) = log.fix[j].unwrap_or_default();
        let alt = log.gps_alt_m.as_ref().and_then(|a| a[j]).unwrap_or(0.0);
        // GPS speed: the odometer's mean speed over the second around the fix.
        let (a, b) = (
            fixes[k.saturating_sub(1)],
            fixes[(k + 1).min(fixes.len() - 1)],
        );
        let speed = match (odo[a], odo[b]) {
            (Some(oa), Some(ob)) if b > a => (ob - oa) / (log.t_s[b] - log.t_s[a]),
            _ => 0.0,
        };
        writeln!(
            loc,
            "{},{},{lat},{lon},{alt:.2},{speed:.3},{:.1},{:.1}",
            boot_ns + (log.t_s[j] * 1e9).round() as i64,
            log.t_s[j],
            3.0 + (k % 5) as f64 * 0.4,
            6.0
        )?;
    }
    std::fs::write(dir.join("phone-location.csv"), loc)?;

    // Custom logger: ms, deg/s (ride frame), cumulative encoder ticks, GPS in the same file.
    let ticks_per_m = 512.0 / 2.105;
    let mut out =
        String::from("# my-logger v2.3\nms,gyro_x,gyro_y,gyro_z,enc_ticks,lat,lon,alt,temp\n");
    for j in 0..log.len() {
        let g = log.gyro_dps[j];
        let ticks = (odo[j].unwrap_or(0.0) * ticks_per_m).floor();
        let (lat, lon) = log.fix[j].map_or((String::new(), String::new()), |(a, b)| {
            (a.to_string(), b.to_string())
        });
        let alt = if log.fix[j].is_some() {
            log.gps_alt_m
                .as_ref()
                .and_then(|a| a[j])
                .map_or(String::new(), |a| format!("{a:.1}"))
        } else {
            String::new()
        };
        let tc = temp
            .as_ref()
            .and_then(|t| t[j])
            .map_or(String::new(), |v| v.to_string());
        writeln!(
            out,
            "{:.0},{},{},{},{ticks},{lat},{lon},{alt},{tc}",
            log.t_s[j] * 1000.0,
            g[0],
            g[1],
            g[2]
        )?;
    }
    std::fs::write(dir.join("logger.csv"), out)?;
    eprintln!("wrote {}", dir.display());
    Ok(())
}
