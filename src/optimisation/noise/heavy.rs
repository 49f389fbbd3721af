//! A heavy-tailed GPS error law: independent fixes whose misfits follow a
//! Cauchy law of scale `c` (per axis; the heights their own `c_v`),
//!
//! ```text
//! -2 ln p(m) = 2 ln(1 + m^2 / c^2) + 2 ln(pi c)
//! ```
//!
//! What a city's reflections look like to a least-squares model: most fixes
//! a few metres off, some tens of metres off for a few seconds, with no
//! clean Gaussian population. Its scale is learnt from the misfits by
//! maximum likelihood (`sum m^2 / (m^2 + c^2) = n / 2`), so the inlier
//! scale is set apart from the outliers, which a Gaussian's variance is not.
//! Its restricted likelihood, comparable with the Gaussian laws' of
//! [`super::neg2_log_likelihood`] (the same constants dropped), takes the
//! parameters out by Laplace's approximation with the Cauchy law's Fisher
//! information `1 / (2 c^2)` per misfit, i.e. the `ln det` of a
//! least-squares model of independent fixes of `sqrt(2) c`.

use crate::model::{Model, ModelSpec};

/// The Cauchy scale that maximises the likelihood of the misfits `m`: the
/// root of `sum m^2 / (m^2 + c^2) = n / 2` (falling in `c`), by bisection
/// in `ln c`; `None` with fewer than four misfits or half of them zero.
pub fn cauchy_scale(m: &[f64]) -> Option<f64> {
    if m.len() < 4 {
        return None;
    }
    let n = m.len() as f64;
    let excess = |c: f64| m.iter().map(|x| x * x / (x * x + c * c)).sum::<f64>() - 0.5 * n;
    let (lo, hi) = (1e-3, 1e4);
    if excess(lo) <= 0.0 || excess(hi) >= 0.0 {
        return None;
    }
    Some(crate::statistics::falling_root_in_log(excess, lo, hi))
}

/// The GPS misfits (path minus fix, m) of `model` at `theta`, horizontal
/// and vertical apart (barometric rows left out), from the path at the rows
/// the observations read ([`Model::misfits`]).
pub fn gps_misfits(model: &Model, theta: &[f64]) -> [Vec<f64>; 2] {
    let path = model.sparse_path(theta, model.residual_rows(theta));
    let mut out = [Vec::new(), Vec::new()];
    for (o, m) in model.observations.iter().zip(model.misfits(theta, &path)) {
        if !o.baro {
            out[usize::from(o.axis == 2)].push(m.metres);
        }
    }
    out
}

/// `-2 ln L` of `model`'s path at `theta` under independent Cauchy fixes of
/// scale `c[0]` (horizontal) and `c[1]` (heights), the `free` parameters
/// integrated out (see the module docs); other rows (the bias prior, the
/// barometer) as the model weighs them.
pub fn cauchy_neg2_log_likelihood(
    model: &Model,
    theta: &[f64],
    free: &[bool],
    c: [f64; 2],
) -> Option<f64> {
    let spec = ModelSpec {
        sigma_horizontal_m: std::f64::consts::SQRT_2 * c[0],
        sigma_vertical_m: std::f64::consts::SQRT_2 * c[1],
        gps_tau_s: None,
        gps_white_m: 0.0,
        gps_white_vertical_m: None,
        gps_tau_vertical_s: None,
        ..model.spec.clone()
    };
    let m = Model::with_start(model.signals.clone(), spec, model.start.clone())
        .ok()?
        .least_squares(true);
    let chain = m.chain_system(theta, free)?;
    let (_, log_det) = chain.fit_with_log_det()?;
    let plan = m.obs_plan(theta);
    let (mut data, mut gauss_cost, mut gauss_log_det) = (0.0, 0.0, 0.0);
    for (((o, x), y), link) in m
        .observations
        .iter()
        .zip(&chain.linearisation().x)
        .zip(&plan.target)
        .zip(&plan.links)
    {
        if o.baro {
            continue;
        }
        let r = x - y;
        // This row's Cauchy scale: the Gaussian's sd over sqrt(2) (a
        // logged accuracy scales both alike).
        let ck = 1.0 / (std::f64::consts::SQRT_2 * link.u);
        data += 2.0 * (r * r / (ck * ck)).ln_1p() + 2.0 * (std::f64::consts::PI * ck).ln()
            - (2.0 * std::f64::consts::PI).ln();
        gauss_cost += (link.u * r).powi(2);
        gauss_log_det += -2.0 * link.u.ln();
    }
    let rest = chain.cost() - gauss_cost + m.noise_log_det(theta, free) - gauss_log_det;
    let v = data + rest + log_det;
    v.is_finite().then_some(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The misfits at the Cauchy law's quantiles: the maximum-likelihood
    /// scale is the law's, whatever a few of them far out would do to a
    /// variance (the largest here is 127 times the scale).
    #[test]
    fn the_scale_of_cauchy_misfits_is_recovered() {
        for scale in [0.5, 2.0, 15.0] {
            let n = 400;
            let m: Vec<f64> = (1..=n)
                .map(|i| scale * (std::f64::consts::PI * (i as f64 / (n + 1) as f64 - 0.5)).tan())
                .collect();
            let c = cauchy_scale(&m).expect("a scale");
            assert!((c / scale - 1.0).abs() < 0.01, "{c} for {scale}");
            let sd = (m.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
            assert!(sd > 5.0 * scale, "{sd}");
        }
    }

    #[test]
    fn too_few_or_zero_misfits_have_no_scale() {
        assert_eq!(cauchy_scale(&[1.0, -2.0, 0.5]), None);
        assert_eq!(cauchy_scale(&[0.0; 10]), None);
    }
}
