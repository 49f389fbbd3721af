//! The Source panel: what the ride was read from (kind, bag topics, the
//! mounting applied) and what the checks said of its axes, units and datum.
//! Choosing another topic or mounting reloads the ride with it; the panel
//! itself holds no state and computes nothing.

use crate::import::timeline::Role;
use crate::import::{DistanceChoice, ImportOptions, Level, MountChoice, TopicChoice};

use super::Command;
use super::worker::{RideSource, RideView};

/// Draw the Source panel for `ride`, pushing a reload when the user changes a choice.
pub fn source_ui(ui: &mut egui::Ui, ride: &RideView, commands: &mut Vec<Command>) {
    let origin = &ride.origin;
    ui.heading("Source");
    ui.label(format!(
        "{} ({} rows{}, {:.0} s, {} fixes)",
        origin.kind.map_or("ride-log CSV", |k| k.label()),
        ride.rows,
        crate::log_gaps::filled_phrase(ride.rows_filled),
        ride.duration_s,
        ride.fixes.len()
    ));
    let RideSource::Path(path, options) = &ride.source else {
        ui.label(format!("attitude: {}", ride.attitude.describe()));
        ui.label(format!("distance: {}", ride.distance));
        checks_ui(ui, ride);
        return;
    };
    if let Some(topics) = &origin.topics {
        egui::Grid::new("topics").num_columns(2).show(ui, |ui| {
            for (role, label, chosen) in [
                (Role::Imu, "IMU", &topics.imu),
                (Role::Odom, "odometer", &topics.odom),
                (Role::Fix, "GPS", &topics.fix),
            ] {
                let name = ui.label(label).id;
                let mut picked = chosen.clone();
                egui::ComboBox::from_id_salt(label)
                    .selected_text(chosen.as_str())
                    .show_ui(ui, |ui| {
                        for t in topics.candidates(role) {
                            ui.selectable_value(
                                &mut picked,
                                t.name.clone(),
                                format!("{} ({}, {} msgs)", t.name, t.type_name, t.messages),
                            );
                        }
                    })
                    .response
                    .labelled_by(name);
                if picked != *chosen {
                    let mut choice = TopicChoice {
                        imu: Some(topics.imu.clone()),
                        odom: Some(topics.odom.clone()),
                        fix: Some(topics.fix.clone()),
                    };
                    match role {
                        Role::Imu => choice.imu = Some(picked),
                        Role::Odom => choice.odom = Some(picked),
                        Role::Fix => choice.fix = Some(picked),
                    }
                    commands.push(reload(path, options, |o| o.topics = choice));
                }
                ui.end_row();
            }
        });
    }
    ui.horizontal(|ui| {
        let name = ui.label("mounting").id;
        let applied = origin.mount.clone().unwrap_or_else(|| "as logged".into());
        let mut picked: Option<MountChoice> = None;
        egui::ComboBox::from_id_salt("mount")
            .selected_text(applied.as_str())
            .show_ui(ui, |ui| {
                if ui
                    .selectable_label(origin.mount.is_none(), "as logged")
                    .clicked()
                {
                    picked = Some(MountChoice::AsLogged);
                }
                if let Some(rec) = &origin.recommended {
                    let label = format!("auto: {rec} (what the checks recommend)");
                    let on = origin.mount.as_deref() == Some(rec.as_str());
                    if ui.selectable_label(on, label).clicked() {
                        picked = Some(MountChoice::Auto);
                    }
                }
            })
            .response
            .labelled_by(name);
        if let Some(m) = picked.filter(|m| *m != options.mount) {
            commands.push(reload(path, options, |o| o.mount = m));
        }
    });
    ui.horizontal(|ui| {
        let name = ui.label("attitude").id;
        let current = options.attitude.clone().unwrap_or_else(|| "auto".into());
        let mut picked = current.clone();
        egui::ComboBox::from_id_salt("attitude")
            .selected_text(if ride.attitude.is_planar() {
                "planar"
            } else {
                "3D"
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut picked, "auto".to_string(), "auto (from the data)");
                ui.selectable_value(&mut picked, "3d".to_string(), "3D");
                ui.selectable_value(&mut picked, "planar".to_string(), "planar (heading only)");
            })
            .response
            .labelled_by(name);
        if picked != current {
            commands.push(reload(path, options, |o| {
                o.attitude = (picked != "auto").then_some(picked);
            }));
        }
    })
    .response
    .on_hover_text(ride.attitude.describe());
    ui.small(ride.attitude.describe());
    if ride.has_gnss_speed && options.wheel.is_none() {
        distance_ui(ui, ride, path, options, commands);
    } else {
        ui.label(format!("distance: {}", ride.distance));
    }
    wheel_ui(ui, path, options, commands);
    gps_track_ui(ui, path, options, commands);
    if let Some((start, end)) = options.between {
        ui.horizontal(|ui| {
            ui.label(format!("rows from {start:.2} to {end:.2} s of the log"));
            if ui
                .button("Whole log")
                .on_hover_text("Read every row of the log again (a pause in it refuses the whole)")
                .clicked()
            {
                commands.push(reload(path, options, |o| o.between = None));
            }
        });
    }
    checks_ui(ui, ride);
}

/// A bike computer's wheel distance (a Garmin FIT activity's, matched by
/// UTC) as the odometer of a log without a wheel sensor: pick one, or take
/// the log's own distance again.
fn wheel_ui(
    ui: &mut egui::Ui,
    path: &std::path::Path,
    options: &ImportOptions,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| match &options.wheel {
        Some(fit) => {
            ui.label(format!(
                "wheel: {}",
                fit.file_name()
                    .map_or_else(|| fit.display().to_string(), |n| n.to_string_lossy().into_owned())
            ));
            if ui
                .button("Remove")
                .on_hover_text("Take the distance from the log itself again")
                .clicked()
            {
                commands.push(reload(path, options, |o| o.wheel = None));
            }
        }
        None => {
            if ui
                .button("Wheel distance (FIT)...")
                .on_hover_text(
                    "A bike computer's wheel-speed sensor (its Garmin FIT activity) as the odometer, matched by UTC; the ride is cut to the time it covers",
                )
                .clicked()
            {
                commands.push(Command::PickWheel);
            }
        }
    });
}

/// The fixes of a GPS track of the same ride (`--gps-track`): the track
/// in use, or a button to pick one (replacing the log's own fixes).
fn gps_track_ui(
    ui: &mut egui::Ui,
    path: &std::path::Path,
    options: &ImportOptions,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| match &options.gps_track {
        Some(track) => {
            ui.label(format!(
                "GPS: {}",
                track
                    .file_name()
                    .map_or_else(|| track.display().to_string(), |n| n.to_string_lossy().into_owned())
            ));
            if ui
                .button("Remove")
                .on_hover_text("Take the fixes from the log itself again")
                .clicked()
            {
                commands.push(reload(path, options, |o| o.gps_track = None));
            }
        }
        None => {
            if ui
                .button("GPS track...")
                .on_hover_text(
                    "The fixes of a GPS track of the same ride (a watch's or bike computer's GPX or FIT, a phone's NMEA) in place of the log's own, matched by UTC or by the vehicle's turns",
                )
                .clicked()
            {
                commands.push(Command::PickGpsTrack(RideSource::Path(
                    path.to_path_buf(),
                    Box::new(options.clone()),
                )));
            }
        }
    });
}

/// Where the distance comes from, for a log that has the GNSS speed: its
/// odometer (when it has one) or the GNSS speed; choosing reloads the ride.
fn distance_ui(
    ui: &mut egui::Ui,
    ride: &RideView,
    path: &std::path::Path,
    options: &ImportOptions,
    commands: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        let name = ui.label("distance").id;
        let mut picked = options.distance;
        egui::ComboBox::from_id_salt("distance")
            .selected_text(match options.distance {
                DistanceChoice::Auto => "auto",
                DistanceChoice::Gnss => "GNSS speed",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(
                    &mut picked,
                    DistanceChoice::Auto,
                    "auto (the odometer when logged)",
                );
                ui.selectable_value(&mut picked, DistanceChoice::Gnss, "GNSS speed");
            })
            .response
            .labelled_by(name);
        if picked != options.distance {
            commands.push(reload(path, options, |o| o.distance = picked));
        }
    })
    .response
    .on_hover_text(&ride.distance);
    ui.small(format!("from {}", ride.distance));
}

/// The checks' verdicts, the worst first, coloured by how much they matter.
fn checks_ui(ui: &mut egui::Ui, ride: &RideView) {
    let mut verdicts: Vec<_> = ride.origin.verdicts.iter().collect();
    verdicts.sort_by_key(|v| std::cmp::Reverse(v.level));
    let worst = verdicts.first().map_or(Level::Ok, |v| v.level);
    let title = format!("Checks ({})", worst.label());
    egui::CollapsingHeader::new(title)
        .default_open(worst >= Level::Warning)
        .show(ui, |ui| {
            for v in verdicts {
                let colour = match v.level {
                    Level::Ok => egui::Color32::from_rgb(60, 160, 60),
                    Level::Info => ui.visuals().text_color(),
                    Level::Warning => egui::Color32::from_rgb(200, 150, 0),
                    Level::Problem => egui::Color32::from_rgb(210, 60, 60),
                };
                ui.colored_label(colour, v.as_warning());
            }
        });
}

fn reload(
    path: &std::path::Path,
    options: &ImportOptions,
    change: impl FnOnce(&mut ImportOptions),
) -> Command {
    let mut o = options.clone();
    change(&mut o);
    Command::Open(RideSource::Path(path.to_path_buf(), Box::new(o)))
}
