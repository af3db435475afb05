//! The link's settings: the command topic's kind, the ROS names, the timeouts and the gripper.

/// How commands are sent.
#[derive(Debug, Clone, PartialEq)]
pub enum CommandKind {
    /// Intera's `intera_core_msgs/JointCommand` in velocity mode, joints by name.
    InteraVelocity,
    /// ros_control's joint group velocity controller: `std_msgs/Float64MultiArray` with one
    /// value per joint of `joints`, in that order (the controller's).
    GroupVelocity {
        /// The controller's joints, in its order.
        joints: Vec<String>,
    },
    /// ros_control's joint group position controller: `std_msgs/Float64MultiArray` of
    /// position targets, one per joint of `joints`, in that order. The velocities Avatarm
    /// commands are integrated into the targets (`target += q̇ Δt`, Δt the time between two
    /// commands, at most the link's stale time), starting from the measured positions after
    /// every stop; a stop holds the last target.
    GroupPosition {
        /// The controller's joints, in its order.
        joints: Vec<String>,
    },
    /// ros2_control's `joint_trajectory_controller` (ROS 2 only), streamed: each command a
    /// `trajectory_msgs/msg/JointTrajectory` of one point for `joints` (named, in this order),
    /// header stamp zero (start on receipt), positions only (the controller interpolates
    /// from its state): where the arm is to be `horizon_s` from now, `q_measured + q̇ ·
    /// horizon_s` (anchored to the newest joint state, so a slowed or blocked arm is never
    /// sent further than that), clamped into `limits`. The controller holds a point once it is
    /// reached, so an Avatarm that falls silent (a crash, a kill) leaves the arm stopped within
    /// `horizon_s`; a stop sends the measured positions.
    JointTrajectory {
        /// The controller's joints (its `joints` parameter).
        joints: Vec<String>,
        /// How far ahead each point lies (s, within 0.01..5): the point's `time_from_start`.
        horizon_s: f64,
        /// Each joint's position limits `(lower, upper)` (rad or m; the description's), in the
        /// order of `joints`; empty: none.
        limits: Vec<(f64, f64)>,
    },
}

impl CommandKind {
    /// The controller's joints (ros_control), `None` for Intera's.
    pub fn controller_joints(&self) -> Option<&[String]> {
        match self {
            Self::InteraVelocity => None,
            Self::GroupVelocity { joints }
            | Self::GroupPosition { joints }
            | Self::JointTrajectory { joints, .. } => Some(joints),
        }
    }
}

/// Where the robot is on ROS and how Avatarm talks to it.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSettings {
    /// The master (`ROS_MASTER_URI`), e.g. `http://localhost:11311`.
    pub master_uri: String,
    /// This node's name.
    pub node_name: String,
    /// `sensor_msgs/JointState` in (Intera: `/robot/joint_states`).
    pub joint_states_topic: String,
    /// Commands out (Intera: `/robot/limb/right/joint_command`).
    pub command_topic: String,
    /// The command message.
    pub command: CommandKind,
    /// The joints commanded (Intera: `right_j0`..`right_j6`), matched to the model by name.
    pub arm_joints: Vec<String>,
    /// Intera's `/robot/state` (`intera_core_msgs/RobotAssemblyState`): no command unless
    /// enabled and not stopped. `None`: the robot has no such state (ros_control).
    pub robot_state_topic: Option<String>,
    /// Latched `std_msgs/Float64` the robot's command timeout is set on (Intera:
    /// `/robot/limb/right/joint_command_timeout`).
    pub command_timeout_topic: Option<String>,
    /// The robot's command timeout (s): with no command for longer, it holds position.
    pub command_timeout_s: f64,
    /// Latched `std_msgs/Float64` speed ratio of position moves (Intera:
    /// `/robot/limb/right/set_speed_ratio`), and its value (0..1).
    pub speed_ratio: Option<(String, f64)>,
    /// Intera's electric gripper (an IO device of the end effector's IO node).
    pub gripper: Option<GripperLink>,
    /// Latched `std_msgs/UInt16` the robot's joint-state rate is set on (Intera:
    /// `/robot/joint_state_publish_rate`), and the rate (Hz). `None`: the robot's own rate.
    pub joint_state_rate: Option<(String, u16)>,
    /// The link is lost when no joint state arrived for this long (s).
    pub stale_after_s: f64,
    /// ROS 2 (DDS or rmw_zenoh) instead of ROS 1 (`master_uri` unused): a ros2_control arm
    /// (feature `ros2`).
    pub ros2: Option<Ros2Transport>,
}

impl LinkSettings {
    /// A right-arm Sawyer through Intera (topics as Intera names them), its master at
    /// `master_uri`.
    pub fn sawyer(master_uri: &str) -> Self {
        Self {
            master_uri: master_uri.to_owned(),
            node_name: "avatarm".into(),
            joint_states_topic: "/robot/joint_states".into(),
            command_topic: "/robot/limb/right/joint_command".into(),
            command: CommandKind::InteraVelocity,
            arm_joints: (0..7).map(|i| format!("right_j{i}")).collect(),
            robot_state_topic: Some("/robot/state".into()),
            command_timeout_topic: Some("/robot/limb/right/joint_command_timeout".into()),
            command_timeout_s: 0.2,
            speed_ratio: Some(("/robot/limb/right/set_speed_ratio".into(), 0.3)),
            gripper: Some(GripperLink::default()),
            joint_state_rate: None,
            stale_after_s: 0.2,
            ros2: None,
        }
    }

    /// A ros2_control arm over ROS 2 (DDS, domain `domain_id`; `ros2.rmw` for rmw_zenoh):
    /// joint states on `/joint_states`, joint velocities to the `forward_command_controller`
    /// named `controller` (`/<controller>/commands`) in the order of `joints`.
    pub fn ros2_control(controller: &str, joints: Vec<String>, domain_id: u16) -> Self {
        Self {
            master_uri: String::new(),
            node_name: "avatarm".into(),
            joint_states_topic: "/joint_states".into(),
            command_topic: format!("/{}/commands", controller.trim_matches('/')),
            command: CommandKind::GroupVelocity {
                joints: joints.clone(),
            },
            arm_joints: joints,
            robot_state_topic: None,
            command_timeout_topic: None,
            command_timeout_s: 0.2,
            speed_ratio: None,
            gripper: None,
            joint_state_rate: None,
            stale_after_s: 0.2,
            ros2: Some(Ros2Transport {
                domain_id,
                ..Ros2Transport::default()
            }),
        }
    }

    /// The link's name in messages: `ROS robot at MASTER` or `ROS 2 robot (DDS domain N)`
    /// ([`Ros2Transport::describe`]).
    pub fn link_name(&self) -> String {
        match &self.ros2 {
            Some(t) => format!("ROS 2 robot ({})", t.describe()),
            None => format!("ROS robot at {}", self.master_uri),
        }
    }

    pub(crate) fn check(&self) -> Result<(), String> {
        if !(self.command_timeout_s.is_finite() && self.command_timeout_s > 0.0) {
            return Err(format!(
                "command timeout {} s: must be > 0",
                self.command_timeout_s
            ));
        }
        if !(self.stale_after_s.is_finite() && self.stale_after_s > 0.0) {
            return Err(format!("stale_after_s {}: must be > 0", self.stale_after_s));
        }
        if let Some((_, r)) = &self.speed_ratio
            && !(r.is_finite() && *r > 0.0 && *r <= 1.0)
        {
            return Err(format!("speed ratio {r}: must be in (0, 1]"));
        }
        if self.arm_joints.is_empty() {
            return Err("no arm joints to command".into());
        }
        if let Some((topic, 0)) = &self.joint_state_rate {
            return Err(format!("joint-state rate 0 Hz on {topic}: must be > 0"));
        }
        if let Some(GripperLink {
            device: Some(d), ..
        }) = &self.gripper
            && (d.is_empty() || d.contains('/'))
        {
            return Err(format!(
                "gripper device '{d}': must be a name (as the IO node's config gives it)"
            ));
        }
        if let Some(t) = &self.ros2 {
            if t.domain_id > 232 {
                return Err(format!(
                    "domain {}: must be within 0..232 (ROS 2's ROS_DOMAIN_ID)",
                    t.domain_id
                ));
            }
            if self.command.controller_joints().is_none() {
                return Err(
                    "a ROS 2 link commands a ros2_control forward_command_controller or joint_trajectory_controller, not Intera's JointCommand".into(),
                );
            }
            let ros1_only = [
                ("robot state", self.robot_state_topic.is_some()),
                ("command timeout", self.command_timeout_topic.is_some()),
                ("speed ratio", self.speed_ratio.is_some()),
                ("gripper", self.gripper.is_some()),
                ("joint-state rate", self.joint_state_rate.is_some()),
            ];
            if let Some((what, _)) = ros1_only.iter().find(|(_, set)| *set) {
                return Err(format!(
                    "a ROS 2 link has no {what} topic (Intera's, ROS 1): leave it out"
                ));
            }
        }
        if let CommandKind::JointTrajectory {
            horizon_s,
            limits,
            joints,
        } = &self.command
        {
            let horizon_s = *horizon_s;
            if !limits.is_empty() && limits.len() != joints.len() {
                return Err(format!(
                    "{} position limits for {} trajectory joints",
                    limits.len(),
                    joints.len()
                ));
            }
            if let Some((j, (lower, upper))) = joints
                .iter()
                .zip(limits)
                .find(|(_, (l, u))| l.is_nan() || u.is_nan() || l > u)
            {
                return Err(format!(
                    "joint {j}: position limits [{lower}, {upper}] are not a range"
                ));
            }
            if self.ros2.is_none() {
                return Err(
                    "a joint_trajectory_controller is commanded over ROS 2 only (kind = \"ros2_control\")".into(),
                );
            }
            if !(0.01..=5.0).contains(&horizon_s) {
                return Err(format!(
                    "trajectory horizon {horizon_s} s: must be within 0.01..5"
                ));
            }
        }
        if let Some(joints) = self.command.controller_joints() {
            if joints.is_empty() {
                return Err("the controller has no joints".into());
            }
            if let Some((i, j)) = joints
                .iter()
                .enumerate()
                .find(|(i, j)| joints[..*i].contains(j))
            {
                return Err(format!(
                    "the controller's joint '{j}' is listed twice (at {i})"
                ));
            }
        }
        if let Some(joints) = self.command.controller_joints()
            && let Some(j) = joints.iter().find(|j| !self.arm_joints.contains(j))
        {
            return Err(format!(
                "the controller's joint '{j}' is not one of the arm joints"
            ));
        }
        Ok(())
    }
}

/// Intera's electric gripper: an IO device of the end effector's IO node (Intera's IO
/// framework: `{io_node}/config` is an `intera_core_msgs/IONodeConfiguration` naming the
/// devices; a device takes `{io_node}/{device}/command` (`IOComponentCommand`) and reports
/// `{io_node}/{device}/state` (`IODeviceStatus`), as `intera_interface.Gripper` uses them).
#[derive(Debug, Clone, PartialEq)]
pub struct GripperLink {
    /// The IO node (Intera: `/io/end_effector`).
    pub io_node: String,
    /// The device (Intera's electric gripper: `right_gripper`); `None`: the first device the
    /// node's config names, found when the config arrives (it is latched).
    pub device: Option<String>,
}

impl Default for GripperLink {
    fn default() -> Self {
        Self {
            io_node: "/io/end_effector".into(),
            device: None,
        }
    }
}
/// Which ROS 2 middleware (RMW) carries the nodes, as `RMW_IMPLEMENTATION` chooses it for a
/// ROS 2 process.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Rmw {
    /// DDS (rmw_cyclonedds_cpp, rmw_fastrtps_cpp, rmw_connextdds: one wire protocol, RTPS).
    #[default]
    Dds,
    /// rmw_zenoh (rmw_zenoh_cpp): a Zenoh session in peer mode that finds the others through
    /// a Zenoh router (`ros2 run rmw_zenoh_cpp rmw_zenohd`).
    Zenoh {
        /// The router's endpoint (e.g. `tcp/192.168.1.10:7447`), which must answer when the
        /// session opens; `None`: rmw_zenoh's own default, `ZENOH_SESSION_CONFIG_URI`'s
        /// config where it is set, else [`Rmw::DEFAULT_ZENOH_ROUTER`] (waited for).
        router: Option<String>,
    },
}

impl Rmw {
    /// rmw_zenoh's default router: on this machine, port 7447.
    pub const DEFAULT_ZENOH_ROUTER: &'static str = "tcp/localhost:7447";

    /// The middleware `RMW_IMPLEMENTATION` names (`rmw_zenoh_cpp`, or one of the DDS ones),
    /// rmw_zenoh through `router`. Errors: another name (naming the ones known).
    pub fn from_implementation(name: &str, router: Option<String>) -> Result<Self, String> {
        match name.trim() {
            "rmw_zenoh_cpp" => Ok(Self::Zenoh { router }),
            ""
            | "rmw_cyclonedds_cpp"
            | "rmw_fastrtps_cpp"
            | "rmw_fastrtps_dynamic_cpp"
            | "rmw_connextdds" => Ok(Self::Dds),
            other => Err(format!(
                "'{other}': rmw_zenoh_cpp, or a DDS one (rmw_cyclonedds_cpp, rmw_fastrtps_cpp, rmw_connextdds)"
            )),
        }
    }
}

/// Where the robot is on ROS 2.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ros2Transport {
    /// The domain (`ROS_DOMAIN_ID`, 0..232): DDS's, or the first chunk of rmw_zenoh's keys.
    pub domain_id: u16,
    /// This node's namespace (`/` for none).
    pub namespace: String,
    /// The middleware.
    pub rmw: Rmw,
}

impl Ros2Transport {
    /// The transport in messages: `DDS domain 3`, `rmw_zenoh domain 3 (router tcp/...)`.
    pub fn describe(&self) -> String {
        match &self.rmw {
            Rmw::Dds => format!("DDS domain {}", self.domain_id),
            Rmw::Zenoh { router: Some(r) } => {
                format!("rmw_zenoh domain {} (router {r})", self.domain_id)
            }
            Rmw::Zenoh { router: None } => match std::env::var("ZENOH_SESSION_CONFIG_URI") {
                Ok(uri) => format!("rmw_zenoh domain {} (session config {uri})", self.domain_id),
                Err(_) => format!(
                    "rmw_zenoh domain {} (router {})",
                    self.domain_id,
                    Rmw::DEFAULT_ZENOH_ROUTER
                ),
            },
        }
    }
}

impl Default for Ros2Transport {
    fn default() -> Self {
        Self {
            domain_id: 0,
            namespace: "/".into(),
            rmw: Rmw::Dds,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Rmw;

    #[test]
    fn rmw_implementation_names_choose_the_middleware() {
        let router = Some("tcp/10.0.0.2:7447".to_owned());
        assert_eq!(
            Rmw::from_implementation("rmw_zenoh_cpp", router.clone()),
            Ok(Rmw::Zenoh { router })
        );
        for dds in [
            "",
            "rmw_cyclonedds_cpp",
            " rmw_fastrtps_cpp\n",
            "rmw_connextdds",
        ] {
            assert_eq!(Rmw::from_implementation(dds, None), Ok(Rmw::Dds), "{dds:?}");
        }
        let e = Rmw::from_implementation("rmw_zenoh", None).expect_err("not a name");
        assert!(
            e.contains("'rmw_zenoh'") && e.contains("rmw_zenoh_cpp"),
            "{e}"
        );
    }
}
