//! The simulated room plugin: Alice's desk with a robot, a camera and ground truth.
//!
//! Add [`SimRoomPlugin`] with a [`SimRoomConfig`] resource. The room spawns at startup; the robot
//! steps in `FixedUpdate` at the control rate; joint states are sent, with their latency, to the
//! twin named by [`SimRoomConfig::twin`] as [`JointStateMessage`]s.
//!
//! One module: this one. Props are described by `avatarm_scene::prop` (re-exported here) and
//! drawn by [`prop_parts`]; the simulated robot's dynamics are `avatarm_core::sim`.

use std::sync::Arc;

use avatarm_core::rng::Rng;
use avatarm_core::robot::RobotModel;
use avatarm_core::robot::trajectory::JointTrajectory;
use avatarm_core::sim::{JointCommand, SimRobot, SimRobotParams};
use avatarm_core::vision::camera::PinholeCamera;
use avatarm_core::vision::distortion::{Distortion, DistortionMap};
use avatarm_core::vision::head::{HeadMotion, HeadTracker, TrackingModel};
use avatarm_core::vision::sensor::SensorModel;
use avatarm_scene::prop::{BOTTLE_BODY_FRACTION, BOTTLE_NECK_RADIUS_FRACTION};
pub use avatarm_scene::prop::{Prop, PropShape};
use avatarm_twin::camera::camera_transform;
use avatarm_twin::camera::{RenderSettled, SCENERY_DEPTH_BIAS, add_render_settled};
pub use avatarm_twin::camera::{spawn_pinhole_camera, target_image};
use avatarm_twin::flat::{FlatPart, FlatView, add_flat_render, flat_target_image};
use avatarm_twin::prelude::*;
use avatarm_twin::readback::{ImageRead, ImageReadbackPlugin, read_image_once};
use avatarm_twin::{CameraBound, layers};
use avatarm_video::{HeadPoseMessage, VideoFrame, VideoInbox};
use bevy::camera::visibility::RenderLayers;
use bevy::camera::visibility::VisibilitySystems;
use bevy::core_pipeline::prepass::DepthPrepass;
use bevy::diagnostic::FrameCount;
use bevy::light::SimulationLightSystems;
use bevy::prelude::*;
use bevy::transform::TransformSystems;
use nalgebra::{DVector, Isometry3};

/// What most users need.
pub mod prelude {
    pub use crate::{
        Prop, PropShape, SimCameras, SimPropPart, SimRobotState, SimRoomConfig, SimRoomPlugin,
        SimRoomSystems, SimTwins, VideoCounter,
    };
}

/// The room's system sets.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimRoomSystems {
    /// Scripted commands, robot step, joint-state delivery (`FixedUpdate`).
    Step,
    /// Spawns the room: props, the robot, the cameras (`PreStartup`).
    Setup,
    /// Poses the simulated robot's visuals at its true joint positions (`PostUpdate`).
    PoseRobot,
    /// The real camera's capture (`Last`); ground truth for a frame is read back after it, in
    /// the same update.
    Capture,
    /// The robot-free view renders only when the room changed (`PostUpdate`, after transform
    /// propagation).
    GateTruth,
    /// A camera on a head: the room's views follow the head at the robot's time (`PostUpdate`,
    /// before transform propagation).
    MoveCamera,
}

/// Everything the room needs to know. Insert it before the app starts.
#[derive(Resource, Debug, Clone)]
pub struct SimRoomConfig {
    /// The robot.
    pub model: Arc<RobotModel>,
    /// Pose of the robot's root link in the world.
    pub robot_base: Isometry3<f64>,
    /// Robot timing and response.
    pub robot: SimRobotParams,
    /// Initial joint positions.
    pub q0: DVector<f64>,
    /// Scripted motion (position commands at the control rate); empty = none.
    pub trajectory: JointTrajectory,
    /// Control / simulation step rate (Hz).
    pub control_rate_hz: f64,
    /// The real camera at its true pose.
    pub camera: PinholeCamera,
    /// Its lens: the room's views render the pinhole view wide enough for every ray it sees
    /// and their read-backs are distorted into the camera's image ([`SimCameras::camera_image`]).
    pub distortion: Distortion,
    /// Props, including the real objects.
    pub props: Vec<Prop>,
    /// Render the ground-truth views (robot silhouette, room without robot).
    pub ground_truth: bool,
    /// The app's twin to send joint states to.
    pub twin: Option<Entity>,
    /// Deliver the real camera's frames as a video source (sensor model, latency).
    pub video: Option<SimVideo>,
    /// The camera rides on a head (Alice's headset camera): the real camera and the ground
    /// truth's views follow `head(t) · mount` at the robot's time, and the head's tracked poses
    /// are sent as [`HeadPoseMessage`]s. `camera`'s pose is then the one at t = 0.
    pub head: Option<SimHead>,
    /// Something else drives the robot (the live teleoperation steps its own simulated arm,
    /// writes it into [`SimRobotState`] and delivers its joint states): the room neither
    /// commands, steps nor reads out the robot, it renders it.
    pub external_drive: bool,
    /// Render the real camera's view of the room even without simulated [`video`](Self::video)
    /// (a preview shows it on its panel); off at the robot site, where a real camera's frames
    /// are the video and nothing shows the room.
    pub room_view: bool,
}

/// One rendered part of a prop (the room's view and its silhouette view): moving a prop
/// (the real object the arm carries) sets each part to the new pose times `local`.
#[derive(Component, Debug, Clone, Copy)]
pub struct SimPropPart {
    /// Index into [`SimRoomConfig::props`].
    pub prop: usize,
    /// The part relative to the prop's base pose.
    pub local: Transform,
}

/// The simulated camera as a video source.
#[derive(Debug, Clone, PartialEq)]
pub struct SimVideo {
    /// Noise and exposure.
    pub sensor: SensorModel,
    /// Capture to arrival (s).
    pub frame_latency_s: f64,
    /// Seed of the sensor noise (frame `k` uses stream `k`).
    pub seed: u64,
    /// Frames per second: the camera captures at most this often, however fast the app
    /// updates (a headset's 72-90 Hz, a replay's one update per frame).
    pub fps: f64,
}

/// A head that the simulated camera rides on.
#[derive(Debug, Clone, PartialEq)]
pub struct SimHead {
    /// Where the head is over time (`world_from_head`).
    pub motion: HeadMotion,
    /// The camera in the head's frame (`head_from_camera`).
    pub mount: Isometry3<f64>,
    /// How the headset reports the head.
    pub tracking: TrackingModel,
    /// Seed of the tracking noise (sample `k` uses stream `k`).
    pub seed: u64,
}

/// The simulated head's tracker (a camera on a head).
#[derive(Resource, Debug, Clone)]
pub struct SimHeadTracker(pub HeadTracker);

/// The simulated robot (ground truth of its joints lives here).
#[derive(Resource, Debug, Clone)]
pub struct SimRobotState(pub SimRobot);

/// The room's render targets.
#[derive(Resource, Debug, Clone)]
pub struct SimCameras {
    /// What the real camera sees.
    pub real: Handle<Image>,
    /// The same view without the robot (ground truth).
    pub no_robot: Option<Handle<Image>>,
    /// The robot's visible silhouette: white robot, black elsewhere (ground truth; `R8Unorm`,
    /// drawn flat by [`avatarm_twin::flat`]).
    pub silhouette: Option<Handle<Image>>,
    /// With a distorting lens, the map from the views' pinhole renders to the camera's image:
    /// the images above are the pinhole renders, [`SimCameras::camera_image`] distorts their
    /// read-backs.
    pub lens: Option<Arc<DistortionMap>>,
}

impl SimCameras {
    /// A read-back of one of the views (`width × height`, `bytes_per_pixel`) as the camera
    /// gives it: through the lens (bilinear for a lit view; `nearest` for a silhouette, whose
    /// pixels stay 0 or 255), else as it is. Errors: a read-back of another size than the
    /// views'.
    pub fn camera_image(
        &self,
        (width, height, bytes_per_pixel): (u32, u32, usize),
        data: Vec<u8>,
        nearest: bool,
    ) -> avatarm_core::Result<(u32, u32, Vec<u8>)> {
        let Some(map) = &self.lens else {
            return Ok((width, height, data));
        };
        if (width, height) != (map.pinhole.width, map.pinhole.height) {
            return Err(avatarm_core::Error::BadImage {
                what: "simulated view".into(),
                message: format!(
                    "read back at {width}x{height}, but the lens's pinhole render is {}x{}",
                    map.pinhole.width, map.pinhole.height
                ),
            });
        }
        let out = if nearest {
            map.remap_nearest("simulated view", &data, bytes_per_pixel)?
        } else {
            map.remap_bilinear("simulated view", &data, bytes_per_pixel)?
        };
        Ok((map.image.width, map.image.height, out))
    }
}

/// The simulated robot's visual twins.
#[derive(Resource, Debug, Clone)]
pub struct SimTwins {
    /// Real appearance, seen by the real camera.
    pub real: Entity,
    /// White silhouette for ground truth.
    pub silhouette: Option<Entity>,
}

/// Adds the room. Needs [`RobotTwinPlugin`] and a [`SimRoomConfig`] resource.
#[derive(Default)]
pub struct SimRoomPlugin;

impl Plugin for SimRoomPlugin {
    fn build(&self, app: &mut App) {
        let rate = app
            .world()
            .get_resource::<SimRoomConfig>()
            .map_or(100.0, |c| c.control_rate_hz);
        if !app.is_plugin_added::<ImageReadbackPlugin>() {
            app.add_plugins(ImageReadbackPlugin);
        }
        add_flat_render(app);
        add_render_settled(app);
        app.insert_resource(Time::<Fixed>::from_hz(rate))
            .add_message::<HeadPoseMessage>()
            .configure_sets(FixedUpdate, SimRoomSystems::Step)
            .configure_sets(
                PostUpdate,
                SimRoomSystems::PoseRobot.in_set(RobotTwinSystems::ApplyJointStates),
            )
            .configure_sets(
                PostUpdate,
                // Before the systems that skip an inactive camera (its visible meshes, its
                // shadow cascades, its light clusters): a view turned on again renders this
                // update with them up to date, not with those of its last active update.
                SimRoomSystems::GateTruth
                    .after(TransformSystems::Propagate)
                    .after(VisibilitySystems::VisibilityPropagate)
                    .before(VisibilitySystems::CheckVisibility)
                    .before(SimulationLightSystems::UpdateDirectionalLightCascades)
                    .before(SimulationLightSystems::AssignLightsToClusters),
            )
            .add_systems(
                PreStartup,
                (setup_room, spawn_camera_views)
                    .chain()
                    .in_set(SimRoomSystems::Setup),
            )
            .add_systems(
                PostUpdate,
                gate_no_robot_view.in_set(SimRoomSystems::GateTruth),
            )
            .add_systems(
                PostUpdate,
                move_head_camera
                    .in_set(SimRoomSystems::MoveCamera)
                    .after(RobotTwinSystems::PoseLinks)
                    .before(TransformSystems::Propagate),
            )
            .add_systems(
                FixedUpdate,
                track_head
                    .in_set(SimRoomSystems::Step)
                    .run_if(resource_exists::<SimHeadTracker>),
            )
            .add_systems(Last, capture_video.in_set(SimRoomSystems::Capture))
            .add_systems(
                FixedUpdate,
                (send_scripted_commands, step_robot, deliver_joint_states)
                    .chain()
                    .in_set(SimRoomSystems::Step)
                    .run_if(|c: Res<SimRoomConfig>| !c.external_drive),
            )
            .add_systems(
                PostUpdate,
                pose_sim_robot
                    .in_set(SimRoomSystems::PoseRobot)
                    .after(avatarm_twin::apply_joint_states),
            );
    }
}

fn setup_room(mut commands: Commands, config: Res<SimRoomConfig>, mut assets: TwinAssets) {
    for (index, prop) in config.props.iter().enumerate() {
        let lit = assets.materials.add(StandardMaterial {
            base_color: Color::srgba(prop.rgba[0], prop.rgba[1], prop.rgba[2], prop.rgba[3]),
            perceptual_roughness: 0.7,
            depth_bias: SCENERY_DEPTH_BIAS,
            ..default()
        });
        for (part, local) in prop_parts(&prop.shape) {
            let mesh = assets.meshes.add(part);
            let transform = iso_to_transform(&prop.pose) * local;
            let part = SimPropPart { prop: index, local };
            commands.spawn((
                Name::new(prop.name.clone()),
                Mesh3d(mesh.clone()),
                MeshMaterial3d(lit.clone()),
                transform,
                RenderLayers::layer(layers::ROOM),
                part,
            ));
            if config.ground_truth {
                commands.spawn((
                    Mesh3d(mesh),
                    FlatPart::OCCLUDER,
                    transform,
                    RenderLayers::layer(layers::SIM_SILHOUETTE),
                    part,
                ));
            }
        }
    }
    commands.spawn((
        DirectionalLight {
            illuminance: 6000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::from_xyz(1.0, 1.5, 3.0).looking_at(Vec3::ZERO, Vec3::Z),
        RenderLayers::from_layers(&[layers::ROOM, layers::SIM_ROBOT, layers::TWIN]),
    ));
    commands.insert_resource(GlobalAmbientLight {
        color: Color::WHITE,
        brightness: 400.0,
        ..default()
    });

    let real = spawn_twin_with_visuals(
        &mut commands,
        &mut assets,
        &config.model,
        &config.robot_base,
        TwinAppearance::Urdf,
        TwinDetail::default(),
        &RenderLayers::layer(layers::SIM_ROBOT),
        "simulated room",
    )
    .root;
    let silhouette = config.ground_truth.then(|| {
        spawn_twin_with_visuals(
            &mut commands,
            &mut assets,
            &config.model,
            &config.robot_base,
            TwinAppearance::Flat(FlatPart::ROBOT),
            TwinDetail::default(),
            &RenderLayers::layer(layers::SIM_SILHOUETTE),
            "simulated room's silhouette",
        )
        .root
    });
    commands.insert_resource(SimTwins { real, silhouette });
    commands.insert_resource(SimRobotState(SimRobot::new(
        config.robot,
        config.model.dof_limits(),
        config.q0.clone(),
    )));
}

/// The room's views through the configured camera ([`SimRoomConfig::camera`],
/// `distortion`, `head`), each marked [`CameraBound`]: the real camera (the video's source),
/// and with ground truth the robot-free camera and the robot's silhouette; [`SimCameras`] names
/// their images, and a camera on a head gets its tracker ([`SimHeadTracker`]). Runs at start-up
/// after the room; a camera switch despawns the views and runs it again for the next camera.
pub fn spawn_camera_views(
    mut commands: Commands,
    config: Res<SimRoomConfig>,
    mut images: ResMut<Assets<Image>>,
    time: Res<Time<Fixed>>,
) {
    // Through a lens, the views render its pinhole view (the read-backs are distorted).
    let lens = if config.distortion.is_none() {
        None
    } else {
        match DistortionMap::new(&config.camera.intrinsics, &config.distortion, 1.0) {
            Ok(map) => Some(Arc::new(map)),
            Err(e) => {
                error!("simulated camera: {e}; its frames are a pinhole's");
                None
            }
        }
    };
    let view_camera = PinholeCamera {
        intrinsics: lens
            .as_ref()
            .map_or(config.camera.intrinsics, |m| m.pinhole),
        world_from_camera: config.camera.world_from_camera,
    };
    let k = &view_camera.intrinsics;
    let background = Color::srgb(0.78, 0.80, 0.83);
    let real_image = images.add(target_image(k.width, k.height));
    // The lit views draw depth first, so each pixel is shaded once: the room's wall, floor and
    // desk overlap across the whole frame, and a software rasteriser shades every layer
    // (measured on llvmpipe: 121 -> 95 ms for this view; the pixels are the same).
    let real = spawn_pinhole_camera(
        &mut commands,
        &view_camera,
        real_image.clone(),
        RenderLayers::from_layers(&[layers::ROOM, layers::SIM_ROBOT]),
        background,
        -30,
        "real camera",
    );
    commands
        .entity(real)
        .insert((DepthPrepass, RoomView, CameraBound));
    if config.video.is_none() && !config.room_view {
        // The camera is a real one (a webcam, a recording) and nothing shows the room's view.
        commands
            .entity(real)
            .entry::<Camera>()
            .and_modify(|mut camera| camera.is_active = false);
    }
    let (mut no_robot, mut silhouette_image) = (None, None);
    if config.ground_truth {
        let image = images.add(target_image(k.width, k.height));
        let no_robot_camera = spawn_pinhole_camera(
            &mut commands,
            &view_camera,
            image.clone(),
            RenderLayers::layer(layers::ROOM),
            background,
            -29,
            "ground truth: no robot",
        );
        commands.entity(no_robot_camera).insert((
            DepthPrepass,
            NoRobotCamera,
            RoomView,
            CameraBound,
        ));
        no_robot = Some(image);
        // White robot, black scenery, drawn flat (no camera: avatarm_twin::flat).
        let image = images.add(flat_target_image(k.width, k.height));
        commands.spawn((
            Name::new("ground truth: robot silhouette"),
            FlatView {
                camera: view_camera,
                target: image.clone(),
                clear: 0,
                active: true,
                name: "ground truth: robot silhouette".to_owned(),
            },
            RenderLayers::layer(layers::SIM_SILHOUETTE),
            RoomView,
            CameraBound,
        ));
        silhouette_image = Some(image);
    }
    commands.insert_resource(SimCameras {
        real: real_image,
        no_robot,
        silhouette: silhouette_image,
        lens,
    });
    match &config.head {
        Some(head) => {
            // From a second back (the frames in flight are older than now): at start-up, t = 0.
            let from_s = time.elapsed_secs_f64() - 1.0;
            commands.insert_resource(SimHeadTracker(HeadTracker::starting_at(
                head.tracking,
                head.seed,
                from_s,
            )));
        }
        None => commands.remove_resource::<SimHeadTracker>(),
    }
}

/// Meshes of a prop's parts with their transforms relative to the prop's base pose.
pub fn prop_parts(shape: &PropShape) -> Vec<(Mesh, Transform)> {
    let upright = |z: f64| {
        Transform::from_xyz(0.0, 0.0, z as f32)
            .with_rotation(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2))
    };
    match *shape {
        PropShape::Box { size } => vec![(
            Cuboid::new(size[0] as f32, size[1] as f32, size[2] as f32).into(),
            Transform::from_xyz(0.0, 0.0, (size[2] / 2.0) as f32),
        )],
        PropShape::Cylinder { radius, height } => vec![(
            Cylinder::new(radius as f32, height as f32).into(),
            upright(height / 2.0),
        )],
        PropShape::Bottle { radius, height } => {
            let body = height * BOTTLE_BODY_FRACTION;
            let neck = height - body;
            vec![
                (
                    Cylinder::new(radius as f32, body as f32).into(),
                    upright(body / 2.0),
                ),
                (
                    Cylinder::new((radius * BOTTLE_NECK_RADIUS_FRACTION) as f32, neck as f32)
                        .into(),
                    upright(body + neck / 2.0),
                ),
            ]
        }
        PropShape::Sphere { radius } => vec![(
            Sphere::new(radius as f32).into(),
            Transform::from_xyz(0.0, 0.0, radius as f32),
        )],
    }
}

fn send_scripted_commands(
    config: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    time: Res<Time<Fixed>>,
) {
    let t = time.elapsed_secs_f64();
    if let Some(q) = config.trajectory.sample(t)
        && let Err(e) = robot.0.send(JointCommand::Position(q))
    {
        warn!("scripted trajectory at t={t:.3}s: command refused: {e}");
    }
}

fn step_robot(mut robot: ResMut<SimRobotState>, time: Res<Time<Fixed>>) {
    robot.0.step(time.delta_secs_f64());
}

fn deliver_joint_states(
    config: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    mut out: MessageWriter<JointStateMessage>,
) {
    let states = robot.0.receive();
    let Some(twin) = config.twin else { return };
    for s in states {
        out.write(JointStateMessage::full(
            twin,
            &config.model,
            &s.positions,
            &s.velocities,
            s.stamp_s,
        ));
    }
}

/// A prop part whose transform (its own or its world one) or visibility changed this update.
type PropChanged = (
    With<SimPropPart>,
    Or<(
        Changed<Transform>,
        Changed<GlobalTransform>,
        Changed<InheritedVisibility>,
    )>,
);

/// Marks the room's views that follow a camera on a head (the real camera, the robot-free
/// view, the silhouette's flat view).
#[derive(Component, Debug, Clone, Copy)]
struct RoomView;

/// A camera on a head: the room's views at `head(t) · mount`, `t` the robot's time (the time
/// the capture in `Last` stamps the frame with).
fn move_head_camera(
    config: Res<SimRoomConfig>,
    robot: Option<Res<SimRobotState>>,
    mut transforms: Query<&mut Transform, (With<RoomView>, With<Camera>)>,
    mut flat: Query<&mut FlatView, With<RoomView>>,
) {
    let (Some(head), Some(robot)) = (&config.head, robot) else {
        return;
    };
    let pose = head.motion.pose_at(robot.0.time_s()) * head.mount;
    let camera = PinholeCamera {
        intrinsics: config.camera.intrinsics,
        world_from_camera: pose,
    };
    let transform = camera_transform(&camera);
    for mut t in &mut transforms {
        if *t != transform {
            *t = transform;
        }
    }
    for mut view in &mut flat {
        if view.camera.world_from_camera != pose {
            view.camera.world_from_camera = pose;
        }
    }
}

/// Samples the head's tracker at the control rate and sends the poses that have arrived.
fn track_head(
    config: Res<SimRoomConfig>,
    time: Res<Time<Fixed>>,
    mut tracker: ResMut<SimHeadTracker>,
    mut out: MessageWriter<HeadPoseMessage>,
) {
    let Some(head) = &config.head else { return };
    for p in tracker.0.poll(&head.motion, time.elapsed_secs_f64()) {
        out.write(HeadPoseMessage {
            stamp_s: p.stamp_s,
            world_from_head: p.pose,
        });
    }
}

/// Marks the robot-free ground-truth camera.
#[derive(Component, Debug, Clone, Copy)]
struct NoRobotCamera;

/// The room without the robot changes only when a prop moves (the real object the arm
/// carries), appears or goes: the robot-free view renders from the room's first update and in
/// an update where a prop part's transform or visibility changed or a part was removed, and
/// then until a frame after that change has rendered completely (no pipeline still compiling,
/// [`RenderSettled`]: at least two renders per change); otherwise its image keeps the last
/// render, which is what the camera would see. Its lights and the camera are fixed for the
/// room's life. On a software rasteriser this view cost a third of a replay's update (measured:
/// 90 ms of 326 on llvmpipe at 640x480).
#[expect(clippy::too_many_arguments, reason = "a system's inputs")]
fn gate_no_robot_view(
    frame: Res<FrameCount>,
    settled: Res<RenderSettled>,
    changed: Query<(), PropChanged>,
    mut removed: RemovedComponents<SimPropPart>,
    mut last_change: Local<Option<u32>>,
    mut cameras: Query<&mut Camera, With<NoRobotCamera>>,
    added: Query<(), Added<NoRobotCamera>>,
    config: Res<SimRoomConfig>,
) {
    let this = RenderSettled::this_update_frame(&frame);
    // A camera on a head sees another room at every update; a new view (a camera switch) has
    // not rendered yet.
    if last_change.is_none()
        || config.head.is_some()
        || !added.is_empty()
        || !changed.is_empty()
        || removed.read().count() > 0
    {
        *last_change = Some(this);
    }
    let active = last_change.is_some_and(|c| settled.last_complete_frame() <= c);
    for mut camera in &mut cameras {
        if camera.is_active != active {
            camera.is_active = active;
        }
    }
}

fn pose_sim_robot(
    robot: Res<SimRobotState>,
    sim_twins: Res<SimTwins>,
    mut twins: Query<&mut RobotTwin>,
) {
    let t = robot.0.time_s();
    for entity in std::iter::once(sim_twins.real).chain(sim_twins.silhouette) {
        if let Ok(mut twin) = twins.get_mut(entity) {
            twin.positions.clone_from(robot.0.true_positions());
            twin.velocities.clone_from(robot.0.true_velocities());
            twin.stamp_s = Some(t);
        }
    }
}

/// Frames captured by the simulated camera so far, and when the next one is due.
#[derive(Resource, Debug, Default)]
pub struct VideoCounter {
    /// Frames captured.
    pub frames: u64,
    /// The newest capture: frame index and capture time (robot clock, s).
    pub last: Option<(u64, f64)>,
    next_s: f64,
}

/// At each update that reaches the next frame time (the camera's fps), the real camera's image
/// is read back (the simulated camera's "sensor"), the sensor model applied at the capture
/// time, and the frame queued to arrive after the latency.
fn capture_video(
    mut commands: Commands,
    config: Res<SimRoomConfig>,
    cameras: Option<Res<SimCameras>>,
    robot: Option<Res<SimRobotState>>,
    counter: Option<ResMut<VideoCounter>>,
    time: Res<Time>,
) {
    let (Some(video), Some(cameras), Some(robot)) = (config.video.clone(), cameras, robot) else {
        return;
    };
    let Some(mut counter) = counter else {
        commands.init_resource::<VideoCounter>();
        return;
    };
    // Frame times on the app clock (a replay's updates land on them, up to rounding); the
    // capture is stamped with the robot's clock, which moves in control steps.
    let now = time.elapsed_secs_f64();
    if now + 1e-6 < counter.next_s {
        return;
    }
    let period = 1.0 / video.fps.max(1e-3);
    counter.next_s = if now - counter.next_s < period {
        counter.next_s + period
    } else {
        // Fell behind (a stall): the next frame one period from now.
        now + period
    };
    let capture_s = robot.0.time_s();
    let index = counter.frames;
    counter.frames += 1;
    counter.last = Some((index, capture_s));
    let cameras = cameras.clone();
    read_image_once(&mut commands, cameras.real.clone()).observe(
        move |read: On<ImageRead>, now: Option<Res<SimCameras>>, mut inbox: ResMut<VideoInbox>| {
            // A capture of a camera the app no longer looks through (a switch since).
            if now.is_none_or(|now| now.real != cameras.real) {
                return;
            }
            let size = (read.width, read.height, read.bytes_per_pixel);
            let (width, height, mut rgba) =
                match cameras.camera_image(size, read.data.clone(), false) {
                    Ok(image) => image,
                    Err(e) => {
                        error!("simulated camera: {e}; frame {index} dropped");
                        return;
                    }
                };
            video
                .sensor
                .apply(&mut rgba, capture_s, &mut Rng::stream(video.seed, index));
            let frame = VideoFrame {
                index,
                capture_s,
                arrival_s: capture_s + video.frame_latency_s,
                width,
                height,
                rgba: Arc::new(rgba),
            };
            if let Err(e) = inbox.push(frame) {
                error!("simulated camera: {e}");
            }
        },
    );
}

#[cfg(test)]
mod tests;
