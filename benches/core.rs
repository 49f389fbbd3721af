//! Speed of the core on simulated 100 Hz rides with 1 Hz GPS and 5 s segments.
//! `cargo bench --bench core`; numbers are in docs/speed.md.

use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, criterion_group, criterion_main};
use gyropath::diagnosis::{Folds, diagnose};
use gyropath::effects::Role;
use gyropath::import::parse;
use gyropath::model::{Model, ModelSpec};
use gyropath::optimisation::{FitSettings, Reconstruction, noise};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

fn ride(minutes: f64) -> (String, Arc<Signals>) {
    let sim = simulate(&SimConfig {
        seed: 3,
        duration_s: minutes * 60.0,
        ..SimConfig::default()
    })
    .expect("simulate");
    let sig = Signals::from_log(&parse(sim.log_csv.as_bytes(), "bench").expect("parse"))
        .expect("signals");
    (sim.log_csv, Arc::new(sig))
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("core");
    g.sample_size(10);
    for minutes in [15.0, 30.0, 60.0] {
        let (csv, sig) = ride(minutes);
        let label = format!("{minutes:.0}min");
        g.bench_function(format!("load/{label}"), |b| {
            b.iter(|| {
                Signals::from_log(&parse(black_box(csv.as_bytes()), "bench").unwrap()).unwrap()
            })
        });
        let model = Model::new(sig.clone(), ModelSpec::default()).unwrap();
        let theta = model.initial_params();
        g.bench_function(format!("cost/{label}"), |b| {
            b.iter(|| model.cost(black_box(&theta)))
        });
        g.bench_function(format!("gradient/{label}"), |b| {
            b.iter(|| model.gradient(black_box(&theta)))
        });
        let free = vec![true; model.n_params()];
        // One LM step: linearise in chain form and solve the damped problem (O(N)).
        g.bench_function(format!("lm_step/{label}"), |b| {
            b.iter(|| {
                let chain = model.chain_system(black_box(&theta), &free).unwrap();
                chain.solve(1e-3).unwrap()
            })
        });
        g.bench_function(format!("fit/{label}"), |b| {
            b.iter(|| {
                let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).unwrap();
                while fit.iterate().is_some() {}
                fit.stats().rms_horizontal_m
            })
        });
        if minutes == 30.0 {
            // The fitted path's sigma at every row (issue 14): the chain's backward pass and one prefix sweep.
            let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).unwrap();
            fit.finish();
            g.bench_function(format!("uncertainty/{label}"), |b| {
                b.iter(|| fit.model().uncertainty(black_box(fit.params())).unwrap())
            });
            // One likelihood of the noise search (dozens per fit; issue 29):
            // the chain solver's forward pass with its log-determinant, under
            // a correlated GPS error (a wander per axis passed from fix to fix).
            let model = fit.model();
            let free = model.free_mask(&[Role::Global, Role::Segments, Role::Step2Only]);
            let base = model.chain_system(fit.params(), &free).unwrap();
            g.bench_function(format!("noise_likelihood/{label}"), |b| {
                b.iter(|| {
                    noise::neg2_log_likelihood(model, &base, fit.params(), &model.spec).unwrap()
                })
            });
        }
    }
    // A gyro that stopped twenty times for 5 s: each stop's turns (98 in
    // all) are local columns of the chain, in the blocks of the segments
    // they overlap; as global columns they widened every row (52 s to fit
    // this ride in full, 3.8 s since).
    let (_, sig) = ride(30.0);
    let mut stopped = (*sig).clone();
    stopped.gyro_stops = (0..20)
        .map(|k| (60.0 + 85.0 * k as f64, 65.0 + 85.0 * k as f64))
        .collect();
    let model = Model::new(Arc::new(stopped), ModelSpec::default()).unwrap();
    let theta = model.initial_params();
    let free = vec![true; model.n_params()];
    g.bench_function("lm_step/30min_20_stops", |b| {
        b.iter(|| {
            let chain = model.chain_system(black_box(&theta), &free).unwrap();
            chain.solve(1e-3).unwrap()
        })
    });
    // `gyropath diagnose` without its printing (issue 13's target: 4 s on 20 minutes).
    let (_, sig) = ride(20.0);
    g.bench_function("diagnose/20min", |b| {
        b.iter(|| {
            diagnose(
                sig.clone(),
                &FitSettings::default(),
                &Folds::default(),
                &|_| {},
            )
            .unwrap()
        })
    });
    // The naive gradient: one finite difference per parameter (what the O(N)
    // sweep replaces), on the 15-minute ride, for 20 parameters -> scale by P/20.
    let (_, sig) = ride(15.0);
    let model = Model::new(sig, ModelSpec::default()).unwrap();
    let theta = model.initial_params();
    g.bench_function("naive_gradient_20_params/15min", |b| {
        b.iter(|| {
            let mut t = theta.clone();
            (0..20)
                .map(|i| {
                    t[i] += 1e-6;
                    let c = model.cost(&t);
                    t[i] -= 1e-6;
                    c
                })
                .sum::<f64>()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
