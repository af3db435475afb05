//! Where the background H comes from, per the scene's `[background]`: the simulated empty
//! room, a file, or the live frame at a given time. The preview's key and the CLI send
//! [`CaptureBackground`] for a capture on command.

use std::sync::Arc;

use avatarm_core::rng::Rng;
use avatarm_erase::{CaptureBackground, SetBackground};
use avatarm_sim::{SimCameras, SimRobotState};
use avatarm_twin::camera::RenderSettled;
use avatarm_twin::readback::{ImageRead, read_image_once};
use bevy::diagnostic::FrameCount;
use bevy::prelude::*;

use crate::{AppError, AvatarmSystems, SceneResource};
use avatarm_scene::spec::BackgroundSpec;

/// Sets the background from the scene's `[background]`. The simulated empty room is
/// photographed once its render is complete: renderers compile pipelines over a varying number
/// of frames, and a capture taken before that is black or misses meshes.
pub struct BackgroundSourcePlugin;

/// Updates after which the newest empty-room capture is used even if no render completed.
const EMPTY_ROOM_GIVE_UP: u32 = 240;

impl Plugin for BackgroundSourcePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<BackgroundProgress>()
            .add_systems(Startup, load_file)
            .add_systems(
                Update,
                (empty_room, capture_at)
                    .chain()
                    .in_set(AvatarmSystems::Background),
            );
    }
}

/// An empty-room capture: width, height, RGBA8, and the pose it was taken from (a camera on a
/// head).
type EmptyRoomCapture = (u32, u32, Vec<u8>, Option<nalgebra::Isometry3<f64>>);

/// How far the scene's background source has got.
#[derive(Resource, Debug, Default)]
pub struct BackgroundProgress {
    updates: u32,
    captured: bool,
    in_flight: bool,
    /// The newest empty-room capture of an incomplete render (before the sensor model), with
    /// its camera pose for a camera on a head.
    last: Option<EmptyRoomCapture>,
    /// The empty room has been set as the background (or the scene uses another source).
    pub empty_room_done: bool,
}

impl BackgroundProgress {
    /// Where a camera switched to at `now_s` (app clock) starts: from the beginning, except a
    /// capture whose time has passed, which is not taken (the robot is in view by then: B
    /// captures one).
    pub(crate) fn after_switch(scene: &avatarm_scene::Scene, now_s: f64) -> Self {
        let passed =
            matches!(scene.file.background, BackgroundSpec::Capture { at_s } if at_s <= now_s);
        if passed {
            info!(
                "background: the capture time has passed for this camera; press B with the robot out of view to capture one"
            );
        }
        Self {
            captured: passed,
            ..default()
        }
    }
}

/// Loads an image file as RGBA8.
pub fn load_rgba(path: &std::path::Path) -> Result<(u32, u32, Vec<u8>), AppError> {
    let img = image::open(path).map_err(|source| AppError::Image {
        path: path.to_owned(),
        action: "read",
        source,
    })?;
    let rgba = img.to_rgba8();
    Ok((rgba.width(), rgba.height(), rgba.into_raw()))
}

/// Sends the scene's `[background]` image file as H, if it names one. Runs at start-up, and
/// again after a camera switch (the next camera's background).
pub(crate) fn load_file(scene: Res<SceneResource>, mut out: MessageWriter<SetBackground>) {
    let Some(path) = &scene.0.background_path else {
        return;
    };
    match load_rgba(path) {
        Ok((width, height, rgba)) => {
            out.write(SetBackground {
                rgba: Arc::new(rgba),
                width,
                height,
                origin: path.display().to_string(),
                camera_pose: None,
                one_view: true,
            });
        }
        Err(e) => error!("background: {e}; the robot is not erased until one is set"),
    }
}

/// The simulated room without the robot, through the camera's sensor model at t = 0 (as if
/// photographed before the robot was installed): the first capture of a render that ended with
/// every pipeline compiled ([`RenderSettled`]) and is not black, with the pose it was taken
/// from (a camera on a head: where the head was then, with the mount the app believes). One
/// capture in flight at a time.
fn empty_room(
    mut commands: Commands,
    scene: Res<SceneResource>,
    cameras: Option<Res<SimCameras>>,
    mut progress: ResMut<BackgroundProgress>,
    (robot, frame): (Option<Res<SimRobotState>>, Res<FrameCount>),
) {
    if scene.0.file.background != BackgroundSpec::EmptyRoom {
        progress.empty_room_done = true;
        return;
    }
    if progress.empty_room_done || progress.in_flight {
        return;
    }
    progress.updates += 1;
    let Some(handle) = cameras.and_then(|c| c.no_robot.clone()) else {
        warn_once!("background: the empty room needs the simulated room's no-robot view");
        return;
    };
    if progress.updates >= EMPTY_ROOM_GIVE_UP
        && let Some((width, height, rgba, pose)) = progress.last.take()
    {
        warn!(
            "background: the empty room's render did not complete in {EMPTY_ROOM_GIVE_UP} \
             updates; using the newest capture"
        );
        progress.empty_room_done = true;
        commands.queue(move |world: &mut World| {
            send_empty_room(world, width, height, rgba, pose);
        });
        return;
    }
    progress.in_flight = true;
    let t = robot.map_or(0.0, |r| r.0.time_s());
    let pose = scene.0.head.as_ref().map(|h| h.believed_camera_at(t));
    let requested = RenderSettled::this_update_frame(&frame);
    read_image_once(&mut commands, handle.clone()).observe(
        move |read: On<ImageRead>,
              mut commands: Commands,
              settled: Res<RenderSettled>,
              cameras: Option<Res<SimCameras>>,
              mut progress: ResMut<BackgroundProgress>| {
            // A capture through a camera the app no longer looks through (a switch since).
            if cameras.is_none_or(|c| c.no_robot.as_ref() != Some(&handle)) {
                return;
            }
            progress.in_flight = false;
            let rgba = read.data.clone();
            // A render with no mesh drawn yet is black: not a room.
            if rgba.chunks_exact(4).all(|px| px[..3] == [0, 0, 0]) || progress.empty_room_done {
                return;
            }
            let (width, height) = (read.width, read.height);
            if !settled.completed(requested) {
                progress.last = Some((width, height, rgba, pose));
                return;
            }
            progress.empty_room_done = true;
            commands.queue(move |world: &mut World| {
                send_empty_room(world, width, height, rgba, pose);
            });
        },
    );
}

fn send_empty_room(
    world: &mut World,
    width: u32,
    height: u32,
    rgba: Vec<u8>,
    camera_pose: Option<nalgebra::Isometry3<f64>>,
) {
    let Some(scene) = world.get_resource::<SceneResource>() else {
        return;
    };
    // The photograph through the camera's lens.
    let Some(cameras) = world.get_resource::<SimCameras>() else {
        return;
    };
    let (width, height, mut rgba) = match cameras.camera_image((width, height, 4), rgba, false) {
        Ok(image) => image,
        Err(e) => {
            error!("background: the empty room: {e}");
            return;
        }
    };
    let sensor = scene.0.file.camera.sensor.clone();
    let seed = scene.0.file.seed;
    sensor.apply(&mut rgba, 0.0, &mut Rng::stream(seed, u64::MAX));
    world.write_message(SetBackground {
        rgba: Arc::new(rgba),
        width,
        height,
        origin: "the simulated empty room".into(),
        camera_pose,
        one_view: true,
    });
}

fn capture_at(
    scene: Res<SceneResource>,
    time: Res<Time<Fixed>>,
    live: Res<avatarm_video::LiveVideo>,
    mut progress: ResMut<BackgroundProgress>,
    mut out: MessageWriter<CaptureBackground>,
) {
    if let BackgroundSpec::Capture { at_s } = scene.0.file.background
        && !progress.captured
        && time.elapsed_secs_f64() >= at_s
        && live.fresh
    {
        progress.captured = true;
        out.write(CaptureBackground);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// After a camera switch a capture whose time has passed is not taken (the robot is in
    /// view); one still to come is.
    #[test]
    fn a_switch_takes_no_capture_whose_time_has_passed() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets/scenes/pouring_two_views.toml");
        let mut scene = avatarm_scene::Scene::load(&path, &Default::default()).expect("scene");
        scene.file.background = BackgroundSpec::Capture { at_s: 1.0 };
        assert!(BackgroundProgress::after_switch(&scene, 2.0).captured);
        assert!(!BackgroundProgress::after_switch(&scene, 0.5).captured);
        scene.file.background = BackgroundSpec::EmptyRoom;
        let p = BackgroundProgress::after_switch(&scene, 2.0);
        assert!(!p.captured && !p.empty_room_done);
    }
}
