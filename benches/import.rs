//! Import throughput on large bags (not a timed test: it prints figures).
//!
//! Writes a 1 GB ROS 2 bag (MCAP, zstd chunks, with the mcap writer) and a
//! 1 GB ROS 1 bag of a 30-minute recording: a 10 Hz camera (45 KB frames,
//! most of the bytes, as in real bags), a 200 Hz IMU, 50 Hz wheel odometry
//! and 5 Hz GPS. Each is then imported (read, joined, checked, mounted) in a
//! child process, which reports its time and peak memory (VmHWM), so the
//! figure is the reader's alone and not the writer's.
//!
//! `cargo bench --bench import` (add `-- 256` for a recording of 256 MB of
//! raw messages; the default, 1320, makes a 1 GB MCAP after compression)

use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

use gyropath::import::ros1::BagWriter;
use gyropath::import::ros2::McapWriter;
use gyropath::import::wire::Writer;
use gyropath::import::{self, ImportOptions};

/// Peak resident memory of this process (MB), from /proc.
fn peak_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// One message of the recording: topic, ROS 1 type, time, payload (ROS 1 and CDR).
type Emit<'a> = dyn FnMut(&str, &str, f64, &[u8], &[u8]) + 'a;

/// The recording, in time order, sized to about `target` bytes.
fn record(target: u64, emit: &mut Emit<'_>) {
    let frame = 45_000usize;
    // Camera bytes dominate: duration from the target size.
    let duration = (target as f64 / (frame as f64 * 10.0)).max(10.0);
    let mut noise = 0x9E37_79B9_7F4A_7C15u64;
    let mut image = vec![0u8; frame];
    let steps = (duration * 200.0) as usize;
    for i in 0..steps {
        let t = 1_700_000_000.0 + i as f64 / 200.0;
        let s = i as f64 / 200.0;
        let yaw = 0.2 * (0.05 * s).sin();
        let imu1 = Writer::ros1().imu(t, [0.01, 0.02, yaw], [0.1, 0.0, 9.81]);
        let imu2 = Writer::cdr().imu(t, [0.01, 0.02, yaw], [0.1, 0.0, 9.81]);
        emit("/imu/data", "sensor_msgs/Imu", t, &imu1, &imu2);
        if i % 4 == 0 {
            let v = 8.0 + (0.01 * s).sin();
            emit(
                "/odom",
                "nav_msgs/Odometry",
                t,
                &Writer::ros1().odometry(t, v),
                &Writer::cdr().odometry(t, v),
            );
        }
        if i % 40 == 0 {
            let (lat, lon) = (47.5 + 2e-5 * (0.05 * s).sin(), 19.0 + 1e-4 * s / 60.0);
            emit(
                "/fix",
                "sensor_msgs/NavSatFix",
                t,
                &Writer::ros1().fix(t, lat, lon, 4.0),
                &Writer::cdr().fix(t, lat, lon, 4.0),
            );
        }
        if i % 20 == 0 {
            for b in image.iter_mut() {
                noise ^= noise << 13;
                noise ^= noise >> 7;
                noise ^= noise << 17;
                *b = (noise >> 56) as u8 & 0x3f;
            }
            emit("/camera/image_raw", "sensor_msgs/Image", t, &image, &image);
        }
    }
}

fn write_mcap(path: &Path, target: u64) {
    let out = BufWriter::with_capacity(1 << 20, std::fs::File::create(path).expect("create"));
    let mut w = McapWriter::new(out, true).expect("mcap writer");
    record(target, &mut |topic, ty, t, _, cdr| {
        let ty2 = ty.replacen('/', "/msg/", 1);
        w.message(topic, &ty2, (t * 1e9) as u64, cdr)
            .expect("write");
    });
    w.finish().expect("finish");
}

fn write_bag(path: &Path, target: u64) {
    let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(path).expect("create"));
    let mut bag = BagWriter::new();
    record(target, &mut |topic, ty, t, ros1, _| {
        bag.message(topic, ty, t, ros1);
        if bag.bytes.len() > 1 << 22 {
            out.write_all(&bag.bytes).expect("write");
            bag.bytes.clear();
        }
    });
    out.write_all(&bag.bytes).expect("write");
    out.flush().expect("flush");
}

/// In the child: import `path` and print seconds, rows and peak memory.
fn read_child(path: &str) {
    let started = Instant::now();
    let im = import::open(Path::new(path), &ImportOptions::default()).expect("import");
    let secs = started.elapsed().as_secs_f64();
    println!(
        "{secs} {} {} {}",
        im.log.len(),
        im.log.fix_count(),
        peak_mb()
    );
}

/// The shared GoPro sample with `pad` bytes of zeros added at the end of its
/// video (`mdat`) box: a longer video of the same telemetry. The `moov`
/// box's chunk offsets point into the unchanged start of `mdat`, so the
/// file stays valid; the padding is a hole in a sparse file, so making a
/// 3 GB video takes no disk.
fn padded_camera(src: &Path, out: &Path, pad: u64) -> std::io::Result<()> {
    use std::io::{Seek, SeekFrom};
    let bytes = std::fs::read(src)?;
    // Top-level boxes: 32-bit size, type.
    let mut at = 0usize;
    let mut mdat = None;
    while at + 8 <= bytes.len() {
        let size = u32::from_be_bytes(bytes[at..at + 4].try_into().expect("4 bytes")) as usize;
        if &bytes[at + 4..at + 8] == b"mdat" {
            mdat = Some((at, size));
        }
        if size < 8 {
            break;
        }
        at += size;
    }
    let (start, size) = mdat.ok_or_else(|| std::io::Error::other("no mdat box"))?;
    let grown = u32::try_from(size as u64 + pad).map_err(std::io::Error::other)?;
    let mut f = std::fs::File::create(out)?;
    f.write_all(&bytes[..start])?;
    f.write_all(&grown.to_be_bytes())?;
    f.write_all(&bytes[start + 4..start + size])?;
    f.seek(SeekFrom::Current(pad as i64))?;
    f.write_all(&bytes[start + size..])?;
    Ok(())
}

/// The boxes directly inside `bytes[from..to]`: (start, size, type).
fn boxes(bytes: &[u8], from: usize, to: usize) -> Vec<(usize, usize, [u8; 4])> {
    let mut out = Vec::new();
    let mut at = from;
    while at + 8 <= to {
        let size = u32::from_be_bytes(bytes[at..at + 4].try_into().expect("4 bytes")) as usize;
        if size < 8 || at + size > to {
            break;
        }
        out.push((at, size, bytes[at + 4..at + 8].try_into().expect("4 bytes")));
        at += size;
    }
    out
}

/// The first box of type `kind` directly inside `parent`.
fn child(bytes: &[u8], parent: (usize, usize), kind: &[u8; 4]) -> Option<(usize, usize)> {
    boxes(bytes, parent.0 + 8, parent.0 + parent.1)
        .into_iter()
        .find(|b| &b.2 == kind)
        .map(|b| (b.0, b.1))
}

/// The shared GoPro sample with its telemetry `k` times as long: the
/// metadata (`gpmd`) track's sample table lists every telemetry sample `k`
/// times (the same bytes in `mdat`, read again), so the reader keeps `k`
/// times the rows from a file of the same size. What a longer recording's
/// telemetry costs to read, apart from the container's fixed costs (the
/// shared sample is 10 s). The `moov` box is the file's last, so growing it
/// moves no data that other offsets point to.
fn lengthened_camera(src: &Path, out: &Path, k: usize) -> std::io::Result<()> {
    let bad = |m: &str| std::io::Error::other(m.to_string());
    let f = std::fs::read(src)?;
    let moov = boxes(&f, 0, f.len())
        .into_iter()
        .find(|b| &b.2 == b"moov")
        .map(|b| (b.0, b.1))
        .ok_or_else(|| bad("no moov"))?;
    if moov.0 + moov.1 != f.len() {
        return Err(bad("moov is not the last box"));
    }
    let be = |at: usize| u32::from_be_bytes(f[at..at + 4].try_into().expect("4 bytes"));
    for (t0, t1, _) in boxes(&f, moov.0 + 8, moov.0 + moov.1)
        .into_iter()
        .filter(|b| &b.2 == b"trak")
    {
        let trak = (t0, t1);
        let path = child(&f, trak, b"mdia")
            .and_then(|mdia| Some((mdia, child(&f, mdia, b"minf")?)))
            .and_then(|(mdia, minf)| Some((mdia, minf, child(&f, minf, b"stbl")?)));
        let Some((mdia, minf, stbl)) = path else {
            continue;
        };
        let Some(stsd) = child(&f, stbl, b"stsd") else {
            continue;
        };
        if !f[stsd.0..stsd.0 + stsd.1].windows(4).any(|w| w == b"gpmd") {
            continue;
        }
        let mut body = Vec::new();
        for (at, size, kind) in boxes(&f, stbl.0 + 8, stbl.0 + stbl.1) {
            // Full boxes: size, type, version and flags, then the table.
            let table: Vec<u8> = match &kind {
                b"stts" | b"stco" => {
                    let n = be(at + 12) as usize;
                    let width = if &kind == b"stts" { 8 } else { 4 };
                    let entries = &f[at + 16..at + 16 + n * width];
                    let mut t = ((n * k) as u32).to_be_bytes().to_vec();
                    for _ in 0..k {
                        t.extend_from_slice(entries);
                    }
                    t
                }
                b"stsz" => {
                    let (fixed, n) = (be(at + 12), be(at + 16) as usize);
                    let mut t = fixed.to_be_bytes().to_vec();
                    t.extend_from_slice(&((n * k) as u32).to_be_bytes());
                    if fixed == 0 {
                        for _ in 0..k {
                            t.extend_from_slice(&f[at + 20..at + 20 + 4 * n]);
                        }
                    }
                    t
                }
                _ => {
                    body.extend_from_slice(&f[at..at + size]);
                    continue;
                }
            };
            body.extend_from_slice(&((12 + table.len()) as u32).to_be_bytes());
            body.extend_from_slice(&kind);
            body.extend_from_slice(&f[at + 8..at + 12]);
            body.extend_from_slice(&table);
        }
        let grow = 8 + body.len() - stbl.1;
        let mut out_bytes = f[..stbl.0].to_vec();
        out_bytes.extend_from_slice(&((8 + body.len()) as u32).to_be_bytes());
        out_bytes.extend_from_slice(b"stbl");
        out_bytes.extend_from_slice(&body);
        out_bytes.extend_from_slice(&f[stbl.0 + stbl.1..]);
        for (at, size) in [moov, trak, mdia, minf] {
            out_bytes[at..at + 4].copy_from_slice(&((size + grow) as u32).to_be_bytes());
        }
        return std::fs::write(out, out_bytes);
    }
    Err(bad("no gpmd track"))
}

/// Import `path` in a child process: seconds, rows, fixes, peak MB.
fn import_in_child(exe: &Path, path: &Path) -> Option<Vec<f64>> {
    let out = std::process::Command::new(exe)
        .args(["--read", &path.display().to_string()])
        .output()
        .expect("child");
    let text = String::from_utf8_lossy(&out.stdout);
    let f: Vec<f64> = text
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    if f.len() < 4 {
        eprintln!("child failed: {}", String::from_utf8_lossy(&out.stderr));
        return None;
    }
    Some(f)
}

/// The GoPro sample as it is and with 1 GB and 3 GB more video: the time
/// per kept row beside the bags', and peak memory against the video's size.
fn cameras(exe: &Path, dir: &Path) {
    let src =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/formats/gopro_gpmf/max-heromode.mp4");
    if !src.exists() {
        println!("(camera: {} not found)", src.display());
        return;
    }
    println!();
    println!("camera telemetry (GoPro MAX sample, 10 s; the video padded to a size)");
    println!(
        "{:<22} {:>9} {:>8} {:>9} {:>9} {:>8} {:>10}",
        "file", "size MB", "time s", "us/row", "rows", "fixes", "peak MB"
    );
    // The best of 5 runs: the reader's time is milliseconds.
    let best_of = |path: &Path| -> Option<Vec<f64>> {
        (0..5)
            .filter_map(|_| import_in_child(exe, path))
            .min_by(|a, b| a[0].total_cmp(&b[0]))
    };
    // The sample as it is, for the lengthened files below.
    let mut one = None;
    for pad_mb in [0u64, 1024, 3072] {
        let path = dir.join(format!("camera-{pad_mb}.mp4"));
        if let Err(e) = padded_camera(&src, &path, pad_mb << 20) {
            eprintln!("cannot write {}: {e}", path.display());
            continue;
        }
        let size = std::fs::metadata(&path).expect("size").len() as f64 / (1 << 20) as f64;
        let Some(best) = best_of(&path) else {
            continue;
        };
        if pad_mb == 0 {
            one = Some(best.clone());
        }
        println!(
            "{:<22} {size:>9.0} {:>8.4} {:>9.2} {:>9.0} {:>8.0} {:>10.0}",
            format!("GoPro MP4 +{pad_mb} MB"),
            best[0],
            best[0] / best[1] * 1e6,
            best[1],
            best[2],
            best[3]
        );
        let _ = std::fs::remove_file(&path);
    }
    // The telemetry k times as long: the time per row beyond the first
    // file's, apart from the container's fixed costs.
    let Some(one) = one else {
        return;
    };
    for k in [50usize, 200] {
        let path = dir.join(format!("camera-x{k}.mp4"));
        if let Err(e) = lengthened_camera(&src, &path, k) {
            eprintln!("cannot write {}: {e}", path.display());
            continue;
        }
        let size = std::fs::metadata(&path).expect("size").len() as f64 / (1 << 20) as f64;
        let Some(best) = best_of(&path) else {
            continue;
        };
        println!(
            "{:<22} {size:>9.0} {:>8.4} {:>9.2} {:>9.0} {:>8.0} {:>10.0}   beyond the 10 s file's: {:.2} us/row, {:.0} bytes/row",
            format!("GoPro telemetry x{k}"),
            best[0],
            best[0] / best[1] * 1e6,
            best[1],
            best[2],
            best[3],
            (best[0] - one[0]) / (best[1] - one[1]) * 1e6,
            (best[3] - one[3]) * (1u64 << 20) as f64 / (best[1] - one[1]),
        );
        let _ = std::fs::remove_file(&path);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--read") {
        read_child(&args[i + 1]);
        return;
    }
    let mb: u64 = args
        .iter()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(1320);
    let dir = tempfile::tempdir().expect("tempdir");
    let exe = std::env::current_exe().expect("exe");
    println!("import of a {mb} MB recording (camera 10 Hz, IMU 200 Hz, odometry 50 Hz, GPS 5 Hz)");
    println!(
        "{:<22} {:>9} {:>8} {:>9} {:>9} {:>8} {:>10}",
        "bag", "size MB", "time s", "MB/s", "rows", "fixes", "peak MB"
    );
    for (name, file, write) in [
        (
            "ROS 2 (MCAP, zstd)",
            "big.mcap",
            write_mcap as fn(&Path, u64),
        ),
        (
            "ROS 1 (uncompressed)",
            "big.bag",
            write_bag as fn(&Path, u64),
        ),
    ] {
        let path = dir.path().join(file);
        write(&path, mb << 20);
        let size = std::fs::metadata(&path).expect("size").len() as f64 / (1 << 20) as f64;
        // Warm the page cache the way a second import would find it.
        let _ = std::fs::read(&path).map(|b| b.len());
        let Some(f) = import_in_child(&exe, &path) else {
            continue;
        };
        println!(
            "{name:<22} {size:>9.0} {:>8.2} {:>9.0} {:>9.0} {:>8.0} {:>10.0} {:>8.2} us/row",
            f[0],
            size / f[0],
            f[1],
            f[2],
            f[3],
            f[0] / f[1] * 1e6
        );
        let _ = std::fs::remove_file(&path);
    }
    cameras(&exe, dir.path());
}
