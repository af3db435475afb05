//! One camera's video in the robot site's report: its frames, its source, how long its frames
//! waited, its app's updates and GPU spans.

use std::sync::atomic::Ordering;

use avatarm_core::stats::Spread;
use serde::{Deserialize, Serialize};

/// One camera's video at the robot site (`ServeReport::video_cameras`).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct CameraVideo {
    /// The camera's name on the network.
    pub camera: String,
    /// Erased frames published.
    pub frames: u64,
    /// Of them, keyframes.
    pub keyframes: u64,
    /// H.264 IDR frames forced by viewers' requests.
    pub forced_keyframes: u64,
    /// Frames the encoder refused.
    pub encode_errors: u64,
    /// Frames H.264's rate control skipped.
    pub skipped: u64,
    /// A camera on a head: its wearer's head poses taken from the network.
    pub head_poses: u64,
    /// Head poses refused (each run of refusals logged once).
    pub head_refused: u64,
    /// Where the frames came from (the simulated camera, a webcam, a recording's file).
    pub source: String,
    /// Frames handed to the encoder more than one app update after they arrived (a frame
    /// path kept short has none).
    pub handed_late: u64,
    /// The most app updates a frame waited between arriving and being handed over.
    pub waited_updates_max: u64,
    /// Frames not published because the erase was not ready for them (drawn while a pipeline
    /// compiled, or before the twin behind the mask had a joint state).
    pub unready: u64,
    /// A recording played as the camera: what its player did.
    pub player: Option<PlayerReport>,
    /// The app's updates.
    pub updates: u64,
    /// The main world's time per update (ms: its systems, `First` to `Last`; the render
    /// world's extraction and rendering not included).
    pub update_ms: Spread,
    /// The GPU's time per span (ms: each camera's render, each erase pass, the upload), where
    /// the device has timestamp queries; the last samples kept.
    pub gpu_ms: std::collections::BTreeMap<String, Spread>,
}

/// A recording's player at the robot site (`CameraVideo::player`).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PlayerReport {
    /// Frames decoded and handed to the app.
    pub played: u64,
    /// Frames skipped because the player fell behind.
    pub skipped: u64,
    /// Laps of the recording completed.
    pub laps: u64,
}

impl CameraVideo {
    /// Reads `camera`'s counters.
    pub(super) fn of(
        camera: String,
        counters: &crate::net::video::VideoCounters,
        source: &crate::app::CameraSource,
    ) -> Self {
        let player = match source {
            crate::app::CameraSource::Recording(r) => Some(PlayerReport {
                played: r.counters.played.load(Ordering::Relaxed),
                skipped: r.counters.skipped.load(Ordering::Relaxed),
                laps: r.counters.laps.load(Ordering::Relaxed),
            }),
            _ => None,
        };
        Self {
            camera,
            source: source.name(),
            handed_late: counters.handed_late.load(Ordering::Relaxed),
            unready: counters.unready.load(Ordering::Relaxed),
            waited_updates_max: counters.waited_updates_max.load(Ordering::Relaxed),
            player,
            updates: counters.updates.load(Ordering::Relaxed),
            update_ms: counters
                .update_ms
                .lock()
                .map(|mut t| Spread::of(t.make_contiguous()))
                .unwrap_or_default(),
            gpu_ms: counters
                .gpu_times
                .lock()
                .ok()
                .and_then(|t| t.as_ref().map(avatarm_erase::GpuTimes::snapshot))
                .map(|t| {
                    t.spans
                        .iter()
                        .map(|(name, s)| {
                            let ms: Vec<f64> = s.ms.iter().copied().collect();
                            (name.clone(), Spread::of(&ms))
                        })
                        .collect()
                })
                .unwrap_or_default(),
            frames: counters.published.load(Ordering::Relaxed),
            keyframes: counters.keyframes.load(Ordering::Relaxed),
            forced_keyframes: counters.forced_keyframes.load(Ordering::Relaxed),
            encode_errors: counters.encode_errors.load(Ordering::Relaxed),
            skipped: counters.skipped.load(Ordering::Relaxed),
            head_poses: counters.head_poses.load(Ordering::Relaxed),
            head_refused: counters.head_refused.load(Ordering::Relaxed),
        }
    }
}
