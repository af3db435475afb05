//! Tests: the hand in physics, headless. A scripted hand reaches a bottle on a table and closes
//! on it, or is tracked straight through it: contacts appear, forces stay bounded, nothing
//! explodes or tunnels. And recorded hands replay on their timestamps.

use std::time::Duration;

use crate::{ActiveHand, GraspTarget, ObjectContacts, ScriptedHand};
use avatarm_core::teleop::grasp::{ContactModel, analyse};
use avatarm_core::teleop::hand::{HandKeyframe, HandNoise, HandScript, Handedness};
use bevy::prelude::*;
use bevy_rapier3d::prelude::*;

const BOTTLE: Vec3 = Vec3::new(0.6, 0.0, 0.75 + 0.125);

fn key(t_s: f64, xyz: [f64; 3], grip: f64) -> HandKeyframe {
    HandKeyframe {
        t_s,
        xyz,
        // Palm facing -y toward the bottle's side: fingers along +x... rolled so the palm
        // (−z of the hand frame) faces the bottle.
        rpy: [std::f64::consts::FRAC_PI_2, 0.0, 0.0],
        grip,
        tracked: true,
    }
}

fn app(keys: Vec<HandKeyframe>) -> App {
    let script = HandScript::new(Handedness::Right, keys, HandNoise::default()).expect("script");
    let mut app = crate::headless_app(Duration::from_millis(10));
    app.insert_resource(ActiveHand::new(ScriptedHand::new(script, 90.0)));
    app.add_systems(Startup, |mut commands: Commands| {
        commands.spawn((
            Name::new("table"),
            RigidBody::Fixed,
            Collider::cuboid(0.65, 0.8, 0.375),
            Transform::from_xyz(0.45, 0.0, 0.375),
        ));
        commands.spawn((
            Name::new("bottle"),
            GraspTarget,
            RigidBody::Dynamic,
            Collider::cylinder(0.125, 0.035),
            ColliderMassProperties::Mass(0.3),
            Friction::coefficient(1.0),
            Ccd::enabled(),
            Velocity::zero(),
            // Cylinders are along y in Rapier; the scene is z-up.
            Transform::from_translation(BOTTLE)
                .with_rotation(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2)),
        ));
    });
    app
}

fn bottle(app: &mut App) -> (Vec3, Vec3) {
    let mut q = app
        .world_mut()
        .query_filtered::<(&Transform, &Velocity), With<GraspTarget>>();
    let (t, v) = q.single(app.world()).expect("one bottle");
    (t.translation, v.linear)
}

#[test]
fn a_closing_hand_touches_the_bottle_on_its_surface_with_bounded_forces() {
    // Wrist beside the bottle, fingers across its front, then closing.
    let keys = vec![
        key(0.0, [0.48, -0.10, 0.90], 0.0),
        key(0.5, [0.52, -0.06, 0.90], 0.0),
        key(1.2, [0.52, -0.06, 0.90], 1.0),
        key(2.0, [0.52, -0.06, 0.90], 1.0),
    ];
    let mut app = app(keys);
    let mut touched = 0;
    let mut max_force: f64 = 0.0;
    let mut squeeze: f64 = 0.0;
    let mut max_speed: f32 = 0.0;
    for _ in 0..200 {
        app.update();
        let c = app.world().resource::<ObjectContacts>().clone();
        if !c.contacts.is_empty() {
            touched += 1;
            max_force = max_force.max(c.max_force_n);
            let o = nalgebra::Vector3::new(
                f64::from(BOTTLE.x),
                f64::from(BOTTLE.y),
                f64::from(BOTTLE.z),
            );
            let points: Vec<_> = c.contacts.iter().map(|k| k.contact).collect();
            if let Ok(a) = analyse(&o, &points, ContactModel::HardFinger) {
                squeeze = squeeze.max(a.squeeze);
            }
            let bottle = app
                .world_mut()
                .query_filtered::<Entity, With<GraspTarget>>()
                .single(app.world())
                .expect("one bottle");
            assert!(c.contacts.iter().all(|k| k.object == bottle));
            assert!(c.contacts.iter().all(|k| {
                k.contact.force.iter().all(|v| v.is_finite())
                    && k.hand_velocity.iter().all(|v| v.is_finite())
                    && k.object_velocity.iter().all(|v| v.is_finite())
            }));
            // Contact points lie on the bottle's surface (radius 3.5 cm about its axis).
            let mut q = app
                .world_mut()
                .query_filtered::<&Transform, With<GraspTarget>>();
            let t = *q.single(app.world()).expect("one bottle");
            for k in &points {
                let p = Vec3::new(k.point.x as f32, k.point.y as f32, k.point.z as f32);
                let local = t.rotation.inverse() * (p - t.translation);
                let radial = Vec2::new(local.x, local.z).length();
                assert!(
                    (radial - 0.035).abs() < 0.01 && local.y.abs() < 0.135,
                    "contact off the surface: {local}"
                );
            }
        }
        let (p, v) = bottle(&mut app);
        assert!(p.is_finite() && v.is_finite());
        max_speed = max_speed.max(v.length());
    }
    eprintln!(
        "frames with contact {touched}, max contact force {max_force:.2} N, max squeeze {squeeze:.2} N, max bottle speed {max_speed:.3} m/s"
    );
    assert!(
        touched > 20,
        "the closing hand touches the bottle: {touched}"
    );
    assert!(max_force < 200.0, "bounded contact force: {max_force}");
    assert!(max_speed < 2.0, "the bottle does not fly off: {max_speed}");
    let (p, _) = bottle(&mut app);
    assert!(p.z > 0.75, "the bottle did not fall through the table: {p}");
}

#[test]
fn fingers_tracked_deep_inside_do_not_explode_the_object() {
    // The tracked hand goes straight through the bottle's axis and closes there.
    let keys = vec![
        key(0.0, [0.45, -0.02, 0.90], 0.3),
        key(0.6, [0.62, -0.02, 0.90], 1.0),
        key(1.5, [0.62, -0.02, 0.90], 1.0),
    ];
    let mut app = app(keys);
    let mut max_speed: f32 = 0.0;
    let mut max_force: f64 = 0.0;
    for _ in 0..150 {
        app.update();
        let (p, v) = bottle(&mut app);
        assert!(p.is_finite() && v.is_finite(), "NaN in the object");
        max_speed = max_speed.max(v.length());
        max_force = max_force.max(app.world().resource::<ObjectContacts>().max_force_n);
    }
    let (p, _) = bottle(&mut app);
    eprintln!("deep: max bottle speed {max_speed:.3} m/s, max force {max_force:.1} N, end {p}");
    // Pushed aside at most at the hand's drive speed, never launched.
    assert!(max_speed <= 1.5, "{max_speed}");
    assert!(max_force < 500.0, "{max_force}");
    assert!(p.z > 0.75 && (p - BOTTLE).length() < 0.5, "{p}");
}

#[test]
fn recorded_hands_replay_on_their_timestamps() {
    use crate::{HandSource, RecordedHand};
    use avatarm_core::teleop::hand::write_frames;
    let script = HandScript::new(
        Handedness::Right,
        vec![
            key(0.0, [0.5, 0.0, 0.9], 0.0),
            key(1.0, [0.5, 0.1, 0.9], 1.0),
        ],
        HandNoise::default(),
    )
    .expect("script");
    let frames: Vec<_> = (0..10)
        .map(|i| script.frame_at(f64::from(i) * 0.1))
        .collect();
    let path = std::env::temp_dir().join(format!("avatarm_hand_{}.hand.jsonl", std::process::id()));
    std::fs::write(&path, write_frames(&frames)).expect("write");
    let mut rec = RecordedHand::open(&path).expect("opens");
    assert!(rec.poll(-0.01).is_none());
    assert_eq!(rec.poll(0.25).map(|f| f.t_s), Some(0.2));
    assert!(rec.poll(0.26).is_none(), "nothing new");
    assert_eq!(rec.poll(5.0).map(|f| f.t_s), Some(0.9));
    std::fs::write(&path, "{\"t_s\": 0").expect("write");
    let err = RecordedHand::open(&path).err().expect("bad file");
    assert!(err.to_string().contains("line 1"), "{err}");
    let _ = std::fs::remove_file(&path);
}

#[test]
fn a_scripted_hand_gives_each_tracker_frame_once() {
    use crate::HandSource;
    let script = HandScript::new(
        Handedness::Right,
        vec![key(0.0, [0.5, 0.0, 1.0], 0.0)],
        HandNoise::default(),
    )
    .expect("script");
    let mut hand = ScriptedHand::new(script, 90.0);
    // Polled at 100 Hz for a second: 90 frames, each newer than the one before; the polls
    // between frames give nothing.
    let frames: Vec<f64> = (0..100)
        .filter_map(|i| hand.poll(f64::from(i) * 0.01).map(|f| f.t_s))
        .collect();
    assert!((89..=91).contains(&frames.len()), "{}", frames.len());
    assert!(frames.windows(2).all(|w| w[1] > w[0]));
}
