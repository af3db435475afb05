//! `avatarm import FOLDER` with CSV and JSON listings and every camera-file kind, and the folders
//! it refuses.

use super::*;

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
