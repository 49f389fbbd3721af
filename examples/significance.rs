//! How often does `diagnose` call an effect significant, with and without one
//! hidden? For simulated rides (15 minutes, the simulator's open-sky GPS:
//! error correlated over a minute) with each catalogue effect hidden, plain
//! rides and city rides, print the top candidate, its held-out drop, the
//! paired t statistics of the per-block scores and whether the rule fires;
//! for plain rides the largest drop and t of any candidate (a false alarm).
//!
//! `cargo run --release --example significance -- [estimated]`: with
//! `estimated`, the candidates are ranked under the GPS noise estimated from
//! the ride instead of the noise as set.

use std::sync::Arc;

use gyropath::diagnosis::{Diagnosis, Folds, diagnose_fitted};
use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn run(seed: u64, hidden: &[&str], gps: &str, estimated: bool) -> anyhow::Result<Diagnosis> {
    let sim = simulate(&SimConfig {
        seed,
        duration_s: if gps == "urban" { 1200.0 } else { 900.0 },
        hidden: hidden.iter().map(|s| s.to_string()).collect(),
        gps: gps.parse().map_err(anyhow::Error::msg)?,
        ..SimConfig::default()
    })?;
    let sig = Arc::new(Signals::from_owned_log(parse(
        sim.log_csv.as_bytes(),
        "sim",
    )?)?);
    let mut fit = Reconstruction::new(sig, FitSettings::default())?;
    fit.finish();
    let mut settings = fit.settings().clone();
    if estimated {
        settings.model = fit.model().spec.clone();
    }
    Ok(diagnose_fitted(
        fit.model(),
        fit.params(),
        &settings,
        &Folds::default(),
        &|_| {},
    )?)
}

fn main() -> anyhow::Result<()> {
    let estimated = std::env::args().any(|a| a == "estimated");
    let cases: Vec<(&str, Vec<u64>, &str)> = vec![
        ("gps_lag", vec![41, 42, 80, 81, 82, 83, 84, 85], "open"),
        ("gyro_scale", vec![43, 44, 70, 71, 72, 73], "open"),
        ("gps_outliers", vec![45, 46, 92, 93, 94, 95, 96, 97], "open"),
        ("mount_misalignment", vec![50, 52, 86, 87], "open"),
        (
            "gyro_bias_channel:temp_c",
            vec![51, 53, 54, 55, 56, 57],
            "open",
        ),
        ("gps_outliers", vec![7, 8, 9, 10, 11, 12, 13, 14], "urban"),
        (
            "",
            vec![48, 49, 60, 61, 62, 63, 64, 65, 66, 67, 68, 69],
            "open",
        ),
    ];
    println!(
        "ranking under the noise {}",
        if estimated {
            "estimated from the ride"
        } else {
            "as set"
        }
    );
    println!(
        "{:<26} {:>4} {:<26} {:>7} {:>6} {:>4}",
        "hidden", "seed", "candidate", "drop %", "t", "sig"
    );
    let mut tally = Vec::new();
    for (hidden, seeds, gps) in cases {
        let h: Vec<&str> = if hidden.is_empty() || gps == "urban" {
            vec![]
        } else {
            vec![hidden]
        };
        let label = match (hidden, gps) {
            ("", _) => "none".to_string(),
            (h, "urban") => format!("{h} (urban)"),
            (h, _) => h.to_string(),
        };
        let (mut first, mut significant, mut n) = (0, 0, 0);
        for seed in seeds {
            let d = run(seed, &h, gps, estimated)?;
            n += 1;
            // A plain ride shows every candidate (any significant one is a
            // false alarm); a ride with a hidden effect its top candidate.
            let shown = if hidden.is_empty() {
                d.ranking.len()
            } else {
                1
            };
            for c in d.ranking.iter().filter(|c| c.error.is_none()).take(shown) {
                println!(
                    "{label:<26} {seed:>4} {:<26} {:>7.1} {:>6.1} {:>4}",
                    c.effect,
                    100.0 * c.drop,
                    c.t_statistic,
                    if c.significant { "yes" } else { "-" }
                );
            }
            let top = d.ranking.first();
            first += usize::from(top.is_some_and(|c| c.effect == hidden));
            significant += usize::from(if hidden.is_empty() {
                d.ranking.iter().any(|c| c.significant)
            } else {
                top.is_some_and(|c| c.effect == hidden && c.significant)
            });
        }
        tally.push((label, n, first, significant));
    }
    println!();
    for (label, n, first, significant) in tally {
        if label == "none" {
            println!("{label:<26} {significant} of {n} rides with a false alarm");
        } else {
            println!("{label:<26} ranked first on {first} of {n}, significant on {significant}");
        }
    }
    Ok(())
}
