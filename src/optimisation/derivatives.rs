//! Step 2's derivatives after its first iteration, from the ride in coarse
//! steps.
//!
//! An LM iteration linearises the whole ride: a sweep of every row that
//! carries the path's derivatives (on a 20-minute ride at 100 Hz the price
//! of a validation fold). Once a stage has linearised the ride at a point
//! `theta_a` (the anchor), its later iterations take the derivatives from
//! the coarse ride (`Signals::coarse`, steps of about 0.1 s) instead,
//! corrected by what the coarse ride missed at the anchor:
//!
//! `J(theta) ~ J_c(theta) + J(theta_a) - J_c(theta_a)`,
//!
//! with the residuals of the ride itself at `theta` (the step's own
//! evaluation). The error left is `(J - J_c)(theta) - (J - J_c)(theta_a)`,
//! second order in how far the fit moved and how coarse the steps are; the
//! residuals are exact, so the fit still stops where the gradient of the
//! ride's own cost vanishes, to the accuracy of that error. On a validation
//! fold of a 20-minute ride the coarse derivatives alone ended 2 mm from
//! the fold's optimum, the anchor's derivatives alone (a chord step) 14 mm,
//! the corrected ones 0.09 mm, at the same cost to nine digits.

use crate::model::{ChainSystem, DerivativeAnchor, Model};

use super::coarse_model;
use super::lm::Linearised;

/// The largest gain of a step (a fraction of the cost) after which the next
/// iteration takes its derivatives from the coarse ride. Larger steps are
/// still finding the minimum: the next iteration linearises the ride itself
/// (and anchors there), since the correction's error grows with the
/// distance from the anchor. A validation fold's first step gains 2-7 % of
/// its cost (20-minute ride), a fit's step 2 starts with steps of 2 to 27
/// times the cost left after them, then gains a few thousandths.
pub(super) const SMALL_GAIN: f64 = 0.1;

/// The coarse twin of a fit's model and the anchor its derivatives are
/// corrected at.
#[derive(Debug, Default)]
pub(super) struct CoarseDerivatives {
    /// The model on the coarse ride (`None`: not made yet, or none exists
    /// for this ride, see `unavailable`).
    twin: Option<Model>,
    /// No coarse twin exists for the model (a log already in coarse steps).
    unavailable: bool,
    anchor: Option<DerivativeAnchor>,
    /// The system handed to the next iteration came from the coarse ride
    /// (it cannot serve as an anchor).
    pub(super) handed: bool,
}

impl CoarseDerivatives {
    /// Forget the twin and the anchor (the model's effects or parameters
    /// changed).
    pub(super) fn reset(&mut self) {
        *self = Self::default();
    }

    /// Make ready to hand `model`'s next iteration a system from the coarse
    /// ride: its coarse twin, and the anchor at `last` (the iteration just
    /// made: its system and where it was made; `from_coarse`, whether that
    /// system came from here) unless one over the same parameters is held.
    pub(super) fn anchor(&mut self, model: &Model, last: &Linearised, from_coarse: bool) {
        if self.unavailable {
            return;
        }
        let matches = |twin: &Model| {
            twin.spec == model.spec && twin.observations.len() == model.observations.len()
        };
        if !self.twin.as_ref().is_some_and(matches) {
            self.anchor = None;
            self.twin = coarse_model(model);
            self.unavailable = self.twin.is_none();
        }
        let Some(twin) = &self.twin else {
            return;
        };
        // The last system of the ride itself is the anchor: the nearest.
        if !from_coarse {
            self.anchor = model.derivative_anchor(twin, &last.system, &last.theta);
        } else if self
            .anchor
            .as_ref()
            .is_some_and(|a| a.columns() != last.system.columns())
        {
            self.anchor = None;
        }
    }

    /// The system of `model`'s next iteration at `theta`, where its observed
    /// values are `observed`, from the coarse ride (see
    /// [`CoarseDerivatives::anchor`]); `None` where it should linearise the
    /// ride itself.
    pub(super) fn system(
        &self,
        model: &Model,
        theta: &[f64],
        observed: &[f64],
    ) -> Option<ChainSystem> {
        let (twin, anchor) = (self.twin.as_ref()?, self.anchor.as_ref()?);
        model.chain_system_from_coarse(twin, anchor, theta, observed)
    }
}
