//! A small SVG chart writer for the report: axes with round ticks, lines,
//! dots, bands and shaded time spans, styled by CSS classes that the page
//! defines once.
//!
//! Why our own and not `plotters`' SVG backend: the report needs an
//! equal-aspect map, quads for the uncertainty band, shaded outages and
//! classes that one stylesheet colours; plotters' SVG backend writes inline
//! styles per element and needs a font backend to lay out text, while a
//! browser lays out SVG text itself. What matters most, honest decimation
//! (every pixel column keeps its minimum and maximum, so an outlier is never
//! thinned away), is ours in either case. The writer is some 250 lines.
//!
//! Coordinates: data `(x, y)` map to pixels by
//! `px = left + (x - x0) / (x1 - x0) * w`, `py = top + (1 - (y - y0) / (y1 - y0)) * h`.

use std::fmt::Write as _;

/// Margins (px) around the plotting area: room for the tick labels.
const LEFT: f64 = 58.0;
const RIGHT: f64 = 12.0;
const TOP: f64 = 26.0;
const BOTTOM: f64 = 34.0;

/// A point in data units.
pub type Point = (f64, f64);

/// Where data land on the picture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub width: f64,
    pub height: f64,
    pub x: (f64, f64),
    pub y: (f64, f64),
    /// Ticks on x only at whole numbers (a count, not a measure).
    pub whole_x: bool,
}

impl Frame {
    /// A frame over `x` and `y`, each widened when empty or not finite.
    pub fn new(width: f64, height: f64, x: (f64, f64), y: (f64, f64)) -> Self {
        Self {
            width,
            height,
            x: usable(x),
            y: usable(y),
            whole_x: false,
        }
    }

    /// A frame where one metre is as long across as up (a map): the
    /// narrower range is widened about its middle.
    pub fn equal_aspect(width: f64, height: f64, x: (f64, f64), y: (f64, f64)) -> Self {
        let (x, y) = (usable(x), usable(y));
        let (w, h) = (width - LEFT - RIGHT, height - TOP - BOTTOM);
        let per_px = ((x.1 - x.0) / w).max((y.1 - y.0) / h);
        let widen = |r: (f64, f64), px: f64| {
            let mid = 0.5 * (r.0 + r.1);
            (mid - 0.5 * per_px * px, mid + 0.5 * per_px * px)
        };
        Self {
            width,
            height,
            x: widen(x, w),
            y: widen(y, h),
            whole_x: false,
        }
    }

    /// The plotting area's width and height (px).
    fn area(&self) -> (f64, f64) {
        (self.width - LEFT - RIGHT, self.height - TOP - BOTTOM)
    }

    /// Pixel position of a data point.
    pub fn px(&self, x: f64, y: f64) -> (f64, f64) {
        let (w, h) = self.area();
        (
            LEFT + (x - self.x.0) / (self.x.1 - self.x.0) * w,
            TOP + (1.0 - (y - self.y.0) / (self.y.1 - self.y.0)) * h,
        )
    }

    /// Data length of one pixel along x.
    pub fn x_per_px(&self) -> f64 {
        (self.x.1 - self.x.0) / self.area().0
    }

    /// Pixel columns of the plotting area.
    pub fn columns(&self) -> usize {
        self.area().0.ceil().max(1.0) as usize
    }
}

/// A range that can be drawn: finite, and not empty.
fn usable((lo, hi): (f64, f64)) -> (f64, f64) {
    if !lo.is_finite() || !hi.is_finite() || hi < lo {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        let pad = (lo.abs() * 0.1).max(0.5);
        return (lo - pad, hi + pad);
    }
    (lo, hi)
}

/// The smallest and largest finite values (with `pad` of the span added
/// either side), or `None` when there is none.
pub fn extent(values: impl IntoIterator<Item = f64>, pad: f64) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    (lo <= hi).then(|| {
        let p = (hi - lo) * pad;
        (lo - p, hi + p)
    })
}

/// Round tick positions (1, 2 or 5 times a power of ten apart) inside
/// `[lo, hi]`, about `target` of them.
pub fn nice_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let span = hi - lo;
    if !(span.is_finite() && span > 0.0) {
        return Vec::new();
    }
    let raw = span / target.max(1) as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * power);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// A tick label: as many decimals as the tick step needs.
fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize
    };
    let s = format!("{v:.decimals$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        s
    }
}

/// A series with a break (NaN) wherever consecutive points are more than
/// `gap` apart in x: a line must not bridge a GPS outage as if it had data.
pub fn broken_at_gaps(series: &[(f64, f64)], gap: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(series.len() + 8);
    for (i, &p) in series.iter().enumerate() {
        if i > 0 && p.0 - series[i - 1].0 > gap {
            out.push((0.5 * (p.0 + series[i - 1].0), f64::NAN));
        }
        out.push(p);
    }
    out
}

/// Thin a time series for a plot `columns` pixels wide over `x`: per pixel
/// column, the first point and the points with the column's smallest and
/// largest value, in time order. Every peak the full series would draw is
/// still drawn; NaN values are kept as breaks.
pub fn min_max_columns(series: &[(f64, f64)], x: (f64, f64), columns: usize) -> Vec<(f64, f64)> {
    if series.len() <= 3 * columns {
        return series.to_vec();
    }
    let width = (x.1 - x.0) / columns as f64;
    let column = |t: f64| ((t - x.0) / width).floor() as i64;
    let mut out = Vec::with_capacity(4 * columns);
    let mut start = 0;
    while start < series.len() {
        let c = column(series[start].0);
        let mut end = start + 1;
        while end < series.len() && column(series[end].0) == c && series[end].1.is_finite() {
            end += 1;
        }
        let part = &series[start..end];
        let mut keep = vec![0];
        let finite = || part.iter().enumerate().filter(|(_, p)| p.1.is_finite());
        if let Some((i, _)) = finite().min_by(|a, b| a.1.1.total_cmp(&b.1.1)) {
            keep.push(i);
        }
        if let Some((i, _)) = finite().max_by(|a, b| a.1.1.total_cmp(&b.1.1)) {
            keep.push(i);
        }
        keep.push(part.len() - 1);
        keep.sort_unstable();
        keep.dedup();
        out.extend(keep.iter().map(|&i| part[i]));
        start = end;
    }
    out
}

/// One SVG picture being written.
pub struct Svg {
    frame: Frame,
    out: String,
}

/// A number in the SVG text: one decimal is a tenth of a pixel.
fn n(v: f64) -> String {
    format!("{v:.1}")
}

/// Text escaped for SVG/XML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

impl Svg {
    /// A picture of `frame` with an accessible title (a screen reader's and
    /// a tooltip's text).
    pub fn new(frame: Frame, title: &str) -> Self {
        let mut out = String::new();
        _ = write!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" class="chart" viewBox="0 0 {w} {h}" width="{w}" height="{h}" role="img"><title>{t}</title>"#,
            w = frame.width,
            h = frame.height,
            t = escape(title)
        );
        Self { frame, out }
    }

    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// Grid, ticks and the axis labels.
    pub fn axes(&mut self, x_label: &str, y_label: &str) {
        let f = self.frame;
        let (w, h) = f.area();
        _ = write!(
            self.out,
            r#"<rect class="area" x="{LEFT}" y="{TOP}" width="{}" height="{}"/>"#,
            n(w),
            n(h)
        );
        let mut xt = nice_ticks(f.x.0, f.x.1, (w / 90.0).max(2.0) as usize);
        if f.whole_x {
            xt = (f.x.0.ceil() as i64..=f.x.1.floor() as i64)
                .map(|i| i as f64)
                .collect();
        }
        let yt = nice_ticks(f.y.0, f.y.1, (h / 45.0).max(2.0) as usize);
        let step = |t: &[f64]| if t.len() > 1 { t[1] - t[0] } else { 1.0 };
        for &x in &xt {
            let (px, _) = f.px(x, f.y.0);
            _ = write!(
                self.out,
                r#"<line class="grid" x1="{p}" y1="{TOP}" x2="{p}" y2="{b}"/><text class="tick" x="{p}" y="{ty}" text-anchor="middle">{l}</text>"#,
                p = n(px),
                b = n(TOP + h),
                ty = n(TOP + h + 14.0),
                l = tick_label(x, step(&xt))
            );
        }
        for &y in &yt {
            let (_, py) = f.px(f.x.0, y);
            _ = write!(
                self.out,
                r#"<line class="grid" x1="{LEFT}" y1="{p}" x2="{r}" y2="{p}"/><text class="tick" x="{tx}" y="{ty}" text-anchor="end">{l}</text>"#,
                p = n(py),
                r = n(LEFT + w),
                tx = n(LEFT - 5.0),
                ty = n(py + 4.0),
                l = tick_label(y, step(&yt))
            );
        }
        _ = write!(
            self.out,
            r#"<text class="label" x="{x}" y="{y}" text-anchor="middle">{xl}</text><text class="label" transform="translate(13 {cy}) rotate(-90)" text-anchor="middle">{yl}</text>"#,
            x = n(LEFT + w / 2.0),
            y = n(f.height - 4.0),
            xl = escape(x_label),
            cy = n(TOP + h / 2.0),
            yl = escape(y_label)
        );
    }

    /// Shaded spans of x (GPS outages), drawn under the data.
    pub fn x_spans(&mut self, spans: &[(f64, f64)], class: &str) {
        let f = self.frame;
        let (_, h) = f.area();
        for &(a, b) in spans {
            let (pa, _) = f.px(a.max(f.x.0), 0.0);
            let (pb, _) = f.px(b.min(f.x.1), 0.0);
            if pb > pa {
                _ = write!(
                    self.out,
                    r#"<rect class="{class}" x="{}" y="{TOP}" width="{}" height="{}"/>"#,
                    n(pa),
                    n(pb - pa),
                    n(h)
                );
            }
        }
    }

    /// A line through `points`, broken at every non-finite value; points
    /// that fall on the pixel of the one before are left out.
    pub fn line(&mut self, points: impl IntoIterator<Item = (f64, f64)>, class: &str) {
        let mut d = String::new();
        let mut last: Option<(f64, f64)> = None;
        for (x, y) in points {
            if !(x.is_finite() && y.is_finite()) {
                last = None;
                continue;
            }
            let p = self.frame.px(x, y);
            match last {
                Some(l) if (l.0 - p.0).abs() < 0.5 && (l.1 - p.1).abs() < 0.5 => continue,
                Some(_) => _ = write!(d, "L{} {}", n(p.0), n(p.1)),
                None => _ = write!(d, "M{} {}", n(p.0), n(p.1)),
            }
            last = Some(p);
        }
        if !d.is_empty() {
            _ = write!(self.out, r#"<path class="{class}" d="{d}"/>"#);
        }
    }

    /// A dot at each point; a dot on a pixel already dotted is left out.
    pub fn dots(&mut self, points: impl IntoIterator<Item = (f64, f64)>, class: &str) {
        let mut seen = std::collections::HashSet::new();
        let mut d = String::new();
        for (x, y) in points {
            if !(x.is_finite() && y.is_finite()) {
                continue;
            }
            let p = self.frame.px(x, y);
            if seen.insert((p.0.round() as i64, p.1.round() as i64)) {
                // A zero-length segment with a round cap draws a dot: one
                // path for all of them instead of an element per fix.
                _ = write!(d, "M{} {}h0", n(p.0), n(p.1));
            }
        }
        if !d.is_empty() {
            _ = write!(self.out, r#"<path class="{class}" d="{d}"/>"#);
        }
    }

    /// Filled quadrilaterals between consecutive pairs of `(left, right)`
    /// edge points: a band along a path that may cross itself.
    pub fn band(&mut self, edges: &[(Point, Point)], class: &str) {
        let mut d = String::new();
        for w in edges.windows(2) {
            let [a, b] = [w[0], w[1]];
            let pts = [a.0, b.0, b.1, a.1].map(|(x, y)| self.frame.px(x, y));
            if pts.iter().any(|p| !(p.0.is_finite() && p.1.is_finite())) {
                continue;
            }
            _ = write!(
                d,
                "M{} {}L{} {}L{} {}L{} {}Z",
                n(pts[0].0),
                n(pts[0].1),
                n(pts[1].0),
                n(pts[1].1),
                n(pts[2].0),
                n(pts[2].1),
                n(pts[3].0),
                n(pts[3].1)
            );
        }
        if !d.is_empty() {
            // Inside a nested `svg` the size of the plot area, which clips
            // what lies outside it: the map's extent is the fixes' and the
            // path's, and a wider band (the Husky robot's 12 m each side)
            // ran over the axes and the legend.
            let (w, h) = self.frame.area();
            _ = write!(
                self.out,
                r#"<svg x="{LEFT}" y="{TOP}" width="{w}" height="{h}" viewBox="{LEFT} {TOP} {w} {h}"><path class="{class}" d="{d}"/></svg>"#,
                w = n(w),
                h = n(h)
            );
        }
    }

    /// Filled rectangles from `(x0, x1, y_lo, y_hi)` (a per-segment band).
    pub fn boxes(&mut self, boxes: &[(f64, f64, f64, f64)], class: &str) {
        let mut d = String::new();
        for &(x0, x1, lo, hi) in boxes {
            let (a, b) = (self.frame.px(x0, hi), self.frame.px(x1, lo));
            if [a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) {
                _ = write!(
                    d,
                    "M{} {}H{}V{}H{}Z",
                    n(a.0),
                    n(a.1),
                    n(b.0),
                    n(b.1),
                    n(a.0)
                );
            }
        }
        if !d.is_empty() {
            _ = write!(self.out, r#"<path class="{class}" d="{d}"/>"#);
        }
    }

    /// A legend in a row above the plotting area: `(class, label)` per
    /// entry (the width of a label is reckoned at 6.2 px per character of
    /// the 11 px font, so a long row wraps to a second line in the margin
    /// only when it would leave the picture; then it is cut).
    pub fn legend(&mut self, entries: &[(&str, &str)]) {
        let mut x = LEFT;
        let y = TOP - 9.0;
        for (class, label) in entries {
            _ = write!(
                self.out,
                r#"<path class="{class} key" d="M{x0} {py}h18"/><text class="legend" x="{tx}" y="{ty}">{l}</text>"#,
                x0 = n(x),
                py = n(y - 4.0),
                tx = n(x + 23.0),
                ty = n(y),
                l = escape(label)
            );
            x += 23.0 + 6.2 * label.chars().count() as f64 + 16.0;
        }
    }

    /// A legend down the top-left corner of the plotting area (a map's,
    /// whose corners are mostly empty and whose width varies), on a pale
    /// backing: a wide 95 % band or a dense track may run under the corner
    /// (the Husky robot's 12 m band did), and the keys must stay legible.
    pub fn legend_inside(&mut self, entries: &[(&str, &str)]) {
        if entries.is_empty() {
            return;
        }
        let widest = entries
            .iter()
            .map(|(_, label)| label.chars().count())
            .max()
            .unwrap_or(0);
        _ = write!(
            self.out,
            r#"<rect class="legend-back" x="{x}" y="{y}" width="{w}" height="{h}" rx="3"/>"#,
            x = n(LEFT + 3.0),
            y = n(TOP + 3.0),
            w = n(33.0 + 6.2 * widest as f64),
            h = n(16.0 * entries.len() as f64 + 5.0)
        );
        let mut y = TOP + 16.0;
        for (class, label) in entries {
            _ = write!(
                self.out,
                r#"<path class="{class} key" d="M{x0} {py}h18"/><text class="legend" x="{tx}" y="{ty}">{l}</text>"#,
                x0 = n(LEFT + 8.0),
                py = n(y - 4.0),
                tx = n(LEFT + 31.0),
                ty = n(y),
                l = escape(label)
            );
            y += 16.0;
        }
    }

    /// The finished `<svg>` element.
    pub fn finish(mut self) -> String {
        self.out.push_str("</svg>");
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_inside() {
        let t = nice_ticks(0.3, 9.7, 5);
        assert_eq!(t, vec![2.0, 4.0, 6.0, 8.0]);
        let t = nice_ticks(-0.013, 0.021, 4);
        assert!(t.iter().all(|v| (-0.013..=0.021).contains(v)), "{t:?}");
        assert_eq!(tick_label(0.01, 0.01), "0.01");
        assert_eq!(tick_label(-0.0, 0.01), "0");
        assert!(nice_ticks(1.0, 1.0, 4).is_empty());
    }

    #[test]
    fn a_map_legend_sits_on_a_backing_that_holds_its_longest_label() {
        let frame = || Frame::new(400.0, 300.0, (0.0, 1.0), (0.0, 1.0));
        let mut svg = Svg::new(frame(), "map");
        svg.legend_inside(&[("fix", "GPS fixes"), ("band", "95 % band across the path")]);
        let out = svg.finish();
        let back = out.find("legend-back").expect("a backing");
        assert!(back < out.find("GPS fixes").expect("a label"), "{out}");
        // 33 + 6.2 x 25 characters wide, two rows of 16 + 5 high.
        assert!(out.contains(r#"width="188.0" height="37.0""#), "{out}");
        let mut empty = Svg::new(frame(), "map");
        empty.legend_inside(&[]);
        assert!(!empty.finish().contains("legend-back"));
    }

    #[test]
    fn a_band_is_clipped_to_the_plot_area() {
        // A band 50 m each side of a 10 m path: far wider than the frame.
        let frame = Frame::equal_aspect(400.0, 300.0, (0.0, 10.0), (-1.0, 1.0));
        let mut s = Svg::new(frame, "band");
        s.band(
            &[((0.0, 50.0), (0.0, -50.0)), ((10.0, 50.0), (10.0, -50.0))],
            "band",
        );
        let out = s.finish();
        let (w, h) = frame.area();
        let clip = format!(
            r#"<svg x="{LEFT}" y="{TOP}" width="{w}" height="{h}" viewBox="{LEFT} {TOP} {w} {h}"><path class="band" d="M"#,
            w = n(w),
            h = n(h)
        );
        assert!(out.contains(&clip), "{out}");
    }

    #[test]
    fn thinning_keeps_every_column_extreme() {
        // 100 000 samples of noise with one spike: the spike survives.
        let mut s: Vec<(f64, f64)> = (0..100_000)
            .map(|i| (i as f64, ((i * 7919) % 13) as f64))
            .collect();
        s[61_234].1 = 500.0;
        s[7].1 = -80.0;
        let thin = min_max_columns(&s, (0.0, 100_000.0), 600);
        assert!(thin.len() <= 4 * 600 + 4, "{}", thin.len());
        assert!(thin.contains(&(61_234.0, 500.0)));
        assert!(thin.contains(&(7.0, -80.0)));
        assert!(thin.windows(2).all(|w| w[0].0 <= w[1].0), "time order kept");
        // Short series are kept whole.
        assert_eq!(min_max_columns(&s[..50], (0.0, 50.0), 600).len(), 50);
    }

    #[test]
    fn an_equal_aspect_frame_has_square_metres() {
        let f = Frame::equal_aspect(800.0, 500.0, (0.0, 1000.0), (0.0, 100.0));
        let (a, b) = (f.px(0.0, 0.0), f.px(100.0, 100.0));
        assert!(((b.0 - a.0) - (a.1 - b.1)).abs() < 1e-9);
    }

    #[test]
    fn lines_break_at_nan_and_text_is_escaped() {
        let mut s = Svg::new(
            Frame::new(300.0, 200.0, (0.0, 10.0), (0.0, 10.0)),
            "a <b> & c",
        );
        s.line(
            [
                (0.0, 0.0),
                (5.0, 5.0),
                (6.0, f64::NAN),
                (7.0, 7.0),
                (9.0, 1.0),
            ],
            "p",
        );
        let svg = s.finish();
        assert_eq!(svg.matches('M').count(), 2, "{svg}");
        assert!(svg.contains("a &lt;b&gt; &amp; c"));
    }
}
