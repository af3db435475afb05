//! Avatarm's grasp-to-robot mapping as a Bevy plugin.
//!
//! Every physics step, after the hand's contacts are read ([`avatarm_hand::HandSystems`]):
//! joint states from the robot → [`Mapper::tick`] (grasp matrix, twin twist, scaling to the
//! real object, paper or closed-loop mode, damped least squares, gripper from σ) →
//! [`SafetyLimiter`] (always) → the robot through [`RobotInterface`]. A mapping error (bad
//! joint state, non-finite contact) becomes a non-finite command, which the limiter turns into
//! a ramped stop; the gripper keeps its state while the robot is being stopped, so a lost hand
//! does not drop the real object.
//!
//! Modules: [`pouring`], [`chess`], [`error`]. The robot-interface trait and the simulated arm are
//! Bevy-free, in [`avatarm_core::sim::arm`], so that a robot link (`avatarm_ros`) builds without
//! Bevy.
//!
//! [`pouring`] is the paper's experiment with the same [`Teleop`] (ticked after each physics
//! step of a headless hand world, as a two-site session's operator steps it): a scripted hand
//! grasps the bottle's twin, lifts, pours and raises it, and the simulated arm carries the real
//! bottle; the error between them is the paper's measure. [`chess`] is the paper's opening
//! scene: several pieces, pick and place, and the robot anticipating the piece the hand reaches
//! for (`avatarm_core::teleop::{intent, pick_place}`).

pub mod chess;
pub mod error;
pub mod pouring;
pub mod threaded;

use std::sync::Arc;

use avatarm_core::robot::kinematics::Frame;
use avatarm_core::robot::{LinkId, RobotModel};
use avatarm_core::sim::JointState;
use avatarm_core::sim::arm::RobotInterface;
use avatarm_core::teleop::grasp::Contact;
use avatarm_core::teleop::mapping::{
    Mapper, MappingSettings, OperatorInputs, OperatorTarget, RobotInputs, RobotSide, VirtualToReal,
};
use avatarm_core::teleop::safety::{self, Intervention, SafetyLimiter};
use avatarm_hand::{ActiveHand, GraspTarget, HandSystems, HeldObject, ObjectContacts};
use bevy::prelude::*;
use nalgebra::{DVector, Isometry3, Matrix6xX, Translation3, UnitQuaternion, Vector3};

pub use error::MappingError;

/// What most users of the mapping need.
pub mod prelude {
    pub use crate::pouring::{PouringTask, TrialParts, TrialSetup, run_trials};
    pub use crate::{Approach, MappingError, MappingPlugin, MappingSystems, Teleop, TeleopConfig};
    pub use avatarm_core::sim::arm::{RobotInterface, SimArm};
}

/// Adds the control tick. Needs the [`avatarm_hand::HandPlugin`] and a [`Teleop`] resource.
pub struct MappingPlugin;

impl Plugin for MappingPlugin {
    fn build(&self, app: &mut App) {
        app.configure_sets(
            FixedUpdate,
            MappingSystems::Tick.after(HandSystems::Contacts),
        )
        .add_systems(FixedUpdate, teleop_tick.in_set(MappingSystems::Tick));
    }
}

/// The mapping's system set (`FixedUpdate`), after the hand's contacts.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MappingSystems {
    /// The control tick (after the hand's contacts).
    Tick,
}

/// One control tick, as recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct TeleopSample {
    /// App time (s).
    pub t_s: f64,
    /// The real object's target: the twin mapped into the real world.
    pub target: Isometry3<f64>,
    /// The real object as the measured joint states place it (while the tool holds it).
    pub measured: Isometry3<f64>,
    /// The real object's true pose, where the robot backend knows it (simulation).
    pub truth: Option<Isometry3<f64>>,
    /// Gripper commanded closed.
    pub gripper_closed: bool,
    /// Commanded tool-point speed (m/s).
    pub tcp_speed: f64,
    /// Largest commanded joint speed (rad/s).
    pub max_joint_speed: f64,
    /// The limiter is stopping the robot.
    pub stopping: bool,
    /// Contacts on the twin.
    pub contacts: usize,
    /// Squeezing force σ (N).
    pub squeeze_n: f64,
    /// The twin's twist from the contacts (virtual scene, at the twin's origin).
    pub twin_twist: nalgebra::Vector6<f64>,
    /// The measured joint positions the tick used (NaN before the first joint state).
    pub q: DVector<f64>,
    /// The joint velocities sent (zero when nothing was sent).
    pub qdot: DVector<f64>,
    /// The tick's operator side, where it gave one (the hand's own here, or the operator's
    /// target as received; `None` while moving to the start, or when refused).
    pub operator: Option<OperatorTarget>,
}

impl TeleopSample {
    /// The real object: the truth where the backend knows it (simulation), else where the
    /// measured joint states put it; `None` before any joint state.
    pub fn real_object(&self) -> Option<Isometry3<f64>> {
        self.truth.or_else(|| {
            self.measured
                .translation
                .vector
                .iter()
                .all(|v| v.is_finite())
                .then_some(self.measured)
        })
    }
}

/// Counters for the status line and the report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TeleopStatus {
    /// Control ticks run.
    pub ticks: u64,
    /// Ticks the mapping refused (with the last reason).
    pub errors: u64,
    /// The last mapping or robot error.
    pub last_error: Option<String>,
    /// Joint states refused (wrong size, NaN).
    pub bad_joint_states: u64,
    /// Ticks on which each intervention of the limiter happened.
    pub interventions: Vec<(Intervention, u64)>,
    /// Largest commanded tool-point speed (m/s).
    pub max_tcp_speed: f64,
    /// Wall time spent in the control ticks (s): mapping, limiter, robot interface.
    pub tick_wall_s: f64,
    /// The arm is moving to the task's start ([`Teleop::approach`]): the hand does not drive
    /// it yet.
    pub approaching: bool,
    /// How long the move to the start took (s of app time), once arrived.
    pub approach_s: Option<f64>,
}

/// The move to the task's start before the hand drives the arm: a real robot starts wherever
/// it was left, and the mapping assumes the tool at the grasp's start.
///
/// A straight line in joint space, `q̇ = k (q* − q)` scaled down as a whole so that no arm
/// joint exceeds `speed_ratio` × its velocity limit (the meaning of Intera's speed ratio), sent
/// as joint velocities through the same [`SafetyLimiter`] as the hand's commands (tool-point
/// speed cap, acceleration ramp, stale joint states). Arrived when every arm joint is within
/// `tolerance_rad` of the start.
#[derive(Debug, Clone, PartialEq)]
pub struct Approach {
    /// The start, all joints in the model's order (only the arm joints are moved).
    pub target: DVector<f64>,
    /// Arrival tolerance per arm joint (rad).
    pub tolerance_rad: f64,
    /// The fraction of each joint's velocity limit used (0 < r <= 1).
    pub speed_ratio: f64,
    /// The gain `k` (1/s): how fast the last stretch closes.
    pub gain_per_s: f64,
}

impl Approach {
    /// To `target` at 30 % of the joints' speed limits (Intera's default speed ratio), within
    /// 0.01 rad.
    pub fn to(target: DVector<f64>) -> Self {
        Self {
            target,
            tolerance_rad: 0.01,
            speed_ratio: 0.3,
            gain_per_s: 2.0,
        }
    }

    /// Joint velocities toward the target from `q` (zero for joints not in `arm`), or `None`
    /// when every arm joint is within the tolerance. `limits` are the joints' speed limits
    /// (rad/s; a limit that is not finite and positive counts as 1 rad/s).
    pub fn velocity(
        &self,
        q: &DVector<f64>,
        arm: &[usize],
        limits: &[f64],
    ) -> Option<DVector<f64>> {
        let error = |i: usize| self.target[i] - q[i];
        if arm.iter().all(|&i| error(i).abs() <= self.tolerance_rad) {
            return None;
        }
        let mut qdot = DVector::zeros(q.len());
        let mut scale: f64 = 1.0;
        for &i in arm {
            let v = self.gain_per_s * error(i);
            let limit = limits
                .get(i)
                .copied()
                .filter(|l| l.is_finite() && *l > 0.0)
                .unwrap_or(1.0)
                * self.speed_ratio;
            if v.abs() > limit {
                scale = scale.min(limit / v.abs());
            }
            qdot[i] = v;
        }
        Some(qdot * scale)
    }

    fn validate(&self, n: usize) -> Result<(), MappingError> {
        let bad = |message: String| Err(MappingError::Setup { message });
        if self.target.len() != n || !self.target.iter().all(|v| v.is_finite()) {
            return bad(format!(
                "approach: the start has {} values ({n} joints), all must be finite",
                self.target.len()
            ));
        }
        if !(self.speed_ratio > 0.0 && self.speed_ratio <= 1.0) {
            return bad(format!(
                "approach: speed ratio {} must be in (0, 1]",
                self.speed_ratio
            ));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(self.tolerance_rad) && positive(self.gain_per_s)) {
            return bad(format!(
                "approach: tolerance {} rad and gain {} /s must be > 0",
                self.tolerance_rad, self.gain_per_s
            ));
        }
        Ok(())
    }
}

/// A move to the start under way: the move, when it started (app clock, s; at the first joint
/// state), and the joints' speed limits (rad/s, read once).
struct ApproachRun {
    approach: Approach,
    started_s: Option<f64>,
    speed_limits: Vec<f64>,
}

/// The teleoperation loop's state: the robot, the mapping and the limiter.
#[derive(Resource)]
pub struct Teleop {
    model: Arc<RobotModel>,
    base: Isometry3<f64>,
    tcp: LinkId,
    arm: Vec<usize>,
    tcp_from_object: Isometry3<f64>,
    v2r: VirtualToReal,
    mapper: Mapper,
    limiter: SafetyLimiter,
    robot: Box<dyn RobotInterface>,
    approach: Option<ApproachRun>,
    joints: Option<JointState>,
    received: Vec<JointState>,
    /// Counters.
    pub status: TeleopStatus,
    /// Record every tick into [`Teleop::log`].
    pub record: bool,
    /// The recorded ticks.
    pub log: Vec<TeleopSample>,
    /// The thread the robot side runs on ([`Teleop::on_control_thread`]); `None`: it runs in
    /// [`Teleop::tick`] itself.
    thread: Option<threaded::ControlThread>,
    /// Ticks refused on this side while a control thread drives the robot (the operator's side
    /// failed), and the last reason.
    front_errors: (u64, Option<String>),
    /// With a control thread: this tick is its update's last fixed step, when the thread's
    /// results are taken back (set by the plugin's system; `true` for direct callers).
    last_step: bool,
}

/// What the teleoperation loop is made of.
pub struct TeleopConfig {
    /// The robot.
    pub model: Arc<RobotModel>,
    /// Its root link in the real world.
    pub base: Isometry3<f64>,
    /// The tool link (between the gripper's fingers).
    pub tcp: LinkId,
    /// Arm joints the mapping drives (the others get zero velocity).
    pub arm: Vec<usize>,
    /// The real object in the tool frame while grasped.
    pub tcp_from_object: Isometry3<f64>,
    /// The virtual scene to the real one.
    pub v2r: VirtualToReal,
    /// The mapping.
    pub mapping: MappingSettings,
    /// The limiter.
    pub safety: safety::SafetySettings,
}

impl Teleop {
    /// The loop for `robot`. Errors when the settings are invalid.
    pub fn new(config: TeleopConfig, robot: impl RobotInterface) -> Result<Self, MappingError> {
        Self::with_robot(config, Box::new(robot))
    }

    /// [`Teleop::new`] for a robot chosen at run time (the simulated arm, a ROS link).
    pub fn with_robot(
        config: TeleopConfig,
        robot: Box<dyn RobotInterface>,
    ) -> Result<Self, MappingError> {
        config.safety.validate()?;
        let n = config.model.dof();
        if let Some(&bad) = config.arm.iter().find(|&&i| i >= n) {
            return Err(MappingError::Setup {
                message: format!("arm joint index {bad} out of range ({n} joints)"),
            });
        }
        let limits = config.model.dof_limits();
        Ok(Self {
            limiter: SafetyLimiter::new(config.safety, limits),
            mapper: Mapper::new(config.mapping),
            model: config.model,
            base: config.base,
            tcp: config.tcp,
            arm: config.arm,
            tcp_from_object: config.tcp_from_object,
            v2r: config.v2r,
            robot,
            approach: None,
            joints: None,
            received: Vec::new(),
            status: TeleopStatus::default(),
            record: false,
            log: Vec::new(),
            thread: None,
            front_errors: (0, None),
            last_step: true,
        })
    }

    /// Refuses to set `what` once the robot side runs on a thread ([`Teleop::on_control_thread`]):
    /// set it before.
    fn not_threaded(&self, what: &str) -> Result<(), MappingError> {
        match self.thread {
            Some(_) => Err(MappingError::Setup {
                message: format!("{what} is set before the robot side moves to its thread"),
            }),
            None => Ok(()),
        }
    }

    /// A loop with `other`'s model, mapping and limiter settings around `robot`, nothing run
    /// yet (the app's side of [`Teleop::on_control_thread`]).
    fn with_robot_parts(other: &Self, robot: Box<dyn RobotInterface>) -> Self {
        Self {
            model: other.model.clone(),
            base: other.base,
            tcp: other.tcp,
            arm: other.arm.clone(),
            tcp_from_object: other.tcp_from_object,
            v2r: other.v2r,
            mapper: other.mapper.clone(),
            limiter: other.limiter.clone(),
            robot,
            approach: None,
            joints: other.joints.clone(),
            received: Vec::new(),
            status: other.status.clone(),
            record: other.record,
            log: Vec::new(),
            thread: None,
            front_errors: (0, None),
            last_step: true,
        }
    }

    /// Moves the arm to `approach`'s start before the hand drives it ([`Approach`]); the hand
    /// takes over on the tick the arm arrives. Errors when the start or the settings cannot
    /// work.
    pub fn approach(&mut self, approach: Approach) -> Result<(), MappingError> {
        self.not_threaded("the move to the start")?;
        approach.validate(self.model.dof())?;
        self.approach = Some(ApproachRun {
            approach,
            started_s: None,
            speed_limits: self.model.dof_limits().iter().map(|l| l.velocity).collect(),
        });
        self.status.approaching = true;
        self.status.approach_s = None;
        Ok(())
    }

    /// Sets the limiter's watchdog: hand data (or a remote operator's targets) and joint states
    /// older than `timeout_s` stop the robot. The robot site of a two-site session sets it above
    /// the network's delay. Errors for a timeout that is not > 0.
    pub fn set_watchdog_timeout(&mut self, timeout_s: f64) -> Result<(), MappingError> {
        self.not_threaded("the watchdog's timeout")?;
        let settings = safety::SafetySettings {
            timeout_s,
            ..*self.limiter.settings()
        };
        settings.validate()?;
        self.limiter = SafetyLimiter::new(settings, self.model.dof_limits());
        Ok(())
    }

    /// The limiter's settings.
    pub fn safety(&self) -> &safety::SafetySettings {
        self.limiter.settings()
    }

    /// The robot backend's name.
    pub fn robot_name(&self) -> &str {
        self.robot.name()
    }

    /// The newest accepted joint state.
    pub fn joints(&self) -> Option<&JointState> {
        self.joints.as_ref()
    }

    /// The joint states accepted in the last tick, oldest first: what the app's twin of the
    /// robot should receive too.
    pub fn received(&self) -> &[JointState] {
        &self.received
    }

    /// The robot backend.
    pub fn robot(&self) -> &dyn RobotInterface {
        self.robot.as_ref()
    }

    /// The virtual scene to the real one.
    pub fn v2r(&self) -> &VirtualToReal {
        &self.v2r
    }

    /// The real object (its centre, real world): the truth where the backend knows it
    /// (simulation), else where the newest joint state puts the tool's grasp of it (right only
    /// while the tool holds it); `None` before a finite joint state.
    pub fn real_object(&self) -> Option<Isometry3<f64>> {
        if let Some(truth) = self.robot.true_object_pose() {
            return Some(truth);
        }
        self.object_at(&self.joints.as_ref()?.positions)
    }

    /// Where the tool holds the object (its centre, real world) at joint positions `q` (the
    /// robot's joint vector): the tool's forward kinematics times the grasp; `None` for a
    /// vector of another length or with a value that is not finite.
    pub fn object_at(&self, q: &DVector<f64>) -> Option<Isometry3<f64>> {
        if q.len() != self.model.dof() || q.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let q: Vec<f64> = q.iter().copied().collect();
        Some(self.model.forward_kinematics(&self.base, &q)[self.tcp] * self.tcp_from_object)
    }

    fn count(&mut self, what: Intervention) {
        match self
            .status
            .interventions
            .iter_mut()
            .find(|(i, _)| *i == what)
        {
            Some((_, n)) => *n += 1,
            None => self.status.interventions.push((what, 1)),
        }
    }

    fn fail(&mut self, message: String) {
        self.status.errors += 1;
        if self.status.errors % 100 == 1 {
            warn!(
                "mapping: {message} ({} refused ticks so far); stopping the robot",
                self.status.errors
            );
        }
        self.status.last_error = Some(message);
    }
}

fn teleop_tick(
    time: Res<Time<Fixed>>,
    contacts: Res<ObjectContacts>,
    hand: Option<Res<ActiveHand>>,
    held: Option<Res<HeldObject>>,
    twin: Query<&Transform, With<GraspTarget>>,
    teleop: Option<ResMut<Teleop>>,
    mut scratch: Local<(Vec<Contact>, Vec<Vector3<f64>>)>,
) {
    let Some(mut teleop) = teleop else { return };
    // The core's tick takes the contacts and their points' velocities as two slices; the
    // buffers keep their capacity from tick to tick.
    scratch.0.clear();
    scratch.1.clear();
    for c in &contacts.contacts {
        scratch.0.push(c.contact);
        scratch.1.push(c.object_velocity);
    }
    let (hand_stamp_s, hand_tracked) = match hand.as_ref().and_then(|h| h.latest.as_ref()) {
        Some(f) => (Some(f.t_s), f.tracked),
        None => (None, false),
    };
    // No further fixed step runs in this update once less than a step is left over.
    teleop.last_step = time.overstep() < time.timestep();
    let twin_pose = twin
        .single()
        .map(avatarm_twin::transform_to_iso)
        .map_err(|e| format!("the mapping needs exactly one object twin (GraspTarget): {e}"));
    teleop.tick(
        time.elapsed_secs_f64(),
        time.timestep().as_secs_f64(),
        TickSource::Local {
            contacts: &scratch.0,
            contact_velocities: &scratch.1,
            twin_pose,
            held: held.as_ref().is_some_and(|h| h.held.is_some()),
            hand_stamp_s,
            hand_tracked,
        },
    );
}

/// Where a control tick's operator side ([`Mapper::operator_side`]) comes from.
#[derive(Debug, Clone)]
pub enum TickSource<'a> {
    /// The hand and the twin in this process (`avatarm run`).
    Local {
        /// The hand's contacts on the twin (virtual scene).
        contacts: &'a [Contact],
        /// Their points' velocities (virtual scene, m/s).
        contact_velocities: &'a [Vector3<f64>],
        /// The twin's pose (virtual scene), or why there is none.
        twin_pose: Result<Isometry3<f64>, String>,
        /// The hand holds the twin.
        held: bool,
        /// When the newest hand frame was captured (s, this clock).
        hand_stamp_s: Option<f64>,
        /// The hand is tracked.
        hand_tracked: bool,
    },
    /// The operator's site over a network (`avatarm serve`): the newest valid target, `None`
    /// while there is none (none yet, the operator gone, a refused message).
    Remote(Option<RemoteTarget>),
}

/// A target from the operator's site, as the robot's site uses it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemoteTarget {
    /// The operator's side of the tick (stamp on this site's clock).
    pub target: avatarm_core::teleop::mapping::OperatorTarget,
    /// When the hand frame behind it was captured (s, this site's clock): the watchdog's age.
    pub hand_stamp_s: f64,
    /// The operator's hand is tracked.
    pub hand_tracked: bool,
}

impl RemoteTarget {
    /// The target as a tick uses it `age_s` after it arrived: past `fresh_for_s` it keeps its
    /// pose but loses its twist, so that a stream that stopped does not drive the arm on at its
    /// last velocity until the watchdog stops it.
    pub fn freshened(mut self, age_s: f64, fresh_for_s: f64) -> Self {
        if age_s.is_nan() || age_s > fresh_for_s {
            self.target.object_twist = nalgebra::Vector6::zeros();
        }
        self
    }
}

impl Teleop {
    /// One control tick at `now_s` (s, the joint states' clock) of period `dt_s`: joint states
    /// from the robot, the operator's side from `source`, the robot's side
    /// ([`Mapper::robot_side`]), the limiter, the command to the robot and the gripper; counted
    /// in [`Teleop::status`] and recorded in [`Teleop::log`] when [`Teleop::record`]. Every
    /// failure becomes a stop of the robot (a non-finite command the limiter ramps to zero),
    /// counted, never a panic.
    pub fn tick(&mut self, now_s: f64, dt_s: f64, source: TickSource) {
        if self.thread.is_some() {
            let operator = self.operator_for_thread(now_s, &source);
            self.front_tick(now_s, operator, self.last_step);
            return;
        }
        let started = std::time::Instant::now();
        let t = self;
        let now = now_s;
        let dt = dt_s.max(1e-6);
        t.robot.advance(now);
        let n = t.model.dof();
        t.received.clear();
        for s in t.robot.receive() {
            let ok = s.positions.len() == n
                && s.positions.iter().all(|v| v.is_finite())
                && s.stamp_s.is_finite();
            if ok {
                t.received.push(s.clone());
                t.joints = Some(s);
            } else {
                t.status.bad_joint_states += 1;
            }
        }
        t.status.ticks += 1;
        if approach_tick(t, now, dt) {
            t.status.tick_wall_s += started.elapsed().as_secs_f64();
            return;
        }
        let q: Vec<f64> = t
            .joints
            .as_ref()
            .map(|s| s.positions.iter().copied().collect())
            .unwrap_or_else(|| vec![f64::NAN; n]);
        // The operator's side: here, or received.
        let (operator, hand_stamp, hand_tracked) = operator_of(&source, now, &t.v2r);
        let side = RobotSide {
            model: &t.model,
            base: t.base,
            tcp: t.tcp,
            arm: &t.arm,
            tcp_from_object: t.tcp_from_object,
        };
        let mapped = match (&operator, &t.joints) {
            (Err(e), _) => Err(e.clone()),
            (_, None) => Err("no joint state received yet".to_string()),
            (Ok(target), Some(joints)) => t
                .mapper
                .robot_side(
                    target,
                    &RobotInputs {
                        q: &q,
                        now_s: now,
                        joints_stamp_s: joints.stamp_s,
                    },
                    &side,
                )
                .map_err(|e| e.to_string()),
        };
        let (qdot, jacobian, out) = match mapped {
            Ok(out) => (out.qdot.clone(), out.tcp_jacobian.clone(), Some(out)),
            Err(e) => {
                // Before the first joint state, and while a remote operator has sent nothing
                // valid, there is nothing to refuse: the robot is simply not driven.
                let quiet = t.joints.is_none() || matches!(source, TickSource::Remote(None));
                if !quiet {
                    t.fail(e);
                }
                (
                    DVector::from_element(n, f64::NAN),
                    Matrix6xX::zeros(n),
                    None,
                )
            }
        };
        let joints_stamp_s = t.joints.as_ref().map(|s| s.stamp_s);
        let limited = limit_and_send(
            t,
            &safety::TickInputs {
                now_s: now,
                qdot: &qdot,
                q: &q,
                joints_stamp_s,
                hand_stamp_s: hand_stamp,
                hand_tracked,
                jacobian: &jacobian,
            },
            dt,
        );
        // The gripper follows σ only while the hand drives the robot: a lost hand or a refused
        // tick keeps it as it is (never drops the real object).
        if let Some(out) = &out
            && !limited.stopping
            && let Err(e) = t.robot.gripper(&out.gripper)
        {
            t.fail(e.to_string());
        }
        t.status.tick_wall_s += started.elapsed().as_secs_f64();
        if t.record {
            let nan = Isometry3::from_parts(
                Translation3::new(f64::NAN, f64::NAN, f64::NAN),
                UnitQuaternion::identity(),
            );
            let (target, measured, gripper_closed, squeeze_n, twin_twist) = match &out {
                Some(o) => (
                    o.target,
                    o.measured,
                    o.gripper.closed,
                    o.squeeze_n,
                    o.twin_twist,
                ),
                None => (
                    match (&source, &operator) {
                        (_, Ok(op)) => op.target,
                        (
                            TickSource::Local {
                                twin_pose: Ok(p), ..
                            },
                            _,
                        ) => t.v2r.pose(p),
                        _ => nan,
                    },
                    nan,
                    false,
                    0.0,
                    nalgebra::Vector6::zeros(),
                ),
            };
            let contacts = match (&source, &operator) {
                (TickSource::Local { contacts, .. }, _) => contacts.len(),
                (_, Ok(op)) => op.contacts,
                _ => 0,
            };
            let sample = TeleopSample {
                t_s: now,
                target,
                measured,
                truth: t.robot.true_object_pose(),
                gripper_closed,
                tcp_speed: limited.tcp_speed,
                max_joint_speed: limited.command.as_ref().map_or(0.0, |c| c.amax()),
                stopping: limited.stopping,
                contacts,
                squeeze_n,
                twin_twist,
                q: DVector::from_vec(q),
                qdot: limited.command.clone().unwrap_or_else(|| DVector::zeros(n)),
                operator: operator.as_ref().ok().copied(),
            };
            t.log.push(sample);
        }
    }
}

/// A tick's operator side at `now_s` from `source` (the hand's here, through `v2r`, or the
/// one received), with the hand frame's stamp and whether the hand is tracked.
fn operator_of(
    source: &TickSource,
    now_s: f64,
    v2r: &VirtualToReal,
) -> (Result<OperatorTarget, String>, Option<f64>, bool) {
    match source {
        TickSource::Local {
            contacts,
            contact_velocities,
            twin_pose,
            held,
            hand_stamp_s,
            hand_tracked,
        } => (
            twin_pose.clone().and_then(|pose| {
                Mapper::operator_side(
                    &OperatorInputs {
                        contacts,
                        contact_velocities,
                        twin_pose: pose,
                        held: *held,
                        stamp_s: now_s,
                    },
                    v2r,
                )
                .map_err(|e| e.to_string())
            }),
            *hand_stamp_s,
            *hand_tracked,
        ),
        TickSource::Remote(Some(r)) => (Ok(r.target), Some(r.hand_stamp_s), r.hand_tracked),
        TickSource::Remote(None) => (
            Err("no valid target from the operator".to_string()),
            None,
            false,
        ),
    }
}

impl Teleop {
    /// The operator's side of a tick at `now_s` for the control thread ([`operator_of`]):
    /// without a hand frame its stamp is `-inf`, which the thread's watchdog takes as stale; an
    /// empty error is no target received (nothing to refuse).
    fn operator_for_thread(&self, now_s: f64, source: &TickSource) -> Result<RemoteTarget, String> {
        if matches!(source, TickSource::Remote(None)) {
            return Err(String::new());
        }
        let (target, hand_stamp_s, hand_tracked) = operator_of(source, now_s, &self.v2r);
        Ok(RemoteTarget {
            target: target?,
            hand_stamp_s: hand_stamp_s.unwrap_or(f64::NEG_INFINITY),
            hand_tracked,
        })
    }
}

/// One tick of the move to the start ([`Approach`]): `true` when it commanded the arm (the
/// tick ends there, recorded in [`Teleop::log`] with the object's target and measured pose
/// both where the tool holds it now); `false` when there is none, no
/// joint state yet, or the arm arrived this tick (the hand drives it from this tick on).
fn approach_tick(t: &mut Teleop, now: f64, dt: f64) -> bool {
    let Some(run) = t.approach.as_mut() else {
        return false;
    };
    let Some(joints) = t.joints.as_ref() else {
        // Nothing known of the arm yet: the ordinary tick refuses to drive it and says so.
        return false;
    };
    let started = *run.started_s.get_or_insert(now);
    let Some(qdot) = run
        .approach
        .velocity(&joints.positions, &t.arm, &run.speed_limits)
    else {
        info!(
            "mapping: the arm is at the task's start after {:.2} s; the hand drives it now",
            now - started
        );
        t.status.approaching = false;
        t.status.approach_s = Some(now - started);
        t.approach = None;
        return false;
    };
    let q: Vec<f64> = joints.positions.iter().copied().collect();
    let jacobian = t
        .model
        .jacobian(&t.base, &q, t.tcp, &Vector3::zeros(), Frame::World);
    let stamp = joints.stamp_s;
    let limited = limit_and_send(
        t,
        &safety::TickInputs {
            now_s: now,
            qdot: &qdot,
            q: &q,
            joints_stamp_s: Some(stamp),
            // No hand drives the approach: the limiter's hand checks do not apply.
            hand_stamp_s: Some(now),
            hand_tracked: true,
            jacobian: &jacobian,
        },
        dt,
    );
    if t.record {
        let held = t.model.forward_kinematics(&t.base, &q)[t.tcp] * t.tcp_from_object;
        let sample = TeleopSample {
            t_s: now,
            target: held,
            measured: held,
            truth: t.robot.true_object_pose(),
            gripper_closed: false,
            tcp_speed: limited.tcp_speed,
            max_joint_speed: limited.command.as_ref().map_or(0.0, |c| c.amax()),
            stopping: limited.stopping,
            contacts: 0,
            squeeze_n: 0.0,
            twin_twist: nalgebra::Vector6::zeros(),
            qdot: limited
                .command
                .clone()
                .unwrap_or_else(|| DVector::zeros(q.len())),
            q: DVector::from_vec(q),
            operator: None,
        };
        t.log.push(sample);
    }
    true
}

/// The limiter on `inputs`, its interventions counted, and its command sent to the robot (a
/// refusal counted as a failed tick): every command of the loop, the hand's and the
/// approach's, goes through here.
fn limit_and_send(t: &mut Teleop, inputs: &safety::TickInputs, dt: f64) -> safety::Limited {
    let limited = t.limiter.tick(inputs, dt);
    for &i in &limited.interventions {
        t.count(i);
    }
    t.status.max_tcp_speed = t.status.max_tcp_speed.max(limited.tcp_speed);
    if let Some(cmd) = &limited.command
        && let Err(e) = t.robot.send(cmd)
    {
        t.fail(e.to_string());
    }
    limited
}

#[cfg(test)]
mod tests;
