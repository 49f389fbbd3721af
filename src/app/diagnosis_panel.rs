//! The diagnosis panel: the missing effects ranked by the held-out error
//! they save, each with its estimate and an Add button.

use super::worker::RideSource;
use super::{Command, GyropathApp};
use crate::diagnosis::{describe_estimates, shown};
use crate::effects::short_model;

impl GyropathApp {
    pub(super) fn diagnosis_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        ui.horizontal(|ui| {
            ui.heading("Diagnosis");
            let idle = self.diagnosing.is_none() && self.snapshot.is_some();
            if ui
                .add_enabled(idle, egui::Button::new("Diagnose"))
                .on_hover_text(
                    "rank the effects the model lacks by how much each lowers the held-out error",
                )
                .clicked()
            {
                commands.push(Command::Diagnose);
            }
            if let Some(p) = &self.diagnosing {
                ui.spinner();
                ui.label(p);
            }
        });
        self.explain_ui(ui, commands);
        let Some(d) = &self.diagnosis else {
            ui.label("Diagnose ranks every effect the model lacks by the held-out error it saves.");
            if self
                .ride
                .as_ref()
                .is_some_and(|r| matches!(r.source, RideSource::Bytes { .. }))
            {
                ui.label(
                    "This sample has nothing missing, so Diagnose finds nothing here: File > Examples has rides with something to find.",
                );
            }
            return;
        };
        let jumps = match d.excluded_fixes {
            0 => String::new(),
            n => format!(" ({n} jumps out)"),
        };
        let to_reference = d.reference.as_ref().map_or(String::new(), |r| {
            format!(", {:.2} m to the reference", r.horizontal.rms_m)
        });
        ui.label(format!(
            "{}: fit {:.3} m, held-out {:.3} m{jumps}{to_reference}",
            short_model(&d.model.join(", ")),
            d.fit_rms_m,
            d.heldout_rms_m
        ))
        .on_hover_text(format!(
            "Refitted under {}, the GPS noise as set in Settings (not the noise estimated from the ride), as the ranking's significance rule was calibrated; so these errors can differ from the model history's, which are of the fit as it runs.",
            d.gps_noise
        ));
        let current = self.snapshot.as_ref().map(|s| s.effects.clone());
        let stale = current.as_ref().is_some_and(|c| *c != d.model);
        if stale {
            ui.label("(for an earlier model: diagnose again)");
        }
        if !d.not_physical.is_empty() {
            let red = egui::Color32::from_rgb(210, 60, 60);
            ui.colored_label(
                red,
                "The model's own fit is not physical: fix the axes or units first (Source panel).",
            );
            for v in &d.not_physical {
                ui.colored_label(red, v);
            }
        }
        egui::ScrollArea::vertical()
            .id_salt("diagnosis-scroll")
            .show(ui, |ui| {
                // The estimates go under each effect's name, wrapped to what
                // is left of the panel: as a column of their own they ran
                // off its right edge, where a narrow panel hid them.
                let with_reference = d.reference.is_some();
                let name_w =
                    (ui.available_width() - if with_reference { 270.0 } else { 200.0 }).max(160.0);
                egui::Grid::new("ranking")
                    .num_columns(if with_reference { 5 } else { 4 })
                    .striped(true)
                    .show(ui, |ui| {
                        for h in ["", "effect (estimate)", "held-out", "drop (t)"] {
                            ui.strong(h);
                        }
                        if with_reference {
                            ui.strong("to ref").on_hover_text(
                                "the model with the effect added, fitted as Fit fits it (the noise from the ride), against the reference track: what Add gives",
                            );
                        }
                        ui.end_row();
                        for c in &d.ranking {
                            let present = current.as_ref().is_some_and(|m| m.contains(&c.effect));
                            if ui
                                .add_enabled(
                                    !present && c.error.is_none(),
                                    egui::Button::new("Add"),
                                )
                                .on_hover_text(format!("add {} and refit", c.effect))
                                .clicked()
                            {
                                commands.push(Command::AddEffect(c.effect.clone()));
                            }
                            let name = if c.significant {
                                egui::RichText::new(format!("{} (significant)", c.effect))
                                    .strong()
                                    .color(egui::Color32::from_rgb(120, 220, 120))
                            } else {
                                egui::RichText::new(&c.effect)
                            };
                            let detail = match &c.error {
                                Some(e) => e.clone(),
                                None => describe_estimates(&c.estimate),
                            };
                            ui.vertical(|ui| {
                                ui.set_max_width(name_w);
                                ui.label(name).on_hover_text(&c.explanation);
                                if !detail.is_empty() {
                                    ui.add(
                                        egui::Label::new(egui::RichText::new(detail).small().weak())
                                            .wrap(),
                                    );
                                }
                            });
                            if c.error.is_some() {
                                ui.label("-");
                                ui.label("-");
                                if with_reference {
                                    ui.label("-");
                                }
                            } else {
                                ui.label(format!("{:.3} m", c.heldout_rms_m));
                                ui.label(format!(
                                    "{:+.1} % ({:.1})",
                                    shown(100.0 * c.drop, 1),
                                    shown(c.t_statistic, 1)
                                ))
                                .on_hover_text(
                                    "drop: how much lower the held-out error is; t: how consistent the gain is across the validation blocks (significant: drop at least 2 % and t at least 3, or at least 10 % and 1.5)",
                                );
                                if with_reference {
                                    ui.label(c.reference.as_ref().map_or("-".to_string(), |r| {
                                        format!("{:.2} m", r.horizontal.rms_m)
                                    }));
                                }
                            }
                            ui.end_row();
                        }
                    });
                if let Some(best) = d.ranking.first().filter(|c| c.significant) {
                    ui.label(format!("Missing: {}: {}", best.effect, best.explanation));
                } else {
                    ui.label(
                        "Nothing significant: no effect lowers the held-out error beyond chance.",
                    );
                }
            });
    }
}
