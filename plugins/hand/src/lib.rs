//! The Avatarm hand: a tracked hand as Rapier bodies that touch the object twin, and the
//! contacts they make, every physics step.
//!
//! - Sources ([`HandSource`]): anything that yields timestamped 26-joint
//!   [`HandFrame`](avatarm_core::teleop::hand::HandFrame)s: a scripted hand ([`ScriptedHand`]), a
//!   recorded `.hand.jsonl` file ([`RecordedHand`]), Leap Motion ([`leap`]) and OpenXR hand
//!   tracking ([`openxr`], frames pushed by the app's XR mode into a [`openxr::HandInbox`]).
//! - Bodies: one capsule per phalanx (thumb 2, fingers 3 each) and a box for the palm, no more
//!   than a grasp needs. Each is a dynamic body without gravity, driven toward its tracked pose
//!   by a velocity clamped to `max_speed` (and `max_spin`), with continuous collision detection.
//!   Contact forces therefore stay bounded (a finger tracked deep inside the object pushes with
//!   at most its drive, it does not teleport into it) and nothing tunnels.
//! - Contacts ([`ObjectContacts`]): after each step, every contact between a hand body and a
//!   body marked [`GraspTarget`]: world point, inward normal, normal force (impulse / step) and
//!   the hand's velocity at that point, ready for [`avatarm_core::teleop::grasp`].
//!
//! Modules: [`leap`] (Leap Motion's bones to the skeleton; the device behind feature `leap`),
//! [`leap_recording`] (real Leap recordings, protocol v6 JSON, read into the same bones),
//! [`openxr`] (OpenXR hand joints to the skeleton), [`error`].

pub mod error;
pub mod leap;
pub mod leap_recording;
pub mod openxr;

pub use error::HandError;

/// What most users of the hand need.
pub mod prelude {
    pub use crate::{
        ActiveHand, FixedUntilGrasped, GraspTarget, HandContact, HandError, HandPlugin, HandSource,
        HandSystems, HeldObject, ObjectContacts, RecordedHand, ScriptedHand,
    };
}

use std::path::Path;

use avatarm_core::teleop::grasp::Contact;
use avatarm_core::teleop::hand::{
    HandFilter, HandFilterSettings, HandFrame, HandScript, JOINT_NAMES, PALM, WRIST, parse_frames,
};
use bevy::prelude::*;
use bevy_rapier3d::prelude::*;
use nalgebra::Vector3;

/// A source of hand frames.
pub trait HandSource: Send + Sync + 'static {
    /// Name, for messages.
    fn name(&self) -> &str;
    /// The newest frame captured at or before `now_s`, if any.
    fn poll(&mut self, now_s: f64) -> Option<HandFrame>;
}

/// A scripted hand ([`HandScript`]) sampled at `rate_hz` (tracker rate).
pub struct ScriptedHand {
    script: HandScript,
    period_s: f64,
    /// The last frame's time: a poll before the next frame is due gives nothing, as a
    /// tracker's does.
    last_s: Option<f64>,
}

impl ScriptedHand {
    /// A script sampled at `rate_hz`.
    pub fn new(script: HandScript, rate_hz: f64) -> Self {
        Self {
            script,
            period_s: 1.0 / rate_hz.max(1.0),
            last_s: None,
        }
    }
}

impl HandSource for ScriptedHand {
    fn name(&self) -> &str {
        "scripted hand"
    }

    fn poll(&mut self, now_s: f64) -> Option<HandFrame> {
        let t = (now_s / self.period_s).floor() * self.period_s;
        if self.last_s.is_some_and(|last| t <= last) {
            return None;
        }
        self.last_s = Some(t);
        Some(self.script.frame_at(t))
    }
}

/// Frames from a `.hand.jsonl` file (docs/hand.md), replayed on their timestamps.
pub struct RecordedHand {
    name: String,
    frames: Vec<HandFrame>,
    next: usize,
}

impl RecordedHand {
    /// Loads a `.hand.jsonl` file; errors name the file, the line and the joint.
    pub fn open(path: &Path) -> Result<Self, HandError> {
        let text = std::fs::read_to_string(path).map_err(|source| HandError::Io {
            path: path.to_owned(),
            source,
        })?;
        let frames = parse_frames(&text).map_err(|source| HandError::Recording {
            path: path.to_owned(),
            source: Box::new(source),
        })?;
        if frames.is_empty() {
            return Err(HandError::Empty {
                path: path.to_owned(),
            });
        }
        Ok(Self {
            name: path.display().to_string(),
            frames,
            next: 0,
        })
    }
}

impl RecordedHand {
    /// Frames already converted (a Leap recording's, say), replayed on their timestamps;
    /// `name` is the source's name in messages.
    pub fn from_frames(name: String, frames: Vec<HandFrame>) -> Result<Self, HandError> {
        if frames.is_empty() {
            return Err(HandError::Empty { path: name.into() });
        }
        for f in &frames {
            f.validate()?;
        }
        Ok(Self {
            name,
            frames,
            next: 0,
        })
    }
}

impl HandSource for RecordedHand {
    fn name(&self) -> &str {
        &self.name
    }

    fn poll(&mut self, now_s: f64) -> Option<HandFrame> {
        let mut out = None;
        while self.next < self.frames.len() && self.frames[self.next].t_s <= now_s {
            out = Some(self.frames[self.next].clone());
            self.next += 1;
        }
        out
    }
}

/// The active hand source and its newest frame.
#[derive(Resource)]
pub struct ActiveHand {
    source: Box<dyn HandSource>,
    /// The newest frame received (filtered, see [`HandDrive::filter`]).
    pub latest: Option<HandFrame>,
    /// Frames refused (bad numbers), for the status line.
    pub refused: u64,
    /// The joint filter, made from [`HandDrive::filter`] at the first frame.
    filter: Option<HandFilter>,
}

impl ActiveHand {
    /// A hand fed by `source`.
    pub fn new(source: impl HandSource) -> Self {
        Self {
            source: Box::new(source),
            latest: None,
            refused: 0,
            filter: None,
        }
    }

    /// The source's name.
    pub fn name(&self) -> &str {
        self.source.name()
    }
}

/// How the hand bodies follow the tracked joints.
#[derive(Resource, Debug, Clone, Copy)]
pub struct HandDrive {
    /// Largest linear speed of a hand body (m/s).
    pub max_speed: f32,
    /// Largest angular speed (rad/s).
    pub max_spin: f32,
    /// Density of the hand bodies (kg/m³), which sets how hard they can push.
    pub density: f32,
    /// Friction of the hand's surfaces.
    pub friction: f32,
    /// Largest speed of the finger bodies while the hand holds an object (m/s): they rest on
    /// it instead of pushing the tracked fingers' depth into it, which would shake the object
    /// against the palm's hold.
    pub held_finger_speed: f32,
    /// The adaptive filter on the tracked joint positions. Trackers jitter by about
    /// a millimetre per frame; unfiltered, the hand bodies pass that jitter to a held object
    /// and into the contact twist the robot follows, and a grasp detected on jittering fingers
    /// can come late (docs/hand.md).
    pub filter: HandFilterSettings,
    /// Time in which a body closes its gap to the tracked pose (s), at least one physics step.
    /// A fixed time, not the step: at a higher physics rate a step-sized drive pushes twice as
    /// hard into the object for the same tracked depth (200 Hz physics knocked the bottle out
    /// of one grasp in three with a step-sized drive).
    pub response_s: f32,
}

impl Default for HandDrive {
    fn default() -> Self {
        Self {
            max_speed: 1.0,
            max_spin: 20.0,
            density: 5000.0,
            friction: 1.0,
            held_finger_speed: 0.05,
            filter: HandFilterSettings::default(),
            response_s: 0.01,
        }
    }
}

/// One hand body: which joints it spans.
#[derive(Component, Debug, Clone, Copy)]
pub struct HandPart {
    /// Joint at the start of the bone (index into the 26).
    pub from: usize,
    /// Joint at its end.
    pub to: usize,
}

/// Marks the dynamic body whose contacts are reported (the object twin).
#[derive(Component, Debug, Clone, Copy, Default)]
pub struct GraspTarget;

/// Marks a grasp target that holds still where it rests until the hand takes it: a piece among
/// many on a board. Until grasped the body is fixed ([`RigidBody::Fixed`]): the hand's bodies
/// meet it (their contacts are read and can grasp it) but cannot push it, so a hand reaching
/// past it does not knock it over and its twin stays where the real piece is (the robot cannot
/// follow a push that was never a grasp). The grasp makes it dynamic; after the release it
/// settles under gravity, clear of the opening hand (which touches it without pushing it), and
/// is fixed again once it has been at rest for [`GraspAssist::rest_s`] with no hand body on it,
/// or [`GraspAssist::settle_max_s`] after the release whatever it does. The same policy as the "kinematic until grabbed" objects of VR
/// toolkits (Unity XR Interaction Toolkit's grab interactables). Spawn the body
/// [`RigidBody::Fixed`] with a [`Velocity`].
#[derive(Component, Debug, Clone, Copy, Default, PartialEq)]
pub struct FixedUntilGrasped {
    /// How long the released body has been at rest (s).
    pub at_rest_s: f32,
    /// How long since it was released (s).
    pub released_s: f32,
}

/// One contact of a hand body on a grasp target, after a physics step (world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandContact {
    /// The hand body that makes it.
    pub part: Entity,
    /// The grasp target it is on.
    pub object: Entity,
    /// Point, inward normal, and the normal force as `force` (N).
    pub contact: Contact,
    /// The hand body's velocity at the point (m/s).
    pub hand_velocity: Vector3<f64>,
    /// The object's own velocity at the point (m/s): the material point under the contact,
    /// from the object's pose over the last step. For a grasp that holds (no slip) it equals
    /// the hand's velocity there without the tracking jitter of the finger bodies, and it is
    /// what the paper differentiates: the contact points' positions over time.
    pub object_velocity: Vector3<f64>,
}

/// Contacts of the hand on the grasp targets, after the last physics step (world frame).
#[derive(Resource, Debug, Clone, Default)]
pub struct ObjectContacts {
    /// Time of the step (s, `Time<Fixed>`).
    pub t_s: f64,
    /// One record per contact.
    pub contacts: Vec<HandContact>,
    /// Largest normal force in this step (N).
    pub max_force_n: f64,
}

/// Holding the object once the hand closes around it.
///
/// Tracked fingers cannot squeeze a virtual object the way real ones squeeze a real one (there
/// is nothing to stop them, and the scripted or tracked skeleton rarely wraps an object so that
/// friction alone carries its weight). Like most physics hands in VR, the hand therefore takes
/// the object when two of its bodies touch it from opposing sides (contact normals more than
/// `opposition` apart), one of them the palm or the thumb, while the hand closes
/// (`closing_m`), by a fixed joint between the palm and the object at their pose of that
/// moment; it lets go when the tracked hand opens by `release_opening_m` from its tightest
/// closure since the grasp (a real hand, measured on the Leap `grab` recording, takes the
/// object as its fingers first meet it and goes on closing: released against its closure at
/// the grasp, it never let go). The contacts, their forces and velocities are read as before,
/// so the grasp matrix and the mapping see the hand, not the joint.
#[derive(Resource, Debug, Clone, Copy, PartialEq)]
pub struct GraspAssist {
    /// On (default) or off (contacts and friction only).
    pub enabled: bool,
    /// Two contact normals oppose when their dot product is below this.
    pub opposition: f32,
    /// The hand lets go when its closure opens by this much (m, mean fingertip distance to
    /// the palm).
    pub release_opening_m: f64,
    /// The hand takes an object only once it has closed: its closure this much below the most
    /// open it has been since it last held one, or since tracking last found it (m). An open
    /// hand tracked through an object, or jammed against it, touches it from several sides
    /// without grasping it; a hand found already closed (a fist) opens and closes again first.
    /// A hand that closed earlier and then meets an object (the pouring task's hands 4 and 5,
    /// which brush the bottle on the way in and take it mid-pour) still takes it.
    pub closing_m: f64,
    /// A released [`FixedUntilGrasped`] body is at rest below this speed (m/s, its centre's,
    /// and the same figure in rad/s for its spin).
    pub rest_speed: f32,
    /// ... and is fixed again after this long at rest, clear of the hand (s).
    pub rest_s: f32,
    /// ... or this long after the release whatever it does (s): a piece knocked off the desk
    /// or rolling on its side does not drift on for ever.
    pub settle_max_s: f32,
}

impl Default for GraspAssist {
    fn default() -> Self {
        Self {
            enabled: true,
            opposition: 0.0,
            release_opening_m: 0.015,
            closing_m: 0.005,
            rest_speed: 0.01,
            rest_s: 0.2,
            settle_max_s: 2.0,
        }
    }
}

/// The object the hand holds, if any.
#[derive(Resource, Debug, Clone, Copy, Default, PartialEq)]
pub struct HeldObject {
    /// The held body and the hand's tightest closure since it was taken: a hand goes on
    /// closing after its fingers first meet the object (a real hand does), and it lets go when
    /// it opens from there.
    pub held: Option<(Entity, f64)>,
    /// Grasps so far.
    pub grasps: u32,
    /// Releases so far.
    pub releases: u32,
    /// The most open closure since the hand last let go or held an object, or tracking last
    /// found it (m): a hand takes an object only once it has closed from there, by
    /// [`GraspAssist::closing_m`], or by `release_opening_m` after a release (an opening hand
    /// whose fingers still rest on the object, or meet it again as it drops, does not take it
    /// back).
    pub most_open: Option<f64>,
    /// The hand let go and has not closed by `release_opening_m` since.
    pub released: bool,
}

/// The most closed frame of `frames` ([`closure`]): where a recorded fist is tightest.
pub fn tightest(frames: &[HandFrame]) -> Option<&HandFrame> {
    frames
        .iter()
        .filter_map(|f| closure(f).map(|c| (c, f)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, f)| f)
}

/// How closed a hand is: the mean distance of its five fingertips to the palm joint (m).
pub fn closure(frame: &HandFrame) -> Option<f64> {
    let palm = frame.joints.get(PALM)?.pose.translation.vector;
    let tips = avatarm_core::teleop::hand::TIPS;
    let sum: f64 = tips
        .iter()
        .map(|&t| {
            frame
                .joints
                .get(t)
                .map_or(f64::NAN, |j| (j.pose.translation.vector - palm).norm())
        })
        .sum();
    let c = sum / tips.len() as f64;
    c.is_finite().then_some(c)
}

/// The hand's system sets (`FixedUpdate`).
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub enum HandSystems {
    /// Poll the source and drive the bodies (before the physics step).
    Drive,
    /// Read the contacts (after the physics step).
    Contacts,
}

/// The bones that get a body: thumb proximal→distal→tip, and each finger's proximal,
/// intermediate and distal phalanx.
pub const BONES: [(usize, usize); 14] = [
    (3, 4),
    (4, 5),
    (7, 8),
    (8, 9),
    (9, 10),
    (12, 13),
    (13, 14),
    (14, 15),
    (17, 18),
    (18, 19),
    (19, 20),
    (22, 23),
    (23, 24),
    (24, 25),
];

/// The thumb's joints (metacarpal to tip): its bodies start at these.
const THUMB: [usize; 4] = [2, 3, 4, 5];

/// Contact points farther apart than this (m) without an impulse are predictions, not contacts.
const CONTACT_SLOP: f32 = 0.001;

/// Collision group of the hand (hand bodies do not touch each other).
pub const HAND_GROUP: Group = Group::GROUP_2;

/// Adds the hand: sources are polled in `FixedUpdate`, bodies driven before Rapier's step and
/// contacts read after it. Needs `RapierPhysicsPlugin` in `FixedUpdate` and an [`ActiveHand`].
pub struct HandPlugin;

impl Plugin for HandPlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<HandDrive>()
            .init_resource::<ObjectContacts>()
            .init_resource::<GraspAssist>()
            .init_resource::<HeldObject>()
            .configure_sets(
                FixedUpdate,
                (
                    HandSystems::Drive.before(PhysicsSet::SyncBackend),
                    HandSystems::Contacts.after(PhysicsSet::Writeback),
                ),
            )
            .add_systems(Startup, spawn_hand)
            .add_systems(
                FixedUpdate,
                (z_up_gravity, drive_hand)
                    .chain()
                    .in_set(HandSystems::Drive),
            )
            .add_systems(
                FixedUpdate,
                (read_contacts, assist_grasp, settle_released)
                    .chain()
                    .in_set(HandSystems::Contacts),
            );
    }
}

/// A headless physics app with the hand: minimal Bevy, Rapier in `FixedUpdate`, and one fixed
/// step of `period` per `App::update` (virtual time). Tests and the pouring trials use it;
/// insert an [`ActiveHand`] and spawn the scene.
pub fn headless_app(period: std::time::Duration) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        RapierPhysicsPlugin::<NoUserData>::default().in_fixed_schedule(),
        HandPlugin,
    ))
    .insert_resource(Time::<Fixed>::from_duration(period))
    .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(period));
    app
}

/// Standard gravity along −z: Avatarm's world is z-up (ROS, URDF), Rapier's default is y-up.
pub const GRAVITY: Vec3 = Vec3::new(0.0, 0.0, -9.81);

fn z_up_gravity(mut configs: Query<&mut RapierConfiguration>) {
    for mut c in &mut configs {
        if c.gravity != GRAVITY {
            c.gravity = GRAVITY;
        }
    }
}

fn to_vec3(v: &Vector3<f64>) -> Vec3 {
    Vec3::new(v.x as f32, v.y as f32, v.z as f32)
}

fn to_quat(q: &nalgebra::UnitQuaternion<f64>) -> Quat {
    Quat::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize()
}

/// Where a body should be for a frame: bones centred between their joints with the capsule
/// axis (local y) along the bone; the palm box between the wrist and the middle knuckle.
fn part_target(frame: &HandFrame, part: &HandPart) -> Option<(Transform, f32, f32)> {
    let a = frame.joints.get(part.from)?;
    let b = frame.joints.get(part.to)?;
    let pa = to_vec3(&a.pose.translation.vector);
    let pb = to_vec3(&b.pose.translation.vector);
    let axis = pb - pa;
    let len = axis.length();
    if !len.is_finite() || len < 1e-4 {
        return None;
    }
    if part.from == WRIST {
        // The palm: oriented like the palm joint.
        let rot = to_quat(&frame.joints[PALM].pose.rotation);
        return Some((
            Transform::from_translation((pa + pb) / 2.0).with_rotation(rot),
            len,
            a.radius as f32,
        ));
    }
    let rot = Quat::from_rotation_arc(Vec3::Y, axis / len);
    Some((
        Transform::from_translation((pa + pb) / 2.0).with_rotation(rot),
        len,
        ((a.radius + b.radius) / 2.0) as f32,
    ))
}

fn spawn_hand(mut commands: Commands, drive: Res<HandDrive>) {
    let groups = CollisionGroups::new(HAND_GROUP, Group::ALL ^ HAND_GROUP);
    let common = (
        RigidBody::Dynamic,
        GravityScale(0.0),
        Ccd::enabled(),
        Velocity::zero(),
        Damping {
            linear_damping: 0.0,
            angular_damping: 0.0,
        },
        ColliderMassProperties::Density(drive.density),
        Friction::coefficient(drive.friction),
        groups,
        // In the hand's own solver group, so that a released object can leave it
        // ([`FixedUntilGrasped`]).
        SolverGroups::new(HAND_GROUP, Group::ALL),
        // Parked far away until the first tracked frame.
        Transform::from_xyz(0.0, 0.0, -100.0),
    );
    for (from, to) in BONES {
        let len = 0.03;
        commands.spawn((
            Name::new(format!("hand {}", JOINT_NAMES[from])),
            HandPart { from, to },
            Collider::capsule_y(len / 2.0, 0.008),
            common,
        ));
    }
    // Palm: wrist to the middle finger's metacarpal end (its proximal joint).
    commands.spawn((
        Name::new("hand palm"),
        HandPart {
            from: WRIST,
            to: 12,
        },
        Collider::cuboid(0.04, 0.035, 0.012),
        common,
    ));
}

/// Polls the source and sets each hand body's velocity to reach its target pose in one step,
/// clamped. Capsule sizes follow the tracked bone lengths.
fn drive_hand(
    time: Res<Time<Fixed>>,
    hand: Option<ResMut<ActiveHand>>,
    drive: Res<HandDrive>,
    held: Res<HeldObject>,
    mut parts: Query<(&HandPart, &mut Transform, &mut Velocity, &mut Collider)>,
) {
    let Some(mut hand) = hand else { return };
    let now = time.elapsed_secs_f64();
    if let Some(mut frame) = hand.source.poll(now) {
        match frame.validate() {
            Ok(()) => {
                hand.filter
                    .get_or_insert_with(|| HandFilter::new(drive.filter))
                    .apply(&mut frame);
                hand.latest = Some(frame);
            }
            Err(e) => {
                hand.refused += 1;
                if hand.refused % 100 == 1 {
                    warn!(
                        "hand '{}': frame refused ({} so far): {e}",
                        hand.name(),
                        hand.refused
                    );
                }
            }
        }
    }
    let dt = time
        .timestep()
        .as_secs_f32()
        .max(drive.response_s)
        .max(1e-4);
    let tracked = hand.latest.as_ref().filter(|f| f.tracked);
    for (part, mut transform, mut velocity, mut collider) in &mut parts {
        let Some((target, len, radius)) = tracked.and_then(|f| part_target(f, part)) else {
            // Untracked: hold still where it is (no contact forces come from a lost hand).
            *velocity = Velocity::zero();
            continue;
        };
        if transform.translation.z < -50.0 {
            // First tracked frame: appear at the target.
            *transform = target;
        }
        // Capsules follow the tracked bone length (rebuilt only when it changes by > 1 mm).
        if part.from != WRIST
            && let Some(half) = collider.as_capsule().map(|c| c.half_height())
            && (half - len / 2.0).abs() > 1e-3
        {
            *collider = Collider::capsule_y((len / 2.0).max(1e-3), radius.clamp(0.004, 0.012));
        }
        let mut lin = (target.translation - transform.translation) / dt;
        let max_speed = if held.held.is_some() && part.from != WRIST {
            drive.held_finger_speed
        } else {
            drive.max_speed
        };
        if lin.length() > max_speed {
            lin = lin.normalize() * max_speed;
        }
        let (axis, angle) = (target.rotation * transform.rotation.inverse()).to_axis_angle();
        let angle = if angle > std::f32::consts::PI {
            angle - std::f32::consts::TAU
        } else {
            angle
        };
        let mut ang = axis * angle / dt;
        if !ang.is_finite() {
            ang = Vec3::ZERO;
        }
        if ang.length() > drive.max_spin {
            ang = ang.normalize() * drive.max_spin;
        }
        *velocity = Velocity {
            linear: lin,
            angular: ang,
        };
    }
}

/// Each grasp target's pose at the previous step.
type PreviousPoses = std::collections::HashMap<Entity, Transform>;

/// Grasp targets with a collider, and their poses.
type Targets<'w, 's> =
    Query<'w, 's, (Entity, &'static Transform), (With<GraspTarget>, With<Collider>)>;

/// Reads the contacts between hand bodies and the grasp target after the step.
fn read_contacts(
    time: Res<Time<Fixed>>,
    context: ReadRapierContext,
    targets: Targets,
    mut previous: Local<PreviousPoses>,
    parts: Query<(&Velocity, &Transform), With<HandPart>>,
    mut out: ResMut<ObjectContacts>,
) {
    out.t_s = time.elapsed_secs_f64();
    out.contacts.clear();
    out.max_force_n = 0.0;
    let Ok(context) = context.single() else {
        return;
    };
    let dt = f64::from(time.timestep().as_secs_f32()).max(1e-6);
    for (target, now) in &targets {
        // The object's motion over the step: a point p now was at `back(p)` before it.
        let before = previous.insert(target, *now).unwrap_or(*now);
        let back = |p: Vec3| before.transform_point(now.rotation.inverse() * (p - now.translation));
        for pair in context.contact_pairs_with(target) {
            let (Some(c1), Some(c2)) = (pair.collider1(), pair.collider2()) else {
                continue;
            };
            let (hand_entity, sign) = if c1 == target { (c2, -1.0) } else { (c1, 1.0) };
            let Ok((velocity, transform)) = parts.get(hand_entity) else {
                continue;
            };
            let hand_is_first = c1 == hand_entity;
            for manifold in pair.manifolds() {
                // The world normal points from collider 1 to collider 2: into the object when
                // the hand is collider 1.
                let n = manifold.normal() * sign;
                let normal = Vector3::new(f64::from(n.x), f64::from(n.y), f64::from(n.z));
                for point in manifold.points() {
                    let impulse = point.impulse().abs();
                    // Predicted contacts that are not touching and carry no force.
                    if point.dist() > CONTACT_SLOP && impulse == 0.0 {
                        continue;
                    }
                    let local = if hand_is_first {
                        point.local_p1()
                    } else {
                        point.local_p2()
                    };
                    let p = transform.transform_point(local);
                    let force = f64::from(impulse) / dt;
                    let r = p - transform.translation;
                    let v = velocity.linear + velocity.angular.cross(r);
                    out.max_force_n = out.max_force_n.max(force);
                    let w = (p - back(p)) / dt as f32;
                    out.contacts.push(HandContact {
                        part: hand_entity,
                        object: target,
                        contact: Contact {
                            point: p.as_dvec3().to_array().into(),
                            normal,
                            force: normal * force,
                            moment: Vector3::zeros(),
                        },
                        hand_velocity: v.as_dvec3().to_array().into(),
                        object_velocity: w.as_dvec3().to_array().into(),
                    });
                }
            }
        }
    }
}

/// Takes the object when two hand bodies press on it from opposing sides; lets it go when the
/// tracked hand opens ([`GraspAssist`]).
fn assist_grasp(
    mut commands: Commands,
    assist: Res<GraspAssist>,
    hand: Option<Res<ActiveHand>>,
    contacts: Res<ObjectContacts>,
    mut held: ResMut<HeldObject>,
    parts: Query<(Entity, &HandPart, &Transform)>,
    targets: Query<(Entity, &Transform), With<GraspTarget>>,
) {
    let tracked = hand
        .as_ref()
        .and_then(|h| h.latest.as_ref())
        .filter(|f| f.tracked);
    let now_closure = tracked.and_then(closure);
    if let Some((target, tightest)) = held.held {
        if let Some(c) = now_closure.filter(|c| *c < tightest) {
            held.held = Some((target, c));
        }
        let opened = now_closure.is_some_and(|c| c > tightest + assist.release_opening_m);
        if opened || !assist.enabled || targets.get(target).is_err() {
            if let Ok(mut e) = commands.get_entity(target) {
                e.remove::<ImpulseJoint>();
            }
            held.held = None;
            held.releases += 1;
            held.released = true;
            held.most_open = now_closure;
        }
        return;
    }
    let Some(closure_now) = now_closure else {
        // Untracked: what the hand did before it was lost says nothing of it now.
        held.most_open = None;
        return;
    };
    // The bar rises as the hand opens further: a hand takes an object only by closing,
    // whether or not its fingers lost one it released for a moment (a piece set down drops
    // the last millimetres out of the fingers).
    let most_open = held.most_open.map_or(closure_now, |m| m.max(closure_now));
    held.most_open = Some(most_open);
    let bar = if held.released {
        assist.release_opening_m
    } else {
        assist.closing_m
    };
    if closure_now > most_open - bar {
        return;
    }
    held.released = false;
    if !assist.enabled || contacts.contacts.is_empty() {
        return;
    }
    // An object touched by two hand bodies from opposing sides, one of them the palm or the
    // thumb: the oppositions of a grasp (Iberall's pad, palm and side opposition). Two fingers
    // alone on opposite sides of an object are not holding it: closing round one chess piece,
    // a hand's fingertips reach past it to the next and straddle it.
    let opposer = |e: Entity| {
        parts
            .get(e)
            .is_ok_and(|(_, p, _)| p.from == WRIST || THUMB.contains(&p.from))
    };
    let c = &contacts.contacts;
    let opposed = c.iter().enumerate().find_map(|(i, a)| {
        c[i + 1..]
            .iter()
            .any(|b| {
                a.object == b.object
                    && a.part != b.part
                    && (opposer(a.part) || opposer(b.part))
                    && a.contact.normal.dot(&b.contact.normal) < f64::from(assist.opposition)
            })
            .then_some(a.object)
    });
    let Some(object) = opposed else {
        return;
    };
    let Some((palm, _, palm_t)) = parts.iter().find(|(_, p, _)| p.from == WRIST) else {
        return;
    };
    let Ok((target, target_t)) = targets.get(object) else {
        return;
    };
    // The object's pose in the palm's frame, now.
    let inv = palm_t.rotation.inverse();
    let joint = FixedJointBuilder::new()
        .local_anchor1(inv * (target_t.translation - palm_t.translation))
        .local_basis1(inv * target_t.rotation);
    commands
        .entity(target)
        .insert(ImpulseJoint::new(palm, joint));
    held.held = Some((target, closure_now));
    held.most_open = None;
    held.grasps += 1;
}

/// The solver groups of a released [`FixedUntilGrasped`] body while it settles: the hand's
/// bodies still touch it (their contacts are read) but no longer push it.
const SETTLING: SolverGroups = SolverGroups {
    memberships: Group::ALL,
    filters: Group::ALL.difference(HAND_GROUP),
};

/// Makes a [`FixedUntilGrasped`] body dynamic while the hand holds it; after the release it
/// settles clear of the opening hand (which would otherwise push or topple it) and is fixed
/// again once it has rested [`GraspAssist::rest_s`].
fn settle_released(
    time: Res<Time<Fixed>>,
    assist: Res<GraspAssist>,
    held: Res<HeldObject>,
    contacts: Res<ObjectContacts>,
    mut bodies: Query<(
        Entity,
        &mut FixedUntilGrasped,
        &mut RigidBody,
        &mut Velocity,
        Option<&mut SolverGroups>,
    )>,
    mut commands: Commands,
) {
    let dt = time.timestep().as_secs_f32();
    for (entity, mut still, mut body, mut velocity, solver) in &mut bodies {
        if held.held.is_some_and(|(e, _)| e == entity) {
            if *body != RigidBody::Dynamic {
                *body = RigidBody::Dynamic;
            }
            if let Some(mut s) = solver.filter(|s| **s != SolverGroups::default()) {
                *s = SolverGroups::default();
            }
            still.at_rest_s = 0.0;
            still.released_s = 0.0;
        } else if *body == RigidBody::Dynamic {
            let resting = velocity.linear.length() < assist.rest_speed
                && velocity.angular.length() < assist.rest_speed;
            still.at_rest_s = if resting { still.at_rest_s + dt } else { 0.0 };
            still.released_s += dt;
            // Fixed with a hand body inside it, the restored groups would throw the hand out.
            let touched = contacts.contacts.iter().any(|c| c.object == entity);
            let settled = (still.at_rest_s >= assist.rest_s && !touched)
                || still.released_s >= assist.settle_max_s;
            if settled {
                *body = RigidBody::Fixed;
                *velocity = Velocity::zero();
            }
            // Fixed again, the hand meets it as before.
            let groups = if settled {
                SolverGroups::default()
            } else {
                SETTLING
            };
            match solver {
                Some(mut s) if *s != groups => *s = groups,
                Some(_) => {}
                None => {
                    commands.entity(entity).insert(groups);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
