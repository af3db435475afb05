//! A ROS 2 camera's calibration from its driver (`--ros2-camera TOPIC`, feature `ros`): before
//! the camera is used, its `CameraInfo` (the image topic's `camera_info`) and the transform
//! tree (`/tf_static`, `/tf`) are gathered for up to [`CALIBRATION_WAIT`]; the scene's camera
//! then takes the driver's size, K and lens, and the pose the app believes is chained through
//! the tree from the robot description's root link to CameraInfo's optical frame (REP 104),
//! unless `--believed-pose` gave one. What is missing or wrong leaves the scene's, said in
//! the notes with what to do.

use std::time::Duration;

use avatarm_core::tf::chain;
use avatarm_core::vision::camera::Intrinsics;
use avatarm_core::vision::distortion::Distortion;
use avatarm_record::camera::CameraCalibration;
use avatarm_ros::ros2::calibration::{CameraInfo, DriverCalibration, gather, is_rectified};
use avatarm_ros::ros2::camera::CameraTopic;
use avatarm_scene::Scene;

use crate::AppError;

/// How long the driver's `CameraInfo` and transforms are waited for (a driver publishes
/// CameraInfo with each frame and its static transforms latched: a fraction of a second where
/// they exist).
pub const CALIBRATION_WAIT: Duration = Duration::from_secs(3);

/// Gathers the driver's calibration for `topic` and applies it to `scene` ([`apply`]); the
/// pose too where `pose_from_tf`. Errors: the middleware could not be joined (named by the flag).
pub fn from_driver(
    topic: &CameraTopic,
    scene: &mut Scene,
    pose_from_tf: bool,
    notes: &mut Vec<String>,
) -> Result<(), AppError> {
    let root = scene
        .model
        .links
        .first()
        .map(|l| l.name.clone())
        .unwrap_or_default();
    let gathered = gather(topic, CALIBRATION_WAIT, |g| {
        g.info.as_ref().is_some_and(|i| {
            !pose_from_tf || chain(&g.links, &root, &i.header.frame_id, 0).is_some()
        })
    })
    .map_err(|e| AppError::flag("--ros2-camera", format!("{}: {e}", topic.topic)))?;
    apply(&gathered, scene, pose_from_tf, notes);
    Ok(())
}

/// Applies what the driver gave to `scene`: CameraInfo's size, K and lens (P and no lens for a
/// rectified `image_rect*` topic) to the true and believed cameras (unless it is missing,
/// uncalibrated (K zero), binned, cropped, a lens that does not invert over the image, or
/// refused),
/// and, where `pose_from_tf`, the believed camera's pose `world_from_camera = robot_base *
/// base_from_optical` chained from the description's root link at the newest transforms.
/// Each outcome is said in `notes`.
pub fn apply(
    driver: &DriverCalibration,
    scene: &mut Scene,
    pose_from_tf: bool,
    notes: &mut Vec<String>,
) {
    let topic = &driver.info_topic;
    let Some(info) = &driver.info else {
        let undecoded = driver
            .bad_info
            .as_ref()
            .map(|e| format!(" (one came that does not decode as CameraInfo: {e})"))
            .unwrap_or_default();
        notes.push(format!(
            "--ros2-camera: no CameraInfo on {topic} within {:.1} s{undecoded}: the scene's camera '{}' is used (its size, K and pose); a driver publishes it once calibrated (ROS's camera_calibration), or calibrate with avatarm calibrate",
            driver.waited.as_secs_f64(),
            scene.camera_name()
        ));
        return;
    };
    match intrinsics_of(info, is_rectified(&driver.image_topic)) {
        Ok((k, lens)) => {
            let before = scene.believed_camera.intrinsics;
            scene.true_camera.intrinsics = k;
            scene.believed_camera.intrinsics = k;
            scene.lens = lens;
            let c = &mut scene.file.camera;
            c.intrinsics = Some(k);
            (c.width, c.height) = (k.width, k.height);
            notes.push(format!(
                "--ros2-camera: the camera's calibration from {topic}: {}x{}, fx fy cx cy [{:.1}, {:.1}, {:.1}, {:.1}] px, lens {} (the scene's was {}x{}, [{:.1}, {:.1}, {:.1}, {:.1}])",
                k.width,
                k.height,
                k.fx,
                k.fy,
                k.cx,
                k.cy,
                match lens {
                    Distortion::None => "none".to_owned(),
                    _ => format!("{} {:?}", info.distortion_model, info.d),
                },
                before.width,
                before.height,
                before.fx,
                before.fy,
                before.cx,
                before.cy
            ));
        }
        Err(why) => notes.push(format!(
            "--ros2-camera: {topic}: {why}: the scene's camera '{}' is used",
            scene.camera_name()
        )),
    }
    if !pose_from_tf {
        return;
    }
    let root = scene.model.links.first().map_or("", |l| l.name.as_str());
    let optical = info.header.frame_id.trim_start_matches('/');
    let base_from_camera = (!optical.is_empty())
        .then(|| chain(&driver.links, root, optical, u64::MAX))
        .flatten();
    match base_from_camera {
        Some(p) => {
            scene.believed_camera.world_from_camera = scene.robot_base() * p;
            let t = p.translation.vector;
            notes.push(format!(
                "--ros2-camera: the camera's pose from /tf: {root} -> {optical}, at [{:.3}, {:.3}, {:.3}] m in {root}",
                t.x, t.y, t.z
            ));
        }
        None => {
            let frames = avatarm_core::tf::frames(&driver.links);
            let left_out = if driver.bad_links.is_empty() {
                String::new()
            } else {
                format!(
                    "; left out as not finite or not unit: {}",
                    driver.bad_links.join("; ")
                )
            };
            notes.push(format!(
                "--ros2-camera: /tf does not connect the robot's root link '{root}' to the camera's frame '{optical}' (frames seen: {}){left_out}: the scene's camera pose is used; publish the camera's mount (a static transform), or give --believed-pose FILE",
                if frames.is_empty() {
                    "none".to_owned()
                } else {
                    frames.join(", ")
                }
            ));
        }
    }
}

/// CameraInfo as the virtual camera's intrinsics and lens. Errors: K zero (uncalibrated),
/// binning or a region of interest (not applied), or what [`CameraCalibration`] and
/// [`Distortion`] refuse.
fn intrinsics_of(info: &CameraInfo, rectified: bool) -> Result<(Intrinsics, Distortion), String> {
    if info.k.iter().all(|&v| v == 0.0) {
        return Err("K is zero: the camera is not calibrated".into());
    }
    if info.binning_x > 1 || info.binning_y > 1 {
        return Err(format!(
            "binning {}x{} is not applied",
            info.binning_x, info.binning_y
        ));
    }
    let roi = &info.roi;
    if roi.width != 0 && (roi.width, roi.height) != (info.width, info.height) {
        return Err(format!(
            "a region of interest {}x{} at ({}, {}) is not applied",
            roi.width, roi.height, roi.x_offset, roi.y_offset
        ));
    }
    let c = CameraCalibration::from_camera_info(
        info.width,
        info.height,
        info.k,
        &info.distortion_model,
        info.d.clone(),
    )
    .map_err(|e| e.0)?;
    if rectified {
        // image_proc's rectified image: P's pinhole, no distortion left (REP 104's
        // CameraInfo: K and D are the raw image's).
        let p = &info.p;
        if !(p[0] > 0.0 && p[5] > 0.0 && p.iter().all(|v| v.is_finite())) {
            return Err(format!(
                "a rectified topic, but P has no focal length ({}, {})",
                p[0], p[5]
            ));
        }
        let k = Intrinsics {
            fx: p[0],
            fy: p[5],
            cx: p[2],
            cy: p[6],
            width: c.width,
            height: c.height,
        };
        return Ok((k, Distortion::None));
    }
    let k = Intrinsics {
        fx: c.k[0],
        fy: c.k[4],
        cx: c.k[2],
        cy: c.k[5],
        width: c.width,
        height: c.height,
    };
    let lens =
        Distortion::from_ros(c.distortion_model.ros_name(), &c.d).map_err(|e| e.to_string())?;
    // The mask is drawn through the lens: it must invert over the image.
    lens.check_over(&k).map_err(|e| e.to_string())?;
    Ok((k, lens))
}

#[cfg(test)]
mod tests {
    use avatarm_core::tf::FrameLink;
    use avatarm_ros::ros2::Header;
    use nalgebra::{Point3, Vector3};

    use super::*;

    fn scene() -> Scene {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/default.toml");
        Scene::load(&path, &Default::default()).expect("the default scene")
    }

    fn info(frame: &str) -> CameraInfo {
        CameraInfo {
            header: Header {
                frame_id: frame.into(),
                ..Header::default()
            },
            width: 1280,
            height: 720,
            distortion_model: "plumb_bob".into(),
            d: vec![0.1, -0.05, 0.0, 0.0, 0.0],
            k: [900.0, 0.0, 640.5, 0.0, 901.0, 360.5, 0.0, 0.0, 1.0],
            ..CameraInfo::default()
        }
    }

    /// The driver's CameraInfo becomes the scene's camera (size, K, lens) and its pose is
    /// chained through /tf from the description's root link to the optical frame.
    #[test]
    fn the_drivers_camera_info_and_tf_pose_become_the_scenes_camera() {
        let mut scene = scene();
        let root = scene.model.links[0].name.clone();
        let q = nalgebra::UnitQuaternion::from_euler_angles(-1.9, 0.0, 0.4);
        let (v, w) = (q.imag(), q.scalar());
        let links = vec![
            FrameLink::new(
                &root,
                "camera_link",
                0,
                [1.2, -0.3, 0.6],
                [0.0, 0.0, 0.0, 1.0],
            )
            .expect("good"),
            FrameLink::new(
                "camera_link",
                "camera_optical",
                0,
                [0.0, 0.0, 0.0],
                [v.x, v.y, v.z, w],
            )
            .expect("good"),
        ];
        let driver = DriverCalibration {
            info_topic: "/camera/camera_info".into(),
            info: Some(info("camera_optical")),
            links,
            ..DriverCalibration::default()
        };
        let mut notes = Vec::new();
        apply(&driver, &mut scene, true, &mut notes);
        let k = scene.believed_camera.intrinsics;
        assert_eq!((k.width, k.height, k.fx, k.cy), (1280, 720, 900.0, 360.5));
        assert_eq!(scene.true_camera.intrinsics, k);
        assert_eq!(
            (scene.file.camera.width, scene.file.camera.height),
            (1280, 720)
        );
        assert!(matches!(scene.lens, Distortion::PlumbBob(d) if d[0] == 0.1));
        let camera = scene.believed_camera.world_from_camera;
        let expected = scene.robot_base()
            * nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(1.2, -0.3, 0.6), q);
        assert!((camera * Point3::origin() - expected * Point3::origin()).norm() < 1e-9);
        assert!((camera * Vector3::z() - expected * Vector3::z()).norm() < 1e-9);
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(notes[1].contains("camera_optical"), "{notes:?}");
    }

    /// No CameraInfo, an uncalibrated one, a tree that does not reach the camera, or a pose
    /// the user gave: the scene's camera stays, said with what to do.
    #[test]
    fn what_the_driver_does_not_give_leaves_the_scenes_camera_and_is_said() {
        let before = scene();
        let unchanged = |s: &Scene| {
            s.believed_camera.intrinsics == before.believed_camera.intrinsics
                && s.believed_camera.world_from_camera == before.believed_camera.world_from_camera
        };
        let mut notes = Vec::new();
        let mut s = scene();
        apply(&DriverCalibration::default(), &mut s, true, &mut notes);
        assert!(
            unchanged(&s) && notes[0].contains("no CameraInfo"),
            "{notes:?}"
        );

        let mut uncalibrated = info("camera_optical");
        uncalibrated.k = [0.0; 9];
        let far = FrameLink::new("map", "odom", 0, [0.0; 3], [0.0, 0.0, 0.0, 1.0]).expect("good");
        let driver = DriverCalibration {
            info_topic: "/c/camera_info".into(),
            info: Some(uncalibrated),
            links: vec![far],
            bad_links: vec!["/tf: a -> b (translation [NaN, 0.0, 0.0], quaternion norm 1)".into()],
            ..DriverCalibration::default()
        };
        let (mut s, mut notes) = (scene(), Vec::new());
        apply(&driver, &mut s, true, &mut notes);
        assert!(unchanged(&s), "{notes:?}");
        assert!(notes[0].contains("not calibrated"), "{notes:?}");
        assert!(
            notes[1].contains("does not connect")
                && notes[1].contains("map, odom")
                && notes[1].contains("a -> b"),
            "{notes:?}"
        );

        // A pose given by the user: the tree is not asked; the size and K still taken.
        let driver = DriverCalibration {
            info: Some(info("camera_optical")),
            ..DriverCalibration::default()
        };
        let (mut s, mut notes) = (scene(), Vec::new());
        apply(&driver, &mut s, false, &mut notes);
        assert_eq!(
            s.believed_camera.world_from_camera,
            before.believed_camera.world_from_camera
        );
        assert_eq!(s.believed_camera.intrinsics.width, 1280);
        assert_eq!(notes.len(), 1, "{notes:?}");
    }

    /// A rectified topic is seen through P without a lens; a lens that folds over the image
    /// is refused as the scene's own would be.
    #[test]
    fn a_rectified_topic_takes_p_and_a_folding_lens_is_refused() {
        let mut rect = info("camera_optical");
        rect.p = [
            880.0, 0.0, 630.0, 0.0, 0.0, 882.0, 350.0, 0.0, 0.0, 0.0, 1.0, 0.0,
        ];
        let driver = DriverCalibration {
            image_topic: "/camera/image_rect_color/compressed".into(),
            info: Some(rect),
            ..DriverCalibration::default()
        };
        let (mut s, mut notes) = (scene(), Vec::new());
        apply(&driver, &mut s, false, &mut notes);
        let k = s.believed_camera.intrinsics;
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (880.0, 882.0, 630.0, 350.0));
        assert_eq!(s.lens, Distortion::None, "{notes:?}");

        let mut folding = info("camera_optical");
        folding.d = vec![-2.0, 0.0, 0.0, 0.0, 0.0];
        let driver = DriverCalibration {
            image_topic: "/camera/image_raw".into(),
            info: Some(folding),
            ..DriverCalibration::default()
        };
        let before = scene();
        let (mut s, mut notes) = (scene(), Vec::new());
        apply(&driver, &mut s, false, &mut notes);
        assert_eq!(
            s.believed_camera.intrinsics,
            before.believed_camera.intrinsics
        );
        assert!(notes[0].contains("does not invert"), "{notes:?}");
    }
}
