//! The operator's scripted hand for a chess trial: every move of the opening in one
//! [`HandScript`], in the virtual scene.
//!
//! Each move: from a rest pose above the operator's edge of the board, a reach (bent through a
//! seeded via point) to above the piece's approach side, down beside it, in to a side grasp
//! (palm on the side whose neighbouring square is empty, the pouring task's grasp scaled to the
//! piece), a close, a lift above the tallest piece, a carry to the target square, a set-down,
//! a release, a step back, straight up, and on to the next rest. Seeded per move: the rest (±`start_jitter_m`), the
//! via point (±`via_jitter_m`), each stretch's duration (±`time_jitter`), the grasp height
//! (1 ± 1 cm above the piece's centre) and the set-down point (±`place_jitter_m`).

use std::f64::consts::FRAC_PI_2;

use avatarm_core::rng::Rng;
use avatarm_core::teleop::hand::{HandKeyframe, HandNoise, HandScript, Handedness};
use avatarm_core::teleop::mapping::VirtualToReal;
use avatarm_scene::chess::{ChessSetup, ChessTask, Square};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::MappingError;

/// The grip of a closed hand on a piece (the pouring task's).
pub const GRIP: f64 = 0.7;

/// One move of the script: when its stretches start (s, the trial's clock).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveTimes {
    /// The hand leaves its rest.
    pub start_s: f64,
    /// The hand starts closing on the piece.
    pub close_s: f64,
    /// The hand starts opening over the target square.
    pub release_s: f64,
    /// The hand is back at rest (the next move starts).
    pub end_s: f64,
}

/// The whole trial's script and each move's times.
#[derive(Debug, Clone)]
pub struct ChessScript {
    /// The hand.
    pub script: HandScript,
    /// Per move.
    pub moves: Vec<MoveTimes>,
    /// The approach direction of each move (unit, virtual, from the palm toward the piece).
    pub approach: Vec<Vector3<f64>>,
}

/// The board's axes in the world: files, ranks (unit, horizontal).
fn board_axes(task: &ChessTask) -> (Vector3<f64>, Vector3<f64>) {
    let r = task.board_pose().rotation;
    (r * Vector3::x(), r * Vector3::y())
}

/// The square next to `square` one step along `step` (file, rank), if on the board.
fn neighbour(square: Square, step: (i8, i8)) -> Option<Square> {
    let f = square.file as i8 + step.0;
    let r = square.rank as i8 + step.1;
    ((0..8).contains(&f) && (0..8).contains(&r)).then_some(Square {
        file: f as u8,
        rank: r as u8,
    })
}

/// The approach direction for a piece on `from` going to `to` with the board's squares
/// `occupied`: the first of toward higher ranks (palm on the lower-rank side), along the files
/// either way, toward lower ranks, then the diagonals, whose palm-side square is free at both
/// ends of the move (or off the board). Returned as a board step (file, rank).
fn approach_step(from: Square, to: Square, occupied: &[Square]) -> (i8, i8) {
    let free = |s: Square, step: (i8, i8)| {
        neighbour(s, (-step.0, -step.1)).is_none_or(|n| n == from || !occupied.contains(&n))
    };
    [
        (0, 1),
        (1, 0),
        (-1, 0),
        (0, -1),
        (1, 1),
        (-1, 1),
        (1, -1),
        (-1, -1),
    ]
    .into_iter()
    .find(|&step| free(from, step) && free(to, step))
    .unwrap_or((0, 1))
}

/// The hand script of trial `trial` (its seed `task.seed + trial`) for the set-up's moves, in
/// the virtual scene `v2r`. Errors when the script is not valid.
pub fn chess_script(
    task: &ChessTask,
    setup: &ChessSetup,
    v2r: &VirtualToReal,
    trial: u32,
) -> Result<ChessScript, MappingError> {
    let seed = task.seed.wrapping_add(u64::from(trial));
    let mut rng = Rng::stream(seed, 0x4348_4553);
    let mut sym = |a: f64| (2.0 * rng.uniform() - 1.0) * a;
    let k = task.k;
    let (files, ranks) = board_axes(task);
    let board = task.board_pose();
    let top_v = v2r.virtual_pose(&board).translation.vector;
    let tallest_v = setup.tallest_m() * k;
    // Operator's side: beyond the first rank, above the board.
    let rest = |j: Vector3<f64>| top_v - ranks * (0.30 * k) + Vector3::new(0.0, 0.0, 0.22 * k) + j;
    let mut at: Vec<Square> = setup.pieces.iter().map(|p| p.square).collect();
    let mut keys = Vec::new();
    let mut times = Vec::new();
    let mut approach = Vec::new();
    let mut t = 0.0;
    let mut here = rest(Vector3::zeros());
    let tj = task.time_jitter;
    let push = |keys: &mut Vec<HandKeyframe>, t: f64, p: Vector3<f64>, yaw: f64, grip: f64| {
        keys.push(HandKeyframe {
            t_s: t,
            xyz: [p.x, p.y, p.z],
            rpy: [FRAC_PI_2, 0.0, yaw],
            grip,
            tracked: true,
        });
    };
    for &(m, piece) in &setup.moves {
        let (r, _) = setup.sizes[piece];
        let step = approach_step(m.from, m.to, &at);
        let d = (files * f64::from(step.0) + ranks * f64::from(step.1)).normalize();
        let yaw = (-d.x).atan2(d.y);
        // The hand's lower fingers clear the board.
        let grasp_dz = 0.01 + sym(0.01);
        // The pouring grasp scaled to the piece: wrist 5 cm behind the piece along the
        // fingers, palm against its side.
        let offset = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw)
            * Vector3::new(-0.05, -(r * k + 0.01), grasp_dz);
        let from_c = v2r
            .virtual_pose(&setup.centre_on(task, piece, m.from))
            .translation
            .vector;
        let to_c = v2r
            .virtual_pose(&setup.centre_on(task, piece, m.to))
            .translation
            .vector
            + Vector3::new(sym(task.place_jitter_m), sym(task.place_jitter_m), 0.0) * k;
        let high = top_v.z + tallest_v + 0.08;
        let lift = tallest_v + 0.03;
        let grasp = from_c + offset;
        let above = Vector3::new(grasp.x, grasp.y, high) - d * 0.05;
        let side = grasp - d * 0.04;
        let via = (here + above) / 2.0
            + Vector3::new(-d.y, d.x, 0.0) * sym(task.via_jitter_m)
            + Vector3::new(0.0, 0.0, 0.03);
        let start = t;
        if keys.is_empty() {
            push(&mut keys, t, here, yaw, 0.0);
        }
        t += 0.5 * (1.0 + sym(tj));
        push(&mut keys, t, via, yaw, 0.0);
        t += 0.5 * (1.0 + sym(tj));
        push(&mut keys, t, above, yaw, 0.0);
        t += 0.6 * (1.0 + sym(tj));
        push(&mut keys, t, side, yaw, 0.0);
        t += 0.4 * (1.0 + sym(tj));
        push(&mut keys, t, grasp, yaw, 0.0);
        let close = t;
        t += 0.4 * (1.0 + sym(tj));
        push(&mut keys, t, grasp, yaw, GRIP);
        t += 0.2 * (1.0 + sym(tj));
        push(&mut keys, t, grasp, yaw, GRIP);
        t += 0.7 * (1.0 + sym(tj));
        push(
            &mut keys,
            t,
            grasp + Vector3::new(0.0, 0.0, lift),
            yaw,
            GRIP,
        );
        let put = to_c + offset;
        t += 1.0 * (1.0 + sym(tj));
        push(&mut keys, t, put + Vector3::new(0.0, 0.0, lift), yaw, GRIP);
        t += 0.7 * (1.0 + sym(tj));
        push(
            &mut keys,
            t,
            put + Vector3::new(0.0, 0.0, 0.004 * k),
            yaw,
            GRIP,
        );
        t += 0.2 * (1.0 + sym(tj));
        push(
            &mut keys,
            t,
            put + Vector3::new(0.0, 0.0, 0.004 * k),
            yaw,
            GRIP,
        );
        let release = t;
        t += 0.4 * (1.0 + sym(tj));
        push(
            &mut keys,
            t,
            put + Vector3::new(0.0, 0.0, 0.004 * k),
            yaw,
            0.0,
        );
        t += 0.4 * (1.0 + sym(tj));
        push(&mut keys, t, put - d * 0.06, yaw, 0.0);
        t += 0.4 * (1.0 + sym(tj));
        push(
            &mut keys,
            t,
            Vector3::new(put.x, put.y, high) - d * 0.06,
            yaw,
            0.0,
        );
        let j = task.start_jitter_m;
        here = rest(Vector3::new(sym(j), sym(j), sym(j)));
        t += 0.7 * (1.0 + sym(tj));
        push(&mut keys, t, here, yaw, 0.0);
        times.push(MoveTimes {
            start_s: start,
            close_s: close,
            release_s: release,
            end_s: t,
        });
        approach.push(d);
        at[piece] = m.to;
    }
    let script = HandScript::new(Handedness::Right, keys, HandNoise { seed, ..task.noise })?;
    Ok(ChessScript {
        script,
        moves: times,
        approach,
    })
}

/// The virtual scene of a chess task: the virtual board `k` times the real one about the
/// board's centre, offset by `virtual_offset`.
pub fn chess_v2r(task: &ChessTask) -> VirtualToReal {
    let centre: Isometry3<f64> = task.board_pose();
    let c = centre.translation.vector;
    VirtualToReal {
        k: task.k,
        rotation: UnitQuaternion::identity(),
        real_centre: c,
        virtual_centre: c + Vector3::from(task.virtual_offset),
    }
}
