//! How a sensor sits on the vehicle, as the data need it: which logged axis,
//! with which sign, is the ride-log's forward (x), left (y) and up (z), and a
//! unit factor for a gyro logged in other units than its label says.
//!
//! ```text
//! g_ride[i] = scale * sign[i] * g_logged[axis[i]]      (gyro)
//! a_ride[i] =         sign[i] * a_logged[axis[i]]      (accelerometer)
//! ```
//!
//! Written and parsed as `x=-z,y=-x,z=y` (the `g` of `gx = -z` may be given),
//! with `,scale=57.29578` appended when the unit factor is not 1. Only proper
//! rotations are accepted: a mirrored frame cannot be a real mounting.

use super::RideLog;

/// A signed permutation of the axes, and a gyro unit factor.
#[derive(Clone, Debug, PartialEq)]
pub struct Mount {
    /// Logged axis (0 x, 1 y, 2 z) that each ride axis takes.
    pub axis: [usize; 3],
    pub sign: [f64; 3],
    /// Multiplies the gyro (57.29578 when rad/s were logged as deg/s).
    pub scale: f64,
}

const NAMES: [char; 3] = ['x', 'y', 'z'];

impl Mount {
    pub fn identity() -> Self {
        Self {
            axis: [0, 1, 2],
            sign: [1.0; 3],
            scale: 1.0,
        }
    }

    pub fn is_identity(&self) -> bool {
        *self == Self::identity()
    }

    /// The mounting whose forward and up are the given signed logged axes
    /// (left completes a right-handed frame: left = up x forward).
    pub fn from_forward_up(forward: (usize, f64), up: (usize, f64)) -> Option<Self> {
        if forward.0 == up.0 || forward.0 > 2 || up.0 > 2 {
            return None;
        }
        let unit = |(a, s): (usize, f64)| {
            let mut v = [0.0; 3];
            v[a] = s.signum();
            v
        };
        let (f, u) = (unit(forward), unit(up));
        let left = [
            u[1] * f[2] - u[2] * f[1],
            u[2] * f[0] - u[0] * f[2],
            u[0] * f[1] - u[1] * f[0],
        ];
        let l = (0..3).find(|&i| left[i] != 0.0)?;
        Some(Self {
            axis: [forward.0, l, up.0],
            sign: [forward.1.signum(), left[l], up.1.signum()],
            scale: 1.0,
        })
    }

    /// The rotation matrix's determinant: +1 for a proper mounting.
    fn determinant(&self) -> f64 {
        let mut m = [[0.0; 3]; 3];
        for i in 0..3 {
            m[i][self.axis[i]] = self.sign[i];
        }
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// One vector in the ride frame.
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| self.sign[i] * v[self.axis[i]])
    }

    /// Mount a log: its gyro and accelerometer columns turned into the ride
    /// frame (the gyro scaled), and the mounting written to its metadata.
    pub fn apply(&self, log: &mut RideLog) {
        for g in &mut log.gyro_dps {
            *g = self.rotate(*g).map(|w| w * self.scale);
        }
        if let Some(acc) = &mut log.accel_mps2 {
            for a in acc.iter_mut().flatten() {
                *a = self.rotate(*a);
            }
        }
        log.metadata.insert("mount".into(), self.to_string());
        log.metadata.insert(
            "gyro_frame".into(),
            "x forward, y left, z up (mounted)".into(),
        );
    }
}

impl std::fmt::Display for Mount {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for i in 0..3 {
            if i > 0 {
                f.write_str(",")?;
            }
            let sign = if self.sign[i] < 0.0 { "-" } else { "" };
            write!(f, "{}={sign}{}", NAMES[i], NAMES[self.axis[i]])?;
        }
        if self.scale != 1.0 {
            write!(f, ",scale={}", self.scale)?;
        }
        Ok(())
    }
}

impl std::str::FromStr for Mount {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let mut axis = [usize::MAX; 3];
        let mut sign = [1.0; 3];
        let mut scale = 1.0;
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (lhs, rhs) = part
                .split_once('=')
                .ok_or_else(|| format!("'{part}' is not of the form x=-z"))?;
            let (lhs, rhs) = (
                lhs.trim().to_ascii_lowercase(),
                rhs.trim().to_ascii_lowercase(),
            );
            if lhs == "scale" {
                scale = rhs
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| format!("scale '{rhs}' is not a positive number"))?;
                continue;
            }
            let axis_of = |name: &str| {
                let name = name.trim_start_matches('g');
                NAMES
                    .iter()
                    .position(|&c| name.len() == 1 && name.starts_with(c))
                    .ok_or_else(|| format!("'{name}' in '{part}' is not an axis x, y or z"))
            };
            let target = axis_of(&lhs)?;
            let (s, source) = match rhs.strip_prefix('-') {
                Some(r) => (-1.0, r),
                None => (1.0, rhs.strip_prefix('+').unwrap_or(&rhs)),
            };
            if axis[target] != usize::MAX {
                return Err(format!("axis {} is given twice", NAMES[target]));
            }
            axis[target] = axis_of(source)?;
            sign[target] = s;
        }
        if axis.contains(&usize::MAX) {
            return Err(format!(
                "'{s}' must give all three axes, e.g. x=-z,y=-x,z=y"
            ));
        }
        let mut used = axis;
        used.sort_unstable();
        if used != [0, 1, 2] {
            return Err(format!("'{s}' uses a logged axis twice"));
        }
        let m = Self { axis, sign, scale };
        if m.determinant() < 0.0 {
            return Err(format!(
                "'{s}' mirrors the frame (a left-handed mounting cannot be real): flip one sign"
            ));
        }
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_prints_and_rotates() {
        let m: Mount = "gx = -z, gy = -x, gz = y".parse().unwrap();
        assert_eq!(m.to_string(), "x=-z,y=-x,z=y");
        assert_eq!(m.rotate([1.0, 2.0, 3.0]), [-3.0, -1.0, 2.0]);
        assert_eq!(m.to_string().parse::<Mount>().unwrap(), m);
        let s: Mount = "x=x,y=y,z=z,scale=57.29578".parse().unwrap();
        assert_eq!(s.scale, 57.29578);
        assert!("x=x,y=y".parse::<Mount>().is_err());
        assert!("x=x,y=x,z=z".parse::<Mount>().is_err());
        assert!(
            "x=x,y=y,z=-z"
                .parse::<Mount>()
                .unwrap_err()
                .contains("mirror")
        );
        assert!("x=q,y=y,z=z".parse::<Mount>().is_err());
    }

    #[test]
    fn forward_and_up_make_a_right_handed_mounting() {
        // The Husky's IMU: forward is -z, up is +y, so left is -x.
        let m = Mount::from_forward_up((2, -1.0), (1, 1.0)).unwrap();
        assert_eq!(m.to_string(), "x=-z,y=-x,z=y");
        assert_eq!(
            Mount::from_forward_up((0, 1.0), (2, 1.0)).unwrap(),
            Mount::identity()
        );
        assert!(Mount::from_forward_up((1, 1.0), (1, -1.0)).is_none());
        for f in 0..3 {
            for u in 0..3 {
                for (sf, su) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
                    if let Some(m) = Mount::from_forward_up((f, sf), (u, su)) {
                        assert!(m.determinant() > 0.0);
                    }
                }
            }
        }
    }
}
