//! A fit thinned for drawing: the path at a bounded number of rows, the
//! residual of every fix and the bias per segment, from one sweep of the
//! ride. The app draws it after every iteration and the report draws it
//! once; neither holds the whole trajectory (some 190 MB on a 6-hour ride).

use crate::model::{Model, PathAt, SparsePath};
use crate::signals::Signals;

use super::{FixResidual, SegmentBias, fix_residuals, segment_biases};

/// A gap between fixes longer than this (s) is a GPS outage.
pub const OUTAGE_S: f64 = 2.5;

/// The path's rows thinned to at most `max` (evenly, always keeping the last row).
pub fn decimated_rows(n: usize, max: usize) -> Vec<usize> {
    let stride = n.div_ceil(max.max(1)).max(1);
    let mut rows: Vec<usize> = (0..n).step_by(stride).collect();
    if n > 0 && !(n - 1).is_multiple_of(stride) {
        rows.push(n - 1);
    }
    rows
}

/// GPS outages (log time from, to): gaps between fixes, or between a fix
/// and the ride's start or end, longer than [`OUTAGE_S`].
pub fn outages(sig: &Signals) -> Vec<(f64, f64)> {
    let (Some(&first), Some(&last)) = (sig.t.first(), sig.t.last()) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut prev = first;
    for f in sig.fixes.iter().map(|f| f.t).chain(std::iter::once(last)) {
        if f - prev > OUTAGE_S {
            out.push((prev, f));
        }
        prev = f;
    }
    out
}

/// `(t, value)` pairs thinned to at most `n`: each kept point is the largest
/// value of the stretch it stands for, so no error peak is lost to drawing.
pub fn peaks(series: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let stride = series.len().div_ceil(n.max(1)).max(1);
    series
        .chunks(stride)
        .filter_map(|c| c.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)))
        .collect()
}

/// z of the two-sided 95 % interval of a normal error.
pub const Z95: f64 = 1.959_964;

/// One point of the path's 95 % band: the path there, its normal (unit,
/// to the left of travel) and the band's half-width across the track.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BandPoint {
    /// Log time (s), east and north (m).
    pub t: f64,
    pub east: f64,
    pub north: f64,
    pub normal: [f64; 2],
    /// `1.96 sigma_cross` (m), with `sigma_cross^2 = n' S n` for the
    /// east-north covariance `S` and the normal `n`.
    pub half_width_m: f64,
}

impl BandPoint {
    /// The band's left and right edges here (east, north).
    pub fn edges(&self) -> [[f64; 2]; 2] {
        let w = self.half_width_m;
        [
            [
                self.east + w * self.normal[0],
                self.north + w * self.normal[1],
            ],
            [
                self.east - w * self.normal[0],
                self.north - w * self.normal[1],
            ],
        ]
    }
}

/// The 95 % band across the path at each point of `path` (log time, east,
/// north), from the east-north covariance there (`[var_e, var_n, cov_en]`,
/// m^2, same length). The direction of travel is that from the point before
/// to the point after; standing still, the last one. Empty when the lengths
/// differ.
pub fn cross_band(path: &[[f64; 3]], cov: &[[f64; 3]]) -> Vec<BandPoint> {
    if cov.len() != path.len() || path.len() < 2 {
        return Vec::new();
    }
    let mut normal = [0.0, 1.0];
    (0..path.len())
        .map(|i| {
            let (a, b) = (path[i.saturating_sub(1)], path[(i + 1).min(path.len() - 1)]);
            let (de, dn) = (b[1] - a[1], b[2] - a[2]);
            let len = de.hypot(dn);
            if len > 1e-6 {
                normal = [-dn / len, de / len];
            }
            let [ve, vn, c] = cov[i];
            let var = normal[0] * normal[0] * ve
                + 2.0 * normal[0] * normal[1] * c
                + normal[1] * normal[1] * vn;
            BandPoint {
                t: path[i][0],
                east: path[i][1],
                north: path[i][2],
                normal,
                half_width_m: Z95 * var.max(0.0).sqrt(),
            }
        })
        .collect()
}

/// What is drawn of a fit.
pub struct FitView {
    /// The rows drawn, and the path there: log time, east, north (m).
    pub rows: Vec<usize>,
    pub path: Vec<[f64; 3]>,
    /// Every fix's residual.
    pub residuals: Vec<FixResidual>,
    pub segments: Vec<SegmentBias>,
    /// The path at the drawn rows and at the rows the residuals read.
    pub sparse: SparsePath,
}

impl FitView {
    /// The view of `model` at `theta`, with the path at most `max_points`.
    pub fn of(model: &Model, theta: &[f64], max_points: usize) -> Self {
        let t = &model.signals.t;
        let path_rows = decimated_rows(t.len(), max_points);
        let mut rows = model.residual_rows(theta);
        rows.extend(&path_rows);
        rows.sort_unstable();
        rows.dedup();
        let sparse = model.sparse_path(theta, rows);
        let residuals = fix_residuals(model, theta, &sparse);
        let path = path_rows
            .iter()
            .map(|&j| {
                let p = sparse.p_at(j);
                [t[j], p.x, p.y]
            })
            .collect();
        Self {
            rows: path_rows,
            path,
            residuals,
            segments: segment_biases(model, theta),
            sparse,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_bounded_and_keep_the_ends() {
        let r = decimated_rows(10_001, 4000);
        assert!(r.len() <= 4001);
        assert_eq!((r[0], *r.last().unwrap()), (0, 10_000));
        assert_eq!(decimated_rows(5, 4000), vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn the_band_is_the_cross_track_interval() {
        // Travel north-east; the error is 2 m (1-sigma) across, 0 along.
        let path: Vec<[f64; 3]> = (0..5).map(|i| [i as f64, i as f64, i as f64]).collect();
        let n = [-(0.5f64).sqrt(), (0.5f64).sqrt()];
        let cov = [n[0] * n[0] * 4.0, n[1] * n[1] * 4.0, n[0] * n[1] * 4.0];
        let band = cross_band(&path, &[cov; 5]);
        for b in &band {
            assert!((b.half_width_m - Z95 * 2.0).abs() < 1e-9, "{b:?}");
            assert!((b.normal[0] - n[0]).abs() < 1e-12 && (b.normal[1] - n[1]).abs() < 1e-12);
        }
        let [l, r] = band[2].edges();
        assert!((l[0] - r[0] + 2.0 * Z95 * 2.0 * (0.5f64).sqrt()).abs() < 1e-9);
        assert!(cross_band(&path, &[cov]).is_empty());
    }

    #[test]
    fn peaks_keep_the_largest_of_each_stretch() {
        let s: Vec<(f64, f64)> = (0..100).map(|i| (i as f64, (i % 10) as f64)).collect();
        let p = peaks(&s, 10);
        assert_eq!(p.len(), 10);
        assert!(p.iter().all(|v| v.1 == 9.0));
    }
}
