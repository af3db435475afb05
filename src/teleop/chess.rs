//! The chess scene played live in `avatarm run`: a scene with `[chess]` (and no `[task]`) runs
//! one game of its opening with any hand source, the robot picking and placing the real pieces
//! (anticipating the piece the hand reaches for) with the robot erased from the video.
//!
//! The game's loop is the bench's ([`ChessGame`], `avatarm_mapping::chess`): the operator's
//! Rapier world holds a twin of every piece (the app's fixed steps, the scene's control rate),
//! the hand grasps and carries them, and each control tick after the hand's contacts the game
//! ticks the operator's side, the intent estimate, the robot's side ([`PickPlaceRobot`]), the
//! limiter and the simulated arm with every real piece. After each tick the simulated room shows
//! the arm and each real piece where the game left them (the room drives nothing itself), the
//! app's twin gets the joint states, and in the interaction view each piece's twin follows its
//! physics twin mapped into the real world. A scripted hand plays the scene's moves (trial 0 of
//! the bench); a live hand (desktop, OpenXR, Leap, a recording) plays what it likes, the moves
//! being scored in the scene's order.
//!
//! [`PickPlaceRobot`]: avatarm_core::teleop::pick_place::PickPlaceRobot

use avatarm_core::teleop::pick_place::PickPhase;
use avatarm_mapping::chess::{ChessCase, ChessGame, MoveResult, chess_script, chess_v2r};

use super::*;

/// Where each piece of the game is drawn: its prop in the simulated room, its twin in the
/// interaction layer, and its base (the prop's pose) from its body centre (the game's frame).
#[derive(Debug, Clone)]
struct PieceLink {
    prop: usize,
    object_twin: Option<usize>,
    centre_to_base: Isometry3<f64>,
}

/// A live game, prepared before any window exists ([`LiveChess::prepare`]): every way the
/// set-up can fail fails there, so that `avatarm run` refuses it with a non-zero exit.
pub struct LiveChess {
    scene_name: String,
    task: avatarm_scene::chess::ChessTask,
    setup: avatarm_scene::chess::ChessSetup,
    game: ChessGame,
    hand: Option<ActiveHand>,
    desktop: Option<DesktopHand>,
    start: Isometry3<f64>,
    state: ChessState,
}

/// The live game's state for the systems, the status line and the summary.
#[derive(Resource)]
pub struct ChessState {
    /// The hand source's name.
    pub source: String,
    v2r: avatarm_core::teleop::mapping::VirtualToReal,
    pieces: Vec<PieceLink>,
    /// The piece of each of the room's props that is one (prop index -> piece index).
    piece_of_prop: std::collections::HashMap<usize, usize>,
    names: Vec<String>,
    /// Control ticks run.
    pub ticks: u64,
    /// The last error of the game's loop (the arm refused a command, the hand world broken).
    pub last_error: Option<String>,
}

/// The game itself, stepped by [`chess_tick`] (a resource of its own so that the exclusive
/// system can take it out of the world while it reads the hand's world).
#[derive(Resource)]
pub struct LiveGame(pub ChessGame);

impl LiveChess {
    /// Sets up a game of `scene`'s `[chess]` driven by `choice` on the simulated arm. Errors when
    /// the scene has no `[chess]`, the robot is not the simulated arm (the pick-and-place side
    /// runs on the simulated arm holding the real pieces only), the arm cannot reach its ready
    /// pose, or the hand source is unavailable.
    pub fn prepare(scene: &Scene, choice: &HandChoice, link: &TrialLink) -> Result<Self, AppError> {
        let (Some(task), Some(setup)) = (&scene.file.chess, &scene.chess) else {
            return Err(AppError::flag(
                "--hand",
                format!("the scene '{}' has no [chess]", scene.file.name),
            ));
        };
        let why = "the chess scene's pick and place runs on the simulated arm only (it knows \
                   every real piece from the simulation)";
        match link {
            TrialLink::Simulated => {}
            TrialLink::Ros => {
                return Err(AppError::flag(
                    "--robot",
                    format!("{why}; a real arm plays the pouring task"),
                ));
            }
            TrialLink::Given(_) => {
                return Err(AppError::flag(
                    "--camera-recording",
                    format!("{why}; add --hand none to watch the recording without it"),
                ));
            }
        }
        let v2r = chess_v2r(task);
        let plan = chess_script(task, setup, &v2r, 0)?;
        let (hand, desktop) = hand_source(scene, choice, &plan.script, task.hand_rate_hz)?;
        // A scripted hand plays the scene's moves at the script's times; a live one is scored
        // against the moves in their order.
        let starts = matches!(choice, HandChoice::Scripted)
            .then(|| plan.moves.iter().map(|m| m.start_s).collect());
        let game = ChessGame::new(
            task,
            setup,
            ChessCase {
                intent: true,
                delay_s: 0.0,
            },
            starts,
            0,
        )?;
        let config = crate::app::interaction_config(scene);
        let pieces = setup
            .pieces
            .iter()
            .zip(&setup.sizes)
            .map(|(piece, &(_, h))| {
                let (prop, _) = find_prop(&scene.props, &piece.name).ok_or_else(|| {
                    avatarm_scene::SceneError::field(
                        "chess",
                        format!("no prop for the piece '{}'", piece.name),
                    )
                })?;
                Ok(PieceLink {
                    prop,
                    object_twin: config.objects.iter().position(|o| o.name == piece.name),
                    centre_to_base: Isometry3::translation(0.0, 0.0, -h / 2.0),
                })
            })
            .collect::<Result<Vec<_>, AppError>>()?;
        Ok(Self {
            scene_name: scene.file.name.clone(),
            task: task.clone(),
            setup: setup.clone(),
            game,
            start: plan.script.wrist_at(0.0).0,
            state: ChessState {
                source: hand.as_ref().map_or("OpenXR hand", |h| h.name()).to_owned(),
                v2r,
                piece_of_prop: pieces
                    .iter()
                    .enumerate()
                    .map(|(i, l)| (l.prop, i))
                    .collect(),
                pieces,
                names: setup.pieces.iter().map(|p| p.name.clone()).collect(),
                ticks: 0,
                last_error: None,
            },
            hand,
            desktop,
        })
    }

    /// Adds the game to a preview app built by [`crate::preview::build_app`]: the operator's
    /// Rapier world with the hand and the pieces' twins, the game's tick, the room and the
    /// interaction layer following it. Errors only for OpenXR hand tracking without the XR view.
    pub fn install(self, app: &mut App) -> Result<(), AppError> {
        let hand = match self.hand {
            Some(hand) => hand,
            None => ActiveHand::new(xr_inbox(app, &self.start)?),
        };
        let (task, setup) = (&self.task, &self.setup);
        info!(
            "live teleoperation: '{}' (chess, {} moves) with the {} on the simulated arm, the \
             robot anticipating the piece the hand reaches for",
            self.scene_name,
            setup.moves.len(),
            hand.name()
        );
        {
            let mut room = app.world_mut().resource_mut::<SimRoomConfig>();
            room.external_drive = true;
            room.q0 = self.game.arm().robot().true_positions().clone();
        }
        let spawn = avatarm_mapping::chess::spawn_chess_twins(task, setup, &self.state.v2r);
        let drive = avatarm_hand::HandDrive {
            filter: task.hand_filter,
            ..avatarm_hand::HandDrive::default()
        };
        app.add_plugins((
            RapierPhysicsPlugin::<NoUserData>::default().in_fixed_schedule(),
            HandPlugin,
        ))
        .insert_resource(drive)
        .insert_resource(hand)
        .insert_resource(LiveGame(self.game))
        .insert_resource(self.state)
        .init_gizmo_group::<HandViewGizmos>()
        .init_gizmo_group::<HandInteractionGizmos>()
        .add_systems(
            Startup,
            (spawn, configure_gizmos).in_set(AvatarmSystems::Teleop),
        )
        .add_systems(
            FixedUpdate,
            chess_tick
                .after(avatarm_hand::HandSystems::Contacts)
                .before(AvatarmSystems::Mirror),
        )
        .add_systems(FixedUpdate, mirror_game.in_set(AvatarmSystems::Mirror))
        .add_systems(
            Update,
            (follow_twins, draw_chess_hand)
                .chain()
                .in_set(AvatarmSystems::Teleop),
        );
        if let Some(desktop) = self.desktop {
            app.insert_resource(desktop).add_systems(
                Update,
                drive_desktop_chess_hand
                    .before(follow_twins)
                    .in_set(AvatarmSystems::Teleop),
            );
        }
        Ok(())
    }
}

/// The game's control tick, after the hand's contacts in each fixed step. An error is kept
/// for the status line and said once: a command the arm refused (the limiter stops it on the
/// next ticks), or a hand world missing its parts (the game does not tick: the simulated arm
/// stands where it is).
fn chess_tick(world: &mut World) {
    world.resource_scope(|world, mut game: Mut<LiveGame>| {
        let result = game.0.step(world);
        let mut state = world.resource_mut::<ChessState>();
        match result {
            Ok(true) => state.ticks += 1,
            Ok(false) => {}
            Err(e) => {
                let e = e.to_string();
                if state.last_error.as_ref() != Some(&e) {
                    warn!("chess: {e}");
                }
                state.last_error = Some(e);
            }
        }
    });
}

/// After each tick: the room's arm is the game's simulated arm, the app's twin gets the joint
/// states that arrived, and every real piece is where the game has it.
fn mirror_game(
    game: Res<LiveGame>,
    state: Res<ChessState>,
    twin: Option<Res<AppTwin>>,
    room: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    mut states: MessageWriter<JointStateMessage>,
    mut parts: Query<(&SimPropPart, &mut Transform)>,
) {
    let arm = game.0.arm();
    robot.0.clone_from(arm.robot());
    if let Some(twin) = twin {
        twin.send(&mut states, &room.model, game.0.received(), 0.0);
    }
    let pieces = arm.objects();
    for (part, mut t) in &mut parts {
        let Some((piece, link)) = state
            .piece_of_prop
            .get(&part.prop)
            .and_then(|&i| Some((pieces.get(i)?, state.pieces.get(i)?)))
        else {
            continue;
        };
        let base = piece.pose * link.centre_to_base;
        let next = iso_to_transform(&base) * part.local;
        if *t != next {
            *t = next;
        }
    }
}

/// Each piece's twin in the interaction view shows its physics twin mapped into the real
/// world: the piece the hand moves is drawn under the hand, the real one follows through the
/// robot.
fn follow_twins(
    state: Res<ChessState>,
    twins: Option<Res<avatarm_mapping::chess::ChessTwins>>,
    bodies: Query<&Transform, With<GraspTarget>>,
    mut config: ResMut<InteractionConfig>,
) {
    let Some(twins) = twins else { return };
    for (&entity, link) in twins.0.iter().zip(&state.pieces) {
        let (Some(i), Ok(t)) = (link.object_twin, bodies.get(entity)) else {
            continue;
        };
        let pose = state.v2r.pose(&transform_to_iso(t)) * link.centre_to_base;
        if let Some(object) = config.objects.get_mut(i)
            && object.world_from_object != pose
        {
            object.world_from_object = pose;
        }
    }
}

/// The hand as a skeleton: in the 3-D view where the mapping puts it in the real world, and in
/// the interaction view around the twin it holds (else the piece the robot is reaching,
/// carrying or placing, else the intent's piece, else the nearest twin), as drawn there.
fn draw_chess_hand(
    hand: Res<ActiveHand>,
    held: Res<HeldObject>,
    (state, game): (Res<ChessState>, Res<LiveGame>),
    config: Res<InteractionConfig>,
    mut view: Gizmos<HandViewGizmos>,
    mut interaction: Gizmos<HandInteractionGizmos>,
) {
    let colour = hand_colour(held.held.is_some());
    let Some(real) = hand_in_3d_view(&hand, &state.v2r, colour, &mut view) else {
        return;
    };
    let palm = real[avatarm_core::teleop::hand::PALM];
    let nearest = config
        .objects
        .iter()
        .enumerate()
        .min_by(|(_, a), (_, b)| {
            let d = |o: &avatarm_erase::interaction::ObjectTwinSpec| {
                (o.world_from_object.translation.vector - palm).norm()
            };
            d(a).total_cmp(&d(b))
        })
        .map(|(i, _)| i);
    let piece = game
        .0
        .held()
        .or(match game.0.phase() {
            PickPhase::Reach { object }
            | PickPhase::Carry { object }
            | PickPhase::Place { object, .. } => Some(object),
            PickPhase::Free | PickPhase::Retreat => None,
        })
        .or_else(|| game.0.intent());
    let Some(i) = piece
        .and_then(|p| state.pieces.get(p))
        .and_then(|l| l.object_twin)
        .or(nearest)
    else {
        return;
    };
    for (a, b) in hand_in_interaction_view(&real, &config, i) {
        interaction.line(a, b, colour);
    }
}

/// Keys and mouse move the desktop hand (Home puts it back, open, at its start; the pieces
/// stay where they are).
fn drive_desktop_chess_hand(
    controls: DesktopControls,
    time: Res<Time<Real>>,
    fixed: Res<Time<Fixed>>,
    mut hand: ResMut<DesktopHand>,
) {
    hand.step(
        &controls.input(),
        time.delta_secs_f64(),
        fixed.elapsed_secs_f64(),
    );
}

impl ChessState {
    fn name(&self, piece: usize) -> &str {
        self.names.get(piece).map_or("?", String::as_str)
    }

    /// What the robot does, in words.
    fn doing(&self, game: &ChessGame) -> String {
        match game.phase() {
            PickPhase::Free => match game.intent() {
                Some(p) => format!("to the {} (intent)", self.name(p)),
                None => "waiting for a reach".to_owned(),
            },
            PickPhase::Reach { object } => format!("reaching the {}", self.name(object)),
            PickPhase::Carry { object } => format!("carrying the {}", self.name(object)),
            PickPhase::Place { object, .. } => format!("placing the {}", self.name(object)),
            PickPhase::Retreat => "retreating".to_owned(),
        }
    }

    /// The status line: the move being played, what the robot does, the moves placed.
    pub fn status_line(&self, game: &ChessGame, held: &HeldObject) -> String {
        let moves = game.moves();
        let placed = moves.iter().filter(|m| m.place_error_mm.is_some()).count();
        let right = moves.iter().filter(|m| m.correct).count();
        let current = moves
            .iter()
            .find(|m| m.place_error_mm.is_none())
            .map_or_else(
                || "all played".to_owned(),
                |m| format!("move {}", m.notation),
            );
        let hand = match game.held() {
            Some(p) => format!("holding the {}'s twin", self.name(p)),
            None if held.held.is_some() => "holding".to_owned(),
            None => "not holding".to_owned(),
        };
        let error = self
            .last_error
            .as_ref()
            .map_or_else(String::new, |e| format!("; last error: {e}"));
        format!(
            "chess ({}): {current}; hand {hand}; robot {}; placed {placed}/{} ({right} right){error}",
            self.source,
            self.doing(game),
            moves.len()
        )
    }

    /// One line for the end of a run: ticks, moves placed and right, the wait from the virtual
    /// to the real grasp, placement, then each move played.
    pub fn summary(&self, game: &ChessGame) -> String {
        let moves = game.moves();
        let placed: Vec<&MoveResult> = moves
            .iter()
            .filter(|m| m.place_error_mm.is_some())
            .collect();
        let right = moves.iter().filter(|m| m.correct).count();
        let median = |v: Vec<f64>, decimals: usize| {
            avatarm_core::stats::Spread::some_of(&v)
                .map_or_else(|| "-".to_owned(), |s| format!("{:.decimals$}", s.median))
        };
        let waits = median(moves.iter().filter_map(|m| m.grasp_delay_ms).collect(), 0);
        let errors = median(placed.iter().filter_map(|m| m.place_error_mm).collect(), 1);
        let per_move: Vec<String> = placed
            .iter()
            .map(|m| {
                format!(
                    "{} {} ({}, {:.1} mm)",
                    m.notation,
                    if m.correct { "right" } else { "wrong" },
                    m.grasped.as_deref().unwrap_or("none"),
                    m.place_error_mm.unwrap_or(f64::NAN)
                )
            })
            .collect();
        format!(
            "chess: {} ticks, {} of {} moves placed, {right} right, virtual to real grasp median {waits} ms, placed median {} mm from the square{}; {}",
            self.ticks,
            placed.len(),
            moves.len(),
            errors,
            self.last_error
                .as_ref()
                .map_or_else(String::new, |e| format!(", last error: {e}")),
            if per_move.is_empty() {
                "no move placed".to_owned()
            } else {
                per_move.join(", ")
            }
        )
    }
}
