//! The fit panel: run, pause, step, reset; where the fit stands; the fitted
//! parameters and the ride's warnings.

use crate::optimisation::Phase;

use super::{Command, GyropathApp};

impl GyropathApp {
    /// Fit controls and state.
    pub(super) fn fit_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        ui.heading("Fit");
        ui.horizontal(|ui| {
            let can = self.snapshot.is_some();
            if self.running {
                if ui.button("Pause").clicked() {
                    commands.push(Command::Pause);
                }
            } else if ui.add_enabled(can, egui::Button::new("Run")).clicked() {
                commands.push(Command::Run);
            }
            if ui
                .add_enabled(can, egui::Button::new("Step once"))
                .clicked()
            {
                commands.push(Command::Step);
            }
            if ui.add_enabled(can, egui::Button::new("Reset")).clicked() {
                commands.push(Command::Reset);
            }
        });
        ui.checkbox(&mut self.settings.auto_run, "run on load");
        if let Some(s) = &self.snapshot {
            let last = s.history.last();
            let phase = match s.phase {
                Phase::Step1 => "step 1 (constant bias, start, gain)",
                Phase::Step2 => "step 2 (segment biases)",
                Phase::Noise => "noise settings from the data",
                Phase::Done => "done",
            };
            egui::Grid::new("fit-state").num_columns(2).show(ui, |ui| {
                ui.label("phase");
                ui.label(phase);
                ui.end_row();
                ui.label("iteration");
                ui.label(format!("{}", last.map_or(0, |r| r.iteration)));
                ui.end_row();
                ui.label("cost");
                ui.label(format!("{:.6e}", s.stats.cost));
                ui.end_row();
                ui.label("GPS RMS");
                ui.label(format!("{:.3} m", s.stats.rms_horizontal_m))
                    .on_hover_text(format!(
                        "The path's RMS distance from the fixes, under {}",
                        s.gps_noise
                    ));
                ui.end_row();
                ui.label("along / cross");
                ui.label(format!(
                    "{:.2} / {:.2} m",
                    s.residual_rms.along_m, s.residual_rms.cross_m
                ));
                ui.end_row();
                if let Some(up) = s.residual_rms.up_m {
                    ui.label("vertical");
                    ui.label(format!("{up:.2} m"));
                    ui.end_row();
                }
                ui.label("segments");
                ui.label(format!("{}", s.segments.len()));
                ui.end_row();
                ui.label("parameters");
                ui.label(format!("{}", s.n_params));
                ui.end_row();
            });
            // Below the grid, wrapped: the law in words can be longer than
            // the panel is wide (a grid's cell would widen the panel).
            ui.add(egui::Label::new(format!("GPS error law: {}", s.gps_noise)).wrap());
            if s.phase == Phase::Done && !s.violations.is_empty() {
                let red = egui::Color32::from_rgb(210, 60, 60);
                ui.colored_label(red, "Not physical: this fit is no result.");
                for v in &s.violations {
                    ui.colored_label(red, v);
                }
            }
        }
    }

    /// The fitted global parameters and the ride's warnings.
    pub(super) fn parameters_ui(&self, ui: &mut egui::Ui) {
        if let Some(s) = &self.snapshot {
            ui.separator();
            ui.heading("Parameters");
            egui::Grid::new("params")
                .num_columns(3)
                .striped(true)
                .show(ui, |ui| {
                    for (k, (effect, name, value, unit)) in s.params.iter().enumerate() {
                        ui.label(effect);
                        ui.label(name);
                        let sigma = s
                            .sigma
                            .as_ref()
                            .and_then(|u| u.params.get(k).copied().flatten());
                        ui.label(crate::effects::plus_minus(*value, sigma, unit, 5));
                        ui.end_row();
                    }
                });
        }
        if let Some(r) = &self.ride
            && !r.warnings.is_empty()
        {
            ui.separator();
            ui.heading("Warnings");
            for w in &r.warnings {
                ui.label(w);
            }
        }
    }
}
