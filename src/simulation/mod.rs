//! A realistic bicycle-ride simulator: the test bed for everything.
//!
//! [`route`] makes the true 3-D motion; this module turns it into sensor
//! readings in the ride-log format. Sensors: gyro with white noise,
//! quantisation, a constant bias plus a slow random walk; reed-switch wheel
//! pulses with a wrongly configured circumference; 1 Hz GPS with noise
//! correlated over about a minute plus white noise and outages of 20-60 s;
//! noisy GPS altitude; a barometer (10 Hz) with an offset and a slow drift; a
//! temperature channel (1 Hz) from a thermal model of the logger
//! ([`thermal`]). Optional *hidden* effects, which the paper's model lacks:
//! `gyro_scale`, `gps_lag`, `mount_misalignment`, `gyro_bias_channel:temp_c`,
//! `gps_outliers`, and with the GNSS speed logged (`gnss_speed`) `speed_lag`.
//!
//! The gyro reading of row `k` is the exact mean body rate over
//! `(t_{k-1}, t_k]`, `Log(R_{k-1}^T R_k) / dt`, computed from the true
//! attitudes: no integration scheme is shared with the model.
//!
//! The measurements and the history behind these choices: docs/accuracy.md
//! and docs/real-drives.md (the simulator against the real drives).

pub mod reflections;
pub mod rng;
pub mod route;
pub mod thermal;
pub mod urban;

use std::fmt::Write as _;

use nalgebra::{UnitQuaternion, Vector3};
use thiserror::Error;

use crate::geodesy::{Geodetic, LocalFrame};
use rng::Rng;
use route::Route;
pub use route::Vehicle;
use thermal::Thermal;
pub use urban::GpsEnvironment;
use urban::UrbanGps;

/// Effects the simulator can hide in a ride.
pub const HIDDEN_EFFECTS: [&str; 6] = [
    "gyro_scale",
    "gps_lag",
    "mount_misalignment",
    "gyro_bias_channel:temp_c",
    "gps_outliers",
    "speed_lag",
];

#[derive(Debug, Error)]
pub enum SimulationError {
    #[error("unknown hidden effect '{0}' (known: {known})", known = HIDDEN_EFFECTS.join(", "))]
    UnknownHidden(String),
    #[error("{0}")]
    Setting(String),
}

/// What to simulate.
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig {
    pub seed: u64,
    /// Ride length (s).
    pub duration_s: f64,
    /// Logging rate (Hz).
    pub rate_hz: f64,
    /// Hidden effects, ids from [`HIDDEN_EFFECTS`].
    pub hidden: Vec<String>,
    /// Log cumulative distance (`odo_m`) instead of wheel pulses.
    pub odometer: bool,
    /// Include GPS outages.
    pub outages: bool,
    /// What drives the route (a bicycle logs wheel pulses or `odo_m`, a car
    /// or robot a signed wheel speed `speed_mps`; a robot's GPS runs at 2.5 Hz).
    pub vehicle: Vehicle,
    /// Log only the yaw rate (`gx_dps`, `gy_dps` written as 0), as a car's yaw-rate sensor.
    pub yaw_only: bool,
    /// Write the gyro in other axes or units: the mounting that undoes it
    /// (`x=-z,y=-x,z=y,scale=57.29577951308232` writes rad/s in a Husky's axes).
    pub gyro_axes: Option<crate::import::Mount>,
    /// Open sky, or a city (see [`urban`]): urban rides also log `gps_hacc_m` and `gps_num_sats`.
    pub gps: GpsEnvironment,
    /// The gyro bias's random-walk density (deg/s/sqrt(s)); `None`: drawn in 0.002-0.004.
    pub bias_walk_dps_sqrt_s: Option<f64>,
    /// Log the GNSS receiver's ground speed with every fix (`gps_speed_mps`,
    /// 0.05 m/s of noise), from which a ride without a wheel sensor takes
    /// its distance (`--distance gnss`).
    pub gnss_speed: bool,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            duration_s: 600.0,
            rate_hz: 100.0,
            hidden: Vec::new(),
            odometer: false,
            outages: true,
            vehicle: Vehicle::Bicycle,
            yaw_only: false,
            gyro_axes: None,
            gps: GpsEnvironment::Open,
            bias_walk_dps_sqrt_s: None,
            gnss_speed: false,
        }
    }
}

/// The true values behind a simulated ride, for tests and `data/README.md`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SimTruth {
    pub seed: u64,
    pub vehicle: Vehicle,
    /// Metres driven in reverse.
    pub reversed_m: f64,
    pub duration_s: f64,
    pub rate_hz: f64,
    pub hidden: Vec<String>,
    pub distance_m: f64,
    pub stops: usize,
    pub wheel_circumference_true_m: f64,
    pub wheel_circumference_configured_m: f64,
    /// True metres per odometer metre.
    pub odometer_gain: f64,
    /// Gyro bias at the start (deg/s, sensor axes).
    pub gyro_bias_start_dps: [f64; 3],
    /// Gyro bias at the end (deg/s).
    pub gyro_bias_end_dps: [f64; 3],
    pub bias_walk_dps_sqrt_s: f64,
    pub gps_outages_s: Vec<(f64, f64)>,
    pub gps_lag_s: Option<f64>,
    /// How late the logged GNSS speed is (s): it is the speed at `t - lag`.
    pub speed_lag_s: Option<f64>,
    pub gyro_scale: Option<[f64; 3]>,
    /// Sensor frame rotated from the bike's frame (roll, pitch, yaw, deg).
    pub mount_misalignment_deg: Option<[f64; 3]>,
    /// Bias per degree C (deg/s/C).
    pub temp_coefficient_dps_per_c: Option<[f64; 3]>,
    pub gps_outlier_episodes: Vec<(f64, f64, f64)>,
    pub gps: GpsEnvironment,
    /// Urban street canyons (start, end, sideways pull m) and jumps (start, end, size m).
    pub urban_canyons: Vec<(f64, f64, f64)>,
    pub urban_jumps: Vec<(f64, f64, f64)>,
    pub baro_offset_m: f64,
    pub baro_drift_m_per_h: f64,
}

/// A simulated ride: the log as CSV text, the true path and the truth.
#[derive(Clone, Debug)]
pub struct SimulatedRide {
    pub log_csv: String,
    /// `t_s,lat_deg,lon_deg,alt_m` per row.
    pub truth_csv: String,
    /// True local ENU position per row (same frame origin as `origin`).
    pub truth_enu: Vec<Vector3<f64>>,
    pub origin: Geodetic,
    pub truth: SimTruth,
}

impl SimulatedRide {
    /// The ride log read back as a user's file is (`name` in messages).
    pub fn log(&self, name: &str) -> Result<crate::ride::RideLog, crate::import::LoadError> {
        crate::import::parse(self.log_csv.as_bytes(), name)
    }

    /// The true path as a reference track, as `--reference` reads it.
    pub fn reference(
        &self,
        name: &str,
    ) -> Result<crate::import::reference::ReferenceTrack, crate::import::LoadError> {
        crate::import::reference::parse_reference(self.truth_csv.as_bytes(), name)
    }
}

/// Gauss-Markov process `x_{k+1} = a x_k + sqrt(1 - a^2) sigma n_k`, stationary std `sigma`.
struct GaussMarkov {
    x: f64,
    a: f64,
    sigma: f64,
}

impl GaussMarkov {
    fn new(rng: &mut Rng, sigma: f64, tau: f64, dt: f64) -> Self {
        Self {
            x: sigma * rng.normal(),
            a: (-dt / tau).exp(),
            sigma,
        }
    }

    fn next(&mut self, rng: &mut Rng) -> f64 {
        self.x = self.a * self.x + (1.0 - self.a * self.a).sqrt() * self.sigma * rng.normal();
        self.x
    }
}

fn hidden_has(config: &SimConfig, id: &str) -> bool {
    config.hidden.iter().any(|h| h == id)
}

/// Simulate a ride.
pub fn simulate(config: &SimConfig) -> Result<SimulatedRide, SimulationError> {
    for h in &config.hidden {
        if !HIDDEN_EFFECTS.contains(&h.as_str()) {
            return Err(SimulationError::UnknownHidden(h.clone()));
        }
    }
    if hidden_has(config, "speed_lag") && !config.gnss_speed {
        return Err(SimulationError::Setting(
            "a hidden speed_lag needs the GNSS speed logged (--gnss-speed)".into(),
        ));
    }
    if !(config.duration_s.is_finite() && config.duration_s >= 10.0) {
        return Err(SimulationError::Setting(format!(
            "duration must be at least 10 s, got {}",
            config.duration_s
        )));
    }
    if !(config.rate_hz.is_finite() && (1.0..=10_000.0).contains(&config.rate_hz)) {
        return Err(SimulationError::Setting(format!(
            "rate must be 1..10000 Hz, got {}",
            config.rate_hz
        )));
    }
    let mut rng = Rng::new(config.seed);
    let route = Route::plan_for(config.vehicle, &mut rng, config.duration_s);
    let bicycle = config.vehicle == Vehicle::Bicycle;
    let gps_hz = if config.vehicle == Vehicle::Robot {
        2.5
    } else {
        1.0
    };
    let n = (config.duration_s * config.rate_hz).round() as usize + 1;
    let dt = 1.0 / config.rate_hz;
    let times: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let states: Vec<route::State> = times.iter().map(|&t| route.state(t)).collect();

    // Sensor and environment parameters.
    let origin = Geodetic::new(
        47.47 + rng.range(0.0, 0.05),
        19.0 + rng.range(0.0, 0.08),
        rng.range(100.0, 160.0),
    );
    let frame = LocalFrame::new(origin);
    let c_true = 2.105;
    let c_conf = c_true * (1.0 + rng.sign() * rng.range(0.01, 0.04));
    let bias0 = Vector3::new(rng.normal() * 0.4, rng.normal() * 0.4, rng.normal() * 0.4);
    let drawn_walk = rng.range(0.002, 0.004);
    let bias_walk = config.bias_walk_dps_sqrt_s.unwrap_or(drawn_walk);
    if !(bias_walk.is_finite() && bias_walk >= 0.0) {
        return Err(SimulationError::Setting(format!(
            "bias walk must be a non-negative number of deg/s/sqrt(s), got {bias_walk}"
        )));
    }
    let noise_dps = 0.07;
    let lsb_dps = 1.0 / 65.5;
    let temp_air = rng.range(8.0, 18.0);
    // Temperature at which the bias is `bias0` (a hidden temperature
    // coefficient moves it by `c (T - temp_calibration)`).
    let temp_calibration = rng.range(22.0, 28.0);
    let temp_tau = rng.range(400.0, 900.0);
    let baro_offset = rng.range(-30.0, 60.0);
    let baro_drift = rng.sign() * rng.range(1.0, 4.0);

    let gps_lag = hidden_has(config, "gps_lag").then(|| rng.range(0.3, 1.2));
    let scale = hidden_has(config, "gyro_scale").then(|| {
        [
            rng.sign() * rng.range(0.02, 0.05),
            rng.sign() * rng.range(0.02, 0.05),
            rng.sign() * rng.range(0.02, 0.05),
        ]
    });
    let misalign = hidden_has(config, "mount_misalignment").then(|| {
        [
            rng.sign() * rng.range(1.0, 3.0),
            rng.sign() * rng.range(2.0, 5.0),
            rng.sign() * rng.range(2.0, 5.0),
        ]
    });
    let temp_coeff = hidden_has(config, "gyro_bias_channel:temp_c").then(|| {
        [
            rng.sign() * rng.range(0.03, 0.06),
            rng.sign() * rng.range(0.03, 0.06),
            rng.sign() * rng.range(0.04, 0.08),
        ]
    });
    let mount = misalign.map_or(UnitQuaternion::identity(), |m| {
        UnitQuaternion::from_euler_angles(m[0].to_radians(), m[1].to_radians(), m[2].to_radians())
    });

    // GPS outages and outlier episodes.
    let mut outages: Vec<(f64, f64)> = Vec::new();
    if config.outages && config.duration_s > 180.0 {
        let count = ((config.duration_s / 600.0) * 1.5).round().max(1.0) as usize;
        for i in 0..count {
            let span = (config.duration_s - 120.0) / count as f64;
            let start = 60.0 + span * i as f64 + rng.range(0.0, (span - 60.0).max(1.0));
            let len = rng.range(20.0, 60.0);
            outages.push((start, (start + len).min(config.duration_s - 20.0)));
        }
    }
    let mut episodes: Vec<(f64, f64, f64)> = Vec::new();
    let mut jumps: Vec<Vector3<f64>> = Vec::new();
    if hidden_has(config, "gps_outliers") {
        let count = (config.duration_s / 150.0).ceil().max(2.0) as usize;
        for i in 0..count {
            let span = config.duration_s / count as f64;
            let start = span * i as f64 + rng.range(10.0, (span - 12.0).max(11.0));
            let len = rng.range(3.0, 10.0);
            let size = rng.range(10.0, 40.0);
            let dir = rng.range(0.0, std::f64::consts::TAU);
            episodes.push((start, start + len, size));
            jumps.push(Vector3::new(
                size * dir.cos(),
                size * dir.sin(),
                0.3 * size * rng.normal(),
            ));
        }
    }

    let mut gm = [
        GaussMarkov::new(&mut rng, 1.5, 60.0, 1.0 / gps_hz),
        GaussMarkov::new(&mut rng, 1.5, 60.0, 1.0 / gps_hz),
        GaussMarkov::new(&mut rng, 3.0, 60.0, 1.0 / gps_hz),
    ];
    let mut baro_gm = GaussMarkov::new(&mut rng, 0.2, 30.0, dt);
    let phase = rng.range(0.0, c_true);

    let mut log = String::with_capacity(n * 48);
    let _ = writeln!(log, "# gyropath ride log");
    if bicycle {
        let _ = writeln!(log, "# wheel_circumference_m: {c_conf:.4}");
        let _ = writeln!(
            log,
            "# generator: gyropath simulate --seed {} --duration {}",
            config.seed, config.duration_s
        );
    } else {
        let _ = writeln!(
            log,
            "# generator: gyropath simulate --vehicle {} --seed {} --duration {} --rate {}{}",
            format!("{:?}", config.vehicle).to_lowercase(),
            config.seed,
            config.duration_s,
            config.rate_hz,
            if config.yaw_only { " --yaw-only" } else { "" }
        );
    }
    let distance_col = if !bicycle {
        "speed_mps"
    } else if config.odometer {
        "odo_m"
    } else {
        "wheel_pulse"
    };
    let urban = config.gps == GpsEnvironment::Urban;
    let mut city = urban.then(|| {
        UrbanGps::new(
            Rng::new(config.seed ^ 0x0C17_5CA9_E0F5_1DE5),
            config.duration_s,
        )
    });
    let mut reflections = (config.gps == GpsEnvironment::City)
        .then(|| reflections::Reflections::new(Rng::new(config.seed ^ 0x5EF1_EC71_0B5E_B111)));
    let extra_cols = match (bicycle, urban) {
        (true, false) => ",baro_alt_m,temp_c",
        (true, true) => ",baro_alt_m,temp_c,gps_hacc_m,gps_num_sats",
        (false, false) => "",
        (false, true) => ",gps_hacc_m,gps_num_sats",
    };
    // The GNSS speed's noise and lag from their own random stream, so every
    // other draw stays as it was.
    let mut speed_rng = Rng::new(config.seed ^ 0x5BEE_D1A6_7A60_0F5E);
    let speed_lag = hidden_has(config, "speed_lag").then(|| speed_rng.range(0.2, 0.6));
    let speed_col = if config.gnss_speed {
        ",gps_speed_mps"
    } else {
        ""
    };
    let _ = writeln!(
        log,
        "t_s,gx_dps,gy_dps,gz_dps,{distance_col},lat_deg,lon_deg,gps_alt_m{extra_cols}{speed_col}"
    );
    let mut truth_csv = String::with_capacity(n * 44);
    let _ = writeln!(truth_csv, "t_s,lat_deg,lon_deg,alt_m");

    let mut walk = Vector3::zeros();
    let baro_every = ((config.rate_hz / 10.0).round() as usize).max(1);
    let temp_every = (config.rate_hz.round() as usize).max(1);
    let mut next_fix = 0.0f64;
    let mut truth_enu = Vec::with_capacity(n);
    let t_decimals = if config.rate_hz > 100.0 { 3 } else { 2 };
    // Its own random stream, so the thermal model leaves every other draw as it was.
    let mut thermal = Thermal::new(
        Rng::new(config.seed ^ 0x7E4D_5EED_0BAD_CAFE),
        temp_air,
        0.15 * temp_tau,
    );
    let temp_bias = |temp: f64| {
        temp_coeff.map_or(Vector3::zeros(), |c| {
            Vector3::new(c[0], c[1], c[2]) * (temp - temp_calibration)
        })
    };
    let bias_start = bias0 + temp_bias(thermal.temperature());
    let mut bias_end = bias_start;
    for k in 0..n {
        let t = times[k];
        let st = &states[k];
        truth_enu.push(st.position);
        let g = frame.to_geodetic(&st.position);
        let _ = writeln!(
            truth_csv,
            "{t:.td$},{:.9},{:.9},{:.3}",
            g.lat_deg,
            g.lon_deg,
            g.alt_m,
            td = t_decimals
        );

        // Gyro: exact mean body rate over the step, into the sensor frame.
        if k > 0 {
            thermal.step(st.speed, dt);
        }
        let temp = thermal.temperature();
        let gyro = if k == 0 {
            Vector3::zeros()
        } else {
            let body = (states[k - 1].attitude.inverse() * st.attitude).scaled_axis() / dt;
            let sensor = mount.inverse() * body;
            walk +=
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * (bias_walk * dt.sqrt());
            let bias = bias0 + walk + temp_bias(temp);
            bias_end = bias;
            let mut w = sensor.map(f64::to_degrees);
            if let Some(s) = scale {
                w = w.component_mul(&Vector3::new(1.0 + s[0], 1.0 + s[1], 1.0 + s[2]));
            }
            (w + bias + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise_dps)
                .map(|v| (v / lsb_dps).round() * lsb_dps)
        };
        let gyro = logged_gyro(config, gyro);

        // Distance.
        let distance_field = if !bicycle {
            // Wheel speed, signed, with the odometer's scale error.
            format!("{:.3}", st.velocity / (c_true / c_conf))
        } else if config.odometer {
            format!("{:.3}", st.odo / (c_true / c_conf))
        } else {
            // The reed switch is closed while the magnet is within `window` of it;
            // the row reads 1 if that happened at any time during its step.
            let prev = if k == 0 { st.s } else { states[k - 1].s };
            let window = 0.08 * c_true;
            let last_pass = ((st.s - phase) / c_true).floor() * c_true;
            let on = last_pass + window >= prev - phase;
            (if on { "1" } else { "0" }).to_string()
        };

        // GPS.
        let mut fix = String::from(",,");
        let mut urban_fields = String::from(",,");
        let mut speed_field = String::new();
        if t + 0.5 * dt >= next_fix {
            next_fix += 1.0 / gps_hz;
            let noise =
                Vector3::new(
                    gm[0].next(&mut rng),
                    gm[1].next(&mut rng),
                    gm[2].next(&mut rng),
                ) + Vector3::new(0.5 * rng.normal(), 0.5 * rng.normal(), 1.5 * rng.normal());
            let in_outage = outages.iter().any(|&(a, b)| t >= a && t < b);
            // Among buildings the receiver has no solution in many seconds.
            let reflected = reflections.as_mut().map(|r| r.fix(1.0 / gps_hz));
            if !in_outage && reflected != Some(None) {
                let seen =
                    gps_lag.map_or(st.position, |lag| route.state((t - lag).max(0.0)).position);
                let mut p = seen + noise;
                for (e, j) in episodes.iter().zip(&jumps) {
                    if t >= e.0 && t < e.1 {
                        p += j;
                    }
                }
                if let Some(Some(r)) = reflected {
                    p += r;
                }
                if let Some(c) = city.as_mut() {
                    let f = st.attitude * Vector3::x();
                    let u = c.fix(t, f.y.atan2(f.x));
                    p += u.offset;
                    urban_fields = format!(",{:.1},{}", u.hacc, u.satellites);
                }
                let gp = frame.to_geodetic(&p);
                fix = format!("{:.8},{:.8},{:.1}", gp.lat_deg, gp.lon_deg, gp.alt_m);
                if config.gnss_speed {
                    let moving =
                        speed_lag.map_or(st.speed, |lag| route.state((t - lag).max(0.0)).speed);
                    let v = (moving.abs() + 0.05 * speed_rng.normal()).max(0.0);
                    speed_field = format!("{v:.3}");
                }
            }
        }
        let baro = if k % baro_every == 0 {
            let v = st.position.z
                + origin.alt_m
                + baro_offset
                + baro_drift * t / 3600.0
                + baro_gm.next(&mut rng);
            format!("{v:.2}")
        } else {
            String::new()
        };
        let temp_field = if k % temp_every == 0 {
            format!("{:.2}", temp + 0.05 * rng.normal())
        } else {
            String::new()
        };
        let mut tail = if bicycle {
            format!(",{baro},{temp_field}")
        } else {
            String::new()
        };
        if urban {
            tail.push_str(&urban_fields);
        }
        if config.gnss_speed {
            tail.push(',');
            tail.push_str(&speed_field);
        }
        let _ = writeln!(
            log,
            "{t:.td$},{:.4},{:.4},{:.4},{distance_field},{fix}{tail}",
            gyro.x,
            gyro.y,
            gyro.z,
            td = t_decimals
        );
    }
    let truth = SimTruth {
        seed: config.seed,
        vehicle: config.vehicle,
        reversed_m: route.reversed_m,
        duration_s: config.duration_s,
        rate_hz: config.rate_hz,
        hidden: config.hidden.clone(),
        distance_m: states.last().map_or(0.0, |s| s.s),
        stops: route.stops,
        wheel_circumference_true_m: c_true,
        wheel_circumference_configured_m: c_conf,
        odometer_gain: c_true / c_conf,
        gyro_bias_start_dps: bias_start.into(),
        gyro_bias_end_dps: bias_end.into(),
        bias_walk_dps_sqrt_s: bias_walk,
        gps_outages_s: outages,
        gps_lag_s: gps_lag,
        speed_lag_s: speed_lag,
        gyro_scale: scale,
        mount_misalignment_deg: misalign,
        temp_coefficient_dps_per_c: temp_coeff,
        gps_outlier_episodes: episodes,
        gps: config.gps,
        urban_canyons: city.as_ref().map(|c| c.episodes().0).unwrap_or_default(),
        urban_jumps: city.as_ref().map(|c| c.episodes().1).unwrap_or_default(),
        baro_offset_m: baro_offset,
        baro_drift_m_per_h: baro_drift,
    };
    Ok(SimulatedRide {
        log_csv: log,
        truth_csv,
        truth_enu,
        origin,
        truth,
    })
}

/// The gyro as the log writes it: yaw only, or in other axes and units
/// (`logged[axis[i]] = ride[i] / (sign[i] scale)`, undone by mounting with `gyro_axes`).
fn logged_gyro(config: &SimConfig, ride: Vector3<f64>) -> Vector3<f64> {
    let mut w = ride;
    if config.yaw_only {
        w.x = 0.0;
        w.y = 0.0;
    }
    if let Some(m) = &config.gyro_axes {
        let mut logged = Vector3::zeros();
        for i in 0..3 {
            logged[m.axis[i]] = w[i] / (m.sign[i] * m.scale);
        }
        w = logged;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::parse;
    use crate::signals::Signals;

    #[test]
    fn a_simulated_ride_loads_and_has_what_it_promises() {
        let ride = simulate(&SimConfig {
            duration_s: 300.0,
            ..SimConfig::default()
        })
        .unwrap();
        let log = parse(ride.log_csv.as_bytes(), "sim.csv").unwrap();
        assert_eq!(log.len(), 30_001);
        let sig = Signals::from_log(&log).unwrap();
        // About one fix per second minus the outage.
        let outage: f64 = ride.truth.gps_outages_s.iter().map(|(a, b)| b - a).sum();
        assert!(
            (sig.fixes.len() as f64 - (301.0 - outage)).abs() < 3.0,
            "{} fixes",
            sig.fixes.len()
        );
        // Wheel pulses, scaled by the configured circumference, give the distance within a revolution or two.
        let odo: f64 = sig.distance.iter().sum();
        let true_d = ride.truth.distance_m;
        assert!(
            (odo * ride.truth.odometer_gain - true_d).abs() < 2.0 * 2.105 + 0.01 * true_d,
            "{odo} vs {true_d}"
        );
        assert!(sig.channel("temp_c").is_some());
        // Deterministic.
        let again = simulate(&SimConfig {
            duration_s: 300.0,
            ..SimConfig::default()
        })
        .unwrap();
        assert_eq!(again.log_csv, ride.log_csv);
    }

    #[test]
    fn gyro_integrates_to_the_true_heading() {
        // With the true bias removed, integrating the rates follows the true attitude.
        let cfg = SimConfig {
            duration_s: 60.0,
            ..SimConfig::default()
        };
        let ride = simulate(&cfg).unwrap();
        let log = parse(ride.log_csv.as_bytes(), "sim.csv").unwrap();
        let route_start = {
            let mut rng = Rng::new(cfg.seed);
            Route::plan(&mut rng, cfg.duration_s).state(0.0).attitude
        };
        let mut q = route_start;
        let b = Vector3::from(ride.truth.gyro_bias_start_dps);
        for k in 1..log.len() {
            let g = Vector3::from(log.gyro_dps[k]);
            q *= UnitQuaternion::from_scaled_axis((g - b).map(f64::to_radians) * 0.01);
        }
        let f = q * Vector3::x();
        let p = &ride.truth_enu;
        let course = (p[p.len() - 1] - p[p.len() - 11]).normalize();
        // Within a couple of degrees after a minute (noise, bias walk, lean sway).
        assert!(f.dot(&course) > 2f64.to_radians().cos(), "{f} vs {course}");
    }
}

/// Horizontal errors of a reconstructed path against the simulator's truth.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TruthErrors {
    /// Path - truth at the rows with a GPS fix, RMS (m).
    pub path_at_fixes_m: f64,
    /// GPS fix - truth, RMS (m): what the path has to beat.
    pub fixes_m: f64,
    /// Path - truth over the rows inside GPS outages, RMS (m).
    pub path_in_outages_m: Option<f64>,
    /// Path - truth over every row, RMS (m).
    pub path_all_m: f64,
}

impl SimulatedRide {
    /// True position of every row in the local frame of `signals`.
    pub fn truth_in(&self, frame: &LocalFrame) -> Vec<Vector3<f64>> {
        let sim = LocalFrame::new(self.origin);
        self.truth_enu
            .iter()
            .map(|p| frame.to_enu(&sim.to_geodetic(p)))
            .collect()
    }

    /// Compare a reconstructed path (one position per row, in `frame`) with the truth.
    pub fn errors(&self, signals: &crate::signals::Signals, path: &[Vector3<f64>]) -> TruthErrors {
        let truth = self.truth_in(&signals.frame);
        let h = |a: &Vector3<f64>, b: &Vector3<f64>| (a.x - b.x).powi(2) + (a.y - b.y).powi(2);
        let rms = |s: f64, n: usize| (s / n.max(1) as f64).sqrt();
        let (mut at_fix, mut fixes) = (0.0, 0.0);
        for f in &signals.fixes {
            at_fix += h(&path[f.row], &truth[f.row]);
            fixes += (f.en[0] - truth[f.row].x).powi(2) + (f.en[1] - truth[f.row].y).powi(2);
        }
        let (mut out, mut n_out, mut all) = (0.0, 0, 0.0);
        for (j, &t) in signals.t.iter().enumerate() {
            let e = h(&path[j], &truth[j]);
            all += e;
            if self
                .truth
                .gps_outages_s
                .iter()
                .any(|&(a, b)| t >= a && t < b)
            {
                out += e;
                n_out += 1;
            }
        }
        TruthErrors {
            path_at_fixes_m: rms(at_fix, signals.fixes.len()),
            fixes_m: rms(fixes, signals.fixes.len()),
            path_in_outages_m: (n_out > 0).then(|| rms(out, n_out)),
            path_all_m: rms(all, signals.len()),
        }
    }
}
