//! Are the GPS residuals white? The objective treats fixes as independent;
//! real GPS errors wander for tens of seconds (atmosphere, multipath, the
//! receiver's own filter). This measures how long, from the fitted model's
//! residuals at the fixes, per component (east and north).
//!
//! For lag `h` the autocorrelation is taken over pairs of fixes `h` fix
//! intervals apart in time (within half an interval), so pairs never straddle
//! an outage. The Ljung-Box statistic over the first `m` lags,
//!
//! ```text
//! Q = n (n + 2) sum_{h=1..m} r_h^2 / (n - h)      ~ chi^2(m) for white residuals,
//! ```
//!
//! gives a p-value; the correlation time is the first lag at which the
//! autocorrelation falls below 1/e (what a first-order Gauss-Markov error
//! with that time constant would show).

use super::FixResidual;

/// Lags in the Ljung-Box statistic.
const LJUNG_BOX_LAGS: usize = 20;
/// Longest lag searched for the correlation time (s).
const MAX_LAG_S: f64 = 300.0;

/// The whiteness of one residual component.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Whiteness {
    /// `east` or `north`.
    pub component: String,
    pub lags: usize,
    pub ljung_box_q: f64,
    /// Probability of a `Q` at least this large if the residuals were white.
    pub p_value: f64,
    /// First lag (s) with autocorrelation below 1/e; `None` if none within 300 s.
    pub correlation_time_s: Option<f64>,
    /// Autocorrelation at lag 1 (one fix interval).
    pub r1: f64,
}

impl Whiteness {
    /// White at the 1 % level.
    pub fn white(&self) -> bool {
        self.p_value >= 0.01
    }
}

/// Whiteness of the east and north residuals (`None` with fewer than 30 fixes).
pub fn whiteness(residuals: &[FixResidual]) -> Option<Vec<Whiteness>> {
    if residuals.len() < 30 {
        return None;
    }
    let mut dts: Vec<f64> = residuals.windows(2).map(|w| w[1].t - w[0].t).collect();
    let interval = crate::statistics::median(&mut dts);
    if interval <= 0.0 {
        return None;
    }
    let max_lag = ((MAX_LAG_S / interval) as usize).min(residuals.len() / 2);
    Some(
        [("east", 0usize), ("north", 1)]
            .iter()
            .map(|&(name, c)| {
                let x: Vec<f64> = residuals
                    .iter()
                    .map(|r| if c == 0 { r.east } else { r.north })
                    .collect();
                let t: Vec<f64> = residuals.iter().map(|r| r.t).collect();
                let acf: Vec<f64> = (1..=max_lag)
                    .map(|h| autocorrelation(&x, &t, h as f64 * interval, 0.5 * interval))
                    .collect();
                let n = x.len() as f64;
                let m = LJUNG_BOX_LAGS.min(acf.len());
                let q = n
                    * (n + 2.0)
                    * acf[..m]
                        .iter()
                        .enumerate()
                        .map(|(i, r)| r * r / (n - (i + 1) as f64))
                        .sum::<f64>();
                let correlation_time_s = acf
                    .iter()
                    .position(|&r| r < (-1.0f64).exp())
                    .map(|i| (i + 1) as f64 * interval);
                Whiteness {
                    component: name.into(),
                    lags: m,
                    ljung_box_q: q,
                    p_value: chi2_survival(q, m as f64),
                    correlation_time_s,
                    r1: acf.first().copied().unwrap_or(0.0),
                }
            })
            .collect(),
    )
}

/// Autocorrelation of `x` (sampled at times `t`) over pairs `lag +- tol` apart.
fn autocorrelation(x: &[f64], t: &[f64], lag: f64, tol: f64) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    if var <= 0.0 {
        return 0.0;
    }
    let (mut s, mut pairs) = (0.0, 0usize);
    let mut j = 0usize;
    for i in 0..x.len() {
        while j < x.len() && t[j] < t[i] + lag - tol {
            j += 1;
        }
        if j < x.len() && (t[j] - t[i] - lag).abs() <= tol {
            s += (x[i] - mean) * (x[j] - mean);
            pairs += 1;
        }
    }
    if pairs == 0 {
        0.0
    } else {
        s / pairs as f64 / var
    }
}

/// `P(chi^2_k >= q)`: the regularised upper incomplete gamma `Q(k/2, q/2)`
/// (series below `a + 1`, continued fraction above; Numerical Recipes 6.2).
pub fn chi2_survival(q: f64, k: f64) -> f64 {
    let (a, x) = (0.5 * k, 0.5 * q);
    if x <= 0.0 {
        return 1.0;
    }
    let ln_prefix = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..500 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_prefix.exp()).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..500 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_prefix.exp() * h).clamp(0.0, 1.0)
    }
}

/// `ln Gamma(x)` for `x > 0` (Lanczos, g = 7, nine terms: 1e-15 relative).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi_square_tail_matches_tables() {
        // chi^2 critical values: P(chi2_20 >= 31.410) = 0.05, P(chi2_20 >= 37.566) = 0.01,
        // P(chi2_1 >= 3.841) = 0.05, P(chi2_10 >= 2.558) = 0.99.
        for (q, k, p) in [
            (31.410, 20.0, 0.05),
            (37.566, 20.0, 0.01),
            (3.841, 1.0, 0.05),
            (2.558, 10.0, 0.99),
        ] {
            let got = chi2_survival(q, k);
            assert!((got - p).abs() < 2e-4, "Q({q}, {k}) = {got}, expected {p}");
        }
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-12);
    }

    fn residuals(x: &[f64]) -> Vec<FixResidual> {
        x.iter()
            .enumerate()
            .map(|(k, &v)| FixResidual {
                t: k as f64 + if k > 300 { 40.0 } else { 0.0 },
                row: k,
                east: v,
                north: v,
                along: v,
                cross: v,
                up: None,
                speed: 5.0,
                normalised: [v, v],
            })
            .collect()
    }

    #[test]
    fn white_noise_is_white_and_a_minute_correlated_error_is_not() {
        let mut rng = crate::simulation::rng::Rng::new(9);
        let white: Vec<f64> = (0..900).map(|_| rng.normal()).collect();
        let w = whiteness(&residuals(&white)).unwrap();
        assert!(w[0].white(), "{:?}", w[0]);
        // First-order Gauss-Markov with tau 60 s at 1 Hz, an outage after fix 300.
        let a = (-1.0f64 / 60.0).exp();
        let mut x = 0.0;
        let gm: Vec<f64> = (0..900)
            .map(|_| {
                x = a * x + (1.0 - a * a).sqrt() * rng.normal();
                x
            })
            .collect();
        let w = whiteness(&residuals(&gm)).unwrap();
        assert!(!w[0].white() && w[0].p_value < 1e-6, "{:?}", w[0]);
        let tau = w[0].correlation_time_s.unwrap();
        assert!((25.0..=120.0).contains(&tau), "correlation time {tau} s");
    }
}
