//! The command line: `gyropath fit`, `diagnose`, `import`, `check`, `simulate`
//! and `open`, one file per subcommand; here the arguments they share and
//! the steps of their common journey (open the source, judge the fit's
//! physical limits, match a reference, write a report).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};

use gyropath::diagnosis::{Diagnosis, Folds, describe_estimates};
use gyropath::export::{
    FitReport, PathFormat, check_html_name, check_report_name, is_stdout, write_atomically,
    write_json, write_path_csv, write_path_gpx, write_path_tum,
};
use gyropath::import::{ImportOptions, Imported, Level, MountChoice, TopicChoice};
use gyropath::model::{DEFAULT_BIAS_WALK, Increment, ModelSpec};
use gyropath::optimisation::{
    AutoNoise, FitSettings, IterationReport, Method, Phase, Reconstruction,
};
use gyropath::pipeline;
use gyropath::signals::Signals;
use gyropath::simulation::{self, SimConfig};

mod batch;
mod check;
mod diagnose;
mod explain;
mod fit;
mod import;
mod simulate;

pub use check::{CheckArgs, check};
pub use diagnose::{DiagnoseArgs, diagnose};
pub use explain::{ExplainArgs, explain};
pub use fit::{FitArgs, fit};
pub use import::{ImportArgs, import};
pub use simulate::{SimulateArgs, simulate};

#[derive(Debug, Parser)]
#[command(
    name = "gyropath",
    version,
    about = "Reconstruct a ride's path from gyro, odometer and GPS by estimating the gyro bias"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit the model to a ride log and write the reconstructed path.
    ///
    /// Example: `gyropath fit ride.csv --out path.csv --json report.json`;
    /// with a GPS lag added and a reference track:
    /// `gyropath fit ride.csv --effects gps_lag --reference truth.csv`;
    /// a folder of rides: `gyropath fit rides/ --out-dir results/`.
    Fit(FitArgs),
    /// Write a simulated ride (and its true path).
    ///
    /// Example: `gyropath simulate --seed 7 --gps city --out ride.csv --truth truth.csv`.
    Simulate(SimulateArgs),
    /// Fit the model, then rank the effects it lacks by how much each lowers the held-out error.
    ///
    /// It starts with the answer and the command that adds the missing
    /// effect. Example: `gyropath diagnose ride.csv --reference truth.csv --json diagnosis.json`.
    Diagnose(DiagnoseArgs),
    /// Find what the model lacks in one step: fit, diagnose, add the top
    /// significant effect, refit, until nothing significant is left.
    ///
    /// Each step is told as it finishes (the effect, its estimate, the
    /// held-out error and its drop, the error to a reference). Example:
    /// `gyropath explain ride.csv --reference truth.csv --out path.csv --save-model sensor.json`;
    /// then `gyropath fit next-ride.csv --model sensor.json`.
    Explain(ExplainArgs),
    /// Open the app on a ride log or bag; without one, on the bundled sample ride.
    ///
    /// Example: `gyropath open ride.csv`, `gyropath open test1.bag --mount auto`.
    Open(OpenArgs),
    /// Convert a ROS 1 bag, a ROS 2 bag (MCAP or rosbag2 folder), a comma2k19 segment, a PX4 ULog, an ArduPilot .bin, a camera file (GoPro MP4, ...), an Android GnssLogger .txt or a mapped CSV to a ride-log CSV.
    ///
    /// Example: `gyropath import test1.bag --out ride.csv`;
    /// `gyropath import logger.csv --map logger.toml --out ride.csv`.
    Import(ImportArgs),
    /// Check a log's axes, units and datum against its own data, and recommend a mounting.
    ///
    /// Exits with status 1 when it reports a problem that reading the input
    /// as its kind does by default leaves (a bag's axes are re-mounted by
    /// default, a CSV's are not), and with --strict on a warning too.
    /// Example: `gyropath check ride.csv --json check.json`.
    Check(CheckArgs),
}

#[derive(Debug, Args)]
pub struct OpenArgs {
    /// Ride log (CSV), ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder),
    /// comma2k19 segment, PX4 ULog or ArduPilot .bin, camera file (GoPro MP4, ...), Android GnssLogger .txt, or a CSV
    /// with --map; none: the bundled sample ride.
    pub ride: Option<PathBuf>,
    #[command(flatten)]
    pub source: SourceArgs,
    /// A better track of the same drive (RTK, an INS), loaded as File > Open
    /// reference track loads it: drawn under the path, and the path's error
    /// to it shown and plotted. Example: `gyropath open ride.csv --reference truth.csv`.
    #[arg(long)]
    pub reference: Option<PathBuf>,
}

/// How to read an input: topics of a bag, mounting, column map.
#[derive(Clone, Debug, Default, Args)]
pub struct SourceArgs {
    /// Bag topic of the IMU (sensor_msgs/Imu); by type when there is one.
    #[arg(long)]
    pub imu: Option<String>,
    /// Bag topic of the odometer (nav_msgs/Odometry or geometry_msgs/TwistStamped).
    #[arg(long)]
    pub odom: Option<String>,
    /// Bag topic of the GPS (sensor_msgs/NavSatFix).
    #[arg(long)]
    pub fix: Option<String>,
    /// Sensor mounting: `auto` (what `check` recommends), `none` (as logged), or a
    /// mapping such as "x=-z,y=-x,z=y". Not given: `auto` for bags, `none` for CSV.
    #[arg(long)]
    pub mount: Option<String>,
    /// TOML column map: read the input as a mapped CSV (see docs/real-logs.md).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Second CSV with the GPS fixes of a mapped CSV, joined by time.
    #[arg(long)]
    pub gps_csv: Option<PathBuf>,
    /// Attitude model: `auto` (planar for yaw-rate sensors and vehicles that stay
    /// level, else 3D), `3d`, or `planar` (heading only).
    #[arg(long, default_value = "auto")]
    pub attitude: String,
    /// Distance: `auto` (the wheel sensor or odometer, else the GNSS speed) or
    /// `gnss` (the GNSS speed, leaving the log's odometer out).
    #[arg(long, default_value = "auto")]
    pub distance: String,
    /// A Garmin FIT activity (a bike computer's) whose distance, its
    /// wheel-speed sensor's, is the ride's odometer, matched by UTC: for a
    /// camera, phone or drone log without a wheel sensor. The ride is cut to
    /// the time the FIT covers.
    #[arg(long)]
    pub wheel: Option<PathBuf>,
    /// A GPS track of the same ride (a watch's or bike computer's GPX or FIT,
    /// a phone's NMEA, a t_s,lat_deg,lon_deg CSV) whose points are the
    /// ride's fixes: for a camera, phone or robot log without GPS. Matched by
    /// UTC, or by the vehicle's turns where the log has no UTC start.
    #[arg(long, value_name = "FILE")]
    pub gps_track: Option<PathBuf>,
    /// Fit only the part of the log between two times, START,END (s, on the
    /// log's own clock, as `t_s`): one side of a pause, say.
    #[arg(long, value_name = "START,END")]
    pub between: Option<String>,
}

/// `START,END` of `--between`: two times, the first before the second.
fn parse_between(text: &str) -> Result<(f64, f64)> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let times: Vec<f64> = parts.iter().filter_map(|p| p.parse::<f64>().ok()).collect();
    match times.as_slice() {
        [a, b] if parts.len() == 2 && a.is_finite() && b.is_finite() && a < b => Ok((*a, *b)),
        _ => anyhow::bail!(
            "--between '{text}': give START,END, two times in seconds on the log's clock, the first before the second (e.g. --between 0,600)"
        ),
    }
}

impl SourceArgs {
    pub fn options(&self) -> Result<ImportOptions> {
        let mount: MountChoice = match &self.mount {
            Some(m) => m.parse().map_err(|e| anyhow::anyhow!("--mount: {e}"))?,
            None => MountChoice::default(),
        };
        if self.gps_csv.is_some() && self.map.is_none() {
            anyhow::bail!(
                "--gps-csv joins a second CSV to a mapped CSV: give the column map with --map"
            );
        }
        Ok(ImportOptions {
            topics: TopicChoice {
                imu: self.imu.clone(),
                odom: self.odom.clone(),
                fix: self.fix.clone(),
            },
            mount,
            map: self.map.clone(),
            gps: self.gps_csv.clone(),
            attitude: (self.attitude != "auto").then(|| self.attitude.clone()),
            distance: self
                .distance
                .parse()
                .map_err(|e| anyhow::anyhow!("--distance: {e}"))?,
            wheel: self.wheel.clone(),
            gps_track: self.gps_track.clone(),
            between: self.between.as_deref().map(parse_between).transpose()?,
        })
    }
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum MethodArg {
    Lm,
    Gd,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum IncrementArg {
    Exact,
    SmallAngle,
}

/// The model and optimiser options shared by `fit` and `diagnose`.
#[derive(Debug, Args)]
pub struct SettingsArgs {
    /// Effects added to the paper's model (its five: initial_position,
    /// initial_orientation, odometer_gain, gyro_bias, gyro_bias_segments), comma
    /// separated; `-ID` takes one out. Catalogue: gyro_scale, gps_lag,
    /// mount_misalignment, gyro_bias_channel:<column>, baro_drift, gps_outliers.
    /// Example: `--effects gps_lag` fits the paper's model plus a GPS lag;
    /// `--effects=-odometer_gain` takes the odometer as calibrated.
    #[arg(long, default_value = "paper", allow_hyphen_values = true)]
    pub effects: String,
    /// Length of a bias segment (s).
    #[arg(long, default_value_t = 5.0)]
    pub segment_s: f64,
    /// Step-2 optimiser.
    #[arg(long, value_enum, default_value_t = MethodArg::Lm)]
    pub method: MethodArg,
    /// Gradient-descent step size gamma.
    #[arg(long, default_value_t = 1e-6)]
    pub step_size: f64,
    /// Initial Levenberg-Marquardt damping lambda.
    #[arg(long, default_value_t = 1e-3)]
    pub damping: f64,
    /// Iteration limit for each step.
    #[arg(long, default_value_t = 200)]
    pub max_iter: usize,
    /// Random-walk density of the segment-bias prior in deg/s/sqrt(s), `auto`
    /// (estimated from the ride by restricted marginal likelihood), or `none`
    /// for the paper's model without prior.
    #[arg(long, default_value_t = DEFAULT_BIAS_WALK.to_string())]
    pub bias_walk: String,
    /// GPS noise: `auto` (wander, correlation time and jitter estimated from the
    /// ride), `SIGMA` in m (independent fixes), `SIGMA,TAU` (an error wandering
    /// over TAU s) or `SIGMA,TAU,JITTER` (plus a jitter of JITTER m per fix).
    #[arg(long, alias = "gps-sigma", default_value = "auto")]
    pub gps_noise: String,
    /// With `--gps-noise auto`: `gain` (the default) keeps the Gaussian law
    /// but checks the odometer gain against a heavy-tailed (Student-t) fit
    /// where the ride's innovations ask for one, and holds the robust gain
    /// where the two differ beyond chance (Hausman's test at 0.1 %: a city's
    /// reflections lengthen the least squares' track; Berlin 9.34 -> 6.28 m
    /// from its reference); `auto` keeps the heavy-tailed fit whole, each fix
    /// weighted by how unlikely it is (Berlin 7.85 m; some simulated urban
    /// rides end further from their truth); `off`: the Gaussian law alone.
    /// See docs/real-drives.md.
    #[arg(long, value_enum, default_value_t = TailsArg::Gain)]
    pub gps_tails: TailsArg,
    /// Increment map: exact exponential or the paper's small-angle quaternion.
    #[arg(long, value_enum, default_value_t = IncrementArg::Exact)]
    pub increment: IncrementArg,
}

/// Whether the GPS error's heavy tails are learnt from the ride.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TailsArg {
    Gain,
    Auto,
    Off,
}

fn split_list(s: &str) -> Vec<String> {
    s.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(String::from)
        .collect()
}

impl SettingsArgs {
    pub fn settings(&self) -> Result<FitSettings> {
        let walk = match self.bias_walk.trim() {
            "none" | "off" => None,
            "auto" => Some(DEFAULT_BIAS_WALK),
            v => Some(v.parse::<f64>().with_context(|| {
                format!("--bias-walk: '{v}' is not a number, 'auto' or 'none'")
            })?),
        };
        let (sigma, tau, white) = match self.gps_noise.trim() {
            "auto" => (ModelSpec::default().sigma_horizontal_m, None, 0.0),
            v => {
                let bad = || {
                    format!(
                        "--gps-noise: '{v}' is not 'auto', SIGMA, SIGMA,TAU or SIGMA,TAU,JITTER"
                    )
                };
                let mut parts = v.split(',').map(str::trim);
                let sigma: f64 = parts.next().unwrap_or("").parse().with_context(bad)?;
                let tau: Option<f64> = parts
                    .next()
                    .map(|t| t.parse::<f64>().with_context(bad))
                    .transpose()?;
                let white: f64 = match parts.next() {
                    Some(w) if tau.is_some() => w.parse().with_context(bad)?,
                    Some(_) => anyhow::bail!(bad()),
                    None => 0.0,
                };
                if parts.next().is_some() {
                    anyhow::bail!(bad());
                }
                (sigma, tau, white)
            }
        };
        Ok(FitSettings {
            auto_noise: AutoNoise {
                gps: self.gps_noise.trim() == "auto",
                walk: self.bias_walk.trim() == "auto",
                tails: self.gps_tails == TailsArg::Auto,
                robust_gain: self.gps_tails == TailsArg::Gain,
            },
            model: ModelSpec {
                // The paper's model, then what the user listed (once each:
                // `--effects paper,gps_lag` says the same as `gps_lag`).
                effects: std::iter::once("paper".to_string())
                    .chain(
                        split_list(&self.effects)
                            .into_iter()
                            .filter(|e| e != "paper"),
                    )
                    .collect(),
                segment_s: self.segment_s,
                bias_walk_dps_sqrt_s: walk,
                sigma_horizontal_m: sigma,
                gps_tau_s: tau,
                gps_white_m: white,
                increment: match self.increment {
                    IncrementArg::Exact => Increment::Exact,
                    IncrementArg::SmallAngle => Increment::SmallAngle,
                },
                ..ModelSpec::default()
            },
            method: match self.method {
                MethodArg::Lm => Method::Lm,
                MethodArg::Gd => Method::Gd,
            },
            step_size: self.step_size,
            damping: self.damping,
            max_iter: self.max_iter,
            ..FitSettings::default()
        })
    }
}

/// Read any input, say where it came from and what the checks found (unless
/// quiet), and derive its signals.
pub fn load_signals(path: &Path, source: &SourceArgs, quiet: bool) -> Result<Arc<Signals>> {
    Ok(load_ride(path, source, quiet)?.0)
}

/// [`load_signals`], with where the ride came from and what its checks
/// said (for the HTML report).
pub fn load_ride(
    path: &Path,
    source: &SourceArgs,
    quiet: bool,
) -> Result<(Arc<Signals>, pipeline::Origin)> {
    let imported = pipeline::open(path, &source.options()?)?;
    if !quiet {
        describe_source(&imported);
    }
    let origin = pipeline::Origin::of(&imported);
    Ok((pipeline::signals(imported)?, origin))
}

/// The command line as typed, to print on a report ("gyropath fit ride.csv
/// --html r.html"); arguments with spaces or quotes are single-quoted.
fn command_line() -> String {
    std::env::args()
        .enumerate()
        .map(|(i, a)| {
            let a = if i == 0 { "gyropath".to_string() } else { a };
            if a.is_empty() || a.contains(|c: char| c.is_whitespace() || "'\"$`\\".contains(c)) {
                format!("'{}'", a.replace('\'', "'\\''"))
            } else {
                a
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Write the HTML report of a plain fit (`fit --html`, a batch's pages).
fn write_fit_html(
    out: &Path,
    ride: &Path,
    fit: &Reconstruction,
    origin: &pipeline::Origin,
    against: Option<&pipeline::MatchedReference>,
    uncertainty: Option<&gyropath::model::Uncertainty>,
    report: &FitReport,
) -> Result<()> {
    let contents = gyropath::report::Contents::of_fit(
        fit,
        Some(origin),
        against,
        uncertainty,
        Some(report),
        command_line(),
    );
    write_html(out, ride, &contents)
}

/// Write the HTML report of `contents` to `out`.
fn write_html(out: &Path, ride: &Path, contents: &gyropath::report::Contents) -> Result<()> {
    gyropath::report::write(out, Some(ride), contents)
        .context("the HTML report could not be written")
}

/// One or two lines on stderr: what was read, from which topics, mounted how.
fn describe_source(im: &Imported) {
    if let Some(t) = &im.topics {
        eprintln!(
            "read {} ({}): IMU {}, odometer {}, GPS {}",
            im.log.source,
            im.kind.label(),
            t.imu,
            t.odom,
            t.fix
        );
    }
    if let Some(m) = &im.mount {
        eprintln!("mounting applied: {m}");
    }
}

/// Write a JSON report to `out`.
fn write_report(out: &Path, ride: &Path, report: &impl serde::Serialize) -> Result<()> {
    write_atomically(out, Some(ride), |w| write_json(w, report))
        .context("the report could not be written")
}

/// A fit beyond the physical limits is a failure, with its likely cause,
/// never a result (see `gyropath::limits`).
fn physical(fit: &Reconstruction, origin: &pipeline::Origin) -> Result<()> {
    match pipeline::failure_given(fit, origin) {
        Some(message) => anyhow::bail!(message),
        None => Ok(()),
    }
}

/// Match a reference track (read before the ride, so that a bad file fails
/// before a long load) to the ride's rows: one of another drive fails here,
/// before the fit. What its reading left out is said unless `quiet` (the
/// reports carry it too).
fn matched_reference(
    reference: Option<&Path>,
    signals: &Signals,
    quiet: bool,
) -> Result<Option<pipeline::MatchedReference>> {
    let matched = reference
        .map(|p| pipeline::reference_for(p, signals))
        .transpose()?;
    if !quiet {
        for w in matched.iter().flat_map(|(track, _)| &track.warnings) {
            eprintln!("warning: {w}");
        }
    }
    Ok(matched)
}

/// Write the fitted path to `out` in `format`.
fn write_path(
    out: &Path,
    format: PathFormat,
    ride: &Path,
    fit: &Reconstruction,
    uncertainty: Option<&gyropath::model::Uncertainty>,
) -> Result<()> {
    match format {
        PathFormat::Csv => write_atomically(out, Some(ride), |w| {
            write_path_csv(w, fit.model(), fit.params(), uncertainty)
        }),
        PathFormat::Gpx => {
            let trajectory = fit.trajectory();
            write_atomically(out, Some(ride), |w| {
                write_path_gpx(w, fit.model(), &trajectory)
            })
        }
        PathFormat::Tum => write_atomically(out, Some(ride), |w| {
            write_path_tum(w, fit.model(), fit.params())
        }),
    }
    .context("the path could not be written")
}

/// Whether one of a command's outputs goes to standard output (`-`), where
/// its summary must then stay out of the way; an error naming them when
/// more than one does, since their data would be mixed.
fn data_on_stdout(outputs: &[(&str, &Option<PathBuf>)]) -> Result<bool> {
    let on: Vec<&str> = outputs
        .iter()
        .filter(|(_, p)| p.as_deref().is_some_and(is_stdout))
        .map(|(flag, _)| *flag)
        .collect();
    if on.len() > 1 {
        let all = if on.len() == 2 { "both" } else { "all" };
        anyhow::bail!("{} cannot {all} go to standard output", on.join(" and "));
    }
    Ok(on.len() == 1)
}
