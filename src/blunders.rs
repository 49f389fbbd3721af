//! Gross GPS blunders: fixes that cannot belong to the ride at all.
//!
//! Consumer receivers (phones, action cameras, drones) write fixes that are
//! kilometres off: the placeholder `0, 0` ("null island") while they have no
//! fix, a wild first fix before they lock, a run of seconds on a wrong
//! solution. The model's least squares cannot survive one of them: a single
//! fix 1.1 km off on a 5-minute simulated city ride took the path from
//! 27.5 m to 71 m RMS from the fixes (and its noise estimate from a wander
//! over 64 s to one over 1 s); one 11 km off, or three at `0, 0`, made the
//! fit fail as "not physical". The robust loss and the noise model are for
//! the errors a working receiver makes (reflections of 10-70 m); these are
//! no measurement of the ride, and they are left out before anything else
//! reads the fixes, with a warning that names them.
//!
//! A fix is a blunder when it is at exactly `0, 0`, or when it is not on the
//! longest chain of fixes in which each is reachable from the one before:
//!
//! `|p_j - p_i| <= V_MAX_MPS (t_j - t_i) + SLACK_M + 3 (hacc_i + hacc_j)`.
//!
//! The bound is physical, not fitted: no vehicle gyropath reconstructs moves
//! faster than [`V_MAX_MPS`], and [`SLACK_M`] covers the worst errors of a
//! working receiver at both ends (a receiver that says its fix is poor, by
//! its `gps_hacc_m`, gets that much more). So a blunder is at least
//! `V_MAX_MPS dt + SLACK_M` (300 m a second apart) off the track, and no
//! fix of a working receiver is ever one.
//!
//! Before them, a logger's held repeats: many loggers and phone apps write
//! the last fix they had on every row (at the gyro's 100 Hz), where the
//! format leaves a row without a fix empty. Read as fixes, a 5-minute ride
//! had 30,000 of them, one a second repeated a hundred times: the fit took
//! 16 s and 227 MB (0.15 s and 15 MB without) and failed as "not physical".
//! A fix is such a repeat when it equals the one before it to the bit and
//! most of the log's fixes do ([`held`]): then only the rows where the value
//! changes are fixes, at the row where it first appears. A receiver that
//! repeats its fix while standing (the Husky robot's, 7 of 988) keeps them.
//!
//! And a receiver's stale repeats: many receivers, and the apps and
//! converters behind them, go on writing the last fix they had once they
//! lose the sky, a new row a second with the old position, where others
//! leave the rows empty. Read as fixes, they say the vehicle stood while its
//! odometer drove on: ten seconds of them on the comma car drive took its
//! path from 1.25 m to 17 m off the reference (the noise search read a 57 m
//! wander into the ride to fit them), reported as a success. A run of fixes
//! equal to the bit to the one that starts it is stale when the distance
//! signal moves more than [`STALE_MOVED_M`] over it ([`stale`]): no working
//! receiver repeats a fix to the bit across that much road. Its repeats are
//! left out (an outage); the run's first fix, the last one the receiver had,
//! is kept.

use crate::geodesy::{Geodetic, LocalFrame};
use crate::statistics::median;

/// The fastest any vehicle that gyropath reconstructs moves (m/s, 360 km/h).
pub const V_MAX_MPS: f64 = 100.0;

/// A working receiver's worst error at both ends of a pair of fixes (m):
/// city reflections reach 70 m, so 100 m each.
pub const SLACK_M: f64 = 200.0;

/// How many fixes back a fix looks for the one before it on the chain: a
/// run of blunders longer than this splits the ride into chains, of which
/// the longest is kept.
const LOOK_BACK: usize = 256;

/// How far the vehicle must move (m, by its distance signal) across a run
/// of fixes equal to the bit for the run to be a receiver's stale repeats:
/// more than a fix written with four decimals of a degree moves between
/// roundings (11 m north, less east: 13.4 m on the diagonal) and a receiver's
/// static hold, which freezes the fix of a vehicle crawling at walking pace
/// for a few metres.
pub const STALE_MOVED_M: f64 = 20.0;

/// The fixes of a ride that are left out: a logger's held repeats, then blunders.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Blunders {
    /// Rows of the log whose fix is left out, ascending.
    pub rows: Vec<usize>,
    /// How many of them are a logger's held repeats of the fix before (see [`held`]).
    pub held: usize,
    /// How many of them are a receiver's stale repeats while the vehicle
    /// moves (see [`stale`]).
    pub stale: usize,
    /// The longest run of stale repeats: its first and last repeat's rows
    /// and how far the vehicle moved from the run's first fix (m).
    pub stale_longest: Option<(usize, usize, f64)>,
    /// How many rows of the log have a fix, before any is left out.
    pub logged: usize,
    /// How many of the blunders are at `0, 0`.
    pub null_island: usize,
    /// The farthest of the other blunders from the nearest kept fix in time (m).
    pub farthest_m: f64,
    /// The row of the first blunder (not a held repeat).
    pub first: Option<usize>,
}

impl Blunders {
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Whether the fix on `row` is left out.
    pub fn contains(&self, row: usize) -> bool {
        self.rows.binary_search(&row).is_ok()
    }

    /// What a user is told, naming the first blunder's line and time; `None`
    /// when nothing is left out.
    pub fn describe(&self, file: &str, line: &[u64], t: &[f64]) -> Option<String> {
        let said = self.sentences(line, t);
        (!said.is_empty()).then(|| format!("{file}: {}", said.join("; ")))
    }

    /// What [`Blunders::describe`] says, one clause per kind, without the file.
    pub fn sentences(&self, line: &[u64], t: &[f64]) -> Vec<String> {
        let mut said = Vec::new();
        if self.held > 0 {
            said.push(format!(
                "the GPS fix on {} of the {} rows that have one repeats the one before (a logger that writes its last fix on every row, or faster than the receiver makes them): only the {} rows where it changes are fixes",
                self.held,
                self.logged,
                self.logged - self.held
            ));
        }
        if let Some((a, b, moved)) = self.stale_longest.filter(|_| self.stale > 0) {
            let at = |row: usize| {
                (
                    line.get(row).copied().unwrap_or(row as u64 + 1),
                    t.get(row).copied().unwrap_or(f64::NAN),
                )
            };
            let ((line_a, t_a), (_, t_b)) = (at(a), at(b));
            said.push(format!(
                "{} GPS fix{} repeat{} the fix before to the bit while the vehicle moves on (the longest run from line {line_a}, t = {t_a:.2} s to {t_b:.2} s, over {moved:.0} m of distance): a receiver that lost its fix and wrote its last one again; they are left out, as an outage",
                self.stale,
                if self.stale == 1 { "" } else { "es" },
                if self.stale == 1 { "s" } else { "" },
            ));
        }
        let n = self.rows.len() - self.held - self.stale;
        if let Some(first) = self.first.filter(|_| n > 0) {
            let far = n - self.null_island;
            let mut what = Vec::new();
            if self.null_island > 0 {
                what.push(format!(
                    "{} at 0, 0 (a receiver's placeholder while it has no fix)",
                    self.null_island
                ));
            }
            if far > 0 {
                what.push(format!(
                    "{far} up to {:.1} km off the track, farther than {V_MAX_MPS:.0} m/s moves between fixes",
                    self.farthest_m / 1000.0
                ));
            }
            said.push(format!(
                "{n} GPS fix{} left out as blunder{}: {} (the first on line {}, t = {:.2} s)",
                if n == 1 { "" } else { "es" },
                if n == 1 { "" } else { "s" },
                what.join("; "),
                line.get(first).copied().unwrap_or(first as u64 + 1),
                t.get(first).copied().unwrap_or(f64::NAN),
            ));
        }
        said
    }
}

/// Rows whose fix is a logger's held repeat: those equal to the fix before
/// them (to the bit), when at least [`HELD_SHARE`] of the fixes are (a
/// receiver repeats a fix now and then, a logger that writes its last one
/// faster than the receiver makes them does so on every row between two:
/// nearly always at the gyro's rate, on half the rows at twice the
/// receiver's); none otherwise, nor when the fix never changes (a ride that
/// never moves: the fit then says its heading is unobservable).
pub fn held(fix: &[Option<(f64, f64)>]) -> Vec<usize> {
    let mut logged = 0usize;
    let mut repeats = Vec::new();
    let mut before: Option<(u64, u64)> = None;
    for (row, f) in fix.iter().enumerate() {
        if let Some((lat, lon)) = *f {
            logged += 1;
            let bits = (lat.to_bits(), lon.to_bits());
            if before == Some(bits) {
                repeats.push(row);
            }
            before = Some(bits);
        }
    }
    if repeats.len() as f64 >= HELD_SHARE * logged as f64 && logged - repeats.len() >= 2 {
        repeats
    } else {
        Vec::new()
    }
}

/// The share of a log's fixes that repeat the one before them to the bit
/// above which all repeats are a logger's (see [`held`]). A 1 Hz receiver
/// logged at 2 Hz repeats every other fix, half a second late: read as
/// fixes, the comma drive logged so ended 5.74 m from its reference
/// instead of 1.25 m (its noise search at "correlated over at most 0 s"),
/// reported as a success. A receiver repeats far less (the Husky robot's
/// 7 of 988 while it stood), and where a stop-and-go ride's receiver holds
/// its fix through every stand, leaving those out costs nothing: the
/// stand's first fix stays, and the odometer says the rest.
pub const HELD_SHARE: f64 = 0.25;

/// Runs of a receiver's stale repeats among the fixes `fix` (by row; the
/// rows in `skip`, a logger's held repeats, passed over), by the per-step
/// distance `step_m` (negative reversing): each run as the rows of its
/// repeats (not its first fix, which the receiver had) and how far the
/// vehicle moved from the first fix by the last repeat (m). A run is the
/// fixes equal to the bit to the one before them; it is stale when the
/// distance moves more than [`STALE_MOVED_M`] between its first fix and
/// any repeat.
pub fn stale(fix: &[Option<(f64, f64)>], skip: &[usize], step_m: &[f64]) -> Vec<(Vec<usize>, f64)> {
    /// The run so far: its first fix's bits and the distance there, its
    /// repeats, and how far the vehicle has moved from its first fix.
    struct Run {
        bits: (u64, u64),
        from: f64,
        repeats: Vec<usize>,
        moved: f64,
    }
    let mut runs = Vec::new();
    let mut close = |run: Option<Run>| {
        if let Some(r) = run.filter(|r| r.moved > STALE_MOVED_M) {
            runs.push((r.repeats, r.moved));
        }
    };
    // The distance travelled through each row's step, summed as the rows
    // are passed (no table of the ride's length).
    let mut travelled = 0.0;
    let mut run: Option<Run> = None;
    let mut skipped = skip.iter().peekable();
    for (row, f) in fix.iter().enumerate() {
        travelled += step_m
            .get(row)
            .copied()
            .filter(|d| d.is_finite())
            .unwrap_or(0.0);
        let Some((lat, lon)) = *f else { continue };
        if skipped.next_if_eq(&&row).is_some() {
            continue;
        }
        let bits = (lat.to_bits(), lon.to_bits());
        match &mut run {
            Some(r) if r.bits == bits => {
                r.repeats.push(row);
                r.moved = r.moved.max((travelled - r.from).abs());
            }
            _ => close(run.replace(Run {
                bits,
                from: travelled,
                repeats: Vec::new(),
                moved: 0.0,
            })),
        }
    }
    close(run);
    runs
}

/// A fix as the screen sees it: its row, time, east and north (m) in the
/// local frame at the fixes' median and its own accuracy (m, 0 when not
/// logged).
struct Point {
    row: usize,
    t: f64,
    xy: [f64; 2],
    hacc: f64,
}

/// Whether `b` is reachable from `a` (see the module's bound).
fn reachable(a: &Point, b: &Point) -> bool {
    let d = (b.xy[0] - a.xy[0]).hypot(b.xy[1] - a.xy[1]);
    d <= V_MAX_MPS * (b.t - a.t).abs() + SLACK_M + 3.0 * (a.hacc + b.hacc)
}

/// The blunders among the fixes `fix` (by row, `None` where a row has none)
/// at times `t`, with the receiver's accuracy `hacc` where logged, and the
/// stale repeats (see [`stale`]) where the log has a distance (`step_m`,
/// per step).
pub fn find(
    t: &[f64],
    fix: &[Option<(f64, f64)>],
    hacc: Option<&[Option<f64>]>,
    step_m: Option<&[f64]>,
) -> Blunders {
    let mut repeat_rows = held(fix);
    let stale_runs = step_m.map_or_else(Vec::new, |d| stale(fix, &repeat_rows, d));
    let stale_longest = stale_runs
        .iter()
        .max_by_key(|(rows, _)| rows.len())
        .and_then(|(rows, moved)| Some((*rows.first()?, *rows.last()?, *moved)));
    let stale_count: usize = stale_runs.iter().map(|(rows, _)| rows.len()).sum();
    let held = repeat_rows.len();
    repeat_rows.extend(stale_runs.into_iter().flat_map(|(rows, _)| rows));
    repeat_rows.sort_unstable();
    let is_null = |lat: f64, lon: f64| lat.abs() < 1e-9 && lon.abs() < 1e-9;
    let mut null_rows = Vec::new();
    let mut raw = Vec::new();
    let mut logged = 0;
    let mut next_held = repeat_rows.iter().peekable();
    for (row, f) in fix.iter().enumerate() {
        if let Some((lat, lon)) = *f {
            logged += 1;
            if next_held.next_if_eq(&&row).is_some() {
                continue;
            }
            if is_null(lat, lon) {
                null_rows.push(row);
            } else {
                raw.push((row, lat, lon));
            }
        }
    }
    // East and north in the local frame at the fixes' median: the median
    // stands among the good fixes however far the blunders are.
    let median_of = |coordinate: fn(&(usize, f64, f64)) -> f64| {
        let mut values: Vec<f64> = raw.iter().map(coordinate).collect();
        median(&mut values)
    };
    let (lat0, lon0) = (median_of(|p| p.1), median_of(|p| p.2));
    let frame = LocalFrame::new(Geodetic::new(lat0, lon0, 0.0));
    let points: Vec<Point> = raw
        .iter()
        .map(|&(row, lat, lon)| {
            let enu = frame.to_enu(&Geodetic::new(lat, lon, 0.0));
            Point {
                row,
                t: t.get(row).copied().unwrap_or(f64::NAN),
                xy: [enu.x, enu.y],
                hacc: hacc
                    .and_then(|h| h.get(row).copied().flatten())
                    .filter(|h| h.is_finite() && *h > 0.0)
                    .unwrap_or(0.0),
            }
        })
        .collect();
    let kept = longest_chain(&points);
    let mut rows = null_rows.clone();
    let mut farthest_m: f64 = 0.0;
    let mut k = 0;
    for (i, p) in points.iter().enumerate() {
        while k + 1 < kept.len() && kept[k + 1] <= i {
            k += 1;
        }
        if kept.get(k) == Some(&i) {
            continue;
        }
        rows.push(p.row);
        // The nearest kept fix in time, before or after.
        let near = [kept.get(k), kept.get(k + 1)]
            .into_iter()
            .flatten()
            .map(|&j| &points[j])
            .min_by(|a, b| (a.t - p.t).abs().total_cmp(&(b.t - p.t).abs()));
        if let Some(q) = near {
            farthest_m = farthest_m.max((p.xy[0] - q.xy[0]).hypot(p.xy[1] - q.xy[1]));
        }
    }
    let first = rows.iter().copied().min();
    rows.extend(repeat_rows);
    rows.sort_unstable();
    Blunders {
        rows,
        held,
        stale: stale_count,
        stale_longest,
        logged,
        null_island: null_rows.len(),
        farthest_m,
        first,
    }
}

/// Indices (ascending) of the longest chain of `points` in which each is
/// [`reachable`] from the one before; all of them when every neighbour is
/// reachable from the last (the common case, one pass).
fn longest_chain(points: &[Point]) -> Vec<usize> {
    let n = points.len();
    if points.windows(2).all(|w| reachable(&w[0], &w[1])) {
        return (0..n).collect();
    }
    // length[j]: the longest chain ending at j; before[j]: its previous fix.
    let mut length = vec![1usize; n];
    let mut before = vec![usize::MAX; n];
    for j in 0..n {
        for i in j.saturating_sub(LOOK_BACK)..j {
            if length[i] + 1 > length[j] && reachable(&points[i], &points[j]) {
                length[j] = length[i] + 1;
                before[j] = i;
            }
        }
    }
    let Some(mut j) = (0..n).max_by_key(|&j| (length[j], std::cmp::Reverse(j))) else {
        return Vec::new();
    };
    let mut chain = vec![j];
    while before[j] != usize::MAX {
        j = before[j];
        chain.push(j);
    }
    chain.reverse();
    chain
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight ride east at 10 m/s with a fix a second, near Budapest.
    fn ride(n: usize) -> (Vec<f64>, Vec<Option<(f64, f64)>>) {
        let t: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let fix = t
            .iter()
            .map(|&s| {
                Some((
                    47.5,
                    19.05 + 10.0 * s / (111_320.0 * 47.5f64.to_radians().cos()),
                ))
            })
            .collect();
        (t, fix)
    }

    #[test]
    fn a_clean_ride_has_no_blunder() {
        let (t, fix) = ride(300);
        assert!(find(&t, &fix, None, None).is_empty());
    }

    #[test]
    fn null_island_a_wild_fix_and_a_run_are_found_and_nothing_else() {
        let (t, mut fix) = ride(300);
        fix[0] = Some((0.0, 0.0));
        fix[50] = Some((0.0, 0.0));
        // 1.1 km north for one fix.
        fix[100] = fix[100].map(|(la, lo)| (la + 0.01, lo));
        // 3.3 km south for five fixes in a row.
        for f in &mut fix[200..205] {
            *f = f.map(|(la, lo)| (la - 0.03, lo));
        }
        // A 70 m reflection is the robust loss's, not a blunder.
        fix[250] = fix[250].map(|(la, lo)| (la + 70.0 / 111_320.0, lo));
        let b = find(&t, &fix, None, None);
        assert_eq!(b.rows, vec![0, 50, 100, 200, 201, 202, 203, 204]);
        assert_eq!(b.null_island, 2);
        assert!((b.farthest_m - 3340.0).abs() < 30.0, "{}", b.farthest_m);
        let line: Vec<u64> = (0..300).map(|k| k + 5).collect();
        let text = b.describe("ride.csv", &line, &t).unwrap_or_default();
        assert!(
            text.contains("8 GPS fixes left out")
                && text.contains("2 at 0, 0")
                && text.contains("6 up to 3.3 km")
                && text.contains("line 5, t = 0.00 s"),
            "{text}"
        );
    }

    #[test]
    fn a_loggers_held_fix_is_one_fix_a_receivers_repeats_stay() {
        // Ten rows a second, each fix held until the next.
        let (t, fix) = ride(30);
        let rows_t: Vec<f64> = (0..300).map(|k| k as f64 / 10.0).collect();
        let mut held_fix: Vec<_> = (0..300).map(|k| fix[k / 10]).collect();
        let b = find(&rows_t, &held_fix, None, None);
        assert_eq!(b.held, 270);
        assert_eq!(b.rows.len(), 270);
        assert!((0..300).all(|k| b.contains(k) != (k % 10 == 0)));
        let text = b.describe("log.csv", &[], &rows_t).unwrap_or_default();
        assert_eq!(
            text,
            "log.csv: the GPS fix on 270 of the 300 rows that have one repeats the one before (a logger that writes its last fix on every row, or faster than the receiver makes them): only the 30 rows where it changes are fixes"
        );
        // And a blunder among them is still one.
        for f in &mut held_fix[150..160] {
            *f = Some((0.0, 0.0));
        }
        let b = find(&rows_t, &held_fix, None, None);
        assert_eq!((b.held, b.null_island, b.first), (270, 1, Some(150)));
        // A receiver that repeats a fix now and then keeps its repeats.
        let mut fix = fix;
        fix[5] = fix[4];
        fix[6] = fix[4];
        assert!(find(&t, &fix, None, None).is_empty());
        // A 1 Hz receiver logged at 2 Hz: every other fix a repeat, all of
        // them a logger's; one in five (a receiver through its stands) not.
        let rows_t: Vec<f64> = (0..60).map(|k| k as f64 / 2.0).collect();
        let (_, one_hz) = ride(30);
        let twice: Vec<_> = (0..60).map(|k| one_hz[k / 2]).collect();
        let b = find(&rows_t, &twice, None, None);
        assert_eq!(b.held, 30);
        let (t, mut fix) = ride(50);
        for k in (0..50).step_by(5) {
            fix[k + 1] = fix[k];
        }
        assert!(find(&t, &fix, None, None).is_empty());
    }

    /// A receiver that lost its fix and wrote its last one again for ten
    /// seconds while the car drove on 10 m/s: the ten repeats are left out
    /// and said, the fix it had kept; the same repeats while the car stands,
    /// or while it crawls under [`STALE_MOVED_M`], are the receiver's and stay.
    #[test]
    fn a_receivers_stale_fixes_while_moving_are_left_out() {
        let (t, mut fix) = ride(100);
        for k in 41..=50 {
            fix[k] = fix[40];
        }
        let step = vec![10.0; 100];
        let b = find(&t, &fix, None, Some(&step));
        assert_eq!(b.rows, (41..=50).collect::<Vec<_>>());
        assert_eq!((b.stale, b.held, b.first), (10, 0, None));
        let (first, last, moved) = b.stale_longest.unwrap_or_default();
        assert_eq!((first, last), (41, 50));
        assert!((moved - 100.0).abs() < 1e-9, "{moved}");
        let line: Vec<u64> = (0..100).map(|k| k + 3).collect();
        assert_eq!(
            b.describe("ride.csv", &line, &t).unwrap_or_default(),
            "ride.csv: 10 GPS fixes repeat the fix before to the bit while the vehicle moves on (the longest run from line 44, t = 41.00 s to 50.00 s, over 100 m of distance): a receiver that lost its fix and wrote its last one again; they are left out, as an outage"
        );
        // Without a distance the repeats cannot be told from a stand.
        assert!(find(&t, &fix, None, None).is_empty());
        // Standing through them, or crawling 18 m, they stay.
        let mut standing = step.clone();
        standing[41..=50].fill(0.0);
        assert!(find(&t, &fix, None, Some(&standing)).is_empty());
        standing[41..=50].fill(1.8);
        assert!(find(&t, &fix, None, Some(&standing)).is_empty());
        // Reversing counts as moving.
        standing[41..=50].fill(-2.5);
        assert_eq!(find(&t, &fix, None, Some(&standing)).stale, 10);
        // Two runs, and a blunder beside them.
        fix[80] = Some((0.0, 0.0));
        fix[91] = fix[90];
        fix[92] = fix[90];
        fix[93] = fix[90];
        let b = find(&t, &fix, None, Some(&step));
        assert_eq!((b.stale, b.null_island, b.first), (13, 1, Some(80)));
        assert_eq!(b.rows.len(), 14);
        let text = b.describe("ride.csv", &line, &t).unwrap_or_default();
        assert!(
            text.contains("13 GPS fixes repeat") && text.contains("1 GPS fix left out as blunder"),
            "{text}"
        );
    }

    /// A logger that writes the last fix on every row, behind a receiver
    /// that holds its fix: the held rows are one fix each as before, and the
    /// receiver's stale seconds among what changes are then no change at all
    /// (an outage already).
    #[test]
    fn stale_fixes_behind_a_loggers_held_fix_are_an_outage() {
        let (_, mut fix) = ride(30);
        for k in 11..=15 {
            fix[k] = fix[10];
        }
        let rows_t: Vec<f64> = (0..300).map(|k| k as f64 / 10.0).collect();
        let held_fix: Vec<_> = (0..300).map(|k| fix[k / 10]).collect();
        let step = vec![1.0; 300];
        let b = find(&rows_t, &held_fix, None, Some(&step));
        assert_eq!((b.held, b.stale), (275, 0));
        assert!((0..300).all(|k| b.contains(k) != (k % 10 == 0 && !(110..=150).contains(&k))));
    }

    #[test]
    fn a_wrong_first_fix_is_left_out_not_the_ride() {
        let (t, mut fix) = ride(100);
        fix[0] = fix[0].map(|(la, lo)| (la + 0.5, lo + 0.5));
        assert_eq!(find(&t, &fix, None, None).rows, vec![0]);
    }

    #[test]
    fn a_fast_car_and_a_long_outage_are_not_blunders() {
        // 90 m/s, then a 10-minute outage after which the car is 30 km on.
        let n = 120;
        let t: Vec<f64> = (0..n)
            .map(|k| if k < 60 { k as f64 } else { k as f64 + 600.0 })
            .collect();
        let fix: Vec<_> = t
            .iter()
            .map(|&s| Some((47.5 + 50.0 * s / 111_320.0, 19.05)))
            .collect();
        assert!(find(&t, &fix, None, None).is_empty());
    }

    #[test]
    fn a_fix_the_receiver_calls_poor_is_not_a_blunder() {
        let (t, mut fix) = ride(100);
        fix[40] = fix[40].map(|(la, lo)| (la + 500.0 / 111_320.0, lo));
        assert_eq!(find(&t, &fix, None, None).rows, vec![40]);
        let mut hacc = vec![Some(3.0); 100];
        hacc[40] = Some(200.0);
        assert!(find(&t, &fix, Some(&hacc), None).is_empty());
    }

    #[test]
    fn blunders_across_the_date_line_are_measured_the_short_way() {
        let t: Vec<f64> = (0..50).map(f64::from).collect();
        let mut fix: Vec<_> = t
            .iter()
            .map(|&s| {
                Some((
                    10.0,
                    179.9999 + 5.0 * s / 111_000.0 - if s > 10.0 { 360.0 } else { 0.0 },
                ))
            })
            .collect();
        assert!(find(&t, &fix, None, None).is_empty());
        fix[30] = fix[30].map(|(la, lo)| (la, lo + 0.1));
        assert_eq!(find(&t, &fix, None, None).rows, vec![30]);
    }
}
