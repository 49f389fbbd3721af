//! Gradient descent on the per-segment biases (paper eq. 8-9), with a guard.
//!
//! `b <- b - gamma dC/db`, with `b` in the units it is shown in (deg/s), so
//! `gamma` means the same on every ride of similar length. The paper takes
//! every step; here a step that raises the cost (or makes it non-finite) is
//! rejected and the working step size halves, and each accepted step grows
//! it by 20 %, so a too-large `gamma` costs a few rejected iterations instead
//! of a divergence.

use crate::model::Model;

use super::lm::StepOutcome;

/// Step-size state carried between iterations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GdState {
    /// Working step size (starts at the user's gamma).
    pub gamma: f64,
    /// Consecutive accepted steps with a tiny decrease.
    flat: usize,
}

impl GdState {
    pub fn new(gamma: f64) -> Self {
        Self { gamma, flat: 0 }
    }
}

/// One gradient step on the parameters where `free` is true; `scale[i]` is
/// the display scale of parameter `i` (step taken in displayed units).
pub fn iterate(
    model: &Model,
    theta: &mut [f64],
    free: &[bool],
    scale: &[f64],
    state: &mut GdState,
    tolerance: f64,
) -> StepOutcome {
    let (cost, grad) = model.gradient(theta);
    let mut trial = theta.to_vec();
    for i in 0..theta.len() {
        if free[i] {
            trial[i] = theta[i] - state.gamma * grad[i] / (scale[i] * scale[i]);
        }
    }
    let new_cost = model.cost(&trial);
    if new_cost.is_finite() && new_cost < cost {
        theta.copy_from_slice(&trial);
        state.gamma *= 1.2;
        if cost - new_cost <= tolerance * cost {
            state.flat += 1;
        } else {
            state.flat = 0;
        }
        StepOutcome {
            cost_before: cost,
            cost: new_cost,
            accepted: true,
            converged: state.flat >= 5,
            evaluations: 2,
            evaluation: None,
        }
    } else {
        state.gamma *= 0.5;
        StepOutcome {
            cost_before: cost,
            cost,
            accepted: false,
            converged: state.gamma < 1e-30,
            evaluations: 2,
            evaluation: None,
        }
    }
}
