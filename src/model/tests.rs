//! Derivative checks: the analytic gradient and Jacobian against central
//! finite differences, for both increment maps and every effect.

use std::sync::Arc;

use super::*;
use crate::testing::winding_signals;

fn model(increment: Increment, walk: Option<f64>) -> Model {
    correlated_model(increment, walk, None)
}

fn correlated_model(increment: Increment, walk: Option<f64>, tau: Option<f64>) -> Model {
    let sig = Arc::new(winding_signals(60.0, 50.0));
    let spec = ModelSpec {
        segment_s: 7.0,
        bias_walk_dps_sqrt_s: walk,
        gps_tau_s: tau,
        increment,
        ..ModelSpec::default()
    };
    Model::new(sig, spec).unwrap()
}

/// The paper's model plus the whole effect catalogue, on a simulated ride
/// with barometer and temperature channel.
fn catalogue_model() -> Model {
    catalogue_model_with(None)
}

/// The catalogue with GPS errors correlated over `tau` (whitened residuals
/// through the robust loss of `gps_outliers`, lag-interpolated fixes).
fn catalogue_model_with(tau: Option<f64>) -> Model {
    catalogue_model_with_noise(tau, 0.0)
}

/// ... and a jitter of `white` (m) on top of the wander.
fn catalogue_model_with_noise(tau: Option<f64>, white: f64) -> Model {
    let sig = Arc::new(crate::testing::simulated_signals(
        4,
        60.0,
        &["gps_lag", "gps_outliers"],
    ));
    let mut effects = vec!["paper".to_string()];
    // Every effect of the catalogue that a wheel-sensor ride offers
    // (`speed_lag` needs a distance from the GNSS speed).
    effects.extend(
        effects::catalogue(&["temp_c".to_string()])
            .into_iter()
            .map(|(id, _)| id)
            .filter(|id| id != "speed_lag"),
    );
    let spec = ModelSpec {
        effects,
        segment_s: 7.0,
        gps_tau_s: tau,
        gps_white_m: white,
        ..ModelSpec::default()
    };
    let m = Model::new(sig, spec).unwrap();
    assert_eq!(m.effects().len(), 12, "{:?}", m.effect_ids());
    m
}

/// A ride whose distance is the GNSS speed's, with `speed_lag` chained
/// before `odometer_gain` at the distance site and `gnss_gaps` after it
/// (two gaps), and `gps_lag`.
fn gnss_speed_model() -> Model {
    let mut sig = crate::testing::simulated_signals(4, 60.0, &["gps_lag"]);
    sig.odometer = crate::signals::Odometer::GnssSpeed {
        samples: 60,
        standing_s: 0.0,
        gaps: vec![(10.0, 14.0), (30.5, 40.0)],
        stands_in_gaps: Vec::new(),
        stand_rule: None,
    };
    let spec = ModelSpec {
        effects: vec!["paper".into(), "speed_lag".into(), "gps_lag".into()],
        segment_s: 7.0,
        ..ModelSpec::default()
    };
    let m = Model::new(Arc::new(sig), spec).unwrap();
    assert!(
        m.effect_index("gnss_gaps").is_some(),
        "{:?}",
        m.effect_ids()
    );
    m
}

/// A 3D ride whose gyro stopped twice (one stop in three pieces, one in
/// one), with `gyro_scale` chained before `gyro_stops` at the gyro site.
fn gyro_stops_model() -> Model {
    let mut sig = crate::testing::simulated_signals(5, 60.0, &[]);
    sig.gyro_stops = vec![(12.0, 17.5), (40.003, 41.0)];
    let spec = ModelSpec {
        effects: vec!["paper".into(), "gyro_scale".into()],
        segment_s: 7.0,
        ..ModelSpec::default()
    };
    let m = Model::new(Arc::new(sig), spec).unwrap();
    assert!(
        m.effect_index("gyro_stops").is_some(),
        "{:?}",
        m.effect_ids()
    );
    m
}

/// A parameter vector away from the start so every term is non-trivial; the
/// lag is set so that fixes are interpolated inside steps, away from row times.
fn perturbed(m: &Model) -> Vec<f64> {
    let mut p = m.initial_params();
    for (i, v) in p.iter_mut().enumerate() {
        *v += 1e-3 * ((i as f64 * 1.7).sin());
    }
    if let Some(e) = m.effect_index("gps_lag") {
        p[m.range(e).start] = 0.4337;
    }
    p
}

fn models() -> Vec<Model> {
    vec![
        model(Increment::Exact, Some(0.01)),
        model(Increment::SmallAngle, Some(0.01)),
        catalogue_model(),
        correlated_model(Increment::Exact, Some(0.01), Some(20.0)),
        catalogue_model_with(Some(45.0)),
        catalogue_model_with_noise(Some(45.0), 1.5),
        gnss_speed_model(),
        gyro_stops_model(),
    ]
}

fn fd_gradient(m: &Model, p: &[f64], i: usize) -> f64 {
    let h = 1e-6 * (1.0 + p[i].abs());
    let (mut a, mut b) = (p.to_vec(), p.to_vec());
    a[i] += h;
    b[i] -= h;
    (m.cost(&a) - m.cost(&b)) / (2.0 * h)
}

#[test]
fn gradient_matches_finite_differences() {
    for m in models() {
        let inc = m.effect_ids();
        let p = perturbed(&m);
        let linked = m
            .obs_plan(&p)
            .links
            .iter()
            .filter(|l| l.prev.is_some())
            .count();
        assert_eq!(linked > 0, m.spec.gps_tau_s.is_some(), "{linked} links");
        let (cost, g) = m.gradient(&p);
        assert!((cost - m.cost(&p)).abs() < 1e-9 * cost);
        let scale = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for i in 0..p.len() {
            let fd = fd_gradient(&m, &p, i);
            let err = (fd - g[i]).abs() / (g[i].abs() + 1e-6 * scale);
            assert!(
                err < 1e-5,
                "{inc:?} param {i} {:?}: analytic {} fd {fd}",
                m.param_infos()[i],
                g[i]
            );
        }
    }
}

#[test]
fn jacobian_matches_finite_differences_and_the_gradient() {
    for m in models() {
        let inc = m.effect_ids();
        let p = perturbed(&m);
        let free = vec![true; m.n_params()];
        let lin = m.linearise(&p, &free);
        let r0 = m.residuals(&p);
        assert_eq!(lin.residuals.len(), r0.len());
        for (a, b) in lin.residuals.iter().zip(&r0) {
            assert!((a - b).abs() < 1e-9);
        }
        let (_, g) = m.gradient(&p);
        let jtr = lin.jacobian.transpose() * &lin.residuals * 2.0;
        for i in 0..p.len() {
            assert!(
                (jtr[i] - g[i]).abs() < 1e-7 * (1.0 + g[i].abs()),
                "param {i}: {} vs {}",
                jtr[i],
                g[i]
            );
            let h = 1e-6;
            let (mut a, mut b) = (p.clone(), p.clone());
            a[i] += h;
            b[i] -= h;
            let (ra, rb) = (m.residuals(&a), m.residuals(&b));
            for r in 0..ra.len() {
                let fd = (ra[r] - rb[r]) / (2.0 * h);
                let an = lin.jacobian[(r, i)];
                assert!(
                    (fd - an).abs() < 1e-5 * (1.0 + an.abs()),
                    "{inc:?} row {r} param {i}: {an} vs {fd}"
                );
            }
        }
    }
}

#[test]
fn jacobian_of_a_subset_is_the_matching_columns() {
    let m = model(Increment::Exact, None);
    let p = perturbed(&m);
    let all = m.linearise(&p, &vec![true; m.n_params()]);
    let mask = m.free_mask(&[effects::Role::Segments]);
    let sub = m.linearise(&p, &mask);
    assert_eq!(sub.columns.len(), mask.iter().filter(|&&f| f).count());
    for (c, &i) in sub.columns.iter().enumerate() {
        assert_eq!(sub.jacobian.column(c), all.jacobian.column(i));
    }
}

#[test]
fn moment_normal_equations_equal_the_dense_ones() {
    for m in [
        model(Increment::Exact, None),
        model(Increment::Exact, Some(0.01)),
        catalogue_model(),
        gyro_stops_model(),
    ] {
        let p = perturbed(&m);
        for roles in [
            vec![effects::Role::Global, effects::Role::Segments],
            vec![effects::Role::Segments],
            vec![effects::Role::Global, effects::Role::Step1Only],
            // The stops' turns share blocks with the segments they lie in.
            vec![
                effects::Role::Global,
                effects::Role::Segments,
                effects::Role::Step2Only,
            ],
        ] {
            let free = m.free_mask(&roles);
            let lin = m.linearise(&p, &free);
            let jt = lin.jacobian.transpose();
            let a = &jt * &lin.jacobian;
            let g = &jt * &lin.residuals;
            let ne = m.normal_equations(&p, &free);
            assert_eq!(ne.columns, lin.columns);
            assert!((ne.cost - lin.cost).abs() < 1e-9 * lin.cost);
            let scale = a.amax();
            assert!(
                (&ne.a - &a).amax() < 1e-9 * scale,
                "{roles:?}: A differs by {}",
                (&ne.a - &a).amax()
            );
            assert!(
                (&ne.g - &g).amax() < 1e-9 * g.amax().max(1.0),
                "{roles:?}: g differs"
            );
        }
    }
}

#[test]
fn chain_solver_gives_the_dense_lm_step() {
    use crate::model::damped_solve;
    let full = catalogue_model();
    // A step-1 window: observations up to 35 s, segments reached by then free.
    let window = full.restricted(full.signals.t[0] + 35.0).unwrap();
    let mut window_free = window.free_mask(&[effects::Role::Global, effects::Role::Segments]);
    let seg = window.effect_index("gyro_bias_segments").unwrap();
    for i in window.range(seg).skip(18) {
        window_free[i] = false;
    }
    // An anchored window: only the segments after the anchor are free.
    let anchor_row = 2100;
    let anchored = full
        .window(&perturbed(&full), anchor_row, full.signals.t[0] + 50.0)
        .unwrap();
    let mut anchored_free = vec![false; anchored.n_params()];
    let effect = &anchored.effects()[seg];
    for (k, i) in anchored.range(seg).enumerate() {
        anchored_free[i] = effect.param_steps(k).is_some_and(|(f, _)| f > anchor_row);
    }
    assert!(anchored.anchor_holds(&anchored_free));
    let mut cases: Vec<(Model, Vec<bool>)> = vec![(window, window_free), (anchored, anchored_free)];
    for m in [
        model(Increment::Exact, None),
        model(Increment::SmallAngle, Some(0.01)),
        full,
        correlated_model(Increment::Exact, Some(0.01), Some(20.0)),
        catalogue_model_with(Some(45.0)),
        catalogue_model_with_noise(Some(45.0), 1.5),
    ] {
        for roles in [
            vec![effects::Role::Global, effects::Role::Segments],
            vec![effects::Role::Segments],
        ] {
            let free = m.free_mask(&roles);
            cases.push((m.restricted(f64::INFINITY).unwrap(), free));
        }
    }
    // A gyro stop's turns in the blocks of the segments they overlap (the
    // first stop straddles two segments and merges them), the segments and
    // globals free as in step 2, or the stops' turns alone.
    let stops = gyro_stops_model();
    let in_blocks = stops
        .chain_linearisation(
            &perturbed(&stops),
            &stops.free_mask(&[effects::Role::Segments, effects::Role::Step2Only]),
        )
        .expect("a chain");
    assert!(in_blocks.globals.is_empty());
    assert!(in_blocks.blocks.iter().any(|b| b.params.len() > 6));
    for roles in [
        vec![
            effects::Role::Global,
            effects::Role::Segments,
            effects::Role::Step2Only,
        ],
        vec![effects::Role::Segments, effects::Role::Step2Only],
    ] {
        let free = stops.free_mask(&roles);
        cases.push((stops.restricted(f64::INFINITY).unwrap(), free));
    }
    for (m, free) in &cases {
        let p = perturbed(m);
        let chain = m.chain_system(&p, free).expect("segments form a chain");
        let ne = m.normal_equations(&p, free);
        assert_eq!(chain.columns(), &ne.columns[..]);
        assert!((chain.cost() - ne.cost).abs() < 1e-12 * ne.cost);
        for lambda in [1e-8, 1e-3, 1.0, 1e3] {
            let dense = damped_solve(&ne.a, &-&ne.g, lambda).unwrap();
            let fast = chain.solve(lambda).unwrap();
            let err = (&fast - &dense).norm() / dense.norm();
            assert!(err < 1e-6, "lambda {lambda}: relative difference {err:e}");
            if lambda == 1e-3 {
                // ln det(A + lambda D), D = diag(A): the chain's QR against a dense Cholesky.
                let mut a = ne.a.clone();
                let max_diag = a.diagonal().max();
                for i in 0..a.nrows() {
                    let d = a[(i, i)].max(1e-9 * max_diag);
                    a[(i, i)] += lambda * d + 1e-15 * max_diag;
                }
                let dense_ld = 2.0
                    * a.cholesky()
                        .unwrap()
                        .l()
                        .diagonal()
                        .iter()
                        .map(|v| v.ln())
                        .sum::<f64>();
                let (_, chain_ld) = chain.solve_with_log_det(lambda).unwrap();
                assert!(
                    (chain_ld - dense_ld).abs() < 1e-6 * dense_ld.abs().max(1.0),
                    "case {:?} log det {chain_ld} vs {dense_ld}",
                    (
                        m.n_params(),
                        m.spec.gps_tau_s,
                        free.iter().filter(|&&f| f).count()
                    )
                );
            }
            let predicted = -(2.0 * dense.dot(&ne.g) + dense.dot(&(&ne.a * &dense)));
            let fast_predicted = chain.predicted_decrease(&dense);
            assert!(
                (fast_predicted - predicted).abs() < 1e-8 * ne.cost,
                "{fast_predicted} vs {predicted}"
            );
        }
        // The likelihood's pass: the linearised cost at its minimum, left
        // below the QR's triangle, against the dense minimum
        // `C - g^T A^-1 g`, and the log-determinant of the full pass.
        let (fit, log_det) = chain.fit_with_log_det().unwrap();
        let dense = damped_solve(&ne.a, &-&ne.g, 0.0).unwrap();
        let dense_fit = ne.cost + dense.dot(&ne.g);
        assert!(
            (fit - dense_fit).abs() < 1e-8 * ne.cost,
            "minimum {fit} vs {dense_fit}"
        );
        let (_, full_ld) = chain.solve_with_log_det(0.0).unwrap();
        assert!((log_det - full_ld).abs() < 1e-9 * full_ld.abs().max(1.0));
        // A noise likelihood's system under other settings, scaled as the
        // base's, gives its own system's minimum and log-determinant, to
        // the floor `1e-15 max D` that keeps the array regular, which is
        // the base's `D`'s (1e-12 to 3e-7 of them; in a likelihood of a
        // 30-minute ride 1.5e-9, where the search looks at 0.2).
        let mut spec = m.spec.clone();
        spec.sigma_horizontal_m *= 1.7;
        spec.gps_white_m *= 0.6;
        spec.gps_tau_s = spec.gps_tau_s.map(|t| 2.5 * t);
        let other = m.with_spec(spec).unwrap();
        let own = other.chain_system_like(&chain, &p).unwrap();
        let scaled = other.likelihood_system_like(&chain, &p).unwrap();
        let (own_fit, own_ld) = own.fit_with_log_det().unwrap();
        let (scaled_fit, scaled_ld) = scaled.fit_with_log_det().unwrap();
        assert!(
            (scaled_fit - own_fit).abs() < 1e-6 * own_fit.abs().max(1.0),
            "minimum {scaled_fit} vs {own_fit}"
        );
        assert!(
            (scaled_ld - own_ld).abs() < 1e-6 * own_ld.abs().max(1.0),
            "log det {scaled_ld} vs {own_ld}"
        );
    }
}

#[test]
fn chunked_parallel_sweep_equals_the_sequential_path() {
    for m in [catalogue_model(), model(Increment::SmallAngle, Some(0.01))] {
        let p = perturbed(&m);
        assert!(m.signals.len() > 4 * super::sweep::CHUNK_ROWS);
        let sequential: f64 = m.residuals(&p).iter().map(|r| r * r).sum();
        let chunked = m.cost(&p);
        assert!(
            (chunked - sequential).abs() < 1e-10 * sequential,
            "{chunked} vs {sequential}"
        );
        // A window anchored part-way gives the same cost as its unanchored twin.
        let t_end = m.signals.t[0] + 50.0;
        let anchored = m.window(&p, 2600, t_end).unwrap();
        let mut plain = m.restricted(t_end).unwrap();
        plain.observations.retain(|o| o.row > 2600);
        let (a, b) = (anchored.cost(&p), plain.cost(&p));
        assert!((a - b).abs() < 1e-10 * b, "anchored {a} vs {b}");
        // Its Jacobian in the segments after the anchor is the twin's.
        let seg = m.effect_index("gyro_bias_segments").unwrap();
        let effect = &m.effects()[seg];
        let mut free = vec![false; m.n_params()];
        for (k, i) in m.range(seg).enumerate() {
            free[i] = effect.param_steps(k).is_some_and(|(f, _)| f > 2600);
        }
        let (ja, jb) = (anchored.linearise(&p, &free), plain.linearise(&p, &free));
        let scale = jb.jacobian.amax();
        assert!((&ja.jacobian - &jb.jacobian).amax() < 1e-9 * scale);
        assert!((&ja.residuals - &jb.residuals).amax() < 1e-9 * jb.residuals.amax());
        // Changing a parameter that acts before the anchor invalidates it.
        let mut q = p.clone();
        q[anchored
            .range(anchored.effect_index("odometer_gain").unwrap())
            .start] += 1e-3;
        let (a, b) = (anchored.cost(&q), plain.cost(&q));
        assert!((a - b).abs() < 1e-10 * b, "stale anchor {a} vs {b}");
    }
}

/// The noise search rebuilds the model at every setting it tries through
/// `with_spec`, which shares the segments' per-row table: the result must
/// be the model built for those settings from scratch, on the whole ride
/// and on a window of it.
#[test]
fn a_model_under_other_noise_settings_is_the_one_built_for_them() {
    let m = correlated_model(Increment::Exact, Some(0.004), Some(20.0));
    let mut p = m.initial_params();
    for (i, v) in p.iter_mut().enumerate() {
        *v += 1e-4 * ((i % 7) as f64 - 3.0);
    }
    let spec = ModelSpec {
        sigma_horizontal_m: 2.5,
        gps_tau_s: Some(40.0),
        gps_white_m: 0.3,
        bias_walk_dps_sqrt_s: Some(0.01),
        ..m.spec.clone()
    };
    let fresh = Model::with_start(m.signals.clone(), spec.clone(), m.start.clone()).unwrap();
    let reused = m.with_spec(spec.clone()).unwrap();
    let (a, b) = (reused.cost(&p), fresh.cost(&p));
    assert!((a - b).abs() <= 1e-12 * b, "reused {a} vs fresh {b}");
    assert_eq!(reused.n_residuals(), fresh.n_residuals());
    // The prior changed with the walk: the same model at the old walk costs otherwise.
    assert!((m.cost(&p) - b).abs() > 1e-6 * b);
    // A window keeps its fixes under the new settings.
    let t0 = m.signals.t[0];
    let window = m.between(t0 + 20.0, t0 + 40.0).unwrap();
    let (w_reused, w_fresh) = (
        window.with_spec(spec.clone()).unwrap(),
        fresh.between(t0 + 20.0, t0 + 40.0).unwrap(),
    );
    assert_eq!(w_reused.observed_fixes(), w_fresh.observed_fixes());
    assert!(w_reused.observed_fixes() > 0 && w_reused.observed_fixes() < m.observed_fixes());
    let (a, b) = (w_reused.cost(&p), w_fresh.cost(&p));
    assert!((a - b).abs() <= 1e-12 * b, "window {a} vs {b}");
    // Settings no model can have are refused as by a fresh build.
    let bad = ModelSpec {
        gps_white_m: f64::NAN,
        ..spec
    };
    assert!(m.with_spec(bad).is_err());
}

/// A window of the ride frees the globals and only the segment biases that
/// act between its first fix and the end of its sweep.
#[test]
fn a_window_frees_the_globals_and_its_own_segments() {
    let m = model(Increment::Exact, Some(0.004));
    let t0 = m.signals.t[0];
    let window = m.between(t0 + 20.0, t0 + 35.0).unwrap();
    let all = m.free_mask(&[Role::Global, Role::Segments]);
    let free = window.free_within_fixes(&all);
    assert_eq!(
        m.free_within_fixes(&all),
        all,
        "the whole ride frees everything"
    );
    let seg = m.effect_index("gyro_bias_segments").unwrap();
    let effect = &m.effects()[seg];
    let first = window.observations[0].row;
    let last = window.horizon() - 1;
    for (i, &f) in free.iter().enumerate() {
        if m.range(seg).contains(&i) {
            let (a, b) = effect.param_steps(i - m.range(seg).start).unwrap();
            assert_eq!(
                f,
                all[i] && b >= first && a <= last,
                "segment parameter {i}"
            );
        } else {
            assert_eq!(f, all[i], "global parameter {i}");
        }
    }
    assert!(free.iter().filter(|&&f| f).count() < all.iter().filter(|&&f| f).count());
}

/// A fold of a validation (fixes withheld in the middle of the ride) starts
/// from the full ride's linearisation with its own fixes picked out: the
/// same system, number for number, as the fold's own sweep gives, under
/// independent and correlated GPS errors and the whole catalogue (robust
/// loss, lag-interpolated fixes); a mask that is not the fold's is refused.
#[test]
fn a_fold_picked_from_the_full_linearisation_is_the_folds_own() {
    let mut checked = 0;
    for m in models() {
        let p = perturbed(&m);
        let free = m.free_mask(&[
            crate::effects::Role::Global,
            crate::effects::Role::Segments,
            crate::effects::Role::Step2Only,
        ]);
        let Some(base) = m.chain_system(&p, &free) else {
            continue;
        };
        let t0 = m.signals.t[0];
        let keep = |t: f64| !(t0 + 20.0..t0 + 32.0).contains(&t);
        let fold = m.withholding(keep).unwrap();
        assert!(fold.observations.len() < m.observations.len());
        let kept: Vec<bool> = m.observations.iter().map(|o| keep(o.t)).collect();
        let own = fold.chain_system(&p, &free).unwrap();
        let picked = fold.chain_system_within(&base, &p, &kept).unwrap();
        assert_eq!(own.cost(), picked.cost());
        assert_eq!(own.columns(), picked.columns());
        let (a, b) = (own.solve(1e-3).unwrap(), picked.solve(1e-3).unwrap());
        assert_eq!(a, b);
        // The full ride's own mask is not this fold's.
        let all = vec![true; m.observations.len()];
        assert!(fold.chain_system_within(&base, &p, &all).is_none());
        checked += 1;
    }
    assert!(checked >= 5, "{checked} models in chain form");
}

/// The coarse ride's derivatives corrected at an anchor (see
/// `optimisation::derivatives`): at the anchor they are the ride's own (to
/// rounding), so the system is the ride's own system; next to a fitted
/// anchor, as a validation fold or a fit's last steps are, they give the
/// ride's own Gauss-Newton step far more nearly than the coarse ride's
/// derivatives alone do (on these one-minute rides to 0.15-1.5 % of the
/// step, where the coarse ride's alone err by 50-240 %).
#[test]
fn coarse_derivatives_corrected_at_an_anchor_are_the_rides_own() {
    let mut checked = 0;
    for m in models() {
        let Some(coarse) = crate::optimisation::coarse_model(&m) else {
            continue;
        };
        let free = m.free_mask(&[
            crate::effects::Role::Global,
            crate::effects::Role::Segments,
            crate::effects::Role::Step2Only,
        ]);
        // Fitted first, from the perturbed start.
        let mut p = perturbed(&m);
        let mut state = crate::optimisation::lm::LmState::new(1e-3);
        for _ in 0..12 {
            crate::optimisation::lm::iterate(None, &m, &mut p, &free, &mut state, 0.0, false, None);
        }
        let Some(base) = m.chain_system(&p, &free) else {
            continue;
        };
        let anchor = m.derivative_anchor(&coarse, &base, &p).unwrap();
        let here = m
            .chain_system_from_coarse(&coarse, &anchor, &p, &m.evaluate(&p).observed)
            .unwrap();
        assert!((here.cost() - base.cost()).abs() <= 1e-12 * base.cost());
        let (a, b) = (base.solve(1e-3).unwrap(), here.solve(1e-3).unwrap());
        let at_anchor = (&a - &b).norm();
        assert!(at_anchor <= 1e-6 * a.norm() + 1e-12, "{a} against {b}");
        // Moved off the fit, as a fold's withheld fixes move it.
        let mut q = p.clone();
        for &i in base.columns() {
            q[i] += 1e-3 * (1.3 * i as f64).sin();
        }
        let observed = m.evaluate(&q).observed;
        let own = m.chain_system(&q, &free).unwrap().solve(1e-3).unwrap();
        // `None` where the move put an observation into another block (the
        // GPS lag's): the fit then linearises the ride itself.
        let Some(corrected) = m.chain_system_from_coarse(&coarse, &anchor, &q, &observed) else {
            continue;
        };
        let corrected = corrected.solve(1e-3).unwrap();
        let alone = coarse.chain_linearisation(&q, &free).unwrap();
        let alone = ChainSystem::new(m.moved(alone, &q, &observed).unwrap(), m.n_params())
            .unwrap()
            .solve(1e-3)
            .unwrap();
        let (err, err_alone) = ((&corrected - &own).norm(), (&alone - &own).norm());
        println!(
            "corrected {err:.3e}, coarse alone {err_alone:.3e}, step {:.3e}",
            own.norm()
        );
        assert!(
            err < 0.1 * err_alone && err < 2e-2 * own.norm(),
            "{err} against {err_alone} of a step of {}",
            own.norm()
        );
        checked += 1;
    }
    assert!(checked >= 5, "{checked} models with a coarse ride");
}
