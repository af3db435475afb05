//! A ROS 2 camera's calibration as its driver gives it, gathered once before the camera is
//! used: `sensor_msgs/msg/CameraInfo` on the image topic's `camera_info` (image_transport's
//! convention: `/camera/image_raw` and `/camera/image_raw/compressed` -> `/camera/camera_info`),
//! and the transform tree on `/tf_static` (reliable, transient local: the static broadcaster's
//! latched transforms reach a late subscriber) and `/tf` (best effort), from which the caller
//! chains the camera's pose ([`avatarm_core::tf::chain`]).

use std::time::{Duration, Instant};

use avatarm_core::tf::FrameLink;
use serde::{Deserialize, Serialize};

use super::Header;
use super::camera::CameraTopic;
use super::node::{self, Qos, ros2_message};

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Left column (px).
    pub x_offset: u32,
    /// Top row (px).
    pub y_offset: u32,
    /// Rows (px; 0: the whole image).
    pub height: u32,
    /// Columns (px; 0: the whole image).
    pub width: u32,
    /// Whether the region is to be rectified.
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`: the calibration of the image stream it accompanies.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Stamp and the camera's optical frame (REP 104: x right, y down, z forward).
    pub header: Header,
    /// Rows of the images it calibrates (px).
    pub height: u32,
    /// Columns (px).
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`, ...
    pub distortion_model: String,
    /// The model's coefficients.
    pub d: Vec<f64>,
    /// The intrinsics K, row-major (px); all zero: the camera is not calibrated.
    pub k: [f64; 9],
    /// The rectification rotation R (row-major; stereo).
    pub r: [f64; 9],
    /// The projection P of the rectified image, row-major 3x4 (px).
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// The region of interest.
    pub roi: RegionOfInterest,
}
ros2_message!(
    CameraInfo,
    "sensor_msgs",
    "CameraInfo",
    hiroz_msgs::sensor_msgs::CameraInfo
);

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// z (m).
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `geometry_msgs/msg/Transform`: the child frame's pose in the parent frame.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Transform {
    /// Translation (m).
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child's pose in the parent frame.
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}
ros2_message!(
    TfMessage,
    "tf2_msgs",
    "TFMessage",
    hiroz_msgs::tf2_msgs::TFMessage
);

/// The `camera_info` topic beside `image_topic` (image_transport's convention): the image
/// topic's last name (and a `/compressed` transport's) replaced by `camera_info`.
pub fn info_topic(image_topic: &str) -> String {
    let base = image_topic.trim_end_matches('/');
    let base = base.strip_suffix("/compressed").unwrap_or(base);
    match base.rsplit_once('/') {
        Some((ns, _)) => format!("{ns}/camera_info"),
        None => "camera_info".to_owned(),
    }
}

/// Whether `image_topic` carries image_proc's rectified images (`image_rect`, `image_rect_color`,
/// and their `/compressed`): undistorted, to be seen through CameraInfo's P, not K and D.
pub fn is_rectified(image_topic: &str) -> bool {
    let base = image_topic.trim_end_matches('/');
    let base = base.strip_suffix("/compressed").unwrap_or(base);
    base.rsplit('/')
        .next()
        .is_some_and(|n| n.starts_with("image_rect"))
}

/// What the driver gave within the wait.
#[derive(Debug, Clone, Default)]
pub struct DriverCalibration {
    /// The image topic whose calibration it is.
    pub image_topic: String,
    /// The `camera_info` topic listened to.
    pub info_topic: String,
    /// Why a CameraInfo that came did not decode (the newest such).
    pub bad_info: Option<String>,
    /// The newest `CameraInfo`, if one came.
    pub info: Option<CameraInfo>,
    /// Every good transform received (static ones at stamp 0).
    pub links: Vec<FrameLink>,
    /// Transforms left out (not finite, not a unit quaternion), each said as what it held.
    pub bad_links: Vec<String>,
    /// How long the gathering took.
    pub waited: Duration,
}

/// Subscribes to `topic`'s `camera_info`, `/tf_static` and `/tf` on its domain and gathers
/// them until `done` says enough (checked after each message) or `wait` has passed, on a
/// thread of its own (the caller may be inside another runtime). Errors: the middleware could
/// not be joined or a subscription made (the message says which).
pub fn gather(
    topic: &CameraTopic,
    wait: Duration,
    done: impl Fn(&DriverCalibration) -> bool + Send,
) -> Result<DriverCalibration, String> {
    std::thread::scope(|s| {
        s.spawn(|| {
            let runtime = crate::client::link_runtime(
                "ROS 2 camera calibration",
                crate::client::Threads::WithWorker,
            )
            .ok_or_else(|| "no runtime".to_owned())?;
            runtime.block_on(gather_async(topic, wait, done))
        })
        .join()
        .unwrap_or_else(|_| Err("its thread panicked".into()))
    })
}

async fn gather_async(
    topic: &CameraTopic,
    wait: Duration,
    done: impl Fn(&DriverCalibration) -> bool,
) -> Result<DriverCalibration, String> {
    let started = Instant::now();
    let node_name = format!("{}_calibration", topic.node_name);
    let (mut spin, mut node) = node::join(&topic.transport, &node_name)?;
    let mut out = DriverCalibration {
        image_topic: topic.topic.clone(),
        info_topic: info_topic(&topic.topic),
        ..DriverCalibration::default()
    };
    // CameraInfo rides with each frame: best effort, the newest.
    let info = node.subscribe::<CameraInfo>(&out.info_topic, Qos::best_effort(1))?;
    // tf2's static listener: reliable, transient local, the last 100; its listener: best
    // effort, the last 100.
    let tf_static = node.subscribe::<TfMessage>("/tf_static", Qos::latched(100))?;
    let tf = node.subscribe::<TfMessage>("/tf", Qos::best_effort(100))?;
    let deadline = tokio::time::sleep(wait);
    tokio::pin!(deadline);
    loop {
        tokio::select! {
            m = info.recv() => match m {
                Ok(m) => out.info = Some(m),
                Err(e) => out.bad_info = Some(e),
            },
            m = tf_static.recv() => match m {
                Ok(m) => add_links(&mut out, m, true),
                Err(e) => out.bad_links.push(format!("/tf_static: does not decode: {e}")),
            },
            m = tf.recv() => match m {
                Ok(m) => add_links(&mut out, m, false),
                Err(e) => out.bad_links.push(format!("/tf: does not decode: {e}")),
            },
            why = &mut spin => return Err(why),
            () = &mut deadline => break,
        }
        if done(&out) {
            break;
        }
    }
    out.waited = started.elapsed();
    Ok(out)
}

/// The message's transforms into `out`: good ones as links (a static one at stamp 0), bad
/// ones said.
fn add_links(out: &mut DriverCalibration, m: TfMessage, is_static: bool) {
    let topic = if is_static { "/tf_static" } else { "/tf" };
    for t in m.transforms {
        let (p, q) = (&t.transform.translation, &t.transform.rotation);
        // A static transform (or one stamped before the epoch) holds at any time.
        let stamp_ns = if is_static {
            0
        } else {
            t.header.stamp.as_nanos().unwrap_or(0)
        };
        match FrameLink::new(
            &t.header.frame_id,
            &t.child_frame_id,
            stamp_ns,
            [p.x, p.y, p.z],
            [q.x, q.y, q.z, q.w],
        ) {
            Ok(link) => out.links.push(link),
            Err(what) => out.bad_links.push(format!("{topic}: {what}")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::info_topic;

    #[test]
    fn the_camera_info_topic_is_the_image_topic_s_sibling() {
        assert_eq!(info_topic("/camera/image_raw"), "/camera/camera_info");
        assert_eq!(
            info_topic("/camera/color/image_raw/compressed"),
            "/camera/color/camera_info"
        );
        assert_eq!(info_topic("/image_raw/"), "/camera_info");
        assert_eq!(info_topic("image"), "camera_info");
    }

    #[test]
    fn image_procs_rectified_topics_are_told_apart() {
        assert!(super::is_rectified("/camera/image_rect"));
        assert!(super::is_rectified(
            "/cam/color/image_rect_color/compressed"
        ));
        assert!(!super::is_rectified("/camera/image_raw"));
        assert!(!super::is_rectified("/image_rect/foo"));
    }
}
