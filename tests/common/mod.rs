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
