//! The scene file as written: one struct per TOML table, documented in
//! `docs/scene-format.md`. [`crate::Scene::load`] parses these and checks every value.

use std::collections::BTreeMap;
use std::path::PathBuf;

use avatarm_core::dr::EraseSettings;
use avatarm_core::robot::GeometryKind;
use avatarm_core::sim::SimRobotParams;
use avatarm_core::vision::camera::{CameraPose, Intrinsics};
use avatarm_core::vision::sensor::SensorModel;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Deserialize;

use crate::prop::PropShape;
use crate::task::PouringTask;

/// A pose: position and roll-pitch-yaw (rad, fixed axes, as URDF).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// Position (m).
    #[serde(default)]
    pub xyz: [f64; 3],
    /// Roll, pitch, yaw (rad).
    #[serde(default)]
    pub rpy: [f64; 3],
}

impl PoseSpec {
    /// As an isometry.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.xyz[0], self.xyz[1], self.xyz[2]),
            UnitQuaternion::from_euler_angles(self.rpy[0], self.rpy[1], self.rpy[2]),
        )
    }
}

/// Joint positions, by name (`{ right_j0 = 0.1 }`) or in joint-vector order (`[0.1, ...]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum JointValues {
    /// By joint name.
    Named(BTreeMap<String, f64>),
    /// In joint-vector order (missing trailing joints keep their previous value).
    List(Vec<f64>),
}

/// `[robot]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// URDF file, relative to the scene file.
    pub urdf: PathBuf,
    /// Folders for `package://` URIs, relative to the scene file.
    #[serde(default)]
    pub package_path: Vec<PathBuf>,
    /// Pose of the robot's root link in the world.
    #[serde(default)]
    pub base: PoseSpec,
    /// Initial joint positions.
    pub q0: Option<JointValues>,
    /// Simulated robot timing and response.
    #[serde(default)]
    pub sim: SimRobotParams,
    /// The real robot's ROS 1 link (`[robot.link]`), used by `avatarm run --robot ros`.
    #[serde(default)]
    pub link: RobotLinkSpec,
}

/// How commands reach a ROS 1 robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobotLinkKind {
    /// A Rethink Sawyer through Intera: `intera_core_msgs/JointCommand` in velocity mode, the
    /// robot's enable and e-stop state obeyed, the electric gripper.
    #[default]
    Intera,
    /// Any arm with a ros_control joint group velocity or position controller
    /// (`controller`): `std_msgs/Float64MultiArray` in the controller's joint order.
    RosControl,
    /// Any arm with a ros2_control `forward_command_controller` (a joint group velocity or
    /// position controller) over ROS 2 (DDS, `domain_id`): `std_msgs/msg/Float64MultiArray`
    /// on its `/<controller>/commands`; joint states default to `/joint_states`.
    Ros2Control,
}

/// Which ros_control joint group controller a `ros_control` link commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RosControlController {
    /// `JointGroupVelocityController`: joint velocities.
    #[default]
    Velocity,
    /// `JointGroupPositionController`: position targets (the velocities integrated).
    Position,
    /// ros2_control's `joint_trajectory_controller` (`ros2_control` only): a one-point
    /// `JointTrajectory` streamed each tick, the point `command_timeout_s` ahead (the arm holds
    /// it once reached: a silent Avatarm stops the arm within that time).
    Trajectory,
}

/// The middleware of a `ros2_control` link (ROS 2's `RMW_IMPLEMENTATION`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ros2Rmw {
    /// DDS (rmw_cyclonedds_cpp, rmw_fastrtps_cpp, rmw_connextdds).
    Dds,
    /// rmw_zenoh (rmw_zenoh_cpp), through the Zenoh router `zenoh_router`.
    Zenoh,
}

/// `[robot.link]`: the real robot over ROS 1 (docs/robot-ros.md). Topic defaults are
/// Intera's for a right-arm Sawyer; a `ros_control` link has no robot state, command timeout,
/// speed ratio or gripper topics unless given.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotLinkSpec {
    /// `intera`, `ros_control` (ROS 1) or `ros2_control` (ROS 2).
    pub kind: RobotLinkKind,
    /// `ros2_control`: the domain (0..232); default: `ROS_DOMAIN_ID`, else 0.
    pub domain_id: Option<u16>,
    /// `ros2_control`: `dds` or `zenoh`; default: as `RMW_IMPLEMENTATION` says
    /// (`rmw_zenoh_cpp`: zenoh), else dds.
    pub rmw: Option<Ros2Rmw>,
    /// `ros2_control` on rmw_zenoh: the Zenoh router's endpoint; default
    /// `tcp/localhost:7447` (rmw_zenoh's).
    pub zenoh_router: Option<String>,
    /// `ros2_control`: the nodes' namespace (`/robot1`), against which relative topic names
    /// resolve (the joint states then default to `joint_states` in it); default `/`.
    pub namespace: Option<String>,
    /// The ROS master; default: `ROS_MASTER_URI`, else `http://localhost:11311`.
    pub master_uri: Option<String>,
    /// This node's name.
    pub node_name: String,
    /// `sensor_msgs/JointState` in; default `/robot/joint_states` (ROS 1: Intera's, and a
    /// `ros_control` arm's), `/joint_states` for `ros2_control` (its joint_state_broadcaster's).
    pub joint_states_topic: Option<String>,
    /// Commands out; default `/robot/limb/right/joint_command` (Intera).
    pub command_topic: Option<String>,
    /// The joints commanded; default: the task's arm joints (else every movable joint without
    /// "finger" in its name).
    pub arm_joints: Vec<String>,
    /// `ros_control`: the controller's joints, in its order (default: `arm_joints`).
    pub controller_joints: Vec<String>,
    /// `ros_control`/`ros2_control`: a `velocity` (default) or `position` joint group
    /// controller, or (`ros2_control`) a `trajectory` controller.
    pub controller: RosControlController,
    /// Intera's robot state (`/robot/state`); `""` for none.
    pub robot_state_topic: Option<String>,
    /// Latched command timeout topic (Intera's `/robot/limb/right/joint_command_timeout`);
    /// `""` for none.
    pub command_timeout_topic: Option<String>,
    /// The robot's command timeout (s, 0.01..5); for a `trajectory` controller, how far ahead
    /// each streamed point lies.
    pub command_timeout_s: f64,
    /// Latched speed ratio topic (Intera's `/robot/limb/right/set_speed_ratio`); `""` for
    /// none.
    pub speed_ratio_topic: Option<String>,
    /// The speed ratio of position moves (0 < r <= 1).
    pub speed_ratio: f64,
    /// Intera's gripper: the device of the end effector's IO node (`/io/end_effector`),
    /// e.g. `right_gripper`; default for `intera`: the first device the node's config names;
    /// `""` for none (the default for `ros_control`).
    pub gripper_device: Option<String>,
    /// Intera: the joint-state rate to set (Hz, 1..800, on `/robot/joint_state_publish_rate`);
    /// default: the robot's own (100 Hz).
    pub joint_state_rate_hz: Option<u16>,
    /// No joint state for this long (s) and the link is down: commands stop.
    pub stale_after_s: f64,
}

impl Default for RobotLinkSpec {
    fn default() -> Self {
        Self {
            kind: RobotLinkKind::Intera,
            domain_id: None,
            rmw: None,
            zenoh_router: None,
            namespace: None,
            master_uri: None,
            node_name: "avatarm".into(),
            joint_states_topic: None,
            command_topic: None,
            arm_joints: Vec::new(),
            controller_joints: Vec::new(),
            controller: RosControlController::Velocity,
            robot_state_topic: None,
            command_timeout_topic: None,
            command_timeout_s: 0.2,
            speed_ratio_topic: None,
            speed_ratio: 0.3,
            gripper_device: None,
            joint_state_rate_hz: None,
            stale_after_s: 0.2,
        }
    }
}

impl RobotLinkSpec {
    /// Checks the numbers; the message names the field.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |field: &str, message: String| Err((format!("robot.link.{field}"), message));
        if !(0.01..=5.0).contains(&self.command_timeout_s) {
            return bad(
                "command_timeout_s",
                format!("{} s: must be within 0.01..5", self.command_timeout_s),
            );
        }
        if !(self.speed_ratio > 0.0 && self.speed_ratio <= 1.0) {
            return bad(
                "speed_ratio",
                format!("{}: must be in (0, 1]", self.speed_ratio),
            );
        }
        if !(0.01..=5.0).contains(&self.stale_after_s) {
            return bad(
                "stale_after_s",
                format!("{} s: must be within 0.01..5", self.stale_after_s),
            );
        }
        match (self.kind, self.domain_id) {
            (RobotLinkKind::Ros2Control, Some(d)) if d > 232 => {
                return bad(
                    "domain_id",
                    format!("{d}: must be within 0..232 (ROS 2's ROS_DOMAIN_ID)"),
                );
            }
            (RobotLinkKind::Intera | RobotLinkKind::RosControl, Some(_)) => {
                return bad(
                    "domain_id",
                    "a ROS 1 link has no DDS domain (its master is master_uri); kind = \"ros2_control\" for ROS 2".into(),
                );
            }
            _ => {}
        }
        if self.kind != RobotLinkKind::Ros2Control && self.rmw.is_some() {
            return bad(
                "rmw",
                "a ROS 1 link speaks TCPROS through its master; kind = \"ros2_control\" for ROS 2"
                    .into(),
            );
        }
        if let Some(router) = &self.zenoh_router {
            let zenoh = self.kind == RobotLinkKind::Ros2Control && self.rmw != Some(Ros2Rmw::Dds);
            if !zenoh {
                return bad(
                    "zenoh_router",
                    "only a ros2_control link on rmw_zenoh has a Zenoh router".into(),
                );
            }
            // PROTOCOL/ADDRESS; an IP protocol's address ends in its port.
            let well_formed = router.split_once('/').is_some_and(|(p, a)| {
                let port = || {
                    a.rsplit_once(':')
                        .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok())
                };
                !p.is_empty()
                    && !a.is_empty()
                    && (!["tcp", "udp", "tls", "quic", "ws"].contains(&p) || port())
            });
            if !well_formed {
                return bad(
                    "zenoh_router",
                    format!(
                        "'{router}': a Zenoh endpoint is PROTOCOL/ADDRESS, e.g. tcp/localhost:7447"
                    ),
                );
            }
        }
        if let Some(ns) = &self.namespace {
            if self.kind != RobotLinkKind::Ros2Control {
                return bad(
                    "namespace",
                    "only a ros2_control link has a namespace here (a ROS 1 node's is ROS_NAMESPACE)".into(),
                );
            }
            let chunks_ok = ns == "/"
                || ns.strip_prefix('/').is_some_and(|rest| {
                    rest.split('/').all(|c| {
                        c.chars()
                            .next()
                            .is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
                            && c.chars().all(|x| x.is_ascii_alphanumeric() || x == '_')
                    })
                });
            if !chunks_ok {
                return bad(
                    "namespace",
                    format!(
                        "'{ns}': a ROS 2 namespace is / or /name[/name...], each name letters, digits and _, not starting with a digit"
                    ),
                );
            }
        }
        if self.kind == RobotLinkKind::Ros2Control && self.master_uri.is_some() {
            return bad(
                "master_uri",
                "a ROS 2 link has no master (DDS discovers its peers); leave it out".into(),
            );
        }
        if let Some(hz) = self.joint_state_rate_hz {
            if !(1..=800).contains(&hz) {
                return bad(
                    "joint_state_rate_hz",
                    format!("{hz} Hz: must be within 1..800"),
                );
            }
            if self.kind != RobotLinkKind::Intera {
                return bad(
                    "joint_state_rate_hz",
                    "only an Intera robot takes its joint-state rate from a topic".into(),
                );
            }
        }
        if let Some(d) = &self.gripper_device
            && d.contains('/')
        {
            return bad(
                "gripper_device",
                format!("'{d}': a device name (as /io/end_effector/config gives it), not a topic"),
            );
        }
        if self.controller == RosControlController::Trajectory
            && self.kind != RobotLinkKind::Ros2Control
        {
            return bad(
                "controller",
                "a joint_trajectory_controller is commanded over ROS 2 only (kind = \"ros2_control\")".into(),
            );
        }
        if self.kind == RobotLinkKind::Intera && self.controller != RosControlController::Velocity {
            return bad(
                "controller",
                "only a ros_control link has a group controller to choose (Intera takes velocities)"
                    .into(),
            );
        }
        if self.node_name.is_empty() {
            return bad("node_name", "must not be empty".into());
        }
        if self.joint_states_topic.as_deref() == Some("") {
            return bad(
                "joint_states_topic",
                "must not be empty: the link needs the robot's joint states (leave it out for the default)"
                    .into(),
            );
        }
        Ok(())
    }
}

/// Calibration error between the camera's true pose and the pose the app believes.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationError {
    /// Rotation error (degrees) about `axis` through the camera centre.
    pub rotation_deg: f64,
    /// Rotation axis (world).
    pub axis: [f64; 3],
    /// Translation error (mm, world).
    pub translation_mm: [f64; 3],
}

/// `[camera]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Intrinsics; when absent, `fov_y_deg` with `width` × `height`.
    pub intrinsics: Option<Intrinsics>,
    /// Vertical field of view (degrees), used when `intrinsics` is absent.
    #[serde(default = "default_fov")]
    pub fov_y_deg: f64,
    /// Width (px), with `fov_y_deg`.
    #[serde(default = "default_width")]
    pub width: u32,
    /// Height (px), with `fov_y_deg`.
    #[serde(default = "default_height")]
    pub height: u32,
    /// True pose of a fixed camera (required unless the camera rides on a head, `head`).
    #[serde(default)]
    pub pose: Option<CameraPose>,
    /// The camera moves with a head (`[camera.head]`: Alice's headset camera): its pose is the
    /// head's times the mount, and the mask follows the tracked head.
    #[serde(default)]
    pub head: Option<HeadSpec>,
    /// Frames per second.
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Delay from capture to arrival (s).
    #[serde(default)]
    pub frame_latency_s: f64,
    /// Noise and exposure.
    #[serde(default)]
    pub sensor: SensorModel,
    /// Error of the pose the app believes.
    #[serde(default)]
    pub calibration_error: CalibrationError,
    /// The lens's distortion (none: a pinhole). The simulated camera's frames are distorted
    /// by it and the mask honours it (`[erase] lens_distortion`).
    #[serde(default)]
    pub distortion: Option<LensSpec>,
}

/// `[camera.head]`: a camera on a head. The head's frame is an optical one (x right, y down,
/// z forward, the way the face points); `mount` places the camera in it. Exactly one of
/// `sweep` and `keyframes` says how the head moves. The camera's `calibration_error` is the
/// mount's error, in the head's frame.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadSpec {
    /// `head_from_camera` (default: the camera at the head's origin, looking where it looks).
    #[serde(default)]
    pub mount: PoseSpec,
    /// How the headset reports the head.
    #[serde(default)]
    pub tracking: TrackingSpec,
    /// Looking left and right about a centre pose.
    #[serde(default)]
    pub sweep: Option<HeadSweepSpec>,
    /// Look-at keyframes (minimum jerk between them).
    #[serde(default)]
    pub keyframes: Vec<HeadKeyframeSpec>,
    /// The background that follows the view.
    #[serde(default)]
    pub background: HeadBackgroundSpec,
}

/// `[camera.head.background]`: a background H that follows the moving camera, re-projected
/// from views captured at other head poses (the `[background]` image and the frames' pixels the
/// robot cannot cover) through the scene's boxes that are not objects (desk, wall, floor).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HeadBackgroundSpec {
    /// Views kept (0..=32; 0: the `[background]` image alone, as for a fixed camera).
    pub views: u32,
    /// A frame becomes a view when it looks at least this far (degrees) from every kept one.
    pub min_separation_deg: f64,
    /// CPU threads that re-project the views (0..=256; 0: one per core). Fewer leave cores
    /// to the rest of the machine (a robot site's control loop); the image is the same.
    pub threads: u32,
}

impl Default for HeadBackgroundSpec {
    fn default() -> Self {
        Self {
            views: 8,
            min_separation_deg: 4.0,
            threads: 0,
        }
    }
}

/// `[camera.head.tracking]`: a headset's head tracking (defaults: 90 Hz, no latency, no noise).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackingSpec {
    /// Samples per second.
    pub rate_hz: f64,
    /// From the moment a sample describes to its arrival (s).
    pub latency_s: f64,
    /// Position noise per axis (mm).
    pub position_sigma_mm: f64,
    /// Orientation noise per axis (degrees).
    pub angle_sigma_deg: f64,
}

impl Default for TrackingSpec {
    fn default() -> Self {
        Self {
            rate_hz: 90.0,
            latency_s: 0.0,
            position_sigma_mm: 0.0,
            angle_sigma_deg: 0.0,
        }
    }
}

/// `[camera.head.sweep]`: the head at `eye` looking at `target` turns about the vertical
/// through a pivot `pivot_back_m` behind the eye, yaw(t) = A sin(t ω / A).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadSweepSpec {
    /// The eye at the sweep's centre (m).
    pub eye: [f64; 3],
    /// What it looks at there (m).
    pub target: [f64; 3],
    /// A (degrees, 0..=90).
    #[serde(default = "default_sweep_amplitude")]
    pub amplitude_deg: f64,
    /// ω, the peak angular speed (degrees/s, 0..=720; 0: still).
    pub peak_speed_deg_s: f64,
    /// The neck's distance behind the eye (m, 0..=0.3).
    #[serde(default = "default_pivot_back")]
    pub pivot_back_m: f64,
}

fn default_sweep_amplitude() -> f64 {
    15.0
}
fn default_pivot_back() -> f64 {
    0.09
}

/// `[[camera.head.keyframes]]`: the head at `eye` looking at `target` at `t_s`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadKeyframeSpec {
    /// Time (s, strictly increasing).
    pub t_s: f64,
    /// Eye (m).
    pub eye: [f64; 3],
    /// Looked-at point (m).
    pub target: [f64; 3],
    /// The world direction that appears up.
    #[serde(default = "default_up")]
    pub up: [f64; 3],
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// `[camera] distortion = { model = "plumb_bob", coefficients = [k1, k2, p1, p2, k3] }`: a lens
/// as ROS's `camera_info` gives it (`plumb_bob`, `rational_polynomial`, `equidistant`; the
/// coefficients in OpenCV's order, see `avatarm_core::vision::distortion`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LensSpec {
    /// The model's ROS name.
    pub model: String,
    /// Its coefficients.
    pub coefficients: Vec<f64>,
}

fn default_fov() -> f64 {
    55.0
}
fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}
fn default_fps() -> f64 {
    30.0
}
fn default_rate() -> f64 {
    100.0
}

/// `[[props]]`: a prop or real object.
#[derive(Debug, Clone, Deserialize)]
pub struct PropSpec {
    /// Name.
    pub name: String,
    /// Shape and size (`shape = "box" | "cylinder" | "bottle" | "sphere"`).
    #[serde(flatten)]
    pub shape: PropShape,
    /// Pose of the base centre.
    #[serde(default)]
    pub pose: PoseSpec,
    /// Colour, sRGB + alpha.
    #[serde(default = "default_rgba")]
    pub rgba: [f32; 4],
    /// One of the real objects the user manipulates (vs. a prop).
    #[serde(default)]
    pub object: bool,
    /// Known to the app as something that can hide the robot (the desk): the mask's view draws
    /// it black so that the mask follows the robot's visible pixels.
    #[serde(default)]
    pub occluder: bool,
}

fn default_rgba() -> [f32; 4] {
    [0.6, 0.6, 0.6, 1.0]
}

/// A keyframe of `[[timeline.robot]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotKeyframe {
    /// Time (s).
    pub t_s: f64,
    /// Joint positions; joints not given keep the previous keyframe's value.
    pub q: JointValues,
}

/// `[timeline]`.
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Timeline {
    /// Joint-position keyframes of the robot (minimum-jerk in between).
    #[serde(default)]
    pub robot: Vec<RobotKeyframe>,
}

/// The scene file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Name, for reports.
    pub name: String,
    /// Random seed: the same seed gives the same replay.
    #[serde(default)]
    pub seed: u64,
    /// Length of the replay (s).
    pub duration_s: f64,
    /// Control and simulation step rate (Hz).
    #[serde(default = "default_rate")]
    pub control_rate_hz: f64,
    /// The robot.
    pub robot: RobotSpec,
    /// The real camera.
    pub camera: CameraSpec,
    /// The room.
    #[serde(default)]
    pub props: Vec<PropSpec>,
    /// What happens.
    #[serde(default)]
    pub timeline: Timeline,
    /// How the robot is erased (`[erase]`).
    #[serde(default)]
    pub erase: EraseSettings,
    /// Where the background H comes from (`[background]`).
    #[serde(default)]
    pub background: BackgroundSpec,
    /// The interaction layer (`[interaction]`).
    #[serde(default)]
    pub interaction: InteractionSpec,
    /// The teleoperation task measured on every replay (`[task]`), e.g. the paper's pouring.
    #[serde(default)]
    pub task: Option<PouringTask>,
    /// The paper's chess scene (`[chess]`, docs/chess.md): its board and pieces become props.
    #[serde(default)]
    pub chess: Option<crate::chess::ChessTask>,
    /// Start `avatarm run` in XR (an OpenXR headset), as `--xr` does.
    #[serde(default)]
    pub xr: bool,
    /// The hand that teleoperates the `[task]` in `avatarm run` (as `--hand`): scripted,
    /// desktop, xr, leap, a `.hand.jsonl` file or none.
    #[serde(default)]
    pub hand: Option<String>,
    /// Where the interaction layer sits in the headset (`[xr_layout]`).
    #[serde(default)]
    pub xr_layout: XrLayout,
    /// How detailed the mask twin is (`[twin]`).
    #[serde(default)]
    pub twin: TwinSpec,
    /// Where the operator's Leap Motion sits (`[leap]`): for `hand = "leap"` and Leap
    /// recordings.
    #[serde(default)]
    pub leap: LeapSpec,
}

/// How a Leap Motion is mounted: which way its tracking frame (+y out of its face, +z toward
/// the cable side) points relative to the operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LeapMountKind {
    /// Lying on the desk facing up, the operator on its +z side (Leap's standard desktop
    /// orientation).
    #[default]
    Desk,
    /// On the front of the operator's headset, its face forward, +z up (the paper's
    /// head-mounted Leap; the head is taken to be still, looking along the operator's facing).
    Head,
    /// No physical mount: a recording's first wrist is put at the task's start pose, position
    /// and orientation (recordings only).
    FirstWrist,
}

impl LeapMountKind {
    /// The name as written in scenes and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Desk => "desk",
            Self::Head => "head",
            Self::FirstWrist => "first_wrist",
        }
    }
}

impl std::str::FromStr for LeapMountKind {
    type Err = String;

    /// `desk`, `head` or `first_wrist` (`first-wrist` too).
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "desk" => Ok(Self::Desk),
            "head" => Ok(Self::Head),
            "first_wrist" | "first-wrist" => Ok(Self::FirstWrist),
            other => Err(format!("'{other}': expected desk, head or first_wrist")),
        }
    }
}

/// `[leap]`: where the operator's Leap Motion sits in the scene. The operator faces the
/// scene's +x (as the task's hand does). Without `device_at` the device is placed so that the
/// operator's hand at rest lands on the task's start: for a live device, a hand 20 cm above a
/// desk device or 35 cm ahead of and 20 cm below a head-mounted one; for a recording, its
/// first wrist.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LeapSpec {
    /// `desk`, `head` or `first_wrist`.
    pub mount: LeapMountKind,
    /// The device's origin in the scene (m); not with `first_wrist`.
    pub device_at: Option<[f64; 3]>,
}

/// `[twin]`: the mask twin, the one the app renders white to make M(t). It can be lighter than
/// the robot the camera sees: another description of the same robot (joints matched by name),
/// its collision geometry, or its meshes simplified.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TwinSpec {
    /// Another URDF of the robot, relative to the scene file (default: `robot.urdf`).
    pub urdf: Option<PathBuf>,
    /// `visual` or `collision`.
    pub geometry: GeometryKind,
    /// Fraction of each mesh's triangles kept (0 < f <= 1; 1 = the meshes as they are).
    /// Default [`TwinSpec::DEFAULT_KEEP`].
    pub keep_triangles: f64,
}

impl TwinSpec {
    /// The default fraction of triangles the mask twin keeps: all of them, chosen from `avatarm
    /// bench twin` on the real Sawyer (docs/erase.md, "How much twin the mask needs"). The full
    /// meshes leak 0.004 % against 0.016 % at half the triangles (PSNR 46.9 against 44.5 dB),
    /// for 4 % more frame time even on llvmpipe, where triangles cost most.
    pub const DEFAULT_KEEP: f64 = 1.0;
}

impl Default for TwinSpec {
    fn default() -> Self {
        Self {
            urdf: None,
            geometry: GeometryKind::Visual,
            keep_triangles: Self::DEFAULT_KEEP,
        }
    }
}

/// `[xr_layout]`: the interaction layer in the headset, relative to where the user's head is
/// when the session starts (looking ahead).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct XrLayout {
    /// Distance of the video panel in front of the eyes (m).
    pub panel_distance_m: f64,
    /// Height of the video panel (m); its width follows the camera's aspect ratio.
    pub panel_height_m: f64,
    /// How far the panel's centre is below eye level (m): a little below is easier on the
    /// neck for a seated user.
    pub panel_below_eye_m: f64,
}

impl Default for XrLayout {
    fn default() -> Self {
        Self {
            panel_distance_m: 1.2,
            panel_height_m: 0.7,
            panel_below_eye_m: 0.15,
        }
    }
}

/// `[background]`: where the background image H comes from.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(tag = "source", rename_all = "snake_case", deny_unknown_fields)]
pub enum BackgroundSpec {
    /// The simulated room photographed with the robot out of the way, through the same sensor
    /// model (simulated room only).
    #[default]
    EmptyRoom,
    /// An image file of the camera's size (PNG or JPEG), relative to the scene.
    File {
        /// The image.
        path: PathBuf,
    },
    /// The live frame at a time of the timeline (s), e.g. while the robot is out of view.
    Capture {
        /// When (s).
        at_s: f64,
    },
    /// None until one is captured on command (the preview's B key).
    None,
}

/// `[interaction]`: the layout of what the user sees.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InteractionSpec {
    /// Distance of the video panel from the viewer (m).
    pub panel_distance_m: f64,
    /// Depth of the object twins, in front of the panel (m).
    pub object_depth_m: f64,
}

impl Default for InteractionSpec {
    fn default() -> Self {
        Self {
            panel_distance_m: 2.5,
            object_depth_m: 1.0,
        }
    }
}
