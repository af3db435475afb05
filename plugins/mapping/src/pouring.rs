//! The paper's experiment: pour from a bottle through the Avatarm, measured.
//!
//! A scripted hand (minimum-jerk keyframes with seeded tremor and tracking noise, and a seeded
//! start pose) grasps the bottle's twin in physics, lifts it about 5 cm, pours, puts it upright
//! and raises it 9 cm more. The mapping drives the simulated arm, which starts with its open
//! gripper around the real bottle (the paper's robot did not pre-grasp either: the grasp
//! happens when the hand squeezes the twin). Each trial records the twin mapped into the real
//! world and the real bottle's true pose; the error between them from the moment the gripper
//! closes is the paper's measure: position RMSE and roll/pitch/yaw RMSE.
//!
//! Headless and without rendering: the object metrics do not depend on the video.

use std::time::Duration;

use avatarm_core::rng::Rng;
use avatarm_core::robot::ik::solve_pose;
use avatarm_core::sim::SimRobot;
use avatarm_core::teleop::hand::{HandKeyframe, HandNoise, HandScript, Handedness};
use avatarm_core::teleop::mapping::{MappingMode, MappingSettings, VirtualToReal, pose_rmse};
use avatarm_core::teleop::safety::SafetySettings;
use avatarm_hand::{ActiveHand, GraspTarget, HandDrive, HeldObject, ObjectContacts, ScriptedHand};
use avatarm_scene::prop::BOTTLE_NECK_RADIUS_FRACTION;
pub use avatarm_scene::task::{PouringTask, TrialSetup};
use bevy::prelude::*;
use bevy_rapier3d::prelude::*;
use nalgebra::{DVector, Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::{MappingError, Teleop, TeleopConfig, TeleopSample, TickSource};
use avatarm_core::sim::arm::{CarriedObject, RobotInterface, SimArm};

/// The arm of `setup` with its open gripper around the bottle: a side grasp at the body's
/// centre, approaching horizontally from the robot's base, fingers closing horizontally.
/// Returns the joint positions and the bottle's centre in the tool frame.
pub fn grasp_configuration(
    setup: &TrialSetup,
) -> Result<(DVector<f64>, Isometry3<f64>), MappingError> {
    let c = setup.bottle_centre();
    let p = c.translation.vector;
    let b = setup.base.translation.vector;
    let approach = Vector3::new(p.x - b.x, p.y - b.y, 0.0)
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::x);
    let fingers = Vector3::new(-approach.y, approach.x, 0.0);
    let down = fingers.cross(&approach);
    let rot = UnitQuaternion::from_matrix(&Matrix3::from_columns(&[down, fingers, approach]));
    let tool = Isometry3::from_parts(Translation3::from(p), rot);
    // Several starts; keep the solution farthest from its joint limits, so the arm has room
    // to lift and pour (the first solution found is often at a wrist limit).
    let limits = setup.model.dof_limits();
    let margin = |q: &DVector<f64>| {
        setup
            .arm
            .iter()
            .map(|&i| {
                let l = &limits[i];
                ((q[i] - l.lower).min(l.upper - q[i]) / (l.upper - l.lower)).max(0.0)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let yaw = (p.y - b.y).atan2(p.x - b.x);
    let mut best: Option<DVector<f64>> = None;
    let mut last_err = None;
    for j0 in [setup.q_start[setup.arm[0]], yaw] {
        for wrist in [-1.5, 0.0, 1.5, 3.0] {
            let mut start = setup.q_start.clone();
            if setup.arm.len() == 7 {
                start[setup.arm[0]] = j0;
                start[setup.arm[4]] = 0.0;
                start[setup.arm[6]] = wrist;
            }
            match solve_pose(
                &setup.model,
                &setup.base,
                setup.tcp,
                &setup.arm,
                &start,
                &tool,
            ) {
                Ok(q) => {
                    if best.as_ref().is_none_or(|b| margin(&q) > margin(b)) {
                        best = Some(q);
                    }
                }
                Err(e) => last_err = Some(e),
            }
        }
    }
    let q = best.ok_or_else(|| MappingError::Grasp {
        source: Box::new(last_err.unwrap_or_else(|| avatarm_core::Error::Ik {
            message: "no start tried".into(),
        })),
    })?;
    let reached = setup.model.forward_kinematics(&setup.base, q.as_slice())[setup.tcp];
    Ok((q, reached.inverse() * c))
}

/// One trial's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialResult {
    /// Trial index.
    pub trial: u32,
    /// Its seed.
    pub seed: u64,
    /// Mode.
    pub mode: MappingMode,
    /// Position RMSE (m) between the real bottle and the mapped twin, from the grasp on.
    pub pos_rmse_m: f64,
    /// Roll RMSE (degrees).
    pub roll_rmse_deg: f64,
    /// Pitch RMSE (degrees).
    pub pitch_rmse_deg: f64,
    /// Yaw RMSE (degrees).
    pub yaw_rmse_deg: f64,
    /// When the gripper closed (s); `None`: it never did and the errors cover the whole trial.
    pub grasp_at_s: Option<f64>,
    /// Largest height gain of the twin (m, virtual scene) and of the real bottle (m).
    pub twin_lift_m: f64,
    /// See `twin_lift_m`.
    pub real_lift_m: f64,
    /// Largest position error during the trial (m).
    pub max_pos_error_m: f64,
    /// Largest commanded TCP speed (m/s).
    pub max_tcp_speed: f64,
    /// Ticks on which the limiter was stopping the robot.
    pub stop_ticks: u64,
    /// Largest contact force of the hand on the twin (N).
    pub max_contact_n: f64,
    /// Wall time of the trial's loop (hand, physics, mapping, robot), s.
    pub wall_s: f64,
    /// Mean wall time of one control tick (mapping and limiter), µs.
    pub tick_us_mean: f64,
    /// Hand frames refused as invalid (non-finite joints).
    pub hand_frames_refused: u64,
}

/// Mean and standard deviation (sample, n − 1) over trials.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeanStd {
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
}

impl MeanStd {
    /// Of a list of values (std 0 for one value).
    pub fn of(values: &[f64]) -> Self {
        let n = values.len().max(1) as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = if values.len() > 1 {
            values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Self {
            mean,
            std: var.sqrt(),
        }
    }
}

/// One mode over all trials: the report's `object.<mode>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModeSummary {
    /// Position RMSE (m).
    pub pos_rmse_m: MeanStd,
    /// Roll RMSE (degrees).
    pub roll_rmse_deg: MeanStd,
    /// Pitch RMSE (degrees).
    pub pitch_rmse_deg: MeanStd,
    /// Yaw RMSE (degrees).
    pub yaw_rmse_deg: MeanStd,
    /// Trials in which the gripper closed.
    pub grasped: u32,
    /// Largest commanded TCP speed over all trials (m/s).
    pub max_tcp_speed: f64,
    /// Every trial.
    pub trials: Vec<TrialResult>,
}

impl ModeSummary {
    /// Summarises trials of one mode.
    pub fn of(trials: Vec<TrialResult>) -> Self {
        let col =
            |f: fn(&TrialResult) -> f64| MeanStd::of(&trials.iter().map(f).collect::<Vec<_>>());
        Self {
            pos_rmse_m: col(|t| t.pos_rmse_m),
            roll_rmse_deg: col(|t| t.roll_rmse_deg),
            pitch_rmse_deg: col(|t| t.pitch_rmse_deg),
            yaw_rmse_deg: col(|t| t.yaw_rmse_deg),
            grasped: trials.iter().filter(|t| t.grasp_at_s.is_some()).count() as u32,
            max_tcp_speed: trials.iter().map(|t| t.max_tcp_speed).fold(0.0, f64::max),
            trials,
        }
    }
}

/// The paper's figures (ICRA 2023, 10 trials): position 0.0173 ± 0.0132 m, roll 1.81 ± 1.80°,
/// pitch 2.08 ± 2.49°, yaw 3.99 ± 5.27°.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PaperFigures {
    /// Position RMSE (m).
    pub pos_rmse_m: MeanStd,
    /// Roll RMSE (degrees).
    pub roll_rmse_deg: MeanStd,
    /// Pitch RMSE (degrees).
    pub pitch_rmse_deg: MeanStd,
    /// Yaw RMSE (degrees).
    pub yaw_rmse_deg: MeanStd,
}

/// The published figures.
pub const PUBLISHED: PaperFigures = PaperFigures {
    pos_rmse_m: MeanStd {
        mean: 0.0173,
        std: 0.0132,
    },
    roll_rmse_deg: MeanStd {
        mean: 1.81,
        std: 1.80,
    },
    pitch_rmse_deg: MeanStd {
        mean: 2.08,
        std: 2.49,
    },
    yaw_rmse_deg: MeanStd {
        mean: 3.99,
        std: 5.27,
    },
};

/// A trial's full record, for tests and plots.
#[derive(Debug, Clone)]
pub struct TrialRecord {
    /// The result.
    pub result: TrialResult,
    /// Every control tick.
    pub samples: Vec<TeleopSample>,
    /// The twin's pose every tick (virtual scene).
    pub twin: Vec<Isometry3<f64>>,
}

/// The hand script of trial `trial`: the task's keyframes placed at the twin, with the
/// trial's start pose, grasp height and noise seed.
pub fn trial_script(
    task: &PouringTask,
    twin_centre: &Vector3<f64>,
    trial: u32,
) -> Result<HandScript, MappingError> {
    let seed = task.seed.wrapping_add(u64::from(trial));
    let mut rng = Rng::stream(seed, 0x504f_5552);
    let mut sym = |a: f64| (2.0 * rng.uniform() - 1.0) * a;
    let start = Vector3::new(
        sym(task.start_jitter_m),
        sym(task.start_jitter_m),
        sym(task.start_jitter_m),
    );
    let grasp_dz = sym(task.grasp_jitter_m);
    let keys = task
        .hand
        .iter()
        .enumerate()
        .map(|(i, k)| {
            let offset = if i == 0 {
                start + Vector3::new(0.0, 0.0, grasp_dz)
            } else {
                Vector3::new(0.0, 0.0, grasp_dz)
            };
            let p = twin_centre + Vector3::from(k.xyz) + offset;
            HandKeyframe {
                xyz: [p.x, p.y, p.z],
                ..*k
            }
        })
        .collect();
    Ok(HandScript::new(
        Handedness::Right,
        keys,
        HandNoise { seed, ..task.noise },
    )?)
}

/// The twin's collider: the body cylinder about the origin and the neck above (z up).
fn bottle_collider(radius: f32, body: f32, height: f32) -> Collider {
    let neck = height - body;
    let up = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
    Collider::compound(vec![
        (Vec3::ZERO, up, Collider::cylinder(body / 2.0, radius)),
        (
            Vec3::new(0.0, 0.0, body / 2.0 + neck / 2.0),
            up,
            Collider::cylinder(neck / 2.0, radius * BOTTLE_NECK_RADIUS_FRACTION as f32),
        ),
    ])
}

/// Checks the task and the set-up, and places the arm around the bottle: what every trial
/// shares.
pub fn prepare(task: &PouringTask, setup: &TrialSetup) -> Result<Prepared, MappingError> {
    task.validate()?;
    if !(setup.control_rate_hz.is_finite() && setup.control_rate_hz >= 10.0) {
        return Err(MappingError::Setup {
            message: format!("control rate {} Hz: at least 10 Hz", setup.control_rate_hz),
        });
    }
    let (q0, tcp_from_object) = grasp_configuration(setup)?;
    Ok(Prepared {
        q0,
        tcp_from_object,
    })
}

/// The arm's start around the bottle and the bottle in the tool frame ([`prepare`]).
#[derive(Debug, Clone)]
pub struct Prepared {
    q0: DVector<f64>,
    tcp_from_object: Isometry3<f64>,
}

impl Prepared {
    /// The arm's joint positions around the bottle (q order): where a real robot is moved
    /// before a trial.
    pub fn q0(&self) -> &DVector<f64> {
        &self.q0
    }
}

/// One trial's world before it runs: the teleoperation loop with the simulated arm around the
/// real bottle, the trial's hand script, and where the twin starts. [`run_trial`] steps it
/// headless; `avatarm run` steps it live in the preview with any hand source.
pub struct TrialParts {
    /// The loop (simulated arm, mapping, limiter).
    pub teleop: Teleop,
    /// The trial's scripted hand (virtual scene).
    pub script: HandScript,
    /// How the hand bodies follow whichever hand source drives them (the task's filter).
    pub hand_drive: HandDrive,
    /// The twin's start pose (virtual scene, its centre).
    pub twin_start: Isometry3<f64>,
    /// The virtual scene to the real one.
    pub v2r: VirtualToReal,
    /// The control (and physics) period.
    pub period: Duration,
    bodies: TrialBodies,
}

/// The physics bodies of a trial: a virtual table under the twin and the bottle's twin.
#[derive(Debug, Clone, Copy)]
struct TrialBodies {
    twin: Transform,
    table_top: f32,
    radius: f32,
    body: f32,
    height: f32,
    mass: f32,
    friction: f32,
}

/// The task's simulated arm at `q` (all joints, the model's order) with the real bottle
/// standing where the setup says, not held.
pub fn simulated_arm(setup: &TrialSetup, q: DVector<f64>) -> SimArm {
    let centre = setup.bottle_centre();
    SimArm::new(
        SimRobot::new(setup.sim, setup.model.dof_limits(), q),
        setup.model.clone(),
        setup.base,
        setup.tcp,
        CarriedObject {
            pose: centre,
            rest_z: centre.translation.z,
            grasp_radius_m: 0.02,
            held: None,
        },
    )
}

impl TrialParts {
    /// Builds trial `trial` in `mode` (the arm placed by [`prepare`]) on the simulated arm.
    pub fn new(
        task: &PouringTask,
        setup: &TrialSetup,
        prepared: &Prepared,
        mode: MappingMode,
        trial: u32,
    ) -> Result<Self, MappingError> {
        Self::on_robot(task, setup, prepared, mode, trial, None)
    }

    /// [`TrialParts::new`] on `robot` (a real robot's link, already at [`Prepared::q0`]), or
    /// on the simulated arm when `None`.
    pub fn on_robot(
        task: &PouringTask,
        setup: &TrialSetup,
        prepared: &Prepared,
        mode: MappingMode,
        trial: u32,
        robot: Option<Box<dyn RobotInterface>>,
    ) -> Result<Self, MappingError> {
        let (q0, tcp_from_object) = (prepared.q0.clone(), prepared.tcp_from_object);
        let centre = setup.bottle_centre();
        let v2r = task.virtual_to_real(&centre.translation.vector);
        let twin_start = v2r.virtual_pose(&centre);
        let script = trial_script(task, &twin_start.translation.vector, trial)?;
        let period = Duration::from_secs_f64(1.0 / setup.control_rate_hz);
        let dt = period.as_secs_f64();
        let arm = robot.unwrap_or_else(|| Box::new(simulated_arm(setup, q0)));
        let teleop = Teleop::with_robot(
            TeleopConfig {
                model: setup.model.clone(),
                base: setup.base,
                tcp: setup.tcp,
                arm: setup.arm.clone(),
                tcp_from_object,
                v2r,
                mapping: MappingSettings {
                    mode,
                    gain: task.gain,
                    feedforward_smoothing_s: task.feedforward_smoothing_s,
                    dls: avatarm_core::robot::ik::DlsSettings {
                        dt,
                        ..Default::default()
                    },
                    ..MappingSettings::default()
                },
                safety: SafetySettings {
                    max_tcp_speed: task.max_tcp_speed,
                    ..SafetySettings::default()
                },
            },
            arm,
        )?;
        let k = task.k as f32;
        let twin = avatarm_twin::iso_to_transform(&twin_start);
        let body = setup.body_height_m() as f32 * k;
        Ok(Self {
            teleop,
            script,
            hand_drive: HandDrive {
                filter: task.hand_filter,
                ..HandDrive::default()
            },
            twin_start,
            v2r,
            period,
            bodies: TrialBodies {
                twin,
                table_top: twin.translation.z - body / 2.0,
                radius: setup.bottle_radius_m as f32 * k,
                body,
                height: setup.bottle_height_m as f32 * k,
                mass: task.mass_kg as f32,
                friction: task.friction as f32,
            },
        })
    }

    /// The operator's physics world for this trial: [`avatarm_hand::headless_app`] (one fixed
    /// step of the control period per `App::update` after the first, which has none) with the hand
    /// driven by `hand` and the trial's bodies. The one-process trials ([`run_trial`]) and the
    /// operator's site of a two-site session step this same world, so the same hand moves the same
    /// twin to the bit: Rapier's contacts depend on the order bodies enter it, which anything else
    /// in the world (a resource more) can change, and a grasp that brushes the bottle first turns a
    /// micrometre into a different grasp.
    pub fn hand_app(&self, hand: ActiveHand) -> App {
        let mut app = avatarm_hand::headless_app(self.period);
        app.insert_resource(self.hand_drive).insert_resource(hand);
        app.add_systems(Startup, self.spawn_bodies());
        app
    }

    /// A startup system that spawns the trial's bodies (needs Rapier and the hand plugin).
    pub fn spawn_bodies(&self) -> impl FnMut(Commands) + Send + Sync + 'static {
        let b = self.bodies;
        move |mut commands: Commands| {
            let at = b.twin.translation;
            commands.spawn((
                Name::new("virtual table"),
                RigidBody::Fixed,
                Collider::cuboid(0.6, 0.6, 0.05),
                Friction::coefficient(0.6),
                Transform::from_xyz(at.x, at.y, b.table_top - 0.05),
            ));
            commands.spawn((
                Name::new("bottle twin"),
                GraspTarget,
                RigidBody::Dynamic,
                bottle_collider(b.radius, b.body, b.height),
                ColliderMassProperties::Mass(b.mass),
                Friction::coefficient(b.friction),
                Ccd::enabled(),
                Velocity::zero(),
                b.twin,
            ));
        }
    }
}

/// Runs one trial in `mode`. Errors when the set-up is impossible (the gripper cannot reach
/// the bottle, bad settings).
pub fn run_trial(
    task: &PouringTask,
    setup: &TrialSetup,
    mode: MappingMode,
    trial: u32,
) -> Result<TrialRecord, MappingError> {
    run_trial_with(task, setup, mode, trial, ActiveHand::new)
}

/// [`run_trial`] with the trial's scripted hand passed through `hand` first: tests wrap it
/// to inject tracking faults the script cannot describe (NaN frames).
pub fn run_trial_with(
    task: &PouringTask,
    setup: &TrialSetup,
    mode: MappingMode,
    trial: u32,
    hand: impl FnOnce(ScriptedHand) -> ActiveHand,
) -> Result<TrialRecord, MappingError> {
    run_prepared(task, setup, &prepare(task, setup)?, mode, trial, hand, None)
}

/// One trial on a real robot's link (`robot`, already at [`Prepared::q0`] with its gripper
/// open around the real bottle), stepped in real time: each control tick waits for the wall
/// clock. With no ground truth, the real bottle is where the measured joint states put it.
pub fn run_trial_on_robot(
    task: &PouringTask,
    setup: &TrialSetup,
    prepared: &Prepared,
    mode: MappingMode,
    trial: u32,
    robot: Box<dyn RobotInterface>,
) -> Result<TrialRecord, MappingError> {
    run_prepared(
        task,
        setup,
        prepared,
        mode,
        trial,
        ActiveHand::new,
        Some(robot),
    )
}

/// The operator's side of a control tick as the hand's world holds it after a step
/// ([`read_hand_world`]).
#[derive(Debug, Clone, Copy)]
pub struct HandWorldState {
    /// The newest fixed step's time (s, the world's `Time<Fixed>`): 0 after the first
    /// `App::update`, which runs no step (Bevy's first update has no elapsed time).
    pub now_s: f64,
    /// The twin's pose (virtual scene, its centre).
    pub twin: Isometry3<f64>,
    /// The hand holds the twin ([`avatarm_hand::HeldObject`]).
    pub held: bool,
    /// When the newest hand frame was captured (s, the world's clock), if any.
    pub hand_stamp_s: Option<f64>,
    /// The newest hand frame is tracked.
    pub hand_tracked: bool,
    /// The largest contact force of the step (N).
    pub max_force_n: f64,
}

/// Reads the hand's world after a step: the state above, and the hand's contacts on the twin
/// and their points' velocities (virtual scene, m/s) into `contacts` and `velocities`
/// (cleared first; the same length). Errors when the world has no single twin
/// ([`GraspTarget`]) or lacks the hand plugin's resources.
pub fn read_hand_world(
    world: &mut World,
    contacts: &mut Vec<avatarm_core::teleop::grasp::Contact>,
    velocities: &mut Vec<Vector3<f64>>,
) -> Result<HandWorldState, MappingError> {
    let twin = world
        .query_filtered::<&Transform, With<GraspTarget>>()
        .single(world)
        .map(avatarm_twin::transform_to_iso)
        .map_err(|e| MappingError::Trial {
            message: format!("the twin is gone: {e}"),
        })?;
    let missing = |what: &str| MappingError::Trial {
        message: format!("the hand's world has no {what} (it is not TrialParts::hand_app's)"),
    };
    contacts.clear();
    velocities.clear();
    let found = world
        .get_resource::<ObjectContacts>()
        .ok_or_else(|| missing("ObjectContacts"))?;
    for c in &found.contacts {
        contacts.push(c.contact);
        velocities.push(c.object_velocity);
    }
    let max_force_n = found.max_force_n;
    let latest = world
        .get_resource::<ActiveHand>()
        .ok_or_else(|| missing("ActiveHand"))?
        .latest
        .as_ref();
    Ok(HandWorldState {
        now_s: world
            .get_resource::<Time<Fixed>>()
            .ok_or_else(|| missing("Time<Fixed>"))?
            .elapsed_secs_f64(),
        twin,
        held: world
            .get_resource::<HeldObject>()
            .ok_or_else(|| missing("HeldObject"))?
            .held
            .is_some(),
        hand_stamp_s: latest.map(|f| f.t_s),
        hand_tracked: latest.is_some_and(|f| f.tracked),
        max_force_n,
    })
}

fn run_prepared(
    task: &PouringTask,
    setup: &TrialSetup,
    prepared: &Prepared,
    mode: MappingMode,
    trial: u32,
    hand: impl FnOnce(ScriptedHand) -> ActiveHand,
    robot: Option<Box<dyn RobotInterface>>,
) -> Result<TrialRecord, MappingError> {
    let realtime = robot.is_some();
    let parts = TrialParts::on_robot(task, setup, prepared, mode, trial, robot)?;
    let centre = setup.bottle_centre();
    let twin_start = parts.twin_start;
    let period = parts.period;
    let dt = period.as_secs_f64();
    let hand = hand(ScriptedHand::new(parts.script.clone(), task.hand_rate_hz));
    let mut app = parts.hand_app(hand);
    let mut teleop = parts.teleop;
    teleop.record = true;
    let steps = (task.duration_s / dt).round() as usize;
    let mut twin = Vec::with_capacity(steps);
    let mut max_contact: f64 = 0.0;
    let (mut contacts, mut velocities) = (Vec::new(), Vec::new());
    let mut last_step_s: Option<f64> = None;
    let started = std::time::Instant::now();
    for i in 0..steps {
        if realtime {
            let due = started + period.mul_f64(i as f64);
            std::thread::sleep(due.saturating_duration_since(std::time::Instant::now()));
        }
        app.update();
        // The mapping's tick after the step, as the operator's site runs it: the world the
        // hand moves is the same with or without a robot in this process.
        let state = read_hand_world(app.world_mut(), &mut contacts, &mut velocities)?;
        twin.push(state.twin);
        max_contact = max_contact.max(state.max_force_n);
        // Bevy's first update runs no physics step (the fixed clock is still at 0): nothing new
        // to tick on, as for an in-step tick.
        let stepped = state.now_s > 0.0 && last_step_s != Some(state.now_s);
        last_step_s = Some(state.now_s);
        if !stepped {
            continue;
        }
        teleop.tick(
            state.now_s,
            dt,
            TickSource::Local {
                contacts: &contacts,
                contact_velocities: &velocities,
                twin_pose: Ok(state.twin),
                held: state.held,
                hand_stamp_s: state.hand_stamp_s,
                hand_tracked: state.hand_tracked,
            },
        );
    }
    let wall_s = started.elapsed().as_secs_f64();
    let hand_frames_refused = app.world().resource::<ActiveHand>().refused;
    let samples = teleop.log;
    let grasp = samples.iter().position(|s| s.gripper_closed);
    let from = grasp.unwrap_or(0);
    // The real bottle: the truth where the backend knows it (simulation), else where the
    // measured joint states put it.
    let real = TeleopSample::real_object;
    let window: Vec<&TeleopSample> = samples[from..]
        .iter()
        .filter(|s| real(s).is_some() && s.target.translation.vector.iter().all(|v| v.is_finite()))
        .collect();
    let targets: Vec<Isometry3<f64>> = window.iter().map(|s| s.target).collect();
    let truths: Vec<Isometry3<f64>> = window.iter().filter_map(|s| real(s)).collect();
    let rmse = pose_rmse(&targets, &truths).ok_or_else(|| MappingError::Trial {
        message: "no samples to measure".into(),
    })?;
    let max_pos_error_m = targets
        .iter()
        .zip(&truths)
        .map(|(a, b)| (a.translation.vector - b.translation.vector).norm())
        .fold(0.0, f64::max);
    let z0 = twin_start.translation.z;
    let twin_lift_m = twin
        .iter()
        .map(|p| p.translation.z - z0)
        .fold(0.0, f64::max);
    let real_lift_m = samples
        .iter()
        .filter_map(real)
        .map(|p| p.translation.z - centre.translation.z)
        .fold(0.0, f64::max);
    Ok(TrialRecord {
        result: TrialResult {
            trial,
            seed: task.seed.wrapping_add(u64::from(trial)),
            mode,
            pos_rmse_m: rmse[0],
            roll_rmse_deg: rmse[1],
            pitch_rmse_deg: rmse[2],
            yaw_rmse_deg: rmse[3],
            grasp_at_s: grasp.map(|i| samples[i].t_s),
            twin_lift_m,
            real_lift_m,
            max_pos_error_m,
            max_tcp_speed: teleop.status.max_tcp_speed,
            stop_ticks: samples.iter().filter(|s| s.stopping).count() as u64,
            max_contact_n: max_contact,
            wall_s,
            tick_us_mean: teleop.status.tick_wall_s / teleop.status.ticks.max(1) as f64 * 1e6,
            hand_frames_refused,
        },
        samples,
        twin,
    })
}

/// Every trial of every mode of the task, summarised per mode (the report's `object`).
pub fn run_trials(
    task: &PouringTask,
    setup: &TrialSetup,
    mut progress: impl FnMut(MappingMode, u32),
) -> Result<Vec<(MappingMode, ModeSummary)>, MappingError> {
    let prepared = prepare(task, setup)?;
    let mut out = Vec::new();
    for &mode in &task.modes {
        let mut trials = Vec::new();
        for i in 0..task.trials {
            progress(mode, i);
            let record = run_prepared(task, setup, &prepared, mode, i, ActiveHand::new, None)?;
            trials.push(record.result);
        }
        out.push((mode, ModeSummary::of(trials)));
    }
    Ok(out)
}
