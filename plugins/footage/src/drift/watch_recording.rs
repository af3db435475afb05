//! The drift watch over a recording's frames, as `avatarm replay --recording` runs it.

use avatarm_core::robot::RobotModel;
use avatarm_core::vision::calibrate::RobotSilhouette;
use avatarm_core::vision::camera::Intrinsics;
use avatarm_core::vision::distortion::Distortion;
use avatarm_record::CompressedFrame;
use nalgebra::{DVector, Isometry3};

use super::{DriftReport, DriftSettings, DriftWatch};
use crate::FootageError;
use crate::recording::decode;

/// Triangles the watch draws the robot with (as `avatarm calibrate`'s default).
const TRIANGLES: usize = 6000;

/// Watches a fixed camera over a recording's `frames` (by capture time), each with its joints
/// `q[i]` (the model's q order, at the frame's capture), the camera `k` with `lens` believed
/// at `base_from_camera` (its optical frame in the robot's base frame) and its mask dilated by
/// `margin_px`. Each due frame is decoded and checked ([`DriftWatch::check`]); `progress(done,
/// total)` is told of the frames. Returns the report and the pose believed at each frame
/// (`base_from_camera`), which changes at the frame that confirmed each drift.
///
/// Errors: a frame that does not decode (naming the recording `name` and the stamp), a frame of
/// another size, joints of another count, bad settings.
pub fn watch_recording(
    (frames, q): (&[CompressedFrame], &[DVector<f64>]),
    model: &RobotModel,
    (k, lens): (Intrinsics, Distortion),
    base_from_camera: Isometry3<f64>,
    margin_px: u32,
    settings: DriftSettings,
    (name, mut progress): (&str, impl FnMut(usize, usize)),
) -> Result<(DriftReport, Vec<Isometry3<f64>>), FootageError> {
    if frames.len() != q.len() {
        return Err(FootageError::input(
            name,
            format!("{} frames but {} joint vectors", frames.len(), q.len()),
        ));
    }
    let silhouette = RobotSilhouette::new(model, TRIANGLES)?;
    let mut watch = DriftWatch::new(
        model,
        &silhouette,
        (k, lens),
        base_from_camera.inverse(),
        margin_px,
        settings,
    )?;
    let mut poses = Vec::with_capacity(frames.len());
    for (i, (f, qi)) in frames.iter().zip(q).enumerate() {
        if watch.due(f.stamp_ns) {
            let rgba = decode(f, name)?;
            let q: Vec<f64> = qi.iter().copied().collect();
            watch.check(i, f.stamp_ns, &rgba, &q)?;
        }
        poses.push(watch.camera_from_base().inverse());
        progress(i + 1, frames.len());
    }
    Ok((watch.report(), poses))
}
