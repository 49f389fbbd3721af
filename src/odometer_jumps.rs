//! Readings of the distance sensor that are no distance travelled: a
//! cumulative odometer that resets (a logger or an ECU restarting, a trip
//! meter zeroed), wraps (a fixed-width counter) or drops to 0 for a sample,
//! and a logged speed's invalid codes (a CAN signal's "not available",
//! 0xFFFF = 655.35 km/h, or a corrupt sample).
//!
//! Read as distance, a reset of a cumulative odometer is the whole distance
//! so far travelled backwards within one sample. On the real comma drive
//! with its odometer zeroed half-way the fit failed as "not physical",
//! blaming the odometer's units and an upside-down sensor, while `gyropath
//! check` read the odometer as fine.
//!
//! The rule is physical, not fitted to any ride. Between two readings of a
//! cumulative odometer, `o_i` and then `o_k`, the vehicle covers at most
//!
//! ```text
//! o_k - o_i <= V_MAX (t_k - t_c) + Q          forwards
//! o_i - o_k <= V_REVERSE (t_k - t_c) + Q      backwards (reversing)
//! ```
//!
//! with `t_c` the time `o_i` was first read (a coarse counter, a car's
//! 0.1 km odometer, holds one value while the vehicle moves on) and `Q` a
//! counter's quantum. A step beyond that is a jump: the odometer is re-based
//! there, so that the step across it continues at the speed of the step
//! before it (what the vehicle covered within that one sample is not
//! measured; at 5-100 Hz it is a fraction of a metre), and every later
//! reading keeps its differences. A speed faster than `V_MAX` either way is
//! not a speed: that sample is left empty and interpolated, as an empty
//! field is.

use crate::blunders::V_MAX_MPS;

/// The fastest a wheeled vehicle reverses (m/s): a car's reverse gear tops
/// out near 10 m/s, and a bicycle's rider walks it back.
pub const V_REVERSE_MPS: f64 = 15.0;

/// A counter's quantum (m) that any step may have on top of the distance
/// the speed bound allows.
pub const QUANTUM_M: f64 = 1.0;

/// The samples of a distance column that are no distance: by row, and the
/// largest of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Jumps {
    /// The column read (`odo_m`, `speed_mps`, `gps_speed_mps`).
    pub column: &'static str,
    /// Rows whose reading jumped (a cumulative odometer) or was invalid (a speed).
    pub rows: Vec<usize>,
    /// The largest jump (m) or invalid speed (m/s), by magnitude, with its sign.
    pub largest: f64,
}

impl Jumps {
    /// Whether nothing was found.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// What was found and done, naming the first on its `line` and time;
    /// `None` where nothing was.
    pub fn describe(&self, file: &str, line: &[u64], t: &[f64]) -> Option<String> {
        let &first = self.rows.first()?;
        let n = self.rows.len();
        let at = format!(
            "the first on line {}, column '{}', t = {:.2} s",
            line.get(first).copied().unwrap_or(first as u64 + 1),
            self.column,
            t.get(first).copied().unwrap_or(f64::NAN)
        );
        let what = if self.column == "odo_m" {
            format!(
                "the odometer jumps {n} time{} by more than a vehicle moves (up to {:+.1} m within one sample: a reset, a wrapped counter or a dropout; {at}); the distance runs on across each at the speed before it",
                if n == 1 { "" } else { "s" },
                self.largest,
            )
        } else {
            format!(
                "{n} speed sample{} faster than {V_MAX_MPS:.0} m/s either way{} (up to {:.1} m/s: an invalid-value code or a corrupt sample; {at}) read as empty, interpolated from the samples either side",
                if n == 1 { "" } else { "s" },
                if self.column == "gps_speed_mps" {
                    " or negative (a ground speed has no sign; iOS writes -1 where it has none)"
                } else {
                    ""
                },
                self.largest,
            )
        };
        Some(format!("{file}: {what}"))
    }
}

/// `odo` (a cumulative distance, empty where not read) with its jumps
/// mended (see the module's notes), and the jumps. Forwards is the way most
/// of its steps go: an odometer whose sign is flipped counts down, and
/// `gyropath check` says so, rather than each step being a jump.
pub fn cumulative(t: &[f64], odo: &[Option<f64>]) -> (Vec<Option<f64>>, Jumps) {
    let read: Vec<f64> = odo.iter().flatten().copied().collect();
    let ups = read.windows(2).filter(|w| w[1] > w[0]).count();
    let downs = read.windows(2).filter(|w| w[1] < w[0]).count();
    let sign = if downs > ups { -1.0 } else { 1.0 };
    let mut out = odo.to_vec();
    let mut jumps = Jumps {
        column: "odo_m",
        ..Jumps::default()
    };
    // The previous reading as mended: its row, value, and when its raw value was first read.
    let mut prev: Option<(usize, f64, f64)> = None;
    let mut raw_prev = f64::NAN;
    let mut offset = 0.0;
    let mut speed = 0.0;
    for (k, value) in odo.iter().enumerate() {
        let Some(raw) = *value else { continue };
        let mut mended = raw + offset;
        if let Some((i, o_i, since)) = prev {
            let step = mended - o_i;
            let dt = t[k] - since;
            let reach = if sign * step >= 0.0 {
                V_MAX_MPS * dt
            } else {
                V_REVERSE_MPS * dt
            };
            if step.abs() > reach + QUANTUM_M {
                jumps.rows.push(k);
                if step.abs() > jumps.largest.abs() {
                    jumps.largest = step;
                }
                let continued = o_i + speed * (t[k] - t[i]);
                offset += continued - mended;
                mended = continued;
            } else if t[k] > t[i] {
                speed = step / (t[k] - t[i]);
            }
        }
        let since = match prev {
            Some((_, _, since)) if raw == raw_prev => since,
            _ => t[k],
        };
        raw_prev = raw;
        prev = Some((k, mended, since));
        out[k] = Some(mended);
    }
    if !rare(jumps.rows.len(), ups + downs) {
        return (odo.to_vec(), Jumps::default());
    }
    (out, jumps)
}

/// Whether `n` readings beyond the bounds among `of` are glitches: a few
/// (at most 2, or 1 % of them). More are no glitches but the column's units
/// (an odometer in millimetres steps "190 m" every 0.01 s, a speed in km/h
/// passes "100 m/s" on a highway): then nothing is mended, and the fit's
/// and the check's units verdicts say what it is. Mended step by step, an
/// odometer in millimetres became no distance at all.
fn rare(n: usize, of: usize) -> bool {
    n <= 2.max(of / 100)
}

/// `speed` (m/s, named `column`) with its samples faster than
/// [`V_MAX_MPS`] either way left empty, and those samples. A GNSS ground
/// speed (`gps_speed_mps`) has no sign, so a negative one is no speed
/// either: iOS writes -1 where it has none, which read as a speed ran the
/// path backwards.
pub fn speed(column: &'static str, speed: &[Option<f64>]) -> (Vec<Option<f64>>, Jumps) {
    let ground = column == "gps_speed_mps";
    let mut jumps = Jumps {
        column,
        ..Jumps::default()
    };
    // Too fast only where rare (see [`rare`]); a ground speed below 0 always.
    let samples = speed.iter().flatten().count();
    let too_fast = speed
        .iter()
        .flatten()
        .filter(|v| v.abs() > V_MAX_MPS)
        .count();
    let fast_is_glitch = rare(too_fast, samples);
    let out = speed
        .iter()
        .enumerate()
        .map(|(k, v)| match *v {
            Some(v) if (fast_is_glitch && v.abs() > V_MAX_MPS) || (ground && v < 0.0) => {
                jumps.rows.push(k);
                if v.abs() > jumps.largest.abs() {
                    jumps.largest = v;
                }
                None
            }
            other => other,
        })
        .collect();
    (out, jumps)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle at `v` m/s read at `hz` for `n` samples by a counter of
    /// quantum `q` (m; 0: exact).
    fn odometer(n: usize, hz: f64, v: f64, q: f64) -> (Vec<f64>, Vec<Option<f64>>) {
        let t: Vec<f64> = (0..n).map(|k| k as f64 / hz).collect();
        let odo = t
            .iter()
            .map(|&s| {
                let d = 1000.0 + v * s;
                Some(if q > 0.0 { (d / q).floor() * q } else { d })
            })
            .collect();
        (t, odo)
    }

    fn steps(odo: &[Option<f64>]) -> Vec<f64> {
        let v: Vec<f64> = odo.iter().flatten().copied().collect();
        v.windows(2).map(|w| w[1] - w[0]).collect()
    }

    #[test]
    fn a_reset_mid_ride_runs_on_at_the_speed_before_it() {
        let (t, mut odo) = odometer(2000, 100.0, 12.0, 0.0);
        for o in &mut odo[1200..] {
            *o = o.map(|x| x - 1100.0);
        }
        let (mended, jumps) = cumulative(&t, &odo);
        assert_eq!(jumps.rows, vec![1200]);
        assert!((jumps.largest - (0.12 - 1100.0)).abs() < 1e-9, "{jumps:?}");
        for s in steps(&mended) {
            assert!((s - 0.12).abs() < 1e-9, "{s}");
        }
        let said = jumps
            .describe("r.csv", &(1..=2000).collect::<Vec<u64>>(), &t)
            .expect("said");
        assert!(
            said.contains("jumps 1 time by more")
                && said.contains("line 1201, column 'odo_m', t = 12.00 s"),
            "{said}"
        );
    }

    #[test]
    fn a_dropout_to_zero_and_back_is_two_jumps_and_no_distance() {
        let (t, mut odo) = odometer(500, 100.0, 5.0, 0.0);
        odo[300] = Some(0.0);
        odo[301] = None;
        let (mended, jumps) = cumulative(&t, &odo);
        assert_eq!(jumps.rows, vec![300, 302]);
        let total = mended[499].unwrap() - mended[0].unwrap();
        assert!((total - 5.0 * 4.99).abs() < 1e-9, "{total}");
    }

    #[test]
    fn a_coarse_counter_reversing_and_standing_are_distance() {
        // A 0.1 km counter at 30 m/s: a 100 m step every 3.3 s.
        let (t, odo) = odometer(3000, 100.0, 30.0, 100.0);
        let (mended, jumps) = cumulative(&t, &odo);
        assert!(jumps.is_empty(), "{jumps:?}");
        assert_eq!(mended, odo);
        // Reversing at 8 m/s, read at 10 Hz, after a stand of 20 s.
        let t: Vec<f64> = (0..600).map(|k| k as f64 * 0.1).collect();
        let odo: Vec<Option<f64>> = t
            .iter()
            .map(|&s| {
                Some(if s < 20.0 {
                    50.0
                } else {
                    50.0 - 8.0 * (s - 20.0)
                })
            })
            .collect();
        let (mended, jumps) = cumulative(&t, &odo);
        assert!(jumps.is_empty(), "{jumps:?}");
        assert_eq!(mended, odo);
    }

    #[test]
    fn an_odometer_counting_down_is_no_jump() {
        // Sign flipped, 30 m/s read at 1 Hz, and zeroed once.
        let (t, mut odo) = odometer(120, 1.0, -30.0, 0.0);
        let (mended, jumps) = cumulative(&t, &odo);
        assert!(jumps.is_empty(), "{jumps:?}");
        assert_eq!(mended, odo);
        for o in &mut odo[60..] {
            *o = o.map(|x| x + 800.0);
        }
        let (mended, jumps) = cumulative(&t, &odo);
        assert_eq!(jumps.rows, vec![60]);
        assert!(steps(&mended).iter().all(|s| (s + 30.0).abs() < 1e-9));
    }

    /// An odometer in millimetres, or a speed in km/h read as m/s, is no
    /// run of glitches but the column's units: left as it is, for the
    /// units verdicts to name.
    #[test]
    fn wrong_units_are_no_jumps() {
        let (t, odo) = odometer(3000, 100.0, 12.0, 0.0);
        let mm: Vec<Option<f64>> = odo.iter().map(|o| o.map(|x| x * 1000.0)).collect();
        let (mended, jumps) = cumulative(&t, &mm);
        assert!(jumps.is_empty(), "{jumps:?}");
        assert_eq!(mended, mm);
        let kmh: Vec<Option<f64>> = (0..500).map(|k| Some(90.0 + 0.05 * k as f64)).collect();
        let (out, jumps) = speed("speed_mps", &kmh);
        assert!(jumps.is_empty());
        assert_eq!(out, kmh);
    }

    #[test]
    fn a_reset_after_a_stand_is_still_a_jump() {
        // 20 s standing at 5 km, then the trip meter zeroed: 250 m/s backwards.
        let t: Vec<f64> = (0..400).map(|k| k as f64 * 0.1).collect();
        let odo: Vec<Option<f64>> = t
            .iter()
            .map(|&s| Some(if s < 30.0 { 5000.0 } else { 0.0 }))
            .collect();
        let (mended, jumps) = cumulative(&t, &odo);
        assert_eq!(jumps.rows, vec![300]);
        assert!(mended.iter().all(|o| *o == Some(5000.0)), "{mended:?}");
    }

    #[test]
    fn a_negative_ground_speed_is_no_speed() {
        let v = vec![Some(3.0), Some(-1.0), Some(-1.0), Some(4.0)];
        let (out, jumps) = speed("gps_speed_mps", &v);
        assert_eq!(out, vec![Some(3.0), None, None, Some(4.0)]);
        assert_eq!(jumps.rows, vec![1, 2]);
        let said = jumps
            .describe("r.csv", &[2, 3, 4, 5], &[0.0, 1.0, 2.0, 3.0])
            .expect("said");
        assert!(
            said.contains("or negative (a ground speed has no sign"),
            "{said}"
        );
        // A wheel's forward speed is signed: reversing.
        let (out, jumps) = speed("speed_mps", &v);
        assert_eq!(out, v);
        assert!(jumps.is_empty());
    }

    #[test]
    fn invalid_speed_codes_are_left_empty() {
        let v = vec![
            Some(3.0),
            Some(655.35),
            None,
            Some(-2.0),
            Some(-120.0),
            Some(4.0),
        ];
        let (out, jumps) = speed("speed_mps", &v);
        assert_eq!(
            out,
            vec![Some(3.0), None, None, Some(-2.0), None, Some(4.0)]
        );
        assert_eq!(jumps.rows, vec![1, 4]);
        assert_eq!(jumps.largest, 655.35);
        let said = jumps
            .describe(
                "r.csv",
                &[10, 11, 12, 13, 14, 15],
                &[0.0, 0.1, 0.2, 0.3, 0.4, 0.5],
            )
            .expect("said");
        assert!(
            said.contains("2 speed samples faster than 100 m/s either way (up to 655.4 m/s")
                && said.contains("line 11, column 'speed_mps', t = 0.10 s"),
            "{said}"
        );
    }
}
