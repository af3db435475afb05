//! `avatarm import FILE.bag --out FILE.mcap`: a ROS 1 bag (format 2.0, as `rosbag record`
//! writes it, chunks uncompressed, bz2 or lz4) into a recording ([`avatarm_record`]).
//!
//! The bag is read by the `rosbag` crate and each message decoded from ROS 1's serialisation
//! by `roslibrust_serde_rosmsg` (the ROS link's own decoder) into the standard messages'
//! fields, after checking each connection's type and MD5 sum against the standard ones:
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

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::{Path, PathBuf};

use avatarm_record::camera::{CameraCalibration, DistortionModel, read_calibration, read_pose};
use avatarm_record::{CompressedFrame, ImageFormat, JointStates, RecordingWriter};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use rosbag::{ChunkRecord, IndexRecord, MessageRecord, RosBag};
use serde::Deserialize;

use crate::FootageError;

/// What `avatarm import FILE.bag` does.
#[derive(Debug, Clone, Default)]
pub struct BagOptions {
    /// The bag.
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
    /// Every topic in the bag: (topic, type, messages).
    pub topics: Vec<(String, String, usize)>,
    /// What was left out: joint states without positions, transforms not finite or not unit.
    pub notes: Vec<String>,
}

const IMAGE: (&str, &str) = ("sensor_msgs/Image", "060021388200f6f0f447d0fcd9c64743");
const COMPRESSED: (&str, &str) = (
    "sensor_msgs/CompressedImage",
    "8f7a12909da2c9d3332d540a0977563f",
);
const CAMERA_INFO: (&str, &str) = ("sensor_msgs/CameraInfo", "c9a58c1b0b154e0e6da7578cb991d214");
const JOINT_STATE: (&str, &str) = ("sensor_msgs/JointState", "3066dcd76a6cfaef579bd0f34173e9fd");
const TF: (&str, &str) = ("tf2_msgs/TFMessage", "94810edda583a504dfda3829e70d7eec");

// The standard messages' fields in their wire order (ROS 1 serialisation is the fields in
// order: little-endian numbers, strings and variable arrays behind a u32 length).

#[derive(Deserialize)]
struct Time {
    secs: u32,
    nsecs: u32,
}

#[derive(Deserialize)]
struct Header {
    _seq: u32,
    stamp: Time,
    frame_id: String,
}

#[derive(Deserialize)]
struct Image {
    header: Header,
    height: u32,
    width: u32,
    encoding: String,
    is_bigendian: u8,
    step: u32,
    #[serde(with = "serde_bytes")]
    data: Vec<u8>,
}

#[derive(Deserialize)]
struct CompressedImage {
    header: Header,
    format: String,
    #[serde(with = "serde_bytes")]
    data: Vec<u8>,
}

#[derive(Deserialize)]
struct RegionOfInterest {
    _x_offset: u32,
    _y_offset: u32,
    _height: u32,
    _width: u32,
    _do_rectify: bool,
}

#[derive(Deserialize)]
struct CameraInfo {
    header: Header,
    height: u32,
    width: u32,
    distortion_model: String,
    d: Vec<f64>,
    k: [f64; 9],
    _r: [f64; 9],
    _p: [f64; 12],
    _binning_x: u32,
    _binning_y: u32,
    _roi: RegionOfInterest,
}

#[derive(Deserialize)]
struct JointState {
    header: Header,
    name: Vec<String>,
    position: Vec<f64>,
    velocity: Vec<f64>,
    _effort: Vec<f64>,
}

#[derive(Deserialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Deserialize)]
struct QuaternionMsg {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Deserialize)]
struct Transform {
    translation: Vector3,
    rotation: QuaternionMsg,
}

#[derive(Deserialize)]
struct TransformStamped {
    header: Header,
    child_frame_id: String,
    transform: Transform,
}

#[derive(Deserialize)]
struct TfMessage {
    transforms: Vec<TransformStamped>,
}

/// One connection (a topic as one publisher recorded it).
#[derive(Debug, Clone)]
struct Connection {
    topic: String,
    kind: String,
    md5: String,
}

/// A transform on `/tf` or `/tf_static`: parent, child, stamp, `parent_from_child`.
type Link = (String, String, u64, Isometry3<f64>);

fn bag_error(bag: &Path, message: impl Into<String>) -> FootageError {
    FootageError::input(bag.display().to_string(), message)
}

fn stamp_ns(t: &Time, received_ns: u64) -> u64 {
    let ns = u64::from(t.secs) * 1_000_000_000 + u64::from(t.nsecs);
    if ns == 0 { received_ns } else { ns }
}

/// A silhouette with every non-zero pixel at 255 (a label mask of 0/1 is common), as PNG.
fn as_silhouette(frame: CompressedFrame, at: &str) -> Result<CompressedFrame, String> {
    let luma = image::load_from_memory(&frame.data)
        .map_err(|e| format!("{at}: the mask does not decode: {e}"))?
        .to_luma16();
    let (w, h) = luma.dimensions();
    let bytes: Vec<u8> = luma
        .pixels()
        .map(|p| if p.0[0] != 0 { 255 } else { 0 })
        .collect();
    let picture =
        image::GrayImage::from_raw(w, h, bytes).ok_or_else(|| format!("{at}: {w}x{h}"))?;
    let mut png = Vec::new();
    picture
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| format!("{at}: PNG encoding failed: {e}"))?;
    Ok(CompressedFrame {
        stamp_ns: frame.stamp_ns,
        format: ImageFormat::Png,
        data: png,
    })
}

/// An image message as PNG (Image) or as recorded (CompressedImage), with its frame_id.
fn image_of(
    c: &Connection,
    data: &[u8],
    at: &str,
    received_ns: u64,
) -> Result<(CompressedFrame, String), String> {
    let decode_error = |e: roslibrust_serde_rosmsg::Error| format!("{at}: not a {}: {e}", c.kind);
    if c.kind == COMPRESSED.0 {
        let m: CompressedImage =
            roslibrust_serde_rosmsg::from_slice_known_length(data, data.len() as u32)
                .map_err(decode_error)?;
        let format = ImageFormat::of_bytes(&m.data).ok_or_else(|| {
            format!(
                "{at}: format '{}': the data is neither JPEG nor PNG",
                m.format
            )
        })?;
        return Ok((
            CompressedFrame {
                stamp_ns: stamp_ns(&m.header.stamp, received_ns),
                format,
                data: m.data,
            },
            m.header.frame_id,
        ));
    }
    let m: Image = roslibrust_serde_rosmsg::from_slice_known_length(data, data.len() as u32)
        .map_err(decode_error)?;
    let (w, h) = (m.width as usize, m.height as usize);
    if w == 0 || h == 0 {
        return Err(format!("{at}: an empty image ({w}x{h})"));
    }
    let (channels, bytes) = match m.encoding.as_str() {
        "rgb8" | "bgr8" | "8UC3" => (3, 1),
        "rgba8" | "bgra8" | "8UC4" => (4, 1),
        "mono8" | "8UC1" => (1, 1),
        "mono16" | "16UC1" => (1, 2),
        other => {
            return Err(format!(
                "{at}: encoding '{other}' is not read (rgb8, bgr8, rgba8, bgra8, mono8, mono16, 8UC1, 8UC3, 8UC4, 16UC1)"
            ));
        }
    };
    let row = w * channels * bytes;
    let step = m.step as usize;
    if step < row || m.data.len() < step * (h - 1) + row {
        return Err(format!(
            "{at}: {w}x{h} {} needs a step of at least {row} bytes and {} bytes of data; the message has step {step} and {} bytes",
            m.encoding,
            step * (h - 1) + row,
            m.data.len()
        ));
    }
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        let line = &m.data[y * step..y * step + row];
        match (m.encoding.as_str(), bytes) {
            ("rgb8", _) => rgb.extend_from_slice(line),
            ("bgr8" | "8UC3", _) => line
                .chunks_exact(3)
                .for_each(|p| rgb.extend([p[2], p[1], p[0]])),
            ("rgba8", _) => line
                .chunks_exact(4)
                .for_each(|p| rgb.extend([p[0], p[1], p[2]])),
            ("bgra8" | "8UC4", _) => line
                .chunks_exact(4)
                .for_each(|p| rgb.extend([p[2], p[1], p[0]])),
            (_, 1) => line.iter().for_each(|&v| rgb.extend([v, v, v])),
            _ => line.chunks_exact(2).for_each(|p| {
                let v = if m.is_bigendian != 0 {
                    u16::from_be_bytes([p[0], p[1]])
                } else {
                    u16::from_le_bytes([p[0], p[1]])
                };
                let v = (v >> 8) as u8;
                rgb.extend([v, v, v]);
            }),
        }
    }
    let picture = image::RgbImage::from_raw(m.width, m.height, rgb)
        .ok_or_else(|| format!("{at}: {w}x{h} does not fit its pixels"))?;
    let mut png = Vec::new();
    picture
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| format!("{at}: PNG encoding failed: {e}"))?;
    Ok((
        CompressedFrame {
            stamp_ns: stamp_ns(&m.header.stamp, received_ns),
            format: ImageFormat::Png,
            data: png,
        },
        m.header.frame_id,
    ))
}

fn size_of(f: &CompressedFrame, at: &str) -> Result<(u32, u32), String> {
    image::ImageReader::new(std::io::Cursor::new(&f.data))
        .with_guessed_format()
        .map_err(|e| format!("{at}: {e}"))?
        .into_dimensions()
        .map_err(|e| format!("{at}: the image does not decode: {e}"))
}

/// `base_from_target` through the transforms (an undirected tree search from `base`).
fn chain(links: &[Link], base: &str, target: &str, near_ns: u64) -> Option<Isometry3<f64>> {
    // Per edge, the transform nearest `near_ns` (a static one has stamp 0 or any).
    let mut edges: HashMap<(&str, &str), (u64, Isometry3<f64>)> = HashMap::new();
    for (parent, child, stamp, t) in links {
        let d = stamp.abs_diff(near_ns);
        let e = edges
            .entry((parent.as_str(), child.as_str()))
            .or_insert((d, *t));
        if d < e.0 {
            *e = (d, *t);
        }
    }
    let mut from: HashMap<&str, Isometry3<f64>> = HashMap::from([(base, Isometry3::identity())]);
    let mut queue = VecDeque::from([base]);
    while let Some(frame) = queue.pop_front() {
        let here = from[frame];
        if frame == target {
            return Some(here);
        }
        for ((parent, child), (_, t)) in &edges {
            let (next, step) = if *parent == frame {
                (*child, *t)
            } else if *child == frame {
                (*parent, t.inverse())
            } else {
                continue;
            };
            if !from.contains_key(next) {
                from.insert(next, here * step);
                queue.push_back(next);
            }
        }
    }
    None
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

/// Imports the bag. Errors name the bag, the topic and the message (`/camera/image_raw,
/// message 3`): a file that is not a bag, a topic whose type or MD5 sum is not the standard
/// message's, a message that does not decode, an image encoding not read, frames of
/// different sizes or repeated stamps, a non-finite joint value, a calibration that does not
/// fit the images, no camera frames, no calibration, a `--base-frame` that `/tf` does not
/// connect to the camera's frame.
#[expect(
    clippy::too_many_lines,
    reason = "one pass over the bag's chunks with a branch per message kind, then the recording written; a split by message kind is left for the next pass"
)]
pub fn import_bag(o: &BagOptions) -> Result<BagSummary, FootageError> {
    let path = &o.bag;
    let bag = RosBag::new(path)
        .map_err(|e| bag_error(path, format!("not a ROS 1 bag (format 2.0), or one never closed (`rosbag reindex` repairs that): {e}")))?;
    let mut connections: HashMap<u32, Connection> = HashMap::new();
    for record in bag.index_records() {
        if let IndexRecord::Connection(c) =
            record.map_err(|e| bag_error(path, format!("its index: {e}")))?
        {
            connections.insert(
                c.id,
                Connection {
                    topic: c.topic.to_owned(),
                    kind: c.tp.to_owned(),
                    md5: c.md5sum.iter().map(|b| format!("{b:02x}")).collect(),
                },
            );
        }
    }
    let mut topics: BTreeMap<String, String> = BTreeMap::new();
    for c in connections.values() {
        for (kind, md5) in [IMAGE, COMPRESSED, CAMERA_INFO, JOINT_STATE, TF] {
            if c.kind == kind && c.md5 != md5 {
                return Err(bag_error(
                    path,
                    format!(
                        "{}: {} with MD5 sum {}, not the standard message's {md5}",
                        c.topic, c.kind, c.md5
                    ),
                ));
            }
        }
        topics.insert(c.topic.clone(), c.kind.clone());
    }
    let images = [IMAGE.0, COMPRESSED.0];
    // The mask topic is not a candidate for the frames.
    let mut candidates = topics.clone();
    if let Some(m) = &o.mask_topic {
        candidates.remove(m);
    }
    let image_topic = pick(
        path,
        &candidates,
        o.image_topic.as_deref(),
        &images,
        "--image-topic",
        true,
    )?
    .unwrap_or_default()
    .to_owned();
    let mask_topic = match &o.mask_topic {
        Some(t) => pick(path, &topics, Some(t), &images, "--mask-topic", true)?.map(str::to_owned),
        None => None,
    };
    // With --camera the bag's CameraInfo is not read (a RealSense bag has several).
    let info_topic = if o.camera.is_some() {
        None
    } else {
        pick(
            path,
            &topics,
            o.camera_info_topic.as_deref(),
            &[CAMERA_INFO.0],
            "--camera-info-topic",
            true,
        )?
        .map(str::to_owned)
    };
    let joints_topic = pick(
        path,
        &topics,
        o.joint_states_topic.as_deref(),
        &[JOINT_STATE.0],
        "--joint-states-topic",
        true,
    )?
    .unwrap_or_default()
    .to_owned();
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut frames: Vec<CompressedFrame> = Vec::new();
    let mut masks: Vec<CompressedFrame> = Vec::new();
    let mut image_frame = String::new();
    let mut info: Option<CameraInfo> = None;
    let mut skipped_states = 0usize;
    let mut bad_links: Vec<String> = Vec::new();
    let mut states: Vec<JointStates> = Vec::new();
    let mut links: Vec<Link> = Vec::new();
    for record in bag.chunk_records() {
        let ChunkRecord::Chunk(chunk) =
            record.map_err(|e| bag_error(path, format!("a chunk: {e}")))?
        else {
            continue;
        };
        for m in chunk.messages() {
            let MessageRecord::MessageData(m) =
                m.map_err(|e| bag_error(path, format!("a chunk's message: {e}")))?
            else {
                continue;
            };
            let Some(c) = connections.get(&m.conn_id) else {
                return Err(bag_error(
                    path,
                    format!(
                        "a message on connection {} that the index does not list",
                        m.conn_id
                    ),
                ));
            };
            let n = counts.entry(c.topic.clone()).or_default();
            let at = format!("{}, message {}", c.topic, *n);
            *n += 1;
            let fail = |message: String| bag_error(path, message);
            let decode =
                |e: roslibrust_serde_rosmsg::Error| fail(format!("{at}: not a {}: {e}", c.kind));
            let len = m.data.len() as u32;
            if c.topic == image_topic || mask_topic.as_deref() == Some(c.topic.as_str()) {
                let (frame, frame_id) = image_of(c, m.data, &at, m.time).map_err(fail)?;
                if c.topic == image_topic {
                    if image_frame.is_empty() {
                        image_frame = frame_id;
                    }
                    frames.push(frame);
                } else {
                    masks.push(as_silhouette(frame, &at).map_err(fail)?);
                }
            } else if Some(c.topic.as_str()) == info_topic.as_deref() {
                let m: CameraInfo = roslibrust_serde_rosmsg::from_slice_known_length(m.data, len)
                    .map_err(decode)?;
                if info.is_none() {
                    info = Some(m);
                }
            } else if c.topic == joints_topic {
                let s: JointState = roslibrust_serde_rosmsg::from_slice_known_length(m.data, len)
                    .map_err(decode)?;
                if s.position.is_empty() {
                    // Efforts or velocities alone (the message allows it): no positions to keep.
                    skipped_states += 1;
                    continue;
                }
                if s.position.len() != s.name.len() {
                    return Err(fail(format!(
                        "{at}: {} positions for {} names",
                        s.position.len(),
                        s.name.len()
                    )));
                }
                if let Some((name, v)) =
                    s.name.iter().zip(&s.position).find(|(_, v)| !v.is_finite())
                {
                    return Err(fail(format!("{at}: joint '{name}': {v} is not finite")));
                }
                let velocities = if s.velocity.len() == s.name.len()
                    && s.velocity.iter().all(|v| v.is_finite())
                {
                    s.velocity
                } else {
                    Vec::new()
                };
                states.push(JointStates {
                    stamp_ns: stamp_ns(&s.header.stamp, m.time),
                    names: s.name,
                    positions: s.position,
                    velocities,
                });
            } else if c.kind == TF.0 {
                let tf: TfMessage = roslibrust_serde_rosmsg::from_slice_known_length(m.data, len)
                    .map_err(decode)?;
                let is_static = c.topic == "/tf_static";
                for t in tf.transforms {
                    let (p, q) = (&t.transform.translation, &t.transform.rotation);
                    let values = [p.x, p.y, p.z, q.x, q.y, q.z, q.w];
                    // A bad transform is left out, and said if the pose needed its link.
                    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
                    if values.iter().any(|v| !v.is_finite()) || (norm - 1.0).abs() > 1e-3 {
                        bad_links.push(format!(
                            "{at}: {} -> {} (translation {:?}, quaternion norm {norm})",
                            t.header.frame_id,
                            t.child_frame_id,
                            [p.x, p.y, p.z]
                        ));
                        continue;
                    }
                    let rotation =
                        UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z));
                    let stamp = if is_static {
                        0
                    } else {
                        stamp_ns(&t.header.stamp, m.time)
                    };
                    links.push((
                        t.header.frame_id.trim_start_matches('/').to_owned(),
                        t.child_frame_id.trim_start_matches('/').to_owned(),
                        stamp,
                        Isometry3::from_parts(Translation3::new(p.x, p.y, p.z), rotation),
                    ));
                }
            }
        }
    }
    if frames.is_empty() {
        return Err(bag_error(path, format!("{image_topic} has no messages")));
    }
    frames.sort_by_key(|f| f.stamp_ns);
    if let Some(w) = frames.windows(2).find(|w| w[0].stamp_ns == w[1].stamp_ns) {
        return Err(bag_error(
            path,
            format!(
                "{image_topic}: two frames share the stamp {} ns",
                w[0].stamp_ns
            ),
        ));
    }
    // Every frame and mask the first frame's size (read from the headers alone).
    let size = size_of(&frames[0], &format!("{image_topic}, the first frame"))
        .map_err(|m| bag_error(path, m))?;
    let masks_topic = mask_topic.clone().unwrap_or_default();
    let frames_at = frames.iter().enumerate().map(|(i, f)| (&image_topic, i, f));
    let masks_at = masks.iter().enumerate().map(|(i, f)| (&masks_topic, i, f));
    for (topic, i, f) in frames_at.chain(masks_at) {
        let at = format!("{topic}, message {i}");
        let s = size_of(f, &at).map_err(|m| bag_error(path, m))?;
        if s != size {
            return Err(bag_error(
                path,
                format!(
                    "{at}: {}x{}, the first frame {}x{}",
                    s.0, s.1, size.0, size.1
                ),
            ));
        }
    }
    if states.is_empty() {
        return Err(bag_error(path, format!("{joints_topic} has no messages")));
    }
    states.sort_by_key(|s| s.stamp_ns);
    // The pose chains to CameraInfo's frame (the optical frame), else the frames'.
    let mut camera_frame = String::new();
    let calibration = match (&o.camera, info) {
        (Some(file), _) => read_calibration(file, Some(size))?,
        (None, Some(i)) => {
            camera_frame.clone_from(&i.header.frame_id);
            let model = DistortionModel::from_ros_name(&i.distortion_model).ok_or_else(|| {
                bag_error(
                    path,
                    format!(
                        "{}: distortion model '{}' is not read (plumb_bob, rational_polynomial, equidistant)",
                        info_topic.as_deref().unwrap_or_default(),
                        i.distortion_model
                    ),
                )
            })?;
            let c = CameraCalibration {
                width: i.width,
                height: i.height,
                k: i.k,
                distortion_model: model,
                d: if i.d.is_empty() {
                    vec![0.0; model.coefficients()]
                } else {
                    i.d
                },
            };
            c.validate().map_err(|m| {
                bag_error(
                    path,
                    format!("{}: {m}", info_topic.as_deref().unwrap_or_default()),
                )
            })?;
            if (c.width, c.height) != size {
                return Err(bag_error(
                    path,
                    format!(
                        "{}: the calibration is for {}x{} images, the frames are {}x{}",
                        info_topic.as_deref().unwrap_or_default(),
                        c.width,
                        c.height,
                        size.0,
                        size.1
                    ),
                ));
            }
            c
        }
        (None, None) => {
            return Err(bag_error(
                path,
                format!(
                    "{} has no messages: give --camera FILE",
                    info_topic.as_deref().unwrap_or_default()
                ),
            ));
        }
    };
    let t0 = frames[0].stamp_ns;
    if camera_frame.is_empty() {
        camera_frame = image_frame;
    }
    let camera_frame = camera_frame.trim_start_matches('/').to_owned();
    let (pose, pose_source) = match (&o.pose, &o.base_frame) {
        (Some(file), _) => (Some(read_pose(file)?), format!("--pose {}", file.display())),
        (None, Some(base)) => {
            if camera_frame.is_empty() {
                return Err(FootageError::input(
                    "--base-frame",
                    "the camera's frames have no frame_id to chain the pose to",
                ));
            }
            let pose = chain(&links, base.trim_start_matches('/'), &camera_frame, t0).ok_or_else(|| {
                let frames: std::collections::BTreeSet<&str> =
                    links.iter().flat_map(|l| [l.0.as_str(), l.1.as_str()]).collect();
                let left_out = if bad_links.is_empty() {
                    String::new()
                } else {
                    format!("; left out as not finite or not unit: {}", bad_links.join("; "))
                };
                FootageError::input(
                    "--base-frame",
                    format!(
                        "/tf does not connect {base} to the camera's frame {camera_frame} (frames in /tf and /tf_static: {}){left_out}",
                        frames.into_iter().collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
            (Some(pose), format!("/tf: {base} -> {camera_frame}"))
        }
        (None, None) if !links.is_empty() => (
            None,
            format!("not written: give --base-frame to chain it from /tf to {camera_frame}"),
        ),
        (None, None) => (
            None,
            "not in the bag (avatarm calibrate can find it)".to_owned(),
        ),
    };
    let mut out = RecordingWriter::create(&o.out)?;
    out.calibration(t0, &calibration)?;
    if let Some(p) = &pose {
        out.camera_pose(t0, p)?;
    }
    for f in &frames {
        out.frame(f)?;
    }
    for m in &masks {
        out.reference_mask(m)?;
    }
    for s in &states {
        out.joint_states(s)?;
    }
    out.finish()?;
    let mut names: Vec<String> = Vec::new();
    for s in &states {
        for n in &s.names {
            if !names.contains(n) {
                names.push(n.clone());
            }
        }
    }
    let listed: Vec<(String, String, usize)> = topics
        .iter()
        .map(|(t, k)| (t.clone(), k.clone(), counts.get(t).copied().unwrap_or(0)))
        .collect();
    let mut notes = Vec::new();
    if skipped_states > 0 {
        notes.push(format!(
            "{skipped_states} joint states on {joints_topic} had no positions and were left out"
        ));
    }
    if !bad_links.is_empty() {
        notes.push(format!(
            "transforms left out (not finite or not unit): {}",
            bad_links.join("; ")
        ));
    }
    Ok(BagSummary {
        frames: frames.len(),
        masks: masks.len(),
        joint_states: states.len(),
        size,
        duration_s: (frames[frames.len() - 1].stamp_ns - t0) as f64 * 1e-9,
        joints: names,
        pose: pose_source,
        topics: listed,
        notes,
    })
}
