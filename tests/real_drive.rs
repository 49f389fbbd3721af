//! A real drive: one minute of the comma2k19 example segment (data/comma2k19-example1,
//! MIT licence), fitted with the paper's model and compared with comma's own
//! fused reference trajectory.

use std::path::Path;
use std::sync::Arc;

use gyropath::effects::DEG_PER_RAD;
use gyropath::geodesy::Geodetic;
use gyropath::import::load_file;
use gyropath::optimisation::{FitSettings, Limit, Reconstruction};
use gyropath::signals::Signals;
use nalgebra::Vector3;

fn data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/comma2k19-example1")
        .join(name)
}

/// The reference path in the ride's local frame, one point per row.
fn reference(sig: &Signals) -> Vec<Vector3<f64>> {
    let text = std::fs::read_to_string(data("truth.csv")).expect("truth.csv");
    let mut rdr = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    rdr.records()
        .map(|r| {
            let r = r.expect("row");
            let v = |i: usize| r[i].parse::<f64>().expect("number");
            sig.frame.to_enu(&Geodetic::new(v(1), v(2), v(3)))
        })
        .collect()
}

fn horizontal_rms(a: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (p, q) in a {
        s += (p.x - q.x).powi(2) + (p.y - q.y).powi(2);
        n += 1;
    }
    (s / n as f64).sqrt()
}

/// `gyropath diagnose` of `sig` with the default settings and folds.
fn diagnosed(sig: Arc<Signals>) -> gyropath::diagnosis::Diagnosis {
    gyropath::diagnosis::diagnose(
        sig,
        &FitSettings::default(),
        &gyropath::diagnosis::Folds::default(),
        &|_: &str| {},
    )
    .expect("diagnose")
}

#[test]
fn paper_model_recovers_the_yaw_bias_and_beats_the_raw_fixes() {
    let log = load_file(&data("ride.csv")).expect("load");
    let sig = Arc::new(Signals::from_log(&log).expect("signals"));
    let truth = reference(&sig);
    assert_eq!(truth.len(), sig.len());

    let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
    fit.finish();
    let m = fit.model();
    let bias = &fit.params()[m.range(m.effect_index("gyro_bias").expect("gyro_bias"))];
    let yaw_bias = bias[2] * DEG_PER_RAD;
    let path = fit.trajectory().p;

    let fixes = horizontal_rms(
        sig.fixes
            .iter()
            .map(|f| (Vector3::new(f.en[0], f.en[1], 0.0), truth[f.row])),
    );
    let at_fixes = horizontal_rms(sig.fixes.iter().map(|f| (path[f.row], truth[f.row])));
    let everywhere = horizontal_rms(path.iter().copied().zip(truth.iter().copied()));
    eprintln!(
        "yaw bias {yaw_bias:.3} deg/s; fixes {fixes:.3} m, path at fixes {at_fixes:.3} m, path at all rows {everywhere:.3} m from the reference"
    );
    // comma's own calibration says -3.917 deg/s; a constant-bias fit to the GPS course -3.885.
    assert!((yaw_bias + 3.9).abs() < 0.1, "yaw bias {yaw_bias} deg/s");
    assert!(
        (1.2..1.9).contains(&fixes),
        "fixes {fixes} m from the reference"
    );
    assert!(at_fixes < fixes, "path {at_fixes} m vs fixes {fixes} m");
    // A minute cannot tell a GPS error correlated over minutes from one
    // correlated over hours: the correlation time is a lower bound, never
    // a number longer than the drive with a tight range.
    let noise = fit.noise().expect("noise estimated");
    eprintln!("{}", noise.describe());
    let tau = noise.gps_tau_s;
    assert!(tau.value <= 61.0, "{tau:?}");
    assert!(tau.limit == Limit::AtLeast || tau.high <= 61.0, "{tau:?}");
    assert!(everywhere < fixes, "path {everywhere} m vs fixes {fixes} m");

    // The fixes are stamped on arrival, about 0.08 s after the reference
    // (data README): with gps_lag the path comes much closer to it.
    let mut settings = FitSettings::default();
    settings.model.effects.push("gps_lag".into());
    let mut lagged = Reconstruction::new(sig.clone(), settings).expect("fit");
    lagged.finish();
    let m = lagged.model();
    let lag = lagged.params()[m.range(m.effect_index("gps_lag").expect("gps_lag")).start];
    let path = lagged.trajectory().p;
    let with_lag = horizontal_rms(path.iter().copied().zip(truth.iter().copied()));
    eprintln!("with gps_lag: lag {lag:.3} s, path {with_lag:.3} m from the reference");
    assert!((0.03..0.15).contains(&lag), "lag {lag} s");
    assert!(
        with_lag < 0.6 * everywhere,
        "{with_lag} m vs {everywhere} m"
    );
    // Issue 13's target: diagnosed, the significant effect added and
    // refitted, the path stays within 0.6 m of comma's reference.
    assert!(with_lag < 0.6, "{with_lag} m from the reference");
}

#[test]
fn diagnose_runs_on_a_one_minute_drive_and_points_at_the_gps_latency() {
    let log = load_file(&data("ride.csv")).expect("load");
    let sig = Arc::new(Signals::from_log(&log).expect("signals"));
    let d = diagnosed(sig);
    assert!(
        d.folds.block_s < 10.0,
        "blocks fitted to the minute: {:?}",
        d.folds
    );
    let best = &d.ranking[0];
    eprintln!(
        "{}: {:+.1} % ({})",
        best.effect,
        100.0 * best.drop,
        best.explanation
    );
    assert_eq!(best.effect, "gps_lag");
    assert!(best.drop > 0.1);
}

/// The receiver of the same minute loses its fix for 10 s (20-30 s) and
/// writes its last one again every second, as many receivers and the apps
/// behind them do: the repeats are left out as an outage, and the path
/// stays as near comma's reference as with the fixes whole (1.25 m).
/// Read as fixes, they took it to 17 m off, reported as a success (the
/// noise search read a 57 m GPS wander into the ride to fit them).
#[test]
fn a_receiver_that_repeats_its_last_fix_for_ten_seconds_is_an_outage() {
    let mut log = load_file(&data("ride.csv")).expect("load");
    let first = log.t_s.partition_point(|&t| t < 20.0);
    let end = log.t_s.partition_point(|&t| t < 30.0);
    let had = (0..first).rev().find_map(|j| log.fix[j]).expect("a fix");
    let alt = log
        .gps_alt_m
        .as_ref()
        .and_then(|a| a[..first].iter().rev().flatten().next().copied());
    let mut repeated = 0;
    for j in first..end {
        if log.fix[j].is_some() {
            log.fix[j] = Some(had);
            if let Some(a) = log.gps_alt_m.as_mut() {
                a[j] = alt;
            }
            repeated += 1;
        }
    }
    assert!(repeated >= 9, "{repeated}");
    let sig = Arc::new(Signals::from_log(&log).expect("signals"));
    assert!(
        sig.warnings
            .iter()
            .any(|w| w.contains(&format!("{repeated} GPS fixes repeat the fix before"))),
        "{:?}",
        sig.warnings
    );
    assert!(sig.fixes.iter().all(|f| f.t < 20.0 || f.t >= 30.0));
    let truth = reference(&sig);
    let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
    fit.finish();
    let path = fit.trajectory().p;
    let rms = horizontal_rms(path.iter().copied().zip(truth.iter().copied()));
    eprintln!("stale fixes: path {rms:.3} m from the reference");
    assert!(rms < 1.4, "{rms} m from the reference");
}

/// The same minute's 1 Hz fixes logged at 2 Hz, each written again half a
/// second later (a logger that samples its receiver faster than it makes
/// fixes): every repeat is a logger's and left out, and the path is the
/// one of the fixes as logged once. Read as fixes, half of them half a
/// second late took the path from 1.25 m to 5.74 m off the reference,
/// reported as a success.
#[test]
fn a_receiver_logged_at_twice_its_rate_is_read_as_its_fixes() {
    let once = load_file(&data("ride.csv")).expect("load");
    let mut log = once.clone();
    let mut last: Option<(usize, f64)> = None;
    for j in 0..log.len() {
        if log.fix[j].is_some() {
            last = Some((j, log.t_s[j]));
        } else if let Some((k, _)) = last.filter(|&(_, t)| log.t_s[j] - t >= 0.5) {
            log.fix[j] = log.fix[k];
            if let Some(a) = log.gps_alt_m.as_mut() {
                a[j] = a[k];
            }
            last = None;
        }
    }
    assert!(
        log.fix_count() >= 2 * once.fix_count() - 2,
        "{}",
        log.fix_count()
    );
    let fitted = |log: &gyropath::import::RideLog| {
        let sig = Arc::new(Signals::from_log(log).expect("signals"));
        let truth = reference(&sig);
        let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
        fit.finish();
        let path = fit.trajectory().p;
        let rms = horizontal_rms(path.iter().copied().zip(truth.iter().copied()));
        (sig, rms)
    };
    let (sig, rms) = fitted(&log);
    let (sig_once, rms_once) = fitted(&once);
    assert_eq!(sig.fixes, sig_once.fixes);
    assert!(
        sig.warnings
            .iter()
            .any(|w| w.contains("faster than the receiver makes them")),
        "{:?}",
        sig.warnings
    );
    eprintln!("fixes logged twice: path {rms:.3} m from the reference ({rms_once:.3} m once)");
    assert_eq!(rms, rms_once);
}

/// The gyro of the same minute stops answering for 10 s (20-30 s), its
/// rows written as zeros or as its last reading held, as a logger that
/// loses its IMU writes them: the stop is found, the turn across it fitted
/// (`gyro_stops`), and the path stays as near comma's reference as with
/// the gyro whole (1.25 m). Before, the zeros ended in a fit refused as
/// "not physical" (a start tilt of 53 deg standing in for them).
#[test]
fn a_gyro_that_stops_answering_for_ten_seconds_is_bridged() {
    let whole = load_file(&data("ride.csv")).expect("load");
    for held in [false, true] {
        let mut log = whole.clone();
        let first = log.t_s.partition_point(|&t| t < 20.0);
        let end = log.t_s.partition_point(|&t| t < 30.0);
        let value = if held {
            log.gyro_dps[first - 1]
        } else {
            [0.0; 3]
        };
        for g in &mut log.gyro_dps[first..end] {
            *g = value;
        }
        let sig = Arc::new(Signals::from_log(&log).expect("signals"));
        assert_eq!(sig.gyro_stops.len(), 1, "held {held}: {:?}", sig.gyro_stops);
        let (a, b) = sig.gyro_stops[0];
        assert!(
            (a - 20.0).abs() < 0.02 && (b - 30.0).abs() < 0.02,
            "{a}-{b}"
        );
        let truth = reference(&sig);
        let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
        fit.finish();
        assert!(fit.model().effect_index("gyro_stops").is_some());
        let broken = gyropath::limits::check(fit.model(), fit.params());
        assert!(broken.is_empty(), "held {held}: {broken:?}");
        let path = fit.trajectory().p;
        let rms = horizontal_rms(path.iter().copied().zip(truth.iter().copied()));
        eprintln!("held {held}: path {rms:.3} m from the reference");
        assert!(rms < 1.4, "held {held}: {rms} m from the reference");
        // Diagnosed, the GPS latency is still what is missing: the fixes
        // inside the stop are not scored (their predictions are how the
        // free turns were drawn without them).
        let d = diagnosed(sig);
        let best = &d.ranking[0];
        eprintln!("held {held}: {} {:+.1} %", best.effect, 100.0 * best.drop);
        assert_eq!(best.effect, "gps_lag", "held {held}");
        assert!(best.significant, "held {held}: {best:?}");
    }
}

/// The logger of the same minute drops its rows for 10 s (20-30 s), as a
/// phone app sent to the background or an SD card's write stall does: the
/// gap is filled with rows at the log's rate and the turn across it
/// fitted (`gyro_stops`, two pieces: no fix inside tells more). Outside
/// the gap the path stays near comma's reference (1.18 m; 1.48 m with the
/// rotation interpolated across one step, as before).
#[test]
fn ten_seconds_of_rows_lost_are_filled_and_the_turn_across_them_fitted() {
    let whole = load_file(&data("ride.csv")).expect("load");
    let mut log = whole.clone();
    let first = log.t_s.partition_point(|&t| t <= 20.0);
    let end = log.t_s.partition_point(|&t| t < 30.0);
    log.drop_rows(first..end);
    let sig = Arc::new(Signals::from_log(&log).expect("signals"));
    assert_eq!(sig.log_gaps.len(), 1, "{:?}", sig.log_gaps);
    // Bridged as a gyro stop, to the last row filled.
    assert_eq!(sig.gyro_stops.len(), 1);
    let ((a, b), (c, d)) = (sig.log_gaps[0], sig.gyro_stops[0]);
    assert!(a == c && d < b && b - d < 0.02, "{a}-{b} bridged {c}-{d}");
    assert!(
        sig.warnings
            .iter()
            .any(|w| w.contains("1 gap(s) in the log") && w.contains("rows are filled")),
        "{:?}",
        sig.warnings
    );
    // Filled at the log's rate: about as many rows as were lost.
    let filled = sig.len() - log.len();
    assert_eq!(sig.filled_rows(), filled);
    assert!(
        (filled as f64 - (end - first) as f64).abs() < 0.05 * (end - first) as f64,
        "{filled} rows filled for {} lost",
        end - first
    );
    let truth = reference(&Signals::from_log(&whole).expect("signals"));
    let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
    fit.finish();
    let broken = gyropath::limits::check(fit.model(), fit.params());
    assert!(broken.is_empty(), "{broken:?}");
    // The path's rows outside the gap are the log's own, in order.
    let path = fit.trajectory().p;
    let outside: Vec<Vector3<f64>> = (0..sig.len())
        .filter(|&j| sig.t[j] <= a || sig.t[j] >= b)
        .map(|j| path[j])
        .collect();
    let kept: Vec<Vector3<f64>> = (0..whole.len())
        .filter(|&j| j < first || j >= end)
        .map(|j| truth[j])
        .collect();
    assert_eq!(outside.len(), kept.len());
    let rms = horizontal_rms(outside.into_iter().zip(kept));
    eprintln!("rows lost for 10 s: path {rms:.3} m from the reference outside the gap");
    assert!(rms < 1.35, "{rms} m from the reference");
}
