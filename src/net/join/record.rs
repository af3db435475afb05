//! `join --record`: what the operator's site writes of a session (the received video with its
//! camera poses, the hand, the targets), each frame once, stamped on the robot's clock.

use super::*;

/// What `join --record` wrote.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct JoinRecording {
    /// The file.
    pub path: PathBuf,
    /// The camera whose erased frames were recorded (the one this site views).
    pub camera: Option<String>,
    /// Erased frames written.
    pub erased_frames: u64,
    /// Joint states written.
    pub joint_states: u64,
    /// The robot site's stops written (as safety events).
    pub stops: u64,
    /// The operator's own hand frames written (an operator's site).
    pub hands: u64,
    /// The operator's targets written, each one sent (an operator's site).
    pub targets: u64,
    /// Messages the recording refused (bad values, a failed write), and the first reason.
    pub refused: u64,
    /// The first refusal.
    pub first_refusal: Option<String>,
}

/// `join --record`: what the operator's (or observer's) site receives, written as it arrives:
/// its camera's erased frames (JPEG as received; an H.264 frame coded to JPEG as
/// `run --record` codes its frames) with the camera pose each was erased from, the robot's
/// joint states and its stops, and at an operator's site her own hand (in the hand's world,
/// as `run --record` writes it) and every target she sent (the real object's, in the world),
/// stamped on the robot site's clock moved to the Unix epoch at the join (so that MCAP tools
/// show wall time).
///
/// The camera's poses: a fixed camera's, once (the first frame's); a camera on a head's, each
/// frame's as the head's pose at its capture with an identity mount (the head's frame is then
/// the camera's own), so that [`avatarm_record::Recording::camera_at`] gives each frame's.
pub(super) struct JoinRecorder {
    pub(super) writer: RecordingWriter,
    /// Unix time (ns) of the robot site's clock's 0 s.
    pub(super) epoch_ns: i128,
    pub(super) names: Vec<String>,
    /// The scene's world in the robot's base frame (the recording's frame).
    pub(super) base_from_world: nalgebra::Isometry3<f64>,
    /// The recorded camera rides on a head: each frame's pose is written.
    pub(super) on_head: bool,
    /// The camera's pose (or, on a head, the identity mount) is written.
    pub(super) camera_written: bool,
    /// The hand source's time of the last hand frame written.
    pub(super) last_hand: Option<f64>,
    pub(super) report: JoinRecording,
}

impl JoinRecorder {
    /// Creates `path` and writes the scene's camera calibration; errors name the file.
    pub(super) fn create(path: &std::path::Path, scene: &Scene) -> Result<Self, AppError> {
        let mut writer = RecordingWriter::create(path)?;
        let now_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        writer.calibration(now_ns, &crate::replay::scene_calibration(scene))?;
        Ok(Self {
            writer,
            epoch_ns: i128::from(now_ns),
            names: scene
                .model
                .dof_names()
                .iter()
                .map(|n| n.to_string())
                .collect(),
            base_from_world: scene.robot_base().inverse(),
            on_head: scene.head.is_some(),
            camera_written: false,
            last_hand: None,
            report: JoinRecording {
                path: path.to_owned(),
                ..JoinRecording::default()
            },
        })
    }

    /// The robot site's clock is `robot_now_s` now: its 0 s is that long before the epoch's
    /// now.
    pub(super) fn set_clock(&mut self, robot_now_s: f64) {
        if robot_now_s.is_finite() {
            let now_ns = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as i128);
            self.epoch_ns = now_ns - (robot_now_s * 1e9) as i128;
        }
    }

    /// `t_s` on the robot site's clock as a recording's stamp; `None` when not finite or
    /// before the epoch.
    pub(super) fn stamp_ns(&self, t_s: f64) -> Option<u64> {
        if !t_s.is_finite() || t_s.abs() > 1e9 {
            return None;
        }
        u64::try_from(self.epoch_ns + (t_s * 1e9) as i128).ok()
    }

    pub(super) fn refused(&mut self, why: String) {
        self.report.refused += 1;
        if self.report.first_refusal.is_none() {
            warn!("join --record: {why}");
            self.report.first_refusal = Some(why);
        }
    }

    pub(super) fn joint_states(&mut self, m: &avatarm_net::msg::JointStatesMsg) {
        let Some(stamp_ns) = self.stamp_ns(m.stamp_s) else {
            return self.refused(format!("joint states stamped {} s", m.stamp_s));
        };
        let names = if self.names.len() == m.positions.len() {
            self.names.clone()
        } else {
            (0..m.positions.len()).map(|i| format!("q{i}")).collect()
        };
        let states = avatarm_record::JointStates {
            stamp_ns,
            names,
            positions: m.positions.clone(),
            velocities: m.velocities.clone(),
        };
        match self.writer.joint_states(&states) {
            Ok(()) => self.report.joint_states += 1,
            Err(e) => self.refused(e.to_string()),
        }
    }

    /// The operator's hand frame, taken at `stamp_s` (robot clock); a frame already written
    /// (the hand source gave none newer) is not written again.
    pub(super) fn hand(&mut self, f: &avatarm_core::teleop::hand::HandFrame, stamp_s: f64) {
        if self.last_hand == Some(f.t_s) {
            return;
        }
        self.last_hand = Some(f.t_s);
        let Some(stamp_ns) = self.stamp_ns(stamp_s) else {
            return self.refused(format!("a hand frame taken at {stamp_s} s"));
        };
        let hand = avatarm_record::HandPoses {
            stamp_ns,
            hand: match f.hand {
                avatarm_core::teleop::hand::Handedness::Left => "left".into(),
                avatarm_core::teleop::hand::Handedness::Right => "right".into(),
            },
            tracked: f.tracked,
            poses: f.joints.iter().map(|j| j.pose).collect(),
            radii: f.joints.iter().map(|j| j.radius).collect(),
        };
        match self.writer.hand(&hand) {
            Ok(()) => self.report.hands += 1,
            Err(e) => self.refused(e.to_string()),
        }
    }

    /// A target the operator sent (its stamp on the robot site's clock).
    pub(super) fn target(&mut self, t: &avatarm_core::teleop::mapping::OperatorTarget) {
        let Some(stamp_ns) = self.stamp_ns(t.stamp_s) else {
            return self.refused(format!("a target stamped {} s", t.stamp_s));
        };
        match self
            .writer
            .object_target(&crate::session::object_target(stamp_ns, t))
        {
            Ok(()) => self.report.targets += 1,
            Err(e) => self.refused(e.to_string()),
        }
    }

    pub(super) fn stop(&mut self, m: &avatarm_net::msg::RobotStatusMsg) {
        let Some(stamp_ns) = self.stamp_ns(m.stamp_s) else {
            return self.refused(format!("robot status stamped {} s", m.stamp_s));
        };
        let event = avatarm_record::SafetyEvent {
            stamp_ns,
            level: avatarm_record::LogLevel::Error,
            source: "robot site".into(),
            message: format!(
                "stopping the arm: {}",
                m.reason.as_deref().unwrap_or("no reason given")
            ),
        };
        match self.writer.safety_event(&event) {
            Ok(()) => self.report.stops += 1,
            Err(e) => self.refused(e.to_string()),
        }
    }

    /// One decoded frame of `camera` (the first camera received is the one recorded).
    pub(super) fn frame(&mut self, h: &avatarm_net::msg::FrameHeader, payload: &[u8], rgba: &[u8]) {
        if self.report.camera.get_or_insert_with(|| h.camera.clone()) != &h.camera {
            return;
        }
        let Some(stamp_ns) = self.stamp_ns(h.capture_s) else {
            return self.refused(format!("a frame captured at {} s", h.capture_s));
        };
        // The camera the frame's mask was drawn from (checked finite and unit on receipt).
        let base_from_camera = self.base_from_world * h.world_from_camera();
        let pose = match (self.on_head, self.camera_written) {
            (true, written) => {
                let mount = if written {
                    Ok(())
                } else {
                    self.writer
                        .camera_mount(stamp_ns, &nalgebra::Isometry3::identity())
                };
                mount.and_then(|()| {
                    self.writer.head_pose(&avatarm_record::HeadPose {
                        stamp_ns,
                        base_from_head: base_from_camera,
                    })
                })
            }
            (false, false) => self.writer.camera_pose(stamp_ns, &base_from_camera),
            (false, true) => Ok(()),
        };
        match pose {
            Ok(()) => self.camera_written = true,
            Err(e) => return self.refused(format!("frame {}: {e}", h.index)),
        }
        let data = if h.codec == avatarm_net::msg::Codec::Jpeg.name() {
            payload.to_vec()
        } else {
            match crate::session::jpeg(h.width, h.height, rgba) {
                Ok(d) => d,
                Err(e) => return self.refused(format!("frame {}: {e}", h.index)),
            }
        };
        let frame = avatarm_record::CompressedFrame {
            stamp_ns,
            format: avatarm_record::ImageFormat::Jpeg,
            data,
        };
        match self.writer.erased(&frame) {
            Ok(()) => self.report.erased_frames += 1,
            Err(e) => self.refused(e.to_string()),
        }
    }

    /// Closes the file; a failure is counted in the report.
    pub(super) fn finish(mut self) -> JoinRecording {
        let mut report = std::mem::take(&mut self.report);
        if let Err(e) = self.writer.finish() {
            report.refused += 1;
            report.first_refusal.get_or_insert_with(|| e.to_string());
            warn!("join --record: {e}");
        }
        report
    }
}
