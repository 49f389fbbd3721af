//! Accuracy against the simulator's truth over a few seeds (numbers for the README).
//! `cargo run --release --example accuracy -- [duration_s] [seeds]`
use std::sync::Arc;

use gyropath::import::parse;
use gyropath::model::ModelSpec;
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn main() {
    let mut args = std::env::args().skip(1);
    let duration: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1200.0);
    let seeds: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(5);
    println!(
        "seed | GPS fixes vs truth | step 1 only | paper (no prior) | paper + prior | in outages: paper | prior | s"
    );
    for seed in 1..=seeds {
        let ride = simulate(&SimConfig {
            seed,
            duration_s: duration,
            ..SimConfig::default()
        })
        .unwrap();
        let sig =
            Arc::new(Signals::from_log(&parse(ride.log_csv.as_bytes(), "sim").unwrap()).unwrap());
        let mut row = Vec::new();
        let mut fixes = 0.0;
        let mut outs = Vec::new();
        let started = std::time::Instant::now();
        for (walk, step1_only) in [
            (None, true),
            (None, false),
            (Some(gyropath::model::DEFAULT_BIAS_WALK), false),
        ] {
            let settings = FitSettings {
                model: ModelSpec {
                    bias_walk_dps_sqrt_s: walk,
                    ..ModelSpec::default()
                },
                ..FitSettings::default()
            };
            let mut fit = Reconstruction::new(sig.clone(), settings).unwrap();
            while let Some(r) = fit.iterate() {
                if step1_only && r.phase_finished {
                    break;
                }
            }
            let e = ride.errors(&sig, &fit.trajectory().p);
            fixes = e.fixes_m;
            row.push(e.path_at_fixes_m);
            if !step1_only {
                outs.push(e.path_in_outages_m.unwrap_or(f64::NAN));
            }
        }
        println!(
            "{seed} | {fixes:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1}",
            row[0],
            row[1],
            row[2],
            outs[0],
            outs[1],
            started.elapsed().as_secs_f64()
        );
    }
}
