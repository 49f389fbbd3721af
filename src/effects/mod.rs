//! Physical effects: each one a self-contained piece with its parameters, how
//! it enters the model and its partial derivatives there.
//!
//! The model (see [`crate::model`]) has a few *sites* where an effect can act:
//!
//! | site | what the effect maps | used by |
//! | --- | --- | --- |
//! | gyro | rate `omega_j` (rad/s) of step `j` -> corrected rate | `gyro_bias`, `gyro_bias_segments`, `gyro_bias_channel:<c>`, `gyro_scale`, `gyro_stops` |
//! | distance | odometer distance `d_j` of step `j` -> corrected distance | `speed_lag`, `odometer_gain`, `gnss_gaps` |
//! | forward axis | the vehicle's forward axis in sensor axes, `dir_t = q_t f` | `mount_misalignment` |
//! | start | initial orientation and position | `initial_orientation`, `initial_position` |
//! | observation time | the instant a fix refers to (`t - lag`, path interpolated) | `gps_lag` |
//! | observation target | what a row is compared with (shift of the target) | `baro_offset`, `baro_drift` |
//! | loss | robust loss on the GPS rows | `gps_outliers` |
//! | prior | extra residuals on the parameters | `gyro_bias_segments` (random walk) |
//!
//! An effect implements only the sites it uses; the model chains the effects
//! of a site in registry order and applies the chain rule, so the gradient
//! stays one O(N) backward sweep and the Jacobian one O(N) forward sweep
//! whatever the combination. Adding an effect = one file here plus one line
//! in [`build`].
//!
//! The measurements and the history behind these choices: docs/effects.md
//! (the catalogue, and how to add an effect).

mod baro_drift;
mod baro_offset;
mod gnss_gaps;
mod gps_lag;
mod gps_outliers;
mod gyro_bias;
mod gyro_bias_channel;
mod gyro_bias_segments;
mod gyro_scale;
mod gyro_stops;
mod initial_orientation;
mod initial_position;
pub mod mount_misalignment;
mod odometer_gain;
mod speed_lag;

pub use baro_drift::BaroDrift;
pub use baro_offset::BaroOffset;
pub use gnss_gaps::GnssGaps;
pub use gps_lag::GpsLag;
pub use gps_outliers::GpsOutliers;
pub use gyro_bias::DEG_PER_RAD;
pub use gyro_bias::GyroBias;
pub use gyro_bias_channel::GyroBiasChannel;
pub use gyro_bias_segments::GyroBiasSegments;
pub use gyro_scale::GyroScale;
pub use gyro_stops::GyroStops;
pub use initial_orientation::InitialOrientation;
pub use initial_position::InitialPosition;
pub use mount_misalignment::MountMisalignment;
pub use odometer_gain::OdometerGain;
pub use speed_lag::SpeedLag;

pub use crate::contract::{
    Columns, DistancePartials, Effect, GyroPartials, ParamInfo, PriorRows, Role, TargetSite,
    plus_minus,
};
use crate::contract::{ModelError, ModelSpec, StartGuess};
use crate::signals::Signals;

/// The error for an id that is no effect, listing those that are.
fn unknown(id: &str) -> ModelError {
    ModelError::UnknownEffect {
        id: id.to_string(),
        known: REGISTRY.join(", "),
    }
}

/// Effect ids of the paper's model (`paper` on the command line).
pub const PAPER: [&str; 5] = [
    "initial_position",
    "initial_orientation",
    "odometer_gain",
    "gyro_bias",
    "gyro_bias_segments",
];

/// Expand a list of ids (`paper` stands for the paper's five) into effect ids
/// in registry order, without duplicates. `-id` takes an effect out again
/// (`paper,-odometer_gain`: the paper's model with the odometer taken as
/// calibrated). `baro_offset` is added whenever the log has a barometer,
/// `gnss_gaps` whenever the distance is the GNSS speed's and it has gaps
/// (`-gnss_gaps` takes it out), and `gyro_stops` whenever the gyro stopped
/// answering somewhere (`-gyro_stops`).
pub fn expand(list: &[String], signals: &Signals) -> Result<Vec<String>, ModelError> {
    let mut ids: Vec<String> = Vec::new();
    let mut removed: Vec<String> = Vec::new();
    for item in list {
        for part in item.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (target, name) = match part.strip_prefix('-') {
                Some(name) => (&mut removed, name.trim()),
                None => (&mut ids, part),
            };
            if name == "paper" {
                target.extend(PAPER.iter().map(|s| s.to_string()));
            } else if known(name) {
                target.push(name.to_string());
            } else {
                return Err(unknown(name));
            }
        }
    }
    if GnssGaps::applies(signals) {
        ids.push("gnss_gaps".into());
    }
    if GyroStops::applies(signals) {
        ids.push("gyro_stops".into());
    }
    ids.retain(|id| !removed.contains(id));
    if signals.has_baro {
        ids.push("baro_offset".into());
    }
    let order = |id: &str| registry_position(id).unwrap_or(usize::MAX);
    ids.sort_by_key(|id| order(id));
    ids.dedup();
    Ok(ids)
}

/// All ids in registry order (the order effects are chained in).
pub const REGISTRY: [&str; 15] = [
    "initial_position",
    "initial_orientation",
    "speed_lag",
    "odometer_gain",
    "gnss_gaps",
    "gyro_bias",
    "gyro_bias_segments",
    CHANNEL_PREFIX,
    "gyro_scale",
    "gyro_stops",
    "mount_misalignment",
    "gps_lag",
    "baro_offset",
    "baro_drift",
    "gps_outliers",
];

/// Effects a user can add to the paper's model, with one line on what each
/// models; `gyro_bias_channel:<c>` once per extra channel of the log.
pub fn catalogue(channels: &[String]) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = CATALOGUE
        .iter()
        .filter(|(id, _)| known(id))
        .map(|(id, about)| (id.to_string(), about.to_string()))
        .collect();
    for c in channels {
        out.push((
            format!("{CHANNEL_PREFIX}{c}"),
            format!("gyro bias linear in the log's {c} channel (3 per-axis slopes)"),
        ));
    }
    out
}

/// The catalogue's effects that `signals` can take: `speed_lag` only where
/// the distance is the GNSS speed's, the barometer's only with a barometer
/// (what the app's Effects panel lists).
pub fn offered(signals: &Signals) -> Vec<(String, String)> {
    let channels: Vec<String> = signals.channels.iter().map(|(n, _)| n.clone()).collect();
    catalogue(&channels)
        .into_iter()
        .filter(|(id, _)| match id.as_str() {
            "speed_lag" => SpeedLag::applies(signals),
            "baro_drift" => signals.has_baro,
            _ => true,
        })
        .collect()
}

/// Prefix of the per-channel bias effect ids.
pub const CHANNEL_PREFIX: &str = "gyro_bias_channel:";

/// The effect catalogue: ids and what they model.
const CATALOGUE: [(&str, &str); 6] = [
    ("gyro_scale", "per-axis gyro scale-factor error (3)"),
    (
        "gps_lag",
        "GPS fixes refer to an earlier instant than their row time (1, s)",
    ),
    (
        "mount_misalignment",
        "sensor axes rotated from the vehicle's forward axis (2: yaw and pitch of the forward axis)",
    ),
    (
        "baro_drift",
        "barometric altitude drifting linearly in time (1, m/h)",
    ),
    (
        "gps_outliers",
        "robust (Cauchy) loss that stops multipath jumps bending the path",
    ),
    (
        "speed_lag",
        "the GNSS speed that gives the distance lags the gyro (1, s; rides without a wheel sensor)",
    ),
];

/// Place of an id in [`REGISTRY`] (`gyro_bias_channel:<c>` at its prefix).
fn registry_position(id: &str) -> Option<usize> {
    REGISTRY
        .iter()
        .position(|r| *r == id || (*r == CHANNEL_PREFIX && id.len() > r.len() && id.starts_with(r)))
}

fn known(id: &str) -> bool {
    registry_position(id).is_some()
}

/// Build one effect by id.
pub fn build(
    id: &str,
    signals: &Signals,
    spec: &ModelSpec,
    start: &StartGuess,
) -> Result<Box<dyn Effect>, ModelError> {
    Ok(match id {
        "initial_position" => Box::new(InitialPosition),
        "initial_orientation" => Box::new(InitialOrientation {
            planar: signals.attitude.is_planar(),
        }),
        "odometer_gain" => Box::new(OdometerGain),
        "speed_lag" => Box::new(SpeedLag::new(signals)?),
        "gnss_gaps" => Box::new(GnssGaps::new(signals)?),
        "gyro_stops" => Box::new(GyroStops::new(signals)?),
        "gyro_bias" => Box::new(GyroBias::new(start, signals.attitude.is_planar())),
        "gyro_bias_segments" => Box::new(GyroBiasSegments::new(
            signals,
            spec.segment_s,
            spec.bias_walk_dps_sqrt_s,
        )?),
        "baro_offset" | "baro_drift" => {
            if !signals.has_baro {
                return Err(ModelError::NotApplicable {
                    effect: id.into(),
                    reason: "the log has no baro_alt_m column".into(),
                });
            }
            if id == "baro_offset" {
                Box::new(BaroOffset)
            } else {
                Box::new(BaroDrift)
            }
        }
        "gyro_scale" => Box::new(GyroScale {
            planar: signals.attitude.is_planar(),
        }),
        "mount_misalignment" => Box::new(MountMisalignment),
        "gps_lag" => Box::new(GpsLag),
        "gps_outliers" => Box::new(GpsOutliers::new(signals, spec.sigma_horizontal_m)),
        channel if channel.starts_with(CHANNEL_PREFIX) => Box::new(GyroBiasChannel::new(
            signals,
            &channel[CHANNEL_PREFIX.len()..],
        )?),
        other => return Err(unknown(other)),
    })
}

/// Effects added by themselves where the data have what they model.
pub const COMES_WITH_THE_DATA: [&str; 3] = ["baro_offset", "gnss_gaps", "gyro_stops"];

/// A model's effect list ("initial_position, ..., gps_lag") with the
/// paper's five said once: "paper + gps_lag" (a barometer's offset, the
/// GNSS gaps' distances and the gyro stops' turns, which come with the
/// data, are left out); other
/// lists as they are.
pub fn short_model(model: &str) -> String {
    let ids: Vec<&str> = model.split(", ").collect();
    if PAPER.iter().all(|p| ids.contains(p)) {
        let extra: Vec<&str> = ids
            .into_iter()
            .filter(|i| !PAPER.contains(i) && !COMES_WITH_THE_DATA.contains(i))
            .collect();
        if extra.is_empty() {
            "paper".to_string()
        } else {
            format!("paper + {}", extra.join(" + "))
        }
    } else {
        model.to_string()
    }
}

#[cfg(test)]
pub(crate) mod testing {
    //! Finite-difference checks shared by the effect tests.
    use super::*;
    use nalgebra::Vector3;

    /// Check that the batch forms agree with the per-step forms over `n` steps.
    pub fn check_batches(effect: &dyn Effect, p: &[f64], n: usize) {
        let rates: Vec<Vector3<f64>> = (0..n)
            .map(|j| Vector3::new(0.1, -0.2, 0.3) * (j as f64 * 0.01).sin())
            .collect();
        let mut batch = rates.clone();
        effect.gyro_batch(p, 0, &mut batch);
        // A run that starts later (a chunk of the parallel sweep) gives the same rows.
        let from = n / 3;
        let mut tail = rates[from..].to_vec();
        effect.gyro_batch(p, from, &mut tail);
        for (k, w) in tail.iter().enumerate() {
            assert!(
                (w - batch[from + k]).norm() < 1e-15,
                "batch from {from} at {k}"
            );
        }
        let mut grad: Vec<Vector3<f64>> = (0..n)
            .map(|j| Vector3::new(1.0, 2.0, -1.0) * (j as f64 * 0.03).cos())
            .collect();
        let mut gp = vec![0.0; p.len()];
        let mut gp_ref = vec![0.0; p.len()];
        let grad_ref: Vec<Vector3<f64>> = grad
            .iter()
            .enumerate()
            .map(|(j, g)| {
                if j == 0 {
                    return *g;
                }
                let part = effect.gyro_partials(p, j, &rates[j]);
                for &(c, col) in part.params.as_slice() {
                    gp_ref[c] += col.dot(g);
                }
                part.d_in.transpose() * g
            })
            .collect();
        effect.gyro_backward(p, &rates, &mut grad, &mut gp);
        for j in 1..n {
            assert!(
                (batch[j] - effect.gyro(p, j, rates[j])).norm() < 1e-12,
                "batch forward at {j}"
            );
            assert!(
                (grad[j] - grad_ref[j]).norm() < 1e-9,
                "batch backward at {j}"
            );
        }
        for (a, b) in gp.iter().zip(&gp_ref) {
            assert!(
                (a - b).abs() < 1e-9 * (1.0 + b.abs()),
                "parameter gradient {a} vs {b}"
            );
        }
    }

    /// Check `gyro_partials` of `effect` against central differences at step `j`.
    pub fn check_gyro_partials(effect: &dyn Effect, p: &[f64], j: usize, omega: Vector3<f64>) {
        let part = effect.gyro_partials(p, j, &omega);
        let h = 1e-6;
        for a in 0..3 {
            let mut d = Vector3::zeros();
            d[a] = h;
            let fd = (effect.gyro(p, j, omega + d) - effect.gyro(p, j, omega - d)) / (2.0 * h);
            assert!((fd - part.d_in.column(a)).norm() < 1e-7, "d_in column {a}");
        }
        let mut dense = vec![Vector3::zeros(); p.len()];
        for &(i, v) in part.params.as_slice() {
            dense[i] += v;
        }
        for (i, col) in dense.iter().enumerate() {
            let (mut pp, mut pm) = (p.to_vec(), p.to_vec());
            pp[i] += h;
            pm[i] -= h;
            let fd = (effect.gyro(&pp, j, omega) - effect.gyro(&pm, j, omega)) / (2.0 * h);
            assert!((fd - col).norm() < 1e-7, "param {i}: fd {fd} vs {col}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn a_sigma_as_wide_as_the_physical_range_reads_not_determined() {
        let yaw = ParamInfo::new("forward_yaw", "deg", DEG_PER_RAD).within(FRAC_PI_2);
        // A planar robot's mounting yaw: 84,191 deg of sigma is no measurement.
        let sigma = 84191.0 / DEG_PER_RAD;
        assert!(!yaw.determined(sigma));
        assert!(!yaw.determined(f64::NAN));
        assert!(yaw.determined(2.0 / DEG_PER_RAD));
        assert_eq!(
            plus_minus(0.001, Some((84191.0, yaw.determined(sigma))), "deg", 3),
            "0.001 deg (not determined by this ride)"
        );
        assert_eq!(
            plus_minus(1.5, Some((0.25, true)), "deg", 3),
            "1.500 ± 0.250 deg"
        );
        // No unit, no trailing space; no sigma, the value alone.
        assert_eq!(
            plus_minus(0.97677, Some((0.00083, true)), "", 5),
            "0.97677 ± 0.00083"
        );
        assert_eq!(plus_minus(2.0, None, "m", 1), "2.0 m");
        // Unbounded parameters are always shown with their sigma.
        assert!(ParamInfo::new("start_east", "m", 1.0).determined(1e6));
    }

    #[test]
    fn a_listed_effect_can_be_taken_out_again() {
        let sig = crate::testing::simulated_signals(3, 60.0, &[]);
        let list = |s: &str| vec![s.to_string()];
        let ids = expand(&list("paper,gps_lag,-odometer_gain"), &sig).unwrap();
        assert!(ids.contains(&"gps_lag".to_string()));
        assert!(!ids.contains(&"odometer_gain".to_string()));
        // The paper's five, less the gain, plus the lag and the barometer's offset.
        assert_eq!(ids.len(), 6, "{ids:?}");
        assert!(matches!(
            expand(&list("paper,-warp_drive"), &sig),
            Err(ModelError::UnknownEffect { id: e, .. }) if e == "warp_drive"
        ));
    }
}
