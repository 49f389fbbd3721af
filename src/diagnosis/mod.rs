//! Seeing where the model fails: residuals in the frame of travel, the fitted
//! bias per segment, held-out validation and the ranking of missing effects.
//!
//! The measurements and the history behind these choices: docs/diagnosis.md
//! (how the missing effect is found, and the validation behind it).

pub mod absurd;
pub mod ranking;
pub mod reference;
pub mod reference_clock;
pub mod residuals;
pub mod structure;
pub mod validation;
pub mod view;
pub mod whiteness;

pub use ranking::{
    Against, Candidate, Diagnosis, Estimate, describe_estimates, diagnose, diagnose_against,
    diagnose_fitted, diagnose_fitted_against,
};
pub use reference::{ErrorStats, ReferenceComparison, ReferenceError};
pub use residuals::{FixResidual, NormalisedSpread, ResidualRms, fix_residuals, rms_per_minute};
pub use structure::{Correlation, structure};
pub use validation::{Folds, HeldOut, HeldOutRms, held_out, held_out_from, held_out_rms};
pub use view::FitView;
pub use whiteness::{Whiteness, whiteness};

use crate::effects::DEG_PER_RAD;
use crate::model::Model;

/// `x` as printed to `decimals` places, with a value that rounds to zero
/// made `+0`: a drop of -0.0004 printed "-0.0 %" in the ranking, a sign
/// that says nothing. Other values are returned unchanged.
pub fn shown(x: f64, decimals: i32) -> f64 {
    if (x * 10f64.powi(decimals)).round() == 0.0 {
        0.0
    } else {
        x
    }
}

/// The total gyro bias (constant plus segment, deg/s) over one stretch of the ride.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SegmentBias {
    /// Start and end of the stretch (log time, s).
    pub t0: f64,
    pub t1: f64,
    pub bias_dps: [f64; 3],
}

/// The 1-sigma (deg/s, per axis) of the bias of every entry of
/// [`segment_biases`], from the parameters' sigmas (internal units, `None`
/// where not free; NaN then). Step 2 holds the constant part and fits the
/// segments, so a segment's sigma is that of the total bias over it; without
/// segments it is the constant's.
pub fn segment_sigmas(model: &Model, sigmas: &[Option<f64>]) -> Vec<[f64; 3]> {
    let axis = |i: usize| {
        sigmas
            .get(i)
            .copied()
            .flatten()
            .map_or(f64::NAN, |v| v * DEG_PER_RAD)
    };
    if let Some(e) = model.effect_index("gyro_bias_segments") {
        let r = model.range(e);
        return (0..r.len() / 3)
            .map(|s| [0, 1, 2].map(|a| axis(r.start + 3 * s + a)))
            .collect();
    }
    match model.effect_index("gyro_bias") {
        Some(e) => vec![[0, 1, 2].map(|a| axis(model.range(e).start + a))],
        None => vec![[f64::NAN; 3]],
    }
}

/// The bias the model subtracts from the gyro, per segment: `b + b_s` of the
/// paper's model. Without segments it is one stretch over the whole ride.
pub fn segment_biases(model: &Model, theta: &[f64]) -> Vec<SegmentBias> {
    let constant = model
        .effect_index("gyro_bias")
        .map(|e| {
            let p = &theta[model.range(e)];
            [p[0], p[1], p[2]]
        })
        .unwrap_or([0.0; 3]);
    let total = |extra: &[f64]| {
        [0, 1, 2].map(|a| (constant[a] + extra.get(a).copied().unwrap_or(0.0)) * DEG_PER_RAD)
    };
    let segments = model
        .effect_index("gyro_bias_segments")
        .and_then(|e| Some((e, model.effects()[e].segment_edges()?)));
    match segments {
        Some((e, edges)) => {
            let p = &theta[model.range(e)];
            edges
                .windows(2)
                .enumerate()
                .map(|(s, w)| SegmentBias {
                    t0: w[0],
                    t1: w[1],
                    bias_dps: total(&p[3 * s..3 * s + 3]),
                })
                .collect()
        }
        None => {
            let t = &model.signals.t;
            vec![SegmentBias {
                t0: t[0],
                t1: t[t.len() - 1],
                bias_dps: total(&[]),
            }]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::shown;

    #[test]
    fn a_value_that_rounds_to_zero_is_shown_without_a_sign() {
        assert_eq!(format!("{:.1}", shown(-0.0004 * 100.0, 1)), "0.0");
        assert_eq!(format!("{:.1}", shown(-0.0, 1)), "0.0");
        assert_eq!(format!("{:.1}", shown(-0.06, 1)), "-0.1");
        assert_eq!(format!("{:+.1}", shown(-0.04, 1)), "+0.0");
        assert_eq!(shown(2.5, 3), 2.5);
        assert!(shown(f64::NAN, 1).is_nan());
    }
}
