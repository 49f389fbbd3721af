//! The settings panel: segment length, step-2 method, LM damping, GD step
//! size and the bias smoothness prior, all live; and what the view shows.

use crate::model::DEFAULT_BIAS_WALK;
use crate::optimisation::Method;

use super::GyropathApp;

impl GyropathApp {
    /// Fit settings; whether any changed this frame.
    pub(super) fn settings_ui(&mut self, ui: &mut egui::Ui) -> bool {
        ui.heading("Settings");
        let fit = &mut self.settings.fit;
        let mut changed = false;
        changed |= ui
            .add(
                egui::Slider::new(&mut fit.model.segment_s, 1.0..=120.0)
                    .logarithmic(true)
                    .text("segment (s)"),
            )
            .changed();
        ui.horizontal(|ui| {
            ui.label("step 2");
            changed |= ui
                .radio_value(&mut fit.method, Method::Lm, "Levenberg-Marquardt")
                .changed();
            changed |= ui
                .radio_value(&mut fit.method, Method::Gd, "gradient descent")
                .changed();
        });
        changed |= ui
            .add(
                egui::Slider::new(&mut fit.damping, 1e-9..=1e3)
                    .logarithmic(true)
                    .custom_formatter(|v, _| format!("{v:.1e}"))
                    .text("LM damping λ"),
            )
            .changed();
        changed |= ui
            .add(
                egui::Slider::new(&mut fit.step_size, 1e-10..=1e-2)
                    .logarithmic(true)
                    .custom_formatter(|v, _| format!("{v:.1e}"))
                    .text("GD step size γ"),
            )
            .changed();
        let mut prior = fit.model.bias_walk_dps_sqrt_s.is_some();
        if ui
            .checkbox(&mut prior, "bias smoothness prior")
            .on_hover_text(
                "a random-walk prior between neighbouring segment biases; off = the paper",
            )
            .changed()
        {
            fit.model.bias_walk_dps_sqrt_s = prior.then_some(DEFAULT_BIAS_WALK);
            changed = true;
        }
        if let Some(w) = fit.model.bias_walk_dps_sqrt_s.as_mut() {
            changed |= ui
                .add(
                    egui::Slider::new(w, 1e-4..=1e-1)
                        .logarithmic(true)
                        .text("bias walk (deg/s/sqrt(s))"),
                )
                .changed();
        }
        changed
    }

    /// What the plots show (not a fit setting).
    pub(super) fn view_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("View");
        ui.checkbox(
            &mut self.settings.colour_by_residual,
            "colour path by residual",
        );
    }
}
