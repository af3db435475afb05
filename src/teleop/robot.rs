//! The robot the live task commands: the simulated arm, or the scene's ROS link (its settings from
//! the scene's `[robot.link]`).

use super::*;

/// The robot a live task commands (`avatarm run --robot`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RobotChoice {
    /// The embedded simulated arm (the simulated room's).
    #[default]
    Sim,
    /// The real robot through the scene's `[robot.link]` (ROS 1, feature `ros`).
    Ros,
}

/// `--robot NAME` for `scene`: `sim`, `ros` (the scene's `[robot.link]`, ROS 1 or ROS 2 as
/// its `kind` says) or `ros2` (the same, checked to be a `ros2_control` link). Errors name
/// `--robot` and the link's kind.
pub fn robot_choice(name: &str, scene: &Scene) -> Result<RobotChoice, AppError> {
    use avatarm_scene::spec::RobotLinkKind;
    match name {
        "sim" => Ok(RobotChoice::Sim),
        "ros" => Ok(RobotChoice::Ros),
        "ros2" if scene.file.robot.link.kind == RobotLinkKind::Ros2Control => Ok(RobotChoice::Ros),
        "ros2" => Err(AppError::flag(
            "--robot ros2",
            format!(
                "the scene's [robot.link] is kind = \"{}\" (ROS 1); a ROS 2 robot needs kind = \"ros2_control\" (docs/robot-ros2.md)",
                match scene.file.robot.link.kind {
                    RobotLinkKind::Intera => "intera",
                    RobotLinkKind::RosControl => "ros_control",
                    RobotLinkKind::Ros2Control => "ros2_control",
                }
            ),
        )),
        other => Err(AppError::flag(
            "--robot",
            format!("'{other}': sim, ros or ros2"),
        )),
    }
}

/// The scene's `[robot.link]` as the ROS link's settings: Intera's topics by default, the
/// master from the scene, else `ROS_MASTER_URI`, else `http://localhost:11311`.
#[cfg(feature = "ros")]
pub fn link_settings(
    scene: &Scene,
    setup: &avatarm_scene::task::TrialSetup,
) -> Result<avatarm_ros::LinkSettings, AppError> {
    use avatarm_ros::{CommandKind, LinkSettings};
    use avatarm_scene::spec::{RobotLinkKind, RosControlController};
    let spec = &scene.file.robot.link;
    let intera = spec.kind == RobotLinkKind::Intera;
    let ros2 = if spec.kind == RobotLinkKind::Ros2Control {
        Some(crate::net::site_camera::ros2_transport(scene)?)
    } else {
        None
    };
    let master_uri = spec
        .master_uri
        .clone()
        .or_else(|| std::env::var("ROS_MASTER_URI").ok())
        .unwrap_or_else(|| "http://localhost:11311".into());
    let sawyer = LinkSettings::sawyer(&master_uri);
    // A topic given (or "" for none), else Intera's where the link is Intera's.
    let topic = |given: &Option<String>, intera_topic: Option<String>| match given {
        Some(t) if t.is_empty() => None,
        Some(t) => Some(t.clone()),
        None if intera => intera_topic,
        None => None,
    };
    let names = setup.model.dof_names();
    let arm_joints: Vec<String> = if spec.arm_joints.is_empty() {
        setup.arm.iter().map(|&i| names[i].to_owned()).collect()
    } else {
        spec.arm_joints.clone()
    };
    let command_topic =
        topic(&spec.command_topic, Some(sawyer.command_topic.clone())).ok_or_else(|| {
            AppError::flag(
                "robot.link.command_topic",
                "a ros_control or ros2_control link needs its controller's command topic",
            )
        })?;
    let joint_states_topic = joint_states_topic(spec, &sawyer.joint_states_topic);
    Ok(LinkSettings {
        master_uri,
        node_name: spec.node_name.clone(),
        joint_states_topic,
        command_topic,
        command: {
            let joints = if spec.controller_joints.is_empty() {
                arm_joints.clone()
            } else {
                spec.controller_joints.clone()
            };
            match (intera, spec.controller) {
                (true, _) => CommandKind::InteraVelocity,
                (false, RosControlController::Velocity) => CommandKind::GroupVelocity { joints },
                (false, RosControlController::Position) => CommandKind::GroupPosition { joints },
                (false, RosControlController::Trajectory) => CommandKind::JointTrajectory {
                    limits: position_limits(&setup.model, &joints),
                    joints,
                    horizon_s: spec.command_timeout_s,
                },
            }
        },
        arm_joints,
        robot_state_topic: topic(&spec.robot_state_topic, sawyer.robot_state_topic.clone()),
        command_timeout_topic: topic(
            &spec.command_timeout_topic,
            sawyer.command_timeout_topic.clone(),
        ),
        command_timeout_s: spec.command_timeout_s,
        speed_ratio: topic(
            &spec.speed_ratio_topic,
            sawyer.speed_ratio.as_ref().map(|(t, _)| t.clone()),
        )
        .map(|t| (t, spec.speed_ratio)),
        gripper: match (&spec.gripper_device, intera) {
            (Some(d), _) if d.is_empty() => None,
            (Some(d), _) => Some(avatarm_ros::GripperLink {
                device: Some(d.clone()),
                ..Default::default()
            }),
            (None, true) => Some(avatarm_ros::GripperLink::default()),
            (None, false) => None,
        },
        joint_state_rate: spec
            .joint_state_rate_hz
            .map(|hz| ("/robot/joint_state_publish_rate".to_owned(), hz)),
        stale_after_s: spec.stale_after_s,
        ros2,
    })
}

/// The position limits `(lower, upper)` of `joints` in `model` (unlimited where the model has
/// no such joint: the link refuses it when it starts).
#[cfg(feature = "ros")]
fn position_limits(model: &avatarm_core::robot::RobotModel, joints: &[String]) -> Vec<(f64, f64)> {
    let limits = model.dof_limits();
    joints
        .iter()
        .map(|j| {
            model
                .dof_index(j)
                .ok()
                .and_then(|i| limits.get(i))
                .map_or((f64::NEG_INFINITY, f64::INFINITY), |l| (l.lower, l.upper))
        })
        .collect()
}

/// The link's joint-state topic: the one given, else ROS 1's `ros1_default` (Intera's
/// `/robot/joint_states`), or `/joint_states` for `ros2_control` (its joint_state_broadcaster's).
#[cfg(feature = "ros")]
fn joint_states_topic(spec: &avatarm_scene::spec::RobotLinkSpec, ros1_default: &str) -> String {
    match (&spec.joint_states_topic, spec.kind) {
        (Some(given), _) => given.clone(),
        // joint_state_broadcaster's, in the link's namespace where it has one.
        (None, avatarm_scene::spec::RobotLinkKind::Ros2Control) if spec.namespace.is_some() => {
            "joint_states".into()
        }
        (None, avatarm_scene::spec::RobotLinkKind::Ros2Control) => "/joint_states".into(),
        (None, _) => ros1_default.into(),
    }
}

#[cfg(feature = "ros")]
pub(super) fn ros_arm(
    scene: &Scene,
    setup: &avatarm_scene::task::TrialSetup,
    q0: &nalgebra::DVector<f64>,
) -> Result<Box<dyn avatarm_core::sim::arm::RobotInterface>, AppError> {
    let settings = link_settings(scene, setup)?;
    if matches!(
        settings.command,
        avatarm_ros::CommandKind::GroupVelocity { .. }
    ) {
        // Nothing on ROS stops it if this process dies (docs/network.md, "When the robot site
        // dies"): said once, where the user reads what the link is.
        bevy::log::warn!(
            "ROS link: a ros_control velocity controller keeps its last command for ever; if this process dies (a crash, a kill, the power) the arm keeps that velocity until its own limits or an e-stop stop it. Prefer controller = \"position\" (it holds its last target) or a controller with a command timeout"
        );
    }
    let names = setup
        .model
        .dof_names()
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
    let arm = avatarm_ros::RosArm::start(settings, names, q0.clone())
        .map_err(|e| AppError::flag("--robot ros", e.to_string()))?;
    Ok(Box::new(arm))
}

#[cfg(not(feature = "ros"))]
pub(super) fn ros_arm(
    _: &Scene,
    _: &avatarm_scene::task::TrialSetup,
    _: &nalgebra::DVector<f64>,
) -> Result<Box<dyn avatarm_core::sim::arm::RobotInterface>, AppError> {
    Err(AppError::flag(
        "--robot ros",
        "this avatarm was built without the ros feature; rebuild with `cargo build --features ros`",
    ))
}

/// The simulated arm's start (the room shows it there from the first frame).
pub(super) fn prepared_q0(teleop: &Teleop) -> Option<nalgebra::DVector<f64>> {
    teleop
        .robot()
        .simulated()
        .map(|r| r.true_positions().clone())
}

#[cfg(all(test, feature = "ros"))]
mod tests {
    use avatarm_scene::spec::{RobotLinkKind, RobotLinkSpec};

    use super::joint_states_topic;

    #[test]
    fn a_given_joint_state_topic_is_kept_whatever_the_links_kind() {
        let of = |kind, given: Option<&str>| {
            let spec = RobotLinkSpec {
                kind,
                joint_states_topic: given.map(str::to_owned),
                ..RobotLinkSpec::default()
            };
            joint_states_topic(&spec, "/robot/joint_states")
        };
        assert_eq!(of(RobotLinkKind::Intera, None), "/robot/joint_states");
        assert_eq!(of(RobotLinkKind::RosControl, None), "/robot/joint_states");
        assert_eq!(of(RobotLinkKind::Ros2Control, None), "/joint_states");
        let namespaced = RobotLinkSpec {
            kind: RobotLinkKind::Ros2Control,
            namespace: Some("/robot1".into()),
            ..RobotLinkSpec::default()
        };
        // Relative: resolved in the namespace (/robot1/joint_states).
        assert_eq!(
            joint_states_topic(&namespaced, "/robot/joint_states"),
            "joint_states"
        );
        // Given as ROS 1's default, on a ROS 2 link: what was given (it was read as the
        // default and replaced by /joint_states).
        assert_eq!(
            of(RobotLinkKind::Ros2Control, Some("/robot/joint_states")),
            "/robot/joint_states"
        );
        assert_eq!(
            of(RobotLinkKind::Intera, Some("/joint_states")),
            "/joint_states"
        );
    }
}
