//! The map: GPS fixes and the reconstructed path in local metres (equal
//! aspect), coloured by outage or residual, over the path's 95 % band,
//! the time hovered in the other plots, a scale bar and the tile background.

use egui::Color32;
use egui_plot::{Legend, Line, LineStyle, MarkerShape, Plot, Points};

use super::axes::{nearest, nice_grid, nice_grid_y, nice_step, runs, thin_to_pixels, tick_label};
use super::band::BandLayer;
use super::{GPS, OUTAGE, PATH, RESIDUAL_BINS, SCALE};
use crate::app::map_tiles::{MapBackground, attribution_ui};
use crate::app::worker::{ReferenceView, RideView, SigmaView, Snapshot};

/// GPS fixes and reconstructed path in local metres, equal aspect.
pub fn map_ui(
    ui: &mut egui::Ui,
    ride: &RideView,
    snap: Option<&Snapshot>,
    colour_by_residual: bool,
    hover_t: Option<f64>,
    mut background: Option<&mut MapBackground>,
    reference: Option<&ReferenceView>,
) {
    let shown = Plot::new("map")
        .data_aspect(1.0)
        .x_grid_spacer(nice_grid)
        .y_grid_spacer(nice_grid_y)
        .x_axis_formatter(tick_label)
        .y_axis_formatter(tick_label)
        .legend(Legend::default())
        .x_axis_label("east (m)")
        .y_axis_label("north (m)")
        .show(ui, |plot| {
            if let Some(bg) = background.as_deref_mut() {
                let layer = bg.layer(plot.ctx(), plot.transform(), &ride.frame);
                plot.add(layer);
            }
            if let Some(r) = reference {
                // Under the path: where the path should have been.
                plot.line(
                    Line::new(
                        "reference track",
                        r.points.iter().map(|p| [p[1], p[2]]).collect::<Vec<_>>(),
                    )
                    .color(super::REFERENCE)
                    .width(3.0),
                );
            }
            let fixes = thin_to_pixels(plot, ride.fixes.iter().map(|f| [f[1], f[2]]));
            plot.points(
                Points::new("GPS fixes", fixes)
                    .color(GPS)
                    .radius(1.5)
                    .shape(MarkerShape::Circle),
            );
            let Some(snap) = snap else {
                return;
            };
            // Under the path: the band where the path may be.
            if let Some(sigma) = &snap.sigma {
                band_ui(plot, snap, sigma);
            }
            let in_outage = |t: f64| ride.outages.iter().any(|&(a, b)| t > a && t < b);
            if colour_by_residual && !snap.residuals.is_empty() {
                let res = &snap.residuals;
                let bin = |i: usize| {
                    let t = snap.path[i][0];
                    let r =
                        nearest(|k| res[k].t, res.len(), t).map_or(0.0, |k| res[k].horizontal());
                    RESIDUAL_BINS.iter().position(|(b, _)| r < *b).unwrap_or(3)
                };
                for (b, run) in runs(&snap.path, bin) {
                    let (bound, colour) = RESIDUAL_BINS[b];
                    let name = if bound.is_finite() {
                        format!("path, residual < {bound} m")
                    } else {
                        "path, residual >= 5 m".to_string()
                    };
                    plot.line(Line::new(name, run).color(colour).width(2.0));
                }
            } else {
                for (outage, run) in runs(&snap.path, |i| in_outage(snap.path[i][0])) {
                    let (name, colour) = if outage {
                        ("path in GPS outage", OUTAGE)
                    } else {
                        ("reconstructed path", PATH)
                    };
                    plot.line(Line::new(name, run).color(colour).width(2.0));
                }
            }
            if let Some(t) = hover_t
                && let Some(i) = nearest(|k| snap.path[k][0], snap.path.len(), t)
            {
                let p = snap.path[i];
                plot.points(
                    Points::new(format!("t = {:.1} s", t - ride.t0), vec![[p[1], p[2]]])
                        .color(Color32::WHITE)
                        .radius(6.0)
                        .shape(MarkerShape::Diamond),
                );
                if let Some(k) = nearest(|k| ride.fixes[k][0], ride.fixes.len(), t)
                    && (ride.fixes[k][0] - t).abs() < 1.5
                {
                    let f = ride.fixes[k];
                    plot.line(
                        Line::new("residual at cursor", vec![[p[1], p[2]], [f[1], f[2]]])
                            .color(Color32::WHITE)
                            .style(LineStyle::dashed_dense()),
                    );
                }
            }
        });
    scale_bar_ui(ui, &shown.transform);
    if let Some(bg) = background {
        attribution_ui(ui, &shown.transform, bg.status());
    }
}

/// A scale bar's length for a map `width` metres wide (a 1-2-5 step of a
/// fifth to a half of it) and its label; `None` for no width.
pub fn scale_bar(width: f64) -> Option<(f64, String)> {
    if !(width.is_finite() && width > 0.0) {
        return None;
    }
    let length = nice_step(width / 5.0);
    let label = if length >= 1000.0 {
        format!("{} km", length / 1000.0)
    } else {
        format!("{length} m")
    };
    Some((length, label))
}

/// The scale bar in the map's lower left corner: the axes give the
/// coordinates, the bar how far a distance on screen is at a glance. Painted
/// on the screen over the plot, not as a plot item: an item would count in
/// the plot's automatic bounds, and a bar placed by the last frame's bounds
/// then pushes the next frame's out by a little every frame (on a 6-hour
/// ride the map had crept out to 18,000 km).
fn scale_bar_ui(ui: &egui::Ui, transform: &egui_plot::PlotTransform) {
    let Some((length, label)) = scale_bar(transform.bounds().width()) else {
        return;
    };
    let frame = *transform.frame();
    let px = (length * transform.dpos_dvalue_x()).abs() as f32;
    let start = egui::pos2(
        frame.left() + 0.04 * frame.width(),
        frame.bottom() - 0.05 * frame.height(),
    );
    let painter = ui.painter_at(frame);
    // A dark backing, so the bar and its label stay legible over the path.
    let backing = egui::Rect::from_min_max(
        start + egui::vec2(-6.0, -22.0),
        start + egui::vec2(px + 6.0, 6.0),
    );
    painter.rect_filled(backing, 3.0, Color32::from_black_alpha(150));
    painter.line_segment(
        [start, start + egui::vec2(px, 0.0)],
        egui::Stroke::new(4.0, SCALE),
    );
    painter.text(
        start + egui::vec2(0.5 * px, -5.0),
        egui::Align2::CENTER_BOTTOM,
        label,
        egui::FontId::proportional(11.0),
        SCALE,
    );
}

/// At most this many points of the band are drawn.
const BAND_POINTS: usize = 2000;

/// The path's 95 % band across the track (`diagnosis::view::cross_band`),
/// filled under the path: it widens where the path is least sure (long
/// outages, the ride's ends) and is as narrow as the fit says elsewhere.
fn band_ui(plot: &mut egui_plot::PlotUi<'_>, snap: &Snapshot, sigma: &SigmaView) {
    let band = crate::diagnosis::view::cross_band(&snap.path, &sigma.path);
    let step = band.len().div_ceil(BAND_POINTS).max(1);
    let points: Vec<_> = band
        .iter()
        .step_by(step)
        .chain(band.last())
        .map(|b| {
            let [l, r] = b.edges();
            [[b.east, b.north], l, r]
        })
        .collect();
    if points.len() >= 2 {
        plot.add(BandLayer::new(points));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_bar_is_a_round_fifth_of_the_map() {
        assert_eq!(scale_bar(1000.0), Some((200.0, "200 m".to_string())));
        assert_eq!(scale_bar(130.0), Some((50.0, "50 m".to_string())));
        assert_eq!(scale_bar(12_000.0), Some((5000.0, "5 km".to_string())));
        assert_eq!(scale_bar(3.0), Some((1.0, "1 m".to_string())));
        for w in [0.7, 13.0, 480.0, 2.5e4] {
            let (l, _) = scale_bar(w).unwrap();
            assert!(l >= w / 5.0 && l <= 0.5 * w + 1e-9, "{w}: {l}");
        }
        assert_eq!(scale_bar(0.0), None);
        assert_eq!(scale_bar(f64::NAN), None);
    }
}
