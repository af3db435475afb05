//! The desktop preview: what the remote user sees (the interaction view Ĩ(t) with the robot
//! erased and the object twins in front), or the raw camera feed, or the mask, beside a 3-D
//! view of the robot twin.
//!
//! Keys: [`keys::PREVIEW_KEYS`] (the one list the on-screen help, `--help` and the README
//! show). The status lines show the frame time, the ages of the
//! camera frame and joint state, how often the mask was rendered per camera frame and, in the
//! simulated room, the live erasure scores against its ground truth
//! ([`crate::preview::live_scores`]).

pub mod budget;
pub mod glass;
pub mod keys;
pub mod live_scores;
pub mod recorded;
pub mod switch;
#[cfg(feature = "xr")]
pub mod xr;

use std::path::PathBuf;

use avatarm_erase::{
    CaptureBackground, EraseConfig, EraseState, EraseTargets, InteractionTargets, toggle_erasure,
};
use avatarm_sim::SimCameras;
use avatarm_twin::layers;
use avatarm_video::LiveVideo;
use bevy::asset::embedded_asset;
use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::pbr::wireframe::{Wireframe, WireframeColor, WireframePlugin};
use bevy::prelude::*;
use bevy::render::render_resource::AsBindGroup;
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use bevy::shader::ShaderRef;
use bevy::ui_render::UiMaterialPlugin;
use bevy::ui_render::ui_material::{MaterialNode, UiMaterial};

use crate::app::{AppBase, Runner};
use crate::preview::live_scores::LiveDr;
use crate::{AppError, AvatarmSystems, SceneResource};

/// Options of the preview.
#[derive(Debug, Clone, Default)]
pub struct PreviewOptions {
    /// Quit after this many frames.
    pub frames: Option<u32>,
    /// Save a screenshot of the window at the last frame (needs `frames`; default 120).
    pub screenshot: Option<PathBuf>,
    /// Start an OpenXR session (falls back to the window without a runtime).
    pub xr: bool,
    /// Advance simulated time by exactly this much per rendered frame (s) instead of by the
    /// wall clock: scripted runs use half a camera frame, a display twice as fast as the
    /// camera, as a headset's is.
    pub fixed_step_s: Option<f64>,
    /// Where the camera's frames come from (`--webcam`, `--camera-recording`;
    /// [`crate::net::site_camera::open`]).
    pub camera: crate::app::CameraSource,
    /// A recording played as the camera: its robot, the robot (`--camera-recording`).
    pub recorded_arm: Option<avatarm_core::sim::recorded::RecordedArm>,
    /// Run the scene's `[task]` live with this hand ([`crate::teleop`]).
    pub hand: Option<avatarm_scene::hand::HandChoice>,
    /// The robot the live task commands: the simulated arm or the scene's ROS link.
    pub robot: crate::teleop::RobotChoice,
    /// The scene through each of its cameras (its `[[cameras]]`, the file's order) for the
    /// `C` key, which switches between them in place ([`crate::preview::switch`]). Empty: `C` does
    /// not switch (one camera; a recording or a webcam holds one camera).
    pub cameras: Vec<avatarm_scene::Scene>,
    /// Why `C` does not switch when `cameras` is empty and the scene has several (for its
    /// log line).
    pub no_switch: Option<String>,
    /// Keys pressed by script: `(frame, key)`, the key pressed at the start of that rendered
    /// frame (counted from 1) and released at the next (`--press`).
    pub press: Vec<(u32, KeyCode)>,
    /// Each update sleeps this long at its end: a renderer slowed on purpose
    /// (`--slow-update-ms`), to show that the robot's control keeps its rate.
    pub slow_update: Option<std::time::Duration>,
}

/// The preview's cameras, panels and keys.
pub struct PreviewPlugin(pub PreviewOptions);

/// Builds the preview's app for `scene`: the app's base in a window ([`crate::app::build_app`]),
/// then the XR view, the live scores (where the simulated empty room gives their truth), the
/// camera switch (several cameras), [`PreviewPlugin`] and the live teleoperation of the
/// scene's `[task]`. Errors before any window when the hand or the task's grasp cannot be set
/// up, or when no display can open a window.
pub fn build_app(scene: &avatarm_scene::Scene, options: &PreviewOptions) -> Result<App, AppError> {
    // Before any window: a hand or task that cannot be set up is refused at start-up.
    let live = options
        .hand
        .as_ref()
        .map(|choice| {
            let link = match &options.recorded_arm {
                Some(arm) => crate::teleop::TrialLink::Given(Box::new(arm.clone())),
                None => crate::teleop::TrialLink::of(options.robot),
            };
            crate::teleop::LiveSession::prepare(scene, choice, link).map_err(|e| AppError::Teleop {
                source: Box::new(e),
            })
        })
        .transpose()?;
    let base = AppBase {
        camera: options.camera.clone(),
        other_cameras: options.cameras.clone(),
        ..AppBase::new(Runner::Window {
            xr: options.xr,
            fixed_step_s: options.fixed_step_s,
        })
    };
    let mut app = crate::app::build_app(scene, &base)?;
    #[cfg(feature = "xr")]
    if options.xr {
        app.add_plugins(xr::XrViewPlugin);
    }
    if base.camera.is_simulated() && base.empty_room_anywhere(scene) {
        // The room renders its ground truth anyway (the empty room is H); two scored frames a
        // second.
        let every = (scene.file.camera.fps / 2.0).round().max(1.0) as u64;
        app.add_plugins(live_scores::LiveDrPlugin { every });
    }
    if options.cameras.len() > 1 {
        app.add_plugins(switch::CameraSwitchPlugin(switch::CameraViews {
            scenes: options.cameras.clone(),
            current: scene.camera_index,
        }));
    }
    app.add_plugins(PreviewPlugin(options.clone()));
    if options.fixed_step_s.is_none() {
        // On the wall clock only: glass to glass live (`glass`).
        app.add_plugins(glass::PreviewGlassPlugin);
    }
    if let Some(pause) = options.slow_update {
        info!(
            "preview: each update slowed on purpose by {} ms (--slow-update-ms)",
            pause.as_millis()
        );
        app.add_systems(Last, move || std::thread::sleep(pause));
    }
    match (live, &options.recorded_arm) {
        (Some(live), _) => live.install(&mut app)?,
        (None, Some(arm)) => {
            app.add_plugins(recorded::RecordedRobotPlugin(arm.clone()));
        }
        (None, None) => {}
    }
    Ok(app)
}

/// What the preview's panel shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PanelView {
    /// The interaction camera's image: Ĩ(t) with the object twins.
    #[default]
    Interaction,
    /// The live camera frame I(t) as received.
    Feed,
    /// The mask M(t).
    Mask,
}

impl PanelView {
    fn next(self) -> Self {
        match self {
            Self::Interaction => Self::Feed,
            Self::Feed => Self::Mask,
            Self::Mask => Self::Interaction,
        }
    }

    fn title(self) -> &'static str {
        match self {
            Self::Interaction => "Interaction view: robot erased, object twins in front",
            Self::Feed => "Camera feed I(t), as received",
            Self::Mask => "Mask M(t) from the twin",
        }
    }
}

#[derive(Resource)]
struct PreviewState {
    options: PreviewOptions,
    frame: u32,
    shots: u32,
    view: PanelView,
    mask_overlay: bool,
    wireframe: bool,
    /// Updates left before quitting: read-backs already asked for (camera frames, scores,
    /// screenshots) come back first, so none is sent to a closed app.
    quit_in: Option<u32>,
}

impl PreviewState {
    /// At start: no frame yet, the interaction view, no overlay.
    fn new(options: PreviewOptions) -> Self {
        Self {
            options,
            frame: 0,
            shots: 0,
            view: PanelView::default(),
            mask_overlay: false,
            wireframe: false,
            quit_in: None,
        }
    }
}

/// Updates between asking to quit and quitting, with no new read-backs.
const QUIT_DRAIN: u32 = 4;

/// The panel's image with the mask tinted over it (`mask_overlay.wgsl`); a tint of alpha 0
/// shows the image alone. `grey.x = 1` shows a one-channel image (the `R8` mask) in grey.
#[derive(Asset, TypePath, AsBindGroup, Debug, Clone)]
struct PanelMaterial {
    #[uniform(0)]
    tint: Vec4,
    #[uniform(5)]
    grey: Vec4,
    #[texture(1)]
    #[sampler(2)]
    image: Handle<Image>,
    #[texture(3)]
    #[sampler(4)]
    mask: Handle<Image>,
}

impl UiMaterial for PanelMaterial {
    fn fragment_shader() -> ShaderRef {
        "embedded://avatarm/preview/mask_overlay.wgsl".into()
    }
}

/// The mask overlay's colour and opacity.
const MASK_TINT: Vec4 = Vec4::new(1.0, 0.1, 0.6, 0.45);

#[derive(Component)]
struct StatusText;

#[derive(Component)]
struct PanelTitle;

#[derive(Component)]
struct PanelImage;

impl Plugin for PreviewPlugin {
    fn build(&self, app: &mut App) {
        embedded_asset!(app, "mask_overlay.wgsl");
        #[cfg(feature = "xr")]
        app.add_message::<crate::preview::xr::RecenterXrPanel>();
        app.add_plugins((
            UiMaterialPlugin::<PanelMaterial>::default(),
            WireframePlugin::default(),
            budget::FrameBudgetPlugin,
        ))
        .insert_resource(PreviewState::new(self.0.clone()))
        // C asks for a switch; the switch itself is added with several cameras.
        .add_message::<crate::preview::switch::SwitchCamera>()
        .add_systems(Startup, setup_preview)
        .add_systems(
            PreUpdate,
            press_scripted_keys.after(bevy::input::InputSystems),
        )
        .add_systems(
            Update,
            (
                handle_keys,
                show_panel,
                update_status,
                count_frames,
                quit_when_drained,
            )
                .chain()
                .in_set(AvatarmSystems::View),
        );
    }
}

fn setup_preview(
    mut commands: Commands,
    cameras: Res<SimCameras>,
    scene: Res<SceneResource>,
    mut materials: ResMut<Assets<PanelMaterial>>,
    desktop_hand: Option<Res<crate::teleop::DesktopHand>>,
) {
    let base = scene.0.robot_base().translation.vector;
    let focus = Vec3::new(base.x as f32 + 0.45, base.y as f32, base.z as f32 + 0.25);
    // Aimed a little left of the robot so that the twin shows right of the camera feed panel.
    let eye = focus + Vec3::new(1.6, -1.6, 0.9);
    let right = (focus - eye).cross(Vec3::Z).normalize();
    commands.spawn((
        Name::new("preview camera"),
        avatarm_twin::gpu_timing::GpuTimed("preview camera".to_owned()),
        Camera3d::default(),
        Tonemapping::None,
        Transform::from_translation(eye).looking_at(focus - 0.45 * right, Vec3::Z),
        RenderLayers::from_layers(&[layers::ROOM, layers::TWIN]),
    ));
    let panel_w = PANEL_WIDTH_PX;
    let panel_h = panel_height(&scene.0);
    commands
        .spawn((
            Node {
                position_type: PositionType::Absolute,
                left: Val::Px(12.0),
                top: Val::Px(12.0),
                width: Val::Px(panel_w),
                flex_direction: FlexDirection::Column,
                row_gap: Val::Px(6.0),
                ..default()
            },
            BackgroundColor(Color::srgba(0.05, 0.05, 0.07, 0.8)),
        ))
        .with_children(|panel| {
            panel.spawn((
                PanelTitle,
                Text::new(PanelView::default().title()),
                TextFont {
                    font_size: FontSize::Px(18.0),
                    ..default()
                },
                TextColor(Color::WHITE),
            ));
            panel.spawn((
                PanelImage,
                MaterialNode(materials.add(PanelMaterial {
                    tint: Vec4::ZERO,
                    grey: Vec4::ZERO,
                    image: cameras.real.clone(),
                    mask: cameras.real.clone(),
                })),
                Node {
                    width: Val::Px(panel_w),
                    height: Val::Px(panel_h),
                    ..default()
                },
            ));
            panel.spawn((
                StatusText,
                Text::new(""),
                TextFont {
                    font_size: FontSize::Px(13.0),
                    ..default()
                },
                TextColor(Color::srgb(0.85, 0.9, 0.95)),
            ));
        });
    let hand_keys = if desktop_hand.is_some() {
        format!(
            "\ndesktop hand:\n{}",
            keys::lines(&keys::DESKTOP_HAND_KEYS, 3)
        )
    } else {
        String::new()
    };
    commands.spawn((
        Text::new(format!(
            "Robot twin (from joint states)\n{}{hand_keys}",
            keys::lines(&keys::PREVIEW_KEYS, 3)
        )),
        TextFont {
            font_size: FontSize::Px(16.0),
            ..default()
        },
        TextColor(Color::WHITE),
        Node {
            position_type: PositionType::Absolute,
            right: Val::Px(12.0),
            bottom: Val::Px(10.0),
            ..default()
        },
    ));
}

/// The panel's width on screen (px).
const PANEL_WIDTH_PX: f32 = 560.0;

/// The panel's height on screen (px): the camera's aspect at [`PANEL_WIDTH_PX`].
fn panel_height(scene: &avatarm_scene::Scene) -> f32 {
    let k = &scene.true_camera.intrinsics;
    PANEL_WIDTH_PX * k.height as f32 / k.width.max(1) as f32
}

/// After the panel's title: the camera looked through, for a scene with several.
fn camera_title(scene: &avatarm_scene::Scene, switches: bool) -> String {
    if scene.cameras.len() < 2 {
        return String::new();
    }
    format!(
        " - camera '{}' ({} of {}{})",
        scene.camera_name(),
        scene.camera_index + 1,
        scene.cameras.len(),
        if switches { ", C switches" } else { "" }
    )
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn show_panel(
    state: Res<PreviewState>,
    scene: Res<SceneResource>,
    views: Option<Res<crate::preview::switch::CameraViews>>,
    cameras: Res<SimCameras>,
    interaction: Option<Res<InteractionTargets>>,
    erase: Option<Res<EraseTargets>>,
    mut image: Query<(&MaterialNode<PanelMaterial>, &mut Node), With<PanelImage>>,
    mut materials: ResMut<Assets<PanelMaterial>>,
    mut title: Query<&mut Text, With<PanelTitle>>,
) {
    let handle = match state.view {
        PanelView::Interaction => interaction.map(|t| t.view.clone()),
        PanelView::Feed => Some(cameras.real.clone()),
        PanelView::Mask => erase.as_ref().map(|t| t.mask.clone()),
    };
    // Through a lens the feed shown is the room's pinhole render: the mask (the camera's
    // distorted image) does not lie over it.
    let pinhole_feed = state.view == PanelView::Feed && cameras.lens.is_some();
    let tint = if state.mask_overlay && state.view != PanelView::Mask && !pinhole_feed {
        MASK_TINT
    } else {
        Vec4::ZERO
    };
    let grey = if state.view == PanelView::Mask {
        Vec4::X
    } else {
        Vec4::ZERO
    };
    if let (Some(handle), Some(erase)) = (handle, erase) {
        // Another camera (a switch) may have another aspect.
        let height = Val::Px(panel_height(&scene.0));
        for (node, mut layout) in &mut image {
            if layout.height != height {
                layout.height = height;
            }
            let unchanged = materials.get(&node.0).is_some_and(|m| {
                m.image == handle && m.tint == tint && m.mask == erase.mask && m.grey == grey
            });
            if !unchanged && let Some(mut m) = materials.get_mut(&node.0) {
                m.image = handle.clone();
                m.mask = erase.mask.clone();
                m.tint = tint;
                m.grey = grey;
            }
        }
    }
    let wanted = format!(
        "{}{}",
        state.view.title(),
        camera_title(&scene.0, views.is_some())
    );
    for mut text in &mut title {
        if text.0 != wanted {
            text.0.clone_from(&wanted);
        }
    }
}

/// What the status line shows of a live teleoperation.
#[derive(bevy::ecs::system::SystemParam)]
struct LiveTeleopStatus<'w, 's> {
    live: Option<Res<'w, crate::teleop::LiveTask>>,
    teleop: Option<Res<'w, avatarm_mapping::Teleop>>,
    contacts: Option<Res<'w, avatarm_hand::ObjectContacts>>,
    held: Option<Res<'w, avatarm_hand::HeldObject>>,
    anchor: Option<Res<'w, crate::teleop::HandAnchor>>,
    twin: Query<'w, 's, &'static Transform, With<avatarm_hand::GraspTarget>>,
    chess: Option<Res<'w, crate::teleop::ChessState>>,
    game: Option<Res<'w, crate::teleop::LiveGame>>,
}

impl LiveTeleopStatus<'_, '_> {
    /// The end-of-run summary, or nothing without a teleoperation.
    fn summary(&self) -> Option<String> {
        if let (Some(chess), Some(game)) = (&self.chess, &self.game) {
            return Some(chess.summary(&game.0));
        }
        let (Some(live), Some(teleop), Some(held)) = (&self.live, &self.teleop, &self.held) else {
            return None;
        };
        let twin = self.twin.single().ok().map(avatarm_twin::transform_to_iso);
        Some(crate::teleop::summary(
            live,
            teleop,
            held,
            twin,
            self.anchor.as_deref(),
        ))
    }

    /// The teleoperation's line and a line break, or nothing without one.
    fn line(&self) -> String {
        if let (Some(chess), Some(game), Some(held)) = (&self.chess, &self.game, &self.held) {
            return format!("{}\n", chess.status_line(&game.0, held));
        }
        match (&self.live, &self.teleop, &self.contacts, &self.held) {
            (Some(live), Some(teleop), Some(contacts), Some(held)) => {
                let twin = self.twin.single().ok().map(avatarm_twin::transform_to_iso);
                format!(
                    "{}\n",
                    crate::teleop::status_line(
                        live,
                        teleop,
                        contacts,
                        held,
                        twin,
                        self.anchor.as_deref()
                    )
                )
            }
            _ => String::new(),
        }
    }
}

/// The status line's optional sources: the live scores, glass to glass, the drift watch.
type StatusExtras<'w> = (
    Option<Res<'w, LiveDr>>,
    Option<Res<'w, glass::GlassToGlass>>,
    Option<Res<'w, crate::app::drift::LiveDriftWatch>>,
);

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn update_status(
    mut text: Query<&mut Text, With<StatusText>>,
    robot: Option<Res<avatarm_sim::SimRobotState>>,
    twin: Option<Res<crate::AppTwin>>,
    twins: Query<&avatarm_twin::RobotTwin>,
    erase: (
        Res<EraseConfig>,
        Res<EraseState>,
        Res<LiveVideo>,
        Res<avatarm_erase::GpuTimes>,
    ),
    (live_dr, glass, drift): StatusExtras,
    time: Res<Time<Real>>,
    teleop: LiveTeleopStatus,
    scene: Res<crate::app::SceneResource>,
) {
    let (config, erase_state, live, gpu_times) = erase;
    let (Some(robot), Some(twin)) = (robot, twin) else {
        return;
    };
    let Ok(twin) = twins.get(twin.0) else { return };
    let t = robot.0.time_s();
    let age_ms = twin.stamp_s.map_or(f64::NAN, |s| (t - s) * 1e3);
    let frame_age_ms = erase_state
        .frame_capture_s
        .map_or(f64::NAN, |s| (t - s) * 1e3);
    let erasing = match (config.settings.enabled, &erase_state.background_origin) {
        (false, _) => "erase off".to_owned(),
        (true, None) => "erase on, no background yet (B captures one)".to_owned(),
        (true, Some(origin)) => format!("erase on; background: {origin}"),
    };
    let stale = if live.stale { "   CAMERA STALE" } else { "" };
    let per_frame = erase_state.renders as f64 / erase_state.frames_in.max(1) as f64;
    let gpu = gpu_pass_times(&gpu_times).map_or(String::new(), |g| format!("\n{g}"));
    let scores = match live_dr.as_deref().and_then(LiveDr::means) {
        Some((iou, leak, psnr)) => format!(
            "\nlive vs truth (last {} scored): IoU {iou:.3}   leak {leak:.2} %   PSNR {}",
            live_dr.as_ref().map_or(0, |l| l.recent.len()),
            psnr.map_or("-".to_owned(), |p| format!("{p:.1} dB"))
        ),
        None if live_dr.is_some() => "\nlive vs truth: waiting for a scored frame".to_owned(),
        None => String::new(),
    };
    let teleop_line = teleop.line();
    let head = head_line(&scene.0, &erase_state);
    let glass = glass.map_or_else(String::new, |g| g.line());
    let drift = drift.map_or_else(String::new, |d| format!("\n{}", d.line()));
    for mut line in &mut text {
        **line = format!(
            "{teleop_line}sim {t:6.2} s   frame {:5.1} ms   refused joint states {}{stale}\ncamera frame age {frame_age_ms:5.1} ms   joint state age {age_ms:5.1} ms{head}\nmask renders per camera frame {per_frame:.2}{gpu}{glass}{drift}\n{erasing}{scores}",
            time.delta_secs_f64() * 1e3,
            twin.rejected
        );
    }
}

/// A camera on a head: a line (with its leading line break) on the newest frame's mask camera:
/// how much newer than the frame the newest tracked head pose is, the mask camera's error
/// against the simulated head's truth at the frame's capture, and the background's views kept.
/// Empty for a fixed camera, or before the first frame.
fn head_line(scene: &avatarm_scene::Scene, erase: &EraseState) -> String {
    let (Some(head), Some(pose), Some(capture_s)) =
        (&scene.head, erase.camera_pose, erase.frame_capture_s)
    else {
        return String::new();
    };
    let newest = match erase.head_pose_s {
        Some((newest_s, _)) => format!("{:+5.1} ms", (newest_s - capture_s) * 1e3),
        None => "none".to_owned(),
    };
    let (angle, offset) = avatarm_core::vision::head::pose_error(&pose, &head.camera_at(capture_s));
    let views = erase
        .view_background
        .as_ref()
        .map(|vb| format!("  {} views", vb.views.len()))
        .unwrap_or_default();
    format!(
        "\nhead pose {newest} vs frame  mask cam off {:.3} deg {:.1} mm{views}",
        angle.to_degrees(),
        offset * 1e3
    )
}

/// Presses the keys `--press` scripts at their frames and releases them one frame later.
fn press_scripted_keys(state: Res<PreviewState>, mut keys: ResMut<ButtonInput<KeyCode>>) {
    // `frame` counts the updates done; this one is frame + 1.
    let this = state.frame + 1;
    // Releases first: a key pressed again at the next frame is pressed again.
    for &(at, key) in &state.options.press {
        if at + 1 == this {
            keys.release(key);
        }
    }
    for &(at, key) in &state.options.press {
        if at == this {
            keys.press(key);
        }
    }
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn handle_keys(
    keys: Res<ButtonInput<KeyCode>>,
    mut commands: Commands,
    mut state: ResMut<PreviewState>,
    views: Option<Res<crate::preview::switch::CameraViews>>,
    mut switch: MessageWriter<crate::preview::switch::SwitchCamera>,
    mut config: ResMut<EraseConfig>,
    mut capture: MessageWriter<CaptureBackground>,
    #[cfg(feature = "xr")] mut recenter: MessageWriter<crate::preview::xr::RecenterXrPanel>,
    twin_meshes: Query<(Entity, &RenderLayers), With<Mesh3d>>,
) {
    if keys.just_pressed(KeyCode::Escape) {
        state.quit_in.get_or_insert(QUIT_DRAIN);
    }
    if keys.just_pressed(KeyCode::KeyV) {
        state.view = state.view.next();
        info!("panel: {}", state.view.title());
    }
    if keys.just_pressed(KeyCode::KeyC) {
        match (views, &state.options.no_switch) {
            (Some(views), _) => {
                let next = views.next();
                info!(
                    "camera: switching to '{}'",
                    views.scenes[next].camera_name()
                );
                switch.write(crate::preview::switch::SwitchCamera(next));
            }
            (None, Some(why)) => info!("camera: not switched: {why}"),
            (None, None) => {
                info!("camera: the scene has one camera (name several with [[cameras]])");
            }
        }
    }
    if keys.just_pressed(KeyCode::KeyE) {
        let on = toggle_erasure(&mut config);
        info!("robot erasure {}", if on { "on" } else { "off" });
    }
    if keys.just_pressed(KeyCode::KeyB) {
        info!("capturing the background from the live frame");
        capture.write(CaptureBackground);
    }
    if keys.just_pressed(KeyCode::KeyM) {
        state.mask_overlay = !state.mask_overlay;
        info!(
            "mask overlay {}",
            if state.mask_overlay { "on" } else { "off" }
        );
    }
    if keys.just_pressed(KeyCode::KeyW) {
        state.wireframe = !state.wireframe;
        info!(
            "twin wireframe {}",
            if state.wireframe { "on" } else { "off" }
        );
        let twin_layer = RenderLayers::layer(layers::TWIN);
        for (e, layers) in &twin_meshes {
            if *layers != twin_layer {
                continue;
            }
            if state.wireframe {
                commands.entity(e).insert((
                    Wireframe,
                    WireframeColor {
                        color: Color::srgb(0.2, 1.0, 0.4),
                    },
                ));
            } else {
                commands.entity(e).remove::<(Wireframe, WireframeColor)>();
            }
        }
    }
    if keys.just_pressed(KeyCode::KeyR) {
        #[cfg(feature = "xr")]
        recenter.write_default();
        #[cfg(not(feature = "xr"))]
        info!("R: this build has no XR mode");
    }
    if keys.just_pressed(KeyCode::F12) {
        state.shots += 1;
        let path = format!("avatarm_screenshot_{:03}.png", state.shots);
        info!("screenshot: {path}");
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(path));
    }
}

/// The erase's recent GPU times (median of the last 30 renders of the mask twin and of each
/// pass that runs) for the status line and the run's summary; nothing before the first times
/// arrive.
fn gpu_pass_times(gpu: &avatarm_erase::GpuTimes) -> Option<String> {
    let times: Vec<(&str, f64)> = avatarm_erase::PASS_NAMES
        .iter()
        .filter_map(|&name| gpu.recent_median(name, 30).map(|ms| (name, ms)))
        .collect();
    match (times.first(), gpu.unavailable()) {
        (Some(_), _) => {
            let total: f64 = times.iter().map(|(_, ms)| ms).sum();
            let parts: Vec<String> = times
                .iter()
                .map(|(name, ms)| format!("{name} {ms:.2}"))
                .collect();
            Some(format!("GPU ms: erase {total:.2} ({})", parts.join(" + ")))
        }
        (None, Some(_)) => Some("GPU ms: no timestamp queries on this device".to_owned()),
        (None, None) => None,
    }
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn count_frames(
    mut commands: Commands,
    mut state: ResMut<PreviewState>,
    erase: Res<EraseState>,
    gpu_times: Res<avatarm_erase::GpuTimes>,
    budget: Res<budget::FrameBudget>,
    readbacks: Option<Res<avatarm_twin::readback::ReadbackStats>>,
    live_dr: Option<Res<LiveDr>>,
    teleop: LiveTeleopStatus,
) {
    state.frame += 1;
    let last = match (state.options.frames, &state.options.screenshot) {
        (Some(n), _) => n,
        (None, Some(_)) => 120,
        (None, None) => return,
    };
    if state.frame == last
        && let Some(path) = state.options.screenshot.clone()
    {
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(path));
    }
    // Leave a few frames for the screenshot to be read back and written.
    let grace = if state.options.screenshot.is_some() {
        10
    } else {
        0
    };
    if state.frame == last + grace {
        // One line for scripted runs (and the tests that run them).
        let scores = live_dr
            .as_deref()
            .and_then(|l| l.means().map(|m| (l.scored, l.incomplete, m)))
            .map_or(String::new(), |(n, incomplete, (iou, leak, psnr))| {
                let unscored = if incomplete > 0 {
                    format!(
                        " ({incomplete} sampled frames not scored: their truth's render had not completed)"
                    )
                } else {
                    String::new()
                };
                format!(
                    "; {n} frames scored live, last IoU {iou:.3}, leak {leak:.2} %, PSNR {} dB{unscored}",
                    psnr.map_or("-".to_owned(), |p| format!("{p:.1}"))
                )
            });
        let gpu = gpu_pass_times(&gpu_times).map_or(String::new(), |g| format!("; {g}"));
        info!(
            "preview: {} frames rendered, {} camera frames, mask rendered {} times, composite {} times{scores}{gpu}",
            state.frame, erase.frames_in, erase.renders, erase.renders
        );
        // "preview frame budget ...", after the line the tests read.
        info!(
            "preview {}",
            budget.summary(&gpu_times, readbacks.as_deref())
        );
        if let Some(line) = teleop.summary() {
            info!("{line}");
        }
        state.quit_in.get_or_insert(QUIT_DRAIN);
    }
}

/// Quits [`QUIT_DRAIN`] updates after being asked to, asking for no new read-backs meanwhile.
fn quit_when_drained(
    mut state: ResMut<PreviewState>,
    room: Option<ResMut<avatarm_sim::SimRoomConfig>>,
    live_dr: Option<ResMut<LiveDr>>,
    mut exit: MessageWriter<AppExit>,
) {
    let Some(left) = state.quit_in else { return };
    if left == QUIT_DRAIN {
        if let Some(mut room) = room {
            room.video = None;
        }
        if let Some(mut live) = live_dr {
            live.stop();
        }
    }
    if left == 0 {
        exit.write(AppExit::Success);
    } else {
        state.quit_in = Some(left - 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--press` presses a key at the start of its frame and releases it at the next; a key
    /// pressed at two frames in a row is pressed twice, whatever the order given.
    #[test]
    fn scripted_keys_are_pressed_for_one_frame() {
        let mut app = App::new();
        app.insert_resource(ButtonInput::<KeyCode>::default())
            .insert_resource(PreviewState::new(PreviewOptions {
                // C at frames 2 and 3: pressed again, not held.
                press: vec![(3, KeyCode::KeyV), (2, KeyCode::KeyC), (3, KeyCode::KeyC)],
                ..default()
            }))
            .add_systems(Update, press_scripted_keys);
        let mut pressed = Vec::new();
        for frame in 0..4 {
            app.world_mut().resource_mut::<PreviewState>().frame = frame;
            app.update();
            let mut keys = app.world_mut().resource_mut::<ButtonInput<KeyCode>>();
            let mut now: Vec<KeyCode> = keys.get_just_pressed().copied().collect();
            now.sort();
            pressed.push((now, keys.get_pressed().count()));
            keys.clear();
        }
        assert_eq!(
            pressed,
            vec![
                (vec![], 0),
                (vec![KeyCode::KeyC], 1),
                (vec![KeyCode::KeyC, KeyCode::KeyV], 2),
                (vec![], 0),
            ]
        );
    }
}
