//! What a chess trial measures, move by move, and its summary per case.

use std::collections::BTreeSet;

use avatarm_core::sim::arm::SimArm;
use avatarm_core::stats::Spread;
use avatarm_core::teleop::mapping::PoseErrors;
use avatarm_core::teleop::pick_place::{PickPhase, PickPlaceCommand, PickTick};
use avatarm_scene::chess::{ChessSetup, ChessTask};
use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use super::{ChessCase, carried, goal_piece};

/// One move's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MoveResult {
    /// Trial.
    pub trial: u32,
    /// The move's index in the opening.
    pub index: usize,
    /// The move ("e2e4").
    pub notation: String,
    /// The piece it moves.
    pub piece: String,
    /// Intent on.
    pub intent: bool,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// When the hand took the piece's twin (s, the trial's clock).
    pub virtual_grasp_s: Option<f64>,
    /// When the gripper took the real piece (s).
    pub real_grasp_s: Option<f64>,
    /// `real_grasp_s − virtual_grasp_s` (ms).
    pub grasp_delay_ms: Option<f64>,
    /// The real piece the gripper took, if any (its name).
    pub grasped: Option<String>,
    /// The real piece's distance from its square's centre once let go (mm).
    pub place_error_mm: Option<f64>,
    /// The real piece's distance from where the operator set its twin down, mapped (mm).
    pub follow_error_mm: Option<f64>,
    /// The right piece on the right square (within half a square of its centre).
    pub correct: bool,
    /// Pieces other than this move's the robot went toward before the real grasp.
    pub wrong_pregrasps: u32,
    /// Times the tool (or the piece it carried) touched a piece it was not sent to.
    pub touches: u32,
    /// The intent estimate named this move's piece this long before the virtual grasp (ms;
    /// negative: after); `None` without intent or when it never did.
    pub intent_lead_ms: Option<f64>,
    /// Position RMSE between the mapping's target and the real piece while carried (mm).
    pub carry_pos_rmse_mm: Option<f64>,
    /// Orientation RMSE while carried (the largest of roll, pitch, yaw; degrees).
    pub carry_rot_rmse_deg: Option<f64>,
}

/// One case's summary over every trial's moves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConditionSummary {
    /// Moves played.
    pub moves: usize,
    /// Moves that put the right piece on the right square.
    pub correct: usize,
    /// Virtual grasp to real grasp (ms).
    pub grasp_delay_ms: Spread,
    /// The real pieces' distance from their squares' centres (mm).
    pub place_error_mm: Spread,
    /// The real pieces' distance from where their twins were set down (mm).
    pub follow_error_mm: Spread,
    /// Pre-grasps toward a wrong piece, all moves.
    pub wrong_pregrasps: u32,
    /// Virtual to real grasp of the moves that had a wrong pre-grasp (ms): their cost.
    pub grasp_delay_after_wrong_ms: Spread,
    /// Touches of pieces the tool was not sent to, all moves.
    pub touches: u32,
    /// How long before the virtual grasp the estimate named the right piece (ms).
    pub intent_lead_ms: Spread,
    /// Mean position RMSE while carried (mm).
    pub carry_pos_rmse_mm: f64,
    /// Mean orientation RMSE while carried (degrees).
    pub carry_rot_rmse_deg: f64,
    /// Ticks the limiter was stopping the robot.
    pub stop_ticks: u64,
    /// Largest commanded TCP speed (m/s).
    pub max_tcp_speed: f64,
    /// Ticks whose target the operator's side refused (a twin knocked off the table).
    pub refused_ticks: u64,
    /// Wall time of the trials (s).
    pub wall_s: f64,
}

/// One case (intent on or off at one delay) over every trial.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChessCondition {
    /// Intent on.
    pub intent: bool,
    /// One-way delay (ms).
    pub delay_ms: f64,
    /// The summary.
    pub summary: ConditionSummary,
    /// Every move.
    pub moves: Vec<MoveResult>,
}

/// What a case's trials add up to besides their moves.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrialTotals {
    /// Wall time of the trials (s).
    pub wall_s: f64,
    /// Control ticks the safety layer stopped the robot in.
    pub stop_ticks: u64,
    /// The robot's fastest tool-centre-point speed (m/s).
    pub max_tcp_speed: f64,
    /// Control ticks whose operator sample was refused.
    pub refused_ticks: u64,
}

impl ChessCondition {
    /// Summarises `moves` of `case`, with its trials' `totals`.
    pub fn of(case: ChessCase, moves: Vec<MoveResult>, totals: TrialTotals) -> Self {
        let TrialTotals {
            wall_s,
            stop_ticks,
            max_tcp_speed,
            refused_ticks,
        } = totals;
        let col = |f: fn(&MoveResult) -> Option<f64>| -> Vec<f64> {
            moves.iter().filter_map(f).collect()
        };
        let mean = |v: Vec<f64>| {
            if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let after_wrong: Vec<f64> = moves
            .iter()
            .filter(|m| m.wrong_pregrasps > 0)
            .filter_map(|m| m.grasp_delay_ms)
            .collect();
        Self {
            intent: case.intent,
            delay_ms: case.delay_s * 1000.0,
            summary: ConditionSummary {
                moves: moves.len(),
                correct: moves.iter().filter(|m| m.correct).count(),
                grasp_delay_ms: Spread::of(&col(|m| m.grasp_delay_ms)),
                place_error_mm: Spread::of(&col(|m| m.place_error_mm)),
                follow_error_mm: Spread::of(&col(|m| m.follow_error_mm)),
                wrong_pregrasps: moves.iter().map(|m| m.wrong_pregrasps).sum(),
                grasp_delay_after_wrong_ms: Spread::of(&after_wrong),
                touches: moves.iter().map(|m| m.touches).sum(),
                intent_lead_ms: Spread::of(&col(|m| m.intent_lead_ms)),
                carry_pos_rmse_mm: mean(col(|m| m.carry_pos_rmse_mm)),
                carry_rot_rmse_deg: mean(col(|m| m.carry_rot_rmse_deg)),
                stop_ticks,
                max_tcp_speed,
                refused_ticks,
                wall_s,
            },
            moves,
        }
    }
}

/// Every case of a chess run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChessReport {
    /// Moves in one trial.
    pub moves_per_trial: usize,
    /// Trials per case.
    pub trials: u32,
    /// Per case: intent off and on at each delay.
    pub conditions: Vec<ChessCondition>,
}

/// What the meter sees of one control tick.
pub(crate) struct TickView<'a> {
    pub now_s: f64,
    /// The twin the hand holds.
    pub held: Option<usize>,
    /// The robot side's tick (`None`: refused or before a joint state).
    pub tick: Option<&'a PickTick>,
    /// The operator's command the robot side had.
    pub delivered: Option<&'a PickPlaceCommand>,
    /// The simulated arm: the truth.
    pub arm: &'a SimArm,
    /// The tool's true pose.
    pub tool: Isometry3<f64>,
}

#[derive(Debug, Clone, Default)]
struct MoveState {
    virtual_grasp_s: Option<f64>,
    real_grasp_s: Option<f64>,
    grasped: Option<usize>,
    released: Option<(Isometry3<f64>, Option<Isometry3<f64>>)>,
    wrong_goals: BTreeSet<usize>,
    touches: u32,
    intent_first_s: Option<f64>,
    errors: PoseErrors,
}

/// Measures a trial tick by tick.
pub(crate) struct Meter {
    trial: u32,
    case: ChessCase,
    /// Per move: notation, piece, the target square's centre of the piece (world).
    moves: Vec<(String, usize, Isometry3<f64>)>,
    /// When the operator starts each move (s), where a script knows it.
    starts: Option<Vec<f64>>,
    names: Vec<String>,
    sizes: Vec<(f64, f64)>,
    /// The open gripper's reach about the tool point (m, `[chess] gripper_reach_m`).
    reach_m: f64,
    square_m: f64,
    files: Vector3<f64>,
    ranks: Vector3<f64>,
    state: Vec<MoveState>,
    last_held: Option<usize>,
    last_holding: Option<usize>,
    /// The piece the gripper let go of last: the tool rises from beside it.
    last_released: Option<usize>,
    /// The piece the open gripper was sent around at the last tick.
    last_around: Option<usize>,
    /// A piece the open gripper was around and no longer is sent to, and where the tool was
    /// then, while the tool rises straight up within its reach.
    rising_from: Option<(usize, Vector3<f64>)>,
    touching: bool,
    /// The robot's target at the last tick that had one.
    last_target: Option<Isometry3<f64>>,
}

impl Meter {
    pub fn new(
        task: &ChessTask,
        setup: &ChessSetup,
        starts: Option<Vec<f64>>,
        case: ChessCase,
        trial: u32,
    ) -> Self {
        let r = task.board_pose().rotation;
        let moves = setup
            .moves
            .iter()
            .map(|&(m, piece)| {
                (
                    format!("{}{}", m.from.name(), m.to.name()),
                    piece,
                    setup.centre_on(task, piece, m.to),
                )
            })
            .collect::<Vec<_>>();
        Self {
            trial,
            case,
            state: vec![MoveState::default(); moves.len()],
            moves,
            starts,
            names: setup.pieces.iter().map(|p| p.name.clone()).collect(),
            sizes: setup.sizes.clone(),
            reach_m: task.gripper_reach_m,
            square_m: task.square_m,
            files: r * Vector3::x(),
            ranks: r * Vector3::y(),
            last_held: None,
            last_holding: None,
            last_released: None,
            last_around: None,
            rising_from: None,
            touching: false,
            last_target: None,
        }
    }

    /// The move the operator is playing at `t_s`: by the script's clock where there is one,
    /// else the first move whose piece the robot has not let go of yet (the last move once all
    /// are).
    fn current(&self, t_s: f64) -> usize {
        match &self.starts {
            Some(starts) => starts.iter().rposition(|&s| s <= t_s).unwrap_or(0),
            None => self
                .state
                .iter()
                .position(|s| s.released.is_none())
                .unwrap_or(self.moves.len().saturating_sub(1)),
        }
    }

    /// The first move of `piece` without `done`, else the current one.
    fn of_piece(&self, piece: usize, t_s: f64, done: impl Fn(&MoveState) -> bool) -> usize {
        (0..self.moves.len())
            .find(|&m| self.moves[m].1 == piece && !done(&self.state[m]))
            .unwrap_or_else(|| self.current(t_s))
    }

    pub fn tick(&mut self, v: &TickView) {
        let now = v.now_s;
        let current = self.current(now);
        // The virtual grasp.
        if let Some(p) = v.held
            && self.last_held != Some(p)
        {
            let m = self.of_piece(p, now, |s| s.virtual_grasp_s.is_some());
            if self.state[m].virtual_grasp_s.is_none() {
                self.state[m].virtual_grasp_s = Some(now);
            }
        }
        self.last_held = v.held;
        // The real grasp and release.
        let holding = v.arm.holding();
        if holding != self.last_holding {
            if let Some(p) = holding {
                let m = self.of_piece(p, now, |s| s.real_grasp_s.is_some());
                let s = &mut self.state[m];
                if s.real_grasp_s.is_none() {
                    s.real_grasp_s = Some(now);
                    s.grasped = Some(p);
                }
            }
            if let Some(p) = self.last_holding {
                let m = (0..self.moves.len()).find(|&m| {
                    self.state[m].grasped == Some(p) && self.state[m].released.is_none()
                });
                if let Some(m) = m {
                    self.state[m].released = Some((v.arm.objects()[p].pose, self.last_target));
                }
                self.last_released = Some(p);
            }
            self.last_holding = holding;
        }
        if let Some(t) = v.tick.and_then(|t| t.target) {
            self.last_target = Some(t);
        }
        // Intent and pre-grasps toward the current move's piece, before its real grasp.
        let piece = self.moves[current].1;
        let state = &mut self.state[current];
        if state.real_grasp_s.is_none() {
            if let Some(g) = v.tick.and_then(|t| goal_piece(t.goal))
                && g != piece
            {
                state.wrong_goals.insert(g);
            }
            if state.intent_first_s.is_none() && v.delivered.and_then(|c| c.intent) == Some(piece) {
                state.intent_first_s = Some(now);
            }
        }
        // The carry's errors.
        if let Some(t) = v.tick
            && let Some(object) = carried(t.phase)
            && let Some(target) = t.target
        {
            let m = (0..self.moves.len()).find(|&m| {
                self.state[m].grasped == Some(object) && self.state[m].released.is_none()
            });
            if let Some(m) = m {
                self.state[m]
                    .errors
                    .push(&target, &v.arm.objects()[object].pose);
            }
        }
        // Touches: the tool point or the carried piece inside another piece's reach.
        let sent_to = v.tick.and_then(|t| match t.phase {
            PickPhase::Reach { object }
            | PickPhase::Carry { object }
            | PickPhase::Place { object, .. } => Some(object),
            PickPhase::Retreat => self.last_released,
            PickPhase::Free => goal_piece(t.goal),
        });
        // The open gripper at or around a piece it was sent to (a pre-grasp whose estimate then
        // changed; coming down onto the pre-grasp it may dip below the piece's top) rises
        // straight up from it, as from a piece it let go of: not a touch until it is clear.
        let around = v.tick.and_then(|t| goal_piece(t.goal));
        let tool = v.tool.translation.vector;
        if let Some(i) = self.last_around
            && around != Some(i)
            && self.within_reach(v, i)
        {
            self.rising_from = Some((i, tool));
        }
        // Only straight up: out of reach, moved 5 mm across, or 2 mm down, it is no longer
        // exempt.
        if self.rising_from.is_some_and(|(i, from)| {
            !self.within_reach(v, i)
                || Vector3::new(tool.x - from.x, tool.y - from.y, 0.0).norm() > 0.005
                || tool.z < from.z - 0.002
        }) {
            self.rising_from = None;
        }
        self.last_around = around;
        let touching = self.touches(v, holding, sent_to);
        if touching && !self.touching {
            self.state[current].touches += 1;
        }
        self.touching = touching;
    }

    /// The tool point within piece `j`'s reach: closer to its axis than its radius and the open
    /// gripper's reach, below its top (and 5 mm).
    fn within_reach(&self, v: &TickView, j: usize) -> bool {
        let Some(o) = v.arm.objects().get(j) else {
            return false;
        };
        let (c, tool) = (o.pose.translation.vector, v.tool.translation.vector);
        let (r, h) = self.sizes[j];
        Vector3::new(tool.x - c.x, tool.y - c.y, 0.0).norm() < r + self.reach_m
            && tool.z < c.z + h / 2.0 + 0.005
    }

    fn touches(&self, v: &TickView, holding: Option<usize>, sent_to: Option<usize>) -> bool {
        let objects = v.arm.objects();
        let carried = holding.map(|h| {
            let c = objects[h].pose.translation.vector;
            (c, self.sizes[h].0, c.z - self.sizes[h].1 / 2.0)
        });
        objects.iter().enumerate().any(|(j, o)| {
            if Some(j) == holding || Some(j) == sent_to || Some(j) == self.rising_from.map(|r| r.0)
            {
                return false;
            }
            let c = o.pose.translation.vector;
            let (r, h) = self.sizes[j];
            let top = c.z + h / 2.0;
            let across = |p: &Vector3<f64>| Vector3::new(p.x - c.x, p.y - c.y, 0.0).norm();
            let by_piece =
                carried.is_some_and(|(p, rp, bottom)| across(&p) < r + rp && bottom < top);
            self.within_reach(v, j) || by_piece
        })
    }

    /// Each move's result so far.
    pub fn results(&self) -> Vec<MoveResult> {
        self.moves
            .iter()
            .zip(&self.state)
            .enumerate()
            .map(|(i, ((notation, piece, square), s))| {
                let grasp_delay_ms = match (s.virtual_grasp_s, s.real_grasp_s) {
                    (Some(v), Some(r)) => Some((r - v) * 1000.0),
                    _ => None,
                };
                let place = s
                    .released
                    .map(|(pose, _)| pose.translation.vector - square.translation.vector);
                let follow = s.released.and_then(|(pose, twin)| {
                    twin.map(|t| {
                        let d = pose.translation.vector - t.translation.vector;
                        Vector3::new(d.x, d.y, 0.0).norm() * 1000.0
                    })
                });
                let inside = place.is_some_and(|d| {
                    d.dot(&self.files).abs() < self.square_m / 2.0
                        && d.dot(&self.ranks).abs() < self.square_m / 2.0
                });
                let rmse = s.errors.rmse();
                MoveResult {
                    trial: self.trial,
                    index: i,
                    notation: notation.clone(),
                    piece: self.names[*piece].clone(),
                    intent: self.case.intent,
                    delay_ms: self.case.delay_s * 1000.0,
                    virtual_grasp_s: s.virtual_grasp_s,
                    real_grasp_s: s.real_grasp_s,
                    grasp_delay_ms,
                    grasped: s.grasped.map(|g| self.names[g].clone()),
                    place_error_mm: place.map(|d| d.norm() * 1000.0),
                    follow_error_mm: follow,
                    correct: s.grasped == Some(*piece) && inside,
                    wrong_pregrasps: s.wrong_goals.len() as u32,
                    touches: s.touches,
                    intent_lead_ms: match (s.intent_first_s, s.virtual_grasp_s) {
                        (Some(f), Some(v)) => Some((v - f) * 1000.0),
                        _ => None,
                    },
                    carry_pos_rmse_mm: rmse.map(|r| r[0] * 1000.0),
                    carry_rot_rmse_deg: rmse.map(|r| r[1].max(r[2]).max(r[3])),
                }
            })
            .collect()
    }
}
