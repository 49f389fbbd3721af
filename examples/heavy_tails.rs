//! Which GPS error law a ride's own fixes prefer, and which is nearer its
//! reference (issue 28): the default (a Gaussian wander and jitter, settings
//! searched by the restricted likelihood) against independent fixes under a
//! Cauchy law whose scale is learnt from the misfits (the inlier scale apart
//! from the outliers; `optimisation::noise::heavy`), fitted with the robust
//! loss of `gps_outliers` at that scale and refitted until the scale settles.
//! Both `-2 ln L` drop the same constants, so the lower is the law the fixes
//! prefer. Rides: the shared real drives and the simulator's open-sky, urban
//! and city GPS (10 minutes, seeds 7-9). `cargo run --release --example
//! heavy_tails` (about 30 s).
use std::path::Path;
use std::sync::Arc;

use gyropath::contract::ModelSpec;
use gyropath::contract::Role;
use gyropath::diagnosis::reference::{compare, match_rows};
use gyropath::import::reference::ReferenceTrack;
use gyropath::import::{ImportOptions, open, read_reference};
use gyropath::optimisation::noise::heavy::{cauchy_neg2_log_likelihood, cauchy_scale, gps_misfits};
use gyropath::optimisation::noise::neg2_log_likelihood;
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{GpsEnvironment, SimConfig, simulate};

fn run(name: &str, signals: Arc<Signals>, reference: &ReferenceTrack) -> anyhow::Result<()> {
    let matched = match_rows(&signals, reference)?;
    // A finished fit, its path's horizontal RMS to the reference and the
    // parameters its likelihood integrates out (those of step 2).
    let fitted = |settings: FitSettings| -> anyhow::Result<(Reconstruction, f64, Vec<bool>)> {
        let mut fit = Reconstruction::new(signals.clone(), settings)?;
        fit.finish();
        let rms = compare(fit.model(), fit.params(), reference, &matched)
            .horizontal
            .rms_m;
        let free = fit
            .model()
            .free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
        Ok((fit, rms, free))
    };
    let (a, ra, free) = fitted(FitSettings::default())?;
    let base = a.model().chain_system(a.params(), &free).expect("chain");
    let la = neg2_log_likelihood(a.model(), &base, a.params(), &a.model().spec).unwrap_or(f64::NAN);
    let mis = gps_misfits(a.model(), a.params());
    let mut c = [
        cauchy_scale(&mis[0]).unwrap_or(3.0),
        cauchy_scale(&mis[1]).unwrap_or(8.0),
    ];
    let mut last = (f64::NAN, f64::NAN, f64::NAN);
    for _ in 0..3 {
        // The robust loss's scale is 2.385 sd of the weighted residual.
        let s = FitSettings {
            auto_noise: AutoNoise::OFF,
            model: ModelSpec {
                effects: vec!["paper".into(), "gps_outliers".into()],
                gps_tau_s: None,
                sigma_horizontal_m: c[0] / 2.385,
                sigma_vertical_m: c[1] / 2.385,
                ..ModelSpec::default()
            },
            ..FitSettings::default()
        };
        let (b, rb, freeb) = fitted(s)?;
        let lb = cauchy_neg2_log_likelihood(b.model(), b.params(), &freeb, c).unwrap_or(f64::NAN);
        last = (rb, lb, c[0]);
        let mis = gps_misfits(b.model(), b.params());
        c = [
            cauchy_scale(&mis[0]).unwrap_or(c[0]),
            cauchy_scale(&mis[1]).unwrap_or(c[1]),
        ];
    }
    let (rb, lb, scale) = last;
    let prefers = if la < lb { "wander" } else { "Cauchy" };
    println!("| {name} | {ra:.2} m | {la:.1} | {scale:.2} m | {rb:.2} m | {lb:.1} | {prefers} |");
    Ok(())
}

fn main() -> anyhow::Result<()> {
    println!(
        "| ride | default to ref | -2 ln L | Cauchy scale | Cauchy to ref | -2 ln L | the fixes prefer |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real");
    for drive in ["smartloc-berlin-potsdamer-platz", "comma2k19-example1"] {
        let d = real.join(drive);
        let signals =
            Arc::new(open(&d.join("ride.csv"), &ImportOptions::default())?.into_signals()?);
        run(drive, signals, &read_reference(&d.join("truth.csv"))?)?;
    }
    for (gps, name) in [
        (GpsEnvironment::Open, "open"),
        (GpsEnvironment::Urban, "urban"),
        (GpsEnvironment::City, "city"),
    ] {
        for seed in [7, 8, 9] {
            let sim = simulate(&SimConfig {
                seed,
                duration_s: 600.0,
                gps,
                ..SimConfig::default()
            })?;
            let signals = Arc::new(Signals::from_log(&sim.log("sim")?)?);
            let truth = sim.reference("truth")?;
            run(&format!("{name} {seed}"), signals, &truth)?;
        }
    }
    Ok(())
}
