//! The robot site's erased video (`avatarm serve`, video on): the app runs headless in real
//! time; the simulated room's arm (and the app's twin behind the mask) follow the control
//! loop's joint states ([`ArmUpdate`]), the real object where the arm carries
//! it. Each erased frame is read back once, coded (JPEG, or H.264 with IDR frames on time and
//! on a viewer's request; [`avatarm_net::codec`]) on a thread of its own and published with
//! its stage stamps (capture, erased, sent; the site's clock).
//!
//! The read-back is the one the live path gets for the network, as `--record` gets one for
//! the disk.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

use avatarm_core::sim::JointState;
use avatarm_erase::{EraseState, EraseTargets};
use avatarm_net::msg::{FrameHeader, PROTOCOL_VERSION};
use avatarm_net::{FrameSender, SiteClock};
use avatarm_scene::Scene;
use avatarm_scene::prop::find_prop;
use avatarm_sim::{SimPropPart, SimRobotState, SimRoomConfig};
use avatarm_twin::JointStateMessage;
use avatarm_twin::readback::{ImageRead, read_image_once};
use bevy::prelude::*;
use nalgebra::Isometry3;

use crate::AppTwin;

/// The least time between two IDR frames forced by viewers' requests (s): many viewers
/// asking at once, or one asking again and again, cost one keyframe per this long.
pub const MIN_FORCED_KEYFRAME_INTERVAL_S: f64 = 0.25;

/// The video's counters, for the site's report.
#[derive(Debug, Default)]
pub struct VideoCounters {
    /// Frames published.
    pub published: AtomicU64,
    /// Of them, keyframes.
    pub keyframes: AtomicU64,
    /// Keyframes forced by viewers' requests.
    pub forced_keyframes: AtomicU64,
    /// Frames the encoder refused (each also logged).
    pub encode_errors: AtomicU64,
    /// Frames H.264's rate control skipped.
    pub skipped: AtomicU64,
    /// A camera on a head: poses of the head taken from its wearer's headset (the network).
    pub head_poses: AtomicU64,
    /// Of those received, refused (malformed, not finite, another camera's) or not newer than
    /// the last taken.
    pub head_refused: AtomicU64,
}

/// What the video side needs: the loop's updates, the publisher, the site's clock, and the
/// flag that ends the app.
#[derive(Clone)]
pub struct ServeVideoOptions {
    /// The loop's joint states.
    pub updates: Arc<Mutex<Receiver<ArmUpdate>>>,
    /// Publishes coded frames.
    pub sender: FrameSender,
    /// The camera's name on the network.
    pub camera: String,
    /// The site's clock.
    pub clock: SiteClock,
    /// Set when the app should end (the loop finished).
    pub stop: Arc<AtomicBool>,
    /// How frames are coded.
    pub encoder: avatarm_net::codec::EncoderSettings,
    /// The counters.
    pub counters: Arc<VideoCounters>,
    /// A camera on a head: its wearer's head poses from the network (`join --xr` or `--head`),
    /// which the scene's live head ([`avatarm_core::vision::head::LiveHead`]) takes; until the
    /// first arrives, the scene's simulated head moves the camera.
    pub head: Option<Arc<avatarm_net::HeadReceiver>>,
}

impl std::fmt::Debug for ServeVideoOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServeVideoOptions")
            .field("camera", &self.camera)
            .finish_non_exhaustive()
    }
}

/// What the video side gets from the loop: each joint state, with the real object's pose
/// where the robot backend knows it (simulation).
#[derive(Debug, Clone)]
pub struct ArmUpdate {
    /// The joint state (stamp on the site's clock).
    pub state: JointState,
    /// The real object's centre (real world).
    pub object: Option<Isometry3<f64>>,
}

/// The robot site's video: mirrors the loop into the room, publishes erased frames.
pub struct ServeVideoPlugin(pub ServeVideoOptions);

/// Builds the robot site's app for one camera of `scene`: the app's base without a window, in
/// real time ([`crate::app::build_app`]), then [`ServeVideoPlugin`].
pub fn build_app(scene: &Scene, options: ServeVideoOptions) -> Result<App, crate::AppError> {
    let base = crate::app::AppBase::new(crate::app::Runner::RealTime);
    let mut app = crate::app::build_app(scene, &base)?;
    app.add_plugins(ServeVideoPlugin(options));
    Ok(app)
}

#[derive(Resource)]
struct ServeVideo {
    options: ServeVideoOptions,
    encoder: Sender<Coded>,
    last_index: Option<u64>,
    carried: Option<(usize, Isometry3<f64>)>,
    /// The camera's believed pose (the frames' until the erase has drawn one).
    world_from_camera: Isometry3<f64>,
    /// A refused head pose has been logged (one line per run of refusals).
    head_refusing: bool,
    /// The site's clock minus the app's (s) the head's poses were last stamped with.
    head_clock: Option<f64>,
}

/// A frame read back, to be coded.
struct Coded {
    header: FrameHeader,
    rgba: Vec<u8>,
}

impl Plugin for ServeVideoPlugin {
    fn build(&self, app: &mut App) {
        let options = self.0.clone();
        let (tx, rx) = channel::<Coded>();
        let sender = options.sender.clone();
        let clock = options.clock;
        let counters = options.counters.clone();
        let settings = options.encoder;
        let camera = options.camera.clone();
        let _ = std::thread::Builder::new()
            .name("video encoder".into())
            .spawn(move || encode_and_send(rx, sender, clock, settings, &camera, &counters));
        let carried = app
            .world()
            .get_resource::<crate::SceneResource>()
            .and_then(|s| carried_object(&s.0));
        let world_from_camera = app
            .world()
            .get_resource::<crate::SceneResource>()
            .map_or_else(Isometry3::identity, |s| {
                s.0.believed_camera.world_from_camera
            });
        if let Some(mut room) = app.world_mut().get_resource_mut::<SimRoomConfig>() {
            room.external_drive = true;
        }
        app.insert_resource(ServeVideo {
            options,
            encoder: tx,
            last_index: None,
            carried,
            world_from_camera,
            head_refusing: false,
            head_clock: None,
        })
        .add_systems(
            Update,
            (
                (take_remote_head, mirror_loop).chain(),
                // The frame erased in this update, with the camera it was drawn from.
                publish_erased.after(avatarm_erase::EraseSystems::Prepare),
                stop_when_done,
            ),
        );
    }
}

/// The carried prop's index and its base pose from its centre (the pose the loop reports).
fn carried_object(scene: &Scene) -> Option<(usize, Isometry3<f64>)> {
    let task = scene.file.task.as_ref()?;
    let setup = scene.trial.as_ref()?;
    let (prop, _) = find_prop(&scene.props, &task.object)?;
    Some((prop, setup.bottle_centre().inverse() * setup.bottle_base))
}

/// The site's clock minus the app's (s), for this update: the site's clock at the update's
/// start (now, less the time since it began) against the app's elapsed time then. One value
/// for every stamp converted in an update, so that they keep their order. It changes between
/// updates when the app's clock falls behind the wall's (an update longer than Bevy's largest
/// step).
fn site_minus_app(clock: &SiteClock, time: &Time, real: &Time<Real>) -> f64 {
    let since_update = real
        .last_update()
        .map_or(0.0, |t| t.elapsed().as_secs_f64());
    clock.now_s() - since_update - time.elapsed_secs_f64()
}

/// The loop's joint states into the room's arm and the app's twin (their stamps moved to the
/// app's clock), the real object where the arm holds it.
#[allow(clippy::too_many_arguments)] // a Bevy system: each argument is a parameter it reads
fn mirror_loop(
    video: Res<ServeVideo>,
    time: Res<Time>,
    real: Res<Time<Real>>,
    twin: Option<Res<AppTwin>>,
    room: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    mut states: MessageWriter<JointStateMessage>,
    mut parts: Query<(&SimPropPart, &mut Transform)>,
) {
    let site_minus_app = site_minus_app(&video.options.clock, &time, &real);
    let updates: Vec<ArmUpdate> = match video.options.updates.lock() {
        Ok(rx) => rx.try_iter().collect(),
        Err(_) => return,
    };
    let Some(last) = updates.last() else { return };
    robot
        .0
        .place_at(&last.state.positions, last.state.stamp_s - site_minus_app);
    if let Some(twin) = twin {
        for u in &updates {
            states.write(JointStateMessage::full(
                twin.0,
                &room.model,
                &u.state.positions,
                &u.state.velocities,
                u.state.stamp_s - site_minus_app,
            ));
        }
    }
    if let (Some(centre), Some((prop, centre_to_base))) = (last.object, video.carried) {
        crate::teleop::place_prop(&mut parts, prop, &(centre * centre_to_base));
    }
}

/// A camera on a head: the wearer's head poses from the network into the scene's live head,
/// their stamps moved from the site's clock to the app's. A refused one (malformed, stamped
/// more than [`avatarm_net::msg::MAX_AHEAD_S`] ahead, not newer than the last) is counted and
/// logged (one line until a pose is taken again); the head then holds its last pose.
fn take_remote_head(
    mut video: ResMut<ServeVideo>,
    time: Res<Time>,
    real: Res<Time<Real>>,
    scene: Res<crate::SceneResource>,
) {
    let Some(receiver) = video.options.head.clone() else {
        return;
    };
    let Some(avatarm_core::vision::head::HeadMotion::Live(live)) =
        scene.0.head.as_ref().map(|h| &h.motion)
    else {
        return;
    };
    // The poses taken before move with the app's clock, so that each keeps its moment on the
    // site's clock.
    let site_minus_app = site_minus_app(&video.options.clock, &time, &real);
    if let Some(before) = video.head_clock.replace(site_minus_app) {
        live.shift(before - site_minus_app);
    }
    let site_now = video.options.clock.now_s();
    for m in receiver.poll() {
        let taken = match m {
            // A pose from the future would hold every later one off as older.
            Ok(m) if m.stamp_s > site_now + avatarm_net::msg::MAX_AHEAD_S => Err(format!(
                "a pose stamped {:.3} s, more than {} s ahead of the site's clock ({site_now:.3} s)",
                m.stamp_s,
                avatarm_net::msg::MAX_AHEAD_S
            )),
            Ok(m) if live.push_world(m.stamp_s - site_minus_app, &m.world_from_head()) => Ok(()),
            Ok(m) => Err(format!(
                "a pose stamped {:.3} s, not newer than the last taken",
                m.stamp_s
            )),
            Err(e) => Err(e.to_string()),
        };
        match taken {
            Ok(()) => {
                video
                    .options
                    .counters
                    .head_poses
                    .fetch_add(1, Ordering::Relaxed);
                if std::mem::take(&mut video.head_refusing) {
                    info!("camera '{}': head poses taken again", video.options.camera);
                }
            }
            Err(why) => {
                video
                    .options
                    .counters
                    .head_refused
                    .fetch_add(1, Ordering::Relaxed);
                if !std::mem::replace(&mut video.head_refusing, true) {
                    warn!(
                        "camera '{}': head pose refused: {why}",
                        video.options.camera
                    );
                }
            }
        }
    }
}

/// Each newly erased frame, read back and handed to the encoder.
fn publish_erased(
    mut commands: Commands,
    mut video: ResMut<ServeVideo>,
    time: Res<Time>,
    real: Res<Time<Real>>,
    state: Res<EraseState>,
    targets: Option<Res<EraseTargets>>,
) {
    let (Some(targets), Some((t_s, index, _))) = (
        targets,
        state
            .current
            .as_ref()
            .filter(|c| c.dirty)
            .and_then(|c| c.frame.clone()),
    ) else {
        return;
    };
    if video.last_index == Some(index) {
        return;
    }
    video.last_index = Some(index);
    let clock = video.options.clock;
    let capture_s = t_s + site_minus_app(&clock, &time, &real);
    // The camera this frame's mask was drawn from (a camera on a head moves).
    let camera_pose = FrameHeader::pose_of(&state.camera_pose.unwrap_or(video.world_from_camera));
    let camera = video.options.camera.clone();
    let codec = video.options.encoder.codec.name();
    let tx = video.encoder.clone();
    read_image_once(&mut commands, targets.composite.clone()).observe(
        move |read: On<ImageRead>| {
            let header = FrameHeader {
                v: PROTOCOL_VERSION,
                camera: camera.clone(),
                index,
                codec: codec.into(),
                seq: 0,
                keyframe: false,
                stream: 0,
                width: read.width,
                height: read.height,
                capture_s,
                erased_s: clock.now_s(),
                sent_s: f64::NAN,
                camera_pose,
            };
            let _ = tx.send(Coded {
                header,
                rgba: read.data.clone(),
            });
        },
    );
}

fn stop_when_done(video: Res<ServeVideo>, mut exit: MessageWriter<AppExit>) {
    if video.options.stop.load(Ordering::Relaxed) {
        exit.write(AppExit::Success);
    }
}

/// The encoder's thread: RGBA → JPEG or H.264 → the network, newest first (a frame that
/// waited behind a newer one is dropped: late video is useless). An H.264 IDR frame is forced
/// when a viewer asked, at most once per [`MIN_FORCED_KEYFRAME_INTERVAL_S`].
fn encode_and_send(
    rx: Receiver<Coded>,
    sender: FrameSender,
    clock: SiteClock,
    settings: avatarm_net::codec::EncoderSettings,
    camera: &str,
    counters: &VideoCounters,
) {
    let mut encoder = match avatarm_net::codec::VideoEncoder::new(settings) {
        Ok(e) => e,
        Err(e) => {
            error!("robot site video: {e}; no video is published");
            return;
        }
    };
    let mut requested = false;
    let mut last_forced_s = f64::NEG_INFINITY;
    while let Ok(mut frame) = rx.recv() {
        while let Ok(newer) = rx.try_recv() {
            frame = newer;
        }
        let Coded { mut header, rgba } = frame;
        requested |= sender.take_keyframe_request(camera);
        let now = clock.now_s();
        let force = requested && now - last_forced_s >= MIN_FORCED_KEYFRAME_INTERVAL_S;
        let coded = match encoder.encode(&rgba, header.width, header.height, now, force) {
            Ok(Some(c)) => c,
            // Skipped by the rate control: viewers keep the frame before.
            Ok(None) => {
                counters.skipped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            Err(e) => {
                if counters.encode_errors.fetch_add(1, Ordering::Relaxed) == 0 {
                    warn!("robot site video: {e} (further errors are counted, not logged)");
                }
                continue;
            }
        };
        if coded.keyframe {
            // Any keyframe answers the viewers' requests (JPEG: every frame).
            requested = false;
            if force && settings.codec == avatarm_net::msg::Codec::H264 {
                last_forced_s = now;
                counters.forced_keyframes.fetch_add(1, Ordering::Relaxed);
            }
        }
        header.seq = coded.seq;
        header.stream = coded.stream;
        header.keyframe = coded.keyframe;
        header.sent_s = clock.now_s();
        match sender.send(&header, coded.bytes) {
            Ok(()) => {
                counters.published.fetch_add(1, Ordering::Relaxed);
                if coded.keyframe {
                    counters.keyframes.fetch_add(1, Ordering::Relaxed);
                }
            }
            Err(e) => warn!("robot site video: {e}"),
        }
    }
}
