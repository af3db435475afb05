//! `avatarm import FOLDER`: the frames a lab has into a recording, read back by Avatarm's
//! reader and by PyPI's `mcap` reader (`scripts/setup.sh` installs it): EasyHeC's layout on the
//! real Panda frames, CSV and JSON listings, every camera-file kind, and the errors.

mod bag;
mod calibrate;
mod drift;
mod import;
mod panda;
mod rim;

use std::path::{Path, PathBuf};
use std::process::Command;

use avatarm::replay::recording::RecordingReport;
use avatarm::replay::{MaskReport, ReplayReport};
use avatarm_footage::calibrate::CalibrateReport;
use avatarm_record::{ImageFormat, Recording};

use crate::support::output;
use crate::support::python_mcap::python_read;
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
    avatarm("import", args)
}

/// Runs `avatarm COMMAND ARGS` from the project root; (success, stdout + stderr).
fn avatarm(command: &str, args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg(command)
        .args(args)
        .current_dir(root())
        .output()
        .expect("avatarm runs");
    (out.status.success(), output::printed(&out))
}

fn png(path: &Path, width: u32, height: u32, shade: u8) {
    image::RgbImage::from_pixel(width, height, image::Rgb([shade, 128, 255 - shade]))
        .save(path)
        .expect("png");
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
    avatarm("replay", args)
}

/// Runs `avatarm calibrate ARGS`; (success, stdout + stderr).
fn calibrate(args: &[&str]) -> (bool, String) {
    avatarm("calibrate", args)
}

/// A report written by a command, read as its type.
fn report<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}\n{text}", path.display()))
}

/// Runs `avatarm replay --recording RECORDING --urdf URDF --out DIR EXTRA` and asserts it
/// succeeds; its report.
fn replay_recording(recording: &Path, urdf: &str, dir: &Path, extra: &[&str]) -> RecordingReport {
    let mut args = vec![
        "--recording",
        recording.to_str().expect("utf-8"),
        "--urdf",
        urdf,
        "--out",
        dir.to_str().expect("utf-8"),
    ];
    args.extend_from_slice(extra);
    let (ok, log) = replay(&args);
    assert!(ok, "{log}");
    report(&dir.join("report.json"))
}

/// Writes `text` as `out/scene.toml` and replays it with `--record out/session.mcap` (its
/// frames and report in `out/recorded`); the scene's path and the recording, read back (a
/// reference mask with every frame).
fn record_scene(out: &Path, text: &str) -> (PathBuf, PathBuf, Recording) {
    let scene_path = out.join("scene.toml");
    std::fs::write(&scene_path, text).expect("scene");
    let recording = out.join("session.mcap");
    let (ok, log) = replay(&[
        scene_path.to_str().expect("utf-8"),
        "--record",
        recording.to_str().expect("utf-8"),
        "--out",
        out.join("recorded").to_str().expect("utf-8"),
    ]);
    assert!(ok, "{log}");
    let r = Recording::open(&recording).expect("read back");
    assert_eq!(r.reference_masks.len(), r.frames.len());
    (scene_path, recording, r)
}
