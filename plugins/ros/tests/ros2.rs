//! The ROS 2 link against a fake ros2_control arm on Cyclone DDS (`src/testing/fake_ros2_arm.py`,
//! PyPI's cyclonedds: the DDS of rmw_cyclonedds_cpp, nothing of Avatarm's) and on rmw_zenoh
//! (the same arm through `rmw_zenoh_peer.py`: PyPI's eclipse-zenoh and rosbags, from
//! rmw_zenoh's design document): joint states in on the arm's own clock, velocities out to its
//! forward_command_controller in the controller's joint order, a stop at the end, a vanished
//! arm noticed, bad commands refused.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use avatarm_core::sim::arm::RobotInterface;
use avatarm_core::tf::chain;
use avatarm_ros::ros2::calibration::gather;
use avatarm_ros::ros2::camera::{CameraEvent, CameraTopic, RosImage, spawn_camera};
use avatarm_ros::ros2::publish::{Outgoing, Ros2Publisher};
use avatarm_ros::testing::{
    self as support, FakeRos2Arm, FakeRos2Camera, Ros2Listener, ZenohRouter, test_domain as domain,
    wall_s,
};
use avatarm_ros::{CommandKind, LinkSettings, Rmw, Ros2Transport, RosArm};
use nalgebra::DVector;

/// The robot model's joints (q order).
const MODEL: [&str; 3] = ["j1", "j2", "j3"];
/// The controller's joints, in its order (not the model's).
const CONTROLLER: [&str; 3] = ["j3", "j1", "j2"];

fn link(domain: u16) -> RosArm {
    link_on(domain, Rmw::Dds)
}

/// The link to the forward_velocity_controller on domain `domain` over `rmw`.
fn link_on(domain: u16, rmw: Rmw) -> RosArm {
    let joints = CONTROLLER.iter().map(|s| (*s).to_owned()).collect();
    let mut settings = LinkSettings::ros2_control("forward_velocity_controller", joints, domain);
    if let Some(t) = settings.ros2.as_mut() {
        t.rmw = rmw;
    }
    RosArm::start(
        settings,
        MODEL.iter().map(|s| (*s).to_owned()).collect(),
        DVector::zeros(3),
    )
    .expect("link")
}

fn wait_alive(arm: &mut RosArm) {
    let started = Instant::now();
    while !arm.alive() {
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "no joint state from the fake arm: {:?}",
            arm.status()
        );
        arm.advance(wall_s());
        arm.receive();
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// `(median, p95)` of `v` (sorted in place).
fn spread(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    (at(0.5), at(0.95))
}

#[test]
fn joint_states_flow_in_and_velocities_reach_a_ros2_control_arm_over_dds() {
    let _serial = support::serial();
    let domain = domain(1);
    // No command timeout on the arm (a forward_command_controller has none): the stop at the
    // end must come from the link.
    let node = FakeRos2Arm::start(
        domain,
        &CONTROLLER,
        &["--offset", "1000", "--timeout", "1e9"],
    );
    velocities_reach_the_arm("DDS", &node, link(domain));
}

/// The same over rmw_zenoh: the arm takes commands only on the key its own type store's
/// REP-2016 hash makes, with rmw_zenoh's attachment, and sees Avatarm's node, its
/// subscription and its publisher in the ROS graph (their liveliness tokens).
#[test]
fn joint_states_flow_in_and_velocities_reach_a_ros2_control_arm_over_rmw_zenoh() {
    let _serial = support::serial();
    let domain = domain(13);
    let router = ZenohRouter::start();
    let node = zenoh_arm(&router, domain, &["--offset", "1000", "--timeout", "1e9"]);
    let arm = link_on(
        domain,
        Rmw::Zenoh {
            router: Some(router.endpoint.clone()),
        },
    );
    let r = velocities_reach_the_arm("rmw_zenoh", &node, arm);
    assert_eq!(r["no_attachment"].as_u64(), Some(0), "{r}");
    assert_eq!(r["undecodable"].as_u64(), Some(0), "{r}");
    // The command key: `<domain>/forward_velocity_controller/commands/<type>/<hash>`.
    let key = r["command_key"].as_str().expect("command_key");
    let (_, type_and_hash) = key
        .split_once("/forward_velocity_controller/commands/")
        .expect("the command key");
    assert!(
        type_and_hash.starts_with("std_msgs::msg::dds_::Float64MultiArray_/RIHS01_"),
        "{key}"
    );
    let graph: Vec<&str> = r["graph"]
        .as_array()
        .expect("graph")
        .iter()
        .filter_map(|t| t.as_str())
        .collect();
    assert!(
        graph.iter().any(
            |t| t.starts_with(&format!("@ros2_lv/{domain}/")) && t.ends_with("/NN/%/%/avatarm")
        ),
        "Avatarm's node: {graph:?}"
    );
    assert!(
        graph.iter().any(
            |t| t.contains("/MP/%/%/avatarm/%forward_velocity_controller%commands/")
                && t.contains(&format!("/{type_and_hash}/"))
        ),
        "Avatarm's command publisher under the arm's type and hash: {graph:?}"
    );
    assert!(
        graph.iter().any(|t| t
            .contains("/MS/%/%/avatarm/%joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_")),
        "Avatarm's joint-state subscription: {graph:?}"
    );
}

/// A ros2_control arm in a namespace (`/robot1`, its topics `/robot1/joint_states` and
/// `/robot1/forward_velocity_controller/commands`): the link's node in the same namespace
/// finds them by their relative names, over DDS and over rmw_zenoh (where the graph shows
/// Avatarm's node and publisher in the namespace).
#[test]
fn a_namespaced_arm_is_found_by_relative_names_over_dds_and_rmw_zenoh() {
    let _serial = support::serial();
    let namespaced = |domain: u16, rmw: Rmw| {
        let joints = CONTROLLER.iter().map(|s| (*s).to_owned()).collect();
        let mut settings =
            LinkSettings::ros2_control("forward_velocity_controller", joints, domain);
        settings.joint_states_topic = "joint_states".into();
        settings.command_topic = "forward_velocity_controller/commands".into();
        if let Some(t) = settings.ros2.as_mut() {
            t.rmw = rmw;
            t.namespace = "/robot1".into();
        }
        RosArm::start(
            settings,
            MODEL.iter().map(|s| (*s).to_owned()).collect(),
            DVector::zeros(3),
        )
        .expect("link")
    };
    let args = [
        "--offset",
        "1000",
        "--timeout",
        "1e9",
        "--namespace",
        "/robot1",
    ];
    let domain = domain(20);
    let node = FakeRos2Arm::start(domain, &CONTROLLER, &args);
    velocities_reach_the_arm("DDS, in /robot1", &node, namespaced(domain, Rmw::Dds));
    drop(node);
    let router = ZenohRouter::start();
    let node = zenoh_arm(&router, domain, &args);
    let r = velocities_reach_the_arm(
        "rmw_zenoh, in /robot1",
        &node,
        namespaced(
            domain,
            Rmw::Zenoh {
                router: Some(router.endpoint.clone()),
            },
        ),
    );
    let key = r["command_key"].as_str().expect("command_key");
    assert!(
        key.starts_with(&format!(
            "{domain}/robot1/forward_velocity_controller/commands/"
        )),
        "{key}"
    );
    let graph = r["graph"].to_string();
    assert!(
        graph.contains("/MP/%/%robot1/avatarm/%robot1%forward_velocity_controller%commands/"),
        "{graph}"
    );
}

/// A Zenoh router that does not answer: the link says so, naming it, and is not connected
/// (it tries again every second) instead of waiting for joint states that cannot come.
#[test]
fn an_unreachable_zenoh_router_is_said_and_the_link_stays_down() {
    let _serial = support::serial();
    // A port nothing listens on.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let router = format!("tcp/127.0.0.1:{port}");
    let mut arm = link_on(
        domain(22),
        Rmw::Zenoh {
            router: Some(router.clone()),
        },
    );
    let started = Instant::now();
    let why = loop {
        arm.advance(wall_s());
        arm.receive();
        let status = arm.status();
        if let Some(why) = status.last_bad.clone() {
            assert!(!status.connected, "{status:?}");
            break why;
        }
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "nothing said: {status:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        why.contains("cannot open a Zenoh session") && why.contains(&router),
        "{why}"
    );
    let e = arm
        .send(&DVector::from_vec(vec![0.1, 0.0, 0.0]))
        .expect_err("no command without a link");
    assert!(e.to_string().contains("link is down"), "{e}");
}

/// The fake arm on rmw_zenoh through `router`, with more of its arguments.
fn zenoh_arm(router: &ZenohRouter, domain: u16, more: &[&str]) -> FakeRos2Arm {
    FakeRos2Arm::start(
        domain,
        &CONTROLLER,
        &[&["--rmw", "zenoh", "--router", &router.endpoint][..], more].concat(),
    )
}

/// Waits for `arm` to hear `node` (started with its clock 1000 s ahead and no command
/// timeout), sends a second of velocities, checks what the arm did, when each command arrived
/// and the clock, then drops the link and checks its stop arrived. Returns the arm's report
/// before the stop.
fn velocities_reach_the_arm(rmw: &str, node: &FakeRos2Arm, mut arm: RosArm) -> serde_json::Value {
    let started = Instant::now();
    wait_alive(&mut arm);
    let discovery_s = started.elapsed().as_secs_f64();
    // 1 s of j1 = +0.2 rad/s, j3 = -0.3 rad/s; j3's value carries the command's number (1e-7
    // rad/s apart) so that the arm's receipt of each is matched to its send.
    let mut sent: HashMap<u64, f64> = HashMap::new();
    let end = Instant::now() + Duration::from_secs(1);
    let mut k = 0u64;
    let mut refused = Vec::new();
    while Instant::now() < end {
        arm.advance(wall_s());
        arm.receive();
        k += 1;
        let qdot = DVector::from_vec(vec![0.2, 0.0, -0.3 - k as f64 * 1e-7]);
        sent.insert(k, wall_s());
        if let Err(e) = arm.send(&qdot) {
            refused.push(e.to_string());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(refused.is_empty(), "{refused:?}");
    let status = arm.status();
    let r = node.report();
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
    // The arm's q in its controller's order: j3, j1, j2.
    let (j3, j1, j2) = (
        r["q"][0].as_f64().expect("q"),
        r["q"][1].as_f64().expect("q"),
        r["q"][2].as_f64().expect("q"),
    );
    assert!((0.14..=0.26).contains(&j1), "j1 {j1}: {r}");
    assert!((-0.39..=-0.21).contains(&j3), "j3 {j3}: {r}");
    assert!(j2.abs() < 1e-9, "j2 {j2}");
    // Publish -> the arm's receipt, for each command the arm reports.
    let mut latency_ms: Vec<f64> = r["receipts"]
        .as_array()
        .expect("receipts")
        .iter()
        .filter_map(|x| {
            let (t, v) = (x[0].as_f64()?, x[1].as_f64()?);
            let k = ((-0.3 - v) / 1e-7).round() as u64;
            Some((t - sent.get(&k)?) * 1e3)
        })
        .collect();
    assert!(
        latency_ms.len() > 30,
        "{} commands matched",
        latency_ms.len()
    );
    let (median, p95) = spread(&mut latency_ms);
    // The arm's clock runs 1000 s ahead: the link's estimate of it.
    let (ahead, jitter) = status.robot_minus_local_s.expect("clock estimated");
    let rate = status.joint_state_rate_hz.expect("rate");
    eprintln!(
        "ROS 2 over {rmw}: discovery {discovery_s:.2} s; joint states {rate:.1} Hz; command publish -> the arm's receipt median {median:.2} ms, p95 {p95:.2} ms over {} commands; clock offset error {:.2} ms (jitter {:.2} ms)",
        latency_ms.len(),
        (ahead - 1000.0) * 1e3,
        jitter * 1e3
    );
    assert!((ahead - 1000.0).abs() < 0.05, "{ahead}");
    assert!(rate > 50.0, "{rate} Hz");
    assert!(status.connected && status.connects == 1, "{status:?}");
    // The controller keeps its last command: the link's end sends zeros and waits for them.
    drop(arm);
    let after = node.report();
    assert!(
        after["velocity"]
            .as_array()
            .is_some_and(|v| v.iter().all(|x| x.as_f64() == Some(0.0))),
        "{after}"
    );
    let last = after["receipts"]
        .as_array()
        .and_then(|v| v.last())
        .and_then(|x| x[1].as_f64());
    assert_eq!(last, Some(0.0), "the last command is the stop: {after}");
    r
}

#[test]
fn a_vanished_arm_stops_the_commands_and_a_nan_is_refused_by_name() {
    let _serial = support::serial();
    let domain = domain(2);
    // NaN velocities (hardware without a velocity interface): the positions keep it alive.
    let node = FakeRos2Arm::start(domain, &CONTROLLER, &["--no-velocity"]);
    a_vanished_arm_stops_the_commands("DDS", node, link(domain));
}

#[test]
fn a_vanished_arm_on_rmw_zenoh_stops_the_commands() {
    let _serial = support::serial();
    let domain = domain(14);
    let router = ZenohRouter::start();
    let node = zenoh_arm(&router, domain, &["--no-velocity"]);
    let arm = link_on(
        domain,
        Rmw::Zenoh {
            router: Some(router.endpoint.clone()),
        },
    );
    a_vanished_arm_stops_the_commands("rmw_zenoh", node, arm);
}

/// A NaN refused by name, then `node` killed: the link refuses commands within its stale
/// time, one loss counted.
fn a_vanished_arm_stops_the_commands(rmw: &str, mut node: FakeRos2Arm, mut arm: RosArm) {
    wait_alive(&mut arm);
    let e = arm
        .send(&DVector::from_vec(vec![0.1, f64::NAN, 0.0]))
        .expect_err("NaN");
    assert!(e.to_string().contains("j2"), "{e}");
    let go = DVector::from_vec(vec![0.1, 0.0, 0.0]);
    arm.send(&go).expect("a good command after the refusal");
    node.kill();
    let killed = Instant::now();
    let stopped_after = loop {
        arm.advance(wall_s());
        arm.receive();
        if let Err(e) = arm.send(&go) {
            assert!(e.to_string().contains("link is down"), "{e}");
            break killed.elapsed().as_secs_f64();
        }
        assert!(killed.elapsed() < Duration::from_secs(5), "never refused");
        std::thread::sleep(Duration::from_millis(5));
    };
    arm.advance(wall_s());
    let status = arm.status();
    eprintln!("ROS 2 over {rmw}: commands refused {stopped_after:.3} s after the arm vanished");
    // The stale time (0.2 s), with room for a loaded machine's scheduling.
    assert!(stopped_after <= 0.2 + 0.3, "{stopped_after} s");
    assert_eq!(status.losses, 1, "{status:?}");
}

/// The fake arm started with `arm_args`, the link with `settings` alive to it, and `qdot`
/// (model order) sent every 10 ms for a second.
fn drive_for_a_second(
    domain: u16,
    settings: LinkSettings,
    arm_args: &[&str],
    qdot: [f64; 3],
) -> (FakeRos2Arm, RosArm) {
    let node = FakeRos2Arm::start(domain, &CONTROLLER, arm_args);
    let mut arm = RosArm::start(
        settings,
        MODEL.iter().map(|s| (*s).to_owned()).collect(),
        DVector::zeros(3),
    )
    .expect("link");
    wait_alive(&mut arm);
    let end = Instant::now() + Duration::from_secs(1);
    while Instant::now() < end {
        arm.advance(wall_s());
        arm.receive();
        arm.send(&DVector::from_row_slice(&qdot)).expect("sent");
        std::thread::sleep(Duration::from_millis(10));
    }
    (node, arm)
}

/// A `JointGroupPositionController` (`--mode position` on the fake arm): the velocities reach
/// it integrated into targets, and the targets hold after the link's end.
#[test]
fn a_ros2_position_controller_gets_integrated_targets_and_holds_them() {
    let _serial = support::serial();
    let domain = domain(5);
    let mut settings = LinkSettings::ros2_control(
        "forward_position_controller",
        CONTROLLER.iter().map(|s| (*s).to_owned()).collect(),
        domain,
    );
    settings.command = CommandKind::GroupPosition {
        joints: CONTROLLER.iter().map(|s| (*s).to_owned()).collect(),
    };
    assert_eq!(
        settings.command_topic,
        "/forward_position_controller/commands"
    );
    let (node, arm) = drive_for_a_second(
        domain,
        settings,
        &[
            "--mode",
            "position",
            "--controller",
            "forward_position_controller",
        ],
        [0.2, 0.0, 0.0],
    );
    drop(arm);
    std::thread::sleep(Duration::from_millis(300));
    let before = node.report();
    std::thread::sleep(Duration::from_millis(300));
    let after = node.report();
    // j1 is the controller's second joint.
    let j1 = before["q"][1].as_f64().expect("q");
    assert!((0.14..=0.26).contains(&j1), "j1 {j1}: {before}");
    assert_eq!(before["q"], after["q"], "the target holds");
    assert_eq!(after["bad"].as_u64(), Some(0), "{after}");
}

/// A `joint_trajectory_controller` (`--mode trajectory` on the fake arm): each command a
/// one-point `JointTrajectory` by joint name, the point the horizon's motion ahead of where the
/// arm is (so without the horizon the arm would not move at all) and within the joints'
/// limits; when the commands stop (a hung or killed Avatarm sends nothing, not even a stop),
/// the arm holds the last point within the horizon.
#[test]
fn a_ros2_trajectory_controller_gets_points_ahead_of_the_arm_and_holds_when_they_stop() {
    let _serial = support::serial();
    trajectory_points_ahead_and_held(domain(12), Rmw::Dds, &[]);
}

/// The same on rmw_zenoh (`trajectory_msgs/msg/JointTrajectory` under the arm's own hash).
#[test]
fn a_ros2_trajectory_controller_on_rmw_zenoh_gets_points_ahead_of_the_arm() {
    let _serial = support::serial();
    let router = ZenohRouter::start();
    trajectory_points_ahead_and_held(
        domain(19),
        Rmw::Zenoh {
            router: Some(router.endpoint.clone()),
        },
        &["--rmw", "zenoh", "--router", &router.endpoint],
    );
}

/// The trajectory controller (the fake arm's `--mode trajectory`, with `rmw_args`) driven for
/// a second over `rmw`: points a horizon ahead, a joint's limit kept, held when they stop.
fn trajectory_points_ahead_and_held(domain: u16, rmw: Rmw, rmw_args: &[&str]) {
    let joints: Vec<String> = CONTROLLER.iter().map(|s| (*s).to_owned()).collect();
    let mut settings =
        LinkSettings::ros2_control("joint_trajectory_controller", joints.clone(), domain);
    if let Some(t) = settings.ros2.as_mut() {
        t.rmw = rmw;
    }
    settings.command_topic = "/joint_trajectory_controller/joint_trajectory".into();
    // In the controller's order [j3, j1, j2]: j1 stops at 0.15 rad.
    settings.command = CommandKind::JointTrajectory {
        joints,
        horizon_s: 0.2,
        limits: vec![(-1.0, 1.0), (-1.0, 0.15), (-1.0, 1.0)],
    };
    let arm_args = [
        "--mode",
        "trajectory",
        "--controller",
        "joint_trajectory_controller",
    ];
    let (node, arm) = drive_for_a_second(
        domain,
        settings,
        &[&arm_args[..], rmw_args].concat(),
        [0.2, 0.0, -0.1],
    );
    // Silent from here (the link still up): the arm reaches the last point and holds it.
    let silent = Instant::now();
    std::thread::sleep(Duration::from_millis(400));
    let before = node.report();
    std::thread::sleep(Duration::from_millis(300));
    let after = node.report();
    let q = |i: usize| before["q"][i].as_f64().expect("q");
    // j3 at about -0.1 rad/s for 1 s, and the last point the horizon's 0.02 rad ahead.
    assert!((-0.14..=-0.09).contains(&q(0)), "j3 {}: {before}", q(0));
    // j1 at its limit, not past it.
    assert!(
        (0.14..=0.15 + 1e-9).contains(&q(1)),
        "j1 {}: {before}",
        q(1)
    );
    assert_eq!(q(2), 0.0, "{before}");
    assert_eq!(after["horizon"].as_f64(), Some(0.2), "{after}");
    assert_eq!(
        before["q"],
        after["q"],
        "held {:?} after the last point",
        silent.elapsed()
    );
    assert_eq!(after["bad"].as_u64(), Some(0), "{after}");
    assert!(
        after["commands"].as_u64().is_some_and(|n| n >= 50),
        "{after}"
    );
    drop(arm);
}

#[test]
fn settings_a_ros2_link_cannot_use_are_refused() {
    let joints: Vec<String> = CONTROLLER.iter().map(|s| (*s).to_owned()).collect();
    let model: Vec<String> = MODEL.iter().map(|s| (*s).to_owned()).collect();
    let start = |s: LinkSettings| {
        RosArm::start(s, model.clone(), DVector::zeros(3))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    let mut s = LinkSettings::ros2_control("c", joints.clone(), 0);
    s.command = CommandKind::InteraVelocity;
    assert!(start(s).contains("forward_command_controller"));
    let mut s = LinkSettings::ros2_control("c", joints.clone(), 0);
    s.gripper = Some(avatarm_ros::GripperLink::default());
    assert!(start(s).contains("no gripper topic"));
    let s = LinkSettings::ros2_control("c", joints.clone(), 300);
    assert!(start(s).contains("domain 300: must be within 0..232"));
    let trajectory = |horizon_s: f64, limits: Vec<(f64, f64)>| CommandKind::JointTrajectory {
        joints: joints.clone(),
        horizon_s,
        limits,
    };
    let mut s = LinkSettings::ros2_control("c", joints.clone(), 0);
    s.command = trajectory(0.0, Vec::new());
    assert!(start(s).contains("trajectory horizon 0 s"));
    let mut s = LinkSettings::ros2_control("c", joints.clone(), 0);
    s.command = trajectory(0.2, vec![(0.0, 1.0)]);
    assert!(start(s).contains("1 position limits for 3 trajectory joints"));
    let mut s = LinkSettings::ros2_control("c", joints.clone(), 0);
    s.command = trajectory(0.2, vec![(0.0, 1.0), (1.0, -1.0), (0.0, f64::NAN)]);
    assert!(start(s).contains("joint j1: position limits [1, -1]"));
    let mut s = LinkSettings::sawyer("http://localhost:11311");
    s.command = trajectory(0.2, Vec::new());
    assert!(start(s).contains("over ROS 2 only"));
}

/// On DDS domain `domain`.
fn dds(domain: u16) -> Ros2Transport {
    Ros2Transport {
        domain_id: domain,
        ..Ros2Transport::default()
    }
}

/// On rmw_zenoh domain `domain` through `router`.
fn zenoh(domain: u16, router: &ZenohRouter) -> Ros2Transport {
    Ros2Transport {
        domain_id: domain,
        rmw: Rmw::Zenoh {
            router: Some(router.endpoint.clone()),
        },
        ..Ros2Transport::default()
    }
}

/// `n` frames of the ROS 2 camera on `topic` (on `transport`), within 20 s.
fn frames_of(transport: Ros2Transport, topic: &str, n: usize) -> Vec<RosImage> {
    let (tx, rx) = std::sync::mpsc::channel();
    spawn_camera(
        CameraTopic {
            transport,
            topic: topic.into(),
            node_name: "avatarm_camera".into(),
        },
        tx,
    )
    .expect("the camera's thread");
    let mut frames = Vec::new();
    let started = Instant::now();
    while frames.len() < n {
        let left = Duration::from_secs(20).saturating_sub(started.elapsed());
        match rx.recv_timeout(left) {
            Ok(CameraEvent::Frame(f)) => frames.push(f),
            Ok(CameraEvent::Opened(_)) => {}
            Ok(CameraEvent::Failed(why)) => panic!("{why}"),
            Err(e) => panic!("{} of {n} frames on {topic}: {e}", frames.len()),
        }
    }
    frames
}

/// A camera driver's raw `Image` (bgr8, a known pattern) and `CompressedImage` (a PNG file's
/// bytes) arrive over DDS as published, stamped with the driver's clock.
#[test]
fn a_ros2_camera_s_raw_and_compressed_frames_arrive_as_published() {
    let _serial = support::serial();
    let domain = domain(6);
    let camera = FakeRos2Camera::start(domain, "/camera/image_raw", &["--fps", "30"]);
    let frames = frames_of(dds(domain), "/camera/image_raw", 30);
    assert!(camera.report()["frames"].as_u64().is_some_and(|n| n >= 30));
    raw_frames_as_published("DDS", &frames);
    drop(camera);
    let file =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/latency_stages.png");
    let bytes = std::fs::read(&file).expect("a PNG");
    let camera = FakeRos2Camera::start(
        domain,
        "/camera/image_raw/compressed",
        &["--file", file.to_str().expect("utf-8"), "--fps", "15"],
    );
    let frames = frames_of(dds(domain), "/camera/image_raw/compressed", 5);
    for f in &frames {
        assert!(f.compressed && f.encoding == "png", "{}", f.encoding);
        assert!(f.data == bytes, "the PNG as published");
    }
    drop(camera);
}

/// The same raw frames from a driver on rmw_zenoh.
#[test]
fn a_ros2_camera_s_raw_frames_arrive_as_published_over_rmw_zenoh() {
    let _serial = support::serial();
    let domain = domain(17);
    let router = ZenohRouter::start();
    let camera = FakeRos2Camera::start(
        domain,
        "/camera/image_raw",
        &[
            "--fps",
            "30",
            "--rmw",
            "zenoh",
            "--router",
            &router.endpoint,
        ],
    );
    let frames = frames_of(zenoh(domain, &router), "/camera/image_raw", 30);
    raw_frames_as_published("rmw_zenoh", &frames);
    drop(camera);
}

/// `frames` are the fake driver's raw 64x48 bgr8 pattern, stamped before they arrived.
fn raw_frames_as_published(rmw: &str, frames: &[RosImage]) {
    for f in frames {
        assert!(!f.compressed);
        assert_eq!(
            (f.width, f.height, f.encoding.as_str(), f.step),
            (64, 48, "bgr8", 192)
        );
        assert_eq!(f.data.len(), 64 * 48 * 3);
        // Pixel (5, 7): B the frame's number, G = y, R = x.
        let p = &f.data[(7 * 64 + 5) * 3..][..3];
        assert_eq!((p[1], p[2]), (7, 5));
    }
    let mut delay_ms: Vec<f64> = frames
        .iter()
        .map(|f| (f.arrival_unix_s - f.stamp_unix_s) * 1e3)
        .collect();
    let (median, p95) = spread(&mut delay_ms);
    eprintln!(
        "ROS 2 camera over {rmw}: raw 64x48 bgr8, stamp -> arrival median {median:.2} ms, p95 {p95:.2} ms over {} frames",
        frames.len()
    );
    assert!(median >= 0.0 && p95 < 500.0, "{median} {p95}");
}

/// A camera driver's `CameraInfo` (beside its image topic) and its latched static transforms
/// (published before Avatarm subscribed: transient local) are gathered as published, and the
/// optical frame's pose chains through them.
#[test]
fn a_ros2_camera_drivers_camera_info_and_static_transforms_are_gathered() {
    let _serial = support::serial();
    let domain = domain(11);
    driver_calibration_gathered("DDS", dds(domain), &[]);
}

/// The same from a driver on rmw_zenoh: its static transforms kept by Zenoh's publication
/// cache (rmw_zenoh's transient local) and queried by the late subscription.
#[test]
fn a_ros2_camera_drivers_camera_info_and_static_transforms_are_gathered_over_rmw_zenoh() {
    let _serial = support::serial();
    let domain = domain(18);
    let router = ZenohRouter::start();
    driver_calibration_gathered(
        "rmw_zenoh",
        zenoh(domain, &router),
        &["--rmw", "zenoh", "--router", &router.endpoint],
    );
}

/// The fake driver (with `rmw_args`) on `transport`'s domain: its CameraInfo and latched
/// static transforms gathered as published and chained.
fn driver_calibration_gathered(rmw: &str, transport: Ros2Transport, rmw_args: &[&str]) {
    let camera_args = [
        "--file",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/latency_stages.png"),
        "--fps",
        "15",
        "--width",
        "1280",
        "--height",
        "720",
        "--fx",
        "910.5",
        "--fy",
        "911",
        "--cx",
        "640",
        "--cy",
        "359.5",
        "--d",
        "0.1",
        "-0.2",
        "0.001",
        "0",
        "0.05",
        "--tf-static",
        "base",
        "cam_link",
        "1",
        "-0.5",
        "0.75",
        "0",
        "0",
        "0",
        "1",
        "--tf-static",
        "cam_link",
        "camera_optical_frame",
        "0",
        "0",
        "0",
        "-0.5",
        "0.5",
        "-0.5",
        "0.5",
    ];
    let camera = FakeRos2Camera::start(
        transport.domain_id,
        "/cam/color/image_raw/compressed",
        &[&camera_args[..], rmw_args].concat(),
    );
    // The static transforms were latched before this subscription.
    std::thread::sleep(Duration::from_millis(500));
    let topic = CameraTopic {
        transport,
        topic: "/cam/color/image_raw/compressed".into(),
        node_name: "avatarm_camera".into(),
    };
    let g = gather(&topic, Duration::from_secs(20), |g| {
        g.info.is_some() && g.links.len() >= 2
    })
    .expect(rmw);
    assert_eq!(g.info_topic, "/cam/color/camera_info");
    let info = g.info.as_ref().expect("a CameraInfo within 20 s");
    assert_eq!((info.width, info.height), (1280, 720));
    assert_eq!(
        info.k,
        [910.5, 0.0, 640.0, 0.0, 911.0, 359.5, 0.0, 0.0, 1.0]
    );
    assert_eq!(info.distortion_model, "plumb_bob");
    assert_eq!(info.d, [0.1, -0.2, 0.001, 0.0, 0.05]);
    assert_eq!(info.header.frame_id, "camera_optical_frame");
    // Chained to the frame CameraInfo names, as the app does.
    let pose = chain(&g.links, "base", &info.header.frame_id, u64::MAX)
        .expect("base -> CameraInfo's frame");
    // REP 103/104: the optical frame looks along the link's x, its x along the link's -y.
    let (origin, z, x) = (
        pose * nalgebra::Point3::origin(),
        pose * nalgebra::Vector3::z(),
        pose * nalgebra::Vector3::x(),
    );
    assert!(
        (origin - nalgebra::Point3::new(1.0, -0.5, 0.75)).norm() < 1e-9,
        "{origin}"
    );
    assert!((z - nalgebra::Vector3::x()).norm() < 1e-9, "{z}");
    assert!((x + nalgebra::Vector3::y()).norm() < 1e-9, "{x}");
    eprintln!(
        "ROS 2 camera calibration over {rmw}: CameraInfo and {} transforms in {:.0} ms",
        g.links.len(),
        g.waited.as_secs_f64() * 1e3
    );
    drop(camera);
}

/// What Avatarm publishes back (the erased video and the mask as `CompressedImage`, the
/// commands as `JointState`, the safety events as `String`) is received and decoded by a
/// listener written with Cyclone DDS, as rviz2 would subscribe (reliable).
#[test]
fn the_erased_video_the_mask_the_commands_and_the_safety_events_reach_a_ros2_listener() {
    let _serial = support::serial();
    let domain = domain(8);
    let listener = Ros2Listener::start(domain, "/avatarm");
    let report = published_and_heard(&listener, domain, Rmw::Dds);
    assert_eq!(report["erased/compressed"]["format"], "jpeg");
}

/// The same on rmw_zenoh: each topic under its type's REP-2016 hash (the listener keys on
/// its own), every sample with rmw_zenoh's attachment.
#[test]
fn the_erased_video_the_mask_the_commands_and_the_safety_events_reach_a_listener_on_rmw_zenoh() {
    let _serial = support::serial();
    let domain = domain(15);
    let router = ZenohRouter::start();
    let listener = Ros2Listener::start_with(
        domain,
        "/avatarm",
        &["--rmw", "zenoh", "--router", &router.endpoint],
    );
    let report = published_and_heard(
        &listener,
        domain,
        Rmw::Zenoh {
            router: Some(router.endpoint.clone()),
        },
    );
    for topic in [
        "erased/compressed",
        "mask/compressed",
        "joint_commands",
        "safety",
    ] {
        let t = &report[topic];
        assert_eq!(t["no_attachment"].as_u64(), Some(0), "{topic}: {t}");
        assert_eq!(t["undecodable"].as_u64(), Some(0), "{topic}: {t}");
    }
}

/// Publishes on `rmw` (domain `domain`) until `listener` has taken 5 of each topic; checks
/// what it took and returns its report.
fn published_and_heard(listener: &Ros2Listener, domain: u16, rmw: Rmw) -> serde_json::Value {
    let publisher = Ros2Publisher::start(
        Ros2Transport {
            domain_id: domain,
            rmw,
            ..Ros2Transport::default()
        },
        "avatarm_out",
        "/avatarm",
        "camera_optical",
    )
    .expect("the publisher's thread");
    // A reliable writer delivers to the readers it has matched: publish until the listener
    // has taken some of each, as a steady stream does.
    let jpeg = vec![0xFF, 0xD8, 0xFF, 0xE0, 1, 2, 3];
    let png = b"\x89PNG\r\n\x1a\n....".to_vec();
    let started = Instant::now();
    let report = loop {
        let stamp_ns = 1_700_000_000_250_000_000;
        publisher.publish(Outgoing::Erased {
            stamp_ns,
            jpeg: jpeg.clone(),
        });
        publisher.publish(Outgoing::Mask {
            stamp_ns,
            png: png.clone(),
        });
        publisher.publish(Outgoing::Command {
            stamp_ns,
            names: vec!["j1".into(), "j2".into()],
            velocities: vec![0.25, -0.5],
        });
        publisher.publish(Outgoing::Safety {
            stamp_ns,
            text: "WARN limiter: TCP speed capped".into(),
        });
        std::thread::sleep(Duration::from_millis(50));
        let r = listener.report();
        let counts: Vec<u64> = [
            "erased/compressed",
            "mask/compressed",
            "joint_commands",
            "safety",
        ]
        .iter()
        .map(|t| r[t]["count"].as_u64().unwrap_or(0))
        .collect();
        if counts.iter().all(|&n| n >= 5) {
            break r;
        }
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "the listener took {counts:?}: {r}"
        );
    };
    let erased = &report["erased/compressed"];
    assert_eq!(erased["format"], "jpeg", "{erased}");
    assert_eq!(erased["magic"], true, "{erased}");
    assert_eq!(erased["bytes"].as_u64(), Some(jpeg.len() as u64));
    assert_eq!(erased["frame_id"], "camera_optical");
    assert!((erased["stamp"].as_f64().expect("stamp") - 1_700_000_000.25).abs() < 1e-6);
    assert_eq!(report["mask/compressed"]["format"], "png");
    assert_eq!(report["mask/compressed"]["magic"], true);
    let command = &report["joint_commands"];
    assert_eq!(command["name"], serde_json::json!(["j1", "j2"]));
    assert_eq!(command["velocity"], serde_json::json!([0.25, -0.5]));
    assert_eq!(report["safety"]["data"], "WARN limiter: TCP speed capped");
    assert_eq!(publisher.dropped(), 0);
    report
}
