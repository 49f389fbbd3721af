//! Sensor temperature of a logger box on a bicycle: a first-order thermal
//! model, so that the temperature channel moves the way a real one does
//! (and a temperature-dependent bias with it).
//!
//! The box (heat capacity `C`) gains heat from its electronics and the sun
//! and loses it to the air by convection, which grows with airspeed:
//!
//! ```text
//! C dT/dt = P_elec + s(t) P_sun - h0 (1 + v / v0) (T - T_air)
//! ```
//!
//! so `T` relaxes towards `T_air + (rise_elec + s(t) rise_sun) / (1 + v / v0)`
//! with time constant `tau / (1 + v / v0)` (`tau = C / h0`, the still-air
//! one). Riding cools the box within a minute or so; it warms at every stop
//! at the lights and in every stretch of sunshine `s(t) = 1` (shade, trees
//! and buildings: `s = 0.2`). The bike stood outside before the ride, so the
//! box starts at its resting equilibrium. Each step uses the exact solution
//! for constant inputs over the step.
//!
//! The still-air time constant of a small logger is one to two minutes, so
//! the temperature moves by a degree or more within a minute at stops and
//! between sun and shade: faster than a gyro bias random walk of a few
//! thousandths of a deg/s/sqrt(s) can follow, which is what lets a
//! temperature-dependent bias be told apart from that walk.

use super::rng::Rng;

/// Airspeed (m/s) at which convection doubles.
const V0: f64 = 4.0;
/// Sun fraction in shade.
const SHADE: f64 = 0.2;

pub struct Thermal {
    air: f64,
    tau_still: f64,
    rise_elec: f64,
    rise_sun: f64,
    temp: f64,
    sun: bool,
    /// Time left until sun and shade change over (s).
    next_change: f64,
    rng: Rng,
}

impl Thermal {
    /// A box at rest in air at `air` degrees whose still-air time constant
    /// is `tau_still` seconds; heating and the sunshine pattern are drawn from `rng`.
    pub fn new(mut rng: Rng, air: f64, tau_still: f64) -> Self {
        let rise_elec = rng.range(3.0, 5.0);
        let rise_sun = rng.range(5.0, 12.0);
        let sun = rng.uniform() < 0.5;
        let next_change = rng.range(20.0, 150.0);
        let mut box_ = Self {
            air,
            tau_still,
            rise_elec,
            rise_sun,
            temp: air,
            sun,
            next_change,
            rng,
        };
        box_.temp = box_.target(0.0);
        box_
    }

    /// Where the temperature relaxes to at `speed` m/s in the current sunshine.
    fn target(&self, speed: f64) -> f64 {
        let sun = if self.sun { 1.0 } else { SHADE };
        self.air + (self.rise_elec + sun * self.rise_sun) / self.convection(speed)
    }

    /// Convective heat loss relative to still air.
    fn convection(&self, speed: f64) -> f64 {
        1.0 + speed.max(0.0) / V0
    }

    /// The temperature now.
    pub fn temperature(&self) -> f64 {
        self.temp
    }

    /// Advance by `dt` seconds at `speed` m/s.
    pub fn step(&mut self, speed: f64, dt: f64) {
        self.next_change -= dt;
        if self.next_change <= 0.0 {
            self.sun = !self.sun;
            self.next_change += self.rng.range(20.0, 150.0);
        }
        let target = self.target(speed);
        let decay = (-dt * self.convection(speed) / self.tau_still).exp();
        self.temp = target + (self.temp - target) * decay;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn riding_cools_the_box_and_a_stop_warms_it() {
        let mut th = Thermal::new(Rng::new(3), 10.0, 100.0);
        let resting = th.temperature();
        assert!(resting > 13.0, "{resting}");
        for _ in 0..30_000 {
            th.step(6.0, 0.01);
        }
        let riding = th.temperature();
        assert!(riding < resting - 2.0 && riding > 10.0, "{riding}");
        for _ in 0..3_000 {
            th.step(0.0, 0.01);
        }
        assert!(th.temperature() > riding + 0.3, "{}", th.temperature());
    }
}
