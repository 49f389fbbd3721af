//! The find-the-missing-effect loop in one call, as a user runs it by hand
//! with Diagnose and Add: fit the model, rank the effects it lacks, add the
//! top significant one, refit, and again, until nothing significant is left
//! or a fit is no result (a physical limit, see [`crate::limits`]), which
//! ends the loop with the last good model.
//!
//! Each step keeps what a user needs to trust it: the effect added, its
//! estimate with its 1-sigma, the held-out error it reached and its drop
//! with the significance figure (all three under the ranking's noise, as
//! `diagnose` measures them), the refitted model's own error to the fixes
//! and to a reference track when one is given, and the time taken.
//!
//! The measurements and the history behind these choices: docs/command-
//! line.md (`gyropath explain`) and docs/app.md (the Explain button).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use crate::diagnosis::{Diagnosis, Estimate, Folds, ReferenceComparison, diagnose_fitted_against};
use crate::optimisation::{FitError, FitSettings, Reconstruction};
use crate::pipeline::{self, MatchedReference};
use crate::signals::Signals;

/// At most this many effects are added: more than the catalogue's that can
/// apply to one ride, so the loop ends by itself first.
pub const MAX_ADDED: usize = 8;

/// One step of the loop: the base fit (nothing added) or one effect added.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Step {
    /// The model's effects after this step.
    pub model: Vec<String>,
    /// The effect this step added (`None` for the base model).
    pub added: Option<String>,
    /// The added effect's estimate per parameter, with its 1-sigma.
    pub estimate: BTreeMap<String, Estimate>,
    /// Held-out error (m) under the ranking's noise: the base model's, or
    /// the added effect's as the ranking measured it (`None`: the ride
    /// could not be validated).
    pub heldout_rms_m: Option<f64>,
    /// `1 - held-out / previous held-out` (0 for the base).
    pub drop: f64,
    /// The ranking's paired t of the gain (0 for the base).
    pub t_statistic: f64,
    /// The refitted model's RMS distance from the fixes (m), under the
    /// noise it estimates from the ride (`gps_noise`).
    pub fit_rms_m: f64,
    /// The GPS error law `fit_rms_m` is measured under.
    pub gps_noise: String,
    /// The refitted model against the reference track, when one is given.
    pub reference: Option<ReferenceComparison>,
    /// Seconds this step took (its diagnosis and refit).
    pub elapsed_s: f64,
}

/// Why the loop stopped.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "reason")]
pub enum Ending {
    /// No catalogue effect lowers the held-out error beyond chance.
    NothingSignificant,
    /// The fit with the next effect is no result (its failure message);
    /// the model before it is kept.
    NoResult(String),
    /// [`MAX_ADDED`] effects were added.
    StepLimit,
    /// The ride cannot be validated (too short to withhold anything: the
    /// reason); the model so far is kept, unjudged.
    CannotValidate(String),
}

/// The loop's record: every step, why it ended, and the last diagnosis.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Explanation {
    pub steps: Vec<Step>,
    pub ending: Ending,
    /// The diagnosis of the final model (the ranking that found nothing
    /// more), when the loop got that far.
    pub last_diagnosis: Option<Diagnosis>,
}

/// A model saved for the next rides of the same sensor: what
/// `gyropath explain --save-model` writes and `gyropath fit --model` reads.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SavedModel {
    /// The ride it was explained on.
    pub source: String,
    /// The effects and settings.
    pub model: crate::model::ModelSpec,
}

impl SavedModel {
    /// The model of a finished fit.
    pub fn of(fit: &Reconstruction) -> Self {
        Self {
            source: fit.model().signals.source.clone(),
            model: fit.model().spec.clone(),
        }
    }
}

/// What the loop reports as it works.
pub enum Progress<'a> {
    /// A line of work in progress ("tried gps_lag (2 of 4)").
    Working(&'a str),
    /// A step finished.
    Step(&'a Step),
}

/// Run the loop on `signals` from `settings`' model. Returns the record and
/// the final fit (the last that is a result). An error only when the base
/// model itself cannot be fitted (a base fit that is no result ends the loop
/// at once, with the reason, as [`Ending::NoResult`]).
pub fn explain(
    signals: Arc<Signals>,
    settings: &FitSettings,
    folds: &Folds,
    reference: Option<&MatchedReference>,
    observer: &(dyn Fn(Progress) + Sync),
) -> Result<(Explanation, Reconstruction), FitError> {
    let started = Instant::now();
    observer(Progress::Working("fitting the model"));
    let mut settings = settings.clone();
    let mut current = Reconstruction::new(signals.clone(), settings.clone())?;
    current.finish();
    let mut steps = vec![step_of(&current, None, reference, started)];
    if let Some(failure) = pipeline::failure(&current) {
        observer(Progress::Step(&steps[0]));
        let explanation = Explanation {
            steps,
            ending: Ending::NoResult(failure),
            last_diagnosis: None,
        };
        return Ok((explanation, current));
    }
    let progress = |line: &str| observer(Progress::Working(line));
    for _ in 0..MAX_ADDED {
        let started = Instant::now();
        let diagnosis = match diagnose_fitted_against(
            current.model(),
            current.params(),
            &settings,
            folds,
            reference.map(|(t, m)| (t, m)),
            &progress,
        ) {
            Ok(d) => d,
            // A clip too short to validate still has its path: keep the fit.
            Err(e @ FitError::TooShortToValidate { .. }) => {
                if steps.len() == 1 {
                    observer(Progress::Step(&steps[0]));
                }
                let explanation = Explanation {
                    steps,
                    ending: Ending::CannotValidate(e.to_string()),
                    last_diagnosis: None,
                };
                return Ok((explanation, current));
            }
            Err(e) => return Err(e),
        };
        if steps.len() == 1 {
            // The base step is told once its held-out error is known.
            steps[0].heldout_rms_m = Some(diagnosis.heldout_rms_m);
            observer(Progress::Step(&steps[0]));
        }
        let Some(top) = diagnosis.ranking.first().filter(|c| c.significant).cloned() else {
            let explanation = Explanation {
                steps,
                ending: Ending::NothingSignificant,
                last_diagnosis: Some(diagnosis),
            };
            return Ok((explanation, current));
        };
        observer(Progress::Working(&format!("adding {}", top.effect)));
        let mut next_settings = settings.clone();
        next_settings.model.effects.push(top.effect.clone());
        let mut next = Reconstruction::new(signals.clone(), next_settings.clone())?;
        next.finish();
        if let Some(failure) = pipeline::failure(&next) {
            let explanation = Explanation {
                steps,
                ending: Ending::NoResult(failure),
                last_diagnosis: Some(diagnosis),
            };
            return Ok((explanation, current));
        }
        let mut step = step_of(&next, Some(top.effect.clone()), reference, started);
        step.estimate = top.estimate.clone();
        step.heldout_rms_m = Some(top.heldout_rms_m);
        step.drop = top.drop;
        step.t_statistic = top.t_statistic;
        observer(Progress::Step(&step));
        steps.push(step);
        settings = next_settings;
        current = next;
    }
    let explanation = Explanation {
        steps,
        ending: Ending::StepLimit,
        last_diagnosis: None,
    };
    Ok((explanation, current))
}

/// The record of a finished fit (the ranking's figures are filled in by the caller).
fn step_of(
    fit: &Reconstruction,
    added: Option<String>,
    reference: Option<&MatchedReference>,
    started: Instant,
) -> Step {
    let model = fit.model();
    Step {
        model: model.effect_ids(),
        added,
        estimate: BTreeMap::new(),
        heldout_rms_m: None,
        drop: 0.0,
        t_statistic: 0.0,
        fit_rms_m: fit.stats().rms_horizontal_m,
        gps_noise: model.spec.gps_noise_text(),
        reference: reference.map(|(track, matched)| {
            crate::diagnosis::reference::compare(model, fit.params(), track, matched)
        }),
        elapsed_s: started.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The loop with the defaults on a simulated ride.
    fn explained(seed: u64, duration_s: f64, hidden: &[&str]) -> (Explanation, Reconstruction) {
        let sig = Arc::new(crate::testing::simulated_signals(seed, duration_s, hidden));
        explain(
            sig,
            &FitSettings::default(),
            &Folds::default(),
            None,
            &|_: Progress| {},
        )
        .expect("the base fit stands")
    }

    /// Ten seconds make two 5 s blocks, both ends: nothing can be withheld.
    /// The loop keeps the base fit and says why it could not judge it.
    #[test]
    fn a_ride_too_short_to_validate_keeps_its_base_fit() {
        let (e, fit) = explained(3, 10.0, &[]);
        assert_eq!(e.steps.len(), 1);
        assert_eq!(e.steps[0].heldout_rms_m, None);
        let Ending::CannotValidate(why) = &e.ending else {
            panic!("{:?}", e.ending);
        };
        assert!(why.contains("too short to validate"), "{why}");
        assert!(fit.stats().rms_horizontal_m.is_finite());
    }

    #[test]
    fn a_hidden_gps_lag_is_found_added_and_the_loop_then_stops() {
        let (e, fit) = explained(21, 600.0, &["gps_lag"]);
        assert_eq!(e.steps[0].added, None);
        assert!(e.steps[0].heldout_rms_m.is_some_and(f64::is_finite));
        let added: Vec<&str> = e.steps.iter().filter_map(|s| s.added.as_deref()).collect();
        assert_eq!(added.first(), Some(&"gps_lag"), "{added:?}");
        let lag = &e.steps[1].estimate["lag"];
        assert!(lag.value > 0.0 && lag.sigma > 0.0, "{lag:?}");
        assert!(e.steps[1].drop > 0.02 && e.steps[1].heldout_rms_m < e.steps[0].heldout_rms_m);
        assert_eq!(e.ending, Ending::NothingSignificant);
        assert!(fit.model().effect_ids().contains(&"gps_lag".to_string()));
    }
}
