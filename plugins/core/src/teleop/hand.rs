//! Hand skeletons in OpenXR's 26-joint convention (`XR_EXT_hand_tracking`): every hand source
//! (replay file, scripted keyframes, Leap Motion, OpenXR) produces [`HandFrame`]s.
//!
//! File format (`.hand.jsonl`, JSON Lines, one frame per line, documented in `docs/hand.md`):
//!
//! ```text
//! {"t_s": 0.0, "hand": "right", "tracked": true,
//!  "joints": [[px, py, pz, qx, qy, qz, qw, radius], ... 26 rows in JOINT_NAMES order]}
//! ```
//!
//! Positions in metres and orientations as unit quaternions, world frame (the scene's frame,
//! z up); `radius` in metres. A frame with `"tracked": false` may leave `joints` empty.
//!
//! Scripted hands ([`HandScript`]) move the wrist through keyframes with minimum-jerk
//! interpolation, close the fingers by a grip value in [0, 1], and add seeded physiological
//! tremor and tracking noise, so tests need no recording.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::rng::Rng;

/// The 26 joints, in OpenXR's `XrHandJointEXT` order.
pub const JOINT_NAMES: [&str; 26] = [
    "palm",
    "wrist",
    "thumb_metacarpal",
    "thumb_proximal",
    "thumb_distal",
    "thumb_tip",
    "index_metacarpal",
    "index_proximal",
    "index_intermediate",
    "index_distal",
    "index_tip",
    "middle_metacarpal",
    "middle_proximal",
    "middle_intermediate",
    "middle_distal",
    "middle_tip",
    "ring_metacarpal",
    "ring_proximal",
    "ring_intermediate",
    "ring_distal",
    "ring_tip",
    "little_metacarpal",
    "little_proximal",
    "little_intermediate",
    "little_distal",
    "little_tip",
];

/// Index of the palm joint.
pub const PALM: usize = 0;

/// The skeleton's bones as joint pairs (wrist to each metacarpal, then along each digit): what
/// a drawing of the hand connects.
pub const SKELETON: [(usize, usize); 24] = [
    (1, 2),
    (2, 3),
    (3, 4),
    (4, 5),
    (1, 6),
    (6, 7),
    (7, 8),
    (8, 9),
    (9, 10),
    (1, 11),
    (11, 12),
    (12, 13),
    (13, 14),
    (14, 15),
    (1, 16),
    (16, 17),
    (17, 18),
    (18, 19),
    (19, 20),
    (1, 21),
    (21, 22),
    (22, 23),
    (23, 24),
    (24, 25),
];
/// Index of the wrist joint.
pub const WRIST: usize = 1;
/// Indices of the five fingertips (thumb first).
pub const TIPS: [usize; 5] = [5, 10, 15, 20, 25];

/// Left or right.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Handedness {
    /// Left hand.
    Left,
    /// Right hand.
    Right,
}

/// One joint: pose (world frame) and radius (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandJoint {
    /// Pose, world frame. Avatarm's joint frame: +x along the bone toward the tip, +z out of
    /// the back of the hand (OpenXR's is −z along the bone, +y out of the back; the OpenXR and
    /// Leap sources convert).
    pub pose: Isometry3<f64>,
    /// Radius of the bone's capsule at this joint (m).
    pub radius: f64,
}

/// One hand at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct HandFrame {
    /// Capture time (s, app clock).
    pub t_s: f64,
    /// Which hand.
    pub hand: Handedness,
    /// Tracked; an untracked frame carries no joints.
    pub tracked: bool,
    /// 26 joints when tracked, in [`JOINT_NAMES`] order.
    pub joints: Vec<HandJoint>,
}

impl HandFrame {
    /// Checks the frame; errors ([`Error::BadHandFrame`]) name the joint.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |joint, message| Error::BadHandFrame {
            line: None,
            joint,
            message,
        };
        if !self.t_s.is_finite() {
            return Err(bad(None, format!("t_s = {} is not finite", self.t_s)));
        }
        if !self.tracked {
            return Ok(());
        }
        if self.joints.len() != JOINT_NAMES.len() {
            return Err(bad(
                None,
                format!(
                    "a tracked hand needs {} joints, got {}",
                    JOINT_NAMES.len(),
                    self.joints.len()
                ),
            ));
        }
        for (j, name) in self.joints.iter().zip(JOINT_NAMES) {
            let p = j.pose.translation.vector;
            let q = j.pose.rotation.coords;
            if !(p.iter().chain(q.iter()).all(|v| v.is_finite())
                && j.radius.is_finite()
                && j.radius > 0.0)
            {
                return Err(bad(
                    Some(name),
                    "pose or radius is not finite and positive".into(),
                ));
            }
        }
        Ok(())
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameLine {
    t_s: f64,
    hand: Handedness,
    tracked: bool,
    #[serde(default)]
    joints: Vec<[f64; 8]>,
}

/// Parses a `.hand.jsonl` text; errors name the line (1-based), the joint where one is at
/// fault, and what is wrong: [`Error::HandRecordLine`] for a line that is not a frame record,
/// [`Error::BadHandFrame`] for a frame that cannot be used (a joint orientation of zero length,
/// a non-finite value, time not moving forward).
pub fn parse_frames(text: &str) -> crate::Result<Vec<HandFrame>> {
    let mut out: Vec<HandFrame> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        if line.trim().is_empty() || line.trim_start().starts_with('#') {
            continue;
        }
        let l: FrameLine = serde_json::from_str(line)
            .map_err(|source| Error::HandRecordLine { line: n, source })?;
        let bad = |joint, message| Error::BadHandFrame {
            line: Some(n),
            joint,
            message,
        };
        let mut joints = Vec::with_capacity(l.joints.len());
        for (k, r) in l.joints.iter().enumerate() {
            let q = Quaternion::new(r[6], r[3], r[4], r[5]);
            // A zero quaternion has no direction: normalising it gives NaN.
            let rotation = UnitQuaternion::try_new(q, 1e-9).ok_or_else(|| {
                bad(
                    JOINT_NAMES.get(k).copied(),
                    format!(
                        "zero-length orientation [{}, {}, {}, {}] (x, y, z, w)",
                        r[3], r[4], r[5], r[6]
                    ),
                )
            })?;
            joints.push(HandJoint {
                pose: Isometry3::from_parts(Translation3::new(r[0], r[1], r[2]), rotation),
                radius: r[7],
            });
        }
        let frame = HandFrame {
            t_s: l.t_s,
            hand: l.hand,
            tracked: l.tracked,
            joints,
        };
        frame.validate().map_err(|e| match e {
            Error::BadHandFrame { joint, message, .. } => bad(joint, message),
            other => other,
        })?;
        if let Some(prev) = out.iter().rev().find(|f| f.hand == frame.hand)
            && frame.t_s <= prev.t_s
        {
            return Err(bad(
                None,
                format!(
                    "t_s {} is not after the previous frame's {}",
                    frame.t_s, prev.t_s
                ),
            ));
        }
        out.push(frame);
    }
    Ok(out)
}

/// Writes frames as `.hand.jsonl` text.
pub fn write_frames(frames: &[HandFrame]) -> String {
    let mut text = String::new();
    for f in frames {
        let line = FrameLine {
            t_s: f.t_s,
            hand: f.hand,
            tracked: f.tracked,
            joints: f
                .joints
                .iter()
                .map(|j| {
                    let p = j.pose.translation.vector;
                    let q = j.pose.rotation.coords;
                    [p.x, p.y, p.z, q.x, q.y, q.z, q.w, j.radius]
                })
                .collect(),
        };
        if let Ok(s) = serde_json::to_string(&line) {
            text.push_str(&s);
            text.push('\n');
        }
    }
    text
}

/// A keyframe of a scripted hand.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandKeyframe {
    /// Time (s).
    pub t_s: f64,
    /// Wrist position (m, world frame).
    pub xyz: [f64; 3],
    /// Wrist orientation, roll-pitch-yaw (rad).
    #[serde(default)]
    pub rpy: [f64; 3],
    /// Finger closure: 0 open, 1 fist.
    #[serde(default)]
    pub grip: f64,
    /// Tracked from this keyframe to the next.
    #[serde(default = "yes")]
    pub tracked: bool,
}

fn yes() -> bool {
    true
}

/// Noise added to a scripted hand.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HandNoise {
    /// Physiological tremor amplitude (m), 8–12 Hz, on the whole hand.
    pub tremor_m: f64,
    /// Tracking noise per joint, standard deviation (m).
    pub tracking_sigma_m: f64,
    /// Seed of both.
    pub seed: u64,
}

impl Default for HandNoise {
    fn default() -> Self {
        Self {
            tremor_m: 0.0005,
            tracking_sigma_m: 0.001,
            seed: 1,
        }
    }
}

/// A hand moved through keyframes.
#[derive(Debug, Clone, PartialEq)]
pub struct HandScript {
    /// Which hand.
    pub hand: Handedness,
    /// Keyframes, strictly increasing in time.
    pub keys: Vec<HandKeyframe>,
    /// Noise.
    pub noise: HandNoise,
    tremor: [(f64, f64, Vector3<f64>); 2],
}

/// Points rigidly attached to an object at `from` (e.g. the hand holding the object's twin),
/// carried with it to `to` (the real object): `to · from⁻¹ · p` for each point (m, world).
/// Alice's view draws the operator's hand this way while she holds the object, so the hand
/// holds the bottle Alice sees even when the robot lags the twin.
pub fn carried_with(
    points: &[nalgebra::Vector3<f64>],
    from: &nalgebra::Isometry3<f64>,
    to: &nalgebra::Isometry3<f64>,
) -> Vec<nalgebra::Vector3<f64>> {
    let moved = to * from.inverse();
    points
        .iter()
        .map(|p| (moved * nalgebra::Point3::from(*p)).coords)
        .collect()
}

/// The minimum-jerk profile `10τ³ − 15τ⁴ + 6τ⁵` on [0, 1].
pub fn min_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

impl HandScript {
    /// A script; errors name the keyframe.
    pub fn new(hand: Handedness, keys: Vec<HandKeyframe>, noise: HandNoise) -> crate::Result<Self> {
        let bad = |what: String, message: String| Error::BadSetting { what, message };
        if keys.is_empty() {
            return Err(bad(
                "scripted hand".into(),
                "needs at least one keyframe".into(),
            ));
        }
        for (i, k) in keys.iter().enumerate() {
            if !(k.t_s.is_finite()
                && k.xyz.iter().chain(&k.rpy).all(|v| v.is_finite())
                && (0.0..=1.0).contains(&k.grip))
            {
                return Err(bad(
                    format!("hand keyframe {i}"),
                    "t_s, xyz, rpy must be finite and grip in [0, 1]".into(),
                ));
            }
            if i > 0 && k.t_s <= keys[i - 1].t_s {
                return Err(bad(
                    format!("hand keyframe {i}"),
                    format!("t_s {} is not after {}", k.t_s, keys[i - 1].t_s),
                ));
            }
        }
        if !(noise.tremor_m.is_finite()
            && noise.tremor_m >= 0.0
            && noise.tracking_sigma_m.is_finite()
            && noise.tracking_sigma_m >= 0.0)
        {
            return Err(bad(
                "hand noise".into(),
                "tremor_m and tracking_sigma_m must be >= 0".into(),
            ));
        }
        let mut rng = Rng::stream(noise.seed, 0x4841_4e44);
        let mut tremor = || {
            let f = 8.0 + 4.0 * rng.uniform();
            let phase = std::f64::consts::TAU * rng.uniform();
            let dir = Vector3::new(rng.gaussian(), rng.gaussian(), rng.gaussian())
                .try_normalize(1e-9)
                .unwrap_or_else(Vector3::x);
            (f, phase, dir)
        };
        let tremor = [tremor(), tremor()];
        Ok(Self {
            hand,
            keys,
            noise,
            tremor,
        })
    }

    /// The wrist pose, grip and tracking at `t` without noise: minimum-jerk between the
    /// keyframes around `t` (held before the first and after the last).
    pub fn wrist_at(&self, t: f64) -> (Isometry3<f64>, f64, bool) {
        let pose = |k: &HandKeyframe| {
            Isometry3::from_parts(
                Translation3::new(k.xyz[0], k.xyz[1], k.xyz[2]),
                UnitQuaternion::from_euler_angles(k.rpy[0], k.rpy[1], k.rpy[2]),
            )
        };
        let i = self.keys.partition_point(|k| k.t_s <= t);
        if i == 0 {
            let k = &self.keys[0];
            return (pose(k), k.grip, k.tracked);
        }
        if i == self.keys.len() {
            let k = &self.keys[i - 1];
            return (pose(k), k.grip, k.tracked);
        }
        let (a, b) = (&self.keys[i - 1], &self.keys[i]);
        let s = min_jerk((t - a.t_s) / (b.t_s - a.t_s));
        let (pa, pb) = (pose(a), pose(b));
        let trans = pa.translation.vector.lerp(&pb.translation.vector, s);
        let rot = pa.rotation.slerp(&pb.rotation, s);
        (
            Isometry3::from_parts(Translation3::from(trans), rot),
            a.grip + (b.grip - a.grip) * s,
            a.tracked,
        )
    }

    /// The hand at `t`, noise included (deterministic for a seed and `t`).
    pub fn frame_at(&self, t: f64) -> HandFrame {
        let (wrist, grip, tracked) = self.wrist_at(t);
        if !tracked {
            return HandFrame {
                t_s: t,
                hand: self.hand,
                tracked: false,
                joints: Vec::new(),
            };
        }
        let tremor: Vector3<f64> = self
            .tremor
            .iter()
            .map(|(f, phase, dir)| dir * (std::f64::consts::TAU * f * t + phase).sin())
            .sum::<Vector3<f64>>()
            * (self.noise.tremor_m / 2.0);
        let wrist = Isometry3::from_parts(
            Translation3::from(wrist.translation.vector + tremor),
            wrist.rotation,
        );
        let mut joints = skeleton(&wrist, grip, self.hand);
        if self.noise.tracking_sigma_m > 0.0 {
            // Per-frame noise, seeded by time so the same t gives the same frame.
            let mut rng = Rng::stream(self.noise.seed, (t * 1e6).round() as i64 as u64);
            for j in &mut joints {
                let n = Vector3::new(rng.gaussian(), rng.gaussian(), rng.gaussian())
                    * self.noise.tracking_sigma_m;
                j.pose.translation.vector += n;
            }
        }
        HandFrame {
            t_s: t,
            hand: self.hand,
            tracked: true,
            joints,
        }
    }
}

/// Settings of [`HandFilter`], the One Euro filter (Casiez, Roussel and Vogel, CHI 2012) on
/// the tracked joint positions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HandFilterSettings {
    /// Filter the joints (false: frames pass as tracked).
    pub enabled: bool,
    /// Cutoff frequency of a joint at rest (Hz): lower removes more jitter from a still hand.
    pub min_cutoff_hz: f64,
    /// How fast the cutoff rises with the joint's speed (Hz per m/s): higher lags less behind
    /// a moving hand.
    pub beta: f64,
    /// Cutoff of the speed estimate that steers the cutoff (Hz).
    pub speed_cutoff_hz: f64,
}

impl Default for HandFilterSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            min_cutoff_hz: 1.5,
            beta: 10.0,
            speed_cutoff_hz: 1.0,
        }
    }
}

impl HandFilterSettings {
    /// Checks the settings; errors name the field.
    pub fn validate(&self) -> crate::Result<()> {
        for (name, v) in [
            ("min_cutoff_hz", self.min_cutoff_hz),
            ("speed_cutoff_hz", self.speed_cutoff_hz),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::BadSetting {
                    what: format!("hand filter: {name}"),
                    message: format!("{v} must be > 0"),
                });
            }
        }
        if !(self.beta.is_finite() && self.beta >= 0.0) {
            return Err(Error::BadSetting {
                what: "hand filter: beta".into(),
                message: format!("{} must be >= 0", self.beta),
            });
        }
        Ok(())
    }
}

/// Adaptive low-pass filter of a hand's joint positions: heavy on a still hand, where a
/// tracker's millimetre of jitter would shake a held object, light on a moving one, where a
/// fixed filter would lag. Joint orientations pass through (the sources derive them from the
/// positions or report them smooth). A repeated frame (same time) gives the same output; an
/// untracked frame, a different joint count or a clock that goes back starts it afresh.
#[derive(Debug, Clone)]
pub struct HandFilter {
    settings: HandFilterSettings,
    /// Time of the last frame, and per joint the filtered position and speed.
    state: Option<(f64, Vec<JointEstimate>)>,
}

/// A joint's filtered position and speed.
type JointEstimate = (Vector3<f64>, Vector3<f64>);

impl HandFilter {
    /// A filter with `settings`.
    pub fn new(settings: HandFilterSettings) -> Self {
        Self {
            settings,
            state: None,
        }
    }

    /// Filters `frame` in place (nothing when the settings say disabled).
    pub fn apply(&mut self, frame: &mut HandFrame) {
        if !self.settings.enabled {
            return;
        }
        let restart = match &self.state {
            Some((t, joints)) => {
                !frame.tracked || joints.len() != frame.joints.len() || frame.t_s < *t
            }
            None => true,
        };
        if let Some((t, joints)) = &self.state
            && !restart
            && frame.t_s == *t
        {
            // The same frame again (a source that repeats its newest one): the same output.
            for (j, (x, _)) in frame.joints.iter_mut().zip(joints) {
                j.pose.translation.vector = *x;
            }
            return;
        }
        if restart {
            self.state = frame.tracked.then(|| {
                let joints = frame
                    .joints
                    .iter()
                    .map(|j| (j.pose.translation.vector, Vector3::zeros()))
                    .collect();
                (frame.t_s, joints)
            });
            return;
        }
        let Some((t, joints)) = self.state.as_mut() else {
            return;
        };
        let dt = frame.t_s - *t;
        *t = frame.t_s;
        // Smoothing factor of a first-order low-pass with cutoff `hz` over `dt`.
        let alpha = |hz: f64| {
            let tau = 1.0 / (std::f64::consts::TAU * hz);
            dt / (dt + tau)
        };
        let a_speed = alpha(self.settings.speed_cutoff_hz);
        for (j, (x, v)) in frame.joints.iter_mut().zip(joints.iter_mut()) {
            let raw = j.pose.translation.vector;
            *v += ((raw - *x) / dt - *v) * a_speed;
            let a = alpha(self.settings.min_cutoff_hz + self.settings.beta * v.norm());
            *x += (raw - *x) * a;
            j.pose.translation.vector = *x;
        }
    }
}

/// Bone lengths (m) of metacarpal, proximal, intermediate, distal for each finger (thumb has no
/// intermediate: its metacarpal, proximal, distal), an adult hand.
const BONES: [[f64; 4]; 5] = [
    [0.045, 0.035, 0.0, 0.030],
    [0.065, 0.040, 0.025, 0.020],
    [0.062, 0.045, 0.028, 0.021],
    [0.058, 0.042, 0.026, 0.020],
    [0.052, 0.033, 0.019, 0.018],
];

/// Knuckle offsets across the palm (m) along the hand's y axis (thumb side positive for a right
/// hand).
const SPREAD: [f64; 5] = [0.025, 0.022, 0.0, -0.020, -0.038];

/// The 26 joints of a hand whose wrist frame is `wrist` (x toward the fingers, y toward the
/// thumb for a right hand, z out of the back of the hand), fingers flexed by `grip` (0 open,
/// 1 closed).
pub fn skeleton(wrist: &Isometry3<f64>, grip: f64, hand: Handedness) -> Vec<HandJoint> {
    let side = match hand {
        Handedness::Right => 1.0,
        Handedness::Left => -1.0,
    };
    let g = grip.clamp(0.0, 1.0);
    let mut joints = vec![
        HandJoint {
            pose: *wrist,
            radius: 0.02,
        };
        26
    ];
    // Palm: halfway along the middle metacarpal.
    joints[PALM] = HandJoint {
        pose: wrist * Translation3::new(0.035, 0.0, 0.0),
        radius: 0.025,
    };
    joints[WRIST] = HandJoint {
        pose: *wrist,
        radius: 0.022,
    };
    for (f, bones) in BONES.iter().enumerate() {
        let first = if f == 0 { 2 } else { 6 + 5 * (f - 1) };
        let count = if f == 0 { 4 } else { 5 };
        // Thumb: angled toward the palm side, opposing as the grip closes.
        let (mut frame, flex_axis) = if f == 0 {
            let base = wrist
                * Translation3::new(0.02, side * 0.02, -0.01)
                * UnitQuaternion::from_euler_angles(0.0, 0.0, side * (0.7 - 0.4 * g));
            (base, Vector3::z() * -side)
        } else {
            (
                wrist * Translation3::new(0.0, side * SPREAD[f], 0.0),
                Vector3::y(),
            )
        };
        let lengths: Vec<f64> = bones.iter().copied().filter(|&l| l > 0.0).collect();
        let flex = [0.1, 1.2, 1.4, 0.9];
        for k in 0..count {
            let radius = (0.011 - 0.0012 * k as f64) * if f == 0 { 1.1 } else { 1.0 };
            joints[first + k] = HandJoint {
                pose: frame,
                radius,
            };
            if k < lengths.len() {
                let angle = if k == 0 { 0.0 } else { g * flex[k.min(3)] };
                let axis = nalgebra::Unit::new_normalize(flex_axis);
                frame = frame
                    * UnitQuaternion::from_axis_angle(&axis, angle)
                    * Translation3::new(lengths[k], 0.0, 0.0);
            }
        }
    }
    joints
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_carried_hand_keeps_its_grip_on_the_moved_object() {
        use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
        let twin = Isometry3::from_parts(
            Translation3::new(0.6, -0.1, 0.9),
            UnitQuaternion::from_euler_angles(0.0, 0.2, 0.5),
        );
        let real = Isometry3::from_parts(
            Translation3::new(0.58, -0.12, 0.88),
            UnitQuaternion::from_euler_angles(0.05, 0.15, 0.45),
        );
        let hand = vec![
            Vector3::new(0.62, -0.05, 0.95),
            Vector3::new(0.55, -0.1, 0.9),
        ];
        let carried = carried_with(&hand, &twin, &real);
        for (p, q) in hand.iter().zip(&carried) {
            // Where the point sits on the twin is where it sits on the real object.
            let on_twin = twin.inverse_transform_point(&nalgebra::Point3::from(*p));
            let on_real = real.inverse_transform_point(&nalgebra::Point3::from(*q));
            assert!((on_twin - on_real).norm() < 1e-12);
        }
        assert!((carried_with(&hand, &twin, &twin)[0] - hand[0]).norm() < 1e-12);
    }

    use super::*;

    fn keys() -> Vec<HandKeyframe> {
        vec![
            HandKeyframe {
                t_s: 0.0,
                xyz: [0.5, 0.0, 1.0],
                rpy: [0.0; 3],
                grip: 0.0,
                tracked: true,
            },
            HandKeyframe {
                t_s: 1.0,
                xyz: [0.6, 0.1, 1.0],
                rpy: [0.0, 0.0, 0.5],
                grip: 1.0,
                tracked: true,
            },
        ]
    }

    #[test]
    fn minimum_jerk_starts_and_ends_at_rest() {
        assert_eq!(min_jerk(0.0), 0.0);
        assert_eq!(min_jerk(1.0), 1.0);
        assert!((min_jerk(0.5) - 0.5).abs() < 1e-12);
        let h = 1e-6;
        for tau in [0.0, 1.0] {
            let v = (min_jerk(tau + h) - min_jerk(tau - h)) / (2.0 * h);
            assert!(v.abs() < 1e-5, "velocity at {tau}: {v}");
        }
    }

    #[test]
    fn scripted_hand_follows_keyframes_with_bounded_noise() {
        let s = HandScript::new(Handedness::Right, keys(), HandNoise::default()).expect("valid");
        let clean = HandScript::new(
            Handedness::Right,
            keys(),
            HandNoise {
                tremor_m: 0.0,
                tracking_sigma_m: 0.0,
                seed: 1,
            },
        )
        .expect("valid");
        for i in 0..=20 {
            let t = f64::from(i) * 0.05;
            let a = s.frame_at(t);
            let b = clean.frame_at(t);
            a.validate().expect("valid frame");
            assert_eq!(a.joints.len(), 26);
            for (ja, jb) in a.joints.iter().zip(&b.joints) {
                let d = (ja.pose.translation.vector - jb.pose.translation.vector).norm();
                assert!(d < 0.0005 + 6.0 * 0.001 * 3f64.sqrt(), "t {t}: {d}");
            }
            // Same seed and time, same frame.
            assert_eq!(s.frame_at(t), a);
        }
        let (w, grip, _) = clean.wrist_at(1.0);
        assert!((w.translation.vector - Vector3::new(0.6, 0.1, 1.0)).norm() < 1e-12);
        assert_eq!(grip, 1.0);
    }

    /// The palm's position error against `clean` over `frames`, filtered or not (RMS, m).
    fn palm_error(
        noisy: &HandScript,
        clean: &HandScript,
        filter: Option<HandFilterSettings>,
        times: impl Iterator<Item = f64>,
    ) -> f64 {
        let mut f = filter.map(HandFilter::new);
        let (mut sum, mut n) = (0.0, 0.0);
        for t in times {
            let mut frame = noisy.frame_at(t);
            if let Some(f) = f.as_mut() {
                f.apply(&mut frame);
            }
            frame.validate().expect("a filtered frame is valid");
            if t >= 0.5 {
                let d = frame.joints[PALM].pose.translation.vector
                    - clean.frame_at(t).joints[PALM].pose.translation.vector;
                sum += d.norm_squared();
                n += 1.0;
            }
        }
        (sum / n).sqrt()
    }

    #[test]
    fn the_hand_filter_calms_a_still_hand_and_follows_a_moving_one() {
        let still = |noise| {
            let k = HandKeyframe {
                t_s: 0.0,
                ..keys()[0]
            };
            let far = HandKeyframe { t_s: 3.0, ..k };
            HandScript::new(Handedness::Right, vec![k, far], noise).expect("valid")
        };
        let noise = HandNoise {
            tremor_m: 0.0,
            tracking_sigma_m: 0.001,
            seed: 3,
        };
        let off = HandNoise {
            tracking_sigma_m: 0.0,
            ..noise
        };
        let frames = || (0..270).map(|i| f64::from(i) / 90.0);
        let raw = palm_error(&still(noise), &still(off), None, frames());
        let calm = palm_error(
            &still(noise),
            &still(off),
            Some(HandFilterSettings::default()),
            frames(),
        );
        // 1 mm per axis of tracking noise on a still hand: the filter removes most of it.
        assert!(raw > 0.0015, "{raw}");
        assert!(calm < raw / 3.0, "raw {raw} m, filtered {calm} m");
        // A hand moving 10 cm in 0.5 s (0.375 m/s at its fastest), noise-free: the filter lags
        // it by a few centimetres at most while it moves and lands on it once it stops.
        let moving = HandScript::new(
            Handedness::Right,
            vec![
                HandKeyframe {
                    t_s: 0.5,
                    ..keys()[0]
                },
                HandKeyframe {
                    t_s: 1.0,
                    xyz: [0.6, 0.0, 1.0],
                    ..keys()[0]
                },
            ],
            off,
        )
        .expect("valid");
        let mut f = HandFilter::new(HandFilterSettings::default());
        let mut worst: f64 = 0.0;
        let mut last = 0.0;
        for i in 0..180 {
            let t = f64::from(i) / 90.0;
            let mut frame = moving.frame_at(t);
            f.apply(&mut frame);
            let d = (frame.joints[PALM].pose.translation.vector
                - moving.frame_at(t).joints[PALM].pose.translation.vector)
                .norm();
            worst = worst.max(d);
            last = d;
        }
        assert!(worst < 0.03, "lag while moving {worst} m");
        assert!(last < 0.001, "left behind {last} m after the stop");
        // Disabled, the frames pass as they are.
        let mut f = HandFilter::new(HandFilterSettings {
            enabled: false,
            ..HandFilterSettings::default()
        });
        let mut a = still(noise).frame_at(0.0);
        let b = still(noise).frame_at(0.1);
        f.apply(&mut a);
        let mut b2 = b.clone();
        f.apply(&mut b2);
        assert_eq!(b, b2);
    }

    #[test]
    fn the_hand_filter_restarts_on_a_lost_hand_and_a_clock_that_goes_back_not_on_a_repeat() {
        let s = HandScript::new(Handedness::Right, keys(), HandNoise::default()).expect("valid");
        let mut f = HandFilter::new(HandFilterSettings::default());
        let mut a = s.frame_at(0.0);
        f.apply(&mut a);
        let mut lost = HandFrame {
            t_s: 0.1,
            hand: Handedness::Right,
            tracked: false,
            joints: Vec::new(),
        };
        f.apply(&mut lost);
        // After the loss, the hand reappears where it is, not pulled from where it was.
        let mut far = s.frame_at(1.0);
        let raw = far.clone();
        f.apply(&mut far);
        assert_eq!(far, raw);
        let mut back = s.frame_at(0.5);
        let raw = back.clone();
        f.apply(&mut back);
        assert_eq!(back, raw);
        // A repeated frame gives what the filter gave for it, not the raw frame.
        let mut next = s.frame_at(0.6);
        f.apply(&mut next);
        let mut again = s.frame_at(0.6);
        f.apply(&mut again);
        assert_eq!(again, next);
        assert_ne!(again, s.frame_at(0.6));
        for bad in [
            HandFilterSettings {
                min_cutoff_hz: 0.0,
                ..HandFilterSettings::default()
            },
            HandFilterSettings {
                beta: f64::NAN,
                ..HandFilterSettings::default()
            },
        ] {
            let e = bad.validate().expect_err("refused");
            let e = e.to_string();
            assert!(e.contains("min_cutoff_hz") || e.contains("beta"), "{e}");
        }
    }

    #[test]
    fn closing_the_grip_brings_the_fingertips_toward_the_palm() {
        let w = Isometry3::identity();
        let dist = |grip: f64| {
            let j = skeleton(&w, grip, Handedness::Right);
            TIPS[1..]
                .iter()
                .map(|&t| (j[t].pose.translation.vector - j[PALM].pose.translation.vector).norm())
                .sum::<f64>()
        };
        assert!(
            dist(1.0) < 0.7 * dist(0.0),
            "{} vs {}",
            dist(1.0),
            dist(0.0)
        );
    }

    #[test]
    fn file_round_trip_and_errors_name_the_line() {
        let s = HandScript::new(Handedness::Left, keys(), HandNoise::default()).expect("valid");
        let mut frames: Vec<HandFrame> = (0..5).map(|i| s.frame_at(f64::from(i) * 0.1)).collect();
        frames.push(HandFrame {
            t_s: 0.6,
            hand: Handedness::Left,
            tracked: false,
            joints: Vec::new(),
        });
        let text = write_frames(&frames);
        let back = parse_frames(&text).expect("parses");
        assert_eq!(back.len(), 6);
        for (a, b) in back.iter().zip(&frames) {
            assert_eq!(a.tracked, b.tracked);
            for (ja, jb) in a.joints.iter().zip(&b.joints) {
                assert!((ja.pose.translation.vector - jb.pose.translation.vector).norm() < 1e-12);
                assert!(ja.pose.rotation.angle_to(&jb.pose.rotation) < 1e-9);
            }
        }
        let bad = text.replacen("\"t_s\":0.2", "\"t_s\":0.05", 1);
        assert!(
            parse_frames(&bad)
                .expect_err("order")
                .to_string()
                .starts_with("line 3:")
        );
        let nan =
            "{\"t_s\":0.0,\"hand\":\"right\",\"tracked\":true,\"joints\":[[0,0,0,0,0,0,1,0.01]]}";
        assert!(
            parse_frames(nan)
                .expect_err("26")
                .to_string()
                .contains("needs 26 joints")
        );
        assert!(
            parse_frames("{oops")
                .expect_err("json")
                .to_string()
                .starts_with("line 1:")
        );
    }
}
