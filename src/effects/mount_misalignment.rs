//! `mount_misalignment`: the sensor is not mounted square to the vehicle
//! (2 parameters: yaw and pitch of the vehicle's forward axis in sensor axes, deg).
//!
//! The gyro measures in sensor axes, so the attitude `q_t` integrated from it
//! is the sensor's; the path advances along the vehicle's forward axis `f`,
//! which in sensor axes is
//!
//! ```text
//! f(psi, th) = (cos psi cos th, sin psi cos th, -sin th),   dir_t = q_t f,   p_t = p_{t-1} + q_t f d_t
//! d f / d psi = (-sin psi cos th, cos psi cos th, 0),   d f / d th = (-cos psi sin th, -sin psi sin th, -cos th)
//! ```
//!
//! A mounting rotation has three angles, but a roll about the forward axis
//! leaves `f` unchanged, so only these two are observable from the path. A yaw
//! offset alone is nearly absorbed by the initial heading while the sensor's
//! z axis stays vertical; leaning into turns and pitching on slopes separate them.

use std::f64::consts::FRAC_PI_2;

use nalgebra::Vector3;

use super::gyro_bias::DEG_PER_RAD;
use super::{Columns, Effect, ParamInfo};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct MountMisalignment;

/// Forward axis and its partials for yaw `psi` and pitch `th` (rad).
pub fn forward_axis(psi: f64, th: f64) -> (Vector3<f64>, [Vector3<f64>; 2]) {
    let (sp, cp) = psi.sin_cos();
    let (st, ct) = th.sin_cos();
    (
        Vector3::new(cp * ct, sp * ct, -st),
        [
            Vector3::new(-sp * ct, cp * ct, 0.0),
            Vector3::new(-cp * st, -sp * st, -ct),
        ],
    )
}

impl Effect for MountMisalignment {
    fn id(&self) -> String {
        "mount_misalignment".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        vec![
            ParamInfo::new("forward_yaw", "deg", DEG_PER_RAD).within(FRAC_PI_2),
            ParamInfo::new("forward_pitch", "deg", DEG_PER_RAD).within(FRAC_PI_2),
        ]
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; 2]
    }

    fn forward_axis(&self, p: &[f64]) -> Option<(Vector3<f64>, Columns<Vector3<f64>>)> {
        let (f, [d_psi, d_th]) = forward_axis(p[0], p[1]);
        let mut cols = Columns::default();
        cols.push(0, d_psi);
        cols.push(1, d_th);
        Some((f, cols))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_is_a_unit_vector_with_exact_partials() {
        let (psi, th) = (0.05, -0.03);
        let (f, d) = forward_axis(psi, th);
        assert!((f.norm() - 1.0).abs() < 1e-15);
        assert_eq!(forward_axis(0.0, 0.0).0, Vector3::x());
        let h = 1e-6;
        let fd_psi = (forward_axis(psi + h, th).0 - forward_axis(psi - h, th).0) / (2.0 * h);
        let fd_th = (forward_axis(psi, th + h).0 - forward_axis(psi, th - h).0) / (2.0 * h);
        assert!((fd_psi - d[0]).norm() < 1e-9);
        assert!((fd_th - d[1]).norm() < 1e-9);
    }
}
