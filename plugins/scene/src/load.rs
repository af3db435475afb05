//! A loaded, validated scene: [`Scene::load`] parses the file, checks every value (finite, in
//! range, consistent), loads the robot and resolves the `[task]` against it, so that a scene that
//! loads can run.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use avatarm_core::robot::trajectory::{JointTrajectory, Keyframe};
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::vision::camera::{CameraPose, Intrinsics, PinholeCamera};
use avatarm_core::vision::distortion::Distortion;
use avatarm_core::vision::head::{HeadMotion, TrackingModel, perturbed_mount};
use nalgebra::{DVector, Isometry3, Vector3};

use crate::error::SceneError;
use crate::finite::first_non_finite;
use crate::hand::HandChoice;
use crate::prop::Prop;
use crate::spec::{BackgroundSpec, CalibrationError, CameraSpec, HeadSpec, JointValues, SceneFile};
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
    /// The head a camera rides on (`[camera.head]`), `None` for a fixed camera; then
    /// `true_camera` and `believed_camera` are the camera at t = 0.
    pub head: Option<HeadRig>,
    /// The names of the scene file's cameras, in the file's order: its `[[cameras]]`, or
    /// [`SINGLE_CAMERA`] for its one `[camera]`.
    pub cameras: Vec<String>,
    /// Which of `cameras` this scene looks through (`file.camera`, `true_camera`, ...).
    pub camera_index: usize,
    /// Props in the room.
    pub props: Vec<Prop>,
    /// The background image file, resolved (`[background] source = "file"`).
    pub background_path: Option<PathBuf>,
    /// The `[task]`'s real side, resolved against the robot and the props when the scene
    /// loads (`None` without a `[task]`). Code that changes `file.task`, the robot or the props
    /// afterwards resolves it again with [`TrialSetup::resolve`]; readers take the task from
    /// `file.task` and its set-up from here, and run it only when both are there.
    pub trial: Option<TrialSetup>,
    /// The `[chess]` task's real side, resolved when the scene loads (`None` without one); its
    /// board and pieces are among `props` (and `file.props`).
    pub chess: Option<crate::chess::ChessSetup>,
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

    /// Reads and validates a scene file looking through its camera named `view` (one of
    /// `[[cameras]]`; `None`: the first). Every camera of the file is checked, not only that
    /// one.
    pub fn load_view(
        path: &Path,
        extra_packages: &PackagePath,
        view: Option<&str>,
    ) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::parse_view(&text, path, extra_packages, view)
    }

    /// Parses scene text as if read from `path`, looking through its first camera.
    pub fn parse(
        text: &str,
        path: &Path,
        extra_packages: &PackagePath,
    ) -> Result<Self, SceneError> {
        Self::parse_view(text, path, extra_packages, None)
    }

    /// Parses scene text as if read from `path`, looking through the camera named `view`
    /// (`None`: the first). A scene's cameras are its one `[camera]` (named `camera`) or its
    /// `[[cameras]]`: the chosen one becomes `file.camera` (its `erase` keys over the scene's
    /// `[erase]`, its `background` instead of the scene's), and the others are checked as
    /// they would be chosen.
    #[expect(
        clippy::too_many_lines,
        reason = "every field of the scene file checked in the file's order, each check naming its field; a split by section is left for the next pass"
    )]
    pub fn parse_view(
        text: &str,
        path: &Path,
        extra_packages: &PackagePath,
        view: Option<&str>,
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
        let mut table: toml::Table = toml::from_str(text).map_err(parse_error)?;
        if let Some((field, value)) = first_non_finite(&table) {
            return Err(invalid(&field, format!("{value} is not a finite number")));
        }
        let (file, cameras, camera_index, camera_field) = match CameraEntries::take(
            &mut table, path,
        )? {
            // One `[camera]`: the parser's own errors, with line and column.
            None => {
                if let Some(v) = view.filter(|v| *v != SINGLE_CAMERA) {
                    return Err(invalid(
                        "camera",
                        format!(
                            "no camera named '{v}': the scene has one camera ([camera], named '{SINGLE_CAMERA}'); name several with [[cameras]]"
                        ),
                    ));
                }
                let file: SceneFile = toml::from_str(text).map_err(parse_error)?;
                (file, vec![SINGLE_CAMERA.to_owned()], 0, "camera".to_owned())
            }
            Some(entries) => {
                let index = entries.index(view, path)?;
                let file = entries.file_for(&table, index, path)?;
                // The others, checked as if chosen.
                for other in (0..entries.0.len()).filter(|j| *j != index) {
                    let f = entries.file_for(&table, other, path)?;
                    let field = entries.field(other);
                    resolve_camera(&f.camera, path)
                        .map_err(|e| e.with_field_prefix("camera", &field))?;
                    // Its own erase and background, named as its; the scene's are checked below.
                    let own = |key: &str| entries.0[other].1.contains_key(key);
                    if own("erase") {
                        f.erase.validate("erase").map_err(|e| {
                            SceneError::value(format!("{field}.erase"), e).in_file(path)
                        })?;
                    }
                    if own("background") {
                        background_path(&f, path).map_err(|e| {
                            e.with_field_prefix("background", &format!("{field}.background"))
                        })?;
                    }
                }
                let names = entries.0.iter().map(|(name, _)| name.clone()).collect();
                (file, names, index, entries.field(index))
            }
        };
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
        let CameraParts {
            true_camera,
            believed_camera,
            lens,
            head,
        } = resolve_camera(&file.camera, path)
            .map_err(|e| e.with_field_prefix("camera", &camera_field))?;
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
        let background_path = background_path(&file, path)?;

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

        let mut file = file;
        if let Some(chess) = &file.chess {
            chess.validate().map_err(|e| e.in_file(path))?;
            let board = chess.props().map_err(|e| e.in_file(path))?;
            file.props.extend(board.into_iter().map(|p| {
                let (r, pi, y) = p.pose.rotation.euler_angles();
                let t = p.pose.translation.vector;
                crate::spec::PropSpec {
                    name: p.name,
                    shape: p.shape,
                    pose: crate::spec::PoseSpec {
                        xyz: [t.x, t.y, t.z],
                        rpy: [r, pi, y],
                    },
                    rgba: p.rgba,
                    object: p.object,
                    occluder: false,
                }
            }));
        }
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
        let chess = match &file.chess {
            Some(task) => Some(
                crate::chess::ChessSetup::resolve(
                    task,
                    &model,
                    base,
                    q0.clone(),
                    file.robot.sim,
                    file.control_rate_hz,
                )
                .map_err(|e| e.in_file(path))?,
            ),
            None => None,
        };
        Ok(Scene {
            path: path.to_owned(),
            trial,
            chess,
            background_path,
            model,
            twin_model,
            q0,
            trajectory: JointTrajectory::new(keyframes),
            true_camera,
            believed_camera,
            lens,
            head,
            cameras,
            camera_index,
            props,
            file,
        })
    }

    /// The robot base pose.
    pub fn robot_base(&self) -> Isometry3<f64> {
        self.file.robot.base.to_isometry()
    }

    /// The name of the camera this scene looks through.
    pub fn camera_name(&self) -> &str {
        &self.cameras[self.camera_index]
    }
}

/// The name of a scene's one `[camera]`.
pub const SINGLE_CAMERA: &str = "camera";

/// A scene file's `[[cameras]]`: each one's name and its table (the `[camera]` fields, with
/// `erase` and `background` of its own when it has them).
struct CameraEntries(Vec<(String, toml::Table)>);

impl CameraEntries {
    /// Takes `cameras` out of the file's `table`: `None` when the file has none (then it
    /// must have a `[camera]`). Checks that there are some, not beside a `[camera]`, each
    /// with a unique name of letters, digits, `_` and `-` (it names the replay's folders).
    fn take(table: &mut toml::Table, path: &Path) -> Result<Option<Self>, SceneError> {
        let invalid = |field: &str, message: String| SceneError::Invalid {
            path: path.to_owned(),
            field: field.to_owned(),
            message,
        };
        let Some(value) = table.remove("cameras") else {
            return Ok(None);
        };
        if table.contains_key("camera") {
            return Err(invalid(
                "camera",
                "give one [camera] or several [[cameras]], not both".into(),
            ));
        }
        let toml::Value::Array(items) = value else {
            return Err(invalid(
                "cameras",
                "must be an array of tables ([[cameras]])".into(),
            ));
        };
        if items.is_empty() {
            return Err(invalid("cameras", "is empty: give at least one".into()));
        }
        let mut entries: Vec<(String, toml::Table)> = Vec::new();
        for (i, item) in items.into_iter().enumerate() {
            let toml::Value::Table(mut t) = item else {
                return Err(invalid(&format!("cameras[{i}]"), "must be a table".into()));
            };
            let name = match t.remove("name") {
                Some(toml::Value::String(n)) => n,
                Some(other) => {
                    return Err(invalid(
                        &format!("cameras[{i}].name"),
                        format!("{other}: must be a string"),
                    ));
                }
                None => {
                    return Err(invalid(
                        &format!("cameras[{i}].name"),
                        "missing: each of [[cameras]] needs a name (e.g. \"blair\", \"alice\")"
                            .into(),
                    ));
                }
            };
            if name.is_empty()
                || !name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            {
                return Err(invalid(
                    &format!("cameras[{i}].name"),
                    format!("'{name}': use letters, digits, '_' and '-' (it names folders)"),
                ));
            }
            if entries.iter().any(|(n, _)| *n == name) {
                return Err(invalid(
                    &format!("cameras[{i}].name"),
                    format!("another camera is already named '{name}'"),
                ));
            }
            entries.push((name, t));
        }
        Ok(Some(Self(entries)))
    }

    /// The index of the camera named `view` (`None`: the first).
    fn index(&self, view: Option<&str>, path: &Path) -> Result<usize, SceneError> {
        let Some(view) = view else { return Ok(0) };
        self.0
            .iter()
            .position(|(name, _)| name == view)
            .ok_or_else(|| SceneError::Invalid {
                path: path.to_owned(),
                field: "cameras".into(),
                message: format!(
                    "no camera named '{view}'; the scene's cameras: {}",
                    self.0
                        .iter()
                        .map(|(n, _)| n.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })
    }

    /// How errors name camera `i`: `cameras[i] (name)`.
    fn field(&self, i: usize) -> String {
        format!("cameras[{i}] ({})", self.0[i].0)
    }

    /// The scene file as seen through camera `i`: `table` (without `cameras`) with the
    /// camera as its `[camera]`, the camera's `erase` keys over the scene's `[erase]` and its
    /// `background` instead of the scene's.
    fn file_for(
        &self,
        table: &toml::Table,
        i: usize,
        path: &Path,
    ) -> Result<SceneFile, SceneError> {
        let field = self.field(i);
        let invalid = |message: String| SceneError::Invalid {
            path: path.to_owned(),
            field: field.clone(),
            message,
        };
        let mut camera = self.0[i].1.clone();
        let mut table = table.clone();
        match camera.remove("erase") {
            None => {}
            Some(toml::Value::Table(own)) => {
                let erase = table
                    .entry("erase")
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()));
                let Some(erase) = erase.as_table_mut() else {
                    return Err(invalid("the scene's erase is not a table".into()));
                };
                erase.extend(own);
            }
            Some(_) => return Err(invalid("erase: must be a table".into())),
        }
        if let Some(background) = camera.remove("background") {
            table.insert("background".into(), background);
        }
        // The camera's own fields first, so that an error names the camera.
        toml::Value::Table(camera.clone())
            .try_into::<CameraSpec>()
            .map_err(|e| invalid(e.to_string().trim_end().to_owned()))?;
        table.insert("camera".into(), toml::Value::Table(camera));
        toml::Value::Table(table)
            .try_into()
            .map_err(|source| SceneError::Parse {
                path: path.to_owned(),
                source,
            })
    }
}

/// The `[background]` image file of `file` (a scene file at `path`), resolved and checked:
/// `None` unless it comes from a file.
fn background_path(file: &SceneFile, path: &Path) -> Result<Option<PathBuf>, SceneError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let invalid = |field: &str, message: String| SceneError::Invalid {
        path: path.to_owned(),
        field: field.to_owned(),
        message,
    };
    match &file.background {
        BackgroundSpec::File { path: p } => {
            let full = dir.join(p);
            if !full.is_file() {
                return Err(invalid(
                    "background.path",
                    format!("{} does not exist", full.display()),
                ));
            }
            Ok(Some(full))
        }
        BackgroundSpec::Capture { at_s } if !(at_s.is_finite() && *at_s >= 0.0) => {
            Err(invalid("background.at_s", format!("{at_s} must be >= 0")))
        }
        _ => Ok(None),
    }
}

/// A scene's camera, resolved from its spec.
struct CameraParts {
    true_camera: PinholeCamera,
    believed_camera: PinholeCamera,
    lens: Distortion,
    head: Option<HeadRig>,
}

/// Checks and resolves one camera (`[camera]`, or one of `[[cameras]]`) of the scene file
/// `path`; errors name the field under `camera`.
fn resolve_camera(c: &CameraSpec, path: &Path) -> Result<CameraParts, SceneError> {
    let invalid = |field: &str, message: String| SceneError::Invalid {
        path: path.to_owned(),
        field: field.to_owned(),
        message,
    };
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
    let head = match (&c.pose, &c.head) {
        (Some(_), Some(_)) => {
            return Err(invalid(
                "camera.pose",
                "a camera on a head ([camera.head]) takes its pose from the head and the mount; remove camera.pose".into(),
            ));
        }
        (None, None) => {
            return Err(invalid(
                "camera.pose",
                "missing: a fixed camera needs { eye, target, up } (or [camera.head] for one on a head)".into(),
            ));
        }
        (None, Some(h)) => Some(
            HeadRig::resolve(h, ce)
                .map_err(|(field, message)| invalid(&format!("camera.head.{field}"), message))?,
        ),
        (Some(_), None) => None,
    };
    let pose = match (&c.pose, &head) {
        (Some(p), _) => p
            .to_isometry()
            .map_err(|e| SceneError::value("camera.pose", e).in_file(path))?,
        (None, Some(h)) => h.camera_at(0.0),
        (None, None) => unreachable!("checked above"),
    };
    let true_camera = PinholeCamera {
        intrinsics,
        world_from_camera: pose,
    };
    let lens = match &c.distortion {
        Some(l) => {
            let lens = Distortion::from_ros(&l.model, &l.coefficients)
                .map_err(|e| SceneError::value("camera.distortion", e).in_file(path))?;
            // The lens must invert over the image (a render can be drawn through it).
            lens.check_over(&intrinsics)
                .map_err(|e| SceneError::value("camera.distortion", e).in_file(path))?;
            lens
        }
        None => Distortion::None,
    };
    // A head camera's error is its mount's (in the head's frame), already in `believed_mount`.
    let believed_camera = match &head {
        Some(h) => PinholeCamera {
            intrinsics,
            world_from_camera: h.believed_camera_at(0.0),
        },
        None => true_camera.perturbed(
            &Vector3::from(ce.axis),
            ce.rotation_deg.to_radians(),
            &(Vector3::from(ce.translation_mm) * 1e-3),
        ),
    };

    Ok(CameraParts {
        true_camera,
        believed_camera,
        lens,
        head,
    })
}

/// A camera on a head (`[camera.head]`), resolved: the head's motion, the mount and how the
/// head is tracked.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadRig {
    /// Where the head is over time (`world_from_head`).
    pub motion: HeadMotion,
    /// The camera in the head's frame (`head_from_camera`), true.
    pub mount: Isometry3<f64>,
    /// The mount as the app believes it: with `[camera] calibration_error` (head frame).
    pub believed_mount: Isometry3<f64>,
    /// How the headset reports the head.
    pub tracking: TrackingModel,
    /// Background views kept (0: none, the `[background]` image alone).
    pub background_views: usize,
    /// A frame becomes a background view this far (rad) from every kept one.
    pub background_separation_rad: f64,
    /// CPU threads that re-project the background views (0: one per core).
    pub background_threads: usize,
}

impl HeadRig {
    /// Checks and resolves `spec`; `error` is the mount's calibration error. Errors give the
    /// field under `camera.head` and the message.
    pub fn resolve(spec: &HeadSpec, error: &CalibrationError) -> Result<Self, (String, String)> {
        let motion = match (&spec.sweep, spec.keyframes.is_empty()) {
            (Some(_), false) => {
                return Err((
                    "sweep".into(),
                    "give either a sweep or keyframes, not both".into(),
                ));
            }
            (None, true) => {
                return Err((
                    "keyframes".into(),
                    "a head needs a motion: a sweep = { eye, target, peak_speed_deg_s } or [[camera.head.keyframes]]".into(),
                ));
            }
            (Some(w), true) => {
                if !(0.0..=90.0).contains(&w.amplitude_deg) {
                    return Err((
                        "sweep.amplitude_deg".into(),
                        format!("{} must be within 0..=90", w.amplitude_deg),
                    ));
                }
                if !(0.0..=720.0).contains(&w.peak_speed_deg_s) {
                    return Err((
                        "sweep.peak_speed_deg_s".into(),
                        format!("{} must be within 0..=720", w.peak_speed_deg_s),
                    ));
                }
                if w.peak_speed_deg_s > 0.0 && w.amplitude_deg <= 0.0 {
                    return Err((
                        "sweep.amplitude_deg".into(),
                        "a moving sweep needs an amplitude > 0".into(),
                    ));
                }
                if !(0.0..=0.3).contains(&w.pivot_back_m) {
                    return Err((
                        "sweep.pivot_back_m".into(),
                        format!("{} must be within 0..=0.3 m", w.pivot_back_m),
                    ));
                }
                let centre = CameraPose {
                    eye: w.eye,
                    target: w.target,
                    up: [0.0, 0.0, 1.0],
                }
                .to_isometry()
                .map_err(|e| ("sweep".to_owned(), e.to_string()))?;
                HeadMotion::Sweep {
                    centre,
                    amplitude_rad: w.amplitude_deg.to_radians(),
                    peak_speed_rad_s: w.peak_speed_deg_s.to_radians(),
                    pivot_back_m: w.pivot_back_m,
                }
            }
            (None, false) => {
                let mut keys = Vec::with_capacity(spec.keyframes.len());
                for (i, k) in spec.keyframes.iter().enumerate() {
                    if k.t_s < 0.0 || (i > 0 && k.t_s <= spec.keyframes[i - 1].t_s) {
                        return Err((
                            format!("keyframes[{i}].t_s"),
                            format!("{} must be >= 0 and after the previous keyframe's", k.t_s),
                        ));
                    }
                    let pose = CameraPose {
                        eye: k.eye,
                        target: k.target,
                        up: k.up,
                    };
                    pose.to_isometry()
                        .map_err(|e| (format!("keyframes[{i}]"), e.to_string()))?;
                    keys.push((k.t_s, pose));
                }
                HeadMotion::look_at(&keys).map_err(|e| ("keyframes".to_owned(), e.to_string()))?
            }
        };
        let t = &spec.tracking;
        let tracking = TrackingModel {
            rate_hz: t.rate_hz,
            latency_s: t.latency_s,
            position_sigma_m: t.position_sigma_mm * 1e-3,
            angle_sigma_rad: t.angle_sigma_deg.to_radians(),
        };
        tracking
            .validate("tracking")
            .map_err(|e| ("tracking".to_owned(), e.to_string()))?;
        let mount = spec.mount.to_isometry();
        if mount.translation.vector.norm() > 1.0 {
            return Err((
                "mount.xyz".into(),
                "the camera is more than 1 m from the head".into(),
            ));
        }
        let b = &spec.background;
        if b.views > 32 {
            return Err((
                "background.views".into(),
                format!("{} must be within 0..=32", b.views),
            ));
        }
        if !(0.0..=90.0).contains(&b.min_separation_deg) {
            return Err((
                "background.min_separation_deg".into(),
                format!("{} must be within 0..=90", b.min_separation_deg),
            ));
        }
        if b.threads > 256 {
            return Err((
                "background.threads".into(),
                format!("{} must be within 0..=256 (0: one per core)", b.threads),
            ));
        }
        let believed_mount = perturbed_mount(
            &mount,
            &Vector3::from(error.axis),
            error.rotation_deg.to_radians(),
            &(Vector3::from(error.translation_mm) * 1e-3),
        );
        Ok(Self {
            motion,
            mount,
            believed_mount,
            tracking,
            background_views: b.views as usize,
            background_separation_rad: b.min_separation_deg.to_radians(),
            background_threads: b.threads as usize,
        })
    }

    /// The camera's true pose (`world_from_camera`, optical frame) at `t_s`.
    pub fn camera_at(&self, t_s: f64) -> Isometry3<f64> {
        self.motion.pose_at(t_s) * self.mount
    }

    /// The pose the app would believe at `t_s` from a perfect tracker: the head's true pose
    /// times the believed mount.
    pub fn believed_camera_at(&self, t_s: f64) -> Isometry3<f64> {
        self.motion.pose_at(t_s) * self.believed_mount
    }

    /// With the sweep's peak speed set to `deg_s` (a keyframed motion is left as it is; returns
    /// whether it was a sweep).
    pub fn set_sweep_speed(&mut self, deg_s: f64) -> bool {
        match &mut self.motion {
            HeadMotion::Sweep {
                peak_speed_rad_s, ..
            } => {
                *peak_speed_rad_s = deg_s.to_radians();
                true
            }
            HeadMotion::Keyframes(_) | HeadMotion::Live(_) => false,
        }
    }
}
