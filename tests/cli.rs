//! The command line end to end: simulate, fit, outputs, exit codes.

use std::path::Path;
use std::process::Command;

fn gyropath(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .args(args)
        .output()
        .expect("run gyropath")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn simulate_then_fit_writes_path_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    let truth = dir.path().join("truth.csv");
    let out = gyropath(&[
        "simulate",
        "--seed",
        "11",
        "--duration",
        "240",
        "--out",
        s(&ride),
        "--truth",
        s(&truth),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let path = dir.path().join("path.csv");
    let report = dir.path().join("report.json");
    let out = gyropath(&[
        "fit",
        s(&ride),
        "--out",
        s(&path),
        "--json",
        s(&report),
        "--segment-s",
        "10",
        "--verbose",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("rms       path to the fixes"), "{stdout}");
    // With --verbose: plain progress lines when stderr is not a terminal,
    // and the segment lengths' -2 ln L.
    assert!(String::from_utf8_lossy(&out.stderr).contains("step 2 lm"));
    assert!(stdout.contains("-2 ln L"), "{stdout}");

    let ride_rows = std::fs::read_to_string(&ride)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count()
        - 1;
    let text = std::fs::read_to_string(&path).unwrap();
    // The `#` lines say what the columns are measured from.
    assert!(text.starts_with("# gyropath path"), "{text:.300}");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = lines.next().unwrap();
    assert!(header.starts_with("t_s,lat_deg,lon_deg,alt_m"));
    // The path's 1-sigma per row: positive, finite, metres.
    assert!(
        header.ends_with(",sigma_east_m,sigma_north_m,sigma_up_m"),
        "{header}"
    );
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .step_by(997)
    {
        for v in line.split(',').skip(8) {
            let v: f64 = v.parse().unwrap();
            assert!(v.is_finite() && v > 0.0 && v < 50.0, "{line}");
        }
    }
    assert_eq!(lines.count(), ride_rows);
    let truth_rows = std::fs::read_to_string(&truth).unwrap().lines().count() - 1;
    assert_eq!(truth_rows, ride_rows);

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert!(json["stats"]["rms_horizontal_m"].as_f64().unwrap() < 5.0);
    assert!(json["iterations_step1"].as_u64().unwrap() > 0);
    assert!(json["iterations_step2"].as_u64().unwrap() > 0);
    assert_eq!(json["model"][0], "initial_position");
    assert!(
        json["parameters"]["odometer_gain"][0]["value"]
            .as_f64()
            .unwrap()
            > 0.9
    );
    assert_eq!(
        json["parameters"]["gyro_bias_segments"]
            .as_array()
            .unwrap()
            .len(),
        3 * 24
    );
    // Every fitted parameter has its sigma; the noise the fit ran with is reported.
    let gain_sigma = json["parameters"]["odometer_gain"][0]["sigma"]
        .as_f64()
        .unwrap();
    assert!(gain_sigma > 0.0 && gain_sigma < 0.05, "{gain_sigma}");
    assert!(
        json["parameters"]["gyro_bias_segments"]
            .as_array()
            .unwrap()
            .iter()
            .all(|p| p["sigma"].as_f64().is_some_and(|s| s > 0.0))
    );
    assert!(json["noise"]["gps_sigma_m"]["value"].as_f64().unwrap() > 0.0);

    // Never over the input log.
    let out = gyropath(&["fit", s(&ride), "--out", s(&ride)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("refusing to write over the input"));
}

#[test]
fn bad_input_fails_with_one_line_naming_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(
        &bad,
        "t_s,gx_dps,gy_dps,gz_dps,odo_m,lat_deg,lon_deg\n0,0,0,0,0,47.5,19.0\n0.01,0,x,0,0.1,,\n",
    )
    .unwrap();
    let out = gyropath(&["fit", s(&bad)]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("bad.csv:3: column 'gy_dps': 'x' is not a number"),
        "{err}"
    );

    let missing = dir.path().join("missing.csv");
    let out = gyropath(&["fit", s(&missing)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.csv: cannot read"));

    // A ride that never moves: the heading is unobservable, said so.
    let still = dir.path().join("still.csv");
    let mut text = String::from("t_s,gx_dps,gy_dps,gz_dps,odo_m,lat_deg,lon_deg\n");
    for i in 0..3000 {
        let fix = if i % 100 == 0 { "47.5,19.0" } else { "," };
        text.push_str(&format!("{},0.01,0.02,0.03,0,{fix}\n", i as f64 * 0.01));
    }
    std::fs::write(&still, text).unwrap();
    let out = gyropath(&["fit", s(&still)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("heading is unobservable"));
}

#[test]
fn help_lists_every_command() {
    let out = gyropath(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for cmd in ["fit", "simulate", "diagnose", "open"] {
        assert!(text.contains(cmd), "{cmd} missing from: {text}");
    }
}

#[test]
fn diagnose_writes_the_documented_json_shape() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("lag.csv");
    let out = gyropath(&[
        "simulate",
        "--seed",
        "12",
        "--duration",
        "420",
        "--hidden",
        "gps_lag",
        "--out",
        s(&ride),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json = dir.path().join("diag.json");
    let out = gyropath(&["diagnose", s(&ride), "--json", s(&json), "--quiet"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("held-out") && table.contains("gps_lag"),
        "{table}"
    );
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(
        d["model"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m == "gyro_bias_segments")
    );
    assert!(d["fit_rms_m"].as_f64().unwrap() > 0.0);
    assert!(d["heldout_rms_m"].as_f64().unwrap() > 0.0);
    let ranking = d["ranking"].as_array().unwrap();
    assert!(ranking.len() >= 5, "{ranking:?}");
    for c in ranking {
        for key in [
            "effect",
            "heldout_rms_m",
            "drop",
            "significant",
            "estimate",
            "explanation",
        ] {
            assert!(c.get(key).is_some(), "{key} missing in {c}");
        }
    }
    assert_eq!(ranking[0]["effect"], "gps_lag");
    assert!(ranking[0]["estimate"]["lag"]["sigma"].as_f64().unwrap() > 0.0);
}

#[test]
fn diagnose_refuses_bad_fold_settings() {
    let out = gyropath(&["diagnose", "nope.csv", "--folds", "1"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--folds"));
}

#[test]
fn batch_mode_fits_a_folder_and_reports_every_ride() {
    let dir = tempfile::tempdir().unwrap();
    let rides = dir.path().join("rides");
    std::fs::create_dir(&rides).unwrap();
    for seed in ["21", "22"] {
        let out = gyropath(&[
            "simulate",
            "--seed",
            seed,
            "--duration",
            "200",
            "--out",
            s(&rides.join(format!("ride{seed}.csv"))),
        ]);
        assert!(out.status.success());
    }
    std::fs::write(rides.join("broken.csv"), "t_s,gx_dps\n0,1\n").unwrap();
    let out_dir = dir.path().join("out");
    let out = gyropath(&["fit", s(&rides), "--out-dir", s(&out_dir), "--quiet"]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{table}");
    assert!(
        table.contains("ride21.csv") && table.contains("ride22.csv"),
        "{table}"
    );
    assert!(
        table.contains("broken.csv") && table.contains("failed"),
        "{table}"
    );
    assert!(table.contains("3 rides, 2 fitted, 1 failed"), "{table}");
    for stem in ["ride21", "ride22"] {
        assert!(out_dir.join(format!("{stem}-path.csv")).exists());
        assert!(out_dir.join(format!("{stem}-report.json")).exists());
    }
    // Several rides with --out is refused.
    let out = gyropath(&[
        "fit",
        s(&rides.join("ride21.csv")),
        s(&rides.join("ride22.csv")),
        "--out",
        "x.csv",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--out-dir"));
}

const HUSKY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/real/robot_localization-test1"
);

/// `gyropath fit SOURCE --json R` with no other flag: the report's odometer gain and RMS.
fn fit_source(source: &str, report: &Path) -> (f64, f64) {
    let out = gyropath(&["fit", source, "--quiet", "--json", s(report)]);
    assert!(
        out.status.success(),
        "{source}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    let gain = r["parameters"]["odometer_gain"][0]["value"]
        .as_f64()
        .unwrap_or_else(|| panic!("no gain in {r}"));
    (gain, r["stats"]["rms_horizontal_m"].as_f64().unwrap())
}

#[test]
fn bags_fit_with_no_other_flag_and_import_writes_a_ride_log_that_fits_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let (g1, rms1) = fit_source(&format!("{HUSKY}/test1.bag"), &dir.path().join("a.json"));
    let (g2, rms2) = fit_source(&format!("{HUSKY}/test1_ros2"), &dir.path().join("b.json"));
    assert!((g1 - g2).abs() < 0.001, "gain {g1} vs {g2}");
    // The Husky's fixes are smooth (8 cm of jitter) on a wander of about 3 m
    // over minutes: the path follows their motion, not their offset (gain
    // 0.947 +- 0.020; 0.970 +- 0.002 when the wander was whitened per fix).
    assert!((0.92..=1.05).contains(&g1), "gain {g1}");
    assert!(rms1 <= 4.0 && rms2 <= 4.0, "rms {rms1} {rms2}");
    let csv = dir.path().join("husky.csv");
    let out = gyropath(&["import", &format!("{HUSKY}/test1.bag"), "--out", s(&csv)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.contains("# mount: x=-z,y=-x,z=y"), "{}", &text[..400]);
    assert!(
        text.contains("# topics: imu /imu/data, odom /husky_velocity_controller/odom, fix /fix")
    );
    assert!(text.contains("gps_hacc_m") && text.contains("ax_mps2") && text.contains("speed_mps"));
    let (g3, rms3) = fit_source(s(&csv), &dir.path().join("c.json"));
    assert!(
        (g3 - g1).abs() < 1e-9 && (rms3 - rms1).abs() < 1e-9,
        "{g3} {rms3} vs {g1} {rms1}"
    );
}

#[test]
fn check_names_the_mounting_and_a_wrong_topic_lists_the_candidates() {
    let out = gyropath(&["check", &format!("{HUSKY}/test1.bag")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("+y points up") && text.contains("-z points forward"),
        "{text}"
    );
    assert!(text.contains("--mount \"x=-z,y=-x,z=y\""), "{text}");
    let out = gyropath(&["fit", &format!("{HUSKY}/test1.bag"), "--imu", "/imu/nope"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("test1.bag") && err.contains("'/imu/nope'") && err.contains("/imu/data"),
        "{err}"
    );
    let out = gyropath(&[
        "fit",
        &format!("{HUSKY}/test1.bag"),
        "--mount",
        "x=x,y=y,z=-z",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("mirror"));
}

/// Berlin's yaw rate written as a MEMS gyro's raw counts (131 per deg/s):
/// the checks name the counts with the scales they can be (the city's GPS
/// course tells the ratio to +-36 %), and the fit's failure, which on its
/// own blames the odometer (a gain of 2.6), points at them as the likelier
/// cause with the mounting that undoes them. With the counts' scale the fit
/// is Berlin's own.
#[test]
fn a_gyro_in_raw_counts_is_named_and_the_fits_failure_points_at_it() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("counts.csv");
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real/smartloc-berlin-potsdamer-platz/ride.csv"
    ))
    .unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        if let Some(gz) = f.get(3).and_then(|v| v.parse::<f64>().ok()) {
            f[3] = format!("{:.0}", gz * 131.0);
        }
        out.push_str(&f.join(","));
        out.push('\n');
    }
    std::fs::write(&ride, out).unwrap();
    let check = gyropath(&["check", s(&ride)]);
    let said = String::from_utf8_lossy(&check.stdout);
    assert!(
        said.contains("PROBLEM   gyro units")
            && said.contains(
                "raw counts of a gyro at +-250 deg/s full scale (131 per deg/s) (scale 0.007634)"
            )
            && !said.contains("deg/s logged as rad/s"),
        "{said}"
    );
    let fit = gyropath(&["fit", s(&ride)]);
    assert!(!fit.status.success());
    let err = String::from_utf8_lossy(&fit.stderr);
    assert!(
        err.contains("the fit failed")
            && err
                .contains("the likelier cause is what the checks found in the log's axes or units")
            && err.contains("  gyro units: the gyro turns"),
        "{err}"
    );
    let fit = gyropath(&["fit", s(&ride), "--mount", "x=x,y=y,z=z,scale=0.0076335878"]);
    assert!(
        fit.status.success(),
        "{}",
        String::from_utf8_lossy(&fit.stderr)
    );
}

#[test]
fn a_fit_with_wrong_axes_fails_with_its_cause_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("path.csv");
    let out = gyropath(&[
        "fit",
        &format!("{HUSKY}/test1.bag"),
        "--mount",
        "none",
        "--out",
        s(&path),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the fit failed: it is not physical"), "{err}");
    assert!(err.contains("start tilt of the sensor"), "{err}");
    assert!(err.contains("--mount auto"), "{err}");
    // The checks had said so, with the mounting that undoes it.
    assert!(err.contains("the data say 'x=-z,y=-x,z=y'"), "{err}");
    assert!(!path.exists(), "a failed fit wrote a path");
}

#[test]
fn the_husky_is_planar_physical_and_diagnose_finds_nothing_absurd() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("r.json");
    let (gain, rms) = fit_source(&format!("{HUSKY}/test1.bag"), &report);
    assert!(
        (0.92..=1.05).contains(&gain) && rms <= 4.0,
        "gain {gain}, rms {rms}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert!(
        r["attitude"].as_str().unwrap().starts_with("planar"),
        "{}",
        r["attitude"]
    );
    let tilt = &r["parameters"]["initial_orientation"];
    assert_eq!(tilt[0]["fixed"], true);
    assert_eq!(tilt[0]["value"], 0.0);
    let diag = dir.path().join("d.json");
    let out = gyropath(&[
        "diagnose",
        &format!("{HUSKY}/test1.bag"),
        "--quiet",
        "--json",
        s(&diag),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&diag).unwrap()).unwrap();
    // A planar model holds the roll and pitch parts of every gyro effect: they
    // are not estimated, so not reported (they printed the prior's sigma).
    let scale = d["ranking"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["effect"] == "gyro_scale")
        .expect("gyro_scale ranked");
    let names: Vec<&String> = scale["estimate"].as_object().unwrap().keys().collect();
    assert_eq!(names, ["scale_error_z"], "{}", scale["estimate"]);
    for c in d["ranking"].as_array().unwrap() {
        if c["significant"] == true {
            for (name, e) in c["estimate"].as_object().unwrap() {
                let v = e["value"].as_f64().unwrap().abs();
                use gyropath::limits::{MAX_MOUNT_DEG, MAX_SCALE_PERCENT};
                let limit = if name.starts_with("forward") {
                    MAX_MOUNT_DEG
                } else if name.starts_with("scale") {
                    MAX_SCALE_PERCENT
                } else {
                    f64::INFINITY
                };
                assert!(v <= limit, "{}: {name} {v} marked significant", c["effect"]);
            }
        }
    }
}

#[test]
fn diagnose_on_an_unphysical_fit_says_so_and_marks_nothing_significant() {
    let dir = tempfile::tempdir().unwrap();
    let diag = dir.path().join("d.json");
    let out = gyropath(&[
        "diagnose",
        &format!("{HUSKY}/test1.bag"),
        "--mount",
        "none",
        "--attitude",
        "3d",
        "--quiet",
        "--json",
        s(&diag),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the model's own fit is not physical"), "{err}");
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&diag).unwrap()).unwrap();
    assert!(!d["not_physical"].as_array().unwrap().is_empty());
    assert!(
        d["ranking"]
            .as_array()
            .unwrap()
            .iter()
            .all(|c| c["significant"] == false)
    );
}

/// A short simulated ride at `path`.
fn simulated(path: &Path, seed: &str, hidden: &str, duration: &str) {
    let out = gyropath(&[
        "simulate",
        "--seed",
        seed,
        "--duration",
        duration,
        "--hidden",
        hidden,
        "--out",
        s(path),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn listed_effects_add_to_the_papers_model_and_a_path_that_misses_the_fixes_is_a_failure() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "31", "gps_lag", "600");
    let report = dir.path().join("r.json");
    let out = gyropath(&[
        "fit",
        s(&ride),
        "--effects",
        "gps_lag",
        "--quiet",
        "--json",
        s(&report),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let model: Vec<&str> = r["model"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    for id in ["initial_position", "gyro_bias_segments", "gps_lag"] {
        assert!(model.contains(&id), "{model:?}");
    }
    assert!(r["stats"]["rms_horizontal_m"].as_f64().unwrap() < 10.0);

    // The lag alone, the paper's model taken out: no path parameters, and
    // the path cannot follow the fixes. That is a failure, not a result.
    let path = dir.path().join("p.csv");
    let out = gyropath(&[
        "fit",
        s(&ride),
        "--effects=-paper,gps_lag",
        "--quiet",
        "--out",
        s(&path),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("path's distance from the GPS fixes") && err.contains("scatter"),
        "{err}"
    );
    assert!(!path.exists(), "a failed fit wrote its path");
}

#[test]
fn a_batchs_outputs_never_collide_and_without_out_dir_it_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    for (folder, seed) in [("comma", "41"), ("berlin", "42")] {
        std::fs::create_dir(dir.path().join(folder)).unwrap();
        simulated(&dir.path().join(folder).join("ride.csv"), seed, "", "180");
    }
    let a = dir.path().join("comma/ride.csv");
    let b = dir.path().join("berlin/ride.csv");
    let out_dir = dir.path().join("out");
    let out = gyropath(&["fit", s(&a), s(&b), "--out-dir", s(&out_dir), "--quiet"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for stem in ["comma-ride", "berlin-ride"] {
        let report = out_dir.join(format!("{stem}-report.json"));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let folder = stem.trim_end_matches("-ride");
        assert!(
            r["source"].as_str().unwrap().contains(folder),
            "{stem}: {}",
            r["source"]
        );
        assert!(out_dir.join(format!("{stem}-path.csv")).exists());
    }
    // The same ride twice: refused, naming it.
    let out = gyropath(&["fit", s(&a), s(&a), "--out-dir", s(&out_dir)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("give each ride once"));

    // A folder without --out-dir: the table, and no files in the working directory.
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .args(["fit", s(&dir.path().join("comma")), "--quiet"])
        .current_dir(&work)
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{table}");
    assert!(table.contains("no files written"), "{table}");
    assert_eq!(std::fs::read_dir(&work).unwrap().count(), 0);
}

/// A folder of drives, one folder each with its ride and reference (as
/// `../shared/real` is laid out): the batch finds the rides in the
/// subfolders and measures each against the `truth.csv` beside it, which is
/// not taken for a ride; without `--reference` that file fails as what it is.
#[test]
fn a_batch_searches_subfolders_and_a_reference_beside_a_ride_is_not_a_ride() {
    let dir = tempfile::tempdir().unwrap();
    let drives = dir.path().join("drives");
    for (folder, seed) in [("a", "61"), ("b/deeper", "62")] {
        let here = drives.join(folder);
        std::fs::create_dir_all(&here).unwrap();
        let out = gyropath(&[
            "simulate",
            "--seed",
            seed,
            "--duration",
            "120",
            "--out",
            s(&here.join("ride.csv")),
            "--truth",
            s(&here.join("truth.csv")),
        ]);
        assert!(out.status.success());
    }
    // The outputs inside the folder of drives: a second batch does not
    // take the first one's paths for rides.
    let out_dir = drives.join("out");
    for _ in 0..2 {
        let out = gyropath(&[
            "fit",
            s(&drives),
            "--reference",
            "truth.csv",
            "--out-dir",
            s(&out_dir),
            "--quiet",
        ]);
        let table = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{table}");
        assert!(table.contains("2 rides, 2 fitted, 0 failed"), "{table}");
    }
    for stem in ["a-ride", "deeper-ride"] {
        let report = out_dir.join(format!("{stem}-report.json"));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let to_ref = r["reference"]["horizontal"]["rms_m"].as_f64();
        assert!(to_ref.is_some_and(|m| m < 5.0), "{stem}: {to_ref:?}");
    }
    std::fs::remove_dir_all(&out_dir).unwrap();
    let out = gyropath(&["fit", s(&drives), "--quiet"]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{table}");
    assert!(table.contains("4 rides, 2 fitted, 2 failed"), "{table}");
    assert!(
        table.contains("a track of positions without a gyro"),
        "{table}"
    );
}

#[test]
fn dash_is_standard_output_the_format_follows_the_extension_and_devices_stay_devices() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "51", "", "180");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_gyropath"))
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    // The report on standard output (JSON alone there), the summary on standard error.
    let out = run(&["fit", "ride.csv", "--json", "-"]);
    assert!(out.status.success());
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert!(r["stats"]["rms_horizontal_m"].as_f64().is_some());
    assert!(String::from_utf8_lossy(&out.stderr).contains("rms       path to the fixes"));
    assert!(!dir.path().join("-").exists(), "a file named - was written");

    // .gpx is GPX; an unknown extension fails before the fit, naming the choices.
    let out = run(&["fit", "ride.csv", "--quiet", "--out", "p.gpx"]);
    assert!(out.status.success());
    let gpx = std::fs::read_to_string(dir.path().join("p.gpx")).unwrap();
    assert!(
        gpx.starts_with("<?xml") && gpx.contains("<trkpt"),
        "{gpx:.200}"
    );
    let out = run(&["fit", "ride.csv", "--out", "p.kml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("p.kml") && err.contains(".gpx"), "{err}");
    assert!(!err.contains("step 1"), "it fitted before refusing: {err}");
    let out = run(&["diagnose", "ride.csv", "--json", "d.txt"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains(".json"));
    // So does an output into a folder that is not there (a typo), for every
    // command and output: the work would be lost at the end.
    for args in [
        &["fit", "ride.csv", "--out", "typo/p.csv"][..],
        &["fit", "ride.csv", "--html", "typo/r.html"],
        &["explain", "ride.csv", "--save-model", "typo/m.json"],
        &["diagnose", "ride.csv", "--json", "typo/d.json"],
    ] {
        let out = run(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains("cannot write: there is no folder typo"),
            "{args:?}: {err}"
        );
        assert!(
            !err.contains("step 1") && !err.contains("base "),
            "{args:?} worked first: {err}"
        );
    }

    // check --json /dev/stdout: the JSON arrives on standard output and
    // /dev/stdout is still a link.
    let out = run(&["check", "ride.csv", "--json", "/dev/stdout"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let json_start = text.find('{').expect("JSON on stdout");
    let _: serde_json::Value = serde_json::from_str(&text[json_start..]).expect("valid JSON");
    assert!(
        std::fs::symlink_metadata("/dev/stdout")
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let out = run(&["fit", "ride.csv", "--quiet", "--out", "/dev/null"]);
    assert!(out.status.success());
    use std::os::unix::fs::FileTypeExt;
    assert!(
        std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );
}

#[test]
fn the_bundled_city_example_is_a_result_not_a_failure() {
    // Its fixes sit in a street canyon 10-70 m off for tens of seconds with
    // a jitter of 1.9 m: a right path misses a quarter of them by 14 m,
    // which the path's limit must not call a failure.
    let city = concat!(env!("CARGO_MANIFEST_DIR"), "/data/city-gps.csv");
    let out = gyropath(&["fit", city, "--quiet"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn check_fails_on_a_problem_the_default_reading_leaves_and_json_says_what_made_it() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("mis.csv");
    let out = gyropath(&[
        "simulate",
        "--seed",
        "3",
        "--duration",
        "200",
        "--gyro-axes",
        "x=-z,y=-x,z=y",
        "--out",
        s(&ride),
    ]);
    assert!(out.status.success());
    // A CSV is read as logged: its wrong axes are a problem, status 1, with the cure.
    let out = gyropath(&["check", s(&ride)]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--mount \"") && err.contains("undoes it"),
        "{err}"
    );
    // A bag's axes are re-mounted by default: the same finding is no failure.
    let out = gyropath(&["check", &format!("{HUSKY}/test1.bag")]);
    assert!(out.status.success());
    // --strict fails on the Berlin drive's warnings (its 5 Hz yaw-rate
    // sensor gives no vertical axis to check); without it, status 0.
    let berlin = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real/smartloc-berlin-potsdamer-platz/ride.csv"
    );
    assert!(gyropath(&["check", berlin]).status.success());
    assert_eq!(
        gyropath(&["check", berlin, "--strict"]).status.code(),
        Some(1)
    );

    // Every JSON output carries the tool's and the schema's versions, and
    // a setting with no limit says null, not "None".
    let fit = gyropath(&["fit", s(&ride), "--mount", "auto", "--quiet", "--json", "-"]);
    assert!(fit.status.success());
    let r: serde_json::Value = serde_json::from_slice(&fit.stdout).unwrap();
    assert_eq!(r["tool"], "gyropath");
    assert_eq!(r["tool_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(r["schema_version"], 2);
    assert!(
        r["noise"]["gps_sigma_m"]["limit"].is_null(),
        "{}",
        r["noise"]
    );
    assert!(!String::from_utf8_lossy(&fit.stdout).contains("\"None\""));
    let check = gyropath(&["check", berlin, "--json", "-"]);
    let c: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
    assert_eq!(c["schema_version"], 2);
}

#[test]
fn the_summary_gives_the_bias_the_sensor_had_not_only_its_constant_part() {
    // Berlin's yaw-rate sensor: the constant part reads 0.179 deg/s, while
    // the segments move it by -0.13 to -0.09: the bias it had is 0.05-0.09.
    let berlin = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real/smartloc-berlin-potsdamer-platz/ride.csv"
    );
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("r.json");
    let out = gyropath(&["fit", berlin, "--json", s(&report)]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("bias      total z "), "{text}");
    assert!(text.contains("gyro_bias (constant part): "), "{text}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let z = &r["bias_total"][2];
    let mean = z["mean_dps"].as_f64().unwrap();
    assert!((0.04..0.09).contains(&mean), "{z}");
    assert!(z["min_dps"].as_f64().unwrap() <= mean && mean <= z["max_dps"].as_f64().unwrap());
    // With its 1-sigma, as every other parameter: a segment's, which is the
    // total bias's over it (step 2 holds the constant part).
    let sigma = z["sigma_per_segment_dps"].as_f64().unwrap();
    assert!((0.001..0.1).contains(&sigma), "{z}");
    assert!(
        text.contains(&format!("1-sigma {sigma:.4} per segment")),
        "{text}"
    );
    assert!(
        r["bias_total"][0].is_null(),
        "a yaw-rate sensor has no roll bias"
    );
    // The JSON report holds the segment lengths' likelihoods even without
    // --verbose (they are computed only where something shows them), the
    // best at 0 and the others above it.
    let preference = r["segment_preference"].as_array().unwrap();
    assert_eq!(preference.len(), 5, "{preference:?}");
    assert!(
        preference.iter().any(|p| p[1].as_f64() == Some(0.0))
            && preference.iter().all(|p| p[1].as_f64().unwrap() >= 0.0),
        "{preference:?}"
    );
    // Without --verbose the summary does not show them.
    assert!(!text.contains("segments  "), "{text}");
}

#[test]
fn diagnose_starts_with_the_answer_and_the_command_that_adds_it() {
    let comma = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/ride.csv"
    );
    let out = gyropath(&["diagnose", comma, "--quiet"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let first = text.lines().next().unwrap_or_default();
    assert!(
        first.starts_with("missing:  gps_lag (0.0")
            && first.ends_with(&format!("add it: gyropath fit {comma} --effects gps_lag")),
        "{first}"
    );
    // Ljung-Box statistics only with --verbose.
    assert!(!text.contains("Ljung-Box"), "{text}");
    let out = gyropath(&["diagnose", comma, "--quiet", "--verbose"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("Ljung-Box"));
    // A plain fit prints no iteration lines and no -2 ln L.
    let out = gyropath(&["fit", comma]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("step 2 lm"));
    assert!(!String::from_utf8_lossy(&out.stdout).contains("-2 ln L"));
}

/// `gyropath open ARGS` with no display to open a window on.
fn open_headless(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .arg("open")
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .unwrap()
}

#[test]
fn open_without_a_file_opens_the_sample_as_its_help_says() {
    // No display here: it gets as far as the window, not to a missing argument.
    let out = open_headless(&[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("required"), "{err}");
    assert!(err.contains("cannot open the app window"), "{err}");
}

#[test]
fn open_with_a_reference_that_is_not_there_fails_before_the_window() {
    let out = open_headless(&["--reference", "no-such-truth.csv"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("reference track no-such-truth.csv: no such file"),
        "{err}"
    );
    assert!(!err.contains("app window"), "{err}");
}

#[test]
fn every_subcommands_help_has_an_example() {
    for sub in [
        "fit", "diagnose", "explain", "simulate", "import", "check", "open",
    ] {
        let out = gyropath(&[sub, "--help"]);
        assert!(out.status.success(), "{sub}");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains(&format!("Example: `gyropath {sub} ")),
            "{sub} --help: {text}"
        );
    }
}

#[test]
fn every_fit_error_names_the_gps_noise_law_it_is_measured_under() {
    let comma = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/ride.csv"
    );
    // fit: the RMS under the noise it estimated from the ride.
    let out = gyropath(&["fit", comma, "--json", "-"]);
    assert!(out.status.success());
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let law = report["gps_noise"].as_str().unwrap().to_string();
    assert!(law.starts_with("a GPS error wandering "), "{law}");
    let summary = String::from_utf8_lossy(&out.stderr);
    assert!(
        summary.contains("rms       path to the fixes") && summary.contains(&law),
        "{summary}"
    );
    // diagnose: its errors under the noise as set, and it says which.
    let out = gyropath(&["diagnose", comma, "--quiet", "--json", "-"]);
    let d: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(d["gps_noise"], "independent GPS fixes of 3.0 m");
    let out = gyropath(&["diagnose", comma, "--quiet"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("ranked under independent GPS fixes of 3.0 m: the noise as set"),
        "{text}"
    );
    // Its --help says what `auto` means for the ranking.
    let help = String::from_utf8_lossy(&gyropath(&["diagnose", "--help"]).stdout).to_string();
    assert!(
        help.contains("ranks every candidate under independent 3 m fixes"),
        "{help}"
    );
}

#[test]
fn one_flag_name_per_idea_across_subcommands() {
    for sub in ["fit", "diagnose", "check", "import", "open"] {
        let help = String::from_utf8_lossy(&gyropath(&[sub, "--help"]).stdout).to_string();
        // No placeholder default on the mounting.
        assert!(!help.contains("[default: default]"), "{sub}: {help}");
        // A second CSV of fixes is --gps-csv; --gps is simulate's GPS environment only.
        assert!(help.contains("--gps-csv"), "{sub}: {help}");
        assert!(!help.contains("--gps <"), "{sub}: {help}");
        if sub != "import" && sub != "open" {
            assert!(help.contains("--json <"), "{sub}: {help}");
            assert!(!help.contains("--report <"), "{sub}: {help}");
        }
    }
    let help = String::from_utf8_lossy(&gyropath(&["simulate", "--help"]).stdout).to_string();
    assert!(help.contains("--gps <GPS>"), "{help}");
    // The old name of fit's report still works.
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "52", "", "120");
    let report = dir.path().join("r.json");
    let out = gyropath(&["fit", s(&ride), "--quiet", "--report", s(&report)]);
    assert!(out.status.success());
    assert!(report.exists());
}

/// The path's fields of one TUM line: t x y z qx qy qz qw.
fn tum_line(line: &str) -> [f64; 8] {
    let v: Vec<f64> = line.split(' ').map(|x| x.parse().unwrap()).collect();
    v.try_into().expect("8 fields")
}

#[test]
fn the_path_keeps_the_sources_time_and_frame_and_is_written_as_tum_for_evo() {
    let dir = tempfile::tempdir().unwrap();
    let bag = format!("{HUSKY}/test1.bag");
    let (csv, tum) = (dir.path().join("p.csv"), dir.path().join("p.tum"));
    for out in [&csv, &tum] {
        let run = gyropath(&["fit", &bag, "--quiet", "--out", s(out)]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    let csv = std::fs::read_to_string(&csv).unwrap();
    let tum = std::fs::read_to_string(&tum).unwrap();
    // Both headers: the bag's start in Unix time, the frame's origin, the heading's convention.
    for text in [&csv, &tum] {
        assert!(text.contains("# t0_unix_s: 1432235498.05"), "{text:.600}");
        assert!(text.contains("# origin_lat_deg: 42.37"), "{text:.600}");
        assert!(text.contains(
            "# heading: of the sensor's forward (x) axis, degrees clockwise from true north"
        ));
    }
    let rows: Vec<&str> = csv
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .collect();
    let poses: Vec<[f64; 8]> = tum
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(tum_line)
        .collect();
    assert_eq!(rows.len(), poses.len());
    for (row, pose) in rows.iter().zip(&poses).step_by(991) {
        let f: Vec<f64> = row.split(',').map(|x| x.parse().unwrap()).collect();
        // Unix time = t0 + t_s; x, y, z = east, north, up.
        assert!(
            (pose[0] - (1_432_235_498.055_589_7 + f[0])).abs() < 1e-5,
            "{row} / {pose:?}"
        );
        for a in 0..3 {
            assert!((pose[1 + a] - f[4 + a]).abs() < 2e-3, "{row} / {pose:?}");
        }
        // A unit quaternion whose forward axis has the CSV's compass heading.
        let [_, _, _, _, x, y, z, w] = *pose;
        assert!(((x * x + y * y + z * z + w * w).sqrt() - 1.0).abs() < 1e-6);
        let east = 1.0 - 2.0 * (y * y + z * z);
        let north = 2.0 * (x * y + w * z);
        let heading = east.atan2(north).to_degrees().rem_euclid(360.0);
        let diff = (heading - f[7] + 540.0).rem_euclid(360.0) - 180.0;
        assert!(diff.abs() < 0.02, "{heading} vs {}", f[7]);
    }
    // A log without an absolute time keeps its own clock, and says so.
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "53", "", "120");
    let tum = dir.path().join("r.tum");
    assert!(
        gyropath(&["fit", s(&ride), "--quiet", "--out", s(&tum)])
            .status
            .success()
    );
    let text = std::fs::read_to_string(&tum).unwrap();
    assert!(text.contains("# time: t_s is the ride log's own clock"));
    let first = text.lines().find(|l| !l.starts_with('#')).unwrap();
    assert_eq!(tum_line(first)[0], 0.0);
}

#[test]
fn a_bad_absolute_time_in_a_log_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "54", "", "60");
    let text = std::fs::read_to_string(&ride).unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, format!("# t0_unix_s: yesterday\n{text}")).unwrap();
    let out = gyropath(&["fit", s(&bad)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        err.contains("bad.csv") && err.contains("t0_unix_s") && err.contains("yesterday"),
        "{err}"
    );
}

#[test]
fn an_error_says_whether_the_input_or_the_output_failed_and_says_it_once() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "55", "", "60");
    let missing = dir.path().join("no/such/folder/p.csv");
    // The output's missing folder is said before the fit, in words of its own.
    for (args, says, os_reason) in [
        (
            vec!["fit", s(&ride), "--quiet", "--out", s(&missing)],
            "cannot write: there is no folder",
            0,
        ),
        (vec!["fit", "no-such-ride.csv"], "cannot read", 1),
        (
            vec![
                "fit",
                s(&ride),
                "--quiet",
                "--reference",
                "no-such-truth.csv",
            ],
            "cannot read",
            1,
        ),
    ] {
        let out = gyropath(&args);
        assert_eq!(out.status.code(), Some(1));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
        assert_eq!(
            err.matches("No such file or directory").count(),
            os_reason,
            "{args:?}: {err}"
        );
    }
}

#[test]
fn explain_runs_the_whole_loop_and_its_model_carries_to_the_next_fit() {
    let comma = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/ride.csv"
    );
    let truth = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/truth.csv"
    );
    let dir = tempfile::tempdir().unwrap();
    let (path, json, model) = (
        dir.path().join("p.csv"),
        dir.path().join("e.json"),
        dir.path().join("sensor.json"),
    );
    let out = gyropath(&[
        "explain",
        comma,
        "--reference",
        truth,
        "--out",
        s(&path),
        "--json",
        s(&json),
        "--save-model",
        s(&model),
        "--quiet",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("base      "), "{text}");
    assert!(lines[1].starts_with("added     gps_lag (lag 0.0"), "{text}");
    assert!(
        lines[2].starts_with("answer    the paper's model + gps_lag: nothing more"),
        "{text}"
    );
    // Every step as JSON, with the reference error falling.
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(e["ending"]["kind"], "nothing_significant");
    let steps = e["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 2);
    let to_ref = |i: usize| {
        steps[i]["reference"]["horizontal"]["rms_m"]
            .as_f64()
            .unwrap()
    };
    assert!(
        to_ref(1) < 0.6 && to_ref(1) < to_ref(0),
        "{} -> {}",
        to_ref(0),
        to_ref(1)
    );
    assert!(steps[1]["estimate"]["lag"]["sigma"].as_f64().unwrap() > 0.0);
    // The final model's path, as fit writes it.
    assert!(
        std::fs::read_to_string(&path)
            .unwrap()
            .contains("t_s,lat_deg,lon_deg,alt_m")
    );
    // The saved model starts the next fit with gps_lag.
    let out = gyropath(&["fit", comma, "--model", s(&model), "--quiet", "--json", "-"]);
    assert!(out.status.success());
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        r["model"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m == "gps_lag"),
        "{}",
        r["model"]
    );
    // With --json - the steps go to standard error and standard output is JSON alone.
    let out = gyropath(&["explain", comma, "--quiet", "--json", "-"]);
    let e: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON alone");
    assert_eq!(e["steps"].as_array().unwrap().len(), 2);
    assert!(String::from_utf8_lossy(&out.stderr).contains("added     gps_lag"));
    // A file that is no saved model is refused, naming it.
    let out = gyropath(&["fit", comma, "--model", truth]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a model saved by"));
}

#[test]
fn a_reader_that_stops_early_ends_the_command_quietly() {
    use std::io::{BufRead, BufReader};
    let comma = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/ride.csv"
    );
    // As `gyropath explain RIDE | head -1`: the reader goes after a line.
    let mut child = Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .args(["explain", comma, "--quiet"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("base "), "{first}");
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
}

/// A reference as GPX or NMEA (UTC) measures the same as the same track as
/// CSV on the ride's clock, once the ride says when it started; without its
/// start it is refused, naming both files.
#[test]
fn gpx_and_nmea_references_are_put_on_the_rides_clock() {
    const T0: f64 = 1_600_000_000.0; // 2020-09-13 12:26:40 UTC
    let dir = tempfile::tempdir().unwrap();
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let ride_text = std::fs::read_to_string(data.join("sample-ride.csv")).unwrap();
    let ride = dir.path().join("ride.csv");
    std::fs::write(
        &ride,
        ride_text.replacen('\n', &format!("\n# t0_unix_s: {T0}\n"), 1),
    )
    .unwrap();
    // The truth at 10 Hz, three ways.
    let truth = std::fs::read_to_string(data.join("sample-ride-truth.csv")).unwrap();
    let rows: Vec<[f64; 4]> = truth
        .lines()
        .skip_while(|l| !l.starts_with("t_s"))
        .skip(1)
        .step_by(10)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect();
    let csv: String = std::iter::once("t_s,lat_deg,lon_deg,alt_m\n".to_string())
        .chain(
            rows.iter()
                .map(|r| format!("{},{},{},{}\n", r[0], r[1], r[2], r[3])),
        )
        .collect();
    // UTC calendar of a Unix time (Howard Hinnant's civil_from_days).
    let civil = |unix: f64| {
        let days = (unix / 86_400.0).floor() as i64;
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z - era * 146_097;
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        let d = doy - (153 * mp + 2) / 5 + 1;
        let m = if mp < 10 { mp + 3 } else { mp - 9 };
        let y = yoe + era * 400 + i64::from(m <= 2);
        let sod = unix - days as f64 * 86_400.0;
        let (h, mi, s) = (
            (sod / 3600.0).floor(),
            (sod % 3600.0 / 60.0).floor(),
            sod % 60.0,
        );
        (y, m, d, h, mi, s)
    };
    let gpx: String = std::iter::once(
        r#"<?xml version="1.0"?><gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>"#
            .to_string(),
    )
    .chain(rows.iter().map(|r| {
        let (y, m, d, h, mi, s) = civil(T0 + r[0]);
        format!(
            r#"<trkpt lat="{}" lon="{}"><ele>{}</ele><time>{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:06.3}Z</time></trkpt>"#,
            r[1], r[2], r[3]
        )
    }))
    .chain(std::iter::once("</trkseg></trk></gpx>".to_string()))
    .collect();
    let nmea_angle = |v: f64, pos: char, neg: char, width: usize| {
        let a = v.abs();
        let deg = a.floor();
        format!(
            "{:0width$}{:010.7},{}",
            deg as i64,
            (a - deg) * 60.0,
            if v >= 0.0 { pos } else { neg }
        )
    };
    let sentence = |body: String| format!("${body}*{:02X}\n", body.bytes().fold(0u8, |a, b| a ^ b));
    let gga: String = rows
        .iter()
        .map(|r| {
            let (y, m, d, h, mi, s) = civil(T0 + r[0]);
            sentence(format!(
                "GPGGA,{h:02}{mi:02}{s:05.2},{},{},1,12,0.8,{:.3},M,0.0,M,,",
                nmea_angle(r[1], 'N', 'S', 2),
                nmea_angle(r[2], 'E', 'W', 3),
                r[3]
            )) + &sentence(format!(
                "GPRMC,{h:02}{mi:02}{s:05.2},A,,,,,0.0,0.0,{d:02}{m:02}{:02},,,A",
                y % 100
            ))
        })
        .collect();
    let mut rms = Vec::new();
    for (name, text) in [
        ("truth.csv", &csv),
        ("truth.gpx", &gpx),
        ("truth.gga", &gga),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let json = dir.path().join(format!("{name}.json"));
        let out = gyropath(&[
            "fit",
            s(&ride),
            "--reference",
            s(&path),
            "--json",
            s(&json),
            "--quiet",
        ]);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        rms.push(r["reference"]["horizontal"]["rms_m"].as_f64().unwrap());
        assert!(
            r["reference"]["covered_s"].as_f64().unwrap() > 590.0,
            "{name}: {r}"
        );
    }
    eprintln!("to the reference as CSV, GPX, NMEA: {rms:?}");
    assert!(
        (rms[1] - rms[0]).abs() < 0.01 && (rms[2] - rms[0]).abs() < 0.01,
        "{rms:?}"
    );
    // The bundled ride has no t0_unix_s: the UTC reference is placed on
    // its clock by its track (the odometer's distance), with a warning, and
    // measures the fit as the same track on the ride's clock does (the
    // wheel pulses' timing, 0.09 s here, moves it by a few centimetres).
    let json = dir.path().join("placed.json");
    let out = gyropath(&[
        "fit",
        s(&data.join("sample-ride.csv")),
        "--reference",
        s(&dir.path().join("truth.gpx")),
        "--json",
        s(&json),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("truth.gpx") && err.contains("placed on the ride's clock by its track"),
        "{err}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let placed = r["reference"]["horizontal"]["rms_m"].as_f64().unwrap();
    assert!((placed - rms[0]).abs() < 0.1, "{placed} against {}", rms[0]);
    // A track of another place tells no clock: refused, asking for the start.
    let elsewhere = dir.path().join("elsewhere.gpx");
    std::fs::write(&elsewhere, gpx.replace("lat=\"4", "lat=\"3")).unwrap();
    let out = gyropath(&[
        "fit",
        s(&data.join("sample-ride.csv")),
        "--reference",
        s(&elsewhere),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("elsewhere.gpx") && err.contains("has no t0_unix_s"),
        "{err}"
    );
}

/// A 10 s ride cannot be validated: `diagnose` fails naming the file and
/// why (it printed a NaN held-out error and "nothing missing"), and
/// `explain` keeps the base fit, writes its path and says it is not
/// validated.
#[test]
fn a_ride_too_short_to_validate_is_told_so() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("short.csv");
    let truth = dir.path().join("truth.csv");
    let out = gyropath(&[
        "simulate",
        "--seed",
        "3",
        "--duration",
        "10",
        "--out",
        s(&ride),
        "--truth",
        s(&truth),
    ]);
    assert!(out.status.success());
    let out = gyropath(&["diagnose", s(&ride)]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(!out.status.success(), "{stdout}");
    assert!(
        stderr.contains("short.csv") && stderr.contains("too short to validate"),
        "{stderr}"
    );
    assert!(!stdout.contains("NaN") && !stdout.contains("nothing missing"));
    let path = dir.path().join("path.csv");
    let out = gyropath(&["explain", s(&ride), "--out", s(&path)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("not validated"), "{stdout}");
    assert!(!stdout.contains("NaN"), "{stdout}");
    assert!(path.exists());
}

/// `--between START,END` fits the part of a log between two times on its
/// own clock (one side of a pause), and a window that keeps nothing or is
/// not two increasing times is an error that says so.
#[test]
fn between_fits_a_part_of_the_ride_and_refuses_an_empty_or_malformed_window() {
    let dir = tempfile::tempdir().unwrap();
    let ride = dir.path().join("ride.csv");
    simulated(&ride, "4", "", "120");
    let out = gyropath(&["fit", s(&ride), "--between", "30,90"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("(6001 rows, 60 s, 61 GPS fixes)"), "{text}");
    for (window, says) in [
        (
            "500,600",
            "--between 500,600 keeps 0 row(s) of the log, which runs from 0.00 to 120.00 s",
        ),
        ("90,30", "--between '90,30': give START,END"),
        ("30", "--between '30': give START,END"),
    ] {
        let out = gyropath(&["fit", s(&ride), "--between", window]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(says),
            "{window}: {err}"
        );
    }
}

/// A reference whose recorder stopped while writing (its last line cut
/// short) measures the fit over what it holds, with a warning naming the
/// line in the terminal and the report, instead of refusing the reference
/// and with it the fit (the comma drive's own truth, cut inside a row).
#[test]
fn a_reference_cut_short_measures_the_fit_over_what_it_holds() {
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real/comma2k19-example1");
    let dir = tempfile::tempdir().unwrap();
    let truth = std::fs::read(real.join("truth.csv")).unwrap();
    let cut = dir.path().join("truth.csv");
    std::fs::write(&cut, &truth[..200_020]).unwrap();
    let report = dir.path().join("r.json");
    let out = gyropath(&[
        "fit",
        s(&real.join("ride.csv")),
        "--reference",
        s(&cut),
        "--json",
        s(&report),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("warning:") && err.contains("truth.csv:4463") && err.contains("left out"),
        "{err}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let covered = r["reference"]["covered_s"].as_f64().unwrap();
    assert!((40.0..45.0).contains(&covered), "{covered}");
    let rms = r["reference"]["horizontal"]["rms_m"].as_f64().unwrap();
    assert!(rms > 0.5 && rms < 2.0, "{rms}");
    let warned = r["warnings"].as_array().unwrap();
    assert!(
        warned
            .iter()
            .any(|w| w.as_str().unwrap().contains("truth.csv:4463")),
        "{warned:?}"
    );
}

/// A camera or phone log without GPS, and a watch's GPX of the same drive:
/// the Berlin drive's rows with their fixes emptied and no start time, and
/// its reference track as a 1 Hz GPX in UTC (2023-11-14 22:13:20 + t).
#[test]
fn a_gps_track_gives_a_log_without_gps_its_fixes_placed_by_the_turns() {
    let berlin = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz");
    let dir = tempfile::tempdir().unwrap();
    let ride = std::fs::read_to_string(berlin.join("ride.csv")).unwrap();
    let mut bare = String::new();
    let mut columns: Vec<String> = Vec::new();
    let mut fixes = Vec::new();
    for line in ride.lines() {
        if line.starts_with('#') {
            bare.push_str(line);
        } else if columns.is_empty() {
            columns = line.split(',').map(str::to_string).collect();
            bare.push_str(line);
        } else {
            let at = |name: &str| columns.iter().position(|c| c == name).unwrap();
            let mut f: Vec<&str> = line.split(',').collect();
            if !f[at("lat_deg")].is_empty() {
                fixes.push((
                    f[0].to_string(),
                    f[at("lat_deg")].to_string(),
                    f[at("lon_deg")].to_string(),
                ));
            }
            for name in ["lat_deg", "lon_deg", "gps_alt_m"] {
                f[at(name)] = "";
            }
            bare.push_str(&f.join(","));
        }
        bare.push('\n');
    }
    let gpx = |points: &mut dyn Iterator<Item = (f64, String, String)>| {
        let mut g = String::from(
            "<?xml version=\"1.0\"?>\n<gpx version=\"1.1\" creator=\"test\" xmlns=\"http://www.topografix.com/GPX/1/1\"><trk><trkseg>\n",
        );
        for (t, lat, lon) in points {
            let sod = 80_000.0 + t;
            let (h, m, sec) = (
                (sod / 3600.0).floor(),
                ((sod % 3600.0) / 60.0).floor(),
                sod % 60.0,
            );
            g.push_str(&format!(
                "<trkpt lat=\"{lat}\" lon=\"{lon}\"><time>2023-11-14T{h:02}:{m:02}:{sec:06.3}Z</time></trkpt>\n"
            ));
        }
        g.push_str("</trkseg></trk></gpx>\n");
        g
    };
    let truth = std::fs::read_to_string(berlin.join("truth.csv")).unwrap();
    let mut watch = truth
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("t_s"))
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let t: f64 = f[0].parse().ok()?;
            ((t - t.round()).abs() < 1e-6).then(|| (t, f[1].to_string(), f[2].to_string()))
        });
    let (ride_path, watch_path, city_path) = (
        dir.path().join("nogps.csv"),
        dir.path().join("watch.gpx"),
        dir.path().join("city.gpx"),
    );
    std::fs::write(&ride_path, bare).unwrap();
    std::fs::write(&watch_path, gpx(&mut watch)).unwrap();
    std::fs::write(
        &city_path,
        gpx(&mut fixes
            .into_iter()
            .map(|(t, a, b)| (t.parse().unwrap(), a, b))),
    )
    .unwrap();

    // Without a track: the error names the option.
    let out = gyropath(&["fit", s(&ride_path), "--quiet"]);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("no GPS fix") && e.contains("--gps-track"), "{e}");

    // The watch's track: placed within 0.2 s of its start (the yaw-rate
    // sensor's 5 Hz rows read 0.1 s late), and fitted close to the truth.
    let report = dir.path().join("r.json");
    let out = gyropath(&[
        "fit",
        s(&ride_path),
        "--gps-track",
        s(&watch_path),
        "--reference",
        s(&berlin.join("truth.csv")),
        "--json",
        s(&report),
    ]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stderr}");
    let placed = stderr
        .split("t0_unix_s ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("{stderr}"));
    assert!((placed - 1_700_000_000.0).abs() < 0.2, "{placed}: {stderr}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let rms = r["reference"]["horizontal"]["rms_m"]
        .as_f64()
        .unwrap_or_else(|| panic!("{}", r["reference"]));
    assert!(rms < 2.0, "{rms} m: {stdout}");

    // A batch would give every ride the same track: refused.
    let out = gyropath(&[
        "fit",
        s(&ride_path),
        s(&berlin.join("ride.csv")),
        "--gps-track",
        s(&watch_path),
    ]);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("gives one ride its fixes"), "{e}");

    // The city's own fixes, 20 m off: too noisy to read turns from,
    // refused with the way out.
    let out = gyropath(&[
        "fit",
        s(&ride_path),
        "--gps-track",
        s(&city_path),
        "--quiet",
    ]);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("turns") && e.contains("t0_unix_s:"), "{e}");
}

/// A reference whose clock is off the ride's: comma's own track written in
/// GPS time (18 s ahead of UTC, as RTK and INS tracks often are) is put on
/// the ride's clock by its track and measured as the original, saying so;
/// before, it was refused as "not of this ride" (310 m from the fixes), and
/// a slower vehicle's would have been measured tens of metres off, blaming
/// the fit. A sub-second offset is said, not applied; the reference as
/// recorded says nothing.
#[test]
fn a_reference_in_gps_time_is_placed_by_its_track_and_said() {
    let dir = tempfile::tempdir().unwrap();
    let comma = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/comma2k19-example1");
    let ride = comma.join("ride.csv");
    let text = std::fs::read_to_string(comma.join("truth.csv")).unwrap();
    let shifted = |by: f64| {
        let mut out = String::new();
        for line in text.lines() {
            match line.split_once(',') {
                Some((t, rest)) if t.parse::<f64>().is_ok() => {
                    let t: f64 = t.parse().unwrap();
                    out.push_str(&format!("{:.6},{rest}\n", t + by));
                }
                _ => {
                    out.push_str(line);
                    out.push('\n');
                }
            }
        }
        let path = dir.path().join(format!("truth-{by}.csv"));
        std::fs::write(&path, out).unwrap();
        path
    };
    let run = |reference: &Path| {
        let out = gyropath(&["fit", s(&ride), "--reference", s(reference)]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (
            String::from_utf8_lossy(&out.stdout).to_string(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    let line = |stdout: &str| {
        stdout
            .lines()
            .find(|l| l.contains("path RMS"))
            .map(str::to_string)
            .unwrap_or_default()
    };
    let (as_recorded, said) = run(&comma.join("truth.csv"));
    assert!(!said.contains("clock"), "{said}");
    let (gps_time, said) = run(&shifted(18.0));
    assert!(
        said.contains(
            "its clock is +18.00 s off the ride's (GPS time against UTC: 18 leap seconds)"
        ) && said.contains("310 m in the median"),
        "{said}"
    );
    assert_eq!(line(&gps_time), line(&as_recorded));
    assert!(
        line(&as_recorded).contains("path RMS 1.25 m"),
        "{as_recorded}"
    );
    let (_, said) = run(&shifted(0.5));
    assert!(
        said.contains("its clock may be +0.5") && said.contains("measured at its times as given"),
        "{said}"
    );
}
