//! One control tick (hand contacts → grasp analysis → mapped twist → DLS joint velocities →
//! safety limiter) for 2 to 20 contacts, beside FK + Jacobian of the same 7-DOF arm measured in
//! the same run (the tick's kinematic floor), and that FK + Jacobian against the `k` crate
//! (openrr) on the same URDF, checked equal first and reported as a ratio.
//! `cargo bench -p avatarm_core --bench control`.

mod common;

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use avatarm_core::robot::kinematics::Frame;
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::teleop::grasp::Contact;
use avatarm_core::teleop::mapping::{
    Mapper, MappingSettings, RobotSide, TickInputs, VirtualToReal,
};
use avatarm_core::teleop::safety::{self, SafetyLimiter, SafetySettings};
use common::median;
use criterion::{BenchmarkId, Criterion};
use nalgebra::{DVector, Isometry3, Vector3};

fn sawyer_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/robots/sawyer_lite/sawyer_lite.urdf")
}

fn sawyer() -> RobotModel {
    RobotModel::from_urdf_file(&sawyer_urdf(), &PackagePath::default())
        .expect("the bundled Sawyer loads")
}

/// The same arm in the `k` crate: the serial chain from the root to the tool frame (7 DOF).
fn k_arm() -> k::SerialChain<f64> {
    let chain = k::Chain::<f64>::from_urdf_file(sawyer_urdf()).expect("k loads the URDF");
    let tip = chain
        .find("right_gripper_tip_joint")
        .expect("the tool joint in k's chain");
    k::SerialChain::from_end(tip)
}

/// The arm's joint values (7) and the same with the gripper's fingers (9, Avatarm's order).
const Q_ARM: [f64; 7] = [0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161];

/// k's FK + Jacobian of the tool frame at `q`.
fn k_jacobian(arm: &k::SerialChain<f64>, q: &[f64]) -> k::nalgebra::DMatrix<f64> {
    arm.set_joint_positions_unchecked(q);
    arm.update_transforms();
    k::jacobian(arm)
}

/// Both libraries give the same Jacobian (base at the origin: k's chain has no base offset).
fn check_k_agrees(model: &RobotModel, tcp: usize, arm: &k::SerialChain<f64>) {
    let mut q = Q_ARM.to_vec();
    q.extend([0.02, 0.02]);
    let ours = model.jacobian(
        &Isometry3::identity(),
        &q,
        tcp,
        &Vector3::zeros(),
        Frame::World,
    );
    let theirs = k_jacobian(arm, &Q_ARM);
    assert_eq!((theirs.nrows(), theirs.ncols()), (6, 7));
    for r in 0..6 {
        for c in 0..7 {
            assert!(
                (ours[(r, c)] - theirs[(r, c)]).abs() < 1e-9,
                "Jacobian ({r}, {c}): Avatarm {} vs k {}",
                ours[(r, c)],
                theirs[(r, c)]
            );
        }
    }
}

/// `n` contacts spread around a bottle at `origin`, squeezing inward, moving with it.
fn contacts(n: usize, origin: &Vector3<f64>) -> (Vec<Contact>, Vec<Vector3<f64>>) {
    (0..n)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / n as f64;
            let radial = Vector3::new(a.cos(), a.sin(), 0.0);
            let point = origin + radial * 0.035 + Vector3::new(0.0, 0.0, 0.02 * (i % 3) as f64);
            let contact = Contact {
                point,
                normal: -radial,
                force: -radial * 2.0,
                moment: Vector3::zeros(),
            };
            (contact, Vector3::new(0.0, 0.0, 0.05))
        })
        .unzip()
}

fn benches(c: &mut Criterion) {
    let model = sawyer();
    let tcp = model.link_id("right_gripper_tip").expect("tool link");
    let arm: Vec<usize> = (0..7).collect();
    let base = Isometry3::translation(0.0, 0.0, 0.75);
    let q = [0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02];
    let robot = RobotSide {
        model: &model,
        base,
        tcp,
        arm: &arm,
        tcp_from_object: Isometry3::identity(),
    };
    let v2r = VirtualToReal {
        k: 0.5,
        ..VirtualToReal::identity()
    };
    let twin = Isometry3::translation(0.3, -0.08, 0.45);
    let k_arm = k_arm();
    check_k_agrees(&model, tcp, &k_arm);
    let mut group = c.benchmark_group("control");
    group.bench_function("fk+jacobian", |b| {
        b.iter(|| {
            let poses = model.forward_kinematics(&base, black_box(&q));
            black_box(model.jacobian_from_poses(&poses, tcp, &Vector3::zeros(), Frame::World))
        });
    });
    group.bench_function("fk+jacobian k crate", |b| {
        b.iter(|| black_box(k_jacobian(&k_arm, black_box(&Q_ARM))));
    });
    for n in [2usize, 4, 8, 12, 20] {
        let (cs, vs) = contacts(n, &twin.translation.vector);
        let mut mapper = Mapper::new(MappingSettings::default());
        let mut limiter = SafetyLimiter::new(SafetySettings::default(), model.dof_limits());
        let mut now = 0.0;
        group.bench_function(BenchmarkId::new("tick", n), |b| {
            b.iter(|| {
                now += 0.01;
                let out = mapper
                    .tick(
                        &TickInputs {
                            contacts: black_box(&cs),
                            contact_velocities: &vs,
                            twin_pose: twin,
                            q: &q,
                            held: true,
                            now_s: now,
                            joints_stamp_s: now - 0.01,
                        },
                        &v2r,
                        &robot,
                    )
                    .expect("tick");
                let limited = limiter.tick(
                    &safety::TickInputs {
                        now_s: now,
                        qdot: &out.qdot,
                        q: &q,
                        joints_stamp_s: Some(now),
                        hand_stamp_s: Some(now),
                        hand_tracked: true,
                        jacobian: &out.tcp_jacobian,
                    },
                    0.01,
                );
                black_box(limited.command.unwrap_or_else(|| DVector::zeros(9)))
            });
        });
    }
    group.finish();
}

/// The median of some timings.
/// FK + Jacobian, Avatarm against k, from batches interleaved in one loop (so both see the
/// same machine state); criterion's report above has the statistics of each.
fn k_ratio() {
    const BATCH: u32 = 2000;
    let model = sawyer();
    let tcp = model.link_id("right_gripper_tip").expect("tool link");
    let k_arm = k_arm();
    let base = Isometry3::identity();
    let q = [0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02];
    let (mut ours, mut theirs) = (Vec::new(), Vec::new());
    for _ in 0..31 {
        let t = Instant::now();
        for _ in 0..BATCH {
            let poses = model.forward_kinematics(&base, black_box(&q));
            black_box(model.jacobian_from_poses(&poses, tcp, &Vector3::zeros(), Frame::World));
        }
        ours.push(t.elapsed() / BATCH);
        let t = Instant::now();
        for _ in 0..BATCH {
            black_box(k_jacobian(&k_arm, black_box(&Q_ARM)));
        }
        theirs.push(t.elapsed() / BATCH);
    }
    let (ours, theirs) = (median(ours), median(theirs));
    println!(
        "\nFK + Jacobian of the 7-DOF arm (medians of 31 interleaved batches of {BATCH}): \
         Avatarm {:.2} us (every link of the tree, 9 DOF), k {:.2} us (the serial chain, 7 DOF); \
         Avatarm / k = {:.2}",
        ours.as_secs_f64() * 1e6,
        theirs.as_secs_f64() * 1e6,
        ours.as_secs_f64() / theirs.as_secs_f64().max(1e-12)
    );
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    benches(&mut c);
    c.final_summary();
    k_ratio();
}
