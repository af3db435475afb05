//! Tests: the teleoperation loop on the pouring task, headless.

use std::sync::Arc;

use avatarm_core::mapping::MappingMode;
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::sim::SimRobotParams;
use nalgebra::{DVector, Isometry3};

use crate::pouring::{PouringTask, TrialSetup, run_trial};

pub(crate) fn setup() -> TrialSetup {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
    let model = Arc::new(RobotModel::from_urdf_file(&path, &PackagePath::default()).expect("urdf"));
    let tcp = model.link_id("right_gripper_tip").expect("tcp");
    TrialSetup {
        model,
        base: Isometry3::translation(0.0, 0.0, 0.75),
        q_start: DVector::from_row_slice(&[0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02]),
        tcp,
        arm: (0..7).collect(),
        sim: SimRobotParams::default(),
        control_rate_hz: 100.0,
        bottle_base: Isometry3::translation(0.62, -0.16, 0.75),
        bottle_radius_m: 0.03,
        bottle_height_m: 0.25,
    }
}

fn pour(task: &PouringTask, mode: MappingMode) -> crate::pouring::TrialRecord {
    run_trial(task, &setup(), mode, 0).expect("trial runs")
}

fn finite(p: &Isometry3<f64>) -> bool {
    p.translation.vector.iter().all(|v| v.is_finite())
        && p.rotation.coords.iter().all(|v| v.is_finite())
}

#[test]
fn the_hand_pours_with_the_real_bottle_and_closed_loop_tracks_it_closer() {
    let task = PouringTask::default();
    let closed = pour(&task, MappingMode::ClosedLoop);
    let paper = pour(&task, MappingMode::Paper);
    eprintln!("closed loop {:?}\npaper {:?}", closed.result, paper.result);
    for r in [&closed, &paper] {
        let res = &r.result;
        assert!(res.grasp_at_s.is_some(), "the gripper closes: {res:?}");
        assert!(res.twin_lift_m > 0.10, "the hand lifts the twin: {res:?}");
        assert!(
            res.real_lift_m > 0.10,
            "the robot lifts the real bottle: {res:?}"
        );
        assert!(
            res.max_tcp_speed <= task.max_tcp_speed + 1e-9,
            "the cap holds: {res:?}"
        );
        assert!(
            r.samples
                .iter()
                .all(|s| s.truth.as_ref().is_some_and(finite))
        );
    }
    assert!(
        closed.result.pos_rmse_m < paper.result.pos_rmse_m,
        "closed {:?} vs paper {:?}",
        closed.result,
        paper.result
    );
    assert!(closed.result.pos_rmse_m < 0.03, "{:?}", closed.result);
}

#[test]
fn tracking_lost_mid_pour_stops_the_arm_and_keeps_the_bottle_in_the_gripper() {
    let mut task = PouringTask::default();
    // Lost from 4.0 s to 5.0 s, while the bottle is lifted.
    let lost = task.hand.iter().position(|k| k.t_s > 4.0).expect("keys");
    let mut k = task.hand[lost - 1];
    k.t_s = 4.0;
    k.tracked = false;
    task.hand.insert(lost, k);
    let mut back = k;
    back.t_s = 5.0;
    back.tracked = true;
    task.hand.insert(lost + 1, back);
    let r = pour(&task, MappingMode::ClosedLoop);
    let during: Vec<_> = r
        .samples
        .iter()
        .filter(|s| s.t_s > 4.0 && s.t_s < 5.0)
        .collect();
    assert!(
        during.iter().filter(|s| s.stopping).count() > 80,
        "the limiter stops the arm"
    );
    // Ramped down, then held: no command jumps, and still nothing at the end of the window.
    let last = during.last().expect("samples");
    assert!(last.tcp_speed < 1e-6, "stopped: {}", last.tcp_speed);
    assert!(during.iter().all(|s| s.max_joint_speed.is_finite()));
    let z0 = setup().bottle_centre().translation.z;
    assert!(
        during
            .iter()
            .all(|s| s.truth.is_some_and(|p| p.translation.z > z0 + 0.02)),
        "the gripper keeps the bottle while the hand is lost"
    );
    assert!(r.result.grasp_at_s.is_some());
}

#[test]
fn a_twin_moved_faster_than_the_cap_is_followed_at_the_cap_and_caught_up() {
    let mut task = PouringTask {
        duration_s: 6.0,
        ..PouringTask::default()
    };
    // After the grasp, the hand jerks the bottle 12 cm up in 0.25 s (~0.9 m/s peak).
    task.hand.truncate(4);
    let mut up = task.hand[3];
    up.t_s += 0.25;
    up.xyz[2] += 0.12;
    task.hand.push(up);
    let r = pour(&task, MappingMode::ClosedLoop);
    assert!(r.result.grasp_at_s.is_some());
    assert!(
        r.result.max_tcp_speed <= task.max_tcp_speed + 1e-9,
        "{:?}",
        r.result
    );
    let end = r.samples.last().expect("samples");
    let err = (end.target.translation.vector - end.truth.expect("truth").translation.vector).norm();
    assert!(
        r.result.max_pos_error_m > 0.03,
        "the twin ran ahead: {:?}",
        r.result
    );
    assert!(err < 0.005, "caught up: {err}");
}

#[test]
fn trials_summarise_per_mode_with_the_paper_beside() {
    let task = PouringTask {
        trials: 2,
        duration_s: 4.0,
        ..PouringTask::default()
    };
    let modes = crate::pouring::run_trials(&task, &setup(), |_, _| {}).expect("trials");
    assert_eq!(modes.len(), 2);
    for (_, m) in &modes {
        assert_eq!(m.trials.len(), 2);
        let mean = (m.trials[0].pos_rmse_m + m.trials[1].pos_rmse_m) / 2.0;
        assert!((m.pos_rmse_m.mean - mean).abs() < 1e-12);
        assert!(m.pos_rmse_m.std >= 0.0);
    }
    // Different seeds, different trials.
    assert_ne!(
        modes[0].1.trials[0].pos_rmse_m,
        modes[0].1.trials[1].pos_rmse_m
    );
    assert!(
        PouringTask {
            k: 0.0,
            ..PouringTask::default()
        }
        .validate()
        .is_err()
    );
}
