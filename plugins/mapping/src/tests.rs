//! Tests: the teleoperation loop on the pouring task, headless.

use std::sync::Arc;

use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::sim::SimRobotParams;
use avatarm_core::teleop::mapping::MappingMode;
use nalgebra::{DVector, Isometry3};

use avatarm_core::robot::ik::{pinv_step, smallest_singular_value};
use avatarm_core::teleop::hand::{HandFrame, HandNoise};
use avatarm_hand::{ActiveHand, HandSource, ScriptedHand};
use nalgebra::Vector6;

use crate::pouring::{PouringTask, TrialSetup, run_trial, run_trial_with};

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

/// Every tick sent finite joint velocities within the joint speed limits, and the measured
/// joints stayed within their position limits.
fn assert_safe(r: &crate::pouring::TrialRecord, task: &PouringTask) {
    let limits = setup().model.dof_limits();
    for s in &r.samples {
        assert!(
            s.qdot.iter().all(|v| v.is_finite()),
            "finite command at {}",
            s.t_s
        );
        for (i, l) in limits.iter().enumerate() {
            assert!(
                s.qdot[i].abs() <= l.velocity + 1e-9,
                "joint {i} at {} s: {} rad/s over its limit {}",
                s.t_s,
                s.qdot[i],
                l.velocity
            );
            if s.q[i].is_finite() {
                assert!(
                    s.q[i] >= l.lower - 1e-3 && s.q[i] <= l.upper + 1e-3,
                    "joint {i} at {} s: {} outside [{}, {}]",
                    s.t_s,
                    s.q[i],
                    l.lower,
                    l.upper
                );
            }
        }
        assert!(s.tcp_speed <= task.max_tcp_speed + 1e-9, "cap at {}", s.t_s);
    }
}

#[test]
fn a_twin_carried_out_of_reach_meets_a_singularity_that_dls_survives_and_pinv_does_not() {
    let mut task = PouringTask {
        duration_s: 9.0,
        ..PouringTask::default()
    };
    // After the lift, the hand carries the bottle 1.2 m away from the robot's base, far beyond
    // the arm's reach: the arm stretches into its elbow singularity.
    task.hand.truncate(5);
    let mut away = task.hand[4];
    away.t_s += 4.0;
    away.xyz[0] += 1.2;
    task.hand.push(away);
    let r = pour(&task, MappingMode::ClosedLoop);
    assert!(r.result.grasp_at_s.is_some());
    assert_safe(&r, &task);
    // The arm got close to singular: the tool Jacobian's smallest singular value collapsed.
    let s = setup();
    let arm_jacobian = |q: &DVector<f64>| {
        let full = s.model.jacobian(
            &s.base,
            q.as_slice(),
            s.tcp,
            &nalgebra::Vector3::zeros(),
            avatarm_core::robot::kinematics::Frame::World,
        );
        nalgebra::Matrix6xX::from_fn(s.arm.len(), |r, c| full[(r, s.arm[c])])
    };
    let (worst, q_worst) = r
        .samples
        .iter()
        .filter(|x| x.q.iter().all(|v| v.is_finite()))
        .map(|x| (smallest_singular_value(&arm_jacobian(&x.q)), x.q.clone()))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .expect("joint states");
    let start = smallest_singular_value(&arm_jacobian(&r.samples[200].q));
    eprintln!("smallest singular value: {start:.3} at the grasp, {worst:.4} at the worst");
    assert!(worst < start / 4.0, "{worst} vs {start}");
    // There a plain pseudoinverse asks more than any joint can give for a twist of 0.25 (m/s,
    // rad/s) along the Jacobian's weakest direction; the loop's DLS never left the limits.
    let j = arm_jacobian(&q_worst);
    let svd = j.clone().svd(true, false);
    let u = svd.u.as_ref().expect("u");
    let weakest = (0..svd.singular_values.len())
        .min_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]))
        .expect("singular values");
    let twist: Vector6<f64> = u.column(weakest) * 0.25;
    let pinv = pinv_step(&j, &twist).amax();
    let dls = r.samples.iter().map(|x| x.qdot.amax()).fold(0.0, f64::max);
    let fastest = s
        .model
        .dof_limits()
        .iter()
        .map(|l| l.velocity)
        .fold(0.0, f64::max);
    eprintln!("pinv {pinv:.1} rad/s, DLS loop at most {dls:.2} rad/s, fastest joint {fastest}");
    assert!(pinv > fastest, "pinv {pinv} vs limits {fastest}");
    assert!(dls <= fastest);
}

#[test]
fn contacts_lost_mid_grasp_let_the_twin_fall_and_the_arm_rests_without_a_jump() {
    let mut task = PouringTask {
        duration_s: 7.0,
        ..PouringTask::default()
    };
    // At the top of the lift the hand snaps open in 100 ms and moves away: every contact is
    // lost.
    task.hand.truncate(5);
    let mut open = task.hand[4];
    open.t_s += 0.5;
    task.hand.push(open);
    open.t_s += 0.1;
    open.grip = 0.0;
    task.hand.push(open);
    open.t_s += 0.2;
    open.xyz[1] -= 0.1;
    task.hand.push(open);
    let r = pour(&task, MappingMode::ClosedLoop);
    assert!(r.result.grasp_at_s.is_some());
    assert_safe(&r, &task);
    let released = task.hand[7].t_s;
    let after: Vec<_> = r
        .samples
        .iter()
        .filter(|s| s.t_s > released + 1.0)
        .collect();
    assert!(after.iter().all(|s| s.contacts == 0), "no contacts after");
    assert!(
        after.iter().all(|s| !s.gripper_closed),
        "the gripper opened"
    );
    let last = after.last().expect("samples");
    assert!(last.tcp_speed < 1e-3, "the arm rests: {}", last.tcp_speed);
    let twin_z = r.twin.last().expect("twin").translation.z;
    assert!(
        twin_z < r.twin[0].translation.z + 0.01,
        "the twin fell back to the table: {twin_z}"
    );
    // The command changes smoothly: no tick jumps by more than the cap's worth.
    for w in r.samples.windows(2) {
        assert!((w[1].tcp_speed - w[0].tcp_speed).abs() <= task.max_tcp_speed + 1e-9);
    }
}

/// The scripted hand with NaN joint positions from `from` to `to` (s).
struct NanFrames {
    inner: ScriptedHand,
    from: f64,
    to: f64,
}

impl HandSource for NanFrames {
    fn name(&self) -> &str {
        "hand with NaN frames"
    }

    fn poll(&mut self, now_s: f64) -> Option<HandFrame> {
        let mut f = self.inner.poll(now_s)?;
        if (self.from..self.to).contains(&f.t_s) {
            for j in f.joints.iter_mut().step_by(3) {
                j.pose.translation.x = f64::NAN;
            }
        }
        Some(f)
    }
}

#[test]
fn nan_hand_frames_are_refused_and_the_watchdog_stops_the_arm_holding_the_bottle() {
    let task = PouringTask::default();
    let r = run_trial_with(&task, &setup(), MappingMode::ClosedLoop, 0, |inner| {
        ActiveHand::new(NanFrames {
            inner,
            from: 4.0,
            to: 4.8,
        })
    })
    .expect("trial");
    assert!(
        r.result.hand_frames_refused >= 70,
        "{}",
        r.result.hand_frames_refused
    );
    assert_safe(&r, &task);
    let during: Vec<_> = r
        .samples
        .iter()
        .filter(|s| s.t_s > 4.2 && s.t_s < 4.8)
        .collect();
    assert!(
        during.iter().all(|s| s.stopping),
        "the watchdog stops the arm"
    );
    assert!(during.last().is_some_and(|s| s.tcp_speed < 1e-6));
    let z0 = setup().bottle_centre().translation.z;
    assert!(
        during
            .iter()
            .all(|s| s.truth.is_some_and(|p| p.translation.z > z0 + 0.02)),
        "the bottle stays in the gripper"
    );
    // Frames good again: the trial goes on and ends close.
    let end = r.samples.last().expect("samples");
    assert!(!end.stopping);
    let err = (end.target.translation.vector - end.truth.expect("truth").translation.vector).norm();
    assert!(err < 0.01, "{err}");
}

#[test]
fn a_jittery_hand_still_pours_within_the_limits() {
    // Four times the default tremor and three times the tracking noise.
    let task = PouringTask {
        noise: HandNoise {
            tremor_m: 0.002,
            tracking_sigma_m: 0.003,
            ..HandNoise::default()
        },
        ..PouringTask::default()
    };
    let calm = pour(&PouringTask::default(), MappingMode::ClosedLoop);
    let r = pour(&task, MappingMode::ClosedLoop);
    eprintln!("calm {:?}\njittery {:?}", calm.result, r.result);
    assert!(r.result.grasp_at_s.is_some() && r.result.real_lift_m > 0.10);
    assert_safe(&r, &task);
    assert!(r.result.pos_rmse_m < 0.015, "{:?}", r.result);
    assert!(r.result.roll_rmse_deg < 5.0, "{:?}", r.result);
    // The jitter costs accuracy (the test can tell them apart).
    assert!(r.result.pos_rmse_m > calm.result.pos_rmse_m);
}

#[test]
fn closed_loop_meets_the_goal_over_the_trials_grasped_before_the_lift() {
    // The goal at the default latencies (20 ms command, 50 ms response, 100 Hz joint
    // states 10 ms late, 100 Hz control, 0.25 m/s cap): position RMSE <= 5 mm and each angle
    // <= 1 degree, as the mean over the task's seeded trials whose hand takes the twin before
    // the lift (2.5 s). Hands 4 and 5 brush the bottle on their way in, and micrometres decide
    // whether the grasp assist catches it then or the fingers push it off and take it mid-pour
    // (docs/grasp.md): a twin that jumps into the hand, which the capped arm follows late.
    // They are held to their own bound, and only they may grasp late (here hand 5 does).
    let task = PouringTask::default();
    let setup = setup();
    let results: Vec<_> = (0..task.trials)
        .map(|i| {
            run_trial(&task, &setup, MappingMode::ClosedLoop, i)
                .expect("trial runs")
                .result
        })
        .collect();
    for r in &results {
        eprintln!(
            "trial {}: grasp {:?} s, {:.2} mm, roll {:.2} deg, real lift {:.1} mm, twin lift {:.1} mm",
            r.trial,
            r.grasp_at_s,
            r.pos_rmse_m * 1e3,
            r.roll_rmse_deg,
            r.real_lift_m * 1e3,
            r.twin_lift_m * 1e3
        );
    }
    assert!(
        results.iter().all(|r| r.grasp_at_s.is_some()),
        "every hand grasps"
    );
    let (on_time, late): (Vec<_>, Vec<_>) = results
        .into_iter()
        .partition(|r| r.grasp_at_s.is_some_and(|t| t < 2.5));
    assert!(
        late.iter().all(|r| r.trial == 4 || r.trial == 5),
        "grasped after 2.5 s: trials {:?}",
        late.iter().map(|r| r.trial).collect::<Vec<_>>()
    );
    for r in &late {
        // Still carried: the real bottle rises with its twin, within the pour's limits.
        assert!(
            r.pos_rmse_m <= 0.025,
            "late trial {}: {} m",
            r.trial,
            r.pos_rmse_m
        );
        assert!(
            r.real_lift_m >= 0.05,
            "late trial {}: lift {} m",
            r.trial,
            r.real_lift_m
        );
    }
    let m = crate::pouring::ModeSummary::of(on_time);
    let (pos, roll, pitch, yaw) = (
        m.pos_rmse_m.mean,
        m.roll_rmse_deg.mean,
        m.pitch_rmse_deg.mean,
        m.yaw_rmse_deg.mean,
    );
    eprintln!(
        "closed loop, {} of {} trials grasped on time: {:.2} mm, roll {roll:.2} pitch {pitch:.2} yaw {yaw:.2} deg",
        task.trials as usize - late.len(),
        task.trials,
        pos * 1e3
    );
    assert!(pos <= 0.005, "{pos}");
    assert!(
        roll <= 1.0 && pitch <= 1.0 && yaw <= 1.0,
        "{roll} {pitch} {yaw}"
    );
}

/// Real human motion through the hand and the mapping: the Leap `grab` recording (a right hand
/// that closes into a fist, opens, closes and opens again; recorded closing on air) placed by
/// its mount so that its fist closes around the bottle twin's neck, in the scripted grasp's
/// orientation (palm toward the bottle, fingers along +x). The fist is too small to wrap the
/// 6 cm body (placed there it knocks the bottle over, docs/hand.md); the neck (2.3 cm) is what
/// a fist holds. The hand drives the closed loop against the simulated arm: no NaN, bounded
/// contact forces, contacts on the twin, the gripper closes while the hand closes and opens
/// when it opens, the twin stays on its table, the arm within its limits and the speed cap.
#[test]
fn a_real_leap_grab_takes_the_bottle_twin_by_its_neck_and_lets_go() {
    use avatarm_hand::leap::LeapMount;
    use avatarm_hand::leap_recording::LeapRecording;
    use avatarm_hand::{RecordedHand, tightest};
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    let dir = match avatarm_core::shared_data::shared_data() {
        Ok(dir) => dir,
        Err(why) => {
            return why.skip("a_real_leap_grab_takes_the_bottle_twin_by_its_neck_and_lets_go");
        }
    };
    let rec = LeapRecording::open(&dir.join("real/leap/grab.json.gz")).expect("recording");
    let first = rec.frames[0].hands[0].1.clone();
    let s = setup();
    let mut task = PouringTask::default();
    // Where the twin's neck is (virtual scene): above the body's centre by half the body and
    // half the neck.
    let centre = s.bottle_centre();
    let twin = task
        .virtual_to_real(&centre.translation.vector)
        .virtual_pose(&centre);
    let body = s.body_height_m() * task.k;
    let neck = (s.bottle_height_m - s.body_height_m()) * task.k;
    let neck_centre = twin.translation.vector + Vector3::z() * (body + neck) / 2.0;
    // The scripted grasp's orientation; the fist's inside (between the palm and each finger's
    // middle joint, at its tightest) on the neck's axis at mid-neck.
    let [r, p, y] = task.hand[1].rpy;
    let rotation = UnitQuaternion::from_euler_angles(r, p, y);
    let wrist_at = |t: Vector3<f64>| Isometry3::from_parts(Translation3::from(t), rotation);
    let grip_point = |f: &HandFrame| {
        let palm = f.joints[0].pose.translation.vector;
        [8, 13, 18, 23]
            .iter()
            .map(|&j| (palm + f.joints[j].pose.translation.vector) / 2.0)
            .sum::<Vector3<f64>>()
            / 4.0
    };
    let at_origin = rec
        .hand_frames(
            Some(first.hand),
            &LeapMount::with_wrist_pose(&first, &wrist_at(Vector3::zeros())).expect("mount"),
        )
        .expect("frames");
    let fist = tightest(&at_origin).expect("frames");
    let mount = LeapMount::with_wrist_pose(&first, &wrist_at(neck_centre - grip_point(fist)))
        .expect("mount");
    let frames = rec.hand_frames(Some(first.hand), &mount).expect("frames");
    let end_s = frames.last().map_or(0.0, |f| f.t_s);
    task.duration_s = end_s + 0.5;
    let r = run_trial_with(&task, &s, MappingMode::ClosedLoop, 0, |_| {
        ActiveHand::new(RecordedHand::from_frames("grab.json.gz".into(), frames).expect("hand"))
    })
    .expect("trial");
    let res = &r.result;
    let closed: Vec<f64> = r
        .samples
        .iter()
        .filter(|x| x.gripper_closed)
        .map(|x| x.t_s)
        .collect();
    let touching = r.samples.iter().filter(|x| x.contacts > 0).count();
    let first_open_after = |t: f64| {
        r.samples
            .iter()
            .find(|x| x.t_s > t && !x.gripper_closed)
            .map(|x| x.t_s)
    };
    let tilt = |p: &Isometry3<f64>| {
        (p.rotation * Vector3::z())
            .angle(&Vector3::z())
            .to_degrees()
    };
    let held_tilt = r
        .samples
        .iter()
        .zip(&r.twin)
        .filter(|(x, _)| x.gripper_closed)
        .map(|(_, t)| tilt(t))
        .fold(0.0, f64::max);
    let lowest = r
        .twin
        .iter()
        .map(|t| t.translation.z - twin.translation.z)
        .fold(f64::INFINITY, f64::min);
    // Grasp/release edges of the gripper (s).
    let edges: Vec<(f64, bool)> = r
        .samples
        .windows(2)
        .filter(|w| w[0].gripper_closed != w[1].gripper_closed)
        .map(|w| (w[1].t_s, w[1].gripper_closed))
        .collect();
    eprintln!(
        "real grab on the neck: gripper closed from {:?} s, edges (s, closed) {edges:?}, {} ticks closed, ticks with contacts {touching}/{}, max contact {:.1} N, twin lift {:.1} mm, real lift {:.1} mm, largest tilt while held {held_tilt:.1} deg, lowest twin centre {:.1} mm, max TCP {:.3} m/s, refused {}",
        closed.first(),
        closed.len(),
        r.samples.len(),
        res.max_contact_n,
        res.twin_lift_m * 1e3,
        res.real_lift_m * 1e3,
        lowest * 1e3,
        res.max_tcp_speed,
        res.hand_frames_refused,
    );
    assert_safe(&r, &task);
    assert!(r.twin.iter().all(finite), "no NaN in the twin");
    assert_eq!(res.hand_frames_refused, 0);
    assert!(
        res.max_contact_n < 200.0,
        "bounded forces: {}",
        res.max_contact_n
    );
    assert!(touching > 50, "contacts on the twin: {touching}");
    // The hand closes until 0.9 s, opens from 1.0 s to 1.5 s, closes from 1.8 s to 2.9 s
    // and opens from 2.9 s (closure, fingertips to palm: 107 -> 58 -> 108 -> 65 -> 107 mm).
    let grasp = closed.first().copied().expect("the gripper closed");
    assert!(
        grasp <= 0.9,
        "the grasp while the hand closes, not at {grasp} s"
    );
    let release = first_open_after(grasp).expect("the gripper opened again");
    assert!(
        (1.0..=1.6).contains(&release),
        "the release when the hand opens, not at {release} s"
    );
    let again = closed
        .iter()
        .find(|&&t| t > release)
        .copied()
        .expect("a second grasp");
    assert!(
        (1.7..=2.9).contains(&again),
        "the second grasp at {again} s"
    );
    let last = first_open_after(again).expect("a second release");
    assert!(last >= 2.9, "the second release at {last} s");
    assert!(held_tilt < 25.0, "the twin held upright: {held_tilt} deg");
    // Never into the table: a bottle on its side has its centre a radius above it.
    let floor = s.bottle_radius_m * task.k - body / 2.0;
    assert!(lowest > floor - 0.003, "{lowest} vs {floor}");
}

/// The task's trial on a simulated arm left away from the task's start by `off` (joint index,
/// rad), in closed loop; and that start.
fn parts_off_the_start(
    s: &TrialSetup,
    task: &PouringTask,
    off: &[(usize, f64)],
) -> (crate::pouring::TrialParts, DVector<f64>) {
    use crate::pouring::{TrialParts, prepare, simulated_arm};
    let prepared = prepare(task, s).expect("prepared");
    let q0 = prepared.q0().clone();
    let mut away = q0.clone();
    for &(i, d) in off {
        away[i] += d;
    }
    let arm = simulated_arm(s, away);
    let parts = TrialParts::on_robot(
        task,
        s,
        &prepared,
        MappingMode::ClosedLoop,
        0,
        Some(Box::new(arm)),
    )
    .expect("parts");
    (parts, q0)
}

#[test]
fn an_arm_away_from_the_start_is_brought_there_first_within_the_limits() {
    use crate::{Approach, MappingPlugin, Teleop};
    let (s, task) = (setup(), PouringTask::default());
    // Where a real arm might have been left: 0.4, 0.3 and 0.2 rad off on three joints.
    let (mut parts, q0) = parts_off_the_start(&s, &task, &[(0, 0.4), (3, -0.3), (5, 0.2)]);
    let approach = Approach::to(q0.clone());
    parts.teleop.approach(approach.clone()).expect("approach");
    // A start that cannot work is refused and the one set stays.
    let e = parts
        .teleop
        .approach(Approach::to(DVector::from_element(3, 0.0)))
        .expect_err("3 values for 9 joints");
    assert!(e.to_string().contains("3 values"), "{e}");
    let e = parts
        .teleop
        .approach(Approach {
            speed_ratio: 1.5,
            ..approach.clone()
        })
        .expect_err("ratio");
    assert!(e.to_string().contains("speed ratio"), "{e}");
    parts.teleop.record = true;
    let (period, spawn) = (parts.period, parts.spawn_bodies());
    let mut app = avatarm_hand::headless_app(period);
    app.add_plugins(MappingPlugin)
        .insert_resource(parts.hand_drive)
        .insert_resource(ActiveHand::new(ScriptedHand::new(
            parts.script,
            task.hand_rate_hz,
        )))
        .insert_resource(parts.teleop)
        .add_systems(bevy::prelude::Startup, spawn);
    let limits: Vec<f64> = s.model.dof_limits().iter().map(|l| l.velocity).collect();
    let mut worst_ratio: f64 = 0.0;
    let mut ticks = 0;
    loop {
        app.update();
        ticks += 1;
        let t = app.world().resource::<Teleop>();
        let v = t.robot().simulated().expect("sim").true_velocities();
        for &i in &s.arm {
            worst_ratio = worst_ratio.max(v[i].abs() / limits[i]);
        }
        if !t.status.approaching {
            break;
        }
        assert!(ticks < 2000, "not there after 20 s: {:?}", t.status);
    }
    let t = app.world().resource::<Teleop>();
    let took = t.status.approach_s.expect("arrival time");
    let q = t.robot().simulated().expect("sim").true_positions();
    let off = s
        .arm
        .iter()
        .map(|&i| (q[i] - q0[i]).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "approach: {took:.2} s, {ticks} ticks, within {off:.4} rad, joints at most {:.0} % of their limits, TCP {:.3} m/s",
        worst_ratio * 1e2,
        t.status.max_tcp_speed
    );
    // The measured joints are within the tolerance; the true ones lag them by a tick at most.
    assert!(off <= approach.tolerance_rad + 0.01, "{off}");
    assert!(worst_ratio <= approach.speed_ratio + 0.02, "{worst_ratio}");
    assert!(t.status.max_tcp_speed <= task.max_tcp_speed + 1e-9);
    assert!(
        took > 0.5,
        "a 0.4 rad move at 30 % speed takes time: {took}"
    );
    // Approach ticks are recorded too (their commands; no contact, the gripper open), one per
    // tick that commanded the arm; the arrival tick is the mapping's first.
    let approached = t.log.len();
    assert!(approached > 50, "{approached} ticks recorded");
    assert!(
        t.log[..approached - 1]
            .iter()
            .all(|s| s.contacts == 0 && !s.gripper_closed && s.qdot.iter().all(|v| v.is_finite()))
    );
    assert!(t.log[..approached - 1].iter().any(|s| s.qdot.amax() > 0.0));
    // Then the hand drives it: ticks are the mapping's, recorded.
    for _ in 0..50 {
        app.update();
    }
    let t = app.world().resource::<Teleop>();
    assert_eq!(t.log.len(), approached + 50);
    assert!(!t.status.approaching);
}

/// On its own thread the robot side ticks at the control rate whatever the app's side does:
/// with the app ticking every 150 ms, the arm still moves to the start on every 10 ms tick, and
/// the joint states and the log come back to the app (on its clock, in order, even where the
/// app's clock loses time against the wall's); dropping the app's side stops the thread.
#[test]
fn the_control_thread_ticks_the_robot_while_the_app_is_slow() {
    use crate::{Approach, TickSource};
    use std::time::Duration;
    let (s, task) = (setup(), PouringTask::default());
    let (mut parts, q0) = parts_off_the_start(&s, &task, &[(0, 0.3)]);
    parts
        .teleop
        .approach(Approach::to(q0.clone()))
        .expect("approach");
    parts.teleop.record = true;
    let mut front = parts
        .teleop
        .on_control_thread(Duration::from_millis(10))
        .expect("the thread starts");
    assert!(
        front.robot().simulated().is_none(),
        "the arm is the thread's"
    );
    let mut stamps = Vec::new();
    let mut logged = 0;
    for k in 0..6 {
        std::thread::sleep(Duration::from_millis(150));
        // The app's clock runs behind the wall's (a slow app): the offset is taken back.
        front.tick(f64::from(k) * 0.01, 0.01, TickSource::Remote(None));
        stamps.extend(front.received().iter().map(|j| j.stamp_s));
        logged += front.log.len();
        front.log.clear();
    }
    let ticks = front.status.ticks;
    let stats = front.thread_stats().expect("on a thread");
    eprintln!("{} ticks; {}", ticks, stats.line());
    // About 90 ticks in 0.9 s; a third of that whatever the machine's load.
    assert!(ticks >= 30, "{ticks} ticks");
    assert!(
        stamps.len() >= 30 && logged >= 30,
        "{} states, {logged} logged",
        stamps.len()
    );
    assert!(stamps.windows(2).all(|w| w[0] < w[1]), "{stamps:?}");
    // Moved onto the app's clock: the newest state is near the app's last tick (0.05 s), not
    // at the thread's 0.9 s.
    let newest = *stamps.last().unwrap();
    assert!((newest - 0.05).abs() < 0.1, "{newest}");
    assert_eq!(stats.period_ms, 10.0);
    assert!(stats.intervals_ms.n + 1 >= 30);
    // An app whose clock follows the wall's (a constant offset from the thread's): the joint
    // states come back at the thread's spacing (10 ms), the newest just before the app's now.
    let wall = std::time::Instant::now();
    let mut stamps = Vec::new();
    let mut app_now = 0.0;
    for _ in 0..6 {
        std::thread::sleep(Duration::from_millis(50));
        app_now = 100.0 + wall.elapsed().as_secs_f64();
        front.tick(app_now, 0.01, TickSource::Remote(None));
        stamps.extend(front.received().iter().map(|j| j.stamp_s));
    }
    let mut steps: Vec<f64> = stamps.windows(2).map(|w| (w[1] - w[0]) * 1e3).collect();
    steps.sort_by(f64::total_cmp);
    let step = steps[steps.len() / 2];
    assert!(
        (5.0..=20.0).contains(&step),
        "median spacing {step} ms: {steps:?}"
    );
    let newest = *stamps.last().unwrap();
    assert!(
        newest <= app_now + 1e-3 && newest > app_now - 0.06,
        "{newest} vs the app's {app_now}"
    );
    // Settings of the robot side are set before it moves to its thread.
    assert!(front.approach(Approach::to(q0.clone())).is_err());
    assert!(front.set_watchdog_timeout(0.2).is_err());
    // The arm moved toward the start on the thread's ticks.
    let q = front.joints().expect("a joint state").positions.clone();
    assert!((q[0] - q0[0]).abs() < 0.29, "{} vs {}", q[0], q0[0]);
    assert!(front.status.approaching || front.status.approach_s.is_some());
    // Dropped: the thread stops and is joined (this returns).
    drop(front);
}
