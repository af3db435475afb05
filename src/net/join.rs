//! `avatarm join ENDPOINT`: the operator's site (the hand, the physics twin and the operator's
//! side of the mapping, so her hand and the twin respond with no network delay) or, with
//! `--watch`, an observer. Both receive the robot site's video, joint states and status, and
//! report the latency of each stage of the video on the robot site's clock (the offset
//! estimated from the shortest of several clock queries).
//!
//! The operator steps the scene's `[task]` trial in real time at the control rate: the hand
//! (the trial's scripted hand) grasps the twin in Rapier, [`Mapper::operator_side`] turns the
//! contacts into the real object's target and twist, and one [`TargetMsg`] goes out per tick,
//! stamped on the robot's clock.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use avatarm_core::teleop::grasp::Contact;
use avatarm_core::teleop::mapping::{Mapper, MappingMode, OperatorInputs};
use avatarm_hand::{ActiveHand, GraspTarget, HeldObject, ScriptedHand};
use avatarm_mapping::pouring::{TrialParts, read_hand_world};
use avatarm_net::msg::{FrameHeader, HandMsg, PROTOCOL_VERSION, TargetMsg};
use avatarm_net::{NetConfig, OperatorInbox, OperatorSite};
use avatarm_record::RecordingWriter;
use avatarm_scene::Scene;
use avatarm_scene::hand::HandChoice;
use bevy::log::warn;
use bevy::prelude::*;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::window::{ViewShared, WindowOptions, WindowReport};
use crate::AppError;
use crate::teleop::{RobotChoice, trial_parts};
use avatarm_core::stats::Spread;

mod head;
use head::HeadSender;
pub use head::{HeadReport, HeadSource};

mod record;
use record::JoinRecorder;
pub use record::JoinRecording;

mod latency;
use latency::Stages;

mod robot_site;
pub use latency::VideoLatency;
pub use robot_site::ROBOT_SITE_SILENT;
use robot_site::may_command;

/// How `avatarm join` runs.
#[derive(Debug, Clone)]
pub struct JoinOptions {
    /// The network settings.
    pub net: NetConfig,
    /// The scene (the same file as the robot site's).
    pub scene: Scene,
    /// Only watch (no hand, no targets).
    pub watch: bool,
    /// Stop after this long (s); `None`: the task's duration (operator) or until killed.
    pub duration_s: Option<f64>,
    /// The mapping mode the robot site runs (for the report only).
    pub mode: Option<MappingMode>,
    /// Where to write the report.
    pub report: Option<PathBuf>,
    /// Where to record what this site receives (MCAP), if anywhere.
    pub record: Option<PathBuf>,
    /// How long to wait for the robot site (s).
    pub wait_s: f64,
    /// The task's trial whose seeded hand the operator plays.
    pub trial: u32,
    /// The operator's hand (the trial's scripted hand by default).
    pub hand: HandChoice,
    /// The operator's or observer's window (`None`: headless).
    pub window: Option<WindowOptions>,
    /// Where the head of the viewed camera comes from, for a camera on a head (sent to the
    /// robot site, which erases that camera at it); `None`: the robot site's simulated head.
    pub head: Option<HeadSource>,
}

/// The operator's (or observer's) report (`--report`).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct JoinReport {
    /// Protocol version.
    pub protocol: u32,
    /// Operator or observer.
    pub role: String,
    /// The robot site's scene and backend.
    pub scene: String,
    /// The robot backend.
    pub robot: String,
    /// The clock offset at the end (s, robot minus here; the newest estimate, after any
    /// restart of the robot site) and the round trip it came from (ms).
    pub clock_offset_s: f64,
    /// The round trip (ms).
    pub clock_rtt_ms: f64,
    /// How long it ran (s).
    pub duration_s: f64,
    /// Targets sent.
    pub targets_sent: u64,
    /// Targets that could not be sent (the operator's side refused a tick).
    pub targets_failed: u64,
    /// Joint states received.
    pub joint_states: u64,
    /// Status messages received; the last said the arm was stopping.
    pub status: u64,
    /// Status messages that said the arm was stopping.
    pub status_stopping: u64,
    /// Hand frames received (observers).
    pub hands: u64,
    /// Messages refused.
    pub refused: u64,
    /// The video.
    pub video: VideoLatency,
    /// Highest lift of the twin (m, virtual scene).
    pub twin_lift_m: f64,
    /// Age of the joint states on arrival (ms: robot clock now minus their stamp).
    pub joint_state_age_ms: Spread,
    /// The window, when there was one.
    pub window: Option<WindowReport>,
    /// What `--record` wrote, when it was given.
    pub recording: Option<JoinRecording>,
    /// The head this site sent for its camera on a head (`--xr`, `--head FILE.mcap`).
    pub head: Option<HeadReport>,
    /// Times the robot site fell silent (no status or joint state for
    /// [`ROBOT_SITE_SILENT`]): a cut link, or the robot site stopped.
    #[serde(default)]
    pub robot_site_silences: u64,
    /// Times the robot site restarted (its clock jumped back: the offset was estimated again).
    #[serde(default)]
    pub robot_site_restarts: u64,
}

/// The least time between two keyframe requests of one camera (s).
const KEYFRAME_REQUEST_INTERVAL_S: f64 = 0.5;

/// One camera's decoding state at the viewer.
#[derive(Default)]
struct CameraView {
    decoder: avatarm_net::codec::VideoDecoder,
    /// The first frame's camera pose.
    first_pose: Option<nalgebra::Isometry3<f64>>,
    stream: Option<u64>,
    last_seq: Option<u64>,
    last_request: Option<Instant>,
}

#[derive(Default)]
struct Collect {
    report: JoinReport,
    /// The window's view of the session, when there is a window.
    view: Option<Arc<ViewShared>>,
    /// Only watching: the hand shown is the operator's, as received.
    observer: bool,
    /// The last status said the arm was stopping.
    stopping: bool,
    /// The camera the window shows.
    window_camera: Option<String>,
    cameras: std::collections::BTreeMap<String, CameraView>,
    stages: Stages,
    joint_age: Vec<f64>,
    recorder: Option<JoinRecorder>,
    /// Sends the head of this site's camera on a head.
    head: Option<HeadSender>,
    /// The real object's poses the robot site reported, `(stamp_s, pose)`, oldest first.
    objects: std::collections::VecDeque<(f64, nalgebra::Isometry3<f64>)>,
    /// When the robot site was last heard (a status or a joint state).
    last_word: Option<Instant>,
    /// It has been silent for [`ROBOT_SITE_SILENT`] since (said once).
    silent: bool,
    /// It restarted as another robot site: why the session ends.
    changed_site: Option<String>,
}

/// How long the real object's reported poses are kept (s): longer than the video's latency
/// (up to 2 s on a software renderer).
const OBJECT_HISTORY_S: f64 = 10.0;

/// A reported object pose describes the object this long after its stamp at most (s): the
/// joint states come at the control rate.
const OBJECT_GAP_S: f64 = 0.2;

/// The real object's reported pose at `t_s`: the newest reported at or before it, if at most
/// [`OBJECT_GAP_S`] before it; `None` when none is (before the history, or the reports
/// stopped).
fn object_at(
    objects: &std::collections::VecDeque<(f64, nalgebra::Isometry3<f64>)>,
    t_s: f64,
) -> Option<nalgebra::Isometry3<f64>> {
    objects
        .iter()
        .rev()
        .find(|(t, _)| *t <= t_s)
        .filter(|(t, _)| t_s - t <= OBJECT_GAP_S)
        .map(|(_, p)| *p)
}

impl Collect {
    fn take(&mut self, site: &OperatorSite, inbox: OperatorInbox, robot_now: f64) {
        let heard = !inbox.status.is_empty() || !inbox.joint_states.is_empty();
        self.watch_robot_site(site, heard);
        if let Some(head) = &mut self.head {
            head.send(site, robot_now);
        }
        let r = &mut self.report;
        for j in inbox.joint_states {
            match j {
                Ok(j) => {
                    r.joint_states += 1;
                    Spread::push(&mut self.joint_age, (robot_now - j.stamp_s) * 1e3);
                    if let Some(o) = &j.object {
                        // The last seconds, for the frames' capture times (a robot site that
                        // started again starts its clock again).
                        if self.objects.back().is_some_and(|(t, _)| *t > j.stamp_s) {
                            self.objects.clear();
                        }
                        self.objects
                            .push_back((j.stamp_s, avatarm_net::msg::pose_from_wire(o)));
                        while self
                            .objects
                            .front()
                            .is_some_and(|(t, _)| j.stamp_s - t > OBJECT_HISTORY_S)
                        {
                            self.objects.pop_front();
                        }
                    }
                    if let Some(rec) = &mut self.recorder {
                        rec.joint_states(&j);
                    }
                }
                Err(_) => r.refused += 1,
            }
        }
        for s in inbox.status {
            match s {
                Ok(s) => {
                    r.status += 1;
                    r.status_stopping += u64::from(s.stopping);
                    if s.stopping
                        && !self.stopping
                        && let Some(rec) = &mut self.recorder
                    {
                        rec.stop(&s);
                    }
                    self.stopping = s.stopping;
                }
                Err(_) => r.refused += 1,
            }
        }
        for h in inbox.hands {
            match h {
                Ok(h) => {
                    r.hands += 1;
                    if let Some(view) = self.view.as_ref().filter(|_| self.observer) {
                        let joints = (h.tracked && h.joints.len() == 26)
                            .then(|| h.joints.iter().map(|p| Vector3::from(*p)).collect());
                        let held = h.held_object.as_ref().map(avatarm_net::msg::pose_from_wire);
                        view.update(|s| {
                            s.hand = joints;
                            s.hand_at = Some(Instant::now());
                            s.holding = held.is_some();
                            s.held_object = held;
                        });
                    }
                }
                Err(_) => r.refused += 1,
            }
        }
        for f in inbox.frames {
            let Ok(avatarm_net::ReceivedFrame {
                header: h,
                payload,
                received_s: received,
            }) = f
            else {
                r.video.refused += 1;
                continue;
            };
            r.video.frames += 1;
            r.video.bytes += payload.len() as u64;
            r.video.keyframes += u64::from(h.keyframe);
            r.video.codec.clone_from(&h.codec);
            let view = self.cameras.entry(h.camera.clone()).or_default();
            let pose = h.world_from_camera();
            let first = *view.first_pose.get_or_insert(pose);
            let (angle, offset) = avatarm_core::vision::head::pose_error(&first, &pose);
            r.video.camera_turned_deg = r.video.camera_turned_deg.max(angle.to_degrees());
            r.video.camera_moved_mm = r.video.camera_moved_mm.max(1e3 * offset);
            // `seq` is at most MAX_SEQ (the header's check): no overflow. Another stream (the
            // robot site restarted) starts the count again.
            if view.stream != Some(h.stream) {
                view.stream = Some(h.stream);
                view.last_seq = None;
            }
            if let Some(last) = view.last_seq
                && h.seq > last.saturating_add(1)
            {
                r.video.lost += h.seq - last - 1;
            }
            view.last_seq = Some(view.last_seq.map_or(h.seq, |l| l.max(h.seq)));
            let started = Instant::now();
            let decoded = view.decoder.decode(&h, &payload);
            let decode_ms = started.elapsed().as_secs_f64() * 1e3;
            match decoded {
                Ok(avatarm_net::codec::Decoded::Image {
                    width,
                    height,
                    rgba,
                }) => {
                    if let Some(rec) = &mut self.recorder {
                        rec.frame(&h, &payload, &rgba);
                    }
                    let capture_to_decoded_ms =
                        self.stages.note(&mut r.video, &h, received, decode_ms);
                    // The window shows one camera: the first one received.
                    let first = self.window_camera.get_or_insert_with(|| h.camera.clone());
                    if let Some(view) = self.view.as_ref().filter(|_| *first == h.camera) {
                        // With the real object as this frame shows it.
                        let object = object_at(&self.objects, h.capture_s);
                        view.put_frame(
                            width,
                            height,
                            rgba,
                            h.world_from_camera(),
                            object,
                            capture_to_decoded_ms,
                        );
                    }
                }
                Ok(avatarm_net::codec::Decoded::NeedKeyframe { reason }) => {
                    r.video.waiting_for_keyframe += 1;
                    let due = view
                        .last_request
                        .is_none_or(|t| t.elapsed().as_secs_f64() >= KEYFRAME_REQUEST_INTERVAL_S);
                    if due {
                        view.last_request = Some(Instant::now());
                        r.video.keyframe_requests += 1;
                        info!("video '{}': {reason}; asking for a keyframe", h.camera);
                        if let Err(e) = site.request_keyframe(&h.camera) {
                            warn!("video '{}': {e}", h.camera);
                        }
                    }
                }
                Ok(avatarm_net::codec::Decoded::Stale) => r.video.stale += 1,
                Err(e) => {
                    // One line for the first and every hundredth: a broken stream at 30 fps
                    // would otherwise flood the log; the report counts them all.
                    r.video.refused += 1;
                    if r.video.refused % 100 == 1 {
                        warn!("video: {e} ({} refused so far)", r.video.refused);
                    }
                }
            }
        }
    }

    /// The window closed: the session ends.
    /// Hands the window its status line.
    fn show_line(&self) {
        if let Some(view) = &self.view {
            let line = self.line();
            view.update(|s| s.line = line);
        }
    }

    /// The window's status line: what arrived and how late, what went out, the arm's state.
    fn line(&self) -> String {
        let r = &self.report;
        let last = |v: &[f64]| v.last().map_or("-".to_owned(), |ms| format!("{ms:.0} ms"));
        let sent = if self.observer {
            format!("{} operator hand frames", r.hands)
        } else {
            format!("{} targets sent", r.targets_sent)
        };
        format!(
            "{}: {} video frames shown of {} ({}, {} lost, {} keyframe requests); last frame \
             capture to decoded {}, network {}\n{sent}; {} joint states (age {}); arm {}",
            if self.observer {
                "observer"
            } else {
                "operator"
            },
            r.video.shown,
            r.video.frames,
            if r.video.codec.is_empty() {
                "-"
            } else {
                &r.video.codec
            },
            r.video.lost,
            r.video.keyframe_requests,
            last(&self.stages.total),
            last(&self.stages.network),
            r.joint_states,
            last(&self.joint_age),
            if self.stopping { "STOPPING" } else { "running" },
        )
    }

    fn finish(mut self, duration_s: f64) -> JoinReport {
        let r = &mut self.report;
        r.duration_s = duration_s;
        r.video.fps = r.video.frames as f64 / duration_s.max(1e-9);
        r.video.mbit_s = r.video.bytes as f64 * 8.0 / 1e6 / duration_s.max(1e-9);
        r.video.erase_ms = Spread::of(&self.stages.erase);
        r.video.arrive_ms = Spread::of(&self.stages.arrive);
        r.video.app_ms = Spread::of(&self.stages.in_app);
        r.video.encode_ms = Spread::of(&self.stages.encode);
        r.video.network_ms = Spread::of(&self.stages.network);
        r.video.decode_ms = Spread::of(&self.stages.decode);
        r.video.total_ms = Spread::of(&self.stages.total);
        r.joint_state_age_ms = Spread::of(&self.joint_age);
        r.recording = self.recorder.take().map(JoinRecorder::finish);
        r.head = self.head.take().map(|h| h.report);
        self.report
    }
}

/// Joins the session and runs until the duration passes. Errors when the robot site does not
/// answer, speaks another protocol version or runs another scene.
#[expect(
    clippy::too_many_lines,
    reason = "the operator's session set up in its order (scene check, clock, streams, window or headless loop), each step needing the ones before"
)]
pub fn join(options: &JoinOptions) -> Result<JoinReport, AppError> {
    if !(options.wait_s.is_finite() && (0.0..1e6).contains(&options.wait_s)) {
        return Err(AppError::flag(
            "--wait",
            format!("{} s must be >= 0", options.wait_s),
        ));
    }
    if options.head.is_some() && options.scene.head.is_none() {
        return Err(AppError::flag(
            "--head",
            format!(
                "the camera '{}' is fixed, not on a head: look through a camera on a head \
                 (--view)",
                options.scene.camera_name()
            ),
        ));
    }
    if let Some(d) = options.duration_s
        && !(d.is_finite() && d > 0.0 && d < 1e7)
    {
        return Err(AppError::flag("--duration", format!("{d} s must be > 0")));
    }
    // Everything that can fail here fails before the network: the hand source (a recording, a
    // device), the window (a display) and the XR hand.
    let xr = options.window.as_ref().is_some_and(|w| w.xr);
    let operator = if options.watch {
        None
    } else {
        match options.hand {
            HandChoice::Desktop if options.window.is_none() => {
                return Err(AppError::flag(
                    "--hand desktop",
                    "the desktop hand moves with the window's keys: add --window",
                ));
            }
            HandChoice::Xr if !xr => {
                return Err(AppError::flag(
                    "--hand xr",
                    "OpenXR hand tracking comes with the XR view: add --xr",
                ));
            }
            _ => {}
        }
        let (parts, _) = trial_parts(
            &options.scene,
            RobotChoice::Sim,
            options.mode,
            options.trial,
            "avatarm join",
        )?;
        let Some(task) = &options.scene.file.task else {
            return Err(AppError::flag("--scene", "the scene has no [task]"));
        };
        let (hand, desktop) = crate::teleop::hand_source(
            &options.scene,
            &options.hand,
            &parts.script,
            task.hand_rate_hz,
        )?;
        Some((parts, hand, desktop))
    };
    let mut window = None;
    let operator = match (options.window.as_ref(), operator) {
        (None, Some((parts, Some(hand), None))) => Some((parts, hand)),
        (None, Some(_)) => {
            return Err(AppError::flag(
                "--hand",
                "this hand needs the window: add --window",
            ));
        }
        (None, None) => None,
        (Some(w), operator) => {
            let shared = Arc::new(ViewShared::new());
            let desktop = operator.as_ref().and_then(|(_, _, d)| d.clone());
            let (mut app, handle) =
                super::window::build(&options.scene, w, shared.clone(), options.watch, desktop)?;
            // The window's hands (keys, OpenXR) are made on its thread, on its clock: the
            // session stamps their frames as it takes them.
            let operator = match operator {
                Some((parts, _, Some(desktop))) => {
                    let hand = ActiveHand::new(StampedOnArrival(desktop.inbox().clone()));
                    Some((parts, hand))
                }
                Some((parts, Some(hand), None)) => Some((parts, hand)),
                Some((parts, None, None)) => {
                    let start = parts.script.wrist_at(0.0).0;
                    let inbox = crate::teleop::xr_inbox(&mut app, &start)?;
                    Some((parts, ActiveHand::new(StampedOnArrival(inbox))))
                }
                None => None,
            };
            window = Some((app, handle, shared));
            operator
        }
    };
    // The recording's file is made before the network: a bad path fails here.
    let recorder = match &options.record {
        Some(path) => Some(JoinRecorder::create(path, &options.scene)?),
        None => None,
    };
    let mut site = OperatorSite::join(&options.net, Duration::from_secs_f64(options.wait_s))?;
    let info = site.info().clone();
    may_command(options, &info)?;
    let ours = super::scene_fingerprint(&options.scene)?;
    if !options.watch && info.scene_hash != ours {
        return Err(AppError::flag(
            "--scene",
            format!(
                "the robot site runs the scene '{}' (fingerprint {}), this is '{}' ({ours}): \
                 give the same scene file at both sites",
                info.scene, info.scene_hash, options.scene.file.name
            ),
        ));
    }
    // Several cameras: the robot site serves one or more; this site shows one, and the
    // twins are drawn through it.
    let view = super::serve::camera_key(&options.scene);
    if options.scene.cameras.len() > 1 && !info.cameras.is_empty() && !info.cameras.contains(&view)
    {
        return Err(AppError::flag(
            "--view",
            format!(
                "the robot site serves the camera(s) {:?}, this site looks through '{view}': \
                 give join the robot site's --view",
                info.cameras
            ),
        ));
    }
    if info.cameras.len() > 1 && info.cameras.contains(&view) {
        // Only the frames this site shows cross the network to it.
        site.view_camera(&view)?;
    }
    let offset = site.offset();
    info!(
        "joined '{}' ({} at the robot site, protocol {}): clock offset {:+.3} ms (round trip {:.2} ms)",
        info.scene,
        info.robot,
        PROTOCOL_VERSION,
        offset.offset_s * 1e3,
        offset.rtt_s * 1e3
    );
    let result = match window {
        None => run_session(&mut site, options, operator, None, recorder),
        Some((mut app, handle, shared)) => {
            let site = &mut site;
            let result = std::thread::scope(|scope| {
                let view = shared.clone();
                let session = scope.spawn(move || {
                    // The window closes when the session ends, however it ends.
                    let _ended = SetOnDrop(&view.ended);
                    run_session(site, options, operator, Some(view.clone()), recorder)
                });
                let exit = {
                    // The session ends when the window closes, however it closes.
                    let _closed = SetOnDrop(&shared.closed);
                    app.run()
                };
                let result = session.join().unwrap_or_else(|_| {
                    Err(AppError::Session {
                        message: "its thread panicked (see the log above)".into(),
                    })
                });
                if exit.is_error() {
                    return Err(AppError::Preview);
                }
                result
            });
            result.map(|mut r| {
                r.window = handle.report();
                r
            })
        }
    };
    let mut report = result?;
    report.protocol = PROTOCOL_VERSION;
    report.scene = info.scene.clone();
    report.robot = info.robot.clone();
    // The newest estimate: a robot site that restarted has another clock than at the start.
    let offset = site.offset();
    report.clock_offset_s = offset.offset_s;
    report.clock_rtt_ms = offset.rtt_s * 1e3;
    site.close();
    if let Some(path) = &options.report {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text).map_err(|e| AppError::write(path, e))?;
    }
    Ok(report)
}

/// Sets its flag when dropped: at the end of a scope, by return or by panic.
struct SetOnDrop<'a>(&'a std::sync::atomic::AtomicBool);

impl Drop for SetOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// A hand source fed from the window's thread (the desktop hand's keys, OpenXR hand tracking):
/// the window's clock is not the session's hand app's, so each frame is stamped with the hand
/// app's time as it takes it. The stamp is then late by at most one window frame plus one
/// control tick (the targets' age at the robot site reads that much younger).
struct StampedOnArrival(avatarm_hand::openxr::HandInbox);

impl avatarm_hand::HandSource for StampedOnArrival {
    fn name(&self) -> &str {
        avatarm_hand::HandSource::name(&self.0)
    }

    fn poll(&mut self, now_s: f64) -> Option<avatarm_core::teleop::hand::HandFrame> {
        let mut frame = self.0.poll(f64::INFINITY)?;
        frame.t_s = now_s;
        Some(frame)
    }
}

/// The session on a joined `site` until `options`' duration passes or the window (`view`)
/// closes: the operator's trial (`operator`: its parts and hand) or, without one, watching.
fn run_session(
    site: &mut OperatorSite,
    options: &JoinOptions,
    operator: Option<(TrialParts, ActiveHand)>,
    view: Option<Arc<ViewShared>>,
    recorder: Option<JoinRecorder>,
) -> Result<JoinReport, AppError> {
    let mut collect = Collect {
        view,
        observer: operator.is_none(),
        recorder,
        head: options.head.clone().map(|source| {
            HeadSender::new(
                source,
                super::serve::camera_key(&options.scene),
                &options.scene,
            )
        }),
        ..Collect::default()
    };
    if let Some(rec) = &mut collect.recorder {
        rec.set_clock(site.robot_now_s());
    }
    let started = Instant::now();
    match operator {
        None => {
            collect.report.role = "observer".into();
            let until = options.duration_s.map(Duration::from_secs_f64);
            let mut polls = 0u64;
            while until.is_none_or(|d| started.elapsed() < d) && !collect.closed() {
                std::thread::sleep(Duration::from_millis(5));
                let now = site.robot_now_s();
                let inbox = site.poll();
                collect.take(site, inbox, now);
                polls += 1;
                if polls.is_multiple_of(20) {
                    collect.show_line();
                }
            }
        }
        Some((parts, hand)) => {
            collect.report.role = "operator".into();
            operate_with(
                site,
                &options.scene,
                parts,
                hand,
                options.duration_s,
                &mut collect,
                started,
            )?;
        }
    }
    if let Some(message) = collect.changed_site.take() {
        return Err(AppError::Session { message });
    }
    Ok(collect.finish(started.elapsed().as_secs_f64()))
}

/// The operator on a joined `site`: trial `trial` of `scene`'s task, its hand and twin stepped
/// in real time, one target per control tick, for `duration_s` (default: the task's). The
/// report says what was sent and received (no clock or info: [`join`] fills those).
pub fn operate(
    site: &mut OperatorSite,
    scene: &Scene,
    mode: Option<MappingMode>,
    trial: u32,
    duration_s: Option<f64>,
) -> Result<JoinReport, AppError> {
    let (parts, _) = trial_parts(scene, RobotChoice::Sim, mode, trial, "avatarm join")?;
    let Some(task) = &scene.file.task else {
        return Err(AppError::flag("--scene", "the scene has no [task]"));
    };
    let hand = ActiveHand::new(ScriptedHand::new(parts.script.clone(), task.hand_rate_hz));
    let mut collect = Collect::default();
    collect.report.role = "operator".into();
    let started = Instant::now();
    operate_with(site, scene, parts, hand, duration_s, &mut collect, started)?;
    Ok(collect.finish(started.elapsed().as_secs_f64()))
}

/// The operator's loop: `parts`' hand app stepped in real time with `hand`, one target per
/// control tick, for `duration_s` (default: the task's, or until the window closes when there
/// is one).
fn operate_with(
    site: &mut OperatorSite,
    scene: &Scene,
    parts: TrialParts,
    hand: ActiveHand,
    duration_s: Option<f64>,
    collect: &mut Collect,
    started: Instant,
) -> Result<(), AppError> {
    let Some(task) = &scene.file.task else {
        return Err(AppError::flag("--scene", "the scene has no [task]"));
    };
    let v2r = parts.v2r;
    let period = parts.period;
    // The same world as the one-process trials': the same hand moves the same twin.
    let mut app = parts.hand_app(hand);
    let steps = match (duration_s, &collect.view) {
        (Some(d), _) => Some((d / period.as_secs_f64()).round() as u64),
        (None, Some(_)) => None,
        (None, None) => Some((task.duration_s / period.as_secs_f64()).round() as u64),
    };
    let centre_to_base = crate::teleop::carried_object(scene).map(|(_, c)| c);
    let z0 = parts.twin_start.translation.z;
    let mut seq = 0u64;
    let mut contacts: Vec<Contact> = Vec::new();
    let mut velocities: Vec<Vector3<f64>> = Vec::new();
    let twin_start = avatarm_twin::iso_to_transform(&parts.twin_start);
    let mut tick = 0u64;
    while steps.is_none_or(|n| tick < n) && !collect.closed() {
        let i = tick;
        tick += 1;
        let due = started + period.mul_f64(i as f64);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        if collect
            .view
            .as_ref()
            .is_some_and(|v| v.reset_twin.swap(false, Ordering::Relaxed))
        {
            reset_twin(app.world_mut(), twin_start);
        }
        app.update();
        let world = app.world_mut();
        let state = read_hand_world(world, &mut contacts, &mut velocities).map_err(|e| {
            AppError::Session {
                message: e.to_string(),
            }
        })?;
        let robot_now = site.robot_now_s();
        let twin = state.twin;
        collect.report.twin_lift_m = collect.report.twin_lift_m.max(twin.translation.z - z0);
        let held = state.held;
        let frame = world.resource::<ActiveHand>().latest.clone();
        let (hand_stamp, tracked) = match state.hand_stamp_s {
            Some(t) => (robot_now - (state.now_s - t), state.hand_tracked),
            None => (f64::NEG_INFINITY, false),
        };
        if let (Some(f), Some(rec)) = (&frame, &mut collect.recorder) {
            rec.hand(f, robot_now - (state.now_s - f.t_s));
        }
        let operator = Mapper::operator_side(
            &OperatorInputs {
                contacts: &contacts,
                contact_velocities: &velocities,
                twin_pose: twin,
                held,
                stamp_s: robot_now,
            },
            &v2r,
        );
        match operator {
            Ok(target) if hand_stamp.is_finite() => {
                let m = TargetMsg::new(seq, &target, hand_stamp, tracked);
                seq += 1;
                match site.publish_target(&m) {
                    Ok(()) => {
                        collect.report.targets_sent += 1;
                        if let Some(rec) = &mut collect.recorder {
                            rec.target(&target);
                        }
                    }
                    Err(e) => {
                        collect.report.targets_failed += 1;
                        warn!("operator: {e}");
                    }
                }
            }
            // Bevy's first update runs no physics step (the fixed clock still at 0): there is
            // no hand yet, and nothing failed.
            _ if state.now_s <= 0.0 => {}
            // No hand yet, or a tick the mapping refuses: nothing goes out, and the robot
            // site's watchdog stops the arm if it lasts.
            _ => collect.report.targets_failed += 1,
        }
        if let Some(f) = frame
            && i.is_multiple_of(3)
        {
            let m = HandMsg {
                v: PROTOCOL_VERSION,
                stamp_s: hand_stamp,
                hand: match f.hand {
                    avatarm_core::teleop::hand::Handedness::Left => "left".into(),
                    avatarm_core::teleop::hand::Handedness::Right => "right".into(),
                },
                tracked: f.tracked,
                joints: f
                    .joints
                    .iter()
                    .map(|j| {
                        let p = v2r.point(&j.pose.translation.vector);
                        [p.x, p.y, p.z]
                    })
                    .collect(),
                held_object: held.then(|| FrameHeader::pose_of(&v2r.pose(&twin))),
            };
            if let Err(e) = site.publish_hand(&m) {
                warn!("operator: {e}");
            }
        }
        if let Some(view) = &collect.view {
            let world = app.world();
            let hand = world
                .resource::<ActiveHand>()
                .latest
                .as_ref()
                .filter(|f| f.tracked && f.joints.len() == 26)
                .map(|f| {
                    f.joints
                        .iter()
                        .map(|j| v2r.point(&j.pose.translation.vector))
                        .collect()
                });
            let object = centre_to_base.map(|c| v2r.pose(&twin) * c);
            view.update(|s| {
                s.hand = hand;
                s.hand_at = Some(Instant::now());
                s.holding = held;
                s.object = object;
            });
            if i.is_multiple_of(10) {
                collect.show_line();
            }
        }
        let inbox = site.poll();
        collect.take(site, inbox, robot_now);
    }
    Ok(())
}

/// Puts the physics twin back at `start`, at rest, unless the hand holds it (the desktop
/// hand's Home, as in `avatarm run`).
fn reset_twin(world: &mut World, start: Transform) {
    if world.resource::<HeldObject>().held.is_some() {
        return;
    }
    let mut twins = world.query_filtered::<
        (&mut Transform, &mut bevy_rapier3d::prelude::Velocity),
        With<GraspTarget>,
    >();
    for (mut t, mut v) in twins.iter_mut(world) {
        *t = start;
        *v = bevy_rapier3d::prelude::Velocity::zero();
    }
}

/// One line for the terminal.
pub fn summary(r: &JoinReport) -> String {
    let presented = r
        .window
        .as_ref()
        .map_or_else(String::new, WindowReport::glass_to_glass_words);
    let outages = if r.robot_site_silences + r.robot_site_restarts > 0 {
        format!(
            "; the robot site fell silent {} times and restarted {} times",
            r.robot_site_silences, r.robot_site_restarts
        )
    } else {
        String::new()
    };
    format!(
        "{}: {:.1} s, {} targets sent, {} joint states, {} status ({} stopping), {} frames \
         ({:.1} fps, {:.2} Mbit/s, capture to decoded {:.0} ms median{presented}), clock offset \
         {:+.2} ms (round trip {:.2} ms){outages}",
        r.role,
        r.duration_s,
        r.targets_sent,
        r.joint_states,
        r.status,
        r.status_stopping,
        r.video.frames,
        r.video.fps,
        r.video.mbit_s,
        r.video.total_ms.median,
        r.clock_offset_s * 1e3,
        r.clock_rtt_ms
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame's real object is the newest reported at or before its capture, and none when
    /// the reports do not reach it.
    #[test]
    fn a_frame_s_object_is_the_one_reported_before_its_capture() {
        let at = |x: f64| nalgebra::Isometry3::translation(x, 0.0, 0.8);
        let objects: std::collections::VecDeque<_> =
            [(1.0, at(0.1)), (1.01, at(0.2)), (1.02, at(0.3))].into();
        assert_eq!(object_at(&objects, 1.015), Some(at(0.2)));
        assert_eq!(object_at(&objects, 1.1), Some(at(0.3)));
        // Before the history, or long after the last report: none.
        assert_eq!(object_at(&objects, 0.9), None);
        assert_eq!(object_at(&objects, 1.5), None);
        assert_eq!(object_at(&Default::default(), 1.0), None);
    }

    /// The summary's glass to glass: the window's present, or in XR the headset's frames
    /// alone (the others ended at the window), and nothing without a window.
    #[test]
    fn the_summary_names_where_glass_to_glass_ended() {
        let spread = |median: f64, n: usize| Spread {
            median,
            p95: median + 10.0,
            max: median + 20.0,
            n,
        };
        let mut r = JoinReport::default();
        let headless = summary(&r);
        assert!(
            !headless.contains("presented") && !headless.contains("headset"),
            "{headless}"
        );
        r.window = Some(WindowReport {
            glass_to_glass_ms: spread(150.0, 40),
            ..Default::default()
        });
        let flat = summary(&r);
        assert!(
            flat.contains("capture to presented in the window 150 ms median (p95 160)"),
            "{flat}"
        );
        r.window = Some(WindowReport {
            glass_to_glass_ms: spread(150.0, 40),
            headset_glass_to_glass_ms: spread(120.0, 30),
            ..Default::default()
        });
        let xr = summary(&r);
        assert!(
            xr.contains("capture to the headset's predicted display 120 ms median (p95 130) over 30 of 40 frames (the other 10 at the window's present)"),
            "{xr}"
        );
        assert!(!xr.contains("in the window"), "{xr}");
    }
}
