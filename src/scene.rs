//! Scene files: the robot, the cameras, the room, the simulation, the timeline.
//!
//! TOML, documented in `docs/scene-format.md`. Paths inside a scene are relative to the scene
//! file. [`Scene::load`] parses and validates; every error names the file and the field.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use avatarm_core::camera::{CameraPose, Intrinsics, PinholeCamera};
use avatarm_core::dr::EraseSettings;
use avatarm_core::robot::{PackagePath, RobotModel};
use avatarm_core::sensor::SensorModel;
use avatarm_core::sim::SimRobotParams;
use avatarm_core::trajectory::{JointTrajectory, Keyframe};
use avatarm_sim::{Prop, PropShape};
use nalgebra::{DVector, Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

/// Errors loading a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: cannot read scene: {source}")]
    Io {
        /// The scene file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not valid TOML, or a field of the wrong type, or an unknown field.
    #[error("{path}: {message}")]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// The parser's message (with line and column).
        message: String,
    },
    /// A field's value is not usable.
    #[error("{path}: {field}: {message}")]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// The field, dotted (`camera.intrinsics.fx`).
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The robot description failed to load.
    #[error("{path}: robot.urdf: {source}")]
    Robot {
        /// The scene file.
        path: PathBuf,
        /// Why.
        source: Box<avatarm_core::Error>,
    },
}

/// A pose: position and roll-pitch-yaw (rad, fixed axes, as URDF).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// Position (m).
    #[serde(default)]
    pub xyz: [f64; 3],
    /// Roll, pitch, yaw (rad).
    #[serde(default)]
    pub rpy: [f64; 3],
}

impl PoseSpec {
    /// As an isometry.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.xyz[0], self.xyz[1], self.xyz[2]),
            UnitQuaternion::from_euler_angles(self.rpy[0], self.rpy[1], self.rpy[2]),
        )
    }
}

/// Joint positions, by name (`{ right_j0 = 0.1 }`) or in joint-vector order (`[0.1, ...]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum JointValues {
    /// By joint name.
    Named(BTreeMap<String, f64>),
    /// In joint-vector order (missing trailing joints keep their previous value).
    List(Vec<f64>),
}

/// `[robot]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// URDF file, relative to the scene file.
    pub urdf: PathBuf,
    /// Folders for `package://` URIs, relative to the scene file.
    #[serde(default)]
    pub package_path: Vec<PathBuf>,
    /// Pose of the robot's root link in the world.
    #[serde(default)]
    pub base: PoseSpec,
    /// Initial joint positions.
    pub q0: Option<JointValues>,
    /// Simulated robot timing and response.
    #[serde(default)]
    pub sim: SimRobotParams,
}

/// Calibration error between the camera's true pose and the pose the app believes.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationError {
    /// Rotation error (degrees) about `axis` through the camera centre.
    pub rotation_deg: f64,
    /// Rotation axis (world).
    pub axis: [f64; 3],
    /// Translation error (mm, world).
    pub translation_mm: [f64; 3],
}

/// `[camera]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Intrinsics; when absent, `fov_y_deg` with `width` × `height`.
    pub intrinsics: Option<Intrinsics>,
    /// Vertical field of view (degrees), used when `intrinsics` is absent.
    #[serde(default = "default_fov")]
    pub fov_y_deg: f64,
    /// Width (px), with `fov_y_deg`.
    #[serde(default = "default_width")]
    pub width: u32,
    /// Height (px), with `fov_y_deg`.
    #[serde(default = "default_height")]
    pub height: u32,
    /// True pose.
    pub pose: CameraPose,
    /// Frames per second.
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Delay from capture to arrival (s).
    #[serde(default)]
    pub frame_latency_s: f64,
    /// Noise and exposure.
    #[serde(default)]
    pub sensor: SensorModel,
    /// Error of the pose the app believes.
    #[serde(default)]
    pub calibration_error: CalibrationError,
}

fn default_fov() -> f64 {
    55.0
}
fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}
fn default_fps() -> f64 {
    30.0
}
fn default_rate() -> f64 {
    100.0
}

/// `[[props]]`: a prop or real object.
#[derive(Debug, Clone, Deserialize)]
pub struct PropSpec {
    /// Name.
    pub name: String,
    /// Shape and size (`shape = "box" | "cylinder" | "bottle" | "sphere"`).
    #[serde(flatten)]
    pub shape: PropShape,
    /// Pose of the base centre.
    #[serde(default)]
    pub pose: PoseSpec,
    /// Colour, sRGB + alpha.
    #[serde(default = "default_rgba")]
    pub rgba: [f32; 4],
    /// One of the real objects the user manipulates (vs. a prop).
    #[serde(default)]
    pub object: bool,
    /// Known to the app as something that can hide the robot (the desk): the mask camera draws
    /// it black so that the mask follows the robot's visible pixels.
    #[serde(default)]
    pub occluder: bool,
}

fn default_rgba() -> [f32; 4] {
    [0.6, 0.6, 0.6, 1.0]
}

/// A keyframe of `[[timeline.robot]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotKeyframe {
    /// Time (s).
    pub t_s: f64,
    /// Joint positions; joints not given keep the previous keyframe's value.
    pub q: JointValues,
}

/// `[timeline]`.
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Timeline {
    /// Joint-position keyframes of the robot (minimum-jerk in between).
    #[serde(default)]
    pub robot: Vec<RobotKeyframe>,
}

/// The scene file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Name, for reports.
    pub name: String,
    /// Random seed: the same seed gives the same replay.
    #[serde(default)]
    pub seed: u64,
    /// Length of the replay (s).
    pub duration_s: f64,
    /// Control and simulation step rate (Hz).
    #[serde(default = "default_rate")]
    pub control_rate_hz: f64,
    /// The robot.
    pub robot: RobotSpec,
    /// The real camera.
    pub camera: CameraSpec,
    /// The room.
    #[serde(default)]
    pub props: Vec<PropSpec>,
    /// What happens.
    #[serde(default)]
    pub timeline: Timeline,
    /// How the robot is erased (`[erase]`).
    #[serde(default)]
    pub erase: EraseSettings,
    /// Where the background H comes from (`[background]`).
    #[serde(default)]
    pub background: BackgroundSpec,
    /// The interaction layer (`[interaction]`).
    #[serde(default)]
    pub interaction: InteractionSpec,
    /// The teleoperation task measured on every replay (`[task]`), e.g. the paper's pouring.
    #[serde(default)]
    pub task: Option<avatarm_mapping::pouring::PouringTask>,
    /// Start `avatarm run` in XR (an OpenXR headset), as `--xr` does.
    #[serde(default)]
    pub xr: bool,
    /// The hand that teleoperates the `[task]` in `avatarm run` (as `--hand`): scripted,
    /// desktop, xr, leap, a `.hand.jsonl` file or none.
    #[serde(default)]
    pub hand: Option<String>,
    /// Where the interaction layer sits in the headset (`[xr_layout]`).
    #[serde(default)]
    pub xr_layout: XrLayout,
}

/// `[xr_layout]`: the interaction layer in the headset, relative to where the user's head is
/// when the session starts (looking ahead).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct XrLayout {
    /// Distance of the video panel in front of the eyes (m).
    pub panel_distance_m: f64,
    /// Height of the video panel (m); its width follows the camera's aspect ratio.
    pub panel_height_m: f64,
    /// How far the panel's centre is below eye level (m): a little below is easier on the
    /// neck for a seated user.
    pub panel_below_eye_m: f64,
}

impl Default for XrLayout {
    fn default() -> Self {
        Self {
            panel_distance_m: 1.2,
            panel_height_m: 0.7,
            panel_below_eye_m: 0.15,
        }
    }
}

/// `[background]`: where the background image H comes from.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(tag = "source", rename_all = "snake_case", deny_unknown_fields)]
pub enum BackgroundSpec {
    /// The simulated room photographed with the robot out of the way, through the same sensor
    /// model (simulated room only).
    #[default]
    EmptyRoom,
    /// An image file of the camera's size (PNG or JPEG), relative to the scene.
    File {
        /// The image.
        path: PathBuf,
    },
    /// The live frame at a time of the timeline (s), e.g. while the robot is out of view.
    Capture {
        /// When (s).
        at_s: f64,
    },
    /// None until one is captured on command (the preview's B key).
    None,
}

/// `[interaction]`: the layout of what the user sees.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InteractionSpec {
    /// Distance of the video panel from the viewer (m).
    pub panel_distance_m: f64,
    /// Depth of the object twins, in front of the panel (m).
    pub object_depth_m: f64,
}

impl Default for InteractionSpec {
    fn default() -> Self {
        Self {
            panel_distance_m: 2.5,
            object_depth_m: 1.0,
        }
    }
}

/// A loaded, validated scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Where it came from.
    pub path: PathBuf,
    /// As written.
    pub file: SceneFile,
    /// The robot.
    pub model: Arc<RobotModel>,
    /// Initial joint positions.
    pub q0: DVector<f64>,
    /// The robot timeline.
    pub trajectory: JointTrajectory,
    /// The camera at its true pose.
    pub true_camera: PinholeCamera,
    /// The camera at the pose the app believes (true pose + calibration error).
    pub believed_camera: PinholeCamera,
    /// Props in the room.
    pub props: Vec<Prop>,
    /// The background image file, resolved (`[background] source = "file"`).
    pub background_path: Option<PathBuf>,
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
        let file: SceneFile = toml::from_str(text).map_err(|e| SceneError::Parse {
            path: path.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        let invalid = |field: &str, message: String| SceneError::Invalid {
            path: path.to_owned(),
            field: field.to_owned(),
            message,
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
        let c = &file.camera;
        if !(c.fps.is_finite() && (1.0..=1000.0).contains(&c.fps)) {
            return Err(invalid(
                "camera.fps",
                format!("{} must be within 1..=1000", c.fps),
            ));
        }
        if !(c.frame_latency_s.is_finite() && c.frame_latency_s >= 0.0) {
            return Err(invalid("camera.frame_latency_s", "must be >= 0".into()));
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
            .map_err(|e| invalid("erase", e.to_string()))?;
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
            h.parse::<crate::teleop::HandChoice>()
                .map_err(|e| invalid("hand", e))?;
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
        let model = RobotModel::from_urdf_file(&dir.join(&file.robot.urdf), &packages).map_err(
            |source| SceneError::Robot {
                path: path.to_owned(),
                source: Box::new(source),
            },
        )?;

        let values = |field: &str, v: &JointValues, previous: &DVector<f64>| {
            let mut q = previous.clone();
            match v {
                JointValues::Named(map) => {
                    for (name, value) in map {
                        let i = model
                            .dof_index(name)
                            .map_err(|e| invalid(field, e.to_string()))?;
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
                .map_err(|e| invalid(field, e.to_string()))?;
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
            .map_err(|e| invalid("camera.intrinsics", e.to_string()))?;
        let pose = c
            .pose
            .to_isometry()
            .map_err(|e| invalid("camera.pose", e.to_string()))?;
        let true_camera = PinholeCamera {
            intrinsics,
            world_from_camera: pose,
        };
        let ce = &c.calibration_error;
        let believed_camera = true_camera.perturbed(
            &Vector3::from(ce.axis),
            ce.rotation_deg.to_radians(),
            &(Vector3::from(ce.translation_mm) * 1e-3),
        );

        let mut props = Vec::new();
        for (i, p) in file.props.iter().enumerate() {
            let positive = match p.shape {
                PropShape::Box { size } => size.iter().all(|v| *v > 0.0),
                PropShape::Cylinder { radius, height } | PropShape::Bottle { radius, height } => {
                    radius > 0.0 && height > 0.0
                }
                PropShape::Sphere { radius } => radius > 0.0,
            };
            if !positive {
                return Err(invalid(
                    &format!("props[{i}] ({})", p.name),
                    "sizes must be positive".into(),
                ));
            }
            props.push(Prop {
                name: p.name.clone(),
                shape: p.shape.clone(),
                pose: p.pose.to_isometry(),
                rgba: p.rgba,
            });
        }
        Ok(Scene {
            path: path.to_owned(),
            background_path,
            model: Arc::new(model),
            q0,
            trajectory: JointTrajectory::new(keyframes),
            true_camera,
            believed_camera,
            props,
            file,
        })
    }

    /// The robot base pose.
    pub fn robot_base(&self) -> Isometry3<f64> {
        self.file.robot.base.to_isometry()
    }
}

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
    /// Load the background H from an image file (the camera's size).
    #[arg(long, value_name = "PATH", conflicts_with = "capture_background_at")]
    pub background: Option<PathBuf>,
    /// Capture the background H from the live frame at this time (s).
    #[arg(long, value_name = "S")]
    pub capture_background_at: Option<f64>,
}

/// Parses `on`/`off` (also `true`/`false`, `1`/`0`) for command-line switches.
pub fn on_off(s: &str) -> Result<bool, String> {
    match s {
        "on" | "true" | "1" => Ok(true),
        "off" | "false" | "0" => Ok(false),
        _ => Err(format!("'{s}': expected on or off")),
    }
}

impl Scene {
    /// Applies command-line overrides and checks the result; errors name the flag.
    pub fn apply_overrides(&mut self, o: &EraseOverrides) -> Result<(), String> {
        let e = &mut self.file.erase;
        if let Some(v) = o.erase {
            e.enabled = v;
        }
        if let Some(v) = o.dilate {
            e.dilate_px = v;
        }
        if let Some(v) = o.feather {
            e.feather_px = v;
        }
        if let Some(v) = o.latency_compensation {
            e.latency_compensation = v;
        }
        if let Some(v) = o.photometric {
            e.photometric = v;
        }
        if let Some(v) = o.mask_scale {
            e.resolution_scale = v;
        }
        if let Some(v) = o.background_refresh {
            e.background_refresh = v as f32;
        }
        e.validate("command line").map_err(|e| e.to_string())?;
        if let Some(path) = &o.background {
            if !path.is_file() {
                return Err(format!("--background: {} does not exist", path.display()));
            }
            self.file.background = BackgroundSpec::File { path: path.clone() };
            self.background_path = Some(path.clone());
        }
        if let Some(at_s) = o.capture_background_at {
            if !(at_s.is_finite() && at_s >= 0.0) {
                return Err(format!("--capture-background-at: {at_s} must be >= 0"));
            }
            self.file.background = BackgroundSpec::Capture { at_s };
            self.background_path = None;
        }
        Ok(())
    }
}
