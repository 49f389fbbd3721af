//! Physical effects: each one a self-contained piece with its parameters, how
//! it enters the model and its partial derivatives there.
//!
//! The model (see [`crate::model`]) has a few *sites* where an effect can act:
//!
//! | site | what the effect maps | used by |
//! | --- | --- | --- |
//! | gyro | rate `omega_j` (rad/s) of step `j` -> corrected rate | `gyro_bias`, `gyro_bias_segments`, `gyro_bias_channel:<c>`, `gyro_scale` |
//! | distance | odometer distance `d_j` of step `j` -> corrected distance | `odometer_gain` |
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

mod baro_drift;
mod baro_offset;
mod gps_lag;
mod gps_outliers;
mod gyro_bias;
mod gyro_bias_channel;
mod gyro_bias_segments;
mod gyro_scale;
mod initial_orientation;
mod initial_position;
pub mod mount_misalignment;
mod odometer_gain;

pub use baro_drift::BaroDrift;
pub use baro_offset::BaroOffset;
pub use gps_lag::GpsLag;
pub use gps_outliers::GpsOutliers;
pub use gyro_bias::DEG_PER_RAD;
pub use gyro_bias::GyroBias;
pub use gyro_bias_channel::GyroBiasChannel;
pub use gyro_bias_segments::GyroBiasSegments;
pub use gyro_scale::GyroScale;
pub use initial_orientation::InitialOrientation;
pub use initial_position::InitialPosition;
pub use mount_misalignment::MountMisalignment;
pub use odometer_gain::OdometerGain;

use nalgebra::{Matrix3, Vector3};

use crate::model::{ModelError, ModelSpec, StartGuess};
use crate::signals::Signals;

/// Name, unit and display scale of one parameter (`shown = value * scale`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ParamInfo {
    pub name: String,
    pub unit: &'static str,
    #[serde(skip)]
    pub scale: f64,
    /// A 1-sigma at or above this (internal units) says the ride does not
    /// determine the parameter (see [`Self::within`]); infinite: always shown.
    #[serde(skip)]
    pub range: f64,
}

impl ParamInfo {
    pub fn new(name: impl Into<String>, unit: &'static str, scale: f64) -> Self {
        Self {
            name: name.into(),
            unit,
            scale,
            range: f64::INFINITY,
        }
    }

    /// With the span of values the parameter can physically take: a sigma
    /// as wide as that (an angle known to +-90 degrees, a gain to +-50 %) is
    /// not a measurement but a direction the ride does not see (a planar
    /// robot's mounting yaw, which trades exactly against its start heading),
    /// and is shown as such instead of as a number.
    pub fn within(mut self, range: f64) -> Self {
        self.range = range;
        self
    }

    /// Whether a 1-sigma of `sigma` (internal units) determines the parameter.
    pub fn determined(&self, sigma: f64) -> bool {
        sigma.is_finite() && sigma < self.range
    }
}

/// A value with its 1-sigma for people: "0.97677 ± 0.00083" (then the
/// unit), or "not determined by this ride" when the sigma does not determine
/// it (`sigma`: the 1-sigma and whether it determines the value, see
/// [`ParamInfo::determined`]; `None`: the value alone).
pub fn plus_minus(value: f64, sigma: Option<(f64, bool)>, unit: &str, digits: usize) -> String {
    match sigma {
        Some((_, false)) => format!("{value:.digits$} {unit} (not determined by this ride)"),
        Some((s, true)) => format!("{value:.digits$} ± {s:.digits$} {unit}"),
        None => format!("{value:.digits$} {unit}"),
    }
    .trim_end()
    .to_string()
}

/// Which optimisation step fits an effect's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Fitted in step 1 and refined with the segments in step 2 (LM).
    Global,
    /// Fitted in step 1 only: degenerate with the per-segment parameters.
    Step1Only,
    /// Per-segment parameters, fitted in step 2.
    Segments,
    /// Fitted in step 2 only, with the segments: a parameter that the data
    /// tell apart from the segment biases only through what they cannot
    /// follow, and that a short step-1 window cannot pin (a bias slope on a
    /// channel that hardly varies inside the window is just more constant
    /// bias there, and extrapolates wildly when the window widens).
    Step2Only,
}

/// Up to three parameter columns touched at one step: `(local index, d out / d param)`.
#[derive(Clone, Copy, Debug)]
pub struct Columns<V: Copy> {
    cols: [(usize, V); 3],
    len: usize,
}

impl<V: Copy + Default> Default for Columns<V> {
    fn default() -> Self {
        Self {
            cols: [(0, V::default()); 3],
            len: 0,
        }
    }
}

impl<V: Copy + Default> Columns<V> {
    #[inline]
    pub fn push(&mut self, index: usize, value: V) {
        self.cols[self.len] = (index, value);
        self.len += 1;
    }

    #[inline]
    pub fn as_slice(&self) -> &[(usize, V)] {
        &self.cols[..self.len]
    }

    #[inline]
    pub fn as_mut_slice(&mut self) -> &mut [(usize, V)] {
        &mut self.cols[..self.len]
    }
}

/// Partials of a gyro-site effect at one step: `d omega_out / d omega_in` and
/// the parameter columns `d omega_out / d p`.
#[derive(Clone, Copy, Debug)]
pub struct GyroPartials {
    pub d_in: Matrix3<f64>,
    pub params: Columns<Vector3<f64>>,
}

impl GyroPartials {
    /// `omega_out = omega_in - b`: identity in the input, `-I` in `b` (at `first..first+3`).
    pub fn bias(first: usize) -> Self {
        let mut params = Columns::default();
        for a in 0..3 {
            let mut e = Vector3::zeros();
            e[a] = -1.0;
            params.push(first + a, e);
        }
        Self {
            d_in: Matrix3::identity(),
            params,
        }
    }
}

/// Partials of a distance-site effect at one step.
#[derive(Clone, Copy, Debug)]
pub struct DistancePartials {
    pub d_in: f64,
    pub params: Columns<f64>,
}

/// Sparse rows of prior residuals: values and `(row, local column, value)` entries.
#[derive(Clone, Debug, Default)]
pub struct PriorRows {
    pub residuals: Vec<f64>,
    pub entries: Vec<(usize, usize, f64)>,
}

/// What a target shift may depend on.
#[derive(Clone, Copy, Debug)]
pub struct TargetSite {
    /// Time of the fix (log time, s) and of the start of the ride.
    pub t: f64,
    pub t_start: f64,
    /// Component: 0 east, 1 north, 2 up.
    pub axis: usize,
    /// A barometric row.
    pub baro: bool,
}

/// One physical effect. Default methods mean "does not act at this site".
pub trait Effect: Send + Sync + std::fmt::Debug {
    /// Fixed id used on the command line, in reports and in the app.
    fn id(&self) -> String;
    /// One entry per parameter.
    fn params(&self) -> Vec<ParamInfo>;
    fn n_params(&self) -> usize {
        self.params().len()
    }
    fn role(&self) -> Role {
        Role::Global
    }
    /// Whether local parameter `i` is held at its starting value, never
    /// fitted (the roll and pitch parts of a planar model).
    fn fixed(&self, _i: usize) -> bool {
        false
    }
    /// Starting values, from the guess made before step 1.
    fn initial(&self, guess: &StartGuess) -> Vec<f64>;

    /// Whether the effect acts at the gyro site.
    fn acts_on_gyro(&self) -> bool {
        false
    }
    /// Corrected rate of step `j`.
    fn gyro(&self, _p: &[f64], _j: usize, omega: Vector3<f64>) -> Vector3<f64> {
        omega
    }
    fn gyro_partials(&self, _p: &[f64], _j: usize, _omega: &Vector3<f64>) -> GyroPartials {
        GyroPartials {
            d_in: Matrix3::identity(),
            params: Columns::default(),
        }
    }

    /// [`gyro`](Effect::gyro) over a run of steps at once: `rates[k]` (row
    /// `first + k`) in, corrected out. Override with a tight loop where it
    /// matters: the cost sweep calls it on every chunk of every evaluation.
    fn gyro_batch(&self, p: &[f64], first: usize, rates: &mut [Vector3<f64>]) {
        for (k, w) in rates.iter_mut().enumerate() {
            *w = self.gyro(p, first + k, *w);
        }
    }
    /// Whether [`gyro_backward`](Effect::gyro_backward) reads the input rates
    /// (an additive bias does not, so the gradient need not keep a copy of them).
    fn gyro_backward_reads_input(&self) -> bool {
        true
    }
    /// Back-propagate through the gyro site over every step: `grad[j]` holds
    /// `dC/d omega_out` and becomes `dC/d omega_in`; parameter gradients are added to `grad_p`.
    fn gyro_backward(
        &self,
        p: &[f64],
        omega_in: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        grad_p: &mut [f64],
    ) {
        for (j, g) in grad.iter_mut().enumerate().skip(1) {
            let part = self.gyro_partials(p, j, &omega_in[j]);
            for &(c, col) in part.params.as_slice() {
                grad_p[c] += col.dot(g);
            }
            *g = part.d_in.transpose() * *g;
        }
    }

    fn acts_on_distance(&self) -> bool {
        false
    }
    fn distance(&self, _p: &[f64], _j: usize, d: f64) -> f64 {
        d
    }
    fn distance_partials(&self, _p: &[f64], _j: usize, _d: f64) -> DistancePartials {
        DistancePartials {
            d_in: 1.0,
            params: Columns::default(),
        }
    }

    /// [`distance`](Effect::distance) over a run of steps at once (`d[k]` is row `first + k`).
    fn distance_batch(&self, p: &[f64], first: usize, d: &mut [f64]) {
        for (k, x) in d.iter_mut().enumerate() {
            *x = self.distance(p, first + k, *x);
        }
    }
    /// Back-propagate through the distance site (see [`gyro_backward`](Effect::gyro_backward)).
    fn distance_backward(&self, p: &[f64], d_in: &[f64], grad: &mut [f64], grad_p: &mut [f64]) {
        for (j, g) in grad.iter_mut().enumerate().skip(1) {
            let part = self.distance_partials(p, j, d_in[j]);
            for &(c, v) in part.params.as_slice() {
                grad_p[c] += v * *g;
            }
            *g *= part.d_in;
        }
    }

    /// Rotation vector (world frame) applied on the left of the start attitude guess.
    fn initial_orientation(&self, _p: &[f64]) -> Option<Vector3<f64>> {
        None
    }
    /// Offset (m) added to the start position guess.
    fn initial_position(&self, _p: &[f64]) -> Option<Vector3<f64>> {
        None
    }
    /// Whether barometric rows are observed (the effect that fits the barometer's offset).
    fn observes_baro(&self) -> bool {
        false
    }
    /// Shift of an observation's target, `target' = target + s(p)`, and `d s / d p`.
    fn target_shift(&self, _p: &[f64], _site: &TargetSite) -> Option<(f64, Columns<f64>)> {
        None
    }
    /// The vehicle's forward axis in sensor axes, `f(p)`, and `d f / d p`
    /// (`None`: the sensor's x axis).
    fn forward_axis(&self, _p: &[f64]) -> Option<(Vector3<f64>, Columns<Vector3<f64>>)> {
        None
    }
    /// GPS latency (s): the fix logged at `t` is the position at `t - lag`.
    fn gps_lag(&self, _p: &[f64]) -> Option<f64> {
        None
    }
    /// Scale of a Cauchy loss on the GPS rows, in units of the weighted
    /// residual (`None`: least squares).
    fn robust_scale(&self) -> Option<f64> {
        None
    }

    /// Number of prior residual rows.
    fn n_prior(&self) -> usize {
        0
    }
    /// Prior residuals (already weighted) and their Jacobian entries.
    fn prior(&self, _p: &[f64], _out: &mut PriorRows) {}

    /// Parameters for this effect given another version of it (e.g. the same
    /// effect on a different segment length). `None` if it cannot map them.
    fn carry_over(&self, _other: &dyn Effect, _other_p: &[f64]) -> Option<Vec<f64>> {
        None
    }

    /// First and last step (inclusive) at which local parameter `i` acts, for
    /// parameters that act only on a stretch of the ride (segment biases).
    /// `None`: it acts everywhere. Lets LM build `J^T J` from moments.
    fn param_steps(&self, _i: usize) -> Option<(usize, usize)> {
        None
    }

    /// Extra data for [`carry_over`](Effect::carry_over): segment boundaries (s).
    fn segment_edges(&self) -> Option<&[f64]> {
        None
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
/// calibrated). `baro_offset` is added whenever the log has a barometer.
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
                return Err(ModelError::UnknownEffect(name.to_string()));
            }
        }
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
pub const REGISTRY: [&str; 12] = [
    "initial_position",
    "initial_orientation",
    "odometer_gain",
    "gyro_bias",
    "gyro_bias_segments",
    CHANNEL_PREFIX,
    "gyro_scale",
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

/// Prefix of the per-channel bias effect ids.
pub const CHANNEL_PREFIX: &str = "gyro_bias_channel:";

/// The effect catalogue: ids and what they model.
const CATALOGUE: [(&str, &str); 5] = [
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
        other => return Err(ModelError::UnknownEffect(other.to_string())),
    })
}

#[cfg(test)]
pub(crate) mod testing {
    //! Finite-difference checks shared by the effect tests.
    use super::*;

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
            Err(ModelError::UnknownEffect(e)) if e == "warp_drive"
        ));
    }
}
