//! Degenerate rides get a clear message, never a garbage path.

use std::sync::Arc;

use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

/// A simulated ride's CSV, with each data row passed through `edit(index, fields)`
/// (columns: t_s,gx,gy,gz,distance,lat,lon,gps_alt,baro,temp); `None` drops the row.
fn edited(duration_s: f64, edit: impl Fn(usize, Vec<String>) -> Option<Vec<String>>) -> String {
    let sim = simulate(&SimConfig {
        seed: 3,
        duration_s,
        outages: false,
        ..SimConfig::default()
    })
    .expect("simulate");
    let mut out = String::new();
    let mut row = 0;
    let mut header_seen = false;
    for line in sim.log_csv.lines() {
        if line.starts_with('#') || !header_seen {
            header_seen |= !line.starts_with('#');
            out.push_str(line);
            out.push('\n');
            continue;
        }
        let fields = line.split(',').map(str::to_string).collect();
        if let Some(f) = edit(row, fields) {
            out.push_str(&f.join(","));
            out.push('\n');
        }
        row += 1;
    }
    out
}

/// Empty the GPS fields (lat, lon, altitude) of a row.
fn drop_fix(f: &mut [String]) {
    for field in &mut f[5..=7] {
        field.clear();
    }
}

/// The simulated ride with only the fixes whose count `k` (1 for the first) passes `keep`.
fn keeping_fixes(duration_s: f64, keep: impl Fn(usize) -> bool) -> String {
    let kept = std::cell::Cell::new(0usize);
    edited(duration_s, |_, mut f| {
        if !f[5].is_empty() {
            kept.set(kept.get() + 1);
            if !keep(kept.get()) {
                drop_fix(&mut f);
            }
        }
        Some(f)
    })
}

/// The message a fit of `csv` stops with.
fn refusal(csv: &str) -> String {
    let sig = match parse(csv.as_bytes(), "ride.csv").map_err(|e| e.to_string()) {
        Ok(log) => match Signals::from_log(&log) {
            Ok(s) => Arc::new(s),
            Err(e) => return e.to_string(),
        },
        Err(e) => return e,
    };
    match Reconstruction::new(sig, FitSettings::default()) {
        Ok(_) => panic!("the ride was accepted"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn all_fixes_in_one_spot_make_the_heading_unobservable() {
    let csv = edited(120.0, |_, mut f| {
        if !f[5].is_empty() {
            f[5] = "47.5".into();
            f[6] = "19.05".into();
        }
        Some(f)
    });
    let msg = refusal(&csv);
    assert!(
        msg.contains("ride.csv") && msg.contains("heading is unobservable"),
        "{msg}"
    );
}

#[test]
fn fixes_too_sparse_for_a_course_are_refused() {
    // One fix every 20 s: no two within 2.5 s of each other.
    let csv = keeping_fixes(120.0, |k| k % 20 == 1);
    let msg = refusal(&csv);
    assert!(
        msg.contains("ride.csv") && msg.contains("too sparse"),
        "{msg}"
    );
}

#[test]
fn fewer_fixes_than_parameters_is_refused_with_the_counts() {
    // Keep two consecutive fixes in twenty: 120 s of ride, 24 segments, 12 fixes.
    let csv = keeping_fixes(120.0, |k| k % 20 <= 2);
    let msg = refusal(&csv);
    assert!(
        msg.contains("ride.csv") && msg.contains("GPS fixes") && msg.contains("fewer than"),
        "{msg}"
    );
}

#[test]
fn a_ride_shorter_than_one_segment_is_refused() {
    // The first 3 s of a ride: shorter than one 5 s segment.
    let csv = edited(10.0, |row, f| (row < 300).then_some(f));
    let msg = refusal(&csv);
    assert!(msg.contains("ride.csv"), "{msg}");
    assert!(
        msg.contains("fewer than") || msg.contains("unobservable"),
        "{msg}"
    );
}

#[test]
fn a_ride_without_any_fix_is_refused() {
    let csv = edited(60.0, |_, mut f| {
        drop_fix(&mut f);
        Some(f)
    });
    let msg = refusal(&csv);
    assert!(msg.contains("no GPS fix"), "{msg}");
}
