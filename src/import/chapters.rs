//! GoPro chapters: a camera splits one recording into files of at most
//! 4 GB (8-17 minutes of video), so every ride longer than that comes as
//! several files, `GX010123.MP4`, `GX020123.MP4`, ... (HERO6 and later:
//! `GH`/`GX`, the chapter, the recording's number) or `GOPR0123.MP4`,
//! `GP010123.MP4`, ... (HERO5 and earlier). Fitted apart, each chapter
//! starts from an unknown heading and the ride's path breaks at every
//! seam; read as one, the ride is one path.
//!
//! The chapters are seamless: the camera goes on recording into the next
//! file, and each file's telemetry clock starts again at zero. So chapter
//! `k + 1` is placed one sample step after the last sample of chapter `k`
//! (the step being chapter `k`'s median): exact to a sample, where the
//! receiver's UTC (`GPSU`, to the second) is not. Where both chapters
//! carry a UTC start, it is checked against that placement.

use std::path::{Path, PathBuf};

use super::LoadError;
use crate::ride::RideLog;

/// Largest disagreement (s) between the seamless placement of a chapter and
/// its receiver's UTC start (`GPSU`, whole seconds, stamped on the payload
/// after the first fix) that is not said.
const UTC_TOLERANCE_S: f64 = 2.5;

/// A file name read as a GoPro chapter.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chapter {
    /// The chapter's number, 1 for the recording's first file.
    pub number: u32,
    /// The recording's number (the name's last four digits).
    pub recording: String,
    /// The naming: `GH`/`GX` (HERO6 and later) or `GP` (HERO5 and earlier,
    /// whose first chapter is `GOPR`).
    pub family: String,
    /// The extension as written (`MP4`, `mp4`).
    pub extension: String,
}

impl Chapter {
    /// `name` (a file name) as a GoPro chapter, or `None`.
    pub fn of(name: &str) -> Option<Self> {
        let (stem, extension) = name.rsplit_once('.')?;
        if !extension.eq_ignore_ascii_case("mp4") || stem.len() != 8 || !stem.is_ascii() {
            return None;
        }
        let upper = stem.to_ascii_uppercase();
        let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
        let recording = upper[4..].to_string();
        if !digits(&recording) {
            return None;
        }
        let (family, number) = match &upper[..4] {
            "GOPR" => ("GP".to_string(), 1),
            head if (head.starts_with("GH")
                || head.starts_with("GX")
                || head.starts_with("GP"))
                && digits(&head[2..]) =>
            {
                let number: u32 = head[2..].parse().ok()?;
                // `GP01` is a HERO5's second file; `GH01` a HERO6's first.
                let number = if head.starts_with("GP") {
                    number + 1
                } else {
                    number
                };
                (head[..2].to_string(), number)
            }
            _ => return None,
        };
        (number >= 1).then_some(Self {
            number,
            recording,
            family,
            extension: extension.to_string(),
        })
    }

    /// The file name of chapter `number` of the same recording.
    fn name(&self, number: u32) -> String {
        match (self.family.as_str(), number) {
            ("GP", 1) => format!("GOPR{}.{}", self.recording, self.extension),
            ("GP", n) => format!("GP{:02}{}.{}", n - 1, self.recording, self.extension),
            (family, n) => format!("{family}{n:02}{}.{}", self.recording, self.extension),
        }
    }
}

/// The file of chapter `number` of `path`'s recording, where it is beside it.
fn sibling(path: &Path, chapter: &Chapter, number: u32) -> Option<PathBuf> {
    let wanted = chapter.name(number);
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let exact = dir.join(&wanted);
    if exact.is_file() {
        return Some(exact);
    }
    // Cards are FAT: a copy may have lowered the names' case.
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| {
            p.is_file()
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().eq_ignore_ascii_case(&wanted))
        })
}

/// The chapters that follow `path` in its recording, in order, where `path`
/// is a recording's first chapter and they are beside it (up to the first
/// one missing); empty otherwise.
pub fn following(path: &Path) -> Vec<PathBuf> {
    let Some(chapter) = path
        .file_name()
        .and_then(|n| Chapter::of(&n.to_string_lossy()))
    else {
        return Vec::new();
    };
    if chapter.number != 1 {
        return Vec::new();
    }
    (2..100).map_while(|k| sibling(path, &chapter, k)).collect()
}

/// The first chapter of `path`'s recording, where `path` is a later chapter
/// and the first is beside it: that file reads the whole recording.
pub fn first_of(path: &Path) -> Option<PathBuf> {
    let chapter = Chapter::of(&path.file_name()?.to_string_lossy())?;
    (chapter.number > 1)
        .then(|| sibling(path, &chapter, 1))
        .flatten()
}

/// Append chapter `next` (read from `file`) to the recording `log`, one
/// sample step after its last sample (see the module docs); its UTC start,
/// where both have one, is checked against that, and a chapter with none
/// gives the recording its start when the first had none.
pub fn append(log: &mut RideLog, mut next: RideLog, file: &str) -> Result<(), LoadError> {
    let (Some(&last), Some(&first_next)) = (log.t_s.last(), next.t_s.first()) else {
        return Err(LoadError::File {
            file: file.to_string(),
            message: "a chapter of the recording has no samples".into(),
        });
    };
    let mut steps: Vec<f64> = log
        .t_s
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    let step = crate::statistics::median(&mut steps);
    if !(step.is_finite() && step > 0.0) {
        return Err(LoadError::File {
            file: log.source.clone(),
            message: "a chapter of the recording has fewer than two sample times".into(),
        });
    }
    let offset = last + step - first_next;
    match (log.t0_unix_s(), next.t0_unix_s()) {
        (Some(t0), Some(t0_next)) => {
            let apart = (t0_next - t0) - offset;
            if apart.abs() > UTC_TOLERANCE_S {
                log.warnings.push(format!(
                    "{file}: read as the next chapter of {}, {offset:.1} s after its start, but its GNSS clock puts it {:.1} s after it ({apart:+.1} s): a chapter copied from another recording, or a GNSS clock off at the seam",
                    log.source,
                    t0_next - t0
                ));
            }
        }
        (None, Some(t0_next)) => {
            log.metadata
                .insert("t0_unix_s".into(), format!("{:.3}", t0_next - offset));
        }
        _ => {}
    }
    let rows_before = log.line.last().copied().unwrap_or(0);
    for line in &mut next.line {
        *line += rows_before;
    }
    for t in &mut next.t_s {
        *t += offset;
    }
    log.warnings.append(&mut next.warnings);
    log.append(next);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gopro_names_read_as_chapters_of_a_recording() {
        let c = Chapter::of("GX010123.MP4").unwrap();
        assert_eq!(
            (c.number, c.recording.as_str(), c.family.as_str()),
            (1, "0123", "GX")
        );
        assert_eq!(c.name(2), "GX020123.MP4");
        assert_eq!(Chapter::of("gh030042.mp4").unwrap().number, 3);
        // HERO5 and earlier: GOPR first, then GP01, GP02, ...
        let c = Chapter::of("GOPR0077.MP4").unwrap();
        assert_eq!(c.number, 1);
        assert_eq!(c.name(2), "GP010077.MP4");
        assert_eq!(c.name(3), "GP020077.MP4");
        assert_eq!(Chapter::of("GP010077.MP4").unwrap().number, 2);
        for other in [
            "ride.mp4",
            "GX01012.MP4",
            "GX0A0123.MP4",
            "GL010123.LRV",
            "GX010123.THM",
        ] {
            assert_eq!(Chapter::of(other), None, "{other}");
        }
    }

    #[test]
    fn the_following_chapters_are_found_beside_the_first_up_to_a_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "GX010009.MP4",
            "GX020009.MP4",
            "gx030009.mp4",
            "GX050009.MP4",
            "GX020010.MP4",
        ] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        let first = dir.path().join("GX010009.MP4");
        let names: Vec<String> = following(&first)
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["GX020009.MP4", "gx030009.mp4"]);
        assert!(following(&dir.path().join("GX020009.MP4")).is_empty());
        assert_eq!(first_of(&dir.path().join("GX020009.MP4")), Some(first));
        assert_eq!(first_of(&dir.path().join("GX020010.MP4")), None);
    }

    #[test]
    fn a_chapter_is_appended_one_step_after_the_last_sample() {
        let mut log = crate::testing::winding_log(10.0, 10.0);
        log.metadata.insert("t0_unix_s".into(), "1000.000".into());
        let n = log.len();
        let last = *log.t_s.last().unwrap();
        let step = log.t_s[1] - log.t_s[0];
        let mut next = crate::testing::winding_log(10.0, 10.0);
        next.metadata
            .insert("t0_unix_s".into(), format!("{:.3}", 1000.0 + last + step));
        append(&mut log, next.clone(), "GX020001.MP4").unwrap();
        assert_eq!(log.len(), 2 * n);
        assert!(log.t_s.windows(2).all(|w| w[1] > w[0]));
        assert!((log.t_s[n] - last - step).abs() < 1e-9, "{}", log.t_s[n]);
        assert_eq!(log.fix_count(), 2 * next.fix_count());
        assert!(log.line.windows(2).all(|w| w[1] > w[0]));
        assert!(log.warnings.is_empty(), "{:?}", log.warnings);
        // A chapter whose UTC start says it belongs elsewhere is said.
        let mut far = crate::testing::winding_log(10.0, 10.0);
        far.metadata.insert("t0_unix_s".into(), "5000.000".into());
        append(&mut log, far, "GX030001.MP4").unwrap();
        assert!(
            log.warnings
                .iter()
                .any(|w| w.contains("GX030001.MP4") && w.contains("GNSS clock")),
            "{:?}",
            log.warnings
        );
    }
}
