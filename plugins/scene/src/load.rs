//! A loaded, validated scene: [`Scene::load`] parses the file, checks every value (finite, in
//! range, consistent), loads the robot and resolves the `[task]` against it, so that a scene that
//! loads can run.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use avatarm_core::robot::trajectory::{JointTrajectory, Keyframe};
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::vision::camera::{Intrinsics, PinholeCamera};
use avatarm_core::vision::distortion::{Distortion, DistortionMap};
use nalgebra::{DVector, Isometry3, Vector3};

use crate::error::SceneError;
use crate::finite::first_non_finite;
use crate::hand::HandChoice;
use crate::prop::Prop;
use crate::spec::{BackgroundSpec, JointValues, SceneFile};
use crate::task::TrialSetup;

/// A loaded, validated scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Where it came from.
    pub path: PathBuf,
    /// As written.
    pub file: SceneFile,
    /// The robot.
    pub model: Arc<RobotModel>,
    /// The mask twin's description: `[twin] urdf`, else the robot's own (the same `Arc`).
    pub twin_model: Arc<RobotModel>,
    /// Initial joint positions.
    pub q0: DVector<f64>,
    /// The robot timeline.
    pub trajectory: JointTrajectory,
    /// The camera at its true pose.
    pub true_camera: PinholeCamera,
    /// The camera at the pose the app believes (true pose + calibration error).
    pub believed_camera: PinholeCamera,
    /// The camera's lens (`[camera] distortion`; the believed camera's is the true one's, as a
    /// calibrated lens's would be).
    pub lens: Distortion,
    /// Props in the room.
    pub props: Vec<Prop>,
    /// The background image file, resolved (`[background] source = "file"`).
    pub background_path: Option<PathBuf>,
    /// The `[task]`'s real side, resolved against the robot and the props when the scene
    /// loads (`None` without a `[task]`). Code that changes `file.task`, the robot or the props
    /// afterwards resolves it again with [`TrialSetup::resolve`]; readers take the task from
    /// `file.task` and its set-up from here, and run it only when both are there.
    pub trial: Option<TrialSetup>,
}

impl Scene {
    /// Reads and validates a scene file; `extra_packages` are searched for `package://` URIs
    /// before the scene's own `robot.package_path`.
    pub fn load(path: &Path, extra_packages: &PackagePath) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path, extra_packages)
    }

    /// Parses scene text as if read from `path`.
    pub fn parse(
        text: &str,
        path: &Path,
        extra_packages: &PackagePath,
    ) -> Result<Self, SceneError> {
        let parse_error = |source| SceneError::Parse {
            path: path.to_owned(),
            source,
        };
        let invalid = |field: &str, message: String| SceneError::Invalid {
            path: path.to_owned(),
            field: field.to_owned(),
            message,
        };
        // Syntax first, then every float finite (TOML allows nan and inf), then the types.
        let table: toml::Table = toml::from_str(text).map_err(parse_error)?;
        if let Some((field, value)) = first_non_finite(&table) {
            return Err(invalid(&field, format!("{value} is not a finite number")));
        }
        let file: SceneFile = toml::from_str(text).map_err(parse_error)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        if !(file.duration_s.is_finite() && file.duration_s > 0.0) {
            return Err(invalid(
                "duration_s",
                format!("{} must be > 0", file.duration_s),
            ));
        }
        if !(file.control_rate_hz.is_finite() && (1.0..=10_000.0).contains(&file.control_rate_hz)) {
            return Err(invalid(
                "control_rate_hz",
                format!("{} must be within 1..=10000", file.control_rate_hz),
            ));
        }
        let c = &file.camera;
        if !(c.fps.is_finite() && (1.0..=1000.0).contains(&c.fps)) {
            return Err(invalid(
                "camera.fps",
                format!("{} must be within 1..=1000", c.fps),
            ));
        }
        if !(c.frame_latency_s.is_finite() && (0.0..=10.0).contains(&c.frame_latency_s)) {
            return Err(invalid(
                "camera.frame_latency_s",
                format!("{} must be within 0..=10 s", c.frame_latency_s),
            ));
        }
        if !(0.0..=255.0).contains(&c.sensor.noise_sigma) {
            return Err(invalid(
                "camera.sensor.noise_sigma",
                format!("{} must be within 0..=255 levels", c.sensor.noise_sigma),
            ));
        }
        for (i, [t_s, gain]) in c.sensor.exposure.iter().copied().enumerate() {
            let field = format!("camera.sensor.exposure[{i}]");
            if !(t_s >= 0.0 && gain > 0.0 && gain <= 100.0) {
                return Err(invalid(
                    &field,
                    format!("[{t_s}, {gain}]: need t_s >= 0 and 0 < gain <= 100"),
                ));
            }
            if i > 0 && t_s <= c.sensor.exposure[i - 1][0] {
                return Err(invalid(
                    &field,
                    format!("t_s {t_s} is not after the previous keyframe's"),
                ));
            }
        }
        let ce = &c.calibration_error;
        if ce.rotation_deg.abs() > 180.0 {
            return Err(invalid(
                "camera.calibration_error.rotation_deg",
                format!("{} must be within -180..=180", ce.rotation_deg),
            ));
        }
        if ce.rotation_deg != 0.0 && Vector3::from(ce.axis).norm() < 1e-9 {
            return Err(invalid(
                "camera.calibration_error.axis",
                "a rotation error needs a non-zero axis".into(),
            ));
        }
        let s = &file.robot.sim;
        for (name, v) in [
            ("command_latency_s", s.command_latency_s),
            ("time_constant_s", s.time_constant_s),
            ("state_latency_s", s.state_latency_s),
            ("command_timeout_s", s.command_timeout_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(
                    &format!("robot.sim.{name}"),
                    format!("{v} must be >= 0"),
                ));
            }
        }
        if !(s.state_rate_hz.is_finite() && s.state_rate_hz > 0.0) {
            return Err(invalid("robot.sim.state_rate_hz", "must be > 0".into()));
        }

        file.erase
            .validate("erase")
            .map_err(|e| SceneError::value("erase", e).in_file(path))?;
        let i = &file.interaction;
        if !(i.panel_distance_m.is_finite()
            && i.panel_distance_m > 0.0
            && i.object_depth_m > 0.0
            && i.object_depth_m < i.panel_distance_m)
        {
            return Err(invalid(
                "interaction",
                format!(
                    "need 0 < object_depth_m ({}) < panel_distance_m ({})",
                    i.object_depth_m, i.panel_distance_m
                ),
            ));
        }
        if let Some(h) = &file.hand
            && h != "none"
        {
            h.parse::<HandChoice>().map_err(|e| e.in_file(path))?;
        }
        if let Err((field, message)) = file.robot.link.validate() {
            return Err(invalid(&field, message));
        }
        if file.leap.mount == crate::spec::LeapMountKind::FirstWrist
            && file.leap.device_at.is_some()
        {
            return Err(invalid(
                "leap.device_at",
                "first_wrist places a recording by its first wrist; a device position needs \
                 mount = \"desk\" or \"head\""
                    .into(),
            ));
        }
        let x = &file.xr_layout;
        if !(x.panel_distance_m.is_finite()
            && (0.2..=20.0).contains(&x.panel_distance_m)
            && x.panel_height_m.is_finite()
            && (0.05..=20.0).contains(&x.panel_height_m)
            && x.panel_below_eye_m.is_finite()
            && x.panel_below_eye_m.abs() <= 5.0)
        {
            return Err(invalid(
                "xr_layout",
                format!(
                    "need 0.2 <= panel_distance_m ({}) <= 20, 0.05 <= panel_height_m ({}) <= 20 \
                     and |panel_below_eye_m| ({}) <= 5",
                    x.panel_distance_m, x.panel_height_m, x.panel_below_eye_m
                ),
            ));
        }
        let background_path = match &file.background {
            BackgroundSpec::File { path: p } => {
                let full = dir.join(p);
                if !full.is_file() {
                    return Err(invalid(
                        "background.path",
                        format!("{} does not exist", full.display()),
                    ));
                }
                Some(full)
            }
            BackgroundSpec::Capture { at_s } if !(at_s.is_finite() && *at_s >= 0.0) => {
                return Err(invalid("background.at_s", format!("{at_s} must be >= 0")));
            }
            _ => None,
        };

        let mut packages = extra_packages.clone();
        packages
            .0
            .extend(file.robot.package_path.iter().map(|p| dir.join(p)));
        // A description in a ROS package may be named by package://, as its meshes are.
        let resolve = |field: &str, urdf: &Path| -> Result<PathBuf, SceneError> {
            let text = urdf.to_string_lossy();
            let Some(rest) = text.strip_prefix("package://") else {
                return Ok(dir.join(urdf));
            };
            let (package, file) = rest.split_once('/').unwrap_or((rest, ""));
            packages
                .find_package(package)
                .map(|d| d.join(file))
                .ok_or_else(|| invalid(field, packages.not_found(package)))
        };
        let urdf = resolve("robot.urdf", &file.robot.urdf)?;
        let model =
            RobotModel::from_urdf_file(&urdf, &packages).map_err(|source| SceneError::Robot {
                path: path.to_owned(),
                source: Box::new(source),
            })?;

        let model = Arc::new(model);
        let keep = file.twin.keep_triangles;
        if !(keep.is_finite() && keep > 0.0 && keep <= 1.0) {
            return Err(invalid(
                "twin.keep_triangles",
                format!("{keep} must be in (0, 1]"),
            ));
        }
        let twin_model = match &file.twin.urdf {
            None => Arc::clone(&model),
            Some(urdf) => {
                let twin = RobotModel::from_urdf_file(&resolve("twin.urdf", urdf)?, &packages)
                    .map_err(|e| SceneError::value("twin.urdf", e).in_file(path))?;
                // The twin is posed from the robot's joint states by name: a joint of the
                // twin that the robot does not have would stay still while the robot moves.
                let missing = avatarm_core::robot::JointMap::new(&model, &twin).missing;
                if !missing.is_empty() {
                    return Err(invalid(
                        "twin.urdf",
                        format!(
                            "'{}' has movable joints that the robot '{}' does not: {} (the twin must be the same robot)",
                            twin.name,
                            model.name,
                            missing.join(", ")
                        ),
                    ));
                }
                Arc::new(twin)
            }
        };

        let values = |field: &str, v: &JointValues, previous: &DVector<f64>| {
            let mut q = previous.clone();
            match v {
                JointValues::Named(map) => {
                    for (name, value) in map {
                        let i = model
                            .dof_index(name)
                            .map_err(|e| SceneError::value(field, e).in_file(path))?;
                        q[i] = *value;
                    }
                }
                JointValues::List(list) => {
                    if list.len() > model.dof() {
                        return Err(invalid(
                            field,
                            format!("{} values for {} movable joints", list.len(), model.dof()),
                        ));
                    }
                    for (i, value) in list.iter().enumerate() {
                        q[i] = *value;
                    }
                }
            }
            model
                .check_q(&q)
                .map_err(|e| SceneError::value(field, e).in_file(path))?;
            Ok(q)
        };
        let q0 = match &file.robot.q0 {
            Some(v) => values("robot.q0", v, &DVector::zeros(model.dof()))?,
            None => DVector::zeros(model.dof()),
        };
        let mut keyframes = Vec::new();
        let mut previous = q0.clone();
        for (i, k) in file.timeline.robot.iter().enumerate() {
            let field = format!("timeline.robot[{i}]");
            if !(k.t_s.is_finite() && k.t_s >= 0.0) {
                return Err(invalid(
                    &format!("{field}.t_s"),
                    format!("{} must be >= 0", k.t_s),
                ));
            }
            if let Some(last) = keyframes.last().map(|k: &Keyframe| k.t_s)
                && k.t_s <= last
            {
                return Err(invalid(
                    &format!("{field}.t_s"),
                    format!("{} is not after the previous keyframe's {last}", k.t_s),
                ));
            }
            let q = values(&format!("{field}.q"), &k.q, &previous)?;
            previous = q.clone();
            keyframes.push(Keyframe { t_s: k.t_s, q });
        }

        let intrinsics = match c.intrinsics {
            Some(k) => k,
            None => {
                if !(c.fov_y_deg.is_finite() && c.fov_y_deg > 1.0 && c.fov_y_deg < 179.0) {
                    return Err(invalid("camera.fov_y_deg", "must be within 1..179".into()));
                }
                Intrinsics::from_fov_y(c.fov_y_deg.to_radians(), c.width, c.height)
            }
        };
        intrinsics
            .validate()
            .map_err(|e| SceneError::value("camera.intrinsics", e).in_file(path))?;
        let pose = c
            .pose
            .to_isometry()
            .map_err(|e| SceneError::value("camera.pose", e).in_file(path))?;
        let true_camera = PinholeCamera {
            intrinsics,
            world_from_camera: pose,
        };
        let lens = match &c.distortion {
            Some(l) => {
                let lens = Distortion::from_ros(&l.model, &l.coefficients)
                    .map_err(|e| SceneError::value("camera.distortion", e).in_file(path))?;
                // The lens must invert over the image (a render can be drawn through it).
                if !lens.is_none() {
                    let map = DistortionMap::new(&intrinsics, &lens, 1.0)
                        .map_err(|e| SceneError::value("camera.distortion", e).in_file(path))?;
                    if map.unmapped > 0 {
                        let e = avatarm_core::Error::BadSetting {
                            what: "lens distortion".into(),
                            message: format!(
                                "does not invert at {} of the image's pixels (past a barrel's fold): not a lens over this image",
                                map.unmapped
                            ),
                        };
                        return Err(SceneError::value("camera.distortion", e).in_file(path));
                    }
                }
                lens
            }
            None => Distortion::None,
        };
        let believed_camera = true_camera.perturbed(
            &Vector3::from(ce.axis),
            ce.rotation_deg.to_radians(),
            &(Vector3::from(ce.translation_mm) * 1e-3),
        );

        let mut props: Vec<Prop> = Vec::new();
        for (i, p) in file.props.iter().enumerate() {
            let field = format!("props[{i}] ({})", p.name);
            if !p.shape.sizes_are_positive() {
                return Err(invalid(&field, "sizes must be positive".into()));
            }
            if !p.rgba.iter().all(|v| (0.0..=1.0).contains(v)) {
                return Err(invalid(
                    &format!("{field}.rgba"),
                    format!("{:?}: each channel must be within 0..=1", p.rgba),
                ));
            }
            if props.iter().any(|q| q.name == p.name) {
                return Err(invalid(
                    &field,
                    format!("another prop is already named '{}'", p.name),
                ));
            }
            props.push(Prop {
                name: p.name.clone(),
                shape: p.shape.clone(),
                pose: p.pose.to_isometry(),
                rgba: p.rgba,
            });
        }
        let base = file.robot.base.to_isometry();
        let trial = match &file.task {
            Some(task) => {
                task.validate().map_err(|e| e.in_file(path))?;
                Some(
                    TrialSetup::resolve(
                        task,
                        &model,
                        base,
                        q0.clone(),
                        file.robot.sim,
                        file.control_rate_hz,
                        &props,
                    )
                    .map_err(|e| e.in_file(path))?,
                )
            }
            None => None,
        };
        Ok(Scene {
            path: path.to_owned(),
            trial,
            background_path,
            model,
            twin_model,
            q0,
            trajectory: JointTrajectory::new(keyframes),
            true_camera,
            believed_camera,
            lens,
            props,
            file,
        })
    }

    /// The robot base pose.
    pub fn robot_base(&self) -> Isometry3<f64> {
        self.file.robot.base.to_isometry()
    }
}
