//! Estimates no real sensor has: a diagnosis candidate whose estimate is
//! beyond the physical limits ([`crate::limits`]) is the axes or units being
//! wrong, never a missing effect.

use super::Estimate;
use crate::limits::{MAX_BARO_DRIFT_M_PER_H, MAX_MOUNT_DEG, MAX_SCALE_PERCENT};

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
        "baro_drift" => worst("drift").filter(|w| w.1 > MAX_BARO_DRIFT_M_PER_H).map(|(k, v)| {
            format!(
                "{k} of {v:.0} m/h is no weather's (limit {MAX_BARO_DRIFT_M_PER_H:.0} m/h): the path and the barometer part for another reason"
            )
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let drift = "drift".to_string();
        assert!(absurd_estimate("baro_drift", &[(&drift, &e(3.0))]).is_none());
        assert!(
            absurd_estimate("baro_drift", &[(&drift, &e(-184.0))])
                .unwrap()
                .contains("184 m/h")
        );
    }
}
