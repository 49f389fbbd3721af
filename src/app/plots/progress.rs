//! The fit's progress: GPS RMS and cost per iteration.

use egui::Color32;
use egui_plot::{Legend, Line, LineStyle, Plot, PlotPoints, VLine};

use super::axes::{decade_grid, decade_label, nice_grid, tick_label};
use super::{GPS, PATH};
use crate::app::worker::Snapshot;
use crate::optimisation::IterationReport;

/// The fit's progress per iteration, log scale: first the GPS RMS over the
/// whole ride, which falls as the fit proceeds; then, fainter, what each
/// iteration itself fitted (in step 1 its growing window, whose cost and RMS
/// rise as it takes in more of the ride, which read as the fit getting
/// worse when they led). Settings changes and step ends are marked. The top
/// of the plot is kept free for the legend, so it never covers the data.
pub fn cost_ui(ui: &mut egui::Ui, snap: &Snapshot, height: f32) {
    // log10 of a positive, finite value per iteration.
    let log_series = |value: fn(&IterationReport) -> f64| -> Vec<[f64; 2]> {
        snap.history
            .iter()
            .map(|r| (r.iteration as f64, value(r)))
            .filter(|(_, v)| *v > 0.0 && v.is_finite())
            .map(|(i, v)| [i, v.log10()])
            .collect()
    };
    let ride = log_series(|r| r.ride_rms_m);
    let fitted = log_series(|r| r.rms_horizontal_m);
    let cost = log_series(|r| r.cost);
    let (lo, hi) = ride
        .iter()
        .chain(&fitted)
        .chain(&cost)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[1]), hi.max(p[1]))
        });
    let headroom = if hi > lo { 1.3 * (hi - lo) } else { 1.0 };
    Plot::new("cost")
        .height(height)
        .legend(Legend::default().position(egui_plot::Corner::LeftTop))
        .x_axis_label("iteration")
        .x_grid_spacer(nice_grid)
        .x_axis_formatter(tick_label)
        .y_grid_spacer(decade_grid)
        .y_axis_formatter(decade_label)
        .include_y(if hi.is_finite() { hi + headroom } else { 1.0 })
        .show(ui, |plot| {
            plot.line(
                Line::new("GPS RMS, whole ride (m)", PlotPoints::from(ride))
                    .color(GPS)
                    .width(2.5),
            );
            plot.line(
                Line::new(
                    "GPS RMS, fixes fitted (m; step 1: its window)",
                    PlotPoints::from(fitted),
                )
                .color(GPS.gamma_multiply(0.45))
                .width(1.0),
            );
            plot.line(
                Line::new("cost (step 1: its window)", PlotPoints::from(cost))
                    .color(PATH.gamma_multiply(0.5))
                    .width(1.0)
                    .style(LineStyle::dashed_loose()),
            );
            for r in &snap.history {
                if r.settings_changed {
                    // Unnamed: marks, not series, so they stay out of the legend.
                    plot.vline(
                        VLine::new("", r.iteration as f64 - 0.5)
                            .color(Color32::LIGHT_RED)
                            .style(LineStyle::dashed_loose()),
                    );
                }
                if r.phase_finished {
                    plot.vline(VLine::new("", r.iteration as f64 + 0.5).color(Color32::GRAY));
                }
            }
        });
}
