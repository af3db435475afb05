//! `avatarm robot`: a description's tree, meshes and link poses, real descriptions included.

use super::*;
use avatarm::cli::robot::RobotReport;

#[test]
fn robot_command_prints_fk_poses_as_json() {
    let urdf = root().join("assets/robots/sawyer_lite/sawyer_lite.urdf");
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args([
            "robot",
            urdf.to_str().unwrap(),
            "--json",
            "--q",
            "0.1,-0.5,0.2,1.0",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: RobotReport = serde_json::from_slice(&out.stdout).unwrap();
    let model =
        avatarm_core::robot::RobotModel::from_urdf_file(&urdf, &PackagePath::default()).unwrap();
    let q = [0.1, -0.5, 0.2, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let poses = model.forward_kinematics(&Isometry3::identity(), &q);
    let tip = &json.links["right_gripper_tip"];
    let t = poses[model.link_id("right_gripper_tip").unwrap()];
    for (i, v) in t.translation.vector.iter().enumerate() {
        assert!((tip.translation[i] - v).abs() < 1e-12);
    }
    let w = tip.rotation_xyzw[3];
    assert!((w.abs() - t.rotation.w.abs()).abs() < 1e-12);
    assert_eq!(json.links.len(), model.links.len());
    assert_eq!(json.q.len(), model.dof());
    assert_eq!(json.q, q[..model.dof()]);

    // Named values, and the tree.
    let tree = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["robot", urdf.to_str().unwrap(), "--q", "right_j3=0.5"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&tree.stdout);
    assert!(
        text.contains("right_j6 (revolute q[6]") && text.contains("[-4.7124, 4.7124] rad"),
        "{text}"
    );

    // A broken description: non-zero exit, the element named.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let bad = dir.join("bad_joint.urdf");
    std::fs::write(
        &bad,
        "<robot name='b'>\n<link name='a'/><link name='c'/>\n<joint name='j' type='ball'><parent link='a'/><child link='c'/></joint>\n</robot>\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["robot", bad.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad_joint.urdf:3") && err.contains("'j'") && err.contains("ball"),
        "{err}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["robot", urdf.to_str().unwrap(), "--q", "nope=1"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nope"));
}

/// The real robot descriptions (../shared/data/ros): `avatarm robot` prints the tree with the
/// mimic fingers and each link's meshes, and `--json` the mimic joint's position; a mesh that
/// cannot be read names the link, the URI and the file.
#[test]
fn robot_command_reads_real_descriptions() {
    let ros = match avatarm_core::shared_data::ros_packages() {
        Ok(dir) => dir,
        Err(why) => return why.skip("robot_command_reads_real_descriptions"),
    };
    let robot = |urdf: &Path, extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
            .arg("robot")
            .arg(urdf)
            .arg("--package-path")
            .arg(&ros)
            .args(extra)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let sawyer = ros.join("sawyer_description/urdf/sawyer_electric_gripper.urdf");
    let (ok, text, err) = robot(&sawyer, &[]);
    assert!(ok, "{err}");
    assert!(
        text.contains("9 movable")
            && text.contains(
                "right_gripper_r_finger_joint (prismatic mimic of right_gripper_l_finger_joint ×-1"
            )
            && text.contains("-> right_l0 [1 visual mesh, ")
            && text.contains("l0.DAE ("),
        "{text}"
    );
    let (ok, json, err) = robot(
        &sawyer,
        &["--json", "--q", "right_gripper_l_finger_joint=0.01"],
    );
    assert!(ok, "{err}");
    let json: RobotReport = serde_json::from_str(&json).unwrap();
    let follower = &json.mimic["right_gripper_r_finger_joint"];
    assert_eq!(follower.position, -0.01);
    assert_eq!(follower.leader, "right_gripper_l_finger_joint");
    let panda = ros.join("example-robot-data/robots/panda_description/urdf/panda.urdf");
    let (ok, text, err) = robot(&panda, &[]);
    assert!(
        ok && text.contains("mimic of panda_finger_joint1"),
        "{text}{err}"
    );

    // A Collada file that is not one: the link, the URI and the resolved file are named.
    let dir = out_dir("broken_mesh");
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::write(
        dir.join("meshes/Wrist.DAE"),
        "<COLLADA><library_geometries>",
    )
    .unwrap();
    let urdf = dir.join("arm.urdf");
    std::fs::write(
        &urdf,
        r#"<robot name="b"><link name="wrist"><visual><geometry><mesh filename="meshes/Wrist.DAE"/></geometry></visual></link></robot>"#,
    )
    .unwrap();
    let (ok, _, err) = robot(&urdf, &[]);
    assert!(!ok);
    assert!(
        err.contains("link 'wrist'")
            && err.contains("mesh 'meshes/Wrist.DAE'")
            && err.contains(&dir.join("meshes/Wrist.DAE").display().to_string()),
        "{err}"
    );
}
