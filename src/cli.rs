//! The command line: `gyropath fit`, `diagnose`, `import`, `check`, `simulate` and `open`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};

use gyropath::diagnosis::{Diagnosis, Folds, reference};
use gyropath::export::{
    FitReport, PathFormat, check_report_name, is_stdout, write_atomically, write_json,
    write_path_csv, write_path_gpx, write_path_tum,
};
use gyropath::import::{
    self, ImportOptions, Imported, Level, MountChoice, ReferenceTrack, TopicChoice,
};
use gyropath::limits;
use gyropath::model::{DEFAULT_BIAS_WALK, Increment, ModelSpec};
use gyropath::optimisation::{
    AutoNoise, FitSettings, IterationReport, Method, Phase, Reconstruction,
};
use gyropath::signals::Signals;
use gyropath::simulation::{self, SimConfig};

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
    /// Open the app on a ride log or bag; without one, on the bundled sample ride.
    ///
    /// Example: `gyropath open ride.csv`, `gyropath open test1.bag --mount auto`.
    Open(OpenArgs),
    /// Convert a ROS 1 bag, a ROS 2 bag (MCAP or rosbag2 folder) or a mapped CSV to a ride-log CSV.
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
    /// Ride log (CSV), ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder), or
    /// a CSV with --map; none: the bundled sample ride.
    pub ride: Option<PathBuf>,
    #[command(flatten)]
    pub source: SourceArgs,
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
        })
    }
}

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The input: ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder), ride-log CSV, or a CSV with --map.
    pub source: PathBuf,
    #[command(flatten)]
    pub options: SourceArgs,
    /// Where to write the ride-log CSV.
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The input: ride-log CSV, ROS 1 bag, ROS 2 bag, or a CSV with --map.
    pub source: PathBuf,
    #[command(flatten)]
    pub options: SourceArgs,
    /// Write the verdicts here (JSON; - for standard output).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Exit with status 1 on warnings too, not only on problems.
    #[arg(long)]
    pub strict: bool,
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

#[derive(Debug, Args)]
pub struct FitArgs {
    /// Ride log(s) (CSV, see the ride-log format), or folders of them: more
    /// than one, a folder, or --out-dir fits them all in parallel (batch mode).
    #[arg(required = true, num_args = 1..)]
    pub rides: Vec<PathBuf>,
    #[command(flatten)]
    pub source: SourceArgs,
    #[command(flatten)]
    pub settings: SettingsArgs,
    /// Batch mode: write RIDE-path.csv and RIDE-report.json for every ride here.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Write the reconstructed path here, in the format its extension names:
    /// `.csv` (t_s,lat_deg,lon_deg,alt_m,...; - for standard output), `.gpx`,
    /// or `.tum` (a TUM trajectory for evo, in Unix time when the source has it).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the fit report here (JSON; - for standard output). `--report`
    /// is an older name for it.
    #[arg(long, alias = "report")]
    pub json: Option<PathBuf>,
    /// A better track of the same drive to measure the path against (RTK, an
    /// INS): `t_s,lat_deg,lon_deg[,alt_m]` CSV on the ride's clock. In a batch
    /// a file name that does not exist is looked up beside each ride
    /// (`--reference truth.csv`). Example: `gyropath fit ride.csv --reference truth.csv`.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(long, short)]
    pub quiet: bool,
    /// Also print every iteration's cost and the segment lengths' -2 ln L.
    #[arg(long, short)]
    pub verbose: bool,
}

#[derive(Debug, Args)]
#[command(mut_arg("gps_noise", |a| a.help(
    "GPS noise: `auto` fits the base model with the noise estimated from the ride, then \
     ranks every candidate under independent 3 m fixes (the noise the significance rule \
     was calibrated under); `SIGMA`, `SIGMA,TAU` or `SIGMA,TAU,JITTER` (m, s, m) are used \
     for both"
)))]
pub struct DiagnoseArgs {
    /// Ride log (CSV), ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder), or a CSV with --map.
    pub ride: PathBuf,
    #[command(flatten)]
    pub source: SourceArgs,
    #[command(flatten)]
    pub settings: SettingsArgs,
    /// Write the diagnosis here (JSON).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// A better track of the same drive (`t_s,lat_deg,lon_deg[,alt_m]` CSV on
    /// the ride's clock): the model and every candidate are measured against it.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Number of validation folds.
    #[arg(long, default_value_t = 5)]
    pub folds: usize,
    /// Length of a validation block of GPS fixes (s).
    #[arg(long, default_value_t = 60.0)]
    pub block_s: f64,
    /// h-block guard band (s): fixes this close to a withheld block are neither fitted nor scored.
    #[arg(long, default_value_t = 0.0)]
    pub guard_s: f64,
    /// Print nothing but errors and the table.
    #[arg(long, short)]
    pub quiet: bool,
    /// Also print the residuals' whiteness (Ljung-Box) and structure.
    #[arg(long, short)]
    pub verbose: bool,
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
    /// Increment map: exact exponential or the paper's small-angle quaternion.
    #[arg(long, value_enum, default_value_t = IncrementArg::Exact)]
    pub increment: IncrementArg,
}

#[derive(Debug, Args)]
pub struct SimulateArgs {
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Ride length (s).
    #[arg(long, default_value_t = 600.0)]
    pub duration: f64,
    /// Logging rate (Hz).
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Hidden effects, comma separated: gyro_scale, gps_lag, mount_misalignment, gyro_bias_channel:temp_c, gps_outliers.
    #[arg(long, default_value = "")]
    pub hidden: String,
    /// Log cumulative distance (odo_m) instead of wheel pulses.
    #[arg(long)]
    pub odometer: bool,
    /// No GPS outages.
    #[arg(long)]
    pub no_outages: bool,
    /// What drives: bicycle (wheel pulses), car (8-20 m/s, lane changes, reversing
    /// out of a parking bay; wheel speed) or robot (0.5-1 m/s, skid-steer shaking, 2.5 Hz GPS).
    #[arg(long, default_value = "bicycle")]
    pub vehicle: String,
    /// Log only the yaw rate (gx_dps and gy_dps written as 0), as a car's yaw-rate sensor.
    #[arg(long)]
    pub yaw_only: bool,
    /// Write the gyro in other axes or units: the mounting that undoes it, e.g.
    /// "x=-z,y=-x,z=y" or "x=y,y=-x,z=z,scale=57.29577951308232" (rad/s).
    #[arg(long)]
    pub gyro_axes: Option<String>,
    /// GPS environment: open sky; urban (street canyons, heavy tails, fixes pulled
    /// to one side, jumps of 10-70 m; logs gps_hacc_m and sats); or city
    /// (reflections of 10-75 m that come and go within seconds over a broad
    /// error, a fix in about 55 % of the seconds: calibrated on a real city drive).
    #[arg(long, default_value = "open")]
    pub gps: String,
    /// The gyro bias's random-walk density (deg/s/sqrt(s)); drawn in 0.002-0.004 when not given.
    #[arg(long)]
    pub bias_walk: Option<f64>,
    /// Where to write the ride log.
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the true path (t_s,lat_deg,lon_deg,alt_m).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Where to write the true parameters (JSON).
    #[arg(long)]
    pub truth_params: Option<PathBuf>,
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
pub fn load_signals(path: &Path, source: &SourceArgs, quiet: bool) -> Result<Signals> {
    let imported = import::open(path, &source.options()?)?;
    if !quiet {
        describe_source(&imported);
    }
    Ok(imported.into_signals()?)
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

fn phase_name(p: Phase) -> &'static str {
    match p {
        Phase::Step1 => "step 1",
        Phase::Step2 => "step 2",
        Phase::Noise => "noise",
        Phase::Done => "done",
    }
}

fn progress_line(r: &IterationReport) -> String {
    format!(
        "{:>4} {} {:<2} cost {:>12.4} rms {:>7.3} m {} {}{}",
        r.iteration,
        phase_name(r.phase),
        match r.method {
            Method::Lm => "lm",
            Method::Gd => "gd",
        },
        r.cost,
        r.rms_horizontal_m,
        match r.method {
            Method::Lm => format!("lambda {:.1e}", r.damping),
            Method::Gd => format!("gamma {:.1e}", r.step_size),
        },
        if r.accepted { "" } else { "(step rejected) " },
        if r.phase_finished { "(converged)" } else { "" }
    )
}

pub fn fit(args: &FitArgs) -> Result<()> {
    let folder_of_rides = args.rides[0].is_dir() && !args.rides[0].join("metadata.yaml").is_file();
    let batch = args.rides.len() > 1 || args.out_dir.is_some() || folder_of_rides;
    if batch {
        return fit_batch(args);
    }
    let ride = &args.rides[0];
    let started = Instant::now();
    let settings = args.settings.settings()?;
    // The outputs' names are checked before the fit, not after minutes of it.
    let path_format = args.out.as_deref().map(PathFormat::of).transpose()?;
    if let Some(rep) = &args.json {
        check_report_name(rep)?;
    }
    let to_stdout = |p: &Option<PathBuf>| p.as_deref().is_some_and(is_stdout);
    if to_stdout(&args.out) && to_stdout(&args.json) {
        anyhow::bail!("--out and --json cannot both go to standard output");
    }
    let data_is_stdout = to_stdout(&args.out) || to_stdout(&args.json);
    let reference = args
        .reference
        .as_deref()
        .map(import::read_reference)
        .transpose()?;
    let signals = Arc::new(load_signals(ride, &args.source, args.quiet)?);
    if !args.quiet {
        for w in &signals.warnings {
            eprintln!("warning: {w}");
        }
    }
    let against = matched_reference(reference, &signals)?;
    let mut fit = Reconstruction::new(signals, settings)?;
    let terminal = std::io::stderr().is_terminal() && !args.quiet;
    let bar = terminal.then(|| {
        let bar = indicatif::ProgressBar::new_spinner();
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar
    });
    let verbose = args.verbose && !args.quiet;
    fit.run(&mut |_: &Reconstruction, r: &IterationReport| {
        let line = progress_line(r);
        match &bar {
            Some(b) => b.set_message(line),
            None if verbose => eprintln!("{line}"),
            None => {}
        }
    });
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    physical(&fit)?;
    let uncertainty = (args.out.is_some() || args.json.is_some())
        .then(|| fit.model().uncertainty(fit.params()))
        .flatten();
    let elapsed = started.elapsed().as_secs_f64();
    let mut report = match &uncertainty {
        Some(u) => FitReport::with_uncertainty(&fit, elapsed, u),
        None => FitReport::new(&fit, elapsed),
    };
    if let Some((r, m)) = &against {
        report.reference = Some(reference::compare(fit.model(), fit.params(), r, m));
    }
    if let (Some(out), Some(format)) = (&args.out, path_format) {
        write_path(out, format, ride, &fit, uncertainty.as_ref())?;
    }
    if let Some(rep) = &args.json {
        write_report(rep, ride, &report)?;
    }
    if !args.quiet {
        // Data on standard output: the summary goes to standard error.
        let summary = summary_text(&report, args.verbose);
        if data_is_stdout {
            eprint!("{summary}");
        } else {
            print!("{summary}");
        }
    }
    Ok(())
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

/// Write a JSON report to `out`.
fn write_report(out: &Path, ride: &Path, report: &impl serde::Serialize) -> Result<()> {
    write_atomically(out, Some(ride), |w| write_json(w, report))
        .context("the report could not be written")
}

/// A fit beyond the physical limits is a failure, with its likely cause,
/// never a result (see `gyropath::limits`).
fn physical(fit: &Reconstruction) -> Result<()> {
    let broken = limits::check(fit.model(), fit.params());
    if broken.is_empty() {
        return Ok(());
    }
    let lines: Vec<String> = broken.iter().map(|v| format!("  {v}")).collect();
    anyhow::bail!(
        "{}: the fit failed: it is {} (its path is {:.2} m RMS from the fixes):\n{}",
        fit.model().signals.source,
        if limits::parameters(fit.model(), fit.params()).is_empty() {
            "no result"
        } else {
            "not physical"
        },
        fit.stats().rms_horizontal_m,
        lines.join("\n")
    )
}

/// One line of the batch summary.
struct BatchRow {
    ride: String,
    outcome: Result<FitReport, String>,
}

/// Every `.csv`, `.bag` and `.mcap` in the given files and folders (folders not
/// recursed; a rosbag2 folder is one ride), sorted.
fn collect_rides(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut rides = Vec::new();
    for input in inputs {
        if input.is_dir() && !input.join("metadata.yaml").is_file() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(input)
                .with_context(|| format!("cannot list {}", input.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().is_some_and(|x| {
                        ["csv", "bag", "mcap"]
                            .iter()
                            .any(|e| x.eq_ignore_ascii_case(e))
                    })
                })
                .collect();
            found.sort();
            rides.extend(found);
        } else {
            rides.push(input.clone());
        }
    }
    if rides.is_empty() {
        anyhow::bail!("no ride logs (*.csv, *.bag, *.mcap) found in the given folders");
    }
    Ok(rides)
}

/// The names of a batch's outputs, one per ride: the ride's file stem, with
/// as many of its folders before it as it takes to tell it from every other
/// ride (`comma/ride.csv` and `berlin/ride.csv` become `comma-ride` and
/// `berlin-ride`), so one ride's outputs never overwrite another's. The same
/// ride given twice is an error that names it.
fn output_stems(rides: &[PathBuf]) -> Result<Vec<String>> {
    let parts: Vec<Vec<String>> = rides
        .iter()
        .map(|ride| {
            let absolute = std::path::absolute(ride).unwrap_or_else(|_| ride.clone());
            let mut parts: Vec<String> = absolute
                .parent()
                .into_iter()
                .flat_map(|p| p.components())
                .filter_map(|c| match c {
                    std::path::Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
                    _ => None,
                })
                .collect();
            parts.push(
                absolute
                    .file_stem()
                    .map_or_else(|| "ride".into(), |s| s.to_string_lossy().into_owned()),
            );
            parts
        })
        .collect();
    let name = |p: &[String], k: usize| p[p.len() - k.min(p.len())..].join("-");
    let mut depth = vec![1usize; rides.len()];
    loop {
        let names: Vec<String> = (0..rides.len())
            .map(|i| name(&parts[i], depth[i]))
            .collect();
        let twin = |i: usize| (0..rides.len()).find(|&j| j != i && names[j] == names[i]);
        let clashing: Vec<usize> = (0..rides.len()).filter(|&i| twin(i).is_some()).collect();
        if clashing.is_empty() {
            return Ok(names);
        }
        if let Some(&i) = clashing.iter().find(|&&i| depth[i] >= parts[i].len()) {
            anyhow::bail!(
                "{} and {} would write the same outputs ({}-path.csv): give each ride once",
                rides[twin(i).unwrap_or(i)].display(),
                rides[i].display(),
                names[i]
            );
        }
        for i in clashing {
            depth[i] += 1;
        }
    }
}

/// Match a reference track (read before the ride, so that a bad file fails
/// before a long load) to the ride's rows: one of another drive fails here,
/// before the fit.
fn matched_reference(
    reference: Option<ReferenceTrack>,
    signals: &Signals,
) -> Result<Option<(ReferenceTrack, reference::Matched)>> {
    reference
        .map(|r| {
            let m = reference::match_rows(signals, &r)?;
            Ok((r, m))
        })
        .transpose()
}

/// A batch ride's reference: `reference` itself where it exists, else a file
/// of that name beside the ride (none if there is none).
fn reference_for(ride: &Path, reference: Option<&Path>) -> Option<PathBuf> {
    let r = reference?;
    if r.exists() {
        return Some(r.to_path_buf());
    }
    let beside = ride.parent().unwrap_or(Path::new(".")).join(r);
    beside.is_file().then_some(beside)
}

/// Fit one ride of a batch and write its outputs into `out_dir` as
/// `STEM-path.csv` and `STEM-report.json` (nothing without an `out_dir`).
fn fit_one(
    ride: &Path,
    source: &SourceArgs,
    settings: &FitSettings,
    out_dir: Option<&Path>,
    stem: &str,
    reference: Option<&Path>,
) -> Result<FitReport> {
    let started = Instant::now();
    let reference = reference_for(ride, reference)
        .map(|p| import::read_reference(&p))
        .transpose()?;
    let signals = Arc::new(load_signals(ride, source, true)?);
    let against = matched_reference(reference, &signals)?;
    let mut fit = Reconstruction::new(signals, settings.clone())?;
    fit.finish();
    physical(&fit)?;
    let uncertainty = fit.model().uncertainty(fit.params());
    let elapsed = started.elapsed().as_secs_f64();
    let mut report = match &uncertainty {
        Some(u) => FitReport::with_uncertainty(&fit, elapsed, u),
        None => FitReport::new(&fit, elapsed),
    };
    if let Some((r, m)) = &against {
        report.reference = Some(reference::compare(fit.model(), fit.params(), r, m));
    }
    if let Some(dir) = out_dir {
        write_path(
            &dir.join(format!("{stem}-path.csv")),
            PathFormat::Csv,
            ride,
            &fit,
            uncertainty.as_ref(),
        )?;
        write_report(&dir.join(format!("{stem}-report.json")), ride, &report)?;
    }
    Ok(report)
}

/// Batch mode: every ride on all cores (one ride per task; each fit is
/// sequential apart from the linear algebra), then a summary table. Rides that
/// fail are reported in the table and make the exit status 1, but never stop the others.
fn fit_batch(args: &FitArgs) -> Result<()> {
    use rayon::prelude::*;
    if args.out.is_some() || args.json.is_some() {
        anyhow::bail!("with several rides use --out-dir instead of --out/--json");
    }
    // Without --out-dir a batch writes no files: a folder of rides must not
    // scatter outputs into the working directory.
    let out_dir = args.out_dir.as_deref();
    if let Some(dir) = out_dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    }
    let settings = args.settings.settings()?;
    let rides = collect_rides(&args.rides)?;
    let stems = output_stems(&rides)?;
    let started = Instant::now();
    let rows: Vec<BatchRow> = rides
        .par_iter()
        .zip(stems.par_iter())
        .map(|(ride, stem)| {
            let outcome = fit_one(
                ride,
                &args.source,
                &settings,
                out_dir,
                stem,
                args.reference.as_deref(),
            )
            .map_err(|e| format!("{e:#}"));
            if !args.quiet {
                eprintln!(
                    "{} {}",
                    if outcome.is_ok() { "fitted" } else { "FAILED" },
                    ride.display()
                );
            }
            BatchRow {
                ride: ride.display().to_string(),
                outcome,
            }
        })
        .collect();
    println!(
        "{:<40} {:>8} {:>6} {:>9} {:>9} {:>9} {:>8} {:>9}",
        "ride", "min", "fixes", "fit RMS", "vert RMS", "yaw bias", "gain", "ref RMS"
    );
    let mut failed = 0;
    for row in &rows {
        match &row.outcome {
            Ok(r) => {
                let value = |e: &str, n: &str| r.value(e, n).unwrap_or(f64::NAN);
                let vertical = r.stats.rms_baro_up_m.or(r.stats.rms_gps_up_m);
                println!(
                    "{:<40} {:>8.1} {:>6} {:>7.3} m {:>9} {:>5.3}°/s {:>8.4} {:>9}",
                    row.ride,
                    r.duration_s / 60.0,
                    r.gps_fixes,
                    r.stats.rms_horizontal_m,
                    vertical.map_or("-".into(), |v| format!("{v:.3} m")),
                    r.bias_total[2].map_or(f64::NAN, |t| t.mean_dps),
                    value("odometer_gain", "gain"),
                    r.reference
                        .as_ref()
                        .map_or("-".into(), |c| format!("{:.3} m", c.horizontal.rms_m)),
                );
            }
            Err(e) => {
                failed += 1;
                println!("{:<40} failed: {e}", row.ride);
            }
        }
    }
    println!(
        "{} rides, {} fitted, {} failed, {:.1} s on {} threads; {}",
        rows.len(),
        rows.len() - failed,
        failed,
        started.elapsed().as_secs_f64(),
        rayon::current_num_threads(),
        match out_dir {
            Some(d) => format!("outputs in {}", d.display()),
            None => "no files written (--out-dir DIR keeps each ride's path and report)".into(),
        }
    );
    if failed > 0 {
        anyhow::bail!("{failed} of {} rides could not be fitted", rows.len());
    }
    Ok(())
}

/// Differences of `-2 ln L` below this are no evidence for one segment
/// length over another (a likelihood ratio of about 7).
const SEGMENT_EVIDENCE: f64 = 4.0;

/// The terminal summary of a fit.
fn summary_text(r: &FitReport, verbose: bool) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    _ = writeln!(
        out,
        "ride      {} ({} rows, {:.0} s, {} GPS fixes)",
        r.source, r.rows, r.duration_s, r.gps_fixes
    );
    _ = writeln!(out, "model     {}", r.model.join(", "));
    _ = writeln!(out, "attitude  {}", r.attitude);
    match &r.noise {
        Some(n) => _ = writeln!(out, "noise     from the ride: {}", n.describe()),
        None => {
            _ = writeln!(
                out,
                "noise     GPS sigma {:.2} m, {}, bias walk {} (set)",
                r.gps_sigma_m,
                r.gps_tau_s.map_or("independent fixes".into(), |t| format!(
                    "correlated over {t:.0} s, jitter {:.2} m",
                    r.gps_white_m
                )),
                r.bias_walk
                    .map_or("none".into(), |w| format!("{w:.4} deg/s/sqrt(s)"))
            )
        }
    }
    if let Some(&(best, _)) = r
        .segment_preference
        .iter()
        .find(|v| v.1 == 0.0)
        .filter(|_| verbose)
    {
        let spread = r.segment_preference.iter().map(|v| v.1).fold(0.0, f64::max);
        let lengths: Vec<String> = r
            .segment_preference
            .iter()
            .map(|(s, d)| format!("{s} s {d:+.1}"))
            .collect();
        if spread < SEGMENT_EVIDENCE {
            _ = writeln!(
                out,
                "segments  no length preferred ({}, -2 ln L): the bias walk sets the smoothing",
                lengths.join(", ")
            );
        } else {
            _ = writeln!(
                out,
                "segments  the ride prefers {best} s ({}, -2 ln L)",
                lengths.join(", ")
            );
        }
    }
    _ = writeln!(
        out,
        "iters     step 1: {}, step 2: {}",
        r.iterations_step1, r.iterations_step2
    );
    _ = writeln!(out, "cost      {:.4}", r.stats.cost);
    _ = writeln!(
        out,
        "rms       path to the fixes {:.3} m horizontal (under {})",
        r.stats.rms_horizontal_m, r.gps_noise
    );
    if let Some(v) = r.stats.rms_gps_up_m {
        _ = writeln!(out, "          GPS altitude {v:.3} m");
    }
    if let Some(v) = r.stats.rms_baro_up_m {
        _ = writeln!(out, "          barometer {v:.3} m");
    }
    for (axis, total) in ["x", "y", "z"].iter().zip(&r.bias_total) {
        if let Some(t) = total {
            _ = writeln!(out, "bias      total {axis} {}", t.describe());
        }
    }
    for (effect, values) in &r.parameters {
        if effect == "gyro_bias_segments" {
            let n = values.len() / 3;
            _ = writeln!(out, "{effect}: {n} segments (see --json)");
            continue;
        }
        let list: Vec<String> = values
            .iter()
            .map(|p| format!("{} {}", p.name, p.describe()))
            .collect();
        let part = if effect == "gyro_bias" && r.parameters.contains_key("gyro_bias_segments") {
            " (constant part)"
        } else {
            ""
        };
        _ = writeln!(out, "{effect}{part}: {}", list.join(", "));
    }
    if let Some(c) = &r.reference {
        _ = writeln!(out, "reference {}: {}", c.reference, c.coverage());
        _ = writeln!(out, "          {}", c.describe());
    }
    _ = writeln!(out, "time      {:.2} s", r.elapsed_s);
    out
}

pub fn simulate(args: &SimulateArgs) -> Result<()> {
    let config = SimConfig {
        seed: args.seed,
        duration_s: args.duration,
        rate_hz: args.rate,
        hidden: split_list(&args.hidden),
        odometer: args.odometer,
        outages: !args.no_outages,
        vehicle: args
            .vehicle
            .parse()
            .map_err(|e| anyhow::anyhow!("--vehicle: {e}"))?,
        yaw_only: args.yaw_only,
        gyro_axes: args
            .gyro_axes
            .as_deref()
            .map(str::parse)
            .transpose()
            .map_err(|e| anyhow::anyhow!("--gyro-axes: {e}"))?,
        gps: args
            .gps
            .parse()
            .map_err(|e| anyhow::anyhow!("--gps: {e}"))?,
        bias_walk_dps_sqrt_s: args.bias_walk,
    };
    let ride = simulation::simulate(&config)?;
    write_atomically(&args.out, None, |w| w.write_all(ride.log_csv.as_bytes()))?;
    if let Some(t) = &args.truth {
        write_atomically(t, None, |w| w.write_all(ride.truth_csv.as_bytes()))?;
    }
    if let Some(t) = &args.truth_params {
        write_atomically(t, None, |w| write_json(w, &ride.truth))?;
    }
    eprintln!(
        "wrote {} ({:.0} s, {:.0} m, hidden: {})",
        args.out.display(),
        ride.truth.duration_s,
        ride.truth.distance_m,
        if config.hidden.is_empty() {
            "none".into()
        } else {
            config.hidden.join(", ")
        }
    );
    Ok(())
}

pub fn diagnose(args: &DiagnoseArgs) -> Result<()> {
    let started = Instant::now();
    let settings = args.settings.settings()?;
    if let Some(json) = &args.json {
        check_report_name(json)?;
    }
    if args.folds < 2 {
        anyhow::bail!("--folds must be at least 2, got {}", args.folds);
    }
    if !(args.block_s.is_finite() && args.block_s >= 5.0) {
        anyhow::bail!("--block-s must be at least 5 s, got {}", args.block_s);
    }
    let reference = args
        .reference
        .as_deref()
        .map(import::read_reference)
        .transpose()?;
    let signals = Arc::new(load_signals(&args.ride, &args.source, args.quiet)?);
    if !args.quiet {
        for w in &signals.warnings {
            eprintln!("warning: {w}");
        }
    }
    let against = matched_reference(reference, &signals)?;
    let folds = Folds {
        block_s: args.block_s,
        k: args.folds,
        guard_s: args.guard_s,
    };
    let quiet = args.quiet;
    // On a terminal a bar with the time left (the candidates' refits are
    // most of a diagnosis); elsewhere one line per step.
    let bar = (std::io::stderr().is_terminal() && !quiet).then(|| {
        let bar = indicatif::ProgressBar::new(3);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} {msg} ({elapsed}, about {eta} left)",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        bar
    });
    let progress = |msg: &str| match &bar {
        Some(b) => {
            // "tried gps_lag (2 of 6)": the steps are then known.
            if let Some(total) = msg
                .rsplit_once(" of ")
                .and_then(|(_, n)| n.trim_end_matches(')').parse::<u64>().ok())
            {
                b.set_length(total + 3);
            }
            b.inc(1);
            b.set_message(msg.to_string());
        }
        None if !quiet => eprintln!("{msg}"),
        None => {}
    };
    let diagnosis = gyropath::diagnosis::diagnose_against(
        signals,
        &settings,
        &folds,
        against.as_ref().map(|(r, m)| (r, m)),
        &progress,
    )?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    if let Some(path) = &args.json {
        write_report(path, &args.ride, &diagnosis)?;
    }
    let mut table = diagnosis_text(&diagnosis, &args.ride, args.verbose);
    if !args.quiet {
        table += &format!("time      {:.2} s\n", started.elapsed().as_secs_f64());
    }
    if args.json.as_deref().is_some_and(is_stdout) {
        eprint!("{table}");
    } else {
        print!("{table}");
    }
    if !diagnosis.not_physical.is_empty() {
        anyhow::bail!(
            "{}: the model's own fit is not physical, so nothing it lacks can be told:\n  {}",
            args.ride.display(),
            diagnosis.not_physical.join("\n  ")
        );
    }
    Ok(())
}

/// The terminal table of a diagnosis.
fn diagnosis_text(d: &Diagnosis, ride: &Path, verbose: bool) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    // The answer first, in plain words, with the next command to run.
    let added: Vec<&str> = d
        .model
        .iter()
        .map(String::as_str)
        .filter(|id| !gyropath::effects::PAPER.contains(id) && *id != "baro_offset")
        .collect();
    match d.ranking.first() {
        _ if !d.not_physical.is_empty() => {
            _ = writeln!(
                out,
                "answer    the model's own fit is not physical: fix the axes or units first (see below)"
            );
        }
        Some(best) if best.significant => {
            let estimate: Vec<String> = best.estimate.values().map(|e| e.describe()).collect();
            let effects: Vec<&str> = added
                .iter()
                .copied()
                .chain(std::iter::once(best.effect.as_str()))
                .collect();
            _ = writeln!(
                out,
                "missing:  {} ({}); add it: gyropath fit {} --effects {}",
                best.effect,
                estimate.join(", "),
                ride.display(),
                effects.join(",")
            );
        }
        _ => {
            _ = writeln!(
                out,
                "answer    nothing missing: no catalogue effect lowers the held-out error beyond chance"
            );
        }
    }
    _ = writeln!(out, "model     {}", d.model.join(", "));
    _ = writeln!(
        out,
        "error     fit {:.3} m, held-out {:.3} m ({}-fold over {:.0} s blocks{})",
        d.fit_rms_m,
        d.heldout_rms_m,
        d.folds.k,
        d.folds.block_s,
        if d.excluded_fixes > 0 {
            format!(", {} GPS jumps left out", d.excluded_fixes)
        } else {
            String::new()
        }
    );
    _ = writeln!(
        out,
        "          ranked under {}: the noise as set, not estimated from the ride",
        d.gps_noise
    );
    _ = writeln!(
        out,
        "residual  along {:.2} m, cross {:.2} m{}",
        d.residual_rms.along_m,
        d.residual_rms.cross_m,
        d.residual_rms
            .up_m
            .map_or(String::new(), |u| format!(", vertical {u:.2} m"))
    );
    if let Some(c) = &d.reference {
        _ = writeln!(out, "reference {}: {}", c.reference, c.coverage());
        _ = writeln!(out, "          {}", c.describe());
    }
    let strong: Vec<String> = d
        .structure
        .iter()
        .take(4)
        .map(|c| format!("{} ~ {} r={:+.2}", c.quantity, c.signal, c.r))
        .collect();
    _ = writeln!(out, "structure {}", strong.join(", "));
    if let Some(w) = d.whiteness.as_ref().filter(|_| verbose) {
        let parts: Vec<String> = w
            .iter()
            .map(|c| {
                format!(
                    "{} {} (Ljung-Box Q {:.0} over {} lags, p {}{})",
                    c.component,
                    if c.white() { "white" } else { "not white" },
                    c.ljung_box_q,
                    c.lags,
                    if c.p_value < 1e-12 {
                        "< 1e-12".to_string()
                    } else {
                        format!("{:.1e}", c.p_value)
                    },
                    c.correlation_time_s
                        .map_or(String::new(), |t| format!(", correlated over ~{t:.0} s"))
                )
            })
            .collect();
        _ = writeln!(out, "whiteness {}", parts.join("; "));
    }
    _ = writeln!(out);
    _ = writeln!(
        out,
        "{:<5}{:<26}{:>11}{:>8}{:>7}  {:<5}{}  estimate",
        "rank",
        "effect",
        "held-out",
        "drop",
        "t",
        "sig.",
        if d.reference.is_some() {
            format!("{:>10}", "to ref")
        } else {
            String::new()
        }
    );
    for (i, c) in d.ranking.iter().enumerate() {
        if let Some(e) = &c.error {
            _ = writeln!(
                out,
                "{:<5}{:<26}  could not be fitted: {e}",
                i + 1,
                c.effect
            );
            continue;
        }
        let est: Vec<String> = c
            .estimate
            .iter()
            .map(|(k, e)| format!("{k} {}", e.describe()))
            .collect();
        _ = writeln!(
            out,
            "{:<5}{:<26}{:>9.3} m{:>7.1}%{:>7.1}  {:<5}{}  {}",
            i + 1,
            c.effect,
            c.heldout_rms_m,
            100.0 * c.drop,
            c.t_statistic,
            if c.significant { "yes" } else { "no" },
            c.reference
                .as_ref()
                .map_or(String::new(), |r| format!("{:>8.3} m", r.horizontal.rms_m)),
            est.join(", ")
        );
    }
    if !d.not_physical.is_empty() {
        _ = writeln!(out);
        _ = writeln!(
            out,
            "not physical: the model's own fit breaks a physical limit (below); fix the axes or units first"
        );
        return out;
    }
    if let Some(best) = d.ranking.first().filter(|c| c.significant) {
        _ = writeln!(out);
        _ = writeln!(out, "missing:  {} - {}", best.effect, best.explanation);
    } else {
        _ = writeln!(out);
        _ = writeln!(
            out,
            "nothing significant: no catalogue effect lowers the held-out error beyond chance"
        );
        if let Some(best) = d.ranking.first().filter(|c| c.drop >= 0.02) {
            _ = writeln!(
                out,
                "best:     {} ({:.1} % lower held-out error) - {}",
                best.effect,
                100.0 * best.drop,
                best.explanation
            );
        }
    }
    out
}

pub fn import(args: &ImportArgs) -> Result<()> {
    let imported = import::open(&args.source, &args.options.options()?)?;
    describe_source(&imported);
    for w in imported.warnings() {
        eprintln!("warning: {w}");
    }
    let mut log = imported.log;
    if let Some(t) = &imported.topics {
        log.metadata.insert(
            "topics".into(),
            format!("imu {}, odom {}, fix {}", t.imu, t.odom, t.fix),
        );
    }
    log.metadata.insert(
        "mount".into(),
        imported
            .mount
            .as_ref()
            .map_or_else(|| "as logged".into(), ToString::to_string),
    );
    write_atomically(&args.out, None, |w| import::ride_csv::write(&log, w))?;
    eprintln!(
        "wrote {} ({} rows, {:.0} s, {} GPS fixes)",
        args.out.display(),
        log.len(),
        log.t_s.last().copied().unwrap_or(0.0) - log.t_s.first().copied().unwrap_or(0.0),
        log.fix_count()
    );
    Ok(())
}

pub fn check(args: &CheckArgs) -> Result<()> {
    let mut options = args.options.options()?;
    // The checks read the data as logged; the mounting is what they recommend.
    options.mount = MountChoice::AsLogged;
    if let Some(json) = &args.json {
        check_report_name(json)?;
    }
    let imported = import::open(&args.source, &options)?;
    let report = &imported.check;
    use std::fmt::Write as _;
    let mut text = String::new();
    _ = writeln!(text, "{} ({})", imported.log.source, imported.kind.label());
    if let Some(t) = &imported.topics {
        _ = writeln!(
            text,
            "topics    IMU {}, odometer {}, GPS {}",
            t.imu, t.odom, t.fix
        );
    }
    for w in &imported.log.warnings {
        _ = writeln!(text, "{:<9} {w}", "note");
    }
    for v in &report.verdicts {
        _ = writeln!(text, "{:<9} {}: {}", v.level.label(), v.subject, v.message);
    }
    _ = writeln!(text);
    match &report.recommended {
        Some(m) if m.is_identity() => {
            _ = writeln!(
                text,
                "mounting  as logged: the axes are x forward, y left, z up, in deg/s"
            )
        }
        Some(m) => {
            _ = writeln!(
                text,
                "mounting  recommended: --mount \"{m}\" ({})",
                match imported.kind.default_mount() {
                    MountChoice::Auto => "bags get it by default",
                    _ => "--mount auto applies it",
                }
            )
        }
        None => {
            _ = writeln!(
                text,
                "mounting  the data cannot tell; read as logged unless --mount says otherwise"
            )
        }
    }
    if args.json.as_deref().is_some_and(is_stdout) {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    if let Some(path) = &args.json {
        write_report(path, &args.source, report)?;
    }
    if report.worst() == Level::Problem && report.recommended.is_none() {
        anyhow::bail!("the log's axes or units contradict its data, and no mounting undoes it");
    }
    // What a fit of this input with its defaults would still meet.
    let default_mount = match imported.kind.default_mount() {
        MountChoice::Auto => report.recommended.as_ref(),
        _ => None,
    };
    let remaining = report.after_mounting(default_mount);
    let worst = remaining.iter().map(|v| v.level).max().unwrap_or(Level::Ok);
    if worst == Level::Problem {
        anyhow::bail!(
            "the checks found a problem (above) that the input's default reading leaves{}",
            report
                .recommended
                .as_ref()
                .map_or(String::new(), |m| format!(": --mount \"{m}\" undoes it"))
        );
    }
    if args.strict && worst == Level::Warning {
        anyhow::bail!("the checks found a warning (above), and --strict was given");
    }
    Ok(())
}
