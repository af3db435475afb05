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
use bevy::log::{info, warn};

use crate::AppError;
use crate::app::CameraSource;

/// Where the robot site's camera comes from.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum SiteCamera {
    /// The simulated room's camera.
    #[default]
    Simulated,
    /// A webcam by its index (feature `webcam`).
    Webcam(u32),
    /// A recording (MCAP) played as the camera, its joint states as the robot's.
    Recording(PathBuf),
}

/// The camera opened: its source for the video app and, for a recording, the robot it plays.
pub(crate) struct OpenedCamera {
    /// The video app's source.
    pub(crate) source: CameraSource,
    /// The recording's robot.
    pub(crate) arm: Option<RecordedArm>,
}

/// Opens `camera` for `scene` (served with `views` cameras in all; `scene` may be changed:
/// the simulated empty room is no background for a real camera). Errors: a real camera with
/// more than one view or a camera on a head, a webcam in a build without the feature, a
/// recording that cannot be read or played (no frames, frames of another size than the
/// scene's camera, joints the robot does not have).
pub(crate) fn open(
    camera: &SiteCamera,
    scene: &mut Scene,
    views: usize,
) -> Result<OpenedCamera, AppError> {
    let flag = match camera {
        SiteCamera::Simulated => {
            return Ok(OpenedCamera {
                source: CameraSource::Simulated,
                arm: None,
            });
        }
        SiteCamera::Webcam(_) => "--webcam",
        SiteCamera::Recording(_) => "--camera-recording",
    };
    if views > 1 {
        return Err(AppError::flag(
            flag,
            format!(
                "a real camera is one camera: serve one --view of the scene '{}'",
                scene.file.name
            ),
        ));
    }
    if scene.head.is_some() {
        return Err(AppError::flag(
            flag,
            format!(
                "the camera '{}' rides on a head, whose poses only the simulated head gives yet; serve a fixed camera",
                scene.camera_name()
            ),
        ));
    }
    if scene.file.background == BackgroundSpec::EmptyRoom {
        warn!(
            "{flag}: the simulated empty room is no background for a real camera; the erase has none until the scene's [background] gives a photograph of the empty room (source = \"file\")"
        );
        scene.file.background = BackgroundSpec::None;
    }
    match camera {
        SiteCamera::Simulated => unreachable!("returned above"),
        SiteCamera::Webcam(index) => {
            if !cfg!(feature = "webcam") {
                return Err(AppError::flag(
                    "--webcam",
                    "this avatarm was built without the webcam feature; rebuild with `cargo build --features webcam`",
                ));
            }
            Ok(OpenedCamera {
                source: CameraSource::Webcam(*index),
                arm: None,
            })
        }
        SiteCamera::Recording(path) => open_recording(path, scene),
    }
}

/// A recording's frames and joints, played from now.
fn open_recording(path: &Path, scene: &Scene) -> Result<OpenedCamera, AppError> {
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
    let size = crate::replay::recording::decode(first, &name)?.dimensions();
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
            warn!(
                "{name}: the recording's camera (fx fy cx cy {theirs:?} px) is not the scene's ({ours:?} px); the scene's is used"
            );
        }
    }
    let mut notes = Vec::new();
    let joints =
        crate::replay::recording::joint_vectors(&recording, &scene.model, &name, &mut notes)?;
    for note in notes {
        warn!("{name}: {note}");
    }
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
    let states: Vec<JointState> = joints
        .into_iter()
        .map(|(stamp_ns, q)| JointState {
            stamp_s: stamp_ns as f64 * 1e-9,
            velocities: nalgebra::DVector::zeros(0),
            positions: q,
        })
        .collect();
    // The joints on the frames' timeline: each frame meets the joints it was recorded with.
    let arm = RecordedArm::new(
        format!("recording {}", file_name(path)),
        states,
        Playback::with_lap(
            playback_start(&playback),
            playback.first_s(),
            playback.lap_s(),
        ),
    )
    .map_err(|e| bad(e.to_string()))?;
    info!(
        "camera: {name}, {} frames of {}x{} over {:.1} s, played in a loop; the robot is the recording's ({} joint states; commands are not obeyed)",
        frames.len(),
        size.0,
        size.1,
        playback.lap_s(),
        recording.joint_states.len()
    );
    Ok(OpenedCamera {
        source: CameraSource::Recording(RecordedCameraConfig {
            name: file_name(path),
            frames,
            playback,
            counters: Arc::new(PlayerCounters::default()),
        }),
        arm: Some(arm),
    })
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
