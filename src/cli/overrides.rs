//! Command-line overrides of a scene's `[erase]` and `[background]`.

use std::path::PathBuf;

use avatarm_core::dr::EraseSettings;
use avatarm_core::vision::camera::Intrinsics;
use avatarm_scene::Scene;
use avatarm_scene::spec::BackgroundSpec;

use crate::AppError;

/// Command-line overrides of a scene's `[erase]` and `[background]` (each flag left out keeps
/// the scene's value). Shared by `avatarm run` and `avatarm replay`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct EraseOverrides {
    /// Erase the robot at all.
    #[arg(long, value_name = "on|off", value_parser = on_off)]
    pub erase: Option<bool>,
    /// Grow the mask by N pixels.
    #[arg(long, value_name = "N")]
    pub dilate: Option<u32>,
    /// Soften the mask's edge over N pixels.
    #[arg(long, value_name = "N")]
    pub feather: Option<u32>,
    /// Render the twin at each frame's capture time (predicted joint state).
    #[arg(long, value_name = "on|off", value_parser = on_off)]
    pub latency_compensation: Option<bool>,
    /// Fit the background's gain and offset to each frame.
    #[arg(long, value_name = "on|off", value_parser = on_off)]
    pub photometric: Option<bool>,
    /// Render the mask twin at this fraction of the camera's resolution.
    #[arg(long, value_name = "F")]
    pub mask_scale: Option<f64>,
    /// Refresh the background from pixels the robot cannot cover (0 = never, 1 = copy).
    #[arg(long, value_name = "F")]
    pub background_refresh: Option<f64>,
    /// Draw the mask through the camera's lens distortion (off: as a pinhole's).
    #[arg(long, value_name = "on|off", value_parser = on_off)]
    pub lens_distortion: Option<bool>,
    /// Watch a fixed real camera for moving (a few frames a second, the robot's outline against
    /// each frame's edges): a move beyond the erase margin is fitted again and the new pose
    /// used from then on (`replay --recording`'s report says what was found under `drift`;
    /// `run` and `serve` log it). On by default; no effect on the simulated room's camera.
    #[arg(long = "drift-watch", value_name = "on|off", value_parser = on_off)]
    pub drift_watch: Option<bool>,
    /// A camera on a head: draw each frame's mask at the head pose of its capture time (off:
    /// at the newest tracked pose).
    #[arg(long, value_name = "on|off", value_parser = on_off)]
    pub pose_compensation: Option<bool>,
    /// A camera on a head that sweeps: its peak angular speed (degrees/s).
    #[arg(long, value_name = "DEG_S")]
    pub head_speed: Option<f64>,
    /// A camera on a head: the head tracking's latency (ms).
    #[arg(long, value_name = "MS")]
    pub tracking_latency_ms: Option<f64>,
    /// Load the background H from an image file (the camera's size).
    #[arg(long, value_name = "PATH", conflicts_with = "capture_background_at")]
    pub background: Option<PathBuf>,
    /// Capture the background H from the live frame at this time (s).
    #[arg(long, value_name = "S")]
    pub capture_background_at: Option<f64>,
    /// The camera pose the app believes, from a file (under camera_from_base or
    /// base_from_camera, the robot's base frame; what `avatarm calibrate` writes) instead of
    /// the scene's pose and calibration error. The simulated room's camera stays where the
    /// scene puts it.
    #[arg(long = "believed-pose", value_name = "FILE")]
    pub believed_pose: Option<PathBuf>,
    /// A camera on a head: the mount the app believes, from a file (under head_from_camera or
    /// camera_from_head; what `avatarm calibrate` writes for a recording of a camera on a head)
    /// instead of the scene's mount and calibration error. The simulated room's camera stays
    /// where the scene's mount puts it. With --recording: instead of the recording's mount.
    #[arg(long = "believed-mount", value_name = "FILE")]
    pub believed_mount: Option<PathBuf>,
    /// Run the scene's camera at WIDTHxHEIGHT pixels, its pose and vertical field of view kept
    /// (the principal point at the centre): the same scene at 1080p.
    #[arg(long = "camera-size", value_name = "WxH", value_parser = super::args::frame_size)]
    pub camera_size: Option<(u32, u32)>,
}

/// Parses `on`/`off` (also `true`/`false`, `1`/`0`) for command-line switches.
pub fn on_off(s: &str) -> Result<bool, AppError> {
    match s {
        "on" | "true" | "1" => Ok(true),
        "off" | "false" | "0" => Ok(false),
        _ => Err(AppError::Value {
            text: s.to_owned(),
            message: "expected on or off".into(),
        }),
    }
}

impl EraseOverrides {
    /// Applies the `[erase]` overrides alone to `settings` and checks them; errors name the
    /// flag.
    pub fn apply_to_settings(&self, e: &mut EraseSettings) -> Result<(), AppError> {
        if let Some(v) = self.erase {
            e.enabled = v;
        }
        if let Some(v) = self.dilate {
            e.dilate_px = v;
        }
        if let Some(v) = self.feather {
            e.feather_px = v;
        }
        if let Some(v) = self.latency_compensation {
            e.latency_compensation = v;
        }
        if let Some(v) = self.photometric {
            e.photometric = v;
        }
        if let Some(v) = self.mask_scale {
            e.resolution_scale = v;
        }
        if let Some(v) = self.background_refresh {
            e.background_refresh = v as f32;
        }
        if let Some(v) = self.lens_distortion {
            e.lens_distortion = v;
        }
        if let Some(v) = self.pose_compensation {
            e.pose_compensation = v;
        }
        if let Some(v) = self.drift_watch {
            e.drift_watch = v;
        }
        e.validate("command line")?;
        Ok(())
    }

    /// Applies `--head-speed` and `--tracking-latency-ms` to the scene's head; errors name the
    /// flag (no head, a keyframed head, a value out of range).
    fn apply_head(&self, scene: &mut Scene) -> Result<(), AppError> {
        let (speed, latency) = (self.head_speed, self.tracking_latency_ms);
        if speed.is_none() && latency.is_none() {
            return Ok(());
        }
        let flag = if speed.is_some() {
            "--head-speed"
        } else {
            "--tracking-latency-ms"
        };
        if scene.head.is_none() {
            return Err(AppError::flag(
                flag,
                format!(
                    "the scene '{}' has a fixed camera; a camera on a head is [camera.head]",
                    scene.file.name
                ),
            ));
        }
        if let Some(v) = speed {
            if !(v.is_finite() && (0.0..=720.0).contains(&v)) {
                return Err(AppError::flag(
                    "--head-speed",
                    format!("{v} must be within 0..=720 degrees/s"),
                ));
            }
            let sweep = scene
                .file
                .camera
                .head
                .as_mut()
                .and_then(|h| h.sweep.as_mut());
            let Some(sweep) = sweep else {
                return Err(AppError::flag(
                    "--head-speed",
                    "the scene's head follows keyframes; a speed needs [camera.head.sweep]",
                ));
            };
            if v > 0.0 && sweep.amplitude_deg <= 0.0 {
                return Err(AppError::flag(
                    "--head-speed",
                    "the head's sweep has no amplitude to move through",
                ));
            }
            sweep.peak_speed_deg_s = v;
            if let Some(head) = scene.head.as_mut() {
                head.set_sweep_speed(v);
            }
        }
        if let Some(ms) = latency {
            let Some(head) = scene.head.as_mut() else {
                return Ok(());
            };
            let mut tracking = head.tracking;
            tracking.latency_s = ms / 1e3;
            tracking
                .validate("tracking")
                .map_err(|e| AppError::flag("--tracking-latency-ms", e.to_string()))?;
            head.tracking = tracking;
            if let Some(h) = scene.file.camera.head.as_mut() {
                h.tracking.latency_s = tracking.latency_s;
            }
        }
        Ok(())
    }

    /// Without `--dilate`, the erase margin a believed pose or mount file carries
    /// (`erase_margin_px`, what `avatarm calibrate` writes beside the pose it fits) becomes
    /// the scene's `[erase] dilate_px`, said on the standard error.
    fn take_margin(&self, file: &std::path::Path, scene: &mut Scene) -> Result<(), AppError> {
        if self.dilate.is_some() {
            return Ok(());
        }
        if let Some(px) = avatarm_record::camera::read_erase_margin(file)? {
            eprintln!(
                "erase: dilating the mask by {px} px, the margin {} asks for (--dilate to say otherwise)",
                file.display()
            );
            scene.file.erase.dilate_px = px;
        }
        Ok(())
    }

    /// Applies the overrides to `scene` and checks the result; errors name the flag.
    pub fn apply(&self, scene: &mut Scene) -> Result<(), AppError> {
        if let Some((width, height)) = self.camera_size {
            let resized = |k: &Intrinsics| Intrinsics::from_fov_y(k.fov_y_rad(), width, height);
            scene.true_camera.intrinsics = resized(&scene.true_camera.intrinsics);
            scene.believed_camera.intrinsics = resized(&scene.believed_camera.intrinsics);
            let c = &mut scene.file.camera;
            c.intrinsics = Some(scene.true_camera.intrinsics);
            (c.width, c.height) = (width, height);
        }
        self.apply_to_settings(&mut scene.file.erase)?;
        self.apply_head(scene)?;
        if let Some(path) = &self.believed_pose {
            if scene.head.is_some() {
                return Err(AppError::flag(
                    "--believed-pose",
                    "the scene's camera rides on a head: its pose is the tracked head's times the mount, not a fixed pose",
                ));
            }
            let base_from_camera = avatarm_record::camera::read_pose(path)?;
            scene.believed_camera.world_from_camera = scene.robot_base() * base_from_camera;
            self.take_margin(path, scene)?;
        }
        if let Some(path) = &self.believed_mount {
            let Some(head) = scene.head.as_mut() else {
                return Err(AppError::flag(
                    "--believed-mount",
                    "the scene's camera is fixed, not on a head: give its pose with --believed-pose",
                ));
            };
            head.believed_mount = avatarm_record::camera::read_mount(path)?;
            // The camera as believed at t = 0 (before the first tracked pose; where a
            // background photograph was taken from).
            scene.believed_camera.world_from_camera = head.believed_camera_at(0.0);
            self.take_margin(path, scene)?;
        }
        if let Some(path) = &self.background {
            if !path.is_file() {
                return Err(AppError::flag(
                    "--background",
                    format!("{} does not exist", path.display()),
                ));
            }
            scene.file.background = BackgroundSpec::File { path: path.clone() };
            scene.background_path = Some(path.clone());
        }
        if let Some(at_s) = self.capture_background_at {
            if !(at_s.is_finite() && at_s >= 0.0) {
                return Err(AppError::flag(
                    "--capture-background-at",
                    format!("{at_s} must be >= 0"),
                ));
            }
            scene.file.background = BackgroundSpec::Capture { at_s };
            scene.background_path = None;
        }
        Ok(())
    }
}
