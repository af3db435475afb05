//! Where the background H comes from, per the scene's `[background]`: the simulated empty
//! room, a file, or the live frame at a given time. The preview's key and the CLI send
//! [`CaptureBackground`] for a capture on command.

use std::sync::Arc;

use avatarm_core::rng::Rng;
use avatarm_erase::{CaptureBackground, SetBackground};
use avatarm_sim::SimCameras;
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};

use crate::SceneResource;
use crate::scene::BackgroundSpec;

/// Sets the background from the scene's `[background]`. `empty_room_updates` are the updates
/// on which the simulated empty room is photographed (later ones replace earlier ones, for
/// renderers that compile pipelines over several frames).
pub struct BackgroundSourcePlugin {
    /// Update numbers (1-based) of the empty-room captures.
    pub empty_room_updates: Vec<u32>,
}

impl Plugin for BackgroundSourcePlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(BackgroundProgress {
            updates: 0,
            captured: false,
            empty_room_updates: self.empty_room_updates.clone(),
        })
            .add_systems(Startup, load_file)
            .add_systems(Update, (empty_room, capture_at));
    }
}

#[derive(Resource, Debug, Default)]
struct BackgroundProgress {
    updates: u32,
    captured: bool,
    empty_room_updates: Vec<u32>,
}

/// Loads an image file as RGBA8.
pub fn load_rgba(path: &std::path::Path) -> Result<(u32, u32, Vec<u8>), String> {
    let img = image::open(path).map_err(|e| format!("{}: cannot read image: {e}", path.display()))?;
    let rgba = img.to_rgba8();
    Ok((rgba.width(), rgba.height(), rgba.into_raw()))
}

fn load_file(scene: Res<SceneResource>, mut out: MessageWriter<SetBackground>) {
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
            });
        }
        Err(e) => error!("background: {e}; the robot is not erased until one is set"),
    }
}

/// The simulated room without the robot, through the camera's sensor model at t = 0 (as if
/// photographed before the robot was installed).
fn empty_room(
    mut commands: Commands,
    scene: Res<SceneResource>,
    cameras: Option<Res<SimCameras>>,
    mut progress: ResMut<BackgroundProgress>,
) {
    if scene.0.file.background != BackgroundSpec::EmptyRoom {
        return;
    }
    progress.updates += 1;
    if !progress.empty_room_updates.contains(&progress.updates) {
        return;
    }
    let Some(handle) = cameras.and_then(|c| c.no_robot.clone()) else {
        warn!("background: the empty room needs the simulated room's no-robot view");
        return;
    };
    let sensor = scene.0.file.camera.sensor.clone();
    let seed = scene.0.file.seed;
    commands.spawn(Screenshot::image(handle)).observe(
        move |captured: On<ScreenshotCaptured>, mut out: MessageWriter<SetBackground>| {
            let image = &captured.image;
            let Some(mut rgba) = image.data.clone() else {
                return;
            };
            sensor.apply(&mut rgba, 0.0, &mut Rng::stream(seed, u64::MAX));
            out.write(SetBackground {
                rgba: Arc::new(rgba),
                width: image.width(),
                height: image.height(),
                origin: "the simulated empty room".into(),
            });
        },
    );
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
