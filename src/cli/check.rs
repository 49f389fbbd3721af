//! `gyropath check SOURCE`: axes, units and datum checked against the data.

use super::*;

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The input: ride-log CSV, ROS 1 bag, ROS 2 bag, comma2k19 segment, PX4
    /// ULog, camera file (GoPro MP4, ...), or a CSV with --map.
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

pub fn check(args: &CheckArgs) -> Result<()> {
    let mut options = args.options.options()?;
    // The checks read the data as logged; the mounting is what they recommend.
    options.mount = MountChoice::AsLogged;
    if let Some(json) = &args.json {
        check_report_name(json)?;
    }
    let imported = gyropath::import::open(&args.source, &options)?;
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
    // Where the turn's scale matched no unit (a warning), the mounting
    // claims none.
    let units = if report
        .verdicts
        .iter()
        .any(|v| v.subject == "gyro units" && v.level == Level::Warning)
    {
        "in units the data do not tell (see gyro units)"
    } else {
        "in deg/s"
    };
    match &report.recommended {
        // Without an accelerometer the forward axis is not told (see the
        // forward axis' verdict): only what the data say is claimed.
        Some(m) if m.is_identity() && report.forward.is_none() => {
            _ = writeln!(
                text,
                "mounting  as logged: z up, {units} (which axis is forward the data cannot tell)"
            )
        }
        Some(m) if m.is_identity() => {
            _ = writeln!(
                text,
                "mounting  as logged: the axes are x forward, y left, z up, {units}"
            )
        }
        Some(m) => {
            _ = writeln!(
                text,
                "mounting  recommended: --mount \"{m}\" ({})",
                match imported.kind.default_mount() {
                    MountChoice::Auto => "bags and camera files get it by default",
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
        anyhow::bail!("the checks found a problem (above) that no mounting undoes");
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
