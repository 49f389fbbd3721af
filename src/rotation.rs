//! Rotation conventions and the small pieces of SO(3) calculus the model needs.
//!
//! **Convention.** Hamilton quaternions; `q` maps sensor-frame vectors to the
//! local ENU frame, `v_world = q v_sensor q*`. Per-step increments are
//! expressed in the sensor frame and multiply on the right,
//! `q_t = q_{t-1} g_t` (paper eq. 1), so a positive rate about the sensor's
//! z (up) axis turns the forward vector from east towards north (a left turn).
//!
//! For derivatives a perturbation `eps` of the increment is a right (body)
//! perturbation, `g(theta + d) = g(theta) Exp(J(theta) d)`, and one of the
//! initial orientation a left (world) one.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// How a per-step rotation vector `theta = omega dt` becomes the increment `g_t`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Increment {
    /// The paper's eq. 3, `g = [1, theta/2]`, normalised so `q` stays a rotation.
    SmallAngle,
    /// The exponential map, `g = [cos(|theta|/2), sin(|theta|/2) theta/|theta|]`.
    #[default]
    Exact,
}

impl Increment {
    /// The increment quaternion for the rotation vector `theta`.
    #[inline]
    pub fn quaternion(self, theta: &Vector3<f64>) -> UnitQuaternion<f64> {
        match self {
            Increment::Exact => exp_quaternion(theta),
            Increment::SmallAngle => UnitQuaternion::from_quaternion(Quaternion::new(
                1.0,
                0.5 * theta.x,
                0.5 * theta.y,
                0.5 * theta.z,
            )),
        }
    }

    /// `J^T v` without forming `J`: for the exponential map
    /// `J_r^T v = v + a theta x v + b theta x (theta x v)` (the coefficients of
    /// [`right_jacobian`], `[theta]x^T = -[theta]x`). The adjoint sweep needs
    /// it at every step.
    #[inline]
    pub fn right_jacobian_transpose_mul(
        self,
        theta: &Vector3<f64>,
        v: &Vector3<f64>,
    ) -> Vector3<f64> {
        match self {
            Increment::Exact => {
                let (a, b) = right_jacobian_coefficients(theta.norm_squared());
                let tv = theta.cross(v);
                v + tv * a + theta.cross(&tv) * b
            }
            Increment::SmallAngle => self.right_jacobian(theta).transpose() * v,
        }
    }

    /// `J` with `g(theta + d) = g(theta) Exp(J d) + O(d^2)`.
    ///
    /// Exact map: the right Jacobian of SO(3). Small-angle map: `[1, theta/2]`
    /// normalised is the rotation by angle `2 atan(|theta|/2)` about `theta`, i.e.
    /// the rotation vector `phi = s(n) theta` with `s(n) = 2 atan(n/2)/n`, so
    /// `J = J_r(phi) (s I + s'(n)/n theta theta^T)`.
    #[inline]
    pub fn right_jacobian(self, theta: &Vector3<f64>) -> Matrix3<f64> {
        match self {
            Increment::Exact => right_jacobian(theta),
            Increment::SmallAngle => {
                let n2 = theta.norm_squared();
                let n = n2.sqrt();
                let (s, ds_over_n) = if n < 1e-4 {
                    (1.0 - n2 / 12.0 + n2 * n2 / 80.0, -1.0 / 6.0 + n2 / 20.0)
                } else {
                    let s = 2.0 * (0.5 * n).atan() / n;
                    let ds = (1.0 / (1.0 + 0.25 * n2) - s) / n;
                    (s, ds / n)
                };
                let phi = theta * s;
                right_jacobian(&phi)
                    * (Matrix3::identity() * s + theta * theta.transpose() * ds_over_n)
            }
        }
    }
}

/// `Exp(theta)` as a quaternion, `[cos(n/2), sin(n/2) theta/n]`; for the small
/// angles of one gyro step (`n < 0.03` rad) by its Taylor series, which is
/// exact to rounding there and needs no square root, sine or cosine.
#[inline]
pub fn exp_quaternion(theta: &Vector3<f64>) -> UnitQuaternion<f64> {
    let n2 = theta.norm_squared();
    if n2 < 1e-3 {
        let w = 1.0 - n2 / 8.0 + n2 * n2 / 384.0 - n2 * n2 * n2 / 46080.0;
        let s = 0.5 - n2 / 48.0 + n2 * n2 / 3840.0 - n2 * n2 * n2 / 645_120.0;
        UnitQuaternion::new_unchecked(Quaternion::new(w, s * theta.x, s * theta.y, s * theta.z))
    } else {
        UnitQuaternion::from_scaled_axis(*theta)
    }
}

/// The forward (x) axis of the sensor frame in the world, the first column of `R(q)`.
#[inline]
pub fn forward(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    Vector3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y + w * z),
        2.0 * (x * z - w * y),
    )
}

/// The cross-product matrix, `skew(a) b = a x b`.
#[inline]
pub fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Right Jacobian of SO(3): `Exp(phi + d) = Exp(phi) Exp(J_r(phi) d) + O(d^2)`,
/// `J_r = I - (1 - cos n)/n^2 [phi]x + (n - sin n)/n^3 [phi]x^2`.
#[inline]
pub fn right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let (a, b) = right_jacobian_coefficients(phi.norm_squared());
    let k = skew(phi);
    Matrix3::identity() - k * a + k * k * b
}

/// `((1 - cos n)/n^2, (n - sin n)/n^3)` for `n^2 = n2`, by Taylor series for small angles.
#[inline]
fn right_jacobian_coefficients(n2: f64) -> (f64, f64) {
    if n2 < 1e-2 {
        (
            0.5 - n2 / 24.0 + n2 * n2 / 720.0 - n2 * n2 * n2 / 40320.0,
            1.0 / 6.0 - n2 / 120.0 + n2 * n2 / 5040.0 - n2 * n2 * n2 / 362_880.0,
        )
    } else {
        let n = n2.sqrt();
        ((1.0 - n.cos()) / n2, (n - n.sin()) / (n2 * n))
    }
}

/// Left Jacobian of SO(3): `Exp(phi + d) = Exp(J_l(phi) d) Exp(phi) + O(d^2)`.
#[inline]
pub fn left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    right_jacobian(&-phi)
}

/// Heading of a horizontal direction, degrees clockwise from north (compass).
pub fn compass_deg(east: f64, north: f64) -> f64 {
    let h = east.atan2(north).to_degrees();
    if h < 0.0 { h + 360.0 } else { h }
}

/// An angle (rad) brought into `[-pi, pi)`: the difference of two headings
/// or courses as the shorter turn between them.
pub fn wrap_pi(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    a - two_pi * ((a + std::f64::consts::PI) / two_pi).floor()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_vectors() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(0.3, -0.2, 0.5),
            Vector3::new(1e-3, 2e-3, -5e-4),
            Vector3::new(1e-6, 0.0, 2e-7),
            Vector3::new(-1.2, 0.4, 2.0),
        ]
    }

    /// Log of a unit quaternion as a rotation vector.
    fn log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
        q.scaled_axis()
    }

    #[test]
    fn series_exponential_and_forward_axis_are_exact() {
        for theta in random_vectors()
            .into_iter()
            .chain([Vector3::new(0.01, -0.02, 0.015)])
        {
            let a = exp_quaternion(&theta);
            let b = UnitQuaternion::from_scaled_axis(theta);
            assert!((a.coords - b.coords).norm() < 1e-15, "{theta}");
            assert!((forward(&b) - b * Vector3::x()).norm() < 1e-15);
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        for inc in [Increment::Exact, Increment::SmallAngle] {
            for theta in random_vectors() {
                let j = inc.right_jacobian(&theta);
                let g0 = inc.quaternion(&theta);
                for axis in 0..3 {
                    let h = 1e-6;
                    let mut d = Vector3::zeros();
                    d[axis] = h;
                    let plus = log(&(g0.inverse() * inc.quaternion(&(theta + d))));
                    let minus = log(&(g0.inverse() * inc.quaternion(&(theta - d))));
                    let fd = (plus - minus) / (2.0 * h);
                    let an = j.column(axis);
                    assert!(
                        (fd - an).norm() < 1e-7,
                        "{inc:?} {theta} axis {axis}: {fd} vs {an}"
                    );
                }
            }
        }
        for phi in random_vectors() {
            let jl = left_jacobian(&phi);
            let q = UnitQuaternion::from_scaled_axis(phi);
            for axis in 0..3 {
                let h = 1e-6;
                let mut d = Vector3::zeros();
                d[axis] = h;
                let plus = log(&(UnitQuaternion::from_scaled_axis(phi + d) * q.inverse()));
                let minus = log(&(UnitQuaternion::from_scaled_axis(phi - d) * q.inverse()));
                assert!(((plus - minus) / (2.0 * h) - jl.column(axis)).norm() < 1e-7);
            }
        }
    }

    /// Hand-computed turn: +90 deg/s about z for one second, in 100 steps,
    /// starting east, ends facing north; the small-angle map agrees to 1e-6 rad.
    #[test]
    fn left_turn_by_hand() {
        for inc in [Increment::Exact, Increment::SmallAngle] {
            let mut q = UnitQuaternion::identity();
            let theta = Vector3::new(0.0, 0.0, 90f64.to_radians() * 0.01);
            for _ in 0..100 {
                q *= inc.quaternion(&theta);
            }
            let fwd = q * Vector3::x();
            // The small-angle map turns by 2 atan(theta/2) = theta - theta^3/12 per step:
            // 100 steps of 0.0157 rad lose 3e-5 rad.
            let tol = if inc == Increment::Exact { 1e-12 } else { 1e-4 };
            assert!((fwd - Vector3::y()).norm() < tol, "{inc:?}: {fwd}");
            let compass = compass_deg(fwd.x, fwd.y);
            assert!(!(0.01..=359.99).contains(&compass), "{compass}");
        }
        // Nose-up pitch is a negative rotation about the left (y) axis.
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, -0.1, 0.0));
        assert!((q * Vector3::x()).z > 0.0);
        assert!((compass_deg(1.0, 0.0) - 90.0).abs() < 1e-12);
    }
}
