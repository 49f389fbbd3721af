//! `gyropath explain RIDE`: the whole find-the-missing-effect loop in one
//! step (fit, diagnose, add the top significant effect, refit, until nothing
//! significant is left), each step told as it finishes.

use gyropath::explain::{Ending, Explanation, Progress, SavedModel, Step, explain as run_loop};

use super::*;

#[derive(Debug, Args)]
pub struct ExplainArgs {
    /// Ride log (CSV), ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder),
    /// comma2k19 segment, PX4 ULog or ArduPilot .bin, camera file (GoPro MP4, ...), Android GnssLogger .txt, or a CSV with --map.
    pub ride: PathBuf,
    #[command(flatten)]
    pub source: SourceArgs,
    #[command(flatten)]
    pub settings: SettingsArgs,
    /// A better track of the same drive (`t_s,lat_deg,lon_deg[,alt_m]` CSV on
    /// the ride's clock): every step is measured against it.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Write the final model's path here (.csv, .gpx or .tum, as `fit --out`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write every step, why the loop ended and the last ranking here (JSON).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a report to share here (HTML, opens offline in any browser):
    /// the ride, every step of the loop, the final model's map, residuals
    /// and bias, and the last ranking.
    #[arg(long)]
    pub html: Option<PathBuf>,
    /// Save the final model (its effects and settings) here (JSON), for
    /// `gyropath fit OTHER_RIDE --model FILE` and the next rides of the same sensor.
    #[arg(long)]
    pub save_model: Option<PathBuf>,
    /// Print nothing but errors and the steps.
    #[arg(long, short)]
    pub quiet: bool,
}

/// One line per step: what was added, its estimate, the held-out error it
/// reached (under the ranking's noise), the fit's own error and the time.
fn step_line(s: &Step) -> String {
    let reference = s.reference.as_ref().map_or(String::new(), |c| {
        format!("; to the reference {:.2} m", c.horizontal.rms_m)
    });
    let held_out = s
        .heldout_rms_m
        .map_or("not validated".into(), |h| format!("held-out {h:.3} m"));
    match &s.added {
        None => format!(
            "base      {}: {held_out}; path to the fixes {:.3} m{reference} ({:.1} s)",
            s.model.join(", "),
            s.fit_rms_m,
            s.elapsed_s
        ),
        Some(effect) => {
            format!(
                "added     {effect} ({}): {held_out}, {:.1} % lower (t {:.1}); path to the fixes {:.3} m{reference} ({:.1} s)",
                describe_estimates(&s.estimate),
                100.0 * s.drop,
                s.t_statistic,
                s.fit_rms_m,
                s.elapsed_s
            )
        }
    }
}

pub fn explain(args: &ExplainArgs) -> Result<()> {
    let settings = args.settings.settings()?;
    let path_format = args.out.as_deref().map(PathFormat::of).transpose()?;
    for json in [&args.json, &args.save_model].into_iter().flatten() {
        check_report_name(json)?;
    }
    if let Some(html) = &args.html {
        check_html_name(html)?;
    }
    let data_is_stdout = data_on_stdout(&[
        ("--out", &args.out),
        ("--json", &args.json),
        ("--html", &args.html),
        ("--save-model", &args.save_model),
    ])?;
    // Data on standard output: the steps go to standard error.
    let say = |line: String| {
        if data_is_stdout {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    let (signals, origin) = load_ride(&args.ride, &args.source, args.quiet)?;
    if !args.quiet {
        for w in &signals.warnings {
            eprintln!("warning: {w}");
        }
    }
    let against = matched_reference(args.reference.as_deref(), &signals, args.quiet)?;
    let terminal = std::io::stderr().is_terminal() && !args.quiet;
    let bar = terminal.then(|| {
        let bar = indicatif::ProgressBar::new_spinner();
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar
    });
    let observer = |p: Progress| match p {
        Progress::Working(line) => {
            if let Some(b) = &bar {
                b.set_message(line.to_string());
            }
        }
        Progress::Step(s) => match &bar {
            Some(b) => b.println(step_line(s)),
            None => say(step_line(s)),
        },
    };
    let (explanation, fit) = run_loop(
        signals,
        &settings,
        &Folds::default(),
        against.as_ref(),
        &observer,
    )?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    say(ending_line(&explanation, &fit));
    if let Some(d) = &explanation.last_diagnosis {
        say(format!(
            "          held-out errors under {} (the ranking's noise); paths under the noise each fit estimates",
            d.gps_noise
        ));
    }
    let uncertainty = args
        .out
        .is_some()
        .then(|| fit.model().uncertainty(fit.params()))
        .flatten();
    if let (Some(out), Some(format)) = (&args.out, path_format) {
        write_path(out, format, &args.ride, &fit, uncertainty.as_ref())?;
    }
    if let Some(html) = &args.html {
        let contents = gyropath::report::Contents {
            history: gyropath::report::ModelRow::of_explanation(&explanation),
            explanation: Some(&explanation),
            diagnosis: explanation.last_diagnosis.as_ref(),
            ..gyropath::report::Contents::of_fit(
                &fit,
                Some(&origin),
                against.as_ref(),
                uncertainty.as_ref(),
                None,
                command_line(),
            )
        };
        write_html(html, &args.ride, &contents)?;
    }
    if let Some(json) = &args.json {
        write_report(json, &args.ride, &explanation)?;
    }
    if let Some(path) = &args.save_model {
        let saved = SavedModel::of(&fit);
        write_report(path, &args.ride, &saved)?;
    }
    Ok(())
}

/// The answer: what the model now is and why the loop stopped.
fn ending_line(e: &Explanation, fit: &Reconstruction) -> String {
    let added: Vec<&str> = e.steps.iter().filter_map(|s| s.added.as_deref()).collect();
    let model = if added.is_empty() {
        "the paper's model".to_string()
    } else {
        format!("the paper's model + {}", added.join(" + "))
    };
    match &e.ending {
        Ending::NothingSignificant => format!(
            "answer    {model}: nothing more lowers the held-out error beyond chance (path {:.3} m from the fixes)",
            fit.stats().rms_horizontal_m
        ),
        Ending::NoResult(reason) => {
            format!("answer    {model}; the next fit was no result:\n{reason}")
        }
        Ending::StepLimit => format!("answer    {model}: stopped after {} effects", added.len()),
        Ending::CannotValidate(reason) => format!(
            "answer    {model}, not validated (path {:.3} m from the fixes):\n{reason}",
            fit.stats().rms_horizontal_m
        ),
    }
}

/// Read a model saved by `explain --save-model`.
pub fn load_model(path: &Path) -> Result<ModelSpec> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the model", path.display()))?;
    let saved: SavedModel = serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: not a model saved by `gyropath explain --save-model`",
            path.display()
        )
    })?;
    Ok(saved.model)
}
