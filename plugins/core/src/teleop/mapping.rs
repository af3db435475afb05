//! From the virtual grasp to the robot: the paper's motion mapping, one control tick at a time.
//!
//! 1. The object twin's twist in the virtual scene, from the hand's contact twists through the
//!    grasp matrix (`ν = (Gᵀ)⁺ ν_c`, [`crate::teleop::grasp`]), and the squeezing force σ.
//! 2. Scaled to the real object ([`VirtualToReal`]: the twin is the real object scaled by `k`
//!    about the camera centre, see [`crate::vision::placement`]): `v_r = Rᵀ v_v / k`, `ω_r = Rᵀ ω_v`.
//! 3. `paper` mode sends that twist open loop; `closed_loop` adds `K · (target ⊖ measured)`, the
//!    pose error between the scaled twin and the real object as the robot's measured joint
//!    states place it through forward kinematics and the grasp offset.
//! 4. The object twist is moved to the gripper's tool point (the robot holds the object rigidly
//!    with its m = 2 fingers), then to joint velocities by damped least squares
//!    ([`crate::robot::ik::dls_step`]); the gripper closes when σ passes a threshold (with hysteresis)
//!    and its force follows σ. Joint torques for the object wrench are `Jᵀ w`.
//!
//! The [`crate::teleop::safety::SafetyLimiter`] comes after this, always.

use std::collections::VecDeque;

use nalgebra::{DVector, Isometry3, Translation3, UnitQuaternion, Vector3, Vector6};

use crate::robot::ik::{DlsSettings, dls_step};
use crate::robot::kinematics::{Frame, pose_difference};
use crate::robot::{LinkId, RobotModel};
use crate::teleop::grasp::{self, Contact, ContactModel};

/// How the mapped twist drives the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MappingMode {
    /// Open-loop velocity mapping, as published.
    Paper,
    /// Velocity mapping plus a correction toward the scaled twin pose from measured joints.
    ClosedLoop,
}

impl MappingMode {
    /// The mode as scenes and reports spell it (`paper`, `closed_loop`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::ClosedLoop => "closed_loop",
        }
    }
}

/// The virtual scene to the real one: the object twin is the real object scaled by `k` about
/// the camera centre (virtual = `c_v + R (real − c_r) k`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualToReal {
    /// Scale `k` of the twin relative to the real object (`z_v / z_r`).
    pub k: f64,
    /// Rotation from the real world to the virtual scene.
    pub rotation: UnitQuaternion<f64>,
    /// Real camera centre (real world).
    pub real_centre: Vector3<f64>,
    /// Virtual camera centre (virtual scene).
    pub virtual_centre: Vector3<f64>,
}

impl VirtualToReal {
    /// The identity map (virtual scene = real world).
    pub fn identity() -> Self {
        Self {
            k: 1.0,
            rotation: UnitQuaternion::identity(),
            real_centre: Vector3::zeros(),
            virtual_centre: Vector3::zeros(),
        }
    }

    /// A virtual point in the real world.
    pub fn point(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.real_centre + self.rotation.inverse() * (v - self.virtual_centre) / self.k
    }

    /// A virtual pose in the real world (orientation rotated, position scaled).
    pub fn pose(&self, v: &Isometry3<f64>) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.point(&v.translation.vector)),
            self.rotation.inverse() * v.rotation,
        )
    }

    /// A real pose in the virtual scene: the inverse of [`Self::pose`], where the twin of an
    /// object at `real` is placed.
    pub fn virtual_pose(&self, real: &Isometry3<f64>) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(
                self.virtual_centre
                    + self.rotation * (real.translation.vector - self.real_centre) * self.k,
            ),
            self.rotation * real.rotation,
        )
    }

    /// A virtual twist (taken at a virtual point) as the real twist at the mapped point.
    pub fn twist(&self, v: &Vector6<f64>) -> Vector6<f64> {
        let r = self.rotation.inverse();
        let lin = r * v.fixed_rows::<3>(0).into_owned() / self.k;
        let ang = r * v.fixed_rows::<3>(3).into_owned();
        Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z)
    }
}

/// Settings of the mapping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MappingSettings {
    /// Open or closed loop.
    pub mode: MappingMode,
    /// Closed-loop gain on the pose error (1/s).
    pub gain: f64,
    /// Time constant of the low-pass on the closed loop's feed-forward twist (s; 0: off).
    pub feedforward_smoothing_s: f64,

    /// σ above which the gripper closes (N).
    pub close_at_n: f64,
    /// σ below which it opens again (N); less than `close_at_n`.
    pub open_at_n: f64,
    /// Largest gripper force (N).
    pub max_grip_n: f64,
    /// Damped least squares.
    pub dls: DlsSettings,
}

impl Default for MappingSettings {
    fn default() -> Self {
        Self {
            mode: MappingMode::ClosedLoop,
            gain: 12.0,
            feedforward_smoothing_s: 0.04,
            close_at_n: 1.0,
            open_at_n: 0.3,
            max_grip_n: 40.0,
            dls: DlsSettings::default(),
        }
    }
}

/// The robot side of the mapping.
#[derive(Debug, Clone)]
pub struct RobotSide<'a> {
    /// The robot.
    pub model: &'a RobotModel,
    /// Its base in the real world.
    pub base: Isometry3<f64>,
    /// The tool link (between the gripper's fingers).
    pub tcp: LinkId,
    /// Arm joints driven by the mapping (joint-vector indices); the others (the fingers) get
    /// zero velocity here and follow the gripper command.
    pub arm: &'a [usize],
    /// Pose of the real object in the tool frame while grasped.
    pub tcp_from_object: Isometry3<f64>,
}

/// One tick's inputs.
#[derive(Debug, Clone)]
pub struct TickInputs<'a> {
    /// Contacts of the hand on the object twin (virtual scene).
    pub contacts: &'a [Contact],
    /// Velocities of the contact points (the hand's, virtual scene, m/s).
    pub contact_velocities: &'a [Vector3<f64>],
    /// The object twin's pose (virtual scene).
    pub twin_pose: Isometry3<f64>,
    /// Measured joint positions.
    pub q: &'a [f64],
    /// The hand holds the twin (its grasp state, e.g. the hand plugin's grasp assist): the
    /// gripper closes on this as well as on σ.
    pub held: bool,
    /// The tick's time (s, the clock of the joint states' stamps).
    pub now_s: f64,
    /// When the robot measured `q` (s, same clock): the closed loop compares `q` with the
    /// target of that moment, not with the newer one.
    pub joints_stamp_s: f64,
}

/// The operator's side of a tick's inputs ([`Mapper::operator_side`]).
#[derive(Debug, Clone)]
pub struct OperatorInputs<'a> {
    /// Contacts of the hand on the object twin (virtual scene).
    pub contacts: &'a [Contact],
    /// Velocities of the contact points (the hand's, virtual scene, m/s).
    pub contact_velocities: &'a [Vector3<f64>],
    /// The object twin's pose (virtual scene).
    pub twin_pose: Isometry3<f64>,
    /// The hand holds the twin (its grasp state).
    pub held: bool,
    /// When (s, the robot's clock: the joint states' stamps; over a network, the operator's
    /// estimate of it).
    pub stamp_s: f64,
}

/// The robot's side of a tick's inputs ([`Mapper::robot_side`]).
#[derive(Debug, Clone)]
pub struct RobotInputs<'a> {
    /// Measured joint positions (all joints, the model's order).
    pub q: &'a [f64],
    /// The tick's time (s, the clock of the joint states' stamps).
    pub now_s: f64,
    /// When the robot measured `q` (s, same clock).
    pub joints_stamp_s: f64,
}

/// What the operator's side sends the robot's side each tick: the real object's target and
/// twist (real world, from the twin through [`VirtualToReal`]), the grasp's squeezing force
/// and state. Checked by [`OperatorTarget::validate`] on both sides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatorTarget {
    /// When the twin was there (s, the robot's clock).
    pub stamp_s: f64,
    /// The real object's target pose (the scaled twin, real world).
    pub target: Isometry3<f64>,
    /// The real object's twist from the contacts (real world, at its origin; m/s, rad/s).
    pub object_twist: Vector6<f64>,
    /// The twin's twist (virtual scene, at its origin).
    pub twin_twist: Vector6<f64>,
    /// Squeezing force σ (N, virtual).
    pub squeeze_n: f64,
    /// Grasp matrix rank (0–6).
    pub rank: usize,
    /// Contacts on the twin.
    pub contacts: usize,
    /// The hand holds the twin.
    pub held: bool,
}

/// Largest target position from the real world's origin an [`OperatorTarget`] may have (m):
/// beyond any desk.
pub const MAX_TARGET_DISTANCE_M: f64 = 10.0;
/// Largest linear (m/s) or angular (rad/s) speed in an [`OperatorTarget`]'s twists: far above
/// a hand's, below anything that is not a measurement error.
pub const MAX_TARGET_SPEED: f64 = 50.0;
/// Largest squeezing force an [`OperatorTarget`] may carry (N).
pub const MAX_SQUEEZE_N: f64 = 10_000.0;

impl OperatorTarget {
    /// Checks that every number is finite and in range (position within
    /// [`MAX_TARGET_DISTANCE_M`], twists within [`MAX_TARGET_SPEED`], σ in
    /// `0..=`[`MAX_SQUEEZE_N`], a unit rotation, rank ≤ 6); the error names the field.
    pub fn validate(&self) -> crate::Result<()> {
        let field =
            |name: &str, message: String| Err(bad_input(format!("target {name}: {message}")));
        if !self.stamp_s.is_finite() {
            return field("stamp_s", format!("{} is not finite", self.stamp_s));
        }
        let p = self.target.translation.vector;
        if !p.iter().all(|v| v.is_finite()) || p.norm() > MAX_TARGET_DISTANCE_M {
            return field(
                "position",
                format!("{p:?} is not finite or beyond {MAX_TARGET_DISTANCE_M} m"),
            );
        }
        let q = self.target.rotation.quaternion();
        if !q.coords.iter().all(|v| v.is_finite()) || (q.norm() - 1.0).abs() > 1e-6 {
            return field(
                "rotation",
                format!("{:?} is not a unit quaternion", q.coords),
            );
        }
        for (name, t) in [
            ("object_twist", &self.object_twist),
            ("twin_twist", &self.twin_twist),
        ] {
            if !t
                .iter()
                .all(|v| v.is_finite() && v.abs() <= MAX_TARGET_SPEED)
            {
                return field(
                    name,
                    format!(
                        "{:?} is not finite or beyond {MAX_TARGET_SPEED}",
                        t.as_slice()
                    ),
                );
            }
        }
        if !(self.squeeze_n.is_finite() && (0.0..=MAX_SQUEEZE_N).contains(&self.squeeze_n)) {
            return field(
                "squeeze_n",
                format!("{} is outside 0..={MAX_SQUEEZE_N} N", self.squeeze_n),
            );
        }
        if self.rank > 6 {
            return field("rank", format!("{} is more than 6", self.rank));
        }
        Ok(())
    }
}

/// The gripper command.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GripperCommand {
    /// Closed.
    pub closed: bool,
    /// Force (N) while closed.
    pub force_n: f64,
}

/// One tick's outputs, before the safety limiter.
#[derive(Debug, Clone, PartialEq)]
pub struct TickOutput {
    /// Joint velocities (all joints; zero for non-arm joints).
    pub qdot: DVector<f64>,
    /// The twin's twist (virtual scene, at its origin).
    pub twin_twist: Vector6<f64>,
    /// The real object's commanded twist (real world, at its origin).
    pub object_twist: Vector6<f64>,
    /// The real object's target pose (the scaled twin).
    pub target: Isometry3<f64>,
    /// The real object's pose from measured joints.
    pub measured: Isometry3<f64>,
    /// Squeezing force σ (N, virtual).
    pub squeeze_n: f64,
    /// Grasp matrix rank.
    pub rank: usize,
    /// The gripper.
    pub gripper: GripperCommand,
    /// Smallest singular value of the arm Jacobian.
    pub sigma_min: f64,
    /// Jacobian of the tool point at the measured joints (6 × dof, world frame), for the
    /// safety limiter's TCP speed.
    pub tcp_jacobian: nalgebra::Matrix6xX<f64>,
}

/// The mapping's state between ticks (the gripper's hysteresis).
#[derive(Debug, Clone)]
pub struct Mapper {
    settings: MappingSettings,
    closed: bool,
    /// The targets of the last [`TARGET_HISTORY_S`], oldest first, with their tick times.
    history: VecDeque<(f64, Isometry3<f64>)>,
    /// The low-passed feed-forward twist and the time it was last updated.
    feedforward: (f64, Vector6<f64>),
}

/// How far back the mapper remembers its targets (s): longer than any joint-state latency
/// the closed loop makes sense with.
pub const TARGET_HISTORY_S: f64 = 0.5;

impl Mapper {
    /// A mapper, gripper open.
    pub fn new(settings: MappingSettings) -> Self {
        Self {
            settings,
            closed: false,
            history: VecDeque::new(),
            feedforward: (f64::NEG_INFINITY, Vector6::zeros()),
        }
    }

    /// The settings.
    pub fn settings(&self) -> &MappingSettings {
        &self.settings
    }

    /// Keeps `target` as the target at `t_s` and forgets those older than
    /// [`TARGET_HISTORY_S`]. A clock that goes back (a restarted session) starts afresh.
    fn remember(&mut self, t_s: f64, target: Isometry3<f64>) {
        if self.history.back().is_some_and(|(t, _)| *t > t_s) {
            self.history.clear();
        }
        self.history.push_back((t_s, target));
        while self
            .history
            .front()
            .is_some_and(|(t, _)| *t < t_s - TARGET_HISTORY_S)
        {
            self.history.pop_front();
        }
    }

    /// `twist` through the first-order low-pass of [`MappingSettings::feedforward_smoothing_s`].
    fn smooth_feedforward(&mut self, t_s: f64, twist: Vector6<f64>) -> Vector6<f64> {
        let tau = self.settings.feedforward_smoothing_s;
        let (last, state) = &mut self.feedforward;
        let dt = t_s - *last;
        *last = t_s;
        if tau <= 0.0 || !(0.0..=0.1).contains(&dt) {
            // Off, or the first tick or a gap: start from the twist as it is.
            *state = twist;
        } else {
            *state += (twist - *state) * (1.0 - (-dt / tau).exp());
        }
        *state
    }

    /// The target at `t_s`, interpolated between the remembered ones; the oldest or the
    /// newest outside them.
    fn target_at(&self, t_s: f64) -> Isometry3<f64> {
        let (Some(first), Some(last)) = (self.history.front(), self.history.back()) else {
            return Isometry3::identity();
        };
        if t_s <= first.0 {
            return first.1;
        }
        if t_s >= last.0 {
            return last.1;
        }
        let after = self.history.partition_point(|(t, _)| *t <= t_s);
        let (t0, a) = &self.history[after - 1];
        let (t1, b) = &self.history[after];
        let f = if t1 > t0 { (t_s - t0) / (t1 - t0) } else { 1.0 };
        // Along the shortest rotation (never the undefined half-turn slerp).
        let turn = (a.rotation.inverse() * b.rotation).scaled_axis() * f;
        Isometry3::from_parts(
            Translation3::from(a.translation.vector.lerp(&b.translation.vector, f)),
            a.rotation * UnitQuaternion::from_scaled_axis(turn),
        )
    }

    /// The real object's pose as the measured joints place it.
    pub fn measured_object(robot: &RobotSide, q: &[f64]) -> Isometry3<f64> {
        robot.model.forward_kinematics(&robot.base, q)[robot.tcp] * robot.tcp_from_object
    }

    /// One tick, both sides in one process: [`Mapper::operator_side`] then
    /// [`Mapper::robot_side`]. Errors name the bad input; the caller stops the robot on an
    /// error.
    pub fn tick(
        &mut self,
        input: &TickInputs,
        v2r: &VirtualToReal,
        robot: &RobotSide,
    ) -> crate::Result<TickOutput> {
        let n = robot.model.dof();
        if input.q.len() != n || input.q.iter().any(|v| !v.is_finite()) {
            return Err(bad_input(format!("joint state: {n} finite values needed")));
        }
        let target = Self::operator_side(
            &OperatorInputs {
                contacts: input.contacts,
                contact_velocities: input.contact_velocities,
                twin_pose: input.twin_pose,
                held: input.held,
                stamp_s: input.now_s,
            },
            v2r,
        )?;
        self.robot_side(
            &target,
            &RobotInputs {
                q: input.q,
                now_s: input.now_s,
                joints_stamp_s: input.joints_stamp_s,
            },
            robot,
        )
    }

    /// The operator's side of a tick (steps 1–2 of the module's list), where the hand and
    /// the twin are: the twin's twist from the contacts through the grasp matrix, σ, and both
    /// mapped into the real world. Needs no robot: this is what crosses the network from the
    /// operator's site to the robot's. Errors name the bad input.
    pub fn operator_side(
        input: &OperatorInputs,
        v2r: &VirtualToReal,
    ) -> crate::Result<OperatorTarget> {
        if !input.stamp_s.is_finite() {
            return Err(bad_input(format!(
                "tick time {} s is not finite",
                input.stamp_s
            )));
        }
        if input.contact_velocities.len() != input.contacts.len() {
            return Err(bad_input(format!(
                "{} contact velocities for {} contacts",
                input.contact_velocities.len(),
                input.contacts.len()
            )));
        }
        let origin = input.twin_pose.translation.vector;
        let (twin_twist, squeeze_n, rank) = if input.contacts.is_empty() {
            (Vector6::zeros(), 0.0, 0)
        } else {
            let a = grasp::analyse(&origin, input.contacts, ContactModel::HardFinger)?;
            let vc = DVector::from_iterator(
                3 * input.contacts.len(),
                input
                    .contact_velocities
                    .iter()
                    .flat_map(|v| v.iter().copied()),
            );
            let nu = grasp::object_twist_from_pinv(&a.g_pinv, &vc)?;
            // σ < 0 (contacts pulling apart, or a rounding error around 0) squeezes nothing:
            // the squeezing force is 0 then, not a malformed target that stops the robot. NaN
            // stays NaN and is refused below.
            let squeeze = if a.squeeze < 0.0 { 0.0 } else { a.squeeze };
            (nu, squeeze, a.rank)
        };
        let target = OperatorTarget {
            stamp_s: input.stamp_s,
            target: v2r.pose(&input.twin_pose),
            object_twist: v2r.twist(&twin_twist),
            twin_twist,
            squeeze_n,
            rank,
            contacts: input.contacts.len(),
            held: input.held,
        };
        target.validate()?;
        Ok(target)
    }

    /// The robot's side of a tick (steps 3–4), next to the robot: the gripper from σ, the
    /// closed loop's correction against the measured joints, and the tool point's twist to
    /// joint velocities. `target` comes from [`Mapper::operator_side`], in this process or
    /// over the network (its stamp on this clock). Errors name the bad input.
    pub fn robot_side(
        &mut self,
        target: &OperatorTarget,
        input: &RobotInputs,
        robot: &RobotSide,
    ) -> crate::Result<TickOutput> {
        let n = robot.model.dof();
        if input.q.len() != n || input.q.iter().any(|v| !v.is_finite()) {
            return Err(bad_input(format!("joint state: {n} finite values needed")));
        }
        if !(input.now_s.is_finite() && input.joints_stamp_s.is_finite()) {
            return Err(bad_input(format!(
                "tick time {} s or joint-state stamp {} s is not finite",
                input.now_s, input.joints_stamp_s
            )));
        }
        target.validate()?;
        let squeeze_n = target.squeeze_n;
        // Gripper from σ (with hysteresis) or the hand's grasp state.
        let s = self.settings;
        if !self.closed && (squeeze_n >= s.close_at_n || target.held) {
            self.closed = true;
        } else if self.closed && squeeze_n < s.open_at_n && !target.held {
            self.closed = false;
        }
        let gripper = GripperCommand {
            closed: self.closed,
            force_n: if self.closed {
                squeeze_n.clamp(0.0, s.max_grip_n)
            } else {
                0.0
            },
        };
        // One FK for the measured object pose, the tool point and its Jacobian.
        let poses = robot.model.forward_kinematics(&robot.base, input.q);
        let measured = poses[robot.tcp] * robot.tcp_from_object;
        let mut object_twist = target.object_twist;
        if s.mode == MappingMode::ClosedLoop {
            // The contact twist carries the fingers' tracking jitter; integrated by the robot it
            // becomes a slow wander that the correction has to undo. Low-passed, it still
            // leads the correction.
            object_twist = self.smooth_feedforward(input.now_s, object_twist);
            // Like with like: the joints were measured at their stamp, so they are compared
            // with the target of that moment. Against the newest target, a joint-state latency
            // d makes the loop settle d ahead of a moving twin (1° at the pour's peak speed
            // for 15 ms). A target from the network is remembered at its own stamp.
            self.remember(target.stamp_s, target.target);
            let then = self.target_at(input.joints_stamp_s);
            object_twist += pose_difference(&measured, &then) * s.gain;
        }
        if !self.closed {
            // An open gripper cannot move the object: the arm holds still around it.
            object_twist = Vector6::zeros();
        }
        // Move the object twist to the tool point, then to the arm's joints.
        let tcp = poses[robot.tcp].translation.vector;
        let tcp_twist = grasp::transport_twist(&object_twist, &measured.translation.vector, &tcp);
        let j_full =
            robot
                .model
                .jacobian_from_poses(&poses, robot.tcp, &Vector3::zeros(), Frame::World);
        let j = nalgebra::Matrix6xX::from_fn(robot.arm.len(), |r, c| j_full[(r, robot.arm[c])]);
        let q_arm: Vec<f64> = robot.arm.iter().map(|&i| input.q[i]).collect();
        let limits = robot.model.dof_limits();
        let lim_arm: Vec<_> = robot.arm.iter().map(|&i| limits[i]).collect();
        let step = dls_step(&j, &tcp_twist, &q_arm, &lim_arm, &s.dls);
        if step.rejected {
            return Err(bad_input(
                "the arm Jacobian or the twist is not finite".into(),
            ));
        }
        let mut qdot = DVector::zeros(n);
        for (k, &i) in robot.arm.iter().enumerate() {
            qdot[i] = step.qdot[k];
        }
        Ok(TickOutput {
            qdot,
            twin_twist: target.twin_twist,
            object_twist,
            target: target.target,
            measured,
            squeeze_n,
            rank: target.rank,
            gripper,
            sigma_min: step.sigma_min,
            tcp_jacobian: j_full,
        })
    }
}

/// Errors of a trial's pose track, the paper's measure: position RMSE (m) and roll/pitch/yaw
/// RMSE (degrees) of `actual` against `target`, each orientation error as the roll-pitch-yaw
/// of `target⁻¹ · actual`; `None` for tracks of different lengths or none.
pub fn pose_rmse(target: &[Isometry3<f64>], actual: &[Isometry3<f64>]) -> Option<[f64; 4]> {
    if target.len() != actual.len() {
        return None;
    }
    let mut errors = PoseErrors::default();
    for (t, a) in target.iter().zip(actual) {
        errors.push(t, a);
    }
    errors.rmse()
}

/// [`pose_rmse`] as running sums: pairs pushed one at a time, so a track of any length (a
/// robot site serving for days) is measured in constant memory.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PoseErrors {
    /// Sums of squares: position (m²), roll, pitch, yaw (rad²).
    sum: [f64; 4],
    n: usize,
}

impl PoseErrors {
    /// Adds the pair (`actual` against `target`); a pair with a value that is not finite is
    /// left out.
    pub fn push(&mut self, target: &Isometry3<f64>, actual: &Isometry3<f64>) {
        let d = (actual.translation.vector - target.translation.vector).norm_squared();
        let (r, p, y) = (target.rotation.inverse() * actual.rotation).euler_angles();
        let add = [d, r * r, p * p, y * y];
        if add.iter().all(|v| v.is_finite()) {
            for (s, a) in self.sum.iter_mut().zip(add) {
                *s += a;
            }
            self.n += 1;
        }
    }

    /// Pairs summed.
    pub fn len(&self) -> usize {
        self.n
    }

    /// No pair summed.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Position RMSE (m) and roll, pitch, yaw RMSE (degrees); `None` before any pair.
    pub fn rmse(&self) -> Option<[f64; 4]> {
        if self.n == 0 {
            return None;
        }
        let n = self.n as f64;
        let [p, r, pi, y] = self.sum.map(|s| (s / n).sqrt());
        Some([p, r.to_degrees(), pi.to_degrees(), y.to_degrees()])
    }
}

fn bad_input(message: String) -> crate::Error {
    crate::Error::BadTickInput { message }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::kinematics::tests::sawyer;
    use crate::sim::{JointCommand, SimRobot, SimRobotParams};

    /// The Sawyer's seven arm joints (the gripper's fingers follow).
    const ARM: [usize; 7] = [0, 1, 2, 3, 4, 5, 6];

    /// The Sawyer on the 0.75 m table, holding the object at its tool point.
    fn sawyer_side(model: &RobotModel) -> RobotSide<'_> {
        RobotSide {
            model,
            base: Isometry3::translation(0.0, 0.0, 0.75),
            tcp: model.link_id("right_gripper_tip").expect("tcp"),
            arm: &ARM,
            tcp_from_object: Isometry3::identity(),
        }
    }

    /// Four fingertips around a bottle of radius 3.5 cm, squeezing 3 N each.
    fn grasp_contacts(
        pose: &Isometry3<f64>,
        twist: &Vector6<f64>,
    ) -> (Vec<Contact>, Vec<Vector3<f64>>) {
        let local = [
            Vector3::new(0.035, 0.0, 0.10),
            Vector3::new(-0.035, 0.0, 0.10),
            Vector3::new(0.0, 0.035, 0.12),
            Vector3::new(0.0, -0.035, 0.08),
        ];
        let o = pose.translation.vector;
        let mut contacts = Vec::new();
        let mut vel = Vec::new();
        for l in local {
            let p = pose * nalgebra::Point3::from(l);
            let radial = pose.rotation * Vector3::new(l.x, l.y, 0.0);
            let normal = -radial.normalize();
            contacts.push(Contact {
                point: p.coords,
                normal,
                force: normal * 3.0,
                moment: Vector3::zeros(),
            });
            vel.push(
                grasp::transport_twist(twist, &o, &p.coords)
                    .fixed_rows::<3>(0)
                    .into_owned(),
            );
        }
        (contacts, vel)
    }

    #[test]
    fn the_closed_loop_compares_a_joint_state_with_the_target_of_its_stamp() {
        let model = sawyer();
        let robot = sawyer_side(&model);
        let v2r = VirtualToReal::identity();
        let q = [0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02];
        let start = Mapper::measured_object(&robot, &q);
        // The twin moves along x at 0.1 m/s; the robot's last joint state, taken at t = 0,
        // put the object exactly on the twin of that moment.
        let run = |stamped: bool| {
            let mut m = Mapper::new(MappingSettings::default());
            let mut out = None;
            for k in 0..=5 {
                let t = f64::from(k) * 0.01;
                let twin = Isometry3::from_parts(
                    Translation3::from(start.translation.vector + Vector3::x() * 0.1 * t),
                    start.rotation,
                );
                out = Some(
                    m.tick(
                        &TickInputs {
                            contacts: &[],
                            contact_velocities: &[],
                            twin_pose: twin,
                            q: &q,
                            held: true,
                            now_s: t,
                            joints_stamp_s: if stamped { 0.0 } else { t },
                        },
                        &v2r,
                        &robot,
                    )
                    .expect("tick"),
                );
            }
            out.expect("ticked").object_twist
        };
        // Against the target of its own time the measurement is on target: no correction.
        assert!(run(true).norm() < 1e-9, "{}", run(true));
        // Against the newest target, the same data look 5 mm behind.
        let newest = run(false);
        let want = MappingSettings::default().gain * 0.005;
        assert!((newest[0] - want).abs() < 1e-9, "{newest}");
        // A non-finite stamp is refused, naming it.
        let mut m = Mapper::new(MappingSettings::default());
        let e = m
            .tick(
                &TickInputs {
                    contacts: &[],
                    contact_velocities: &[],
                    twin_pose: start,
                    q: &q,
                    held: true,
                    now_s: 0.0,
                    joints_stamp_s: f64::NAN,
                },
                &v2r,
                &robot,
            )
            .expect_err("refused");
        assert!(e.to_string().contains("stamp"), "{e}");
    }

    #[test]
    fn a_rigid_grasp_maps_to_the_twins_velocity_scaled() {
        let pose = Isometry3::translation(0.6, -0.1, 0.9);
        let nu = Vector6::new(0.02, -0.01, 0.05, 0.1, 0.0, 0.3);
        let (contacts, vel) = grasp_contacts(&pose, &nu);
        let model = sawyer();
        let robot = sawyer_side(&model);
        let v2r = VirtualToReal {
            k: 0.5,
            ..VirtualToReal::identity()
        };
        let mut m = Mapper::new(MappingSettings {
            mode: MappingMode::Paper,
            ..MappingSettings::default()
        });
        let q = [0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02];
        let out = m
            .tick(
                &TickInputs {
                    contacts: &contacts,
                    contact_velocities: &vel,
                    twin_pose: pose,
                    q: &q,
                    held: true,
                    now_s: 0.0,
                    joints_stamp_s: 0.0,
                },
                &v2r,
                &robot,
            )
            .expect("tick");
        assert!(
            (out.twin_twist - nu).norm() < 1e-9,
            "{} vs {nu}",
            out.twin_twist
        );
        let want = Vector6::new(0.04, -0.02, 0.10, 0.1, 0.0, 0.3);
        assert!(
            (out.object_twist - want).norm() < 1e-9,
            "{}",
            out.object_twist
        );
        assert_eq!(out.rank, 6);
        assert!(
            out.squeeze_n > 2.0 && out.gripper.closed,
            "{}",
            out.squeeze_n
        );
        // Fingers are not driven by the arm mapping.
        assert_eq!((out.qdot[7], out.qdot[8]), (0.0, 0.0));
    }

    /// Fingertips pulling outward (or a rounding error: σ = -3e-16 was seen live) give a
    /// negative internal force along the normals: no squeeze, a valid target, not a stop.
    #[test]
    fn contacts_pulling_apart_squeeze_nothing_and_the_target_is_valid() {
        let pose = Isometry3::translation(0.6, -0.1, 0.9);
        let (mut contacts, vel) = grasp_contacts(&pose, &Vector6::zeros());
        for c in &mut contacts {
            c.force = -c.force;
        }
        let target = Mapper::operator_side(
            &OperatorInputs {
                stamp_s: 0.0,
                contacts: &contacts,
                contact_velocities: &vel,
                twin_pose: pose,
                held: false,
            },
            &VirtualToReal::identity(),
        )
        .expect("a valid target");
        assert_eq!(target.squeeze_n, 0.0);
        assert!(target.validate().is_ok());
    }

    #[test]
    fn virtual_to_real_round_trips_points_and_poses() {
        let v2r = VirtualToReal {
            k: 0.4,
            rotation: UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
            real_centre: Vector3::new(1.85, 0.0, 1.3),
            virtual_centre: Vector3::new(0.0, 0.0, 0.0),
        };
        let real = Vector3::new(0.6, -0.16, 0.8);
        let virt = v2r.virtual_centre + v2r.rotation * (real - v2r.real_centre) * v2r.k;
        assert!((v2r.point(&virt) - real).norm() < 1e-12);
        let pose = Isometry3::from_parts(
            Translation3::from(real),
            UnitQuaternion::from_euler_angles(0.3, 0.0, -1.0),
        );
        let back = v2r.pose(&v2r.virtual_pose(&pose));
        assert!((back.translation.vector - real).norm() < 1e-12);
        assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
    }

    /// The twin moves the object 10 cm up and back at ~0.1 m/s; the simulated robot (latency,
    /// lag) carries the real object. Closed loop tracks the scaled twin far better than the
    /// open-loop paper mode, whose errors integrate.
    #[test]
    fn closed_loop_tracks_the_twin_better_than_open_loop() {
        let model = sawyer();
        let q0 = DVector::from_row_slice(&[0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02]);
        let robot = sawyer_side(&model);
        let start = Mapper::measured_object(&robot, q0.as_slice());
        let v2r = VirtualToReal {
            k: 0.5,
            rotation: UnitQuaternion::identity(),
            real_centre: Vector3::zeros(),
            virtual_centre: Vector3::zeros(),
        };
        // The twin's path in the virtual scene (scaled by k), minimum jerk up 10 cm and back.
        let twin_at = |t: f64| -> (Isometry3<f64>, Vector6<f64>) {
            let (s, ds) = if t < 1.0 {
                (
                    crate::teleop::hand::min_jerk(t),
                    30.0 * t * t * (1.0 - t) * (1.0 - t),
                )
            } else if t < 2.0 {
                let u = t - 1.0;
                (
                    1.0 - crate::teleop::hand::min_jerk(u),
                    -30.0 * u * u * (1.0 - u) * (1.0 - u),
                )
            } else {
                (0.0, 0.0)
            };
            let z = 0.1 * s * v2r.k;
            let p = start.translation.vector * v2r.k + Vector3::new(0.0, 0.0, z);
            (
                Isometry3::from_parts(Translation3::from(p), start.rotation),
                Vector6::new(0.0, 0.0, 0.1 * ds * v2r.k, 0.0, 0.0, 0.0),
            )
        };
        let run_with = |mode: MappingMode, gain: f64| -> [f64; 4] {
            let mut sim = SimRobot::new(SimRobotParams::default(), model.dof_limits(), q0.clone());
            let mut m = Mapper::new(MappingSettings {
                mode,
                gain,
                ..MappingSettings::default()
            });
            let mut q_meas = q0.clone();
            let mut stamp = 0.0;
            let (mut targets, mut actual) = (Vec::new(), Vec::new());
            let dt = 0.01;
            for k in 0..250 {
                let t = f64::from(k) * dt;
                let (pose, twist) = twin_at(t);
                let (contacts, vel) = grasp_contacts(&pose, &twist);
                for s in sim.receive() {
                    q_meas = s.positions;
                    stamp = s.stamp_s;
                }
                let out = m
                    .tick(
                        &TickInputs {
                            contacts: &contacts,
                            contact_velocities: &vel,
                            twin_pose: pose,
                            q: q_meas.as_slice(),
                            held: true,
                            now_s: t,
                            joints_stamp_s: stamp,
                        },
                        &v2r,
                        &robot,
                    )
                    .expect("tick");
                sim.send(JointCommand::Velocity(out.qdot)).expect("finite");
                sim.step(dt);
                targets.push(v2r.pose(&pose));
                let q_true: Vec<f64> = sim.true_positions().iter().copied().collect();
                actual.push(Mapper::measured_object(&robot, &q_true));
            }
            pose_rmse(&targets, &actual).expect("same length")
        };
        // Gain against accuracy, as the docs report it (the default is 10 /s).
        let sweep: Vec<(f64, f64)> = [2.0, 5.0, 10.0, 20.0]
            .into_iter()
            .map(|g| (g, run_with(MappingMode::ClosedLoop, g)[0]))
            .collect();
        eprintln!("closed-loop gain (1/s) -> position RMSE (m): {sweep:?}");
        assert!(sweep.windows(2).all(|w| w[1].1 < w[0].1), "{sweep:?}");
        let run = |mode| run_with(mode, MappingSettings::default().gain);
        let open = run(MappingMode::Paper);
        let closed = run(MappingMode::ClosedLoop);
        assert!(
            closed[0] < 0.005,
            "closed loop position RMSE {} m",
            closed[0]
        );
        assert!(
            closed[1..].iter().all(|&d| d < 1.0),
            "closed loop angles {closed:?}"
        );
        eprintln!("position, roll, pitch, yaw RMSE: paper {open:?}, closed loop {closed:?}");
        assert!(closed[0] < open[0], "closed {closed:?} vs open {open:?}");
    }

    #[test]
    fn rmse_of_a_known_offset() {
        let t = vec![Isometry3::identity(); 3];
        let a = vec![
            Isometry3::from_parts(
                Translation3::new(0.003, 0.004, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 2f64.to_radians()),
            );
            3
        ];
        let r = pose_rmse(&t, &a).expect("sizes");
        assert!((r[0] - 0.005).abs() < 1e-12);
        assert!((r[3] - 2.0).abs() < 1e-9 && r[1].abs() < 1e-9);
        assert!(pose_rmse(&t, &a[..2]).is_none());
        assert!(pose_rmse(&[], &[]).is_none());
        // The running sums: the same figures, a pair that is not finite left out.
        let mut errors = PoseErrors::default();
        for (t, a) in t.iter().zip(&a) {
            errors.push(t, a);
        }
        errors.push(&t[0], &Isometry3::translation(f64::NAN, 0.0, 0.0));
        assert_eq!((errors.len(), errors.rmse()), (3, Some(r)));
    }
}
