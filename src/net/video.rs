//! The robot site's erased video (`avatarm serve`, video on): the app runs headless in real
//! time; the simulated room's arm (and the app's twin behind the mask) follow the control
//! loop's joint states ([`ArmUpdate`]), the real object where the arm carries
//! it. The camera is the simulated room's, a webcam or a recording played live
//! ([`crate::app::CameraSource`]). Each erased frame is read back in the render world right after
//! its frame (`avatarm_twin::readback::direct`), coded (JPEG, or H.264
//! with IDR frames on time and on a viewer's request; [`avatarm_net::codec`]) on a thread of
//! its own and published with its stage stamps (captured, arrived in the app, erased and read
//! back, sent; the site's clock) and the app's updates it arrived and was handed to the encoder
//! in.
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
use avatarm_twin::camera::{RenderSettled, add_render_settled};
use avatarm_twin::readback::direct::{DirectRead, DirectReadQueue, DirectReadbackPlugin};
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
    /// Frames handed to the encoder more than one app update after they arrived.
    pub handed_late: AtomicU64,
    /// Frames not published because the erase was not ready for them: drawn while a pipeline
    /// compiled (the app's first frames), or before the twin behind the mask had a joint state.
    pub unready: AtomicU64,
    /// The most app updates a frame waited between arriving and being handed over.
    pub waited_updates_max: AtomicU64,
    /// The main world's time per update (ms, `First` to the end of `Last`: the systems, not the
    /// render world's extraction and rendering), the last [`UPDATE_TIMES_KEPT`].
    pub update_ms: Mutex<std::collections::VecDeque<f64>>,
    /// Updates run.
    pub updates: AtomicU64,
    /// The app's GPU spans (each camera's render, each erase pass; where the device times
    /// them), for the report.
    pub gpu_times: Mutex<Option<avatarm_erase::GpuTimes>>,
}

/// How many updates' times [`VideoCounters::update_ms`] keeps.
pub const UPDATE_TIMES_KEPT: usize = 100_000;

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
    /// Where the camera's frames come from.
    pub source: crate::app::CameraSource,
    /// `--ros2-publish`: each erased frame also on ROS 2 (`/avatarm/erased/compressed`; the
    /// JPEG the network gets, so with `--codec jpeg` only), and its mask
    /// (`/avatarm/mask/compressed`, PNG, read back and coded only then).
    pub ros2: Option<crate::net::ros2_out::Ros2Sink>,
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
    let base = crate::app::AppBase {
        camera: options.source.clone(),
        // The site publishes the erased frames; each viewer draws its own interaction layer.
        interaction_layer: false,
        ..crate::app::AppBase::new(crate::app::Runner::RealTime)
    };
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
    /// The frames published lately: (index, arrival (s, app clock), the update it arrived in).
    arrivals: std::collections::VecDeque<(u64, f64, u32)>,
    /// The main world's update now (its frame count), for the render thread.
    update: Arc<AtomicU64>,
    /// When this update began.
    update_started: Option<std::time::Instant>,
    /// The site's clock minus the app's (s), this update's ([`note_site_clock`]).
    site_minus_app: f64,
    /// `--ros2-publish`: the masks read back, to the thread that codes and publishes them.
    masks: Option<Sender<MaskRead>>,
}

/// A mask read back (`bytes_per_pixel` bytes a pixel, the first the mask), captured at
/// `capture_s` (the site's clock).
struct MaskRead {
    capture_s: f64,
    image: avatarm_twin::readback::direct::ImageBytes,
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
        let ros2 = options.ros2.clone();
        // One mapping of the site's clock for the frames and masks on ROS 2.
        let to_unix = crate::net::ros2_out::SiteToUnix::now(&clock);
        let _ = std::thread::Builder::new()
            .name("video encoder".into())
            .spawn(move || {
                encode_and_send(
                    rx,
                    sender,
                    clock,
                    settings,
                    &camera,
                    &counters,
                    ros2.as_ref().map(|sink| (sink, to_unix)),
                );
            });
        let masks = options.ros2.clone().and_then(|sink| {
            let (tx, rx) = channel::<MaskRead>();
            std::thread::Builder::new()
                .name("ros2 masks".into())
                .spawn(move || publish_masks(&rx, &sink, to_unix))
                .map_err(|e| warn!("robot site: no mask on ROS 2: cannot start its thread: {e}"))
                .ok()
                .map(|_| tx)
        });
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
            // The video is the camera's: a real camera's frames, or the simulated one's.
            room.room_view = false;
        }
        add_render_settled(app);
        if let (Some(times), Ok(mut slot)) = (
            app.world().get_resource::<avatarm_erase::GpuTimes>(),
            self.0.counters.gpu_times.lock(),
        ) {
            *slot = Some(times.clone());
        }
        app.insert_resource(ServeVideo {
            options,
            encoder: tx,
            last_index: None,
            carried,
            world_from_camera,
            head_refusing: false,
            head_clock: None,
            arrivals: std::collections::VecDeque::new(),
            update: Arc::default(),
            update_started: None,
            site_minus_app: 0.0,
            masks,
        })
        .add_plugins(DirectReadbackPlugin)
        .add_systems(First, count_update)
        .add_systems(
            RunFixedMainLoop,
            note_site_clock.in_set(RunFixedMainLoopSystems::AfterFixedMainLoop),
        )
        .add_systems(Last, time_update)
        .add_systems(
            Update,
            (
                (take_remote_head, mirror_loop).chain(),
                note_arrival.after(avatarm_video::VideoSystems::Publish),
                // The frame erased in this update, with the camera it was drawn from.
                publish_erased
                    .after(avatarm_erase::EraseSystems::Prepare)
                    .after(note_arrival),
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

/// Once per update, right after its fixed steps: the site's clock minus the app's (s), the
/// fixed clock as this update's live inputs are stamped with it (a camera's frames,
/// `avatarm_video::threaded`). Bevy sets its clocks from the instant the render world's previous
/// frame ended (pipelined rendering), 25-50 ms before an update's systems run on this machine;
/// converting from that instant (as before) put the camera's frames that much earlier than the
/// joint states on the site's clock, and the latencies measured from them that much longer. One
/// value for every stamp converted in an update, so that they keep their order. It changes
/// between updates when the app's clock falls behind the wall's (an update longer than Bevy's
/// largest step).
fn note_site_clock(mut video: ResMut<ServeVideo>, fixed: Res<Time<Fixed>>) {
    video.site_minus_app = video.options.clock.now_s() - fixed.elapsed_secs_f64();
}

/// The loop's joint states into the room's arm and the app's twin (their stamps moved to the
/// app's clock), the real object where the arm holds it.
#[allow(clippy::too_many_arguments)] // a Bevy system: each argument is a parameter it reads
fn mirror_loop(
    video: Res<ServeVideo>,
    twin: Option<Res<AppTwin>>,
    room: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    mut states: MessageWriter<JointStateMessage>,
    mut parts: Query<(&SimPropPart, &mut Transform)>,
) {
    let site_minus_app = video.site_minus_app;
    let updates: Vec<ArmUpdate> = match video.options.updates.lock() {
        Ok(rx) => rx.try_iter().collect(),
        Err(_) => return,
    };
    let Some(last) = updates.last() else { return };
    robot
        .0
        .place_at(&last.state.positions, last.state.stamp_s - site_minus_app);
    if let Some(twin) = twin {
        twin.send(
            &mut states,
            &room.model,
            updates.iter().map(|u| &u.state),
            site_minus_app,
        );
    }
    if let (Some(centre), Some((prop, centre_to_base))) = (last.object, video.carried) {
        crate::teleop::place_prop(&mut parts, prop, &(centre * centre_to_base));
    }
}

/// A camera on a head: the wearer's head poses from the network into the scene's live head,
/// their stamps moved from the site's clock to the app's. A refused one (malformed, stamped
/// more than [`avatarm_net::msg::MAX_AHEAD_S`] ahead, not newer than the last) is counted and
/// logged (one line until a pose is taken again); the head then holds its last pose.
fn take_remote_head(mut video: ResMut<ServeVideo>, scene: Res<crate::SceneResource>) {
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
    let site_minus_app = video.site_minus_app;
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

/// How many published frames' arrivals are kept for their stamps.
const ARRIVALS_KEPT: usize = 32;

/// The frame published in this update: its index, its arrival and this update's number.
fn note_arrival(
    mut video: ResMut<ServeVideo>,
    live: Res<avatarm_video::LiveVideo>,
    frames: Res<bevy::diagnostic::FrameCount>,
) {
    if let Some(f) = live.frame.as_ref().filter(|_| live.fresh) {
        if video.arrivals.len() == ARRIVALS_KEPT {
            video.arrivals.pop_front();
        }
        video.arrivals.push_back((f.index, f.arrival_s, frames.0));
    }
}

/// Each newly erased frame, read back and handed to the encoder; its header stamped with when
/// it arrived and the updates it arrived and was handed over in.
#[allow(clippy::too_many_arguments)] // a Bevy system: each argument is a parameter it reads
fn publish_erased(
    mut reads: ResMut<DirectReadQueue>,
    mut video: ResMut<ServeVideo>,
    fixed: Res<Time<Fixed>>,
    state: Res<EraseState>,
    targets: Option<Res<EraseTargets>>,
    frames: Res<bevy::diagnostic::FrameCount>,
    settled: Option<Res<RenderSettled>>,
) {
    let (Some(targets), Some((t_s, index, _)), Some(settled)) = (
        targets,
        state
            .current
            .as_ref()
            .filter(|c| c.dirty)
            .and_then(|c| c.frame.clone()),
        settled,
    ) else {
        return;
    };
    if video.last_index == Some(index) {
        return;
    }
    video.last_index = Some(index);
    let counters = video.options.counters.clone();
    // The twin behind the mask has no joint state yet: its mask would be the scene's start
    // pose, not the robot's.
    if state.mask_stamp_s.is_none() {
        counters.unready.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let render_frame = RenderSettled::this_update_frame(&frames);
    if let Some(masks) = video.masks.clone() {
        let settled = settled.clone();
        let capture_s = t_s + video.site_minus_app;
        reads.0.push(DirectRead {
            image: targets.mask.clone(),
            frame: render_frame,
            deliver: Box::new(move |read| {
                if let (true, Ok(image)) = (settled.completed(render_frame), read) {
                    let _ = masks.send(MaskRead { capture_s, image });
                }
            }),
        });
    }
    let settled = settled.clone();
    let clock = video.options.clock;
    let site_minus_app = video.site_minus_app;
    let capture_s = t_s + site_minus_app;
    // A frame whose arrival is no longer kept (it cannot be: the erase draws the newest)
    // counts as arrived now.
    let (arrived_s, arrived_update) = video
        .arrivals
        .iter()
        .rev()
        .find(|a| a.0 == index)
        .map_or((fixed.elapsed_secs_f64(), frames.0), |a| (a.1, a.2));
    let arrived_s = arrived_s + site_minus_app;
    // The camera this frame's mask was drawn from (a camera on a head moves).
    let camera_pose = FrameHeader::pose_of(&state.camera_pose.unwrap_or(video.world_from_camera));
    let camera = video.options.camera.clone();
    let codec = video.options.encoder.codec.name();
    let tx = video.encoder.clone();
    let update = video.update.clone();
    let deliver = move |read: Result<avatarm_twin::readback::direct::ImageBytes, _>| {
        // Drawn while a pipeline compiled: a pass or a mesh may be missing (a black frame, or
        // the robot not erased). Noted before the read-back runs (the render graph's end).
        if !settled.completed(render_frame) {
            counters.unready.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let read = match read {
            Ok(r) => r,
            Err(e) => {
                counters.encode_errors.fetch_add(1, Ordering::Relaxed);
                warn!("robot site video: frame {index}: {e}");
                return;
            }
        };
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
            arrived_s,
            erased_s: clock.now_s(),
            arrived_update: u64::from(arrived_update),
            // The update the main world is in while the render thread hands it over.
            handed_update: update.load(Ordering::Relaxed),
            sent_s: f64::NAN,
            camera_pose,
        };
        let waited = header.handed_update.saturating_sub(header.arrived_update);
        counters
            .waited_updates_max
            .fetch_max(waited, Ordering::Relaxed);
        if waited > 1 {
            counters.handed_late.fetch_add(1, Ordering::Relaxed);
        }
        let _ = tx.send(Coded {
            header,
            rgba: read.data,
        });
    };
    reads.0.push(DirectRead {
        image: targets.composite.clone(),
        frame: render_frame,
        deliver: Box::new(deliver),
    });
}

/// The masks' thread (`--ros2-publish`): each mask read back (the newest where several
/// waited) coded as a PNG of 0 and 255 and published, stamped with its frame's capture on the
/// system clock, until the app is gone.
fn publish_masks(
    rx: &Receiver<MaskRead>,
    sink: &crate::net::ros2_out::Ros2Sink,
    to_unix: crate::net::ros2_out::SiteToUnix,
) {
    let mut said = false;
    while let Ok(mut read) = rx.recv() {
        while let Ok(newer) = rx.try_recv() {
            read = newer;
        }
        let MaskRead { capture_s, image } = read;
        let mask: Vec<u8> = image
            .data
            .iter()
            .step_by(image.bytes_per_pixel.max(1))
            .copied()
            .collect();
        match crate::session::mask_png(image.width, image.height, &mask) {
            Ok(png) => {
                crate::net::ros2_out::publish_mask(sink, to_unix.stamp_ns(capture_s), png);
            }
            Err(e) if !said => {
                said = true;
                warn!(
                    "robot site: a mask for ROS 2 does not code: {e} (further ones are not said)"
                );
            }
            Err(_) => {}
        }
    }
}

/// The main world's update number (its frame count) for the render thread's stamps, and when
/// the update began.
fn count_update(mut video: ResMut<ServeVideo>, frames: Res<bevy::diagnostic::FrameCount>) {
    video.update.store(u64::from(frames.0), Ordering::Relaxed);
    video.update_started = Some(std::time::Instant::now());
}

/// The main world's time in this update, counted.
fn time_update(video: Res<ServeVideo>) {
    let Some(started) = video.update_started else {
        return;
    };
    let counters = &video.options.counters;
    counters.updates.fetch_add(1, Ordering::Relaxed);
    if let Ok(mut times) = counters.update_ms.lock() {
        if times.len() == UPDATE_TIMES_KEPT {
            times.pop_front();
        }
        times.push_back(started.elapsed().as_secs_f64() * 1e3);
    }
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
    ros2: Option<(
        &crate::net::ros2_out::Ros2Sink,
        crate::net::ros2_out::SiteToUnix,
    )>,
) {
    let jpeg = settings.codec == avatarm_net::msg::Codec::Jpeg;
    if ros2.is_some() && !jpeg {
        warn!(
            "robot site video: --ros2-publish publishes the network's JPEG frames; with --codec h264 no erased frame goes to ROS 2 (use --codec jpeg)"
        );
    }
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
        if let Some((sink, to_unix)) = ros2.filter(|_| jpeg) {
            // The capture on the system clock, as its mask's.
            crate::net::ros2_out::publish_erased(
                sink,
                to_unix.stamp_ns(header.capture_s),
                coded.bytes.clone(),
            );
        }
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
