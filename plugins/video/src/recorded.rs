//! A recording's camera played as a live camera: a thread releases each coded frame at its
//! capture time ([`avatarm_core::sim::recorded::Playback`], lap after lap), decodes it (PNG or
//! JPEG) and hands it to the app as a webcam's would be ([`crate::threaded`]). The frame's
//! capture instant is its release: what a camera with no transport delay would give. A player
//! that falls behind (decoding slower than the camera's rate) skips to the newest due frame,
//! and a frame the app has not taken two frames later is dropped, as a camera's driver drops
//! the frames nobody read.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::time::Instant;

use avatarm_core::sim::recorded::{Playback, PlaybackCursor};
use bevy::prelude::*;

use crate::threaded::{SourceEvent, add_threaded_source};
use crate::wake::FrameWake;

/// One coded frame of a recording.
#[derive(Debug, Clone)]
pub struct CodedFrame {
    /// Capture time (s, the recording's clock).
    pub stamp_s: f64,
    /// The PNG or JPEG image.
    pub data: Arc<[u8]>,
}

/// What the player counts (shared with whoever reports on it).
#[derive(Debug, Default)]
pub struct PlayerCounters {
    /// Frames decoded and handed to the app.
    pub played: AtomicU64,
    /// Frames skipped: the player fell behind, or the app had not taken the two before.
    pub skipped: AtomicU64,
    /// Laps completed.
    pub laps: AtomicU64,
}

/// A recording played as the camera.
#[derive(Debug, Clone)]
pub struct RecordedCameraConfig {
    /// The source's name, for messages (the recording's file).
    pub name: String,
    /// The frames, by capture time.
    pub frames: Arc<[CodedFrame]>,
    /// When each frame is released (the frames' own timeline, or one shared with the
    /// recording's joint states).
    pub playback: Playback,
    /// The player's counters.
    pub counters: Arc<PlayerCounters>,
}

/// Plays a recording as the camera; see the module docs. The thread ends with the app.
pub struct RecordedCameraPlugin(pub RecordedCameraConfig);

/// Set when the app ends, so that the player stops.
#[derive(Resource)]
struct PlayerStop(Arc<AtomicBool>);

impl Drop for PlayerStop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

impl Plugin for RecordedCameraPlugin {
    fn build(&self, app: &mut App) {
        // Two frames in flight at most: a frame nobody took is dropped, as a camera's driver
        // drops it, rather than queued behind the app.
        let (tx, rx) = sync_channel(2);
        let config = self.0.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let thread_stop = stop.clone();
        let wake = FrameWake::of(app);
        let spawned = std::thread::Builder::new()
            .name("recorded camera".into())
            .spawn(move || play(&config, &tx, &thread_stop, &wake));
        if let Err(e) = spawned {
            error!("{}: cannot start the player thread: {e}", self.0.name);
        }
        add_threaded_source(app, self.0.name.clone(), rx);
        app.insert_resource(PlayerStop(stop));
    }
}

/// The player's thread: wait for the next frame's release, decode the newest due, send.
fn play(
    config: &RecordedCameraConfig,
    tx: &SyncSender<SourceEvent>,
    stop: &AtomicBool,
    wake: &FrameWake,
) {
    let stamps: Vec<f64> = config.frames.iter().map(|f| f.stamp_s).collect();
    let _ = tx.try_send(SourceEvent::Opened(format!(
        "a recording: {} frames over {:.1} s, played in a loop",
        stamps.len(),
        config.playback.lap_s()
    )));
    let mut cursor = PlaybackCursor::default();
    let mut index = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let Some(next) = config.playback.next_release(&stamps, cursor) else {
            let _ = tx.try_send(SourceEvent::Failed(format!(
                "{}: the recording has no frames",
                config.name
            )));
            return;
        };
        let now = Instant::now();
        if next > now {
            // Short sleeps, so that the app's end is seen soon.
            std::thread::sleep((next - now).min(std::time::Duration::from_millis(50)));
            continue;
        }
        let Some(due) = config.playback.due(&stamps, &mut cursor, Instant::now()) else {
            continue;
        };
        config
            .counters
            .skipped
            .fetch_add(due.skipped, Ordering::Relaxed);
        config.counters.laps.store(due.lap, Ordering::Relaxed);
        let frame = &config.frames[due.index];
        let event = match image::load_from_memory(&frame.data) {
            Ok(image) => {
                let rgba = image.to_rgba8();
                SourceEvent::Frame {
                    index,
                    captured: due.at,
                    width: rgba.width(),
                    height: rgba.height(),
                    rgba: rgba.into_raw(),
                }
            }
            Err(e) => SourceEvent::Failed(format!(
                "{}: the frame at {} s cannot be decoded: {e}",
                config.name, frame.stamp_s
            )),
        };
        if matches!(event, SourceEvent::Failed(_)) {
            // The last word: waits for room.
            let _ = tx.send(event);
            return;
        }
        match tx.try_send(event) {
            Ok(()) => {
                wake.notify();
                config.counters.played.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Full(_)) => {
                config.counters.skipped.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Disconnected(_)) => return,
        }
        index += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{LiveVideo, VideoPlugin};
    use std::time::Duration;

    fn png(value: u8) -> Arc<[u8]> {
        let image = image::RgbaImage::from_pixel(4, 2, image::Rgba([value, 0, 0, 255]));
        let mut bytes = std::io::Cursor::new(Vec::new());
        image
            .write_to(&mut bytes, image::ImageFormat::Png)
            .expect("a PNG");
        bytes.into_inner().into()
    }

    #[test]
    fn a_recording_plays_as_a_camera_in_a_loop_and_a_bad_frame_stops_it_with_a_message() {
        let frames: Arc<[CodedFrame]> = (0..3)
            .map(|i| CodedFrame {
                stamp_s: 100.0 + 0.02 * f64::from(i),
                data: png(i as u8 * 10),
            })
            .collect();
        let stamps: Vec<f64> = frames.iter().map(|f| f.stamp_s).collect();
        let counters = Arc::new(PlayerCounters::default());
        let config = RecordedCameraConfig {
            name: "rec.mcap".into(),
            frames,
            playback: Playback::new("rec.mcap", Instant::now(), &stamps).expect("valid"),
            counters: counters.clone(),
        };
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, VideoPlugin, RecordedCameraPlugin(config)));
        let mut seen = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(20);
        while counters.laps.load(Ordering::Relaxed) < 2 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
            app.update();
            let live = app.world().resource::<LiveVideo>();
            if live.fresh
                && let Some(f) = &live.frame
            {
                assert_eq!((f.width, f.height), (4, 2));
                assert!(f.capture_s <= f.arrival_s + 1e-9);
                seen.push(f.rgba[0]);
            }
        }
        assert!(counters.laps.load(Ordering::Relaxed) >= 2, "{counters:?}");
        // The recording's frames, more than one of them.
        assert!(seen.iter().all(|v| [0, 10, 20].contains(v)), "{seen:?}");
        assert!(seen.iter().any(|&v| v != seen[0]), "{seen:?}");

        // A frame that is not an image: one message, the player stops.
        let bad: Arc<[CodedFrame]> = vec![CodedFrame {
            stamp_s: 0.0,
            data: vec![1u8, 2, 3].into(),
        }]
        .into();
        let (tx, rx) = sync_channel(4);
        let config = RecordedCameraConfig {
            name: "bad.mcap".into(),
            frames: bad,
            playback: Playback::new("bad.mcap", Instant::now(), &[0.0]).expect("valid"),
            counters: Arc::default(),
        };
        play(&config, &tx, &AtomicBool::new(false), &FrameWake::default());
        let events: Vec<_> = rx.try_iter().collect();
        assert!(
            matches!(events.last(), Some(SourceEvent::Failed(m)) if m.contains("bad.mcap: the frame at 0 s")),
            "{events:?}"
        );
    }
}
