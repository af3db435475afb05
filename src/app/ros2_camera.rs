//! A camera from ROS 2 (`--ros2-camera TOPIC`, feature `ros`): the frames `avatarm_ros`'s camera
//! thread receives over DDS or rmw_zenoh, decoded to RGBA on a thread of their own and pushed into
//! the video's inbox as any threaded source's ([`avatarm_video::threaded`]), each stamped with its
//! capture time: the header's stamp mapped onto this machine's clock (the driver's clock taken as
//! this machine's, as on one host or under NTP/PTP; a stamp in the future or more than 2 s old is
//! taken as the arrival, and said once).

use std::sync::mpsc::{Sender, channel};
use std::time::Duration;

use avatarm_ros::ros2::camera::{CameraEvent, CameraTopic, RosImage, spawn_camera};
use avatarm_video::pixels::{PixelFormat, to_rgba};
use avatarm_video::threaded::{SourceEvent, add_threaded_source};
use avatarm_video::wake::FrameWake;
use bevy::prelude::*;

/// Reads the ROS 2 camera `topic`; see the module docs.
pub struct Ros2CameraPlugin(pub CameraTopic);

impl Plugin for Ros2CameraPlugin {
    fn build(&self, app: &mut App) {
        let name = format!("ROS 2 camera {}", self.0.topic);
        let (tx, rx) = channel();
        let (ros_tx, ros_rx) = channel();
        let wake = FrameWake::of(app);
        if let Err(e) = spawn_camera(self.0.clone(), ros_tx) {
            let _ = tx.send(SourceEvent::Failed(format!(
                "{name}: cannot start its thread: {e}"
            )));
        } else {
            let forward_name = name.clone();
            let spawned = std::thread::Builder::new()
                .name("ros2 camera decode".into())
                .spawn(move || forward(&forward_name, &ros_rx, &tx, &wake));
            if let Err(e) = spawned {
                error!("{name}: cannot start the decoding thread: {e}");
            }
        }
        add_threaded_source(app, name, rx);
    }
}

/// Decodes each frame the camera thread hands over and sends it on, until either side is gone.
fn forward(
    name: &str,
    frames: &std::sync::mpsc::Receiver<CameraEvent>,
    tx: &Sender<SourceEvent>,
    wake: &FrameWake,
) {
    let mut clock_said = false;
    let mut last_error = String::new();
    for (index, event) in frames.iter().enumerate() {
        let event = match event {
            CameraEvent::Opened(what) => SourceEvent::Opened(what),
            CameraEvent::Failed(why) => SourceEvent::Failed(why),
            CameraEvent::Frame(frame) => {
                let age_s = frame.arrival_unix_s - frame.stamp_unix_s;
                let age = if frame.stamp_unix_s > 0.0 && (0.0..=2.0).contains(&age_s) {
                    Duration::from_secs_f64(age_s)
                } else {
                    if !clock_said {
                        clock_said = true;
                        warn!(
                            "{name}: a frame stamped {age_s:.3} s before its arrival: the camera's clock is not this machine's; its frames are taken as captured on arrival"
                        );
                    }
                    Duration::ZERO
                };
                let captured = frame.arrival.checked_sub(age).unwrap_or(frame.arrival);
                match decode(&frame) {
                    Ok((width, height, rgba)) => SourceEvent::Frame {
                        index: index as u64,
                        captured,
                        width,
                        height,
                        rgba,
                    },
                    // A bad frame is skipped and the stream goes on; each new cause said once.
                    Err(why) => {
                        if why != last_error {
                            warn!(
                                "{name}: frame {index}: {why} (frames failing alike are skipped)"
                            );
                            last_error = why;
                        }
                        continue;
                    }
                }
            }
        };
        let stop = matches!(event, SourceEvent::Failed(_));
        if tx.send(event).is_err() || stop {
            return;
        }
        wake.notify();
    }
}

/// A frame as (width, height, RGBA8): a compressed file (JPEG, PNG) decoded, or a raw frame of
/// REP 118's `rgb8`, `bgr8`, `rgba8`, `bgra8`, `mono8`, rows `step` bytes apart.
fn decode(frame: &RosImage) -> Result<(u32, u32, Vec<u8>), String> {
    if frame.compressed {
        let picture = image::load_from_memory(&frame.data)
            .map_err(|e| format!("'{}' does not decode: {e}", frame.encoding))?
            .to_rgba8();
        let (w, h) = picture.dimensions();
        return Ok((w, h, picture.into_raw()));
    }
    let (w, h) = (frame.width as usize, frame.height as usize);
    let channels = match frame.encoding.as_str() {
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" => 4,
        "mono8" => 1,
        other => {
            return Err(format!(
                "encoding '{other}' is not read (rgb8, bgr8, rgba8, bgra8, mono8; or a /compressed topic)"
            ));
        }
    };
    let row = w * channels;
    let step = frame.step as usize;
    if w == 0 || h == 0 || step < row || frame.data.len() < step * (h - 1) + row {
        return Err(format!(
            "{w}x{h} {} with step {step} and {} bytes does not fit",
            frame.encoding,
            frame.data.len()
        ));
    }
    let packed: Vec<u8> = (0..h)
        .flat_map(|y| &frame.data[y * step..y * step + row])
        .copied()
        .collect();
    let format = match frame.encoding.as_str() {
        "rgb8" => PixelFormat::Rgb,
        "bgr8" => PixelFormat::Bgr,
        "mono8" => PixelFormat::Gray,
        "rgba8" => return Ok((frame.width, frame.height, packed)),
        _ => {
            // bgra8: swap R and B.
            let mut rgba = packed;
            rgba.chunks_exact_mut(4).for_each(|p| p.swap(0, 2));
            return Ok((frame.width, frame.height, rgba));
        }
    };
    to_rgba(format, frame.width, frame.height, &packed)
        .map(|rgba| (frame.width, frame.height, rgba))
        .map_err(|e| e.to_string())
}
