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

/// The unit factor a course-per-gyro ratio points to, when it is one of the usual mix-ups.
pub(super) fn unit_factor(beta: f64) -> Option<f64> {
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

/// Least squares `y = beta x + b z` (no intercept): (beta, R^2 about zero).
pub(super) fn fit2(x: &[f64], z: &[f64], y: &[f64]) -> (f64, f64) {
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

/// An angle (deg) wrapped into -180..180.
pub(super) fn wrap_deg(a: f64) -> f64 {
    (a + 540.0).rem_euclid(360.0) - 180.0
}

/// The axis whose integrated rate follows the GPS course, and beta.
pub(super) fn course_vertical(
    fixes: &[AtFix],
    stretches: &Stretches,
    report: &mut CheckReport,
) -> Option<(AxisFinding, f64)> {
    let (mut dc, mut dt) = (Vec::new(), Vec::new());
    let mut turns: [Vec<f64>; 3] = Default::default();
    for w in stretches.idx.windows(3) {
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

pub(super) fn gyro_units(beta: f64, vertical: AxisFinding, report: &mut CheckReport) {
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
