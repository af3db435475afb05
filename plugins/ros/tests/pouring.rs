//! The paper's pouring task teleoperated through the ROS 1 link against the simulated Sawyer
//! node (a real ROS master, Intera's topics), beside the same trial on the embedded simulated
//! arm: the object error through ROS is reported as in the simulated room.

#[path = "support/mod.rs"]
mod support;

use std::path::Path;

use avatarm_core::robot::PackagePath;
use avatarm_core::teleop::mapping::MappingMode;
use avatarm_mapping::pouring::{prepare, run_trial, run_trial_on_robot};
use avatarm_ros::{LinkSettings, RosArm};
use avatarm_scene::Scene;

use support::{FakeSawyer, Master, wait_alive};

#[test]
fn the_pouring_task_runs_against_a_ros_sawyer_as_in_the_simulated_room() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/scenes/pouring.toml");
    let scene = Scene::load(&path, &PackagePath::default()).expect("the pouring scene");
    let (Some(task), Some(setup)) = (scene.file.task.clone(), scene.trial.clone()) else {
        panic!("the pouring scene has a [task]");
    };
    let prepared = prepare(&task, &setup).expect("the arm reaches the bottle");
    let q0 = prepared.q0().clone();
    let _serial = support::serial();
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
