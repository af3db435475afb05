//! The live drift watch: `avatarm serve` with a recording played as its camera, the camera
//! bumped in the recording; the watch on its worker thread finds the move and the pose is
//! fitted again.

use std::path::Path;

use nalgebra::{Unit, UnitQuaternion, Vector3};

use crate::latency::record_pouring;
use crate::network::{POURING, free_port, out_dir, serve_scene};
use crate::serial;
use crate::support::bump::write_bumped;

/// The pouring scene's 4 s recorded by the replay (`dir/session.mcap`), then bumped 1 deg from
/// 0.5 s on (`dir/bumped.mcap`).
fn bumped_recording(dir: &Path) -> std::path::PathBuf {
    let recording = record_pouring(dir, "4.0");
    let r = avatarm_record::Recording::open(&recording).expect("read back");
    let first = r.frames.first().expect("frames").stamp_ns;
    let turn = UnitQuaternion::from_axis_angle(
        &Unit::new_normalize(Vector3::new(0.3, 1.0, 0.2)),
        1f64.to_radians(),
    );
    let bumped = dir.join("bumped.mcap");
    write_bumped(&r, &bumped, first + 500_000_000, &turn);
    bumped
}

/// `avatarm serve --camera-recording` (the robot site, on the wall clock) with the camera bumped
/// 1 deg half a second into the recording: the live watch (on by default with a real camera)
/// checks a frame every half second on its worker thread, confirms the move and fits the
/// camera's turn again; the log says so, with a turn near the true 1 deg.
#[test]
fn the_robot_site_finds_a_bumped_camera_and_fits_it_again() {
    let _serial = serial();
    let dir = out_dir("serve_drift");
    let recording = bumped_recording(&dir);
    let recording = recording.to_str().expect("UTF-8");
    let mut serve = serve_scene(
        &dir,
        POURING,
        free_port(),
        12.0,
        &["--insecure-lan", "--camera-recording", recording],
    );
    let status = serve.wait().expect("serve runs");
    let log = std::fs::read_to_string(dir.join("serve.log")).expect("the log");
    assert!(status.success(), "{log}");
    assert!(log.contains("drift watch: on"), "{log}");
    let moved = log
        .lines()
        .find(|l| l.contains("drift watch: the camera moved"))
        .unwrap_or_else(|| panic!("no move found:\n{log}"));
    eprintln!("{moved}");
    // "... ({deg} deg from the pose before, ...".
    let deg: f64 = moved
        .split_once(" deg from the pose before")
        .and_then(|(head, _)| head.rsplit('(').next())
        .and_then(|w| w.trim().parse().ok())
        .unwrap_or_else(|| panic!("no turn in: {moved}"));
    assert!((0.7..=1.3).contains(&deg), "{moved}");
}
