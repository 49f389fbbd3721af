//! The settings panel: segment length, step-2 method, LM damping, GD step
//! size and the bias smoothness prior, all live; and what the view shows.

use crate::model::DEFAULT_BIAS_WALK;
use crate::optimisation::{Limit, Method};

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
        changed |= ui
            .checkbox(&mut fit.auto_noise.gps, "GPS noise from the ride")
            .on_hover_text(
                "estimate the GPS error's wander (sigma, correlation time) and jitter by \
                 restricted marginal likelihood once step 2 has converged; off = set them here",
            )
            .changed();
        if fit.auto_noise.gps {
            changed |= ui
                .checkbox(&mut fit.auto_noise.tails, "heavy tails from the ride")
                .on_hover_text(
                    "where the fit's innovations ask for it, a Student-t GPS error: each fix \
                     weighted by how unlikely it is, so that a city's reflections do not \
                     widen the wander for every fix; off = Gaussian",
                )
                .changed();
        }
        if !fit.auto_noise.gps {
            changed |= ui
                .add(
                    egui::Slider::new(&mut fit.model.sigma_horizontal_m, 0.1..=30.0)
                        .logarithmic(true)
                        .text("GPS sigma (m)"),
                )
                .changed();
            let mut correlated = fit.model.gps_tau_s.is_some();
            if ui
                .checkbox(&mut correlated, "GPS error correlated")
                .on_hover_text("first-order Gauss-Markov; off = independent fixes (the paper)")
                .changed()
            {
                fit.model.gps_tau_s = correlated.then_some(20.0);
                changed = true;
            }
            if let Some(t) = fit.model.gps_tau_s.as_mut() {
                changed |= ui
                    .add(
                        egui::Slider::new(t, 0.5..=1800.0)
                            .logarithmic(true)
                            .text("correlation time (s)"),
                    )
                    .changed();
                changed |= ui
                    .add(
                        egui::Slider::new(&mut fit.model.gps_white_m, 0.0..=10.0)
                            .text("jitter per fix (m)"),
                    )
                    .on_hover_text(
                        "white error of each fix on top of the wander, scaled by the fix's \
                         logged accuracy",
                    )
                    .changed();
            }
        }
        let mut prior = fit.model.bias_walk_dps_sqrt_s.is_some();
        if ui
            .checkbox(&mut prior, "bias smoothness prior")
            .on_hover_text(
                "a random-walk prior between neighbouring segment biases; off = the paper",
            )
            .changed()
        {
            fit.model.bias_walk_dps_sqrt_s = prior.then_some(DEFAULT_BIAS_WALK);
            if !prior {
                fit.auto_noise.walk = false;
            }
            changed = true;
        }
        if prior {
            changed |= ui
                .checkbox(&mut fit.auto_noise.walk, "bias walk from the ride")
                .changed();
        }
        if let (Some(w), false) = (fit.model.bias_walk_dps_sqrt_s.as_mut(), fit.auto_noise.walk) {
            changed |= ui
                .add(
                    egui::Slider::new(w, 1e-4..=1e-1)
                        .logarithmic(true)
                        .text("bias walk (deg/s/sqrt(s))"),
                )
                .changed();
        }
        if let Some(n) = self.snapshot.as_ref().and_then(|s| s.noise.as_ref()) {
            ui.label("The ride prefers (1-sigma range):");
            egui::Grid::new("noise_estimate")
                .num_columns(2)
                .show(ui, |ui| {
                    ui.label("GPS sigma");
                    ui.label(n.gps_sigma_m.describe("m", 2));
                    ui.end_row();
                    ui.label("GPS error");
                    let tau = ui.label(n.tau_text());
                    if n.gps_tau_s.limit == Limit::AtLeast {
                        tau.on_hover_text(
                            "The likelihood keeps rising towards the ride's length: a wander \
                             that slow is an offset plus a drift over the ride, and only the \
                             drift (sigma^2 / tau) shows. The value is a lower bound.",
                        );
                    }
                    ui.end_row();
                    ui.label("GPS jitter");
                    ui.label(n.gps_white_m.describe("m", 2));
                    ui.end_row();
                    if let Some(heights) = n.heights_text() {
                        ui.label("GPS heights");
                        // Wrapped: on one line it widened the whole panel.
                        ui.vertical(|ui| {
                            ui.set_max_width(280.0);
                            ui.add(egui::Label::new(heights).wrap());
                        });
                        ui.end_row();
                    }
                    ui.label("bias walk");
                    ui.label(n.walk_text("°/s/√s"));
                    ui.end_row();
                    for c in n.calibration.iter().filter(|c| c.held) {
                        ui.label("odometer gain").on_hover_text(
                            "Least squares and a heavy-tailed (Student-t) fit of the same \
                             fixes disagree on the gain beyond chance (Hausman's test at \
                             0.1 %): reflected fixes pulled the least squares. The \
                             heavy-tailed fit's gain is held; the rest of the fit keeps the \
                             Gaussian law.",
                        );
                        ui.vertical(|ui| {
                            ui.set_max_width(230.0);
                            ui.add(egui::Label::new(c.describe()).wrap());
                        });
                        ui.end_row();
                    }
                });
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
        if self.map_background.is_some() {
            ui.checkbox(&mut self.settings.map_tiles, "map background")
                .on_hover_text(
                    "OpenStreetMap tiles under the map, fetched when online and \
                     cached on disk; without a network the map is drawn without them",
                );
        }
        ui.checkbox(
            &mut self.settings.normalised_residuals,
            "residuals in sigmas of the noise model",
        )
        .on_hover_text(
            "Each fix's residual divided by what the GPS noise model expects there \
             (given the fix before, when the noise is correlated): under a right model \
             about 1 in 22 lies beyond ±2",
        );
    }
}
