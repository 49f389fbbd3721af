//! `gyro_stops`: the turns across each stretch where the gyro stopped
//! answering (deg: per stop one about x and one about y, and one about z per
//! piece of at most [`PIECE_S`]). Added by itself where the log has such a
//! stop, as `gnss_gaps` comes with the GNSS speed's gaps (`-gyro_stops`
//! takes it out).
//!
//! A logger that loses its IMU writes zeros or the last reading on every
//! row (see [`crate::gyro_stops`]); what the vehicle turned through there
//! is unknown. The signals set the yaw rates of the stop's steps to the line
//! between the readings either side ([`crate::signals::Signals::gyro_stops`]),
//! and this effect spreads each turn evenly over its time: piece `k`'s
//! `c_k,z` over its `T_k` about z on top of that line, stop `g`'s `c_g,x`
//! and `c_g,y` over its `T_g = t_b - t_a` in place of the rates as read:
//!
//! `omega'_j = (c_g,x w_j / T_g, c_g,y w_j / T_g, omega_j,z + c_k,z w_j / T_k)`,
//! `d omega'_j / d omega_j = diag(0, 0, 1)`
//!
//! for the steps that overlap the stop, `w_j` the share of step `j` inside
//! it (1 on the log's own rows; a step of the coarse ride that straddles an
//! end turns its share). About z: the vertical once the log is mounted (the
//! checks say which axis is up), the yaw of a planar ride, whose roll and
//! pitch are held. Roll and pitch are free as well on a 3D ride: the road's
//! grade changes over a stop, and the comma minute's heights, with them
//! held at no turn over a 10 s stop, ended 3.7 m off its reference (1.3 m
//! with the turn free), and with the log's median rate there 1.5 m.
//!
//! The fit starts about z from the turn the fixes around the stop tell
//! (see [`turn_from_fixes`]), shared among its pieces by their length,
//! else from no turn across it: from the turn
//! the interpolated rates make, Berlin's yaw rate held for 25 s after a
//! bend at -27 deg/s started 420 deg off, and simulated bicycles with
//! 200 deg in a 15 s stop ended in other minima.
//!
//! Priors: about z, `c_k,z + turned_k ~ N(0, (min(90 deg/s T_k,
//! 180 deg))^2)`, no turn through the rates as read (`turned_k`): a vehicle
//! turns at most some 90 deg/s, and a stop that no fix follows (at a ride's
//! end) turns nothing; about x and y, `N(0, (20 deg)^2)`: a vehicle's
//! attitude comes back, a bicycle's lean may differ by tens of degrees
//! between the stop's ends.

use nalgebra::{Matrix3, Vector3};

use super::{Columns, DEG_PER_RAD, Effect, GyroPartials, ParamInfo, PriorRows, Role};
use crate::contract::{ModelError, ModelSpec, StartGuess};
use crate::signals::Signals;

/// The fastest turn the prior expects across a stop (deg/s), and the most (deg).
const MAX_TURN_RATE_DPS: f64 = 90.0;
const MAX_TURN_DEG: f64 = 180.0;

/// The prior's spread of the roll and pitch turned across a stop (deg):
/// a vehicle's attitude comes back, a bicycle's lean may differ by tens of
/// degrees between the stop's ends.
const LEVEL_SIGMA_DEG: f64 = 20.0;

/// The longest piece of a stop with a turn about z of its own (s): inside
/// a stop the fixes (1 Hz and more) tell how the turn went, a corner taken
/// in its first seconds or its last. One turn spread evenly over a 15 s
/// stop put a simulated bicycle's corner where it was not, and the fit bent
/// the minute around it to meet the fixes inside the stop (3.9 m from the
/// truth against 1.5 m with its gyro whole).
const PIECE_S: f64 = 2.0;

/// Where a step lies in the stops (see [`GyroStops`]).
#[derive(Clone, Copy, Debug)]
struct InStop {
    /// The stop and the step's weight `w_j / T_g` in it.
    stop: usize,
    w_stop: f64,
    /// The piece and the step's weight `w_j / T_k` in it.
    piece: usize,
    w_piece: f64,
}

#[derive(Clone, Debug, Default)]
pub struct GyroStops {
    /// A planar ride: roll and pitch held.
    planar: bool,
    /// Each stop's length `T_g` (s).
    lengths: Vec<f64>,
    /// Each piece's length `T_k` (s), and its turn about z through the
    /// signals' own rates, `sum_j w_j omega_j,z dt_j` (rad): `c_k = -that`
    /// turns nothing net.
    piece_lengths: Vec<f64>,
    turned: Vec<f64>,
    /// Each piece's stop.
    piece_stop: Vec<usize>,
    /// Per step: where it lies in the stops, if it does.
    step: Vec<Option<InStop>>,
    /// Each stop's turn as the fixes around it tell it (see
    /// [`turn_from_fixes`]), before the bias; `None` where they cannot.
    from_fixes: Vec<Option<f64>>,
    /// Whether each stop is a gap in the log, its rows filled (see
    /// [`crate::log_gaps`]).
    filled: Vec<bool>,
    /// First and last step each parameter acts on (see
    /// [`Effect::param_steps`]).
    acts_on: Vec<Option<(usize, usize)>>,
}

impl GyroStops {
    pub fn applies(signals: &Signals) -> bool {
        !signals.gyro_stops.is_empty()
    }

    pub fn new(signals: &Signals) -> Result<Self, ModelError> {
        if !Self::applies(signals) {
            return Err(ModelError::NotApplicable {
                effect: "gyro_stops".into(),
                reason: "the gyro answers on every row of the log".into(),
            });
        }
        let n = signals.t.len();
        let mut step: Vec<Option<InStop>> = vec![None; n];
        let mut lengths = Vec::with_capacity(signals.gyro_stops.len());
        let (mut piece_lengths, mut turned, mut piece_stop) = (Vec::new(), Vec::new(), Vec::new());
        for (g, &(a, b)) in signals.gyro_stops.iter().enumerate() {
            let length = b - a;
            lengths.push(length);
            if length <= 0.0 {
                continue;
            }
            // How the turn went inside the stop only its fixes tell: at
            // most one piece more than they bound, and two without any (a
            // gap in the log), so that the stop's end can come out beside
            // the line it went in on (a lane change, an S-bend) and, with
            // its distance free, anywhere (a turn, a move, a turn). Pieces
            // of 2 s with no fix in them let the fit wiggle the path through
            // a 10 s gap on comma's straight highway (2.1 m from the
            // reference, 1.75 m in two pieces).
            let fixes_inside = signals.fixes.iter().filter(|f| f.t > a && f.t < b).count();
            let pieces = ((length / PIECE_S).ceil().max(1.0) as usize).min(fixes_inside + 2);
            let piece_length = length / pieces as f64;
            let first_piece = piece_lengths.len();
            for _ in 0..pieces {
                piece_lengths.push(piece_length);
                turned.push(0.0);
                piece_stop.push(g);
            }
            // Steps `(t_{j-1}, t_j]` that overlap `(a, b]`, each counted in
            // the piece that holds its middle.
            let first = signals.t.partition_point(|&t| t <= a).max(1);
            for j in first..n {
                let start = signals.t[j] - signals.dt[j];
                if start >= b {
                    break;
                }
                let overlap = signals.t[j].min(b) - start.max(a);
                if overlap > 0.0 && signals.dt[j] > 0.0 {
                    let middle = 0.5 * (signals.t[j].min(b) + start.max(a));
                    let k = (((middle - a) / piece_length) as usize).min(pieces - 1);
                    let piece = first_piece + k;
                    // The piece's weight once its time is summed, below.
                    step[j] = Some(InStop {
                        stop: g,
                        w_stop: overlap / signals.dt[j] / length,
                        piece,
                        w_piece: overlap / signals.dt[j],
                    });
                    turned[piece] += signals.gyro[j].z * overlap;
                }
            }
        }
        // A piece's time `T_k` is that of the steps it holds (each step in
        // one piece), so that its turn is `c_k` exactly.
        piece_lengths.iter_mut().for_each(|l| *l = 0.0);
        for (j, s) in step.iter().enumerate() {
            if let Some(s) = s {
                piece_lengths[s.piece] += s.w_piece * signals.dt[j];
            }
        }
        for s in step.iter_mut().flatten() {
            s.w_piece /= piece_lengths[s.piece].max(f64::MIN_POSITIVE);
        }
        let from_fixes = (0..lengths.len())
            .map(|g| {
                turn_from_fixes(signals, signals.gyro_stops[g], |j| {
                    step[j].filter(|s| s.stop == g).map(|s| s.w_stop)
                })
            })
            .collect();
        let filled = signals
            .gyro_stops
            .iter()
            .map(|&(a, _)| signals.log_gaps.iter().any(|&(from, _)| from == a))
            .collect();
        let mut acts_on = vec![None; 2 * lengths.len() + piece_lengths.len()];
        for (j, s) in step.iter().enumerate() {
            if let Some(s) = s {
                let z = 2 * lengths.len() + s.piece;
                for i in [2 * s.stop, 2 * s.stop + 1, z] {
                    let span: &mut Option<(usize, usize)> = &mut acts_on[i];
                    *span = Some(span.map_or((j, j), |(first, _)| (first, j)));
                }
            }
        }
        Ok(Self {
            filled,
            acts_on,
            planar: signals.attitude.is_planar(),
            lengths,
            piece_lengths,
            turned,
            piece_stop,
            step,
            from_fixes,
        })
    }

    /// Index of the z turn of piece `k` (after every stop's x and y).
    fn z(&self, k: usize) -> usize {
        2 * self.lengths.len() + k
    }

    /// Piece `k`'s turn about z at the fit's start, before the bias (rad):
    /// its share of the stop's turn from the fixes, else none through the
    /// rates as read, and on a gap in the log the rates as they are (see
    /// [`Effect::initial`]).
    fn start_turn(&self, k: usize) -> f64 {
        let g = self.piece_stop[k];
        if self.filled[g] {
            0.0
        } else {
            let share = self.piece_lengths[k] / self.lengths[g];
            self.from_fixes[g].map_or(-self.turned[k], |c| c * share)
        }
    }

    /// The yaw rate each row's step gains at the fit's start (rad/s, zero
    /// outside the stops): `c_k,z w_j / T_k` with `c_k,z` from
    /// [`Self::start_turn`], the bias aside. The start guess dead-reckons
    /// with it, so that its track turns across the stops as the fit's
    /// first does: with the held rates' line alone, a helmet camera's
    /// looks, bridged as stops while the car turned 60 deg, kinked the
    /// guess's track there and its course samples' line.
    pub(crate) fn start_yaw_rates(&self) -> Vec<f64> {
        self.step
            .iter()
            .map(|s| s.map_or(0.0, |s| self.start_turn(s.piece) * s.w_piece))
            .collect()
    }
}

impl Effect for GyroStops {
    fn id(&self) -> String {
        "gyro_stops".into()
    }

    /// Each stop's roll and pitch, `turn_x[g]` and `turn_y[g]`, then each
    /// piece's yaw, `turn_z[g.k]`.
    fn params(&self) -> Vec<ParamInfo> {
        let mut out: Vec<ParamInfo> = (0..self.lengths.len())
            .flat_map(|g| {
                ["x", "y"].into_iter().map(move |a| {
                    ParamInfo::new(format!("turn_{a}[{}]", g + 1), "deg", DEG_PER_RAD)
                })
            })
            .collect();
        let mut k_in_stop = 0;
        for k in 0..self.piece_lengths.len() {
            if k > 0 && self.piece_stop[k] != self.piece_stop[k - 1] {
                k_in_stop = 0;
            }
            k_in_stop += 1;
            out.push(ParamInfo::new(
                format!("turn_z[{}.{k_in_stop}]", self.piece_stop[k] + 1),
                "deg",
                DEG_PER_RAD,
            ));
        }
        out
    }

    fn n_params(&self) -> usize {
        2 * self.lengths.len() + self.piece_lengths.len()
    }

    /// Held at their start through step 1: its windows before a stop see
    /// nothing of the turn but its prior, which pulled it to no turn before
    /// they reached the stop (a simulated 198 deg stop then ended at
    /// -120 deg, 115 m from the truth).
    fn role(&self) -> Role {
        Role::Step2Only
    }

    /// A stop's turns act on its own steps only, and move the path after
    /// it as a segment's bias does: local parameters, which the chain
    /// solver carries only while their stop is open. As global ones, every
    /// stop widened every row of the chain (a 30-minute ride with twenty
    /// 5 s stops, a hundred turns, took 52 s to fit instead of 0.8 s).
    fn param_steps(&self, i: usize) -> Option<(usize, usize)> {
        self.acts_on.get(i).copied().flatten()
    }

    /// A planar ride has no roll or pitch to turn.
    fn fixed(&self, i: usize) -> bool {
        self.planar && i < 2 * self.lengths.len()
    }

    /// The stops' times and turns are the signals', not the spec's.
    fn reweighted(&self, _spec: &ModelSpec) -> Option<Box<dyn Effect>> {
        Some(Box::new(self.clone()))
    }

    /// No roll or pitch across each stop; about z, the turn the fixes
    /// around it tell (see [`turn_from_fixes`]) shared among its pieces by
    /// their length, or else no turn (the signals' own rates there undone),
    /// with the guessed bias's turn added back: the model takes the bias off
    /// every rate, the stop's too. Across a gap in the log, the line between
    /// the readings either side as it is: they are the gyro's own, where a
    /// stop's are a held reading's ends. From the fixes' turn, a simulated
    /// bicycle circling at 17 deg/s through a 15 s gap (seed 7) came out of
    /// it turned 600 deg too far, 1.93 m from the truth outside the gap
    /// where it is 0.95 m from the line (0.93 m with no rows lost); on the
    /// other rides tried (three bicycles, a car, comma, Berlin) the two
    /// starts end alike.
    fn initial(&self, guess: &StartGuess) -> Vec<f64> {
        let mut out = vec![0.0; 2 * self.lengths.len()];
        for (k, &length) in self.piece_lengths.iter().enumerate() {
            out.push(guess.gyro_bias.z * length + self.start_turn(k));
        }
        out
    }

    fn n_prior(&self) -> usize {
        self.n_params()
    }

    /// Residuals `c_g,x / sigma_level` and `c_g,y / sigma_level` per stop,
    /// `(c_k,z + turned_k) / sigma_k` per piece, `sigma_k = min(90 deg/s
    /// T_k, 180 deg)`: about no turn through the rates as read.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        let level = LEVEL_SIGMA_DEG / DEG_PER_RAD;
        for i in 0..2 * self.lengths.len() {
            let row = out.residuals.len();
            out.residuals.push(p[i] / level);
            out.entries.push((row, i, 1.0 / level));
        }
        for (k, &length) in self.piece_lengths.iter().enumerate() {
            let sigma = ((MAX_TURN_RATE_DPS * length).min(MAX_TURN_DEG) / DEG_PER_RAD).max(1e-3);
            let (i, row) = (self.z(k), out.residuals.len());
            out.residuals.push((p[i] + self.turned[k]) / sigma);
            out.entries.push((row, i, 1.0 / sigma));
        }
    }

    fn acts_on_gyro(&self) -> bool {
        true
    }

    fn gyro(&self, p: &[f64], j: usize, omega: Vector3<f64>) -> Vector3<f64> {
        match self.step.get(j).copied().flatten() {
            Some(s) => Vector3::new(
                p[2 * s.stop] * s.w_stop,
                p[2 * s.stop + 1] * s.w_stop,
                omega.z + p[self.z(s.piece)] * s.w_piece,
            ),
            None => omega,
        }
    }

    fn gyro_partials(&self, _p: &[f64], j: usize, _omega: &Vector3<f64>) -> GyroPartials {
        let mut params = Columns::default();
        let mut d_in = Matrix3::identity();
        if let Some(s) = self.step.get(j).copied().flatten() {
            params.push(2 * s.stop, Vector3::x() * s.w_stop);
            params.push(2 * s.stop + 1, Vector3::y() * s.w_stop);
            params.push(self.z(s.piece), Vector3::z() * s.w_piece);
            d_in = Matrix3::from_diagonal(&Vector3::z());
        }
        GyroPartials { d_in, params }
    }

    fn gyro_batch(&self, p: &[f64], first: usize, rates: &mut [Vector3<f64>]) {
        for (w, s) in rates.iter_mut().zip(&self.step[first..]) {
            if let Some(s) = *s {
                *w = Vector3::new(
                    p[2 * s.stop] * s.w_stop,
                    p[2 * s.stop + 1] * s.w_stop,
                    w.z + p[self.z(s.piece)] * s.w_piece,
                );
            }
        }
    }

    fn gyro_backward_reads_input(&self) -> bool {
        false
    }

    fn gyro_backward(
        &self,
        _p: &[f64],
        _omega_in: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        grad_p: &mut [f64],
    ) {
        for (g, s) in grad.iter_mut().zip(&self.step).skip(1) {
            if let Some(s) = *s {
                grad_p[2 * s.stop] += g.x * s.w_stop;
                grad_p[2 * s.stop + 1] += g.y * s.w_stop;
                grad_p[self.z(s.piece)] += g.z * s.w_piece;
                g.x = 0.0;
                g.y = 0.0;
            }
        }
    }
}

/// Seconds of fixes before a stop whose chord gives the course into it,
/// and after it whose misfit chooses the turn (see [`turn_from_fixes`]).
const COURSE_S: f64 = 5.0;
const AFTER_S: f64 = 10.0;

/// Shortest chord (m) that gives a course.
const MIN_CHORD_M: f64 = 3.0;

/// The turns tried (rad): every 5 deg within two full turns either way.
const TRIED_DEG: (f64, f64, f64) = (-720.0, 720.0, 5.0);

/// The turn `c` across stop `(a, b)` (the parameter's value, before the
/// bias) that the fixes around it ask for: the path is dead-reckoned in the
/// plane from the last fix before the stop, at the course of the fixes of
/// the [`COURSE_S`] before it (carried to that fix by the rates), through
/// the stop with `c` spread over its steps (`weight(j)`: `w_j / T`) and
/// [`AFTER_S`] past it, for every turn of [`TRIED_DEG`], and the one whose
/// path passes nearest the fixes (least squares) is taken. Without it the
/// fit started from no turn and stopped in another minimum where the
/// vehicle turned far: on simulated rides with 255 deg in a 15 s stop,
/// -29 deg, 36 m from the truth. `None` without a course into the stop or
/// two fixes in and after it.
fn turn_from_fixes(
    signals: &Signals,
    (a, b): (f64, f64),
    weight: impl Fn(usize) -> Option<f64>,
) -> Option<f64> {
    let fixes = &signals.fixes;
    let into: Vec<&crate::signals::Fix> = fixes
        .iter()
        .filter(|f| f.t <= a && f.t >= a - COURSE_S)
        .collect();
    let (first, last) = (into.first()?, into.last()?);
    let (de, dn) = (last.en[0] - first.en[0], last.en[1] - first.en[1]);
    if de.hypot(dn) < MIN_CHORD_M {
        return None;
    }
    // The course at the chord's middle, carried to the last fix.
    let middle = 0.5 * (first.t + last.t);
    let carried: f64 = (first.row + 1..=last.row)
        .filter(|&j| signals.t[j] > middle)
        .map(|j| signals.gyro[j].z * signals.dt[j])
        .sum();
    let heading = dn.atan2(de) + carried;
    let end = signals.t.partition_point(|&t| t <= b + AFTER_S);
    let judged: Vec<&crate::signals::Fix> = fixes
        .iter()
        .filter(|f| f.row > last.row && f.row < end)
        .collect();
    if judged.len() < 2 {
        return None;
    }
    let misfit = |c: f64| {
        let (mut psi, mut p) = (heading, [last.en[0], last.en[1]]);
        let mut next = judged.iter().peekable();
        let mut sum = 0.0;
        for j in last.row + 1..end {
            psi += (signals.gyro[j].z + c * weight(j).unwrap_or(0.0)) * signals.dt[j];
            p[0] += signals.distance[j] * psi.cos();
            p[1] += signals.distance[j] * psi.sin();
            while let Some(f) = next.next_if(|f| f.row == j) {
                sum += (p[0] - f.en[0]).powi(2) + (p[1] - f.en[1]).powi(2);
            }
        }
        sum
    };
    let (from, to, step) = TRIED_DEG;
    let tried = ((to - from) / step) as usize + 1;
    (0..tried)
        .map(|k| (from + k as f64 * step) / DEG_PER_RAD)
        .map(|c| (c, misfit(c)))
        .min_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(c, _)| c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::winding_signals;

    #[test]
    fn the_turn_is_spread_over_the_stop_and_partials_are_right() {
        let mut sig = winding_signals(12.0, 100.0);
        // A 5 s stop in three pieces, a 0.495 s one in one.
        sig.gyro_stops = vec![(3.0, 8.0), (9.005, 9.5)];
        let e = GyroStops::new(&sig).unwrap();
        assert_eq!(e.piece_lengths.len(), 4);
        assert_eq!(e.n_params(), 8);
        assert_eq!(e.params()[6].name, "turn_z[1.3]");
        let p = [0.1, -0.05, 0.02, 0.03, 0.4, -0.3, 0.1, -0.2];
        for j in [350, 450, 750, 940] {
            crate::effects::testing::check_gyro_partials(&e, &p, j, Vector3::new(0.1, 0.2, 0.3));
        }
        crate::effects::testing::check_batches(&e, &p, sig.len());
        // The rates integrate to each stop's turns, about every axis.
        let turned = |sig: &Signals, e: &GyroStops, range: (f64, f64)| -> Vector3<f64> {
            (1..sig.len())
                .filter(|&j| sig.t[j] > range.0 && sig.t[j] <= range.1)
                .map(|j| e.gyro(&p, j, Vector3::zeros()) * sig.dt[j])
                .sum()
        };
        let first = Vector3::new(p[0], p[1], p[4] + p[5] + p[6]);
        let second = Vector3::new(p[2], p[3], p[7]);
        let got = turned(&sig, &e, (2.98, 8.02));
        assert!((got - first).norm() < 1e-12, "{got}");
        let got = turned(&sig, &e, (8.98, 9.52));
        assert!((got - second).norm() < 1e-12, "{got}");
        // On a coarse ride whose steps straddle the stops' ends, too.
        let coarse = sig.coarse(0.05).unwrap();
        let e = GyroStops::new(&coarse).unwrap();
        let got = turned(&coarse, &e, (0.0, 12.0));
        assert!((got - first - second).norm() < 1e-12, "{got}");
        let mut rows = PriorRows::default();
        e.prior(&p, &mut rows);
        assert_eq!(rows.residuals.len(), e.n_prior());
        assert!((e.piece_lengths[0] - 5.0 / 3.0).abs() < 0.05);
        let sigma = MAX_TURN_RATE_DPS * e.piece_lengths[0] / DEG_PER_RAD;
        assert!((rows.residuals[4] - (p[4] + e.turned[0]) / sigma).abs() < 1e-12);
        assert!((rows.residuals[0] - p[0] / (LEVEL_SIGMA_DEG / DEG_PER_RAD)).abs() < 1e-12);
        assert!(GyroStops::new(&winding_signals(12.0, 100.0)).is_err());
    }

    /// The start guess's rates across the stops are the fit's first, row by
    /// row: `c_k w_j / T_k` with the effect's initial turns (bias aside).
    #[test]
    fn the_start_guess_turns_in_the_stops_as_the_fit_starts() {
        let mut sig = winding_signals(12.0, 100.0);
        sig.gyro_stops = vec![(3.0, 8.0), (9.005, 9.5)];
        for sig in [sig.clone(), sig.coarse(0.05).unwrap()] {
            let e = GyroStops::new(&sig).unwrap();
            let mut guess = StartGuess::from_signals(&sig).unwrap();
            guess.gyro_bias = Vector3::zeros();
            let start = e.initial(&guess);
            let rates = e.start_yaw_rates();
            assert_eq!(rates.len(), sig.len());
            assert!(rates.iter().any(|r| r.abs() > 1e-6));
            for (j, r) in rates.iter().enumerate().skip(1) {
                let fit = e.gyro(&start, j, Vector3::zeros()).z;
                assert!((fit - r).abs() < 1e-12, "row {j}: {fit} against {r}");
            }
        }
    }
}
