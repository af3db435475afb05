//! `avatarm import BAG`: ROS 1 bags written by Debian's python3-rosbag, compressed or not,
//! with raw and compressed images; the same bags as rosbag2 (MCAP and SQLite storage,
//! compressed every way rosbag2 does) converted by PyPI's `rosbags` (an implementation
//! Avatarm did not write), which must import to the very same recording.

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

/// `rosbags-convert` (PyPI's `rosbags`, which `scripts/setup.sh` installs) from the ROS 1 bag
/// `src` to the rosbag2 `dst`, its messages rewritten to ROS 2 Humble's definitions (a
/// Header without `seq`), with `extra` options (storage, compression).
fn rosbags_convert(src: &Path, dst: &Path, extra: &[&str]) {
    let _ = std::fs::remove_dir_all(dst);
    let out = Command::new("python3")
        .args(["-m", "rosbags.convert", "--src"])
        .arg(src)
        .arg("--dst")
        .arg(dst)
        .args(["--dst-typestore", "ros2_humble"])
        .args(extra)
        .env("PYTHONPATH", crate::support::python_mcap::python_path())
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "rosbags-convert failed (scripts/setup.sh installs PyPI's rosbags): {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Imports `bag` with `args` to `out` and checks the recording is, byte for byte, `expected`.
fn imports_to(bag: &Path, out: &Path, args: &[&str], expected: &Path, format: &str) {
    let mut all = vec![
        bag.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
    ];
    all.extend(args);
    let (ok, log) = import(&all);
    assert!(ok && log.contains(format), "{}: {log}", bag.display());
    let (a, b) = (
        std::fs::read(out).expect("written"),
        std::fs::read(expected).expect("the ROS 1 bag's"),
    );
    assert!(
        a == b,
        "{}: not the recording the ROS 1 bag gives ({} and {} bytes)",
        bag.display(),
        a.len(),
        b.len()
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
    // The same bag as rosbag2, MCAP (chunks zstd-compressed, rosbag2's default) and SQLite.
    let args = [
        "--mask-topic",
        "/camera/mask/compressed",
        "--base-frame",
        "panda_link0",
    ];
    for (storage, extra) in [
        (
            "mcap",
            &["--compress", "zstd", "--compress-mode", "storage"][..],
        ),
        ("sqlite3", &[][..]),
    ] {
        let dst = out.join(format!("panda_{storage}"));
        let mut options = vec!["--dst-storage", storage];
        options.extend(extra);
        rosbags_convert(&bag, &dst, &options);
        let format = format!("rosbag2 ({storage})");
        imports_to(
            &dst,
            &out.join(format!("from_{storage}.mcap")),
            &args,
            &from_bag,
            &format,
        );
    }
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
    if compression == "none" {
        rosbag2_layouts(&out, &bag, &file);
    }
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

/// The raw bag as rosbag2 in every layout rosbag2 writes: MCAP and SQLite, uncompressed, zstd
/// by file, by message and (MCAP) by chunk; a folder or its one storage file. Each imports to
/// the recording the ROS 1 bag gives (`expected`, from the same options); what is not a
/// rosbag2 is refused by name.
fn rosbag2_layouts(out: &Path, bag: &Path, expected: &Path) {
    let args = [
        "--image-topic",
        "/camera/image_raw",
        "--mask-topic",
        "/camera/mask",
        "--base-frame",
        "camera_base",
    ];
    let zstd = |mode: &'static str| vec!["--compress", "zstd", "--compress-mode", mode];
    for (name, storage, extra, file) in [
        ("mcap", "mcap", vec![], Some("mcap.mcap")),
        (
            "mcap_file",
            "mcap",
            zstd("file"),
            Some("mcap_file.mcap.zstd"),
        ),
        ("mcap_message", "mcap", zstd("message"), None),
        ("mcap_chunks", "mcap", zstd("storage"), None),
        ("sqlite3", "sqlite3", vec![], Some("sqlite3.db3")),
        ("sqlite3_message", "sqlite3", zstd("message"), None),
    ] {
        let dst = out.join(name);
        let mut options = vec!["--dst-storage", storage];
        options.extend(extra);
        rosbags_convert(bag, &dst, &options);
        let format = format!("rosbag2 ({storage})");
        imports_to(
            &dst,
            &out.join(format!("{name}.mcap")),
            &args,
            expected,
            &format,
        );
        if let Some(f) = file {
            let one = dst.join(f);
            let to = out.join(format!("{name}_file.mcap"));
            imports_to(&one, &to, &args, expected, &format);
        }
    }
    // An Avatarm recording is not a rosbag2; a .db3 that is not SQLite; a storage not read.
    let fake = out.join("fake.db3");
    std::fs::write(&fake, b"not a database").expect("write");
    let other = out.join("other_storage");
    std::fs::create_dir_all(&other).expect("mkdir");
    std::fs::write(
        other.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  storage_identifier: foo\n  relative_file_paths: [a.foo]\n",
    )
    .expect("write");
    let lone = out.join("mcap_message/mcap_message.mcap");
    for (input, said) in [
        (expected, ["no topic is CDR", "--recording"]),
        // A message-compressed bag's storage file without its metadata.yaml.
        (&lone, ["zstd-compressed message", "metadata.yaml"]),
        (&fake, ["fake.db3", "not a rosbag2 SQLite file"]),
        (&other, ["metadata.yaml", "ros2 bag convert"]),
    ] {
        let x = out.join("x.mcap");
        let mut all = vec![
            input.to_str().expect("utf-8"),
            "--out",
            x.to_str().expect("utf-8"),
        ];
        all.extend(args);
        let (ok, log) = import(&all);
        assert!(!ok && said.iter().all(|s| log.contains(s)), "{log}");
    }
}
