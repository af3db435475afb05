//! The operator's scripted hand for a chess trial: every move of the opening in one
//! [`HandScript`], in the virtual scene.
//!
//! Each move: from a rest pose above the operator's edge of the board, a reach (bent through a
//! seeded via point) to above the piece's approach side, down beside it, in to a side grasp
//! (the pouring task's grasp scaled to the piece, from the first side, straight or diagonal,
//! where the hand's bones keep 1 cm from every other piece: [`choose_side`]), a close, a lift
//! above the tallest piece, a carry to the target square (the hand turning about the piece to
//! the side it sets it down from), a set-down, a release, a step back, straight up, and on to
//! the next rest. Seeded per move: the rest (±`start_jitter_m`), the via point (±`via_jitter_m`), each stretch's duration (±`time_jitter`), the grasp height
//! (1 ± 1 cm above the piece's centre) and the set-down point (±`place_jitter_m`).

use std::f64::consts::FRAC_PI_2;

use avatarm_core::rng::Rng;
use avatarm_core::teleop::hand::{
    HandKeyframe, HandNoise, HandScript, Handedness, SKELETON, skeleton,
};
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
}

/// The board's axes in the world: files, ranks (unit, horizontal).
fn board_axes(task: &ChessTask) -> (Vector3<f64>, Vector3<f64>) {
    let r = task.board_pose().rotation;
    (r * Vector3::x(), r * Vector3::y())
}

/// The sides a hand may take a piece from, in the operator's order of preference, as board
/// steps (file, rank) from the palm toward the piece: toward higher ranks (palm on the
/// operator's side), along the files either way, toward lower ranks, then the diagonals.
const SIDES: [(i8, i8); 8] = [
    (0, 1),
    (1, 0),
    (-1, 0),
    (0, -1),
    (1, 1),
    (-1, 1),
    (1, -1),
    (-1, -1),
];

/// The room a hand wants between its bones and the other pieces (m, virtual).
const ROOM_M: f64 = 0.01;

/// The other pieces as the hand meets them (virtual): axis position, radius, top.
type Obstacle = (Vector3<f64>, f64, f64);

/// The least distance (m) between the hand's bone capsules (`skeleton` at `wrist` and `grip`,
/// sampled along each bone) and the side of any `others` piece below its top; negative where
/// they overlap.
fn hand_room(wrist: &Isometry3<f64>, grip: f64, others: &[Obstacle]) -> f64 {
    let joints = skeleton(wrist, grip, Handedness::Right);
    let mut room = f64::INFINITY;
    for &(a, b) in SKELETON.iter() {
        let (ja, jb) = (&joints[a], &joints[b]);
        for i in 0..=4 {
            let s = f64::from(i) / 4.0;
            let p = ja
                .pose
                .translation
                .vector
                .lerp(&jb.pose.translation.vector, s);
            let radius = ja.radius + (jb.radius - ja.radius) * s;
            for (c, r, top) in others {
                if p.z - radius > *top {
                    continue;
                }
                let across = ((p.x - c.x).powi(2) + (p.y - c.y).powi(2)).sqrt();
                room = room.min(across - r - radius);
            }
        }
    }
    room
}

/// A grasp (or set-down) of one piece from one side: the hand's wrist poses on the way in and
/// out (virtual), from the scripted hand's key poses.
struct Side {
    /// Unit, from the palm toward the piece (virtual, horizontal).
    d: Vector3<f64>,
    /// The hand's heading about the vertical (rad).
    yaw: f64,
}

impl Side {
    fn of(step: (i8, i8), files: &Vector3<f64>, ranks: &Vector3<f64>) -> Self {
        let d = (files * f64::from(step.0) + ranks * f64::from(step.1)).normalize();
        Self {
            d,
            yaw: (-d.x).atan2(d.y),
        }
    }

    /// The wrist's offset from the piece's centre: the pouring grasp scaled to a piece of
    /// radius `r` (m, virtual), wrist 5 cm behind the piece along the fingers, palm against its
    /// side, `dz` above its centre.
    fn offset(&self, r: f64, dz: f64) -> Vector3<f64> {
        UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw) * Vector3::new(-0.05, -(r + 0.01), dz)
    }

    fn wrist(&self, at: Vector3<f64>) -> Isometry3<f64> {
        Isometry3::from_parts(
            at.into(),
            UnitQuaternion::from_euler_angles(FRAC_PI_2, 0.0, self.yaw),
        )
    }

    /// The least room (m) the hand has around the other pieces taking a piece centred at `c`
    /// of radius `r` from this side: the open hand coming down beside it, in to the grasp,
    /// closed on it, and stepping back open.
    fn room(&self, c: Vector3<f64>, r: f64, dz: f64, others: &[Obstacle]) -> f64 {
        let grasp = c + self.offset(r, dz);
        [
            (grasp - self.d * 0.04 + Vector3::new(0.0, 0.0, 0.03), 0.0),
            (grasp - self.d * 0.04, 0.0),
            (grasp, 0.0),
            (grasp, GRIP),
            (grasp - self.d * 0.06, 0.0),
        ]
        .iter()
        .map(|&(w, grip)| hand_room(&self.wrist(w), grip, others))
        .fold(f64::INFINITY, f64::min)
    }
}

/// The side a hand takes a piece of radius `r` centred at `c` from (virtual): the first of
/// [`SIDES`] that leaves the hand [`ROOM_M`] around the `others`, else the one with the most
/// room. The grasp and the set-down each take their own side: the hand turns about the piece
/// while carrying it.
fn choose_side(
    c: Vector3<f64>,
    r: f64,
    dz: f64,
    others: &[Obstacle],
    files: &Vector3<f64>,
    ranks: &Vector3<f64>,
) -> Side {
    let mut best: Option<(f64, Side)> = None;
    for step in SIDES {
        let side = Side::of(step, files, ranks);
        let room = side.room(c, r, dz, others);
        if room >= ROOM_M {
            return side;
        }
        if best.as_ref().is_none_or(|(b, _)| room > *b) {
            best = Some((room, side));
        }
    }
    best.map_or_else(|| Side::of(SIDES[0], files, ranks), |(_, s)| s)
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
        let from_c = v2r
            .virtual_pose(&setup.centre_on(task, piece, m.from))
            .translation
            .vector;
        let to_c = v2r
            .virtual_pose(&setup.centre_on(task, piece, m.to))
            .translation
            .vector
            + Vector3::new(sym(task.place_jitter_m), sym(task.place_jitter_m), 0.0) * k;
        // The other pieces where they stand now (virtual).
        let others: Vec<Obstacle> = at
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != piece)
            .map(|(i, &sq)| {
                let c = v2r
                    .virtual_pose(&setup.centre_on(task, i, sq))
                    .translation
                    .vector;
                let (ri, hi) = setup.sizes[i];
                (c, ri * k, c.z + hi * k / 2.0)
            })
            .collect();
        // The hand's lower fingers clear the board.
        let grasp_dz = 0.01 + sym(0.01);
        let take = choose_side(from_c, r * k, grasp_dz, &others, &files, &ranks);
        let set = choose_side(to_c, r * k, grasp_dz, &others, &files, &ranks);
        let (d, yaw) = (take.d, take.yaw);
        let offset = take.offset(r * k, grasp_dz);
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
        let put = to_c + set.offset(r * k, grasp_dz);
        let (d, yaw) = (set.d, set.yaw);
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
        at[piece] = m.to;
    }
    let script = HandScript::new(Handedness::Right, keys, HandNoise { seed, ..task.noise })?;
    Ok(ChessScript {
        script,
        moves: times,
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
