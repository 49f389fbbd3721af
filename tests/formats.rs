//! The small real files of `../shared/formats` (each with its licence and a
//! README there) that have no gyro: a Garmin FIT activity, a car's NMEA
//! 0183 log and a runner's GPX track. Opened as a ride, each says what it is,
//! that a path needs a gyro, and how it can serve (the GPX and NMEA files as
//! reference tracks).

use std::path::{Path, PathBuf};

use gyropath::import::ImportOptions;

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
    assert!(e.contains("--reference"), "{e}");

    let nmea = formats().join("nmea/MTV.Local1.ublox-F9K.20200206-181434.nmea");
    let e = open_err(&nmea);
    assert!(e.starts_with(&nmea.display().to_string()), "{e}");
    assert!(e.contains("NMEA 0183 of") && e.contains("no gyro"), "{e}");

    for fit in [
        "Edge810-Vector-2013-08-16-15-35-10.fit",
        "elemnt-bolt-no-application-id-inside-developer-data-id.fit",
    ] {
        let e = open_err(&formats().join("fit").join(fit));
        assert!(
            e.contains("a Garmin FIT activity") && e.contains("A path needs a gyro"),
            "{e}"
        );
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
