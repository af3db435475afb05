//! Top-level tests: scripted scene replays rendered for real (software Vulkan is enough), the
//! command line, and scene validation. One test binary, so Bevy is linked once.

use std::path::{Path, PathBuf};
use std::process::Command;

use avatarm::replay::{self, ReplayOptions};
use avatarm::scene::{Scene, SceneError};
use avatarm_core::robot::{PackagePath, Shape};
use nalgebra::{Isometry3, Point3};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn default_scene() -> Scene {
    Scene::load(
        &root().join("assets/scenes/default.toml"),
        &PackagePath::default(),
    )
    .expect("the default scene loads")
}

fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn load_rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Renders the default scene and checks that the robot appears in the camera frame exactly where
/// forward kinematics and the pinhole model put it; also that the same seed gives the same frames.
#[test]
fn replay_shows_the_robot_where_fk_and_the_camera_model_project_it() {
    let mut scene = default_scene();
    // Past the first keyframe (0.5 s), so the arm is moving in the last saved frame.
    scene.file.duration_s = 2.1;
    let out = out_dir("replay_default");
    let mut options = ReplayOptions::new(out.clone());
    options.frames_every = 30;
    let report = replay::run(&scene, options).expect("replay runs");

    // The report has what it promises.
    assert_eq!(report["scene"], "default");
    assert_eq!(report["seed"], 7);
    assert_eq!(report["frames"], 63);
    assert_eq!(report["frames_written"], 3);
    let sim = report["sim_time_s"].as_f64().unwrap();
    assert!((sim - 2.1).abs() < 0.05, "sim time {sim}");
    assert!(report["wall_time_s"].as_f64().unwrap() > 0.0);
    let on_disk: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(on_disk["frames"], report["frames"]);
    let frames: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("frames.json")).unwrap()).unwrap();
    let last = &frames[2];
    assert_eq!(last["index"], 60);
    // The twin follows the robot through delayed joint states.
    let t = last["t_s"].as_f64().unwrap();
    let stamp = last["twin_stamp_s"].as_f64().unwrap();
    assert!(
        stamp < t && t - stamp < 0.05,
        "joint state at {stamp} for a frame at {t}"
    );

    let frame = load_rgb(&out.join("frame_00060.png"));
    let no_robot = load_rgb(&out.join("gt_norobot_00060.png"));
    let silhouette = image::open(out.join("gt_silhouette_00060.png"))
        .unwrap()
        .to_luma8();
    assert_eq!(frame.dimensions(), (640, 480));
    let robot_px = |x: u32, y: u32| silhouette.get_pixel(x, y).0[0] > 127;

    // 1. The camera frame differs from the robot-free frame exactly on the silhouette.
    let (mut inter, mut union, mut area) = (0u32, 0u32, 0u32);
    for (x, y, p) in frame.enumerate_pixels() {
        let q = no_robot.get_pixel(x, y);
        let diff: i32 = (0..3)
            .map(|c| (i32::from(p.0[c]) - i32::from(q.0[c])).abs())
            .sum();
        let changed = diff > 24;
        let sil = robot_px(x, y);
        area += u32::from(sil);
        inter += u32::from(changed && sil);
        union += u32::from(changed || sil);
    }
    assert!(
        area > 640 * 480 / 100,
        "the robot covers only {area} pixels"
    );
    let iou = f64::from(inter) / f64::from(union);
    assert!(
        iou > 0.9,
        "frame-vs-background change and silhouette disagree: IoU {iou:.3}"
    );

    // 2. Points inside the robot's links, by FK at the true joint positions and the camera
    //    model, land on robot pixels.
    let q: Vec<f64> = last["q_true"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let poses = scene.model.forward_kinematics(&scene.robot_base(), &q);
    let mut checked = 0;
    for (link, pose) in scene.model.links.iter().zip(&poses) {
        for g in &link.visuals {
            if !matches!(g.shape, Shape::Cylinder { .. } | Shape::Box { .. }) {
                continue;
            }
            let centre = pose * g.origin * Point3::origin();
            let (u, v, _) = scene
                .true_camera
                .project(&centre)
                .expect("in front of the camera");
            assert!(
                scene.true_camera.in_image(u, v),
                "{} off-image at ({u:.1}, {v:.1})",
                link.name
            );
            let (x, y) = (u.round() as i64, v.round() as i64);
            let near = (-2..=2).any(|dx| {
                (-2..=2).any(|dy| {
                    robot_px((x + dx).clamp(0, 639) as u32, (y + dy).clamp(0, 479) as u32)
                })
            });
            assert!(
                near,
                "link '{}' projects to ({u:.1}, {v:.1}), not on the robot",
                link.name
            );
            checked += 1;
        }
    }
    assert!(checked >= 10, "only {checked} link shapes checked");

    // 3. A point on the book is not robot, and there the frame shows the room.
    let book = scene.props.iter().find(|p| p.name == "book").unwrap();
    let (u, v, _) = scene
        .true_camera
        .project(&(book.pose * Point3::new(0.0, 0.0, 0.04)))
        .unwrap();
    assert!(!robot_px(u as u32, v as u32));

    // 4. Same seed, same frames (noise included).
    let out2 = out_dir("replay_default_again");
    let mut options = ReplayOptions::new(out2.clone());
    options.frames_every = 10;
    replay::run(&scene, options).expect("second replay runs");
    for name in ["frame_00060.png", "gt_silhouette_00060.png"] {
        assert_eq!(
            std::fs::read(out.join(name)).unwrap(),
            std::fs::read(out2.join(name)).unwrap(),
            "{name} differs between two replays with the same seed"
        );
    }
    // The robot moved between the first and last saved frame (the trajectory ran).
    let q0: Vec<f64> = frames[0]["q_true"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let moved: f64 = q0.iter().zip(&q).map(|(a, b)| (a - b).abs()).sum();
    assert!(moved > 0.01, "the robot did not move: {moved}");
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
}

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
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let model =
        avatarm_core::robot::RobotModel::from_urdf_file(&urdf, &PackagePath::default()).unwrap();
    let q = [0.1, -0.5, 0.2, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let poses = model.forward_kinematics(&Isometry3::identity(), &q);
    let tip = &json["links"]["right_gripper_tip"];
    let t = poses[model.link_id("right_gripper_tip").unwrap()];
    for (i, v) in t.translation.vector.iter().enumerate() {
        assert!((tip["translation"][i].as_f64().unwrap() - v).abs() < 1e-12);
    }
    let w = tip["rotation_xyzw"][3].as_f64().unwrap();
    assert!((w.abs() - t.rotation.w.abs()).abs() < 1e-12);
    assert_eq!(json["links"].as_object().unwrap().len(), model.links.len());

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

#[test]
fn replay_of_a_bad_scene_exits_nonzero_with_a_message() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let bad = dir.join("bad_scene.toml");
    std::fs::write(&bad, "name = 'x'\nduration_s = 1\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["replay", bad.to_str().unwrap(), "--headless", "--out"])
        .arg(dir.join("bad_out"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad_scene.toml") && err.contains("robot"),
        "{err}"
    );
}
