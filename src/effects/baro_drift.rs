//! `baro_drift`: the barometric altitude drifts linearly in time (1 parameter, m/h).
//!
//! Air pressure changes with the weather, so over an hour a barometer's
//! altitude wanders by metres. With the drift `k` the barometer reads
//! `baro = up + c_0 + k (t - t_0)`, so a barometric row compares the path's up
//! with `baro + c - k (t - t_0) / 3600` (`c` from `baro_offset`):
//! `d target / d k = -(t - t_0) / 3600`. Only barometric rows are shifted.

use super::{Columns, Effect, ParamInfo, TargetSite};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct BaroDrift;

impl Effect for BaroDrift {
    fn id(&self) -> String {
        "baro_drift".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        vec![ParamInfo::new("drift", "m/h", 1.0)]
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0]
    }

    fn target_shift(&self, p: &[f64], site: &TargetSite) -> Option<(f64, Columns<f64>)> {
        site.baro.then(|| {
            let h = -(site.t - site.t_start) / 3600.0;
            let mut cols = Columns::default();
            cols.push(0, h);
            (p[0] * h, cols)
        })
    }
}
