//! Inside GNSS-speed gaps: the path's error and how often the truth lies in
//! its 95 % ellipse, on simulated 10-minute bicycle rides with stops (the
//! rides of `tests/gnss_speed.rs`), with the stands the gyro tells.
//! `cargo run --release --example gap_stands -- [FIRST_SEED LAST_SEED]`

use std::sync::Arc;

use gyropath::import::parse;
use gyropath::optimisation::{FitSettings, Reconstruction};
use gyropath::signals::{Odometer, Signals};
use gyropath::simulation::{SimConfig, simulate};

fn main() -> anyhow::Result<()> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (first, last) = (
        args.first().copied().unwrap_or(2),
        args.get(1).copied().unwrap_or(9),
    );
    println!(
        "| seed | gap rows | in ellipse | gap error RMS | stands told (s) | stands truly in gaps (s) | threshold |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let (mut all_in, mut all_n, mut all_sq) = (0, 0, 0.0);
    for seed in first..=last {
        let sim = simulate(&SimConfig {
            seed,
            gnss_speed: true,
            outages: true,
            duration_s: 600.0,
            ..SimConfig::default()
        })?;
        let mut log = parse(sim.log_csv.as_bytes(), "sim")?;
        log.odo_m = None;
        log.speed_mps = None;
        log.wheel_pulse = None;
        let sig = Arc::new(Signals::from_log(&log)?);
        let mut fit = Reconstruction::new(sig.clone(), FitSettings::default())?;
        fit.finish();
        let path = fit.trajectory().p;
        let u = fit
            .model()
            .uncertainty(fit.params())
            .ok_or_else(|| anyhow::anyhow!("no uncertainty"))?;
        let truth = sim.truth_in(&sig.frame);
        let Odometer::GnssSpeed {
            gaps,
            stands_in_gaps,
            stand_rule,
            ..
        } = &sig.odometer
        else {
            anyhow::bail!("not a GNSS-speed distance");
        };
        let (mut inside, mut n, mut sq) = (0, 0, 0.0);
        let mut true_stand = 0.0;
        for j in 0..sig.len() {
            if !gaps.iter().any(|&(a, b)| sig.t[j] > a && sig.t[j] <= b) {
                continue;
            }
            if j > 0 && (truth[j] - truth[j - 1]).norm() < 1e-4 {
                true_stand += sig.dt[j];
            }
            if j % 50 != 0 {
                continue;
            }
            let (de, dn) = (path[j].x - truth[j].x, path[j].y - truth[j].y);
            inside += (u.mahalanobis2(j, de, dn) <= 5.991) as usize;
            n += 1;
            sq += de * de + dn * dn;
        }
        let told: f64 = stands_in_gaps.iter().map(|(a, b)| b - a).sum();
        println!(
            "| {seed} | {n} | {:.3} | {:.2} m | {told:.1} | {true_stand:.1} | {} |",
            inside as f64 / n as f64,
            (sq / n as f64).sqrt(),
            stand_rule.map_or("none".into(), |r| format!("{:.3} deg/s", r.threshold_dps)),
        );
        all_in += inside;
        all_n += n;
        all_sq += sq;
    }
    println!(
        "| all | {all_n} | {:.3} | {:.2} m | | | |",
        all_in as f64 / all_n as f64,
        (all_sq / all_n as f64).sqrt()
    );
    Ok(())
}
