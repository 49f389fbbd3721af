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
}

/// Chords shorter than this give no course (m).
const MIN_CHORD_M: f64 = 2.0;
/// The heading and yaw-bias guess uses course samples from this much of the
/// start of the ride (s), or more until it has [`MIN_HEADING_SAMPLES`].
const HEADING_FIT_S: f64 = 180.0;
const MIN_HEADING_SAMPLES: usize = 60;
/// Consecutive fixes further apart than this are not used for a course (s).
const MAX_FIX_GAP_S: f64 = 2.5;
/// A slow vehicle's course chord spans at least this much odometer distance
/// (m), so that GPS noise of a metre or two moves it by tens of degrees at most...
const SLOW_CHORD_M: f64 = 5.0;
/// ...within this long (s).
const SLOW_CHORD_MAX_S: f64 = 20.0;

impl StartGuess {
    pub fn from_signals(sig: &Signals) -> Result<Self, StartError> {
        let n = sig.len();
        let rate_bias = level_bias(sig);
        // Raw heading: integrate the rates (less the rate bias guess) from a level, east-facing start.
        let mut q = UnitQuaternion::identity();
        let mut psi = vec![0.0; n];
        let mut unwrapped = 0.0;
        let mut last = 0.0;
        for j in 1..n {
            q *= UnitQuaternion::from_scaled_axis((sig.gyro[j] - rate_bias) * sig.dt[j]);
            let f = q * Vector3::x();
            let h = f.y.atan2(f.x);
            unwrapped += wrap_pi(h - last);
            last = h;
            psi[j] = unwrapped;
        }
        let t0 = sig.t[0];
        // Course samples: (time since start, course - raw heading, chord length).
        let mut samples: Vec<(f64, f64, f64)> = Vec::new();
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
            let chord = (b.en[0] - a.en[0]).hypot(b.en[1] - a.en[1]);
            let odo = odo_at[k + 1] - odo_at[k];
            chord_sum += chord;
            odo_sum += odo;
            // A slow vehicle (under MIN_CHORD_M between fixes, but moving)
            // takes its chord over as many fixes as SLOW_CHORD_M needs.
            let end = if chord >= MIN_CHORD_M {
                Some(k + 1)
            } else if odo.abs() > 0.1 {
                (k + 1..fixes.len())
                    .take_while(|&m| {
                        fixes[m].t - fixes[m - 1].t <= MAX_FIX_GAP_S
                            && fixes[m].t - a.t <= SLOW_CHORD_MAX_S
                    })
                    .find(|&m| (odo_at[m] - odo_at[k]).abs() >= SLOW_CHORD_M)
            } else {
                None
            };
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
            samples.push((sig.t[mid] - t0, dn.atan2(de) + reverse - psi[mid], chord));
        }
        // Only the start of the ride: over many minutes an error of a few
        // hundredths of a deg/s in the level-bias guess tilts the raw attitude
        // by tens of degrees and corrupts the raw heading, and the bias itself
        // drifts. Step 1 starts on the first minutes, which is what needs the guess.
        let enough = samples
            .iter()
            .position(|s| s.0 >= HEADING_FIT_S)
            .unwrap_or(samples.len())
            .max(MIN_HEADING_SAMPLES.min(samples.len()));
        samples.truncate(enough);
        if pairs == 0 {
            return Err(StartError::SparseFixes {
                file: sig.source.clone(),
                max_gap_s: MAX_FIX_GAP_S,
            });
        }
        if samples.len() < 2 {
            return Err(StartError::NoMotion {
                file: sig.source.clone(),
                min_m: MIN_CHORD_M,
            });
        }
        // Slope (the yaw-bias error of the guess): the rate that lines the
        // samples up best on the circle, `max_s |sum_k w_k exp(i (d_k - s t_k))|`,
        // searched over +-10 deg/s in steps that turn the last sample by at most
        // 0.05 rad. Robust to wrap-around and to outliers, unlike a median of
        // neighbouring differences, whose noise (tenths of a radian per second)
        // can wrap the detrended samples over a few minutes.
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
        let slope0 = (-n_steps..=n_steps)
            .map(|k| k as f64 * step)
            .map(|slope| (slope, coherence(slope)))
            .fold((0.0, f64::NEG_INFINITY), |best, x| {
                if x.1 > best.1 { x } else { best }
            })
            .0;
        // Offset: circular mean of the detrended samples.
        let (s, c) = samples.iter().fold((0.0, 0.0), |(s, c), &(t, d, w)| {
            let x = d - slope0 * t;
            (s + w * x.sin(), c + w * x.cos())
        });
        let offset0 = s.atan2(c);
        // Refine by weighted least squares on the unwrapped residuals within 3 MAD.
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
        let heading = offset0 + da;
        let slope = slope0 + db;
        let attitude = UnitQuaternion::from_scaled_axis(Vector3::z() * heading);
        let gyro_bias = rate_bias + Vector3::new(0.0, 0.0, -slope);
        let odometer_gain = if odo_sum > 10.0 && (0.5..2.0).contains(&(chord_sum / odo_sum)) {
            chord_sum / odo_sum
        } else {
            1.0
        };

        // Dead-reckon with these guesses and place the start so the first fixes line up.
        let mut q = attitude;
        let mut p = Vector3::zeros();
        let mut dr = vec![Vector3::zeros(); n];
        for j in 1..n {
            q *= UnitQuaternion::from_scaled_axis((sig.gyro[j] - gyro_bias) * sig.dt[j]);
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
        Ok(Self {
            attitude,
            position,
            gyro_bias,
            odometer_gain,
            baro_offset,
        })
    }
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
