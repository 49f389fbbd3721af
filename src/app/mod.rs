//! The desktop app (eframe/egui): load a ride, watch the fit iterate on a
//! worker thread, tune it live, compare the model with the measurements.
//!
//! Structure (after egui's demo app): [`AppSettings`] is what persists between
//! runs; [`GyropathApp`] adds the runtime state. Widgets do not act directly:
//! they collect [`Command`]s that are applied after the frame. The UI holds no
//! physics: it sends settings to the [`worker`] and draws its snapshots.
//!
//! This file holds the state and the Command loop; each panel is a file of
//! its own (`impl GyropathApp` blocks): `menu`, `source`, `fit_panel`,
//! `settings_panel`, `effects_panel`, `plots`, `history_panel`,
//! `diagnosis_panel`, `examples`; `map_tiles` draws the map's background.
//!
//! The measurements and the history behind these choices: docs/app.md (the
//! panels, the model history, the map).

mod diagnosis_panel;
mod effects_panel;
pub mod examples;
pub mod explain;
mod fit_panel;
mod history_panel;
pub mod map_tiles;
mod menu;
pub mod plots;
mod settings_panel;
pub mod source;
pub mod worker;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender};

use crate::diagnosis::HeldOutRms;
use crate::optimisation::{FitSettings, Phase};
use worker::{
    ExportKind, ReportExtras, Request, RideSource, RideView, Snapshot, Update, WorkerHandle,
};

/// The bundled sample ride (the one the app opens first).
pub const SAMPLE_RIDE: &[u8] = include_bytes!("../../data/sample-ride.csv");
pub const SAMPLE_NAME: &str = "sample-ride.csv (bundled)";

/// The sample ride as a source.
pub fn sample_ride() -> RideSource {
    RideSource::Bytes {
        name: SAMPLE_NAME.into(),
        bytes: Arc::from(SAMPLE_RIDE),
    }
}

const MAX_RECENT: usize = 8;

/// What persists between runs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AppSettings {
    pub fit: FitSettings,
    pub recent: Vec<PathBuf>,
    pub colour_by_residual: bool,
    /// Residual plot in sigmas of the noise model instead of metres.
    pub normalised_residuals: bool,
    /// Start fitting as soon as a ride is loaded.
    pub auto_run: bool,
    /// Draw map tiles under the map (when the app has a tile server).
    pub map_tiles: bool,
}

impl Default for AppSettings {
    fn default() -> Self {
        Self {
            fit: FitSettings::default(),
            recent: Vec::new(),
            colour_by_residual: false,
            normalised_residuals: false,
            auto_run: true,
            map_tiles: true,
        }
    }
}

/// What the user asked for during a frame, applied after it.
#[derive(Clone, Debug)]
pub enum Command {
    Open(RideSource),
    PickRide,
    /// Pick a rosbag2 folder (a ROS 2 bag is a folder, which a file dialog cannot pick).
    PickBagFolder,
    Run,
    Pause,
    Step,
    Reset,
    /// The fit settings in [`AppSettings`] changed: send them to the worker.
    SettingsChanged,
    PickExport(ExportKind),
    DismissError,
    /// Rank the effects the model lacks.
    Diagnose,
    /// Switch an effect on and refit.
    AddEffect(String),
    /// Diagnose and Add until nothing significant is left.
    Explain,
    /// End Explain; the models found so far stay.
    StopExplain,
    /// Pick a reference track of the loaded ride with a file dialog.
    PickReference,
    /// Measure the fit against this reference track.
    OpenReference(PathBuf),
    /// Pick a bike computer's activity (Garmin FIT) whose wheel distance
    /// becomes the loaded ride's odometer.
    PickWheel,
    /// Pick a GPS track of the same ride (GPX, FIT, NMEA, CSV) whose points
    /// become this source's fixes, and read it so.
    PickGpsTrack(RideSource),
}

/// One row of the model history: a finished fit of one model.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryRow {
    pub model: String,
    pub segment_s: f64,
    pub params: usize,
    pub fit_rms_m: f64,
    /// The GPS error law both RMS are measured under, in words.
    pub gps_noise: String,
    /// Held-out error over the fixes that are not GPS jumps (and how many
    /// were left out), filled in by a background validation of this fit as
    /// it is (its own noise settings).
    pub held_out: Option<HeldOutRms>,
    /// Why this fit could not be validated (a ride too short to withhold
    /// anything), shown in place of a held-out error.
    pub held_out_failed: Option<String>,
    pub iterations: usize,
    /// Horizontal RMS distance from the reference track (m), when one is loaded.
    pub reference_rms_m: Option<f64>,
}

/// Result of a file dialog, which runs on its own thread.
enum Picked {
    Ride(PathBuf),
    Reference(PathBuf),
    Wheel(PathBuf),
    /// A GPS track for this ride source.
    GpsTrack(RideSource, PathBuf),
    Export(ExportKind, PathBuf),
}

pub struct GyropathApp {
    pub settings: AppSettings,
    worker: WorkerHandle,
    pub ride: Option<RideView>,
    pub snapshot: Option<Snapshot>,
    pub running: bool,
    pub loading: Option<String>,
    pub error: Option<String>,
    /// What the error offers instead (a ride refused for a pause: each side of it).
    pub retry: Vec<(String, RideSource)>,
    /// A ride refused for having no GPS fix, to read again with a GPS track
    /// that the user picks (the error's "GPS track..." button).
    pub track_for: Option<RideSource>,
    pub status: Option<String>,
    pub history: Vec<HistoryRow>,
    pub diagnosis: Option<crate::diagnosis::Diagnosis>,
    /// The loaded ride's reference track, when one is open.
    pub reference: Option<worker::ReferenceView>,
    /// Progress of a running diagnosis.
    pub diagnosing: Option<String>,
    /// A running Explain, and what it has said (kept after it ends).
    pub explaining: Option<explain::Explaining>,
    pub explain_log: Vec<explain::ExplainLine>,
    hover_t: Option<f64>,
    picked_tx: Sender<Picked>,
    picked_rx: Receiver<Picked>,
    /// Start running when the ride being loaded arrives.
    run_on_load: bool,
    /// Frame-time statistics on stderr (`GYROPATH_FRAME_LOG=1`), for measuring.
    frame_log: Option<FrameLog>,
    /// The map's tile background; `None` (the default, and in tests) never
    /// touches the network. [`run`] sets OpenStreetMap's.
    pub map_background: Option<map_tiles::MapBackground>,
}

/// Frame times of the UI (eframe's CPU time per frame, without the GPU).
#[derive(Default)]
struct FrameLog {
    times: Vec<f32>,
    /// Frames seen; the first [`FrameLog::WARM_UP`] (font atlas, first layout) are not counted.
    seen: usize,
}

impl FrameLog {
    const WARM_UP: usize = 30;

    fn record(&mut self, cpu: Option<f32>) {
        let Some(t) = cpu else {
            return;
        };
        self.seen += 1;
        if self.seen <= Self::WARM_UP {
            return;
        }
        self.times.push(t);
        if self.times.len() == 200 {
            let mut v = std::mem::take(&mut self.times);
            v.sort_by(f32::total_cmp);
            let rss = std::fs::read_to_string("/proc/self/status")
                .ok()
                .and_then(|s| {
                    s.lines()
                        .find(|l| l.starts_with("VmRSS:"))
                        .map(|l| l.trim_start_matches("VmRSS:").trim().to_string())
                })
                .unwrap_or_default();
            eprintln!(
                "frames: median {:.2} ms, 95% {:.2} ms, max {:.2} ms over 200; RSS {rss}",
                1e3 * v[100],
                1e3 * v[190],
                1e3 * v[199]
            );
        }
    }
}

impl GyropathApp {
    /// Start the worker and load `ride`. `wake` is called whenever the worker
    /// has something new (pass the egui context's `request_repaint`).
    pub fn new(
        settings: AppSettings,
        ride: RideSource,
        wake: impl Fn() + Send + Sync + 'static,
    ) -> Self {
        let worker = WorkerHandle::spawn(settings.fit.clone(), wake);
        let (picked_tx, picked_rx) = std::sync::mpsc::channel();
        let mut app = Self {
            run_on_load: settings.auto_run,
            settings,
            worker,
            ride: None,
            snapshot: None,
            running: false,
            loading: None,
            error: None,
            retry: Vec::new(),
            track_for: None,
            status: None,
            history: Vec::new(),
            diagnosis: None,
            reference: None,
            diagnosing: None,
            explaining: None,
            explain_log: Vec::new(),
            hover_t: None,
            picked_tx,
            picked_rx,
            frame_log: std::env::var_os("GYROPATH_FRAME_LOG").map(|_| FrameLog::default()),
            map_background: None,
        };
        app.apply(Command::Open(ride));
        app
    }

    /// Drain what the worker and the file dialogs sent since the last frame.
    fn poll(&mut self) {
        while let Ok(update) = self.worker.rx.try_recv() {
            match update {
                Update::Loading(name) => self.loading = Some(name),
                Update::Loaded(view) => {
                    self.loading = None;
                    self.error = None;
                    self.retry.clear();
                    self.track_for = None;
                    if let RideSource::Path(p, _) = &view.source {
                        self.settings.recent.retain(|r| r != p);
                        self.settings.recent.insert(0, p.clone());
                        self.settings.recent.truncate(MAX_RECENT);
                    }
                    self.ride = Some(*view);
                    self.snapshot = None;
                    self.history.clear();
                    self.diagnosis = None;
                    // A reference belongs to the ride it was opened for.
                    self.reference = None;
                    if std::mem::take(&mut self.run_on_load) {
                        self.worker.send(Request::Run);
                    }
                }
                Update::LoadFailed {
                    message,
                    retry,
                    track_for,
                } => {
                    self.loading = None;
                    self.run_on_load = false;
                    self.error = Some(format!("could not load the ride: {message}"));
                    self.retry = retry;
                    self.track_for = track_for;
                }
                Update::Snapshot(s) => {
                    self.record_history(&s);
                    let done = s.phase == Phase::Done;
                    self.snapshot = Some(*s);
                    if done {
                        self.explain_fit_finished();
                    }
                }
                Update::Running(r) => self.running = r,
                Update::Error(e) => {
                    if e.starts_with("diagnosis failed") {
                        self.diagnosing = None;
                        if self.explaining.take().is_some() {
                            self.explain_log
                                .push(explain::ExplainLine::new("Explain stops", e.clone()));
                        }
                    }
                    self.error = Some(e);
                }
                Update::Exported(p) => self.status = Some(format!("wrote {p}")),
                Update::DiagnosisProgress(p) => self.diagnosing = Some(p),
                Update::ReferenceLoaded(r) => {
                    self.status = Some(format!(
                        "reference {}: covers {:.0} s of the ride{}",
                        r.name,
                        r.covered_s,
                        r.warnings
                            .iter()
                            .map(|w| format!("; warning: {w}"))
                            .collect::<String>()
                    ));
                    self.reference = Some(*r);
                    // The worker follows with a snapshot of the current fit
                    // measured against it, which fills the last history row;
                    // earlier models get it when they are fitted again.
                }
                // The diagnosis's own held-out error is of a refit under the
                // noise as set: it stays in the diagnosis panel, and the
                // history keeps one kind of number, its own validation's.
                Update::Diagnosis(d) => {
                    self.diagnosing = None;
                    let mut commands = Vec::new();
                    self.explain_diagnosed(&d, &mut commands);
                    self.diagnosis = Some(*d);
                    for c in commands {
                        self.apply(c);
                    }
                }
                Update::HeldOut {
                    model,
                    params,
                    held_out,
                } => {
                    if let Some(row) = self
                        .history
                        .iter_mut()
                        .rev()
                        .find(|r| r.model == model && r.params == params)
                        .filter(|r| r.held_out.is_none() && r.held_out_failed.is_none())
                    {
                        match held_out {
                            Ok(h) => row.held_out = Some(h),
                            Err(why) => row.held_out_failed = Some(why),
                        }
                    }
                }
            }
        }
        while let Ok(p) = self.picked_rx.try_recv() {
            match p {
                Picked::Ride(path) => self.apply(Command::Open(RideSource::file(path))),
                Picked::Reference(path) => self.apply(Command::OpenReference(path)),
                Picked::Wheel(fit) => {
                    if let Some(reload) = self.ride.as_ref().and_then(|r| r.source.with_wheel(fit))
                    {
                        self.apply(Command::Open(reload));
                    }
                }
                Picked::GpsTrack(source, track) => {
                    if let Some(reload) = source.with_gps_track(Some(track)) {
                        self.apply(Command::Open(reload));
                    }
                }
                Picked::Export(kind, path) => self.export_to(kind, path),
            }
        }
    }

    /// A fit that just finished becomes a row of the model history.
    fn record_history(&mut self, s: &Snapshot) {
        if s.phase != Phase::Done || s.history.is_empty() {
            return;
        }
        let row = HistoryRow {
            model: s.effects.join(", "),
            segment_s: self.settings.fit.model.segment_s,
            params: s.n_params,
            fit_rms_m: s.stats.rms_horizontal_m,
            gps_noise: s.gps_noise.clone(),
            held_out: None,
            held_out_failed: None,
            iterations: s.history.len(),
            reference_rms_m: s.reference.as_ref().map(|c| c.horizontal.rms_m),
        };
        let same = self.history.last().is_some_and(|r| {
            r.model == row.model && r.params == row.params && r.iterations == row.iterations
        });
        if !same {
            self.history.push(row);
        } else if let (Some(last), Some(r)) = (self.history.last_mut(), row.reference_rms_m) {
            // The same fit, now measured against a reference opened after it.
            last.reference_rms_m = Some(r);
        }
    }

    pub fn apply(&mut self, command: Command) {
        match command {
            Command::Open(source) => {
                // Each ride starts from the default model, as `gyropath fit`
                // does on the same file: effects added on one ride say
                // nothing about the next (nor about the last run's ride).
                let default = crate::model::ModelSpec::default().effects;
                if self.settings.fit.model.effects != default {
                    self.status = Some(format!(
                        "new ride: the model starts again from the paper's (the last ride had {})",
                        self.settings.fit.model.effects.join(", ")
                    ));
                    self.settings.fit.model.effects = default;
                    self.worker
                        .send(Request::Settings(Box::new(self.settings.fit.clone())));
                }
                self.run_on_load = self.settings.auto_run;
                self.worker.send(Request::Load(source));
            }
            Command::PickRide => {
                let tx = self.picked_tx.clone();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new()
                        .add_filter(
                            "ride log, bag, drone, camera or phone log",
                            &crate::import::RIDE_EXTENSIONS,
                        )
                        .add_filter("ride-log CSV", &["csv"])
                        .add_filter("ROS 1 bag", &["bag"])
                        .add_filter("ROS 2 bag (MCAP)", &["mcap"])
                        .add_filter("PX4 ULog", &["ulg"])
                        .add_filter("ArduPilot DataFlash", &["bin"])
                        .add_filter("camera (GoPro MP4, ...)", &["mp4", "mov"])
                        .add_filter("Android GnssLogger", &["txt"])
                        .pick_file()
                    {
                        let _ = tx.send(Picked::Ride(p));
                    }
                });
            }
            Command::PickBagFolder => {
                let tx = self.picked_tx.clone();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new().pick_folder() {
                        let _ = tx.send(Picked::Ride(p));
                    }
                });
            }
            Command::PickExport(kind) => {
                let tx = self.picked_tx.clone();
                let (filter, ext) = match kind {
                    ExportKind::PathCsv => ("path CSV", "csv"),
                    ExportKind::PathGpx => ("GPX track", "gpx"),
                    ExportKind::PathTum => ("TUM trajectory", "tum"),
                    ExportKind::ReportJson => ("fit report", "json"),
                    ExportKind::ReportHtml => ("report (HTML)", "html"),
                };
                let stem = self.export_stem();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new()
                        .add_filter(filter, &[ext])
                        .set_file_name(format!("{stem}.{ext}"))
                        .save_file()
                    {
                        let _ = tx.send(Picked::Export(kind, p));
                    }
                });
            }
            Command::PickReference => {
                let tx = self.picked_tx.clone();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new()
                        .add_filter(
                            "reference track (t_s,lat_deg,lon_deg[,alt_m] CSV, GPX, Garmin FIT, NMEA; a comma2k19 global_pose folder: drop it on the window)",
                            &["csv", "gpx", "fit", "gga", "nmea"],
                        )
                        .pick_file()
                    {
                        let _ = tx.send(Picked::Reference(p));
                    }
                });
            }
            Command::OpenReference(path) => self.worker.send(Request::LoadReference(path)),
            Command::PickWheel => {
                let tx = self.picked_tx.clone();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new()
                        .add_filter("bike computer activity (Garmin FIT)", &["fit"])
                        .pick_file()
                    {
                        let _ = tx.send(Picked::Wheel(p));
                    }
                });
            }
            Command::PickGpsTrack(source) => {
                let tx = self.picked_tx.clone();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new()
                        .add_filter(
                            "GPS track (GPX, FIT, NMEA, CSV)",
                            &["gpx", "fit", "nmea", "gga", "csv"],
                        )
                        .pick_file()
                    {
                        let _ = tx.send(Picked::GpsTrack(source, p));
                    }
                });
            }
            Command::Run => self.worker.send(Request::Run),
            Command::Pause => self.worker.send(Request::Pause),
            Command::Step => self.worker.send(Request::Step),
            Command::Reset => self.worker.send(Request::Reset),
            Command::SettingsChanged => {
                self.worker
                    .send(Request::Settings(Box::new(self.settings.fit.clone())));
            }
            Command::DismissError => {
                self.error = None;
                self.retry.clear();
                self.track_for = None;
            }
            Command::Diagnose => {
                self.diagnosing = Some("starting".into());
                self.worker.send(Request::Diagnose);
            }
            Command::Explain => self.start_explain(),
            Command::StopExplain => self.stop_explain(),
            Command::AddEffect(id) => {
                effects_panel::set_effect(&mut self.settings.fit.model.effects, &id, true);
                self.worker
                    .send(Request::Settings(Box::new(self.settings.fit.clone())));
                self.worker.send(Request::Run);
            }
        }
    }

    fn export_stem(&self) -> String {
        let name = self
            .ride
            .as_ref()
            .map_or("ride".to_string(), |r| match &r.source {
                RideSource::Path(p, _) => p
                    .file_stem()
                    .map_or("ride".into(), |s| s.to_string_lossy().into_owned()),
                RideSource::Bytes { .. } => "sample-ride".into(),
            });
        format!("{name}-gyropath")
    }

    /// Export to a chosen path without a dialog (scripts and tests).
    pub fn export_to(&self, kind: ExportKind, path: PathBuf) {
        let extras = match kind {
            ExportKind::ReportHtml => self.report_extras(),
            _ => ReportExtras::default(),
        };
        self.worker
            .send(Request::Export(kind, path, Box::new(extras)));
    }

    /// The model history, and the diagnosis when it is of the current model.
    fn report_extras(&self) -> ReportExtras {
        let current = self.snapshot.as_ref().map(|s| &s.effects);
        ReportExtras {
            history: self
                .history
                .iter()
                .map(|r| crate::report::ModelRow {
                    model: r.model.clone(),
                    note: format!("segments of {:.1} s, {} parameters", r.segment_s, r.params),
                    fit_rms_m: r.fit_rms_m,
                    gps_noise: r.gps_noise.clone(),
                    heldout_rms_m: r.held_out.map(|h| h.rms_m),
                    reference_rms_m: r.reference_rms_m,
                })
                .collect(),
            diagnosis: self.diagnosis.clone().filter(|d| Some(&d.model) == current),
        }
    }

    /// Draw the whole window and apply what the user did.
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        self.poll();
        let mut commands = Vec::new();
        self.dropped_files(ui, &mut commands);
        egui::Panel::top("menu").show(ui, |ui| self.menu_ui(ui, &mut commands));
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(300.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.controls_ui(ui, &mut commands));
            });
        egui::Panel::bottom("history")
            .resizable(true)
            .min_size(180.0)
            .default_size(200.0)
            .show(ui, |ui| {
                ui.columns(2, |cols| {
                    self.history_ui(&mut cols[0]);
                    // The ranking and Explain's lines can be taller than the panel.
                    egui::ScrollArea::vertical()
                        .id_salt("diagnosis-scroll")
                        .show(&mut cols[1], |ui| self.diagnosis_ui(ui, &mut commands));
                });
            });
        egui::CentralPanel::default().show(ui, |ui| self.plots_ui(ui));
        for c in commands {
            self.apply(c);
        }
        if self.running || self.loading.is_some() || self.diagnosing.is_some() {
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_millis(100));
        }
    }
}

impl GyropathApp {
    /// The left panel: source, fit, settings, effects, view, parameters.
    fn controls_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        if let Some(ride) = &self.ride {
            source::source_ui(ui, ride, commands);
            ui.separator();
        }
        self.fit_ui(ui, commands);
        ui.separator();
        let settings = self.settings_ui(ui);
        ui.separator();
        let effects = self.effects_ui(ui);
        if settings || effects {
            commands.push(Command::SettingsChanged);
        }
        ui.separator();
        self.view_ui(ui);
        self.parameters_ui(ui);
    }
}

impl eframe::App for GyropathApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        GyropathApp::ui(self, ui);
        if let Some(log) = self.frame_log.as_mut() {
            log.record(frame.info().cpu_usage);
        }
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, eframe::APP_KEY, &self.settings);
    }
}

/// Run a blocking file dialog off the UI thread.
fn spawn_dialog(f: impl FnOnce() + Send + 'static) {
    let _ = std::thread::Builder::new()
        .name("file-dialog".into())
        .spawn(f);
}

/// The app's window on `ride` (the sample without one), with `reference`
/// loaded as File > Open reference track loads it (the worker takes it
/// after the ride, and matches it to the ride's clock).
pub fn run(
    ride: Option<(PathBuf, crate::import::ImportOptions)>,
    reference: Option<PathBuf>,
) -> eframe::Result {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1280.0, 800.0])
            .with_min_inner_size([900.0, 600.0])
            .with_title("gyropath")
            .with_drag_and_drop(true),
        ..Default::default()
    };
    // The fit's pool threads yield to the window (see `background_priority`);
    // a pool already built (by an earlier command in this process) keeps its own.
    let _ = rayon::ThreadPoolBuilder::new()
        .start_handler(|_| worker::background_priority())
        .build_global();
    eframe::run_native(
        "gyropath",
        options,
        Box::new(move |cc| {
            let settings: AppSettings = cc
                .storage
                .and_then(|s| eframe::get_value(s, eframe::APP_KEY))
                .unwrap_or_default();
            let ctx = cc.egui_ctx.clone();
            let source = ride.map_or_else(sample_ride, |(p, o)| RideSource::Path(p, Box::new(o)));
            let mut app = GyropathApp::new(settings, source, move || ctx.request_repaint());
            app.map_background = Some(map_tiles::MapBackground::new(
                map_tiles::TileServer::from_env(),
            ));
            if let Some(path) = reference {
                app.apply(Command::OpenReference(path));
            }
            Ok(Box::new(app))
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_round_trip_through_json_and_default_missing_fields() {
        let s = AppSettings::default();
        let json = serde_json::to_string(&s).expect("json");
        let back: AppSettings = serde_json::from_str(&json).expect("back");
        assert_eq!(s, back);
        let partial: AppSettings = serde_json::from_str(r#"{"auto_run": false}"#).expect("partial");
        assert!(!partial.auto_run);
        assert_eq!(partial.fit, FitSettings::default());
    }
}
