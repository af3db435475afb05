//! The robot site's camera (`avatarm serve --webcam N`, `--camera-recording FILE.mcap`): the
//! simulated room's, a webcam, or a recording played as a live camera with its robot as the
//! robot ([`avatarm_core::sim::recorded`]), so that a machine with neither runs the real frame
//! path end to end (a CPU frame arriving, uploaded, erased, read back, coded, published).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use avatarm_core::sim::JointState;
use avatarm_core::sim::recorded::{Playback, RecordedArm};
use avatarm_scene::Scene;
use avatarm_scene::spec::BackgroundSpec;
use avatarm_video::recorded::{CodedFrame, PlayerCounters, RecordedCameraConfig};

use crate::AppError;
use crate::app::CameraSource;

/// Where the camera comes from (`serve` and `run`: `--webcam N`, `--camera-recording FILE`).
#[derive(Debug, Clone, Default, PartialEq)]
pub enum SiteCamera {
    /// The simulated room's camera.
    #[default]
    Simulated,
    /// A webcam by its index (feature `webcam`).
    Webcam(u32),
    /// A recording (MCAP) played as the camera, its joint states as the robot's.
    Recording(PathBuf),
    /// A ROS 2 camera topic (`Image`, or `CompressedImage` on a `/compressed` topic) over DDS or
    /// rmw_zenoh (feature `ros`; the domain of the scene's `ros2_control` link, else
    /// `ROS_DOMAIN_ID`, else 0), its size, K and lens from the driver's `CameraInfo` and, where
    /// `pose_from_tf`, its pose from `/tf` ([`super::driver_calibration`]).
    Ros2 {
        /// The image topic.
        topic: String,
        /// Whether the believed pose is chained from `/tf` (not where `--believed-pose`
        /// gave one).
        pose_from_tf: bool,
    },
}

impl SiteCamera {
    /// The camera the command line names (clap keeps the flags apart); `pose_given`: the
    /// command line gave the believed pose (`--believed-pose`).
    pub fn of(
        webcam: Option<u32>,
        recording: Option<PathBuf>,
        ros2: Option<String>,
        pose_given: bool,
    ) -> Self {
        match (webcam, recording, ros2) {
            (Some(index), _, _) => Self::Webcam(index),
            (None, Some(path), _) => Self::Recording(path),
            (None, None, Some(topic)) => Self::Ros2 {
                topic,
                pose_from_tf: !pose_given,
            },
            (None, None, None) => Self::Simulated,
        }
    }
}

/// The ROS 2 domain of `scene`: its `ros2_control` link's (checked at load), else
/// `ROS_DOMAIN_ID`, else 0. Errors: a `ROS_DOMAIN_ID` that is not a number within 0..232.
pub fn ros2_domain(scene: &Scene) -> Result<u16, AppError> {
    let link = &scene.file.robot.link;
    if let Some(d) = link
        .domain_id
        .filter(|_| link.kind == avatarm_scene::spec::RobotLinkKind::Ros2Control)
    {
        return Ok(d);
    }
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(text) if text.trim().is_empty() => Ok(0),
        Ok(text) => text
            .trim()
            .parse::<u16>()
            .ok()
            .filter(|d| *d <= 232)
            .ok_or_else(|| {
                AppError::flag(
                    "ROS_DOMAIN_ID",
                    format!("'{text}': a DDS domain is a number within 0..232"),
                )
            }),
        Err(_) => Ok(0),
    }
}

/// Where `scene`'s ROS 2 nodes are: its domain ([`ros2_domain`]), namespace (its
/// `ros2_control` link's, else `/`) and middleware (the link's `rmw`, else
/// `RMW_IMPLEMENTATION`, else DDS; on rmw_zenoh the link's `zenoh_router`, else rmw_zenoh's
/// default: `ZENOH_SESSION_CONFIG_URI`, else `tcp/localhost:7447`). Errors name
/// `ROS_DOMAIN_ID` or `RMW_IMPLEMENTATION`.
#[cfg(feature = "ros")]
pub fn ros2_transport(scene: &Scene) -> Result<avatarm_ros::Ros2Transport, AppError> {
    use avatarm_ros::Rmw;
    use avatarm_scene::spec::{RobotLinkKind, Ros2Rmw};
    let link = &scene.file.robot.link;
    let ros2_link = link.kind == RobotLinkKind::Ros2Control;
    let router = link.zenoh_router.clone().filter(|_| ros2_link);
    let rmw = match link.rmw.filter(|_| ros2_link) {
        Some(Ros2Rmw::Dds) => Rmw::Dds,
        Some(Ros2Rmw::Zenoh) => Rmw::Zenoh { router },
        None => match std::env::var("RMW_IMPLEMENTATION") {
            Ok(name) => Rmw::from_implementation(&name, router)
                .map_err(|e| AppError::flag("RMW_IMPLEMENTATION", e))?,
            Err(_) => Rmw::Dds,
        },
    };
    // A router given to a link that ends up on DDS would be silently unused.
    if rmw == Rmw::Dds
        && let Some(r) = link.zenoh_router.as_ref().filter(|_| ros2_link)
    {
        return Err(AppError::flag(
            "robot.link.zenoh_router",
            format!(
                "'{r}' is given but the link is on DDS (rmw unset and RMW_IMPLEMENTATION not rmw_zenoh_cpp); set rmw = \"zenoh\" or RMW_IMPLEMENTATION=rmw_zenoh_cpp, or leave the router out"
            ),
        ));
    }
    Ok(avatarm_ros::Ros2Transport {
        domain_id: ros2_domain(scene)?,
        namespace: link
            .namespace
            .clone()
            .filter(|_| ros2_link)
            .unwrap_or_else(|| "/".into()),
        rmw,
    })
}

/// The camera opened: its source for the video app and, for a recording, the robot it plays.
#[derive(Debug)]
pub struct OpenedCamera {
    /// The video app's source.
    pub source: CameraSource,
    /// The recording's robot.
    pub arm: Option<RecordedArm>,
    /// What the user should know (the simulated empty room dropped as the background; a
    /// recording's camera that is not the scene's, joints it never names, what is played),
    /// for the caller to say: its log may not be set up yet.
    pub notes: Vec<String>,
}

/// Opens `camera` for `scene` (seen through `views` cameras in all; `scene` may be changed:
/// the simulated empty room is no background for a real camera). Errors: a real camera with
/// more than one view or a camera on a head, a webcam in a build without the feature, a
/// recording that cannot be read or played (no frames, frames of another size than the
/// scene's camera, joints the robot does not have).
pub fn open(
    camera: &SiteCamera,
    scene: &mut Scene,
    views: usize,
) -> Result<OpenedCamera, AppError> {
    let flag = match camera {
        SiteCamera::Simulated => {
            return Ok(OpenedCamera {
                source: CameraSource::Simulated,
                arm: None,
                notes: Vec::new(),
            });
        }
        SiteCamera::Webcam(_) => "--webcam",
        SiteCamera::Recording(_) => "--camera-recording",
        SiteCamera::Ros2 { .. } => "--ros2-camera",
    };
    if views > 1 {
        return Err(AppError::flag(
            flag,
            format!(
                "a real camera is one camera: one --view of the scene '{}'",
                scene.file.name
            ),
        ));
    }
    if scene.head.is_some() {
        return Err(AppError::flag(
            flag,
            format!(
                "the camera '{}' rides on a head, whose poses only the simulated head gives yet; use a scene with a fixed camera",
                scene.camera_name()
            ),
        ));
    }
    let mut notes = Vec::new();
    if scene.file.background == BackgroundSpec::EmptyRoom {
        scene.file.background = BackgroundSpec::None;
        notes.push(format!(
            "{flag}: the simulated empty room is no background for a real camera; give a photograph of the empty room with --background PATH (or the scene's [background]), or press B in the preview with the robot out of view"
        ));
    }
    let (source, arm) = match camera {
        SiteCamera::Simulated => unreachable!("returned above"),
        SiteCamera::Webcam(index) => {
            if !cfg!(feature = "webcam") {
                return Err(AppError::flag(
                    "--webcam",
                    "this avatarm was built without the webcam feature; rebuild with `cargo build --features webcam`",
                ));
            }
            (CameraSource::Webcam(*index), None)
        }
        SiteCamera::Recording(path) => {
            let (camera, arm) = open_recording(path, scene, &mut notes)?;
            (CameraSource::Recording(camera), Some(arm))
        }
        #[cfg(feature = "ros")]
        SiteCamera::Ros2 {
            topic,
            pose_from_tf,
        } => {
            let topic = avatarm_ros::ros2::camera::CameraTopic {
                transport: ros2_transport(scene)?,
                topic: topic.clone(),
                node_name: "avatarm_camera".into(),
            };
            super::driver_calibration::from_driver(&topic, scene, *pose_from_tf, &mut notes)?;
            (CameraSource::Ros2(topic), None)
        }
        #[cfg(not(feature = "ros"))]
        SiteCamera::Ros2 { .. } => {
            return Err(AppError::flag(
                "--ros2-camera",
                "this avatarm was built without the ros feature; rebuild with `cargo build --features ros`",
            ));
        }
    };
    Ok(OpenedCamera { source, arm, notes })
}

/// A recording's frames and joints, played from now; what the user should know into `notes`.
fn open_recording(
    path: &Path,
    scene: &Scene,
    notes: &mut Vec<String>,
) -> Result<(RecordedCameraConfig, RecordedArm), AppError> {
    let name = path.display().to_string();
    let bad = |message: String| AppError::recording(name.clone(), message);
    let recording = avatarm_record::Recording::open(path)?;
    if recording.camera_on_head() {
        return Err(bad(
            "the recording's camera rides on a head, whose recorded poses are not played yet; use a recording of a fixed camera".into(),
        ));
    }
    let first = recording
        .frames
        .first()
        .ok_or_else(|| bad("the recording has no camera frames".into()))?;
    let size = avatarm_footage::recording::decode(first, &name)?.dimensions();
    let k = &scene.believed_camera.intrinsics;
    if size != (k.width, k.height) {
        return Err(bad(format!(
            "its frames are {}x{}, the scene's camera '{}' is {}x{}",
            size.0,
            size.1,
            scene.camera_name(),
            k.width,
            k.height
        )));
    }
    if let Some(c) = &recording.calibration {
        let theirs = [c.k[0], c.k[4], c.k[2], c.k[5]];
        let ours = [k.fx, k.fy, k.cx, k.cy];
        if theirs.iter().zip(&ours).any(|(a, b)| (a - b).abs() > 0.5) {
            notes.push(format!(
                "{name}: the recording's camera (fx fy cx cy {theirs:?} px) is not the scene's ({ours:?} px); the scene's is used"
            ));
        }
    }
    let mut joint_notes = Vec::new();
    let joints = avatarm_footage::recording::joint_vectors(
        &recording,
        &scene.model,
        &name,
        &mut joint_notes,
    )?;
    notes.extend(joint_notes.into_iter().map(|n| format!("{name}: {n}")));
    let frames: Arc<[CodedFrame]> = recording
        .frames
        .iter()
        .map(|f| CodedFrame {
            stamp_s: f.stamp_ns as f64 * 1e-9,
            data: f.data.as_slice().into(),
        })
        .collect();
    let stamps: Vec<f64> = frames.iter().map(|f| f.stamp_s).collect();
    let playback = Playback::new(&format!("{name}: camera frames"), Instant::now(), &stamps)
        .map_err(|e| bad(e.to_string()))?;
    let states = lap_of_joints(joints, &playback, &name, notes)?;
    // The joints on the frames' timeline: each frame meets the joints it was recorded with.
    let arm = RecordedArm::new(
        format!("recording {}", file_name(path)),
        states,
        Playback::with_lap(
            &name,
            playback_start(&playback),
            playback.first_s(),
            playback.lap_s(),
        )
        .map_err(|e| bad(e.to_string()))?,
    )
    .map_err(|e| bad(e.to_string()))?;
    notes.push(format!(
        "camera: {name}, {} frames of {}x{} over {:.1} s, played in a loop; the robot is the recording's ({} joint states; commands are not obeyed)",
        frames.len(),
        size.0,
        size.1,
        playback.lap_s(),
        recording.joint_states.len()
    ));
    let camera = RecordedCameraConfig {
        name: file_name(path),
        frames,
        playback,
        counters: Arc::new(PlayerCounters::default()),
    };
    Ok((camera, arm))
}

/// The recording's joint states that fall in one lap of the frames' playback (from the first
/// frame's capture to a frame period after the last's): the lap repeats, and a state outside
/// it would be released out of order. States of one stamp (a message per group of joints)
/// are one state, the last. Errors: no state in the lap.
fn lap_of_joints(
    joints: Vec<(u64, nalgebra::DVector<f64>)>,
    playback: &Playback,
    name: &str,
    notes: &mut Vec<String>,
) -> Result<Vec<JointState>, AppError> {
    let (first, end) = (playback.first_s(), playback.first_s() + playback.lap_s());
    let total = joints.len();
    let mut states: Vec<JointState> = Vec::with_capacity(total);
    for (stamp_ns, q) in joints {
        let stamp_s = stamp_ns as f64 * 1e-9;
        if !(first..end).contains(&stamp_s) {
            continue;
        }
        let state = JointState {
            stamp_s,
            velocities: nalgebra::DVector::zeros(0),
            positions: q,
        };
        match states.last_mut() {
            Some(last) if last.stamp_s == stamp_s => *last = state,
            // Out of order (a recording's are not): left out.
            Some(last) if last.stamp_s > stamp_s => {}
            _ => states.push(state),
        }
    }
    if states.is_empty() {
        return Err(AppError::recording(
            name.to_owned(),
            format!(
                "none of its {total} joint states falls between its first and last camera frames"
            ),
        ));
    }
    if states.len() < total {
        notes.push(format!(
            "{name}: {} of {total} joint states played (those between the first and last camera frames, one per stamp)",
            states.len()
        ));
    }
    Ok(states)
}

/// When a playback's first sample is released.
fn playback_start(playback: &Playback) -> Instant {
    playback.release(playback.first_s(), 0)
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Joints outside the frames' lap are left out (they would be released out of order in a
    /// loop), one state per stamp is kept (the last), and a recording whose joints all fall
    /// outside is refused naming it.
    #[test]
    fn the_joints_played_are_one_lap_of_the_frames_one_per_stamp() {
        let start = Instant::now();
        // Frames at 10.0, 10.1, 10.2 s: a lap of 0.3 s from 10.0.
        let playback = Playback::new("frames", start, &[10.0, 10.1, 10.2]).expect("valid");
        let q = |v: f64| nalgebra::DVector::from_element(2, v);
        let ns = |s: f64| (s * 1e9).round() as u64;
        let joints = vec![
            (ns(9.9), q(0.0)),
            (ns(10.0), q(1.0)),
            (ns(10.05), q(2.0)),
            (ns(10.05), q(3.0)),
            (ns(10.25), q(4.0)),
            (ns(10.35), q(5.0)),
        ];
        let mut notes = Vec::new();
        let states = lap_of_joints(joints, &playback, "rec.mcap", &mut notes).expect("states");
        assert!(notes.iter().any(|n| n.contains("3 of 6")), "{notes:?}");
        let kept: Vec<f64> = states.iter().map(|s| s.positions[0]).collect();
        assert_eq!(kept, [1.0, 3.0, 4.0]);
        let e = lap_of_joints(vec![(ns(20.0), q(0.0))], &playback, "rec.mcap", &mut notes)
            .expect_err("none in the lap");
        assert!(e.to_string().contains("rec.mcap"), "{e}");
        // The arm takes them as they are.
        let lap = Playback::with_lap("joints", start, 10.0, playback.lap_s()).expect("valid");
        assert!(RecordedArm::new("rec", states, lap).is_ok());
        assert!(Playback::with_lap("joints", start, f64::NAN, 0.3).is_err());
        assert!(Playback::with_lap("joints", start, 0.0, 0.0).is_err());
    }
}
