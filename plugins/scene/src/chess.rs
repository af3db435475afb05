//! The paper's opening scene as data (`[chess]`): a board on Alice's desk, its pieces from a
//! FEN placement, and an opening's moves for the operator to play through the robot.
//!
//! The board and the pieces become props when the scene loads ([`ChessTask::props`]): the
//! board a box with its light squares on it, each piece an upright cylinder marked `object`
//! (so each has its own twin in the interaction layer and in the operator's physics world).
//! Piece sizes follow Staunton proportions scaled to the square ([`PieceKind::size`]).
//! [`ChessSetup`] is the real side resolved against the robot; `avatarm_mapping::chess` runs
//! the moves.

use std::sync::Arc;

use avatarm_core::robot::{LinkId, RobotModel};
use avatarm_core::sim::SimRobotParams;
use avatarm_core::teleop::hand::{HandFilterSettings, HandNoise};
use avatarm_core::teleop::intent::IntentSettings;
use avatarm_core::teleop::safety::SafetySettings;
use nalgebra::{DVector, Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::error::SceneError;
use crate::prop::PropShape;

/// The board's pose as written (`board = { xyz, rpy }`): its top surface's centre (m) and
/// roll, pitch, yaw (rad, fixed axes).
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardPose {
    /// Position (m).
    #[serde(default)]
    pub xyz: [f64; 3],
    /// Roll, pitch, yaw (rad).
    #[serde(default)]
    pub rpy: [f64; 3],
}

impl BoardPose {
    /// As an isometry.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.xyz[0], self.xyz[1], self.xyz[2]),
            UnitQuaternion::from_euler_angles(self.rpy[0], self.rpy[1], self.rpy[2]),
        )
    }
}

/// A prop of the board (the board, a light square, a piece), before it joins the scene's props.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardProp {
    /// Name.
    pub name: String,
    /// Shape.
    pub shape: PropShape,
    /// Pose of its base centre (world).
    pub pose: Isometry3<f64>,
    /// Colour.
    pub rgba: [f32; 4],
    /// A real object (a piece) with its own twin.
    pub object: bool,
}

/// The standard starting position (FEN piece placement, rank 8 first).
pub const START_POSITION: &str = "rnbqkbnr/pppppppp/8/8/8/8/PPPPPPPP/RNBQKBNR";

/// A chess piece's kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PieceKind {
    /// Pawn.
    Pawn,
    /// Knight.
    Knight,
    /// Bishop.
    Bishop,
    /// Rook.
    Rook,
    /// Queen.
    Queen,
    /// King.
    King,
}

impl PieceKind {
    /// From a FEN letter (either case).
    pub fn from_fen(c: char) -> Option<Self> {
        Some(match c.to_ascii_lowercase() {
            'p' => Self::Pawn,
            'n' => Self::Knight,
            'b' => Self::Bishop,
            'r' => Self::Rook,
            'q' => Self::Queen,
            'k' => Self::King,
            _ => return None,
        })
    }

    /// The name used in prop names.
    pub fn name(self) -> &'static str {
        match self {
            Self::Pawn => "pawn",
            Self::Knight => "knight",
            Self::Bishop => "bishop",
            Self::Rook => "rook",
            Self::Queen => "queen",
            Self::King => "king",
        }
    }

    /// Radius and height as fractions of the square's side: a Staunton set with a 95 mm king
    /// on 50 mm squares (FIDE Handbook C.02, 2.2: the king's base 40-50 % of its height, the
    /// square about twice the king's base diameter; the others in the usual proportions).
    pub fn size(self) -> (f64, f64) {
        match self {
            Self::Pawn => (0.28, 1.0),
            Self::Knight => (0.32, 1.2),
            Self::Bishop => (0.32, 1.4),
            Self::Rook => (0.32, 1.1),
            Self::Queen => (0.36, 1.7),
            Self::King => (0.38, 1.9),
        }
    }
}

/// A square: file 0..8 (a..h), rank 0..8 (1..8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Square {
    /// File, 0 = a.
    pub file: u8,
    /// Rank, 0 = the first.
    pub rank: u8,
}

impl Square {
    /// From algebraic notation ("e2").
    pub fn parse(s: &str) -> Option<Self> {
        let b = s.as_bytes();
        if b.len() != 2 || !(b'a'..=b'h').contains(&b[0]) || !(b'1'..=b'8').contains(&b[1]) {
            return None;
        }
        Some(Self {
            file: b[0] - b'a',
            rank: b[1] - b'1',
        })
    }

    /// In algebraic notation.
    pub fn name(self) -> String {
        format!("{}{}", (b'a' + self.file) as char, self.rank + 1)
    }
}

/// A piece on the board at the start.
#[derive(Debug, Clone, PartialEq)]
pub struct Piece {
    /// Its prop's name (`white_pawn_e2`).
    pub name: String,
    /// White or black.
    pub white: bool,
    /// Kind.
    pub kind: PieceKind,
    /// Where it starts.
    pub square: Square,
}

/// One move of one piece (no captures, no castling: one piece to an empty square).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChessMove {
    /// From.
    pub from: Square,
    /// To.
    pub to: Square,
}

impl ChessMove {
    /// From long algebraic notation without the piece ("e2e4").
    pub fn parse(s: &str) -> Option<Self> {
        if s.len() != 4 || !s.is_ascii() {
            return None;
        }
        Some(Self {
            from: Square::parse(&s[..2])?,
            to: Square::parse(&s[2..])?,
        })
    }
}

/// `[chess]`: the board, the pieces, the moves and how they are played (docs/chess.md).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChessTask {
    /// The board's top surface: its centre, and its yaw (files along the board's x, ranks
    /// along its y).
    pub board: BoardPose,
    /// Side of a square (m).
    pub square_m: f64,
    /// Thickness of the board (m).
    pub thickness_m: f64,
    /// The pieces: a FEN piece placement (rank 8 first, upper case white).
    pub position: String,
    /// The moves played, in order ("e2e4"): one piece each to an empty square.
    pub moves: Vec<String>,
    /// Times the moves are played (each with its own seed).
    pub trials: u32,
    /// Seed of trial 0.
    pub seed: u64,
    /// The robot's tool link, between the gripper's fingers.
    pub tcp_link: String,
    /// Joints driven; empty: every movable joint whose name does not contain "finger".
    pub arm_joints: Vec<String>,
    /// Scale of the virtual board relative to the real one (`k`): 2 puts pieces of a bottle's
    /// size in the operator's hand.
    pub k: f64,
    /// The virtual board's offset from the real one (m).
    pub virtual_offset: [f64; 3],
    /// Mass of a piece's twin (kg).
    pub mass_kg: f64,
    /// Friction of the twins.
    pub friction: f64,
    /// Hand tracker rate (Hz).
    pub hand_rate_hz: f64,
    /// Tremor and tracking noise of the scripted hand.
    pub noise: HandNoise,
    /// The filter on the tracked hand.
    pub hand_filter: HandFilterSettings,
    /// Per move: the hand starts up to this far off its rest (m, each axis, virtual).
    pub start_jitter_m: f64,
    /// Per move: the reach bends through a point up to this far off the straight line (m).
    pub via_jitter_m: f64,
    /// Per move: each stretch of the script takes up to this fraction longer or shorter.
    pub time_jitter: f64,
    /// Per move: the piece is set down up to this far off the square's centre (m, virtual).
    pub place_jitter_m: f64,
    /// Closed-loop gain of the carry (1/s).
    pub gain: f64,
    /// How far the robot's open gripper reaches across from its tool point (m): half its
    /// opening and a finger's thickness. Between grasps the tool keeps this clear of the
    /// pieces it passes, and comes down onto a piece only once centred on it within the
    /// half-opening less the piece's radius (`PickPlaceSettings::tool_radius_m`).
    pub gripper_reach_m: f64,
    /// TCP speed cap (m/s).
    pub max_tcp_speed: f64,
    /// The intent estimate's settings.
    pub intent: IntentSettings,
    /// One-way delays (ms) between the operator and the robot measured by `bench chess`.
    pub delays_ms: Vec<f64>,
    /// Colours: light and dark squares, white and black pieces (sRGB, alpha).
    pub light_rgba: [f32; 4],
    /// See `light_rgba`.
    pub dark_rgba: [f32; 4],
    /// See `light_rgba`.
    pub white_rgba: [f32; 4],
    /// See `light_rgba`.
    pub black_rgba: [f32; 4],
}

impl Default for ChessTask {
    fn default() -> Self {
        Self {
            board: BoardPose {
                xyz: [0.62, 0.0, 0.75],
                rpy: [0.0; 3],
            },
            square_m: 0.05,
            thickness_m: 0.012,
            position: START_POSITION.into(),
            moves: Vec::new(),
            trials: 2,
            seed: 1,
            tcp_link: "right_gripper_tip".into(),
            arm_joints: Vec::new(),
            k: 2.0,
            virtual_offset: [0.0; 3],
            mass_kg: 0.2,
            friction: 1.0,
            hand_rate_hz: 90.0,
            noise: HandNoise::default(),
            hand_filter: HandFilterSettings::default(),
            start_jitter_m: 0.03,
            via_jitter_m: 0.04,
            time_jitter: 0.15,
            place_jitter_m: 0.003,
            gain: 8.0,
            gripper_reach_m: 0.025,
            max_tcp_speed: SafetySettings::default().max_tcp_speed,
            intent: IntentSettings::default(),
            delays_ms: vec![0.0, 100.0],
            light_rgba: [0.93, 0.86, 0.70, 1.0],
            dark_rgba: [0.45, 0.28, 0.16, 1.0],
            white_rgba: [0.96, 0.94, 0.88, 1.0],
            black_rgba: [0.10, 0.09, 0.09, 1.0],
        }
    }
}

impl ChessTask {
    /// The board's top height (world z, m).
    pub fn board_top(&self) -> f64 {
        self.board_pose().translation.z
    }

    /// The pieces of [`ChessTask::position`], rank 8 first. Errors name the field.
    pub fn pieces(&self) -> Result<Vec<Piece>, SceneError> {
        let bad = |m: String| SceneError::field("chess.position", m);
        let ranks: Vec<&str> = self.position.split('/').collect();
        if ranks.len() != 8 {
            return Err(bad(format!("{} ranks, 8 needed", ranks.len())));
        }
        let mut pieces = Vec::new();
        for (i, text) in ranks.iter().enumerate() {
            let rank = 7 - i as u8;
            let mut file = 0u8;
            for c in text.chars() {
                if let Some(n) = c.to_digit(10).filter(|n| (1..=8).contains(n)) {
                    file += n as u8;
                    continue;
                }
                let kind = PieceKind::from_fen(c)
                    .ok_or_else(|| bad(format!("'{c}' in rank {} is not a piece", rank + 1)))?;
                if file >= 8 {
                    return Err(bad(format!("rank {} has more than 8 squares", rank + 1)));
                }
                let square = Square { file, rank };
                let white = c.is_ascii_uppercase();
                pieces.push(Piece {
                    name: format!(
                        "{}_{}_{}",
                        if white { "white" } else { "black" },
                        kind.name(),
                        square.name()
                    ),
                    white,
                    kind,
                    square,
                });
                file += 1;
            }
            if file != 8 {
                return Err(bad(format!(
                    "rank {} has {file} squares, 8 needed",
                    rank + 1
                )));
            }
        }
        Ok(pieces)
    }

    /// The moves, each checked against the position it is played in: a piece on its
    /// from-square, its to-square empty. Returns each move with the index (into
    /// [`ChessTask::pieces`]) of the piece it moves. Errors name the move.
    pub fn resolved_moves(&self) -> Result<Vec<(ChessMove, usize)>, SceneError> {
        let pieces = self.pieces()?;
        let mut at: Vec<Square> = pieces.iter().map(|p| p.square).collect();
        let mut out = Vec::new();
        for (i, text) in self.moves.iter().enumerate() {
            let field = format!("chess.moves[{i}]");
            let m = ChessMove::parse(text).ok_or_else(|| {
                SceneError::field(&field, format!("'{text}' is not a move like \"e2e4\""))
            })?;
            let piece = at.iter().position(|&s| s == m.from).ok_or_else(|| {
                SceneError::field(&field, format!("'{text}': no piece on {}", m.from.name()))
            })?;
            if let Some(other) = at.iter().position(|&s| s == m.to) {
                return Err(SceneError::field(
                    &field,
                    format!(
                        "'{text}': {} stands on {} (captures are not played)",
                        pieces[other].name,
                        m.to.name()
                    ),
                ));
            }
            at[piece] = m.to;
            out.push((m, piece));
        }
        Ok(out)
    }

    /// Checks every value; errors name the field.
    pub fn validate(&self) -> Result<(), SceneError> {
        for (name, v) in [
            ("square_m", self.square_m),
            ("thickness_m", self.thickness_m),
            ("k", self.k),
            ("mass_kg", self.mass_kg),
            ("hand_rate_hz", self.hand_rate_hz),
            ("max_tcp_speed", self.max_tcp_speed),
            ("gripper_reach_m", self.gripper_reach_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(SceneError::field(
                    format!("chess.{name}"),
                    format!("{v} must be a positive number"),
                ));
            }
        }
        for (name, v) in [
            ("friction", self.friction),
            ("start_jitter_m", self.start_jitter_m),
            ("via_jitter_m", self.via_jitter_m),
            ("place_jitter_m", self.place_jitter_m),
            ("gain", self.gain),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(SceneError::field(
                    format!("chess.{name}"),
                    format!("{v} must be a number >= 0"),
                ));
            }
        }
        if !(self.time_jitter.is_finite() && (0.0..0.5).contains(&self.time_jitter)) {
            return Err(SceneError::field(
                "chess.time_jitter",
                format!("{} must be in [0, 0.5)", self.time_jitter),
            ));
        }
        if self.trials == 0 {
            return Err(SceneError::field("chess.trials", "at least one trial"));
        }
        if self.moves.is_empty() {
            return Err(SceneError::field("chess.moves", "at least one move"));
        }
        if let Some(d) = self
            .delays_ms
            .iter()
            .find(|d| !(d.is_finite() && (0.0..=1000.0).contains(*d)))
        {
            return Err(SceneError::field(
                "chess.delays_ms",
                format!("{d} must be within 0..=1000 ms"),
            ));
        }
        if self
            .virtual_offset
            .iter()
            .chain(&self.board.xyz)
            .chain(&self.board.rpy)
            .any(|v| !v.is_finite())
        {
            return Err(SceneError::field("chess.board", "positions must be finite"));
        }
        self.intent
            .validate()
            .map_err(|e| SceneError::value("chess.intent", e))?;
        self.hand_filter
            .validate()
            .map_err(|e| SceneError::value("chess.hand_filter", e))?;
        self.resolved_moves().map(|_| ())
    }

    /// The board's top surface centre (world; files along its x, ranks along its y, z up).
    pub fn board_pose(&self) -> Isometry3<f64> {
        self.board.to_isometry()
    }

    /// The centre of `square` on the board's top (world).
    pub fn square_centre(&self, square: Square) -> Point3<f64> {
        let s = self.square_m;
        self.board_pose()
            * Point3::new(
                (f64::from(square.file) - 3.5) * s,
                (f64::from(square.rank) - 3.5) * s,
                0.0,
            )
    }

    /// A piece's radius and height (m).
    pub fn piece_size(&self, kind: PieceKind) -> (f64, f64) {
        let (r, h) = kind.size();
        (r * self.square_m, h * self.square_m)
    }

    /// The board and its pieces as props: the board (a box of the dark colour, its top at the
    /// board's pose), the 32 light squares on it (1 mm thick), and each piece (an upright
    /// cylinder, marked `object`). Errors as [`ChessTask::pieces`].
    pub fn props(&self) -> Result<Vec<BoardProp>, SceneError> {
        let s = self.square_m;
        let board = self.board_pose();
        let yaw = UnitQuaternion::from_euler_angles(0.0, 0.0, board.rotation.euler_angles().2);
        let at = |p: Point3<f64>, z: f64| {
            Isometry3::from_parts(Translation3::new(p.x, p.y, p.z + z), yaw)
        };
        let prop =
            |name: String, shape: PropShape, pose: Isometry3<f64>, rgba: [f32; 4], object| {
                BoardProp {
                    name,
                    shape,
                    pose,
                    rgba,
                    object,
                }
            };
        let edge = 8.0 * s + 0.04;
        let mut out = vec![prop(
            "chess_board".into(),
            PropShape::Box {
                size: [edge, edge, self.thickness_m],
            },
            at(board * Point3::origin(), -self.thickness_m - 0.001),
            self.dark_rgba,
            false,
        )];
        for rank in 0..8u8 {
            for file in 0..8u8 {
                if (file + rank) % 2 == 1 {
                    let sq = Square { file, rank };
                    out.push(prop(
                        format!("chess_square_{}", sq.name()),
                        PropShape::Box {
                            size: [s, s, 0.001],
                        },
                        at(self.square_centre(sq), -0.001),
                        self.light_rgba,
                        false,
                    ));
                }
            }
        }
        for piece in self.pieces()? {
            let (radius, height) = self.piece_size(piece.kind);
            out.push(prop(
                piece.name.clone(),
                PropShape::Cylinder { radius, height },
                at(self.square_centre(piece.square), 0.0),
                if piece.white {
                    self.white_rgba
                } else {
                    self.black_rgba
                },
                true,
            ));
        }
        Ok(out)
    }
}

/// The real side of the chess task: the robot, the tool and the pieces, from the scene.
#[derive(Debug, Clone)]
pub struct ChessSetup {
    /// The robot.
    pub model: Arc<RobotModel>,
    /// Its root link in the world.
    pub base: Isometry3<f64>,
    /// Joint positions at the start.
    pub q_start: DVector<f64>,
    /// The tool link.
    pub tcp: LinkId,
    /// Arm joints.
    pub arm: Vec<usize>,
    /// Simulated robot timing.
    pub sim: SimRobotParams,
    /// Control and physics rate (Hz).
    pub control_rate_hz: f64,
    /// The pieces at the start, in [`ChessTask::pieces`]' order.
    pub pieces: Vec<Piece>,
    /// Each piece's body centre at the start (world, z up).
    pub centres: Vec<Isometry3<f64>>,
    /// Each piece's radius and height (m).
    pub sizes: Vec<(f64, f64)>,
    /// The moves and the piece each moves.
    pub moves: Vec<(ChessMove, usize)>,
}

impl ChessSetup {
    /// The real side of `task` for the robot `model`: the tool link and the arm joints looked
    /// up, the pieces placed. Errors name the `chess.*` field.
    pub fn resolve(
        task: &ChessTask,
        model: &Arc<RobotModel>,
        base: Isometry3<f64>,
        q_start: DVector<f64>,
        sim: SimRobotParams,
        control_rate_hz: f64,
    ) -> Result<Self, SceneError> {
        let (tcp, arm) =
            crate::task::resolve_tool(model, &task.tcp_link, &task.arm_joints, "chess")?;
        let pieces = task.pieces()?;
        let yaw = task.board_pose().rotation.euler_angles().2;
        let sizes: Vec<(f64, f64)> = pieces.iter().map(|p| task.piece_size(p.kind)).collect();
        let centres = pieces
            .iter()
            .zip(&sizes)
            .map(|(p, &(_, h))| {
                let c = task.square_centre(p.square);
                Isometry3::from_parts(
                    Translation3::new(c.x, c.y, c.z + h / 2.0),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
                )
            })
            .collect();
        Ok(Self {
            model: Arc::clone(model),
            base,
            q_start,
            tcp,
            arm,
            sim,
            control_rate_hz,
            moves: task.resolved_moves()?,
            pieces,
            centres,
            sizes,
        })
    }

    /// The tallest piece's height (m).
    pub fn tallest_m(&self) -> f64 {
        self.sizes.iter().map(|s| s.1).fold(0.0, f64::max)
    }

    /// Where a piece moved to `square` stands (its body centre, world).
    pub fn centre_on(&self, task: &ChessTask, piece: usize, square: Square) -> Isometry3<f64> {
        let c = task.square_centre(square);
        let h = self.sizes[piece].1;
        Isometry3::from_parts(
            Translation3::from(Vector3::new(c.x, c.y, c.z + h / 2.0)),
            self.centres[piece].rotation,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opening(moves: &[&str]) -> ChessTask {
        ChessTask {
            moves: moves.iter().map(|m| (*m).to_owned()).collect(),
            ..ChessTask::default()
        }
    }

    #[test]
    fn the_start_position_has_32_pieces_where_they_belong() {
        let pieces = opening(&["e2e4"]).pieces().unwrap();
        assert_eq!(pieces.len(), 32);
        let king = pieces.iter().find(|p| p.name == "white_king_e1").unwrap();
        assert_eq!(king.kind, PieceKind::King);
        assert!(pieces.iter().any(|p| p.name == "black_queen_d8"));
        assert_eq!(
            pieces.iter().filter(|p| p.kind == PieceKind::Pawn).count(),
            16
        );
    }

    #[test]
    fn moves_are_checked_against_the_position_they_are_played_in() {
        let ok = opening(&["e2e4", "e7e5", "g1f3"]).resolved_moves().unwrap();
        assert_eq!(ok.len(), 3);
        let e = opening(&["e2e4", "e2e3"])
            .validate()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("chess.moves[1]") && e.contains("no piece on e2"),
            "{e}"
        );
        let e = opening(&["d1d2"]).validate().unwrap_err().to_string();
        assert!(e.contains("white_pawn_d2 stands on d2"), "{e}");
        let e = opening(&["e2e9"]).validate().unwrap_err().to_string();
        assert!(e.contains("not a move"), "{e}");
        let refused = |bad: ChessTask| bad.validate().unwrap_err().to_string();
        let base = || opening(&["e2e4"]);
        let e = refused(ChessTask {
            position: "8/8/8".into(),
            ..base()
        });
        assert!(e.contains("chess.position"), "{e}");
        let e = refused(ChessTask {
            square_m: f64::NAN,
            ..base()
        });
        assert!(e.contains("chess.square_m"), "{e}");
        let e = refused(ChessTask {
            gripper_reach_m: 0.0,
            ..base()
        });
        assert!(e.contains("chess.gripper_reach_m"), "{e}");
    }

    #[test]
    fn the_props_put_each_piece_on_its_square() {
        let task = opening(&["e2e4"]);
        let props = task.props().unwrap();
        assert_eq!(props.len(), 1 + 32 + 32);
        let e2 = props.iter().find(|p| p.name == "white_pawn_e2").unwrap();
        assert!(e2.object);
        let c = task.square_centre(Square::parse("e2").unwrap());
        let p = e2.pose.translation.vector;
        assert!((p.x - c.x).abs() < 1e-12 && (p.y - c.y).abs() < 1e-12);
        // a1 is dark: no light square there; h1 is light.
        assert!(!props.iter().any(|p| p.name == "chess_square_a1"));
        assert!(props.iter().any(|p| p.name == "chess_square_h1"));
    }
}
