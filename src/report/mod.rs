//! The report to share: one self-contained HTML page of a fit that opens in
//! any browser, offline. Everything is inline (the plots are SVG written by
//! [`svg`], the style is one `<style>` block, there is no script), and the
//! page's Content-Security-Policy forbids every request, so a page that
//! tried to load anything would say so in the browser's console.
//!
//! The page is the template `assets/report.html` (minijinja, autoescaped)
//! filled from a [`Page`]: numbers are formatted here, in Rust, so the
//! template only lays them out. What goes on it:
//! the ride and its checks, the result (model, noise, bias, parameters with
//! their 1-sigma), the reference comparison, the map (fixes, path with its
//! 95 % band, outages, the reference), residuals along and across the
//! track and vertical, the bias per segment, the model history, the
//! diagnosis, and the settings and version that made it.
//!
//! The measurements and the history behind these choices: docs/command-
//! line.md ("--html": what the page holds).

pub mod figures;
pub mod svg;

use std::path::Path;

use serde::Serialize;

use crate::diagnosis::view::BandPoint;
use crate::diagnosis::{Diagnosis, FitView, describe_estimates};
use crate::explain::{Ending, Explanation, SavedModel};
use crate::export::{ExportError, FitReport, write_atomically};
use crate::model::Uncertainty;
use crate::optimisation::Reconstruction;
use crate::pipeline::{self, MatchedReference, Origin};

/// The page's template.
const TEMPLATE: &str = include_str!("../../assets/report.html");
/// The batch index page's template.
const INDEX_TEMPLATE: &str = include_str!("../../assets/report-index.html");

/// Path points a report draws at most (before thinning to pixels).
pub const MAX_POINTS: usize = 6000;

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("the report's template failed: {0}")]
    Template(#[from] minijinja::Error),
    #[error(transparent)]
    Export(#[from] ExportError),
}

/// One model of the history: a row of the table and a point of its chart.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelRow {
    /// The effects, comma-separated.
    pub model: String,
    /// What this row added and why, in one line (empty for a plain fit).
    pub note: String,
    pub fit_rms_m: f64,
    /// The GPS error law `fit_rms_m` is measured under.
    pub gps_noise: String,
    /// Held-out error (m), when measured.
    pub heldout_rms_m: Option<f64>,
    /// Horizontal RMS to the reference (m), when one is given.
    pub reference_rms_m: Option<f64>,
}

impl ModelRow {
    /// The one row of a plain fit.
    pub fn of_fit(fit: &Reconstruction, reference_rms_m: Option<f64>) -> Self {
        Self {
            model: fit.model().effect_ids().join(", "),
            note: "the fit".into(),
            fit_rms_m: fit.stats().rms_horizontal_m,
            gps_noise: fit.model().spec.gps_noise_text(),
            heldout_rms_m: None,
            reference_rms_m,
        }
    }

    /// One row per step of `explain`.
    pub fn of_explanation(e: &Explanation) -> Vec<Self> {
        e.steps
            .iter()
            .map(|s| Self {
                model: s.model.join(", "),
                note: match &s.added {
                    None => "base model".into(),
                    Some(effect) => format!(
                        "added {effect} ({}): held-out {:.1} % lower (t {:.1})",
                        describe_estimates(&s.estimate),
                        100.0 * s.drop,
                        s.t_statistic
                    ),
                },
                fit_rms_m: s.fit_rms_m,
                gps_noise: s.gps_noise.clone(),
                heldout_rms_m: s.heldout_rms_m,
                reference_rms_m: s.reference.as_ref().map(|r| r.horizontal.rms_m),
            })
            .collect()
    }
}

/// What a report is made of, beyond the fit itself.
pub struct Contents<'a> {
    pub fit: &'a Reconstruction,
    /// Where the ride came from and what the checks said (when known).
    pub origin: Option<&'a Origin>,
    pub reference: Option<&'a MatchedReference>,
    /// The fit's uncertainty at every row, when the caller has it already
    /// (for a path file); else the report computes it at the rows it draws.
    pub uncertainty: Option<&'a Uncertainty>,
    /// The model history (empty: the fit's own row).
    pub history: Vec<ModelRow>,
    /// The explain loop that made the model, when it did.
    pub explanation: Option<&'a Explanation>,
    /// The last diagnosis of the model, when one was run.
    pub diagnosis: Option<&'a Diagnosis>,
    /// How to make it again ("gyropath fit ride.csv --html r.html").
    pub command: String,
    /// The fit's report when the caller has made it already (the command
    /// line has, for its summary and JSON), with the reference compared; else
    /// the page makes it. Its sigmas are the same either way: a report
    /// costs the segment lengths' likelihoods, some 7 % of a fit.
    pub report: Option<&'a FitReport>,
}

impl<'a> Contents<'a> {
    /// The contents of a plain fit: its own history row, no diagnosis.
    pub fn of_fit(
        fit: &'a Reconstruction,
        origin: Option<&'a Origin>,
        reference: Option<&'a MatchedReference>,
        uncertainty: Option<&'a Uncertainty>,
        report: Option<&'a FitReport>,
        command: String,
    ) -> Self {
        Self {
            fit,
            origin,
            reference,
            uncertainty,
            history: Vec::new(),
            explanation: None,
            diagnosis: None,
            command,
            report,
        }
    }
}

/// A titled value of a table.
#[derive(Debug, Serialize)]
pub struct Item {
    pub key: String,
    pub value: String,
}

fn item(key: &str, value: impl Into<String>) -> Item {
    Item {
        key: key.into(),
        value: value.into(),
    }
}

/// A check's verdict.
#[derive(Debug, Serialize)]
pub struct VerdictRow {
    pub level: String,
    pub subject: String,
    pub message: String,
}

/// A parameter with its 1-sigma.
#[derive(Debug, Serialize)]
pub struct ParamRow {
    pub effect: String,
    pub name: String,
    pub value: String,
    pub sigma: String,
    pub unit: String,
}

/// A candidate of the diagnosis.
#[derive(Debug, Serialize)]
pub struct CandidateRow {
    pub effect: String,
    pub estimate: String,
    pub heldout: String,
    pub drop: String,
    pub t: String,
    pub significant: bool,
    pub reference: String,
    pub explanation: String,
}

/// A history row as shown.
#[derive(Debug, Serialize)]
pub struct HistoryView {
    pub model: String,
    pub note: String,
    pub fit: String,
    pub heldout: String,
    pub reference: String,
}

/// A figure: its SVG, and a caption saying how to read it.
#[derive(Debug, Serialize)]
pub struct Figure {
    pub id: String,
    pub title: String,
    pub caption: String,
    pub svg: String,
}

/// Everything the page shows, formatted.
#[derive(Debug, Serialize)]
pub struct Page {
    pub title: String,
    pub version: String,
    pub made: String,
    /// The fit's failure (no result, not physical), shown first.
    pub failure: Option<String>,
    pub ride: Vec<Item>,
    pub verdicts: Vec<VerdictRow>,
    pub warnings: Vec<String>,
    pub result: Vec<Item>,
    pub params: Vec<ParamRow>,
    pub reference: Vec<Item>,
    pub figures: Vec<Figure>,
    pub history: Vec<HistoryView>,
    pub history_figure: Option<Figure>,
    /// Why `explain` stopped, when it made the model.
    pub ending: Option<String>,
    /// What the diagnosis was ranked under, and its candidates.
    pub diagnosis_under: Option<String>,
    pub diagnosis: Vec<CandidateRow>,
    pub command: String,
    pub settings_json: String,
    pub model_json: String,
}

fn m(v: f64) -> String {
    format!("{v:.3} m")
}

fn opt_m(v: Option<f64>) -> String {
    v.map_or("-".into(), m)
}

/// The page of a fit: the fit drawn once at [`MAX_POINTS`] rows, its
/// uncertainty computed at those rows.
pub fn page(c: &Contents) -> Page {
    let fit = c.fit;
    let model = fit.model();
    let theta = fit.params();
    let sig = &model.signals;
    let view = FitView::of(model, theta, MAX_POINTS);
    let uncertainty: Option<Uncertainty> = match c.uncertainty {
        Some(u) if u.path.len() == sig.len() => Some(Uncertainty {
            params: u.params.clone(),
            path: view.rows.iter().map(|&j| u.path[j]).collect(),
        }),
        _ => model.uncertainty_at(theta, Some(&view.rows)),
    };
    let made;
    let report = match c.report {
        Some(r) => r,
        None => {
            made = pipeline::report_with(fit, 0.0, uncertainty.as_ref(), c.reference);
            &made
        }
    };
    // The band across the path, once, for the map, its half-width plot and
    // how often the reference lies inside it.
    let band = uncertainty.as_ref().map_or(Vec::new(), |u| {
        let cov: Vec<[f64; 3]> = u.path.iter().map(|v| [v[0], v[1], v[3]]).collect();
        crate::diagnosis::view::cross_band(&view.path, &cov)
    });
    let history = if c.history.is_empty() {
        vec![ModelRow::of_fit(
            fit,
            report.reference.as_ref().map(|r| r.horizontal.rms_m),
        )]
    } else {
        c.history.clone()
    };
    let figures = figures::all(&figures::Input {
        model,
        view: &view,
        uncertainty: uncertainty.as_ref(),
        band: &band,
        reference: c.reference,
        comparison: report.reference.as_ref(),
    });
    Page {
        title: format!("gyropath report: {}", sig.source),
        version: env!("CARGO_PKG_VERSION").into(),
        made: utc_now(),
        failure: pipeline::failure(fit),
        ride: ride_items(c, report),
        verdicts: c.origin.map_or(Vec::new(), |o| {
            o.verdicts
                .iter()
                .map(|v| VerdictRow {
                    level: format!("{:?}", v.level).to_lowercase(),
                    subject: v.subject.clone(),
                    message: v.message.clone(),
                })
                .collect()
        }),
        // The checks' warnings reach the fit's warnings too (the terminal
        // prints them); the page shows each once, in the checks' table.
        warnings: report
            .warnings
            .iter()
            .filter(|w| {
                !c.origin
                    .is_some_and(|o| o.verdicts.iter().any(|v| **w == v.as_warning()))
            })
            .cloned()
            .collect(),
        result: result_items(report),
        params: param_rows(report),
        reference: report.reference.as_ref().map_or(Vec::new(), |r| {
            let mut items = vec![
                item("reference", &r.reference),
                item("coverage", r.coverage()),
                item("path", r.horizontal.describe()),
                item(
                    "along / across",
                    format!("{} / {} RMS", m(r.along_rms_m), m(r.cross_rms_m)),
                ),
            ];
            if let Some(v) = &r.vertical {
                items.push(item("vertical", v.describe()));
            }
            if let Some(f) = &r.fixes {
                items.push(item("GPS fixes", f.describe()));
            }
            if let Some((inside, n)) = band_coverage(&view, &band, c.reference) {
                items.push(item(
                    "inside the 95 % band",
                    format!(
                        "the reference at {:.1} % of the {n} drawn rows it covers (across the track)",
                        100.0 * inside as f64 / n as f64
                    ),
                ));
            }
            items
        }),
        figures,
        history_figure: figures::history(&history),
        history: history
            .iter()
            .map(|h| HistoryView {
                model: crate::effects::short_model(&h.model),
                note: h.note.clone(),
                fit: format!("{} (under {})", m(h.fit_rms_m), h.gps_noise),
                heldout: opt_m(h.heldout_rms_m),
                reference: opt_m(h.reference_rms_m),
            })
            .collect(),
        ending: c.explanation.map(|e| match &e.ending {
            Ending::NothingSignificant => {
                "Nothing more lowers the held-out error beyond chance.".to_string()
            }
            Ending::NoResult(reason) => format!("The next fit was no result: {reason}"),
            Ending::StepLimit => "Stopped at the limit of added effects.".into(),
            Ending::CannotValidate(reason) => format!("Not validated: {reason}"),
        }),
        diagnosis_under: c.diagnosis.map(|d| {
            format!(
                "Ranked under {} (the noise as set); the model's held-out error is {}.",
                d.gps_noise,
                m(d.heldout_rms_m)
            )
        }),
        diagnosis: c.diagnosis.map_or(Vec::new(), |d| {
            d.ranking
                .iter()
                .map(|r| CandidateRow {
                    effect: r.effect.clone(),
                    estimate: describe_estimates(&r.estimate),
                    heldout: m(r.heldout_rms_m),
                    drop: format!("{:.1} %", crate::diagnosis::shown(100.0 * r.drop, 1)),
                    t: format!("{:.1}", crate::diagnosis::shown(r.t_statistic, 1)),
                    significant: r.significant,
                    reference: opt_m(r.reference.as_ref().map(|x| x.horizontal.rms_m)),
                    explanation: r.error.clone().unwrap_or_else(|| r.explanation.clone()),
                })
                .collect()
        }),
        command: c.command.clone(),
        settings_json: serde_json::to_string_pretty(&report.settings).unwrap_or_default(),
        model_json: serde_json::to_string_pretty(&SavedModel::of(fit)).unwrap_or_default(),
    }
}

/// How often the reference lies inside the path's 95 % band across the
/// track, over the drawn rows it covers: `(inside, rows)`, `None` without
/// a reference, a band or a covered row. Near 95 % when the
/// band is honest.
fn band_coverage(
    view: &FitView,
    band: &[BandPoint],
    reference: Option<&MatchedReference>,
) -> Option<(usize, usize)> {
    let (_, matched) = reference?;
    let (mut inside, mut n) = (0, 0);
    for (b, &row) in band.iter().zip(&view.rows) {
        if let Ok(k) = matched.at_rows.binary_search_by_key(&row, |(r, _)| *r) {
            let p = matched.at_rows[k].1;
            let across = (p.x - b.east) * b.normal[0] + (p.y - b.north) * b.normal[1];
            n += 1;
            if across.abs() <= b.half_width_m {
                inside += 1;
            }
        }
    }
    (n > 0).then_some((inside, n))
}

fn ride_items(c: &Contents, r: &FitReport) -> Vec<Item> {
    let sig = &c.fit.model().signals;
    let distance: f64 = sig.distance.iter().sum();
    let duration = r.duration_s.max(f64::EPSILON);
    let outages = crate::diagnosis::view::outages(sig);
    let mut items = vec![item("source", &r.source)];
    if let Some(o) = c.origin {
        if let Some(k) = o.kind {
            items.push(item("format", k.label()));
        }
        if let Some(t) = &o.topics {
            items.push(item(
                "topics",
                format!("IMU {}, odometer {}, GPS {}", t.imu, t.odom, t.fix),
            ));
        }
        if let Some(mount) = &o.mount {
            items.push(item("mounting applied", mount));
        }
    }
    if let Some(t0) = sig.t0_unix_s {
        items.push(item("starts", utc(t0)));
    }
    items.extend([
        item(
            "duration",
            format!("{:.0} s ({:.1} min)", r.duration_s, r.duration_s / 60.0),
        ),
        item(
            "distance",
            format!(
                "{:.2} km as logged, from {}",
                distance / 1000.0,
                sig.odometer.describe()
            ),
        ),
        item(
            "rows",
            format!("{} ({:.0} Hz)", r.rows, r.rows as f64 / duration),
        ),
        item(
            "GPS fixes",
            format!(
                "{} ({:.2} Hz), {}",
                r.gps_fixes,
                r.gps_fixes as f64 / duration,
                outage_summary(&outages)
            ),
        ),
        item("attitude", &r.attitude),
    ]);
    items
}

/// "no outage longer than 2.5 s", or how many there are and the time they
/// cover (never "-0 s": an empty `f64` sum is `-0.0`).
fn outage_summary(outages: &[(f64, f64)]) -> String {
    let limit = crate::diagnosis::view::OUTAGE_S;
    if outages.is_empty() {
        return format!("no outage longer than {limit} s");
    }
    format!(
        "{} outage(s) longer than {limit} s covering {:.0} s",
        outages.len(),
        outages.iter().map(|(a, b)| b - a).sum::<f64>()
    )
}

fn result_items(r: &FitReport) -> Vec<Item> {
    let mut items = vec![
        item("model", r.model.join(", ")),
        item(
            "path to the fixes",
            format!("{} RMS horizontal", m(r.stats.rms_horizontal_m)),
        ),
        item("under", &r.gps_noise),
    ];
    if let Some(n) = &r.noise {
        items.push(item("noise from the ride", n.describe()));
    }
    if let Some(v) = r.stats.rms_gps_up_m {
        items.push(item("GPS altitude", format!("{} RMS", m(v))));
    }
    if let Some(v) = r.stats.rms_baro_up_m {
        items.push(item("barometer", format!("{} RMS", m(v))));
    }
    for (axis, total) in ["x", "y", "z"].iter().zip(&r.bias_total) {
        if let Some(t) = total {
            items.push(item(&format!("gyro bias {axis}"), t.describe()));
        }
    }
    items.push(item(
        "iterations",
        format!(
            "step 1: {}, step 2: {}",
            r.iterations_step1, r.iterations_step2
        ),
    ));
    items
}

fn param_rows(r: &FitReport) -> Vec<ParamRow> {
    let segments = r.parameters.contains_key("gyro_bias_segments");
    r.parameters
        .iter()
        .filter(|(effect, _)| effect.as_str() != "gyro_bias_segments")
        .flat_map(move |(effect, values)| {
            // With segments, step 2 holds the constant and fits the segments:
            // the total bias (the result above) carries the sigma.
            let effect = if segments && effect == "gyro_bias" {
                "gyro_bias (constant part; total above)".to_string()
            } else {
                effect.clone()
            };
            values.iter().filter(|p| !p.fixed).map(move |p| ParamRow {
                effect: effect.clone(),
                name: if p.held {
                    format!("{} (held: the heavy-tailed fit's)", p.name)
                } else {
                    p.name.clone()
                },
                value: format!("{:.6}", p.value),
                sigma: match (p.sigma, p.determined) {
                    (Some(s), true) => format!("{s:.6}"),
                    (Some(s), false) => format!("{s:.6} (not determined)"),
                    (None, _) => "-".into(),
                },
                unit: p.unit.clone(),
            })
        })
        .collect()
}

/// The page as HTML.
pub fn html(c: &Contents) -> Result<String, ReportError> {
    render(TEMPLATE, "report.html", &page(c))
}

fn render(template: &str, name: &str, context: &impl Serialize) -> Result<String, ReportError> {
    let mut env = minijinja::Environment::new();
    env.add_template(name, template)?;
    Ok(env
        .get_template(name)?
        .render(minijinja::value::Serde(context))?)
}

/// Write the report of `c` to `path` (atomically; never over `protect`, the ride).
pub fn write(path: &Path, protect: Option<&Path>, c: &Contents) -> Result<(), ReportError> {
    let text = html(c)?;
    write_atomically(path, protect, |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

/// A ride of a batch's index page.
#[derive(Debug, Serialize)]
pub struct IndexEntry {
    pub source: String,
    /// The ride's report, relative to the index (`None`: the ride failed).
    pub href: Option<String>,
    /// "0.445 m to the fixes", or the failure.
    pub outcome: String,
    pub reference: String,
}

/// The index page of a batch: one row per ride, linking its report.
pub fn index_html(entries: &[IndexEntry]) -> Result<String, ReportError> {
    #[derive(Serialize)]
    struct Index<'a> {
        version: &'static str,
        made: String,
        entries: &'a [IndexEntry],
    }
    render(
        INDEX_TEMPLATE,
        "index.html",
        &Index {
            version: env!("CARGO_PKG_VERSION"),
            made: utc_now(),
            entries,
        },
    )
}

/// Now, as "2026-11-25 22:41 UTC".
fn utc_now() -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    utc(now)
}

/// A Unix time as "YYYY-MM-DD HH:MM UTC" (the civil calendar from days
/// since 1970, Howard Hinnant's `civil_from_days`).
fn utc(unix_s: f64) -> String {
    let secs = unix_s.floor() as i64;
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates_are_civil() {
        assert_eq!(utc(0.0), "1970-01-01 00:00 UTC");
        assert_eq!(utc(951_782_400.0), "2000-02-29 00:00 UTC");
        assert_eq!(utc(1_764_110_520.0), "2025-11-25 22:42 UTC");
    }
}
