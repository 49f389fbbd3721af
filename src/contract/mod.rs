//! The contract between the model and its effects: what an effect is (the
//! [`Effect`] trait and what it declares: its parameters, their roles, the
//! rows and sites it touches), what the model is made of ([`ModelSpec`]),
//! the start guess every effect builds from ([`StartGuess`]) and the errors
//! of building a model ([`ModelError`]).
//!
//! It sits beneath both: `effects` implements the trait, `model` composes
//! the effects of a [`ModelSpec`]; neither imports the other's side of it.

mod spec;
mod start;

pub use spec::{DEFAULT_BIAS_WALK, GpsTails, HeldParam, ModelError, ModelSpec};
pub use start::{StartError, StartGuess};

use nalgebra::{Matrix3, Vector3};

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
    /// Variance (m^2) of the path along the track at row `j` that no
    /// parameter carries: a distance bridged without a measurement, whose
    /// spread inside the bridge the fit cannot see (added to the path's
    /// covariance, [`crate::model::Uncertainty`]).
    fn along_track_variance(&self, _j: usize) -> f64 {
        0.0
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

    /// This effect under `spec` (the same effects, other noise or prior
    /// settings), sharing what does not depend on them: a noise search
    /// rebuilds the model at every setting it tries, and a per-row table
    /// rebuilt each time cost more than the likelihood of a long ride's
    /// window. `None`: build it anew from the ride.
    fn reweighted(&self, _spec: &ModelSpec) -> Option<Box<dyn Effect>> {
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
