//! GPS in a city (`gyropath simulate --gps urban`), on top of the open-sky
//! error (Gauss-Markov, correlated over a minute):
//!
//! - **Street canyons**: every 1-4 minutes the vehicle spends 20-90 s where
//!   only 4-6 satellites are seen (9-14 elsewhere). Every error below grows as
//!   `10 / satellites`.
//! - **Heavy tails**: a white error drawn from Student's t with 3 degrees of
//!   freedom (1 m scale in the open): most fixes are fine, a few are far off.
//! - **Pulled to one side**: in a canyon, reflections off one row of
//!   buildings pull the fixes 3-12 m sideways, perpendicular to the street,
//!   ramping in and out over 5 s.
//! - **Jumps**: about one every three minutes, a jump of 10-70 m in a random
//!   direction lasting 2-60 s (a wrong multipath lock).
//! - **The receiver's accuracy** (`gps_hacc_m`): it knows how many
//!   satellites it sees, not that it is locked onto a reflection:
//!   `1.5 m x 10 / satellites`, times 1-1.3, and only doubled in a jump.
//!
//! It draws from its own random stream, so a ride's other values are the
//! same as on open sky.

use nalgebra::Vector3;

use super::rng::Rng;

/// How the GPS sees the sky.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum GpsEnvironment {
    #[default]
    Open,
    Urban,
    /// Reflections that come and go, calibrated on a real city drive (see
    /// `simulation::reflections`).
    City,
}

impl std::str::FromStr for GpsEnvironment {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "open" => Ok(Self::Open),
            "urban" => Ok(Self::Urban),
            "city" => Ok(Self::City),
            other => Err(format!("gps '{other}' is none of open, urban, city")),
        }
    }
}

/// An episode of urban error: (start s, end s, size m).
pub type Episode = (f64, f64, f64);

/// The urban error process over one ride.
pub struct UrbanGps {
    rng: Rng,
    /// Canyons: (start, end, side pull m, side +-1).
    canyons: Vec<(f64, f64, f64, f64)>,
    /// Jumps: (start, end, offset east/north/up).
    jumps: Vec<(f64, f64, Vector3<f64>)>,
}

/// What the urban error adds to one fix.
pub struct UrbanFix {
    pub offset: Vector3<f64>,
    pub satellites: u32,
    /// The receiver's own 1-sigma horizontal accuracy (m).
    pub hacc: f64,
}

impl UrbanGps {
    pub fn new(mut rng: Rng, duration: f64) -> Self {
        let mut canyons = Vec::new();
        let mut t = rng.range(20.0, 90.0);
        while t < duration {
            let len = rng.range(20.0, 90.0);
            canyons.push((t, t + len, rng.range(3.0, 12.0), rng.sign()));
            t += len + rng.range(40.0, 180.0);
        }
        let mut jumps = Vec::new();
        let mut t = rng.range(30.0, 180.0);
        while t < duration {
            let len = rng.range(2.0, 60.0);
            let size = rng.range(10.0, 70.0);
            let dir = rng.range(0.0, std::f64::consts::TAU);
            jumps.push((
                t,
                t + len,
                Vector3::new(
                    size * dir.cos(),
                    size * dir.sin(),
                    0.5 * size * rng.normal(),
                ),
            ));
            t += len + rng.range(60.0, 300.0);
        }
        Self {
            rng,
            canyons,
            jumps,
        }
    }

    /// Canyons as (start, end, pull) and jumps as (start, end, size), for the truth.
    pub fn episodes(&self) -> (Vec<Episode>, Vec<Episode>) {
        (
            self.canyons.iter().map(|c| (c.0, c.1, c.2)).collect(),
            self.jumps
                .iter()
                .map(|j| (j.0, j.1, j.2.xy().norm()))
                .collect(),
        )
    }

    /// Student's t with 3 degrees of freedom: `z / sqrt(chi2_3 / 3)`.
    fn student3(&mut self) -> f64 {
        let z = self.rng.normal();
        let chi2: f64 = (0..3).map(|_| self.rng.normal().powi(2)).sum();
        z / (chi2 / 3.0).max(1e-6).sqrt()
    }

    /// The error of a fix at `t` on a vehicle heading `heading` (radians from east).
    pub fn fix(&mut self, t: f64, heading: f64) -> UrbanFix {
        let canyon = self.canyons.iter().find(|c| t >= c.0 && t < c.1).copied();
        let satellites = match canyon {
            Some(_) => 4 + (self.rng.uniform() * 3.0) as u32,
            None => 9 + (self.rng.uniform() * 6.0) as u32,
        };
        let scale = 10.0 / satellites as f64;
        let mut offset =
            Vector3::new(self.student3(), self.student3(), 1.5 * self.student3()) * scale;
        if let Some((a, b, pull, side)) = canyon {
            let ramp = ((t - a) / 5.0).min((b - t) / 5.0).clamp(0.0, 1.0);
            // Perpendicular to the street: left of the heading is (-sin, cos).
            offset += Vector3::new(-heading.sin(), heading.cos(), 0.0) * (side * pull * ramp);
        }
        let jump = self.jumps.iter().find(|j| t >= j.0 && t < j.1).map(|j| j.2);
        if let Some(j) = jump {
            offset += j;
        }
        let hacc = 1.5 * scale * self.rng.range(1.0, 1.3) * if jump.is_some() { 2.0 } else { 1.0 };
        UrbanFix {
            offset,
            satellites,
            hacc,
        }
    }
}
