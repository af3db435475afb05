//! XR mode: the interaction layer in an OpenXR headset (through `bevy_mod_openxr`), with the
//! desktop preview going on beside it.
//!
//! - **Panel.** When a session starts, the interaction view Ĩ(t) (the video with the robot
//!   erased and the object twins in front, the same image as the preview's panel) is shown on
//!   a quad `[xr_layout]` places in front of the user's head, level, facing them. The headset's
//!   eye cameras see only that layer ([`layers::XR_PANEL`]); the mask and composite are render
//!   targets drawn once per camera frame (`avatarm_erase::EraseJob::render`), not once per eye. R in
//!   the preview places the panel in front of the head again.
//! - **Hands.** The tracked hands' 26 joints are drawn as a skeleton on the same layer and the
//!   followed hand is pushed, converted to the scene ([`avatarm_hand::openxr`]), into
//!   [`XrHand`]'s inbox, a hand source like the recorded and Leap ones.
//! - **Fallback.** Without a runtime or headset `bevy_mod_openxr` logs its error and renders
//!   the flat window; this module adds one line saying so and what to do. A session that ends
//!   (headset off, Link unplugged) is reported once; the preview goes on and a new session is
//!   asked for every few seconds, so XR comes back when the headset does.

use avatarm_core::teleop::hand::{Handedness, SKELETON};
use avatarm_core::vision::head::{HeadMotion, LiveHead};
use avatarm_erase::InteractionTargets;
use avatarm_hand::openxr::{HandInbox, XrJoint, XrMount, xr_frame};
use avatarm_twin::layers;
use bevy::camera::visibility::RenderLayers;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy_mod_xr::camera::XrCamera;
use bevy_mod_xr::hands::{HandBone, LeftHand, XrHandBoneEntities, XrHandBoneRadius};
use bevy_mod_xr::session::{XrCreateSessionMessage, XrState, XrTrackingRoot, session_running};
use bevy_mod_xr::spaces::XrSpaceLocationFlags;

use crate::{AvatarmSystems, SceneResource};
use avatarm_scene::spec::XrLayout;

/// Seconds between requests for a new session while the runtime has none.
const RETRY_S: f64 = 5.0;

/// Adds the XR panel, the XR hand and the session reports. Needs `bevy_mod_openxr`'s plugins.
pub struct XrViewPlugin;

/// The followed hand from OpenXR hand tracking, as a hand source ([`HandInbox`]).
#[derive(Resource, Clone)]
pub struct XrHand {
    /// Frames for the active hand (scene frame).
    pub inbox: HandInbox,
    /// The hand followed.
    pub hand: Handedness,
    /// Where the tracking space sits in the scene.
    pub mount: XrMount,
    /// Frames pushed so far.
    pub frames: u64,
}

/// Hand skeletons drawn in the headset.
#[derive(Default, Reflect, GizmoConfigGroup)]
struct XrHandGizmos;

/// The session as this module last saw it.
#[derive(Resource, Default)]
struct XrReport {
    started: bool,
    last: Option<XrState>,
    fallback_told: bool,
    retry_at_s: f64,
    sessions: u32,
    /// Updates with a session running (bevy_mod_openxr submits a frame in each).
    frames_running: u64,
}

#[derive(Component)]
struct XrPanel;

/// Asks for the panel to be placed in front of the head again.
#[derive(Message, Debug, Clone, Copy, Default)]
pub struct RecenterXrPanel;

impl Plugin for XrViewPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<XrReport>()
            .insert_resource(XrHand {
                inbox: HandInbox::new("OpenXR hand tracking"),
                hand: Handedness::Right,
                mount: XrMount::default(),
                frames: 0,
            })
            .add_message::<RecenterXrPanel>()
            .init_gizmo_group::<XrHandGizmos>()
            .add_systems(Startup, configure_gizmos.in_set(AvatarmSystems::Xr))
            .add_systems(
                Update,
                (
                    report_session,
                    eye_cameras_see_the_panel,
                    (place_panel, read_hands, read_head)
                        .chain()
                        .run_if(session_running),
                )
                    .chain()
                    .in_set(AvatarmSystems::Xr),
            )
            // After the replay's and the preview's own exits are asked for.
            .add_systems(Last, report_at_exit.after(AvatarmSystems::Score));
    }
}

/// The scene's head when a headset drives it (`avatarm run --xr` with a camera on a head).
fn live_head(scene: &SceneResource) -> Option<&LiveHead> {
    match scene.0.head.as_ref().map(|h| &h.motion) {
        Some(HeadMotion::Live(live)) => Some(live),
        _ => None,
    }
}

/// The headset's head (the middle of its eye views, the first's orientation; tracking space)
/// drives the scene's head: the simulated room's camera rides on it and its tracker reports
/// it, so the mask follows the wearer. Stamped on the app clock, as the hands are.
fn read_head(
    scene: Res<SceneResource>,
    eyes: Query<&Transform, With<XrCamera>>,
    time: Res<Time<Fixed>>,
) {
    let Some(live) = live_head(&scene) else {
        return;
    };
    let n = eyes.iter().count();
    let Some(first) = eyes.iter().next() else {
        return;
    };
    let centre = eyes.iter().map(|t| t.translation).sum::<Vec3>() / n as f32;
    if centre == Vec3::ZERO && first.rotation == Quat::IDENTITY {
        return; // not located yet
    }
    let c = centre.as_dvec3();
    let q = first.rotation.as_dquat();
    let tracking_from_view = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(c.x, c.y, c.z),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
    );
    live.push_openxr_view(time.elapsed_secs_f64(), &tracking_from_view);
}

/// One line when the app exits: the sessions, the frames submitted, the hand frames taken,
/// for a camera on a head how the headset drove it, and the video frames stamped at the
/// headset's display (the tests against a runtime read it).
#[allow(clippy::too_many_arguments)]
fn report_at_exit(
    mut exits: MessageReader<AppExit>,
    report: Res<XrReport>,
    hand: Res<XrHand>,
    scene: Res<SceneResource>,
    erase: Option<Res<avatarm_erase::EraseState>>,
    glass: Option<Res<super::glass::GlassToGlass>>,
    exts: Option<Res<bevy_mod_openxr::exts::OxrEnabledExtensions>>,
) {
    if exits.read().next().is_none() {
        return;
    }
    let clock = exts.is_some_and(|e| super::glass::ClockConversion::has_clock_conversion(&e.0));
    let shown = match glass.map(|g| (g.headset_spread(), g.spread().n)) {
        Some((s, _)) if s.n > 0 => format!(
            "; {} video frames stamped at the headset's predicted display (capture -> display median {:.1} ms, p95 {:.1} ms)",
            s.n, s.median, s.p95
        ),
        Some((_, n)) if n > 0 && report.frames_running > 0 && !clock => {
            "; video frames stamped at the present only (the runtime granted no clock conversion)"
                .to_owned()
        }
        _ => String::new(),
    };
    let head = match (live_head(&scene), &scene.0.head) {
        (Some(live), Some(rig)) => {
            // The last erased frame's mask camera against the headset's head at that frame's
            // capture, times the mount.
            let mask = match erase.as_ref().map(|e| (e.camera_pose, e.frame_capture_s)) {
                Some((Some(camera), Some(capture_s))) => {
                    let (angle, offset) = avatarm_core::vision::head::pose_error(
                        &camera,
                        &(live.pose_at(capture_s) * rig.believed_mount),
                    );
                    format!(
                        ", the last frame's mask camera {:.3} deg and {:.1} mm off the headset's head at its capture",
                        angle.to_degrees(),
                        offset * 1e3
                    )
                }
                _ => String::new(),
            };
            format!(
                "; head: {} poses from the headset, turned {:.1} deg since the first{mask}",
                live.poses(),
                live.turned_rad().to_degrees()
            )
        }
        _ => String::new(),
    };
    info!(
        "XR summary: {} sessions, {} updates while the session ran (a frame each), {} hand frames from OpenXR hand tracking{head}{shown}",
        report.sessions, report.frames_running, hand.frames
    );
}

fn configure_gizmos(mut store: ResMut<GizmoConfigStore>) {
    let (config, _) = store.config_mut::<XrHandGizmos>();
    config.render_layers = RenderLayers::layer(layers::XR_PANEL);
    config.line.width = 3.0;
}

/// One line per change a user needs to know of; new sessions asked for while there is none.
fn report_session(
    state: Option<Res<XrState>>,
    mut report: ResMut<XrReport>,
    time: Res<Time<Real>>,
    mut create: MessageWriter<XrCreateSessionMessage>,
) {
    let now = time.elapsed_secs_f64();
    let state = state.map(|s| *s);
    if !report.started {
        report.started = true;
        report.retry_at_s = now + RETRY_S;
    }
    match state {
        None | Some(XrState::Unavailable) => {
            if !report.fallback_told {
                report.fallback_told = true;
                warn!(
                    "XR: no OpenXR runtime or headset could be started (the reason is logged \
                     above); showing the desktop preview. Start the runtime with the headset \
                     connected (docs/quest2.md) and run avatarm --xr again."
                );
            }
        }
        Some(s) => {
            if report.last != Some(s) {
                match s {
                    XrState::Running => {
                        report.sessions += 1;
                        info!(
                            "XR: session running (session {}); the interaction panel is in \
                             front of you, R in the preview re-centres it",
                            report.sessions
                        );
                    }
                    XrState::Available if report.sessions > 0 => warn!(
                        "XR: the session ended (headset off or disconnected?); the desktop \
                         preview goes on and XR comes back when the runtime starts a session"
                    ),
                    XrState::Available => info!(
                        "XR: runtime found; waiting for it to start a session (is the headset \
                         on and connected?)"
                    ),
                    _ => {}
                }
            }
            if s == XrState::Available && now >= report.retry_at_s {
                create.write_default();
                report.retry_at_s = now + RETRY_S;
            }
            if s != XrState::Available {
                report.retry_at_s = now + RETRY_S;
            }
        }
    }
    if state == Some(XrState::Running) {
        report.frames_running += 1;
    }
    report.last = state;
}

fn eye_cameras_see_the_panel(mut commands: Commands, cameras: Query<Entity, Added<XrCamera>>) {
    for e in &cameras {
        commands
            .entity(e)
            .insert((RenderLayers::layer(layers::XR_PANEL), Tonemapping::None));
    }
}

/// Where the panel goes for a head pose (tracking space, y up): `distance` ahead along the
/// head's level heading, `below` under the eyes, facing the head. None before the head is
/// located (an identity pose).
pub fn panel_pose(head: &Transform, layout: &XrLayout) -> Option<Transform> {
    if head.translation == Vec3::ZERO && head.rotation == Quat::IDENTITY {
        return None;
    }
    let ahead = head.rotation * Vec3::NEG_Z;
    let level = Vec3::new(ahead.x, 0.0, ahead.z)
        .try_normalize()
        .unwrap_or(Vec3::NEG_Z);
    let centre = head.translation + level * layout.panel_distance_m as f32
        - Vec3::Y * layout.panel_below_eye_m as f32;
    Some(Transform::from_translation(centre).looking_to(level, Vec3::Y))
}

#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn place_panel(
    mut commands: Commands,
    scene: Res<SceneResource>,
    targets: Option<Res<InteractionTargets>>,
    eyes: Query<&Transform, (With<XrCamera>, Without<XrPanel>)>,
    root: Query<Entity, With<XrTrackingRoot>>,
    mut panels: Query<&mut Transform, With<XrPanel>>,
    mut recenter: MessageReader<RecenterXrPanel>,
    mut placed_for: Local<u32>,
    report: Res<XrReport>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let again = recenter.read().count() > 0;
    let Some(targets) = targets else { return };
    // The head: the middle of the eyes.
    let n = eyes.iter().count();
    if n == 0 {
        return;
    }
    let mut head = Transform::IDENTITY;
    head.translation = eyes.iter().map(|t| t.translation).sum::<Vec3>() / n as f32;
    head.rotation = eyes.iter().next().map_or(Quat::IDENTITY, |t| t.rotation);
    let layout = &scene.0.file.xr_layout;
    let Some(pose) = panel_pose(&head, layout) else {
        return;
    };
    if let Ok(mut t) = panels.single_mut() {
        if again || *placed_for != report.sessions {
            *t = pose;
            *placed_for = report.sessions;
        }
        return;
    }
    let k = &scene.0.believed_camera.intrinsics;
    let h = layout.panel_height_m as f32;
    let w = h * k.width as f32 / k.height as f32;
    let panel = commands
        .spawn((
            Name::new("XR interaction panel"),
            XrPanel,
            // It shows the camera's interaction view: a camera switch spawns it again.
            avatarm_twin::CameraBound,
            Mesh3d(meshes.add(Rectangle::new(w, h))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color_texture: Some(targets.view.clone()),
                unlit: true,
                cull_mode: None,
                ..default()
            })),
            pose,
            RenderLayers::layer(layers::XR_PANEL),
        ))
        .id();
    if let Ok(root) = root.single() {
        commands.entity(root).add_child(panel);
    }
    *placed_for = report.sessions;
}

/// Hand frames from the XR runtime's hand tracking, stamped on the app clock (`Time<Fixed>`'s
/// elapsed time, the clock of joint states and camera frames).
fn read_hands(
    hands: Query<(&XrHandBoneEntities, Has<LeftHand>)>,
    bones: Query<(&GlobalTransform, &XrSpaceLocationFlags, &XrHandBoneRadius), With<HandBone>>,
    mut xr_hand: ResMut<XrHand>,
    mut gizmos: Gizmos<XrHandGizmos>,
    time: Res<Time<Fixed>>,
) {
    for (entities, left) in &hands {
        let mut joints = Vec::with_capacity(26);
        for e in entities.iter() {
            let Ok((t, flags, radius)) = bones.get(*e) else {
                break;
            };
            let (_, rotation, position) = t.to_scale_rotation_translation();
            joints.push(XrJoint {
                position: position.to_array(),
                orientation: rotation.to_array(),
                radius: radius.0,
                tracked: flags.position_tracked && flags.rotation_tracked,
            });
        }
        if joints.len() != 26 {
            continue;
        }
        if joints.iter().all(|j| j.tracked) {
            let color = if left {
                Color::srgb(0.4, 0.8, 1.0)
            } else {
                Color::srgb(1.0, 0.8, 0.4)
            };
            for (a, b) in SKELETON {
                gizmos.line(
                    Vec3::from_array(joints[a].position),
                    Vec3::from_array(joints[b].position),
                    color,
                );
            }
        }
        let side = if left {
            Handedness::Left
        } else {
            Handedness::Right
        };
        if side != xr_hand.hand {
            continue;
        }
        match xr_frame(&joints, side, &xr_hand.mount, time.elapsed_secs_f64()) {
            Ok(frame) => {
                xr_hand.inbox.push(frame);
                xr_hand.frames += 1;
            }
            Err(e) => warn!("{e}; frame dropped"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_panel_faces_the_head_level_ahead_and_below_the_eyes() {
        let layout = XrLayout {
            panel_distance_m: 1.0,
            panel_height_m: 0.5,
            panel_below_eye_m: 0.2,
        };
        assert!(
            panel_pose(&Transform::IDENTITY, &layout).is_none(),
            "not located yet"
        );
        // Head 1.6 m up, turned 90 degrees left (looking down -x) and pitched down 30 degrees.
        let head = Transform::from_xyz(0.3, 1.6, 0.0).with_rotation(
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2)
                * Quat::from_rotation_x(-30f32.to_radians()),
        );
        let p = panel_pose(&head, &layout).expect("a located head");
        assert!(
            (p.translation - Vec3::new(-0.7, 1.4, 0.0)).length() < 1e-5,
            "{p:?}"
        );
        // The quad's front (+z) looks back at the head, level.
        let normal = p.rotation * Vec3::Z;
        assert!((normal - Vec3::X).length() < 1e-5, "{normal}");
        assert!((p.rotation * Vec3::Y - Vec3::Y).length() < 1e-5);
    }
}
