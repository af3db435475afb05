//! The ROS 2 link against a fake ros2_control arm on Cyclone DDS (`src/testing/fake_ros2_arm.py`,
//! PyPI's cyclonedds: the DDS of rmw_cyclonedds_cpp, nothing of Avatarm's): joint states in on
//! the arm's own clock, velocities out to its forward_command_controller in the controller's
//! joint order, a stop at the end, a vanished arm noticed, bad commands refused.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use avatarm_core::sim::arm::RobotInterface;
use avatarm_ros::testing::{self as support, FakeRos2Arm, wall_s};
use avatarm_ros::{CommandKind, LinkSettings, RosArm};
use nalgebra::DVector;

/// The robot model's joints (q order).
const MODEL: [&str; 3] = ["j1", "j2", "j3"];
/// The controller's joints, in its order (not the model's).
const CONTROLLER: [&str; 3] = ["j3", "j1", "j2"];

fn link(domain: u16) -> RosArm {
    let joints = CONTROLLER.iter().map(|s| (*s).to_owned()).collect();
    RosArm::start(
        LinkSettings::ros2_control("forward_velocity_controller", joints, domain),
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
            "no joint state from the fake arm over DDS: {:?}",
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
    let domain = 61;
    let node = FakeRos2Arm::start(domain, &CONTROLLER, &["--offset", "1000"]);
    let mut arm = link(domain);
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
        "ROS 2 over DDS: discovery {discovery_s:.2} s; joint states {rate:.1} Hz; command publish -> the arm's receipt median {median:.2} ms, p95 {p95:.2} ms over {} commands; clock offset error {:.2} ms (jitter {:.2} ms)",
        latency_ms.len(),
        (ahead - 1000.0) * 1e3,
        jitter * 1e3
    );
    assert!((ahead - 1000.0).abs() < 0.05, "{ahead}");
    assert!(rate > 50.0, "{rate} Hz");
    assert!(status.connected && status.connects == 1, "{status:?}");
    // The controller keeps its last command: the link's end sends zeros and waits for them.
    drop(arm);
    let r = node.report();
    assert!(
        r["velocity"]
            .as_array()
            .is_some_and(|v| v.iter().all(|x| x.as_f64() == Some(0.0))),
        "{r}"
    );
}

#[test]
fn a_vanished_arm_stops_the_commands_and_a_nan_is_refused_by_name() {
    let _serial = support::serial();
    let domain = 62;
    let mut node = FakeRos2Arm::start(domain, &CONTROLLER, &[]);
    let mut arm = link(domain);
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
    eprintln!("ROS 2 over DDS: commands refused {stopped_after:.3} s after the arm vanished");
    assert!(stopped_after <= 0.2 + 0.1, "{stopped_after} s");
    assert_eq!(status.losses, 1, "{status:?}");
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
    let s = LinkSettings::ros2_control("c", joints, 300);
    assert!(start(s).contains("DDS domain 300"));
}
