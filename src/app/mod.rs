//! The app's base, assembled from the plugins: [`build_app`] for a scene with what the front
//! end on top needs of it ([`AppBase`]: the clock and window, the camera's source, the room's
//! ground truth), the app's own twin of the robot ([`AppTwin`]) and the scene as a resource
//! ([`SceneResource`]). The front ends build on it and add their own plugin: the preview
//! ([`crate::preview::build_app`]), the headless replay ([`crate::replay::build_app`]) and the
//! robot site's video ([`crate::net::video::build_app`]). Nothing here knows them.
//!
//! - [`background`]: where the background H comes from (the scene's `[background]`).

pub mod background;
pub mod drift;
#[cfg(feature = "ros")]
pub mod ros2_camera;

use std::time::Duration;

use avatarm_core::robot::JointMap;
use avatarm_erase::interaction::ObjectTwinSpec;
use avatarm_erase::{EraseConfig, ErasePlugin, InteractionConfig, InteractionPlugin};
use avatarm_sim::{SimHead, SimRoomConfig, SimRoomPlugin, SimVideo};
use avatarm_twin::layers;
use avatarm_twin::prelude::*;
use avatarm_video::{LiveVideo, VideoPlugin};
use bevy::app::{PluginGroupBuilder, ScheduleRunnerPlugin};
use bevy::camera::visibility::RenderLayers;
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::time::TimeUpdateStrategy;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;

use avatarm_scene::Scene;
use avatarm_scene::spec::BackgroundSpec;

use crate::AppError;

/// How the app's clock and window run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Runner {
    /// No window: one camera frame of simulated time per update, as fast as it renders (the
    /// replay).
    Replay,
    /// No window, in real time (the robot site's video): one update per camera frame at most
    /// for the simulated camera; a real camera's frames wake the app, an update as soon as one
    /// arrives ([`avatarm_video::wake`]). Bevy's log set-up is left out: the caller's stays.
    RealTime,
    /// A window, through OpenXR's plugins when `xr` (falling back to the window without a
    /// runtime), with a fixed step (s) per update when given.
    Window {
        /// Through OpenXR.
        xr: bool,
        /// Simulated seconds per update, instead of the wall clock's.
        fixed_step_s: Option<f64>,
    },
}

/// Where the camera's frames come from: the simulated room's camera, or a real camera source
/// read on a thread of its own (docs/latency.md).
#[derive(Debug, Clone, Default)]
pub enum CameraSource {
    /// The simulated room's camera (rendered, read back, delayed by its latency).
    #[default]
    Simulated,
    /// A webcam by its index (feature `webcam`).
    Webcam(u32),
    /// A recording played as a live camera, frames released at their capture times.
    Recording(avatarm_video::recorded::RecordedCameraConfig),
    /// A ROS 2 camera topic over DDS or rmw_zenoh (feature `ros`).
    #[cfg(feature = "ros")]
    Ros2(avatarm_ros::ros2::camera::CameraTopic),
}

impl CameraSource {
    /// Whether the simulated room renders the video.
    pub fn is_simulated(&self) -> bool {
        matches!(self, Self::Simulated)
    }

    /// The source's name, for messages.
    pub fn name(&self) -> String {
        match self {
            Self::Simulated => "simulated camera".to_owned(),
            Self::Webcam(i) => format!("webcam {i}"),
            Self::Recording(r) => r.name.clone(),
            #[cfg(feature = "ros")]
            Self::Ros2(t) => format!("ROS 2 camera {}", t.topic),
        }
    }
}

/// What the app's base ([`AvatarmPlugins`]) takes from the front end built on top of it.
#[derive(Debug, Clone)]
pub struct AppBase {
    /// The clock and the window.
    pub runner: Runner,
    /// Where the camera's frames come from (nothing renders the simulated room's video but
    /// for [`CameraSource::Simulated`]).
    pub camera: CameraSource,
    /// Render the room's ground truth (its robot-free view) even where no camera takes the
    /// empty room as its background: a replay scores against it.
    pub ground_truth: bool,
    /// The scene through the other cameras the front end may switch to (their backgrounds
    /// count for [`AppBase::empty_room_anywhere`]).
    pub other_cameras: Vec<Scene>,
    /// Render the interaction layer (the virtual hand and the object twins in front of the
    /// panel): the views need it; the robot site, which publishes the erased frames only, does
    /// not.
    pub interaction_layer: bool,
}

impl AppBase {
    /// A base with `runner`, the simulated camera, no forced ground truth and no other camera.
    pub fn new(runner: Runner) -> Self {
        Self {
            runner,
            camera: CameraSource::Simulated,
            ground_truth: false,
            other_cameras: Vec::new(),
            interaction_layer: true,
        }
    }

    /// Whether the scene's camera, or one the front end can switch to, takes the simulated
    /// empty room as its background.
    pub fn empty_room_anywhere(&self, scene: &Scene) -> bool {
        std::iter::once(scene)
            .chain(&self.other_cameras)
            .any(|s| s.file.background == BackgroundSpec::EmptyRoom)
    }
}

/// The app's own twin of the robot (what the app believes, from received joint states).
#[derive(Resource, Debug, Clone, Copy)]
pub struct AppTwin(pub Entity);

impl AppTwin {
    /// Sends `states` (the robot's, in `model`'s joint order) to the twin, each stamp less
    /// `minus_s` (s; 0 for stamps already on the app's clock).
    pub fn send<'a>(
        &self,
        writer: &mut MessageWriter<JointStateMessage>,
        model: &avatarm_core::robot::RobotModel,
        states: impl IntoIterator<Item = &'a avatarm_core::sim::JointState>,
        minus_s: f64,
    ) {
        for s in states {
            writer.write(JointStateMessage::full(
                self.0,
                model,
                &s.positions,
                &s.velocities,
                s.stamp_s - minus_s,
            ));
        }
    }
}

/// The scene being run.
#[derive(Resource, Debug, Clone)]
pub struct SceneResource(pub Scene);

/// Bevy's plugins without a window: rendering into images only, pipelines compiled before the
/// frame that needs them (a replay's first frames are complete), the app kept alive without a
/// window. For the replay and the benches' own apps.
pub fn headless_plugins() -> PluginGroupBuilder {
    crate::log::with_log(DefaultPlugins)
        .set(WindowPlugin {
            primary_window: None,
            exit_condition: ExitCondition::DontExit,
            ..default()
        })
        .set(RenderPlugin {
            synchronous_pipeline_compilation: true,
            ..default()
        })
        .disable::<WinitPlugin>()
}

/// Builds the app's base for a scene: Bevy's window or headless renderer as `base.runner`
/// says, then [`AvatarmPlugins`]. The front end adds its own plugin after.
pub fn build_app(scene: &Scene, base: &AppBase) -> Result<App, AppError> {
    let mut app = App::new();
    let frame_dt = Duration::from_secs_f64(1.0 / scene.file.camera.fps);
    match base.runner {
        Runner::Replay => {
            app.add_plugins((
                headless_plugins(),
                ScheduleRunnerPlugin::run_loop(Duration::ZERO),
            ))
            .insert_resource(TimeUpdateStrategy::ManualDuration(frame_dt));
        }
        Runner::RealTime => {
            // Real time (the clock is the wall's); one update per camera frame at most. The
            // site's own log set-up stays (the control loop logs before the app exists).
            app.add_plugins(headless_plugins().disable::<bevy::log::LogPlugin>());
            if base.camera.is_simulated() {
                app.add_plugins(ScheduleRunnerPlugin::run_loop(frame_dt));
            } else {
                // A real camera wakes the app with each frame: it is taken in the update right
                // after it arrives, not at the next tick of a fixed schedule.
                app.add_plugins(avatarm_video::wake::FrameDrivenRunnerPlugin {
                    max_wait: frame_dt,
                    min_period: Duration::from_millis(2),
                });
            }
        }
        Runner::Window { xr, fixed_step_s } => {
            check_display()?;
            let window = Window {
                title: format!("Avatarm — {}", scene.file.name),
                resolution: (1280u32, 720u32).into(),
                ..default()
            };
            let plugins = crate::log::with_log(DefaultPlugins.set(WindowPlugin {
                primary_window: Some(window),
                ..default()
            }));
            add_window_plugins(&mut app, plugins, xr);
            if let Some(step) = fixed_step_s {
                app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
                    step,
                )));
            }
        }
    }
    app.add_plugins(AvatarmPlugins {
        scene: scene.clone(),
        base: base.clone(),
    });
    Ok(app)
}

/// Errors with [`AppError::NoDisplay`] where a window cannot open (no X11 or Wayland display):
/// winit panics without one, so a windowed mode checks first and says what to do instead.
pub fn check_display() -> Result<(), AppError> {
    let no_display = ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"]
        .iter()
        .all(|v| std::env::var_os(v).is_none_or(|s| s.is_empty()));
    if cfg!(all(unix, not(target_os = "macos"))) && no_display {
        return Err(AppError::NoDisplay);
    }
    Ok(())
}

/// The interaction layer's layout for `scene`: the believed camera (as the interaction camera
/// and as the real one), the scene's panel distance and object depth, and a twin of each prop
/// marked `object` at its pose.
pub fn interaction_config(scene: &Scene) -> InteractionConfig {
    InteractionConfig {
        camera: scene.believed_camera,
        real_camera: scene.believed_camera,
        panel_distance_m: scene.file.interaction.panel_distance_m,
        object_depth_m: scene.file.interaction.object_depth_m,
        objects: scene
            .file
            .props
            .iter()
            .zip(&scene.props)
            .filter(|(spec, _)| spec.object)
            .map(|(_, prop)| ObjectTwinSpec {
                name: prop.name.clone(),
                parts: avatarm_sim::prop_parts(&prop.shape),
                world_from_object: prop.pose,
                rgba: prop.rgba,
            })
            .collect(),
    }
}

/// The meshes of the scene's props marked `occluder` (the desk), at their world transforms: what
/// the mask's view draws in black.
pub fn scene_occluders(scene: &Scene) -> Vec<(Mesh, Transform)> {
    scene
        .file
        .props
        .iter()
        .zip(&scene.props)
        .filter(|(spec, _)| spec.occluder)
        .flat_map(|(_, prop)| {
            avatarm_sim::prop_parts(&prop.shape)
                .into_iter()
                .map(|(mesh, local)| (mesh, iso_to_transform(&prop.pose) * local))
        })
        .collect()
}

/// Avatarm's base plugins for a scene, on top of Bevy's window or headless renderer
/// ([`build_app`] adds those): the robot twin, image read-backs, the simulated room, the video
/// (the simulated camera's, a webcam or a recording played live), the erase pipeline and the interaction layer, and the
/// background source. [`AvatarmSetupPlugin`] goes first: it inserts the scene's resources the
/// others read, and orders [`AvatarmSystems`]. The front end's own plugin (the replay, the
/// preview, the robot site's video) comes after.
pub struct AvatarmPlugins {
    /// The scene.
    pub scene: Scene,
    /// What the front end needs of the base.
    pub base: AppBase,
}

impl PluginGroup for AvatarmPlugins {
    fn build(self) -> PluginGroupBuilder {
        let mut group = PluginGroupBuilder::start::<Self>()
            .add(AvatarmSetupPlugin {
                scene: self.scene.clone(),
                base: self.base.clone(),
            })
            .add(RobotTwinPlugin)
            // Before the room (which adds it too when alone): the replay, the live scores and
            // the empty-room background read images back with it.
            .add(avatarm_twin::readback::ImageReadbackPlugin)
            .add(SimRoomPlugin)
            .add(VideoPlugin)
            .add(ErasePlugin)
            .add(InteractionPlugin)
            .add(background::BackgroundSourcePlugin);
        if !self.base.interaction_layer {
            group = group.disable::<InteractionPlugin>();
        }
        // A real camera can be bumped; the simulated room's never moves.
        if self.scene.file.erase.drift_watch && !self.base.camera.is_simulated() {
            group = group.add(drift::DriftWatchPlugin(drift::live_settings()));
        }
        match &self.base.camera {
            CameraSource::Simulated => {}
            #[cfg(feature = "webcam")]
            CameraSource::Webcam(index) => {
                let k = &self.scene.true_camera.intrinsics;
                group = group.add(avatarm_video::webcam::WebcamPlugin(
                    avatarm_video::webcam::WebcamConfig {
                        index: *index,
                        width: k.width,
                        height: k.height,
                        fps: self.scene.file.camera.fps.round().max(1.0) as u32,
                        latency_s: self.scene.file.camera.frame_latency_s,
                    },
                ));
            }
            // The command line refuses --webcam in a build without the feature.
            #[cfg(not(feature = "webcam"))]
            CameraSource::Webcam(_) => {}
            CameraSource::Recording(config) => {
                group = group.add(avatarm_video::recorded::RecordedCameraPlugin(
                    config.clone(),
                ));
            }
            #[cfg(feature = "ros")]
            CameraSource::Ros2(topic) => {
                group = group.add(ros2_camera::Ros2CameraPlugin(topic.clone()));
            }
        }
        group
    }
}

/// The app's own system sets, ordered once by [`AvatarmSetupPlugin`] against the plugins'
/// sets. Each variant says its schedule.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AvatarmSystems {
    /// `FixedUpdate`, after the mapping's tick (and the simulated room's own stepping, which
    /// the live teleoperation switches off): the live teleoperation puts the simulated arm
    /// and the carried object where the loop left them.
    Mirror,
    /// `Update`, between the video's publish and the erase pipeline's prepare: the background
    /// H from the scene's source.
    Background,
    /// `Update`, after the erase pipeline's prepare and before the object twins follow their
    /// objects: the live teleoperation moves the twins and draws the hands. Its start-up
    /// systems are in this set in `Startup`.
    Teleop,
    /// `Update`, after the interaction layer: the preview's keys, panel and status line.
    View,
    /// `Update`, after the preview (whose key re-centres the headset's panel): the XR view,
    /// its panel and the tracked hands. In `Startup` too, after [`AvatarmSystems::Teleop`].
    Xr,
    /// `Last`, after the simulated room's capture: read-backs, scores and the replay's
    /// stepping.
    Score,
}

/// The simulated camera's video for `scene`'s camera: its sensor model, latency and fps.
pub(crate) fn sim_video(scene: &Scene) -> SimVideo {
    SimVideo {
        sensor: scene.file.camera.sensor.clone(),
        frame_latency_s: scene.file.camera.frame_latency_s,
        seed: scene.file.seed,
        fps: scene.file.camera.fps,
    }
}

/// The simulated head `scene`'s camera rides on, if it does.
pub(crate) fn sim_head(scene: &Scene) -> Option<SimHead> {
    scene.head.as_ref().map(|h| SimHead {
        motion: h.motion.clone(),
        mount: h.mount,
        tracking: h.tracking,
        seed: scene.file.seed,
    })
}

/// The live video's state for `scene`'s camera from `source`: stale after three frame periods
/// (at least 0.2 s) plus the camera's latency.
pub(crate) fn live_video(scene: &Scene, source: &CameraSource) -> LiveVideo {
    LiveVideo::new(
        source.name(),
        (3.0 / scene.file.camera.fps).max(0.2) + scene.file.camera.frame_latency_s,
    )
}

/// The erase pipeline's configuration for `scene`'s camera (no source twin yet: the app's
/// twin, once spawned).
pub(crate) fn erase_config(scene: &Scene) -> EraseConfig {
    EraseConfig {
        settings: scene.file.erase,
        camera: scene.believed_camera,
        distortion: scene.lens,
        joint_map: JointMap::new(&scene.model, &scene.twin_model),
        model: scene.twin_model.clone(),
        detail: twin_detail(&scene.file.twin),
        base: scene.robot_base(),
        source_twin: None,
        occluders: scene_occluders(scene),
        head_mount: scene.head.as_ref().map(|h| h.believed_mount),
        view_background: view_background(scene),
    }
}

/// The head's tracked poses (empty for a fixed camera), kept long enough for a frame's capture
/// time to stay inside them: the frames' and the tracking's latency and half a second more.
pub(crate) fn head_tracking(scene: &Scene) -> avatarm_video::HeadTracking {
    let mut tracking = avatarm_video::HeadTracking::default();
    if let Some(head) = &scene.head {
        tracking.history.window_s =
            (scene.file.camera.frame_latency_s + head.tracking.latency_s + 0.5)
                .max(tracking.history.window_s);
    }
    tracking
}

/// A camera on a head with `[camera.head.background] views > 0`: the view-following
/// background, its proxy the scene's boxes that are not objects (desk, wall, floor).
pub fn view_background(scene: &Scene) -> Option<avatarm_erase::ViewBackgroundConfig> {
    let head = scene.head.as_ref().filter(|h| h.background_views > 0)?;
    Some(avatarm_erase::ViewBackgroundConfig {
        proxy: room_proxy(scene, &nalgebra::Isometry3::identity()),
        max_views: head.background_views,
        min_separation_rad: head.background_separation_rad,
        threads: head.background_threads,
    })
}

/// The scene's room as a view-following background's geometric proxy: its boxes that are not
/// objects (desk, wall, floor; a prop of another shape is no plane of the room), each moved by
/// `frame_from_world` into the frame the cameras are posed in (the robot's base frame for a
/// recording: `base_from_world`).
pub fn room_proxy(
    scene: &Scene,
    frame_from_world: &nalgebra::Isometry3<f64>,
) -> avatarm_core::dr::view_background::GeometricProxy {
    let boxes: Vec<_> = scene
        .props
        .iter()
        .zip(&scene.file.props)
        .filter(|(_, spec)| !spec.object)
        .filter_map(|(prop, _)| match prop.shape {
            avatarm_scene::prop::PropShape::Box { size } => {
                Some((frame_from_world * prop.pose, size))
            }
            _ => None,
        })
        .collect();
    avatarm_core::dr::view_background::GeometricProxy::from_boxes(&boxes)
}

/// Inserts the scene's resources (the room, the video, the erase pipeline, the interaction
/// layer), spawns the app's twin of the robot, and orders [`AvatarmSystems`].
pub struct AvatarmSetupPlugin {
    /// The scene.
    pub scene: Scene,
    /// What the front end needs of the base.
    pub base: AppBase,
}

impl Plugin for AvatarmSetupPlugin {
    fn build(&self, app: &mut App) {
        let (scene, base) = (&self.scene, &self.base);
        app.insert_resource(SceneResource(scene.clone()))
            .insert_resource(SimRoomConfig {
                model: scene.model.clone(),
                robot_base: scene.robot_base(),
                robot: scene.file.robot.sim,
                q0: scene.q0.clone(),
                trajectory: scene.trajectory.clone(),
                control_rate_hz: scene.file.control_rate_hz,
                camera: scene.true_camera,
                distortion: scene.lens,
                props: scene.props.clone(),
                // The no-robot view also gives the simulated "empty room" background (of this
                // camera, or of one the preview can switch to).
                ground_truth: base.ground_truth || base.empty_room_anywhere(scene),
                twin: None,
                video: base.camera.is_simulated().then(|| sim_video(scene)),
                head: sim_head(scene),
                external_drive: false,
                room_view: true,
            })
            .insert_resource(live_video(scene, &base.camera))
            .insert_resource(head_tracking(scene))
            .insert_resource(erase_config(scene))
            .insert_resource(interaction_config(scene))
            .add_systems(
                PreStartup,
                spawn_app_twin.after(avatarm_sim::SimRoomSystems::Setup),
            )
            .configure_sets(
                FixedUpdate,
                AvatarmSystems::Mirror
                    .after(avatarm_mapping::MappingSystems::Tick)
                    .after(avatarm_sim::SimRoomSystems::Step),
            )
            .configure_sets(Startup, AvatarmSystems::Xr.after(AvatarmSystems::Teleop))
            .configure_sets(
                Update,
                (
                    AvatarmSystems::Background
                        .after(avatarm_video::VideoSystems::Publish)
                        .before(avatarm_erase::EraseSystems::Prepare),
                    AvatarmSystems::Teleop
                        .after(avatarm_erase::EraseSystems::Prepare)
                        .before(avatarm_erase::EraseSystems::Interaction),
                    AvatarmSystems::View.after(avatarm_erase::EraseSystems::Interaction),
                    AvatarmSystems::Xr.after(AvatarmSystems::View),
                ),
            )
            .configure_sets(
                Last,
                AvatarmSystems::Score.after(avatarm_sim::SimRoomSystems::Capture),
            );
    }
}

/// Adds Bevy's windowed `plugins`, through OpenXR's when `xr` (falling back to the window
/// without a runtime, or with a warning in a build without the `xr` feature).
#[cfg(feature = "xr")]
pub(crate) fn add_window_plugins(app: &mut App, plugins: bevy::app::PluginGroupBuilder, xr: bool) {
    if xr {
        // Hand tracking (as bevy_mod_openxr's default), and the runtime's clock for the
        // headset's display stamps (`preview::glass`); a runtime without one goes on without.
        let mut exts = bevy_mod_openxr::exts::OxrExtensions::default();
        exts.enable_hand_tracking();
        crate::preview::glass::request_clock_conversion(&mut exts);
        // Falls back to the flat renderer, with a log line, when no OpenXR runtime is present.
        app.add_plugins(
            bevy_mod_openxr::add_xr_plugins(plugins)
                .set(bevy_mod_openxr::init::OxrInitPlugin { exts, ..default() }),
        );
    } else {
        app.add_plugins(plugins);
    }
}

/// Adds Bevy's windowed `plugins`; `xr` only warns in this build (no `xr` feature).
#[cfg(not(feature = "xr"))]
pub(crate) fn add_window_plugins(app: &mut App, plugins: bevy::app::PluginGroupBuilder, xr: bool) {
    if xr {
        warn!("--xr: this build has no OpenXR support (feature `xr`); using the desktop preview");
    }
    app.add_plugins(plugins);
}

/// The mask twin's detail as the scene's `[twin]` gives it.
pub fn twin_detail(spec: &avatarm_scene::TwinSpec) -> TwinDetail {
    TwinDetail {
        geometry: spec.geometry,
        keep_triangles: spec.keep_triangles as f32,
    }
}

/// Spawns the app's twin on the twin layer and points the simulated room's joint states at it.
fn spawn_app_twin(
    mut commands: Commands,
    mut config: ResMut<SimRoomConfig>,
    mut erase: ResMut<EraseConfig>,
    mut assets: TwinAssets,
) {
    let twin = spawn_twin_with_visuals(
        &mut commands,
        &mut assets,
        &config.model,
        &config.robot_base,
        TwinAppearance::Urdf,
        TwinDetail::default(),
        &RenderLayers::layer(layers::TWIN),
        "the app's twin",
    );
    config.twin = Some(twin.root);
    erase.source_twin = Some(twin.root);
    commands.insert_resource(AppTwin(twin.root));
}

/// The pairs of systems whose full names (`crate::module::system`) both start with one of
/// `prefixes` and that conflict in some schedule of the main world with no order between them:
/// each as `"SCHEDULE: a <-> b (on C, D)"`. Finishes the app's plugins (waiting for the
/// renderer) and builds every schedule with Bevy's ambiguity detection. With `["avatarm"]`, the
/// project's own systems; the test suite asserts that there are none (docs/architecture.md).
pub fn ambiguities(app: &mut App, prefixes: &[&str]) -> Vec<String> {
    while app.plugins_state() == bevy::app::PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    let ours = |name: &str| prefixes.iter().any(|p| name.starts_with(p));
    let mut found = Vec::new();
    let world = app.world_mut();
    let labels: Vec<_> = world
        .resource::<Schedules>()
        .iter()
        .map(|(_, schedule)| schedule.label())
        .collect();
    for label in labels {
        // Out of `Schedules` while it builds: building looks `Schedules` up in the world.
        let Some(mut schedule) = world.resource_mut::<Schedules>().remove(label) else {
            continue;
        };
        schedule.set_build_settings(bevy::ecs::schedule::ScheduleBuildSettings {
            ambiguity_detection: bevy::ecs::schedule::LogLevel::Warn,
            use_shortnames: false,
            report_sets: false,
            ..default()
        });
        if let Err(e) = schedule.initialize(world) {
            found.push(format!("{label:?}: the schedule does not build: {e}"));
        }
        // Built: the systems live in the executable schedule now, not the graph.
        let names: std::collections::HashMap<_, String> = schedule
            .systems()
            .into_iter()
            .flatten()
            .map(|(key, system)| (key, system.name().to_string()))
            .collect();
        let name = |key| names.get(key).cloned().unwrap_or_default();
        for (a, b, on) in schedule.graph().conflicting_systems().iter() {
            let (a, b) = (name(a), name(b));
            if ours(&a) && ours(&b) {
                let on: Vec<String> = on
                    .iter()
                    .filter_map(|id| world.components().get_name(*id))
                    .map(|n| n.to_string())
                    .collect();
                found.push(format!("{label:?}: {a} <-> {b} (on {})", on.join(", ")));
            }
        }
        world.resource_mut::<Schedules>().insert(schedule);
    }
    found
}
