//! How often the truth lies inside the path's 95 % sigma ellipse, on
//! simulated rides, under the noise settings estimated from the ride and
//! under settings given by hand; and how often the true GPS sigma and
//! correlation time (1.5 m, 60 s) lie inside the 1-sigma ranges estimated.
//!
//! `cargo run --release --example calibration -- [duration_s] [seeds...]`

use std::sync::Arc;

use gyropath::import::parse;
use gyropath::optimisation::{AutoNoise, Estimated, FitSettings, Limit, Reconstruction};
use gyropath::signals::Signals;
use gyropath::simulation::{SimConfig, simulate};

/// GPS sigma (m) and correlation time (s) given by hand.
type Noise = (f64, Option<f64>);

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let duration: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(600.0);
    let mut seeds: Vec<u64> = args.filter_map(|a| a.parse().ok()).collect();
    if seeds.is_empty() {
        seeds = vec![21, 22, 23, 24];
    }
    let cases: [(&str, Option<Noise>); 5] = [
        ("auto", None),
        ("auto, bias walk too", Some((f64::NAN, None))),
        ("1.58 m, tau 60 s", Some((1.58, Some(60.0)))),
        ("1.58 m, independent", Some((1.58, None))),
        ("3 m, independent", Some((3.0, None))),
    ];
    for (label, noise) in cases {
        let (mut inside, mut total) = (0usize, 0usize);
        // z = ln(estimate / truth) / sd per searched setting (sigma, tau).
        let mut z: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
        for &seed in &seeds {
            let sim = simulate(&SimConfig {
                seed,
                duration_s: duration,
                ..SimConfig::default()
            })?;
            let sig = Arc::new(Signals::from_owned_log(parse(
                sim.log_csv.as_bytes(),
                "cal",
            )?)?);
            let mut settings = FitSettings::default();
            if noise.is_some_and(|(sigma, _)| sigma.is_nan()) {
                settings.auto_noise.walk = true;
            } else if let Some((sigma, tau)) = noise {
                settings.auto_noise = AutoNoise::OFF;
                settings.model.sigma_horizontal_m = sigma;
                settings.model.gps_tau_s = tau;
            }
            let mut fit = Reconstruction::new(sig.clone(), settings)?;
            fit.finish();
            let path = fit.trajectory().p;
            let Some(u) = fit.model().uncertainty(fit.params()) else {
                continue;
            };
            let truth = sim.truth_in(&sig.frame);
            let (mut here, mut rows, mut d2_sum) = (0usize, 0usize, 0.0);
            let mut by_tenth = [(0usize, 0usize); 10];
            for j in (0..sig.len()).step_by(100) {
                let (de, dn) = (path[j].x - truth[j].x, path[j].y - truth[j].y);
                let d2 = u.mahalanobis2(j, de, dn);
                let ok = d2 <= 5.991;
                here += usize::from(ok);
                rows += 1;
                d2_sum += d2;
                let tenth = &mut by_tenth[(10 * j / sig.len()).min(9)];
                tenth.0 += usize::from(ok);
                tenth.1 += 1;
            }
            inside += here;
            total += rows;
            if let Some(n) = fit.noise() {
                for (k, (e, truth)) in [(&n.gps_sigma_m, 1.5), (&n.gps_tau_s, 60.0)]
                    .into_iter()
                    .enumerate()
                {
                    if let Some(v) = z_score(e, truth) {
                        z[k].push(v);
                    }
                }
            }
            let tenths: Vec<String> = by_tenth
                .iter()
                .map(|(a, b)| format!("{:.0}", 100.0 * *a as f64 / (*b).max(1) as f64))
                .collect();
            println!(
                "  seed {seed}: {:.1} % inside, mean d2 {:.2} (2 if calibrated), by tenth [{}]; {}",
                100.0 * here as f64 / rows.max(1) as f64,
                d2_sum / rows.max(1) as f64,
                tenths.join(" "),
                fit.noise()
                    .map_or("noise as set".to_string(), |n| n.describe())
            );
        }
        println!(
            "{label:>22}: {:.1} % of {total} rows inside the 95 % ellipse",
            100.0 * inside as f64 / total.max(1) as f64
        );
        for (name, z) in ["GPS sigma", "GPS correlation time"].iter().zip(&z) {
            if z.is_empty() {
                continue;
            }
            let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
            let within = z.iter().filter(|v| v.abs() <= 1.0).count();
            println!(
                "{:>22}  {name}: truth within the 1-sigma range on {within} of {} rides (68 % expected), RMS z {rms:.2} (1 if calibrated), mean z {:+.2}",
                "",
                z.len(),
                z.iter().sum::<f64>() / z.len() as f64
            );
        }
    }
    Ok(())
}

/// `ln(estimate / truth)` in units of the estimate's log-range on the
/// truth's side; `None` for a setting held at a bound or not searched.
fn z_score(e: &Estimated, truth: f64) -> Option<f64> {
    if !e.estimated || e.limit != Limit::None {
        return None;
    }
    let d = (e.value / truth).ln();
    let sd = if d > 0.0 {
        (e.value / e.low).ln()
    } else {
        (e.high / e.value).ln()
    };
    (sd > 0.0).then(|| d / sd)
}
