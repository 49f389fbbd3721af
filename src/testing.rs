//! Small synthetic rides for unit tests (the simulator makes the realistic ones).

use crate::import::RideLog;
use crate::signals::Signals;
use std::collections::BTreeMap;

/// A winding, climbing ride at `rate_hz` for `duration` seconds, with a
/// barometer, GPS altitude, a temperature channel and 1 Hz fixes.
pub fn winding_log(duration: f64, rate_hz: f64) -> RideLog {
    let n = (duration * rate_hz) as usize + 1;
    let mut log = RideLog {
        source: "synthetic.csv".into(),
        metadata: BTreeMap::new(),
        odo_m: Some(Vec::new()),
        gps_alt_m: Some(Vec::new()),
        baro_alt_m: Some(Vec::new()),
        channels: vec![("temp_c".into(), Vec::new())],
        ..RideLog::default()
    };
    let (mut e, mut nn, mut u, mut s) = (0.0, 0.0, 0.0, 0.0);
    let mut psi: f64 = 0.3;
    let lat0: f64 = 47.5;
    let m_per_deg_lat = 111_200.0;
    let m_per_deg_lon = m_per_deg_lat * lat0.to_radians().cos();
    for i in 0..n {
        let t = i as f64 / rate_hz;
        let v = 5.0 + (0.05 * t).sin();
        let yaw_rate = 0.25 * (0.13 * t).sin() + 0.05;
        let pitch = 0.03 * (0.02 * t).sin();
        if i > 0 {
            let dt = 1.0 / rate_hz;
            psi += yaw_rate * dt;
            let ds = v * dt;
            e += ds * pitch.cos() * psi.cos();
            nn += ds * pitch.cos() * psi.sin();
            u += ds * pitch.sin();
            s += ds;
        }
        log.line.push(i as u64 + 2);
        log.t_s.push(t);
        let bias = [0.05, -0.1, 0.2];
        log.gyro_dps.push([
            bias[0] + 2.0 * (0.7 * t).sin(),
            bias[1] + 0.6 * (0.011 * t).cos(),
            bias[2] + yaw_rate.to_degrees(),
        ]);
        if let Some(o) = log.odo_m.as_mut() {
            o.push(Some(s * 0.97));
        }
        let fix = (i as f64 / rate_hz).fract() < 0.5 / rate_hz;
        let wobble = 1.5 * (0.31 * t).sin();
        log.fix.push(fix.then(|| {
            (
                lat0 + (nn + wobble) / m_per_deg_lat,
                19.0 + (e - wobble) / m_per_deg_lon,
            )
        }));
        if let Some(a) = log.gps_alt_m.as_mut() {
            a.push(fix.then_some(100.0 + u + 2.0 * (0.2 * t).cos()));
        }
        if let Some(b) = log.baro_alt_m.as_mut() {
            b.push(Some(140.0 + u + 0.1 * (1.3 * t).sin()));
        }
        log.channels[0].1.push(Some(15.0 + t / 100.0));
    }
    log
}

/// Signals of [`winding_log`].
pub fn winding_signals(duration: f64, rate_hz: f64) -> Signals {
    Signals::from_log(&winding_log(duration, rate_hz)).expect("synthetic log is valid")
}

/// Signals of a simulated ride (`hidden`: effect ids of the simulator).
pub fn simulated_signals(seed: u64, duration_s: f64, hidden: &[&str]) -> Signals {
    let sim = simulated(seed, duration_s, hidden);
    Signals::from_log(&crate::import::parse(sim.log_csv.as_bytes(), "sim.csv").expect("parse"))
        .expect("signals")
}

/// The true path of [`simulated_signals`]' ride, as a reference track.
pub fn simulated_truth(
    seed: u64,
    duration_s: f64,
    hidden: &[&str],
) -> crate::import::reference::ReferenceTrack {
    let sim = simulated(seed, duration_s, hidden);
    crate::import::reference::parse_reference(sim.truth_csv.as_bytes(), "truth.csv")
        .expect("the simulator's truth reads")
}

/// A simulated bicycle ride on open sky (`hidden`: effect ids of the simulator).
fn simulated(seed: u64, duration_s: f64, hidden: &[&str]) -> crate::simulation::SimulatedRide {
    crate::simulation::simulate(&crate::simulation::SimConfig {
        seed,
        duration_s,
        hidden: hidden.iter().map(|s| s.to_string()).collect(),
        ..Default::default()
    })
    .expect("simulate")
}
