//! The app's systems run in a defined order (no ambiguous pairs but those stated).

use super::*;

/// No two of the project's own systems touch the same data in an undefined order, in any
/// schedule: the replay's app with the preview's plugins, the live scores, the XR view and the
/// live teleoperation added (everything `avatarm run` and `avatarm replay` can add), built with
/// Bevy's ambiguity detection.
#[test]
fn the_apps_own_systems_run_in_a_defined_order() {
    let scene = scene("pouring");
    let options = ReplayOptions::new(out_dir("ambiguities"));
    let mut app = avatarm::replay::build_app(&scene, options).expect("app");
    let preview = avatarm::preview::PreviewOptions {
        frames: Some(1),
        screenshot: None,
        xr: false,
        fixed_step_s: None,
        camera: avatarm::app::CameraSource::Simulated,
        recorded_arm: None,
        hand: None,
        robot: avatarm::teleop::RobotChoice::Sim,
        cameras: Vec::new(),
        no_switch: None,
        press: vec![(1, bevy::input::keyboard::KeyCode::KeyV)],
        slow_update: None,
    };
    app.add_plugins((
        avatarm::preview::PreviewPlugin(preview),
        avatarm::preview::live_scores::LiveDrPlugin { every: 15 },
        avatarm::preview::switch::CameraSwitchPlugin(avatarm::preview::switch::CameraViews {
            scenes: vec![scene.clone(), scene.clone()],
            current: 0,
        }),
    ));
    #[cfg(feature = "xr")]
    app.add_plugins(avatarm::preview::xr::XrViewPlugin);
    avatarm::teleop::add_live_teleop(
        &mut app,
        &scene,
        &avatarm::scene::hand::HandChoice::Desktop,
        avatarm::teleop::RobotChoice::Sim,
    )
    .expect("live teleoperation");
    // Two systems of this test that write the same resource unordered: the check must see them.
    app.init_resource::<Probe>()
        .add_systems(bevy::prelude::Update, (probe_a, probe_b));
    // Bevy's systems that skip an inactive camera count as the project's here: the room turns
    // its robot-free view on and off (avatarm_sim::gate_no_robot_view), and a view turned on
    // after them in an update rendered with its visible meshes, shadow cascades and light
    // clusters of its last active update.
    let found = avatarm::app::ambiguities(
        &mut app,
        &[
            "avatarm",
            // This test's own systems (the planted pair), named by this module's path.
            concat!(module_path!(), "::probe"),
            "bevy_camera::visibility::check_visibility",
            "bevy_light::cascade::build_directional_light_cascades",
            "bevy_light::cluster::assign::assign_objects_to_clusters",
            // The frame count: the live scores and the background read which render is this
            // update's.
            "bevy_diagnostic::frame_count::update_frame_count",
        ],
    );
    let (probes, ours): (Vec<&String>, Vec<&String>) = found
        .iter()
        .partition(|f| f.contains(concat!(module_path!(), "::probe")));
    assert_eq!(probes.len(), 1, "the check finds a planted pair: {found:?}");
    assert!(probes[0].contains("probe_a") && probes[0].contains("probe_b"));
    assert!(
        ours.is_empty(),
        "{} ambiguous pairs of Avatarm's systems:\n{}",
        ours.len(),
        ours.iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[derive(bevy::prelude::Resource, Default)]
struct Probe(u32);

fn probe_a(mut p: bevy::prelude::ResMut<Probe>) {
    p.0 += 1;
}

fn probe_b(mut p: bevy::prelude::ResMut<Probe>) {
    p.0 += 2;
}
