//! `avatarm serve`: the robot site. The robot's side of the motion mapping runs on a thread of
//! its own at the control rate ([`ControlLoop`]), next to the robot: each tick it takes the
//! newest valid target from the operator ([`avatarm_mapping::TickSource::Remote`]), maps it
//! to joint velocities (Jacobian pseudoinverse, limiter, watchdog) and publishes the joint
//! states. The erased video, where enabled, comes from the app ([`super::video`]), fed with
//! the loop's joint states.
//!
//! Safety: a target that is malformed, of another protocol version, out of range, non-finite
//! or oversized is refused (counted, one log line per episode) and the arm stops until a
//! fresh valid one arrives; so it does when the operator's liveliness token goes or its
//! targets grow older than the watchdog's timeout. The stop is the limiter's ramp to zero,
//! then no command at all (a real robot's link then holds position).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use avatarm_core::stats::Spread;
use avatarm_core::teleop::mapping::MappingMode;
use avatarm_mapping::{RemoteTarget, Teleop, TickSource};
use avatarm_net::RobotSite;
use avatarm_net::episodes::RefusalEpisodes;
use avatarm_net::msg::MAX_AHEAD_S;
use avatarm_net::msg::{JointStatesMsg, PROTOCOL_VERSION, RobotStatusMsg};
use avatarm_record::LogLevel;
use bevy::log::{info, warn};

use super::video::ArmUpdate;

mod camera_video;
mod trial;
pub use camera_video::{CameraVideo, PlayerReport};
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};
pub use trial::TrialMeasure;
use trial::TrialTrack;

/// One stop of the arm: when it began (s, site clock), why, and how long it lasted.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StopEpisode {
    /// Start (s).
    pub t_s: f64,
    /// Why.
    pub reason: String,
    /// Length (s); `None` while still stopped at the end.
    pub length_s: Option<f64>,
}

/// An operator's liveliness token appearing or the last one going, as the robot site saw it.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct OperatorChange {
    /// When (s, site clock).
    pub t_s: f64,
    /// `true`: an operator joined; `false`: the last one left.
    pub present: bool,
}

/// How many operator changes the report lists (the counts go on beyond): a link that flaps
/// for hours must not grow the report without bound.
pub const MAX_OPERATOR_CHANGES: usize = 1000;

/// How many of the arm's stops the report lists (counted beyond), for the same reason.
pub const MAX_STOPS: usize = 1000;

impl ServeReport {
    /// Counts a stop of the arm and lists it while fewer than [`MAX_STOPS`] are.
    fn stopped(&mut self, stop: StopEpisode) {
        self.stops_total += 1;
        if self.stops.len() < MAX_STOPS {
            self.stops.push(stop);
        }
    }
}

/// The robot site's report (`--report`).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct ServeReport {
    /// Protocol version.
    pub protocol: u32,
    /// The scene.
    pub scene: String,
    /// The site's name.
    pub site: String,
    /// The robot backend.
    pub robot: String,
    /// The mapping mode.
    pub mode: String,
    /// Control rate (Hz).
    pub control_rate_hz: f64,
    /// The watchdog's timeout (s).
    pub target_timeout_s: f64,
    /// How long the loop ran (s).
    pub duration_s: f64,
    /// Control ticks.
    pub ticks: u64,
    /// Targets used.
    pub targets_used: u64,
    /// Targets dropped as older than one already used (reordered or duplicated).
    pub targets_stale: u64,
    /// Targets refused.
    pub targets_refused: u64,
    /// The first refusals' reasons (at most 10).
    pub refusals: Vec<String>,
    /// Episodes of refusals (each logged once, with a summary every 5 s while it lasts).
    pub refusal_episodes: u64,
    /// Refusals by kind (the reason with its numbers as `N`).
    pub refusals_by_kind: std::collections::BTreeMap<String, u64>,
    /// Times an operator joined.
    pub operator_joins: u64,
    /// Times the operator left.
    pub operator_leaves: u64,
    /// When operators joined and left, in order (the first [`MAX_OPERATOR_CHANGES`]).
    pub operator_changes: Vec<OperatorChange>,
    /// The arm's stops, in order (the first [`MAX_STOPS`]).
    pub stops: Vec<StopEpisode>,
    /// All the arm's stops, listed or not.
    pub stops_total: u64,
    /// Age of the target each tick used (ms, site clock minus the hand frame's stamp).
    pub target_age_ms: Spread,
    /// The control loop's tick period as run (ms).
    pub tick_period_ms: Spread,
    /// The pouring measure.
    pub trial: TrialMeasure,
    /// Mapping errors (refused ticks).
    pub mapping_errors: u64,
    /// The last one.
    pub last_error: Option<String>,
    /// Non-finite values the robot received: must be 0.
    pub nan_commands: u64,
    /// The robot link's state at the end, its status line (ROS or ROS 2, the middleware and
    /// where, the robot's state, rates, clocks); none in simulation.
    pub robot_link: Option<String>,
    /// Erased frames published.
    pub video_frames: u64,
    /// The video's codec (`jpeg` or `h264`).
    pub video_codec: String,
    /// Of the frames, keyframes (every JPEG; H.264 IDR frames).
    pub video_keyframes: u64,
    /// H.264 IDR frames forced by viewers' requests.
    pub video_forced_keyframes: u64,
    /// Frames the encoder refused.
    pub video_encode_errors: u64,
    /// Frames H.264's rate control skipped to hold the bit rate.
    pub video_skipped: u64,
    /// Each camera's video (the totals above are their sums).
    pub video_cameras: Vec<CameraVideo>,
}

/// The robot site's control loop, built before it runs.
pub struct ControlLoop {
    /// The teleoperation loop (robot, robot side of the mapping, limiter).
    pub teleop: Teleop,
    /// The real object's start height (m), for the lift.
    pub start_z: f64,
    /// The control period.
    pub period: Duration,
    /// The mapping mode.
    pub mode: MappingMode,
    /// The scene's name.
    pub scene: String,
    /// `--ros2-publish`: the commands and the safety events published on ROS 2, with the
    /// robot's joints' names (q order).
    pub ros2: Option<(crate::net::ros2_out::Ros2Sink, Vec<String>)>,
}

/// Why the arm is stopped now, if it is.
fn stop_reason(
    present: bool,
    refused: Option<&str>,
    latest: Option<&RemoteTarget>,
    now: f64,
    timeout: f64,
    stopping: bool,
) -> Option<String> {
    if !present {
        return Some("no operator (liveliness token absent)".into());
    }
    if let Some(r) = refused {
        return Some(format!("refused target: {r}"));
    }
    match latest {
        None => Some("no target from the operator yet".into()),
        Some(t) if now - t.hand_stamp_s > timeout => Some(format!(
            "targets stale ({:.0} ms old, timeout {:.0} ms)",
            (now - t.hand_stamp_s) * 1e3,
            timeout * 1e3
        )),
        Some(t) if !t.hand_tracked => Some("the operator's hand is not tracked".into()),
        Some(_) if stopping => Some("stopped by the limiter".into()),
        Some(_) => None,
    }
}

impl ControlLoop {
    /// Runs until `stop` is set or `duration` passes, publishing on `site` and feeding each
    /// camera's video app in `video` (none: the loop alone). Returns the report.
    #[expect(
        clippy::too_many_lines,
        reason = "the robot site's control loop: one tick's steps in their order, on the loop's own state"
    )]
    pub fn run(
        mut self,
        site: &mut RobotSite,
        duration: Option<Duration>,
        stop: &AtomicBool,
        video: Vec<Sender<ArmUpdate>>,
    ) -> ServeReport {
        let clock = site.clock();
        let dt = self.period.as_secs_f64();
        let timeout = self.teleop.safety().timeout_s;
        self.teleop.record = true;
        let mut report = ServeReport {
            protocol: PROTOCOL_VERSION,
            scene: self.scene.clone(),
            site: site.keys().site().to_owned(),
            robot: self.teleop.robot_name().to_owned(),
            mode: self.mode.name().to_owned(),
            control_rate_hz: 1.0 / dt,
            target_timeout_s: timeout,
            ..ServeReport::default()
        };
        let mut latest: Option<RemoteTarget> = None;
        let mut last_seq: Option<(u64, f64)> = None;
        let mut refused: Option<String> = None;
        let mut episodes = RefusalEpisodes::new(2.0, 5.0);
        let mut stop_since: Option<(f64, String)> = None;
        let mut trial = TrialTrack::new(self.start_z);
        let mut ages = Vec::new();
        let mut periods = Vec::new();
        let mut last_status = f64::NEG_INFINITY;
        let mut last_stopping = None;
        let started = Instant::now();
        let mut tick: u64 = 0;
        let mut last_tick_at: Option<Instant> = None;
        let mut ticker = avatarm_mapping::threaded::Ticker::new(self.period);
        // When the newest target arrived (s): its twist is fed forward only while it is this
        // fresh; an older one keeps only its pose, so a lost stream never drives the arm on at
        // the last velocity until the watchdog.
        let mut latest_arrival_s = f64::NEG_INFINITY;
        let fresh_for_s = avatarm_mapping::threaded::FRESH_PERIODS * dt;
        loop {
            // Late by more than a period (the machine stalled): the schedule restarts from now
            // rather than running the missed ticks back to back.
            ticker.wait();
            tick += 1;
            if stop.load(Ordering::Relaxed) || duration.is_some_and(|d| started.elapsed() >= d) {
                break;
            }
            let at = Instant::now();
            if let Some(prev) = last_tick_at {
                Spread::push(&mut periods, (at - prev).as_secs_f64() * 1e3);
            }
            last_tick_at = Some(at);
            let now = clock.now_s();
            let inbox = site.poll();
            if let Some(present) = inbox.operator_changed {
                if present {
                    report.operator_joins += 1;
                    info!("robot site: an operator joined");
                } else {
                    report.operator_leaves += 1;
                    warn!("robot site: the operator left; stopping the arm");
                }
                if report.operator_changes.len() < MAX_OPERATOR_CHANGES {
                    report
                        .operator_changes
                        .push(OperatorChange { t_s: now, present });
                }
            }
            let present = inbox.operator_present;
            for received in inbox.targets {
                match received {
                    Ok((m, t)) => {
                        if t.stamp_s > now + MAX_AHEAD_S {
                            let e = format!(
                                "stamped {:.3} s ahead of this site's clock (the operator's clock \
                                 estimate is off)",
                                t.stamp_s - now
                            );
                            refuse(
                                &mut report,
                                &mut episodes,
                                now,
                                &mut refused,
                                &mut latest,
                                e,
                            );
                            continue;
                        }
                        // Older than one used (reordered, duplicated): dropped; a restarted
                        // operator (sequence from 0) is taken once the last is stale.
                        if let Some((seq, at)) = last_seq
                            && m.seq <= seq
                            && now - at <= timeout
                        {
                            report.targets_stale += 1;
                            continue;
                        }
                        last_seq = Some((m.seq, now));
                        refused = None;
                        trial.target(t.stamp_s, t.target);
                        latest = Some(RemoteTarget {
                            target: t,
                            hand_stamp_s: m.hand_stamp_s.min(now),
                            hand_tracked: m.hand_tracked,
                        });
                        latest_arrival_s = now;
                        report.targets_used += 1;
                    }
                    Err(e) => refuse(
                        &mut report,
                        &mut episodes,
                        now,
                        &mut refused,
                        &mut latest,
                        e.to_string(),
                    ),
                }
            }
            if let Some(line) = episodes.tick(now) {
                warn!("robot site: {line}");
                self.safety(LogLevel::Warning, &line);
            }
            if !present {
                latest = None;
            }
            let use_target = latest
                .filter(|_| present && refused.is_none())
                .map(|t| t.freshened(now - latest_arrival_s, fresh_for_s));
            if let Some(t) = &use_target {
                Spread::push(&mut ages, (now - t.hand_stamp_s) * 1e3);
            }
            self.teleop.tick(now, dt, TickSource::Remote(use_target));
            let stopping = self.teleop.log.last().is_some_and(|s| s.stopping);
            // Joint states to the network and to the video.
            let object = self.teleop.robot().true_object_pose();
            for s in self.teleop.received() {
                let m = JointStatesMsg {
                    v: PROTOCOL_VERSION,
                    stamp_s: s.stamp_s,
                    positions: s.positions.iter().copied().collect(),
                    velocities: s.velocities.iter().copied().collect(),
                    object: object.map(pose7),
                };
                if let Err(e) = site.publish_joint_states(&m) {
                    warn!("robot site: {e}");
                }
                for v in &video {
                    let _ = v.send(ArmUpdate {
                        state: s.clone(),
                        object,
                    });
                }
            }
            // Stops as episodes, one line each; those of a refusal episode are told by it.
            let quiet = episodes.active();
            let reason = stop_reason(
                present,
                refused.as_deref(),
                use_target.as_ref().or(latest.as_ref()),
                now,
                timeout,
                stopping,
            )
            .filter(|_| stopping || use_target.is_none());
            match (&stop_since, &reason) {
                (None, Some(r)) => {
                    if tick > 1 && report.targets_used > 0 && !quiet {
                        warn!("robot site: stopping the arm: {r}");
                    }
                    self.safety(LogLevel::Warning, &format!("stopping the arm: {r}"));
                    stop_since = Some((now, r.clone()));
                }
                (Some((since, r)), None) => {
                    if report.targets_used > 0 && !quiet {
                        info!(
                            "robot site: resumed on fresh targets after {:.2} s stopped ({r})",
                            now - since
                        );
                    }
                    self.safety(
                        LogLevel::Info,
                        &format!("resumed after {:.2} s stopped ({r})", now - since),
                    );
                    report.stopped(StopEpisode {
                        t_s: *since,
                        reason: r.clone(),
                        length_s: Some(now - since),
                    });
                    stop_since = None;
                }
                _ => {}
            }
            if now - last_status >= 0.1 || last_stopping != Some(stopping) {
                last_status = now;
                last_stopping = Some(stopping);
                let status = RobotStatusMsg {
                    v: PROTOCOL_VERSION,
                    stamp_s: now,
                    stopping,
                    reason: reason.clone(),
                    ticks: self.teleop.status.ticks,
                    refused_targets: report.targets_refused,
                    targets: report.targets_used,
                    operator_present: present,
                };
                if let Err(e) = site.publish_status(&status) {
                    warn!("robot site: {e}");
                }
            }
            for s in self.teleop.log.drain(..) {
                if let Some((sink, names)) = &self.ros2 {
                    // q order: the names are the model's movable joints, one per velocity.
                    crate::net::ros2_out::publish_command(
                        sink,
                        crate::net::ros2_out::unix_now_ns(),
                        names,
                        s.qdot.as_slice(),
                    );
                }
                trial.sample(&s);
            }
        }
        if let Some((since, r)) = stop_since {
            report.stopped(StopEpisode {
                t_s: since,
                reason: r,
                length_s: None,
            });
        }
        report.refusal_episodes = episodes.episodes();
        report.refusals_by_kind = episodes.by_kind().clone();
        report.duration_s = started.elapsed().as_secs_f64();
        report.ticks = self.teleop.status.ticks;
        report.mapping_errors = self.teleop.status.errors;
        report.last_error = self.teleop.status.last_error.clone();
        report.target_age_ms = Spread::of(&ages);
        report.tick_period_ms = Spread::of(&periods);
        report.nan_commands = trial.nan_commands();
        report.robot_link = self.teleop.robot().status_line();
        report.trial = trial.finish(self.teleop.status.max_tcp_speed);
        report
    }
}

impl ControlLoop {
    /// A safety event on ROS 2 (`--ros2-publish`), now.
    fn safety(&self, level: LogLevel, message: &str) {
        if let Some((sink, _)) = &self.ros2 {
            crate::net::ros2_out::publish_safety(
                sink,
                crate::net::ros2_out::unix_now_ns(),
                level,
                "robot site",
                message,
            );
        }
    }
}

/// A refused target: counted, its episode logged ([`RefusalEpisodes`]), the arm stopped until
/// a fresh valid target.
fn refuse(
    report: &mut ServeReport,
    episodes: &mut RefusalEpisodes,
    now: f64,
    refused: &mut Option<String>,
    latest: &mut Option<RemoteTarget>,
    reason: String,
) {
    report.targets_refused += 1;
    if report.refusals.len() < 10 {
        report.refusals.push(reason.clone());
    }
    if let Some(line) = episodes.refused(now, &reason) {
        warn!("robot site: {line}; stopping the arm until a fresh valid target");
    }
    *refused = Some(reason);
    *latest = None;
}

fn pose7(p: Isometry3<f64>) -> [f64; 7] {
    let t = p.translation.vector;
    let q = p.rotation.quaternion().coords;
    [t.x, t.y, t.z, q.x, q.y, q.z, q.w]
}

/// A place the video side and the loop share: whether the loop should stop.
pub type StopFlag = Arc<AtomicBool>;

/// The newest report, for the app's exit.
pub type ReportSlot = Arc<Mutex<Option<ServeReport>>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stop_says_why() {
        let t = RemoteTarget {
            target: avatarm_core::teleop::mapping::OperatorTarget {
                stamp_s: 1.0,
                target: Isometry3::identity(),
                object_twist: nalgebra::Vector6::zeros(),
                twin_twist: nalgebra::Vector6::zeros(),
                squeeze_n: 0.0,
                rank: 0,
                contacts: 0,
                held: false,
            },
            hand_stamp_s: 1.0,
            hand_tracked: true,
        };
        let r =
            |present, refused, latest, now| stop_reason(present, refused, latest, now, 0.1, false);
        assert!(r(false, None, Some(&t), 1.0).is_some_and(|s| s.contains("liveliness")));
        assert!(r(true, Some("bad"), Some(&t), 1.0).is_some_and(|s| s.contains("refused")));
        assert!(r(true, None, Some(&t), 1.5).is_some_and(|s| s.contains("stale")));
        assert!(r(true, None, Some(&t), 1.05).is_none());
        assert!(r(true, None, None, 1.0).is_some_and(|s| s.contains("yet")));
    }
}

/// How `avatarm serve` runs.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The scene (with a `[task]`), looking through the first camera served.
    pub scene: avatarm_scene::Scene,
    /// The same scene through each further camera served at once (`--view alice,blair`; each
    /// is erased by an app of its own, fed the same joint states).
    pub more_views: Vec<avatarm_scene::Scene>,
    /// The robot.
    pub robot: crate::teleop::RobotChoice,
    /// The mapping mode (default: the task's closed loop).
    pub mode: Option<MappingMode>,
    /// The network settings.
    pub net: avatarm_net::NetConfig,
    /// Stop after this long (s); `None`: until killed.
    pub duration_s: Option<f64>,
    /// Where to write the report.
    pub report: Option<std::path::PathBuf>,
    /// Render, erase and publish the video.
    pub video: bool,
    /// The watchdog's timeout on the operator's targets (s).
    pub target_timeout_s: f64,
    /// How the video is coded.
    pub encoder: avatarm_net::codec::EncoderSettings,
    /// Where the camera comes from (a recording's robot replaces `robot`).
    pub camera: super::site_camera::SiteCamera,
    /// Publish on ROS 2 (`--ros2-publish`): the erased frames (with `--codec jpeg`), the
    /// commands and the safety events, under `/avatarm`.
    pub ros2_publish: bool,
}

/// Sets the flag when dropped.
struct StopOnDrop(StopFlag);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// `encoder` for `view`'s camera: its frame rate for H.264's rate control. Errors name the
/// camera whose rate the encoder refuses.
fn view_encoder(
    encoder: &avatarm_net::codec::EncoderSettings,
    view: &avatarm_scene::Scene,
) -> Result<avatarm_net::codec::EncoderSettings, crate::AppError> {
    let settings = avatarm_net::codec::EncoderSettings {
        fps: view.file.camera.fps.clamp(1.0, 240.0) as f32,
        ..*encoder
    };
    settings.validate().map_err(|e| {
        crate::AppError::flag(
            "the video encoder",
            format!("camera '{}': {e}", view.camera_name()),
        )
    })?;
    Ok(settings)
}

/// The camera's name on the network for a scene with one `[camera]`.
pub const CAMERA: &str = "desk";

/// The name the robot site publishes `scene`'s camera under: [`CAMERA`] for a scene's one
/// `[camera]`, the camera's own name (`--view`) for one of its `[[cameras]]`.
pub fn camera_key(scene: &avatarm_scene::Scene) -> String {
    if scene.cameras.len() > 1 {
        scene.camera_name().to_owned()
    } else {
        CAMERA.to_owned()
    }
}

/// What the robot site says about itself: the scene and its fingerprint, the cameras, the
/// control rate, the watchdog's timeout, the robot and who may command it (`operators`, the
/// network configuration's).
pub fn robot_info(
    scene: &avatarm_scene::Scene,
    parts: &avatarm_mapping::pouring::TrialParts,
    target_timeout_s: f64,
    cameras: Vec<String>,
    operators: Vec<String>,
) -> Result<avatarm_net::msg::RobotInfo, crate::AppError> {
    Ok(avatarm_net::msg::RobotInfo {
        v: PROTOCOL_VERSION,
        software: env!("CARGO_PKG_VERSION").into(),
        scene: scene.file.name.clone(),
        scene_hash: super::scene_fingerprint(scene)?,
        cameras,
        control_rate_hz: 1.0 / parts.period.as_secs_f64(),
        target_timeout_s,
        robot: parts.teleop.robot_name().to_owned(),
        operators,
    })
}

/// Runs the robot site until the duration passes (or the process is killed). Errors when the
/// scene has no task, the robot or the network cannot be set up.
#[expect(
    clippy::too_many_lines,
    reason = "the robot site set up in its order (network, control loop thread, one app per camera) and torn down whatever ends first"
)]
pub fn serve(options: &ServeOptions) -> Result<ServeReport, crate::AppError> {
    let mut scene = options.scene.clone();
    let views_served = if options.video {
        1 + options.more_views.len()
    } else {
        1
    };
    let opened = super::site_camera::open(&options.camera, &mut scene, views_served)?;
    for note in &opened.notes {
        info!("{note}");
    }
    let scene = &scene;
    if !(options.target_timeout_s.is_finite() && (0.0..=10.0).contains(&options.target_timeout_s))
        || options.target_timeout_s == 0.0
    {
        return Err(crate::AppError::flag(
            "--target-timeout",
            format!("{} s must be > 0 and at most 10", options.target_timeout_s),
        ));
    }
    if let Some(d) = options.duration_s
        && !(d.is_finite() && d > 0.0 && d < 1e7)
    {
        return Err(crate::AppError::flag(
            "--duration",
            format!("{d} s must be > 0"),
        ));
    }
    // Before the arm moves: the video thread makes its encoder later. The error names the
    // setting (`net::encoder_settings` checked the flags; this is for other callers).
    options
        .encoder
        .validate()
        .map_err(|e| crate::AppError::flag("the video encoder", e.to_string()))?;
    let link = match (opened.arm, options.robot) {
        (Some(arm), _) => crate::teleop::TrialLink::Given(Box::new(arm)),
        (None, crate::teleop::RobotChoice::Sim) => crate::teleop::TrialLink::Simulated,
        (None, crate::teleop::RobotChoice::Ros) => crate::teleop::TrialLink::Ros,
    };
    let (mut parts, mode) =
        crate::teleop::trial_parts_on(scene, link, options.mode, 0, "avatarm serve")?;
    parts
        .teleop
        .set_watchdog_timeout(options.target_timeout_s)
        .map_err(|e| crate::AppError::flag("--target-timeout", e.to_string()))?;
    let start_z = scene
        .trial
        .as_ref()
        .map_or(0.0, |s| s.bottle_centre().translation.z);
    let views: Vec<&avatarm_scene::Scene> =
        std::iter::once(scene).chain(&options.more_views).collect();
    let cameras: Vec<String> = if options.video {
        views.iter().map(|v| camera_key(v)).collect()
    } else {
        Vec::new()
    };
    if let Some(twice) = cameras
        .iter()
        .enumerate()
        .find_map(|(i, c)| cameras[..i].contains(c).then_some(c))
    {
        return Err(crate::AppError::flag(
            "--view",
            format!("the camera '{twice}' is named twice"),
        ));
    }
    let info = robot_info(
        scene,
        &parts,
        options.target_timeout_s,
        cameras.clone(),
        options.net.operators.clone(),
    )?;
    let clock = avatarm_net::SiteClock::start();
    let mut site = RobotSite::open(&options.net, &info, clock)?;
    info!(
        "robot site '{}' on {:?}: scene '{}', {} ({} mode), video {}",
        options.net.keys.site(),
        options.net.listen,
        info.scene,
        info.robot,
        mode.name(),
        if options.video {
            format!("of {}", cameras.join(", "))
        } else {
            "off".to_owned()
        }
    );
    let ros2 = if options.ros2_publish {
        Some(crate::net::ros2_out::ros2_publisher(scene)?)
    } else {
        None
    };
    let control = ControlLoop {
        teleop: parts.teleop,
        start_z,
        period: parts.period,
        mode,
        scene: scene.file.name.clone(),
        ros2: ros2.clone().map(|sink| {
            let names = scene
                .model
                .dof_names()
                .iter()
                .map(ToString::to_string)
                .collect();
            (sink, names)
        }),
    };
    let stop: StopFlag = Arc::new(AtomicBool::new(false));
    let duration = options.duration_s.map(Duration::from_secs_f64);
    let (report, site) = if options.video {
        // One app per camera, each fed the loop's joint states: the first on this thread
        // (where the process's apps have always run), the others on threads of their own.
        let mut feeds = Vec::new();
        let mut apps = Vec::new();
        for (i, (view, camera)) in views.iter().zip(&cameras).enumerate() {
            let (tx, rx) = std::sync::mpsc::channel();
            feeds.push(tx);
            let mut video = super::video::ServeVideoOptions {
                updates: Arc::new(Mutex::new(rx)),
                sender: site.frame_sender(),
                camera: camera.clone(),
                clock,
                stop: stop.clone(),
                encoder: view_encoder(&options.encoder, view)?,
                counters: Arc::default(),
                head: None,
                source: opened.source.clone(),
                // One erased stream on /avatarm/erased: the scene's own camera's.
                ros2: ros2.clone().filter(|_| i == 0),
            };
            let mut view = (*view).clone();
            if let Some(head) = view.head.as_mut() {
                // The cameras' apps share the cores: a view-following background left at one
                // thread per core gets its share, so one camera's bursts do not starve another's.
                if head.background_threads == 0 {
                    head.background_threads =
                        (avatarm_core::dr::view_background::default_threads() / views.len()).max(1);
                }
                // A camera on a head rides on its wearer's head where one reports over the
                // network (the scene's simulated head until then).
                head.motion = avatarm_core::vision::head::HeadMotion::Live(
                    avatarm_core::vision::head::LiveHead::new(head.motion.clone()),
                );
                video.head = Some(Arc::new(site.head_receiver(camera)?));
            }
            apps.push((view, video));
        }
        let counters: Vec<_> = apps
            .iter()
            .map(|(_, v)| (v.camera.clone(), v.counters.clone(), v.source.clone()))
            .collect();
        let loop_stop = stop.clone();
        let handle = std::thread::Builder::new()
            .name("control loop".into())
            .spawn(move || {
                // However the loop ends (a panic included), the video apps end with it.
                let _stop = StopOnDrop(loop_stop.clone());
                let report = control.run(&mut site, duration, &loop_stop, feeds);
                (report, site)
            })
            .map_err(|e| {
                crate::AppError::command("serve", format!("cannot start the control loop: {e}"))
            })?;
        let mut apps = apps.into_iter();
        let (first, first_video) = apps.next().expect("one camera at least");
        let others: Vec<_> = apps
            .map(|(view, video)| {
                let camera = video.camera.clone();
                let stop = stop.clone();
                let thread = std::thread::Builder::new()
                    .name(format!("camera {camera}"))
                    .spawn(move || {
                        // However this camera's app ends, the site ends with it.
                        let _stop = StopOnDrop(stop);
                        super::video::build_app(&view, video)
                            .map(|mut app| {
                                app.run();
                            })
                            .map_err(|e| e.to_string())
                    });
                (camera, thread)
            })
            .collect();
        let ran = super::video::build_app(&first, first_video).map(|mut app| {
            app.run();
        });
        stop.store(true, Ordering::Relaxed);
        let (mut report, site) = handle
            .join()
            .map_err(|_| crate::AppError::command("serve", "the control loop panicked"))?;
        // Every app has ended (the stop flag) before an error is returned.
        let others: Vec<_> = others
            .into_iter()
            .map(|(camera, thread)| {
                thread
                    .map_err(|e| format!("cannot start its app: {e}"))
                    .and_then(|t| {
                        t.join()
                            .map_err(|_| "its app panicked".to_owned())
                            .and_then(|r| r)
                    })
                    .map_err(|e| {
                        crate::AppError::command("serve", format!("camera '{camera}': {e}"))
                    })
            })
            .collect();
        ran?;
        others.into_iter().collect::<Result<Vec<()>, _>>()?;
        report.video_cameras = counters
            .iter()
            .map(|(camera, c, source)| CameraVideo::of(camera.clone(), c, source))
            .collect();
        let sum = |f: fn(&CameraVideo) -> u64| report.video_cameras.iter().map(f).sum::<u64>();
        report.video_frames = sum(|c| c.frames);
        report.video_keyframes = sum(|c| c.keyframes);
        report.video_forced_keyframes = sum(|c| c.forced_keyframes);
        report.video_encode_errors = sum(|c| c.encode_errors);
        report.video_skipped = sum(|c| c.skipped);
        report.video_codec = options.encoder.codec.name().into();
        (report, site)
    } else {
        let report = control.run(&mut site, duration, &stop, Vec::new());
        (report, site)
    };
    site.close();
    if let Some(path) = &options.report {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text).map_err(|e| crate::AppError::write(path, e))?;
    }
    Ok(report)
}

/// One line for the terminal (the robot link's state at the end after it, where there is one).
pub fn summary(r: &ServeReport) -> String {
    format!(
        "robot site: {:.1} s, {} ticks, {} targets used ({} refused, {} stale), {} stops, \
         position RMSE {} (as received {}), real lift {:.0} mm, {} video frames ({}, {} keyframes){}",
        r.duration_s,
        r.ticks,
        r.targets_used,
        r.targets_refused,
        r.targets_stale,
        r.stops.len(),
        r.trial
            .pos_rmse_m
            .map_or("-".into(), |v| format!("{:.1} mm", v * 1e3)),
        r.trial
            .pos_rmse_as_received_m
            .map_or("-".into(), |v| format!("{:.1} mm", v * 1e3)),
        r.trial.real_lift_m * 1e3,
        r.video_frames,
        if r.video_codec.is_empty() {
            "-"
        } else {
            &r.video_codec
        },
        r.video_keyframes,
        r.robot_link
            .as_ref()
            .map_or_else(String::new, |l| format!("; {l}"))
    )
}
