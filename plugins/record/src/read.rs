//! Reading a recording back ([`Recording::open`]): every channel checked by its schema, its format
//! version and its messages.

use std::collections::BTreeMap;
use std::path::Path;

use base64::Engine;
use nalgebra::Isometry3;

use crate::camera::{CameraCalibration, DistortionModel};
use crate::error::RecordError;
use crate::types::{
    CompressedFrame, HandPoses, HeadPose, ImageFormat, JointStates, LogLevel, ObjectTarget,
    Recording, RobotCommand, SafetyEvent, head_at,
};
use crate::wire::{
    WireCalibration, WireCommand, WireHand, WireImage, WireJointState, WireLog, WireObjectTarget,
    WireTransform, object_target_fault, pose_of,
};
use crate::{BASE_FRAME, CAMERA_FRAME, FORMAT_VERSION, HEAD_FRAME, WORLD_FRAME, topics};

/// Makes the error of the message being read, from what is wrong with it.
type Bad<'a> = &'a dyn Fn(String) -> RecordError;

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
            out.take(&topic, &message.data, &bad)?;
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

    /// One message of a known topic, checked, into the recording.
    fn take(&mut self, topic: &str, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        match topic {
            topics::IMAGE | topics::REFERENCE_MASK | topics::ERASED | topics::MASK => {
                self.take_image(topic, data, bad)
            }
            topics::CALIBRATION => self.take_calibration(data, bad),
            topics::TRANSFORM => self.take_transform(topic, data, bad),
            topics::HAND => self.take_hand(data, bad),
            topics::ROBOT_COMMAND => self.take_command(data, bad),
            topics::OBJECT_TARGET => self.take_target(data, bad),
            topics::SAFETY => self.take_safety(data, bad),
            _ => self.take_joint_states(data, bad),
        }
    }

    /// A frame, a reference mask, an erased frame or a mask (`foxglove.CompressedImage`).
    fn take_image(&mut self, topic: &str, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireImage = serde_json::from_slice(data)
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
        match topic {
            topics::IMAGE => self.frames.push(frame),
            topics::REFERENCE_MASK => self.reference_masks.push(frame),
            topics::ERASED => self.erased.push(frame),
            _ => self.masks.push(frame),
        }
        Ok(())
    }

    /// The camera's calibration (`foxglove.CameraCalibration`).
    fn take_calibration(&mut self, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireCalibration = serde_json::from_slice(data)
            .map_err(|e| bad(format!("not a foxglove.CameraCalibration: {e}")))?;
        let model = DistortionModel::from_ros_name(&m.distortion_model)
            .ok_or_else(|| bad(format!("distortion model '{}'", m.distortion_model)))?;
        let k: [f64; 9] =
            m.K.try_into()
                .map_err(|k: Vec<f64>| bad(format!("K has {} values, not 9", k.len())))?;
        let c = CameraCalibration {
            width: m.width,
            height: m.height,
            k,
            distortion_model: model,
            d: m.D,
        };
        c.validate().map_err(|m| bad(m.0))?;
        self.calibration = Some(c);
        Ok(())
    }

    /// A pose (`foxglove.FrameTransform`): the camera's, the head's, the mount or the base in the
    /// world; another pair of frames is counted.
    fn take_transform(&mut self, topic: &str, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireTransform = serde_json::from_slice(data)
            .map_err(|e| bad(format!("not a foxglove.FrameTransform: {e}")))?;
        // An unrelated transform is counted, never refused: its pose is read only where it is
        // one of Avatarm's.
        let pose = || pose_of(&m.translation, &m.rotation).map_err(bad);
        match (m.parent_frame_id.as_str(), m.child_frame_id.as_str()) {
            (WORLD_FRAME, BASE_FRAME) => self.world_from_base = Some(pose()?),
            (BASE_FRAME, HEAD_FRAME) => self.head_poses.push(HeadPose {
                stamp_ns: m.timestamp.ns(),
                base_from_head: pose()?,
            }),
            (HEAD_FRAME, CAMERA_FRAME) => self.head_from_camera = Some(pose()?),
            (BASE_FRAME, CAMERA_FRAME) => self.base_from_camera = Some(pose()?),
            (parent, child) => {
                *self
                    .other_topics
                    .entry(format!("{topic} {parent} -> {child}"))
                    .or_default() += 1;
            }
        }
        Ok(())
    }

    /// The operator's hand (`foxglove.PosesInFrame`).
    fn take_hand(&mut self, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireHand = serde_json::from_slice(data)
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
        self.hands.push(HandPoses {
            stamp_ns: m.timestamp.ns(),
            hand: m.hand,
            tracked: m.tracked,
            poses,
            radii: m.radius,
        });
        Ok(())
    }

    /// A command to the robot (`avatarm.JointCommand`).
    fn take_command(&mut self, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireCommand = serde_json::from_slice(data)
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
        self.commands.push(RobotCommand {
            stamp_ns: m.timestamp.ns(),
            names: m.name,
            velocities: m.velocity,
            gripper_closed: m.gripper_closed,
            stopping: m.stopping,
            tcp_speed: m.tcp_speed,
        });
        Ok(())
    }

    /// The operator's object target (`avatarm.ObjectTarget`).
    fn take_target(&mut self, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireObjectTarget = serde_json::from_slice(data)
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
        self.targets.push(ObjectTarget {
            stamp_ns: m.timestamp.ns(),
            world_from_object: pose,
            object_twist: m.object_twist,
            twin_twist: m.twin_twist,
            squeeze_n: m.squeeze,
            grasp_rank: m.grasp_rank,
            contacts: m.contacts,
            held: m.held,
        });
        Ok(())
    }

    /// A safety event (`foxglove.Log`).
    fn take_safety(&mut self, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireLog =
            serde_json::from_slice(data).map_err(|e| bad(format!("not a foxglove.Log: {e}")))?;
        let level =
            LogLevel::of_code(m.level).ok_or_else(|| bad(format!("log level {}", m.level)))?;
        self.safety.push(SafetyEvent {
            stamp_ns: m.timestamp.ns(),
            level,
            source: m.name,
            message: m.message,
        });
        Ok(())
    }

    /// Joint states (`avatarm.JointState`).
    fn take_joint_states(&mut self, data: &[u8], bad: Bad) -> Result<(), RecordError> {
        let m: WireJointState = serde_json::from_slice(data)
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
        self.joint_states.push(JointStates {
            stamp_ns: m.timestamp.ns(),
            names: m.name,
            positions: m.position,
            velocities: m.velocity,
        });
        Ok(())
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
