//! Axes, units and datum checked against the data itself, on every load.
//!
//! A log's labels can lie (a phone's axes, a bag with no mounting, rad/s
//! written as deg/s); its physics cannot. Each check compares two things that
//! must agree on a moving vehicle:
//!
//! - **Vertical axis and its sign.** At rest and on average a vehicle is
//!   level, so the accelerometer's mean (specific force) points up with
//!   |g| = 9.8 m/s^2. Without an accelerometer: the GPS course turns with the
//!   yaw rate, so between consecutive stretches of the track
//!   `delta course = beta * integral(omega_a dt) + b dt`, fitted for each
//!   axis a (b absorbs a constant bias); the axis that explains the course
//!   (largest R^2) is vertical, the sign of beta its sign.
//! - **Gyro units.** On that axis beta is 1 when the gyro is in deg/s as
//!   labelled; 57.3 when rad/s were logged as deg/s (turns 57 times too
//!   small); 1/57.3 the other way round.
//! - **Forward axis.** The accelerometer along the forward axis follows the
//!   odometer's dv/dt; along the left axis it follows the centripetal
//!   acceleration v * omega_up. Of the four signed horizontal axes the one
//!   that best explains both is forward (left then completes a right-handed
//!   frame). Without an accelerometer forward cannot be told from the data;
//!   a wrong guess there is a turn about the vertical, which the fitted start
//!   heading absorbs.
//! - **Odometer scale and sign** against the GPS track length; a **saturated
//!   gyro** (rows pinned at the same extreme); **GPS altitude** datum and
//!   jumps; the **sample rate**.
//!
//! The checks read the log as it is, before any mounting; the recommended
//! mounting is what `--mount auto` applies.

use serde::Serialize;

use super::{Mount, RideLog};
use crate::geodesy::{Geodetic, LocalFrame};
use crate::statistics::pearson;

/// How much a verdict matters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum Level {
    /// Checked and fine.
    Ok,
    /// Worth knowing, nothing wrong.
    Info,
    /// Could not be checked, or something looks off.
    Warning,
    /// The data contradict the labels: results would be wrong.
    Problem,
}

impl Level {
    pub fn label(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Info => "info",
            Self::Warning => "warning",
            Self::Problem => "PROBLEM",
        }
    }
}

/// One finding.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Verdict {
    /// What was checked ("vertical axis", "gyro units", ...).
    pub subject: String,
    pub level: Level,
    pub message: String,
}

/// Which logged axis plays a role, with its sign and how strongly the data say so.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AxisFinding {
    /// Logged axis 0 x, 1 y, 2 z.
    pub axis: usize,
    pub sign: f64,
    /// Strength of the evidence: a correlation (course or accelerometer), or the cosine of the tilt.
    pub r: f64,
    /// What it was told by.
    pub by: &'static str,
}

/// Everything the checks found.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CheckReport {
    pub verdicts: Vec<Verdict>,
    /// The mounting that makes the log x forward, y left, z up in deg/s
    /// (`None` when the data cannot tell the vertical).
    #[serde(serialize_with = "as_text")]
    pub recommended: Option<Mount>,
    pub vertical: Option<AxisFinding>,
    pub forward: Option<AxisFinding>,
    /// GPS course turn per gyro turn on the vertical axis (1 for deg/s as labelled).
    pub course_per_gyro: Option<f64>,
    /// Odometer distance per GPS track length.
    pub odometer_per_gps: Option<f64>,
}

fn as_text<S: serde::Serializer>(m: &Option<Mount>, s: S) -> Result<S::Ok, S::Error> {
    match m {
        Some(m) => s.serialize_some(&m.to_string()),
        None => s.serialize_none(),
    }
}

impl CheckReport {
    fn say(&mut self, subject: &str, level: Level, message: String) {
        self.verdicts.push(Verdict {
            subject: subject.into(),
            level,
            message,
        });
    }

    /// The worst level found.
    pub fn worst(&self) -> Level {
        self.verdicts
            .iter()
            .map(|v| v.level)
            .max()
            .unwrap_or(Level::Ok)
    }

    /// The verdicts as they stand once `applied` is the mounting: an axis or
    /// unit problem that the applied mounting undoes becomes a note saying so.
    pub fn after_mounting(&self, applied: Option<&Mount>) -> Vec<Verdict> {
        let undone = applied.is_some() && applied == self.recommended.as_ref();
        self.verdicts
            .iter()
            .map(|v| {
                let axes = matches!(
                    v.subject.as_str(),
                    "vertical axis" | "forward axis" | "gyro units"
                );
                if undone && axes && v.level == Level::Problem {
                    Verdict {
                        subject: v.subject.clone(),
                        level: Level::Info,
                        message: format!(
                            "{} (as logged; the mounting {} applied undoes it)",
                            v.message,
                            applied.map(ToString::to_string).unwrap_or_default()
                        ),
                    }
                } else {
                    v.clone()
                }
            })
            .collect()
    }

    /// Lines to warn a user with, given the mounting that was applied on load.
    pub fn warnings(&self, applied: Option<&Mount>) -> Vec<String> {
        let mut out: Vec<String> = self
            .after_mounting(applied)
            .into_iter()
            .filter(|v| v.level >= Level::Warning)
            .map(|v| format!("{}: {}", v.subject, v.message))
            .collect();
        if let Some(rec) = &self.recommended {
            let applied_or_identity = applied.cloned().unwrap_or_else(Mount::identity);
            if *rec != applied_or_identity {
                out.push(format!(
                    "mounting: the data say '{rec}' (--mount \"{rec}\" or --mount auto), the log is read as '{applied_or_identity}'"
                ));
            }
        }
        out
    }
}

/// Course stretches at least this long (m) along the odometer: GPS noise of a
/// few metres then moves a course by a few degrees, not tens.
const STRETCH_M: f64 = 15.0;

/// Per-fix summaries: everything the checks need, O(fixes) in memory.
struct AtFix {
    t: f64,
    en: [f64; 2],
    alt: Option<f64>,
    /// Odometer distance from the start (m).
    s: f64,
    /// Integrated gyro per logged axis (units as labelled x s).
    turn: [f64; 3],
    /// Mean acceleration since the previous fix, per logged axis.
    acc: Option<[f64; 3]>,
}

/// Check a log.
pub fn check(log: &RideLog) -> CheckReport {
    let mut report = CheckReport::default();
    if log.len() < 2 {
        report.say("rows", Level::Problem, "fewer than two rows".into());
        return report;
    }
    sample_rate(log, &mut report);
    saturation(log, &mut report);
    let fixes = summarise(log);
    let accel_up = accelerometer_vertical(log, &mut report);
    let course = course_vertical(&fixes, &mut report);
    let vertical = match (accel_up, course) {
        (Some(a), Some((c, _))) if a.axis != c.axis || a.sign != c.sign => {
            report.say(
                "vertical axis",
                Level::Problem,
                format!(
                    "the accelerometer says {} is up, the GPS course says {}: the two sensors' axes disagree",
                    signed(a.axis, a.sign),
                    signed(c.axis, c.sign)
                ),
            );
            Some(c)
        }
        (Some(a), _) => Some(a),
        (None, Some((c, _))) => Some(c),
        (None, None) => None,
    };
    if let Some(v) = vertical {
        report.vertical = Some(v);
        let level = if v.axis == 2 && v.sign > 0.0 {
            Level::Ok
        } else {
            Level::Problem
        };
        report.say(
            "vertical axis",
            level,
            format!(
                "{} points up (by {}, r = {:+.2}){}",
                signed(v.axis, v.sign),
                v.by,
                v.r,
                if level == Level::Ok {
                    String::new()
                } else {
                    " - the log's z is not up".into()
                }
            ),
        );
    }
    if let Some((c, beta)) = course {
        gyro_units(beta, c, &mut report);
    }
    let forward = vertical.and_then(|v| forward_axis(&fixes, v, &mut report));
    report.forward = forward;
    odometer_scale(&fixes, &mut report);
    altitude(log, &fixes, &mut report);
    if let Some(v) = vertical {
        let fwd = forward.map_or_else(
            || {
                // No evidence: keep the logged order as far as the vertical allows.
                let a = (0..3).find(|&a| a != v.axis).unwrap_or(0);
                (a, 1.0)
            },
            |f| (f.axis, f.sign),
        );
        report.recommended = Mount::from_forward_up(fwd, (v.axis, v.sign)).map(|mut m| {
            if let Some(s) = report.course_per_gyro.and_then(unit_factor) {
                m.scale = s;
            }
            m
        });
    }
    report
}

fn signed(axis: usize, sign: f64) -> String {
    format!(
        "{}{}",
        if sign < 0.0 { "-" } else { "+" },
        ['x', 'y', 'z'][axis]
    )
}

/// The unit factor a course-per-gyro ratio points to, when it is one of the usual mix-ups.
fn unit_factor(beta: f64) -> Option<f64> {
    let deg = 180.0 / std::f64::consts::PI;
    let l = beta.abs().log10();
    if (l - deg.log10()).abs() < 0.5 {
        Some(deg)
    } else if (l + deg.log10()).abs() < 0.5 {
        Some(1.0 / deg)
    } else {
        None
    }
}

fn sample_rate(log: &RideLog, report: &mut CheckReport) {
    let mut dt: Vec<f64> = log.t_s.windows(2).map(|w| w[1] - w[0]).collect();
    let rate = 1.0 / crate::statistics::median(&mut dt);
    let (level, note) = if rate < 20.0 {
        (
            Level::Info,
            ": a coarse integration step; fast turns are smoothed",
        )
    } else {
        (Level::Ok, "")
    };
    report.say(
        "sample rate",
        level,
        format!(
            "{} rows at {rate:.1} Hz over {:.0} s, time increasing{note}",
            log.len(),
            log.t_s[log.len() - 1] - log.t_s[0]
        ),
    );
}

/// Rows pinned at an axis's extreme: a saturated gyro.
fn saturation(log: &RideLog, report: &mut CheckReport) {
    for a in 0..3 {
        let max = log
            .gyro_dps
            .iter()
            .map(|g| g[a].abs())
            .fold(0.0f64, f64::max);
        if max < 30.0 {
            continue;
        }
        let pinned = log
            .gyro_dps
            .iter()
            .filter(|g| g[a].abs() >= max * (1.0 - 1e-9))
            .count();
        if pinned >= 5 {
            report.say(
                "gyro saturation",
                Level::Warning,
                format!(
                    "axis {} sits at +-{max:.1} (as labelled) on {pinned} rows: it looks saturated, and turns there are lost",
                    ['x', 'y', 'z'][a]
                ),
            );
        }
    }
}

fn summarise(log: &RideLog) -> Vec<AtFix> {
    let Some(first) = log.fix.iter().flatten().next() else {
        return Vec::new();
    };
    let frame = LocalFrame::new(Geodetic::new(first.0, first.1, 0.0));
    let dist =
        crate::signals::odometer_distance(log).map_or_else(|_| vec![0.0; log.len()], |(d, _)| d);
    let mut s = 0.0;
    let mut turn = [0.0; 3];
    let mut acc_sum = [0.0; 3];
    let mut acc_n = 0usize;
    let mut out = Vec::new();
    for j in 0..log.len() {
        if j > 0 {
            let dt = log.t_s[j] - log.t_s[j - 1];
            s += dist[j];
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
        if let Some((lat, lon)) = log.fix[j] {
            let enu = frame.to_enu(&Geodetic::new(lat, lon, 0.0));
            out.push(AtFix {
                t: log.t_s[j],
                en: [enu.x, enu.y],
                alt: log.gps_alt_m.as_ref().and_then(|a| a[j]),
                s,
                turn,
                acc: (acc_n > 0).then(|| acc_sum.map(|x| x / acc_n as f64)),
            });
            acc_sum = [0.0; 3];
            acc_n = 0;
        }
    }
    out
}

/// Gravity in the accelerometer's mean.
fn accelerometer_vertical(log: &RideLog, report: &mut CheckReport) -> Option<AxisFinding> {
    let acc = log.accel_mps2.as_ref()?;
    let mut sum = [0.0; 3];
    let mut n = 0usize;
    for a in acc.iter().flatten() {
        for i in 0..3 {
            sum[i] += a[i];
        }
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let mean = sum.map(|x| x / n as f64);
    let norm = mean.iter().map(|x| x * x).sum::<f64>().sqrt();
    let axis = (0..3)
        .max_by(|&a, &b| mean[a].abs().total_cmp(&mean[b].abs()))
        .unwrap_or(2);
    let cos = mean[axis].abs() / norm.max(1e-12);
    if (0.9..=1.1).contains(&norm) {
        report.say(
            "accelerometer units",
            Level::Warning,
            format!("its mean is {norm:.2}: gravity in g, not m/s^2 (multiply by 9.81)"),
        );
    } else if !(8.8..=10.8).contains(&norm) {
        report.say(
            "accelerometer units",
            Level::Warning,
            format!(
                "its mean is {norm:.2} m/s^2, not gravity (9.8): not a specific force in m/s^2; it is not used for the axes"
            ),
        );
        return None;
    } else {
        report.say(
            "accelerometer units",
            Level::Ok,
            format!("mean {norm:.2} m/s^2: gravity"),
        );
    }
    if cos < 0.9 {
        report.say(
            "vertical axis",
            Level::Warning,
            format!(
                "gravity lies between the axes (the sensor is tilted {:.0} deg from the nearest axis); the nearest is {}",
                cos.acos().to_degrees(),
                signed(axis, mean[axis].signum())
            ),
        );
    }
    Some(AxisFinding {
        axis,
        sign: mean[axis].signum(),
        r: cos,
        by: "gravity in the accelerometer",
    })
}

/// Stretches of the track: indices of fixes at least [`STRETCH_M`] apart along the odometer.
fn stretches(fixes: &[AtFix]) -> Vec<usize> {
    stretches_of(fixes, STRETCH_M)
}

/// Indices of fixes at least `length` (m) apart along the odometer.
fn stretches_of(fixes: &[AtFix], length: f64) -> Vec<usize> {
    let mut idx = Vec::new();
    let mut last = f64::NEG_INFINITY;
    for (k, f) in fixes.iter().enumerate() {
        if f.s - last >= length || idx.is_empty() {
            idx.push(k);
            last = f.s;
        }
    }
    idx
}

/// Least squares `y = beta x + b z` (no intercept): (beta, R^2 about zero).
fn fit2(x: &[f64], z: &[f64], y: &[f64]) -> (f64, f64) {
    let (mut sxx, mut sxz, mut szz, mut sxy, mut szy, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for i in 0..y.len() {
        sxx += x[i] * x[i];
        sxz += x[i] * z[i];
        szz += z[i] * z[i];
        sxy += x[i] * y[i];
        szy += z[i] * y[i];
        syy += y[i] * y[i];
    }
    let det = sxx * szz - sxz * sxz;
    if det.abs() < 1e-300 || syy <= 0.0 {
        return (0.0, 0.0);
    }
    let beta = (sxy * szz - szy * sxz) / det;
    let b = (szy * sxx - sxy * sxz) / det;
    let ssr: f64 = (0..y.len())
        .map(|i| (y[i] - beta * x[i] - b * z[i]).powi(2))
        .sum();
    (beta, 1.0 - ssr / syy)
}

/// The axis whose integrated rate follows the GPS course, and beta.
fn course_vertical(fixes: &[AtFix], report: &mut CheckReport) -> Option<(AxisFinding, f64)> {
    let idx = stretches(fixes);
    let course = |a: usize, b: usize| {
        let (p, q) = (&fixes[a], &fixes[b]);
        let (de, dn) = (q.en[0] - p.en[0], q.en[1] - p.en[1]);
        ((de * de + dn * dn).sqrt(), dn.atan2(de).to_degrees())
    };
    let (mut dc, mut dt) = (Vec::new(), Vec::new());
    let mut turns: [Vec<f64>; 3] = Default::default();
    for w in idx.windows(3) {
        let (len1, c1) = course(w[0], w[1]);
        let (len2, c2) = course(w[1], w[2]);
        let (s1, s2) = (fixes[w[1]].s - fixes[w[0]].s, fixes[w[2]].s - fixes[w[1]].s);
        // Straight-line stretches: the chord's course is the heading halfway along.
        if len1 < 0.5 * s1 || len2 < 0.5 * s2 {
            continue;
        }
        let d = (c2 - c1 + 540.0).rem_euclid(360.0) - 180.0;
        if d.abs() > 120.0 {
            continue;
        }
        dc.push(d);
        dt.push(0.5 * (fixes[w[2]].t - fixes[w[0]].t));
        for a in 0..3 {
            turns[a].push(0.5 * (fixes[w[2]].turn[a] - fixes[w[0]].turn[a]));
        }
    }
    let total: f64 = dc.iter().map(|d| d.abs()).sum();
    if dc.len() < 8 || total < 90.0 {
        report.say(
            "vertical axis (GPS course)",
            Level::Info,
            format!(
                "not checked: the track turns too little ({total:.0} deg over {} stretches of {STRETCH_M} m)",
                dc.len()
            ),
        );
        return None;
    }
    let fits: Vec<(f64, f64)> = (0..3).map(|a| fit2(&turns[a], &dt, &dc)).collect();
    let axis = (0..3)
        .max_by(|&a, &b| fits[a].1.total_cmp(&fits[b].1))
        .unwrap_or(2);
    let (beta, r2) = fits[axis];
    let r = r2.max(0.0).sqrt();
    let others: Vec<String> = (0..3)
        .filter(|&a| a != axis)
        .map(|a| format!("{} R^2 {:.2}", ['x', 'y', 'z'][a], fits[a].1))
        .collect();
    if r2 < 0.3 {
        report.say(
            "vertical axis (GPS course)",
            Level::Warning,
            format!(
                "cannot tell: no axis follows the GPS course (best {} R^2 {r2:.2}; {})",
                ['x', 'y', 'z'][axis],
                others.join(", ")
            ),
        );
        return None;
    }
    report.say(
        "vertical axis (GPS course)",
        Level::Info,
        format!(
            "{} follows the course turn (R^2 {r2:.2} over {} stretches, {total:.0} deg; {})",
            signed(axis, beta.signum()),
            dc.len(),
            others.join(", ")
        ),
    );
    report.course_per_gyro = Some(beta.abs());
    Some((
        AxisFinding {
            axis,
            sign: beta.signum(),
            r: r * beta.signum(),
            by: "the GPS course",
        },
        beta,
    ))
}

fn gyro_units(beta: f64, vertical: AxisFinding, report: &mut CheckReport) {
    let b = beta.abs();
    let axis = signed(vertical.axis, vertical.sign);
    match unit_factor(b) {
        Some(f) if f > 1.0 => report.say(
            "gyro units",
            Level::Problem,
            format!(
                "the gyro turns {b:.1} times less than the GPS course on {axis}: rad/s logged as deg/s (scale {f:.5})"
            ),
        ),
        Some(f) => report.say(
            "gyro units",
            Level::Problem,
            format!(
                "the gyro turns {:.1} times more than the GPS course on {axis}: deg/s logged as rad/s (scale {f:.6})",
                1.0 / b
            ),
        ),
        None if (0.8..=1.25).contains(&b) => report.say(
            "gyro units",
            Level::Ok,
            format!("deg/s: the course turns {b:.3} deg per gyro degree on {axis}"),
        ),
        None => report.say(
            "gyro units",
            Level::Warning,
            format!(
                "the course turns {b:.3} deg per gyro degree on {axis}: neither deg/s nor rad/s; check the units or the scale"
            ),
        ),
    }
}

/// Forward from the accelerometer against dv/dt and v * yaw rate.
fn forward_axis(fixes: &[AtFix], up: AxisFinding, report: &mut CheckReport) -> Option<AxisFinding> {
    if fixes.iter().all(|f| f.acc.is_none()) {
        report.say(
            "forward axis",
            Level::Info,
            "not told by the data (no accelerometer); a turn of the sensor about the vertical is absorbed by the fitted start heading".into(),
        );
        return None;
    }
    // Per interval between fixes: speed, yaw rate (rad/s) and mean acceleration.
    let (mut dvdt, mut centripetal) = (Vec::new(), Vec::new());
    let mut acc: [Vec<f64>; 3] = Default::default();
    let mut acc_lat: [Vec<f64>; 3] = Default::default();
    for w in fixes.windows(3) {
        let (Some(a1), Some(a2)) = (w[1].acc, w[2].acc) else {
            continue;
        };
        let (dt1, dt2) = (w[1].t - w[0].t, w[2].t - w[1].t);
        if dt1 <= 0.0 || dt2 <= 0.0 || dt1 > 5.0 || dt2 > 5.0 {
            continue;
        }
        let (v1, v2) = ((w[1].s - w[0].s) / dt1, (w[2].s - w[1].s) / dt2);
        dvdt.push((v2 - v1) / (0.5 * (dt1 + dt2)));
        let yaw = up.sign * (w[2].turn[up.axis] - w[1].turn[up.axis]) / dt2;
        centripetal.push(v2 * yaw.to_radians());
        for i in 0..3 {
            acc[i].push(0.5 * (a1[i] + a2[i]));
            acc_lat[i].push(a2[i]);
        }
    }
    if dvdt.len() < 20 {
        report.say(
            "forward axis",
            Level::Info,
            "not checked: too few GPS intervals with accelerometer data".into(),
        );
        return None;
    }
    let mut best: Option<(f64, usize, f64, f64, f64)> = None;
    for f in (0..3).filter(|&a| a != up.axis) {
        for sf in [1.0, -1.0] {
            let Some(m) = Mount::from_forward_up((f, sf), (up.axis, up.sign)) else {
                continue;
            };
            let r_fwd = sf * pearson(&acc[f], &dvdt).unwrap_or(0.0);
            let r_lat = m.sign[1] * pearson(&acc_lat[m.axis[1]], &centripetal).unwrap_or(0.0);
            let score = r_fwd + r_lat;
            if best.is_none_or(|b| score > b.0) {
                best = Some((score, f, sf, r_fwd, r_lat));
            }
        }
    }
    let (score, axis, sign, r_fwd, r_lat) = best?;
    if r_fwd < 0.1 && r_lat < 0.1 {
        report.say(
            "forward axis",
            Level::Warning,
            format!(
                "cannot tell: no horizontal axis follows the odometer's acceleration (best {} with r {r_fwd:+.2}, lateral r {r_lat:+.2})",
                signed(axis, sign)
            ),
        );
        return None;
    }
    let level = if axis == 0 && sign > 0.0 {
        Level::Ok
    } else {
        Level::Problem
    };
    report.say(
        "forward axis",
        level,
        format!(
            "{} points forward (its acceleration follows the odometer's dv/dt, r = {r_fwd:+.2}; the left axis follows v * yaw rate, r = {r_lat:+.2}){}",
            signed(axis, sign),
            if level == Level::Ok {
                ""
            } else {
                " - the log's x is not forward"
            }
        ),
    );
    Some(AxisFinding {
        axis,
        sign,
        r: score / 2.0,
        by: "the accelerometer against the odometer",
    })
}

/// Stretches for the odometer check are at least this many times the fixes'
/// own scatter long: a chord `L` between two fixes with errors of scatter `s`
/// reads about `sqrt(L^2 + 2 s^2)`, so city fixes 10-20 m off made 15 m
/// stretches of GPS track 40 % longer than the road (Berlin read 0.728 m of
/// odometer per GPS m); at `L = 10 s` the excess is 1 %.
const STRETCH_PER_SCATTER: f64 = 10.0;

/// Odometer distance against the GPS track length, over stretches that moved.
fn odometer_scale(fixes: &[AtFix], report: &mut CheckReport) {
    let t: Vec<f64> = fixes.iter().map(|f| f.t).collect();
    let en: Vec<[f64; 2]> = fixes.iter().map(|f| f.en).collect();
    let scatter = crate::statistics::track_scatter_m(&t, &en).unwrap_or(0.0);
    let idx = stretches_of(fixes, STRETCH_M.max(STRETCH_PER_SCATTER * scatter));
    let (mut odo, mut gps) = (0.0, 0.0);
    for w in idx.windows(2) {
        let (a, b) = (&fixes[w[0]], &fixes[w[1]]);
        odo += b.s - a.s;
        gps += ((b.en[0] - a.en[0]).powi(2) + (b.en[1] - a.en[1]).powi(2)).sqrt();
    }
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
    if gps < 50.0 {
        report.say(
            "odometer",
            Level::Info,
            format!("scale not checked: the GPS track is only {gps:.0} m long"),
        );
        return;
    }
    let ratio = odo / gps;
    report.odometer_per_gps = Some(ratio);
    let (level, note) = if (0.85..=1.15).contains(&ratio) {
        (Level::Ok, String::new())
    } else if (ratio * 3.6 - 1.0).abs() < 0.15 {
        (Level::Problem, ": km/h logged as m/s?".into())
    } else if (ratio / 3.6 - 1.0).abs() < 0.15 {
        (Level::Problem, ": m/s logged as km/h?".into())
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
            "it measures {ratio:.3} m per metre of GPS track ({odo:.0} m against {gps:.0} m){note}"
        ),
    );
}

/// The altitude's datum cannot be told from the data; a jump in it can.
fn altitude(log: &RideLog, fixes: &[AtFix], report: &mut CheckReport) {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn ride() -> RideLog {
        crate::testing::winding_log(600.0, 50.0)
    }

    #[test]
    fn a_log_in_the_ride_frame_passes() {
        let log = ride();
        let r = check(&log);
        assert_eq!(r.recommended, Some(Mount::identity()), "{:#?}", r.verdicts);
        let v = r.vertical.unwrap();
        assert_eq!((v.axis, v.sign), (2, 1.0));
        assert!(r.worst() < Level::Problem, "{:#?}", r.verdicts);
        let c = r.course_per_gyro.unwrap();
        assert!((c - 1.0).abs() < 0.1, "{c}");
        let o = r.odometer_per_gps.unwrap();
        assert!((o - 1.0).abs() < 0.05, "{o}");
    }

    #[test]
    fn permuted_axes_and_radians_are_named_with_the_mapping_that_undoes_them() {
        let truth: Mount = "x=-z,y=-x,z=y".parse().unwrap();
        let mut log = ride();
        // Write the ride as the Husky's IMU would see it: logged = inverse(truth) of ride.
        for g in &mut log.gyro_dps {
            let ride = *g;
            let mut logged = [0.0; 3];
            for i in 0..3 {
                logged[truth.axis[i]] = truth.sign[i] * ride[i];
            }
            *g = logged.map(|w| w.to_radians());
        }
        let r = check(&log);
        let rec = r.recommended.clone().unwrap();
        assert_eq!(rec.sign[2], 1.0);
        assert_eq!(rec.axis[2], 1, "{:#?}", r.verdicts);
        assert!((rec.scale - 57.29578).abs() < 1e-3, "{rec}");
        assert!(
            r.verdicts
                .iter()
                .any(|v| v.subject == "gyro units" && v.level == Level::Problem)
        );
        // Undone, the yaw is the ride's again.
        let mut fixed = log.clone();
        rec.apply(&mut fixed);
        let orig = ride();
        for j in (0..orig.len()).step_by(997) {
            assert!((fixed.gyro_dps[j][2] - orig.gyro_dps[j][2]).abs() < 1e-9);
        }
    }

    #[test]
    fn a_sign_flipped_odometer_and_a_saturated_gyro_are_reported() {
        let mut log = ride();
        for o in log.odo_m.as_mut().unwrap().iter_mut().flatten() {
            *o = -*o;
        }
        for g in log.gyro_dps.iter_mut().take(40) {
            g[0] = 250.0;
        }
        let r = check(&log);
        assert!(
            r.verdicts
                .iter()
                .any(|v| v.subject == "odometer" && v.message.contains("backwards")),
            "{:#?}",
            r.verdicts
        );
        assert!(r.verdicts.iter().any(|v| v.subject == "gyro saturation"));
    }
}
