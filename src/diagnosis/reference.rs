//! A fitted path measured against a reference track (see
//! [`crate::import::reference`]): what a user with RTK or an INS wants to
//! know first, and what tells which model is truly better where held-out
//! GPS cannot (the fixes of a city are 20 m off).
//!
//! The reference is matched on the ride's clock: at every row `j` whose time
//! lies between two reference points `k`, `k+1` at most [`MAX_GAP_S`] apart,
//! the reference position is interpolated linearly in the local frame,
//! `r(t_j) = r_k + (t_j - t_k) / (t_{k+1} - t_k) (r_{k+1} - r_k)`, and the
//! error is `e_j = p_j - r(t_j)`. Rows outside the reference or in its gaps
//! are not compared; the coverage says how much was. The along- and
//! cross-track parts are `e_j` on the path's horizontal heading `f_j` and on
//! `up x f_j` (left positive). Heights are compared only where both the
//! reference and the ride have them (GPS altitude or a barometer).
//!
//! The measurements and the history behind these choices: docs/command-
//! line.md (reference tracks) and docs/real-drives.md.

use nalgebra::Vector3;
use thiserror::Error;

use crate::import::reference::ReferenceTrack;
use crate::model::Model;
use crate::signals::Signals;

/// Reference points further apart than this (s) are a gap: nothing between
/// them is compared.
pub const MAX_GAP_S: f64 = 2.0;

/// A reference whose median distance from the ride's fixes is beyond this
/// (m) is not of this ride (city fixes are up to 70 m off; a wrong file is
/// kilometres away).
pub const MAX_FIX_DISTANCE_M: f64 = 300.0;

/// Why a reference cannot be compared with a ride.
#[derive(Debug, Error, PartialEq)]
pub enum ReferenceError {
    #[error(
        "{reference}: no time in common with the ride (reference {r0:.1}-{r1:.1} s, ride {s0:.1}-{s1:.1} s on the ride's clock)"
    )]
    NoOverlap {
        reference: String,
        r0: f64,
        r1: f64,
        s0: f64,
        s1: f64,
    },
    #[error(
        "{reference}: is not of this ride: it runs {median_m:.0} m from the ride's GPS fixes in the median (more than {MAX_FIX_DISTANCE_M:.0} m)"
    )]
    TooFar { reference: String, median_m: f64 },
}

/// Order statistics of an error (m).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    pub rms_m: f64,
    pub median_m: f64,
    pub p95_m: f64,
    pub max_m: f64,
}

impl ErrorStats {
    /// Statistics of the absolute values in `v` (`None` when empty).
    pub fn of(mut v: Vec<f64>) -> Option<Self> {
        if v.is_empty() {
            return None;
        }
        for x in &mut v {
            *x = x.abs();
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let at = |q: f64| v[((q * (n - 1) as f64).round() as usize).min(n - 1)];
        Some(Self {
            rms_m: (v.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt(),
            median_m: at(0.5),
            p95_m: at(0.95),
            max_m: v[n - 1],
        })
    }

    /// "RMS 9.31 m, median 7.20, 95 % 18.1, max 25.3".
    pub fn describe(&self) -> String {
        format!(
            "RMS {:.2} m, median {:.2}, 95 % {:.2}, max {:.2}",
            self.rms_m, self.median_m, self.p95_m, self.max_m
        )
    }
}

/// A path compared with a reference track.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ReferenceComparison {
    pub reference: String,
    /// Rows compared, and the ride time they cover (s) of the ride's duration.
    pub rows: usize,
    pub covered_s: f64,
    pub ride_s: f64,
    /// Horizontal distance from the reference.
    pub horizontal: ErrorStats,
    /// Along- and cross-track parts (RMS, m).
    pub along_rms_m: f64,
    pub cross_rms_m: f64,
    /// Height error, where both have heights.
    pub vertical: Option<ErrorStats>,
    /// The GPS fixes' own horizontal distance from the reference over the
    /// same coverage: what the path has to beat.
    pub fixes: Option<ErrorStats>,
    /// `(t_s, horizontal error m)` at every compared row, for plots.
    #[serde(skip)]
    pub series: Vec<(f64, f64)>,
}

impl ReferenceComparison {
    /// One or two lines for a terminal.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "path {} (along {:.2}, cross {:.2}){}",
            self.horizontal.describe(),
            self.along_rms_m,
            self.cross_rms_m,
            self.vertical.map_or(String::new(), |v| format!(
                "; vertical RMS {:.2} m",
                v.rms_m
            )),
        );
        if let Some(f) = &self.fixes {
            s += &format!("\n          GPS fixes {}", f.describe());
        }
        s
    }

    /// "covers 140 s of 283 s (675 rows)".
    pub fn coverage(&self) -> String {
        format!(
            "covers {:.0} s of the ride's {:.0} s ({} rows)",
            self.covered_s, self.ride_s, self.rows
        )
    }
}

/// The reference in the ride's local frame, interpolated at the ride's rows.
pub struct Matched {
    /// `(row, reference position)` for every covered row, in row order.
    pub at_rows: Vec<(usize, Vector3<f64>)>,
}

impl Matched {
    /// The ride time it covers (s): the step `dt_j` of every covered row
    /// whose row before it is covered too.
    pub fn covered_s(&self, signals: &Signals) -> f64 {
        self.at_rows
            .windows(2)
            .filter(|w| w[1].0 == w[0].0 + 1)
            .map(|w| signals.dt[w[1].0])
            .sum()
    }
}

/// Match `reference` to the rows of `signals` (see the module documentation).
pub fn match_rows(
    signals: &Signals,
    reference: &ReferenceTrack,
) -> Result<Matched, ReferenceError> {
    let (t, rt) = (&signals.t, &reference.t_s);
    let (s0, s1) = (t[0], t[t.len() - 1]);
    let (r0, r1) = (rt[0], rt[rt.len() - 1]);
    let no_overlap = || ReferenceError::NoOverlap {
        reference: reference.source.clone(),
        r0,
        r1,
        s0,
        s1,
    };
    if r1 < s0 || r0 > s1 {
        return Err(no_overlap());
    }
    let enu: Vec<Vector3<f64>> = reference
        .points
        .iter()
        .map(|g| {
            let alt = if g.alt_m.is_finite() { g.alt_m } else { 0.0 };
            let mut p = signals
                .frame
                .to_enu(&crate::geodesy::Geodetic::new(g.lat_deg, g.lon_deg, alt));
            if !g.alt_m.is_finite() {
                p.z = f64::NAN;
            }
            p
        })
        .collect();
    let mut at_rows = Vec::new();
    let mut k = 0usize;
    for (j, &tj) in t.iter().enumerate() {
        if tj < r0 || tj > r1 {
            continue;
        }
        while k + 2 < rt.len() && rt[k + 1] < tj {
            k += 1;
        }
        let (ta, tb) = (rt[k], rt[k + 1]);
        if tj < ta || tj > tb || tb - ta > MAX_GAP_S {
            continue;
        }
        let w = (tj - ta) / (tb - ta);
        at_rows.push((j, enu[k] + w * (enu[k + 1] - enu[k])));
    }
    if at_rows.is_empty() {
        return Err(no_overlap());
    }
    // A file of another drive: far from every fix it overlaps.
    let mut d = fix_distances(signals, &at_rows);
    if !d.is_empty() {
        let median = crate::statistics::median(&mut d);
        if median > MAX_FIX_DISTANCE_M {
            return Err(ReferenceError::TooFar {
                reference: reference.source.clone(),
                median_m: median,
            });
        }
    }
    Ok(Matched { at_rows })
}

/// `(t, [east, north])`: the error of every fix on a covered row against
/// the reference there (m), in row order.
fn fix_errors(signals: &Signals, at_rows: &[(usize, Vector3<f64>)]) -> Vec<(f64, [f64; 2])> {
    let mut out = Vec::new();
    let mut k = 0usize;
    for f in &signals.fixes {
        while k < at_rows.len() && at_rows[k].0 < f.row {
            k += 1;
        }
        if let Some((row, r)) = at_rows.get(k)
            && *row == f.row
        {
            out.push((f.t, [f.en[0] - r.x, f.en[1] - r.y]));
        }
    }
    out
}

/// The horizontal distance of every fix on a covered row from the reference there.
fn fix_distances(signals: &Signals, at_rows: &[(usize, Vector3<f64>)]) -> Vec<f64> {
    fix_errors(signals, at_rows)
        .iter()
        .map(|(_, e)| e[0].hypot(e[1]))
        .collect()
}

/// Compare the path of `model` at `theta` with the matched reference.
pub fn compare(
    model: &Model,
    theta: &[f64],
    reference: &ReferenceTrack,
    matched: &Matched,
) -> ReferenceComparison {
    let sig = &model.signals;
    let has_heights = sig.has_gps_alt || sig.has_baro;
    let n = matched.at_rows.len();
    let (mut horizontal, mut along, mut cross, mut vertical) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::new(),
    );
    let mut series = Vec::with_capacity(n);
    let mut next = 0usize;
    model.for_each_pose(theta, |j, q, p| {
        let Some(&(row, r)) = matched.at_rows.get(next) else {
            return;
        };
        if row != j {
            return;
        }
        next += 1;
        let e = p - r;
        let forward = q * Vector3::x();
        let h = forward.x.hypot(forward.y);
        let (fx, fy) = if h > 1e-9 {
            (forward.x / h, forward.y / h)
        } else {
            (1.0, 0.0)
        };
        let dist = e.x.hypot(e.y);
        horizontal.push(dist);
        along.push(e.x * fx + e.y * fy);
        cross.push(-e.x * fy + e.y * fx);
        if has_heights && r.z.is_finite() {
            vertical.push(e.z);
        }
        series.push((sig.t[j], dist));
    });
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let fixes = fix_distances(sig, &matched.at_rows);
    ReferenceComparison {
        reference: reference.source.clone(),
        rows: horizontal.len(),
        covered_s: matched.covered_s(sig),
        ride_s: sig.duration(),
        along_rms_m: rms(&along),
        cross_rms_m: rms(&cross),
        horizontal: ErrorStats::of(horizontal).unwrap_or(ErrorStats {
            rms_m: f64::NAN,
            median_m: f64::NAN,
            p95_m: f64::NAN,
            max_m: f64::NAN,
        }),
        vertical: ErrorStats::of(vertical),
        fixes: ErrorStats::of(fixes),
        series,
    }
}

/// What a ride's GPS errors look like against a reference: the statistics
/// that tell a city's reflections from an open sky's wander, to set a
/// simulated ride beside a real one (`examples/gps_errors.rs`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GpsErrorStatistics {
    /// Fixes on covered rows.
    pub fixes: usize,
    /// Horizontal distance of the fixes from the reference.
    pub error: ErrorStats,
    /// Share of fixes more than 15 m off, and the mean length (in fixes) of
    /// a run of them.
    pub over_15m: f64,
    pub mean_run_over_15m: f64,
    /// Correlation of the error (east and north pooled, each about its
    /// mean) between fixes 1, 5, 10 and 30 s apart (within 0.25 s).
    pub correlation: [(f64, Option<f64>); 4],
    /// Share of the covered whole seconds that hold a fix.
    pub availability: f64,
}

impl GpsErrorStatistics {
    pub fn of(signals: &Signals, matched: &Matched) -> Option<Self> {
        let errors = fix_errors(signals, &matched.at_rows);
        if errors.len() < 2 {
            return None;
        }
        let distances: Vec<f64> = errors.iter().map(|(_, e)| e[0].hypot(e[1])).collect();
        let over: Vec<bool> = distances.iter().map(|d| *d > 15.0).collect();
        let runs = over.windows(2).filter(|w| w[1] && !w[0]).count() + usize::from(over[0]);
        let n_over = over.iter().filter(|o| **o).count();
        let mean =
            [0, 1].map(|a| errors.iter().map(|(_, e)| e[a]).sum::<f64>() / errors.len() as f64);
        let var: f64 = errors
            .iter()
            .map(|(_, e)| (e[0] - mean[0]).powi(2) + (e[1] - mean[1]).powi(2))
            .sum::<f64>()
            / errors.len() as f64;
        let correlation = [1.0, 5.0, 10.0, 30.0].map(|lag| {
            let mut k = 0usize;
            let (mut sum, mut n) = (0.0, 0usize);
            for (t, e) in &errors {
                while k < errors.len() && errors[k].0 < t + lag - 0.25 {
                    k += 1;
                }
                if let Some((u, g)) = errors.get(k)
                    && (u - t - lag).abs() <= 0.25
                {
                    sum +=
                        (e[0] - mean[0]) * (g[0] - mean[0]) + (e[1] - mean[1]) * (g[1] - mean[1]);
                    n += 1;
                }
            }
            (lag, (n >= 10 && var > 0.0).then(|| sum / n as f64 / var))
        });
        let t = &signals.t;
        let covered: std::collections::BTreeSet<i64> = matched
            .at_rows
            .iter()
            .map(|(j, _)| t[*j].round() as i64)
            .collect();
        let with_fix: std::collections::BTreeSet<i64> =
            errors.iter().map(|(t, _)| t.round() as i64).collect();
        Some(Self {
            fixes: errors.len(),
            error: ErrorStats::of(distances)?,
            over_15m: n_over as f64 / errors.len() as f64,
            mean_run_over_15m: if runs > 0 {
                n_over as f64 / runs as f64
            } else {
                0.0
            },
            correlation,
            availability: with_fix.len() as f64 / covered.len().max(1) as f64,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::geodesy::Geodetic;
    use crate::model::ModelSpec;

    /// The model's own initial path as a reference, shifted by `offset` (east, north, m).
    fn reference_of(
        model: &Model,
        theta: &[f64],
        offset: [f64; 2],
        every: usize,
    ) -> ReferenceTrack {
        let sig = &model.signals;
        let mut r = ReferenceTrack::empty("ref.csv", crate::import::reference::Clock::Ride);
        model.for_each_pose(theta, |j, _, p| {
            if j % every == 0 {
                let g = sig
                    .frame
                    .to_geodetic(&(p + Vector3::new(offset[0], offset[1], 0.0)));
                r.t_s.push(sig.t[j]);
                r.points.push(Geodetic::new(g.lat_deg, g.lon_deg, f64::NAN));
            }
        });
        r
    }

    #[test]
    fn a_shifted_copy_of_the_path_reads_as_its_shift_along_and_across() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 120.0, &[]));
        let model = Model::new(sig.clone(), ModelSpec::default()).unwrap();
        let theta = model.initial_params();
        // Every 10th row (0.1 s): interpolation between points on a smooth path is exact to mm.
        let r = reference_of(&model, &theta, [3.0, 4.0], 10);
        let m = match_rows(&sig, &r).unwrap();
        let c = compare(&model, &theta, &r, &m);
        assert!((c.horizontal.rms_m - 5.0).abs() < 0.02, "{c:?}");
        assert!((c.horizontal.max_m - 5.0).abs() < 0.05, "{c:?}");
        assert!((c.along_rms_m.hypot(c.cross_rms_m) - 5.0).abs() < 0.02);
        assert!(c.vertical.is_none());
        assert!(c.covered_s > 0.95 * sig.duration(), "{}", c.coverage());
        let f = c.fixes.unwrap();
        assert!(f.rms_m > 1.0, "the fixes have their own noise: {f:?}");
    }

    #[test]
    fn coverage_gaps_and_foreign_references_are_stated() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 120.0, &[]));
        let model = Model::new(sig.clone(), ModelSpec::default()).unwrap();
        let theta = model.initial_params();
        let mut r = reference_of(&model, &theta, [0.0, 0.0], 10);
        // Keep the first 60 s, with a 10 s gap in it.
        let keep: Vec<bool> = r
            .t_s
            .iter()
            .map(|&t| t <= 60.0 && !(20.0..30.0).contains(&t))
            .collect();
        let mut k = keep.iter();
        r.points.retain(|_| *k.next().unwrap());
        r.t_s.retain(|&t| t <= 60.0 && !(20.0..30.0).contains(&t));
        let c = compare(&model, &theta, &r, &match_rows(&sig, &r).unwrap());
        assert!((c.covered_s - 50.0).abs() < 1.0, "{}", c.coverage());

        let late = ReferenceTrack {
            t_s: r.t_s.iter().map(|t| t + 1000.0).collect(),
            ..r.clone()
        };
        assert!(matches!(
            match_rows(&sig, &late),
            Err(ReferenceError::NoOverlap { .. })
        ));
        let far = reference_of(&model, &theta, [2000.0, 0.0], 10);
        let e = match_rows(&sig, &far).err().unwrap();
        assert!(e.to_string().contains("not of this ride"), "{e}");
    }

    #[test]
    fn error_stats_are_order_statistics_of_the_absolute_values() {
        let s = ErrorStats::of((1..=100).map(|i| -(i as f64)).collect()).unwrap();
        assert_eq!(s.max_m, 100.0);
        assert!((s.median_m - 50.5).abs() <= 0.5);
        assert!((s.p95_m - 95.0).abs() <= 1.0);
        assert!((s.rms_m - (338350.0f64 / 100.0).sqrt()).abs() < 1e-9);
        assert!(ErrorStats::of(Vec::new()).is_none());
    }

    #[test]
    fn the_gps_error_statistics_of_a_simulated_ride_are_its_own() {
        // The open-sky simulator: a 1.5 m wander over 60 s plus 0.5 m of
        // jitter, a fix nearly every second outside its outages.
        let sig = crate::testing::simulated_signals(3, 600.0, &[]);
        let truth = crate::testing::simulated_truth(3, 600.0, &[]);
        let m = match_rows(&sig, &truth).unwrap();
        let g = GpsErrorStatistics::of(&sig, &m).unwrap();
        assert!(g.fixes > 400, "{g:?}");
        assert!((1.0..3.0).contains(&g.error.median_m), "{g:?}");
        assert_eq!(g.over_15m, 0.0);
        let c1 = g.correlation[0].1.unwrap();
        let c30 = g.correlation[3].1.unwrap();
        assert!(c1 > 0.8 && c30 < c1, "{g:?}");
        assert!((0.7..=1.0).contains(&g.availability), "{g:?}");
    }
}
