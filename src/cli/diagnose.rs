//! `gyropath diagnose RIDE`: the missing effects ranked, the answer first.

use super::*;

#[derive(Debug, Args)]
#[command(mut_arg("gps_noise", |a| a.help(
    "GPS noise: `auto` fits the base model and ranks every candidate under independent \
     3 m fixes (the noise the significance rule was calibrated under; `fit` estimates the \
     ride's own); `SIGMA`, `SIGMA,TAU` or `SIGMA,TAU,JITTER` (m, s, m) are used for both"
)))]
pub struct DiagnoseArgs {
    /// Ride log (CSV), ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder),
    /// comma2k19 segment, PX4 ULog or ArduPilot .bin, camera file (GoPro MP4, ...), Android GnssLogger .txt, or a CSV with --map.
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
    let signals = load_signals(&args.ride, &args.source, args.quiet)?;
    if !args.quiet {
        for w in &signals.warnings {
            eprintln!("warning: {w}");
        }
    }
    let against = matched_reference(args.reference.as_deref(), &signals, args.quiet)?;
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
        .filter(|id| {
            !gyropath::effects::PAPER.contains(id)
                && !gyropath::effects::COMES_WITH_THE_DATA.contains(id)
        })
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
        .filter(|c| c.beyond_chance())
        .take(4)
        .map(|c| format!("{} ~ {} r={:+.2}", c.quantity, c.signal, c.r))
        .collect();
    if strong.is_empty() {
        _ = writeln!(out, "structure none beyond chance (|r| < 2/sqrt(n))");
    } else {
        _ = writeln!(out, "structure {}", strong.join(", "));
    }
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
        _ = writeln!(
            out,
            "{:<5}{:<26}{:>9.3} m{:>7.1}%{:>7.1}  {:<5}{}  {}",
            i + 1,
            c.effect,
            c.heldout_rms_m,
            gyropath::diagnosis::shown(100.0 * c.drop, 1),
            gyropath::diagnosis::shown(c.t_statistic, 1),
            if c.significant { "yes" } else { "no" },
            c.reference
                .as_ref()
                .map_or(String::new(), |r| format!("{:>8.3} m", r.horizontal.rms_m)),
            describe_estimates(&c.estimate)
        );
    }
    if d.reference.is_some() {
        _ = writeln!(
            out,
            "          to ref: the model with the effect, fitted as `gyropath fit` fits it (the noise from the ride), against the reference"
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
