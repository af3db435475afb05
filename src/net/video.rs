//! The robot site's erased video (`avatarm serve`, video on): the app runs headless in real
//! time; the simulated room's arm (and the app's twin behind the mask) follow the control
//! loop's joint states ([`super::serve::ArmUpdate`]), the real object where the arm carries
//! it. Each erased frame is read back once, coded as JPEG on a thread of its own and
//! published with its stage stamps (capture, erased, sent; the site's clock).
//!
//! The read-back is the one the live path gets for the network, as `--record` gets one for
//! the disk.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

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

use super::serve::ArmUpdate;
use crate::AppTwin;

/// JPEG quality of the published frames.
pub const JPEG_QUALITY: u8 = 85;

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
    /// Frames published so far.
    pub published: Arc<AtomicU64>,
}

impl std::fmt::Debug for ServeVideoOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServeVideoOptions")
            .field("camera", &self.camera)
            .finish_non_exhaustive()
    }
}

/// The robot site's video: mirrors the loop into the room, publishes erased frames.
pub struct ServeVideoPlugin(pub ServeVideoOptions);

#[derive(Resource)]
struct ServeVideo {
    options: ServeVideoOptions,
    encoder: Sender<Coded>,
    last_index: Option<u64>,
    carried: Option<(usize, Isometry3<f64>)>,
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
        let published = options.published.clone();
        let _ = std::thread::Builder::new()
            .name("video encoder".into())
            .spawn(move || encode_and_send(rx, sender, clock, published));
        let carried = app
            .world()
            .get_resource::<crate::SceneResource>()
            .and_then(|s| carried_object(&s.0));
        if let Some(mut room) = app.world_mut().get_resource_mut::<SimRoomConfig>() {
            room.external_drive = true;
        }
        app.insert_resource(ServeVideo {
            options,
            encoder: tx,
            last_index: None,
            carried,
        })
        .add_systems(Update, (mirror_loop, publish_erased, stop_when_done));
    }
}

/// The carried prop's index and its base pose from its centre (the pose the loop reports).
fn carried_object(scene: &Scene) -> Option<(usize, Isometry3<f64>)> {
    let task = scene.file.task.as_ref()?;
    let setup = scene.trial.as_ref()?;
    let (prop, _) = find_prop(&scene.props, &task.object)?;
    Some((prop, setup.bottle_centre().inverse() * setup.bottle_base))
}

/// The loop's joint states into the room's arm and the app's twin (their stamps moved to the
/// app's clock), the real object where the arm holds it.
fn mirror_loop(
    video: Res<ServeVideo>,
    time: Res<Time>,
    twin: Option<Res<AppTwin>>,
    room: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    mut states: MessageWriter<JointStateMessage>,
    mut parts: Query<(&SimPropPart, &mut Transform)>,
) {
    let site_minus_app = video.options.clock.now_s() - time.elapsed_secs_f64();
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

/// Each newly erased frame, read back and handed to the encoder.
fn publish_erased(
    mut commands: Commands,
    mut video: ResMut<ServeVideo>,
    time: Res<Time>,
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
    let capture_s = clock.now_s() - (time.elapsed_secs_f64() - t_s);
    let camera = video.options.camera.clone();
    let tx = video.encoder.clone();
    read_image_once(&mut commands, targets.composite.clone()).observe(
        move |read: On<ImageRead>| {
            let header = FrameHeader {
                v: PROTOCOL_VERSION,
                camera: camera.clone(),
                index,
                codec: "jpeg".into(),
                width: read.width,
                height: read.height,
                capture_s,
                erased_s: clock.now_s(),
                sent_s: f64::NAN,
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

/// The encoder's thread: RGBA → JPEG → the network, newest first (a frame that waited behind
/// a newer one is dropped: late video is useless).
fn encode_and_send(
    rx: Receiver<Coded>,
    sender: FrameSender,
    clock: SiteClock,
    published: Arc<AtomicU64>,
) {
    while let Ok(mut frame) = rx.recv() {
        while let Ok(newer) = rx.try_recv() {
            frame = newer;
        }
        let Coded { mut header, rgba } = frame;
        let Some(img) = image::RgbaImage::from_raw(header.width, header.height, rgba) else {
            continue;
        };
        let rgb = image::DynamicImage::ImageRgba8(img).to_rgb8();
        let mut bytes = Vec::new();
        let mut encoder =
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, JPEG_QUALITY);
        if encoder.encode_image(&rgb).is_err() {
            continue;
        }
        header.sent_s = clock.now_s();
        match sender.send(&header, bytes) {
            Ok(()) => {
                published.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => warn!("robot site video: {e}"),
        }
    }
}
