//! What the noise search found, and how sure: each setting with its
//! 1-sigma range or the bound it reached, and all of it in words.

use super::*;

/// A setting and its 1-sigma range (the range is multiplicative: the
/// likelihood is close to Gaussian in the logarithm).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimated {
    pub value: f64,
    pub low: f64,
    pub high: f64,
    /// Estimated (`false`: held at the value given).
    pub estimated: bool,
    /// Whether the ride only bounds the setting from one side.
    #[serde(default)]
    pub limit: Limit,
}

/// A setting the likelihood keeps pushing to the edge of the search: the
/// ride cannot tell how far beyond it the setting lies (a correlation time
/// longer than the ride, a jitter too small to see), only that it is beyond
/// `low` (`AtLeast`) or within `high` (`AtMost`), at 1 sigma.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Limit {
    #[default]
    None,
    AtLeast,
    AtMost,
}

/// In JSON: `null` (no limit; it was the string `"None"`, which no JSON
/// reader takes for nothing), `"at_least"`, `"at_most"`.
impl serde::Serialize for Limit {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Limit::None => s.serialize_none(),
            Limit::AtLeast => s.serialize_some("at_least"),
            Limit::AtMost => s.serialize_some("at_most"),
        }
    }
}

impl<'de> serde::Deserialize<'de> for Limit {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text: Option<String> = serde::Deserialize::deserialize(d)?;
        match text.as_deref() {
            None | Some("None") => Ok(Limit::None),
            Some("at_least" | "AtLeast") => Ok(Limit::AtLeast),
            Some("at_most" | "AtMost") => Ok(Limit::AtMost),
            Some(other) => Err(serde::de::Error::custom(format!(
                "unknown limit '{other}' (null, at_least or at_most)"
            ))),
        }
    }
}

impl Estimated {
    pub(crate) fn held(value: f64) -> Self {
        Self {
            value,
            low: value,
            high: value,
            estimated: false,
            limit: Limit::None,
        }
    }

    /// `value` with its range, e.g. "2.1 m (1.8-2.5)", or its one-sided
    /// bound, e.g. "at most 0.03 m".
    pub fn describe(&self, unit: &str, digits: usize) -> String {
        if self.limit == Limit::AtLeast {
            format!("at least {:.d$} {unit}", self.low, d = digits)
        } else if self.limit == Limit::AtMost {
            format!("at most {:.d$} {unit}", self.high, d = digits)
        } else if self.estimated {
            format!(
                "{:.d$} {unit} ({:.d$}-{:.d$})",
                self.value,
                self.low,
                self.high,
                d = digits
            )
        } else {
            format!("{:.d$} {unit} (set)", self.value, d = digits)
        }
    }
}

/// The noise settings the data prefer.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseEstimate {
    /// GPS horizontal sigma per axis (m).
    pub gps_sigma_m: Estimated,
    /// Correlation time of the GPS error (s).
    pub gps_tau_s: Estimated,
    /// The jitter of each fix on top of the wander (m per axis, horizontal).
    #[serde(default = "not_estimated")]
    pub gps_white_m: Estimated,
    /// Bias-walk density (deg/s/sqrt(s)).
    pub bias_walk: Estimated,
    /// The GPS heights' wander over the horizontal's.
    #[serde(default = "default_vertical_ratio")]
    pub gps_vertical_ratio: Estimated,
    /// The GPS heights' own jitter (m), from their misfits' second
    /// differences; `None`: the horizontal jitter times the ratio.
    #[serde(default)]
    pub gps_white_vertical_m: Option<f64>,
    /// The GPS heights' own correlation time (s).
    #[serde(default = "not_estimated")]
    pub gps_tau_vertical_s: Estimated,
    /// `-2 ln L` at the choice.
    pub neg2_log_likelihood: f64,
    /// Likelihood evaluations (chain solves) the search took.
    pub evaluations: usize,
    /// The heavy tails learnt from the ride (`None`: Gaussian fixes).
    #[serde(default)]
    pub gps_tails: Option<super::tails::TailSummary>,
    /// The odometer gain checked against the heavy-tailed fit (empty where
    /// the ride's innovations did not ask for heavy tails, or the check was
    /// not asked for).
    #[serde(default)]
    pub calibration: Vec<super::calibration::CalibrationCheck>,
}

impl NoiseEstimate {
    /// `spec` with the settings of `which` replaced by these.
    pub fn apply(&self, spec: &ModelSpec, which: AutoNoise) -> ModelSpec {
        let x = [
            self.gps_sigma_m.value,
            self.gps_tau_s.value,
            self.bias_walk.value,
            self.gps_white_m.value.max(BOUNDS[3].0),
            self.gps_vertical_ratio.value,
            if self.gps_tau_vertical_s.value > 0.0 {
                self.gps_tau_vertical_s.value
            } else {
                self.gps_tau_s.value
            },
        ];
        let mut spec = spec_at(spec, x.map(f64::ln), which);
        if which.gps && self.gps_white_vertical_m.is_some() {
            spec.gps_white_vertical_m = self.gps_white_vertical_m;
        }
        // The uncertainty is averaged over the correlation time's range
        // (see `ModelSpec::band_specs`), where the ride bounds it.
        let tau = &self.gps_tau_s;
        spec.band_taus =
            (which.gps && tau.estimated && tau.limit == Limit::None).then_some((tau.low, tau.high));
        spec
    }

    /// The check of parameter `name` of `effect` where it held the
    /// heavy-tailed fit's value (see [`super::calibration`]).
    pub fn held(&self, effect: &str, name: &str) -> Option<&super::calibration::CalibrationCheck> {
        self.calibration
            .iter()
            .find(|c| c.held && c.effect == effect && c.name == name)
    }

    /// The GPS error's correlation in words: "correlated over 3 s (2-4)", or independent fixes.
    pub fn tau_text(&self) -> String {
        if self.gps_tau_s.limit == Limit::AtLeast {
            format!(
                "correlated over {} (more than the ride can tell)",
                self.gps_tau_s.describe("s", 0)
            )
        } else if self.gps_tau_s.value > 0.0 {
            format!("correlated over {}", self.gps_tau_s.describe("s", 0))
        } else {
            "independent fixes (set)".to_string()
        }
    }

    /// The bias walk in words, or no prior.
    pub fn walk_text(&self, unit: &str) -> String {
        if self.bias_walk.value > 0.0 {
            self.bias_walk.describe(unit, 4)
        } else {
            "no prior (set)".to_string()
        }
    }

    /// The jitter in words, or none.
    pub fn jitter_text(&self) -> String {
        if self.gps_tau_s.value > 0.0 {
            format!("jitter {}", self.gps_white_m.describe("m", 2))
        } else {
            "no jitter apart".to_string()
        }
    }

    /// The GPS heights' noise in words, when it was estimated: "2.0 times
    /// the horizontal wander (1.8-2.2), correlated over 62 s (50-80),
    /// jitter 1.52 m".
    pub fn heights_text(&self) -> Option<String> {
        self.gps_vertical_ratio.estimated.then(|| {
            let tau = &self.gps_tau_vertical_s;
            let tau = if !tau.estimated {
                String::new()
            } else if tau.limit == Limit::AtLeast {
                format!(
                    ", correlated over {} (more than the ride can tell)",
                    tau.describe("s", 0)
                )
            } else {
                format!(", correlated over {}", tau.describe("s", 0))
            };
            let jitter = self
                .gps_white_vertical_m
                .map_or(String::new(), |j| format!(", jitter {j:.2} m"));
            format!(
                "{} the horizontal wander{tau}{jitter}",
                self.gps_vertical_ratio.describe("times", 2)
            )
        })
    }

    /// One line for a summary.
    pub fn describe(&self) -> String {
        let heights = self
            .heights_text()
            .map_or(String::new(), |h| format!(", heights {h}"));
        let tails = self
            .gps_tails
            .as_ref()
            .map_or(String::new(), |t| format!(", {}", t.describe()));
        let held: String = self
            .calibration
            .iter()
            .filter(|c| c.held)
            .map(|c| format!(", {}", c.describe()))
            .collect();
        format!(
            "GPS sigma {}, {}, {}{tails}{heights}, bias walk {}{held}",
            self.gps_sigma_m.describe("m", 2),
            self.tau_text(),
            self.jitter_text(),
            self.walk_text("deg/s/sqrt(s)")
        )
    }
}

/// Reports written before the heights' ratio was estimated held the default's.
pub(super) fn default_vertical_ratio() -> Estimated {
    let spec = ModelSpec::default();
    Estimated::held(spec.sigma_vertical_m / spec.sigma_horizontal_m)
}

/// A setting reports written before it was modelled do not have (the
/// jitter, the heights' own correlation time): none, not estimated.
pub(super) fn not_estimated() -> Estimated {
    Estimated::held(0.0)
}
