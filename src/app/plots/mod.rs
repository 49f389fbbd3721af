//! The plots: map, fit progress, bias per segment, residuals over time, and
//! the model history chart; one file each, with what they share in `axes`.
//!
//! Drawing only: everything here comes from the worker's
//! [`Snapshot`](super::worker::Snapshot) and the loaded
//! [`RideView`](super::worker::RideView). Hovering any time plot sets the
//! time that the map marks.

use egui::Color32;

mod axes;
mod band;
mod history;
mod map;
mod progress;
mod time_series;

pub(super) use history::history_ui;
use map::map_ui;
use progress::cost_ui;
use time_series::{bias_ui, normalised_residuals_ui, residuals_ui};

const GPS: Color32 = Color32::from_rgb(120, 160, 255);
const PATH: Color32 = Color32::from_rgb(255, 200, 60);
const OUTAGE: Color32 = Color32::from_rgb(255, 110, 200);
/// Where the gyro stopped answering.
const GYRO_STOP: Color32 = Color32::from_rgb(255, 150, 40);
const SCALE: Color32 = Color32::from_gray(210);
/// The reference track and the path's distance from it.
const REFERENCE: Color32 = Color32::from_rgb(235, 235, 235);
const SIGMA: Color32 = Color32::from_rgba_premultiplied(150, 150, 150, 140);
const AXES: [Color32; 3] = [
    Color32::from_rgb(240, 90, 90),
    Color32::from_rgb(90, 200, 110),
    Color32::from_rgb(110, 150, 255),
];
/// Residual colour scale (m): below each bound the colour of the same index.
const RESIDUAL_BINS: [(f64, Color32); 4] = [
    (1.0, Color32::from_rgb(80, 200, 120)),
    (2.5, Color32::from_rgb(200, 220, 80)),
    (5.0, Color32::from_rgb(255, 160, 60)),
    (f64::INFINITY, Color32::from_rgb(240, 60, 60)),
];

impl super::GyropathApp {
    pub(super) fn plots_ui(&mut self, ui: &mut egui::Ui) {
        let Some(ride) = &self.ride else {
            ui.centered_and_justified(|ui| {
                ui.label("Open a ride log (File > Open) or drop a CSV file here.");
            });
            return;
        };
        let snap = self.snapshot.as_ref();
        let avail = ui.available_size();
        let mut hover = None;
        ui.horizontal_top(|ui| {
            let map_w = (avail.x * 0.5).max(200.0);
            ui.allocate_ui(egui::vec2(map_w, avail.y), |ui| {
                map_ui(
                    ui,
                    ride,
                    snap,
                    self.settings.colour_by_residual,
                    self.hover_t,
                    self.map_background
                        .as_mut()
                        .filter(|_| self.settings.map_tiles),
                    self.reference.as_ref(),
                );
            });
            ui.vertical(|ui| {
                let Some(snap) = snap else {
                    ui.label("Waiting for the first iteration...");
                    return;
                };
                let h = ((avail.y - 3.0 * 24.0) / 3.0).max(60.0);
                ui.label("Fit progress (log scale): GPS RMS over the whole ride; grey lines end a step, red ones mark a settings change");
                cost_ui(ui, snap, h);
                ui.label("Gyro bias per segment");
                hover = hover.or(bias_ui(ui, ride, snap, h).0);
                if self.settings.normalised_residuals {
                    let spread = snap.normalised_spread;
                    ui.label(format!(
                        "Residuals in sigmas: RMS {:.2} (1 expected), {:.1} % beyond ±2 ({:.1} % expected)",
                        spread.rms,
                        100.0 * spread.beyond_2,
                        100.0 * crate::diagnosis::NormalisedSpread::EXPECTED_BEYOND_2
                    ));
                    hover = hover.or(normalised_residuals_ui(ui, ride, snap, h).0);
                } else {
                    ui.label("Residuals at GPS fixes");
                    hover = hover.or(residuals_ui(ui, ride, snap, h).0);
                }
            });
        });
        self.hover_t = hover;
    }
}
