//! The erase and interaction plugins without a renderer (`MinimalPlugins`): what they spawn on
//! which layers, when the passes render, which background they take, where the object twins
//! go. The rendered result is the replay tests' job (`tests/app/replay/`).

use std::path::Path;

use avatarm_core::robot::PackagePath;
use avatarm_core::vision::camera::{CameraPose, Intrinsics};
use avatarm_twin::RobotTwinPlugin;
use avatarm_video::{VideoFrame, VideoInbox, VideoPlugin};
use nalgebra::{Translation3, UnitQuaternion};

use super::*;
use crate::interaction::{ObjectTwin, ObjectTwinSpec};

const W: u32 = 32;
const H: u32 = 24;

fn camera() -> PinholeCamera {
    let pose = CameraPose {
        eye: [1.85, 0.0, 1.25],
        target: [0.4, 0.0, 0.95],
        up: [0.0, 0.0, 1.0],
    };
    PinholeCamera {
        intrinsics: Intrinsics::from_fov_y(55f64.to_radians(), W, H),
        world_from_camera: pose.to_isometry().expect("pose"),
    }
}

fn app(resolution_scale: f64) -> App {
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
    let model = Arc::new(RobotModel::from_urdf_file(&urdf, &PackagePath::default()).expect("urdf"));
    let bottle = Isometry3::from_parts(
        Translation3::new(0.6, 0.0, 0.75),
        UnitQuaternion::identity(),
    );
    let mut app = avatarm_twin::headless_app();
    app.insert_resource(avatarm_video::LiveVideo::new("test", 1.0))
        .insert_resource(EraseConfig {
            settings: EraseSettings {
                resolution_scale,
                ..EraseSettings::default()
            },
            camera: camera(),
            distortion: Default::default(),
            joint_map: JointMap::new(&model, &model),
            model,
            detail: TwinDetail::default(),
            base: Isometry3::translation(0.0, 0.0, 0.75),
            source_twin: None,
            occluders: vec![(Cuboid::new(1.0, 1.0, 0.05).into(), Transform::default())],
            head_mount: None,
            view_background: None,
        })
        .insert_resource(InteractionConfig {
            camera: camera(),
            real_camera: camera(),
            panel_distance_m: 2.5,
            object_depth_m: 1.0,
            objects: vec![ObjectTwinSpec {
                name: "bottle".into(),
                parts: vec![(Cylinder::new(0.035, 0.17).into(), Transform::default())],
                world_from_object: bottle,
                rgba: [0.2, 0.5, 0.9, 1.0],
            }],
        })
        .add_plugins((RobotTwinPlugin, VideoPlugin, ErasePlugin, InteractionPlugin));
    app
}

fn frame(index: u64, t_s: f64) -> VideoFrame {
    VideoFrame {
        index,
        capture_s: t_s,
        arrival_s: t_s,
        width: W,
        height: H,
        rgba: Arc::new(vec![90; (W * H * 4) as usize]),
    }
}

/// Whether the mask render and the passes run in this update, and what they upload.
fn pipeline(app: &mut App) -> (bool, bool, bool, bool) {
    let entity = app.world().resource::<ErasePipeline>().0;
    let view = app.world().get::<FlatView>(entity).expect("flat view");
    let job = app.world().get::<EraseJob>(entity).expect("erase job");
    (
        view.active,
        job.render,
        job.frame.is_some(),
        job.background.is_some(),
    )
}

#[test]
fn the_pipeline_spawns_its_twin_view_and_targets() {
    let mut app = app(0.5);
    app.update();
    // The mask twin in white and the occluder in black, alone on the mask twin's layer, drawn
    // flat (no material, no camera).
    let on_mask_layer: Vec<FlatPart> = app
        .world_mut()
        .query::<(
            &RenderLayers,
            &FlatPart,
            Option<&MeshMaterial3d<StandardMaterial>>,
        )>()
        .iter(app.world())
        .filter(|(l, _, _)| **l == RenderLayers::layer(layers::MASK_TWIN))
        .map(|(_, p, m)| {
            assert!(m.is_none(), "flat parts carry no material");
            *p
        })
        .collect();
    let white = on_mask_layer
        .iter()
        .filter(|p| **p == FlatPart::ROBOT)
        .count();
    let black = on_mask_layer
        .iter()
        .filter(|p| **p == FlatPart::OCCLUDER)
        .count();
    assert!(white >= 9, "every link with a visual, white: {white}");
    assert_eq!(black, 1, "the occluder, black");
    assert_eq!(
        app.world_mut()
            .query::<&Camera>()
            .iter(app.world())
            .filter(|c| c.order < -17)
            .count(),
        0,
        "no camera renders the mask or the passes"
    );
    // One view on that layer, rendering the raw target at the mask scale.
    let entity = app.world().resource::<ErasePipeline>().0;
    let view = app.world().get::<FlatView>(entity).expect("view").clone();
    let layer = app.world().get::<RenderLayers>(entity).expect("layer");
    assert_eq!(*layer, RenderLayers::layer(layers::MASK_TWIN));
    let targets = app.world().resource::<EraseTargets>().clone();
    assert_eq!(view.target, targets.raw);
    assert_eq!(
        (view.camera.intrinsics.width, view.camera.intrinsics.height),
        (W / 2, H / 2)
    );
    let images = app.world().resource::<Assets<Image>>();
    let format = |h: &Handle<Image>| {
        let i = images.get(h).expect("image");
        (i.width(), i.height(), i.texture_descriptor.format)
    };
    assert_eq!(format(&targets.raw), (W / 2, H / 2, TextureFormat::R8Unorm));
    assert_eq!(format(&targets.mask), (W, H, TextureFormat::R8Unorm));
    assert_eq!(
        format(&targets.composite),
        (W, H, TextureFormat::Rgba8UnormSrgb)
    );
    let composite = images.get(&targets.composite).expect("composite");
    assert_eq!(
        composite.texture_descriptor.view_formats,
        [TextureFormat::Rgba8Unorm],
        "written through a linear view"
    );
    let job = app.world().get::<EraseJob>(entity).expect("job");
    assert_eq!(job.params.raw_size, UVec2::new(W / 2, H / 2));
    assert_eq!(job.params.size, UVec2::new(W, H));
}

#[test]
fn the_passes_render_once_per_camera_frame() {
    let mut app = app(1.0);
    // The first update (new settings) renders, clearing the targets; the next brings nothing
    // new and renders nothing.
    app.update();
    assert_eq!(pipeline(&mut app), (true, true, false, false));
    app.update();
    assert_eq!(pipeline(&mut app), (false, false, false, false));
    // A frame arrives: the update that takes it uploads it and renders, the next one nothing.
    let now = app.world().resource::<Time<Fixed>>().elapsed_secs_f64();
    app.world_mut()
        .resource_mut::<VideoInbox>()
        .pending
        .push(frame(1, now));
    app.update();
    assert_eq!(pipeline(&mut app), (true, true, true, false));
    assert_eq!(app.world().resource::<EraseState>().frames_in, 1);
    app.update();
    assert_eq!(
        pipeline(&mut app),
        (false, false, false, false),
        "nothing new"
    );
    // A frame of the wrong size is refused and renders nothing.
    let now = app.world().resource::<Time<Fixed>>().elapsed_secs_f64();
    let mut bad = frame(2, now);
    bad.width = W / 2;
    bad.rgba = Arc::new(vec![0; (W / 2 * H * 4) as usize]);
    app.world_mut()
        .resource_mut::<VideoInbox>()
        .pending
        .push(bad);
    app.update();
    assert_eq!(pipeline(&mut app), (false, false, false, false));
    let state = app.world().resource::<EraseState>();
    assert_eq!((state.frames_in, state.frames_refused), (1, 1));
    assert_eq!(state.renders, 2, "once at start, once for the frame");
}

#[test]
fn a_new_background_is_uploaded_once_and_turns_the_composite_on() {
    let mut app = app(1.0);
    app.update();
    let alpha = |app: &mut App| {
        let entity = app.world().resource::<ErasePipeline>().0;
        app.world()
            .get::<EraseJob>(entity)
            .expect("job")
            .params
            .alpha_h
    };
    assert_eq!(alpha(&mut app), 0.0, "no H: nothing is replaced");
    app.world_mut().write_message(SetBackground {
        rgba: Arc::new(vec![200; (W * H * 4) as usize]),
        width: W,
        height: H,
        origin: "a file".into(),
        camera_pose: None,
        one_view: true,
    });
    app.update();
    assert_eq!(pipeline(&mut app), (true, true, false, true));
    assert_eq!(alpha(&mut app), 1.0);
    app.update();
    assert_eq!(
        pipeline(&mut app),
        (false, false, false, false),
        "uploaded once"
    );
}

#[test]
fn a_background_of_the_camera_size_is_taken_and_another_refused() {
    let mut app = app(1.0);
    app.update();
    app.world_mut().write_message(SetBackground {
        rgba: Arc::new(vec![0; 4]),
        width: 1,
        height: 1,
        origin: "too small".into(),
        camera_pose: None,
        one_view: true,
    });
    app.update();
    assert!(app.world().resource::<EraseState>().background.is_none());
    app.world_mut().write_message(SetBackground {
        rgba: Arc::new(vec![200; (W * H * 4) as usize]),
        width: W,
        height: H,
        origin: "a file".into(),
        camera_pose: None,
        one_view: true,
    });
    app.update();
    let state = app.world().resource::<EraseState>();
    assert!(state.background.is_some());
    assert_eq!(state.background_origin.as_deref(), Some("a file"));
}

#[test]
fn object_twins_sit_in_front_of_the_panel_and_follow_their_objects() {
    let mut app = app(1.0);
    app.update();
    app.update();
    let twin = |app: &mut App| {
        app.world_mut()
            .query::<(&ObjectTwin, &Transform, &Children)>()
            .iter(app.world())
            .map(|(o, t, c)| (o.index, *t, c.to_vec()))
            .collect::<Vec<_>>()
    };
    let before = twin(&mut app);
    assert_eq!(before.len(), 1);
    let (index, t0, parts) = &before[0];
    assert_eq!(*index, 0);
    // Its parts are drawn by the interaction camera only.
    assert_eq!(parts.len(), 1);
    for part in parts {
        let layer = app.world().get::<RenderLayers>(*part).expect("layer");
        assert_eq!(*layer, RenderLayers::layer(layers::INTERACTION));
    }
    // Between the interaction camera and the panel (2.5 m).
    let eye = camera().world_from_camera.translation.vector;
    let eye = Vec3::new(eye.x as f32, eye.y as f32, eye.z as f32);
    let d = (t0.translation - eye).length();
    assert!(d > 0.5 && d < 2.5, "twin {d:.2} m from the camera");
    // The real object moves 10 cm up: its twin follows.
    app.world_mut().resource_mut::<InteractionConfig>().objects[0]
        .world_from_object
        .translation
        .z += 0.1;
    app.update();
    let after = twin(&mut app);
    assert!(
        after[0].1.translation.z > t0.translation.z,
        "{:?} -> {:?}",
        t0,
        after[0].1
    );
}
