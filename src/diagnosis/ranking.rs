//! Which effect is missing: every catalogue effect not in the model is added
//! in turn, refitted, and judged by how much it lowers the held-out error.
//!
//! ## The significance rule
//! Held-out errors are compared fix by fix on the same fixes for every
//! candidate. The size of a gain is `drop = 1 - rms_candidate / rms_base`
//! over the fixes within `max(5 x median, 10 m)` of the base model's fitted
//! path (GPS jumps would otherwise dominate every RMS). Its consistency is
//! judged on a robust score, the Cauchy loss of the withheld fixes at twice
//! the base fit's median misfit ([`HeldOut::block_loss`], every withheld fix,
//! jumps included but bounded): per validation block `b` the paired gain is
//! `d_b = ln(L_base,b / L_candidate,b)` and over the `B` blocks that hold
//! fixes `t = mean(d) / (sd(d) / sqrt(B))`.
//!
//! A candidate that changes the noise distribution itself (`gps_outliers`:
//! Cauchy errors instead of Gaussian) cannot be judged on one shared score,
//! which would compare only where the two paths run. Each model is then
//! scored by its own predictive log-likelihood of the withheld fixes
//! ([`HeldOut::block_log_likelihood`]: the base's Gaussian, the candidate's
//! bivariate Cauchy, each at the scale that fits its withheld errors best),
//! and `d_b = ln p_candidate,b - ln p_base,b`. In a city the fixes' own
//! error (15-25 m) drowns the robust path's gain of 2 m in every shared
//! score (seeds 9 and 10: t 1.8 and 0.7), while the jumps make the Gaussian
//! a poor law in nearly every block (t 5.5 and 5.7); on the twelve plain
//! rides the Gaussian wins every time (t -1.6 to -12). A candidate is
//! `significant` when
//!
//! ```text
//! drop >= 2 %   and   ( t >= 3   or   (drop >= 10 %  and  t >= 1.5) )
//! ```
//!
//! A gain must be consistent across the ride (blocks are a minute apart, so
//! nearly independent: `t >= 3` is about a 0.5 % false alarm for 10-30
//! blocks), or large and spread over more than one block: a gain that comes
//! from a single block gives `t` close to 1 whatever its size, so
//! `t >= 1.5` rejects it. An effect that only chases noise improves some
//! blocks and worsens others. On twelve simulated rides without a hidden
//! effect (GPS error correlated over a minute) nothing passed, and on 35
//! rides with one the rule decided as it did on the per-block squared
//! error, the per-block median error and this score alike
//! (`examples/significance.rs`, docs/diagnosis.md).
//!
//! The 3 and 1.5 hold from [`CALIBRATED_BLOCKS`] withheld blocks up, which
//! every ride of a minute or more has. A shorter ride withholds fewer (a
//! 30 s clip four 5 s blocks), and `t` over `n` blocks has only `n - 1`
//! degrees of freedom: there each threshold becomes the Student-t quantile
//! at the false-alarm level it has over 10 blocks (`P(T_9 > 3)` = 0.75 %,
//! `P(T_9 > 1.5)` = 8.4 %), 5.05 and 1.81 over four blocks. On twelve plain
//! simulated 30 s rides four had "missing" effects before (gps_lag,
//! gyro_scale and a temperature slope at t 3.5-3.8 on one, a mounting
//! pitch at a 42 % drop and t 1.8 on another, a temperature slope at t 5.0
//! and 5.9 % on a third); with these thresholds two keep one, a mounting
//! pitch of 10 % at t 2.7-2.8. On twelve 60 s rides nothing changes.
//!
//! Passing the rule is not enough where the ride cannot tell the effect's
//! estimate from zero (see `not_told_from_zero`), nor where the estimate is
//! physically absurd (`super::absurd`).

use std::collections::BTreeMap;
use std::sync::Arc;

use rayon::prelude::*;

use super::validation::{ErrorLaw, Folds, HeldOut, comparable_fixes, fix_errors, held_out_from};
use super::{ResidualRms, fix_residuals};
use crate::effects::{self, Role};
use crate::import::reference::ReferenceTrack;
use crate::model::damped_solve;
use crate::model::{Model, ModelSpec};
use crate::optimisation::{FitError, FitSettings, Linearised, Reconstruction};
use crate::signals::Signals;

/// The significance rule (see the module documentation) for a paired `t`
/// over `blocks` withheld blocks.
pub fn significant(drop: f64, t: f64, blocks: usize) -> bool {
    let (strict, loose) = t_thresholds(blocks);
    drop >= MIN_DROP && (t >= strict || (drop >= 0.10 && t >= loose))
}

/// Withheld blocks from which the rule's thresholds are the calibrated 3 and
/// 1.5 (a ride of 60 s or more has 10: see `Folds::for_ride`).
pub const CALIBRATED_BLOCKS: usize = 10;

/// The rule's two thresholds on `t` over `blocks` blocks: 3 and 1.5 from
/// [`CALIBRATED_BLOCKS`] up; below, the Student-t quantiles with
/// `blocks - 1` degrees of freedom at the false-alarm levels 3 and 1.5 have
/// with `CALIBRATED_BLOCKS - 1`; none can pass over fewer than two blocks.
pub fn t_thresholds(blocks: usize) -> (f64, f64) {
    use crate::statistics::{student_t_cdf, student_t_quantile};
    if blocks >= CALIBRATED_BLOCKS {
        return (3.0, 1.5);
    }
    if blocks < 2 {
        return (f64::INFINITY, f64::INFINITY);
    }
    let at = |t: f64| {
        let level = student_t_cdf(t, CALIBRATED_BLOCKS - 1);
        student_t_quantile(level, blocks - 1)
    };
    (at(3.0), at(1.5))
}

/// The smallest held-out drop that can count as significant.
const MIN_DROP: f64 = 0.02;

/// How many of its 1-sigma an estimate must lie from zero for the effect to
/// be shown to exist.
const MIN_Z: f64 = 2.0;

/// Why a candidate that passes the held-out rule is still not a missing
/// effect, if it is not: every parameter it estimates lies within
/// [`MIN_Z`] sigma of zero (the sigma is the larger of the fit's and the
/// folds' spread, see `estimates`), so the ride does not show the effect,
/// and its held-out gain comes from the freedom it adds, not from its
/// value. On a plain simulated 30 s ride a temperature slope of
/// 0.42 ± 0.32 deg/s per degree passed the rule (7.5 %, t 6.6 over four
/// blocks) and was called missing. An effect without parameters (the
/// robust loss) and a sigma that could not be computed do not count here.
fn not_told_from_zero(effect: &str, estimate: &BTreeMap<String, Estimate>) -> Option<String> {
    let told = estimate.is_empty()
        || estimate
            .values()
            .any(|e| e.determined && (e.sigma.is_nan() || e.value.abs() >= MIN_Z * e.sigma));
    (!told).then(|| {
        format!(
            "{effect}'s estimate ({}) is within {MIN_Z:.0} sigma of zero: the ride does not show it, and its held-out gain is the freedom it adds",
            describe_estimates(estimate)
        )
    })
}

/// A fitted parameter with its standard deviation (1 sigma), in display units.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Estimate {
    pub value: f64,
    pub sigma: f64,
    pub unit: String,
    /// `false` when the sigma spans what the parameter can physically be
    /// (see `ParamInfo::within`): the ride does not determine it.
    pub determined: bool,
}

impl Estimate {
    /// "value ± sigma unit", or "not determined by this ride".
    pub fn describe(&self) -> String {
        crate::effects::plus_minus(
            self.value,
            Some((self.sigma, self.determined)),
            &self.unit,
            3,
        )
    }
}

/// Every parameter of an estimate with its 1-sigma, in one line:
/// "lag 0.096 ± 0.010 s, scale_error_z -0.899 ± 0.140 %".
pub fn describe_estimates(estimate: &BTreeMap<String, Estimate>) -> String {
    estimate
        .iter()
        .map(|(k, e)| format!("{k} {}", e.describe()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// One candidate effect, fitted and validated.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    pub effect: String,
    pub heldout_rms_m: f64,
    /// `1 - heldout_rms / base heldout_rms`.
    pub drop: f64,
    pub significant: bool,
    /// Paired t statistic of the per-block gains in robust score.
    pub t_statistic: f64,
    pub fit_rms_m: f64,
    pub estimate: BTreeMap<String, Estimate>,
    pub explanation: String,
    /// Why the candidate could not be fitted (then it ranks last).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The model with this effect added, fitted as `gyropath fit` and the
    /// app's Add fit it (the user's settings: the noise estimated from the
    /// ride and the gain checked by default), against the reference track
    /// when one was given: what the held-out GPS error stands in for, and
    /// what the user gets by adding the effect.
    pub reference: Option<super::ReferenceComparison>,
}

/// What `gyropath diagnose` reports.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Diagnosis {
    pub model: Vec<String>,
    pub fit_rms_m: f64,
    pub heldout_rms_m: f64,
    /// The GPS error law both errors (and the whole ranking) are measured
    /// under: the noise as set, which can differ from what `fit` estimates
    /// on the same ride ([`crate::model::ModelSpec::gps_noise_text`]).
    pub gps_noise: String,
    pub residual_rms: ResidualRms,
    pub folds: Folds,
    /// Fixes left out of the held-out comparison as GPS jumps.
    pub excluded_fixes: usize,
    pub ranking: Vec<Candidate>,
    /// The base model's parameters (segment biases left out).
    pub estimate: BTreeMap<String, Estimate>,
    /// Residual and segment-bias correlations with candidate signals, strongest first.
    pub structure: Vec<super::Correlation>,
    /// Physical limits the base model's own fit breaks: then it is no
    /// result, no candidate is significant, and the axes or units come first.
    pub not_physical: Vec<String>,
    /// Whether the GPS residuals are white (east, north), and over how long they are correlated.
    pub whiteness: Option<Vec<super::Whiteness>>,
    /// The model as `gyropath fit` fits it (the user's settings, not the
    /// ranking's noise as set) against the reference track, when one was
    /// given. Under the ranking's noise Berlin's drive read 9.11 m here and
    /// `gps_outliers` 6.73 m, where the fit the user holds is 6.28 m from
    /// the reference and adding `gps_outliers` takes it to 9.19 m: a column
    /// of numbers the user never gets.
    pub reference: Option<super::ReferenceComparison>,
}

/// Fit `settings.model` on the ride, then rank the missing effects.
pub fn diagnose(
    signals: Arc<Signals>,
    settings: &FitSettings,
    folds: &Folds,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, FitError> {
    diagnose_against(signals, settings, folds, None, progress)
}

/// [`diagnose`], with the model and every candidate measured against a
/// reference track (already matched to the ride's rows).
pub fn diagnose_against(
    signals: Arc<Signals>,
    settings: &FitSettings,
    folds: &Folds,
    reference: Option<Against>,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, FitError> {
    progress("fitting the model");
    // The ranking is under the noise as set (see [`diagnose_fitted`]), so
    // the model is fitted under it from the start: estimating the ride's own
    // noise first would only be refitted away (a 20-minute ride's diagnosis
    // took 3.4 times its fit with that detour).
    let mut fit =
        Reconstruction::new(signals, ranking_settings(settings))?.keeping_its_last_linearisation();
    fit.finish();
    let start = fit.take_last_linearisation();
    rank(
        fit.model(),
        fit.params(),
        start,
        settings,
        folds,
        reference,
        progress,
    )
}

/// The settings a ranking runs under: `settings` with the noise as set
/// (see [`diagnose_fitted`]).
fn ranking_settings(settings: &FitSettings) -> FitSettings {
    FitSettings {
        auto_noise: crate::optimisation::AutoNoise::OFF,
        ..settings.clone()
    }
}

/// A reference track and its rows matched to the ride.
pub type Against<'a> = (&'a ReferenceTrack, &'a super::reference::Matched);

/// Rank the missing effects of a model already fitted at `theta`.
///
/// The ranking compares held-out errors under the noise settings the user
/// set (independent fixes unless a correlation time is given), not under
/// those estimated from the ride: its significance rule was calibrated so,
/// and with the estimated (shorter, tighter) GPS noise it misses a hidden
/// `gps_outliers` on one of the catalogue's rides. A model fitted with
/// estimated noise is first refitted under the set noise.
pub fn diagnose_fitted(
    model: &Model,
    theta: &[f64],
    settings: &FitSettings,
    folds: &Folds,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, FitError> {
    diagnose_fitted_against(model, theta, settings, folds, None, progress)
}

/// [`diagnose_fitted`], measured against a reference track as well.
pub fn diagnose_fitted_against(
    model: &Model,
    theta: &[f64],
    settings: &FitSettings,
    folds: &Folds,
    reference: Option<Against>,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, FitError> {
    rank(model, theta, None, settings, folds, reference, progress)
}

/// [`diagnose_fitted_against`], where the fit at `theta` may have kept
/// the linearisation its last iteration made (see
/// [`Reconstruction::keeping_its_last_linearisation`]).
fn rank(
    model: &Model,
    theta: &[f64],
    start: Option<Linearised>,
    settings: &FitSettings,
    folds: &Folds,
    reference: Option<Against>,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, FitError> {
    let user = settings;
    let settings = &ranking_settings(settings);
    let set = ModelSpec {
        effects: model.spec.effects.clone(),
        segment_s: model.spec.segment_s,
        ..settings.model.clone()
    };
    // The model as the user fitted it, against the reference: the one
    // given when it is refitted below for the ranking, else (fitted under
    // the ranking's noise, as the command line does) fitted anew.
    let base_reference = reference.map(|(r, m)| {
        if set != model.spec || !needs_own_fit(user) {
            super::reference::compare(model, theta, r, m)
        } else {
            as_fitted(model.signals.clone(), user, model.spec.clone(), r, m)
                .unwrap_or_else(|| super::reference::compare(model, theta, r, m))
        }
    });
    let refitted;
    let (model, theta, start) = if set == model.spec {
        (model, theta, start)
    } else {
        progress("refitting with the noise as set");
        let m = Model::with_start(model.signals.clone(), set, model.start.clone())?;
        let t = m.carry_over(model, theta);
        let mut fit =
            Reconstruction::resume(m, t, settings.clone())?.keeping_its_last_linearisation();
        fit.finish();
        let start = fit.take_last_linearisation();
        refitted = fit.into_parts();
        (&refitted.0, &refitted.1[..], start)
    };
    let sig = &model.signals;
    let folds = &folds.for_ride(sig.duration());
    progress("held-out validation of the model");
    let base = held_out_from(model, theta, settings, folds, start)?;
    let fit_errors = fix_errors(model, theta);
    let fit_rms = rms(&fit_errors);
    let use_fix = comparable_fixes(&fit_errors);
    let base_rms = base.comparable_rms(&use_fix);
    // The robust score's scale: twice the base fit's median misfit, so that
    // fixes within the GPS noise count quadratically and a jump logarithmically.
    let scale = 2.0 * crate::statistics::median_of_finite(&fit_errors);

    let channels: Vec<String> = sig.channels.iter().map(|(n, _)| n.clone()).collect();
    let present = model.effect_ids();
    let ids: Vec<String> = effects::catalogue(&channels)
        .into_iter()
        .map(|(id, _)| id)
        .filter(|id| !present.contains(id))
        .filter(|id| effects::build(id, sig, &model.spec, &model.start).is_ok())
        .collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let mut ranking: Vec<Candidate> = ids
        .par_iter()
        .map(|id| {
            let c = candidate(
                model,
                theta,
                (user, settings),
                folds,
                id,
                &base,
                &use_fix,
                base_rms.rms_m,
                scale,
                reference,
            );
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(&format!("tried {id} ({n} of {})", ids.len()));
            c
        })
        .collect();
    ranking.sort_by(|a, b| {
        a.error
            .is_some()
            .cmp(&b.error.is_some())
            .then(a.heldout_rms_m.total_cmp(&b.heldout_rms_m))
    });
    let residuals = fix_residuals(model, theta, &model.residual_path(theta));
    let not_physical: Vec<String> = crate::limits::check(model, theta)
        .iter()
        .map(ToString::to_string)
        .collect();
    if !not_physical.is_empty() {
        for c in &mut ranking {
            c.significant = false;
        }
    }
    Ok(Diagnosis {
        model: present,
        fit_rms_m: fit_rms,
        heldout_rms_m: base_rms.rms_m,
        gps_noise: model.spec.gps_noise_text(),
        residual_rms: ResidualRms::of(&residuals),
        folds: *folds,
        excluded_fixes: base_rms.jumps_left_out,
        ranking,
        estimate: estimates(model, theta, None, &base.fold_params),
        structure: super::structure(model, theta),
        not_physical,
        whiteness: super::whiteness(&residuals),
        reference: base_reference,
    })
}

/// Whether `gyropath fit` under `settings` fits differently from the
/// ranking (which holds the noise as set).
fn needs_own_fit(settings: &FitSettings) -> bool {
    settings.auto_noise.any()
}

/// `spec` fitted on `signals` from the start under the user's `settings`,
/// as `gyropath fit` and the app's Add fit it, against the reference;
/// `None` when it cannot be fitted.
fn as_fitted(
    signals: std::sync::Arc<Signals>,
    settings: &FitSettings,
    spec: ModelSpec,
    reference: &ReferenceTrack,
    matched: &super::reference::Matched,
) -> Option<super::ReferenceComparison> {
    let settings = FitSettings {
        model: ModelSpec {
            held: Vec::new(),
            ..spec
        },
        ..settings.clone()
    };
    let mut fit = Reconstruction::new(signals, settings).ok()?;
    fit.finish();
    Some(super::reference::compare(
        fit.model(),
        fit.params(),
        reference,
        matched,
    ))
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

#[allow(clippy::too_many_arguments)]
fn candidate(
    base_model: &Model,
    base_theta: &[f64],
    (user, settings): (&FitSettings, &FitSettings),
    folds: &Folds,
    id: &str,
    base: &HeldOut,
    use_fix: &[bool],
    base_rms: f64,
    scale: f64,
    reference: Option<Against>,
) -> Candidate {
    let failed = |e: String| Candidate {
        effect: id.to_string(),
        heldout_rms_m: f64::NAN,
        drop: f64::NAN,
        significant: false,
        t_statistic: f64::NAN,
        fit_rms_m: f64::NAN,
        estimate: BTreeMap::new(),
        explanation: String::new(),
        error: Some(e),
        reference: None,
    };
    let mut spec: ModelSpec = base_model.spec.clone();
    spec.effects.push(id.to_string());
    let model = match Model::with_start(base_model.signals.clone(), spec, base_model.start.clone())
    {
        Ok(m) => m,
        Err(e) => return failed(e.to_string()),
    };
    let theta = model.carry_over(base_model, base_theta);
    let full_settings = FitSettings {
        model: model.spec.clone(),
        ..settings.clone()
    };
    let settings = super::validation::validation_settings(&full_settings);
    let signals = model.signals.clone();
    let added = model.spec.clone();
    let mut resumed = match Reconstruction::resume(model, theta, settings.clone()) {
        Ok(f) => f.keeping_its_last_linearisation(),
        Err(e) => return failed(e.to_string()),
    };
    resumed.finish();
    // A model that lacks an effect can settle in a poor basin (a large mount
    // error can do that): when the resumed fit is still far from the fixes
    // (more than twice the GPS noise), the candidate also gets the whole
    // two-step fit from the start guess, and the better fit is kept.
    let poor = resumed.stats().rms_horizontal_m > 2.0 * full_settings.model.sigma_horizontal_m;
    let fresh = poor.then(|| {
        Reconstruction::new(signals.clone(), full_settings).map(|f| {
            let mut f = f.keeping_its_last_linearisation();
            f.finish();
            f
        })
    });
    let mut fit = match fresh {
        Some(Ok(f)) if f.stats().cost < resumed.stats().cost => f,
        _ => resumed,
    };
    let start = fit.take_last_linearisation();
    let ho = match held_out_from(fit.model(), fit.params(), &settings, folds, start) {
        Ok(h) => h,
        Err(e) => return failed(e.to_string()),
    };
    let heldout = ho.rms(use_fix);
    let (base_law, law) = (ErrorLaw::of(base_model), ErrorLaw::of(fit.model()));
    let gains = if law == base_law {
        loss_gains(&base.block_loss(scale), &ho.block_loss(scale))
    } else {
        likelihood_gains(
            &base.block_log_likelihood(base_law),
            &ho.block_log_likelihood(law),
        )
    };
    let t = paired_t(&gains);
    let drop = 1.0 - heldout / base_rms;
    let e = fit.model().effect_index(id).map(|e| fit.model().range(e));
    let estimate = estimates(fit.model(), fit.params(), Some(id), &ho.fold_params);
    let absurd = super::absurd::absurd_estimate(id, &estimate.iter().collect::<Vec<_>>());
    // A physically absurd estimate is never a missing effect, however much
    // it helps; nor one the ride cannot tell from zero.
    let passes = significant(drop, t, gains.len());
    let unshown = passes.then(|| not_told_from_zero(id, &estimate)).flatten();
    let significant = passes && absurd.is_none() && unshown.is_none();
    let explanation = absurd
        .or(unshown)
        .unwrap_or_else(|| explain(id, fit.model(), fit.params(), &estimate, e.is_some()));
    Candidate {
        effect: id.to_string(),
        heldout_rms_m: heldout,
        drop,
        significant,
        t_statistic: t,
        fit_rms_m: rms(&fix_errors(fit.model(), fit.params())),
        estimate,
        explanation,
        error: None,
        reference: reference.map(|(r, m)| {
            needs_own_fit(user)
                .then(|| as_fitted(signals.clone(), user, added.clone(), r, m))
                .flatten()
                .unwrap_or_else(|| super::reference::compare(fit.model(), fit.params(), r, m))
        }),
    }
}

/// Per-block gains `ln(L_base / L_candidate)` of the robust loss, over blocks that hold fixes.
fn loss_gains(base: &[f64], cand: &[f64]) -> Vec<f64> {
    base.iter()
        .zip(cand)
        .filter(|(b, c)| **b > 0.0 && **c > 0.0)
        .map(|(b, c)| (b / c).ln())
        .collect()
}

/// Per-block gains in predictive log-likelihood, `ln p_candidate - ln p_base`.
fn likelihood_gains(base: &[Option<f64>], cand: &[Option<f64>]) -> Vec<f64> {
    base.iter()
        .zip(cand)
        .filter_map(|(b, c)| Some((*c)? - (*b)?))
        .collect()
}

/// Paired t statistic of per-block gains: `mean(d) / (sd(d) / sqrt(B))`.
fn paired_t(d: &[f64]) -> f64 {
    let n = d.len() as f64;
    if d.len() < 2 {
        return 0.0;
    }
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    if var <= 0.0 {
        return if mean > 0.0 { f64::INFINITY } else { 0.0 };
    }
    mean / (var / n).sqrt()
}

/// Values and 1-sigma uncertainties of the global parameters of `only` (or of
/// every non-segment effect), from the Gauss-Newton covariance
/// `s^2 (J^T J)^-1` over the parameters step 2 fits, `s^2 = C / (m - n)`.
///
/// The reported sigma is the larger of that and the delete-a-fold jackknife
/// over the validation refits `folds` (`(k-1)/k sum (theta_i - mean)^2`): the
/// Gauss-Newton covariance takes the GPS errors as independent, while they
/// are correlated over about a minute and the bias walk can mimic a global
/// effect, which the spread between refits on different 60 s blocks shows.
fn estimates(
    model: &Model,
    theta: &[f64],
    only: Option<&str>,
    folds: &[Vec<f64>],
) -> BTreeMap<String, Estimate> {
    let free = model.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
    let ne = model.normal_equations(theta, &free);
    let m = model.n_residuals() as f64;
    let s2 = ne.cost / (m - ne.columns.len() as f64).max(1.0);
    let mut out = BTreeMap::new();
    let infos = model.param_infos();
    for (e, effect) in model.effects().iter().enumerate() {
        if effect.segment_edges().is_some() || only.is_some_and(|id| effect.id() != id) {
            continue;
        }
        for i in model.range(e) {
            if effect.fixed(i - model.range(e).start) {
                // Held, not estimated (a planar model's roll and pitch parts).
                continue;
            }
            let (_, info) = &infos[i];
            let sigma = ne
                .columns
                .iter()
                .position(|&c| c == i)
                .and_then(|col| {
                    let mut unit = nalgebra::DVector::zeros(ne.columns.len());
                    unit[col] = 1.0;
                    damped_solve(&ne.a, &unit, 0.0).map(|x| (x[col] * s2).max(0.0).sqrt())
                })
                .unwrap_or(f64::NAN);
            let sigma = sigma.max(jackknife_sigma(folds, i));
            let key = if only.is_some() {
                info.name.clone()
            } else {
                format!("{}.{}", effect.id(), info.name)
            };
            out.insert(
                key,
                Estimate {
                    value: theta[i] * info.scale,
                    sigma: sigma * info.scale.abs(),
                    unit: info.unit.to_string(),
                    determined: info.determined(sigma),
                },
            );
        }
    }
    out
}

/// Delete-a-fold jackknife standard error of parameter `i` (`NaN` with fewer than two folds).
fn jackknife_sigma(folds: &[Vec<f64>], i: usize) -> f64 {
    let values: Vec<f64> = folds.iter().filter_map(|p| p.get(i).copied()).collect();
    let k = values.len() as f64;
    if values.len() < 2 {
        return f64::NAN;
    }
    let mean = values.iter().sum::<f64>() / k;
    ((k - 1.0) / k * values.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt()
}

/// One sentence of physics for a fitted candidate.
fn explain(
    id: &str,
    model: &Model,
    theta: &[f64],
    est: &BTreeMap<String, Estimate>,
    present: bool,
) -> String {
    let v = |name: &str| est.get(name).map_or(f64::NAN, |e| e.value);
    if !present {
        return format!("{id} could not be added to the model");
    }
    match id {
        "gps_lag" => {
            let lag = v("lag");
            if lag >= 0.0 {
                format!(
                    "GPS fixes lag the odometer path by {lag:.2} s: the along-track residual follows speed"
                )
            } else {
                format!(
                    "GPS fixes lead the odometer path by {:.2} s: the along-track residual follows speed",
                    -lag
                )
            }
        }
        "gyro_scale" => {
            let z = v("scale_error_z");
            format!(
                "the yaw gyro reads {:.2} % {}{}: turns come out {}, so the cross-track residual grows with each heading change",
                z.abs(),
                if z > 0.0 { "high" } else { "low" },
                other_axes(est, "scale_error_", 2, " %"),
                if z > 0.0 { "too sharp" } else { "too wide" }
            )
        }
        "mount_misalignment" => {
            let angles: Vec<String> = [("forward_yaw", "yaw"), ("forward_pitch", "pitch")]
                .iter()
                .filter_map(|&(name, axis)| {
                    let e = est.get(name).filter(|e| e.determined)?;
                    Some(format!("{:.2} deg in {axis}", e.value))
                })
                .collect();
            if angles.is_empty() {
                "the sensor may be mounted askew, but this ride determines neither angle"
                    .to_string()
            } else {
                format!(
                    "the sensor is mounted askew: the vehicle's forward axis is off by {} in sensor axes, so the path drifts sideways and vertically as the vehicle leans and climbs",
                    angles.join(" and ")
                )
            }
        }
        "baro_drift" => format!(
            "the barometer drifts {:.2} m/h (weather): the vertical residual grows linearly in time",
            v("drift")
        ),
        "gps_outliers" => {
            let res = fix_residuals(model, theta, &model.residual_path(theta));
            let scale = model.robust_scale().unwrap_or(1.0) * model.spec.sigma_horizontal_m;
            let far = res.iter().filter(|r| r.horizontal() > 3.0 * scale).count();
            format!(
                "{far} of {} fixes sit more than {:.0} m from the robust path (multipath jumps); a Cauchy loss stops them bending it",
                res.len(),
                3.0 * scale
            )
        }
        channel if channel.starts_with(effects::CHANNEL_PREFIX) => {
            let c = &channel[effects::CHANNEL_PREFIX.len()..];
            format!(
                "the gyro bias moves with {c}: {:.4} deg/s per unit on z{}, so the fitted segment bias tracks {c}",
                v("slope_z"),
                other_axes(est, "slope_", 4, "")
            )
        }
        other => format!("{other} lowers the held-out error"),
    }
}

/// " (x 0.12 %, y -0.03 %)": the roll and pitch axes' estimates of a
/// per-axis parameter `{prefix}x`, `{prefix}y` beside the yaw axis's, or
/// nothing when the fit left them out (a planar ride estimates yaw only).
fn other_axes(est: &BTreeMap<String, Estimate>, prefix: &str, digits: usize, unit: &str) -> String {
    let axes: Vec<String> = ["x", "y"]
        .iter()
        .filter_map(|a| {
            let e = est.get(&format!("{prefix}{a}"))?;
            Some(format!("{a} {:.digits$}{unit}", e.value))
        })
        .collect();
    if axes.is_empty() {
        String::new()
    } else {
        format!(" ({})", axes.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_other_axes_are_named_only_where_the_fit_estimated_them() {
        let estimate = |value| Estimate {
            value,
            sigma: 0.1,
            unit: "%".into(),
            determined: true,
        };
        let mut est = BTreeMap::from([("scale_error_z".to_string(), estimate(2.0))]);
        assert_eq!(other_axes(&est, "scale_error_", 2, " %"), "");
        est.insert("scale_error_x".into(), estimate(0.123));
        est.insert("scale_error_y".into(), estimate(-0.03));
        assert_eq!(
            other_axes(&est, "scale_error_", 2, " %"),
            " (x 0.12 %, y -0.03 %)"
        );
    }

    #[test]
    fn the_thresholds_rise_on_rides_with_few_blocks() {
        assert_eq!(t_thresholds(10), (3.0, 1.5));
        assert_eq!(t_thresholds(30), (3.0, 1.5));
        let (strict, loose) = t_thresholds(9);
        assert!(strict > 3.0 && loose > 1.5, "{strict} {loose}");
        // Four blocks (a 30 s ride): 3 degrees of freedom.
        let (strict, loose) = t_thresholds(4);
        assert!((4.5..5.2).contains(&strict), "{strict}");
        assert!((1.65..1.85).contains(&loose), "{loose}");
        assert!(!significant(0.087, 3.8, 4));
        assert!(significant(0.087, 3.8, 12));
        assert_eq!(t_thresholds(1).0, f64::INFINITY);
    }

    #[test]
    fn an_effect_is_shown_only_by_an_estimate_told_from_zero() {
        let est = |pairs: &[(&str, f64, f64, bool)]| -> BTreeMap<String, Estimate> {
            pairs
                .iter()
                .map(|&(k, value, sigma, determined)| {
                    (
                        k.to_string(),
                        Estimate {
                            value,
                            sigma,
                            unit: "deg".into(),
                            determined,
                        },
                    )
                })
                .collect()
        };
        // The plain 30 s ride's temperature slope: 1.3 sigma.
        let why = not_told_from_zero("temp", &est(&[("slope_z", 0.42, 0.317, true)]));
        assert!(why.is_some_and(|w| w.contains("within 2 sigma of zero")));
        // comma's lag, 9.6 sigma; a mounting whose yaw is not determined but
        // whose pitch is, 18 sigma.
        assert!(not_told_from_zero("lag", &est(&[("lag", 0.096, 0.010, true)])).is_none());
        assert!(
            not_told_from_zero(
                "mount",
                &est(&[
                    ("forward_yaw", 0.0, 3.0, false),
                    ("forward_pitch", 0.754, 0.041, true)
                ])
            )
            .is_none()
        );
        // Only an undetermined parameter far from zero: not shown.
        assert!(not_told_from_zero("mount", &est(&[("forward_yaw", 20.0, 1.0, false)])).is_some());
        // No parameters (the robust loss), or no sigma: not judged here.
        assert!(not_told_from_zero("gps_outliers", &BTreeMap::new()).is_none());
        assert!(not_told_from_zero("x", &est(&[("a", 0.1, f64::NAN, true)])).is_none());
    }

    #[test]
    fn paired_t_is_large_for_consistent_gains_and_small_for_noise() {
        let base = vec![10.0; 12];
        let better: Vec<f64> = (0..12).map(|i| 8.0 + 0.1 * (i % 3) as f64).collect();
        assert!(paired_t(&loss_gains(&base, &better)) > 10.0);
        let noise: Vec<f64> = (0..12)
            .map(|i| if i % 2 == 0 { 9.0 } else { 11.2 })
            .collect();
        assert!(paired_t(&loss_gains(&base, &noise)) < 1.0);
        // Blocks without fixes do not count.
        assert_eq!(paired_t(&loss_gains(&[0.0, 0.0], &[1.0, 2.0])), 0.0);
        assert_eq!(
            likelihood_gains(
                &[Some(-3.0), None, Some(-2.0)],
                &[Some(-1.0), Some(0.0), None]
            ),
            vec![2.0]
        );
    }

    #[test]
    fn jackknife_sigma_is_the_delete_a_fold_standard_error() {
        let folds = vec![
            vec![0.0, 1.0],
            vec![0.0, 2.0],
            vec![0.0, 3.0],
            vec![0.0, 4.0],
        ];
        // mean 2.5, sum of squares 5, (k-1)/k = 3/4: sqrt(3.75).
        assert!((jackknife_sigma(&folds, 1) - 3.75f64.sqrt()).abs() < 1e-12);
        assert_eq!(jackknife_sigma(&folds, 0), 0.0);
        assert!(jackknife_sigma(&folds[..1], 1).is_nan());
    }
}
