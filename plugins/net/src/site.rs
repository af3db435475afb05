//! The two ends of a session over Zenoh: [`RobotSite`] (Alice's desk) and [`OperatorSite`]
//! (Blair, or an observer). Both are synchronous (Zenoh's `Wait`): calls return at once,
//! received messages wait in bounded queues until polled.
//!
//! QoS per stream (`docs/network.md`):
//!
//! | stream | priority | express | when congested |
//! |---|---|---|---|
//! | targets | real time | yes | drop (the next one is 10 ms away) |
//! | joint states | interactive high | yes | drop |
//! | status | data high | no | drop (10 Hz; each says everything) |
//! | erased video | data | no | drop (a late frame is useless) |
//! | hand | interactive low | yes | drop |
//! | a head camera's head | interactive high | yes | drop (and the oldest dropped at the robot site while its camera's app is busy) |

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use zenoh::Session;
use zenoh::Wait;
use zenoh::handlers::{FifoChannelHandler, RingChannelHandler};
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Queryable;
use zenoh::sample::{Sample, SampleKind};

use crate::NetError;
use crate::config::NetConfig;
use crate::keys::Keys;
use crate::msg::{
    self, FrameHeader, HandMsg, HeadPoseMsg, JointStatesMsg, PROTOCOL_VERSION, RobotInfo,
    RobotStatusMsg, TargetMsg,
};

/// How many messages of a stream wait to be polled; beyond, Zenoh's handler blocks its
/// thread briefly (the stream's own congestion control applies upstream).
const QUEUE: usize = 1024;

/// The robot site's clock: seconds since the site started. Every stamp of the session is on
/// it.
#[derive(Debug, Clone, Copy)]
pub struct SiteClock {
    start: Instant,
}

impl SiteClock {
    /// A clock starting now.
    pub fn start() -> Self {
        Self {
            start: Instant::now(),
        }
    }

    /// Now (s).
    pub fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}

#[derive(Debug, Serialize, Deserialize)]
struct ClockReply {
    v: u32,
    now_s: f64,
}

fn zerr(what: &str, e: impl std::fmt::Display) -> NetError {
    NetError::Zenoh {
        what: what.into(),
        message: e.to_string(),
    }
}

fn open(config: &NetConfig) -> Result<Session, NetError> {
    let z = config.zenoh()?;
    if !config.listen.is_empty() {
        let endpoints = &config.listen;
        return zenoh::open(z)
            .wait()
            .map_err(|e| zerr(&format!("opening the session on {endpoints:?}"), e));
    }
    let endpoints = &config.connect;
    zenoh::open(z).wait().map_err(|e| {
        zerr(
            &format!("connecting to {endpoints:?}"),
            format!("{e}; {}", connect_causes(config)),
        )
    })
}

/// What may have refused a session that connects, for the user to check: Zenoh says only that
/// it could not connect, the same for no listener, a refused login and a certificate it cannot
/// check (and the robot site logs none of them).
fn connect_causes(config: &NetConfig) -> String {
    let mut causes = vec![
        "nothing listens there (is `avatarm serve` or `avatarm router` running, on that endpoint?)"
            .to_owned(),
    ];
    // Who checks the login and shows the certificate: the robot site, or the router between.
    let peer = if config.role == crate::Role::RobotSite {
        "the router"
    } else {
        "the robot site (or its router)"
    };
    causes.push(match &config.credentials {
        Some(c) => format!(
            "the login of user '{}' was refused (a wrong password and an unknown user look alike from here)",
            c.user
        ),
        None => format!("{peer} requires a login: give --credentials FILE (user:password)"),
    });
    if config.connect.iter().any(|e| crate::config::secure(e)) {
        causes.push(match config.tls.as_ref().and_then(|t| t.root_ca.as_ref()) {
            Some(ca) => format!(
                "{peer}'s certificate is not signed by {}, or not for that host name",
                ca.display()
            ),
            None => format!(
                "no --tls-ca: {peer}'s certificate was checked against the system's authorities only"
            ),
        });
    }
    format!("possible causes: {}", causes.join("; "))
}

fn publisher(
    session: &Session,
    key: String,
    priority: Priority,
    express: bool,
    congestion: CongestionControl,
) -> Result<Publisher<'static>, NetError> {
    session
        .declare_publisher(key.clone())
        .priority(priority)
        .express(express)
        .congestion_control(congestion)
        .wait()
        .map_err(|e| zerr(&key, e))
}

fn subscriber(
    session: &Session,
    key: String,
) -> Result<Subscriber<FifoChannelHandler<Sample>>, NetError> {
    session
        .declare_subscriber(key.clone())
        .with(zenoh::handlers::FifoChannel::new(QUEUE))
        .wait()
        .map_err(|e| zerr(&key, e))
}

fn drain(sub: &Subscriber<FifoChannelHandler<Sample>>) -> Vec<Sample> {
    let mut out = Vec::new();
    while let Ok(Some(s)) = sub.try_recv() {
        out.push(s);
    }
    out
}

/// What the robot site received since the last poll.
#[derive(Debug, Default)]
pub struct RobotInbox {
    /// Targets, decoded and checked, in arrival order; a refused one says why.
    pub targets: Vec<Result<(TargetMsg, avatarm_core::teleop::mapping::OperatorTarget), NetError>>,
    /// An operator's liveliness token is present.
    pub operator_present: bool,
    /// An operator's token appeared (`true`) or went (`false`) since the last poll.
    pub operator_changed: Option<bool>,
}

/// One camera's head poses as they arrive at the robot site ([`RobotSite::head_receiver`]).
pub struct HeadReceiver {
    subscriber: Subscriber<RingChannelHandler<Sample>>,
    camera: String,
}

/// How many head poses wait for the camera's app (about 3 s at a headset's rate): beyond, the
/// oldest are dropped, so that an app that stalls (or is still starting) never blocks the
/// session's other streams, the operator's targets among them.
const HEAD_QUEUE: usize = 256;

impl std::fmt::Debug for HeadReceiver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HeadReceiver")
            .field("camera", &self.camera)
            .finish_non_exhaustive()
    }
}

impl HeadReceiver {
    /// The poses received since the last call, decoded and checked, in arrival order; a
    /// refused one (malformed, another version, not finite, another camera's) says why.
    pub fn poll(&self) -> Vec<Result<HeadPoseMsg, NetError>> {
        let mut samples = Vec::new();
        while let Ok(Some(s)) = self.subscriber.try_recv() {
            samples.push(s);
        }
        samples
            .iter()
            .map(|s| {
                let m = msg::decode_head(&s.payload().to_bytes())?;
                if m.camera == self.camera {
                    Ok(m)
                } else {
                    Err(NetError::Invalid {
                        what: "head pose".into(),
                        message: format!(
                            "camera '{}' in the message, on camera '{}''s key",
                            m.camera, self.camera
                        ),
                    })
                }
            })
            .collect()
    }
}

/// Alice's end: publishes the robot's state and the erased video, receives the operator's
/// targets, answers info and clock queries.
pub struct RobotSite {
    session: Session,
    keys: Keys,
    clock: SiteClock,
    targets: Subscriber<FifoChannelHandler<Sample>>,
    alive: Subscriber<FifoChannelHandler<Sample>>,
    operators: usize,
    joint_states: Publisher<'static>,
    status: Publisher<'static>,
    frames: Arc<Vec<(String, Publisher<'static>)>>,
    keyframe_requests: Arc<Vec<(String, AtomicBool)>>,
    _info: Queryable<()>,
    _clock: Queryable<()>,
    _keyframe: Queryable<()>,
}

impl RobotSite {
    /// Opens the session (listening on the configuration's endpoints), declares every stream
    /// and answers `info`. Errors name the setting or the key.
    pub fn open(config: &NetConfig, info: &RobotInfo, clock: SiteClock) -> Result<Self, NetError> {
        let session = open(config)?;
        let keys = config.keys.clone();
        let targets = subscriber(&session, keys.target())?;
        let alive = session
            .liveliness()
            .declare_subscriber(keys.alive())
            .history(true)
            .with(zenoh::handlers::FifoChannel::new(QUEUE))
            .wait()
            .map_err(|e| zerr(&keys.alive(), e))?;
        let joint_states = publisher(
            &session,
            keys.joint_states(),
            Priority::InteractiveHigh,
            true,
            CongestionControl::Drop,
        )?;
        // Drop, not block: this is published from the control loop, which must never wait
        // for a stalled link (the next status is 0.1 s away and says it all again).
        let status = publisher(
            &session,
            keys.status(),
            Priority::DataHigh,
            false,
            CongestionControl::Drop,
        )?;
        let mut frames = Vec::new();
        for camera in &info.cameras {
            frames.push((
                camera.clone(),
                publisher(
                    &session,
                    keys.erased(camera),
                    Priority::Data,
                    false,
                    CongestionControl::Drop,
                )?,
            ));
        }
        // A viewer's keyframe request (any authenticated peer may ask: it is a query, which
        // the access control lets everyone make) sets its camera's flag; the encoder takes it
        // ([`FrameSender::take_keyframe_request`]) and limits how often it obliges.
        let keyframe_requests: Arc<Vec<(String, AtomicBool)>> = Arc::new(
            info.cameras
                .iter()
                .map(|c| (c.clone(), AtomicBool::new(false)))
                .collect(),
        );
        let keyframe_key = keys.all_keyframes();
        let requests = keyframe_requests.clone();
        let keyframe_keys: Vec<String> = info.cameras.iter().map(|c| keys.keyframe(c)).collect();
        let keyframe_queryable = session
            .declare_queryable(keyframe_key.clone())
            .callback(move |q| {
                let key = q.key_expr().as_str();
                if let Some(i) = keyframe_keys.iter().position(|k| k == key) {
                    requests[i].1.store(true, Ordering::Relaxed);
                    let _ = q.reply(q.key_expr().clone(), Vec::<u8>::new()).wait();
                }
            })
            .wait()
            .map_err(|e| zerr(&keyframe_key, e))?;
        let info_bytes = msg::encode("info", info)?;
        let info_key = keys.info();
        let info_queryable = session
            .declare_queryable(info_key.clone())
            .callback(move |q| {
                let _ = q.reply(q.key_expr().clone(), info_bytes.clone()).wait();
            })
            .wait()
            .map_err(|e| zerr(&info_key, e))?;
        let clock_key = keys.clock();
        let clock_queryable = session
            .declare_queryable(clock_key.clone())
            .callback(move |q| {
                let reply = ClockReply {
                    v: PROTOCOL_VERSION,
                    now_s: clock.now_s(),
                };
                if let Ok(bytes) = msg::encode("clock", &reply) {
                    let _ = q.reply(q.key_expr().clone(), bytes).wait();
                }
            })
            .wait()
            .map_err(|e| zerr(&clock_key, e))?;
        Ok(Self {
            session,
            keys,
            clock,
            targets,
            alive,
            operators: 0,
            joint_states,
            status,
            frames: Arc::new(frames),
            keyframe_requests,
            _info: info_queryable,
            _clock: clock_queryable,
            _keyframe: keyframe_queryable,
        })
    }

    /// The site's clock.
    pub fn clock(&self) -> SiteClock {
        self.clock
    }

    /// A receiver of camera `camera`'s head poses (its wearer's headset), to hand to the
    /// thread that erases that camera. Errors name the key Zenoh refused.
    pub fn head_receiver(&self, camera: &str) -> Result<HeadReceiver, NetError> {
        let key = self.keys.head(camera);
        let subscriber = self
            .session
            .declare_subscriber(key.clone())
            .with(zenoh::handlers::RingChannel::new(HEAD_QUEUE))
            .wait()
            .map_err(|e| zerr(&key, e))?;
        Ok(HeadReceiver {
            subscriber,
            camera: camera.to_owned(),
        })
    }

    /// The session's keys.
    pub fn keys(&self) -> &Keys {
        &self.keys
    }

    /// Everything received since the last poll.
    pub fn poll(&mut self) -> RobotInbox {
        let mut inbox = RobotInbox::default();
        let before = self.operators > 0;
        for s in drain(&self.alive) {
            match s.kind() {
                SampleKind::Put => self.operators += 1,
                SampleKind::Delete => self.operators = self.operators.saturating_sub(1),
            }
        }
        inbox.operator_present = self.operators > 0;
        if inbox.operator_present != before {
            inbox.operator_changed = Some(inbox.operator_present);
        }
        for s in drain(&self.targets) {
            inbox
                .targets
                .push(msg::decode_target(&s.payload().to_bytes()));
        }
        inbox
    }

    /// Publishes the robot's joint states.
    pub fn publish_joint_states(&self, m: &JointStatesMsg) -> Result<(), NetError> {
        let bytes = msg::encode("joint_states", m)?;
        self.joint_states
            .put(bytes)
            .wait()
            .map_err(|e| zerr(&self.keys.joint_states(), e))
    }

    /// Publishes the site's status.
    pub fn publish_status(&self, m: &RobotStatusMsg) -> Result<(), NetError> {
        let bytes = msg::encode("status", m)?;
        self.status
            .put(bytes)
            .wait()
            .map_err(|e| zerr(&self.keys.status(), e))
    }

    /// A handle that publishes camera frames from another thread (the video encoder's).
    pub fn frame_sender(&self) -> FrameSender {
        FrameSender {
            publishers: self.frames.clone(),
            keyframe_requests: self.keyframe_requests.clone(),
        }
    }

    /// Closes the session (the operator sees the site go).
    pub fn close(self) {
        let _ = self.session.close().wait();
    }
}

/// Publishes coded frames of the robot site's cameras; cloned to the encoder's thread.
#[derive(Clone)]
pub struct FrameSender {
    publishers: Arc<Vec<(String, Publisher<'static>)>>,
    keyframe_requests: Arc<Vec<(String, AtomicBool)>>,
}

impl FrameSender {
    /// Whether a viewer asked for a keyframe of `camera` since the last call (the request is
    /// taken: a second call says `false` until a viewer asks again).
    pub fn take_keyframe_request(&self, camera: &str) -> bool {
        self.keyframe_requests
            .iter()
            .find(|(c, _)| c == camera)
            .is_some_and(|(_, f)| f.swap(false, Ordering::Relaxed))
    }

    /// Publishes one coded frame. Errors for an unknown camera or a frame Zenoh refuses.
    pub fn send(&self, header: &FrameHeader, payload: Vec<u8>) -> Result<(), NetError> {
        let Some((_, p)) = self.publishers.iter().find(|(n, _)| *n == header.camera) else {
            return Err(NetError::Invalid {
                what: "frame".into(),
                message: format!("no camera '{}'", header.camera),
            });
        };
        let attachment = msg::encode("frame header", header)?;
        p.put(payload)
            .attachment(attachment)
            .wait()
            .map_err(|e| zerr(&header.camera, e))
    }
}

/// The operator's estimate of the robot site's clock: `robot = local + offset_s`, from the
/// query with the shortest round trip (Cristian's algorithm). Its sign is robot minus local;
/// the ROS link's `avatarm_ros::ClockOffset` (a filter over joint-state arrivals) gives
/// Avatarm's clock minus the robot's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockSample {
    /// Robot clock minus this process's clock (s).
    pub offset_s: f64,
    /// The round trip of the query it came from (s): the estimate is within half of it.
    pub rtt_s: f64,
}

/// A coded frame as received: its header, the coded image, and when it arrived (s, the robot
/// site's clock as estimated).
#[derive(Debug, Clone)]
pub struct ReceivedFrame {
    /// The header.
    pub header: FrameHeader,
    /// The coded image.
    pub payload: Vec<u8>,
    /// Arrival (s, robot clock).
    pub received_s: f64,
}

/// What an operator or observer received since the last poll.
#[derive(Debug, Default)]
pub struct OperatorInbox {
    /// Joint states.
    pub joint_states: Vec<Result<JointStatesMsg, NetError>>,
    /// Status messages.
    pub status: Vec<Result<RobotStatusMsg, NetError>>,
    /// Erased frames, checked.
    pub frames: Vec<Result<ReceivedFrame, NetError>>,
    /// The operator's hand (observers).
    pub hands: Vec<Result<HandMsg, NetError>>,
}

/// Blair's end (or an observer's): asks the robot site who it is, estimates its clock,
/// publishes targets and hand frames (an operator), receives the video and the robot's state.
pub struct OperatorSite {
    session: Session,
    keys: Keys,
    info: RobotInfo,
    local: SiteClock,
    offset: Arc<std::sync::Mutex<RobotClock>>,
    refresh: Refresh,
    target: Publisher<'static>,
    hand: Publisher<'static>,
    _token: Option<LivelinessToken>,
    joint_states: Subscriber<FifoChannelHandler<Sample>>,
    status: Subscriber<FifoChannelHandler<Sample>>,
    frames: Subscriber<FifoChannelHandler<Sample>>,
    hands: Subscriber<FifoChannelHandler<Sample>>,
}

impl OperatorSite {
    /// Connects, waits up to `wait` for the robot site's info (refusing another protocol
    /// version with both named), estimates the clock offset, and — for an operator — declares
    /// its liveliness token. Errors name what failed.
    pub fn join(config: &NetConfig, wait: Duration) -> Result<Self, NetError> {
        let deadline = Instant::now() + wait;
        // The robot site may still be starting: the session is retried until `wait` passes.
        let session = loop {
            match open(config) {
                Ok(s) => break s,
                Err(_) if Instant::now() + Duration::from_millis(250) < deadline => {
                    std::thread::sleep(Duration::from_millis(250));
                }
                Err(e) => return Err(e),
            }
        };
        let keys = config.keys.clone();
        let local = SiteClock::start();
        let info = loop {
            match query(&session, &keys.info(), Duration::from_millis(1000)) {
                Some(bytes) => break msg::decode_info(&bytes)?,
                None if Instant::now() >= deadline => {
                    return Err(NetError::NoRobotSite {
                        key: keys.info(),
                        waited_s: wait.as_secs_f64(),
                    });
                }
                None => std::thread::sleep(Duration::from_millis(100)),
            }
        };
        let offset = Arc::new(std::sync::Mutex::new(RobotClock {
            sample: estimate_offset(&session, &keys, &local, 9)?,
            restarts: 0,
            last_jump_s: 0.0,
        }));
        let operator = config.role == crate::Role::Operator;
        let token = if operator {
            Some(
                session
                    .liveliness()
                    .declare_token(keys.alive())
                    .wait()
                    .map_err(|e| zerr(&keys.alive(), e))?,
            )
        } else {
            None
        };
        Ok(Self {
            target: publisher(
                &session,
                keys.target(),
                Priority::RealTime,
                true,
                CongestionControl::Drop,
            )?,
            hand: publisher(
                &session,
                keys.hand(),
                Priority::InteractiveLow,
                true,
                CongestionControl::Drop,
            )?,
            joint_states: subscriber(&session, keys.joint_states())?,
            status: subscriber(&session, keys.status())?,
            frames: subscriber(&session, keys.all_erased())?,
            hands: subscriber(&session, keys.hand())?,
            _token: token,
            refresh: refresher(&session, &keys, local, offset.clone()),
            session,
            keys,
            info,
            local,
            offset,
        })
    }

    /// The robot site's info, as it answered at the join.
    pub fn info(&self) -> &RobotInfo {
        &self.info
    }

    /// Asks the robot site for its info again (a restarted robot site may run another scene,
    /// version or operators): `None` when none answers within `timeout`. Errors for an answer
    /// that does not decode (another protocol version named).
    pub fn ask_info(&self, timeout: Duration) -> Result<Option<RobotInfo>, NetError> {
        query(&self.session, &self.keys.info(), timeout)
            .map(|bytes| msg::decode_info(&bytes))
            .transpose()
    }

    /// The clock offset's estimate (re-estimated every [`OFFSET_REFRESH`] on a thread of its
    /// own, so the operator's loop never waits for a round trip).
    pub fn offset(&self) -> ClockSample {
        self.robot_clock().sample
    }

    /// The estimate with the robot site's restarts seen so far (its clock jumped).
    pub fn robot_clock(&self) -> RobotClock {
        *self.offset.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Re-estimates the offset at the refresher's next look (within 0.1 s) instead of at the
    /// next [`OFFSET_REFRESH`]: for a robot site heard again after a silence, which may have
    /// restarted with a new clock.
    pub fn refresh_offset_soon(&self) {
        self.refresh
            .soon
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// Now on the robot site's clock, as estimated (s).
    pub fn robot_now_s(&self) -> f64 {
        self.local.now_s() + self.offset().offset_s
    }

    /// Publishes a target.
    pub fn publish_target(&self, m: &TargetMsg) -> Result<(), NetError> {
        let bytes = msg::encode("target", m)?;
        self.target
            .put(bytes)
            .wait()
            .map_err(|e| zerr(&self.keys.target(), e))
    }

    /// Publishes the operator's hand.
    pub fn publish_hand(&self, m: &HandMsg) -> Result<(), NetError> {
        let bytes = msg::encode("hand", m)?;
        self.hand
            .put(bytes)
            .wait()
            .map_err(|e| zerr(&self.keys.hand(), e))
    }

    /// Publishes the head a camera rides on (the wearer's headset; [`HeadPoseMsg`]): express,
    /// dropped rather than queued behind a stalled link (the next pose is a frame away).
    /// Errors for a non-finite pose or a put Zenoh refuses, with the key named.
    pub fn publish_head(&self, m: &HeadPoseMsg) -> Result<(), NetError> {
        let bytes = msg::encode("head pose", m)?;
        let key = self.keys.head(&m.camera);
        self.session
            .put(key.clone(), bytes)
            .priority(Priority::InteractiveHigh)
            .express(true)
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(|e| zerr(&key, e))
    }

    /// Receives the erased video of `camera` alone from now on (at first every camera's):
    /// a robot site serving several cameras then sends this site only the one it shows.
    /// Errors when Zenoh refuses the subscription, with the key named.
    pub fn view_camera(&mut self, camera: &str) -> Result<(), NetError> {
        // The new subscriber first: no frame of `camera` is missed between the two.
        self.frames = subscriber(&self.session, self.keys.erased(camera))?;
        Ok(())
    }

    /// Asks the robot site for an H.264 IDR frame of `camera` (after a loss, or on joining
    /// mid-stream); returns at once, the reply is not awaited.
    pub fn request_keyframe(&self, camera: &str) -> Result<(), NetError> {
        let key = self.keys.keyframe(camera);
        // Dropped, never blocking, when the link is congested: the viewer asks again.
        self.session
            .get(&key)
            .callback(|_| {})
            .congestion_control(CongestionControl::Drop)
            .timeout(Duration::from_secs(1))
            .wait()
            .map_err(|e| zerr(&key, e))
    }

    /// Publishes raw bytes on the target key: for tests of the robot site's checks (a
    /// malformed or foreign message must stop the arm, not move it).
    pub fn publish_raw_target(&self, bytes: Vec<u8>) -> Result<(), NetError> {
        self.target
            .put(bytes)
            .wait()
            .map_err(|e| zerr(&self.keys.target(), e))
    }

    /// Everything received since the last poll.
    pub fn poll(&mut self) -> OperatorInbox {
        let now = self.robot_now_s();
        OperatorInbox {
            joint_states: drain(&self.joint_states)
                .iter()
                .map(|s| msg::decode_joint_states(&s.payload().to_bytes()))
                .collect(),
            status: drain(&self.status)
                .iter()
                .map(|s| msg::decode_status(&s.payload().to_bytes()))
                .collect(),
            frames: drain(&self.frames)
                .iter()
                .map(|s| {
                    let payload = s.payload().to_bytes().into_owned();
                    let header = s
                        .attachment()
                        .map(|a| a.to_bytes().into_owned())
                        .ok_or_else(|| NetError::Invalid {
                            what: "frame".into(),
                            message: "no header attached".into(),
                        })?;
                    let header = msg::decode_frame_header(&header, payload.len())?;
                    // The header names the camera of the key it came on, no other.
                    if s.key_expr().as_str() != self.keys.erased(&header.camera) {
                        return Err(NetError::Invalid {
                            what: "frame".into(),
                            message: format!(
                                "camera '{}' in its header, on key '{}'",
                                header.camera,
                                s.key_expr()
                            ),
                        });
                    }
                    Ok(ReceivedFrame {
                        header,
                        payload,
                        received_s: now,
                    })
                })
                .collect(),
            hands: drain(&self.hands)
                .iter()
                .map(|s| msg::decode_hand(&s.payload().to_bytes()))
                .collect(),
        }
    }

    /// Leaves the session (the robot site sees the operator's token go).
    pub fn close(self) {
        self.refresh
            .stop
            .store(true, std::sync::atomic::Ordering::Relaxed);
        let _ = self.session.close().wait();
    }
}

impl Drop for OperatorSite {
    fn drop(&mut self) {
        self.refresh
            .stop
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// The operator's view of the robot site's clock: the offset's estimate, and the robot
/// site's restarts, seen as jumps of its clock (a restarted robot site starts its clock from
/// zero).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotClock {
    /// The newest estimate in use.
    pub sample: ClockSample,
    /// Jumps of the robot site's clock back by more than [`RESTART_JUMP_S`] (plus the round
    /// trip): restarts of the robot site.
    pub restarts: u64,
    /// The last jump (s, new offset minus the old).
    pub last_jump_s: f64,
}

/// An offset that moves by more than this (s, beyond the estimate's round trip) is the robot
/// site's clock started again: taken at once, whatever its round trip, and counted.
pub const RESTART_JUMP_S: f64 = 1.0;

/// The refresher's flags: `stop` ends it, `soon` makes it estimate at its next look.
#[derive(Clone, Default)]
struct Refresh {
    stop: Arc<std::sync::atomic::AtomicBool>,
    soon: Arc<std::sync::atomic::AtomicBool>,
}

/// How often the operator re-estimates the robot site's clock (clocks drift, paths change).
pub const OFFSET_REFRESH: Duration = Duration::from_secs(5);

/// Re-estimates the offset every [`OFFSET_REFRESH`] (or at once when asked to) until told
/// to stop.
fn refresher(
    session: &Session,
    keys: &Keys,
    local: SiteClock,
    offset: Arc<std::sync::Mutex<RobotClock>>,
) -> Refresh {
    let flags = Refresh::default();
    let (session, keys, f) = (session.clone(), keys.clone(), flags.clone());
    let _ = std::thread::Builder::new()
        .name("clock offset".into())
        .spawn(move || {
            let mut last = Instant::now();
            while !f.stop.load(std::sync::atomic::Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(100));
                let soon = f.soon.swap(false, std::sync::atomic::Ordering::Relaxed);
                if last.elapsed() < OFFSET_REFRESH && !soon {
                    continue;
                }
                last = Instant::now();
                match estimate_offset(&session, &keys, &local, 5) {
                    Ok(o) => offset.lock().unwrap_or_else(|e| e.into_inner()).take(o),
                    // Asked for at once (the robot site heard again) and not had: asked again
                    // at the next look, not a whole refresh later.
                    Err(_) if soon => f.soon.store(true, std::sync::atomic::Ordering::Relaxed),
                    Err(_) => {}
                }
            }
        });
    flags
}

impl RobotClock {
    /// Takes a new estimate: at once when the robot site's clock jumped, counted as a restart
    /// when it jumped back (a restarted robot site starts its clock from zero; a jump forward
    /// is this machine's clock stopped, e.g. suspended); else only when its round trip is close
    /// to the one in use (a worse round trip gives a worse estimate: its queueing is one-sided).
    fn take(&mut self, o: ClockSample) {
        let jump = o.offset_s - self.sample.offset_s;
        if jump.abs() > RESTART_JUMP_S + o.rtt_s {
            if jump < 0.0 {
                self.restarts += 1;
            }
            self.last_jump_s = jump;
            self.sample = o;
        } else if o.rtt_s <= self.sample.rtt_s * 1.5 + 0.002 {
            self.sample = o;
        }
    }
}

/// The first reply's payload to a query on `key`, or `None` within `timeout`.
fn query(session: &Session, key: &str, timeout: Duration) -> Option<Vec<u8>> {
    let replies = session.get(key).timeout(timeout).wait().ok()?;
    while let Ok(reply) = replies.recv() {
        if let Ok(sample) = reply.result() {
            return Some(sample.payload().to_bytes().into_owned());
        }
    }
    None
}

fn estimate_offset(
    session: &Session,
    keys: &Keys,
    local: &SiteClock,
    samples: usize,
) -> Result<ClockSample, NetError> {
    let mut best: Option<ClockSample> = None;
    for _ in 0..samples {
        let sent = local.now_s();
        let Some(bytes) = query(session, &keys.clock(), Duration::from_secs(2)) else {
            continue;
        };
        let received = local.now_s();
        let Ok(reply) = serde_json::from_slice::<ClockReply>(&bytes) else {
            continue;
        };
        if reply.v != PROTOCOL_VERSION || !reply.now_s.is_finite() {
            continue;
        }
        let rtt_s = received - sent;
        let estimate = ClockSample {
            offset_s: reply.now_s - (sent + received) / 2.0,
            rtt_s,
        };
        if best.is_none_or(|b| rtt_s < b.rtt_s) {
            best = Some(estimate);
        }
    }
    best.ok_or_else(|| NetError::NoRobotSite {
        key: keys.clock(),
        waited_s: 2.0 * samples as f64,
    })
}

/// A Zenoh router (`avatarm router`): routes between sites and fans streams out; closes when
/// dropped.
pub struct Router {
    _session: Session,
}

impl Router {
    /// Opens the router's session (its configuration's role must be [`crate::Role::Router`]).
    pub fn open(config: &NetConfig) -> Result<Self, NetError> {
        if config.role != crate::Role::Router {
            return Err(NetError::Config {
                what: "role".into(),
                message: "a router's configuration is needed".into(),
            });
        }
        Ok(Self {
            _session: open(config)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(offset_s: f64, rtt_s: f64) -> ClockSample {
        ClockSample { offset_s, rtt_s }
    }

    #[test]
    fn a_restarted_robot_site_s_clock_is_taken_at_once_and_counted() {
        let mut clock = RobotClock {
            sample: sample(120.0, 0.001),
            restarts: 0,
            last_jump_s: 0.0,
        };
        // Drift with a round trip as good: taken.
        clock.take(sample(120.002, 0.0012));
        assert_eq!((clock.sample.offset_s, clock.restarts), (120.002, 0));
        // A slow round trip: its estimate is worse, kept out.
        clock.take(sample(120.3, 0.4));
        assert_eq!(clock.sample.offset_s, 120.002);
        // A jump no round trip explains (the robot site started its clock again 19 s ago),
        // however slow the reply: taken and counted.
        clock.take(sample(-19.0, 0.05));
        assert_eq!((clock.sample.offset_s, clock.restarts), (-19.0, 1));
        assert!((clock.last_jump_s + 139.002).abs() < 1e-9);
        // A reply delayed by 3 s may be off by 1.5 s: not taken for a restart.
        clock.take(sample(-17.8, 3.0));
        assert_eq!((clock.sample.offset_s, clock.restarts), (-19.0, 1));
        // A jump forward (this machine suspended for 60 s): taken, not a restart.
        clock.take(sample(41.0, 0.001));
        assert_eq!((clock.sample.offset_s, clock.restarts), (41.0, 1));
    }
}
