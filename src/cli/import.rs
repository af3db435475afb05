//! `avatarm import`: a real Leap Motion recording to a `.hand.jsonl`, or a folder of camera
//! frames or a ROS bag (ROS 1, or a rosbag2's folder or storage file) to a recording (MCAP,
//! `avatarm_footage`).

use std::path::PathBuf;

use avatarm_core::teleop::hand::Handedness;
use clap::Args;

use crate::AppError;
use crate::cli::args::packages;

/// The arguments of `avatarm import`.
#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The Leap recording, a folder of camera frames with the robot's joints (a listing
    /// frames.csv or frames.json, or EasyHeC's color/ qpos/ mask/ K.txt), or a ROS bag: ROS 1
    /// (.bag), or a rosbag2 folder (metadata.yaml) or storage file (.mcap, .db3); Image or
    /// CompressedImage, CameraInfo, JointState, /tf (docs/real-footage.md).
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
}

impl ImportArgs {
    /// Runs `avatarm import`.
    pub fn run(self) -> Result<(), AppError> {
        match self {
            Self {
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
            } if is_bag(&recording) => {
                let s = avatarm_footage::bag::import_bag(&avatarm_footage::bag::BagOptions {
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
                    "wrote {} ({}): {} frames {}x{} over {:.2} s, {} reference masks, {} joint states of {}, camera pose {}",
                    out.display(),
                    s.format,
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
            Self {
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
                let summary = avatarm_footage::footage::import_footage(
                    &avatarm_footage::footage::FootageOptions {
                        folder: recording,
                        out: out.clone(),
                        listing,
                        camera,
                        pose,
                        joint_names,
                        urdf,
                        packages: packages(package_path),
                        fps,
                    },
                )?;
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
            Self {
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
        }
    }
}

/// A ROS 1 bag (`.bag`), a rosbag2 folder (with `metadata.yaml`) or a rosbag2 storage file
/// (`.mcap`, `.db3`, either as `.zstd`).
fn is_bag(path: &std::path::Path) -> bool {
    if path.is_dir() {
        return path.join("metadata.yaml").is_file();
    }
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    let name = name.strip_suffix(".zstd").unwrap_or(&name);
    [".bag", ".mcap", ".db3"].iter().any(|e| name.ends_with(e))
}
