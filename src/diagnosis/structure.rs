//! Structure left in the residuals and in the fitted segment biases, against
//! the signals a missing effect would follow.
//!
//! A model that lacks an effect leaves residual that is not noise: it follows
//! something. Pearson correlations (`r` in -1..1) of
//!
//! - the along-track, cross-track and vertical residuals at the GPS fixes, and
//! - the fitted total bias of every segment (x, y, z axes)
//!
//! with speed, turn rate, accumulated heading change, lean, time and every
//! extra channel of the log point at the culprit: along-track residual with
//! speed says GPS latency; cross-track residual or the yaw bias with turn rate
//! says scale factor; a segment bias with temperature says temperature-dependent bias.
//!
//! Segment biases are compared by their changes from one segment to the next
//! (`b_{k+1} - b_k` against the change of the signal's segment mean). Their
//! levels follow a random walk, and a random walk correlates with any slowly
//! trending signal (time, accumulated heading, a cooling temperature) at
//! |r| 0.7-0.97 on rides with nothing missing: a spurious regression. Its
//! increments are white, so only a bias that really moves with the signal
//! (`b = c T + walk` gives `Delta b = c Delta T + white`) correlates. Time has
//! constant increments and drops out of the bias comparison.
//!
//! An axis whose segment biases barely move (increments under
//! [`STILL_BIAS_DPS`] RMS) is left out: Pearson's `r` is blind to scale, and
//! on the comma drive the roll axis, held by its prior and varying by 1e-4
//! deg/s, "followed" the speed at r = -0.62.

use nalgebra::Vector3;

use super::{SegmentBias, fix_residuals, segment_biases};
use crate::model::{Model, Trajectory};

/// One correlation.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Correlation {
    /// What was correlated: `along`, `cross`, `vertical`, `bias_x`, `bias_y`, `bias_z`.
    pub quantity: String,
    /// Against which signal.
    pub signal: String,
    pub r: f64,
    /// Number of samples (fixes or segments).
    pub n: usize,
}

impl Correlation {
    /// Whether `|r|` reaches `2 / sqrt(n)`, about where an uncorrelated pair
    /// of `n` samples lands 5 % of the time: below it the pair says nothing.
    pub fn beyond_chance(&self) -> bool {
        self.r.abs() * (self.n as f64).sqrt() >= 2.0
    }
}

pub use crate::statistics::pearson;

/// Segment-to-segment bias changes (deg/s, RMS) below which an axis has no
/// structure to show: 0.001 deg/s moves the heading by 0.005 deg over a 5 s
/// segment, far under anything a gyro or the fixes resolve.
pub const STILL_BIAS_DPS: f64 = 1e-3;

/// `x_{k+1} - x_k`.
fn increments(x: &[f64]) -> Vec<f64> {
    x.windows(2).map(|w| w[1] - w[0]).collect()
}

/// The segment biases' increments per axis (`bias_x`, ...), leaving out
/// the axes that stand still (see [`STILL_BIAS_DPS`]).
fn moving_bias_increments(segs: &[SegmentBias]) -> Vec<(&'static str, Vec<f64>)> {
    ["bias_x", "bias_y", "bias_z"]
        .into_iter()
        .enumerate()
        .map(|(axis, q)| {
            let y: Vec<f64> = segs.iter().map(|s| s.bias_dps[axis]).collect();
            (q, increments(&y))
        })
        .filter(|(_, dy)| {
            let ms = dy.iter().map(|d| d * d).sum::<f64>() / dy.len().max(1) as f64;
            ms.sqrt() >= STILL_BIAS_DPS
        })
        .collect()
}

/// Per-row motion signals of the fitted path: speed (m/s), turn rate
/// (deg/s about world up), accumulated heading change (deg), lean (deg).
fn motion(model: &Model, traj: &Trajectory) -> Vec<(String, Vec<f64>)> {
    let sig = &model.signals;
    let n = sig.len();
    let (mut speed, mut turn, mut heading, mut lean) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut acc = 0.0;
    for j in 1..n {
        let dt = sig.dt[j];
        if dt > 0.0 {
            speed[j] = traj.d[j] / dt;
            // World rotation of the step about up, per second.
            let w = traj.q[j] * traj.theta[j];
            turn[j] = w.z.to_degrees() / dt;
            acc += w.z.abs().to_degrees();
        }
        heading[j] = acc;
        // Lean: elevation of the sensor's y axis above the horizontal.
        let y = traj.q[j] * Vector3::y();
        lean[j] = y.z.clamp(-1.0, 1.0).asin().to_degrees();
    }
    let mut out = vec![
        ("speed".to_string(), speed),
        ("turn_rate".to_string(), turn),
        ("heading_change".to_string(), heading),
        ("lean".to_string(), lean),
        ("time".to_string(), sig.t.clone()),
    ];
    for (name, v) in &sig.channels {
        out.push((name.clone(), v.clone()));
    }
    out
}

/// Correlations of residuals and segment biases with the candidate signals,
/// strongest first.
pub fn structure(model: &Model, theta: &[f64]) -> Vec<Correlation> {
    let sig = &model.signals;
    let traj = model.trajectory(theta);
    let res = fix_residuals(model, theta, &traj);
    let signals = motion(model, &traj);
    let mut out = Vec::new();
    let rows: Vec<usize> = res.iter().map(|r| r.row).collect();
    let mut quantities: Vec<(&str, Vec<f64>)> = vec![
        ("along", res.iter().map(|r| r.along).collect()),
        ("cross", res.iter().map(|r| r.cross).collect()),
    ];
    let (up_rows, up): (Vec<usize>, Vec<f64>) =
        res.iter().filter_map(|r| r.up.map(|u| (r.row, u))).unzip();
    for (name, values) in &signals {
        for (q, v) in &quantities {
            let x: Vec<f64> = rows.iter().map(|&j| values[j]).collect();
            if let Some(r) = pearson(&x, v) {
                out.push(Correlation {
                    quantity: q.to_string(),
                    signal: name.clone(),
                    r,
                    n: v.len(),
                });
            }
        }
        let x: Vec<f64> = up_rows.iter().map(|&j| values[j]).collect();
        if let Some(r) = pearson(&x, &up) {
            out.push(Correlation {
                quantity: "vertical".into(),
                signal: name.clone(),
                r,
                n: up.len(),
            });
        }
    }
    quantities.clear();
    // Segment biases against the segment means of each signal.
    let segs = segment_biases(model, theta);
    if segs.len() >= 3 {
        let bounds: Vec<(usize, usize)> = segs
            .iter()
            .map(|s| {
                let a = sig.t.partition_point(|&t| t < s.t0);
                let b = sig
                    .t
                    .partition_point(|&t| t < s.t1)
                    .max(a + 1)
                    .min(sig.len());
                (a.min(sig.len() - 1), b)
            })
            .collect();
        let bias_increments = moving_bias_increments(&segs);
        // Time advances by the segment length each segment: nothing to compare.
        for (name, values) in signals.iter().filter(|(name, _)| name != "time") {
            let x: Vec<f64> = bounds
                .iter()
                .map(|&(a, b)| values[a..b].iter().sum::<f64>() / (b - a) as f64)
                .collect();
            let dx = increments(&x);
            for (q, dy) in &bias_increments {
                if let Some(r) = pearson(&dx, dy) {
                    out.push(Correlation {
                        quantity: q.to_string(),
                        signal: name.clone(),
                        r,
                        n: segs.len(),
                    });
                }
            }
        }
    }
    out.sort_by(|a, b| b.r.abs().total_cmp(&a.r.abs()));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optimisation::{FitSettings, Reconstruction};
    use std::sync::Arc;

    /// An axis whose biases move by 1e-4 deg/s between segments has nothing
    /// to correlate; one that moves by 0.01 deg/s has.
    #[test]
    fn still_bias_axes_are_left_out() {
        let segs: Vec<SegmentBias> = (0..6)
            .map(|k| SegmentBias {
                t0: 5.0 * k as f64,
                t1: 5.0 * (k + 1) as f64,
                bias_dps: [
                    -0.62 + 1e-4 * (k % 2) as f64,
                    2.03 + 0.01 * k as f64,
                    -3.9 + 0.02 * (k % 3) as f64,
                ],
            })
            .collect();
        let kept: Vec<&str> = moving_bias_increments(&segs)
            .iter()
            .map(|(q, _)| *q)
            .collect();
        assert_eq!(kept, ["bias_y", "bias_z"]);
    }

    /// 2 / sqrt(n): r = 0.3 over 60 fixes is beyond chance, over 30 it is not.
    #[test]
    fn beyond_chance_scales_with_the_samples() {
        let c = |r: f64, n: usize| Correlation {
            quantity: "along".into(),
            signal: "speed".into(),
            r,
            n,
        };
        assert!(c(0.3, 60).beyond_chance());
        assert!(c(-0.3, 60).beyond_chance());
        assert!(!c(0.3, 30).beyond_chance());
        assert!(!c(0.09, 60).beyond_chance());
    }

    #[test]
    fn pearson_of_known_series() {
        let x = [1.0, 2.0, 3.0, 4.0];
        assert!((pearson(&x, &[2.0, 4.0, 6.0, 8.0]).unwrap_or(0.0) - 1.0).abs() < 1e-12);
        assert!((pearson(&x, &[8.0, 6.0, 4.0, 2.0]).unwrap_or(0.0) + 1.0).abs() < 1e-12);
        assert_eq!(pearson(&x, &[1.0, 1.0, 1.0, 1.0]), None);
    }

    /// A random walk of the segment biases no longer looks like structure:
    /// compared by level, the biases of a ride with nothing missing followed
    /// time or accumulated heading at |r| 0.7-0.97; by increments they stay
    /// below 0.6 (about 0.2-0.4 here: stops and starts move both the
    /// temperature and the fitted biases a little). A temperature-driven bias
    /// still shows.
    #[test]
    fn segment_biases_are_compared_by_increments() {
        let fitted = |hidden: &[&str]| {
            let sig = Arc::new(crate::testing::simulated_signals(8, 900.0, hidden));
            let mut fit = Reconstruction::new(sig, FitSettings::default()).expect("fit");
            fit.finish();
            structure(fit.model(), fit.params())
        };
        let plain = fitted(&[]);
        assert!(
            !plain
                .iter()
                .any(|c| c.quantity.starts_with("bias") && c.signal == "time")
        );
        for c in plain.iter().filter(|c| c.quantity.starts_with("bias")) {
            assert!(c.r.abs() < 0.6, "{c:?}");
        }
        let temp = fitted(&["gyro_bias_channel:temp_c"]);
        let temp_z = temp
            .iter()
            .find(|c| c.quantity == "bias_z" && c.signal == "temp_c")
            .expect("bias_z vs temp_c");
        assert!(temp_z.r.abs() > 0.35, "{temp_z:?}");
    }
}
