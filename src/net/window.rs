//! The operator's (or an observer's) window in `avatarm join --window`: the robot site's
//! erased video, as received and decoded, on the interaction layer's panel, with the hand and
//! the object's twin in front of it (the paper's interaction layer, Blair's view), and a status
//! line. With `--xr` the same view goes to the headset's panel (`crate::preview::xr`).
//!
//! The window runs on the main thread; the session (the network, the hand's physics twin and
//! the operator's side of the mapping, [`super::join`]) runs beside it at the control rate
//! and hands the window what to draw through [`ViewShared`]: the newest decoded frame, the hand
//! and the twin in the real world, and a line of figures. The window never waits on the
//! network, and a slow window never slows the control loop. The desktop hand's keys move the
//! hand from the window ([`crate::preview::keys::DESKTOP_HAND_KEYS`]).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use avatarm_erase::interaction::ObjectTwin;
use avatarm_erase::{EraseTargets, InteractionConfig, InteractionPlugin, InteractionTargets};
use avatarm_scene::Scene;
use avatarm_twin::camera::rgba8_image;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureFormat, TextureUsages};
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use crate::preview::glass::{GlassToGlass, GlassToGlassPlugin, Taken, TakenFrame};
use crate::teleop::{DesktopControls, DesktopHand, HandInteractionGizmos, HandViewGizmos};
use crate::{AppError, SceneResource};
use avatarm_core::stats::Spread;

/// The window's options (`avatarm join --window`).
#[derive(Debug, Clone, Default)]
pub struct WindowOptions {
    /// Through OpenXR: the view on the headset's panel (falls back to the window alone).
    pub xr: bool,
    /// Close after this many rendered frames (scripted runs and tests).
    pub frames: Option<u32>,
    /// Save a screenshot of the window at frame `frames` (120 without it), then close.
    pub screenshot: Option<PathBuf>,
}

/// What the window did (in the join report).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct WindowReport {
    /// Frames rendered.
    pub frames: u64,
    /// Decoded video frames put on the panel.
    pub video_frames: u64,
    /// Rendered frames in which the hand was drawn.
    pub hand_frames: u64,
    /// A camera on a head (Alice's view), watching: rendered frames in which the operator's
    /// hand was drawn carried with the real object she holds.
    pub anchored_hand_frames: u64,
    /// In those frames, how far the hand was moved (mm): the distance between the operator's
    /// twin of the object and the real object as the frame on the panel shows it (the video's
    /// age and the arm's lag behind the twin).
    pub anchor_correction_mm: Spread,
    /// Rendered frames per second.
    pub fps: f64,
    /// Each rendered frame's time (ms, the window's clock).
    pub frame_ms: Spread,
    /// Decoded → taken onto the panel by the window's update (ms).
    pub panel_wait_ms: Spread,
    /// Decoded → presented (ms): the window's frame that first shows it handed to the display
    /// (the render world's present, after [`bevy::render::RenderSystems::Render`]). The
    /// display's own scan-out and response come after and are not measured. In XR, a frame the
    /// headset was given ends at its predicted display instead (as
    /// [`WindowReport::glass_to_glass_ms`]).
    pub display_ms: Spread,
    /// Capture → presented (ms): glass to glass but the display's scan-out (the frame's
    /// capture → decoded, on the robot site's clock as the session estimates it, plus
    /// [`WindowReport::display_ms`]). In XR, a frame the headset was given ends at its
    /// predicted display instead (`preview::glass`), so this mixes both ends where a session
    /// ran for part of the time; [`WindowReport::headset_glass_to_glass_ms`] has those alone.
    pub glass_to_glass_ms: Spread,
    /// Capture → on the headset's display (ms) of the frames stamped there (`--xr` with a
    /// session running and the runtime's clock conversion granted; `n = 0` otherwise): the
    /// frame's capture → decoded plus decoded → the runtime's predicted display time for the
    /// XR frame that first shows it (OpenXR 1.0, `XrFrameState::predictedDisplayTime`).
    #[serde(default)]
    pub headset_glass_to_glass_ms: Spread,
    /// The view was asked for in XR (`--xr`); whether a headset took it is in the log.
    pub xr: bool,
}

impl WindowReport {
    /// The operator's summary's words on glass to glass (empty before a frame was presented):
    /// capture → presented in the window, or in XR the frames the headset showed alone
    /// (capture → its predicted display), naming the others that ended at the window.
    pub fn glass_to_glass_words(&self) -> String {
        let (all, headset) = (&self.glass_to_glass_ms, &self.headset_glass_to_glass_ms);
        if all.n == 0 {
            return String::new();
        }
        if headset.n == 0 {
            return format!(
                ", capture to presented in the window {:.0} ms median (p95 {:.0})",
                all.median, all.p95
            );
        }
        let others = if all.n > headset.n {
            format!(" (the other {} at the window's present)", all.n - headset.n)
        } else {
            String::new()
        };
        format!(
            ", capture to the headset's predicted display {:.0} ms median (p95 {:.0}) over {} of {} frames{others}",
            headset.median, headset.p95, headset.n, all.n
        )
    }
}

/// A decoded frame: RGBA8, `width * height * 4` bytes, numbered as it arrived.
#[derive(Debug, Clone)]
pub struct ViewFrame {
    /// Counts frames put here (the window uploads each once).
    pub number: u64,
    /// When it was put here (decoded).
    pub decoded_at: Instant,
    /// Its capture → decoded (ms; the robot site's clock as the session estimates it).
    pub capture_to_decoded_ms: f64,
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// The pixels.
    pub rgba: Vec<u8>,
    /// The real object (its centre) as the frame shows it, where the robot site reports it.
    pub real_object: Option<Isometry3<f64>>,
    /// The camera the robot site drew the frame's mask from (`world_from_camera`): where the
    /// hand and the twins are placed in front of it (a camera on a head moves).
    pub world_from_camera: Isometry3<f64>,
}

/// What the session hands the window, newest only.
#[derive(Debug, Clone, Default)]
pub struct ViewState {
    /// The newest decoded frame of the first camera the session received.
    pub frame: Option<ViewFrame>,
    /// The hand's 26 joints in the real world (robot frame, m): the operator's own hand mapped
    /// through the virtual-to-real transform, or the operator's hand as an observer receives
    /// it. `None` while untracked.
    pub hand: Option<Vec<Vector3<f64>>>,
    /// When `hand` came: a hand older than [`HAND_SHOWN_S`] is not drawn (the operator left,
    /// or her hand frames stopped).
    pub hand_at: Option<Instant>,
    /// The hand holds the object.
    pub holding: bool,
    /// The object's twin in the real world (its base pose, robot frame), for the operator;
    /// `None` for an observer (which has no twin: it sees the real object in the video).
    pub object: Option<Isometry3<f64>>,
    /// An observer: while the operator's hand holds the object, her twin of it in the real
    /// world (its centre), as her hand frame came with it.
    pub held_object: Option<Isometry3<f64>>,

    /// A line of figures for the status text.
    pub line: String,
}

/// Shared between the session's thread and the window.
#[derive(Debug)]
pub struct ViewShared {
    /// The newest of everything.
    pub state: Mutex<ViewState>,
    /// The window closed (or reached its frames): the session ends.
    pub closed: AtomicBool,
    /// The session ended (its duration passed, or an error): the window closes.
    pub ended: AtomicBool,
    /// The desktop hand's Home was pressed: the session puts the twin back at its start
    /// unless the hand holds it.
    pub reset_twin: AtomicBool,
    /// Frames put in [`ViewState::frame`].
    frames_in: AtomicU64,
}

impl ViewShared {
    /// Empty.
    pub fn new() -> Self {
        Self {
            state: Mutex::new(ViewState::default()),
            closed: AtomicBool::new(false),
            ended: AtomicBool::new(false),
            reset_twin: AtomicBool::new(false),
            frames_in: AtomicU64::new(0),
        }
    }

    /// Puts a decoded frame up for the window (replacing one it has not drawn yet), seen from
    /// `world_from_camera`, decoded `capture_to_decoded_ms` after its capture.
    pub fn put_frame(
        &self,
        width: u32,
        height: u32,
        rgba: Vec<u8>,
        world_from_camera: Isometry3<f64>,
        real_object: Option<Isometry3<f64>>,
        capture_to_decoded_ms: f64,
    ) {
        let number = self.frames_in.fetch_add(1, Ordering::Relaxed) + 1;
        if let Ok(mut s) = self.state.lock() {
            s.frame = Some(ViewFrame {
                number,
                decoded_at: Instant::now(),
                capture_to_decoded_ms,
                width,
                height,
                rgba,
                world_from_camera,
                real_object,
            });
        }
    }

    /// Changes the state under its lock (a poisoned lock is taken as it is: the state is only
    /// ever replaced whole, never left half-written).
    pub fn update(&self, f: impl FnOnce(&mut ViewState)) {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut s);
    }
}

impl Default for ViewShared {
    fn default() -> Self {
        Self::new()
    }
}

/// The window's link to the session.
#[derive(Resource, Clone)]
struct Session(Arc<ViewShared>);

/// The window's state.
#[derive(Resource)]
struct WindowState {
    options: WindowOptions,
    observer: bool,
    /// Watching through a camera on a head (Alice's view): the held hand is drawn carried
    /// with the real object.
    anchor: bool,
    /// The real object as the frame on the panel shows it.
    panel_object: Option<Isometry3<f64>>,
    /// The carried object's index among the object twins.
    object: Option<usize>,
    video: Handle<Image>,
    shown: u64,
    report: WindowReport,
    /// The first frame's time (the rate counts from it, not from the renderer's start-up).
    first_frame: Option<Instant>,
    quit_in: Option<u32>,
}

/// What the window measured, read when it has closed.
#[derive(Default)]
struct WindowRecord {
    report: WindowReport,
    frame_ms: Vec<f64>,
    panel_wait_ms: Vec<f64>,
    correction_mm: Vec<f64>,
}

/// The window's record and its frames' display stage (stamped at the present,
/// [`GlassToGlassPlugin`]), shared with the [`WindowHandle`].
#[derive(Resource, Clone)]
struct WindowOutcome(Arc<Mutex<WindowRecord>>, GlassToGlass);

#[derive(Component)]
struct StatusText;

/// How long a hand is drawn after its last frame (s).
pub const HAND_SHOWN_S: f64 = 1.0;

/// Updates between asking to quit and quitting (the screenshot's read-back lands first).
const QUIT_DRAIN: u32 = 10;

/// The window app for `scene` showing what `shared` holds; `desktop`: the desktop hand, driven
/// by the window's keys and mouse. Errors without a display.
pub fn build(
    scene: &Scene,
    options: &WindowOptions,
    shared: Arc<ViewShared>,
    observer: bool,
    desktop: Option<DesktopHand>,
) -> Result<(App, WindowHandle), AppError> {
    crate::app::check_display()?;
    let role = if observer { "observer" } else { "operator" };
    let window = Window {
        title: format!("Avatarm — {role}: {}", scene.file.name),
        resolution: (1280u32, 720u32).into(),
        ..default()
    };
    // The session logs before the app exists: its log set-up stays.
    let plugins = DefaultPlugins
        .set(WindowPlugin {
            primary_window: Some(window),
            ..default()
        })
        .disable::<bevy::log::LogPlugin>();
    let mut app = App::new();
    crate::app::add_window_plugins(&mut app, plugins, options.xr);
    app.add_plugins(GlassToGlassPlugin);
    let outcome = WindowOutcome(
        Arc::default(),
        app.world().resource::<GlassToGlass>().clone(),
    );
    let k = &scene.believed_camera.intrinsics;
    let video = app
        .world_mut()
        .resource_mut::<Assets<Image>>()
        .add(rgba8_image(
            k.width,
            k.height,
            TextureFormat::Rgba8UnormSrgb,
            TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_DST,
        ));
    app.insert_resource(SceneResource(scene.clone()))
        .insert_resource(crate::app::interaction_config(scene))
        // The interaction layer's panel shows the erased frame: here, the one received.
        .insert_resource(EraseTargets {
            raw: video.clone(),
            mask: video.clone(),
            composite: video.clone(),
        })
        .insert_resource(Session(shared))
        .insert_resource(outcome.clone())
        .insert_resource(WindowState {
            options: options.clone(),
            observer,
            anchor: observer && scene.head.is_some(),
            panel_object: None,
            object: crate::teleop::carried_object(scene).and_then(|(i, _)| i),
            video,
            shown: 0,
            report: WindowReport {
                xr: options.xr,
                ..default()
            },
            first_frame: None,
            quit_in: None,
        })
        .add_plugins(InteractionPlugin)
        .init_gizmo_group::<HandViewGizmos>()
        .init_gizmo_group::<HandInteractionGizmos>()
        .add_systems(Startup, crate::teleop::configure_gizmos)
        .add_systems(
            Update,
            (
                show_view.run_if(resource_added::<InteractionTargets>),
                show_session.before(avatarm_erase::EraseSystems::Interaction),
                count_frames,
            )
                .chain(),
        );
    #[cfg(feature = "xr")]
    if options.xr {
        app.add_plugins(crate::preview::xr::XrViewPlugin);
    }
    if let Some(desktop) = desktop {
        app.insert_resource(desktop)
            .add_systems(Update, drive_desktop_hand.before(show_session));
    }
    // After the desktop hand is in: the keys' help shows with it.
    app.add_systems(Startup, spawn_ui);
    Ok((app, WindowHandle(outcome)))
}

/// Gives the window's report once its app has run.
pub struct WindowHandle(WindowOutcome);

impl WindowHandle {
    /// The report the window left when it closed (`None` if it never rendered a frame).
    pub fn report(&self) -> Option<WindowReport> {
        let record = self.0.0.lock().unwrap_or_else(|e| e.into_inner());
        (record.report.frames > 0).then(|| WindowReport {
            frame_ms: Spread::of(&record.frame_ms),
            panel_wait_ms: Spread::of(&record.panel_wait_ms),
            display_ms: self.0.1.display_spread(),
            glass_to_glass_ms: self.0.1.spread(),
            headset_glass_to_glass_ms: self.0.1.headset_spread(),
            anchor_correction_mm: Spread::of(&record.correction_mm),
            ..record.report.clone()
        })
    }
}

fn spawn_ui(mut commands: Commands, state: Res<WindowState>, desktop: Option<Res<DesktopHand>>) {
    commands.spawn((Name::new("operator window camera"), Camera2d));
    let about = if state.observer {
        "Observer: the robot site's video\n(robot erased) with the operator's\nhand as received"
    } else {
        "Operator: the robot site's video\n(robot erased) with your hand and\nthe object's twin in front"
    };
    let about = format!("{about}\n\nEscape or closing the window\nends the session");
    let keys = if desktop.is_some() {
        format!(
            "\n\ndesktop hand:\n{}",
            crate::preview::keys::lines(&crate::preview::keys::DESKTOP_HAND_KEYS, 1)
        )
    } else {
        String::new()
    };
    commands.spawn((
        Text::new(format!("{about}{keys}")),
        TextFont {
            font_size: FontSize::Px(16.0),
            ..default()
        },
        TextColor(Color::WHITE),
        Node {
            position_type: PositionType::Absolute,
            right: Val::Px(12.0),
            top: Val::Px(12.0),
            ..default()
        },
    ));
    commands.spawn((
        StatusText,
        Text::new("waiting for the robot site's video"),
        TextFont {
            font_size: FontSize::Px(15.0),
            ..default()
        },
        TextColor(Color::srgb(0.85, 0.9, 0.95)),
        Node {
            position_type: PositionType::Absolute,
            left: Val::Px(12.0),
            bottom: Val::Px(10.0),
            ..default()
        },
    ));
}

/// The interaction view on the window, as large as fits above the status lines.
fn show_view(mut commands: Commands, targets: Res<InteractionTargets>, scene: Res<SceneResource>) {
    let k = &scene.0.believed_camera.intrinsics;
    let height = 560.0;
    let width = height * k.width as f32 / k.height as f32;
    commands.spawn((
        Name::new("interaction view"),
        ImageNode::new(targets.view.clone()),
        Node {
            position_type: PositionType::Absolute,
            left: Val::Px(12.0),
            top: Val::Px(12.0),
            width: Val::Px(width),
            height: Val::Px(height),
            ..default()
        },
    ));
}

/// The newest frame onto the panel, the object's twin where the operator's twin is, the hand
/// around it, and the status line. The shared state is copied out under its lock and the lock
/// let go before any work, so the session never waits on the window.
#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn show_session(
    session: Res<Session>,
    (mut state, mut panel): (ResMut<WindowState>, ResMut<TakenFrame>),
    outcome: Res<WindowOutcome>,
    mut images: ResMut<Assets<Image>>,
    mut config: ResMut<InteractionConfig>,
    mut twins: Query<&mut Visibility, With<ObjectTwin>>,
    mut gizmos: Gizmos<HandInteractionGizmos>,
    mut text: Query<&mut Text, With<StatusText>>,
) {
    let (frame, hand, holding, object_pose, carried, line) = {
        let mut shared = session.0.state.lock().unwrap_or_else(|e| e.into_inner());
        let shown = state.shown;
        let fresh = shared
            .hand_at
            .is_some_and(|t| t.elapsed().as_secs_f64() < HAND_SHOWN_S);
        (
            shared.frame.take_if(|f| f.number > shown),
            shared.hand.clone().filter(|_| fresh),
            shared.holding,
            shared.object,
            shared.held_object,
            shared.line.clone(),
        )
    };
    if let Some(frame) = frame {
        state.shown = frame.number;
        let wait_ms = frame.decoded_at.elapsed().as_secs_f64() * 1e3;
        if let Some(mut image) = images.get_mut(&state.video) {
            let size = Extent3d {
                width: frame.width,
                height: frame.height,
                depth_or_array_layers: 1,
            };
            if image.texture_descriptor.size != size {
                image.resize(size);
            }
            image.data = Some(frame.rgba);
            state.report.video_frames += 1;
            state.panel_object = frame.real_object;
            // The hand and the twins in front of the frame, from where it was taken.
            if config.real_camera.world_from_camera != frame.world_from_camera {
                config.real_camera.world_from_camera = frame.world_from_camera;
            }
            if let Ok(mut record) = outcome.0.lock() {
                Spread::push(&mut record.panel_wait_ms, wait_ms);
            }
            // Its age when decoded: the display stage counts from there.
            panel.0 = Some(Taken {
                number: frame.number,
                at: frame.decoded_at,
                age_ms: frame.capture_to_decoded_ms,
            });
        }
    }
    // The operator's twin is drawn where her physics twin is (mapped to the real world); an
    // observer has none, and sees the real object in the video.
    let object = state.object.filter(|&i| i < config.objects.len());
    match (state.observer, object, object_pose) {
        (false, Some(i), Some(pose)) if config.objects[i].world_from_object != pose => {
            config.objects[i].world_from_object = pose;
        }
        (true, _, _) => {
            for mut v in &mut twins {
                v.set_if_neq(Visibility::Hidden);
            }
        }
        _ => {}
    }
    if let (Some(hand), Some(i)) = (hand, object) {
        let colour = crate::teleop::hand_colour(holding);
        // Alice's view: the hand that holds the object is drawn on the real object as this
        // frame shows it (as `avatarm run` draws it in one process).
        let anchor = carried
            .zip(state.panel_object)
            .filter(|_| state.anchor && holding);
        let hand = match anchor {
            Some((twin, real)) => avatarm_core::teleop::hand::carried_with(&hand, &twin, &real),
            None => hand,
        };
        let lines = crate::teleop::hand_in_interaction_view(&hand, &config, i);
        state.report.hand_frames += u64::from(!lines.is_empty());
        if let Some((twin, real)) = anchor.filter(|_| !lines.is_empty()) {
            state.report.anchored_hand_frames += 1;
            if let Ok(mut record) = outcome.0.lock() {
                let d = twin.translation.vector - real.translation.vector;
                Spread::push(&mut record.correction_mm, 1e3 * d.norm());
            }
        }
        for (a, b) in lines {
            gizmos.line(a, b, colour);
        }
    }
    if !line.is_empty() {
        // Glass to glass live: the newest presented frame's, and the median of the last ones.
        let line = format!("{line}{}", outcome.1.line());
        for mut t in &mut text {
            if t.0 != line {
                t.0.clone_from(&line);
            }
        }
    }
}

fn drive_desktop_hand(
    session: Res<Session>,
    controls: DesktopControls,
    time: Res<Time<Real>>,
    mut hand: ResMut<DesktopHand>,
) {
    // Home puts the hand back here, and the twin back in the session's physics. The frame's
    // time is the session's to give (`join::StampedOnArrival`).
    if hand.step(&controls.input(), time.delta_secs_f64(), 0.0) {
        session.0.reset_twin.store(true, Ordering::Relaxed);
    }
}

/// Counts frames; closes at `frames` (after the screenshot), on Escape (as the preview does)
/// or when the session has ended.
fn count_frames(
    mut commands: Commands,
    keys: Res<ButtonInput<KeyCode>>,
    session: Res<Session>,
    mut state: ResMut<WindowState>,
    outcome: Res<WindowOutcome>,
    time: Res<Time<Real>>,
    mut exit: MessageWriter<AppExit>,
) {
    state.report.frames += 1;
    let first = *state.first_frame.get_or_insert_with(Instant::now);
    if state.report.frames > 1 {
        state.report.fps =
            (state.report.frames - 1) as f64 / first.elapsed().as_secs_f64().max(1e-9);
    }
    if let Ok(mut record) = outcome.0.lock() {
        if state.report.frames > 1 {
            Spread::push(&mut record.frame_ms, time.delta_secs_f64() * 1e3);
        }
        record.report = state.report.clone();
    }
    let last = match (state.options.frames, &state.options.screenshot) {
        (Some(n), _) => Some(u64::from(n)),
        (None, Some(_)) => Some(120),
        (None, None) => None,
    };
    if last == Some(state.report.frames)
        && let Some(path) = state.options.screenshot.clone()
    {
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(path));
    }
    if last == Some(state.report.frames)
        || session.0.ended.load(Ordering::Relaxed)
        || keys.just_pressed(KeyCode::Escape)
    {
        state.quit_in.get_or_insert(QUIT_DRAIN);
    }
    match state.quit_in {
        Some(0) => {
            exit.write(AppExit::Success);
        }
        Some(n) => state.quit_in = Some(n - 1),
        None => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window takes each frame once, newest only, numbered as they came.
    #[test]
    fn the_view_holds_the_newest_frame_numbered() {
        let shared = ViewShared::new();
        let at = |x: f64| Isometry3::translation(x, 0.0, 1.0);
        shared.put_frame(2, 1, vec![1; 8], at(1.0), None, 10.0);
        shared.put_frame(2, 1, vec![2; 8], at(2.0), Some(at(0.5)), 20.0);
        let frame = shared.state.lock().unwrap().frame.take().unwrap();
        assert_eq!((frame.number, frame.rgba[0]), (2, 2));
        assert_eq!(frame.world_from_camera, at(2.0));
        assert_eq!(frame.real_object, Some(at(0.5)));
        assert_eq!(frame.capture_to_decoded_ms, 20.0);
        shared.put_frame(2, 1, vec![3; 8], at(3.0), None, 30.0);
        let frame = shared.state.lock().unwrap().frame.take().unwrap();
        assert_eq!(frame.number, 3);
    }
}
