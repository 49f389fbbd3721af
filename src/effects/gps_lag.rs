//! `gps_lag`: GPS fixes refer to an earlier instant than the row they are
//! logged on (1 parameter, s).
//!
//! Receivers output a fix some hundreds of milliseconds after its epoch, and
//! loggers stamp it on arrival. The fix on row time `t` is then the position
//! at `t - lag`, which the model takes from its own path by linear
//! interpolation inside the step that contains `t - lag` (see
//! `model::observe`): `x = p_j - beta Delta_j`, `d x / d lag = -Delta_j / dt_j`,
//! the path's velocity. Visible as an along-track residual that follows speed.

use super::{Effect, ParamInfo};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct GpsLag;

impl Effect for GpsLag {
    fn id(&self) -> String {
        "gps_lag".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        vec![ParamInfo::new("lag", "s", 1.0).within(5.0)]
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0]
    }

    fn gps_lag(&self, p: &[f64]) -> Option<f64> {
        Some(p[0])
    }
}
