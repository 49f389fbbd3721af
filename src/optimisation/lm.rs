//! Levenberg-Marquardt that cannot diverge (paper eq. 10-11, made safe).
//!
//! One iteration linearises once, then solves
//! `(J^T J + lambda D) delta = -J^T r` with `D = diag(J^T J)` (Marquardt's
//! scaling, floored so unobservable directions stay bounded). A step is
//! accepted only if the cost is finite and lower, by more than round-off;
//! otherwise lambda grows (x nu, nu doubling) and the solve is retried with
//! the same linearisation.
//! After an accepted step lambda shrinks by Nielsen's rule
//! `max(1/3, 1 - (2 rho - 1)^3)`, `rho` = actual / predicted decrease.
//! The paper's LM diverged because it took every step; this one never
//! raises the cost.

use nalgebra::DVector;

use crate::model::{ChainSystem, Evaluation, Model, NormalEquations};

/// Damping state carried between iterations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmState {
    pub lambda: f64,
    nu: f64,
}

impl LmState {
    pub fn new(lambda: f64) -> Self {
        Self {
            lambda: lambda.clamp(LAMBDA_MIN, LAMBDA_MAX),
            nu: 2.0,
        }
    }
}

const LAMBDA_MIN: f64 = 1e-12;
const LAMBDA_MAX: f64 = 1e16;
const MAX_TRIES: usize = 12;
/// A step must lower the cost by more than this share of it: the cost of
/// the linearisation and the trial's evaluation sum the same terms in other
/// orders, and at the minimum they differ in the last digits (1e-15 of the
/// cost), which a plain `new < old` took for a gain step after step (a
/// 60-s winding ride: 200 "accepted" steps at the minimum).
const ROUND_OFF: f64 = 1e-12;

/// Damping (relative to Marquardt's diagonal) below which a step is close
/// to the Gauss-Newton step (see [`iterate`]).
const NEAR_ENOUGH_LAMBDA: f64 = 1e-2;

/// What one iteration did.
#[derive(Clone, Debug, PartialEq)]
pub struct StepOutcome {
    pub cost_before: f64,
    pub cost: f64,
    pub accepted: bool,
    /// No further progress is expected (tiny decrease, or no step lowers the cost).
    pub converged: bool,
    /// Cost evaluations made.
    pub evaluations: usize,
    /// The evaluation of the accepted parameters, when the step made one.
    pub evaluation: Option<Evaluation>,
}

pub use crate::model::damped_solve;

/// The damped Gauss-Newton problem of one iteration: in chain form (O(N)) when
/// the model allows it, else the dense normal equations.
enum LinearSystem {
    Chain(Box<ChainSystem>),
    Dense(NormalEquations),
}

impl LinearSystem {
    fn of(model: &Model, theta: &[f64], free: &[bool]) -> Self {
        match model.chain_system(theta, free) {
            Some(c) => Self::Chain(Box::new(c)),
            None => Self::Dense(model.normal_equations(theta, free)),
        }
    }

    fn cost(&self) -> f64 {
        match self {
            Self::Chain(c) => c.cost(),
            Self::Dense(ne) => ne.cost,
        }
    }

    fn columns(&self) -> &[usize] {
        match self {
            Self::Chain(c) => c.columns(),
            Self::Dense(ne) => &ne.columns,
        }
    }

    fn solve(&self, lambda: f64) -> Option<DVector<f64>> {
        match self {
            Self::Chain(c) => c.solve(lambda),
            Self::Dense(ne) => damped_solve(&ne.a, &-&ne.g, lambda),
        }
    }

    /// `C - ||r + J delta||^2`.
    fn predicted_decrease(&self, delta: &DVector<f64>) -> f64 {
        match self {
            Self::Chain(c) => c.predicted_decrease(delta),
            Self::Dense(ne) => -(2.0 * delta.dot(&ne.g) + delta.dot(&(&ne.a * delta))),
        }
    }
}

/// A linearisation kept from an iteration: the chain system made at `theta`.
///
/// A fit's last iteration linearises the ride at the point it steps from,
/// next to where the fit ends (within its tolerance): a validation can
/// start its folds from there instead of linearising the ride once more.
#[derive(Clone, Debug)]
pub struct Linearised {
    pub theta: Vec<f64>,
    pub system: ChainSystem,
}

/// One LM iteration on the parameters where `free` is true, linearised as
/// `start` where the caller has it (the model's chain system at `theta`
/// over `free`), else here.
///
/// Converged when the step gained at most `tolerance` of the cost or,
/// where the caller only needs the fit near its optimum (`near_enough`),
/// when the step met its quadratic model: a step barely damped
/// (`lambda <=` [`NEAR_ENOUGH_LAMBDA`]) whose actual decrease `a` matched
/// the predicted one to within `|1 - rho| a <= tolerance C` has reached
/// the minimum of a model that holds, and what is left is about that
/// model's error. Step 1's windows each ended on such a step's successor,
/// which gained a few hundredths of what was asked (30-minute ride: 8 of
/// its 34 iterations). Where `keep` is given, the iteration's chain system
/// is left there with the point it was made at.
#[allow(clippy::too_many_arguments)]
pub fn iterate(
    start: Option<ChainSystem>,
    model: &Model,
    theta: &mut [f64],
    free: &[bool],
    state: &mut LmState,
    tolerance: f64,
    near_enough: bool,
    keep: Option<&mut Option<Linearised>>,
) -> StepOutcome {
    let system = match start {
        Some(c) => LinearSystem::Chain(Box::new(c)),
        None => LinearSystem::of(model, theta, free),
    };
    let from = keep.is_some().then(|| theta.to_vec());
    let outcome = step(&system, model, theta, state, tolerance, near_enough);
    if let Some(keep) = keep {
        *keep = match (from, system) {
            (Some(theta), LinearSystem::Chain(c)) => Some(Linearised { theta, system: *c }),
            _ => None,
        };
    }
    outcome
}

/// The tries of one iteration on `system`, linearised at `theta`.
fn step(
    system: &LinearSystem,
    model: &Model,
    theta: &mut [f64],
    state: &mut LmState,
    tolerance: f64,
    near_enough: bool,
) -> StepOutcome {
    let cost = system.cost();
    let entry = *state;
    let mut evaluations = 0;
    let mut trial = theta.to_vec();
    for _ in 0..MAX_TRIES {
        if let Some(delta) = system.solve(state.lambda) {
            for (c, &i) in system.columns().iter().enumerate() {
                trial[i] = theta[i] + delta[c];
            }
            let evaluation = model.evaluate(&trial);
            let new_cost = evaluation.cost;
            evaluations += 1;
            if new_cost.is_finite() && cost - new_cost > ROUND_OFF * cost {
                let predicted = system.predicted_decrease(&delta);
                let rho = if predicted > 0.0 {
                    (cost - new_cost) / predicted
                } else {
                    0.0
                };
                let gained = cost - new_cost;
                let met_its_model = near_enough
                    && state.lambda <= NEAR_ENOUGH_LAMBDA
                    && (1.0 - rho).abs() * gained <= tolerance * new_cost;
                state.lambda = (state.lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3)))
                    .clamp(LAMBDA_MIN, LAMBDA_MAX);
                state.nu = 2.0;
                theta.copy_from_slice(&trial);
                return StepOutcome {
                    cost_before: cost,
                    cost: new_cost,
                    accepted: true,
                    converged: gained <= tolerance * cost || met_its_model,
                    evaluations,
                    evaluation: Some(evaluation),
                };
            }
        }
        state.lambda = (state.lambda * state.nu).clamp(LAMBDA_MIN, LAMBDA_MAX);
        state.nu = (state.nu * 2.0).min(1e6);
    }
    // No step lowered the cost: the fit is at its minimum. The damping is
    // left as it came, not as the failed tries raised it (up to 1e13): the
    // next stage keeps it, and on a 6-hour ride whose step 1 had ended
    // exactly at the minimum, step 2 after the noise search started at
    // 1e13, took one step too short to gain and stopped far from its own
    // minimum, 0.3 m further from the truth.
    *state = entry;
    StepOutcome {
        cost_before: cost,
        cost,
        accepted: false,
        converged: true,
        evaluations,
        evaluation: None,
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::contract::{ModelSpec, Role};
    use crate::signals::Signals;

    /// At the minimum no step lowers the cost: the iteration says so and
    /// leaves the damping as it found it.
    #[test]
    fn a_failed_iteration_leaves_the_damping_as_it_came() {
        let log = crate::testing::winding_log(60.0, 50.0);
        let signals = Arc::new(Signals::from_log(&log).expect("signals"));
        let model = Model::new(signals, ModelSpec::default()).expect("model");
        let mut theta = model.initial_params();
        let free = model.free_mask(&[Role::Global, Role::Step1Only]);
        let mut state = LmState::new(1e-3);
        let mut failed = None;
        for _ in 0..200 {
            let before = state;
            let outcome = iterate(
                None, &model, &mut theta, &free, &mut state, 0.0, false, None,
            );
            if !outcome.accepted {
                failed = Some((before, outcome));
                break;
            }
        }
        let (before, outcome) = failed.expect("an iteration that finds no lower cost");
        assert!(outcome.converged && outcome.evaluations == MAX_TRIES);
        assert_eq!(state, before);
    }
}
