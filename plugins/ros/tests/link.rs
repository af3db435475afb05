//! The ROS 1 link against a real ROS master (Debian's `rosmaster`) and a simulated Sawyer
//! node (`src/testing/fake_sawyer.py`, rospy, Intera's topics): joint states in, velocity
//! commands out with the md5 sums the robot checks, the robot's state obeyed, a dead link
//! noticed and recovered from. `scripts/setup.sh` installs the ROS packages.

use std::time::{Duration, Instant};

use avatarm_core::sim::arm::RobotInterface;
use avatarm_ros::testing::{self as support, FakeSawyer, Master, wall_s};
use avatarm_ros::{LinkSettings, RosArm};
use nalgebra::DVector;

const ARM: [&str; 7] = [
    "right_j0", "right_j1", "right_j2", "right_j3", "right_j4", "right_j5", "right_j6",
];

fn link(master: &Master) -> RosArm {
    RosArm::start(
        LinkSettings::sawyer(&master.uri),
        ARM.iter().map(|s| (*s).to_owned()).collect(),
        DVector::zeros(7),
    )
    .expect("link")
}

/// Runs the link for `secs` (advance + receive every 5 ms on the wall clock as the app's),
/// sending `qdot` each tick when given; returns the joint states received and the sends
/// refused.
fn pump(
    arm: &mut RosArm,
    secs: f64,
    qdot: Option<&DVector<f64>>,
) -> (Vec<avatarm_core::sim::JointState>, Vec<String>) {
    let (mut states, mut refused) = (Vec::new(), Vec::new());
    let end = Instant::now() + Duration::from_secs_f64(secs);
    while Instant::now() < end {
        arm.advance(wall_s());
        states.extend(arm.receive());
        if let Some(q) = qdot
            && let Err(e) = arm.send(q)
        {
            refused.push(e.to_string());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    (states, refused)
}

fn wait_until(arm: &mut RosArm, what: &str, mut ok: impl FnMut(&RosArm) -> bool) {
    let started = Instant::now();
    while !ok(arm) {
        assert!(
            started.elapsed() < Duration::from_secs(15),
            "timed out waiting for {what}: {:?}",
            arm.status()
        );
        pump(arm, 0.05, None);
    }
}

fn velocity(j0: f64) -> DVector<f64> {
    let mut v = DVector::zeros(7);
    v[0] = j0;
    v
}

#[test]
fn joint_states_flow_in_commands_reach_the_robot_and_its_clock_is_mapped() {
    let _serial = support::serial();
    let master = Master::start();
    let robot_ahead_s = 1234.5;
    let sawyer = FakeSawyer::start(&master, robot_ahead_s);
    let mut arm = link(&master);
    wait_until(&mut arm, "the robot's state", |a| {
        a.alive() && a.status().robot.is_some()
    });

    // Joint states at the robot's rate, stamped on its clock and mapped onto ours.
    let (states, _) = pump(&mut arm, 2.0, None);
    let span = states.last().expect("states").stamp_s - states[0].stamp_s;
    let rate = (states.len() - 1) as f64 / span;
    let status = arm.status();
    let (offset, jitter) = status.clock_offset_s.expect("offset");
    eprintln!(
        "joint states: {} in {span:.2} s = {rate:.1} Hz; clock offset {offset:.4} s (robot {robot_ahead_s} s ahead), jitter {:.2} ms",
        states.len(),
        jitter * 1e3
    );
    assert!(rate >= 95.0, "{rate} Hz");
    assert!(
        (offset + robot_ahead_s).abs() < 0.002,
        "offset {offset} vs {}",
        -robot_ahead_s
    );
    // The same against this machine's clock, as the status line says it.
    let (ahead, _) = status.robot_minus_local_s.expect("robot minus local");
    assert!((ahead - robot_ahead_s).abs() < 0.002, "{ahead}");
    let line = status.line();
    eprintln!("status: {line}");
    assert!(
        line.contains("ROS link up")
            && line.contains("robot enabled")
            && (line.contains("robot clock +123449") || line.contains("robot clock +123450")),
        "{line}"
    );
    let now = wall_s();
    let last = states.last().expect("states").stamp_s;
    assert!(
        (now - last).abs() < 0.1,
        "stamps on our clock: {last} vs {now}"
    );

    // Velocity commands: the robot moves (the md5 sums agree), the latched settings are set.
    let (_, refused) = pump(&mut arm, 1.0, Some(&velocity(0.2)));
    assert!(refused.is_empty(), "{refused:?}");
    let r = sawyer.report();
    eprintln!(
        "fake Sawyer after 1 s at 0.2 rad/s: {} commands, j0 {:.3} rad, latency median {} ms, p95 {} ms",
        r["commands"], r["q"][0], r["latency_ms_median"], r["latency_ms_p95"]
    );
    assert_eq!(r["md5"], "c8c85922d297da6209a089a906207e5d");
    assert!(r["commands"].as_u64().is_some_and(|n| n >= 50), "{r}");
    let j0 = r["q"][0].as_f64().expect("q");
    assert!((0.14..=0.26).contains(&j0), "j0 {j0}");
    assert_eq!(r["timeout_s"].as_f64(), Some(0.2));
    assert_eq!(r["speed_ratio"].as_f64(), Some(0.3));
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");

    // Commands stop: the robot holds within its timeout.
    pump(&mut arm, 0.5, None);
    let r = sawyer.report();
    assert!(r["holds"].as_u64().is_some_and(|n| n >= 1), "{r}");
    assert_eq!(r["velocity"][0].as_f64(), Some(0.0));

    // A NaN never leaves Avatarm.
    let before = r["commands"].as_u64();
    let mut bad = velocity(0.1);
    bad[3] = f64::NAN;
    let e = arm.send(&bad).expect_err("NaN refused");
    assert!(e.to_string().contains("right_j3"), "{e}");
    pump(&mut arm, 0.3, None);
    let r = sawyer.report();
    // At most the one zero-velocity stop a refusal after a moving command sends (unless the
    // link went stale first and sent it then); nothing malformed, nothing moving.
    assert!(
        r["commands"]
            .as_u64()
            .zip(before)
            .is_some_and(|(n, b)| n <= b + 1),
        "{r}"
    );
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
    assert!(
        r["velocity"]
            .as_array()
            .is_some_and(|v| v.iter().all(|x| x.as_f64() == Some(0.0))),
        "{r}"
    );

    // The gripper closes (the link pumped first: a report was waited for without it).
    pump(&mut arm, 0.05, None);
    arm.gripper(&avatarm_core::teleop::mapping::GripperCommand {
        closed: true,
        force_n: 10.0,
    })
    .expect("gripper");
    pump(&mut arm, 0.3, None);
    assert_eq!(sawyer.report()["gripper_m"].as_f64(), Some(0.0));
}

#[test]
fn a_stopped_or_disabled_robot_gets_no_command() {
    let _serial = support::serial();
    let master = Master::start();
    let sawyer = FakeSawyer::start(&master, 0.0);
    let mut arm = link(&master);
    wait_until(&mut arm, "the robot's state", |a| {
        a.alive() && a.status().robot.is_some_and(|r| r.enabled)
    });
    // E-stop.
    sawyer.signal("-USR1");
    wait_until(&mut arm, "the e-stop", |a| {
        a.status().robot.is_some_and(|r| r.stopped)
    });
    let (_, refused) = pump(&mut arm, 0.5, Some(&velocity(0.2)));
    assert!(
        !refused.is_empty() && refused.iter().all(|e| e.contains("stopped")),
        "{refused:?}"
    );
    let r = sawyer.report();
    assert_eq!(r["ignored"].as_u64(), Some(0), "nothing was sent: {r}");
    assert_eq!(r["commands"].as_u64(), Some(0));
    // Released: commands flow.
    sawyer.signal("-USR1");
    wait_until(&mut arm, "the release", |a| {
        a.status().robot.is_some_and(|r| !r.stopped)
    });
    let (_, refused) = pump(&mut arm, 0.5, Some(&velocity(0.2)));
    assert!(refused.is_empty(), "{refused:?}");
    assert!(sawyer.report()["commands"].as_u64().is_some_and(|n| n > 0));
    // Disabled.
    sawyer.signal("-USR2");
    wait_until(&mut arm, "disabling", |a| {
        a.status().robot.is_some_and(|r| !r.enabled)
    });
    pump(&mut arm, 0.3, None);
    let before = sawyer.report()["commands"].as_u64();
    let (_, refused) = pump(&mut arm, 0.5, Some(&velocity(0.2)));
    assert!(
        !refused.is_empty() && refused.iter().all(|e| e.contains("not enabled")),
        "{refused:?}"
    );
    let r = sawyer.report();
    assert_eq!(r["commands"].as_u64(), before);
    // The arm was moving: the first refusal sent zero velocities once, nothing else.
    assert!(r["ignored"].as_u64().is_some_and(|n| n <= 1), "{r}");
    assert_eq!(r["ignored_max_speed"].as_f64(), Some(0.0), "{r}");
}

#[test]
fn a_dead_robot_node_stops_the_commands_and_a_restarted_one_is_taken_back() {
    let _serial = support::serial();
    let master = Master::start();
    let sawyer = FakeSawyer::start(&master, 0.0);
    let mut arm = link(&master);
    wait_until(&mut arm, "the robot", |a| {
        a.alive() && a.status().robot.is_some()
    });
    let (_, refused) = pump(&mut arm, 0.3, Some(&velocity(0.1)));
    assert!(refused.is_empty(), "{refused:?}");

    // The node dies: commands stop within the link's stale time.
    let losses = arm.status().losses;
    drop(sawyer);
    let killed = Instant::now();
    let mut stopped_after = None;
    while killed.elapsed() < Duration::from_secs(2) {
        arm.advance(wall_s());
        arm.receive();
        if arm.send(&velocity(0.1)).is_err() && stopped_after.is_none() {
            stopped_after = Some(killed.elapsed().as_secs_f64());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let stopped_after = stopped_after.expect("commands refused once the link died");
    eprintln!(
        "commands refused {:.0} ms after the robot node died",
        stopped_after * 1e3
    );
    assert!(stopped_after <= 0.5, "{stopped_after}");
    let status = arm.status();
    assert_eq!(status.losses, losses + 1, "said once: {status:?}");

    // It comes back: joint states and commands flow again, without restarting Avatarm.
    let sawyer = FakeSawyer::start(&master, 0.0);
    wait_until(&mut arm, "the robot back", |a| a.alive());
    let (_, refused) = pump(&mut arm, 0.5, Some(&velocity(0.1)));
    assert!(refused.len() < 10, "{refused:?}");
    assert!(sawyer.report()["commands"].as_u64().is_some_and(|n| n > 0));
}

#[test]
fn a_restarted_master_is_registered_with_again() {
    let _serial = support::serial();
    let master = Master::start();
    let sawyer = FakeSawyer::start(&master, 0.0);
    let mut arm = link(&master);
    wait_until(&mut arm, "the robot", |a| a.alive());
    // The master and the robot's node restart (rospy does not register again with a new
    // master either); Avatarm's node registers again by itself.
    let port = master.port();
    drop(sawyer);
    drop(master);
    std::thread::sleep(Duration::from_millis(500));
    let master = Master::start_on(port);
    let sawyer = FakeSawyer::start(&master, 0.0);
    // Commands go out once the new connection has both the joint states and the robot's state
    // (each subscription connects to its publisher on its own; the state comes at 10 Hz): the
    // test once pumped as soon as joint states came back, and the 80 ms before the robot's state
    // arrived gave 16 refusals ("no robot state received yet").
    wait_until(&mut arm, "the robot through the new master", |a| {
        a.alive() && a.status().connects >= 2 && a.status().robot.is_some()
    });
    let (_, refused) = pump(&mut arm, 0.5, Some(&velocity(0.1)));
    assert!(refused.len() < 10, "{refused:?}");
    assert!(sawyer.report()["commands"].as_u64().is_some_and(|n| n > 0));
}

#[test]
fn the_gripper_is_found_from_the_io_config_and_the_joint_state_rate_is_set() {
    let _serial = support::serial();
    let master = Master::start();
    // A gripper device that is not Intera's default name (a ClickSmart plate's serial).
    let device = "stp_021709TP00378";
    let sawyer = FakeSawyer::start_with(&master, 0.0, "", &["--gripper-device", device]);
    let settings = LinkSettings {
        joint_state_rate: Some(("/robot/joint_state_publish_rate".into(), 200)),
        ..LinkSettings::sawyer(&master.uri)
    };
    let mut arm = RosArm::start(
        settings,
        ARM.iter().map(|s| (*s).to_owned()).collect(),
        DVector::zeros(7),
    )
    .expect("link");
    // A close command before the device is known waits for it.
    wait_until(&mut arm, "the robot", |a| {
        a.alive() && a.status().robot.is_some()
    });
    arm.gripper(&avatarm_core::teleop::mapping::GripperCommand {
        closed: true,
        force_n: 10.0,
    })
    .expect("gripper");
    wait_until(&mut arm, "the gripper closed on its state", |a| {
        a.status()
            .gripper
            .is_some_and(|g| g.position_m.is_some_and(|p| p < 1e-3) && g.gripping == Some(true))
    });
    let g = arm.status().gripper.expect("gripper");
    assert_eq!(g.device, device);
    assert_eq!((g.calibrated, g.error), (Some(true), Some(false)));
    let r = sawyer.report();
    assert_eq!(r["gripper_commands"].as_u64(), Some(1), "{r}");

    // The joint-state rate Avatarm set, measured on the stamps.
    assert_eq!(r["rate_hz"].as_f64(), Some(200.0), "{r}");
    let (states, _) = pump(&mut arm, 2.0, None);
    let span = states.last().expect("states").stamp_s - states[0].stamp_s;
    let rate = (states.len() - 1) as f64 / span;
    let status = arm.status();
    eprintln!(
        "joint states at {rate:.1} Hz after setting 200 Hz; status: {}",
        status.line()
    );
    assert!(rate >= 190.0, "{rate} Hz");
    assert!(
        status.joint_state_rate_hz.is_some_and(|hz| hz >= 150.0),
        "{status:?}"
    );
    assert!(
        status
            .line()
            .contains(&format!("gripper {device} 0.000 m gripping"))
    );
}

#[test]
fn settings_that_cannot_work_are_refused_before_connecting() {
    let base = LinkSettings::sawyer("http://localhost:1");
    let names: Vec<String> = ARM.iter().map(|s| (*s).to_owned()).collect();
    for (settings, want) in [
        (
            LinkSettings {
                joint_state_rate: Some(("/robot/joint_state_publish_rate".into(), 0)),
                ..base.clone()
            },
            "0 Hz",
        ),
        (
            LinkSettings {
                gripper: Some(avatarm_ros::GripperLink {
                    device: Some("/io/end_effector/right_gripper".into()),
                    ..Default::default()
                }),
                ..base.clone()
            },
            "must be a name",
        ),
    ] {
        let e = RosArm::start(settings, names.clone(), DVector::zeros(7))
            .err()
            .expect("refused");
        assert!(e.to_string().contains(want), "{e}");
    }
}

/// A link to the simulated arm under ros_control (`fake_sawyer.py --ros-control`), its group
/// controller's joints in the reverse of the arm's order.
fn ros_control_link(master: &Master, position: bool) -> RosArm {
    let joints: Vec<String> = ARM.iter().rev().map(|s| (*s).to_owned()).collect();
    let command = if position {
        avatarm_ros::CommandKind::GroupPosition { joints }
    } else {
        avatarm_ros::CommandKind::GroupVelocity { joints }
    };
    RosArm::start(
        LinkSettings {
            joint_states_topic: "/joint_states".into(),
            command_topic: "/arm_controller/command".into(),
            command,
            robot_state_topic: None,
            command_timeout_topic: None,
            speed_ratio: None,
            gripper: None,
            joint_state_rate: None,
            ..LinkSettings::sawyer(&master.uri)
        },
        ARM.iter().map(|s| (*s).to_owned()).collect(),
        DVector::zeros(7),
    )
    .expect("link")
}

fn j0_and_j6(j0: f64, j6: f64) -> DVector<f64> {
    let mut v = DVector::zeros(7);
    v[0] = j0;
    v[6] = j6;
    v
}

#[test]
fn a_ros_control_velocity_controller_gets_velocities_in_its_order_and_a_stop_at_the_end() {
    let _serial = support::serial();
    let master = Master::start();
    let arm_node = FakeSawyer::start_with(&master, 0.0, "", &["--ros-control", "velocity"]);
    let mut arm = ros_control_link(&master, false);
    wait_until(&mut arm, "the arm's joint states", |a| a.alive());
    let (_, refused) = pump(&mut arm, 1.0, Some(&j0_and_j6(0.2, -0.3)));
    assert!(refused.is_empty(), "{refused:?}");
    let r = arm_node.report();
    eprintln!("ros_control velocity after 1 s: {r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
    let (j0, j6) = (
        r["q"][0].as_f64().expect("q"),
        r["q"][6].as_f64().expect("q"),
    );
    assert!(
        (0.14..=0.26).contains(&j0),
        "j0 {j0}: by name through the controller's order"
    );
    assert!((-0.39..=-0.21).contains(&j6), "j6 {j6}");
    // The controller keeps its last command for ever: the link's end sends zeros, and the
    // drop waits for them to go out (an app that exits next would otherwise lose them).
    drop(arm);
    let before = arm_node.report();
    std::thread::sleep(Duration::from_millis(300));
    let after = arm_node.report();
    assert!(
        before["velocity"]
            .as_array()
            .is_some_and(|v| v.iter().all(|x| x.as_f64() == Some(0.0))),
        "{before}"
    );
    assert_eq!(before["q"], after["q"], "the arm stays where it stopped");
}

#[test]
fn a_ros_control_position_controller_gets_integrated_targets_and_holds_them() {
    let _serial = support::serial();
    let master = Master::start();
    let arm_node = FakeSawyer::start_with(&master, 0.0, "", &["--ros-control", "position"]);
    let mut arm = ros_control_link(&master, true);
    wait_until(&mut arm, "the arm's joint states", |a| a.alive());
    let (_, refused) = pump(&mut arm, 1.0, Some(&j0_and_j6(0.2, -0.3)));
    assert!(refused.is_empty(), "{refused:?}");
    let r = arm_node.report();
    eprintln!("ros_control position after 1 s: {r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
    let (j0, j6) = (
        r["q"][0].as_f64().expect("q"),
        r["q"][6].as_f64().expect("q"),
    );
    assert!((0.14..=0.26).contains(&j0), "j0 {j0}");
    assert!((-0.39..=-0.21).contains(&j6), "j6 {j6}");
    let t0 = r["target"][0].as_f64().expect("target");
    assert!(
        (t0 - j0).abs() < 0.02,
        "the arm follows its target: {t0} vs {j0}"
    );
    // A refused command (NaN) holds the last target; so does the link's end.
    let mut bad = j0_and_j6(0.2, 0.0);
    bad[2] = f64::NAN;
    assert!(arm.send(&bad).is_err());
    pump(&mut arm, 0.3, None);
    let held = arm_node.report();
    drop(arm);
    std::thread::sleep(Duration::from_millis(400));
    let end = arm_node.report();
    let moved = (end["q"][0].as_f64().expect("q") - held["q"][0].as_f64().expect("q")).abs();
    assert!(moved < 0.01, "held: {held} then {end}");
    assert_eq!(end["bad"].as_u64(), Some(0), "{end}");
}
