//! The model history chart: fit and held-out error per model.

use egui_plot::{Legend, Line, MarkerShape, Plot, PlotPoints, Points};

use super::axes::{nice_grid_y, tick_label};
use super::{GPS, PATH};
use crate::app::HistoryRow;

/// Held-out and fit error per model of the history (x: the model's number),
/// so the error can be watched falling as effects are added.
pub fn history_series(history: &[HistoryRow]) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let heldout = history
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.held_out.map(|h| [(i + 1) as f64, h.rms_m]))
        .collect();
    let fit = history
        .iter()
        .enumerate()
        .map(|(i, r)| [(i + 1) as f64, r.fit_rms_m])
        .collect();
    (heldout, fit)
}

/// The history chart: held-out error per model (bold, with points) and the fit error.
pub fn history_ui(ui: &mut egui::Ui, history: &[HistoryRow], height: f32) {
    let (heldout, fit) = history_series(history);
    let names: Vec<String> = history.iter().map(|r| r.model.clone()).collect();
    Plot::new("history-chart")
        .height(height)
        .legend(Legend::default().position(egui_plot::Corner::RightTop))
        .x_axis_label("model")
        .y_axis_label("error (m)")
        .x_grid_spacer(egui_plot::uniform_grid_spacer(|_| [1.0, 5.0, 10.0]))
        .x_axis_formatter(|mark, _| {
            if mark.value >= 1.0 && mark.value.fract() == 0.0 {
                format!("{}", mark.value as usize)
            } else {
                String::new()
            }
        })
        .y_grid_spacer(nice_grid_y)
        .y_axis_formatter(tick_label)
        .include_y(0.0)
        .include_x(0.5)
        .include_x(history.len() as f64 + 0.5)
        .label_formatter(move |hover| {
            let p = match hover {
                egui_plot::HoverPosition::NearDataPoint { position, .. } => position,
                egui_plot::HoverPosition::Elsewhere { .. } => return None,
            };
            let i = p.x.round() as usize;
            names
                .get(i.wrapping_sub(1))
                .map(|m| format!("{m}\n{:.3} m", p.y))
        })
        .show(ui, |plot| {
            plot.line(
                Line::new("held-out", PlotPoints::from(heldout.clone()))
                    .color(PATH)
                    .width(2.5),
            );
            plot.points(
                Points::new("", heldout)
                    .color(PATH)
                    .radius(4.0)
                    .shape(MarkerShape::Circle),
            );
            plot.line(
                Line::new("fit", PlotPoints::from(fit))
                    .color(GPS.gamma_multiply(0.6))
                    .width(1.0),
            );
            let reference: Vec<[f64; 2]> = history
                .iter()
                .enumerate()
                .filter_map(|(i, r)| r.reference_rms_m.map(|e| [(i + 1) as f64, e]))
                .collect();
            if !reference.is_empty() {
                plot.points(
                    Points::new("to reference", reference)
                        .color(super::REFERENCE)
                        .radius(4.0)
                        .shape(MarkerShape::Diamond),
                );
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::HeldOutRms;

    #[test]
    fn the_chart_has_a_held_out_point_per_validated_model() {
        let row = |h: Option<f64>, fit: f64| HistoryRow {
            model: "paper".into(),
            segment_s: 5.0,
            params: 3,
            fit_rms_m: fit,
            gps_noise: String::new(),
            held_out: h.map(|rms_m| HeldOutRms {
                rms_m,
                jumps_left_out: 0,
            }),
            held_out_failed: None,
            iterations: 9,
            reference_rms_m: None,
        };
        let (heldout, fit) =
            history_series(&[row(Some(3.0), 2.0), row(None, 1.5), row(Some(2.0), 1.6)]);
        assert_eq!(
            heldout,
            vec![[1.0, 3.0], [3.0, 2.0]],
            "a model still validating has no point yet"
        );
        assert_eq!(fit.len(), 3);
    }
}
