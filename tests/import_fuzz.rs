//! Bags are untrusted input: truncated files, corrupt chunks, wrong message
//! types and missing topics give a clear error naming the file (and the topic
//! where there is one), never a panic or a hang.

use std::io::Cursor;

use gyropath::import::ros1::{self, BagWriter};
use gyropath::import::ros2::{self, McapWriter};
use gyropath::import::timeline::{Recording, TopicChoice};
use gyropath::import::wire::Writer;
use proptest::prelude::*;

const HUSKY_BAG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/real/robot_localization-test1/test1.bag"
);

/// A message: topic, ROS 1 type, time, ROS 1 payload, CDR payload.
type Message = (&'static str, &'static str, f64, Vec<u8>, Vec<u8>);

/// A minute of a small robot: IMU 20 Hz, odometry 10 Hz, fixes 1 Hz.
fn messages() -> Vec<Message> {
    let mut out = Vec::new();
    for i in 0..1200 {
        let t = 1000.0 + i as f64 * 0.05;
        let (g, a) = ([0.0, 0.0, 0.1], [0.0, 0.0, 9.81]);
        out.push((
            "/imu",
            "sensor_msgs/Imu",
            t,
            Writer::ros1().imu(t, g, a),
            Writer::cdr().imu(t, g, a),
        ));
        if i % 2 == 0 {
            out.push((
                "/odom",
                "nav_msgs/Odometry",
                t,
                Writer::ros1().odometry(t, 1.0),
                Writer::cdr().odometry(t, 1.0),
            ));
        }
        if i % 20 == 10 {
            let lon = -71.0 + 1e-5 * i as f64;
            out.push((
                "/fix",
                "sensor_msgs/NavSatFix",
                t,
                Writer::ros1().fix(t, 42.0, lon, 4.0),
                Writer::cdr().fix(t, 42.0, lon, 4.0),
            ));
        }
    }
    out
}

fn ros1_bag() -> Vec<u8> {
    let mut bag = BagWriter::new();
    for (topic, ty, t, data, _) in messages() {
        bag.message(topic, ty, t, &data);
    }
    bag.bytes
}

fn mcap(skip_imu: bool, zstd: bool) -> Vec<u8> {
    let mut buf = Cursor::new(Vec::new());
    let mut w = McapWriter::new(&mut buf, zstd).unwrap();
    for (topic, ty, t, _, data) in messages() {
        if skip_imu && topic == "/imu" {
            continue;
        }
        let ty2 = ty.replace('/', "/msg/");
        w.message(topic, &ty2, (t * 1e9) as u64, &data).unwrap();
    }
    w.finish().unwrap();
    buf.into_inner()
}

fn read_ros1(bytes: &[u8]) -> Result<usize, String> {
    let choice = TopicChoice::default();
    let (rec, topics) = ros1::read_from(bytes, "fuzz.bag", &choice).map_err(|e| e.to_string())?;
    let log = gyropath::import::timeline::assemble(rec, &topics).map_err(|e| e.to_string())?;
    Ok(log.len())
}

fn read_mcap(bytes: &[u8]) -> Result<usize, String> {
    let choice = TopicChoice::default();
    let mut rec = Recording::new("fuzz.mcap");
    ros2::read_mcap(bytes, "fuzz.mcap", &mut rec, &choice).map_err(|e| e.to_string())?;
    let topics = rec.choose(&choice).map_err(|e| e.to_string())?;
    let log = gyropath::import::timeline::assemble(rec, &topics).map_err(|e| e.to_string())?;
    Ok(log.len())
}

/// A corrupted zstd chunk whose header claims more bytes than its frame
/// holds made the mcap crate's streaming decompression loop forever (found
/// by `corrupt_bags_never_panic`); chunks are now decompressed here, into a
/// buffer of the claimed size, and this is an error naming the file.
#[test]
fn a_chunk_shorter_than_its_header_says_is_an_error_not_a_hang() {
    let mut m = mcap(false, true);
    for (at, byte) in [
        (1892878usize, 122u8),
        (1223443, 17),
        (171322, 5),
        (1831985, 132),
        (95748, 179),
        (1529149, 91),
    ] {
        let k = at % m.len();
        m[k] ^= byte | 1;
    }
    let e = read_mcap(&m).expect_err("corrupt");
    assert!(e.contains("fuzz.mcap") && e.contains("chunk"), "{e}");
}

#[test]
fn the_writers_make_bags_the_readers_read() {
    // 1199 IMU rows inside the odometer's span; the fixes fall on samples.
    assert_eq!(read_ros1(&ros1_bag()), Ok(1199));
    assert_eq!(read_mcap(&mcap(false, true)), read_ros1(&ros1_bag()));
    assert_eq!(read_mcap(&mcap(false, false)), read_ros1(&ros1_bag()));
}

/// `rosbag record` packs messages into chunks (bz2 or lz4 when asked): a
/// chunked bag in every compression reads to the same rows as a bare one,
/// with connections declared in one chunk and used in later ones.
#[test]
fn chunked_bags_in_every_compression_read_the_same() {
    let bare = read_ros1(&ros1_bag());
    for compression in ["none", "bz2", "lz4"] {
        let mut bag = BagWriter::chunked(compression);
        for (k, (topic, ty, t, data, _)) in messages().into_iter().enumerate() {
            bag.message(topic, ty, t, &data);
            if k % 500 == 499 {
                bag.flush_chunk().unwrap();
            }
        }
        bag.flush_chunk().unwrap();
        assert!(bag.bytes.len() > 1000);
        assert_eq!(read_ros1(&bag.bytes), bare, "{compression}");
        // A corrupt compressed chunk is an error naming the file, never a panic.
        let mut bad = bag.bytes.clone();
        let at = bad.len() / 2;
        bad[at] ^= 0x5a;
        if let Err(e) = read_ros1(&bad) {
            assert!(e.contains("fuzz.bag"), "{compression}: {e}");
        }
    }
}

#[test]
fn an_mcap_with_no_imu_topic_names_the_file_and_what_it_has() {
    let e = read_mcap(&mcap(true, true)).unwrap_err();
    assert!(e.contains("fuzz.mcap") && e.contains("no IMU"), "{e}");
    assert!(e.contains("/odom") && e.contains("/fix"), "{e}");
}

#[test]
fn a_wrong_message_type_names_the_topic() {
    let mut bag = BagWriter::new();
    // Declared an IMU, carrying fixes.
    bag.message(
        "/imu",
        "sensor_msgs/Imu",
        1.0,
        &Writer::ros1().fix(1.0, 42.0, -71.0, 1.0),
    );
    let e = read_ros1(&bag.bytes).unwrap_err();
    assert!(
        e.contains("fuzz.bag") && e.contains("'/imu'") && e.contains("cannot be decoded"),
        "{e}"
    );
}

#[test]
fn not_a_bag_is_told_apart() {
    let e = read_ros1(b"t_s,gx_dps\n").unwrap_err();
    assert!(
        e.contains("fuzz.bag") && e.contains("not a ROS 1 bag"),
        "{e}"
    );
    let e = read_mcap(b"t_s,gx_dps\n").unwrap_err();
    assert!(e.contains("fuzz.mcap") && e.contains("MCAP"), "{e}");
}

/// A recording cut short (a recorder killed, a disk full, a copy cut
/// short) keeps the records before the cut, and says where it ends; it was
/// refused whole before. Cut before anything usable, it is an error naming
/// the file.
#[test]
fn the_real_bag_cut_short_keeps_what_came_before_the_cut() {
    let bytes = std::fs::read(HUSKY_BAG).unwrap();
    let whole = read_ros1(&bytes).unwrap();
    let mut rows = Vec::new();
    for cut in [bytes.len() / 3, bytes.len() * 7 / 10, bytes.len() - 7] {
        let choice = TopicChoice::default();
        let (rec, topics) = ros1::read_from(&bytes[..cut], "fuzz.bag", &choice).unwrap();
        assert!(rec.cut_at.is_some_and(|at| at < cut as u64), "cut {cut}");
        let log = gyropath::import::timeline::assemble(rec, &topics).unwrap();
        assert!(
            log.warnings
                .iter()
                .any(|w| w
                    .starts_with("fuzz.bag: the recording ends in the middle of a record at byte")),
            "cut {cut}: {:?}",
            log.warnings
        );
        rows.push(log.len());
    }
    assert!(
        rows[0] < rows[1] && rows[1] <= rows[2] && rows[2] <= whole,
        "{rows:?} of {whole}"
    );
    for cut in [20, 5000] {
        let e = read_ros1(&bytes[..cut]).unwrap_err();
        assert!(e.contains("fuzz.bag"), "cut {cut}: {e}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn truncated_bags_never_panic(cut in 0usize..1_000_000) {
        let bag = ros1_bag();
        let cut = cut % bag.len();
        if let Err(e) = read_ros1(&bag[..cut]) {
            prop_assert!(e.contains("fuzz.bag"), "{}", e);
        }
        let m = mcap(false, true);
        let cut = cut % m.len();
        if let Err(e) = read_mcap(&m[..cut]) {
            prop_assert!(e.contains("fuzz.mcap"), "{}", e);
        }
    }

    #[test]
    fn corrupt_bags_never_panic(flips in proptest::collection::vec((0usize..2_000_000, any::<u8>()), 1..8)) {
        let mut bag = ros1_bag();
        let mut m = mcap(false, true);
        for &(at, byte) in &flips {
            let i = at % bag.len();
            bag[i] ^= byte | 1;
            let k = at % m.len();
            m[k] ^= byte | 1;
        }
        if let Err(e) = read_ros1(&bag) {
            prop_assert!(e.contains("fuzz.bag"), "{}", e);
        }
        if let Err(e) = read_mcap(&m) {
            prop_assert!(e.contains("fuzz.mcap"), "{}", e);
        }
    }

    #[test]
    fn the_real_bags_bz2_chunks_corrupted_never_panic(at in 0usize..1_470_000, byte in 1u8..=255) {
        let mut bytes = std::fs::read(HUSKY_BAG).unwrap();
        let i = at % bytes.len();
        bytes[i] ^= byte;
        if let Err(e) = read_ros1(&bytes) {
            prop_assert!(e.contains("fuzz.bag"), "{}", e);
        }
    }
}

const ULOG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/formats/ulog/sample_log_small.ulg"
);

const GNSSLOGGER: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/formats/android_gnsslogger/pixel6.txt"
);

const DATAFLASH: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/formats/ardupilot_dataflash/backend_log_80k.bin"
);

const FIT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/formats/fit/elemnt-bolt-no-application-id-inside-developer-data-id.fit"
);

const CAN_SPEED: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/formats/comma2k19-segment/segment/processed_log/CAN/speed/value"
);

/// The file at `path` with bytes flipped (`byte | 1`, so each one changes)
/// and cut short at `cut` (modulo its length + 1).
fn damaged(path: &str, cut: usize, flips: &[(usize, u8)]) -> Vec<u8> {
    let mut bytes = std::fs::read(path).unwrap();
    for &(at, byte) in flips {
        let i = at % bytes.len();
        bytes[i] ^= byte | 1;
    }
    bytes.truncate(cut % (bytes.len() + 1));
    bytes
}

/// A reader's ride log turned into signals: its row count, or the error.
fn to_signals(
    read: Result<gyropath::import::RideLog, gyropath::import::LoadError>,
) -> Result<usize, String> {
    let log = read.map_err(|e| e.to_string())?;
    let n = log.len();
    gyropath::signals::Signals::from_owned_log(log).map_err(|e| e.to_string())?;
    Ok(n)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// A PX4 log cut off (a power loss) or with bytes flipped: an error
    /// naming the file or the part before the damage, never a panic.
    #[test]
    fn damaged_ulogs_never_panic(cut in 0usize..1_000_000, flips in proptest::collection::vec((0usize..1_000_000, any::<u8>()), 0..8)) {
        let bytes = damaged(ULOG, cut, &flips);
        if let Err(e) = to_signals(gyropath::import::ulog::parse(&bytes, "fuzz.ulg")) {
            prop_assert!(e.contains("fuzz.ulg"), "{}", e);
        }
    }

    /// A comma2k19 array cut off or damaged: an error naming it, never a panic.
    #[test]
    fn damaged_numpy_arrays_never_panic(cut in 0usize..100_000, flips in proptest::collection::vec((0usize..100_000, any::<u8>()), 0..4)) {
        let bytes = damaged(CAN_SPEED, cut, &flips);
        if let Err(e) = gyropath::import::npy::parse(&bytes, "fuzz/value") {
            prop_assert!(e.to_string().contains("fuzz/value"), "{}", e);
        }
    }

    /// A phone's GnssLogger text cut off or with bytes flipped (a digit
    /// turned into a letter, a comma into something else): an error naming
    /// the file, never a panic.
    #[test]
    fn damaged_gnsslogger_logs_never_panic(cut in 0usize..400_000, flips in proptest::collection::vec((0usize..400_000, any::<u8>()), 0..8)) {
        let bytes = damaged(GNSSLOGGER, cut, &flips);
        if let Err(e) = to_signals(gyropath::import::gnsslogger::parse(&bytes[..], "fuzz.txt")) {
            prop_assert!(e.contains("fuzz.txt"), "{}", e);
        }
    }

    /// An ArduPilot log cut off or with bytes flipped (in its FMT records
    /// too, which the parser trusts for every message's length): an error
    /// naming the file, never a panic.
    #[test]
    fn damaged_dataflash_logs_never_panic(cut in 0usize..90_000, flips in proptest::collection::vec((0usize..90_000, any::<u8>()), 0..8)) {
        let bytes = damaged(DATAFLASH, cut, &flips);
        if let Err(e) = to_signals(gyropath::import::dataflash::parse(&bytes[..], "fuzz.bin")) {
            prop_assert!(e.contains("fuzz.bin"), "{}", e);
        }
    }

    /// A FIT activity cut off or with bytes flipped, read as a reference
    /// track: an error naming the file, never a panic.
    #[test]
    fn damaged_fit_files_never_panic(cut in 0usize..6_000, flips in proptest::collection::vec((0usize..6_000, any::<u8>()), 0..8)) {
        let bytes = damaged(FIT, cut, &flips);
        if let Err(e) = gyropath::import::fit::parse(&bytes, "fuzz.fit") {
            prop_assert!(e.to_string().contains("fuzz.fit"), "{}", e);
        }
    }
}
