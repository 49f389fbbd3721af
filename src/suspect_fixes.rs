//! Fixes suspected of a reflection, which step 1 leaves out: runs of fixes far off the
//! vehicle's own track shape, found before any fit.
//!
//! Step 1 fits its windows by least squares (see `Model::least_squares`:
//! a robust loss is no start from a guess far off). Least squares has one
//! basin, but it is the fixes' basin: a city reflection holding a slow
//! vehicle's fixes 50 m off for half a minute moves the window's optimum
//! wherever it fits that run best. A simulated robot at 0.7 m/s in urban
//! GPS (seed 6: 37 s of fixes 50 m off, then an outage) had its first
//! window's yaw bias pulled from the start guess's 0.86 deg/s (the gyro's
//! is 0.85) to 3.2 deg/s, a spiral through the reflection, and step 2 and
//! the noise search stayed in that basin: 46 m from the truth, reported as
//! a success under a "GPS wander of 20 m". With those fixes left out of
//! step 1 alone, the same defaults end 2.2 m from the truth: step 2, the
//! noise model and the robust loss see every fix again, from the right
//! basin.
//!
//! The dead-reckoned track of the start guess (its heading, yaw bias and
//! odometer gain, see [`crate::contract::StartGuess`]) has the vehicle's
//! shape over a minute or two, whatever its drift over the ride. So each
//! stretch of [`BLOCK_S`] is judged within the fixes of [`WINDOW_S`] and
//! [`WINDOW_M`] either side: the track is laid on them by the rigid motion
//! (rotation `R`, shift `T`) that a robust fit finds,
//! `min sum_j rho(|y_j - (R p_j + T)|)` (Tukey's biweight by iteratively
//! reweighted Procrustes, from the median shift: it holds while the
//! reflected fixes are under half of the window), and a fix whose residual
//! is over [`RESIDUALS`] times the ride's median residual and over
//! [`MIN_OFF_M`] is a suspect. Errors under [`MIN_OFF_M`] are the noise
//! model's to weigh, not a basin's risk.
//!
//! Where the guess is wrong the track has no shape to lay (a robot under
//! city GPS, whose chords give a bias guess tens of times off): its
//! residuals are all large, the median with them, and few fixes stand out;
//! where over [`MAX_SHARE`] of them would, none is left out.

/// The stretch of fixes judged by one rigid fit (s).
pub const BLOCK_S: f64 = 5.0;
/// The fixes the fit lays the track on: this long either side of the
/// stretch (s)...
pub const WINDOW_S: f64 = 120.0;
/// ...and this far along the track (m): a car's minute is a kilometre,
/// over which a start guess's bias error of a few hundredths of a deg/s
/// bends the track by metres.
pub const WINDOW_M: f64 = 300.0;
/// A suspect is this many times the ride's median residual off...
pub const RESIDUALS: f64 = 3.0;
/// ...and at least this far (m).
pub const MIN_OFF_M: f64 = 10.0;
/// Over this share of the fixes suspect, the track is not trusted and
/// none is.
pub const MAX_SHARE: f64 = 0.25;
/// A rigid fit takes at most this many of its window's fixes, evenly:
/// a 10 Hz receiver's four minutes are 2,400.
const MAX_WINDOW_FIXES: usize = 600;
/// Tukey's biweight constant (95 % efficiency under Gaussian errors).
const TUKEY_C: f64 = 4.685;
/// Reweighting rounds of a rigid fit.
const ROUNDS: usize = 5;

/// The suspect fixes, one flag per fix: `t` the fixes' times (s,
/// increasing), `along` the track's distance at each (m, the odometer's),
/// `track` the dead-reckoned position at each and `fixes` the fixes
/// (east, north; m).
pub fn find(t: &[f64], along: &[f64], track: &[[f64; 2]], fixes: &[[f64; 2]]) -> Vec<bool> {
    let n = t.len().min(along.len()).min(track.len()).min(fixes.len());
    let mut residual = vec![f64::NAN; n];
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut start = 0usize;
    while start < n {
        let end = (start..n)
            .find(|&k| t[k] - t[start] >= BLOCK_S)
            .unwrap_or(n);
        while lo < start && t[start] - t[lo] > WINDOW_S {
            lo += 1;
        }
        while hi < n && t[hi] - t[end - 1] <= WINDOW_S {
            hi += 1;
        }
        let within: Vec<usize> = (lo..hi)
            .filter(|&j| {
                along[j] >= along[start].min(along[end - 1]) - WINDOW_M
                    && along[j] <= along[start].max(along[end - 1]) + WINDOW_M
            })
            .collect();
        // Every k-th where a fast receiver gives more than enough.
        let stride = within.len().div_ceil(MAX_WINDOW_FIXES).max(1);
        let window: Vec<usize> = within.into_iter().step_by(stride).collect();
        if let Some((r, shift)) = rigid_fit(&window, track, fixes) {
            for k in start..end {
                let p = rotate(r, track[k]);
                residual[k] = (fixes[k][0] - p[0] - shift[0]).hypot(fixes[k][1] - p[1] - shift[1]);
            }
        }
        start = end;
    }
    let median = crate::statistics::median_of_finite(&residual);
    if !median.is_finite() {
        return vec![false; n];
    }
    let limit = (RESIDUALS * median).max(MIN_OFF_M);
    let flags: Vec<bool> = residual.iter().map(|&r| r > limit).collect();
    let share = flags.iter().filter(|&&f| f).count() as f64 / n.max(1) as f64;
    if share > MAX_SHARE {
        return vec![false; n];
    }
    flags
}

/// The median distance (m) of `fixes` from `track` laid on them by the
/// robust rigid fit; `None` under three fixes.
pub(crate) fn laid_misfit(track: &[[f64; 2]], fixes: &[[f64; 2]]) -> Option<f64> {
    let all: Vec<usize> = (0..track.len().min(fixes.len())).collect();
    let (angle, shift) = rigid_fit(&all, track, fixes)?;
    let mut distances: Vec<f64> = all
        .iter()
        .map(|&j| {
            let p = rotate(angle, track[j]);
            (fixes[j][0] - p[0] - shift[0]).hypot(fixes[j][1] - p[1] - shift[1])
        })
        .collect();
    Some(crate::statistics::median(&mut distances))
}

fn rotate(angle: f64, p: [f64; 2]) -> [f64; 2] {
    let (s, c) = angle.sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1]]
}

/// The rigid motion `(angle, shift)` laying `track` on `fixes` over the
/// `window`'s fixes, robustly: rounds of weighted Procrustes under Tukey's
/// biweight on the residuals' robust scale, from two starts.
/// `None` under three fixes.
fn rigid_fit(window: &[usize], track: &[[f64; 2]], fixes: &[[f64; 2]]) -> Option<(f64, [f64; 2])> {
    if window.len() < 3 {
        return None;
    }
    // From no rotation (the track's heading is the start guess's, near the
    // fixes' already) and from plain Procrustes's (a track turned against
    // the fixes), each with the median shift under it: the fit that ends
    // nearer the fixes in the median. Either alone misses: plain Procrustes
    // leans to a reflection that holds 40 % of a window, and no rotation
    // is far from a turned track.
    let (plain, _) = procrustes(window, track, fixes, &vec![1.0; window.len()])?;
    [0.0, plain]
        .into_iter()
        .map(|angle| reweighted(window, track, fixes, angle))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(fit, _)| fit)
}

/// Rounds of weighted Procrustes under Tukey's biweight from `angle` and
/// the median shift under it; the fit and the median residual at its end.
fn reweighted(
    window: &[usize],
    track: &[[f64; 2]],
    fixes: &[[f64; 2]],
    mut angle: f64,
) -> ((f64, [f64; 2]), f64) {
    let median_of = |axis: usize| {
        let mut d: Vec<f64> = window
            .iter()
            .map(|&j| fixes[j][axis] - rotate(angle, track[j])[axis])
            .collect();
        crate::statistics::median(&mut d)
    };
    let mut shift = [median_of(0), median_of(1)];
    let residuals = |angle: f64, shift: [f64; 2]| -> Vec<f64> {
        window
            .iter()
            .map(|&j| {
                let p = rotate(angle, track[j]);
                (fixes[j][0] - p[0] - shift[0]).hypot(fixes[j][1] - p[1] - shift[1])
            })
            .collect()
    };
    for _ in 0..ROUNDS {
        let res = residuals(angle, shift);
        let mut abs = res.clone();
        let scale = (1.4826 * crate::statistics::median(&mut abs)).max(0.1);
        let w: Vec<f64> = res
            .iter()
            .map(|r| {
                let u = r / (TUKEY_C * scale);
                if u < 1.0 { (1.0 - u * u).powi(2) } else { 0.0 }
            })
            .collect();
        let Some(fit) = procrustes(window, track, fixes, &w) else {
            break;
        };
        (angle, shift) = fit;
    }
    let mut res = residuals(angle, shift);
    ((angle, shift), crate::statistics::median(&mut res))
}

/// Weighted Procrustes in the plane: the rotation and shift minimising
/// `sum_j w_j |y_j - (R p_j + T)|^2` over the `window`; `None` without weight.
fn procrustes(
    window: &[usize],
    track: &[[f64; 2]],
    fixes: &[[f64; 2]],
    w: &[f64],
) -> Option<(f64, [f64; 2])> {
    let sw: f64 = w.iter().sum();
    if sw <= 0.0 {
        return None;
    }
    let centre = |pts: &[[f64; 2]]| {
        let (mut x, mut y) = (0.0, 0.0);
        for (&j, &wj) in window.iter().zip(w) {
            x += wj * pts[j][0];
            y += wj * pts[j][1];
        }
        [x / sw, y / sw]
    };
    let (pc, yc) = (centre(track), centre(fixes));
    let (mut dot, mut cross) = (0.0, 0.0);
    for (&j, &wj) in window.iter().zip(w) {
        let a = [track[j][0] - pc[0], track[j][1] - pc[1]];
        let b = [fixes[j][0] - yc[0], fixes[j][1] - yc[1]];
        dot += wj * (a[0] * b[0] + a[1] * b[1]);
        cross += wj * (a[0] * b[1] - a[1] * b[0]);
    }
    let angle = if dot == 0.0 && cross == 0.0 {
        0.0
    } else {
        cross.atan2(dot)
    };
    let rc = rotate(angle, pc);
    Some((angle, [yc[0] - rc[0], yc[1] - rc[1]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle at `v` m/s for `secs` s, fixes every `dt` s along an L
    /// (straight, then a right-angle turn halfway), with a deterministic
    /// jitter of `jitter` m; the track is the truth turned by `turn` rad
    /// and shifted.
    fn ride(v: f64, secs: f64, dt: f64, jitter: f64, turn: f64) -> Ride {
        let n = (secs / dt) as usize;
        let mut r = Ride::default();
        for k in 0..n {
            let t = k as f64 * dt;
            let s = v * t;
            let half = v * secs / 2.0;
            let truth = if s < half { [s, 0.0] } else { [half, s - half] };
            let wobble = [
                jitter * (1.7 * k as f64).sin(),
                jitter * (2.3 * k as f64).cos(),
            ];
            r.t.push(t);
            r.along.push(s);
            let p = rotate(turn, truth);
            r.track.push([p[0] + 40.0, p[1] - 25.0]);
            r.fixes.push([truth[0] + wobble[0], truth[1] + wobble[1]]);
        }
        r
    }

    #[derive(Default)]
    struct Ride {
        t: Vec<f64>,
        along: Vec<f64>,
        track: Vec<[f64; 2]>,
        fixes: Vec<[f64; 2]>,
    }

    impl Ride {
        fn suspects(&self) -> Vec<bool> {
            find(&self.t, &self.along, &self.track, &self.fixes)
        }
    }

    #[test]
    fn a_ride_without_reflections_has_no_suspect() {
        let r = ride(0.7, 300.0, 0.5, 3.0, 0.4);
        assert!(r.suspects().iter().all(|&s| !s));
    }

    #[test]
    fn a_half_minute_reflection_is_suspect_and_nothing_else() {
        let mut r = ride(0.7, 300.0, 0.5, 3.0, -1.2);
        let run = 106..180;
        for k in run.clone() {
            r.fixes[k][0] -= 35.0;
            r.fixes[k][1] += 38.0;
        }
        let flags = r.suspects();
        for (k, &f) in flags.iter().enumerate() {
            assert_eq!(f, run.contains(&k), "fix {k}");
        }
    }

    #[test]
    fn a_car_in_a_city_has_its_reflections_found_within_its_window() {
        let mut r = ride(12.0, 600.0, 1.0, 4.0, 2.0);
        let runs = [40..46, 200..203, 420..428];
        for run in runs.clone() {
            for k in run {
                r.fixes[k][1] += 45.0;
            }
        }
        let flags = r.suspects();
        for (k, &f) in flags.iter().enumerate() {
            assert_eq!(f, runs.iter().any(|run| run.contains(&k)), "fix {k}");
        }
    }

    #[test]
    fn a_track_without_the_rides_shape_leaves_every_fix_in() {
        let mut r = ride(0.7, 300.0, 0.5, 3.0, 0.0);
        // A bias guess 10 deg/s off: the track is a tight spiral.
        let mut psi: f64 = 0.0;
        let mut p = [0.0, 0.0];
        for k in 0..r.t.len() {
            psi += 10f64.to_radians() * 0.5;
            p = [p[0] + 0.35 * psi.cos(), p[1] + 0.35 * psi.sin()];
            r.track[k] = p;
        }
        for k in 100..120 {
            r.fixes[k][0] += 60.0;
        }
        let share = r.suspects().iter().filter(|&&s| s).count();
        assert!(share <= 20, "{share} of {} fixes left out", r.t.len());
    }

    #[test]
    fn too_few_fixes_judge_nothing() {
        assert!(find(&[], &[], &[], &[]).is_empty());
        let flags = find(
            &[0.0, 1.0],
            &[0.0, 1.0],
            &[[0.0, 0.0]; 2],
            &[[0.0, 0.0], [50.0, 0.0]],
        );
        assert_eq!(flags, vec![false, false]);
    }
}
