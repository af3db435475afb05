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

//!
//! Modules: [`types`] (what a recording holds), [`write`] ([`RecordingWriter`]), [`read`]
//! ([`Recording::open`]), [`error`], [`camera`] (the camera files labs have); the wire messages
//! and the channels' schemas are the crate's own (`wire`, `schema`).

pub mod camera;
pub mod error;
pub mod read;
mod schema;
#[cfg(test)]
mod tests;
pub mod types;
mod wire;
pub mod write;

pub use camera::{CameraCalibration, CameraFileError, DistortionModel, InvalidCalibration};
pub use error::RecordError;
pub use types::{
    CompressedFrame, HEAD_POSE_SLACK_NS, HandPoses, HeadPose, ImageFormat, JointStates, LogLevel,
    ObjectTarget, Recording, RobotCommand, SafetyEvent, head_at,
};
pub use write::RecordingWriter;

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
