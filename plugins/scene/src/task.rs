//! The teleoperation task a scene measures (`[task]`): the paper's pouring experiment, as data.
//!
//! [`PouringTask`] is the task as written (the hand's script, the modes, gains and noise);
//! [`TrialSetup`] is its real side resolved against the scene (the robot, the tool link, the
//! arm joints, the bottle). Both are checked when the scene loads. `avatarm_mapping::pouring`
//! runs the trials.

use std::sync::Arc;

use avatarm_core::robot::{LinkId, RobotModel};
use avatarm_core::sim::SimRobotParams;
use avatarm_core::teleop::hand::{
    HandFilterSettings, HandKeyframe, HandNoise, HandScript, Handedness,
};
use avatarm_core::teleop::mapping::{MappingMode, MappingSettings, VirtualToReal};
use avatarm_core::teleop::safety::SafetySettings;
use nalgebra::{DVector, Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::SceneError;
use crate::prop::{BOTTLE_BODY_FRACTION, Prop, find_prop};

/// The task as a scene describes it (`[task]`, docs/scene-format.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PouringTask {
    /// The scene prop that is the bottle (a `bottle` or `cylinder` prop).
    pub object: String,
    /// The robot's tool link, between the gripper's fingers.
    pub tcp_link: String,
    /// Joints the mapping drives; empty: every movable joint whose name does not contain
    /// "finger" (the gripper's).
    pub arm_joints: Vec<String>,
    /// Trials per mode.
    pub trials: u32,
    /// Seed of trial 0 (trial `i` uses `seed + i` for its noise and start pose).
    pub seed: u64,
    /// Length of a trial (s).
    pub duration_s: f64,
    /// The modes to run.
    pub modes: Vec<MappingMode>,
    /// Mass of the bottle's twin (kg).
    pub mass_kg: f64,
    /// Friction of the twin's surface.
    pub friction: f64,
    /// Start pose of the hand: uniform offset in each axis, ± this (m).
    pub start_jitter_m: f64,
    /// Height of the grasp on the bottle: uniform offset, ± this (m).
    pub grasp_jitter_m: f64,
    /// Hand tracker rate (Hz).
    pub hand_rate_hz: f64,
    /// Tremor and tracking noise (the seed is set per trial).
    pub noise: HandNoise,
    /// Closed-loop gain (1/s).
    pub gain: f64,
    /// Time constant of the closed loop's low-pass on the feed-forward twist (s; 0: off).
    pub feedforward_smoothing_s: f64,
    /// The filter on the tracked hand's joints (docs/hand.md).
    pub hand_filter: HandFilterSettings,
    /// TCP speed cap (m/s), the paper's ISO 10218 figure by default.
    pub max_tcp_speed: f64,
    /// Scale of the twin relative to the real bottle (`k`).
    pub k: f64,
    /// The virtual scene's yaw about the bottle (degrees) and its offset (m): where the twin
    /// stands in front of the user, relative to the real bottle.
    pub virtual_yaw_deg: f64,
    /// See `virtual_yaw_deg`.
    pub virtual_offset: [f64; 3],
    /// The hand's keyframes, positions relative to the twin's centre (virtual scene axes).
    pub hand: Vec<HandKeyframe>,
}

impl Default for PouringTask {
    fn default() -> Self {
        let roll = std::f64::consts::FRAC_PI_2;
        let pour: f64 = 1.0;
        let key = |t_s: f64, xyz: [f64; 3], roll: f64, grip: f64| HandKeyframe {
            t_s,
            xyz,
            rpy: [roll, 0.0, 0.0],
            grip,
            tracked: true,
        };
        // Palm on the bottle's −y side, fingers along +x wrapping around it; the pour turns
        // the hand about the bottle's centre (the wrist moves on that arc).
        let (px, py, gg): (f64, f64, f64) = (-0.05, -0.040, 0.7);
        let (wy, wz) = (py * pour.cos(), -py * pour.sin());
        Self {
            object: "bottle".into(),
            tcp_link: "right_gripper_tip".into(),
            arm_joints: Vec::new(),
            trials: 10,
            seed: 1,
            duration_s: 10.0,
            modes: vec![MappingMode::Paper, MappingMode::ClosedLoop],
            mass_kg: 0.5,
            friction: 1.0,
            start_jitter_m: 0.02,
            grasp_jitter_m: 0.01,
            hand_rate_hz: 90.0,
            noise: HandNoise::default(),
            gain: MappingSettings::default().gain,
            feedforward_smoothing_s: MappingSettings::default().feedforward_smoothing_s,
            hand_filter: HandFilterSettings::default(),
            max_tcp_speed: SafetySettings::default().max_tcp_speed,
            k: 1.0,
            virtual_yaw_deg: 0.0,
            virtual_offset: [0.0; 3],
            hand: vec![
                key(0.0, [px, -0.14, 0.0], roll, 0.0),
                key(1.0, [px, py, 0.0], roll, 0.0),
                key(1.8, [px, py, 0.0], roll, gg),
                key(2.2, [px, py, 0.0], roll, gg),
                key(3.7, [px, py, 0.05], roll, gg),
                key(5.2, [px, wy, 0.05 + wz], roll - pour, gg),
                key(5.7, [px, wy, 0.05 + wz], roll - pour, gg),
                key(7.2, [px, py, 0.05], roll, gg),
                key(8.7, [px, py, 0.14], roll, gg),
            ],
        }
    }
}

impl PouringTask {
    /// Checks the numbers; errors name the field.
    pub fn validate(&self) -> Result<(), SceneError> {
        let positive = [
            ("duration_s", self.duration_s),
            ("mass_kg", self.mass_kg),
            ("hand_rate_hz", self.hand_rate_hz),
            ("max_tcp_speed", self.max_tcp_speed),
            ("k", self.k),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(SceneError::field(
                    format!("task.{name}"),
                    format!("{v} must be a positive number"),
                ));
            }
        }
        let non_negative = [
            ("friction", self.friction),
            ("start_jitter_m", self.start_jitter_m),
            ("grasp_jitter_m", self.grasp_jitter_m),
            ("gain", self.gain),
            ("feedforward_smoothing_s", self.feedforward_smoothing_s),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(SceneError::field(
                    format!("task.{name}"),
                    format!("{v} must be a number >= 0"),
                ));
            }
        }
        if self.trials == 0 {
            return Err(SceneError::field("task.trials", "at least one trial"));
        }
        if self.modes.is_empty() {
            return Err(SceneError::field("task.modes", "at least one mode"));
        }
        if !self.virtual_yaw_deg.is_finite() {
            return Err(SceneError::field(
                "task.virtual_yaw_deg",
                format!("{} is not finite", self.virtual_yaw_deg),
            ));
        }
        if self.virtual_offset.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::field(
                "task.virtual_offset",
                format!("{:?} is not finite", self.virtual_offset),
            ));
        }
        self.hand_filter
            .validate()
            .map_err(|e| SceneError::value("task.hand_filter", e))?;
        HandScript::new(Handedness::Right, self.hand.clone(), self.noise)
            .map(|_| ())
            .map_err(|e| SceneError::value("task.hand", e))
    }

    /// The virtual scene relative to the real one, for a bottle whose centre is at `centre`.
    pub fn virtual_to_real(&self, centre: &Vector3<f64>) -> VirtualToReal {
        VirtualToReal {
            k: self.k,
            rotation: UnitQuaternion::from_euler_angles(
                0.0,
                0.0,
                self.virtual_yaw_deg.to_radians(),
            ),
            real_centre: *centre,
            virtual_centre: centre + Vector3::from(self.virtual_offset),
        }
    }
}

/// A task's tool link and arm joints looked up in `model`: `arm_joints` by name, or, when
/// empty, every movable joint whose name does not contain "finger" (the gripper's). Errors
/// name `TABLE.tcp_link` or `TABLE.arm_joints`.
pub fn resolve_tool(
    model: &RobotModel,
    tcp_link: &str,
    arm_joints: &[String],
    table: &str,
) -> Result<(LinkId, Vec<usize>), SceneError> {
    let tcp = model
        .link_id(tcp_link)
        .map_err(|e| SceneError::value(format!("{table}.tcp_link"), e))?;
    let arm: Vec<usize> = if arm_joints.is_empty() {
        model
            .dof_names()
            .iter()
            .enumerate()
            .filter(|(_, n)| !n.contains("finger"))
            .map(|(i, _)| i)
            .collect()
    } else {
        arm_joints
            .iter()
            .map(|n| {
                model
                    .dof_index(n)
                    .map_err(|e| SceneError::value(format!("{table}.arm_joints"), e))
            })
            .collect::<Result<_, _>>()?
    };
    if arm.is_empty() {
        return Err(SceneError::field(
            format!("{table}.arm_joints"),
            "no arm joints to drive",
        ));
    }
    Ok((tcp, arm))
}

/// The real side of a trial: the robot and the bottle, from the scene.
#[derive(Debug, Clone)]
pub struct TrialSetup {
    /// The robot.
    pub model: Arc<RobotModel>,
    /// Its root link in the world.
    pub base: Isometry3<f64>,
    /// Joint positions before the arm is moved to the bottle (IK starts here).
    pub q_start: DVector<f64>,
    /// The tool link.
    pub tcp: LinkId,
    /// Arm joints.
    pub arm: Vec<usize>,
    /// Simulated robot timing.
    pub sim: SimRobotParams,
    /// Control and physics rate (Hz).
    pub control_rate_hz: f64,
    /// Where the bottle's base centre stands on the table (world).
    pub bottle_base: Isometry3<f64>,
    /// Bottle body radius and total height (m); the body is the lower
    /// [`BOTTLE_BODY_FRACTION`], as the scene's bottle prop.
    pub bottle_radius_m: f64,
    /// See `bottle_radius_m`.
    pub bottle_height_m: f64,
}

impl TrialSetup {
    /// Height of the bottle's body (the part the hand and the gripper hold).
    pub fn body_height_m(&self) -> f64 {
        self.bottle_height_m * BOTTLE_BODY_FRACTION
    }

    /// The bottle's reference frame: the centre of its body, z up.
    pub fn bottle_centre(&self) -> Isometry3<f64> {
        self.bottle_base * Translation3::new(0.0, 0.0, self.body_height_m() / 2.0)
    }

    /// The real side of `task` in a scene: the tool link and arm joints looked up in `model`,
    /// the bottle found among `props` by name. Errors name the `task.*` field.
    pub fn resolve(
        task: &PouringTask,
        model: &Arc<RobotModel>,
        base: Isometry3<f64>,
        q_start: DVector<f64>,
        sim: SimRobotParams,
        control_rate_hz: f64,
        props: &[Prop],
    ) -> Result<Self, SceneError> {
        let (tcp, arm) = resolve_tool(model, &task.tcp_link, &task.arm_joints, "task")?;
        let (_, prop) = find_prop(props, &task.object).ok_or_else(|| {
            SceneError::field(
                "task.object",
                format!("no prop named '{}' in the scene", task.object),
            )
        })?;
        let (radius, height) = prop.shape.upright_round().ok_or_else(|| {
            SceneError::field(
                "task.object",
                format!(
                    "'{}': the pouring task needs a bottle or cylinder prop",
                    task.object
                ),
            )
        })?;
        Ok(Self {
            model: Arc::clone(model),
            base,
            q_start,
            tcp,
            arm,
            sim,
            control_rate_hz,
            bottle_base: prop.pose,
            bottle_radius_m: radius,
            bottle_height_m: height,
        })
    }
}
