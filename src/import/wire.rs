//! Decoding the four message types gyropath reads, in both wire encodings:
//! ROS 1 serialization (little-endian, packed, `u32` lengths) and ROS 2's CDR
//! (an encapsulation header, then each primitive aligned to its own size from
//! the end of that header; strings carry their NUL). One layout per message,
//! written once against [`Wire`], so the two encodings cannot drift apart.
//!
//! Every read is bounds-checked: a truncated or corrupt message is an error,
//! never a panic, and an absurd length is refused before anything is allocated.

/// A field that cannot be decoded.
#[derive(Clone, Debug, PartialEq)]
pub struct WireError(pub String);

impl std::fmt::Display for WireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

type Result<T> = std::result::Result<T, WireError>;

/// The message types gyropath reads, by their ROS names (ROS 1 `pkg/Type`, ROS 2 `pkg/msg/Type`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum MessageType {
    Imu,
    Odometry,
    TwistStamped,
    NavSatFix,
}

impl MessageType {
    /// The type of a topic, from its ROS 1 or ROS 2 name.
    pub fn from_ros_name(name: &str) -> Option<Self> {
        match name.replace("/msg/", "/").as_str() {
            "sensor_msgs/Imu" => Some(Self::Imu),
            "nav_msgs/Odometry" => Some(Self::Odometry),
            "geometry_msgs/TwistStamped" => Some(Self::TwistStamped),
            "sensor_msgs/NavSatFix" => Some(Self::NavSatFix),
            _ => None,
        }
    }
}

/// Primitive reads of one encoding.
pub trait Wire {
    fn f64(&mut self) -> Result<f64>;
    fn u32(&mut self) -> Result<u32>;
    fn i32(&mut self) -> Result<i32>;
    fn u16(&mut self) -> Result<u16>;
    fn u8(&mut self) -> Result<u8>;
    /// Skip a string.
    fn skip_string(&mut self) -> Result<()>;
    /// A header's stamp in nanoseconds (exact: the same integer in both
    /// encodings), after which the rest of the header is skipped.
    fn header_stamp(&mut self) -> Result<i64>;

    fn i8(&mut self) -> Result<i8> {
        self.u8().map(|b| b as i8)
    }

    fn f64s<const N: usize>(&mut self) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64()?;
        }
        Ok(out)
    }
}

/// Bounds-checked little-endian reads over a byte slice.
struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bytes<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| {
                WireError(format!(
                    "message ends after {} bytes, {} more needed at byte {}",
                    self.data.len(),
                    n,
                    self.pos
                ))
            })?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
}

/// ROS 1 serialization: packed little-endian, strings as `u32` length + bytes.
pub struct Ros1<'a>(Bytes<'a>);

impl<'a> Ros1<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Self(Bytes { data, pos: 0 })
    }
}

impl Wire for Ros1<'_> {
    fn f64(&mut self) -> Result<f64> {
        self.0.array().map(f64::from_le_bytes)
    }
    fn u32(&mut self) -> Result<u32> {
        self.0.array().map(u32::from_le_bytes)
    }
    fn i32(&mut self) -> Result<i32> {
        self.0.array().map(i32::from_le_bytes)
    }
    fn u16(&mut self) -> Result<u16> {
        self.0.array().map(u16::from_le_bytes)
    }
    fn u8(&mut self) -> Result<u8> {
        self.0.array::<1>().map(|a| a[0])
    }
    fn skip_string(&mut self) -> Result<()> {
        let n = self.u32()? as usize;
        self.0.take(n).map(|_| ())
    }
    /// `std_msgs/Header`: `seq: u32, stamp: (u32 sec, u32 nsec), frame_id: string`.
    fn header_stamp(&mut self) -> Result<i64> {
        self.u32()?;
        let sec = self.u32()?;
        let nsec = self.u32()?;
        self.skip_string()?;
        Ok(sec as i64 * 1_000_000_000 + nsec as i64)
    }
}

/// CDR as ROS 2 writes it: a 4-byte encapsulation header (`00 01`: little
/// endian, `00 00`: big endian), then primitives aligned to their size.
pub struct Cdr<'a> {
    bytes: Bytes<'a>,
    little: bool,
}

impl<'a> Cdr<'a> {
    pub fn new(data: &'a [u8]) -> Result<Self> {
        let mut bytes = Bytes { data, pos: 0 };
        let head: [u8; 4] = bytes.array()?;
        let little = match head[1] {
            0 | 2 => false,
            1 | 3 => true,
            k => {
                return Err(WireError(format!(
                    "unknown CDR encapsulation kind {k} (expected plain CDR)"
                )));
            }
        };
        // Alignment counts from the end of the encapsulation header.
        Ok(Self {
            bytes: Bytes {
                data: &data[4..],
                pos: 0,
            },
            little,
        })
    }

    fn aligned<const N: usize>(&mut self) -> Result<[u8; N]> {
        let pad = (N - self.bytes.pos % N) % N;
        self.bytes.take(pad)?;
        let mut a: [u8; N] = self.bytes.array()?;
        if !self.little {
            a.reverse();
        }
        Ok(a)
    }
}

impl Wire for Cdr<'_> {
    fn f64(&mut self) -> Result<f64> {
        self.aligned().map(f64::from_le_bytes)
    }
    fn u32(&mut self) -> Result<u32> {
        self.aligned().map(u32::from_le_bytes)
    }
    fn i32(&mut self) -> Result<i32> {
        self.aligned().map(i32::from_le_bytes)
    }
    fn u16(&mut self) -> Result<u16> {
        self.aligned().map(u16::from_le_bytes)
    }
    fn u8(&mut self) -> Result<u8> {
        self.bytes.array::<1>().map(|a| a[0])
    }
    fn skip_string(&mut self) -> Result<()> {
        let n = self.u32()? as usize;
        self.bytes.take(n).map(|_| ())
    }
    /// `std_msgs/msg/Header`: `stamp: (i32 sec, u32 nanosec), frame_id: string`.
    fn header_stamp(&mut self) -> Result<i64> {
        let sec = self.i32()?;
        let nsec = self.u32()?;
        self.skip_string()?;
        Ok(sec as i64 * 1_000_000_000 + nsec as i64)
    }
}

/// An IMU sample: `sensor_msgs/Imu`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuMsg {
    /// Header stamp (ns).
    pub t_ns: i64,
    /// rad/s, sensor frame.
    pub angular_velocity: [f64; 3],
    /// m/s^2; `None` when the message marks it as not provided (covariance[0] = -1).
    pub linear_acceleration: Option<[f64; 3]>,
}

/// `header, orientation (4), orientation_covariance (9), angular_velocity (3),
/// angular_velocity_covariance (9), linear_acceleration (3), linear_acceleration_covariance (9)`.
pub fn imu(w: &mut impl Wire) -> Result<ImuMsg> {
    let t_ns = w.header_stamp()?;
    w.f64s::<4>()?;
    w.f64s::<9>()?;
    let angular_velocity = w.f64s::<3>()?;
    let gyro_cov = w.f64s::<9>()?;
    let acc = w.f64s::<3>()?;
    let acc_cov = w.f64s::<9>()?;
    if gyro_cov[0] == -1.0 {
        return Err(WireError(
            "the message says it has no angular velocity (covariance[0] = -1)".into(),
        ));
    }
    Ok(ImuMsg {
        t_ns,
        angular_velocity,
        linear_acceleration: (acc_cov[0] != -1.0).then_some(acc),
    })
}

/// A forward speed sample: `nav_msgs/Odometry` or `geometry_msgs/TwistStamped`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedMsg {
    /// Header stamp (ns).
    pub t_ns: i64,
    /// `twist.linear.x` (m/s), signed.
    pub speed: f64,
    /// `twist.angular.z` (rad/s): the odometry's own yaw rate, for the checks.
    pub yaw_rate: f64,
}

/// `header, child_frame_id, pose (position 3, orientation 4, covariance 36),
/// twist (linear 3, angular 3, covariance 36)`.
pub fn odometry(w: &mut impl Wire) -> Result<SpeedMsg> {
    let t_ns = w.header_stamp()?;
    w.skip_string()?;
    w.f64s::<7>()?;
    w.f64s::<36>()?;
    twist(w, t_ns)
}

/// `header, twist (linear 3, angular 3)`.
pub fn twist_stamped(w: &mut impl Wire) -> Result<SpeedMsg> {
    let t_ns = w.header_stamp()?;
    twist(w, t_ns)
}

/// `geometry_msgs/Twist`: `linear (3), angular (3)`.
fn twist(w: &mut impl Wire, t_ns: i64) -> Result<SpeedMsg> {
    let linear = w.f64s::<3>()?;
    let angular = w.f64s::<3>()?;
    Ok(SpeedMsg {
        t_ns,
        speed: linear[0],
        yaw_rate: angular[2],
    })
}

/// A GPS fix: `sensor_msgs/NavSatFix`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixMsg {
    /// Header stamp (ns).
    pub t_ns: i64,
    /// `status.status`: -1 no fix, 0 fix, 1 SBAS, 2 GBAS (RTK).
    pub status: i8,
    pub lat: f64,
    pub lon: f64,
    pub alt: f64,
    /// 1-sigma horizontal and vertical accuracy (m) from `position_covariance`,
    /// when its type is not `COVARIANCE_TYPE_UNKNOWN`.
    pub hacc: Option<f64>,
    pub vacc: Option<f64>,
    /// The receiver's HDOP and satellites used (not in a `NavSatFix`; a
    /// mapped CSV may have them).
    pub hdop: Option<f64>,
    pub sats: Option<f64>,
}

/// `header, status (i8 status, u16 service), latitude, longitude, altitude,
/// position_covariance (9, ENU, m^2), position_covariance_type (u8)`.
pub fn nav_sat_fix(w: &mut impl Wire) -> Result<FixMsg> {
    let t_ns = w.header_stamp()?;
    let status = w.i8()?;
    w.u16()?;
    let lat = w.f64()?;
    let lon = w.f64()?;
    let alt = w.f64()?;
    let cov = w.f64s::<9>()?;
    let kind = w.u8()?;
    let sigma = |v: f64| (v.is_finite() && v > 0.0).then(|| v.sqrt());
    let known = kind != 0;
    Ok(FixMsg {
        t_ns,
        status,
        lat,
        lon,
        alt,
        hacc: if known {
            sigma(0.5 * (cov[0] + cov[4]))
        } else {
            None
        },
        vacc: if known { sigma(cov[8]) } else { None },
        hdop: None,
        sats: None,
    })
}

/// Writes the same messages in either encoding: for tests, benchmarks and
/// for making small bags to try the readers on.
pub struct Writer {
    pub buf: Vec<u8>,
    cdr: bool,
}

impl Writer {
    pub fn ros1() -> Self {
        Self {
            buf: Vec::new(),
            cdr: false,
        }
    }
    pub fn cdr() -> Self {
        Self {
            buf: vec![0, 1, 0, 0],
            cdr: true,
        }
    }
    fn align(&mut self, n: usize) {
        if self.cdr {
            while !(self.buf.len() - 4).is_multiple_of(n) {
                self.buf.push(0);
            }
        }
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend(v.to_le_bytes());
        self
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend(v.to_le_bytes());
        self
    }
    pub fn u16(&mut self, v: u16) -> &mut Self {
        self.align(2);
        self.buf.extend(v.to_le_bytes());
        self
    }
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        if self.cdr {
            self.u32(s.len() as u32 + 1);
            self.buf.extend(s.as_bytes());
            self.buf.push(0);
        } else {
            self.u32(s.len() as u32);
            self.buf.extend(s.as_bytes());
        }
        self
    }
    pub fn header(&mut self, t: f64, frame: &str) -> &mut Self {
        if !self.cdr {
            self.u32(7);
        }
        let sec = t.floor();
        self.u32(sec as u32);
        self.u32(((t - sec) * 1e9).round() as u32);
        self.string(frame)
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for &x in v {
            self.f64(x);
        }
        self
    }
    pub fn imu(mut self, t: f64, gyro: [f64; 3], acc: [f64; 3]) -> Vec<u8> {
        self.header(t, "imu_link")
            .f64s(&[0.0, 0.0, 0.0, 1.0])
            .f64s(&[0.0; 9])
            .f64s(&gyro)
            .f64s(&[0.01; 9])
            .f64s(&acc)
            .f64s(&[0.1; 9]);
        self.buf
    }
    pub fn odometry(mut self, t: f64, speed: f64) -> Vec<u8> {
        self.header(t, "odom")
            .string("base_link")
            .f64s(&[0.0; 7])
            .f64s(&[0.0; 36])
            .f64s(&[speed, 0.0, 0.0, 0.0, 0.0, 0.1])
            .f64s(&[0.0; 36]);
        self.buf
    }
    pub fn fix(mut self, t: f64, lat: f64, lon: f64, var: f64) -> Vec<u8> {
        self.header(t, "gps")
            .u8(0)
            .u16(1)
            .f64(lat)
            .f64(lon)
            .f64(12.0);
        self.f64s(&[var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, 4.0 * var])
            .u8(2);
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_encodings_decode_the_same_messages() {
        let imus = [
            (
                Writer::ros1().imu(12.5, [0.1, -0.2, 0.3], [0.0, 9.8, 0.1]),
                false,
            ),
            (
                Writer::cdr().imu(12.5, [0.1, -0.2, 0.3], [0.0, 9.8, 0.1]),
                true,
            ),
        ];
        for (bytes, cdr) in &imus {
            let m = if *cdr {
                imu(&mut Cdr::new(bytes).unwrap())
            } else {
                imu(&mut Ros1::new(bytes))
            }
            .unwrap();
            assert_eq!(m.t_ns, 12_500_000_000);
            assert_eq!(m.angular_velocity, [0.1, -0.2, 0.3]);
            assert_eq!(m.linear_acceleration, Some([0.0, 9.8, 0.1]));
        }
        let f1 = nav_sat_fix(&mut Ros1::new(&Writer::ros1().fix(3.0, 42.1, -71.2, 4.0))).unwrap();
        let f2 =
            nav_sat_fix(&mut Cdr::new(&Writer::cdr().fix(3.0, 42.1, -71.2, 4.0)).unwrap()).unwrap();
        assert_eq!(f1, f2);
        assert_eq!(f1.hacc, Some(2.0));
        assert_eq!(f1.vacc, Some(4.0));
        let o1 = odometry(&mut Ros1::new(&Writer::ros1().odometry(1.0, 0.9))).unwrap();
        let o2 = odometry(&mut Cdr::new(&Writer::cdr().odometry(1.0, 0.9)).unwrap()).unwrap();
        assert_eq!(o1, o2);
        assert_eq!(o1.speed, 0.9);
    }

    #[test]
    fn truncated_and_corrupt_messages_are_errors() {
        let bytes = Writer::cdr().imu(1.0, [0.0; 3], [0.0; 3]);
        for cut in 0..bytes.len() {
            let r = Cdr::new(&bytes[..cut]).and_then(|mut c| imu(&mut c));
            assert!(r.is_err(), "cut at {cut}");
        }
        let mut bad = Writer::ros1().odometry(1.0, 1.0);
        bad[12..16].copy_from_slice(&u32::MAX.to_le_bytes()); // frame_id length
        assert!(odometry(&mut Ros1::new(&bad)).is_err());
        assert!(Cdr::new(&[0, 9, 0, 0]).is_err());
    }
}
