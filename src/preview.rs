//! The desktop preview: what the remote user sees (the interaction view Ĩ(t) with the robot
//! erased and the object twins in front), or the raw camera feed, or the mask, beside a 3-D
//! view of the robot twin.
//!
//! Keys: V cycles the panel (interaction view, camera feed, mask), E switches erasure on and
//! off, B captures the background H from the live frame, F12 saves a screenshot, Esc quits.

use std::path::PathBuf;

use avatarm_erase::{
    CaptureBackground, EraseConfig, EraseState, EraseTargets, InteractionTargets, toggle_erasure,
};
use avatarm_sim::SimCameras;
use avatarm_twin::layers;
use avatarm_video::LiveVideo;
use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, save_to_disk};

use crate::SceneResource;

/// Options of the preview.
#[derive(Debug, Clone, Default)]
pub struct PreviewOptions {
    /// Quit after this many frames.
    pub frames: Option<u32>,
    /// Save a screenshot of the window at the last frame (needs `frames`; default 120).
    pub screenshot: Option<PathBuf>,
    /// Start an OpenXR session (falls back to the window without a runtime).
    pub xr: bool,
    /// Advance time by exactly one camera frame per rendered frame (scripted runs).
    pub fixed_timestep: bool,
    /// Take the camera feed from this webcam instead of the simulated room's camera (needs
    /// the `webcam` feature).
    pub webcam: Option<u32>,
}

/// The preview's cameras, panels and keys.
pub struct PreviewPlugin(pub PreviewOptions);

/// The keys, as listed in `--help` and the README.
pub const KEYS: &str = "V: panel (view / feed / mask)   E: erase on/off   B: capture background   F12: screenshot   Esc: quit";

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
}

#[derive(Component)]
struct StatusText;

#[derive(Component)]
struct PanelTitle;

#[derive(Component)]
struct PanelImage;

impl Plugin for PreviewPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(PreviewState {
            options: self.0.clone(),
            frame: 0,
            shots: 0,
            view: PanelView::default(),
        })
        .add_systems(Startup, setup_preview)
        .add_systems(
            Update,
            (handle_keys, show_panel, update_status, count_frames).chain(),
        );
    }
}

fn setup_preview(mut commands: Commands, cameras: Res<SimCameras>, scene: Res<SceneResource>) {
    let base = scene.0.robot_base().translation.vector;
    let focus = Vec3::new(base.x as f32 + 0.45, base.y as f32, base.z as f32 + 0.25);
    // Aimed a little left of the robot so that the twin shows right of the camera feed panel.
    let eye = focus + Vec3::new(1.6, -1.6, 0.9);
    let right = (focus - eye).cross(Vec3::Z).normalize();
    commands.spawn((
        Name::new("preview camera"),
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
                ImageNode::new(cameras.real.clone()),
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
                    font_size: FontSize::Px(15.0),
                    ..default()
                },
                TextColor(Color::srgb(0.85, 0.9, 0.95)),
            ));
        });
    commands.spawn((
        Text::new(format!("Robot twin (from joint states)\n{KEYS}")),
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
    mut image: Query<&mut ImageNode, With<PanelImage>>,
    mut title: Query<&mut Text, With<PanelTitle>>,
) {
    let handle = match state.view {
        PanelView::Interaction => interaction.map(|t| t.view.clone()),
        PanelView::Feed => Some(cameras.real.clone()),
        PanelView::Mask => erase.map(|t| t.mask.clone()),
    };
    if let Some(handle) = handle {
        for mut node in &mut image {
            if node.image != handle {
                node.image = handle.clone();
            }
        }
    }
    for mut text in &mut title {
        if text.0 != state.view.title() {
            text.0 = state.view.title().to_owned();
        }
    }
}

fn update_status(
    mut text: Query<&mut Text, With<StatusText>>,
    robot: Option<Res<avatarm_sim::SimRobotState>>,
    twin: Option<Res<crate::AppTwin>>,
    twins: Query<&avatarm_twin::RobotTwin>,
    erase: (Res<EraseConfig>, Res<EraseState>, Res<LiveVideo>),
    time: Res<Time>,
) {
    let (config, erase_state, live) = erase;
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
    for mut line in &mut text {
        **line = format!(
            "sim {t:6.2} s   frame {:5.1} ms   refused joint states {}{stale}\ncamera frame age {frame_age_ms:5.1} ms   joint state age {age_ms:5.1} ms\n{erasing}",
            time.delta_secs_f64() * 1e3,
            twin.rejected
        );
    }
}

fn handle_keys(
    keys: Res<ButtonInput<KeyCode>>,
    mut commands: Commands,
    mut state: ResMut<PreviewState>,
    mut config: ResMut<EraseConfig>,
    mut capture: MessageWriter<CaptureBackground>,
    mut exit: MessageWriter<AppExit>,
) {
    if keys.just_pressed(KeyCode::Escape) {
        exit.write(AppExit::Success);
    }
    if keys.just_pressed(KeyCode::KeyV) {
        state.view = state.view.next();
        info!("panel: {}", state.view.title());
    }
    if keys.just_pressed(KeyCode::KeyE) {
        let on = toggle_erasure(&mut config);
        info!("robot erasure {}", if on { "on" } else { "off" });
    }
    if keys.just_pressed(KeyCode::KeyB) {
        info!("capturing the background from the live frame");
        capture.write(CaptureBackground);
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

fn count_frames(
    mut commands: Commands,
    mut state: ResMut<PreviewState>,
    mut exit: MessageWriter<AppExit>,
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
    if state.frame >= last + grace {
        exit.write(AppExit::Success);
    }
}
