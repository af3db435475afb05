//! Avatarm's recorded sessions: one MCAP file per session, each stream on its own channel with
//! Foxglove's well-known schemas in JSON encoding, so that a user opens the file in Foxglove
//! (or reads it with any MCAP reader) and sees the session; and the camera files labs have
//! ([`camera`]).
//!
//! Channels (topic: schema, all `jsonschema`/`json`):
//!
//! | topic | schema | what |
//! |---|---|---|
//! | [`topics::IMAGE`] | `foxglove.CompressedImage` | camera frames (PNG or JPEG), stamped at capture |
//! | [`topics::CALIBRATION`] | `foxglove.CameraCalibration` | K, D and its model, the image size |
//! | [`topics::TRANSFORM`] | `foxglove.FrameTransform` | the camera's pose: [`BASE_FRAME`] → [`CAMERA_FRAME`] (OpenCV optical axes); or, for a camera on a head, the head's tracked poses [`BASE_FRAME`] → [`HEAD_FRAME`] (each stamped with the moment it describes) and the mount [`HEAD_FRAME`] → [`CAMERA_FRAME`] |
//! | [`topics::JOINT_STATES`] | `avatarm.JointState` | names, positions (rad or m), velocities, stamp |
//! | [`topics::REFERENCE_MASK`] | `foxglove.CompressedImage` | a reference silhouette (PNG, 255 = robot), where the source has one |
//! | [`topics::ERASED`] | `foxglove.CompressedImage` | Avatarm's output Ĩ(t): the frame with the robot erased (PNG) |
//! | [`topics::MASK`] | `foxglove.CompressedImage` | Avatarm's mask M(t) of that frame (PNG, 255 = robot) |
//! | [`topics::HAND`] | `foxglove.PosesInFrame` (with `hand`, `tracked`, `radius`) | the operator's tracked hand: its 26 joints' poses in [`WORLD_FRAME`] (none while untracked), each joint's capsule radius (m) |
//! | [`topics::ROBOT_COMMAND`] | `avatarm.JointCommand` | each control tick's command to the robot: joint names and velocities (rad/s or m/s), gripper closed, the limiter stopping, tool-point speed (m/s) |
//! | [`topics::SAFETY`] | `foxglove.Log` | safety events: the limiter starting or ending a stop or an intervention, mapping and robot-link errors |
//! | [`topics::OBJECT_TARGET`] | `avatarm.ObjectTarget` | the operator's side of the motion mapping, each control tick: the real object's target pose in [`WORLD_FRAME`], its twist and the twin's (m/s, rad/s), the squeezing force σ (N), the grasp matrix's rank, the contacts, whether the hand holds the twin |
//!
//! [`topics::TRANSFORM`] also carries the robot's base in the world ([`WORLD_FRAME`] →
//! [`BASE_FRAME`]) where the session has one, so Foxglove's 3D panel puts the hand, the robot's
//! base and the camera in one scene.
//!
//! Times: MCAP log and publish times in ns since the Unix epoch (or since the session's start
//! where the source has no wall clock); each message's `timestamp` is Foxglove's JSON time
//! `{sec, nsec}`; bytes are base64 (Foxglove's JSON encoding of `bytes`). Every channel
//! carries `avatarm_format` ([`FORMAT_VERSION`]) in its metadata; a file of another version is
//! refused by name.

pub mod camera;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use base64::Engine;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use serde_json::json;

pub use camera::{CameraCalibration, CameraFileError, DistortionModel};

/// The recording format's version (channel metadata `avatarm_format`).
pub const FORMAT_VERSION: &str = "1";
/// The robot's base frame.
pub const BASE_FRAME: &str = "base";
/// The camera's optical frame (x right, y down, z forward).
pub const CAMERA_FRAME: &str = "camera_optical";
/// The world frame of a live session (z up): the hand's, and the parent of [`BASE_FRAME`].
pub const WORLD_FRAME: &str = "world";
/// The head a moving camera rides on (Alice's headset): an optical frame (x right, y down,
/// z forward, the way the face points), as `avatarm_core::vision::head` has it.
pub const HEAD_FRAME: &str = "head";

/// The topics of a recording.
pub mod topics {
    /// Camera frames.
    pub const IMAGE: &str = "/camera/image/compressed";
    /// The camera's calibration.
    pub const CALIBRATION: &str = "/camera/calibration";
    /// The camera's pose in the base frame.
    pub const TRANSFORM: &str = "/tf";
    /// The robot's joint states.
    pub const JOINT_STATES: &str = "/joint_states";
    /// Reference silhouettes of the robot.
    pub const REFERENCE_MASK: &str = "/camera/reference_mask/compressed";
    /// Avatarm's erased frames Ĩ(t).
    pub const ERASED: &str = "/avatarm/erased/compressed";
    /// Avatarm's masks M(t).
    pub const MASK: &str = "/avatarm/mask/compressed";
    /// The operator's tracked hand.
    pub const HAND: &str = "/avatarm/hand";
    /// The commands sent to the robot.
    pub const ROBOT_COMMAND: &str = "/avatarm/robot/command";
    /// Safety events.
    pub const SAFETY: &str = "/avatarm/safety";
    /// The operator's targets for the real object ([`super::ObjectTarget`]).
    pub const OBJECT_TARGET: &str = "/avatarm/operator/target";
}

/// One hand at one instant, as the hand source gave it.
#[derive(Debug, Clone, PartialEq)]
pub struct HandPoses {
    /// Capture time (ns).
    pub stamp_ns: u64,
    /// `left` or `right`.
    pub hand: String,
    /// Tracked; an untracked hand has no joints.
    pub tracked: bool,
    /// The joints' poses in [`WORLD_FRAME`] (26, OpenXR's order, when tracked).
    pub poses: Vec<Isometry3<f64>>,
    /// Each joint's capsule radius (m).
    pub radii: Vec<f64>,
}

/// One control tick's command to the robot.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotCommand {
    /// Tick time (ns).
    pub stamp_ns: u64,
    /// Joint names (the description's).
    pub names: Vec<String>,
    /// Joint velocities sent (rad/s or m/s), one per name (zero when nothing was sent).
    pub velocities: Vec<f64>,
    /// The gripper commanded closed.
    pub gripper_closed: bool,
    /// The safety limiter is stopping the robot.
    pub stopping: bool,
    /// Commanded tool-point speed (m/s).
    pub tcp_speed: f64,
}

/// The operator's side of the motion mapping at one control tick: what the hand makes of the
/// twin (contacts -> grasp matrix -> squeeze and twist; Avatarm paper, Sec. III-C), mapped
/// into the real world as the target the robot's side drives the real object to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectTarget {
    /// When the twin was there (ns).
    pub stamp_ns: u64,
    /// The real object's target pose in [`WORLD_FRAME`] (m).
    pub world_from_object: Isometry3<f64>,
    /// The real object's twist from the contacts ([`WORLD_FRAME`] axes, at the object's
    /// origin): m/s, then rad/s.
    pub object_twist: [f64; 6],
    /// The twin's twist (the virtual scene's axes, at the twin's origin): m/s, then rad/s.
    pub twin_twist: [f64; 6],
    /// Squeezing force σ (N).
    pub squeeze_n: f64,
    /// The grasp matrix's rank (0-6).
    pub grasp_rank: u8,
    /// Contacts on the twin.
    pub contacts: u32,
    /// The hand holds the twin.
    pub held: bool,
}

/// A safety event's severity (`foxglove.Log`'s levels).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogLevel {
    /// Something ended, or information (2; a reader takes 0 and 1 as this too).
    Info,
    /// The limiter intervened (3).
    Warning,
    /// The robot was stopped, or an error (4).
    Error,
}

impl LogLevel {
    fn code(self) -> u8 {
        match self {
            Self::Info => 2,
            Self::Warning => 3,
            Self::Error => 4,
        }
    }

    fn of_code(code: u8) -> Option<Self> {
        match code {
            0..=2 => Some(Self::Info),
            3 => Some(Self::Warning),
            4 | 5 => Some(Self::Error),
            _ => None,
        }
    }
}

/// A safety event.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyEvent {
    /// When (ns).
    pub stamp_ns: u64,
    /// Its severity.
    pub level: LogLevel,
    /// What raised it (`limiter`, `mapping`, `robot`).
    pub source: String,
    /// What happened.
    pub message: String,
}

/// A compressed image's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// PNG.
    Png,
    /// JPEG.
    Jpeg,
}

impl ImageFormat {
    /// Foxglove's name (`CompressedImage.format`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Png => "png",
            Self::Jpeg => "jpeg",
        }
    }

    /// The format of encoded bytes, from their magic number.
    pub fn of_bytes(data: &[u8]) -> Option<Self> {
        if data.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(Self::Png)
        } else if data.starts_with(&[0xff, 0xd8, 0xff]) {
            Some(Self::Jpeg)
        } else {
            None
        }
    }
}

/// One compressed image and when it was captured.
#[derive(Debug, Clone, PartialEq)]
pub struct CompressedFrame {
    /// Capture time (ns).
    pub stamp_ns: u64,
    /// The encoding.
    pub format: ImageFormat,
    /// The encoded image.
    pub data: Vec<u8>,
}

/// The robot's joints at one instant (`sensor_msgs/JointState`'s fields, no effort).
#[derive(Debug, Clone, PartialEq)]
pub struct JointStates {
    /// Sample time (ns).
    pub stamp_ns: u64,
    /// Joint names (the description's).
    pub names: Vec<String>,
    /// Positions (rad or m), one per name.
    pub positions: Vec<f64>,
    /// Velocities (rad/s or m/s), one per name, or none.
    pub velocities: Vec<f64>,
}

/// One tracked pose of the head a moving camera rides on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadPose {
    /// The moment it describes (ns).
    pub stamp_ns: u64,
    /// `base_from_head`: the head's optical frame in the robot's base frame (m).
    pub base_from_head: Isometry3<f64>,
}

/// A frame captured further than this outside a recording's tracked head poses has no head
/// pose of its own (ns): [`Recording::head_covers`].
pub const HEAD_POSE_SLACK_NS: u64 = 50_000_000;

/// The head's pose (`base_from_head`) at `stamp_ns` from tracked poses sorted by stamp:
/// interpolated between the two around it (translation linearly, rotation by slerp), the
/// first or the last outside them; `None` without poses.
pub fn head_at(poses: &[HeadPose], stamp_ns: u64) -> Option<Isometry3<f64>> {
    let i = poses.partition_point(|p| p.stamp_ns <= stamp_ns);
    let before = i.checked_sub(1).map(|i| &poses[i]);
    match (before, poses.get(i)) {
        (Some(a), Some(b)) => {
            let s = (stamp_ns - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64;
            let (pa, pb) = (&a.base_from_head, &b.base_from_head);
            let t = pa.translation.vector.lerp(&pb.translation.vector, s);
            // Two opposite rotations have no one path between them: the nearer one is kept.
            let r = pa
                .rotation
                .try_slerp(&pb.rotation, s, 1e-9)
                .unwrap_or(if s < 0.5 { pa.rotation } else { pb.rotation });
            Some(Isometry3::from_parts(Translation3::from(t), r))
        }
        (Some(p), None) | (None, Some(p)) => Some(p.base_from_head),
        (None, None) => None,
    }
}

/// A recording read back.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// The camera's calibration (the last one recorded).
    pub calibration: Option<CameraCalibration>,
    /// The camera's pose in the base frame (the last one recorded), OpenCV optical axes. `None`
    /// for a camera on a head (see [`Recording::camera_at`]).
    pub base_from_camera: Option<Isometry3<f64>>,
    /// A camera on a head: the head's tracked poses in the base frame, by the moment each
    /// describes.
    pub head_poses: Vec<HeadPose>,
    /// A camera on a head: the mount, `head_from_camera` (the last one recorded).
    pub head_from_camera: Option<Isometry3<f64>>,
    /// Camera frames, by capture time.
    pub frames: Vec<CompressedFrame>,
    /// Reference silhouettes, by capture time.
    pub reference_masks: Vec<CompressedFrame>,
    /// Avatarm's erased frames, by the capture time of the frame they erase.
    pub erased: Vec<CompressedFrame>,
    /// Avatarm's masks, by the capture time of the frame they mask.
    pub masks: Vec<CompressedFrame>,
    /// Joint states, by sample time.
    pub joint_states: Vec<JointStates>,
    /// The robot's base in the world (the last one recorded), where the session has one.
    pub world_from_base: Option<Isometry3<f64>>,
    /// The operator's hand, by capture time.
    pub hands: Vec<HandPoses>,
    /// The commands sent to the robot, by tick time.
    pub commands: Vec<RobotCommand>,
    /// Safety events, by time.
    pub safety: Vec<SafetyEvent>,
    /// The operator's targets for the real object, by tick time.
    pub targets: Vec<ObjectTarget>,
    /// Messages on topics Avatarm does not read, by topic.
    pub other_topics: BTreeMap<String, usize>,
}

/// A recording that cannot be written or read: the file, and where in it.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not an MCAP file, or a damaged one.
    #[error("{path}: not a readable MCAP file: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// Why.
        source: mcap::McapError,
    },
    /// One message is wrong.
    #[error("{path}: {topic}, message {index}: {message}")]
    Message {
        /// The file.
        path: PathBuf,
        /// Its topic.
        topic: String,
        /// Its index on the topic (0-based).
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// A value to write is wrong, or the file as a whole.
    #[error("{path}: {message}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

#[derive(Debug, Serialize, Deserialize)]
struct Time {
    sec: u32,
    nsec: u32,
}

impl Time {
    fn of(ns: u64) -> Self {
        Self {
            sec: u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (ns % 1_000_000_000) as u32,
        }
    }

    fn ns(&self) -> u64 {
        u64::from(self.sec) * 1_000_000_000 + u64::from(self.nsec)
    }
}

#[derive(Debug, Serialize, Deserialize)]
struct WireImage {
    timestamp: Time,
    frame_id: String,
    data: String,
    format: String,
}

#[derive(Debug, Serialize, Deserialize)]
#[allow(non_snake_case)]
struct WireCalibration {
    timestamp: Time,
    frame_id: String,
    width: u32,
    height: u32,
    distortion_model: String,
    D: Vec<f64>,
    K: Vec<f64>,
    R: Vec<f64>,
    P: Vec<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireVector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireQuaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireTransform {
    timestamp: Time,
    parent_frame_id: String,
    child_frame_id: String,
    translation: WireVector3,
    rotation: WireQuaternion,
}

#[derive(Debug, Serialize, Deserialize)]
struct WirePose {
    position: WireVector3,
    orientation: WireQuaternion,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireHand {
    timestamp: Time,
    frame_id: String,
    poses: Vec<WirePose>,
    hand: String,
    tracked: bool,
    radius: Vec<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireCommand {
    timestamp: Time,
    name: Vec<String>,
    velocity: Vec<f64>,
    gripper_closed: bool,
    stopping: bool,
    tcp_speed: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireObjectTarget {
    timestamp: Time,
    frame_id: String,
    pose: WirePose,
    object_twist: [f64; 6],
    twin_twist: [f64; 6],
    squeeze: f64,
    grasp_rank: u8,
    contacts: u32,
    held: bool,
}

#[derive(Debug, Serialize, Deserialize)]
struct WireLog {
    timestamp: Time,
    level: u8,
    message: String,
    name: String,
    file: String,
    line: u32,
}

fn wire_pose(p: &Isometry3<f64>) -> WirePose {
    let (t, q) = (p.translation.vector, p.rotation);
    WirePose {
        position: WireVector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: WireQuaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// The pose of `translation` and `rotation`, or what is wrong with them.
fn pose_of(t: &WireVector3, q: &WireQuaternion) -> Result<Isometry3<f64>, String> {
    let t = Vector3::new(t.x, t.y, t.z);
    let q = Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = q.norm();
    if !(t.iter().all(|v| v.is_finite()) && norm.is_finite() && (norm - 1.0).abs() < 1e-3) {
        return Err(format!(
            "translation {t:?}, rotation of norm {norm}: not a pose"
        ));
    }
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// What is wrong with an object target's values, if anything.
fn object_target_fault(
    pose: &Isometry3<f64>,
    object_twist: &[f64; 6],
    twin_twist: &[f64; 6],
    squeeze_n: f64,
    grasp_rank: u8,
) -> Option<String> {
    if !finite_pose(pose) {
        return Some(format!("pose {pose:?} is not finite"));
    }
    if let Some(v) = object_twist.iter().find(|v| !v.is_finite()) {
        return Some(format!("the object's twist has {v}"));
    }
    if let Some(v) = twin_twist.iter().find(|v| !v.is_finite()) {
        return Some(format!("the twin's twist has {v}"));
    }
    if !squeeze_n.is_finite() {
        return Some(format!("squeezing force {squeeze_n} N"));
    }
    if grasp_rank > 6 {
        return Some(format!("grasp matrix rank {grasp_rank}, above 6"));
    }
    None
}

fn finite_pose(p: &Isometry3<f64>) -> bool {
    p.translation.vector.iter().all(|v| v.is_finite())
        && p.rotation.coords.iter().all(|v| v.is_finite())
}

#[derive(Debug, Serialize, Deserialize)]
struct WireJointState {
    timestamp: Time,
    name: Vec<String>,
    position: Vec<f64>,
    #[serde(default)]
    velocity: Vec<f64>,
}

/// The JSON Schema of each topic's messages, and its name (Foxglove's where it has one).
fn schema(topic: &str) -> (&'static str, serde_json::Value) {
    let time = json!({
        "type": "object",
        "title": "time",
        "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}
    });
    let numbers = json!({"type": "array", "items": {"type": "number"}});
    let xyz = json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}});
    match topic {
        topics::IMAGE | topics::REFERENCE_MASK | topics::ERASED | topics::MASK => (
            "foxglove.CompressedImage",
            json!({
                "title": "foxglove.CompressedImage",
                "description": "A compressed image",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "data": {"type": "string", "contentEncoding": "base64"},
                    "format": {"type": "string"}
                }
            }),
        ),
        topics::CALIBRATION => (
            "foxglove.CameraCalibration",
            json!({
                "title": "foxglove.CameraCalibration",
                "description": "Camera calibration parameters",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "width": {"type": "integer", "minimum": 0},
                    "height": {"type": "integer", "minimum": 0},
                    "distortion_model": {"type": "string"},
                    "D": numbers, "K": numbers, "R": numbers, "P": numbers
                }
            }),
        ),
        topics::TRANSFORM => (
            "foxglove.FrameTransform",
            json!({
                "title": "foxglove.FrameTransform",
                "description": "A transform between two reference frames in 3D space",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "parent_frame_id": {"type": "string"},
                    "child_frame_id": {"type": "string"},
                    "translation": xyz,
                    "rotation": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}
                }
            }),
        ),
        topics::HAND => (
            "foxglove.PosesInFrame",
            json!({
                "title": "foxglove.PosesInFrame",
                "description": "An array of timestamped poses in a reference frame (Avatarm: a hand's joints, with its side, whether it is tracked and each joint's radius in m)",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "poses": {"type": "array", "items": {"type": "object", "properties": {
                        "position": xyz,
                        "orientation": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}
                    }}},
                    "hand": {"type": "string", "enum": ["left", "right"]},
                    "tracked": {"type": "boolean"},
                    "radius": numbers
                }
            }),
        ),
        topics::ROBOT_COMMAND => (
            "avatarm.JointCommand",
            json!({
                "title": "avatarm.JointCommand",
                "description": "One control tick's command to the robot: joint velocities (rad/s or m/s), the gripper, whether the safety limiter is stopping the arm, the tool-point speed (m/s)",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "name": {"type": "array", "items": {"type": "string"}},
                    "velocity": numbers,
                    "gripper_closed": {"type": "boolean"},
                    "stopping": {"type": "boolean"},
                    "tcp_speed": {"type": "number"}
                }
            }),
        ),
        topics::OBJECT_TARGET => (
            "avatarm.ObjectTarget",
            json!({
                "title": "avatarm.ObjectTarget",
                "description": "The operator's target for the real object at one control tick: its pose in frame_id (m), its twist and the twin's (m/s then rad/s), the squeezing force (N), the grasp matrix's rank, the contacts on the twin, whether the hand holds it",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "frame_id": {"type": "string"},
                    "pose": {"type": "object", "properties": {
                        "position": xyz,
                        "orientation": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}
                    }},
                    "object_twist": numbers,
                    "twin_twist": numbers,
                    "squeeze": {"type": "number"},
                    "grasp_rank": {"type": "integer", "minimum": 0, "maximum": 6},
                    "contacts": {"type": "integer", "minimum": 0},
                    "held": {"type": "boolean"}
                }
            }),
        ),
        topics::SAFETY => (
            "foxglove.Log",
            json!({
                "title": "foxglove.Log",
                "description": "A log message",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "level": {"type": "integer", "minimum": 0, "maximum": 5},
                    "message": {"type": "string"},
                    "name": {"type": "string"},
                    "file": {"type": "string"},
                    "line": {"type": "integer", "minimum": 0}
                }
            }),
        ),
        _ => (
            "avatarm.JointState",
            json!({
                "title": "avatarm.JointState",
                "description": "The robot's joints at one instant: names, positions (rad or m), velocities (rad/s or m/s)",
                "type": "object",
                "properties": {
                    "timestamp": time,
                    "name": {"type": "array", "items": {"type": "string"}},
                    "position": numbers,
                    "velocity": numbers
                }
            }),
        ),
    }
}

/// Writes a recording ([`RecordingWriter::finish`] completes the file; a writer dropped
/// without it leaves a file that MCAP readers can still read up to the last chunk written).
pub struct RecordingWriter {
    path: PathBuf,
    out: mcap::Writer<BufWriter<File>>,
    channels: BTreeMap<&'static str, u16>,
    sequence: u32,
    messages: u64,
}

impl RecordingWriter {
    /// Creates `path` (replacing a file there).
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        let io = |source| RecordError::Io {
            path: path.to_owned(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let file = File::create(path).map_err(io)?;
        let out = mcap::WriteOptions::new()
            .profile("")
            .library(concat!("avatarm ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|source| RecordError::Mcap {
                path: path.to_owned(),
                source,
            })?;
        Ok(Self {
            path: path.to_owned(),
            out,
            channels: BTreeMap::new(),
            sequence: 0,
            messages: 0,
        })
    }

    fn mcap_error(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    fn write(
        &mut self,
        topic: &'static str,
        stamp_ns: u64,
        message: &impl Serialize,
    ) -> Result<(), RecordError> {
        let channel = match self.channels.get(topic) {
            Some(c) => *c,
            None => {
                let (name, schema) = schema(topic);
                let schema_id = self
                    .out
                    .add_schema(name, "jsonschema", schema.to_string().as_bytes())
                    .map_err(|e| self.mcap_error(e))?;
                let metadata =
                    BTreeMap::from([("avatarm_format".to_owned(), FORMAT_VERSION.to_owned())]);
                let id = self
                    .out
                    .add_channel(schema_id, topic, "json", &metadata)
                    .map_err(|e| self.mcap_error(e))?;
                self.channels.insert(topic, id);
                id
            }
        };
        let data = serde_json::to_vec(message).map_err(|e| RecordError::Content {
            path: self.path.clone(),
            message: format!("{topic}: {e}"),
        })?;
        self.sequence = self.sequence.wrapping_add(1);
        self.out
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: self.sequence,
                    log_time: stamp_ns,
                    publish_time: stamp_ns,
                },
                &data,
            )
            .map_err(|e| self.mcap_error(e))?;
        self.messages += 1;
        Ok(())
    }

    fn refuse(&self, message: String) -> RecordError {
        RecordError::Content {
            path: self.path.clone(),
            message,
        }
    }

    /// The camera's calibration at `stamp_ns`. Refused when it does not validate.
    pub fn calibration(&mut self, stamp_ns: u64, c: &CameraCalibration) -> Result<(), RecordError> {
        c.validate()
            .map_err(|m| self.refuse(format!("camera calibration: {m}")))?;
        let k = c.k;
        let message = WireCalibration {
            timestamp: Time::of(stamp_ns),
            frame_id: CAMERA_FRAME.into(),
            width: c.width,
            height: c.height,
            distortion_model: c.distortion_model.ros_name().into(),
            D: c.d.clone(),
            K: k.to_vec(),
            R: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            P: vec![
                k[0], k[1], k[2], 0.0, k[3], k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0,
            ],
        };
        self.write(topics::CALIBRATION, stamp_ns, &message)
    }

    /// The camera's pose in the base frame at `stamp_ns` (OpenCV optical axes). Refused when
    /// not finite.
    pub fn camera_pose(
        &mut self,
        stamp_ns: u64,
        base_from_camera: &Isometry3<f64>,
    ) -> Result<(), RecordError> {
        if !finite_pose(base_from_camera) {
            return Err(self.refuse(format!("camera pose {base_from_camera:?} is not finite")));
        }
        self.transform(stamp_ns, BASE_FRAME, CAMERA_FRAME, base_from_camera)
    }

    /// A tracked pose of the head a moving camera rides on: `base_from_head` at the moment
    /// `stamp_ns` describes. Refused when not finite.
    pub fn head_pose(&mut self, p: &HeadPose) -> Result<(), RecordError> {
        if !finite_pose(&p.base_from_head) {
            return Err(self.refuse(format!(
                "head pose at {} ns {:?} is not finite",
                p.stamp_ns, p.base_from_head
            )));
        }
        self.transform(p.stamp_ns, BASE_FRAME, HEAD_FRAME, &p.base_from_head)
    }

    /// The mount of a camera on a head (`head_from_camera`, OpenCV optical axes), recorded at
    /// `stamp_ns`. Refused when not finite.
    pub fn camera_mount(
        &mut self,
        stamp_ns: u64,
        head_from_camera: &Isometry3<f64>,
    ) -> Result<(), RecordError> {
        if !finite_pose(head_from_camera) {
            return Err(self.refuse(format!("camera mount {head_from_camera:?} is not finite")));
        }
        self.transform(stamp_ns, HEAD_FRAME, CAMERA_FRAME, head_from_camera)
    }

    fn transform(
        &mut self,
        stamp_ns: u64,
        parent: &str,
        child: &str,
        parent_from_child: &Isometry3<f64>,
    ) -> Result<(), RecordError> {
        let p = wire_pose(parent_from_child);
        let message = WireTransform {
            timestamp: Time::of(stamp_ns),
            parent_frame_id: parent.into(),
            child_frame_id: child.into(),
            translation: p.position,
            rotation: p.orientation,
        };
        self.write(topics::TRANSFORM, stamp_ns, &message)
    }

    fn image(&mut self, topic: &'static str, f: &CompressedFrame) -> Result<(), RecordError> {
        if ImageFormat::of_bytes(&f.data) != Some(f.format) {
            return Err(self.refuse(format!(
                "{topic}: the image at {} ns is not {} data",
                f.stamp_ns,
                f.format.name()
            )));
        }
        let message = WireImage {
            timestamp: Time::of(f.stamp_ns),
            frame_id: CAMERA_FRAME.into(),
            data: base64::engine::general_purpose::STANDARD.encode(&f.data),
            format: f.format.name().into(),
        };
        self.write(topic, f.stamp_ns, &message)
    }

    /// A camera frame.
    pub fn frame(&mut self, f: &CompressedFrame) -> Result<(), RecordError> {
        self.image(topics::IMAGE, f)
    }

    /// A reference silhouette (PNG, 255 = robot) for the frame captured at `f.stamp_ns`.
    pub fn reference_mask(&mut self, f: &CompressedFrame) -> Result<(), RecordError> {
        self.image(topics::REFERENCE_MASK, f)
    }

    /// Avatarm's erased frame for the frame captured at `f.stamp_ns`.
    pub fn erased(&mut self, f: &CompressedFrame) -> Result<(), RecordError> {
        self.image(topics::ERASED, f)
    }

    /// Avatarm's mask (PNG, 255 = robot) for the frame captured at `f.stamp_ns`.
    pub fn mask(&mut self, f: &CompressedFrame) -> Result<(), RecordError> {
        self.image(topics::MASK, f)
    }

    /// The robot's joints. Refused when the lengths do not match or a value is not finite
    /// (nothing is written).
    pub fn joint_states(&mut self, s: &JointStates) -> Result<(), RecordError> {
        if s.positions.len() != s.names.len()
            || !(s.velocities.is_empty() || s.velocities.len() == s.names.len())
        {
            return Err(self.refuse(format!(
                "joint states at {} ns: {} names, {} positions, {} velocities",
                s.stamp_ns,
                s.names.len(),
                s.positions.len(),
                s.velocities.len()
            )));
        }
        if let Some((i, v)) = s
            .positions
            .iter()
            .chain(&s.velocities)
            .enumerate()
            .find(|(_, v)| !v.is_finite())
        {
            let name = &s.names[i % s.names.len()];
            return Err(self.refuse(format!(
                "joint states at {} ns: joint '{name}' has {v}",
                s.stamp_ns
            )));
        }
        let message = WireJointState {
            timestamp: Time::of(s.stamp_ns),
            name: s.names.clone(),
            position: s.positions.clone(),
            velocity: s.velocities.clone(),
        };
        self.write(topics::JOINT_STATES, s.stamp_ns, &message)
    }

    /// The robot's base in the world at `stamp_ns` (a live session's). Refused when not
    /// finite.
    pub fn base_pose(
        &mut self,
        stamp_ns: u64,
        world_from_base: &Isometry3<f64>,
    ) -> Result<(), RecordError> {
        if !finite_pose(world_from_base) {
            return Err(self.refuse(format!("base pose {world_from_base:?} is not finite")));
        }
        self.transform(stamp_ns, WORLD_FRAME, BASE_FRAME, world_from_base)
    }

    /// The operator's hand. Refused (nothing written) when a pose or radius is not finite, the
    /// counts differ, a tracked hand has no joints or `hand` is not `left` or `right`.
    pub fn hand(&mut self, h: &HandPoses) -> Result<(), RecordError> {
        let at = format!("hand at {} ns", h.stamp_ns);
        if !matches!(h.hand.as_str(), "left" | "right") {
            return Err(self.refuse(format!("{at}: side '{}'", h.hand)));
        }
        if h.poses.len() != h.radii.len() || (h.tracked && h.poses.is_empty()) {
            return Err(self.refuse(format!(
                "{at}: {} poses, {} radii (tracked: {})",
                h.poses.len(),
                h.radii.len(),
                h.tracked
            )));
        }
        if let Some(i) =
            (0..h.poses.len()).find(|&i| !(finite_pose(&h.poses[i]) && h.radii[i].is_finite()))
        {
            return Err(self.refuse(format!("{at}: joint {i} is not finite")));
        }
        let message = WireHand {
            timestamp: Time::of(h.stamp_ns),
            frame_id: WORLD_FRAME.into(),
            poses: h.poses.iter().map(wire_pose).collect(),
            hand: h.hand.clone(),
            tracked: h.tracked,
            radius: h.radii.clone(),
        };
        self.write(topics::HAND, h.stamp_ns, &message)
    }

    /// A command sent to the robot. Refused (nothing written) when the counts differ or a
    /// value is not finite (a NaN command is never recorded as if it were sent).
    pub fn robot_command(&mut self, c: &RobotCommand) -> Result<(), RecordError> {
        if c.names.len() != c.velocities.len() {
            return Err(self.refuse(format!(
                "robot command at {} ns: {} names, {} velocities",
                c.stamp_ns,
                c.names.len(),
                c.velocities.len()
            )));
        }
        if let Some(i) = c.velocities.iter().position(|v| !v.is_finite()) {
            return Err(self.refuse(format!(
                "robot command at {} ns: joint '{}' has {}",
                c.stamp_ns, c.names[i], c.velocities[i]
            )));
        }
        if !c.tcp_speed.is_finite() {
            return Err(self.refuse(format!(
                "robot command at {} ns: tool-point speed {}",
                c.stamp_ns, c.tcp_speed
            )));
        }
        let message = WireCommand {
            timestamp: Time::of(c.stamp_ns),
            name: c.names.clone(),
            velocity: c.velocities.clone(),
            gripper_closed: c.gripper_closed,
            stopping: c.stopping,
            tcp_speed: c.tcp_speed,
        };
        self.write(topics::ROBOT_COMMAND, c.stamp_ns, &message)
    }

    /// The operator's target for the real object. Refused (nothing written) when a value is not
    /// finite or the rank is above 6.
    pub fn object_target(&mut self, t: &ObjectTarget) -> Result<(), RecordError> {
        if let Some(why) = object_target_fault(
            &t.world_from_object,
            &t.object_twist,
            &t.twin_twist,
            t.squeeze_n,
            t.grasp_rank,
        ) {
            return Err(self.refuse(format!("object target at {} ns: {why}", t.stamp_ns)));
        }
        let message = WireObjectTarget {
            timestamp: Time::of(t.stamp_ns),
            frame_id: WORLD_FRAME.into(),
            pose: wire_pose(&t.world_from_object),
            object_twist: t.object_twist,
            twin_twist: t.twin_twist,
            squeeze: t.squeeze_n,
            grasp_rank: t.grasp_rank,
            contacts: t.contacts,
            held: t.held,
        };
        self.write(topics::OBJECT_TARGET, t.stamp_ns, &message)
    }

    /// A safety event.
    pub fn safety_event(&mut self, e: &SafetyEvent) -> Result<(), RecordError> {
        let message = WireLog {
            timestamp: Time::of(e.stamp_ns),
            level: e.level.code(),
            message: e.message.clone(),
            name: e.source.clone(),
            file: String::new(),
            line: 0,
        };
        self.write(topics::SAFETY, e.stamp_ns, &message)
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Completes the file (its summary and index).
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.out.finish().map_err(|e| self.mcap_error(e))?;
        Ok(())
    }
}

impl Recording {
    /// Reads a recording. Messages are sorted by their stamps. Errors name the file and, for a
    /// message that cannot be read (not JSON of its schema, a non-finite value, an image whose
    /// bytes are not its format), its topic and index; a channel of another Avatarm format
    /// version is refused by name. The whole file is read into memory.
    pub fn open(path: &Path) -> Result<Self, RecordError> {
        let bytes = std::fs::read(path).map_err(|source| RecordError::Io {
            path: path.to_owned(),
            source,
        })?;
        let mut out = Recording::default();
        let mut counts: BTreeMap<String, usize> = BTreeMap::new();
        let stream = mcap::MessageStream::new(&bytes).map_err(|source| RecordError::Mcap {
            path: path.to_owned(),
            source,
        })?;
        for message in stream {
            let message = message.map_err(|source| RecordError::Mcap {
                path: path.to_owned(),
                source,
            })?;
            let topic = message.channel.topic.clone();
            let index = {
                let n = counts.entry(topic.clone()).or_default();
                *n += 1;
                *n - 1
            };
            let bad = |message: String| RecordError::Message {
                path: path.to_owned(),
                topic: topic.clone(),
                index,
                message,
            };
            let known = [
                topics::IMAGE,
                topics::CALIBRATION,
                topics::TRANSFORM,
                topics::JOINT_STATES,
                topics::REFERENCE_MASK,
                topics::ERASED,
                topics::MASK,
                topics::HAND,
                topics::ROBOT_COMMAND,
                topics::SAFETY,
                topics::OBJECT_TARGET,
            ];
            if !known.contains(&topic.as_str()) {
                *out.other_topics.entry(topic.clone()).or_default() += 1;
                continue;
            }
            if let Some(v) = message.channel.metadata.get("avatarm_format")
                && v != FORMAT_VERSION
            {
                return Err(bad(format!(
                    "written in Avatarm's recording format {v}; this Avatarm reads format {FORMAT_VERSION}"
                )));
            }
            if message.channel.message_encoding != "json" {
                return Err(bad(format!(
                    "encoded as '{}', Avatarm reads 'json'",
                    message.channel.message_encoding
                )));
            }
            match topic.as_str() {
                topics::IMAGE | topics::REFERENCE_MASK | topics::ERASED | topics::MASK => {
                    let m: WireImage = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not a foxglove.CompressedImage: {e}")))?;
                    let data = base64::engine::general_purpose::STANDARD
                        .decode(m.data.as_bytes())
                        .map_err(|e| bad(format!("data is not base64: {e}")))?;
                    let format = match m.format.as_str() {
                        "png" => ImageFormat::Png,
                        "jpeg" | "jpg" => ImageFormat::Jpeg,
                        f => {
                            return Err(bad(format!(
                                "image format '{f}': Avatarm reads png and jpeg"
                            )));
                        }
                    };
                    if ImageFormat::of_bytes(&data) != Some(format) {
                        return Err(bad(format!("the data is not {}", format.name())));
                    }
                    let frame = CompressedFrame {
                        stamp_ns: m.timestamp.ns(),
                        format,
                        data,
                    };
                    match topic.as_str() {
                        topics::IMAGE => out.frames.push(frame),
                        topics::REFERENCE_MASK => out.reference_masks.push(frame),
                        topics::ERASED => out.erased.push(frame),
                        _ => out.masks.push(frame),
                    }
                }
                topics::CALIBRATION => {
                    let m: WireCalibration = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not a foxglove.CameraCalibration: {e}")))?;
                    let model = DistortionModel::from_ros_name(&m.distortion_model)
                        .ok_or_else(|| bad(format!("distortion model '{}'", m.distortion_model)))?;
                    let k: [f64; 9] = m
                        .K
                        .try_into()
                        .map_err(|k: Vec<f64>| bad(format!("K has {} values, not 9", k.len())))?;
                    let c = CameraCalibration {
                        width: m.width,
                        height: m.height,
                        k,
                        distortion_model: model,
                        d: m.D,
                    };
                    c.validate().map_err(bad)?;
                    out.calibration = Some(c);
                }
                topics::TRANSFORM => {
                    let m: WireTransform = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not a foxglove.FrameTransform: {e}")))?;
                    if (m.parent_frame_id.as_str(), m.child_frame_id.as_str())
                        == (WORLD_FRAME, BASE_FRAME)
                    {
                        out.world_from_base =
                            Some(pose_of(&m.translation, &m.rotation).map_err(bad)?);
                        continue;
                    }
                    match (m.parent_frame_id.as_str(), m.child_frame_id.as_str()) {
                        (BASE_FRAME, HEAD_FRAME) => {
                            out.head_poses.push(HeadPose {
                                stamp_ns: m.timestamp.ns(),
                                base_from_head: pose_of(&m.translation, &m.rotation)
                                    .map_err(bad)?,
                            });
                            continue;
                        }
                        (HEAD_FRAME, CAMERA_FRAME) => {
                            out.head_from_camera =
                                Some(pose_of(&m.translation, &m.rotation).map_err(bad)?);
                            continue;
                        }
                        _ => {}
                    }
                    if (m.parent_frame_id.as_str(), m.child_frame_id.as_str())
                        != (BASE_FRAME, CAMERA_FRAME)
                    {
                        *out.other_topics
                            .entry(format!(
                                "{topic} {} -> {}",
                                m.parent_frame_id, m.child_frame_id
                            ))
                            .or_default() += 1;
                        continue;
                    }
                    out.base_from_camera = Some(pose_of(&m.translation, &m.rotation).map_err(bad)?);
                }
                topics::HAND => {
                    let m: WireHand = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not a foxglove.PosesInFrame hand: {e}")))?;
                    let poses = m
                        .poses
                        .iter()
                        .map(|p| pose_of(&p.position, &p.orientation))
                        .collect::<Result<Vec<_>, _>>()
                        .map_err(bad)?;
                    if !matches!(m.hand.as_str(), "left" | "right") {
                        return Err(bad(format!("hand side '{}'", m.hand)));
                    }
                    if poses.len() != m.radius.len()
                        || m.radius.iter().any(|r| !r.is_finite())
                        || (m.tracked && poses.is_empty())
                    {
                        return Err(bad(format!(
                            "{} poses, {} radii (all finite; a tracked hand has joints)",
                            poses.len(),
                            m.radius.len()
                        )));
                    }
                    out.hands.push(HandPoses {
                        stamp_ns: m.timestamp.ns(),
                        hand: m.hand,
                        tracked: m.tracked,
                        poses,
                        radii: m.radius,
                    });
                }
                topics::ROBOT_COMMAND => {
                    let m: WireCommand = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not an avatarm.JointCommand: {e}")))?;
                    if m.velocity.len() != m.name.len()
                        || m.velocity.iter().any(|v| !v.is_finite())
                        || !m.tcp_speed.is_finite()
                    {
                        return Err(bad(format!(
                            "{} names, {} velocities (all finite), tool-point speed {}",
                            m.name.len(),
                            m.velocity.len(),
                            m.tcp_speed
                        )));
                    }
                    out.commands.push(RobotCommand {
                        stamp_ns: m.timestamp.ns(),
                        names: m.name,
                        velocities: m.velocity,
                        gripper_closed: m.gripper_closed,
                        stopping: m.stopping,
                        tcp_speed: m.tcp_speed,
                    });
                }
                topics::OBJECT_TARGET => {
                    let m: WireObjectTarget = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not an avatarm.ObjectTarget: {e}")))?;
                    if m.frame_id != WORLD_FRAME {
                        return Err(bad(format!(
                            "frame_id '{}': Avatarm writes targets in '{WORLD_FRAME}'",
                            m.frame_id
                        )));
                    }
                    let pose = pose_of(&m.pose.position, &m.pose.orientation).map_err(bad)?;
                    if let Some(why) = object_target_fault(
                        &pose,
                        &m.object_twist,
                        &m.twin_twist,
                        m.squeeze,
                        m.grasp_rank,
                    ) {
                        return Err(bad(why));
                    }
                    out.targets.push(ObjectTarget {
                        stamp_ns: m.timestamp.ns(),
                        world_from_object: pose,
                        object_twist: m.object_twist,
                        twin_twist: m.twin_twist,
                        squeeze_n: m.squeeze,
                        grasp_rank: m.grasp_rank,
                        contacts: m.contacts,
                        held: m.held,
                    });
                }
                topics::SAFETY => {
                    let m: WireLog = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not a foxglove.Log: {e}")))?;
                    let level = LogLevel::of_code(m.level)
                        .ok_or_else(|| bad(format!("log level {}", m.level)))?;
                    out.safety.push(SafetyEvent {
                        stamp_ns: m.timestamp.ns(),
                        level,
                        source: m.name,
                        message: m.message,
                    });
                }
                _ => {
                    let m: WireJointState = serde_json::from_slice(&message.data)
                        .map_err(|e| bad(format!("not an avatarm.JointState: {e}")))?;
                    if m.position.len() != m.name.len()
                        || !(m.velocity.is_empty() || m.velocity.len() == m.name.len())
                    {
                        return Err(bad(format!(
                            "{} names, {} positions, {} velocities",
                            m.name.len(),
                            m.position.len(),
                            m.velocity.len()
                        )));
                    }
                    if m.position.iter().chain(&m.velocity).any(|v| !v.is_finite()) {
                        return Err(bad("a position or velocity is not finite".into()));
                    }
                    out.joint_states.push(JointStates {
                        stamp_ns: m.timestamp.ns(),
                        names: m.name,
                        positions: m.position,
                        velocities: m.velocity,
                    });
                }
            }
        }
        out.frames.sort_by_key(|f| f.stamp_ns);
        out.reference_masks.sort_by_key(|f| f.stamp_ns);
        out.erased.sort_by_key(|f| f.stamp_ns);
        out.masks.sort_by_key(|f| f.stamp_ns);
        out.joint_states.sort_by_key(|s| s.stamp_ns);
        out.head_poses.sort_by_key(|p| p.stamp_ns);
        out.hands.sort_by_key(|h| h.stamp_ns);
        out.commands.sort_by_key(|c| c.stamp_ns);
        out.safety.sort_by_key(|e| e.stamp_ns);
        out.targets.sort_by_key(|t| t.stamp_ns);
        Ok(out)
    }

    /// Whether the camera rides on a head: the recording has the head's poses or a mount.
    pub fn camera_on_head(&self) -> bool {
        !self.head_poses.is_empty() || self.head_from_camera.is_some()
    }

    /// The head's pose (`base_from_head`) at `stamp_ns` ([`head_at`] of its tracked poses).
    pub fn head_at(&self, stamp_ns: u64) -> Option<Isometry3<f64>> {
        head_at(&self.head_poses, stamp_ns)
    }

    /// Whether the tracked head poses cover `stamp_ns`: it lies within `slack_ns` of their
    /// span (`false` without head poses).
    pub fn head_covers(&self, stamp_ns: u64, slack_ns: u64) -> bool {
        match (self.head_poses.first(), self.head_poses.last()) {
            (Some(first), Some(last)) => {
                stamp_ns.saturating_add(slack_ns) >= first.stamp_ns
                    && stamp_ns <= last.stamp_ns.saturating_add(slack_ns)
            }
            _ => false,
        }
    }

    /// The camera's pose in the base frame at `stamp_ns`: the fixed one, or for a camera on a
    /// head the head's pose then ([`Recording::head_at`]) times the mount. `None` when the
    /// recording has neither.
    pub fn camera_at(&self, stamp_ns: u64) -> Option<Isometry3<f64>> {
        match self.head_from_camera {
            Some(mount) => Some(self.head_at(stamp_ns)? * mount),
            None => self.base_from_camera,
        }
    }

    /// The joint states at or just before `stamp_ns` (sample-and-hold), `None` before the first.
    pub fn joints_at(&self, stamp_ns: u64) -> Option<&JointStates> {
        let i = self
            .joint_states
            .partition_point(|s| s.stamp_ns <= stamp_ns);
        i.checked_sub(1).map(|i| &self.joint_states[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PNG: &[u8] = b"\x89PNG\r\n\x1a\n(the rest of a png)";
    const JPEG: &[u8] = &[0xff, 0xd8, 0xff, 0xe0, 1, 2, 3];

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("avatarm_record_{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        dir.join(name)
    }

    fn calibration() -> CameraCalibration {
        CameraCalibration {
            width: 640,
            height: 480,
            k: [600.0, 0.0, 320.0, 0.0, 601.0, 240.0, 0.0, 0.0, 1.0],
            distortion_model: DistortionModel::RationalPolynomial,
            d: vec![0.1, -0.05, 0.001, 0.002, 0.01, 0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn a_recording_reads_back_as_written() {
        let path = temp("round_trip.mcap");
        let pose = Isometry3::from_parts(
            Translation3::new(1.2, -0.1, 0.6),
            UnitQuaternion::from_euler_angles(-2.0, 0.1, 1.5),
        );
        let joints = |i: u64| JointStates {
            stamp_ns: 1_700_000_000_000_000_000 + i * 10_000_000,
            names: vec!["j1".into(), "j2".into()],
            positions: vec![0.1 * i as f64, -0.2],
            velocities: vec![0.5, 0.0],
        };
        let mut w = RecordingWriter::create(&path).expect("create");
        w.calibration(1_700_000_000_000_000_000, &calibration())
            .expect("calibration");
        w.camera_pose(1_700_000_000_000_000_000, &pose)
            .expect("pose");
        // Written out of order: read back by stamp.
        for i in [2u64, 0, 1] {
            w.joint_states(&joints(i)).expect("joints");
            let f = CompressedFrame {
                stamp_ns: 1_700_000_000_000_000_000 + i * 33_333_333,
                format: if i == 1 {
                    ImageFormat::Jpeg
                } else {
                    ImageFormat::Png
                },
                data: if i == 1 { JPEG.to_vec() } else { PNG.to_vec() },
            };
            w.frame(&f).expect("frame");
        }
        w.reference_mask(&CompressedFrame {
            stamp_ns: 1_700_000_000_000_000_000,
            format: ImageFormat::Png,
            data: PNG.to_vec(),
        })
        .expect("mask");
        assert_eq!(w.messages(), 9);
        // A live session's streams: the base in the world, the hand, commands, events.
        let base = Isometry3::translation(0.0, 0.0, 0.75);
        w.base_pose(1_700_000_000_000_000_000, &base).expect("base");
        let hand = HandPoses {
            stamp_ns: 1_700_000_000_005_000_000,
            hand: "right".into(),
            tracked: true,
            poses: vec![pose, base],
            radii: vec![0.01, 0.008],
        };
        w.hand(&hand).expect("hand");
        let lost = HandPoses {
            stamp_ns: 1_700_000_000_006_000_000,
            tracked: false,
            poses: vec![],
            radii: vec![],
            ..hand.clone()
        };
        w.hand(&lost).expect("untracked hand");
        let command = RobotCommand {
            stamp_ns: 1_700_000_000_010_000_000,
            names: vec!["j1".into(), "j2".into()],
            velocities: vec![0.1, -0.05],
            gripper_closed: true,
            stopping: false,
            tcp_speed: 0.12,
        };
        w.robot_command(&command).expect("command");
        let event = SafetyEvent {
            stamp_ns: 1_700_000_000_011_000_000,
            level: LogLevel::Error,
            source: "limiter".into(),
            message: "stopping: the hand is not tracked".into(),
        };
        w.safety_event(&event).expect("event");
        let target = ObjectTarget {
            stamp_ns: 1_700_000_000_010_000_000,
            world_from_object: Isometry3::from_parts(
                Translation3::new(0.6, -0.1, 0.9),
                UnitQuaternion::from_euler_angles(0.2, 0.0, 0.1),
            ),
            object_twist: [0.01, 0.0, 0.02, 0.0, 0.3, 0.0],
            twin_twist: [0.01, 0.0, 0.02, 0.0, 0.3, 0.0],
            squeeze_n: 4.5,
            grasp_rank: 6,
            contacts: 5,
            held: true,
        };
        w.object_target(&target).expect("target");
        // A NaN target, a rank above 6: refused by name, nothing written.
        let nan = ObjectTarget {
            squeeze_n: f64::NAN,
            ..target
        };
        let e = w.object_target(&nan).expect_err("a NaN target");
        assert!(e.to_string().contains("squeezing force NaN"), "{e}");
        let e = w
            .object_target(&ObjectTarget {
                grasp_rank: 7,
                ..target
            })
            .expect_err("rank 7");
        assert!(e.to_string().contains("rank 7"), "{e}");
        w.finish().expect("finish");

        let r = Recording::open(&path).expect("open");
        assert_eq!(r.calibration, Some(calibration()));
        let back = r.base_from_camera.expect("pose");
        assert!((back.translation.vector - pose.translation.vector).norm() < 1e-12);
        assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
        assert_eq!(r.frames.len(), 3);
        assert!(r.frames.windows(2).all(|w| w[0].stamp_ns < w[1].stamp_ns));
        assert_eq!(r.frames[1].format, ImageFormat::Jpeg);
        assert_eq!(r.frames[1].data, JPEG);
        assert_eq!(r.reference_masks.len(), 1);
        assert_eq!(r.joint_states, vec![joints(0), joints(1), joints(2)]);
        // Sample-and-hold lookup.
        assert_eq!(r.joints_at(1_700_000_000_015_000_000), Some(&joints(1)));
        assert_eq!(r.joints_at(1), None);
        assert!(r.other_topics.is_empty());
        assert!((r.world_from_base.expect("base").translation.z - 0.75).abs() < 1e-12);
        assert_eq!(r.hands.len(), 2);
        assert_eq!(
            (r.hands[0].hand.as_str(), r.hands[0].tracked),
            ("right", true)
        );
        assert!(r.hands[0].poses[0].rotation.angle_to(&pose.rotation) < 1e-12);
        assert_eq!(r.hands[0].radii, hand.radii);
        assert_eq!(r.hands[1], lost);
        assert_eq!(r.commands, vec![command]);
        assert_eq!(r.safety, vec![event]);
        assert_eq!(r.targets.len(), 1);
        let t = r.targets[0];
        assert_eq!(
            (t.stamp_ns, t.grasp_rank, t.contacts, t.held),
            (target.stamp_ns, 6, 5, true)
        );
        assert_eq!(
            (t.object_twist, t.twin_twist),
            (target.object_twist, target.twin_twist)
        );
        assert!(
            t.world_from_object
                .rotation
                .angle_to(&target.world_from_object.rotation)
                < 1e-12
        );
        assert!(
            (t.world_from_object.translation.vector - target.world_from_object.translation.vector)
                .norm()
                < 1e-12
        );
    }

    #[test]
    fn a_camera_on_a_head_reads_back_as_its_head_poses_and_mount() {
        let path = temp("head.mcap");
        let head = |i: u64| HeadPose {
            stamp_ns: 1_000_000_000 + i * 10_000_000,
            base_from_head: Isometry3::from_parts(
                Translation3::new(0.1 * i as f64, -1.0, 0.5),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 0.1 * i as f64),
            ),
        };
        let mount = Isometry3::translation(0.0, -0.03, 0.08);
        let mut w = RecordingWriter::create(&path).expect("create");
        w.camera_mount(1_000_000_000, &mount).expect("mount");
        for i in [1u64, 0, 2] {
            w.head_pose(&head(i)).expect("head");
        }
        let nan = HeadPose {
            stamp_ns: 5,
            base_from_head: Isometry3::translation(f64::NAN, 0.0, 0.0),
        };
        let e = w.head_pose(&nan).expect_err("NaN");
        assert!(e.to_string().contains("head pose at 5 ns"), "{e}");
        w.finish().expect("finish");
        let r = Recording::open(&path).expect("open");
        assert!(r.camera_on_head());
        assert_eq!(r.base_from_camera, None);
        assert_eq!(r.head_poses.len(), 3);
        assert!(
            r.head_poses
                .windows(2)
                .all(|w| w[0].stamp_ns < w[1].stamp_ns)
        );
        assert!(r.other_topics.is_empty(), "{:?}", r.other_topics);
        // Halfway between the first two: 5 cm and 0.05 rad along; outside, the nearest.
        let mid = r.head_at(1_005_000_000).expect("head");
        assert!((mid.translation.x - 0.05).abs() < 1e-12);
        assert!((mid.rotation.euler_angles().2 - 0.05).abs() < 1e-12);
        assert_eq!(r.head_at(0), Some(head(0).base_from_head));
        // The poses span 1.00-1.02 s: 50 ms either side is covered, not more.
        assert!(r.head_covers(1_010_000_000, 0) && r.head_covers(955_000_000, HEAD_POSE_SLACK_NS));
        assert!(!r.head_covers(945_000_000, HEAD_POSE_SLACK_NS));
        assert!(!r.head_covers(1_071_000_000, HEAD_POSE_SLACK_NS));
        let camera = r.camera_at(1_020_000_000).expect("camera");
        let expected = head(2).base_from_head * mount;
        assert!((camera.translation.vector - expected.translation.vector).norm() < 1e-12);
        assert!(camera.rotation.angle_to(&expected.rotation) < 1e-12);
    }

    #[test]
    fn bad_values_are_refused_before_they_are_written() {
        let path = temp("refused.mcap");
        let mut w = RecordingWriter::create(&path).expect("create");
        let e = w
            .joint_states(&JointStates {
                stamp_ns: 1,
                names: vec!["a".into(), "b".into()],
                positions: vec![0.0, f64::NAN],
                velocities: vec![],
            })
            .expect_err("NaN");
        assert!(e.to_string().contains("joint 'b' has NaN"), "{e}");
        let e = w
            .joint_states(&JointStates {
                stamp_ns: 1,
                names: vec!["a".into()],
                positions: vec![0.0, 1.0],
                velocities: vec![],
            })
            .expect_err("lengths");
        assert!(e.to_string().contains("1 names, 2 positions"), "{e}");
        let e = w
            .frame(&CompressedFrame {
                stamp_ns: 1,
                format: ImageFormat::Jpeg,
                data: PNG.to_vec(),
            })
            .expect_err("not jpeg");
        assert!(e.to_string().contains("not jpeg"), "{e}");
        let e = w
            .robot_command(&RobotCommand {
                stamp_ns: 1,
                names: vec!["j1".into()],
                velocities: vec![f64::NAN],
                gripper_closed: false,
                stopping: true,
                tcp_speed: 0.0,
            })
            .expect_err("a NaN command");
        assert!(e.to_string().contains("joint 'j1' has NaN"), "{e}");
        let e = w
            .hand(&HandPoses {
                stamp_ns: 1,
                hand: "right".into(),
                tracked: true,
                poses: vec![],
                radii: vec![],
            })
            .expect_err("tracked, no joints");
        assert!(e.to_string().contains("0 poses"), "{e}");
        let mut bad = calibration();
        bad.d.pop();
        let e = w.calibration(0, &bad).expect_err("7 of 8");
        assert!(e.to_string().contains("7 coefficients"), "{e}");
        assert_eq!(w.messages(), 0);
        w.finish().expect("finish");
        let r = Recording::open(&path).expect("an empty recording");
        assert!(r.frames.is_empty() && r.calibration.is_none());
    }

    /// A file written by another writer: one message `data` on the joint-state topic, its
    /// channel's metadata `metadata`.
    fn raw_joint_states(name: &str, metadata: &BTreeMap<String, String>, data: &[u8]) -> PathBuf {
        let path = temp(name);
        let file = File::create(&path).expect("create");
        let mut w = mcap::Writer::new(BufWriter::new(file)).expect("writer");
        let schema = w
            .add_schema("avatarm.JointState", "jsonschema", b"{}")
            .expect("schema");
        let channel_id = w
            .add_channel(schema, topics::JOINT_STATES, "json", metadata)
            .expect("channel");
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        };
        w.write_to_known_channel(&header, data).expect("message");
        w.finish().expect("finish");
        path
    }

    #[test]
    fn damaged_or_foreign_files_are_refused_by_name() {
        // Not MCAP.
        let path = temp("not.mcap");
        std::fs::write(&path, b"hello").expect("write");
        let e = Recording::open(&path).expect_err("not mcap");
        assert!(e.to_string().contains("not a readable MCAP file"), "{e}");
        // Another format version, and a message that is not its schema.
        let v2 = BTreeMap::from([("avatarm_format".to_owned(), "2".to_owned())]);
        let path = raw_joint_states("foreign.mcap", &v2, b"{}");
        let e = Recording::open(&path).expect_err("format 2");
        assert!(e.to_string().contains("format 2"), "{e}");
        let path = raw_joint_states(
            "bad_message.mcap",
            &BTreeMap::new(),
            br#"{"timestamp": {"sec": 1, "nsec": 0}, "name": ["a"], "position": [1.0, 2.0]}"#,
        );
        let e = Recording::open(&path).expect_err("sizes");
        assert!(
            e.to_string()
                .contains("/joint_states, message 0: 1 names, 2 positions"),
            "{e}"
        );
    }
}
