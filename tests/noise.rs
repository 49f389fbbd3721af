//! Noise settings from the ride (issue 13) against simulated truth: rides
//! whose GPS error is correlated over a minute (plus white noise) and whose
//! gyro bias walks at a known density.

mod common;

use std::sync::Arc;

use gyropath::diagnosis::{Folds, diagnose};
use gyropath::import::parse;
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, SimulatedRide, TruthErrors, simulate};

const TRUE_WALK: f64 = 0.004;

fn ride(seed: u64, duration_s: f64, gps: &str) -> (SimulatedRide, Arc<Signals>) {
    let sim = simulate(&SimConfig {
        seed,
        duration_s,
        bias_walk_dps_sqrt_s: Some(TRUE_WALK),
        gps: gps.parse().expect("environment"),
        ..SimConfig::default()
    })
    .expect("simulate");
    let sig = Signals::from_log(&parse(sim.log_csv.as_bytes(), "sim.csv").expect("parse"))
        .expect("signals");
    (sim, Arc::new(sig))
}

fn truth_error(sim: &SimulatedRide, sig: &Signals, settings: FitSettings) -> f64 {
    let mut fit = Reconstruction::new(Arc::new(sig.clone()), settings).expect("fit");
    fit.finish();
    sim.errors(sig, &fit.trajectory().p).path_at_fixes_m
}

#[test]
fn default_settings_are_within_5_percent_of_the_best_swept() {
    for seed in [1, 2] {
        let (sim, sig) = ride(seed, 900.0, "open");
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for sigma in [1.5, 3.0, 6.0] {
            for walk in [0.001, 0.002, 0.004, 0.008] {
                let mut s = FitSettings {
                    auto_noise: AutoNoise::OFF,
                    ..FitSettings::default()
                };
                s.model.sigma_horizontal_m = sigma;
                s.model.bias_walk_dps_sqrt_s = Some(walk);
                let e = truth_error(&sim, &sig, s);
                if e < best.0 {
                    best = (e, sigma, walk);
                }
            }
        }
        let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
        fit.finish();
        let errors = sim.errors(&sig, &fit.trajectory().p);
        let auto = errors.path_at_fixes_m;
        let noise = fit.noise().expect("the default estimates the GPS noise");
        eprintln!(
            "seed {seed}: auto {auto:.3} m ({}), best by hand {:.3} m (sigma {} m, walk {}), fixes {:.3} m",
            noise.describe(),
            best.0,
            best.1,
            best.2,
            errors.fixes_m
        );
        // The noise the simulator used, set by hand, for comparison: on
        // seed 1 the best swept setting is a bias walk four times stiffer
        // than the truth, and the true noise itself ends 6.1 % behind it
        // (the default, with the heights' own correlation time, 4.6 %).
        let mut truth = FitSettings {
            auto_noise: AutoNoise::OFF,
            ..FitSettings::default()
        };
        truth.model.sigma_horizontal_m = 1.5;
        truth.model.gps_tau_s = Some(60.0);
        truth.model.gps_white_m = 0.5;
        truth.model.sigma_vertical_m = 3.0;
        truth.model.gps_white_vertical_m = Some(1.5);
        let true_noise = truth_error(&sim, &sig, truth);
        eprintln!("seed {seed}: under the true noise {true_noise:.3} m");
        assert!(
            auto <= 1.05 * best.0,
            "seed {seed}: {auto} m vs {} m (true noise {true_noise} m)",
            best.0
        );
        assert!(
            auto <= 0.8 * errors.fixes_m,
            "seed {seed}: {auto} m vs fixes {} m",
            errors.fixes_m
        );
        // The estimate says how sure it is: a finite range around the value.
        let s = noise.gps_sigma_m;
        assert!(s.estimated && s.low < s.value && s.value < s.high && s.high < 2.0 * s.value);
        // The simulator's GPS error is 1.5 m correlated over 60 s plus 0.5 m white
        // per axis: a single Gauss-Markov process sees the white part as a short
        // correlation time and a sigma between the two.
        assert!((0.5..2.0).contains(&s.value), "sigma {}", s.value);
        assert!(noise.gps_tau_s.value > 1.0, "tau {}", noise.gps_tau_s.value);
    }
}

#[test]
fn the_bias_walk_estimate_brackets_the_true_walk() {
    let (_, sig) = ride(3, 900.0, "open");
    let mut settings = FitSettings::default();
    settings.auto_noise.walk = true;
    let mut fit = Reconstruction::new(sig, settings).expect("fit");
    fit.finish();
    let w = fit.noise().expect("estimated").bias_walk;
    let sd = (w.high / w.value).ln();
    let off = (w.value / TRUE_WALK).ln().abs();
    eprintln!(
        "walk {:.5} ({:.5}-{:.5}) vs true {TRUE_WALK}",
        w.value, w.low, w.high
    );
    assert!(w.estimated && sd > 0.0 && sd < 1.0, "range {w:?}");
    assert!(off <= 2.0 * sd + 0.05, "walk {w:?} vs {TRUE_WALK}");
}

#[test]
fn city_rides_point_at_gps_outliers_and_the_fit_with_them_beats_the_fixes() {
    // Seeds 9 and 10 were missed while the ranking judged `gps_outliers` by
    // the base model's robust score alone (t 1.8 and 0.7): the fixes' own
    // error, 15-25 m, drowns the path's gain of 2 m. Scored as a noise
    // distribution against the base's Gaussian, every block sees it.
    for seed in [7, 9, 10] {
        let (sim, sig) = ride(seed, 1200.0, "urban");
        let d = diagnose(
            sig.clone(),
            &FitSettings::default(),
            &Folds::default(),
            &|_| {},
        )
        .expect("diagnose");
        let first = &d.ranking[0];
        eprintln!(
            "urban seed {seed}: {} first ({:+.1} %, t {:.1}, significant {})",
            first.effect,
            100.0 * first.drop,
            first.t_statistic,
            first.significant
        );
        assert_eq!(first.effect, "gps_outliers", "seed {seed}");
        assert!(first.significant, "seed {seed}");
        if seed == 7 {
            let e = fit_with_outliers(7, &sim, &sig);
            assert!(e.path_at_fixes_m <= 0.4 * e.fixes_m, "{e:?}");
        }
    }
}

#[test]
fn the_bundled_city_example_points_at_gps_outliers() {
    // What File > Examples says of it.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/city-gps.csv");
    let log = gyropath::import::load_file(&path).expect("city example");
    let sig = Arc::new(Signals::from_owned_log(log).expect("signals"));
    let d = diagnose(sig, &FitSettings::default(), &Folds::default(), &|_| {}).expect("diagnose");
    let first = &d.ranking[0];
    assert_eq!(first.effect, "gps_outliers", "{:?}", d.ranking);
    assert!(first.significant, "{first:?}");
}

/// A fit of a city ride with `gps_outliers` from the start, against the truth (printed).
fn fit_with_outliers(seed: u64, sim: &SimulatedRide, sig: &Arc<Signals>) -> TruthErrors {
    let mut settings = FitSettings::default();
    settings.model.effects.push("gps_outliers".into());
    let mut fit = Reconstruction::new(sig.clone(), settings).expect("fit");
    fit.finish();
    let e = sim.errors(sig, &fit.trajectory().p);
    eprintln!(
        "urban seed {seed}: path {:.2} m, fixes {:.2} m from the truth; {}",
        e.path_at_fixes_m,
        e.fixes_m,
        fit.noise().map_or("noise as set".into(), |n| n.describe())
    );
    e
}

#[test]
fn city_rides_fitted_with_gps_outliers_from_the_start_beat_the_fixes() {
    // Seed 9's first window, fitted under the robust loss, once settled
    // 1.7 km from the truth (seed 7 is the test above).
    for seed in [8, 9] {
        let (sim, sig) = ride(seed, 1200.0, "urban");
        let e = fit_with_outliers(seed, &sim, &sig);
        assert!(e.path_at_fixes_m <= 0.3 * e.fixes_m, "{e:?}");
    }
}

#[test]
fn the_heights_noise_is_estimated_apart_from_the_horizontal() {
    // The simulator's heights wander at 2 times the horizontal (3 m against
    // 1.5 m) over the same 60 s, and jitter at 3 times (1.5 m against 0.5 m).
    for seed in [21, 22] {
        let (_, sig) = ride(seed, 600.0, "open");
        let mut fit = Reconstruction::new(sig, FitSettings::default()).expect("fit");
        fit.finish();
        let n = fit.noise().expect("noise estimated");
        eprintln!("seed {seed}: {}", n.describe());
        let r = n.gps_vertical_ratio;
        let sd = (r.high / r.value).ln();
        assert!(r.estimated && sd > 0.0 && sd < 0.5, "{r:?}");
        assert!((r.value / 2.0).ln().abs() <= 2.0 * sd, "ratio {r:?} vs 2");
        let j = n.gps_white_vertical_m.expect("heights' own jitter");
        assert!((j / 1.5 - 1.0).abs() < 0.2, "vertical jitter {j} vs 1.5 m");
        // Their own correlation time (the simulator's is the horizontal's,
        // 60 s), with a range that holds it.
        let t = n.gps_tau_vertical_s;
        let sd = if t.value < 60.0 {
            (t.high / t.value).ln()
        } else {
            (t.value / t.low).ln()
        };
        assert!(t.estimated && sd > 0.0 && sd < 1.0, "{t:?}");
        assert!(
            (t.value / 60.0).ln().abs() <= 2.0 * sd,
            "heights' tau {t:?} vs 60 s"
        );
    }
}

#[test]
fn the_noise_search_keeps_what_is_set_by_hand() {
    let (_, sig) = common::ride(8, 300.0, &[]);
    let mut settings = FitSettings {
        auto_noise: AutoNoise::OFF,
        ..FitSettings::default()
    };
    settings.model.gps_tau_s = Some(30.0);
    let mut fit = Reconstruction::new(sig, settings).expect("fit");
    fit.finish();
    assert!(fit.noise().is_none());
    assert_eq!(fit.model().spec.gps_tau_s, Some(30.0));
    assert_eq!(fit.model().spec.sigma_horizontal_m, 3.0);
}

/// The odometer gain's sigma says how far the gain is from the truth: pooled
/// over ten simulated rides, the normalised errors `z = (gain - truth) / sigma`
/// have a median |z| near a normal's 0.67 and few beyond 3. Measured: median
/// 0.96, one ride at 6.0 (without the residual-correlation widening the
/// median was 1.34 and two rides were beyond 4): still somewhat overconfident,
/// see docs/uncertainty.md.
#[test]
fn the_gain_sigma_is_calibrated_against_the_truth() {
    let mut z = Vec::new();
    for seed in 11..21 {
        let (sim, sig) = common::ride(seed, 600.0, &[]);
        let mut fit = Reconstruction::new(sig, FitSettings::default()).expect("fit");
        fit.finish();
        let report = gyropath::export::FitReport::new(&fit, 0.0);
        let p = report.parameters["odometer_gain"]
            .iter()
            .find(|p| p.name == "gain")
            .expect("gain");
        let sigma = p.sigma.expect("the gain has a sigma");
        z.push((p.value - sim.truth.odometer_gain) / sigma);
    }
    let mut abs: Vec<f64> = z.iter().map(|v| v.abs()).collect();
    abs.sort_by(f64::total_cmp);
    let median = 0.5 * (abs[4] + abs[5]);
    eprintln!("gain z-scores {z:.2?}, median |z| {median:.2}");
    assert!((0.35..1.3).contains(&median), "median |z| {median}: {z:?}");
    assert!(abs.iter().filter(|&&a| a > 3.0).count() <= 1, "{z:?}");
}

/// The path's sigma ellipses hold the truth as often as they say when the
/// noise model describes the GPS error: pooled over simulated rides, with the
/// simulator's own error process as the noise (1.58 m per axis, correlated
/// over 60 s), the truth is inside the 95 % ellipse at 85-99 % of the rows
/// (sampled every second).
/// Under the noise estimated from the ride they hold it less often (78.7 %
/// on these rides, 76.4 % on 12; see `examples/calibration.rs` and the
/// docs/gps-noise.md): the estimated wander comes out about a fifth small.
#[test]
fn the_path_sigma_ellipses_cover_the_truth_under_the_true_noise() {
    let mut settings = FitSettings {
        auto_noise: AutoNoise::OFF,
        ..FitSettings::default()
    };
    settings.model.sigma_horizontal_m = 1.58;
    settings.model.gps_tau_s = Some(60.0);
    let (share, band) = pooled_coverage(&settings, 21..25, 600.0);
    assert!((0.85..=0.99).contains(&share), "{share}");
    // The band the map draws holds the truth about as often as it says.
    assert!((0.85..=0.99).contains(&band), "band {band}");
}

/// Issue 14's target under the default settings: the noise estimated from
/// each ride (wander, its time, jitter, the heights' own ratio and jitter).
#[test]
fn the_path_sigma_ellipses_cover_the_truth_under_the_estimated_noise() {
    let (share, band) = pooled_coverage(&FitSettings::default(), 21..25, 600.0);
    assert!((0.85..=0.99).contains(&share), "{share}");
    assert!((0.85..=0.99).contains(&band), "band {band}");
}

/// On rides of five minutes, a few of the GPS wander's correlation times,
/// the ride pins the wander's short-lag spread but hardly its time, which
/// comes out short; the band is therefore averaged over the time's 1-sigma
/// range (`ModelSpec::band_specs`). Taken as known, the estimate's band held
/// the truth at 67.3 % of these rides' rows (35-100 % by ride); averaged,
/// at 78.6 % (measured).
#[test]
fn the_band_of_a_short_ride_is_averaged_over_what_it_cannot_pin() {
    let (share, _) = pooled_coverage(&FitSettings::default(), 1..7, 300.0);
    assert!(share >= 0.75, "{share}");
}

/// The share of rows (every 100th) of the simulated rides of `seeds`,
/// `duration_s` long, whose truth lies inside the path's 95 % ellipse, and
/// inside the map's 95 % band across the track, fitted with `settings`;
/// each ride's ellipses must not shrink in its outages.
fn pooled_coverage(
    settings: &FitSettings,
    seeds: std::ops::Range<u64>,
    duration_s: f64,
) -> (f64, f64) {
    let (mut inside, mut total, mut band_inside) = (0usize, 0usize, 0usize);
    for seed in seeds {
        let (sim, sig) = common::ride(seed, duration_s, &[]);
        let mut fit = Reconstruction::new(sig.clone(), settings.clone()).expect("fit");
        fit.finish();
        let path = fit.trajectory().p;
        let u = fit.model().uncertainty(fit.params()).expect("uncertainty");
        let truth = sim.truth_in(&sig.frame);
        let (mut ride_in, mut ride_n) = (0, 0);
        let mut band_in = 0;
        let (mut out_sigma, mut out_n, mut in_sigma, mut in_n) = (0.0, 0, 0.0, 0);
        for j in (0..sig.len()).step_by(100) {
            let (de, dn) = (path[j].x - truth[j].x, path[j].y - truth[j].y);
            if u.mahalanobis2(j, de, dn) <= 5.991 {
                ride_in += 1;
            }
            // The map's 95 % band across the track (diagnosis::view::cross_band).
            if (1..sig.len() - 1).contains(&j) {
                let at = |k: usize| [sig.t[k], path[k].x, path[k].y];
                let [ve, vn, _, c] = u.path[j];
                let band = gyropath::diagnosis::view::cross_band(
                    &[at(j - 1), at(j), at(j + 1)],
                    &[[ve, vn, c]; 3],
                )[1];
                let across = de * band.normal[0] + dn * band.normal[1];
                if across.abs() <= band.half_width_m {
                    band_in += 1;
                }
            }
            ride_n += 1;
            let s = u.sigma_enu(j);
            let h = (s[0] * s[0] + s[1] * s[1]).sqrt();
            let t = sig.t[j];
            if sim
                .truth
                .gps_outages_s
                .iter()
                .any(|&(a, b)| t >= a && t < b)
            {
                out_sigma += h;
                out_n += 1;
            } else {
                in_sigma += h;
                in_n += 1;
            }
        }
        eprintln!(
            "seed {seed}: {ride_in} of {ride_n} rows inside the 95 % ellipse, {band_in} inside the 95 % band across the track; horizontal sigma {:.2} m with GPS, {:.2} m in outages",
            in_sigma / in_n.max(1) as f64,
            out_sigma / out_n.max(1) as f64
        );
        // With the error correlated over a minute, a fix barely pins the
        // path more than the fixes a minute away do: the ellipses stay about
        // as wide in an outage (measured 1.60 vs 1.53 m on seed 21), and they
        // must not shrink there.
        if out_n > 0 {
            assert!(
                out_sigma / out_n as f64 > 0.8 * in_sigma / in_n as f64,
                "seed {seed}: the ellipses shrink in outages"
            );
        }
        inside += ride_in;
        total += ride_n;
        band_inside += band_in;
    }
    let share = inside as f64 / total as f64;
    let band_share = band_inside as f64 / total as f64;
    eprintln!(
        "pooled: {:.1} % inside the 95 % ellipse, {:.1} % inside the 95 % band across the track",
        100.0 * share,
        100.0 * band_share
    );
    (share, band_share)
}

/// The segment length the data prefer: every length tried has a finite
/// likelihood relative to the best, and on a ride whose bias walks as the
/// prior says the lengths are within a few units of each other (the walk
/// prior scales with the length, so it, not the length, sets the smoothing).
#[test]
fn segment_lengths_are_compared_by_their_likelihood() {
    let (_, sig) = ride(4, 600.0, "open");
    let mut fit = Reconstruction::new(sig, FitSettings::default()).expect("fit");
    fit.finish();
    let pref = gyropath::optimisation::noise::segment_preference(fit.model(), fit.params());
    eprintln!("{pref:?}");
    assert_eq!(
        pref.len(),
        gyropath::optimisation::noise::SEGMENT_CHOICES.len()
    );
    assert!(pref.iter().all(|v| v.1.is_finite() && v.1 >= 0.0));
    assert!(pref.iter().any(|v| v.1 == 0.0));
    assert!(pref.iter().all(|v| v.1 < 10.0), "{pref:?}");
}
