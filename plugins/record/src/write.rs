//! Writing a session ([`RecordingWriter`]): one channel per stream, each message checked before it
//! is written.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use base64::Engine;
use nalgebra::Isometry3;
use serde::Serialize;

use crate::camera::CameraCalibration;
use crate::error::RecordError;
use crate::schema::schema;
use crate::types::{
    CompressedFrame, HandPoses, HeadPose, ImageFormat, JointStates, ObjectTarget, RobotCommand,
    SafetyEvent,
};
use crate::wire::{
    Time, WireCalibration, WireCommand, WireHand, WireImage, WireJointState, WireLog,
    WireObjectTarget, WireTransform, finite_pose, object_target_fault, wire_pose,
};
use crate::{BASE_FRAME, CAMERA_FRAME, FORMAT_VERSION, HEAD_FRAME, WORLD_FRAME, topics};

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
