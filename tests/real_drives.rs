//! Every real drive in `../shared/real` that has a reference `truth.csv`,
//! run as a user runs it: the default fit, then the workflow of the app's
//! Diagnose and Add buttons (diagnose, add the top significant effect, refit,
//! until nothing significant is left), each measured against the drive's
//! reference. The table it prints is the README's "Real drives" table.
//!
//! The drives and their licences: `comma2k19-example1` (comma.ai, MIT) and
//! `smartloc-berlin-potsdamer-platz` (TU Chemnitz, CC BY-SA 4.0; only the
//! first 140 s of its reference are shared, the rest is kept back to check
//! that nothing is tuned to it).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use gyropath::diagnosis::reference::{self, Matched, ReferenceComparison};
use gyropath::diagnosis::{Diagnosis, Folds, diagnose_fitted_against};
use gyropath::import::reference::ReferenceTrack;
use gyropath::import::{ImportOptions, read_reference};
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::{Fix, Signals};

fn shared_real() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real")
}

/// Drives with a ride log and a reference, by folder name.
fn drives() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(shared_real())
        .expect("../shared/real")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("ride.csv").is_file() && p.join("truth.csv").is_file())
        .collect();
    out.sort();
    out
}

struct Drive {
    signals: Arc<Signals>,
    /// What `gyropath check` says of the log.
    verdicts: Vec<gyropath::import::Verdict>,
    reference: ReferenceTrack,
    matched: Matched,
}

fn open(folder: &Path) -> Drive {
    let imported =
        gyropath::import::open(&folder.join("ride.csv"), &ImportOptions::default()).expect("ride");
    let verdicts = imported.check.verdicts.clone();
    let signals = Arc::new(imported.into_signals().expect("signals"));
    let reference = read_reference(&folder.join("truth.csv")).expect("truth.csv");
    let matched = reference::match_rows(&signals, &reference).expect("matched");
    Drive {
        signals,
        verdicts,
        reference,
        matched,
    }
}

fn fit(d: &Drive, settings: FitSettings) -> (Reconstruction, ReferenceComparison) {
    let mut f = Reconstruction::new(d.signals.clone(), settings).expect("fit");
    f.finish();
    let c = reference::compare(f.model(), f.params(), &d.reference, &d.matched);
    (f, c)
}

/// The app's Diagnose of `current`, fitted under `settings`, with the
/// drive's reference.
fn diagnose(d: &Drive, current: &Reconstruction, settings: &FitSettings) -> Diagnosis {
    diagnose_fitted_against(
        current.model(),
        current.params(),
        settings,
        &Folds::default(),
        Some((&d.reference, &d.matched)),
        &|_: &str| {},
    )
    .expect("diagnose")
}

/// What the app's Diagnose and Add do, until nothing significant is left:
/// the effects added, in order, and the last fit against the reference.
fn workflow(d: &Drive) -> (Vec<String>, ReferenceComparison) {
    let mut settings = FitSettings::default();
    let (mut current, mut c) = fit(d, settings.clone());
    let mut added = Vec::new();
    for _ in 0..4 {
        let diagnosis = diagnose(d, &current, &settings);
        let Some(top) = diagnosis.ranking.first().filter(|c| c.significant) else {
            break;
        };
        added.push(top.effect.clone());
        settings.model.effects.push(top.effect.clone());
        (current, c) = fit(d, settings.clone());
    }
    (added, c)
}

/// What the sensors allow: the paper's model with a constant bias (no
/// segments) fitted to the reference itself, taken as 0.1 m fixes at the
/// rows of the GPS fixes it covers.
fn dead_reckoning_floor(d: &Drive) -> ReferenceComparison {
    let mut s: Signals = (*d.signals).clone();
    let at: std::collections::HashMap<usize, nalgebra::Vector3<f64>> =
        d.matched.at_rows.iter().copied().collect();
    s.fixes = s
        .fixes
        .iter()
        .filter_map(|f| {
            let r = at.get(&f.row)?;
            Some(Fix {
                en: [r.x, r.y],
                up: None,
                baro: None,
                hacc: None,
                vacc: None,
                hdop: None,
                ..f.clone()
            })
        })
        .collect();
    let floor = Drive {
        signals: Arc::new(s),
        verdicts: Vec::new(),
        reference: d.reference.clone(),
        matched: Matched {
            at_rows: d.matched.at_rows.clone(),
        },
    };
    let mut settings = FitSettings {
        auto_noise: AutoNoise::OFF,
        ..FitSettings::default()
    };
    settings.model.effects = vec!["paper".into(), "-gyro_bias_segments".into()];
    settings.model.sigma_horizontal_m = 0.1;
    fit(&floor, settings).1
}

#[test]
fn real_drives_against_their_references() {
    let drives = drives();
    assert!(
        drives.len() >= 2,
        "real drives with a reference: {drives:?}"
    );
    let mut table = vec![
        "| drive | covered | GPS fixes | default | workflow (added) | dead-reckoning floor |"
            .to_string(),
        "| --- | --- | --- | --- | --- | --- |".to_string(),
    ];
    for folder in &drives {
        let name = folder.file_name().unwrap().to_string_lossy().into_owned();
        let d = open(folder);
        let (default_fit, default) = fit(&d, FitSettings::default());
        let (added, after) = workflow(&d);
        let floor = dead_reckoning_floor(&d);
        let fixes = default.fixes.expect("fixes covered by the reference");
        table.push(format!(
            "| {name} | {:.0} of {:.0} s | {:.2} m | {:.2} m | {:.2} m ({}) | {:.2} m |",
            default.covered_s,
            default.ride_s,
            fixes.rms_m,
            default.horizontal.rms_m,
            after.horizontal.rms_m,
            if added.is_empty() {
                "nothing significant".to_string()
            } else {
                added.join(", ")
            },
            floor.horizontal.rms_m
        ));
        // Every drive: the default path beats the fixes it was fitted to, and
        // the workflow never makes the path worse than the default by more
        // than noise.
        assert!(
            default.horizontal.rms_m < fixes.rms_m,
            "{name}: default {} m vs fixes {} m",
            default.horizontal.rms_m,
            fixes.rms_m
        );
        assert!(
            after.horizontal.rms_m < 1.05 * default.horizontal.rms_m,
            "{name}: workflow {} m vs default {} m",
            after.horizontal.rms_m,
            default.horizontal.rms_m
        );
        assert!(floor.horizontal.rms_m < default.horizontal.rms_m);
        let odometer: Vec<String> = d
            .verdicts
            .iter()
            .filter(|v| v.subject == "odometer")
            .map(|v| format!("{}: {}", v.level.label(), v.message))
            .collect();
        match name.as_str() {
            // The real-drives issue's comma target: after the workflow within 0.6 m.
            "comma2k19-example1" => {
                assert!(after.horizontal.rms_m < 0.6, "{name}: {after:?}");
                assert_eq!(added.first().map(String::as_str), Some("gps_lag"));
            }
            // Berlin: city fixes 20 m off. The default target, 0.35 x
            // the fixes (measured 6.28 m against 20.33 m: the odometer gain
            // held at the heavy-tailed fit's); its workflow target, 0.25 x,
            // is not met yet (docs/real-drives.md). No odometer warning from
            // a noisy GPS track.
            "smartloc-berlin-potsdamer-platz" => {
                assert!(
                    default.horizontal.rms_m < 0.35 * fixes.rms_m,
                    "{name}: {default:?}"
                );
                // A noisy city track is longer than the road; that is no
                // odometer fault (it read 0.728 m per GPS m before).
                assert!(
                    odometer.iter().all(|v| v.starts_with("ok")),
                    "{name}: {odometer:?}"
                );
                // Nor a warning that no gyro axis follows the GPS course:
                // over stretches as long as the fixes' scatter asks, the car's
                // yaw rate does (15 m chords read R^2 0.05, noise).
                let vertical: Vec<String> = d
                    .verdicts
                    .iter()
                    .filter(|v| v.subject.starts_with("vertical axis"))
                    .map(|v| format!("{}: {}: {}", v.level.label(), v.subject, v.message))
                    .collect();
                assert!(
                    vertical
                        .iter()
                        .any(|v| v.starts_with("ok: vertical axis: +z points up")),
                    "{name}: {vertical:?}"
                );
                assert!(
                    vertical
                        .iter()
                        .all(|v| v.starts_with("ok") || v.starts_with("info")),
                    "{name}: {vertical:?}"
                );
                let m = default_fit.model();
                let bias = m.range(m.effect_index("gyro_bias").expect("gyro_bias"));
                let fixed = m.fixed_mask();
                assert!(
                    fixed[bias.start] && fixed[bias.start + 1],
                    "a yaw-rate sensor gets no roll or pitch bias"
                );
            }
            _ => {}
        }
    }
    eprintln!("{}", table.join("\n"));
}

/// The Gaussian law alone (`--gps-tails off`): no gain checked.
fn gaussian_alone() -> FitSettings {
    FitSettings {
        auto_noise: AutoNoise {
            robust_gain: false,
            ..AutoNoise::default()
        },
        ..FitSettings::default()
    }
}

/// `--gps-tails auto` on the real drives: the Student-t wander is chosen by
/// the innovations' likelihood on both and lowers the error to the
/// reference against the Gaussian law alone (measured: Berlin 9.34 -> 7.85
/// m, comma 1.24 -> 0.93 m); the rule sees no reference.
#[test]
fn heavy_tails_learnt_from_the_real_drives_bring_them_nearer_their_references() {
    for folder in drives() {
        let name = folder.file_name().unwrap().to_string_lossy().into_owned();
        let d = open(&folder);
        let (_, gaussian) = fit(&d, gaussian_alone());
        let heavy = FitSettings {
            auto_noise: AutoNoise {
                tails: true,
                ..AutoNoise::default()
            },
            ..FitSettings::default()
        };
        let (fitted, tails) = fit(&d, heavy);
        let summary = fitted
            .noise()
            .and_then(|n| n.gps_tails.clone())
            .expect("the innovations ask for heavy tails");
        eprintln!(
            "{name}: Gaussian {:.2} m, tails {:.2} m ({})",
            gaussian.horizontal.rms_m,
            tails.horizontal.rms_m,
            summary.describe()
        );
        assert!(
            tails.horizontal.rms_m < 0.9 * gaussian.horizontal.rms_m,
            "{name}: {} m with the tails against {} m",
            tails.horizontal.rms_m,
            gaussian.horizontal.rms_m
        );
        assert!(summary.nu < 5.0 && summary.rounds >= 1, "{summary:?}");
    }
}

/// Asking for the tails after a finished fit (the app's checkbox) ends
/// where a fit that asked from the start does: the same weights, the same
/// path within centimetres.
#[test]
fn tails_asked_for_after_the_fit_end_where_a_fresh_fit_does() {
    let folder = shared_real().join("smartloc-berlin-potsdamer-platz");
    let d = open(&folder);
    let heavy = FitSettings {
        auto_noise: AutoNoise {
            tails: true,
            ..AutoNoise::default()
        },
        ..FitSettings::default()
    };
    let (fresh, fresh_ref) = fit(&d, heavy.clone());
    let mut later = Reconstruction::new(d.signals.clone(), FitSettings::default()).expect("fit");
    later.finish();
    later.apply_settings(heavy).expect("settings");
    later.finish();
    let later_ref = reference::compare(later.model(), later.params(), &d.reference, &d.matched);
    let rounds = |f: &Reconstruction| f.noise().and_then(|n| n.gps_tails.clone());
    eprintln!(
        "fresh {:.3} m {:?}; later {:.3} m {:?}",
        fresh_ref.horizontal.rms_m,
        rounds(&fresh),
        later_ref.horizontal.rms_m,
        rounds(&later)
    );
    assert!(
        (fresh_ref.horizontal.rms_m - later_ref.horizontal.rms_m).abs() < 0.1,
        "fresh {} m, later {} m",
        fresh_ref.horizontal.rms_m,
        later_ref.horizontal.rms_m
    );
}

/// The default checks the odometer gain against the heavy-tailed fit
/// (`optimisation::noise::calibration`): on Berlin least squares reads
/// 1.0385 +- 0.0139 against the heavy-tailed 1.0086 +- 0.0144 (the CAN speed
/// fitted to the reference: 0.992), Hausman's test 7.7 sigma, so the robust
/// gain is held and the path ends 6.28 m from the reference instead of 9.34
/// m; on the comma drive the heavy-tailed fit is no less precise, the test
/// says nothing and the Gaussian fit stands to the digit.
#[test]
fn the_default_holds_the_heavy_tailed_gain_where_least_squares_strays() {
    for folder in drives() {
        let name = folder.file_name().unwrap().to_string_lossy().into_owned();
        let d = open(&folder);
        let (plain, plain_ref) = fit(&d, gaussian_alone());
        let (checked, checked_ref) = fit(&d, FitSettings::default());
        let checks = checked.noise().expect("noise").calibration.clone();
        let [gain] = &checks[..] else {
            panic!("{name}: {checks:?}");
        };
        eprintln!(
            "{name}: Gaussian alone {:.2} m, default {:.2} m; gain {:.4} +- {:.4} against {:.4} ({:+.2} sigma), held {}",
            plain_ref.horizontal.rms_m,
            checked_ref.horizontal.rms_m,
            gain.gaussian,
            gain.gaussian_sigma,
            gain.robust,
            gain.shift(),
            gain.held
        );
        match name.as_str() {
            "smartloc-berlin-potsdamer-platz" => {
                let h = gain
                    .hausman()
                    .expect("the heavy-tailed fit is less precise");
                assert!(gain.held && h > 10.83 && gain.shift() < 0.0, "{gain:?}");
                assert!((0.99..1.02).contains(&gain.robust), "{gain:?}");
                assert!(
                    checked_ref.horizontal.rms_m < 0.75 * plain_ref.horizontal.rms_m,
                    "{name}: {} m against {} m",
                    checked_ref.horizontal.rms_m,
                    plain_ref.horizontal.rms_m
                );
                // The held gain is reported with the heavy-tailed fit's sigma.
                let report = gyropath::export::FitReport::new(&checked, 0.0);
                let g = &report.parameters["odometer_gain"][0];
                assert!(g.held && !g.fixed && g.sigma.is_some(), "{g:?}");
                assert!(g.describe().contains("held"), "{}", g.describe());
            }
            _ => {
                assert!(!gain.held, "{gain:?}");
                assert_eq!(checked.params(), plain.params(), "{name}");
            }
        }
    }
}

/// `diagnose --reference` reads what the user gets: the model's error to
/// the reference is that of the fit the user holds, and each candidate's
/// that of the model with it added, fitted as `gyropath fit` fits it. Under
/// the ranking's noise as set, Berlin's column read 9.11 m for the model
/// and 6.73 m with `gps_outliers`, where the user's fits are 6.28 m and
/// 9.19 m.
#[test]
fn the_diagnosis_measures_against_the_reference_what_fit_gives() {
    let d = open(&shared_real().join("smartloc-berlin-potsdamer-platz"));
    let settings = FitSettings::default();
    let (current, held) = fit(&d, settings.clone());
    let diagnosis = diagnose(&d, &current, &settings);
    let base = diagnosis
        .reference
        .as_ref()
        .expect("the model's comparison");
    assert!(
        (base.horizontal.rms_m - held.horizontal.rms_m).abs() < 1e-9,
        "{} vs {}",
        base.horizontal.rms_m,
        held.horizontal.rms_m
    );
    for c in &diagnosis.ranking {
        let mut with = settings.clone();
        with.model.effects.push(c.effect.clone());
        let (_, added) = fit(&d, with);
        let column = c.reference.as_ref().expect("a candidate's comparison");
        eprintln!(
            "{}: column {:.2} m, fit {:.2} m",
            c.effect, column.horizontal.rms_m, added.horizontal.rms_m
        );
        assert!(
            (column.horizontal.rms_m - added.horizontal.rms_m).abs() < 1e-6,
            "{}: {} vs {}",
            c.effect,
            column.horizontal.rms_m,
            added.horizontal.rms_m
        );
    }
}
