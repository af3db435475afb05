//! One game's control loop, tick by tick: what the bench's trials and the live run
//! (`avatarm run` with a `[chess]` scene) both step.
//!
//! Each control tick [`ChessGame::step`] reads the operator's hand world (the twins, the one
//! the hand holds, its contacts, the palm and the hand's aperture), makes the operator's
//! command ([`Operator`]: the mapping's target for the held twin, the intent estimate while
//! the hand holds nothing), passes it through the one-way delay, and ticks the robot's side:
//! [`PickPlaceRobot`] → [`SafetyLimiter`] → the simulated arm holding every real piece
//! ([`SimArm::with_objects`]). Each tick is measured ([`report::Meter`]).

use std::collections::VecDeque;

use avatarm_core::sim::arm::{CarriedObject, RobotInterface, SimArm};
use avatarm_core::sim::{JointState, SimRobot};
use avatarm_core::teleop::grasp::Contact;
use avatarm_core::teleop::hand::PALM;
use avatarm_core::teleop::intent::IntentEstimator;
use avatarm_core::teleop::mapping::{Mapper, OperatorInputs, VirtualToReal};
use avatarm_core::teleop::pick_place::{
    PickObject, PickPhase, PickPlaceCommand, PickPlaceRobot, PickPlaceSettings, PickTick,
};
use avatarm_core::teleop::safety::{self, SafetyLimiter, SafetySettings};
use avatarm_hand::{ActiveHand, HeldObject, ObjectContacts};
use avatarm_scene::chess::{ChessSetup, ChessTask};
use bevy::prelude::*;
use nalgebra::{DVector, Isometry3, Matrix6xX, Vector3};

use super::report::{self, MoveResult};
use super::{ChessCase, ChessTwins, ready_configuration, robot_settings};
use crate::MappingError;

/// What the operator's side reads from the hand's world after a physics step.
#[derive(Debug, Clone)]
pub struct OperatorView {
    /// The hand world's fixed clock (s).
    pub now_s: f64,
    /// Each piece's twin (virtual scene), in the set-up's order.
    pub twins: Vec<Isometry3<f64>>,
    /// The twin the hand holds.
    pub held: Option<usize>,
    /// The palm (virtual scene, m) and the hand's aperture (mean fingertip distance to the
    /// palm, m; NaN when unknown), while the hand is tracked.
    pub palm: Option<(Vector3<f64>, f64)>,
}

/// Reads the operator's view from a hand world with [`ChessTwins`] (the contacts on the held
/// twin into `contacts` and `velocities`). Errors name the resource or component missing.
fn read_operator(
    world: &mut World,
    contacts: &mut Vec<Contact>,
    velocities: &mut Vec<Vector3<f64>>,
) -> Result<OperatorView, MappingError> {
    let missing = |what: &str| MappingError::Trial {
        message: format!("the chess hand world has no {what}"),
    };
    let entities = &world
        .get_resource::<ChessTwins>()
        .ok_or_else(|| missing("ChessTwins"))?
        .0;
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
    contacts: Vec<Contact>,
    velocities: Vec<Vector3<f64>>,
    /// Ticks whose target the mapping's operator side refused.
    refused: u64,
}

impl Operator {
    /// The command of this tick from the hand's world.
    fn command(&mut self, view: &OperatorView) -> PickPlaceCommand {
        if view.held.is_some()
            && view.held != self.last_object
            && let Some(e) = self.estimator.as_mut()
        {
            e.reset();
        }
        if view.held.is_some() {
            self.last_object = view.held;
        }
        let target = self.last_object.and_then(|i| {
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
        });
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
        PickPlaceCommand {
            object: self.last_object,
            target,
            intent,
            intent_near,
        }
    }
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

/// One trial's record: each move's result and the run's totals.
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

/// One game of the chess task: the operator's side, the delay, the robot's side and the
/// simulated arm with the real pieces, measured; stepped once per control tick after the hand
/// world's physics step ([`ChessGame::step`]).
pub struct ChessGame {
    setup: ChessSetup,
    delay_s: f64,
    dt: f64,
    operator: Operator,
    robot: PickPlaceRobot,
    limiter: SafetyLimiter,
    arm: SimArm,
    queue: VecDeque<InFlight>,
    delivered: Option<(f64, PickPlaceCommand)>,
    joints: Option<JointState>,
    received: Vec<JointState>,
    last_step_s: Option<f64>,
    held: Option<usize>,
    stop_ticks: u64,
    max_tcp_speed: f64,
    meter: report::Meter,
}

impl ChessGame {
    /// A game of `task` on `setup` in `case`, the arm ready over the board
    /// ([`ready_configuration`]). `move_starts` are the times (s, the hand world's clock) at
    /// which the operator starts each move, where a script knows them (the bench's scripted
    /// hand); `None` for a live hand, whose current move is the first one not yet placed.
    /// `trial` labels the results. Errors when the settings are invalid or the arm cannot
    /// reach its ready pose.
    pub fn new(
        task: &ChessTask,
        setup: &ChessSetup,
        case: ChessCase,
        move_starts: Option<Vec<f64>>,
        trial: u32,
    ) -> Result<Self, MappingError> {
        if !(case.delay_s.is_finite() && case.delay_s >= 0.0) {
            return Err(MappingError::Setup {
                message: format!("delay {} s must be >= 0", case.delay_s),
            });
        }
        let settings = robot_settings(task, setup);
        let q_ready = ready_configuration(task, setup, &settings)?;
        let arm = SimArm::with_objects(
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
        let robot = PickPlaceRobot::new(
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
        let estimator = if case.intent {
            Some(IntentEstimator::new(task.intent, setup.pieces.len())?)
        } else {
            None
        };
        Ok(Self {
            setup: setup.clone(),
            delay_s: case.delay_s,
            dt: 1.0 / setup.control_rate_hz,
            operator: Operator {
                v2r: super::chess_v2r(task),
                estimator,
                last_object: None,
                contacts: Vec::new(),
                velocities: Vec::new(),
                refused: 0,
            },
            robot,
            limiter: SafetyLimiter::new(safety, setup.model.dof_limits()),
            arm,
            queue: VecDeque::new(),
            delivered: None,
            joints: None,
            received: Vec::new(),
            last_step_s: None,
            held: None,
            stop_ticks: 0,
            max_tcp_speed: 0.0,
            meter: report::Meter::new(task, setup, move_starts, case, trial),
        })
    }

    /// One control tick after the hand world's physics step: reads the operator's view from
    /// `world`, then ticks the operator's side, the delay and the robot's side. Returns whether
    /// it ticked (`false` when the world's fixed clock has not advanced since the last call).
    /// Errors when the world lacks the chess hand world's parts or the arm refuses a command.
    pub fn step(&mut self, world: &mut World) -> Result<bool, MappingError> {
        self.received.clear();
        let view = read_operator(
            world,
            &mut self.operator.contacts,
            &mut self.operator.velocities,
        )?;
        let stepped = view.now_s > 0.0 && self.last_step_s != Some(view.now_s);
        self.last_step_s = Some(view.now_s);
        if stepped {
            self.tick(&view)?;
        }
        Ok(stepped)
    }

    fn tick(&mut self, view: &OperatorView) -> Result<(), MappingError> {
        let now = view.now_s;
        self.held = view.held;
        let command = self.operator.command(view);
        self.queue.push_back((now + self.delay_s, now, command));
        // The robot's side.
        self.arm.advance(now);
        self.received = self.arm.receive();
        if let Some(s) = self.received.last() {
            self.joints = Some(s.clone());
        }
        while let Some((_, made, c)) = self.queue.pop_front_if(|(at, _, _)| *at <= now + 1e-9) {
            self.delivered = Some((made, c));
        }
        let n = self.setup.model.dof();
        let q: Vec<f64> = self
            .joints
            .as_ref()
            .map(|s| s.positions.iter().copied().collect())
            .unwrap_or_else(|| vec![f64::NAN; n]);
        let tick: Option<PickTick> = self.joints.as_ref().and_then(|j| {
            self.robot
                .tick(self.delivered.as_ref().map(|d| &d.1), &q, now, j.stamp_s)
                .ok()
        });
        // No tick (refused, or before a joint state): a NaN command, which the limiter turns
        // into a ramped stop.
        let refused;
        let (qdot, jacobian) = match &tick {
            Some(t) => (&t.qdot, &t.tcp_jacobian),
            None => {
                refused = (DVector::from_element(n, f64::NAN), Matrix6xX::zeros(n));
                (&refused.0, &refused.1)
            }
        };
        let limited = self.limiter.tick(
            &safety::TickInputs {
                now_s: now,
                qdot,
                q: &q,
                joints_stamp_s: self.joints.as_ref().map(|s| s.stamp_s),
                hand_stamp_s: self.delivered.as_ref().map(|d| d.0),
                hand_tracked: true,
                jacobian,
            },
            self.dt,
        );
        self.max_tcp_speed = self.max_tcp_speed.max(limited.tcp_speed);
        if limited.stopping {
            self.stop_ticks += 1;
        }
        if let Some(c) = &limited.command {
            self.arm.send(c)?;
        }
        if let Some(t) = &tick
            && !limited.stopping
        {
            self.arm.gripper(&t.gripper)?;
        }
        self.meter.tick(&report::TickView {
            now_s: now,
            held: view.held,
            tick: tick.as_ref(),
            delivered: self.delivered.as_ref().map(|d| &d.1),
            arm: &self.arm,
            tool: self.tool_pose(),
        });
        Ok(())
    }

    /// The tool's true pose (world) of the simulated arm.
    fn tool_pose(&self) -> Isometry3<f64> {
        let q: Vec<f64> = self.arm.robot().true_positions().iter().copied().collect();
        self.setup.model.forward_kinematics(&self.setup.base, &q)[self.setup.tcp]
    }

    /// The simulated arm and the real pieces (their true poses: [`SimArm::objects`]).
    pub fn arm(&self) -> &SimArm {
        &self.arm
    }

    /// The robot side's phase after the last tick.
    pub fn phase(&self) -> PickPhase {
        self.robot.phase()
    }

    /// The intent estimate the robot had at the last tick (a piece's index), if any.
    pub fn intent(&self) -> Option<usize> {
        self.delivered.as_ref().and_then(|d| d.1.intent)
    }

    /// The twin the hand held at the last tick.
    pub fn held(&self) -> Option<usize> {
        self.held
    }

    /// The joint states the arm sent that arrived at the last tick (oldest first).
    pub fn received(&self) -> &[JointState] {
        &self.received
    }

    /// The moves measured so far (a move not yet played has no grasp or placement).
    pub fn moves(&self) -> Vec<MoveResult> {
        self.meter.results()
    }

    /// The game's record; `wall_s` is the caller's.
    pub fn finish(self, wall_s: f64) -> ChessTrialRecord {
        ChessTrialRecord {
            moves: self.meter.results(),
            wall_s,
            stop_ticks: self.stop_ticks,
            max_tcp_speed: self.max_tcp_speed,
            refused_ticks: self.operator.refused,
        }
    }
}
