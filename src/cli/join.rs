//! `avatarm join`: the operator's site of a two-site session (Blair, docs/network.md), or
//! with `--watch` an observer; `--head` plays a recorded head for a camera on one.

use std::path::{Path, PathBuf};

use avatarm_scene::Scene;
use avatarm_scene::hand::HandChoice;
use clap::Args;

use crate::AppError;
use crate::cli::args::{live_hand, packages, pouring_scene};

/// The arguments of `avatarm join`.
#[derive(Args, Debug)]
pub struct JoinArgs {
    /// The robot site (or a router): tcp/HOST:PORT, udp/HOST:PORT or quic/HOST:PORT (tls/ is
    /// refused: Zenoh's TLS link crashes under load, docs/network.md).
    endpoint: String,
    /// The scene file, the same as the robot site's (default: the pouring scene).
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// The scene's camera NAME whose video the robot site serves (its `serve --view`;
    /// default: the first).
    #[arg(long, value_name = "NAME")]
    view: Option<String>,
    /// Only watch: no hand, no targets.
    #[arg(long)]
    watch: bool,
    /// Stop after this many seconds (default: the task's duration; an observer: until
    /// killed).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// Write the report (JSON) here when it stops.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Record what this site received (MCAP, docs/network.md): its camera's erased frames
    /// as they arrived with the camera pose of each, the robot's joint states and its
    /// stops, on the robot site's clock
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// The head the viewed camera rides on (a camera on a head, Alice's), sent to the robot
    /// site, which erases that camera at it: a recording's tracked head poses
    /// (`run --record` of a head camera), played from the join on. With --xr and no
    /// --head, the headset's head is sent.
    #[arg(long, value_name = "FILE.mcap")]
    head: Option<PathBuf>,
    /// How long to wait for the robot site (s).
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    wait: f64,
    /// The task's trial whose seeded hand the operator plays.
    #[arg(long, value_name = "N", default_value_t = 0)]
    trial: u32,
    /// The operator's hand: scripted (the trial's, default), desktop (keys and mouse, with
    /// --window), xr (OpenXR hand tracking, with --xr), leap (feature `leap`) or a
    /// recorded FILE.hand.jsonl.
    #[arg(long, value_name = "SOURCE")]
    hand: Option<String>,
    /// Open the window: the robot site's video with the hand and the object's twin in
    /// front (the interaction view), and the session's figures.
    #[arg(long)]
    window: bool,
    /// The window's view in an OpenXR headset too (implies --window; without a runtime
    /// the window alone).
    #[arg(long)]
    xr: bool,
    /// Close the window after N frames.
    #[arg(long, value_name = "N")]
    frames: Option<u32>,
    /// Save a screenshot of the window at frame N of --frames (else at frame 120), then
    /// close it.
    #[arg(long, value_name = "PATH")]
    screenshot: Option<PathBuf>,
    /// Folder searched for package://NAME/... URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
    #[command(flatten)]
    net: crate::net::NetArgs,
}

impl JoinArgs {
    /// Runs `avatarm join`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            endpoint,
            scene,
            watch,
            duration,
            report,
            record,
            wait,
            trial,
            hand,
            window,
            xr,
            frames,
            screenshot,
            package_path,
            net,
            view,
            head,
        } = self;
        crate::log::init_log();
        let path = scene.unwrap_or_else(pouring_scene);
        #[allow(unused_mut)] // changed with the feature `xr`
        let mut scene = Scene::load_view(&path, &packages(package_path), view.as_deref())?;
        let head = match head {
            Some(file) => Some(crate::net::join::HeadSource::Recorded(recorded_head(
                &file, &scene,
            )?)),
            None => None,
        };
        // In XR a camera on a head rides on the wearer's head, which goes to the robot
        // site (docs/alice-view.md).
        #[cfg(feature = "xr")]
        let head = match (head, scene.head.as_mut()) {
            (None, Some(rig)) if xr => {
                let live = avatarm_core::vision::head::LiveHead::new(rig.motion.clone());
                rig.motion = avatarm_core::vision::head::HeadMotion::Live(live.clone());
                Some(crate::net::join::HeadSource::Headset(live))
            }
            (head, _) => head,
        };
        let role = if watch {
            avatarm_net::Role::Observer
        } else {
            avatarm_net::Role::Operator
        };
        let window = window || xr;
        if frames == Some(0) {
            return Err(AppError::flag(
                "--frames",
                "0: the window renders at least one",
            ));
        }
        if !window && (frames.is_some() || screenshot.is_some()) {
            return Err(AppError::flag(
                if frames.is_some() {
                    "--frames"
                } else {
                    "--screenshot"
                },
                "counts the window's frames: add --window",
            ));
        }
        let hand = match (watch, hand.as_deref()) {
            (true, Some(_)) => {
                return Err(AppError::flag(
                    "--hand",
                    "an observer (--watch) has no hand",
                ));
            }
            (true, None) => HandChoice::Scripted,
            (false, text) => live_hand(&scene, text, xr)?.ok_or_else(|| {
                AppError::flag("--hand", "the operator needs a hand; --watch only watches")
            })?,
        };
        let options = crate::net::join::JoinOptions {
            hand,
            window: window.then_some(crate::net::window::WindowOptions {
                xr,
                frames,
                screenshot,
            }),
            net: net.config(role, Vec::new(), vec![endpoint])?,
            scene,
            watch,
            duration_s: duration,
            mode: None,
            report,
            record,
            wait_s: wait,
            trial,
            head,
        };
        let r = crate::net::join::join(&options)?;
        println!("{}", crate::net::join::summary(&r));
        Ok(())
    }
}

/// A recording's tracked head poses (`join --head FILE.mcap`) as the head `scene`'s camera
/// rides on: where the recording's mount is another (`join --record` writes the camera as its
/// own head, an identity mount), each is moved so that the scene's mount gives the recorded
/// camera (`base_from_head · recorded mount · scene mount⁻¹`). Errors name the file, and say
/// so when it has no head poses.
fn recorded_head(path: &Path, scene: &Scene) -> Result<Vec<avatarm_record::HeadPose>, AppError> {
    let recording = avatarm_record::Recording::open(path)?;
    if recording.head_poses.is_empty() {
        return Err(AppError::flag(
            "--head",
            format!(
                "{} has no head poses: record a camera on a head (`avatarm run --record`)",
                path.display()
            ),
        ));
    }
    let to_scene = match (recording.head_from_camera, &scene.head) {
        (Some(recorded), Some(rig)) => recorded * rig.believed_mount.inverse(),
        _ => nalgebra::Isometry3::identity(),
    };
    Ok(recording
        .head_poses
        .into_iter()
        .map(|p| avatarm_record::HeadPose {
            base_from_head: p.base_from_head * to_scene,
            ..p
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    /// A recording whose head is the camera itself (`join --record`: an identity mount) plays
    /// as the head of the scene's camera: the scene's mount then gives the recorded camera.
    #[test]
    fn a_recorded_head_is_moved_by_its_mount_against_the_scene_s() {
        let path = std::env::temp_dir().join(format!("avatarm-head-{}.mcap", std::process::id()));
        let base_from_camera = Isometry3::from_parts(
            Translation3::new(0.4, -1.0, 0.3),
            UnitQuaternion::from_euler_angles(-1.4, 0.1, 0.6),
        );
        let mut w = avatarm_record::RecordingWriter::create(&path).expect("created");
        w.camera_mount(0, &Isometry3::identity()).expect("written");
        w.head_pose(&avatarm_record::HeadPose {
            stamp_ns: 5,
            base_from_head: base_from_camera,
        })
        .expect("written");
        w.finish().expect("closed");
        let scene = Scene::load_view(
            Path::new(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/assets/scenes/pouring_two_views.toml"
            )),
            &avatarm_core::robot::PackagePath::default(),
            Some("alice"),
        )
        .expect("the scene");
        let mount = scene.head.as_ref().expect("a head").believed_mount;
        let poses = recorded_head(&path, &scene).expect("read");
        let _ = std::fs::remove_file(&path);
        let camera = poses[0].base_from_head * mount;
        assert!((camera.translation.vector - base_from_camera.translation.vector).norm() < 1e-9);
        assert!(camera.rotation.angle_to(&base_from_camera.rotation) < 1e-9);
        // A recording without head poses is refused by flag, naming the file.
        let empty =
            std::env::temp_dir().join(format!("avatarm-nohead-{}.mcap", std::process::id()));
        avatarm_record::RecordingWriter::create(&empty)
            .expect("created")
            .finish()
            .expect("closed");
        let e = recorded_head(&empty, &scene).expect_err("refused");
        let _ = std::fs::remove_file(&empty);
        assert!(
            e.to_string().contains("--head") && e.to_string().contains("no head poses"),
            "{e}"
        );
    }
}
