//! `gyropath import SOURCE`: any input written as a ride-log CSV.

use super::*;

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The input: ROS 1 bag, ROS 2 bag (MCAP file or rosbag2 folder), comma2k19
    /// segment, PX4 ULog or ArduPilot .bin, camera file (GoPro MP4, ...), Android GnssLogger .txt, ride-log CSV, or a CSV with --map.
    pub source: PathBuf,
    #[command(flatten)]
    pub options: SourceArgs,
    /// Where to write the ride-log CSV.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn import(args: &ImportArgs) -> Result<()> {
    let imported = gyropath::import::open(&args.source, &args.options.options()?)?;
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
    write_atomically(&args.out, None, |w| {
        gyropath::import::ride_csv::write(&log, w)
    })?;
    eprintln!(
        "wrote {} ({} rows, {:.0} s, {} GPS fixes)",
        args.out.display(),
        log.len(),
        log.t_s.last().copied().unwrap_or(0.0) - log.t_s.first().copied().unwrap_or(0.0),
        log.fix_count()
    );
    Ok(())
}
