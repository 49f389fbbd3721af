//! Whether a ride's gyro tells a standing vehicle from a moving one (the
//! rule `gyropath::standing` learns outside GNSS-speed gaps), on any ride
//! gyropath reads, with its own distance (wheel, CAN or GNSS speed) as the
//! truth of standing: the rule's threshold, the two classes' percentiles,
//! and how many of the logged stands of 2 s or more it finds.
//! `cargo run --release --example stand_rule -- RIDE...`

use std::path::Path;

use gyropath::import::ImportOptions;
use gyropath::standing::{MIN_STAND_S, activity, stand_rule};

fn main() -> anyhow::Result<()> {
    println!(
        "| ride | gyro rows | standing (s) | moving (s) | standing q95 | moving q05 | threshold | stands >= 2 s found |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for path in std::env::args().skip(1) {
        let imported = gyropath::pipeline::open(Path::new(&path), &ImportOptions::default())?;
        let sig = gyropath::pipeline::signals(imported)?;
        let t = &sig.t;
        let v: Vec<f64> = (0..t.len())
            .map(|j| {
                if sig.dt[j] > 0.0 {
                    sig.distance[j] / sig.dt[j]
                } else {
                    0.0
                }
            })
            .collect();
        let a = activity(t, |j| sig.gyro[j].map(f64::to_degrees).into());
        let no_gap = vec![false; t.len()];
        let (mut standing, mut moving) = (0.0, 0.0);
        for j in 1..t.len() {
            if v[j] < 0.3 && v[j - 1] < 0.3 {
                standing += sig.dt[j];
            } else if v[j] > 2.0 && v[j - 1] > 2.0 {
                moving += sig.dt[j];
            }
        }
        let rule = stand_rule(t, &v, &a, &no_gap);
        // Logged stands of MIN_STAND_S or more, and how many the rule finds
        // (most of the stand's rows below the threshold).
        let (mut stands, mut found) = (0, 0);
        let mut start: Option<usize> = None;
        for j in 0..=t.len() {
            let still = j < t.len() && v[j] < 0.3;
            match (still, start) {
                (true, None) => start = Some(j),
                (false, Some(s)) => {
                    if t[j - 1] - t[s] >= MIN_STAND_S {
                        stands += 1;
                        if let Some(r) = &rule {
                            let quiet = (s..j).filter(|&k| a[k] < r.threshold_dps).count();
                            found += (2 * quiet > j - s) as usize;
                        }
                    }
                    start = None;
                }
                _ => {}
            }
        }
        let name = Path::new(&path)
            .file_name()
            .map_or(path.clone(), |n| n.to_string_lossy().into());
        match rule {
            Some(r) => println!(
                "| {name} | {} | {standing:.0} | {moving:.0} | {:.3} deg/s | {:.3} deg/s | {:.3} deg/s | {found} of {stands} |",
                t.len(),
                r.standing_q95_dps,
                r.moving_q05_dps,
                r.threshold_dps
            ),
            None => println!(
                "| {name} | {} | {standing:.0} | {moving:.0} | | | none: the gyro cannot tell, or too little of either | {stands} logged |",
                t.len()
            ),
        }
    }
    Ok(())
}
