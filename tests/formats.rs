//! The small real files of `../shared/formats` (each with its licence and a
//! README there) that have no gyro: a Garmin FIT activity, a car's NMEA
//! 0183 log and a runner's GPX track. Opened as a ride, each says what it is,
//! that a path needs a gyro, and how it can serve (the GPX and NMEA files as
//! reference tracks).

use std::path::{Path, PathBuf};

use gyropath::import::ImportOptions;

mod common;

fn formats() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/formats")
}

fn open_err(path: &Path) -> String {
    match gyropath::pipeline::open(path, &ImportOptions::default()) {
        Ok(_) => panic!("{} opened as a ride", path.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn gnss_only_files_say_what_they_are_and_that_a_path_needs_a_gyro() {
    let gpx = formats().join("gpx/garmin-activity.gpx");
    let e = open_err(&gpx);
    assert!(e.contains("a GPX track of"), "{e}");
    assert!(
        e.contains("no gyro") && e.contains("A path needs a gyro"),
        "{e}"
    );
    assert!(
        e.contains("--reference") && e.contains("--gps-track"),
        "{e}"
    );

    let nmea = formats().join("nmea/MTV.Local1.ublox-F9K.20200206-181434.nmea");
    let e = open_err(&nmea);
    assert!(e.starts_with(&nmea.display().to_string()), "{e}");
    assert!(e.contains("NMEA 0183 of") && e.contains("no gyro"), "{e}");

    for (fit, what) in [
        (
            "Edge810-Vector-2013-08-16-15-35-10.fit",
            "(edge810) of 4700 points over 4699 s, 41.3 km, with a wheel-speed sensor paired",
        ),
        (
            "elemnt-bolt-no-application-id-inside-developer-data-id.fit",
            "(ELEMNT BOLT) of 131 points over 130 s, 1.0 km, with a wheel-speed sensor paired",
        ),
    ] {
        let e = open_err(&formats().join("fit").join(fit));
        assert!(
            e.contains(&format!("a Garmin FIT activity {what}"))
                && e.contains("A path needs a gyro"),
            "{e}"
        );
        assert!(e.contains("--reference"), "{e}");
    }
}

/// A FIT activity is a reference track in UTC, as a GPX track is: the
/// Edge 810's first point in St. John's, Newfoundland, on 16 August 2013,
/// 18:05:10 UTC.
#[test]
fn a_fit_activity_reads_as_a_reference_track() {
    let fit = formats().join("fit/Edge810-Vector-2013-08-16-15-35-10.fit");
    let track = gyropath::import::read_reference(&fit).expect("reference");
    assert_eq!(track.clock, gyropath::import::reference::Clock::Unix);
    assert_eq!(track.t_s.len(), 4700);
    assert_eq!(track.t_s[0], 1_376_676_310.0);
    assert!(track.has_alt);
    let p = track.points[0];
    assert!(
        (p.lat_deg - 47.626).abs() < 0.01 && (p.lon_deg + 52.81).abs() < 0.01,
        "{p:?}"
    );
    assert!((p.alt_m - 132.2).abs() < 0.01);
    // Cut short or damaged: an error naming the file, never a panic.
    let bytes = std::fs::read(&fit).expect("read");
    for n in [0, 11, 14, 1000, bytes.len() / 2] {
        if let Err(e) = gyropath::import::fit::parse(&bytes[..n], "cut.fit") {
            assert!(e.to_string().starts_with("cut.fit: "), "{e}");
        }
    }
    let mut flipped = bytes.clone();
    for at in (20..flipped.len()).step_by(997) {
        flipped[at] ^= 0x5a;
    }
    if let Err(e) = gyropath::import::fit::parse(&flipped, "flipped.fit") {
        assert!(e.to_string().starts_with("flipped.fit: "), "{e}");
    }
}

/// The command line says the same, and exits with an error.
#[test]
fn fit_refuses_a_gpx_track_with_the_reason() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .arg("fit")
        .arg(formats().join("gpx/garmin-activity.gpx"))
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("a GPX track of") && err.contains("A path needs a gyro"),
        "{err}"
    );
}

/// A PX4 ULog of a VTOL standing on the ground (pyulog's
/// `sample_log_small.ulg`, BSD-3-Clause): its gyro, accelerometer and GNSS
/// read with their rates, the checks find gravity on +z (PX4's down axis
/// made up), and a fit says the vehicle never moved instead of drawing a path.
#[test]
fn a_px4_ulog_reads_with_its_channels_and_a_standing_vehicle_is_said() {
    let ulog = formats().join("ulog/sample_log_small.ulg");
    let im = gyropath::pipeline::open(&ulog, &ImportOptions::default()).expect("open");
    assert_eq!(im.kind, gyropath::import::SourceKind::Ulog);
    let log = &im.log;
    // sensor_combined: 1298 samples at about 200 Hz over 6.5 s.
    assert_eq!(log.len(), 1298);
    let rate = (log.len() - 1) as f64 / log.t_s[log.len() - 1];
    assert!((195.0..210.0).contains(&rate), "{rate} Hz");
    // vehicle_gps_position: 32 samples at 5 Hz with speed and course; one
    // fix per second, in Trondheim.
    let speeds = log.gps_speed_mps.as_ref().expect("GNSS speed");
    assert_eq!(speeds.iter().flatten().count(), 32);
    assert!(speeds.iter().flatten().all(|v| *v < 0.5), "standing");
    assert!((6..=8).contains(&log.fix_count()), "{}", log.fix_count());
    let (lat, lon) = log.fix.iter().flatten().next().copied().expect("fix");
    assert!((lat - 63.417).abs() < 0.01 && (lon - 10.408).abs() < 0.01);
    assert!(
        log.gps_hacc_m
            .as_ref()
            .expect("eph")
            .iter()
            .flatten()
            .all(|h| *h > 0.0)
    );
    // 21 April 2021 (time_utc_usec of the first fix).
    let t0: f64 = log.metadata["t0_unix_s"].parse().expect("t0_unix_s");
    assert!((t0 - 1_618_986_658.0).abs() < 10.0, "{t0}");
    let verdict = |subject: &str| {
        im.check
            .verdicts
            .iter()
            .find(|v| v.subject == subject)
            .unwrap_or_else(|| panic!("no verdict on {subject}: {:?}", im.check.verdicts))
    };
    assert!(verdict("vertical axis").message.contains("+z points up"));
    assert!(verdict("accelerometer units").message.contains("gravity"));
    assert_eq!(verdict("sample rate").level, gyropath::import::Level::Ok);
    // Its distance is the GNSS speed's, and standing it stays put.
    let signals = gyropath::pipeline::signals(im).expect("signals");
    let gyropath::signals::Odometer::GnssSpeed { standing_s, .. } = signals.odometer else {
        panic!("{:?}", signals.odometer);
    };
    assert!(standing_s > 5.0, "{standing_s} s standing");
    assert!(signals.distance.iter().sum::<f64>() < 1.0);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .arg("fit")
        .arg(&ulog)
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("a ride without motion"), "{err}");
}

/// A Pixel 7's GnssLogger log (gnss_lib_py's `pixel6.txt`, MIT), decimated
/// for unit tests: 10 UncalGyro samples over 509 s and 94 fixes of the GPS
/// provider. It reads with its channels and clock, and the checks and the
/// fit both say that a gyro at 0.02 Hz cannot be integrated.
#[test]
fn an_android_gnsslogger_log_reads_and_its_sparse_gyro_is_refused() {
    let txt = formats().join("android_gnsslogger/pixel6.txt");
    let im = gyropath::import::open(&txt, &ImportOptions::default()).expect("open");
    assert_eq!(im.kind, gyropath::import::SourceKind::GnssLogger);
    let log = &im.log;
    assert_eq!(log.len(), 10);
    assert!((log.t_s[9] - 508.62).abs() < 0.01, "{}", log.t_s[9]);
    assert_eq!(log.metadata["t0_boot_s"], "16175.376985");
    // The first UncalGyro record, rad/s made deg/s.
    assert!((log.gyro_dps[0][0] - 0.364_839_26f64.to_degrees()).abs() < 1e-9);
    // 85 of the 94 GPS fixes fall while the gyro runs, about one in 6 s,
    // but ten rows hold only ten of them, and the reader says so.
    assert_eq!(log.fix_count(), 10);
    assert!(
        log.warnings
            .iter()
            .any(|w| w.contains("75 GNSS fix(es) fall nearest")),
        "{:?}",
        log.warnings
    );
    assert_eq!(
        log.gps_hacc_m
            .as_ref()
            .expect("accuracy")
            .iter()
            .flatten()
            .count(),
        10
    );
    let (lat, lon) = log.fix.iter().flatten().next().copied().expect("fix");
    assert!((lat - 37.4265).abs() < 0.001 && (lon + 122.1737).abs() < 0.001);
    let t0: f64 = log.metadata["t0_unix_s"].parse().expect("t0_unix_s");
    assert!((t0 - 1_699_400_633.3).abs() < 1.0, "{t0}");
    assert_eq!(
        log.accel_mps2
            .as_ref()
            .expect("accel")
            .iter()
            .flatten()
            .count(),
        10
    );
    let rate = im
        .check
        .verdicts
        .iter()
        .find(|v| v.subject == "sample rate")
        .expect("rate verdict");
    assert_eq!(rate.level, gyropath::import::Level::Problem);
    assert!(rate.message.contains("0.018 Hz"), "{}", rate.message);
    assert!(
        im.check
            .verdicts
            .iter()
            .all(|v| v.subject != "vertical axis"),
        "no axis verdict from 10 samples: {:?}",
        im.check.verdicts
    );
    let e = gyropath::pipeline::signals(im)
        .expect_err("too slow")
        .to_string();
    assert!(e.contains("0.02 Hz") && e.contains("pixel6.txt"), "{e}");
}

/// An ArduCopter 4.6.2 log on a Pixhawk 4 (ArduPilot/MethodicConfigurator's
/// `backend_log_80k.bin`, GPL-3.0-or-later, cut to 80 KiB): 0.4 s of
/// sensor data after the parameters. IMU instance 0 at about 25 Hz as
/// logged, gravity on +z once made z up, two GPS records with their GPA
/// accuracy in Braunschweig; too short for a path, and the fit says why.
#[test]
fn an_ardupilot_dataflash_log_reads_with_its_channels() {
    let bin = formats().join("ardupilot_dataflash/backend_log_80k.bin");
    let im = gyropath::import::open(&bin, &ImportOptions::default()).expect("open");
    assert_eq!(im.kind, gyropath::import::SourceKind::DataFlash);
    let log = &im.log;
    assert_eq!(log.len(), 10);
    let rate = (log.len() - 1) as f64 / log.t_s[log.len() - 1];
    assert!((23.0..27.0).contains(&rate), "{rate} Hz");
    assert_eq!(log.metadata["t0_boot_s"], "140.209868");
    // The first IMU record: GyrX 0.0053447 rad/s, GyrY -0.0032336 (made left).
    assert!((log.gyro_dps[0][0] - 0.005_344_705f64.to_degrees()).abs() < 1e-6);
    assert!((log.gyro_dps[0][1] - 0.003_233_568f64.to_degrees()).abs() < 1e-6);
    assert_eq!(log.fix_count(), 1);
    assert_eq!(log.gnss_speed_samples(), 2);
    let (lat, lon) = log.fix.iter().flatten().next().copied().expect("fix");
    assert!((lat - 52.455_636_3).abs() < 1e-9 && (lon - 10.558_581_5).abs() < 1e-9);
    assert_eq!(
        log.gps_hacc_m
            .as_ref()
            .expect("GPA HAcc")
            .iter()
            .flatten()
            .next(),
        Some(&0.9)
    );
    assert_eq!(
        log.gps_alt_m.as_ref().expect("Alt").iter().flatten().next(),
        Some(&47.77)
    );
    // GPS week 2382, 219552.2 s: 2 September 2025, 12:58:54 UTC.
    let t0: f64 = log.metadata["t0_unix_s"].parse().expect("t0_unix_s");
    assert!((t0 - 1_756_817_934.185).abs() < 0.01, "{t0}");
    let verdict = |subject: &str| {
        im.check
            .verdicts
            .iter()
            .rev()
            .find(|v| v.subject == subject)
            .unwrap_or_else(|| panic!("no verdict on {subject}: {:?}", im.check.verdicts))
    };
    assert!(verdict("vertical axis").message.contains("+z points up"));
    assert!(verdict("accelerometer units").message.contains("gravity"));
    let e = gyropath::pipeline::signals(im)
        .expect_err("one fix")
        .to_string();
    assert!(
        e.contains("1 GPS fix") && e.contains("backend_log_80k.bin"),
        "{e}"
    );
}

/// A GoPro MAX's 10 s of hand-held walking (gopro/gpmf-parser's
/// `max-heromode.mp4`, Apache-2.0 or MIT), read through telemetry-parser:
/// the gyro at 197.5 Hz, GPS5 at 18 Hz with its 2-D speed, gravity on the
/// camera's x axis (the checks recommend the mounting, applied by default),
/// and a fit whose distance is the GNSS speed's.
#[test]
fn a_gopro_mp4_reads_through_telemetry_parser_and_fits_on_its_gnss_speed() {
    let mp4 = formats().join("gopro_gpmf/max-heromode.mp4");
    let im = gyropath::pipeline::open(&mp4, &ImportOptions::default()).expect("open");
    assert_eq!(im.kind, gyropath::import::SourceKind::Camera);
    let log = &im.log;
    assert_eq!(log.len(), 2082);
    let rate = (log.len() - 1) as f64 / log.t_s[log.len() - 1];
    assert!((195.0..200.0).contains(&rate), "{rate} Hz");
    let speeds = log.gps_speed_mps.as_ref().expect("GNSS speed");
    let n = speeds.iter().flatten().count();
    assert!((180..=200).contains(&n), "{n} GNSS samples");
    assert!(speeds.iter().flatten().all(|v| *v < 2.0), "walking");
    assert_eq!(log.fix_count(), 11);
    let (lat, lon) = log.fix.iter().flatten().next().copied().expect("fix");
    assert!((lat - 33.1268).abs() < 0.001 && (lon + 117.3273).abs() < 0.001);
    // 18 November 2019, 23:45:14 UTC (GPSU of the first payload).
    let t0: f64 = log.metadata["t0_unix_s"].parse().expect("t0_unix_s");
    assert!((t0 - 1_574_120_714.0).abs() < 2.0, "{t0}");
    assert_eq!(
        im.check
            .recommended
            .as_ref()
            .map(ToString::to_string)
            .as_deref(),
        Some("x=y,y=z,z=x")
    );
    assert_eq!(
        im.mount.as_ref().map(ToString::to_string).as_deref(),
        Some("x=y,y=z,z=x")
    );
    // Ten metres of walking give the course check nothing to compare, and
    // it says so (it once read "turns too little (-0 deg over 0 stretches)").
    let course = im
        .check
        .verdicts
        .iter()
        .find(|v| v.subject == "vertical axis (GPS course)")
        .expect("a course verdict");
    assert!(
        course.message.contains("no straight stretch"),
        "{}",
        course.message
    );
    let signals = gyropath::pipeline::signals(im).expect("signals");
    assert!(matches!(
        signals.odometer,
        gyropath::signals::Odometer::GnssSpeed { .. }
    ));
    let mut fit = gyropath::optimisation::Reconstruction::new(
        signals.clone(),
        gyropath::optimisation::FitSettings::default(),
    )
    .expect("fit");
    fit.finish();
    assert!(gyropath::pipeline::failure(&fit).is_none());
    // About 14 m walked in 10.5 s.
    let walked: f64 = signals.distance.iter().sum();
    assert!((8.0..20.0).contains(&walked), "{walked} m");
    // A camera gyro's bias is a few deg/s at most. Ten seconds with barely a
    // turn cannot see the segments' roll level: before the segments' level
    // prior it drifted to -15.6 deg/s (1-sigma 9.9) with no change in the path.
    // Ten seconds are two 5 s blocks, both ends, which validation never
    // withholds: it says so instead of a NaN held-out error.
    let validated = gyropath::diagnosis::held_out_rms(
        fit.model(),
        fit.params(),
        fit.settings(),
        &gyropath::diagnosis::Folds::default(),
    );
    assert!(
        matches!(
            validated,
            Err(gyropath::optimisation::FitError::TooShortToValidate { found: 0, .. })
        ),
        "{validated:?}"
    );
    for s in gyropath::diagnosis::segment_biases(fit.model(), fit.params()) {
        assert!(
            s.bias_dps.iter().all(|b| b.abs() < 3.0),
            "{:?} deg/s at {} s",
            s.bias_dps,
            s.t0
        );
    }
}

/// A camera file cut short or damaged is an error naming it, never a panic
/// (telemetry-parser's own panics are caught).
#[test]
fn a_damaged_camera_file_is_an_error_naming_it() {
    let bytes = std::fs::read(formats().join("gopro_gpmf/max-heromode.mp4")).expect("read");
    let dir = std::env::temp_dir().join(format!("gyropath-camera-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("mkdir");
    let cut = dir.join("cut.mp4");
    for n in [0, 12, 100, 5_000, bytes.len() / 3, bytes.len() - 100_000] {
        std::fs::write(&cut, &bytes[..n]).expect("write");
        let opened = gyropath::pipeline::open(&cut, &ImportOptions::default());
        assert!(n <= 5_000 || opened.is_err(), "cut at {n} bytes, it read");
        if let Err(e) = opened {
            assert!(e.to_string().contains("cut.mp4"), "{e}");
            // Cut inside its media data: the index the camera writes last
            // is missing, and the error says so and how to mend it.
            if n > 5_000 {
                let e = e.to_string();
                assert!(
                    e.contains("never finished") && e.contains("'moov'") && e.contains("repair"),
                    "{e}"
                );
            }
        }
    }
    let mut flipped = bytes.clone();
    for at in (0..flipped.len()).step_by(7919) {
        flipped[at] ^= 0x5a;
    }
    std::fs::write(&cut, &flipped).expect("write");
    if let Err(e) = gyropath::pipeline::open(&cut, &ImportOptions::default()) {
        assert!(e.to_string().contains("cut.mp4"), "{e}");
    }
    std::fs::remove_dir_all(&dir).expect("clean");
}

/// A bike computer's wheel-speed sensor as the odometer of a log without
/// one (`--wheel ride.fit`): the Edge 810's distance matched to a ride log
/// of five minutes of its own track by UTC. Every row's distance is the
/// FIT's at that second; the fit takes the wheel's metres for the track's
/// (gain near 1) and follows the fixes; a ride that starts before the FIT's
/// distance is cut to it, with a warning; a ride without a UTC start, or
/// one from another day, is a clear error naming the FIT.
#[test]
fn a_fit_wheel_distance_is_the_odometer_of_a_ride_matched_by_utc() {
    let path = formats().join("fit/Edge810-Vector-2013-08-16-15-35-10.fit");
    let fit = gyropath::import::fit::parse(&std::fs::read(&path).expect("read"), "edge.fit")
        .expect("fit");
    assert!(fit.wheel_sensor && fit.odometer.len() > 4000);
    let dir = std::env::temp_dir().join(format!("gyropath-wheel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let ride = dir.join("camera.csv");
    std::fs::write(&ride, common::ride_along(&fit, 1200.0, 1500.0, 0.0)).expect("write");
    let options = ImportOptions {
        wheel: Some(path.clone()),
        ..ImportOptions::default()
    };
    let im = gyropath::pipeline::open(&ride, &options).expect("open with the wheel");
    let log = &im.log;
    let odo = log.odo_m.as_ref().expect("an odometer");
    let t0 = fit.track.t_s[0] + 1200.0;
    // At the rows on a record's second, the record's distance.
    for &(t, d) in fit
        .odometer
        .iter()
        .filter(|r| (t0 + 5.0..t0 + 295.0).contains(&r.0))
    {
        let j = log.t_s.partition_point(|&x| x < t - t0 - 0.001);
        assert!((odo[j].expect("distance") - d).abs() < 1e-6, "{t}: {odo:?}");
    }
    assert!(
        log.warnings
            .iter()
            .any(|w| w.contains("wheel-speed sensor's")),
        "{:?}",
        log.warnings
    );
    let sig = std::sync::Arc::new(gyropath::signals::Signals::from_log(log).expect("signals"));
    let said = sig.odometer.describe();
    assert!(
        said.contains("wheel-speed sensor") && said.contains("Edge810"),
        "{said}"
    );
    let (gain, rms) = gain_and_rms(sig);
    println!("Edge 810, 5 minutes: gain {gain:.4}, path {rms:.2} m from the fixes");
    assert!((gain - 1.0).abs() < 0.03, "gain {gain}");
    assert!(rms < 5.0, "{rms} m from the fixes");

    // A ride that starts 20 s before the FIT's distance: cut, with a warning.
    std::fs::write(&ride, common::ride_along(&fit, 0.0, 120.0, -20.0)).expect("write");
    let im = gyropath::pipeline::open(&ride, &options).expect("open, cut");
    assert!(im.log.t_s[0] >= 19.9, "{}", im.log.t_s[0]);
    assert!(
        im.log.warnings.iter().any(|w| w.contains("is cut to")),
        "{:?}",
        im.log.warnings
    );
    // From another day, and without a UTC start: errors naming the FIT.
    std::fs::write(&ride, common::ride_along(&fit, 0.0, 120.0, 86_400.0)).expect("write");
    let e = gyropath::pipeline::open(&ride, &options)
        .expect_err("another day")
        .to_string();
    assert!(
        e.starts_with(&path.display().to_string()) && e.contains("same ride"),
        "{e}"
    );
    let text = common::ride_along(&fit, 0.0, 120.0, 0.0);
    std::fs::write(&ride, text.lines().skip(1).collect::<Vec<_>>().join("\n")).expect("write");
    let e = gyropath::pipeline::open(&ride, &options)
        .expect_err("no t0_unix_s")
        .to_string();
    assert!(e.contains("t0_unix_s"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A default fit of `sig`: its odometer gain and its path's horizontal RMS
/// from the fixes (m).
fn gain_and_rms(sig: std::sync::Arc<gyropath::signals::Signals>) -> (f64, f64) {
    use gyropath::optimisation::{FitSettings, Reconstruction};
    let mut rec = Reconstruction::new(sig, FitSettings::default()).expect("fit");
    rec.finish();
    let gain = rec
        .model()
        .effect_params(rec.params(), "odometer_gain")
        .expect("gain")[0];
    (gain, rec.stats().rms_horizontal_m)
}

/// A camera without GPS and without a clock, on the bike of the Edge 810's
/// ride: the bike computer's FIT gives it both its fixes (`--gps-track`,
/// placed by the turns, which also gives the ride its UTC start) and then
/// its wheel distance (`--wheel`, matched by that start).
#[test]
fn a_fit_activity_is_both_the_gps_track_and_the_wheel_of_a_camera_without_either() {
    let path = formats().join("fit/Edge810-Vector-2013-08-16-15-35-10.fit");
    let fit = gyropath::import::fit::parse(&std::fs::read(&path).expect("read"), "edge.fit")
        .expect("fit");
    let dir = std::env::temp_dir().join(format!("gyropath-track-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let ride = dir.join("camera.csv");
    // No start time, and no fix or GNSS speed on any row.
    let text: Vec<String> = common::ride_along(&fit, 1200.0, 1500.0, 0.0)
        .lines()
        .skip(1)
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            if f[0] == "t_s" {
                line.to_string()
            } else {
                format!("{},{},{},{},,,", f[0], f[1], f[2], f[3])
            }
        })
        .collect();
    std::fs::write(&ride, text.join("\n")).expect("write");
    let options = ImportOptions {
        gps_track: Some(path.clone()),
        wheel: Some(path.clone()),
        ..ImportOptions::default()
    };
    let im = gyropath::pipeline::open(&ride, &options).expect("open with the track and the wheel");
    let log = &im.log;
    let t0 = log.t0_unix_s().expect("a start found");
    let truly = fit.track.t_s[0] + 1200.0;
    assert!(
        (t0 - truly).abs() < 0.5,
        "{t0} against {truly}: {:?}",
        log.warnings
    );
    assert!(log.fix_count() > 250 && log.odo_m.is_some());
    let (gain, rms) = gain_and_rms(std::sync::Arc::new(
        gyropath::signals::Signals::from_log(log).expect("signals"),
    ));
    println!(
        "Edge 810 as track and wheel: start {:+.2} s, gain {gain:.4}, path {rms:.2} m from the fixes",
        t0 - truly
    );
    assert!((gain - 1.0).abs() < 0.03, "gain {gain}");
    assert!(rms < 5.0, "{rms} m from the fixes");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A GoPro recording's chapters (`GX010001.MP4`, `GX020001.MP4`: the
/// camera's 4 GB files) are read as one ride when its first chapter is
/// opened, and a batch over their folder fits it once. Made of two copies
/// of the real sample, so the second "chapter" carries the first's UTC
/// start: that is said (a chapter from another recording), the placement
/// stays seamless.
#[test]
fn a_gopro_recordings_chapters_read_as_one_ride() {
    let sample = formats().join("gopro_gpmf/max-heromode.mp4");
    let dir = tempfile::tempdir().expect("tempdir");
    let first = dir.path().join("GX010001.MP4");
    let second = dir.path().join("GX020001.MP4");
    std::fs::copy(&sample, &first).expect("copy");
    std::fs::copy(&sample, &second).expect("copy");
    let alone = gyropath::pipeline::open(&sample, &ImportOptions::default()).expect("sample");
    let joined = gyropath::pipeline::open(&first, &ImportOptions::default()).expect("chapters");
    let (n, log) = (alone.log.len(), &joined.log);
    assert_eq!(log.len(), 2 * n);
    assert_eq!(log.fix_count(), 2 * alone.log.fix_count());
    assert!(log.t_s.windows(2).all(|w| w[1] > w[0]));
    let step = alone.log.t_s[n - 1] - alone.log.t_s[n - 2];
    let seam = log.t_s[n] - log.t_s[n - 1];
    assert!(
        seam > 0.0 && seam < 3.0 * step,
        "seam {seam} s, step {step} s"
    );
    let warnings = joined.warnings();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("chapter that follows") && w.contains("GX020001.MP4")),
        "{warnings:?}"
    );
    assert!(
        warnings.iter().any(|w| w.contains("GNSS clock")),
        "{warnings:?}"
    );
    // The later chapter alone reads alone, and says where the whole is.
    let later = gyropath::pipeline::open(&second, &ImportOptions::default()).expect("chapter 2");
    assert_eq!(later.log.len(), n);
    assert!(
        later.warnings().iter().any(|w| w.contains("later chapter")),
        "{:?}",
        later.warnings()
    );
    // A last chapter that was never finished (the battery ran out: no
    // index) ends the recording at the chapter before it, and is said.
    let third = dir.path().join("GX030001.MP4");
    let bytes = std::fs::read(&sample).expect("read");
    std::fs::write(&third, &bytes[..bytes.len() * 7 / 10]).expect("write");
    let ended = gyropath::pipeline::open(&first, &ImportOptions::default()).expect("two chapters");
    assert_eq!(ended.log.len(), 2 * n);
    assert!(
        ended.warnings().iter().any(|w| w.contains("GX030001.MP4")
            && w.contains("never finished")
            && w.contains("up to the chapter before")),
        "{:?}",
        ended.warnings()
    );
    std::fs::remove_file(&third).expect("rm");
    // A batch over the folder takes the recording once.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .args(["fit", dir.path().to_str().unwrap(), "--out-dir"])
        .arg(dir.path().join("out"))
        .output()
        .expect("run gyropath");
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(said.contains("1 rides,"), "{said}");
}
