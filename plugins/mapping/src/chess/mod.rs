//! The paper's opening scene, measured: Blair plays an opening on Alice's board through the
//! hidden robot, with and without the robot anticipating which piece she reaches for.
//!
//! A trial plays every move of `[chess]` once ([`script`]): the operator's hand world holds a
//! twin of every piece ([`GraspTarget`]s in Rapier, `k` times the real size) and the scripted
//! hand grasps, carries and sets down one piece per move. Each control tick the operator's side
//! reads which twin the hand holds, the mapping's target for it ([`Mapper::operator_side`]) and,
//! while the hand holds nothing, the intent estimate ([`IntentEstimator`]); the command reaches
//! the robot's side after the one-way delay; [`PickPlaceRobot`] moves the simulated arm (through
//! the same [`SafetyLimiter`]) to pre-grasp, grasp, carry and place the real pieces
//! ([`SimArm::with_objects`]). Headless, without rendering.
//!
//! Measured per move ([`MoveResult`]): the time from the virtual grasp to the real grasp, the
//! real piece's placement error against its square, whether the right piece went to the right
//! square, the pre-grasps toward a wrong piece, the tool's touches of other pieces, and the
//! mapping's error while carried.

pub mod report;
pub mod script;

use std::collections::VecDeque;
use std::time::Duration;

use avatarm_core::sim::arm::{CarriedObject, RobotInterface, SimArm};
use avatarm_core::sim::{JointState, SimRobot};
use avatarm_core::teleop::hand::PALM;
use avatarm_core::teleop::intent::IntentEstimator;
use avatarm_core::teleop::mapping::{Mapper, MappingSettings, OperatorInputs, VirtualToReal};
use avatarm_core::teleop::pick_place::{
    PickGoal, PickObject, PickPhase, PickPlaceCommand, PickPlaceRobot, PickPlaceSettings, PickTick,
};
use avatarm_core::teleop::safety::{self, SafetyLimiter, SafetySettings};
use avatarm_hand::{ActiveHand, GraspTarget, HandDrive, HeldObject, ObjectContacts, ScriptedHand};
use avatarm_scene::chess::{ChessSetup, ChessTask};
use bevy::prelude::*;
use bevy_rapier3d::prelude::*;
use nalgebra::{DVector, Isometry3, Matrix3, Matrix6xX, UnitQuaternion, Vector3};

pub use report::{ChessCondition, ChessReport, ConditionSummary, MoveResult, TrialTotals};
pub use script::{ChessScript, MoveTimes, chess_script, chess_v2r};

use crate::MappingError;

/// How one run plays: intent on or off, the one-way delay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChessCase {
    /// The robot anticipates the piece the hand reaches for.
    pub intent: bool,
    /// One-way delay between the operator and the robot (s), both ways of the loop.
    pub delay_s: f64,
}

/// Seconds run after the last move (the last placement and retreat).
pub const TAIL_S: f64 = 2.0;
/// The finger's half-width around the tool point (m): a tool point closer than this to another
/// piece's side (below its top) touches it.
pub const FINGER_HALF_WIDTH_M: f64 = 0.01;

/// The twins of the pieces in the hand's world, in the set-up's order.
#[derive(Resource, Debug, Clone, Default)]
pub struct ChessTwins(pub Vec<Entity>);

/// The robot's settings for `task` on `setup`: a top grasp (the tool's approach axis down,
/// its x away from the robot's base toward the board), the clearance 3 cm above the tallest
/// piece, the pre-grasp 3 cm above the grasp, 1.5 cm below a piece's top; moves between grasps
/// capped at 96 % of the TCP cap; the carry's closed loop at the task's gain.
pub fn robot_settings(task: &ChessTask, setup: &ChessSetup) -> PickPlaceSettings {
    let board = task.board_pose().translation.vector;
    let radial = Vector3::new(
        board.x - setup.base.translation.x,
        board.y - setup.base.translation.y,
        0.0,
    )
    .try_normalize(1e-9)
    .unwrap_or_else(Vector3::x);
    let down = -Vector3::z();
    let y = down.cross(&radial);
    let dt = 1.0 / setup.control_rate_hz;
    PickPlaceSettings {
        clearance_z: task.board_top() + setup.tallest_m() + 0.03,
        hover_m: 0.03,
        grasp_depth_m: 0.015,
        tool_down: UnitQuaternion::from_matrix(&Matrix3::from_columns(&[radial, y, down])),
        arrive_m: 0.003,
        arrive_rad: 0.03,
        over_m: 0.02,
        gain_per_s: 5.0,
        max_speed: task.max_tcp_speed * 0.96,
        max_turn: 1.5,
        place_m: 0.002,
        place_rad: 0.03,
        place_timeout_s: 1.0,
        mapping: MappingSettings {
            gain: task.gain,
            dls: avatarm_core::robot::ik::DlsSettings {
                dt,
                ..Default::default()
            },
            ..MappingSettings::default()
        },
    }
}

/// The arm's ready pose before the first move: the tool over the board's centre at the
/// clearance height, pointing down (as the pouring task starts with the gripper around the
/// bottle, a lab starts the game with the arm over the board). Errors when no joint positions
/// reach it.
pub fn ready_configuration(
    task: &ChessTask,
    setup: &ChessSetup,
    settings: &PickPlaceSettings,
) -> Result<DVector<f64>, MappingError> {
    let c = task.board_pose().translation.vector;
    let ready = Isometry3::from_parts(
        nalgebra::Translation3::new(c.x, c.y, settings.clearance_z),
        settings.tool_down,
    );
    avatarm_core::robot::ik::solve_pose(
        &setup.model,
        &setup.base,
        setup.tcp,
        &setup.arm,
        &setup.q_start,
        &ready,
    )
    .map_err(|e| MappingError::Grasp {
        source: Box::new(e),
    })
}

/// The real pieces as the simulated arm holds them: each piece's body centre, grasped when the
/// tool point comes within its centre's distance from the grasp pose plus 1 cm.
fn real_pieces(setup: &ChessSetup, settings: &PickPlaceSettings) -> Vec<CarriedObject> {
    setup
        .centres
        .iter()
        .zip(&setup.sizes)
        .map(|(c, &(_, h))| CarriedObject {
            pose: *c,
            rest_z: c.translation.z,
            grasp_radius_m: (h / 2.0 - settings.grasp_depth_m).abs() + 0.01,
            held: None,
        })
        .collect()
}

/// The startup system that spawns the virtual board and each piece's twin (z-up cylinders,
/// `k` times the real size, dynamic, [`GraspTarget`]) and records them in [`ChessTwins`].
fn spawn_twins(
    task: &ChessTask,
    setup: &ChessSetup,
    v2r: &VirtualToReal,
) -> impl FnMut(Commands) + Send + Sync + 'static {
    let k = task.k as f32;
    let top = v2r.virtual_pose(&task.board_pose());
    let board = avatarm_twin::iso_to_transform(&top);
    // The desk around the board, so that a twin knocked off the board lands on it.
    let half = (4.0 * task.square_m as f32 + 0.02) * k + 0.6;
    let twins: Vec<(Transform, f32, f32)> = setup
        .centres
        .iter()
        .zip(&setup.sizes)
        .map(|(c, &(r, h))| {
            (
                avatarm_twin::iso_to_transform(&v2r.virtual_pose(c)),
                r as f32 * k,
                h as f32 * k,
            )
        })
        .collect();
    let (mass, friction) = (task.mass_kg as f32, task.friction as f32);
    move |mut commands: Commands| {
        commands.spawn((
            Name::new("virtual desk and chess board"),
            RigidBody::Fixed,
            Collider::cuboid(half, half, 0.02),
            Friction::coefficient(0.8),
            Transform::from_translation(board.translation - Vec3::Z * 0.02)
                .with_rotation(board.rotation),
        ));
        let up = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
        let entities = twins
            .iter()
            .map(|&(at, r, h)| {
                commands
                    .spawn((
                        Name::new("piece twin"),
                        GraspTarget,
                        RigidBody::Dynamic,
                        Collider::compound(vec![(Vec3::ZERO, up, Collider::cylinder(h / 2.0, r))]),
                        ColliderMassProperties::Mass(mass),
                        Friction::coefficient(friction),
                        Ccd::enabled(),
                        Velocity::zero(),
                        at,
                    ))
                    .id()
            })
            .collect();
        commands.insert_resource(ChessTwins(entities));
    }
}

/// The operator's hand world of a chess trial: [`avatarm_hand::headless_app`] with `hand`, the
/// task's hand filter, the virtual board and the pieces' twins.
pub fn chess_hand_app(
    task: &ChessTask,
    setup: &ChessSetup,
    v2r: &VirtualToReal,
    hand: ActiveHand,
) -> App {
    let period = Duration::from_secs_f64(1.0 / setup.control_rate_hz);
    let mut app = avatarm_hand::headless_app(period);
    app.insert_resource(HandDrive {
        filter: task.hand_filter,
        ..HandDrive::default()
    })
    .insert_resource(hand)
    .add_systems(Startup, spawn_twins(task, setup, v2r));
    app
}

/// What the operator's side reads from the hand's world after a step.
struct OperatorView {
    now_s: f64,
    twins: Vec<Isometry3<f64>>,
    held: Option<usize>,
    palm: Option<(Vector3<f64>, f64)>,
}

fn read_operator(
    world: &mut World,
    contacts: &mut Vec<avatarm_core::teleop::grasp::Contact>,
    velocities: &mut Vec<Vector3<f64>>,
) -> Result<OperatorView, MappingError> {
    let missing = |what: &str| MappingError::Trial {
        message: format!("the chess hand world has no {what}"),
    };
    let entities = world
        .get_resource::<ChessTwins>()
        .ok_or_else(|| missing("ChessTwins"))?
        .0
        .clone();
    let twins = entities
        .iter()
        .map(|&e| {
            world
                .get::<Transform>(e)
                .map(avatarm_twin::transform_to_iso)
                .ok_or_else(|| missing("twin"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let held_entity = world
        .get_resource::<HeldObject>()
        .ok_or_else(|| missing("HeldObject"))?
        .held
        .map(|(e, _)| e);
    let held = held_entity.and_then(|e| entities.iter().position(|&x| x == e));
    contacts.clear();
    velocities.clear();
    if let Some(e) = held_entity {
        let found = world
            .get_resource::<ObjectContacts>()
            .ok_or_else(|| missing("ObjectContacts"))?;
        for c in found.contacts.iter().filter(|c| c.object == e) {
            contacts.push(c.contact);
            velocities.push(c.object_velocity);
        }
    }
    let palm = world
        .get_resource::<ActiveHand>()
        .ok_or_else(|| missing("ActiveHand"))?
        .latest
        .as_ref()
        .filter(|f| f.tracked)
        .and_then(|f| {
            let p = f.joints.get(PALM)?.pose.translation.vector;
            Some((p, avatarm_hand::closure(f).unwrap_or(f64::NAN)))
        });
    Ok(OperatorView {
        now_s: world
            .get_resource::<Time<Fixed>>()
            .ok_or_else(|| missing("Time<Fixed>"))?
            .elapsed_secs_f64(),
        twins,
        held,
        palm,
    })
}

/// A command on its way to the robot: when it arrives, when it was made, what it says.
type InFlight = (f64, f64, PickPlaceCommand);

/// The operator's side of the loop across ticks.
struct Operator {
    v2r: VirtualToReal,
    estimator: Option<IntentEstimator>,
    last_object: Option<usize>,
    contacts: Vec<avatarm_core::teleop::grasp::Contact>,
    velocities: Vec<Vector3<f64>>,
    /// Ticks whose target the mapping's operator side refused.
    refused: u64,
}

impl Operator {
    /// The command of this tick from the hand's world.
    fn command(&mut self, view: &OperatorView) -> Result<PickPlaceCommand, MappingError> {
        if view.held.is_some()
            && view.held != self.last_object
            && let Some(e) = self.estimator.as_mut()
        {
            e.reset();
        }
        if view.held.is_some() {
            self.last_object = view.held;
        }
        let target = match self.last_object {
            Some(i) => {
                let held = view.held == Some(i);
                let (c, v): (&[_], &[_]) = if held {
                    (&self.contacts, &self.velocities)
                } else {
                    (&[], &[])
                };
                // A twin knocked off the table, or contacts the grasp matrix refuses: no target
                // this tick (the robot holds or is stopped by the watchdog), counted.
                Mapper::operator_side(
                    &OperatorInputs {
                        contacts: c,
                        contact_velocities: v,
                        twin_pose: view.twins[i],
                        held,
                        stamp_s: view.now_s,
                    },
                    &self.v2r,
                )
                .inspect_err(|_| self.refused += 1)
                .ok()
            }
            None => None,
        };
        let (mut intent, mut intent_near) = (None, false);
        if let (Some(e), None, Some((palm, aperture))) =
            (self.estimator.as_mut(), view.held, view.palm)
        {
            let goals: Vec<Option<Vector3<f64>>> = view
                .twins
                .iter()
                .map(|t| Some(t.translation.vector))
                .collect();
            let est = e.update(view.now_s, &palm, aperture, &goals);
            intent = est.goal;
            intent_near = est.near;
        }
        Ok(PickPlaceCommand {
            object: self.last_object,
            target,
            intent,
            intent_near,
        })
    }
}

/// One trial's record: each move's result and the run's wall time.
#[derive(Debug, Clone)]
pub struct ChessTrialRecord {
    /// Per move.
    pub moves: Vec<MoveResult>,
    /// Wall time of the trial's loop (s).
    pub wall_s: f64,
    /// Control ticks the limiter was stopping the robot.
    pub stop_ticks: u64,
    /// Largest commanded TCP speed (m/s).
    pub max_tcp_speed: f64,
    /// Ticks whose target the operator's side refused (a twin knocked off the table).
    pub refused_ticks: u64,
}

/// Runs trial `trial` of the chess task in `case`. Errors when the set-up cannot work (bad
/// settings, the hand's world broken).
pub fn run_chess_trial(
    task: &ChessTask,
    setup: &ChessSetup,
    trial: u32,
    case: ChessCase,
) -> Result<ChessTrialRecord, MappingError> {
    task.validate()?;
    if !(case.delay_s.is_finite() && case.delay_s >= 0.0) {
        return Err(MappingError::Setup {
            message: format!("delay {} s must be >= 0", case.delay_s),
        });
    }
    let v2r = chess_v2r(task);
    let plan = chess_script(task, setup, &v2r, trial)?;
    let settings = robot_settings(task, setup);
    let hand = ActiveHand::new(ScriptedHand::new(plan.script.clone(), task.hand_rate_hz));
    let mut app = chess_hand_app(task, setup, &v2r, hand);
    let dt = 1.0 / setup.control_rate_hz;
    let q_ready = ready_configuration(task, setup, &settings)?;
    let mut arm = SimArm::with_objects(
        SimRobot::new(setup.sim, setup.model.dof_limits(), q_ready),
        setup.model.clone(),
        setup.base,
        setup.tcp,
        real_pieces(setup, &settings),
    )?;
    let objects: Vec<PickObject> = setup
        .centres
        .iter()
        .zip(&setup.sizes)
        .map(|(&pose, &(radius_m, height_m))| PickObject {
            pose,
            radius_m,
            height_m,
        })
        .collect();
    let mut robot = PickPlaceRobot::new(
        settings,
        setup.model.clone(),
        setup.base,
        setup.tcp,
        setup.arm.clone(),
        objects,
    )?;
    let safety = SafetySettings {
        max_tcp_speed: task.max_tcp_speed,
        timeout_s: case.delay_s + 0.1,
        ..SafetySettings::default()
    };
    safety.validate()?;
    let mut limiter = SafetyLimiter::new(safety, setup.model.dof_limits());
    let mut operator = Operator {
        v2r,
        estimator: if case.intent {
            Some(IntentEstimator::new(task.intent, setup.pieces.len())?)
        } else {
            None
        },
        last_object: None,
        contacts: Vec::new(),
        velocities: Vec::new(),
        refused: 0,
    };
    let mut meter = report::Meter::new(task, setup, &plan, case, trial);
    let end_s = plan.moves.last().map_or(0.0, |m| m.end_s) + TAIL_S;
    let steps = (end_s / dt).round() as usize;
    let mut queue: VecDeque<InFlight> = VecDeque::new();
    let mut delivered: Option<(f64, PickPlaceCommand)> = None;
    let mut joints: Option<JointState> = None;
    let mut last_step_s = None;
    let (mut stop_ticks, mut max_tcp_speed) = (0u64, 0.0f64);
    let n = setup.model.dof();
    let started = std::time::Instant::now();
    for _ in 0..steps {
        app.update();
        let view = read_operator(
            app.world_mut(),
            &mut operator.contacts,
            &mut operator.velocities,
        )?;
        let stepped = view.now_s > 0.0 && last_step_s != Some(view.now_s);
        last_step_s = Some(view.now_s);
        if !stepped {
            continue;
        }
        let now = view.now_s;
        let command = operator.command(&view)?;
        queue.push_back((now + case.delay_s, now, command));
        // The robot's side.
        arm.advance(now);
        if let Some(s) = arm.receive().into_iter().last() {
            joints = Some(s);
        }
        while queue.front().is_some_and(|(at, _, _)| *at <= now + 1e-9) {
            let (_, made, c) = queue.pop_front().expect("checked");
            delivered = Some((made, c));
        }
        let q: Vec<f64> = joints
            .as_ref()
            .map(|s| s.positions.iter().copied().collect())
            .unwrap_or_else(|| vec![f64::NAN; n]);
        let tick: Option<PickTick> = match &joints {
            Some(j) => robot
                .tick(delivered.as_ref().map(|d| &d.1), &q, now, j.stamp_s)
                .ok(),
            None => None,
        };
        let (qdot, jacobian) = match &tick {
            Some(t) => (t.qdot.clone(), t.tcp_jacobian.clone()),
            None => (DVector::from_element(n, f64::NAN), Matrix6xX::zeros(n)),
        };
        let limited = limiter.tick(
            &safety::TickInputs {
                now_s: now,
                qdot: &qdot,
                q: &q,
                joints_stamp_s: joints.as_ref().map(|s| s.stamp_s),
                hand_stamp_s: delivered.as_ref().map(|d| d.0),
                hand_tracked: true,
                jacobian: &jacobian,
            },
            dt,
        );
        max_tcp_speed = max_tcp_speed.max(limited.tcp_speed);
        if limited.stopping {
            stop_ticks += 1;
        }
        if let Some(c) = &limited.command {
            arm.send(c)?;
        }
        if let Some(t) = &tick
            && !limited.stopping
        {
            arm.gripper(&t.gripper)?;
        }
        meter.tick(&report::TickView {
            now_s: now,
            held: view.held,
            tick: tick.as_ref(),
            delivered: delivered.as_ref().map(|d| &d.1),
            arm: &arm,
            tool: tool_pose(setup, &arm),
        });
    }
    Ok(ChessTrialRecord {
        moves: meter.finish(),
        wall_s: started.elapsed().as_secs_f64(),
        stop_ticks,
        max_tcp_speed,
        refused_ticks: operator.refused,
    })
}

/// The tool's true pose (world) of the simulated arm.
fn tool_pose(setup: &ChessSetup, arm: &SimArm) -> Isometry3<f64> {
    let q: Vec<f64> = arm.robot().true_positions().iter().copied().collect();
    setup.model.forward_kinematics(&setup.base, &q)[setup.tcp]
}

/// Every trial of the task in every case (intent off and on at each of `task.delays_ms`),
/// summarised per case; `progress(done, total)` after each trial.
pub fn run_chess(
    task: &ChessTask,
    setup: &ChessSetup,
    mut progress: impl FnMut(usize, usize),
) -> Result<ChessReport, MappingError> {
    task.validate()?;
    let mut cases = Vec::new();
    for &delay_ms in &task.delays_ms {
        for intent in [false, true] {
            cases.push(ChessCase {
                intent,
                delay_s: delay_ms / 1000.0,
            });
        }
    }
    let total = cases.len() * task.trials as usize;
    let mut done = 0;
    let mut conditions = Vec::new();
    for case in cases {
        let mut moves = Vec::new();
        let mut totals = TrialTotals::default();
        for trial in 0..task.trials {
            let record = run_chess_trial(task, setup, trial, case)?;
            moves.extend(record.moves);
            totals.wall_s += record.wall_s;
            totals.stop_ticks += record.stop_ticks;
            totals.refused_ticks += record.refused_ticks;
            totals.max_tcp_speed = totals.max_tcp_speed.max(record.max_tcp_speed);
            done += 1;
            progress(done, total);
        }
        conditions.push(ChessCondition::of(case, moves, totals));
    }
    Ok(ChessReport {
        moves_per_trial: setup.moves.len(),
        trials: task.trials,
        conditions,
    })
}

/// Where the tool was going, as a piece index, if toward a piece.
pub(crate) fn goal_piece(goal: Option<PickGoal>) -> Option<usize> {
    match goal? {
        PickGoal::Hover(i) | PickGoal::Around(i) => Some(i),
        PickGoal::Grasp(_) => None,
    }
}

/// The phase's carried piece, if carrying.
pub(crate) fn carried(phase: PickPhase) -> Option<usize> {
    match phase {
        PickPhase::Carry { object } => Some(object),
        _ => None,
    }
}

#[cfg(test)]
mod tests;
