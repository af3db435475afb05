//! The room without a renderer (`MinimalPlugins`): what it spawns, on which layers, and how its
//! robot moves and reports. Rendering is the replay tests' job (`tests/app/replay/`).

use std::path::Path;

use avatarm_core::robot::PackagePath;
use avatarm_core::robot::trajectory::Keyframe;
use avatarm_core::vision::camera::{CameraPose, Intrinsics};
use avatarm_twin::{RobotTwin, RobotTwinPlugin};
use nalgebra::{Translation3, UnitQuaternion};

use super::*;

fn config(ground_truth: bool) -> SimRoomConfig {
    let urdf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../assets/robots/sawyer_lite/sawyer_lite.urdf");
    let model = Arc::new(RobotModel::from_urdf_file(&urdf, &PackagePath::default()).expect("urdf"));
    let pose = CameraPose {
        eye: [1.85, 0.0, 1.25],
        target: [0.4, 0.0, 0.95],
        up: [0.0, 0.0, 1.0],
    };
    let q0 = DVector::zeros(model.dof());
    let mut q1 = q0.clone();
    q1[0] = 0.5;
    SimRoomConfig {
        robot_base: Isometry3::translation(0.0, 0.0, 0.75),
        robot: SimRobotParams::default(),
        trajectory: JointTrajectory::new(vec![
            Keyframe {
                t_s: 0.0,
                q: q0.clone(),
            },
            Keyframe { t_s: 0.3, q: q1 },
        ]),
        q0,
        control_rate_hz: 100.0,
        camera: PinholeCamera {
            intrinsics: Intrinsics::from_fov_y(55f64.to_radians(), 64, 48),
            world_from_camera: pose.to_isometry().expect("pose"),
        },
        distortion: Default::default(),
        head: None,
        props: vec![
            Prop {
                name: "desk".into(),
                shape: PropShape::Box {
                    size: [1.0, 1.0, 0.05],
                },
                pose: Isometry3::identity(),
                rgba: [0.5, 0.4, 0.3, 1.0],
            },
            Prop {
                name: "bottle".into(),
                shape: PropShape::Bottle {
                    radius: 0.035,
                    height: 0.25,
                },
                pose: Isometry3::from_parts(
                    Translation3::new(0.6, 0.0, 0.75),
                    UnitQuaternion::identity(),
                ),
                rgba: [0.2, 0.5, 0.9, 1.0],
            },
        ],
        ground_truth,
        twin: None,
        video: None,
        external_drive: false,
        room_view: true,
        model,
    }
}

fn room(config: SimRoomConfig) -> App {
    let mut app = avatarm_twin::headless_app();
    app.insert_resource(config)
        .add_plugins((RobotTwinPlugin, SimRoomPlugin));
    app
}

fn on_layer(app: &mut App, layer: usize) -> usize {
    app.world_mut()
        .query::<(&RenderLayers, &Mesh3d)>()
        .iter(app.world())
        .filter(|(l, _)| l.intersects(&RenderLayers::layer(layer)))
        .count()
}

#[test]
fn the_room_spawns_props_robot_and_cameras_on_their_layers() {
    for ground_truth in [false, true] {
        let mut app = room(config(ground_truth));
        app.update();
        // A desk (one part) and a bottle (body and neck).
        let props = on_layer(&mut app, layers::ROOM);
        assert_eq!(props, 3, "ground truth {ground_truth}");
        let robot_meshes = on_layer(&mut app, layers::SIM_ROBOT);
        assert!(
            robot_meshes >= 9,
            "every link with a visual: {robot_meshes}"
        );
        // The silhouette view: the props black and the robot white, drawn flat, only with
        // ground truth.
        let silhouette = on_layer(&mut app, layers::SIM_SILHOUETTE);
        let expected = if ground_truth { 3 + robot_meshes } else { 0 };
        assert_eq!(silhouette, expected, "ground truth {ground_truth}");
        let flat: Vec<FlatPart> = app
            .world_mut()
            .query::<(&RenderLayers, &FlatPart)>()
            .iter(app.world())
            .filter(|(l, _)| l.intersects(&RenderLayers::layer(layers::SIM_SILHOUETTE)))
            .map(|(_, p)| *p)
            .collect();
        assert_eq!(flat.len(), expected);
        assert_eq!(
            flat.iter().filter(|p| **p == FlatPart::OCCLUDER).count(),
            if ground_truth { 3 } else { 0 }
        );
        let cameras = app.world_mut().query::<&Camera>().iter(app.world()).count();
        assert_eq!(cameras, if ground_truth { 2 } else { 1 });
        let views = app
            .world_mut()
            .query::<&FlatView>()
            .iter(app.world())
            .count();
        assert_eq!(views, usize::from(ground_truth));
        let sim = app.world().resource::<SimCameras>();
        assert_eq!(sim.no_robot.is_some(), ground_truth);
        assert_eq!(sim.silhouette.is_some(), ground_truth);
        let twins = app.world().resource::<SimTwins>();
        assert_eq!(twins.silhouette.is_some(), ground_truth);
        assert!(app.world().get::<RobotTwin>(twins.real).is_some());
    }
}

/// The robot-free view renders while the room changes and until a frame after the change has
/// rendered completely; then not until a prop moves again.
#[test]
fn the_robot_free_view_renders_only_when_the_room_changes() {
    let mut app = room(config(true));
    let active = |app: &mut App| {
        app.world_mut()
            .query::<(&Name, &Camera)>()
            .iter(app.world())
            .find(|(n, _)| n.as_str() == "ground truth: no robot")
            .map(|(_, c)| c.is_active)
            .expect("the robot-free camera")
    };
    let complete = |app: &mut App| {
        let frame = app.world().resource::<FrameCount>().0;
        app.world().resource::<RenderSettled>().note_complete(frame);
    };
    app.update();
    assert!(active(&mut app), "the room is new");
    app.update();
    assert!(active(&mut app), "no complete frame yet");
    complete(&mut app);
    app.update();
    assert!(!active(&mut app), "rendered completely, nothing moved");
    app.update();
    assert!(!active(&mut app));
    // The bottle moves (the arm carries it): the view renders again until that is complete.
    let mut parts = app.world_mut().query::<(&SimPropPart, &mut Transform)>();
    for (part, mut t) in parts.iter_mut(app.world_mut()) {
        if part.prop == 1 {
            t.translation.z += 0.01;
        }
    }
    app.update();
    assert!(active(&mut app), "a prop moved");
    app.update();
    assert!(
        active(&mut app),
        "the frame of the move is not complete yet"
    );
    complete(&mut app);
    app.update();
    assert!(!active(&mut app));
}

#[test]
fn the_robot_follows_its_trajectory_and_reports_joint_states() {
    let mut app = room(config(false));
    // A twin of the app's, to receive the joint states.
    let model = app.world().resource::<SimRoomConfig>().model.clone();
    let n = model.dof();
    let twin = app
        .world_mut()
        .spawn(RobotTwin {
            model,
            positions: DVector::zeros(n),
            velocities: DVector::zeros(n),
            stamp_s: None,
            links: Vec::new(),
            rejected: 0,
            strict_names: true,
        })
        .id();
    app.world_mut().resource_mut::<SimRoomConfig>().twin = Some(twin);
    for _ in 0..60 {
        app.update();
    }
    let robot = &app.world().resource::<SimRobotState>().0;
    assert!(
        robot.time_s() > 0.5,
        "the robot stepped: {} s",
        robot.time_s()
    );
    let q = robot.true_positions()[0];
    assert!((q - 0.5).abs() < 0.02, "j0 reached its keyframe: {q}");
    // Joint states at 100 Hz, 10 ms late: the twin is at most a few control steps behind.
    let got = app.world().get::<RobotTwin>(twin).expect("twin");
    let stamp = got.stamp_s.expect("joint states arrived");
    assert!(
        robot.time_s() - stamp < 0.05,
        "{stamp} vs {}",
        robot.time_s()
    );
    assert_eq!(got.rejected, 0);
    assert!((got.positions[0] - q).abs() < 0.05, "{}", got.positions[0]);
    // The room's own twin shows the true joints.
    let real = app.world().resource::<SimTwins>().real;
    let shown = app.world().get::<RobotTwin>(real).expect("twin").positions[0];
    assert!((shown - q).abs() < 1e-9);
}

/// A camera on a head: the room's views follow head(t) · mount at the robot's time, and the
/// tracker's poses arrive stamped at its rate, after its latency.
#[test]
fn a_camera_on_a_head_moves_with_it_and_the_head_is_tracked() {
    use avatarm_core::vision::head::{HeadMotion, TrackingModel, pose_error};
    let mut c = config(true);
    let centre = c.camera.world_from_camera;
    let motion = HeadMotion::Sweep {
        centre,
        amplitude_rad: 20f64.to_radians(),
        peak_speed_rad_s: 60f64.to_radians(),
        pivot_back_m: 0.09,
    };
    let mount = Isometry3::translation(0.0, -0.03, 0.08);
    c.head = Some(SimHead {
        motion: motion.clone(),
        mount,
        tracking: TrackingModel {
            rate_hz: 50.0,
            latency_s: 0.1,
            ..TrackingModel::default()
        },
        seed: 1,
    });
    let mut app = room(c);
    #[derive(Resource, Default)]
    struct Got(Vec<HeadPoseMessage>);
    app.init_resource::<Got>().add_systems(
        Update,
        |mut r: MessageReader<HeadPoseMessage>, mut got: ResMut<Got>| {
            got.0.extend(r.read().copied());
        },
    );
    for _ in 0..40 {
        app.update();
    }
    let t = app.world().resource::<SimRobotState>().0.time_s();
    assert!(t > 0.3, "the room's time moved: {t}");
    let expected = motion.pose_at(t) * mount;
    let mut cameras = app
        .world_mut()
        .query_filtered::<(&Name, &Transform), With<Camera>>();
    let moved: Vec<(String, Transform)> = cameras
        .iter(app.world())
        .map(|(n, t)| (n.to_string(), *t))
        .collect();
    assert_eq!(moved.len(), 2, "the real camera and the robot-free view");
    for (name, transform) in &moved {
        let shown = avatarm_twin::transform_to_iso(transform);
        let want = avatarm_core::vision::camera::PinholeCamera {
            intrinsics: app.world().resource::<SimRoomConfig>().camera.intrinsics,
            world_from_camera: expected,
        }
        .world_from_view();
        let (angle, offset) = pose_error(&shown, &want);
        assert!(
            angle < 1e-5 && offset < 1e-5,
            "{name}: {angle} rad, {offset} m"
        );
    }
    let view = app
        .world_mut()
        .query::<&FlatView>()
        .single(app.world())
        .expect("the silhouette's view")
        .camera
        .world_from_camera;
    assert_eq!(view, expected);
    // Every 20 ms a sample, arriving 100 ms later; none early.
    let got = &app.world().resource::<Got>().0;
    assert!(!got.is_empty());
    for (i, p) in got.iter().enumerate() {
        assert!(
            (p.stamp_s - i as f64 * 0.02).abs() < 1e-9,
            "{i}: {}",
            p.stamp_s
        );
        assert!(p.stamp_s <= t - 0.1 + 1e-9, "arrived before its latency");
        let (angle, _) = pose_error(&p.world_from_head, &motion.pose_at(p.stamp_s));
        assert!(angle < 1e-12, "no noise set");
    }
    assert!(got.last().unwrap().stamp_s > t - 0.1 - 0.03);
}
