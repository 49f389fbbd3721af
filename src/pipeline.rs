//! The journey of one fit, the same for every front end: open the source
//! and derive its signals, match a reference track to it, fit, judge the
//! fit against the physical limits, and make its report. The command line
//! (`fit`, a batch, `diagnose`) and the app's worker each call these steps,
//! so a change to the journey (what a report holds, when a fit is no
//! result) is made once, here.
//!
//! The measurements and the history behind these choices:
//! docs/architecture.md (the layers and the data's path through them).

use std::path::Path;
use std::sync::Arc;

use crate::diagnosis::reference::{self, Matched, ReferenceError};
use crate::export::FitReport;
use crate::import::reference::Clock;
use crate::import::{
    self, ImportOptions, Imported, Level, LoadError, ReferenceTrack, SourceKind, Topics, Verdict,
};
use crate::limits::{self, Violation};
use crate::model::{Model, Uncertainty};
use crate::optimisation::Reconstruction;
use crate::signals::Signals;

/// A reference track and the ride's rows it covers.
pub type MatchedReference = (ReferenceTrack, Matched);

/// Open any input `gyropath` reads (ride log, bag, mapped CSV), checked.
pub fn open(path: &Path, options: &ImportOptions) -> Result<Imported, LoadError> {
    import::open(path, options)
}

/// Read a reference track (CSV on the ride's clock, or GPX / NMEA in UTC put
/// on it by the ride's `t0_unix_s`) and match it to `signals`' rows: an
/// error when it cannot belong to the ride (no time in common, far from
/// every fix).
///
/// A UTC track for a ride that does not say when it started is placed on
/// the ride's clock by its track where that is unambiguous
/// ([`crate::diagnosis::reference_clock`]), with a warning that says so;
/// else it is refused, asking for the ride's start.
pub fn reference_for(path: &Path, signals: &Signals) -> Result<MatchedReference, PipelineError> {
    let read = import::read_reference(path)?;
    let utc = matches!(read.clock, Clock::Unix | Clock::TimeOfDay);
    let placed = (utc && signals.t0_unix_s.is_none())
        .then(|| crate::diagnosis::reference_clock::track_clock(&read, signals))
        .flatten();
    let track = match placed {
        // Without a clock the track tells, the ride's own clock decides
        // (and refuses a UTC track, asking for the ride's start); unless the
        // track says that clock is off by seconds.
        None => clock_checked(
            read.on_ride_clock(signals.t0_unix_s, signals.t0_boot_s, &signals.source)?,
            signals,
        ),
        Some(clock) => {
            let mut track = read;
            for t in &mut track.t_s {
                *t -= clock.offset_s;
            }
            let start = match track.clock {
                Clock::Unix => format!("t0_unix_s {:.2}", clock.offset_s),
                _ => format!("a start at {:.2} s of the UTC day", clock.offset_s),
            };
            track.clock = Clock::Ride;
            // What a clock off by a tenth of a second costs along the
            // track at the ride's mean speed.
            let speed = signals.mean_speed_mps();
            track.warnings.push(format!(
                "{}: its times are UTC and {} does not say when it started (no t0_unix_s): placed on the ride's clock by its track ({start}, {}; {} fixes a median of {:.1} m from it there). A clock found so carries that sensor's latency, hundredths to tenths of a second: at the ride's mean {speed:.1} m/s, 0.1 s is {:.1} m along the track, so the error along the track{} is uncertain by that much; a '# t0_unix_s:' line in the ride places it by the clock instead",
                track.source,
                signals.source,
                clock.found_by(),
                clock.fixes,
                clock.median_m,
                0.1 * speed,
                if clock.by_distance {
                    ""
                } else {
                    " (and any GPS lag, which the fixes' own latency hides)"
                }
            ));
            track
        }
    };
    let matched = reference::match_rows(signals, &track)?;
    Ok((track, matched))
}

/// A reference on the ride's clock is off by this much (s) or more when its
/// track says so: the fixes' latency against a reference is tenths of a
/// second (comma's 0.1 s), a clock kept in GPS time instead of UTC 18 s,
/// a time zone hours.
pub const REFERENCE_CLOCK_OFF_S: f64 = 1.0;

/// Below [`REFERENCE_CLOCK_OFF_S`] and from this (s) up, an offset the
/// odometer tells is said, not applied.
pub const REFERENCE_CLOCK_DOUBT_S: f64 = 0.3;

/// `track` (on the ride's clock) moved onto it by the offset its track
/// tells ([`crate::diagnosis::reference_clock::track_clock`]), with a
/// warning, where that offset is [`REFERENCE_CLOCK_OFF_S`] or more and the
/// fixes lie at most half as far from the track there as at its times as
/// given; `track` as it is otherwise. An RTK or INS track kept in GPS time
/// against a log in UTC is 18 s off (the leap seconds since 1980): the comma
/// drive's reference so was refused as "not of this ride" (310 m from the
/// fixes), and a bicycle's at 5 m/s would have been measured 90 m off,
/// blaming the fit.
fn clock_checked(mut track: ReferenceTrack, signals: &Signals) -> ReferenceTrack {
    let Some(clock) = crate::diagnosis::reference_clock::track_clock(&track, signals) else {
        return track;
    };
    let off = clock.offset_s;
    let nearer = clock
        .median_at_zero_m
        .is_none_or(|m0| clock.median_m <= 0.5 * m0);
    if clock.by_distance && (REFERENCE_CLOCK_DOUBT_S..REFERENCE_CLOCK_OFF_S).contains(&off.abs()) {
        // Too little to be sure of (an odometer's own latency is
        // hundredths to a tenth or two), too much to pass over: 0.5 s on
        // the comma drive took its path from 1.25 m to 7.4 m off.
        let speed = signals.mean_speed_mps();
        track.warnings.push(format!(
            "{}: its clock may be {off:+.2} s off the ride's (where the odometer's distance matches the track's): at the ride's mean {speed:.1} m/s that is {:.1} m along the track, which the error along the track then holds; it is measured at its times as given",
            track.source,
            off.abs() * speed
        ));
        return track;
    }
    if off.abs() < REFERENCE_CLOCK_OFF_S || !nearer {
        return track;
    }
    // Offsets that are whole by their cause, taken as such where the track's
    // is within a quarter of a second of one: GPS time's leap seconds over
    // UTC (15 from mid 2012, 18 since 2017) and a time zone's whole hours.
    let hours = off / 3600.0;
    let (off, why) = if let Some(leap) = (15..=18)
        .map(f64::from)
        .find(|l| (off.abs() - l).abs() < 0.25)
    {
        (
            leap.copysign(off),
            format!(" (GPS time against UTC: {leap:.0} leap seconds)"),
        )
    } else if off.abs() >= 1800.0 && (hours - hours.round()).abs() * 3600.0 < 0.25 {
        (
            3600.0 * hours.round(),
            format!(" ({:.0} h: a time zone)", hours.round()),
        )
    } else {
        (off, String::new())
    };
    for t in &mut track.t_s {
        *t -= off;
    }
    track.warnings.push(format!(
        "{}: its clock is {off:+.2} s off the ride's{why}: the ride's fixes lie {} from it at its times as given, {:.1} m at {:+.2} s (found {}); it is measured with its times moved by {:+.2} s",
        track.source,
        clock
            .median_at_zero_m
            .map_or("too few to compare".to_string(), |m| format!("{m:.0} m in the median")),
        clock.median_m,
        clock.offset_s,
        clock.found_by(),
        -off,
    ));
    track
}

/// Where a ride came from: its kind, the topics read (bags), the mounting
/// applied and the checks' verdicts, for the Source panel.
#[derive(Clone, Debug, Default)]
pub struct Origin {
    pub kind: Option<SourceKind>,
    pub topics: Option<Topics>,
    pub mount: Option<String>,
    pub recommended: Option<String>,
    pub verdicts: Vec<Verdict>,
}

impl Origin {
    /// What `im` was read from and what its checks said.
    pub fn of(im: &Imported) -> Self {
        Self {
            kind: Some(im.kind),
            topics: im.topics.clone(),
            mount: im.mount.as_ref().map(ToString::to_string),
            recommended: im.check.recommended.as_ref().map(ToString::to_string),
            verdicts: im.check.after_mounting(im.mount.as_ref()),
        }
    }
}

/// Why a step of the journey failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Load(#[from] LoadError),
    #[error(transparent)]
    Reference(#[from] ReferenceError),
    #[error(transparent)]
    Signals(#[from] crate::signals::SignalError),
}

impl PipelineError {
    /// The windows either side of the log's longest pause, where a pause is what refused it.
    pub fn pause_windows(&self) -> Option<[(f64, f64); 2]> {
        match self {
            Self::Signals(e) => e.pause_windows(),
            _ => None,
        }
    }

    /// Whether the log has no GPS fix at all, which a GPS track of the same
    /// ride (`--gps-track`, the app's "GPS track..." button) would give it.
    pub fn needs_fixes(&self) -> bool {
        matches!(
            self,
            Self::Load(LoadError::NoFix { .. })
                | Self::Signals(crate::signals::SignalError::NoFix { .. })
        )
    }
}

/// What a finished fit is: a result, or a failure with its reasons.
#[derive(Clone, Debug, PartialEq)]
pub enum Judgement {
    /// Within every physical limit: a result.
    Result,
    /// The parameters are physical but the path does not follow the fixes
    /// (see [`limits::path_far_from_fixes`]): no result.
    NoResult(Vec<Violation>),
    /// A parameter no real vehicle has (a negative gain, an upside-down
    /// sensor): the axes or units are the likely fault.
    NotPhysical(Vec<Violation>),
}

impl Judgement {
    /// The limits the fit breaks (none for a result).
    pub fn violations(&self) -> &[Violation] {
        match self {
            Self::Result => &[],
            Self::NoResult(v) | Self::NotPhysical(v) => v,
        }
    }

    /// The failure in one message, naming the ride, or `None` for a result:
    /// "ride.csv: the fit failed: it is not physical (its path is 3.1 m RMS
    /// from the fixes):" and one line per broken limit.
    pub fn failure(&self, source: &str, rms_horizontal_m: f64) -> Option<String> {
        let what = match self {
            Self::Result => return None,
            Self::NoResult(_) => "no result",
            Self::NotPhysical(_) => "not physical",
        };
        let lines: Vec<String> = self.violations().iter().map(|v| format!("  {v}")).collect();
        Some(format!(
            "{source}: the fit failed: it is {what} (its path is {rms_horizontal_m:.2} m RMS from the fixes):\n{}",
            lines.join("\n")
        ))
    }
}

/// Judge the fit of `model` at `theta` against the physical limits.
pub fn judge(model: &Model, theta: &[f64]) -> Judgement {
    let broken = limits::check(model, theta);
    if broken.is_empty() {
        Judgement::Result
    } else if limits::parameters(model, theta).is_empty() {
        Judgement::NoResult(broken)
    } else {
        Judgement::NotPhysical(broken)
    }
}

/// Why a finished fit is no result, in one message naming its ride, or
/// `None` when it is a result (see [`judge`] and [`Judgement::failure`]).
pub fn failure(fit: &Reconstruction) -> Option<String> {
    judge(fit.model(), fit.params())
        .failure(&fit.model().signals.source, fit.stats().rms_horizontal_m)
}

/// [`failure`], with the axis and unit problems that the checks of the
/// ride's `origin` found and its mounting left, as the likelier cause: a
/// gyro in raw counts makes the fit fail with an odometer gain of 2.6 ("the
/// odometer's units look wrong"), where the gyro's are.
pub fn failure_given(fit: &Reconstruction, origin: &Origin) -> Option<String> {
    let message = failure(fit)?;
    let found: Vec<String> = origin
        .verdicts
        .iter()
        .filter(|v| v.level == Level::Problem && v.is_axes_or_units())
        .map(|v| format!("  {}: {}", v.subject, v.message))
        .collect();
    if found.is_empty() {
        return Some(message);
    }
    Some(format!(
        "{message}\nthe likelier cause is what the checks found in the log's axes or units; mend that first{}:\n{}",
        origin
            .recommended
            .as_ref()
            .map(|m| format!(" (--mount \"{m}\")"))
            .unwrap_or_default(),
        found.join("\n")
    ))
}

/// The report of a finished fit: its parameters with their sigmas (and the
/// path's uncertainty, returned for the path file, when `with_path_sigma`),
/// measured against the reference track when one is given.
pub fn report(
    fit: &Reconstruction,
    elapsed_s: f64,
    with_path_sigma: bool,
    reference: Option<&MatchedReference>,
) -> (FitReport, Option<Uncertainty>) {
    let uncertainty = with_path_sigma
        .then(|| fit.model().uncertainty(fit.params()))
        .flatten();
    let report = report_with(fit, elapsed_s, uncertainty.as_ref(), reference);
    (report, uncertainty)
}

/// [`report`] with the sigmas of an uncertainty already computed (at any
/// rows: only its parameters' sigmas are read), or the parameters' own.
pub fn report_with(
    fit: &Reconstruction,
    elapsed_s: f64,
    uncertainty: Option<&Uncertainty>,
    reference: Option<&MatchedReference>,
) -> FitReport {
    let mut report = match uncertainty {
        Some(u) => FitReport::with_uncertainty(fit, elapsed_s, u),
        None => FitReport::new(fit, elapsed_s),
    };
    if let Some((track, matched)) = reference {
        report.warnings.extend(track.warnings.iter().cloned());
        report.reference = Some(reference::compare(
            fit.model(),
            fit.params(),
            track,
            matched,
        ));
    }
    report
}

/// The signals of an opened input, shared between the fit and its checks.
pub fn signals(imported: Imported) -> Result<Arc<Signals>, PipelineError> {
    Ok(Arc::new(imported.into_signals()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelSpec;

    #[test]
    fn a_broken_limit_is_a_failure_that_says_which_kind() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 240.0, &[]));
        let model = Model::new(sig, ModelSpec::default()).unwrap();
        let mut theta = model.initial_params();
        assert_eq!(judge(&model, &theta), Judgement::Result);
        assert!(Judgement::Result.failure("r.csv", 1.0).is_none());
        let gain = model
            .range(model.effect_index("odometer_gain").unwrap())
            .start;
        theta[gain] = -1.0;
        let j = judge(&model, &theta);
        assert!(matches!(j, Judgement::NotPhysical(_)), "{j:?}");
        let message = j.failure("r.csv", 3.25).unwrap();
        assert!(
            message.starts_with("r.csv: the fit failed: it is not physical (its path is 3.25 m"),
            "{message}"
        );
        assert!(message.contains("odometer gain"), "{message}");
    }
}
