//! Whether held-out validation ranks GPS error laws as a reference does
//! (issue 28, docs/real-drives.md): each law fitted to the ride, then
//! `diagnose`'s folds (5, over blocks of up to 60 s) refitted without their
//! fixes; per law the path's RMS to the reference, the median held-out
//! error, the robust held-out score (`HeldOut::block_loss` at twice the
//! first law's median misfit, summed) and the RMS over comparable fixes.
//! Rides: the shared real drives and `simulate --gps urban` and `city`
//! (10 minutes, seeds 7-10). `cargo run --release --example noise_cv`.
use std::path::Path;
use std::sync::Arc;

use gyropath::contract::ModelSpec;
use gyropath::diagnosis::reference::{compare, match_rows};
use gyropath::diagnosis::validation::{Folds, comparable_fixes, fix_errors, held_out};
use gyropath::import::reference::ReferenceTrack;
use gyropath::import::{ImportOptions, open, read_reference};
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{GpsEnvironment, SimConfig, simulate};

/// The median of the finite values.
fn median(v: &[f64]) -> f64 {
    let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The laws compared: the Gaussian wander alone, the heavy-tailed fit,
/// independent fixes of 5 and 10 m, and `gps_outliers` on 5 and 2 m.
fn laws() -> Vec<(&'static str, FitSettings)> {
    let independent = |sigma: f64, effects: &[&str]| FitSettings {
        auto_noise: AutoNoise::OFF,
        model: ModelSpec {
            effects: effects.iter().map(|e| e.to_string()).collect(),
            gps_tau_s: None,
            sigma_horizontal_m: sigma,
            ..ModelSpec::default()
        },
        ..FitSettings::default()
    };
    let auto = |tails: bool| FitSettings {
        auto_noise: AutoNoise {
            tails,
            robust_gain: false,
            ..AutoNoise::default()
        },
        ..FitSettings::default()
    };
    vec![
        ("wander", auto(false)),
        ("tails", auto(true)),
        ("ind5", independent(5.0, &["paper"])),
        ("ind10", independent(10.0, &["paper"])),
        ("rob5", independent(5.0, &["paper", "gps_outliers"])),
        ("rob2", independent(2.0, &["paper", "gps_outliers"])),
    ]
}

fn run(name: &str, signals: Arc<Signals>, reference: &ReferenceTrack) -> anyhow::Result<()> {
    let matched = match_rows(&signals, reference)?;
    let mut scale = f64::NAN;
    let mut line = format!("{name:10}");
    for (law, settings) in laws() {
        let mut fit = Reconstruction::new(signals.clone(), settings)?;
        fit.finish();
        let to_ref = compare(fit.model(), fit.params(), reference, &matched)
            .horizontal
            .rms_m;
        let ho = held_out(fit.model(), fit.params(), fit.settings(), &Folds::default())?;
        let misfits = fix_errors(fit.model(), fit.params());
        if scale.is_nan() {
            scale = 2.0 * median(&misfits);
        }
        let loss: f64 = ho.block_loss(scale).iter().sum();
        let comparable = ho.rms(&comparable_fixes(&misfits));
        line += &format!(
            " | {law} ref {to_ref:6.2} med {:6.2} loss {loss:7.1} crms {comparable:6.2}",
            median(&ho.errors)
        );
    }
    println!("{line}");
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real");
    for drive in ["smartloc-berlin-potsdamer-platz", "comma2k19-example1"] {
        let d = real.join(drive);
        let signals =
            Arc::new(open(&d.join("ride.csv"), &ImportOptions::default())?.into_signals()?);
        run(drive, signals, &read_reference(&d.join("truth.csv"))?)?;
    }
    for (gps, kind) in [
        (GpsEnvironment::Urban, "urban"),
        (GpsEnvironment::City, "city"),
    ] {
        for seed in 7..=10 {
            let sim = simulate(&SimConfig {
                seed,
                duration_s: 600.0,
                gps,
                ..SimConfig::default()
            })?;
            let signals = Arc::new(Signals::from_log(&sim.log("sim")?)?);
            let truth = sim.reference("truth")?;
            run(&format!("{kind} {seed}"), signals, &truth)?;
        }
    }
    Ok(())
}
