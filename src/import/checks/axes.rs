//! Which logged axis is up and which forward, and the gyro's units: from the
//! accelerometer, and from the GPS course turning with the yaw rate.

use super::*;

pub(super) fn signed(axis: usize, sign: f64) -> String {
    format!(
        "{}{}",
        if sign < 0.0 { "-" } else { "+" },
        ['x', 'y', 'z'][axis]
    )
}

/// The usual mix-ups of a gyro's units, each as the scale that undoes it
/// (deg/s per logged unit) and what it is: a unit taken for another, or the
/// chip's raw output written as it comes. Raw counts are the sensitivities
/// of the common MEMS gyros at their full scales (InvenSense's and Bosch's
/// 131 per deg/s at +-250 deg/s, halving with each doubling of the range;
/// ST's 8.75, 17.5, 35 and 70 mdps per count).
const GYRO_CONFUSIONS: [(f64, &str); 15] = [
    (DEG_PER_RAD, "rad/s logged as deg/s"),
    (1.0 / DEG_PER_RAD, "deg/s logged as rad/s"),
    (
        0.001,
        "millidegrees per second (mdps, as ST's drivers give them)",
    ),
    (DEG_PER_RAD / 1000.0, "milliradians per second"),
    (0.01, "hundredths of a deg/s (a CAN signal's raw value)"),
    (0.1, "tenths of a deg/s (a CAN signal's raw value)"),
    (
        1.0 / 262.4,
        "raw counts of a gyro at +-125 deg/s full scale (262.4 per deg/s)",
    ),
    (
        1.0 / 131.0,
        "raw counts of a gyro at +-250 deg/s full scale (131 per deg/s)",
    ),
    (
        1.0 / 65.5,
        "raw counts of a gyro at +-500 deg/s full scale (65.5 per deg/s)",
    ),
    (
        1.0 / 32.8,
        "raw counts of a gyro at +-1000 deg/s full scale (32.8 per deg/s)",
    ),
    (
        1.0 / 16.4,
        "raw counts of a gyro at +-2000 deg/s full scale (16.4 per deg/s)",
    ),
    (
        0.00875,
        "raw counts of an ST gyro at +-250 deg/s (8.75 mdps each)",
    ),
    (
        0.0175,
        "raw counts of an ST gyro at +-500 deg/s (17.5 mdps each)",
    ),
    (
        0.035,
        "raw counts of an ST gyro at +-1000 deg/s (35 mdps each)",
    ),
    (
        0.07,
        "raw counts of an ST gyro at +-2000 deg/s (70 mdps each)",
    ),
];

const DEG_PER_RAD: f64 = 180.0 / std::f64::consts::PI;

/// The narrowest band (as a fraction) about a course-per-gyro ratio in
/// which [`gyro_confusions`] looks, whatever the regression's own sigma
/// says: that sigma takes the stretches' course errors as independent, and
/// a simulated skid-steer robot's rad/s read 45.5 where 57.3 is true (21 %
/// off) at R^2 0.69 over 21 stretches.
pub(super) const GYRO_UNIT_TOLERANCE: f64 = 0.3;

/// The widest band: beyond it a ratio names nothing.
pub(super) const GYRO_UNIT_WIDEST: f64 = 0.5;

/// The unit mix-ups ([`GYRO_CONFUSIONS`]) a course-per-gyro ratio `beta`
/// (1-sigma `sigma`) can be, nearest first: those within three sigmas in
/// ratio, at least [`GYRO_UNIT_TOLERANCE`] and at most
/// [`GYRO_UNIT_WIDEST`]; of two within 1 % of each other (deg/s as rad/s
/// and ST's +-500 deg/s counts) the nearer alone, as their scales are the
/// same to that. Each as the scale that undoes it and what it is. Before,
/// any ratio within half a decade of 57.3 read as rad/s: Berlin's yaw rate
/// written as counts of 131 per deg/s was handed a scale 2.3 times off.
pub(super) fn gyro_confusions(beta: f64, sigma: f64) -> Vec<(f64, &'static str)> {
    let b = beta.abs();
    if !(b.is_finite() && b > 0.0) {
        return Vec::new();
    }
    let band = unit_band(b, sigma);
    let mut near: Vec<(f64, f64, &str)> = GYRO_CONFUSIONS
        .iter()
        .map(|&(scale, what)| ((b / scale).ln().abs(), scale, what))
        .filter(|&(off, _, _)| off < band)
        .collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut kept: Vec<(f64, &str)> = Vec::new();
    for (_, scale, what) in near {
        if kept
            .iter()
            .all(|&(s, _)| (scale / s).ln().abs() > 0.01f64.ln_1p())
        {
            kept.push((scale, what));
        }
    }
    kept
}

/// How far (in the logarithm) a course-per-gyro ratio `b` (1-sigma
/// `sigma`) may lie from a unit's scale and still be read as that unit:
/// `ln(1 + clamp(3 sigma / b,` [`GYRO_UNIT_TOLERANCE`]`,`
/// [`GYRO_UNIT_WIDEST`]`))`. Deg/s itself is judged in the same band as
/// the mix-ups: on a city ride of a dozen stretches the ratio of a gyro
/// logged in deg/s reads 0.68-1.50, and a fixed 0.8-1.25 told 45 of 322
/// simulated rides (every one in deg/s) to check their units; with the band
/// 18 (16 with the log's z kept, see [`vertical_by_course`]). No mix-up
/// lies within a factor of 1.5 of deg/s, so none is missed.
pub(super) fn unit_band(b: f64, sigma: f64) -> f64 {
    (3.0 * sigma / b)
        .clamp(GYRO_UNIT_TOLERANCE, GYRO_UNIT_WIDEST)
        .ln_1p()
}

/// The scale that undoes the nearest unit mix-up a course-per-gyro ratio
/// points to (see [`gyro_confusions`]), if any.
pub(super) fn unit_factor(beta: f64, sigma: f64) -> Option<f64> {
    gyro_confusions(beta, sigma).first().map(|&(s, _)| s)
}

/// Gravity in the accelerometer's mean.
pub(super) fn accelerometer_vertical(
    log: &RideLog,
    report: &mut CheckReport,
) -> Option<AxisFinding> {
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

/// Least squares `y = beta x + b z` (no intercept): (beta, the partial
/// `R^2` of `x`, the 1-sigma of beta from the scatter,
/// `sqrt(s^2 (Z'Z) / det)` with `s^2 = SSR / (n - 2)`).
///
/// The partial `R^2 = 1 - SSR / SSR_z` is the share of what `z` alone
/// leaves (`SSR_z = y'y - (z'y)^2 / z'z`) that `x` explains: with `z` the
/// stretches' times, how far an axis's turn follows the course beyond a
/// steady turn at a constant rate, which the gyro's bias gives every axis
/// alike. The `R^2` about zero counted that steady turn for every axis: a
/// car that turned one way across two GPS outages (a chord over 72 s, its
/// course 58 deg against the gyro's 36) read `R^2` 0.39-0.40 on all three
/// axes, and the check called its z "not up" and its deg/s raw counts
/// (-z, 23 times: a simulated open-sky car, seed 62); over 322 simulated
/// rides, all logged z up in deg/s, 7 were told their z was not up, 2 with
/// this partial `R^2`, and no rotated or rescaled log of 90 lost its
/// mounting.
pub(super) fn fit2(x: &[f64], z: &[f64], y: &[f64]) -> (f64, f64, f64) {
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
        return (0.0, 0.0, f64::INFINITY);
    }
    let beta = (sxy * szz - szy * sxz) / det;
    let b = (szy * sxx - sxy * sxz) / det;
    let ssr: f64 = (0..y.len())
        .map(|i| (y[i] - beta * x[i] - b * z[i]).powi(2))
        .sum();
    let dof = y.len().saturating_sub(2).max(1) as f64;
    let ssr_z = (syy - szy * szy / szz.max(f64::MIN_POSITIVE)).max(0.0);
    let r2 = if ssr_z > 0.0 { 1.0 - ssr / ssr_z } else { 0.0 };
    (beta, r2, (ssr / dof * szz / det).max(0.0).sqrt())
}

/// An angle (deg) wrapped into -180..180.
pub(super) fn wrap_deg(a: f64) -> f64 {
    (a + 540.0).rem_euclid(360.0) - 180.0
}

/// How many times the share of the course's turn that one axis leaves
/// unexplained (`1 - R^2`) must exceed the best axis's before the best is
/// read as the vertical on its `R^2` alone (see [`vertical_by_course`]).
pub(super) const CLEARLY_BETTER: f64 = 2.0;

/// The axis of `fits` (`fit2` of the course's turn on each axis's turn,
/// `(beta, R^2, sigma)`) read as the vertical: of the axes that follow the
/// course about as well as the best (`R^2` at least [`MIN_R2`] and
/// `1 - R^2 <= CLEARLY_BETTER (1 - R^2_best)`), the one that turns the most
/// per degree of course, the least `|beta|`. The vertical carries the whole
/// turn; another axis sees a share of it, through the vehicle's roll or
/// pitch or a tilted mount, so it needs a larger `beta` to follow the course,
/// whatever unit all three axes are logged in. A car rolls out of its
/// turns, so its pitch gyro sees the yaw rate times the sine of the roll, a
/// turn of one sign for a car that turns mostly one way: over simulated car
/// rides (seeds 3 and 4) the pitch axis edged the yaw axis by `R^2` (0.87
/// against 0.84, 0.62 against 0.54) at 46-60 times its `beta`, and the check
/// called a level log's z not up and its deg/s rad/s.
///
/// The log's own z stays the vertical where it follows the course about as
/// well as the best (without the [`MIN_R2`] floor) at a ratio that reads as
/// deg/s ([`unit_band`] about 1, either sign) and stands clear of zero by
/// its sigma: to call the log's labels wrong the course must tell against
/// them, not merely lean elsewhere. A simulated bicycle in the city (seed
/// 62, 240 s, 10 stretches) read -y at `R^2` 0.49 and 2.6 times the
/// course's turn (a share of it through the lean), z at 0.28 and
/// 0.98 +- 0.56, and was told its z was not up; where z turns nothing of
/// the course (1.27 +- 1.61, `R^2` 0.01: a bicycle log rotated y up, in
/// an urban street) the axis that does is read.
pub(super) fn vertical_by_course(fits: &[(f64, f64, f64)]) -> usize {
    let Some(best) = (0..fits.len()).max_by(|&a, &b| fits[a].1.total_cmp(&fits[b].1)) else {
        return 2;
    };
    let unexplained = 1.0 - fits[best].1;
    let about_as_well = |a: usize| 1.0 - fits[a].1 <= CLEARLY_BETTER * unexplained;
    if let Some(&(beta, _, sigma)) = fits.get(2) {
        let b = beta.abs();
        if about_as_well(2) && b > sigma && b.ln().abs() <= unit_band(b, sigma) {
            return 2;
        }
    }
    (0..fits.len())
        .filter(|&a| fits[a].1 >= MIN_R2 && about_as_well(a))
        .min_by(|&a, &b| fits[a].0.abs().total_cmp(&fits[b].0.abs()))
        .unwrap_or(best)
}

/// Least `R^2` of the axis that follows the GPS course: below it, no axis does.
pub(super) const MIN_R2: f64 = 0.3;

/// The axis whose integrated rate follows the GPS course, and beta.
pub(super) fn course_vertical(
    fixes: &[AtFix],
    stretches: &Stretches,
    report: &mut CheckReport,
) -> Option<(AxisFinding, f64)> {
    let (mut dc, mut dt) = (Vec::new(), Vec::new());
    let mut turns: [Vec<f64>; 3] = Default::default();
    for w in stretches.idx.windows(3) {
        // Across rows the log lost, the gyro's turn is not known.
        if fixes[w[2]].lost_s > fixes[w[0]].lost_s {
            continue;
        }
        let course = |a: usize, b: usize| stretches.course(&fixes[w[a]], &fixes[w[b]]);
        let (Some(c1), Some(c2)) = (course(0, 1), course(1, 2)) else {
            continue;
        };
        let d = wrap_deg(c2 - c1);
        if d.abs() > 120.0 {
            continue;
        }
        dc.push(d);
        dt.push(0.5 * (fixes[w[2]].t - fixes[w[0]].t));
        for a in 0..3 {
            turns[a].push(0.5 * (fixes[w[2]].turn[a] - fixes[w[0]].turn[a]));
        }
    }
    if dc.is_empty() {
        report.say(
            "vertical axis (GPS course)",
            Level::Info,
            format!(
                "not checked: no straight stretch of {:.0} m between the fixes",
                stretches.length_m
            ),
        );
        return None;
    }
    let total: f64 = dc.iter().map(|d| d.abs()).sum();
    if dc.len() < 8 || total < 90.0 {
        report.say(
            "vertical axis (GPS course)",
            Level::Info,
            format!(
                "not checked: the track turns too little ({total:.0} deg over {} stretches of {:.0} m)",
                dc.len(),
                stretches.length_m
            ),
        );
        return None;
    }
    let fits: Vec<(f64, f64, f64)> = (0..3).map(|a| fit2(&turns[a], &dt, &dc)).collect();
    let axis = vertical_by_course(&fits);
    let (beta, r2, sigma) = fits[axis];
    let r = r2.max(0.0).sqrt();
    let others: Vec<String> = (0..3)
        .filter(|&a| a != axis)
        .map(|a| {
            let share = if fits[a].1 > r2 {
                format!(
                    " but {:.0} x the turn per degree: a share of it, through the roll or pitch",
                    fits[a].0.abs() / beta.abs().max(f64::MIN_POSITIVE)
                )
            } else {
                String::new()
            };
            format!("{} R^2 {:.2}{share}", ['x', 'y', 'z'][a], fits[a].1)
        })
        .collect();
    if r2 < MIN_R2 {
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
    report.course_per_gyro_sigma = Some(sigma);
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

/// Whether the gyro is in deg/s, by the GPS course's turn per gyro turn
/// `beta` on the vertical (1-sigma in the report): within [`unit_band`] of
/// 1 it is; else the unit mix-ups it can be ([`gyro_confusions`]) are
/// named, each with the scale that undoes it.
pub(super) fn gyro_units(beta: f64, vertical: AxisFinding, report: &mut CheckReport) {
    let b = beta.abs();
    let axis = signed(vertical.axis, vertical.sign);
    let sigma = report.course_per_gyro_sigma.unwrap_or(0.0);
    if b > 0.0 && b.ln().abs() <= unit_band(b, sigma) {
        report.say(
            "gyro units",
            Level::Ok,
            format!("deg/s: the course turns {b:.3} deg per gyro degree on {axis}"),
        );
        return;
    }
    let scale = |s: f64| {
        if s >= 1.0 {
            format!("{s:.5}")
        } else {
            format!("{s:.6}")
        }
    };
    let named: Vec<String> = gyro_confusions(b, sigma)
        .into_iter()
        .map(|(s, what)| format!("{what} (scale {})", scale(s)))
        .collect();
    let how = if b > 1.0 {
        format!("the gyro turns {b:.1} times less than the GPS course on {axis}")
    } else {
        format!(
            "the gyro turns {:.1} times more than the GPS course on {axis}",
            1.0 / b
        )
    };
    match named.len() {
        0 => report.say(
            "gyro units",
            Level::Warning,
            format!(
                "the course turns {b:.3} deg per gyro degree on {axis}: neither deg/s nor a usual mix-up of units (rad/s, mdps, a CAN signal's hundredths, a MEMS gyro's raw counts); check the units or the scale (--mount with scale={})",
                scale(b)
            ),
        ),
        1 => report.say("gyro units", Level::Problem, format!("{how}: {}", named[0])),
        _ => report.say(
            "gyro units",
            Level::Problem,
            format!(
                "{how} (+-{:.0} %, the GPS course tells no closer): {}; the logger's or the gyro's datasheet says which, or a fit at the first scale with `--effects gyro_scale`, whose scale error is what is left",
                100.0 * sigma / b,
                named.join(", or ")
            ),
        ),
    }
}

/// Forward from the accelerometer against dv/dt and v * yaw rate.
pub(super) fn forward_axis(
    fixes: &[AtFix],
    up: AxisFinding,
    report: &mut CheckReport,
) -> Option<AxisFinding> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vertical_is_the_axis_that_turns_most_among_those_that_follow_the_course() {
        let fits = |fit: [(f64, f64); 3]| -> Vec<(f64, f64, f64)> {
            fit.iter().map(|&(beta, r2)| (beta, r2, 0.1)).collect()
        };
        // Simulated cars whose pitch gyro sees the yaw rate through the
        // roll, as logged and with the pitch axis written as z.
        assert_eq!(
            vertical_by_course(&fits([(3.0, 0.01), (59.7, 0.87), (1.08, 0.84)])),
            2
        );
        assert_eq!(
            vertical_by_course(&fits([(3.0, 0.08), (1.2, 0.54), (45.8, 0.62)])),
            1
        );
        // A log in rad/s: every axis's beta 57 times larger.
        assert_eq!(
            vertical_by_course(&fits([(170.0, 0.08), (69.0, 0.54), (2600.0, 0.62)])),
            1
        );
        // A clearly better axis wins whatever its beta; none that follows.
        assert_eq!(
            vertical_by_course(&fits([(0.5, 0.05), (57.3, 0.9), (1.0, 0.7)])),
            1
        );
        assert_eq!(
            vertical_by_course(&fits([(0.5, 0.2), (1.0, 0.1), (1.0, 0.25)])),
            2
        );
        // The log's z in deg/s within its precision, about as good as a
        // horizontal axis that sees a share of the turn: z (the bicycle
        // above); far from deg/s, or clearly worse, it is not.
        let cases = [
            (
                [(-13.2, 0.35, 6.4), (-2.6, 0.49, 0.94), (0.98, 0.28, 0.56)],
                2,
            ),
            ([(4.8, 0.52, 1.6), (0.8, 0.56, 0.25), (7.0, 0.27, 4.1)], 1),
            (
                [(2.87, 0.04, 2.0), (1.22, 0.30, 0.25), (1.27, 0.01, 1.61)],
                1,
            ),
            ([(0.5, 0.05, 0.1), (1.0, 0.9, 0.1), (1.0, 0.7, 0.1)], 1),
        ];
        for (fit, vertical) in cases {
            assert_eq!(vertical_by_course(&fit), vertical, "{fit:?}");
        }
    }

    /// An axis that only shares the steady turn (the gyro's bias turns
    /// every axis alike) does not follow the course; one whose turn the
    /// course follows beyond it does.
    #[test]
    fn an_axis_follows_the_course_by_what_it_explains_beyond_a_steady_turn() {
        let n = 40;
        let dt: Vec<f64> = (0..n).map(|i| 1.0 + (i % 3) as f64).collect();
        // The course turns 2 deg/s steadily plus what the gyro turns.
        let gyro: Vec<f64> = (0..n).map(|i| 10.0 * ((i as f64) * 0.7).sin()).collect();
        let course: Vec<f64> = (0..n).map(|i| 2.0 * dt[i] + gyro[i]).collect();
        let (beta, r2, sigma) = fit2(&gyro, &dt, &course);
        assert!((beta - 1.0).abs() < 1e-9 && r2 > 0.999 && sigma < 1e-6);
        // An axis that sees only noise: the steady turn alone explains
        // most of the course about zero, none of it is this axis's.
        let noise: Vec<f64> = (0..n).map(|i| 0.01 * ((i * 7919) % 13) as f64).collect();
        let steady: Vec<f64> = (0..n)
            .map(|i| 2.0 * dt[i] + 0.1 * ((i * 31) % 7) as f64)
            .collect();
        let (_, r2, _) = fit2(&noise, &dt, &steady);
        let (sxx, syy): (f64, f64) = (
            dt.iter().map(|d| d * d).sum(),
            steady.iter().map(|y| y * y).sum(),
        );
        let sxy: f64 = dt.iter().zip(&steady).map(|(d, y)| d * y).sum();
        assert!(
            sxy * sxy / (sxx * syy) > 0.99,
            "the steady turn is most of the course"
        );
        assert!(r2 < 0.2, "partial R^2 {r2}");
    }

    /// Deg/s is read within the ratio's own band, as the mix-ups are.
    #[test]
    fn a_noisy_ratio_near_one_is_deg_per_second() {
        let z = AxisFinding {
            axis: 2,
            sign: 1.0,
            r: 0.8,
            by: "the GPS course",
        };
        let level = |beta: f64, sigma: f64| {
            let mut report = CheckReport {
                course_per_gyro_sigma: Some(sigma),
                ..CheckReport::default()
            };
            gyro_units(beta, z, &mut report);
            report.verdicts[0].level
        };
        // A city ride's 1.42 +- 0.2 (3 sigma: 42 %) and a clean ride's
        // 1.28 +- 0.01 (the band's floor: 30 %) are deg/s ...
        assert_eq!(level(1.42, 0.2), Level::Ok);
        assert_eq!(level(1.28, 0.01), Level::Ok);
        assert_eq!(level(1.0 / 1.28, 0.01), Level::Ok);
        // ... 1.6 is not, however wide (the band's ceiling: 50 %), nor is
        // rad/s.
        assert_eq!(level(1.6, 1.0), Level::Warning);
        assert_eq!(level(57.3, 0.5), Level::Problem);
    }

    /// The mix-ups within the ratio's band, nearest first, one of any two
    /// within 1 %; none near deg/s.
    #[test]
    fn gyro_unit_confusions_are_named_within_the_ratios_precision() {
        let names = |beta: f64, sigma: f64| -> Vec<&str> {
            gyro_confusions(beta, sigma)
                .into_iter()
                .map(|(_, w)| w)
                .collect()
        };
        // Raw counts at +-250 deg/s on a clean ride: those first, ST's
        // within a third beside them.
        let one = gyro_confusions(1.0 / 131.0, 0.001 / 131.0);
        assert_eq!(one.len(), 2, "{one:?}");
        assert!(one[0].1.contains("131 per deg/s") && one[1].1.contains("8.75 mdps"));
        assert!((one[0].0 - 1.0 / 131.0).abs() < 1e-12);
        // The same ratio read 13 % off on a city drive (+-36 %): every
        // mix-up within half of it, the nearest first.
        let city = names(1.0 / 113.5, 0.36 / 113.5);
        assert_eq!(city.len(), 3, "{city:?}");
        assert!(
            city[0].contains("8.75 mdps") && city[2].contains("131 per deg/s"),
            "{city:?}"
        );
        // rad/s as deg/s, also read 21 % off with a tight regression (a
        // robot's), and deg/s as rad/s (ST's 57.14 counts, 0.3 % away, not
        // named beside it).
        assert_eq!(names(57.3, 0.5), vec!["rad/s logged as deg/s"]);
        assert_eq!(names(45.48, 0.5), vec!["rad/s logged as deg/s"]);
        let inverse = names(1.0 / 57.29, 0.0001);
        assert_eq!(inverse[0], "deg/s logged as rad/s", "{inverse:?}");
        assert!(
            inverse.iter().all(|n| !n.contains("17.5 mdps")),
            "{inverse:?}"
        );
        assert_eq!(
            names(0.00101, 0.00001),
            vec!["millidegrees per second (mdps, as ST's drivers give them)"]
        );
        // Half the course's turn is no usual mix-up; deg/s is none either.
        assert!(names(2.0, 0.02).is_empty());
        assert!(names(1.0, 0.02).is_empty());
        assert!(names(0.0, 0.02).is_empty());
    }
}
