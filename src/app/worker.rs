//! The worker thread: owns the ride and the [`Reconstruction`], runs it one
//! iteration at a time and sends the UI what it needs to draw.
//!
//! The UI never blocks on it: requests go in over one channel, updates come
//! back over another, and the worker wakes the UI with `request_repaint` after
//! each send. Requests are read between iterations, so Pause, new settings and
//! shutdown act within one iteration (tens of milliseconds on a 30-minute ride).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::time::{Duration, Instant};

use crate::diagnosis::reference::{self, Matched};
use crate::diagnosis::view::{decimated_rows, peaks};
use crate::diagnosis::{
    Diagnosis, FitView, FixResidual, Folds, HeldOutRms, ResidualRms, SegmentBias,
    diagnose_fitted_against, held_out_rms,
};
use crate::export::{write_atomically, write_json, write_path_csv, write_path_gpx, write_path_tum};
use crate::import::ReferenceTrack;
use crate::import::{self, ImportOptions, MountChoice, SourceKind};
use crate::model::Model;
use crate::optimisation::{FitSettings, FitStats, IterationReport, Phase, Reconstruction};
use crate::pipeline::{self, PipelineError};
use crate::signals::Signals;

/// At most this many path points go to the UI per snapshot.
pub const MAX_PATH_POINTS: usize = 4000;
/// Snapshots are sent at most this often while running (the last of a run always is).
const SNAPSHOT_INTERVAL: Duration = Duration::from_millis(50);

/// Where a ride comes from.
#[derive(Clone, Debug)]
pub enum RideSource {
    /// A file or rosbag2 folder, and how to read it (topics, mounting, column map).
    Path(PathBuf, Box<ImportOptions>),
    /// In-memory bytes (the bundled sample, a dropped file without a path).
    Bytes { name: String, bytes: Arc<[u8]> },
}

impl RideSource {
    /// A file read with the defaults of its kind.
    pub fn file(path: PathBuf) -> Self {
        Self::Path(path, Box::default())
    }

    pub fn name(&self) -> String {
        match self {
            Self::Path(p, _) => p.display().to_string(),
            Self::Bytes { name, .. } => name.clone(),
        }
    }

    /// The same file with only its rows from `window.0` to `window.1` s
    /// (the log's clock; `--between`); `None` for bytes in memory.
    pub fn between(&self, window: (f64, f64)) -> Option<Self> {
        let Self::Path(path, options) = self else {
            return None;
        };
        let mut options = options.clone();
        options.between = Some(window);
        Some(Self::Path(path.clone(), options))
    }

    /// The same file read again with `fit`'s wheel distance as its odometer
    /// (the distance choice back to auto, which a wheel distance needs);
    /// `None` for bytes in memory, which have no UTC start to match by.
    pub fn with_wheel(&self, fit: PathBuf) -> Option<Self> {
        let Self::Path(path, options) = self else {
            return None;
        };
        let mut options = options.clone();
        options.wheel = Some(fit);
        options.distance = crate::import::DistanceChoice::Auto;
        Some(Self::Path(path.clone(), options))
    }

    /// The same file read again with the fixes of a GPS track of the same
    /// ride (`--gps-track`), or with its own (`None`); `None` for bytes in
    /// memory.
    pub fn with_gps_track(&self, track: Option<PathBuf>) -> Option<Self> {
        let Self::Path(path, options) = self else {
            return None;
        };
        let mut options = options.clone();
        options.gps_track = track;
        Some(Self::Path(path.clone(), options))
    }
}

/// What the worker can export.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportKind {
    PathCsv,
    PathGpx,
    /// A TUM trajectory (for evo).
    PathTum,
    ReportJson,
    /// The HTML report to share.
    ReportHtml,
}

/// What the UI knows that a report shows: the model history and the
/// diagnosis of the current model (the worker has the fit and the ride).
#[derive(Clone, Debug, Default)]
pub struct ReportExtras {
    pub history: Vec<crate::report::ModelRow>,
    pub diagnosis: Option<Diagnosis>,
}

/// UI -> worker.
#[derive(Debug)]
pub enum Request {
    Load(RideSource),
    Run,
    Pause,
    Step,
    /// Start the fit again from the start guess with the current settings.
    Reset,
    /// Boxed: the settings are most of the enum's size, sent once per change.
    Settings(Box<FitSettings>),
    Export(ExportKind, PathBuf, Box<ReportExtras>),
    /// Rank the effects the current model lacks (runs beside the fit).
    Diagnose,
    /// Measure the fit against a reference track of the loaded ride.
    LoadReference(PathBuf),
    Shutdown,
}

/// A reference track matched to the loaded ride, for the map.
#[derive(Clone, Debug)]
pub struct ReferenceView {
    pub name: String,
    /// Log time, east, north (m) at the covered rows, at most [`MAX_PATH_POINTS`].
    pub points: Vec<[f64; 3]>,
    /// Seconds of the ride it covers, of its duration.
    pub covered_s: f64,
    /// What reading it left out (a last line cut short).
    pub warnings: Vec<String>,
}

/// A freshly loaded ride: the measurements to draw under the fit.
#[derive(Clone, Debug)]
pub struct RideView {
    pub source: RideSource,
    pub rows: usize,
    /// Of `rows`, those filled across gaps in the log (`crate::log_gaps`).
    pub rows_filled: usize,
    pub duration_s: f64,
    pub t0: f64,
    /// GPS fixes: log time, east, north (m).
    pub fixes: Vec<[f64; 3]>,
    /// GPS outages (log time from, to): gaps between fixes longer than 2.5 s.
    pub outages: Vec<(f64, f64)>,
    /// Where the gyro stopped answering (log time from, to): the fit
    /// bridges them with free turns (`effects::gyro_stops`).
    pub gyro_stops: Vec<(f64, f64)>,
    /// Of `gyro_stops`, how many are where the sensor turned without the
    /// vehicle (`crate::sensor_turns`).
    pub sensor_turns: usize,
    /// The effects of the catalogue this ride can take, with what each models.
    pub offered_effects: Vec<(String, String)>,
    pub warnings: Vec<String>,
    /// What the ride was read from, and what the checks said.
    pub origin: Origin,
    /// The attitude model and why.
    pub attitude: crate::signals::Attitude,
    /// Where the distance came from (wheel sensor, odometer, GNSS speed), in words.
    pub distance: String,
    /// Whether the log has the GNSS receiver's speed (a distance without the odometer).
    pub has_gnss_speed: bool,
    /// The local frame the fixes are in (for the map's tiles).
    pub frame: crate::geodesy::LocalFrame,
}

pub use crate::pipeline::Origin;

/// The state of the fit after an iteration, decimated for drawing.
#[derive(Clone, Debug)]
pub struct Snapshot {
    pub phase: Phase,
    pub history: Vec<IterationReport>,
    pub stats: FitStats,
    /// Path points: log time, east, north (m), at most [`MAX_PATH_POINTS`].
    pub path: Vec<[f64; 3]>,
    pub residuals: Vec<FixResidual>,
    pub residual_rms: ResidualRms,
    /// How the normalised residuals spread against N(0, 1).
    pub normalised_spread: crate::diagnosis::NormalisedSpread,
    pub segments: Vec<SegmentBias>,
    /// Global parameters: effect id, name, value, unit (segment biases are in `segments`).
    pub params: Vec<(String, String, f64, String)>,
    pub n_params: usize,
    pub effects: Vec<String>,
    /// Physical limits the current parameters break (see `limits`).
    pub violations: Vec<String>,
    /// The noise settings estimated from the ride, once the fit has them.
    pub noise: Option<crate::optimisation::NoiseEstimate>,
    /// The GPS error law the fit's errors are measured under, in words.
    pub gps_noise: String,
    /// How sure the finished fit is (computed once the fit is done: 40
    /// posterior sweeps of the ride are too many for every iteration).
    pub sigma: Option<SigmaView>,
    /// The finished fit against the reference track, when one is loaded; its
    /// `series` keeps the largest error of every stretch of the ride that one
    /// of at most [`MAX_PATH_POINTS`] points stands for.
    pub reference: Option<crate::diagnosis::ReferenceComparison>,
}

/// The finished fit's uncertainties, aligned with what the snapshot draws.
#[derive(Clone, Debug, Default)]
pub struct SigmaView {
    /// Per path point: variance east, north (m^2) and their covariance.
    pub path: Vec<[f64; 3]>,
    /// Per segment: 1-sigma bias x, y, z (deg/s).
    pub segments: Vec<[f64; 3]>,
    /// Per entry of `Snapshot::params`: its 1-sigma, and whether that
    /// determines it (see `ParamInfo::within`).
    pub params: Vec<Option<(f64, bool)>>,
}

/// Worker -> UI.
#[derive(Debug)]
pub enum Update {
    Loading(String),
    Loaded(Box<RideView>),
    /// The ride could not be loaded; the previous one (if any) stays.
    /// `retry`: the same file read otherwise, each with a button's label
    /// (either side of a pause that refused it); `track_for`: the same file,
    /// to read again with a GPS track the user picks (a log without fixes).
    LoadFailed {
        message: String,
        retry: Vec<(String, RideSource)>,
        track_for: Option<RideSource>,
    },
    Snapshot(Box<Snapshot>),
    Running(bool),
    /// A setting was refused or an export failed.
    Error(String),
    Exported(String),
    DiagnosisProgress(String),
    Diagnosis(Box<Diagnosis>),
    /// A reference track was read and matched to the ride.
    ReferenceLoaded(Box<ReferenceView>),
    /// Held-out error of a finished fit, for the model history, or why
    /// there is none.
    HeldOut {
        model: String,
        params: usize,
        held_out: Result<HeldOutRms, String>,
    },
}

/// The UI's handle on the worker.
pub struct WorkerHandle {
    tx: Sender<Request>,
    pub rx: Receiver<Update>,
}

/// How much less (in nice steps) the app's background threads get of a
/// busy machine than the window's thread.
#[cfg(target_os = "linux")]
const BACKGROUND_NICE: libc::c_int = 10;

/// Lowers the calling thread to a background priority: the fit's thread,
/// its rayon pool (see [`super::run`]), validation and diagnosis. On a
/// 2-core machine the fit's two pool threads and the window's thread share
/// the cores, and without it the window's frames waited behind the fit's
/// linearisations; the scheduler now gives the window the core it asks for
/// and the fit the rest. On Linux a thread's nice value is its own
/// (`pthreads(7)`); elsewhere the threads keep the process's priority.
pub(crate) fn background_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: `gettid` and `setpriority` on the calling thread's own id read
    // and write no memory of ours; a failure leaves the priority as it was.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, BACKGROUND_NICE);
    }
}

impl WorkerHandle {
    /// Start the worker; `wake` is called after every update it sends (the UI's
    /// `request_repaint`).
    pub fn spawn(settings: FitSettings, wake: impl Fn() + Send + Sync + 'static) -> Self {
        let (tx, worker_rx) = std::sync::mpsc::channel();
        let (worker_tx, rx) = std::sync::mpsc::channel();
        let spawned = std::thread::Builder::new()
            .name("gyropath-worker".into())
            .spawn(move || {
                background_priority();
                let wake: Arc<dyn Fn() + Send + Sync> = Arc::new(wake);
                // A bug that panics must not leave a window that silently
                // stops answering: say so and start a fresh worker.
                loop {
                    let worker = Worker {
                        settings: settings.clone(),
                        ride: None,
                        running: false,
                        tx: worker_tx.clone(),
                        wake: wake.clone(),
                        sigma: None,
                    };
                    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        worker.run(&worker_rx)
                    }));
                    let Err(payload) = run else { break };
                    let what = payload
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| payload.downcast_ref::<String>().cloned())
                        .unwrap_or_default();
                    let _ = worker_tx.send(Update::Error(format!(
                        "the fit stopped on an internal error ({what}); open the ride again, \
                         and please report this with the ride"
                    )));
                    wake();
                }
            });
        if let Err(e) = spawned {
            // Without a worker nothing can be fitted; say so in the window.
            let (etx, erx) = std::sync::mpsc::channel();
            let _ = etx.send(Update::Error(format!(
                "cannot start the worker thread: {e}"
            )));
            return Self { tx, rx: erx };
        }
        Self { tx, rx }
    }

    /// Send a request; a worker that has gone away is ignored (the UI shows the last state).
    pub fn send(&self, request: Request) {
        let _ = self.tx.send(request);
    }
}

impl Drop for WorkerHandle {
    fn drop(&mut self) {
        self.send(Request::Shutdown);
    }
}

struct LoadedRide {
    source: RideSource,
    signals: Arc<Signals>,
    fit: Option<Reconstruction>,
    /// A reference track of this ride, matched to its rows.
    reference: Option<Arc<(ReferenceTrack, Matched)>>,
    /// Where it came from and what the checks said (for a report).
    origin: Origin,
}

struct Worker {
    settings: FitSettings,
    ride: Option<LoadedRide>,
    running: bool,
    tx: Sender<Update>,
    wake: Arc<dyn Fn() + Send + Sync>,
    /// The finished fit's uncertainty and the model and parameters it is of:
    /// 40 posterior sweeps are computed once per finished fit, not again for
    /// every snapshot sent while it stays finished (Step, an export, a diagnosis).
    sigma: Option<SigmaCache>,
}

struct SigmaCache {
    spec: crate::model::ModelSpec,
    theta: Vec<f64>,
    u: Option<crate::model::Uncertainty>,
}

impl Worker {
    fn send(&self, update: Update) {
        let _ = self.tx.send(update);
        (self.wake)();
    }

    fn run(mut self, rx: &Receiver<Request>) {
        let mut last_snapshot = Instant::now() - SNAPSHOT_INTERVAL;
        loop {
            let busy = self.running && self.fit().is_some_and(|f| !f.is_done());
            let request = if busy {
                match rx.try_recv() {
                    Ok(r) => Some(r),
                    Err(TryRecvError::Empty) => None,
                    Err(TryRecvError::Disconnected) => return,
                }
            } else {
                match rx.recv_timeout(Duration::from_secs(3600)) {
                    Ok(r) => Some(r),
                    Err(RecvTimeoutError::Timeout) => continue,
                    Err(RecvTimeoutError::Disconnected) => return,
                }
            };
            if let Some(request) = request {
                if matches!(request, Request::Shutdown) {
                    return;
                }
                self.handle(request);
                continue;
            }
            // One iteration of the running fit.
            let done = match self.fit_mut() {
                Some(fit) => {
                    fit.iterate();
                    fit.is_done()
                }
                None => true,
            };
            if done || last_snapshot.elapsed() >= SNAPSHOT_INTERVAL {
                self.send_snapshot();
                last_snapshot = Instant::now();
            }
            if done {
                self.running = false;
                self.send(Update::Running(false));
                self.validate_in_background();
            }
        }
    }

    fn fit(&self) -> Option<&Reconstruction> {
        self.ride.as_ref().and_then(|r| r.fit.as_ref())
    }

    fn fit_mut(&mut self) -> Option<&mut Reconstruction> {
        self.ride.as_mut().and_then(|r| r.fit.as_mut())
    }

    fn handle(&mut self, request: Request) {
        match request {
            Request::Load(source) => self.load(source),
            Request::Run => {
                self.running = self.fit().is_some();
                self.send(Update::Running(self.running));
            }
            Request::Pause => {
                self.running = false;
                self.send(Update::Running(false));
            }
            Request::Step => {
                self.running = false;
                if let Some(fit) = self.fit_mut() {
                    fit.iterate();
                    self.send_snapshot();
                }
                self.send(Update::Running(false));
            }
            Request::Reset => {
                self.running = false;
                self.restart_fit();
                self.send(Update::Running(false));
            }
            Request::Settings(settings) => self.apply_settings(*settings),
            Request::Export(kind, path, extras) => self.export(kind, &path, &extras),
            Request::Diagnose => self.diagnose_in_background(),
            Request::LoadReference(path) => self.load_reference(&path),
            Request::Shutdown => {}
        }
    }

    fn load(&mut self, source: RideSource) {
        self.send(Update::Loading(source.name()));
        let imported = match &source {
            RideSource::Path(p, options) => pipeline::open(p, options),
            RideSource::Bytes { name, bytes } => import::parse(bytes, name)
                .map(|log| import::checked(log, SourceKind::RideCsv, None, &MountChoice::Default)),
        };
        let (signals, origin) = match imported.map_err(PipelineError::from).and_then(|im| {
            let origin = Origin::of(&im);
            Ok((pipeline::signals(im)?, origin))
        }) {
            Ok(v) => v,
            Err(e) => {
                let retry = e
                    .pause_windows()
                    .map(|windows| {
                        windows
                            .iter()
                            .zip(["before the pause", "after the pause"])
                            .filter_map(|(&w, side)| {
                                let label = format!("Fit {side} ({:.0}-{:.0} s)", w.0, w.1);
                                Some((label, source.between(w)?))
                            })
                            .collect()
                    })
                    .unwrap_or_default();
                let track_for = match &source {
                    RideSource::Path(..) if e.needs_fixes() => Some(source.clone()),
                    _ => None,
                };
                self.send(Update::LoadFailed {
                    message: e.to_string(),
                    retry,
                    track_for,
                });
                return;
            }
        };
        self.running = false;
        self.send(Update::Loaded(Box::new(ride_view(
            &source,
            &signals,
            origin.clone(),
        ))));
        self.ride = Some(LoadedRide {
            source,
            signals,
            fit: None,
            reference: None,
            origin,
        });
        self.restart_fit();
        self.send(Update::Running(false));
    }

    /// Read a reference track, match it to the loaded ride and measure the fit against it.
    fn load_reference(&mut self, path: &std::path::Path) {
        let Some(ride) = self.ride.as_mut() else {
            self.send(Update::Error(
                "open a ride before its reference track".into(),
            ));
            return;
        };
        let loaded = pipeline::reference_for(path, &ride.signals).map_err(|e| e.to_string());
        let (track, matched) = match loaded {
            Ok(v) => v,
            Err(e) => {
                self.send(Update::Error(format!("reference not loaded: {e}")));
                return;
            }
        };
        let sig = &ride.signals;
        let stride = matched.at_rows.len().div_ceil(MAX_PATH_POINTS).max(1);
        let points = matched
            .at_rows
            .iter()
            .step_by(stride)
            .map(|(j, r)| [sig.t[*j], r.x, r.y])
            .collect();
        let view = ReferenceView {
            name: track.source.clone(),
            points,
            covered_s: matched.covered_s(sig),
            warnings: track.warnings.clone(),
        };
        ride.reference = Some(Arc::new((track, matched)));
        self.send(Update::ReferenceLoaded(Box::new(view)));
        self.send_snapshot();
    }

    /// A new fit of the loaded ride from its start guess.
    fn restart_fit(&mut self) {
        let Some(ride) = self.ride.as_mut() else {
            return;
        };
        match Reconstruction::new(ride.signals.clone(), self.settings.clone()) {
            Ok(fit) => {
                ride.fit = Some(fit);
                self.send_snapshot();
            }
            Err(e) => {
                ride.fit = None;
                self.send(Update::Error(e.to_string()));
            }
        }
    }

    fn apply_settings(&mut self, settings: FitSettings) {
        let previous = std::mem::replace(&mut self.settings, settings.clone());
        let Some(ride) = self.ride.as_mut() else {
            return;
        };
        let result = match ride.fit.as_mut() {
            Some(fit) => fit.apply_settings(settings).map_err(|e| e.to_string()),
            // The last settings could not be fitted: try again from the start.
            None => Reconstruction::new(ride.signals.clone(), settings)
                .map(|fit| ride.fit = Some(fit))
                .map_err(|e| e.to_string()),
        };
        match result {
            Ok(()) => self.send_snapshot(),
            Err(e) => {
                if ride.fit.is_some() {
                    self.settings = previous;
                }
                self.send(Update::Error(e));
            }
        }
    }

    /// A copy of the current fit's model and parameters for a background job
    /// (the fit itself stays with this thread and can go on).
    fn detached(&self) -> Option<(Model, Vec<f64>, FitSettings)> {
        let fit = self.fit()?;
        let m = fit.model();
        let model = Model::with_start(m.signals.clone(), m.spec.clone(), m.start.clone()).ok()?;
        Some((model, fit.params().to_vec(), fit.settings().clone()))
    }

    /// Held-out error of the finished fit, for the model history.
    fn validate_in_background(&self) {
        let Some((model, theta, settings)) = self.detached() else {
            return;
        };
        let tx = self.tx.clone();
        let wake = self.wake_handle();
        std::thread::spawn(move || {
            background_priority();
            let held_out = held_out_rms(&model, &theta, &settings, &Folds::default())
                .map_err(|e| e.to_string());
            let _ = tx.send(Update::HeldOut {
                model: model.effect_ids().join(", "),
                params: model.n_params(),
                held_out,
            });
            wake();
        });
    }

    fn diagnose_in_background(&self) {
        let Some((model, theta, settings)) = self.detached() else {
            self.send(Update::Error(
                "nothing to diagnose: no ride is fitted".into(),
            ));
            return;
        };
        // With a reference track loaded, every candidate is also measured
        // against it, as `diagnose --reference` does.
        let reference = self.ride.as_ref().and_then(|r| r.reference.clone());
        let tx = self.tx.clone();
        let wake = self.wake_handle();
        self.send(Update::DiagnosisProgress("starting".into()));
        std::thread::spawn(move || {
            background_priority();
            let progress_tx = std::sync::Mutex::new(tx.clone());
            let progress_wake = wake.clone();
            let progress = move |msg: &str| {
                if let Ok(t) = progress_tx.lock() {
                    let _ = t.send(Update::DiagnosisProgress(msg.to_string()));
                }
                progress_wake();
            };
            let against = reference
                .as_deref()
                .map(|(track, matched)| (track, matched));
            let update = match diagnose_fitted_against(
                &model,
                &theta,
                &settings,
                &Folds::default(),
                against,
                &progress,
            ) {
                Ok(d) => Update::Diagnosis(Box::new(d)),
                Err(e) => Update::Error(format!("diagnosis failed: {e}")),
            };
            let _ = tx.send(update);
            wake();
        });
    }

    fn wake_handle(&self) -> Arc<dyn Fn() + Send + Sync> {
        self.wake.clone()
    }

    fn send_snapshot(&mut self) {
        let Some(fit) = self.ride.as_ref().and_then(|r| r.fit.as_ref()) else {
            return;
        };
        let done = fit.phase() == Phase::Done;
        let cached = self
            .sigma
            .as_ref()
            .is_some_and(|c| c.theta == fit.params() && c.spec == fit.model().spec);
        if done && !cached {
            self.sigma = Some(SigmaCache {
                spec: fit.model().spec.clone(),
                theta: fit.params().to_vec(),
                u: finished_uncertainty(fit),
            });
        }
        let u = self
            .sigma
            .as_ref()
            .filter(|_| done)
            .and_then(|c| c.u.as_ref());
        let mut snap = snapshot(fit, u);
        if done && let Some(r) = self.ride.as_ref().and_then(|r| r.reference.as_ref()) {
            let mut c = reference::compare(fit.model(), fit.params(), &r.0, &r.1);
            c.series = peaks(&c.series, MAX_PATH_POINTS);
            snap.reference = Some(c);
        }
        self.send(Update::Snapshot(Box::new(snap)));
    }

    fn export(&self, kind: ExportKind, path: &std::path::Path, extras: &ReportExtras) {
        let (Some(ride), Some(fit)) = (self.ride.as_ref(), self.fit()) else {
            self.send(Update::Error("nothing to export: no ride is fitted".into()));
            return;
        };
        let protect = match &ride.source {
            RideSource::Path(p, _) => Some(p.as_path()),
            RideSource::Bytes { .. } => None,
        };
        let model = fit.model();
        let result = match kind {
            ExportKind::PathCsv => {
                let sigma = model.uncertainty(fit.params());
                write_atomically(path, protect, |w| {
                    write_path_csv(w, model, fit.params(), sigma.as_ref())
                })
            }
            ExportKind::PathGpx => {
                let traj = fit.trajectory();
                write_atomically(path, protect, |w| write_path_gpx(w, model, &traj))
            }
            ExportKind::PathTum => {
                write_atomically(path, protect, |w| write_path_tum(w, model, fit.params()))
            }
            ExportKind::ReportJson => {
                // The command line's report: sigmas, and the reference when one is loaded.
                let (report, _) = pipeline::report(fit, 0.0, false, ride.reference.as_deref());
                let report = report.with_segment_preference(fit);
                write_atomically(path, protect, |w| write_json(w, &report))
            }
            ExportKind::ReportHtml => {
                let contents = crate::report::Contents {
                    history: extras.history.clone(),
                    diagnosis: extras.diagnosis.as_ref(),
                    ..crate::report::Contents::of_fit(
                        fit,
                        Some(&ride.origin),
                        ride.reference.as_deref(),
                        None,
                        None,
                        format!(
                            "the gyropath app on {} (settings below)",
                            ride.source.name()
                        ),
                    )
                };
                match crate::report::write(path, protect, &contents) {
                    Ok(()) => Ok(()),
                    Err(crate::report::ReportError::Export(e)) => Err(e),
                    Err(e) => {
                        self.send(Update::Error(e.to_string()));
                        return;
                    }
                }
            }
        };
        match result {
            Ok(()) => self.send(Update::Exported(path.display().to_string())),
            Err(e) => self.send(Update::Error(e.to_string())),
        }
    }
}

fn ride_view(source: &RideSource, sig: &Signals, origin: Origin) -> RideView {
    let fixes: Vec<[f64; 3]> = sig.fixes.iter().map(|f| [f.t, f.en[0], f.en[1]]).collect();
    let t_first = sig.t[0];
    RideView {
        source: source.clone(),
        rows: sig.len(),
        rows_filled: sig.filled_rows(),
        sensor_turns: sig.sensor_turns.len(),
        duration_s: sig.duration(),
        t0: t_first,
        fixes,
        outages: crate::diagnosis::view::outages(sig),
        gyro_stops: sig.gyro_stops.clone(),
        offered_effects: crate::effects::offered(sig),
        warnings: sig.warnings.clone(),
        origin,
        attitude: sig.attitude.clone(),
        distance: sig.odometer.describe(),
        has_gnss_speed: sig.has_gnss_speed,
        frame: sig.frame.clone(),
    }
}

/// The uncertainty of a finished fit at the rows a snapshot draws.
pub fn finished_uncertainty(fit: &Reconstruction) -> Option<crate::model::Uncertainty> {
    let rows = decimated_rows(fit.model().signals.t.len(), MAX_PATH_POINTS);
    fit.model().uncertainty_at(fit.params(), Some(&rows))
}

/// Everything the UI draws about the current state of `fit`, with the
/// finished fit's uncertainty `u` (from [`finished_uncertainty`]) if there is one.
pub fn snapshot(fit: &Reconstruction, u: Option<&crate::model::Uncertainty>) -> Snapshot {
    let model = fit.model();
    let theta = fit.params();
    // One sweep, keeping only the rows drawn and the rows the residuals read:
    // never the whole trajectory (some 190 MB on a 6-hour ride, per snapshot).
    let view = FitView::of(model, theta, MAX_PATH_POINTS);
    let segments_len = view.segments.len();
    let mut param_sigmas = Vec::new();
    let mut params = Vec::new();
    for (e, effect) in model.effects().iter().enumerate() {
        if effect.segment_edges().is_some() {
            continue;
        }
        let infos = effect.params();
        for (i, (info, &v)) in infos.iter().zip(&theta[model.range(e)]).enumerate() {
            // Held parameters (roll and pitch of a planar model) are not results.
            if effect.fixed(i) {
                continue;
            }
            // A parameter held at the heavy-tailed fit's value (the gain's
            // check) shows that fit's sigma.
            let held = fit.noise().and_then(|n| n.held(&effect.id(), &info.name));
            let sigma = match held {
                Some(c) => c.robust_sigma,
                None => u.as_ref().and_then(|u| u.params[model.range(e).start + i]),
            };
            param_sigmas.push(
                u.as_ref()
                    .and(sigma)
                    .map(|s| (s * info.scale.abs(), info.determined(s))),
            );
            params.push((
                effect.id(),
                match held {
                    Some(_) => format!("{} (held)", info.name),
                    None => info.name.clone(),
                },
                v * info.scale,
                info.unit.to_string(),
            ));
        }
    }
    Snapshot {
        phase: fit.phase(),
        history: fit.history().to_vec(),
        stats: fit.stats(),
        path: view.path,
        residual_rms: ResidualRms::of(&view.residuals),
        normalised_spread: crate::diagnosis::NormalisedSpread::of(&view.residuals),
        residuals: view.residuals,
        segments: view.segments,
        params,
        n_params: model.n_params(),
        effects: model.effect_ids(),
        violations: crate::limits::check_on(model, theta, &view.sparse)
            .iter()
            .map(ToString::to_string)
            .collect(),
        noise: fit.noise().cloned(),
        gps_noise: model.spec.gps_noise_text(),
        sigma: u.map(|u| SigmaView {
            path: u.path.iter().map(|v| [v[0], v[1], v[3]]).collect(),
            segments: segment_sigmas(model, u, segments_len),
            params: param_sigmas,
        }),
        reference: None,
    }
}

/// 1-sigma of each segment bias (deg/s), if the model's segments are the snapshot's `n`.
fn segment_sigmas(
    model: &crate::model::Model,
    u: &crate::model::Uncertainty,
    n: usize,
) -> Vec<[f64; 3]> {
    let sigmas = crate::diagnosis::segment_sigmas(model, &u.params);
    if sigmas.len() == n {
        sigmas
    } else {
        Vec::new()
    }
}
