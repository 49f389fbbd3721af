//! Where a fit's time goes: wall time per phase (step 1, step 2, noise
//! search) of a simulated ride, and then its uncertainty at every row and the path's error to the truth. `cargo run --release --example phase_times -- [minutes] [seed]`,
//! or of a ride log (no truth): `... -- FILE.csv`.

use std::sync::Arc;
use std::time::Instant;

use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Phase, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let file = args.get(1).filter(|a| a.parse::<f64>().is_err()).cloned();
    let minutes: f64 = match &file {
        Some(_) => f64::NAN,
        None => args.get(1).map_or(Ok(30.0), |s| s.parse())?,
    };
    let seed: u64 = args.get(2).map_or(Ok(3), |s| s.parse())?;
    let sim = match &file {
        Some(_) => None,
        None => Some(simulate(&SimConfig {
            seed,
            duration_s: minutes * 60.0,
            ..SimConfig::default()
        })?),
    };
    let text = match (&file, &sim) {
        (Some(f), _) => std::fs::read_to_string(f)?,
        (None, Some(s)) => s.log_csv.clone(),
        (None, None) => anyhow::bail!("no ride"),
    };
    let started = Instant::now();
    let sig = Arc::new(Signals::from_log(&parse(text.as_bytes(), "ride")?)?);
    let signals = sig.clone();
    let load = started.elapsed().as_secs_f64();
    let mut rec = Reconstruction::new(sig, FitSettings::default())?;
    let mut times = [0.0f64; 3];
    let mut counts = [0usize; 3];
    loop {
        let t = Instant::now();
        let Some(report) = rec.iterate() else { break };
        let slot = match report.phase {
            Phase::Step1 => 0,
            Phase::Step2 => 1,
            _ => 2,
        };
        times[slot] += t.elapsed().as_secs_f64();
        counts[slot] += 1;
        if std::env::var_os("PHASE_TRACE").is_some() {
            eprintln!(
                "{:?} {:?} cost {:.4} accepted {} damping {:.2e} step {:.2e} {:.3} s",
                report.phase,
                report.method,
                report.cost,
                report.accepted,
                report.damping,
                report.step_size,
                t.elapsed().as_secs_f64()
            );
        }
    }
    let evals = rec.noise().map_or(0, |n| n.evaluations);
    let total = started.elapsed().as_secs_f64();
    let t = Instant::now();
    let rows = rec
        .model()
        .uncertainty(rec.params())
        .map_or(0, |u| u.path.len());
    let uncertainty = t.elapsed().as_secs_f64();
    println!(
        "{} : load {load:.3} s, step 1 {:.3} s ({} it), step 2 {:.3} s ({} it), noise {:.3} s ({evals} evals), total {total:.3} s, rms {:.3} m; then uncertainty of {rows} rows {uncertainty:.3} s",
        file.clone().unwrap_or(format!("{minutes} min seed {seed}")),
        times[0],
        counts[0],
        times[1],
        counts[1],
        times[2],
        rec.stats().rms_horizontal_m
    );
    if let Some(sim) = &sim {
        println!(
            "path to the truth at the fixes {:.3} m",
            sim.errors(&signals, &rec.trajectory().p).path_at_fixes_m
        );
    }
    if let Some(n) = rec.noise() {
        println!("{}", n.describe());
    }
    Ok(())
}
