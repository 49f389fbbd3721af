//! The ride as data: the raw columns of a ride log in the file's units,
//! whatever read them. The importers (`import/`) produce it; the derived
//! signals (`signals`) and the simulator's tests read it. It sits at the
//! bottom, so that nothing that reads a ride depends on the readers of
//! every format.

use std::collections::BTreeMap;

/// Raw columns of a ride log, in the file's units.
#[derive(Clone, Debug, Default)]
pub struct RideLog {
    /// Where it came from (for messages).
    pub source: String,
    /// `# key: value` comments before the header.
    pub metadata: BTreeMap<String, String>,
    /// 1-based line number of each data row in the file (for a bag: the row number).
    pub line: Vec<u64>,
    pub t_s: Vec<f64>,
    /// Angular rate in deg/s, sensor frame (x forward, y left, z up once mounted).
    pub gyro_dps: Vec<[f64; 3]>,
    pub wheel_pulse: Option<Vec<bool>>,
    pub odo_m: Option<Vec<Option<f64>>>,
    /// Signed forward speed (m/s), an odometer alternative (integrated to distance).
    pub speed_mps: Option<Vec<Option<f64>>>,
    /// (lat, lon) in degrees, `None` where the row has no fix.
    pub fix: Vec<Option<(f64, f64)>>,
    pub gps_alt_m: Option<Vec<Option<f64>>>,
    /// The GNSS receiver's ground speed (m/s, from its Doppler
    /// measurements; never negative), on the rows where it reported one: the
    /// distance when the log has no wheel sensor.
    pub gps_speed_mps: Option<Vec<Option<f64>>>,
    /// The GNSS receiver's course over ground (degrees clockwise from north),
    /// on the rows where it reported one.
    pub gps_course_deg: Option<Vec<Option<f64>>>,
    /// 1-sigma horizontal accuracy of the fix on this row (m).
    pub gps_hacc_m: Option<Vec<Option<f64>>>,
    /// 1-sigma vertical accuracy of the fix on this row (m).
    pub gps_vacc_m: Option<Vec<Option<f64>>>,
    /// The receiver's horizontal dilution of precision for the fix on this
    /// row: where no accuracy is logged, each fix is weighted by it
    /// relative to the ride's median (see `model::fix_sigma`).
    pub gps_hdop: Option<Vec<Option<f64>>>,
    /// Satellites used in the fix on this row (a whole number; kept and
    /// reported by the checks).
    pub gps_num_sats: Option<Vec<Option<f64>>>,
    pub baro_alt_m: Option<Vec<Option<f64>>>,
    /// Specific force (m/s^2) in the same frame as the gyro, where logged.
    pub accel_mps2: Option<Vec<Option<[f64; 3]>>>,
    /// Extra numeric channels, by column name, in file order.
    pub channels: Vec<(String, Vec<Option<f64>>)>,
    /// Notes about the file that are not errors (dropped text columns, ...).
    pub warnings: Vec<String>,
    /// Rows that no line of the source holds: filled across the log's gaps
    /// before the signals are derived (see [`crate::log_gaps`]).
    pub filled: Vec<std::ops::Range<usize>>,
}

impl RideLog {
    /// The optional number columns that a log has, for what is done to
    /// every column alike.
    pub(crate) fn number_columns_mut(&mut self) -> impl Iterator<Item = &mut Vec<Option<f64>>> {
        [
            &mut self.odo_m,
            &mut self.speed_mps,
            &mut self.gps_alt_m,
            &mut self.gps_speed_mps,
            &mut self.gps_course_deg,
            &mut self.gps_hacc_m,
            &mut self.gps_vacc_m,
            &mut self.gps_hdop,
            &mut self.gps_num_sats,
            &mut self.baro_alt_m,
        ]
        .into_iter()
        .flatten()
    }

    /// Give back the columns' growth slack (up to half of a long log's
    /// memory) before the signals are derived from them.
    pub(crate) fn shrink_to_fit(&mut self) {
        self.line.shrink_to_fit();
        self.t_s.shrink_to_fit();
        self.gyro_dps.shrink_to_fit();
        self.fix.shrink_to_fit();
        for c in self.number_columns_mut() {
            c.shrink_to_fit();
        }
        if let Some(p) = &mut self.wheel_pulse {
            p.shrink_to_fit();
        }
        if let Some(a) = &mut self.accel_mps2 {
            a.shrink_to_fit();
        }
        for (_, c) in &mut self.channels {
            c.shrink_to_fit();
        }
    }

    /// Keep only the rows `rows` (their times unchanged, so the log's clock
    /// ties `t0_unix_s` and `t0_boot_s` still hold): a ride cut to what a
    /// second source covers.
    pub fn keep_rows(&mut self, rows: std::ops::Range<usize>) {
        fn cut<T>(v: &mut Vec<T>, rows: &std::ops::Range<usize>) {
            v.truncate(rows.end);
            v.drain(..rows.start.min(v.len()));
        }
        cut(&mut self.line, &rows);
        cut(&mut self.t_s, &rows);
        cut(&mut self.gyro_dps, &rows);
        cut(&mut self.fix, &rows);
        for c in self.number_columns_mut() {
            cut(c, &rows);
        }
        if let Some(p) = &mut self.wheel_pulse {
            cut(p, &rows);
        }
        if let Some(a) = &mut self.accel_mps2 {
            cut(a, &rows);
        }
        for (_, c) in &mut self.channels {
            cut(c, &rows);
        }
        self.filled = self
            .filled
            .iter()
            .map(|f| {
                f.start.max(rows.start) - rows.start
                    ..f.end.min(rows.end).max(rows.start) - rows.start
            })
            .filter(|f| !f.is_empty())
            .collect();
    }

    /// Leave out the rows `rows`, as a logger that lost them would have
    /// (the rows either side keep their times).
    pub fn drop_rows(&mut self, rows: std::ops::Range<usize>) {
        let mut after = self.clone();
        after.keep_rows(rows.end.min(self.len())..self.len());
        self.keep_rows(0..rows.start.min(self.len()));
        self.append(after);
    }

    /// Keep only the rows from `start` to `end` (s, the log's clock), the
    /// time that a second source (`what`) covers, with a warning saying so
    /// where rows are left out.
    pub fn cut_to(&mut self, start: f64, end: f64, what: &str) {
        let rows =
            self.t_s.partition_point(|&t| t < start)..self.t_s.partition_point(|&t| t <= end);
        if rows.len() < self.len() {
            let span =
                self.t_s.last().copied().unwrap_or(0.0) - self.t_s.first().copied().unwrap_or(0.0);
            self.warnings.push(format!(
                "{}: {what} covers {:.0} s of the ride's {span:.0} s: the ride is cut to {start:.1}-{end:.1} s",
                self.source,
                end - start,
            ));
            self.keep_rows(rows);
        }
    }

    /// `other`'s rows after this log's (their times already on its clock,
    /// later than its last): a column that only one of them has is empty
    /// (or, for wheel pulses, low) on the other's rows; channels are joined
    /// by name. Metadata and warnings stay this log's.
    pub fn append(&mut self, other: RideLog) {
        fn join<T: Clone>(a: &mut Option<Vec<T>>, b: Option<Vec<T>>, n: usize, m: usize, empty: T) {
            match (a.as_mut(), b) {
                (Some(a), Some(b)) => a.extend(b),
                (Some(a), None) => a.extend(std::iter::repeat_n(empty, m)),
                (None, Some(b)) => {
                    let mut v = vec![empty; n];
                    v.extend(b);
                    *a = Some(v);
                }
                (None, None) => {}
            }
        }
        let (n, m) = (self.len(), other.len());
        join(&mut self.wheel_pulse, other.wheel_pulse, n, m, false);
        join(&mut self.odo_m, other.odo_m, n, m, None);
        join(&mut self.speed_mps, other.speed_mps, n, m, None);
        join(&mut self.gps_alt_m, other.gps_alt_m, n, m, None);
        join(&mut self.gps_speed_mps, other.gps_speed_mps, n, m, None);
        join(&mut self.gps_course_deg, other.gps_course_deg, n, m, None);
        join(&mut self.gps_hacc_m, other.gps_hacc_m, n, m, None);
        join(&mut self.gps_vacc_m, other.gps_vacc_m, n, m, None);
        join(&mut self.gps_hdop, other.gps_hdop, n, m, None);
        join(&mut self.gps_num_sats, other.gps_num_sats, n, m, None);
        join(&mut self.baro_alt_m, other.baro_alt_m, n, m, None);
        join(&mut self.accel_mps2, other.accel_mps2, n, m, None);
        let mut theirs = other.channels;
        for (name, column) in &mut self.channels {
            match theirs.iter().position(|(other, _)| other == name) {
                Some(k) => column.extend(theirs.remove(k).1),
                None => column.extend(std::iter::repeat_n(None, m)),
            }
        }
        for (name, column) in theirs {
            let mut v = vec![None; n];
            v.extend(column);
            self.channels.push((name, v));
        }
        self.filled
            .extend(other.filled.iter().map(|f| f.start + n..f.end + n));
        self.line.extend(other.line);
        self.t_s.extend(other.t_s);
        self.gyro_dps.extend(other.gyro_dps);
        self.fix.extend(other.fix);
    }

    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Configured wheel circumference, when the metadata gives one.
    pub fn wheel_circumference_m(&self) -> Option<&str> {
        self.metadata
            .get("wheel_circumference_m")
            .map(String::as_str)
    }

    /// Number of GNSS speed samples (0 without the column).
    /// The Unix time (s) of `t = 0` from the `t0_unix_s` metadata, where
    /// the log gives it as a number.
    pub fn t0_unix_s(&self) -> Option<f64> {
        self.metadata
            .get("t0_unix_s")
            .and_then(|v| v.trim().parse::<f64>().ok())
    }

    pub fn gnss_speed_samples(&self) -> usize {
        self.gps_speed_mps
            .as_ref()
            .map_or(0, |s| s.iter().flatten().count())
    }

    /// Number of GPS fixes.
    pub fn fix_count(&self) -> usize {
        self.fix.iter().filter(|f| f.is_some()).count()
    }
}

#[cfg(test)]
mod tests {
    /// Every column keeps the same rows, with their values and times.
    #[test]
    fn keep_rows_cuts_every_column_alike() {
        let mut log = crate::testing::winding_log(10.0, 10.0);
        log.accel_mps2 = Some((0..log.len()).map(|j| Some([j as f64; 3])).collect());
        log.wheel_pulse = Some((0..log.len()).map(|j| j % 7 == 0).collect());
        let before = log.clone();
        log.keep_rows(20..60);
        assert_eq!(log.len(), 40);
        assert_eq!(log.t_s[..], before.t_s[20..60]);
        assert_eq!(log.line[..], before.line[20..60]);
        assert_eq!(log.gyro_dps[..], before.gyro_dps[20..60]);
        assert_eq!(log.fix[..], before.fix[20..60]);
        let (odo, was) = (log.odo_m.as_ref().unwrap(), before.odo_m.as_ref().unwrap());
        assert_eq!(odo[..], was[20..60]);
        assert_eq!(log.baro_alt_m.as_ref().unwrap().len(), 40);
        assert_eq!(log.gps_alt_m.as_ref().unwrap().len(), 40);
        assert_eq!(log.accel_mps2.as_ref().unwrap()[0], Some([20.0; 3]));
        assert_eq!(log.wheel_pulse.as_ref().unwrap().len(), 40);
        assert!(log.channels.iter().all(|(_, c)| c.len() == 40));
        log.keep_rows(30..100);
        assert_eq!(log.len(), 10);
        assert_eq!(log.t_s[0], before.t_s[50]);
    }

    #[test]
    fn dropped_rows_leave_the_rest_whole_and_the_filled_rows_follow_their_rows() {
        let mut log = crate::testing::winding_log(10.0, 10.0);
        let before = log.clone();
        log.drop_rows(20..60);
        assert_eq!(log.len(), before.len() - 40);
        assert_eq!(log.t_s[..20], before.t_s[..20]);
        assert_eq!(log.t_s[20..], before.t_s[60..]);
        assert_eq!(log.line[20], before.line[60]);
        assert_eq!(log.fix[20..], before.fix[60..]);
        assert!(log.channels.iter().all(|(_, c)| c.len() == log.len()));
        // Filled rows are cut and shifted with the rows, and appended after.
        let mut filled = before.clone();
        filled.filled = vec![5..8, 30..40];
        filled.keep_rows(6..35);
        assert_eq!(filled.filled, vec![0..2, 24..29]);
        let other = filled.clone();
        filled.append(other);
        assert_eq!(filled.filled, vec![0..2, 24..29, 29..31, 53..58]);
    }

    #[test]
    fn append_joins_every_column_and_fills_what_one_side_lacks() {
        let mut a = crate::testing::winding_log(5.0, 10.0);
        a.channels = vec![("temp_c".into(), vec![Some(20.0); a.len()])];
        let mut b = crate::testing::winding_log(5.0, 10.0);
        b.accel_mps2 = Some(vec![Some([1.0; 3]); b.len()]);
        b.channels = vec![("vbat_v".into(), vec![Some(4.0); b.len()])];
        b.odo_m = None;
        let (n, m) = (a.len(), b.len());
        a.append(b.clone());
        assert_eq!(a.len(), n + m);
        assert_eq!(a.gyro_dps[n..], b.gyro_dps[..]);
        assert_eq!(a.fix[n..], b.fix[..]);
        let accel = a.accel_mps2.as_ref().unwrap();
        assert!(accel[..n].iter().all(Option::is_none) && accel[n..].iter().all(Option::is_some));
        let odo = a.odo_m.as_ref().unwrap();
        assert_eq!(odo.len(), n + m);
        assert!(odo[n..].iter().all(Option::is_none));
        assert_eq!(a.channels.len(), 2);
        for (name, column) in &a.channels {
            assert_eq!(column.len(), n + m, "{name}");
        }
        assert_eq!(a.channels[1].1[n], Some(4.0));
        assert_eq!(a.channels[0].1[n], None);
    }
}
