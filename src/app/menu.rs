//! The menu bar (File: open, examples, recent, export) and files dropped on the window.

use super::worker::{ExportKind, RideSource};
use super::{Command, GyropathApp, examples, sample_ride};

impl GyropathApp {
    pub(super) fn dropped_files(&mut self, ui: &egui::Ui, commands: &mut Vec<Command>) {
        let dropped = ui.ctx().input(|i| i.raw.dropped_files.clone());
        if let Some(f) = dropped.into_iter().next() {
            let path = f.path().to_path_buf();
            // A track without a gyro (a CSV of times and positions, GPX,
            // FIT, NMEA) is the GPS track of a ride refused for having no
            // fix, else a reference track of the ride already open.
            let track_for = self
                .track_for
                .as_ref()
                .filter(|_| is_reference_track(&path))
                .and_then(|source| source.with_gps_track(Some(path.clone())));
            if let Some(source) = track_for {
                commands.push(Command::Open(source));
            } else if self.ride.is_some() && is_reference_track(&path) {
                commands.push(Command::OpenReference(path));
            } else {
                commands.push(Command::Open(RideSource::file(path)));
            }
        }
    }

    pub(super) fn menu_ui(&mut self, ui: &mut egui::Ui, commands: &mut Vec<Command>) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open ride or bag...").clicked() {
                    commands.push(Command::PickRide);
                }
                if ui
                    .button("Open folder...")
                    .on_hover_text("A ROS 2 bag (rosbag2 folder) or a comma2k19 segment")
                    .clicked()
                {
                    commands.push(Command::PickBagFolder);
                }
                if ui.button("Open the sample ride").clicked() {
                    commands.push(Command::Open(sample_ride()));
                }
                if ui
                    .add_enabled(
                        self.ride.is_some(),
                        egui::Button::new("Open reference track..."),
                    )
                    .on_hover_text(
                        "A better track of this drive (RTK, an INS): t_s,lat_deg,lon_deg[,alt_m] CSV on the ride's clock; the fit is measured against it",
                    )
                    .clicked()
                {
                    commands.push(Command::PickReference);
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
                    ("Export path (TUM, for evo)...", ExportKind::PathTum),
                    ("Export fit report (JSON)...", ExportKind::ReportJson),
                    ("Save report (HTML)...", ExportKind::ReportHtml),
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
                        "{}: {:.1} min, {} rows{}, {} fixes",
                        r.source.name(),
                        r.duration_s / 60.0,
                        r.rows,
                        crate::log_gaps::filled_phrase(r.rows_filled),
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
                for (label, source) in &self.retry {
                    if ui.button(label).clicked() {
                        commands.push(Command::Open(source.clone()));
                    }
                }
                if let Some(source) = &self.track_for
                    && ui
                        .button("GPS track...")
                        .on_hover_text("The fixes of a GPS track of the same ride (a watch's or bike computer's GPX or FIT, a phone's NMEA), matched by UTC or by the vehicle's turns; or drop the track on the window")
                        .clicked()
                {
                    commands.push(Command::PickGpsTrack(source.clone()));
                }
                if ui.small_button("Dismiss").clicked() {
                    commands.push(Command::DismissError);
                }
            });
        }
    }
}

/// Whether `path` is a reference track: a CSV whose header (after `#`
/// comments) names `t_s`, `lat_deg` and `lon_deg` but no gyro column.
fn is_reference_track(path: &std::path::Path) -> bool {
    use std::io::BufRead;
    // A comma2k19 segment's pose: its `global_pose` folder (the segment
    // itself is a ride).
    if path.is_dir() {
        return is_pose_folder(path);
    }
    // GNSS-only formats: never a ride, so a reference track.
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if matches!(ext.as_deref(), Some("gpx" | "fit" | "gga" | "nmea")) {
        return true;
    }
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let Some(Ok(header)) = std::io::BufReader::new(file)
        .lines()
        .find(|l| l.as_ref().map_or(true, |l| !l.starts_with('#')))
    else {
        return false;
    };
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    let has = |c: &str| columns.contains(&c);
    has("t_s") && has("lat_deg") && has("lon_deg") && !columns.iter().any(|c| c.ends_with("_dps"))
}

/// A `global_pose` folder of a comma2k19 segment, not the segment itself.
fn is_pose_folder(path: &std::path::Path) -> bool {
    crate::import::comma2k19::has_global_pose(path) && !crate::import::comma2k19::is_segment(path)
}
