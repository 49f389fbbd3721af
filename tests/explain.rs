//! `gyropath explain` on simulated rides, as a user runs it: with one effect
//! of the catalogue hidden it adds that effect first and stops after at most
//! one more step; on a plain ride it adds nothing; with two hidden it finds
//! both. Ten-minute rides of seed 11 (over seeds 11-13 the loop was right on
//! 19 of 21 rides: seed 13 missed the temperature-driven bias and the second
//! of two hidden effects; see the closing note of issue 30).

use std::process::Command;

fn gyropath(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .args(args)
        .output()
        .expect("run gyropath")
}

/// The effects `explain` added, in order, on a simulated ride with `hidden`.
fn added(hidden: &str) -> Vec<String> {
    let dir = tempfile::tempdir().expect("temp dir");
    let ride = dir.path().join("ride.csv");
    let json = dir.path().join("steps.json");
    let out = gyropath(&[
        "simulate",
        "--seed",
        "11",
        "--duration",
        "600",
        "--hidden",
        hidden,
        "--out",
        ride.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    let out = gyropath(&[
        "explain",
        ride.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--quiet",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{out:?}");
    eprintln!("hidden [{hidden}]:\n{text}");
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(e["ending"]["kind"], "nothing_significant", "{text}");
    e["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["added"].as_str().map(str::to_string))
        .collect()
}

/// The hidden effect comes first, and at most one more follows.
fn finds_first(hidden: &str, effect: &str) {
    let added = added(hidden);
    assert_eq!(added.first().map(String::as_str), Some(effect), "{added:?}");
    assert!(added.len() <= 2, "{added:?}");
}

#[test]
fn a_plain_ride_is_explained_by_the_papers_model() {
    assert!(added("").is_empty());
}

#[test]
fn a_hidden_gps_lag_is_added_first() {
    finds_first("gps_lag", "gps_lag");
}

#[test]
fn a_hidden_gyro_scale_is_added_first() {
    finds_first("gyro_scale", "gyro_scale");
}

#[test]
fn a_hidden_mount_misalignment_is_added_first() {
    finds_first("mount_misalignment", "mount_misalignment");
}

#[test]
fn a_hidden_temperature_bias_is_added_first() {
    finds_first("gyro_bias_channel:temp_c", "gyro_bias_channel:temp_c");
}

#[test]
fn hidden_gps_outliers_are_added_first() {
    finds_first("gps_outliers", "gps_outliers");
}

#[test]
fn two_hidden_effects_are_both_found() {
    let mut added = added("gps_lag,gyro_scale");
    added.sort();
    assert_eq!(added, ["gps_lag", "gyro_scale"]);
}
