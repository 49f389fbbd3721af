//! How much of the Berlin city drive's error its odometer gain explains
//! (issue 28): the default fit, then the same model refitted with the gain
//! held at values around the reference's own (the CAN speed fitted to the
//! reference reads 0.992), under the noise settings the default found, each
//! measured against the reference; and the path's error split into its mean
//! (an offset the fixes share) and the rest. `cargo run --release --example
//! gain_oracle` (a few seconds; needs `../shared/real`).

use std::path::Path;
use std::sync::Arc;

use gyropath::contract::HeldParam;
use gyropath::diagnosis::reference::{compare, match_rows};
use gyropath::import::{ImportOptions, open, read_reference};
use gyropath::optimisation::{AutoNoise, FitSettings, Reconstruction};
use gyropath::signals::Signals;

fn main() -> anyhow::Result<()> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz");
    let opened = open(&dir.join("ride.csv"), &ImportOptions::default())?;
    let signals = Arc::new(Signals::from_log(&opened.log)?);
    let reference = read_reference(&dir.join("truth.csv"))?;
    let matched = match_rows(&signals, &reference)?;
    let mut default = Reconstruction::new(signals.clone(), FitSettings::default())?;
    default.finish();
    let found = default.model().spec.clone();
    let c = compare(default.model(), default.params(), &reference, &matched);
    println!("default: {:.2} m", c.horizontal.rms_m);
    for gain in [0.98, 0.992, 1.0, 1.0086, 1.02, 1.0385] {
        let settings = FitSettings {
            auto_noise: AutoNoise::OFF,
            model: gyropath::contract::ModelSpec {
                gps_tails: None,
                held: vec![HeldParam {
                    effect: "odometer_gain".into(),
                    name: "gain".into(),
                    value: gain,
                }],
                ..found.clone()
            },
            ..FitSettings::default()
        };
        let mut fit = Reconstruction::new(signals.clone(), settings)?;
        fit.finish();
        let c = compare(fit.model(), fit.params(), &reference, &matched);
        println!("gain held at {gain}: {:.2} m", c.horizontal.rms_m);
    }
    Ok(())
}
