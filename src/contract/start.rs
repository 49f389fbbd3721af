//! The start guess for step 1: heading, yaw bias, odometer gain, start
//! position and barometer offset, from the GPS course and chords.
//!
//! A poor start heading can trap the least-squares fit far from the answer,
//! and a raw phone-class gyro can carry several deg/s of bias (the heading of
//! the comma2k19 drive drifts 233 deg in a minute without it). So the heading
//! and the yaw bias come together from the GPS course: for consecutive fixes
//! with a chord of a few metres, `delta_k = course_k - psi_raw(t_k)` (raw
//! integrated heading) follows `delta(t) = psi_0 - b_z (t - t_0)`; a robust
//! line fit (median of local slopes, then least squares within 3 MAD) gives
//! both.

use nalgebra::{UnitQuaternion, Vector3};
use thiserror::Error;

use crate::rotation::wrap_pi;
use crate::signals::Signals;

/// Why no start could be found: the ride does not determine a heading.
#[derive(Debug, Error)]
pub enum StartError {
    #[error(
        "{file}: the GPS fixes never move more than {min_m} m between consecutive seconds, so the heading is unobservable (a ride without motion?)"
    )]
    NoMotion { file: String, min_m: f64 },
    #[error(
        "{file}: no two GPS fixes are within {max_gap_s} s of each other, so the heading cannot be taken from the GPS course (the fixes are too sparse)"
    )]
    SparseFixes { file: String, max_gap_s: f64 },
}

/// Starting point of the fit.
#[derive(Clone, Debug, PartialEq)]
pub struct StartGuess {
    /// Level attitude with the GPS heading.
    pub attitude: UnitQuaternion<f64>,
    pub position: Vector3<f64>,
    /// rad/s: the level-bias guess (see `level_bias`), its yaw part
    /// corrected by the drift of the raw heading against the GPS course.
    pub gyro_bias: Vector3<f64>,
    pub odometer_gain: f64,
    pub baro_offset: f64,
    /// Times (s, increasing) of the fixes that this guess's dead reckoning
    /// suspects of a reflection, which step 1's windows leave out (see
    /// [`crate::suspect_fixes`]).
    pub suspect_fixes: Vec<f64>,
}

/// Chords shorter than this give no course (m).
const MIN_CHORD_M: f64 = 2.0;
/// The heading and yaw-bias guess uses course samples from this much of the
/// start of the ride (s), or more until it has [`MIN_HEADING_SAMPLES`].
const HEADING_FIT_S: f64 = 180.0;
const MIN_HEADING_SAMPLES: usize = 60;
/// Consecutive fixes further apart than this are not used for a course (s).
const MAX_FIX_GAP_S: f64 = 2.5;
/// A course chord spans at least this much odometer distance (m), from one
/// fix to the first fix that far along, so that GPS noise of a metre or two
/// moves it by tens of degrees at most...
const CHORD_M: f64 = 5.0;
/// ...within this long (s).
const CHORD_MAX_S: f64 = 20.0;
/// The yaw-bias guesses judged by the track's shape: the course coherence's
/// highest peaks, at most this many...
const PEAKS: usize = 3;
/// ...each at least this share of the highest.
const PEAK_SHARE: f64 = 0.5;
/// The track's shape judges a guess over at most this much of it (m)...
const SHAPE_M: f64 = 300.0;
/// ...and overrules the highest course peak only where another's track
/// misses the fixes by under this share of its miss.
const SHAPE_RATIO: f64 = 0.5;

impl StartGuess {
    /// The guess on the signals' rates as they are.
    pub fn from_signals(sig: &Signals) -> Result<Self, StartError> {
        Self::turning_in_stops(sig, &[])
    }

    /// The guess with `stops` (rad/s per row, empty for none) added to the
    /// yaw rates: the turns the model starts from across the gyro's stops
    /// (see `effects::gyro_stops`), where the signals hold only the line
    /// between the readings either side. Without them a vehicle that turned
    /// inside a stop leaves the guess's raw heading and track kinked by that
    /// turn from then on: a helmet camera's looks to the side, bridged as
    /// stops while the car took a 60 deg bend, moved the course samples
    /// after it by 60 deg, and the coherence's peak to a yaw bias 3.2 deg/s
    /// off (a 5-minute car then failed 81 m from the truth; with the turns,
    /// 0.98 m, 0.80 m without the looks).
    pub fn turning_in_stops(sig: &Signals, stops: &[f64]) -> Result<Self, StartError> {
        let n = sig.len();
        let rate_bias = level_bias(sig);
        // Raw heading: integrate the rates (less the rate bias guess) from a level, east-facing start.
        let mut q = UnitQuaternion::identity();
        let mut psi = vec![0.0; n];
        let mut unwrapped = 0.0;
        let mut last = 0.0;
        for j in 1..n {
            q *= UnitQuaternion::from_scaled_axis((rate(sig, stops, j) - rate_bias) * sig.dt[j]);
            let f = q * Vector3::x();
            let h = f.y.atan2(f.x);
            unwrapped += wrap_pi(h - last);
            last = h;
            psi[j] = unwrapped;
        }
        let mut chord_sum = 0.0;
        let mut odo_sum = 0.0;
        let mut pairs = 0;
        // Odometer distance from the start at each fix.
        let mut odo_at = Vec::with_capacity(sig.fixes.len());
        let mut s_row = 0usize;
        let mut s_cum = 0.0;
        for f in &sig.fixes {
            s_cum += sig.distance[(s_row + 1).min(f.row + 1)..=f.row]
                .iter()
                .sum::<f64>();
            s_row = f.row;
            odo_at.push(s_cum);
        }
        let fixes = &sig.fixes;
        for k in 0..fixes.len().saturating_sub(1) {
            let (a, b) = (&fixes[k], &fixes[k + 1]);
            if b.t - a.t > MAX_FIX_GAP_S {
                continue;
            }
            pairs += 1;
            chord_sum += (b.en[0] - a.en[0]).hypot(b.en[1] - a.en[1]);
            odo_sum += odo_at[k + 1] - odo_at[k];
        }
        if pairs == 0 {
            return Err(StartError::SparseFixes {
                file: sig.source.clone(),
                max_gap_s: MAX_FIX_GAP_S,
            });
        }
        let samples = course_samples(sig, &odo_at, &psi);
        if samples.len() < 2 {
            return Err(StartError::NoMotion {
                file: sig.source.clone(),
                min_m: MIN_CHORD_M,
            });
        }
        let odometer_gain = if odo_sum > 10.0 && (0.5..2.0).contains(&(chord_sum / odo_sum)) {
            chord_sum / odo_sum
        } else {
            1.0
        };
        // Where the courses are noisy their coherence has several peaks of
        // like height; the track's own shape decides among them (see
        // `shape_misfit`) where it tells them apart: a lower peak is taken
        // only where the track laid with it misses the fixes by under
        // SHAPE_RATIO of what the highest peak's does. A car under city GPS
        // misses by 20-50 m with any of them (its 300 m of track are no
        // shape against that), and the highest peak stands.
        let lines: Vec<(f64, f64, f64)> = lined_up(&samples)
            .into_iter()
            .map(|slope0| heading_line(&samples, slope0))
            .map(|(heading, slope)| {
                let bias = rate_bias + Vector3::new(0.0, 0.0, -slope);
                let misfit = shape_misfit(sig, stops, &odo_at, heading, bias, odometer_gain);
                (heading, slope, misfit)
            })
            .collect();
        let highest = lines.first().map_or(f64::INFINITY, |l| l.2);
        let (heading, slope, _) = lines
            .iter()
            .copied()
            .filter(|l| l.2 < SHAPE_RATIO * highest)
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .or(lines.first().copied())
            .unwrap_or((0.0, 0.0, 0.0));
        let attitude = UnitQuaternion::from_scaled_axis(Vector3::z() * heading);
        let gyro_bias = rate_bias + Vector3::new(0.0, 0.0, -slope);

        Ok(Self::finish_guess(
            sig,
            stops,
            &odo_at,
            attitude,
            gyro_bias,
            odometer_gain,
        ))
    }

    /// The guess with this attitude, bias and gain: the start placed so
    /// that its dead reckoning meets the first 30 s of fixes on average, and
    /// the fixes that the dead reckoning suspects of a reflection.
    fn finish_guess(
        sig: &Signals,
        stops: &[f64],
        odo_at: &[f64],
        attitude: UnitQuaternion<f64>,
        gyro_bias: Vector3<f64>,
        odometer_gain: f64,
    ) -> Self {
        let n = sig.len();
        let fixes = &sig.fixes;
        // Dead-reckon with these guesses and place the start so the first fixes line up.
        let mut q = attitude;
        let mut p = Vector3::zeros();
        let mut dr = vec![Vector3::zeros(); n];
        for j in 1..n {
            q *= UnitQuaternion::from_scaled_axis((rate(sig, stops, j) - gyro_bias) * sig.dt[j]);
            p += q * Vector3::x() * (odometer_gain * sig.distance[j]);
            dr[j] = p;
        }
        let first: Vec<_> = sig
            .fixes
            .iter()
            .take_while(|f| f.t - sig.fixes[0].t <= 30.0)
            .collect();
        let m = first.len() as f64;
        let mut position = Vector3::zeros();
        for f in &first {
            position.x += (f.en[0] - dr[f.row].x) / m;
            position.y += (f.en[1] - dr[f.row].y) / m;
        }
        let ups: Vec<f64> = first
            .iter()
            .filter_map(|f| f.up.map(|u| u - dr[f.row].z))
            .collect();
        if !ups.is_empty() {
            position.z = ups.iter().sum::<f64>() / ups.len() as f64;
        }
        let baros: Vec<f64> = first
            .iter()
            .filter_map(|f| f.baro.map(|b| position.z + dr[f.row].z - b))
            .collect();
        let baro_offset = if baros.is_empty() {
            0.0
        } else {
            baros.iter().sum::<f64>() / baros.len() as f64
        };
        let track: Vec<[f64; 2]> = fixes.iter().map(|f| [dr[f.row].x, dr[f.row].y]).collect();
        let en: Vec<[f64; 2]> = fixes.iter().map(|f| f.en).collect();
        let t_fix: Vec<f64> = fixes.iter().map(|f| f.t).collect();
        let along: Vec<f64> = odo_at.iter().map(|s| odometer_gain * s).collect();
        let suspect_fixes = crate::suspect_fixes::find(&t_fix, &along, &track, &en)
            .iter()
            .zip(&t_fix)
            .filter_map(|(&s, &t)| s.then_some(t))
            .collect();
        Self {
            attitude,
            position,
            gyro_bias,
            odometer_gain,
            baro_offset,
            suspect_fixes,
        }
    }
}

/// Course samples `(t - t_0, course - raw heading, weight)` of chords
/// spanning [`CHORD_M`] of odometer distance (from each fix to the first
/// fix that far along, within [`CHORD_MAX_S`] and no fix gap over
/// [`MAX_FIX_GAP_S`]; chords under [`MIN_CHORD_M`] give none). A fast
/// vehicle's chord is between consecutive fixes, a slow one's over as many
/// as it takes: two fixes half a second apart, 0.35 m along for a robot,
/// are 2 m apart by their jitter alone, and their course is the jitter's.
/// Weighted as
/// [`course_weighted`] says, over the first [`HEADING_FIT_S`] of the ride
/// (or until [`MIN_HEADING_SAMPLES`]).
///
/// Only the start of the ride: over many minutes an error of a few
/// hundredths of a deg/s in the level-bias guess tilts the raw attitude by
/// tens of degrees and corrupts the raw heading, and the bias itself
/// drifts. Step 1 starts on the first minutes, which is what needs the guess.
fn course_samples(sig: &Signals, odo_at: &[f64], psi: &[f64]) -> Vec<(f64, f64, f64)> {
    let fixes = &sig.fixes;
    let t0 = sig.t[0];
    let mut samples: Vec<(f64, f64, f64, f64)> = Vec::new();
    for k in 0..fixes.len().saturating_sub(1) {
        let a = &fixes[k];
        if fixes[k + 1].t - a.t > MAX_FIX_GAP_S || (odo_at[k + 1] - odo_at[k]).abs() <= 0.1 {
            continue;
        }
        let end = (k + 1..fixes.len())
            .take_while(|&m| {
                fixes[m].t - fixes[m - 1].t <= MAX_FIX_GAP_S && fixes[m].t - a.t <= CHORD_MAX_S
            })
            .find(|&m| (odo_at[m] - odo_at[k]).abs() >= CHORD_M);
        let Some(m) = end else { continue };
        let b = &fixes[m];
        let (de, dn) = (b.en[0] - a.en[0], b.en[1] - a.en[1]);
        let chord = de.hypot(dn);
        if chord < MIN_CHORD_M {
            continue;
        }
        // Driving backwards, the course is the heading turned round.
        let reverse = if odo_at[m] < odo_at[k] {
            std::f64::consts::PI
        } else {
            0.0
        };
        let mid = (a.row + b.row) / 2;
        samples.push((
            sig.t[mid] - t0,
            dn.atan2(de) + reverse - psi[mid],
            chord,
            (odo_at[m] - odo_at[k]).abs(),
        ));
        if samples.len() >= MIN_HEADING_SAMPLES && sig.t[mid] - t0 >= HEADING_FIT_S {
            break;
        }
    }
    course_weighted(&samples)
}

/// The slopes (the yaw-bias error of the guess) that line the samples up
/// best on the circle, `max_s |sum_k w_k exp(i (d_k - s t_k))|`, searched
/// over +-10 deg/s in steps that turn the last sample by at most 0.05 rad:
/// the highest peak and the [`PEAKS`] - 1 next local peaks within
/// [`PEAK_SHARE`] of it. Robust to wrap-around and to outliers, unlike a
/// median of neighbouring differences, whose noise (tenths of a radian per
/// second) can wrap the detrended samples over a few minutes.
fn lined_up(samples: &[(f64, f64, f64)]) -> Vec<f64> {
    let span = samples.last().map_or(1.0, |s| s.0).max(1.0);
    let step = 0.05 / span;
    let limit = 10f64.to_radians();
    let coherence = |slope: f64| {
        let (s, c) = samples.iter().fold((0.0, 0.0), |(s, c), &(t, d, w)| {
            let x = d - slope * t;
            (s + w * x.sin(), c + w * x.cos())
        });
        s.hypot(c)
    };
    let n_steps = (limit / step).ceil() as i64;
    let curve: Vec<(f64, f64)> = (-n_steps..=n_steps)
        .map(|k| k as f64 * step)
        .map(|slope| (slope, coherence(slope)))
        .collect();
    let mut peaks: Vec<(f64, f64)> = (0..curve.len())
        .filter(|&i| {
            (i == 0 || curve[i - 1].1 < curve[i].1)
                && (i + 1 == curve.len() || curve[i + 1].1 <= curve[i].1)
        })
        .map(|i| curve[i])
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    let top = peaks.first().map_or(0.0, |p| p.1);
    peaks
        .into_iter()
        .take(PEAKS)
        .filter(|p| p.1 >= PEAK_SHARE * top)
        .map(|p| p.0)
        .collect()
}

/// The heading at the start and the slope of `delta(t) = psi_0 - b_z t`
/// through the samples from `slope0`: the offset is the circular mean of
/// the detrended samples, then both are refined by weighted least squares
/// on the unwrapped residuals within 3 MAD.
fn heading_line(samples: &[(f64, f64, f64)], slope0: f64) -> (f64, f64) {
    let (s, c) = samples.iter().fold((0.0, 0.0), |(s, c), &(t, d, w)| {
        let x = d - slope0 * t;
        (s + w * x.sin(), c + w * x.cos())
    });
    let offset0 = s.atan2(c);
    let resid: Vec<f64> = samples
        .iter()
        .map(|&(t, d, _)| wrap_pi(d - offset0 - slope0 * t))
        .collect();
    let mut abs: Vec<f64> = resid.iter().map(|r| r.abs()).collect();
    let mad = crate::statistics::median(&mut abs).max(0.01);
    let (mut sw, mut st, mut sr, mut stt, mut str_) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (&(t, _, w), &r) in samples.iter().zip(&resid) {
        if r.abs() <= 3.0 * mad / 0.6745 {
            sw += w;
            st += w * t;
            sr += w * r;
            stt += w * t * t;
            str_ += w * t * r;
        }
    }
    let det = sw * stt - st * st;
    let (da, db) = if sw > 0.0 && det.abs() > 1e-9 * sw * sw.max(1.0) {
        ((stt * sr - st * str_) / det, (sw * str_ - st * sr) / det)
    } else if sw > 0.0 {
        (sr / sw, 0.0)
    } else {
        (0.0, 0.0)
    };
    (offset0 + da, slope0 + db)
}

/// How far the fixes of the ride's first [`HEADING_FIT_S`] and [`SHAPE_M`] lie from the
/// track dead-reckoned with this heading, bias and gain once it is laid on
/// them by a robust rigid fit: the median distance (m; infinite under three
/// fixes) over the fixes that the odometer (`odo_at`, at each fix) moved to. A wrong bias curls the track, and no rotation lays a curl on a
/// street.
fn shape_misfit(
    sig: &Signals,
    stops: &[f64],
    odo_at: &[f64],
    heading: f64,
    gyro_bias: Vector3<f64>,
    gain: f64,
) -> f64 {
    let t_end = sig.t[0] + HEADING_FIT_S;
    let fixes: Vec<_> = sig.fixes.iter().take_while(|f| f.t <= t_end).collect();
    let mut q = UnitQuaternion::from_scaled_axis(Vector3::z() * heading);
    let mut p = Vector3::zeros();
    let mut track = Vec::with_capacity(fixes.len());
    let mut next = fixes.iter().map(|f| f.row).peekable();
    for j in 0..sig.len() {
        if next.peek().is_none() {
            break;
        }
        if j > 0 {
            q *= UnitQuaternion::from_scaled_axis((rate(sig, stops, j) - gyro_bias) * sig.dt[j]);
            p += q * Vector3::x() * (gain * sig.distance[j]);
        }
        while next.next_if_eq(&j).is_some() {
            track.push([p.x, p.y]);
        }
    }
    // Only where the vehicle moves: a curl stands still as well as a
    // straight track does, and a car waiting at lights half the time would
    // have the median at its stops.
    // And over SHAPE_M of track at most: over a car's three minutes a bias
    // right to a tenth of a deg/s still bends the track by hundreds of metres.
    let moving: Vec<usize> = (1..fixes.len())
        .filter(|&k| odo_at[k] - odo_at[k - 1] > 0.1 && odo_at[k] - odo_at[0] <= SHAPE_M)
        .collect();
    let en: Vec<[f64; 2]> = moving.iter().map(|&k| fixes[k].en).collect();
    let track: Vec<[f64; 2]> = moving.iter().map(|&k| track[k]).collect();
    crate::suspect_fixes::laid_misfit(&track, &en).unwrap_or(f64::INFINITY)
}

/// Row `j`'s rates with the turns across the stops (see
/// [`StartGuess::turning_in_stops`]).
fn rate(sig: &Signals, stops: &[f64], j: usize) -> Vector3<f64> {
    sig.gyro[j] + Vector3::z() * stops.get(j).copied().unwrap_or(0.0)
}

/// The course samples `(t, delta, chord, odometer)` as `(t, delta, w)`,
/// weighted by how far the vehicle really went along the chord:
/// `w_k = min(chord_k, odo_k)`.
///
/// A chord's course is as good as the GPS error is small against its length,
/// so a longer chord weighs more; but a chord longer than the odometer says
/// is partly GPS error, and one much longer is a jump, whose course is the
/// jump's. In a city the jumps are the longest chords: weighted by the
/// chord, a robot crawling at 0.7 m/s under 50 m reflections had its
/// yaw-bias guess at 3.41 deg/s (the gyro's is 0.85) and step 1 stayed in
/// that basin, a spiral 46 m from the truth. The odometer's own scale does
/// not matter: read in wrong units, all weights scale together. A ride
/// whose odometer never moves along a chord keeps the chord as the weight.
fn course_weighted(samples: &[(f64, f64, f64, f64)]) -> Vec<(f64, f64, f64)> {
    let moved = samples.iter().any(|s| s.3 > 0.1);
    samples
        .iter()
        .map(|&(t, d, chord, odo)| (t, d, if moved { chord.min(odo) } else { chord }))
        .collect()
}

/// Rate-bias guess before any GPS: the mean rate while standing still (odometer
/// silent for 2 s) when the ride has at least 2 s of that, else the mean roll
/// and pitch rates while not turning (a vehicle does not keep rolling or
/// pitching; turns are left out because leaning couples yaw into pitch).
fn level_bias(sig: &Signals) -> Vector3<f64> {
    let n = sig.len();
    let mut prefix = vec![0.0; n + 1];
    for j in 0..n {
        prefix[j + 1] = prefix[j] + sig.distance[j];
    }
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut still = Vector3::zeros();
    let mut still_t = 0.0;
    for j in 1..n {
        while sig.t[j] - sig.t[lo] > 1.0 {
            lo += 1;
        }
        while hi + 1 < n && sig.t[hi + 1] - sig.t[j] <= 1.0 {
            hi += 1;
        }
        if sig.t[hi] - sig.t[lo] >= 1.9 && prefix[hi + 1] - prefix[lo] == 0.0 {
            still += sig.gyro[j] * sig.dt[j];
            still_t += sig.dt[j];
        }
    }
    if still_t >= 2.0 {
        return still / still_t;
    }
    let mut gz: Vec<f64> = sig.gyro.iter().map(|g| g.z).collect();
    let centre = crate::statistics::median(&mut gz);
    let turn_limit = 3f64.to_radians();
    let (mut sum, mut time) = (Vector3::zeros(), 0.0);
    for j in 1..n {
        if (sig.gyro[j].z - centre).abs() < turn_limit {
            sum += sig.gyro[j] * sig.dt[j];
            time += sig.dt[j];
        }
    }
    if time > 0.0 {
        Vector3::new(sum.x / time, sum.y / time, 0.0)
    } else {
        Vector3::zeros()
    }
}
