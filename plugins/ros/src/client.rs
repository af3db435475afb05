//! The ROS 1 client on its own thread and async runtime: one session with the master at a time, its
//! subscriptions and publishers, reconnecting by itself.

use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::msgs::{intera_core_msgs, sensor_msgs, std_msgs};
use crate::settings::{CommandKind, GripperLink, LinkSettings};
use crate::status::{GripperState, LinkStatus, RobotState};

/// What waits to go out to the robot (the newest replaces the one before).
pub(crate) enum Outbound {
    /// Joint velocities handed over at `at`; the client drops them once older than the
    /// link's command age (a command never goes out late).
    Joints {
        values: Vec<f64>,
        at: Instant,
    },
    /// Zero velocities: always sent (the stop Avatarm's watchdog sends first).
    Stop(Vec<f64>),
    Gripper {
        position_m: f64,
    },
}

/// What the link's caller and its client thread share: the status, the next command, the
/// shutdown.
pub(crate) struct Shared {
    pub(crate) status: LinkStatus,
    pub(crate) outbound: Option<Outbound>,
    pub(crate) gripper: Option<f64>,
    pub(crate) shutdown: bool,
    /// The client published its last commands after `shutdown` and left.
    pub(crate) finished: bool,
}

/// A joint state as the client received it, with its arrival time.
pub(crate) struct Sample {
    pub(crate) arrival: Instant,
    pub(crate) stamp_s: f64,
    pub(crate) names: Vec<String>,
    pub(crate) position: Vec<f64>,
    pub(crate) velocity: Vec<f64>,
}

fn ros_time_s(t: &roslibrust::codegen::integral_types::Time) -> f64 {
    f64::from(t.secs) + f64::from(t.nsecs) * 1e-9
}

fn now_time() -> roslibrust::codegen::integral_types::Time {
    std::time::SystemTime::now().try_into().unwrap_or_default()
}

/// The gripper device's command publisher and state subscription.
struct GripperIo {
    command: roslibrust::ros1::Publisher<intera_core_msgs::IOComponentCommand>,
    state: roslibrust::ros1::Subscriber<intera_core_msgs::IODeviceStatus>,
}

impl GripperIo {
    async fn open(
        nh: &roslibrust::ros1::NodeHandle,
        io_node: &str,
        device: &str,
        shared: &Arc<Mutex<Shared>>,
    ) -> Result<Self, String> {
        let base = format!("{}/{device}", io_node.trim_end_matches('/'));
        let (command_topic, state_topic) = (format!("{base}/command"), format!("{base}/state"));
        // Latched: a command published before the device's node has connected to this new
        // publisher (a device found from the config) still reaches it, and so does the newest
        // command after the gripper's node restarts.
        let command = nh
            .advertise(&command_topic, 1, true)
            .await
            .map_err(|e| format!("{command_topic}: {e}"))?;
        let state = nh
            .subscribe(&state_topic, 1)
            .await
            .map_err(|e| format!("{state_topic}: {e}"))?;
        if let Ok(mut s) = shared.lock() {
            s.status.gripper = Some(GripperState {
                device: device.to_owned(),
                ..GripperState::default()
            });
        }
        Ok(Self { command, state })
    }
}

/// Aborts a task when dropped (a session's helper tasks end with it).
struct AbortOnDrop(tokio::task::JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// The threads of a link's runtime.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Threads {
    /// The link's thread alone (ROS 1).
    One,
    /// The link's thread and one worker: Zenoh's blocking calls (opening a session, declaring
    /// an entity) need a multi-threaded runtime around them (ROS 2, on either middleware).
    #[cfg(feature = "ros2")]
    WithWorker,
}

/// The link thread's runtime; `None` (said, naming `link`) where it cannot start.
pub(crate) fn link_runtime(link: &str, threads: Threads) -> Option<tokio::runtime::Runtime> {
    let mut builder = match threads {
        Threads::One => tokio::runtime::Builder::new_current_thread(),
        #[cfg(feature = "ros2")]
        Threads::WithWorker => {
            let mut b = tokio::runtime::Builder::new_multi_thread();
            b.worker_threads(1);
            b
        }
    };
    builder
        .enable_all()
        .build()
        .map_err(|e| eprintln!("{link}: cannot start its runtime: {e}"))
        .ok()
}

/// The client thread: a single-threaded runtime that keeps the node connected.
pub(crate) fn client_thread(
    settings: LinkSettings,
    shared: Arc<Mutex<Shared>>,
    notify: Arc<tokio::sync::Notify>,
    tx: Sender<Sample>,
) {
    let Some(runtime) = link_runtime("ROS link", Threads::One) else {
        return;
    };
    runtime.block_on(async move {
        let mut said = false;
        loop {
            if shared.lock().map_or(true, |s| s.shutdown) {
                return;
            }
            match session(&settings, &shared, &notify, &tx).await {
                Ok(()) => return,
                Err(e) => {
                    if let Ok(mut s) = shared.lock() {
                        s.status.connected = false;
                    }
                    if !said {
                        eprintln!(
                            "ROS link: {e}; retrying every second (master {})",
                            settings.master_uri
                        );
                        said = true;
                    }
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
    });
}

/// The publishers and subscriptions of one session with the master.
struct Topics {
    states: Ros1Subscriber<sensor_msgs::JointState>,
    robot: Option<Ros1Subscriber<intera_core_msgs::RobotAssemblyState>>,
    intera: Option<Ros1Publisher<intera_core_msgs::JointCommand>>,
    group: Option<Ros1Publisher<std_msgs::Float64MultiArray>>,
    /// The IO node's configuration, until it names the gripper's device.
    gripper_config: Option<Ros1Subscriber<intera_core_msgs::IONodeConfiguration>>,
    gripper: Option<GripperIo>,
    /// Latched settings, kept advertised while the session lasts: the robot's joint-state rate,
    /// its command timeout and speed ratio.
    _rate: Option<Ros1Publisher<std_msgs::UInt16>>,
    _latched: Vec<Ros1Publisher<std_msgs::Float64>>,
}

type Ros1Subscriber<T> = roslibrust::ros1::Subscriber<T>;
type Ros1Publisher<T> = roslibrust::ros1::Publisher<T>;

/// `what: e`, for a topic's error.
fn topic_error(what: &str, e: &dyn std::fmt::Display) -> String {
    format!("{what}: {e}")
}

impl Topics {
    /// Subscribes and advertises what `settings` name, and publishes the latched settings.
    async fn open(
        nh: &roslibrust::ros1::NodeHandle,
        settings: &LinkSettings,
        shared: &Arc<Mutex<Shared>>,
    ) -> Result<Self, String> {
        let err = topic_error;
        let states = nh
            .subscribe::<sensor_msgs::JointState>(&settings.joint_states_topic, 10)
            .await
            .map_err(|e| err(&settings.joint_states_topic, &e))?;
        let robot = match &settings.robot_state_topic {
            Some(t) => Some(
                nh.subscribe::<intera_core_msgs::RobotAssemblyState>(t, 2)
                    .await
                    .map_err(|e| err(t, &e))?,
            ),
            None => None,
        };
        let intera = match (&settings.command, &settings.command_topic) {
            (CommandKind::InteraVelocity, t) => Some(
                nh.advertise::<intera_core_msgs::JointCommand>(t, 1, false)
                    .await
                    .map_err(|e| err(t, &e))?,
            ),
            _ => None,
        };
        let group = match (&settings.command, &settings.command_topic) {
            (CommandKind::GroupVelocity { .. } | CommandKind::GroupPosition { .. }, t) => Some(
                nh.advertise::<std_msgs::Float64MultiArray>(t, 1, false)
                    .await
                    .map_err(|e| err(t, &e))?,
            ),
            _ => None,
        };
        // The gripper: the device the settings name, else the first one the IO node's (latched)
        // config names, opened when it arrives.
        let gripper_config = match &settings.gripper {
            Some(GripperLink {
                io_node,
                device: None,
            }) => {
                let t = format!("{io_node}/config");
                Some(
                    nh.subscribe::<intera_core_msgs::IONodeConfiguration>(&t, 1)
                        .await
                        .map_err(|e| err(&t, &e))?,
                )
            }
            _ => None,
        };
        let gripper = match &settings.gripper {
            Some(GripperLink {
                io_node,
                device: Some(d),
            }) => Some(GripperIo::open(nh, io_node, d, shared).await?),
            _ => None,
        };
        // The robot's joint-state rate (latched, so a robot node that starts later gets it).
        let rate = match &settings.joint_state_rate {
            Some((topic, hz)) => {
                let p = nh
                    .advertise::<std_msgs::UInt16>(topic, 1, true)
                    .await
                    .map_err(|e| err(topic, &e))?;
                p.publish(&std_msgs::UInt16 { data: *hz })
                    .await
                    .map_err(|e| err(topic, &e))?;
                Some(p)
            }
            None => None,
        };
        // Latched settings: the robot's command timeout and speed ratio.
        let mut latched = Vec::new();
        for (topic, value) in settings
            .command_timeout_topic
            .iter()
            .map(|t| (t, settings.command_timeout_s))
            .chain(settings.speed_ratio.iter().map(|(t, r)| (t, *r)))
        {
            let p = nh
                .advertise::<std_msgs::Float64>(topic, 1, true)
                .await
                .map_err(|e| err(topic, &e))?;
            p.publish(&std_msgs::Float64 { data: value })
                .await
                .map_err(|e| err(topic, &e))?;
            latched.push(p);
        }
        Ok(Self {
            states,
            robot,
            intera,
            group,
            gripper_config,
            gripper,
            _rate: rate,
            _latched: latched,
        })
    }

    /// Sends what waits in `shared`: the newest joint command (unless older than `max_age`, or
    /// a stop) and a gripper command once the device is known. Returns whether the link is
    /// shutting down (after giving the last command time to leave).
    async fn send_outbound(
        &self,
        settings: &LinkSettings,
        shared: &Arc<Mutex<Shared>>,
        max_age: Duration,
        seq: &mut u32,
    ) -> Result<bool, String> {
        let err = topic_error;
        let (out, grip, stop) = match shared.lock() {
            // A gripper command waits (the newest wins) until the device is known.
            Ok(mut s) => {
                let grip = if self.gripper.is_some() {
                    s.gripper.take()
                } else {
                    None
                };
                (s.outbound.take(), grip, s.shutdown)
            }
            Err(_) => (None, None, true),
        };
        let values = match out {
            Some(Outbound::Joints { values, at }) if at.elapsed() <= max_age => Some(values),
            Some(Outbound::Stop(values)) => Some(values),
            _ => None,
        };
        if let Some(values) = values {
            *seq = seq.wrapping_add(1);
            let header = std_msgs::Header {
                seq: *seq,
                stamp: now_time(),
                frame_id: String::new(),
            };
            if let Some(p) = &self.intera {
                let m = intera_core_msgs::JointCommand {
                    header,
                    mode: intera_core_msgs::JointCommand::VELOCITY_MODE,
                    names: settings.arm_joints.clone(),
                    velocity: values,
                    ..Default::default()
                };
                p.publish(&m)
                    .await
                    .map_err(|e| err(&settings.command_topic, &e))?;
            } else if let Some(p) = &self.group {
                let m = std_msgs::Float64MultiArray {
                    data: values,
                    ..Default::default()
                };
                p.publish(&m)
                    .await
                    .map_err(|e| err(&settings.command_topic, &e))?;
            }
        }
        if let (Some(position_m), Some(GripperIo { command: p, .. })) = (grip, &self.gripper) {
            let args = serde_json::json!({
                "signals": {
                    "position_m": { "data": [position_m], "format": { "type": "float" } }
                }
            });
            let m = intera_core_msgs::IOComponentCommand {
                time: now_time(),
                op: "set".into(),
                args: args.to_string(),
            };
            p.publish(&m).await.map_err(|e| err("gripper", &e))?;
        }
        if stop {
            // publish() only queues the message for the connections' writer tasks, which end
            // with the node: give them time to send the last command (the stop a ros_control
            // velocity controller would otherwise never get).
            tokio::time::sleep(Duration::from_millis(300)).await;
            if let Ok(mut s) = shared.lock() {
                s.finished = true;
            }
        }
        Ok(stop)
    }
}

/// Watches, once a second on its own task, whether the master still knows `node` as the
/// subscriber of `topic` (an unreachable master never holds up joint states or commands); a
/// restarted master has forgotten it, and the returned receiver then fires. The task ends with
/// the returned guard.
fn watch_master(
    master_uri: String,
    client_uri: String,
    topic: String,
    node: String,
) -> (tokio::sync::oneshot::Receiver<()>, AbortOnDrop) {
    use roslibrust::ros1::MasterClient;
    let (forgotten_tx, forgotten) = tokio::sync::oneshot::channel::<()>();
    let watch = tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        loop {
            tick.tick().await;
            let check = async {
                let master = MasterClient::new(&master_uri, &client_uri, &node)
                    .await
                    .ok()?;
                let state = master.get_system_state().await.ok()?;
                Some(state.is_subscribed(&topic, &node))
            };
            if let Ok(Some(false)) = tokio::time::timeout(Duration::from_secs(2), check).await {
                let _ = forgotten_tx.send(());
                return;
            }
        }
    });
    (forgotten, AbortOnDrop(watch))
}

/// The next message of an optional subscription (`None`: it closed; an error as text); never,
/// without one.
async fn next_of<T: roslibrust::RosMessageType>(
    subscription: Option<&mut Ros1Subscriber<T>>,
) -> Option<Result<T, String>> {
    match subscription {
        Some(s) => s.next().await.map(|r| r.map_err(|e| e.to_string())),
        None => std::future::pending().await,
    }
}

/// One connection to the master: runs until shutdown (Ok) or until the master forgets the
/// node or cannot be reached to connect (Err, the caller retries).
async fn session(
    settings: &LinkSettings,
    shared: &Arc<Mutex<Shared>>,
    notify: &Arc<tokio::sync::Notify>,
    tx: &Sender<Sample>,
) -> Result<(), String> {
    use roslibrust::ros1::NodeHandle;
    let nh = NodeHandle::new(&settings.master_uri, &settings.node_name)
        .await
        .map_err(|e| format!("cannot register with the master: {e}"))?;
    if let Ok(mut s) = shared.lock() {
        s.status.gripper = None;
    }
    let mut topics = Topics::open(&nh, settings, shared).await?;
    let client_uri = nh
        .get_client_uri()
        .await
        .map_err(|e| format!("no client URI: {e}"))?;
    let node = format!("/{}", settings.node_name.trim_start_matches('/'));
    if let Ok(mut s) = shared.lock() {
        s.status.connected = true;
        s.status.connects += 1;
        // A new connection starts from what this robot says now, and never sends a command
        // accepted before it.
        s.status.robot = None;
        s.outbound = None;
    }
    let (mut forgotten, _watch) = watch_master(
        settings.master_uri.clone(),
        client_uri,
        settings.joint_states_topic.clone(),
        node,
    );
    // A command older than this is not sent (the robot would already have timed it out, or the
    // link was down when it was made).
    let max_age = Duration::from_secs_f64(settings.stale_after_s.min(settings.command_timeout_s));
    let mut seq = 0u32;
    loop {
        tokio::select! {
            state = topics.states.next() => match state {
                Some(Ok(m)) => {
                    let sample = Sample {
                        arrival: Instant::now(),
                        stamp_s: ros_time_s(&m.header.stamp),
                        names: m.name,
                        position: m.position,
                        velocity: m.velocity,
                    };
                    if tx.send(sample).is_err() {
                        return Ok(());
                    }
                }
                Some(Err(e)) => {
                    if let Ok(mut s) = shared.lock() {
                        s.status.bad_joint_states += 1;
                        s.status.last_bad = Some(e.to_string());
                    }
                }
                None => return Err("the joint-state subscription closed".into()),
            },
            state = next_of(topics.robot.as_mut()) => {
                if let Some(Ok(m)) = state
                    && let Ok(mut s) = shared.lock()
                {
                    s.status.robot = Some(RobotState {
                        enabled: m.enabled,
                        stopped: m.stopped,
                        error: m.error,
                        estop_button: m.estop_button,
                        estop_source: m.estop_source,
                    });
                }
            },
            config = next_of(topics.gripper_config.as_mut()) => {
                match config {
                    Some(Ok(m)) => {
                        if let (Some(d), Some(g)) = (m.devices.first(), &settings.gripper) {
                            topics.gripper =
                                Some(GripperIo::open(&nh, &g.io_node, &d.name, shared).await?);
                            topics.gripper_config = None;
                            // A gripper command that waited for the device goes out now.
                            notify.notify_one();
                        }
                    }
                    Some(Err(_)) => {}
                    None => topics.gripper_config = None,
                }
            },
            state = next_of(topics.gripper.as_mut().map(|g| &mut g.state)) => {
                if let Some(Ok(m)) = state
                    && let Ok(mut s) = shared.lock()
                    && let Some(g) = s.status.gripper.as_mut()
                {
                    g.read(&m.signals);
                }
            },
            () = notify.notified() => {
                if topics.send_outbound(settings, shared, max_age, &mut seq).await? {
                    return Ok(());
                }
            },
            _ = &mut forgotten => {
                return Err("the master no longer knows this node (restarted?)".into());
            },
            () = tokio::time::sleep(Duration::from_secs(1)) => {
                if shared.lock().map_or(true, |s| s.shutdown) {
                    return Ok(());
                }
            },
        }
    }
}
