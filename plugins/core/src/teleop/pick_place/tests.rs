use super::*;
use crate::robot::kinematics::tests::sawyer;
use nalgebra::Matrix3;
use std::f64::consts::FRAC_PI_2;

const ARM: [usize; 7] = [0, 1, 2, 3, 4, 5, 6];
const DT: f64 = 0.01;

/// The top grasp: approach axis (the tool's z) down, its x pointing away from the robot.
fn down() -> UnitQuaternion<f64> {
    UnitQuaternion::from_matrix(&Matrix3::from_columns(&[
        Vector3::x(),
        -Vector3::y(),
        -Vector3::z(),
    ]))
}

fn settings() -> PickPlaceSettings {
    PickPlaceSettings {
        clearance_z: 0.75 + 0.10 + 0.08,
        clear_m: 0.05,
        tool_radius_m: 0.02,
        hover_m: 0.04,
        grasp_depth_m: 0.015,
        tool_down: down(),
        arrive_m: 0.003,
        arrive_rad: 0.02,
        over_m: 0.01,
        gain_per_s: 8.0,
        max_speed: 0.24,
        max_turn: 1.5,
        place_m: 0.002,
        place_rad: 0.02,
        place_timeout_s: 1.5,
        mapping: MappingSettings::default(),
    }
}

/// Three pieces 6 cm apart across the robot's front, 5 and 9 cm tall, on a 0.75 m table.
fn pieces() -> Vec<PickObject> {
    [(-0.06, 0.05), (0.0, 0.09), (0.06, 0.05)]
        .iter()
        .map(|&(y, h)| PickObject {
            pose: Isometry3::translation(0.65, y, 0.75 + h / 2.0),
            radius_m: 0.015,
            height_m: h,
        })
        .collect()
}

struct World {
    robot: PickPlaceRobot,
    q: DVector<f64>,
    t: f64,
    /// The closest the tool point came to a piece's body it was not sent to (m, negative:
    /// inside), over the run.
    closest: f64,
}

impl World {
    fn new() -> Self {
        let model = Arc::new(sawyer());
        let tcp = model.link_id("right_gripper_tip").unwrap();
        let robot = PickPlaceRobot::new(
            settings(),
            model,
            Isometry3::translation(0.0, 0.0, 0.75),
            tcp,
            ARM.to_vec(),
            pieces(),
        )
        .unwrap();
        Self {
            robot,
            q: DVector::from_vec(vec![0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161, 0.02, 0.02]),
            t: 0.0,
            closest: f64::INFINITY,
        }
    }

    /// Runs for `seconds` with `command`, integrating the joint velocities; returns every tick.
    fn run(
        &mut self,
        seconds: f64,
        command: &PickPlaceCommand,
        goal: Option<usize>,
    ) -> Vec<PickTick> {
        let mut out = Vec::new();
        for _ in 0..(seconds / DT).round() as usize {
            self.t += DT;
            let q: Vec<f64> = self.q.iter().copied().collect();
            let tick = self.robot.tick(Some(command), &q, self.t, self.t).unwrap();
            assert!(tick.qdot.iter().all(|v| v.is_finite()));
            let p = tick.tool.translation.vector;
            for (i, o) in pieces().iter().enumerate() {
                if Some(i) == goal || command.object == Some(i) {
                    continue;
                }
                let c = o.pose.translation.vector;
                let radial = Vector3::new(p.x - c.x, p.y - c.y, 0.0).norm() - o.radius_m;
                let above = p.z - o.top_z();
                self.closest = self.closest.min(radial.max(above));
            }
            self.q += &tick.qdot * DT;
            out.push(tick);
        }
        out
    }
}

fn target_at(stamp_s: f64, pose: Isometry3<f64>, held: bool) -> OperatorTarget {
    OperatorTarget {
        stamp_s,
        target: pose,
        object_twist: Vector6::zeros(),
        twin_twist: Vector6::zeros(),
        squeeze_n: if held { 3.0 } else { 0.0 },
        rank: 6,
        contacts: 4,
        held,
    }
}

#[test]
fn intent_hovers_then_goes_around_the_goal_without_crossing_the_others() {
    let mut w = World::new();
    let hover = PickPlaceCommand {
        object: None,
        target: None,
        intent: Some(0),
        intent_near: false,
    };
    w.run(4.0, &hover, Some(0));
    let g = w.robot.grasp_pose(0).unwrap();
    let tool = w.run(0.01, &hover, Some(0)).pop().unwrap().tool;
    let off = tool.translation.vector - (g.translation.vector + Vector3::new(0.0, 0.0, 0.04));
    assert!(off.norm() < 0.005, "hovering {off:?} off");
    // The estimate moves to the far piece, across the tall one in the middle.
    let other = PickPlaceCommand {
        intent: Some(2),
        intent_near: true,
        ..hover
    };
    w.closest = f64::INFINITY;
    let ticks = w.run(4.0, &other, Some(2));
    assert!(
        w.closest > 0.02,
        "the tool came within {} m of a piece",
        w.closest
    );
    let g = w.robot.grasp_pose(2).unwrap();
    let last = ticks.last().unwrap();
    assert!((last.tool.translation.vector - g.translation.vector).norm() < 0.005);
    assert_eq!(last.goal, Some(PickGoal::Around(2)));
    assert!(!last.gripper.closed);
    // Every commanded tool speed stayed under the cap.
    let fastest = ticks
        .iter()
        .map(|t| {
            (t.tcp_jacobian.columns(0, 7) * t.qdot.rows(0, 7))
                .fixed_rows::<3>(0)
                .norm()
        })
        .fold(0.0, f64::max);
    assert!(fastest <= 0.24 + 1e-6, "{fastest}");
}

#[test]
fn a_grasp_carry_and_place_moves_the_believed_piece_and_only_it() {
    let mut w = World::new();
    let start = pieces()[1].pose;
    let held = PickPlaceCommand {
        object: Some(1),
        target: Some(target_at(0.0, start, true)),
        intent: None,
        intent_near: false,
    };
    let ticks = w.run(5.0, &held, Some(1));
    let grasp = ticks
        .iter()
        .position(|t| t.grasped.is_some())
        .expect("grasped");
    assert_eq!(ticks[grasp].grasped, Some(1));
    assert!(matches!(w.robot.phase(), PickPhase::Carry { object: 1 }));
    // Carried 10 cm up and 8 cm toward the robot, set down there, and let go.
    let placed = Isometry3::translation(-0.08, 0.0, 0.0) * start;
    for k in 0..=100 {
        let s = f64::from(k) / 100.0;
        let lift = (s * std::f64::consts::PI).sin() * 0.10;
        let pose = Isometry3::translation(-0.08 * s, 0.0, lift) * start;
        let c = PickPlaceCommand {
            target: Some(target_at(w.t, pose, true)),
            ..held
        };
        w.run(0.02, &c, Some(1));
    }
    let release = PickPlaceCommand {
        target: Some(target_at(w.t, placed, false)),
        ..held
    };
    let ticks = w.run(3.0, &release, Some(1));
    let r = ticks
        .iter()
        .position(|t| t.released.is_some())
        .expect("released");
    assert_eq!(ticks[r].released, Some(1));
    let believed = w.robot.objects()[1].pose.translation.vector;
    assert!(
        (believed - placed.translation.vector).norm() < 0.003,
        "{believed:?}"
    );
    assert_eq!(w.robot.objects()[0], pieces()[0]);
    assert_eq!(w.robot.phase(), PickPhase::Free);
    assert!(!ticks.last().unwrap().gripper.closed);
}

/// Grasps piece `i` (the hand holding its twin where it stands) and returns the command.
fn grasped(w: &mut World, i: usize) -> PickPlaceCommand {
    let held = PickPlaceCommand {
        object: Some(i),
        target: Some(target_at(0.0, pieces()[i].pose, true)),
        intent: None,
        intent_near: false,
    };
    w.run(5.0, &held, Some(i));
    assert!(matches!(w.robot.phase(), PickPhase::Carry { object } if object == i));
    held
}

/// The twin moved to `goal` for 50 ms, then let go of there; runs `seconds` and returns the
/// carried piece's centre at each tick, and the tick the gripper opened.
fn set_down_at(
    w: &mut World,
    held: &PickPlaceCommand,
    goal: Isometry3<f64>,
    seconds: f64,
) -> (Vec<Vector3<f64>>, Option<usize>) {
    let moved = PickPlaceCommand {
        target: Some(target_at(w.t, goal, true)),
        ..*held
    };
    let mut ticks = w.run(0.05, &moved, held.object);
    let release = PickPlaceCommand {
        target: Some(target_at(w.t, goal, false)),
        ..*held
    };
    ticks.extend(w.run(seconds, &release, held.object));
    let centres = ticks
        .iter()
        .map(|t| (t.tool * w.robot.tcp_from_object).translation.vector)
        .collect();
    (centres, ticks.iter().position(|t| t.released.is_some()))
}

/// A twin taken straight across its two neighbours (one 4 cm taller than it) and let go of
/// there at once: the real piece is lifted straight up, carried across above both, and set
/// down on the target, though the crossing takes longer than the place's timeout; its body
/// never enters a neighbour's below that one's top, and it is let go of on the board, not in
/// the air.
#[test]
fn a_carried_piece_goes_over_its_neighbours_not_through_them() {
    let mut w = World::new();
    // A place timeout shorter than the crossing (about 0.9 s).
    w.robot.settings.place_timeout_s = 0.3;
    let held = grasped(&mut w, 2);
    let goal = Isometry3::translation(0.0, -0.18, 0.0) * pieces()[2].pose;
    let (centres, released) = set_down_at(&mut w, &held, goal, 6.0);
    let (r, h) = (pieces()[2].radius_m, pieces()[2].height_m);
    let mut grazed = Vec::new();
    for c in &centres {
        for (i, o) in pieces().iter().enumerate().take(2) {
            let p = o.pose.translation.vector;
            let across = Vector3::new(c.x - p.x, c.y - p.y, 0.0).norm();
            if across < r + o.radius_m && c.z - h / 2.0 < o.top_z() {
                grazed.push((i, across, c.z - h / 2.0 - o.top_z()));
            }
        }
    }
    assert!(grazed.is_empty(), "{:?}", &grazed[..grazed.len().min(5)]);
    // Over the tallest top (0.84 m) by the clearance's margin.
    let s = w.robot.settings;
    let highest = centres
        .iter()
        .map(|c| c.z - h / 2.0)
        .fold(f64::MIN, f64::max);
    assert!(highest >= s.clearance_z - s.over_m, "{highest}");
    let released = released.expect("let go");
    assert!(
        released as f64 * DT > 2.0 * s.place_timeout_s,
        "the crossing took {} s",
        released as f64 * DT
    );
    let at = centres[released];
    assert!((at - goal.translation.vector).norm() < 0.003, "{at:?}");
}

/// A twin let go of where the arm cannot take the real piece (2 m away): after 5 place
/// timeouts the piece is set down straight below where it is instead, and let go of there on
/// the board, not held for ever.
#[test]
fn a_piece_that_cannot_reach_its_place_is_set_down_where_it_is() {
    let mut w = World::new();
    let held = grasped(&mut w, 0);
    let goal = Isometry3::translation(2.0, 0.0, 0.3) * pieces()[0].pose;
    let s = settings();
    let give_up = PLACE_GIVE_UP * s.place_timeout_s;
    let (centres, released) = set_down_at(&mut w, &held, goal, 2.0 * give_up + 1.0);
    let released = released.expect("let go");
    let after = released as f64 * DT;
    assert!(after > give_up, "let go after {after} s");
    let rest_z = pieces()[0].pose.translation.z;
    let at = centres[released];
    assert!((at.z - rest_z).abs() < 0.005, "let go at {at:?}");
    assert!(matches!(
        w.robot.phase(),
        PickPhase::Retreat | PickPhase::Free
    ));
}

#[test]
fn bad_commands_and_joints_are_refused_by_name() {
    let mut w = World::new();
    let q: Vec<f64> = w.q.iter().copied().collect();
    let c = PickPlaceCommand {
        object: Some(7),
        target: None,
        intent: None,
        intent_near: false,
    };
    let e = w
        .robot
        .tick(Some(&c), &q, 0.0, 0.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("object 7 of 3"), "{e}");
    let mut nan = q.clone();
    nan[2] = f64::NAN;
    assert!(w.robot.tick(None, &nan, 0.0, 0.0).is_err());
    let mut t = target_at(0.0, pieces()[0].pose, true);
    t.squeeze_n = f64::NAN;
    let c = PickPlaceCommand {
        object: Some(0),
        target: Some(t),
        ..c
    };
    assert!(w.robot.tick(Some(&c), &q, 0.0, 0.0).is_err());
    let s = PickPlaceSettings {
        max_speed: -1.0,
        ..settings()
    };
    assert!(
        s.validate()
            .unwrap_err()
            .to_string()
            .contains("pick_place.max_speed")
    );
}

/// Piece `i`'s body centre (world).
fn centre_of(o: &[PickObject], i: usize) -> Vector3<f64> {
    o[i].pose.translation.vector
}

#[test]
fn between_grasps_the_tool_crosses_above_the_pieces_beside_its_way_not_the_tallest() {
    let (w, s, o) = (World::new(), settings(), pieces());
    let centre = |i: usize| centre_of(&o, i);
    let above = |i: usize| centre(i) + Vector3::new(0.0, 0.0, 0.1);
    let (short, tall) = (o[0].top_z() + s.clear_m, o[1].top_z() + s.clear_m);
    // From above the first short piece to 4 cm beyond it, away from the others: over it only.
    let beyond = centre(0) + Vector3::new(0.0, -0.04, 0.0);
    assert!((w.robot.crossing_z(&above(0), &beyond) - short).abs() < 1e-12);
    // Coming to a piece's grasp from the side, the tool crosses above that piece's own top and
    // comes down onto it from there (not sideways at the grasp's height, into its side).
    let grasp = w.robot.grasp_pose(0).unwrap().translation.vector;
    let z = w
        .robot
        .crossing_z(&(grasp + Vector3::new(0.05, 0.0, 0.0)), &grasp);
    assert!((z - short).abs() < 1e-12 && z > o[0].top_z(), "{z}");
    // From one short piece to the other, past the tall one in between: over the tall one ...
    let z = w.robot.crossing_z(&above(0), &above(2));
    assert!((z - tall).abs() < 1e-12 && tall > short, "{z}");
    // ... capped at the clearance height.
    let capped = PickPlaceRobot::new(
        PickPlaceSettings {
            clearance_z: tall - 0.01,
            ..s
        },
        Arc::new(sawyer()),
        Isometry3::translation(0.0, 0.0, 0.75),
        w.robot.tcp,
        ARM.to_vec(),
        pieces(),
    )
    .unwrap();
    assert!((capped.crossing_z(&above(0), &above(2)) - (tall - 0.01)).abs() < 1e-12);
    // A way farther from every piece's side than the gripper's reach and over_m stays low,
    // below their tops.
    let aside = |i: usize| centre(i) + Vector3::new(-0.05, 0.0, 0.0);
    let z = w.robot.crossing_z(&aside(0), &aside(2));
    assert!((z - aside(2).z).abs() < 1e-12 && z < o[0].top_z(), "{z}");
    // A way 3.5 cm from the tall piece's axis: its side is 2 cm away, out of over_m but within
    // the open gripper's reach: crossed above.
    let near = |i: usize| centre(i) + Vector3::new(-0.035, 0.0, 0.0);
    let z = w.robot.crossing_z(&near(0), &near(2));
    assert!((z - tall).abs() < 1e-12, "{z}");
    // The way ends over_m short of its goal: coming along x to 4 cm from the tall piece's axis,
    // it is not crossed (the tool goes down beside it, 5 cm from its axis at the least).
    let z = w.robot.crossing_z(
        &(centre(1) + Vector3::new(0.10, 0.0, 0.0)),
        &(centre(1) + Vector3::new(0.04, 0.0, 0.0)),
    );
    assert!((z - centre(1).z).abs() < 1e-12, "{z}");
    // Rising from a piece (a retreat): above it and the pieces within reach around it.
    let z = w.robot.crossing_z(&centre(2), &centre(2));
    assert!((z - short).abs() < 1e-12, "{z}");
    // The crossing margin must exceed the band the tool moves sideways in.
    let bad = PickPlaceSettings {
        clear_m: s.over_m,
        ..s
    };
    assert!(bad.validate().unwrap_err().to_string().contains("clear_m"));
    let mut nan = pieces();
    nan[1].radius_m = f64::NAN;
    let e = PickPlaceRobot::new(
        s,
        Arc::new(sawyer()),
        Isometry3::identity(),
        w.robot.tcp,
        ARM.to_vec(),
        nan,
    )
    .unwrap_err();
    assert!(e.to_string().contains("objects[1]"), "{e}");
    // The clearance height must clear every top by more than over_m.
    let e = PickPlaceRobot::new(
        PickPlaceSettings {
            clearance_z: o[1].top_z(),
            ..s
        },
        Arc::new(sawyer()),
        Isometry3::identity(),
        w.robot.tcp,
        ARM.to_vec(),
        pieces(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("clearance_z"), "{e}");
}

#[test]
fn in_its_last_stretch_the_tool_keeps_above_the_pieces_the_open_gripper_is_over() {
    let (w, s, o) = (World::new(), settings(), pieces());
    let centre = |i: usize| centre_of(&o, i);
    // 3 cm from the tall piece's axis (its side 1.5 cm away, inside the gripper's 2 cm reach):
    // above its top.
    let beside_tall = centre(1) + Vector3::new(0.0, -0.03, 0.0);
    let floor = w.robot.descent_floor(&beside_tall, Some(0));
    assert!(
        (floor - (o[1].top_z() + s.over_m / 2.0)).abs() < 1e-12,
        "{floor}"
    );
    // On the goal's axis, the others out of reach: nothing holds it up.
    assert_eq!(
        w.robot.descent_floor(&centre(0), Some(0)),
        f64::NEG_INFINITY
    );
    // 1.5 cm off the goal's axis the fingers would land on its top: above it until centred.
    let off = centre(0) + Vector3::new(0.015, 0.0, 0.0);
    let floor = w.robot.descent_floor(&off, Some(0));
    assert!(
        (floor - (o[0].top_z() + s.over_m / 2.0)).abs() < 1e-12,
        "{floor}"
    );
    // The last stretch's twist does not go down while the floor is above the tool.
    let tool = Isometry3::from_parts(
        Translation3::from(beside_tall + Vector3::new(0.0, 0.0, 0.06)),
        down(),
    );
    let goal = Isometry3::from_parts(
        Translation3::from(beside_tall + Vector3::new(0.0, -0.005, -0.03)),
        down(),
    );
    let floor = w.robot.descent_floor(&tool.translation.vector, Some(0));
    assert!(tool.translation.z < floor + 0.03);
    let (twist, _) = clearance_twist(&tool, &goal, f64::NEG_INFINITY, floor, &s);
    let (free, _) = clearance_twist(&tool, &goal, f64::NEG_INFINITY, f64::NEG_INFINITY, &s);
    assert!(free[2] < 0.0, "{free}");
    assert!(
        twist[2] > free[2] && (tool.translation.z + twist[2] / s.gain_per_s - floor).abs() < 1e-9,
        "{twist}"
    );
}

/// The tool's heading about the vertical (rad, its x axis).
fn heading(tool: &Isometry3<f64>) -> f64 {
    let x = tool.rotation * Vector3::x();
    x.y.atan2(x.x)
}

#[test]
fn a_top_grasp_keeps_the_tools_heading_within_a_quarter_turn_and_the_carry_does_not_turn_it() {
    let d = down();
    let turned = |a: f64| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a) * d;
    // Within a quarter turn of tool_down's heading the tool keeps its own; beyond, it turns to
    // the nearer edge of that band, not back to tool_down and not through half a turn.
    for (a, want) in [
        (0.3, 0.3),
        (-1.2, -1.2),
        (2.0, FRAC_PI_2),
        (-2.9, -FRAC_PI_2),
    ] {
        let h = grasp_heading(&d, &turned(a));
        assert!((h - want).abs() < 1e-9, "{a}: {h}");
    }
    // Tilted half a radian about x, the tool's heading is still its turn about the vertical.
    let tilted = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.5)
        * d;
    assert!((grasp_heading(&d, &tilted) - 0.4).abs() < 1e-9);
    let nan = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
    assert_eq!(grasp_heading(&d, &nan), 0.0);

    // The hand turns the twin half round about the vertical while carrying it 5 cm up (a
    // scripted hand setting it down from the other side): the tool keeps the heading it
    // grasped with, and the piece still follows the twin's position.
    let mut w = World::new();
    let held = grasped(&mut w, 1);
    let at_grasp = heading(&w.run(0.01, &held, Some(1)).pop().unwrap().tool);
    let start = pieces()[1].pose;
    let mut last = None;
    for k in 0..=100 {
        let s = f64::from(k) / 100.0;
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI * s);
        let pose = Isometry3::from_parts(
            Translation3::from(start.translation.vector + Vector3::new(0.0, 0.0, 0.05 * s)),
            turn * start.rotation,
        );
        let c = PickPlaceCommand {
            target: Some(target_at(w.t, pose, true)),
            ..held
        };
        for t in w.run(0.02, &c, Some(1)) {
            let off = (heading(&t.tool) - at_grasp + std::f64::consts::PI)
                .rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            assert!(off.abs() < 0.05, "the tool turned {off} rad");
            last = Some(t);
        }
    }
    let piece = last.unwrap().tool * w.robot.tcp_from_object;
    let want = start.translation.vector + Vector3::new(0.0, 0.0, 0.05);
    assert!(
        (piece.translation.vector - want).norm() < 0.01,
        "{:?}",
        piece.translation.vector
    );
}
