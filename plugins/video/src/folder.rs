//! Recorded sessions: a folder of PNG or JPEG frames and a `timestamps.csv` beside them.
//!
//! `timestamps.csv` has a header line `file,capture_s` and one line per frame: the file name
//! (relative to the folder) and its capture time in seconds (any origin; times must increase).
//! Frames are played on the app clock from the first frame's time, so frame `i` arrives at
//! `capture_s[i] − capture_s[0]`. `avatarm replay` writes this file next to its frames.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bevy::prelude::*;

use crate::{VideoError, VideoFrame, VideoInbox, VideoSystems, app_clock};

/// A recorded session played back as a video source.
#[derive(Resource, Debug, Clone)]
pub struct FolderSource {
    /// The folder.
    pub folder: PathBuf,
    /// Frame files with their capture times (s, as recorded).
    pub frames: Vec<(PathBuf, f64)>,
    next: usize,
    failures: u64,
}

impl FolderSource {
    /// Reads `folder/timestamps.csv` and checks that every listed frame exists and that times
    /// increase.
    pub fn open(folder: &Path) -> Result<Self, VideoError> {
        let path = folder.join("timestamps.csv");
        let text = std::fs::read_to_string(&path).map_err(|source| VideoError::Io {
            path: path.clone(),
            source,
        })?;
        let mut frames: Vec<(PathBuf, f64)> = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            let err = |message: String| VideoError::Line {
                path: path.clone(),
                line: i + 1,
                message,
            };
            if line.is_empty() || line.starts_with('#') || (i == 0 && line.starts_with("file")) {
                continue;
            }
            let (file, t) = line
                .split_once(',')
                .ok_or_else(|| err(format!("expected 'file,capture_s', got '{line}'")))?;
            let t: f64 = t
                .trim()
                .parse()
                .map_err(|_| err(format!("capture time '{}' is not a number", t.trim())))?;
            if !t.is_finite() {
                return Err(err(format!("capture time {t} is not finite")));
            }
            if let Some((_, prev)) = frames.last()
                && t <= *prev
            {
                return Err(err(format!(
                    "capture time {t} does not increase (previous {prev})"
                )));
            }
            let file = folder.join(file.trim());
            if !file.is_file() {
                return Err(err(format!("frame {} does not exist", file.display())));
            }
            frames.push((file, t));
        }
        if frames.is_empty() {
            return Err(VideoError::Empty { path });
        }
        Ok(Self {
            folder: folder.to_owned(),
            frames,
            next: 0,
            failures: 0,
        })
    }

    /// Frames whose time has come at `now_s` (app clock), decoded; files that fail to decode are
    /// reported in the second list and skipped.
    pub fn due(&mut self, now_s: f64) -> (Vec<VideoFrame>, Vec<String>) {
        let t0 = self.frames[0].1;
        let (mut out, mut errors) = (Vec::new(), Vec::new());
        while let Some((file, t)) = self.frames.get(self.next) {
            let capture = t - t0;
            if capture > now_s + 1e-9 {
                break;
            }
            let index = self.next as u64;
            self.next += 1;
            match image::open(file) {
                Ok(img) => {
                    let rgba = img.to_rgba8();
                    out.push(VideoFrame {
                        index,
                        capture_s: capture,
                        arrival_s: capture,
                        width: rgba.width(),
                        height: rgba.height(),
                        rgba: Arc::new(rgba.into_raw()),
                    });
                }
                Err(e) => {
                    self.failures += 1;
                    errors.push(format!("{}: cannot decode frame: {e}", file.display()));
                }
            }
        }
        (out, errors)
    }

    /// Whether every frame has been played.
    pub fn finished(&self) -> bool {
        self.next >= self.frames.len()
    }
}

/// Plays a [`FolderSource`] resource into the inbox.
#[derive(Default)]
pub struct FolderSourcePlugin;

impl Plugin for FolderSourcePlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(Update, feed.in_set(VideoSystems::Receive));
    }
}

fn feed(
    source: Option<ResMut<FolderSource>>,
    mut inbox: ResMut<VideoInbox>,
    time: Res<Time<Fixed>>,
) {
    let Some(mut source) = source else { return };
    let (frames, errors) = source.due(app_clock(&time));
    for e in errors {
        error!("{e}");
    }
    for f in frames {
        if let Err(e) = inbox.push(f) {
            error!("{}: {e}", source.folder.display());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("avatarm_video_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    }

    #[test]
    fn plays_frames_at_their_times_and_reports_bad_ones() {
        let dir = folder("play");
        image::RgbaImage::from_pixel(4, 2, image::Rgba([9, 8, 7, 255]))
            .save(dir.join("a.png"))
            .expect("png");
        std::fs::write(dir.join("b.png"), b"not a png").expect("write");
        image::RgbImage::from_pixel(4, 2, image::Rgb([1, 2, 3]))
            .save(dir.join("c.jpg"))
            .expect("jpg");
        std::fs::write(
            dir.join("timestamps.csv"),
            "file,capture_s\na.png,10.0\nb.png,10.1\nc.jpg,10.2\n",
        )
        .expect("write");
        let mut src = FolderSource::open(&dir).expect("open");
        let (f, e) = src.due(0.0);
        assert_eq!((f.len(), e.len()), (1, 0));
        assert_eq!(&f[0].rgba[..4], &[9, 8, 7, 255]);
        let (f, e) = src.due(0.25);
        assert_eq!(f.len(), 1, "the jpeg");
        assert!((f[0].capture_s - 0.2).abs() < 1e-9);
        assert_eq!(e.len(), 1);
        assert!(e[0].contains("b.png"), "{e:?}");
        assert!(src.finished());
    }

    #[test]
    fn bad_timestamp_files_name_the_line() {
        let dir = folder("bad");
        let e = FolderSource::open(&dir).expect_err("missing");
        assert!(e.to_string().contains("timestamps.csv"));
        image::RgbaImage::new(2, 2)
            .save(dir.join("a.png"))
            .expect("png");
        std::fs::write(
            dir.join("timestamps.csv"),
            "file,capture_s\na.png,1\na.png,0.5\n",
        )
        .expect("write");
        let e = FolderSource::open(&dir).expect_err("not increasing");
        assert!(e.to_string().contains(":3:"), "{e}");
        std::fs::write(dir.join("timestamps.csv"), "file,capture_s\nz.png,1\n").expect("write");
        assert!(
            FolderSource::open(&dir)
                .expect_err("missing")
                .to_string()
                .contains("z.png")
        );
        std::fs::write(dir.join("timestamps.csv"), "file,capture_s\na.png,abc\n").expect("write");
        assert!(
            FolderSource::open(&dir)
                .expect_err("nan")
                .to_string()
                .contains("abc")
        );
    }
}
