//! Video sources: every frame the app shows comes through here, with its capture timestamp.
//!
//! A source pushes [`VideoFrame`]s into the [`VideoInbox`] with the time each one arrives;
//! [`VideoPlugin`] publishes the newest arrived frame as the [`LiveVideo`] resource once per
//! update (older ones that arrived in the same update are counted as dropped). When no frame
//! has arrived for [`LiveVideo::stale_after_s`], the last frame stays on screen marked stale
//! and one warning is logged per stall.
//!
//! Sources: the simulated camera (in `avatarm_sim`), [`folder::FolderSource`] (recorded frames
//! with a timestamps file), [`recorded::RecordedCameraPlugin`] (a recording played as a live
//! camera, in real time) and, with the `webcam` feature, a webcam through `nokhwa`. The last two
//! read on a thread of their own ([`threaded`]).
//!
//! Modules: [`folder`], [`pixels`], [`recorded`], [`threaded`], [`wake`] (an app woken by its
//! camera's frames), `webcam` (feature `webcam`), [`error`].
//!
//! A camera that moves with a head (Alice's headset camera) also has a pose stream: the head's
//! tracked poses arrive as [`HeadPoseMessage`]s and are kept in [`HeadTracking`], whose
//! history gives the head's pose at a frame's capture time.
//!
//! Clock: frame times are on the app clock, `Time<Fixed>`'s elapsed time, which is also the
//! clock of joint states (the simulated robot steps in `FixedUpdate`).

pub mod error;
pub mod folder;
pub mod pixels;
pub mod recorded;
pub mod threaded;
pub mod wake;
#[cfg(feature = "webcam")]
pub mod webcam;

use std::sync::Arc;

use avatarm_core::vision::head::PoseHistory;
use bevy::prelude::*;
use nalgebra::Isometry3;

pub use error::VideoError;

/// What most users of the video need.
pub mod prelude {
    pub use crate::{
        HeadPoseMessage, HeadTracking, LiveVideo, VideoError, VideoFrame, VideoInbox, VideoPlugin,
        VideoSystems,
    };
}

/// A tracked pose of the head the camera rides on, as the headset reports it.
#[derive(Message, Debug, Clone, Copy, PartialEq)]
pub struct HeadPoseMessage {
    /// The moment it describes (s, app clock).
    pub stamp_s: f64,
    /// `world_from_head`, the head's optical frame (x right, y down, z forward;
    /// `avatarm_core::vision::head`), in the robot's world (m).
    pub world_from_head: Isometry3<f64>,
}

/// The head's tracked poses received so far (a camera on a head; empty for a fixed camera).
#[derive(Resource, Debug, Clone, Default)]
pub struct HeadTracking {
    /// About the last second of poses, oldest first.
    pub history: PoseHistory,
    /// Poses taken.
    pub received: u64,
    /// Poses refused: not finite, or not newer than the newest (one warning per 100).
    pub refused: u64,
}

/// One camera frame, RGBA8, top row first.
#[derive(Debug, Clone)]
pub struct VideoFrame {
    /// Frame number from the source.
    pub index: u64,
    /// When the image was captured (s, app clock).
    pub capture_s: f64,
    /// When it reaches the app (s, app clock).
    pub arrival_s: f64,
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// `width * height * 4` bytes.
    pub rgba: Arc<Vec<u8>>,
}

/// Frames on their way to the app, in arrival order.
#[derive(Resource, Debug, Default)]
pub struct VideoInbox {
    /// Frames not yet published.
    pub pending: Vec<VideoFrame>,
}

impl VideoInbox {
    /// Queues a frame; frames whose size does not match `width × height × 4` are refused.
    pub fn push(&mut self, frame: VideoFrame) -> Result<(), VideoError> {
        let expected = frame.width as usize * frame.height as usize * 4;
        let what = || format!("video frame {}", frame.index);
        if frame.rgba.len() != expected || expected == 0 {
            return Err(VideoError::BadFrame {
                what: what(),
                message: format!(
                    "{}x{} needs {expected} bytes, got {}",
                    frame.width,
                    frame.height,
                    frame.rgba.len()
                ),
            });
        }
        if !frame.capture_s.is_finite() || !frame.arrival_s.is_finite() {
            return Err(VideoError::BadFrame {
                what: what(),
                message: "timestamp is not finite".into(),
            });
        }
        self.pending.push(frame);
        Ok(())
    }
}

/// The frame on screen.
#[derive(Resource, Debug)]
pub struct LiveVideo {
    /// Name of the source, for messages.
    pub source: String,
    /// The newest arrived frame.
    pub frame: Option<VideoFrame>,
    /// A new frame was published in this update.
    pub fresh: bool,
    /// No frame arrived for `stale_after_s`.
    pub stale: bool,
    /// Frames published so far.
    pub published: u64,
    /// Frames that arrived in the same update as a newer one and were never shown.
    pub dropped: u64,
    /// When the last frame was published (s, app clock).
    pub last_publish_s: Option<f64>,
    /// After this long without a frame, the source is reported stale (s).
    pub stale_after_s: f64,
}

impl LiveVideo {
    /// A source named `source` that is stale after `stale_after_s` without frames.
    pub fn new(source: impl Into<String>, stale_after_s: f64) -> Self {
        Self {
            source: source.into(),
            frame: None,
            fresh: false,
            stale: false,
            published: 0,
            dropped: 0,
            last_publish_s: None,
            stale_after_s,
        }
    }
}

/// The video system sets (`Update`).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VideoSystems {
    /// Sources fill the inbox.
    Receive,
    /// The newest arrived frame becomes [`LiveVideo`]'s.
    Publish,
}

/// Adds the inbox, [`LiveVideo`] and the publishing system. Insert a [`LiveVideo`] first to
/// name the source and set its stale time; the default is "camera", 0.5 s.
#[derive(Default)]
pub struct VideoPlugin;

impl Plugin for VideoPlugin {
    fn build(&self, app: &mut App) {
        if !app.world().contains_resource::<LiveVideo>() {
            app.insert_resource(LiveVideo::new("camera", 0.5));
        }
        app.init_resource::<VideoInbox>()
            .init_resource::<HeadTracking>()
            .add_message::<HeadPoseMessage>()
            .configure_sets(
                Update,
                (VideoSystems::Receive, VideoSystems::Publish).chain(),
            )
            .add_systems(
                Update,
                (record_head_poses, publish).in_set(VideoSystems::Publish),
            );
    }
}

/// Now on the app clock.
pub fn app_clock(time: &Time<Fixed>) -> f64 {
    time.elapsed_secs_f64()
}

fn record_head_poses(mut poses: MessageReader<HeadPoseMessage>, mut head: ResMut<HeadTracking>) {
    for p in poses.read() {
        if head.history.push(p.stamp_s, p.world_from_head) {
            head.received += 1;
        } else {
            head.refused += 1;
            if head.refused % 100 == 1 {
                warn!(
                    "head tracking: pose stamped {} s refused (not finite, or not newer than the newest); {} so far",
                    p.stamp_s, head.refused
                );
            }
        }
    }
}

fn publish(mut inbox: ResMut<VideoInbox>, mut live: ResMut<LiveVideo>, time: Res<Time<Fixed>>) {
    let now = app_clock(&time);
    live.fresh = false;
    let mut arrived: Vec<VideoFrame> = Vec::new();
    inbox.pending.retain(|f| {
        if f.arrival_s <= now + 1e-9 {
            arrived.push(f.clone());
            false
        } else {
            true
        }
    });
    if let Some(newest) = arrived
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.capture_s.total_cmp(&b.1.capture_s))
        .map(|(i, _)| i)
    {
        live.dropped += arrived.len() as u64 - 1;
        let frame = arrived.swap_remove(newest);
        let older = live
            .frame
            .as_ref()
            .is_some_and(|f| f.capture_s > frame.capture_s);
        if older {
            live.dropped += 1;
        } else {
            live.frame = Some(frame);
            live.fresh = true;
            live.published += 1;
            live.last_publish_s = Some(now);
            if live.stale {
                info!("video source '{}': frames again", live.source);
            }
            live.stale = false;
        }
    }
    let since = live.last_publish_s.map_or(now, |t| now - t);
    if !live.stale && since > live.stale_after_s && (live.frame.is_some() || now > 2.0) {
        live.stale = true;
        warn!(
            "video source '{}': no frame for {since:.2} s; showing the last frame, marked stale",
            live.source
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn frame(index: u64, capture_s: f64, arrival_s: f64) -> VideoFrame {
        VideoFrame {
            index,
            capture_s,
            arrival_s,
            width: 2,
            height: 1,
            rgba: Arc::new(vec![index as u8; 8]),
        }
    }

    fn app() -> App {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, VideoPlugin))
            .insert_resource(Time::<Fixed>::from_hz(100.0))
            .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
                Duration::from_millis(100),
            ));
        app.update();
        app
    }

    #[test]
    fn newest_arrived_frame_is_published_and_staleness_is_reported() {
        let mut app = app();
        let now = app.world().resource::<Time<Fixed>>().elapsed_secs_f64();
        {
            let mut inbox = app.world_mut().resource_mut::<VideoInbox>();
            inbox.push(frame(1, now - 0.05, now)).expect("ok");
            inbox.push(frame(2, now - 0.02, now)).expect("ok");
            inbox.push(frame(3, now, now + 10.0)).expect("ok");
            let bad = VideoFrame {
                rgba: Arc::new(vec![0; 3]),
                ..frame(4, now, now)
            };
            assert!(
                inbox
                    .push(bad)
                    .expect_err("size")
                    .to_string()
                    .contains("needs 8 bytes")
            );
        }
        app.update();
        let live = app.world().resource::<LiveVideo>();
        assert!(live.fresh);
        assert_eq!(live.frame.as_ref().map(|f| f.index), Some(2));
        assert_eq!(live.dropped, 1);
        // Nothing more arrives: stale after 0.5 s, the last frame kept.
        for _ in 0..8 {
            app.update();
        }
        let live = app.world().resource::<LiveVideo>();
        assert!(!live.fresh && live.stale);
        assert_eq!(live.frame.as_ref().map(|f| f.index), Some(2));
    }
}
