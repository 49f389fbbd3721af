//! Mapped CSVs (docs/real-logs.md's two examples), rides written in the wrong axes
//! or units (the checks name the mapping that undoes them), and per-fix GPS
//! accuracy (a stretch of poor fixes is weighted down).

mod common;

use std::path::PathBuf;
use std::sync::Arc;

use gyropath::import::{self, ImportOptions, Level, Mount, MountChoice, SourceKind};
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Signals;

fn mapped(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data/mapped")
        .join(file)
}

fn open_mapped(data: &str, gps: Option<&str>, map: &str) -> Result<import::Imported, String> {
    import::open(
        &mapped(data),
        &ImportOptions {
            map: Some(mapped(map)),
            gps: gps.map(mapped),
            ..ImportOptions::default()
        },
    )
    .map_err(|e| e.to_string())
}

#[test]
fn the_readme_examples_load_and_agree() {
    let phone = open_mapped("phone-gyro.csv", Some("phone-location.csv"), "phone.toml").unwrap();
    let logger = open_mapped("logger.csv", None, "logger.toml").unwrap();
    for im in [&phone, &logger] {
        assert_eq!(im.kind, SourceKind::MappedCsv);
        assert_eq!(im.log.len(), 18_001);
        assert_eq!(im.log.fix_count(), 181);
        assert!(
            im.check.worst() < Level::Problem,
            "{:#?}",
            im.check.verdicts
        );
        assert!(
            im.check
                .recommended
                .as_ref()
                .is_some_and(Mount::is_identity)
        );
    }
    // Both are the same simulated ride: the phone's rad/s in its own axes,
    // mapped, equal the logger's deg/s in the ride frame.
    for j in (0..18_001).step_by(101) {
        for k in 0..3 {
            let (a, b) = (phone.log.gyro_dps[j][k], logger.log.gyro_dps[j][k]);
            assert!((a - b).abs() < 1e-9, "row {j} axis {k}: {a} vs {b}");
        }
    }
    assert_eq!(
        phone.log.metadata.get("mount").map(String::as_str),
        Some("x=-z,y=-x,z=y")
    );
    assert!(phone.log.gps_hacc_m.is_some() && phone.log.speed_mps.is_some());
    assert!(logger.log.odo_m.is_some());
    assert_eq!(logger.log.channels[0].0, "temp");
    for im in [phone, logger] {
        let sig = Arc::new(Signals::from_owned_log(im.log).unwrap());
        let mut fit = Reconstruction::new(sig, FitSettings::default()).unwrap();
        fit.finish();
        // The path models the GPS error's wander rather than chasing the
        // fixes: its misfit is about the fixes' own error (2-2.6 m here).
        let rms = fit.stats().rms_horizontal_m;
        assert!(rms < 3.0, "rms {rms}");
    }
}

#[test]
fn a_bad_map_or_column_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("bad.toml");
    let text = std::fs::read_to_string(mapped("logger.toml")).unwrap();
    std::fs::write(&map, text.replace("\"gyro_z\"", "\"gyro_q\"")).unwrap();
    let opts = ImportOptions {
        map: Some(map.clone()),
        ..ImportOptions::default()
    };
    let e = import::open(&mapped("logger.csv"), &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("logger.csv:2: column 'gyro_q'"), "{e}");
    assert!(e.contains("the header has: ms, gyro_x"), "{e}");
    std::fs::write(&map, text.replace("unit = \"ms\"", "unit = \"fortnights\"")).unwrap();
    let e = import::open(&mapped("logger.csv"), &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("fortnights"), "{e}");
    std::fs::write(&map, text.replace("[gps]", "[gpss]")).unwrap();
    let e = import::open(&mapped("logger.csv"), &opts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bad.toml") && e.contains("not a column map"),
        "{e}"
    );
    let csv = dir.path().join("l.csv");
    let data = std::fs::read_to_string(mapped("logger.csv")).unwrap();
    std::fs::write(&csv, data.replacen("\n100,", "\n100x,", 1)).unwrap();
    let e = import::open(
        &csv,
        &ImportOptions {
            map: Some(mapped("logger.toml")),
            ..ImportOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("l.csv:13: column 'ms'"), "{e}");
}

/// Rewrite a simulated ride's gyro as a sensor mounted `mount` would log it, in rad/s if asked.
fn mis_mounted(mount: &Mount, radians: bool) -> (import::RideLog, import::RideLog) {
    let (sim, _) = common::ride(5, 600.0, &[]);
    let log = import::parse(sim.log_csv.as_bytes(), "sim.csv").unwrap();
    let mut bad = log.clone();
    for g in &mut bad.gyro_dps {
        let ride = *g;
        let mut logged = [0.0; 3];
        for i in 0..3 {
            logged[mount.axis[i]] = mount.sign[i] * ride[i];
        }
        *g = if radians {
            logged.map(f64::to_radians)
        } else {
            logged
        };
    }
    (log, bad)
}

#[test]
fn permuted_axes_and_radians_are_undone_by_the_mapping_the_check_names() {
    for (mapping, radians) in [
        ("x=-z,y=-x,z=y", true),
        ("x=y,y=-x,z=z", false),
        ("x=x,y=-y,z=-z", false),
    ] {
        let mount: Mount = mapping.parse().unwrap();
        let (good, bad) = mis_mounted(&mount, radians);
        let im = import::checked(bad, SourceKind::RideCsv, None, &MountChoice::Auto);
        let rec = im.check.recommended.clone().unwrap();
        // The vertical and the units are always told; without an accelerometer
        // the forward axis is not, and a turn about the vertical is left to the start heading.
        assert_eq!(
            (rec.axis[2], rec.sign[2]),
            (mount.axis[2], mount.sign[2]),
            "{mapping}: {rec}"
        );
        if radians {
            assert!((rec.scale - 57.29578).abs() < 1e-3, "{rec}");
            assert!(
                im.check
                    .verdicts
                    .iter()
                    .any(|v| v.subject == "gyro units" && v.level == Level::Problem)
            );
        }
        let yaw_fixed: Vec<f64> = im.log.gyro_dps.iter().map(|g| g[2]).collect();
        for (j, g) in good.gyro_dps.iter().enumerate().step_by(503) {
            assert!((yaw_fixed[j] - g[2]).abs() < 1e-9, "{mapping}: row {j}");
        }
        // As logged, the user is told, with the mapping (a turn about the
        // vertical alone cannot be told without an accelerometer, and is harmless).
        let (_, bad) = mis_mounted(&mount, radians);
        let as_logged = import::checked(bad, SourceKind::RideCsv, None, &MountChoice::AsLogged);
        let w = as_logged.warnings();
        let told = w
            .iter()
            .any(|w| w.contains(&format!("the data say '{rec}'")));
        assert_eq!(told, !rec.is_identity(), "{mapping}: {w:?}");
    }
}

/// A phone export's HDOP and satellite columns, mapped, become the ride
/// log's `gps_hdop` and `gps_num_sats` at the fixes.
#[test]
fn a_mapped_export_hands_on_the_receivers_hdop_and_satellites() {
    let dir = tempfile::tempdir().unwrap();
    let location = std::fs::read_to_string(mapped("phone-location.csv")).unwrap();
    let mut rows = location.lines();
    let header = rows.next().unwrap();
    let mut with = format!("{header},hdop,satellites\n");
    for (k, row) in rows.enumerate() {
        let (hdop, sats) = if k % 10 == 0 { ("4.5", 5) } else { ("0.9", 11) };
        with.push_str(&format!("{row},{hdop},{sats}\n"));
    }
    std::fs::write(dir.path().join("location.csv"), with).unwrap();
    let map = std::fs::read_to_string(mapped("phone.toml")).unwrap()
        + "hdop = \"hdop\"\nsats = \"satellites\"\n";
    std::fs::write(dir.path().join("phone.toml"), map).unwrap();
    let im = import::open(
        &mapped("phone-gyro.csv"),
        &ImportOptions {
            map: Some(dir.path().join("phone.toml")),
            gps: Some(dir.path().join("location.csv")),
            ..ImportOptions::default()
        },
    )
    .unwrap();
    let at_fixes = |c: &Option<Vec<Option<f64>>>| -> Vec<f64> {
        let c = c.as_ref().expect("the column");
        im.log
            .fix
            .iter()
            .zip(c)
            .filter_map(|(f, v)| f.and(*v))
            .collect()
    };
    let (hdop, sats) = (at_fixes(&im.log.gps_hdop), at_fixes(&im.log.gps_num_sats));
    let fixes = im.log.fix.iter().flatten().count();
    assert_eq!((hdop.len(), sats.len()), (fixes, fixes));
    assert!(hdop.iter().all(|h| *h == 0.9 || *h == 4.5));
    assert!(sats.iter().all(|n| *n == 11.0 || *n == 5.0));
    assert!(hdop.iter().filter(|h| **h == 4.5).count() * 9 < fixes);
}

/// A stretch of fixes 12 m off to the east-north-east for two minutes,
/// wandering by a few metres; the log's quality fields there (`hacc` 15 m
/// against 2.5 m, HDOP 6 against 1, 4 satellites against 9) from `quality`.
fn poor_stretch(log: &mut import::RideLog, quality: impl Fn(bool) -> f64) -> Vec<Option<f64>> {
    let m_per_deg = 111_320.0;
    let mut field = vec![None; log.len()];
    let mut k = 0usize;
    for ((fix, &t), q) in log.fix.iter_mut().zip(&log.t_s).zip(field.iter_mut()) {
        let Some((lat, lon)) = *fix else { continue };
        k += 1;
        let poor = (200.0..320.0).contains(&t);
        *q = Some(quality(poor));
        if poor {
            let wander = 4.0 * ((k as f64) * 0.37).sin();
            let (de, dn) = (12.0 + wander, 5.0 - wander);
            *fix = Some((
                lat + dn / m_per_deg,
                lon + de / (m_per_deg * lat.to_radians().cos()),
            ));
        }
    }
    field
}

fn fit_error(sim: &gyropath::simulation::SimulatedRide, log: &import::RideLog) -> f64 {
    let sig = Arc::new(Signals::from_log(log).unwrap());
    let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).unwrap();
    fit.finish();
    sim.errors(&sig, &fit.trajectory().p).path_at_fixes_m
}

#[test]
fn a_stretch_of_poor_fixes_is_weighted_down_by_its_accuracy() {
    let (sim, _) = common::ride(6, 600.0, &[]);
    let mut log = import::parse(sim.log_csv.as_bytes(), "poor.csv").unwrap();
    let hacc = poor_stretch(&mut log, |poor| if poor { 15.0 } else { 2.5 });
    let unweighted = fit_error(&sim, &log);
    log.gps_hacc_m = Some(hacc);
    let weighted = fit_error(&sim, &log);
    eprintln!("truth error at the fixes: unweighted {unweighted:.2} m, weighted {weighted:.2} m");
    assert!(
        weighted < 0.8 * unweighted,
        "weighted {weighted:.2} m vs {unweighted:.2} m"
    );
}

/// Without an accuracy the receiver's HDOP weighs the fixes (relative to
/// the ride's median), and the check tells what the quality fields say.
#[test]
fn without_an_accuracy_the_hdop_weighs_the_fixes() {
    let (sim, _) = common::ride(6, 600.0, &[]);
    let mut log = import::parse(sim.log_csv.as_bytes(), "poor.csv").unwrap();
    let hdop = poor_stretch(&mut log, |poor| if poor { 6.0 } else { 1.0 });
    let sats: Vec<Option<f64>> = hdop
        .iter()
        .map(|h| h.map(|h| if h > 1.0 { 4.0 } else { 9.0 }))
        .collect();
    let unweighted = fit_error(&sim, &log);
    log.gps_hdop = Some(hdop);
    log.gps_num_sats = Some(sats);
    let weighted = fit_error(&sim, &log);
    eprintln!("truth error at the fixes: unweighted {unweighted:.2} m, by HDOP {weighted:.2} m");
    assert!(
        weighted < 0.8 * unweighted,
        "by HDOP {weighted:.2} m vs {unweighted:.2} m"
    );
    // Written and read back as the format's columns, and told by the check.
    let mut csv = Vec::new();
    import::ride_csv::write(&log, &mut csv).unwrap();
    let back = import::parse(&csv[..], "back.csv").unwrap();
    assert_eq!(back.gps_hdop, log.gps_hdop);
    assert_eq!(back.gps_num_sats, log.gps_num_sats);
    assert!(
        back.channels.iter().all(|(n, _)| !n.starts_with("gps_")),
        "the quality fields are no extra channels"
    );
    let im = import::checked(back, SourceKind::RideCsv, None, &MountChoice::Auto);
    let v = im
        .check
        .verdicts
        .iter()
        .find(|v| v.subject == "GPS quality")
        .expect("a GPS quality verdict");
    assert!(
        v.message.starts_with(
            "HDOP 1.0 in the median, 6.0 at the 95th percentile (each fix is weighted by it"
        ) && v.message.contains("4-9 satellites, 9 in the median")
            && v.level == Level::Info,
        "{v:?}"
    );
}

/// The mapped phone example's gyro file with `location` as its GPS file.
fn phone_with_location(location: &std::path::Path) -> Result<import::Imported, String> {
    import::open(
        &mapped("phone-gyro.csv"),
        &ImportOptions {
            map: Some(mapped("phone.toml")),
            gps: Some(location.to_path_buf()),
            ..ImportOptions::default()
        },
    )
    .map_err(|e| e.to_string())
}

/// A phone app stopped in the middle of writing its location file (no line
/// end after the last row, which is short): that row is left out with a
/// warning naming its line, and the rest of the ride loads. Before, the
/// whole ride was refused for that one unfinished row.
#[test]
fn a_location_file_cut_short_loses_its_last_row_only() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(mapped("phone-location.csv")).unwrap();
    let cut = dir.path().join("cut.csv");
    std::fs::write(&cut, &text[..text.len() - 15]).unwrap();
    let opened = phone_with_location(&cut).unwrap();
    assert_eq!(opened.log.fix_count(), 180);
    let lines = text.lines().count();
    assert!(
        opened
            .log
            .warnings
            .iter()
            .any(|w| w.starts_with(&format!("{}:{lines}: ", cut.display()))
                && w.contains("the last line is left out: it has no line end")),
        "{:?}",
        opened.log.warnings
    );
    // With its line end, the short row is bad input, as any other.
    std::fs::write(&cut, format!("{}\n", &text[..text.len() - 15])).unwrap();
    assert!(phone_with_location(&cut).is_err());
}

/// A phone that has no speed for ten seconds writes -1 there (iOS does):
/// a ground speed has no sign, so those samples are left out and the speed
/// interpolated across them, with a warning. Read as speeds, they ran the
/// path backwards and the fit failed as "not physical".
#[test]
fn a_phones_minus_one_speed_is_no_speed() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(mapped("phone-location.csv")).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let speed = header.split(',').position(|c| c == "speed").unwrap();
    let mut edited = format!("{header}\n");
    for (i, line) in lines.enumerate() {
        let mut f: Vec<&str> = line.split(',').collect();
        if (60..70).contains(&i) {
            f[speed] = "-1";
        }
        edited.push_str(&f.join(","));
        edited.push('\n');
    }
    let location = dir.path().join("location.csv");
    std::fs::write(&location, edited).unwrap();
    let opened = phone_with_location(&location).unwrap();
    assert!(
        opened
            .log
            .warnings
            .iter()
            .any(|w| w
                .contains("10 negative value(s) of the GPS file's speed column 'speed' left out")),
        "{:?}",
        opened.log.warnings
    );
    let speeds = opened.log.speed_mps.as_ref().expect("speed");
    assert!(speeds.iter().flatten().all(|&v| v >= 0.0));
    let sig = Arc::new(Signals::from_owned_log(opened.log).unwrap());
    let mut fit = Reconstruction::new(sig, FitSettings::default()).unwrap();
    fit.finish();
    let rms = fit.stats().rms_horizontal_m;
    assert!(rms < 3.0, "rms {rms}");
}

/// A phone's location file with its coordinates as NMEA writes them
/// (degrees and minutes run together, 4728.73198 for 47.4788664): every fix
/// is out of range, and the load fails naming them with their degrees.
/// Before, it said only "no usable GPS fix while the IMU and the odometer
/// run"; with some fixes in range, the others are left out with the same words.
#[test]
fn coordinates_in_degrees_and_minutes_are_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(mapped("phone-location.csv")).unwrap();
    let as_nmea = |v: &str| {
        let x: f64 = v.parse().unwrap();
        let d = x.abs().trunc();
        format!(
            "{}{:.5}",
            if x < 0.0 { "-" } else { "" },
            100.0 * d + 60.0 * (x.abs() - d)
        )
    };
    let write = |every: usize| {
        let mut out = String::new();
        for (k, line) in text.lines().enumerate() {
            let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
            if k > 0 && k % every == 0 {
                f[2] = as_nmea(&f[2]);
                f[3] = as_nmea(&f[3]);
            }
            out.push_str(&f.join(","));
            out.push('\n');
        }
        let path = dir.path().join(format!("location-{every}.csv"));
        std::fs::write(&path, out).unwrap();
        path
    };
    let e = phone_with_location(&write(1)).err().unwrap_or_default();
    assert!(
        e.contains("181 of 181 fixes are outside -90..90, -180..360 degrees")
            && e.contains("as NMEA writes them? 47.4788663, 19.0226325 in degrees"),
        "{e}"
    );
    let some = phone_with_location(&write(10)).unwrap();
    assert_eq!(some.log.fix_count(), 181 - 18);
    assert!(
        some.log
            .warnings
            .iter()
            .any(|w| w.contains("18 of 181 fixes are outside")
                && w.contains("NMEA")
                && w.ends_with("left out")),
        "{:?}",
        some.log.warnings
    );
}

/// A phone's gyro file whose nanosecond clock went through a
/// single-precision float (a spreadsheet or a float32 array on the way):
/// its times are whole multiples of 2^37 ns (137 s), nearly every row
/// repeats the time of the row before, and the load fails naming the column
/// and why. Before, those rows were dropped with a warning and the few left
/// ended in "no usable GPS fix while the IMU and the odometer run".
#[test]
fn a_clock_written_as_single_precision_floats_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(mapped("phone-gyro.csv")).unwrap();
    let mut out = String::new();
    for (k, line) in text.lines().enumerate() {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        if k > 0 {
            let t: f64 = f[0].parse().unwrap();
            f[0] = format!("{}", f64::from(t as f32));
        }
        out.push_str(&f.join(","));
        out.push('\n');
    }
    let gyro = dir.path().join("phone-gyro.csv");
    std::fs::write(&gyro, out).unwrap();
    let e = import::open(
        &gyro,
        &ImportOptions {
            map: Some(mapped("phone.toml")),
            gps: Some(mapped("phone-location.csv")),
            ..ImportOptions::default()
        },
    )
    .map(|_| ())
    .err()
    .map(|e| e.to_string())
    .unwrap_or_default();
    assert!(
        e.contains("phone-gyro.csv:3: column 'time'")
            && e.contains("rows repeat the time of the row before")
            && e.contains("whole multiples of 137438953472 ns, as a single-precision float"),
        "{e}"
    );
}
