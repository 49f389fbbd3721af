//! The simulated ride's true motion, with its own kinematics.
//!
//! A route is planned along arc length `s` (grid of [`DS`] metres): curvature
//! `kappa(s)` from straights, turns of 8-60 m radius and roundabouts, grade
//! from gentle hills and bridges, and stops at lights. A speed profile obeys
//! a lateral-acceleration limit in turns and acceleration / braking limits,
//! and gives the time of every grid point (stops add their dwell time). The
//! true attitude at time `t` is `Rz(psi) Ry(-pitch) Rx(roll)`, with the bike
//! leaning into turns, `roll = -atan(v^2 kappa / g)`, and swaying while
//! pedalling. Positions are integrated on the grid with the exact slope.
//! Nothing here is shared with the model it tests.

use nalgebra::{UnitQuaternion, Vector3};

use super::rng::Rng;

/// Grid spacing along the route (m).
pub const DS: f64 = 0.25;
const G: f64 = 9.81;
const LATERAL_ACCEL: f64 = 2.0;
const ACCEL: f64 = 0.7;
const BRAKE: f64 = 1.2;
/// Pedalling sway: roll amplitude (rad) and frequency (Hz).
const SWAY_AMPLITUDE: f64 = 0.025;
const SWAY_HZ: f64 = 1.1;

/// What drives the route.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Vehicle {
    #[default]
    Bicycle,
    Car,
    Robot,
}

impl std::str::FromStr for Vehicle {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "bicycle" => Ok(Self::Bicycle),
            "car" => Ok(Self::Car),
            "robot" => Ok(Self::Robot),
            other => Err(format!("vehicle '{other}' is none of bicycle, car, robot")),
        }
    }
}

/// The true motion of one ride.
#[derive(Clone, Debug)]
pub struct Route {
    kappa: Vec<f64>,
    grade: Vec<f64>,
    /// Heading of the vehicle (the direction of travel turned round while reversing).
    psi: Vec<f64>,
    pos: Vec<Vector3<f64>>,
    /// Knots of the time <-> arc-length map: (t, s) increasing in t.
    knots: Vec<(f64, f64)>,
    pub stops: usize,
    vehicle: Vehicle,
    /// Signed distance along the route (runs backwards while reversing), when it reverses.
    signed: Option<Vec<f64>>,
    /// Roll and pitch shaking of a skid-steer robot: (amplitude rad, frequency Hz, phase) per axis.
    shake: [[(f64, f64, f64); 3]; 2],
    /// Metres driven in reverse.
    pub reversed_m: f64,
}

/// The state at one instant.
#[derive(Clone, Copy, Debug)]
pub struct State {
    pub s: f64,
    pub speed: f64,
    /// Signed distance driven (what a wheel-speed odometer integrates).
    pub odo: f64,
    /// Signed speed (negative while reversing).
    pub velocity: f64,
    pub position: Vector3<f64>,
    pub attitude: UnitQuaternion<f64>,
}

/// How a car or robot route is made.
struct Profile {
    lateral_accel: f64,
    accel: f64,
    brake: f64,
    /// Curvature smoothing window (m).
    smooth_m: f64,
}

/// Curvature, grade and cruising speed along the route, one value per grid point.
#[derive(Default)]
struct Plan {
    kappa: Vec<f64>,
    grade: Vec<f64>,
    cruise: Vec<f64>,
}

impl Plan {
    /// Append `len` metres of constant curvature `k`, grade `g` and cruising speed `v`.
    fn push(&mut self, len: f64, k: f64, g: f64, v: f64) {
        for _ in 0..(len / DS).round() as usize {
            self.kappa.push(k);
            self.grade.push(g);
            self.cruise.push(v);
        }
    }
}

fn smooth(v: &[f64], window: usize) -> Vec<f64> {
    let n = v.len();
    let half = window / 2;
    let mut prefix = vec![0.0; n + 1];
    for i in 0..n {
        prefix[i + 1] = prefix[i] + v[i];
    }
    (0..n)
        .map(|i| {
            let a = i.saturating_sub(half);
            let b = (i + half + 1).min(n);
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

impl Route {
    /// Plan a route long enough for `duration` seconds of riding.
    pub fn plan(rng: &mut Rng, duration: f64) -> Self {
        let target = duration * 9.0 + 500.0;
        let mut plan = Plan::default();
        let mut stop_at: Vec<(usize, f64)> = Vec::new();
        // Start on a straight.
        plan.push(60.0, 0.0, 0.0, 5.5);
        while (plan.kappa.len() as f64) * DS < target {
            let v = rng.range(4.5, 7.5);
            let pick = rng.uniform();
            if pick < 0.42 {
                plan.push(rng.range(40.0, 250.0), 0.0, 0.0, v);
                if rng.uniform() < 0.3 {
                    stop_at.push((plan.kappa.len() - 1, rng.range(10.0, 40.0)));
                }
            } else if pick < 0.80 {
                let r = rng.range(8.0, 60.0);
                let angle = rng.range(30f64, 120.0).to_radians();
                plan.push(r * angle, rng.sign() / r, 0.0, v);
            } else if pick < 0.90 {
                // Roundabout (right-hand traffic): right in, counter-clockwise round, right out.
                let r = rng.range(10.0, 18.0);
                let exit = rng.range(90f64, 270.0).to_radians();
                let flare = 45f64.to_radians();
                plan.push(12.0 * flare, -1.0 / 12.0, 0.0, 4.0);
                plan.push(r * (exit + 2.0 * flare), 1.0 / r, 0.0, 4.0);
                plan.push(12.0 * flare, -1.0 / 12.0, 0.0, 4.0);
            } else {
                // Bridge: ramp up, level span, ramp down.
                let g = rng.range(0.03, 0.06);
                plan.push(60.0, 0.0, g, v);
                plan.push(rng.range(30.0, 120.0), 0.0, 0.0, v);
                plan.push(60.0, 0.0, -g, v);
            }
        }
        let Plan {
            kappa,
            grade,
            cruise,
        } = plan;
        let n = kappa.len();
        let kappa = smooth(&kappa, (4.0 / DS) as usize);
        let hill_phase = rng.range(0.0, std::f64::consts::TAU);
        let hill_len = rng.range(500.0, 900.0);
        let grade: Vec<f64> = smooth(&grade, (10.0 / DS) as usize)
            .iter()
            .enumerate()
            .map(|(i, g)| {
                g + 0.015 * (std::f64::consts::TAU * i as f64 * DS / hill_len + hill_phase).sin()
            })
            .collect();
        let cruise = smooth(&cruise, (20.0 / DS) as usize);

        // Speed profile: limits, then acceleration and braking passes.
        let mut v: Vec<f64> = (0..n)
            .map(|i| cruise[i].min((LATERAL_ACCEL / kappa[i].abs().max(1e-9)).sqrt()))
            .collect();
        v[0] = 0.0;
        for &(i, _) in &stop_at {
            v[i] = 0.0;
        }
        for i in 1..n {
            v[i] = v[i].min((v[i - 1] * v[i - 1] + 2.0 * ACCEL * DS).sqrt());
        }
        for i in (0..n - 1).rev() {
            v[i] = v[i].min((v[i + 1] * v[i + 1] + 2.0 * BRAKE * DS).sqrt());
        }
        let mut knots = Vec::with_capacity(n + 2 * stop_at.len());
        let mut t = 0.0;
        let mut stops = stop_at.iter().peekable();
        knots.push((0.0, 0.0));
        for i in 1..n {
            t += 2.0 * DS / (v[i - 1] + v[i]);
            knots.push((t, i as f64 * DS));
            if let Some(&&(si, dwell)) = stops.peek()
                && si == i
            {
                t += dwell;
                knots.push((t, i as f64 * DS));
                stops.next();
            }
        }
        // Heading and position on the grid.
        let mut psi = vec![rng.range(0.0, std::f64::consts::TAU); n];
        let mut pos = vec![Vector3::zeros(); n];
        for i in 1..n {
            psi[i] = psi[i - 1] + 0.5 * (kappa[i - 1] + kappa[i]) * DS;
            let pitch = (0.5 * (grade[i - 1] + grade[i])).atan();
            let h = 0.5 * (psi[i - 1] + psi[i]);
            pos[i] = pos[i - 1]
                + Vector3::new(pitch.cos() * h.cos(), pitch.cos() * h.sin(), pitch.sin()) * DS;
        }
        Self {
            kappa,
            grade,
            psi,
            pos,
            knots,
            stops: stop_at.len(),
            vehicle: Vehicle::Bicycle,
            signed: None,
            shake: [[(0.0, 0.0, 0.0); 3]; 2],
            reversed_m: 0.0,
        }
    }

    /// Plan a route of `vehicle` long enough for `duration` seconds.
    pub fn plan_for(vehicle: Vehicle, rng: &mut Rng, duration: f64) -> Self {
        match vehicle {
            Vehicle::Bicycle => Self::plan(rng, duration),
            Vehicle::Car => Self::plan_car(rng, duration),
            Vehicle::Robot => Self::plan_robot(rng, duration),
        }
    }

    /// A car: out of a parking bay backwards, then town and arterial roads.
    fn plan_car(rng: &mut Rng, duration: f64) -> Self {
        let target = duration * 14.0 + 800.0;
        let mut plan = Plan::default();
        let mut reverse = Vec::new();
        let mut stop_at: Vec<(usize, f64)> = Vec::new();
        // Reverse out of the bay on a 6 m arc, stop, then drive off.
        let side = rng.sign();
        plan.push(rng.range(6.0, 9.0), side / 6.0, 0.0, 1.5);
        reverse.resize(plan.kappa.len(), true);
        stop_at.push((plan.kappa.len() - 1, rng.range(1.5, 3.0)));
        plan.push(30.0, 0.0, 0.0, 8.0);
        while (plan.kappa.len() as f64) * DS < target {
            let v = rng.range(10.0, 20.0);
            let pick = rng.uniform();
            if pick < 0.35 {
                plan.push(rng.range(100.0, 400.0), 0.0, 0.0, v);
                if rng.uniform() < 0.35 {
                    stop_at.push((plan.kappa.len() - 1, rng.range(10.0, 40.0)));
                }
            } else if pick < 0.55 {
                // An intersection: a right-angle turn of 10-20 m radius.
                let r = rng.range(10.0, 20.0);
                plan.push(
                    r * rng.range(80f64, 100.0).to_radians(),
                    rng.sign() / r,
                    0.0,
                    6.0,
                );
            } else if pick < 0.75 {
                let r = rng.range(150.0, 500.0);
                plan.push(
                    r * rng.range(20f64, 60.0).to_radians(),
                    rng.sign() / r,
                    0.0,
                    v,
                );
            } else if pick < 0.9 {
                // A lane change: 3.5 m sideways over 40-70 m (curvature +k then -k).
                let l = rng.range(40.0, 70.0);
                let k = rng.sign() * 4.0 * 3.5 / (l * l);
                plan.push(l / 2.0, k, 0.0, v);
                plan.push(l / 2.0, -k, 0.0, v);
            } else {
                let g = rng.sign() * rng.range(0.03, 0.07);
                plan.push(150.0, 0.0, g, v);
                plan.push(rng.range(50.0, 200.0), 0.0, 0.0, v);
                plan.push(150.0, 0.0, -g, v);
            }
        }
        let profile = Profile {
            lateral_accel: 3.0,
            accel: 2.0,
            brake: 3.0,
            smooth_m: 6.0,
        };
        Self::finish(rng, plan, reverse, stop_at, &profile, Vehicle::Car)
    }

    /// A skid-steer robot: short straights, tight turns, stops, shaking.
    fn plan_robot(rng: &mut Rng, duration: f64) -> Self {
        let target = duration * 0.9 + 40.0;
        let mut plan = Plan::default();
        let mut stop_at: Vec<(usize, f64)> = Vec::new();
        plan.push(5.0, 0.0, 0.0, 0.8);
        while (plan.kappa.len() as f64) * DS < target {
            let v = rng.range(0.5, 1.0);
            let pick = rng.uniform();
            if pick < 0.5 {
                plan.push(rng.range(10.0, 40.0), 0.0, 0.0, v);
                if rng.uniform() < 0.2 {
                    stop_at.push((plan.kappa.len() - 1, rng.range(3.0, 15.0)));
                }
            } else if pick < 0.9 {
                let r = rng.range(1.5, 6.0);
                plan.push(
                    r * rng.range(30f64, 150.0).to_radians(),
                    rng.sign() / r,
                    0.0,
                    0.5,
                );
            } else {
                let g = rng.sign() * rng.range(0.02, 0.05);
                plan.push(8.0, 0.0, g, v);
                plan.push(8.0, 0.0, -g, v);
            }
        }
        let profile = Profile {
            lateral_accel: 0.4,
            accel: 0.5,
            brake: 0.8,
            smooth_m: 1.0,
        };
        let mut route = Self::finish(rng, plan, Vec::new(), stop_at, &profile, Vehicle::Robot);
        // Rate amplitude 1.2 deg/s per component, three components per axis: 1.5 deg/s RMS.
        for axis in &mut route.shake {
            for c in axis.iter_mut() {
                let f = rng.range(2.0, 7.0);
                *c = (
                    1.2f64.to_radians() / (std::f64::consts::TAU * f),
                    f,
                    rng.range(0.0, std::f64::consts::TAU),
                );
            }
        }
        route
    }

    /// Speed profile, times, headings and positions of a planned car or robot route.
    fn finish(
        rng: &mut Rng,
        plan: Plan,
        mut reverse: Vec<bool>,
        stop_at: Vec<(usize, f64)>,
        profile: &Profile,
        vehicle: Vehicle,
    ) -> Self {
        let Plan {
            kappa,
            grade,
            cruise,
        } = plan;
        let n = kappa.len();
        reverse.resize(n, false);
        let kappa = smooth(&kappa, ((profile.smooth_m / DS) as usize).max(1));
        let grade = smooth(&grade, (10.0 / DS) as usize);
        let cruise = smooth(&cruise, (10.0 / DS) as usize);
        let mut v: Vec<f64> = (0..n)
            .map(|i| cruise[i].min((profile.lateral_accel / kappa[i].abs().max(1e-9)).sqrt()))
            .collect();
        v[0] = 0.0;
        for &(i, _) in &stop_at {
            v[i] = 0.0;
        }
        for i in 1..n {
            v[i] = v[i].min((v[i - 1] * v[i - 1] + 2.0 * profile.accel * DS).sqrt());
        }
        for i in (0..n - 1).rev() {
            v[i] = v[i].min((v[i + 1] * v[i + 1] + 2.0 * profile.brake * DS).sqrt());
        }
        let mut knots = Vec::with_capacity(n + 2 * stop_at.len());
        let mut t = 0.0;
        let mut stops = stop_at.iter().peekable();
        knots.push((0.0, 0.0));
        for i in 1..n {
            t += 2.0 * DS / (v[i - 1] + v[i]).max(1e-6);
            knots.push((t, i as f64 * DS));
            if let Some(&&(si, dwell)) = stops.peek()
                && si == i
            {
                t += dwell;
                knots.push((t, i as f64 * DS));
                stops.next();
            }
        }
        // The heading runs on smoothly; the direction of travel is it turned
        // round while reversing (a car reversing on an arc turns the other way).
        let mut psi = vec![rng.range(0.0, std::f64::consts::TAU); n];
        let mut pos = vec![Vector3::zeros(); n];
        let mut signed = vec![0.0; n];
        let back = |i: usize| if reverse[i] { -1.0 } else { 1.0 };
        for i in 1..n {
            // Curvature and grade belong to the direction of travel, which the
            // heading follows at a fixed offset (pi while reversing).
            let dir = back(i);
            psi[i] = psi[i - 1] + 0.5 * (kappa[i - 1] + kappa[i]) * DS;
            let pitch = (0.5 * (grade[i - 1] + grade[i])).atan();
            let h =
                0.5 * (psi[i - 1] + psi[i]) + if dir < 0.0 { std::f64::consts::PI } else { 0.0 };
            pos[i] = pos[i - 1]
                + Vector3::new(pitch.cos() * h.cos(), pitch.cos() * h.sin(), pitch.sin()) * DS;
            signed[i] = signed[i - 1] + dir * DS;
        }
        let reversed_m = reverse.iter().filter(|&&r| r).count() as f64 * DS;
        Self {
            kappa,
            grade,
            psi,
            pos,
            knots,
            stops: stop_at.len(),
            vehicle,
            signed: (reversed_m > 0.0).then_some(signed),
            shake: [[(0.0, 0.0, 0.0); 3]; 2],
            reversed_m,
        }
    }

    /// Time at which the route's grid ends (s).
    pub fn end_time(&self) -> f64 {
        self.knots.last().map_or(0.0, |k| k.0)
    }

    fn interp(v: &[f64], s: f64) -> f64 {
        let x = (s / DS).clamp(0.0, (v.len() - 1) as f64);
        let i = (x.floor() as usize).min(v.len().saturating_sub(2));
        let f = x - i as f64;
        v[i] * (1.0 - f) + v[i + 1] * f
    }

    /// Arc length and speed at time `t`.
    fn s_at(&self, t: f64) -> (f64, f64) {
        let k = self
            .knots
            .partition_point(|&(tk, _)| tk <= t)
            .clamp(1, self.knots.len() - 1);
        let (t0, s0) = self.knots[k - 1];
        let (t1, s1) = self.knots[k];
        let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        (s0 + f * (s1 - s0), (s1 - s0) / (t1 - t0))
    }

    /// True state at time `t`.
    pub fn state(&self, t: f64) -> State {
        let (s, speed) = self.s_at(t);
        let x = (s / DS).clamp(0.0, (self.pos.len() - 1) as f64);
        let i = (x.floor() as usize).min(self.pos.len() - 2);
        let f = x - i as f64;
        let position = self.pos[i] * (1.0 - f) + self.pos[i + 1] * f;
        let psi = Self::interp(&self.psi, s);
        let kappa = Self::interp(&self.kappa, s);
        let (odo, velocity) = match &self.signed {
            Some(signed) => {
                let odo = Self::interp(signed, s);
                let back = signed[i + 1] < signed[i];
                (odo, if back { -speed } else { speed })
            }
            None => (s, speed),
        };
        let (roll, pitch) = match self.vehicle {
            Vehicle::Bicycle => {
                let pedalling = (speed / 2.0).min(1.0);
                (
                    -(speed * speed * kappa / G).atan()
                        + SWAY_AMPLITUDE * pedalling * (std::f64::consts::TAU * SWAY_HZ * t).sin(),
                    Self::interp(&self.grade, s).atan(),
                )
            }
            // A car's body rolls outwards, about 0.45 deg per m/s^2 of lateral acceleration.
            Vehicle::Car => (
                0.008 * velocity.signum() * speed * speed * kappa,
                velocity.signum() * Self::interp(&self.grade, s).atan(),
            ),
            Vehicle::Robot => {
                let moving = (speed / 0.3).min(1.0);
                let jolt = |axis: &[(f64, f64, f64); 3]| {
                    moving
                        * axis
                            .iter()
                            .map(|&(a, fq, ph)| a * (std::f64::consts::TAU * fq * t + ph).sin())
                            .sum::<f64>()
                };
                (
                    jolt(&self.shake[0]),
                    Self::interp(&self.grade, s).atan() + jolt(&self.shake[1]),
                )
            }
        };
        let attitude = UnitQuaternion::from_scaled_axis(Vector3::z() * psi)
            * UnitQuaternion::from_scaled_axis(Vector3::y() * -pitch)
            * UnitQuaternion::from_scaled_axis(Vector3::x() * roll);
        State {
            s,
            speed,
            odo,
            velocity,
            position,
            attitude,
        }
    }
}
