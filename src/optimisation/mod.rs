//! Fitting, one iteration at a time (problem / solver / observer split).
//!
//! Step 1 fits the global parameters (constant bias, start orientation and
//! position, odometer gain, barometer offset) with Levenberg-Marquardt (a
//! Gauss-Newton method with a trust region) on the first two minutes of the
//! ride, then on a window that grows by half each time the fit on it converges.
//! Past the first window a constant bias no longer holds (MEMS biases drift
//! by tenths of a deg/s over minutes, and a roll tilt with a matching
//! roll-axis bias can fit a drifting window and then roll the path over),
//! so with LM the widened windows fit the segment biases instead, held
//! beyond the window by their random-walk prior (without a prior, or with
//! gradient descent as step 2, the constant bias as in the paper). Step 2
//! fits the per-segment biases with gradient descent or LM; LM also refines
//! the globals except the constant bias, which the segments absorb. Effects
//! whose parameters a short window cannot pin (a bias slope on a logged
//! channel) wait for step 2 ([`Role::Step2Only`]). [`Reconstruction::iterate`] does
//! one iteration and reports it; [`Reconstruction::apply_settings`] changes
//! segment length, method, step size, damping or model between iterations
//! without starting over (parameters carry over, segments are re-mapped).
//!
//! The measurements and the history behind these choices: docs/method.md
//! (step 1, step 2, the LM that cannot diverge).

mod derivatives;
pub mod gd;
pub mod lm;
pub mod noise;

use std::sync::Arc;

use thiserror::Error;

use crate::effects::Role;
use crate::model::{Evaluation, GpsTails, Model, ModelError, ModelSpec, Trajectory};
use crate::signals::Signals;

pub use gd::GdState;
pub use lm::{Linearised, LmState, StepOutcome};
pub use noise::{AutoNoise, Estimated, Limit, NoiseEstimate};

/// Why a fit could not be set up.
#[derive(Debug, Error)]
pub enum FitError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("{0}")]
    Setting(String),
    #[error(
        "{file}: {fixes} GPS fixes give {rows} residuals, fewer than the {params} parameters of the model; use longer segments or a longer ride"
    )]
    TooFewFixes {
        file: String,
        fixes: usize,
        rows: usize,
        params: usize,
    },
    #[error(
        "{file}: too short to validate a model: its {duration_s:.1} s make {blocks} blocks of {block_s:.1} s, and held-out validation withholds the blocks between the first and the last (which every refit keeps) and needs at least {needed} of them with GPS fixes ({found} here); a ride of {min_duration_s:.0} s or more"
    )]
    TooShortToValidate {
        file: String,
        duration_s: f64,
        blocks: usize,
        block_s: f64,
        found: usize,
        needed: usize,
        min_duration_s: f64,
    },
}

/// Step-2 optimiser.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Levenberg-Marquardt (paper eq. 10-11, with step rejection).
    #[default]
    Lm,
    /// Gradient descent (paper eq. 8-9, with step-size backtracking).
    Gd,
}

/// Everything a fit can be told.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitSettings {
    pub model: ModelSpec,
    pub method: Method,
    /// Gradient-descent step size gamma (deg/s per unit of dC/d(deg/s)).
    pub step_size: f64,
    /// Initial LM damping lambda.
    pub damping: f64,
    /// Iteration limit for each step.
    pub max_iter: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction.
    pub tolerance: f64,
    /// Noise settings estimated from the ride (see [`noise`]), overriding the
    /// model's GPS sigma and correlation time and its bias walk once step 2
    /// has converged; the fit then resumes step 2 with them.
    #[serde(default)]
    pub auto_noise: AutoNoise,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            model: ModelSpec::default(),
            method: Method::Lm,
            step_size: 1e-6,
            damping: 1e-3,
            max_iter: 200,
            tolerance: 1e-7,
            auto_noise: AutoNoise::default(),
        }
    }
}

impl FitSettings {
    fn validate(&self) -> Result<(), FitError> {
        if !(self.step_size.is_finite() && self.step_size > 0.0) {
            return Err(FitError::Setting(format!(
                "step size must be positive, got {}",
                self.step_size
            )));
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return Err(FitError::Setting(format!(
                "damping must be zero or positive, got {}",
                self.damping
            )));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(FitError::Setting(format!(
                "tolerance must be zero or positive, got {}",
                self.tolerance
            )));
        }
        Ok(())
    }
}

/// Where a fit is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Global parameters (constant bias, start, gain).
    Step1,
    /// Per-segment biases.
    Step2,
    /// Noise settings from the data (one likelihood search), then step 2 again.
    Noise,
    Done,
}

/// What one iteration did, for observers.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct IterationReport {
    /// Iteration count over the whole fit (1-based).
    pub iteration: usize,
    pub phase: Phase,
    pub method: Method,
    pub cost: f64,
    pub accepted: bool,
    /// Horizontal distance RMS between path and GPS fixes (m), over the
    /// fixes the iteration fitted: in step 1 those of its window.
    pub rms_horizontal_m: f64,
    /// The same over the whole ride: the figure that falls as the fit
    /// proceeds (a growing window's own cost and RMS rise as it takes in
    /// more of the ride). In step 1 it is evaluated when the window widens
    /// and when the step ends (a whole-ride sweep per iteration would cost
    /// long rides what the anchored windows save) and carried in between.
    pub ride_rms_m: f64,
    pub damping: f64,
    pub step_size: f64,
    /// The settings changed just before this iteration.
    pub settings_changed: bool,
    /// The phase finished with this iteration.
    pub phase_finished: bool,
}

/// Fit statistics of a parameter vector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FitStats {
    pub cost: f64,
    /// Horizontal distance path - fix, RMS over fixes (m).
    pub rms_horizontal_m: f64,
    /// Path up - GPS altitude, RMS (m), if the log has GPS altitude.
    pub rms_gps_up_m: Option<f64>,
    /// Path up - (baro + offset), RMS (m), if the log has a barometer.
    pub rms_baro_up_m: Option<f64>,
}

impl FitStats {
    pub fn of(model: &Model, theta: &[f64]) -> Self {
        Self::from_evaluation(&model.evaluate(theta))
    }

    pub fn from_evaluation(ev: &Evaluation) -> Self {
        let rms =
            |s: usize| (ev.count[s] > 0).then(|| (ev.sum_sq_m[s] / ev.count[s] as f64).sqrt());
        Self {
            cost: ev.cost,
            // Two horizontal rows per fix: RMS of the 2-D distance.
            rms_horizontal_m: (ev.sum_sq_m[0] / (ev.count[0] / 2).max(1) as f64).sqrt(),
            rms_gps_up_m: rms(1),
            rms_baro_up_m: rms(2),
        }
    }
}

/// Receives every iteration (the CLI's progress, the app's worker, tests).
pub trait Observer {
    fn on_iteration(&mut self, fit: &Reconstruction, report: &IterationReport);
}

impl<F: FnMut(&Reconstruction, &IterationReport)> Observer for F {
    fn on_iteration(&mut self, fit: &Reconstruction, report: &IterationReport) {
        self(fit, report)
    }
}

/// A running reconstruction: model, parameters, phase and optimiser state.
#[derive(Debug)]
pub struct Reconstruction {
    model: Model,
    theta: Vec<f64>,
    settings: FitSettings,
    phase: Phase,
    lm: LmState,
    /// The first LM iteration's linear system, where a caller already has it
    /// (see [`Reconstruction::resume_from`]).
    start_system: Option<crate::model::ChainSystem>,
    /// A whole-ride stage ends on a step that met its quadratic model (see
    /// [`Reconstruction::running_to_its_tolerance`]).
    ends_on_a_met_model: bool,
    /// The last LM iteration's chain system of the whole ride is kept (see
    /// [`Reconstruction::keeping_its_last_linearisation`]).
    keeps_linearisation: bool,
    /// Step 2's derivatives after its first iteration (see [`derivatives`]).
    derivatives: derivatives::CoarseDerivatives,
    /// See [`Reconstruction::linearising_the_ride_every_iteration`].
    coarse_derivatives: bool,
    coarse_iterations: usize,
    last_linearisation: Option<Linearised>,
    gd: GdState,
    iteration: usize,
    phase_iterations: [usize; 2],
    /// Iterations since the phase started or step 1's window last widened:
    /// the iteration limit applies to each window, so a long ride's many
    /// windows do not use up step 1's budget.
    stage_iterations: usize,
    settings_changed: bool,
    history: Vec<IterationReport>,
    /// Step 1's growing window; `None` once it covers the ride.
    window: Option<Window>,
    /// The ride in coarser steps that step 1's windows are cut from while
    /// there are windows (see [`coarse_model`]); `None` after them, or where
    /// the log's steps are coarse already.
    coarse: Option<Model>,
    /// Step 1 has moved past its first window: from here on it fits the
    /// segment biases instead of the constant bias (when the model has a prior).
    widened: bool,
    /// The last whole-ride RMS (see [`IterationReport::ride_rms_m`]).
    ride_rms_m: Option<f64>,
    /// The noise settings estimated from the ride, in force in `model`.
    noise: Option<NoiseEstimate>,
    /// The noise search has run for the current model (or is not wanted).
    noise_done: bool,
    /// The GPS error's heavy tails learnt from the ride, in force in `model`
    /// (see [`noise::tails`]).
    tails: Option<GpsTails>,
    /// What the fit reports of them.
    tail_summary: Option<noise::tails::TailSummary>,
    /// Rounds of tail weights run.
    tail_rounds: usize,
    /// The tails are settled (or not wanted).
    tails_done: bool,
    /// While the tails only check the gain (`AutoNoise::robust_gain`): the
    /// Gaussian fit's parameters and step-2 iterations, to go back to once
    /// they have spoken.
    gaussian_fit: Option<(Vec<f64>, usize)>,
    /// What that check found (see [`noise::calibration`]).
    calibration: Vec<noise::calibration::CalibrationCheck>,
}

/// Rounds of tail weights at most. Each costs a step 2; under the Gaussian
/// search's noise settings the weights settle within 5 % in one to three
/// rounds on the rides measured (Berlin 3, comma 2, `simulate --gps urban`
/// and `city` 1-2).
const MAX_TAIL_ROUNDS: usize = 6;

/// The tail weights count as settled when no fix's noise factor moved by
/// more than this (in the logarithm) since the round before.
const TAILS_SETTLED: f64 = 0.05;

/// Step 1's window: the first `length` seconds of the ride, seen by `model`.
#[derive(Debug)]
struct Window {
    length: f64,
    model: Model,
    /// Log time from which an anchored window fits the segment biases (the
    /// path before is fixed and not swept again); `None`: from the start.
    from: Option<f64>,
}

/// A window this long (s) or longer is followed by anchored windows, which
/// fit only the segment biases of their last stretch: the globals are settled
/// by then, and refitting the whole ride at every widening would make step 1
/// quadratic in the ride's length.
const ANCHOR_AFTER_S: f64 = 900.0;

/// An anchored window refits this much (s) of the stretch its predecessor fitted.
const ANCHOR_OVERLAP_S: f64 = 600.0;

/// Step 1 widens its window by at most this much at a time (s).
const MAX_WIDENING_S: f64 = 300.0;

/// Relative cost decrease below which a window that will still widen counts as converged.
const WINDOW_TOLERANCE: f64 = 1e-3;

/// The damping (relative to the setting's) with which the whole ride
/// starts after anchored windows. Every parameter has been fitted on its
/// stretch by then, and the quadratic model holds (every step of that stage
/// met it, `rho` near 1): from the setting's 1e-3, Marquardt's diagonal
/// damped the ride's weakest directions for 12 iterations of a 6-hour ride
/// (4 of them gaining under one unit of its cost of 18877), each as long as
/// all the windows' iterations of 15 minutes; from 1e-6 it reaches the same
/// minimum in 7.
const WHOLE_AFTER_ANCHORED_DAMPING: f64 = 1e-3;

/// `model` on the ride in [`crate::signals::COARSE_STEP_S`] steps, for
/// step 1's windows and step 2's later derivatives (see [`derivatives`]);
/// `None` where the log's steps are that long already or the coarse ride's
/// parameters would not be the ride's one for one (a gap in the GNSS speed
/// that merged steps no longer show).
///
/// It observes the fixes `model` observes, no others (a validation fold's
/// model withholds some), each on its row of the coarse ride, with the
/// same weights.
pub(crate) fn coarse_model(model: &Model) -> Option<Model> {
    let signals = model.signals.coarse_shared()?;
    let mut coarse = Model::with_start(signals, model.spec.clone(), model.start.clone()).ok()?;
    let names =
        |m: &Model| -> Vec<String> { m.param_infos().into_iter().map(|(_, p)| p.name).collect() };
    if names(&coarse) != names(model) {
        return None;
    }
    let key = |o: &crate::model::Observation| (o.t.to_bits(), o.axis, o.baro);
    let rows: std::collections::HashMap<_, usize> = coarse
        .observations
        .iter()
        .map(|o| (key(o), o.row))
        .collect();
    coarse.observations = model
        .observations
        .iter()
        .map(|o| {
            rows.get(&key(o))
                .map(|&row| crate::model::Observation { row, ..*o })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(coarse)
}

/// Step 1's first window (s); it grows by half each time the fit on it converges.
const FIRST_WINDOW_S: f64 = 120.0;

impl Reconstruction {
    /// Set up a fit of `settings.model` on `signals`, at the start guess.
    pub fn new(signals: Arc<Signals>, settings: FitSettings) -> Result<Self, FitError> {
        settings.validate()?;
        let model = Model::new(signals, settings.model.clone())?;
        let theta = model.initial_params();
        Self::at(model, theta, settings, false)?.with_first_window()
    }

    /// Continue a fitted ride on `model` from `theta` (its own layout, e.g. from
    /// [`Model::carry_over`]): LM over the global and segment parameters, as in
    /// step 2, without step 1's windows. Used after adding an effect to a fitted
    /// model or withholding fixes for validation, where the start is already close.
    pub fn resume(model: Model, theta: Vec<f64>, settings: FitSettings) -> Result<Self, FitError> {
        if theta.len() != model.n_params() {
            return Err(FitError::Setting(format!(
                "{} parameters given for a model of {}",
                theta.len(),
                model.n_params()
            )));
        }
        let settings = FitSettings {
            method: Method::Lm,
            ..settings
        };
        let mut fit = Self::at(model, theta, settings, true)?;
        // A resumed fit keeps the noise settings of the model it was given.
        fit.noise_done = true;
        fit.tails_done = true;
        fit.tails = fit.model.spec.gps_tails.clone();
        if fit.has_segments() {
            fit.phase = Phase::Step2;
        }
        Ok(fit)
    }

    /// [`Reconstruction::resume`] whose first iteration is linearised as
    /// `start`, the model's chain system at `theta` over step 2's free
    /// parameters made by the caller (a validation's folds share the full
    /// ride's linearisation, see `Model::chain_system_within`).
    pub fn resume_from(
        model: Model,
        theta: Vec<f64>,
        settings: FitSettings,
        start: crate::model::ChainSystem,
    ) -> Result<Self, FitError> {
        let mut fit = Self::resume(model, theta, settings)?;
        fit.start_system = Some(start);
        Ok(fit)
    }

    /// This fit runs each whole-ride stage (step 1 after its windows, step
    /// 2) until a step gains at most the tolerance, as a confirmation.
    ///
    /// By default a stage ends instead on its second or a later LM step that
    /// met its quadratic model (`lm::iterate`'s `near_enough`, under the
    /// fit's own tolerance, not a step-1 window's looser one): there the
    /// cost is quadratic to the digits and the confirming step gains a few
    /// hundredths of the tolerance. A 30-minute ride's step 2 after the
    /// noise search took 3 iterations, now 2, and a 20-minute ride's
    /// validation folds 3, now 2 (their held-out errors moved by at most
    /// 1 mm, a jackknifed 1-sigma, the mount's yaw, by 2 %). Not the first
    /// step: it solves the system the stage started from (for a fold the
    /// whole ride's, its fold's fixes taken out), and what that system
    /// leaves shows in the second. Under the fold's own tolerance the first
    /// step seldom meets its model anyway, but where it does the fold
    /// stopped short: on Berlin the held-out error moved by 1 mm and the `t`
    /// of candidates that change nothing (drop 0.0 %) by up to 3.
    pub fn running_to_its_tolerance(mut self) -> Self {
        self.ends_on_a_met_model = false;
        self
    }

    /// This fit keeps the chain system its last iteration made of the whole
    /// ride, for [`Reconstruction::take_last_linearisation`]: a validation
    /// that follows starts its folds from it (see
    /// `diagnosis::validation::held_out_from`) rather than linearising the
    /// ride again next to the same point (one sweep of the ride fewer per
    /// validated model; on a 20-minute ride a linearisation is the price of
    /// a fold).
    pub fn keeping_its_last_linearisation(mut self) -> Self {
        self.keeps_linearisation = true;
        self
    }

    /// This fit linearises the whole ride at every iteration of step 2,
    /// never taking the derivatives from the coarse ride (see
    /// [`derivatives`]): the reference the coarse derivatives are tested
    /// against.
    pub fn linearising_the_ride_every_iteration(mut self) -> Self {
        self.coarse_derivatives = false;
        self
    }

    /// Iterations so far whose derivatives came from the coarse ride.
    pub fn coarse_iterations(&self) -> usize {
        self.coarse_iterations
    }

    /// The chain system of the whole ride that the fit's last iteration made
    /// and stepped from (within the fit's tolerance of where it ended), if
    /// it keeps one and the last iteration made one.
    pub fn take_last_linearisation(&mut self) -> Option<Linearised> {
        self.last_linearisation.take()
    }

    /// A fit of `model` at `theta`, in step 1 with no window yet.
    fn at(
        model: Model,
        theta: Vec<f64>,
        settings: FitSettings,
        widened: bool,
    ) -> Result<Self, FitError> {
        settings.validate()?;
        check_observability(&model)?;
        Ok(Self {
            lm: LmState::new(settings.damping),
            start_system: None,
            ends_on_a_met_model: true,
            keeps_linearisation: false,
            derivatives: derivatives::CoarseDerivatives::default(),
            coarse_derivatives: true,
            coarse_iterations: 0,
            last_linearisation: None,
            gd: GdState::new(settings.step_size),
            model,
            theta,
            settings,
            phase: Phase::Step1,
            iteration: 0,
            phase_iterations: [0, 0],
            stage_iterations: 0,
            settings_changed: false,
            history: Vec::new(),
            ride_rms_m: None,
            window: None,
            coarse: None,
            widened,
            noise: None,
            noise_done: false,
            tails: None,
            tail_summary: None,
            tail_rounds: 0,
            tails_done: false,
            gaussian_fit: None,
            calibration: Vec::new(),
        })
    }

    /// Iterate to the end without observers.
    pub fn finish(&mut self) {
        while self.iterate().is_some() {}
    }

    /// Start step 1 on the first window of the ride, if the ride is longer.
    fn with_first_window(mut self) -> Result<Self, FitError> {
        self.coarse = coarse_model(&self.model);
        self.window = self.next_window(FIRST_WINDOW_S)?;
        if self.window.is_none() {
            self.coarse = None;
        }
        Ok(self)
    }

    /// The model step 1's windows are cut from: the coarse ride while there
    /// is one, else the ride itself.
    fn windows_model(&self) -> &Model {
        self.coarse.as_ref().unwrap_or(&self.model)
    }

    /// The window after the current one, `length` long. Under a robust loss
    /// the whole ride is a last window too, so that it is also reached by
    /// least squares first (see `Model::least_squares`), and so is it after
    /// anchored windows: the ride's last stretch is fitted as one more
    /// anchored window before the whole ride is swept. Without it the whole
    /// ride started from the last stretch's dead reckoning (a 30-minute
    /// ride: 289 s of it, 56 m RMS from the fixes) and took three whole-ride
    /// iterations to come back; the stretch's own window takes four on the
    /// coarse ride, at a twentieth of the cost.
    fn next_window(&self, length: f64) -> Result<Option<Window>, FitError> {
        let sig = &self.model.signals;
        let whole_done = self
            .window
            .as_ref()
            .is_some_and(|w| w.length >= sig.duration());
        let after_anchored = self.window.as_ref().is_some_and(|w| w.from.is_some());
        if length >= sig.duration()
            && ((self.model.robust_scale().is_none() && !after_anchored) || whole_done)
        {
            return Ok(None);
        }
        let length = length.min(sig.duration());
        let t_end = sig.t[0] + length;
        if let Some(prev) = &self.window
            && prev.length >= ANCHOR_AFTER_S
            && self.windows_fit_segments()
        {
            let from = sig.t[0] + prev.length - ANCHOR_OVERLAP_S;
            if let Some((row, start)) = self.first_segment_from(from) {
                return Ok(Some(Window {
                    length,
                    model: prev
                        .model
                        .window(&self.theta, row - 1, t_end)?
                        .without_suspect_fixes()
                        .least_squares(true),
                    from: Some(start),
                }));
            }
        }
        self.cut_window(length, true).map(Some)
    }

    /// Step 1's window over the ride's first `length` seconds, from row 0.
    fn cut_window(&self, length: f64, least_squares: bool) -> Result<Window, FitError> {
        let source = self.windows_model();
        let model = source
            .restricted(source.signals.t[0] + length)?
            .without_suspect_fixes();
        Ok(Window {
            length,
            model: model.least_squares(least_squares),
            from: None,
        })
    }

    /// The first step and start time of the first segment starting at or after `from`.
    fn first_segment_from(&self, from: f64) -> Option<(usize, f64)> {
        let start = self
            .segment_starts()
            .into_iter()
            .map(|(_, _, start)| start)
            .filter(|&start| start >= from && start.is_finite())
            .min_by(f64::total_cmp)?;
        let t = &self.windows_model().signals.t;
        Some((t.partition_point(|&x| x < start), start))
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    pub fn params(&self) -> &[f64] {
        &self.theta
    }

    pub fn settings(&self) -> &FitSettings {
        &self.settings
    }

    pub fn phase(&self) -> Phase {
        self.phase
    }

    pub fn is_done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// The fitted model and its parameters.
    pub fn into_parts(self) -> (Model, Vec<f64>) {
        (self.model, self.theta)
    }

    /// The noise settings estimated from the ride, if the fit has estimated them.
    pub fn noise(&self) -> Option<&NoiseEstimate> {
        self.noise.as_ref()
    }

    /// Iterations spent in step 1 and step 2.
    pub fn phase_iterations(&self) -> [usize; 2] {
        self.phase_iterations
    }

    pub fn history(&self) -> &[IterationReport] {
        &self.history
    }

    pub fn trajectory(&self) -> Trajectory {
        self.model.trajectory(&self.theta)
    }

    pub fn stats(&self) -> FitStats {
        FitStats::of(&self.model, &self.theta)
    }

    /// Whether step 1 fits segment biases on its widened windows: only with the
    /// random-walk prior, which holds the segments beyond the window (without it
    /// they would be unconstrained there).
    /// With gradient descent as step 2, step 1 stays the paper's constant-bias
    /// fit, so that step 2 has the segment biases to fit.
    fn windows_fit_segments(&self) -> bool {
        self.widened
            && self.settings.method == Method::Lm
            && self.has_segments()
            && self.settings.model.bias_walk_dps_sqrt_s.is_some()
    }

    fn mask(&self, phase: Phase) -> Vec<bool> {
        match (phase, self.settings.method) {
            (Phase::Step1, _) if self.windows_fit_segments() => {
                let from = self.window.as_ref().and_then(|w| w.from);
                // An anchored window fits its own segments only.
                let roles: &[Role] = match from {
                    Some(_) => &[Role::Segments],
                    None => &[Role::Global, Role::Segments],
                };
                let mut free = self.model.free_mask(roles);
                // Only the segments the window reaches: the others have no
                // observation yet.
                if let Some(end) = self.window_end() {
                    for (i, _, started) in self.segment_starts() {
                        free[i] &= started < end && from.is_none_or(|f| started >= f);
                    }
                }
                free
            }
            (Phase::Step1, _) => self.model.free_mask(&[Role::Global, Role::Step1Only]),
            (_, Method::Lm) => {
                self.model
                    .free_mask(&[Role::Global, Role::Segments, Role::Step2Only])
            }
            (_, Method::Gd) => self.model.free_mask(&[Role::Segments, Role::Step2Only]),
        }
    }

    /// Log time where step 1's window ends (`None`: it covers the ride).
    fn window_end(&self) -> Option<f64> {
        self.window
            .as_ref()
            .map(|w| self.model.signals.t[0] + w.length)
    }

    /// Every segment parameter (its index and the index of the first of its
    /// (x, y, z) triple) with the log time of its first step, in the model
    /// step 1's windows are cut from.
    fn segment_starts(&self) -> Vec<(usize, usize, f64)> {
        let model = self.windows_model();
        let t = &model.signals.t;
        let mut out = Vec::new();
        for (e, effect) in model.effects().iter().enumerate() {
            if effect.role() != Role::Segments {
                continue;
            }
            let range = model.range(e);
            for (k, i) in range.clone().enumerate() {
                let first = effect.param_steps(k).map_or(0, |(f, _)| f);
                let start = t.get(first).copied().unwrap_or(f64::INFINITY);
                out.push((i, range.start + k - k % 3, start));
            }
        }
        out
    }

    /// When the window widens: the segments it has not reached yet take the
    /// bias of the last segment it had (the random walk's best guess), so the
    /// newly observed stretch starts from an extrapolation, not from zero.
    fn extrapolate_segments(&mut self, reached: f64) {
        let starts = self.segment_starts();
        // The mean of the last few reached segments: the very last one, at the
        // window's edge, is the least determined.
        let reached_triples: Vec<usize> = starts
            .iter()
            .filter(|(i, triple, t)| *t < reached && i == triple)
            .map(|(_, triple, _)| *triple)
            .collect();
        let tail = &reached_triples[reached_triples.len().saturating_sub(3)..];
        if tail.is_empty() {
            return;
        }
        let mut value = [0.0; 3];
        for &b in tail {
            for a in 0..3 {
                value[a] += self.theta[b + a] / tail.len() as f64;
            }
        }
        for &(i, triple, t) in &starts {
            if t >= reached {
                self.theta[i] = value[i - triple];
            }
        }
    }

    fn has_segments(&self) -> bool {
        self.model
            .effects()
            .iter()
            .any(|e| e.role() == Role::Segments)
    }

    /// One iteration of the current phase. Does nothing once the fit is done.
    pub fn iterate(&mut self) -> Option<IterationReport> {
        let phase = self.phase;
        // Only the last iteration's is kept: a noise search (which rebuilds
        // the model) or a window's iteration leaves none. A call on a done
        // fit (as `finish` makes last) leaves the last one as it is.
        if phase != Phase::Done {
            self.last_linearisation = None;
        }
        let slot = match phase {
            Phase::Step1 => 0,
            Phase::Step2 => 1,
            Phase::Noise => return Some(self.estimate_noise()),
            Phase::Done => return None,
        };
        let free = self.mask(phase);
        let tol = self.settings.tolerance;
        // Whether the iteration runs on a step-1 window's model, not the
        // whole ride's (whose evaluation is then the ride's own).
        let window = matches!((&self.window, phase), (Some(_), Phase::Step1));
        // The system this iteration stepped on (a whole-ride LM iteration's),
        // and whether it came from the coarse ride.
        let mut made: Option<Linearised> = None;
        let mut from_coarse = false;
        let outcome = if phase == Phase::Step2 && self.settings.method == Method::Gd {
            let scale: Vec<f64> = self
                .model
                .param_infos()
                .iter()
                .map(|(_, p)| p.scale)
                .collect();
            gd::iterate(
                &self.model,
                &mut self.theta,
                &free,
                &scale,
                &mut self.gd,
                tol,
            )
        } else if free.iter().any(|&f| f) {
            let model = match (&self.window, phase) {
                (Some(w), Phase::Step1) => &w.model,
                _ => &self.model,
            };
            // A window that will be widened only has to bring the fit into the
            // right basin; the next window refines it. A refit that ends on a
            // met model keeps its own tolerance for both tests.
            let near_enough = window || (self.ends_on_a_met_model && self.stage_iterations >= 1);
            let tol = if window {
                tol.max(WINDOW_TOLERANCE)
            } else {
                tol
            };
            // A system given for the start serves only the iteration it was
            // made for: the same parameters free, at the same point.
            let start = self.start_system.take().filter(|c| {
                phase == Phase::Step2 && crate::model::free_columns(&free) == c.columns()
            });
            from_coarse = std::mem::take(&mut self.derivatives.handed) && start.is_some();
            lm::iterate(
                start,
                model,
                &mut self.theta,
                &free,
                &mut self.lm,
                tol,
                near_enough,
                (!window).then_some(&mut made),
            )
        } else {
            let c = self.model.cost(&self.theta);
            StepOutcome {
                cost_before: c,
                cost: c,
                accepted: false,
                converged: true,
                evaluations: 1,
                evaluation: None,
            }
        };
        self.iteration += 1;
        self.phase_iterations[slot] += 1;
        self.stage_iterations += 1;
        let stage_done = outcome.converged || self.stage_iterations >= self.settings.max_iter;
        // Step 2's next iteration takes its derivatives from the coarse ride
        // (the system just made is let go first, unless it is kept: a fold's
        // refit held two at a time).
        self.coarse_iterations += usize::from(from_coarse);
        // Only once the steps are small: the correction holds to second order
        // in how far the fit moves from the anchor.
        let coarse_next = self.coarse_derivatives
            && phase == Phase::Step2
            && outcome.accepted
            && !stage_done
            && outcome.cost_before - outcome.cost <= derivatives::SMALL_GAIN * outcome.cost;
        if coarse_next && let Some(last) = &made {
            self.derivatives.anchor(&self.model, last, from_coarse);
        }
        if self.keeps_linearisation && !window {
            self.last_linearisation = made;
        } else {
            drop(made);
        }
        if coarse_next && let Some(ev) = &outcome.evaluation {
            self.start_system = self
                .derivatives
                .system(&self.model, &self.theta, &ev.observed);
            self.derivatives.handed = self.start_system.is_some();
        }
        if phase == Phase::Step1
            && stage_done
            && let Some(window) = self
                .window
                .take_if(|w| w.model.is_least_squares() && self.model.robust_scale().is_some())
        {
            // The window's least-squares optimum reached: the same window
            // again under the robust loss (see `Model::least_squares`).
            self.window = Some(Window {
                model: window.model.least_squares(false),
                ..window
            });
            self.stage_iterations = 0;
            self.lm = LmState::new(self.settings.damping);
            return Some(self.report(phase, outcome, false));
        }
        if phase == Phase::Step1
            && let Some(window) = &self.window
            && stage_done
        {
            // Widen the window and keep fitting step 1.
            let length = window.length;
            // By half, but by at most five minutes at a time: dead reckoning
            // with a drifting bias over a longer unseen stretch can start LM
            // in the wrong basin.
            let anchored = window.from.is_some();
            if let Ok(next) = self.next_window((1.5 * length).min(length + MAX_WIDENING_S)) {
                let damping = if anchored && next.is_none() {
                    self.settings.damping * WHOLE_AFTER_ANCHORED_DAMPING
                } else {
                    self.settings.damping
                };
                if self.windows_fit_segments() {
                    let reached = self.model.signals.t[0] + length;
                    self.extrapolate_segments(reached);
                }
                if next.is_none() {
                    self.coarse = None;
                }
                self.window = next;
                self.widened = true;
                self.stage_iterations = 0;
                self.lm = LmState::new(damping);
                // The whole ride with step 2's parameters free is step 2:
                // fitted as step 1 and then confirmed by a step 2 of one
                // iteration, it was swept once more to find nothing to gain.
                let into_step2 = self.window.is_none()
                    && self.has_segments()
                    && self.mask(Phase::Step1) == self.mask(Phase::Step2);
                if into_step2 {
                    self.phase = Phase::Step2;
                }
                return Some(self.report(phase, outcome, into_step2));
            }
        }
        if stage_done {
            // The coarse ride's derivatives serve one stage (the next has
            // other weights or parameters): not held through the noise search
            // and the uncertainty.
            self.derivatives.reset();
            self.stage_iterations = 0;
            self.phase = match phase {
                Phase::Step1 if self.has_segments() => Phase::Step2,
                Phase::Step2 if self.wants_noise() || self.wants_tails() => Phase::Noise,
                _ => Phase::Done,
            };
            // A gain check cut short (a round of tails broke a physical
            // limit) ends on the Gaussian fit it set aside, not the tails'.
            let set_aside = self.phase == Phase::Done && self.gaussian_back().is_some();
            if set_aside {
                self.last_linearisation = None;
            }
            // The next stage starts where this one converged: step 2 after
            // step 1's whole-ride window (which fitted the same parameters),
            // and step 2 after the noise search (the same path under new
            // weights). The cost is quadratic to the digits there, so the
            // damping this stage ended with is kept: from the setting's 1e-3
            // the step 2 after the search took 7 iterations on a 30-minute
            // ride, each gaining a fifth of the one before. A step that does
            // not lower the cost still raises it.
            self.gd = GdState::new(self.settings.step_size);
            if !window && !set_aside && outcome.evaluation.is_some() {
                return Some(self.report_evaluated(phase, outcome));
            }
        }
        Some(self.report(phase, outcome, stage_done))
    }

    /// The tails learnt anew after the next noise search (which is searched
    /// under the Gaussian law, as a fresh fit's is), if asked for.
    fn reset_tails(&mut self, auto: AutoNoise) {
        self.tail_rounds = 0;
        self.tails_done = !auto.learns_tails();
        self.tails = None;
        self.tail_summary = None;
        self.gaussian_fit = None;
        self.calibration.clear();
    }

    /// Whether the noise search is still to run: asked for, not yet run on
    /// this model, and a model with segment biases (the bias walk and the GPS
    /// noise are only told apart through them).
    /// A fit that breaks a physical limit (see [`crate::limits`])
    /// is not searched: a loose bias walk would let the segment biases hide
    /// what is wrong (wrong axes, units), and the fit must fail with its cause.
    fn wants_noise(&self) -> bool {
        self.settings.auto_noise.any()
            && !self.noise_done
            && self.has_segments()
            && crate::limits::parameters(&self.model, &self.theta).is_empty()
    }

    /// Whether a round of tail weights is still to run: after the noise
    /// search, with the GPS noise automatic (the tails are part of the GPS
    /// error law the fit learns; `diagnose` ranks under the law as set),
    /// and no robust loss (which answers the same tails; see `Model`).
    fn wants_tails(&self) -> bool {
        self.settings.auto_noise.learns_tails()
            && self.noise_done
            && !self.tails_done
            && self.model.robust_scale().is_none()
            && self.has_segments()
            && crate::limits::parameters(&self.model, &self.theta).is_empty()
    }

    /// The spec the fit runs: `spec` with the estimated noise in place of
    /// the settings `auto` covers, the tails learnt (while they only check
    /// the gain, until they have) and what that check holds.
    fn effective_spec(&self, spec: &ModelSpec, auto: AutoNoise) -> ModelSpec {
        let mut spec = match &self.noise {
            Some(n) => n.apply(spec, auto),
            None => spec.clone(),
        };
        if auto.learns_tails() {
            spec.gps_tails = self.tails.clone();
            spec.held = self.calibration.iter().filter_map(|c| c.hold()).collect();
        }
        spec
    }

    /// The noise estimate in force told the tails' summary and the gain's
    /// check as they now stand.
    fn refresh_noise(&mut self) {
        if let Some(n) = &mut self.noise {
            n.gps_tails = self.tail_summary.clone();
            n.calibration = self.calibration.clone();
        }
    }

    /// The noise phase's one iteration: search the likelihood, rebuild the
    /// model with what it prefers and go back to step 2.
    fn estimate_noise(&mut self) -> IterationReport {
        if self.noise_done {
            return self.estimate_tails();
        }
        self.noise_done = true;
        let free = self
            .model
            .free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        let before = self.model.cost(&self.theta);
        let found = noise::estimate_with_linearisation(
            &self.model,
            &self.theta,
            &free,
            self.settings.auto_noise,
        );
        let mut outcome = StepOutcome {
            cost_before: before,
            cost: before,
            accepted: false,
            converged: true,
            evaluations: found.as_ref().map_or(0, |(n, _)| n.evaluations),
            evaluation: None,
        };
        if let Some((n, base)) = found {
            self.noise = Some(n);
            self.refresh_noise();
            let searched_at = self.theta.clone();
            self.rebuild(&mut outcome);
            // Step 2 resumes at the same point: its first system is the
            // search's linearisation under the settings found (where the
            // robust filter's weights do not move with them), not a sweep.
            if self.model.robust_scale().is_none() && self.theta == searched_at {
                self.start_system =
                    base.and_then(|b| self.model.chain_system_like(&b, &self.theta));
            }
        }
        self.iteration += 1;
        self.phase = Phase::Step2;
        self.phase_iterations[1] = 0;
        self.report(Phase::Noise, outcome, true)
    }

    /// A round of the tails' weights (see [`noise::tails`]): the weights at
    /// their expectation given the fit's innovations and back to step 2,
    /// under the noise settings the Gaussian search chose; or, where the
    /// ride's innovations do not ask for heavy tails or the weights have
    /// settled, the fit is done.
    fn estimate_tails(&mut self) -> IterationReport {
        let before = self.model.cost(&self.theta);
        let mut outcome = StepOutcome {
            cost_before: before,
            cost: before,
            accepted: false,
            converged: true,
            evaluations: 0,
            evaluation: None,
        };
        self.iteration += 1;
        let found = noise::tails::estimate(&self.model, &self.theta, self.tails.is_some());
        let next = found.filter(|(_, t)| {
            self.tail_rounds < MAX_TAIL_ROUNDS
                && noise::tails::change(self.tails.as_ref(), Some(t)) > TAILS_SETTLED
        });
        let Some((fit, tails)) = next else {
            self.tails_done = true;
            if !self.settings.auto_noise.tails {
                return self.check_calibration(outcome);
            }
            self.phase = Phase::Done;
            return self.report(Phase::Noise, outcome, true);
        };
        if !self.settings.auto_noise.tails && self.gaussian_fit.is_none() {
            self.gaussian_fit = Some((self.theta.clone(), self.phase_iterations[1]));
        }
        self.tail_rounds += 1;
        self.tails = Some(tails);
        let summary = noise::tails::TailSummary {
            nu: fit.nu,
            // The evidence that chose the tails: the first round's.
            gain: self.tail_summary.as_ref().map_or(fit.gain, |s| s.gain),
            rounds: self.tail_rounds,
            down_weighted: self
                .tails
                .as_ref()
                .map_or(0, |t| t.scale.iter().filter(|&&f| f >= 2.0).count()),
        };
        self.tail_summary = Some(summary);
        self.refresh_noise();
        self.rebuild(&mut outcome);
        self.phase = Phase::Step2;
        self.phase_iterations[1] = 0;
        self.report(Phase::Noise, outcome, true)
    }

    /// The end of the gain's check (see [`noise::calibration`]): the
    /// heavy-tailed fit's gain against the Gaussian fit's. Back to the
    /// Gaussian fit as it was; where the test holds the heavy-tailed gain,
    /// one more step 2 under the Gaussian law with the gain held there. A
    /// ride whose innovations did not ask for heavy tails never left the
    /// Gaussian fit.
    fn check_calibration(&mut self, mut outcome: StepOutcome) -> IterationReport {
        let Some((robust, robust_theta)) = self.gaussian_back() else {
            self.phase = Phase::Done;
            return self.report(Phase::Noise, outcome, true);
        };
        self.calibration =
            noise::calibration::check(&self.model, &self.theta, &robust, &robust_theta);
        self.refresh_noise();
        outcome.cost = self.model.cost(&self.theta);
        outcome.accepted = true;
        let held = self.calibration.iter().any(|c| c.held);
        if held {
            self.rebuild(&mut outcome);
            self.phase = Phase::Step2;
            self.phase_iterations[1] = 0;
        } else {
            self.phase = Phase::Done;
        }
        self.report(Phase::Noise, outcome, !held)
    }

    /// The Gaussian fit the gain's check set aside, back in force (its
    /// model, parameters and step-2 iterations), the tails dropped from it
    /// and from the noise estimate; returns the heavy-tailed fit it
    /// replaces. `None` (and nothing changed) when no check is under way or
    /// the Gaussian model cannot be rebuilt.
    fn gaussian_back(&mut self) -> Option<(Model, Vec<f64>)> {
        let (theta, iterations) = self
            .gaussian_fit
            .take()
            .filter(|(t, _)| t.len() == self.model.n_params())?;
        let tails = self.tails.take();
        let spec = self.effective_spec(&self.settings.model, self.settings.auto_noise);
        let Ok(gaussian) =
            Model::with_start(self.model.signals.clone(), spec, self.model.start.clone())
        else {
            self.tails = tails;
            return None;
        };
        self.tail_summary = None;
        self.refresh_noise();
        self.phase_iterations[1] = iterations;
        Some((
            std::mem::replace(&mut self.model, gaussian),
            std::mem::replace(&mut self.theta, theta),
        ))
    }

    /// The model rebuilt under the settings now in force (the noise and
    /// tails estimated), the parameters carried over; `outcome` takes the
    /// cost there.
    fn rebuild(&mut self, outcome: &mut StepOutcome) {
        let spec = self.effective_spec(&self.settings.model, self.settings.auto_noise);
        if let Ok(model) =
            Model::with_start(self.model.signals.clone(), spec, self.model.start.clone())
        {
            self.theta = model.carry_over(&self.model, &self.theta);
            self.model = model;
            outcome.cost = self.model.cost(&self.theta);
            outcome.accepted = true;
        }
    }

    fn report(&mut self, phase: Phase, outcome: StepOutcome, finished: bool) -> IterationReport {
        self.report_as(phase, outcome, finished, false)
    }

    /// [`Self::report`] of a finished stage whose outcome holds the whole
    /// ride's evaluation at the parameters it ends on: the ride's RMS is
    /// that evaluation's, not a sweep of the ride again (a validation
    /// fold's refit made three sweeps where two say the same).
    fn report_evaluated(&mut self, phase: Phase, outcome: StepOutcome) -> IterationReport {
        self.report_as(phase, outcome, true, true)
    }

    fn report_as(
        &mut self,
        phase: Phase,
        outcome: StepOutcome,
        finished: bool,
        evaluated: bool,
    ) -> IterationReport {
        // Over the fixes this iteration fitted (in step 1 its window, which the
        // widening may just have replaced: then over the ride).
        let rms_horizontal_m = match (&outcome.evaluation, &self.window, phase) {
            (Some(ev), _, _) => FitStats::from_evaluation(ev),
            (None, Some(w), Phase::Step1) => FitStats::of(&w.model, &self.theta),
            (None, _, _) => FitStats::of(&self.model, &self.theta),
        }
        .rms_horizontal_m;
        let windowed = phase == Phase::Step1 && self.window.is_some();
        let ride_rms_m = match self.ride_rms_m {
            Some(r) if windowed && outcome.evaluation.is_some() && !finished => r,
            _ if evaluated => rms_horizontal_m,
            _ if windowed || finished => FitStats::of(&self.model, &self.theta).rms_horizontal_m,
            _ => rms_horizontal_m,
        };
        self.ride_rms_m = Some(ride_rms_m);
        let report = IterationReport {
            iteration: self.iteration,
            phase,
            method: if phase == Phase::Step1 {
                Method::Lm
            } else {
                self.settings.method
            },
            cost: outcome.cost,
            accepted: outcome.accepted,
            rms_horizontal_m,
            ride_rms_m,
            damping: self.lm.lambda,
            step_size: self.gd.gamma,
            settings_changed: std::mem::take(&mut self.settings_changed),
            phase_finished: finished,
        };
        self.history.push(report.clone());
        report
    }

    /// Iterate until done, reporting each iteration to `observer`.
    pub fn run(&mut self, observer: &mut dyn Observer) {
        while let Some(report) = self.iterate() {
            observer.on_iteration(self, &report);
        }
    }

    /// Change settings between iterations. A changed model (effects, segment
    /// length, prior, noise levels, increment map) is rebuilt on the same start
    /// guess and the current parameters carried over (segment biases are
    /// averaged onto the new segments); new effects send the fit back to step 1,
    /// other changes of a finished fit resume step 2.
    pub fn apply_settings(&mut self, new: FitSettings) -> Result<(), FitError> {
        new.validate()?;
        if new == self.settings {
            return Ok(());
        }
        self.last_linearisation = None;
        self.start_system = None;
        self.derivatives.reset();
        let effects_changed = new.model.effects != self.settings.model.effects;
        if new.auto_noise != self.settings.auto_noise {
            // Asked anew: search again (the estimate stays in force meanwhile
            // for what is still automatic).
            self.noise_done = !new.auto_noise.any();
            self.reset_tails(new.auto_noise);
        }
        if new.model != self.settings.model || new.auto_noise != self.settings.auto_noise {
            if effects_changed || new.model.segment_s != self.settings.model.segment_s {
                self.noise_done = !new.auto_noise.any();
                self.reset_tails(new.auto_noise);
            }
            let spec = self.effective_spec(&new.model, new.auto_noise);
            let model =
                Model::with_start(self.model.signals.clone(), spec, self.model.start.clone())?;
            check_observability(&model)?;
            self.theta = model.carry_over(&self.model, &self.theta);
            self.model = model;
            if self.coarse.is_some() {
                self.coarse = coarse_model(&self.model);
            }
            // Step 1's window was cut from the old model: its parameters no
            // longer match theta's layout (a new segment length changes their
            // number). Cut it again over the same stretch.
            if let Some(w) = &self.window {
                self.window = Some(self.cut_window(w.length, w.model.is_least_squares())?);
            }
        }
        if new.damping != self.settings.damping {
            self.lm = LmState::new(new.damping);
        }
        if new.step_size != self.settings.step_size || new.method != self.settings.method {
            self.gd = GdState::new(new.step_size);
        }
        self.stage_iterations = 0;
        if effects_changed {
            self.phase = Phase::Step1;
            self.phase_iterations = [0, 0];
            self.window = None;
            self.coarse = None;
        } else if self.phase == Phase::Done && self.has_segments() {
            self.phase = Phase::Step2;
            self.phase_iterations[1] = 0;
        }
        self.settings = new;
        self.settings_changed = true;
        Ok(())
    }
}

/// Refuse models with more parameters than residual rows: the fit would be
/// fitting noise (or singular) and the path would look plausible but be wrong.
fn check_observability(model: &Model) -> Result<(), FitError> {
    let rows = model.observations.len();
    let params = model.n_params();
    if rows < params {
        return Err(FitError::TooFewFixes {
            file: model.signals.source.clone(),
            fixes: model.signals.fixes.len(),
            rows,
            params,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::model::ModelSpec;

    /// A channel's bias slopes stay at zero through step 1 (whose short
    /// windows cannot tell them from constant bias) and are fitted in step 2,
    /// by LM and by gradient descent.
    #[test]
    fn step2_only_parameters_wait_for_step_2() {
        let id = "gyro_bias_channel:temp_c";
        let sig = Arc::new(crate::testing::simulated_signals(53, 300.0, &[id]));
        for method in [Method::Lm, Method::Gd] {
            let settings = FitSettings {
                model: ModelSpec {
                    effects: vec!["paper".into(), id.into()],
                    ..ModelSpec::default()
                },
                method,
                ..FitSettings::default()
            };
            let mut fit = Reconstruction::new(sig.clone(), settings).expect("fit");
            let e = fit.model().effect_index(id).expect("channel effect");
            let slopes = fit.model().range(e);
            while fit.phase() == Phase::Step1 {
                fit.iterate();
                assert!(
                    fit.params()[slopes.clone()].iter().all(|&k| k == 0.0),
                    "{method:?}: slopes moved in step 1"
                );
            }
            fit.finish();
            assert!(
                fit.params()[slopes.clone()].iter().any(|&k| k != 0.0),
                "{method:?}: slopes not fitted in step 2"
            );
        }
    }

    /// A new segment length in the middle of step 1 (the app's slider) cuts
    /// the window again: its model once kept the old segments, and LM indexed
    /// the new model's mask past its end.
    #[test]
    fn a_new_segment_length_in_step_1_recuts_the_window() {
        let sig = Arc::new(crate::testing::simulated_signals(5, 900.0, &[]));
        let mut fit = Reconstruction::new(sig, FitSettings::default()).expect("fit");
        while !fit.widened {
            fit.iterate();
        }
        assert!(fit.phase() == Phase::Step1 && fit.window.is_some());
        let mut settings = fit.settings().clone();
        settings.model.segment_s = 10.0;
        fit.apply_settings(settings).expect("settings");
        let n = fit.model().n_params();
        assert_eq!(fit.window.as_ref().map(|w| w.model.n_params()), Some(n));
        fit.finish();
        assert!(fit.stats().rms_horizontal_m < 5.0, "{:?}", fit.stats());
    }
}
