//! The HTML report, as a user gets it: written by `fit --html`, `explain
//! --html` and a batch, then opened in a real browser (headless Chromium):
//! no console error, no request leaving the page, the plots and tables there.
//!
//! The browser part runs where Chromium is installed; `.ci/run` installs it
//! and sets `GYROPATH_BROWSER_TESTS=1`, which makes a missing browser a
//! failure instead of a skip.

use std::path::{Path, PathBuf};
use std::process::Command;

fn gyropath(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_gyropath"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .expect("run gyropath")
}

fn ok(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Chromium's executable, if there is one (`None` skips the browser part,
/// unless CI asks for it).
fn chromium() -> Option<PathBuf> {
    let found = ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            std::env::var_os("PATH").and_then(|paths| {
                std::env::split_paths(&paths)
                    .map(|p| p.join(name))
                    .find(|p| p.is_file())
            })
        });
    if found.is_none() && std::env::var_os("GYROPATH_BROWSER_TESTS").is_some() {
        panic!("GYROPATH_BROWSER_TESTS is set but no Chromium is installed");
    }
    found
}

/// What the browser made of a page: its DOM after loading, and the console
/// messages it logged (a blocked request is one).
struct Loaded {
    dom: String,
    console: Vec<String>,
}

fn load_in_browser(browser: &Path, page: &Path) -> Loaded {
    let profile = tempfile::tempdir().expect("profile dir");
    let out = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--enable-logging=stderr",
            "--v=0",
            "--dump-dom",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!(
            "file://{}",
            std::path::absolute(page).expect("absolute").display()
        ))
        .output()
        .expect("run chromium");
    assert!(out.status.success(), "chromium: {:?}", out.status);
    Loaded {
        dom: String::from_utf8_lossy(&out.stdout).into_owned(),
        console: String::from_utf8_lossy(&out.stderr)
            .lines()
            .filter(|l| l.contains(":CONSOLE"))
            .map(str::to_string)
            .collect(),
    }
}

/// Nothing in the page can make a request: no scripts, links, frames or
/// external images, fonts or styles; everything is inline.
fn assert_self_contained(html: &str) {
    let lower = html.to_ascii_lowercase();
    for forbidden in [
        "<script", "<link", "<iframe", "<img", "<object", "<embed", "@import", "url(", "src=",
        "http://", "https://",
    ] {
        // The SVG namespace is a name, not a request.
        let hits = lower
            .matches(forbidden)
            .count()
            .saturating_sub(if forbidden == "http://" {
                lower
                    .matches("xmlns=\"http://www.w3.org/2000/svg\"")
                    .count()
            } else {
                0
            });
        assert_eq!(hits, 0, "the report holds {forbidden:?}");
    }
    assert!(
        html.contains(r#"http-equiv="Content-Security-Policy" content="default-src 'none'"#),
        "the page forbids every request"
    );
}

#[test]
fn a_fit_report_is_one_offline_page_with_its_plots_and_tables() {
    let dir = tempfile::tempdir().expect("temp dir");
    let page = dir.path().join("sample.html");
    let json = dir.path().join("sample.json");
    let out = gyropath(&[
        "fit",
        "data/sample-ride.csv",
        "--reference",
        "data/sample-ride-truth.csv",
        "--html",
        page.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--quiet",
    ]);
    ok(&out);
    let html = std::fs::read_to_string(&page).expect("report written");
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_self_contained(&html);
    // Its numbers are the fit's: the JSON report's, formatted.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rms = report["stats"]["rms_horizontal_m"].as_f64().unwrap();
    assert!(
        html.contains(&format!("{rms:.3} m RMS horizontal")),
        "fit RMS {rms}"
    );
    let to_ref = report["reference"]["horizontal"]["rms_m"].as_f64().unwrap();
    assert!(
        html.contains(&format!("RMS {to_ref:.2} m")),
        "reference RMS {to_ref}"
    );
    // How often the truth lies inside the band: near 95 % when it is honest
    // (96.6 % on the sample ride).
    let at = html.find("the reference at ").expect("band coverage") + 17;
    let share: f64 = html[at..]
        .split(' ')
        .next()
        .and_then(|v| v.parse().ok())
        .expect("a share");
    assert!((85.0..=100.0).contains(&share), "{share} %");
    let gain = report["parameters"]["odometer_gain"][0]["value"]
        .as_f64()
        .unwrap();
    assert!(html.contains(&format!("{gain:.6}")), "odometer gain {gain}");
    for section in [
        "ride",
        "checks",
        "result",
        "parameters",
        "reference",
        "map",
        "residuals",
        "vertical",
        "reference-error",
        "uncertainty",
        "bias",
        "history",
        "diagnosis",
        "settings",
    ] {
        assert!(html.contains(&format!("id=\"{section}\"")), "no {section}");
    }
    // The model as `fit --model` reads it.
    let start = html.find("<pre>{").expect("the saved model") + 5;
    let end = start + html[start..].find("</pre>").unwrap();
    let model = html[start..end].replace("&quot;", "\"");
    let saved: serde_json::Value = serde_json::from_str(&model).expect("model JSON");
    assert_eq!(saved["model"]["effects"][0], "paper");

    let Some(browser) = chromium() else {
        eprintln!("no Chromium here: the report was checked without a browser");
        return;
    };
    let loaded = load_in_browser(&browser, &page);
    assert!(
        loaded.console.is_empty(),
        "console messages: {:#?}",
        loaded.console
    );
    // The browser built every figure and table.
    assert!(loaded.dom.matches("<svg").count() >= 6, "figures");
    assert!(loaded.dom.matches("<table").count() >= 5, "tables");
    assert!(loaded.dom.contains("GPS fixes") && loaded.dom.contains("95 % band"));
}

/// The console check can fail: a page that requests an image from the
/// network under the same policy is reported.
#[test]
fn the_browser_reports_a_request_that_a_page_makes() {
    let Some(browser) = chromium() else {
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let page = dir.path().join("leaky.html");
    std::fs::write(
        &page,
        r#"<!DOCTYPE html><html><head><meta charset="utf-8"><meta http-equiv="Content-Security-Policy" content="default-src 'none'; style-src 'unsafe-inline'; img-src data:"></head><body><img src="http://example.com/x.png"></body></html>"#,
    )
    .unwrap();
    let loaded = load_in_browser(&browser, &page);
    assert!(
        loaded
            .console
            .iter()
            .any(|l| l.contains("http://example.com/x.png")),
        "{:#?}",
        loaded.console
    );
}

#[test]
fn an_explain_report_holds_every_step_and_the_last_ranking() {
    let dir = tempfile::tempdir().expect("temp dir");
    let page = dir.path().join("lag.html");
    let out = gyropath(&[
        "explain",
        "data/hidden-gps-lag.csv",
        "--html",
        page.to_str().unwrap(),
        "--quiet",
    ]);
    ok(&out);
    let html = std::fs::read_to_string(&page).expect("report written");
    assert_self_contained(&html);
    let history = &html[html.find("id=\"history-table\"").expect("history table")..];
    let history = &history[..history.find("</table>").unwrap()];
    assert!(history.contains("base model"), "{history}");
    assert!(history.contains("added gps_lag (lag "), "{history}");
    assert!(history.contains("paper + gps_lag"), "{history}");
    assert!(
        html.contains("<title>Model history</title>"),
        "the history chart"
    );
    assert!(
        html.contains(r#"<table id="diagnosis-table">"#),
        "the last ranking"
    );
    assert!(html.contains("Ranked under independent GPS fixes"));
    if let Some(browser) = chromium() {
        let loaded = load_in_browser(&browser, &page);
        assert!(loaded.console.is_empty(), "{:#?}", loaded.console);
        assert!(loaded.dom.contains("Model history"));
    }
}

/// A real planar ride (the Husky robot's ROS 2 bag: heading only, no GPS
/// outage) is told in words and numbers, never as "NaN" or "-0": the
/// ranking once explained its yaw-only gyro scale as "(x NaN %, y NaN %)"
/// and the ride's outages as "0 outages ... covering -0 s".
#[test]
fn a_planar_real_ride_is_reported_without_nan_or_negative_zero() {
    let dir = tempfile::tempdir().expect("temp dir");
    let page = dir.path().join("husky.html");
    let out = gyropath(&[
        "explain",
        "../shared/real/robot_localization-test1/test1_ros2",
        "--html",
        page.to_str().unwrap(),
        "--quiet",
    ]);
    ok(&out);
    let html = std::fs::read_to_string(&page).expect("report written");
    assert!(html.contains("planar, heading only"), "a planar fit");
    assert!(html.contains("no outage longer than"), "the ride's outages");
    assert!(
        html.contains("the yaw gyro reads"),
        "the scale's explanation"
    );
    assert!(!html.contains("NaN"), "a NaN in the report");
    assert!(!html.contains("covering -0"), "a negative zero");
}

/// A check's warning is shown once, in the checks' table (the Berlin drive's
/// GPS altitude jumps by 62 m; its report once repeated that under the table).
#[test]
fn a_checks_warning_is_shown_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let page = dir.path().join("berlin.html");
    let out = gyropath(&[
        "fit",
        "../shared/real/smartloc-berlin-potsdamer-platz/ride.csv",
        "--html",
        page.to_str().unwrap(),
        "--quiet",
    ]);
    ok(&out);
    let html = std::fs::read_to_string(&page).expect("report written");
    assert_eq!(html.matches("jumps by 62 m at t = 70.1 s").count(), 1);
}

#[test]
fn a_batch_writes_a_report_per_ride_and_an_index_linking_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = gyropath(&[
        "fit",
        "data/sample-ride.csv",
        "data/hidden-gyro-scale.csv",
        "--out-dir",
        dir.path().to_str().unwrap(),
        "--quiet",
    ]);
    ok(&out);
    let index = std::fs::read_to_string(dir.path().join("index.html")).expect("index");
    assert_self_contained(&index);
    for stem in ["sample-ride", "hidden-gyro-scale"] {
        let href = format!("{stem}-report.html");
        assert!(index.contains(&format!("href=\"{href}\"")), "{index}");
        // minijinja's HTML escaping writes `/` as `&#x2f;`.
        let page = std::fs::read_to_string(dir.path().join(&href))
            .expect("ride report")
            .replace("&#x2f;", "/");
        assert!(page.contains(&format!("gyropath report: data/{stem}.csv")));
    }
    assert!(index.contains("m to the fixes (under "));
    if let Some(browser) = chromium() {
        let loaded = load_in_browser(&browser, &dir.path().join("index.html"));
        assert!(loaded.console.is_empty(), "{:#?}", loaded.console);
        assert_eq!(loaded.dom.matches("-report.html\"").count(), 2);
    }
}

#[test]
fn a_report_must_be_named_html_and_is_checked_before_the_fit() {
    let out = gyropath(&["fit", "data/sample-ride.csv", "--html", "report.txt"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("report.txt") && err.contains(".html"), "{err}");
    assert!(
        !Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("report.txt")
            .exists()
    );
}
