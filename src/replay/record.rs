//! `replay --record`: a simulated session written as a recording (frames, reference masks, the
//! camera), and the scene's camera as a file.

use super::*;

/// One scored frame as `--record` writes it (PNG bytes, the robot's joints at capture).
pub(super) struct RecordedFrame {
    pub(super) t_s: f64,
    pub(super) frame: Vec<u8>,
    pub(super) truth: Vec<u8>,
    pub(super) erased: Vec<u8>,
    pub(super) mask: Vec<u8>,
    pub(super) q_true: Vec<f64>,
}

/// PNG bytes of an RGBA8 image (as RGB) or of a 0/1 mask (as 0/255 grey).
pub(super) fn png_bytes(
    width: u32,
    height: u32,
    data: &[u8],
    mask: bool,
) -> Result<Vec<u8>, AppError> {
    let image = if mask {
        image::GrayImage::from_raw(width, height, data.iter().map(|&v| v * 255).collect())
            .map(image::DynamicImage::ImageLuma8)
    } else {
        image::RgbaImage::from_raw(width, height, data.to_vec())
            .map(|i| image::DynamicImage::ImageRgb8(image::DynamicImage::ImageRgba8(i).to_rgb8()))
    }
    .ok_or(AppError::ImageSize {
        what: "recorded frame".into(),
        width,
        height,
    })?;
    let mut out = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut out, image::ImageFormat::Png)
        .map_err(|source| AppError::write_image("(recording)", source))?;
    Ok(out.into_inner())
}

/// The scene's believed camera as a recording's calibration: K, the size and the lens, as its
/// `camera_info` would give them.
pub(crate) fn scene_calibration(s: &avatarm_scene::Scene) -> avatarm_record::CameraCalibration {
    let k = &s.believed_camera.intrinsics;
    let mut calibration = avatarm_record::CameraCalibration::pinhole(
        k.width,
        k.height,
        [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
    );
    if let Some(model) = avatarm_record::DistortionModel::from_ros_name(s.lens.ros_name()) {
        calibration.distortion_model = model;
        calibration.d = s.lens.coefficients().to_vec();
    }
    calibration
}

/// Writes the scene's believed camera's place at `stamp_ns`: its pose in the robot's base
/// frame, or for a camera on a head the believed mount (the head's poses follow as they are
/// tracked).
pub(crate) fn write_scene_camera(
    w: &mut avatarm_record::RecordingWriter,
    stamp_ns: u64,
    s: &avatarm_scene::Scene,
) -> Result<(), avatarm_record::RecordError> {
    match &s.head {
        Some(head) => w.camera_mount(stamp_ns, &head.believed_mount),
        None => w.camera_pose(
            stamp_ns,
            &(s.robot_base().inverse() * s.believed_camera.world_from_camera),
        ),
    }
}

/// Writes `--record`'s MCAP: the believed camera ([`write_scene_camera`]; for a camera on a
/// head, every tracked head pose received), and per scored frame the frame, the simulated
/// robot's joints at capture, the true silhouette as the reference mask, Avatarm's erased
/// frame and mask; stamped with the capture time.
pub(super) fn write_recording(
    path: &Path,
    replay: &Replay,
    scene: &SceneResource,
) -> Result<(), AppError> {
    use avatarm_record::{CompressedFrame, ImageFormat, JointStates, RecordingWriter};
    let s = &scene.0;
    let mut w = RecordingWriter::create(path)?;
    let ns = |t: f64| (t.max(0.0) * 1e9).round() as u64;
    let first = replay
        .recorded
        .iter()
        .map(|r| r.t_s)
        .fold(f64::INFINITY, f64::min);
    let t0 = ns(if first.is_finite() { first } else { 0.0 });
    w.calibration(t0, &scene_calibration(s))?;
    write_scene_camera(&mut w, t0, s)?;
    let base_from_world = s.robot_base().inverse();
    for (stamp_s, world_from_head) in &replay.head_poses {
        w.head_pose(&avatarm_record::HeadPose {
            stamp_ns: ns(*stamp_s),
            base_from_head: base_from_world * world_from_head,
        })?;
    }
    let names: Vec<String> = s.model.dof_names().iter().map(|n| n.to_string()).collect();
    let mut frames: Vec<&RecordedFrame> = replay.recorded.iter().collect();
    frames.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    for r in frames {
        let stamp_ns = ns(r.t_s);
        let png = |data: &Vec<u8>| CompressedFrame {
            stamp_ns,
            format: ImageFormat::Png,
            data: data.clone(),
        };
        if r.q_true.len() == names.len() {
            w.joint_states(&JointStates {
                stamp_ns,
                names: names.clone(),
                positions: r.q_true.clone(),
                velocities: Vec::new(),
            })?;
        }
        w.frame(&png(&r.frame))?;
        w.reference_mask(&png(&r.truth))?;
        w.erased(&png(&r.erased))?;
        w.mask(&png(&r.mask))?;
    }
    w.finish()?;
    Ok(())
}
