//! What a recording gives the erase and the calibration, read the same way by `avatarm replay
//! --recording`, `avatarm calibrate` and a robot site serving a recording: its camera
//! (calibration checked against the frames, and the pinhole intrinsics of its K), a head
//! camera's mount, the joint vectors in a description's order, the joints at any stamp and
//! decoded frames. Each error names the recording (as given) or the flag at fault.

use std::path::Path;

use avatarm_core::robot::RobotModel;
use avatarm_core::vision::camera::Intrinsics;
use avatarm_record::camera::{CameraCalibration, read_calibration, read_mount};
use avatarm_record::{CompressedFrame, Recording};
use nalgebra::{DVector, Isometry3};

use crate::FootageError;

/// A recording of a camera on a head: its mount (`head_from_camera`), from `mount_file` or
/// else the recording's; `None` for a fixed camera. Errors: `pose_flag` (a fixed camera's pose
/// given on the command line) for a camera on a head, `mount_flag` for a fixed camera, a
/// camera on a head with no tracked head pose, or with no mount at all.
pub fn recording_mount(
    recording: &Recording,
    mount_file: Option<&Path>,
    pose_flag: Option<&str>,
    mount_flag: &str,
    name: &str,
) -> Result<Option<Isometry3<f64>>, FootageError> {
    let bad = |message: String| FootageError::input(name, message);
    if !recording.camera_on_head() {
        return match mount_file {
            Some(_) => Err(FootageError::input(
                mount_flag,
                format!(
                    "{name}: the recording's camera is fixed, not on a head: give its pose with --pose"
                ),
            )),
            None => Ok(None),
        };
    }
    if let Some(flag) = pose_flag {
        return Err(FootageError::input(
            flag,
            format!(
                "{name}: the camera rides on a head ({} tracked head poses): its pose is the head's times the mount; give the mount with {mount_flag} FILE (head_from_camera), or none for the recording's",
                recording.head_poses.len()
            ),
        ));
    }
    if recording.head_poses.is_empty() {
        return Err(bad(
            "the camera rides on a head (the recording has its mount) but there is no tracked head pose".into(),
        ));
    }
    match mount_file {
        Some(path) => Ok(Some(read_mount(path)?)),
        None => recording.head_from_camera.map(Some).ok_or_else(|| {
            bad(format!(
                "the recording has head poses but no mount: give one with {mount_flag} FILE"
            ))
        }),
    }
}

/// A recording's camera: its calibration (or `camera`, a camera file, instead) checked against
/// the frames' size, and the pinhole intrinsics from its K. Errors: no frames, no calibration,
/// a calibration for another image size.
pub fn recording_camera(
    recording: &Recording,
    camera: Option<&Path>,
    name: &str,
) -> Result<(CameraCalibration, Intrinsics), FootageError> {
    let bad = |message: String| FootageError::input(name, message);
    let first = recording
        .frames
        .first()
        .ok_or_else(|| bad("the recording has no camera frames".into()))?;
    let size = decode(first, name)?.dimensions();
    let calibration = match camera {
        Some(path) => read_calibration(path, Some(size))?,
        None => recording.calibration.clone().ok_or_else(|| {
            bad("the recording has no camera calibration: give one with --camera FILE".into())
        })?,
    };
    if (calibration.width, calibration.height) != size {
        return Err(bad(format!(
            "the calibration is for {}x{} images, the frames are {}x{}",
            calibration.width, calibration.height, size.0, size.1
        )));
    }
    let k = calibration.k;
    let intrinsics = Intrinsics {
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
        width: size.0,
        height: size.1,
    };
    Ok((calibration, intrinsics))
}

/// The recording's joint states in the description's q order, by stamp. Errors name a joint
/// the description does not have; joints the recording never names stay at 0 (said in the
/// notes).
pub fn joint_vectors(
    recording: &Recording,
    model: &RobotModel,
    name: &str,
    notes: &mut Vec<String>,
) -> Result<Vec<(u64, DVector<f64>)>, FootageError> {
    if recording.joint_states.is_empty() {
        return Err(FootageError::input(
            name,
            "the recording has no joint states",
        ));
    }
    let mut named = vec![false; model.dof()];
    let mut q = DVector::zeros(model.dof());
    let mut out = Vec::with_capacity(recording.joint_states.len());
    for s in &recording.joint_states {
        for (joint, &v) in s.names.iter().zip(&s.positions) {
            match model.dof_index(joint) {
                Ok(i) => {
                    q[i] = v;
                    named[i] = true;
                }
                // A mimic joint follows its leader (ROS names it too).
                Err(avatarm_core::Error::MimicJoint { .. }) => {}
                Err(_) => {
                    return Err(FootageError::input(
                        name,
                        format!(
                            "joint states at {} ns: joint '{joint}' is not in the description '{}'",
                            s.stamp_ns, model.name
                        ),
                    ));
                }
            }
        }
        out.push((s.stamp_ns, q.clone()));
    }
    let never: Vec<&str> = model
        .dof_names()
        .into_iter()
        .zip(&named)
        .filter(|(_, n)| !**n)
        .map(|(j, _)| j)
        .collect();
    if !never.is_empty() {
        notes.push(format!(
            "joints the recording never names, held at 0: {}",
            never.join(", ")
        ));
    }
    Ok(out)
}

/// The joints at `stamp_ns`: linear between the two states around it, the first before the
/// first, the last after the last.
pub fn interpolate(states: &[(u64, DVector<f64>)], stamp_ns: u64) -> DVector<f64> {
    let i = states.partition_point(|s| s.0 <= stamp_ns);
    match (i.checked_sub(1).map(|j| &states[j]), states.get(i)) {
        (Some(a), Some(b)) if b.0 > a.0 => {
            let s = (stamp_ns - a.0) as f64 / (b.0 - a.0) as f64;
            &a.1 + (&b.1 - &a.1) * s
        }
        (Some(a), _) => a.1.clone(),
        (None, Some(b)) => b.1.clone(),
        (None, None) => DVector::zeros(0),
    }
}

/// The frame decoded to RGBA8. Errors: a frame its format's decoder refuses, naming the
/// recording, the format and the stamp.
pub fn decode(f: &CompressedFrame, name: &str) -> Result<image::RgbaImage, FootageError> {
    image::load_from_memory(&f.data)
        .map(|i| i.to_rgba8())
        .map_err(|e| {
            FootageError::input(
                name,
                format!(
                    "the {} image at {} ns cannot be decoded: {e}",
                    f.format.name(),
                    f.stamp_ns
                ),
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joints_are_interpolated_to_the_capture_time() {
        let v = |x: f64| DVector::from_vec(vec![x, -x]);
        let states = vec![(100, v(0.0)), (200, v(1.0)), (400, v(3.0))];
        assert_eq!(interpolate(&states, 150), v(0.5));
        assert_eq!(interpolate(&states, 300), v(2.0));
        assert_eq!(
            interpolate(&states, 50),
            v(0.0),
            "the first before the first"
        );
        assert_eq!(interpolate(&states, 900), v(3.0), "the last after the last");
        assert_eq!(interpolate(&states, 200), v(1.0));
    }
}
