//! A camera from ROS 2 (a lab's `usb_cam`, `realsense2_camera`, `v4l2_camera` driver): its
//! `sensor_msgs/msg/Image` or, on a topic ending in `/compressed` (image_transport's
//! convention), `sensor_msgs/msg/CompressedImage`, subscribed over DDS or rmw_zenoh on a thread of its own
//! and handed over as they arrive, stamped, undecoded (the app decodes, off this crate: no
//! image codecs here). Best effort, the last 2: a camera's frames are sensor data, and a late
//! frame is worth less than the next.

use std::sync::mpsc::Sender;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::Header;
use super::node::{self, Qos, Ros2Message, ros2_message};
use crate::settings::Ros2Transport;

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Image {
    /// Stamp (the capture) and the camera's optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// The pixel encoding (`rgb8`, `bgr8`, `mono8`, ...; REP 118's names).
    pub encoding: String,
    /// Big-endian multi-byte pixels.
    pub is_bigendian: u8,
    /// Bytes from one row to the next.
    pub step: u32,
    /// The pixels.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}
ros2_message!(
    Image,
    "sensor_msgs",
    "Image",
    hiroz_msgs::sensor_msgs::Image
);

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Stamp (the capture) and the camera's optical frame.
    pub header: Header,
    /// `jpeg`, `png` (image_transport writes e.g. `rgb8; jpeg compressed bgr8`).
    pub format: String,
    /// The file's bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}
ros2_message!(
    CompressedImage,
    "sensor_msgs",
    "CompressedImage",
    hiroz_msgs::sensor_msgs::CompressedImage
);

/// Which camera topic, on which domain and middleware.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraTopic {
    /// The domain and namespace.
    pub transport: Ros2Transport,
    /// The topic: raw `Image`, or `CompressedImage` where it ends in `/compressed`.
    pub topic: String,
    /// This node's name.
    pub node_name: String,
}

impl CameraTopic {
    /// Whether the topic carries `CompressedImage` (image_transport's `/compressed`).
    pub fn compressed(&self) -> bool {
        self.topic.trim_end_matches('/').ends_with("/compressed")
    }
}

/// A frame as it arrived.
#[derive(Debug, Clone)]
pub struct RosImage {
    /// The header's stamp (s since the Unix epoch, the camera driver's clock); 0 where unset.
    pub stamp_unix_s: f64,
    /// When it arrived here.
    pub arrival: Instant,
    /// The system clock at its arrival (s since the Unix epoch).
    pub arrival_unix_s: f64,
    /// Size (px); 0 for a compressed frame (its file says).
    pub width: u32,
    /// Rows; 0 for a compressed frame.
    pub height: u32,
    /// A raw frame's encoding, or a compressed frame's `format`.
    pub encoding: String,
    /// A raw frame's row step (bytes); 0 for a compressed frame.
    pub step: u32,
    /// A raw frame's big-endian flag.
    pub is_bigendian: bool,
    /// The pixels, or the compressed file.
    pub data: Vec<u8>,
    /// Whether `data` is a compressed file (JPEG, PNG).
    pub compressed: bool,
}

/// What the camera's thread hands over.
#[derive(Debug)]
pub enum CameraEvent {
    /// Subscribed: what, for the log.
    Opened(String),
    /// A frame.
    Frame(RosImage),
    /// The subscription failed for good: why.
    Failed(String),
}

fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Starts the camera's thread: it subscribes and sends each frame to `events` until the
/// receiver is gone. Errors: the thread could not start (the middleware's errors arrive as
/// [`CameraEvent::Failed`]).
pub fn spawn_camera(topic: CameraTopic, events: Sender<CameraEvent>) -> std::io::Result<()> {
    std::thread::Builder::new()
        .name(format!("ros2 camera {}", topic.topic))
        .spawn(move || {
            let Some(runtime) =
                crate::client::link_runtime("ROS 2 camera", crate::client::Threads::WithWorker)
            else {
                let _ = events.send(CameraEvent::Failed("ROS 2 camera: no runtime".to_owned()));
                return;
            };
            if let Err(e) = runtime.block_on(subscribe(&topic, &events)) {
                let _ = events.send(CameraEvent::Failed(format!(
                    "ROS 2 camera {} ({}): {e}",
                    topic.topic,
                    topic.transport.describe()
                )));
            }
        })
        .map(|_| ())
}

/// A message on the camera's topic that does not decode as the type: said once.
fn bad_frame(topic: &str, e: &str, said: &mut bool) {
    if !*said {
        *said = true;
        eprintln!(
            "ROS 2 camera {topic}: a frame that does not decode: {e} (further ones are not said)"
        );
    }
}

async fn subscribe(topic: &CameraTopic, events: &Sender<CameraEvent>) -> Result<(), String> {
    let (mut spin, mut node) = node::join(&topic.transport, &topic.node_name)?;
    // A camera's frames are sensor data: best effort, the last 2.
    let qos = Qos::best_effort(2);
    let kind = if topic.compressed() {
        "CompressedImage"
    } else {
        "Image"
    };
    let _ = events.send(CameraEvent::Opened(format!(
        "sensor_msgs/msg/{kind} on {} ({})",
        topic.topic,
        topic.transport.describe()
    )));
    if topic.compressed() {
        let sub = node.subscribe::<CompressedImage>(&topic.topic, qos)?;
        return forward(
            &topic.topic,
            &sub,
            &mut spin,
            events,
            |m: CompressedImage| RosImage {
                stamp_unix_s: m.header.stamp.as_secs_f64(),
                arrival: Instant::now(),
                arrival_unix_s: unix_now_s(),
                width: 0,
                height: 0,
                encoding: m.format,
                step: 0,
                is_bigendian: false,
                data: m.data,
                compressed: true,
            },
        )
        .await;
    }
    let sub = node.subscribe::<Image>(&topic.topic, qos)?;
    forward(&topic.topic, &sub, &mut spin, events, |m: Image| RosImage {
        stamp_unix_s: m.header.stamp.as_secs_f64(),
        arrival: Instant::now(),
        arrival_unix_s: unix_now_s(),
        width: m.width,
        height: m.height,
        encoding: m.encoding,
        step: m.step,
        is_bigendian: m.is_bigendian != 0,
        data: m.data,
        compressed: false,
    })
    .await
}

/// Each message of `sub` as a frame (`frame` makes it) to `events`, until the receiver is gone
/// (Ok), or the node stops (Err).
async fn forward<M: Ros2Message>(
    topic: &str,
    sub: &node::Subscription<M>,
    spin: &mut node::Spin,
    events: &Sender<CameraEvent>,
    frame: impl Fn(M) -> RosImage,
) -> Result<(), String> {
    let mut said = false;
    loop {
        tokio::select! {
            m = sub.recv() => match m {
                Ok(m) => {
                    if events.send(CameraEvent::Frame(frame(m))).is_err() {
                        return Ok(());
                    }
                }
                Err(e) => bad_frame(topic, &e, &mut said),
            },
            why = &mut *spin => return Err(why),
        }
    }
}
