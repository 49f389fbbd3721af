//! The app rendered to pixels (egui_kittest on wgpu; Mesa's lavapipe runs it
//! on the CPU, no display or GPU needed): what the uncertainty adds to the
//! picture is drawn, not only computed.

use std::time::{Duration, Instant};

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use gyropath::app::map_tiles::{MapBackground, Status, TileServer as MapServer};
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
fn the_path_band_and_the_bias_band_are_drawn() {
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
    // Map (the middle column, above the model history): the 95 % band along the path.
    let map = changed(&with, &without, 0.29..0.63, 0.05..0.75);
    // Bias plot (the right column, between the cost and the residual plots):
    // the +-1 sigma band about each axis.
    let plots = changed(&with, &without, 0.65..1.0, 0.32..0.52);
    eprintln!("pixels changed: map {map}, bias plot {plots}");
    assert!(map > 1000, "path band: {map} pixels changed");
    assert!(plots > 1000, "bias band: {plots} pixels changed");
}

/// A tile server on a free local port: every request gets one magenta
/// 256-pixel PNG tile, cacheable for a day, and is recorded (path and
/// User-Agent). Tests never reach the network.
struct TileServer {
    url: String,
    requests: std::sync::Arc<std::sync::Mutex<Vec<(String, String)>>>,
}

impl TileServer {
    fn start() -> Self {
        use std::io::{Read, Write};
        let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("addr").port();
        let mut png = Vec::new();
        image::RgbaImage::from_pixel(256, 256, image::Rgba([255, 0, 255, 255]))
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .expect("png");
        let requests = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log = requests.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let (png, log) = (png.clone(), log.clone());
                std::thread::spawn(move || {
                    let mut stream = stream;
                    let mut head = Vec::new();
                    let mut byte = [0u8; 1];
                    while !head.ends_with(b"\r\n\r\n") && stream.read(&mut byte).unwrap_or(0) == 1 {
                        head.push(byte[0]);
                    }
                    let head = String::from_utf8_lossy(&head).to_string();
                    let path = head.split_whitespace().nth(1).unwrap_or("").to_string();
                    let agent = head
                        .lines()
                        .find_map(|l| {
                            l.strip_prefix("user-agent: ")
                                .or(l.strip_prefix("User-Agent: "))
                        })
                        .unwrap_or("")
                        .to_string();
                    log.lock().expect("log").push((path, agent));
                    let header = format!(
                        "HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Length: {}\r\n\
                         Cache-Control: public, max-age=86400\r\nConnection: close\r\n\r\n",
                        png.len()
                    );
                    let _ = stream.write_all(header.as_bytes());
                    let _ = stream.write_all(&png);
                });
            }
        });
        Self {
            url: format!("http://127.0.0.1:{port}/{{z}}/{{x}}/{{y}}.png"),
            requests,
        }
    }

    fn requests(&self) -> Vec<(String, String)> {
        self.requests.lock().expect("log").clone()
    }
}

/// The sample ride's app with a tile background from `server`, cached in `cache`.
fn app_with_tiles(url: &str, cache: &std::path::Path) -> Harness<'static, GyropathApp> {
    let settings = AppSettings {
        auto_run: false,
        ..AppSettings::default()
    };
    let mut app = GyropathApp::new(settings, sample_ride(), || {});
    app.map_background = Some(MapBackground::new(MapServer {
        url: url.to_string(),
        cache: Some(cache.to_path_buf()),
    }));
    Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut GyropathApp| app.ui(ui), app)
}

/// Step until the map background's status is `want`.
fn step_until_tiles(h: &mut Harness<'static, GyropathApp>, want: Status) {
    let start = Instant::now();
    loop {
        h.step();
        let status = h.state().map_background.as_ref().map(|b| b.status());
        if h.state().ride.is_some() && status == Some(want) {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "map tiles: {status:?}, waited for {want:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Settle what the frame shows. Under load the tile fetcher may still ask
    // for repaints past the harness's step limit (it did on CI: "would have
    // settled after 6 steps"); the status waited for is already there.
    h.run_ok();
}

/// Map pixels (the middle column above the model history) that are the tile's
/// magenta, dimmed by the map's tint: red and blue alike and well above green.
fn magenta_pixels(img: &image::RgbaImage) -> usize {
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    img.enumerate_pixels()
        .filter(|(x, y, _)| {
            (0.29..0.63).contains(&(f64::from(*x) / w))
                && (0.05..0.75).contains(&(f64::from(*y) / h))
        })
        .filter(|(_, _, p)| {
            let [r, g, b, _] = p.0;
            r > 60 && (i16::from(r) - i16::from(b)).abs() < 12 && i16::from(r) - i16::from(g) > 50
        })
        .count()
}

#[test]
fn map_tiles_are_fetched_drawn_under_the_ride_and_cached_on_disk() {
    let server = TileServer::start();
    let cache = tempfile::tempdir().expect("tempdir");
    let mut h = app_with_tiles(&server.url, cache.path());
    step_until_tiles(&mut h, Status::Shown);
    // Let the rest of the view's tiles arrive.
    for _ in 0..50 {
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    h.run();
    let img = h.render().expect("render");
    img.save(std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("app_with_tiles.png"))
        .expect("save");
    let map_px = 0.34 * 1280.0 * 0.70 * 800.0;
    let magenta = magenta_pixels(&img);
    eprintln!("magenta map pixels: {magenta} of {map_px:.0}");
    assert!(
        magenta as f64 > 0.3 * map_px,
        "tiles cover {magenta} pixels"
    );
    // Requests are slippy-map tiles at a street-level zoom, and say who asks.
    let requests = server.requests();
    assert!(!requests.is_empty());
    for (path, agent) in &requests {
        let parts: Vec<u32> = path
            .trim_start_matches('/')
            .trim_end_matches(".png")
            .split('/')
            .map(|p| p.parse().expect("number"))
            .collect();
        assert_eq!(parts.len(), 3, "{path}");
        assert!((10..=19).contains(&parts[0]), "zoom of {path}");
        assert!(agent.starts_with("gyropath/"), "user agent {agent:?}");
    }
    // The tiles were written to the disk cache: a new app on the same cache
    // draws them without asking the server again.
    assert!(
        std::fs::read_dir(cache.path())
            .expect("cache")
            .next()
            .is_some()
    );
    let asked = requests.len();
    drop(h);
    let mut again = app_with_tiles(&server.url, cache.path());
    step_until_tiles(&mut again, Status::Shown);
    for _ in 0..20 {
        again.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let after = server.requests().len();
    assert!(
        after <= asked,
        "{asked} requests, then {after} more with a warm cache"
    );
}

#[test]
fn without_a_tile_server_the_map_quietly_goes_without() {
    // A port nobody listens on: every fetch fails, as offline.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind")
        .local_addr()
        .expect("addr")
        .port();
    let cache = tempfile::tempdir().expect("tempdir");
    let url = format!("http://127.0.0.1:{port}/{{z}}/{{x}}/{{y}}.png");
    let mut h = app_with_tiles(&url, cache.path());
    step_until_tiles(&mut h, Status::Unavailable);
    let img = h.render().expect("render");
    // (A few antialiased pixels of the path's colours may pass for magenta.)
    let magenta = magenta_pixels(&img);
    assert!(magenta < 200, "{magenta} magenta pixels with no tiles");
    // The map itself is still there: the fixes' points are drawn.
    assert!(h.state().ride.as_ref().is_some_and(|r| !r.fixes.is_empty()));
}

#[test]
fn the_reference_track_is_drawn_on_the_map_and_its_error_in_the_residual_plot() {
    let drive = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/real/smartloc-berlin-potsdamer-platz");
    let app = GyropathApp::new(
        AppSettings::default(),
        gyropath::app::worker::RideSource::file(drive.join("ride.csv")),
        || {},
    );
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut GyropathApp| app.ui(ui), app);
    let wait = |h: &mut Harness<'_, GyropathApp>, done: &dyn Fn(&GyropathApp) -> bool| {
        let start = Instant::now();
        while !done(h.state()) {
            assert!(
                start.elapsed() < Duration::from_secs(180),
                "timed out: {:?}",
                h.state().error
            );
            h.step();
            std::thread::sleep(Duration::from_millis(20));
        }
        h.run();
    };
    wait(&mut h, &|a| {
        a.snapshot.as_ref().is_some_and(|s| s.sigma.is_some())
    });
    let without = h.render().expect("render");
    h.state_mut().apply(gyropath::app::Command::OpenReference(
        drive.join("truth.csv"),
    ));
    wait(&mut h, &|a| {
        a.snapshot.as_ref().is_some_and(|s| s.reference.is_some())
    });
    let with = h.render().expect("render");
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("berlin-reference.png");
    with.save(&out).expect("png");
    eprintln!("rendered {}", out.display());
    // The map (left half, below the menu) gains the reference track; the
    // residual plot (right half, bottom third of the plots) its distance.
    let map = changed(&without, &with, 0.25..0.5, 0.1..0.7);
    let plots = changed(&without, &with, 0.5..1.0, 0.45..0.7);
    assert!(map > 300, "{map} map pixels changed");
    assert!(plots > 100, "{plots} residual-plot pixels changed");
    // Diagnose with the reference loaded: a "to ref" column, each candidate
    // fitted as Fit fits it (Berlin: none nearer than the model's 6.28 m).
    h.state_mut().apply(gyropath::app::Command::Diagnose);
    wait(&mut h, &|a| a.diagnosis.is_some() && a.diagnosing.is_none());
    let diagnosed = h.render().expect("render");
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("berlin-diagnosis.png");
    diagnosed.save(&out).expect("png");
    eprintln!("rendered {}", out.display());
    assert!(h.query_all_by_label("to ref").count() >= 1);
    let d = h.state().diagnosis.clone().expect("diagnosis");
    let model = d
        .reference
        .as_ref()
        .expect("the model against the reference");
    assert!(
        d.ranking
            .iter()
            .filter_map(|c| c.reference.as_ref())
            .all(|r| r.horizontal.rms_m > model.horizontal.rms_m - 0.05),
        "{:?}",
        d.ranking
            .iter()
            .map(|c| (
                c.effect.clone(),
                c.reference.as_ref().map(|r| r.horizontal.rms_m)
            ))
            .collect::<Vec<_>>()
    );
}

#[test]
fn explain_draws_its_steps_in_the_diagnosis_panel() {
    let app = GyropathApp::new(AppSettings::default(), sample_ride(), || {});
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut GyropathApp| app.ui(ui), app);
    let ride = gyropath::app::examples::EXAMPLES
        .iter()
        .find(|e| e.label.contains("GPS lag"))
        .and_then(|e| e.file())
        .expect("the GPS lag example");
    h.state_mut().apply(gyropath::app::Command::Open(
        gyropath::app::worker::RideSource::file(ride),
    ));
    let start = Instant::now();
    let mut explained = false;
    while start.elapsed() < Duration::from_secs(600) {
        h.step();
        let a = h.state();
        if !explained
            && a.ride
                .as_ref()
                .is_some_and(|r| r.source.name().contains("hidden-gps-lag"))
            && a.snapshot.as_ref().is_some_and(|s| s.sigma.is_some())
        {
            h.state_mut().apply(gyropath::app::Command::Explain);
            explained = true;
        } else if explained
            && a.explaining.is_none()
            && a.snapshot.as_ref().is_some_and(|s| s.sigma.is_some())
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    h.run();
    let image = h.render().expect("render");
    image
        .save(std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("app_explained.png"))
        .expect("save");
    let log = &h.state().explain_log;
    assert!(
        log.iter().any(|l| l.text.starts_with("added gps_lag")),
        "{log:?}"
    );
}
