//! One control tick (hand contacts → grasp analysis → mapped twist → DLS joint velocities →
//! safety limiter) for 2 to 20 contacts, beside FK + Jacobian of the same 7-DOF arm measured in
//! the same run (the tick's kinematic floor). `cargo bench -p avatarm_core --bench control`.

use std::hint::black_box;
use std::path::Path;

use avatarm_core::grasp::Contact;
use avatarm_core::kinematics::Frame;
use avatarm_core::mapping::{Mapper, MappingSettings, RobotSide, TickInputs, VirtualToReal};
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::safety::{self, SafetyLimiter, SafetySettings};
use criterion::{BenchmarkId, Criterion};
use nalgebra::{DVector, Isometry3, Vector3};

fn sawyer() -> RobotModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
    RobotModel::from_urdf_file(&path, &PackagePath::default()).expect("the bundled Sawyer loads")
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
    let mut group = c.benchmark_group("control");
    group.bench_function("fk+jacobian", |b| {
        b.iter(|| {
            let poses = model.forward_kinematics(&base, black_box(&q));
            black_box(model.jacobian_from_poses(&poses, tcp, &Vector3::zeros(), Frame::World))
        });
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

fn main() {
    let mut c = Criterion::default().configure_from_args();
    benches(&mut c);
    c.final_summary();
}
