//! `initial_orientation`: the attitude at the first row (3 parameters, rad).
//!
//! `q_0 = Exp(phi) q_guess`: a world-frame rotation vector `phi` around the
//! start guess (heading from the GPS course, level). Rotating `q_0` by a small
//! world rotation `eps` turns every later step, `delta p_t = eps x (p_t - p_0)`,
//! and `eps = J_l(phi) d phi` (left Jacobian of SO(3)); the model applies both.
//!
//! The tilt part (`phi_east`, `phi_north`) has a prior `N(0, 10 deg)`: a
//! sensor on a bicycle or car sits within a few degrees of level, and early
//! in a ride (step 1's first window) the roll tilt trades off almost freely
//! against the roll-axis bias. Without the prior a fit could settle on a 20
//! degree roll with a matching 0.8 deg/s bias that looks fine for two minutes
//! and then rolls the path over. Heading (`phi_up`) is left free. In a planar
//! model (see [`crate::signals::Attitude`]) the tilt is held at zero: a free
//! tilt of the yaw axis would scale the turns by its cosine.

use nalgebra::Vector3;

use super::{Effect, ParamInfo, PriorRows};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct InitialOrientation {
    /// Heading only: the tilt is not fitted.
    pub planar: bool,
}

/// Prior standard deviation of the start tilt (rad): 10 degrees.
const TILT_PRIOR_SIGMA_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

impl Effect for InitialOrientation {
    fn id(&self) -> String {
        "initial_orientation".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        ["east", "north", "up"]
            .iter()
            .map(|a| {
                ParamInfo::new(format!("rotation_{a}"), "deg", 180.0 / std::f64::consts::PI)
                    .within(std::f64::consts::FRAC_PI_2)
            })
            .collect()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; 3]
    }

    fn fixed(&self, i: usize) -> bool {
        self.planar && i < 2
    }

    fn initial_orientation(&self, p: &[f64]) -> Option<Vector3<f64>> {
        Some(Vector3::new(p[0], p[1], p[2]))
    }

    fn n_prior(&self) -> usize {
        2
    }

    /// Residuals `phi_east / sigma`, `phi_north / sigma`.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        let w = 1.0 / TILT_PRIOR_SIGMA_RAD;
        for a in 0..2 {
            let row = out.residuals.len();
            out.residuals.push(w * p[a]);
            out.entries.push((row, a, w));
        }
    }
}
