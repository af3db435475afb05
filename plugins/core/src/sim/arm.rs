//! The robot behind the mapping: one trait for every backend ([`RobotInterface`]), its error
//! ([`RobotError`]), and the simulated arm ([`SimArm`]).
//!
//! A real backend (Intera SDK over ROS for the Sawyer, or any arm that takes joint velocities)
//! implements [`RobotInterface`]; the embedded default is [`SimArm`]: the simulated robot of
//! [`crate::sim`] (command and state latency, first-order response, limits) with a
//! gripper that carries the real object rigidly while closed around it. The simulated arm also
//! knows the ground truth that no real set-up has: where the real object really is.

use std::sync::Arc;

use nalgebra::{DVector, Isometry3, Translation3, UnitQuaternion};

use crate::robot::{LinkId, RobotModel};
use crate::sim::{JointCommand, JointState, SimRobot};
use crate::teleop::mapping::GripperCommand;

/// A robot backend refused a command: the backend's name and what it refused and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{robot}: {message}")]
pub struct RobotError {
    /// The backend's name ([`RobotInterface::name`]).
    pub robot: String,
    /// What it refused and why.
    pub message: String,
}

/// A robot arm that takes joint velocity commands and reports joint states.
///
/// When commands stop arriving the robot must hold still (the Sawyer reverts to position mode
/// after its command timeout); the mapping stops the stream only after a held zero command.
pub trait RobotInterface: Send + Sync + 'static {
    /// Name, for messages.
    fn name(&self) -> &str;
    /// Joint states received since the last call, oldest first.
    fn receive(&mut self) -> Vec<JointState>;
    /// Sends joint velocities (all joints, the model's order, rad/s or m/s). Errors name the
    /// backend and what was refused.
    fn send(&mut self, qdot: &DVector<f64>) -> Result<(), RobotError>;
    /// Sends a gripper command.
    fn gripper(&mut self, command: &GripperCommand) -> Result<(), RobotError>;
    /// Called once per control tick with the app clock: hardware backends pump their I/O here,
    /// the simulated arm advances its physics to `now_s`.
    fn advance(&mut self, _now_s: f64) {}
    /// The link's state in one line (connection, robot enabled or stopped, rates, clocks),
    /// for the preview's status line and the end of a run; `None` where there is no link
    /// (simulation).
    fn status_line(&self) -> Option<String> {
        None
    }
    /// The real object's true pose, where the backend knows it (simulation only).
    fn true_object_pose(&self) -> Option<Isometry3<f64>> {
        None
    }
    /// The simulated robot itself, for a simulated room to render (simulation only).
    fn simulated(&self) -> Option<&SimRobot> {
        None
    }
}

/// The real object as the simulated gripper carries it: rigidly attached while the gripper is
/// closed around it, resting upright on the table otherwise. No more physics than the pouring
/// task needs.
#[derive(Debug, Clone, PartialEq)]
pub struct CarriedObject {
    /// Pose of the object's reference frame (its centre, z up at rest).
    pub pose: Isometry3<f64>,
    /// Height of that frame above the world origin when the object rests on the table.
    pub rest_z: f64,
    /// The gripper takes the object when its tool point is within this distance (m).
    pub grasp_radius_m: f64,
    /// Pose of the object in the tool frame while held.
    pub held: Option<Isometry3<f64>>,
}

/// The simulated robot with a gripper and the real object.
pub struct SimArm {
    robot: SimRobot,
    model: Arc<RobotModel>,
    base: Isometry3<f64>,
    tcp: LinkId,
    closed: bool,
    object: CarriedObject,
}

impl SimArm {
    /// A simulated arm whose tool link is `tcp`, with the real object.
    pub fn new(
        robot: SimRobot,
        model: Arc<RobotModel>,
        base: Isometry3<f64>,
        tcp: LinkId,
        object: CarriedObject,
    ) -> Self {
        Self {
            robot,
            model,
            base,
            tcp,
            closed: false,
            object,
        }
    }

    /// The simulated robot (true joint positions, time).
    pub fn robot(&self) -> &SimRobot {
        &self.robot
    }

    /// The real object.
    pub fn object(&self) -> &CarriedObject {
        &self.object
    }

    /// Whether the gripper is closed.
    pub fn gripper_closed(&self) -> bool {
        self.closed
    }

    fn update_object(&mut self) {
        let q: Vec<f64> = self.robot.true_positions().iter().copied().collect();
        let tool = self.model.forward_kinematics(&self.base, &q)[self.tcp];
        let o = &mut self.object;
        match (self.closed, o.held) {
            (true, Some(held)) => o.pose = tool * held,
            (true, None) => {
                if (tool.translation.vector - o.pose.translation.vector).norm() <= o.grasp_radius_m
                {
                    o.held = Some(tool.inverse() * o.pose);
                }
            }
            (false, Some(_)) => {
                // Released: it drops onto the table, upright, where it is.
                o.held = None;
                let (_, _, yaw) = o.pose.rotation.euler_angles();
                let p = o.pose.translation.vector;
                o.pose = Isometry3::from_parts(
                    Translation3::new(p.x, p.y, o.rest_z),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
                );
            }
            (false, None) => {}
        }
    }
}

impl RobotInterface for SimArm {
    fn name(&self) -> &str {
        "simulated arm"
    }

    fn receive(&mut self) -> Vec<JointState> {
        self.robot.receive()
    }

    fn send(&mut self, qdot: &DVector<f64>) -> Result<(), RobotError> {
        self.robot
            .send(JointCommand::Velocity(qdot.clone()))
            .map_err(|e| RobotError {
                robot: self.name().to_owned(),
                message: e.to_string(),
            })
    }

    fn gripper(&mut self, command: &GripperCommand) -> Result<(), RobotError> {
        if !command.force_n.is_finite() {
            return Err(RobotError {
                robot: self.name().to_owned(),
                message: format!("gripper force {} is not finite", command.force_n),
            });
        }
        // The object is taken or let go at the next `advance` (the next tick).
        self.closed = command.closed;
        Ok(())
    }

    fn advance(&mut self, now_s: f64) {
        let dt = now_s - self.robot.time_s();
        if dt > 0.0 {
            self.robot.step(dt);
        }
        self.update_object();
    }

    fn true_object_pose(&self) -> Option<Isometry3<f64>> {
        Some(self.object.pose)
    }

    fn simulated(&self) -> Option<&SimRobot> {
        Some(&self.robot)
    }
}
