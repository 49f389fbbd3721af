//! Heavy tails of the GPS error, learnt from the ride: a Student-t wander.
//!
//! A city's reflections put a fix 10-70 m off for a few seconds and then let
//! it go. Under the Gaussian wander ([`crate::model::ModelSpec`]'s
//! `gps_tau_s`) the noise search can only read those jumps as a large, fast
//! wander plus a large jitter (Berlin: 13.5 m over 5 s + 4.9 m), at which
//! scale the good fixes weigh no more than the reflected ones. The
//! Student-t wander gives each fix a weight of its own, Gamma-distributed
//! with `nu` degrees of freedom: its jitter and the wander's step into it
//! are Gaussian with their variances divided by `w_k`, so that its
//! bivariate (east, north) innovation `e'_k` follows the t law
//!
//! ```text
//! p(e') = 1 / (2 pi c^2) (1 + |e'|^2 / (nu c^2))^(-(nu / 2 + 1))
//! ```
//!
//! and a reflection is one unlikely step, not evidence of a wide wander.
//! The fit holds the weights at their expectation given its innovations
//! under the t law it fitted, `w_k = (nu + 2) / (nu + |e'_k|^2 / c^2)` (the
//! innovations whitened by the Gaussian filter under the searched settings,
//! each fix at its own unit weight; `c` the law's scale in those units,
//! below 1 where the reflections widened the Gaussian: 0.47 on Berlin,
//! 0.56 on the comma drive, 0.29-0.65 on the simulated rides that take it),
//! refits step 2 under them and takes the weights again, round after round
//! until they settle (one to three rounds). Weights taken as if `c` were 1
//! (session 28) were those of a law wider than the one fitted, and
//! discounted the reflections less: Berlin 8.26 m from its reference
//! instead of 7.85 m, comma 0.99 m instead of 0.93 m (docs/real-drives.md).
//! The noise settings stay those the Gaussian search chose: searching them
//! again under the weights (the full expectation-maximisation) learnt a
//! slower, narrower wander that let the path drift along it, and on
//! simulated urban rides whose Gaussian fits were good it ended 32-47 %
//! further from the truth (docs/real-drives.md); held, the same rides move
//! by 1-5 % (others by up to 33 % either way).
//! Both of a fix's axes share its weight: a reflection moves the fix in one
//! direction, and weighing each axis alone (as `gps_outliers`' loss does)
//! kept its other axis at full weight (Berlin: 8.66 m from the reference on
//! a dead reckoning with a wander, 6.86 m bivariate).
//!
//! Whether the ride has heavy tails at all is the data's choice, by
//! likelihood: `nu` and `c` by maximum likelihood on the innovations, against
//! the Gaussian (`nu` infinite) with its own `c`. Measured on every ride with
//! a reference (docs/real-drives.md): open-sky simulations gain 0.3-0.7 in
//! `2 ln L` (the Gaussian stays, at no cost), the comma drive 28, the urban
//! and city simulations 112-691, Berlin 126, each with `nu` near 2-4.

use crate::model::{GpsTails, Model, ModelSpec};

/// `2 ln L` that the t law must gain over the Gaussian before the fit takes
/// it: the 0.1 % point of a chi-squared of one degree of freedom (the one
/// extra parameter, `nu`). Strict, because each round costs a step 2, and
/// a Gaussian ride must not pay for them, nor lose its Gaussian fit, by chance.
pub const SIGNIFICANT_GAIN: f64 = 10.83;

/// The range of `nu` searched (below 1 the law has no mean; above 200 it is
/// Gaussian to the fixes' digits).
const NU_RANGE: (f64, f64) = (0.5, 200.0);

/// How the t law fits a ride's innovations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TailFit {
    /// Degrees of freedom by maximum likelihood.
    pub nu: f64,
    /// The t law's scale (in units of the innovations).
    pub scale: f64,
    /// `2 ln L` of the t law over the Gaussian, each at its own scale.
    pub gain: f64,
}

impl TailFit {
    /// Whether the ride's innovations ask for the t law.
    pub fn significant(&self) -> bool {
        self.gain > SIGNIFICANT_GAIN
    }
}

/// `ln L` of the bivariate t law of `nu` degrees of freedom and scale
/// `sqrt(c2)` on squared innovation norms `q`, with `c2` at its maximum (the
/// fixed point `c^2 = sum w_k q_k / (2 n)`, `w_k = (nu + 2) / (nu + q_k / c^2)`,
/// an EM that never lowers the likelihood). Returns `(ln L, c2)`.
fn t_log_likelihood(q: &[f64], nu: f64) -> (f64, f64) {
    let n = q.len() as f64;
    let mut c2 = q.iter().sum::<f64>() / (2.0 * n);
    for _ in 0..200 {
        let next = q
            .iter()
            .map(|&qk| (nu + 2.0) / (nu + qk / c2) * qk)
            .sum::<f64>()
            / (2.0 * n);
        let settled = (next / c2 - 1.0).abs() < 1e-10;
        c2 = next;
        if settled {
            break;
        }
    }
    let ll = q
        .iter()
        .map(|&qk| {
            -(2.0 * std::f64::consts::PI * c2).ln() - (0.5 * nu + 1.0) * (qk / (nu * c2)).ln_1p()
        })
        .sum();
    (ll, c2)
}

/// The t law that best fits squared innovation norms `q` (two axes each),
/// against the Gaussian: `nu` by golden-section search in `ln nu` over
/// [`NU_RANGE`] (the profile likelihood is unimodal in practice; a grid
/// first guards against a flat start). `None` with fewer than ten.
pub fn fit_t(q: &[f64]) -> Option<TailFit> {
    if q.len() < 10 || q.iter().any(|x| !x.is_finite()) || q.iter().all(|&x| x == 0.0) {
        return None;
    }
    let n = q.len() as f64;
    let c2g = q.iter().sum::<f64>() / (2.0 * n);
    let gauss = -n * (2.0 * std::f64::consts::PI * c2g).ln() - q.iter().sum::<f64>() / (2.0 * c2g);
    let (lo, hi) = (NU_RANGE.0.ln(), NU_RANGE.1.ln());
    let f = |x: f64| t_log_likelihood(q, x.exp()).0;
    let grid = 24;
    let at = |i: usize| lo + (hi - lo) * i as f64 / grid as f64;
    let best = (0..=grid)
        .map(|i| (i, f(at(i))))
        .max_by(|a, b| a.1.total_cmp(&b.1))?
        .0;
    let (mut a, mut b) = (at(best.saturating_sub(1)), at((best + 1).min(grid)));
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..40 {
        if f1 > f2 {
            b = x2;
            (x2, f2) = (x1, f1);
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            (x1, f1) = (x2, f2);
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
    }
    let nu = (0.5 * (a + b)).exp();
    let (ll, c2) = t_log_likelihood(q, nu);
    if ll <= gauss {
        // The Gaussian itself (`nu` infinite) beats every t law searched.
        return Some(TailFit {
            nu: f64::INFINITY,
            scale: c2g.sqrt(),
            gain: 0.0,
        });
    }
    Some(TailFit {
        nu,
        scale: c2.sqrt(),
        gain: 2.0 * (ll - gauss),
    })
}

/// What the fit reports of the tails it learnt.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TailSummary {
    /// Degrees of freedom of the t law.
    pub nu: f64,
    /// `2 ln L` of the t law over the Gaussian on the first round's
    /// innovations (the evidence that chose it).
    pub gain: f64,
    /// Rounds of weights and refits run.
    pub rounds: usize,
    /// Fixes whose noise the weights at least doubled (the ones read as
    /// reflections).
    pub down_weighted: usize,
}

impl TailSummary {
    /// In words: "Student-t fixes (nu 1.6, 2 ln L +126), 35 fixes down-weighted".
    pub fn describe(&self) -> String {
        format!(
            "Student-t fixes (nu {:.1}, 2 ln L {:+.0} over Gaussian), {} fixes down-weighted",
            self.nu, self.gain, self.down_weighted
        )
    }
}

/// Per fix (indexed as `Signals::fixes`), the squared norm of its horizontal
/// innovation `|e'_k|^2 = e'_east^2 + e'_north^2` at `theta`, whitened by the
/// Gaussian filter of `model`'s settings with every fix at its own logged
/// accuracy (no tail weight: the weights' expectation asks how unlikely
/// each fix is under unit weight). `None` for a fix the model does not
/// observe on both axes.
pub fn innovations(model: &Model, theta: &[f64]) -> Option<Vec<Option<f64>>> {
    let unit = Model::with_start(
        model.signals.clone(),
        ModelSpec {
            gps_tails: None,
            ..model.spec.clone()
        },
        model.start.clone(),
    )
    .ok()?;
    let path = unit.sparse_path(theta, unit.residual_rows(theta));
    let sig = &unit.signals;
    let mut q: Vec<Option<f64>> = vec![None; sig.fixes.len()];
    let mut axes = vec![0u8; sig.fixes.len()];
    for (o, m) in unit.observations.iter().zip(unit.misfits(theta, &path)) {
        if o.baro || o.axis == 2 {
            continue;
        }
        let i = *sig.fix_at_row.get(o.row)? as usize;
        let (Some(slot), Some(count)) = (q.get_mut(i), axes.get_mut(i)) else {
            continue;
        };
        *slot = Some(slot.unwrap_or(0.0) + m.white * m.white);
        *count += 1;
    }
    for (slot, count) in q.iter_mut().zip(axes) {
        if count != 2 {
            *slot = None;
        }
    }
    Some(q)
}

/// The tails of `model`'s GPS error at `theta`: the t law fitted to its
/// innovations and, when the ride asks for it (or `keep`: a fit already
/// under tails keeps them and only updates them), each fix's noise factor
/// (see [`noise_factors`]). `None`: Gaussian.
pub fn estimate(model: &Model, theta: &[f64], keep: bool) -> Option<(TailFit, GpsTails)> {
    let q = innovations(model, theta)?;
    let seen: Vec<f64> = q.iter().flatten().copied().collect();
    let fit = fit_t(&seen)?;
    if !(keep || fit.significant()) {
        return None;
    }
    let scale = noise_factors(&q, &fit)?;
    Some((
        fit,
        GpsTails {
            nu: fit.nu,
            scale: scale.into(),
        },
    ))
}

/// Each fix's noise factor under the t law `fit` of its squared innovation
/// norm `q_k`: `1 / sqrt(w_k)`, `w_k = (nu + 2) / (nu + q_k / c^2)`, over
/// the ride's median of it (so that the searched sigma stays the typical
/// fix's). A fix without an innovation keeps the median. With the law's own
/// scale `c` the factors do not depend on the units the innovations were
/// whitened in, only on how far each lies out in the law fitted to them.
fn noise_factors(q: &[Option<f64>], fit: &TailFit) -> Option<Vec<f64>> {
    let (nu, c2) = (fit.nu, fit.scale * fit.scale);
    let factor = |qk: f64| ((nu + qk / c2) / (nu + 2.0)).sqrt();
    let mut factors: Vec<f64> = q.iter().flatten().map(|&qk| factor(qk)).collect();
    let median = crate::statistics::median(&mut factors);
    (median.is_finite() && median > 0.0).then(|| {
        q.iter()
            .map(|qk| qk.map_or(1.0, |qk| factor(qk) / median))
            .collect()
    })
}

/// How far apart two sets of tail factors are: the largest change of a
/// fix's factor, in the logarithm (0.05: 5 %). Infinite when either is
/// missing or they cover different fixes.
pub fn change(a: Option<&GpsTails>, b: Option<&GpsTails>) -> f64 {
    match (a, b) {
        (Some(a), Some(b)) if a.scale.len() == b.scale.len() => a
            .scale
            .iter()
            .zip(b.scale.iter())
            .map(|(x, y)| (x / y).ln().abs())
            .fold(0.0, f64::max),
        (None, None) => 0.0,
        _ => f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulation::rng::Rng;

    /// Squared norms of bivariate t draws (`nu`, unit scale) as a Gaussian
    /// pair over a Gamma weight: `e = n / sqrt(w)`, `w ~ chi2(nu) / nu`.
    fn t_draws(nu: f64, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Rng::new(seed);
        let k = nu.round().max(1.0) as usize;
        (0..n)
            .map(|_| {
                let w = (0..k).map(|_| rng.normal().powi(2)).sum::<f64>() / k as f64;
                (rng.normal().powi(2) + rng.normal().powi(2)) / w
            })
            .collect()
    }

    #[test]
    fn the_degrees_of_freedom_of_t_innovations_are_recovered_and_significant() {
        for nu in [1.0, 2.0, 4.0] {
            let fit = fit_t(&t_draws(nu, 4000, 3)).expect("a fit");
            assert!((fit.nu / nu).ln().abs() < 0.25, "{fit:?} for nu {nu}");
            assert!((fit.scale - 1.0).abs() < 0.1, "{fit:?}");
            assert!(fit.significant(), "{fit:?}");
        }
    }

    /// Gaussian innovations (of any scale) do not ask for heavy tails: the
    /// t law gains less than the threshold and `nu` runs high.
    #[test]
    fn gaussian_innovations_keep_the_gaussian() {
        for seed in 1..6 {
            let mut rng = Rng::new(seed + 100);
            let q: Vec<f64> = (0..600)
                .map(|_| 2.5 * (rng.normal().powi(2) + rng.normal().powi(2)))
                .collect();
            let fit = fit_t(&q).expect("a fit");
            assert!(!fit.significant(), "seed {seed}: {fit:?}");
            assert!(fit.gain >= 0.0 && fit.nu > 20.0, "seed {seed}: {fit:?}");
        }
    }

    #[test]
    fn too_few_or_degenerate_innovations_have_no_fit() {
        assert_eq!(fit_t(&[1.0; 5]), None);
        assert_eq!(fit_t(&[0.0; 50]), None);
        assert_eq!(
            fit_t(&[1.0, f64::NAN, 2.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]),
            None
        );
    }

    #[test]
    fn the_noise_factors_do_not_depend_on_the_innovations_units() {
        // Innovations whitened under a Gaussian four times too wide read a
        // quarter as large: the same law, in other units, so the same weights.
        let q: Vec<f64> = t_draws(2.0, 400, 7);
        let quarter: Vec<f64> = q.iter().map(|x| x / 4.0).collect();
        let factors = |q: &[f64]| {
            let fit = fit_t(q).expect("fit");
            let with: Vec<Option<f64>> = q.iter().map(|&x| Some(x)).collect();
            noise_factors(&with, &fit).expect("factors")
        };
        let (a, b) = (factors(&q), factors(&quarter));
        for (x, y) in a.iter().zip(&b) {
            assert!((x / y - 1.0).abs() < 1e-6, "{x} against {y}");
        }
        // The farthest fix is discounted most, the median fix keeps 1.
        let far = q
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(y.1))
            .map(|(i, _)| i);
        let far = far.expect("draws");
        assert!(a[far] > 3.0, "{}", a[far]);
        assert!(a.iter().all(|&f| f > 0.5));
    }

    /// The t law's likelihood with the scale at its maximum is never below
    /// the same law at a scale off by 10 % either way.
    #[test]
    fn the_scale_maximises_the_t_likelihood() {
        let q = t_draws(2.0, 500, 9);
        let (best, c2) = t_log_likelihood(&q, 2.0);
        for f in [0.9f64, 1.1] {
            let c = c2 * f * f;
            let ll: f64 = q
                .iter()
                .map(|&qk| -(2.0 * std::f64::consts::PI * c).ln() - 2.0 * (qk / (2.0 * c)).ln_1p())
                .sum();
            assert!(ll < best, "{ll} >= {best}");
        }
    }
}
