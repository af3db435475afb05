//! The robot over ROS 1 (feature `ros`) against a real ROS master and the simulated Sawyer node
//! (`avatarm_ros::testing`): the live preview commanding it, and the pouring trial through the link
//! beside the embedded simulated arm.

use std::path::{Path, PathBuf};
use std::process::Command;

use avatarm_core::robot::PackagePath;
use avatarm_core::teleop::mapping::MappingMode;
use avatarm_mapping::pouring::{prepare, run_trial, run_trial_on_robot};
use avatarm_ros::testing::{self as ros_support, FakeSawyer, Master, wait_alive};
use avatarm_ros::{LinkSettings, RosArm};
use avatarm_scene::Scene;

use super::{out_dir, root, run_preview_with, scene};

/// A ROS master and the simulated Sawyer node with its arm at the pouring task's start but
/// `off_rad` on its first joint.
#[cfg(feature = "ros")]
fn sawyer_off_the_start(off_rad: f64) -> (Master, FakeSawyer) {
    let master = Master::start();
    let sawyer = FakeSawyer::start_at(&master, 0.0, &pouring_start_off(off_rad));
    (master, sawyer)
}

/// The pouring task's start (the Sawyer's seven arm joints, comma-separated, rad) but
/// `off_rad` on the first joint.
#[cfg(feature = "ros")]
fn pouring_start_off(off_rad: f64) -> String {
    let scene = scene("pouring");
    let (Some(task), Some(setup)) = (&scene.file.task, &scene.trial) else {
        panic!("the pouring scene has a task");
    };
    let prepared = avatarm_mapping::pouring::prepare(task, setup).expect("grasp");
    let start: Vec<String> = setup
        .arm
        .iter()
        .enumerate()
        .map(|(k, &i)| (prepared.q0()[i] + if k == 0 { off_rad } else { 0.0 }).to_string())
        .collect();
    start.join(",")
}

/// `avatarm run assets/scenes/pouring.toml --robot ros EXTRA` under Xvfb against `master`,
/// its output in the test folder `name`; the run's log.
#[cfg(feature = "ros")]
fn preview_on_ros(master: &Master, name: &str, extra: &[&str]) -> String {
    let out = out_dir(name);
    std::fs::create_dir_all(&out).expect("the test's folder");
    let args = [&["assets/scenes/pouring.toml", "--robot", "ros"][..], extra].concat();
    // Mesa's software rasteriser takes a thread per core; on a 2-core machine it starved the
    // simulated Sawyer (a Python process) of its 100 Hz joint states for over 0.2 s while the
    // app's own control thread kept its 10 ms ticks (measured December 2026: link lost twice,
    // control ticks 10.0 ms median, 16.6 ms max). One rasteriser thread leaves the robot its
    // core, as a real robot has its own computer.
    run_preview_with(
        &args,
        &out,
        &[("ROS_MASTER_URI", &master.uri), ("LP_NUM_THREADS", "1")],
    )
}

/// `avatarm run --robot ros`: the live pouring task commands a Sawyer over ROS 1 (a real master
/// and the simulated Sawyer node of `avatarm_ros::testing`, its arm where the task starts).
#[cfg(feature = "ros")]
#[test]
fn live_teleoperation_commands_a_sawyer_over_ros() {
    let _serial = ros_support::serial();
    // The real arm left 0.05 rad off the task's start on its first joint: Avatarm moves it
    // there before the hand drives it.
    let (master, sawyer) = sawyer_off_the_start(0.05);
    let log = preview_on_ros(&master, "ros_live", &["--frames", "90"]);
    assert!(
        log.contains("on the ROS robot at http://127.0.0.1"),
        "{log}"
    );
    assert!(
        log.contains("the arm is at the task's start after"),
        "{log}"
    );
    // The run's last line says the link's state, and that a real object is not measured.
    let line = log
        .lines()
        .find(|l| l.contains("teleop: "))
        .unwrap_or_default();
    eprintln!("{line}");
    assert!(
        line.contains("ROS link up, robot enabled, joint states")
            && line.contains("gripper right_gripper")
            && line.contains("real object not measured"),
        "{line}"
    );
    let r = sawyer.report();
    eprintln!("fake Sawyer after the live run: {r}");
    assert!(r["commands"].as_u64().is_some_and(|n| n > 0), "{r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
    assert_eq!(r["timeout_s"].as_f64(), Some(0.2));
    // Refused where it cannot work: a scene without a task.
    let run = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["run", "assets/scenes/default.toml", "--robot", "ros"])
        .current_dir(root())
        .output()
        .unwrap();
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("--robot ros"));
}

/// `avatarm run --robot ros` with the renderer slowed on purpose (every update 250 ms longer):
/// the robot's control loop keeps its own rate on its own thread. The Sawyer node receives the
/// commands evenly spaced at the control period (10 ms), not one per update, and the link is
/// never judged lost although the app reads the joint states only four times a second or less.
/// (`--frames` steps the app's clock by a fixed 1/60 s per update, far behind the wall's: the
/// robot's commands and link are on the wall's, which is what is checked.)
#[cfg(feature = "ros")]
#[test]
fn a_slow_renderer_does_not_slow_the_robots_control() {
    let _serial = ros_support::serial();
    // 0.3 rad off on the first joint: seconds of moving to the start, a steady stream of
    // commands that no hand data gates.
    let (master, sawyer) = sawyer_off_the_start(0.3);
    let log = preview_on_ros(
        &master,
        "ros_slow_render",
        &["--frames", "30", "--slow-update-ms", "250"],
    );
    let r = sawyer.report();
    eprintln!("fake Sawyer after a slowed run: {r}");
    let line = log
        .lines()
        .find(|l| l.contains("teleop: "))
        .unwrap_or_default();
    eprintln!("{line}");
    assert!(
        log.contains("ticked on its own thread every 10.0 ms"),
        "{log}"
    );
    assert!(
        !log.contains("the link is down") && !line.contains("link lost"),
        "a false link loss:\n{log}"
    );
    assert!(
        line.contains("ROS link up") && line.contains("control thread: a tick every"),
        "{line}"
    );
    // One command per update would be 250 ms or more apart; a burst of the missed fixed steps
    // would be microseconds apart.
    let gaps = r["command_gaps"].as_u64().unwrap_or(0);
    let median = r["command_gap_ms_median"].as_f64().unwrap_or(f64::NAN);
    let p95 = r["command_gap_ms_p95"].as_f64().unwrap_or(f64::NAN);
    assert!(gaps >= 200, "{gaps} commands in a stream: {r}");
    assert!(
        (6.0..=16.0).contains(&median),
        "median gap {median} ms: {r}"
    );
    assert!(p95 <= 40.0, "p95 gap {p95} ms: {r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
}

/// The paper's pouring task teleoperated through the ROS 1 link against the simulated Sawyer
/// node (a real ROS master, Intera's topics), beside the same trial on the embedded simulated
/// arm: the object error through ROS is reported as in the simulated room.
#[test]
fn the_pouring_task_runs_against_a_ros_sawyer_as_in_the_simulated_room() {
    let path = root().join("assets/scenes/pouring.toml");
    let scene = Scene::load(&path, &PackagePath::default()).expect("the pouring scene");
    let (Some(task), Some(setup)) = (scene.file.task.clone(), scene.trial.clone()) else {
        panic!("the pouring scene has a [task]");
    };
    let prepared = prepare(&task, &setup).expect("the arm reaches the bottle");
    let q0 = prepared.q0().clone();
    let _serial = ros_support::serial();
    let master = Master::start();
    let start: Vec<String> = (0..7).map(|i| q0[i].to_string()).collect();
    let sawyer = FakeSawyer::start_at(&master, 512.25, &start.join(","));
    let names: Vec<String> = setup
        .model
        .dof_names()
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
    let mut arm =
        RosArm::start(LinkSettings::sawyer(&master.uri), names, q0.clone()).expect("link");
    wait_alive(&mut arm);

    let ros = run_trial_on_robot(
        &task,
        &setup,
        &prepared,
        MappingMode::ClosedLoop,
        0,
        Box::new(arm),
    )
    .expect("trial over ROS");
    let sim = run_trial(&task, &setup, MappingMode::ClosedLoop, 0).expect("simulated trial");
    let r = sawyer.report();
    eprintln!(
        "pouring, closed loop, trial 0: over ROS {:.2} mm / roll {:.2} / pitch {:.2} / yaw {:.2} deg (lift {:.1} cm, grasp at {:?} s, max TCP {:.3} m/s); simulated arm {:.2} mm / {:.2} / {:.2} / {:.2} deg; the fake Sawyer took {} commands, latency median {} ms p95 {} ms",
        ros.result.pos_rmse_m * 1e3,
        ros.result.roll_rmse_deg,
        ros.result.pitch_rmse_deg,
        ros.result.yaw_rmse_deg,
        ros.result.real_lift_m * 1e2,
        ros.result.grasp_at_s,
        ros.result.max_tcp_speed,
        sim.result.pos_rmse_m * 1e3,
        sim.result.roll_rmse_deg,
        sim.result.pitch_rmse_deg,
        sim.result.yaw_rmse_deg,
        r["commands"],
        r["latency_ms_median"],
        r["latency_ms_p95"],
    );
    assert!(ros.result.grasp_at_s.is_some(), "{:?}", ros.result);
    assert!(
        ros.result.real_lift_m > 0.10,
        "the ROS arm lifts: {:?}",
        ros.result
    );
    assert!(ros.result.max_tcp_speed <= task.max_tcp_speed + 1e-9);
    assert!(
        ros.samples
            .iter()
            .all(|s| s.qdot.iter().all(|v| v.is_finite()))
    );
    // Within twice the simulated figure (a floor of 1 mm for a very good simulated trial).
    let bound = (2.0 * sim.result.pos_rmse_m).max(0.001);
    assert!(
        ros.result.pos_rmse_m <= bound,
        "{} vs {}",
        ros.result.pos_rmse_m,
        sim.result.pos_rmse_m
    );
    assert!(r["commands"].as_u64().is_some_and(|n| n > 500), "{r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
    // The gripper closed on the bottle and stays closed; sent when it changed, not each tick.
    assert_eq!(r["gripper_m"].as_f64(), Some(0.0), "{r}");
    assert!(
        r["gripper_commands"].as_u64().is_some_and(|n| n <= 3),
        "{r}"
    );
}

/// The pouring trial, closed loop, through the ROS 2 link (DDS) against the fake ros2_control
/// arm on Cyclone DDS (`avatarm_ros::testing::FakeRos2Arm`, its forward_command_controller
/// taking the Sawyer's seven joint velocities): the same figures as the embedded simulated arm,
/// within twice its position RMSE.
#[cfg(feature = "ros")]
#[test]
fn the_pouring_task_runs_against_a_ros2_control_arm_over_dds() {
    let _serial = ros_support::serial();
    pouring_against_a_ros2_control_arm(ros_support::test_domain(3), |_| avatarm_ros::Rmw::Dds);
}

/// The same over rmw_zenoh: the fake arm on rmw_zenoh (`rmw_zenoh_peer.py`) through a Zenoh
/// router.
#[cfg(feature = "ros")]
#[test]
fn the_pouring_task_runs_against_a_ros2_control_arm_over_rmw_zenoh() {
    let _serial = ros_support::serial();
    let router = avatarm_ros::testing::ZenohRouter::start();
    pouring_against_a_ros2_control_arm(ros_support::test_domain(16), |arm_args| {
        arm_args.extend(["--rmw".to_owned(), "zenoh".to_owned()]);
        arm_args.extend(["--router".to_owned(), router.endpoint.clone()]);
        avatarm_ros::Rmw::Zenoh {
            router: Some(router.endpoint.clone()),
        }
    });
}

/// The pouring trial 0, closed loop, through the ROS 2 link against the fake arm on domain
/// `domain`; `rmw` adds the arm's arguments for its middleware and says the link's. Within
/// twice the embedded simulated arm's position RMSE, the arm lifts, the speed capped.
#[cfg(feature = "ros")]
fn pouring_against_a_ros2_control_arm(
    domain: u16,
    rmw: impl FnOnce(&mut Vec<String>) -> avatarm_ros::Rmw,
) {
    let path = root().join("assets/scenes/pouring.toml");
    let scene = Scene::load(&path, &PackagePath::default()).expect("the pouring scene");
    let (Some(task), Some(setup)) = (scene.file.task.clone(), scene.trial.clone()) else {
        panic!("the pouring scene has a [task]");
    };
    let prepared = prepare(&task, &setup).expect("the arm reaches the bottle");
    let q0 = prepared.q0().clone();
    let joints: Vec<String> = (0..7).map(|i| format!("right_j{i}")).collect();
    let start: Vec<String> = (0..7).map(|i| q0[i].to_string()).collect();
    let names: Vec<&str> = joints.iter().map(String::as_str).collect();
    let mut arm_args: Vec<String> = vec![
        "--start".into(),
        start.join(","),
        "--offset".into(),
        "512.25".into(),
    ];
    let rmw = rmw(&mut arm_args);
    let label = match &rmw {
        avatarm_ros::Rmw::Dds => "DDS",
        avatarm_ros::Rmw::Zenoh { .. } => "rmw_zenoh",
    };
    let arm_args: Vec<&str> = arm_args.iter().map(String::as_str).collect();
    let node = avatarm_ros::testing::FakeRos2Arm::start(domain, &names, &arm_args);
    let model: Vec<String> = setup
        .model
        .dof_names()
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
    let mut settings = LinkSettings::ros2_control("forward_velocity_controller", joints, domain);
    if let Some(t) = settings.ros2.as_mut() {
        t.rmw = rmw;
    }
    let mut arm = RosArm::start(settings, model, q0.clone()).expect("link");
    let started = std::time::Instant::now();
    while !arm.alive() {
        assert!(started.elapsed().as_secs() < 20, "{:?}", arm.status());
        use avatarm_core::sim::arm::RobotInterface;
        arm.advance(ros_support::wall_s());
        arm.receive();
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let ros2 = run_trial_on_robot(
        &task,
        &setup,
        &prepared,
        MappingMode::ClosedLoop,
        0,
        Box::new(arm),
    )
    .expect("trial over ROS 2");
    let sim = run_trial(&task, &setup, MappingMode::ClosedLoop, 0).expect("simulated trial");
    let r = node.report();
    eprintln!(
        "pouring, closed loop, trial 0: over ROS 2 ({label}) {:.2} mm / roll {:.2} / pitch {:.2} / yaw {:.2} deg (lift {:.1} cm, max TCP {:.3} m/s); simulated arm {:.2} mm / {:.2} / {:.2} / {:.2} deg; the fake arm took {} commands",
        ros2.result.pos_rmse_m * 1e3,
        ros2.result.roll_rmse_deg,
        ros2.result.pitch_rmse_deg,
        ros2.result.yaw_rmse_deg,
        ros2.result.real_lift_m * 1e2,
        ros2.result.max_tcp_speed,
        sim.result.pos_rmse_m * 1e3,
        sim.result.roll_rmse_deg,
        sim.result.pitch_rmse_deg,
        sim.result.yaw_rmse_deg,
        r["commands"],
    );
    assert!(
        ros2.result.real_lift_m > 0.10,
        "the arm lifts: {:?}",
        ros2.result
    );
    assert!(ros2.result.max_tcp_speed <= task.max_tcp_speed + 1e-9);
    let bound = (2.0 * sim.result.pos_rmse_m).max(0.001);
    assert!(
        ros2.result.pos_rmse_m <= bound,
        "{} vs {}",
        ros2.result.pos_rmse_m,
        sim.result.pos_rmse_m
    );
    assert!(r["commands"].as_u64().is_some_and(|n| n > 500), "{r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
}

/// `avatarm run SCENE --robot ros2`: the live pouring task commands a ros2_control arm over
/// DDS (the fake arm of `avatarm_ros::testing`, on Cyclone DDS, its arm where the task starts
/// but 0.05 rad off on its first joint), the scene's `[robot.link]` of kind `ros2_control`;
/// `--robot ros2` on a scene whose link is ROS 1's is refused naming the kind.
#[cfg(feature = "ros")]
#[test]
fn live_teleoperation_commands_a_ros2_control_arm_over_dds() {
    let _serial = ros_support::serial();
    let domain = ros_support::test_domain(4);
    live_teleoperation_over_ros2(domain, &[], "", &[], &format!("DDS domain {domain}"));
    let run = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["run", "assets/scenes/pouring.toml", "--robot", "ros2"])
        .current_dir(root())
        .output()
        .expect("avatarm runs");
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && err.contains("kind = \"intera\"") && err.contains("ros2_control"),
        "{err}"
    );
}

/// The same over rmw_zenoh, chosen as a ROS 2 process chooses it (`RMW_IMPLEMENTATION=
/// rmw_zenoh_cpp`), the scene's link naming the Zenoh router: the fake arm on rmw_zenoh.
#[cfg(feature = "ros")]
#[test]
fn live_teleoperation_commands_a_ros2_control_arm_over_rmw_zenoh() {
    let _serial = ros_support::serial();
    let domain = ros_support::test_domain(21);
    let router = avatarm_ros::testing::ZenohRouter::start();
    live_teleoperation_over_ros2(
        domain,
        &["--rmw", "zenoh", "--router", &router.endpoint],
        &format!("zenoh_router = \"{}\"\n", router.endpoint),
        &[("RMW_IMPLEMENTATION", "rmw_zenoh_cpp")],
        &format!("rmw_zenoh domain {domain} (router {})", router.endpoint),
    );
}

/// `avatarm run SCENE --robot ros2 --frames 90` (with `env`) on the pouring scene with a
/// `ros2_control` link (plus `link_extra`) on `domain`, the fake arm (with `arm_args`) where
/// the task starts but 0.05 rad off on its first joint: the log and the run's last line name
/// the link's middleware (`link`), the arm reaches the start and is teleoperated, every
/// command good.
#[cfg(feature = "ros")]
fn live_teleoperation_over_ros2(
    domain: u16,
    arm_args: &[&str],
    link_extra: &str,
    env: &[(&str, &str)],
    link: &str,
) {
    let node = fake_arm_off_the_start(domain, arm_args);
    let out = out_dir(&format!("ros2_live_{domain}"));
    let path = ros2_pouring_scene(&out, domain, link_extra);
    let log = run_preview_with(
        &[
            path.to_str().expect("utf-8"),
            "--robot",
            "ros2",
            "--frames",
            "90",
        ],
        &out,
        env,
    );
    assert!(
        log.contains(&format!("on the ROS 2 robot ({link})")),
        "{log}"
    );
    assert!(
        log.contains("the arm is at the task's start after"),
        "{log}"
    );
    let line = log
        .lines()
        .find(|l| l.contains("teleop: "))
        .unwrap_or_default();
    eprintln!("{line}");
    assert!(
        line.contains(&format!("ROS 2 link up on {link}"))
            && line.contains("real object not measured"),
        "{line}"
    );
    let r = node.report();
    assert!(r["commands"].as_u64().is_some_and(|n| n > 0), "{r}");
    assert_eq!(r["bad"].as_u64(), Some(0), "{r}");
}

/// The fake ros2_control arm (with `arm_args`) on `domain`, the Sawyer's seven joints where
/// the pouring task starts but 0.05 rad off on the first.
#[cfg(feature = "ros")]
fn fake_arm_off_the_start(domain: u16, arm_args: &[&str]) -> avatarm_ros::testing::FakeRos2Arm {
    let joints: Vec<String> = (0..7).map(|i| format!("right_j{i}")).collect();
    let names: Vec<&str> = joints.iter().map(String::as_str).collect();
    let start = pouring_start_off(0.05);
    avatarm_ros::testing::FakeRos2Arm::start(
        domain,
        &names,
        &[&["--start", start.as_str()][..], arm_args].concat(),
    )
}

/// The pouring scene with a `ros2_control` link on `domain` (plus `link_extra`), its robot's
/// path made absolute, written into `out` (created).
#[cfg(feature = "ros")]
fn ros2_pouring_scene(out: &Path, domain: u16, link_extra: &str) -> PathBuf {
    std::fs::create_dir_all(out).expect("the test's folder");
    let text = std::fs::read_to_string(root().join("assets/scenes/pouring.toml"))
        .expect("the pouring scene")
        .replace(
            "urdf = \"../robots/",
            &format!("urdf = \"{}/assets/robots/", root().display()),
        );
    let path = out.join("pouring_ros2.toml");
    std::fs::write(
        &path,
        format!(
            "{text}\n[robot.link]\nkind = \"ros2_control\"\ndomain_id = {domain}\ncommand_topic = \"/forward_velocity_controller/commands\"\n{link_extra}"
        ),
    )
    .expect("write the scene");
    path
}

/// `avatarm serve SCENE --robot ros2` (the robot site) with the scene's link on DDS, and an
/// operator joining over Zenoh: the robot site brings the fake arm to the task's start (0.05
/// rad away) and drives it through the operator's pour, every command good, its report naming
/// the link's middleware.
#[cfg(feature = "ros")]
#[test]
fn the_robot_site_drives_a_ros2_control_arm_over_dds() {
    let _serial = ros_support::serial();
    let domain = ros_support::test_domain(24);
    let node = fake_arm_off_the_start(domain, &[]);
    robot_site_drives(
        &node,
        domain,
        "",
        &format!("DDS domain {domain}"),
        "ros2_serve_dds",
    );
}

/// The same with the link on rmw_zenoh (`rmw = "zenoh"`, its router): the fake arm on
/// rmw_zenoh alone, so what moves it came over rmw_zenoh, every command with rmw_zenoh's
/// attachment.
#[cfg(feature = "ros")]
#[test]
fn the_robot_site_drives_a_ros2_control_arm_over_rmw_zenoh() {
    let _serial = ros_support::serial();
    let domain = ros_support::test_domain(23);
    let router = avatarm_ros::testing::ZenohRouter::start();
    let node = fake_arm_off_the_start(domain, &["--rmw", "zenoh", "--router", &router.endpoint]);
    let moved = robot_site_drives(
        &node,
        domain,
        &format!("rmw = \"zenoh\"\nzenoh_router = \"{}\"\n", router.endpoint),
        &format!("rmw_zenoh domain {domain} (router {})", router.endpoint),
        "ros2_serve_zenoh",
    );
    assert_eq!(moved["no_attachment"].as_u64(), Some(0), "{moved}");
}

/// `avatarm serve` on the pouring scene with a `ros2_control` link on `domain` (plus
/// `link_extra`), `--robot ros2`, for 20 s, and `avatarm join` as the operator, its scripted
/// hand pouring: the site brings `node` (the fake arm) to the task's start and drives it
/// through the pour (the grasp commanded when the operator's hand closed: a ROS 2 link has no
/// gripper yet; the arm carried far from where it started), every command good, and its
/// report names the link and its middleware (`link`, e.g. `DDS domain 24`). The fake arm's
/// last report.
#[cfg(feature = "ros")]
fn robot_site_drives(
    node: &avatarm_ros::testing::FakeRos2Arm,
    domain: u16,
    link_extra: &str,
    link: &str,
    dir: &str,
) -> serde_json::Value {
    let out = out_dir(dir);
    let scene = ros2_pouring_scene(&out, domain, link_extra);
    let joints = |r: &serde_json::Value| -> Vec<f64> {
        r["q"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(serde_json::Value::as_f64)
            .collect()
    };
    let before = joints(&node.report());
    let path = out.join("serve.json");
    let (mut serve, mut join) = serve_and_join(
        scene.to_str().expect("utf-8"),
        "ros2",
        &out,
        &[
            "--duration",
            "20",
            "--report",
            path.to_str().expect("utf-8"),
        ],
        &[],
    );
    // Both end by themselves: the operator after its pour, the site after its 20 s.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(90);
    let joined = finish_by(&mut join, deadline, &out, "join");
    let served = finish_by(&mut serve, deadline, &out, "serve");
    let log = |name: &str| std::fs::read_to_string(out.join(format!("{name}.log")));
    let serve_log = log("serve").unwrap_or_default();
    assert!(joined.success(), "{}", log("join").unwrap_or_default());
    assert!(served.success(), "{serve_log}");
    let after = node.report();
    let report: avatarm::net::serve::ServeReport = {
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{e}\n{serve_log}"));
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}\n{text}"))
    };
    // The largest change of a joint from before the session to its end.
    let moved = before
        .iter()
        .zip(joints(&after))
        .fold(0.0, |m: f64, (a, b)| m.max((a - b).abs()));
    eprintln!(
        "robot site over {link}: {} targets used, grasp commanded at {:?} s, a joint {moved:.3} rad from where it was; the arm: {after}\nthe link: {:?}",
        report.targets_used, report.trial.grasp_at_s, report.robot_link
    );
    let link_line = report.robot_link.clone().unwrap_or_default();
    assert!(
        link_line.contains(&format!("ROS 2 link up on {link}")),
        "{link_line}\n{serve_log}"
    );
    assert!(report.targets_used > 500, "{report:?}\n{serve_log}");
    assert_eq!(report.mapping_errors, 0, "{report:?}");
    assert_eq!(report.nan_commands, 0, "{report:?}");
    assert!(report.trial.grasp_at_s.is_some(), "no grasp: {report:?}");
    // The move to the start is 0.05 rad; the pour carries a joint 0.23 rad (measured).
    assert!(moved > 0.15, "the arm moved {moved} rad: {after}");
    assert!(
        after["commands"].as_u64().is_some_and(|n| n > 500),
        "{after}"
    );
    assert_eq!(after["bad"].as_u64(), Some(0), "{after}");
    after
}

/// Waits for `child` (its log `out/NAME.log`) to end until `deadline`; killed then, and the
/// test failed with its log.
#[cfg(feature = "ros")]
fn finish_by(
    child: &mut std::process::Child,
    deadline: std::time::Instant,
    out: &Path,
    name: &str,
) -> std::process::ExitStatus {
    loop {
        if let Some(status) = child.try_wait().expect(name) {
            return status;
        }
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            let log = std::fs::read_to_string(out.join(format!("{name}.log"))).unwrap_or_default();
            panic!("avatarm {name} did not end in time:\n{log}");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// `avatarm serve SCENE --robot ROBOT` (TCP on a free port of this machine, no video,
/// `serve_args` after those, e.g. `--duration 20`; `env` added) and `avatarm join` as its
/// operator, their stderr in `out`'s `serve.log` and `join.log`. Both run in the checkout.
#[cfg(feature = "ros")]
fn serve_and_join(
    scene: &str,
    robot: &str,
    out: &Path,
    serve_args: &[&str],
    env: &[(&str, &str)],
) -> (std::process::Child, std::process::Child) {
    use std::process::Stdio;
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port");
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let log = |name: &str| std::fs::File::create(out.join(format!("{name}.log"))).expect("log");
    let serve = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["serve", scene, "--robot", robot])
        .args(["--insecure-lan", "--video", "off"])
        .args(["--listen", &endpoint])
        .args(serve_args)
        .envs(env.iter().copied())
        .current_dir(root())
        .stdout(Stdio::null())
        .stderr(log("serve"))
        .spawn()
        .expect("avatarm serve");
    let join = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["join", &endpoint, "--scene", scene])
        .args(["--wait", "30"])
        .current_dir(root())
        .stdout(Stdio::null())
        .stderr(log("join"))
        .spawn()
        .expect("avatarm join");
    (serve, join)
}

/// `avatarm run --ros2-publish`: the live pouring session's erased frames, masks and commands
/// reach a ROS 2 listener written with Cyclone DDS (`avatarm_ros::testing::Ros2Listener`), as
/// rviz2 would subscribe.
#[cfg(feature = "ros")]
#[test]
fn a_live_session_is_published_on_ros2() {
    let _serial = ros_support::serial();
    let domain = ros_support::test_domain(9);
    let listener = avatarm_ros::testing::Ros2Listener::start(domain, "/avatarm");
    let out = out_dir("ros2_publish");
    std::fs::create_dir_all(&out).expect("the test's folder");
    let log = run_preview_with(
        &[
            "assets/scenes/pouring.toml",
            "--ros2-publish",
            "--frames",
            "60",
        ],
        &out,
        &[("ROS_DOMAIN_ID", &domain.to_string())],
    );
    let r = listener.report();
    eprintln!("the ROS 2 listener after the run: {r}");
    let count = |topic: &str| r[topic]["count"].as_u64().unwrap_or(0);
    assert!(count("erased/compressed") > 0, "{r}\n{log}");
    assert!(count("mask/compressed") > 0, "{r}");
    assert!(count("joint_commands") > 0, "{r}");
    assert_eq!(r["erased/compressed"]["format"], "jpeg", "{r}");
    assert_eq!(r["erased/compressed"]["magic"], true, "{r}");
    assert_eq!(r["mask/compressed"]["magic"], true, "{r}");
    assert!(
        r["joint_commands"]["name"]
            .as_array()
            .is_some_and(|n| n.iter().any(|j| j == "right_j0")),
        "{r}"
    );
    assert!(log.contains("published on ROS 2"), "{log}");
}

/// The robot site killed mid-pour (SIGKILL: no goodbye, no last zero command): the Sawyer stops
/// by itself within the command timeout Avatarm set on the link (Intera's
/// `joint_command_timeout`, 0.2 s), and holds where it was. What keeps a real arm safe when the
/// process that commands it dies, whatever killed it (docs/network.md, "When the robot site
/// dies").
#[cfg(feature = "ros")]
#[test]
fn a_killed_robot_site_leaves_the_sawyer_stopped_within_its_command_timeout() {
    use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
    let _serial = ros_support::serial();
    let (master, sawyer) = sawyer_off_the_start(0.0);
    let out = out_dir("ros_serve_killed");
    std::fs::create_dir_all(&out).unwrap();
    let (mut serve, mut join) = serve_and_join(
        "assets/scenes/pouring.toml",
        "ros",
        &out,
        &["--duration", "120"],
        &[("ROS_MASTER_URI", &master.uri)],
    );
    // The operator joins and its hand pours: wait until the arm moves under the robot site's
    // commands from the operator's targets.
    let deadline = Instant::now() + Duration::from_secs(60);
    while !std::fs::read_to_string(out.join("join.log"))
        .unwrap_or_default()
        .contains("joined")
    {
        assert!(Instant::now() < deadline, "the operator never joined");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(2));
    let now = || {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .expect("clock")
            .as_secs_f64()
    };
    let fastest = |r: &serde_json::Value| {
        r["velocity"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(serde_json::Value::as_f64)
            .fold(0.0, |m: f64, v| m.max(v.abs()))
    };
    let moving = loop {
        let r = sawyer.report();
        if fastest(&r) > 0.02 {
            break r;
        }
        let serve_log = std::fs::read_to_string(out.join("serve.log")).unwrap_or_default();
        assert!(
            Instant::now() < deadline,
            "the arm never moved: {r}\n{serve_log}"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let killed_at = now();
    serve.kill().expect("SIGKILL");
    let _ = serve.wait();
    std::thread::sleep(Duration::from_secs(1));
    let r = sawyer.report();
    let _ = join.kill();
    let _ = join.wait();
    eprintln!("moving: {moving}\nafter the kill: {r}");
    let f = |key: &str| r[key].as_f64().unwrap_or_else(|| panic!("no {key} in {r}"));
    // Avatarm set the timeout (the node's own default is 0.5 s).
    assert_eq!(f("timeout_s"), 0.2, "{r}");
    // The commands ended with the process, the arm moving then; it held the timeout later
    // (plus one of its 10 ms cycles).
    let (last, held) = (f("last_command_at"), f("held_at"));
    assert!(last <= killed_at + 0.05, "a command after the kill: {r}");
    assert!(
        held > last && held - last <= 0.2 + 0.03,
        "held {:.0} ms after the last command",
        (held - last) * 1e3
    );
    assert!(held - killed_at <= 0.2 + 0.05, "{r}");
    assert!(f("speed_at_hold") > 0.0, "the arm was still already: {r}");
    assert_eq!(fastest(&r), 0.0, "{r}");
    eprintln!(
        "robot site killed: the arm held {:.0} ms after the kill, {:.0} ms after the last command",
        (held - killed_at) * 1e3,
        (held - last) * 1e3
    );
}
