//! GPS among tall buildings as a real city drive shows it
//! (`gyropath simulate --gps city`), calibrated on the shared half of the
//! smartLoc Berlin Potsdamer Platz drive against its reference
//! (`examples/gps_errors.rs` sets the two side by side). Where
//! `--gps urban` offers a clean majority of fixes a few metres off and
//! errors correlated for tens of seconds, a street of glass and stone has:
//!
//! - **Reflections that come and go**: a fix is locked onto a reflection
//!   with a chance [`REFLECTION_START`] a second, for a run of seconds
//!   (ending with [`REFLECTION_END`] a second: 2.5 s on average), thrown
//!   10 m plus an exponential of mean 15 m (at most 75 m) in a direction of
//!   its own (heights 1.5 times as far).
//! - **A broad error underneath**: a wander correlated over
//!   [`SLOW_TAU_S`] (sd [`SLOW_SD_M`] per axis) plus a fix-to-fix part
//!   (sd [`FAST_SD_M`]): no fix is reliably within a few metres.
//! - **Fixes missing in runs**: the receiver loses its solution with a
//!   chance [`LOSE_FIX`] a second and regains it with [`REGAIN_FIX`]
//!   (a fix in about 60 % of the seconds).
//!
//! It draws from its own random stream, so a ride's other values are the
//! same as on open sky.

use nalgebra::Vector3;

use super::rng::Rng;

/// Chance a second that a reflection starts, and that one ends.
pub const REFLECTION_START: f64 = 0.2;
pub const REFLECTION_END: f64 = 0.4;
/// The wander underneath: correlation time (s) and sd per axis (m).
pub const SLOW_TAU_S: f64 = 15.0;
pub const SLOW_SD_M: f64 = 8.0;
/// The fix-to-fix part (m per axis).
pub const FAST_SD_M: f64 = 3.0;
/// Chance a second of losing the fix, and of regaining it.
pub const LOSE_FIX: f64 = 0.25;
pub const REGAIN_FIX: f64 = 0.45;

/// The reflection process over one ride, stepped once per fix epoch.
pub struct Reflections {
    rng: Rng,
    slow: Vector3<f64>,
    reflection: Option<Vector3<f64>>,
    has_fix: bool,
}

impl Reflections {
    pub fn new(rng: Rng) -> Self {
        Self {
            rng,
            slow: Vector3::zeros(),
            reflection: None,
            has_fix: true,
        }
    }

    /// The error of the fix of the next epoch, `dt` seconds after the last;
    /// `None` when the receiver has no solution then.
    pub fn fix(&mut self, dt: f64) -> Option<Vector3<f64>> {
        let per_second = |p: f64| 1.0 - (1.0 - p).powf(dt);
        let a = (-dt / SLOW_TAU_S).exp();
        let drive = SLOW_SD_M * (1.0 - a * a).sqrt();
        self.slow = self.slow * a
            + Vector3::new(
                self.rng.normal(),
                self.rng.normal(),
                1.5 * self.rng.normal(),
            ) * drive;
        self.reflection = match self.reflection {
            Some(r) if self.rng.uniform() >= per_second(REFLECTION_END) => Some(r),
            Some(_) => None,
            None if self.rng.uniform() < per_second(REFLECTION_START) => {
                // 10 m and an exponential tail of mean 15 m, at most 75 m.
                let size = (10.0 - 15.0 * (1.0 - self.rng.uniform()).ln()).min(75.0);
                let dir = self.rng.range(0.0, std::f64::consts::TAU);
                Some(Vector3::new(
                    size * dir.cos(),
                    size * dir.sin(),
                    1.5 * size * self.rng.normal(),
                ))
            }
            None => None,
        };
        self.has_fix = if self.has_fix {
            self.rng.uniform() >= per_second(LOSE_FIX)
        } else {
            self.rng.uniform() < per_second(REGAIN_FIX)
        };
        let fast = Vector3::new(
            self.rng.normal(),
            self.rng.normal(),
            1.5 * self.rng.normal(),
        ) * FAST_SD_M;
        self.has_fix
            .then(|| self.slow + fast + self.reflection.unwrap_or_else(Vector3::zeros))
    }
}

#[cfg(test)]
mod tests {
    use crate::diagnosis::reference::{GpsErrorStatistics, match_rows};
    use crate::simulation::{GpsEnvironment, SimConfig, simulate};

    #[test]
    fn a_simulated_city_looks_like_the_real_one_against_its_truth() {
        // Berlin's shared half (83 fixes): median 14.1 m, 46 % over 15 m in
        // runs of 2.5, correlation 0.51 / 0.32 / 0.18 at 1 / 5 / 10 s, a fix
        // in 59 % of the seconds. Bands wide enough for 10 minutes of one seed.
        let sim = simulate(&SimConfig {
            seed: 7,
            duration_s: 600.0,
            gps: GpsEnvironment::City,
            ..SimConfig::default()
        })
        .unwrap();
        let log = crate::import::parse(sim.log_csv.as_bytes(), "city.csv").unwrap();
        let sig = crate::signals::Signals::from_log(&log).unwrap();
        let truth =
            crate::import::reference::parse_reference(sim.truth_csv.as_bytes(), "truth.csv")
                .unwrap();
        let g = GpsErrorStatistics::of(&sig, &match_rows(&sig, &truth).unwrap()).unwrap();
        assert!((10.0..18.0).contains(&g.error.median_m), "{g:?}");
        assert!((15.0..26.0).contains(&g.error.rms_m), "{g:?}");
        assert!((0.3..0.55).contains(&g.over_15m), "{g:?}");
        assert!((1.5..3.5).contains(&g.mean_run_over_15m), "{g:?}");
        let r1 = g.correlation[0].1.unwrap();
        assert!((0.4..0.8).contains(&r1), "{g:?}");
        assert!(g.correlation[3].1.unwrap().abs() < 0.25, "{g:?}");
        assert!((0.45..0.65).contains(&g.availability), "{g:?}");
    }
}
