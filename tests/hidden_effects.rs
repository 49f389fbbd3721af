//! `diagnose` on simulated rides with an effect hidden from the paper's model:
//! the missing effect must come out on top, and adding it must lower the
//! held-out error and the error against the true path and recover the hidden value.

mod common;

use std::sync::Arc;

use gyropath::diagnosis::{Diagnosis, Folds, diagnose};
use gyropath::model::ModelSpec;
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::SimulatedRide;

const MINUTES: f64 = 15.0;

fn settings(effects: &[&str]) -> FitSettings {
    FitSettings {
        model: ModelSpec {
            effects: effects.iter().map(|s| s.to_string()).collect(),
            ..ModelSpec::default()
        },
        ..FitSettings::default()
    }
}

/// Path error against the truth of a full fit, RMS over all rows: horizontal and 3-D.
fn truth_error(sim: &SimulatedRide, sig: &Arc<Signals>, effects: &[&str]) -> (f64, f64) {
    let mut fit = Reconstruction::new(sig.clone(), settings(effects)).expect("fit");
    fit.finish();
    truth_error_of(sim, sig, &fit)
}

/// [`truth_error`] of a finished fit.
fn truth_error_of(sim: &SimulatedRide, sig: &Arc<Signals>, fit: &Reconstruction) -> (f64, f64) {
    let path = fit.trajectory().p;
    let truth = sim.truth_in(&sig.frame);
    let d3 = path
        .iter()
        .zip(&truth)
        .map(|(p, t)| (p - t).norm_squared())
        .sum::<f64>()
        / path.len() as f64;
    (sim.errors(sig, &path).path_all_m, d3.sqrt())
}

struct Case {
    sim: SimulatedRide,
    sig: Arc<Signals>,
    diagnosis: Diagnosis,
}

fn case(seed: u64, hidden: &[&str], model: &[&str]) -> Case {
    let (sim, sig) = common::ride(seed, MINUTES * 60.0, hidden);
    let diagnosis = diagnose(
        sig.clone(),
        &settings(model),
        &Folds::default(),
        &|_: &str| {},
    )
    .expect("diagnose");
    let top: Vec<String> = diagnosis
        .ranking
        .iter()
        .take(3)
        .map(|c| {
            format!(
                "{} {:.3} m ({:+.1} %, t {:.1}, {})",
                c.effect,
                c.heldout_rms_m,
                100.0 * c.drop,
                c.t_statistic,
                if c.significant { "significant" } else { "-" }
            )
        })
        .collect();
    eprintln!(
        "seed {seed} hidden {hidden:?} model {model:?}: held-out {:.3} m; {}",
        diagnosis.heldout_rms_m,
        top.join("; ")
    );
    Case {
        sim,
        sig,
        diagnosis,
    }
}

/// The hidden effect ranks first, significant, with a clearly lower held-out
/// error, a lower error against the truth; returns its estimate for the caller to check.
fn found(c: &Case, effect: &str, model: &[&str]) -> std::collections::BTreeMap<String, f64> {
    let best = &c.diagnosis.ranking[0];
    assert_eq!(best.effect, effect, "ranking {:?}", c.diagnosis.ranking);
    assert!(best.significant, "{best:?}");
    assert!(best.drop > 0.05, "held-out drop {}", best.drop);
    assert!(!best.explanation.is_empty());
    let with: Vec<&str> = model.iter().copied().chain([effect]).collect();
    let (before, after) = (
        truth_error(&c.sim, &c.sig, model),
        truth_error(&c.sim, &c.sig, &with),
    );
    eprintln!(
        "  truth error horizontal {:.3} m -> {:.3} m, 3-D {:.3} m -> {:.3} m",
        before.0, after.0, before.1, after.1
    );
    assert!(after.1 < before.1, "truth error {before:?} -> {after:?}");
    best.estimate
        .iter()
        .map(|(k, e)| (k.clone(), e.value))
        .collect()
}

/// The structure correlation of `quantity` with `signal` in the paper's fit (printed).
fn correlation(c: &Case, quantity: &str, signal: &str) -> f64 {
    let k = c
        .diagnosis
        .structure
        .iter()
        .find(|k| k.quantity == quantity && k.signal == signal)
        .unwrap_or_else(|| panic!("no {quantity} ~ {signal} in the structure"));
    eprintln!("  {quantity} ~ {signal}: r = {:.2}", k.r);
    k.r
}

fn within(value: f64, truth: f64, rel: f64) -> bool {
    (value - truth).abs() <= rel * truth.abs()
}

#[test]
fn gps_lag_is_found_and_its_lag_recovered() {
    for seed in [41, 42] {
        let c = case(seed, &["gps_lag"], &["paper"]);
        // The paper's fit leaves the lag's signature: a late fix sits behind
        // the path by speed x lag, so the along-track residual follows speed.
        let along = correlation(&c, "along", "speed");
        assert!(along < -0.3, "along-track residual ~ speed: r = {along}");
        let est = found(&c, "gps_lag", &["paper"]);
        let truth = c.sim.truth.gps_lag_s.expect("lag");
        eprintln!("  lag {:.3} s (truth {truth:.3} s)", est["lag"]);
        assert!(
            within(est["lag"], truth, 0.2),
            "lag {} vs {truth}",
            est["lag"]
        );
    }
}

#[test]
fn gyro_scale_is_found_and_the_yaw_factor_recovered() {
    // Within 20 % on nine of ten seeds (docs/diagnosis.md). Seed 44 is the exception,
    // kept here because it is: its bias walk and GPS noise look like a
    // +0.8 % yaw scale error even with the true one removed, so the fit
    // lands 21 % short; its reported sigma (jackknife) covers that.
    for (seed, tolerance) in [(43, 0.2), (44, 0.25)] {
        let c = case(seed, &["gyro_scale"], &["paper"]);
        let est = found(&c, "gyro_scale", &["paper"]);
        let truth = c.sim.truth.gyro_scale.expect("scale")[2] * 100.0;
        let z = est["scale_error_z"];
        eprintln!("  yaw scale error {z:.3} % (truth {truth:.3} %)");
        assert!(within(z, truth, tolerance), "z scale {z} % vs {truth} %");
    }
}

/// Hidden outliers: `diagnose` puts `gps_outliers` first, and its robust
/// loss beats the default's Gaussian law. A fit that learns heavy tails of
/// its own (`--gps-tails auto`: Student-t, where the innovations ask for
/// them) takes the outliers better still (seeds 45, 46: 1.78 and 1.34 m from
/// the truth, against 2.07 and 1.54 m with the robust loss and 2.29 and
/// 1.78 m Gaussian).
#[test]
fn gps_outliers_are_found() {
    for seed in [45, 46] {
        let c = case(seed, &["gps_outliers"], &["paper"]);
        let best = &c.diagnosis.ranking[0];
        assert_eq!(best.effect, "gps_outliers", "{:?}", c.diagnosis.ranking);
        assert!(best.significant && best.drop > 0.05, "{best:?}");
        let gaussian = truth_error(&c.sim, &c.sig, &["paper"]);
        let robust = truth_error(&c.sim, &c.sig, &["paper", "gps_outliers"]);
        let heavy = FitSettings {
            auto_noise: AutoNoise {
                tails: true,
                ..AutoNoise::default()
            },
            ..settings(&["paper"])
        };
        let mut fit = Reconstruction::new(c.sig.clone(), heavy).expect("fit");
        fit.finish();
        let tails = fit
            .noise()
            .and_then(|n| n.gps_tails.clone())
            .expect("the fit learns the outliers' tails");
        let with_tails = truth_error_of(&c.sim, &c.sig, &fit);
        eprintln!(
            "  truth error horizontal: Gaussian {:.3} m, gps_outliers {:.3} m, tails ({}) {:.3} m",
            gaussian.0,
            robust.0,
            tails.describe(),
            with_tails.0
        );
        assert!(robust.1 < gaussian.1, "{robust:?} against {gaussian:?}");
        assert!(with_tails.1 < robust.1, "{with_tails:?} against {robust:?}");
        assert!(tails.nu < 10.0 && tails.down_weighted > 0, "{tails:?}");
    }
}

#[test]
fn a_clean_ride_fitted_under_the_robust_loss_keeps_to_its_path() {
    // Seed 67 (open sky, nothing hidden): step 1 widened a window whose dead
    // reckoning started 40 m off, and under the Cauchy loss, which hardly
    // pulls at fixes that far, settled 146 m from them. Every window is now
    // reached by least squares first.
    let (sim, sig) = common::ride(67, MINUTES * 60.0, &[]);
    let (plain, _) = truth_error(&sim, &sig, &["paper"]);
    let (robust, _) = truth_error(&sim, &sig, &["paper", "gps_outliers"]);
    eprintln!("seed 67 from the truth: plain {plain:.2} m, robust {robust:.2} m");
    assert!(
        robust <= 1.2 * plain + 0.1,
        "robust {robust} vs plain {plain}"
    );
}

#[test]
fn two_hidden_effects_are_found_one_after_the_other() {
    let c = case(47, &["gps_lag", "gyro_scale"], &["paper"]);
    let first = c.diagnosis.ranking[0].effect.clone();
    assert!(
        first == "gps_lag" || first == "gyro_scale",
        "first {first}: {:?}",
        c.diagnosis.ranking
    );
    found(&c, &first, &["paper"]);
    let second = if first == "gps_lag" {
        "gyro_scale"
    } else {
        "gps_lag"
    };
    let c2 = case(47, &["gps_lag", "gyro_scale"], &["paper", &first]);
    found(&c2, second, &["paper", &first]);
}

#[test]
fn nothing_is_significant_without_a_hidden_effect() {
    for seed in [48, 49] {
        let c = case(seed, &[], &["paper"]);
        for cand in &c.diagnosis.ranking {
            assert!(!cand.significant, "{cand:?}");
        }
    }
}

#[test]
fn mount_misalignment_is_found_and_the_forward_axis_recovered() {
    for seed in [50, 52] {
        let c = case(seed, &["mount_misalignment"], &["paper"]);
        let est = found(&c, "mount_misalignment", &["paper"]);
        let m = c.sim.truth.mount_misalignment_deg.expect("mount");
        let mount = nalgebra::UnitQuaternion::from_euler_angles(
            m[0].to_radians(),
            m[1].to_radians(),
            m[2].to_radians(),
        );
        let truth = mount.inverse() * nalgebra::Vector3::x();
        let (fitted, _) = gyropath::effects::mount_misalignment::forward_axis(
            est["forward_yaw"].to_radians(),
            est["forward_pitch"].to_radians(),
        );
        let off = truth.angle(&nalgebra::Vector3::x()).to_degrees();
        let miss = truth.angle(&fitted).to_degrees();
        eprintln!(
            "  forward axis {off:.2} deg off the sensor x axis, recovered within {miss:.2} deg"
        );
        assert!(
            miss < 0.2 * off,
            "forward axis recovered within {miss} deg of {off} deg"
        );
    }
}

#[test]
fn a_temperature_driven_bias_is_found_and_its_yaw_coefficient_recovered() {
    // The simulated logger warms at stops and in sunshine and cools when
    // riding (src/simulation/thermal.rs): the bias moves faster than the
    // random walk of the segment biases can follow, so adding the channel
    // lowers the held-out error inside the ride.
    for seed in [51, 53] {
        let c = case(seed, &["gyro_bias_channel:temp_c"], &["paper"]);
        let est = found(&c, "gyro_bias_channel:temp_c", &["paper"]);
        let truth = c.sim.truth.temp_coefficient_dps_per_c.expect("coefficient")[2];
        let z = est["slope_z"];
        eprintln!("  yaw temperature coefficient {z:.4} deg/s/C (truth {truth:.4})");
        assert!(within(z, truth, 0.2), "z coefficient {z} vs {truth}");
        correlation(&c, "bias_z", "temp_c");
    }
}

/// A plain minute that stays level enough to be fitted planar, on a road
/// that climbs, with a barometer: the planar path does not climb, and its
/// held-out error is horizontal, so neither a mounting pitch nor a
/// barometer drift (each would stand in for the grade) is called missing.
/// Before, the held-out error counted the barometer's vertical misfit here,
/// and a 0.75 deg mounting pitch and a barometer drift came out at t 3.7.
#[test]
fn a_planar_ride_up_a_grade_is_not_told_its_sensor_is_pitched() {
    let (_sim, sig) = common::ride(11, 60.0, &[]);
    assert!(sig.attitude.is_planar(), "{:?}", sig.attitude);
    assert!(sig.has_baro);
    let d =
        diagnose(sig, &settings(&["paper"]), &Folds::default(), &|_: &str| {}).expect("diagnose");
    for cand in &d.ranking {
        eprintln!(
            "{} {:+.1} % t {:.1}",
            cand.effect,
            100.0 * cand.drop,
            cand.t_statistic
        );
        assert!(!cand.significant, "{cand:?}");
    }
    let mount = d
        .ranking
        .iter()
        .find(|c| c.effect == "mount_misalignment")
        .expect("mount_misalignment ranked");
    assert!(mount.drop < 0.02, "{mount:?}");
}
