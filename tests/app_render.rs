//! The app rendered to pixels (egui_kittest on wgpu; Mesa's lavapipe runs it
//! on the CPU, no display or GPU needed): what the uncertainty adds to the
//! picture is drawn, not only computed.

use std::time::{Duration, Instant};

use egui_kittest::Harness;
use gyropath::app::{AppSettings, GyropathApp, sample_ride};

/// Pixels that differ between two renders of the same size, counted in the
/// box `x` by `y` (fractions of the width and height).
fn changed(
    a: &image::RgbaImage,
    b: &image::RgbaImage,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> usize {
    let (w, h) = (f64::from(a.width()), f64::from(a.height()));
    a.enumerate_pixels()
        .filter(|(px, py, _)| {
            x.contains(&(f64::from(*px) / w)) && y.contains(&(f64::from(*py) / h))
        })
        .filter(|(x, y, p)| {
            let q = b.get_pixel(*x, *y);
            p.0.iter()
                .zip(q.0)
                .any(|(u, v)| (i16::from(*u) - i16::from(v)).abs() > 24)
        })
        .count()
}

#[test]
fn the_sigma_band_and_ellipses_are_drawn() {
    let app = GyropathApp::new(AppSettings::default(), sample_ride(), || {});
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut GyropathApp| app.ui(ui), app);
    // The sample runs on load; its finished fit carries its sigmas.
    let start = Instant::now();
    while h
        .state()
        .snapshot
        .as_ref()
        .is_none_or(|s| s.sigma.is_none())
    {
        assert!(
            start.elapsed() < Duration::from_secs(180),
            "the fit did not finish"
        );
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    h.run();
    let with = h
        .render()
        .expect("render (lavapipe: apt-get install mesa-vulkan-drivers)");
    // The same frame without the uncertainty.
    if let Some(s) = h.state_mut().snapshot.as_mut() {
        s.sigma = None;
    }
    h.run();
    let without = h.render().expect("render");
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    with.save(dir.join("app_with_sigma.png")).expect("save");
    without
        .save(dir.join("app_without_sigma.png"))
        .expect("save");
    // Map (the middle column, above the model history): the 95 % ellipses along the path.
    let map = changed(&with, &without, 0.29..0.63, 0.05..0.75);
    // Bias plot (the right column, between the cost and the residual plots):
    // the +-1 sigma band about each axis.
    let plots = changed(&with, &without, 0.65..1.0, 0.32..0.52);
    eprintln!("pixels changed: map {map}, bias plot {plots}");
    assert!(map > 1000, "ellipses: {map} pixels changed");
    assert!(plots > 1000, "bias band: {plots} pixels changed");
}
