//! The report's figures, each an SVG drawn from a [`FitView`]: the map, the
//! residuals along and across the track and vertical, the error to the
//! reference, the path's uncertainty, the bias per segment and the model
//! history. Time series are thinned to the minimum and maximum of every
//! pixel column ([`svg::min_max_columns`]), so no outlier is lost; the map's
//! points are thinned to one per pixel.

use crate::diagnosis::FitView;
use crate::diagnosis::ReferenceComparison;
use crate::diagnosis::view::{BandPoint, OUTAGE_S, outages};
use crate::model::Uncertainty;
use crate::pipeline::MatchedReference;

use super::svg::{Frame, Svg, broken_at_gaps, extent, min_max_columns};
use super::{Figure, ModelRow};

/// Width (px) of every figure; the map is taller.
const WIDTH: f64 = 920.0;
const HEIGHT: f64 = 260.0;
const MAP_HEIGHT: f64 = 620.0;

/// What the figures are drawn from.
pub struct Input<'a> {
    pub model: &'a crate::model::Model,
    pub view: &'a FitView,
    /// At the view's rows.
    pub uncertainty: Option<&'a Uncertainty>,
    /// The 95 % band across the path at the view's rows (empty without an
    /// uncertainty; see [`crate::diagnosis::view::cross_band`]).
    pub band: &'a [BandPoint],
    pub reference: Option<&'a MatchedReference>,
    pub comparison: Option<&'a ReferenceComparison>,
}

/// Every figure of the page that the fit has data for, in page order.
pub fn all(input: &Input) -> Vec<Figure> {
    let band = input.band;
    let mut figures = vec![map(input, band)];
    figures.push(residuals(input));
    if let Some(f) = vertical(input) {
        figures.push(f);
    }
    if let Some(f) = reference_error(input) {
        figures.push(f);
    }
    if let Some(f) = uncertainty(input, band) {
        figures.push(f);
    }
    figures.push(bias(input));
    figures
}

/// The map's size (px) for data `dx` by `dy` metres: as large as the page
/// allows at one scale for both axes, so a drive along one street is a
/// narrow picture rather than a line in an empty square.
fn map_size(dx: f64, dy: f64) -> (f64, f64) {
    let (mx, my) = (WIDTH - 70.0, MAP_HEIGHT - 60.0);
    let scale = (mx / dx.max(1e-9)).min(my / dy.max(1e-9));
    (
        (dx * scale + 70.0).clamp(360.0, WIDTH),
        (dy * scale + 60.0).clamp(260.0, MAP_HEIGHT),
    )
}

fn in_any(t: f64, spans: &[(f64, f64)]) -> bool {
    spans.iter().any(|&(a, b)| t > a && t < b)
}

fn map(input: &Input, band: &[BandPoint]) -> Figure {
    let sig = &input.model.signals;
    let path = &input.view.path;
    let reference: Vec<(f64, f64)> = input.reference.map_or(Vec::new(), |(_, m)| {
        m.at_rows.iter().map(|(_, p)| (p.x, p.y)).collect()
    });
    let xs = sig
        .fixes
        .iter()
        .map(|f| f.en[0])
        .chain(path.iter().map(|p| p[1]))
        .chain(reference.iter().map(|p| p.0));
    let ys = sig
        .fixes
        .iter()
        .map(|f| f.en[1])
        .chain(path.iter().map(|p| p[2]))
        .chain(reference.iter().map(|p| p.1));
    let (x, y) = (
        extent(xs, 0.03).unwrap_or((0.0, 1.0)),
        extent(ys, 0.03).unwrap_or((0.0, 1.0)),
    );
    let (width, height) = map_size(x.1 - x.0, y.1 - y.0);
    let frame = Frame::equal_aspect(width, height, x, y);
    let mut s = Svg::new(
        frame,
        "Map: GPS fixes, reconstructed path and its 95 % band",
    );
    s.axes("east (m)", "north (m)");
    let edges: Vec<_> = band
        .iter()
        .map(|b| {
            let [l, r] = b.edges();
            ((l[0], l[1]), (r[0], r[1]))
        })
        .collect();
    s.band(&edges, "band");
    s.line(reference.iter().copied(), "reference");
    s.dots(sig.fixes.iter().map(|f| (f.en[0], f.en[1])), "fix");
    // The path, and over it the stretches without fixes.
    let gaps = outages(sig);
    s.line(path.iter().map(|p| (p[1], p[2])), "path");
    let mut prev_in = false;
    s.line(
        path.iter().map(|p| {
            let inside = in_any(p[0], &gaps);
            let shown = inside || prev_in;
            prev_in = inside;
            if shown {
                (p[1], p[2])
            } else {
                (f64::NAN, f64::NAN)
            }
        }),
        "path-outage",
    );
    let mut legend = vec![("fix", "GPS fixes"), ("path", "path")];
    if !gaps.is_empty() {
        legend.push(("path-outage", "path in GPS outages"));
    }
    if !edges.is_empty() {
        legend.push(("band", "95 % band across the path"));
    }
    if !reference.is_empty() {
        legend.push(("reference", "reference"));
    }
    s.legend_inside(&legend);
    let widest = band.iter().map(|b| b.half_width_m).fold(0.0, f64::max);
    Figure {
        id: "map".into(),
        title: "Map".into(),
        caption: format!(
            "East and north of the ride's first fix. The band is the path's 95 % interval across the track \
             (up to {widest:.1} m wide each side; one pixel here is {:.1} m, so where the band is narrower than the line the path is known better than a pixel).",
            frame.x_per_px()
        ),
        svg: s.finish(),
    }
}

/// A time-series frame over the ride, with its outages shaded.
fn time_frame(input: &Input, values: impl IntoIterator<Item = f64>, title: &str, y: &str) -> Svg {
    let sig = &input.model.signals;
    let t = (
        sig.t.first().copied().unwrap_or(0.0),
        sig.t.last().copied().unwrap_or(1.0),
    );
    let (lo, hi) = extent(values, 0.05).unwrap_or((-1.0, 1.0));
    let mut s = Svg::new(Frame::new(WIDTH, HEIGHT, t, (lo, hi)), title);
    s.axes("time (s)", y);
    s.x_spans(&outages(sig), "outage");
    s
}

/// A series of fixes thinned to the pixel columns of `s`, broken across
/// GPS outages.
fn thinned(s: &Svg, series: &[(f64, f64)]) -> Vec<(f64, f64)> {
    min_max_columns(
        &broken_at_gaps(series, OUTAGE_S),
        s.frame().x,
        s.frame().columns(),
    )
}

fn residuals(input: &Input) -> Figure {
    let r = &input.view.residuals;
    let along: Vec<(f64, f64)> = r.iter().map(|x| (x.t, x.along)).collect();
    let cross: Vec<(f64, f64)> = r.iter().map(|x| (x.t, x.cross)).collect();
    let mut s = time_frame(
        input,
        along.iter().chain(&cross).map(|v| v.1),
        "Residuals along and across the track",
        "fix - path (m)",
    );
    s.line(thinned(&s, &along), "along");
    s.line(thinned(&s, &cross), "cross");
    s.legend(&[
        ("along", "along (+: the fix is ahead)"),
        ("cross", "across (+: the fix is to the left)"),
        ("outage", "GPS outage"),
    ]);
    Figure {
        id: "residuals".into(),
        title: "Residuals".into(),
        caption: "Each fix minus the path, split along the direction of travel and across it. \
                  A GPS latency shows along the track (in proportion to speed), a heading or scale error across it, growing through turns."
            .into(),
        svg: s.finish(),
    }
}

fn vertical(input: &Input) -> Option<Figure> {
    let up: Vec<(f64, f64)> = input
        .view
        .residuals
        .iter()
        .filter_map(|x| Some((x.t, x.up?)))
        .collect();
    if up.is_empty() {
        return None;
    }
    let mut s = time_frame(
        input,
        up.iter().map(|v| v.1),
        "Vertical residuals",
        "height - path (m)",
    );
    s.line(thinned(&s, &up), "up");
    s.legend(&[("up", "barometer or GPS height minus path")]);
    Some(Figure {
        id: "vertical".into(),
        title: "Vertical residuals".into(),
        caption: "The height measurement (barometer with its offset, else GPS altitude) minus the path's height.".into(),
        svg: s.finish(),
    })
}

fn reference_error(input: &Input) -> Option<Figure> {
    let c = input.comparison?;
    if c.series.is_empty() {
        return None;
    }
    let mut s = time_frame(
        input,
        c.series.iter().map(|v| v.1).chain([0.0]),
        "Distance of the path from the reference",
        "horizontal error (m)",
    );
    s.line(thinned(&s, &c.series), "reference-error");
    s.legend(&[
        ("reference-error", "path to reference"),
        ("outage", "GPS outage"),
    ]);
    Some(Figure {
        id: "reference-error".into(),
        title: "Error to the reference".into(),
        caption: format!(
            "Horizontal distance of the path from {} at every row it covers ({}).",
            c.reference,
            c.coverage()
        ),
        svg: s.finish(),
    })
}

fn uncertainty(input: &Input, band: &[BandPoint]) -> Option<Figure> {
    if band.is_empty() {
        return None;
    }
    let half: Vec<(f64, f64)> = band.iter().map(|b| (b.t, b.half_width_m)).collect();
    let mut s = time_frame(
        input,
        half.iter().map(|v| v.1).chain([0.0]),
        "Half-width of the 95 % band across the path",
        "95 % half-width (m)",
    );
    s.line(thinned(&s, &half), "path");
    s.legend(&[
        ("path", "1.96 sigma across the track"),
        ("outage", "GPS outage"),
    ]);
    Some(Figure {
        id: "uncertainty".into(),
        title: "How sure the path is".into(),
        caption: format!(
            "How far across the track the path may be (95 %), from the fit's posterior (GPS outages shaded){}. \
             Under a GPS error that wanders, the path can be no surer than the wander, fixes or not.",
            input
                .model
                .spec
                .band_taus
                .map_or(String::new(), |(lo, hi)| format!(
                    ", averaged over the GPS error's correlation time from {lo:.0} to {hi:.0} s \
                 (its 1-sigma range: the ride pins the wander's spread better than its time)"
                ))
        ),
        svg: s.finish(),
    })
}

fn bias(input: &Input) -> Figure {
    let segments = &input.view.segments;
    let model = input.model;
    let sigmas = input.uncertainty.map_or(Vec::new(), |u| {
        crate::diagnosis::segment_sigmas(model, &u.params)
    });
    let fitted: Vec<usize> = model.effect_index("gyro_bias").map_or(vec![2], |e| {
        let fixed = model.fixed_mask();
        let r = model.range(e);
        (0..3).filter(|&a| !fixed[r.start + a]).collect()
    });
    let sigma = |i: usize, a: usize| {
        sigmas
            .get(i)
            .filter(|_| sigmas.len() == segments.len())
            .map_or(0.0, |s| s[a])
    };
    let values = segments.iter().enumerate().flat_map(|(i, s)| {
        fitted
            .iter()
            .flat_map(move |&a| [s.bias_dps[a] - sigma(i, a), s.bias_dps[a] + sigma(i, a)])
    });
    let mut s = time_frame(
        input,
        values.collect::<Vec<_>>(),
        "Gyro bias per segment",
        "bias (deg/s)",
    );
    let names = ["x", "y", "z"];
    let mut legend = Vec::new();
    let classes = ["bias-x", "bias-y", "bias-z"];
    for &a in &fitted {
        let boxes: Vec<_> = segments
            .iter()
            .enumerate()
            .map(|(i, g)| {
                let v = g.bias_dps[a];
                (g.t0, g.t1, v - sigma(i, a), v + sigma(i, a))
            })
            .collect();
        s.boxes(&boxes, &format!("{}-band", classes[a]));
        s.line(
            segments
                .iter()
                .flat_map(|g| [(g.t0, g.bias_dps[a]), (g.t1, g.bias_dps[a])]),
            classes[a],
        );
        legend.push((classes[a], names[a]));
    }
    s.legend(&legend);
    Figure {
        id: "bias".into(),
        title: "Gyro bias".into(),
        caption: "The bias the model takes off the gyro (constant plus each segment's), with its 1-sigma per segment as a band.".into(),
        svg: s.finish(),
    }
}

/// The model history chart: held-out error, error to the fixes and to the
/// reference per model, when there is more than one model.
pub fn history(rows: &[ModelRow]) -> Option<Figure> {
    let has = |f: fn(&ModelRow) -> Option<f64>| rows.iter().any(|r| f(r).is_some());
    if rows.len() < 2 {
        return None;
    }
    let values = rows.iter().flat_map(|r| {
        [Some(r.fit_rms_m), r.heldout_rms_m, r.reference_rms_m]
            .into_iter()
            .flatten()
    });
    let (_, hi) = extent(values.chain([0.0]), 0.08)?;
    let n = rows.len() as f64;
    let frame = Frame {
        whole_x: true,
        ..Frame::new(WIDTH, HEIGHT, (-0.3, n - 0.7), (0.0, hi))
    };
    let mut s = Svg::new(frame, "Model history");
    s.axes("model (# of the table)", "RMS (m)");
    let series = |f: &dyn Fn(&ModelRow) -> Option<f64>| -> Vec<(f64, f64)> {
        rows.iter()
            .enumerate()
            .map(|(i, r)| (i as f64, f(r).unwrap_or(f64::NAN)))
            .collect()
    };
    let mut legend = vec![("fit-rms", "path to the fixes")];
    for (class, points) in [
        ("fit-rms", series(&|r| Some(r.fit_rms_m))),
        ("heldout", series(&|r| r.heldout_rms_m)),
        ("reference", series(&|r| r.reference_rms_m)),
    ] {
        s.line(points.iter().copied(), class);
        s.dots(points.iter().copied(), &format!("{class} mark"));
    }
    if has(|r| r.heldout_rms_m) {
        legend.push(("heldout", "held-out"));
    }
    if has(|r| r.reference_rms_m) {
        legend.push(("reference", "to the reference"));
    }
    s.legend(&legend);
    Some(Figure {
        id: "history".into(),
        title: "Model history".into(),
        caption: "Each model's error: to the fixes (under its own noise), held-out (fixes it did not see), and to the reference when one is given.".into(),
        svg: s.finish(),
    })
}
