//! Avatarm: manipulate real objects through a robot arm that is hidden from view.
//!
//! This crate is the application: scene files ([`scene`]), the app assembled from the plugins
//! ([`build_app`]), the desktop preview ([`preview`]), headless scene replay with its report
//! ([`replay`]) and the `avatarm robot` description check ([`robot_info`]). The binary
//! `avatarm` is a thin command line over these.

pub mod bench;
pub mod bench_control;
pub mod live_dr;
pub mod preview;
pub mod replay;
pub mod robot_info;
pub mod scene;
pub mod session;
pub mod task;
pub mod teleop;
#[cfg(feature = "xr")]
pub mod xr;

use std::time::Duration;

use avatarm_erase::interaction::ObjectTwinSpec;
use avatarm_erase::{EraseConfig, ErasePlugin, InteractionConfig, InteractionPlugin};
use avatarm_sim::{SimRoomConfig, SimRoomPlugin, SimVideo};
use avatarm_twin::prelude::*;
use avatarm_twin::{TwinMeshCache, layers};
use avatarm_video::{LiveVideo, VideoPlugin};
use bevy::app::ScheduleRunnerPlugin;
use bevy::camera::visibility::RenderLayers;
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::time::TimeUpdateStrategy;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;

use crate::scene::Scene;

/// How the app runs.
#[derive(Debug, Clone)]
pub enum Mode {
    /// A window with the camera feed and the twin.
    Preview(preview::PreviewOptions),
    /// No window: replay the scene on a fixed timestep and write frames and a report.
    Headless(replay::ReplayOptions),
}

/// The app's own twin of the robot (what the app believes, from received joint states).
#[derive(Resource, Debug, Clone, Copy)]
pub struct AppTwin(pub Entity);

/// The scene being run.
#[derive(Resource, Debug, Clone)]
pub struct SceneResource(pub Scene);

/// Builds the app for a scene; shared by `main` and the tests.
pub fn build_app(scene: &Scene, mode: &Mode) -> App {
    let mut app = App::new();
    let frame_dt = Duration::from_secs_f64(1.0 / scene.file.camera.fps);
    match mode {
        Mode::Headless(_) => {
            app.add_plugins((
                DefaultPlugins
                    .set(WindowPlugin {
                        primary_window: None,
                        exit_condition: ExitCondition::DontExit,
                        ..default()
                    })
                    .set(RenderPlugin {
                        synchronous_pipeline_compilation: true,
                        ..default()
                    })
                    .disable::<WinitPlugin>(),
                ScheduleRunnerPlugin::run_loop(Duration::ZERO),
            ))
            .insert_resource(TimeUpdateStrategy::ManualDuration(frame_dt));
        }
        Mode::Preview(options) => {
            let window = Window {
                title: format!("Avatarm — {}", scene.file.name),
                resolution: (1280u32, 720u32).into(),
                ..default()
            };
            let plugins = DefaultPlugins.set(WindowPlugin {
                primary_window: Some(window),
                ..default()
            });
            add_window_plugins(&mut app, plugins, options.xr);
            if let Some(step) = options.fixed_step_s {
                app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
                    step,
                )));
            }
        }
    }
    let webcam = match mode {
        Mode::Preview(options) => options.webcam,
        Mode::Headless(_) => None,
    };
    #[cfg(feature = "webcam")]
    if let Some(index) = webcam {
        let k = &scene.true_camera.intrinsics;
        app.add_plugins(avatarm_video::webcam::WebcamPlugin(
            avatarm_video::webcam::WebcamConfig {
                index,
                width: k.width,
                height: k.height,
                fps: scene.file.camera.fps.round().max(1.0) as u32,
                latency_s: scene.file.camera.frame_latency_s,
            },
        ));
    }
    app.insert_resource(SceneResource(scene.clone()))
        .insert_resource(SimRoomConfig {
            model: scene.model.clone(),
            robot_base: scene.robot_base(),
            robot: scene.file.robot.sim,
            q0: scene.q0.clone(),
            trajectory: scene.trajectory.clone(),
            control_rate_hz: scene.file.control_rate_hz,
            camera: scene.true_camera,
            props: scene.props.clone(),
            // The no-robot view also gives the simulated "empty room" background.
            ground_truth: matches!(mode, Mode::Headless(_))
                || scene.file.background == scene::BackgroundSpec::EmptyRoom,
            twin: None,
            video: webcam.is_none().then(|| SimVideo {
                sensor: scene.file.camera.sensor.clone(),
                frame_latency_s: scene.file.camera.frame_latency_s,
                seed: scene.file.seed,
                fps: scene.file.camera.fps,
            }),
            external_drive: false,
        })
        .insert_resource(LiveVideo::new(
            match webcam {
                Some(i) => format!("webcam {i}"),
                None => "simulated camera".to_owned(),
            },
            (3.0 / scene.file.camera.fps).max(0.2) + scene.file.camera.frame_latency_s,
        ))
        .insert_resource(EraseConfig {
            settings: scene.file.erase,
            camera: scene.believed_camera,
            model: scene.model.clone(),
            base: scene.robot_base(),
            source_twin: None,
            occluders: scene
                .file
                .props
                .iter()
                .zip(&scene.props)
                .filter(|(spec, _)| spec.occluder)
                .flat_map(|(_, prop)| {
                    avatarm_sim::prop_parts(&prop.shape)
                        .into_iter()
                        .map(|(mesh, local)| (mesh, iso_to_transform(&prop.pose) * local))
                })
                .collect(),
        })
        .insert_resource(InteractionConfig {
            camera: scene.believed_camera,
            real_camera: scene.believed_camera,
            panel_distance_m: scene.file.interaction.panel_distance_m,
            object_depth_m: scene.file.interaction.object_depth_m,
            objects: scene
                .file
                .props
                .iter()
                .zip(&scene.props)
                .filter(|(spec, _)| spec.object)
                .map(|(_, prop)| ObjectTwinSpec {
                    name: prop.name.clone(),
                    parts: avatarm_sim::prop_parts(&prop.shape),
                    world_from_object: prop.pose,
                    rgba: prop.rgba,
                })
                .collect(),
        })
        .add_plugins((
            RobotTwinPlugin,
            // Before the room (which adds it too when alone): the replay, the live scores and
            // the empty-room background read images back with it.
            avatarm_twin::readback::ImageReadbackPlugin,
            SimRoomPlugin,
            VideoPlugin,
            ErasePlugin,
            InteractionPlugin,
            session::BackgroundSourcePlugin,
        ))
        .add_systems(PreStartup, spawn_app_twin);
    match mode {
        Mode::Headless(options) => {
            app.add_plugins(replay::ReplayPlugin(options.clone()));
        }
        Mode::Preview(options) => {
            app.add_plugins(preview::PreviewPlugin(options.clone()));
            if webcam.is_none() && scene.file.background == scene::BackgroundSpec::EmptyRoom {
                // The room renders its ground truth anyway (the empty room is H): score
                // two frames a second against it.
                let every = (scene.file.camera.fps / 2.0).round().max(1.0) as u64;
                app.add_plugins(live_dr::LiveDrPlugin { every });
            }
            #[cfg(feature = "xr")]
            if options.xr {
                app.add_plugins(xr::XrViewPlugin);
            }
            if let Some(choice) = &options.hand
                && let Err(e) = teleop::add_live_teleop(&mut app, scene, choice)
            {
                error!("live teleoperation: {e}; the preview runs without it");
            }
        }
    }
    app
}

#[cfg(feature = "xr")]
fn add_window_plugins(app: &mut App, plugins: bevy::app::PluginGroupBuilder, xr: bool) {
    if xr {
        // Falls back to the flat renderer, with a log line, when no OpenXR runtime is present.
        app.add_plugins(bevy_mod_openxr::add_xr_plugins(plugins));
    } else {
        app.add_plugins(plugins);
    }
}

#[cfg(not(feature = "xr"))]
fn add_window_plugins(app: &mut App, plugins: bevy::app::PluginGroupBuilder, xr: bool) {
    if xr {
        warn!("--xr: this build has no OpenXR support (feature `xr`); using the desktop preview");
    }
    app.add_plugins(plugins);
}

/// Spawns the app's twin on the twin layer and points the simulated room's joint states at it.
fn spawn_app_twin(
    mut commands: Commands,
    mut config: ResMut<SimRoomConfig>,
    mut erase: ResMut<EraseConfig>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut cache: ResMut<TwinMeshCache>,
    mut exit: MessageWriter<AppExit>,
) {
    let twin = spawn_twin(&mut commands, config.model.clone(), &config.robot_base);
    if let Err(e) = attach_visuals(
        &mut commands,
        &mut meshes,
        &mut materials,
        &mut cache,
        &config.model,
        &twin,
        TwinAppearance::Urdf,
        GeometrySource::Visual,
        &RenderLayers::layer(layers::TWIN),
    ) {
        error!("{e}");
        exit.write(AppExit::error());
    }
    config.twin = Some(twin.root);
    erase.source_twin = Some(twin.root);
    commands.insert_resource(AppTwin(twin.root));
}
