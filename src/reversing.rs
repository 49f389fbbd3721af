//! Reversing on an odometer that has no sign: which stretches between
//! stops the vehicle drove backwards, told by the GPS track against the
//! gyro's heading.
//!
//! A GNSS receiver's ground speed has no sign, nor have wheel pulses, and
//! most cars' CAN speed has none either; yet nearly every car drive starts
//! by reversing out of a parking bay, and a three-point turn or a drive
//! backed into goes backwards too. Read forwards, the model moves ahead
//! where the car went back, `p_j = p_{j-1} + (q_j f) d_j` with `d_j > 0`:
//! on simulated car drives logged with the GNSS speed (`simulate --vehicle
//! car --gnss-speed --no-outages`, 6-9 m reversed out of the bay), the noise
//! search read the misfit as a GPS wander of 3.6-7.6 m (the fixes' is about
//! 1.5 m), and the whole 5-minute path ended 1.8-3.9 m from the truth
//! instead of 0.8-1.9 m, as a success.
//!
//! A vehicle changes direction only through a stop, so the log's moving
//! steps (faster than [`STOP_SPEED_MPS`]) fall into stretches between stops,
//! each driven one way. The gyro's heading `psi_j = sum (w_z - b) dt` (the
//! bias `b` from the stops, where the vehicle does not turn) runs on through
//! the stops, as the vehicle's does; the dead-reckoned track
//! `P_j = P_{j-1} + d_j (cos psi_j, sin psi_j)` is the true track's shape
//! with an unknown rotation, and where the vehicle reversed, the track
//! turned by half a turn. So each stretch's fixes (and those of its stops
//! next to it, where it stood) are matched to its track by a rotation
//! (Procrustes: `phi = atan2(sum r x g, sum r . g)` over the centred
//! points), and a stretch whose rotation is half a turn from its
//! neighbours' is reversed. Stretches longer than [`MAX_REVERSE_M`] are
//! driven forwards (they anchor the rest); a short one is decided from a
//! neighbour already decided, only where its shape matches its fixes
//! (misfit under [`MAX_MISFIT_SHARE`] of its spread) and every decided
//! neighbour agrees; where nothing decides, forwards, as before. A city's
//! reflections (tens of metres) leave short stretches unmatched, so
//! undecided.

use std::ops::Range;

/// Steps slower than this (m/s) are stops, where a vehicle may change
/// direction: a walking pace's tenth, above a GNSS speed's noise at a
/// standstill (a few cm/s).
pub const STOP_SPEED_MPS: f64 = 0.2;

/// A stretch between stops longer than this (m) is driven forwards: cars
/// reverse out of a bay or into a drive, some metres to a few tens.
pub const MAX_REVERSE_M: f64 = 50.0;

/// Of a long stretch, the part next to a stop (s) whose fixes give its
/// heading there: short enough that a bias left in the gyro (after the
/// stops' own) turns the track little.
const NEIGHBOUR_S: f64 = 15.0;

/// Of a stop, the part next to a stretch (s) whose fixes count with it:
/// the vehicle stands there, at the stretch's end.
const STOP_S: f64 = 5.0;

/// Fixes a stretch needs to be matched.
const MIN_FIXES: usize = 3;

/// The spread (m, RMS about their centre) a stretch's track needs at its
/// fixes to be matched: below it a rotation means nothing.
const MIN_SPREAD_M: f64 = 1.0;

/// A stretch's fixes match its track when what the rotation leaves (RMS,
/// after the centres are matched) is at most this share of the track's
/// spread.
const MAX_MISFIT_SHARE: f64 = 0.5;

/// Rotations within this of each other (rad, 60 deg) say the same way;
/// within it of half a turn apart, the other way. Between, nothing.
const AGREE_RAD: f64 = std::f64::consts::FRAC_PI_3;

/// A GPS fix as its row of the log and its east, north (m).
pub type RowFix = (usize, [f64; 2]);

/// A stretch the vehicle drove backwards: the steps `steps` (step `j` runs
/// from row `j - 1` to row `j`), from `from_s` to `to_s`, `metres` long.
#[derive(Clone, Debug, PartialEq)]
pub struct Reversal {
    pub steps: Range<usize>,
    pub from_s: f64,
    pub to_s: f64,
    pub metres: f64,
}

/// A run of moving steps between stops.
#[derive(Clone, Debug)]
struct Stretch {
    steps: Range<usize>,
    metres: f64,
}

impl Stretch {
    /// Row where it starts (the stop before ends).
    fn first_row(&self) -> usize {
        self.steps.start - 1
    }

    /// Row where it ends (the stop after starts).
    fn last_row(&self) -> usize {
        self.steps.end - 1
    }
}

/// The stretches of a log, `t` its times, `dt` its steps and `distance`
/// the distance of each step (all `>= 0`): its reversals (none when the
/// distance has a sign already, some step being negative, or nothing
/// decides). `yaw_rate(j)` is step `j`'s rate about the vertical (rad/s);
/// `fixes` are the GPS fixes as their rows and east, north (m), in order.
pub fn find(
    t: &[f64],
    dt: &[f64],
    yaw_rate: impl Fn(usize) -> f64,
    distance: &[f64],
    fixes: &[RowFix],
) -> Vec<Reversal> {
    let n = t.len().min(dt.len()).min(distance.len());
    if n < 2 || distance.iter().any(|&d| d < 0.0) {
        return Vec::new();
    }
    let moves = |j: usize| moving(dt, distance, j);
    let mut stretches: Vec<Stretch> = Vec::new();
    let mut j = 1;
    while j < n {
        if !moves(j) {
            j += 1;
            continue;
        }
        let start = j;
        while j < n && moves(j) {
            j += 1;
        }
        stretches.push(Stretch {
            steps: start..j,
            metres: distance[start..j].iter().sum(),
        });
    }
    if stretches.len() < 2 || stretches.iter().all(|s| s.metres > MAX_REVERSE_M) {
        return Vec::new();
    }
    let track = dead_reckoned(n, dt, &yaw_rate, distance, fixes);
    // The fixes' rotation onto the track over rows `rows`, where they match.
    let rotation = |rows: Range<usize>| -> Option<f64> {
        let from = fixes.partition_point(|f| f.0 < rows.start);
        let to = fixes.partition_point(|f| f.0 <= rows.end);
        matched_rotation(
            fixes[from..to]
                .iter()
                .zip(&track[from..to])
                .map(|(&(_, en), &r)| (r, en)),
        )
    };
    // Each stretch's rows next to its start and end, each with what it
    // stands of the stops either side.
    let ends = |k: usize| -> [Range<usize>; 2] {
        let s = &stretches[k];
        let stop_before = k
            .checked_sub(1)
            .map_or(0, |p| stretches[p].last_row())
            .max(rows_before(t, s.first_row(), STOP_S));
        let stop_after = stretches
            .get(k + 1)
            .map_or(n - 1, |next| next.first_row())
            .min(rows_after(t, s.last_row(), STOP_S));
        if s.metres <= MAX_REVERSE_M {
            let whole = stop_before..stop_after;
            return [whole.clone(), whole];
        }
        [
            stop_before..rows_after(t, s.first_row(), NEIGHBOUR_S).min(s.last_row()),
            rows_before(t, s.last_row(), NEIGHBOUR_S).max(s.first_row())..stop_after,
        ]
    };
    let rotations: Vec<[Option<f64>; 2]> = (0..stretches.len())
        .map(|k| ends(k).map(&rotation))
        .collect();
    // Whether stretch k + 1 runs the way stretch k does (+1), the other (-1).
    let relation: Vec<Option<f64>> = (0..stretches.len() - 1)
        .map(|k| {
            let (a, b) = (rotations[k][1]?, rotations[k + 1][0]?);
            let apart = crate::rotation::wrap_pi(b - a).abs();
            if apart <= AGREE_RAD {
                Some(1.0)
            } else if apart >= std::f64::consts::PI - AGREE_RAD {
                Some(-1.0)
            } else {
                None
            }
        })
        .collect();
    let mut sign: Vec<Option<f64>> = stretches
        .iter()
        .map(|s| (s.metres > MAX_REVERSE_M).then_some(1.0))
        .collect();
    loop {
        let mut changed = false;
        for k in 0..stretches.len() {
            if sign[k].is_some() {
                continue;
            }
            let before = k.checked_sub(1).and_then(|p| Some(sign[p]? * relation[p]?));
            let after = sign
                .get(k + 1)
                .copied()
                .flatten()
                .and_then(|s| Some(s * relation[k]?));
            let said = match (before, after) {
                (Some(a), Some(b)) if a != b => continue,
                (Some(a), _) | (None, Some(a)) => a,
                (None, None) => continue,
            };
            sign[k] = Some(said);
            changed = true;
        }
        if !changed {
            break;
        }
    }
    stretches
        .iter()
        .zip(&sign)
        .filter(|(_, s)| **s == Some(-1.0))
        .map(|(s, _)| Reversal {
            steps: s.steps.clone(),
            from_s: t[s.first_row()],
            to_s: t[s.last_row()],
            metres: s.metres,
        })
        .collect()
}

/// The dead-reckoned track at each of the `fixes`' rows (in order), `P_j =
/// P_{j-1} + d_j (cos psi_j, sin psi_j)`, `psi_j = psi_{j-1} + (w_j - b)
/// dt_j`, with `b` the median rate over the stops (where the vehicle does
/// not turn) when they last a second or more, else 0. Only the fixes' rows
/// are kept: on a 6-hour ride every row's would be 35 MB.
pub(crate) fn dead_reckoned(
    n: usize,
    dt: &[f64],
    yaw_rate: &impl Fn(usize) -> f64,
    distance: &[f64],
    fixes: &[RowFix],
) -> Vec<[f64; 2]> {
    let mut rates: Vec<f64> = Vec::new();
    let mut still_s = 0.0;
    for j in 1..n {
        if !moving(dt, distance, j) {
            rates.push(yaw_rate(j));
            still_s += dt[j];
        }
    }
    let bias = if still_s >= 1.0 {
        crate::statistics::median(&mut rates)
    } else {
        0.0
    };
    let mut psi = 0.0;
    let mut p = [0.0, 0.0];
    let mut at = Vec::with_capacity(fixes.len());
    let mut next = fixes.iter().map(|f| f.0.min(n - 1)).peekable();
    for j in 0..n {
        if j > 0 {
            psi += (yaw_rate(j) - bias) * dt[j];
            p = [
                p[0] + distance[j] * psi.cos(),
                p[1] + distance[j] * psi.sin(),
            ];
        }
        while next.next_if_eq(&j).is_some() {
            at.push(p);
        }
    }
    at
}

/// A point of a dead-reckoned track and the fix there (east, north; m).
type Pair = ([f64; 2], [f64; 2]);

/// The rotation `phi` that takes a track's points `r` onto their fixes `g`
/// (both centred), `atan2(sum r x g, sum r . g)`, where there are
/// [`MIN_FIXES`], the track spreads [`MIN_SPREAD_M`] and what the rotation
/// leaves is at most [`MAX_MISFIT_SHARE`] of that spread.
fn matched_rotation(pairs: impl Iterator<Item = Pair>) -> Option<f64> {
    let pairs: Vec<Pair> = pairs.collect();
    if pairs.len() < MIN_FIXES {
        return None;
    }
    let count = pairs.len() as f64;
    let centre = |which: fn(&Pair) -> [f64; 2]| {
        let sum = pairs
            .iter()
            .map(which)
            .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
        [sum[0] / count, sum[1] / count]
    };
    let (cr, cg) = (centre(|p| p.0), centre(|p| p.1));
    let centred: Vec<Pair> = pairs
        .iter()
        .map(|(r, g)| ([r[0] - cr[0], r[1] - cr[1]], [g[0] - cg[0], g[1] - cg[1]]))
        .collect();
    let (mut dot, mut cross, mut spread) = (0.0, 0.0, 0.0);
    for (r, g) in &centred {
        dot += r[0] * g[0] + r[1] * g[1];
        cross += r[0] * g[1] - r[1] * g[0];
        spread += r[0] * r[0] + r[1] * r[1];
    }
    let spread = (spread / count).sqrt();
    if spread < MIN_SPREAD_M {
        return None;
    }
    let phi = cross.atan2(dot);
    let (s, c) = phi.sin_cos();
    let misfit = (centred
        .iter()
        .map(|(r, g)| {
            let (x, y) = (c * r[0] - s * r[1], s * r[0] + c * r[1]);
            (g[0] - x).powi(2) + (g[1] - y).powi(2)
        })
        .sum::<f64>()
        / count)
        .sqrt();
    (misfit <= MAX_MISFIT_SHARE * spread).then_some(phi)
}

/// Whether step `j` moves: faster than [`STOP_SPEED_MPS`] either way.
fn moving(dt: &[f64], distance: &[f64], j: usize) -> bool {
    dt[j] > 0.0 && distance[j].abs() > STOP_SPEED_MPS * dt[j]
}

/// The first row at most `seconds` before row `row`.
fn rows_before(t: &[f64], row: usize, seconds: f64) -> usize {
    t[..=row].partition_point(|&x| x < t[row] - seconds)
}

/// The last row at most `seconds` after row `row`.
fn rows_after(t: &[f64], row: usize, seconds: f64) -> usize {
    row + t[row..].partition_point(|&x| x <= t[row] + seconds) - 1
}

/// What was found, in a sentence; `None` for nothing.
pub fn describe(found: &[Reversal]) -> Option<String> {
    let longest = found.iter().max_by(|a, b| a.metres.total_cmp(&b.metres))?;
    let total: f64 = found.iter().map(|r| r.metres).sum();
    Some(format!(
        "the distance has no sign, and the GPS track says the vehicle drove backwards over {} stretch(es) between stops, {total:.1} m in all, the longest {:.1} m at {:.1}-{:.1} s: the path moves backwards there",
        found.len(),
        longest.metres,
        longest.from_s,
        longest.to_s,
    ))
}

/// `distance` with each of `found`'s steps negated.
pub fn apply(distance: &mut [f64], found: &[Reversal]) {
    for r in found {
        for d in &mut distance[r.steps.clone()] {
            *d = -*d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight drive east at 10 Hz: `speed(t)` (signed), its fixes at
    /// 1 Hz off the truth by `error(k)`; returns the times, steps, unsigned
    /// distances and fixes.
    fn drive(
        seconds: f64,
        speed: impl Fn(f64) -> f64,
        error: impl Fn(usize) -> [f64; 2],
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<RowFix>) {
        let n = (seconds * 10.0) as usize + 1;
        let t: Vec<f64> = (0..n).map(|j| j as f64 * 0.1).collect();
        let mut dt = vec![0.0; n];
        let mut distance = vec![0.0; n];
        let mut x = vec![0.0; n];
        for j in 1..n {
            dt[j] = 0.1;
            let d = 0.5 * (speed(t[j - 1]) + speed(t[j])) * 0.1;
            x[j] = x[j - 1] + d;
            distance[j] = d.abs();
        }
        let fixes = (0..n)
            .step_by(10)
            .enumerate()
            .map(|(k, row)| {
                let e = error(k);
                (row, [x[row] + e[0], e[1]])
            })
            .collect();
        (t, dt, distance, fixes)
    }

    /// Back 8 m at 1.6 m/s for 5 s, stand 3 s, then east at 10 m/s.
    fn out_of_a_bay(t: f64) -> f64 {
        if t < 5.0 {
            -1.6
        } else if t < 8.0 {
            0.0
        } else {
            10.0_f64.min(2.0 * (t - 8.0))
        }
    }

    /// Fixes off by up to about half a metre, in no pattern.
    fn jitter(k: usize) -> [f64; 2] {
        let k = k as f64;
        [0.4 * (1.7 * k).sin(), 0.4 * (2.3 * k).cos()]
    }

    #[test]
    fn backing_out_of_a_bay_is_found_and_nothing_else() {
        let (t, dt, distance, fixes) = drive(40.0, out_of_a_bay, jitter);
        let found = find(&t, &dt, |_| 0.0, &distance, &fixes);
        assert_eq!(found.len(), 1, "{found:?}");
        let r = &found[0];
        assert!((r.metres - 8.0).abs() < 0.2, "{r:?}");
        assert!(r.from_s < 0.2 && (r.to_s - 5.0).abs() < 0.2, "{r:?}");
        let mut signed = distance.clone();
        apply(&mut signed, &found);
        // The step into the stand (t = 4.9-5.0 s) still moves backwards.
        assert!(signed[1..=50].iter().all(|&d| d < 0.0));
        assert!(signed[51..].iter().all(|&d| d >= 0.0));
        let said = describe(&found).unwrap_or_default();
        assert!(said.contains("7.9 m at 0.0-5.0 s"), "{said}");
    }

    #[test]
    fn a_drive_forwards_throughout_keeps_its_direction() {
        let forwards = |t: f64| out_of_a_bay(t).abs();
        let (t, dt, distance, fixes) = drive(40.0, forwards, jitter);
        assert!(find(&t, &dt, |_| 0.0, &distance, &fixes).is_empty());
    }

    #[test]
    fn a_bias_the_stops_show_is_taken_out_of_the_heading() {
        // 4 deg/s of bias, which over the 13 s between the stretches'
        // pieces turns the track by 50 deg: the stands read it.
        let (t, dt, distance, fixes) = drive(40.0, out_of_a_bay, jitter);
        let bias = 4f64.to_radians();
        assert_eq!(find(&t, &dt, |_| bias, &distance, &fixes).len(), 1);
    }

    #[test]
    fn reflections_of_tens_of_metres_decide_nothing() {
        let reflections = |k: usize| {
            let k = k as f64;
            [25.0 * (1.3 * k).sin(), 25.0 * (0.7 * k).cos()]
        };
        let (t, dt, distance, fixes) = drive(40.0, out_of_a_bay, reflections);
        assert!(find(&t, &dt, |_| 0.0, &distance, &fixes).is_empty());
    }

    #[test]
    fn a_signed_distance_is_left_to_its_sign() {
        let (t, dt, mut distance, fixes) = drive(40.0, out_of_a_bay, jitter);
        distance[1] = -distance[1];
        assert!(find(&t, &dt, |_| 0.0, &distance, &fixes).is_empty());
    }

    #[test]
    fn the_rotation_of_a_matched_shape_is_recovered() {
        let track = [[0.0, 0.0], [3.0, 0.0], [6.0, 1.0], [8.0, 3.0]];
        let turn = 2.5f64;
        let (s, c) = turn.sin_cos();
        let pairs = track.map(|r| (r, [c * r[0] - s * r[1] + 7.0, s * r[0] + c * r[1] - 2.0]));
        let phi = matched_rotation(pairs.into_iter()).unwrap_or(f64::NAN);
        assert!((phi - turn).abs() < 1e-9, "{phi}");
        // Too few fixes, or a track that hardly moves, match nothing.
        assert!(matched_rotation(pairs[..2].iter().copied()).is_none());
        let still = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.1]].map(|r| (r, r));
        assert!(matched_rotation(still.into_iter()).is_none());
    }
}
