//! The desktop preview: what the remote user sees (the interaction view Ĩ(t) with the robot
//! erased and the object twins in front), or the raw camera feed, or the mask, beside a 3-D
//! view of the robot twin.
//!
//! Keys: [`keys::PREVIEW_KEYS`] (the one list the on-screen help, `--help` and the README
//! show). The status lines show the frame time, the ages of the
//! camera frame and joint state, how often the mask was rendered per camera frame and, in the
//! simulated room, the live erasure scores against its ground truth ([`crate::preview::live_scores`]).

pub mod budget;
pub mod keys;
pub mod live_scores;
#[cfg(feature = "xr")]
pub mod xr;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

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
    /// Take the camera feed from this webcam instead of the simulated room's camera (needs
    /// the `webcam` feature).
    pub webcam: Option<u32>,
    /// Run the scene's `[task]` live with this hand ([`crate::teleop`]).
    pub hand: Option<avatarm_scene::hand::HandChoice>,
    /// The robot the live task commands: the simulated arm or the scene's ROS link.
    pub robot: crate::teleop::RobotChoice,
    /// Where the `C` key leaves the name of the scene's camera to look through next (a scene
    /// with several `[[cameras]]`): the preview then quits, and the caller starts it again
    /// through that camera ([`crate::preview::restart_with_view`]). `None`: the camera cannot
    /// be switched (a recording holds one camera).
    pub next_view: Option<Arc<Mutex<Option<String>>>>,
}

/// The preview's cameras, panels and keys.
pub struct PreviewPlugin(pub PreviewOptions);

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
    /// The scene's camera the `C` key switches to ([`next_camera`]).
    next_camera: Option<String>,
    /// After the panel's title: the camera looked through, for a scene with several.
    camera_title: String,
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
        .insert_resource(PreviewState {
            options: self.0.clone(),
            frame: 0,
            shots: 0,
            view: PanelView::default(),
            mask_overlay: false,
            wireframe: false,
            quit_in: None,
            next_camera: None,
            camera_title: String::new(),
        })
        .add_systems(Startup, setup_preview)
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
    mut state: ResMut<PreviewState>,
) {
    let s = &scene.0;
    state.next_camera = next_camera(s).map(str::to_owned);
    if s.cameras.len() > 1 {
        state.camera_title = format!(
            " - camera '{}' ({} of {}, C switches)",
            s.camera_name(),
            s.camera_index + 1,
            s.cameras.len()
        );
    }
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
    let k = &scene.0.true_camera.intrinsics;
    let panel_w = 560.0;
    let panel_h = panel_w * k.height as f32 / k.width as f32;
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

fn show_panel(
    state: Res<PreviewState>,
    cameras: Res<SimCameras>,
    interaction: Option<Res<InteractionTargets>>,
    erase: Option<Res<EraseTargets>>,
    image: Query<&MaterialNode<PanelMaterial>, With<PanelImage>>,
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
        for node in &image {
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
    let wanted = format!("{}{}", state.view.title(), state.camera_title);
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
    twin: Query<'w, 's, &'static Transform, With<avatarm_hand::GraspTarget>>,
}

impl LiveTeleopStatus<'_, '_> {
    /// The end-of-run summary, or nothing without a teleoperation.
    fn summary(&self) -> Option<String> {
        let (Some(live), Some(teleop), Some(held)) = (&self.live, &self.teleop, &self.held) else {
            return None;
        };
        let twin = self.twin.single().ok().map(avatarm_twin::transform_to_iso);
        Some(crate::teleop::summary(live, teleop, held, twin))
    }

    /// The teleoperation's line and a line break, or nothing without one.
    fn line(&self) -> String {
        match (&self.live, &self.teleop, &self.contacts, &self.held) {
            (Some(live), Some(teleop), Some(contacts), Some(held)) => {
                let twin = self.twin.single().ok().map(avatarm_twin::transform_to_iso);
                format!(
                    "{}\n",
                    crate::teleop::status_line(live, teleop, contacts, held, twin)
                )
            }
            _ => String::new(),
        }
    }
}

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
    live_dr: Option<Res<LiveDr>>,
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
    for mut line in &mut text {
        **line = format!(
            "{teleop_line}sim {t:6.2} s   frame {:5.1} ms   refused joint states {}{stale}\ncamera frame age {frame_age_ms:5.1} ms   joint state age {age_ms:5.1} ms{head}\nmask renders per camera frame {per_frame:.2}{gpu}\n{erasing}{scores}",
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

fn handle_keys(
    keys: Res<ButtonInput<KeyCode>>,
    mut commands: Commands,
    mut state: ResMut<PreviewState>,
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
        if let Some(next) = state.next_camera.clone() {
            match &state.options.next_view {
                Some(slot) => {
                    info!("camera: switching to '{next}' (the preview starts again through it)");
                    if let Ok(mut slot) = slot.lock() {
                        *slot = Some(next);
                    }
                    state.quit_in.get_or_insert(QUIT_DRAIN);
                }
                None => info!(
                    "camera: not switched while recording (a recording holds one camera); start again with --view {next}"
                ),
            }
        } else {
            info!("camera: the scene has one camera (name several with [[cameras]])");
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
            .and_then(|l| l.means().map(|m| (l.scored, m)))
            .map_or(String::new(), |(n, (iou, leak, _))| {
                format!("; {n} frames scored live, last IoU {iou:.3}, leak {leak:.2} %")
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

/// The camera the `C` key switches to: the scene's next one (after the last, the first);
/// `None` for a scene with one camera.
pub fn next_camera(scene: &avatarm_scene::Scene) -> Option<&str> {
    let n = scene.cameras.len();
    (n > 1).then(|| scene.cameras[(scene.camera_index + 1) % n].as_str())
}

/// The command line that starts this preview again through the scene's camera `view`: this
/// process's arguments with `--view` set to it.
pub fn args_with_view(args: &[std::ffi::OsString], view: &str) -> Vec<std::ffi::OsString> {
    let mut out = Vec::with_capacity(args.len() + 2);
    let mut rest = args.iter();
    while let Some(arg) = rest.next() {
        if arg == "--view" {
            rest.next();
        } else if !arg.to_string_lossy().starts_with("--view=") {
            out.push(arg.clone());
        }
    }
    out.push("--view".into());
    out.push(view.into());
    out
}

/// Starts this program again in place of this process (Unix `exec`), looking through the
/// scene's camera `view`: the window closes and a new one opens, the scene from its start
/// (one process's windowing event loop cannot be made twice). Returns only on failure.
pub fn restart_with_view(view: &str) -> AppError {
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    let args = args_with_view(&args, view);
    let exe = match std::env::current_exe() {
        Ok(exe) => exe,
        Err(e) => {
            return AppError::flag(
                "C (switch camera)",
                format!("cannot find this program: {e}"),
            );
        }
    };
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        let e = std::process::Command::new(&exe).args(&args[1..]).exec();
        AppError::flag(
            "C (switch camera)",
            format!("cannot start {} again: {e}", exe.display()),
        )
    }
    #[cfg(not(unix))]
    {
        AppError::flag(
            "C (switch camera)",
            format!("start it again with --view {view}: {}", exe.display()),
        )
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

    /// C goes through the scene's cameras in turn; a scene with one camera has none to go to.
    #[test]
    fn c_goes_through_the_scenes_cameras() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes");
        let view = |file: &str, v: Option<&str>| {
            avatarm_scene::Scene::load_view(&root.join(file), &Default::default(), v)
                .expect("scene")
        };
        let two = "pouring_two_views.toml";
        assert_eq!(next_camera(&view(two, None)), Some("alice"));
        assert_eq!(next_camera(&view(two, Some("alice"))), Some("blair"));
        assert_eq!(next_camera(&view("pouring.toml", None)), None);
    }

    /// Switching camera starts the same command again with `--view` set, in either spelling,
    /// and the other arguments as they were.
    #[test]
    fn the_restart_keeps_the_arguments_and_sets_the_view() {
        let args = |a: &[&str]| a.iter().map(std::ffi::OsString::from).collect::<Vec<_>>();
        assert_eq!(
            args_with_view(
                &args(&["avatarm", "run", "s.toml", "--frames", "9"]),
                "alice"
            ),
            args(&[
                "avatarm", "run", "s.toml", "--frames", "9", "--view", "alice"
            ])
        );
        assert_eq!(
            args_with_view(
                &args(&["avatarm", "run", "--view", "alice", "s.toml"]),
                "blair"
            ),
            args(&["avatarm", "run", "s.toml", "--view", "blair"])
        );
        assert_eq!(
            args_with_view(
                &args(&["avatarm", "run", "--view=alice", "s.toml"]),
                "blair"
            ),
            args(&["avatarm", "run", "s.toml", "--view", "blair"])
        );
    }
}
