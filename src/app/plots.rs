//! The four plots: map, cost curve, bias per segment, residuals over time.
//!
//! Drawing only: everything here comes from the worker's [`Snapshot`] and the
//! loaded [`RideView`]. The time plots share one x axis and cursor
//! (`link_axis` / `link_cursor`); hovering any of them sets the time that the
//! map marks.

use egui::{Color32, Id};
use egui_plot::{
    GridInput, GridMark, HLine, Legend, Line, LineStyle, MarkerShape, Plot, PlotPoints, Points,
    VLine,
};

use super::map_tiles::{MapBackground, attribution_ui};
use super::worker::{RideView, SigmaView, Snapshot};
use crate::diagnosis::FixResidual;
use crate::optimisation::IterationReport;

const GPS: Color32 = Color32::from_rgb(120, 160, 255);
const PATH: Color32 = Color32::from_rgb(255, 200, 60);
const OUTAGE: Color32 = Color32::from_rgb(255, 110, 200);
const SCALE: Color32 = Color32::from_gray(210);
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

/// The smallest 1, 2 or 5 times a power of ten at or above `x` (> 0).
fn nice_step(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&s| s >= x * (1.0 - 1e-12))
        .unwrap_or(10.0 * p)
}

/// A grid of 1-2-5 steps whose coarsest level, the one that carries tick
/// labels, is at least nine grid spacings (about 70 points) apart, with each
/// finer level dividing the next. The default log-10 grid labels only powers
/// of ten: on a 150 m map only "0" was left on the east axis.
pub fn nice_grid(input: GridInput) -> Vec<GridMark> {
    nice_grid_spaced(input, 9.0)
}

/// The same for a vertical axis, whose labels need only about 20 points:
/// labels four grid spacings apart, so a short plot still shows its scale.
pub fn nice_grid_y(input: GridInput) -> Vec<GridMark> {
    nice_grid_spaced(input, 4.0)
}

/// 1-2-5 marks, labelled every `label_spacings` grid spacings or more.
fn nice_grid_spaced(input: GridInput, label_spacings: f64) -> Vec<GridMark> {
    if !(input.base_step_size.is_finite() && input.base_step_size > 0.0) {
        return Vec::new();
    }
    let label = nice_step(label_spacings * input.base_step_size);
    let finer = |s: f64| {
        let mantissa = (s / 10f64.powf(s.log10().floor())).round();
        if mantissa == 2.0 { s / 2.0 } else { s / 5.0 }
    };
    let mid = finer(label);
    let fine = finer(mid);
    let (lo, hi) = input.bounds;
    let mut marks = Vec::new();
    let first = (lo / fine).ceil() as i64;
    let last = (hi / fine).floor() as i64;
    if last - first > 10_000 {
        return marks;
    }
    for k in first..=last {
        let value = k as f64 * fine;
        let on = |s: f64| ((value / s).round() * s - value).abs() < 1e-9 * s;
        let step_size = if on(label) {
            label
        } else if on(mid) {
            mid
        } else {
            fine
        };
        marks.push(GridMark { value, step_size });
    }
    marks
}

/// A tick label with as many decimals as its 1-2-5 step needs (egui_plot's
/// default rounds `-log10(step)`, which gives 0.5 no decimal: "-0").
pub fn tick_label(mark: GridMark, _range: &std::ops::RangeInclusive<f64>) -> String {
    let decimals = (-mark.step_size.log10()).ceil().max(0.0) as usize;
    let text = format!("{:.*}", decimals, mark.value);
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        text
    }
}

fn time_group() -> Id {
    Id::unique("gyropath-time-axis")
}

/// Runs of consecutive points with the same key, each run sharing its first point
/// with the previous run's last so the drawn line has no gaps.
fn runs<K: PartialEq + Copy>(
    points: &[[f64; 3]],
    key: impl Fn(usize) -> K,
) -> Vec<(K, Vec<[f64; 2]>)> {
    let mut out: Vec<(K, Vec<[f64; 2]>)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let k = key(i);
        match out.last_mut() {
            Some((last, run)) if *last == k => run.push([p[1], p[2]]),
            _ => {
                let mut run = Vec::new();
                if i > 0 {
                    run.push([points[i - 1][1], points[i - 1][2]]);
                }
                run.push([p[1], p[2]]);
                out.push((k, run));
            }
        }
    }
    out
}

/// Index of the entry of `ts` (sorted) nearest to `t`.
pub fn nearest(ts: impl Fn(usize) -> f64, len: usize, t: f64) -> Option<usize> {
    if len == 0 {
        return None;
    }
    let (mut lo, mut hi) = (0, len);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if ts(mid) < t {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    let i = lo.min(len - 1);
    if i > 0 && (ts(i - 1) - t).abs() < (ts(i) - t).abs() {
        Some(i - 1)
    } else {
        Some(i)
    }
}

/// GPS fixes and reconstructed path in local metres, equal aspect.
pub fn map_ui(
    ui: &mut egui::Ui,
    ride: &RideView,
    snap: Option<&Snapshot>,
    colour_by_residual: bool,
    hover_t: Option<f64>,
    mut background: Option<&mut MapBackground>,
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
            if let Some(sigma) = &snap.sigma {
                sigma_ellipses_ui(plot, snap, sigma);
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

/// How many 95 % ellipses the map draws along the path.
const ELLIPSES: usize = 80;

/// The path's 95 % ellipses (chi-square 5.99 with 2 degrees of freedom) at
/// evenly spaced points: where they grow (outages, the ride's ends) the path
/// is least sure.
fn sigma_ellipses_ui(plot: &mut egui_plot::PlotUi<'_>, snap: &Snapshot, sigma: &SigmaView) {
    let n = snap.path.len().min(sigma.path.len());
    let step = n.div_ceil(ELLIPSES).max(1);
    for i in (0..n).step_by(step) {
        let [ve, vn, c] = sigma.path[i];
        let Some(loop_) = ellipse(snap.path[i][1], snap.path[i][2], ve, vn, c, 5.991) else {
            continue;
        };
        plot.line(Line::new("95 % ellipse", loop_).color(SIGMA).width(1.0));
    }
}

/// The ellipse `d^T C^-1 d = k` around `(x, y)` for the covariance
/// `C = [[ve, c], [c, vn]]`, as a closed loop; `None` if `C` is not positive.
pub fn ellipse(x: f64, y: f64, ve: f64, vn: f64, c: f64, k: f64) -> Option<Vec<[f64; 2]>> {
    // Eigen-decomposition of the symmetric 2x2 matrix.
    let mean = 0.5 * (ve + vn);
    let d = (0.25 * (ve - vn).powi(2) + c * c).sqrt();
    let (l1, l2) = (mean + d, mean - d);
    if !(l1.is_finite() && l2 > 0.0) {
        return None;
    }
    let angle = 0.5 * (2.0 * c).atan2(ve - vn);
    let (a, b) = ((k * l1).sqrt(), (k * l2).sqrt());
    let (sin, cos) = angle.sin_cos();
    Some(
        (0..=32)
            .map(|i| {
                let t = i as f64 / 32.0 * std::f64::consts::TAU;
                let (u, v) = (a * t.cos(), b * t.sin());
                [x + u * cos - v * sin, y + u * sin + v * cos]
            })
            .collect(),
    )
}

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
        .y_axis_formatter(|mark, _| format!("{:.0e}", 10f64.powf(mark.value)))
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

/// Held-out and fit error per model of the history (x: the model's number),
/// so the error can be watched falling as effects are added.
pub fn history_series(history: &[super::HistoryRow]) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let heldout = history
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.heldout_rms_m.map(|h| [(i + 1) as f64, h]))
        .collect();
    let fit = history
        .iter()
        .enumerate()
        .map(|(i, r)| [(i + 1) as f64, r.fit_rms_m])
        .collect();
    (heldout, fit)
}

/// The history chart: held-out error per model (bold, with points) and the fit error.
pub fn history_ui(ui: &mut egui::Ui, history: &[super::HistoryRow], height: f32) {
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
        });
}

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

#[cfg(test)]
mod grid_tests {
    use super::*;

    #[test]
    fn the_grid_labels_a_150_m_map_every_50_m() {
        // 150 m over 400 points, grid lines no closer than 8 points: 3 m.
        let marks = nice_grid(GridInput {
            bounds: (-60.0, 90.0),
            base_step_size: 3.0,
        });
        let labelled: Vec<f64> = marks
            .iter()
            .filter(|m| m.step_size == 50.0)
            .map(|m| m.value)
            .collect();
        assert_eq!(labelled, vec![-50.0, 0.0, 50.0]);
        // Every finer level divides the coarser one.
        assert!(
            marks
                .iter()
                .all(|m| [2.0, 10.0, 50.0].contains(&m.step_size))
        );
        assert_eq!(nice_step(0.03), 0.05);
        let row = |h: Option<f64>, fit: f64| crate::app::HistoryRow {
            model: "paper".into(),
            segment_s: 5.0,
            params: 3,
            fit_rms_m: fit,
            heldout_rms_m: h,
            iterations: 9,
        };
        let (heldout, fit) =
            history_series(&[row(Some(3.0), 2.0), row(None, 1.5), row(Some(2.0), 1.6)]);
        assert_eq!(
            heldout,
            vec![[1.0, 3.0], [3.0, 2.0]],
            "a model still validating has no point yet"
        );
        assert_eq!(fit.len(), 3);
        let mark = |value: f64, step_size: f64| GridMark { value, step_size };
        assert_eq!(tick_label(mark(-0.5, 0.5), &(0.0..=1.0)), "-0.5");
        assert_eq!(tick_label(mark(0.25, 0.05), &(0.0..=1.0)), "0.25");
        assert_eq!(tick_label(mark(-800.0, 200.0), &(0.0..=1.0)), "-800");
        assert_eq!(tick_label(mark(-1e-17, 0.2), &(0.0..=1.0)), "0");
        assert_eq!(nice_step(2.0), 2.0);
        assert_eq!(nice_step(7.0), 10.0);
    }
}

/// Total gyro bias (constant + segment), three axes, as steps over time.
pub fn bias_ui(ui: &mut egui::Ui, ride: &RideView, snap: &Snapshot, height: f32) -> TimeHover {
    let t0 = ride.t0;
    let r = time_plot("bias", height, "bias (deg/s)").show(ui, |plot| {
        let (lo, hi, px) = view(plot);
        for (a, name) in ["x (roll)", "y (pitch)", "z (yaw)"].iter().enumerate() {
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
        if let Some(b) = band {
            for y in [-b, b] {
                plot.hline(
                    HLine::new(format!("±{b} σ"), y)
                        .color(egui::Color32::GRAY)
                        .style(LineStyle::dashed_loose()),
                );
            }
        }
        for &(a, b) in &ride.outages {
            plot.vline(VLine::new("GPS outage", a - t0).color(OUTAGE));
            plot.vline(VLine::new("GPS outage", b - t0).color(OUTAGE));
        }
        hovered_time(plot, t0)
    });
    TimeHover(r.inner)
}

/// Points (sorted by x) thinned to what `pixels` columns can show over the
/// visible x range `[lo, hi]`: per column the lowest and the highest point,
/// in order, so spikes survive; one point beyond each edge is kept so the
/// line still runs off the plot. A 6-hour ride's 19,000 residuals per
/// series become about 1,000 points, and a frame stays within its budget.
pub fn decimate(points: &[[f64; 2]], lo: f64, hi: f64, pixels: usize) -> Vec<[f64; 2]> {
    let (Some(a), Some(b)) = (points.first(), points.last()) else {
        return Vec::new();
    };
    // Columns over the points' own span at most: an auto-bounded view
    // passes an unbounded range (see `view`) and gets the whole line thinned.
    let (lo, hi) = (lo.max(a[0]), hi.min(b[0]));
    let first = points.partition_point(|p| p[0] < lo).saturating_sub(1);
    let last = (points.partition_point(|p| p[0] <= hi) + 1).min(points.len());
    let visible = &points[first.min(last)..last];
    if visible.len() <= 2 * pixels.max(1)
        || hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater)
    {
        return visible.to_vec();
    }
    let width = (hi - lo) / pixels as f64;
    let mut out = Vec::with_capacity(2 * pixels + 2);
    let mut i = 0;
    while i < visible.len() {
        let column = ((visible[i][0] - lo) / width).floor();
        let mut j = i;
        let (mut min, mut max) = (i, i);
        while j < visible.len() && ((visible[j][0] - lo) / width).floor() == column {
            if visible[j][1] < visible[min][1] {
                min = j;
            }
            if visible[j][1] > visible[max][1] {
                max = j;
            }
            j += 1;
        }
        out.push(visible[min.min(max)]);
        if min != max {
            out.push(visible[min.max(max)]);
        }
        i = j;
    }
    out
}

/// Markers thinned to one per pixel of the plot (those off the view are
/// dropped): a marker hidden under another costs a frame and shows nothing.
/// A 6-hour ride's 19,000 fixes on a 100 km map share pixels several at a time.
fn thin_to_pixels(
    plot: &egui_plot::PlotUi<'_>,
    points: impl Iterator<Item = [f64; 2]>,
) -> Vec<[f64; 2]> {
    let b = plot.plot_bounds();
    let rect = plot.response().rect;
    let (w, h) = (rect.width().max(1.0) as f64, rect.height().max(1.0) as f64);
    let (x0, y0) = (b.min()[0], b.min()[1]);
    let (sx, sy) = (w / b.width().max(1e-12), h / b.height().max(1e-12));
    let mut seen = std::collections::HashSet::new();
    points
        .filter(|p| {
            let (cx, cy) = ((p[0] - x0) * sx, (p[1] - y0) * sy);
            (0.0..=w).contains(&cx)
                && (0.0..=h).contains(&cy)
                && seen.insert((cx as u32, cy as u32))
        })
        .collect()
}

/// The visible x range of a plot and its width in points.
/// The x range a time plot shows and its width in pixels. While the plot
/// bounds itself to its data (a plot just shown, or never zoomed), the whole
/// range: its last bounds are those of the last frame's points (or, on its
/// first frame, a unit box at the origin), and lines decimated to them would
/// keep it zoomed in on the start of the ride.
fn view(plot: &egui_plot::PlotUi<'_>) -> (f64, f64, usize) {
    let px = plot.response().rect.width().max(1.0) as usize;
    if plot.auto_bounds().x {
        return (f64::NEG_INFINITY, f64::INFINITY, px);
    }
    let b = plot.plot_bounds();
    (b.min()[0], b.max()[0], px)
}

fn hovered_time(plot: &egui_plot::PlotUi<'_>, t0: f64) -> Option<f64> {
    if plot.response().hovered() {
        plot.pointer_coordinate().map(|p| p.x + t0)
    } else {
        None
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

    #[test]
    fn ellipses_have_the_covariance_axes() {
        // Axis-aligned: semi-axes 2 sqrt(k) east, sqrt(k) north.
        let e = ellipse(10.0, 20.0, 4.0, 1.0, 0.0, 9.0).unwrap();
        let max_e = e.iter().map(|p| (p[0] - 10.0).abs()).fold(0.0, f64::max);
        let max_n = e.iter().map(|p| (p[1] - 20.0).abs()).fold(0.0, f64::max);
        assert!(
            (max_e - 6.0).abs() < 1e-9 && (max_n - 3.0).abs() < 0.05,
            "{max_e} {max_n}"
        );
        // Correlated: every point satisfies d^T C^-1 d = k.
        let (ve, vn, c) = (2.0, 1.0, 0.8);
        for p in ellipse(0.0, 0.0, ve, vn, c, 5.991).unwrap() {
            let det = ve * vn - c * c;
            let m = (vn * p[0] * p[0] - 2.0 * c * p[0] * p[1] + ve * p[1] * p[1]) / det;
            assert!((m - 5.991).abs() < 1e-9, "{m}");
        }
        assert!(ellipse(0.0, 0.0, 1.0, 1.0, 2.0, 1.0).is_none());
    }

    #[test]
    fn decimation_keeps_the_extremes_and_the_edges() {
        let pts: Vec<[f64; 2]> = (0..10_000)
            .map(|i| [i as f64, if i == 4321 { 50.0 } else { (i % 7) as f64 }])
            .collect();
        let d = decimate(&pts, 1000.0, 9000.0, 100);
        // Two points per column, and the columns of the two edge neighbours.
        assert!(d.len() <= 2 * (100 + 2), "{}", d.len());
        assert!(d.iter().any(|p| p[1] == 50.0), "the spike survives");
        assert!(d.first().unwrap()[0] < 1000.0 && d.last().unwrap()[0] > 9000.0);
        assert!(d.windows(2).all(|w| w[0][0] <= w[1][0]), "in order");
        let few = decimate(&pts[..50], 0.0, 49.0, 100);
        assert_eq!(few.len(), 50, "nothing to thin");
        // An auto-bounded plot's unbounded range: the whole line, thinned.
        let all = decimate(&pts, f64::NEG_INFINITY, f64::INFINITY, 100);
        assert!(all.len() <= 2 * (100 + 1), "{}", all.len());
        assert_eq!((all[0], all[all.len() - 1]), (pts[0], pts[9999]));
        assert!(all.iter().any(|p| p[1] == 50.0), "the spike survives");
        assert!(decimate(&[], 0.0, 1.0, 100).is_empty());
    }

    #[test]
    fn nearest_finds_the_closest_sorted_entry() {
        let ts = [0.0, 1.0, 2.0, 10.0];
        let f = |i: usize| ts[i];
        assert_eq!(nearest(f, 4, -5.0), Some(0));
        assert_eq!(nearest(f, 4, 1.4), Some(1));
        assert_eq!(nearest(f, 4, 1.6), Some(2));
        assert_eq!(nearest(f, 4, 7.0), Some(3));
        assert_eq!(nearest(f, 4, 99.0), Some(3));
        assert_eq!(nearest(f, 0, 1.0), None);
    }

    #[test]
    fn runs_split_by_key_and_join_up() {
        let pts: Vec<[f64; 3]> = (0..6).map(|i| [i as f64, i as f64, 0.0]).collect();
        let r = runs(&pts, |i| i >= 3);
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].1.len(), 3);
        // The second run starts at the first run's last point.
        assert_eq!(r[1].1[0], [2.0, 0.0]);
        assert_eq!(r[1].1.len(), 4);
    }
}
