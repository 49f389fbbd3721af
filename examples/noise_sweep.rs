//! Does the held-out error choose the noise settings that bring the path
//! closest to the truth? On simulated rides whose GPS error is correlated over
//! a minute (the simulator's open sky: Gauss-Markov, tau 60 s, 1.5 m per
//! axis, plus 0.5 m white) and whose gyro bias walks at a known density,
//! sweep the bias-walk prior and the GPS sigma and print, per setting, the
//! path's error against the truth at the fixes and the held-out RMS of the
//! default validation (5 folds of 60 s blocks).
//!
//! `cargo run --release --example noise_sweep -- [duration_s] [walk] [guard_s] [seeds...]`
//! (defaults: 1200 s, 0.004 deg/s/sqrt(s), no guard band, seeds 1 2 3)

use std::sync::Arc;

use gyropath::diagnosis::{Folds, held_out};
use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let duration: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1200.0);
    let walk: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(0.004);
    let guard: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(0.0);
    let folds = Folds {
        guard_s: guard,
        ..Folds::default()
    };
    let mut seeds: Vec<u64> = args.filter_map(|a| a.parse().ok()).collect();
    if seeds.is_empty() {
        seeds = vec![1, 2, 3];
    }
    let priors = [0.0005, 0.001, 0.002, 0.004, 0.008];
    let sigmas = [1.5, 3.0, 6.0];
    println!(
        "{duration:.0} s rides, true bias walk {walk} deg/s/sqrt(s), GPS error correlated over 60 s, guard band {guard} s"
    );
    println!(
        "{:>5} {:>9} {:>8} {:>10} {:>10} {:>10}",
        "seed", "prior", "sigma m", "fixes m", "path m", "held-out m"
    );
    for &seed in &seeds {
        let sim = simulate(&SimConfig {
            seed,
            duration_s: duration,
            bias_walk_dps_sqrt_s: Some(walk),
            ..SimConfig::default()
        })?;
        let sig = Arc::new(Signals::from_owned_log(parse(
            sim.log_csv.as_bytes(),
            "sweep",
        )?)?);
        let mut best_truth = (f64::INFINITY, 0.0, 0.0);
        let mut best_heldout = (f64::INFINITY, 0.0, 0.0, 0.0);
        for &sigma in &sigmas {
            for &prior in &priors {
                let mut settings = FitSettings::default();
                settings.model.bias_walk_dps_sqrt_s = Some(prior);
                settings.model.sigma_horizontal_m = sigma;
                settings.auto_noise = gyropath::optimisation::AutoNoise::OFF;
                let mut fit = Reconstruction::new(sig.clone(), settings.clone())?;
                fit.finish();
                let e = sim.errors(&sig, &fit.trajectory().p);
                let ho = held_out(fit.model(), fit.params(), &settings, &folds)?;
                let heldout = ho.rms(&vec![true; sig.fixes.len()]);
                println!(
                    "{seed:>5} {prior:>9} {sigma:>8} {:>10.2} {:>10.3} {heldout:>10.3}",
                    e.fixes_m, e.path_at_fixes_m
                );
                if e.path_at_fixes_m < best_truth.0 {
                    best_truth = (e.path_at_fixes_m, prior, sigma);
                }
                if heldout < best_heldout.0 {
                    best_heldout = (heldout, prior, sigma, e.path_at_fixes_m);
                }
            }
        }
        // The defaults (GPS noise from the ride), and with the bias walk from the ride too.
        for walk_auto in [false, true] {
            let t0 = std::time::Instant::now();
            let mut settings = FitSettings::default();
            settings.auto_noise.walk = walk_auto;
            let mut fit = Reconstruction::new(sig.clone(), settings)?;
            fit.finish();
            let e = sim.errors(&sig, &fit.trajectory().p);
            println!(
                "seed {seed}: auto{} {:.3} m from the truth ({:.2} s): {}",
                if walk_auto { " with walk" } else { "" },
                e.path_at_fixes_m,
                t0.elapsed().as_secs_f64(),
                fit.noise().map_or("no estimate".into(), |n| n.describe())
            );
        }
        println!(
            "seed {seed}: closest to the truth: prior {} sigma {} ({:.3} m); held-out picks prior {} sigma {} ({:.3} m from the truth)",
            best_truth.1,
            best_truth.2,
            best_truth.0,
            best_heldout.1,
            best_heldout.2,
            best_heldout.3
        );
    }
    Ok(())
}
