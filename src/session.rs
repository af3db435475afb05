//! `avatarm run --record FILE.mcap`: the live session as a recording (`avatarm_record`'s
//! channels, docs/real-footage.md), written while it runs; `avatarm run --ros2-publish`: the
//! same session's erased frames, masks, commands and safety events published on ROS 2
//! (`avatarm_ros::ros2::publish`, feature `ros`; docs/robot-ros2.md), with or without the file.
//!
//! What is recorded, each stamped with its capture or sample time on the app's clock (offset to
//! the Unix epoch at start): the camera's frames (JPEG) as the pipeline received them, its
//! calibration (K, the lens) and believed pose (for a camera on a head: the believed mount and
//! every tracked head pose received, in the base frame), the robot's base in the world, the robot's
//! every joint state sent to the app's twin, Avatarm's erased frame (JPEG) and mask (PNG)
//! of every frame (read back after the frame's render: the one read-back the live path gets
//! with `--record`), the operator's hand frames, every control tick's command to the robot and
//! the target it drove the real object to (the operator's side of the mapping), and safety
//! events: the limiter starting or ending an intervention (a stop for a lost hand,
//! stale or non-finite data; a slow-down at a limit), mapping errors, refused joint states.
//!
//! The encoding and the file are on a thread of their own fed through a channel, so the app's
//! updates never wait for the disk; nothing is dropped (the channel is unbounded). A message
//! the recording refuses (a non-finite value) is left out and counted, not fatal. The file is
//! completed when the app ends (the recorder's resource is dropped with the app's world).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

use avatarm_core::teleop::safety::Intervention;
use avatarm_erase::{EraseState, EraseTargets};
use avatarm_hand::ActiveHand;
use avatarm_mapping::{Teleop, TeleopSample, TeleopStatus};
use avatarm_record::{
    CompressedFrame, HandPoses, HeadPose, ImageFormat, JointStates, LogLevel, ObjectTarget,
    RecordError, RecordingWriter, RobotCommand, SafetyEvent,
};
use avatarm_scene::Scene;
use avatarm_twin::JointStateMessage;
use avatarm_twin::readback::{ImageRead, read_image_once};
use avatarm_video::LiveVideo;
use bevy::prelude::*;

use crate::{AppError, AppTwin};

/// The JPEG quality of recorded camera and erased frames.
const JPEG_QUALITY: u8 = 90;

pub use crate::net::ros2_out::Ros2Sink;

/// Adds the session recorder to `app`: creates `path` now (an error names it) and publishes
/// on `ros2`, until the app ends. At least one of them.
pub fn add_session_recorder(
    app: &mut App,
    path: Option<&Path>,
    ros2: Option<Ros2Sink>,
    scene: &Scene,
) -> Result<(), AppError> {
    let epoch_ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let base = scene.robot_base();
    let writer = match path {
        Some(path) => {
            let mut writer = RecordingWriter::create(path)?;
            let calibration = crate::replay::scene_calibration(scene);
            writer.calibration(epoch_ns, &calibration)?;
            crate::replay::write_scene_camera(&mut writer, epoch_ns, scene)?;
            writer.base_pose(epoch_ns, &base)?;
            Some(writer)
        }
        None => None,
    };
    let outputs = match (path, ros2.is_some()) {
        (Some(p), false) => p.display().to_string(),
        (Some(p), true) => format!("{} and on ROS 2", p.display()),
        (None, _) => "on ROS 2".to_owned(),
    };
    let (tx, rx) = channel();
    let thread = std::thread::Builder::new()
        .name("session recorder".into())
        .spawn(move || write_session(writer, ros2, rx))
        .map_err(|source| RecordError::Io {
            path: path.map(Path::to_owned).unwrap_or_default(),
            source,
        })?;
    let names = scene
        .model
        .dof_names()
        .iter()
        .map(|n| n.to_string())
        .collect();
    app.insert_resource(SessionRecorder {
        outputs,
        tx: Some(tx),
        thread: Some(thread),
        epoch_ns,
        names,
        last_frame: None,
        last_erased: None,
        last_hand: None,
        writer_gone: Default::default(),
        watch: SafetyWatch::default(),
        base_from_world: base.inverse(),
    })
    .add_systems(Last, record_session);
    if scene.head.is_some() {
        app.add_systems(Last, record_head_poses);
    }
    // Every control tick from the first (the live task's loop is in the app already).
    if let Some(mut teleop) = app.world_mut().get_resource_mut::<Teleop>() {
        teleop.record = true;
    }
    Ok(())
}

/// The recording's message for the operator's side of a control tick at `stamp_ns`: its target
/// for the real object (real world), the twists, σ, the grasp's rank and contacts.
pub(crate) fn object_target(
    stamp_ns: u64,
    t: &avatarm_core::teleop::mapping::OperatorTarget,
) -> ObjectTarget {
    let six = |v: &nalgebra::Vector6<f64>| std::array::from_fn(|i| v[i]);
    ObjectTarget {
        stamp_ns,
        world_from_object: t.target,
        object_twist: six(&t.object_twist),
        twin_twist: six(&t.twin_twist),
        squeeze_n: t.squeeze_n,
        grasp_rank: u8::try_from(t.rank).unwrap_or(u8::MAX),
        contacts: u32::try_from(t.contacts).unwrap_or(u32::MAX),
        held: t.held,
    }
}

/// One message for the writer thread.
enum Item {
    /// An RGBA8 image to encode (`mask`: 0/255 in one byte per pixel, as PNG).
    Image {
        stream: Stream,
        stamp_ns: u64,
        width: u32,
        height: u32,
        data: Arc<Vec<u8>>,
    },
    Joints(JointStates),
    Head(HeadPose),
    Hand(HandPoses),
    Command(RobotCommand),
    Target(ObjectTarget),
    Safety(SafetyEvent),
    /// The session is over: finish the file.
    End,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stream {
    Frame,
    Erased,
    Mask,
}

/// What the writer did, for the log line at the end.
#[derive(Debug, Default)]
struct Written {
    messages: u64,
    /// Handed to the ROS 2 publisher, and dropped by it (its queue full).
    published: u64,
    dropped: u64,
    refused: u64,
    first_refusal: Option<String>,
}

fn encode(stream: Stream, width: u32, height: u32, data: &[u8]) -> Result<CompressedFrame, String> {
    let (format, data) = if stream == Stream::Mask {
        (
            ImageFormat::Png,
            mask_png(width, height, data).map_err(|e| format!("{stream:?} image: {e}"))?,
        )
    } else {
        let jpeg = jpeg(width, height, data).map_err(|e| format!("{stream:?} image: {e}"))?;
        (ImageFormat::Jpeg, jpeg)
    };
    Ok(CompressedFrame {
        stamp_ns: 0,
        format,
        data,
    })
}

/// A mask (`width × height` bytes, one per pixel, non-zero = robot) as a PNG of 0 and 255;
/// errors when the buffer does not match the size, or the encoder fails.
pub(crate) fn mask_png(width: u32, height: u32, mask: &[u8]) -> Result<Vec<u8>, String> {
    let grey: Vec<u8> = mask.iter().map(|&v| if v > 0 { 255 } else { 0 }).collect();
    let image = image::GrayImage::from_raw(width, height, grey)
        .ok_or_else(|| format!("{} bytes for {width}x{height}", mask.len()))?;
    let mut out = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// An RGBA8 image (`width × height`) as a JPEG of the recorded frames' quality
/// ([`JPEG_QUALITY`]); errors when the buffer does not match the size, or the encoder fails.
pub(crate) fn jpeg(width: u32, height: u32, rgba: &[u8]) -> Result<Vec<u8>, String> {
    let image = image::RgbaImage::from_raw(width, height, rgba.to_vec())
        .ok_or_else(|| format!("{} bytes for {width}x{height}", rgba.len()))?;
    let rgb = image::DynamicImage::ImageRgba8(image).to_rgb8();
    let mut out = std::io::Cursor::new(Vec::new());
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
        .encode_image(&rgb)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// The recorder's thread: each item encoded once, written to the file and published on ROS 2
/// where they are given.
fn write_session(
    mut writer: Option<RecordingWriter>,
    ros2: Option<Ros2Sink>,
    rx: Receiver<Item>,
) -> Result<Written, RecordError> {
    let mut written = Written::default();
    for item in rx {
        // Each image encoded once, for the file and for ROS 2 (which takes no camera frame).
        let encoded = match &item {
            Item::End => break,
            Item::Image {
                stream,
                width,
                height,
                data,
                ..
            } if writer.is_some() || (ros2.is_some() && *stream != Stream::Frame) => {
                Some(encode(*stream, *width, *height, data))
            }
            _ => None,
        };
        if let Some(publisher) = &ros2 {
            written.published += u64::from(publish(publisher, &item, encoded.as_ref()));
        }
        let Some(writer) = writer.as_mut() else {
            continue;
        };
        let result = match item {
            Item::End => break,
            Item::Image {
                stream, stamp_ns, ..
            } => match encoded.unwrap_or_else(|| Err("not encoded".into())) {
                Ok(frame) => {
                    let frame = CompressedFrame { stamp_ns, ..frame };
                    match stream {
                        Stream::Frame => writer.frame(&frame),
                        Stream::Erased => writer.erased(&frame),
                        Stream::Mask => writer.mask(&frame),
                    }
                }
                Err(message) => {
                    written.refused += 1;
                    written.first_refusal.get_or_insert(message);
                    continue;
                }
            },
            Item::Joints(s) => writer.joint_states(&s),
            Item::Head(p) => writer.head_pose(&p),
            Item::Hand(h) => writer.hand(&h),
            Item::Command(c) => writer.robot_command(&c),
            Item::Target(t) => writer.object_target(&t),
            Item::Safety(e) => writer.safety_event(&e),
        };
        match result {
            Ok(()) => {}
            // A value the recording refuses is left out; the file itself failing ends it.
            Err(RecordError::Content { message, .. }) => {
                written.refused += 1;
                written.first_refusal.get_or_insert(message);
            }
            Err(e) => return Err(e),
        }
    }
    if let Some(publisher) = &ros2 {
        written.dropped = crate::net::ros2_out::dropped(publisher);
    }
    if let Some(writer) = writer {
        written.messages = writer.messages();
        writer.finish()?;
    }
    Ok(written)
}

/// Publishes what ROS 2 takes of `item` (the erased frames, the masks, the commands, the
/// safety events; the camera's frames and joint states have their own topics already), its
/// image `encoded` once; whether one was handed over.
fn publish(
    publisher: &Ros2Sink,
    item: &Item,
    encoded: Option<&Result<CompressedFrame, String>>,
) -> bool {
    use crate::net::ros2_out as out;
    match (item, encoded) {
        (
            Item::Image {
                stream: Stream::Erased,
                stamp_ns,
                ..
            },
            Some(Ok(f)),
        ) => out::publish_erased(publisher, *stamp_ns, f.data.clone()),
        (
            Item::Image {
                stream: Stream::Mask,
                stamp_ns,
                ..
            },
            Some(Ok(f)),
        ) => out::publish_mask(publisher, *stamp_ns, f.data.clone()),
        (Item::Command(c), _) => {
            out::publish_command(publisher, c.stamp_ns, &c.names, &c.velocities)
        }
        (Item::Safety(e), _) => {
            out::publish_safety(publisher, e.stamp_ns, e.level, &e.source, &e.message)
        }
        _ => false,
    }
}

/// Intervention counts and flags seen so far, to turn the limiter's counters into events.
#[derive(Debug, Default)]
struct SafetyWatch {
    /// Ticks counted per intervention at the last update.
    counts: BTreeMap<String, u64>,
    /// Episodes under way (interventions, refused ticks, refused joint states): the last
    /// time one happened (s), the count when the episode began, and its source.
    active: BTreeMap<String, (f64, u64, &'static str)>,
    stopping: bool,
}

/// The live session's recorder (its thread finishes the file when this is dropped).
#[derive(Resource)]
struct SessionRecorder {
    /// Where it goes (the file, ROS 2), for messages.
    outputs: String,
    tx: Option<Sender<Item>>,
    thread: Option<JoinHandle<Result<Written, RecordError>>>,
    epoch_ns: u64,
    /// The robot's joint names (the description's q order).
    names: Vec<String>,
    last_frame: Option<u64>,
    last_erased: Option<u64>,
    last_hand: Option<f64>,
    /// The writer thread ended early (said once).
    writer_gone: std::sync::atomic::AtomicBool,
    watch: SafetyWatch,
    /// The world into the robot's base frame (head poses are recorded in the base frame).
    base_from_world: nalgebra::Isometry3<f64>,
}

impl SessionRecorder {
    fn ns(&self, t_s: f64) -> u64 {
        self.epoch_ns + (t_s.max(0.0) * 1e9).round() as u64
    }

    /// The names of a vector of `n` joint values: the description's, or `q0`, `q1`, ... when
    /// it has another length.
    fn names_of(&self, n: usize) -> Vec<String> {
        if self.names.len() == n {
            self.names.clone()
        } else {
            (0..n).map(|i| format!("q{i}")).collect()
        }
    }

    fn send(&self, item: Item) {
        if let Some(tx) = &self.tx
            && tx.send(item).is_err()
            && !self
                .writer_gone
                .swap(true, std::sync::atomic::Ordering::Relaxed)
        {
            // The thread ended early (the file failed): its error is reported at the end.
            error!(
                "recording {}: the writer stopped; nothing more is recorded",
                self.outputs
            );
        }
    }

    fn event(&self, t_s: f64, level: LogLevel, source: &str, message: String) {
        info!("safety ({source}): {message}");
        self.send(Item::Safety(SafetyEvent {
            stamp_ns: self.ns(t_s),
            level,
            source: source.into(),
            message,
        }));
    }
}

impl Drop for SessionRecorder {
    fn drop(&mut self) {
        // The end, explicitly: read-backs still in flight hold senders of their own.
        self.send(Item::End);
        self.tx = None;
        let Some(thread) = self.thread.take() else {
            return;
        };
        match thread.join() {
            Ok(Ok(w)) => {
                eprintln!(
                    "recorded the session: {} messages in a file, {} published on ROS 2 ({} dropped), {}{}",
                    w.messages,
                    w.published,
                    w.dropped,
                    self.outputs,
                    match w.first_refusal {
                        Some(m) => format!(" ({} left out, the first: {m})", w.refused),
                        None => String::new(),
                    }
                );
            }
            Ok(Err(e)) => eprintln!("recording the session failed: {e}"),
            Err(_) => eprintln!("recording the session failed: its thread panicked"),
        }
    }
}

/// An intervention is over when none has happened for this long (s): the limiter's slews come
/// and go from tick to tick while it works.
const INTERVENTION_QUIET_S: f64 = 0.5;

/// How serious an intervention is: the ones that stop the arm are errors.
fn severity(kind: &str) -> LogLevel {
    let stops = [
        Intervention::NotFinite,
        Intervention::HandStale,
        Intervention::HandLost,
        Intervention::JointsStale,
    ];
    if stops.iter().any(|i| format!("{i:?}") == kind) {
        LogLevel::Error
    } else {
        LogLevel::Warning
    }
}

/// A camera on a head: every tracked head pose the app receives, in the base frame.
fn record_head_poses(
    recorder: Res<SessionRecorder>,
    mut poses: MessageReader<avatarm_video::HeadPoseMessage>,
) {
    for p in poses.read() {
        let item = Item::Head(HeadPose {
            stamp_ns: recorder.ns(p.stamp_s),
            base_from_head: recorder.base_from_world * p.world_from_head,
        });
        recorder.send(item);
    }
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn record_session(
    mut commands: Commands,
    mut recorder: ResMut<SessionRecorder>,
    live: Res<LiveVideo>,
    erase: (Res<EraseState>, Option<Res<EraseTargets>>),
    (app_twin, mut joint_states): (Option<Res<AppTwin>>, MessageReader<JointStateMessage>),
    time: Res<Time>,
    hand: Option<Res<ActiveHand>>,
    teleop: Option<ResMut<Teleop>>,
) {
    let recorder = &mut *recorder;
    let (state, targets) = erase;
    // The camera frame, once.
    if let Some(f) = live.frame.as_ref().filter(|_| live.fresh)
        && recorder.last_frame != Some(f.index)
    {
        recorder.last_frame = Some(f.index);
        recorder.send(Item::Image {
            stream: Stream::Frame,
            stamp_ns: recorder.ns(f.capture_s),
            width: f.width,
            height: f.height,
            data: f.rgba.clone(),
        });
    }
    // Avatarm's outputs of the frame erased in this update, read back after its render.
    if let (Some(targets), Some((t_s, index, _))) = (
        targets,
        state
            .current
            .as_ref()
            .filter(|c| c.dirty)
            .and_then(|c| c.frame.clone()),
    ) && recorder.last_erased != Some(index)
    {
        recorder.last_erased = Some(index);
        let stamp_ns = recorder.ns(t_s);
        for (stream, handle) in [
            (Stream::Erased, targets.composite.clone()),
            (Stream::Mask, targets.mask.clone()),
        ] {
            let tx = recorder.tx.clone();
            read_image_once(&mut commands, handle).observe(move |read: On<ImageRead>| {
                if let Some(tx) = &tx {
                    let _ = tx.send(Item::Image {
                        stream,
                        stamp_ns,
                        width: read.width,
                        height: read.height,
                        data: Arc::new(read.data.clone()),
                    });
                }
            });
        }
    }
    // Every joint state sent to the app's twin since the last update.
    let twin = app_twin.map(|t| t.0);
    for m in joint_states.read().filter(|m| Some(m.twin) == twin) {
        recorder.send(Item::Joints(JointStates {
            stamp_ns: recorder.ns(m.stamp_s),
            names: m.names.clone(),
            positions: m.positions.clone(),
            velocities: m.velocities.clone(),
        }));
    }
    // The operator's hand.
    if let Some(frame) = hand.as_ref().and_then(|h| h.latest.as_ref())
        && recorder.last_hand != Some(frame.t_s)
    {
        recorder.last_hand = Some(frame.t_s);
        recorder.send(Item::Hand(HandPoses {
            stamp_ns: recorder.ns(frame.t_s),
            hand: match frame.hand {
                avatarm_core::teleop::hand::Handedness::Left => "left".into(),
                avatarm_core::teleop::hand::Handedness::Right => "right".into(),
            },
            tracked: frame.tracked,
            poses: frame.joints.iter().map(|j| j.pose).collect(),
            radii: frame.joints.iter().map(|j| j.radius).collect(),
        }));
    }
    let Some(mut teleop) = teleop else {
        return;
    };
    teleop.record = true;
    // Every control tick's command, and the limiter's stops as they start and end.
    let samples: Vec<_> = teleop.log.drain(..).collect();
    for s in &samples {
        recorder.send(Item::Command(RobotCommand {
            stamp_ns: recorder.ns(s.t_s),
            names: recorder.names_of(s.qdot.len()),
            velocities: s.qdot.iter().copied().collect(),
            gripper_closed: s.gripper_closed,
            stopping: s.stopping,
            tcp_speed: s.tcp_speed,
        }));
        if let Some(target) = &s.operator {
            recorder.send(Item::Target(object_target(recorder.ns(s.t_s), target)));
        }
    }
    let events = recorder
        .watch
        .events(&samples, &teleop.status, time.elapsed_secs_f64());
    for (t_s, level, source, message) in events {
        recorder.event(t_s, level, source, message);
    }
}

impl SafetyWatch {
    /// The safety events of one update: its control ticks `samples` (oldest first), the loop's
    /// counters after them, and the app's time `now_s` (for an update with no tick, as while
    /// nothing drives the arm): `(time s, level, source, message)`. Each counter's episode
    /// (interventions, refused ticks, refused joint states) is one event when it begins and one
    /// when none has come for [`INTERVENTION_QUIET_S`], not one per tick.
    fn events(
        &mut self,
        samples: &[TeleopSample],
        status: &TeleopStatus,
        now_s: f64,
    ) -> Vec<(f64, LogLevel, &'static str, String)> {
        let mut out = Vec::new();
        for s in samples {
            if s.stopping != self.stopping {
                self.stopping = s.stopping;
                out.push(if s.stopping {
                    (
                        s.t_s,
                        LogLevel::Error,
                        "limiter",
                        "stopping the robot (zero velocity, ramped)".to_owned(),
                    )
                } else {
                    (
                        s.t_s,
                        LogLevel::Info,
                        "limiter",
                        "stop ended: the robot follows the hand again".to_owned(),
                    )
                });
            }
        }
        let t_s = samples.last().map_or(now_s, |s| s.t_s);
        // (key, count, source, severity, what began)
        let mut counters: Vec<(String, u64, &'static str, LogLevel, String)> = status
            .interventions
            .iter()
            .map(|(kind, count)| {
                let kind = format!("{kind:?}");
                let what = format!("intervention began: {kind}");
                (kind.clone(), *count, "limiter", severity(&kind), what)
            })
            .collect();
        counters.push((
            "refused ticks".into(),
            status.errors,
            "mapping",
            LogLevel::Error,
            format!(
                "ticks refused: {}",
                status.last_error.as_deref().unwrap_or("no reason given")
            ),
        ));
        counters.push((
            "refused joint states".into(),
            status.bad_joint_states,
            "robot",
            LogLevel::Warning,
            "joint states refused (wrong size or not finite)".into(),
        ));
        for (key, count, source, level, what) in counters {
            let before = self.counts.insert(key.clone(), count).unwrap_or(0);
            if count <= before {
                continue;
            }
            match self.active.get_mut(&key) {
                Some(episode) => episode.0 = t_s,
                None => {
                    self.active.insert(key, (t_s, before, source));
                    out.push((t_s, level, source, what));
                }
            }
        }
        let ended: Vec<String> = self
            .active
            .iter()
            .filter(|(_, e)| t_s - e.0 > INTERVENTION_QUIET_S)
            .map(|(key, _)| key.clone())
            .collect();
        for key in ended {
            if let Some((_, first, source)) = self.active.remove(&key) {
                let n = self.counts.get(&key).copied().unwrap_or(first) - first;
                let message = if source == "limiter" {
                    format!("intervention ended: {key} ({n} ticks)")
                } else {
                    format!("{key} ended ({n} in all)")
                };
                out.push((t_s, LogLevel::Info, source, message));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DVector, Isometry3, Vector6};

    fn tick(t_s: f64, stopping: bool) -> TeleopSample {
        TeleopSample {
            t_s,
            target: Isometry3::identity(),
            measured: Isometry3::identity(),
            truth: None,
            gripper_closed: false,
            tcp_speed: 0.0,
            max_joint_speed: 0.0,
            stopping,
            contacts: 0,
            squeeze_n: 0.0,
            twin_twist: Vector6::zeros(),
            q: DVector::zeros(2),
            qdot: DVector::zeros(2),
            operator: None,
        }
    }

    #[test]
    fn the_limiter_s_counters_become_events_that_begin_and_end() {
        let mut watch = SafetyWatch::default();
        // The hand is lost: a stop, and the intervention that caused it.
        let mut status = TeleopStatus {
            interventions: vec![(Intervention::HandLost, 3)],
            ..TeleopStatus::default()
        };
        let e = watch.events(&[tick(1.0, false), tick(1.01, true)], &status, 1.01);
        assert_eq!(e.len(), 2, "{e:?}");
        assert_eq!((e[0].1, e[0].0), (LogLevel::Error, 1.01));
        assert!(e[1].3.contains("began: HandLost") && e[1].1 == LogLevel::Error);
        // Still lost: nothing new. A slew at a limit is a warning.
        status.interventions = vec![(Intervention::HandLost, 5), (Intervention::Acceleration, 1)];
        let e = watch.events(&[tick(1.02, true)], &status, 1.02);
        assert_eq!(e.len(), 1, "{e:?}");
        assert_eq!(e[0].1, LogLevel::Warning);
        // Found again; both quiet for more than INTERVENTION_QUIET_S: the stop and both end.
        let e = watch.events(&[tick(1.03, false), tick(1.6, false)], &status, 1.6);
        assert_eq!(e.len(), 3, "{e:?}");
        assert!(e.iter().all(|x| x.1 == LogLevel::Info));
        assert!(
            e.iter()
                .any(|x| x.3 == "intervention ended: HandLost (5 ticks)"),
            "{e:?}"
        );
        // A link refusing every tick: one event when it begins, none while it goes on (even
        // in updates without a tick), one when it ends.
        for (i, t) in [2.0, 2.1, 2.2, 2.3].into_iter().enumerate() {
            status.errors = 10 * (i as u64 + 1);
            status.last_error = Some("the robot link is down".into());
            status.bad_joint_states = i as u64 + 1;
            let e = watch.events(&[], &status, t);
            if i == 0 {
                assert_eq!(e.len(), 2, "{e:?}");
                assert!(e[0].3.contains("ticks refused: the robot link is down"));
                assert_eq!((e[0].2, e[1].2), ("mapping", "robot"));
            } else {
                assert!(e.is_empty(), "{e:?}");
            }
        }
        let e = watch.events(&[], &status, 3.0);
        assert_eq!(e.len(), 2, "{e:?}");
        assert!(
            e.iter().any(|x| x.3 == "refused ticks ended (40 in all)"),
            "{e:?}"
        );
        assert!(watch.events(&[], &status, 4.0).is_empty());
    }
}
