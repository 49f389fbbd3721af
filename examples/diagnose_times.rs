//! Where `diagnose`'s time goes, one phase at a time on one thread: the
//! base fit, its held-out validation, and each candidate's refit and
//! validation, beside a default fit of the same ride.
//! `cargo run --release --example diagnose_times -- [minutes] [seed]`.

use std::sync::Arc;
use std::time::Instant;

use gyropath::contract::ModelSpec;
use gyropath::diagnosis::{Folds, held_out_from};
use gyropath::effects;
use gyropath::import::parse;
use gyropath::model::Model;
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let minutes: f64 = args.get(1).map_or(Ok(20.0), |s| s.parse())?;
    let seed: u64 = args.get(2).map_or(Ok(3), |s| s.parse())?;
    let sim = simulate(&SimConfig {
        seed,
        duration_s: minutes * 60.0,
        ..SimConfig::default()
    })?;
    let sig = Arc::new(Signals::from_log(&parse(sim.log_csv.as_bytes(), "sim")?)?);
    let t = Instant::now();
    let mut fit = Reconstruction::new(sig.clone(), FitSettings::default())?;
    fit.finish();
    println!("default fit, all cores {:.3} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let progress = |what: &str| println!("  {:.3} s {what}", t.elapsed().as_secs_f64());
    gyropath::diagnosis::diagnose(
        sig.clone(),
        &FitSettings::default(),
        &Folds::default(),
        &progress,
    )?;
    println!("diagnose, all cores {:.3} s", t.elapsed().as_secs_f64());
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()?
        .install(|| one_thread(&sig))
}

/// The same phases one after another on one thread.
fn one_thread(sig: &Arc<Signals>) -> anyhow::Result<()> {
    let t = Instant::now();
    let mut fit = Reconstruction::new(sig.clone(), FitSettings::default())?;
    fit.finish();
    println!("default fit, 1 thread {:.3} s", t.elapsed().as_secs_f64());

    let settings = FitSettings {
        auto_noise: AutoNoise::OFF,
        ..FitSettings::default()
    };
    let t = Instant::now();
    let mut base =
        Reconstruction::new(sig.clone(), settings.clone())?.keeping_its_last_linearisation();
    base.finish();
    let start = base.take_last_linearisation();
    println!(
        "base fit, set noise {:.3} s ({} iterations)",
        t.elapsed().as_secs_f64(),
        base.history().len()
    );
    let folds = Folds::default();
    let t = Instant::now();
    let ho = held_out_from(base.model(), base.params(), &settings, &folds, start)?;
    println!(
        "base held-out       {:.3} s ({} iterations)",
        t.elapsed().as_secs_f64(),
        ho.iterations
    );
    let channels: Vec<String> = sig.channels.iter().map(|(n, _)| n.clone()).collect();
    let (mut refits, mut validations) = (0.0, 0.0);
    for (id, _) in effects::catalogue(&channels) {
        let mut spec: ModelSpec = base.model().spec.clone();
        spec.effects.push(id.clone());
        let Ok(model) = Model::with_start(sig.clone(), spec, base.model().start.clone()) else {
            continue;
        };
        let theta = model.carry_over(base.model(), base.params());
        let cand = FitSettings {
            model: model.spec.clone(),
            ..settings.clone()
        };
        let t = Instant::now();
        let mut f = Reconstruction::resume(
            model,
            theta,
            gyropath::diagnosis::validation::validation_settings(&cand),
        )?
        .keeping_its_last_linearisation();
        f.finish();
        let start = f.take_last_linearisation();
        let refit = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let h = held_out_from(f.model(), f.params(), &cand, &folds, start)?;
        let validation = t.elapsed().as_secs_f64();
        refits += refit;
        validations += validation;
        println!(
            "{id:<20} refit {refit:.3} s ({} it), held-out {validation:.3} s ({} it)",
            f.history().len(),
            h.iterations
        );
    }
    println!("candidates: refits {refits:.3} s, held-out {validations:.3} s");
    Ok(())
}
