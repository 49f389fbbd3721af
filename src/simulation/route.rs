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

/// The true motion of one ride.
#[derive(Clone, Debug)]
pub struct Route {
    kappa: Vec<f64>,
    grade: Vec<f64>,
    psi: Vec<f64>,
    pos: Vec<Vector3<f64>>,
    /// Knots of the time <-> arc-length map: (t, s) increasing in t.
    knots: Vec<(f64, f64)>,
    pub stops: usize,
}

/// The state at one instant.
#[derive(Clone, Copy, Debug)]
pub struct State {
    pub s: f64,
    pub speed: f64,
    pub position: Vector3<f64>,
    pub attitude: UnitQuaternion<f64>,
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
        let pitch = Self::interp(&self.grade, s).atan();
        let kappa = Self::interp(&self.kappa, s);
        let pedalling = (speed / 2.0).min(1.0);
        let roll = -(speed * speed * kappa / G).atan()
            + SWAY_AMPLITUDE * pedalling * (std::f64::consts::TAU * SWAY_HZ * t).sin();
        let attitude = UnitQuaternion::from_scaled_axis(Vector3::z() * psi)
            * UnitQuaternion::from_scaled_axis(Vector3::y() * -pitch)
            * UnitQuaternion::from_scaled_axis(Vector3::x() * roll);
        State {
            s,
            speed,
            position,
            attitude,
        }
    }
}
