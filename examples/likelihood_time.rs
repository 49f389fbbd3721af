//! Time of one likelihood of the noise search on a simulated ride, and its
//! value to the digits (so that a faster chain solver can be checked to give
//! the same numbers). `cargo run --release --example likelihood_time -- [minutes] [evaluations]`.

use std::sync::Arc;
use std::time::Instant;

use gyropath::effects::Role;
use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Reconstruction, noise};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let minutes: f64 = args.get(1).map_or(Ok(30.0), |s| s.parse())?;
    let count: usize = args.get(2).map_or(Ok(40), |s| s.parse::<usize>())?.max(1);
    let sim = simulate(&SimConfig {
        seed: 3,
        duration_s: minutes * 60.0,
        ..SimConfig::default()
    })?;
    let sig = Arc::new(Signals::from_log(&parse(sim.log_csv.as_bytes(), "sim")?)?);
    let mut fit = Reconstruction::new(sig, FitSettings::default())?;
    fit.finish();
    let model = fit.model();
    let free = model.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
    let base = model
        .chain_system(fit.params(), &free)
        .ok_or_else(|| anyhow::anyhow!("no chain system"))?;
    let mut spec = model.spec.clone();
    let mut values = Vec::new();
    let mut times = Vec::new();
    for k in 0..count {
        // A different GPS sigma each time, as the search's stencil moves.
        spec.sigma_horizontal_m = model.spec.sigma_horizontal_m * (1.0 + 0.01 * k as f64);
        let started = Instant::now();
        values.push(noise::neg2_log_likelihood(
            model,
            &base,
            fit.params(),
            &spec,
        ));
        times.push(started.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    // The machine's other work only ever adds time: the minimum and the
    // lower quartile are the steadiest figures.
    println!(
        "{minutes} min: per likelihood min {:.2} ms, lower quartile {:.2} ms, median {:.2} ms over {count}; values first {:?}, last {:?}",
        1e3 * times[0],
        1e3 * times[count / 4],
        1e3 * times[count / 2],
        values.first().copied().flatten(),
        values.last().copied().flatten()
    );
    Ok(())
}
