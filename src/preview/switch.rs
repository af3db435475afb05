//! Looking through another of the scene's cameras without starting again (the preview's **C**).
//!
//! The app erases one camera at a time (docs/architecture.md, "Several cameras in one app").
//! A switch keeps everything the cameras share — the simulated room and its clock, the robot
//! and its joint history, the app's twin, the live task, the hand and the objects where they are
//! — and replaces what is one camera's: every entity marked [`CameraBound`] (the room's views,
//! the mask twin and erase pipeline, the interaction camera, panel and object twins, the XR
//! panel) is despawned, the one-camera resources are set for the next camera, and the plugins'
//! start-up systems spawn its views again. Its background starts again from its own source
//! (file, empty room or capture; a capture whose time has passed is left to B); a
//! view-following background's kept views start empty.

use avatarm_erase::{EraseConfig, EraseState, InteractionConfig};
use avatarm_scene::Scene;
use avatarm_sim::{SimRoomConfig, VideoCounter};
use avatarm_twin::CameraBound;
use avatarm_video::VideoInbox;
use bevy::ecs::system::RunSystemOnce;
use bevy::prelude::*;

use crate::app::{
    SceneResource, background, erase_config, head_tracking, interaction_config, live_video,
    sim_head, sim_video,
};

/// The scene seen through each of its cameras (the file's order), and the one looked through.
#[derive(Resource, Debug, Clone)]
pub struct CameraViews {
    /// One scene per camera, each as [`Scene::load_view`] gives it (with the command line's
    /// changes applied alike).
    pub scenes: Vec<Scene>,
    /// Index into `scenes` of the camera looked through now.
    pub current: usize,
}

impl CameraViews {
    /// The camera after the current one (after the last, the first).
    pub fn next(&self) -> usize {
        (self.current + 1) % self.scenes.len().max(1)
    }
}

/// Asks the app to look through camera `0` (an index into [`CameraViews::scenes`]); done at
/// the next update's start ([`CameraSwitchPlugin`]).
#[derive(Message, Debug, Clone, Copy, PartialEq, Eq)]
pub struct SwitchCamera(pub usize);

/// Switches cameras in place on [`SwitchCamera`]: in `PreUpdate`, so the update that follows
/// already erases through the next camera.
pub struct CameraSwitchPlugin(pub CameraViews);

impl Plugin for CameraSwitchPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(self.0.clone())
            .add_message::<SwitchCamera>()
            .add_systems(PreUpdate, take_switch);
    }
}

fn take_switch(mut asked: MessageReader<SwitchCamera>, mut commands: Commands) {
    // Several presses in one update: the last wins.
    if let Some(&SwitchCamera(index)) = asked.read().last() {
        commands.queue(move |world: &mut World| {
            if let Err(e) = switch_camera(world, index) {
                error!(
                    "camera switch: {e}; the panel may show no camera until the app starts again"
                );
            }
        });
    }
}

/// Why a camera switch did not happen ([`switch_camera`]).
#[derive(Debug, thiserror::Error)]
pub enum SwitchError {
    /// The app was built without [`CameraViews`] (one camera).
    #[error("the app has no cameras to switch between")]
    NoViews,
    /// An index past the scene's cameras.
    #[error("camera {index} asked for; the scene has {cameras}")]
    NoCamera {
        /// The index asked for.
        index: usize,
        /// The scene's cameras.
        cameras: usize,
    },
    /// A start-up system of the next camera's views could not run again.
    #[error("{what}: {message}")]
    Startup {
        /// The plugin whose start-up failed (`the room's views`, `the erase pipeline`, ...).
        what: &'static str,
        /// Bevy's error.
        message: String,
    },
}

/// Looks through camera `index` of [`CameraViews`] from now on (see the module's docs). Errors
/// name what is missing: no [`CameraViews`], an index past the scene's cameras, or a start-up
/// system that could not run again.
pub fn switch_camera(world: &mut World, index: usize) -> Result<(), SwitchError> {
    let Some(views) = world.get_resource::<CameraViews>() else {
        return Err(SwitchError::NoViews);
    };
    let Some(scene) = views.scenes.get(index).cloned() else {
        return Err(SwitchError::NoCamera {
            index,
            cameras: views.scenes.len(),
        });
    };
    if index == views.current {
        return Ok(());
    }
    let started = std::time::Instant::now();
    // The views of the camera looked through until now.
    let bound: Vec<Entity> = world
        .query_filtered::<Entity, With<CameraBound>>()
        .iter(world)
        .collect();
    for entity in bound {
        // A child of another bound entity is gone with its parent already.
        if let Ok(e) = world.get_entity_mut(entity) {
            e.despawn();
        }
    }
    // The next camera's settings; the shared state stays.
    if let Some(mut room) = world.get_resource_mut::<SimRoomConfig>() {
        room.camera = scene.true_camera;
        room.distortion = scene.lens;
        if room.video.is_some() {
            room.video = Some(sim_video(&scene));
        }
        room.head = sim_head(&scene);
    }
    let (source_twin, enabled) = world
        .get_resource::<EraseConfig>()
        .map_or((None, true), |c| (c.source_twin, c.settings.enabled));
    let mut erase = erase_config(&scene);
    erase.source_twin = source_twin;
    // Erasure toggled off (E) stays off.
    erase.settings.enabled &= enabled;
    let mut interaction = interaction_config(&scene);
    if let Some(now) = world.get_resource::<InteractionConfig>() {
        // Where the objects are now (the live task moves the one the hand holds).
        interaction.objects.clone_from(&now.objects);
    }
    world.insert_resource(erase);
    world.insert_resource(interaction);
    // A new pipeline's state; the counters go on over the whole run.
    let mut state = EraseState::default();
    if let Some(now) = world.get_resource::<EraseState>() {
        (state.renders, state.frames_in, state.frames_refused) =
            (now.renders, now.frames_in, now.frames_refused);
    }
    world.insert_resource(state);
    // A background the camera left sent in its last update (an empty-room capture that came
    // back then) is not the next camera's.
    if let Some(mut m) = world.get_resource_mut::<Messages<avatarm_erase::SetBackground>>() {
        m.clear();
    }
    if let Some(mut m) = world.get_resource_mut::<Messages<avatarm_erase::CaptureBackground>>() {
        m.clear();
    }
    let now_s = world
        .get_resource::<Time<Fixed>>()
        .map_or(0.0, Time::elapsed_secs_f64);
    let mut live = live_video(&scene, &crate::app::CameraSource::Simulated);
    // Stale counts from the switch, not from the run's start.
    live.last_publish_s = Some(now_s);
    world.insert_resource(live);
    world.insert_resource(VideoInbox::default());
    world.insert_resource(head_tracking(&scene));
    world.insert_resource(background::BackgroundProgress::after_switch(&scene, now_s));
    world.remove_resource::<VideoCounter>();
    let left = world
        .get_resource::<SceneResource>()
        .map_or_else(String::new, |s| s.0.camera_name().to_owned());
    // The live scores of the camera left, for the log.
    let mut scores = String::new();
    if let Some(mut live) = world.get_resource_mut::<crate::preview::live_scores::LiveDr>() {
        if let Some((iou, leak, psnr)) = live.means() {
            scores = format!(
                "; '{left}' scored live: IoU {iou:.3}, leak {leak:.2} %, PSNR {} dB over its last {} frames",
                psnr.map_or("-".to_owned(), |p| format!("{p:.1}")),
                live.recent.len()
            );
        }
        live.restart();
    }
    let name = scene.camera_name().to_owned();
    world.insert_resource(SceneResource(scene));
    // The next camera's views, in start-up's order (each applies its commands before the next
    // reads what it inserted).
    let failed = |what: &'static str, e: &dyn std::fmt::Display| SwitchError::Startup {
        what,
        message: e.to_string(),
    };
    world
        .run_system_once(avatarm_sim::spawn_camera_views)
        .map_err(|e| failed("the room's views", &e))?;
    world
        .run_system_once(avatarm_erase::spawn_pipeline)
        .map_err(|e| failed("the erase pipeline", &e))?;
    world
        .run_system_once(avatarm_erase::interaction::spawn_interaction)
        .map_err(|e| failed("the interaction layer", &e))?;
    world
        .run_system_once(background::load_file)
        .map_err(|e| failed("the background", &e))?;
    let mut views = world.resource_mut::<CameraViews>();
    views.current = index;
    let t = world
        .get_resource::<avatarm_sim::SimRobotState>()
        .map_or(f64::NAN, |r| r.0.time_s());
    // The time the switch itself took (its views' GPU resources are made in the next render).
    let ms = started.elapsed().as_secs_f64() * 1e3;
    info!("camera: now '{name}' (switched in place at sim {t:.2} s, in {ms:.0} ms{scores})");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A switch with nothing to switch between, or to a camera the scene does not have, says
    /// so and changes nothing.
    #[test]
    fn a_switch_to_a_camera_that_is_not_there_is_refused() {
        let mut world = World::new();
        let e = switch_camera(&mut world, 1).expect_err("no views");
        assert!(matches!(e, SwitchError::NoViews), "{e}");
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets/scenes/pouring_two_views.toml");
        let scene = |v| Scene::load_view(&path, &Default::default(), Some(v)).expect("scene");
        let views = CameraViews {
            scenes: vec![scene("blair"), scene("alice")],
            current: 0,
        };
        assert_eq!(views.next(), 1);
        world.insert_resource(views);
        let e = switch_camera(&mut world, 2).expect_err("past the end");
        assert!(
            e.to_string()
                .contains("camera 2 asked for; the scene has 2"),
            "{e}"
        );
        // To the camera looked through: nothing to do.
        switch_camera(&mut world, 0).expect("same camera");
        let views = world.resource::<CameraViews>();
        assert_eq!(views.current, 0);
    }
}
