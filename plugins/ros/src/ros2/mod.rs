//! The link over ROS 2 (feature `ros2`): a ros2_control arm through DDS, spoken by
//! `ros2-client` over RustDDS (pure Rust, no ROS install to build or run), on the link's own
//! thread and runtime, behind the same [`crate::RosArm`] (its safety checks, clock and stops)
//! as the ROS 1 link.
//!
//! - In: `sensor_msgs/msg/JointState` (best effort, which matches a reliable or best-effort
//!   publisher such as ros2_control's `joint_state_broadcaster`).
//! - Out: `std_msgs/msg/Float64MultiArray` to a `forward_command_controller` (a
//!   `JointGroupVelocityController` or `JointGroupPositionController`: one value per joint in
//!   the controller's order), reliable, on `/<controller>/commands`; or
//!   `trajectory_msgs/msg/JointTrajectory` streamed to a `joint_trajectory_controller` on
//!   `/<controller>/joint_trajectory` ([`crate::CommandKind::JointTrajectory`]).
//!
//! DDS has no master: the link is up once the participant and node exist, and alive while
//! joint states arrive (a vanished robot node is a stale link, which stops the arm). Names
//! follow ROS 2's DDS conventions (the topic `rt/<name>`, the type
//! `<pkg>::msg::dds_::<Type>_`), which `ros2-client` applies.
//!
//! [`camera`]: a camera from ROS 2 (`Image` or `CompressedImage`) as a live camera source;
//! [`calibration`]: its `CameraInfo` and the transform tree, gathered before it is used;
//! [`publish`]: the erased video, the mask, the commands and the safety events published.

pub mod calibration;
pub mod camera;
pub mod publish;

use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures::StreamExt;
use ros2_client::{
    Context, ContextOptions, Message, MessageTypeName, Name, NodeName, NodeOptions, QosProfile,
};
use serde::{Deserialize, Serialize};

use crate::client::{Outbound, Sample, Shared};
use crate::settings::{LinkSettings, Ros2Transport};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds since the epoch.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// Seconds since the epoch.
    pub fn as_secs_f64(&self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }

    /// Nanoseconds since the epoch; `None` before it (a negative `sec`).
    pub fn as_nanos(&self) -> Option<u64> {
        u64::try_from(self.sec)
            .ok()
            .map(|s| s * 1_000_000_000 + u64::from(self.nanosec))
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Header {
    /// The stamp.
    pub stamp: Time,
    /// The frame.
    pub frame_id: String,
}

/// `sensor_msgs/msg/JointState`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp and frame.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions (rad or m).
    pub position: Vec<f64>,
    /// Velocities (rad/s or m/s).
    pub velocity: Vec<f64>,
    /// Efforts (N m or N).
    pub effort: Vec<f64>,
}
impl Message for JointState {}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MultiArrayDimension {
    /// The dimension's label.
    pub label: String,
    /// Its size.
    pub size: u32,
    /// Its stride.
    pub stride: u32,
}

/// `std_msgs/msg/MultiArrayLayout`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct MultiArrayLayout {
    /// The dimensions.
    pub dim: Vec<MultiArrayDimension>,
    /// Padding before the data.
    pub data_offset: u32,
}

/// `std_msgs/msg/Float64MultiArray`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Float64MultiArray {
    /// The layout (empty: a plain vector, as forward_command_controller takes it).
    pub layout: MultiArrayLayout,
    /// The values.
    pub data: Vec<f64>,
}
impl Message for Float64MultiArray {}

/// `builtin_interfaces/msg/Duration`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RosDuration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl RosDuration {
    /// `s` seconds (finite, >= 0; rounded to the nanosecond).
    pub fn from_secs(s: f64) -> Self {
        let ns = (s.max(0.0) * 1e9).round() as u64;
        Self {
            sec: i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct JointTrajectoryPoint {
    /// Positions (rad or m), one per joint of the trajectory.
    pub positions: Vec<f64>,
    /// Velocities; empty: the controller interpolates positions.
    pub velocities: Vec<f64>,
    /// Accelerations; empty.
    pub accelerations: Vec<f64>,
    /// Efforts; empty.
    pub effort: Vec<f64>,
    /// When the point is to be reached, from the trajectory's start.
    pub time_from_start: RosDuration,
}

/// `trajectory_msgs/msg/JointTrajectory`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct JointTrajectory {
    /// Stamp (zero: start on receipt).
    pub header: Header,
    /// The joints, in the order of each point's values.
    pub joint_names: Vec<String>,
    /// The points.
    pub points: Vec<JointTrajectoryPoint>,
}
impl Message for JointTrajectory {}

/// The command publisher of the link's controller.
enum Commands {
    /// A forward_command_controller's `Float64MultiArray`.
    Group(ros2_client::Publisher<Float64MultiArray>),
    /// A joint_trajectory_controller's one-point `JointTrajectory`.
    Trajectory {
        publisher: ros2_client::Publisher<JointTrajectory>,
        joints: Vec<String>,
        horizon_s: f64,
    },
}

impl Commands {
    /// Publishes `values` (one per controller joint, in its order).
    async fn publish(&self, data: Vec<f64>) -> Result<(), String> {
        match self {
            Self::Group(p) => p
                .async_publish(Float64MultiArray {
                    layout: MultiArrayLayout::default(),
                    data,
                })
                .await
                .map_err(|e| format!("{e:?}")),
            Self::Trajectory {
                publisher,
                joints,
                horizon_s,
            } => publisher
                .async_publish(JointTrajectory {
                    header: Header::default(),
                    joint_names: joints.clone(),
                    points: vec![JointTrajectoryPoint {
                        positions: data,
                        time_from_start: RosDuration::from_secs(*horizon_s),
                        ..JointTrajectoryPoint::default()
                    }],
                })
                .await
                .map_err(|e| format!("{e:?}")),
        }
    }
}

/// A ROS 2 topic name (`/ns/base`, or relative to the node's namespace) for ros2-client.
fn topic_name(topic: &str) -> Result<Name, String> {
    Name::parse(topic).map_err(|e| format!("topic '{topic}': not a ROS 2 name: {e:?}"))
}

/// A node `node_name` on `transport`'s DDS domain (its context, which must outlive it) and its
/// spinner's future (ros2-client's graph and discovery events: polled beside the node's work).
/// Errors say which step failed.
pub(crate) fn join(
    transport: &Ros2Transport,
    node_name: &str,
) -> Result<
    (
        Context,
        ros2_client::Node,
        impl std::future::Future<Output = ros2_client::CreateResult<()>>,
    ),
    String,
> {
    let context = Context::with_options(ContextOptions::new().domain_id(transport.domain_id))
        .map_err(|e| format!("cannot join DDS: {e:?}"))?;
    let name = NodeName::new(&transport.namespace, node_name)
        .map_err(|e| format!("node name '{node_name}': {e:?}"))?;
    let mut node = context
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| format!("cannot create the node: {e:?}"))?;
    let spin = node
        .spinner()
        .map_err(|e| format!("cannot spin the node: {e:?}"))?
        .spin();
    Ok((context, node, spin))
}

/// The client thread: a single-threaded runtime holding the DDS participant, its node, the
/// joint-state subscription and the command publisher until shutdown.
pub(crate) fn client_thread(
    settings: LinkSettings,
    transport: Ros2Transport,
    shared: Arc<Mutex<Shared>>,
    notify: Arc<tokio::sync::Notify>,
    tx: Sender<Sample>,
) {
    let Some(runtime) = crate::client::link_runtime("ROS 2 link") else {
        return;
    };
    if let Ok(mut s) = shared.lock() {
        s.status.dds = true;
    }
    // As the ROS 1 link: a session that fails is said once and tried again every second.
    let mut said = false;
    loop {
        if shared.lock().map_or(true, |s| s.shutdown) {
            break;
        }
        match runtime.block_on(session(&settings, &transport, &shared, &notify, &tx)) {
            Ok(()) => break,
            Err(e) => {
                if let Ok(mut s) = shared.lock() {
                    s.status.connected = false;
                    s.status.last_bad = Some(e.clone());
                }
                if !said {
                    said = true;
                    eprintln!(
                        "ROS 2 link (DDS domain {}): {e}; retrying every second",
                        transport.domain_id
                    );
                }
                std::thread::sleep(Duration::from_secs(1));
            }
        }
    }
    if let Ok(mut s) = shared.lock() {
        s.status.connected = false;
        s.finished = true;
    }
}

/// The session: runs until shutdown or the app is gone (Ok) or until DDS cannot be set up or
/// its node stops (Err, the caller retries).
async fn session(
    settings: &LinkSettings,
    transport: &Ros2Transport,
    shared: &Arc<Mutex<Shared>>,
    notify: &Arc<tokio::sync::Notify>,
    tx: &Sender<Sample>,
) -> Result<(), String> {
    let (_context, mut node, spin) = join(transport, &settings.node_name)?;
    let states_topic = node
        .create_topic(
            &topic_name(&settings.joint_states_topic)?,
            MessageTypeName::new("sensor_msgs", "JointState"),
            &QosProfile::subscription_default(),
        )
        .map_err(|e| format!("{}: {e:?}", settings.joint_states_topic))?;
    // Best effort, the last 10: matches reliable and best-effort publishers alike.
    let states = node
        .create_subscription::<JointState>(
            &states_topic,
            Some(
                QosProfile::subscription_default()
                    .history(ros2_client::qos::History::KeepLast { depth: 10 }),
            ),
        )
        .map_err(|e| format!("{}: {e:?}", settings.joint_states_topic))?;
    let command_type = match &settings.command {
        crate::CommandKind::JointTrajectory { .. } => {
            MessageTypeName::new("trajectory_msgs", "JointTrajectory")
        }
        _ => MessageTypeName::new("std_msgs", "Float64MultiArray"),
    };
    let command_topic = node
        .create_topic(
            &topic_name(&settings.command_topic)?,
            command_type,
            &QosProfile::publisher_default(),
        )
        .map_err(|e| format!("{}: {e:?}", settings.command_topic))?;
    let bad_topic = |e| format!("{}: {e:?}", settings.command_topic);
    let commands = match &settings.command {
        crate::CommandKind::JointTrajectory {
            joints, horizon_s, ..
        } => Commands::Trajectory {
            publisher: node
                .create_publisher::<JointTrajectory>(&command_topic, None)
                .map_err(bad_topic)?,
            joints: joints.clone(),
            horizon_s: *horizon_s,
        },
        _ => Commands::Group(
            node.create_publisher::<Float64MultiArray>(&command_topic, None)
                .map_err(bad_topic)?,
        ),
    };
    if let Ok(mut s) = shared.lock() {
        s.status.connected = true;
        s.status.connects += 1;
        s.outbound = None;
    }
    let max_age = Duration::from_secs_f64(settings.stale_after_s.min(settings.command_timeout_s));
    let mut publish_said = false;
    let mut stream = std::pin::pin!(states.async_stream());
    let mut spin = std::pin::pin!(spin);
    loop {
        tokio::select! {
            m = stream.next() => match m {
                Some(Ok((m, _))) => {
                    let sample = Sample {
                        arrival: Instant::now(),
                        stamp_s: m.header.stamp.as_secs_f64(),
                        names: m.name,
                        position: m.position,
                        velocity: m.velocity,
                    };
                    if tx.send(sample).is_err() {
                        return Ok(());
                    }
                }
                Some(Err(e)) => {
                    if let Ok(mut s) = shared.lock() {
                        s.status.bad_joint_states += 1;
                        s.status.last_bad = Some(format!("{e:?}"));
                    }
                }
                None => return Err("the joint-state subscription closed".into()),
            },
            () = notify.notified() => {
                match send_outbound(settings, shared, &commands, max_age).await {
                    Ok(true) => return Ok(()),
                    Ok(false) => {}
                    // A command that could not go out (the writer's window full): counted and
                    // said once; the next command is the newest anyway.
                    Err(e) => {
                        if let Ok(mut s) = shared.lock() {
                            s.status.commands_refused += 1;
                        }
                        if !publish_said {
                            publish_said = true;
                            eprintln!("ROS 2 link: {e} (further failures are counted)");
                        }
                    }
                }
            },
            r = &mut spin => {
                return Err(format!("the node's spinner stopped: {r:?}"));
            },
            () = tokio::time::sleep(Duration::from_secs(1)) => {
                if shared.lock().map_or(true, |s| s.shutdown) {
                    return Ok(());
                }
            },
        }
    }
}

/// Sends the newest joint command (unless older than `max_age`; a stop always). Returns
/// whether the link is shutting down (after giving the last command time to leave).
async fn send_outbound(
    settings: &LinkSettings,
    shared: &Arc<Mutex<Shared>>,
    commands: &Commands,
    max_age: Duration,
) -> Result<bool, String> {
    let (out, stop) = match shared.lock() {
        Ok(mut s) => {
            // ROS 2 links have no gripper yet: a gripper command is dropped here (the arm's
            // settings refuse one).
            s.gripper = None;
            (s.outbound.take(), s.shutdown)
        }
        Err(_) => (None, true),
    };
    let values = match out {
        Some(Outbound::Joints { values, at }) if at.elapsed() <= max_age => Some(values),
        Some(Outbound::Stop(values)) => Some(values),
        _ => None,
    };
    if let Some(data) = values {
        commands
            .publish(data)
            .await
            .map_err(|e| format!("{}: {e}", settings.command_topic))?;
    }
    if stop {
        // A reliable writer resends what was lost; give the stop time to arrive.
        tokio::time::sleep(Duration::from_millis(300)).await;
        if let Ok(mut s) = shared.lock() {
            s.finished = true;
        }
    }
    Ok(stop)
}
