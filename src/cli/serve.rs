//! `avatarm serve`: the robot site of a two-site session (Alice's desk, docs/network.md):
//! the robot, the cameras, the erase and the robot's side of the mapping, over Zenoh.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::cli::args::{mapping_mode, packages, pouring_scene};
use crate::cli::overrides::on_off;

/// The arguments of `avatarm serve`.
#[derive(Args, Debug)]
pub struct ServeArgs {
    /// The scene file.
    scene: Option<PathBuf>,
    /// Serve the scene's cameras NAME,... (of its [[cameras]]; repeatable; default: every
    /// one), each erased by an app of its own and published under its name.
    #[arg(long, value_name = "NAME", value_delimiter = ',')]
    view: Vec<String>,
    /// The robot: sim (the simulated arm), ros (the scene's [robot.link], ROS 1 or ROS 2 as
    /// its kind says) or ros2 (the same, checked to be kind = "ros2_control"). With
    /// --camera-recording the robot is the recording's.
    #[arg(long, value_name = "ROBOT", value_parser = ["sim", "ros", "ros2"], default_value = "sim")]
    robot: String,
    /// Take the camera from webcam N (feature `webcam`) instead of the simulated room (one
    /// camera: one --view).
    #[arg(long, value_name = "N", conflicts_with_all = ["camera_recording", "ros2_camera"])]
    webcam: Option<u32>,
    /// Play a recording (MCAP: `avatarm replay --record`, `run --record`, `import`) as the
    /// camera, each frame released at its capture time (in a loop), and its joint states as
    /// the robot's: the real frame path without hardware (docs/latency.md). Commands to the
    /// recording's robot are counted, not obeyed.
    #[arg(
        long = "camera-recording",
        value_name = "FILE.mcap",
        conflicts_with = "ros2_camera"
    )]
    camera_recording: Option<PathBuf>,
    /// Take the camera from a ROS 2 topic over DDS or rmw_zenoh (sensor_msgs/msg/Image, or
    /// CompressedImage on a topic ending in /compressed, e.g. /camera/image_raw/compressed; the
    /// scene's ros2_control link's domain and middleware, else ROS_DOMAIN_ID and
    /// RMW_IMPLEMENTATION; one camera: one --view; docs/robot-ros2.md).
    #[arg(long = "ros2-camera", value_name = "TOPIC")]
    ros2_camera: Option<String>,
    /// Publish on ROS 2 over DDS or rmw_zenoh (feature `ros`), under /avatarm: the erased frames
    /// (with --codec jpeg: CompressedImage on /avatarm/erased/compressed), the commands (JointState
    /// on /avatarm/joint_commands) and the safety events (String on /avatarm/safety), on the
    /// scene's ros2_control link's domain and middleware, else ROS_DOMAIN_ID and RMW_IMPLEMENTATION
    /// (docs/robot-ros2.md).
    #[arg(long = "ros2-publish")]
    ros2_publish: bool,
    /// Where to listen (tcp/HOST:PORT, udp/HOST:PORT or quic/HOST:PORT; quic/ between real
    /// sites; default tcp/0.0.0.0:7447 unless --connect is given).
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Connect to a router instead of listening (`avatarm router`, docs/network.md):
    /// nothing listens at the robot site, which logs in to the router with --credentials
    /// (its user:password line).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// The mapping mode: paper or closed_loop (default: the task's closed loop).
    #[arg(long, value_name = "MODE", value_parser = mapping_mode)]
    mode: Option<avatarm_core::teleop::mapping::MappingMode>,
    /// Targets older than this stop the arm (s): above the network's one-way delay.
    #[arg(long = "target-timeout", value_name = "S", default_value_t = 0.5)]
    target_timeout: f64,
    /// Render, erase and publish the camera's video: on or off (the control loop alone).
    #[arg(long, value_name = "on|off", value_parser = on_off)]
    video: Option<bool>,
    /// The video's codec: jpeg (each frame stands alone) or h264 (OpenH264, Constrained
    /// Baseline; IDR frames periodically and when a viewer asks after a loss).
    #[arg(long, value_name = "CODEC", value_parser = ["jpeg", "h264"], default_value = "jpeg")]
    codec: String,
    /// JPEG quality (1-100).
    #[arg(long = "jpeg-quality", value_name = "Q", default_value_t = 85)]
    jpeg_quality: u8,
    /// H.264 target bit rate (Mbit/s).
    #[arg(long, value_name = "MBIT_S", default_value_t = 2.0)]
    bitrate: f64,
    /// Seconds between periodic H.264 IDR frames.
    #[arg(long = "keyframe-interval", value_name = "S", default_value_t = 2.0)]
    keyframe_interval: f64,
    /// Stop after this many seconds (default: until killed).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// Write the site's report (JSON) here when it stops.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Folder searched for package://NAME/... URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
    #[command(flatten)]
    net: crate::net::NetArgs,
    #[command(flatten)]
    overrides: crate::cli::overrides::EraseOverrides,
}

impl ServeArgs {
    /// Runs `avatarm serve`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            scene,
            robot,
            webcam,
            camera_recording,
            ros2_camera,
            ros2_publish,
            mut listen,
            connect,
            mode,
            target_timeout,
            video,
            codec,
            jpeg_quality,
            bitrate,
            keyframe_interval,
            duration,
            report,
            package_path,
            net,
            view,
            overrides,
        } = self;
        if camera_recording.is_some() && robot != "sim" {
            return Err(AppError::flag(
                "--robot",
                "with --camera-recording the robot is the recording's; leave --robot out",
            ));
        }
        let camera = crate::net::site_camera::SiteCamera::of(
            webcam,
            camera_recording,
            ros2_camera,
            overrides.believed_pose.is_some(),
        );
        crate::log::init_log();
        let path = scene.unwrap_or_else(pouring_scene);
        let packages = packages(package_path);
        let load = |view: Option<&str>| -> Result<Scene, AppError> {
            let mut scene = Scene::load_view(&path, &packages, view)?;
            overrides.apply(&mut scene)?;
            Ok(scene)
        };
        let scene = load(view.first().map(String::as_str))?;
        // Every camera of the scene unless named.
        let more: Vec<String> = if view.is_empty() {
            scene.cameras.iter().skip(1).cloned().collect()
        } else {
            view[1..].to_vec()
        };
        let more_views = more
            .iter()
            .map(|name| load(Some(name)))
            .collect::<Result<Vec<_>, _>>()?;
        let encoder = crate::net::encoder_settings(
            &codec,
            jpeg_quality,
            bitrate,
            keyframe_interval,
            scene.file.camera.fps,
        )?;
        let robot = crate::teleop::robot_choice(&robot, &scene)?;
        let options = crate::net::serve::ServeOptions {
            net: {
                if listen.is_empty() && connect.is_empty() {
                    listen.push("tcp/0.0.0.0:7447".to_owned());
                }
                net.config(avatarm_net::Role::RobotSite, listen, connect)?
            },
            scene,
            more_views,
            robot,
            mode,
            duration_s: duration,
            report,
            video: video.unwrap_or(true),
            target_timeout_s: target_timeout,
            encoder,
            camera,
            ros2_publish,
        };
        let r = crate::net::serve::serve(&options)?;
        println!("{}", crate::net::serve::summary(&r));
        Ok(())
    }
}
