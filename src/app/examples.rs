//! File > Examples: rides that show what gyropath is for, each with one line
//! on what it shows. The bundled sample has nothing missing, so Diagnose
//! finds nothing there; these have something to find.

use std::path::PathBuf;

use super::Command;
use super::worker::RideSource;

/// An example: menu label, path from the project folder, what it shows.
pub struct Example {
    pub label: &'static str,
    pub path: &'static str,
    pub shows: &'static str,
}

pub const EXAMPLES: [Example; 5] = [
    Example {
        label: "GPS lag (simulated bicycle)",
        path: "data/hidden-gps-lag.csv",
        shows: "Fixes arrive 0.71 s late: Diagnose ranks gps_lag first; add it and watch the held-out error fall.",
    },
    Example {
        label: "Gyro scale errors (simulated bicycle)",
        path: "data/hidden-gyro-scale.csv",
        shows: "The gyro reads 3-4 % off on each axis: Diagnose finds gyro_scale.",
    },
    Example {
        label: "City GPS (simulated bicycle)",
        path: "data/city-gps.csv",
        shows: "Street canyons: fixes pulled aside and a 70 m jump for 25 s. Diagnose ranks gps_outliers first; add it and the path stops bending towards the jumps.",
    },
    Example {
        label: "A real car minute (comma2k19)",
        path: "data/comma2k19-example1/ride.csv",
        shows: "An uncalibrated phone gyro with a -3.9 deg/s bias on I-280; Diagnose finds a 0.1 s GPS lag.",
    },
    Example {
        label: "A real robot (ROS 1 bag, Clearpath Husky)",
        path: "../shared/real/robot_localization-test1/test1.bag",
        shows: "A skid-steer robot logged in its own axes: the checks find the mounting, and it is fitted level (planar).",
    },
];

impl Example {
    /// Where the example is on this machine, if it is there.
    pub fn file(&self) -> Option<PathBuf> {
        let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(self.path);
        p.exists().then_some(p)
    }
}

/// The Examples menu: one entry per example, its line as the hover text.
pub fn examples_menu_ui(ui: &mut egui::Ui, commands: &mut Vec<Command>) {
    for ex in &EXAMPLES {
        let file = ex.file();
        let button = ui
            .add_enabled(file.is_some(), egui::Button::new(ex.label))
            .on_hover_text(ex.shows)
            .on_disabled_hover_text(format!("{} is not on this machine", ex.path));
        if let (true, Some(p)) = (button.clicked(), file) {
            commands.push(Command::Open(RideSource::file(p)));
            ui.close();
        }
    }
}
