//! The desktop app (eframe/egui): load a ride, watch the fit iterate on a
//! worker thread, tune it live, compare the model with the measurements.
//!
//! Structure (after egui's demo app): [`AppSettings`] is what persists between
//! runs; [`GyropathApp`] adds the runtime state. Widgets do not act directly:
//! they collect [`Command`]s that are applied after the frame. The UI holds no
//! physics: it sends settings to the [`worker`] and draws its snapshots.

pub mod examples;
pub mod plots;
pub mod source;
pub mod worker;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender};

use crate::effects;
use crate::model::DEFAULT_BIAS_WALK;
use crate::optimisation::{FitSettings, Method, Phase};
use worker::{ExportKind, Request, RideSource, RideView, Snapshot, Update, WorkerHandle};

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
    /// Start fitting as soon as a ride is loaded.
    pub auto_run: bool,
}

impl Default for AppSettings {
    fn default() -> Self {
        Self {
            fit: FitSettings::default(),
            recent: Vec::new(),
            colour_by_residual: false,
            auto_run: true,
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
}

/// One row of the model history: a finished fit of one model.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryRow {
    pub model: String,
    pub segment_s: f64,
    pub params: usize,
    pub fit_rms_m: f64,
    /// Held-out error, filled in by a background validation.
    pub heldout_rms_m: Option<f64>,
    pub iterations: usize,
}

/// Result of a file dialog, which runs on its own thread.
enum Picked {
    Ride(PathBuf),
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
    pub status: Option<String>,
    pub history: Vec<HistoryRow>,
    pub diagnosis: Option<crate::diagnosis::Diagnosis>,
    /// Progress of a running diagnosis.
    pub diagnosing: Option<String>,
    hover_t: Option<f64>,
    picked_tx: Sender<Picked>,
    picked_rx: Receiver<Picked>,
    /// Start running when the ride being loaded arrives.
    run_on_load: bool,
    /// Frame-time statistics on stderr (`GYROPATH_FRAME_LOG=1`), for measuring.
    frame_log: Option<FrameLog>,
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
            status: None,
            history: Vec::new(),
            diagnosis: None,
            diagnosing: None,
            hover_t: None,
            picked_tx,
            picked_rx,
            frame_log: std::env::var_os("GYROPATH_FRAME_LOG").map(|_| FrameLog::default()),
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
                    if let RideSource::Path(p, _) = &view.source {
                        self.settings.recent.retain(|r| r != p);
                        self.settings.recent.insert(0, p.clone());
                        self.settings.recent.truncate(MAX_RECENT);
                    }
                    self.ride = Some(*view);
                    self.snapshot = None;
                    self.history.clear();
                    self.diagnosis = None;
                    if std::mem::take(&mut self.run_on_load) {
                        self.worker.send(Request::Run);
                    }
                }
                Update::LoadFailed(e) => {
                    self.loading = None;
                    self.run_on_load = false;
                    self.error = Some(format!("could not load the ride: {e}"));
                }
                Update::Snapshot(s) => {
                    self.record_history(&s);
                    self.snapshot = Some(*s);
                }
                Update::Running(r) => self.running = r,
                Update::Error(e) => {
                    if e.starts_with("diagnosis failed") {
                        self.diagnosing = None;
                    }
                    self.error = Some(e);
                }
                Update::Exported(p) => self.status = Some(format!("wrote {p}")),
                Update::DiagnosisProgress(p) => self.diagnosing = Some(p),
                Update::Diagnosis(d) => {
                    self.diagnosing = None;
                    if let Some(row) = self
                        .history
                        .iter_mut()
                        .rev()
                        .find(|r| r.model == d.model.join(", "))
                    {
                        row.heldout_rms_m = Some(d.heldout_rms_m);
                    }
                    self.diagnosis = Some(*d);
                }
                Update::HeldOut {
                    model,
                    params,
                    rms_m,
                } => {
                    if let Some(row) = self
                        .history
                        .iter_mut()
                        .rev()
                        .find(|r| r.model == model && r.params == params)
                    {
                        row.heldout_rms_m.get_or_insert(rms_m);
                    }
                }
            }
        }
        while let Ok(p) = self.picked_rx.try_recv() {
            match p {
                Picked::Ride(path) => self.apply(Command::Open(RideSource::file(path))),
                Picked::Export(kind, path) => self.worker.send(Request::Export(kind, path)),
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
            heldout_rms_m: None,
            iterations: s.history.len(),
        };
        let same = self.history.last().is_some_and(|r| {
            r.model == row.model && r.params == row.params && r.iterations == row.iterations
        });
        if !same {
            self.history.push(row);
        }
    }

    pub fn apply(&mut self, command: Command) {
        match command {
            Command::Open(source) => {
                self.run_on_load = self.settings.auto_run;
                self.worker.send(Request::Load(source));
            }
            Command::PickRide => {
                let tx = self.picked_tx.clone();
                spawn_dialog(move || {
                    if let Some(p) = rfd::FileDialog::new()
                        .add_filter("ride log or bag", &["csv", "bag", "mcap"])
                        .add_filter("ride-log CSV", &["csv"])
                        .add_filter("ROS 1 bag", &["bag"])
                        .add_filter("ROS 2 bag (MCAP)", &["mcap"])
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
                    ExportKind::ReportJson => ("fit report", "json"),
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
            Command::Run => self.worker.send(Request::Run),
            Command::Pause => self.worker.send(Request::Pause),
            Command::Step => self.worker.send(Request::Step),
            Command::Reset => self.worker.send(Request::Reset),
            Command::SettingsChanged => {
                self.worker
                    .send(Request::Settings(self.settings.fit.clone()));
            }
            Command::DismissError => self.error = None,
            Command::Diagnose => {
                self.diagnosing = Some("starting".into());
                self.worker.send(Request::Diagnose);
            }
            Command::AddEffect(id) => {
                set_effect(&mut self.settings.fit.model.effects, &id, true);
                self.worker
                    .send(Request::Settings(self.settings.fit.clone()));
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
        self.worker.send(Request::Export(kind, path));
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
                    self.diagnosis_ui(&mut cols[1], &mut commands);
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

    fn dropped_files(&mut self, ui: &egui::Ui, commands: &mut Vec<Command>) {
        let dropped = ui.ctx().input(|i| i.raw.dropped_files.clone());
        if let Some(f) = dropped.into_iter().next() {
            commands.push(Command::Open(RideSource::file(f.path().to_path_buf())));
        }
    }

    fn menu_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open ride or bag...").clicked() {
                    commands.push(Command::PickRide);
                }
                if ui.button("Open ROS 2 bag folder...").clicked() {
                    commands.push(Command::PickBagFolder);
                }
                if ui.button("Open the sample ride").clicked() {
                    commands.push(Command::Open(sample_ride()));
                }
                ui.menu_button("Examples", |ui| examples::examples_menu_ui(ui, commands));
                ui.menu_button("Recent", |ui| {
                    if self.settings.recent.is_empty() {
                        ui.label("(none yet)");
                    }
                    for p in &self.settings.recent {
                        if ui.button(p.display().to_string()).clicked() {
                            commands.push(Command::Open(RideSource::file(p.clone())));
                        }
                    }
                });
                ui.separator();
                let fitted = self.snapshot.is_some();
                for (label, kind) in [
                    ("Export path (CSV)...", ExportKind::PathCsv),
                    ("Export path (GPX)...", ExportKind::PathGpx),
                    ("Export fit report (JSON)...", ExportKind::ReportJson),
                ] {
                    if ui.add_enabled(fitted, egui::Button::new(label)).clicked() {
                        commands.push(Command::PickExport(kind));
                    }
                }
            });
            ui.separator();
            match (&self.loading, &self.ride) {
                (Some(name), _) => {
                    ui.spinner();
                    ui.label(format!("Loading {name}..."));
                }
                (None, Some(r)) => {
                    ui.label(format!(
                        "{}: {:.1} min, {} rows, {} fixes",
                        r.source.name(),
                        r.duration_s / 60.0,
                        r.rows,
                        r.fixes.len()
                    ));
                }
                (None, None) => {
                    ui.label("No ride loaded: File > Open, or drop a CSV on the window");
                }
            }
            if let Some(s) = &self.status {
                ui.separator();
                ui.label(s);
            }
        });
        if let Some(e) = self.error.clone() {
            ui.horizontal_wrapped(|ui| {
                ui.colored_label(
                    egui::Color32::from_rgb(255, 110, 110),
                    format!("Error: {e}"),
                );
                if ui.small_button("Dismiss").clicked() {
                    commands.push(Command::DismissError);
                }
            });
        }
    }

    fn controls_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        if let Some(ride) = &self.ride {
            source::source_ui(ui, ride, commands);
            ui.separator();
        }
        ui.heading("Fit");
        ui.horizontal(|ui| {
            let can = self.snapshot.is_some();
            if self.running {
                if ui.button("Pause").clicked() {
                    commands.push(Command::Pause);
                }
            } else if ui.add_enabled(can, egui::Button::new("Run")).clicked() {
                commands.push(Command::Run);
            }
            if ui
                .add_enabled(can, egui::Button::new("Step once"))
                .clicked()
            {
                commands.push(Command::Step);
            }
            if ui.add_enabled(can, egui::Button::new("Reset")).clicked() {
                commands.push(Command::Reset);
            }
        });
        ui.checkbox(&mut self.settings.auto_run, "run on load");
        if let Some(s) = &self.snapshot {
            let last = s.history.last();
            let phase = match s.phase {
                Phase::Step1 => "step 1 (constant bias, start, gain)",
                Phase::Step2 => "step 2 (segment biases)",
                Phase::Done => "done",
            };
            egui::Grid::new("fit-state").num_columns(2).show(ui, |ui| {
                ui.label("phase");
                ui.label(phase);
                ui.end_row();
                ui.label("iteration");
                ui.label(format!("{}", last.map_or(0, |r| r.iteration)));
                ui.end_row();
                ui.label("cost");
                ui.label(format!("{:.6e}", s.stats.cost));
                ui.end_row();
                ui.label("GPS RMS");
                ui.label(format!("{:.3} m", s.stats.rms_horizontal_m));
                ui.end_row();
                ui.label("along / cross");
                ui.label(format!(
                    "{:.2} / {:.2} m",
                    s.residual_rms.along_m, s.residual_rms.cross_m
                ));
                ui.end_row();
                if let Some(up) = s.residual_rms.up_m {
                    ui.label("vertical");
                    ui.label(format!("{up:.2} m"));
                    ui.end_row();
                }
                ui.label("segments");
                ui.label(format!("{}", s.segments.len()));
                ui.end_row();
                ui.label("parameters");
                ui.label(format!("{}", s.n_params));
                ui.end_row();
            });
            if s.phase == Phase::Done && !s.violations.is_empty() {
                let red = egui::Color32::from_rgb(210, 60, 60);
                ui.colored_label(red, "Not physical: this fit is no result.");
                for v in &s.violations {
                    ui.colored_label(red, v);
                }
            }
        }

        ui.separator();
        ui.heading("Settings");
        let fit = &mut self.settings.fit;
        let mut changed = false;
        changed |= ui
            .add(
                egui::Slider::new(&mut fit.model.segment_s, 1.0..=120.0)
                    .logarithmic(true)
                    .text("segment (s)"),
            )
            .changed();
        ui.horizontal(|ui| {
            ui.label("step 2");
            changed |= ui
                .radio_value(&mut fit.method, Method::Lm, "Levenberg-Marquardt")
                .changed();
            changed |= ui
                .radio_value(&mut fit.method, Method::Gd, "gradient descent")
                .changed();
        });
        changed |= ui
            .add(
                egui::Slider::new(&mut fit.damping, 1e-9..=1e3)
                    .logarithmic(true)
                    .custom_formatter(|v, _| format!("{v:.1e}"))
                    .text("LM damping λ"),
            )
            .changed();
        changed |= ui
            .add(
                egui::Slider::new(&mut fit.step_size, 1e-10..=1e-2)
                    .logarithmic(true)
                    .custom_formatter(|v, _| format!("{v:.1e}"))
                    .text("GD step size γ"),
            )
            .changed();
        let mut prior = fit.model.bias_walk_dps_sqrt_s.is_some();
        if ui
            .checkbox(&mut prior, "bias smoothness prior")
            .on_hover_text(
                "a random-walk prior between neighbouring segment biases; off = the paper",
            )
            .changed()
        {
            fit.model.bias_walk_dps_sqrt_s = prior.then_some(DEFAULT_BIAS_WALK);
            changed = true;
        }
        if let Some(w) = fit.model.bias_walk_dps_sqrt_s.as_mut() {
            changed |= ui
                .add(
                    egui::Slider::new(w, 1e-4..=1e-1)
                        .logarithmic(true)
                        .text("bias walk (deg/s/sqrt(s))"),
                )
                .changed();
        }

        ui.separator();
        ui.heading("Effects");
        ui.label("The paper's model is always on; add effects it lacks:");
        let channels = self
            .ride
            .as_ref()
            .map_or(Vec::new(), |r| r.channels.clone());
        for (id, about) in effects::catalogue(&channels) {
            let mut on = effects_contains(&fit.model.effects, &id);
            if ui.checkbox(&mut on, &id).on_hover_text(about).changed() {
                set_effect(&mut fit.model.effects, &id, on);
                changed = true;
            }
        }
        if changed {
            commands.push(Command::SettingsChanged);
        }

        ui.separator();
        ui.heading("View");
        ui.checkbox(
            &mut self.settings.colour_by_residual,
            "colour path by residual",
        );

        if let Some(s) = &self.snapshot {
            ui.separator();
            ui.heading("Parameters");
            egui::Grid::new("params")
                .num_columns(3)
                .striped(true)
                .show(ui, |ui| {
                    for (effect, name, value, unit) in &s.params {
                        ui.label(effect);
                        ui.label(name);
                        ui.label(format!("{value:.5} {unit}"));
                        ui.end_row();
                    }
                });
        }
        if let Some(r) = &self.ride
            && !r.warnings.is_empty()
        {
            ui.separator();
            ui.heading("Warnings");
            for w in &r.warnings {
                ui.label(w);
            }
        }
    }

    fn history_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Model history");
        if self.history.is_empty() {
            ui.label(
                "Each finished fit adds a row: change the model or settings and watch the error.",
            );
            return;
        }
        if self.history.iter().any(|r| r.heldout_rms_m.is_some()) {
            plots::history_ui(ui, &self.history, 110.0);
        }
        egui::ScrollArea::vertical()
            .id_salt("history-scroll")
            .show(ui, |ui| {
                egui::Grid::new("history")
                    .num_columns(6)
                    .striped(true)
                    .show(ui, |ui| {
                        for h in [
                            "model",
                            "segment",
                            "params",
                            "iters",
                            "fit RMS",
                            "held-out RMS",
                        ] {
                            ui.strong(h);
                        }
                        ui.end_row();
                        for row in &self.history {
                            ui.label(short_model(&row.model)).on_hover_text(&row.model);
                            ui.label(format!("{:.1} s", row.segment_s));
                            ui.label(format!("{}", row.params));
                            ui.label(format!("{}", row.iterations));
                            ui.label(format!("{:.3} m", row.fit_rms_m));
                            match row.heldout_rms_m {
                                Some(h) => ui.label(format!("{h:.3} m")),
                                None => ui.label("validating..."),
                            };
                            ui.end_row();
                        }
                    });
            });
    }

    fn diagnosis_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        ui.horizontal(|ui| {
            ui.heading("Diagnosis");
            let idle = self.diagnosing.is_none() && self.snapshot.is_some();
            if ui
                .add_enabled(idle, egui::Button::new("Diagnose"))
                .on_hover_text(
                    "rank the effects the model lacks by how much each lowers the held-out error",
                )
                .clicked()
            {
                commands.push(Command::Diagnose);
            }
            if let Some(p) = &self.diagnosing {
                ui.spinner();
                ui.label(p);
            }
        });
        let Some(d) = &self.diagnosis else {
            ui.label("Diagnose ranks every effect the model lacks by the held-out error it saves.");
            if self
                .ride
                .as_ref()
                .is_some_and(|r| matches!(r.source, RideSource::Bytes { .. }))
            {
                ui.label(
                    "This sample has nothing missing, so Diagnose finds nothing here: File > Examples has rides with something to find.",
                );
            }
            return;
        };
        ui.label(format!(
            "{}: fit {:.3} m, held-out {:.3} m",
            short_model(&d.model.join(", ")),
            d.fit_rms_m,
            d.heldout_rms_m
        ));
        let current = self.snapshot.as_ref().map(|s| s.effects.clone());
        let stale = current.as_ref().is_some_and(|c| *c != d.model);
        if stale {
            ui.label("(for an earlier model: diagnose again)");
        }
        if !d.not_physical.is_empty() {
            let red = egui::Color32::from_rgb(210, 60, 60);
            ui.colored_label(
                red,
                "The model's own fit is not physical: fix the axes or units first (Source panel).",
            );
            for v in &d.not_physical {
                ui.colored_label(red, v);
            }
        }
        egui::ScrollArea::vertical()
            .id_salt("diagnosis-scroll")
            .show(ui, |ui| {
                egui::Grid::new("ranking")
                    .num_columns(5)
                    .striped(true)
                    .show(ui, |ui| {
                        for h in ["", "effect", "held-out (m)", "drop", "estimate"] {
                            ui.strong(h);
                        }
                        ui.end_row();
                        for c in &d.ranking {
                            let present = current.as_ref().is_some_and(|m| m.contains(&c.effect));
                            if ui
                                .add_enabled(
                                    !present && c.error.is_none(),
                                    egui::Button::new("Add"),
                                )
                                .on_hover_text(format!("add {} and refit", c.effect))
                                .clicked()
                            {
                                commands.push(Command::AddEffect(c.effect.clone()));
                            }
                            let label = if c.significant {
                                egui::RichText::new(&c.effect)
                                    .strong()
                                    .color(egui::Color32::from_rgb(120, 220, 120))
                            } else {
                                egui::RichText::new(&c.effect)
                            };
                            ui.label(label).on_hover_text(&c.explanation);
                            if let Some(e) = &c.error {
                                ui.label("-");
                                ui.label("-");
                                ui.label(e);
                            } else {
                                ui.label(format!("{:.3}", c.heldout_rms_m));
                                ui.label(format!(
                                    "{:+.1} %{}",
                                    100.0 * c.drop,
                                    if c.significant { " significant" } else { "" }
                                ));
                                let est: Vec<String> = c
                                    .estimate
                                    .iter()
                                    .map(|(k, e)| format!("{k} {:.3}±{:.3}", e.value, e.sigma))
                                    .collect();
                                ui.label(est.join(", ")).on_hover_text(&c.explanation);
                            }
                            ui.end_row();
                        }
                    });
                if let Some(best) = d.ranking.first().filter(|c| c.significant) {
                    ui.label(format!("Missing: {}: {}", best.effect, best.explanation));
                } else {
                    ui.label(
                        "Nothing significant: no effect lowers the held-out error beyond chance.",
                    );
                }
            });
    }

    fn plots_ui(&mut self, ui: &mut egui::Ui) {
        let Some(ride) = &self.ride else {
            ui.centered_and_justified(|ui| {
                ui.label("Open a ride log (File > Open) or drop a CSV file here.");
            });
            return;
        };
        let snap = self.snapshot.as_ref();
        let avail = ui.available_size();
        let mut hover = None;
        ui.horizontal_top(|ui| {
            let map_w = (avail.x * 0.5).max(200.0);
            ui.allocate_ui(egui::vec2(map_w, avail.y), |ui| {
                plots::map_ui(
                    ui,
                    ride,
                    snap,
                    self.settings.colour_by_residual,
                    self.hover_t,
                );
            });
            ui.vertical(|ui| {
                let Some(snap) = snap else {
                    ui.label("Waiting for the first iteration...");
                    return;
                };
                let h = ((avail.y - 3.0 * 24.0) / 3.0).max(60.0);
                ui.label("Fit progress (log scale): GPS RMS over the whole ride; grey lines end a step, red ones mark a settings change");
                plots::cost_ui(ui, snap, h);
                ui.label("Gyro bias per segment");
                hover = hover.or(plots::bias_ui(ui, ride, snap, h).0);
                ui.label("Residuals at GPS fixes");
                hover = hover.or(plots::residuals_ui(ui, ride, snap, h).0);
            });
        });
        self.hover_t = hover;
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

/// The model's effect list with the paper's five said once.
fn short_model(model: &str) -> String {
    let ids: Vec<&str> = model.split(", ").collect();
    if effects::PAPER.iter().all(|p| ids.contains(p)) {
        let extra: Vec<&str> = ids
            .into_iter()
            .filter(|i| !effects::PAPER.contains(i) && *i != "baro_offset")
            .collect();
        if extra.is_empty() {
            "paper".to_string()
        } else {
            format!("paper + {}", extra.join(" + "))
        }
    } else {
        model.to_string()
    }
}

fn effects_contains(list: &[String], id: &str) -> bool {
    list.iter().any(|e| e.split(',').any(|p| p.trim() == id))
}

fn set_effect(list: &mut Vec<String>, id: &str, on: bool) {
    if on {
        if !effects_contains(list, id) {
            list.push(id.to_string());
        }
    } else {
        list.retain(|e| e.trim() != id);
    }
}

/// Open the app window on `ride` (the bundled sample when `None`).
pub fn run(ride: Option<(PathBuf, crate::import::ImportOptions)>) -> eframe::Result {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1280.0, 800.0])
            .with_min_inner_size([900.0, 600.0])
            .with_title("gyropath")
            .with_drag_and_drop(true),
        ..Default::default()
    };
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
            Ok(Box::new(GyropathApp::new(settings, source, move || {
                ctx.request_repaint()
            })))
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effect_toggles_edit_the_list() {
        let mut list = vec!["paper".to_string()];
        set_effect(&mut list, "gyro_scale", true);
        set_effect(&mut list, "gyro_scale", true);
        assert_eq!(list, ["paper", "gyro_scale"]);
        assert!(effects_contains(&list, "gyro_scale"));
        set_effect(&mut list, "gyro_scale", false);
        assert_eq!(list, ["paper"]);
    }

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
