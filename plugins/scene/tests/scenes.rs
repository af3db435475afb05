//! Scene validation: every bad value is refused when the scene loads, naming the file and the
//! field. No Bevy here: these tests link only the scene crate and the core.

use std::path::{Path, PathBuf};

use avatarm_core::robot::PackagePath;
use avatarm_scene::{Scene, SceneError};

/// The workspace root (the scenes live in its `assets/`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scene_text(name: &str) -> (PathBuf, String) {
    let path = root().join("assets/scenes").join(name);
    let text = std::fs::read_to_string(&path).expect("the scene file");
    (path, text)
}

#[test]
fn bad_scenes_are_refused_naming_the_field() {
    let path = root().join("assets/scenes/default.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());

    let e = parse(&text.replace("fps = 30.0", "fps = 30.0\nfsp = 1")).unwrap_err();
    assert!(
        matches!(e, SceneError::Parse { .. }) && e.to_string().contains("fsp"),
        "{e}"
    );

    let e = parse(&text.replace("fx = 461.0", "fx = -461.0"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera.intrinsics") && e.contains("fx"), "{e}");

    let e = parse(&text.replace(
        "q = { right_j0 = 0.1, right_j6 = 4.5 }",
        "q = { right_j9 = 0.1 }",
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("timeline.robot[5].q") && e.contains("right_j9"),
        "{e}"
    );

    let e = parse(&text.replace(
        "latency_compensation = true",
        "latency_compensation = true\nranges = [[240, 255], [250, 240], [240, 255], [240, 255]]",
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("erase") && e.contains("G range"), "{e}");
    let e = parse(&text.replace(
        "[erase]",
        "[background]\nsource = \"file\"\npath = \"nowhere.png\"\n\n[erase]",
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("background.path") && e.contains("nowhere.png"),
        "{e}"
    );
    let e = parse(&text.replace("duration_s = 10.0", "duration_s = -1"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("duration_s"), "{e}");

    let e = parse(&text.replace("sawyer_lite.urdf\"", "missing.urdf\""))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("robot.urdf") && e.contains("missing.urdf"),
        "{e}"
    );

    let e = parse(&text.replace("t_s = 2.5", "t_s = 0.2"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("timeline.robot[1].t_s"), "{e}");

    let e = parse(&format!("{text}\n[xr_layout]\npanel_distance_m = 0.05\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("xr_layout") && e.contains("0.05"), "{e}");
    let xr = parse(&text.replace("duration_s = 10.0", "duration_s = 10.0\nxr = true"))
        .expect("xr = true is a scene setting");
    assert!(xr.file.xr);

    let head = parse(&format!(
        "{text}\n[leap]\nmount = \"head\"\ndevice_at = [0.2, 0.0, 1.1]\n"
    ))
    .expect("a head-mounted Leap");
    assert_eq!(
        head.file.leap.mount,
        avatarm_scene::spec::LeapMountKind::Head
    );
    assert_eq!(head.file.leap.device_at, Some([0.2, 0.0, 1.1]));
    let e = parse(&format!("{text}\n[leap]\nmount = \"chest\"\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("leap.mount") || e.contains("chest"), "{e}");
    let e = parse(&format!(
        "{text}\n[leap]\nmount = \"first_wrist\"\ndevice_at = [0.0, 0.0, 1.0]\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("leap.device_at"), "{e}");
}

/// `[robot.link]`: ROS 1's and ROS 2's settings, each bad one refused naming its field.
#[test]
fn robot_links_are_checked_at_load() {
    let path = root().join("assets/scenes/default.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());
    let with_link = format!(
        "{text}\n[robot.link]\nkind = \"ros_control\"\ncommand_topic = \"/c\"\nspeed_ratio = 0.5\n"
    );
    let link = parse(&with_link).expect("a ros_control link");
    assert_eq!(
        link.file.robot.link.kind,
        avatarm_scene::spec::RobotLinkKind::RosControl
    );
    let e = parse(&with_link.replace("speed_ratio = 0.5", "speed_ratio = 0"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("robot.link.speed_ratio"), "{e}");
    let ros2 = parse(&format!(
        "{text}\n[robot.link]\nkind = \"ros2_control\"\ndomain_id = 7\ncommand_topic = \"/forward_velocity_controller/commands\"\n"
    ))
    .expect("a ros2_control link");
    assert_eq!(
        (ros2.file.robot.link.kind, ros2.file.robot.link.domain_id),
        (avatarm_scene::spec::RobotLinkKind::Ros2Control, Some(7))
    );
    let zenoh = parse(&format!(
        "{text}\n[robot.link]\nkind = \"ros2_control\"\nrmw = \"zenoh\"\nzenoh_router = \"tcp/10.0.0.2:7447\"\ncommand_topic = \"/c\"\n"
    ))
    .expect("a ros2_control link on rmw_zenoh");
    let namespaced = parse(&format!(
        "{text}\n[robot.link]\nkind = \"ros2_control\"\nnamespace = \"/lab/robot_1\"\ncommand_topic = \"c\"\n"
    ))
    .expect("a namespaced ros2_control link");
    assert_eq!(
        namespaced.file.robot.link.namespace.as_deref(),
        Some("/lab/robot_1")
    );
    assert_eq!(
        (
            zenoh.file.robot.link.rmw,
            zenoh.file.robot.link.zenoh_router.as_deref()
        ),
        (
            Some(avatarm_scene::spec::Ros2Rmw::Zenoh),
            Some("tcp/10.0.0.2:7447")
        )
    );
    for (link, field) in [
        ("kind = \"intera\"\nrmw = \"zenoh\"", "robot.link.rmw"),
        (
            "kind = \"ros2_control\"\nrmw = \"dds\"\nzenoh_router = \"tcp/h:7447\"",
            "robot.link.zenoh_router",
        ),
        (
            "kind = \"ros2_control\"\nzenoh_router = \"localhost:7447\"",
            "robot.link.zenoh_router",
        ),
        (
            "kind = \"ros2_control\"\nzenoh_router = \"tcp/localhost\"",
            "robot.link.zenoh_router",
        ),
        (
            "kind = \"ros2_control\"\nnamespace = \"robot1\"",
            "robot.link.namespace",
        ),
        (
            "kind = \"ros2_control\"\nnamespace = \"/robot1/\"",
            "robot.link.namespace",
        ),
        (
            "kind = \"ros2_control\"\nnamespace = \"/1robot\"",
            "robot.link.namespace",
        ),
        (
            "kind = \"intera\"\nnamespace = \"/robot1\"",
            "robot.link.namespace",
        ),
        (
            "kind = \"ros2_control\"\ndomain_id = 300",
            "robot.link.domain_id",
        ),
        ("kind = \"intera\"\ndomain_id = 3", "robot.link.domain_id"),
        (
            "kind = \"ros2_control\"\nmaster_uri = \"http://x:11311\"",
            "robot.link.master_uri",
        ),
    ] {
        let e = parse(&format!("{text}\n[robot.link]\n{link}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{e}");
    }
}

/// `../shared/cases/18-scene-nan-camera-pose`: a NaN in the camera pose (found by mutating the
/// default scene) used to pass validation and panic inside Bevy.
#[test]
fn a_nan_anywhere_in_a_scene_is_refused_at_load_naming_its_field() {
    let text = include_str!("fixtures/nan_camera_pose.toml");
    // As if copied to assets/scenes (its robot path is relative to that folder).
    let path = root().join("assets/scenes/nan_pose.toml");
    let e = Scene::parse(text, &path, &PackagePath::default()).expect_err("NaN pose");
    let message = e.to_string();
    assert!(
        matches!(&e, SceneError::Invalid { field, .. } if field == "camera.pose.eye[2]"),
        "{message}"
    );
    assert!(
        message.contains("nan_pose.toml") && message.contains("NaN is not a finite number"),
        "{message}"
    );
    // The same text with the NaN fixed loads (-0.0 is a valid latency).
    let fixed = text.replace("eye = [1.85, 0.0, nan]", "eye = [1.85, 0.0, 1.25]");
    Scene::parse(&fixed, &path, &PackagePath::default()).expect("fixed scene");

    // Every table: a non-finite number is refused wherever it is.
    let (path, text) = scene_text("default.toml");
    for (from, to, field) in [
        ("duration_s = 10.0", "duration_s = inf", "duration_s"),
        ("fx = 461.0", "fx = nan", "camera.intrinsics.fx"),
        (
            "base = { xyz = [0.0, 0.0, 0.75] }",
            "base = { xyz = [0.0, -inf, 0.75] }",
            "robot.base.xyz[1]",
        ),
        (
            "noise_sigma = 1.0",
            "noise_sigma = nan",
            "camera.sensor.noise_sigma",
        ),
    ] {
        assert!(text.contains(from), "the default scene has '{from}'");
        let e = Scene::parse(&text.replace(from, to), &path, &PackagePath::default())
            .expect_err(to)
            .to_string();
        assert!(
            e.contains(field) && e.contains("not a finite number"),
            "{to}: {e}"
        );
    }
}

/// Numbers that are finite but out of their range are refused too.
#[test]
fn out_of_range_numbers_are_refused_naming_their_field() {
    let (path, text) = scene_text("default.toml");
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());
    for (from, to, field) in [
        (
            "noise_sigma = 1.0",
            "noise_sigma = -2.0",
            "camera.sensor.noise_sigma",
        ),
        (
            "frame_latency_s = 0.05",
            "frame_latency_s = 50.0",
            "camera.frame_latency_s",
        ),
    ] {
        assert!(text.contains(from), "the default scene has '{from}'");
        let e = parse(&text.replace(from, to)).expect_err(to).to_string();
        assert!(e.contains(field), "{to}: {e}");
    }
    let with_prop = format!(
        "{text}\n[[props]]\nname = \"cup\"\nshape = \"sphere\"\nradius = 0.05\nrgba = [1.5, 0.0, 0.0, 1.0]\n"
    );
    let e = parse(&with_prop).expect_err("rgba > 1").to_string();
    assert!(e.contains("props[") && e.contains("rgba"), "{e}");
    let twice = format!(
        "{text}\n[[props]]\nname = \"cup\"\nshape = \"sphere\"\nradius = 0.05\n\n[[props]]\nname = \"cup\"\nshape = \"sphere\"\nradius = 0.05\n"
    );
    let e = parse(&twice).expect_err("two cups").to_string();
    assert!(e.contains("already named 'cup'"), "{e}");
}

/// The `[task]` is checked when the scene loads (it used to be checked only after a whole
/// replay), with errors naming the file and the `task.*` field.
#[test]
fn the_task_is_validated_at_load() {
    let (path, text) = scene_text("pouring.toml");
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());
    let scene = parse(&text).expect("the pouring scene loads");
    let setup = scene.trial.as_ref().expect("its task is resolved");
    assert_eq!(scene.model.links[setup.tcp].name, "right_gripper_tip");
    assert_eq!(setup.arm.len(), 7, "the arm joints, not the fingers");
    for (from, to, field) in [
        ("object = \"bottle\"", "object = \"glass?\"", "task.object"),
        (
            "trials = 10\n",
            "trials = 10\nmass_kg = -0.5\n",
            "task.mass_kg",
        ),
        (
            "tcp_link = \"right_gripper_tip\"",
            "tcp_link = \"nowhere\"",
            "task.tcp_link",
        ),
        (
            "trials = 10\n",
            "trials = 10\narm_joints = [\"right_j9\"]\n",
            "task.arm_joints",
        ),
        (
            "trials = 10\n",
            "trials = 10\nhand_filter = { min_cutoff_hz = 0.0 }\n",
            "task.hand_filter",
        ),
        ("gain = 12.0", "gain = -1.0", "task.gain"),
    ] {
        assert_eq!(text.matches(from).count(), 1, "'{from}' once in the task");
        let e = parse(&text.replace(from, to)).expect_err(to);
        let message = e.to_string();
        assert!(
            e.field_name() == Some(field) && !matches!(e, SceneError::Field { .. }),
            "{to}: {message}"
        );
        assert!(message.contains("pouring.toml"), "{message}");
    }
}

/// `[twin]` and a description named by `package://`: a bad fraction, a missing package, a mimic
/// joint given a value, and the real Sawyer's scene, each as the user would meet it.
#[test]
fn the_twin_and_package_descriptions_are_checked() {
    let path = root().join("assets/scenes/default.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());
    let e = parse(&format!("{text}\n[twin]\nkeep_triangles = 0.0\n"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("twin.keep_triangles") && e.contains("(0, 1]"),
        "{e}"
    );
    let e = parse(&format!("{text}\n[twin]\nurdf = \"nowhere.urdf\"\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("twin.urdf") && e.contains("nowhere.urdf"), "{e}");
    let twin = parse(&format!(
        "{text}\n[twin]\nurdf = \"../robots/sawyer_lite/sawyer_lite.urdf\"\ngeometry = \"collision\"\n"
    ))
    .unwrap();
    assert!(!std::sync::Arc::ptr_eq(&twin.model, &twin.twin_model));
    // A twin that is another robot: its joints cannot follow this robot's states.
    let e = parse(&format!(
        "{text}\n[twin]\nurdf = \"../../plugins/core/tests/fixtures/cases/09-mimic-joint/robot.urdf\"\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("twin.urdf") && e.contains("j_leader") && e.contains("same robot"),
        "{e}"
    );
    let plain = parse(&text).unwrap();
    assert!(std::sync::Arc::ptr_eq(&plain.model, &plain.twin_model));

    let e = parse(&text.replace(
        "urdf = \"../robots/sawyer_lite/sawyer_lite.urdf\"",
        "urdf = \"package://no_such_description/urdf/arm.urdf\"",
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("robot.urdf") && e.contains("'no_such_description'"),
        "{e}"
    );

    let (real, text) = scene_text("sawyer_real.toml");
    match avatarm_core::shared_data::ros_packages() {
        Err(why) => why.skip("the_twin_and_package_descriptions_are_checked"),
        Ok(_) => {
            let scene = Scene::parse(&text, &real, &PackagePath::default()).unwrap();
            assert_eq!(scene.model.name, "sawyer");
            let e = Scene::parse(
                &text.replace(
                    "right_gripper_l_finger_joint = 0.02,",
                    "right_gripper_l_finger_joint = 0.02, right_gripper_r_finger_joint = 0.02,",
                ),
                &real,
                &PackagePath::default(),
            )
            .unwrap_err()
            .to_string();
            assert!(
                e.contains("robot.q0")
                    && e.contains("'right_gripper_r_finger_joint' is a mimic joint"),
                "{e}"
            );
        }
    }
}

/// A camera on a head (`[camera.head]`): the head scene loads with its camera at the head's
/// pose times the mount, and every inconsistent head is refused naming its field.
#[test]
fn a_camera_on_a_head_is_resolved_and_checked() {
    let (path, text) = scene_text("head_camera.toml");
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());
    let scene = parse(&text).expect("the head scene loads");
    let head = scene.head.as_ref().expect("a head");
    for t in [0.0, 0.7, 2.3] {
        let camera = head.camera_at(t);
        let expected = head.motion.pose_at(t) * head.mount;
        assert!((camera.translation.vector - expected.translation.vector).norm() < 1e-12);
    }
    assert_eq!(scene.true_camera.world_from_camera, head.camera_at(0.0));
    assert_eq!(scene.believed_camera.world_from_camera, head.camera_at(0.0));
    let peak = head
        .motion
        .peak_angular_speed(scene.file.duration_s)
        .to_degrees();
    assert!((peak - 30.0).abs() < 0.3, "peak {peak}");
    assert!((head.tracking.latency_s - 0.02).abs() < 1e-12);
    assert!(scene.file.erase.pose_compensation);
    // The camera 8 cm ahead of the eye: it looks at the desk from the head's side.
    let eye = nalgebra::Vector3::new(0.75, -1.15, 1.2);
    let d = (scene.true_camera.world_from_camera.translation.vector - eye).norm();
    assert!(
        (d - (0.08f64.powi(2) + 0.03f64.powi(2)).sqrt()).abs() < 1e-9,
        "{d}"
    );

    // A mount error is the believed camera's only error.
    let with_error = text.replace(
        "sensor = { noise_sigma = 1.0 }",
        "sensor = { noise_sigma = 1.0 }\ncalibration_error = { rotation_deg = 1.0, axis = [0.0, 1.0, 0.0] }",
    );
    let s = parse(&with_error).expect("mount error");
    let h = s.head.as_ref().expect("head");
    let angle = h
        .mount
        .rotation
        .angle_to(&h.believed_mount.rotation)
        .to_degrees();
    assert!((angle - 1.0).abs() < 1e-9);

    let fails = |t: String, field: &str| {
        let e = parse(&t).expect_err(field).to_string();
        assert!(e.contains(field), "expected {field} in: {e}");
    };
    fails(
        text.replace(
            "fps = 30.0",
            "fps = 30.0\npose = { eye = [1.0, 0.0, 1.0], target = [0.0, 0.0, 1.0] }",
        ),
        "camera.pose",
    );
    let without_head = {
        let start = text.find("[camera.head]").unwrap();
        let end = text.find("\n[erase]").unwrap() + 1;
        format!("{}{}", &text[..start], &text[end..])
    };
    fails(without_head, "camera.pose");
    fails(
        text.replace("[camera.head]", "[camera.head]\nkeyframes = [{ t_s = 0.0, eye = [1.0, 0.0, 1.0], target = [0.0, 0.0, 1.0] }]"),
        "camera.head.sweep",
    );
    fails(
        text.replace("latency_s = 0.02, position", "latency_s = -0.02, position"),
        "camera.head.tracking",
    );
    fails(
        text.replace("peak_speed_deg_s = 30.0", "peak_speed_deg_s = 900.0"),
        "camera.head.sweep.peak_speed_deg_s",
    );
    fails(
        text.replace("amplitude_deg = 15.0", "amplitude_deg = 0.0"),
        "camera.head.sweep.amplitude_deg",
    );
    fails(
        text.replace("target = [0.3, 0.0, 0.95]", "target = [0.75, -1.15, 1.2]"),
        "camera.head.sweep",
    );
    fails(
        text.replace("rate_hz = 90.0", "rate_hz = nan"),
        "camera.head.tracking.rate_hz",
    );
    // The background's threads: one per core unless set, at most 256.
    assert_eq!(head.background_threads, 0);
    let threads = |n: u32| {
        text.replace(
            "\n[erase]",
            &format!("\n[camera.head.background]\nthreads = {n}\n\n[erase]"),
        )
    };
    let s = parse(&threads(3)).expect("3 threads");
    assert_eq!(s.head.as_ref().expect("head").background_threads, 3);
    fails(threads(257), "camera.head.background.threads");
    // Keyframes instead of a sweep: strictly increasing times.
    let keyed = text.replace(
        "sweep = { eye = [0.75, -1.15, 1.2], target = [0.3, 0.0, 0.95], amplitude_deg = 15.0, peak_speed_deg_s = 30.0, pivot_back_m = 0.09 }",
        "keyframes = [{ t_s = 0.0, eye = [0.75, -1.15, 1.2], target = [0.3, 0.0, 0.95] }, { t_s = 2.0, eye = [0.5, -0.9, 1.1], target = [0.3, 0.0, 0.95] }]",
    );
    let s = parse(&keyed).expect("keyframes");
    let h = s.head.as_ref().expect("head");
    assert!(
        (h.motion.pose_at(2.0).translation.vector - nalgebra::Vector3::new(0.5, -0.9, 1.1)).norm()
            < 1e-12
    );
    fails(
        keyed.replace("t_s = 2.0", "t_s = 0.0"),
        "camera.head.keyframes[1].t_s",
    );
}

/// `[[cameras]]`: a scene with Blair's fixed camera and Alice's head camera loads through
/// either, each camera with its own settings, and every camera is checked whichever is chosen.
#[test]
fn several_cameras_load_by_name_and_each_is_checked() {
    let (path, text) = scene_text("pouring_two_views.toml");
    let view = |t: &str, v: Option<&str>| Scene::parse_view(t, &path, &PackagePath::default(), v);

    let blair = view(&text, None).expect("the first camera");
    assert_eq!(blair.cameras, ["blair", "alice"]);
    assert_eq!((blair.camera_index, blair.camera_name()), (0, "blair"));
    assert!(blair.head.is_none(), "Blair's camera is fixed");
    let alice = view(&text, Some("alice")).expect("Alice's camera");
    assert_eq!((alice.camera_index, alice.camera_name()), (1, "alice"));
    let head = alice
        .head
        .as_ref()
        .expect("Alice's camera rides on her head");
    assert_eq!(alice.true_camera.world_from_camera, head.camera_at(0.0));
    assert_ne!(
        alice.true_camera.world_from_camera,
        blair.true_camera.world_from_camera
    );
    // The rest of the scene is the same through either camera.
    assert_eq!(alice.props.len(), blair.props.len());
    assert_eq!(alice.q0, blair.q0);
    assert_eq!(alice.file.seed, blair.file.seed);

    let e = view(&text, Some("carol")).unwrap_err().to_string();
    assert!(e.contains("carol") && e.contains("blair, alice"), "{e}");

    // A camera's own erase keys go over the scene's [erase], for it alone.
    let own = text.replace(
        "name = \"blair\"",
        "name = \"blair\"\nerase = { latency_compensation = false }",
    );
    assert!(!view(&own, None).unwrap().file.erase.latency_compensation);
    assert!(
        view(&own, Some("alice"))
            .unwrap()
            .file
            .erase
            .latency_compensation
    );

    // A bad value in the scene's own [erase] is the scene's, not a camera's.
    let shared = text.replace(
        "latency_compensation = true",
        "latency_compensation = true\nranges = [[240, 255], [250, 240], [240, 255], [240, 255]]",
    );
    assert_ne!(shared, text);
    let e = view(&shared, None).unwrap_err().to_string();
    assert!(
        e.contains("erase") && e.contains("G range") && !e.contains("cameras["),
        "{e}"
    );

    // A bad value in the camera not chosen is still refused, naming that camera.
    let bad = text.replace(
        "name = \"alice\"\nintrinsics = { fx = 461.0",
        "name = \"alice\"\nintrinsics = { fx = -461.0",
    );
    assert_ne!(bad, text);
    let e = view(&bad, None).unwrap_err().to_string();
    assert!(e.contains("cameras[1] (alice).intrinsics"), "{e}");
    let typo = text.replace("name = \"alice\"", "name = \"alice\"\nfsp = 30");
    let e = view(&typo, None).unwrap_err().to_string();
    assert!(e.contains("cameras[1] (alice)") && e.contains("fsp"), "{e}");

    for (change, expected) in [
        (
            text.replacen("name = \"alice\"", "name = \"blair\"", 1),
            "already named 'blair'",
        ),
        (text.replacen("name = \"alice\"", "", 1), "cameras[1].name"),
        (
            text.replacen("name = \"alice\"", "name = \"al ice\"", 1),
            "letters, digits",
        ),
        (format!("{text}\n[camera]\nfps = 30.0\n"), "not both"),
    ] {
        let e = view(&change, None).unwrap_err().to_string();
        assert!(e.contains(expected), "{expected}: {e}");
    }

    // A scene with one [camera] has one camera, named "camera".
    let (path1, one) = scene_text("pouring.toml");
    let single = Scene::parse_view(&one, &path1, &PackagePath::default(), Some("camera"))
        .expect("the one camera by its name");
    assert_eq!(single.cameras, ["camera"]);
    let e = Scene::parse_view(&one, &path1, &PackagePath::default(), Some("alice"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("one camera"), "{e}");
}

#[test]
fn the_chess_scene_puts_its_board_and_pieces_among_the_props_and_checks_its_moves() {
    let (path, text) = scene_text("chess.toml");
    let parse = |t: &str| Scene::parse(t, &path, &PackagePath::default());
    let scene = parse(&text).expect("chess.toml loads");
    let chess = scene.chess.as_ref().expect("[chess] resolved");
    assert_eq!(chess.pieces.len(), 32);
    assert_eq!(chess.moves.len(), 5);
    // The room's three props, the board, its 32 light squares and the 32 pieces; the pieces
    // are objects (each gets its twin), the board is not.
    assert_eq!(scene.props.len(), 3 + 1 + 32 + 32);
    assert_eq!(scene.file.props.len(), scene.props.len());
    let objects: Vec<_> = scene.file.props.iter().filter(|p| p.object).collect();
    assert_eq!(objects.len(), 32);
    // White's king on e1, nearest the camera (the files run along +y, rank 1 at x = 0.795).
    let king = scene
        .props
        .iter()
        .find(|p| p.name == "white_king_e1")
        .unwrap();
    let at = king.pose.translation.vector;
    assert!(
        (at.x - 0.795).abs() < 1e-3 && (at.y - 0.025).abs() < 1e-3,
        "{at:?}"
    );
    let e = parse(&text.replace("\"g1f3\"", "\"g1g2\""))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("chess.moves[2]") && e.contains("white_pawn_g2 stands on g2"),
        "{e}"
    );
    let e = parse(&text.replace("k = 2.0", "k = 0.0"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("chess.k"), "{e}");
    let e = parse(&text.replace("trials = 4", "trials = 4\nbeta = 1"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("beta"), "{e}");
    let e = parse(&text.replace(
        "seed = 1\n# Blair",
        "seed = 1\nintent = { window_s = -1.0 }\n# Blair",
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("intent.window_s"), "{e}");
    let e = parse(&text.replace(
        "[[props]]\nname = \"wall\"",
        "[[props]]\nname = \"white_king_e1\"",
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("white_king_e1"), "{e}");
}
