//! `avatarm import FOLDER`: the frames a lab has into a recording, read back by Avatarm's
//! reader and by PyPI's `mcap` reader (`scripts/setup.sh` installs it): EasyHeC's layout on the
//! real Panda frames, CSV and JSON listings, every camera-file kind, and the errors.

use std::path::{Path, PathBuf};
use std::process::Command;

use avatarm_record::{ImageFormat, Recording};
use nalgebra::{Isometry3, Matrix4, Rotation3, Translation3, UnitQuaternion};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn out_dir(name: &str) -> PathBuf {
    let d = root().join("target/test-out/footage").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("out dir");
    d
}

/// Runs `avatarm import ARGS`; (success, stdout + stderr).
fn import(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg("import")
        .args(args)
        .current_dir(root())
        .output()
        .expect("avatarm runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// Reads the file with PyPI's `mcap` reader; returns one line per channel:
/// `topic schema_name encoding count first_json_keys`.
fn python_read(path: &Path) -> String {
    let script = r#"
import json, sys
from collections import Counter, OrderedDict
from mcap.reader import make_reader
counts, keys, schemas = Counter(), OrderedDict(), {}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        counts[channel.topic] += 1
        schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
        keys.setdefault(channel.topic, sorted(json.loads(message.data)))
for topic in sorted(counts):
    name, enc, menc = schemas[topic]
    print(topic, name, enc, menc, counts[topic], ",".join(keys[topic]))
"#;
    let python_path = std::env::var("HOME")
        .map(|h| format!("{h}/.cache/avatarm/python"))
        .unwrap_or_default();
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(path)
        .env("PYTHONPATH", python_path)
        .output()
        .expect("python3");
    assert!(
        out.status.success(),
        "PyPI's mcap reader (scripts/setup.sh installs it): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn png(path: &Path, width: u32, height: u32, shade: u8) {
    image::RgbImage::from_pixel(width, height, image::Rgb([shade, 128, 255 - shade]))
        .save(path)
        .expect("png");
}

#[test]
fn the_real_panda_frames_import_from_easyhec_s_layout_and_read_back_in_both_readers() {
    let data = match avatarm_core::shared_data::shared_data() {
        Ok(d) => d,
        Err(why) => return eprintln!("skipped: {why}"),
    };
    let folder = data.join("real/franka_easyhec");
    let out = out_dir("easyhec");
    // The rough pose the data's README gives, camera_from_base (OpenCV axes, m).
    let rows = [
        [0.93969262, 0.34202009, 0.0, -0.64085639],
        [0.17101002, -0.46984622, -0.86602539, 0.49582830],
        [-0.29619810, 0.81379771, -0.49999991, 1.24120010],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let pose = out.join("pose.yaml");
    std::fs::write(
        &pose,
        format!(
            "camera_from_base:\n{}",
            rows.iter()
                .map(|r| format!("  - [{}, {}, {}, {}]\n", r[0], r[1], r[2], r[3]))
                .collect::<String>()
        ),
    )
    .expect("pose");
    let file = out.join("panda.mcap");
    let names = "panda_joint1,panda_joint2,panda_joint3,panda_joint4,panda_joint5,panda_joint6,panda_joint7,panda_finger_joint1,panda_finger_joint2";
    let (ok, log) = import(&[
        folder.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
        "--pose",
        pose.to_str().expect("utf-8"),
        "--joint-names",
        names,
    ]);
    assert!(ok, "{log}");
    eprintln!("{log}");
    assert!(log.contains("(EasyHeC): 10 frames 640x480"), "{log}");
    assert!(log.contains("10 reference masks"), "{log}");

    let r = Recording::open(&file).expect("read back");
    assert_eq!(r.frames.len(), 10);
    assert_eq!(r.reference_masks.len(), 10);
    assert!(r.frames.iter().all(|f| f.format == ImageFormat::Png));
    // The frames are the files, byte for byte.
    let first = std::fs::read(folder.join("color/000000.png")).expect("frame 0");
    assert_eq!(r.frames[0].data, first);
    let c = r.calibration.as_ref().expect("calibration");
    let k_txt: Vec<f64> = std::fs::read_to_string(folder.join("K.txt"))
        .expect("K.txt")
        .split_whitespace()
        .map(|t| t.parse().expect("number"))
        .collect();
    assert_eq!(c.k.to_vec(), k_txt);
    assert_eq!((c.width, c.height), (640, 480));
    assert!(c.is_pinhole());
    // The pose read back is the inverse of camera_from_base.
    let m = Matrix4::from_fn(|i, j| rows[i][j]);
    let r3 = Rotation3::from_matrix(&m.fixed_view::<3, 3>(0, 0).into());
    let camera_from_base = Isometry3::from_parts(
        Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_rotation_matrix(&r3),
    );
    let d = r.base_from_camera.expect("pose") * camera_from_base;
    assert!(
        d.translation.vector.norm() < 1e-6 && d.rotation.angle() < 1e-6,
        "{d:?}"
    );
    // Joints: qpos/000003.txt, by name, frames 1/30 s apart.
    let q3: Vec<f64> = std::fs::read_to_string(folder.join("qpos/000003.txt"))
        .expect("qpos")
        .split_whitespace()
        .map(|t| t.parse().expect("number"))
        .collect();
    assert_eq!(r.joint_states.len(), 10);
    assert_eq!(r.joint_states[3].positions, q3);
    assert_eq!(r.joint_states[3].names[6], "panda_joint7");
    assert_eq!(r.joint_states[3].stamp_ns, 100_000_000);
    assert_eq!(r.frames[3].stamp_ns, 100_000_000);

    // The same file through PyPI's reader: Foxglove's schema names, JSON, every message.
    let py = python_read(&file);
    eprintln!("{py}");
    for line in [
        "/camera/calibration foxglove.CameraCalibration jsonschema json 1 D,K,P,R,distortion_model,frame_id,height,timestamp,width",
        "/camera/image/compressed foxglove.CompressedImage jsonschema json 10 data,format,frame_id,timestamp",
        "/camera/reference_mask/compressed foxglove.CompressedImage jsonschema json 10 data,format,frame_id,timestamp",
        "/joint_states avatarm.JointState jsonschema json 10 name,position,timestamp,velocity",
        "/tf foxglove.FrameTransform jsonschema json 1 child_frame_id,parent_frame_id,rotation,timestamp,translation",
    ] {
        assert!(py.lines().any(|l| l == line), "{line}\nnot in\n{py}");
    }
}

/// Imports the real Panda frames with the data README's rough pose into `out/panda.mcap`.
fn import_panda(data: &Path, out: &Path) -> PathBuf {
    let pose = out.join("pose.yaml");
    std::fs::write(
        &pose,
        "camera_from_base:\n  - [0.93969262, 0.34202009, 0.0, -0.64085639]\n  - [0.17101002, -0.46984622, -0.86602539, 0.49582830]\n  - [-0.29619810, 0.81379771, -0.49999991, 1.24120010]\n  - [0, 0, 0, 1]\n",
    )
    .expect("pose");
    let file = out.join("panda.mcap");
    let (ok, log) = import(&[
        data.join("real/franka_easyhec").to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
        "--pose",
        pose.to_str().expect("utf-8"),
        "--joint-names",
        "panda_joint1,panda_joint2,panda_joint3,panda_joint4,panda_joint5,panda_joint6,panda_joint7,panda_finger_joint1,panda_finger_joint2",
    ]);
    assert!(ok, "{log}");
    file
}

/// Runs `avatarm replay ARGS`; (success, stdout + stderr).
fn replay(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg("replay")
        .args(args)
        .current_dir(root())
        .output()
        .expect("avatarm runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// The real Panda's frames through the erase: every frame masked at its recorded joints,
/// erased with a background built from the footage, scored against the reference masks, the
/// GPU equal to the CPU reference, and everything written (PNGs, an MCAP both readers read).
/// With the data's rough pose (20-60 px off) the mask lands beside the robot: the IoU measures
/// the pose, which `avatarm calibrate` is for.
#[test]
fn the_real_panda_recording_replays_through_the_erase() {
    let data = match avatarm_core::shared_data::shared_data() {
        Ok(d) => d,
        Err(why) => return eprintln!("skipped: {why}"),
    };
    let out = out_dir("panda_replay");
    let file = import_panda(&data, &out);
    let urdf = data.join("ros/example-robot-data/robots/panda_description/urdf/panda.urdf");
    let result = out.join("replay");
    let (ok, log) = replay(&[
        "--recording",
        file.to_str().expect("utf-8"),
        "--urdf",
        urdf.to_str().expect("utf-8"),
        "--package-path",
        data.join("ros").to_str().expect("utf-8"),
        "--photometric",
        "on",
        "--out",
        result.to_str().expect("utf-8"),
    ]);
    assert!(ok, "{log}");
    eprintln!("{}", log.lines().last().unwrap_or_default());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(result.join("report.json")).expect("report"))
            .expect("json");
    assert_eq!(report["frames"], 10);
    assert_eq!(report["robot"], "panda");
    let vs = &report["mask"]["vs_reference"];
    assert_eq!(vs["frames_scored"], 10, "{vs}");
    // Measured with the rough pose: IoU 0.18-0.30 per frame. The mask is the robot's, near
    // it: some overlap, not none and not all.
    let iou = vs["iou_mean"].as_f64().expect("iou");
    assert!(iou > 0.1 && iou < 0.9, "{vs}");
    let coverage = report["mask"]["coverage_pct_mean"]
        .as_f64()
        .expect("coverage");
    assert!(coverage > 2.0 && coverage < 40.0, "{report}");
    // The GPU erased exactly what the CPU reference erases on the same inputs.
    assert!(
        report["gpu_vs_cpu"]["max_abs_diff"].as_u64() <= Some(1),
        "{report}"
    );
    assert_eq!(report["gpu_vs_cpu"]["mask_mismatch_px_max"], 0);
    let bg = &report["background"];
    assert_eq!(bg["source"], "the footage");
    let seen = bg["robot_region_seen_pct"].as_f64().expect("seen");
    assert!((0.0..=100.0).contains(&seen), "{bg}");
    for name in [
        "erased_00000.png",
        "mask_00009.png",
        "background.png",
        "background_seen.png",
    ] {
        assert!(result.join(name).is_file(), "{name}");
    }
    // The output recording: the original streams and Avatarm's beside them.
    let mcap = result.join("erased.mcap");
    let r = Recording::open(&mcap).expect("read back");
    assert_eq!(
        (
            r.frames.len(),
            r.erased.len(),
            r.masks.len(),
            r.reference_masks.len()
        ),
        (10, 10, 10, 10)
    );
    assert_eq!(r.joint_states.len(), 10);
    assert!(r.calibration.is_some() && r.base_from_camera.is_some());
    let py = python_read(&mcap);
    for topic in ["/avatarm/erased/compressed", "/avatarm/mask/compressed"] {
        assert!(
            py.lines().any(|l| l.starts_with(&format!(
                "{topic} foxglove.CompressedImage jsonschema json 10 "
            ))),
            "{topic} not in\n{py}"
        );
    }
    // Another robot's description is refused naming the joint it lacks.
    let sawyer = data.join("ros/sawyer_description/urdf/sawyer_electric_gripper.urdf");
    let (ok, log) = replay(&[
        "--recording",
        file.to_str().expect("utf-8"),
        "--urdf",
        sawyer.to_str().expect("utf-8"),
        "--package-path",
        data.join("ros").to_str().expect("utf-8"),
        "--out",
        out.join("wrong").to_str().expect("utf-8"),
    ]);
    assert!(!ok);
    assert!(
        log.contains("joint 'panda_joint1' is not in the description"),
        "{log}"
    );
    // A scene and a recording at once are refused.
    let (ok, log) = replay(&[
        "assets/scenes/default.toml",
        "--recording",
        "x.mcap",
        "--out",
        "o",
    ]);
    assert!(
        !ok && (log.contains("--recording") || log.contains("--urdf")),
        "{log}"
    );
}

#[test]
fn csv_and_json_listings_import_with_ros_and_opencv_camera_files() {
    let dir = out_dir("listings");
    for i in 0..3 {
        png(&dir.join(format!("f{i}.png")), 64, 48, i * 60);
    }
    png(&dir.join("m1.png"), 64, 48, 255);
    std::fs::write(
        dir.join("frames.csv"),
        "file,stamp_s,mask,j1,j2\nf1.png,1700000000.5,m1.png,0.1,0.2\nf0.png,1700000000.0,,0.0,0.1\nf2.png,1700000001.0,,0.2,-0.3\n",
    )
    .expect("csv");
    std::fs::write(
        dir.join("camera_info.yaml"),
        "image_width: 64\nimage_height: 48\ncamera_name: desk\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [60, 0, 32, 0, 60, 24, 0, 0, 1]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.05, -0.01, 0, 0, 0]\n",
    )
    .expect("camera");
    std::fs::write(
        dir.join("pose.json"),
        r#"{"base_from_camera": {"translation": [1.5, 0, 0.8], "quaternion_xyzw": [0, 0, 0, 1]}}"#,
    )
    .expect("pose");
    let file = dir.join("csv.mcap");
    let (ok, log) = import(&[
        dir.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
    ]);
    assert!(ok, "{log}");
    assert!(log.contains("(listing CSV): 3 frames 64x48 over 1.00 s, 1 reference masks, joints j1, j2, camera pose given"), "{log}");
    let r = Recording::open(&file).expect("csv read back");
    let stamps: Vec<u64> = r.joint_states.iter().map(|s| s.stamp_ns).collect();
    assert_eq!(
        stamps,
        [
            1_700_000_000_000_000_000,
            1_700_000_000_500_000_000,
            1_700_000_001_000_000_000
        ]
    );
    assert_eq!(r.joint_states[1].positions, [0.1, 0.2]);
    assert_eq!(r.reference_masks[0].stamp_ns, stamps[1]);
    assert_eq!(r.calibration.as_ref().map(|c| c.d[0]), Some(0.05));
    assert_eq!(
        r.base_from_camera.map(|p| p.translation.vector.x),
        Some(1.5)
    );

    // JSON with q lists, an OpenCV camera file and no pose.
    std::fs::write(
        dir.join("frames.json"),
        r#"{"joint_names": ["j1", "j2"], "frames": [{"file": "f0.png", "stamp_s": 0.0, "q": [0.0, 0.1]}, {"file": "f1.png", "stamp_s": 0.04, "q": [0.3, 0.4]}]}"#,
    )
    .expect("json");
    let cv = dir.join("cv.yaml");
    std::fs::write(
        &cv,
        "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 60., 0., 32., 0., 60., 24., 0., 0., 1. ]\ndist_coeffs: !!opencv-matrix\n   rows: 1\n   cols: 8\n   dt: d\n   data: [ 0., 0., 0., 0., 0., 0., 0., 0. ]\n",
    )
    .expect("opencv");
    let file = dir.join("json.mcap");
    let listing = dir.join("frames.json");
    let none = dir.join("no_pose.yaml");
    std::fs::write(
        &none,
        "base_from_camera: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n",
    )
    .expect("pose");
    let (ok, log) = import(&[
        dir.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
        "--listing",
        listing.to_str().expect("utf-8"),
        "--camera",
        cv.to_str().expect("utf-8"),
        "--pose",
        none.to_str().expect("utf-8"),
    ]);
    assert!(ok, "{log}");
    let r = Recording::open(&file).expect("json read back");
    assert_eq!(r.joint_states[1].positions, [0.3, 0.4]);
    assert_eq!(r.joint_states[1].stamp_ns, 40_000_000);
    assert_eq!(
        r.calibration.map(|c| c.distortion_model),
        Some(avatarm_record::DistortionModel::RationalPolynomial)
    );
}

#[test]
fn bad_folders_are_refused_naming_the_entry() {
    let dir = out_dir("bad");
    png(&dir.join("f0.png"), 32, 24, 0);
    png(&dir.join("f1.png"), 30, 24, 0);
    std::fs::write(dir.join("K.txt"), "30 0 16\n0 30 12\n0 0 1\n").expect("K");
    let file = dir.join("bad.mcap");
    let file = file.to_str().expect("utf-8");
    let folder = dir.to_str().expect("utf-8");
    let case = |csv: &str, want: &str, extra: &[&str]| {
        std::fs::write(dir.join("frames.csv"), csv).expect("csv");
        let mut args = vec![folder, "--out", file];
        args.extend_from_slice(extra);
        let (ok, log) = import(&args);
        assert!(!ok, "{csv}: accepted\n{log}");
        assert!(log.contains(want), "{csv}: wanted '{want}' in\n{log}");
    };
    case(
        "file,stamp_s,j1\nf0.png,0,0.1\nf0.png,0.1,nan\n",
        "frames.csv, line 3: joint 'j1': NaN is not finite",
        &[],
    );
    case(
        "file,stamp_s,j1\nf0.png,0,0.1\nf0.png,0,0.2\n",
        "line 3: stamp_s 0 repeats",
        &[],
    );
    case(
        "file,stamp_s,j1\nf0.png,0,0.1\nmissing.png,0.1,0.2\n",
        "missing.png",
        &[],
    );
    case(
        "file,stamp_s,j1\nf0.png,0,0.1\nf1.png,0.1,0.2\n",
        "is 30x24, the first frame 32x24",
        &[],
    );
    case("file,j1\nf0.png,0.1\n", "needs `file` and `stamp_s`", &[]);
    // Without a pose direction.
    let pose = dir.join("pose_any.yaml");
    std::fs::write(
        &pose,
        "pose: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n",
    )
    .expect("pose");
    case(
        "file,stamp_s,j1\nf0.png,0,0.1\n",
        "direction is not stated",
        &["--pose", pose.to_str().expect("utf-8")],
    );
    // A camera file for other images.
    let cam = dir.join("cam.yaml");
    std::fs::write(
        &cam,
        "image_width: 640\nimage_height: 480\ncamera_matrix: [500, 0, 320, 0, 500, 240, 0, 0, 1]\n",
    )
    .expect("cam");
    case(
        "file,stamp_s,j1\nf0.png,0,0.1\n",
        "the file says 640x480, the images are 32x24",
        &["--camera", cam.to_str().expect("utf-8")],
    );
    // q lists with no names.
    std::fs::remove_file(dir.join("frames.csv")).expect("rm");
    std::fs::write(
        dir.join("frames.json"),
        r#"{"frames": [{"file": "f0.png", "stamp_s": 0, "q": [1, 2]}]}"#,
    )
    .expect("json");
    let (ok, log) = import(&[folder, "--out", file]);
    assert!(
        !ok && log.contains("frames[0]: joints in q order and no names"),
        "{log}"
    );
    let (ok, log) = import(&[folder, "--out", file, "--joint-names", "a,b,c"]);
    assert!(
        !ok && log.contains("2 joint values for 3 names (a, b, c)"),
        "{log}"
    );
}
