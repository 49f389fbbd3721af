//! Physical limits: what a real vehicle's fitted parameters cannot be.
//!
//! Least squares will happily explain a log with wrong axes or units by
//! turning the sensor upside down or running the odometer backwards, and the
//! path can then still sit near the fixes. Such a result is not a result:
//! `fit` reports it as failed, with the likely cause, and `diagnose` never
//! calls an estimate beyond these limits a significant missing effect
//! (`diagnosis::absurd`). The optimiser asks them too (a fit beyond them is
//! no stopping point), so they sit beneath both.
//!
//! | quantity | limit | why |
//! | --- | --- | --- |
//! | odometer gain | 0.7 .. 1.3 | a wrong circumference or a CAN scale is off by a few percent; beyond 30 % the units are wrong (km/h as m/s is 3.6, feet as metres 3.28, knots 1.94; see `distance_units`), negative the sign or the forward axis |
//! | start tilt of the sensor | 30 deg | a sensor is mounted near upright (the fit's own prior is 10 deg); more means the vertical axis is not z, or the roll and pitch rates do not describe the vehicle |
//! | tilt of the sensor along the ride | 90 deg | a vehicle never rides on its side or upside down (a motorcycle's lean and a tilted mount together stay under it); more means the fit turned the sensor over, most often across a gyro stop's free roll and pitch turns, to explain wrong axes |
//! | mounting misalignment | 20 deg | a bracket is a few degrees off; 90 or 180 is a swapped or flipped axis |
//! | gyro scale error | 20 % | MEMS scale errors are a few percent; 57x or 1/57 is rad/s against deg/s |
//! | barometer drift (diagnosis only) | 50 m/h | the weather moves the pressure by at most a few hPa an hour (a strong front 3 hPa, 25 m); hundreds of m/h is a vertical misfit of something else (on 30 s simulated rides whose barometers drift 1-4 m/h, `baro_drift` read 184-528 m/h) |
//!
//! The measurements and the history behind these choices: docs/vehicles.md
//! (physical limits, measured on real drives).

use crate::effects::DEG_PER_RAD;
use crate::model::{Model, PathAt};

/// Limits (see the module documentation).
pub const GAIN_RANGE: (f64, f64) = (0.7, 1.3);
pub const MAX_START_TILT_DEG: f64 = 30.0;
pub const MAX_TILT_DEG: f64 = 90.0;
pub const MAX_MOUNT_DEG: f64 = 20.0;
pub const MAX_SCALE_PERCENT: f64 = 20.0;
pub const MAX_BARO_DRIFT_M_PER_H: f64 = 50.0;

/// A fitted quantity beyond its physical limit, and what probably caused it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Violation {
    pub quantity: String,
    pub value: String,
    pub limit: String,
    pub cause: String,
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} is {} (limit {}): {}",
            self.quantity, self.value, self.limit, self.cause
        )
    }
}

/// The limits a fitted model breaks (empty: a physical result): its
/// parameters' ([`parameters`]) and its path's distance from the fixes
/// ([`path_far_from_fixes`]).
pub fn check(model: &Model, theta: &[f64]) -> Vec<Violation> {
    let mut rows: Vec<usize> = model.signals.fixes.iter().map(|f| f.row).collect();
    rows.dedup();
    check_on(model, theta, &model.sparse_path(theta, rows))
}

/// [`check`] on a path already swept at `theta` that holds every fix's row
/// (as the residual rows of a snapshot do): no sweep of its own.
pub fn check_on(model: &Model, theta: &[f64], path: &impl PathAt) -> Vec<Violation> {
    let mut out = parameters(model, theta);
    out.extend(path_far_from_fixes(model, path));
    out.extend(turned_over(model, path));
    out
}

/// The angle (deg) between the sensor's z in attitude `q` and the vertical.
fn tilt_deg(q: &nalgebra::UnitQuaternion<f64>) -> f64 {
    (q * nalgebra::Vector3::z()).z.clamp(-1.0, 1.0).acos() * DEG_PER_RAD
}

/// The sensor's tilt (its z from the vertical) at the fixes' rows, where
/// over [`MAX_TILT_DEG`]: the fit turned the sensor over somewhere after
/// its start, whose own tilt [`parameters`] checks. A gyro stop's roll and
/// pitch turns are free (see `effects::gyro_stops`), and a car logged
/// upside down whose sensor turns were bridged as stops was fitted rolling
/// 170 and 251 deg across two of them, 12 m from fixes 1.5 m off, with a
/// GPS noise of 10 m learnt from its own misfit. `path` must hold every
/// fix's row.
pub fn turned_over(model: &Model, path: &impl PathAt) -> Option<Violation> {
    let (tilt, t) = model
        .signals
        .fixes
        .iter()
        .map(|f| (tilt_deg(&path.q_at(f.row)), f.t))
        .max_by(|a, b| a.0.total_cmp(&b.0))?;
    (tilt > MAX_TILT_DEG).then(|| Violation {
        quantity: "tilt of the sensor along the ride".into(),
        value: format!("{tilt:.0} deg at t = {t:.1} s"),
        limit: format!("{MAX_TILT_DEG:.0} deg"),
        cause: "a vehicle does not ride on its side or upside down: the fit turned the sensor over to explain turns it could not, most often wrong axes (see `gyropath check`; --mount auto)".into(),
    })
}

/// A path whose distance from the fixes, at the upper quartile of the fixes
/// (a quarter of them may be jumps of a city's reflections), is more than
/// this many times the fixes' own scatter ([`fix_scatter_m`]) follows no GPS
/// at all. The median is not enough: a path that follows the fixes for half
/// of the ride and then leaves them by hundreds of metres has a small one.
pub const MAX_PATH_TO_SCATTER: f64 = 5.0;
/// ... and never less than this (m). The scatter is the fixes' jitter from
/// second to second, not a street canyon's offset that lasts tens of seconds:
/// a right path in a city misses a quarter of its fixes by 10-30 m (the
/// bundled city example's by 14.3 m, with a jitter of 1.9 m; Berlin's real
/// drive by 20 m), while a model that cannot place its path misses them by
/// hundreds of metres.
pub const MIN_PATH_LIMIT_M: f64 = 50.0;

/// The fixes' own scatter (m): see [`crate::statistics::track_scatter_m`].
pub fn fix_scatter_m(fixes: &[crate::signals::Fix]) -> Option<f64> {
    let t: Vec<f64> = fixes.iter().map(|f| f.t).collect();
    let en: Vec<[f64; 2]> = fixes.iter().map(|f| f.en).collect();
    crate::statistics::track_scatter_m(&t, &en)
}

/// The path is far worse than the fixes' own scatter: the model cannot follow
/// the GPS (a path effect left out of the model, wrong axes or units), and its
/// path is no result, however well the optimiser converged.
/// `path` must hold every fix's row.
pub fn path_far_from_fixes(model: &Model, path: &impl PathAt) -> Option<Violation> {
    let fixes = &model.signals.fixes;
    let scatter = fix_scatter_m(fixes)?;
    let mut distances: Vec<f64> = fixes
        .iter()
        .map(|f| {
            let p = path.p_at(f.row);
            (p.x - f.en[0]).hypot(p.y - f.en[1])
        })
        .collect();
    if distances.is_empty() {
        return None;
    }
    distances.sort_by(f64::total_cmp);
    let upper_quartile = distances[(3 * distances.len()) / 4];
    let limit = (MAX_PATH_TO_SCATTER * scatter).max(MIN_PATH_LIMIT_M);
    (upper_quartile > limit).then(|| Violation {
        quantity: "path's distance from the GPS fixes".into(),
        value: format!("{upper_quartile:.1} m or more from a quarter of the fixes"),
        limit: format!(
            "{limit:.1} m: {MAX_PATH_TO_SCATTER:.0} x the fixes' own scatter of {scatter:.1} m, at least {MIN_PATH_LIMIT_M:.0} m"
        ),
        cause: "the model cannot follow the GPS: an effect the path needs may be missing (effects are added to the paper's model; `-ID` takes one out), or the log's axes or units are wrong (see `gyropath check`)".into(),
    })
}

/// What a factor `g` between the log's distance and the true one says
/// about the log's units (`g`: metres per logged unit, the fit's odometer
/// gain, or the GPS track's length over the odometer's), where it is near
/// one of the usual confusions: km/h read as m/s (`1 / 3.6`), feet as
/// metres (`0.3048`), knots (`0.514`, NMEA's speed) or mph (`0.447`) as
/// m/s, km (`1000`) or miles (`1609`) as metres, centimetres (`0.01`), a
/// wheel counted twice a revolution (`2`: two magnets, or a counter on
/// both edges of each pulse; 2.8 % from knots, and before it was listed
/// the comma drive's odometer doubled read as knots), and each the other
/// way round. The nearest in ratio is named if within
/// [`UNIT_TOLERANCE`]: feet and km/h are only 9 % apart (`3.28` against
/// `3.6`), so a wheel's few percent decide between them, not a wide band.
pub fn distance_units(g: f64) -> Option<String> {
    if !(g.is_finite() && g > 0.0) {
        return None;
    }
    const CONFUSIONS: [(f64, &str); 8] = [
        (
            2.0,
            "one count and two per wheel revolution (two magnets, or both edges of each pulse)",
        ),
        (3.6, "km/h and m/s"),
        (1.0 / 0.3048, "feet and metres"),
        (1.0 / 0.514_444, "knots and m/s"),
        (1.0 / 0.447_04, "mph and m/s"),
        (1000.0, "metres and km"),
        (1609.344, "metres and miles"),
        (100.0, "centimetres and metres"),
    ];
    // How far `g` lies from the factor `f` or its inverse, in ratio.
    let off = |f: f64| (g.ln().abs() - f.ln()).abs();
    let &(f, pair) = CONFUSIONS
        .iter()
        .min_by(|a, b| off(a.0).total_cmp(&off(b.0)))?;
    let shown = if f > 10.0 {
        format!("{f:.0}")
    } else {
        format!("{f:.3}")
    };
    let way = if g < 1.0 { "long" } else { "short" };
    (off(f) < UNIT_TOLERANCE.ln_1p()).then(|| {
        format!(
            "a factor of {shown}, as between {pair}: the log's distance is {shown} times too {way}"
        )
    })
}

/// How far (as a fraction) a factor may lie from a unit confusion's to be
/// named by [`distance_units`]: a wheel's circumference or a CAN scale is a
/// few percent off.
pub const UNIT_TOLERANCE: f64 = 0.06;

/// The limits a fitted model's parameters break.
pub fn parameters(model: &Model, theta: &[f64]) -> Vec<Violation> {
    let mut out = Vec::new();
    if let Some(e) = model.effect_index("odometer_gain") {
        let gain = theta[model.range(e).start];
        let cause = if gain <= 0.0 {
            "the path runs against the odometer: its sign, or the sensor's forward axis, is flipped (see `gyropath check`; --mount auto)".to_string()
        } else if let Some(units) = distance_units(gain) {
            units
        } else {
            "more than a wrong circumference explains: the odometer's units (ticks per metre, speed units) look wrong".to_string()
        };
        if !(GAIN_RANGE.0..=GAIN_RANGE.1).contains(&gain) {
            out.push(Violation {
                quantity: "odometer gain".into(),
                value: format!("{gain:.3}"),
                limit: format!("{} to {}", GAIN_RANGE.0, GAIN_RANGE.1),
                cause,
            });
        }
    }
    let (q0, _, _) = model.initial_state(theta);
    let tilt = tilt_deg(&q0);
    if tilt > MAX_START_TILT_DEG {
        let cause = if tilt > 90.0 {
            "the sensor is upside down: the sign of its vertical axis is flipped (see `gyropath check`; --mount auto)".to_string()
        } else {
            "either the vertical axis is not the log's z (see `gyropath check`; --mount auto), or the roll and pitch rates do not describe the vehicle's attitude and the tilt stands in for something else, such as a yaw scale error (--attitude planar)".to_string()
        };
        out.push(Violation {
            quantity: "start tilt of the sensor".into(),
            value: format!("{tilt:.0} deg"),
            limit: format!("{MAX_START_TILT_DEG:.0} deg"),
            cause,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::model::ModelSpec;

    #[test]
    fn a_unit_confusion_is_named_by_the_nearest_factor_and_a_wheel_is_not() {
        let said = |g: f64| distance_units(g).unwrap_or_default();
        assert!(
            said(1.0 / 3.6).contains("km/h and m/s"),
            "{}",
            said(1.0 / 3.6)
        );
        assert!(said(1.0 / 3.6).contains("3.600 times too long"));
        // Feet and km/h are 9 % apart: a wheel 3 % long is still feet.
        assert!(said(0.3048 * 1.03).contains("feet and metres"));
        assert!(said(1.0 / 3.6 * 1.03).contains("km/h"));
        assert!(said(0.514_444).contains("knots"));
        // A wheel counted twice is 2.8 % from knots: the nearer is named.
        assert!(said(1.0 / 1.984).contains("two per wheel revolution"));
        assert!(said(2.0 * 1.01).contains("two per wheel revolution"));
        assert!(said(0.514_444 * 1.005).contains("knots"));
        assert!(said(1000.0 * 0.98).contains("metres and km"));
        assert!(said(1000.0).contains("1000 times too short"));
        assert!(said(1609.0).contains("miles"));
        for wheel in [0.75, 0.9, 1.0, 1.1, 1.3] {
            assert_eq!(distance_units(wheel), None, "{wheel}");
        }
        for nonsense in [0.0, -0.3048, f64::NAN, f64::INFINITY] {
            assert_eq!(distance_units(nonsense), None, "{nonsense}");
        }
    }

    #[test]
    fn a_negative_gain_and_an_upside_down_sensor_are_named_with_their_cause() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 240.0, &[]));
        let model = Model::new(sig, ModelSpec::default()).unwrap();
        let mut theta = model.initial_params();
        assert!(parameters(&model, &theta).is_empty());
        let gain = model
            .range(model.effect_index("odometer_gain").unwrap())
            .start;
        theta[gain] = -1.7;
        let orientation = model
            .range(model.effect_index("initial_orientation").unwrap())
            .start;
        theta[orientation] = 152f64.to_radians();
        let v = parameters(&model, &theta);
        assert_eq!(v.len(), 2, "{v:?}");
        assert!(
            v[0].to_string().contains("odometer gain is -1.700") && v[0].cause.contains("sign")
        );
        assert!(v[1].cause.contains("upside down"), "{}", v[1]);
        theta[gain] = 3.55;
        assert!(parameters(&model, &theta)[0].cause.contains("km/h"));
    }

    #[test]
    fn a_sensor_turned_over_across_a_gyro_stop_is_no_result() {
        let mut sig = crate::testing::simulated_signals(5, 60.0, &[]);
        sig.gyro_stops = vec![(12.0, 17.5)];
        let model = Model::new(Arc::new(sig), ModelSpec::default()).unwrap();
        let stops = model.range(model.effect_index("gyro_stops").unwrap());
        let mut theta = model.initial_params();
        let over = |theta: &[f64]| turned_over(&model, &model.trajectory(theta));
        assert!(over(&theta).is_none());
        // A bicycle may come out of a stop leaning the other way ...
        theta[stops.start] = 40f64.to_radians();
        assert!(over(&theta).is_none());
        assert!(check(&model, &theta).is_empty());
        // ... but not on its back.
        theta[stops.start] = 170f64.to_radians();
        let v = over(&theta).expect("turned over");
        let tilt: f64 = v.value.split(' ').next().unwrap().parse().unwrap();
        assert!((150.0..=180.0).contains(&tilt), "{v}");
        assert!(v.cause.contains("--mount auto"), "{v}");
        assert!(parameters(&model, &theta).is_empty());
        assert!(check(&model, &theta).contains(&v));
    }

    #[test]
    fn a_path_that_does_not_follow_the_fixes_is_no_result() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 240.0, &[]));
        let scatter = fix_scatter_m(&sig.fixes).unwrap();
        // The simulator's open-sky fixes scatter by a metre or two about the road.
        assert!((0.3..4.0).contains(&scatter), "scatter {scatter} m");
        let mut fit = crate::optimisation::Reconstruction::new(
            sig,
            crate::optimisation::FitSettings::default(),
        )
        .unwrap();
        fit.finish();
        let (model, mut theta) = fit.into_parts();
        let start = model
            .range(model.effect_index("initial_position").unwrap())
            .start;
        let near = path_far_from_fixes(&model, &model.trajectory(&theta));
        assert!(near.is_none(), "{near:?}");
        theta[start] += 500.0;
        let v = path_far_from_fixes(&model, &model.trajectory(&theta)).expect("500 m off");
        assert!(
            v.value.starts_with("50") || v.value.starts_with("49"),
            "{v}"
        );
        assert!(
            check(&model, &theta)
                .iter()
                .any(|c| c.quantity == v.quantity)
        );
        theta[start] -= 460.0;
        assert!(
            path_far_from_fixes(&model, &model.trajectory(&theta)).is_none(),
            "40 m off is what a street canyon can do"
        );
    }

    #[test]
    fn the_fixes_scatter_is_their_noise_about_a_smooth_track() {
        use crate::signals::Fix;
        // A 10 m/s turn of radius 50 m with +-2 m uniform noise per axis (a
        // fixed pseudo-random sequence): the local quadratic follows the turn.
        let fixes: Vec<Fix> = (0..120)
            .map(|k| {
                let t = k as f64;
                let phase = 0.2 * t;
                let noise = |s: f64| 2.0 * ((s * 12.9898).sin() * 43758.5453).fract();
                Fix {
                    row: k,
                    t,
                    en: [
                        50.0 * phase.cos() + noise(t),
                        50.0 * phase.sin() + noise(t + 0.5),
                    ],
                    up: None,
                    baro: None,
                    hacc: None,
                    vacc: None,
                    hdop: None,
                }
            })
            .collect();
        let scatter = fix_scatter_m(&fixes).unwrap();
        assert!((0.8..4.0).contains(&scatter), "scatter {scatter} m");
        assert!(fix_scatter_m(&fixes[..4]).is_none());
    }
}
