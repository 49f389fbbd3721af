//! Explain in the app: the Diagnose and Add buttons pressed for the user,
//! until nothing significant is left. Each finished fit is diagnosed, the
//! top significant effect is added as Add adds it (so the model history,
//! the map and the plots follow every model as usual), and each step says in
//! one line what was added and why. Stop ends the loop and keeps the models
//! found so far; the effects can still be changed by hand afterwards. The
//! rule is the command line's (`gyropath explain`, `src/explain.rs`): the
//! ranking's own significance, the same ranking, the same refits.

use super::worker::Request;
use super::{Command, GyropathApp};
use crate::diagnosis::{Diagnosis, describe_estimates};
use crate::optimisation::Phase;

/// At most this many effects are added (as `explain::MAX_ADDED`).
const MAX_ADDED: usize = crate::explain::MAX_ADDED;

/// What a running Explain waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Waiting {
    /// The current model's fit to finish.
    Fit,
    /// The diagnosis of the finished fit.
    Diagnosis,
}

/// One line of what Explain did, and its detail on hover.
#[derive(Clone, Debug, PartialEq)]
pub struct ExplainLine {
    pub text: String,
    pub detail: String,
}

impl ExplainLine {
    pub fn new(text: impl Into<String>, detail: impl Into<String>) -> Self {
        Self {
            text: text.into(),
            detail: detail.into(),
        }
    }
}

/// A running Explain.
#[derive(Clone, Debug, PartialEq)]
pub struct Explaining {
    pub waiting: Waiting,
    /// Effects added so far.
    pub added: Vec<String>,
}

impl GyropathApp {
    /// Start explaining the current model.
    pub(super) fn start_explain(&mut self) {
        if self.snapshot.is_none() {
            self.error = Some("nothing to explain: no ride is fitted".into());
            return;
        }
        self.explain_log = vec![ExplainLine::new(
            "Explain: diagnose, add, refit, again",
            "Diagnose the finished fit, add the top significant effect as Add does, refit, until nothing significant is left",
        )];
        self.explaining = Some(Explaining {
            waiting: Waiting::Fit,
            added: Vec::new(),
        });
        let done = self
            .snapshot
            .as_ref()
            .is_some_and(|s| s.phase == Phase::Done);
        if done && !self.running {
            self.explain_fit_finished();
        } else if !self.running {
            self.worker.send(Request::Run);
        }
    }

    /// Stop explaining; the models found so far stay.
    pub(super) fn stop_explain(&mut self) {
        if self.explaining.take().is_some() {
            self.explain_log.push(ExplainLine::new(
                "stopped",
                "the models found so far stay in the model history",
            ));
        }
    }

    /// A fit finished: if Explain waits for it, diagnose it.
    pub(super) fn explain_fit_finished(&mut self) {
        let Some(e) = self
            .explaining
            .as_mut()
            .filter(|e| e.waiting == Waiting::Fit)
        else {
            return;
        };
        e.waiting = Waiting::Diagnosis;
        self.diagnosing = Some("starting".into());
        self.worker.send(Request::Diagnose);
    }

    /// A diagnosis arrived: add its top significant effect, or end.
    pub(super) fn explain_diagnosed(&mut self, d: &Diagnosis, commands: &mut Vec<Command>) {
        let Some(e) = self
            .explaining
            .as_mut()
            .filter(|e| e.waiting == Waiting::Diagnosis)
        else {
            return;
        };
        if !d.not_physical.is_empty() {
            self.explain_log.push(ExplainLine::new(
                "the fit is no result: Explain stops",
                d.not_physical.join("; "),
            ));
            self.explaining = None;
            return;
        }
        let top = d.ranking.first().filter(|c| c.significant);
        match top {
            Some(c) if e.added.len() < MAX_ADDED => {
                self.explain_log.push(ExplainLine::new(
                    format!(
                        "added {}: held-out {:.3} m, {:.1} % lower (t {:.1})",
                        c.effect,
                        c.heldout_rms_m,
                        100.0 * c.drop,
                        c.t_statistic
                    ),
                    format!(
                        "{}; held-out error under {}. {}",
                        describe_estimates(&c.estimate),
                        d.gps_noise,
                        c.explanation
                    ),
                ));
                e.added.push(c.effect.clone());
                e.waiting = Waiting::Fit;
                commands.push(Command::AddEffect(c.effect.clone()));
            }
            Some(_) => {
                self.explain_log.push(ExplainLine::new(
                    format!("stopped after {MAX_ADDED} effects"),
                    "more effects than one ride can show: look at the model history",
                ));
                self.explaining = None;
            }
            None => {
                self.explain_log.push(ExplainLine::new(
                    format!("nothing more is significant (held-out {:.3} m)", d.heldout_rms_m),
                    format!(
                        "no catalogue effect lowers the held-out error beyond chance; held-out error under {}",
                        d.gps_noise
                    ),
                ));
                self.explaining = None;
            }
        }
    }

    /// The Explain button (or Stop) and the loop's lines.
    pub(super) fn explain_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        ui.horizontal(|ui| {
            if self.explaining.is_some() {
                ui.spinner();
                if ui
                    .button("Stop explaining")
                    .on_hover_text("end the loop; the models found so far stay")
                    .clicked()
                {
                    commands.push(Command::StopExplain);
                }
            } else if ui
                .add_enabled(
                    self.snapshot.is_some() && self.diagnosing.is_none(),
                    egui::Button::new("Explain"),
                )
                .on_hover_text(
                    "diagnose, add the top significant effect, refit, until nothing significant is left",
                )
                .clicked()
            {
                commands.push(Command::Explain);
            }
        });
        for line in &self.explain_log {
            ui.label(&line.text).on_hover_text(&line.detail);
        }
    }
}
