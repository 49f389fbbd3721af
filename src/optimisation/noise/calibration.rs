//! The odometer gain checked against the GPS error's heavy tails.
//!
//! The gain multiplies every metre of the ride, so least squares weighs
//! every fix on it, and a run of reflected fixes that lies along the track
//! pulls it as far as its squared misfits reach. On the Berlin city drive
//! (docs/real-drives.md) one such run at a crawl (17-25 s, 16-46 m along
//! the track) lengthens the Gaussian fit's gain to 1.0385 +- 0.0139, where
//! the CAN speed fitted to the reference reads 0.992: 4.7 % long, which
//! alone takes the path from 6.2 to 9.3 m off its reference. The
//! heavy-tailed fit ([`super::tails`]: each fix weighed by how unlikely its
//! innovation is under a Student-t law the ride's own innovations chose)
//! discounts that run and reads 1.0086. Held at that, the rest of the model
//! under the Gaussian law ends 6.28 m off.
//!
//! Why not simply the heavy-tailed fit: its weights also move the local path,
//! and there they are not safe. On 7 of 28 simulated urban and city rides it
//! ends more than 5 % further from the truth (a reflection held for tens of
//! seconds reads as consistent fixes after its first), while its gain is as
//! good as the Gaussian's on every one of them (mean error 0.39 % against
//! 0.41 % of the true gain). So only the gain is taken from it, and only
//! where the two disagree by more than chance allows: Hausman's
//! specification test. Both fits estimate the same gain from the same
//! fixes; where the errors are as the Gaussian law says, the Gaussian's is
//! the efficient one and the heavy-tailed fit's is merely less precise, so
//! their difference has the variance `sigma_t^2 - sigma_G^2` and
//!
//! ```text
//! H = (g_t - g_G)^2 / (sigma_t^2 - sigma_G^2)
//! ```
//!
//! is chi-squared of one degree of freedom. The gain is held at `g_t` where
//! `H` passes the same 0.1 % point the tails themselves must pass
//! ([`super::tails::SIGNIFICANT_GAIN`], 10.83: 3.3 sigma). Where the
//! heavy-tailed fit is no less precise (`sigma_t <= sigma_G`) the test has
//! nothing to say and the Gaussian stays. A first rule, the shift in the
//! Gaussian's own sigma beyond 2 (`|g_t - g_G| > 2 sigma_G`), held Berlin's
//! gain on the whole drive (2.15 sigma) but on none of its cuts to the first
//! 150-240 s (1.25-1.94 sigma), where the gains differ just as much (0.029-0.033):
//! a rule at its margin. Hausman's `sqrt(H)` is 7.7 on the whole drive and
//! 3.3-5.9 on the cuts.
//!
//! Measured (docs/real-drives.md): the comma drive and 26 of the 28
//! simulated city and urban rides (seeds 7-20) keep the Gaussian fit to the
//! digit; urban seed 8 (`sqrt(H)` 5.1) holds 0.9756 (true 0.9793, least
//! squares 0.9686) and city seed 9 (4.7) holds 0.9860 (true 0.9863, least
//! squares 0.9871). On Berlin the gain is held at 1.0086 (least squares
//! 1.0385 +- 0.0139; the CAN speed fitted to the reference 0.992).

use crate::contract::HeldParam;
use crate::model::Model;

/// The parameters checked: (effect id, parameter name). The odometer gain
/// is the one that reflections were measured to pull and the heavy-tailed
/// fit reads right. The start pose is not: Berlin's start north moved 2.2
/// sigma as well, and holding it too took the path from 6.28 to 7.51 m.
pub const CHECKED: [(&str, &str); 1] = [("odometer_gain", "gain")];

/// The 0.1 % point of a chi-squared of one degree of freedom that Hausman's
/// statistic must pass (the tails' own threshold).
pub const SIGNIFICANT: f64 = super::tails::SIGNIFICANT_GAIN;

/// One checked parameter: both fits' values and whether the robust one was held.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationCheck {
    pub effect: String,
    pub name: String,
    /// The Gaussian fit's value and 1-sigma.
    pub gaussian: f64,
    pub gaussian_sigma: f64,
    /// The heavy-tailed fit's value and 1-sigma.
    pub robust: f64,
    pub robust_sigma: Option<f64>,
    /// The robust value is held in the final fit.
    pub held: bool,
}

impl CalibrationCheck {
    /// The robust value's shift from the Gaussian's, in the Gaussian's sigma.
    pub fn shift(&self) -> f64 {
        (self.robust - self.gaussian) / self.gaussian_sigma
    }

    /// Hausman's statistic `(g_t - g_G)^2 / (sigma_t^2 - sigma_G^2)`; `None`
    /// where the heavy-tailed fit is no less precise (or its sigma unknown).
    pub fn hausman(&self) -> Option<f64> {
        let excess = self.robust_sigma?.powi(2) - self.gaussian_sigma.powi(2);
        (excess > 0.0).then(|| (self.robust - self.gaussian).powi(2) / excess)
    }

    /// Whether the test holds the robust value.
    fn significant(&self) -> bool {
        self.hausman().is_some_and(|h| h > SIGNIFICANT)
    }

    /// In words: "odometer gain 1.0086 ± 0.0144 from the heavy-tailed fit,
    /// held (least squares read 1.0385 ± 0.0139; Hausman's test 7.7 sigma)".
    pub fn describe(&self) -> String {
        let robust = match self.robust_sigma {
            Some(s) => format!("{:.4} ± {s:.4}", self.robust),
            None => format!("{:.4}", self.robust),
        };
        format!(
            "{} {} {robust} from the heavy-tailed fit, held (least squares read {:.4} ± {:.4}; Hausman's test {:.1} sigma)",
            self.effect.replace('_', " ").trim_end_matches(" gain"),
            self.name,
            self.gaussian,
            self.gaussian_sigma,
            self.hausman().unwrap_or(f64::NAN).sqrt()
        )
    }

    /// The parameter held at its robust value, where the rule asks for it.
    pub fn hold(&self) -> Option<HeldParam> {
        self.held.then(|| HeldParam {
            effect: self.effect.clone(),
            name: self.name.clone(),
            value: self.robust,
        })
    }
}

/// The checked parameters of the Gaussian fit (`gaussian` at `g_theta`)
/// against the heavy-tailed fit (`robust` at `r_theta`), each marked held
/// where the rule asks for it. A parameter the models lack, or whose
/// Gaussian sigma is unknown, is not checked.
pub fn check(
    gaussian: &Model,
    g_theta: &[f64],
    robust: &Model,
    r_theta: &[f64],
) -> Vec<CalibrationCheck> {
    let find = |m: &Model, effect: &str, name: &str| {
        m.param_infos()
            .iter()
            .position(|(id, p)| id == effect && p.name == name)
    };
    let wanted: Vec<_> = CHECKED
        .iter()
        .filter_map(|&(e, n)| Some((e, n, find(gaussian, e, n)?, find(robust, e, n)?)))
        .collect();
    if wanted.is_empty() {
        return Vec::new();
    }
    let g_sigmas = gaussian.parameter_sigmas(g_theta);
    let r_sigmas = robust.parameter_sigmas(r_theta);
    wanted
        .into_iter()
        .filter_map(|(effect, name, gi, ri)| {
            let sigma = g_sigmas.get(gi).copied().flatten()?;
            let (g, r) = (*g_theta.get(gi)?, *r_theta.get(ri)?);
            (sigma > 0.0 && g.is_finite() && r.is_finite()).then(|| {
                let mut check = CalibrationCheck {
                    effect: effect.into(),
                    name: name.into(),
                    gaussian: g,
                    gaussian_sigma: sigma,
                    robust: r,
                    robust_sigma: r_sigmas.get(ri).copied().flatten(),
                    held: false,
                };
                check.held = check.significant();
                check
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gain(gaussian: f64, sigma: f64, robust: f64, robust_sigma: f64) -> CalibrationCheck {
        let mut c = CalibrationCheck {
            effect: "odometer_gain".into(),
            name: "gain".into(),
            gaussian,
            gaussian_sigma: sigma,
            robust,
            robust_sigma: Some(robust_sigma),
            held: false,
        };
        c.held = c.significant();
        c
    }

    /// Measured pairs (docs/real-drives.md): Berlin's whole drive and its
    /// first 180 s hold the robust gain; the comma drive (the heavy-tailed
    /// fit no less precise) and a simulated city ride whose gains agree keep
    /// the Gaussian's.
    #[test]
    fn hausman_holds_the_robust_gain_only_where_the_difference_is_beyond_chance() {
        let berlin = gain(1.0385, 0.0139, 1.0086, 0.0144);
        assert!(berlin.held);
        let h = berlin.hausman().expect("defined");
        // 7.7 at the fit's digits; 7.9 at these four.
        assert!((h.sqrt() - 7.95).abs() < 0.01, "{}", h.sqrt());
        assert!((berlin.shift() + 2.151).abs() < 0.01, "{}", berlin.shift());
        assert_eq!(
            berlin.hold(),
            Some(HeldParam {
                effect: "odometer_gain".into(),
                name: "gain".into(),
                value: 1.0086
            })
        );
        let text = berlin.describe();
        assert!(
            text.starts_with("odometer gain 1.0086 ± 0.0144 from the heavy-tailed fit, held")
                && text.contains("1.0385 ± 0.0139; Hausman's test 7.9 sigma"),
            "{text}"
        );
        assert!(gain(1.0383, 0.0225, 1.0067, 0.0244).held);
        let comma = gain(1.0088, 0.0007, 1.0092, 0.0006);
        assert!(comma.hausman().is_none() && !comma.held && comma.hold().is_none());
        let city = gain(1.0225, 0.0082, 1.0287, 0.0086);
        assert!(!city.held, "{:?}", city.hausman());
    }
}
