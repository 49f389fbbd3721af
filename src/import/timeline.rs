//! From timestamped messages to ride-log rows, for every message-based
//! source (ROS 1 and ROS 2 bags): which topics to read, messages sorted by
//! their header stamps with duplicates dropped, and the streams joined on one
//! timeline.
//!
//! Rows are the IMU's samples (ROS IMU messages are instantaneous samples, so
//! the log says `gyro_samples: instantaneous` and the signals integrate the
//! trapezoid between rows). A GPS fix that falls between two samples gets a
//! row of its own at its own stamp, its rate and acceleration interpolated
//! linearly between the samples either side: the trapezoid over the two
//! halves then integrates exactly what it did over the whole step, and the
//! fix is compared with the path at the instant it was taken (at 30 m/s a
//! fix moved to the nearest 30 Hz sample would be up to half a metre off).
//! The odometer's speed is interpolated at every row. Only the span that
//! both the IMU and the odometer cover is kept.

use std::collections::BTreeMap;

use super::wire::{self, Cdr, FixMsg, ImuMsg, MessageType, Ros1, SpeedMsg, Wire};
use super::{LoadError, RideLog};

/// Topics asked for by name (`None`: chosen by message type).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TopicChoice {
    pub imu: Option<String>,
    pub odom: Option<String>,
    pub fix: Option<String>,
}

/// A topic of a bag.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TopicInfo {
    pub name: String,
    pub type_name: String,
    pub messages: usize,
    /// The role gyropath can give it, when its type is one it reads.
    pub kind: Option<MessageType>,
}

/// The topics read, and every topic there was.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Topics {
    pub imu: String,
    pub odom: String,
    pub fix: String,
    pub all: Vec<TopicInfo>,
}

impl Topics {
    /// The candidates for a role: `imu`, `odom` or `fix`.
    pub fn candidates(&self, role: Role) -> Vec<&TopicInfo> {
        self.all.iter().filter(|t| t.serves(role)).collect()
    }
}

impl TopicInfo {
    /// Whether its messages can be read for `role`.
    pub fn serves(&self, role: Role) -> bool {
        self.kind.is_some_and(|k| role.accepts(k))
    }
}

/// What a topic is read for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Imu,
    Odom,
    Fix,
}

impl Role {
    pub fn accepts(self, kind: MessageType) -> bool {
        matches!(
            (self, kind),
            (Self::Imu, MessageType::Imu)
                | (
                    Self::Odom,
                    MessageType::Odometry | MessageType::TwistStamped
                )
                | (Self::Fix, MessageType::NavSatFix)
        )
    }

    fn what(self) -> &'static str {
        match self {
            Self::Imu => "IMU (sensor_msgs/Imu)",
            Self::Odom => "odometer (nav_msgs/Odometry or geometry_msgs/TwistStamped)",
            Self::Fix => "GPS (sensor_msgs/NavSatFix)",
        }
    }

    fn flag(self) -> &'static str {
        match self {
            Self::Imu => "--imu",
            Self::Odom => "--odom",
            Self::Fix => "--fix",
        }
    }

    fn asked(self, choice: &TopicChoice) -> Option<&str> {
        match self {
            Self::Imu => choice.imu.as_deref(),
            Self::Odom => choice.odom.as_deref(),
            Self::Fix => choice.fix.as_deref(),
        }
    }

    fn of(kind: MessageType) -> Self {
        match kind {
            MessageType::Imu => Self::Imu,
            MessageType::Odometry | MessageType::TwistStamped => Self::Odom,
            MessageType::NavSatFix => Self::Fix,
        }
    }
}

/// The decoded messages of a recording, per topic.
#[derive(Debug, Default)]
pub struct Recording {
    pub source: String,
    topics: Vec<TopicInfo>,
    imu: BTreeMap<String, Vec<ImuMsg>>,
    speed: BTreeMap<String, Vec<SpeedMsg>>,
    fix: BTreeMap<String, Vec<FixMsg>>,
    /// Messages whose header stamp was zero (the recording time is used instead).
    unstamped: usize,
    /// Where a recording cut short ends (a byte offset): what came before
    /// it was read, the unfinished record after it left out.
    pub cut_at: Option<u64>,
}

impl Recording {
    pub fn new(source: &str) -> Self {
        Self {
            source: source.to_string(),
            ..Self::default()
        }
    }

    /// Declare a topic (a connection or a channel); declaring one twice is harmless.
    pub fn add_topic(&mut self, name: &str, type_name: &str) {
        if !self.topics.iter().any(|t| t.name == name) {
            self.topics.push(TopicInfo {
                name: name.to_string(),
                type_name: type_name.to_string(),
                messages: 0,
                kind: MessageType::from_ros_name(type_name),
            });
        }
    }

    /// A message in ROS 1 serialization.
    pub fn push_ros1(
        &mut self,
        topic: &str,
        type_name: &str,
        data: &[u8],
        bag_time_ns: i64,
        choice: &TopicChoice,
    ) -> Result<(), LoadError> {
        self.push(topic, type_name, bag_time_ns, choice, || {
            Ok(Ros1::new(data))
        })
    }

    /// A message in CDR.
    pub fn push_cdr(
        &mut self,
        topic: &str,
        type_name: &str,
        data: &[u8],
        log_time_ns: i64,
        choice: &TopicChoice,
    ) -> Result<(), LoadError> {
        self.push(topic, type_name, log_time_ns, choice, || Cdr::new(data))
    }

    /// Count a message and, when its topic may be read, decode and keep it.
    /// A message whose header stamp is zero (a driver that never fills it)
    /// takes the time it was recorded at.
    fn push<'d, W: Wire + 'd>(
        &mut self,
        topic: &str,
        type_name: &str,
        log_time_ns: i64,
        choice: &TopicChoice,
        wire: impl FnOnce() -> Result<W, wire::WireError>,
    ) -> Result<(), LoadError> {
        self.add_topic(topic, type_name);
        let Some(info) = self.topics.iter_mut().find(|t| t.name == topic) else {
            return Ok(());
        };
        info.messages += 1;
        let index = info.messages;
        let Some(kind) = info.kind else {
            return Ok(());
        };
        if Role::of(kind).asked(choice).is_some_and(|a| a != topic) {
            return Ok(());
        }
        let err = |e: wire::WireError| LoadError::Topic {
            file: self.source.clone(),
            topic: topic.to_string(),
            message: format!("message {index} ({type_name}) cannot be decoded: {e}"),
        };
        let mut w = wire().map_err(err)?;
        let mut stamp = |t_ns: &mut i64| {
            if *t_ns == 0 {
                *t_ns = log_time_ns;
                self.unstamped += 1;
            }
        };
        match kind {
            MessageType::Imu => {
                let mut m = wire::imu(&mut w).map_err(err)?;
                stamp(&mut m.t_ns);
                self.imu.entry(topic.to_string()).or_default().push(m);
            }
            MessageType::Odometry | MessageType::TwistStamped => {
                let mut m = if kind == MessageType::Odometry {
                    wire::odometry(&mut w)
                } else {
                    wire::twist_stamped(&mut w)
                }
                .map_err(err)?;
                stamp(&mut m.t_ns);
                self.speed.entry(topic.to_string()).or_default().push(m);
            }
            MessageType::NavSatFix => {
                let mut m = wire::nav_sat_fix(&mut w).map_err(err)?;
                stamp(&mut m.t_ns);
                self.fix.entry(topic.to_string()).or_default().push(m);
            }
        }
        Ok(())
    }

    /// Choose the topic for each role: the one asked for, else the only one of its type.
    pub fn choose(&self, choice: &TopicChoice) -> Result<Topics, LoadError> {
        let pick = |role: Role| -> Result<String, LoadError> {
            let candidates: Vec<&TopicInfo> =
                self.topics.iter().filter(|t| t.serves(role)).collect();
            let list = |ts: &[&TopicInfo]| {
                ts.iter()
                    .map(|t| format!("{} ({}, {} messages)", t.name, t.type_name, t.messages))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let every: Vec<&TopicInfo> = self.topics.iter().collect();
            let err = |message: String| LoadError::File {
                file: self.source.clone(),
                message,
            };
            if let Some(asked) = role.asked(choice) {
                let topic_err = |what: String| LoadError::Topic {
                    file: self.source.clone(),
                    topic: asked.to_string(),
                    message: format!(
                        "{what}; candidates: {}",
                        if candidates.is_empty() {
                            "none".into()
                        } else {
                            list(&candidates)
                        }
                    ),
                };
                return match self.topics.iter().find(|t| t.name == asked) {
                    Some(t) if t.serves(role) => Ok(asked.to_string()),
                    Some(t) => Err(topic_err(format!(
                        "is {}, not the role asked for",
                        t.type_name
                    ))),
                    None => Err(topic_err("no such topic".into())),
                };
            }
            match candidates.as_slice() {
                [one] => Ok(one.name.clone()),
                [] => Err(err(format!(
                    "no {} topic; the recording has: {}",
                    role.what(),
                    if every.is_empty() {
                        "no topics".into()
                    } else {
                        list(&every)
                    }
                ))),
                many => Err(err(format!(
                    "{} {} topics: choose one with {} (candidates: {})",
                    many.len(),
                    role.what(),
                    role.flag(),
                    list(many)
                ))),
            }
        };
        Ok(Topics {
            imu: pick(Role::Imu)?,
            odom: pick(Role::Odom)?,
            fix: pick(Role::Fix)?,
            all: self.topics.clone(),
        })
    }
}

/// The row of the times `t` (increasing, not empty) nearest `x`; the
/// earlier of two as near.
pub(crate) fn nearest_row(t: &[f64], x: f64) -> usize {
    let i = t.partition_point(|&v| v < x);
    if i == 0 {
        0
    } else if i >= t.len() || x - t[i - 1] <= t[i] - x {
        i - 1
    } else {
        i
    }
}

/// One GNSS sample of a device that logs its receiver apart from its gyro
/// (cameras, autopilots, dashcams): its time on the ride's clock (s), and
/// what it measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GnssSample {
    pub t: f64,
    /// The receiver's own time of the sample (s, any origin), by which its
    /// seconds are counted: its UTC stamp where the log has one (arrival
    /// times jitter), else `t`.
    pub stamp: f64,
    pub lat: f64,
    pub lon: f64,
    /// Height above the ellipsoid (m), where known.
    pub alt: Option<f64>,
    /// Ground speed (m/s) and course (degrees from north), where known.
    pub speed: Option<f64>,
    pub course: Option<f64>,
    /// The receiver's horizontal accuracy (m), where known.
    pub hacc: Option<f64>,
    /// Its horizontal dilution of precision and satellites used, where known.
    pub hdop: Option<f64>,
    pub sats: Option<f64>,
}

/// A receiver's HDOP and satellite count as the ride-log format takes them
/// ([`super::ride_csv::HDOP_RANGE`], a whole number in
/// [`super::ride_csv::SATS_RANGE`]); a value outside is left out.
fn receiver_quality(hdop: Option<f64>, sats: Option<f64>) -> (Option<f64>, Option<f64>) {
    use super::ride_csv::{HDOP_RANGE, SATS_RANGE};
    (
        hdop.filter(|v| HDOP_RANGE.contains(v)),
        sats.filter(|v| SATS_RANGE.contains(v) && v.fract() == 0.0),
    )
}

/// Put GNSS samples on the rows of `log` (times `log.t_s`): every sample's
/// speed and course on the row nearest it (`gps_speed_mps`,
/// `gps_course_deg`), and the sample nearest each second of its `stamp`
/// counted from the first (the earlier of two as near) as a fix with its
/// height and accuracy.
/// One fix per second is the rate the model's GPS error is built for
/// (receivers at 5-18 Hz repeat their own filter's state between seconds);
/// the speed is kept at the receiver's rate, where the distance gains from it.
/// Samples outside the rows' time, or with a position out of range, are left
/// out; returns the first fix's sample, for the clock.
pub fn place_gnss(log: &mut RideLog, samples: &[GnssSample]) -> Option<GnssSample> {
    let n = log.t_s.len();
    let (Some(&first_t), Some(&last_t)) = (log.t_s.first(), log.t_s.last()) else {
        return None;
    };
    let nearest = |x: f64| nearest_row(&log.t_s, x);
    let mut rows = Vec::with_capacity(samples.len());
    let mut chosen: BTreeMap<i64, (f64, usize)> = BTreeMap::new();
    let mut start = None;
    for (k, s) in samples.iter().enumerate() {
        let position = (-90.0..=90.0).contains(&s.lat)
            && (-180.0..=360.0).contains(&s.lon)
            && (s.lat, s.lon) != (0.0, 0.0);
        if !position {
            rows.push(None);
            continue;
        }
        // Seconds count from the receiver's first fix, in the rows' time or not.
        let t0 = *start.get_or_insert(s.stamp);
        if !(s.t.is_finite() && (first_t..=last_t).contains(&s.t)) {
            rows.push(None);
            continue;
        }
        rows.push(Some(nearest(s.t)));
        let second = (s.stamp - t0).round();
        let off = (s.stamp - t0 - second).abs();
        let best = chosen.entry(second as i64).or_insert((off, k));
        // Within a microsecond is as near (stamps of 1e9 s carry 1e-7 s of
        // rounding): the earlier stays.
        if off < best.0 - 1e-6 {
            *best = (off, k);
        }
    }
    let column = |c: &mut Option<Vec<Option<f64>>>| {
        c.get_or_insert_with(|| vec![None; n]);
    };
    if samples.iter().any(|s| s.speed.is_some()) {
        column(&mut log.gps_speed_mps);
    }
    if samples.iter().any(|s| s.course.is_some()) {
        column(&mut log.gps_course_deg);
    }
    for (s, row) in samples.iter().zip(&rows) {
        let Some(row) = *row else { continue };
        if let (Some(col), Some(v)) = (log.gps_speed_mps.as_mut(), s.speed)
            && v.is_finite()
            && v >= 0.0
        {
            col[row] = Some(v);
        }
        if let (Some(col), Some(v)) = (log.gps_course_deg.as_mut(), s.course)
            && v.is_finite()
        {
            col[row] = Some(v.rem_euclid(360.0));
        }
    }
    if chosen.values().any(|&(_, k)| samples[k].alt.is_some()) {
        column(&mut log.gps_alt_m);
    }
    if chosen.values().any(|&(_, k)| samples[k].hacc.is_some()) {
        column(&mut log.gps_hacc_m);
    }
    if chosen.values().any(|&(_, k)| samples[k].hdop.is_some()) {
        column(&mut log.gps_hdop);
    }
    if chosen.values().any(|&(_, k)| samples[k].sats.is_some()) {
        column(&mut log.gps_num_sats);
    }
    let mut shared = 0;
    for &(_, k) in chosen.values() {
        let (s, Some(row)) = (samples[k], rows[k]) else {
            continue;
        };
        if log.fix[row].is_some() {
            shared += 1;
            continue;
        }
        log.fix[row] = Some((s.lat, s.lon));
        if let Some(a) = log.gps_alt_m.as_mut() {
            a[row] = s.alt.filter(|v| v.is_finite());
        }
        if let Some(h) = log.gps_hacc_m.as_mut() {
            h[row] = s.hacc.filter(|v| v.is_finite() && *v > 0.0);
        }
        let (hdop, sats) = receiver_quality(s.hdop, s.sats);
        if let Some(h) = log.gps_hdop.as_mut() {
            h[row] = hdop;
        }
        if let Some(n) = log.gps_num_sats.as_mut() {
            n[row] = sats;
        }
    }
    if shared > 0 {
        log.warnings.push(format!(
            "{}: {shared} GNSS fix(es) fall nearest a gyro row that already holds one (the gyro is logged more sparsely than the fixes); only the first on each row is kept",
            log.source
        ));
    }
    chosen.values().next().map(|&(_, k)| samples[k])
}

/// Sort messages by stamp (stable) and drop exact duplicates of a stamp.
/// Returns how many were out of order and how many were dropped.
fn sort_dedup<T>(v: &mut Vec<T>, stamp: impl Fn(&T) -> i64) -> (usize, usize) {
    let out_of_order = v.windows(2).filter(|w| stamp(&w[1]) < stamp(&w[0])).count();
    v.sort_by_key(&stamp);
    let before = v.len();
    v.dedup_by(|b, a| stamp(a) == stamp(b));
    (out_of_order, before - v.len())
}

/// Linear interpolation of `value` over messages sorted by `stamp`, at `t` (held at the ends).
fn interpolate<T>(
    msgs: &[T],
    cursor: &mut usize,
    t: i64,
    stamp: impl Fn(&T) -> i64,
    value: impl Fn(&T) -> f64,
) -> f64 {
    while *cursor + 1 < msgs.len() && stamp(&msgs[*cursor + 1]) <= t {
        *cursor += 1;
    }
    let a = &msgs[*cursor];
    match msgs.get(*cursor + 1) {
        Some(b) if stamp(a) <= t => {
            let s = (t - stamp(a)) as f64 / (stamp(b) - stamp(a)) as f64;
            value(a) + s * (value(b) - value(a))
        }
        _ => value(a),
    }
}

/// What the odometer stream measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OdometerKind {
    /// Signed forward speed (m/s), written as `speed_mps`.
    Speed,
    /// Cumulative distance (m), written as `odo_m`.
    Distance,
}

/// Timestamped streams to join into rows; `names` say where each came from
/// (topics, or files and columns) for messages.
#[derive(Debug, Default)]
pub struct Streams {
    pub source: String,
    pub imu: Vec<ImuMsg>,
    /// Odometer samples: `speed` holds the speed or the cumulative distance.
    pub odometer: Vec<SpeedMsg>,
    pub odometer_kind: Option<OdometerKind>,
    pub fixes: Vec<FixMsg>,
    /// The IMU rows are means over the step before them, not instantaneous samples.
    pub mean_samples: bool,
    /// Names of the IMU, odometer and GPS sources.
    pub names: [String; 3],
    pub warnings: Vec<String>,
}

/// Join the chosen topics of a recording into ride-log rows (gyro in deg/s,
/// sensor frame as recorded; time from the first row, its stamp in the metadata).
pub fn assemble(mut rec: Recording, topics: &Topics) -> Result<RideLog, LoadError> {
    let mut streams = Streams {
        source: rec.source.clone(),
        imu: rec.imu.remove(&topics.imu).unwrap_or_default(),
        odometer: rec.speed.remove(&topics.odom).unwrap_or_default(),
        odometer_kind: Some(OdometerKind::Speed),
        fixes: rec.fix.remove(&topics.fix).unwrap_or_default(),
        mean_samples: false,
        names: [topics.imu.clone(), topics.odom.clone(), topics.fix.clone()],
        warnings: Vec::new(),
    };
    if let Some(at) = rec.cut_at {
        streams.warnings.push(format!(
            "{}: the recording ends in the middle of a record at byte {at} (a recorder stopped abruptly, or a copy cut short): the records before it are read, the unfinished one left out",
            rec.source
        ));
    }
    if rec.unstamped > 0 {
        streams.warnings.push(format!(
            "{}: {} message(s) have no header stamp (zero); the time they were recorded at is used",
            rec.source, rec.unstamped
        ));
    }
    let mut log = join(streams)?;
    log.metadata.insert("imu_topic".into(), topics.imu.clone());
    log.metadata
        .insert("odom_topic".into(), topics.odom.clone());
    log.metadata.insert("fix_topic".into(), topics.fix.clone());
    Ok(log)
}

/// Join streams into ride-log rows: the IMU's samples, plus a row at each fix
/// that falls between two of them, over the span the IMU and the odometer both cover.
pub fn join(mut st: Streams) -> Result<RideLog, LoadError> {
    let file = st.source.clone();
    let [imu_name, odo_name, fix_name] = st.names.clone();
    let topic_err = |topic: &str, message: String| LoadError::Topic {
        file: file.clone(),
        topic: topic.to_string(),
        message,
    };
    let mut warnings = std::mem::take(&mut st.warnings);
    for (name, (late, dup)) in [
        (&imu_name, sort_dedup(&mut st.imu, |m| m.t_ns)),
        (&odo_name, sort_dedup(&mut st.odometer, |m| m.t_ns)),
        (&fix_name, sort_dedup(&mut st.fixes, |m| m.t_ns)),
    ] {
        if late > 0 || dup > 0 {
            warnings.push(format!(
                "{file}: '{name}': {late} message(s) out of order by time stamp were sorted, {dup} with a repeated stamp dropped"
            ));
        }
    }
    let (imu, speed, mut fixes) = (st.imu, st.odometer, st.fixes);
    if let Some((i, _)) = imu.iter().enumerate().find(|(_, m)| {
        !m.angular_velocity.iter().all(|v| v.is_finite())
            || m.linear_acceleration
                .is_some_and(|a| !a.iter().all(|v| v.is_finite()))
    }) {
        return Err(topic_err(
            &imu_name,
            format!(
                "message {} (by stamp) has a non-finite rate or acceleration",
                i + 1
            ),
        ));
    }
    if let Some(i) = speed.iter().position(|m| !m.speed.is_finite()) {
        return Err(topic_err(
            &odo_name,
            format!(
                "message {} (by stamp) has a non-finite odometer value",
                i + 1
            ),
        ));
    }
    if imu.len() < 2 {
        return Err(topic_err(
            &imu_name,
            format!("{} IMU message(s); at least two are needed", imu.len()),
        ));
    }
    let Some(kind) = st.odometer_kind.filter(|_| !speed.is_empty()) else {
        return Err(topic_err(&odo_name, "no odometer messages".into()));
    };
    // The span both the IMU and the odometer cover.
    let start = imu[0].t_ns.max(speed[0].t_ns);
    let end = imu[imu.len() - 1].t_ns.min(speed[speed.len() - 1].t_ns);
    let imu: Vec<ImuMsg> = imu
        .into_iter()
        .filter(|m| (start..=end).contains(&m.t_ns))
        .collect();
    if imu.len() < 2 {
        return Err(LoadError::File {
            file,
            message: format!(
                "the IMU ('{imu_name}') and the odometer ('{odo_name}') do not overlap in time"
            ),
        });
    }
    let fix_count = fixes.len();
    let mut no_fix = 0;
    // How many fixes' coordinates are no degrees (units: 10^7, NMEA's
    // degrees and minutes), and the first of them.
    let (mut out_of_range, mut first_out) = (0usize, None);
    fixes.retain(|f| {
        let finite = f.status >= 0 && f.lat.is_finite() && f.lon.is_finite();
        let in_range = (-90.0..=90.0).contains(&f.lat) && (-180.0..=360.0).contains(&f.lon);
        if finite && !in_range {
            out_of_range += 1;
            first_out = first_out.or(Some((f.lat, f.lon)));
            return false;
        }
        let usable = finite && !(f.lat == 0.0 && f.lon == 0.0);
        no_fix += usize::from(!usable);
        usable
    });
    let range_said = first_out.map(|(lat, lon)| {
        format!(
            "'{fix_name}': {out_of_range} of {fix_count} fixes are outside -90..90, -180..360 degrees (the first: {lat}, {lon}{})",
            super::ride_csv::coordinate_hint(lat, lon)
        )
    });
    if let Some(said) = range_said {
        if fixes.is_empty() {
            return Err(LoadError::File {
                file,
                message: said,
            });
        }
        warnings.push(format!("{file}: {said}; they are left out"));
    }
    if no_fix > 0 {
        warnings.push(format!(
            "{file}: '{fix_name}': {no_fix} of {fix_count} messages carry no fix (status -1, NaN or 0,0) and are left out"
        ));
    }
    // Fixes within the rows' span: rows start at the first IMU sample kept.
    let outside = fixes.len();
    let span = imu[0].t_ns..=imu[imu.len() - 1].t_ns;
    fixes.retain(|f| span.contains(&f.t_ns));
    let outside = outside - fixes.len();
    if outside > 0 {
        warnings.push(format!(
            "{file}: {outside} GPS fix(es) before the IMU and the odometer both run, or after either stops, are left out"
        ));
    }
    if fixes.is_empty() {
        return Err(topic_err(
            &fix_name,
            "no usable GPS fix while the IMU and the odometer run".into(),
        ));
    }

    let has_alt = fixes.iter().any(|f| f.alt.is_finite());
    let has_hacc = fixes.iter().any(|f| f.hacc.is_some());
    let has_vacc = fixes.iter().any(|f| f.vacc.is_some());
    let has_hdop = fixes.iter().any(|f| f.hdop.is_some());
    let has_sats = fixes.iter().any(|f| f.sats.is_some());
    let t0 = imu[0].t_ns;
    let n = imu.len() + fixes.len();
    fn column<T>(on: bool, n: usize) -> Option<Vec<T>> {
        on.then(|| Vec::with_capacity(n))
    }
    let mut log = RideLog {
        source: file.clone(),
        speed_mps: column(kind == OdometerKind::Speed, n),
        odo_m: column(kind == OdometerKind::Distance, n),
        gps_alt_m: column(has_alt, n),
        gps_hacc_m: column(has_hacc, n),
        gps_vacc_m: column(has_vacc, n),
        gps_hdop: column(has_hdop, n),
        gps_num_sats: column(has_sats, n),
        accel_mps2: column(imu.iter().any(|m| m.linear_acceleration.is_some()), n),
        warnings,
        ..RideLog::default()
    };
    let dps = 180.0 / std::f64::consts::PI;
    let mut odo_cursor = 0usize;
    let mut push_row = |log: &mut RideLog,
                        t_ns: i64,
                        gyro: [f64; 3],
                        acc: Option<[f64; 3]>,
                        fix: Option<&FixMsg>| {
        log.line.push(log.t_s.len() as u64 + 1);
        log.t_s.push((t_ns - t0) as f64 * 1e-9);
        log.gyro_dps.push(gyro.map(|w| w * dps));
        if let Some(a) = log.accel_mps2.as_mut() {
            a.push(acc);
        }
        let v = interpolate(&speed, &mut odo_cursor, t_ns, |m| m.t_ns, |m| m.speed);
        if let Some(s) = log.speed_mps.as_mut().or(log.odo_m.as_mut()) {
            s.push(Some(v));
        }
        log.fix.push(fix.map(|f| (f.lat, f.lon)));
        let quality = fix.map_or((None, None), |f| receiver_quality(f.hdop, f.sats));
        for (col, value) in [
            (
                &mut log.gps_alt_m,
                fix.map(|f| f.alt).filter(|a| a.is_finite()),
            ),
            (&mut log.gps_hacc_m, fix.and_then(|f| f.hacc)),
            (&mut log.gps_vacc_m, fix.and_then(|f| f.vacc)),
            (&mut log.gps_hdop, quality.0),
            (&mut log.gps_num_sats, quality.1),
        ] {
            if let Some(c) = col.as_mut() {
                c.push(value);
            }
        }
    };
    let mut k = 0usize;
    for (i, m) in imu.iter().enumerate() {
        // Fixes strictly before this sample get rows of their own.
        while k < fixes.len() && fixes[k].t_ns < m.t_ns {
            let f = &fixes[k];
            let p = &imu[i.saturating_sub(1)];
            // Instantaneous samples are interpolated; a mean over the step holds over its parts.
            let s = if st.mean_samples || m.t_ns <= p.t_ns {
                1.0
            } else {
                (f.t_ns - p.t_ns) as f64 / (m.t_ns - p.t_ns) as f64
            };
            let lerp = |a: [f64; 3], b: [f64; 3]| std::array::from_fn(|j| a[j] + s * (b[j] - a[j]));
            let acc = match (p.linear_acceleration, m.linear_acceleration) {
                (Some(a), Some(b)) => Some(lerp(a, b)),
                _ => None,
            };
            push_row(
                &mut log,
                f.t_ns,
                lerp(p.angular_velocity, m.angular_velocity),
                acc,
                Some(f),
            );
            k += 1;
        }
        let fix = (k < fixes.len() && fixes[k].t_ns == m.t_ns).then(|| &fixes[k]);
        if fix.is_some() {
            k += 1;
        }
        push_row(
            &mut log,
            m.t_ns,
            m.angular_velocity,
            m.linear_acceleration,
            fix,
        );
    }
    log.metadata.insert(
        "gyro_samples".into(),
        if st.mean_samples {
            "mean"
        } else {
            "instantaneous"
        }
        .into(),
    );
    log.metadata
        .insert("t0_unix_s".into(), format!("{:.9}", t0 as f64 * 1e-9));
    log.metadata
        .insert("gyro_frame".into(), "as recorded (see mount)".into());
    log.shrink_to_fit();
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::wire::Writer;

    fn recording() -> Recording {
        let mut r = Recording::new("t.bag");
        let none = TopicChoice::default();
        // IMU at 10 Hz with one sample repeated and one out of order; odometry at 5 Hz; fixes at 1 Hz.
        let mut stamps: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        stamps.swap(10, 11);
        stamps.push(2.0);
        for t in stamps {
            let m = Writer::ros1().imu(100.0 + t, [0.0, 0.0, 0.1 * t], [0.0, 0.0, 9.8]);
            r.push_ros1("/imu", "sensor_msgs/Imu", &m, 0, &none)
                .unwrap();
        }
        for i in 0..26 {
            let t = i as f64 * 0.2;
            let m = Writer::ros1().odometry(100.0 + t, t);
            r.push_ros1("/odom", "nav_msgs/Odometry", &m, 0, &none)
                .unwrap();
        }
        for i in 0..6 {
            let m = Writer::ros1().fix(100.05 + i as f64, 42.0, -71.0 + 1e-5 * i as f64, 1.0);
            r.push_ros1("/fix", "sensor_msgs/NavSatFix", &m, 0, &none)
                .unwrap();
        }
        r
    }

    #[test]
    fn streams_join_on_one_timeline() {
        let rec = recording();
        let topics = rec.choose(&TopicChoice::default()).unwrap();
        assert_eq!((topics.imu.as_str(), topics.fix.as_str()), ("/imu", "/fix"));
        let log = assemble(rec, &topics).unwrap();
        // 50 IMU rows (the repeat dropped) plus 5 fixes between samples (the one at 5.05 s is past the IMU).
        assert_eq!(log.len(), 55);
        assert!(log.t_s.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(log.fix_count(), 5);
        // A fix row sits at its own stamp, its rate interpolated (0.1 t rad/s at t = 1.05 s).
        let row = log.fix.iter().position(|f| f.is_some()).unwrap();
        let t = log.t_s[row];
        assert!((t - 0.05).abs() < 1e-9, "{t}");
        let j = log
            .fix
            .iter()
            .enumerate()
            .filter(|(_, f)| f.is_some())
            .nth(1)
            .unwrap()
            .0;
        assert!((log.t_s[j] - 1.05).abs() < 1e-9);
        let expect = 0.1 * 1.05 * 180.0 / std::f64::consts::PI;
        assert!((log.gyro_dps[j][2] - expect).abs() < 1e-9);
        // Speed (equal to t) interpolated at the rows.
        assert!((log.speed_mps.as_ref().unwrap()[j].unwrap() - 1.05).abs() < 1e-9);
        assert_eq!(log.gps_hacc_m.as_ref().unwrap()[j], Some(1.0));
        assert!(
            log.warnings
                .iter()
                .any(|w| w.contains("2 message(s) out of order")
                    && w.contains("1 with a repeated stamp")),
            "{:?}",
            log.warnings
        );
    }

    #[test]
    fn topics_are_chosen_by_type_or_by_name_and_errors_list_candidates() {
        let mut rec = recording();
        let none = TopicChoice::default();
        let m = Writer::ros1().imu(100.0, [0.0; 3], [0.0; 3]);
        rec.push_ros1("/imu2", "sensor_msgs/Imu", &m, 0, &none)
            .unwrap();
        let e = rec.choose(&none).unwrap_err().to_string();
        assert!(
            e.contains("2 IMU") && e.contains("--imu") && e.contains("/imu2"),
            "{e}"
        );
        let asked = TopicChoice {
            imu: Some("/imu2".into()),
            ..TopicChoice::default()
        };
        assert_eq!(rec.choose(&asked).unwrap().imu, "/imu2");
        let wrong = TopicChoice {
            imu: Some("/fix".into()),
            ..TopicChoice::default()
        };
        let e = rec.choose(&wrong).unwrap_err().to_string();
        assert!(
            e.contains("'/fix'") && e.contains("NavSatFix") && e.contains("candidates"),
            "{e}"
        );
        let missing = Recording::new("empty.mcap")
            .choose(&none)
            .unwrap_err()
            .to_string();
        assert!(
            missing.contains("empty.mcap") && missing.contains("no IMU"),
            "{missing}"
        );
    }
}
