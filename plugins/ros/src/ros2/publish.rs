//! What Avatarm does, published on ROS 2 (DDS or rmw_zenoh) so that rviz2, Foxglove and `ros2 topic echo`
//! show it: the erased video and the mask (`sensor_msgs/msg/CompressedImage`, image_transport's
//! `/compressed` convention), the joint velocity commands (`sensor_msgs/msg/JointState`, names
//! and velocities) and the safety events (`std_msgs/msg/String`), under a prefix (`/avatarm`
//! by default). A thread of its own with its own runtime and node; [`Ros2Publisher::publish`]
//! never blocks: a message that finds the queue full is dropped and counted (a late frame is
//! worth less than the next).
//!
//! | topic | type |
//! |---|---|
//! | `PREFIX/erased/compressed` | `CompressedImage`, `format = "jpeg"`: the frame with the robot erased |
//! | `PREFIX/mask/compressed` | `CompressedImage`, `format = "png"`: M(t), 255 = robot |
//! | `PREFIX/joint_commands` | `JointState`: `name`, `velocity` (rad/s or m/s) of each command sent |
//! | `PREFIX/safety` | `String`: `LEVEL source: message` |
//!
//! All reliable, keep last 2 (a reliable writer matches reliable and best-effort readers).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};

use super::camera::CompressedImage;
use super::node::{self, Qos, ros2_message};
use super::{Header, JointState, Time};
use crate::settings::Ros2Transport;

/// `std_msgs/msg/String`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct StringMsg {
    /// The text.
    pub data: String,
}
ros2_message!(
    StringMsg,
    "std_msgs",
    "String",
    hiroz_msgs::std_msgs::String
);

/// One message to publish; stamps are ns since the Unix epoch.
#[derive(Debug, Clone)]
pub enum Outgoing {
    /// An erased frame as JPEG.
    Erased {
        /// The frame's capture.
        stamp_ns: u64,
        /// The JPEG file.
        jpeg: Vec<u8>,
    },
    /// A mask as PNG (255 = robot).
    Mask {
        /// The frame's capture.
        stamp_ns: u64,
        /// The PNG file.
        png: Vec<u8>,
    },
    /// A joint velocity command.
    Command {
        /// The control tick.
        stamp_ns: u64,
        /// The joints, in the velocities' order.
        names: Vec<String>,
        /// rad/s or m/s.
        velocities: Vec<f64>,
    },
    /// A safety event.
    Safety {
        /// When.
        stamp_ns: u64,
        /// `LEVEL source: message`.
        text: String,
    },
}

/// The publishing thread's handle (a clone hands to the same thread); see the module docs.
#[derive(Clone)]
pub struct Ros2Publisher {
    tx: tokio::sync::mpsc::Sender<Outgoing>,
    dropped: Arc<AtomicU64>,
}

/// Messages that may wait for the thread before new ones are dropped.
const QUEUE: usize = 64;

fn header(stamp_ns: u64, frame_id: &str) -> Header {
    Header {
        stamp: Time {
            sec: i32::try_from(stamp_ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (stamp_ns % 1_000_000_000) as u32,
        },
        frame_id: frame_id.to_owned(),
    }
}

impl Ros2Publisher {
    /// Starts the thread publishing under `prefix` (e.g. `/avatarm`) on `transport`'s domain,
    /// as the node `node_name`; `camera_frame` is the images' `frame_id`. Errors: the thread
    /// could not start (the middleware's errors are said on stderr once, and the messages
    /// dropped).
    pub fn start(
        transport: Ros2Transport,
        node_name: &str,
        prefix: &str,
        camera_frame: &str,
    ) -> std::io::Result<Self> {
        let (tx, rx) = tokio::sync::mpsc::channel(QUEUE);
        let (node_name, prefix, frame) = (
            node_name.to_owned(),
            prefix.trim_end_matches('/').to_owned(),
            camera_frame.to_owned(),
        );
        std::thread::Builder::new()
            .name("ros2 publisher".into())
            .spawn(move || {
                let Some(runtime) = crate::client::link_runtime(
                    "ROS 2 publisher",
                    crate::client::Threads::WithWorker,
                ) else {
                    return;
                };
                if let Err(e) = runtime.block_on(run(&transport, &node_name, &prefix, &frame, rx)) {
                    eprintln!(
                        "ROS 2 publisher ({}): {e}; nothing is published",
                        transport.describe()
                    );
                }
            })?;
        Ok(Self {
            tx,
            dropped: Arc::default(),
        })
    }

    /// Hands `message` to the thread; `false` (and counted) when the queue is full or the
    /// thread is gone.
    pub fn publish(&self, message: Outgoing) -> bool {
        let sent = self.tx.try_send(message).is_ok();
        if !sent {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        sent
    }

    /// Messages dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

async fn run(
    transport: &Ros2Transport,
    node_name: &str,
    prefix: &str,
    frame: &str,
    mut rx: tokio::sync::mpsc::Receiver<Outgoing>,
) -> Result<(), String> {
    let (mut spin, mut node) = node::join(transport, node_name)?;
    let qos = Qos::reliable(2);
    let topic = |base: &str| format!("{prefix}/{base}");
    let erased = node.publisher::<CompressedImage>(&topic("erased/compressed"), qos)?;
    let mask = node.publisher::<CompressedImage>(&topic("mask/compressed"), qos)?;
    let commands = node.publisher::<JointState>(&topic("joint_commands"), qos)?;
    let safety = node.publisher::<StringMsg>(&topic("safety"), qos)?;
    let mut failed_said = false;
    loop {
        let message = tokio::select! {
            m = rx.recv() => match m {
                Some(m) => m,
                None => return Ok(()),
            },
            why = &mut spin => return Err(why),
        };
        let result = match message {
            Outgoing::Erased { stamp_ns, jpeg } => erased
                .publish(CompressedImage {
                    header: header(stamp_ns, frame),
                    format: "jpeg".into(),
                    data: jpeg,
                })
                .await
                .map_err(|e| format!("erased: {e}")),
            Outgoing::Mask { stamp_ns, png } => mask
                .publish(CompressedImage {
                    header: header(stamp_ns, frame),
                    format: "png".into(),
                    data: png,
                })
                .await
                .map_err(|e| format!("mask: {e}")),
            Outgoing::Command {
                stamp_ns,
                names,
                velocities,
            } => commands
                .publish(JointState {
                    header: header(stamp_ns, ""),
                    name: names,
                    position: Vec::new(),
                    velocity: velocities,
                    effort: Vec::new(),
                })
                .await
                .map_err(|e| format!("joint_commands: {e}")),
            Outgoing::Safety { stamp_ns: _, text } => safety
                .publish(StringMsg { data: text })
                .await
                .map_err(|e| format!("safety: {e}")),
        };
        if let Err(e) = result
            && !failed_said
        {
            failed_said = true;
            eprintln!("ROS 2 publisher: {e} (further failures are not said)");
        }
    }
}
