//! gyropath: reconstruct a vehicle's path from a MEMS gyroscope, a wheel
//! odometer and 1 Hz GPS by estimating the gyro bias from the GPS (Engedy &
//! Horvath, "Path Reconstruction based on Gyroscope Bias Estimation using GPS").
//!
//! Module map, in data-flow order:
//! - [`import`]: every input (ride-log CSV, ROS 1 bag, ROS 2 MCAP, mapped CSV) into raw columns, with
//!   errors naming file, line and column or topic; axes, units and datum checked against the data.
//! - [`blunders`]: GPS fixes that cannot belong to the ride (`0, 0`, kilometres off), left out.
//! - [`signals`]: what is derived once: time steps, rad/s, distance per step, fixes in ENU.
//! - [`geodesy`]: WGS84 <-> local east/north/up.
//! - [`effects`]: one module per physical effect (parameters, where it acts, derivatives).
//! - [`model`]: the path equations, residuals, cost, O(N) gradient and Jacobian.
//! - [`optimisation`]: step 1 (globals, LM) and step 2 (segment biases, GD or LM), one iteration at a time.
//! - [`diagnosis`]: residuals along/across the track, bias per segment, held-out error.
//! - [`export`]: reconstructed path CSV and JSON report.
//! - [`report`]: the self-contained HTML report of a fit (and a batch's index page).
//! - `app` (feature `app`, on by default): the eframe desktop app; draws what the core computes.
//! - [`simulation`]: a bicycle-ride simulator with its own physics, for tests and sample data.
//! - [`standing`]: stands inside GNSS-speed gaps, told by the gyro's shaking.
//! - [`statistics`]: order statistics (the median) that the modules above share.

// Index loops over rows and axes read like the equations they implement.
#![allow(clippy::needless_range_loop)]

#[cfg(feature = "app")]
pub mod app;
pub mod blunders;
pub mod contract;
pub mod diagnosis;
pub mod effects;
pub mod explain;
pub mod export;
pub mod geodesy;
pub mod gyro_stops;
pub mod import;
pub mod limits;
pub mod log_gaps;
pub mod model;
pub mod odometer_jumps;
pub mod optimisation;
pub mod pipeline;
pub mod report;
pub mod reversing;
pub mod ride;
pub mod rotation;
pub mod sensor_turns;
pub mod signals;
pub mod simulation;
pub mod standing;
pub mod statistics;
pub mod suspect_fixes;

#[cfg(test)]
pub(crate) mod testing;
