//! A gyro that stops answering for a while (a logger writing zeros, or its
//! last reading, when its IMU does not answer) on simulated rides with
//! known truth: the stop is found, the turn across it fitted
//! (`gyro_stops`), and the path ends near the one the whole gyro gives;
//! without the effect it does not.

mod common;

use std::sync::Arc;

use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Signals;

/// The path's horizontal RMS from the truth over every row, fitted with
/// `extra` effects ids added to the default model.
fn fitted(sim: &gyropath::simulation::SimulatedRide, sig: &Arc<Signals>, extra: &[&str]) -> f64 {
    let mut settings = FitSettings::default();
    settings
        .model
        .effects
        .extend(extra.iter().map(|s| s.to_string()));
    let mut fit = Reconstruction::new(sig.clone(), settings).expect("fit");
    fit.finish();
    sim.errors(sig, &fit.trajectory().p).path_all_m
}

#[test]
fn a_stop_in_a_bend_is_bridged_by_a_fitted_turn() {
    for seed in [1, 2, 3] {
        let (sim, whole) = common::ride(seed, 600.0, &[]);
        let mut log = parse(sim.log_csv.as_bytes(), "sim.csv").expect("parse");
        // The 15 s in which the vehicle turns most, away from the ride's
        // ends and its GPS outages (a stop inside an outage is a turn that
        // only the fixes after the outage tell).
        let n = log.len();
        let outages = &sim.truth.gps_outages_s;
        let clear = |a: usize, b: usize| {
            let (ta, tb) = (log.t_s[a] - 10.0, log.t_s[b] + 15.0);
            outages.iter().all(|&(x, y)| y < ta || x > tb)
        };
        let turn_over = |a: usize, b: usize| -> f64 {
            (a + 1..b)
                .map(|j| log.gyro_dps[j][2] * (log.t_s[j] - log.t_s[j - 1]))
                .sum()
        };
        let width = log.t_s.partition_point(|&t| t < 15.0);
        let (first, turned) = (n / 10..n - n / 10 - width)
            .step_by(50)
            .filter(|&a| clear(a, a + width))
            .map(|a| (a, turn_over(a, a + width)))
            .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
            .expect("a window");
        for g in &mut log.gyro_dps[first..first + width] {
            *g = [0.0; 3];
        }
        let stopped = Arc::new(Signals::from_log(&log).expect("signals"));
        assert_eq!(stopped.gyro_stops.len(), 1, "seed {seed}");

        let clean = fitted(&sim, &whole, &[]);
        let bridged = fitted(&sim, &stopped, &[]);
        let without = fitted(&sim, &stopped, &["-gyro_stops"]);
        eprintln!(
            "seed {seed}: {turned:.0} deg in the stop at t = {:.0} s; path from the truth: whole gyro {clean:.2} m, stopped and bridged {bridged:.2} m, without the turn {without:.2} m",
            log.t_s[first]
        );
        assert!(turned.abs() > 45.0, "seed {seed}: {turned} deg");
        assert!(
            bridged < 1.5 * clean + 0.5,
            "seed {seed}: {bridged} m vs {clean} m"
        );
        assert!(bridged < without, "seed {seed}: {bridged} m vs {without} m");
    }
}
