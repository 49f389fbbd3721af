//! The GPS track against the odometer: per-fix summaries of the log, course
//! stretches, the odometer's scale and sign, the GPS altitude.

use super::*;
use crate::blunders::Blunders;

/// Course stretches at least this long (m) along the odometer: GPS noise of a
/// few metres then moves a course by a few degrees, not tens.
pub(super) const STRETCH_M: f64 = 15.0;

/// Per-fix summaries: everything the checks need, O(fixes) in memory.
#[derive(Clone)]
pub(super) struct AtFix {
    pub(super) t: f64,
    pub(super) en: [f64; 2],
    pub(super) alt: Option<f64>,
    /// Odometer distance from the start (m).
    pub(super) s: f64,
    /// Integrated gyro per logged axis (units as labelled x s).
    pub(super) turn: [f64; 3],
    /// Mean acceleration since the previous fix, per logged axis.
    pub(super) acc: Option<[f64; 3]>,
    /// Time (s) the log lost its rows before this fix, in gaps longer than
    /// [`crate::log_gaps::MIN_GAP_S`] (and, see [`with_turns_lost`], where
    /// the sensor turned without the vehicle): how the vehicle turned across
    /// them the gyro does not tell (the fit bridges them).
    pub(super) lost_s: f64,
}

/// The `fixes` of `log` (see [`local_fixes`]), with what happened between
/// them (`dist`: the odometer's distance per step, zero where it has none).
pub(super) fn summarise(
    log: &RideLog,
    fixes: &[crate::reversing::RowFix],
    dist: &[f64],
) -> Vec<AtFix> {
    let mut s = 0.0;
    let mut turn = [0.0; 3];
    let mut lost_s = 0.0;
    let mut acc_sum = [0.0; 3];
    let mut acc_n = 0usize;
    let mut out = Vec::with_capacity(fixes.len());
    let mut next = fixes.iter().peekable();
    for j in 0..log.len() {
        if j > 0 {
            let dt = log.t_s[j] - log.t_s[j - 1];
            s += dist[j];
            if dt > crate::log_gaps::MIN_GAP_S {
                lost_s += dt;
            }
            for a in 0..3 {
                turn[a] += log.gyro_dps[j][a] * dt;
            }
        }
        if let Some(Some(acc)) = log.accel_mps2.as_ref().map(|v| v[j]) {
            for a in 0..3 {
                acc_sum[a] += acc[a];
            }
            acc_n += 1;
        }
        if let Some(&(_, en)) = next.next_if(|f| f.0 == j) {
            out.push(AtFix {
                t: log.t_s[j],
                en,
                alt: log.gps_alt_m.as_ref().and_then(|a| a[j]),
                s,
                turn,
                lost_s,
                acc: (acc_n > 0).then(|| acc_sum.map(|x| x / acc_n as f64)),
            });
            acc_sum = [0.0; 3];
            acc_n = 0;
        }
    }
    out
}

/// `fixes` with the time the sensor turned without the vehicle (`turns`,
/// from fix to fix) counted as lost too, up to each fix: across it the gyro
/// does not tell how the vehicle turned, as across a gap in the log.
pub(super) fn with_turns_lost(
    fixes: &[AtFix],
    turns: &[crate::sensor_turns::SensorTurn],
) -> Vec<AtFix> {
    fixes
        .iter()
        .map(|f| AtFix {
            lost_s: f.lost_s
                + turns
                    .iter()
                    .map(|s| (f.t.min(s.to_s) - s.from_s).max(0.0))
                    .sum::<f64>(),
            ..f.clone()
        })
        .collect()
}

/// Stretches of the track (see [`stretches`]).
pub(super) struct Stretches {
    /// Indices of the fixes that start and end them.
    pub(super) idx: Vec<usize>,
    /// Their length along the road (m).
    pub(super) length_m: f64,
    /// The odometer's units per metre of road they were set by; `None`
    /// where they were set along the GPS track (the odometer stands).
    pub(super) odometer_per_m: Option<f64>,
}

impl Stretches {
    /// The course (deg, anticlockwise from east) of the chord from fix `a`
    /// to fix `b`, where it is a straight line: no shorter than half the
    /// road the odometer measured along it (set along the GPS track, every
    /// chord is taken). A straight chord's course is the heading halfway
    /// along.
    pub(super) fn course(&self, a: &AtFix, b: &AtFix) -> Option<f64> {
        let (de, dn) = (b.en[0] - a.en[0], b.en[1] - a.en[1]);
        let curved = self
            .odometer_per_m
            .is_some_and(|per_m| de.hypot(dn) < 0.5 * (b.s - a.s) / per_m);
        (!curved).then(|| dn.atan2(de).to_degrees())
    }
}

/// Stretches of the track: fixes at least [`stretch_m`] apart along the
/// odometer.
///
/// The odometer is what sets them (the GPS track is lengthened by its own
/// scatter), unless its units are wrong: a distance in km took every fix
/// into one stretch of a 1.9 km drive, and the checks read "the GPS track
/// is only 0 m long" and "no straight stretch" on it; in feet they read
/// 2.6 m of odometer per GPS m, over stretches of 17 m of road. Where the
/// odometer measures the stretches' track outside [`ODOMETER_OK`], they
/// are set along the GPS track, and then again along the odometer at that
/// length of road (the length times the odometer's units per GPS metre)
/// where the odometer moves at all.
pub(super) fn stretches(fixes: &[AtFix]) -> Stretches {
    let length_m = stretch_m(fixes);
    let idx = stretches_of(fixes, length_m);
    let (odo, gps) = over_stretches(fixes, &idx);
    let moved = fixes.last().map_or(0.0, |f| f.s);
    if moved < 0.0 || (gps >= MIN_TRACK_M && ODOMETER_OK.contains(&(odo / gps))) {
        return Stretches {
            idx,
            length_m,
            odometer_per_m: Some(1.0),
        };
    }
    let along = stretches_along_track(fixes, length_m);
    let (odo, gps) = over_stretches(fixes, &along);
    let ratio = odo / gps;
    if gps >= MIN_TRACK_M && ratio >= MIN_MOVING_RATIO {
        Stretches {
            idx: stretches_of(fixes, length_m * ratio),
            length_m,
            odometer_per_m: Some(ratio),
        }
    } else {
        Stretches {
            idx: along,
            length_m,
            odometer_per_m: None,
        }
    }
}

/// The odometer's distance and the GPS track's over the stretches `idx`.
fn over_stretches(fixes: &[AtFix], idx: &[usize]) -> (f64, f64) {
    let (mut odo, mut gps) = (0.0, 0.0);
    for w in idx.windows(2) {
        let (a, b) = (&fixes[w[0]], &fixes[w[1]]);
        odo += b.s - a.s;
        gps += chord_m(a, b);
    }
    (odo, gps)
}

/// The straight line from fix `a` to fix `b` (m).
fn chord_m(a: &AtFix, b: &AtFix) -> f64 {
    (b.en[0] - a.en[0]).hypot(b.en[1] - a.en[1])
}

/// Indices of fixes at least `length` (m) apart along the GPS track (each
/// from the last one taken, in a straight line).
fn stretches_along_track(fixes: &[AtFix], length: f64) -> Vec<usize> {
    stretches_by(fixes, length, chord_m)
}

/// Indices of fixes at least `length` apart by `apart(from, to)`, each from
/// the last one taken, the first fix first.
fn stretches_by(fixes: &[AtFix], length: f64, apart: impl Fn(&AtFix, &AtFix) -> f64) -> Vec<usize> {
    let mut idx: Vec<usize> = Vec::new();
    for (k, f) in fixes.iter().enumerate() {
        if idx.last().is_none_or(|&i| apart(&fixes[i], f) >= length) {
            idx.push(k);
        }
    }
    idx
}

/// Odometer metres per GPS metre that a wheel's circumference or a CAN
/// scale explains.
const ODOMETER_OK: std::ops::RangeInclusive<f64> = 0.85..=1.15;

/// Shortest GPS track (m) over the stretches whose length the odometer is checked against.
const MIN_TRACK_M: f64 = 50.0;

/// Below this many odometer units per GPS metre the odometer is taken to
/// stand still (km give 0.001, miles 0.0006).
const MIN_MOVING_RATIO: f64 = 1e-4;

/// Below this many odometer metres per GPS metre, and no unit confusion
/// named, the odometer is said to stand while the vehicle moves.
const STANDING_RATIO: f64 = 0.01;

/// How long a stretch of GPS track must be to read the road rather than
/// the fixes' noise: [`STRETCH_M`], or [`STRETCH_PER_SCATTER`] times the
/// fixes' own scatter `s` where that is longer. A chord `L` between two
/// fixes reads about `sqrt(L^2 + 2 s^2)` long (see [`STRETCH_PER_SCATTER`])
/// and points up to `sqrt(2) s / L` rad off: Berlin's city fixes (a
/// scatter of metres to tens) made 15 m chords' courses noise, and the
/// course check warned that no gyro axis followed the GPS course (best
/// R^2 0.05) where the one axis the car logs is its yaw rate. At
/// `L = 10 s` a chord's course is some 8 deg off, a turn between two
/// chords some 11 deg.
pub(super) fn stretch_m(fixes: &[AtFix]) -> f64 {
    STRETCH_M.max(STRETCH_PER_SCATTER * scatter_m(fixes))
}

/// The fixes' own scatter (m; 0 where it cannot be told), see
/// [`crate::statistics::track_scatter_m`].
fn scatter_m(fixes: &[AtFix]) -> f64 {
    let t: Vec<f64> = fixes.iter().map(|f| f.t).collect();
    let en: Vec<[f64; 2]> = fixes.iter().map(|f| f.en).collect();
    crate::statistics::track_scatter_m(&t, &en).unwrap_or(0.0)
}

/// Indices of fixes at least `length` (m) apart along the odometer.
fn stretches_of(fixes: &[AtFix], length: f64) -> Vec<usize> {
    stretches_by(fixes, length, |a, b| b.s - a.s)
}

/// Stretches for the odometer and course checks are at least this many
/// times the fixes' own scatter long (see [`stretch_m`]): a chord `L`
/// between two fixes with errors of scatter `s`
/// reads about `sqrt(L^2 + 2 s^2)`, so city fixes 10-20 m off made 15 m
/// stretches of GPS track 40 % longer than the road (Berlin read 0.728 m of
/// odometer per GPS m); at `L = 10 s` the excess is 1 %.
pub(super) const STRETCH_PER_SCATTER: f64 = 10.0;

/// Fewest stretches whose median [`odometer_scale`] takes; fewer, the
/// ratio of the sums.
const MEDIAN_STRETCHES: usize = 3;

/// The median over the stretches `idx` of each one's odometer distance per
/// metre of its chord, and how many chords it took; `None` with fewer than
/// [`MEDIAN_STRETCHES`].
///
/// A wrong unit scales every stretch alike; a reflected or wandering fix
/// lengthens the one or two chords that end on it, by up to its error. The
/// ratio of the sums took those chords' metres at full weight: a robot
/// crawling at 0.6 m/s under urban fixes (simulated, seed 8, 300 s) read
/// 0.523 m per GPS metre over 9 m stretches and was told its speed was in
/// knots (PROBLEM). Over 322 simulated rides with a right odometer the
/// sums named a unit on 6 and warned on 33, the median on none and 17; on
/// 180 with the speed written in km/h, m/s as km/h or knots (the car and
/// robot rides of the sweeps) the sums named the unit on 120 and passed
/// 5 as right, the median 131 and 1.
fn median_ratio(fixes: &[AtFix], idx: &[usize]) -> Option<(f64, usize)> {
    let each: Vec<f64> = idx
        .windows(2)
        .filter_map(|w| {
            let (a, b) = (&fixes[w[0]], &fixes[w[1]]);
            let chord = chord_m(a, b);
            (chord > 0.0).then(|| (b.s - a.s) / chord)
        })
        .collect();
    (each.len() >= MEDIAN_STRETCHES)
        .then(|| (crate::statistics::median_of_finite(&each), each.len()))
}

/// Odometer distance against the GPS track length, over the stretches
/// `idx` (see [`stretches`]) that moved: the median of the stretches'
/// ratios ([`median_ratio`]).
pub(super) fn odometer_scale(fixes: &[AtFix], idx: &[usize], report: &mut CheckReport) {
    let (odo, gps) = over_stretches(fixes, idx);
    let total_odo = fixes.last().map_or(0.0, |f| f.s);
    if total_odo < 0.0 && total_odo.abs() > 10.0 {
        report.say(
            "odometer",
            Level::Problem,
            format!(
                "the odometer runs backwards ({total_odo:.0} m in all) while the GPS moves: its sign is flipped"
            ),
        );
        return;
    }
    if gps < MIN_TRACK_M {
        report.say(
            "odometer",
            Level::Info,
            format!("scale not checked: the GPS track is only {gps:.0} m long"),
        );
        return;
    }
    let (ratio, over) = match median_ratio(fixes, idx) {
        Some((r, n)) => (r, format!("the median over {n} stretches; ")),
        None => (odo / gps, String::new()),
    };
    report.odometer_per_gps = Some(ratio);
    let (level, note) = if ODOMETER_OK.contains(&ratio) {
        (Level::Ok, String::new())
    } else if ratio < STANDING_RATIO {
        (
            Level::Problem,
            match crate::limits::distance_units(1.0 / ratio) {
                Some(units) => format!(": {units}"),
                None => ": the odometer stands while the vehicle moves (a wheel sensor without a signal, or a column that is not the distance)".into(),
            },
        )
    } else if let Some(units) = crate::limits::distance_units(1.0 / ratio) {
        (Level::Problem, format!(": {units}"))
    } else {
        (
            Level::Warning,
            ": more than a wrong circumference explains; check the odometer's units".into(),
        )
    };
    report.say(
        "odometer",
        level,
        format!(
            "it measures {ratio:.digits$} m per metre of GPS track ({over}{odo:.odo_digits$} m against {gps:.0} m in all){note}",
            digits = if ratio.abs() < 0.01 { 6 } else { 3 },
            odo_digits = if odo.abs() < 10.0 { 3 } else { 0 }
        ),
    );
}

/// Fixes written in radians: every latitude within +-pi/2 and longitude
/// within +-pi (read as degrees, a spot in the Gulf of Guinea), and a track
/// that the odometer measures [`RADIANS_ODOMETER_RATIO`] times as long or
/// more (in radians a fix moves 57.3 times less than the vehicle north, and
/// less still east as read at that latitude; 46 times on a winding ride).
pub(super) fn gps_units(log: &RideLog, fixes: &[AtFix], report: &mut CheckReport) {
    let radian_range = log.fix.iter().flatten().all(|&(lat, lon)| {
        lat.abs() <= std::f64::consts::FRAC_PI_2 && lon.abs() <= std::f64::consts::PI
    });
    let track: f64 = fixes
        .windows(2)
        .map(|w| (w[1].en[0] - w[0].en[0]).hypot(w[1].en[1] - w[0].en[1]))
        .sum();
    let odometer = fixes.last().map_or(0.0, |f| f.s);
    if radian_range && odometer > 200.0 && odometer > RADIANS_ODOMETER_RATIO * track {
        report.say(
            "GPS units",
            Level::Problem,
            format!(
                "lat_deg and lon_deg look like radians: every fix is within +-1.571 and +-3.142, and the fixes move {track:.0} m while the odometer measures {odometer:.0} m ({:.0} times as far); they must be degrees",
                odometer / track.max(1e-9)
            ),
        );
    }
}

/// See [`gps_units`]: a wrong circumference or even km/h for m/s is far less.
const RADIANS_ODOMETER_RATIO: f64 = 20.0;

/// The altitude's datum cannot be told from the data; a jump in it can.
pub(super) fn altitude(log: &RideLog, fixes: &[AtFix], report: &mut CheckReport) {
    if log.gps_alt_m.is_none() {
        return;
    }
    let jump = fixes
        .windows(2)
        .filter_map(|w| Some((w[1].t, (w[1].alt? - w[0].alt?).abs(), w[1].t - w[0].t)))
        .filter(|&(_, d, dt)| dt <= 2.0 && d > 15.0)
        .max_by(|a, b| a.1.total_cmp(&b.1));
    match jump {
        Some((t, d, _)) => report.say(
            "GPS altitude",
            Level::Warning,
            format!(
                "jumps by {d:.0} m at t = {t:.1} s: a datum switch or a bad fix; the vertical fit there is off"
            ),
        ),
        None => report.say(
            "GPS altitude",
            Level::Info,
            "above the WGS84 ellipsoid or above mean sea level (many receivers and ROS drivers write MSL) cannot be told from the data; the two differ by a constant (the geoid height, -106 to +85 m), which is harmless: gyropath uses altitudes relative to the first fix".into(),
        ),
    }
}

/// The receiver's own quality fields, where logged: what the fixes' HDOP
/// and satellite counts say, and how the fit uses them (the HDOP weighs
/// each fix relative to the ride's median where no accuracy is logged).
/// A fix from fewer than 5 satellites has no redundancy: the receiver can
/// neither detect nor leave out a reflected signal, so a ride with many
/// such fixes is warned of.
pub(super) fn quality(log: &RideLog, report: &mut CheckReport) {
    let at_fixes = |c: &Option<Vec<Option<f64>>>| -> Vec<f64> {
        c.as_ref().map_or_else(Vec::new, |v| {
            v.iter()
                .zip(&log.fix)
                .filter_map(|(x, f)| f.and(*x))
                .collect()
        })
    };
    let (hdop, sats) = (at_fixes(&log.gps_hdop), at_fixes(&log.gps_num_sats));
    let q = |v: &[f64], p: f64| crate::statistics::quantile(&mut v.to_vec(), p);
    let mut parts = Vec::new();
    if !hdop.is_empty() {
        let used = if log.gps_hacc_m.is_some() {
            "the logged accuracy weighs the fixes"
        } else {
            "each fix is weighted by it relative to the median"
        };
        parts.push(format!(
            "HDOP {:.1} in the median, {:.1} at the 95th percentile ({used})",
            q(&hdop, 0.5),
            q(&hdop, 0.95)
        ));
    }
    let few = sats.iter().filter(|n| **n < 5.0).count();
    if !sats.is_empty() {
        let (low, high) = (q(&sats, 0.0), q(&sats, 1.0));
        parts.push(if low == high {
            format!("{low:.0} satellites")
        } else {
            format!(
                "{low:.0}-{high:.0} satellites, {:.0} in the median",
                q(&sats, 0.5)
            )
        });
    }
    if parts.is_empty() {
        return;
    }
    let share = few as f64 / sats.len().max(1) as f64;
    let (level, note) = if share > 0.2 {
        (
            Level::Warning,
            format!(
                "; {:.0} % of the fixes come from fewer than 5 satellites, with no redundancy to leave out a reflected signal: consider gps_outliers",
                100.0 * share
            ),
        )
    } else {
        (Level::Info, String::new())
    };
    report.say("GPS quality", level, format!("{}{note}", parts.join("; ")));
}

/// The usable fixes of `log` (not `blunders`) as their rows and east, north
/// (m) about the first.
pub(super) fn local_fixes(log: &RideLog, blunders: &Blunders) -> Vec<crate::reversing::RowFix> {
    let usable = |j: usize| log.fix[j].filter(|_| !blunders.contains(j));
    let Some(first) = (0..log.len()).find_map(usable) else {
        return Vec::new();
    };
    let frame = LocalFrame::new(Geodetic::new(first.0, first.1, 0.0));
    (0..log.len())
        .filter_map(|j| {
            let (lat, lon) = usable(j)?;
            let p = frame.to_enu(&Geodetic::new(lat, lon, 0.0));
            Some((j, [p.x, p.y]))
        })
        .collect()
}

/// What the fit's signals find of the vehicle's direction and the sensor's
/// own turns, about the log's z as they take it: the stretches the GPS
/// track says were driven backwards on a distance without a sign
/// ([`crate::reversing`], said; `distance` is signed after), and where the
/// sensor turned without the vehicle ([`crate::sensor_turns`]), for the
/// caller to say where z proves up.
pub(super) fn direction_and_turns(
    log: &RideLog,
    distance: &mut [f64],
    fixes: &[crate::reversing::RowFix],
    report: &mut CheckReport,
) -> Vec<crate::sensor_turns::SensorTurn> {
    let t = &log.t_s;
    let mut dt = vec![0.0; t.len()];
    for j in 1..t.len() {
        dt[j] = t[j] - t[j - 1];
    }
    let rate = |j: usize| log.gyro_dps[j][2].to_radians();
    let reversed = crate::reversing::find(t, &dt, rate, distance, fixes);
    crate::reversing::apply(distance, &reversed);
    if let Some(said) = crate::reversing::describe(&reversed) {
        report.say("direction", Level::Info, said);
    }
    crate::sensor_turns::find(t, &dt, rate, distance, fixes)
}
