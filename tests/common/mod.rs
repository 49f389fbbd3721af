//! Shared helpers for the integration tests.
#![allow(dead_code)]

use std::sync::Arc;

use gyropath::import::parse;
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, SimulatedRide, simulate};

/// A simulated ride and its signals.
pub fn ride(seed: u64, duration_s: f64, hidden: &[&str]) -> (SimulatedRide, Arc<Signals>) {
    let sim = simulate(&SimConfig {
        seed,
        duration_s,
        hidden: hidden.iter().map(|s| s.to_string()).collect(),
        ..SimConfig::default()
    })
    .expect("simulate");
    let sig = Signals::from_log(&parse(sim.log_csv.as_bytes(), "sim.csv").expect("parse"))
        .expect("signals");
    (sim, Arc::new(sig))
}

/// A ride log of `fit`'s own track between `from` and `to` (s into the
/// activity): 100 Hz rows whose yaw rate is the track's turn (its course
/// from one point to the next, differenced), fixes at its points, no
/// odometer but the GNSS speed (the distance between points over their
/// time), and `t0_unix_s` as the activity's clock says, shifted by
/// `clock_s`: what a camera on the bike would have logged, for the FIT's
/// wheel distance to be matched to.
pub fn ride_along(
    fit: &gyropath::import::fit::Activity,
    from: f64,
    to: f64,
    clock_s: f64,
) -> String {
    let track = &fit.track;
    let t0 = track.t_s[0] + from;
    let pts: Vec<(f64, f64, f64)> = track
        .t_s
        .iter()
        .zip(&track.points)
        .filter(|(t, _)| (t0..=track.t_s[0] + to).contains(*t))
        .map(|(t, p)| (t - t0, p.lat_deg, p.lon_deg))
        .collect();
    // Course (rad, clockwise from north) between consecutive points, unwrapped.
    let mut course: Vec<(f64, f64)> = Vec::new();
    for w in pts.windows(2) {
        let (de, dn) = (
            (w[1].2 - w[0].2).to_radians() * 6_371_000.0 * w[0].1.to_radians().cos(),
            (w[1].1 - w[0].1).to_radians() * 6_371_000.0,
        );
        let mut c = de.atan2(dn);
        if let Some(&(_, last)) = course.last() {
            while c - last > std::f64::consts::PI {
                c -= 2.0 * std::f64::consts::PI;
            }
            while c - last < -std::f64::consts::PI {
                c += 2.0 * std::f64::consts::PI;
            }
        }
        course.push((0.5 * (w[0].0 + w[1].0), c));
    }
    let yaw_dps = |t: f64| {
        let i = course
            .partition_point(|c| c.0 < t)
            .clamp(1, course.len() - 1);
        let (a, b) = (course[i - 1], course[i]);
        -(b.1 - a.1).to_degrees() / (b.0 - a.0)
    };
    let mut csv = format!(
        "# t0_unix_s: {:.3}\nt_s,gx_dps,gy_dps,gz_dps,lat_deg,lon_deg,gps_speed_mps\n",
        t0 + clock_s
    );
    let end = pts.last().expect("points").0;
    let mut k = 0;
    for j in 0..=(end * 100.0).round() as usize {
        let t = j as f64 * 0.01;
        let fix = match pts.get(k) {
            Some(p) if (p.0 - t).abs() < 0.005 => {
                k += 1;
                let speed = pts.get(k).map_or(0.0, |q| {
                    let (de, dn) = (
                        (q.2 - p.2).to_radians() * 6_371_000.0 * p.1.to_radians().cos(),
                        (q.1 - p.1).to_radians() * 6_371_000.0,
                    );
                    de.hypot(dn) / (q.0 - p.0)
                });
                format!("{:.7},{:.7},{speed:.3}", p.1, p.2)
            }
            _ => ",,".into(),
        };
        csv.push_str(&format!("{t:.2},0,0,{:.4},{fix}\n", yaw_dps(t)));
    }
    csv
}
