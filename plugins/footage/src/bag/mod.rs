//! `avatarm import BAG --out FILE.mcap`: a ROS bag into a recording ([`avatarm_record`]):
//! - a ROS 1 bag (`FILE.bag`, format 2.0, as `rosbag record` writes it, chunks uncompressed,
//!   bz2 or lz4; [`ros1`]), each message decoded from ROS 1's serialisation by
//!   `roslibrust_serde_rosmsg` (the ROS link's own decoder) after its type's MD5 sum is checked;
//! - a rosbag2 (ROS 2; [`ros2`]): its folder (`metadata.yaml` beside the storage files), or one
//!   storage file, MCAP (`.mcap`, the default since Iron; chunks uncompressed, zstd or lz4) or
//!   SQLite (`.db3`, Humble's default), whole files zstd-compressed (`compression_mode: file`)
//!   or not; each message's CDR (the OMG's Common Data Representation, ROS 2's serialisation)
//!   decoded by `cdr-encoding`, RustDDS's.
//!
//! Both give the same recording from the same messages:
//! - camera frames: `sensor_msgs/Image` (`rgb8`, `bgr8`, `rgba8`, `bgra8`, `mono8`, `8UC1`,
//!   `8UC3` as BGR, `mono16`/`16UC1` scaled to 8 bits) written as PNG, or
//!   `sensor_msgs/CompressedImage` (JPEG or PNG) kept as they are;
//! - reference silhouettes (optional, `--mask-topic`): the same image types, non-zero = robot
//!   (stored as 255);
//! - the calibration: `sensor_msgs/CameraInfo` (K, the distortion model and D, the size);
//! - joint states: `sensor_msgs/JointState` (names, positions, velocities);
//! - the camera's pose: `tf2_msgs/TFMessage` on `/tf` and `/tf_static`, chained from
//!   `--base-frame` to the camera's frame (CameraInfo's `frame_id`, which REP 104 makes the
//!   optical frame: x right, y down, z forward), each link at the transform nearest the first
//!   frame (the frames' `frame_id` where CameraInfo has none). A transform that is not finite
//!   or not a unit quaternion is left out and said.
//!
//! Stamps are the messages' header stamps (the bag's receive time where a header's is zero).

mod assemble;
mod messages;
mod ros1;
mod ros2;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

use crate::FootageError;

/// What `avatarm import FILE.bag` does.
#[derive(Debug, Clone, Default)]
pub struct BagOptions {
    /// The bag: a ROS 1 bag (`.bag`), a rosbag2 folder (with `metadata.yaml`), or a rosbag2
    /// storage file (`.mcap`, `.db3`).
    pub bag: PathBuf,
    /// The recording to write (`.mcap`).
    pub out: PathBuf,
    /// The camera frames' topic; the bag's only image topic when `None`.
    pub image_topic: Option<String>,
    /// The reference silhouettes' topic, if the bag has them.
    pub mask_topic: Option<String>,
    /// The calibration's topic; the bag's only `CameraInfo` topic when `None`.
    pub camera_info_topic: Option<String>,
    /// The joint states' topic; the bag's only `JointState` topic when `None`.
    pub joint_states_topic: Option<String>,
    /// The robot's base frame in `/tf`, from which the camera's pose is chained.
    pub base_frame: Option<String>,
    /// A camera file instead of the bag's `CameraInfo`.
    pub camera: Option<PathBuf>,
    /// A pose file instead of `/tf`.
    pub pose: Option<PathBuf>,
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct BagSummary {
    /// Frames written.
    pub frames: usize,
    /// Reference masks written.
    pub masks: usize,
    /// Joint states written.
    pub joint_states: usize,
    /// Image size (px).
    pub size: (u32, u32),
    /// From the first frame to the last (s).
    pub duration_s: f64,
    /// The joints' names.
    pub joints: Vec<String>,
    /// Where the camera's pose came from (`/tf: base -> camera_optical`, `--pose FILE`), or
    /// why there is none.
    pub pose: String,
    /// What was read: `ROS 1 bag`, `rosbag2 (mcap)`, `rosbag2 (sqlite3)`.
    pub format: String,
    /// Every topic in the bag: (topic, type, messages).
    pub topics: Vec<(String, String, usize)>,
    /// What was left out: joint states without positions, transforms not finite or not unit.
    pub notes: Vec<String>,
}

/// The standard messages' type names in one ROS generation.
#[derive(Debug, Clone, Copy)]
struct MessageTypes {
    image: &'static str,
    compressed: &'static str,
    camera_info: &'static str,
    joint_state: &'static str,
    tf: &'static str,
}

/// A wire format: its header and its decoder.
trait Dialect {
    /// `std_msgs/Header` as this generation lays it out.
    type Header: messages::Stamped + DeserializeOwned;
    /// The standard messages' type names.
    const TYPES: MessageTypes;
    /// One message from its serialised bytes; the error says why it does not decode.
    fn decode<T: DeserializeOwned>(data: &[u8]) -> Result<T, String>;
}

/// Imports the bag, by what `o.bag` is: a `.bag` file as ROS 1, anything else (a folder, a
/// `.mcap` or `.db3` file) as a rosbag2. Errors name the bag, the topic and the message
/// (`/camera/image_raw, message 3`): a file that is not a bag, a topic whose type is not the
/// standard message's (ROS 1: its MD5 sum), a message that does not decode, an image encoding
/// not read, frames of different sizes or repeated stamps, a non-finite joint value, a
/// calibration that does not fit the images, no camera frames, no calibration, a
/// `--base-frame` that `/tf` does not connect to the camera's frame; a rosbag2 in a storage or
/// a compression not read names the command that converts it.
pub fn import_bag(o: &BagOptions) -> Result<BagSummary, FootageError> {
    if o.bag
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bag"))
    {
        ros1::import(o)
    } else {
        ros2::import(o)
    }
}

fn bag_error(bag: &Path, message: impl Into<String>) -> FootageError {
    FootageError::input(bag.display().to_string(), message)
}

/// The only topic of one of `kinds`, or the one asked for (checked to be of those kinds).
fn pick<'a>(
    bag: &Path,
    topics: &'a BTreeMap<String, String>,
    asked: Option<&'a str>,
    kinds: &[&str],
    flag: &str,
    required: bool,
) -> Result<Option<&'a str>, FootageError> {
    if let Some(t) = asked {
        return match topics.get(t) {
            Some(k) if kinds.contains(&k.as_str()) => Ok(Some(t)),
            Some(k) => Err(FootageError::input(
                flag,
                format!("{t} carries {k}, not {}", kinds.join(" or ")),
            )),
            None => Err(FootageError::input(
                flag,
                format!(
                    "{t} is not in {} (its topics: {})",
                    bag.display(),
                    topics.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            )),
        };
    }
    let of_kind: Vec<&str> = topics
        .iter()
        .filter(|(_, k)| kinds.contains(&k.as_str()))
        .map(|(t, _)| t.as_str())
        .collect();
    match of_kind.as_slice() {
        [one] => Ok(Some(one)),
        [] if !required => Ok(None),
        [] => Err(bag_error(bag, format!("no {} topic", kinds.join(" or ")))),
        several => Err(FootageError::input(
            flag,
            format!(
                "the bag has several {} topics ({}): say which",
                kinds.join(" or "),
                several.join(", ")
            ),
        )),
    }
}
