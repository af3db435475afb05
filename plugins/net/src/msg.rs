//! The messages between the two sites, their encoding and their checks.
//!
//! Every message but a video frame's payload is JSON (serde) with the protocol version `v`
//! first; a frame is the coded image as the payload and its JSON [`FrameHeader`] as the
//! sample's attachment. Stamps are seconds on the **robot site's clock** (its session start);
//! the operator converts its own with its estimate of the offset ([`crate::ClockSample`]).
//!
//! Decoding checks, in order: the size ([`MAX_TARGET_BYTES`] and the others), the version
//! ([`PROTOCOL_VERSION`]), the fields (unknown fields are refused), then every number (finite,
//! in range). Each refusal is a [`NetError`] that names the message and the field.

use avatarm_core::teleop::mapping::OperatorTarget;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector6};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::NetError;

/// A video codec on the wire ([`FrameHeader::codec`]; its coders are in `crate::codec`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Codec {
    /// Baseline JPEG (ISO/IEC 10918-1) per frame, through the `image` crate.
    #[default]
    Jpeg,
    /// H.264 Constrained Baseline (ITU-T H.264, Annex B byte stream), through OpenH264.
    H264,
}

impl Codec {
    /// The name on the wire and on the command line: `jpeg` or `h264`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Jpeg => "jpeg",
            Self::H264 => "h264",
        }
    }

    /// The codec of a name, if it is one.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "jpeg" => Some(Self::Jpeg),
            "h264" => Some(Self::H264),
            _ => None,
        }
    }
}

impl std::fmt::Display for Codec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A target stamped further ahead of the robot's clock than this is refused: the operator's
/// clock estimate is wrong, and its age could not be trusted (s).
pub const MAX_AHEAD_S: f64 = 0.5;

/// The protocol's version: a peer with another is refused with both versions named. Raised
/// on every change of a message's fields or meaning (6: [`RobotInfo::operators`]).
pub const PROTOCOL_VERSION: u32 = 6;

/// Largest operator target accepted (bytes): one is ~400.
pub const MAX_TARGET_BYTES: usize = 4096;
/// Largest hand frame accepted (bytes): 26 joints are ~3 kB.
pub const MAX_HAND_BYTES: usize = 32 * 1024;
/// Largest head pose accepted (bytes): one is ~200.
pub const MAX_HEAD_BYTES: usize = 4096;
/// Largest joint-state, status or info message accepted (bytes).
pub const MAX_SMALL_BYTES: usize = 64 * 1024;
/// Largest coded video frame accepted (bytes): a 1080p JPEG at quality 95 is under 1 MB.
pub const MAX_FRAME_BYTES: usize = 8 << 20;
/// Largest frame index or stream number accepted (2^53: a frame a millisecond for 285 000
/// years), so that counting on from one never overflows.
pub const MAX_SEQ: u64 = 1 << 53;
/// Largest number of joints in a joint state.
pub const MAX_JOINTS: usize = 64;

/// The operator's target for one control tick: [`OperatorTarget`] on the wire, with the hand
/// frame's stamp and tracking state for the robot site's watchdog.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetMsg {
    /// Protocol version.
    pub v: u32,
    /// Sequence number (per operator session, from 0): a target older than one already used
    /// is dropped.
    pub seq: u64,
    /// When the twin was there (s, robot clock).
    pub stamp_s: f64,
    /// When the hand frame behind it was captured (s, robot clock).
    pub hand_stamp_s: f64,
    /// The operator's hand is tracked.
    pub hand_tracked: bool,
    /// The real object's target position (m, real world).
    pub position: [f64; 3],
    /// Its orientation, unit quaternion `[x, y, z, w]`.
    pub rotation_xyzw: [f64; 4],
    /// The real object's twist (real world, at its origin: m/s then rad/s).
    pub object_twist: [f64; 6],
    /// The twin's twist (virtual scene).
    pub twin_twist: [f64; 6],
    /// Squeezing force σ (N).
    pub squeeze_n: f64,
    /// Grasp matrix rank.
    pub rank: u8,
    /// Contacts on the twin.
    pub contacts: u32,
    /// The hand holds the twin.
    pub held: bool,
}

impl TargetMsg {
    /// The message for `target` (its stamp already on the robot's clock).
    pub fn new(seq: u64, target: &OperatorTarget, hand_stamp_s: f64, hand_tracked: bool) -> Self {
        let t = target.target.translation.vector;
        let q = target.target.rotation.quaternion().coords;
        Self {
            v: PROTOCOL_VERSION,
            seq,
            stamp_s: target.stamp_s,
            hand_stamp_s,
            hand_tracked,
            position: [t.x, t.y, t.z],
            rotation_xyzw: [q.x, q.y, q.z, q.w],
            object_twist: array6(&target.object_twist),
            twin_twist: array6(&target.twin_twist),
            squeeze_n: target.squeeze_n,
            rank: target.rank.min(6) as u8,
            contacts: target.contacts.min(u32::MAX as usize) as u32,
            held: target.held,
        }
    }

    /// The target it carries, checked ([`OperatorTarget::validate`] and the hand's stamp).
    pub fn target(&self) -> Result<OperatorTarget, NetError> {
        let [x, y, z, w] = self.rotation_xyzw;
        let t = OperatorTarget {
            stamp_s: self.stamp_s,
            target: Isometry3::from_parts(
                Translation3::new(self.position[0], self.position[1], self.position[2]),
                UnitQuaternion::new_unchecked(Quaternion::new(w, x, y, z)),
            ),
            object_twist: Vector6::from_row_slice(&self.object_twist),
            twin_twist: Vector6::from_row_slice(&self.twin_twist),
            squeeze_n: self.squeeze_n,
            rank: usize::from(self.rank),
            contacts: self.contacts as usize,
            held: self.held,
        };
        t.validate().map_err(|e| NetError::Invalid {
            what: "target".into(),
            message: e.to_string(),
        })?;
        if !self.hand_stamp_s.is_finite() {
            return Err(NetError::Invalid {
                what: "target".into(),
                message: format!("hand_stamp_s {} is not finite", self.hand_stamp_s),
            });
        }
        Ok(t)
    }
}

fn array6(v: &Vector6<f64>) -> [f64; 6] {
    [v[0], v[1], v[2], v[3], v[4], v[5]]
}

/// The robot's joint states, as the robot site received them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointStatesMsg {
    /// Protocol version.
    pub v: u32,
    /// When they were sampled (s, robot clock).
    pub stamp_s: f64,
    /// Joint positions (rad or m, the robot model's order).
    pub positions: Vec<f64>,
    /// Joint velocities (rad/s or m/s).
    pub velocities: Vec<f64>,
    /// The real object's pose (its centre) where the robot site knows it (simulation):
    /// position (m) then quaternion `[x, y, z, w]`.
    pub object: Option<[f64; 7]>,
}

impl JointStatesMsg {
    fn check(&self) -> Result<(), NetError> {
        let bad = |message: String| {
            Err(NetError::Invalid {
                what: "joint_states".into(),
                message,
            })
        };
        if self.positions.len() > MAX_JOINTS || self.velocities.len() != self.positions.len() {
            return bad(format!(
                "{} positions and {} velocities (at most {MAX_JOINTS}, as many of each)",
                self.positions.len(),
                self.velocities.len()
            ));
        }
        let finite = self.stamp_s.is_finite()
            && self
                .positions
                .iter()
                .chain(&self.velocities)
                .all(|v| v.is_finite())
            && self.object.is_none_or(|o| o.iter().all(|v| v.is_finite()));
        if !finite {
            return bad("a value is not finite".into());
        }
        if let Some(o) = self.object.filter(|o| !pose_ok(o)) {
            return bad(format!(
                "the object's pose {o:?} is beyond 100 m or not a unit quaternion"
            ));
        }
        Ok(())
    }
}

/// The robot site's state, a few times a second and on every change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotStatusMsg {
    /// Protocol version.
    pub v: u32,
    /// When (s, robot clock).
    pub stamp_s: f64,
    /// The limiter is stopping (or holding) the arm.
    pub stopping: bool,
    /// Why the arm is stopped, when it is.
    pub reason: Option<String>,
    /// Control ticks run.
    pub ticks: u64,
    /// Targets refused (malformed, another version, out of range).
    pub refused_targets: u64,
    /// Targets used.
    pub targets: u64,
    /// An operator is present (its liveliness token is there).
    pub operator_present: bool,
}

/// What the robot site says about itself when asked ([`crate::keys::Keys::info`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotInfo {
    /// Protocol version.
    pub v: u32,
    /// Avatarm's version (Cargo's).
    pub software: String,
    /// The scene's name.
    pub scene: String,
    /// FNV-1a hash of the scene file's text, hexadecimal: the operator's scene must match.
    pub scene_hash: String,
    /// The cameras whose erased video is published, by name.
    pub cameras: Vec<String>,
    /// Control rate (Hz).
    pub control_rate_hz: f64,
    /// Targets older than this stop the arm (s).
    pub target_timeout_s: f64,
    /// The robot backend's name.
    pub robot: String,
    /// The users the robot site takes targets from (its `--operator` list); empty: no access
    /// control (anyone who reaches it may command). `join` refuses at once to command as a
    /// user not among them, naming `--watch`; the access control refuses its targets anyway.
    /// Absent in a version 5 message (read as empty, so that the version check names both).
    #[serde(default)]
    pub operators: Vec<String>,
}

/// A coded video frame's header (the sample's attachment; the payload is the coded image).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameHeader {
    /// Protocol version.
    pub v: u32,
    /// Camera name.
    pub camera: String,
    /// Frame index at the camera.
    pub index: u64,
    /// Codec: `jpeg` or `h264` ([`Codec`]).
    pub codec: String,
    /// Coded frame number of this camera's stream (from 0, one per published frame): a gap
    /// tells an H.264 viewer that a frame its next ones refer to was lost.
    pub seq: u64,
    /// The frame decodes on its own (every JPEG; an H.264 IDR frame with its SPS and PPS).
    pub keyframe: bool,
    /// The coded stream's identity: `seq` counts within it (a restarted robot site starts
    /// another).
    pub stream: u64,
    /// Width and height (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Stage stamps (s, robot clock): captured by the camera.
    pub capture_s: f64,
    /// Arrived in the robot site's app (taken from the camera's driver, player or renderer).
    pub arrived_s: f64,
    /// Erased (the composite read back).
    pub erased_s: f64,
    /// Coded and handed to the network.
    pub sent_s: f64,
    /// The robot site's app update (its frame count) the frame arrived in.
    pub arrived_update: u64,
    /// The update its erased image was read back in and handed to the encoder: a frame that
    /// waited no longer than it must has `handed_update - arrived_update` at most 1.
    pub handed_update: u64,
    /// The camera's pose the frame's mask was drawn from (`world_from_camera`, the scene's
    /// world, OpenCV optical axes): position (m) then unit quaternion `[x, y, z, w]`. A camera
    /// on a head moves, and a viewer places the hand and the twins in front of the frame from
    /// it.
    pub camera_pose: [f64; 7],
}

impl FrameHeader {
    /// [`FrameHeader::camera_pose`] for `world_from_camera`.
    pub fn pose_of(world_from_camera: &Isometry3<f64>) -> [f64; 7] {
        let t = world_from_camera.translation.vector;
        let q = world_from_camera.rotation.quaternion().coords;
        [t.x, t.y, t.z, q.x, q.y, q.z, q.w]
    }

    /// The camera's pose ([`FrameHeader::camera_pose`]; [`pose_from_wire`]).
    pub fn world_from_camera(&self) -> Isometry3<f64> {
        pose_from_wire(&self.camera_pose)
    }

    fn check(&self) -> Result<(), NetError> {
        let ok = Codec::from_name(&self.codec).is_some()
            && self.seq <= MAX_SEQ
            && self.index <= MAX_SEQ
            && self.stream <= MAX_SEQ
            && (1..=8192).contains(&self.width)
            && (1..=8192).contains(&self.height)
            && [self.capture_s, self.arrived_s, self.erased_s, self.sent_s]
                .iter()
                .all(|v| v.is_finite())
            && self.camera.len() <= 64;
        if ok && !pose_ok(&self.camera_pose) {
            return Err(NetError::Invalid {
                what: "frame header".into(),
                message: format!(
                    "camera pose {:?}: not finite, beyond 100 m or not a unit quaternion",
                    self.camera_pose
                ),
            });
        }
        if ok {
            Ok(())
        } else {
            Err(NetError::Invalid {
                what: "frame header".into(),
                message: format!(
                    "codec '{}' (jpeg or h264), index {} and seq {} (..={MAX_SEQ}), {}x{} (1..=8192), stamps {} {} {} (finite)",
                    self.codec,
                    self.index,
                    self.seq,
                    self.width,
                    self.height,
                    self.capture_s,
                    self.erased_s,
                    self.sent_s
                ),
            })
        }
    }
}

/// A pose from the wire (position, m, then quaternion `[x, y, z, w]`), the quaternion
/// normalised: for a pose the message's check has passed ([`pose_ok`]).
pub fn pose_from_wire(p: &[f64; 7]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_quaternion(Quaternion::new(p[6], p[3], p[4], p[5])),
    )
}

/// A pose on the wire (position, m, then quaternion `[x, y, z, w]`): finite, within 100 m of
/// the origin, the quaternion within 1e-3 of unit length.
fn pose_ok(p: &[f64; 7]) -> bool {
    let position = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let norm = (p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]).sqrt();
    p.iter().all(|v| v.is_finite()) && position <= 100.0 && (norm - 1.0).abs() <= 1e-3
}

/// The operator's hand for observers: joint positions (m, real world), tracked or not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandMsg {
    /// Protocol version.
    pub v: u32,
    /// Capture time (s, robot clock).
    pub stamp_s: f64,
    /// `left` or `right`.
    pub hand: String,
    /// Tracked.
    pub tracked: bool,
    /// Joint positions (m, real world), in OpenXR's joint order.
    pub joints: Vec<[f64; 3]>,
    /// While the hand holds the object: the object's twin in the real world (its centre,
    /// position then quaternion `[x, y, z, w]`) at the control tick the message is sent. A viewer
    /// whose camera rides on a head (Alice's view) draws the hand carried with the real object from
    /// it, so that it holds the bottle she sees.
    pub held_object: Option<[f64; 7]>,
}

impl HandMsg {
    fn check(&self) -> Result<(), NetError> {
        let ok = self.stamp_s.is_finite()
            && (self.hand == "left" || self.hand == "right")
            && self.joints.len() <= 32
            && self.joints.iter().flatten().all(|v| v.is_finite())
            && self.held_object.is_none_or(|o| pose_ok(&o));
        if ok {
            Ok(())
        } else {
            Err(NetError::Invalid {
                what: "hand".into(),
                message: "a side of left or right, at most 32 finite joints, a held object's pose finite, within 100 m and with a unit quaternion".into(),
            })
        }
    }
}

/// The head a camera rides on, as the wearer's headset reports it (Alice's, at the site where
/// she wears it): the robot site draws that camera's mask from it instead of its own
/// simulated head. Sent on `camera/<name>/head` ([`crate::Keys::head`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadPoseMsg {
    /// Protocol version.
    pub v: u32,
    /// When the wearer's site took the pose (s, robot clock): a headset's newest, up to a
    /// window frame and a control tick after the moment it describes; a recording's, at its
    /// moment in the playback. The robot site refuses one stamped more than 0.5 s ahead of
    /// its clock.
    pub stamp_s: f64,
    /// The camera that rides on the head (its name in the scene).
    pub camera: String,
    /// `world_from_head` in the scene's world (z up; the head's frame optical: x right, y
    /// down, z forward), position (m) then quaternion `[x, y, z, w]`.
    pub pose: [f64; 7],
}

impl HeadPoseMsg {
    /// The head's pose ([`pose_from_wire`]).
    pub fn world_from_head(&self) -> Isometry3<f64> {
        pose_from_wire(&self.pose)
    }

    fn check(&self) -> Result<(), NetError> {
        if !(self.stamp_s.is_finite() && !self.camera.is_empty() && self.camera.len() <= 64) {
            return Err(NetError::Invalid {
                what: "head pose".into(),
                message: format!(
                    "stamp {} s (finite) and camera '{}' (1-64 characters)",
                    self.stamp_s, self.camera
                ),
            });
        }
        if !pose_ok(&self.pose) {
            return Err(NetError::Invalid {
                what: "head pose".into(),
                message: format!(
                    "{:?}: not finite, beyond 100 m or not a unit quaternion",
                    self.pose
                ),
            });
        }
        Ok(())
    }
}

/// Encodes a message (JSON). Errors only for a non-finite number, which JSON cannot hold.
pub fn encode<T: Serialize>(what: &str, message: &T) -> Result<Vec<u8>, NetError> {
    serde_json::to_vec(message).map_err(|e| NetError::Invalid {
        what: what.into(),
        message: e.to_string(),
    })
}

#[derive(Deserialize)]
struct Versioned {
    v: Option<u32>,
}

/// Decodes `bytes` as `what`: size, version, fields, in that order.
fn decode<T: DeserializeOwned>(what: &str, bytes: &[u8], max: usize) -> Result<T, NetError> {
    if bytes.len() > max {
        return Err(NetError::Invalid {
            what: what.into(),
            message: format!("{} bytes, more than the {max} allowed", bytes.len()),
        });
    }
    let version: Versioned = serde_json::from_slice(bytes).map_err(|e| NetError::Invalid {
        what: what.into(),
        message: format!("not a message: {e}"),
    })?;
    match version.v {
        Some(PROTOCOL_VERSION) => {}
        other => {
            return Err(NetError::Version {
                what: what.into(),
                theirs: other,
            });
        }
    }
    serde_json::from_slice(bytes).map_err(|e| NetError::Invalid {
        what: what.into(),
        message: e.to_string(),
    })
}

/// Decodes and checks an operator target ([`TargetMsg::target`]).
pub fn decode_target(bytes: &[u8]) -> Result<(TargetMsg, OperatorTarget), NetError> {
    let m: TargetMsg = decode("target", bytes, MAX_TARGET_BYTES)?;
    let t = m.target()?;
    Ok((m, t))
}

/// Decodes and checks a joint-state message.
pub fn decode_joint_states(bytes: &[u8]) -> Result<JointStatesMsg, NetError> {
    let m: JointStatesMsg = decode("joint_states", bytes, MAX_SMALL_BYTES)?;
    m.check()?;
    Ok(m)
}

/// Decodes a robot status.
pub fn decode_status(bytes: &[u8]) -> Result<RobotStatusMsg, NetError> {
    let m: RobotStatusMsg = decode("status", bytes, MAX_SMALL_BYTES)?;
    if !m.stamp_s.is_finite() {
        return Err(NetError::Invalid {
            what: "status".into(),
            message: "stamp_s is not finite".into(),
        });
    }
    Ok(m)
}

/// Decodes the robot site's info.
pub fn decode_info(bytes: &[u8]) -> Result<RobotInfo, NetError> {
    decode("info", bytes, MAX_SMALL_BYTES)
}

/// Decodes and checks a frame header; `payload_len` is the coded image's size.
pub fn decode_frame_header(bytes: &[u8], payload_len: usize) -> Result<FrameHeader, NetError> {
    let h: FrameHeader = decode("frame header", bytes, MAX_SMALL_BYTES)?;
    h.check()?;
    if payload_len > MAX_FRAME_BYTES || payload_len == 0 {
        return Err(NetError::Invalid {
            what: "frame".into(),
            message: format!("{payload_len} bytes (1..={MAX_FRAME_BYTES})"),
        });
    }
    Ok(h)
}

/// Decodes and checks a hand frame.
pub fn decode_hand(bytes: &[u8]) -> Result<HandMsg, NetError> {
    let m: HandMsg = decode("hand", bytes, MAX_HAND_BYTES)?;
    m.check()?;
    Ok(m)
}

/// Decodes a head pose; errors name the field.
pub fn decode_head(bytes: &[u8]) -> Result<HeadPoseMsg, NetError> {
    let m: HeadPoseMsg = decode("head pose", bytes, MAX_HEAD_BYTES)?;
    m.check()?;
    Ok(m)
}

/// FNV-1a (64 bit) of `bytes`, hexadecimal: the scene's fingerprint in [`RobotInfo`].
pub fn fingerprint(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target() -> OperatorTarget {
        OperatorTarget {
            stamp_s: 1.25,
            target: Isometry3::from_parts(
                Translation3::new(0.6, -0.1, 0.9),
                UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
            ),
            object_twist: Vector6::new(0.01, 0.02, 0.0, 0.0, 0.1, 0.0),
            twin_twist: Vector6::new(0.02, 0.04, 0.0, 0.0, 0.1, 0.0),
            squeeze_n: 3.5,
            rank: 6,
            contacts: 4,
            held: true,
        }
    }

    #[test]
    fn a_target_crosses_unchanged() {
        let t = target();
        let bytes = encode("target", &TargetMsg::new(7, &t, 1.2, true)).expect("encodes");
        assert!(bytes.len() < MAX_TARGET_BYTES);
        let (m, back) = decode_target(&bytes).expect("decodes");
        assert_eq!(m.seq, 7);
        assert_eq!(back.stamp_s, t.stamp_s);
        assert!((back.target.translation.vector - t.target.translation.vector).norm() < 1e-12);
        assert!(back.target.rotation.angle_to(&t.target.rotation) < 1e-9);
        assert_eq!(back.object_twist, t.object_twist);
        assert_eq!((back.squeeze_n, back.rank, back.held), (3.5, 6, true));
    }

    #[test]
    fn bad_targets_are_refused_with_the_reason() {
        let good = encode("target", &TargetMsg::new(1, &target(), 1.2, true)).expect("encodes");
        let text = String::from_utf8(good.clone()).expect("utf-8");
        let ours = format!("\"v\":{PROTOCOL_VERSION}");
        let foreign = format!("version {}", PROTOCOL_VERSION + 1);
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"not json".to_vec(), "not a message"),
            (vec![b' '; MAX_TARGET_BYTES + 1], "more than"),
            (
                text.replacen(&ours, &format!("\"v\":{}", PROTOCOL_VERSION + 1), 1)
                    .into_bytes(),
                foreign.as_str(),
            ),
            (
                text.replacen(&format!("{ours},"), "", 1).into_bytes(),
                "no version",
            ),
            (
                text.replacen("\"squeeze_n\":3.5", "\"squeeze_n\":-1.0", 1)
                    .into_bytes(),
                "squeeze_n",
            ),
            (
                text.replacen("\"position\":[0.6", "\"position\":[60.0", 1)
                    .into_bytes(),
                "position",
            ),
            (
                text.replacen("\"rank\":6", "\"rank\":7", 1).into_bytes(),
                "rank",
            ),
            (
                text.replacen("\"held\":true", "\"held\":true,\"extra\":1", 1)
                    .into_bytes(),
                "unknown field",
            ),
            (
                text.replacen("\"squeeze_n\":3.5", "\"squeeze_n\":1e999", 1)
                    .into_bytes(),
                "",
            ),
        ];
        for (bytes, says) in cases {
            let e = decode_target(&bytes).expect_err("refused");
            assert!(e.to_string().contains(says), "{e} should say '{says}'");
        }
        // A rotation that is not a unit quaternion.
        let mut m = TargetMsg::new(1, &target(), 1.2, true);
        m.rotation_xyzw = [0.0, 0.0, 0.0, 2.0];
        let e = m.target().expect_err("refused");
        assert!(e.to_string().contains("rotation"), "{e}");
        // NaN cannot even be encoded.
        m.squeeze_n = f64::NAN;
        assert!(encode("target", &m).is_ok_and(|b| decode_target(&b).is_err()));
    }

    #[test]
    fn headers_and_joint_states_are_checked() {
        let h = FrameHeader {
            v: PROTOCOL_VERSION,
            camera: "desk".into(),
            index: 3,
            codec: "jpeg".into(),
            seq: 2,
            keyframe: true,
            stream: 7,
            width: 640,
            height: 480,
            capture_s: 1.0,
            arrived_s: 1.005,
            erased_s: 1.01,
            sent_s: 1.02,
            arrived_update: 40,
            handed_update: 41,
            camera_pose: FrameHeader::pose_of(&Isometry3::from_parts(
                Translation3::new(1.85, 0.1, 1.3),
                UnitQuaternion::from_euler_angles(-2.0, 0.1, 1.6),
            )),
        };
        let bytes = encode("frame header", &h).expect("encodes");
        let back = decode_frame_header(&bytes, 1000).expect("decodes");
        let d = back.world_from_camera().inverse() * h.world_from_camera();
        assert!(d.translation.vector.norm() < 1e-12 && d.rotation.angle() < 1e-12);
        // (A NaN is JSON's null: refused as not a number.)
        for (i, v, why) in [
            (2, f64::NAN, "null"),
            (0, 1e3, "camera pose"),
            (6, 2.0, "camera pose"),
        ] {
            let mut bad = h.clone();
            bad.camera_pose[i] = v;
            let e = decode_frame_header(&encode("h", &bad).expect("encodes"), 10)
                .expect_err("a bad camera pose");
            assert!(e.to_string().contains(why), "{e}");
        }
        assert_eq!(decode_frame_header(&bytes, 1000).expect("decodes"), h);
        assert!(decode_frame_header(&bytes, 0).is_err());
        let mut bad = h.clone();
        bad.codec = "h265".into();
        assert!(decode_frame_header(&encode("h", &bad).expect("encodes"), 10).is_err());
        let mut bad = h.clone();
        bad.seq = u64::MAX;
        let e = decode_frame_header(&encode("h", &bad).expect("encodes"), 10).expect_err("refused");
        assert!(
            e.to_string().contains("seq") && !e.to_string().contains("camera pose"),
            "{e}"
        );
        let j = JointStatesMsg {
            v: PROTOCOL_VERSION,
            stamp_s: 0.5,
            positions: vec![0.1; 9],
            velocities: vec![0.0; 8],
            object: None,
        };
        let e = decode_joint_states(&encode("j", &j).expect("encodes")).expect_err("refused");
        assert!(
            e.to_string().contains("9 positions and 8 velocities"),
            "{e}"
        );
        // The real object's pose and the held twin's: unit quaternions, or refused.
        let j = JointStatesMsg {
            velocities: vec![0.0; 9],
            object: Some([0.5, 0.0, 0.8, 0.0, 0.0, 0.0, 0.0]),
            ..j
        };
        let e = decode_joint_states(&encode("j", &j).expect("encodes")).expect_err("refused");
        assert!(e.to_string().contains("object's pose"), "{e}");
        let twin = [0.5, 0.0, 0.8, 0.0, 0.0, 0.0, 1.0];
        let mut hand = HandMsg {
            v: PROTOCOL_VERSION,
            stamp_s: 0.5,
            hand: "right".into(),
            tracked: true,
            joints: vec![[0.1, 0.2, 0.3]; 26],
            held_object: Some(twin),
        };
        let back = decode_hand(&encode("hand", &hand).expect("encodes")).expect("decodes");
        assert_eq!(back.held_object, Some(twin));
        hand.held_object = Some([0.5, 0.0, 0.8, 0.0, 0.0, 2.0, 0.0]);
        let e = decode_hand(&encode("hand", &hand).expect("encodes")).expect_err("refused");
        assert!(e.to_string().contains("held object"), "{e}");
    }

    #[test]
    fn a_head_pose_crosses_unchanged_and_a_bad_one_is_refused_by_field() {
        let pose = Isometry3::from_parts(
            Translation3::new(0.8, -1.0, 1.2),
            UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
        );
        let m = HeadPoseMsg {
            v: PROTOCOL_VERSION,
            stamp_s: 3.5,
            camera: "alice".into(),
            pose: FrameHeader::pose_of(&pose),
        };
        let back = decode_head(&encode("head pose", &m).expect("encodes")).expect("decodes");
        assert_eq!((back.stamp_s, back.camera.as_str()), (3.5, "alice"));
        assert!(back.world_from_head().rotation.angle_to(&pose.rotation) < 1e-12);
        let refused = |f: &dyn Fn(&mut HeadPoseMsg), says: &str| {
            let mut bad = m.clone();
            f(&mut bad);
            let e = decode_head(&encode("head pose", &bad).expect("encodes")).expect_err(says);
            assert!(e.to_string().contains(says), "{e}");
        };
        refused(&|b| b.pose[6] = 2.0, "unit quaternion");
        refused(&|b| b.pose[0] = 1e3, "100 m");
        refused(&|b| b.camera.clear(), "camera");
        refused(&|b| b.v = PROTOCOL_VERSION - 1, "version");
    }
}
