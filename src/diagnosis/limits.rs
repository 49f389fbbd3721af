//! Physical limits: what a real vehicle's fitted parameters cannot be.
//!
//! Least squares will happily explain a log with wrong axes or units by
//! turning the sensor upside down or running the odometer backwards, and the
//! path can then still sit near the fixes. Such a result is not a result:
//! `fit` reports it as failed, with the likely cause, and `diagnose` never
//! calls an estimate beyond these limits a significant missing effect.
//!
//! | quantity | limit | why |
//! | --- | --- | --- |
//! | odometer gain | 0.7 .. 1.3 | a wrong circumference or a CAN scale is off by a few percent; beyond 30 % the units are wrong (km/h as m/s is 3.6), negative the sign or the forward axis |
//! | start tilt of the sensor | 30 deg | a sensor is mounted near upright (the fit's own prior is 10 deg); more means the vertical axis is not z, or the roll and pitch rates do not describe the vehicle |
//! | mounting misalignment | 20 deg | a bracket is a few degrees off; 90 or 180 is a swapped or flipped axis |
//! | gyro scale error | 20 % | MEMS scale errors are a few percent; 57x or 1/57 is rad/s against deg/s |

use crate::effects::DEG_PER_RAD;
use crate::model::Model;

use super::Estimate;

/// Limits (see the module documentation).
pub const GAIN_RANGE: (f64, f64) = (0.7, 1.3);
pub const MAX_START_TILT_DEG: f64 = 30.0;
pub const MAX_MOUNT_DEG: f64 = 20.0;
pub const MAX_SCALE_PERCENT: f64 = 20.0;

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

/// The limits a fitted model breaks (empty: a physical result).
pub fn check(model: &Model, theta: &[f64]) -> Vec<Violation> {
    let mut out = Vec::new();
    if let Some(e) = model.effect_index("odometer_gain") {
        let gain = theta[model.range(e).start];
        let cause = if gain <= 0.0 {
            "the path runs against the odometer: its sign, or the sensor's forward axis, is flipped (see `gyropath check`; --mount auto)".to_string()
        } else if (gain / 3.6 - 1.0).abs() < 0.15 || (gain * 3.6 - 1.0).abs() < 0.15 {
            "a factor of 3.6: the speed is in km/h where m/s is read, or the reverse".to_string()
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
    let up = q0 * nalgebra::Vector3::z();
    let tilt = up.z.clamp(-1.0, 1.0).acos() * DEG_PER_RAD;
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

/// Why a diagnosis estimate is physically absurd, if it is: then it cannot be
/// a missing effect, and the axes or units are the likelier fault.
pub fn absurd_estimate(effect: &str, estimate: &[(&String, &Estimate)]) -> Option<String> {
    let worst = |prefix: &str| {
        estimate
            .iter()
            .filter(|(k, _)| k.starts_with(prefix))
            .map(|(k, e)| (k.as_str(), e.value.abs()))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    };
    match effect {
        "mount_misalignment" => worst("forward").filter(|w| w.1 > MAX_MOUNT_DEG).map(|(k, v)| {
            format!(
                "{k} of {v:.0} deg is no bracket's error (limit {MAX_MOUNT_DEG:.0} deg): the log's axes look swapped or flipped; see `gyropath check`"
            )
        }),
        "gyro_scale" => worst("scale_error").filter(|w| w.1 > MAX_SCALE_PERCENT).map(|(k, v)| {
            format!(
                "{k} of {v:.0} % is no MEMS scale error (limit {MAX_SCALE_PERCENT:.0} %): the gyro's units look wrong (rad/s against deg/s is 5,700 %); see `gyropath check`"
            )
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::model::ModelSpec;

    #[test]
    fn a_negative_gain_and_an_upside_down_sensor_are_named_with_their_cause() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 240.0, &[]));
        let model = Model::new(sig, ModelSpec::default()).unwrap();
        let mut theta = model.initial_params();
        assert!(check(&model, &theta).is_empty());
        let gain = model
            .range(model.effect_index("odometer_gain").unwrap())
            .start;
        theta[gain] = -1.7;
        let orientation = model
            .range(model.effect_index("initial_orientation").unwrap())
            .start;
        theta[orientation] = 152f64.to_radians();
        let v = check(&model, &theta);
        assert_eq!(v.len(), 2, "{v:?}");
        assert!(
            v[0].to_string().contains("odometer gain is -1.700") && v[0].cause.contains("sign")
        );
        assert!(v[1].cause.contains("upside down"), "{}", v[1]);
        theta[gain] = 3.55;
        assert!(check(&model, &theta)[0].cause.contains("km/h"));
    }

    #[test]
    fn absurd_mountings_and_scales_are_told_apart_from_real_ones() {
        let e = |v: f64| Estimate {
            value: v,
            sigma: 1.0,
            unit: "deg".into(),
            determined: true,
        };
        let (pitch, yaw) = ("forward_pitch".to_string(), "forward_yaw".to_string());
        let real = [(&pitch, &e(4.0)), (&yaw, &e(-3.0))];
        assert!(absurd_estimate("mount_misalignment", &real).is_none());
        let flipped = [(&pitch, &e(4.0)), (&yaw, &e(185.0))];
        assert!(
            absurd_estimate("mount_misalignment", &flipped)
                .unwrap()
                .contains("185 deg")
        );
        let z = "scale_error_z".to_string();
        assert!(
            absurd_estimate("gyro_scale", &[(&z, &e(40.0))])
                .unwrap()
                .contains("units")
        );
        assert!(absurd_estimate("gyro_scale", &[(&z, &e(3.0))]).is_none());
        assert!(absurd_estimate("gps_lag", &[(&z, &e(400.0))]).is_none());
    }
}
