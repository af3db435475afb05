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

pub mod game;
pub mod report;
pub mod script;

use std::time::Duration;

use avatarm_core::teleop::mapping::{MappingSettings, VirtualToReal};
use avatarm_core::teleop::pick_place::{PickGoal, PickPhase, PickPlaceSettings};
use avatarm_hand::{ActiveHand, FixedUntilGrasped, GraspTarget, HandDrive, ScriptedHand};
use avatarm_scene::chess::{ChessSetup, ChessTask};
use bevy::prelude::*;
use bevy_rapier3d::prelude::*;
use nalgebra::{DVector, Isometry3, Matrix3, UnitQuaternion, Vector3};

pub use game::{ChessGame, ChessTrialRecord, OperatorView};
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

/// The twins of the pieces in the hand's world, in the set-up's order.
#[derive(Resource, Debug, Clone, Default)]
pub struct ChessTwins(pub Vec<Entity>);

/// The robot's settings for `task` on `setup`: a top grasp (the tool's approach axis down,
/// its x away from the robot's base toward the board), the clearance 3 cm above the tallest
/// piece (between grasps, 3 cm above the tallest piece beside the way), the pre-grasp 3 cm above the grasp, 1.5 cm below a piece's top; moves between grasps
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
        clear_m: 0.03,
        tool_radius_m: task.gripper_reach_m,
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

/// The startup system that spawns the virtual board (with a desk around it) and each piece's
/// twin (z-up cylinders, `k` times the real size, dynamic, [`GraspTarget`], in the operator's
/// virtual scene) and records them in [`ChessTwins`]: the hand world of the bench's trials and
/// of the live run.
pub fn spawn_chess_twins(
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
                        FixedUntilGrasped::default(),
                        RigidBody::Fixed,
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
    .add_systems(Startup, spawn_chess_twins(task, setup, v2r));
    app
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
    play_trial(task, setup, trial, case)
}

/// [`run_chess_trial`] on a task already validated.
fn play_trial(
    task: &ChessTask,
    setup: &ChessSetup,
    trial: u32,
    case: ChessCase,
) -> Result<ChessTrialRecord, MappingError> {
    let v2r = chess_v2r(task);
    let plan = chess_script(task, setup, &v2r, trial)?;
    let hand = ActiveHand::new(ScriptedHand::new(plan.script.clone(), task.hand_rate_hz));
    let mut app = chess_hand_app(task, setup, &v2r, hand);
    let starts = plan.moves.iter().map(|m| m.start_s).collect();
    let mut game = ChessGame::new(task, setup, case, Some(starts), trial)?;
    let end_s = plan.moves.last().map_or(0.0, |m| m.end_s) + TAIL_S;
    let steps = (end_s / (1.0 / setup.control_rate_hz)).round() as usize;
    let started = std::time::Instant::now();
    for _ in 0..steps {
        app.update();
        game.step(app.world_mut())?;
    }
    Ok(game.finish(started.elapsed().as_secs_f64()))
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
            let record = play_trial(task, setup, trial, case)?;
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
