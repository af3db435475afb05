//! The real frame path without hardware: a recording played as the robot site's camera
//! (`avatarm serve --camera-recording`), each frame's stage stamps checked at a watcher.

use std::path::Path;
use std::process::Command;

use avatarm::net::join::JoinReport;
use avatarm::net::serve::ServeReport;

use crate::network::{POURING, finish, free_port, join_scene, out_dir, serve_scene};
use crate::serial;
use crate::support::output;

/// A second of the pouring scene recorded by the replay (its frames, the joints at each
/// capture, the camera), as `dir/session.mcap`.
fn record_a_second(dir: &Path) -> std::path::PathBuf {
    record_pouring(dir, "1.0")
}

/// `duration_s` (as the scene file writes it) of the pouring scene recorded by the replay (its
/// frames, the joints at each capture, the camera), as `dir/session.mcap`; the replay's own
/// outputs (the empty room's `background.png`) in `dir/replay`.
pub(crate) fn record_pouring(dir: &Path, duration_s: &str) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let urdf = root.join("assets/robots/sawyer_lite/sawyer_lite.urdf");
    let duration = format!("duration_s = {duration_s}");
    let text = std::fs::read_to_string(root.join(POURING))
        .expect("the pouring scene")
        .replace(
            "../robots/sawyer_lite/sawyer_lite.urdf",
            urdf.to_str().expect("a UTF-8 path"),
        )
        .replacen("duration_s = 2.0", &duration, 1);
    assert!(text.contains(&duration), "the scene's duration moved");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, text).expect("the test's set-up");
    let recording = dir.join("session.mcap");
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg("replay")
        .arg(&scene)
        .arg("--record")
        .arg(&recording)
        .arg("--out")
        .arg(dir.join("replay"))
        .output()
        .expect("the test's set-up");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    recording
}

/// The robot site plays a recording as its camera, in real time and in a loop, and its robot
/// as the robot: no simulated room renders, the twin behind the mask takes the recording's
/// joints. Each frame reaches the watcher with its stages stamped on the robot's clock, in
/// their order (captured, arrived in the app, erased and read back, sent, received), and was
/// handed to the encoder in the update it arrived in or the next (structural: update numbers,
/// not times). The player keeps the recording's rate whatever the app's.
#[test]
fn a_recorded_camera_runs_the_real_frame_path_and_each_frame_carries_its_stages() {
    let _serial = serial();
    let dir = out_dir("recorded_camera");
    let recording = record_a_second(&dir);
    let port = free_port();
    let robot = serve_scene(
        &dir,
        POURING,
        port,
        25.0,
        &[
            "--insecure-lan",
            "--camera-recording",
            recording.to_str().expect("a UTF-8 path"),
            // The replay's photograph of the empty room: the simulated room's is no
            // background for a real camera.
            "--background",
            dir.join("replay/background.png")
                .to_str()
                .expect("a UTF-8 path"),
        ],
    );
    let watched = dir.join("watched.mcap");
    let watcher = join_scene(
        &dir,
        "watch",
        POURING,
        port,
        &[
            "--watch",
            "--wait",
            "30",
            "--duration",
            "10",
            "--record",
            watched.to_str().expect("a UTF-8 path"),
        ],
    );
    let watch: JoinReport = finish(watcher, &dir, "watch");
    let site: ServeReport = finish(robot, &dir, "serve");
    assert_eq!(site.robot, "recording session.mcap", "{site:?}");
    let camera = &site.video_cameras[0];
    assert_eq!(camera.source, "session.mcap", "{camera:?}");
    // The player ran at the recording's rate (about 30 frames a second, a lap a second) for
    // the whole run, however slowly the app took them.
    let player = camera.player.as_ref().expect("the player's report");
    assert!(player.laps >= 15, "{camera:?}");
    assert!(player.played >= 15 * 25, "{camera:?}");
    assert!(camera.frames >= 10, "{camera:?}");
    // No frame waited more than one update between arriving and the encoder.
    assert_eq!(camera.handed_late, 0, "{camera:?}");
    assert!(camera.waited_updates_max <= 1, "{camera:?}");
    assert!(camera.update_ms.n >= 10, "{camera:?}");
    let video = &watch.video;
    assert!(video.shown >= 5, "{video:?}");
    assert_eq!(video.refused, 0, "{video:?}");
    assert!(video.waited_updates_max <= 1, "{video:?}");
    assert_eq!(
        video.waited_updates.iter().sum::<u64>(),
        video.shown,
        "{video:?}"
    );
    // Each frame's stages in their order at the robot site, and every stage counted.
    assert_eq!(video.stamps_out_of_order, 0, "{video:?}");
    let stages = [
        ("arrive_ms", video.arrive_ms),
        ("app_ms", video.app_ms),
        ("encode_ms", video.encode_ms),
        ("network_ms", video.network_ms),
        ("decode_ms", video.decode_ms),
    ];
    for (stage, times) in stages {
        assert_eq!(times.n as u64, video.shown, "{stage}: {video:?}");
    }
    // The stages' medians add up to about the total's (medians do not add exactly).
    let sum: f64 = stages.iter().map(|(_, times)| times.median).sum();
    let total = video.total_ms.median;
    assert!(
        total > 0.0 && sum > 0.5 * total && sum < 2.0 * total,
        "{video:?}"
    );
    // The robot is gone from every frame the watcher received: each frame met the joints it
    // was recorded with (a frame masked at other joints keeps the arm's ghost).
    assert_erased(&watched, &dir.join("replay/background.png"), 5, 0);
}

/// Every erased frame of the recording `path` (at least `min_frames`) after its first
/// `start_up` looks like the empty room `background`: under 1 % of its pixels differ by more
/// than 40 (the sum over RGB). Measured: the arm covers 4.5 % of the frame; an erased frame
/// differs in 0.2 % (JPEG).
fn assert_erased(path: &Path, background: &Path, min_frames: usize, start_up: usize) {
    let background = image::open(background)
        .expect("the replay's background")
        .to_rgb8();
    let rec = avatarm_record::Recording::open(path).expect("the recording");
    assert!(
        rec.erased.len() >= min_frames + start_up,
        "{} frames",
        rec.erased.len()
    );
    for (i, e) in rec.erased.iter().enumerate().skip(start_up) {
        let frame = image::load_from_memory(&e.data)
            .expect("an erased frame")
            .to_rgb8();
        assert_eq!(frame.dimensions(), background.dimensions());
        let off = frame
            .pixels()
            .zip(background.pixels())
            .filter(|(a, b)| {
                a.0.iter()
                    .zip(b.0)
                    .map(|(&x, y)| u32::from(x.abs_diff(y)))
                    .sum::<u32>()
                    > 40
            })
            .count();
        let fraction = off as f64 / f64::from(frame.width() * frame.height());
        assert!(
            fraction < 0.01,
            "frame {i}: {:.2} % unlike the empty room",
            100.0 * fraction
        );
    }
}

/// `avatarm run` of the pouring scene under xvfb-run with `recording` as its camera and
/// `background` as H, no live task, and `args`; its log, once it exited successfully.
fn preview_on_recording(dir: &Path, recording: &Path, background: &Path, args: &[&str]) -> String {
    let run = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_avatarm"))
        .args(["run", POURING, "--hand", "none"])
        .arg("--camera-recording")
        .arg(recording)
        .arg("--background")
        .arg(background)
        .args(args)
        // No OpenXR runtime, even where a developer has one installed.
        .env("XR_RUNTIME_JSON", dir.join("no_runtime.json"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("xvfb-run starts (scripts/setup.sh installs it)");
    let log = output::printed(&run);
    assert!(run.status.success(), "{log}");
    log
}

/// `avatarm run --camera-recording`: the preview plays the recording as its camera and its
/// robot as the twin's (no live task: `--hand none`), and erases it; `--record` keeps what it
/// showed.
#[test]
fn the_preview_plays_a_recording_as_its_camera_and_erases_its_robot() {
    let _serial = serial();
    let dir = out_dir("preview_recorded_camera");
    let recording = record_a_second(&dir);
    let session = dir.join("preview.mcap");
    let background = dir.join("replay/background.png");
    let log = preview_on_recording(
        &dir,
        &recording,
        &background,
        &["--frames", "90", "--record", &session.to_string_lossy()],
    );
    assert!(log.contains("played in a loop"), "{log}");
    // The preview compiles its pipelines while the first frames arrive (the robot site waits
    // for them; the preview does not yet): its first frames are black, then drawn before the
    // mask's pipeline was ready (measured: 2 and 7 of the first 9). From the first drawn mask
    // on, every frame is erased; that start-up is at most half a second.
    let rec = avatarm_record::Recording::open(&session).expect("the preview's recording");
    let start_up = rec
        .masks
        .iter()
        .position(|m| {
            image::load_from_memory(&m.data)
                .expect("a mask")
                .to_luma8()
                .pixels()
                .any(|p| p.0[0] > 0)
        })
        .expect("a mask with the robot in it");
    assert!(start_up <= 15, "{start_up} frames before the first mask");
    assert_erased(&session, &background, 5, start_up);
    // On the wall clock (no --frames: Escape pressed by script ends it), each frame the erase
    // takes is stamped again when the window's frame showing it is presented: glass to glass
    // (but the display's scan-out), said at the exit.
    let log = preview_on_recording(&dir, &recording, &background, &["--press", "45:Esc"]);
    let line = log
        .lines()
        .find(|l| l.contains("glass to glass (capture -> presented) median"))
        .unwrap_or_else(|| panic!("no glass to glass line:\n{log}"));
    // The number after a word of the line: "median X ms, p95 Y ms over N frames".
    let after = |word: &str| -> f64 {
        line.split_once(word)
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .and_then(|w| w.trim_end_matches(',').parse().ok())
            .unwrap_or_else(|| panic!("no number after '{word}' in: {line}"))
    };
    let (median, p95, frames) = (after(" median "), after(" p95 "), after(" over "));
    eprintln!("the preview's glass to glass: median {median} ms, p95 {p95} ms, {frames} frames");
    // Some frames presented, each after its capture.
    assert!(frames >= 3.0, "{line}");
    assert!(median > 0.0 && median <= p95, "{line}");
}

/// `avatarm run --ros2-camera TOPIC`: the preview takes its camera from a ROS 2 camera driver
/// over DDS (the fake driver of `avatarm_ros::testing`, on Cyclone DDS, publishing a 640x480
/// PNG as `sensor_msgs/msg/CompressedImage` at 15 fps), decodes each frame, erases the robot
/// from it and presents it; the glass to glass line counts the frames from the driver's stamp.
/// The driver's `CameraInfo` and its latched static transform (the camera's mount) become
/// the scene's camera, said on stderr.
#[cfg(feature = "ros")]
#[test]
fn the_preview_takes_its_camera_from_a_ros2_driver() {
    let _serial = serial();
    let dir = out_dir("preview_ros2_camera");
    let picture = dir.join("frame.png");
    image::RgbImage::from_fn(640, 480, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, 128])
    })
    .save(&picture)
    .expect("a PNG");
    let domain = avatarm_ros::testing::test_domain(7);
    let topic = "/camera/image_raw/compressed";
    let _camera = avatarm_ros::testing::FakeRos2Camera::start(
        domain,
        topic,
        &[
            "--file",
            picture.to_str().expect("utf-8"),
            "--fps",
            "15",
            // Its calibration and its mount, as a calibrated driver publishes them: the
            // scene's camera replaced by them (the camera level, 1.85 m out, looking back).
            "--width",
            "640",
            "--height",
            "480",
            "--fx",
            "470",
            "--fy",
            "471",
            "--cx",
            "321",
            "--cy",
            "238",
            "--tf-static",
            "base",
            "camera_optical_frame",
            "1.85",
            "0",
            "0.55",
            "-0.5",
            "-0.5",
            "0.5",
            "0.5",
        ],
    );
    let run = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_avatarm"))
        .args(["run", POURING, "--hand", "none", "--ros2-camera", topic])
        .args(["--press", "90:Esc"])
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("XR_RUNTIME_JSON", dir.join("no_runtime.json"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("xvfb-run starts (scripts/setup.sh installs it)");
    let log = output::printed(&run);
    assert!(run.status.success(), "{log}");
    assert!(
        log.contains(&format!(
            "streaming from sensor_msgs/msg/CompressedImage on {topic} (DDS domain {domain})"
        )),
        "{log}"
    );
    for said in [
        "the camera's calibration from /camera/camera_info: 640x480, fx fy cx cy [470.0, 471.0, 321.0, 238.0] px, lens none",
        "the camera's pose from /tf: base -> camera_optical_frame, at [1.850, 0.000, 0.550] m in base",
    ] {
        assert!(log.contains(said), "{said}\n{log}");
    }
    let line = log
        .lines()
        .find(|l| l.contains("glass to glass (capture -> presented) median"))
        .unwrap_or_else(|| panic!("no glass to glass line:\n{log}"));
    eprintln!("ROS 2 camera in the preview: {line}");
    let frames: f64 = line
        .split_once(" over ")
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no frame count in: {line}"));
    assert!(frames >= 3.0, "{line}");
}
