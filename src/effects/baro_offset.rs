//! `baro_offset`: the unknown offset of the barometric altitude (1 parameter, m).
//!
//! At a GPS row the barometer gives `up = baro + c`; the vertical residual is
//! `(p_up - baro - c) / sigma_baro`, so `d r / d c = -1 / sigma_baro`. Added
//! automatically whenever the log has a `baro_alt_m` column.

use super::{Columns, Effect, ParamInfo, TargetSite};
use crate::contract::StartGuess;

#[derive(Clone, Copy, Debug, Default)]
pub struct BaroOffset;

impl Effect for BaroOffset {
    fn id(&self) -> String {
        "baro_offset".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        vec![ParamInfo::new("offset", "m", 1.0)]
    }

    fn initial(&self, guess: &StartGuess) -> Vec<f64> {
        vec![guess.baro_offset]
    }

    fn observes_baro(&self) -> bool {
        true
    }

    fn target_shift(&self, p: &[f64], site: &TargetSite) -> Option<(f64, Columns<f64>)> {
        site.baro.then(|| {
            let mut cols = Columns::default();
            cols.push(0, 1.0);
            (p[0], cols)
        })
    }
}
