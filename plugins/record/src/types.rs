//! What a recording holds, as Avatarm uses it: frames, joint states, head poses, the operator's
//! hand, commands, object targets, safety events ([`Recording`]).

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Translation3};

use crate::camera::CameraCalibration;

/// One hand at one instant, as the hand source gave it.
#[derive(Debug, Clone, PartialEq)]
pub struct HandPoses {
    /// Capture time (ns).
    pub stamp_ns: u64,
    /// `left` or `right`.
    pub hand: String,
    /// Tracked; an untracked hand has no joints.
    pub tracked: bool,
    /// The joints' poses in [`WORLD_FRAME`](crate::WORLD_FRAME) (26, OpenXR's order, when tracked).
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
    /// The real object's target pose in [`WORLD_FRAME`](crate::WORLD_FRAME) (m).
    pub world_from_object: Isometry3<f64>,
    /// The real object's twist from the contacts ([`WORLD_FRAME`](crate::WORLD_FRAME) axes, at the
    /// object's origin): m/s, then rad/s.
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
    pub(crate) fn code(self) -> u8 {
        match self {
            Self::Info => 2,
            Self::Warning => 3,
            Self::Error => 4,
        }
    }

    pub(crate) fn of_code(code: u8) -> Option<Self> {
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
