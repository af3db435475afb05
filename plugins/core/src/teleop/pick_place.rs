//! The robot's side of a pick-and-place task with several objects (the paper's chess scene).
//!
//! The operator's side sends, each tick, a [`PickPlaceCommand`]: which object the hand holds
//! (or last let go of), the mapping's target for it ([`OperatorTarget`], the twin mapped into
//! the real world), and the intent estimate ([`crate::teleop::intent`]) while the hand reaches.
//! [`PickPlaceRobot`] turns that into joint velocities and gripper commands, phase by phase
//! ([`PickPhase`]):
//!
//! - **Free**: no object held. With an intent estimate the tool moves to the goal's
//!   pre-grasp pose (hovering [`PickPlaceSettings::hover_m`] above its grasp pose), and around
//!   it, gripper open, once the estimate says the hand is near; without one it holds still.
//! - **Reach**: the hand holds object `i`'s twin; the tool goes to `i`'s grasp pose (a top grasp
//!   [`PickPlaceSettings::grasp_depth_m`] below the object's top) and closes there: the real
//!   grasp.
//! - **Carry**: the mapping ([`Mapper::robot_side`]) moves the real object with the twin, kept
//!   upright and facing as it was grasped ([`upright`]).
//! - **Place**: the hand let go: the arm brings the real object to the twin's last pose, then
//!   opens, and the object's believed pose becomes where the tool left it.
//! - **Retreat**: the tool rises above the objects around it before anything else.
//!
//! Between grasps the tool travels on a clearance path ([`clearance_twist`]): up to its
//! crossing height first ([`PickPlaceRobot::crossing_z`]: [`PickPlaceSettings::clear_m`] above
//! the tallest object beside its way, at most [`PickPlaceSettings::clearance_z`]), across at
//! that height, down onto the goal, so that it never crosses the other objects. Every twist is capped at
//! [`PickPlaceSettings::max_speed`] (below the safety limiter's cap) and goes to the joints by
//! damped least squares, as the mapping's does.

use std::sync::Arc;

use nalgebra::{DVector, Isometry3, Matrix6xX, Translation3, UnitQuaternion, Vector3, Vector6};

use crate::robot::ik::dls_step;
use crate::robot::kinematics::{Frame, pose_difference};
use crate::robot::{LinkId, RobotModel};
use crate::teleop::mapping::{
    GripperCommand, Mapper, MappingSettings, OperatorTarget, RobotInputs, RobotSide,
};

/// An object the robot may pick: an upright round body (a chess piece), real world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PickObject {
    /// The object's reference frame: the centre of its body, z up at rest.
    pub pose: Isometry3<f64>,
    /// Radius (m).
    pub radius_m: f64,
    /// Height (m).
    pub height_m: f64,
}

impl PickObject {
    /// The height of the object's top (world z, m).
    pub fn top_z(&self) -> f64 {
        self.pose.translation.z + self.height_m / 2.0
    }
}

/// Settings of [`PickPlaceRobot`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PickPlaceSettings {
    /// The highest the tool point travels at between grasps (world z, m): above every object's
    /// top by a margin larger than `over_m` (the tool moves sideways from `over_m` below it).
    /// The carried object crosses with its bottom at this height.
    pub clearance_z: f64,
    /// Between grasps the tool crosses this far (m) above the top of every object beside its
    /// way ([`PickPlaceRobot::crossing_z`]), up to `clearance_z`: over a row of pawns it need
    /// not climb to the king's height. Larger than `over_m`.
    pub clear_m: f64,
    /// How far the open gripper reaches across from the tool point (m): half its opening and a
    /// finger's thickness. An object whose side comes within this and `over_m` of the tool's
    /// way is crossed above.
    pub tool_radius_m: f64,
    /// The pre-grasp pose: this far above the grasp pose (m).
    pub hover_m: f64,
    /// The grasp pose: the tool point this far below the object's top (m).
    pub grasp_depth_m: f64,
    /// The tool's orientation while it grasps (world): a top grasp, approach axis down.
    pub tool_down: UnitQuaternion<f64>,
    /// Arrived within this distance (m) ...
    pub arrive_m: f64,
    /// ... and this angle (rad).
    pub arrive_rad: f64,
    /// Horizontally over the goal within this distance (m): the tool may leave its crossing
    /// height; and the band below the crossing height in which it may move sideways.
    pub over_m: f64,
    /// Gain of the moves between grasps (1/s).
    pub gain_per_s: f64,
    /// Largest tool speed of those moves (m/s).
    pub max_speed: f64,
    /// Largest tool turn rate of those moves (rad/s).
    pub max_turn: f64,
    /// Placed when the real object is within this distance (m) ...
    pub place_m: f64,
    /// ... and this angle (rad) of the twin's last pose ...
    pub place_rad: f64,
    /// ... or after this long (s) within [`PickPlaceSettings::over_m`] of it (the last
    /// millimetres; an object still travelling to its place is not let go of in the air). One
    /// that does not get there within [`PLACE_GIVE_UP`] times this after the hand let go (out
    /// of the arm's reach, the arm stopped) is set down straight below where it is instead, and
    /// let go of at twice that whatever happens, so that the game goes on.
    pub place_timeout_s: f64,
    /// The mapping while the object is carried.
    pub mapping: MappingSettings,
}

impl PickPlaceSettings {
    /// Checks the numbers; errors name the field.
    pub fn validate(&self) -> crate::Result<()> {
        if self.clear_m <= self.over_m {
            return Err(crate::Error::BadSetting {
                what: "pick_place.clear_m".into(),
                message: format!(
                    "{} must be larger than over_m ({}): the tool moves sideways from over_m \
                     below its crossing height",
                    self.clear_m, self.over_m
                ),
            });
        }
        for (name, v) in [
            ("clear_m", self.clear_m),
            ("tool_radius_m", self.tool_radius_m),
            ("hover_m", self.hover_m),
            ("arrive_m", self.arrive_m),
            ("arrive_rad", self.arrive_rad),
            ("over_m", self.over_m),
            ("gain_per_s", self.gain_per_s),
            ("max_speed", self.max_speed),
            ("max_turn", self.max_turn),
            ("place_m", self.place_m),
            ("place_rad", self.place_rad),
            ("place_timeout_s", self.place_timeout_s),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(crate::Error::BadSetting {
                    what: format!("pick_place.{name}"),
                    message: format!("{v} must be > 0"),
                });
            }
        }
        for (name, v) in [
            ("clearance_z", self.clearance_z),
            ("grasp_depth_m", self.grasp_depth_m),
        ] {
            if !v.is_finite() {
                return Err(crate::Error::BadSetting {
                    what: format!("pick_place.{name}"),
                    message: format!("{v} is not finite"),
                });
            }
        }
        Ok(())
    }
}

/// What the operator's side sends each tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PickPlaceCommand {
    /// The object the hand holds, or last let go of (an index into the robot's objects).
    pub object: Option<usize>,
    /// The mapping's target for `object` (its `held` says whether the hand holds it now).
    pub target: Option<OperatorTarget>,
    /// The intent estimate's goal while the hand holds nothing; `None` without one (or with
    /// intent off).
    pub intent: Option<usize>,
    /// The hand is near the goal (the robot may go around it).
    pub intent_near: bool,
}

/// Where the robot is in the task.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PickPhase {
    /// Nothing held; moving to the intent's pre-grasp, or still.
    Free,
    /// The hand holds the twin of `object`: the tool goes to its grasp pose.
    Reach {
        /// The object.
        object: usize,
    },
    /// The real object follows the twin.
    Carry {
        /// The object.
        object: usize,
    },
    /// The hand let go: the real object is brought to the twin's last pose, then released.
    Place {
        /// The object.
        object: usize,
        /// When the hand let go (s).
        since_s: f64,
    },
    /// Up above the objects around the tool ([`PickPlaceRobot::crossing_z`]).
    Retreat,
}

/// What the tool moves to between grasps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PickGoal {
    /// Above `object`'s grasp pose by [`PickPlaceSettings::hover_m`].
    Hover(usize),
    /// `object`'s grasp pose, gripper open.
    Around(usize),
    /// The grasp itself (the hand holds the twin).
    Grasp(usize),
}

/// One tick's outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct PickTick {
    /// Joint velocities (all joints; zero for the others than the arm's).
    pub qdot: DVector<f64>,
    /// The gripper.
    pub gripper: GripperCommand,
    /// The phase after this tick.
    pub phase: PickPhase,
    /// Where the tool was going between grasps, if anywhere.
    pub goal: Option<PickGoal>,
    /// The tool point's Jacobian at the measured joints (6 × dof, world), for the limiter.
    pub tcp_jacobian: Matrix6xX<f64>,
    /// The tool pose at the measured joints (world).
    pub tool: Isometry3<f64>,
    /// The real object's target while carried or placed.
    pub target: Option<Isometry3<f64>>,
    /// The gripper closed on `object` in this tick (the real grasp).
    pub grasped: Option<usize>,
    /// The gripper opened on `object` in this tick (the real release).
    pub released: Option<usize>,
}

/// The linear and angular velocity of a move between grasps: up to `cross_z` (world z, m:
/// [`PickPlaceRobot::crossing_z`], or [`PickPlaceSettings::clearance_z`]), across, and down
/// onto `goal` (module docs), no lower than `floor_z` (world z, m:
/// [`PickPlaceRobot::descent_floor`]) in the last `over_m` across, at `gain_per_s` × the
/// distance left, capped at `max_speed` and `max_turn`. Returns the twist (world, at the tool
/// point) and whether the tool has arrived (within `arrive_m` and `arrive_rad`).
pub fn clearance_twist(
    tool: &Isometry3<f64>,
    goal: &Isometry3<f64>,
    cross_z: f64,
    floor_z: f64,
    s: &PickPlaceSettings,
) -> (Vector6<f64>, bool) {
    let p = tool.translation.vector;
    let e = goal.translation.vector - p;
    let across = Vector3::new(e.x, e.y, 0.0).norm();
    // Sideways only within a band below the crossing height (the margin above the objects
    // covers it), so that a tool that sagged a few millimetres does not crawl up first.
    let band = s.over_m;
    let mut v = if across > s.over_m {
        if p.z < cross_z - band {
            // Straight up first: nothing below the crossing height moves sideways.
            Vector3::new(0.0, 0.0, cross_z + band - p.z)
        } else {
            Vector3::new(e.x, e.y, cross_z - p.z)
        }
    } else {
        // The last stretch: toward the goal, above the pieces the open gripper is over.
        Vector3::new(e.x, e.y, goal.translation.z.max(floor_z) - p.z)
    } * s.gain_per_s;
    if v.norm() > s.max_speed {
        v *= s.max_speed / v.norm();
    }
    let turn = (goal.rotation * tool.rotation.inverse()).scaled_axis();
    let mut w = turn * s.gain_per_s;
    if w.norm() > s.max_turn {
        w *= s.max_turn / w.norm();
    }
    let arrived = e.norm() <= s.arrive_m && turn.norm() <= s.arrive_rad;
    (Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z), arrived)
}

/// The turn about the vertical (rad, world z, within ±π/2) from `tool_down`'s heading to the
/// top grasp's heading nearest the tool's `current` one (the twist about z of `current ·
/// tool_down⁻¹`). An upright round object is grasped the same from any heading, so the tool
/// keeps its heading where it is within a quarter turn of `tool_down`'s (a heading that has
/// drifted there is not corrected), and turns only to the nearest edge of that band otherwise: between grasps the wrist never turns more than it must,
/// and never winds further than a quarter turn from `tool_down`. (While the carry still
/// followed the twin's turn, going back to `tool_down` itself after a piece turned half round
/// drove the wrist into its limit, and the rotation error, near π, flipped sign tick by tick.)
pub fn grasp_heading(tool_down: &UnitQuaternion<f64>, current: &UnitQuaternion<f64>) -> f64 {
    let half = std::f64::consts::FRAC_PI_2;
    heading_from(tool_down, current).clamp(-half, half)
}

/// The turn about the vertical (rad, world z, in (−π, π]) from `tool_down` to `current`: the
/// twist about z of the rotation `current · tool_down⁻¹` (its swing-twist decomposition,
/// `2 atan2(q_z, q_w)`), whatever the tool's tilt; 0 where not finite.
fn heading_from(tool_down: &UnitQuaternion<f64>, current: &UnitQuaternion<f64>) -> f64 {
    let q = (current * tool_down.inverse()).into_inner();
    let pi = std::f64::consts::PI;
    let d = (2.0 * q.k.atan2(q.w) + pi).rem_euclid(2.0 * pi) - pi;
    if d.is_finite() { d } else { 0.0 }
}

/// The carried object's target kept upright and facing `heading` (rad, about the world
/// vertical): the twin's position, neither its tilt nor its turn, and none of its twist's
/// turning. A piece is carried and set down upright: a twin tilted a few degrees in the virtual
/// hand, followed by a top grasp, swings the wrist at rad/s and the piece by centimetres
/// (measured: 30-70 mm carry RMSE when the full orientation was followed, docs/chess.md). And
/// an upright round object is the same whichever way it faces, while following the twin's turn
/// in the hand wound the wrist: a scripted hand that sets a piece down from the other side
/// turns its twin half round, and the Sawyer's last joint ran into its limit (the piece set
/// down up to 75 cm off, 9 of 20 moves wrong; docs/chess.md).
pub fn upright(target: &OperatorTarget, heading: f64) -> OperatorTarget {
    let mut object_twist = target.object_twist;
    object_twist.fixed_rows_mut::<3>(3).fill(0.0);
    OperatorTarget {
        target: Isometry3::from_parts(
            target.target.translation,
            UnitQuaternion::from_euler_angles(0.0, 0.0, heading),
        ),
        object_twist,
        ..*target
    }
}

/// The robot's side of the pick-and-place task (module docs). No Bevy, time as an argument.
#[derive(Debug, Clone)]
pub struct PickPlaceRobot {
    settings: PickPlaceSettings,
    model: Arc<RobotModel>,
    base: Isometry3<f64>,
    tcp: LinkId,
    arm: Vec<usize>,
    objects: Vec<PickObject>,
    phase: PickPhase,
    mapper: Mapper,
    tcp_from_object: Isometry3<f64>,
    closed: bool,
    /// The twin's last target while carried (what a release places the object at).
    last_target: Option<OperatorTarget>,
    /// In Place: since when the object has been within `over_m` of its place (s).
    near_since_s: Option<f64>,
}

/// A gripper finger's thickness (m): [`PickPlaceSettings::tool_radius_m`] less this is the open
/// gripper's half-opening ([`PickPlaceRobot::descent_floor`]).
pub const FINGER_M: f64 = 0.005;

/// In Place, an object that has not come within [`PickPlaceSettings::over_m`] of its place this
/// many [`PickPlaceSettings::place_timeout_s`] after the hand let go is set down straight below
/// where it is; at twice this it is let go of wherever it is.
pub const PLACE_GIVE_UP: f64 = 5.0;

impl PickPlaceRobot {
    /// The robot side for `objects` (their believed real poses), gripper open, phase Free.
    /// Errors for bad settings or an arm joint out of range.
    pub fn new(
        settings: PickPlaceSettings,
        model: Arc<RobotModel>,
        base: Isometry3<f64>,
        tcp: LinkId,
        arm: Vec<usize>,
        objects: Vec<PickObject>,
    ) -> crate::Result<Self> {
        settings.validate()?;
        if let Some(i) = objects.iter().position(|o| {
            !(o.pose.translation.vector.iter().all(|v| v.is_finite())
                && o.pose.rotation.coords.iter().all(|v| v.is_finite())
                && o.radius_m.is_finite()
                && o.radius_m > 0.0
                && o.height_m.is_finite()
                && o.height_m > 0.0)
        }) {
            return Err(crate::Error::BadSetting {
                what: format!("pick_place.objects[{i}]"),
                message: "pose, radius and height must be finite, radius and height > 0".into(),
            });
        }
        if let Some(i) = objects
            .iter()
            .position(|o| o.top_z() + settings.over_m >= settings.clearance_z)
        {
            return Err(crate::Error::BadSetting {
                what: "pick_place.clearance_z".into(),
                message: format!(
                    "{} m is not above object {i}'s top ({} m) by more than over_m ({} m)",
                    settings.clearance_z,
                    objects[i].top_z(),
                    settings.over_m
                ),
            });
        }
        if let Some(&bad) = arm.iter().find(|&&i| i >= model.dof()) {
            return Err(crate::Error::BadSetting {
                what: "pick_place.arm".into(),
                message: format!("joint index {bad} out of range ({} joints)", model.dof()),
            });
        }
        Ok(Self {
            mapper: Mapper::new(settings.mapping),
            settings,
            model,
            base,
            tcp,
            arm,
            objects,
            phase: PickPhase::Free,
            tcp_from_object: Isometry3::identity(),
            closed: false,
            last_target: None,
            near_since_s: None,
        })
    }

    /// The phase.
    pub fn phase(&self) -> PickPhase {
        self.phase
    }

    /// Where the robot believes each object stands.
    pub fn objects(&self) -> &[PickObject] {
        &self.objects
    }

    /// The settings.
    pub fn settings(&self) -> &PickPlaceSettings {
        &self.settings
    }

    /// The tool's grasp pose on object `i` (world): a top grasp on its axis,
    /// [`PickPlaceSettings::grasp_depth_m`] below its top.
    pub fn grasp_pose(&self, i: usize) -> Option<Isometry3<f64>> {
        let o = self.objects.get(i)?;
        let p = o.pose.translation.vector;
        Some(Isometry3::from_parts(
            Translation3::new(p.x, p.y, o.top_z() - self.settings.grasp_depth_m),
            self.settings.tool_down,
        ))
    }

    /// The pose the tool goes to for `goal`, turned about the vertical to the top grasp's
    /// heading nearest the tool's ([`grasp_heading`]).
    fn goal_pose(&self, goal: PickGoal, tool: &Isometry3<f64>) -> Option<Isometry3<f64>> {
        let g = match goal {
            PickGoal::Hover(i) => self
                .grasp_pose(i)
                .map(|g| Translation3::new(0.0, 0.0, self.settings.hover_m) * g),
            PickGoal::Around(i) | PickGoal::Grasp(i) => self.grasp_pose(i),
        }?;
        let turn = UnitQuaternion::from_axis_angle(
            &Vector3::z_axis(),
            grasp_heading(&self.settings.tool_down, &tool.rotation),
        );
        Some(Isometry3::from_parts(g.translation, turn * g.rotation))
    }

    /// The height (world z, m) the tool point crosses at from `from` to `to` (world; their
    /// horizontal way): [`PickPlaceSettings::clear_m`] above the top of every object whose side
    /// comes within [`PickPlaceSettings::over_m`] and [`PickPlaceSettings::tool_radius_m`] of
    /// the way, the object the tool goes to included; not below `to`; at most
    /// [`PickPlaceSettings::clearance_z`]. The way ends `over_m` short of `to`: from there the
    /// tool goes down onto it ([`clearance_twist`]), so `to`'s neighbours are not crossed, and
    /// an object at `to` is come down onto from above its top.
    pub fn crossing_z(&self, from: &Vector3<f64>, to: &Vector3<f64>) -> f64 {
        let s = &self.settings;
        let a = from.xy();
        let ab = to.xy() - a;
        let len = ab.norm();
        let ab = if len > s.over_m {
            ab * ((len - s.over_m) / len)
        } else {
            ab * 0.0
        };
        let len2 = ab.norm_squared();
        let beside = |o: &PickObject| {
            let c = o.pose.translation.vector.xy();
            let t = if len2 > 0.0 {
                ((c - a).dot(&ab) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (a + ab * t - c).norm() <= o.radius_m + s.over_m + s.tool_radius_m
        };
        self.objects
            .iter()
            .filter(|o| beside(o))
            .map(|o| o.top_z() + s.clear_m)
            .fold(to.z, f64::max)
            .min(s.clearance_z)
    }

    /// The lowest the tool point may go at `at` (world) in its last
    /// [`PickPlaceSettings::over_m`] across onto its goal (world z, m; `-inf` where nothing is
    /// below it): [`PickPlaceSettings::over_m`] / 2 above the top of every object whose side
    /// lies within [`PickPlaceSettings::tool_radius_m`] of `at` (the open gripper over it);
    /// the object `goal` left out once the tool is within the gripper's half-opening
    /// (`tool_radius_m` less [`FINGER_M`]) less its radius of its axis, at least
    /// `arrive_m`: the fingers then pass either side of it.
    pub fn descent_floor(&self, at: &Vector3<f64>, goal: Option<usize>) -> f64 {
        let s = &self.settings;
        self.objects
            .iter()
            .enumerate()
            .filter(|&(i, o)| {
                let off = (o.pose.translation.vector.xy() - at.xy()).norm();
                let straddled = Some(i) == goal
                    && off <= (s.tool_radius_m - FINGER_M - o.radius_m).max(s.arrive_m);
                off <= o.radius_m + s.tool_radius_m && !straddled
            })
            .map(|(_, o)| o.top_z() + s.over_m / 2.0)
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The twist of a move between grasps from `tool` to `goal` (world), the object `piece`
    /// the tool goes to if any: [`clearance_twist`] at [`PickPlaceRobot::crossing_z`] and
    /// above [`PickPlaceRobot::descent_floor`]. Returns it and whether the tool has arrived.
    fn move_between_grasps(
        &self,
        tool: &Isometry3<f64>,
        goal: &Isometry3<f64>,
        piece: Option<usize>,
    ) -> (Vector6<f64>, bool) {
        let p = tool.translation.vector;
        let cross_z = self.crossing_z(&p, &goal.translation.vector);
        let floor_z = self.descent_floor(&p, piece);
        clearance_twist(tool, goal, cross_z, floor_z, &self.settings)
    }

    /// One tick at `now_s` with the measured joints `q` (all joints, stamped `joints_stamp_s`)
    /// and the newest operator command (`None`: none yet). Errors name the bad input; the
    /// caller stops the robot on an error.
    pub fn tick(
        &mut self,
        command: Option<&PickPlaceCommand>,
        q: &[f64],
        now_s: f64,
        joints_stamp_s: f64,
    ) -> crate::Result<PickTick> {
        let n = self.model.dof();
        if q.len() != n || q.iter().any(|v| !v.is_finite()) {
            return Err(crate::Error::BadTickInput {
                message: format!("joint state: {n} finite values needed"),
            });
        }
        if let Some(c) = command {
            let bad = [c.object, c.intent]
                .into_iter()
                .flatten()
                .find(|&i| i >= self.objects.len());
            if let Some(i) = bad {
                return Err(crate::Error::BadTickInput {
                    message: format!("object {i} of {}", self.objects.len()),
                });
            }
            if let Some(t) = &c.target {
                t.validate()?;
            }
        }
        let poses = self.model.forward_kinematics(&self.base, q);
        let tool = poses[self.tcp];
        let jacobian =
            self.model
                .jacobian_from_poses(&poses, self.tcp, &Vector3::zeros(), Frame::World);
        let held = command.and_then(|c| match (c.object, c.target) {
            (Some(i), Some(t)) if t.held => Some((i, t)),
            _ => None,
        });
        let mut out = PickTick {
            qdot: DVector::zeros(n),
            gripper: GripperCommand {
                closed: self.closed,
                force_n: if self.closed {
                    self.settings.mapping.max_grip_n
                } else {
                    0.0
                },
            },
            phase: self.phase,
            goal: None,
            tcp_jacobian: jacobian.clone(),
            tool,
            target: None,
            grasped: None,
            released: None,
        };
        match self.phase {
            PickPhase::Free | PickPhase::Retreat => {
                if let Some((i, _)) = held {
                    self.phase = PickPhase::Reach { object: i };
                    return self.tick(command, q, now_s, joints_stamp_s);
                }
                if self.phase == PickPhase::Retreat {
                    let p = tool.translation.vector;
                    let z = self.crossing_z(&p, &p);
                    let up = Isometry3::from_parts(Translation3::new(p.x, p.y, z), tool.rotation);
                    let (twist, arrived) = self.move_between_grasps(&tool, &up, None);
                    if arrived || p.z >= z {
                        self.phase = PickPhase::Free;
                    } else {
                        out.qdot = self.joint_velocity(&jacobian, &twist, q)?;
                    }
                } else if let Some(c) = command
                    && let Some(i) = c.intent
                {
                    let goal = if c.intent_near {
                        PickGoal::Around(i)
                    } else {
                        PickGoal::Hover(i)
                    };
                    out.goal = Some(goal);
                    if let Some(g) = self.goal_pose(goal, &tool) {
                        let (twist, arrived) = self.move_between_grasps(&tool, &g, Some(i));
                        if !arrived {
                            out.qdot = self.joint_velocity(&jacobian, &twist, q)?;
                        }
                    }
                }
            }
            PickPhase::Reach { object } => {
                if held.is_none_or(|(i, _)| i != object) {
                    // Let go (or another object) before the robot got there: start over.
                    self.phase = PickPhase::Retreat;
                    return self.tick(command, q, now_s, joints_stamp_s);
                }
                out.goal = Some(PickGoal::Grasp(object));
                if let Some(g) = self.goal_pose(PickGoal::Grasp(object), &tool) {
                    let (twist, arrived) = self.move_between_grasps(&tool, &g, Some(object));
                    if arrived {
                        self.closed = true;
                        self.tcp_from_object = tool.inverse() * self.objects[object].pose;
                        self.mapper = Mapper::new(self.settings.mapping);
                        self.phase = PickPhase::Carry { object };
                        out.grasped = Some(object);
                        out.gripper = GripperCommand {
                            closed: true,
                            force_n: self.settings.mapping.max_grip_n,
                        };
                    } else {
                        out.qdot = self.joint_velocity(&jacobian, &twist, q)?;
                    }
                }
            }
            PickPhase::Carry { object } => {
                let target = match held {
                    Some((i, t)) if i == object => t,
                    _ => {
                        self.phase = PickPhase::Place {
                            object,
                            since_s: now_s,
                        };
                        self.near_since_s = None;
                        return self.tick(command, q, now_s, joints_stamp_s);
                    }
                };
                self.last_target = Some(target);
                out.target = Some(target.target);
                out.qdot = self.carry(object, &target, &tool, q, (now_s, joints_stamp_s))?;
            }
            PickPhase::Place { object, since_s } => {
                self.place(object, since_s, &tool, q, (now_s, joints_stamp_s), &mut out)?;
            }
        }
        out.phase = self.phase;
        Ok(out)
    }

    /// The Place phase's tick: the real object held at the twin's last pose (upright, still)
    /// until it is there, or the time for the last millimetres is up, then let go; one that
    /// cannot get there is set down below where it is ([`PLACE_GIVE_UP`]). `since_s` is when
    /// the hand let go, `times` the tick's time and the joints' stamp (s).
    fn place(
        &mut self,
        object: usize,
        since_s: f64,
        tool: &Isometry3<f64>,
        q: &[f64],
        times: (f64, f64),
        out: &mut PickTick,
    ) -> crate::Result<()> {
        let (now_s, joints_stamp_s) = times;
        let Some(mut last) = self.last_target else {
            self.release(object, tool, out);
            return Ok(());
        };
        let measured = tool * self.tcp_from_object;
        let s = self.settings;
        let give_up_s = PLACE_GIVE_UP * s.place_timeout_s;
        let distance = |target: &Isometry3<f64>| {
            (target.translation.vector - measured.translation.vector).norm()
        };
        if now_s - since_s >= give_up_s && distance(&last.target) > s.over_m {
            // It cannot get there: down where it is, onto its rest height.
            let p = measured.translation.vector;
            let rest_z = self.objects[object].pose.translation.z;
            last.target.translation = Translation3::new(p.x, p.y, rest_z);
            self.last_target = Some(last);
        }
        let target = self.carried_upright(
            &OperatorTarget {
                held: true,
                object_twist: Vector6::zeros(),
                twin_twist: Vector6::zeros(),
                stamp_s: joints_stamp_s,
                ..last
            },
            object,
        );
        out.target = Some(target.target);
        let error = pose_difference(&measured, &target.target);
        let placed = error.fixed_rows::<3>(0).norm() <= s.place_m
            && error.fixed_rows::<3>(3).norm() <= s.place_rad;
        if error.fixed_rows::<3>(0).norm() > s.over_m {
            // Still travelling: the time for the last millimetres starts once there.
            self.near_since_s = None;
        } else if self.near_since_s.is_none() {
            self.near_since_s = Some(now_s);
        }
        let last_mm_over = self
            .near_since_s
            .is_some_and(|t| now_s - t >= s.place_timeout_s);
        if placed || last_mm_over || now_s - since_s >= 2.0 * give_up_s {
            self.release(object, tool, out);
        } else {
            out.qdot = self.carry(object, &target, tool, q, times)?;
        }
        Ok(())
    }

    /// The carry's joint velocities toward `target` (kept upright, and over the other objects:
    /// [`PickPlaceRobot::over_the_others`]) by the mapping's robot side. `times` is the tick's
    /// time and the joints' stamp (s).
    fn carry(
        &mut self,
        object: usize,
        target: &OperatorTarget,
        tool: &Isometry3<f64>,
        q: &[f64],
        times: (f64, f64),
    ) -> crate::Result<DVector<f64>> {
        let (now_s, joints_stamp_s) = times;
        let target = &self.over_the_others(object, &self.carried_upright(target, object), tool);
        let side = RobotSide {
            model: &self.model,
            base: self.base,
            tcp: self.tcp,
            arm: &self.arm,
            tcp_from_object: self.tcp_from_object,
        };
        let out = self.mapper.robot_side(
            target,
            &RobotInputs {
                q,
                now_s,
                joints_stamp_s,
            },
            &side,
        )?;
        Ok(out.qdot)
    }

    /// The carried object's target kept upright ([`upright`]), facing as the object did when
    /// it was grasped (its believed pose's heading): the tool keeps the heading it grasped with.
    fn carried_upright(&self, target: &OperatorTarget, object: usize) -> OperatorTarget {
        let (_, _, heading) = self.objects[object].pose.rotation.euler_angles();
        upright(target, heading)
    }

    /// The carried object's target shaped by the clearance rule the tool follows between
    /// grasps ([`clearance_twist`]): lifted straight up, across above the other objects, down
    /// onto the goal. Below `clearance_z − over_m` (the object's bottom; every object's top is
    /// lower) the object moves sideways only toward a target within
    /// [`PickPlaceSettings::over_m`] across and not above it (setting down, or nudging it on
    /// its square); a target farther across, or above, is reached straight up first. Above that
    /// height it crosses toward its bottom at `clearance_z` (rising on the way, never below
    /// `clearance_z − over_m`), and follows the target down within `over_m` across. The real object lags its twin under the speed cap, and without
    /// this it cut the corner between the lift and the traverse through the neighbouring pieces
    /// (docs/chess.md). A shaped target's linear feed-forward is dropped (it is the twin's,
    /// along another path).
    fn over_the_others(
        &self,
        object: usize,
        target: &OperatorTarget,
        tool: &Isometry3<f64>,
    ) -> OperatorTarget {
        let s = &self.settings;
        let half = self.objects.get(object).map_or(0.0, |o| o.height_m / 2.0);
        let p = (tool * self.tcp_from_object).translation.vector;
        let t = target.target.translation.vector;
        let across = Vector3::new(t.x - p.x, t.y - p.y, 0.0).norm();
        let cross_z = s.clearance_z + half;
        let low = p.z - half < s.clearance_z - s.over_m;
        let shaped = if low && (across > s.over_m || t.z > p.z + s.arrive_m) {
            // Straight up first.
            Vector3::new(
                p.x,
                p.y,
                if across > s.over_m {
                    t.z.max(cross_z)
                } else {
                    t.z
                },
            )
        } else if !low && across > s.over_m && t.z < cross_z {
            // Across above the others.
            Vector3::new(t.x, t.y, cross_z)
        } else {
            return *target;
        };
        let mut object_twist = target.object_twist;
        object_twist.fixed_rows_mut::<3>(0).fill(0.0);
        OperatorTarget {
            target: Isometry3::from_parts(Translation3::from(shaped), target.target.rotation),
            object_twist,
            ..*target
        }
    }

    fn release(&mut self, object: usize, tool: &Isometry3<f64>, out: &mut PickTick) {
        self.closed = false;
        let held = tool * self.tcp_from_object;
        let o = &mut self.objects[object];
        // It stands where the tool left it, upright, at its rest height.
        let (_, _, yaw) = held.rotation.euler_angles();
        o.pose = Isometry3::from_parts(
            Translation3::new(held.translation.x, held.translation.y, o.pose.translation.z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        );
        self.last_target = None;
        self.near_since_s = None;
        self.phase = PickPhase::Retreat;
        out.released = Some(object);
        out.phase = self.phase;
        out.gripper = GripperCommand {
            closed: false,
            force_n: 0.0,
        };
    }

    fn joint_velocity(
        &self,
        jacobian: &Matrix6xX<f64>,
        twist: &Vector6<f64>,
        q: &[f64],
    ) -> crate::Result<DVector<f64>> {
        let j = Matrix6xX::from_fn(self.arm.len(), |r, c| jacobian[(r, self.arm[c])]);
        let q_arm: Vec<f64> = self.arm.iter().map(|&i| q[i]).collect();
        let limits = self.model.dof_limits();
        let lim_arm: Vec<_> = self.arm.iter().map(|&i| limits[i]).collect();
        let step = dls_step(&j, twist, &q_arm, &lim_arm, &self.settings.mapping.dls);
        if step.rejected {
            return Err(crate::Error::BadTickInput {
                message: "the arm Jacobian or the twist is not finite".into(),
            });
        }
        let mut qdot = DVector::zeros(q.len());
        for (k, &i) in self.arm.iter().enumerate() {
            qdot[i] = step.qdot[k];
        }
        Ok(qdot)
    }
}

#[cfg(test)]
mod tests;
