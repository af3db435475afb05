//! `avatarm run`: the desktop preview of a scene, live teleoperation of its `[task]`, XR
//! with fallback, a webcam, the robot over ROS, a session recording.

use std::path::PathBuf;

use avatarm_scene::Scene;
use avatarm_scene::spec::LeapMountKind;
use clap::Args;

use crate::AppError;
use crate::cli::args::{default_scene, leap_mount, live_hand, packages, step_ms};
use crate::cli::overrides::EraseOverrides;
use crate::preview::PreviewOptions;

/// The arguments of `avatarm run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The scene file.
    scene: Option<PathBuf>,
    /// Look through the scene's camera NAME (one of its [[cameras]]; default: the first).
    #[arg(long, value_name = "NAME")]
    view: Option<String>,
    /// Start an OpenXR session; without a runtime the preview window is used.
    #[arg(long)]
    xr: bool,
    /// Quit after N frames (with --screenshot, 10 more for it to be written).
    #[arg(long, value_name = "N")]
    frames: Option<u32>,
    /// Advance simulated time by MS per rendered frame instead of by the wall clock
    /// (default with --frames: half a camera frame, a display twice as fast as the camera).
    #[arg(long = "step-ms", value_name = "MS", value_parser = step_ms)]
    step_ms: Option<f64>,
    /// Save a screenshot of the window at the last frame.
    #[arg(long, value_name = "PATH")]
    screenshot: Option<PathBuf>,
    /// Press KEY at rendered frame N (from 1) for one frame, for scripted runs (repeatable;
    /// e.g. `--press 60:C` switches camera at frame 60). KEY: one of the keys below
    /// (V, C, E, M, W, B, R, F12, Esc).
    #[arg(long, value_name = "N:KEY", value_parser = crate::preview::keys::parse_press)]
    press: Vec<(u32, bevy::input::keyboard::KeyCode)>,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
    /// Take the camera feed from webcam N (feature `webcam`) instead of the simulated room.
    #[arg(long, value_name = "N", conflicts_with_all = ["camera_recording", "ros2_camera"])]
    webcam: Option<u32>,
    /// Play a recording (MCAP) as the camera, each frame at its capture time, in a loop, and
    /// its joint states as the robot's (the live task's robot with a hand; docs/latency.md).
    #[arg(
        long = "camera-recording",
        value_name = "FILE.mcap",
        conflicts_with = "ros2_camera"
    )]
    camera_recording: Option<PathBuf>,
    /// Take the camera feed from a ROS 2 topic over DDS or rmw_zenoh (sensor_msgs/msg/Image, or
    /// CompressedImage on a topic ending in /compressed; the scene's ros2_control link's domain and
    /// middleware, else ROS_DOMAIN_ID and RMW_IMPLEMENTATION; docs/robot-ros2.md).
    #[arg(long = "ros2-camera", value_name = "TOPIC")]
    ros2_camera: Option<String>,
    /// With a scene that has a [task] or [chess]: teleoperate it live with this hand: scripted
    /// (the task's trial or the opening's moves, default), desktop (keys and mouse), xr (OpenXR hand tracking, with
    /// --xr), leap (feature `leap`), a recorded FILE.hand.jsonl, or none.
    #[arg(long, value_name = "SOURCE")]
    hand: Option<String>,
    /// How the Leap (live or recorded) is mounted: desk, head or first_wrist (the scene's
    /// [leap] mount otherwise; docs/hand.md).
    #[arg(long = "leap-mount", value_name = "MOUNT", value_parser = leap_mount)]
    leap_mount: Option<LeapMountKind>,
    /// The robot the live task commands: sim (the simulated arm), ros (the real robot
    /// through the scene's [robot.link], ROS 1 or ROS 2 as its kind says; docs/robot-ros.md)
    /// or ros2 (the same, checked to be kind = "ros2_control"; docs/robot-ros2.md).
    #[arg(long, value_name = "ROBOT", value_parser = ["sim", "ros", "ros2"], default_value = "sim")]
    robot: String,
    /// Record the session (MCAP, Foxglove's schemas): camera frames, calibration and pose,
    /// joint states, Avatarm's erased frames and masks, the hand, the robot's commands and
    /// safety events (docs/real-footage.md).
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// Publish the session on ROS 2 over DDS or rmw_zenoh (feature `ros`), under /avatarm: the
    /// erased frames and the masks (CompressedImage on /avatarm/erased/compressed and
    /// /avatarm/mask/compressed), the commands (JointState on /avatarm/joint_commands) and the
    /// safety events (String on /avatarm/safety), on the scene's ros2_control link's domain and
    /// middleware, else ROS_DOMAIN_ID and RMW_IMPLEMENTATION (docs/robot-ros2.md).
    #[arg(long = "ros2-publish")]
    ros2_publish: bool,
    /// Sleep MS at the end of every app update: a renderer slowed on purpose, to check that the
    /// robot's control loop keeps its rate whatever the render costs (docs/latency.md).
    #[arg(long = "slow-update-ms", value_name = "MS", value_parser = clap::value_parser!(u64).range(1..=10_000))]
    slow_update_ms: Option<u64>,
    #[command(flatten)]
    overrides: EraseOverrides,
}

impl RunArgs {
    /// Runs `avatarm run`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            xr,
            frames,
            step_ms,
            screenshot,
            press,
            package_path,
            webcam,
            camera_recording,
            ros2_camera,
            hand,
            leap_mount,
            robot,
            record,
            ros2_publish,
            slow_update_ms,
            overrides,
            view,
        } = self;
        if camera_recording.is_some() && robot != "sim" {
            return Err(AppError::flag(
                "--robot",
                "with --camera-recording the robot is the recording's; leave --robot out",
            ));
        }
        let path = scene.unwrap_or_else(default_scene);
        let packages = packages(package_path);
        // The scene through camera `view`, with the command line's changes.
        let through = |view: Option<&str>| -> Result<Scene, AppError> {
            let mut scene = Scene::load_view(&path, &packages, view)?;
            overrides.apply(&mut scene)?;
            if let Some(mount) = leap_mount {
                if mount == LeapMountKind::FirstWrist && scene.file.leap.device_at.is_some() {
                    return Err(AppError::flag(
                        "--leap-mount",
                        "first_wrist places a recording by its first wrist, but the \
                         scene's [leap] gives device_at",
                    ));
                }
                scene.file.leap.mount = mount;
            }
            Ok(scene)
        };
        let mut scene = through(view.as_deref())?;
        let xr = xr || scene.file.xr;
        // In XR a camera on a head rides on the wearer's head (the scripted motion until
        // the headset reports; docs/alice-view.md).
        let ride = |scene: &mut Scene| {
            #[cfg(feature = "xr")]
            if xr && let Some(head) = scene.head.as_mut() {
                head.motion = avatarm_core::vision::head::HeadMotion::Live(
                    avatarm_core::vision::head::LiveHead::new(head.motion.clone()),
                );
            }
            #[cfg(not(feature = "xr"))]
            let _ = (xr, scene);
        };
        ride(&mut scene);
        // A webcam or a recording as the camera (a recording's robot as the robot).
        let opened = crate::net::site_camera::open(
            &crate::net::site_camera::SiteCamera::of(
                webcam,
                camera_recording,
                ros2_camera,
                overrides.believed_pose.is_some(),
            ),
            &mut scene,
            1,
        )?;
        for note in &opened.notes {
            // Said here: the app's log is not set up yet.
            eprintln!("{note}");
        }
        // The C key switches between the scene's cameras in place; a session recording and
        // a real camera hold one camera.
        let no_switch = match &record {
            _ if scene.cameras.len() < 2 => None,
            _ if !opened.source.is_simulated() => {
                Some(format!("the {} is the one camera", opened.source.name()))
            }
            Some(_) => Some(format!(
                "a recording holds one camera; start again with --view {}",
                scene.cameras[(scene.camera_index + 1) % scene.cameras.len()]
            )),
            None => None,
        };
        let cameras = if no_switch.is_none() && scene.cameras.len() > 1 {
            let names = scene.cameras.clone();
            names
                .iter()
                .enumerate()
                .map(|(i, name)| {
                    if i == scene.camera_index {
                        Ok(scene.clone())
                    } else {
                        let mut other = through(Some(name))?;
                        ride(&mut other);
                        Ok(other)
                    }
                })
                .collect::<Result<Vec<_>, AppError>>()?
        } else {
            Vec::new()
        };
        let hand = live_hand(&scene, hand.as_deref(), xr)?;
        let robot = crate::teleop::robot_choice(&robot, &scene)?;
        if robot == crate::teleop::RobotChoice::Ros && hand.is_none() {
            return Err(AppError::flag(
                "--robot ros",
                "commands the robot from a live task: the scene needs a [task] and a hand",
            ));
        }
        let options = PreviewOptions {
            frames,
            screenshot,
            xr,
            fixed_step_s: step_ms
                .map(|ms| ms / 1e3)
                .or_else(|| frames.map(|_| 0.5 / scene.file.camera.fps)),
            camera: opened.source,
            recorded_arm: opened.arm,
            hand,
            robot,
            cameras,
            no_switch,
            press,
            slow_update: slow_update_ms.map(std::time::Duration::from_millis),
        };
        let ros2 = if ros2_publish {
            Some(crate::net::ros2_out::ros2_publisher(&scene)?)
        } else {
            None
        };
        let mut app = crate::preview::build_app(&scene, &options)?;
        if record.is_some() || ros2.is_some() {
            crate::session::add_session_recorder(&mut app, record.as_deref(), ros2, &scene)?;
        }
        let exit = app.run();
        if exit.is_error() {
            return Err(AppError::Preview);
        }
        Ok(())
    }
}
