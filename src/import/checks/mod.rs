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

mod axes;
mod log;
mod track;

use axes::{
    accelerometer_vertical, course_vertical, forward_axis, gyro_units, signed, unit_factor,
};
use log::{sample_rate, saturation, stuck_gyro};
use track::{
    AtFix, Stretches, altitude, direction_and_turns, gps_units, local_fixes, odometer_scale,
    quality, stretches, summarise, with_turns_lost,
};

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

impl Verdict {
    /// The verdict as one warning line, "subject: message", as the
    /// terminal prints it (and the HTML report recognises it by).
    pub fn as_warning(&self) -> String {
        format!("{}: {}", self.subject, self.message)
    }

    /// Whether it is about the log's axes or the gyro's units, which a
    /// mounting undoes.
    pub fn is_axes_or_units(&self) -> bool {
        matches!(
            self.subject.as_str(),
            "vertical axis" | "forward axis" | "gyro units"
        )
    }
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
    /// Its 1-sigma, from the scatter of the course's turns about it.
    pub course_per_gyro_sigma: Option<f64>,
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
                if undone && v.is_axes_or_units() && v.level == Level::Problem {
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
            .map(|v| v.as_warning())
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

/// The course test with the stretches across `turns` left out, where the
/// sensor turned without the vehicle about the log's z (the fit bridges
/// them): taken only where it finds z up. Found about an axis that is not
/// up they mean nothing (a pitch axis read as z "turned alone" for 12 s),
/// and leaving stretches out for them lost a car's vertical.
fn course_without_sensor_turns(
    fixes: &[AtFix],
    turns: &[crate::sensor_turns::SensorTurn],
    stretches: &Stretches,
    report: &mut CheckReport,
) -> Option<(AxisFinding, f64)> {
    if turns.is_empty() {
        return None;
    }
    let mut trial = CheckReport::default();
    let found = course_vertical(&with_turns_lost(fixes, turns), stretches, &mut trial)?;
    if found.0.axis != 2 || found.0.sign < 0.0 {
        return None;
    }
    report.verdicts.extend(trial.verdicts);
    Some(found)
}

/// Check a log.
pub fn check(log: &RideLog) -> CheckReport {
    let mut report = CheckReport::default();
    if log.len() < 2 {
        report.say("rows", Level::Problem, "fewer than two rows".into());
        return report;
    }
    if !sample_rate(log, &mut report) {
        report.say(
            "axes and units",
            Level::Info,
            "not checked: too few gyro samples to compare with the GPS course or gravity".into(),
        );
        return report;
    }
    saturation(log, &mut report);
    let (distance, jumps) = crate::signals::odometer_distance_and_jumps(log, |j| log.gyro_dps[j]);
    if let Some(w) = jumps.describe(&log.source, &log.line, &log.t_s) {
        report.say("odometer jumps", Level::Warning, w);
    }
    let measured = distance.ok().map(|(d, _)| d);
    let blunders = crate::blunders::find(
        &log.t_s,
        &log.fix,
        log.gps_hacc_m.as_deref(),
        measured.as_deref(),
    );
    let mut distance = measured.unwrap_or_else(|| vec![0.0; log.len()]);
    if let Some(w) = blunders.describe(&log.source, &log.line, &log.t_s) {
        report.say("GPS blunders", Level::Warning, w);
    }
    let located = local_fixes(log, &blunders);
    let turns = direction_and_turns(log, &mut distance, &located, &mut report);
    let fixes = summarise(log, &located, &distance);
    let accel_up = accelerometer_vertical(log, &mut report);
    // One set of stretches (and one measure of the fixes' scatter) for the
    // course and odometer checks.
    let stretches = stretches(&fixes);
    let course = course_without_sensor_turns(&fixes, &turns, &stretches, &mut report)
        .or_else(|| course_vertical(&fixes, &stretches, &mut report));
    // The sensor's own turns, said where z (about which they were found, as
    // the fit finds them) is up by the course.
    if course.is_some_and(|(c, _)| c.axis == 2 && c.sign > 0.0)
        && let Some(said) = crate::sensor_turns::describe(&turns)
    {
        report.say("sensor turns", Level::Warning, said);
    }
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
    stuck_gyro(
        log,
        &distance,
        (&fixes, &stretches),
        vertical.map(|v| (v.axis, v.sign)),
        &mut report,
    );
    if let Some((c, beta)) = course {
        gyro_units(beta, c, &mut report);
    }
    let forward = vertical.and_then(|v| forward_axis(&fixes, v, &mut report));
    report.forward = forward;
    odometer_scale(&fixes, &stretches.idx, &mut report);
    gps_units(log, &fixes, &mut report);
    altitude(log, &fixes, &mut report);
    quality(log, &mut report);
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
            if let Some(s) = report
                .course_per_gyro
                .and_then(|b| unit_factor(b, report.course_per_gyro_sigma.unwrap_or(0.0)))
            {
                m.scale = s;
            }
            m
        });
    }
    report
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

    /// A gyro written as raw counts (131 per deg/s), in mdps or at half its
    /// rate is named for what it is, with the scale that undoes it; before,
    /// any factor from 18 to 181 read as "deg/s logged as rad/s", and the
    /// counts were handed a scale 2.3 times off.
    #[test]
    fn raw_counts_and_mdps_are_named_with_their_scale() {
        let scaled = |k: f64| {
            let mut log = ride();
            for g in &mut log.gyro_dps {
                *g = g.map(|w| w * k);
            }
            check(&log)
        };
        let units = |r: &CheckReport| {
            r.verdicts
                .iter()
                .find(|v| v.subject == "gyro units")
                .cloned()
                .unwrap_or_else(|| panic!("{:#?}", r.verdicts))
        };
        for (k, named) in [
            (
                131.0,
                "raw counts of a gyro at +-250 deg/s full scale (131 per deg/s)",
            ),
            (1000.0, "millidegrees per second"),
        ] {
            let r = scaled(k);
            let v = units(&r);
            assert_eq!(v.level, Level::Problem, "{v:?}");
            assert!(v.message.contains(named), "{k}: {v:?}");
            let rec = r.recommended.clone().unwrap_or_else(Mount::identity);
            assert!((rec.scale * k - 1.0).abs() < 1e-9, "{k}: {rec}");
        }
        let r = scaled(0.5);
        let v = units(&r);
        assert_eq!(v.level, Level::Warning, "{v:?}");
        assert!(
            v.message.contains("neither deg/s nor a usual mix-up"),
            "{v:?}"
        );
        assert_eq!(r.recommended.map(|m| m.scale), Some(1.0));
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

    #[test]
    fn fixes_in_radians_are_named_and_a_ride_in_degrees_is_not() {
        let mut log = ride();
        assert!(
            !check(&log)
                .verdicts
                .iter()
                .any(|v| v.subject == "GPS units")
        );
        for f in log.fix.iter_mut().flatten() {
            *f = (f.0.to_radians(), f.1.to_radians());
        }
        let r = check(&log);
        assert!(
            r.verdicts.iter().any(|v| v.subject == "GPS units"
                && v.level == Level::Problem
                && v.message.contains("look like radians")),
            "{:#?}",
            r.verdicts
        );
    }

    /// An odometer in km, in feet or standing still is named as such, and
    /// the course check still reads the vertical (the stretches were set
    /// by the odometer's distance and held every fix in one in km).
    #[test]
    fn an_odometer_in_the_wrong_units_or_standing_still_is_named() {
        let scaled = |factor: f64| {
            let mut log = ride();
            for o in log.odo_m.as_mut().unwrap().iter_mut().flatten() {
                *o *= factor;
            }
            check(&log)
        };
        let odometer = |r: &CheckReport| {
            r.verdicts
                .iter()
                .find(|v| v.subject == "odometer")
                .cloned()
                .unwrap()
        };
        for (factor, says) in [
            (0.001, "a factor of 1000, as between metres and km"),
            (
                1.0 / 0.3048,
                "a factor of 3.281, as between feet and metres",
            ),
            (3.6, "a factor of 3.600, as between km/h and m/s"),
            (0.0, "the odometer stands while the vehicle moves"),
        ] {
            let r = scaled(factor);
            let o = odometer(&r);
            assert_eq!(o.level, Level::Problem, "{factor}: {o:?}");
            assert!(o.message.contains(says), "{factor}: {}", o.message);
            if factor > 0.0 {
                let ratio = r.odometer_per_gps.unwrap();
                assert!((ratio / factor - 1.0).abs() < 0.05, "{factor}: {ratio}");
                let v = r.vertical.unwrap();
                assert_eq!((v.axis, v.sign), (2, 1.0), "{factor}");
            }
        }
        // A wheel 8 % off is a circumference, not a unit.
        let o = odometer(&scaled(1.08));
        assert_eq!(o.level, Level::Ok, "{o:?}");
    }

    /// A gyro that stops answering, its dropout written as zeros or its
    /// last reading held, is named with its rows; a log with a yaw rate
    /// alone that reads 0 where the course does not turn is not.
    #[test]
    fn a_gyro_that_stops_answering_is_named() {
        let stopped = |held: Option<[f64; 3]>| {
            let mut log = ride();
            let (a, b) = (200 * 50, 230 * 50);
            let value = held.unwrap_or(log.gyro_dps[a - 1]);
            for g in &mut log.gyro_dps[a..b] {
                *g = value;
            }
            check(&log)
                .verdicts
                .into_iter()
                .find(|v| v.subject == "gyro stopped")
        };
        assert_eq!(stopped(Some([0.0; 3])).unwrap().level, Level::Problem);
        let held = stopped(None).unwrap();
        assert_eq!(held.level, Level::Problem);
        assert!(
            held.message
                .contains("from t = 199.98 to 229.98 s (lines 10001-11501)"),
            "{}",
            held.message
        );
        assert!(
            check(&ride())
                .verdicts
                .iter()
                .all(|v| v.subject != "gyro stopped")
        );

        // A yaw rate alone (x and y never read): zeros for 2 s where the
        // vehicle barely turns (its yaw rate crosses zero at t = 25.7 s) may
        // be a deadband, not named; zeros through 20 s of a bend on a
        // sensor with a deadband of 3 deg/s are, from the GPS course, as a
        // warning (the fit cannot tell them from the deadband).
        let yaw_deadband = |from_s: f64, to_s: f64, deadband_dps: f64| {
            let mut log = ride();
            for (g, &t) in log.gyro_dps.iter_mut().zip(&log.t_s) {
                g[0] = 0.0;
                g[1] = 0.0;
                if (from_s..to_s).contains(&t) || g[2].abs() < deadband_dps {
                    g[2] = 0.0;
                }
            }
            check(&log)
                .verdicts
                .into_iter()
                .find(|v| v.subject == "gyro stopped")
        };
        let yaw_only = |from_s, to_s| yaw_deadband(from_s, to_s, 0.0);
        assert_eq!(yaw_only(0.0, 0.0), None);
        assert_eq!(yaw_only(24.7, 26.7), None);
        let bend = yaw_deadband(300.0, 320.0, 3.0).unwrap();
        assert_eq!(bend.level, Level::Warning);
        assert!(
            bend.message.contains("the GPS course turns"),
            "{}",
            bend.message
        );
        // Zeros for 6 s where it barely turns: a sensor that reads zero
        // nowhere else has stopped; one with a deadband of 3 deg/s (zero on
        // a fifth of the rows that move) is within it.
        let lone = yaw_only(22.7, 28.7).unwrap();
        assert_eq!(lone.level, Level::Problem);
        assert!(
            lone.message.contains("the fit bridges it"),
            "{}",
            lone.message
        );
        assert!(
            lone.message.contains("elsewhere it reads zero on 0.0 %"),
            "{}",
            lone.message
        );
        assert_eq!(yaw_deadband(22.7, 28.7, 3.0), None);
    }
}
