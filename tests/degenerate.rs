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

/// Every fix in one spot: where the odometer stands too, the heading is
/// unobservable; where it moves on, the receiver never had a fix and wrote
/// one position again and again, and the refusal says so.
#[test]
fn all_fixes_in_one_spot_make_the_heading_unobservable() {
    let one_spot = |moving: bool| {
        edited(120.0, move |_, mut f| {
            if !f[5].is_empty() {
                f[5] = "47.5".into();
                f[6] = "19.05".into();
            }
            if !moving {
                f[4] = "0".into();
            }
            Some(f)
        })
    };
    let msg = refusal(&one_spot(false));
    assert!(
        msg.contains("ride.csv") && msg.contains("heading is unobservable"),
        "{msg}"
    );
    let msg = refusal(&one_spot(true));
    assert!(
        msg.contains("ride.csv")
            && msg.contains("the log has 1 GPS fix; at least two are needed (120 GPS fixes repeat the fix before to the bit while the vehicle moves on"),
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

/// The path and its misfit of a fit of `csv`, with the signals' warnings.
fn fitted(csv: &str) -> (Vec<[f64; 3]>, f64, Vec<String>) {
    let log = parse(csv.as_bytes(), "ride.csv").expect("parse");
    let sig = Arc::new(Signals::from_log(&log).expect("signals"));
    let warnings = sig.warnings.clone();
    let mut rec = Reconstruction::new(sig, FitSettings::default()).expect("fit");
    rec.finish();
    let path = rec.trajectory().p.iter().map(|p| [p.x, p.y, p.z]).collect();
    (path, rec.stats().rms_horizontal_m, warnings)
}

/// The largest horizontal distance (m) between two paths, row by row.
fn farthest_apart(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0, f64::max)
}

/// Asserts that `gyropath check` of `csv` has a verdict on `subject` whose
/// message contains `text`.
fn check_says(csv: &str, subject: &str, text: &str) {
    let check = gyropath::import::checks::check(&parse(csv.as_bytes(), "ride.csv").expect("parse"));
    assert!(
        check
            .verdicts
            .iter()
            .any(|v| v.subject == subject && v.message.contains(text)),
        "{check:?}"
    );
}

/// A receiver's gross blunders (`0, 0` while it has no fix, one fix 1.1 km
/// off, a run of four 3.3 km off) are left out before the fit, which then
/// is the fit of the ride without them, to the digit, and says so on the
/// first one's line. Kept, they made it fail ("not physical") or, one
/// alone, took its path from 3 m to 70 m off the fixes.
#[test]
fn gross_gps_blunders_are_left_out_as_if_never_logged() {
    let blunder = |k: usize| matches!(k, 30..=32 | 60 | 100..=103);
    let first_row = std::cell::Cell::new(None);
    let kept = std::cell::Cell::new(0usize);
    let with = edited(300.0, |row, mut f| {
        if !f[5].is_empty() {
            kept.set(kept.get() + 1);
            let k = kept.get();
            if blunder(k) && first_row.get().is_none() {
                first_row.set(Some(row));
            }
            let lat: f64 = f[5].parse().expect("lat");
            match k {
                30..=32 => (f[5], f[6]) = ("0.0".into(), "0.0".into()),
                60 => f[5] = format!("{:.8}", lat + 0.01),
                100..=103 => f[5] = format!("{:.8}", lat - 0.03),
                _ => {}
            }
        }
        Some(f)
    });
    let without = keeping_fixes(300.0, |k| !blunder(k));
    // 1-based: the comments, the header, then the data rows.
    let comments = with.lines().take_while(|l| l.starts_with('#')).count();
    let line = first_row.get().expect("a blunder") + comments + 2;
    left_out_as_if_never_logged(
        &with,
        &without,
        &format!(
            "8 GPS fixes left out as blunders: 3 at 0, 0 (a receiver's placeholder while it has no fix); 5 up to 3.3 km off the track, farther than 100 m/s moves between fixes (the first on line {line}"
        ),
    );
}

/// The fit of `with` is the fit of `without` to the digit (and near its
/// fixes), and the fit's warnings and the check say `said`.
fn left_out_as_if_never_logged(with: &str, without: &str, said: &str) {
    let (path, rms, warnings) = fitted(with);
    let (clean, clean_rms, _) = fitted(without);
    let worst = farthest_apart(&path, &clean);
    assert!(worst < 1e-9, "paths {worst} m apart");
    assert_eq!(rms, clean_rms);
    assert!(rms < 10.0, "{rms} m from the fixes");
    assert!(
        warnings.iter().any(|w| w.contains(said)),
        "{warnings:?}\n{said}"
    );
    check_says(with, "GPS blunders", said);
}

/// A receiver that loses its fix and writes its last one again, once a
/// second for ten seconds while the bicycle rides on: the repeats are left
/// out, and the fit is the fit of the ride logged with those rows empty, to
/// the digit, and says so on the first repeat's line. Read as fixes, ten
/// such seconds on the comma car drive took its path from 1.25 m to 17 m
/// off the reference, reported as a success.
#[test]
fn a_receivers_stale_fixes_are_left_out_as_if_never_logged() {
    let stale = |k: usize| (101..=110).contains(&k);
    let last: std::cell::RefCell<Vec<String>> = std::cell::RefCell::new(Vec::new());
    let first_row = std::cell::Cell::new(None);
    let kept = std::cell::Cell::new(0usize);
    let with = edited(300.0, |row, mut f| {
        if !f[5].is_empty() {
            kept.set(kept.get() + 1);
            if stale(kept.get()) {
                if first_row.get().is_none() {
                    first_row.set(Some(row));
                }
                f[5..=7].clone_from_slice(&last.borrow());
            } else {
                *last.borrow_mut() = f[5..=7].to_vec();
            }
        }
        Some(f)
    });
    let without = keeping_fixes(300.0, |k| !stale(k));
    let comments = with.lines().take_while(|l| l.starts_with('#')).count();
    let line = first_row.get().expect("a stale fix") + comments + 2;
    left_out_as_if_never_logged(
        &with,
        &without,
        &format!(
            "10 GPS fixes repeat the fix before to the bit while the vehicle moves on (the longest run from line {line}"
        ),
    );
}

/// A logger that writes its last fix on every row (at the gyro's 100 Hz)
/// gives the path of the same ride logged with empty fields between fixes,
/// to the digit, and says so. Read as 30,000 fixes, the 5-minute ride took
/// 16 s and 227 MB to fail as "not physical".
#[test]
fn a_loggers_held_fix_on_every_row_is_read_as_the_fixes_it_holds() {
    let last: std::cell::RefCell<Option<Vec<String>>> = std::cell::RefCell::new(None);
    let held = edited(300.0, |_, mut f| {
        if f[5].is_empty() {
            if let Some(gps) = last.borrow().as_ref() {
                f[5..=7].clone_from_slice(gps);
            }
        } else {
            *last.borrow_mut() = Some(f[5..=7].to_vec());
        }
        Some(f)
    });
    let logged = edited(300.0, |_, f| Some(f));
    let (path, rms, warnings) = fitted(&held);
    let (clean, clean_rms, _) = fitted(&logged);
    assert_eq!(path, clean);
    assert_eq!(rms, clean_rms);
    assert!(
        warnings.iter().any(|w| w
            .contains("repeats the one before (a logger that writes its last fix on every row, or faster than the receiver makes them)")),
        "{warnings:?}"
    );
}

/// A log whose `t_s` is in milliseconds (a logger's own clock unit) is
/// refused as far too slow a gyro, and told why: the column reads as a
/// gyro at the usual rate in milliseconds.
#[test]
fn a_time_column_in_milliseconds_is_named_as_such() {
    let csv = edited(60.0, |_, mut f| {
        let t: f64 = f[0].parse().expect("t_s");
        f[0] = format!("{:.0}", 1000.0 * t);
        Some(f)
    });
    let msg = refusal(&csv);
    assert!(
        msg.contains("ride.csv")
            && msg.contains(
                "Column 't_s' looks like milliseconds (read so, the gyro runs at 100 Hz)"
            )
            && msg.contains("[time] unit = \"ms\""),
        "{msg}"
    );
}

/// A log that pauses (a logger stopped, an auto-pause) for longer than the
/// gyro can be carried across is refused on the pause's line, with the
/// `--between` windows of either side; each side then fits as a ride of
/// its own. Across a 10-minute pause the fit took 122 s to end 13 m from
/// its fixes, as a success.
#[test]
fn a_pause_in_the_log_is_refused_with_the_windows_either_side() {
    let paused = edited(240.0, |_, mut f| {
        let t: f64 = f[0].parse().expect("t_s");
        if t >= 120.0 {
            f[0] = format!("{:.2}", t + 600.0);
        }
        Some(f)
    });
    let msg = refusal(&paused);
    let comments = paused.lines().take_while(|l| l.starts_with('#')).count();
    let line = 12_000 + comments + 2;
    assert!(
        msg.contains(&format!(
            "the log pauses for 600 s after t = 119.99 s (line {line})"
        )) && msg.contains("--between 0,119.99 and --between 720,840"),
        "{msg}"
    );
    // `gyropath check` says the same.
    check_says(&paused, "pause", "--between 0,119.99");
    // The first side, as --between keeps it, is the ride's first two minutes.
    let mut log = parse(paused.as_bytes(), "ride.csv").expect("parse");
    log.keep_rows(0..12_000);
    let first = parse(
        edited(240.0, |row, f| (row < 12_000).then_some(f)).as_bytes(),
        "ride.csv",
    )
    .expect("parse");
    assert_eq!((&log.t_s, &log.fix), (&first.t_s, &first.fix));
}

/// A cumulative odometer zeroed half-way through the real comma drive (a
/// trip meter reset, a logger restarting) runs on across the reset: the
/// path is the unedited drive's to the millimetre, and the fit and the
/// check both name the reset's line. Read as distance, the 517 m step back
/// made the fit fail as "not physical" (odometer gain 1.38, the sensor
/// upside down) while the check read the odometer as fine.
#[test]
fn an_odometer_reset_mid_ride_is_no_distance() {
    let drive = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/ride.csv"
    ))
    .expect("the bundled comma drive");
    let lines: Vec<&str> = drive.lines().collect();
    let header = lines
        .iter()
        .position(|l| l.starts_with("t_s"))
        .expect("a header");
    let column = lines[header]
        .split(',')
        .position(|c| c == "odo_m")
        .expect("odo_m");
    let rows = lines.len() - header - 1;
    let reset_at = header + 1 + rows / 2;
    let odo = |i: usize| -> f64 {
        lines[i]
            .split(',')
            .nth(column)
            .and_then(|f| f.parse().ok())
            .expect("odo_m")
    };
    let (before, base) = (odo(reset_at - 1), odo(reset_at));
    let mut reset = String::new();
    for (i, line) in lines.iter().enumerate() {
        if i >= reset_at {
            let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
            if let Ok(o) = f[column].parse::<f64>() {
                f[column] = format!("{:.3}", o - base);
            }
            reset.push_str(&f.join(","));
        } else {
            reset.push_str(line);
        }
        reset.push('\n');
    }
    let (path, rms, warnings) = fitted(&reset);
    let (clean, clean_rms, _) = fitted(&drive);
    let worst = farthest_apart(&path, &clean);
    assert!(worst < 0.01, "paths {worst} m apart");
    assert!(
        (rms - clean_rms).abs() < 0.001,
        "{rms} against {clean_rms} m"
    );
    let said =
        format!("the odometer jumps 1 time by more than a vehicle moves (up to -{before:.1} m");
    let line = format!("the first on line {}, column 'odo_m'", reset_at + 1);
    assert!(
        warnings
            .iter()
            .any(|w| w.contains(&said) && w.contains(&line)),
        "{warnings:?}\n{said}\n{line}"
    );
    check_says(&reset, "odometer jumps", &line);
}

/// The path of a fitted log, row by row, with its RMS from the fixes.
fn fitted_log(log: &gyropath::ride::RideLog) -> (Vec<[f64; 3]>, f64) {
    let sig = Arc::new(Signals::from_log(log).expect("signals"));
    let mut rec = Reconstruction::new(sig, FitSettings::default()).expect("fit");
    rec.finish();
    let path = rec.trajectory().p.iter().map(|p| [p.x, p.y, p.z]).collect();
    (path, rec.stats().rms_horizontal_m)
}

/// A recording split into chapters (a GoPro's 4 GB files), each with its
/// clock starting again at zero, joined as `gyropath` joins a GoPro
/// recording's chapters (`import::chapters::append`: one sample step after
/// the last sample) is the unsplit ride: the real comma drive cut in two,
/// its second half's clock restarted, fits to the unsplit path within a
/// centimetre. Fitted apart, the second half starts from an unknown
/// heading, and the ride's path breaks at the seam.
#[test]
fn chapters_of_one_recording_joined_fit_as_the_unsplit_ride() {
    let drive = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/data/comma2k19-example1/ride.csv"
    ))
    .expect("the bundled comma drive");
    let whole = parse(&drive, "ride.csv").expect("parse");
    let n = whole.len();
    let mut first = whole.clone();
    first.keep_rows(0..n / 2);
    let mut second = whole.clone();
    second.keep_rows(n / 2..n);
    let start = second.t_s[0];
    for t in &mut second.t_s {
        *t -= start;
    }
    let mut joined = first;
    gyropath::import::chapters::append(&mut joined, second, "GX020001.MP4").expect("append");
    assert_eq!(joined.len(), n);
    assert!(joined.t_s.windows(2).all(|w| w[1] > w[0]));
    // The seam falls within a sample step of where the drive had it.
    let seam = (joined.t_s[n / 2] - whole.t_s[n / 2]).abs();
    assert!(seam < 0.005, "the seam is {seam} s off");
    let (path, rms) = fitted_log(&joined);
    let (clean, clean_rms) = fitted_log(&whole);
    let worst = farthest_apart(&path, &clean);
    assert!(worst < 0.01, "paths {worst} m apart");
    assert!(
        (rms - clean_rms).abs() < 0.001,
        "{rms} against {clean_rms} m"
    );
}
