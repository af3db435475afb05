//! Live teleoperation in `avatarm run`: a scene with a `[task]` runs its trial in the preview,
//! the hand from any source grasping the object's twin in physics and the simulated arm
//! carrying the real object, with the robot erased from the video.
//!
//! The trial's world ([`TrialParts`]: the simulated arm around the real bottle, the mapping,
//! the limiter, the twin's bodies) runs in this app's `FixedUpdate` at the scene's control
//! rate, with Rapier, the hand and the mapping plugins; the simulated room renders the arm
//! (it is driven externally: [`SimRoomConfig::external_drive`]) and the real bottle where the
//! arm carries it, and the app's twin receives the joint states the controller received. The
//! bottle's twin in the interaction view follows the physics twin mapped into the real world,
//! and the hand is drawn as a skeleton there and in the 3-D view.
//!
//! Hand sources ([`HandChoice`], `--hand` or `hand = "..."` in the scene): the trial's scripted
//! hand (default), the desktop hand (keys and mouse, [`crate::preview::keys::DESKTOP_HAND_KEYS`]),
//! OpenXR hand tracking (`--xr`), Leap Motion (feature `leap`), or a recorded `.hand.jsonl` file.

use avatarm_core::teleop::hand::{HandFrame, Handedness, SKELETON, skeleton};
use avatarm_core::teleop::mapping::MappingMode;
use avatarm_erase::interaction::twin_transform;
use avatarm_erase::{EraseState, InteractionConfig, JointHistory};
use avatarm_hand::openxr::HandInbox;
use avatarm_hand::{ActiveHand, GraspTarget, HandPlugin, HeldObject, ObjectContacts, ScriptedHand};
use avatarm_mapping::pouring::{TrialParts, prepare};
use avatarm_mapping::{MappingPlugin, Teleop};
use avatarm_scene::hand::HandChoice;
use avatarm_scene::prop::find_prop;
use avatarm_scene::spec::{LeapMountKind, LeapSpec};
use avatarm_sim::{SimPropPart, SimRobotState, SimRoomConfig};
use avatarm_twin::{JointStateMessage, iso_to_transform, layers, transform_to_iso};
use bevy::camera::visibility::RenderLayers;
use bevy::input::mouse::{AccumulatedMouseMotion, AccumulatedMouseScroll};
use bevy::prelude::*;
use bevy_rapier3d::prelude::{NoUserData, RapierPhysicsPlugin, Velocity};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::{AppError, AppTwin, AvatarmSystems};
use avatarm_core::stats::Spread;
use avatarm_scene::Scene;

mod robot;
#[cfg(feature = "ros")]
pub use robot::link_settings;
pub use robot::{RobotChoice, robot_choice};
use robot::{prepared_q0, ros_arm};

mod hands;
pub(crate) use hands::{hand_source, xr_inbox};

mod anchor;
pub use anchor::HandAnchor;
use anchor::anchor_to_real_object;

mod desktop;
pub use desktop::DesktopHand;
pub(crate) use desktop::{DesktopControls, drive_desktop_hand};

mod chess;
pub use chess::{ChessState, LiveChess, LiveGame};

/// A live session of a scene in `avatarm run`: its `[task]` (pouring), or a game of its
/// `[chess]` where it has no `[task]`.
pub enum LiveSession {
    /// The `[task]`'s trial.
    Task(Box<LiveTeleop>),
    /// A game of `[chess]`.
    Chess(Box<LiveChess>),
}

impl LiveSession {
    /// Prepares the scene's session driven by `choice` on `link` ([`LiveTeleop::prepare_on`],
    /// [`LiveChess::prepare`]); errors as those do, before any window exists.
    pub fn prepare(scene: &Scene, choice: &HandChoice, link: TrialLink) -> Result<Self, AppError> {
        if scene.file.task.is_none() && scene.file.chess.is_some() {
            Ok(Self::Chess(Box::new(LiveChess::prepare(
                scene, choice, &link,
            )?)))
        } else {
            Ok(Self::Task(Box::new(LiveTeleop::prepare_on(
                scene, choice, link,
            )?)))
        }
    }

    /// Adds the session to a preview app ([`LiveTeleop::install`], [`LiveChess::install`]).
    pub fn install(self, app: &mut App) -> Result<(), AppError> {
        match self {
            Self::Task(live) => live.install(app),
            Self::Chess(live) => live.install(app),
        }
    }
}

/// The live trial's fixed parts, for the systems.
#[derive(Resource, Debug, Clone)]
pub struct LiveTask {
    /// The hand source's name.
    pub source: String,
    /// Index of the carried object in the room's props.
    pub prop: usize,
    /// Index of its twin in the interaction layer's objects.
    pub object_twin: Option<usize>,
    /// The real object's base pose (the prop's pose) from its centre (the carried frame).
    pub centre_to_base: Isometry3<f64>,
    /// The mapping mode.
    pub mode: MappingMode,
    /// Height of the real object's centre at the start (m).
    pub start_z: f64,
    /// The object twin's start (virtual scene), where Home puts it back.
    pub twin_start: Transform,
}

/// Hand skeletons in the preview's 3-D view (real world).
#[derive(Default, Reflect, GizmoConfigGroup)]
pub(crate) struct HandViewGizmos;

/// Hand skeletons in the interaction view, in front with the object twins.
#[derive(Default, Reflect, GizmoConfigGroup)]
pub(crate) struct HandInteractionGizmos;

/// The live trial of a scene's `[task]` with a hand source, prepared before any window or app
/// exists: every way the set-up can fail (no task, no grasp the arm can reach, a recording that
/// cannot be read, a device that cannot start) fails in [`LiveTeleop::prepare`], so that
/// `avatarm run` refuses it at start-up with a non-zero exit.
pub struct LiveTeleop {
    scene_name: String,
    object: String,
    mode: MappingMode,
    parts: TrialParts,
    /// `None` for OpenXR hand tracking, which comes from the app's XR view.
    hand: Option<ActiveHand>,
    desktop: Option<DesktopHand>,
    start: Isometry3<f64>,
    prop: usize,
    object_twin: Option<usize>,
    centre_to_base: Isometry3<f64>,
    start_z: f64,
}

impl LiveTeleop {
    /// Sets up the trial of `scene`'s `[task]` driven by `choice`. Errors when the scene has no
    /// task, the task cannot be set up (no reachable grasp, bad settings) or the hand source is
    /// unavailable (a recording that cannot be read, a device, a feature left out of this
    /// build).
    pub fn prepare(
        scene: &Scene,
        choice: &HandChoice,
        robot: RobotChoice,
    ) -> Result<Self, AppError> {
        Self::prepare_on(scene, choice, TrialLink::of(robot))
    }

    /// [`LiveTeleop::prepare`] on the robot `link` (a recording's robot: `run
    /// --camera-recording`).
    pub fn prepare_on(
        scene: &Scene,
        choice: &HandChoice,
        link: TrialLink,
    ) -> Result<Self, AppError> {
        let (parts, mode) = trial_parts_on(scene, link, None, 0, "--hand")?;
        let (Some(task), Some(setup)) = (&scene.file.task, &scene.trial) else {
            return Err(AppError::flag("--hand", "the scene has no [task]"));
        };
        let start = parts.script.wrist_at(0.0).0;
        let (hand, desktop) = hand_source(scene, choice, &parts.script, task.hand_rate_hz)?;
        let (prop, _) = find_prop(&scene.props, &task.object).ok_or_else(|| {
            avatarm_scene::SceneError::field(
                "task.object",
                format!("no prop named '{}'", task.object),
            )
        })?;
        let (object_twin, centre_to_base) = carried_object(scene)
            .ok_or_else(|| AppError::flag("--hand", "the scene has no [task]"))?;
        Ok(Self {
            scene_name: scene.file.name.clone(),
            object: task.object.clone(),
            mode,
            parts,
            hand,
            desktop,
            start,
            prop,
            object_twin,
            centre_to_base,
            start_z: setup.bottle_centre().translation.z,
        })
    }

    /// Adds the trial to a preview app built by [`crate::preview::build_app`] (the simulated room
    /// drives nothing then: the trial's arm does). Errors only for OpenXR hand tracking without the
    /// XR view.
    pub fn install(self, app: &mut App) -> Result<(), AppError> {
        let (hand, desktop) = match self.hand {
            Some(hand) => (hand, self.desktop),
            None => (ActiveHand::new(xr_inbox(app, &self.start)?), None),
        };
        info!(
            "live teleoperation: '{}' with the {} ({} mode) on the {}; the arm starts around the {}",
            self.scene_name,
            hand.name(),
            self.mode.name(),
            self.parts.teleop.robot_name(),
            self.object
        );
        let parts = self.parts;
        let spawn = parts.spawn_bodies();
        {
            let mut room = app.world_mut().resource_mut::<SimRoomConfig>();
            room.external_drive = true;
            room.q0 = prepared_q0(&parts.teleop).unwrap_or_else(|| room.q0.clone());
        }
        // A robot outside the app (a ROS link, a recording's) is ticked on a thread of its own
        // at the control rate, whatever the app's updates cost; the embedded simulated arm is
        // part of the simulated room and keeps its clock (the app's fixed steps).
        let teleop = if parts.teleop.robot().simulated().is_some() {
            parts.teleop
        } else {
            let teleop = parts.teleop.on_control_thread(parts.period)?;
            info!(
                "live teleoperation: the {} is ticked on its own thread every {:.1} ms",
                teleop.robot_name(),
                parts.period.as_secs_f64() * 1e3
            );
            teleop
        };
        app.add_plugins((
            RapierPhysicsPlugin::<NoUserData>::default().in_fixed_schedule(),
            HandPlugin,
            MappingPlugin,
        ))
        .insert_resource(LiveTask {
            source: hand.name().to_owned(),
            prop: self.prop,
            object_twin: self.object_twin,
            centre_to_base: self.centre_to_base,
            mode: self.mode,
            start_z: self.start_z,
            twin_start: avatarm_twin::iso_to_transform(&parts.twin_start),
        })
        .insert_resource(hand)
        .insert_resource(parts.hand_drive)
        .insert_resource(teleop)
        .init_resource::<HandAnchor>()
        .init_gizmo_group::<HandViewGizmos>()
        .init_gizmo_group::<HandInteractionGizmos>()
        .add_systems(
            Startup,
            (spawn, configure_gizmos).in_set(AvatarmSystems::Teleop),
        )
        .add_systems(FixedUpdate, mirror_room.in_set(AvatarmSystems::Mirror))
        .add_systems(
            Update,
            (anchor_to_real_object, follow_twin, draw_hand)
                .chain()
                .in_set(AvatarmSystems::Teleop),
        );
        if let Some(desktop) = desktop {
            app.insert_resource(desktop).add_systems(
                Update,
                drive_desktop_hand
                    .before(anchor_to_real_object)
                    .in_set(AvatarmSystems::Teleop),
            );
        }
        Ok(())
    }
}

/// The live trial's world for `scene`'s `[task]` (trial `trial`'s seeded hand) on `robot`, in
/// `mode` (default: the closed loop where the task has it, else its first mode), and that mode:
/// what `avatarm run` and the robot site of `avatarm serve` drive. A real robot first moves to the
/// grasp's start ([`avatarm_mapping::Approach`]). Errors name `flag` when the scene has no task,
/// and the setting when the task cannot be set up.
pub fn trial_parts(
    scene: &Scene,
    robot: RobotChoice,
    mode: Option<MappingMode>,
    trial: u32,
    flag: &str,
) -> Result<(TrialParts, MappingMode), AppError> {
    trial_parts_on(scene, TrialLink::of(robot), mode, trial, flag)
}

/// The robot behind a live trial ([`trial_parts_on`]).
pub enum TrialLink {
    /// The simulated arm.
    Simulated,
    /// The scene's ROS link (a real arm: it approaches the grasp's start first).
    Ros,
    /// A robot given as it is (a recording's: [`avatarm_core::sim::recorded::RecordedArm`]),
    /// which does not approach.
    Given(Box<dyn avatarm_core::sim::arm::RobotInterface>),
}

impl TrialLink {
    /// The link of a [`RobotChoice`].
    pub fn of(robot: RobotChoice) -> Self {
        match robot {
            RobotChoice::Sim => Self::Simulated,
            RobotChoice::Ros => Self::Ros,
        }
    }
}

/// [`trial_parts`] on the robot `link`.
pub fn trial_parts_on(
    scene: &Scene,
    link: TrialLink,
    mode: Option<MappingMode>,
    trial: u32,
    flag: &str,
) -> Result<(TrialParts, MappingMode), AppError> {
    let (Some(task), Some(setup)) = (&scene.file.task, &scene.trial) else {
        return Err(AppError::flag(
            flag,
            format!(
                "the scene '{}' has no [task] (nor [chess]) to teleoperate",
                scene.file.name
            ),
        ));
    };
    let prepared = prepare(task, setup)?;
    let mode = match mode {
        Some(m) => m,
        None if task.modes.contains(&MappingMode::ClosedLoop) => MappingMode::ClosedLoop,
        None => task
            .modes
            .first()
            .copied()
            .unwrap_or(MappingMode::ClosedLoop),
    };
    let approach = matches!(link, TrialLink::Ros);
    let link = match link {
        TrialLink::Simulated => None,
        TrialLink::Ros => Some(ros_arm(scene, setup, prepared.q0())?),
        TrialLink::Given(arm) => Some(arm),
    };
    let mut parts = TrialParts::on_robot(task, setup, &prepared, mode, trial, link)?;
    if approach {
        // A real arm starts wherever it was left: it moves to the grasp's start first, at
        // the link's speed ratio, before the hand drives it.
        parts.teleop.approach(avatarm_mapping::Approach {
            speed_ratio: scene.file.robot.link.speed_ratio,
            ..avatarm_mapping::Approach::to(prepared.q0().clone())
        })?;
    }
    Ok((parts, mode))
}

/// The scene's carried object (its `[task]` object): its index among the interaction layer's
/// object twins (`None` when it is not drawn as one) and its base pose from its centre (the
/// frame the mapping carries). `None` without a task.
pub(crate) fn carried_object(scene: &Scene) -> Option<(Option<usize>, Isometry3<f64>)> {
    let (Some(task), Some(setup)) = (&scene.file.task, &scene.trial) else {
        return None;
    };
    let object_twin = scene
        .file
        .props
        .iter()
        .zip(&scene.props)
        .filter(|(spec, _)| spec.object)
        .position(|(_, p)| p.name == task.object);
    Some((
        object_twin,
        setup.bottle_centre().inverse() * setup.bottle_base,
    ))
}

/// Adds the live trial of the scene's `[task]` to a preview app, driven by `choice`
/// ([`LiveTeleop::prepare`] then [`LiveTeleop::install`]).
pub fn add_live_teleop(
    app: &mut App,
    scene: &Scene,
    choice: &HandChoice,
    robot: RobotChoice,
) -> Result<(), AppError> {
    LiveTeleop::prepare(scene, choice, robot)?.install(app)
}

pub(crate) fn configure_gizmos(mut store: ResMut<GizmoConfigStore>) {
    let (view, _) = store.config_mut::<HandViewGizmos>();
    view.render_layers = RenderLayers::layer(layers::TWIN);
    view.line.width = 3.0;
    let (interaction, _) = store.config_mut::<HandInteractionGizmos>();
    interaction.render_layers = RenderLayers::layer(layers::INTERACTION);
    interaction.line.width = 4.0;
}

/// After each control tick: the room's arm is the controller's simulated arm, the app's twin
/// gets the joint states the controller got, and the real object is where the arm holds it.
fn mirror_room(
    teleop: Res<Teleop>,
    live: Res<LiveTask>,
    twin: Option<Res<AppTwin>>,
    room: Res<SimRoomConfig>,
    (mut robot, mut anchor): (ResMut<SimRobotState>, ResMut<HandAnchor>),
    mut states: MessageWriter<JointStateMessage>,
    mut parts: Query<(&SimPropPart, &mut Transform)>,
) {
    let arm = teleop.robot();
    if let Some(sim) = arm.simulated() {
        robot.0.clone_from(sim);
    } else if let Some(s) = teleop.received().last() {
        // A real robot: the room's arm (the simulated camera's) shows where it is.
        robot.0.place_at(&s.positions, s.stamp_s);
    }
    if let Some(twin) = twin {
        twin.send(&mut states, &room.model, teleop.received(), 0.0);
    }
    if let Some(centre) = arm.true_object_pose() {
        place_prop(&mut parts, live.prop, &(centre * live.centre_to_base));
        if let Some(sim) = arm.simulated() {
            anchor.record_truth(sim.time_s(), centre);
        }
    }
}

/// Puts the room's prop `prop` (each of its parts) at `base` (its base pose, real world).
pub fn place_prop(
    parts: &mut Query<(&SimPropPart, &mut Transform)>,
    prop: usize,
    base: &Isometry3<f64>,
) {
    let base = iso_to_transform(base);
    for (part, mut t) in parts {
        if part.prop == prop {
            let next = base * part.local;
            if *t != next {
                *t = next;
            }
        }
    }
}

/// The object's twin in the interaction view shows the physics twin mapped into the real
/// world (it moves under the hand, the real one follows through the robot); in Alice's view
/// while held, the real object ([`HandAnchor`]).
fn follow_twin(
    live: Res<LiveTask>,
    teleop: Res<Teleop>,
    anchor: Res<HandAnchor>,
    twin: Query<&Transform, With<GraspTarget>>,
    mut config: ResMut<InteractionConfig>,
) {
    let (Some(i), Ok(t)) = (live.object_twin, twin.single()) else {
        return;
    };
    let centre = match anchor.now {
        Some((_, real)) => real,
        None => teleop.v2r().pose(&transform_to_iso(t)),
    };
    let pose = centre * live.centre_to_base;
    if let Some(object) = config.objects.get(i)
        && object.world_from_object != pose
    {
        config.objects[i].world_from_object = pose;
    }
}

/// The hand as a skeleton: in the 3-D view where the mapping puts it in the real world, and
/// in the interaction view around the object's twin as drawn there.
fn draw_hand(
    hand: Res<ActiveHand>,
    held: Res<HeldObject>,
    live: Res<LiveTask>,
    teleop: Res<Teleop>,
    (config, anchor): (Res<InteractionConfig>, Res<HandAnchor>),
    mut view: Gizmos<HandViewGizmos>,
    mut interaction: Gizmos<HandInteractionGizmos>,
) {
    let colour = hand_colour(held.held.is_some());
    let Some(real) = hand_in_3d_view(&hand, teleop.v2r(), colour, &mut view) else {
        return;
    };
    let Some(i) = live.object_twin else { return };
    let real = match anchor.now {
        Some((twin, object)) => avatarm_core::teleop::hand::carried_with(&real, &twin, &object),
        None => real,
    };
    for (a, b) in hand_in_interaction_view(&real, &config, i) {
        interaction.line(a, b, colour);
    }
}

/// The tracked hand's 26 joints mapped into the real world by `v2r` (m, world), drawn as a
/// skeleton in the preview's 3-D view; `None` (nothing drawn) while the hand is not tracked
/// with 26 joints.
pub(crate) fn hand_in_3d_view(
    hand: &ActiveHand,
    v2r: &avatarm_core::teleop::mapping::VirtualToReal,
    colour: Color,
    view: &mut Gizmos<HandViewGizmos>,
) -> Option<Vec<Vector3<f64>>> {
    let frame = hand
        .latest
        .as_ref()
        .filter(|f| f.tracked && f.joints.len() == 26)?;
    let real: Vec<Vector3<f64>> = frame
        .joints
        .iter()
        .map(|j| v2r.point(&j.pose.translation.vector))
        .collect();
    let v = |p: &Vector3<f64>| Vec3::new(p.x as f32, p.y as f32, p.z as f32);
    for (a, b) in SKELETON {
        view.line(v(&real[a]), v(&real[b]), colour);
    }
    Some(real)
}

/// The real object as the frame on the panel shows it: where the tool held it at the frame's
/// capture time (the joint states interpolated to it, as the mask's twin is posed), else where
/// it is now.
fn object_on_panel(
    teleop: &Teleop,
    history: &JointHistory,
    erase: &EraseState,
) -> Option<Isometry3<f64>> {
    erase
        .frame_capture_s
        .and_then(|t| history.at(t))
        .and_then(|q| teleop.object_at(&q))
        .or_else(|| teleop.real_object())
}

/// The hand skeleton's colour: orange while it holds the object, skin otherwise.
pub(crate) fn hand_colour(holding: bool) -> Color {
    if holding {
        Color::srgb(1.0, 0.55, 0.2)
    } else {
        Color::srgb(0.95, 0.85, 0.7)
    }
}

/// The hand's bones ([`SKELETON`], 26 joints `real` in the real world, m) as drawn in the
/// interaction view: mapped by the similarity that places object twin `object` (its real
/// pose to where [`twin_transform`] draws it), so the hand stays around the twin as drawn.
/// Empty when the object or its placement is missing, or `real` is not 26 joints.
pub(crate) fn hand_in_interaction_view(
    real: &[Vector3<f64>],
    config: &InteractionConfig,
    object: usize,
) -> Vec<(Vec3, Vec3)> {
    let Some(spec) = config.objects.get(object) else {
        return Vec::new();
    };
    let Ok((drawn, _)) = twin_transform(config, spec) else {
        return Vec::new();
    };
    if real.len() != 26 {
        return Vec::new();
    }
    let from_object = spec.world_from_object.inverse();
    let map = |p: &Vector3<f64>| {
        let local = (from_object * nalgebra::Point3::from(*p)).coords;
        drawn.transform_point(Vec3::new(local.x as f32, local.y as f32, local.z as f32))
    };
    SKELETON
        .iter()
        .map(|&(a, b)| (map(&real[a]), map(&real[b])))
        .collect()
}

/// How far the real object is from its twin mapped into the real world (mm), where the robot
/// backend knows the real object (simulation).
fn object_error_mm(teleop: &Teleop, twin: Option<Isometry3<f64>>) -> Option<f64> {
    let truth = teleop.robot().true_object_pose()?;
    let target = teleop.v2r().pose(&twin?);
    Some((target.translation.vector - truth.translation.vector).norm() * 1e3)
}

fn holding(held: &HeldObject) -> &'static str {
    if held.held.is_some() {
        "holding"
    } else {
        "not holding"
    }
}

/// One line for the end of a scripted run: grasps, how high the real object was lifted, and
/// how far it is from its twin mapped into the real world.
pub fn summary(
    live: &LiveTask,
    teleop: &Teleop,
    held: &HeldObject,
    twin: Option<Isometry3<f64>>,
    anchor: Option<&HandAnchor>,
) -> String {
    // Only a simulated robot knows where the real object is; a real one's is not measured.
    let object = match teleop.robot().true_object_pose() {
        Some(truth) => format!(
            "real object lifted {:.1} mm, {:.1} mm from its twin",
            (truth.translation.z - live.start_z) * 1e3,
            object_error_mm(teleop, twin).unwrap_or(f64::NAN)
        ),
        None => "real object not measured (no ground truth on a real robot)".to_owned(),
    };
    let link = teleop
        .robot()
        .status_line()
        .map_or_else(String::new, |l| format!("; {l}"));
    let anchor = anchor.map_or_else(String::new, HandAnchor::summary);
    let thread = teleop
        .thread_stats()
        .map_or_else(String::new, |s| format!("; {}", s.line()));
    format!(
        "teleop: {} ticks, {} grasps, {}, {object}, max TCP speed {:.3} m/s{anchor}{link}{thread}",
        teleop.status.ticks,
        held.grasps,
        holding(held),
        teleop.status.max_tcp_speed
    )
}

/// The live trial's status for the preview's status line; `twin` is the physics twin's pose
/// (virtual scene), for the error between it mapped into the real world and the real object;
/// `anchor` says when the hand is drawn on the real object (Alice's view) and how far it moved.
pub fn status_line(
    live: &LiveTask,
    teleop: &Teleop,
    contacts: &ObjectContacts,
    held: &HeldObject,
    twin: Option<Isometry3<f64>>,
    anchor: Option<&HandAnchor>,
) -> String {
    let s = &teleop.status;
    let error = match object_error_mm(teleop, twin) {
        Some(mm) if held.held.is_some() => format!("; real object {mm:.1} mm off its twin"),
        _ => String::new(),
    };
    let refused = if s.errors > 0 {
        format!(", {} ticks refused", s.errors)
    } else {
        String::new()
    };
    let anchored = anchor
        .and_then(HandAnchor::moved_mm)
        .map_or_else(String::new, |mm| {
            format!("; hand drawn on the real object ({mm:.1} mm from the twin)")
        });
    let link = teleop
        .robot()
        .status_line()
        .map_or_else(String::new, |l| format!("; {l}"));
    let doing = if s.approaching {
        "the arm MOVING TO THE START (the hand takes over there)"
    } else {
        holding(held)
    };
    format!(
        "teleop ({}, {}): {}, {} contacts, max TCP {:.3} m/s{refused}{error}{anchored}{link}",
        live.source,
        live.mode.name(),
        doing,
        contacts.contacts.len(),
        s.max_tcp_speed,
    )
}

#[cfg(test)]
mod tests {
    use super::desktop::DesktopInput;
    use super::*;

    fn step(hand: &mut DesktopHand, keys: &ButtonInput<KeyCode>, dt_s: f64) -> bool {
        let buttons = ButtonInput::<MouseButton>::default();
        let input = DesktopInput {
            keys,
            buttons: &buttons,
            mouse: Vec2::ZERO,
            scroll: 0.0,
        };
        hand.step(&input, dt_s, 1.5)
    }

    /// Up moves the wrist along +x at 0.15 m/s (one update's time capped at 0.1 s), Space
    /// closes the hand over half a second, Home puts it back open at the start; each update
    /// pushes a tracked 26-joint frame at the given time.
    #[test]
    fn the_desktop_hand_moves_closes_and_goes_home() {
        let start = Isometry3::translation(0.1, 0.2, 0.3);
        let mut hand = DesktopHand::new(start);
        let mut keys = ButtonInput::<KeyCode>::default();
        keys.press(KeyCode::ArrowUp);
        keys.press(KeyCode::Space);
        assert!(!step(&mut hand, &keys, 1.0));
        let moved = hand.wrist.translation.vector - start.translation.vector;
        assert!(
            (moved - Vector3::new(0.015, 0.0, 0.0)).norm() < 1e-12,
            "{moved}"
        );
        assert!(
            hand.closing && (hand.grip - 0.2).abs() < 1e-12,
            "{}",
            hand.grip
        );
        let mut frames = hand.inbox.clone();
        let frame = avatarm_hand::HandSource::poll(&mut frames, 2.0).unwrap();
        assert!(frame.tracked && frame.joints.len() == 26 && frame.t_s == 1.5);
        let mut home = ButtonInput::<KeyCode>::default();
        home.press(KeyCode::Home);
        assert!(step(&mut hand, &home, 0.0));
        assert_eq!(hand.wrist, start);
        assert!(!hand.closing && hand.grip == 0.0);
    }

    /// The anchor's record: the true pose at a frame's capture is the one the last control
    /// tick set (sample and hold), none before the kept history; an anchored update counts
    /// how far it moved the hand and how far the drawn object is from that truth.
    #[test]
    fn the_hand_anchor_measures_its_correction_and_its_error_at_the_frame_s_capture() {
        let at = |x: f64| Isometry3::translation(x, 0.0, 0.0);
        let mut anchor = HandAnchor::default();
        for k in 0..=300 {
            let t = f64::from(k) * 0.01;
            anchor.record_truth(t, at(t));
        }
        // A tick's stamp again, or an older one, is not kept twice.
        anchor.record_truth(3.0, at(9.0));
        anchor.record_truth(1.5, at(9.0));
        // The last 2 s are kept.
        assert!(anchor.truth_at(0.5).is_none());
        let held = anchor.truth_at(2.005).unwrap();
        assert!((held.translation.x - 2.0).abs() < 1e-12, "{held}");
        assert!((anchor.truth_at(3.0).unwrap().translation.x - 3.0).abs() < 1e-12);
        assert!(anchor.summary().is_empty(), "nothing anchored yet");
        // Not anchored: nothing counted, nothing drawn on the real object.
        anchor.update(None, Some(2.0));
        assert!(anchor.now.is_none() && anchor.frames == 0 && anchor.moved_mm().is_none());
        // The twin 20 mm ahead of the real object the frame (captured at 2.0 s) shows, which
        // is 1 mm off the truth there; a frame captured before the history: no error counted.
        anchor.update(Some((at(2.021), at(2.001))), Some(2.0));
        anchor.update(Some((at(2.021), at(2.001))), Some(0.2));
        assert_eq!(anchor.frames, 2);
        assert_eq!(anchor.now, Some((at(2.021), at(2.001))));
        assert!((anchor.moved_mm().unwrap() - 20.0).abs() < 1e-9);
        assert_eq!(anchor.correction_mm.len(), 2);
        assert!((anchor.correction_mm[0] - 20.0).abs() < 1e-9);
        assert_eq!(anchor.error_mm.len(), 1);
        assert!((anchor.error_mm[0] - 1.0).abs() < 1e-9);
        let line = anchor.summary();
        assert!(
            line.contains("hand on the real object in 2 updates")
                && line.contains("median 20.0 mm")
                && line.contains("in the frame median 1.0 mm"),
            "{line}"
        );
    }
}
