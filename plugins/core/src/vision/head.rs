//! A camera that moves with a head: Alice's headset camera (the paper's second viewpoint).
//!
//! - [`HeadMotion`]: where the head is at each time, scripted (look-at keyframes, or a yaw
//!   sweep at a set peak angular speed for measurements).
//! - [`TrackingModel`] and [`HeadTracker`]: the head as a tracker reports it, sampled at a rate,
//!   with Gaussian noise, arriving after a latency (a simulated headset's tracking).
//! - [`PoseHistory`]: the tracked poses received so far, and the pose at any time
//!   ([`PoseHistory::at`]: interpolated between samples, extrapolated a little past the last).
//!   *Pose compensation* draws a frame's mask at the head pose of the frame's capture time,
//!   as the joint history does for the arm.
//!
//! Frames: the head's frame follows the OpenCV optical convention, as cameras here do (x right,
//! y down, z forward: the direction the face points). The camera's optical frame is the head's
//! times the *mount* (`head_from_camera`): `world_from_camera = world_from_head * mount`. An
//! OpenXR view pose (x right, y up, -z forward) is turned into this frame by a rotation of π
//! about x ([`openxr_view_from_head`]).

use std::collections::VecDeque;

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::error::{Error, Result};
use crate::rng::Rng;
use crate::vision::camera::CameraPose;

/// A head keyframe: the head's optical frame (x right, y down, z forward) at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadKeyframe {
    /// Time (s, the robot's clock).
    pub t_s: f64,
    /// `world_from_head`.
    pub pose: Isometry3<f64>,
}

/// Where the head is over time.
#[derive(Debug, Clone, PartialEq)]
pub enum HeadMotion {
    /// Keyframes in time order; between two, the position moves by minimum jerk and the
    /// rotation by a spherical interpolation with the same timing (still at each keyframe);
    /// before the first and after the last, the head holds.
    Keyframes(Vec<HeadKeyframe>),
    /// Looking around a centre pose: the head turns about the world's vertical axis through a
    /// pivot `pivot_back_m` behind the eye (the neck), yaw(t) = A sin(t ω / A), so that the
    /// angular speed peaks at ω when crossing the centre and is 0 at ±A.
    Sweep {
        /// The pose at yaw 0.
        centre: Isometry3<f64>,
        /// A (rad, > 0 when ω > 0).
        amplitude_rad: f64,
        /// ω, the peak angular speed (rad/s; 0: the head holds still at the centre).
        peak_speed_rad_s: f64,
        /// The pivot's distance behind the eye, horizontally (m; 0: the head turns about the
        /// eye).
        pivot_back_m: f64,
    },
    /// A real head, as a headset reports it ([`LiveHead`]): the wearer's own motion.
    Live(LiveHead),
}

impl HeadMotion {
    /// Look-at keyframes (`(t_s, eye/target/up)`): sorted by time; errors name the keyframe
    /// whose eye equals its target or whose up is along the view.
    pub fn look_at(keyframes: &[(f64, CameraPose)]) -> Result<Self> {
        let mut out = Vec::with_capacity(keyframes.len());
        for (i, (t_s, pose)) in keyframes.iter().enumerate() {
            let pose = pose.to_isometry().map_err(|e| Error::BadSetting {
                what: format!("head keyframe {i}"),
                message: e.to_string(),
            })?;
            out.push(HeadKeyframe { t_s: *t_s, pose });
        }
        out.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        Ok(Self::Keyframes(out))
    }

    /// `world_from_head` at `t_s`; a motion with no keyframes is the identity.
    pub fn pose_at(&self, t_s: f64) -> Isometry3<f64> {
        match self {
            Self::Keyframes(k) => keyframes_at(k, t_s),
            Self::Sweep {
                centre,
                amplitude_rad,
                peak_speed_rad_s,
                pivot_back_m,
            } => {
                let yaw = sweep_yaw(*amplitude_rad, *peak_speed_rad_s, t_s);
                let forward = centre.rotation * Vector3::z();
                let flat = Vector3::new(forward.x, forward.y, 0.0)
                    .try_normalize(1e-9)
                    .unwrap_or_else(Vector3::zeros);
                let pivot = centre.translation.vector - flat * *pivot_back_m;
                let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
                let eye = pivot + turn * (centre.translation.vector - pivot);
                Isometry3::from_parts(Translation3::from(eye), turn * centre.rotation)
            }
            Self::Live(live) => live.pose_at(t_s),
        }
    }

    /// The head's angular speed at `t_s` (rad/s), by a central difference of 1 ms.
    pub fn angular_speed_at(&self, t_s: f64) -> f64 {
        let h = 5e-4;
        let a = self.pose_at(t_s - h).rotation;
        let b = self.pose_at(t_s + h).rotation;
        a.angle_to(&b) / (2.0 * h)
    }

    /// The largest angular speed over `[0, duration_s]` (rad/s), sampled every 5 ms.
    pub fn peak_angular_speed(&self, duration_s: f64) -> f64 {
        let n = (duration_s / 0.005).ceil().max(1.0) as usize;
        (0..=n)
            .map(|i| self.angular_speed_at(i as f64 * duration_s / n as f64))
            .fold(0.0, f64::max)
    }
}

/// yaw(t) = A sin(t ω / A): peak speed ω at the centre, turning back smoothly at ±A.
fn sweep_yaw(amplitude: f64, peak_speed: f64, t: f64) -> f64 {
    if amplitude <= 0.0 || peak_speed <= 0.0 {
        return 0.0;
    }
    amplitude * (t * peak_speed / amplitude).sin()
}

fn keyframes_at(k: &[HeadKeyframe], t: f64) -> Isometry3<f64> {
    let Some(first) = k.first() else {
        return Isometry3::identity();
    };
    if t <= first.t_s {
        return first.pose;
    }
    for w in k.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if t <= b.t_s {
            let span = (b.t_s - a.t_s).max(1e-9);
            let blend = crate::teleop::hand::min_jerk((t - a.t_s) / span);
            return interpolate(&a.pose, &b.pose, blend);
        }
    }
    k.last().map_or(first.pose, |l| l.pose)
}

/// `a` at 0, `b` at 1: the translation linearly, the rotation by slerp (shortest way).
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    let p = a.translation.vector.lerp(&b.translation.vector, s);
    let r = a
        .rotation
        .try_slerp(&b.rotation, s, 1e-12)
        .unwrap_or(if s < 0.5 { a.rotation } else { b.rotation });
    Isometry3::from_parts(Translation3::from(p), r)
}

/// `view_from_head`: the head's optical frame (x right, y down, z forward) in an OpenXR view
/// space (x right, y up, -z forward; OpenXR 1.0 spec, "Reference Spaces"), a rotation of π
/// about x: `world_from_head = world_from_view * openxr_view_from_head()`.
pub fn openxr_view_from_head() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
}

/// `world_from_tracking` for a headset's tracking space (OpenXR's stage or local space: y up)
/// that puts the head pose `tracking_from_head` (the head's optical frame) on
/// `world_from_head` (the world: z up) as nearly as turning about the vertical allows: the
/// same heading and position, gravity kept (the tracking space's y becomes the world's z).
/// This registers a headset to a scene at one moment; it is not a calibration.
pub fn register_tracking(
    world_from_head: &Isometry3<f64>,
    tracking_from_head: &Isometry3<f64>,
) -> Isometry3<f64> {
    // y up -> z up: +90 degrees about x.
    let z_up = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
    let heading = |r: &UnitQuaternion<f64>| {
        let forward = r * Vector3::z();
        forward.y.atan2(forward.x)
    };
    let upright = z_up * tracking_from_head.rotation;
    let yaw = heading(&world_from_head.rotation) - heading(&upright);
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * z_up;
    let translation =
        world_from_head.translation.vector - rotation * tracking_from_head.translation.vector;
    Isometry3::from_parts(Translation3::from(translation), rotation)
}

/// A head moved by a headset (OpenXR, Alice's): the poses it reports, registered to the scene
/// at the first one ([`register_tracking`] onto the scripted motion's pose then), kept in a
/// [`PoseHistory`]; before the first, the scripted motion. Clones share one head, so that the
/// headset's system and the simulated room read and write the same poses.
#[derive(Debug, Clone)]
pub struct LiveHead(std::sync::Arc<std::sync::Mutex<LiveHeadState>>);

#[derive(Debug)]
struct LiveHeadState {
    scripted: Box<HeadMotion>,
    history: PoseHistory,
    world_from_tracking: Option<Isometry3<f64>>,
    first: Option<Isometry3<f64>>,
    poses: u64,
}

impl LiveHeadState {
    /// Keeps a pose in the scene's world (refused when not finite or not newer than the last).
    fn take(&mut self, t_s: f64, world_from_head: Isometry3<f64>) -> bool {
        if !self.history.push(t_s, world_from_head) {
            return false;
        }
        self.first.get_or_insert(world_from_head);
        self.poses += 1;
        true
    }
}

impl PartialEq for LiveHead {
    fn eq(&self, other: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0)
    }
}

impl LiveHead {
    /// A live head that follows `scripted` until the headset reports.
    pub fn new(scripted: HeadMotion) -> Self {
        Self(std::sync::Arc::new(std::sync::Mutex::new(LiveHeadState {
            scripted: Box::new(scripted),
            history: PoseHistory::default(),
            world_from_tracking: None,
            first: None,
            poses: 0,
        })))
    }

    fn state(&self) -> std::sync::MutexGuard<'_, LiveHeadState> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes the headset's head at `t_s` (s, the app's clock): `tracking_from_view`, an
    /// OpenXR view pose in its tracking space (y up). Returns `world_from_head`, or `None` for
    /// a pose or time that is not finite or not newer than the last.
    pub fn push_openxr_view(
        &self,
        t_s: f64,
        tracking_from_view: &Isometry3<f64>,
    ) -> Option<Isometry3<f64>> {
        let tracking_from_head = Isometry3::from_parts(
            tracking_from_view.translation,
            tracking_from_view.rotation * openxr_view_from_head(),
        );
        let mut s = self.state();
        let registration = match s.world_from_tracking {
            Some(r) => r,
            None => {
                let r = register_tracking(&s.scripted.pose_at(t_s), &tracking_from_head);
                if !(r.translation.vector.iter().all(|v| v.is_finite())
                    && r.rotation.coords.iter().all(|v| v.is_finite()))
                {
                    return None;
                }
                s.world_from_tracking = Some(r);
                r
            }
        };
        let world_from_head = registration * tracking_from_head;
        s.take(t_s, world_from_head).then_some(world_from_head)
    }

    /// Takes a head pose already in the scene's world (`world_from_head`; registered where the
    /// headset is, as a remote wearer's arrives) at `t_s` (s, the app's clock). Returns `false`
    /// for a pose or time that is not finite or not newer than the last.
    pub fn push_world(&self, t_s: f64, world_from_head: &Isometry3<f64>) -> bool {
        self.state().take(t_s, *world_from_head)
    }

    /// The newest pose taken (`(t_s, world_from_head)`, `t_s` on the app's clock), if any.
    pub fn latest(&self) -> Option<(f64, Isometry3<f64>)> {
        self.state().history.latest()
    }

    /// Moves the stamps of the poses taken by `dt_s` (s): the poses come stamped on another
    /// clock ([`LiveHead::push_world`]), and the app's clock moved against it.
    pub fn shift(&self, dt_s: f64) {
        self.state().history.shift(dt_s);
    }

    /// `world_from_head` at `t_s`: the headset's (interpolated, or extrapolated at most 0.1 s)
    /// once it has reported, the scripted motion's before.
    pub fn pose_at(&self, t_s: f64) -> Isometry3<f64> {
        let s = self.state();
        s.history.at(t_s).unwrap_or_else(|| s.scripted.pose_at(t_s))
    }

    /// Poses taken from the headset so far.
    pub fn poses(&self) -> u64 {
        self.state().poses
    }

    /// How far the head has turned (rad) from the headset's first pose to its newest.
    pub fn turned_rad(&self) -> f64 {
        let s = self.state();
        match (s.first, s.history.latest()) {
            (Some(a), Some((_, b))) => a.rotation.angle_to(&b.rotation),
            _ => 0.0,
        }
    }
}

/// How a headset reports its head pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingModel {
    /// Samples per second (> 0; a Quest 2 reports its head at the display's 72–120 Hz).
    pub rate_hz: f64,
    /// From the moment a sample describes to the moment the app receives it (s, ≥ 0).
    pub latency_s: f64,
    /// Position noise, per axis (m, ≥ 0).
    pub position_sigma_m: f64,
    /// Orientation noise, per axis of a small rotation (rad, ≥ 0).
    pub angle_sigma_rad: f64,
}

impl Default for TrackingModel {
    fn default() -> Self {
        Self {
            rate_hz: 90.0,
            latency_s: 0.0,
            position_sigma_m: 0.0,
            angle_sigma_rad: 0.0,
        }
    }
}

impl TrackingModel {
    /// Checks the numbers; `what` names where they came from.
    pub fn validate(&self, what: &str) -> Result<()> {
        let bad = |message: String| {
            Err(Error::BadSetting {
                what: what.to_owned(),
                message,
            })
        };
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 10_000.0) {
            return bad(format!("rate_hz = {} is outside (0, 10000]", self.rate_hz));
        }
        if !(self.latency_s.is_finite() && (0.0..=2.0).contains(&self.latency_s)) {
            return bad(format!("latency = {} s is outside [0, 2]", self.latency_s));
        }
        if !(self.position_sigma_m.is_finite() && (0.0..=0.1).contains(&self.position_sigma_m)) {
            return bad(format!(
                "position noise = {} m is outside [0, 0.1]",
                self.position_sigma_m
            ));
        }
        if !(self.angle_sigma_rad.is_finite()
            && (0.0..=10f64.to_radians()).contains(&self.angle_sigma_rad))
        {
            return bad(format!(
                "angle noise = {}° is outside [0, 10]",
                self.angle_sigma_rad.to_degrees()
            ));
        }
        Ok(())
    }
}

/// A stamped tracked pose: `world_from_head` as the tracker measured it at `stamp_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackedPose {
    /// The moment it describes (s, the robot's clock).
    pub stamp_s: f64,
    /// When the app receives it (s).
    pub arrival_s: f64,
    /// `world_from_head`.
    pub pose: Isometry3<f64>,
}

/// A simulated head tracker: samples a [`HeadMotion`] at the model's rate, adds its noise
/// (seeded: sample `k` uses stream `k`) and hands each sample over once its latency has passed.
#[derive(Debug, Clone)]
pub struct HeadTracker {
    model: TrackingModel,
    seed: u64,
    next_sample: u64,
    in_flight: VecDeque<TrackedPose>,
}

impl HeadTracker {
    /// A tracker whose first sample is at t = 0.
    pub fn new(model: TrackingModel, seed: u64) -> Self {
        Self {
            model,
            seed,
            next_sample: 0,
            in_flight: VecDeque::new(),
        }
    }

    /// A tracker whose first sample is the first at or after `from_s` (s; a camera switched
    /// to mid-session tracks from then on, not from t = 0). Each sample is the one
    /// [`HeadTracker::new`]'s tracker gives at that time, noise included.
    pub fn starting_at(model: TrackingModel, seed: u64, from_s: f64) -> Self {
        let first = if from_s.is_finite() && from_s > 0.0 {
            (from_s * model.rate_hz - 1e-9).ceil() as u64
        } else {
            0
        };
        Self {
            next_sample: first,
            ..Self::new(model, seed)
        }
    }

    /// Takes every sample due up to `now_s` and returns, oldest first, those that have arrived
    /// by then.
    pub fn poll(&mut self, motion: &HeadMotion, now_s: f64) -> Vec<TrackedPose> {
        if !now_s.is_finite() {
            return Vec::new();
        }
        let period = 1.0 / self.model.rate_hz;
        loop {
            let stamp_s = self.next_sample as f64 * period;
            if stamp_s > now_s + 1e-9 {
                break;
            }
            let mut rng = Rng::stream(self.seed, self.next_sample);
            self.next_sample += 1;
            let truth = motion.pose_at(stamp_s);
            let dp = Vector3::new(rng.gaussian(), rng.gaussian(), rng.gaussian())
                * self.model.position_sigma_m;
            let dr = Vector3::new(rng.gaussian(), rng.gaussian(), rng.gaussian())
                * self.model.angle_sigma_rad;
            let pose = Isometry3::from_parts(
                Translation3::from(truth.translation.vector + dp),
                UnitQuaternion::from_scaled_axis(dr) * truth.rotation,
            );
            self.in_flight.push_back(TrackedPose {
                stamp_s,
                arrival_s: stamp_s + self.model.latency_s,
                pose,
            });
        }
        let mut out = Vec::new();
        while self
            .in_flight
            .front()
            .is_some_and(|p| p.arrival_s <= now_s + 1e-9)
        {
            out.extend(self.in_flight.pop_front());
        }
        out
    }
}

/// Tracked poses received so far (about the last second), and the pose at any time.
#[derive(Debug, Clone)]
pub struct PoseHistory {
    samples: VecDeque<(f64, Isometry3<f64>)>,
    /// How far past the newest sample [`PoseHistory::at`] extrapolates (s).
    pub max_ahead_s: f64,
    /// The velocity for extrapolation is taken between the newest sample and the newest one at
    /// least this much older (s): a longer baseline averages the tracker's noise.
    pub velocity_baseline_s: f64,
    /// Samples older than this before the newest are dropped (s): at least the frames'
    /// latency, so that a frame's capture time stays inside the history.
    pub window_s: f64,
}

impl Default for PoseHistory {
    fn default() -> Self {
        Self {
            samples: VecDeque::new(),
            max_ahead_s: 0.1,
            velocity_baseline_s: 0.03,
            window_s: 1.0,
        }
    }
}

impl PoseHistory {
    /// Adds a sample if it is newer than the newest and finite; returns whether it was taken.
    pub fn push(&mut self, stamp_s: f64, pose: Isometry3<f64>) -> bool {
        let finite = stamp_s.is_finite()
            && pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite());
        if !finite || self.samples.back().is_some_and(|s| s.0 >= stamp_s) {
            return false;
        }
        self.samples.push_back((stamp_s, pose));
        while self
            .samples
            .front()
            .is_some_and(|s| stamp_s - s.0 > self.window_s)
        {
            self.samples.pop_front();
        }
        true
    }

    /// The newest sample, `(stamp_s, world_from_head)`.
    pub fn latest(&self) -> Option<(f64, Isometry3<f64>)> {
        self.samples.back().copied()
    }

    /// Moves every sample's stamp by `dt_s` (s; the clock they were converted to moved
    /// against theirs). A shift that is not finite is ignored.
    pub fn shift(&mut self, dt_s: f64) {
        if dt_s.is_finite() {
            for s in &mut self.samples {
                s.0 += dt_s;
            }
        }
    }

    /// The pose at `t_s`: interpolated between the samples around it (translation linearly,
    /// rotation by slerp); past the newest, extrapolated with the velocity over
    /// [`PoseHistory::velocity_baseline_s`] (constant linear and angular velocity), at most
    /// [`PoseHistory::max_ahead_s`] ahead; before the oldest, the oldest. `None` without samples
    /// or for a time that is not finite.
    pub fn at(&self, t_s: f64) -> Option<Isometry3<f64>> {
        if !t_s.is_finite() {
            return None;
        }
        let &(t1, p1) = self.samples.back()?;
        if t_s >= t1 {
            let ahead = (t_s - t1).min(self.max_ahead_s);
            let older = self
                .samples
                .iter()
                .rev()
                .find(|s| t1 - s.0 >= self.velocity_baseline_s)
                .or_else(|| self.samples.front().filter(|s| s.0 < t1));
            let Some(&(t0, p0)) = older else {
                return Some(p1);
            };
            let dt = t1 - t0;
            let v = (p1.translation.vector - p0.translation.vector) / dt;
            let w = (p1.rotation * p0.rotation.inverse()).scaled_axis() / dt;
            return Some(Isometry3::from_parts(
                Translation3::from(p1.translation.vector + v * ahead),
                UnitQuaternion::from_scaled_axis(w * ahead) * p1.rotation,
            ));
        }
        let &(t0, p0) = self.samples.front()?;
        if t_s <= t0 {
            return Some(p0);
        }
        let i = self.samples.partition_point(|s| s.0 <= t_s);
        let (a, b) = (&self.samples[i - 1], &self.samples[i]);
        Some(interpolate(&a.1, &b.1, (t_s - a.0) / (b.0 - a.0)))
    }
}

/// The angle between two poses' rotations (rad) and the distance between their origins (m).
pub fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    (
        a.rotation.angle_to(&b.rotation),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

/// A mount perturbed by a calibration error: a rotation of `angle_rad` about `axis` (in the
/// head's frame, through the camera's centre) and a translation `offset_m` (head frame).
pub fn perturbed_mount(
    mount: &Isometry3<f64>,
    axis: &Vector3<f64>,
    angle_rad: f64,
    offset_m: &Vector3<f64>,
) -> Isometry3<f64> {
    let axis = Unit::try_new(*axis, 1e-12).unwrap_or(Vector3::y_axis());
    Isometry3::from_parts(
        Translation3::from(mount.translation.vector + offset_m),
        UnitQuaternion::from_axis_angle(&axis, angle_rad) * mount.rotation,
    )
}

#[cfg(test)]
mod tests {

    /// A headset's pose is registered onto the scene's head at its first sample; its later
    /// turn about its tracking space's vertical turns the scene's head as much about the
    /// world's vertical.
    #[test]
    fn a_live_head_follows_the_headset_from_where_the_scene_put_it() {
        let scripted = HeadMotion::look_at(&[(
            0.0,
            CameraPose {
                eye: [0.85, -1.1, 1.25],
                target: [0.55, 0.0, 0.9],
                up: [0.0, 0.0, 1.0],
            },
        )])
        .unwrap();
        let start = scripted.pose_at(0.0);
        let live = LiveHead::new(scripted);
        assert_eq!(
            live.pose_at(0.5),
            start,
            "the script until the headset reports"
        );
        // The headset at 1.6 m in its stage space, looking down -z, then turned 20 degrees
        // left (about +y) and 10 cm to the right.
        let view = |yaw_deg: f64, x: f64| {
            Isometry3::from_parts(
                Translation3::new(x, 1.6, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw_deg.to_radians()),
            )
        };
        let first = live.push_openxr_view(1.0, &view(0.0, 0.0)).unwrap();
        assert!((first.translation.vector - start.translation.vector).norm() < 1e-9);
        // Registered by heading: the start pose's pitch is not the headset's.
        let heading = |p: &Isometry3<f64>| {
            let f = p.rotation * Vector3::z();
            f.y.atan2(f.x)
        };
        assert!((heading(&first) - heading(&start)).abs() < 1e-9);
        let later = live.push_openxr_view(2.0, &view(20.0, 0.1)).unwrap();
        assert!(((heading(&later) - heading(&first)).to_degrees() - 20.0).abs() < 1e-6);
        assert!(((later.translation.vector - first.translation.vector).norm() - 0.1).abs() < 1e-9);
        assert!((live.turned_rad().to_degrees() - 20.0).abs() < 1e-6);
        assert_eq!(live.poses(), 2);
        // Between them, interpolated; an old or broken sample is refused.
        let mid = live.pose_at(1.5);
        assert!(((heading(&mid) - heading(&first)).to_degrees() - 10.0).abs() < 1e-6);
        assert!(live.push_openxr_view(1.5, &view(5.0, 0.0)).is_none());
        assert!(live.push_openxr_view(f64::NAN, &view(5.0, 0.0)).is_none());
        // Clones share the head.
        assert_eq!(live.clone().poses(), 2);
        assert_eq!(HeadMotion::Live(live.clone()), HeadMotion::Live(live));
    }
    use super::*;

    fn look(eye: [f64; 3], target: [f64; 3]) -> Isometry3<f64> {
        CameraPose {
            eye,
            target,
            up: [0.0, 0.0, 1.0],
        }
        .to_isometry()
        .expect("pose")
    }

    fn sweep(speed_deg_s: f64, pivot: f64) -> HeadMotion {
        HeadMotion::Sweep {
            centre: look([1.6, 0.0, 1.2], [0.0, 0.0, 0.4]),
            amplitude_rad: 20f64.to_radians(),
            peak_speed_rad_s: speed_deg_s.to_radians(),
            pivot_back_m: pivot,
        }
    }

    #[test]
    fn a_sweep_peaks_at_its_speed_and_stays_within_its_amplitude() {
        for speed in [15.0, 30.0, 60.0] {
            let m = sweep(speed, 0.1);
            let peak = m.peak_angular_speed(10.0).to_degrees();
            assert!((peak - speed).abs() < 0.01 * speed, "{peak} vs {speed}");
            let centre = m.pose_at(0.0);
            for i in 0..200 {
                let (angle, _) = pose_error(&centre, &m.pose_at(i as f64 * 0.05));
                assert!(angle <= 20f64.to_radians() + 1e-9);
            }
        }
        let still = sweep(0.0, 0.1);
        assert_eq!(still.pose_at(3.0), still.pose_at(0.0));
        // Turning about the neck moves the eye; about the eye it does not.
        let t = 20f64.to_radians() / 30f64.to_radians() * std::f64::consts::FRAC_PI_2;
        let (_, moved) = pose_error(&sweep(30.0, 0.1).pose_at(0.0), &sweep(30.0, 0.1).pose_at(t));
        assert!((moved - 2.0 * 0.1 * (10f64.to_radians()).sin()).abs() < 1e-6);
        let (_, moved) = pose_error(&sweep(30.0, 0.0).pose_at(0.0), &sweep(30.0, 0.0).pose_at(t));
        assert!(moved < 1e-12);
    }

    #[test]
    fn keyframes_pass_through_and_hold_outside() {
        let a = look([1.6, 0.0, 1.2], [0.0, 0.0, 0.4]);
        let b = look([1.2, 0.3, 1.0], [0.0, 0.0, 0.4]);
        let m = HeadMotion::Keyframes(vec![
            HeadKeyframe { t_s: 1.0, pose: a },
            HeadKeyframe { t_s: 3.0, pose: b },
        ]);
        assert_eq!(m.pose_at(0.0), a);
        assert_eq!(m.pose_at(1.0), a);
        let end = m.pose_at(3.0);
        assert!(pose_error(&end, &b).0 < 1e-9 && pose_error(&end, &b).1 < 1e-12);
        assert_eq!(m.pose_at(9.0), b);
        // Half-way in time is half-way in space (minimum jerk is symmetric).
        let mid = m.pose_at(2.0);
        let half = interpolate(&a, &b, 0.5);
        assert!(pose_error(&mid, &half).0 < 1e-9 && pose_error(&mid, &half).1 < 1e-12);
        assert!(m.angular_speed_at(1.0) < 1e-3, "still at a keyframe");
        let bad = HeadMotion::look_at(&[(
            0.0,
            CameraPose {
                eye: [1.0, 0.0, 0.0],
                target: [1.0, 0.0, 0.0],
                up: [0.0, 0.0, 1.0],
            },
        )]);
        assert!(bad.unwrap_err().to_string().contains("head keyframe 0"));
    }

    #[test]
    fn history_interpolates_extrapolates_and_refuses_bad_samples() {
        // Constant angular velocity about z and linear motion: interpolation and
        // extrapolation are both exact.
        let w = 0.5;
        let pose = |t: f64| {
            Isometry3::from_parts(
                Translation3::new(0.1 * t, 0.0, 1.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), w * t),
            )
        };
        let mut h = PoseHistory::default();
        for i in 0..10 {
            assert!(h.push(i as f64 * 0.01, pose(i as f64 * 0.01)));
        }
        assert!(!h.push(0.05, pose(0.05)), "out of order");
        let mut nan = pose(1.0);
        nan.translation.vector.x = f64::NAN;
        assert!(!h.push(1.0, nan), "not finite");
        for t in [0.033, 0.0875, 0.1, 0.15] {
            let (angle, dist) = pose_error(&h.at(t).expect("pose"), &pose(t));
            assert!(
                angle < 1e-9 && dist < 1e-12,
                "t = {t}: {angle} rad, {dist} m"
            );
        }
        // Capped: 0.1 s past the newest sample at most.
        let (angle, _) = pose_error(&h.at(5.0).expect("pose"), &pose(0.09 + 0.1));
        assert!(angle < 1e-9);
        assert_eq!(h.at(-1.0), Some(pose(0.0)));
        assert!(h.at(f64::NAN).is_none());
        assert!(PoseHistory::default().at(0.0).is_none());
        // Moved to another clock: the same poses at the moved stamps, still in order.
        h.shift(-0.5);
        let (angle, dist) = pose_error(&h.at(0.033 - 0.5).expect("pose"), &pose(0.033));
        assert!(angle < 1e-9 && dist < 1e-12);
        assert!(
            !h.push(0.05 - 0.5, pose(0.05)),
            "out of order after the shift"
        );
        assert!(h.push(0.1 - 0.5, pose(0.1)));
    }

    #[test]
    fn a_live_head_takes_a_remote_wearers_poses_in_the_world() {
        let scripted = HeadMotion::Keyframes(vec![]);
        let live = LiveHead::new(scripted);
        let at = |x: f64| Isometry3::translation(x, 0.0, 1.5);
        // Before any pose, the scripted head (here the identity).
        assert_eq!(live.pose_at(0.3), Isometry3::identity());
        assert!(live.push_world(0.1, &at(0.0)));
        assert!(live.push_world(0.2, &at(0.1)));
        assert!(!live.push_world(0.15, &at(0.5)), "out of order");
        let mut nan = at(0.0);
        nan.rotation =
            UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
        assert!(!live.push_world(0.3, &nan), "not finite");
        assert_eq!(live.poses(), 2);
        assert!((live.pose_at(0.15).translation.x - 0.05).abs() < 1e-12);
        // The app's clock fell 0.05 s behind the wearer's: the poses move with it.
        live.shift(-0.05);
        assert!((live.pose_at(0.1).translation.x - 0.05).abs() < 1e-12);
        assert_eq!(live.latest().map(|l| l.0), Some(0.2 - 0.05));
    }

    #[test]
    fn the_tracker_samples_at_its_rate_and_delivers_after_its_latency() {
        let m = sweep(30.0, 0.1);
        let model = TrackingModel {
            rate_hz: 100.0,
            latency_s: 0.05,
            ..TrackingModel::default()
        };
        let mut tracker = HeadTracker::new(model, 7);
        assert!(tracker.poll(&m, 0.04).is_empty(), "nothing arrived yet");
        assert!(
            tracker.poll(&m, f64::NAN).is_empty(),
            "a time that is not finite"
        );
        let got = tracker.poll(&m, 0.1);
        assert_eq!(got.len(), 6, "samples at 0..=0.05 s");
        for p in &got {
            assert!((p.arrival_s - p.stamp_s - 0.05).abs() < 1e-12);
            assert_eq!(p.pose, m.pose_at(p.stamp_s), "no noise set");
        }
        // Noise: its spread is the model's.
        let noisy = TrackingModel {
            rate_hz: 1000.0,
            position_sigma_m: 0.001,
            angle_sigma_rad: 0.1f64.to_radians(),
            ..TrackingModel::default()
        };
        let mut tracker = HeadTracker::new(noisy, 3);
        let samples = tracker.poll(&m, 4.0);
        let n = samples.len() as f64;
        let (mut angles, mut dists) = (0.0, 0.0);
        for p in &samples {
            let (a, d) = pose_error(&p.pose, &m.pose_at(p.stamp_s));
            angles += a * a;
            dists += d * d;
        }
        // The norm of a 3-D Gaussian vector: E|x|² = 3σ².
        let rms_angle = (angles / n / 3.0).sqrt().to_degrees();
        let rms_dist = (dists / n / 3.0).sqrt();
        assert!((rms_angle - 0.1).abs() < 0.01, "{rms_angle}°");
        assert!((rms_dist - 0.001).abs() < 0.0001, "{rms_dist} m");
        // Same seed, same samples.
        let again = HeadTracker::new(noisy, 3).poll(&m, 4.0);
        assert_eq!(again, samples);
        // Started later: the same samples from then on, none before.
        let late = HeadTracker::starting_at(noisy, 3, 2.5).poll(&m, 4.0);
        assert!(late.first().is_some_and(|p| (p.stamp_s - 2.5).abs() < 1e-9));
        assert_eq!(late[..], samples[samples.len() - late.len()..]);
        assert_eq!(
            HeadTracker::starting_at(noisy, 3, f64::NAN).poll(&m, 4.0),
            samples
        );
    }

    #[test]
    fn tracking_settings_are_checked() {
        assert!(TrackingModel::default().validate("t").is_ok());
        let bad = TrackingModel {
            latency_s: -0.01,
            ..TrackingModel::default()
        };
        assert!(
            bad.validate("head.tracking")
                .unwrap_err()
                .to_string()
                .contains("latency")
        );
        let bad = TrackingModel {
            rate_hz: f64::NAN,
            ..TrackingModel::default()
        };
        assert!(bad.validate("t").is_err());
    }

    #[test]
    fn an_openxr_view_looks_down_its_minus_z() {
        let view = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.3),
        );
        let head = view * openxr_view_from_head();
        let forward = head.rotation * Vector3::z();
        let expected = view.rotation * -Vector3::z();
        assert!((forward - expected).norm() < 1e-12);
        let down = head.rotation * Vector3::y();
        assert!((down + view.rotation * Vector3::y()).norm() < 1e-12);
    }
}
