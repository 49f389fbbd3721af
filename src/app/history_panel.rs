//! The model history panel: every finished fit with its fit and held-out
//! error, charted so the error can be watched falling.

use super::{GyropathApp, plots};
use crate::effects::short_model;

impl GyropathApp {
    pub(super) fn history_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Model history");
        if self.history.is_empty() {
            ui.label(
                "Each finished fit adds a row: change the model or settings and watch the error.",
            );
            return;
        }
        if self
            .history
            .iter()
            .any(|r| r.held_out.is_some() || r.reference_rms_m.is_some())
        {
            plots::history_ui(ui, &self.history, 110.0);
        }
        egui::ScrollArea::vertical()
            .id_salt("history-scroll")
            .show(ui, |ui| {
                let with_reference = self.reference.is_some()
                    || self.history.iter().any(|r| r.reference_rms_m.is_some());
                egui::Grid::new("history")
                    .num_columns(6 + usize::from(with_reference))
                    .striped(true)
                    .show(ui, |ui| {
                        for h in [
                            "model",
                            "segment",
                            "params",
                            "iters",
                            "fit RMS",
                            "held-out RMS",
                        ] {
                            ui.strong(h);
                        }
                        if with_reference {
                            ui.strong("to reference").on_hover_text(
                                "Horizontal RMS distance of the fitted path from the reference track, over the part of the ride it covers: which model is truly better",
                            );
                        }
                        ui.end_row();
                        for row in &self.history {
                            ui.label(short_model(&row.model)).on_hover_text(&row.model);
                            ui.label(format!("{:.1} s", row.segment_s));
                            ui.label(format!("{}", row.params));
                            ui.label(format!("{}", row.iterations));
                            ui.label(format!("{:.3} m", row.fit_rms_m))
                                .on_hover_text(format!(
                                    "Path to the fixes, under {} (this fit's own noise; Diagnose ranks under the noise as set)",
                                    row.gps_noise
                                ));
                            match row.held_out.map(|h| (h.rms_m, h.jumps_left_out)) {
                                Some((h, 0)) => ui.label(format!("{h:.3} m")),
                                Some((h, jumps)) => ui
                                    .label(format!("{h:.3} m ({jumps} out)"))
                                    .on_hover_text(format!(
                                        "{jumps} fixes more than 5 times the median misfit (at least 10 m) from this model's fitted path are GPS jumps, left out of its held-out RMS"
                                    )),
                                None => match &row.held_out_failed {
                                    Some(why) => ui.label("-").on_hover_text(why),
                                    None => ui.label("validating..."),
                                },
                            };
                            if with_reference {
                                ui.label(
                                    row.reference_rms_m
                                        .map_or("-".into(), |r| format!("{r:.3} m")),
                                );
                            }
                            ui.end_row();
                        }
                    });
            });
    }
}
