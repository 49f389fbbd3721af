//! `gyropath fit` on several rides or a folder: every ride on all cores, outputs
//! that never collide, and a summary table.

use gyropath::report::IndexEntry;

use super::*;

/// One line of the batch summary.
struct BatchRow {
    ride: String,
    outcome: Result<FitReport, String>,
}

/// How deep [`collect_rides`] looks into a folder's subfolders.
const MAX_FOLDER_DEPTH: usize = 8;

/// Every ride log, bag, ULog, DataFlash, camera and GnssLogger log in the
/// given files and folders, sorted; folders are searched through their
/// subfolders (a folder per drive, as `../shared/real` holds them), a rosbag2
/// folder or comma2k19 segment being one ride. Hidden and symlinked folders
/// are not entered, nor the batch's output folder (`rides/out` of an earlier
/// `--out-dir rides/out`: its paths are no rides), and a file that is the
/// batch's reference track (`truth.csv` beside a ride for `--reference
/// truth.csv`) is not a ride, nor is a GoPro recording's later chapter
/// beside its first (which reads them all as one ride).
fn collect_rides(
    inputs: &[PathBuf],
    reference: Option<&Path>,
    out_dir: Option<&Path>,
) -> Result<Vec<PathBuf>> {
    let mut rides = Vec::new();
    let skip = Skip {
        reference,
        out_dir: out_dir.and_then(|d| d.canonicalize().ok()),
    };
    for input in inputs {
        if input.is_dir() && !gyropath::import::is_ride_folder(input) {
            rides_in(input, &skip, 0, &mut rides)?;
        } else {
            rides.push(input.clone());
        }
    }
    if rides.is_empty() {
        anyhow::bail!(
            "no rides (*.csv, *.bag, *.mcap, *.ulg, *.bin, *.mp4, *.mov, GnssLogger *.txt, rosbag2 folders, comma2k19 segments) found in the given folders or their subfolders"
        );
    }
    Ok(rides)
}

/// What [`collect_rides`] leaves out of a folder.
struct Skip<'a> {
    reference: Option<&'a Path>,
    /// The batch's output folder, canonical (`None`: none, or not made yet).
    out_dir: Option<PathBuf>,
}

/// The rides in `dir` and its subfolders, in sorted order (see [`collect_rides`]).
fn rides_in(dir: &Path, skip: &Skip, depth: usize, rides: &mut Vec<PathBuf>) -> Result<()> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    entries.sort();
    for path in entries {
        let hidden = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if hidden {
            continue;
        }
        if gyropath::import::is_ride_folder(&path) {
            rides.push(path);
        } else if path.is_dir() {
            let linked = path.symlink_metadata().is_ok_and(|m| m.is_symlink());
            let output = skip.out_dir.is_some() && path.canonicalize().ok() == skip.out_dir;
            if !linked && !output && depth < MAX_FOLDER_DEPTH {
                rides_in(&path, skip, depth + 1, rides)?;
            }
        } else if gyropath::import::is_ride_file(&path)
            && !is_reference(&path, skip.reference)
            && gyropath::import::chapters::first_of(&path).is_none()
        {
            rides.push(path);
        }
    }
    Ok(())
}

/// Whether `file` is the reference track [`reference_for`] gives a ride beside it.
fn is_reference(file: &Path, reference: Option<&Path>) -> bool {
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    reference_for(file, reference).is_some_and(|r| same(&r, file))
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
/// `STEM-path.csv`, `STEM-report.json` and `STEM-report.html` (nothing
/// without an `out_dir`).
fn fit_one(
    ride: &Path,
    source: &SourceArgs,
    settings: &FitSettings,
    out_dir: Option<&Path>,
    stem: &str,
    reference: Option<&Path>,
) -> Result<FitReport> {
    let started = Instant::now();
    let (signals, origin) = load_ride(ride, source, true)?;
    let against = matched_reference(reference_for(ride, reference).as_deref(), &signals, true)?;
    let mut fit = Reconstruction::new(signals, settings.clone())?;
    fit.finish();
    physical(&fit, &origin)?;
    let (report, uncertainty) = pipeline::report(
        &fit,
        started.elapsed().as_secs_f64(),
        true,
        against.as_ref(),
    );
    let Some(dir) = out_dir else {
        return Ok(report);
    };
    // The JSON report holds the segment lengths' likelihoods.
    let report = report.with_segment_preference(&fit);
    write_path(
        &dir.join(format!("{stem}-path.csv")),
        PathFormat::Csv,
        ride,
        &fit,
        uncertainty.as_ref(),
    )?;
    write_report(&dir.join(format!("{stem}-report.json")), ride, &report)?;
    write_fit_html(
        &dir.join(format!("{stem}-report.html")),
        ride,
        &fit,
        &origin,
        against.as_ref(),
        uncertainty.as_ref(),
        &report,
    )?;
    Ok(report)
}

/// Batch mode: every ride on all cores (one ride per task; each fit is
/// sequential apart from the linear algebra), then a summary table. Rides that
/// fail are reported in the table and make the exit status 1, but never stop the others.
pub(super) fn fit_batch(args: &FitArgs) -> Result<()> {
    use rayon::prelude::*;
    if args.out.is_some() || args.json.is_some() || args.html.is_some() {
        anyhow::bail!("with several rides use --out-dir instead of --out/--json/--html");
    }
    // Without --out-dir a batch writes no files: a folder of rides must not
    // scatter outputs into the working directory.
    let out_dir = args.out_dir.as_deref();
    if let Some(dir) = out_dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    }
    let settings = args.settings_with_model()?;
    let rides = collect_rides(&args.rides, args.reference.as_deref(), out_dir)?;
    if let (Some(track), true) = (&args.source.gps_track, rides.len() > 1) {
        anyhow::bail!(
            "--gps-track {} gives one ride its fixes, and this batch has {} rides: fit each ride with its own track",
            track.display(),
            rides.len()
        );
    }
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
    // The ride column is as wide as the longest name, so the columns line up.
    let w = rows
        .iter()
        .map(|r| r.ride.chars().count())
        .max()
        .unwrap_or(0)
        .max(4);
    println!(
        "{:<w$} {:>8} {:>6} {:>9} {:>9} {:>10} {:>8} {:>9}",
        "ride", "min", "fixes", "fit RMS", "vert RMS", "yaw bias", "gain", "ref RMS"
    );
    let mut failed = 0;
    for row in &rows {
        match &row.outcome {
            Ok(r) => {
                let value = |e: &str, n: &str| r.value(e, n).unwrap_or(f64::NAN);
                let vertical = r.stats.rms_baro_up_m.or(r.stats.rms_gps_up_m);
                println!(
                    "{:<w$} {:>8.1} {:>6} {:>7.3} m {:>9} {:>10} {:>8.4} {:>9}",
                    row.ride,
                    r.duration_s / 60.0,
                    r.gps_fixes,
                    r.stats.rms_horizontal_m,
                    vertical.map_or("-".into(), |v| format!("{v:.3} m")),
                    r.bias_total[2].map_or("-".into(), |t| format!("{:.3}°/s", t.mean_dps)),
                    value("odometer_gain", "gain"),
                    r.reference
                        .as_ref()
                        .map_or("-".into(), |c| format!("{:.3} m", c.horizontal.rms_m)),
                );
            }
            Err(e) => {
                failed += 1;
                println!("{:<w$} failed: {e}", row.ride);
            }
        }
    }
    if let Some(dir) = out_dir {
        write_index(dir, &rows, &stems)?;
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

/// The batch's `index.html`: every ride with its outcome, linking its report.
fn write_index(dir: &Path, rows: &[BatchRow], stems: &[String]) -> Result<()> {
    let entries: Vec<IndexEntry> = rows
        .iter()
        .zip(stems)
        .map(|(row, stem)| match &row.outcome {
            Ok(r) => IndexEntry {
                source: row.ride.clone(),
                href: Some(format!("{stem}-report.html")),
                outcome: format!(
                    "{:.3} m to the fixes (under {})",
                    r.stats.rms_horizontal_m, r.gps_noise
                ),
                reference: r.reference.as_ref().map_or("-".into(), |c| {
                    format!("{:.3} m RMS ({})", c.horizontal.rms_m, c.coverage())
                }),
            },
            Err(e) => IndexEntry {
                source: row.ride.clone(),
                href: None,
                outcome: format!("failed: {e}"),
                reference: "-".into(),
            },
        })
        .collect();
    let page = gyropath::report::index_html(&entries)?;
    let path = dir.join("index.html");
    write_atomically(&path, None, |w| w.write_all(page.as_bytes()))
        .with_context(|| format!("{}: the index could not be written", path.display()))
}
