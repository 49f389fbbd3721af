//! The app driven through its real UI with egui_kittest (no display needed).

use std::time::{Duration, Instant};

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use gyropath::app::{AppSettings, GyropathApp, sample_ride};

mod common;

fn harness(app: GyropathApp) -> Harness<'static, GyropathApp> {
    Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .build_ui_state(|ui, app: &mut GyropathApp| app.ui(ui), app)
}

/// The GPS error law the fit panel names.
fn gps_law(h: &Harness<'static, GyropathApp>) -> String {
    h.state()
        .snapshot
        .as_ref()
        .expect("snapshot")
        .gps_noise
        .clone()
}

/// Step the UI until `done` holds or `timeout` passes (the worker runs on its own thread).
fn step_until(
    h: &mut Harness<'static, GyropathApp>,
    timeout: Duration,
    mut done: impl FnMut(&GyropathApp) -> bool,
) -> bool {
    let start = Instant::now();
    while start.elapsed() < timeout {
        h.step();
        if done(h.state()) {
            h.step();
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

fn manual_settings() -> AppSettings {
    AppSettings {
        auto_run: false,
        ..AppSettings::default()
    }
}

/// The cost shown in the fit panel (the label after "cost").
fn shown_cost(h: &Harness<'static, GyropathApp>) -> f64 {
    let s = h.state().snapshot.as_ref().expect("snapshot");
    let text = format!("{:.6e}", s.stats.cost);
    // The label exists in the UI with exactly this text.
    h.get_by_label(&text);
    text.parse().expect("number")
}

#[test]
fn run_fits_the_sample_and_the_cost_label_falls() {
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .snapshot
        .is_some()));
    let first = shown_cost(&h);
    h.get_by_label("Run").click();
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| !a.history.is_empty()),
        "the fit did not finish"
    );
    let last = shown_cost(&h);
    assert!(last < 0.2 * first, "cost {first} -> {last}");
    let rms = h
        .state()
        .snapshot
        .as_ref()
        .expect("snapshot")
        .stats
        .rms_horizontal_m;
    assert!(rms < 3.0, "GPS RMS {rms}");
    // The fit panel and the model history's row both show the fit RMS, and
    // the panel says which GPS error law it is measured under.
    assert_eq!(h.get_all_by_label(&format!("{rms:.3} m")).count(), 2);
    let law = gps_law(&h);
    assert!(law.contains("GPS"), "{law}");
    h.get_by_label(&format!("GPS error law: {law}"));
    // The finished fit says how sure it is: a band along the path, a band on
    // the biases, every parameter with its sigma.
    let snap = h.state().snapshot.as_ref().expect("snapshot");
    let sigma = snap.sigma.as_ref().expect("a finished fit has its sigmas");
    assert_eq!(sigma.path.len(), snap.path.len());
    assert_eq!(sigma.segments.len(), snap.segments.len());
    assert!(sigma.path.iter().all(|v| v[0] > 0.0 && v[1] > 0.0));
    let gain = snap
        .params
        .iter()
        .position(|p| p.1 == "gain")
        .expect("gain");
    let (sd, determined) = sigma.params[gain].expect("the gain has a sigma");
    assert!(determined, "a bicycle's odometer gain is measured, sd {sd}");
    h.get_by_label(&format!("{:.5} ± {sd:.5}", snap.params[gain].2));
    // Residuals in sigmas of the noise model, with how they spread against N(0, 1).
    let spread = gyropath::diagnosis::NormalisedSpread::of(&snap.residuals);
    assert!((0.7..1.4).contains(&spread.rms), "{spread:?}");
    let check = "residuals in sigmas of the noise model";
    // Below the fold of the controls panel: scrolled to, as a user would.
    h.get_by_label(check).scroll_to_me();
    h.run();
    h.get_by_label(check).click();
    h.run();
    assert!(h.state().settings.normalised_residuals);
    h.get_by_label_contains(&format!(
        "Residuals in sigmas: RMS {:.2} (1 expected)",
        spread.rms
    ));
    // The GPS noise the ride prefers, with its range, in the settings panel.
    let noise = h
        .state()
        .snapshot
        .as_ref()
        .and_then(|s| s.noise.clone())
        .expect("the fit estimates the GPS noise");
    h.get_by_label("The ride prefers (1-sigma range):");
    h.get_by_label(&noise.gps_sigma_m.describe("m", 2));
    // The heights' own noise, in its row.
    h.get_by_label(
        &noise
            .heights_text()
            .expect("the sample ride logs GPS heights"),
    );
    // Unticked, the noise is set by hand (scrolled to first, as a user
    // would: the controls panel is taller than the window).
    h.get_by_label("GPS noise from the ride").scroll_to_me();
    h.run();
    h.get_by_label("GPS noise from the ride").click();
    h.run();
    assert!(!h.state().settings.fit.auto_noise.gps);
    h.get_by_label("GPS error correlated");
}

#[test]
fn segment_length_changes_the_segment_count_live() {
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .snapshot
        .is_some()));
    let before = h
        .state()
        .snapshot
        .as_ref()
        .expect("snapshot")
        .segments
        .len();
    h.get_by_label(&format!("{before}"));
    // Step once, then lengthen the segments through the settings as the slider would.
    h.get_by_label("Step once").click();
    h.state_mut().settings.fit.model.segment_s = 20.0;
    h.state_mut().apply(gyropath::app::Command::SettingsChanged);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| {
        a.snapshot
            .as_ref()
            .is_some_and(|s| s.segments.len() != before)
    }));
    let after = h
        .state()
        .snapshot
        .as_ref()
        .expect("snapshot")
        .segments
        .len();
    assert_eq!(
        after,
        before.div_ceil(4),
        "{before} segments of 5 s -> {after} of 20 s"
    );
    h.get_by_label(&format!("{after}"));
}

#[test]
fn a_bad_file_shows_its_error_and_keeps_the_ride() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("bad.csv");
    // The sample's first rows with a number spoiled on line 40 (column gz_dps).
    let sample = std::str::from_utf8(gyropath::app::SAMPLE_RIDE).expect("utf8");
    let mut lines: Vec<String> = sample.lines().take(60).map(str::to_string).collect();
    let header = lines
        .iter()
        .position(|l| !l.starts_with('#'))
        .expect("header");
    let col = lines[header]
        .split(',')
        .position(|c| c == "gz_dps")
        .expect("gz_dps column");
    let mut fields: Vec<&str> = lines[39].split(',').collect();
    fields[col] = "1.2.3";
    lines[39] = fields.join(",");
    std::fs::write(&bad, lines.join("\n")).expect("write");
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .is_some()));
    h.state_mut().apply(gyropath::app::Command::Open(
        gyropath::app::worker::RideSource::file(bad),
    ));
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .error
        .is_some()));
    let error = h.state().error.clone().expect("error");
    assert!(error.contains("bad.csv:40"), "{error}");
    assert!(error.contains("gz_dps"), "{error}");
    h.get_by_label_contains("bad.csv");
    // The sample ride is still loaded.
    let ride = h.state().ride.as_ref().expect("ride");
    assert!(ride.source.name().contains("sample"));
    h.get_by_label("Dismiss").click();
    h.run_steps(2);
    assert!(h.state().error.is_none());
}

#[test]
fn diagnose_then_add_the_suggested_effect_and_the_history_grows() {
    diagnose_add_and_watch_the_held_out_error_fall("data/hidden-gps-lag.csv", "gps_lag");
}

/// The city example: its held-out error must fall in the history too (it
/// rose from 8.45 to 25.8 m while the history mixed the diagnosis's RMS,
/// jumps left out, with its own validation's over every fix).
#[test]
fn on_the_city_example_gps_outliers_lowers_the_held_out_error_in_the_history() {
    diagnose_add_and_watch_the_held_out_error_fall("data/city-gps.csv", "gps_outliers");
}

/// Open `file`, diagnose, expect `effect` first and significant, add it, and
/// expect the model history's held-out error to fall by 10 % or more.
fn diagnose_add_and_watch_the_held_out_error_fall(file: &str, effect: &str) {
    let ride = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    let app = GyropathApp::new(
        AppSettings::default(),
        gyropath::app::worker::RideSource::file(ride),
        || {},
    );
    let mut h = harness(app);
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| a
            .history
            .first()
            .is_some_and(|r| r.held_out.is_some())),
        "first fit and its validation"
    );
    let first = h.state().history[0].clone();
    assert_eq!(first.model.matches(effect).count(), 0);
    h.get_by_label("Diagnose").click();
    assert!(
        step_until(&mut h, Duration::from_secs(180), |a| a.diagnosis.is_some()),
        "diagnosis"
    );
    let best = h.state().diagnosis.as_ref().expect("diagnosis").ranking[0].clone();
    assert_eq!(best.effect, effect);
    assert!(best.significant);
    // The first Add button belongs to the top-ranked effect.
    h.get_all_by_label("Add")
        .next()
        .expect("an Add button")
        .click();
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| a.history.len() == 2
            && a.history[1].held_out.is_some()),
        "refit with the effect: history {:?}, error {:?}, running {}, phase {:?}",
        h.state().history,
        h.state().error,
        h.state().running,
        h.state()
            .snapshot
            .as_ref()
            .map(|s| (s.phase, s.effects.clone(), s.history.len()))
    );
    let second = h.state().history[1].clone();
    assert!(second.model.contains(effect), "{second:?}");
    // The diagnosis did not overwrite the history's own validation.
    assert_eq!(h.state().history[0].held_out, first.held_out);
    let (before, after) = (
        first.held_out.expect("held-out"),
        second.held_out.expect("held-out"),
    );
    eprintln!(
        "{file}: held-out {:.3} -> {:.3} m ({} -> {} jumps out)",
        before.rms_m, after.rms_m, before.jumps_left_out, after.jumps_left_out
    );
    let (before, after) = (before.rms_m, after.rms_m);
    assert!(after < 0.9 * before, "held-out {before} -> {after}");
    h.get_by_label_contains(&format!("{after:.3} m"));
}

/// A file dropped on the window, as the windowing layer hands it to egui.
#[derive(Debug)]
struct Dropped(std::path::PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &std::path::Path {
        &self.0
    }

    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

#[test]
fn dropping_a_ride_on_the_window_loads_it_and_remembers_it() {
    let ride = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hidden-gyro-scale.csv");
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .is_some()));
    h.input_mut()
        .dropped_files
        .push(std::sync::Arc::new(Dropped(ride.clone())));
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .as_ref()
        .is_some_and(|r| r.source.name().contains("hidden-gyro-scale"))));
    assert_eq!(h.state().settings.recent.first(), Some(&ride));
    h.get_by_label_contains("hidden-gyro-scale.csv");
}

#[test]
fn a_ros_bag_opens_with_its_topics_and_mounting_shown_and_the_mounting_can_be_changed() {
    let bag = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/robot_localization-test1/test1.bag");
    let app = GyropathApp::new(
        manual_settings(),
        gyropath::app::worker::RideSource::file(bag.clone()),
        || {},
    );
    let mut h = harness(app);
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a.ride.is_some()),
        "the bag loads: error {:?}",
        h.state().error
    );
    h.get_by_label_contains("ROS 1 bag");
    // The combo boxes show the chosen topics and the mounting applied.
    h.get_by_value("/imu/data");
    h.get_by_value("/husky_velocity_controller/odom");
    h.get_by_value("/fix");
    h.get_by_value("x=-z,y=-x,z=y");
    // Nothing is wrong once mounted, so the checks are folded; opened, they
    // say what the data showed and that the mounting undoes it.
    h.get_by_label("Checks (info)").click();
    h.run_steps(2);
    h.get_by_label_contains("vertical axis: +y points up");
    // The vertical and the forward axis both.
    assert_eq!(
        h.get_all_by_label_contains("the mounting x=-z,y=-x,z=y applied undoes it")
            .count(),
        2
    );
    let origin = &h.state().ride.as_ref().expect("ride").origin;
    assert_eq!(origin.recommended.as_deref(), Some("x=-z,y=-x,z=y"));
    // Asking for the mounting as logged reloads the bag with it.
    h.get_by_value("x=-z,y=-x,z=y").click();
    h.run_steps(2);
    h.get_by_label("as logged").click();
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a
            .ride
            .as_ref()
            .is_some_and(|r| r.origin.mount.is_none() && a.loading.is_none())),
        "reloaded as logged"
    );
    let ride = h.state().ride.as_ref().expect("ride");
    assert!(
        ride.warnings
            .iter()
            .any(|w| w.contains("mounting: the data say")),
        "{:?}",
        ride.warnings
    );
}

#[test]
fn an_unphysical_fit_is_shown_as_no_result() {
    let bag = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/robot_localization-test1/test1.bag");
    // Forced to 3D, the robot's fit tilts its sensor 46 deg (past the 30 deg limit).
    let options = gyropath::import::ImportOptions {
        attitude: Some("3d".into()),
        ..Default::default()
    };
    let app = GyropathApp::new(
        AppSettings::default(),
        gyropath::app::worker::RideSource::Path(bag, Box::new(options)),
        || {},
    );
    let mut h = harness(app);
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| !a.history.is_empty()),
        "the fit finishes"
    );
    h.get_by_value("3D");
    h.get_by_label("Not physical: this fit is no result.");
    h.get_by_label_contains("start tilt of the sensor is 46 deg (limit 30 deg)");
    // Auto chooses the planar model, which is physical.
    h.get_by_value("3D").click();
    h.run_steps(2);
    h.get_by_label("auto (from the data)").click();
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| {
            a.ride.as_ref().is_some_and(|r| r.attitude.is_planar())
                && a.snapshot
                    .as_ref()
                    .is_some_and(|s| s.phase == gyropath::optimisation::Phase::Done)
        }),
        "reloaded planar and fitted"
    );
    assert!(
        h.query_by_label("Not physical: this fit is no result.")
            .is_none()
    );
}

#[test]
fn file_examples_opens_a_ride_with_something_to_find() {
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .snapshot
        .is_some()));
    // The bundled sample says where to find a ride with something missing.
    h.get_by_label_contains("File > Examples has rides with something to find");
    open_gps_lag_example(&mut h);
}

/// File > Examples > GPS lag, through the menus, until the ride is loaded.
fn open_gps_lag_example(h: &mut Harness<'static, GyropathApp>) {
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Examples").hover();
    h.run_steps(3);
    h.get_by_label("GPS lag (simulated bicycle)").click();
    assert!(
        step_until(h, Duration::from_secs(60), |a| a
            .ride
            .as_ref()
            .is_some_and(|r| r.source.name().contains("hidden-gps-lag"))),
        "the example loads"
    );
}

#[test]
fn each_ride_starts_from_the_default_model_as_the_command_line_does() {
    // As after a restart whose last ride had gps_lag added.
    let mut settings = manual_settings();
    settings.fit.model.effects = vec!["paper".into(), "gps_lag".into()];
    let app = GyropathApp::new(settings, sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .is_some()));
    let default = gyropath::model::ModelSpec::default().effects;
    assert_eq!(h.state().settings.fit.model.effects, default);
    h.get_by_label_contains("the model starts again from the paper's");

    // Add an effect on this ride, then open another: it starts from the default again.
    h.state_mut()
        .apply(gyropath::app::Command::AddEffect("gps_lag".into()));
    assert!(
        h.state()
            .settings
            .fit
            .model
            .effects
            .iter()
            .any(|e| e == "gps_lag")
    );
    let ride = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hidden-gyro-scale.csv");
    h.state_mut().apply(gyropath::app::Command::Open(
        gyropath::app::worker::RideSource::file(ride),
    ));
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .as_ref()
        .is_some_and(|r| r.source.name().contains("hidden-gyro-scale"))));
    assert_eq!(h.state().settings.fit.model.effects, default);
    assert!(
        step_until(&mut h, Duration::from_secs(30), |a| a
            .snapshot
            .as_ref()
            .is_some_and(|s| !s.effects.iter().any(|e| e == "gps_lag"))),
        "the worker's model still has gps_lag"
    );
}

#[test]
fn a_reference_track_is_drawn_and_the_history_says_how_far_each_model_is_from_it() {
    let drive = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/comma2k19-example1");
    let app = GyropathApp::new(
        AppSettings::default(),
        gyropath::app::worker::RideSource::file(drive.join("ride.csv")),
        || {},
    );
    let mut h = harness(app);
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| !a.history.is_empty()),
        "the fit did not finish: {:?}",
        h.state().error
    );
    h.state_mut().apply(gyropath::app::Command::OpenReference(
        drive.join("truth.csv"),
    ));
    assert!(
        step_until(&mut h, Duration::from_secs(30), |a| a
            .history
            .last()
            .is_some_and(|r| r.reference_rms_m.is_some())),
        "no error to the reference: {:?}",
        h.state().error
    );
    let app = h.state();
    let r = app.reference.as_ref().expect("reference view");
    assert!((r.covered_s - 60.0).abs() < 1.0, "{}", r.covered_s);
    let to_ref = app.history.last().unwrap().reference_rms_m.unwrap();
    let snap = app.snapshot.as_ref().unwrap().reference.as_ref().unwrap();
    assert_eq!(to_ref, snap.horizontal.rms_m);
    // comma's path is about a metre from its reference; its fixes 1.5 m.
    assert!((0.5..1.5).contains(&to_ref), "{to_ref} m");
    assert!(!snap.series.is_empty());
    // The history's column and the chart's legend.
    assert!(h.query_all_by_label("to reference").count() >= 2);
    assert!(
        h.query_all_by_label("reference track").count() >= 1,
        "the map's legend"
    );

    // Diagnose with the reference loaded: each candidate measured against
    // it as `diagnose --reference` measures it (the model with the effect,
    // fitted as Fit fits it), in a column of its own.
    h.get_by_label("Diagnose").click();
    assert!(
        step_until(&mut h, Duration::from_secs(180), |a| a.diagnosis.is_some()),
        "diagnosis: {:?}",
        h.state().error
    );
    let d = h.state().diagnosis.clone().expect("diagnosis");
    let base = d
        .reference
        .as_ref()
        .expect("the model against the reference");
    assert_eq!(base.horizontal.rms_m, to_ref);
    let lag = d
        .ranking
        .iter()
        .find(|c| c.effect == "gps_lag")
        .and_then(|c| c.reference.as_ref())
        .expect("gps_lag against the reference");
    // With the lag the path is half a metre from comma's reference.
    assert!(lag.horizontal.rms_m < 0.6, "{:?}", lag.horizontal);
    assert!(h.query_all_by_label("to ref").count() >= 1);

    // File > Save report (HTML): the page has the reference, the model
    // history the app shows, and the ride's checks.
    let dir = tempfile::tempdir().expect("temp dir");
    let page = dir.path().join("comma.html");
    h.state()
        .export_to(gyropath::app::worker::ExportKind::ReportHtml, page.clone());
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a
            .status
            .as_ref()
            .is_some_and(|s| s.contains("comma.html"))),
        "the report was not written: {:?}",
        h.state().error
    );
    let html = std::fs::read_to_string(&page).expect("report");
    assert!(html.contains(r#"<h2 id="reference">Against the reference</h2>"#));
    assert!(
        html.contains(&format!("{to_ref:.3} m")),
        "the history's error to the reference"
    );
    assert!(html.contains(r#"<table id="checks">"#), "the ride's checks");
    assert!(html.contains("the gyropath app on"));

    // A reference of another drive is refused with its reason, and the ride stays.
    let berlin = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz/truth.csv");
    h.state_mut()
        .apply(gyropath::app::Command::OpenReference(berlin));
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .error
        .as_ref()
        .is_some_and(|e| e.contains("not of this ride"))));
    assert!(h.state().ride.is_some());

    // The ride's own reference cut short (its recorder stopped while
    // writing a row): loaded over what it holds, and the status says so.
    let dir = tempfile::tempdir().unwrap();
    let cut = dir.path().join("cut-truth.csv");
    let truth = std::fs::read(drive.join("truth.csv")).unwrap();
    let at = truth.len() * 2 / 3;
    let at = at + truth[at..].iter().position(|&b| b == b',').unwrap() + 1;
    std::fs::write(&cut, &truth[..at]).unwrap();
    h.state_mut()
        .apply(gyropath::app::Command::OpenReference(cut));
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .reference
        .as_ref()
        .is_some_and(|r| r.name.contains("cut-truth"))));
    let app = h.state();
    let r = app.reference.as_ref().unwrap();
    assert!(r.covered_s > 30.0 && r.covered_s < 50.0, "{}", r.covered_s);
    assert!(r.warnings.len() == 1 && r.warnings[0].contains("left out"));
    let status = app.status.as_deref().unwrap_or("");
    assert!(
        status.contains("warning:") && status.contains("left out"),
        "{status}"
    );
}

#[test]
fn explain_adds_the_missing_effect_and_stops_when_nothing_more_is_significant() {
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .snapshot
        .is_some()));
    open_gps_lag_example(&mut h);
    assert!(step_until(&mut h, Duration::from_secs(60), |a| a
        .snapshot
        .is_some()));
    h.get_by_label("Explain").click();
    assert!(
        step_until(&mut h, Duration::from_secs(600), |a| a.explaining.is_none()
            && a.explain_log.len() > 1),
        "Explain did not finish: {:?}",
        h.state().explain_log
    );
    let log = h.state().explain_log.clone();
    // It said what it added and why, then why it stopped; each line is shown.
    assert!(
        log.iter().any(
            |l| l.text.starts_with("added gps_lag: held-out") && l.detail.starts_with("lag 0.")
        ),
        "{log:?}"
    );
    let last = log.last().expect("a line");
    assert!(
        last.text.starts_with("nothing more is significant"),
        "{log:?}"
    );
    for line in &log {
        h.get_by_label(&line.text);
    }
    // The model history grew by the added model, which is now the current one.
    assert!(step_until(&mut h, Duration::from_secs(60), |a| a
        .history
        .iter()
        .any(|r| r.model.contains("gps_lag"))));
    let effects = &h.state().settings.fit.model.effects;
    assert!(effects.contains(&"gps_lag".to_string()), "{effects:?}");
    // The effects can still be changed by hand: Explain is idle again.
    assert!(h.state().explaining.is_none());
    h.get_by_label("Explain");
}

/// A comma2k19 segment (a folder of NumPy arrays) opens as a ride; the
/// Source panel says the distance is the CAN odometer's, and choosing the
/// GNSS speed reloads it with the distance from the u-blox speed.
#[test]
fn a_comma_segment_opens_and_its_distance_can_come_from_the_gnss_speed() {
    let segment = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/formats/comma2k19-segment/segment");
    let app = GyropathApp::new(
        manual_settings(),
        gyropath::app::worker::RideSource::file(segment),
        || {},
    );
    let mut h = harness(app);
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a.ride.is_some()),
        "the segment loads: error {:?}",
        h.state().error
    );
    h.get_by_label_contains("comma2k19 segment");
    h.get_by_label("from a cumulative distance");
    h.get_by_value("auto").click();
    h.run_steps(2);
    h.get_by_label("GNSS speed").click();
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a
            .ride
            .as_ref()
            .is_some_and(
                |r| r.distance.starts_with("the GNSS speed") && a.loading.is_none()
            )),
        "reloaded with the GNSS speed"
    );
    h.get_by_label_contains("from the GNSS speed, integrated (no wheel sensor; 577 samples");
}

/// A log without a wheel sensor takes a bike computer's wheel distance from
/// the Source panel: "Wheel distance (FIT)..." (its file dialog's pick
/// stood in for here) reloads the ride with the Edge 810's distance as its
/// odometer, matched by UTC, and the panel names it; "Remove" reloads the
/// ride on its own GNSS speed.
#[test]
fn a_wheel_distance_from_a_fit_file_is_picked_in_the_source_panel_and_removed() {
    let fit_path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/formats/fit/Edge810-Vector-2013-08-16-15-35-10.fit");
    let fit = gyropath::import::fit::parse(&std::fs::read(&fit_path).expect("read"), "edge.fit")
        .expect("fit");
    let dir = tempfile::tempdir().expect("temp dir");
    let ride = dir.path().join("camera.csv");
    std::fs::write(&ride, common::ride_along(&fit, 1200.0, 1320.0, 0.0)).expect("write");
    let app = GyropathApp::new(
        manual_settings(),
        gyropath::app::worker::RideSource::file(ride.clone()),
        || {},
    );
    let mut h = harness(app);
    let loaded = |h: &mut Harness<'static, GyropathApp>, what: &str| {
        let what = what.to_string();
        assert!(
            step_until(h, Duration::from_secs(60), |a| a
                .ride
                .as_ref()
                .is_some_and(|r| r.distance.contains(&what) && a.loading.is_none())),
            "not loaded with '{what}': error {:?}",
            h.state().error
        );
    };
    loaded(&mut h, "GNSS speed");
    h.get_by_label("Wheel distance (FIT)...");
    let picked = h
        .state()
        .ride
        .as_ref()
        .and_then(|r| r.source.with_wheel(fit_path.clone()))
        .expect("a file source");
    h.state_mut().apply(gyropath::app::Command::Open(picked));
    loaded(&mut h, "wheel-speed sensor");
    h.get_by_label_contains("wheel: Edge810");
    h.get_by_label_contains("distance: the wheel-speed sensor's distance of");
    h.get_by_label("Remove").click();
    loaded(&mut h, "GNSS speed");
    h.get_by_label("Wheel distance (FIT)...");
}

/// On Berlin the default holds the heavy-tailed fit's odometer gain and the
/// panels say so; ticking "heavy tails from the ride" after the fit and
/// running again ends where a fit with the tails from the start does (three
/// rounds of weights, a Student-t law of about 1.8 degrees of freedom).
#[test]
fn heavy_tails_ticked_after_a_fit_run_all_their_rounds() {
    let berlin = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz/ride.csv");
    let app = GyropathApp::new(
        AppSettings::default(),
        gyropath::app::worker::RideSource::file(berlin),
        || {},
    );
    let mut h = harness(app);
    let done = |a: &GyropathApp| {
        a.snapshot
            .as_ref()
            .is_some_and(|s| s.phase == gyropath::optimisation::Phase::Done)
            && !a.running
    };
    assert!(step_until(&mut h, Duration::from_secs(120), done));
    // The default held the heavy-tailed fit's odometer gain, and says so in
    // the noise estimate and the parameter table, with that fit's sigma.
    h.get_by_label_contains("from the heavy-tailed fit, held (least squares read 1.0385");
    h.get_by_label("gain (held)");
    h.get_by_label_contains("1.00861 ± 0.01444");
    h.state_mut().settings.fit.auto_noise.tails = true;
    h.state_mut().apply(gyropath::app::Command::SettingsChanged);
    h.state_mut().apply(gyropath::app::Command::Run);
    assert!(step_until(&mut h, Duration::from_secs(5), |a| a.running));
    assert!(step_until(&mut h, Duration::from_secs(120), done));
    let law = gps_law(&h);
    eprintln!("{law}");
    assert!(law.contains("Student-t fixes (nu 1.8)"), "{law}");
}

/// `gyropath open RIDE --reference FILE` asks for the reference as the app
/// starts, before the worker has loaded the ride: it is taken after the
/// ride, and the first fit's history row already says how far it is.
#[test]
fn a_reference_asked_for_at_start_is_loaded_after_the_ride() {
    let drive = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/comma2k19-example1");
    let mut app = GyropathApp::new(
        AppSettings::default(),
        gyropath::app::worker::RideSource::file(drive.join("ride.csv")),
        || {},
    );
    app.apply(gyropath::app::Command::OpenReference(
        drive.join("truth.csv"),
    ));
    let mut h = harness(app);
    assert!(
        step_until(&mut h, Duration::from_secs(120), |a| a
            .history
            .last()
            .is_some_and(|r| r.reference_rms_m.is_some())),
        "no error to the reference: {:?}",
        h.state().error
    );
    assert!(h.state().error.is_none(), "{:?}", h.state().error);
    let r = h.state().reference.as_ref().expect("reference view");
    assert!((r.covered_s - 60.0).abs() < 1.0, "{}", r.covered_s);
    let to_ref = h.state().history[0].reference_rms_m.expect("first row");
    assert!((0.5..1.5).contains(&to_ref), "{to_ref} m");
}

/// The bias plot draws the axes the model estimates: a planar model's roll
/// and pitch biases are held at zero, and drawn as flat lines they read as
/// results; a 3D ride's three axes are drawn.
#[test]
fn the_bias_plot_shows_only_the_axes_the_model_estimates() {
    let berlin = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz/ride.csv");
    for (source, planar) in [
        (gyropath::app::worker::RideSource::file(berlin), true),
        (sample_ride(), false),
    ] {
        let mut h = harness(GyropathApp::new(AppSettings::default(), source, || {}));
        assert!(
            step_until(&mut h, Duration::from_secs(120), |a| a
                .snapshot
                .as_ref()
                .is_some_and(|s| !s.segments.is_empty())),
            "no fit: {:?}",
            h.state().error
        );
        h.run_steps(2);
        assert_eq!(
            h.state().ride.as_ref().expect("ride").attitude.is_planar(),
            planar
        );
        assert!(h.query_all_by_label("bias z (yaw)").count() >= 1);
        let roll = h.query_all_by_label("bias x (roll)").count();
        let pitch = h.query_all_by_label("bias y (pitch)").count();
        if planar {
            assert_eq!((roll, pitch), (0, 0));
        } else {
            assert!(roll >= 1 && pitch >= 1, "{roll} {pitch}");
        }
    }
}

/// A ride refused for a pause offers each side of it: the error bar has a
/// button for the rows before the pause and one for those after, which
/// loads that part (the Source panel says which rows, and "Whole log"
/// reads them all again, refused as before). The command line's
/// `--between`, as a user of the app reaches it.
#[test]
fn a_ride_refused_for_a_pause_offers_each_side_of_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let paused = dir.path().join("paused.csv");
    let sample = std::str::from_utf8(gyropath::app::SAMPLE_RIDE).expect("utf8");
    let mut header_seen = false;
    let mut text = String::new();
    for line in sample.lines() {
        if line.starts_with('#') || !header_seen {
            header_seen |= !line.starts_with('#');
            text.push_str(line);
        } else {
            let (t, rest) = line.split_once(',').expect("a row");
            let t: f64 = t.parse().expect("t_s");
            let t = if t > 300.0 { t + 120.0 } else { t };
            text.push_str(&format!("{t:.2},{rest}"));
        }
        text.push('\n');
    }
    std::fs::write(&paused, text).expect("write");
    let app = GyropathApp::new(
        manual_settings(),
        gyropath::app::worker::RideSource::file(paused),
        || {},
    );
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .error
        .is_some()));
    let error = h.state().error.clone().expect("error");
    assert!(
        error.contains("the log pauses for 120 s after t = 300.00 s"),
        "{error}"
    );
    h.get_by_label("Fit before the pause (0-300 s)");
    h.get_by_label("Fit after the pause (420-720 s)").click();
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a
            .ride
            .as_ref()
            .is_some_and(|r| a.loading.is_none() && r.duration_s < 301.0)),
        "not loaded: {:?}",
        h.state().error
    );
    assert!(h.state().error.is_none() && h.state().retry.is_empty());
    let rows = h.state().ride.as_ref().expect("ride").rows;
    assert_eq!(rows, 30_000);
    h.get_by_label("rows from 420.01 to 720.00 s of the log");
    h.get_by_label("Whole log").click();
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .error
        .is_some()));
    h.get_by_label("Fit before the pause (0-300 s)");
}

/// A log without GPS (the Berlin drive's rows with their fixes emptied and
/// no start time) is refused with a "GPS track..." button; read with the
/// drive's reference as a GPX in UTC (what a watch would have logged),
/// dropped on the window (or picked by the button's dialog), it loads with
/// the fixes placed by the vehicle's turns, and the Source panel names the
/// track.
#[test]
fn a_log_without_gps_offers_a_gps_track_and_loads_with_it() {
    let berlin = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz");
    let dir = tempfile::tempdir().expect("tempdir");
    let ride = std::fs::read_to_string(berlin.join("ride.csv")).expect("ride");
    let mut bare = String::new();
    for line in ride.lines() {
        let f: Vec<&str> = line.split(',').collect();
        if line.starts_with('#') || f.len() < 8 || f[0] == "t_s" {
            bare.push_str(line);
        } else {
            bare.push_str(&[&f[..5], &["", "", ""]].concat().join(","));
        }
        bare.push('\n');
    }
    let mut gpx = String::from(
        "<?xml version=\"1.0\"?>\n<gpx version=\"1.1\" creator=\"test\" xmlns=\"http://www.topografix.com/GPX/1/1\"><trk><trkseg>\n",
    );
    let truth = std::fs::read_to_string(berlin.join("truth.csv")).expect("truth");
    for line in truth
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("t_s"))
    {
        let f: Vec<&str> = line.split(',').collect();
        let sod = 80_000.0 + f[0].parse::<f64>().expect("t_s");
        gpx.push_str(&format!(
            "<trkpt lat=\"{}\" lon=\"{}\"><time>2023-11-14T{:02}:{:02}:{:06.3}Z</time></trkpt>\n",
            f[1],
            f[2],
            (sod / 3600.0).floor(),
            ((sod % 3600.0) / 60.0).floor(),
            sod % 60.0
        ));
    }
    gpx.push_str("</trkseg></trk></gpx>\n");
    let (ride_path, track) = (dir.path().join("nogps.csv"), dir.path().join("watch.gpx"));
    std::fs::write(&ride_path, bare).expect("write");
    std::fs::write(&track, gpx).expect("write");
    let app = GyropathApp::new(
        manual_settings(),
        gyropath::app::worker::RideSource::file(ride_path),
        || {},
    );
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .error
        .is_some()));
    let error = h.state().error.clone().expect("error");
    assert!(error.contains("no GPS fix"), "{error}");
    h.get_by_label("GPS track...");
    assert!(h.state().track_for.is_some());
    // The track dropped on the window, as the button's dialog would pick it.
    h.input_mut()
        .dropped_files
        .push(std::sync::Arc::new(Dropped(track)));
    assert!(
        step_until(&mut h, Duration::from_secs(60), |a| a
            .ride
            .as_ref()
            .is_some_and(|_| a.loading.is_none())),
        "not loaded: {:?}",
        h.state().error
    );
    assert!(h.state().error.is_none() && h.state().track_for.is_none());
    h.get_by_label("GPS: watch.gpx");
    let ride = h.state().ride.clone().expect("ride");
    assert!(
        ride.duration_s > 130.0 && ride.duration_s < 141.0,
        "{}",
        ride.duration_s
    );
}

/// The app on the sample ride (whose gyro answers on every row and which
/// lost none), then with the ride at `path` opened, whose name holds `name`.
fn the_sample_then(path: std::path::PathBuf, name: &str) -> Harness<'static, GyropathApp> {
    let app = GyropathApp::new(manual_settings(), sample_ride(), || {});
    let mut h = harness(app);
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .is_some()));
    assert!(
        h.state()
            .ride
            .as_ref()
            .is_some_and(|r| r.gyro_stops.is_empty() && r.rows_filled == 0)
    );
    h.state_mut().apply(gyropath::app::Command::Open(
        gyropath::app::worker::RideSource::file(path),
    ));
    assert!(step_until(&mut h, Duration::from_secs(30), |a| a
        .ride
        .as_ref()
        .is_some_and(|r| r.source.name().contains(name))));
    h
}

/// A ride whose gyro stopped answering for 15 s (zeros on all three axes
/// while the bicycle rides on): the app's ride knows the stop, which the
/// time plots shade, and the checks name it.
#[test]
fn a_gyro_stop_is_known_to_the_ride_and_named_by_the_checks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("stopped.csv");
    let sample = std::str::from_utf8(gyropath::app::SAMPLE_RIDE).expect("utf8");
    let mut out = String::new();
    let mut header: Option<Vec<String>> = None;
    for line in sample.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if header.is_none() {
            header = Some(line.split(',').map(str::to_string).collect());
            out.push_str(line);
        } else {
            let cols = header.as_ref().expect("header");
            let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
            let t: f64 = f[0].parse().expect("time");
            if (100.0..115.0).contains(&t) {
                for name in ["gx_dps", "gy_dps", "gz_dps"] {
                    let c = cols.iter().position(|c| c == name).expect("gyro column");
                    f[c] = "0".into();
                }
            }
            out.push_str(&f.join(","));
        }
        out.push('\n');
    }
    std::fs::write(&path, out).expect("write");
    let h = the_sample_then(path, "stopped");
    let ride = h.state().ride.as_ref().expect("ride");
    assert_eq!(ride.gyro_stops.len(), 1, "{:?}", ride.gyro_stops);
    let (a, b) = ride.gyro_stops[0];
    assert!(
        (a - 100.0).abs() < 0.02 && (b - 115.0).abs() < 0.02,
        "{a}-{b}"
    );
    // In the checks and among the ride's warnings.
    assert!(
        h.query_all_by_label_contains("gyro stopped: the gyro repeats one reading")
            .count()
            >= 1
    );
}

/// The sample ride with 10 s of its rows lost (a logger's stall): the app
/// opens it (before, the gap's turn was interpolated over one step), the
/// ride knows the gap as a stop that the time plots shade as rows lost, and
/// its warnings name it.
#[test]
fn a_ride_with_rows_lost_opens_with_the_gap_bridged() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("stalled.csv");
    let sample = std::str::from_utf8(gyropath::app::SAMPLE_RIDE).expect("utf8");
    let mut out = String::new();
    let mut header = false;
    for line in sample.lines() {
        let kept = line.starts_with('#')
            || !std::mem::replace(&mut header, true)
            || !line
                .split(',')
                .next()
                .and_then(|t| t.parse::<f64>().ok())
                .is_some_and(|t| t > 100.0 && t < 110.0);
        if kept {
            out.push_str(line);
            out.push('\n');
        }
    }
    std::fs::write(&path, out).expect("write");
    let h = the_sample_then(path, "stalled");
    let ride = h.state().ride.as_ref().expect("ride");
    assert!(ride.rows_filled > 900, "{}", ride.rows_filled);
    assert_eq!(ride.gyro_stops.len(), 1, "{:?}", ride.gyro_stops);
    let (a, b) = ride.gyro_stops[0];
    assert!(
        (a - 100.0).abs() < 0.02 && b < 110.0 && b > 109.9,
        "{a}-{b}"
    );
    assert!(
        ride.warnings
            .iter()
            .any(|w| w.contains("1 gap(s) in the log") && w.contains("rows are filled")),
        "{:?}",
        ride.warnings
    );
}

/// A car drive filmed from a helmet (simulated, seed 4, 5 minutes): the
/// sensor looks 30 deg to alternate sides for 2 s each minute. The app's
/// ride knows the looks as bridged stops, which the time plots shade as
/// the sensor turning alone, and its warnings say so.
#[test]
fn a_helmet_cameras_looks_open_bridged() {
    let sim = gyropath::simulation::simulate(&gyropath::simulation::SimConfig {
        seed: 4,
        duration_s: 300.0,
        vehicle: gyropath::simulation::Vehicle::Car,
        outages: false,
        ..Default::default()
    })
    .expect("simulate");
    let mut out = String::new();
    let mut gz = None;
    for line in sim.log_csv.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if gz.is_none() {
            gz = line.split(',').position(|c| c == "gz_dps");
            out.push_str(line);
        } else {
            let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
            let t: f64 = cells[0].parse().expect("time");
            let (k, side) = ((t - 20.0).rem_euclid(60.0), ((t - 20.0) / 60.0).floor());
            let look = if side < 0.0 {
                0.0
            } else if k < 1.0 {
                30.0
            } else if (3.0..4.0).contains(&k) {
                -30.0
            } else {
                0.0
            } * if side as i64 % 2 == 0 { 1.0 } else { -1.0 };
            let at = gz.expect("a gz_dps column");
            let rate: f64 = cells[at].parse().expect("gz");
            cells[at] = format!("{:.4}", rate + look);
            out.push_str(&cells.join(","));
        }
        out.push('\n');
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("helmet.csv");
    std::fs::write(&path, out).expect("write");
    let h = the_sample_then(path, "helmet");
    let ride = h.state().ride.as_ref().expect("ride");
    assert!(ride.sensor_turns >= 4, "{}", ride.sensor_turns);
    assert!(
        ride.gyro_stops.len() >= ride.sensor_turns,
        "{:?}",
        ride.gyro_stops
    );
    assert!(
        ride.warnings
            .iter()
            .any(|w| w.contains("turned without the vehicle")),
        "{:?}",
        ride.warnings
    );
}
