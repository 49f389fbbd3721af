//! WGS84 geodetic coordinates <-> a local east/north/up (ENU) frame.
//!
//! The model works in metres in a local tangent frame anchored at one point of
//! the ride. The conversion goes through Earth-centred Earth-fixed (ECEF)
//! coordinates, so it is exact (no flat-earth approximation) for any ride
//! length: geodetic -> ECEF is the closed form
//! `X = (N + h) cos(lat) cos(lon)`, `Y = (N + h) cos(lat) sin(lon)`,
//! `Z = (N (1 - e^2) + h) sin(lat)` with `N = a / sqrt(1 - e^2 sin^2 lat)`,
//! and ECEF -> geodetic is Heikkinen's closed form (exact to well below a
//! millimetre at the Earth's surface).

use nalgebra::{Matrix3, Vector3};

/// WGS84 semi-major axis (m).
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;

const E2: f64 = WGS84_F * (2.0 - WGS84_F);
const B: f64 = WGS84_A * (1.0 - WGS84_F);

/// A point given as WGS84 latitude and longitude (degrees) and height above the ellipsoid (m).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Geodetic {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f64,
}

impl Geodetic {
    pub fn new(lat_deg: f64, lon_deg: f64, alt_m: f64) -> Self {
        Self {
            lat_deg,
            lon_deg,
            alt_m,
        }
    }

    /// ECEF position (m).
    pub fn to_ecef(&self) -> Vector3<f64> {
        let (lat, lon) = (self.lat_deg.to_radians(), self.lon_deg.to_radians());
        let (sl, cl) = lat.sin_cos();
        let n = WGS84_A / (1.0 - E2 * sl * sl).sqrt();
        Vector3::new(
            (n + self.alt_m) * cl * lon.cos(),
            (n + self.alt_m) * cl * lon.sin(),
            (n * (1.0 - E2) + self.alt_m) * sl,
        )
    }

    /// Geodetic coordinates of an ECEF point (Heikkinen 1982, closed form).
    pub fn from_ecef(x: &Vector3<f64>) -> Self {
        let ep2 = (WGS84_A * WGS84_A - B * B) / (B * B);
        let p = (x.x * x.x + x.y * x.y).sqrt();
        let f = 54.0 * B * B * x.z * x.z;
        let g = p * p + (1.0 - E2) * x.z * x.z - E2 * (WGS84_A * WGS84_A - B * B);
        let c = E2 * E2 * f * p * p / (g * g * g);
        let s = (1.0 + c + (c * c + 2.0 * c).sqrt()).cbrt();
        let k = s + 1.0 + 1.0 / s;
        let pp = f / (3.0 * k * k * g * g);
        let q = (1.0 + 2.0 * E2 * E2 * pp).sqrt();
        let r0 = -(pp * E2 * p) / (1.0 + q)
            + (0.5 * WGS84_A * WGS84_A * (1.0 + 1.0 / q)
                - pp * (1.0 - E2) * x.z * x.z / (q * (1.0 + q))
                - 0.5 * pp * p * p)
                .max(0.0)
                .sqrt();
        let u = ((p - E2 * r0).powi(2) + x.z * x.z).sqrt();
        let v = ((p - E2 * r0).powi(2) + (1.0 - E2) * x.z * x.z).sqrt();
        let z0 = B * B * x.z / (WGS84_A * v);
        let alt = u * (1.0 - B * B / (WGS84_A * v));
        let lat = (x.z + ep2 * z0).atan2(p);
        let lon = x.y.atan2(x.x);
        Self::new(lat.to_degrees(), lon.to_degrees(), alt)
    }
}

/// A local east/north/up frame tangent to the ellipsoid at `origin`.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalFrame {
    origin: Geodetic,
    origin_ecef: Vector3<f64>,
    /// Rows are the east, north and up unit vectors in ECEF.
    ecef_to_enu: Matrix3<f64>,
}

impl LocalFrame {
    pub fn new(origin: Geodetic) -> Self {
        let (lat, lon) = (origin.lat_deg.to_radians(), origin.lon_deg.to_radians());
        let (sl, cl) = lat.sin_cos();
        let (so, co) = lon.sin_cos();
        let ecef_to_enu = Matrix3::new(
            -so,
            co,
            0.0, // east
            -sl * co,
            -sl * so,
            cl, // north
            cl * co,
            cl * so,
            sl, // up
        );
        Self {
            origin,
            origin_ecef: origin.to_ecef(),
            ecef_to_enu,
        }
    }

    pub fn origin(&self) -> Geodetic {
        self.origin
    }

    /// East, north, up (m) of a geodetic point.
    pub fn to_enu(&self, g: &Geodetic) -> Vector3<f64> {
        self.ecef_to_enu * (g.to_ecef() - self.origin_ecef)
    }

    /// Geodetic point at local east, north, up (m).
    pub fn to_geodetic(&self, enu: &Vector3<f64>) -> Geodetic {
        Geodetic::from_ecef(&(self.origin_ecef + self.ecef_to_enu.transpose() * enu))
    }
}

/// Web Mercator (EPSG:3857) tile coordinates, as slippy-map tile servers
/// (OpenStreetMap and the like) number their square tiles: at zoom `z` the
/// world is `2^z` tiles across, and a point's fractional tile position is
/// `x = 2^z (lon + 180) / 360`, `y = 2^z (1 - ln(tan lat + sec lat) / pi) / 2`
/// (y grows southward). The tile holding the point is `(floor x, floor y)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TilePosition {
    pub x: f64,
    pub y: f64,
    pub zoom: u8,
}

/// Web Mercator's latitude limit (deg): the square world's edge, `atan(sinh pi)`.
pub const MERCATOR_MAX_LAT_DEG: f64 = 85.051_128_779_806_59;

impl TilePosition {
    /// The fractional tile position of `g` (latitude clamped to Mercator's square).
    pub fn of(g: &Geodetic, zoom: u8) -> Self {
        let n = f64::from(1u32 << zoom.min(30));
        let lat = g
            .lat_deg
            .clamp(-MERCATOR_MAX_LAT_DEG, MERCATOR_MAX_LAT_DEG)
            .to_radians();
        Self {
            x: n * (g.lon_deg + 180.0) / 360.0,
            y: n * (1.0 - (lat.tan() + 1.0 / lat.cos()).ln() / std::f64::consts::PI) / 2.0,
            zoom,
        }
    }

    /// The point at this tile position (height 0): `lon = 360 x / 2^z - 180`,
    /// `lat = atan(sinh(pi (1 - 2 y / 2^z)))`.
    pub fn geodetic(&self) -> Geodetic {
        let n = f64::from(1u32 << self.zoom.min(30));
        let lat = (std::f64::consts::PI * (1.0 - 2.0 * self.y / n))
            .sinh()
            .atan();
        Geodetic::new(lat.to_degrees(), 360.0 * self.x / n - 180.0, 0.0)
    }
}

/// The zoom at which one pixel of a `tile_px`-pixel tile covers about
/// `metres_per_pixel` of ground at latitude `lat_deg` (a tile pixel spans
/// `2 pi a cos(lat) / (tile_px 2^z)` metres), clamped to `0..=max_zoom`
/// (an infinitely wide pixel takes zoom 0, an empty one `max_zoom`).
pub fn tile_zoom_for(metres_per_pixel: f64, lat_deg: f64, tile_px: f64, max_zoom: u8) -> u8 {
    let equator = 2.0 * std::f64::consts::PI * WGS84_A / tile_px;
    let z = (equator * lat_deg.to_radians().cos() / metres_per_pixel).log2();
    // A NaN casts to 0; infinities clamp to the ends.
    z.round().clamp(0.0, f64::from(max_zoom)) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ecef_of_known_points() {
        let equator = Geodetic::new(0.0, 0.0, 0.0).to_ecef();
        assert!((equator - Vector3::new(WGS84_A, 0.0, 0.0)).norm() < 1e-6);
        let pole = Geodetic::new(90.0, 0.0, 100.0).to_ecef();
        assert!((pole - Vector3::new(0.0, 0.0, B + 100.0)).norm() < 1e-6);
    }

    #[test]
    fn geodetic_round_trip_is_sub_millimetre() {
        for &(lat, lon, h) in &[
            (47.49788883, 19.04019799, 95.9),
            (-33.9, 151.2, 10.0),
            (37.7210, -122.4723, -20.0),
            (89.9, -179.0, 3000.0),
            (0.001, 0.0, 0.0),
        ] {
            let g = Geodetic::new(lat, lon, h);
            let back = Geodetic::from_ecef(&g.to_ecef());
            assert!(
                (back.to_ecef() - g.to_ecef()).norm() < 1e-4,
                "{g:?} -> {back:?}"
            );
            assert!((back.alt_m - h).abs() < 1e-4);
        }
    }

    #[test]
    fn enu_axes_point_the_right_way() {
        let frame = LocalFrame::new(Geodetic::new(47.5, 19.0, 100.0));
        // One arc-second of latitude is about 30.9 m north at 47.5 deg.
        let north = frame.to_enu(&Geodetic::new(47.5 + 1.0 / 3600.0, 19.0, 100.0));
        assert!((north.y - 30.89).abs() < 0.05, "{north}");
        assert!(north.x.abs() < 1e-6 && north.z.abs() < 1e-3);
        let east = frame.to_enu(&Geodetic::new(47.5, 19.0 + 1.0 / 3600.0, 100.0));
        assert!(
            (east.x - 20.9).abs() < 0.05 && east.y.abs() < 1e-3,
            "{east}"
        );
        let up = frame.to_enu(&Geodetic::new(47.5, 19.0, 110.0));
        assert!((up - Vector3::new(0.0, 0.0, 10.0)).norm() < 1e-6);
        let p = Vector3::new(1234.5, -987.6, 12.3);
        assert!((frame.to_enu(&frame.to_geodetic(&p)) - p).norm() < 1e-5);
    }

    #[test]
    fn tile_positions_match_the_slippy_map_convention() {
        // Zoom 0 is one tile: its corners are the Mercator square's.
        let nw = TilePosition::of(&Geodetic::new(MERCATOR_MAX_LAT_DEG, -180.0, 0.0), 0);
        assert!(nw.x.abs() < 1e-12 && nw.y.abs() < 1e-9, "{nw:?}");
        let centre = TilePosition::of(&Geodetic::new(0.0, 0.0, 0.0), 3);
        assert!((centre.x - 4.0).abs() < 1e-12 && (centre.y - 4.0).abs() < 1e-12);
        // An exact tile edge: sinh(pi/2) is a quarter of the way down, at
        // latitude atan(sinh(pi/2)) = 66.513 deg; a tile is 360/2^z deg wide.
        let quarter = (std::f64::consts::FRAC_PI_2.sinh().atan()).to_degrees();
        let edge = TilePosition::of(&Geodetic::new(quarter, 19.0, 0.0), 16);
        assert!((edge.y - 16384.0).abs() < 1e-6, "{edge:?}");
        assert!((edge.x - (19.0 + 180.0) / (360.0 / 65536.0)).abs() < 1e-9);
        // And back: a tile corner round-trips to well below a millimetre.
        for &(lat, lon) in &[(47.49895, 19.04357), (-33.9, 151.2), (37.72, -122.47)] {
            let g = Geodetic::new(lat, lon, 0.0);
            let back = TilePosition::of(&g, 17).geodetic();
            assert!((back.lat_deg - lat).abs() < 1e-9 && (back.lon_deg - lon).abs() < 1e-9);
        }
    }

    #[test]
    fn tile_zoom_puts_a_tile_pixel_near_a_screen_pixel() {
        // At the equator zoom 0 is 156 km per pixel of a 256-pixel tile.
        assert_eq!(tile_zoom_for(156_543.0, 0.0, 256.0, 19), 0);
        // 1.08 m per pixel at 47.5 deg: log2(156543 cos(47.5 deg) / 1.08) = 16.58.
        let z = tile_zoom_for(1.08, 47.5, 256.0, 19);
        assert_eq!(z, 17, "zoom {z}");
        assert_eq!(tile_zoom_for(1e-3, 47.5, 256.0, 19), 19);
        assert_eq!(tile_zoom_for(f64::INFINITY, 47.5, 256.0, 19), 0);
        assert_eq!(tile_zoom_for(0.0, 47.5, 256.0, 19), 19);
    }
}
