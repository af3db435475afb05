//! The real Sawyer and Panda descriptions (../shared/data/ros): they load with their Collada
//! meshes and mimic fingers, and the real Sawyer's arm is the project's `sawyer_lite`.

use std::path::{Path, PathBuf};

use avatarm_core::rng::Rng;
use avatarm_core::robot::mesh::load_mesh;
use avatarm_core::robot::{JointKind, PackagePath, RobotModel, Shape};
use avatarm_core::shared_data::ros_packages;
use nalgebra::Isometry3;

fn real(relative: &str) -> Option<(RobotModel, PathBuf)> {
    let ros = match ros_packages() {
        Ok(dir) => dir,
        Err(why) => {
            why.skip(relative);
            return None;
        }
    };
    let model = RobotModel::from_urdf_file(&ros.join(relative), &PackagePath(vec![ros.clone()]))
        .unwrap_or_else(|e| panic!("{relative}: {e}"));
    Some((model, ros))
}

/// The project's primitive Sawyer.
fn sawyer_lite() -> RobotModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
    RobotModel::from_urdf_file(&path, &PackagePath::default()).expect("sawyer_lite loads")
}

/// Loads every visual mesh; returns (meshes, triangles, Collada files).
fn load_visuals(model: &RobotModel) -> (usize, usize, usize) {
    let (mut meshes, mut triangles, mut collada) = (0, 0, 0);
    for link in &model.links {
        for g in &link.visuals {
            if let Shape::Mesh { path, scale, .. } = &g.shape {
                let m =
                    load_mesh(path, scale).unwrap_or_else(|e| panic!("link '{}': {e}", link.name));
                assert!(m.triangle_count() > 0, "{}", path.display());
                let (lo, hi) = m.bounds().expect("a mesh with triangles has bounds");
                // Metres: no link of these arms is larger than a metre or thinner than 5 mm.
                let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max);
                assert!(
                    (0.005..1.2).contains(&size),
                    "{}: {size} m across",
                    path.display()
                );
                meshes += 1;
                triangles += m.triangle_count();
                if path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("dae"))
                {
                    collada += 1;
                }
            }
        }
    }
    (meshes, triangles, collada)
}

#[test]
fn the_real_sawyer_loads_with_collada_meshes_and_a_mimic_finger() {
    let Some((model, _)) = real("sawyer_description/urdf/sawyer_electric_gripper.urdf") else {
        return;
    };
    let (meshes, triangles, collada) = load_visuals(&model);
    eprintln!("sawyer: {meshes} visual meshes ({collada} Collada), {triangles} triangles");
    assert!(
        collada >= 8 && triangles > 10_000,
        "{meshes} {collada} {triangles}"
    );
    let r = model
        .joints
        .iter()
        .find(|j| j.name == "right_gripper_r_finger_joint")
        .unwrap();
    let m = r.mimic.expect("the right finger mimics the left");
    assert_eq!(model.joints[m.leader].name, "right_gripper_l_finger_joint");
    assert_eq!((m.multiplier, m.offset), (-1.0, 0.0));
    assert!(!model.dof_names().contains(&"right_gripper_r_finger_joint"));
    // 7 arm joints, the head and one finger.
    assert_eq!(model.dof(), 9, "{:?}", model.dof_names());
}

#[test]
fn the_real_panda_loads_with_collada_meshes_and_a_mimic_finger() {
    let Some((model, _)) = real("example-robot-data/robots/panda_description/urdf/panda.urdf")
    else {
        return;
    };
    let (meshes, triangles, collada) = load_visuals(&model);
    eprintln!("panda: {meshes} visual meshes ({collada} Collada), {triangles} triangles");
    assert!(collada >= 8, "{meshes} {collada} {triangles}");
    let mimics: Vec<_> = model.joints.iter().filter(|j| j.mimic.is_some()).collect();
    assert_eq!(mimics.len(), 1);
    assert_eq!(mimics[0].kind, JointKind::Prismatic);
    assert_eq!(model.dof(), 8, "{:?}", model.dof_names());
}

/// The project's `sawyer_lite` has the real Sawyer's joint names and origins: at random q the
/// two agree on every arm link within 1 mm.
#[test]
fn the_real_sawyer_arm_is_sawyer_lite() {
    let Some((real, _)) = real("sawyer_description/urdf/sawyer_electric_gripper.urdf") else {
        return;
    };
    let lite = sawyer_lite();
    let arm = [
        "right_j0", "right_j1", "right_j2", "right_j3", "right_j4", "right_j5", "right_j6",
    ];
    let links = [
        "right_l0",
        "right_l1",
        "right_l2",
        "right_l3",
        "right_l4",
        "right_l5",
        "right_l6",
        "right_hand",
    ];
    let mut rng = Rng::new(16);
    let base = Isometry3::identity();
    let mut worst = 0.0f64;
    for _ in 0..200 {
        let mut q_real = vec![0.0; real.dof()];
        let mut q_lite = vec![0.0; lite.dof()];
        for name in arm {
            let i = real.dof_index(name).unwrap();
            let limits = real.dof_limits()[i];
            let v = limits.lower + rng.uniform() * (limits.upper - limits.lower);
            q_real[i] = v;
            q_lite[lite.dof_index(name).unwrap()] = v;
        }
        let a = real.forward_kinematics(&base, &q_real);
        let b = lite.forward_kinematics(&base, &q_lite);
        for name in links {
            let (ia, ib) = (real.link_id(name).unwrap(), lite.link_id(name).unwrap());
            let d = (a[ia].translation.vector - b[ib].translation.vector).norm();
            let angle = (a[ia].rotation.inverse() * b[ib].rotation).angle();
            worst = worst.max(d);
            assert!(d < 1e-3, "{name}: {d} m apart");
            assert!(angle < 1e-3, "{name}: {angle} rad apart");
        }
    }
    eprintln!("worst link distance: {worst:e} m");
}

/// A lighter description of the same robot takes the real one's joint states by name: the
/// arm joints directly, the right finger (a mimic joint in the real description, independent in
/// `sawyer_lite`) from its leader, and `sawyer_lite` has no head to fill.
#[test]
fn joint_states_map_from_the_real_sawyer_to_sawyer_lite() {
    let Some((real, _)) = real("sawyer_description/urdf/sawyer_electric_gripper.urdf") else {
        return;
    };
    let lite = sawyer_lite();
    let map = avatarm_core::robot::JointMap::new(&real, &lite);
    assert!(map.missing.is_empty(), "{:?}", map.missing);
    let q = real
        .parse_q("right_j0=0.3,right_j3=1.2,head_pan=-0.5,right_gripper_l_finger_joint=0.015")
        .unwrap();
    let mapped = map.apply(q.as_slice());
    let at = |name: &str| mapped[lite.dof_index(name).unwrap()];
    assert_eq!(at("right_j0"), 0.3);
    assert_eq!(at("right_j3"), 1.2);
    assert_eq!(at("right_gripper_l_finger_joint"), 0.015);
    assert_eq!(at("right_gripper_r_finger_joint"), -0.015);
    // The other way the head is missing: held at 0 (inside its limits).
    let back = avatarm_core::robot::JointMap::new(&lite, &real);
    assert_eq!(back.missing, ["head_pan"]);
    // The same description maps each joint to itself.
    let same = avatarm_core::robot::JointMap::new(&real, &real);
    assert_eq!(same.apply(q.as_slice()), q);
}
