//! A camera read on a thread of its own (a webcam, a recording played as a live camera): the
//! thread sends [`SourceEvent`]s, each frame stamped with the instant it was captured; one
//! system per update ([`VideoSystems::Receive`]) maps those instants onto the app clock and
//! pushes the frames into the [`VideoInbox`]. A thread that fails or ends: one clear line, the
//! app keeps running on the last frame (marked stale by [`crate::VideoPlugin`]).

use std::sync::Mutex;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::{Duration, Instant};

use bevy::prelude::*;

use crate::{VideoFrame, VideoInbox, VideoSystems, app_clock};

/// What a camera's thread tells the app.
#[derive(Debug)]
pub enum SourceEvent {
    /// The device (or file) is open: what it is, for the log.
    Opened(String),
    /// A frame, RGBA8, top row first.
    Frame {
        /// Frame number from the source.
        index: u64,
        /// When it was captured (for a webcam: read from the driver, less its latency).
        captured: Instant,
        /// Width (px).
        width: u32,
        /// Height (px).
        height: u32,
        /// `width * height * 4` bytes.
        rgba: Vec<u8>,
    },
    /// The source stopped for good: why.
    Failed(String),
}

/// The camera's thread as the app sees it.
#[derive(Resource)]
struct ThreadedSource {
    name: String,
    events: Mutex<Receiver<SourceEvent>>,
    failed: bool,
}

/// Adds the system that takes `events` (the thread of the source named `name`) into the
/// inbox.
pub fn add_threaded_source(app: &mut App, name: String, events: Receiver<SourceEvent>) {
    app.insert_resource(ThreadedSource {
        name,
        events: Mutex::new(events),
        failed: false,
    })
    .add_systems(Update, receive.in_set(VideoSystems::Receive));
}

fn receive(
    mut source: ResMut<ThreadedSource>,
    mut inbox: ResMut<VideoInbox>,
    time: Res<Time<Fixed>>,
) {
    let now_app = app_clock(&time);
    let now = Instant::now();
    let mut events = Vec::new();
    if let Ok(rx) = source.events.lock() {
        loop {
            match rx.try_recv() {
                Ok(e) => events.push(e),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    if !source.failed {
                        events.push(SourceEvent::Failed(format!(
                            "{}: the capture thread stopped",
                            source.name
                        )));
                    }
                    break;
                }
            }
        }
    }
    for event in events {
        match event {
            SourceEvent::Opened(what) => info!("{}: streaming from {what}", source.name),
            SourceEvent::Failed(message) => {
                if !source.failed {
                    error!("{message}; the app keeps running without a camera feed");
                }
                source.failed = true;
            }
            SourceEvent::Frame {
                index,
                captured,
                width,
                height,
                rgba,
            } => {
                let age: Duration = now.saturating_duration_since(captured);
                let frame = VideoFrame {
                    index,
                    capture_s: now_app - age.as_secs_f64(),
                    arrival_s: now_app,
                    width,
                    height,
                    rgba: std::sync::Arc::new(rgba),
                };
                if let Err(e) = inbox.push(frame) {
                    warn!("{}: {e}", source.name);
                }
            }
        }
    }
}
