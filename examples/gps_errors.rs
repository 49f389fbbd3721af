//! What GPS errors look like against a reference, for real and simulated
//! rides side by side: how far off the fixes are, how often a run of them is
//! more than 15 m off, how long their errors stay correlated, how many
//! seconds have a fix. The simulator's `--gps urban` should look like a real
//! city here before a method is judged on it.
//!
//! `cargo run --release --example gps_errors -- RIDE.csv TRUTH.csv [RIDE.csv TRUTH.csv ...]`
//! (without arguments: the shared real drives and the simulator's urban
//! seeds 7-10, 10 minutes each).

use std::path::Path;

use gyropath::diagnosis::reference::{GpsErrorStatistics, match_rows};
use gyropath::import::{ImportOptions, open, read_reference};
use gyropath::signals::Signals;
use gyropath::simulation::{GpsEnvironment, SimConfig, simulate};

fn row(
    name: &str,
    signals: &Signals,
    truth: &gyropath::import::ReferenceTrack,
) -> anyhow::Result<()> {
    let m = match_rows(signals, truth)?;
    let Some(g) = GpsErrorStatistics::of(signals, &m) else {
        println!("{name:<34} too few fixes on the reference");
        return Ok(());
    };
    let c = |k: usize| g.correlation[k].1.map_or("-".into(), |v| format!("{v:.2}"));
    println!(
        "{name:<34} {:>5} {:>7.1} {:>7.1} {:>7.1} {:>7.1} {:>6.0} % {:>5.1} {:>6} {:>6} {:>6} {:>6} {:>6.0} %",
        g.fixes,
        g.error.median_m,
        g.error.rms_m,
        g.error.p95_m,
        g.error.max_m,
        100.0 * g.over_15m,
        g.mean_run_over_15m,
        c(0),
        c(1),
        c(2),
        c(3),
        100.0 * g.availability
    );
    Ok(())
}

fn main() -> anyhow::Result<()> {
    println!(
        "{:<34} {:>5} {:>7} {:>7} {:>7} {:>7} {:>8} {:>5} {:>6} {:>6} {:>6} {:>6} {:>8}",
        "ride",
        "fixes",
        "median",
        "RMS",
        "95 %",
        "max",
        ">15 m",
        "run",
        "r 1s",
        "r 5s",
        "r 10s",
        "r 30s",
        "fix/s"
    );
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !args.is_empty() {
        for pair in args.chunks(2) {
            let [ride, truth] = pair else {
                anyhow::bail!("give rides and references in pairs");
            };
            let signals = open(Path::new(ride), &ImportOptions::default())?.into_signals()?;
            row(ride, &signals, &read_reference(Path::new(truth))?)?;
        }
        return Ok(());
    }
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real");
    for drive in ["smartloc-berlin-potsdamer-platz", "comma2k19-example1"] {
        let d = real.join(drive);
        let signals = open(&d.join("ride.csv"), &ImportOptions::default())?.into_signals()?;
        row(drive, &signals, &read_reference(&d.join("truth.csv"))?)?;
    }
    for (gps, name) in [
        (GpsEnvironment::Urban, "urban"),
        (GpsEnvironment::City, "city"),
    ] {
        for seed in [7, 8, 9, 10] {
            let sim = simulate(&SimConfig {
                seed,
                duration_s: 600.0,
                gps,
                ..SimConfig::default()
            })?;
            let signals = Signals::from_log(&sim.log("sim")?)?;
            let truth = sim.reference("truth")?;
            row(
                &format!("simulate --gps {name} --seed {seed}"),
                &signals,
                &truth,
            )?;
        }
    }
    Ok(())
}
