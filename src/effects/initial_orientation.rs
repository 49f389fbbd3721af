//! `initial_orientation`: the attitude at the first row (3 parameters, rad).
//!
//! `q_0 = Exp(phi) q_guess`: a world-frame rotation vector `phi` around the
//! start guess (heading from the GPS course, level). Rotating `q_0` by a small
//! world rotation `eps` turns every later step, `delta p_t = eps x (p_t - p_0)`,
//! and `eps = J_l(phi) d phi` (left Jacobian of SO(3)); the model applies both.

use nalgebra::Vector3;

use super::{Effect, ParamInfo};
use crate::model::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct InitialOrientation;

impl Effect for InitialOrientation {
    fn id(&self) -> String {
        "initial_orientation".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        ["east", "north", "up"]
            .iter()
            .map(|a| ParamInfo::new(format!("rotation_{a}"), "deg", 180.0 / std::f64::consts::PI))
            .collect()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; 3]
    }

    fn initial_orientation(&self, p: &[f64]) -> Option<Vector3<f64>> {
        Some(Vector3::new(p[0], p[1], p[2]))
    }
}
