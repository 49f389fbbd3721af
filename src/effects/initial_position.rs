//! `initial_position`: where the path starts (3 parameters, m).
//!
//! `p_0 = p_guess + delta`, with `p_guess` the start guess from the first
//! fixes. Its partials are the identity: a shift of `p_0` shifts every `p_t`.

use nalgebra::Vector3;

use super::{Effect, ParamInfo};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct InitialPosition;

impl Effect for InitialPosition {
    fn id(&self) -> String {
        "initial_position".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        ["east", "north", "up"]
            .iter()
            .map(|a| ParamInfo::new(format!("start_{a}"), "m", 1.0))
            .collect()
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; 3]
    }

    fn initial_position(&self, p: &[f64]) -> Option<Vector3<f64>> {
        Some(Vector3::new(p[0], p[1], p[2]))
    }
}
