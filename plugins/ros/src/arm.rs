//! The robot arm over ROS 1 or ROS 2 ([`RosArm`]) behind the core's [`RobotInterface`]: the
//! commands' safety checks and the link's state.

use std::collections::VecDeque;
use std::sync::mpsc::{Receiver, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use avatarm_core::sim::JointState;
use avatarm_core::sim::arm::{RobotError, RobotInterface};
use avatarm_core::teleop::mapping::GripperCommand;
use nalgebra::DVector;

use crate::client::{Outbound, Sample, Shared, client_thread};
use crate::clock::ClockOffset;
use crate::settings::{CommandKind, LinkSettings};
use crate::status::LinkStatus;

/// A robot arm over ROS 1 or ROS 2 ([`RobotInterface`]): joint states in, joint velocities out.
pub struct RosArm {
    name: String,
    settings: LinkSettings,
    /// The model's movable joints (q order).
    joints: Vec<String>,
    /// For each arm joint (settings order), its index in q.
    arm: Vec<usize>,
    shared: Arc<Mutex<Shared>>,
    notify: Arc<tokio::sync::Notify>,
    rx: Mutex<Receiver<Sample>>,
    last_q: DVector<f64>,
    clock: ClockOffset,
    /// App clock minus the wall clock (s since `epoch`), averaged over `advance` calls: the
    /// app's fixed-step clock moves in bursts, so one call's pairing would put an arrival up
    /// to a frame early, and the minimum filter would keep that error.
    app_minus_wall: Option<f64>,
    epoch: Instant,
    /// The system clock at `epoch` (s since the Unix epoch).
    epoch_unix_s: f64,
    /// The same estimate as `clock` on the system clock (arrival times as Unix time).
    system_clock: ClockOffset,
    /// Arrivals of the joint states of the last second.
    arrivals: VecDeque<Instant>,
    /// For each value of a command, its index in q (the arm's joints, or the controller's).
    command_index: Vec<usize>,
    /// A non-zero command went out since the last stop.
    moving: bool,
    last_state: Option<Instant>,
    lost_said: bool,
    /// The gripper command last handed over, and the connection it went out on.
    gripper_sent: Option<(bool, u64)>,
    /// A position controller's targets (command order) and when they were last advanced;
    /// `None` after a stop (the next command starts from the measured positions).
    position_target: Option<(Vec<f64>, Instant)>,
}

/// Errors of the link's set-up.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// A setting that cannot work.
    #[error("ROS link: {0}")]
    Settings(String),
    /// An arm joint the robot model lacks.
    #[error(
        "ROS link: the arm joint '{joint}' is not a movable joint of the robot model ({known})"
    )]
    UnknownJoint {
        /// The joint.
        joint: String,
        /// The model's joints.
        known: String,
    },
    /// The client thread could not start.
    #[error("ROS link: cannot start the client thread: {0}")]
    Thread(std::io::Error),
}

impl RosArm {
    /// Starts the link: a client thread that connects to the master (retrying every second),
    /// subscribes to the joint states (and the robot state), sets the robot's command timeout
    /// and speed ratio, and publishes the commands [`RobotInterface::send`] hands it.
    /// `joints` are the robot model's movable joints in q order and `q0` their values until
    /// the first joint state (joints a state does not name keep their last value). Errors
    /// name a setting that cannot work or an arm joint the model lacks.
    pub fn start(
        settings: LinkSettings,
        joints: Vec<String>,
        q0: DVector<f64>,
    ) -> Result<Self, LinkError> {
        settings.check().map_err(LinkError::Settings)?;
        if q0.len() != joints.len() {
            return Err(LinkError::Settings(format!(
                "{} start values for {} joints",
                q0.len(),
                joints.len()
            )));
        }
        // Each named joint's index in the model's q order.
        let indices = |names: &[String]| {
            names
                .iter()
                .map(|j| {
                    joints
                        .iter()
                        .position(|k| k == j)
                        .ok_or_else(|| LinkError::UnknownJoint {
                            joint: j.clone(),
                            known: joints.join(", "),
                        })
                })
                .collect::<Result<Vec<_>, _>>()
        };
        let arm = indices(&settings.arm_joints)?;
        let command_index = match &settings.command {
            CommandKind::InteraVelocity => arm.clone(),
            CommandKind::GroupVelocity { joints: controller }
            | CommandKind::GroupPosition { joints: controller }
            | CommandKind::JointTrajectory {
                joints: controller, ..
            } => indices(controller)?,
        };
        let shared = Arc::new(Mutex::new(Shared {
            // A ROS 2 link says so (and on what) from the start, before its thread runs.
            status: LinkStatus {
                ros2: settings.ros2.as_ref().map(crate::Ros2Transport::describe),
                ..LinkStatus::default()
            },
            outbound: None,
            gripper: None,
            shutdown: false,
            finished: false,
        }));
        let notify = Arc::new(tokio::sync::Notify::new());
        let (tx, rx) = channel();
        {
            let (settings, shared, notify) = (settings.clone(), shared.clone(), notify.clone());
            let thread = std::thread::Builder::new().name("avatarm-ros".into());
            match settings.ros2.clone() {
                None => thread.spawn(move || client_thread(settings, shared, notify, tx)),
                #[cfg(feature = "ros2")]
                Some(transport) => thread.spawn(move || {
                    crate::ros2::client_thread(settings, transport, shared, notify, tx);
                }),
                #[cfg(not(feature = "ros2"))]
                Some(_) => {
                    return Err(LinkError::Settings(
                        "this build has no ROS 2 (the avatarm_ros feature `ros2`)".into(),
                    ));
                }
            }
            .map_err(LinkError::Thread)?;
        }
        Ok(Self {
            name: settings.link_name(),
            settings,
            joints,
            arm,
            shared,
            notify,
            rx: Mutex::new(rx),
            last_q: q0,
            clock: ClockOffset::new(200),
            app_minus_wall: None,
            epoch: Instant::now(),
            epoch_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
            arrivals: VecDeque::new(),
            system_clock: ClockOffset::new(200),
            command_index,
            moving: false,
            last_state: None,
            lost_said: false,
            gripper_sent: None,
            position_target: None,
        })
    }

    /// What the link has measured so far.
    pub fn status(&self) -> LinkStatus {
        let mut s = self
            .shared
            .lock()
            .map(|s| s.status.clone())
            .unwrap_or_default();
        s.clock_offset_s = self.clock.offset_s().zip(self.clock.jitter_s());
        s.robot_minus_local_s = self
            .system_clock
            .offset_s()
            .zip(self.system_clock.jitter_s())
            .map(|(offset, jitter)| (-offset, jitter));
        s.joint_state_rate_hz = match (self.alive(), self.arrivals.front(), self.arrivals.back()) {
            (true, Some(first), Some(last)) if self.arrivals.len() > 1 => {
                let span = last.saturating_duration_since(*first).as_secs_f64();
                Some((self.arrivals.len() - 1) as f64 / span.max(1e-3))
            }
            _ => None,
        };
        s
    }

    /// The link is alive: a joint state arrived within `stale_after_s`.
    pub fn alive(&self) -> bool {
        self.last_state
            .is_some_and(|t| t.elapsed().as_secs_f64() <= self.settings.stale_after_s)
    }

    fn refuse(&mut self, why: String) -> RobotError {
        if let Ok(mut s) = self.shared.lock() {
            s.status.commands_refused += 1;
            // Nothing accepted before the refusal goes out after it.
            if matches!(s.outbound, Some(Outbound::Joints { .. })) {
                s.outbound = None;
            }
        }
        self.stop();
        RobotError {
            robot: self.name.clone(),
            message: why,
        }
    }

    fn app_time(&self, at: Instant) -> Option<f64> {
        let wall = at.saturating_duration_since(self.epoch).as_secs_f64();
        Some(wall + self.app_minus_wall?)
    }

    fn hand_over(&self, out: Outbound) {
        if let Ok(mut s) = self.shared.lock() {
            match out {
                Outbound::Gripper { position_m } => s.gripper = Some(position_m),
                joints => {
                    s.outbound = Some(joints);
                    s.status.commands_sent += 1;
                }
            }
        }
        self.notify.notify_one();
    }

    /// After a non-zero command, zero velocities once: a ros_control velocity controller keeps
    /// its last command for ever, and Intera's own timeout only acts later.
    fn stop(&mut self) {
        if self.moving {
            self.moving = false;
            // A velocity controller: zeros. A position controller: the last target, held. A
            // trajectory controller: where the arm is (its points are anchored there).
            let hold = match (&self.settings.command, self.position_target.take()) {
                (CommandKind::GroupPosition { .. }, Some((target, _))) => target,
                (CommandKind::GroupPosition { .. } | CommandKind::JointTrajectory { .. }, _) => {
                    self.measured_command()
                }
                _ => vec![0.0; self.command_index.len()],
            };
            self.hand_over(Outbound::Stop(hold));
        }
    }

    /// The measured positions of the commanded joints, in command order.
    fn measured_command(&self) -> Vec<f64> {
        self.command_index.iter().map(|&i| self.last_q[i]).collect()
    }

    /// Checks that a command may leave: the link alive and the robot enabled and running.
    fn may_command(&mut self) -> Result<(), RobotError> {
        if !self.alive() {
            return Err(self.refuse(format!(
                "no joint state for more than {} s: the link is down",
                self.settings.stale_after_s
            )));
        }
        if self.settings.robot_state_topic.is_some() {
            match self.shared.lock().ok().and_then(|s| s.status.robot) {
                None => return Err(self.refuse("no robot state received yet".into())),
                Some(r) if !r.enabled => {
                    return Err(self.refuse("the robot is not enabled".into()));
                }
                Some(r) if r.stopped => {
                    return Err(self.refuse(format!(
                        "the robot is stopped (e-stop source {})",
                        r.estop_source
                    )));
                }
                Some(_) => {}
            }
        }
        Ok(())
    }
}

impl Drop for RosArm {
    /// Tells the client thread to leave (it does within a second, unregistering the node).
    /// When the arm was moving, waits (at most 0.6 s) for the stop to go out, so that an app
    /// that exits next does not leave a ros_control velocity controller running its last
    /// command; otherwise not waited for, so a master that does not answer never holds up
    /// the app.
    fn drop(&mut self) {
        let moving = self.moving;
        self.stop();
        if let Ok(mut s) = self.shared.lock() {
            s.shutdown = true;
        }
        self.notify.notify_one();
        if moving && self.alive() {
            let until = Instant::now() + Duration::from_millis(600);
            while Instant::now() < until && !self.shared.lock().map_or(true, |s| s.finished) {
                std::thread::sleep(Duration::from_millis(10));
            }
        }
    }
}

impl RobotInterface for RosArm {
    fn name(&self) -> &str {
        &self.name
    }

    fn receive(&mut self) -> Vec<JointState> {
        let mut out = Vec::new();
        let samples: Vec<Sample> = match self.rx.lock() {
            Ok(rx) => std::iter::from_fn(|| rx.try_recv().ok()).collect(),
            Err(_) => Vec::new(),
        };
        for s in samples {
            match self.joint_state(&s) {
                Ok(js) => out.push(js),
                Err(why) => {
                    if let Ok(mut sh) = self.shared.lock() {
                        sh.status.bad_joint_states += 1;
                        sh.status.last_bad = Some(why);
                    }
                }
            }
        }
        out
    }

    fn send(&mut self, qdot: &DVector<f64>) -> Result<(), RobotError> {
        if qdot.len() != self.joints.len() {
            return Err(self.refuse(format!(
                "{} joint velocities for {} joints",
                qdot.len(),
                self.joints.len()
            )));
        }
        if let Some(i) = self.arm.iter().position(|&i| !qdot[i].is_finite()) {
            return Err(self.refuse(format!(
                "joint velocity of {} is {}",
                self.settings.arm_joints[i], qdot[self.arm[i]]
            )));
        }
        if self.last_state.is_none() && !self.moving && qdot.iter().all(|v| *v == 0.0) {
            // Before the first joint state nothing was commanded: a stop has nothing to stop
            // (a control loop that starts before the robot's stream does is not refused).
            return Ok(());
        }
        self.may_command()?;
        let mut values: Vec<f64> = self.command_index.iter().map(|&i| qdot[i]).collect();
        if let CommandKind::JointTrajectory {
            horizon_s, limits, ..
        } = &self.settings.command
        {
            // The point a horizon ahead of where the arm is, not of an integrated target: an
            // arm slowed (a scaled controller, a pendant's speed slider) or blocked is never
            // sent further than the horizon's motion, and the point stays within the joints'
            // limits.
            let measured = self.measured_command();
            for (k, (v, q)) in values.iter_mut().zip(measured).enumerate() {
                let point = q + *v * horizon_s;
                *v = limits
                    .get(k)
                    .map_or(point, |&(lower, upper)| point.clamp(lower, upper));
            }
            self.moving = true;
        } else if let CommandKind::GroupPosition { .. } = self.settings.command {
            // Velocities into position targets, from the measured positions after a stop.
            let now = Instant::now();
            let (mut target, dt) = match self.position_target.take() {
                Some((target, at)) => (
                    target,
                    now.saturating_duration_since(at)
                        .as_secs_f64()
                        .min(self.settings.stale_after_s),
                ),
                None => (self.measured_command(), 0.0),
            };
            for (t, v) in target.iter_mut().zip(&values) {
                *t += v * dt;
            }
            self.position_target = Some((target.clone(), now));
            self.moving = true;
            values = target;
        } else {
            self.moving = values.iter().any(|v| *v != 0.0);
        }
        self.hand_over(Outbound::Joints {
            values,
            at: Instant::now(),
        });
        Ok(())
    }

    fn gripper(&mut self, command: &GripperCommand) -> Result<(), RobotError> {
        if !command.force_n.is_finite() {
            return Err(self.refuse(format!("gripper force {} is not finite", command.force_n)));
        }
        if self.settings.gripper.is_none() {
            return Ok(());
        }
        self.may_command()?;
        // Sent when it changes (and again on a new connection), not every tick: the gripper
        // takes a position, not a stream.
        let connection = self.shared.lock().map_or(0, |s| s.status.connects);
        if self.gripper_sent == Some((command.closed, connection)) {
            return Ok(());
        }
        self.gripper_sent = Some((command.closed, connection));
        // Intera's electric gripper: 0 (closed) to 0.041667 m (open).
        let position_m = if command.closed {
            0.0
        } else {
            SAWYER_GRIPPER_OPEN_M
        };
        self.hand_over(Outbound::Gripper { position_m });
        Ok(())
    }

    fn status_line(&self) -> Option<String> {
        Some(self.status().line())
    }

    fn advance(&mut self, now_s: f64) {
        let now = Instant::now();
        if now_s.is_finite() {
            let d = now_s - now.saturating_duration_since(self.epoch).as_secs_f64();
            self.app_minus_wall = Some(match self.app_minus_wall {
                // A jump (a paused or stepped app clock) is taken at once; jitter is averaged.
                Some(prev) if (d - prev).abs() < 0.1 => prev + 0.05 * (d - prev),
                _ => d,
            });
        }
        let alive = self.alive();
        if alive {
            self.lost_said = false;
        } else if self.last_state.is_some() && !self.lost_said {
            self.lost_said = true;
            self.stop();
            if let Ok(mut s) = self.shared.lock() {
                s.status.losses += 1;
            }
            eprintln!(
                "{}: no joint state for {} s: the link is down; commands stop until it is back",
                self.name, self.settings.stale_after_s
            );
        }
    }
}

/// The Sawyer electric gripper's widest opening (m), Intera's `position_m` range 0..0.041667.
pub const SAWYER_GRIPPER_OPEN_M: f64 = 0.041_667;

impl RosArm {
    /// One joint state in q order on Avatarm's clock; errors say what is wrong with it.
    fn joint_state(&mut self, s: &Sample) -> Result<JointState, String> {
        if s.position.len() != s.names.len()
            || !(s.velocity.is_empty() || s.velocity.len() == s.names.len())
        {
            return Err(format!(
                "{} names, {} positions, {} velocities",
                s.names.len(),
                s.position.len(),
                s.velocity.len()
            ));
        }
        let mut q = self.last_q.clone();
        let mut qd = DVector::zeros(self.joints.len());
        for (k, name) in s.names.iter().enumerate() {
            if let Some(i) = self.joints.iter().position(|j| j == name) {
                let p = s.position[k];
                if !p.is_finite() {
                    return Err(format!("joint '{name}': position {p}"));
                }
                q[i] = p;
                // A velocity the robot does not measure is NaN (ros2_control's
                // joint_state_broadcaster for hardware without a velocity interface): unknown,
                // taken as 0; the positions are what the link needs.
                qd[i] = s
                    .velocity
                    .get(k)
                    .copied()
                    .filter(|v| v.is_finite())
                    .unwrap_or(0.0);
            }
        }
        if let Some(j) = self
            .settings
            .arm_joints
            .iter()
            .find(|j| !s.names.contains(j))
        {
            return Err(format!("no arm joint '{j}' in the joint state"));
        }
        self.last_state = Some(s.arrival);
        if s.stamp_s > 0.0 {
            let unix = self.epoch_unix_s
                + s.arrival
                    .saturating_duration_since(self.epoch)
                    .as_secs_f64();
            self.system_clock.add(unix, s.stamp_s);
        }
        self.arrivals.push_back(s.arrival);
        while self
            .arrivals
            .front()
            .is_some_and(|t| s.arrival.saturating_duration_since(*t) > Duration::from_secs(1))
        {
            self.arrivals.pop_front();
        }
        // Before the first `advance` there is no app clock to map onto: the arrival is all
        // there is. A zero stamp (a driver that does not stamp) is taken as the arrival.
        let stamp_s = match self.app_time(s.arrival) {
            Some(arrival) if s.stamp_s > 0.0 => {
                self.clock.add(arrival, s.stamp_s);
                self.clock.to_app(s.stamp_s).unwrap_or(arrival)
            }
            Some(arrival) => arrival,
            None => s.stamp_s,
        };
        self.last_q = q.clone();
        Ok(JointState {
            stamp_s,
            positions: q,
            velocities: qd,
        })
    }
}
