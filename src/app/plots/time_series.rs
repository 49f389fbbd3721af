//! The time plots (bias per segment, residuals at the fixes, in metres or
//! in sigmas): one shared x axis and cursor (`link_axis` / `link_cursor`),
//! and the hovered time reported so the map can mark it.

use egui::Id;
use egui_plot::{HLine, Legend, Line, LineStyle, Plot, Polygon};

use super::axes::{decimate, nice_grid, nice_grid_y, tick_label, view};
use super::{AXES, GYRO_STOP, OUTAGE};
use crate::app::worker::{RideView, Snapshot};
use crate::diagnosis::FixResidual;

/// What hovering a time plot reported.
pub struct TimeHover(pub Option<f64>);

fn time_plot(id: &str, height: f32, y_label: &str) -> Plot<'static> {
    Plot::new(id.to_string())
        .height(height)
        .legend(Legend::default())
        .link_axis(time_group(), [true, false])
        .link_cursor(time_group(), [true, false])
        .x_axis_label("time (s)")
        .y_axis_label(y_label.to_string())
        .x_grid_spacer(nice_grid)
        .y_grid_spacer(nice_grid_y)
        .x_axis_formatter(tick_label)
        .y_axis_formatter(tick_label)
}

fn time_group() -> Id {
    Id::unique("gyropath-time-axis")
}

/// Spans of the ride (log time from, to) lightly shaded over `y0..y1`,
/// named once in the legend: a real city drive has dozens of outages, which
/// as pairs of lines were a wall of pink.
fn shade(
    plot: &mut egui_plot::PlotUi<'_>,
    spans: &[(f64, f64)],
    t0: f64,
    (y0, y1): (f64, f64),
    name: &str,
    fill: egui::Color32,
) {
    if y0.partial_cmp(&y1) != Some(std::cmp::Ordering::Less) {
        return;
    }
    for &(a, b) in spans {
        plot.polygon(
            Polygon::new(
                name,
                vec![[a - t0, y0], [b - t0, y0], [b - t0, y1], [a - t0, y1]],
            )
            .fill_color(fill)
            // No outline; its colour is the legend's marker.
            .stroke(egui::Stroke::new(0.0, fill.to_opaque()))
            .allow_hover(false),
        );
    }
}

/// Where the gyro stopped answering, the log lost its rows or the sensor
/// turned without the vehicle (see [`RideView::gyro_stops`]), shaded
/// more strongly than an outage: there are few, and the fit's turns are free.
fn shade_gyro_stops(plot: &mut egui_plot::PlotUi<'_>, ride: &RideView, t0: f64, y: (f64, f64)) {
    let mut causes = vec!["gyro stopped"];
    if ride.rows_filled > 0 {
        causes.push("rows lost");
    }
    if ride.sensor_turns > 0 {
        causes.push("sensor turned alone");
    }
    let label = match causes.as_slice() {
        [one] => one.to_string(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
        [] => String::new(),
    };
    shade(
        plot,
        &ride.gyro_stops,
        t0,
        y,
        &label,
        GYRO_STOP.gamma_multiply(0.35),
    );
}

/// The lowest and highest of `values` that are finite.
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        })
}

/// Total gyro bias (constant + segment), three axes, as steps over time.
pub fn bias_ui(ui: &mut egui::Ui, ride: &RideView, snap: &Snapshot, height: f32) -> TimeHover {
    let t0 = ride.t0;
    let r = time_plot("bias", height, "bias (deg/s)").show(ui, |plot| {
        let (lo, hi, px) = view(plot);
        // A planar model estimates the yaw bias only: its roll and pitch
        // biases are held at zero, not results, and are not drawn.
        let axes = if ride.attitude.is_planar() {
            2..3
        } else {
            0..3
        };
        for (a, name) in ["x (roll)", "y (pitch)", "z (yaw)"]
            .iter()
            .enumerate()
            .filter(|(a, _)| axes.contains(a))
        {
            let pts: Vec<[f64; 2]> = snap
                .segments
                .iter()
                .flat_map(|s| [[s.t0 - t0, s.bias_dps[a]], [s.t1 - t0, s.bias_dps[a]]])
                .collect();
            let pts = decimate(&pts, lo, hi, px);
            plot.line(Line::new(format!("bias {name}"), pts).color(AXES[a]));
            // +- 1 sigma of each segment, once the fit is done.
            let Some(sigma) = snap
                .sigma
                .as_ref()
                .filter(|s| s.segments.len() == snap.segments.len())
            else {
                continue;
            };
            for side in [-1.0, 1.0] {
                let band: Vec<[f64; 2]> = snap
                    .segments
                    .iter()
                    .zip(&sigma.segments)
                    .flat_map(|(s, sd)| {
                        let v = s.bias_dps[a] + side * sd[a];
                        [[s.t0 - t0, v], [s.t1 - t0, v]]
                    })
                    .collect();
                plot.line(
                    Line::new(format!("bias {name} ± 1σ"), decimate(&band, lo, hi, px))
                        .color(AXES[a].gamma_multiply(0.5))
                        .style(LineStyle::dashed_dense()),
                );
            }
        }
        // Where the gyro stopped, over the drawn biases' range with their
        // sigmas: the bias there is the fit's guess, the turn its free
        // parameter.
        let sigmas = snap
            .sigma
            .as_ref()
            .filter(|s| s.segments.len() == snap.segments.len());
        let y = range(snap.segments.iter().enumerate().flat_map(|(k, s)| {
            let sd = sigmas.map_or([0.0; 3], |sg| sg.segments[k]);
            axes.clone()
                .flat_map(move |a| [s.bias_dps[a] - sd[a], s.bias_dps[a] + sd[a]])
        }));
        shade_gyro_stops(plot, ride, t0, y);
        hovered_time(plot, t0)
    });
    TimeHover(r.inner)
}

/// Residuals at the GPS fixes: along-track, cross-track, vertical.
pub fn residuals_ui(ui: &mut egui::Ui, ride: &RideView, snap: &Snapshot, height: f32) -> TimeHover {
    let series: [ResidualSeries; 3] = [
        ("along-track", &|r| Some(r.along)),
        ("cross-track", &|r| Some(r.cross)),
        ("vertical", &|r| r.up),
    ];
    fix_series_ui(
        ui,
        ride,
        snap,
        height,
        "residuals",
        "fix - path (m)",
        &series,
        None,
    )
}

/// Residuals in sigmas of the fit's noise model (along- and cross-track),
/// with the +-2 band that holds about 95 % of them under a right model.
pub fn normalised_residuals_ui(
    ui: &mut egui::Ui,
    ride: &RideView,
    snap: &Snapshot,
    height: f32,
) -> TimeHover {
    let series: [ResidualSeries; 2] = [
        ("along-track", &|r| Some(r.normalised[0])),
        ("cross-track", &|r| Some(r.normalised[1])),
    ];
    fix_series_ui(
        ui,
        ride,
        snap,
        height,
        "normalised residuals",
        "(fix - path) / sigma",
        &series,
        Some(2.0),
    )
}

/// A named quantity of each fix residual (`None`: the fix has none).
type ResidualSeries<'a> = (&'a str, &'a dyn Fn(&FixResidual) -> Option<f64>);

/// Quantities of the fix residuals over time, one line per stretch of
/// consecutive fixes so outages stay gaps, coloured as the axes are, with
/// horizontal lines at `+-band` when given.
#[allow(clippy::too_many_arguments)]
fn fix_series_ui(
    ui: &mut egui::Ui,
    ride: &RideView,
    snap: &Snapshot,
    height: f32,
    id: &str,
    y_label: &str,
    series: &[ResidualSeries],
    band: Option<f64>,
) -> TimeHover {
    let t0 = ride.t0;
    let r = time_plot(id, height, y_label).show(ui, |plot| {
        let res = &snap.residuals;
        let (lo, hi, px) = view(plot);
        let mut start = 0;
        while start < res.len() {
            let end = (start + 1..res.len())
                .find(|&k| res[k].t - res[k - 1].t > 2.5)
                .unwrap_or(res.len());
            for (i, (name, f)) in series.iter().enumerate() {
                let pts: Vec<[f64; 2]> = res[start..end]
                    .iter()
                    .filter_map(|r| f(r).map(|v| [r.t - t0, v]))
                    .collect();
                if !pts.is_empty() {
                    plot.line(Line::new(*name, decimate(&pts, lo, hi, px)).color(AXES[i]));
                }
            }
            start = end;
        }
        // The path's distance from the reference track, where one is loaded
        // (in metres, so not on the plot in sigmas).
        if band.is_none()
            && let Some(c) = &snap.reference
        {
            let pts: Vec<[f64; 2]> = c.series.iter().map(|&(t, e)| [t - t0, e]).collect();
            plot.line(
                Line::new("|path - reference| (m)", decimate(&pts, lo, hi, px))
                    .color(super::REFERENCE)
                    .width(1.5),
            );
        }
        if let Some(b) = band {
            for y in [-b, b] {
                plot.hline(
                    HLine::new(format!("±{b} σ"), y)
                        .color(egui::Color32::GRAY)
                        .style(LineStyle::dashed_loose()),
                );
            }
        }
        // Outages and the gyro's stops shaded over the values' own range.
        let y = range(
            res.iter()
                .flat_map(|r| series.iter().filter_map(move |(_, f)| f(r))),
        );
        shade(
            plot,
            &ride.outages,
            t0,
            y,
            "GPS outage",
            OUTAGE.gamma_multiply(0.12),
        );
        shade_gyro_stops(plot, ride, t0, y);
        hovered_time(plot, t0)
    });
    TimeHover(r.inner)
}

fn hovered_time(plot: &egui_plot::PlotUi<'_>, t0: f64) -> Option<f64> {
    if plot.response().hovered() {
        plot.pointer_coordinate().map(|p| p.x + t0)
    } else {
        None
    }
}
