//! The real Husky robot (`../shared/real/robot_localization-test1`, BSD
//! licence, see its README): a ROS 1 bag and its ROS 2 MCAP twin go in as the
//! same rows, the checks find the IMU's axes its README measured, and the
//! mounted ride's yaw follows the GPS course.

use std::path::PathBuf;

use gyropath::import::{self, ImportOptions, Level, MountChoice, SourceKind};

fn husky() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/real/robot_localization-test1")
}

fn open(path: PathBuf, mount: MountChoice) -> import::Imported {
    import::open(
        &path,
        &ImportOptions {
            mount,
            ..ImportOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_ros1_bag_and_its_ros2_twin_import_to_the_same_rows() {
    let one = open(husky().join("test1.bag"), MountChoice::AsLogged);
    let two = open(husky().join("test1_ros2"), MountChoice::AsLogged);
    let bare = open(
        husky().join("test1_ros2/test1_ros2.mcap"),
        MountChoice::AsLogged,
    );
    assert_eq!(one.kind, SourceKind::Ros1Bag);
    assert_eq!(two.kind, SourceKind::Ros2Mcap);
    let (a, b) = (&one.log, &two.log);
    // 11,865 IMU samples at 30 Hz over 395 s, a row per fix between samples.
    assert!(a.len() > 11_000, "{} rows", a.len());
    assert_eq!(a.len(), b.len());
    assert_eq!(a.t_s, b.t_s);
    assert_eq!(bare.log.t_s, b.t_s);
    for j in 0..a.len() {
        for k in 0..3 {
            assert!(
                (a.gyro_dps[j][k] - b.gyro_dps[j][k]).abs() < 1e-9,
                "row {j}"
            );
        }
    }
    assert_eq!(a.fix, b.fix);
    // 989 fixes, one of them 17 ms before the first IMU sample.
    assert_eq!(a.fix_count(), 988);
    assert_eq!(a.gps_hacc_m, b.gps_hacc_m);
    assert_eq!(a.speed_mps, b.speed_mps);
    let topics = one.topics.as_ref().unwrap();
    assert_eq!(topics.imu, "/imu/data");
    assert_eq!(topics.odom, "/husky_velocity_controller/odom");
    assert_eq!(topics.fix, "/fix");
    assert_eq!(two.topics.as_ref().unwrap().imu, topics.imu);
    // Per-fix accuracy from position_covariance.
    assert!(
        a.gps_hacc_m
            .as_ref()
            .unwrap()
            .iter()
            .flatten()
            .all(|&h| h > 0.0)
    );
}

#[test]
fn the_checks_find_y_up_z_backward_x_right_and_auto_applies_it() {
    for path in [husky().join("test1.bag"), husky().join("test1_ros2")] {
        let im = open(path, MountChoice::Default);
        let c = &im.check;
        let up = c.vertical.unwrap();
        assert_eq!((up.axis, up.sign), (1, 1.0), "{:#?}", c.verdicts);
        let fwd = c.forward.unwrap();
        assert_eq!((fwd.axis, fwd.sign), (2, -1.0), "{:#?}", c.verdicts);
        let rec = c.recommended.as_ref().unwrap();
        // x forward = -z, y left = -x (x points right), z up = +y.
        assert_eq!(rec.to_string(), "x=-z,y=-x,z=y");
        assert_eq!(
            im.mount.as_ref(),
            Some(rec),
            "bags are mounted by the checks"
        );
        assert_eq!(
            im.log.metadata.get("mount").map(String::as_str),
            Some("x=-z,y=-x,z=y")
        );
        let units = c
            .verdicts
            .iter()
            .find(|v| v.subject == "gyro units")
            .unwrap();
        assert_eq!(units.level, Level::Ok, "{}", units.message);
        // Mounted, the log's z is up and follows the course, in deg/s.
        let again = import::checks::check(&im.log);
        let v = again.vertical.unwrap();
        assert_eq!((v.axis, v.sign), (2, 1.0));
        let beta = again.course_per_gyro.unwrap();
        assert!((beta - 1.0).abs() < 0.15, "course per gyro degree {beta}");
        assert_eq!(
            again.recommended.as_ref().map(|m| m.is_identity()),
            Some(true)
        );
        assert!(
            im.warnings().iter().all(|w| !w.starts_with("mounting")),
            "{:?}",
            im.warnings()
        );
    }
}

#[test]
fn a_hand_mounting_and_as_logged_are_honoured_and_a_mismatch_is_warned() {
    let as_logged = open(husky().join("test1.bag"), MountChoice::AsLogged);
    assert!(as_logged.mount.is_none());
    let w = as_logged.warnings();
    assert!(
        w.iter()
            .any(|w| w.contains("mounting: the data say 'x=-z,y=-x,z=y'")),
        "{w:?}"
    );
    // The reader's own warning is said once, beside the checks' warnings.
    let signals = open(husky().join("test1.bag"), MountChoice::AsLogged)
        .into_signals()
        .unwrap();
    let fix_note = signals
        .warnings
        .iter()
        .filter(|w| w.contains("GPS fix(es) before"))
        .count();
    assert_eq!(fix_note, 1, "{:?}", signals.warnings);
    assert!(
        signals
            .warnings
            .iter()
            .any(|w| w.starts_with("mounting: the data say"))
    );
    let by_hand = open(
        husky().join("test1.bag"),
        MountChoice::Fixed("x=-z,y=-x,z=y".parse().unwrap()),
    );
    assert_eq!(
        by_hand.log.gyro_dps,
        open(husky().join("test1.bag"), MountChoice::Auto)
            .log
            .gyro_dps
    );
}

#[test]
fn an_imported_csv_reads_back_as_the_bag() {
    let im = open(husky().join("test1.bag"), MountChoice::Default);
    let mut out = Vec::new();
    import::ride_csv::write(&im.log, &mut out).unwrap();
    let back = import::parse(&out, "husky.csv").unwrap();
    assert_eq!(back.t_s, im.log.t_s);
    assert_eq!(back.gyro_dps, im.log.gyro_dps);
    assert_eq!(back.fix, im.log.fix);
    assert_eq!(
        back.metadata.get("mount").map(String::as_str),
        Some("x=-z,y=-x,z=y")
    );
    // Read back as a ride log, nothing is re-mounted and the checks are content.
    let csv = import::checked(back, SourceKind::RideCsv, None, &MountChoice::Default);
    assert!(csv.mount.is_none());
    assert!(csv.warnings().iter().all(|w| !w.starts_with("mounting")));
}
