//! A webcam through `nokhwa` (feature `webcam`): V4L2 on Linux, Media Foundation on Windows,
//! AVFoundation on macOS. A capture thread reads frames, converts them to RGBA8
//! ([`crate::pixels`]) and stamps each with the instant it was read, minus the configured
//! sensor-to-driver latency; [`WebcamPlugin`] maps those instants onto the app clock and pushes
//! the frames into the [`VideoInbox`]. No device, or a device that stops: one clear error, the
//! app keeps running on the last frame (marked stale by [`crate::VideoPlugin`]).

use std::sync::mpsc::{Sender, channel};
use std::time::{Duration, Instant};

use bevy::prelude::*;
use nokhwa::pixel_format::RgbFormat;
use nokhwa::utils::{
    CameraFormat, CameraIndex, FrameFormat, RequestedFormat, RequestedFormatType, Resolution,
};

use crate::pixels::{PixelFormat, to_rgba};
use crate::threaded::{SourceEvent, add_threaded_source};
use crate::wake::FrameWake;

/// Which webcam, and what to ask it for.
#[derive(Debug, Clone)]
pub struct WebcamConfig {
    /// Device index (`/dev/videoN` on Linux).
    pub index: u32,
    /// Requested size; the closest the device offers is used, and frames of another size than
    /// the calibrated camera's are refused downstream with a message.
    pub width: u32,
    /// Requested height.
    pub height: u32,
    /// Requested frame rate.
    pub fps: u32,
    /// Time from exposure to the driver handing the frame over (s); subtracted from the
    /// arrival instant to give the capture time.
    pub latency_s: f64,
}

/// Reads a webcam on a thread; see the module docs.
pub struct WebcamPlugin(pub WebcamConfig);

impl Plugin for WebcamPlugin {
    fn build(&self, app: &mut App) {
        let (tx, rx) = channel();
        let config = self.0.clone();
        let wake = FrameWake::of(app);
        let spawned = std::thread::Builder::new()
            .name(format!("webcam {}", config.index))
            .spawn(move || capture(&config, &tx, &wake));
        if let Err(e) = spawned {
            error!(
                "webcam {}: cannot start the capture thread: {e}",
                self.0.index
            );
        }
        add_threaded_source(app, format!("webcam {}", self.0.index), rx);
    }
}

fn frame_format(f: FrameFormat) -> PixelFormat {
    match f {
        FrameFormat::MJPEG => PixelFormat::Mjpeg,
        FrameFormat::YUYV => PixelFormat::Yuyv,
        FrameFormat::NV12 => PixelFormat::Nv12,
        FrameFormat::GRAY => PixelFormat::Gray,
        FrameFormat::RAWRGB => PixelFormat::Rgb,
        FrameFormat::RAWBGR => PixelFormat::Bgr,
    }
}

/// The capture thread: open, stream, convert, send; ends on the first error or when the app
/// is gone.
fn capture(config: &WebcamConfig, tx: &Sender<SourceEvent>, wake: &FrameWake) {
    let requested =
        RequestedFormat::new::<RgbFormat>(RequestedFormatType::Closest(CameraFormat::new(
            Resolution::new(config.width, config.height),
            FrameFormat::MJPEG,
            config.fps,
        )));
    let mut camera = match nokhwa::Camera::new(CameraIndex::Index(config.index), requested) {
        Ok(c) => c,
        Err(e) => {
            let _ = tx.send(SourceEvent::Failed(format!(
                "cannot open webcam {}: {e} (is a camera connected and readable, e.g. /dev/video{} on Linux?)",
                config.index, config.index
            )));
            return;
        }
    };
    if let Err(e) = camera.open_stream() {
        let _ = tx.send(SourceEvent::Failed(format!(
            "webcam {}: cannot start streaming: {e}",
            config.index
        )));
        return;
    }
    let format = camera.camera_format();
    let _ = tx.send(SourceEvent::Opened(format!(
        "{} ({} {}x{} @ {} fps)",
        camera.info().human_name(),
        format.format(),
        format.resolution().width(),
        format.resolution().height(),
        format.frame_rate()
    )));
    for index in 0.. {
        let buffer = match camera.frame() {
            Ok(b) => b,
            Err(e) => {
                let _ = tx.send(SourceEvent::Failed(format!(
                    "webcam {}: frame {index}: {e}",
                    config.index
                )));
                return;
            }
        };
        // Read from the driver now; exposed its latency before.
        let captured = Instant::now()
            .checked_sub(Duration::from_secs_f64(config.latency_s.max(0.0)))
            .unwrap_or_else(Instant::now);
        let res = buffer.resolution();
        let (width, height) = (res.width(), res.height());
        let event = match to_rgba(
            frame_format(buffer.source_frame_format()),
            width,
            height,
            buffer.buffer(),
        ) {
            Ok(rgba) => SourceEvent::Frame {
                index,
                captured,
                width,
                height,
                rgba,
            },
            Err(e) => SourceEvent::Failed(format!("webcam {}: frame {index}: {e}", config.index)),
        };
        let stop = matches!(event, SourceEvent::Failed(_));
        if tx.send(event).is_err() || stop {
            let _ = camera.stop_stream();
            return;
        }
        wake.notify();
    }
}
