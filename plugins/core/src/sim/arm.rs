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

/// The simulated robot with a gripper and the real objects (one for pouring, a chess set's
/// pieces for pick and place).
pub struct SimArm {
    robot: SimRobot,
    model: Arc<RobotModel>,
    base: Isometry3<f64>,
    tcp: LinkId,
    closed: bool,
    /// Never empty.
    objects: Vec<CarriedObject>,
    /// The object the gripper holds (an index into `objects`).
    holding: Option<usize>,
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
            objects: vec![object],
            holding: None,
        }
    }

    /// A simulated arm with several real objects: a closing gripper takes the one whose
    /// reference point is nearest its tool point, within that object's grasp radius. Errors
    /// (naming the backend) for an empty list.
    pub fn with_objects(
        robot: SimRobot,
        model: Arc<RobotModel>,
        base: Isometry3<f64>,
        tcp: LinkId,
        objects: Vec<CarriedObject>,
    ) -> Result<Self, RobotError> {
        if objects.is_empty() {
            return Err(RobotError {
                robot: "simulated arm".into(),
                message: "no real object to simulate".into(),
            });
        }
        Ok(Self {
            robot,
            model,
            base,
            tcp,
            closed: false,
            objects,
            holding: None,
        })
    }

    /// Every real object (the truth), in the order given.
    pub fn objects(&self) -> &[CarriedObject] {
        &self.objects
    }

    /// The object the gripper holds, if any (an index into [`SimArm::objects`]).
    pub fn holding(&self) -> Option<usize> {
        self.holding
    }

    /// The simulated robot (true joint positions, time).
    pub fn robot(&self) -> &SimRobot {
        &self.robot
    }

    /// The real object (the first, where there are several).
    pub fn object(&self) -> &CarriedObject {
        &self.objects[0]
    }

    /// Whether the gripper is closed.
    pub fn gripper_closed(&self) -> bool {
        self.closed
    }

    fn update_object(&mut self) {
        let q: Vec<f64> = self.robot.true_positions().iter().copied().collect();
        let tool = self.model.forward_kinematics(&self.base, &q)[self.tcp];
        match (self.closed, self.holding) {
            (true, Some(i)) => {
                let o = &mut self.objects[i];
                if let Some(held) = o.held {
                    o.pose = tool * held;
                }
            }
            (true, None) => {
                let p = tool.translation.vector;
                let nearest = self
                    .objects
                    .iter()
                    .enumerate()
                    .map(|(i, o)| (i, (p - o.pose.translation.vector).norm()))
                    .filter(|&(i, d)| d <= self.objects[i].grasp_radius_m)
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                if let Some((i, _)) = nearest {
                    let o = &mut self.objects[i];
                    o.held = Some(tool.inverse() * o.pose);
                    self.holding = Some(i);
                }
            }
            (false, Some(i)) => {
                // Released: it drops onto the table, upright, where it is.
                let o = &mut self.objects[i];
                o.held = None;
                let (_, _, yaw) = o.pose.rotation.euler_angles();
                let p = o.pose.translation.vector;
                o.pose = Isometry3::from_parts(
                    Translation3::new(p.x, p.y, o.rest_z),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
                );
                self.holding = None;
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
        Some(self.objects[self.holding.unwrap_or(0)].pose)
    }

    fn simulated(&self) -> Option<&SimRobot> {
        Some(&self.robot)
    }
}
