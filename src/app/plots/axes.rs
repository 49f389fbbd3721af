//! What every plot shares: 1-2-5 grids with labelled ticks, thinning to the
//! pixels a plot has, and finding a time in sorted series.

use egui_plot::{GridInput, GridMark};

/// The smallest 1, 2 or 5 times a power of ten at or above `x` (> 0).
pub(super) fn nice_step(x: f64) -> f64 {
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

/// Grid marks for an axis in decades (`log10` of the value): one at every
/// decade, labelled every 1, 2, 5 or 10 decades, whichever keeps labels
/// about four grid spacings apart. The default grid is base-10 in the
/// axis's own units, so it labelled decades 0 and 10 only (1e0 and 1e10):
/// a short plot spanning six decades showed one label.
pub fn decade_grid(input: GridInput) -> Vec<GridMark> {
    if !(input.base_step_size.is_finite() && input.base_step_size > 0.0) {
        return Vec::new();
    }
    let label = nice_step((4.0 * input.base_step_size).max(1.0));
    let (lo, hi) = input.bounds;
    let (first, last) = (lo.ceil() as i64, hi.floor() as i64);
    if last - first > 10_000 {
        return Vec::new();
    }
    (first..=last)
        .map(|k| {
            let value = k as f64;
            let labelled = (value / label).round() * label == value;
            GridMark {
                value,
                step_size: if labelled { label } else { 1.0 },
            }
        })
        .collect()
}

/// The label of a decade mark: the value `10^mark` plainly from 0.001 to
/// 10,000 ("0.01", "100"), in powers of ten beyond ("1e6").
pub fn decade_label(mark: GridMark, _range: &std::ops::RangeInclusive<f64>) -> String {
    let k = mark.value.round() as i32;
    if (-3..=4).contains(&k) {
        format!("{}", 10f64.powi(k))
    } else {
        format!("1e{k}")
    }
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

/// Runs of consecutive points with the same key, each run sharing its first point
/// with the previous run's last so the drawn line has no gaps.
pub(super) fn runs<K: PartialEq + Copy>(
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
pub(super) fn thin_to_pixels(
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

/// The x range a time plot shows and its width in pixels. While the plot
/// bounds itself to its data (a plot just shown, or never zoomed), the whole
/// range: its last bounds are those of the last frame's points (or, on its
/// first frame, a unit box at the origin), and lines decimated to them would
/// keep it zoomed in on the start of the ride.
pub(super) fn view(plot: &egui_plot::PlotUi<'_>) -> (f64, f64, usize) {
    let px = plot.response().rect.width().max(1.0) as usize;
    if plot.auto_bounds().x {
        return (f64::NEG_INFINITY, f64::INFINITY, px);
    }
    let b = plot.plot_bounds();
    (b.min()[0], b.max()[0], px)
}

#[cfg(test)]
mod tests {
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
        let mark = |value: f64, step_size: f64| GridMark { value, step_size };
        assert_eq!(tick_label(mark(-0.5, 0.5), &(0.0..=1.0)), "-0.5");
        assert_eq!(tick_label(mark(0.25, 0.05), &(0.0..=1.0)), "0.25");
        assert_eq!(tick_label(mark(-800.0, 200.0), &(0.0..=1.0)), "-800");
        assert_eq!(tick_label(mark(-1e-17, 0.2), &(0.0..=1.0)), "0");
        assert_eq!(nice_step(2.0), 2.0);
        assert_eq!(nice_step(7.0), 10.0);
    }

    #[test]
    fn decades_are_marked_one_by_one_and_labelled_plainly() {
        // Six decades on a short axis: a mark per decade, labels two apart.
        let marks = decade_grid(GridInput {
            bounds: (-0.3, 6.2),
            base_step_size: 0.4,
        });
        let values: Vec<f64> = marks.iter().map(|m| m.value).collect();
        assert_eq!(values, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let labelled: Vec<f64> = marks
            .iter()
            .filter(|m| m.step_size > 1.0)
            .map(|m| m.value)
            .collect();
        assert_eq!(labelled, vec![0.0, 2.0, 4.0, 6.0]);
        // Room for every label: every decade carries one.
        let tall = decade_grid(GridInput {
            bounds: (-1.5, 2.5),
            base_step_size: 0.1,
        });
        assert_eq!(tall.len(), 4);
        assert!(tall.iter().all(|m| m.step_size == 1.0));
        let mark = |value: f64| GridMark {
            value,
            step_size: 1.0,
        };
        assert_eq!(decade_label(mark(0.0), &(0.0..=1.0)), "1");
        assert_eq!(decade_label(mark(-2.0), &(0.0..=1.0)), "0.01");
        assert_eq!(decade_label(mark(3.0), &(0.0..=1.0)), "1000");
        assert_eq!(decade_label(mark(6.0), &(0.0..=1.0)), "1e6");
        assert_eq!(decade_label(mark(-5.0), &(0.0..=1.0)), "1e-5");
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
