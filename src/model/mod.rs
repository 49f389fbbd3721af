//! The path model (paper eq. 1-4), its residuals and cost (eq. 7), the O(N)
//! gradient (eq. 12-20 as one adjoint sweep) and the Jacobian for LM.
//!
//! With `theta_j = omega_j dt_j` the corrected rotation of step `j` and `d_j`
//! its corrected distance:
//!
//! ```text
//! q_0 = Exp(phi) q_guess                  initial_orientation
//! q_j = q_{j-1} g(theta_j)                eq. 1, g from eq. 3 or the exponential map
//! Delta_j = (q_j f q_j*) d_j              eq. 4: forward axis f = x turned into the world
//! p_j = p_{j-1} + Delta_j,  p_0 = p_guess + delta
//! ```
//!
//! Each GPS row `k` (log row `i_k`) gives weighted residuals
//! `r = (p_{i_k} - z_k) / sigma` for east, north, GPS up (if the fix has an
//! altitude) and barometric up (if the log has a barometer), and the cost is
//! `C = sum r^2` plus prior rows (eq. 7 with weights `1/sigma^2`).
//!
//! The measurements and the history behind these choices: docs/method.md (the
//! model and its O(N) gradient).

mod adjoint;
mod chain;
mod jacobian;
mod noise;
mod normal;
pub use normal::damped_solve;
mod observe;
pub use crate::rotation;
mod sweep;
mod uncertainty;

pub use crate::contract::{
    DEFAULT_BIAS_WALK, GpsTails, HeldParam, ModelError, ModelSpec, StartError, StartGuess,
};
pub use chain::{ChainSystem, Marginals};
pub use jacobian::Linearisation;
pub use normal::NormalEquations;
pub use rotation::Increment;
pub use sweep::{Evaluation, PathAt, SparsePath, Trajectory};
pub use uncertainty::Uncertainty;

use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};

use crate::effects::{self, Effect, ParamInfo, PriorRows, Role};
use crate::signals::Signals;

/// The indices where `free` is true: the columns of a linear system over
/// the free parameters, in parameter order.
pub(crate) fn free_columns(free: &[bool]) -> Vec<usize> {
    (0..free.len()).filter(|&i| free[i]).collect()
}

/// How far past the last fix of a window its model sweeps (s): beyond any GPS lag.
const HORIZON_MARGIN_S: f64 = 5.0;

/// The median of the logged per-fix accuracies (`None` when no fix has one).
fn accuracy_scale(acc: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let mut v: Vec<f64> = acc
        .flatten()
        .filter(|a| a.is_finite() && *a > 0.0)
        .collect();
    (!v.is_empty()).then(|| crate::statistics::median(&mut v))
}

/// Each fix's horizontal accuracy as the log states it: the receiver's
/// 1-sigma `hacc` where the ride logs one, else its HDOP. Only their ratios
/// to the ride's median are used ([`fix_sigma`]), and a fix's error is its
/// satellites' range error times its HDOP (`sigma = UERE * HDOP`), so the
/// HDOP's ratios are the accuracy's wherever the range error is alike.
fn horizontal_accuracy(fixes: &[crate::signals::Fix]) -> Vec<Option<f64>> {
    let logged = fixes.iter().any(|f| f.hacc.is_some());
    fixes
        .iter()
        .map(|f| if logged { f.hacc } else { f.hdop })
        .collect()
}

/// The noise of one fix: `sigma_k = sigma * acc_k / median(acc)`.
///
/// A receiver's accuracy estimate is good at saying which fixes are worse
/// than others (few satellites, multipath) and poor at the absolute level (it
/// is a filter's covariance, often optimistic), so the fixes are weighted by
/// their accuracy relative to the ride's median, and the setting `sigma`
/// stays the typical fix's noise that the bias prior is balanced against. A
/// fix without an accuracy on a ride where others have one counts as typical.
fn fix_sigma(sigma: f64, acc: Option<f64>, median: Option<f64>) -> f64 {
    match (acc, median) {
        (Some(a), Some(m)) if a.is_finite() && a > 0.0 => sigma * a / m,
        _ => sigma,
    }
}

/// A model's linearisation and its coarse twin's at one point (see
/// [`Model::derivative_anchor`]).
#[derive(Clone, Debug)]
pub(crate) struct DerivativeAnchor {
    /// The ride's linearisation there with `J - J_c` for its derivatives
    /// (`ChainLinearisation::missed_by`).
    missed: normal::ChainLinearisation,
}

impl DerivativeAnchor {
    /// The free parameters it was made over.
    pub(crate) fn columns(&self) -> &[usize] {
        &self.missed.columns
    }
}

/// One scalar observation: component `axis` (0 east, 1 north, 2 up) of the
/// position at `row`, compared with `target`, with an error of a wander
/// shared with neighbouring fixes and a jitter of its own (see [`noise`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Observation {
    pub row: usize,
    pub axis: usize,
    pub target: f64,
    /// Standard deviation of the observation's own error (m): all of it
    /// without a correlation time, the jitter on top of the wander with one.
    pub sd_white: f64,
    /// Stationary standard deviation of the wander (m; 0: none).
    pub sd_gm: f64,
    /// A barometric row (compared with the barometer, not GPS).
    pub baro: bool,
    /// Time of the fix (log time, s).
    pub t: f64,
    /// The weight on this observation's update of the filtered wander (1:
    /// the plain filter; below 1 for an outlier, see [`noise::robust_updates`]).
    pub update: f64,
}

/// A model: the ride's signals, the effects acting on them and where each
/// effect's parameters sit in the parameter vector.
#[derive(Debug)]
pub struct Model {
    pub signals: Arc<Signals>,
    pub spec: ModelSpec,
    effects: Vec<Box<dyn Effect>>,
    /// `offsets[e]..offsets[e + 1]` are effect `e`'s parameters.
    offsets: Vec<usize>,
    pub start: StartGuess,
    pub(crate) observations: Vec<Observation>,
    gyro_chain: Vec<usize>,
    distance_chain: Vec<usize>,
    orientation: Option<usize>,
    position: Option<usize>,
    baro: Option<usize>,
    n_prior: usize,
    /// Rows swept: `0..horizon`. The whole ride, except for a model restricted
    /// to a window of it, whose sweeps stop shortly after its last fix (step 1's
    /// early windows then cost what their length costs, not the whole ride's).
    horizon: usize,
    /// Where the sweeps of a window start (see [`Model::window`]); `None`: at row 0.
    anchor: Option<Anchor>,
    /// Squared residuals on every row, whatever loss the effects ask for
    /// (see [`Model::least_squares`]).
    least_squares: bool,
}

/// A fixed state on the path: sweeps that start here skip the rows before it.
#[derive(Clone, Debug)]
pub(crate) struct Anchor {
    pub row: usize,
    pub q: UnitQuaternion<f64>,
    pub p: Vector3<f64>,
    /// Every parameter acting at or before `row`, with the value the state was computed at.
    fixed: Vec<(usize, f64)>,
}

impl Model {
    /// Build the model of `spec` on `signals`, with the start guess made from them.
    ///
    /// The guess dead-reckons across the gyro's stops with the turns that
    /// `gyro_stops` starts from where the model has it (see
    /// [`StartGuess::turning_in_stops`]).
    ///
    /// That effect is built once, for the guess and the model both: its
    /// turn search reads the fixes around every stop.
    pub fn new(signals: Arc<Signals>, spec: ModelSpec) -> Result<Self, ModelError> {
        Self::checked(&spec)?;
        let ids = effects::expand(&spec.effects, &signals)?;
        let stops = ids
            .iter()
            .any(|id| id == "gyro_stops")
            .then(|| effects::GyroStops::new(&signals))
            .transpose()?;
        let rates = stops
            .as_ref()
            .map_or_else(Vec::new, effects::GyroStops::start_yaw_rates);
        let start = StartGuess::turning_in_stops(&signals, &rates)?;
        let effects = Self::built(&ids, &signals, &spec, &start, stops)?;
        Self::assemble(signals, spec, start, effects)
    }

    /// Build with a given start guess (used when re-shaping a running fit).
    pub fn with_start(
        signals: Arc<Signals>,
        spec: ModelSpec,
        start: StartGuess,
    ) -> Result<Self, ModelError> {
        Self::checked(&spec)?;
        let ids = effects::expand(&spec.effects, &signals)?;
        let effects = Self::built(&ids, &signals, &spec, &start, None)?;
        Self::assemble(signals, spec, start, effects)
    }

    /// The effects `ids`, `gyro_stops` taken from `stops` where already built.
    fn built(
        ids: &[String],
        signals: &Signals,
        spec: &ModelSpec,
        start: &StartGuess,
        mut stops: Option<effects::GyroStops>,
    ) -> Result<Vec<Box<dyn Effect>>, ModelError> {
        ids.iter()
            .map(|id| match stops.take_if(|_| id == "gyro_stops") {
                Some(built) => Ok(Box::new(built) as Box<dyn Effect>),
                None => effects::build(id, signals, spec, start),
            })
            .collect()
    }

    /// `spec`'s noise settings, or why they cannot be.
    fn checked(spec: &ModelSpec) -> Result<(), ModelError> {
        for (name, v) in [
            ("GPS horizontal sigma", spec.sigma_horizontal_m),
            ("GPS vertical sigma", spec.sigma_vertical_m),
            ("barometer sigma", spec.sigma_baro_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ModelError::Setting(format!(
                    "{name} must be a positive number of metres, got {v}"
                )));
            }
        }
        for tau in [spec.gps_tau_s, spec.gps_tau_vertical_s]
            .into_iter()
            .flatten()
        {
            if !(tau.is_finite() && (0.0..noise::MAX_TAU_S).contains(&tau)) {
                return Err(ModelError::Setting(format!(
                    "GPS correlation time must be between 0 and {} s, got {tau}",
                    noise::MAX_TAU_S
                )));
            }
        }
        if let Some(v) = spec.gps_white_vertical_m
            && !(v.is_finite() && v >= 0.0)
        {
            return Err(ModelError::Setting(format!(
                "GPS vertical jitter must be zero or a positive number of metres, got {v}"
            )));
        }
        if !(spec.gps_white_m.is_finite() && spec.gps_white_m >= 0.0) {
            return Err(ModelError::Setting(format!(
                "GPS jitter must be zero or a positive number of metres, got {}",
                spec.gps_white_m
            )));
        }
        Ok(())
    }

    /// The model of `spec` made of `effects` (built for it).
    fn assemble(
        signals: Arc<Signals>,
        spec: ModelSpec,
        start: StartGuess,
        effects: Vec<Box<dyn Effect>>,
    ) -> Result<Self, ModelError> {
        let mut offsets = vec![0];
        for e in &effects {
            offsets.push(offsets.last().copied().unwrap_or(0) + e.n_params());
        }
        let find = |f: &dyn Fn(&dyn Effect) -> bool| effects.iter().position(|e| f(e.as_ref()));
        let zeros = [0.0; 3];
        let orientation = find(&|e| e.initial_orientation(&zeros).is_some());
        let position = find(&|e| e.initial_position(&zeros).is_some());
        let baro = effects.iter().position(|e| e.observes_baro());
        let gyro_chain = (0..effects.len())
            .filter(|&e| effects[e].acts_on_gyro())
            .collect();
        let distance_chain = (0..effects.len())
            .filter(|&e| effects[e].acts_on_distance())
            .collect();
        let n_prior = effects.iter().map(|e| e.n_prior()).sum();

        let mut observations = Vec::new();
        // A robust loss is the other answer to the same heavy tails: under
        // both a reflected fix is discounted twice, and the good fixes around
        // it with it (hidden outliers, seed 45: 1.92 -> 4.58 m from the truth
        // with both; urban seed 7 with `gps_outliers` from the start 13.4 m).
        let robust = effects.iter().any(|e| e.robust_scale().is_some());
        let tails = spec.gps_tails.as_ref().filter(|_| !robust);
        let h_acc = horizontal_accuracy(&signals.fixes);
        let h_scale = accuracy_scale(h_acc.iter().copied());
        let v_scale = accuracy_scale(signals.fixes.iter().map(|f| f.vacc));
        // (wander, jitter) of a GPS axis of sigma `sigma`, each scaled by the
        // fix's accuracy: the jitter alone for independent fixes; with a
        // correlation time the wander is the setting and the jitter keeps the
        // horizontal ratio, unless the heights have their own (`vertical`).
        let correlated = spec.gps_tau_s.is_some_and(|t| t > 0.0);
        let split = |sigma: f64, acc: Option<f64>, scale: Option<f64>, vertical: bool| {
            if correlated {
                let white = spec
                    .gps_white_vertical_m
                    .filter(|_| vertical)
                    .unwrap_or(sigma * spec.gps_white_m / spec.sigma_horizontal_m);
                (fix_sigma(sigma, acc, scale), fix_sigma(white, acc, scale))
            } else {
                (0.0, fix_sigma(sigma, acc, scale))
            }
        };
        for (i, (fix, &acc)) in signals.fixes.iter().zip(&h_acc).enumerate() {
            let (sd_gm, sd_white) = split(spec.sigma_horizontal_m, acc, h_scale, false);
            let tail = tails.map_or(1.0, |t| t.scale_of(i));
            let (sd_gm, sd_white) = (sd_gm * tail, sd_white * tail);
            for axis in 0..2 {
                observations.push(Observation {
                    row: fix.row,
                    axis,
                    target: fix.en[axis],
                    sd_white,
                    sd_gm,
                    baro: false,
                    t: fix.t,
                    update: 1.0,
                });
            }
            if let Some(up) = fix.up {
                let (sd_gm, sd_white) = split(spec.sigma_vertical_m, fix.vacc, v_scale, true);
                observations.push(Observation {
                    row: fix.row,
                    axis: 2,
                    target: up,
                    sd_white,
                    sd_gm,
                    baro: false,
                    t: fix.t,
                    update: 1.0,
                });
            }
            if let (Some(b), Some(_)) = (fix.baro, baro) {
                observations.push(Observation {
                    row: fix.row,
                    axis: 2,
                    target: b,
                    sd_white: spec.sigma_baro_m,
                    sd_gm: 0.0,
                    baro: true,
                    t: fix.t,
                    update: 1.0,
                });
            }
        }
        let horizon = signals.len();
        Ok(Self {
            signals,
            spec,
            effects,
            offsets,
            start,
            observations,
            gyro_chain,
            distance_chain,
            orientation,
            position,
            baro,
            n_prior,
            horizon,
            anchor: None,
            least_squares: false,
        })
    }

    pub fn n_params(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    pub fn effects(&self) -> &[Box<dyn Effect>] {
        &self.effects
    }

    pub fn effect_ids(&self) -> Vec<String> {
        self.effects.iter().map(|e| e.id()).collect()
    }

    /// Parameter range of effect `e`.
    pub fn range(&self, e: usize) -> std::ops::Range<usize> {
        self.offsets[e]..self.offsets[e + 1]
    }

    /// Index of the effect with this id.
    pub fn effect_index(&self, id: &str) -> Option<usize> {
        self.effects.iter().position(|e| e.id() == id)
    }

    /// The parameters of the effect `id` in `theta`, if the model has it.
    pub fn effect_params<'t>(&self, theta: &'t [f64], id: &str) -> Option<&'t [f64]> {
        self.effect_index(id).map(|e| &theta[self.range(e)])
    }

    /// Starting parameter vector.
    pub fn initial_params(&self) -> Vec<f64> {
        let mut theta: Vec<f64> = self
            .effects
            .iter()
            .flat_map(|e| e.initial(&self.start))
            .collect();
        self.set_held(&mut theta);
        theta
    }

    /// Index and value of every parameter the spec holds (see
    /// [`crate::contract::HeldParam`]); one the model lacks is ignored.
    fn held(&self) -> Vec<(usize, f64)> {
        if self.spec.held.is_empty() {
            return Vec::new();
        }
        let infos = self.param_infos();
        self.spec
            .held
            .iter()
            .filter_map(|h| {
                infos
                    .iter()
                    .position(|(id, p)| *id == h.effect && p.name == h.name)
                    .map(|i| (i, h.value))
            })
            .collect()
    }

    /// `theta` with the held parameters at their values.
    fn set_held(&self, theta: &mut [f64]) {
        for (i, v) in self.held() {
            if let Some(x) = theta.get_mut(i) {
                *x = v;
            }
        }
    }

    /// Parameter descriptions, in parameter-vector order, with their effect id.
    pub fn param_infos(&self) -> Vec<(String, ParamInfo)> {
        self.effects
            .iter()
            .flat_map(|e| {
                let id = e.id();
                e.params().into_iter().map(move |p| (id.clone(), p))
            })
            .collect()
    }

    /// Parameters held at their starting values (see [`Effect::fixed`]).
    pub fn fixed_mask(&self) -> Vec<bool> {
        let mut mask: Vec<bool> = self
            .effects
            .iter()
            .flat_map(|e| (0..e.n_params()).map(|i| e.fixed(i)))
            .collect();
        for (i, _) in self.held() {
            mask[i] = true;
        }
        mask
    }

    /// Which parameters each optimisation step frees.
    pub fn free_mask(&self, roles: &[Role]) -> Vec<bool> {
        let mut mask = vec![false; self.n_params()];
        for (e, effect) in self.effects.iter().enumerate() {
            if roles.contains(&effect.role()) {
                for (i, m) in mask[self.range(e)].iter_mut().enumerate() {
                    *m = !effect.fixed(i);
                }
            }
        }
        for (i, _) in self.held() {
            mask[i] = false;
        }
        mask
    }

    /// The same model seeing only the GPS rows up to `t_end` (log time). Step 1
    /// fits on a growing window of the ride: a constant bias fitted to a whole
    /// long ride from a rough start can settle far from the answer, while one
    /// fitted to the first minutes and then extended stays in the right basin.
    ///
    /// Its effects are this model's, shared where they can be (see
    /// [`Model::rebuilt`]): step 1 cuts a window at every widening, and on a
    /// 6-hour ride building every effect anew (the segments' per-row table
    /// of 2.16 M rows among them) for each of its some seventy windows took
    /// 2.7 s of step 1's 11.5 s.
    pub fn restricted(&self, t_end: f64) -> Result<Self, ModelError> {
        let mut m = self.rebuilt(self.spec.clone())?;
        let t = &self.signals.t;
        m.observations.retain(|o| t[o.row] <= t_end);
        // A fix looks at most a few seconds back (GPS lag), never past its own row.
        m.horizon = t.partition_point(|&x| x <= t_end + HORIZON_MARGIN_S).max(1);
        Ok(m)
    }

    /// The same model seeing only the GPS rows from `t_start` to `t_end`
    /// (log time), its sweeps ending there as [`Model::restricted`]'s: a
    /// window of a long ride on which the noise settings are estimated.
    pub fn between(&self, t_start: f64, t_end: f64) -> Result<Self, ModelError> {
        let mut m = self.restricted(t_end)?;
        let t = &self.signals.t;
        m.observations.retain(|o| t[o.row] >= t_start);
        Ok(m)
    }

    /// This model without the fixes its start guess suspects of a
    /// reflection (see [`crate::suspect_fixes`]), for step 1's windows; their
    /// barometer rows stay.
    pub fn without_suspect_fixes(mut self) -> Self {
        let suspect = &self.start.suspect_fixes;
        if !suspect.is_empty() {
            self.observations
                .retain(|o| o.baro || suspect.binary_search_by(|t| t.total_cmp(&o.t)).is_err());
        }
        self
    }

    /// `free` less the parameters that act only outside this model's fixes:
    /// past the rows it sweeps (a restricted model's later segment biases,
    /// which nothing observes and a chain solve would carry as open columns)
    /// and, for a window from [`Model::between`], wholly before its first
    /// fix (the segment biases there stay as fitted: the globals still move
    /// and turn the path at the window, and the solve need not cross the
    /// ride up to it).
    pub fn free_within_fixes(&self, free: &[bool]) -> Vec<bool> {
        let last = self.horizon.saturating_sub(1);
        let first = self.observations.first().map_or(0, |o| o.row);
        free.iter()
            .enumerate()
            .map(|(i, &f)| f && !self.acts_after(i, last) && !self.acts_before(i, first))
            .collect()
    }

    /// Whether parameter `i` acts only on steps before `row`.
    fn acts_before(&self, i: usize, row: usize) -> bool {
        self.param_steps(i).is_some_and(|(_, last)| last < row)
    }

    /// First and last step that parameter `i` acts on (its effect's
    /// [`Effect::param_steps`]); `None`: every step.
    fn param_steps(&self, i: usize) -> Option<(usize, usize)> {
        let e = self.offsets.partition_point(|&o| o <= i) - 1;
        self.effects[e].param_steps(i - self.offsets[e])
    }

    /// Time (s) from this model's first observed fix to its last.
    pub fn fix_span(&self) -> f64 {
        self.observations
            .first()
            .zip(self.observations.last())
            .map_or(0.0, |(f, l)| l.t - f.t)
    }

    /// Fixes with at least one observation in this model.
    pub fn observed_fixes(&self) -> usize {
        let mut rows: Vec<usize> = self.observations.iter().map(|o| o.row).collect();
        rows.dedup();
        rows.len()
    }

    /// This ride and start guess under `spec`, seeing the same fixes as this
    /// model (all of them, a window's from [`Model::between`] or a fold's).
    pub fn with_spec(&self, spec: ModelSpec) -> Result<Self, ModelError> {
        let mut m = self.rebuilt(spec)?;
        // Observations are in row order.
        let rows: Vec<usize> = self.observations.iter().map(|o| o.row).collect();
        m.observations
            .retain(|o| rows.binary_search(&o.row).is_ok());
        m.horizon = self.horizon;
        Ok(m)
    }

    /// The model of `spec` on this ride and start guess, observing every
    /// fix. With the same effects as this model's, each is reweighted for
    /// `spec` where it can be (sharing its per-row tables), else built anew.
    fn rebuilt(&self, spec: ModelSpec) -> Result<Self, ModelError> {
        if spec.effects != self.spec.effects {
            return Self::with_start(self.signals.clone(), spec, self.start.clone());
        }
        Self::checked(&spec)?;
        let ids = effects::expand(&spec.effects, &self.signals)?;
        let effects = ids
            .iter()
            .zip(&self.effects)
            .map(|(id, e)| match e.reweighted(&spec) {
                Some(e) => Ok(e),
                None => effects::build(id, &self.signals, &spec, &self.start),
            })
            .collect::<Result<_, _>>()?;
        Self::assemble(self.signals.clone(), spec, self.start.clone(), effects)
    }

    /// This model with squared residuals on the GPS rows even when an effect
    /// asks for a robust loss (`on`), or with the robust loss back (`!on`).
    /// A robust loss is not convex: from a start guess far off, a path that
    /// misses every fix costs little more than one that meets them (each
    /// miss is bounded near `s^2 ln(1 + e^2 / s^2)`). On a city ride (seed 9)
    /// the first window settled 1.7 km from the truth, and on an open-sky
    /// ride (seed 67) a widened window's dead reckoning, 40 m off, settled
    /// 146 m from the fixes. Least squares has no such basin: step 1 fits
    /// every window by it first, and the robust loss then takes over from
    /// the least-squares optimum.
    pub fn least_squares(mut self, on: bool) -> Self {
        self.least_squares = on;
        self
    }

    /// Whether [`Model::least_squares`] made this model.
    pub fn is_least_squares(&self) -> bool {
        self.least_squares
    }

    /// Rows `0..horizon` that the sweeps cover.
    pub(crate) fn horizon(&self) -> usize {
        self.horizon
    }

    /// First row of the cost sweep: the anchor's, or 0.
    pub(crate) fn first_row(&self) -> usize {
        self.anchor.as_ref().map_or(0, |a| a.row)
    }

    /// The anchor, if `theta` still has the values it was computed at.
    pub(crate) fn anchor_for(&self, theta: &[f64]) -> Option<&Anchor> {
        self.anchor.as_ref().filter(|a| {
            a.fixed
                .iter()
                .all(|&(i, v)| theta[i].to_bits() == v.to_bits())
        })
    }

    /// The same model seeing only the GPS rows after log row `anchor_row` and
    /// up to `t_end`, its cost sweeps starting at `anchor_row` from the state
    /// the path has there at `theta`. Step 1's late windows on a long ride fit
    /// only the segment biases of the last stretch; the path before it is
    /// fixed, so sweeping it again at every iteration would make the fit
    /// quadratic in the ride's length. The anchor is used only while every
    /// parameter acting at or before `anchor_row` keeps its value; otherwise
    /// (and for derivatives with respect to such parameters) the sweeps start
    /// from row 0 as in any model.
    pub fn window(&self, theta: &[f64], anchor_row: usize, t_end: f64) -> Result<Self, ModelError> {
        let mut m = self.restricted(t_end)?;
        let anchor_row = anchor_row.min(m.horizon - 1);
        // The state at the anchor, from this model's own start (itself maybe an anchor before it).
        let from = if self.first_row() <= anchor_row {
            self
        } else {
            &m
        };
        let mut state = None;
        from.sweep(theta, |j, q, p, _, _| {
            if j == anchor_row {
                state = Some((*q, *p));
            }
        });
        if let Some((q, p)) = state {
            m.observations.retain(|o| o.row > anchor_row);
            let fixed = (0..self.n_params())
                .filter(|&i| !self.acts_after(i, anchor_row))
                .map(|i| (i, theta[i]))
                .collect();
            m.anchor = Some(Anchor {
                row: anchor_row,
                q,
                p,
                fixed,
            });
        }
        Ok(m)
    }

    /// Whether parameter `i` acts only on steps after `row`.
    fn acts_after(&self, i: usize, row: usize) -> bool {
        self.param_steps(i).is_some_and(|(first, _)| first > row)
    }

    /// Whether every free parameter acts only after the anchor, so that
    /// prefix sums may start there (the anchor stays valid while they change).
    pub(crate) fn anchor_holds(&self, free: &[bool]) -> bool {
        self.anchor.as_ref().is_none_or(|a| {
            free.iter()
                .enumerate()
                .all(|(i, &f)| !f || self.acts_after(i, a.row))
        })
    }

    /// Number of residual rows: observations then priors.
    pub fn n_residuals(&self) -> usize {
        self.observations.len() + self.n_prior
    }

    /// Parameters for this model from a fit of another model on the same ride:
    /// effects present in both keep their values (or are mapped, e.g. onto new
    /// segments), new ones start from their initial values.
    pub fn carry_over(&self, other: &Model, other_params: &[f64]) -> Vec<f64> {
        let mut p = self.initial_params();
        for (e, effect) in self.effects.iter().enumerate() {
            let Some(o) = other.effect_index(&effect.id()) else {
                continue;
            };
            let old = &other_params[other.range(o)];
            let r = self.range(e);
            if r.len() == old.len() && effect.segment_edges().is_none() {
                p[r].copy_from_slice(old);
            } else if let Some(mapped) = effect.carry_over(other.effects[o].as_ref(), old) {
                p[r].copy_from_slice(&mapped);
            }
        }
        self.set_held(&mut p);
        p
    }

    fn params_of<'a>(&self, e: usize, theta: &'a [f64]) -> &'a [f64] {
        &theta[self.offsets[e]..self.offsets[e + 1]]
    }

    /// Initial attitude and position for `theta`, and the world-rotation vector `phi`.
    pub fn initial_state(
        &self,
        theta: &[f64],
    ) -> (UnitQuaternion<f64>, Vector3<f64>, Vector3<f64>) {
        let phi = self
            .orientation
            .and_then(|e| self.effects[e].initial_orientation(self.params_of(e, theta)))
            .unwrap_or_else(Vector3::zeros);
        let q0 = UnitQuaternion::from_scaled_axis(phi) * self.start.attitude;
        let dp = self
            .position
            .and_then(|e| self.effects[e].initial_position(self.params_of(e, theta)))
            .unwrap_or_else(Vector3::zeros);
        (q0, self.start.position + dp, phi)
    }

    /// The same model without the observations of the fixes where `keep(t_fix)`
    /// is false (held-out validation); the parameter layout is unchanged.
    pub fn withholding(&self, keep: impl Fn(f64) -> bool) -> Result<Model, ModelError> {
        let mut m = Model::with_start(self.signals.clone(), self.spec.clone(), self.start.clone())?;
        m.observations.retain(|o| keep(o.t));
        Ok(m)
    }

    /// The LM problem at `theta` over the `free` parameters in chain form, solved
    /// in O(N) (see [`ChainSystem`]); `None` when the model's local parameters
    /// do not form a chain (the dense normal equations then apply).
    pub fn chain_system(&self, theta: &[f64], free: &[bool]) -> Option<ChainSystem> {
        self.chain_linearisation(theta, free)
            .and_then(|lin| ChainSystem::new(lin, self.n_params()))
    }

    /// [`Model::chain_system`] for this model's noise settings, from the
    /// linearisation of `base` (same ride, effects and segments) at the same
    /// `theta`: O(fixes) instead of a sweep of the ride. `None` as for
    /// `chain_system`, or when the two models do not observe the same fixes.
    pub fn chain_system_like(&self, base: &ChainSystem, theta: &[f64]) -> Option<ChainSystem> {
        let lin = base.linearisation();
        if lin.x.len() != self.observations.len() {
            return None;
        }
        ChainSystem::new(self.reweighted(lin, theta), self.n_params())
    }

    /// [`Model::chain_system_like`] with its unknowns scaled as `base`'s
    /// (see [`ChainSystem::scaled_like`]): the same cost at the minimum and
    /// log-determinant, to rounding, for a noise likelihood, which asks for
    /// nothing else. Not for LM steps: their damping `lambda D` is this
    /// model's own `D`.
    pub fn likelihood_system_like(&self, base: &ChainSystem, theta: &[f64]) -> Option<ChainSystem> {
        let lin = base.linearisation();
        if lin.x.len() != self.observations.len() {
            return None;
        }
        ChainSystem::scaled_like(self.reweighted(lin, theta), base)
    }

    /// [`Model::chain_system`] of this model, which observes the fixes of
    /// `base`'s model where `kept` is true, from `base`'s linearisation at
    /// the same `theta` (see [`Model::restricted_to`]). `None` when the
    /// observations do not match.
    pub fn chain_system_within(
        &self,
        base: &ChainSystem,
        theta: &[f64],
        kept: &[bool],
    ) -> Option<ChainSystem> {
        let lin = self.restricted_to(base.linearisation(), theta, kept)?;
        ChainSystem::new(lin, self.n_params())
    }

    /// Where the derivatives of `coarse` (this model on the ride in coarser
    /// steps, `optimisation::coarse_model`) were compared with this
    /// model's: both linearisations at the point `full` was made (`theta`,
    /// this model's chain system there). `None` when `coarse` cannot be
    /// linearised there.
    pub(crate) fn derivative_anchor(
        &self,
        coarse: &Model,
        full: &ChainSystem,
        theta: &[f64],
    ) -> Option<DerivativeAnchor> {
        let free = self.mask_of(full.columns())?;
        let missed = full
            .linearisation()
            .clone()
            .missed_by(&coarse.chain_linearisation(theta, &free)?)?;
        Some(DerivativeAnchor { missed })
    }

    /// [`Model::chain_system`] at `theta` over the anchor's parameters, with
    /// the derivatives of `coarse` (this model on the coarse ride) there,
    /// corrected by what they missed at the anchor
    /// (`J = J_c(theta) + J(theta_a) - J_c(theta_a)`), and the residuals
    /// of this model's `observed` values at `theta` (an evaluation's): a
    /// sweep of the coarse ride, a tenth of this one at 100 Hz, instead of
    /// the ride's. `None` when the three do not match.
    pub(crate) fn chain_system_from_coarse(
        &self,
        coarse: &Model,
        anchor: &DerivativeAnchor,
        theta: &[f64],
        observed: &[f64],
    ) -> Option<ChainSystem> {
        let free = self.mask_of(anchor.columns())?;
        let lin = coarse
            .chain_linearisation(theta, &free)?
            .corrected(&anchor.missed)?;
        ChainSystem::new(self.moved(lin, theta, observed)?, self.n_params())
    }

    /// The mask that frees `columns` (parameter indices), the inverse of
    /// [`free_columns`]; `None` if one is not a parameter of this model.
    fn mask_of(&self, columns: &[usize]) -> Option<Vec<bool>> {
        let mut free = vec![false; self.n_params()];
        for &c in columns {
            *free.get_mut(c)? = true;
        }
        Some(free)
    }

    /// Whether barometric rows are observed (the model fits the barometer's offset).
    pub fn observes_baro(&self) -> bool {
        self.baro.is_some()
    }

    /// Prior rows of all effects, with columns in the global parameter vector.
    pub(crate) fn prior_rows(&self, theta: &[f64]) -> PriorRows {
        let mut all = PriorRows::default();
        for (e, effect) in self.effects.iter().enumerate() {
            if effect.n_prior() == 0 {
                continue;
            }
            let mut rows = PriorRows::default();
            effect.prior(self.params_of(e, theta), &mut rows);
            let base = all.residuals.len();
            all.residuals.extend_from_slice(&rows.residuals);
            all.entries.extend(
                rows.entries
                    .iter()
                    .map(|&(r, c, v)| (base + r, self.offsets[e] + c, v)),
            );
        }
        all
    }
}

#[cfg(test)]
mod tests;
