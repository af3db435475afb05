//! `avatarm import FILE.bag`: ROS 1 bags written by Debian's python3-rosbag, compressed or not,
//! with raw and compressed images.

use super::*;

/// Writes a bag with `tests/fixtures/write_bag.py` (Debian's python3-rosbag, which
/// `scripts/setup.sh` installs).
fn write_bag(args: &[&str]) {
    let out = Command::new("/usr/bin/python3")
        .arg(root().join("tests/fixtures/write_bag.py"))
        .args(args)
        .output()
        .expect("/usr/bin/python3 runs");
    assert!(
        out.status.success(),
        "writing the bag with python3-rosbag failed (run scripts/setup.sh): {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The real Panda frames as a ROS driver records them (CompressedImage, CameraInfo,
/// JointState at twice the frame rate, the camera placed by /tf_static through camera_link to
/// the optical frame, an unrelated /tf), written by python3-rosbag: the recording `avatarm
/// import FILE.bag` makes holds what the folder import makes from the same frames.
#[test]
fn a_ros_bag_imports_to_the_recording_its_folder_gives() {
    let data = match avatarm_core::shared_data::shared_data() {
        Ok(d) => d,
        Err(why) => return why.skip("a_ros_bag_imports_to_the_recording_its_folder_gives"),
    };
    let out = out_dir("bag_panda");
    let bag = out.join("panda.bag");
    let easyhec = data.join("real/franka_easyhec");
    write_bag(&[
        "panda",
        bag.to_str().expect("utf-8"),
        easyhec.to_str().expect("utf-8"),
    ]);
    let from_bag = out.join("from_bag.mcap");
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        from_bag.to_str().expect("utf-8"),
        "--mask-topic",
        "/camera/mask/compressed",
        "--base-frame",
        "panda_link0",
    ]);
    assert!(ok, "{log}");
    assert!(
        log.contains("/tf: panda_link0 -> camera_color_optical_frame"),
        "{log}"
    );
    assert!(
        log.contains("/tf_static (tf2_msgs/TFMessage): 1 messages"),
        "{log}"
    );
    let folder = import_panda(&data, &out);
    let (a, b) = (
        Recording::open(&from_bag).expect("bag's"),
        Recording::open(&folder).expect("folder's"),
    );
    assert_eq!(a.frames.len(), 10);
    for (i, (x, y)) in a.frames.iter().zip(&b.frames).enumerate() {
        assert!(x.data == y.data, "frame {i}: not the PNG as recorded");
    }
    // The masks as silhouettes: 255 wherever the folder's is not 0.
    for (i, (x, y)) in a.reference_masks.iter().zip(&b.reference_masks).enumerate() {
        let (x, y) = (
            image::load_from_memory(&x.data).expect("png").to_luma8(),
            image::load_from_memory(&y.data).expect("png").to_luma8(),
        );
        assert_eq!(x.dimensions(), y.dimensions());
        let differ = x
            .pixels()
            .zip(y.pixels())
            .filter(|(p, q)| p.0[0] != if q.0[0] != 0 { 255 } else { 0 })
            .count();
        assert_eq!(differ, 0, "mask {i}");
    }
    assert_eq!(a.reference_masks.len(), 10);
    // The stamps: 1/30 s apart from the bag's first, as the folder's from 0.
    let t0 = a.frames[0].stamp_ns;
    for (x, y) in a.frames.iter().zip(&b.frames) {
        assert!(
            (x.stamp_ns - t0).abs_diff(y.stamp_ns) <= 1_000,
            "{} {}",
            x.stamp_ns - t0,
            y.stamp_ns
        );
    }
    assert_eq!(a.joint_states.len(), 20);
    for (i, y) in b.joint_states.iter().enumerate() {
        let x = &a.joint_states[2 * i];
        assert_eq!(x.names, y.names);
        assert_eq!(x.positions, y.positions);
        assert_eq!(x.velocities.len(), x.names.len());
    }
    assert_eq!(a.calibration, b.calibration);
    let (pa, pb) = (
        a.base_from_camera.expect("from /tf"),
        b.base_from_camera.expect("from the pose file"),
    );
    let d = pa.inverse() * pb;
    assert!(d.rotation.angle() < 1e-6, "{}", d.rotation.angle());
    assert!(
        d.translation.vector.norm() < 1e-6,
        "{}",
        d.translation.vector.norm()
    );
    // Without --base-frame the pose is not guessed; a base /tf does not connect is refused.
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        out.join("no_base.mcap").to_str().expect("utf-8"),
        "--image-topic",
        "/camera/color/image_raw/compressed",
    ]);
    assert!(ok && log.contains("give --base-frame"), "{log}");
    assert!(
        Recording::open(&out.join("no_base.mcap"))
            .expect("read")
            .base_from_camera
            .is_none()
    );
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        out.join("bad.mcap").to_str().expect("utf-8"),
        "--image-topic",
        "/camera/color/image_raw/compressed",
        "--base-frame",
        "base_link",
    ]);
    assert!(
        !ok && log.contains("--base-frame") && log.contains("panda_link0"),
        "{log}"
    );
}

/// Raw `sensor_msgs/Image` frames in four encodings, rows padded past their width: each
/// becomes the same RGB picture, from uncompressed and bz2 chunks; a bag with two image topics
/// needs --image-topic; a file that is not a bag is refused by name.
#[test]
fn raw_images_in_a_bag_are_decoded_by_their_encoding() {
    for compression in ["none", "bz2"] {
        raw_bag(compression);
    }
}

fn raw_bag(compression: &str) {
    let out = out_dir(&format!("bag_raw_{compression}"));
    let bag = out.join("raw.bag");
    write_bag(&["raw", bag.to_str().expect("utf-8"), compression]);
    let file = out.join("raw.mcap");
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
    ]);
    assert!(
        !ok && log.contains("--image-topic") && log.contains("/other/image_raw"),
        "{log}"
    );
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
        "--image-topic",
        "/camera/image_raw",
    ]);
    assert!(ok, "{log}");
    assert!(log.contains("give --base-frame"), "{log}");
    // The effort-only joint states and the broken transform are left out and said.
    assert!(
        log.contains("4 joint states on /joint_states had no positions"),
        "{log}"
    );
    assert!(log.contains("map -> odom"), "{log}");
    let r = Recording::open(&file).expect("read back");
    assert_eq!(r.frames.len(), 4);
    assert!(r.base_from_camera.is_none());
    assert!(r.reference_masks.is_empty());
    for (i, f) in r.frames.iter().enumerate() {
        assert_eq!(f.format, ImageFormat::Png);
        let picture = image::load_from_memory(&f.data).expect("png").to_rgb8();
        assert_eq!(picture.dimensions(), (4, 3));
        for (x, y, p) in picture.enumerate_pixels() {
            let (r, g, b) = (10 * x as u8 + 1, 10 * y as u8 + 2, 100 + i as u8);
            let expected = if i < 2 { [r, g, b] } else { [r, r, r] };
            assert_eq!(p.0, expected, "frame {i} pixel ({x}, {y})");
        }
    }
    assert_eq!(r.joint_states.len(), 4);
    assert_eq!(r.joint_states[3].positions, vec![0.1 * 3.0, -0.2 * 3.0]);
    assert!(r.joint_states[0].velocities.is_empty());
    let c = r.calibration.expect("calibration");
    assert_eq!((c.width, c.height, c.k[0], c.k[2]), (4, 3, 5.0, 1.5));
    // The label mask becomes a silhouette (255 = robot); the pose is chained from /tf.
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
        "--image-topic",
        "/camera/image_raw",
        "--mask-topic",
        "/camera/mask",
        "--base-frame",
        "camera_base",
    ]);
    assert!(ok, "{log}");
    let r = Recording::open(&file).expect("read back");
    assert_eq!(r.reference_masks.len(), 4);
    let mask = image::load_from_memory(&r.reference_masks[0].data)
        .expect("png")
        .to_luma8();
    for (x, _, p) in mask.enumerate_pixels() {
        assert_eq!(p.0[0], if x >= 2 { 255 } else { 0 });
    }
    let pose = r.base_from_camera.expect("from /tf");
    assert!((pose.translation.vector.z - 1.0).abs() < 1e-12 && pose.rotation.angle() < 1e-12);
    // A topic of another type, and a file that is not a bag.
    let (ok, log) = import(&[
        bag.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
        "--image-topic",
        "/joint_states",
    ]);
    assert!(!ok && log.contains("sensor_msgs/JointState"), "{log}");
    let fake = out.join("fake.bag");
    std::fs::write(&fake, b"not a bag").expect("write");
    let (ok, log) = import(&[
        fake.to_str().expect("utf-8"),
        "--out",
        file.to_str().expect("utf-8"),
    ]);
    assert!(
        !ok && log.contains("not a ROS 1 bag") && log.contains("fake.bag"),
        "{log}"
    );
}
