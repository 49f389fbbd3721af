//! A comma2k19 segment read as it comes (`../shared/formats/comma2k19-segment`,
//! comma.ai, MIT licence: a folder of NumPy arrays), fitted against comma's
//! own pose (`global_pose`, read as the reference track): with the car's CAN
//! speed it fits as the converted ride in `../shared/real/comma2k19-example1`
//! does; without it the distance is the u-blox receiver's speed.

use std::path::{Path, PathBuf};

use gyropath::diagnosis::reference::compare;
use gyropath::import::{DistanceChoice, ImportOptions, SourceKind};
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Odometer;

fn segment() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/formats/comma2k19-segment/segment")
}

fn converted() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real/comma2k19-example1/ride.csv")
}

/// The default fit of `ride` read with `options`, measured against the
/// segment's `global_pose`: (path RMS, fixes RMS, distance source).
fn fit_against_pose(ride: &Path, options: &ImportOptions) -> (f64, f64, Odometer) {
    let (path, fixes, odometer, _) = fit_with(ride, options, FitSettings::default());
    (path, fixes, odometer)
}

/// Like [`fit_against_pose`] under `settings`, with the fitted `speed_lag`.
fn fit_with(
    ride: &Path,
    options: &ImportOptions,
    settings: FitSettings,
) -> (f64, f64, Odometer, Option<f64>) {
    let imported = gyropath::pipeline::open(ride, options).expect("open");
    let signals = gyropath::pipeline::signals(imported).expect("signals");
    let (track, matched) =
        gyropath::pipeline::reference_for(&segment(), &signals).expect("global_pose");
    let mut fit = Reconstruction::new(signals.clone(), settings).expect("fit");
    fit.finish();
    let c = compare(fit.model(), fit.params(), &track, &matched);
    let lag = fit
        .model()
        .effect_params(fit.params(), "speed_lag")
        .map(|p| p[0]);
    (
        c.horizontal.rms_m,
        c.fixes.expect("fixes").rms_m,
        signals.odometer.clone(),
        lag,
    )
}

#[test]
fn the_segment_reads_with_its_channels_rates_and_clock() {
    let im = gyropath::pipeline::open(&segment(), &ImportOptions::default()).expect("open");
    assert_eq!(im.kind, SourceKind::Comma2k19);
    let log = &im.log;
    // The gyro's 6256 samples within the CAN speed's time: all but the first.
    assert_eq!(log.len(), 6255);
    let rate = (log.len() - 1) as f64 / (log.t_s[log.len() - 1] - log.t_s[0]);
    assert!((rate - 104.4).abs() < 0.2, "{rate} Hz");
    assert_eq!(log.fix_count(), 61);
    let speeds = log.gps_speed_mps.as_ref().expect("GNSS speed");
    assert_eq!(speeds.iter().flatten().count(), 579);
    assert!(speeds.iter().flatten().all(|v| (7.0..21.0).contains(v)));
    assert!(log.gps_course_deg.is_some() && log.odo_m.is_some());
    assert_eq!(log.metadata["t0_boot_s"], "46408.589617");
    // 2 Aug 2018, 16:14:48 UTC (the dataset's README).
    let t0: f64 = log.metadata["t0_unix_s"].parse().expect("t0_unix_s");
    assert!((t0 - 1_533_226_488.0).abs() < 2.0, "{t0}");
    // Forward, right, down made forward, left, up: the car turns left at
    // about 4 deg/s of uncalibrated z bias (the converted ride's first row).
    assert!(
        (log.gyro_dps[0][2] + 4.130).abs() < 1e-3,
        "{:?}",
        log.gyro_dps[0]
    );
    // The checks: the odometer agrees with the GPS track, the rate is fine.
    let odometer = im
        .check
        .verdicts
        .iter()
        .find(|v| v.subject == "odometer")
        .expect("odometer verdict");
    assert_eq!(odometer.level, gyropath::import::Level::Ok, "{odometer:?}");
    // The median of 53 stretches' ratios (the ratio of their sums read
    // 0.992); the fit's own gain, 1.009, says 0.991.
    assert!(
        odometer.message.contains("0.989 m per metre"),
        "{odometer:?}"
    );
}

#[test]
fn read_directly_it_fits_as_the_converted_ride_does() {
    let options = ImportOptions::default();
    let (direct, fixes, odometer) = fit_against_pose(&segment(), &options);
    let (converted, _, _) = fit_against_pose(&converted(), &options);
    assert_eq!(odometer, Odometer::Cumulative);
    println!(
        "comma segment read directly: {direct:.4} m, converted ride {converted:.4} m, fixes {fixes:.4} m"
    );
    assert!(
        (direct - converted).abs() < 0.05,
        "{direct} against {converted}"
    );
    assert!(direct < fixes);
}

/// The converted ride's own `truth.csv` and the segment's `global_pose` are
/// the same reference: the same error, whichever is given.
#[test]
fn global_pose_is_the_reference_truth_csv_was_made_from() {
    let signals = gyropath::pipeline::signals(
        gyropath::pipeline::open(&converted(), &ImportOptions::default()).expect("open"),
    )
    .expect("signals");
    let mut fit = Reconstruction::new(signals.clone(), FitSettings::default()).expect("fit");
    fit.finish();
    let truth = converted().with_file_name("truth.csv");
    let rms = |reference: &Path| {
        let (track, matched) = gyropath::pipeline::reference_for(reference, &signals).expect("ref");
        compare(fit.model(), fit.params(), &track, &matched)
            .horizontal
            .rms_m
    };
    let (a, b) = (rms(&truth), rms(&segment().join("global_pose")));
    assert!((a - b).abs() < 0.01, "truth.csv {a} m, global_pose {b} m");
    // A reference on the boot clock needs a ride that says its boot time.
    let sim = gyropath::pipeline::signals(
        gyropath::pipeline::open(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("data/sample-ride.csv"),
            &ImportOptions::default(),
        )
        .expect("open"),
    )
    .expect("signals");
    let Err(e) = gyropath::pipeline::reference_for(&segment(), &sim) else {
        panic!("a boot-clock reference matched a ride without t0_boot_s");
    };
    let e = e.to_string();
    assert!(e.contains("no t0_boot_s"), "{e}");
}

/// The ride's clock does not depend on which distance is read: with the
/// u-blox speed the rows start 77 ms later (its first sample), but `t_s`
/// still counts from the CAN speed's first gyro sample, so the converted
/// ride's `truth.csv` (on that clock) and `global_pose` (on the boot clock)
/// measure the same path alike. Counted from the first row, `truth.csv`
/// read 0.63 m where the path is 1.64 m from comma's pose.
#[test]
fn the_clock_is_the_same_whichever_distance_is_read() {
    let open = |distance| {
        gyropath::pipeline::open(
            &segment(),
            &ImportOptions {
                distance,
                ..ImportOptions::default()
            },
        )
        .expect("open")
        .log
    };
    let (can, gnss) = (open(DistanceChoice::Auto), open(DistanceChoice::Gnss));
    assert_eq!(can.metadata["t0_boot_s"], gnss.metadata["t0_boot_s"]);
    // The UTC tie comes from the first fix's arrival, which jitters by
    // tens of milliseconds from sample to sample.
    let unix = |log: &gyropath::ride::RideLog| -> f64 {
        log.metadata["t0_unix_s"].parse().expect("t0_unix_s")
    };
    assert!((unix(&can) - unix(&gnss)).abs() < 0.02);
    assert_eq!(can.t_s[0], 0.0);
    assert!((0.05..0.1).contains(&gnss.t_s[0]), "{}", gnss.t_s[0]);
    let signals = gyropath::pipeline::signals(
        gyropath::pipeline::open(
            &segment(),
            &ImportOptions {
                distance: DistanceChoice::Gnss,
                ..ImportOptions::default()
            },
        )
        .expect("open"),
    )
    .expect("signals");
    let mut fit = Reconstruction::new(signals.clone(), FitSettings::default()).expect("fit");
    fit.finish();
    let rms = |reference: &Path| {
        let (track, matched) = gyropath::pipeline::reference_for(reference, &signals).expect("ref");
        compare(fit.model(), fit.params(), &track, &matched)
            .horizontal
            .rms_m
    };
    let truth = converted().with_file_name("truth.csv");
    let (a, b) = (rms(&truth), rms(&segment().join("global_pose")));
    assert!((a - b).abs() < 0.01, "truth.csv {a} m, global_pose {b} m");
}

/// Without the CAN speed: the distance from the u-blox speed. The receiver's
/// fixes and speed arrive about 0.1 s late (the lag the CAN fit's `gps_lag`
/// measures, 0.096 s); on this straight minute nothing but the reference can
/// see a lag both share, so the path is late with them (measured: 1.64 m
/// against 1.25 m with the CAN speed; the fixes 1.50 m).
#[test]
fn without_the_can_speed_the_gnss_speed_gives_the_distance() {
    let options = ImportOptions {
        distance: DistanceChoice::Gnss,
        ..ImportOptions::default()
    };
    let (gnss, fixes, odometer) = fit_against_pose(&segment(), &options);
    let (can, _, _) = fit_against_pose(&segment(), &ImportOptions::default());
    let Odometer::GnssSpeed {
        samples,
        standing_s,
        gaps,
        ..
    } = odometer
    else {
        panic!("{odometer:?}");
    };
    println!(
        "comma segment: CAN speed {can:.3} m, GNSS speed {gnss:.3} m ({samples} samples), fixes {fixes:.3} m"
    );
    assert!(samples > 550 && standing_s == 0.0 && gaps.is_empty());
    assert!(gnss <= 1.5 * can, "{gnss} against {can} with the CAN speed");

    // speed_lag: the speed's lag behind the gyro, fitted, moves the path
    // along the track (measured: 1.51 m, lag 0.043 s; the fixes 1.50 m).
    let mut settings = FitSettings::default();
    settings.model.effects = vec!["paper".into(), "speed_lag".into()];
    let (lagged, _, _, lag) = fit_with(&segment(), &options, settings);
    let lag = lag.expect("speed_lag's parameter");
    println!("with speed_lag: {lagged:.3} m, lag {lag:.4} s");
    assert!((0.02..0.08).contains(&lag), "{lag} s");
    assert!(
        lagged < gnss - 0.1,
        "{lagged} m against {gnss} m without it"
    );
}

#[test]
fn a_broken_segment_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("gyropath-segment-{}", std::process::id()));
    let copy = |from: &Path, to: &Path| {
        for entry in walk(from) {
            let rel = entry.strip_prefix(from).expect("prefix");
            let target = to.join(rel);
            std::fs::create_dir_all(target.parent().expect("parent")).expect("mkdir");
            std::fs::copy(&entry, &target).expect("copy");
            let mut p = std::fs::metadata(&target).expect("meta").permissions();
            #[allow(clippy::permissions_set_readonly_false)]
            p.set_readonly(false);
            std::fs::set_permissions(&target, p).expect("writable");
        }
    };
    copy(&segment(), &dir);
    let speed = dir.join("processed_log/CAN/speed/value");
    let bytes = std::fs::read(&speed).expect("read");
    let open = || gyropath::pipeline::open(&dir, &ImportOptions::default());
    // Every cut of the CAN speed's values is an error naming the file.
    for cut in [0, 5, 60, 200, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&speed, &bytes[..cut]).expect("write");
        let e = open().expect_err("truncated").to_string();
        assert!(e.contains("CAN/speed/value"), "{e}");
    }
    std::fs::write(&speed, &bytes).expect("write");
    // Times that go back.
    let t = dir.join("processed_log/IMU/gyro_uncalibrated/t");
    let good = std::fs::read(&t).expect("read");
    let mut bad = good.clone();
    let at = bad.len() - 8 * 100;
    bad[at..at + 8].copy_from_slice(&0.0f64.to_le_bytes());
    std::fs::write(&t, &bad).expect("write");
    let e = open().expect_err("time back").to_string();
    assert!(
        e.contains("gyro_uncalibrated/t") && e.contains("does not increase"),
        "{e}"
    );
    std::fs::write(&t, &good).expect("write");
    // No u-blox.
    std::fs::remove_dir_all(dir.join("processed_log/GNSS")).expect("rm");
    let e = open().expect_err("no GNSS").to_string();
    assert!(
        e.contains("needs processed_log/GNSS/live_gnss_ublox"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).expect("clean");
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).expect("list").flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// A folder holding segments is a batch of them (each segment one ride), as
/// a folder of ride logs is; the segment itself is one ride.
#[test]
fn a_folder_of_segments_is_a_batch_and_a_segment_one_ride() {
    let out = std::env::temp_dir().join(format!("gyropath-segments-{}", std::process::id()));
    let folder = segment().parent().expect("folder").to_path_buf();
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .arg("fit")
        .arg(&folder)
        .arg("--out-dir")
        .arg(&out)
        .arg("--quiet")
        .output()
        .expect("run");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let written: Vec<String> = std::fs::read_dir(&out)
        .expect("outputs")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect();
    assert!(
        written
            .iter()
            .any(|n| n.starts_with("segment") && n.ends_with(".csv")),
        "{written:?}"
    );
    std::fs::remove_dir_all(&out).expect("clean");
}
