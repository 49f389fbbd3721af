//! The O(N) gradient against central finite differences on a real-sized ride
//! (20 minutes at 100 Hz, 240 segments).

mod common;

use gyropath::model::{Model, ModelSpec};

#[test]
fn gradient_matches_finite_differences_on_a_twenty_minute_ride() {
    let (_, sig) = common::ride(7, 1200.0, &[]);
    let model = Model::new(sig, ModelSpec::default()).unwrap();
    let mut theta = model.initial_params();
    for (i, v) in theta.iter_mut().enumerate() {
        *v += 1e-4 * (i as f64 * 0.37).sin();
    }
    let (_, g) = model.gradient(&theta);
    let gmax = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    // Every global parameter and every 7th segment parameter.
    let globals = model.n_params()
        - model
            .param_infos()
            .iter()
            .filter(|(e, _)| e == "gyro_bias_segments")
            .count();
    let check: Vec<usize> = (0..model.n_params())
        .filter(|&i| i % 7 == 0 || model.param_infos()[i].0 != "gyro_bias_segments")
        .collect();
    assert!(check.len() > globals + 90);
    let mut worst: f64 = 0.0;
    for i in check {
        let h = 1e-5 * (1.0 + theta[i].abs());
        // Five-point stencil: truncation error O(h^4), so the check measures the gradient, not the stencil.
        let at = |x: f64| {
            let mut t = theta.clone();
            t[i] += x;
            model.cost(&t)
        };
        let fd = (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h);
        let rel = (fd - g[i]).abs() / (g[i].abs().max(1e-4 * gmax));
        worst = worst.max(rel);
        assert!(
            rel < 1e-6,
            "param {i} {:?}: analytic {} fd {fd} rel {rel:e}",
            model.param_infos()[i],
            g[i]
        );
    }
    eprintln!("worst relative error {worst:e}");
}
