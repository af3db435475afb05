//! Tests of [`super`] (urdf).

use super::*;

const TREE: &str = r#"<robot name="t">
  <link name="base"/>
  <link name="a"/>
  <link name="b"/>
  <link name="a2"/>
  <joint name="j_b" type="prismatic">
<parent link="base"/><child link="b"/><axis xyz="0 0 2"/>
<limit lower="0" upper="0.5" velocity="0.1" effort="10"/>
  </joint>
  <joint name="j_a" type="revolute">
<parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
<limit lower="-1" upper="1" velocity="2" effort="5"/>
  </joint>
  <joint name="j_a2" type="continuous">
<parent link="a"/><child link="a2"/><axis xyz="1 0 0"/>
  </joint>
</robot>"#;

fn load(text: &str) -> Result<RobotModel> {
    RobotModel::from_urdf_str(text, None, &PackagePath::default())
}

#[test]
fn depth_first_in_file_order() {
    let r = load(TREE).unwrap();
    let names: Vec<_> = r.links.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(names, ["base", "b", "a", "a2"]);
    assert_eq!(r.dof_names(), ["j_b", "j_a", "j_a2"]);
    let jb = &r.joints[r.dofs[0]];
    assert_eq!(jb.kind, JointKind::Prismatic);
    assert!((jb.axis.norm() - 1.0).abs() < 1e-12);
    let ja2 = &r.joints[r.dofs[2]];
    assert_eq!(ja2.limits.lower, f64::NEG_INFINITY);
    assert_eq!(ja2.limits.velocity, f64::INFINITY);
    assert_eq!(r.tip_link(), r.link_id("a2").unwrap());
}

#[test]
fn parses_joint_vectors() {
    let r = load(TREE).unwrap();
    assert_eq!(r.parse_q("0.1, 0.2").unwrap().as_slice(), &[0.1, 0.2, 0.0]);
    assert_eq!(r.parse_q("j_a2=3").unwrap().as_slice(), &[0.0, 0.0, 3.0]);
    assert!(matches!(
        r.parse_q("1,2,3,4"),
        Err(Error::JointCount { .. })
    ));
    assert!(matches!(r.parse_q("x=1"), Err(Error::UnknownJoint { .. })));
    assert!(matches!(r.parse_q("NaN"), Err(Error::NonFinite { .. })));
    assert!(matches!(r.parse_q("abc"), Err(Error::NotANumber { .. })));
}

#[test]
fn rejects_bad_descriptions_naming_the_element() {
    let unknown = TREE.replace(r#"type="continuous""#, r#"type="spherical""#);
    let e = load(&unknown).unwrap_err().to_string();
    assert!(
        e.contains("j_a2") && e.contains("spherical") && e.contains(":14:"),
        "{e}"
    );

    let e = load("<robot><link name='a'></robot>").unwrap_err();
    assert!(matches!(e, Error::MalformedUrdf { .. }), "{e}");

    let two_roots = r#"<robot name="t"><link name="a"/><link name="b"/></robot>"#;
    assert!(matches!(
        load(two_roots),
        Err(Error::SeveralRoots { count: 2, .. })
    ));

    let looped = r#"<robot name="t"><link name="a"/><link name="b"/>
      <joint name="x" type="fixed"><parent link="a"/><child link="b"/></joint>
      <joint name="y" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"#;
    let e = load(looped).unwrap_err();
    assert!(matches!(e, Error::Loop { .. }), "{e}");

    let two_parents = r#"<robot name="t"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="x" type="fixed"><parent link="a"/><child link="c"/></joint>
      <joint name="y" type="fixed"><parent link="b"/><child link="c"/></joint></robot>"#;
    let e = load(two_parents).unwrap_err().to_string();
    assert!(e.contains("'x'") && e.contains("'y'"), "{e}");

    let missing = r#"<robot name="t"><link name="a"/>
      <joint name="x" type="fixed"><parent link="a"/><child link="ghost"/></joint></robot>"#;
    let e = load(missing).unwrap_err().to_string();
    assert!(e.contains("ghost") && e.contains("'x'"), "{e}");

    let bad_limits = TREE.replace(r#"lower="-1" upper="1""#, r#"lower="1" upper="-1""#);
    assert!(matches!(load(&bad_limits), Err(Error::BadJoint { .. })));

    let zero_axis = TREE.replace(r#"<axis xyz="1 0 0"/>"#, r#"<axis xyz="0 0 0"/>"#);
    let e = load(&zero_axis).unwrap_err().to_string();
    assert!(e.contains("j_a2") && e.contains("axis"), "{e}");
}

/// ../shared/cases/05: a revolute joint without `<limit>` used to load with limits
/// [0, 0]; ../shared/cases/14: a decimal comma was "wrong vector element count".
#[test]
fn a_missing_limit_and_a_decimal_comma_are_named() {
    let no_limit = r#"<robot name="t"><link name="a"/><link name="b"/>
      <joint name="elbow" type="revolute"><parent link="a"/><child link="b"/>
      <axis xyz="0 1 0"/></joint></robot>"#;
    let e = load(no_limit).unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, Error::BadJoint { .. }), "{text}");
    assert!(
        text.contains("<string>:2") && text.contains("'elbow'") && text.contains("<limit>"),
        "{text}"
    );
    let prismatic = no_limit.replace("revolute", "prismatic");
    assert!(
        load(&prismatic)
            .unwrap_err()
            .to_string()
            .contains("<limit>")
    );
    // Continuous and fixed joints need none.
    load(&no_limit.replace("revolute", "continuous")).expect("continuous");

    let comma = r#"<robot name="t"><link name="a"/><link name="b"/>
      <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
      <origin xyz="0,25 0 0,5" rpy="0 0 0"/><axis xyz="0 0 1"/>
      <limit lower="-1" upper="1" effort="10" velocity="1"/></joint></robot>"#;
    let e = load(comma).unwrap_err().to_string();
    assert!(
        e.contains("'j1'") && e.contains("<origin xyz=") && e.contains("'0,25' is not a number"),
        "{e}"
    );
    let bad_limit = comma
        .replace("0,25 0 0,5", "0.25 0 0.5")
        .replace(r#"effort="10""#, r#"effort="ten""#);
    let e = load(&bad_limit).unwrap_err().to_string();
    assert!(e.contains("<limit effort=\"ten\">"), "{e}");
}

#[test]
fn floating_and_planar_joints_read_as_fixed_with_a_note() {
    for kind in ["floating", "planar"] {
        let r = load(&TREE.replace(r#"type="continuous""#, &format!(r#"type="{kind}""#))).unwrap();
        assert_eq!(r.dof_names(), ["j_b", "j_a"]);
        let j = r.joints.iter().find(|j| j.name == "j_a2").unwrap();
        assert_eq!(j.kind, JointKind::Fixed);
        assert!(
            r.notes.len() == 1 && r.notes[0].contains("'j_a2'") && r.notes[0].contains(kind),
            "{:?}",
            r.notes
        );
    }
}

#[test]
fn mimic_joints_are_not_in_q_and_bad_mimics_are_named() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/cases/09-mimic-joint/robot.urdf");
    let text = std::fs::read_to_string(&path).unwrap();
    let r = load(&text).unwrap();
    assert_eq!(r.dof(), 1);
    let e = r.parse_q("j_leader=0.3,j_follower=1.0").unwrap_err();
    assert!(matches!(e, Error::MimicJoint { .. }), "{e}");
    assert!(
        e.to_string().contains("'j_follower' is a mimic joint"),
        "{e}"
    );
    let q = r.parse_q("j_leader=0.3").unwrap();
    let positions = r.joint_positions(q.as_slice());
    assert!((positions[1] - 0.7).abs() < 1e-12, "{positions:?}");

    let missing = text.replace(r#"<mimic joint="j_leader""#, r#"<mimic joint="j_ghost""#);
    let e = load(&missing).unwrap_err().to_string();
    assert!(e.contains("'j_follower'") && e.contains("j_ghost"), "{e}");

    // A chain: a third joint follows the follower (x3): 3·(2a + 0.1) - 0.2.
    let chain = text.replace(
        r#"<joint name="tip_joint" type="fixed">"#,
        r#"<joint name="tip_joint" type="revolute"><axis xyz="0 0 1"/>
           <limit lower="-9" upper="9" effort="1" velocity="1"/>
           <mimic joint="j_follower" multiplier="3" offset="-0.2"/>"#,
    );
    let r = load(&chain).unwrap();
    assert_eq!(r.dof(), 1);
    let tip = r.joints.iter().find(|j| j.name == "tip_joint").unwrap();
    assert!((tip.position(&[0.3]) - (3.0 * 0.7 - 0.2)).abs() < 1e-12);
    assert_eq!(tip.drive(), Some((0, 6.0)));

    let looped = text.replace(r#"<mimic joint="j_leader""#, r#"<mimic joint="j_follower""#);
    let e = load(&looped).unwrap_err().to_string();
    assert!(e.contains("loop") && e.contains("j_follower"), "{e}");
    let two = chain.replace(
        r#"<mimic joint="j_leader" multiplier="2.0" offset="0.1"/>"#,
        r#"<mimic joint="tip_joint"/>"#,
    );
    let e = load(&two).unwrap_err().to_string();
    assert!(
        e.contains("loop") && e.contains("j_follower") && e.contains("tip_joint"),
        "{e}"
    );
}

/// ../shared/cases/11: a package two folders below the package-path entry.
#[test]
fn packages_are_found_below_the_path_by_package_xml() {
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/cases/11-package-nested");
    let urdf = case.join("ws/src/arm_stack/my_arm_description/urdf/arm.urdf");
    let r = RobotModel::from_urdf_file(&urdf, &PackagePath(vec![case.join("ws/src")])).unwrap();
    let link1 = r.link_id("link1").unwrap();
    let Shape::Mesh { path, .. } = &r.links[link1].visuals[0].shape else {
        panic!("not a mesh")
    };
    assert!(
        path.ends_with("arm_stack/my_arm_description/meshes/link1.stl"),
        "{path:?}"
    );
    // Not found: the error names the package and the folders searched.
    let e = RobotModel::from_urdf_file(
        &urdf,
        &PackagePath(vec![
            case.join("ws/src/arm_stack/my_arm_description/meshes"),
        ]),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("'my_arm_description'") && e.contains("meshes") && e.contains("package.xml"),
        "{e}"
    );
}

#[test]
fn a_zero_or_non_finite_mesh_scale_names_the_link() {
    let dir = std::env::temp_dir().join(format!("avatarm_scale_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("a.stl"), b"solid a\nendsolid a\n").unwrap();
    for scale in ["0 1 1", "1 nan 1", "1 1 inf"] {
        let urdf = format!(
            r#"<robot name="m"><link name="wrist"><visual><geometry><mesh filename="a.stl" scale="{scale}"/></geometry></visual></link></robot>"#
        );
        let e = RobotModel::from_urdf_str(&urdf, Some(&dir), &PackagePath::default()).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, Error::BadGeometry { .. }), "{text}");
        assert!(text.contains("'wrist'") && text.contains("scale"), "{text}");
    }
    let mirrored = r#"<robot name="m"><link name="wrist"><visual><geometry><mesh filename="a.stl" scale="-1 1 1"/></geometry></visual></link></robot>"#;
    assert!(RobotModel::from_urdf_str(mirrored, Some(&dir), &PackagePath::default()).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn resolves_mesh_uris() {
    let dir = std::env::temp_dir().join(format!("avatarm_uri_{}", std::process::id()));
    let pkg = dir.join("share").join("my_robot").join("meshes");
    std::fs::create_dir_all(&pkg).unwrap();
    std::fs::write(pkg.join("a.stl"), b"solid a\nendsolid a\n").unwrap();
    let urdf = |uri: &str| {
        format!(
            r#"<robot name="m"><link name="l"><visual><geometry><mesh filename="{uri}" scale="2 2 2"/></geometry></visual></link></robot>"#
        )
    };
    let packages = PackagePath(vec![dir.join("share")]);
    let r = RobotModel::from_urdf_str(&urdf("package://my_robot/meshes/a.stl"), None, &packages)
        .unwrap();
    let Shape::Mesh { path, scale, .. } = &r.links[0].visuals[0].shape else {
        panic!("not a mesh")
    };
    assert_eq!(path, &pkg.join("a.stl"));
    assert_eq!(scale.x, 2.0);

    // The package folder itself on the path.
    let itself = PackagePath(vec![dir.join("share").join("my_robot")]);
    assert!(
        RobotModel::from_urdf_str(&urdf("package://my_robot/meshes/a.stl"), None, &itself).is_ok()
    );
    // Relative to the base folder, and file://.
    assert!(
        RobotModel::from_urdf_str(&urdf("meshes/a.stl"), Some(&pkg.join("..")), &packages).is_ok()
    );
    let file_uri = format!("file://{}", pkg.join("a.stl").display());
    assert!(RobotModel::from_urdf_str(&urdf(&file_uri), None, &packages).is_ok());

    let e = RobotModel::from_urdf_str(&urdf("package://other/a.stl"), None, &packages)
        .unwrap_err()
        .to_string();
    assert!(e.contains("'other'") && e.contains("link 'l'"), "{e}");
    let e =
        RobotModel::from_urdf_str(&urdf("package://my_robot/b.stl"), None, &packages).unwrap_err();
    assert!(matches!(e, Error::MissingMesh { .. }), "{e}");
    let e = RobotModel::from_urdf_str(&urdf("http://x/a.stl"), None, &packages).unwrap_err();
    assert!(matches!(e, Error::UnsupportedUri { .. }), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
