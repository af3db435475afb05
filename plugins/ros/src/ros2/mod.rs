//! The link over ROS 2 (feature `ros2`): a ros2_control arm through DDS (`ros2-client` over
//! RustDDS) or rmw_zenoh (`hiroz`), both pure Rust (no ROS install to build or run), on the
//! link's own thread and runtime ([`node`]), behind the same [`crate::RosArm`] (its safety
//! checks, clock and stops) as the ROS 1 link.
//!
//! - In: `sensor_msgs/msg/JointState` (best effort, which matches a reliable or best-effort
//!   publisher such as ros2_control's `joint_state_broadcaster`).
//! - Out: `std_msgs/msg/Float64MultiArray` to a `forward_command_controller` (a
//!   `JointGroupVelocityController` or `JointGroupPositionController`: one value per joint in
//!   the controller's order), reliable, on `/<controller>/commands`; or
//!   `trajectory_msgs/msg/JointTrajectory` streamed to a `joint_trajectory_controller` on
//!   `/<controller>/joint_trajectory` ([`crate::CommandKind::JointTrajectory`]).
//!
//! ROS 2 has no master: the link is up once the node exists, and alive while joint states
//! arrive (a vanished robot node is a stale link, which stops the arm). Names follow each
//! middleware's conventions (DDS: the topic `rt/<name>`, the type `<pkg>::msg::dds_::<Type>_`;
//! rmw_zenoh: `<domain>/<name>/<type>/<REP-2016 hash>`), which the libraries apply.
//!
//! [`camera`]: a camera from ROS 2 (`Image` or `CompressedImage`) as a live camera source;
//! [`calibration`]: its `CameraInfo` and the transform tree, gathered before it is used;
//! [`publish`]: the erased video, the mask, the commands and the safety events published.

pub mod calibration;
pub mod camera;
pub(crate) mod node;
pub mod publish;

use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::client::{Outbound, Sample, Shared};
use crate::settings::{LinkSettings, Ros2Transport};
use node::{Qos, ros2_message};

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
ros2_message!(
    JointState,
    "sensor_msgs",
    "JointState",
    hiroz_msgs::sensor_msgs::JointState
);

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
ros2_message!(
    Float64MultiArray,
    "std_msgs",
    "Float64MultiArray",
    hiroz_msgs::std_msgs::Float64MultiArray
);

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
ros2_message!(
    JointTrajectory,
    "trajectory_msgs",
    "JointTrajectory",
    hiroz_msgs::trajectory_msgs::JointTrajectory
);

/// The command publisher of the link's controller.
enum Commands {
    /// A forward_command_controller's `Float64MultiArray`.
    Group(node::Publisher<Float64MultiArray>),
    /// A joint_trajectory_controller's one-point `JointTrajectory`.
    Trajectory {
        publisher: node::Publisher<JointTrajectory>,
        joints: Vec<String>,
        horizon_s: f64,
    },
}

impl Commands {
    /// Publishes `values` (one per controller joint, in its order).
    async fn publish(&self, data: Vec<f64>) -> Result<(), String> {
        match self {
            Self::Group(p) => {
                p.publish(Float64MultiArray {
                    layout: MultiArrayLayout::default(),
                    data,
                })
                .await
            }
            Self::Trajectory {
                publisher,
                joints,
                horizon_s,
            } => {
                publisher
                    .publish(JointTrajectory {
                        header: Header::default(),
                        joint_names: joints.clone(),
                        points: vec![JointTrajectoryPoint {
                            positions: data,
                            time_from_start: RosDuration::from_secs(*horizon_s),
                            ..JointTrajectoryPoint::default()
                        }],
                    })
                    .await
            }
        }
    }
}

/// The client thread: a runtime (one worker beside it, for Zenoh) holding the node, the joint-state
/// subscription and the command publisher until shutdown.
pub(crate) fn client_thread(
    settings: LinkSettings,
    transport: Ros2Transport,
    shared: Arc<Mutex<Shared>>,
    notify: Arc<tokio::sync::Notify>,
    tx: Sender<Sample>,
) {
    let Some(runtime) =
        crate::client::link_runtime("ROS 2 link", crate::client::Threads::WithWorker)
    else {
        return;
    };
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
                        "ROS 2 link ({}): {e}; retrying every second",
                        transport.describe()
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

/// The session: runs until shutdown or the app is gone (Ok) or until the node cannot be set up
/// or stops (Err, the caller retries).
async fn session(
    settings: &LinkSettings,
    transport: &Ros2Transport,
    shared: &Arc<Mutex<Shared>>,
    notify: &Arc<tokio::sync::Notify>,
    tx: &Sender<Sample>,
) -> Result<(), String> {
    let (mut spin, mut node) = node::join(transport, &settings.node_name)?;
    // Best effort, the last 10: matches reliable and best-effort publishers alike.
    let states =
        node.subscribe::<JointState>(&settings.joint_states_topic, Qos::best_effort(10))?;
    let commands = match &settings.command {
        crate::CommandKind::JointTrajectory {
            joints, horizon_s, ..
        } => Commands::Trajectory {
            publisher: node.publisher(&settings.command_topic, Qos::reliable(1))?,
            joints: joints.clone(),
            horizon_s: *horizon_s,
        },
        _ => Commands::Group(node.publisher(&settings.command_topic, Qos::reliable(1))?),
    };
    if let Ok(mut s) = shared.lock() {
        s.status.connected = true;
        s.status.connects += 1;
        s.outbound = None;
    }
    let max_age = Duration::from_secs_f64(settings.stale_after_s.min(settings.command_timeout_s));
    let mut publish_said = false;
    loop {
        tokio::select! {
            m = states.recv() => match m {
                Ok(m) => {
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
                Err(e) => {
                    if let Ok(mut s) = shared.lock() {
                        s.status.bad_joint_states += 1;
                        s.status.last_bad = Some(e);
                    }
                }
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
            why = &mut spin => return Err(why),
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
