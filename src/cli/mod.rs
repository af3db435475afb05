//! The `avatarm` command line: the clap types, the scene overrides ([`overrides`]), the
//! `avatarm robot` check ([`robot`]) and the dispatch to the app, the replay and the benches.
//!
//! - [`overrides`]: `--erase`, `--dilate`, ... applied to a loaded scene.
//! - [`robot`]: `avatarm robot`: a description's tree, meshes and link poses.

pub mod overrides;
pub mod robot;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::teleop::hand::Handedness;
use avatarm_scene::hand::HandChoice;
use avatarm_scene::spec::{BackgroundSpec, LeapMountKind};
use avatarm_scene::{Scene, SceneError};
use clap::{Parser, Subcommand};

use crate::bench::control::{self as bench_control, ControlSweep};
use crate::bench::dr::{self as bench_dr, DrSweep};
use crate::bench::gpu::{self as bench_gpu, GpuSweep};
use crate::bench::twin::{self as bench_twin, TwinSweep, TwinVariant};
use crate::preview::PreviewOptions;
use crate::replay::ReplayOptions;
use crate::{AppError, Mode, build_app};
use overrides::{EraseOverrides, on_off};

/// Avatarm: manipulate real objects through a robot arm hidden from view.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Check a robot description: joint/link tree, limits, meshes, link poses at q.
    Robot {
        /// The URDF file.
        urdf: PathBuf,
        /// Folder searched for package://NAME/... URIs (repeatable; ROS_PACKAGE_PATH is added).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
        /// Joint values: v1,v2,... in the printed q order, or name=value,... (others are 0).
        #[arg(long, value_name = "Q", allow_hyphen_values = true)]
        q: Option<String>,
        /// Print link poses at q as JSON instead of the tree.
        #[arg(long)]
        json: bool,
    },
    /// Convert a real Leap Motion recording (leapjs-playback JSON, Leap's protocol v6, .json or
    /// .json.gz) to a .hand.jsonl of Avatarm's 26-joint skeleton, and picture one frame; or a
    /// folder of camera frames, or a ROS 1 bag, to a recording (MCAP).
    Import {
        /// The Leap recording, a folder of camera frames with the robot's joints (a listing
        /// frames.csv or frames.json, or EasyHeC's color/ qpos/ mask/ K.txt), or a ROS 1 bag
        /// (.bag: Image or CompressedImage, CameraInfo, JointState, /tf; docs/real-footage.md).
        recording: PathBuf,
        /// The .hand.jsonl to write (a Leap recording), or the .mcap (frames or a bag).
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Frames: the listing, when not frames.csv or frames.json in the folder.
        #[arg(long, value_name = "FILE")]
        listing: Option<PathBuf>,
        /// Frames: the camera file (ROS camera_info or OpenCV YAML, or a 3x3 K), when not
        /// camera_info.yaml, camera.yaml or K.txt in the folder.
        #[arg(long, value_name = "FILE")]
        camera: Option<PathBuf>,
        /// Frames: the camera's pose, under camera_from_base or base_from_camera (a 4x4 matrix,
        /// translation with quaternion_xyzw / quaternion_wxyz / rotation_vector), when not
        /// pose.yaml or pose.json in the folder.
        #[arg(long, value_name = "FILE")]
        pose: Option<PathBuf>,
        /// Frames: names of joints given in q order (comma-separated).
        #[arg(long = "joint-names", value_name = "NAMES", value_delimiter = ',')]
        joint_names: Vec<String>,
        /// Frames: a description naming joints given in q order (its movable joints).
        #[arg(long, value_name = "URDF")]
        urdf: Option<PathBuf>,
        /// Frames: folder searched for package://NAME/... URIs of --urdf (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
        /// Frames: frames per second where the source has no stamps (EasyHeC).
        #[arg(long, value_name = "FPS", default_value_t = 30.0)]
        fps: f64,
        /// Bag: the camera frames' topic (Image or CompressedImage), when the bag has several.
        #[arg(long = "image-topic", value_name = "TOPIC")]
        image_topic: Option<String>,
        /// Bag: a topic of the robot's reference silhouettes (Image or CompressedImage, non-zero
        /// = robot), stamped as the frames they belong to.
        #[arg(long = "mask-topic", value_name = "TOPIC")]
        mask_topic: Option<String>,
        /// Bag: the CameraInfo topic, when the bag has several.
        #[arg(long = "camera-info-topic", value_name = "TOPIC")]
        camera_info_topic: Option<String>,
        /// Bag: the JointState topic, when the bag has several.
        #[arg(long = "joint-states-topic", value_name = "TOPIC")]
        joint_states_topic: Option<String>,
        /// Bag: the robot's base frame in /tf; the camera's pose is chained from it to the
        /// CameraInfo's (optical) frame.
        #[arg(long = "base-frame", value_name = "FRAME")]
        base_frame: Option<String>,
        /// Which hand (default: the first the recording shows).
        #[arg(long, value_parser = ["left", "right"])]
        hand: Option<String>,
        /// How the device was mounted: desk (lying face up) or head (on a headset, facing
        /// ahead); the operator faces the scene's +x.
        #[arg(long, value_parser = ["desk", "head"], default_value = "desk")]
        mount: String,
        /// Where the Leap device sits in the scene (m).
        #[arg(long = "device-at", value_name = "X,Y,Z", value_delimiter = ',', num_args = 3,
              allow_hyphen_values = true, default_values_t = [0.0, 0.0, 0.0])]
        device_at: Vec<f64>,
        /// Draw one frame's skeleton over the recorded joints (PNG, and an SVG beside it).
        #[arg(long, value_name = "PNG")]
        picture: Option<PathBuf>,
        /// The frame to draw (index among the hand's frames).
        #[arg(long, value_name = "N", default_value_t = 0)]
        frame: usize,
    },
    /// Open the desktop preview of a scene (default: assets/scenes/default.toml).
    #[command(after_help = crate::preview::keys::help())]
    Run {
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
        #[arg(long, value_name = "N")]
        webcam: Option<u32>,
        /// With a scene that has a [task]: teleoperate it live with this hand: scripted (the
        /// task's trial, default), desktop (keys and mouse), xr (OpenXR hand tracking, with
        /// --xr), leap (feature `leap`), a recorded FILE.hand.jsonl, or none.
        #[arg(long, value_name = "SOURCE")]
        hand: Option<String>,
        /// How the Leap (live or recorded) is mounted: desk, head or first_wrist (the scene's
        /// [leap] mount otherwise; docs/hand.md).
        #[arg(long = "leap-mount", value_name = "MOUNT", value_parser = leap_mount)]
        leap_mount: Option<LeapMountKind>,
        /// The robot the live task commands: sim (the simulated arm) or ros (the real robot
        /// through the scene's [robot.link], ROS 1; docs/robot-ros.md).
        #[arg(long, value_name = "ROBOT", value_parser = ["sim", "ros"], default_value = "sim")]
        robot: String,
        /// Record the session (MCAP, Foxglove's schemas): camera frames, calibration and pose,
        /// joint states, Avatarm's erased frames and masks, the hand, the robot's commands and
        /// safety events (docs/real-footage.md).
        #[arg(long, value_name = "FILE.mcap")]
        record: Option<PathBuf>,
        #[command(flatten)]
        overrides: EraseOverrides,
    },
    /// Replay a scene without a window: frames, ground truth and report.json in --out. With
    /// --recording: a recorded session (MCAP) through the erase instead (docs/real-footage.md).
    Replay {
        /// The scene file (not with --recording).
        #[arg(required_unless_present = "recording", conflicts_with = "recording")]
        scene: Option<PathBuf>,
        /// A recording (MCAP, `avatarm import` writes one): its frames and joint states through
        /// the erase, with the robot's --urdf.
        #[arg(long, value_name = "FILE.mcap", requires = "urdf")]
        recording: Option<PathBuf>,
        /// With --recording: the robot's description.
        #[arg(long, value_name = "URDF")]
        urdf: Option<PathBuf>,
        /// With --recording: a camera file instead of the recording's calibration (ROS
        /// camera_info or OpenCV YAML, or a 3x3 K).
        #[arg(long, value_name = "FILE")]
        camera: Option<PathBuf>,
        /// With --recording: a pose file instead of the recording's camera pose (under
        /// camera_from_base or base_from_camera).
        #[arg(long, value_name = "FILE")]
        pose: Option<PathBuf>,
        /// With --recording and no --background: pixels this far beyond a frame's mask are not
        /// used for the background built from the footage (px).
        #[arg(long = "background-margin", value_name = "PX", default_value_t = 8)]
        background_margin: u32,
        /// With --recording of a camera on a head (Alice's): the scene file of its room, whose
        /// boxes that are not objects (desk, wall, floor) are the proxy that a view-following
        /// background re-projects the frames' views through, so that H follows the head (the
        /// footage's median is then only the fallback where no view saw a pixel).
        #[arg(long, value_name = "SCENE", requires = "recording")]
        room: Option<PathBuf>,
        /// With a scene: replay only its camera NAME (one of its [[cameras]]; default: each
        /// camera in turn, into DIR/NAME/).
        #[arg(long, value_name = "NAME", conflicts_with = "recording")]
        view: Option<String>,
        /// With a scene: also write the replay as a recording (MCAP): the frames, the robot's
        /// joints at each capture, the believed camera, the true silhouettes as reference
        /// masks, Avatarm's erased frames and masks.
        #[arg(long, value_name = "FILE.mcap", conflicts_with = "recording")]
        record: Option<PathBuf>,
        /// Run without a window (replays are always headless; accepted for clarity).
        #[arg(long)]
        headless: bool,
        /// Output folder.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Save every N-th camera frame.
        #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        frames_every: u32,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
        #[command(flatten)]
        overrides: EraseOverrides,
    },
    /// Fit the camera's pose to the robot itself: the pose (and with --intrinsics fx, fy) that
    /// puts the robot's silhouette at the recorded joints on the recording's reference masks
    /// (or with --background on each frame's difference from an empty room, with --edges on
    /// each frame's own image edges); writes DIR/camera_pose.yaml (a head camera's
    /// DIR/camera_mount.yaml), before/after overlays and report.json (docs/real-footage.md).
    Calibrate {
        /// The recording (MCAP): frames, joint states, and the robot's reference masks if any.
        #[arg(long, value_name = "FILE.mcap")]
        recording: PathBuf,
        /// The robot's description.
        #[arg(long, value_name = "URDF")]
        urdf: PathBuf,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
        /// A camera file instead of the recording's calibration.
        #[arg(long, value_name = "FILE")]
        camera: Option<PathBuf>,
        /// The rough pose (under camera_from_base or base_from_camera), else the recording's.
        #[arg(long, value_name = "FILE", conflicts_with = "look_at")]
        pose: Option<PathBuf>,
        /// A recording of a camera on a head: the rough mount (under head_from_camera or
        /// camera_from_head), else the recording's; the fit is then of the mount.
        #[arg(long, value_name = "FILE", conflicts_with_all = ["pose", "look_at"])]
        mount: Option<PathBuf>,
        /// The rough pose as the camera's eye and a point it looks at, in the base frame (m):
        /// EX,EY,EZ,TX,TY,TZ.
        #[arg(
            long = "look-at",
            value_name = "EX,EY,EZ,TX,TY,TZ",
            value_delimiter = ',',
            allow_negative_numbers = true
        )]
        look_at: Option<Vec<f64>>,
        /// The frames the fit uses: FIRST-LAST ranges or single indices, comma-separated (indices
        /// in the recording, e.g. 0-4 or 0,1,5; the others are held out and only measured).
        /// Default: every frame with a silhouette (a reference mask, or with --background or
        /// --edges every frame).
        #[arg(long, value_name = "FRAMES", value_parser = frame_range, value_delimiter = ',')]
        fit: Vec<(usize, usize)>,
        /// Use only every N-th frame with a silhouette (long recordings).
        #[arg(long, value_name = "N", default_value_t = 1)]
        every: usize,
        /// Also fit the focal lengths fx and fy.
        #[arg(long)]
        intrinsics: bool,
        /// Triangles the robot's silhouette is drawn with (its meshes simplified to about this).
        #[arg(long, value_name = "N", default_value_t = 6000)]
        triangles: usize,
        /// The robot's geometry below this height in its base frame (m) is hidden by the table
        /// it stands on and left out of its silhouette (e.g. 0 for a mounting plate sunk in the
        /// desk).
        #[arg(long = "hidden-below", value_name = "Z", allow_negative_numbers = true)]
        hidden_below: Option<f64>,
        /// An empty-room photograph of the same camera (no robot): the robot's silhouettes
        /// are each frame's difference from it, instead of the recording's reference masks.
        #[arg(long, value_name = "IMAGE")]
        background: Option<PathBuf>,
        /// With --background: the difference (8-bit levels, any channel) that counts as the
        /// robot.
        #[arg(
            long = "background-threshold",
            value_name = "LEVELS",
            default_value_t = 30
        )]
        background_threshold: u8,
        /// Fit to each frame's own image edges (Canny's) instead of silhouettes: no reference
        /// masks or empty-room photograph needed (a moving camera's footage). Reference masks,
        /// where the recording has them, only score the fit.
        #[arg(long, conflicts_with = "background")]
        edges: bool,
        /// With --edges: Canny's LOW,HIGH thresholds on the Sobel gradient's magnitude of the
        /// blurred luma (imageproc's scale: a clean step of N 8-bit levels gives about 2N to
        /// 4N; at most 1141). Each frame's edge map is written to `edges_NNNNN.png`
        /// and drawn in yellow on the overlays, to tune them by eye.
        #[arg(
            long = "edge-thresholds",
            requires = "edges",
            value_name = "LOW,HIGH",
            value_delimiter = ',',
            default_value = "20,60"
        )]
        edge_thresholds: Vec<f32>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/calibrate")]
        out: PathBuf,
    },
    /// The robot site of a two-site session (Alice's desk, docs/network.md): the robot, the
    /// camera, the erase and the robot's side of the mapping, over Zenoh. Needs a scene with a
    /// [task] (default: the pouring scene).
    Serve {
        /// The scene file.
        scene: Option<PathBuf>,
        /// Serve the scene's cameras NAME,... (of its [[cameras]]; repeatable; default: every
        /// one), each erased by an app of its own and published under its name.
        #[arg(long, value_name = "NAME", value_delimiter = ',')]
        view: Vec<String>,
        /// The robot: sim (the simulated arm) or ros (the scene's [robot.link], ROS 1).
        #[arg(long, value_name = "ROBOT", value_parser = ["sim", "ros"], default_value = "sim")]
        robot: String,
        /// Where to listen (tcp/HOST:PORT, udp/HOST:PORT or tls/HOST:PORT; default
        /// tcp/0.0.0.0:7447 unless --connect is given).
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
    },
    /// The operator's site of a two-site session (Blair, docs/network.md): the hand, the
    /// physics twin and the operator's side of the mapping, sending targets to ENDPOINT; or,
    /// with --watch, an observer.
    Join {
        /// The robot site (or a router): tcp/HOST:PORT, udp/HOST:PORT or tls/HOST:PORT.
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
    },
    /// A Zenoh router between the sites (docs/network.md): fans the robot site's video out to
    /// many observers so the robot site sends each stream once.
    Router {
        /// Where to listen.
        #[arg(long, value_name = "ENDPOINT", default_value = "tcp/0.0.0.0:7448")]
        listen: Vec<String>,
        /// Robot sites or other routers to connect to (on a trusted network, --insecure-lan;
        /// with a dictionary the robot site connects to the router instead).
        #[arg(long, value_name = "ENDPOINT")]
        connect: Vec<String>,
        /// Stop after this many seconds (default: until killed).
        #[arg(long, value_name = "S")]
        duration: Option<f64>,
        #[command(flatten)]
        net: crate::net::NetArgs,
    },
    /// The seeded impairment relay between two sites (docs/network.md): TCP or UDP from
    /// 127.0.0.1:PORT to TO, with one-way delay, jitter, loss (UDP) and a bandwidth cap, for
    /// trying a session under a bad network where `tc netem` is not available.
    Relay {
        /// tcp or udp.
        #[arg(long, value_parser = ["tcp", "udp"], default_value = "tcp")]
        transport: String,
        /// Where the traffic goes (HOST:PORT).
        #[arg(long, value_name = "HOST:PORT")]
        to: std::net::SocketAddr,
        /// One-way delay each direction (ms).
        #[arg(long = "delay-ms", default_value_t = 0.0)]
        delay_ms: f64,
        /// Extra delay uniform in 0..JITTER (ms).
        #[arg(long = "jitter-ms", default_value_t = 0.0)]
        jitter_ms: f64,
        /// Datagrams dropped (%, UDP).
        #[arg(long = "loss", default_value_t = 0.0)]
        loss_pct: f64,
        /// Bandwidth cap each direction (Mbit/s).
        #[arg(long = "mbit-s")]
        mbit_s: Option<f64>,
        /// Seed of the loss and jitter.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// TCP: what each direction holds at most (KiB, at least 64): delayed, queued behind
        /// the cap or held through a cut; when full the sender is pushed back.
        #[arg(long = "queue-kib", default_value_t = 4096)]
        queue_kib: usize,
        /// Stop after this many seconds (default: until killed).
        #[arg(long, value_name = "S")]
        duration: Option<f64>,
    },
    /// Measure speed against accuracy and chart it.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Erase from a camera on a moving head (default scene: head_camera, Alice's headset
    /// camera): leak against the head's peak angular speed for each tracking latency, with and
    /// without pose compensation, and against an error in the camera's mount:
    /// DIR/head_erase.{svg,png,csv}.
    Head {
        /// The scene file (needs [camera.head] with a sweep).
        scene: Option<PathBuf>,
        /// The scene's camera NAME (one of its [[cameras]]; default: its first camera on a
        /// head).
        #[arg(long, value_name = "NAME")]
        view: Option<String>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_head")]
        out: PathBuf,
        /// The head's peak angular speeds (degrees/s).
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 15.0, 30.0, 60.0])]
        speeds: Vec<f64>,
        /// Head tracking latencies (ms).
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 20.0, 50.0, 100.0])]
        latencies: Vec<f64>,
        /// Pose compensation settings (off, on).
        #[arg(long, value_delimiter = ',', value_parser = on_off, default_values_t = [false, true])]
        compensation: Vec<bool>,
        /// Errors put into the camera's mount (degrees of yaw), compensated, at --mount-speed
        /// and --mount-latency; the flag with no value for none.
        #[arg(long, value_delimiter = ',', num_args = 0.., default_values_t = [0.0, 0.5, 1.0, 2.0])]
        mount_errors: Vec<f64>,
        /// The head's speed for the mount series (degrees/s).
        #[arg(long, value_name = "DEG_S", default_value_t = 30.0)]
        mount_speed: f64,
        /// The tracking latency for the mount series (ms).
        #[arg(long, value_name = "MS", default_value_t = 20.0)]
        mount_latency: f64,
        /// Background views kept, one point each at --mount-speed and --mount-latency: 0 (the
        /// empty room's photograph as it is), 1 (re-projected into each view), more (with views
        /// from the frames); the flag with no value for none.
        #[arg(long, value_delimiter = ',', num_args = 0.., default_values_t = [0, 1, 8])]
        background_views: Vec<usize>,
        /// Simulated seconds replayed per point.
        #[arg(long, value_name = "S", default_value_t = 2.0)]
        duration: f64,
        /// Run the scene's camera at WIDTHxHEIGHT pixels (its field of view kept).
        #[arg(long = "camera-size", value_name = "WxH", value_parser = frame_size)]
        camera_size: Option<(u32, u32)>,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// Sweep the erase pipeline's settings on a scene (default: the default scene, whose arm
    /// reaches, lifts and pours: the pouring scene's arm rests during its video) and chart
    /// frame cost against leak and PSNR: DIR/dr_speed_accuracy.{svg,png,csv}.
    Dr {
        /// The scene file.
        scene: Option<PathBuf>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_dr")]
        out: PathBuf,
        /// Mask resolution scales.
        #[arg(long, value_delimiter = ',', default_values_t = [1.0, 0.5, 0.25])]
        scales: Vec<f64>,
        /// Dilations (px).
        #[arg(long, value_delimiter = ',', default_values_t = [0, 4])]
        dilate: Vec<u32>,
        /// Feathering widths (px).
        #[arg(long, value_delimiter = ',', default_values_t = [0, 2])]
        feather: Vec<u32>,
        /// Latency compensation settings (off, on).
        #[arg(long, value_delimiter = ',', value_parser = on_off, default_values_t = [false, true])]
        latency: Vec<bool>,
        /// Simulated seconds replayed per setting.
        #[arg(long, value_name = "S", default_value_t = 1.5)]
        duration: f64,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// Measure how much twin the mask needs on a scene (default: sawyer_real, the real Sawyer):
    /// each mask twin (visual meshes, collision geometry, meshes simplified, a primitive
    /// description) with the arm retimed to the TCP speed cap; chart mask GPU time against leak
    /// and the dilation for leak <= 1 %: DIR/twin_detail.{svg,png,csv}.
    Twin {
        /// The scene file.
        scene: Option<PathBuf>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_twin")]
        out: PathBuf,
        /// The twins: visual, collision, keep:FRACTION, urdf:PATH (default: visual, collision,
        /// keep:0.5, keep:0.1, keep:0.02, and the bundled sawyer_lite for a Sawyer).
        #[arg(long, value_delimiter = ',', value_name = "TWIN")]
        variants: Vec<String>,
        /// Simulated seconds replayed per twin.
        #[arg(long, value_name = "S", default_value_t = 2.0)]
        duration: f64,
        /// TCP speed the arm's timeline is retimed to, m/s (the paper's cap).
        #[arg(long = "tcp-speed", value_name = "M_PER_S", default_value_t = 0.25)]
        tcp_speed: f64,
        /// Score every N-th camera frame for the dilation analysis.
        #[arg(long = "frames-every", value_name = "N", default_value_t = 2)]
        frames_every: u32,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// Time the erase on the GPU, pass by pass, at several frame sizes and for one or several
    /// cameras, beside a plain copy of the same images measured in the same run (the floor):
    /// DIR/gpu_erase.{csv,svg,png}. The scene (default: the default scene) gives the robot,
    /// the camera's pose and field of view, and the erase settings.
    Gpu {
        /// The scene file.
        scene: Option<PathBuf>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_gpu")]
        out: PathBuf,
        /// Frame sizes, WIDTHxHEIGHT.
        #[arg(long, value_delimiter = ',', value_parser = frame_size, default_values = ["640x480", "1280x720", "1920x1080"])]
        sizes: Vec<(u32, u32)>,
        /// Cameras erased per update.
        #[arg(long, value_delimiter = ',', default_values_t = [1, 2])]
        cameras: Vec<u32>,
        /// Updates timed per point (after a warm-up).
        #[arg(long, value_name = "N", default_value_t = 120)]
        frames: u32,
        /// Dilation of the mask (px).
        #[arg(long, value_name = "PX", default_value_t = 0)]
        dilate: u32,
        /// Feathering (px).
        #[arg(long, value_name = "PX", default_value_t = 0)]
        feather: u32,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// Sweep the teleoperation loop on a scene's pouring task (default: the pouring scene):
    /// control rate x simulated command latency x TCP speed cap, both mapping modes, and chart
    /// object position RMSE against rate and loop cost: DIR/control_speed_accuracy.{svg,png,csv}.
    Control {
        /// The scene file (needs a [task]).
        scene: Option<PathBuf>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_control")]
        out: PathBuf,
        /// Control (and physics) rates, Hz.
        #[arg(long, value_delimiter = ',', default_values_t = [50.0, 100.0, 200.0])]
        rates: Vec<f64>,
        /// Simulated command latencies, ms.
        #[arg(long = "latency-ms", value_delimiter = ',', default_values_t = [0.0, 20.0, 50.0])]
        latency_ms: Vec<f64>,
        /// TCP speed caps, m/s.
        #[arg(long, value_delimiter = ',', default_values_t = [0.1, 0.25, 0.5])]
        caps: Vec<f64>,
        /// Trials per setting and mode.
        #[arg(long, value_name = "N", default_value_t = 3)]
        trials: u32,
        /// Folder searched for package:// URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// The pouring task across two sites (robot site and operator in this process, over Zenoh
    /// through the seeded impairment relay; docs/network.md): object RMSE against one-way
    /// delay and loss, both mapping modes, with the paper's RMSE as a line. CSV, SVG, PNG.
    Network {
        /// The scene (default: the pouring scene).
        scene: Option<PathBuf>,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_network")]
        out: PathBuf,
        /// One-way delays (ms).
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 25.0, 50.0, 100.0, 200.0])]
        delays: Vec<f64>,
        /// Datagram loss (%): 0 runs over TCP, more over UDP.
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 1.0, 5.0])]
        losses: Vec<f64>,
        /// Mapping modes (paper, closed_loop).
        #[arg(long, value_delimiter = ',', value_parser = mapping_mode, default_values = ["paper", "closed_loop"])]
        modes: Vec<avatarm_core::teleop::mapping::MappingMode>,
        /// Trials per point (the task's seeded hands).
        #[arg(long, value_name = "N", default_value_t = 10)]
        trials: u32,
        /// The robot site's watchdog timeout (s).
        #[arg(long = "target-timeout", value_name = "S", default_value_t = 0.5)]
        target_timeout: f64,
        /// Folder searched for package://NAME/... URIs (repeatable).
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
    },
    /// The erased video's codecs (docs/network.md): a recording's erased frames (`avatarm
    /// replay SCENE --record`) coded with JPEG and H.264 at each frame size; PSNR after
    /// coding against bit rate, encode and decode time, as ratios against JPEG at quality 85.
    /// CSV, SVG, PNG.
    Video {
        /// The recording (MCAP): its erased frames, else its camera frames.
        #[arg(long, value_name = "FILE.mcap")]
        recording: PathBuf,
        /// Output folder.
        #[arg(long, value_name = "DIR", default_value = "out/bench_video")]
        out: PathBuf,
        /// Frame sizes, WIDTHxHEIGHT (the frames are cropped to each aspect and scaled).
        #[arg(long, value_delimiter = ',', value_parser = frame_size, default_values = ["640x480", "1280x720"])]
        sizes: Vec<(u32, u32)>,
        /// JPEG qualities.
        #[arg(long, value_delimiter = ',', default_values_t = [50u8, 70, 85, 95])]
        jpeg: Vec<u8>,
        /// H.264 target bit rates (Mbit/s).
        #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 2.0, 4.0, 8.0])]
        h264: Vec<f64>,
        /// The camera's frame rate (Hz).
        #[arg(long, value_name = "HZ", default_value_t = 30.0)]
        fps: f64,
        /// Seconds between H.264 IDR frames.
        #[arg(long = "keyframe-interval", value_name = "S", default_value_t = 2.0)]
        keyframe_interval: f64,
        /// Frames coded (the recording's first; looped when it has fewer).
        #[arg(long, value_name = "N", default_value_t = 90)]
        frames: usize,
    },
}

fn packages(dirs: Vec<PathBuf>) -> PackagePath {
    let mut p = PackagePath(dirs);
    if let Ok(env) = std::env::var("ROS_PACKAGE_PATH") {
        p.extend_from_env_list(&env);
    }
    p
}

/// A file shipped in `assets/FOLDER` (`scenes`, `robots`): from the working folder when run
/// from the repository, else from the source tree this binary was built from.
fn bundled(folder: &str, file: &str) -> PathBuf {
    let local = Path::new("assets").join(folder).join(file);
    if local.is_file() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets")
            .join(folder)
            .join(file)
    }
}

fn bundled_scene(file: &str) -> PathBuf {
    bundled("scenes", file)
}

fn leap_mount(text: &str) -> Result<LeapMountKind, String> {
    text.parse()
}

fn mapping_mode(s: &str) -> Result<avatarm_core::teleop::mapping::MappingMode, String> {
    match s {
        "paper" => Ok(avatarm_core::teleop::mapping::MappingMode::Paper),
        "closed_loop" => Ok(avatarm_core::teleop::mapping::MappingMode::ClosedLoop),
        other => Err(format!("'{other}' is not paper or closed_loop")),
    }
}

fn default_scene() -> PathBuf {
    bundled_scene("default.toml")
}

fn pouring_scene() -> PathBuf {
    bundled_scene("pouring.toml")
}

/// The live hand for `avatarm run`: `--hand`, else the scene's `hand`, else the scripted hand
/// when the scene has a `[task]`; errors name the flag.
fn live_hand(scene: &Scene, flag: Option<&str>, xr: bool) -> Result<Option<HandChoice>, AppError> {
    let (text, from) = match (flag, &scene.file.hand) {
        (Some(f), _) => (f.to_owned(), "--hand"),
        (None, Some(h)) => (h.clone(), "hand (scene)"),
        (None, None) if scene.file.task.is_some() => ("scripted".to_owned(), "[task]"),
        (None, None) => return Ok(None),
    };
    if text == "none" {
        return Ok(None);
    }
    let refuse = |message: String| AppError::flag(from, message);
    let choice: HandChoice = text.parse().map_err(|e| match e {
        SceneError::Field { message, .. } => refuse(message),
        other => refuse(other.to_string()),
    })?;
    if scene.file.task.is_none() {
        return Err(refuse(format!(
            "the scene '{}' has no [task] to teleoperate (try assets/scenes/pouring.toml)",
            scene.file.name
        )));
    }
    match &choice {
        HandChoice::Xr if !xr => Err(refuse("xr needs XR mode (--xr)".into())),
        HandChoice::Xr if !cfg!(feature = "xr") => Err(refuse(
            "this avatarm was built without the xr feature (it is on by default)".into(),
        )),
        HandChoice::Leap if !cfg!(feature = "leap") => Err(refuse(
            "this avatarm was built without the leap feature; rebuild with `cargo build \
             --features leap` (needs the Ultraleap SDK, docs/hardware.md)"
                .into(),
        )),
        HandChoice::File(path) | HandChoice::LeapRecording { path, .. } if !path.is_file() => {
            Err(refuse(format!("{} does not exist", path.display())))
        }
        _ => Ok(Some(choice)),
    }
}

/// Parses the command line and runs it; errors are printed and give exit code 1.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<(), AppError> {
    match cli.command {
        Command::Serve {
            scene,
            robot,
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
        } => {
            crate::net::init_log();
            let path = scene.unwrap_or_else(pouring_scene);
            let packages = packages(package_path);
            let scene = Scene::load_view(&path, &packages, view.first().map(String::as_str))?;
            // Every camera of the scene unless named.
            let more: Vec<String> = if view.is_empty() {
                scene.cameras.iter().skip(1).cloned().collect()
            } else {
                view[1..].to_vec()
            };
            let more_views = more
                .iter()
                .map(|name| Scene::load_view(&path, &packages, Some(name)))
                .collect::<Result<Vec<_>, _>>()?;
            let encoder = crate::net::encoder_settings(
                &codec,
                jpeg_quality,
                bitrate,
                keyframe_interval,
                scene.file.camera.fps,
            )?;
            let options = crate::net::serve::ServeOptions {
                net: {
                    if listen.is_empty() && connect.is_empty() {
                        listen.push("tcp/0.0.0.0:7447".to_owned());
                    }
                    net.config(avatarm_net::Role::RobotSite, listen, connect)?
                },
                scene,
                more_views,
                robot: if robot == "ros" {
                    crate::teleop::RobotChoice::Ros
                } else {
                    crate::teleop::RobotChoice::Sim
                },
                mode,
                duration_s: duration,
                report,
                video: video.unwrap_or(true),
                target_timeout_s: target_timeout,
                encoder,
            };
            let r = crate::net::serve::serve(&options)?;
            println!("{}", crate::net::serve::summary(&r));
            Ok(())
        }
        Command::Join {
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
        } => {
            crate::net::init_log();
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
        Command::Relay {
            transport,
            to,
            delay_ms,
            jitter_ms,
            loss_pct,
            mbit_s,
            seed,
            queue_kib,
            duration,
        } => {
            use avatarm_net::impair::{Impairment, Relay};
            let queue_bytes = queue_kib.checked_mul(1024).ok_or_else(|| {
                AppError::flag("--queue-kib", format!("{queue_kib} KiB is too large"))
            })?;
            let impairment = Impairment {
                delay_s: delay_ms / 1e3,
                jitter_s: jitter_ms / 1e3,
                loss: loss_pct / 100.0,
                bandwidth_bps: mbit_s.map(|m| m * 1e6),
                seed,
                queue_bytes,
            };
            impairment
                .validate()
                .map_err(|e| AppError::flag("avatarm relay", e))?;
            let relay = if transport == "udp" {
                Relay::udp(to, impairment)
            } else {
                Relay::tcp(to, impairment)
            }
            .map_err(|e| AppError::flag("avatarm relay", e.to_string()))?;
            println!("{transport}/{} -> {to}", relay.local_addr());
            let started = std::time::Instant::now();
            while duration.is_none_or(|d| started.elapsed().as_secs_f64() < d) {
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            Ok(())
        }
        Command::Router {
            listen,
            connect,
            duration,
            net,
        } => {
            crate::net::init_log();
            let config = net.config(avatarm_net::Role::Router, listen, connect)?;
            crate::net::router(&config, duration)
        }
        Command::Robot {
            urdf,
            package_path,
            q,
            json,
        } => {
            let model = RobotModel::from_urdf_file(&urdf, &packages(package_path))?;
            let meshes = robot::check_meshes(&model)?;
            let q = model
                .parse_q(q.as_deref().unwrap_or(""))
                .map_err(|e| AppError::flag("--q", e.to_string()))?;
            let q: Vec<f64> = q.iter().copied().collect();
            if json {
                let text = serde_json::to_string_pretty(&robot::poses_json(&model, &q))?;
                println!("{text}");
            } else {
                print!("{}", robot::tree_text(&model, &meshes));
                print!("{}", robot::mesh_text(&model, &meshes));
            }
            Ok(())
        }
        Command::Import {
            recording,
            out,
            camera,
            pose,
            image_topic,
            mask_topic,
            camera_info_topic,
            joint_states_topic,
            base_frame,
            ..
        } if recording
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("bag")) =>
        {
            let s = crate::bag::import_bag(&crate::bag::BagOptions {
                bag: recording,
                out: out.clone(),
                image_topic,
                mask_topic,
                camera_info_topic,
                joint_states_topic,
                base_frame,
                camera,
                pose,
            })?;
            for (topic, kind, n) in &s.topics {
                println!("  {topic} ({kind}): {n} messages");
            }
            for note in &s.notes {
                eprintln!("note: {note}");
            }
            println!(
                "wrote {} (ROS bag): {} frames {}x{} over {:.2} s, {} reference masks, {} joint states of {}, camera pose {}",
                out.display(),
                s.frames,
                s.size.0,
                s.size.1,
                s.duration_s,
                s.masks,
                s.joint_states,
                s.joints.join(", "),
                s.pose
            );
            Ok(())
        }
        Command::Import {
            recording,
            out,
            listing,
            camera,
            pose,
            joint_names,
            urdf,
            package_path,
            fps,
            ..
        } if recording.is_dir() => {
            let summary = crate::footage::import_footage(&crate::footage::FootageOptions {
                folder: recording,
                out: out.clone(),
                listing,
                camera,
                pose,
                joint_names,
                urdf,
                packages: packages(package_path),
                fps,
            })?;
            println!(
                "wrote {} ({}): {} frames {}x{} over {:.2} s, {} reference masks, joints {}, camera pose {}",
                out.display(),
                summary.layout,
                summary.frames,
                summary.size.0,
                summary.size.1,
                summary.duration_s,
                summary.masks,
                summary.joints.join(", "),
                if summary.pose {
                    "given"
                } else {
                    "not given (avatarm calibrate can find it)"
                }
            );
            Ok(())
        }
        Command::Import {
            recording,
            out,
            hand,
            mount,
            device_at,
            picture,
            frame,
            ..
        } => {
            let options = crate::import::ImportOptions {
                recording,
                out,
                hand: hand.map(|h| {
                    if h == "left" {
                        Handedness::Left
                    } else {
                        Handedness::Right
                    }
                }),
                head_mounted: mount == "head",
                device_at: [device_at[0], device_at[1], device_at[2]],
                picture,
                frame,
            };
            let summary = crate::import::import_leap(&options)?;
            println!(
                "wrote {}: {} frames of the {} hand over {:.2} s",
                options.out.display(),
                summary.frames,
                match summary.hand {
                    Handedness::Left => "left",
                    Handedness::Right => "right",
                },
                summary.duration_s
            );
            if let Some((png, svg)) = summary.picture {
                println!("picture: {}, {}", png.display(), svg.display());
            }
            Ok(())
        }
        Command::Run {
            scene,
            xr,
            frames,
            step_ms,
            screenshot,
            press,
            package_path,
            webcam,
            hand,
            leap_mount,
            robot,
            record,
            overrides,
            view,
        } => {
            if webcam.is_some() && !cfg!(feature = "webcam") {
                return Err(AppError::flag(
                    "--webcam",
                    "this avatarm was built without the webcam feature; rebuild with `cargo \
                     build --features webcam`",
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
            if webcam.is_some() && scene.head.is_some() {
                return Err(AppError::flag(
                    "--webcam",
                    format!(
                        "the scene '{}' has a camera on a head, whose poses only the simulated \
                         head gives yet; use a scene with a fixed camera",
                        scene.file.name
                    ),
                ));
            }
            if webcam.is_some() && scene.file.background == BackgroundSpec::EmptyRoom {
                eprintln!(
                    "webcam: the simulated empty room is no background for it; press B with the \
                     robot out of view to capture one (or pass --background PATH)"
                );
                scene.file.background = BackgroundSpec::None;
            }
            // The C key switches between the scene's cameras in place; a recording and a
            // webcam hold one camera.
            let no_switch = match (&record, webcam) {
                _ if scene.cameras.len() < 2 => None,
                (Some(_), _) => Some(format!(
                    "a recording holds one camera; start again with --view {}",
                    scene.cameras[(scene.camera_index + 1) % scene.cameras.len()]
                )),
                (None, Some(_)) => Some("the webcam is the one camera".to_owned()),
                (None, None) => None,
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
            let robot = if robot == "ros" {
                if hand.is_none() {
                    return Err(AppError::flag(
                        "--robot ros",
                        "commands the robot from a live task: the scene needs a [task] and a hand",
                    ));
                }
                crate::teleop::RobotChoice::Ros
            } else {
                crate::teleop::RobotChoice::Sim
            };
            let mode = Mode::Preview(PreviewOptions {
                frames,
                screenshot,
                xr,
                fixed_step_s: step_ms
                    .map(|ms| ms / 1e3)
                    .or_else(|| frames.map(|_| 0.5 / scene.file.camera.fps)),
                webcam,
                hand,
                robot,
                cameras,
                no_switch,
                press,
            });
            let mut app = build_app(&scene, &mode)?;
            if let Some(path) = &record {
                crate::session::add_session_recorder(&mut app, path, &scene)?;
            }
            let exit = app.run();
            if exit.is_error() {
                return Err(AppError::Preview);
            }
            Ok(())
        }
        Command::Replay {
            recording: Some(recording),
            urdf: Some(urdf),
            camera,
            pose,
            background_margin,
            room,
            out,
            package_path,
            overrides,
            ..
        } => {
            let mut settings = avatarm_core::dr::EraseSettings::default();
            overrides.apply_to_settings(&mut settings)?;
            let report = crate::replay::recording::run_recording(
                &crate::replay::recording::RecordingOptions {
                    recording,
                    urdf,
                    packages: packages(package_path),
                    camera,
                    pose,
                    mount: overrides.believed_mount.clone(),
                    settings,
                    background: overrides.background.clone(),
                    background_margin_px: background_margin,
                    room,
                    out: out.clone(),
                    progress: true,
                },
            )?;
            let vs = &report["mask"]["vs_reference"];
            eprintln!(
                "replayed {}: {} frames of '{}', mask covering {:.1} % of the frame; against {} reference masks: IoU {}, leak {} %; background: {}; report: {}",
                report["recording"].as_str().unwrap_or_default(),
                report["frames"],
                report["robot"].as_str().unwrap_or_default(),
                report["mask"]["coverage_pct_mean"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
                vs["frames_scored"],
                vs["iou_mean"]
                    .as_f64()
                    .map_or("-".into(), |v| format!("{v:.3}")),
                vs["leak_pct_mean"]
                    .as_f64()
                    .map_or("-".into(), |v| format!("{v:.2}")),
                report["background"]["source"].as_str().unwrap_or("none"),
                out.join("report.json").display()
            );
            Ok(())
        }
        Command::Replay {
            scene,
            headless: _,
            out,
            frames_every,
            package_path,
            overrides,
            record,
            view,
            ..
        } => {
            let path =
                scene.ok_or_else(|| AppError::flag("replay", "give a scene or --recording"))?;
            let packages = packages(package_path);
            let mut scene = Scene::load_view(&path, &packages, view.as_deref())?;
            overrides.apply(&mut scene)?;
            let mut options = ReplayOptions::new(out.clone());
            options.frames_every = frames_every;
            options.progress = true;
            options.record = record;
            if view.is_none() && scene.cameras.len() > 1 {
                // Each camera in turn.
                let others = scene.cameras[1..].to_vec();
                let mut scenes = vec![scene];
                for name in others {
                    let mut other = Scene::load_view(&path, &packages, Some(&name))?;
                    overrides.apply(&mut other)?;
                    scenes.push(other);
                }
                let report = crate::replay::run_views(&scenes, options)?;
                for camera in report["cameras"].as_array().into_iter().flatten() {
                    eprintln!(
                        "camera '{}': {} frames, mask IoU {}, leak {} %, PSNR in the robot's region {} dB",
                        camera["name"].as_str().unwrap_or_default(),
                        camera["frames"],
                        camera["mask"]["iou_mean"]
                            .as_f64()
                            .map_or("-".into(), |v| format!("{v:.3}")),
                        camera["mask"]["leak_pct_mean"]
                            .as_f64()
                            .map_or("-".into(), |v| format!("{v:.2}")),
                        camera["dr"]["psnr_robot_db_mean"]
                            .as_f64()
                            .map_or("-".into(), |v| format!("{v:.1}")),
                    );
                }
                eprintln!(
                    "replayed '{}' through {} cameras; report: {}",
                    scenes[0].file.name,
                    scenes.len(),
                    out.join("report.json").display()
                );
                return Ok(());
            }
            let report = crate::replay::run(&scene, options)?;
            eprintln!(
                "replayed '{}': {} frames, {:.2} s simulated in {:.2} s ({:.2} sim s per wall s); report: {}",
                scene.file.name,
                report["frames"],
                report["sim_time_s"].as_f64().unwrap_or(0.0),
                report["wall_time_s"].as_f64().unwrap_or(0.0),
                report["sim_s_per_wall_s"].as_f64().unwrap_or(0.0),
                out.join("report.json").display()
            );
            Ok(())
        }
        Command::Calibrate {
            recording,
            urdf,
            package_path,
            camera,
            pose,
            look_at,
            mount,
            fit,
            every,
            intrinsics,
            triangles,
            hidden_below,
            background,
            background_threshold,
            edges,
            edge_thresholds,
            out,
        } => {
            let edges = match (edges, edge_thresholds.as_slice()) {
                (false, _) => None,
                (true, &[low, high]) => Some((low, high)),
                (true, v) => {
                    return Err(AppError::flag(
                        "--edge-thresholds",
                        format!("{} given: give two numbers, LOW,HIGH", list(v)),
                    ));
                }
            };
            if let Some(z) = hidden_below.filter(|z| !z.is_finite()) {
                return Err(AppError::flag(
                    "--hidden-below",
                    format!("{z} is not a height (m)"),
                ));
            }
            let look_at = match look_at.as_deref() {
                None => None,
                Some(v) if v.iter().any(|x| !x.is_finite()) => {
                    return Err(AppError::flag(
                        "--look-at",
                        format!("{v:?}: every coordinate must be a finite number (m)"),
                    ));
                }
                Some([ex, ey, ez, tx, ty, tz]) => Some(([*ex, *ey, *ez], [*tx, *ty, *tz])),
                Some(v) => {
                    return Err(AppError::flag(
                        "--look-at",
                        format!(
                            "{} given: give six numbers, the eye's x,y,z then the target's",
                            list(v)
                        ),
                    ));
                }
            };
            let report = crate::calibrate::run_calibrate(&crate::calibrate::CalibrateOptions {
                recording,
                urdf,
                packages: packages(package_path),
                camera,
                pose,
                look_at,
                mount,
                fit,
                every,
                fit_focal: intrinsics,
                budget: triangles.max(100),
                hidden_below,
                background,
                background_threshold,
                edges,
                out: out.clone(),
                progress: true,
            })?;
            for note in report["notes"].as_array().into_iter().flatten() {
                eprintln!("note: {}", note.as_str().unwrap_or_default());
            }
            let iou = &report["iou"];
            let f = |v: &serde_json::Value| {
                v.as_f64()
                    .map_or("- (no reference mask)".to_owned(), |x| format!("{x:.3}"))
            };
            println!(
                "calibrated on {} frames in {:.1} s: IoU {} -> {} on the fit frames, {} -> {} held out; moved {:.2} deg, {:.1} mm from the rough pose; spread over starts {:.2} deg, {:.1} mm",
                report["frames_fit"],
                report["wall_time_s"].as_f64().unwrap_or(0.0),
                f(&iou["fit_before"]),
                f(&iou["fit_after"]),
                f(&iou["held_out_before"]),
                f(&iou["held_out_after"]),
                report["change_from_rough"]["rotation_deg"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
                report["change_from_rough"]["translation_mm"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
                report["uncertainty"]["spread_deg"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
                report["uncertainty"]["spread_mm"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
            );
            println!(
                "{}: {}; report: {}",
                if report["head_from_camera"].is_object() {
                    "mount"
                } else {
                    "pose"
                },
                report["outputs"]["pose"].as_str().unwrap_or_default(),
                out.join("report.json").display()
            );
            if let Some(mount) = report["head_from_camera"].as_object() {
                let v = |key: &str| {
                    mount[key]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .map(|x| format!("{:.6}", x.as_f64().unwrap_or(f64::NAN)))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                println!(
                    "in the scene: [camera.head] mount = {{ xyz = [{}], rpy = [{}] }}",
                    v("translation"),
                    v("rpy")
                );
            }
            Ok(())
        }
        Command::Bench(BenchCommand::Head {
            scene,
            view,
            out,
            speeds,
            latencies,
            compensation,
            mount_errors,
            mount_speed,
            mount_latency,
            background_views,
            duration,
            camera_size,
            package_path,
        }) => {
            let path = scene.unwrap_or_else(|| bundled_scene("head_camera.toml"));
            let packages = packages(package_path);
            let mut scene = Scene::load_view(&path, &packages, view.as_deref())?;
            if view.is_none() && scene.head.is_none() {
                // The first camera on a head, where the first is fixed.
                for name in scene.cameras.clone().iter().skip(1) {
                    let other = Scene::load_view(&path, &packages, Some(name))?;
                    if other.head.is_some() {
                        scene = other;
                        break;
                    }
                }
            }
            EraseOverrides {
                camera_size,
                ..Default::default()
            }
            .apply(&mut scene)?;
            let sweep = crate::bench::head::HeadSweep {
                speeds_deg_s: speeds,
                latencies_ms: latencies,
                compensation,
                mount_errors_deg: mount_errors,
                mount_speed_deg_s: mount_speed,
                mount_latency_ms: mount_latency,
                background_views,
                duration_s: duration,
                progress: true,
            };
            let outputs = crate::bench::head::run_head(&scene, &sweep, &out)?;
            println!(
                "{:>8} {:>8} {:>6} {:>8} {:>6} {:>8} {:>8} {:>8} {:>8} {:>11} {:>9}",
                "deg/s",
                "track ms",
                "comp",
                "mount°",
                "views",
                "IoU",
                "leak %",
                "max %",
                "PSNR dB",
                "cam err °",
                "frame ms"
            );
            for p in &outputs.points {
                println!(
                    "{:>8} {:>8} {:>6} {:>8} {:>6} {:>8.4} {:>8.3} {:>8.3} {:>8.2} {:>11.3} {:>9.1}",
                    p.speed_deg_s,
                    p.latency_ms,
                    if p.compensation { "on" } else { "off" },
                    p.mount_error_deg,
                    p.background_views,
                    p.iou_mean,
                    p.leak_pct_mean,
                    p.leak_pct_max,
                    p.psnr_db_mean,
                    p.camera_error_deg_median,
                    p.frame_ms_median
                );
            }
            println!(
                "wrote {}, {}, {}",
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Dr {
            scene,
            out,
            scales,
            dilate,
            feather,
            latency,
            duration,
            package_path,
        }) => {
            let path = scene.unwrap_or_else(default_scene);
            let scene = Scene::load(&path, &packages(package_path))?;
            let sweep = DrSweep {
                scales,
                dilate,
                feather,
                latency,
                duration_s: duration,
                progress: true,
            };
            let outputs = bench_dr::run_dr(&scene, &sweep, &out)?;
            let base = &outputs.points[outputs.baseline];
            println!(
                "{:<22} {:>9} {:>7} {:>12} {:>8} {:>8} {:>8}  front (frame cost / erase GPU time)",
                "setting", "frame ms", "ratio", "erase GPU ms", "leak %", "over %", "PSNR dB"
            );
            for p in &outputs.points {
                let front = |leak: bool, psnr: bool| match (leak, psnr) {
                    (true, true) => "leak, PSNR",
                    (true, false) => "leak",
                    (false, true) => "PSNR",
                    (false, false) => "-",
                };
                let front = format!(
                    "{} / {}",
                    front(p.pareto_leak, p.pareto_psnr),
                    front(p.pareto_leak_gpu, p.pareto_psnr_gpu)
                );
                let erase_gpu = match (p.gpu_mask_ms, p.gpu_composite_ms) {
                    (Some(m), Some(c)) => format!("{:.1}", m + c),
                    _ => "-".into(),
                };
                println!(
                    "{:<22} {:>9.1} {:>7.3} {:>12} {:>8.3} {:>8.2} {:>8.2}  {front}",
                    p.label,
                    p.frame_ms_median,
                    p.frame_cost_ratio,
                    erase_gpu,
                    p.leak_pct_mean,
                    p.overmask_pct_mean,
                    p.psnr_db_mean
                );
            }
            println!(
                "ratios against '{}' ({:.1} ms) of the same run; wrote {}, {}, {}",
                base.label,
                base.frame_ms_median,
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Twin {
            scene,
            out,
            variants,
            duration,
            tcp_speed,
            frames_every,
            package_path,
        }) => {
            let path = scene.unwrap_or_else(|| bundled_scene("sawyer_real.toml"));
            let packages = packages(package_path);
            let scene = Scene::load(&path, &packages)?;
            let mut sweep = TwinSweep {
                duration_s: duration,
                tcp_speed,
                frames_every,
                packages,
                progress: true,
                ..TwinSweep::default()
            };
            if variants.is_empty() {
                let lite = bundled("robots", "sawyer_lite/sawyer_lite.urdf");
                if scene.model.name == "sawyer" && lite.is_file() {
                    sweep
                        .variants
                        .push(TwinVariant::parse(&format!("urdf:{}", lite.display()))?);
                }
            } else {
                sweep.variants = variants
                    .iter()
                    .map(|v| TwinVariant::parse(v))
                    .collect::<Result<_, _>>()?;
            }
            let outputs = bench_twin::run_twin(&scene, &sweep, &out)?;
            println!(
                "TCP peak {:.3} m/s in the scene, timeline x{:.2}: {:.3} m/s peak in the replayed {} s",
                outputs.scene_tcp_speed, outputs.time_scale, outputs.window_tcp_speed, duration
            );
            println!(
                "{:<14} {:>10} {:>13} {:>9} {:>7} {:>8} {:>8} {:>8} {:>8} {:>13}  front",
                "twin",
                "triangles",
                "mask GPU ms",
                "frame ms",
                "ratio",
                "IoU",
                "leak %",
                "over %",
                "PSNR dB",
                "dilate <=1%"
            );
            for p in &outputs.points {
                println!(
                    "{:<14} {:>10} {:>13} {:>9.1} {:>7.3} {:>8.4} {:>8.3} {:>8.3} {:>8.2} {:>13}  {}",
                    p.label,
                    p.triangles,
                    p.gpu_mask_twin_ms.map_or("-".into(), |v| format!("{v:.2}")),
                    p.frame_ms_median,
                    p.frame_cost_ratio,
                    p.iou_mean,
                    p.leak_pct_mean,
                    p.overmask_pct_mean,
                    p.psnr_db_mean,
                    p.dilate_for_1pct.map_or("-".into(), |d| format!("{d} px")),
                    if p.pareto { "yes" } else { "-" }
                );
            }
            println!(
                "ratios against '{}' of the same run; wrote {}, {}, {}",
                outputs.points[0].label,
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Gpu {
            scene,
            out,
            sizes,
            cameras,
            frames,
            dilate,
            feather,
            package_path,
        }) => {
            let path = scene.unwrap_or_else(default_scene);
            let scene = Scene::load(&path, &packages(package_path))?;
            let sweep = GpuSweep {
                sizes,
                cameras,
                frames,
                dilate_px: dilate,
                feather_px: feather,
                progress: true,
            };
            let outputs = bench_gpu::run_gpu(&scene, &sweep, &out)?;
            println!(
                "{:<11} {:>4} {:>10} {:>10} {:>10} {:>10} {:>9} {:>9} {:>10}  GPU clock",
                "size",
                "cams",
                "erase ms",
                "passes ms",
                "twin ms",
                "floor ms",
                "erase/fl",
                "pass/fl",
                "update ms"
            );
            for p in &outputs.points {
                println!(
                    "{:<11} {:>4} {:>10.3} {:>10.3} {:>10.3} {:>10.4} {:>9.1} {:>9.1} {:>10.1}  {}",
                    format!("{}x{}", p.size.0, p.size.1),
                    p.cameras,
                    p.erase.median,
                    p.passes.median,
                    p.mask_twin.median,
                    p.floor.median,
                    p.erase_over_floor(),
                    p.passes_over_floor(),
                    p.update_ms,
                    p.clock.as_deref().unwrap_or("not reported (no nvidia-smi)")
                );
            }
            println!(
                "table: {}\nchart: {} and {}",
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Network {
            scene,
            out,
            delays,
            losses,
            modes,
            trials,
            target_timeout,
            package_path,
        }) => {
            crate::net::init_log_quiet();
            let path = scene.unwrap_or_else(pouring_scene);
            let scene = Scene::load(&path, &packages(package_path))?;
            let sweep = crate::bench::network::NetworkSweep {
                delays_ms: delays,
                losses_pct: losses,
                modes,
                trials,
                target_timeout_s: target_timeout,
                progress: true,
            };
            let outputs = crate::bench::network::run_network(&scene, &sweep, &out)?;
            println!(
                "{:<11} {:>8} {:>6} {:>9} {:>7} {:>7} {:>7} {:>6} {:>8} {:>7}",
                "mode",
                "delay ms",
                "loss %",
                "pos mm",
                "std",
                "roll",
                "yaw",
                "stops",
                "age ms",
                "failed"
            );
            let mut seen = Vec::new();
            for t in &outputs.trials {
                let key = (t.mode, t.delay_ms.to_bits(), t.loss_pct.to_bits());
                if seen.contains(&key) {
                    continue;
                }
                seen.push(key);
                let cell: Vec<_> = outputs
                    .trials
                    .iter()
                    .filter(|u| (u.mode, u.delay_ms.to_bits(), u.loss_pct.to_bits()) == key)
                    .collect();
                let (pos, std) =
                    crate::bench::network::mean_std(cell.iter().map(|u| u.pos_rmse_mm));
                let (roll, _) =
                    crate::bench::network::mean_std(cell.iter().map(|u| u.roll_rmse_deg));
                let (yaw, _) = crate::bench::network::mean_std(cell.iter().map(|u| u.yaw_rmse_deg));
                let stops: usize = cell.iter().map(|u| u.stops_after_grasp).sum();
                let (age, _) =
                    crate::bench::network::mean_std(cell.iter().map(|u| u.target_age_ms));
                let failed = cell
                    .iter()
                    .filter(|u| u.failed.is_some() || !u.grasped)
                    .count();
                println!(
                    "{:<11} {:>8} {:>6} {:>9.2} {:>7.2} {:>7.2} {:>7.2} {:>6} {:>8.1} {:>7}",
                    t.mode.name(),
                    t.delay_ms,
                    t.loss_pct,
                    pos,
                    std,
                    roll,
                    yaw,
                    stops,
                    age,
                    failed
                );
            }
            println!(
                "wrote {}, {} and {}",
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Video {
            recording,
            out,
            sizes,
            jpeg,
            h264,
            fps,
            keyframe_interval,
            frames,
        }) => {
            let sweep = crate::bench::video::VideoSweep {
                sizes,
                jpeg_qualities: jpeg,
                h264_mbit_s: h264,
                fps,
                keyframe_interval_s: keyframe_interval,
                frames,
                progress: true,
            };
            let sources = crate::bench::video::source_frames(&recording, frames)?;
            let outputs = crate::bench::video::run_video(&sources, &sweep, &out)?;
            println!("{} frames from {}", sweep.frames, recording.display());
            println!(
                "{:<7} {:<10} {:<5} {:>7} {:>8} {:>7} {:>8} {:>8} {:>8} {:>8} {:>7} {:>8} {:>5}",
                "source",
                "size",
                "codec",
                "setting",
                "Mbit/s",
                "x jpeg",
                "key kB",
                "delta kB",
                "enc ms",
                "dec ms",
                "PSNR",
                "min PSNR",
                "skip"
            );
            for p in &outputs.points {
                println!(
                    "{:<7} {:<10} {:<5} {:>7} {:>8.2} {:>7.3} {:>8.1} {:>8.1} {:>8.2} {:>8.2} {:>7.2} {:>8.2} {:>5}",
                    p.source,
                    format!("{}x{}", p.width, p.height),
                    p.codec,
                    p.setting,
                    p.mbit_s,
                    p.rate_ratio,
                    p.keyframe_kb,
                    p.delta_kb,
                    p.encode_ms.median,
                    p.decode_ms.median,
                    p.psnr_db,
                    p.psnr_min_db,
                    p.skipped
                );
            }
            println!(
                "wrote {}, {} and {}",
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Control {
            scene,
            out,
            rates,
            latency_ms,
            caps,
            trials,
            package_path,
        }) => {
            let path = scene.unwrap_or_else(pouring_scene);
            let scene = Scene::load(&path, &packages(package_path))?;
            let sweep = ControlSweep {
                rates_hz: rates,
                latencies_ms: latency_ms,
                caps,
                trials,
                progress: true,
            };
            let outputs = bench_control::run_control(&scene, &sweep, &out)?;
            let base = &outputs.points[outputs.baseline];
            println!(
                "{:<22} {:<11} {:>8} {:>7} {:>7} {:>7} {:>7} {:>8} {:>7} {:>7}  front",
                "setting",
                "mode",
                "pos mm",
                "std",
                "roll",
                "pitch",
                "yaw",
                "ms/sim s",
                "ratio",
                "tick us"
            );
            for p in &outputs.points {
                println!(
                    "{:<22} {:<11} {:>8.2} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>8.1} {:>7.3} {:>7.1}  {}",
                    p.label,
                    p.mode.name(),
                    p.pos_rmse_mm,
                    p.pos_rmse_mm_std,
                    p.roll_rmse_deg,
                    p.pitch_rmse_deg,
                    p.yaw_rmse_deg,
                    p.wall_ms_per_sim_s,
                    p.cost_ratio,
                    p.tick_us,
                    if p.pareto { "*" } else { "" }
                );
            }
            println!(
                "ratios against '{} {}' ({:.1} ms per simulated s) of the same run; wrote {}, {}, {}",
                base.label,
                base.mode.name(),
                base.wall_ms_per_sim_s,
                outputs.csv.display(),
                outputs.svg.display(),
                outputs.png.display()
            );
            Ok(())
        }
    }
}

/// One `--fit` entry: `FIRST-LAST` frame indices (inclusive, FIRST ≤ LAST) or one index.
/// Numbers as they were given on the command line, comma-separated (for error messages).
fn list(v: &[impl std::fmt::Display]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

fn frame_range(s: &str) -> Result<(usize, usize), AppError> {
    let bad = || AppError::Value {
        text: s.to_owned(),
        message:
            "expected frame indices: FIRST-LAST or one index, comma-separated (e.g. 0-4 or 0,1,5)"
                .into(),
    };
    let index = |t: &str| t.trim().parse::<usize>().map_err(|_| bad());
    let (a, b) = match s.split_once('-') {
        Some((a, b)) => (index(a)?, index(b)?),
        None => (index(s)?, index(s)?),
    };
    if a <= b { Ok((a, b)) } else { Err(bad()) }
}

/// `WIDTHxHEIGHT`, both at least 1 and at most 8192.
pub(crate) fn frame_size(s: &str) -> Result<(u32, u32), AppError> {
    let bad = || AppError::Value {
        text: s.to_owned(),
        message: "expected WIDTHxHEIGHT in pixels, each 1 to 8192 (e.g. 1920x1080)".into(),
    };
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    );
    if (1..=8192).contains(&w) && (1..=8192).contains(&h) {
        Ok((w, h))
    } else {
        Err(bad())
    }
}

/// `--step-ms`: a time step in milliseconds, more than 0 and at most 250 (Bevy clamps a longer
/// update).
fn step_ms(s: &str) -> Result<f64, AppError> {
    let ms: f64 = s.parse().map_err(|_| AppError::Value {
        text: s.to_owned(),
        message: "expected a number of milliseconds".into(),
    })?;
    if ms.is_finite() && ms > 0.0 && ms <= 250.0 {
        Ok(ms)
    } else {
        Err(AppError::Value {
            text: s.to_owned(),
            message: "expected more than 0 and at most 250 ms (a longer step is clamped)".into(),
        })
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
