//! What a model is made of ([`ModelSpec`]: its effects and the noise
//! settings that shape them) and why one could not be built ([`ModelError`]).

use thiserror::Error;

use super::StartError;
use crate::rotation::Increment;

/// Why a model could not be built.
#[derive(Debug, Error)]
pub enum ModelError {
    #[error("unknown effect '{id}' (known: paper, {known})")]
    UnknownEffect { id: String, known: String },
    #[error("effect '{effect}' does not apply: {reason}")]
    NotApplicable { effect: String, reason: String },
    #[error("{0}")]
    Setting(String),
    #[error(transparent)]
    Start(#[from] StartError),
}

/// What the model is made of: which effects, and the settings that shape them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModelSpec {
    /// Effect ids (`paper` expands to the paper's five).
    pub effects: Vec<String>,
    /// Length of a bias segment (s).
    pub segment_s: f64,
    /// Random-walk density of the segment-bias prior (deg/s/sqrt(s)); `None` = the paper (no prior).
    pub bias_walk_dps_sqrt_s: Option<f64>,
    /// GPS horizontal noise (m): of every fix when fixes are independent,
    /// of the wander (the correlated part) with a correlation time.
    pub sigma_horizontal_m: f64,
    /// GPS altitude noise (m).
    pub sigma_vertical_m: f64,
    /// Barometric altitude noise (m).
    pub sigma_baro_m: f64,
    /// Correlation time of the GPS error (s, first-order Gauss-Markov, see
    /// [`noise`]); `None` = independent fixes (the paper).
    #[serde(default)]
    pub gps_tau_s: Option<f64>,
    /// With a correlation time: the jitter of each fix on top of the wander
    /// (m, horizontal; the vertical one is `gps_white_vertical_m` or keeps the
    /// ratio of the vertical sigma to the horizontal; scaled by the fix's
    /// logged accuracy). See [`noise`].
    #[serde(default)]
    pub gps_white_m: f64,
    /// The GPS heights' own jitter (m) with a correlation time, when known
    /// apart from the horizontal one (the noise search takes it from the
    /// heights' misfits); `None`: the horizontal jitter times the heights'
    /// ratio `sigma_vertical_m / sigma_horizontal_m`.
    #[serde(default)]
    pub gps_white_vertical_m: Option<f64>,
    /// The GPS heights' own correlation time (s), when known apart from the
    /// horizontal one (the noise search estimates it); `None`: `gps_tau_s`.
    /// A 3D path's heights misfit over longer times than its horizontal
    /// fixes (the pitch follows only the heights): one correlation time for
    /// both read that as a slow horizontal wander (a 6-hour ride: 2.57 m over
    /// 187 s for a true 1.5 m over 60 s; 1.47 m over 59 s without the heights).
    #[serde(default)]
    pub gps_tau_vertical_s: Option<f64>,
    pub increment: Increment,
    /// Heavy tails of the GPS error learnt from this ride (see
    /// [`GpsTails`]); `None`: Gaussian. Not saved with the settings: its
    /// per-fix scales belong to one ride, and the next ride's fit learns its own.
    #[serde(skip)]
    pub gps_tails: Option<GpsTails>,
    /// Parameters held at values found apart from this fit's own least
    /// squares (the odometer gain of the heavy-tailed fit, where the
    /// Gaussian's is off by more than its sigma allows; see
    /// `optimisation::calibration`). Not saved with the settings: like the
    /// tails, a held value belongs to one ride's fixes.
    #[serde(skip)]
    pub held: Vec<HeldParam>,
    /// The ends of the GPS error's correlation time's 1-sigma range (s),
    /// over which the fit's uncertainty (the path's band, the reported
    /// sigmas) is averaged (see [`ModelSpec::band_specs`]); `None`: drawn
    /// under the fit's own settings. The noise search sets it. Not saved
    /// with the settings: a range belongs to one ride.
    #[serde(skip)]
    pub band_taus: Option<(f64, f64)>,
}

/// A parameter held at `value` (internal units), named as the report names
/// it: its effect's id and the parameter's name (`odometer_gain`, `gain`).
#[derive(Clone, Debug, PartialEq)]
pub struct HeldParam {
    pub effect: String,
    pub name: String,
    pub value: f64,
}

/// A Student-t GPS error: each fix's error (its jitter and the wander's step
/// into it) is Gaussian with its variance divided by a weight `w_k` of its
/// own, `w_k ~ Gamma(nu / 2, nu / 2)`, so that a fix's bivariate innovation
/// follows a t law of `nu` degrees of freedom. A reflection that puts a fix
/// tens of metres off is then one unlikely draw of a heavy-tailed step, not
/// evidence that the whole error wanders that far; the fit holds the weights
/// at their expectation given the fixes (`optimisation::noise::tails`) and
/// scales each fix's noise by `1 / sqrt(w_k)` (relative to the ride's median).
#[derive(Clone, Debug, PartialEq)]
pub struct GpsTails {
    /// Degrees of freedom of the t law (small: heavy tails).
    pub nu: f64,
    /// Per fix (indexed as `Signals::fixes`), the factor on its horizontal
    /// noise, `1 / sqrt(w_k)` over the ride's median of it.
    pub scale: std::sync::Arc<[f64]>,
}

impl GpsTails {
    /// The factor on fix `i`'s horizontal noise (1 for a fix it does not cover).
    pub fn scale_of(&self, i: usize) -> f64 {
        self.scale.get(i).copied().unwrap_or(1.0)
    }
}

impl Default for ModelSpec {
    fn default() -> Self {
        Self {
            effects: vec!["paper".into()],
            segment_s: 5.0,
            bias_walk_dps_sqrt_s: Some(DEFAULT_BIAS_WALK),
            sigma_horizontal_m: 3.0,
            sigma_vertical_m: 8.0,
            sigma_baro_m: 1.0,
            gps_tau_s: None,
            gps_white_m: 0.0,
            gps_white_vertical_m: None,
            gps_tau_vertical_s: None,
            increment: Increment::Exact,
            gps_tails: None,
            held: Vec::new(),
            band_taus: None,
        }
    }
}

impl ModelSpec {
    /// The two settings the fit's uncertainty is averaged over: these, with
    /// the correlation time at either end of [`ModelSpec::band_taus`] and the
    /// horizontal wander's sigma moved with it along the ridge the likelihood
    /// follows, `sigma'^2 / tau' = sigma^2 / tau`; `None` for these settings
    /// alone.
    ///
    /// Why: a ride pins the wander's short-lag spread, `2 sigma^2 dt / tau`
    /// (`sigma^2 / tau` is what its likelihood curves in), much better than
    /// its correlation time, and the path's absolute error is the wander's
    /// slow part, which the time decides. A band drawn under the estimate
    /// alone takes the time as known; on a ride only a few correlation times
    /// long it is not, and it comes out short (the start position takes the
    /// slow part as one offset that the restricted likelihood integrates out
    /// unseen): on simulated 5-minute rides that band held the truth at
    /// 76 % of the rows. Averaged over the time's posterior,
    /// `Cov = (Cov(tau_-) + Cov(tau_+)) / 2` at its 1-sigma ends (the
    /// two-point Gauss rule for a Gaussian in `ln tau`: exact for a
    /// covariance cubic in it), it holds it at 86 %, and at 95 % on
    /// 10-minute rides (93 % before; docs/uncertainty.md).
    pub fn band_specs(&self) -> Option<[ModelSpec; 2]> {
        let (tau, (low, high)) = (self.gps_tau_s?, self.band_taus?);
        if !(0.0 < low && low < tau && tau < high && high.is_finite()) {
            return None;
        }
        let at = |t: f64| {
            let mut spec = self.clone();
            // The heights keep their own jitter (by default it follows the
            // horizontal one at the heights' ratio).
            spec.gps_white_vertical_m = Some(
                self.gps_white_vertical_m
                    .unwrap_or(self.gps_white_m * self.sigma_vertical_m / self.sigma_horizontal_m),
            );
            spec.sigma_horizontal_m = self.sigma_horizontal_m * (t / tau).sqrt();
            spec.gps_tau_s = Some(t);
            spec.band_taus = None;
            spec
        };
        Some([at(low), at(high)])
    }

    /// The GPS error's correlation time per axis (east, north, up): the
    /// heights' own where set; `None` everywhere for independent fixes.
    pub fn gps_taus(&self) -> [Option<f64>; 3] {
        let tau = self.gps_tau_s;
        [tau, tau, tau.and(self.gps_tau_vertical_s.or(tau))]
    }

    /// The GPS error law these settings assume, in words, to label every
    /// misfit measured under it ("independent GPS fixes of 3.0 m", "a GPS
    /// error wandering 0.55 m over 41 s + 0.11 m jitter"): `fit` estimates the law from the
    /// ride while `diagnose` ranks under the law as set, so the same ride
    /// has two fit errors and each must say which it is.
    pub fn gps_noise_text(&self) -> String {
        let robust = if self.effects.iter().any(|e| e == "gps_outliers") {
            ", outliers down-weighted"
        } else {
            ""
        };
        let robust = match &self.gps_tails {
            Some(t) => format!(", Student-t fixes (nu {:.1}){robust}", t.nu),
            None => robust.to_string(),
        };
        match self.gps_tau_s {
            Some(tau) => format!(
                "a GPS error wandering {:.2} m over {tau:.0} s + {:.2} m jitter{robust}",
                self.sigma_horizontal_m, self.gps_white_m
            ),
            None => format!(
                "independent GPS fixes of {:.1} m{robust}",
                self.sigma_horizontal_m
            ),
        }
    }
}

/// Default random-walk density of the segment-bias prior (deg/s/sqrt(s)):
/// the bias instability of a consumer MEMS gyro (about 10 deg/h drifting over
/// minutes), not tuned on any ride.
pub const DEFAULT_BIAS_WALK: f64 = 0.004;
