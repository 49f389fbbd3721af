//! `gyropath fit RIDE`: one ride fitted, its summary, path and report.

use super::batch::fit_batch;
use super::*;

#[derive(Debug, Args)]
pub struct FitArgs {
    /// Ride log(s) (CSV, see the ride-log format), bags, comma2k19 segments,
    /// PX4 ULogs, ArduPilot .bin logs, camera files (GoPro MP4, ...), GnssLogger .txt logs, or folders of them: more
    /// than one, a folder, or --out-dir fits them all in parallel (batch mode).
    #[arg(required = true, num_args = 1..)]
    pub rides: Vec<PathBuf>,
    #[command(flatten)]
    pub source: SourceArgs,
    #[command(flatten)]
    pub settings: SettingsArgs,
    /// Start from a model saved by `gyropath explain --save-model`: its
    /// effects and segment length (the GPS noise is estimated anew for each
    /// ride); --effects adds to it. Example: `--model sensor.json`.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Batch mode: write RIDE-path.csv, RIDE-report.json and RIDE-report.html
    /// for every ride here, and index.html linking the reports.
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
    /// Write a report to share here: one HTML file that opens offline in any
    /// browser (the ride, its checks, the map, residuals, bias, parameters
    /// with their 1-sigma, the reference when given, the settings).
    #[arg(long)]
    pub html: Option<PathBuf>,
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

fn phase_name(p: Phase) -> &'static str {
    match p {
        Phase::Step1 => "step 1",
        Phase::Step2 => "step 2",
        Phase::Noise => "noise",
        Phase::Done => "done",
    }
}

pub(super) fn progress_line(r: &IterationReport) -> String {
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

impl FitArgs {
    /// The settings, starting from `--model`'s effects when one is given.
    pub(super) fn settings_with_model(&self) -> Result<FitSettings> {
        let mut settings = self.settings.settings()?;
        if let Some(path) = &self.model {
            let saved = super::explain::load_model(path)?;
            let mut effects = saved.effects;
            for e in settings.model.effects.drain(..) {
                if !effects.contains(&e) {
                    effects.push(e);
                }
            }
            settings.model.effects = effects;
            settings.model.segment_s = saved.segment_s;
        }
        Ok(settings)
    }
}

pub fn fit(args: &FitArgs) -> Result<()> {
    let folder_of_rides =
        args.rides[0].is_dir() && !gyropath::import::is_ride_folder(&args.rides[0]);
    let batch = args.rides.len() > 1 || args.out_dir.is_some() || folder_of_rides;
    if batch {
        return fit_batch(args);
    }
    let ride = &args.rides[0];
    let started = Instant::now();
    let settings = args.settings_with_model()?;
    // The outputs' names are checked before the fit, not after minutes of it.
    let path_format = args.out.as_deref().map(PathFormat::of).transpose()?;
    if let Some(rep) = &args.json {
        check_report_name(rep)?;
    }
    if let Some(html) = &args.html {
        check_html_name(html)?;
    }
    let data_is_stdout = data_on_stdout(&[
        ("--out", &args.out),
        ("--json", &args.json),
        ("--html", &args.html),
    ])?;
    let (signals, origin) = load_ride(ride, &args.source, args.quiet)?;
    if !args.quiet {
        for w in &signals.warnings {
            eprintln!("warning: {w}");
        }
    }
    let against = matched_reference(args.reference.as_deref(), &signals, args.quiet)?;
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
    physical(&fit, &origin)?;
    let (mut report, uncertainty) = pipeline::report(
        &fit,
        started.elapsed().as_secs_f64(),
        args.out.is_some() || args.json.is_some(),
        against.as_ref(),
    );
    if args.json.is_some() || verbose {
        report = report.with_segment_preference(&fit);
    }
    if let (Some(out), Some(format)) = (&args.out, path_format) {
        write_path(out, format, ride, &fit, uncertainty.as_ref())?;
    }
    if let Some(rep) = &args.json {
        write_report(rep, ride, &report)?;
    }
    if let Some(html) = &args.html {
        write_fit_html(
            html,
            ride,
            &fit,
            &origin,
            against.as_ref(),
            uncertainty.as_ref(),
            &report,
        )?;
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

/// Differences of `-2 ln L` below this are no evidence for one segment
/// length over another (a likelihood ratio of about 7).
const SEGMENT_EVIDENCE: f64 = 4.0;

/// The terminal summary of a fit.
pub(super) fn summary_text(r: &FitReport, verbose: bool) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    _ = writeln!(
        out,
        "ride      {} ({} rows{}, {:.0} s, {} GPS fixes)",
        r.source,
        r.rows,
        gyropath::log_gaps::filled_phrase(r.rows_filled),
        r.duration_s,
        r.gps_fixes
    );
    _ = writeln!(out, "model     {}", r.model.join(", "));
    _ = writeln!(out, "attitude  {}", r.attitude);
    _ = writeln!(out, "distance  from {}", r.distance_source);
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
        if effect == "gyro_stops" {
            let stops = values
                .iter()
                .filter(|p| p.name.starts_with("turn_x"))
                .count();
            _ = writeln!(
                out,
                "{effect}: {stops} stop(s) of the gyro bridged by {} free turns (see --json)",
                values.len()
            );
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
